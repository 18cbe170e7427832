//! The Model Context Protocol glue both MCP servers of the project share: the
//! guest's `--mcp` (the desktop of one machine) and the host's `--agent mcp` (a
//! benchmark run's episodes). Each server writes only what its tools do, as a
//! [`ToolServer`]; this crate makes it an rmcp [`ServerHandler`] ([`Server`]) that
//! offers the tools of [`arena_shared::mcp_tools`] ([`tools`]), answers with the
//! result shapes both use ([`text`], [`image_png`], [`tool_error`]), speaks the
//! protocol revisions up to [`MAX_PROTOCOL`], and is served with the same
//! streamable-HTTP settings ([`http_config`]), the same bounded sessions
//! ([`BoundedSessions`]: a cap, idle expiry, hung-up calls cancelled) and the
//! session's end and a refused session answered as clients expect ([`HttpStatuses`]).
//!
//! What is not here: the tools' names, arguments and checks (`arena_shared::mcp_tools`),
//! the bearer check (`arena_shared::token::bearer_matches`, which every server of the
//! project uses), and each server's routing and guards.

#![forbid(unsafe_code)]

pub mod sessions;

pub use sessions::{BoundedSessions, CloseReason, SessionEvent, SessionEvents, SessionLimits, STREAM_GRACE};

use std::borrow::Cow;
use std::future::Future;
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::Duration;

use rmcp::model::{
    CallToolRequestParams, CallToolResponse, CallToolResult, ContentBlock, Implementation, ListToolsResult,
    PaginatedRequestParams, ProtocolVersion, ServerCapabilities, ServerConfig, Tool,
};
use rmcp::service::RequestContext;
use rmcp::transport::streamable_http_server::StreamableHttpServerConfig;
use rmcp::{ErrorData, RoleServer, ServerHandler};
use serde_json::Value;

use arena_shared::mcp_tools;

/// The newest MCP revision served: both servers keep state per session
/// (`Mcp-Session-Id`: the host binds an episode to it), which the 2026 revision has
/// no more.
pub const MAX_PROTOCOL: ProtocolVersion = ProtocolVersion::V_2025_11_25;

/// How often an idle server-sent event stream gets a keep-alive comment.
pub const SSE_KEEP_ALIVE: Duration = Duration::from_secs(15);

/// The desktop tools of [`arena_shared::mcp_tools`] as rmcp describes them; the
/// benchmark's `get_task`, `done` and `fail` with `with_task`.
pub fn tools(with_task: bool) -> Vec<Tool> {
    mcp_tools::tool_list(with_task)
        .into_iter()
        .filter_map(|(name, description, schema)| match schema {
            Value::Object(schema) => Some(Tool::new(name, description, Arc::new(schema))),
            // Every input schema is an object (mcp_tools' tests say so); anything else is no tool.
            _ => None,
        })
        .collect()
}

/// A tool's successful text result.
pub fn text(text: impl Into<String>) -> CallToolResponse {
    CallToolResult::success(vec![ContentBlock::text(text)]).into()
}

/// A tool's successful image result: a PNG, base64-encoded.
pub fn image_png(base64: impl Into<String>) -> CallToolResponse {
    CallToolResult::success(vec![ContentBlock::image(base64, "image/png")]).into()
}

/// A tool's failure, told to the model as a result with `isError` (not a protocol error).
pub fn tool_error(message: impl Into<String>) -> CallToolResponse {
    CallToolResult::error(vec![ContentBlock::text(message)]).into()
}

/// The streamable-HTTP settings both servers start from: keep-alives, and every
/// request with an `Origin` refused (a web page never reaches a desktop). Each server
/// adds its own `Host` rule and shutdown.
pub fn http_config() -> StreamableHttpServerConfig {
    StreamableHttpServerConfig::default().with_sse_keep_alive(Some(SSE_KEEP_ALIVE)).enforce_origin_validation()
}

/// A streamable-HTTP MCP service (rmcp's `StreamableHttpService`) with two of its
/// statuses changed to what clients expect; bodies and every other answer are rmcp's.
///
/// - **A session's `DELETE`: `200 OK`, not rmcp's `202 Accepted`.** The MCP
///   specification (transports, "Session Management") lets a client end its session
///   with `DELETE` and names only `405` as an answer, for servers that do not allow it;
///   it says nothing of the success status. The official SDKs' servers answer `200`
///   (the Python SDK's `StreamableHTTPServerTransport._handle_delete_request`, the
///   TypeScript SDK's `handleDeleteRequest`), and the Python SDK's client, which every
///   Python MCP user has, takes `200` and `204` as success and logs `Session
///   termination failed: 202` for anything else (`mcp` 2.3.0,
///   `mcp/client/streamable_http.py`, `terminate_session`). The session is closed when
///   rmcp answers; only the status changes, and only for `DELETE` (a `POST` of a
///   notification keeps its `202`).
/// - **A new session refused because every open one is busy
///   ([`sessions::SessionsError::Full`]): `503 Service Unavailable` with `Retry-After`, not
///   rmcp's `500`.** rmcp answers any failure of its session manager `500` (its
///   `internal_error_response`), which says the server is broken; this refusal is a
///   temporary overload, which HTTP answers `503` and `Retry-After` (RFC 9110, 15.6.4
///   and 10.2.3). The request's own refusal is told apart from any other failure by a
///   flag [`BoundedSessions`] sets in the request's task, so no other `500` changes.
#[derive(Debug, Clone)]
pub struct HttpStatuses<S>(pub S);

