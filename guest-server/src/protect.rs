//! What the server never deletes, moves, recycles or overwrites, whoever asks: drive
//! roots, the Windows and Program Files folders, `ProgramData`, the user's profile, its
//! known folders (Desktop, Documents, ...) and every folder that holds one of them (`C:\Users`).
//!
//! Every route that deletes, recycles or overwrites asks [`refuse_destructive`] first,
//! on every backend, so `DELETE /v1/files?path=C:\&recursive=true` is a 403 and never
//! a wiped drive, and a Windows shell that would report success for a drive root it did
//! not move is never asked. Files and folders inside those folders are the agent's to
//! change, as upstream allows. Platform-neutral: the folders come from the backend's
//! environment and known folders.
//!
//! The rules compare what a path names, not how it is spelt: [`canonical`] turns every
//! spelling Windows accepts for one file into one string before any comparison. Rooted
//! paths (`\`, `/Users`) are on the system drive (the current drive of every guest
//! process); `\\?\`, `\\.\` and `\??\` prefixes are dropped; admin shares
//! (`\\localhost\C$\...`, `\\127.0.0.1\c$`, `\\?\UNC\<computer name>\C$`, and those of any
//! other host name or address, since the guest cannot know every name that reaches it: a
//! VM's NAT address, an alias) are their drives; paths into the device namespace that
//! name no drive letter (`\\?\Volume{GUID}\`, `\\?\GLOBALROOT\Device\...`,
//! `\\.\PhysicalDrive0`) are kept apart and refused by every destructive route; `.` and `..` are applied; trailing dots and spaces and stream suffixes
//! (`:$DATA`) are cut from each name, as Win32 does; 8.3 short names (`PROGRA~1`) are
//! expanded by the backend (`GetLongPathNameW` on Windows); case is folded.

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

/// What a backend knows beyond a path's spelling, for [`canonical`].
pub struct Resolver<'a> {
    /// The drive of rooted paths (`\Users`): `%SystemDrive%`, `C:` by default.
    pub system_drive: String,
    /// The long form of a path holding 8.3 short names, when the backend has them.
    pub long_path: &'a dyn Fn(&str) -> Option<String>,
}

impl std::fmt::Debug for Resolver<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Resolver").field("system_drive", &self.system_drive).finish_non_exhaustive()
    }
}

fn no_long_names(_: &str) -> Option<String> {
    None
}

impl Resolver<'static> {
    /// The resolver of `desktop`: its `%SystemDrive%` and `%COMPUTERNAME%`, and on the
    /// Windows backend the system's own expansion of short names (the stub has none).
    pub fn of(desktop: &dyn Desktop) -> Resolver<'static> {
        let system_drive = desktop
            .env_var("SystemDrive")
            .map(|d| d.trim().trim_end_matches(['\\', '/']).to_owned())
            .filter(|d| d.len() == 2 && d.ends_with(':') && d.starts_with(|c: char| c.is_ascii_alphabetic()))
            .unwrap_or_else(|| "C:".to_owned());
        let long_path: &'static dyn Fn(&str) -> Option<String> = if desktop.kind() == "windows" {
            &crate::desktop::windows::longname::long_path_name
        } else {
            &no_long_names
        };
        Resolver { system_drive, long_path }
    }
}

/// Refuses to let `op` remove, move or overwrite `guest_path` (absolute, expanded) when
/// it names a protected folder or one that holds one, however it is spelt.
///
/// # Errors
///
/// [`DesktopError::PermissionDenied`] naming the path and what it is.
pub fn refuse_destructive(desktop: &dyn Desktop, op: &str, guest_path: &str) -> DesktopResult<()> {
    let resolver = Resolver::of(desktop);
    let path = canonical(guest_path, &resolver);
    let shown = crate::error::clip(guest_path);
    if path.starts_with(DEVICE) {
        return Err(refused(op, &shown, "a volume or device path (only drive-letter and share paths are changed)"));
    }
    if is_root(&path) {
        return Err(refused(op, &shown, "a drive root"));
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
        if folder.trim().is_empty() {
            continue;
        }
        let folder = canonical(&folder, &resolver);
        if is_root(&folder) {
            continue;
        }
        if path == folder {
            return Err(refused(op, &shown, &what));
        }
        if folder.starts_with(&format!("{path}\\")) {
            return Err(refused(op, &shown, &format!("a folder holding {what}")));
        }
    }
    Ok(())
}

