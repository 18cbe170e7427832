//! 8.3 short names (`C:\PROGRA~1`) to the long names they stand for, so that the
//! protection rules ([`crate::protect`]) compare what a path names, not how it is spelt.
//!
//! FFI glue over `GetLongPathNameW`
//! (<https://learn.microsoft.com/windows/win32/api/fileapi/nf-fileapi-getlongpathnamew>),
//! which expands every short component of a path that exists. Elsewhere there are no
//! short names, and the answer is always `None`.

/// The long form of `path` when it exists and the system expands it, else `None`.
#[cfg(windows)]
pub fn long_path_name(path: &str) -> Option<String> {
    use windows::core::PCWSTR;
    use windows::Win32::Storage::FileSystem::GetLongPathNameW;

    let wide = super::text::wide_nul(path);
    let mut buf = vec![0u16; 1024];
    for _ in 0..2 {
        // SAFETY: `wide` is NUL-terminated and outlives the call; the output slice is
        // valid for its length, which the call is told through the slice.
        let len = unsafe { GetLongPathNameW(PCWSTR(wide.as_ptr()), Some(&mut buf)) } as usize;
        if len == 0 {
            return None;
        }
        if len < buf.len() {
            return Some(super::text::from_wide_until_nul(&buf[..len]));
        }
        // Too small: `len` is the size needed, its NUL included.
        buf = vec![0u16; len + 1];
    }
    None
}

/// The long form of `path`: there are no short names off Windows.
#[cfg(not(windows))]
pub fn long_path_name(_path: &str) -> Option<String> {
    None
}