/// Seconds a client refused a session is told to wait before it tries again.
pub const BUSY_RETRY_AFTER_SECS: u32 = 5;

tokio::task_local! {
    /// Set by [`BoundedSessions`] when it refuses the session of the request being
    /// answered in this task ([`HttpStatuses`]).
    pub(crate) static SESSION_REFUSED: std::cell::Cell<bool>;
}

/// A log filter for the servers' subscribers, to combine with their level filter
/// (`level.and(without_refusal_noise())`): it drops the error rmcp logs for a session
/// [`BoundedSessions`] refused (answered 503 by [`HttpStatuses`]), which a client
/// asking again and again would otherwise write once per request; the manager reports
/// its refusals itself, counted, every [`sessions::REFUSAL_WARNING_EVERY`].
///
/// Only rmcp's error call sites are asked per event (whether the request being
/// answered was refused); every other call site keeps the level filter's own cached
/// answer and level hint, so nothing else costs more. rmcp logs every internal
/// error from one call site, so the per-event question is what keeps its other
/// errors in the log.
pub fn without_refusal_noise<S: tracing::Subscriber>() -> impl tracing_subscriber::layer::Filter<S> {
    fn rmcp_error(meta: &tracing::Metadata<'_>) -> bool {
        meta.target().starts_with("rmcp") && *meta.level() == tracing::Level::ERROR
    }
    tracing_subscriber::filter::DynFilterFn::new(|meta, _| {
        !(rmcp_error(meta) && SESSION_REFUSED.try_with(std::cell::Cell::get).unwrap_or(false))
    })
    .with_callsite_filter(|meta| {
        if rmcp_error(meta) {
            tracing::subscriber::Interest::sometimes()
        } else {
            tracing::subscriber::Interest::always()
        }
    })
    .with_max_level_hint(tracing_subscriber::filter::LevelFilter::TRACE)
}

impl<S, B, R> tower_service::Service<http::Request<B>> for HttpStatuses<S>
where
    S: tower_service::Service<http::Request<B>, Response = http::Response<R>>,
    S::Future: Send + 'static,
{
    type Response = http::Response<R>;
    type Error = S::Error;
    type Future = Pin<Box<dyn Future<Output = Result<http::Response<R>, S::Error>> + Send>>;

    fn poll_ready(&mut self, cx: &mut Context<'_>) -> Poll<Result<(), Self::Error>> {
        self.0.poll_ready(cx)
    }

    fn call(&mut self, request: http::Request<B>) -> Self::Future {
        let delete = request.method() == http::Method::DELETE;
        let answer = self.0.call(request);
        Box::pin(SESSION_REFUSED.scope(std::cell::Cell::new(false), async move {
            let mut response = answer.await?;
            if delete && response.status() == http::StatusCode::ACCEPTED {
                *response.status_mut() = http::StatusCode::OK;
            }
            let refused = SESSION_REFUSED.with(std::cell::Cell::get);
            if refused && response.status() == http::StatusCode::INTERNAL_SERVER_ERROR {
                *response.status_mut() = http::StatusCode::SERVICE_UNAVAILABLE;
                response
                    .headers_mut()
                    .insert(http::header::RETRY_AFTER, http::HeaderValue::from(BUSY_RETRY_AFTER_SECS));
            }
            Ok(response)
        }))
    }
}

/// What one MCP server does with its tools; [`Server`] does the rest.
pub trait ToolServer: Send + Sync + 'static {
    /// The server's name in `initialize` (`serverInfo.name`).
    const NAME: &'static str;
    /// The server's version in `initialize`.
    const VERSION: &'static str;
    /// What the server is, for the model (`instructions`).
    const INSTRUCTIONS: &'static str;
    /// Whether the benchmark's `get_task`, `done` and `fail` are offered.
    const WITH_TASK: bool;

    /// Runs one tool call; a failure is a [`tool_error`] result.
    fn call(&self, request: CallToolRequestParams) -> impl Future<Output = CallToolResponse> + Send + '_;
}

/// A [`ToolServer`] as an rmcp [`ServerHandler`]: one per session.
#[derive(Debug)]
pub struct Server<T>(pub T);

impl<T: ToolServer> ServerHandler for Server<T> {
    fn get_info(&self) -> ServerConfig {
        ServerConfig::new(ServerCapabilities::builder().enable_tools().build())
            .with_protocol_version(MAX_PROTOCOL)
            .with_server_info(Implementation::new(T::NAME, T::VERSION))
            .with_instructions(T::INSTRUCTIONS)
    }

