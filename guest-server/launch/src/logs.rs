//! Where the service and the logon task log (a service and a GUI-subsystem launcher
//! have no console), and how their append-only logs stay bounded.

use std::path::{Path, PathBuf};

/// The logon task's log file in [`log_dir`]: the launcher's lines and the server's output.
pub const LOGON_TASK_LOG: &str = "logon-task.log";

/// The folder the service logs into: `%ProgramData%\arena` (`C:\ProgramData\arena` when
/// the variable is missing). A service has no console, so its logs go to files there:
/// `service.log` (the supervisor) and `worker.log` (the worker's output).
pub fn log_dir(program_data: Option<&std::ffi::OsStr>) -> PathBuf {
    let base = program_data.filter(|p| !p.is_empty()).map_or_else(|| PathBuf::from(r"C:\ProgramData"), PathBuf::from);
    base.join("arena")
}

/// Largest log file kept before it is rotated.
pub const LOG_MAX_BYTES: u64 = 10 * 1024 * 1024;

/// Moves `path` to `<path>.old` (replacing an older one) when it is larger than
/// `max_bytes`, so logs that are only ever appended to stay bounded.
///
/// # Errors
///
/// The rename failing; a missing file is not an error.
pub fn rotate_log(path: &Path, max_bytes: u64) -> std::io::Result<bool> {
    match std::fs::metadata(path) {
        Ok(meta) if meta.len() > max_bytes => {
            let mut old = path.as_os_str().to_owned();
            old.push(".old");
            let old = PathBuf::from(old);
            // Windows' rename does not replace an existing file.
            let _ = std::fs::remove_file(&old);
            std::fs::rename(path, &old)?;
            Ok(true)
        }
        Ok(_) => Ok(false),
        Err(err) if err.kind() == std::io::ErrorKind::NotFound => Ok(false),
        Err(err) => Err(err),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn logs_go_under_program_data() {
        let dir = log_dir(Some(std::ffi::OsStr::new("/data")));
        assert_eq!(dir, Path::new("/data").join("arena"));
        assert_eq!(log_dir(None), PathBuf::from(r"C:\ProgramData").join("arena"));
        assert_eq!(log_dir(Some(std::ffi::OsStr::new(""))), PathBuf::from(r"C:\ProgramData").join("arena"));
    }

    #[test]
    fn a_large_log_is_moved_aside() {
        let dir = tempfile::tempdir().unwrap();
        let log = dir.path().join("service.log");
        assert!(!rotate_log(&log, 10).unwrap(), "a missing log is left alone");
        std::fs::write(&log, b"0123456789").unwrap();
        assert!(!rotate_log(&log, 10).unwrap());
        std::fs::write(dir.path().join("service.log.old"), b"older").unwrap();
        std::fs::write(&log, b"0123456789ab").unwrap();
        assert!(rotate_log(&log, 10).unwrap());
        assert!(!log.exists());
        assert_eq!(std::fs::read(dir.path().join("service.log.old")).unwrap(), b"0123456789ab");
    }
}
