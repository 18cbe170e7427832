//! A small DevTools protocol (CDP) client over the guest's websocket relay
//! (`/v1/browser/devtools/...`), [`CdpSession`].
//!
//! One session is one websocket to one target (a page). Commands carry
//! increasing ids; a reader task hands each response to the call waiting on
//! its id, and drops events (this client subscribes to none). Every call has a
//! deadline, and a closed socket fails every waiting call at once.
//!
//! Targets come from the DevTools HTTP endpoint (`json/list`, `json/new`)
//! through the guest's HTTP forward; their `webSocketDebuggerUrl` names an
//! address inside the VM (`ws://127.0.0.1:<port>/devtools/page/<id>`), which
//! [`relay_url`] rewrites to the guest's relay route. The token goes in the
//! `Authorization` header, as on every other call.
//!
//! It is not Playwright: no auto-waiting, no frames or contexts, only what the
//! getters and the DOM proposer need (`Runtime.evaluate`, `Page.navigate`).

use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use futures_util::stream::SplitSink;
use futures_util::{SinkExt as _, StreamExt as _};
use serde_json::{json, Value};
use tokio::net::TcpStream;
use tokio::sync::oneshot;
use tokio_tungstenite::tungstenite::client::IntoClientRequest as _;
use tokio_tungstenite::tungstenite::http::HeaderValue;
use tokio_tungstenite::tungstenite::protocol::WebSocketConfig;
use tokio_tungstenite::tungstenite::{self, Message};
use tokio_tungstenite::{MaybeTlsStream, WebSocketStream};

use crate::client::GuestClient;
use crate::error::ClientError;

/// Default deadline of one command.
pub const CALL_TIMEOUT: Duration = Duration::from_secs(30);
/// Longest the relay may take to open.
const CONNECT_TIMEOUT: Duration = Duration::from_secs(15);
/// Largest message accepted from the browser (the guest's own bound is the same).
const MAX_MESSAGE: usize = 64 << 20;

/// A failure of the DevTools protocol, naming what was being done.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CdpError {
    /// The DevTools HTTP endpoint could not be asked (no browser on the
    /// guest's debugging port answers `502`).
    #[error("DevTools endpoint: {0}")]
    Http(#[from] ClientError),
    /// The browser has no page to talk to.
    #[error("the browser has no open page")]
    NoPage,
    /// The websocket could not be opened (the guest's status and message, or the I/O error).
    #[error("cannot open the DevTools websocket {url}: {reason}")]
    Connect { url: String, reason: String },
    /// The browser answered the command with an error.
    #[error("{method} failed: {message} (CDP error {code})")]
    Protocol { method: String, code: i64, message: String },
    /// Evaluated script threw.
    #[error("the page's script threw: {0}")]
    Script(String),
    /// No answer within the deadline.
    #[error("{method}: no answer within {} ms", after.as_millis())]
    Timeout { method: String, after: Duration },
    /// The websocket closed (or broke) before the answer came.
    #[error("the DevTools websocket closed: {0}")]
    Closed(String),
    /// An answer is not what the command promises.
    #[error("cannot decode {what}: {reason}")]
    Decode { what: String, reason: String },
}

/// One DevTools target of `json/list` or `json/new`.
#[derive(Debug, Clone, PartialEq, Eq, serde::Deserialize)]
pub struct Target {
    pub id: String,
    #[serde(default, rename = "type")]
    pub kind: String,
    #[serde(default)]
    pub title: String,
    #[serde(default)]
    pub url: String,
    #[serde(default, rename = "webSocketDebuggerUrl")]
    pub ws_url: Option<String>,
}

/// The page targets, most recently active first (the order `json/list` gives).
///
/// # Errors
///
/// [`CdpError::Http`] when the endpoint cannot be asked, [`CdpError::Decode`] for an answer that is no target list.
pub async fn page_targets(client: &GuestClient) -> Result<Vec<Target>, CdpError> {
    let body = client.browser_get("json/list").await?;
    let targets: Vec<Target> = serde_json::from_slice(&body)
        .map_err(|err| CdpError::Decode { what: "json/list".into(), reason: err.to_string() })?;
    Ok(targets.into_iter().filter(|t| t.kind == "page").collect())
}

/// The relay address of a target's `webSocketDebuggerUrl`: its path after
/// `/devtools/` under the guest's `/v1/browser/devtools/`.
///
/// # Errors
///
/// [`CdpError::Decode`] when the address has no `/devtools/` path.
pub fn relay_url(client: &GuestClient, debugger_url: &str) -> Result<String, CdpError> {
    let rest = debugger_url.split_once("/devtools/").map(|(_, rest)| rest).filter(|rest| !rest.is_empty()).ok_or_else(
        || CdpError::Decode {
            what: "webSocketDebuggerUrl".into(),
            reason: format!("{debugger_url:?} has no /devtools/ path"),
        },
    )?;
    let base = client.base_url();
    let base = base.strip_prefix("http://").map_or_else(|| base.to_owned(), |rest| format!("ws://{rest}"));
    Ok(format!("{base}/v1/browser/devtools/{rest}"))
}

