//! The typed async client of the guest's native `/v1/` API, [`GuestClient`].
//!
//! One method per route, taking and returning the wire types of
//! `arena_shared`. Every call has a deadline (the configured default, or a
//! longer one the call computes: an action batch with waits, an exec with its
//! own timeout, a tree walk with its own budget), and idempotent calls are
//! retried with a short exponential backoff when the guest was unreachable,
//! too slow or behind a proxy that answered 502 to 504.
//! Calls that change the desktop or start programs (`POST /v1/actions`,
//! `/v1/exec`, `/v1/launch`, `/v1/open`, and the other POSTs and DELETEs)
//! are never retried: doing them twice is worse than failing once.
//!
//! It is not the legacy WAA client (the upstream routes are for upstream
//! hosts) and it does no TLS: guests sit on a private network and are guarded
//! by a bearer token.

use std::hash::{BuildHasher, Hasher};
use std::time::Duration;

// Tokio's clock (the system clock unless a test pauses it), so waits are testable.
use tokio::time::Instant;

use reqwest::header::{HeaderMap, CONTENT_TYPE};
use reqwest::{Method, StatusCode, Url};
use serde::de::DeserializeOwned;
use serde::Serialize;
use sha2::{Digest, Sha256};

use arena_shared::action::{Action, ActionBatch, ActionReport};
use arena_shared::clipboard::ClipboardContent;
use arena_shared::clock::{ClockReading, ClockSet, ClockSetResult};
use arena_shared::error::ErrorBody;
use arena_shared::eval::{
    DetailsViewQuery, EvalAnswer, ImagesTaggedQuery, LibraryFolders, LibraryQuery, ReadOnlyQuery,
    SortedByModifiedQuery, TimerQuery, WorldClockQuery,
};
use arena_shared::exec::{ExecRequest, ExecResult, LaunchRequest, LaunchResult};
use arena_shared::files::{
    DirListing, Exists, FileStat, FileWritten, KnownFolders, MkdirRequest, PathQuery, WriteQuery,
};
use arena_shared::geometry::CoordinateSpace;
use arena_shared::health::{Component, HealthReport};
use arena_shared::observation::{
    A11yQuery, A11yTree, ScreenInfo, ScreenshotMeta, ScreenshotQuery, WindowInfo, WindowTarget,
};
use arena_shared::registry::{RegistryQuery, RegistryRead, RegistryWrite};

use crate::error::{code_for_status, flatten, CallSite, ClientError};

/// Header carrying [`ScreenshotMeta`] as JSON next to the image bytes.
pub const SCREENSHOT_META_HEADER: &str = "x-arena-screenshot";
/// Header carrying the lowercase hex SHA-256 of a downloaded file.
pub const SHA256_HEADER: &str = "x-arena-sha256";

/// How long `doctor` may take: the guest gives itself 180 s.
const DOCTOR_DEADLINE: Duration = Duration::from_secs(200);

/// The guest's default `/v1/exec` timeout, used to size the deadline of an
/// exec request that does not set its own.
const GUEST_DEFAULT_EXEC_TIMEOUT: Duration = Duration::from_secs(120);
/// Time on top of a guest-side limit for the guest to notice it, clean up and answer.
const MARGIN: Duration = Duration::from_secs(10);
/// First retry delay; it doubles on every further attempt.
const FIRST_BACKOFF: Duration = Duration::from_millis(100);
/// Longest retry delay.
const MAX_BACKOFF: Duration = Duration::from_secs(2);
/// How much of a non-JSON error body is kept in the message.
const MAX_ERROR_TEXT: usize = 300;
/// Shortest deadline of an evaluation query: the guest may walk an accessibility tree (60 s by default) and click.
const EVAL_QUERY_DEADLINE: Duration = Duration::from_secs(90);

/// How a [`GuestClient`] talks to its guest.
#[derive(Debug, Clone)]
pub struct ClientConfig {
    /// Bearer token sent with every request, when the guest needs one.
    pub token: Option<String>,
    /// Default deadline of one call (one attempt), from connecting to the last byte of the answer.
    pub timeout: Duration,
    /// How many times an idempotent call is retried after a transient failure.
    pub retries: u32,
}

impl Default for ClientConfig {
    fn default() -> ClientConfig {
        ClientConfig { token: None, timeout: Duration::from_secs(30), retries: 3 }
    }
}

/// A screenshot: the encoded image and what it shows.
#[derive(Debug, Clone)]
pub struct Screenshot {
    pub meta: ScreenshotMeta,
    /// PNG or JPEG bytes, as `meta.format` says.
    pub bytes: Vec<u8>,
}

/// A downloaded file whose bytes matched the guest's SHA-256.
#[derive(Debug, Clone)]
pub struct PulledFile {
    pub bytes: Vec<u8>,
    /// Lowercase hex SHA-256 of `bytes`.
    pub sha256: String,
}

/// A window operation of `POST /v1/windows/{op}`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WindowOp {
    Activate,
    Close,
    Minimize,
    Maximize,
    Restore,
}

impl WindowOp {
    fn path(self) -> &'static str {
        match self {
            WindowOp::Activate => "/v1/windows/activate",
            WindowOp::Close => "/v1/windows/close",
            WindowOp::Minimize => "/v1/windows/minimize",
            WindowOp::Maximize => "/v1/windows/maximize",
            WindowOp::Restore => "/v1/windows/restore",
        }
    }
}

/// Whether a request may be sent again after a transient failure.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Retry {
    Idempotent,
    Never,
}

/// A request body that can be sent again on a retry.
#[derive(Debug, Clone)]
enum Payload {
    None,
    Json(Vec<u8>),
    Bytes(Vec<u8>),
}

/// One request, before it is sent.
#[derive(Debug)]
struct Call<'a> {
    method: Method,
    path: &'a str,
    query: Option<Vec<(String, String)>>,
    /// A query string sent as written (the DevTools `/json/new?<url>` takes a whole URL there).
    raw_query: Option<&'a str>,
    payload: Payload,
    deadline: Duration,
    retry: Retry,
}

