//! Bounded MCP sessions, for both servers: rmcp's [`LocalSessionManager`] keeps every
//! session until its keep-alive passes (300 s by default), so a client that only
//! sends `initialize` grows a server by tens of KiB a call without end.
//! [`BoundedSessions`] wraps it with four rules:
//!
//! - **a cap**: at most [`SessionLimits::max_sessions`] open; a new session first
//!   closes the one idle longest (no call running), and when every open session has a
//!   call running the new one is refused, saying so;
//! - **idle expiry**: a session with no call running and none for
//!   [`SessionLimits::idle`] is closed (a sweeper checks a few times per period), and
//!   its next request gets rmcp's 404, on which the MCP specification has a client
//!   start a new session;
//! - **a hung-up call is cancelled**: when the HTTP response of a request is dropped
//!   before its answer went out (the client closed the connection), the session is sent
//!   the `notifications/cancelled` the client did not send, so rmcp cancels the
//!   request's token and [`crate::Server`] drops the tool's future, which stops its work
//!   (the guest's interpreter through its cancel flag).
//!
//! - **a lost stream closes the session**: a client that opened the session's standalone
//!   stream (the GET that the official SDKs hold open) and then lost it, with no other
//!   request for [`STREAM_GRACE`] after, has gone away (a crashed process, a dropped
//!   network): its session is closed then rather than after the idle period, so what it
//!   held (the host's `--agent mcp` episode) is let go within seconds. A client that
//!   never opens that stream is judged by the idle rule alone.
//!
//! rmcp's own idle timer is off: it counts time since the session's last message, so it
//! would close a session in the middle of a long call; the sweeper here counts only
//! time with no call running.
//!
//! Every session opening and closing, and every stream lost, is a tracing event and, for
//! a caller that asks ([`BoundedSessions::with_events`]), a [`SessionEvent`].

use std::collections::HashMap;
use std::pin::Pin;
use std::sync::{Arc, Mutex, PoisonError, Weak};
use std::task::{Context, Poll};
use std::time::Duration;

// Tokio's clock, which tests can pause and advance.
use tokio::time::Instant;

use rmcp::model::{
    CancelledNotification, CancelledNotificationParam, ClientJsonRpcMessage, ClientNotification, JsonRpcMessage,
    RequestId, ServerJsonRpcMessage,
};
use rmcp::transport::common::server_side_http::ServerSseMessage;
use rmcp::transport::streamable_http_server::session::local::{LocalSessionManager, LocalSessionManagerError};
use rmcp::transport::streamable_http_server::{SessionId, SessionManager};
use rmcp::transport::WorkerTransport;

/// How many sessions may be open and how long one may sit idle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SessionLimits {
    /// Most sessions open at once.
    pub max_sessions: usize,
    /// A session with no call running for this long is closed.
    pub idle: Duration,
}

impl SessionLimits {
    /// The defaults both servers document: 64 sessions, closed after 2 minutes idle.
    pub const DEFAULT: SessionLimits = SessionLimits { max_sessions: 64, idle: Duration::from_secs(120) };
}

impl Default for SessionLimits {
    fn default() -> SessionLimits {
        SessionLimits::DEFAULT
    }
}

/// How long a session whose standalone stream ended may stay without a request or a
/// new stream before it is closed as gone.
pub const STREAM_GRACE: Duration = Duration::from_secs(3);

/// What happened to a session, for a caller that shows it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SessionEvent {
    /// A session opened.
    Opened(SessionId),
    /// A session's standalone stream ended; it is closed after [`STREAM_GRACE`]
    /// unless the client comes back.
    StreamLost(SessionId),
    /// A session closed, and why.
    Closed { id: SessionId, why: CloseReason },
}

/// Why a session closed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CloseReason {
    /// The client ended it (`DELETE`).
    Client,
    /// No call for [`SessionLimits::idle`].
    Idle,
    /// The cap was reached and it was the one idle longest.
    Cap,
    /// Its stream ended and nothing came back within [`STREAM_GRACE`].
    StreamLost,
}

