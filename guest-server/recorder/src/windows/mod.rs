//! The Windows half of the recorder: the window and its message loop (`window`, FFI
//! glue compiled for Windows only), and [`run`], which elsewhere says the recorder is
//! Windows-only.

#[cfg(windows)]
mod window;

use crate::Options;

/// Whether this build is for Windows.
pub const IS_WINDOWS: bool = cfg!(windows);

/// Opens the recorder's window and records into `options.log` until the window is
/// closed.
///
/// # Errors
///
/// On other platforms, that the recorder is Windows-only; on Windows, the log not
/// opening or a write failing, and the window not being created.
pub fn run(options: &Options) -> Result<(), String> {
    #[cfg(windows)]
    {
        window::run(options)
    }
    #[cfg(not(windows))]
    {
        let _ = options;
        Err("arena-input-recorder is Windows-only: it records the messages a Win32 window receives".into())
    }
}
