//! Files and the system: known folders, the Recycle Bin, the registry, the
//! wallpaper, directory ACLs, the session id, shutdown and the clock.

use std::path::Path;

use arena_shared::files::KnownFolder;
use arena_shared::registry::RegistryValue;
use windows::core::{PCWSTR, PWSTR};
use windows::Win32::Foundation::{
    LocalFree, ERROR_FILE_NOT_FOUND, ERROR_MORE_DATA, ERROR_NONE_MAPPED, ERROR_PATH_NOT_FOUND, ERROR_SUCCESS, FILETIME,
    HLOCAL, LUID, WIN32_ERROR,
};
use windows::Win32::Security::Authorization::{GetNamedSecurityInfoW, SE_FILE_OBJECT};
use windows::Win32::Security::{
    AclSizeInformation, AdjustTokenPrivileges, EqualSid, GetAce, GetAclInformation, GetSidSubAuthority,
    GetSidSubAuthorityCount, GetTokenInformation, LookupAccountNameW, LookupPrivilegeValueW, TokenElevationType,
    TokenIntegrityLevel, ACCESS_ALLOWED_ACE, ACE_HEADER, ACL, ACL_SIZE_INFORMATION, DACL_SECURITY_INFORMATION,
    LUID_AND_ATTRIBUTES, PSECURITY_DESCRIPTOR, PSID, SE_PRIVILEGE_ENABLED, SE_SHUTDOWN_NAME, SID_NAME_USE,
    TOKEN_ADJUST_PRIVILEGES, TOKEN_ELEVATION_TYPE, TOKEN_MANDATORY_LABEL, TOKEN_PRIVILEGES, TOKEN_QUERY,
};
use windows::Win32::System::Registry::{
    RegGetValueW, RegSetKeyValueW, HKEY, HKEY_CLASSES_ROOT, HKEY_CURRENT_CONFIG, HKEY_CURRENT_USER, HKEY_LOCAL_MACHINE,
    HKEY_USERS, REG_VALUE_TYPE, RRF_NOEXPAND, RRF_RT_ANY,
};
use windows::Win32::System::RemoteDesktop::ProcessIdToSessionId;
use windows::Win32::System::Shutdown::{
    InitiateSystemShutdownExW, SHTDN_REASON_FLAG_PLANNED, SHTDN_REASON_MAJOR_OTHER,
};
use windows::Win32::System::Threading::{GetCurrentProcess, GetCurrentProcessId, GetSystemTimes, OpenProcessToken};
use windows::Win32::UI::Shell::{
    FOLDERID_Desktop, FOLDERID_Documents, FOLDERID_Downloads, FOLDERID_LocalAppData, FOLDERID_Music, FOLDERID_Pictures,
    FOLDERID_Profile, FOLDERID_RoamingAppData, FOLDERID_Videos, SHFileOperationW, SHGetKnownFolderPath, FOF_ALLOWUNDO,
    FOF_NOCONFIRMATION, FOF_NOERRORUI, FOF_SILENT, FO_DELETE, KF_FLAG_DEFAULT, SHFILEOPSTRUCTW,
};
use windows::Win32::UI::WindowsAndMessaging::{
    SystemParametersInfoW, SPIF_SENDCHANGE, SPIF_UPDATEINIFILE, SPI_GETDESKWALLPAPER, SPI_SETDESKWALLPAPER,
    SYSTEM_PARAMETERS_INFO_UPDATE_FLAGS,
};

use super::sys::{os, token_info, CoTaskString, OwnedHandle};
use crate::desktop::windows::text::{from_wide_until_nul, wide_multi, wide_nul};
use crate::desktop::windows::winsys::{self, Hive};
use crate::desktop::{DesktopError, DesktopResult};

/// The session this process runs in.
pub(super) fn session_id() -> Option<u32> {
    let mut session = 0u32;
    // SAFETY: a valid out-pointer for our own process id.
    unsafe { ProcessIdToSessionId(GetCurrentProcessId(), &mut session) }.ok().map(|()| session)
}