/// What came back: status, headers and the whole body.
#[derive(Debug)]
struct Answer {
    status: StatusCode,
    headers: HeaderMap,
    body: Vec<u8>,
}

/// Async client of one guest's native API. Cheap to clone; clones share connections.
#[derive(Debug, Clone)]
pub struct GuestClient {
    base: Url,
    /// The base URL as given (without a trailing slash), for messages.
    guest: String,
    http: reqwest::Client,
    config: ClientConfig,
}

impl GuestClient {
    /// A client of the guest at `base_url` (`http://HOST:PORT`).
    ///
    /// # Errors
    ///
    /// [`ClientError::InvalidUrl`] if `base_url` does not parse, is not
    /// `http`, or carries a query or credentials.
    pub fn new(base_url: &str, config: ClientConfig) -> Result<GuestClient, ClientError> {
        let invalid = |reason: &str| ClientError::InvalidUrl { url: base_url.to_owned(), reason: reason.to_owned() };
        let trimmed = base_url.trim().trim_end_matches('/');
        let base = Url::parse(trimmed).map_err(|err| invalid(&err.to_string()))?;
        if base.scheme() != "http" {
            return Err(invalid(
                "only http:// is supported (this client has no TLS; guard the guest with a token on a private network)",
            ));
        }
        if base.host_str().is_none_or(str::is_empty) {
            return Err(invalid("no host"));
        }
        if base.query().is_some() || base.fragment().is_some() {
            return Err(invalid("a base URL takes no query or fragment"));
        }
        if !base.username().is_empty() || base.password().is_some() {
            return Err(invalid("credentials go in the token, not the URL"));
        }
        if config.token.as_deref().is_some_and(|t| t.trim().is_empty() || t.contains(['\r', '\n'])) {
            return Err(invalid("the token is empty or spans lines"));
        }
        // Guests are on a private network: a proxy from the environment would
        // only get between the host and them.
        let http = reqwest::Client::builder()
            .no_proxy()
            .connect_timeout(config.timeout.min(Duration::from_secs(10)))
            .build()
            .map_err(|err| invalid(&flatten(&err)))?;
        Ok(GuestClient { base, guest: trimmed.to_owned(), http, config })
    }

    /// A client of the same guest that opens a new connection for every call:
    /// for a guest in a VM that is restored to snapshots, where a kept
    /// connection belongs to a TCP state the restore has undone.
    ///
    /// # Errors
    ///
    /// [`ClientError::InvalidUrl`] when the HTTP client cannot be built.
    pub fn without_kept_connections(&self) -> Result<GuestClient, ClientError> {
        let http = reqwest::Client::builder()
            .no_proxy()
            .connect_timeout(self.config.timeout.min(Duration::from_secs(10)))
            .pool_max_idle_per_host(0)
            .build()
            .map_err(|err| ClientError::InvalidUrl { url: self.guest.clone(), reason: flatten(&err) })?;
        Ok(GuestClient { http, ..self.clone() })
    }

    /// The guest's base URL as given.
    pub fn base_url(&self) -> &str {
        &self.guest
    }

    /// The client's configuration.
    pub fn config(&self) -> &ClientConfig {
        &self.config
    }

    /// A client of the same guest whose default deadline is `timeout`, for a
    /// few calls known to be slow (a UIA walk of a busy desktop).
    pub fn with_timeout(&self, timeout: Duration) -> GuestClient {
        let mut client = self.clone();
        client.config.timeout = timeout;
        client
    }

    // ----- health -----

    /// `GET /v1/health`: the staged readiness report. Needs no token.
    ///
    /// A `503` whose body is a health report is returned as the report, since
    /// "not ready yet" is an answer, not a failure.
    ///
    /// # Errors
    ///
    /// Any [`ClientError`] of the call.
    pub async fn health(&self) -> Result<HealthReport, ClientError> {
        self.health_with(self.config.timeout, Retry::Idempotent).await
    }

    /// One `GET /v1/health` within `deadline`, never retried: what a command that must
    /// answer promptly asks (a hung guest costs `deadline`, not every retry's).
    ///
    /// # Errors
    ///
    /// As [`GuestClient::health`].
    /// `GET /v1/doctor`: every capability checked end to end on the guest's desktop.
    /// It takes a minute or so (it starts Notepad and waits out a command's timeout),
    /// so it has its own deadline, and it is never retried: it types and clicks.
    pub async fn doctor(&self) -> Result<arena_shared::doctor::DoctorReport, ClientError> {
        let call = Call { deadline: DOCTOR_DEADLINE, retry: Retry::Never, ..self.call(Method::GET, "/v1/doctor") };
        self.json(call).await
    }

    /// `GET /v1/doctor?deep=true`: the doctor, with the heavy applications'
    /// tree timings and input round trips.
    pub async fn doctor_deep(&self) -> Result<arena_shared::doctor::DoctorReport, ClientError> {
        let call = Call {
            deadline: DOCTOR_DEADLINE,
            retry: Retry::Never,
            query: Some(vec![("deep".into(), "true".into())]),
            ..self.call(Method::GET, "/v1/doctor")
        };
        self.json(call).await
    }

    pub async fn health_once(&self, deadline: Duration) -> Result<HealthReport, ClientError> {
        self.health_with(deadline, Retry::Never).await
    }

    async fn health_with(&self, deadline: Duration, retry: Retry) -> Result<HealthReport, ClientError> {
        let call = Call { deadline, retry, ..self.call(Method::GET, "/v1/health") };
        let site = self.site(&call);
        let answer = self.send_raw(call).await?;
        if answer.status == StatusCode::SERVICE_UNAVAILABLE {
            if let Ok(report) = serde_json::from_slice::<HealthReport>(&answer.body) {
                return Ok(report);
            }
        }
        let answer = self.check_status(&site, answer)?;
        decode(&site, &answer.body)
    }

