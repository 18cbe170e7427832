//! Request guards: bearer-token authentication and the cross-site request check.
//!
//! - When a token is configured, every request but the readiness probes
//!   (`/probe`, `/v1/health`) must carry `Authorization: Bearer <token>`, checked
//!   by the project's one bearer check (constant time, the scheme in any case).
//! - A request that carries an `Origin` header or `Sec-Fetch-Site: cross-site`
//!   comes from a web page (host clients send neither) and is refused, so a page
//!   browsed inside the VM cannot drive the server with a cross-origin form post
//!   (upstream's CSRF hole, waa-api.md §a.5 item 8).
//! - Without a token, the `Host` header must name this server: an IP address, a
//!   loopback name (`localhost`), or a name given with `--allow-host`. A page in the
//!   VM's browser that reaches the server through DNS rebinding sends its own domain
//!   name as the host, so it is refused even for simple GETs (which carry no
//!   `Origin`). An address cannot come from rebinding, so addresses are accepted.
//! - With a token, a request that shows it takes its connection off probation
//!   ([`crate::serve::ConnContext::authenticated`]); a 401 closes its connection, so
//!   a client without the token cannot keep a slot by sending requests.

use axum::extract::{Request, State};
use axum::http::{header, HeaderMap, StatusCode};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use axum::Json;

use crate::error::ApiError;
use crate::state::AppState;

/// Paths that answer without a token, so readiness can be polled before provisioning finishes.
const OPEN_PATHS: &[&str] = &["/probe", "/v1/health"];

/// Whether the request proved it may see everything: it carried the right token, or
/// none is configured. Set on every request that passes [`guard`]; open routes
/// (`/v1/health`) answer less to a caller without it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Authorized(pub bool);

/// Longest request target (path and query) served; upstream's Werkzeug has no limit,
/// but no route needs more, and a bigger one is refused with a body that says so.
pub const MAX_URI_BYTES: usize = 16 << 10;
/// Most header bytes (names and values) served.
pub const MAX_HEADER_BYTES: usize = 64 << 10;

/// Middleware enforcing the token and the cross-site check.
pub async fn guard(State(state): State<AppState>, mut request: Request, next: Next) -> Response {
    let path = request.uri().path().to_owned();
    let native = path.starts_with("/v1/");
    let target = request.uri().path_and_query().map_or(0, |pq| pq.as_str().len());
    if target > MAX_URI_BYTES {
        return refuse(
            native,
            StatusCode::URI_TOO_LONG,
            &format!(
                "the request target is {target} bytes; at most {MAX_URI_BYTES} are served (send data in the body)"
            ),
        );
    }
    let header_bytes: usize = request.headers().iter().map(|(name, value)| name.as_str().len() + value.len()).sum();
    if header_bytes > MAX_HEADER_BYTES {
        return refuse(
            native,
            StatusCode::REQUEST_HEADER_FIELDS_TOO_LARGE,
            &format!("the headers are {header_bytes} bytes; at most {MAX_HEADER_BYTES} are served"),
        );
    }
    if let Some(reason) = cross_site(request.headers()) {
        return refuse(native, StatusCode::FORBIDDEN, &format!("cross-site request refused: {reason}"));
    }
    if state.token.is_none() {
        if let Err(host) = host_allowed(request.headers(), &state.config.allow_host) {
            return refuse(
                native,
                StatusCode::FORBIDDEN,
                &format!("Host {host:?} is not this server (without a token only addresses, localhost and --allow-host names are served)"),
            );
        }
    }
    let authorized = state.token.as_deref().is_none_or(|token| token_matches(request.headers(), token));
    if authorized {
        if let Some(conn) = request.extensions().get::<crate::serve::ConnContext>() {
            conn.authenticated();
        }
    } else if !OPEN_PATHS.contains(&path.as_str()) {
        let mut res =
            refuse(native, StatusCode::UNAUTHORIZED, "missing or wrong bearer token (Authorization: Bearer <token>)");
        res.headers_mut().insert(header::CONNECTION, axum::http::HeaderValue::from_static("close"));
        return res;
    }
    request.extensions_mut().insert(Authorized(authorized));
    next.run(request).await
}

/// Whether the request's `Host` names this server; `Err` carries the refused host.
fn host_allowed(headers: &HeaderMap, allowed: &[String]) -> Result<(), String> {
    let Some(value) = headers.get(header::HOST) else {
        // HTTP/1.0 clients may send none; browsers always do.
        return Ok(());
    };
    let Ok(host) = value.to_str() else { return Err("<binary>".to_owned()) };
    let name = arena_shared::host_header::name(host);
    let listed = allowed.iter().any(|a| a.trim().eq_ignore_ascii_case(name));
    if name.parse::<std::net::IpAddr>().is_ok() || arena_shared::host_header::is_localhost(name) || listed {
        Ok(())
    } else {
        Err(host.to_owned())
    }
}

fn cross_site(headers: &HeaderMap) -> Option<String> {
    if let Some(origin) = headers.get(header::ORIGIN) {
        return Some(format!("Origin {:?}", origin.to_str().unwrap_or("<binary>")));
    }
    match headers.get("sec-fetch-site").and_then(|v| v.to_str().ok()) {
        Some(site @ ("cross-site" | "same-site")) => Some(format!("Sec-Fetch-Site {site}")),
        _ => None,
    }
}

/// The project's one bearer check ([`arena_shared::token::bearer_matches`]: constant
/// time, the scheme in any case).
fn token_matches(headers: &HeaderMap, token: &str) -> bool {
    arena_shared::token::bearer_matches(headers.get(header::AUTHORIZATION).map(|v| v.as_bytes()), token)
}

fn refuse(native: bool, status: StatusCode, message: &str) -> Response {
    tracing::warn!(%status, message, "request refused");
    if native {
        let err = match status {
            StatusCode::UNAUTHORIZED => ApiError::Unauthorized(message.to_owned()),
            StatusCode::FORBIDDEN => ApiError::Forbidden(message.to_owned()),
            _ => ApiError::BadRequest(message.to_owned()),
        };
        let mut res = err.into_response();
        *res.status_mut() = status;
        return res;
    }
    (status, Json(serde_json::json!({"status": "error", "message": message}))).into_response()
}
