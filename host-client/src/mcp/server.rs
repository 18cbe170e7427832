//! The MCP server of `--agent mcp`: one handler per session ([`ArenaSession`], an
//! `arena_mcp::ToolServer`: the handler, tool table, result shapes and protocol
//! version are `arena_mcp`'s, which the guest's `--mcp` shares), served with rmcp's
//! streamable-HTTP transport at `/mcp` behind the bearer token (the project's one
//! check, `arena_shared::token::bearer_matches`), answering only `Host` names of this
//! machine (`arena_shared::host_header`, the rule the guest and `arena env serve`
//! use) and refusing every `Origin` (a browser page cannot reach it), as the guest's
//! own guards.

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use arena_mcp::{image_png, text, tool_error, BoundedSessions, Server, SessionLimits, ToolServer};
use axum::extract::Request;
use axum::http::StatusCode;
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use base64::Engine as _;
use rmcp::model::{CallToolRequestParams, CallToolResponse};
use rmcp::transport::streamable_http_server::StreamableHttpService;
use rmcp::ServerHandler;
use serde_json::{json, Value};
use tokio_util::sync::CancellationToken;

use super::{ended_text, EpisodeLink, Hub, Pending, Reply};
use arena_shared::mcp_tools::{self as tools, ToolCall};

/// One MCP session: at most one episode at a time.
#[derive(Debug)]
pub struct ArenaSession {
    hub: Arc<Hub>,
    bound: tokio::sync::Mutex<Option<Arc<EpisodeLink>>>,
    /// Longest wait for an episode's evaluation after it ends.
    result_wait: Duration,
}

impl ArenaSession {
    /// A session of the run `hub` serves.
    pub fn new(hub: Arc<Hub>) -> ArenaSession {
        ArenaSession { hub, bound: tokio::sync::Mutex::new(None), result_wait: Duration::from_secs(900) }
    }

    async fn current(&self) -> Option<Arc<EpisodeLink>> {
        let mut bound = self.bound.lock().await;
        if bound.as_ref().is_some_and(|l| l.ended.load(std::sync::atomic::Ordering::SeqCst)) {
            *bound = None;
        }
        bound.clone()
    }

    /// One tool call: binds an episode (`get_task`), answers from its latest
    /// observation, or hands an action to the episode and waits for the step.
    async fn answer(&self, request: CallToolRequestParams) -> CallToolResponse {
        let link = self.current().await;
        let screen = link.as_ref().and_then(|l| l.latest.lock().ok().map(|s| s.screen));
        let arguments = request.arguments.clone().map(Value::Object).unwrap_or_else(|| json!({}));
        let call = match tools::parse(&request.name, request.arguments, screen, true) {
            Ok(call) => call,
            Err(message) => return tool_error(message),
        };
        if call == ToolCall::GetTask {
            if let Some(link) = link {
                return text(link.task_info().to_string());
            }
            return match self.hub.take().await {
                Some(link) => {
                    // Should this call be dropped before the episode is bound (its
                    // client hung up), the episode is let go rather than lost.
                    let taken = Unbound(Some(link));
                    let mut bound = self.bound.lock().await;
                    let Some(link) = taken.bind() else { return tool_error("get_task: the episode was lost") };
                    let info = link.task_info();
                    *bound = Some(link);
                    text(info.to_string())
                }
                None => text(json!({"task_id": null}).to_string()),
            };
        }
        let Some(link) = link else {
            return tool_error(format!("{}: no episode: call get_task first", request.name));
        };
        let latest = match link.latest.lock() {
            Ok(latest) => latest.clone(),
            Err(_) => return tool_error("the episode's observation is unavailable"),
        };
        let action = match call {
            ToolCall::GetTask => return tool_error("get_task: answered above"),
            ToolCall::Screenshot => {
                return image_png(base64::engine::general_purpose::STANDARD.encode(&latest.png));
            }
            ToolCall::AccessibilityTree { win32: true } => {
                return tool_error(
                    "accessibility_tree: a benchmark episode observes the UIA tree; backend win32 is served by `arena-guest --mcp`",
                );
            }
            ToolCall::AccessibilityTree { win32: false } => {
                return match latest.xml {
                    Some(xml) => text(xml),
                    None => tool_error("accessibility_tree: no tree could be read this step"),
                };
            }
            ToolCall::ListWindows => {
                return text(json!({"windows": latest.windows, "foreground": latest.foreground}).to_string());
            }
            other => match super::agent_action(other) {
                Some(action) => action,
                None => return tool_error(format!("{}: not a step", request.name)),
            },
        };
        let (reply, answer) = tokio::sync::oneshot::channel();
        let pending = Pending { tool: request.name.to_string(), arguments, action, reply };
        if link.calls.send(pending).await.is_err() {
            return self.ended(&link).await;
        }
        match answer.await {
            Ok(Reply::Stepped { step, steps_left }) => {
                text(json!({"ok": true, "step": step, "steps_left": steps_left}).to_string())
            }
            Ok(Reply::Ended) | Err(_) => self.ended(&link).await,
        }
    }

