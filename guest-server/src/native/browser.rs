//! `GET`, `PUT` and `POST /v1/browser/{*path}`: the browser's DevTools HTTP
//! endpoint, forwarded.
//!
//! Chrome and Edge started with `--remote-debugging-port=<port>` answer plain
//! HTTP on the guest's loopback (`/json/version`, `/json/list`,
//! `PUT /json/new?<url>`, `/json/close/<id>`). Upstream's host reaches that
//! port through a port forward (socat or Caddy on 9222); here the host asks
//! the guest server, which forwards the request with its query string and
//! body to `http://127.0.0.1:<cdp_port>/<path>` and returns the answer's
//! status, content type and bytes as they are.
//!
//! It is not a DevTools client and it does not forward websockets: the host
//! only needs the HTTP endpoints to open, list and close tabs. It never
//! touches the backend, so it holds no platform code.
//!
//! It reaches the configured DevTools port and nothing else: a redirect in the
//! browser's answer is handed back as it is, never followed (to another host or
//! port of the VM's network), and an answer is read up to [`MAX_ANSWER`] bytes.
//! A request's body is read only once a browser is seen listening on the port (a
//! body sent when no browser runs is never buffered), and up to
//! [`crate::config::JSON_BODY_BYTES`] (the DevTools endpoints take no bodies).

use std::sync::OnceLock;
use std::time::Duration;

use axum::body::Bytes;
use axum::extract::{Path, RawQuery, State};
use axum::http::{header, HeaderValue, Method, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::routing::any;
use axum::{Json, Router};

use arena_shared::error::{ErrorBody, ErrorCode};

use crate::error::ApiError;
use crate::state::AppState;

/// Longest a DevTools answer may take: opening a tab answers at once, before the page loads.
const MAX_DEADLINE: Duration = Duration::from_secs(30);

/// Largest DevTools answer forwarded (the JSON endpoints answer a few KB).
const MAX_ANSWER: usize = 16 << 20;

pub(crate) fn routes() -> Router<AppState> {
    Router::new().route("/v1/browser/{*path}", any(forward))
}

/// One HTTP client for every forwarded request, so connections to the browser are reused.
fn http() -> Result<&'static reqwest::Client, ApiError> {
    static CLIENT: OnceLock<reqwest::Client> = OnceLock::new();
    if let Some(client) = CLIENT.get() {
        return Ok(client);
    }
    // The browser is on loopback: a proxy from the environment must not get in between.
    let client = reqwest::Client::builder()
        .no_proxy()
        .redirect(reqwest::redirect::Policy::none())
        .connect_timeout(Duration::from_secs(5))
        .build()
        .map_err(|err| {
            ApiError::Desktop(crate::desktop::DesktopError::Os { op: "browser", message: err.to_string() })
        })?;
    Ok(CLIENT.get_or_init(|| client))
}

/// An error body with a status [`ApiError`] has no variant for (502).
fn error_response(status: StatusCode, code: ErrorCode, message: String) -> Response {
    tracing::warn!(status = status.as_u16(), %message, "browser request failed");
    (status, Json(ErrorBody { error: code, message })).into_response()
}

/// How long the check that a browser listens may take (it is on loopback).
const CONNECT_DEADLINE: Duration = Duration::from_secs(5);

fn no_browser(port: u16) -> Response {
    error_response(
        StatusCode::BAD_GATEWAY,
        ErrorCode::Internal,
        format!(
            "no browser is listening on the debugging port {port}: start Chrome with --remote-debugging-port={port}"
        ),
    )
}