impl std::fmt::Display for CloseReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            CloseReason::Client => "by the client",
            CloseReason::Idle => "idle too long",
            CloseReason::Cap => "to make room under the session cap",
            CloseReason::StreamLost => "its stream ended and the client did not come back",
        })
    }
}

/// Who is told of [`SessionEvent`]s.
pub type SessionEvents = Arc<dyn Fn(SessionEvent) + Send + Sync>;

/// What the manager knows of one open session.
#[derive(Debug, Clone, Copy)]
struct Activity {
    /// When a call last started or ended (or the session opened).
    last: Instant,
    /// Calls whose answer stream is open now.
    running: usize,
    /// Standalone streams open now.
    streams: usize,
    /// When the last standalone stream ended, if none is open and nothing came since.
    lost: Option<Instant>,
}

impl Activity {
    fn new() -> Activity {
        Activity { last: Instant::now(), running: 0, streams: 0, lost: None }
    }

    /// Its stream ended at least [`STREAM_GRACE`] ago, nothing came from the client
    /// since (which clears `lost`), and no call runs.
    fn gone(&self) -> bool {
        self.running == 0 && self.streams == 0 && self.lost.is_some_and(|lost| lost.elapsed() >= STREAM_GRACE)
    }
}

/// Why a session could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum SessionsError {
    /// Every one of the open sessions has a call running.
    #[error("{0} MCP sessions are open, the most this server keeps, and every one has a call running; try again when one ends")]
    Full(usize),
    /// rmcp's own session manager failed.
    #[error(transparent)]
    Local(#[from] LocalSessionManagerError),
}

/// rmcp's [`LocalSessionManager`] with a cap, idle expiry, hung-up calls cancelled and
/// sessions that lost their stream closed (see the module documentation).
pub struct BoundedSessions {
    inner: LocalSessionManager,
    limits: SessionLimits,
    open: Mutex<HashMap<SessionId, Activity>>,
    sweeping: std::sync::atomic::AtomicBool,
    me: Weak<BoundedSessions>,
    events: Option<SessionEvents>,
    /// Sessions refused since the last warning, and when that was: a client that
    /// keeps asking while every session is busy gets one line per
    /// [`REFUSAL_WARNING_EVERY`], not one per request.
    refusals: Mutex<(u64, Option<tokio::time::Instant>)>,
}

/// How often refused sessions are reported in the log (with their count).
pub const REFUSAL_WARNING_EVERY: Duration = Duration::from_secs(10);

impl std::fmt::Debug for BoundedSessions {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BoundedSessions").field("limits", &self.limits).finish_non_exhaustive()
    }
}

impl BoundedSessions {
    /// A manager enforcing `limits`.
    pub fn new(limits: SessionLimits) -> Arc<BoundedSessions> {
        Self::build(limits, None)
    }

    /// A manager enforcing `limits` that tells `events` of every session opened, closed
    /// or left without its stream.
    pub fn with_events(limits: SessionLimits, events: SessionEvents) -> Arc<BoundedSessions> {
        Self::build(limits, Some(events))
    }

    fn build(limits: SessionLimits, events: Option<SessionEvents>) -> Arc<BoundedSessions> {
        let mut inner = LocalSessionManager::default();
        // Idle time is this manager's to count (calls running do not count as idle).
        inner.session_config.keep_alive = None;
        let limits = SessionLimits { max_sessions: limits.max_sessions.max(1), idle: limits.idle };
        Arc::new_cyclic(|me| BoundedSessions {
            inner,
            limits,
            open: Mutex::new(HashMap::new()),
            sweeping: std::sync::atomic::AtomicBool::new(false),
            me: me.clone(),
            events,
            refusals: Mutex::new((0, None)),
        })
    }

