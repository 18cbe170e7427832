//! The data side of the Windows backend's system calls: which guest paths it serves,
//! how registry key names split into a hive and a subkey, and how registry values
//! are laid out as bytes (`REG_SZ`, `REG_DWORD`, ...).
//!
//! Platform-neutral and tested natively; `desktop/windows/system.rs` makes the calls.

use arena_shared::registry::RegistryValue;

use crate::desktop::{DesktopError, DesktopResult};

/// Longest registry key name component, in characters (Windows' own limit).
pub const MAX_KEY_NAME: usize = 255;
/// Deepest registry key, in levels below the hive (Windows' own limit).
pub const MAX_KEY_DEPTH: usize = 512;
/// Longest registry value name, in characters (Windows' own limit).
pub const MAX_VALUE_NAME: usize = 16_383;

/// Checks a registry key path and value name against Windows' limits, so every
/// backend refuses what Windows would (the stub would otherwise keep any size).
///
/// # Errors
///
/// A message naming the limit and the offending part.
pub fn check_registry_limits(key: &str, value: Option<&str>) -> Result<(), String> {
    let parts: Vec<&str> = key.split('\\').filter(|p| !p.is_empty()).collect();
    if parts.len() > MAX_KEY_DEPTH + 1 {
        return Err(format!("registry key is {} levels deep; Windows allows {MAX_KEY_DEPTH}", parts.len() - 1));
    }
    if let Some(long) = parts.iter().find(|p| p.chars().count() > MAX_KEY_NAME) {
        let shown: String = long.chars().take(32).collect();
        return Err(format!(
            "registry key name {shown:?}... is {} characters; Windows allows {MAX_KEY_NAME}",
            long.chars().count()
        ));
    }
    if let Some(value) = value.filter(|v| v.chars().count() > MAX_VALUE_NAME) {
        return Err(format!(
            "registry value name is {} characters; Windows allows {MAX_VALUE_NAME}",
            value.chars().count()
        ));
    }
    Ok(())
}
/// Registry value types, as `winnt.h` numbers them.
pub const REG_SZ: u32 = 1;
pub const REG_EXPAND_SZ: u32 = 2;
pub const REG_BINARY: u32 = 3;
pub const REG_DWORD: u32 = 4;
pub const REG_DWORD_BIG_ENDIAN: u32 = 5;
pub const REG_MULTI_SZ: u32 = 7;
pub const REG_QWORD: u32 = 11;

/// Checks that `path` is a guest path the Windows backend serves as it is: a
/// drive-letter path (`C:\...`, `C:/...`) or a UNC share (`\\host.lan\Data\...`).
///
/// Relative and drive-relative paths (`a.txt`, `C:a.txt`, `\a.txt`) depend on the
/// server's current directory and are refused. So are device and verbatim paths
/// (`\\.\PhysicalDrive0`, `\\?\C:\...`): they skip the normal path rules and reach
/// devices, and nothing upstream sends them.
///
/// # Errors
///
/// [`DesktopError::InvalidInput`] saying which rule the path breaks.
pub fn check_guest_path(path: &str) -> DesktopResult<()> {
    let bytes = path.as_bytes();
    if path.contains('\0') {
        return Err(DesktopError::InvalidInput(format!("{path:?} contains a NUL character")));
    }
    let sep = |b: u8| b == b'\\' || b == b'/';
    if bytes.len() >= 4 && sep(bytes[0]) && sep(bytes[1]) && (bytes[2] == b'?' || bytes[2] == b'.') && sep(bytes[3]) {
        return Err(DesktopError::InvalidInput(format!(
            "{path}: device and verbatim paths (\\\\.\\, \\\\?\\) are not served"
        )));
    }
    if bytes.len() >= 3 && bytes[0].is_ascii_alphabetic() && bytes[1] == b':' && sep(bytes[2]) {
        return Ok(());
    }
    if bytes.len() >= 3 && sep(bytes[0]) && sep(bytes[1]) && !sep(bytes[2]) {
        return Ok(());
    }
    Err(DesktopError::InvalidInput(format!(
        "{path:?} is not an absolute path (expected C:\\... or \\\\server\\share\\...)"
    )))
}

/// The guest form of a path the OS handed back: verbatim prefixes removed
/// (`\\?\C:\x` is `C:\x`, `\\?\UNC\srv\share` is `\\srv\share`).
pub fn unverbatim(path: &str) -> String {
    if let Some(rest) = path.strip_prefix(r"\\?\UNC\") {
        return format!(r"\\{rest}");
    }
    if let Some(rest) = path.strip_prefix(r"\\?\") {
        return rest.to_owned();
    }
    path.to_owned()
}

/// A predefined registry root.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Hive {
    CurrentUser,
    LocalMachine,
    ClassesRoot,
    Users,
    CurrentConfig,
}

