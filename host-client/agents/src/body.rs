//! Answers over HTTP from parties the harness does not trust (an agent's server, a
//! model endpoint) read chunk by chunk up to a limit, so that a huge or endless answer
//! costs an error for that task instead of the host's memory.

/// The longest answer an outside party may give: one line or HTTP body of an
/// agent over the step protocol (a screenshot inline is far less), or a model
/// endpoint's answer (vendors' answers are kilobytes). A longer one is an error for
/// its task, read no further than this, so it never costs the run more memory.
pub const MAX_ANSWER: usize = 64 << 20;

/// Why a bounded answer could not be read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum BodyError {
    /// Announced or found longer than the limit; `whose` names the party ("the
    /// agent's", "the model's").
    TooLong { whose: &'static str, limit: usize },
    /// The connection failed (or the client's timeout ran out) while reading.
    Read(String),
}

impl std::fmt::Display for BodyError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            BodyError::TooLong { whose, limit } => write!(f, "{whose} answer is longer than {} MiB", limit >> 20),
            BodyError::Read(err) => write!(f, "reading the answer: {err}"),
        }
    }
}

/// The body of `response` from `whose` party, at most `limit` bytes (a whole number of
/// MiB, as the error says): one announced or found longer is refused as soon as that is
/// known, or with `cut` kept to its first `limit` bytes (for the start of an error
/// page). The client's own timeout bounds a slow body.
///
/// # Errors
///
/// [`BodyError`], saying which limit or what failed.
pub async fn read_bounded(
    mut response: reqwest::Response,
    whose: &'static str,
    limit: usize,
    cut: bool,
) -> Result<Vec<u8>, BodyError> {
    if !cut && response.content_length().is_some_and(|n| n > limit as u64) {
        return Err(BodyError::TooLong { whose, limit });
    }
    let mut body = Vec::new();
    while let Some(chunk) = response.chunk().await.map_err(|err| BodyError::Read(error_chain(&err)))? {
        if body.len() + chunk.len() > limit {
            if cut {
                body.extend_from_slice(&chunk[..limit - body.len()]);
                break;
            }
            return Err(BodyError::TooLong { whose, limit });
        }
        body.extend_from_slice(&chunk);
    }
    Ok(body)
}

/// An error and its sources on one line (reqwest hides the useful part in the chain).
pub(crate) fn error_chain(err: &(dyn std::error::Error + 'static)) -> String {
    let mut text = err.to_string();
    let mut source = err.source();
    while let Some(inner) = source {
        let more = inner.to_string();
        if !text.contains(&more) {
            text.push_str(": ");
            text.push_str(&more);
        }
        source = inner.source();
    }
    text
}