    /// Polls `GET /v1/health` every `poll` until every component in
    /// `components` is up (all of them when the slice is empty), and returns
    /// that report.
    ///
    /// # Errors
    ///
    /// [`ClientError::NotReady`] after `overall`, listing what is still down
    /// and the last error seen; an [`ClientError::Api`] error that says the
    /// token is wrong ends the wait at once, since waiting will not fix it.
    pub async fn wait_ready(
        &self,
        components: &[Component],
        overall: Duration,
        poll: Duration,
    ) -> Result<HealthReport, ClientError> {
        let wanted: Vec<Component> = if components.is_empty() { Component::ALL.to_vec() } else { components.to_vec() };
        let started = Instant::now();
        let mut down: Vec<Component> = Vec::new();
        let mut last_error: Option<String>;
        loop {
            let remaining = overall.saturating_sub(started.elapsed());
            let attempt_deadline = self.config.timeout.min(remaining.max(Duration::from_millis(50)));
            match self.health_with(attempt_deadline, Retry::Never).await {
                Ok(report) => {
                    down = wanted.iter().copied().filter(|c| !report.is_up(*c)).collect();
                    if down.is_empty() {
                        tracing::debug!(guest = %self.guest, elapsed_ms = started.elapsed().as_millis() as u64, "guest ready");
                        return Ok(report);
                    }
                    tracing::debug!(guest = %self.guest, ?down, "guest not ready yet");
                    last_error = None;
                }
                Err(err @ ClientError::Api { status: 401 | 403, .. }) => return Err(err),
                Err(err) => {
                    tracing::debug!(guest = %self.guest, error = %err, "health poll failed");
                    last_error = Some(strip_site(&err));
                }
            }
            let remaining = overall.saturating_sub(started.elapsed());
            if remaining.is_zero() {
                return Err(ClientError::NotReady {
                    guest: self.guest.clone(),
                    waited: started.elapsed(),
                    down,
                    last_error,
                });
            }
            tokio::time::sleep(poll.min(remaining)).await;
        }
    }

    // ----- observation -----

    /// `GET /v1/screen`: size, scale and monitors.
    ///
    /// # Errors
    ///
    /// Any [`ClientError`] of the call.
    pub async fn screen(&self) -> Result<ScreenInfo, ClientError> {
        self.get_json("/v1/screen", None).await
    }

    /// `GET /v1/screenshot`: the encoded image and its [`ScreenshotMeta`].
    ///
    /// # Errors
    ///
    /// Any [`ClientError`] of the call; [`ClientError::Decode`] when the
    /// metadata header is missing or malformed.
    pub async fn screenshot(&self, query: &ScreenshotQuery) -> Result<Screenshot, ClientError> {
        let call = Call { query: Some(to_query(query)), ..self.call(Method::GET, "/v1/screenshot") };
        let site = self.site(&call);
        let answer = self.send(call).await?;
        let meta = header_str(&answer.headers, SCREENSHOT_META_HEADER)
            .ok_or_else(|| decode_error(&site, format!("the {SCREENSHOT_META_HEADER} header is missing")))?;
        let meta: ScreenshotMeta = serde_json::from_str(meta)
            .map_err(|err| decode_error(&site, format!("the {SCREENSHOT_META_HEADER} header: {err}")))?;
        Ok(Screenshot { meta, bytes: answer.body })
    }

    /// `GET /v1/a11y`: the accessibility tree within the query's budget.
    ///
    /// The deadline is the client's, or the walk's own `max_ms` plus a margin when that is longer.
    ///
    /// # Errors
    ///
    /// Any [`ClientError`] of the call.
    pub async fn a11y(&self, query: &A11yQuery) -> Result<A11yTree, ClientError> {
        let budget = query.max_ms.map(|ms| Duration::from_millis(ms) + MARGIN).unwrap_or_default();
        let call = Call {
            query: Some(to_query(query)),
            deadline: self.config.timeout.max(budget),
            ..self.call(Method::GET, "/v1/a11y")
        };
        self.json(call).await
    }

    /// `GET /v1/windows`: top-level windows, topmost first.
    ///
    /// # Errors
    ///
    /// Any [`ClientError`] of the call.
    pub async fn windows(&self) -> Result<Vec<WindowInfo>, ClientError> {
        self.get_json("/v1/windows", None).await
    }

    /// `POST /v1/windows/{op}`: acts on one window and returns its new state. Never retried.
    ///
    /// # Errors
    ///
    /// Any [`ClientError`] of the call; `not_found` when nothing matches `target`.
    pub async fn window(&self, op: WindowOp, target: &WindowTarget) -> Result<WindowInfo, ClientError> {
        let call = Call { payload: json_payload(target), ..self.call(Method::POST, op.path()) };
        self.json(call).await
    }

    /// `POST /v1/windows/activate`.
    ///
    /// # Errors
    ///
    /// See [`GuestClient::window`].
    pub async fn activate_window(&self, target: &WindowTarget) -> Result<WindowInfo, ClientError> {
        self.window(WindowOp::Activate, target).await
    }

    /// `POST /v1/windows/close`.
    ///
    /// # Errors
    ///
    /// See [`GuestClient::window`].
    pub async fn close_window(&self, target: &WindowTarget) -> Result<WindowInfo, ClientError> {
        self.window(WindowOp::Close, target).await
    }

    /// `POST /v1/windows/minimize`.
    ///
    /// # Errors
    ///
    /// See [`GuestClient::window`].
    pub async fn minimize_window(&self, target: &WindowTarget) -> Result<WindowInfo, ClientError> {
        self.window(WindowOp::Minimize, target).await
    }

    /// `POST /v1/windows/maximize`.
    ///
    /// # Errors
    ///
    /// See [`GuestClient::window`].
    pub async fn maximize_window(&self, target: &WindowTarget) -> Result<WindowInfo, ClientError> {
        self.window(WindowOp::Maximize, target).await
    }

