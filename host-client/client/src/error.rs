//! The one error type of the guest client, [`ClientError`].
//!
//! Every variant that concerns a request names the guest (its base URL) and
//! the call (method and path), so a message read in a log of many parallel
//! episodes says which VM failed, doing what, and why.
//! Underlying errors are flattened into the message instead of being chained
//! as sources: a reqwest error's chain repeats the URL and hides the one useful
//! line ("Connection refused") three levels down, and a flat message prints
//! the same with `{}` and `{:#}`.
//!
//! It is not the CLI's error type: the binary wraps these in `anyhow`.

use std::fmt;
use std::time::Duration;

use arena_shared::error::ErrorCode;
use arena_shared::health::Component;

/// Which call failed: the guest's base URL, the HTTP method and the path.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CallSite {
    /// Base URL of the guest, e.g. `http://127.0.0.1:5000`.
    pub guest: String,
    /// HTTP method, e.g. `GET`.
    pub method: &'static str,
    /// Path of the route, without the query, e.g. `/v1/files`.
    pub path: String,
}

impl fmt::Display for CallSite {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "guest {}: {} {}", self.guest, self.method, self.path)
    }
}

/// An error of a [`crate::client::GuestClient`] call.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ClientError {
    /// The TCP connection could not be made (nothing listens, host unreachable, DNS).
    #[error("{call}: cannot connect: {reason}")]
    Connect { call: CallSite, reason: String },

    /// No complete answer arrived within the call's deadline.
    #[error("{call}: no answer within {}", fmt_duration(*after))]
    Timeout { call: CallSite, after: Duration },

    /// The guest answered with a non-2xx status.
    #[error("{call}: HTTP {status} {}: {message}", code_name(*code))]
    Api { call: CallSite, status: u16, code: ErrorCode, message: String },

    /// The answer arrived but is not what the route promises.
    #[error("{call}: cannot decode the answer: {reason}")]
    Decode { call: CallSite, reason: String },

    /// The connection broke while the request or answer was in flight.
    #[error("{call}: transfer failed: {reason}")]
    Io { call: CallSite, reason: String },

    /// Bytes do not hash to what the other side said they hash to.
    #[error("{call}: SHA-256 mismatch: expected {expected}, got {actual}")]
    Integrity { call: CallSite, expected: String, actual: String },

    /// [`crate::client::GuestClient::wait_ready`] ran out of time.
    #[error("guest {guest}: not ready after {}: {}", fmt_duration(*waited), describe_down(down, last_error.as_deref()))]
    NotReady { guest: String, waited: Duration, down: Vec<Component>, last_error: Option<String> },

    /// The base URL cannot be used.
    #[error("invalid guest URL {url:?}: {reason}")]
    InvalidUrl { url: String, reason: String },
}

impl ClientError {
    /// The HTTP status of an [`ClientError::Api`] error.
    pub fn status(&self) -> Option<u16> {
        match self {
            ClientError::Api { status, .. } => Some(*status),
            _ => None,
        }
    }

    /// The guest's error code of an [`ClientError::Api`] error.
    pub fn code(&self) -> Option<ErrorCode> {
        match self {
            ClientError::Api { code, .. } => Some(*code),
            _ => None,
        }
    }

    /// The call that failed, when the error concerns one request.
    pub fn call(&self) -> Option<&CallSite> {
        match self {
            ClientError::Connect { call, .. }
            | ClientError::Timeout { call, .. }
            | ClientError::Api { call, .. }
            | ClientError::Decode { call, .. }
            | ClientError::Io { call, .. }
            | ClientError::Integrity { call, .. } => Some(call),
            ClientError::NotReady { .. } | ClientError::InvalidUrl { .. } => None,
        }
    }

    /// Whether the guest is out of reach, rather than refusing one call: nothing
    /// answered (no connection, no answer in time, a transfer broken in flight) or it
    /// never became ready. The one rule for it: the agent executor and the
    /// observation call such an error an infrastructure failure (never the agent's),
    /// and [`ClientError::is_transient`] retries idempotent calls on it.
    pub fn out_of_reach(&self) -> bool {
        matches!(
            self,
            ClientError::Connect { .. }
                | ClientError::Timeout { .. }
                | ClientError::Io { .. }
                | ClientError::NotReady { .. }
        )
    }