/// The process token's integrity level and elevation type, in words.
pub(super) fn integrity_level() -> DesktopResult<String> {
    let mut token = windows::Win32::Foundation::HANDLE::default();
    // SAFETY: a valid out-pointer; the token goes to a guard.
    unsafe { OpenProcessToken(GetCurrentProcess(), TOKEN_QUERY, &mut token) }
        .map_err(|err| os("OpenProcessToken", &err))?;
    let token = OwnedHandle::new(token)
        .ok_or_else(|| DesktopError::Os { op: "OpenProcessToken", message: "no token".into() })?;
    // TOKEN_MANDATORY_LABEL plus its SID: 64 bytes hold any integrity SID, aligned for the struct.
    let mut label = [0u64; 8];
    let mut needed = 0u32;
    // SAFETY: the buffer is writable for its full length and aligned for TOKEN_MANDATORY_LABEL.
    unsafe {
        GetTokenInformation(
            token.raw(),
            TokenIntegrityLevel,
            Some(label.as_mut_ptr().cast()),
            std::mem::size_of_val(&label) as u32,
            &mut needed,
        )
    }
    .map_err(|err| os("GetTokenInformation(TokenIntegrityLevel)", &err))?;
    // SAFETY: the call succeeded, so the buffer starts with a TOKEN_MANDATORY_LABEL whose SID
    // points into the same buffer, which outlives these reads.
    let rid = unsafe {
        let label = &*label.as_ptr().cast::<TOKEN_MANDATORY_LABEL>();
        let sid = label.Label.Sid;
        let count = *GetSidSubAuthorityCount(sid);
        if count == 0 {
            return Err(DesktopError::Os {
                op: "GetSidSubAuthorityCount",
                message: "the integrity SID is empty".into(),
            });
        }
        *GetSidSubAuthority(sid, u32::from(count) - 1)
    };
    // SAFETY: TokenElevationType is written as a TOKEN_ELEVATION_TYPE; the token is live.
    let kind = unsafe { token_info::<TOKEN_ELEVATION_TYPE>(token.raw(), TokenElevationType) }.ok().map(|e| e.0);
    Ok(crate::desktop::windows::session::describe_integrity(rid, kind))
}

/// The guest path of a known folder.
pub(super) fn known_folder(folder: KnownFolder) -> DesktopResult<String> {
    let id = match folder {
        KnownFolder::Home => FOLDERID_Profile,
        KnownFolder::Desktop => FOLDERID_Desktop,
        KnownFolder::Documents => FOLDERID_Documents,
        KnownFolder::Downloads => FOLDERID_Downloads,
        KnownFolder::Pictures => FOLDERID_Pictures,
        KnownFolder::Music => FOLDERID_Music,
        KnownFolder::Videos => FOLDERID_Videos,
        KnownFolder::AppData => FOLDERID_RoamingAppData,
        KnownFolder::LocalAppData => FOLDERID_LocalAppData,
        KnownFolder::Temp => {
            // No known folder for it: GetTempPathW, as Python's tempfile does.
            let temp = std::env::temp_dir().display().to_string();
            return Ok(winsys::unverbatim(temp.trim_end_matches('\\')));
        }
        KnownFolder::Unknown => return Err(DesktopError::InvalidInput("unknown folder".into())),
    };
    // SAFETY: `id` is a valid GUID; the returned string goes to a guard that frees it.
    let path = CoTaskString(
        unsafe { SHGetKnownFolderPath(&id, KF_FLAG_DEFAULT, None) }.map_err(|err| os("SHGetKnownFolderPath", &err))?,
    );
    Ok(path.to_string_lossy())
}

/// Moves a file or folder to the Recycle Bin.
pub(super) fn recycle(path: &str) -> DesktopResult<()> {
    if std::fs::symlink_metadata(path).is_err() {
        return Err(DesktopError::NotFound(format!("{path}: not found")));
    }
    let from = wide_multi(&[path.to_owned()]).map_err(DesktopError::InvalidInput)?;
    let mut op = SHFILEOPSTRUCTW {
        wFunc: FO_DELETE,
        pFrom: PCWSTR(from.as_ptr()),
        fFlags: (FOF_ALLOWUNDO | FOF_NOCONFIRMATION | FOF_SILENT | FOF_NOERRORUI).0 as u16,
        ..Default::default()
    };
    // SAFETY: pFrom is a double-NUL-terminated list that outlives the call; no UI is shown.
    let code = unsafe { SHFileOperationW(&mut op) };
    if code != 0 || op.fAnyOperationsAborted.as_bool() {
        return Err(DesktopError::Os {
            op: "recycle",
            message: format!("{path}: SHFileOperationW failed with code {code:#x}"),
        });
    }
    // The shell reports success for some paths it did not move (a drive root):
    // success means the path is gone.
    if std::fs::symlink_metadata(path).is_ok() {
        return Err(DesktopError::Os { op: "recycle", message: format!("{path}: the shell moved nothing") });
    }
    Ok(())
}

fn hive_handle(hive: Hive) -> HKEY {
    match hive {
        Hive::CurrentUser => HKEY_CURRENT_USER,
        Hive::LocalMachine => HKEY_LOCAL_MACHINE,
        Hive::ClassesRoot => HKEY_CLASSES_ROOT,
        Hive::Users => HKEY_USERS,
        Hive::CurrentConfig => HKEY_CURRENT_CONFIG,
    }
}

