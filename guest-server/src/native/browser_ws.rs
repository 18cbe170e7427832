//! `GET /v1/browser/devtools/{*path}` with `Upgrade: websocket`: the browser's
//! DevTools websocket, relayed.
//!
//! The DevTools protocol (CDP) itself runs over a websocket whose address the
//! JSON endpoints hand out as `webSocketDebuggerUrl`
//! (`ws://127.0.0.1:<port>/devtools/page/<id>`). That address is inside the VM;
//! the host reaches it here instead, through the same guards as every other
//! route (the bearer token, and the `Origin`/`Host` checks that keep the VM's
//! own web pages out), and this module connects to
//! `ws://127.0.0.1:<cdp_port>/devtools/<path>` and relays messages both ways
//! until either side closes.
//!
//! Limits:
//!
//! - the browser is connected to *before* the upgrade, so a browser that is
//!   not there is a plain `502` (and a slow one `504`), not a socket that closes at once;
//! - a message from the host is at most [`MAX_FROM_HOST`] bytes and one from the
//!   browser at most [`MAX_FROM_BROWSER`]; a bigger one closes both sides with
//!   close code 1009 (message too big), and nothing of it is forwarded;
//! - a relay with no message either way for [`IDLE`] is closed (1001);
//! - on server shutdown every relay closes both sides (1001) at once, and a
//!   relay holds its connection's slot in `--max-connections` until it ends
//!   (see [`crate::serve::ConnContext`]).
//!
//! It does not read or change the messages: it is a pipe, not a DevTools client.
//! Like the HTTP forward ([`super::browser`]) it reaches the configured
//! DevTools port on loopback and nothing else.

use std::time::Duration;

use axum::extract::rejection::ExtensionRejection;
use axum::extract::ws::rejection::WebSocketUpgradeRejection;
use axum::extract::ws::{self, CloseFrame, WebSocket, WebSocketUpgrade};
use axum::extract::{Extension, Path, State};
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use axum::routing::any;
use axum::{Json, Router};
use futures_util::{SinkExt as _, StreamExt as _};
use tokio_tungstenite::tungstenite::protocol::frame::coding::CloseCode;
use tokio_tungstenite::tungstenite::protocol::{CloseFrame as TCloseFrame, WebSocketConfig};
use tokio_tungstenite::tungstenite::{self, Message as TMessage};
use tokio_util::sync::CancellationToken;

use arena_shared::error::{ErrorBody, ErrorCode};

use crate::serve::ConnContext;
use crate::state::AppState;

/// Largest message the host may send (DevTools commands are a few KB; a script to evaluate tens of KB).
pub(crate) const MAX_FROM_HOST: usize = 1 << 20;
/// Largest message the browser may send (a page's HTML, a screenshot in base64).
pub(crate) const MAX_FROM_BROWSER: usize = 64 << 20;
/// A relay with no message either way for this long is closed.
pub(crate) const IDLE: Duration = Duration::from_secs(600);
/// Longest the browser may take to accept the websocket.
const CONNECT_DEADLINE: Duration = Duration::from_secs(10);
/// Close code: the message is over the bound (RFC 6455 §7.4.1).
const TOO_BIG: u16 = 1009;
/// Close code: going away (idle, shutdown, the other side went).
const GOING_AWAY: u16 = 1001;

pub(crate) fn routes() -> Router<AppState> {
    Router::new().route("/v1/browser/devtools/{*path}", any(relay_route))
}

fn error_response(status: StatusCode, code: ErrorCode, message: String) -> Response {
    tracing::warn!(status = status.as_u16(), %message, "DevTools websocket refused");
    (status, Json(ErrorBody { error: code, message })).into_response()
}

/// Whether `path` (after `/devtools/`) is a DevTools target path: `page/<id>`,
/// `browser/<id>` and the like, made of letters, digits, `-`, `_` and `/`.
fn valid_path(path: &str) -> bool {
    !path.is_empty()
        && path.len() <= 256
        && !path.split('/').any(|segment| segment.is_empty() || segment == "." || segment == "..")
        && path.chars().all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '/'))
}

