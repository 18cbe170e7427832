//! The Windows backend: the [`Desktop`](crate::desktop::Desktop) trait over Win32,
//! COM and UI Automation, with its platform-neutral halves beside the FFI glue.
//!
//! # Layout
//!
//! Neutral halves, compiled and tested natively on every platform (they decide
//! what to send and how to shape what comes back):
//! - [`vk`]: key names to virtual-key and scan-code strokes, shift planning;
//! - [`pointer`]: absolute mouse coordinates on the virtual screen;
//! - [`winsys`]: guest paths, registry hives and data;
//! - [`text`]: UTF-16, ANSI and newline handling of program output;
//! - [`session`]: the session-0 refusal;
//! - [`std_child`]: how a program is started and killed with `std::process` (the
//!   stub backend's runner, which also runs inside the Windows exe).
//!
//! FFI glue, compiled only for Windows (`cfg(windows)`): `backend` (the
//! [`Desktop`](crate::desktop::Desktop) implementation), `sys` (handle guards,
//! error conversion), `window`, `input`, `capture`, `clipboard`, `process`,
//! `system` (files, registry, wallpaper, ACLs, shutdown), and the two
//! accessibility sources `win32_tree` and `uia`, which feed the shared walker
//! [`crate::desktop::a11y_walk`].
//!
//! The service mode, which starts this backend in the user's session, is not part
//! of the backend: it lives in [`crate::service`].

pub mod pointer;
pub mod session;
pub mod shell;
pub mod std_child;
pub mod text;
pub mod vk;
pub mod winsys;

#[cfg(windows)]
mod backend;
#[cfg(windows)]
mod capture;
#[cfg(windows)]
mod clipboard;
#[cfg(windows)]
mod input;
#[cfg(windows)]
mod process;
#[cfg(windows)]
pub(crate) mod sys;
#[cfg(windows)]
mod system;
#[cfg(windows)]
mod uia;
#[cfg(windows)]
mod win32_tree;
#[cfg(windows)]
mod window;

#[cfg(windows)]
pub use backend::WindowsDesktop;

/// Starts the Windows backend.
///
/// # Errors
///
/// The backend cannot start (no interactive session, COM refusing), or this is not a
/// Windows build, which says to use the stub.
pub fn start() -> anyhow::Result<std::sync::Arc<dyn crate::desktop::Desktop>> {
    #[cfg(windows)]
    {
        use anyhow::Context as _;
        Ok(std::sync::Arc::new(WindowsDesktop::new().context("starting the windows desktop")?))
    }
    #[cfg(not(windows))]
    {
        anyhow::bail!("the windows backend exists only in Windows builds; use --backend stub")
    }
}
