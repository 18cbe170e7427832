//! Request guards: bearer-token authentication and the cross-site request check.
//!
//! - When a token is configured, every request but the readiness probes
//!   (`/probe`, `/v1/health`) must carry `Authorization: Bearer <token>`;
//!   the comparison is constant-time.
//! - A request that carries an `Origin` header or `Sec-Fetch-Site: cross-site`
//!   comes from a web page (host clients send neither) and is refused, so a page
//!   browsed inside the VM cannot drive the server with a cross-origin form post
//!   (upstream's CSRF hole, waa-api.md §a.5 item 8).

use axum::extract::{Request, State};
use axum::http::{header, HeaderMap, StatusCode};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use axum::Json;
use subtle::ConstantTimeEq;

use crate::error::ApiError;
use crate::state::AppState;

/// Paths that answer without a token, so readiness can be polled before provisioning finishes.
const OPEN_PATHS: &[&str] = &["/probe", "/v1/health"];

/// Middleware enforcing the token and the cross-site check.
pub async fn guard(State(state): State<AppState>, request: Request, next: Next) -> Response {
    let path = request.uri().path().to_owned();
    let native = path.starts_with("/v1/");
    if let Some(reason) = cross_site(request.headers()) {
        return refuse(native, StatusCode::FORBIDDEN, &format!("cross-site request refused: {reason}"));
    }
    if let Some(token) = &state.token {
        if !OPEN_PATHS.contains(&path.as_str()) && !token_matches(request.headers(), token) {
            return refuse(
                native,
                StatusCode::UNAUTHORIZED,
                "missing or wrong bearer token (Authorization: Bearer <token>)",
            );
        }
    }
    next.run(request).await
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

fn token_matches(headers: &HeaderMap, token: &str) -> bool {
    let Some(value) = headers.get(header::AUTHORIZATION).and_then(|v| v.to_str().ok()) else {
        return false;
    };
    let Some(given) = value.strip_prefix("Bearer ").or_else(|| value.strip_prefix("bearer ")) else {
        return false;
    };
    given.trim().as_bytes().ct_eq(token.as_bytes()).into()
}

fn refuse(native: bool, status: StatusCode, message: &str) -> Response {
    tracing::warn!(%status, message, "request refused");
    if native {
        let err = match status {
            StatusCode::UNAUTHORIZED => ApiError::Unauthorized(message.to_owned()),
            _ => ApiError::BadRequest(message.to_owned()),
        };
        let mut res = err.into_response();
        *res.status_mut() = status;
        return res;
    }
    (status, Json(serde_json::json!({"status": "error", "message": message}))).into_response()
}