fn refused(op: &str, path: &str, what: &str) -> DesktopError {
    DesktopError::PermissionDenied(format!(
        "refusing to {op} {path}: it is {what}, which this server never removes (change what is inside it instead)"
    ))
}

/// How [`canonical`] starts a path into the device namespace that names no drive letter.
const DEVICE: &str = r"\\?\";

/// What `path` names, as one string: `x:\name\name` (or `\\host\share\name` for a share
/// of another machine), lower case, with no trailing separator but a root's. See the
/// module's documentation for the spellings it folds.
pub fn canonical(path: &str, resolver: &Resolver<'_>) -> String {
    let mut path = path.trim().replace('/', "\\");
    // Win32 device and verbatim prefixes, and the NT object-manager one, name the same
    // files: `\\?\C:\x`, `\\.\C:\x`, `\??\C:\x`; `\\?\UNC\h\s` is `\\h\s`.
    while let Some(prefix) = path.get(..4) {
        if !matches!(prefix, r"\\?\" | r"\\.\" | r"\??\") {
            break;
        }
        let rest = &path[4..];
        path = match rest.get(..4) {
            Some(unc) if unc.eq_ignore_ascii_case(r"UNC\") => format!(r"\\{}", &rest[4..]),
            _ if !names_a_drive(rest) && !rest.starts_with(['\\', '?', '.']) => {
                // A volume, a device or an object-manager path: no drive letter to resolve to.
                return format!("{DEVICE}{}", rest.to_lowercase());
            }
            _ => rest.to_owned(),
        };
    }
    let (root, rest) = split_root(&path, resolver);
    let mut parts: Vec<String> = Vec::new();
    for part in rest.split('\\') {
        // A stream suffix (`name:$DATA`, `name::$INDEX_ALLOCATION`) names the file itself.
        let name = part.split(':').next().unwrap_or_default();
        let trimmed = name.trim_end_matches([' ', '.']);
        if trimmed.is_empty() {
            // "", ".", "..", "..." and the like: only ".." moves, to the parent.
            if name.trim_end_matches(' ') == ".." {
                parts.pop();
            }
            continue;
        }
        parts.push(trimmed.to_owned());
    }
    let mut joined = join(&root, &parts);
    if parts.iter().any(|p| p.contains('~')) {
        joined = expand_short_names(&root, &parts, resolver).unwrap_or(joined);
    }
    joined.to_lowercase()
}

/// Whether `path` starts with a drive letter and its colon.
fn names_a_drive(path: &str) -> bool {
    let bytes = path.as_bytes();
    bytes.len() >= 2 && bytes[1] == b':' && bytes[0].is_ascii_alphabetic()
}

/// The root of a path (`C:\` or `\\host\share`) and the rest after it.
fn split_root<'p>(path: &'p str, resolver: &Resolver<'_>) -> (String, &'p str) {
    let bytes = path.as_bytes();
    if bytes.len() >= 2 && bytes[1] == b':' && bytes[0].is_ascii_alphabetic() {
        return (format!("{}:\\", char::from(bytes[0].to_ascii_uppercase())), &path[2..]);
    }
    if let Some(unc) = path.strip_prefix(r"\\") {
        let mut it = unc.splitn(3, '\\');
        let host = it.next().unwrap_or_default();
        let share = it.next().unwrap_or_default();
        let rest = it.next().unwrap_or_default();
        let share_name = share.trim_end_matches([' ', '.']);
        let admin_drive = share_name.len() == 2
            && share_name.ends_with('$')
            && share_name.starts_with(|c: char| c.is_ascii_alphabetic());
        if admin_drive {
            return (format!("{}:\\", share_name[..1].to_ascii_uppercase()), rest);
        }
        return (format!(r"\\{}\{}", host.to_lowercase(), share_name.to_lowercase()), rest);
    }
    // Rooted without a drive: the current drive, which is the system drive for every
    // guest program. Relative paths never reach here (the backends refuse them).
    (format!("{}\\", resolver.system_drive.to_ascii_uppercase()), path)
}

