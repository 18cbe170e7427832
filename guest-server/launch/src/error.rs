//! Why a `service` or `logon-task` subcommand, or the logon task's launcher, failed,
//! and the exit code each failure gives.

use std::path::PathBuf;

/// Why a `service` or `logon-task` subcommand, or the launcher, failed.
#[derive(Debug, thiserror::Error)]
pub enum ServiceCliError {
    /// The subcommand needs Windows.
    #[error("`arena-guest {0}` works only on Windows (this build is for another platform)")]
    OnlyOnWindows(&'static str),
    /// The serve options to pass on are not valid.
    #[error("invalid serve options: {0}")]
    InvalidServeOptions(String),
    /// An OS call failed.
    #[error("{op}: {message}")]
    Os { op: String, message: String },
    /// One of the two exes that ship together is not beside the other.
    #[error(
        "{name} is missing: expected at {}, beside {} (the two exes ship together: \
         scripts/build-windows.sh builds both, install-guest.ps1 copies both)",
        path.display(),
        beside.display()
    )]
    MissingCompanion { name: &'static str, path: PathBuf, beside: PathBuf },
    /// A file or program could not be used.
    #[error("{what}: {source}")]
    Io {
        what: String,
        #[source]
        source: std::io::Error,
    },
}

impl ServiceCliError {
    /// The process exit code for this error: 2 for a usage problem (wrong platform,
    /// bad options, one of the two exes missing beside the other), 1 for a failure
    /// while doing the work.
    pub fn exit_code(&self) -> u8 {
        match self {
            ServiceCliError::OnlyOnWindows(_)
            | ServiceCliError::InvalidServeOptions(_)
            | ServiceCliError::MissingCompanion { .. } => 2,
            ServiceCliError::Os { .. } | ServiceCliError::Io { .. } => 1,
        }
    }
}