    /// Counts a refused session, and warns of the refusals when the last warning is
    /// [`REFUSAL_WARNING_EVERY`] old.
    fn refused(&self) {
        let now = tokio::time::Instant::now();
        let mut refusals = self.refusals.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        refusals.0 += 1;
        if refusals.1.is_none_or(|last| now.duration_since(last) >= REFUSAL_WARNING_EVERY) {
            tracing::warn!(
                refused = refusals.0,
                max_sessions = self.limits.max_sessions,
                "new MCP sessions refused (503): every open session has a call running"
            );
            *refusals = (0, Some(now));
        }
    }

    fn tell(&self, event: SessionEvent) {
        match &event {
            SessionEvent::Opened(id) => tracing::info!(session = %id, "MCP session opened"),
            SessionEvent::StreamLost(id) => {
                tracing::info!(session = %id, grace_secs = STREAM_GRACE.as_secs(), "an MCP session's stream ended")
            }
            SessionEvent::Closed { id, why } => tracing::info!(session = %id, %why, "MCP session closed"),
        }
        if let Some(events) = &self.events {
            events(event);
        }
    }

    /// Closes session `id` for `why`, telling it once.
    async fn close_for(&self, id: &SessionId, why: CloseReason) -> Result<(), SessionsError> {
        let was_open = self.table().remove(id).is_some();
        let closed = self.inner.close_session(id).await;
        if was_open {
            self.tell(SessionEvent::Closed { id: id.clone(), why });
        }
        Ok(closed?)
    }

    /// A standalone stream of session `id` opened (`true`) or ended (`false`).
    fn stream(&self, id: &SessionId, opened: bool) {
        let lost = {
            let mut table = self.table();
            let Some(activity) = table.get_mut(id) else { return };
            if opened {
                activity.streams += 1;
                activity.lost = None;
                false
            } else {
                activity.streams = activity.streams.saturating_sub(1);
                if activity.streams == 0 {
                    activity.lost = Some(Instant::now());
                }
                activity.streams == 0
            }
        };
        if !lost {
            return;
        }
        self.tell(SessionEvent::StreamLost(id.clone()));
        let (me, id) = (self.me.clone(), id.clone());
        if let Ok(runtime) = tokio::runtime::Handle::try_current() {
            runtime.spawn(async move {
                tokio::time::sleep(STREAM_GRACE).await;
                let Some(sessions) = me.upgrade() else { return };
                if sessions.gone(&id) {
                    let _ = sessions.close_for(&id, CloseReason::StreamLost).await;
                }
            });
        }
    }

    /// Whether session `id` lost its stream at least [`STREAM_GRACE`] ago with
    /// nothing from its client since.
    fn gone(&self, id: &SessionId) -> bool {
        self.table().get(id).is_some_and(Activity::gone)
    }

    /// The limits in force.
    pub fn limits(&self) -> SessionLimits {
        self.limits
    }

    /// How many sessions are open now.
    pub fn open_sessions(&self) -> usize {
        self.table().len()
    }

    fn table(&self) -> std::sync::MutexGuard<'_, HashMap<SessionId, Activity>> {
        self.open.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Marks a call of session `id` started (`delta` 1) or ended (`delta` -1).
    fn call(&self, id: &SessionId, started: bool) {
        if let Some(activity) = self.table().get_mut(id) {
            activity.last = Instant::now();
            if started {
                activity.lost = None;
            }
            activity.running = if started { activity.running + 1 } else { activity.running.saturating_sub(1) };
        }
    }

    fn touch(&self, id: &SessionId) {
        if let Some(activity) = self.table().get_mut(id) {
            activity.last = Instant::now();
            activity.lost = None;
        }
    }

    /// Closes the sessions idle past the limit; answers how many.
    pub async fn sweep(&self) -> usize {
        let idle = self.limits.idle;
        let expired: Vec<SessionId> = self
            .table()
            .iter()
            .filter(|(_, a)| a.running == 0 && a.last.elapsed() >= idle)
            .map(|(id, _)| id.clone())
            .collect();
        for id in &expired {
            let _ = self.close_for(id, CloseReason::Idle).await;
        }
        // Those whose stream ended while a call still ran, once the call is over.
        let gone: Vec<SessionId> = self.table().iter().filter(|(_, a)| a.gone()).map(|(id, _)| id.clone()).collect();
        for id in &gone {
            let _ = self.close_for(id, CloseReason::StreamLost).await;
        }
        expired.len() + gone.len()
    }