/// `root` + `parts` with short names expanded: the longest prefix the resolver expands.
fn expand_short_names(root: &str, parts: &[String], resolver: &Resolver<'_>) -> Option<String> {
    let last_short = parts.iter().rposition(|p| p.contains('~'))?;
    for end in (last_short + 1..=parts.len()).rev() {
        let Some(long) = (resolver.long_path)(&join(root, &parts[..end])) else { continue };
        let long = long.strip_prefix(r"\\?\").unwrap_or(&long).trim_end_matches('\\').to_owned();
        let mut full = long;
        for part in &parts[end..] {
            full.push('\\');
            full.push_str(part);
        }
        return Some(full);
    }
    None
}

/// `root` and `parts` as one path, one separator between each.
fn join(root: &str, parts: &[String]) -> String {
    let mut joined = root.to_owned();
    for part in parts {
        if !joined.ends_with('\\') {
            joined.push('\\');
        }
        joined.push_str(part);
    }
    joined
}

/// Whether a canonical path is a root: a drive's or a share's.
fn is_root(canonical: &str) -> bool {
    (canonical.len() == 3 && canonical.ends_with(":\\"))
        || canonical.strip_prefix(r"\\").is_some_and(|unc| unc.split('\\').filter(|p| !p.is_empty()).count() <= 2)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::desktop::stub::StubDesktop;

    /// The short names a Windows volume would have, for the Windows resolver.
    fn windows_long_path(path: &str) -> Option<String> {
        let lower = path.to_lowercase();
        let table = [
            (r"c:\progra~1", r"C:\Program Files"),
            (r"c:\progra~2", r"C:\Program Files (x86)"),
            (r"c:\progra~3", r"C:\ProgramData"),
            (r"c:\users\docker~1", r"C:\Users\Docker"),
            (r"c:\users\docker~1\docume~1", r"C:\Users\Docker\Documents"),
        ];
        table.iter().find(|(short, _)| *short == lower).map(|(_, long)| (*long).to_owned())
    }

    fn stub_resolver() -> Resolver<'static> {
        Resolver { system_drive: "C:".into(), long_path: &no_long_names }
    }

    fn windows_resolver() -> Resolver<'static> {
        Resolver { system_drive: "C:".into(), long_path: &windows_long_path }
    }

    /// Every spelling of a protected folder, with what each backend's resolver makes of
    /// it: `(input, stub, windows)`; `None` when both agree on the second column.
    const SPELLINGS: &[(&str, &str, Option<&str>)] = &[
        (r"C:\", r"c:\", None),
        ("C:", r"c:\", None),
        ("c:/", r"c:\", None),
        ("/", r"c:\", None),
        (r"\", r"c:\", None),
        (r"\Users\Docker", r"c:\users\docker", None),
        ("/Windows", r"c:\windows", None),
        ("/Users/", r"c:\users", None),
        (r"/Users/../Users/./Docker", r"c:\users\docker", None),
        ("c:/Users/Docker/", r"c:\users\docker", None),
        (r"C:\Users\Docker\Desktop\..", r"c:\users\docker", None),
        (r"C:\Users\.\Docker\\Desktop", r"c:\users\docker\desktop", None),
        (r"C:\Users\Docker\Desktop. ", r"c:\users\docker\desktop", None),
        (r"C:\Windows...", r"c:\windows", None),
        (r"C:\Windows::$INDEX_ALLOCATION", r"c:\windows", None),
        (r"C:\Users\Docker:$I30:$INDEX_ALLOCATION", r"c:\users\docker", None),
        (r"\\?\C:\Windows", r"c:\windows", None),
        (r"\\?\C:\", r"c:\", None),
        (r"\\.\C:\Users\Docker", r"c:\users\docker", None),
        (r"\??\C:\Windows", r"c:\windows", None),
        ("//?/c:/windows", r"c:\windows", None),
        (r"\\localhost\C$\Users\Docker", r"c:\users\docker", None),
        (r"\\LOCALHOST\c$", r"c:\", None),
        (r"\\127.0.0.1\c$\Windows", r"c:\windows", None),
        (r"\\127.1\C$\Windows", r"c:\windows", None),
        (r"\\[::1]\C$\Program Files", r"c:\program files", None),
        (r"\\::1\C$\ProgramData", r"c:\programdata", None),
        (r"\\?\UNC\localhost\C$\Users", r"c:\users", None),
        (r"\\.\UNC\127.0.0.1\C$\Users", r"c:\users", None),
        (r"\\arena-stub\C$\Users", r"c:\users", None),
        (r"\\WIN-GUEST\C$\Users", r"c:\users", None),
        (r"\\10.0.2.15\C$\Windows", r"c:\windows", None),
        (r"\\fileserver\d$\Users", r"d:\users", None),
        (r"\\fileserver\data\Users", r"\\fileserver\data\users", None),
        (
            r"\\?\Volume{26a21bda-a627-11d7-9931-806e6f6e6963}\Windows",
            r"\\?\volume{26a21bda-a627-11d7-9931-806e6f6e6963}\windows",
            None,
        ),
        (r"\\?\GLOBALROOT\Device\HarddiskVolume3\Users", r"\\?\globalroot\device\harddiskvolume3\users", None),
        (r"\\.\PhysicalDrive0", r"\\?\physicaldrive0", None),
        (
            r"\??\Volume{26a21bda-a627-11d7-9931-806e6f6e6963}\",
            r"\\?\volume{26a21bda-a627-11d7-9931-806e6f6e6963}\",
            None,
        ),
        (r"\\localhost\Users", r"\\localhost\users", None),
        (r"C:\PROGRA~1", r"c:\progra~1", Some(r"c:\program files")),
        (r"c:\progra~2\", r"c:\progra~2", Some(r"c:\program files (x86)")),
        (r"C:\Users\DOCKER~1\DOCUME~1", r"c:\users\docker~1\docume~1", Some(r"c:\users\docker\documents")),
        (r"C:\Users\DOCKER~1\Desktop", r"c:\users\docker~1\desktop", Some(r"c:\users\docker\desktop")),
        (r"\\localhost\c$\PROGRA~3", r"c:\progra~3", Some(r"c:\programdata")),
        (r"C:\Users\Docker\Desktop\report.txt", r"c:\users\docker\desktop\report.txt", None),
    ];

    #[test]
    fn every_spelling_resolves_to_what_it_names_on_both_backends() {
        for (resolver, column) in [(stub_resolver(), "stub"), (windows_resolver(), "windows")] {
            for (input, stub, windows) in SPELLINGS {
                let expected = if column == "windows" { windows.unwrap_or(stub) } else { stub };
                assert_eq!(canonical(input, &resolver), *expected, "{column} resolver, {input:?}");
            }
        }
    }

    #[test]
    fn the_stub_resolver_is_the_stubs() {
        let dir = tempfile::tempdir().expect("dir");
        let stub = StubDesktop::new(dir.path().to_path_buf()).expect("stub");
        let resolver = Resolver::of(&stub);
        assert_eq!(resolver.system_drive, "C:");
        assert_eq!((resolver.long_path)(r"C:\PROGRA~1"), None);
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
            "/",
            r"\",
            r"\Users\Docker",
            "/Windows",
            "/Users",
            r"\\localhost\C$",
            r"\\127.0.0.1\c$\Users\Docker",
            r"\\?\UNC\localhost\C$\Windows",
            r"\\.\C:\Program Files",
            r"\\server\share",
            r"\\10.0.2.15\C$\Users\Docker",
            r"\\?\Volume{26a21bda-a627-11d7-9931-806e6f6e6963}\",
            r"\\?\Volume{26a21bda-a627-11d7-9931-806e6f6e6963}\Users\Docker\Desktop\a.txt",
            r"\\?\GLOBALROOT\Device\HarddiskVolume3\Windows",
            r"\\.\PhysicalDrive0",
            r"C:\Windows",
            r"c:\windows\",
            r"C:\Windows.",
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
            r"\Users\Docker\Desktop\a.txt",
            r"C:\data",
        ] {
            check(path, false);
        }
    }

    #[test]
    fn a_refusal_quotes_a_bounded_prefix_of_the_path() {
        let dir = tempfile::tempdir().expect("dir");
        let stub = StubDesktop::new(dir.path().to_path_buf()).expect("stub");
        let long = format!(r"C:\{}\..\..", "x".repeat(100_000));
        let err = refuse_destructive(&stub, "delete", &long).expect_err("the drive root");
        assert!(err.to_string().len() < 1000, "{}", err.to_string().len());
    }
}