    /// `POST /v1/windows/restore`.
    ///
    /// # Errors
    ///
    /// See [`GuestClient::window`].
    pub async fn restore_window(&self, target: &WindowTarget) -> Result<WindowInfo, ClientError> {
        self.window(WindowOp::Restore, target).await
    }

    // ----- input -----

    /// `POST /v1/actions`: performs the batch in order. Never retried.
    ///
    /// The deadline grows by the batch's waits and typing intervals.
    ///
    /// # Errors
    ///
    /// Any [`ClientError`] of the call; `bad_request` for an unknown key name.
    pub async fn act(&self, batch: &ActionBatch) -> Result<ActionReport, ClientError> {
        let call = Call {
            payload: json_payload(batch),
            deadline: self.config.timeout + batch_duration(&batch.actions),
            retry: Retry::Never,
            ..self.call(Method::POST, "/v1/actions")
        };
        self.json(call).await
    }

    /// The screen's size in the coordinate space the guest's input uses (what
    /// pyautogui's `size()` answers there) and where the cursor is: what pyautogui
    /// code is translated against. Two calls: `GET /v1/screen` and an empty
    /// `POST /v1/actions`, which moves nothing and reports the cursor.
    ///
    /// # Errors
    ///
    /// Any [`ClientError`] of the two calls.
    pub async fn pointer(&self) -> Result<((u32, u32), (i32, i32)), ClientError> {
        let screen = self.screen().await?;
        let size = match screen.coordinate_space {
            CoordinateSpace::Logical => (screen.logical_width, screen.logical_height),
            _ => (screen.physical_width, screen.physical_height),
        };
        let report = self.act(&ActionBatch { actions: Vec::new() }).await?;
        Ok((size, (report.cursor.x, report.cursor.y)))
    }

    /// Performs one action; see [`GuestClient::act`].
    ///
    /// # Errors
    ///
    /// See [`GuestClient::act`].
    pub async fn act_one(&self, action: Action) -> Result<ActionReport, ClientError> {
        self.act(&ActionBatch { actions: vec![action] }).await
    }

    // ----- clipboard -----

    /// `GET /v1/clipboard`.
    ///
    /// # Errors
    ///
    /// Any [`ClientError`] of the call.
    pub async fn clipboard_get(&self) -> Result<ClipboardContent, ClientError> {
        self.get_json("/v1/clipboard", None).await
    }

    /// `PUT /v1/clipboard`.
    ///
    /// # Errors
    ///
    /// Any [`ClientError`] of the call.
    pub async fn clipboard_set(&self, content: &ClipboardContent) -> Result<(), ClientError> {
        let call = Call { payload: json_payload(content), ..self.call(Method::PUT, "/v1/clipboard") };
        self.send(call).await.map(drop)
    }

    // ----- files -----

    /// `GET /v1/files`: downloads a guest file and checks it against the
    /// guest's `x-arena-sha256`.
    ///
    /// # Errors
    ///
    /// Any [`ClientError`] of the call; [`ClientError::Integrity`] when the
    /// bytes do not hash to the header, [`ClientError::Decode`] when it is missing.
    pub async fn pull_file(&self, path: &str) -> Result<PulledFile, ClientError> {
        let call = Call { query: Some(vec![("path".into(), path.to_owned())]), ..self.call(Method::GET, "/v1/files") };
        let site = self.site(&call);
        let answer = self.send(call).await?;
        let expected = header_str(&answer.headers, SHA256_HEADER)
            .ok_or_else(|| decode_error(&site, format!("the {SHA256_HEADER} header is missing")))?
            .trim()
            .to_ascii_lowercase();
        let actual = sha256_hex(&answer.body);
        if expected != actual {
            return Err(ClientError::Integrity { call: site, expected, actual });
        }
        Ok(PulledFile { bytes: answer.body, sha256: actual })
    }

    /// `PUT /v1/files`: uploads `bytes` to `path`, sending their SHA-256 so the
    /// guest refuses a corrupted body, and checks the hash the guest reports.
    /// `create_parents` defaults to true on the guest.
    ///
    /// # Errors
    ///
    /// Any [`ClientError`] of the call; [`ClientError::Integrity`] when the
    /// guest reports a different hash.
    pub async fn push_file(
        &self,
        path: &str,
        bytes: Vec<u8>,
        create_parents: Option<bool>,
    ) -> Result<FileWritten, ClientError> {
        let sha256 = sha256_hex(&bytes);
        let query = WriteQuery { path: path.to_owned(), create_parents, sha256: Some(sha256.clone()) };
        // An upload may be large: give it at least the default deadline plus a
        // second per 4 MiB, which a slow virtual network still manages.
        let transfer = Duration::from_secs((bytes.len() as u64) >> 22);
        let call = Call {
            query: Some(to_query(&query)),
            payload: Payload::Bytes(bytes),
            deadline: self.config.timeout + transfer,
            ..self.call(Method::PUT, "/v1/files")
        };
        let site = self.site(&call);
        let written: FileWritten = self.json(call).await?;
        if !written.sha256.eq_ignore_ascii_case(&sha256) {
            return Err(ClientError::Integrity { call: site, expected: sha256, actual: written.sha256 });
        }
        Ok(written)
    }

    /// `GET /v1/files/stat`.
    ///
    /// # Errors
    ///
    /// Any [`ClientError`] of the call; `not_found` for a missing path.
    pub async fn stat(&self, path: &str) -> Result<FileStat, ClientError> {
        self.get_json("/v1/files/stat", Some(path_query(path))).await
    }

    /// `GET /v1/files/exists`.
    ///
    /// # Errors
    ///
    /// Any [`ClientError`] of the call.
    pub async fn exists(&self, path: &str) -> Result<Exists, ClientError> {
        self.get_json("/v1/files/exists", Some(path_query(path))).await
    }