    /// Starts the sweeper once, on the runtime of the first session.
    fn start_sweeper(&self) {
        if self.sweeping.swap(true, std::sync::atomic::Ordering::Relaxed) {
            return;
        }
        let me = self.me.clone();
        let period = (self.limits.idle / 4).clamp(Duration::from_millis(50), Duration::from_secs(15));
        tokio::spawn(async move {
            loop {
                tokio::time::sleep(period).await;
                // The sweeper ends with the manager.
                let Some(sessions) = me.upgrade() else { return };
                sessions.sweep().await;
            }
        });
    }

    /// Makes room for one more session: closes the one idle longest when at the cap.
    async fn make_room(&self) -> Result<(), SessionsError> {
        loop {
            let victim = {
                let table = self.table();
                if table.len() < self.limits.max_sessions {
                    return Ok(());
                }
                table.iter().filter(|(_, a)| a.running == 0).min_by_key(|(_, a)| a.last).map(|(id, _)| id.clone())
            };
            match victim {
                Some(id) => self.close_for(&id, CloseReason::Cap).await?,
                None => {
                    self.refused();
                    // Outside a request's task (tests, other callers) there is nothing to tell.
                    let _ = crate::SESSION_REFUSED.try_with(|refused| refused.set(true));
                    return Err(SessionsError::Full(self.limits.max_sessions));
                }
            }
        }
    }
}

/// The `notifications/cancelled` a client sends for `request`, sent on its behalf.
fn cancelled(request: RequestId) -> ClientJsonRpcMessage {
    let reason = "the client closed the connection before the answer".to_owned();
    let notification = CancelledNotification::new(CancelledNotificationParam::new(Some(request), Some(reason)));
    ClientJsonRpcMessage::notification(ClientNotification::CancelledNotification(notification))
}

/// Whether `message` answers `request`.
fn answers(message: &ServerJsonRpcMessage, request: &RequestId) -> bool {
    match message {
        JsonRpcMessage::Response(response) => &response.id == request,
        JsonRpcMessage::Error(error) => error.id.as_ref() == Some(request),
        _ => false,
    }
}

/// A request's answer stream: counts the call as running while it is open, and when
/// it is dropped before the answer went out, cancels the request.
struct CallStream {
    inner: Pin<Box<dyn futures_util::Stream<Item = ServerSseMessage> + Send + Sync>>,
    sessions: Weak<BoundedSessions>,
    session: SessionId,
    request: RequestId,
    answered: bool,
}

impl futures_util::Stream for CallStream {
    type Item = ServerSseMessage;

    fn poll_next(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Option<ServerSseMessage>> {
        let polled = self.inner.as_mut().poll_next(cx);
        match &polled {
            Poll::Ready(Some(sse)) => {
                if sse.message.as_deref().is_some_and(|m| answers(m, &self.request)) {
                    self.answered = true;
                }
            }
            // The session ended the stream: nothing is left to cancel.
            Poll::Ready(None) => self.answered = true,
            Poll::Pending => {}
        }
        polled
    }
}

impl Drop for CallStream {
    fn drop(&mut self) {
        let Some(sessions) = self.sessions.upgrade() else { return };
        sessions.call(&self.session, false);
        if self.answered {
            return;
        }
        let (session, request) = (self.session.clone(), self.request.clone());
        tracing::info!(%session, %request, "the MCP client went away before the answer: cancelling the call");
        if let Ok(runtime) = tokio::runtime::Handle::try_current() {
            runtime.spawn(async move {
                // A session closed meanwhile has nothing left to cancel.
                let _ = sessions.inner.accept_message(&session, cancelled(request)).await;
            });
        }
    }
}

/// A session's standalone stream: counted while open, and when it ends the session
/// has [`STREAM_GRACE`] to come back.
struct StandaloneStream {
    inner: Pin<Box<dyn futures_util::Stream<Item = ServerSseMessage> + Send + Sync>>,
    sessions: Weak<BoundedSessions>,
    session: SessionId,
}

impl futures_util::Stream for StandaloneStream {
    type Item = ServerSseMessage;

