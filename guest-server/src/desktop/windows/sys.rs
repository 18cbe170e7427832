//! Guards for raw Win32 handles, and the conversion of Win32 errors into
//! [`DesktopError`] at the backend's boundary.
//!
//! Every handle the backend opens is wrapped in one of these guards right after
//! the call that returns it, so early returns and panics release it. Nothing here
//! decides behaviour; it only owns resources.

use windows::Win32::Foundation::{CloseHandle, GetLastError, HANDLE, HWND, WIN32_ERROR};
use windows::Win32::Graphics::Gdi::{DeleteDC, DeleteObject, ReleaseDC, SelectObject, HBITMAP, HDC, HGDIOBJ};
use windows::Win32::System::Com::{CoInitializeEx, CoUninitialize, COINIT};

use crate::desktop::DesktopError;

/// Converts a windows-rs error into [`DesktopError::Os`], keeping the OS's words and code.
pub(crate) fn os(op: &'static str, err: &windows::core::Error) -> DesktopError {
    DesktopError::Os { op, message: describe(err) }
}

/// The OS's words for `err` and its code; Wine often has no words, only the code.
pub(crate) fn describe(err: &windows::core::Error) -> String {
    let message = err.message();
    let message = message.trim_end();
    if message.is_empty() {
        format!("error 0x{:08X}", err.code().0)
    } else {
        format!("{message} (0x{:08X})", err.code().0)
    }
}

/// [`os`] for the calling thread's last error, for APIs that return a bare BOOL or handle.
pub(crate) fn last_os(op: &'static str) -> DesktopError {
    // SAFETY: GetLastError only reads the calling thread's error slot.
    let code = unsafe { GetLastError() };
    os(op, &windows::core::Error::from(code.to_hresult()))
}

/// Whether a windows-rs error carries `code` (a Win32 error such as `ERROR_FILE_NOT_FOUND`).
pub(crate) fn is_win32(err: &windows::core::Error, code: WIN32_ERROR) -> bool {
    err.code() == code.to_hresult()
}

/// One fixed-size piece of a token's information (`TokenElevationType` as a
/// `TOKEN_ELEVATION_TYPE`, `TokenLinkedToken` as a `TOKEN_LINKED_TOKEN`).
///
/// # Safety
///
/// `T` must be the structure Windows writes for `class`, and `token` a live token
/// handle opened with `TOKEN_QUERY`.
pub(crate) unsafe fn token_info<T: Default>(
    token: HANDLE,
    class: windows::Win32::Security::TOKEN_INFORMATION_CLASS,
) -> windows::core::Result<T> {
    let mut value = T::default();
    let mut needed = 0u32;
    // SAFETY: `value` is writable for the size passed, and the caller vouches that `T`
    // is what Windows writes for `class`.
    unsafe {
        windows::Win32::Security::GetTokenInformation(
            token,
            class,
            Some((&raw mut value).cast()),
            std::mem::size_of::<T>() as u32,
            &mut needed,
        )
    }?;
    Ok(value)
}

/// An owned kernel handle (process, thread, job, pipe end, token), closed on drop.
#[derive(Debug)]
pub(crate) struct OwnedHandle(pub(crate) HANDLE);

impl OwnedHandle {
    /// Takes ownership of `handle`; `None` for a null or invalid one.
    pub(crate) fn new(handle: HANDLE) -> Option<OwnedHandle> {
        (!handle.is_invalid() && !handle.0.is_null()).then_some(OwnedHandle(handle))
    }

    pub(crate) fn raw(&self) -> HANDLE {
        self.0
    }

    /// Gives the handle up without closing it.
    pub(crate) fn into_raw(self) -> HANDLE {
        let handle = self.0;
        std::mem::forget(self);
        handle
    }
}

impl Drop for OwnedHandle {
    fn drop(&mut self) {
        // SAFETY: the guard owns this handle exclusively and it is closed exactly once.
        if let Err(err) = unsafe { CloseHandle(self.0) } {
            tracing::debug!(%err, "CloseHandle failed");
        }
    }
}

/// A device context from `GetDC`, released with `ReleaseDC` on drop.
#[derive(Debug)]
pub(crate) struct WindowDc {
    hwnd: Option<HWND>,
    pub(crate) hdc: HDC,
}

impl WindowDc {
    /// The DC of `hwnd`, or of the whole screen for `None`.
    pub(crate) fn get(hwnd: Option<HWND>) -> Option<WindowDc> {
        // SAFETY: GetDC has no preconditions; a null result is checked below.
        let hdc = unsafe { windows::Win32::Graphics::Gdi::GetDC(hwnd) };
        (!hdc.is_invalid()).then_some(WindowDc { hwnd, hdc })
    }
}

