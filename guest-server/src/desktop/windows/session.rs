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

/// The name of a mandatory integrity level, from the last sub-authority of the
/// token's integrity SID (`S-1-16-<rid>`).
pub fn integrity_name(rid: u32) -> String {
    match rid {
        0x0000 => "Untrusted".to_owned(),
        0x1000 => "Low".to_owned(),
        0x2000 => "Medium".to_owned(),
        0x2100 => "Medium Plus".to_owned(),
        0x3000 => "High".to_owned(),
        0x4000 => "System".to_owned(),
        0x5000 => "Protected Process".to_owned(),
        other => format!("level 0x{other:04x}"),
    }
}

/// What the token's `TOKEN_ELEVATION_TYPE` says: 1 default (UAC off, or not an
/// administrator), 2 full (an elevated administrator), 3 limited (an
/// administrator's filtered token: UAC on, not elevated).
pub fn elevation_name(kind: i32) -> &'static str {
    match kind {
        1 => "default token (no split: UAC off or not an administrator)",
        2 => "elevated (full administrator token)",
        3 => "limited (filtered administrator token: not elevated)",
        _ => "unknown elevation type",
    }
}

/// The doctor's and health's one line: `High, elevated (full administrator token)`.
pub fn describe_integrity(rid: u32, elevation: Option<i32>) -> String {
    match elevation {
        Some(kind) => format!("{}, {}", integrity_name(rid), elevation_name(kind)),
        None => integrity_name(rid),
    }
}

#[cfg(test)]
mod integrity_tests {
    use super::*;

    #[test]
    fn integrity_levels_and_elevation_read_as_words() {
        assert_eq!(describe_integrity(0x3000, Some(2)), "High, elevated (full administrator token)");
        assert_eq!(describe_integrity(0x2000, Some(3)), "Medium, limited (filtered administrator token: not elevated)");
        assert_eq!(describe_integrity(0x4000, None), "System");
        assert_eq!(integrity_name(0x2345), "level 0x2345");
    }
}
