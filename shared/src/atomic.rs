//! Atomic file replacement: the one way either side writes a file that a reader, a
//! resumed run or a crash may see half-done.
//!
//! The rule, everywhere: the bytes go to a temporary file in the target's own folder
//! (named [`TEMP_PREFIX`]`…`, so leftovers of a killed process can be recognised and
//! removed), which is given the permissions of the file it replaces (or ordinary
//! file permissions), synced to disk, and renamed over the target; on Unix the
//! folder is synced too, so the rename itself survives a power cut. Any failure
//! removes the temporary file and leaves the target as it was.
//! Missing parent folders are not created: callers decide that.
//!
//! This is the crate's one piece of file I/O; it is here because the guest (uploads,
//! screenshots saved by agent code) and the host (results, downloads, the cache)
//! must follow the same rule.

use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Prefix of every temporary file this module creates.
pub const TEMP_PREFIX: &str = ".arena-partial-";

/// A file being written in place of `target`; nothing is visible at `target` until
/// [`AtomicFile::commit`]. Dropping it uncommitted removes the temporary file.
#[derive(Debug)]
pub struct AtomicFile {
    temp: tempfile::NamedTempFile,
    target: PathBuf,
}

/// The folder a file lives in (`.` for a bare name).
fn folder_of(path: &Path) -> &Path {
    match path.parent() {
        Some(parent) if !parent.as_os_str().is_empty() => parent,
        _ => Path::new("."),
    }
}

impl AtomicFile {
    /// Starts writing a file that will replace `target`.
    ///
    /// # Errors
    ///
    /// The target's folder is missing or not writable.
    pub fn create(target: &Path) -> std::io::Result<AtomicFile> {
        let temp = tempfile::Builder::new().prefix(TEMP_PREFIX).tempfile_in(folder_of(target))?;
        Ok(AtomicFile { temp, target: target.to_path_buf() })
    }

    /// The temporary file, to write into.
    pub fn file(&mut self) -> &mut File {
        self.temp.as_file_mut()
    }

    /// Where the temporary file is.
    pub fn temp_path(&self) -> &Path {
        self.temp.path()
    }

    /// Changes the file this one will replace (for content-addressed names known only
    /// after writing). The new target must be in the same folder.
    pub fn retarget(&mut self, target: &Path) {
        self.target = target.to_path_buf();
    }

    /// Gives the file its permissions, syncs it and renames it over the target.
    ///
    /// # Errors
    ///
    /// Syncing or renaming failed (the target is a folder, the disk is full); the
    /// temporary file is removed and the target is untouched.
    pub fn commit(self) -> std::io::Result<()> {
        let AtomicFile { temp, target } = self;
        // A temporary file is private (0600 on Unix); the result should look like any
        // other file, or keep the permissions of the file it replaces.
        if let Some(permissions) = permissions_for(&target) {
            temp.as_file().set_permissions(permissions)?;
        }
        temp.as_file().sync_all()?;
        temp.persist(&target).map_err(|err| err.error)?;
        sync_folder(folder_of(&target));
        Ok(())
    }
}

/// Replaces `target` with `bytes` atomically (see the module documentation).
///
/// # Errors
///
/// The folder is missing or not writable, the target is a folder, or the disk is
/// full; `target` is then left as it was and no temporary file remains.
pub fn write_atomic(target: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let mut file = AtomicFile::create(target)?;
    file.file().write_all(bytes)?;
    file.commit()
}

/// Removes the temporary files a killed writer left directly in `folder`; answers how
/// many were removed. Files younger than `min_age` may still be in use and are kept.
pub fn remove_leftovers(folder: &Path, min_age: std::time::Duration) -> usize {
    let Ok(entries) = std::fs::read_dir(folder) else { return 0 };
    let old_enough = |entry: &std::fs::DirEntry| {
        entry
            .metadata()
            .ok()
            .and_then(|m| m.modified().ok())
            .and_then(|t| t.elapsed().ok())
            .is_some_and(|age| age >= min_age)
    };
    entries
        .filter_map(Result::ok)
        .filter(|e| e.file_name().to_string_lossy().starts_with(TEMP_PREFIX) && old_enough(e))
        .filter(|e| e.file_type().is_ok_and(|t| t.is_file()) && std::fs::remove_file(e.path()).is_ok())
        .count()
}