    fn poll_next(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Option<ServerSseMessage>> {
        self.inner.as_mut().poll_next(cx)
    }
}

impl Drop for StandaloneStream {
    fn drop(&mut self) {
        if let Some(sessions) = self.sessions.upgrade() {
            sessions.stream(&self.session, false);
        }
    }
}

impl SessionManager for BoundedSessions {
    type Error = SessionsError;
    type Transport = WorkerTransport<rmcp::transport::streamable_http_server::session::local::LocalSessionWorker>;

    async fn create_session(&self) -> Result<(SessionId, Self::Transport), Self::Error> {
        self.start_sweeper();
        self.make_room().await?;
        let (id, transport) = self.inner.create_session().await?;
        self.table().insert(id.clone(), Activity::new());
        self.tell(SessionEvent::Opened(id.clone()));
        Ok((id, transport))
    }

    async fn initialize_session(
        &self,
        id: &SessionId,
        message: ClientJsonRpcMessage,
    ) -> Result<ServerJsonRpcMessage, Self::Error> {
        self.touch(id);
        Ok(self.inner.initialize_session(id, message).await?)
    }

    async fn has_session(&self, id: &SessionId) -> Result<bool, Self::Error> {
        Ok(self.inner.has_session(id).await?)
    }

    async fn close_session(&self, id: &SessionId) -> Result<(), Self::Error> {
        // rmcp calls this for a client's DELETE; this manager's own closings go through `close_for`.
        self.close_for(id, CloseReason::Client).await
    }

    async fn create_stream(
        &self,
        id: &SessionId,
        message: ClientJsonRpcMessage,
    ) -> Result<impl futures_util::Stream<Item = ServerSseMessage> + Send + Sync + 'static, Self::Error> {
        let request = match &message {
            JsonRpcMessage::Request(request) => Some(request.id.clone()),
            _ => None,
        };
        self.call(id, true);
        let stream = match self.inner.create_stream(id, message).await {
            Ok(stream) => stream,
            Err(err) => {
                self.call(id, false);
                return Err(err.into());
            }
        };
        let Some(request) = request else {
            // Not a request (rmcp sends only requests here): nothing to cancel.
            self.call(id, false);
            return Ok(CallStream {
                inner: Box::pin(stream),
                sessions: Weak::new(),
                session: id.clone(),
                request: RequestId::Number(0),
                answered: true,
            });
        };
        Ok(CallStream {
            inner: Box::pin(stream),
            sessions: self.me.clone(),
            session: id.clone(),
            request,
            answered: false,
        })
    }

    async fn accept_message(&self, id: &SessionId, message: ClientJsonRpcMessage) -> Result<(), Self::Error> {
        self.touch(id);
        Ok(self.inner.accept_message(id, message).await?)
    }

    async fn create_standalone_stream(
        &self,
        id: &SessionId,
    ) -> Result<impl futures_util::Stream<Item = ServerSseMessage> + Send + Sync + 'static, Self::Error> {
        self.touch(id);
        let stream = self.inner.create_standalone_stream(id).await?;
        self.stream(id, true);
        Ok(StandaloneStream { inner: Box::pin(stream), sessions: self.me.clone(), session: id.clone() })
    }