    /// Whether retrying the same idempotent request may succeed: the guest was
    /// [out of reach](ClientError::out_of_reach), or a proxy in front of it
    /// reported a bad gateway (502 to 504).
    pub fn is_transient(&self) -> bool {
        self.out_of_reach() || matches!(self, ClientError::Api { status: 502..=504, .. })
    }
}

/// The error code a status stands for, for error bodies that are not an
/// [`arena_shared::error::ErrorBody`] (a proxy's HTML page, an empty body).
pub(crate) fn code_for_status(status: u16) -> ErrorCode {
    match status {
        400 | 405 | 422 => ErrorCode::BadRequest,
        401 | 403 => ErrorCode::Unauthorized,
        404 => ErrorCode::NotFound,
        409 => ErrorCode::Conflict,
        413 => ErrorCode::PayloadTooLarge,
        501 => ErrorCode::Unsupported,
        504 => ErrorCode::Timeout,
        500..=599 => ErrorCode::Internal,
        _ => ErrorCode::Unknown,
    }
}

fn code_name(code: ErrorCode) -> &'static str {
    match code {
        ErrorCode::BadRequest => "bad_request",
        ErrorCode::Unauthorized => "unauthorized",
        ErrorCode::NotFound => "not_found",
        ErrorCode::Conflict => "conflict",
        ErrorCode::PayloadTooLarge => "payload_too_large",
        ErrorCode::Unsupported => "unsupported",
        ErrorCode::Timeout => "timeout",
        ErrorCode::Internal => "internal",
        _ => "unknown",
    }
}

/// Formats a duration the way people read it: `250 ms`, `1.5 s`.
pub(crate) fn fmt_duration(d: Duration) -> String {
    let ms = d.as_millis();
    if ms < 1000 {
        format!("{ms} ms")
    } else if ms % 1000 == 0 {
        format!("{} s", ms / 1000)
    } else {
        format!("{:.1} s", d.as_secs_f64())
    }
}

fn describe_down(down: &[Component], last_error: Option<&str>) -> String {
    let mut text = if down.is_empty() {
        String::from("no health report received")
    } else {
        let names: Vec<String> = down.iter().map(|c| component_name(*c)).collect();
        format!("still down: {}", names.join(", "))
    };
    if let Some(err) = last_error {
        text.push_str(&format!(" (last error: {err})"));
    }
    text
}

/// The wire name of a component (`capture`, `accessibility`).
pub fn component_name(component: Component) -> String {
    serde_json::to_value(component)
        .ok()
        .and_then(|v| v.as_str().map(str::to_owned))
        .unwrap_or_else(|| format!("{component:?}").to_lowercase())
}

