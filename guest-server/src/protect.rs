//! What the server never deletes, moves or recycles, whoever asks: drive roots, the
//! Windows and Program Files folders, `ProgramData`, the user's profile, its known
//! folders (Desktop, Documents, ...) and every folder that holds one of them (`C:\Users`).
//!
//! Every route that deletes or recycles asks [`refuse_destructive`] first, on every
//! backend, so `DELETE /v1/files?path=C:\&recursive=true` is a 403 and never a wiped
//! drive, and a Windows shell that would report success for a drive root it did not
//! move is never asked. Files and folders inside those folders are the agent's to
//! change, as upstream allows. Platform-neutral: the folders come from the backend's
//! environment and known folders.

use arena_shared::files::KnownFolder;

use crate::desktop::{Desktop, DesktopError, DesktopResult};

/// Environment variables naming system folders that must stay.
const SYSTEM_FOLDERS: [&str; 8] = [
    "SystemRoot",
    "windir",
    "ProgramFiles",
    "ProgramFiles(x86)",
    "ProgramW6432",
    "ProgramData",
    "USERPROFILE",
    "PUBLIC",
];

/// Refuses to let `op` remove or move `guest_path` (absolute, expanded) when it is a
/// protected folder or holds one.
///
/// # Errors
///
/// [`DesktopError::PermissionDenied`] naming the path and what it is.
pub fn refuse_destructive(desktop: &dyn Desktop, op: &str, guest_path: &str) -> DesktopResult<()> {
    let path = normalize(guest_path);
    if is_drive_root(&path) {
        return Err(refused(op, guest_path, "a drive root"));
    }
    let mut protected: Vec<(String, String)> = SYSTEM_FOLDERS
        .iter()
        .filter_map(|name| desktop.env_var(name).map(|value| (value, format!("%{name}%"))))
        .collect();
    protected.extend(
        KnownFolder::ALL
            .iter()
            .filter_map(|folder| desktop.known_folder(*folder).ok().map(|p| (p, format!("the {folder:?} folder")))),
    );
    for (folder, what) in protected {
        let folder = normalize(&folder);
        if folder.is_empty() || is_drive_root(&folder) {
            continue;
        }
        if path == folder {
            return Err(refused(op, guest_path, &what));
        }
        if folder.starts_with(&format!("{path}\\")) {
            return Err(refused(op, guest_path, &format!("a folder holding {what}")));
        }
    }
    Ok(())
}

fn refused(op: &str, path: &str, what: &str) -> DesktopError {
    DesktopError::PermissionDenied(format!(
        "refusing to {op} {path}: it is {what}, which this server never removes (change what is inside it instead)"
    ))
}

/// A guest path for comparison: separators as `\`, no `\\?\` prefix, `.` and `..`
/// resolved, no trailing separator (but a drive root keeps its `\`), lower case.
fn normalize(path: &str) -> String {
    let path = path.trim().replace('/', "\\");
    let path = path.strip_prefix(r"\\?\").unwrap_or(&path);
    let (drive, rest) = match path.get(..2) {
        Some(d) if d.ends_with(':') && d.starts_with(|c: char| c.is_ascii_alphabetic()) => (d, &path[2..]),
        _ => ("", path),
    };
    let mut parts: Vec<&str> = Vec::new();
    for part in rest.split('\\') {
        match part {
            "" | "." => {}
            ".." => {
                parts.pop();
            }
            other => parts.push(other.trim_end_matches([' ', '.'])),
        }
    }
    format!("{drive}\\{}", parts.join("\\")).to_lowercase()
}

fn is_drive_root(normalized: &str) -> bool {
    normalized.len() == 3 && normalized.ends_with(":\\")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::desktop::stub::StubDesktop;

    #[test]
    fn paths_are_compared_as_windows_compares_them() {
        let check = |input: &str, expected: &str| assert_eq!(normalize(input), expected, "{input:?}");
        check(r"C:\", r"c:\");
        check("C:", r"c:\");
        check("c:/Users/Docker/", r"c:\users\docker");
        check(r"C:\Users\Docker\Desktop\..", r"c:\users\docker");
        check(r"C:\Users\.\Docker\\Desktop", r"c:\users\docker\desktop");
        check(r"\\?\C:\Windows", r"c:\windows");
        check(r"C:\Users\Docker\Desktop. ", r"c:\users\docker\desktop");
    }

    #[test]
    fn system_folders_the_profile_and_their_holders_are_refused() {
        let dir = tempfile::tempdir().expect("dir");
        let stub = StubDesktop::new(dir.path().to_path_buf()).expect("stub");
        let check = |path: &str, refused: bool| {
            let got = refuse_destructive(&stub, "delete", path);
            assert_eq!(got.is_err(), refused, "{path}: {got:?}");
            if let Err(err) = got {
                assert!(matches!(err, DesktopError::PermissionDenied(_)), "{err:?}");
                assert!(err.to_string().contains(path), "{err}");
            }
        };
        for path in [
            r"C:\",
            "D:",
            r"C:\Windows",
            r"c:\windows\",
            r"C:\Program Files",
            r"C:\Program Files (x86)",
            r"C:\ProgramData",
            r"C:\Users",
            r"C:\Users\Docker",
            r"C:\Users\Docker\Desktop",
            r"C:\Users\Docker\Documents\..\Downloads",
            r"C:\Users\Docker\AppData",
            r"C:\Users\Docker\AppData\Local\Temp",
            r"C:\Users\Public",
        ] {
            check(path, true);
        }
        for path in [
            r"C:\Users\Docker\Desktop\report.txt",
            r"C:\Users\Docker\Documents\Projects",
            r"C:\Users\Docker\Desktop2",
            r"C:\Windows\Temp\x.log",
            r"C:\data",
        ] {
            check(path, false);
        }
    }
}