    /// `GET /v1/files/list`: the entries of a guest directory.
    ///
    /// # Errors
    ///
    /// Any [`ClientError`] of the call.
    pub async fn list_dir(&self, path: &str) -> Result<DirListing, ClientError> {
        self.get_json("/v1/files/list", Some(path_query(path))).await
    }

    /// `DELETE /v1/files`: removes a file, or a directory (with its contents when `recursive`).
    /// Not retried: a retry after a lost answer would report `not_found` for a delete that worked.
    ///
    /// # Errors
    ///
    /// Any [`ClientError`] of the call.
    pub async fn delete(&self, path: &str, recursive: bool) -> Result<(), ClientError> {
        let query = PathQuery { path: path.to_owned(), recursive };
        let call =
            Call { query: Some(to_query(&query)), retry: Retry::Never, ..self.call(Method::DELETE, "/v1/files") };
        self.send(call).await.map(drop)
    }

    /// `POST /v1/files/mkdir`: creates a directory and its parents.
    ///
    /// # Errors
    ///
    /// Any [`ClientError`] of the call.
    pub async fn mkdir(&self, path: &str) -> Result<(), ClientError> {
        let call = Call {
            payload: json_payload(&MkdirRequest { path: path.to_owned() }),
            retry: Retry::Never,
            ..self.call(Method::POST, "/v1/files/mkdir")
        };
        self.send(call).await.map(drop)
    }

    /// `POST /v1/files/recycle`: moves a path to the recycle bin.
    ///
    /// # Errors
    ///
    /// Any [`ClientError`] of the call.
    pub async fn recycle(&self, path: &str) -> Result<(), ClientError> {
        let call = Call {
            payload: json_payload(&PathQuery { path: path.to_owned(), recursive: false }),
            retry: Retry::Never,
            ..self.call(Method::POST, "/v1/files/recycle")
        };
        self.send(call).await.map(drop)
    }

    /// `GET /v1/folders`: the guest paths of the well-known folders.
    ///
    /// # Errors
    ///
    /// Any [`ClientError`] of the call.
    pub async fn folders(&self) -> Result<KnownFolders, ClientError> {
        self.get_json("/v1/folders", None).await
    }

    // ----- programs -----

    /// `POST /v1/exec`: runs a program to completion. Never retried.
    ///
    /// The deadline is the request's own timeout (or the guest's default, 120 s) plus a margin.
    ///
    /// # Errors
    ///
    /// Any [`ClientError`] of the call. A program that fails is not an error:
    /// read `exit_code` and `timed_out`.
    pub async fn exec(&self, request: &ExecRequest) -> Result<ExecResult, ClientError> {
        let limit = request.timeout_ms.map(Duration::from_millis).unwrap_or(GUEST_DEFAULT_EXEC_TIMEOUT);
        let call = Call {
            payload: json_payload(request),
            deadline: self.config.timeout.max(limit + MARGIN),
            retry: Retry::Never,
            ..self.call(Method::POST, "/v1/exec")
        };
        self.json(call).await
    }

    /// `POST /v1/launch`: starts a program without waiting for it. Never retried.
    ///
    /// # Errors
    ///
    /// Any [`ClientError`] of the call.
    pub async fn launch(&self, request: &LaunchRequest) -> Result<LaunchResult, ClientError> {
        let call =
            Call { payload: json_payload(request), retry: Retry::Never, ..self.call(Method::POST, "/v1/launch") };
        self.json(call).await
    }

    /// `POST /v1/open`: opens a path with its associated program. Never retried.
    ///
    /// # Errors
    ///
    /// Any [`ClientError`] of the call.
    pub async fn open(&self, path: &str) -> Result<(), ClientError> {
        let call = Call {
            payload: json_payload(&PathQuery { path: path.to_owned(), recursive: false }),
            retry: Retry::Never,
            ..self.call(Method::POST, "/v1/open")
        };
        self.send(call).await.map(drop)
    }

    // ----- registry -----

    /// `GET /v1/registry`: reads `value` of `key` (the default value when `None`).
    ///
    /// # Errors
    ///
    /// Any [`ClientError`] of the call; `not_found` for a missing key or value.
    pub async fn registry_get(&self, key: &str, value: Option<&str>) -> Result<RegistryRead, ClientError> {
        let query = RegistryQuery { key: key.to_owned(), value: value.map(str::to_owned) };
        self.get_json("/v1/registry", Some(to_query(&query))).await
    }

    /// `PUT /v1/registry`: writes a value.
    ///
    /// # Errors
    ///
    /// Any [`ClientError`] of the call.
    pub async fn registry_set(&self, write: &RegistryWrite) -> Result<(), ClientError> {
        let call = Call { payload: json_payload(write), ..self.call(Method::PUT, "/v1/registry") };
        self.send(call).await.map(drop)
    }

    /// `GET /v1/clock`: the guest's wall clock.
    ///
    /// # Errors
    ///
    /// Any [`ClientError`] of the call.
    pub async fn clock(&self) -> Result<ClockReading, ClientError> {
        self.get_json("/v1/clock", None).await
    }

    /// `PUT /v1/clock`: sets the guest's wall clock to `unix_ms` (milliseconds
    /// since the Unix epoch, UTC). Never retried: a retry would set a stale time.
    ///
    /// # Errors
    ///
    /// Any [`ClientError`] of the call; `bad_request` for a time outside
    /// [`arena_shared::clock::check`]'s range.
    pub async fn set_clock(&self, unix_ms: i64) -> Result<ClockSetResult, ClientError> {
        let call = Call {
            payload: json_payload(&ClockSet { unix_ms }),
            retry: Retry::Never,
            ..self.call(Method::PUT, "/v1/clock")
        };
        self.json(call).await
    }

    /// `PUT /v1/wallpaper`: sets the wallpaper to an existing guest image.
    ///
    /// # Errors
    ///
    /// Any [`ClientError`] of the call; `not_found` for a missing file.
    pub async fn set_wallpaper(&self, path: &str) -> Result<(), ClientError> {
        let call = Call {
            payload: json_payload(&PathQuery { path: path.to_owned(), recursive: false }),
            ..self.call(Method::PUT, "/v1/wallpaper")
        };
        self.send(call).await.map(drop)
    }

