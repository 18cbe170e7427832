//! The one error body every native route answers with, and how a JSON value's
//! kind is named in error messages ([`json_kind`]).

use serde::{Deserialize, Serialize};

/// Machine-readable error kind.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ErrorCode {
    /// The request was malformed or named something invalid (400).
    BadRequest,
    /// Missing or wrong bearer token (401).
    Unauthorized,
    /// The request is understood and refused: a cross-site or foreign-host request, or
    /// an operation on something that must not be touched (403).
    Forbidden,
    /// The path, window or value does not exist (404).
    NotFound,
    /// The request conflicts with the current state, e.g. a hash mismatch (409).
    Conflict,
    /// The body is over the configured limit (413).
    PayloadTooLarge,
    /// The backend cannot do this (501).
    Unsupported,
    /// A deadline passed (504).
    Timeout,
    /// The server is at a limit right now (too many connections) or is shutting down;
    /// try again (503).
    Unavailable,
    /// Something failed inside the guest; details are in its log (500).
    Internal,
    #[serde(other)]
    Unknown,
}

/// `{"error": "<code>", "message": "..."}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ErrorBody {
    pub error: ErrorCode,
    pub message: String,
}

/// A JSON value's kind as error messages name it ("a string", "a list"): for task
/// files, action spaces and any other JSON a caller sends in the wrong shape.
pub fn json_kind(value: &serde_json::Value) -> &'static str {
    use serde_json::Value;
    match value {
        Value::Null => "null",
        Value::Bool(_) => "a boolean",
        Value::Number(_) => "a number",
        Value::String(_) => "a string",
        Value::Array(_) => "a list",
        Value::Object(_) => "an object",
    }
}