    /// The episode is over: unbind, wait for its evaluation, tell the result.
    async fn ended(&self, link: &EpisodeLink) -> CallToolResponse {
        *self.bound.lock().await = None;
        text(ended_text(self.hub.result(&link.task_name, self.result_wait).await))
    }
}

/// An episode taken from the hub and not yet bound to its session: dropped
/// unbound, it is let go as a closed session's would be.
struct Unbound(Option<Arc<EpisodeLink>>);

impl Unbound {
    fn bind(mut self) -> Option<Arc<EpisodeLink>> {
        self.0.take()
    }
}

impl Drop for Unbound {
    fn drop(&mut self) {
        if let Some(link) = self.0.take() {
            link.abandoned.cancel();
        }
    }
}

impl Drop for ArenaSession {
    fn drop(&mut self) {
        // A closed session lets its episode go at once: the agent's wait sees it
        // abandoned (and hands it back, or ends it, by whether the session acted).
        if let Ok(mut bound) = self.bound.try_lock() {
            if let Some(link) = bound.take() {
                link.abandoned.cancel();
            }
        }
    }
}

impl ToolServer for ArenaSession {
    const NAME: &'static str = "arena";
    const VERSION: &'static str = env!("CARGO_PKG_VERSION");
    const INSTRUCTIONS: &'static str =
        "A WindowsAgentArena benchmark episode: call get_task, act with the desktop tools, then done or fail.";
    const WITH_TASK: bool = true;

    async fn call(&self, request: CallToolRequestParams) -> CallToolResponse {
        self.answer(request).await
    }
}

/// Refuses a request without `Authorization: Bearer TOKEN` (the project's one bearer
/// check: constant time, the scheme in any case).
async fn require_token(token: Arc<str>, request: Request, next: Next) -> Response {
    let given = request.headers().get(axum::http::header::AUTHORIZATION).map(|v| v.as_bytes());
    if arena_shared::token::bearer_matches(given, &token) {
        next.run(request).await
    } else {
        (StatusCode::UNAUTHORIZED, [(axum::http::header::WWW_AUTHENTICATE, "Bearer")], "a bearer token is required\n")
            .into_response()
    }
}

/// Whether a request's `Host` names this endpoint: a loopback name or address
/// (`arena_shared::host_header::is_loopback`) or the address it listens on. A
/// missing `Host` (HTTP/1.0) passes, as rmcp's own check lets it.
fn host_allowed(host: Option<&str>, listen: SocketAddr) -> bool {
    let Some(host) = host else { return true };
    let name = arena_shared::host_header::name(host);
    arena_shared::host_header::is_loopback(host) || name.parse::<std::net::IpAddr>().is_ok_and(|ip| ip == listen.ip())
}

/// Refuses a request whose `Host` is not this endpoint's ([`host_allowed`]), with
/// rmcp's own answer to that (403).
async fn require_host(listen: SocketAddr, request: Request, next: Next) -> Response {
    let host = request.headers().get(axum::http::header::HOST).and_then(|v| v.to_str().ok());
    if host_allowed(host, listen) {
        next.run(request).await
    } else {
        (StatusCode::FORBIDDEN, "Forbidden: Host header is not allowed\n").into_response()
    }
}

