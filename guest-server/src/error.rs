//! The two error shapes the server answers with, and the backend's error they map.
//!
//! - [`DesktopError`]: what a backend call fails with, the same variants on every
//!   platform (re-exported as `crate::desktop::DesktopError`, the trait's error). It
//!   is defined here, beside its HTTP mapping, so that this module imports nothing
//!   from `desktop` (which quotes input through [`clip`]).
//! - [`ApiError`]: native `/v1/` routes, an [`ErrorBody`] with a precise status.
//! - [`WaaError`]: legacy routes, upstream's `{"status":"error","message":...}`
//!   with 500 for everything the catch-all handler would catch, or the exact
//!   status and body a route returns itself (see [`WaaError::custom`]).
//!
//! Both log server-side failures once, here, and never panic. Neither echoes more
//! than a bounded prefix of what the client sent: input quoted in a message goes
//! through [`clip`], and a whole message is cut at [`MAX_MESSAGE_BYTES`].

use axum::extract::rejection::{JsonRejection, QueryRejection};
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use axum::Json;

use arena_shared::error::{ErrorBody, ErrorCode};

/// What went wrong in a backend call. The same variants on every platform.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DesktopError {
    /// The caller asked for something malformed or impossible; the message says what.
    #[error("{0}")]
    InvalidInput(String),
    /// A path, window, key or value does not exist.
    #[error("{0}")]
    NotFound(String),
    /// The thing exists and may not be touched.
    #[error("{0}")]
    PermissionDenied(String),
    /// The thing to be created exists already.
    #[error("{0}")]
    AlreadyExists(String),
    /// This backend cannot do this.
    #[error("{0}")]
    Unsupported(String),
    /// The call did not finish within its deadline.
    #[error("{op} timed out after {ms} ms")]
    Timeout { op: &'static str, ms: u64 },
    /// The guest began shutting down and stopped the call.
    #[error("{op} was stopped: the guest is shutting down")]
    ShuttingDown { op: &'static str },
    /// The operating system refused; `message` carries its words.
    #[error("{op}: {message}")]
    Os { op: &'static str, message: String },
}

impl DesktopError {
    /// Maps an I/O error about `what` (usually a path) onto the closest variant.
    pub fn io(op: &'static str, what: &str, err: std::io::Error) -> DesktopError {
        use std::io::ErrorKind;
        match err.kind() {
            ErrorKind::NotFound => DesktopError::NotFound(format!("{what}: not found")),
            ErrorKind::PermissionDenied => DesktopError::PermissionDenied(format!("{what}: permission denied")),
            ErrorKind::AlreadyExists => DesktopError::AlreadyExists(format!("{what}: already exists")),
            _ => DesktopError::Os { op, message: format!("{what}: {err}") },
        }
    }
}

/// Most bytes of client input quoted in one error message.
pub const MAX_ECHO_BYTES: usize = 256;
/// Most bytes of one error message (a message quoting several inputs, a chain of causes).
pub const MAX_MESSAGE_BYTES: usize = 4096;

/// `text` for quoting in a message: whole when short, else its first
/// [`MAX_ECHO_BYTES`] (on a character boundary) and how long it was.
pub fn clip(text: &str) -> std::borrow::Cow<'_, str> {
    clip_to(text, MAX_ECHO_BYTES)
}

fn clip_to(text: &str, max: usize) -> std::borrow::Cow<'_, str> {
    if text.len() <= max {
        return std::borrow::Cow::Borrowed(text);
    }
    let mut end = max;
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    std::borrow::Cow::Owned(format!("{}... ({} bytes in all)", &text[..end], text.len()))
}

