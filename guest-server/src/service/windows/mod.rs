//! The Windows half of the service mode and the logon task: the Service Control
//! Manager registration and the supervisor it starts ([`scm`]), the logon task's
//! launcher loop (`logon`, what `arena-guest-logon.exe` runs), both FFI glue compiled
//! for Windows only, and the entry points the neutral [`crate::service`] calls.

#[cfg(windows)]
mod logon;
#[cfg(windows)]
pub mod scm;

use std::convert::Infallible;
use std::path::Path;

use super::{ServiceCliError, ServiceCommand};

/// Runs a `service` subcommand against the Service Control Manager.
///
/// # Errors
///
/// [`ServiceCliError::OnlyOnWindows`] on other platforms; the Service Control
/// Manager refusing (not an administrator, ...) on Windows.
pub fn execute(command: &ServiceCommand) -> Result<String, ServiceCliError> {
    #[cfg(windows)]
    {
        scm::execute(command)
    }
    #[cfg(not(windows))]
    {
        let _ = command;
        Err(ServiceCliError::OnlyOnWindows("service"))
    }
}

/// The logon task's launcher loop: `server` with `serve_args` without a console
/// window, restarted when it dies, until the launcher is ended. Returns only on failure.
///
/// # Errors
///
/// [`ServiceCliError::OnlyOnWindows`] on other platforms; the log folder or the
/// server not starting on Windows.
pub fn run_logon_task(server: &Path, serve_args: &[String]) -> Result<Infallible, ServiceCliError> {
    #[cfg(windows)]
    {
        logon::run(server, serve_args)
    }
    #[cfg(not(windows))]
    {
        let _ = (server, serve_args);
        Err(ServiceCliError::OnlyOnWindows("logon-task"))
    }
}

/// Adds a failed launcher's last word to the logon task's log (it has no console to
/// say it on); on other platforms, and when the log cannot be opened, nothing.
pub fn note_launcher_failure(err: &ServiceCliError) {
    #[cfg(windows)]
    {
        logon::note_failure(err);
    }
    #[cfg(not(windows))]
    {
        let _ = err;
    }
}