    fn supported_protocol_versions(&self) -> Cow<'static, [ProtocolVersion]> {
        Cow::Borrowed(ProtocolVersion::known_up_to(&MAX_PROTOCOL))
    }

    async fn list_tools(
        &self,
        _request: Option<PaginatedRequestParams>,
        _context: RequestContext<RoleServer>,
    ) -> Result<ListToolsResult, ErrorData> {
        Ok(ListToolsResult::with_all_items(tools(T::WITH_TASK)))
    }

    async fn call_tool(
        &self,
        request: CallToolRequestParams,
        context: RequestContext<RoleServer>,
    ) -> Result<CallToolResponse, ErrorData> {
        // A cancelled request (the client's `notifications/cancelled`, or its hang-up,
        // which `BoundedSessions` turns into one) drops the tool's future: the work
        // behind it is told to stop (the guest's backend calls set their cancel flag
        // when dropped, which the interpreter checks).
        tokio::select! {
            answer = self.0.call(request) => Ok(answer),
            () = context.ct.cancelled() => Err(ErrorData::internal_error("the call was cancelled", None)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) struct Echo;

    impl ToolServer for Echo {
        const NAME: &'static str = "echo";
        const VERSION: &'static str = "1.2.3";
        const INSTRUCTIONS: &'static str = "echoes";
        const WITH_TASK: bool = true;

        async fn call(&self, request: CallToolRequestParams) -> CallToolResponse {
            if request.name == "fail" {
                tool_error("no")
            } else {
                text(request.name.to_string())
            }
        }
    }

    #[test]
    fn every_tool_of_the_table_is_offered_with_its_schema() {
        for with_task in [false, true] {
            let offered = tools(with_task);
            let table = mcp_tools::tool_list(with_task);
            assert_eq!(offered.len(), table.len(), "a tool was dropped (with_task {with_task})");
            for (tool, (name, _, schema)) in offered.iter().zip(&table) {
                assert_eq!(tool.name, *name);
                assert_eq!(Value::Object((*tool.input_schema).clone()), *schema);
            }
        }
        assert!(tools(true).iter().any(|t| t.name == "get_task"));
        assert!(!tools(false).iter().any(|t| t.name == "get_task"));
    }

    #[test]
    fn the_handler_says_who_it_is_and_which_revisions_it_speaks() {
        let server = Server(Echo);
        let info = server.get_info();
        assert_eq!(info.server_info.name, "echo");
        assert_eq!(info.server_info.version, "1.2.3");
        assert_eq!(info.instructions.as_deref(), Some("echoes"));
        assert!(info.capabilities.tools.is_some());
        let versions = server.supported_protocol_versions();
        assert_eq!(versions.last(), Some(&MAX_PROTOCOL));
    }

    /// Answers every request `202 Accepted`, as rmcp answers a session's `DELETE` and a notification.
    #[derive(Clone)]
    struct Accepts;

    impl tower_service::Service<http::Request<()>> for Accepts {
        type Response = http::Response<()>;
        type Error = std::convert::Infallible;
        type Future = std::future::Ready<Result<http::Response<()>, std::convert::Infallible>>;

        fn poll_ready(&mut self, _cx: &mut Context<'_>) -> Poll<Result<(), Self::Error>> {
            Poll::Ready(Ok(()))
        }

        fn call(&mut self, _request: http::Request<()>) -> Self::Future {
            let mut response = http::Response::new(());
            *response.status_mut() = http::StatusCode::ACCEPTED;
            std::future::ready(Ok(response))
        }
    }

    #[tokio::test]
    async fn a_session_delete_is_answered_200_and_nothing_else_changes() {
        use tower_service::Service as _;
        let mut service = HttpStatuses(Accepts);
        let mut status = |method: http::Method| {
            let request = http::Request::builder().method(method).uri("/mcp").body(()).expect("a request");
            service.call(request)
        };
        let deleted = status(http::Method::DELETE).await.expect("an answer");
        assert_eq!(deleted.status(), http::StatusCode::OK, "what the Python SDK's client takes as success");
        let posted = status(http::Method::POST).await.expect("an answer");
        assert_eq!(posted.status(), http::StatusCode::ACCEPTED, "a notification's 202 stays");
    }

    #[tokio::test]
    async fn calls_reach_the_tool_server_and_failures_are_results() {
        let call = |name: &'static str| CallToolRequestParams::new(name);
        let ok = Echo.call(call("screenshot")).await;
        let failed = Echo.call(call("fail")).await;
        let complete = |r: CallToolResponse| match r {
            CallToolResponse::Complete(result) => serde_json::to_value(result).expect("serialises"),
            other => panic!("not a complete result: {other:?}"),
        };
        assert_eq!(complete(ok), complete(text("screenshot")));
        assert_eq!(complete(failed)["isError"], Value::Bool(true));
    }
}
