//! The two exes that ship together (the server and the logon task's launcher) and how
//! each finds the other in its own folder.

use std::path::{Path, PathBuf};

use crate::error::ServiceCliError;

/// The server's file name, which the logon task's launcher starts from its own folder.
pub const SERVER_EXE: &str = "arena-guest.exe";

/// The logon task's launcher (this crate's binary, `guest-server/launch/src/main.rs`): a GUI-subsystem
/// program, so Windows gives it no console and no window flashes at logon (see
/// `docs/windows.md`, "The logon task"). It ships beside [`SERVER_EXE`].
pub const LAUNCHER_EXE: &str = "arena-guest-logon.exe";

/// `name`, in the folder of `exe`, when it is a file there; otherwise
/// [`ServiceCliError::MissingCompanion`] naming both.
///
/// # Errors
///
/// As above.
pub fn companion(exe: &Path, name: &'static str) -> Result<PathBuf, ServiceCliError> {
    let path = exe.with_file_name(name);
    if path.is_file() {
        Ok(path)
    } else {
        Err(ServiceCliError::MissingCompanion { name, path, beside: exe.to_path_buf() })
    }
}

/// This program's path, for the command lines stored in the service or task.
///
/// # Errors
///
/// The OS not telling.
pub fn current_exe() -> Result<PathBuf, ServiceCliError> {
    std::env::current_exe().map_err(|source| ServiceCliError::Io { what: "finding this program's path".into(), source })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_exe_finds_the_other_beside_it_or_names_the_missing_one() {
        let dir = tempfile::tempdir().unwrap();
        let server = dir.path().join(SERVER_EXE);
        let launcher = dir.path().join(LAUNCHER_EXE);
        std::fs::write(&server, b"MZ").unwrap();
        let err = companion(&server, LAUNCHER_EXE).unwrap_err();
        let text = err.to_string();
        assert!(text.starts_with("arena-guest-logon.exe is missing: expected at "), "{text}");
        assert!(
            text.contains(&launcher.display().to_string()) && text.contains(&server.display().to_string()),
            "{text}"
        );
        assert_eq!(err.exit_code(), 2);
        std::fs::write(&launcher, b"MZ").unwrap();
        assert_eq!(companion(&server, LAUNCHER_EXE).unwrap(), launcher);
        assert_eq!(companion(&launcher, SERVER_EXE).unwrap(), server);
        // A folder of that name is not the program.
        std::fs::remove_file(&server).unwrap();
        std::fs::create_dir(&server).unwrap();
        assert!(
            matches!(companion(&launcher, SERVER_EXE), Err(ServiceCliError::MissingCompanion { name, .. }) if name == SERVER_EXE)
        );
    }
}
