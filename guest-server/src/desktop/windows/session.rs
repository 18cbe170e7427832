//! Which Windows session the server may drive a desktop from.
//!
//! Session 0 is where services run: it has no interactive desktop, so screenshots
//! come back black, input goes nowhere and windows the server starts are invisible to
//! the user. The Windows backend asks [`refuse_session_zero`] before every call that
//! needs the user's desktop and answers those calls with a clear error instead of
//! silently doing nothing. File, registry and process calls still work there.
//!
//! Platform-neutral: the session id comes from `ProcessIdToSessionId` in
//! `desktop/windows/`; the decision and its wording are here and tested natively.

use crate::desktop::{DesktopError, DesktopResult};

/// The session services run in.
pub const SERVICE_SESSION: u32 = 0;

/// What an operation needs from the session it runs in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Needs {
    /// Screen, input, windows, clipboard, accessibility: only an interactive session has them.
    InteractiveDesktop,
    /// Files, registry, processes: any session will do.
    AnySession,
}

/// Refuses `op` when it needs the interactive desktop and the server runs in session 0.
///
/// An unknown session (`None`, the call to find it failed) is given the benefit of the
/// doubt: refusing everything because of a failed query would be worse than trying.
///
/// # Errors
///
/// [`DesktopError::Unsupported`] naming the operation and what to do instead.
pub fn refuse_session_zero(session: Option<u32>, op: &str, needs: Needs) -> DesktopResult<()> {
    match (session, needs) {
        (Some(SERVICE_SESSION), Needs::InteractiveDesktop) => Err(DesktopError::Unsupported(format!(
            "{op} needs the user's desktop, but this server runs in session 0 (the services session), \
             which has none: screenshots would be black and input would go nowhere. \
             Start the server from the user's logon task, or run `arena-guest service install`, \
             whose service starts a worker in the active console session"
        ))),
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn session_zero_refuses_desktop_calls_only() {
        let err = refuse_session_zero(Some(0), "capture", Needs::InteractiveDesktop).unwrap_err();
        let DesktopError::Unsupported(message) = err else { panic!("wrong variant") };
        assert!(message.starts_with("capture needs the user's desktop"), "{message}");
        assert!(message.contains("session 0"), "{message}");
        assert!(refuse_session_zero(Some(0), "registry read", Needs::AnySession).is_ok());
        assert!(refuse_session_zero(Some(1), "capture", Needs::InteractiveDesktop).is_ok());
        assert!(refuse_session_zero(None, "capture", Needs::InteractiveDesktop).is_ok());
    }
}