#[cfg(unix)]
fn permissions_for(target: &Path) -> Option<std::fs::Permissions> {
    use std::os::unix::fs::PermissionsExt;
    match std::fs::metadata(target) {
        Ok(meta) if meta.is_file() => Some(meta.permissions()),
        _ => Some(std::fs::Permissions::from_mode(0o644)),
    }
}

#[cfg(not(unix))]
fn permissions_for(target: &Path) -> Option<std::fs::Permissions> {
    // A read-only file keeps its flag; otherwise the new file's defaults are right.
    std::fs::metadata(target).ok().filter(|m| m.is_file()).map(|m| m.permissions())
}

/// Syncs a folder so a rename in it is durable; best effort (not every file system
/// lets a folder be opened or synced, and the data itself is already on disk).
#[cfg(unix)]
fn sync_folder(folder: &Path) {
    if let Ok(dir) = File::open(folder) {
        let _ = dir.sync_all();
    }
}

#[cfg(not(unix))]
fn sync_folder(_folder: &Path) {}

#[cfg(test)]
mod tests {
    use super::*;

    fn leftovers(dir: &Path) -> Vec<String> {
        std::fs::read_dir(dir)
            .expect("list")
            .filter_map(Result::ok)
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with(TEMP_PREFIX))
            .collect()
    }

    #[test]
    fn replaces_the_file_and_leaves_nothing_behind() {
        let dir = tempfile::tempdir().expect("dir");
        let target = dir.path().join("a.txt");
        write_atomic(&target, b"one").expect("first write");
        write_atomic(&target, b"two").expect("second write");
        assert_eq!(std::fs::read(&target).expect("read"), b"two");
        assert!(leftovers(dir.path()).is_empty());
    }

    #[test]
    fn a_failed_write_keeps_the_old_content_and_no_temporary_file() {
        let dir = tempfile::tempdir().expect("dir");
        // The target is a folder: the rename fails after the bytes were written.
        let folder = dir.path().join("sub");
        std::fs::create_dir(&folder).expect("mkdir");
        std::fs::write(folder.join("keep"), b"x").expect("write");
        assert!(write_atomic(&folder, b"new").is_err());
        assert!(folder.join("keep").is_file());
        assert!(leftovers(dir.path()).is_empty());
        // A missing parent folder is not created.
        let err = write_atomic(&dir.path().join("missing").join("a"), b"x").expect_err("no parent");
        assert_eq!(err.kind(), std::io::ErrorKind::NotFound);
        // Dropping an uncommitted file removes it.
        let mut file = AtomicFile::create(&dir.path().join("b")).expect("create");
        file.file().write_all(b"half").expect("write");
        drop(file);
        assert!(leftovers(dir.path()).is_empty());
        assert!(!dir.path().join("b").exists());
    }

    #[cfg(unix)]
    #[test]
    fn permissions_are_ordinary_or_kept() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().expect("dir");
        let fresh = dir.path().join("fresh");
        write_atomic(&fresh, b"x").expect("write");
        assert_eq!(std::fs::metadata(&fresh).expect("meta").permissions().mode() & 0o777, 0o644);
        std::fs::set_permissions(&fresh, std::fs::Permissions::from_mode(0o600)).expect("chmod");
        write_atomic(&fresh, b"y").expect("rewrite");
        assert_eq!(std::fs::metadata(&fresh).expect("meta").permissions().mode() & 0o777, 0o600);
    }

    #[test]
    fn leftovers_of_killed_writers_are_removed_when_old_enough() {
        let dir = tempfile::tempdir().expect("dir");
        let stale = dir.path().join(format!("{TEMP_PREFIX}abc"));
        std::fs::write(&stale, b"half").expect("write");
        std::fs::write(dir.path().join("mine.txt"), b"keep").expect("write");
        assert_eq!(remove_leftovers(dir.path(), std::time::Duration::from_secs(3600)), 0);
        assert!(stale.exists());
        assert_eq!(remove_leftovers(dir.path(), std::time::Duration::ZERO), 1);
        assert!(!stale.exists());
        assert!(dir.path().join("mine.txt").exists());
    }
}