/// An error from a native route.
#[derive(Debug, thiserror::Error)]
pub enum ApiError {
    #[error("{0}")]
    BadRequest(String),
    #[error("{0}")]
    Unauthorized(String),
    #[error("{0}")]
    Forbidden(String),
    #[error("{0}")]
    NotFound(String),
    #[error("{0}")]
    Conflict(String),
    #[error("{0}")]
    PayloadTooLarge(String),
    /// The guest is at a limit of work running at once (`--max-programs`).
    #[error("{0}")]
    Busy(String),
    #[error(transparent)]
    Desktop(#[from] DesktopError),
}

impl ApiError {
    fn status_and_code(&self) -> (StatusCode, ErrorCode) {
        match self {
            ApiError::BadRequest(_) => (StatusCode::BAD_REQUEST, ErrorCode::BadRequest),
            ApiError::Unauthorized(_) => (StatusCode::UNAUTHORIZED, ErrorCode::Unauthorized),
            ApiError::Forbidden(_) => (StatusCode::FORBIDDEN, ErrorCode::Forbidden),
            ApiError::NotFound(_) => (StatusCode::NOT_FOUND, ErrorCode::NotFound),
            ApiError::Conflict(_) => (StatusCode::CONFLICT, ErrorCode::Conflict),
            ApiError::PayloadTooLarge(_) => (StatusCode::PAYLOAD_TOO_LARGE, ErrorCode::PayloadTooLarge),
            ApiError::Busy(_) => (StatusCode::SERVICE_UNAVAILABLE, ErrorCode::Unavailable),
            ApiError::Desktop(err) => match err {
                DesktopError::InvalidInput(_) => (StatusCode::BAD_REQUEST, ErrorCode::BadRequest),
                DesktopError::NotFound(_) => (StatusCode::NOT_FOUND, ErrorCode::NotFound),
                DesktopError::PermissionDenied(_) => (StatusCode::FORBIDDEN, ErrorCode::Forbidden),
                DesktopError::AlreadyExists(_) => (StatusCode::CONFLICT, ErrorCode::Conflict),
                DesktopError::Unsupported(_) => (StatusCode::NOT_IMPLEMENTED, ErrorCode::Unsupported),
                DesktopError::Timeout { .. } => (StatusCode::GATEWAY_TIMEOUT, ErrorCode::Timeout),
                DesktopError::ShuttingDown { .. } => (StatusCode::SERVICE_UNAVAILABLE, ErrorCode::Unavailable),
                DesktopError::Os { .. } => (StatusCode::INTERNAL_SERVER_ERROR, ErrorCode::Internal),
            },
        }
    }
}

impl From<crate::programs::Busy> for ApiError {
    fn from(busy: crate::programs::Busy) -> ApiError {
        ApiError::Busy(busy.to_string())
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let (status, code) = self.status_and_code();
        if status.is_server_error() {
            tracing::error!(error = %self, "native request failed");
        } else {
            tracing::debug!(error = %self, "native request rejected");
        }
        let message = clip_to(&self.to_string(), MAX_MESSAGE_BYTES).into_owned();
        (status, Json(ErrorBody { error: code, message })).into_response()
    }
}

impl From<JsonRejection> for ApiError {
    fn from(rejection: JsonRejection) -> ApiError {
        match rejection {
            JsonRejection::BytesRejection(err) if err.status() == StatusCode::PAYLOAD_TOO_LARGE => {
                ApiError::PayloadTooLarge(err.body_text())
            }
            other => ApiError::BadRequest(format!("invalid JSON body: {}", other.body_text())),
        }
    }
}

impl From<QueryRejection> for ApiError {
    fn from(rejection: QueryRejection) -> ApiError {
        ApiError::BadRequest(format!("invalid query: {}", rejection.body_text()))
    }
}

/// `Json<T>` whose rejections are [`ApiError`]s, so bad bodies get the one error shape.
#[derive(Debug, Clone, Copy, Default, axum::extract::FromRequest)]
#[from_request(via(axum::Json), rejection(ApiError))]
pub struct AppJson<T>(pub T);

impl<T: serde::Serialize> IntoResponse for AppJson<T> {
    fn into_response(self) -> Response {
        Json(self.0).into_response()
    }
}

/// `Query<T>` whose rejections are [`ApiError`]s, and which refuses a query string
/// that is not UTF-8 once percent-decoded (axum's own would silently replace the
/// bad bytes, so a path could name a different file than the client meant).
#[derive(Debug, Clone, Copy, Default)]
pub struct AppQuery<T>(pub T);

impl<T, S> axum::extract::FromRequestParts<S> for AppQuery<T>
where
    T: serde::de::DeserializeOwned,
    S: Send + Sync,
{
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut axum::http::request::Parts, state: &S) -> Result<Self, ApiError> {
        if let Some(query) = parts.uri.query() {
            check_utf8_query(query)?;
        }
        let axum::extract::Query(value) = axum::extract::Query::<T>::from_request_parts(parts, state).await?;
        Ok(AppQuery(value))
    }
}

/// Refuses a query string whose decoded names or values are not UTF-8, naming the
/// parameter and the byte offset of the first bad byte.
fn check_utf8_query(query: &str) -> Result<(), ApiError> {
    for pair in query.split('&').filter(|p| !p.is_empty()) {
        let (name, value) = pair.split_once('=').unwrap_or((pair, ""));
        for (what, raw) in [("name", name), ("value", value)] {
            let bytes = crate::urlencoded::decode(raw);
            if let Err(err) = std::str::from_utf8(&bytes) {
                let at = err.valid_up_to();
                let shown = String::from_utf8_lossy(&crate::urlencoded::decode(name)).into_owned();
                return Err(ApiError::BadRequest(format!(
                    "the query parameter {shown:?} has a {what} that is not UTF-8: byte {:#04x} at offset {at} \
                     (percent-encode the UTF-8 bytes of the text)",
                    bytes[at]
                )));
            }
        }
    }
    Ok(())
}

/// An error from a legacy WAA route.
///
/// [`WaaError::Catch`] is upstream's catch-all: `{"status":"error","message":m}` with 500.
/// [`WaaError::Custom`] is a response a route returns on purpose (a 400 with
/// `{"error": ...}`, a 404 text, ...), kept byte-compatible with upstream.
#[derive(Debug)]
pub enum WaaError {
    Catch(String),
    Custom(Box<Response>),
}

impl WaaError {
    /// Upstream's catch-all 500 with `message`.
    pub fn catch(message: impl Into<String>) -> WaaError {
        WaaError::Catch(message.into())
    }

    /// A response the upstream route itself returns.
    pub fn custom(response: impl IntoResponse) -> WaaError {
        WaaError::Custom(Box::new(response.into_response()))
    }

    /// Werkzeug's 404 text for an unknown URL, as the catch-all renders it.
    pub fn not_found_route() -> WaaError {
        WaaError::catch(
            "404 Not Found: The requested URL was not found on the server. If you entered the URL manually please check your spelling and try again.",
        )
    }

    /// Werkzeug's 405 text, as the catch-all renders it.
    pub fn method_not_allowed() -> WaaError {
        WaaError::catch("405 Method Not Allowed: The method is not allowed for the requested URL.")
    }
}

impl From<DesktopError> for WaaError {
    fn from(err: DesktopError) -> WaaError {
        WaaError::Catch(err.to_string())
    }
}

impl IntoResponse for WaaError {
    fn into_response(self) -> Response {
        match self {
            WaaError::Catch(message) => {
                let message = clip_to(&message, MAX_MESSAGE_BYTES).into_owned();
                tracing::warn!(%message, "WAA request failed");
                (StatusCode::INTERNAL_SERVER_ERROR, Json(serde_json::json!({"status": "error", "message": message})))
                    .into_response()
            }
            WaaError::Custom(response) => *response,
        }
    }
}