fn reg_error(op: &'static str, what: &str, code: WIN32_ERROR) -> DesktopError {
    if code == ERROR_FILE_NOT_FOUND || code == ERROR_PATH_NOT_FOUND {
        return DesktopError::NotFound(format!("{what}: not found"));
    }
    if code == windows::Win32::Foundation::ERROR_ACCESS_DENIED {
        return DesktopError::PermissionDenied(format!("{what}: access denied"));
    }
    os(op, &windows::core::Error::from(code.to_hresult()))
}

fn value_label(key: &str, value: Option<&str>) -> String {
    match value {
        Some(v) => format!(r"{key}\{v}"),
        None => format!(r"{key} (default value)"),
    }
}

/// Reads a registry value (`None` is the default value); `REG_EXPAND_SZ` stays unexpanded.
pub(super) fn registry_read(key: &str, value: Option<&str>) -> DesktopResult<RegistryValue> {
    let (hive, subkey) = winsys::split_key(key)?;
    let subkey_w = wide_nul(&subkey);
    let value_w = value.map(wide_nul);
    let value_ptr = value_w.as_ref().map_or(PCWSTR::null(), |v| PCWSTR(v.as_ptr()));
    let label = value_label(key, value);
    let mut buf: Vec<u8> = vec![0; 512];
    // The value may grow between the calls; a few rounds settle it.
    for _ in 0..4 {
        let mut kind = REG_VALUE_TYPE(0);
        let mut size = buf.len() as u32;
        // SAFETY: the strings are NUL-terminated; buf holds `size` bytes; the out-pointers are valid.
        let code = unsafe {
            RegGetValueW(
                hive_handle(hive),
                PCWSTR(subkey_w.as_ptr()),
                value_ptr,
                RRF_RT_ANY | RRF_NOEXPAND,
                Some(&mut kind),
                Some(buf.as_mut_ptr().cast()),
                Some(&mut size),
            )
        };
        if code == ERROR_MORE_DATA {
            buf.resize(size as usize + 2, 0);
            continue;
        }
        if code != ERROR_SUCCESS {
            return Err(reg_error("registry read", &label, code));
        }
        return Ok(winsys::decode_value(kind.0, &buf[..(size as usize).min(buf.len())]));
    }
    Err(DesktopError::Os { op: "registry read", message: format!("{label}: the value kept changing size") })
}

/// Writes a registry value, creating the key.
pub(super) fn registry_write(key: &str, value: Option<&str>, data: &RegistryValue) -> DesktopResult<()> {
    let (hive, subkey) = winsys::split_key(key)?;
    let (kind, bytes) = winsys::encode_value(data)?;
    let subkey_w = wide_nul(&subkey);
    let value_w = value.map(wide_nul);
    let value_ptr = value_w.as_ref().map_or(PCWSTR::null(), |v| PCWSTR(v.as_ptr()));
    let len = u32::try_from(bytes.len()).map_err(|_| DesktopError::InvalidInput("registry value too large".into()))?;
    // SAFETY: the strings are NUL-terminated and `bytes` holds `len` bytes.
    let code = unsafe {
        RegSetKeyValueW(hive_handle(hive), PCWSTR(subkey_w.as_ptr()), value_ptr, kind, Some(bytes.as_ptr().cast()), len)
    };
    if code != ERROR_SUCCESS {
        return Err(reg_error("registry write", &value_label(key, value), code));
    }
    Ok(())
}

/// The current wallpaper's path, `None` when there is none.
pub(super) fn wallpaper() -> DesktopResult<Option<String>> {
    let mut buf = vec![0u16; 1024];
    // SAFETY: buf holds the number of UTF-16 units passed as uiParam.
    unsafe {
        SystemParametersInfoW(
            SPI_GETDESKWALLPAPER,
            buf.len() as u32,
            Some(buf.as_mut_ptr().cast()),
            SYSTEM_PARAMETERS_INFO_UPDATE_FLAGS(0),
        )
    }
    .map_err(|err| os("SPI_GETDESKWALLPAPER", &err))?;
    let path = from_wide_until_nul(&buf);
    Ok((!path.is_empty()).then_some(path))
}