type Sink = SplitSink<WebSocketStream<MaybeTlsStream<TcpStream>>, Message>;
type Reply = Result<Value, CdpError>;

/// The calls waiting for an answer, and why the socket closed once it has.
#[derive(Debug, Default)]
struct Waiting {
    calls: HashMap<u64, (String, oneshot::Sender<Reply>)>,
    closed: Option<String>,
}

/// One DevTools websocket to one target, through the guest.
#[derive(Debug)]
pub struct CdpSession {
    sink: tokio::sync::Mutex<Sink>,
    waiting: Arc<Mutex<Waiting>>,
    next_id: AtomicU64,
    timeout: Duration,
    reader: tokio::task::JoinHandle<()>,
}

impl Drop for CdpSession {
    fn drop(&mut self) {
        self.reader.abort();
    }
}

impl CdpSession {
    /// Opens the websocket of the target whose `webSocketDebuggerUrl` is
    /// `debugger_url`, through `client`'s guest, with its token.
    ///
    /// # Errors
    ///
    /// [`CdpError::Connect`] with the guest's status and message (401 without
    /// the right token, 502 when no browser listens) or the I/O error.
    pub async fn connect(client: &GuestClient, debugger_url: &str) -> Result<CdpSession, CdpError> {
        let url = relay_url(client, debugger_url)?;
        let connect_error = |reason: String| CdpError::Connect { url: url.clone(), reason };
        let mut request = url.as_str().into_client_request().map_err(|err| connect_error(err.to_string()))?;
        if let Some(token) = &client.config().token {
            let value = HeaderValue::from_str(&format!("Bearer {}", token.trim()))
                .map_err(|err| connect_error(format!("the token is no header value: {err}")))?;
            request.headers_mut().insert("authorization", value);
        }
        let config = WebSocketConfig::default().max_message_size(Some(MAX_MESSAGE)).max_frame_size(Some(MAX_MESSAGE));
        let opened = tokio::time::timeout(
            CONNECT_TIMEOUT,
            tokio_tungstenite::connect_async_with_config(request, Some(config), false),
        )
        .await
        .map_err(|_| connect_error(format!("no answer within {} s", CONNECT_TIMEOUT.as_secs())))?;
        let (socket, _) = opened.map_err(|err| connect_error(handshake_error(err)))?;
        let (sink, mut stream) = socket.split();
        let waiting = Arc::new(Mutex::new(Waiting::default()));
        let shared = Arc::clone(&waiting);
        let reader = tokio::spawn(async move {
            let reason = loop {
                match stream.next().await {
                    Some(Ok(Message::Text(text))) => dispatch(&shared, text.as_str()),
                    Some(Ok(Message::Close(frame))) => {
                        break frame.map_or_else(
                            || "closed without a reason".to_owned(),
                            |f| format!("close code {}: {}", u16::from(f.code), f.reason),
                        );
                    }
                    Some(Ok(_)) => {}
                    Some(Err(err)) => break err.to_string(),
                    None => break "the connection ended".to_owned(),
                }
            };
            let calls = {
                let mut waiting = lock(&shared);
                waiting.closed = Some(reason.clone());
                std::mem::take(&mut waiting.calls)
            };
            for (_, (_, reply)) in calls {
                let _ = reply.send(Err(CdpError::Closed(reason.clone())));
            }
        });
        Ok(CdpSession {
            sink: tokio::sync::Mutex::new(sink),
            waiting,
            next_id: AtomicU64::new(1),
            timeout: CALL_TIMEOUT,
            reader,
        })
    }

    /// The same session with another default deadline per command.
    #[must_use]
    pub fn with_timeout(mut self, timeout: Duration) -> CdpSession {
        self.timeout = timeout;
        self
    }

    /// Sends `method` with `params` and answers its `result`, within the session's deadline.
    ///
    /// # Errors
    ///
    /// [`CdpError::Protocol`] for the browser's error answer, [`CdpError::Timeout`],
    /// [`CdpError::Closed`].
    pub async fn call(&self, method: &str, params: Value) -> Result<Value, CdpError> {
        self.call_within(method, params, self.timeout).await
    }

    /// [`CdpSession::call`] with its own deadline.
    ///
    /// # Errors
    ///
    /// See [`CdpSession::call`].
    pub async fn call_within(&self, method: &str, params: Value, deadline: Duration) -> Result<Value, CdpError> {
        let id = self.next_id.fetch_add(1, Ordering::Relaxed);
        let (reply, answer) = oneshot::channel();
        {
            let mut waiting = lock(&self.waiting);
            if let Some(reason) = &waiting.closed {
                return Err(CdpError::Closed(reason.clone()));
            }
            waiting.calls.insert(id, (method.to_owned(), reply));
        }
        let text = json!({"id": id, "method": method, "params": params}).to_string();
        let exchange = async {
            self.sink
                .lock()
                .await
                .send(Message::Text(text.into()))
                .await
                .map_err(|err| CdpError::Closed(err.to_string()))?;
            answer.await.map_err(|_| CdpError::Closed("the reader stopped".into()))?
        };
        match tokio::time::timeout(deadline, exchange).await {
            Ok(reply) => {
                lock(&self.waiting).calls.remove(&id);
                reply
            }
            Err(_) => {
                lock(&self.waiting).calls.remove(&id);
                Err(CdpError::Timeout { method: method.to_owned(), after: deadline })
            }
        }
    }