/// Splits `HKEY_CURRENT_USER\Software\X` (or `HKCU\Software\X`, any case, `/` or `\`)
/// into its hive and subkey (`Software\X`, separators normalised, no trailing one).
///
/// # Errors
///
/// [`DesktopError::InvalidInput`] when the key does not start with a known hive.
pub fn split_key(key: &str) -> DesktopResult<(Hive, String)> {
    let normalized = key.replace('/', "\\");
    let trimmed = normalized.trim_matches('\\');
    let (root, rest) = trimmed.split_once('\\').unwrap_or((trimmed, ""));
    let hive = match root.to_ascii_uppercase().as_str() {
        "HKCU" | "HKEY_CURRENT_USER" => Hive::CurrentUser,
        "HKLM" | "HKEY_LOCAL_MACHINE" => Hive::LocalMachine,
        "HKCR" | "HKEY_CLASSES_ROOT" => Hive::ClassesRoot,
        "HKU" | "HKEY_USERS" => Hive::Users,
        "HKCC" | "HKEY_CURRENT_CONFIG" => Hive::CurrentConfig,
        _ => {
            return Err(DesktopError::InvalidInput(format!(
                "registry key {key:?} does not start with a hive (HKCU, HKLM, HKCR, HKU or HKCC)"
            )))
        }
    };
    let subkey: Vec<&str> = rest.split('\\').filter(|p| !p.is_empty()).collect();
    Ok((hive, subkey.join("\\")))
}

fn utf16_bytes(units: impl Iterator<Item = u16>) -> Vec<u8> {
    units.flat_map(u16::to_le_bytes).collect()
}

/// A value as the registry stores it: its type and bytes.
///
/// # Errors
///
/// [`DesktopError::InvalidInput`] for [`RegistryValue::Unknown`] and strings with NULs.
pub fn encode_value(value: &RegistryValue) -> DesktopResult<(u32, Vec<u8>)> {
    let no_nul = |s: &str| {
        if s.contains('\0') {
            Err(DesktopError::InvalidInput(format!("registry string {s:?} contains a NUL character")))
        } else {
            Ok(())
        }
    };
    Ok(match value {
        RegistryValue::String(s) => {
            no_nul(s)?;
            (REG_SZ, utf16_bytes(s.encode_utf16().chain([0])))
        }
        RegistryValue::Dword(v) => (REG_DWORD, v.to_le_bytes().to_vec()),
        RegistryValue::Qword(v) => (REG_QWORD, v.to_le_bytes().to_vec()),
        RegistryValue::MultiString(items) => {
            let wide = super::text::wide_multi(items)
                .map_err(|e| DesktopError::InvalidInput(format!("registry multi-string: {e}")))?;
            (REG_MULTI_SZ, utf16_bytes(wide.into_iter()))
        }
        RegistryValue::Binary(bytes) => (REG_BINARY, bytes.clone()),
        RegistryValue::Unknown => return Err(DesktopError::InvalidInput("unknown registry value type".into())),
    })
}