async fn relay_route(
    State(state): State<AppState>,
    Path(path): Path<String>,
    context: Result<Extension<ConnContext>, ExtensionRejection>,
    upgrade: Result<WebSocketUpgrade, WebSocketUpgradeRejection>,
) -> Response {
    let path = path.trim_start_matches('/').to_owned();
    let upgrade = match upgrade {
        Ok(upgrade) => upgrade,
        Err(rejection) => {
            return error_response(
                StatusCode::BAD_REQUEST,
                ErrorCode::BadRequest,
                format!(
                    "/v1/browser/devtools/{path} is the browser's DevTools websocket: connect with GET, \
                     Connection: Upgrade and Upgrade: websocket ({}); the DevTools HTTP endpoints are under \
                     /v1/browser/json/...",
                    rejection.body_text()
                ),
            )
        }
    };
    if !valid_path(&path) {
        return error_response(
            StatusCode::BAD_REQUEST,
            ErrorCode::BadRequest,
            format!("{path:?} is not a DevTools target path (page/<id> or browser/<id>)"),
        );
    }
    let port = state.config.cdp_port;
    let url = format!("ws://127.0.0.1:{port}/devtools/{path}");
    let config =
        WebSocketConfig::default().max_message_size(Some(MAX_FROM_BROWSER)).max_frame_size(Some(MAX_FROM_BROWSER));
    let connect = tokio_tungstenite::connect_async_with_config(url.as_str(), Some(config), false);
    let browser = match tokio::time::timeout(CONNECT_DEADLINE, connect).await {
        Ok(Ok((browser, _))) => browser,
        Ok(Err(tungstenite::Error::Io(err))) if err.kind() == std::io::ErrorKind::ConnectionRefused => {
            return error_response(
                StatusCode::BAD_GATEWAY,
                ErrorCode::Internal,
                format!(
                    "no browser is listening on the debugging port {port}: start Chrome with --remote-debugging-port={port}"
                ),
            )
        }
        Ok(Err(tungstenite::Error::Http(answer))) => {
            return error_response(
                StatusCode::BAD_GATEWAY,
                ErrorCode::Internal,
                format!(
                    "the browser on port {port} refused the websocket /devtools/{path} with HTTP {} (is the target id current?)",
                    answer.status()
                ),
            )
        }
        Ok(Err(err)) => {
            return error_response(
                StatusCode::BAD_GATEWAY,
                ErrorCode::Internal,
                format!("the browser on port {port} failed to open the websocket /devtools/{path}: {err}"),
            )
        }
        Err(_) => {
            return error_response(
                StatusCode::GATEWAY_TIMEOUT,
                ErrorCode::Timeout,
                format!(
                    "the browser on port {port} did not accept the websocket /devtools/{path} within {} s",
                    CONNECT_DEADLINE.as_secs()
                ),
            )
        }
    };
    let context = context.ok().map(|Extension(context)| context);
    tracing::info!(%path, "relaying a DevTools websocket");
    upgrade.max_message_size(MAX_FROM_HOST).max_frame_size(MAX_FROM_HOST).on_upgrade(move |host| async move {
        let stop = context.as_ref().map(|c| c.shutdown.clone()).unwrap_or_default();
        let why = relay(host, browser, &stop).await;
        tracing::info!(%path, why, "DevTools websocket relay ended");
        // The connection's slot is given back only now.
        drop(context);
    })
}