async fn forward(
    State(state): State<AppState>,
    method: Method,
    Path(path): Path<String>,
    RawQuery(query): RawQuery,
    body: axum::body::Body,
) -> Result<Response, ApiError> {
    let method = match method {
        Method::GET => reqwest::Method::GET,
        Method::PUT => reqwest::Method::PUT,
        Method::POST => reqwest::Method::POST,
        other => {
            return Err(ApiError::BadRequest(format!(
                "method {other} is not forwarded to the browser (GET, PUT and POST are)"
            )))
        }
    };
    let port = state.config.cdp_port;
    // Before the body is read: is anyone listening?
    let listening = tokio::time::timeout(CONNECT_DEADLINE, tokio::net::TcpStream::connect(("127.0.0.1", port))).await;
    if !matches!(listening, Ok(Ok(_))) {
        return Ok(no_browser(port));
    }
    let body: Bytes = match axum::body::to_bytes(body, crate::config::JSON_BODY_BYTES).await {
        Ok(body) => body,
        Err(err) => {
            return Err(ApiError::PayloadTooLarge(format!(
                "the body could not be read within {} bytes: {err}",
                crate::config::JSON_BODY_BYTES
            )))
        }
    };
    let mut url = reqwest::Url::parse(&format!("http://127.0.0.1:{port}/"))
        .map_err(|err| ApiError::BadRequest(format!("cannot build the DevTools URL: {err}")))?;
    // `set_path` percent-encodes what needs it; the query goes on as the host wrote it,
    // since `/json/new?<url>` takes a whole URL there.
    url.set_path(path.trim_start_matches('/'));
    url.set_query(query.as_deref());
    let deadline = state.call_timeout().min(MAX_DEADLINE);
    let mut request = http()?.request(method, url.clone()).timeout(deadline);
    if !body.is_empty() {
        request = request.body(body);
    }
    let answer = match request.send().await {
        Ok(answer) => answer,
        Err(err) if err.is_connect() => return Ok(no_browser(port)),
        Err(err) if err.is_timeout() => {
            return Ok(error_response(
                StatusCode::GATEWAY_TIMEOUT,
                ErrorCode::Timeout,
                format!(
                    "the browser on port {port} did not answer {} within {} ms",
                    crate::error::clip(url.path()),
                    deadline.as_millis()
                ),
            ))
        }
        Err(err) => {
            return Ok(error_response(
                StatusCode::BAD_GATEWAY,
                ErrorCode::Internal,
                format!("the browser on port {port} failed on {}: {err}", crate::error::clip(url.path())),
            ))
        }
    };
    let status = StatusCode::from_u16(answer.status().as_u16()).unwrap_or(StatusCode::BAD_GATEWAY);
    let content_type =
        answer.headers().get(reqwest::header::CONTENT_TYPE).and_then(|v| HeaderValue::from_bytes(v.as_bytes()).ok());
    let location =
        answer.headers().get(reqwest::header::LOCATION).and_then(|v| HeaderValue::from_bytes(v.as_bytes()).ok());
    let mut answer = answer;
    let mut bytes = Vec::new();
    loop {
        match answer.chunk().await {
            Ok(Some(chunk)) if bytes.len() + chunk.len() > MAX_ANSWER => {
                return Ok(error_response(
                    StatusCode::BAD_GATEWAY,
                    ErrorCode::Internal,
                    format!(
                        "the browser's answer to {} is over {MAX_ANSWER} bytes; it was not forwarded",
                        crate::error::clip(url.path())
                    ),
                ));
            }
            Ok(Some(chunk)) => bytes.extend_from_slice(&chunk),
            Ok(None) => break,
            Err(err) => {
                return Ok(error_response(
                    StatusCode::BAD_GATEWAY,
                    ErrorCode::Internal,
                    format!(
                        "the browser on port {port} broke off its answer to {}: {err}",
                        crate::error::clip(url.path())
                    ),
                ))
            }
        }
    }
    let mut response = (status, bytes).into_response();
    if let Some(content_type) = content_type {
        response.headers_mut().insert(header::CONTENT_TYPE, content_type);
    }
    if let Some(location) = location {
        response.headers_mut().insert(header::LOCATION, location);
    }
    Ok(response)
}