/// Sets the wallpaper and saves it in the user's profile.
pub(super) fn set_wallpaper(path: &str) -> DesktopResult<()> {
    if !Path::new(path).is_file() {
        return Err(DesktopError::NotFound(format!("{path}: not found")));
    }
    let mut wide = wide_nul(path);
    // SAFETY: pvParam is a NUL-terminated path that outlives the call.
    unsafe {
        SystemParametersInfoW(
            SPI_SETDESKWALLPAPER,
            0,
            Some(wide.as_mut_ptr().cast()),
            SPIF_UPDATEINIFILE | SPIF_SENDCHANGE,
        )
    }
    .map_err(|err| os("SPI_SETDESKWALLPAPER", &err))
}

/// A security descriptor from `GetNamedSecurityInfoW`, freed with `LocalFree`.
struct SecurityDescriptor(PSECURITY_DESCRIPTOR);

impl Drop for SecurityDescriptor {
    fn drop(&mut self) {
        // SAFETY: the descriptor was allocated by GetNamedSecurityInfoW and is freed once.
        unsafe { LocalFree(Some(HLOCAL(self.0 .0))) };
    }
}

/// The SID bytes of account `user`.
fn lookup_sid(user: &str) -> DesktopResult<Vec<u8>> {
    let name = wide_nul(user);
    let (mut sid_len, mut dom_len) = (0u32, 0u32);
    let mut use_ = SID_NAME_USE(0);
    // SAFETY: the first call only measures the buffers (null buffers, valid lengths).
    let first = unsafe {
        LookupAccountNameW(PCWSTR::null(), PCWSTR(name.as_ptr()), None, &mut sid_len, None, &mut dom_len, &mut use_)
    };
    if let Err(err) = first {
        if super::sys::is_win32(&err, ERROR_NONE_MAPPED) || sid_len == 0 {
            return Err(DesktopError::NotFound(format!("user {user} not found")));
        }
    }
    let mut sid = vec![0u8; sid_len as usize];
    let mut domain = vec![0u16; dom_len.max(1) as usize];
    // SAFETY: both buffers have the sizes the first call asked for.
    unsafe {
        LookupAccountNameW(
            PCWSTR::null(),
            PCWSTR(name.as_ptr()),
            Some(PSID(sid.as_mut_ptr().cast())),
            &mut sid_len,
            Some(PWSTR(domain.as_mut_ptr())),
            &mut dom_len,
            &mut use_,
        )
    }
    .map_err(|err| {
        if super::sys::is_win32(&err, ERROR_NONE_MAPPED) {
            DesktopError::NotFound(format!("user {user} not found"))
        } else {
            os("LookupAccountNameW", &err)
        }
    })?;
    Ok(sid)
}

/// The access mask of the first allow or deny ACE in `path`'s DACL whose SID is `user`'s.
pub(super) fn directory_access_mask(path: &str, user: &str) -> DesktopResult<Option<u32>> {
    if std::fs::metadata(path).is_err() {
        return Err(DesktopError::NotFound(format!("{path}: not found")));
    }
    let sid = lookup_sid(user)?;
    let name = wide_nul(path);
    let mut dacl: *mut ACL = std::ptr::null_mut();
    let mut sd = PSECURITY_DESCRIPTOR::default();
    // SAFETY: valid out-pointers; the descriptor is freed by the guard; `dacl` points into it.
    let code = unsafe {
        GetNamedSecurityInfoW(
            PCWSTR(name.as_ptr()),
            SE_FILE_OBJECT,
            DACL_SECURITY_INFORMATION,
            None,
            None,
            Some(&mut dacl),
            None,
            &mut sd,
        )
    };
    if code != ERROR_SUCCESS {
        return Err(reg_error("GetNamedSecurityInfoW", path, code));
    }
    let _sd = SecurityDescriptor(sd);
    if dacl.is_null() {
        // A NULL DACL grants everyone everything; there is no ACE naming the user.
        return Ok(None);
    }
    let mut info = ACL_SIZE_INFORMATION::default();
    // SAFETY: dacl points into the live descriptor; info is the structure the class names.
    unsafe {
        GetAclInformation(
            dacl,
            (&mut info as *mut ACL_SIZE_INFORMATION).cast(),
            std::mem::size_of::<ACL_SIZE_INFORMATION>() as u32,
            AclSizeInformation,
        )
    }
    .map_err(|err| os("GetAclInformation", &err))?;
    for index in 0..info.AceCount {
        let mut ace: *mut core::ffi::c_void = std::ptr::null_mut();
        // SAFETY: index < AceCount; `ace` receives a pointer into the DACL.
        if unsafe { GetAce(dacl, index, &mut ace) }.is_err() || ace.is_null() {
            continue;
        }
        // SAFETY: every ACE starts with an ACE_HEADER.
        let header = unsafe { &*(ace as *const ACE_HEADER) };
        // Types 0 and 1 (access allowed / denied) share ACCESS_ALLOWED_ACE's layout.
        if header.AceType > 1 {
            continue;
        }
        // SAFETY: for these types the ACE is an ACCESS_ALLOWED_ACE; its SID starts at SidStart.
        let allowed = unsafe { &*(ace as *const ACCESS_ALLOWED_ACE) };
        let ace_sid = PSID(&allowed.SidStart as *const u32 as *mut _);
        // SAFETY: both SIDs are valid for the duration of the call.
        if unsafe { EqualSid(ace_sid, PSID(sid.as_ptr() as *mut _)) }.is_ok() {
            return Ok(Some(allowed.Mask));
        }
    }
    Ok(None)
}