/// Why a relay ended, for the log.
type Ended = &'static str;
/// A close frame to send one side (code and reason), if that side is still there.
type Closing = Option<(u16, &'static str)>;

/// Relays `host` ⇄ `browser` until one side closes, a message is over its bound,
/// the relay is idle for [`IDLE`], or `stop` is cancelled; then closes both.
async fn relay<B>(host: WebSocket, browser: B, stop: &CancellationToken) -> Ended
where
    B: futures_util::Stream<Item = Result<TMessage, tungstenite::Error>>
        + futures_util::Sink<TMessage, Error = tungstenite::Error>
        + Unpin,
{
    let (mut host_tx, mut host_rx) = host.split();
    let (mut browser_tx, mut browser_rx) = browser.split();
    let (host_close, browser_close, why): (Closing, Closing, Ended) = loop {
        tokio::select! {
            () = stop.cancelled() => {
                break (Some((GOING_AWAY, "the guest server is shutting down")), Some((GOING_AWAY, "")), "server shutdown");
            }
            () = tokio::time::sleep(IDLE) => {
                break (Some((GOING_AWAY, "idle")), Some((GOING_AWAY, "")), "idle");
            }
            message = host_rx.next() => match message {
                Some(Ok(ws::Message::Close(frame))) => {
                    let code = frame.as_ref().map_or(1000, |f| f.code);
                    break (None, Some((code, "")), "the host closed");
                }
                Some(Ok(message)) => {
                    if let Some(message) = to_browser(message) {
                        if browser_tx.send(message).await.is_err() {
                            break (Some((GOING_AWAY, "the browser went away")), None, "the browser went away");
                        }
                    }
                }
                Some(Err(err)) if too_big(&err) => {
                    break (
                        Some((TOO_BIG, "message over the guest's bound for host messages")),
                        Some((GOING_AWAY, "")),
                        "a host message over the bound",
                    );
                }
                Some(Err(_)) | None => break (None, Some((GOING_AWAY, "")), "the host went away"),
            },
            message = browser_rx.next() => match message {
                Some(Ok(TMessage::Close(frame))) => {
                    let code = frame.as_ref().map_or(1000, |f| u16::from(f.code));
                    break (Some((code, "the browser closed the DevTools session")), None, "the browser closed");
                }
                Some(Ok(message)) => {
                    if let Some(message) = to_host(message) {
                        if host_tx.send(message).await.is_err() {
                            break (None, Some((GOING_AWAY, "")), "the host went away");
                        }
                    }
                }
                Some(Err(tungstenite::Error::Capacity(_))) => {
                    break (
                        Some((TOO_BIG, "the browser sent a message over the guest's bound")),
                        Some((TOO_BIG, "")),
                        "a browser message over the bound",
                    );
                }
                Some(Err(_)) | None => {
                    break (Some((GOING_AWAY, "the browser went away")), None, "the browser went away");
                }
            },
        }
    };
    // Each close is a courtesy with a short deadline: a side that does not read is dropped.
    let grace = Duration::from_secs(2);
    if let Some((code, reason)) = host_close {
        let frame = CloseFrame { code, reason: reason.into() };
        let _ = tokio::time::timeout(grace, host_tx.send(ws::Message::Close(Some(frame)))).await;
    }
    if let Some((code, reason)) = browser_close {
        let frame = TCloseFrame { code: CloseCode::from(code), reason: reason.into() };
        let _ = tokio::time::timeout(grace, browser_tx.send(TMessage::Close(Some(frame)))).await;
    }
    why
}

/// Whether an error of the host's socket is a message or frame over the bound.
fn too_big(err: &axum::Error) -> bool {
    let mut source: Option<&(dyn std::error::Error + 'static)> = Some(err);
    while let Some(err) = source {
        if let Some(tungstenite::Error::Capacity(_)) = err.downcast_ref::<tungstenite::Error>() {
            return true;
        }
        source = err.source();
    }
    false
}

fn to_browser(message: ws::Message) -> Option<TMessage> {
    Some(match message {
        ws::Message::Text(text) => TMessage::Text(text.as_str().to_owned().into()),
        ws::Message::Binary(bytes) => TMessage::Binary(bytes),
        // Each side answers its own pings.
        ws::Message::Ping(_) | ws::Message::Pong(_) | ws::Message::Close(_) => return None,
    })
}

fn to_host(message: TMessage) -> Option<ws::Message> {
    Some(match message {
        TMessage::Text(text) => ws::Message::Text(text.as_str().to_owned().into()),
        TMessage::Binary(bytes) => ws::Message::Binary(bytes),
        TMessage::Ping(_) | TMessage::Pong(_) | TMessage::Close(_) | TMessage::Frame(_) => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::valid_path;

    #[test]
    fn only_target_paths_are_relayed() {
        assert!(valid_path("page/8A1F"));
        assert!(valid_path("browser/1b6e-44a0_9"));
        for bad in ["", "page/../x", "page//x", "page/a?b", "page/a b", "page/%2e%2e", "./page"] {
            assert!(!valid_path(bad), "{bad:?}");
        }
    }
}
