//! What one setup step did ([`Outcome`]): done or failed, with a detail for the log.
//!
//! A leaf module, so the step runner (`steps`) and the browser steps (`cdp`) both
//! build outcomes without importing each other.

use arena_client::error::ClientError;

/// What a step did.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) struct Outcome {
    pub(super) ok: bool,
    pub(super) detail: String,
}

impl Outcome {
    pub(super) fn done(detail: impl Into<String>) -> Outcome {
        Outcome { ok: true, detail: detail.into() }
    }

    pub(super) fn failed(detail: impl Into<String>) -> Outcome {
        Outcome { ok: false, detail: detail.into() }
    }

    /// Done with `detail` when `result` is `Ok`, failed with the error otherwise.
    pub(super) fn of<T>(result: Result<T, ClientError>, detail: impl Into<String>) -> Outcome {
        match result {
            Ok(_) => Outcome::done(detail),
            Err(err) => Outcome::failed(err.to_string()),
        }
    }
}