/// `/mcp` with `make` as the per-session handler, behind `token`, accepting
/// `Host` names of loopback and `listen`'s own address, refusing every `Origin`;
/// sessions kept by `sessions`.
pub fn router<S, F>(
    make: F,
    token: &str,
    listen: SocketAddr,
    stop: CancellationToken,
    sessions: Arc<BoundedSessions>,
) -> axum::Router
where
    S: ServerHandler + Send + 'static,
    F: Fn() -> S + Send + Sync + 'static,
{
    // The Host rule is the project's one (`require_host`), not a list of rmcp's.
    let mut config = arena_mcp::http_config().with_cancellation_token(stop).disable_allowed_hosts();
    config.legacy_session_mode = true;
    let service: StreamableHttpService<S, BoundedSessions> =
        StreamableHttpService::new(move || Ok(make()), sessions, config);
    let token: Arc<str> = Arc::from(token);
    axum::Router::new()
        .nest_service("/mcp", arena_mcp::HttpStatuses(service))
        .layer(axum::middleware::from_fn(move |req, next| require_token(Arc::clone(&token), req, next)))
        .layer(axum::middleware::from_fn(move |req, next| require_host(listen, req, next)))
}

/// Serves the run's MCP endpoint on `listener` until `stop`.
pub async fn serve(listener: tokio::net::TcpListener, hub: Arc<Hub>, token: String, stop: CancellationToken) {
    let addr = match listener.local_addr() {
        Ok(addr) => addr,
        Err(err) => {
            tracing::error!(error = %err, "the MCP listener has no address");
            return;
        }
    };
    // At most 64 sessions (a new one closes the one idle longest), each closed after
    // 2 minutes without a call or soon after its stream is lost, a call whose client
    // hung up cancelled; every opening and closing is a note of the run.
    let events = Arc::clone(&hub);
    let sessions = BoundedSessions::with_events(SessionLimits::DEFAULT, Arc::new(move |e| events.session_event(e)));
    let app = router(move || Server(ArenaSession::new(Arc::clone(&hub))), &token, addr, stop.clone(), sessions);
    if let Err(err) = axum::serve(listener, app).with_graceful_shutdown(stop.cancelled_owned()).await {
        tracing::error!(error = %err, "the MCP server stopped");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_this_machines_host_names_pass() {
        let listen: SocketAddr = "10.1.2.3:8791".parse().unwrap();
        for host in ["localhost", "localhost:8791", "agent.localhost", "127.0.0.1:8791", "[::1]:8791", "10.1.2.3:8791"]
        {
            assert!(host_allowed(Some(host), listen), "{host}");
        }
        for host in ["evil.example:8791", "10.1.2.4:8791", "localhost.evil.example", "127.0.0.1.nip.io"] {
            assert!(!host_allowed(Some(host), listen), "{host}");
        }
        assert!(host_allowed(None, listen), "HTTP/1.0 sends no Host");
    }

    /// `initialize` on the endpoint; answers the status and the session id.
    async fn initialize(http: &reqwest::Client, url: &str) -> (u16, Option<String>) {
        let init = json!({"jsonrpc": "2.0", "id": 0, "method": "initialize", "params": {
            "protocolVersion": "2025-06-18", "capabilities": {}, "clientInfo": {"name": "t", "version": "0"}}});
        let response = http
            .post(url)
            .bearer_auth("t0ken")
            .header("Accept", "application/json, text/event-stream")
            .json(&init)
            .send()
            .await
            .expect("answered");
        let session = response.headers().get("mcp-session-id").and_then(|v| v.to_str().ok()).map(str::to_owned);
        let status = response.status().as_u16();
        let _ = response.bytes().await;
        (status, session)
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn initialize_floods_keep_the_endpoint_at_its_session_cap() {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.expect("binds");
        let addr = listener.local_addr().expect("an address");
        let stop = CancellationToken::new();
        let hub = super::super::Hub::new();
        let sessions = BoundedSessions::new(SessionLimits::DEFAULT);
        let app = router(move || Server(ArenaSession::new(Arc::clone(&hub))), "t0ken", addr, stop.clone(), sessions);
        let served = tokio::spawn(async move { axum::serve(listener, app).await });
        let url = format!("http://{addr}/mcp");
        let http = reqwest::Client::new();
        let (status, first) = initialize(&http, &url).await;
        assert_eq!(status, 200);
        let first = first.expect("a session id");
        // Past the cap of 64, each new session closes the one idle longest.
        for _ in 0..300 {
            assert_eq!(initialize(&http, &url).await.0, 200);
        }
        let list = json!({"jsonrpc": "2.0", "id": 1, "method": "tools/list"});
        let gone = http
            .post(&url)
            .bearer_auth("t0ken")
            .header("Accept", "application/json, text/event-stream")
            .header("Mcp-Session-Id", &first)
            .json(&list)
            .send()
            .await
            .expect("answered");
        assert_eq!(gone.status(), 404, "the first session was closed to make room");
        stop.cancel();
        served.abort();
    }
}
