//! The stub's file system: guest paths (`C:\Users\Docker\a.txt`) mapped under one root
//! directory (`<root>/C/Users/Docker/a.txt`), the user profile, the environment and known folders.
//!
//! This is path arithmetic plus a few `std::fs` calls; it is not a sandbox against
//! symlinks planted under the root by the host.

use std::path::{Path, PathBuf};

use arena_shared::files::KnownFolder;

use crate::desktop::{DesktopError, DesktopResult};

/// The guest user's profile folder.
pub(crate) const PROFILE: &str = r"C:\Users\Docker";

/// Folders created at start-up, relative to the profile.
const PROFILE_DIRS: &[&str] =
    &["Desktop", "Documents", "Downloads", "Pictures", "Music", "Videos", r"AppData\Roaming", r"AppData\Local\Temp"];

/// Characters Windows forbids in file names (besides separators and control characters).
const FORBIDDEN: &[char] = &['<', '>', ':', '"', '|', '?', '*'];

/// Splits an absolute guest path into its upper-case drive letter and its
/// normalised components (`.` dropped, `..` applied).
///
/// `\Users\x` (rooted without a drive) is taken as drive `C:`, which is the
/// current drive of every guest process.
///
/// # Errors
///
/// A message for relative, drive-relative (`C:foo`), UNC and device paths, a `..` that
/// climbs above the drive, and names with characters Windows forbids.
pub(crate) fn guest_components(path: &str) -> Result<(char, Vec<String>), String> {
    if path.is_empty() {
        return Err("the path is empty".into());
    }
    if path.contains('\0') {
        return Err(format!("{path:?} contains a NUL character"));
    }
    let bytes = path.as_bytes();
    let is_sep = |b: u8| b == b'\\' || b == b'/';
    if bytes.len() >= 2 && is_sep(bytes[0]) && is_sep(bytes[1]) {
        return Err(format!("{path:?} is a UNC or device path, which the stub does not serve"));
    }
    let (drive, rest) = if bytes.len() >= 2 && bytes[1] == b':' && bytes[0].is_ascii_alphabetic() {
        let rest = &path[2..];
        if !rest.is_empty() && !rest.starts_with(['\\', '/']) {
            return Err(format!(
                "{path:?} is relative to the current folder of drive {}: (write {}:\\...)",
                &path[..1],
                &path[..1]
            ));
        }
        (char::from(bytes[0].to_ascii_uppercase()), rest)
    } else if bytes.first().is_some_and(|&b| is_sep(b)) {
        ('C', path)
    } else {
        return Err(format!("{path:?} is a relative path; give an absolute one such as C:\\Users\\Docker\\a.txt"));
    };
    let mut parts: Vec<String> = Vec::new();
    for part in rest.split(['\\', '/']) {
        match part {
            "" | "." => {}
            ".." => {
                if parts.pop().is_none() {
                    return Err(format!("{path:?} climbs above the drive root"));
                }
            }
            name => {
                if let Some(c) = name.chars().find(|c| FORBIDDEN.contains(c) || c.is_control()) {
                    return Err(format!("{path:?}: the name {name:?} contains {c:?}, which Windows forbids"));
                }
                parts.push(name.to_owned());
            }
        }
    }
    Ok((drive, parts))
}

/// Maps a guest path under `root`, resolving each component case-insensitively against
/// what exists (as NTFS would) and keeping the given spelling for what does not.
///
/// # Errors
///
/// [`DesktopError::InvalidInput`] naming the path, for the paths [`guest_components`] rejects.
pub(crate) fn map_path(root: &Path, guest: &str) -> DesktopResult<PathBuf> {
    let (drive, parts) = guest_components(guest).map_err(DesktopError::InvalidInput)?;
    let mut local = root.join(drive.to_string());
    for part in parts {
        let exact = local.join(&part);
        if exact.symlink_metadata().is_ok() {
            local = exact;
            continue;
        }
        local = find_case_insensitive(&local, &part).unwrap_or(exact);
    }
    Ok(local)
}

/// The entry of `dir` whose name equals `name` ignoring case, if there is one.
fn find_case_insensitive(dir: &Path, name: &str) -> Option<PathBuf> {
    let wanted = name.to_lowercase();
    std::fs::read_dir(dir)
        .ok()?
        .filter_map(Result::ok)
        .find(|entry| entry.file_name().to_string_lossy().to_lowercase() == wanted)
        .map(|entry| entry.path())
}

