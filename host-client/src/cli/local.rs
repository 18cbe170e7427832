//! Local files on the host: atomic writes of downloads and screenshots.
//!
//! A download is written to a temporary file beside its destination and
//! renamed over it only once every byte is on disk, so an interrupted or
//! failed pull never leaves a truncated file where a good one was.

use std::path::Path;

use anyhow::Context;

/// Writes `bytes` to `path` atomically: a temporary file in the same
/// directory, flushed and synced, then renamed over `path`.
///
/// # Errors
///
/// The directory does not exist or is not writable, or the disk is full; the
/// message names `path`. On error `path` is left as it was.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    if path.is_dir() {
        anyhow::bail!("{} is a directory; name the file to write", path.display());
    }
    arena_shared::atomic::write_atomic(path, bytes).with_context(|| format!("writing {}", path.display()))
}

/// Reads a whole local file for upload.
///
/// # Errors
///
/// The file is missing, a directory or unreadable; the message names it.
pub fn read(path: &Path) -> anyhow::Result<Vec<u8>> {
    if path.is_dir() {
        anyhow::bail!("{} is a directory; push uploads one file", path.display());
    }
    std::fs::read(path).with_context(|| format!("reading {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_replace_the_file_and_leave_no_temporaries() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.bin");
        std::fs::write(&path, b"old").unwrap();
        write_atomic(&path, b"new contents").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"new contents");
        let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names, vec![std::ffi::OsString::from("out.bin")]);
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let fresh = dir.path().join("fresh.bin");
            write_atomic(&fresh, b"x").unwrap();
            assert_eq!(std::fs::metadata(&fresh).unwrap().permissions().mode() & 0o777, 0o644);
        }
    }

    #[test]
    fn failures_name_the_path_and_keep_the_old_file() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("no-such-dir").join("out.bin");
        let err = write_atomic(&missing, b"x").unwrap_err();
        assert!(format!("{err:#}").contains("no-such-dir"), "{err:#}");
        let err = write_atomic(dir.path(), b"x").unwrap_err();
        assert!(format!("{err:#}").contains("is a directory"), "{err:#}");
        let err = read(&dir.path().join("absent.txt")).unwrap_err();
        assert!(format!("{err:#}").contains("absent.txt"), "{err:#}");
    }
}
