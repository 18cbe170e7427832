//! The Windows half of the service mode and the logon task: the Service Control
//! Manager registration and the supervisor it starts ([`scm`]), the logon task's
//! launcher (`logon`), both FFI glue compiled for Windows only, and the entry points
//! the neutral [`crate::service`] calls.

#[cfg(windows)]
mod logon;
#[cfg(windows)]
pub mod scm;

use super::{LauncherOptions, ServiceCliError, ServiceCommand};

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

/// Runs the logon task's launcher: the server without a console window, restarted
/// when it dies, until the task is ended.
///
/// # Errors
///
/// [`ServiceCliError::OnlyOnWindows`] on other platforms; the log folder or the
/// server not starting on Windows.
pub fn run_logon_task(options: &LauncherOptions) -> Result<String, ServiceCliError> {
    #[cfg(windows)]
    {
        logon::run(options)
    }
    #[cfg(not(windows))]
    {
        let _ = options;
        Err(ServiceCliError::OnlyOnWindows("logon-task"))
    }
}
