//! The Windows half of the service mode: the Service Control Manager registration and
//! the supervisor it starts ([`scm`]), FFI glue compiled for Windows only, and the
//! entry point the neutral [`crate::service`] calls. (The logon task's launcher loop is
//! `arena_guest_launch`'s, the crate of `arena-guest-logon.exe`.)

#[cfg(windows)]
pub mod scm;

use arena_guest_launch::error::ServiceCliError;

use crate::cli::ServiceCommand;

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