    // ----- evaluation queries -----

    /// `POST /v1/eval/is_details_view`: whether the foreground File Explorer window shows Details view.
    ///
    /// # Errors
    ///
    /// Any [`ClientError`] of the call.
    pub async fn eval_is_details_view(&self, query: &DetailsViewQuery) -> Result<EvalAnswer, ClientError> {
        self.eval_query("/v1/eval/is_details_view", query).await
    }

    /// `POST /v1/eval/are_files_sorted_by_modified_time`.
    ///
    /// # Errors
    ///
    /// Any [`ClientError`] of the call.
    pub async fn eval_files_sorted_by_modified(
        &self,
        query: &SortedByModifiedQuery,
    ) -> Result<EvalAnswer, ClientError> {
        self.eval_query("/v1/eval/are_files_sorted_by_modified_time", query).await
    }

    /// `POST /v1/eval/check_if_timer_started`: may click the Clock app's "Maximize Clock" button first.
    ///
    /// # Errors
    ///
    /// Any [`ClientError`] of the call.
    pub async fn eval_timer_started(&self, query: &TimerQuery) -> Result<EvalAnswer, ClientError> {
        self.eval_query("/v1/eval/check_if_timer_started", query).await
    }

    /// `POST /v1/eval/check_if_world_clock_exists`: may click "Maximize Clock" first.
    ///
    /// # Errors
    ///
    /// Any [`ClientError`] of the call.
    pub async fn eval_world_clock_exists(&self, query: &WorldClockQuery) -> Result<EvalAnswer, ClientError> {
        self.eval_query("/v1/eval/check_if_world_clock_exists", query).await
    }

    /// `POST /v1/eval/is_directory_read_only_for_user`.
    ///
    /// # Errors
    ///
    /// Any [`ClientError`] of the call; `not_found` for a missing directory.
    pub async fn eval_read_only_for_user(&self, query: &ReadOnlyQuery) -> Result<EvalAnswer, ClientError> {
        self.eval_query("/v1/eval/is_directory_read_only_for_user", query).await
    }

    /// `POST /v1/eval/are_all_images_tagged`.
    ///
    /// # Errors
    ///
    /// Any [`ClientError`] of the call; `not_found` for a missing directory.
    pub async fn eval_images_tagged(&self, query: &ImagesTaggedQuery) -> Result<EvalAnswer, ClientError> {
        self.eval_query("/v1/eval/are_all_images_tagged", query).await
    }

    /// `POST /v1/eval/library_folders`: the folders of a Windows library.
    ///
    /// # Errors
    ///
    /// Any [`ClientError`] of the call.
    pub async fn eval_library_folders(&self, query: &LibraryQuery) -> Result<LibraryFolders, ClientError> {
        self.eval_query("/v1/eval/library_folders", query).await
    }

    /// One evaluation query. Not retried: the Clock queries may click, and a
    /// second click would undo the first.
    async fn eval_query<Q: Serialize, A: DeserializeOwned>(&self, path: &str, query: &Q) -> Result<A, ClientError> {
        let call = Call {
            payload: json_payload(query),
            deadline: self.config.timeout.max(EVAL_QUERY_DEADLINE),
            retry: Retry::Never,
            ..self.call(Method::POST, path)
        };
        self.json(call).await
    }

    // ----- browser -----

    /// `GET /v1/browser/{path}`: a GET of the browser's DevTools HTTP endpoint
    /// inside the guest (`json/version`, `json/list`), forwarded by the guest.
    /// `path` may carry a query (`json/new?https://example.com`), sent as written.
    /// Answers the browser's body.
    ///
    /// # Errors
    ///
    /// Any [`ClientError`] of the call; a `502` when no browser listens on the
    /// guest's debugging port, the browser's own status otherwise.
    pub async fn browser_get(&self, path: &str) -> Result<Vec<u8>, ClientError> {
        self.browser(Method::GET, path, Retry::Idempotent).await
    }

    /// `PUT /v1/browser/{path}`: a PUT of the browser's DevTools HTTP endpoint
    /// (`json/new?<url>` opens a tab). Never retried: a retry after a lost answer
    /// would open the tab twice.
    ///
    /// # Errors
    ///
    /// See [`GuestClient::browser_get`].
    pub async fn browser_put(&self, path: &str) -> Result<Vec<u8>, ClientError> {
        self.browser(Method::PUT, path, Retry::Never).await
    }

    async fn browser(&self, method: Method, path: &str, retry: Retry) -> Result<Vec<u8>, ClientError> {
        let (path, query) = match path.split_once('?') {
            Some((path, query)) => (path, Some(query)),
            None => (path, None),
        };
        let route = format!("/v1/browser/{}", path.trim_start_matches('/'));
        let call = Call { raw_query: query, retry, ..self.call(method, &route) };
        self.send(call).await.map(|answer| answer.body)
    }

    // ----- plumbing -----