    /// `Runtime.evaluate` of `expression` (awaiting a promise), answering its value as JSON.
    ///
    /// # Errors
    ///
    /// [`CdpError::Script`] when it throws; the errors of [`CdpSession::call`].
    pub async fn evaluate(&self, expression: &str) -> Result<Value, CdpError> {
        let params = json!({"expression": expression, "returnByValue": true, "awaitPromise": true});
        let answer = self.call("Runtime.evaluate", params).await?;
        if let Some(details) = answer.get("exceptionDetails") {
            let text = details
                .pointer("/exception/description")
                .or_else(|| details.get("text"))
                .and_then(Value::as_str)
                .unwrap_or("an exception");
            return Err(CdpError::Script(text.to_owned()));
        }
        Ok(answer.pointer("/result/value").cloned().unwrap_or(Value::Null))
    }

    /// Closes the websocket politely.
    pub async fn close(self) {
        let _ = tokio::time::timeout(Duration::from_secs(2), async { self.sink.lock().await.close().await }).await;
    }
}

fn lock(waiting: &Mutex<Waiting>) -> std::sync::MutexGuard<'_, Waiting> {
    waiting.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Hands a response to its call; events (no `id`) and unknown ids are dropped.
fn dispatch(waiting: &Mutex<Waiting>, text: &str) {
    let Ok(message) = serde_json::from_str::<Value>(text) else {
        tracing::debug!(len = text.len(), "a DevTools message that is not JSON was dropped");
        return;
    };
    let Some(id) = message.get("id").and_then(Value::as_u64) else {
        return;
    };
    let Some((method, reply)) = lock(waiting).calls.remove(&id) else { return };
    let answer = match message.get("error") {
        Some(error) => Err(CdpError::Protocol {
            method,
            code: error.get("code").and_then(Value::as_i64).unwrap_or_default(),
            message: error.get("message").and_then(Value::as_str).unwrap_or("no message").to_owned(),
        }),
        None => Ok(message.get("result").cloned().unwrap_or(Value::Null)),
    };
    let _ = reply.send(answer);
}

/// The guest's refusal of a handshake: its status and error message.
fn handshake_error(err: tungstenite::Error) -> String {
    match err {
        tungstenite::Error::Http(answer) => {
            let status = answer.status().as_u16();
            let message = answer
                .body()
                .as_deref()
                .and_then(|body| serde_json::from_slice::<arena_shared::error::ErrorBody>(body).ok())
                .map(|body| body.message)
                .unwrap_or_default();
            format!("HTTP {status}: {message}")
        }
        other => other.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn debugger_urls_are_rewritten_to_the_relay() {
        let client = GuestClient::new("http://10.0.0.5:5000/", crate::client::ClientConfig::default()).expect("client");
        assert_eq!(
            relay_url(&client, "ws://127.0.0.1:1337/devtools/page/AB12").expect("url"),
            "ws://10.0.0.5:5000/v1/browser/devtools/page/AB12"
        );
        assert_eq!(
            relay_url(&client, "ws://localhost:9222/devtools/browser/x-y").expect("url"),
            "ws://10.0.0.5:5000/v1/browser/devtools/browser/x-y"
        );
        assert!(matches!(relay_url(&client, "ws://127.0.0.1:1337/other"), Err(CdpError::Decode { .. })));
    }

    #[test]
    fn responses_reach_their_call_and_events_are_dropped() {
        let waiting = Mutex::new(Waiting::default());
        let (tx1, mut rx1) = oneshot::channel();
        let (tx2, mut rx2) = oneshot::channel();
        lock(&waiting).calls.insert(1, ("Runtime.evaluate".into(), tx1));
        lock(&waiting).calls.insert(2, ("Page.navigate".into(), tx2));
        dispatch(&waiting, r#"{"method":"Page.loadEventFired","params":{}}"#);
        dispatch(&waiting, r#"{"id":2,"error":{"code":-32000,"message":"Cannot navigate"}}"#);
        dispatch(&waiting, r#"{"id":1,"result":{"result":{"value":3}}}"#);
        assert_eq!(rx1.try_recv().expect("answered").expect("ok"), json!({"result": {"value": 3}}));
        let err = rx2.try_recv().expect("answered").expect_err("an error");
        assert_eq!(err.to_string(), "Page.navigate failed: Cannot navigate (CDP error -32000)");
        assert!(lock(&waiting).calls.is_empty());
    }
}