/// Shuts the machine down now (SeShutdownPrivilege is enabled for the call).
pub(super) fn shutdown() -> DesktopResult<()> {
    let mut token = windows::Win32::Foundation::HANDLE::default();
    // SAFETY: a valid out-pointer; the token goes to a guard.
    unsafe { OpenProcessToken(GetCurrentProcess(), TOKEN_ADJUST_PRIVILEGES | TOKEN_QUERY, &mut token) }
        .map_err(|err| os("OpenProcessToken", &err))?;
    let token = OwnedHandle::new(token)
        .ok_or_else(|| DesktopError::Os { op: "OpenProcessToken", message: "no token".into() })?;
    let mut luid = LUID::default();
    // SAFETY: SE_SHUTDOWN_NAME is a static string; luid is a valid out-pointer.
    unsafe { LookupPrivilegeValueW(PCWSTR::null(), SE_SHUTDOWN_NAME, &mut luid) }
        .map_err(|err| os("LookupPrivilegeValueW", &err))?;
    let privileges = TOKEN_PRIVILEGES {
        PrivilegeCount: 1,
        Privileges: [LUID_AND_ATTRIBUTES { Luid: luid, Attributes: SE_PRIVILEGE_ENABLED }],
    };
    // SAFETY: the token is live and `privileges` is a complete TOKEN_PRIVILEGES.
    unsafe { AdjustTokenPrivileges(token.raw(), false, Some(&privileges), 0, None, None) }
        .map_err(|err| os("AdjustTokenPrivileges", &err))?;
    // SAFETY: shuts down the local machine (null machine name) with no message and no delay.
    unsafe {
        InitiateSystemShutdownExW(
            PCWSTR::null(),
            PCWSTR::null(),
            0,
            true,
            false,
            SHTDN_REASON_MAJOR_OTHER | SHTDN_REASON_FLAG_PLANNED,
        )
    }
    .map_err(|err| os("InitiateSystemShutdownExW", &err))
}

/// Sets the wall clock to `unix_ms` (UTC) with `SetSystemTime`.
///
/// Microsoft's documentation of `SetSystemTime` (sysinfoapi.h): the caller needs
/// the `SE_SYSTEMTIME_NAME` privilege, which the function itself enables for the
/// call; an elevated administrator's token (the guest's) holds it.
pub(super) fn set_system_time(unix_ms: i64) -> DesktopResult<()> {
    let t = arena_shared::clock::civil(unix_ms).map_err(DesktopError::InvalidInput)?;
    let time = windows::Win32::Foundation::SYSTEMTIME {
        wYear: t.year,
        wMonth: t.month,
        wDayOfWeek: t.day_of_week,
        wDay: t.day,
        wHour: t.hour,
        wMinute: t.minute,
        wSecond: t.second,
        wMilliseconds: t.millisecond,
    };
    // SAFETY: a valid pointer to a complete SYSTEMTIME that outlives the call.
    unsafe { windows::Win32::System::SystemInformation::SetSystemTime(&time) }.map_err(|err| os("SetSystemTime", &err))
}

/// All processors' idle and busy time since boot (`GetSystemTimes`: 100 ns
/// ticks; its kernel time includes the idle time), or `None` when it fails.
pub(super) fn cpu_times() -> Option<crate::desktop::settle::CpuTimes> {
    let (mut idle, mut kernel, mut user) = (FILETIME::default(), FILETIME::default(), FILETIME::default());
    // SAFETY: three valid out-pointers to FILETIMEs on this stack frame, alive for the call.
    unsafe { GetSystemTimes(Some(&mut idle), Some(&mut kernel), Some(&mut user)) }.ok()?;
    let ticks = |t: FILETIME| (u64::from(t.dwHighDateTime) << 32) | u64::from(t.dwLowDateTime);
    Some(crate::desktop::settle::CpuTimes { idle: ticks(idle), total: ticks(kernel).saturating_add(ticks(user)) })
}