    /// A call with the defaults: no query, no body, the default deadline, and
    /// retries for the idempotent methods.
    fn call<'a>(&self, method: Method, path: &'a str) -> Call<'a> {
        let retry = if method == Method::GET || method == Method::PUT { Retry::Idempotent } else { Retry::Never };
        Call {
            method,
            path,
            query: None,
            raw_query: None,
            payload: Payload::None,
            deadline: self.config.timeout,
            retry,
        }
    }

    fn site(&self, call: &Call<'_>) -> CallSite {
        CallSite { guest: self.guest.clone(), method: method_name(&call.method), path: call.path.to_owned() }
    }

    async fn get_json<T: DeserializeOwned>(
        &self,
        path: &str,
        query: Option<Vec<(String, String)>>,
    ) -> Result<T, ClientError> {
        let call = Call { query, ..self.call(Method::GET, path) };
        self.json(call).await
    }

    async fn json<T: DeserializeOwned>(&self, call: Call<'_>) -> Result<T, ClientError> {
        let site = self.site(&call);
        let answer = self.send(call).await?;
        decode(&site, &answer.body)
    }

    /// Sends with retries and turns a non-2xx answer into [`ClientError::Api`].
    async fn send(&self, call: Call<'_>) -> Result<Answer, ClientError> {
        let site = self.site(&call);
        let answer = self.send_raw(call).await?;
        self.check_status(&site, answer)
    }

    fn check_status(&self, site: &CallSite, answer: Answer) -> Result<Answer, ClientError> {
        if answer.status.is_success() {
            Ok(answer)
        } else {
            Err(api_error(site, answer.status, &answer.body))
        }
    }

    /// Sends `call`, retrying transient failures of idempotent calls; returns
    /// any answer that is not a gateway error, whatever its status.
    async fn send_raw(&self, call: Call<'_>) -> Result<Answer, ClientError> {
        let site = self.site(&call);
        let attempts = match call.retry {
            Retry::Idempotent => self.config.retries + 1,
            Retry::Never => 1,
        };
        let mut attempt = 0;
        loop {
            attempt += 1;
            let result = self.attempt(&site, &call).await;
            let transient = match &result {
                Ok(answer) => matches!(answer.status.as_u16(), 502..=504),
                Err(err) => err.is_transient(),
            };
            if !transient || attempt >= attempts {
                return result;
            }
            let delay = backoff(attempt);
            match &result {
                Ok(answer) => {
                    tracing::debug!(call = %site, status = answer.status.as_u16(), attempt, delay_ms = delay.as_millis() as u64, "retrying")
                }
                Err(err) => {
                    tracing::debug!(call = %site, error = %err, attempt, delay_ms = delay.as_millis() as u64, "retrying")
                }
            }
            tokio::time::sleep(delay).await;
        }
    }

    /// One attempt: send, then read the whole body, all within the deadline.
    async fn attempt(&self, site: &CallSite, call: &Call<'_>) -> Result<Answer, ClientError> {
        let mut url = self.url(site, call.path)?;
        if let Some(raw) = call.raw_query {
            url.set_query(Some(raw));
        }
        let mut request = self.http.request(call.method.clone(), url);
        if let Some(query) = &call.query {
            request = request.query(query);
        }
        if let Some(token) = &self.config.token {
            request = request.bearer_auth(token.trim());
        }
        request = match &call.payload {
            Payload::None => request,
            Payload::Json(body) => request.header(CONTENT_TYPE, "application/json").body(body.clone()),
            Payload::Bytes(body) => request.header(CONTENT_TYPE, "application/octet-stream").body(body.clone()),
        };
        let exchange = async {
            let response = request.send().await.map_err(|err| transport_error(site, &err, call.deadline))?;
            let status = response.status();
            let headers = response.headers().clone();
            let body = response.bytes().await.map_err(|err| transport_error(site, &err, call.deadline))?;
            Ok(Answer { status, headers, body: body.to_vec() })
        };
        match tokio::time::timeout(call.deadline, exchange).await {
            Ok(result) => result,
            Err(_) => Err(ClientError::Timeout { call: site.clone(), after: call.deadline }),
        }
    }

    fn url(&self, site: &CallSite, path: &str) -> Result<Url, ClientError> {
        let mut url = self.base.clone();
        // Keep a path prefix of the base URL (a guest behind a reverse proxy at `/vm3`).
        let prefix = url.path().trim_end_matches('/').to_owned();
        url.set_path(&format!("{prefix}{path}"));
        if url.cannot_be_a_base() {
            return Err(ClientError::InvalidUrl { url: site.guest.clone(), reason: "not a base URL".into() });
        }
        Ok(url)
    }
}

fn method_name(method: &Method) -> &'static str {
    match *method {
        Method::GET => "GET",
        Method::PUT => "PUT",
        Method::POST => "POST",
        Method::DELETE => "DELETE",
        Method::HEAD => "HEAD",
        Method::PATCH => "PATCH",
        _ => "OTHER",
    }
}

/// How long a batch keeps the guest busy on purpose.
fn batch_duration(actions: &[Action]) -> Duration {
    let ms: u64 = actions
        .iter()
        .map(|action| match action {
            Action::Wait { ms } => *ms,
            Action::TypeText { text, interval_ms: Some(interval) } => {
                interval.saturating_mul(text.chars().count() as u64)
            }
            _ => 0,
        })
        .fold(0u64, u64::saturating_add);
    Duration::from_millis(ms)
}

/// The retry delay after `attempt` failed attempts: 100 ms doubling, capped,
/// with up to a quarter added at random so parallel hosts do not retry in step.
fn backoff(attempt: u32) -> Duration {
    let base = FIRST_BACKOFF.saturating_mul(1 << attempt.saturating_sub(1).min(8)).min(MAX_BACKOFF);
    let quarter = (base.as_millis() as u64 / 4).max(1);
    let random = std::collections::hash_map::RandomState::new().build_hasher().finish();
    base + Duration::from_millis(random % quarter)
}

fn transport_error(site: &CallSite, err: &reqwest::Error, deadline: Duration) -> ClientError {
    if err.is_timeout() {
        ClientError::Timeout { call: site.clone(), after: deadline }
    } else if err.is_connect() {
        ClientError::Connect { call: site.clone(), reason: innermost(err) }
    } else if err.is_builder() {
        ClientError::InvalidUrl { url: site.guest.clone(), reason: flatten(err) }
    } else {
        ClientError::Io { call: site.clone(), reason: innermost(err) }
    }
}