/// The guest path of a local path under `root`: `<root>/C/Users/Docker/a.txt` -> `C:\Users\Docker\a.txt`.
///
/// # Errors
///
/// [`DesktopError::InvalidInput`] for a path outside the root's drive folders.
pub(crate) fn unmap_path(root: &Path, local: &Path) -> DesktopResult<String> {
    let rel = match local.strip_prefix(root) {
        Ok(rel) => rel.to_path_buf(),
        Err(_) => {
            let canonical = local.canonicalize().ok();
            match canonical.as_deref().and_then(|c| c.strip_prefix(root).ok()) {
                Some(rel) => rel.to_path_buf(),
                None => {
                    return Err(DesktopError::InvalidInput(format!("{} is not under the stub root", local.display())))
                }
            }
        }
    };
    let mut parts = rel.components().map(|c| c.as_os_str().to_string_lossy().into_owned());
    let drive = parts.next().filter(|d| d.len() == 1 && d.as_bytes()[0].is_ascii_uppercase());
    let Some(drive) = drive else {
        return Err(DesktopError::InvalidInput(format!(
            "{} is not inside a drive folder of the stub root",
            local.display()
        )));
    };
    let rest: Vec<String> = parts.collect();
    Ok(format!("{drive}:\\{}", rest.join("\\")))
}

/// Creates the drive, the user profile and `C:\Windows` under `root`.
///
/// # Errors
///
/// The I/O error of the first folder that could not be created.
pub(crate) fn create_profile(root: &Path) -> DesktopResult<()> {
    let mut dirs: Vec<String> = PROFILE_DIRS.iter().map(|d| format!(r"{PROFILE}\{d}")).collect();
    dirs.push(r"C:\Windows".into());
    dirs.push(r"C:\Windows\Temp".into());
    dirs.push(r"C:\Program Files".into());
    for dir in dirs {
        let local = map_path(root, &dir)?;
        std::fs::create_dir_all(&local).map_err(|err| DesktopError::io("creating the profile", &dir, err))?;
    }
    Ok(())
}