/// Reads a value of registry type `kind` from its bytes. Types this API has no
/// variant for (links, resource lists) come back as their raw bytes.
pub fn decode_value(kind: u32, data: &[u8]) -> RegistryValue {
    let units = || -> Vec<u16> { data.chunks_exact(2).map(|c| u16::from_le_bytes([c[0], c[1]])).collect() };
    match kind {
        REG_SZ | REG_EXPAND_SZ => RegistryValue::String(super::text::from_wide_until_nul(&units())),
        REG_MULTI_SZ => RegistryValue::MultiString(super::text::split_multi(&units())),
        REG_DWORD if data.len() >= 4 => RegistryValue::Dword(u32::from_le_bytes([data[0], data[1], data[2], data[3]])),
        REG_DWORD_BIG_ENDIAN if data.len() >= 4 => {
            RegistryValue::Dword(u32::from_be_bytes([data[0], data[1], data[2], data[3]]))
        }
        REG_QWORD if data.len() >= 8 => {
            let mut b = [0u8; 8];
            b.copy_from_slice(&data[..8]);
            RegistryValue::Qword(u64::from_le_bytes(b))
        }
        _ => RegistryValue::Binary(data.to_vec()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn registry_paths_are_held_to_windows_limits() {
        assert!(check_registry_limits(r"HKCU\Software\Arena", Some("Name")).is_ok());
        let deep = format!("HKCU{}", "\\k".repeat(MAX_KEY_DEPTH));
        assert!(check_registry_limits(&deep, None).is_ok());
        let too_deep = format!("{deep}\\k");
        assert!(check_registry_limits(&too_deep, None).unwrap_err().contains("levels deep"));
        let long = format!(r"HKCU\{}", "n".repeat(MAX_KEY_NAME + 1));
        assert!(check_registry_limits(&long, None).unwrap_err().contains("255"));
        assert!(check_registry_limits("HKCU", Some(&"v".repeat(MAX_VALUE_NAME + 1))).unwrap_err().contains("16383"));
    }

    #[test]
    fn only_absolute_drive_and_unc_paths_are_served() {
        for ok in [r"C:\Users\Docker", "c:/x", r"\\host.lan\Data\server", r"D:\"] {
            assert!(check_guest_path(ok).is_ok(), "{ok}");
        }
        for bad in
            ["a.txt", "C:a.txt", r"\a.txt", r"\\?\C:\x", r"\\.\PhysicalDrive0", "//./pipe/x", "", r"\\\x", "C:\\a\0b"]
        {
            assert!(matches!(check_guest_path(bad), Err(DesktopError::InvalidInput(_))), "{bad:?}");
        }
    }

    #[test]
    fn verbatim_prefixes_are_removed() {
        assert_eq!(unverbatim(r"\\?\C:\Users"), r"C:\Users");
        assert_eq!(unverbatim(r"\\?\UNC\srv\share\a"), r"\\srv\share\a");
        assert_eq!(unverbatim(r"C:\x"), r"C:\x");
    }

    fn check(key: &str, hive: Hive, subkey: &str) {
        assert_eq!(split_key(key).unwrap(), (hive, subkey.to_owned()), "{key}");
    }

    #[test]
    fn keys_split_into_hive_and_subkey() {
        check(r"HKEY_CURRENT_USER\Control Panel\Desktop", Hive::CurrentUser, r"Control Panel\Desktop");
        check(r"hkcu\\Software\\Arena\\", Hive::CurrentUser, r"Software\Arena");
        check("HKLM/SOFTWARE/Microsoft", Hive::LocalMachine, r"SOFTWARE\Microsoft");
        check(r"HKEY_CLASSES_ROOT\.txt", Hive::ClassesRoot, ".txt");
        check(r"HKU\.DEFAULT", Hive::Users, ".DEFAULT");
        check("HKCC", Hive::CurrentConfig, "");
        assert!(split_key(r"HKXX\a").unwrap_err().to_string().contains("HKXX"));
    }

    #[test]
    fn values_round_trip_through_bytes() {
        for value in [
            RegistryValue::String("Wallpaper Ü".into()),
            RegistryValue::String(String::new()),
            RegistryValue::Dword(0xDEAD_BEEF),
            RegistryValue::Qword(1 << 40),
            RegistryValue::MultiString(vec!["a".into(), "bc".into()]),
            RegistryValue::MultiString(vec![]),
            RegistryValue::Binary(vec![0, 1, 2, 255]),
        ] {
            let (kind, bytes) = encode_value(&value).unwrap();
            assert_eq!(decode_value(kind, &bytes), value, "{value:?}");
        }
        assert_eq!(encode_value(&RegistryValue::String("ab".into())).unwrap(), (REG_SZ, vec![b'a', 0, b'b', 0, 0, 0]));
        assert!(encode_value(&RegistryValue::Unknown).is_err());
        assert!(encode_value(&RegistryValue::String("a\0".into())).is_err());
    }

    #[test]
    fn odd_types_and_short_data_decode_safely() {
        assert_eq!(decode_value(REG_EXPAND_SZ, &[b'%', 0, b'A', 0, 0, 0]), RegistryValue::String("%A".into()));
        assert_eq!(decode_value(REG_DWORD_BIG_ENDIAN, &[0, 0, 1, 0]), RegistryValue::Dword(256));
        assert_eq!(decode_value(REG_DWORD, &[1, 2]), RegistryValue::Binary(vec![1, 2]));
        assert_eq!(decode_value(6, &[9]), RegistryValue::Binary(vec![9]));
        // A string without its terminator, as some programs write them.
        assert_eq!(decode_value(REG_SZ, &[b'h', 0, b'i', 0]), RegistryValue::String("hi".into()));
    }
}

/// The Win32 error code inside an `HRESULT_FROM_WIN32` value (`0x8007xxxx`), if it is one.
pub fn win32_code(hresult: i32) -> Option<u32> {
    let bits = hresult as u32;
    (bits & 0xFFFF_0000 == 0x8007_0000).then_some(bits & 0xFFFF)
}

/// What starting `program` failing with Win32 error `code` means, in words a caller
/// can act on; `None` for codes without a better message than the system's own.
pub fn spawn_failure(code: u32, program: &str) -> Option<DesktopError> {
    Some(match code {
        // ERROR_FILE_NOT_FOUND, ERROR_PATH_NOT_FOUND
        2 | 3 => DesktopError::NotFound(format!("program {program} not found")),
        // ERROR_DIRECTORY
        267 => DesktopError::NotFound(format!("working directory of {program} not found")),
        // ERROR_BAD_EXE_FORMAT
        193 => DesktopError::InvalidInput(format!("{program} is not a valid Windows program")),
        // ERROR_ELEVATION_REQUIRED: the program's manifest asks for administrator rights.
        740 => DesktopError::PermissionDenied(format!(
            "{program} needs elevation (error 740) and the server is not elevated: install the service with \
             --worker-token elevated (the default) or start arena-guest as administrator"
        )),
        // ERROR_ACCESS_DENIED
        5 => DesktopError::PermissionDenied(format!(
            "access denied starting {program} (error 5): the server's user may not run it, or it is blocked"
        )),
        _ => return None,
    })
}

#[cfg(test)]
mod spawn_tests {
    use super::*;

    #[test]
    fn spawn_failures_name_the_program_and_what_to_do() {
        assert_eq!(win32_code(0x8007_02E4_u32 as i32), Some(740));
        assert_eq!(win32_code(0x8000_4005_u32 as i32), None);
        let err = spawn_failure(740, "regedit.exe").unwrap();
        assert!(matches!(err, DesktopError::PermissionDenied(_)), "{err:?}");
        assert!(err.to_string().contains("regedit.exe needs elevation (error 740)"), "{err}");
        assert!(matches!(spawn_failure(2, "x.exe"), Some(DesktopError::NotFound(m)) if m == "program x.exe not found"));
        assert!(matches!(spawn_failure(5, "x.exe"), Some(DesktopError::PermissionDenied(_))));
        assert!(spawn_failure(1455, "x.exe").is_none());
    }
}

/// What opening `path` with its associated program (`ShellExecuteExW`, as Python's
/// `os.startfile`) failing with Win32 error `code` means.
pub fn open_failure(code: u32, path: &str) -> DesktopError {
    match code {
        // ERROR_FILE_NOT_FOUND, ERROR_PATH_NOT_FOUND
        2 | 3 => DesktopError::NotFound(format!("{path}: not found")),
        // ERROR_NO_ASSOCIATION
        1155 => {
            DesktopError::Os { op: "open", message: format!("{path}: no application is associated with this file") }
        }
        // ERROR_ACCESS_DENIED
        5 => DesktopError::PermissionDenied(format!("{path}: access denied (error 5)")),
        // ERROR_ELEVATION_REQUIRED
        740 => DesktopError::PermissionDenied(format!(
            "{path}: its program needs elevation (error 740) and the server is not elevated"
        )),
        // ERROR_CANCELLED: someone dismissed a prompt (an "open with" or elevation dialog).
        1223 => DesktopError::Os { op: "open", message: format!("{path}: the operation was cancelled at a prompt") },
        c => DesktopError::Os { op: "open", message: format!("{path}: ShellExecuteExW failed with error {c}") },
    }
}

/// The working directory a command gets when its caller names none.
///
/// Upstream's server runs from a logon task whose working directory is the folder its
/// script lives in (a share, `\\host.lan\Data`). A program started from an argument
/// vector inherits that folder: here the server's own folder (`install_dir`, the one
/// the service's worker and the logon task also start in). A shell line starts
/// `cmd.exe`, which refuses a share as its current directory and falls back to the
/// Windows folder: here `system_root` (`%SystemRoot%`) directly, without cmd's
/// warning. Either missing leaves the choice to the process's own directory (`None`).
pub fn default_exec_dir(shell: bool, system_root: Option<&str>, install_dir: Option<&str>) -> Option<String> {
    let chosen = if shell { system_root } else { install_dir };
    chosen.map(str::trim).filter(|dir| !dir.is_empty()).map(str::to_owned)
}

#[cfg(test)]
mod exec_dir_tests {
    use super::*;

    #[test]
    fn shell_lines_start_in_the_windows_folder_and_programs_in_the_servers() {
        let root = Some(r"C:\Windows");
        let install = Some(r"C:\arena");
        assert_eq!(default_exec_dir(true, root, install).as_deref(), Some(r"C:\Windows"));
        assert_eq!(default_exec_dir(false, root, install).as_deref(), Some(r"C:\arena"));
        // Unknown folders leave the process's own directory in charge.
        assert_eq!(default_exec_dir(true, None, install), None);
        assert_eq!(default_exec_dir(false, root, Some("  ")), None);
    }

    #[test]
    fn open_failures_say_what_went_wrong() {
        assert!(matches!(open_failure(2, r"C:\x.txt"), DesktopError::NotFound(m) if m == r"C:\x.txt: not found"));
        assert!(open_failure(1155, "a.xyz").to_string().contains("no application is associated"));
        assert!(matches!(open_failure(740, "setup.exe"), DesktopError::PermissionDenied(_)));
        assert!(open_failure(1223, "a").to_string().contains("cancelled"));
        assert!(open_failure(31, "a").to_string().contains("error 31"));
    }
}