/// The deepest cause of a reqwest error: the one line that says what happened
/// ("Connection refused (os error 111)"), without the URL the call site names already.
fn innermost(err: &reqwest::Error) -> String {
    let mut current: &(dyn std::error::Error + 'static) = err;
    while let Some(source) = current.source() {
        current = source;
    }
    current.to_string()
}

fn api_error(site: &CallSite, status: StatusCode, body: &[u8]) -> ClientError {
    let (code, message) = match serde_json::from_slice::<ErrorBody>(body) {
        Ok(parsed) => (parsed.error, parsed.message),
        Err(_) => {
            let text = String::from_utf8_lossy(body);
            let text = text.trim();
            let message = if text.is_empty() {
                status.canonical_reason().unwrap_or("no message").to_owned()
            } else {
                truncate(text, MAX_ERROR_TEXT)
            };
            (code_for_status(status.as_u16()), message)
        }
    };
    ClientError::Api { call: site.clone(), status: status.as_u16(), code, message }
}

fn decode<T: DeserializeOwned>(site: &CallSite, body: &[u8]) -> Result<T, ClientError> {
    serde_json::from_slice(body).map_err(|err| {
        let text = String::from_utf8_lossy(body);
        decode_error(site, format!("{err} (body: {})", truncate(text.trim(), 120)))
    })
}

fn decode_error(site: &CallSite, reason: String) -> ClientError {
    ClientError::Decode { call: site.clone(), reason }
}

fn truncate(text: &str, max: usize) -> String {
    if text.len() <= max {
        return text.to_owned();
    }
    let mut end = max;
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    format!("{}...", &text[..end])
}

fn header_str<'h>(headers: &'h HeaderMap, name: &str) -> Option<&'h str> {
    headers.get(name).and_then(|v| v.to_str().ok())
}

fn json_payload<T: Serialize + ?Sized>(value: &T) -> Payload {
    // Serialising our own wire types cannot fail (no maps with non-string
    // keys, no failing Serialize impls); an empty body would be refused by the
    // guest with a clear message if it ever did.
    Payload::Json(serde_json::to_vec(value).unwrap_or_default())
}

/// Flattens a query struct into pairs through JSON, so `Option`s that are
/// `None` are left out and enums use their wire names.
fn to_query<T: Serialize>(value: &T) -> Vec<(String, String)> {
    let Ok(serde_json::Value::Object(map)) = serde_json::to_value(value) else {
        return Vec::new();
    };
    map.into_iter()
        .filter_map(|(key, value)| match value {
            serde_json::Value::Null => None,
            serde_json::Value::String(s) => Some((key, s)),
            other => Some((key, other.to_string())),
        })
        .collect()
}

fn path_query(path: &str) -> Vec<(String, String)> {
    vec![("path".to_owned(), path.to_owned())]
}

/// The message of an error without its "guest URL: METHOD path: " prefix,
/// for a summary that names the guest once.
fn strip_site(err: &ClientError) -> String {
    let text = err.to_string();
    match err.call() {
        Some(site) => text.strip_prefix(&format!("{site}: ")).map(str::to_owned).unwrap_or(text),
        None => text,
    }
}

/// Lowercase hex SHA-256 of `bytes`.
pub fn sha256_hex(bytes: &[u8]) -> String {
    hex::encode(Sha256::digest(bytes))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn backoff_doubles_with_bounded_jitter() {
        for (attempt, base_ms) in [(1u32, 100u64), (2, 200), (3, 400), (5, 1600), (6, 2000), (30, 2000)] {
            let delay = backoff(attempt).as_millis() as u64;
            assert!(delay >= base_ms && delay < base_ms + base_ms / 4 + 1, "attempt {attempt}: {delay} ms");
        }
    }

    #[test]
    fn queries_leave_out_absent_fields_and_use_wire_names() {
        let query = ScreenshotQuery {
            format: arena_shared::observation::ImageFormat::Jpeg,
            quality: Some(80),
            max_side: None,
            cursor: Some(false),
        };
        let mut pairs = to_query(&query);
        pairs.sort();
        let expected: Vec<(String, String)> = [("cursor", "false"), ("format", "jpeg"), ("quality", "80")]
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
        assert_eq!(pairs, expected);
    }

    #[test]
    fn batch_deadline_grows_by_waits_and_typing() {
        let actions = vec![
            Action::Wait { ms: 500 },
            Action::TypeText { text: "abcd".into(), interval_ms: Some(100) },
            Action::KeyPress { key: "enter".into(), presses: 1 },
        ];
        assert_eq!(batch_duration(&actions), Duration::from_millis(900));
    }

    #[test]
    fn invalid_base_urls_are_refused_with_a_reason() {
        for url in ["not a url", "https://g:5000", "http://user:pw@g:5000", "http://g:5000/?x=1", "ftp://g"] {
            let err = GuestClient::new(url, ClientConfig::default()).expect_err(url);
            assert!(matches!(err, ClientError::InvalidUrl { .. }), "{url}: {err}");
            assert!(err.to_string().contains(url.trim()), "{url}: {err}");
        }
        let client = GuestClient::new("http://127.0.0.1:5000/", ClientConfig::default()).unwrap();
        assert_eq!(client.base_url(), "http://127.0.0.1:5000");
    }

    #[test]
    fn non_json_error_bodies_keep_status_and_text() {
        let site = CallSite { guest: "http://g".into(), method: "GET", path: "/v1/screen".into() };
        let err = api_error(&site, StatusCode::BAD_GATEWAY, b"<html>upstream down</html>");
        assert_eq!(err.to_string(), "guest http://g: GET /v1/screen: HTTP 502 internal: <html>upstream down</html>");
        let err = api_error(&site, StatusCode::NOT_FOUND, b"");
        assert_eq!(err.to_string(), "guest http://g: GET /v1/screen: HTTP 404 not_found: Not Found");
        let err = api_error(&site, StatusCode::CONFLICT, br#"{"error":"conflict","message":"hash mismatch"}"#);
        assert_eq!(err.code(), Some(arena_shared::error::ErrorCode::Conflict));
        assert_eq!(err.status(), Some(409));
    }
}