    async fn resume(
        &self,
        id: &SessionId,
        last_event_id: String,
    ) -> Result<impl futures_util::Stream<Item = ServerSseMessage> + Send + Sync + 'static, Self::Error> {
        self.touch(id);
        Ok(self.inner.resume(id, last_event_id).await?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn sessions_past_the_cap_close_the_one_idle_longest() {
        let _one_at_a_time = REFUSING.lock().await;
        let sessions = BoundedSessions::new(SessionLimits { max_sessions: 3, idle: Duration::from_secs(600) });
        let mut ids = Vec::new();
        for _ in 0..3 {
            ids.push(sessions.create_session().await.expect("opens").0);
        }
        // The first is busy and the second was used last: the third is the one idle longest.
        sessions.call(&ids[0], true);
        sessions.touch(&ids[1]);
        let (fourth, _) = sessions.create_session().await.expect("opens by closing one");
        assert_eq!(sessions.open_sessions(), 3);
        assert!(!sessions.has_session(&ids[2]).await.expect("answers"), "the one idle longest was closed");
        assert!(sessions.has_session(&ids[0]).await.expect("answers"), "a busy session stays");
        assert!(sessions.has_session(&fourth).await.expect("answers"));
        // With every session busy, a new one is refused, saying why.
        sessions.call(&ids[1], true);
        sessions.call(&fourth, true);
        let Err(err) = sessions.create_session().await else { panic!("a session opened though all are busy") };
        assert!(err.to_string().contains("3 MCP sessions are open"), "{err}");
    }

    /// An `initialize` as a client opens its session with, over streamable HTTP.
    fn initialize() -> http::Request<http_body_util::Full<bytes::Bytes>> {
        let body = serde_json::json!({
            "jsonrpc": "2.0", "id": 1, "method": "initialize",
            "params": {"protocolVersion": "2025-06-18", "capabilities": {}, "clientInfo": {"name": "t", "version": "1"}},
        });
        http::Request::post("/mcp")
            .header(http::header::HOST, "localhost")
            .header(http::header::ACCEPT, "application/json, text/event-stream")
            .header(http::header::CONTENT_TYPE, "application/json")
            .body(http_body_util::Full::new(serde_json::to_vec(&body).expect("serialises").into()))
            .expect("a request")
    }

    /// The streamable-HTTP service both servers run, over a manager capped at one
    /// session, and that session with a call running.
    async fn one_busy_session() -> (
        Arc<BoundedSessions>,
        SessionId,
        crate::HttpStatuses<rmcp::transport::StreamableHttpService<crate::Server<crate::tests::Echo>, BoundedSessions>>,
    ) {
        let sessions = BoundedSessions::new(SessionLimits { max_sessions: 1, idle: Duration::from_secs(600) });
        let service = crate::HttpStatuses(rmcp::transport::StreamableHttpService::new(
            || Ok(crate::Server(crate::tests::Echo)),
            Arc::clone(&sessions),
            crate::http_config(),
        ));
        let (busy, _) = sessions.create_session().await.expect("opens");
        sessions.call(&busy, true);
        (sessions, busy, service)
    }

    #[tokio::test]
    async fn a_session_refused_because_all_are_busy_is_a_503_with_retry_after() {
        let _one_at_a_time = REFUSING.lock().await;
        use tower_service::Service as _;
        let (sessions, busy, mut service) = one_busy_session().await;

        let refused = service.call(initialize()).await.expect("an answer");
        assert_eq!(refused.status(), http::StatusCode::SERVICE_UNAVAILABLE);
        let retry = refused.headers().get(http::header::RETRY_AFTER).expect("Retry-After is set");
        assert_eq!(retry.to_str().expect("ASCII"), crate::BUSY_RETRY_AFTER_SECS.to_string());
        let body = http_body_util::BodyExt::collect(refused.into_body()).await.expect("a body").to_bytes();
        let body = String::from_utf8_lossy(&body);
        assert!(body.contains("1 MCP sessions are open") && body.contains("every one has a call running"), "{body}");
        assert_eq!(sessions.open_sessions(), 1, "nothing was closed to make room");

        // Once the call ends, the idle session makes room and the next one opens.
        sessions.call(&busy, false);
        let opened = service.call(initialize()).await.expect("an answer");
        assert_eq!(opened.status(), http::StatusCode::OK);
        assert!(opened.headers().contains_key("mcp-session-id"), "{:?}", opened.headers());
        assert!(!sessions.has_session(&busy).await.expect("answers"), "the idle one made room");
    }

    /// Held by the tests that refuse sessions: a log call site that another thread
    /// registers while this test installs its subscriber can keep the interest computed
    /// without it (tracing-core's registration race), and the test's log would miss it.
    static REFUSING: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

    /// What a log layer wrote.
    #[derive(Clone, Default)]
    struct Captured(Arc<Mutex<Vec<u8>>>);

    impl std::io::Write for Captured {
        fn write(&mut self, bytes: &[u8]) -> std::io::Result<usize> {
            self.0.lock().expect("not poisoned").extend_from_slice(bytes);
            Ok(bytes.len())
        }

        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    impl Captured {
        fn text(&self) -> String {
            String::from_utf8_lossy(&self.0.lock().expect("not poisoned")).into_owned()
        }
    }

    #[tokio::test]
    async fn refused_sessions_are_one_counted_warning_not_an_error_each() {
        let _one_at_a_time = REFUSING.lock().await;
        use tower_service::Service as _;
        use tracing_subscriber::layer::SubscriberExt as _;
        use tracing_subscriber::Layer as _;
        // The same events twice: through the servers' filter, and unfiltered.
        let (filtered, all) = (Captured::default(), Captured::default());
        let (to_filtered, to_all) = (filtered.clone(), all.clone());
        let subscriber = tracing_subscriber::registry()
            .with(
                tracing_subscriber::fmt::layer().with_ansi(false).with_writer(move || to_filtered.clone()).with_filter(
                    tracing_subscriber::filter::FilterExt::and(
                        tracing_subscriber::filter::LevelFilter::INFO,
                        crate::without_refusal_noise(),
                    ),
                ),
            )
            .with(tracing_subscriber::fmt::layer().with_ansi(false).with_writer(move || to_all.clone()));
        let _log = tracing::subscriber::set_default(subscriber);

        let (_sessions, _busy, mut service) = one_busy_session().await;
        for _ in 0..50 {
            let refused = service.call(initialize()).await.expect("an answer");
            assert_eq!(refused.status(), http::StatusCode::SERVICE_UNAVAILABLE);
        }
        // rmcp's other internal errors come from the same call site, and stay in the log.
        let mut broken = crate::HttpStatuses(rmcp::transport::StreamableHttpService::new(
            || Err::<crate::Server<crate::tests::Echo>, _>(std::io::Error::other("no service")),
            BoundedSessions::new(SessionLimits { max_sessions: 1, idle: Duration::from_secs(600) }),
            crate::http_config(),
        ));
        let failed = broken.call(initialize()).await.expect("an answer");
        assert_eq!(failed.status(), http::StatusCode::INTERNAL_SERVER_ERROR);

        let rmcp_errors = |log: &str| log.lines().filter(|l| l.contains("ERROR") && l.contains("rmcp")).count();
        let warnings = |log: &str| log.lines().filter(|l| l.contains("new MCP sessions refused")).count();
        let (filtered, all) = (filtered.text(), all.text());
        assert_eq!(rmcp_errors(&all), 51, "rmcp logs every refusal:\n{all}");
        assert_eq!(rmcp_errors(&filtered), 1, "only the real failure is kept:\n{filtered}");
        assert!(filtered.contains("no service"), "{filtered}");
        assert_eq!(warnings(&filtered), 1, "one warning per {REFUSAL_WARNING_EVERY:?}:\n{filtered}");
    }

    #[tokio::test]
    async fn twenty_thousand_sessions_stay_at_the_cap() {
        let sessions = BoundedSessions::new(SessionLimits { max_sessions: 64, idle: Duration::from_secs(600) });
        for _ in 0..20_000 {
            sessions.create_session().await.expect("opens");
        }
        assert_eq!(sessions.open_sessions(), 64);
        assert_eq!(sessions.inner.sessions.read().await.len(), 64, "rmcp's own table holds no more");
    }

    /// A manager without its sweeper that records its events.
    fn recorded() -> (Arc<BoundedSessions>, Arc<Mutex<Vec<SessionEvent>>>) {
        let seen = Arc::new(Mutex::new(Vec::new()));
        let log = Arc::clone(&seen);
        let limits = SessionLimits { max_sessions: 8, idle: Duration::from_secs(600) };
        let sessions = BoundedSessions::with_events(limits, Arc::new(move |e| log.lock().unwrap().push(e)));
        sessions.sweeping.store(true, std::sync::atomic::Ordering::Relaxed);
        (sessions, seen)
    }

    #[tokio::test(start_paused = true)]
    async fn a_session_whose_stream_ended_closes_after_the_grace_unless_its_client_comes_back() {
        let (sessions, seen) = recorded();
        let (gone, _) = sessions.create_session().await.expect("opens");
        let (back, _) = sessions.create_session().await.expect("opens");
        let (quiet, _) = sessions.create_session().await.expect("opens");
        for id in [&gone, &back] {
            sessions.stream(id, true);
            sessions.stream(id, false);
        }
        // `back` sends a request within the grace; `quiet` never opened a stream.
        tokio::time::sleep(STREAM_GRACE / 2).await;
        sessions.touch(&back);
        tokio::time::sleep(STREAM_GRACE).await;
        tokio::task::yield_now().await;
        assert!(!sessions.has_session(&gone).await.expect("answers"), "the session that went away is closed");
        assert!(sessions.has_session(&back).await.expect("answers"), "a client that came back keeps its session");
        assert!(sessions.has_session(&quiet).await.expect("answers"), "no stream, no stream rule");
        let seen = seen.lock().unwrap().clone();
        assert!(seen.contains(&SessionEvent::Opened(gone.clone())), "{seen:?}");
        assert!(seen.contains(&SessionEvent::StreamLost(gone.clone())), "{seen:?}");
        assert!(seen.contains(&SessionEvent::Closed { id: gone.clone(), why: CloseReason::StreamLost }), "{seen:?}");
        assert!(!seen.iter().any(|e| matches!(e, SessionEvent::Closed { id, .. } if *id == back)), "{seen:?}");
    }

    #[tokio::test(start_paused = true)]
    async fn a_stream_lost_during_a_call_closes_the_session_once_the_call_is_over() {
        let (sessions, seen) = recorded();
        let (id, _) = sessions.create_session().await.expect("opens");
        sessions.stream(&id, true);
        sessions.call(&id, true);
        sessions.stream(&id, false);
        tokio::time::sleep(STREAM_GRACE * 2).await;
        assert!(sessions.has_session(&id).await.expect("answers"), "a call still runs");
        sessions.call(&id, false);
        assert_eq!(sessions.sweep().await, 1);
        assert!(!sessions.has_session(&id).await.expect("answers"));
        let _ = sessions.close_session(&id).await;
        let closed = seen.lock().unwrap().iter().filter(|e| matches!(e, SessionEvent::Closed { .. })).count();
        assert_eq!(closed, 1, "told once");
    }

    #[tokio::test]
    async fn idle_sessions_expire_and_busy_ones_do_not() {
        let sessions = BoundedSessions::new(SessionLimits { max_sessions: 8, idle: Duration::ZERO });
        // This test sweeps itself, at the moments it chooses.
        sessions.sweeping.store(true, std::sync::atomic::Ordering::Relaxed);
        let (idle, _) = sessions.create_session().await.expect("opens");
        let (busy, _) = sessions.create_session().await.expect("opens");
        sessions.call(&busy, true);
        assert_eq!(sessions.sweep().await, 1);
        assert!(!sessions.has_session(&idle).await.expect("answers"));
        assert!(sessions.has_session(&busy).await.expect("answers"));
    }
}