impl Drop for WindowDc {
    fn drop(&mut self) {
        // SAFETY: the DC came from GetDC for this same window and is released once.
        unsafe { ReleaseDC(self.hwnd, self.hdc) };
    }
}

/// A memory DC from `CreateCompatibleDC`, deleted on drop.
#[derive(Debug)]
pub(crate) struct MemoryDc(pub(crate) HDC);

impl Drop for MemoryDc {
    fn drop(&mut self) {
        // SAFETY: this DC was created by CreateCompatibleDC and is deleted once; any
        // object selected into it has been selected out by its SelectGuard already.
        unsafe {
            let _ = DeleteDC(self.0);
        }
    }
}

/// A GDI bitmap, deleted on drop.
#[derive(Debug)]
pub(crate) struct Bitmap(pub(crate) HBITMAP);

impl Drop for Bitmap {
    fn drop(&mut self) {
        // SAFETY: the bitmap is owned by this guard and is not selected into any DC any
        // more (SelectGuard restores the previous object first, being dropped earlier).
        unsafe {
            let _ = DeleteObject(HGDIOBJ(self.0 .0));
        }
    }
}

/// An object selected into a DC; the previous object is selected back on drop.
#[derive(Debug)]
pub(crate) struct SelectGuard {
    hdc: HDC,
    previous: HGDIOBJ,
}

impl SelectGuard {
    /// Selects `object` into `hdc`.
    ///
    /// # Safety
    ///
    /// `hdc` and `object` must be live and outlive the guard.
    pub(crate) unsafe fn select(hdc: HDC, object: HGDIOBJ) -> SelectGuard {
        // SAFETY: the caller guarantees both handles are live.
        let previous = unsafe { SelectObject(hdc, object) };
        SelectGuard { hdc, previous }
    }
}

impl Drop for SelectGuard {
    fn drop(&mut self) {
        // SAFETY: restores the object that was selected before, on the same live DC.
        unsafe {
            SelectObject(self.hdc, self.previous);
        }
    }
}

/// COM initialised on the current thread; uninitialised on drop. Not `Send`: the
/// uninitialisation must happen on the thread that initialised.
#[derive(Debug)]
pub(crate) struct ComApartment(std::marker::PhantomData<*const ()>);

impl ComApartment {
    /// Initialises COM on this thread with `model` (apartment or multithreaded).
    ///
    /// # Errors
    ///
    /// The OS refusing, e.g. when the thread already uses the other model.
    pub(crate) fn init(model: COINIT) -> Result<ComApartment, DesktopError> {
        // SAFETY: called at most once per guard; paired with CoUninitialize in Drop.
        let hr = unsafe { CoInitializeEx(None, model) };
        hr.ok().map_err(|err| os("CoInitializeEx", &err))?;
        Ok(ComApartment(std::marker::PhantomData))
    }
}

impl Drop for ComApartment {
    fn drop(&mut self) {
        // SAFETY: paired with the successful CoInitializeEx of this guard, on the same
        // thread (the guard is not Send, so it is dropped where it was made).
        unsafe { CoUninitialize() };
    }
}

/// Memory the shell allocated with `CoTaskMemAlloc` (known-folder paths), freed on drop.
#[derive(Debug)]
pub(crate) struct CoTaskString(pub(crate) windows::core::PWSTR);

impl CoTaskString {
    pub(crate) fn to_string_lossy(&self) -> String {
        if self.0.is_null() {
            return String::new();
        }
        // SAFETY: the shell returned a valid NUL-terminated string that lives until drop.
        unsafe { String::from_utf16_lossy(self.0.as_wide()) }
    }
}

impl Drop for CoTaskString {
    fn drop(&mut self) {
        // SAFETY: the pointer came from the shell's CoTaskMemAlloc and is freed once.
        unsafe { windows::Win32::System::Com::CoTaskMemFree(Some(self.0 .0 as *const _)) };
    }
}

/// `Send` wrapper for an HWND: a window handle is a plain number any thread may use.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Hwnd(pub(crate) isize);

impl Hwnd {
    pub(crate) fn from_id(id: u64) -> Hwnd {
        Hwnd(id as isize)
    }

    pub(crate) fn get(self) -> HWND {
        HWND(self.0 as *mut _)
    }

    pub(crate) fn id(hwnd: HWND) -> u64 {
        hwnd.0 as isize as u64
    }
}
