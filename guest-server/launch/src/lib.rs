//! What starts the guest server and keeps it running, without the server: the serve
//! options ([`config`]) and their checks before they are stored ([`options`]), the
//! two exes that ship together ([`exes`]), the restart backoff ([`restart`]), the log
//! folder and rotation ([`logs`]), the errors of all this ([`error`]), and the logon
//! task's launcher loop ([`windows`], FFI glue for Windows only).
//!
//! `arena-guest` (its `service` and `logon-task` subcommands) builds on this crate;
//! this crate's own binary, `arena-guest-logon` (the logon task's launcher), is only
//! this crate. So the launcher links clap and the standard library, not the server's
//! HTTP stack, UI Automation or the MCP SDK.

#![forbid(unsafe_code)]

pub mod config;
pub mod error;
pub mod exes;
pub mod logs;
pub mod options;
pub mod restart;
pub mod windows;

use crate::error::ServiceCliError;
use crate::exes::{companion, current_exe, SERVER_EXE};
use crate::options::launcher_serve_args;

/// Runs the logon task's launcher ([`exes::LAUNCHER_EXE`]) with its command-line arguments:
/// starts [`SERVER_EXE`] from the launcher's folder without a console window, and
/// again whenever it dies, until the launcher is ended. Returns only on failure.
///
/// # Errors
///
/// Invalid serve options, the server missing from the launcher's folder, the log
/// folder or the server not starting; [`ServiceCliError::OnlyOnWindows`] elsewhere.
pub fn run_logon_launcher(
    args: impl IntoIterator<Item = std::ffi::OsString>,
) -> Result<std::convert::Infallible, ServiceCliError> {
    let serve_args = launcher_serve_args(args)?;
    if !windows::IS_WINDOWS {
        return Err(ServiceCliError::OnlyOnWindows("logon-task"));
    }
    let launcher = current_exe()?;
    let server = companion(&launcher, SERVER_EXE)?;
    windows::run_logon_task(&server, &serve_args)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn other_platforms_say_windows_only() {
        if windows::IS_WINDOWS {
            return;
        }
        let launched = run_logon_launcher(["--port".into(), "5000".into()]);
        assert!(matches!(launched, Err(ServiceCliError::OnlyOnWindows("logon-task"))), "{launched:?}");
        // The options are checked first, everywhere.
        let launched = run_logon_launcher(["--port".into(), "0".into()]);
        assert!(matches!(launched, Err(ServiceCliError::InvalidServeOptions(_))), "{launched:?}");
    }
}