/// The environment every guest program sees before the scenario's additions.
pub(crate) fn default_env() -> Vec<(String, String)> {
    let pairs = [
        ("USERPROFILE", PROFILE.to_owned()),
        ("USERNAME", "Docker".to_owned()),
        ("USERDOMAIN", "ARENA-STUB".to_owned()),
        ("HOMEDRIVE", "C:".to_owned()),
        ("HOMEPATH", r"\Users\Docker".to_owned()),
        ("APPDATA", format!(r"{PROFILE}\AppData\Roaming")),
        ("LOCALAPPDATA", format!(r"{PROFILE}\AppData\Local")),
        ("TEMP", format!(r"{PROFILE}\AppData\Local\Temp")),
        ("TMP", format!(r"{PROFILE}\AppData\Local\Temp")),
        ("SystemRoot", r"C:\Windows".to_owned()),
        ("windir", r"C:\Windows".to_owned()),
        ("SystemDrive", "C:".to_owned()),
        ("ProgramFiles", r"C:\Program Files".to_owned()),
        ("ProgramFiles(x86)", r"C:\Program Files (x86)".to_owned()),
        ("ProgramData", r"C:\ProgramData".to_owned()),
        ("PUBLIC", r"C:\Users\Public".to_owned()),
        ("COMPUTERNAME", "ARENA-STUB".to_owned()),
        ("OS", "Windows_NT".to_owned()),
        ("PATHEXT", ".COM;.EXE;.BAT;.CMD;.VBS;.JS;.PS1".to_owned()),
        ("ComSpec", r"C:\Windows\system32\cmd.exe".to_owned()),
        ("Path", r"C:\Windows\system32;C:\Windows;C:\Windows\System32\WindowsPowerShell\v1.0\".to_owned()),
        ("PROCESSOR_ARCHITECTURE", "AMD64".to_owned()),
        ("NUMBER_OF_PROCESSORS", "2".to_owned()),
    ];
    pairs.into_iter().map(|(k, v)| (k.to_owned(), v)).collect()
}

/// A known folder's guest path.
///
/// # Errors
///
/// [`DesktopError::InvalidInput`] for [`KnownFolder::Unknown`].
pub(crate) fn known_folder(folder: KnownFolder) -> DesktopResult<String> {
    let sub = match folder {
        KnownFolder::Home => "",
        KnownFolder::Desktop => r"\Desktop",
        KnownFolder::Documents => r"\Documents",
        KnownFolder::Downloads => r"\Downloads",
        KnownFolder::Pictures => r"\Pictures",
        KnownFolder::Music => r"\Music",
        KnownFolder::Videos => r"\Videos",
        KnownFolder::AppData => r"\AppData\Roaming",
        KnownFolder::LocalAppData => r"\AppData\Local",
        KnownFolder::Temp => r"\AppData\Local\Temp",
        KnownFolder::Unknown => return Err(DesktopError::InvalidInput("unknown known folder".into())),
    };
    Ok(format!("{PROFILE}{sub}"))
}

/// Moves `local` (the mapping of `guest`) into `<root>/C/$Recycle.Bin/`, numbering the
/// name when the bin already holds one like it.
///
/// # Errors
///
/// [`DesktopError::NotFound`] when `local` does not exist, [`DesktopError::InvalidInput`]
/// for a drive root, and the I/O error of the move.
pub(crate) fn recycle(root: &Path, guest: &str, local: &Path) -> DesktopResult<()> {
    if local.symlink_metadata().is_err() {
        return Err(DesktopError::NotFound(format!("{guest}: not found")));
    }
    let name = match local.file_name() {
        Some(name) if local.parent() != Some(root) => name.to_string_lossy().into_owned(),
        _ => return Err(DesktopError::InvalidInput(format!("{guest} is a drive root and cannot be recycled"))),
    };
    let bin = root.join("C").join("$Recycle.Bin");
    if local.starts_with(&bin) {
        return Err(DesktopError::InvalidInput(format!("{guest} is already in the Recycle Bin")));
    }
    std::fs::create_dir_all(&bin).map_err(|err| DesktopError::io("recycle", r"C:\$Recycle.Bin", err))?;
    let mut target = bin.join(&name);
    let mut n = 2;
    while target.symlink_metadata().is_ok() {
        target = bin.join(format!("{name} ({n})"));
        n += 1;
    }
    std::fs::rename(local, &target).map_err(|err| DesktopError::io("recycle", guest, err))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(input: &str, expected: Result<&str, &str>) {
        let root = Path::new("/r");
        match (map_path(root, input), expected) {
            (Ok(got), Ok(want)) => assert_eq!(got, Path::new(want), "mapping {input:?}"),
            (Err(DesktopError::InvalidInput(msg)), Err(needle)) => {
                assert!(msg.contains(needle), "error for {input:?} is {msg:?}, expected it to mention {needle:?}")
            }
            (got, want) => panic!("mapping {input:?}: got {got:?}, expected {want:?}"),
        }
    }

    #[test]
    fn guest_paths_map_under_the_root() {
        check(r"C:\Users\Docker\Desktop\a.txt", Ok("/r/C/Users/Docker/Desktop/a.txt"));
        check(r"c:\Users\Docker", Ok("/r/C/Users/Docker"));
        check("C:/Users/Docker/Desktop/a.txt", Ok("/r/C/Users/Docker/Desktop/a.txt"));
        check(r"C:\Users\\Docker\.\Desktop\", Ok("/r/C/Users/Docker/Desktop"));
        check(r"C:\Users\Docker\..\Public", Ok("/r/C/Users/Public"));
        check(r"C:\", Ok("/r/C"));
        check("C:", Ok("/r/C"));
        check(r"d:\data\x.csv", Ok("/r/D/data/x.csv"));
        check(r"\Windows\notepad.exe", Ok("/r/C/Windows/notepad.exe"));
        check(r"C:\a b\c d.txt", Ok("/r/C/a b/c d.txt"));
    }

    #[test]
    fn bad_guest_paths_are_rejected_by_name() {
        check(r"Users\Docker", Err(r"Users\\Docker"));
        check("a.txt", Err("relative"));
        check("", Err("empty"));
        check(r"C:foo", Err("relative"));
        check(r"\\server\share\a.txt", Err("UNC"));
        check(r"\\?\C:\a.txt", Err("UNC"));
        check(r"//server/share", Err("UNC"));
        check(r"C:\..\etc\passwd", Err("climbs"));
        check(r"C:\Users\..\..\x", Err("climbs"));
        check(r"C:\a.txt:stream", Err("forbids"));
        check("C:\\a\0b", Err("NUL"));
        check(r"C:\what?.txt", Err("forbids"));
    }

    #[test]
    fn unmapping_inverts_mapping() {
        let root = Path::new("/r");
        for guest in [r"C:\Users\Docker\Desktop\a.txt", r"C:\", r"D:\x"] {
            let local = map_path(root, guest).unwrap();
            assert_eq!(unmap_path(root, &local).unwrap(), guest);
        }
        assert!(matches!(unmap_path(root, Path::new("/elsewhere/a")), Err(DesktopError::InvalidInput(_))));
        assert!(matches!(unmap_path(root, Path::new("/r")), Err(DesktopError::InvalidInput(_))));
    }

    #[test]
    fn existing_names_resolve_case_insensitively() {
        let dir = tempfile::tempdir().unwrap();
        create_profile(dir.path()).unwrap();
        let got = map_path(dir.path(), r"c:\users\docker\DESKTOP\new.txt").unwrap();
        assert_eq!(got, dir.path().join("C/Users/Docker/Desktop/new.txt"));
    }

    #[test]
    fn known_folders_are_under_the_profile() {
        for folder in KnownFolder::ALL {
            assert!(known_folder(folder).unwrap().starts_with(PROFILE), "{folder:?}");
        }
        assert_eq!(known_folder(KnownFolder::Temp).unwrap(), r"C:\Users\Docker\AppData\Local\Temp");
        assert!(matches!(known_folder(KnownFolder::Unknown), Err(DesktopError::InvalidInput(_))));
    }
}
