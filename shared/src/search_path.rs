//! Finding a program on `PATH` as a shell does, the one lookup of the workspace: the
//! stub backend's check that a shell line's program exists, the guest's real-Python
//! fallback for `/execute`, the host's QEMU, and the test support's stand-in VM.
//!
//! A name with a folder in it is checked as given; a bare name is tried in each `PATH`
//! folder in order, as it is and with the platform's executable suffix
//! ([`std::env::consts::EXE_SUFFIX`]: `.exe` on Windows, none elsewhere). A candidate
//! counts when it is a file that can be run (on Unix, one with an execute bit).
//! It reads the file system and the environment; it is not a shell and knows no
//! built-in commands, `PATHEXT` or App Paths.

use std::ffi::OsStr;
use std::path::{Path, PathBuf};

/// `name` on this process's `PATH`, or `name` itself when it has a folder part.
pub fn find_program(name: &Path) -> Option<PathBuf> {
    find_in(name, std::env::var_os("PATH").as_deref())
}

/// `name` on `path` (a `PATH`-style list; `None` finds no bare name).
pub fn find_in(name: &Path, path: Option<&OsStr>) -> Option<PathBuf> {
    if name.as_os_str().is_empty() {
        return None;
    }
    if name.is_absolute() || name.components().count() > 1 {
        return runnable(name).then(|| name.to_path_buf());
    }
    std::env::split_paths(path?).find_map(|dir| {
        let plain = dir.join(name);
        let suffixed = (!std::env::consts::EXE_SUFFIX.is_empty()).then(|| {
            let mut file = plain.clone().into_os_string();
            file.push(std::env::consts::EXE_SUFFIX);
            PathBuf::from(file)
        });
        std::iter::once(plain).chain(suffixed).find(|candidate| runnable(candidate))
    })
}

/// Whether `path` is a file this process could run.
fn runnable(path: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::metadata(path).is_ok_and(|m| m.is_file() && m.permissions().mode() & 0o111 != 0)
    }
    #[cfg(not(unix))]
    {
        path.is_file()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Writes an empty program file (executable on Unix) into `dir`.
    fn program(dir: &Path, name: &str) -> PathBuf {
        let file = dir.join(name);
        std::fs::write(&file, b"").expect("write");
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            std::fs::set_permissions(&file, std::fs::Permissions::from_mode(0o755)).expect("chmod");
        }
        file
    }

    #[test]
    fn the_first_runnable_file_on_the_path_is_found() {
        let (a, b) = (tempfile::tempdir().expect("dir"), tempfile::tempdir().expect("dir"));
        let name = format!("qemu-system-x86_64{}", std::env::consts::EXE_SUFFIX);
        let found = program(b.path(), &name);
        let path = std::env::join_paths([a.path(), b.path()]).expect("join");
        assert_eq!(find_in(Path::new("qemu-system-x86_64"), Some(&path)), Some(found.clone()));
        assert_eq!(find_in(Path::new("qemu-system-x86_64"), None), None);
        assert_eq!(find_in(&found, None), Some(found), "a path is checked as given");
        assert_eq!(find_in(Path::new("arena-no-such-program-xyz"), Some(&path)), None);
        assert_eq!(find_in(Path::new("/definitely/not/python3"), Some(&path)), None);
        assert_eq!(find_in(Path::new(""), Some(&path)), None);
    }

    #[cfg(unix)]
    #[test]
    fn a_file_without_an_execute_bit_is_not_a_program() {
        let dir = tempfile::tempdir().expect("dir");
        std::fs::write(dir.path().join("notes"), b"").expect("write");
        assert_eq!(find_in(Path::new("notes"), Some(dir.path().as_os_str())), None);
    }
}