/// Joins an error and its sources into one line, skipping a source whose text
/// its parent already contains (reqwest and hyper repeat themselves).
pub fn flatten(err: &(dyn std::error::Error + 'static)) -> String {
    let mut parts: Vec<String> = vec![err.to_string()];
    let mut source = err.source();
    while let Some(inner) = source {
        let text = inner.to_string();
        if !parts.iter().any(|p| p.contains(&text)) {
            parts.push(text);
        }
        source = inner.source();
    }
    parts.join(": ")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn site() -> CallSite {
        CallSite { guest: "http://10.0.0.5:5000".into(), method: "GET", path: "/v1/files".into() }
    }

    fn check(err: ClientError, expected: &str) {
        assert_eq!(err.to_string(), expected);
        assert_eq!(format!("{:#}", anyhow::Error::new(err)), expected, "the alternate form adds nothing");
    }

    #[test]
    fn every_call_error_names_guest_call_and_reason() {
        check(
            ClientError::Api {
                call: site(),
                status: 404,
                code: ErrorCode::NotFound,
                message: "C:\\x.txt: not found".into(),
            },
            "guest http://10.0.0.5:5000: GET /v1/files: HTTP 404 not_found: C:\\x.txt: not found",
        );
        check(
            ClientError::Connect { call: site(), reason: "Connection refused (os error 111)".into() },
            "guest http://10.0.0.5:5000: GET /v1/files: cannot connect: Connection refused (os error 111)",
        );
        check(
            ClientError::Timeout { call: site(), after: Duration::from_millis(1500) },
            "guest http://10.0.0.5:5000: GET /v1/files: no answer within 1.5 s",
        );
        check(
            ClientError::Timeout { call: site(), after: Duration::from_secs(30) },
            "guest http://10.0.0.5:5000: GET /v1/files: no answer within 30 s",
        );
        check(
            ClientError::Integrity { call: site(), expected: "aa".into(), actual: "bb".into() },
            "guest http://10.0.0.5:5000: GET /v1/files: SHA-256 mismatch: expected aa, got bb",
        );
        check(
            ClientError::Decode { call: site(), reason: "missing field `path`".into() },
            "guest http://10.0.0.5:5000: GET /v1/files: cannot decode the answer: missing field `path`",
        );
    }

    #[test]
    fn not_ready_lists_what_is_down() {
        check(
            ClientError::NotReady {
                guest: "http://g:5000".into(),
                waited: Duration::from_millis(200),
                down: vec![Component::Capture, Component::Accessibility],
                last_error: None,
            },
            "guest http://g:5000: not ready after 200 ms: still down: capture, accessibility",
        );
        check(
            ClientError::NotReady {
                guest: "http://g:5000".into(),
                waited: Duration::from_secs(2),
                down: vec![],
                last_error: Some("cannot connect: refused".into()),
            },
            "guest http://g:5000: not ready after 2 s: no health report received (last error: cannot connect: refused)",
        );
    }

    #[test]
    fn transient_errors_are_connect_timeout_and_gateway_statuses() {
        let api =
            |status| ClientError::Api { call: site(), status, code: code_for_status(status), message: String::new() };
        assert!(api(502).is_transient());
        assert!(api(503).is_transient());
        assert!(api(504).is_transient());
        assert!(!api(500).is_transient());
        assert!(!api(404).is_transient());
        assert!(ClientError::Connect { call: site(), reason: String::new() }.is_transient());
        assert!(ClientError::Io { call: site(), reason: String::new() }.is_transient());
        assert!(!ClientError::Decode { call: site(), reason: String::new() }.is_transient());
    }

    #[test]
    fn out_of_reach_is_no_answer_at_all_never_an_answer() {
        let reached = [
            ClientError::Api { call: site(), status: 504, code: ErrorCode::Timeout, message: String::new() },
            ClientError::Api { call: site(), status: 502, code: ErrorCode::Internal, message: String::new() },
            ClientError::Decode { call: site(), reason: String::new() },
            ClientError::Integrity { call: site(), expected: String::new(), actual: String::new() },
            ClientError::InvalidUrl { url: String::new(), reason: String::new() },
        ];
        for err in reached {
            assert!(!err.out_of_reach(), "{err}");
        }
        let gone = [
            ClientError::Connect { call: site(), reason: String::new() },
            ClientError::Timeout { call: site(), after: Duration::from_secs(1) },
            ClientError::Io { call: site(), reason: String::new() },
            ClientError::NotReady { guest: String::new(), waited: Duration::ZERO, down: vec![], last_error: None },
        ];
        for err in gone {
            assert!(err.out_of_reach(), "{err}");
        }
    }

    #[test]
    fn statuses_map_to_codes_when_the_body_is_not_an_error_body() {
        let cases = [
            (400, ErrorCode::BadRequest),
            (401, ErrorCode::Unauthorized),
            (404, ErrorCode::NotFound),
            (409, ErrorCode::Conflict),
            (413, ErrorCode::PayloadTooLarge),
            (501, ErrorCode::Unsupported),
            (502, ErrorCode::Internal),
            (504, ErrorCode::Timeout),
            (418, ErrorCode::Unknown),
        ];
        for (status, code) in cases {
            assert_eq!(code_for_status(status), code, "status {status}");
        }
    }
}
