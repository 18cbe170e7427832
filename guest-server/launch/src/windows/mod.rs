//! The Windows half of the logon task's launcher: the launcher loop (`logon`, FFI glue
//! compiled for Windows only) and the entry points the neutral code calls, which say
//! "Windows only" elsewhere.

#[cfg(windows)]
mod logon;

use std::convert::Infallible;
use std::path::Path;

use crate::error::ServiceCliError;

/// Whether this build is for Windows, for neutral code that must decide by platform.
pub const IS_WINDOWS: bool = cfg!(windows);

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
