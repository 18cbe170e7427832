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
//! - [`longname`]: 8.3 short names expanded (`GetLongPathNameW` on Windows, nothing elsewhere),
//!   for the protection rules;
//! - [`std_child`]: how a program is started and killed with `std::process` (the
//!   stub backend's runner, which also runs inside the Windows exe);
//! - [`target`]: what the build's platform decides for neutral code elsewhere (the
//!   default backend, the shell, the service subcommands), so no `cfg!(windows)` is
//!   written outside `windows/` folders.
//!
//! FFI glue, compiled only for Windows (`cfg(windows)`): `backend` (the
//! [`Desktop`](crate::desktop::Desktop) implementation), `sys` (handle guards,
//! error conversion), `window`, `input`, `capture`, `clipboard`, `process`,
//! `system` (files, registry, wallpaper, ACLs, shutdown), and the two
//! accessibility sources `win32_tree` and `uia`, which feed the shared walker
//! [`arena_a11y_walk`].
//!
//! The service mode, which starts this backend in the user's session, is not part
//! of the backend: it lives in [`crate::service`].

pub mod longname;
pub mod pointer;
pub mod session;
pub mod shell;
pub mod std_child;
pub mod target;
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

use crate::config::{ServerConfig, UiaView};

/// The server options the Windows backend reads, taken from the configuration once
/// at start-up (neutral, so the mapping is tested on every platform).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WindowsOptions {
    /// The UI Automation view the `uia` tree walks (condition of the cache requests and
    /// the walker of the element-by-element fallback).
    pub uia_view: UiaView,
    /// Capture with `CAPTUREBLT` (Pillow's `include_layered_windows=True`); off by
    /// default, as Pillow's plain `ImageGrab.grab()`.
    pub capture_layered: bool,
    /// How long each phase of a drag lasts (`--drag-step-ms`).
    pub drag_step_ms: u64,
}

impl WindowsOptions {
    /// The backend's options from the server configuration.
    pub fn from_config(config: &ServerConfig) -> WindowsOptions {
        WindowsOptions {
            uia_view: config.uia_view,
            capture_layered: config.capture_layered,
            drag_step_ms: config.drag_step_ms,
        }
    }
}

impl Default for WindowsOptions {
    fn default() -> WindowsOptions {
        WindowsOptions::from_config(&ServerConfig::for_stub())
    }
}

/// Starts the Windows backend with the options `config` gives it.
///
/// # Errors
///
/// The backend cannot start (no interactive session, COM refusing), or this is not a
/// Windows build, which says to use the stub.
pub fn start(config: &ServerConfig) -> anyhow::Result<std::sync::Arc<dyn crate::desktop::Desktop>> {
    let options = WindowsOptions::from_config(config);
    #[cfg(windows)]
    {
        use anyhow::Context as _;
        Ok(std::sync::Arc::new(WindowsDesktop::new(options).context("starting the windows desktop")?))
    }
    #[cfg(not(windows))]
    {
        let _ = options;
        anyhow::bail!("the windows backend exists only in Windows builds; use --backend stub")
    }
}

/// `arena-guest uia-worker --view raw|control`, the UI Automation worker process
/// the Windows backend starts ([`crate::desktop::uia_process`]): `None` when the
/// command line is not that; else how it ended.
pub fn uia_worker_from_args() -> Option<Result<(), String>> {
    let mut args = std::env::args().skip(1);
    if args.next().as_deref() != Some(crate::desktop::uia_process::SUBCOMMAND) {
        return None;
    }
    let view = match args.skip_while(|a| a != "--view").nth(1).as_deref() {
        Some("control") => crate::config::UiaView::Control,
        _ => crate::config::UiaView::Raw,
    };
    #[cfg(windows)]
    return Some(uia::run_worker_process(view).map_err(|err| format!("the UI Automation worker: {err}")));
    #[cfg(not(windows))]
    {
        let _ = view;
        Some(Err("the UI Automation worker runs only in the Windows exe".into()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser as _;

    fn options(args: &[&str]) -> WindowsOptions {
        let config = ServerConfig::try_parse_from(std::iter::once("arena-guest").chain(args.iter().copied())).unwrap();
        WindowsOptions::from_config(&config)
    }

    #[test]
    fn the_raw_view_and_a_plain_blit_are_the_defaults() {
        let defaults = options(&[]);
        assert_eq!(defaults, WindowsOptions { uia_view: UiaView::Raw, capture_layered: false, drag_step_ms: 200 });
        assert_eq!(defaults, WindowsOptions::default());
    }

    #[test]
    fn the_control_view_and_layered_capture_are_options() {
        let chosen = options(&["--uia-view", "control", "--capture-layered", "--drag-step-ms", "60"]);
        assert_eq!(chosen, WindowsOptions { uia_view: UiaView::Control, capture_layered: true, drag_step_ms: 60 });
        assert!(ServerConfig::try_parse_from(["arena-guest", "--drag-step-ms", "60000"]).is_err());
        assert_eq!(options(&["--uia-view", "raw"]).uia_view, UiaView::Raw);
        let refused = ServerConfig::try_parse_from(["arena-guest", "--uia-view", "content"]);
        assert!(refused.is_err(), "only raw and control are views the walker knows");
    }
}
