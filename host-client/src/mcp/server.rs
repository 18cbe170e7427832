//! The MCP server of `--agent mcp`: one rmcp handler per session
//! ([`ArenaSession`]), served with rmcp's streamable-HTTP transport at `/mcp`
//! behind the bearer token, with rmcp's `Host` check and every `Origin`
//! refused (a browser page cannot reach it), as the guest's own guards.

use std::borrow::Cow;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use axum::extract::Request;
use axum::http::StatusCode;
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use base64::Engine as _;
use rmcp::model::{
    CallToolRequestParams, CallToolResponse, CallToolResult, ContentBlock, Implementation, ListToolsResult,
    PaginatedRequestParams, ProtocolVersion, ServerCapabilities, ServerConfig, Tool,
};
use rmcp::service::RequestContext;
use rmcp::transport::streamable_http_server::session::local::LocalSessionManager;
use rmcp::transport::streamable_http_server::{StreamableHttpServerConfig, StreamableHttpService};
use rmcp::{ErrorData, RoleServer, ServerHandler};
use serde_json::{json, Value};
use tokio_util::sync::CancellationToken;

use super::{ended_text, EpisodeLink, Hub, Pending, Reply};
use arena_shared::mcp_tools::{self as tools, ToolCall};

/// The newest protocol version served: sessions (`Mcp-Session-Id`) carry the
/// episode a client is bound to, and the 2026 revision has none.
pub const MAX_PROTOCOL: ProtocolVersion = ProtocolVersion::V_2025_11_25;

/// The MCP tools as rmcp describes them.
pub fn rmcp_tools(with_task: bool) -> Vec<Tool> {
    tools::tool_list(with_task)
        .into_iter()
        .map(|(name, description, schema)| {
            let Value::Object(schema) = schema else { unreachable!("every input schema is an object") };
            Tool::new(name, description, Arc::new(schema))
        })
        .collect()
}

fn text(text: impl Into<String>) -> CallToolResponse {
    CallToolResult::success(vec![ContentBlock::text(text)]).into()
}

fn tool_error(message: impl Into<String>) -> CallToolResponse {
    CallToolResult::error(vec![ContentBlock::text(message)]).into()
}

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

    async fn call(&self, request: CallToolRequestParams) -> CallToolResponse {
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
                    let info = link.task_info();
                    *self.bound.lock().await = Some(link);
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
                let b64 = base64::engine::general_purpose::STANDARD.encode(&latest.png);
                return CallToolResult::success(vec![ContentBlock::image(b64, "image/png")]).into();
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

impl Drop for ArenaSession {
    fn drop(&mut self) {
        // A closed session ends its episode: the agent's next wait sees the channel closed.
        if let Ok(mut bound) = self.bound.try_lock() {
            bound.take();
        }
    }
}

impl ServerHandler for ArenaSession {
    fn get_info(&self) -> ServerConfig {
        ServerConfig::new(ServerCapabilities::builder().enable_tools().build())
            .with_protocol_version(MAX_PROTOCOL)
            .with_server_info(Implementation::new("arena", env!("CARGO_PKG_VERSION")))
            .with_instructions(
                "A WindowsAgentArena benchmark episode: call get_task, act with the desktop tools, then done or fail.",
            )
    }

    fn supported_protocol_versions(&self) -> Cow<'static, [ProtocolVersion]> {
        Cow::Borrowed(ProtocolVersion::known_up_to(&MAX_PROTOCOL))
    }

    async fn list_tools(
        &self,
        _request: Option<PaginatedRequestParams>,
        _context: RequestContext<RoleServer>,
    ) -> Result<ListToolsResult, ErrorData> {
        Ok(ListToolsResult::with_all_items(rmcp_tools(true)))
    }

    async fn call_tool(
        &self,
        request: CallToolRequestParams,
        _context: RequestContext<RoleServer>,
    ) -> Result<CallToolResponse, ErrorData> {
        Ok(self.call(request).await)
    }
}

/// Refuses a request without `Authorization: Bearer TOKEN`.
async fn require_token(token: Arc<str>, request: Request, next: Next) -> Response {
    let given = request
        .headers()
        .get(axum::http::header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "));
    let ok = given.is_some_and(|g| g.len() == token.len() && g.bytes().zip(token.bytes()).all(|(a, b)| a == b));
    if ok {
        next.run(request).await
    } else {
        (StatusCode::UNAUTHORIZED, [(axum::http::header::WWW_AUTHENTICATE, "Bearer")], "a bearer token is required\n")
            .into_response()
    }
}

/// `/mcp` with `make` as the per-session handler, behind `token`, accepting
/// `Host` names of loopback and `listen`'s own address, refusing every `Origin`.
pub fn router<S, F>(make: F, token: &str, listen: SocketAddr, stop: CancellationToken) -> axum::Router
where
    S: ServerHandler + Send + 'static,
    F: Fn() -> S + Send + Sync + 'static,
{
    let mut hosts: Vec<String> = ["localhost", "127.0.0.1", "::1", "[::1]"].iter().map(|s| (*s).to_owned()).collect();
    hosts.push(listen.ip().to_string());
    hosts.push(listen.to_string());
    let mut config = StreamableHttpServerConfig::default()
        .with_sse_keep_alive(Some(Duration::from_secs(15)))
        .with_cancellation_token(stop);
    config.allowed_hosts = hosts;
    config.legacy_session_mode = true;
    let config = config.enforce_origin_validation();
    let service: StreamableHttpService<S, LocalSessionManager> =
        StreamableHttpService::new(move || Ok(make()), Default::default(), config);
    let token: Arc<str> = Arc::from(token);
    axum::Router::new()
        .nest_service("/mcp", service)
        .layer(axum::middleware::from_fn(move |req, next| require_token(Arc::clone(&token), req, next)))
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
    let app = router(move || ArenaSession::new(Arc::clone(&hub)), &token, addr, stop.clone());
    if let Err(err) = axum::serve(listener, app).with_graceful_shutdown(stop.cancelled_owned()).await {
        tracing::error!(error = %err, "the MCP server stopped");
    }
}
