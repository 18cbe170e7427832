//! What the build's platform decides for the guest's platform-neutral code, named: the
//! one place outside the FFI glue that asks whether this is the Windows exe.
//!
//! The configuration's default backend, the stub backend's shell and its doctor's
//! probes, and the service subcommands read these constants instead of writing
//! `cfg!(windows)` themselves, so every platform branch of the guest is in a `windows/`
//! folder (the tidy test enforces it). Compiled and tested everywhere.

/// Whether this build is the Windows exe (the stub backend runs inside it too).
pub const IS_WINDOWS: bool = cfg!(windows);

/// The program that runs a shell line: `cmd.exe` (`/c "LINE"`) on Windows, `sh` (`-c`) elsewhere.
pub const SHELL: &str = if IS_WINDOWS { "cmd.exe" } else { "sh" };

/// Whether a shell line's missing program is reported by the shell itself, so nothing
/// checks for it first: `cmd.exe` has too many built-ins to tell ahead of it.
pub const SHELL_REPORTS_MISSING_PROGRAMS: bool = IS_WINDOWS;

/// A shell line whose child outlives a timeout and starts a grandchild that holds the
/// output pipe too, for the doctor's check that a timeout kills the whole tree.
pub const SLOW_SHELL_LINE: &str =
    if IS_WINDOWS { "start /b ping -n 60 127.0.0.1 >nul & ping -n 60 127.0.0.1" } else { "sleep 60 & sleep 60" };

/// Where `setup.ps1` records the image setup's progress: `%ProgramData%\arena\setup-status.json`
/// on Windows; nowhere elsewhere (the stub's hosts pass `--setup-status` when they have one).
pub fn default_setup_status() -> Option<std::path::PathBuf> {
    if !IS_WINDOWS {
        return None;
    }
    let data = std::env::var_os("ProgramData").unwrap_or_else(|| r"C:\ProgramData".into());
    Some(std::path::Path::new(&data).join("arena").join("setup-status.json"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shell_matches_the_platform() {
        assert_eq!(SHELL == "cmd.exe", IS_WINDOWS);
        assert_eq!(SLOW_SHELL_LINE.contains("ping"), IS_WINDOWS);
        assert_eq!(SHELL_REPORTS_MISSING_PROGRAMS, IS_WINDOWS);
        assert_eq!(default_setup_status().is_some(), IS_WINDOWS);
    }
}
