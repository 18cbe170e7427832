//! The Windows backend's [`Desktop`] implementation: every trait method as calls
//! into the FFI glue beside it (see the folder's `mod.rs` for the layout).
//!
//! # Platform-specific behavior
//!
//! The process makes itself per-monitor DPI aware when the backend starts, so every
//! coordinate is in physical pixels. Calls that need the user's desktop are refused
//! in session 0 (a service) with [`DesktopError::Unsupported`].

use std::path::{Path, PathBuf};
use std::time::Instant;

use arena_shared::action::Action;
use arena_shared::files::KnownFolder;
use arena_shared::geometry::{Point, Rect};
use arena_shared::health::Component;
use arena_shared::observation::{A11yBackend, A11yTree, ScreenInfo, TreeBudget, WindowInfo};
use arena_shared::registry::RegistryValue;
use windows::Win32::UI::HiDpi::{
    SetProcessDpiAwareness, SetProcessDpiAwarenessContext, DPI_AWARENESS_CONTEXT_PER_MONITOR_AWARE_V2,
    PROCESS_PER_MONITOR_DPI_AWARE,
};
use windows::Win32::UI::Input::KeyboardAndMouse::{
    SendInput, INPUT, INPUT_0, INPUT_MOUSE, MOUSEEVENTF_MOVE, MOUSEINPUT,
};
use windows::Win32::UI::WindowsAndMessaging::{SetProcessDPIAware, ShowCursor};

use super::session::{refuse_session_zero, Needs};
use super::{capture, clipboard, input, process, system, uia, win32_tree, window};
use crate::desktop::{
    ClipboardData, CommandSpec, Desktop, DesktopError, DesktopResult, ExecLimits, ExecOutput, Frame, WindowState,
};

/// The real Windows desktop of the session the server runs in.
#[derive(Debug)]
pub struct WindowsDesktop {
    session: Option<u32>,
    uia: uia::UiaWorker,
    options: super::WindowsOptions,
}

/// Makes the process per-monitor DPI aware (v2, else v1, else system aware), so
/// capture, input and window rectangles all use physical pixels.
fn make_dpi_aware() -> &'static str {
    // SAFETY: process-wide settings with no preconditions; each fails harmlessly if already set.
    unsafe {
        if SetProcessDpiAwarenessContext(DPI_AWARENESS_CONTEXT_PER_MONITOR_AWARE_V2).is_ok() {
            return "per-monitor v2";
        }
        if SetProcessDpiAwareness(PROCESS_PER_MONITOR_DPI_AWARE).is_ok() {
            return "per-monitor";
        }
        if SetProcessDPIAware().as_bool() {
            return "system";
        }
    }
    "unchanged (already set)"
}

/// Upstream's cursor fix: show the cursor and nudge it, so VMs that hide the cursor
/// until the mouse moves draw it in screenshots. The nudge goes one pixel right and
/// back, so the cursor ends where it was.
fn wake_cursor() {
    let nudge = |dx| INPUT {
        r#type: INPUT_MOUSE,
        Anonymous: INPUT_0 {
            mi: MOUSEINPUT { dx, dy: 0, mouseData: 0, dwFlags: MOUSEEVENTF_MOVE, time: 0, dwExtraInfo: 0 },
        },
    };
    // SAFETY: ShowCursor only changes this thread's display counter; SendInput gets two initialised records.
    let sent = unsafe {
        ShowCursor(true);
        SendInput(&[nudge(1), nudge(-1)], std::mem::size_of::<INPUT>() as i32)
    };
    if sent != 2 {
        tracing::warn!(sent, of = 2, "the cursor nudge was not accepted in full (a secure desktop or UIPI)");
    }
}

impl WindowsDesktop {
    /// Starts the backend with `options`: DPI awareness, the session check and the cursor fix.
    ///
    /// # Errors
    ///
    /// None today; the signature leaves room for checks that can fail.
    pub fn new(options: super::WindowsOptions) -> DesktopResult<WindowsDesktop> {
        let dpi = make_dpi_aware();
        let session = system::session_id();
        tracing::info!(
            dpi_awareness = dpi,
            session = ?session,
            uia_view = ?options.uia_view,
            capture_layered = options.capture_layered,
            "windows backend started"
        );
        if session == Some(super::session::SERVICE_SESSION) {
            tracing::warn!("running in session 0: screen, input, windows and clipboard calls will be refused");
        } else {
            wake_cursor();
        }
        Ok(WindowsDesktop { session, uia: uia::UiaWorker::new(options.uia_view), options })
    }

    /// The title of the window in front, when a person would see one over a lit
    /// screen: the foreground window passes the trees' root filter, is not minimised,
    /// and the screen is not black (a locked or disconnected desktop). `None` otherwise.
    fn window_in_front(&self) -> Option<String> {
        let hwnd = window::foreground();
        if hwnd.is_invalid() || !window::seen(hwnd) || window::is_minimized(hwnd) {
            return None;
        }
        let lit = capture::capture(false, self.options.capture_layered)
            .is_ok_and(|frame| !crate::imaging::is_black(&frame.image));
        lit.then(|| window::title(hwnd))
    }

    fn need_desktop(&self, op: &str) -> DesktopResult<()> {
        refuse_session_zero(self.session, op, Needs::InteractiveDesktop)
    }

    fn probe_inner(&self, component: Component) -> DesktopResult<String> {
        match component {
            Component::Capture => {
                self.need_desktop("capture")?;
                let started = Instant::now();
                let frame = capture::capture(false, self.options.capture_layered)?;
                let (w, h) = frame.image.dimensions();
                if crate::imaging::is_black(&frame.image) {
                    return Err(DesktopError::Os {
                        op: "probe capture",
                        message: format!(
                            "the {w}x{h} frame is entirely black (locked, secure or disconnected desktop?)"
                        ),
                    });
                }
                Ok(format!("captured a {w}x{h} frame in {} ms", started.elapsed().as_millis()))
            }
            Component::Input => {
                self.need_desktop("input")?;
                let p = input::cursor()?;
                Ok(format!("cursor at {},{}", p.x, p.y))
            }
            Component::Accessibility => {
                self.need_desktop("accessibility")?;
                let tree = arena_a11y_walk::walk(
                    &mut win32_tree::Win32Source::new(),
                    A11yBackend::Win32,
                    &TreeBudget { max_ms: 2_000, ..TreeBudget::WAA },
                    true,
                )?;
                Ok(format!(
                    "walked the foreground window's win32 tree: {} nodes in {} ms",
                    tree.node_count, tree.elapsed_ms
                ))
            }
            Component::Uia => {
                self.need_desktop("ui automation")?;
                let in_front = self.window_in_front();
                let budget = crate::desktop::uia_health::HEALTH_BUDGET;
                crate::desktop::uia_health::check(
                    in_front.as_deref(),
                    &mut || self.uia.tree(&budget, true),
                    &mut || {
                        self.uia.recreate();
                        Ok(())
                    },
                )
            }
            Component::Clipboard => {
                self.need_desktop("clipboard")?;
                Ok(match clipboard::get()? {
                    ClipboardData::Empty => "opened the clipboard: it is empty".to_owned(),
                    ClipboardData::Text(t) => format!("opened the clipboard: {} characters of text", t.chars().count()),
                    ClipboardData::Image(img) => {
                        format!("opened the clipboard: a {}x{} image", img.width(), img.height())
                    }
                })
            }
            Component::Files => {
                let dir = std::env::temp_dir();
                // A name of its own per call: concurrent probes must not share (and delete) one file.
                static PROBES: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
                let n = PROBES.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                let probe = dir.join(format!("arena-probe-{}-{n}.tmp", std::process::id()));
                let what = probe.display().to_string();
                std::fs::write(&probe, b"arena probe").map_err(|err| DesktopError::io("probe files", &what, err))?;
                let back = std::fs::read(&probe).map_err(|err| DesktopError::io("probe files", &what, err));
                let _ = std::fs::remove_file(&probe);
                if back? != b"arena probe" {
                    return Err(DesktopError::Os {
                        op: "probe files",
                        message: format!("{what} read back different bytes"),
                    });
                }
                Ok(format!("wrote, read back and deleted {what}"))
            }
            Component::Exec => {
                let limits = ExecLimits { timeout_ms: 10_000, max_output_bytes: 4096, cwd: None, stdin: None };
                let out = process::run(&CommandSpec::Argv(vec!["cmd".into(), "/c".into(), "exit 0".into()]), &limits)?;
                match out.exit_code {
                    Some(0) => Ok(format!("ran cmd /c exit 0 in {} ms", out.duration_ms)),
                    other => Err(DesktopError::Os {
                        op: "probe exec",
                        message: format!("cmd /c exit 0 ended with {other:?}"),
                    }),
                }
            }
            // The server reads the setup record itself (`native::health`); nothing of the desktop's.
            Component::Setup => Ok("the setup record is the server's to read".to_owned()),
            // The server keeps the shell's history itself (`native::health`, `settle`).
            Component::Shell => Ok("the shell's settle is the server's to judge".to_owned()),
            Component::Unknown => Err(DesktopError::InvalidInput("unknown component".into())),
        }
    }
}

impl Desktop for WindowsDesktop {
    fn shell_sample(&self) -> DesktopResult<crate::desktop::settle::ShellSample> {
        self.need_desktop("the shell")?;
        Ok(crate::desktop::settle::ShellSample {
            taskbar: window::taskbar_shown(),
            front: window::front(),
            cpu: system::cpu_times(),
        })
    }

    fn kind(&self) -> &'static str {
        "windows"
    }

    fn probe(&self, component: Component) -> DesktopResult<String> {
        self.probe_inner(component)
    }

    fn session_id(&self) -> Option<u32> {
        self.session
    }

    fn integrity_level(&self) -> DesktopResult<String> {
        system::integrity_level()
    }

    fn screen(&self) -> DesktopResult<ScreenInfo> {
        self.need_desktop("screen")?;
        capture::screen()
    }

    fn capture(&self, draw_cursor: bool) -> DesktopResult<Frame> {
        self.need_desktop("capture")?;
        capture::capture(draw_cursor, self.options.capture_layered)
    }

    fn cursor_position(&self) -> DesktopResult<Point> {
        self.need_desktop("cursor position")?;
        input::cursor()
    }

    fn perform(&self, action: &Action) -> DesktopResult<()> {
        self.need_desktop("input")?;
        input::perform(action, std::time::Duration::from_millis(self.options.drag_step_ms))
    }

    fn windows(&self) -> DesktopResult<Vec<WindowInfo>> {
        self.need_desktop("window list")?;
        Ok(window::list())
    }

    fn activate_window(&self, id: u64) -> DesktopResult<()> {
        self.need_desktop("activate window")?;
        window::activate(id)
    }

    fn set_window_state(&self, id: u64, state: WindowState) -> DesktopResult<()> {
        self.need_desktop("window state")?;
        window::set_state(id, state)
    }

    fn close_window(&self, id: u64) -> DesktopResult<()> {
        self.need_desktop("close window")?;
        window::close(id)
    }

    fn move_window(&self, id: u64, rect: Rect) -> DesktopResult<()> {
        self.need_desktop("move window")?;
        window::move_to(id, rect)
    }

    fn accessibility(
        &self,
        backend: A11yBackend,
        budget: &TreeBudget,
        foreground_only: bool,
    ) -> DesktopResult<A11yTree> {
        self.need_desktop("accessibility")?;
        match backend {
            A11yBackend::Win32 => {
                arena_a11y_walk::walk(&mut win32_tree::Win32Source::new(), A11yBackend::Win32, budget, foreground_only)
            }
            A11yBackend::Uia => self.uia.tree(budget, foreground_only),
            A11yBackend::Unknown => Err(DesktopError::InvalidInput("unknown accessibility backend".into())),
        }
    }

    fn clipboard_get(&self) -> DesktopResult<ClipboardData> {
        self.need_desktop("clipboard")?;
        clipboard::get()
    }

    fn clipboard_set(&self, data: &ClipboardData) -> DesktopResult<()> {
        self.need_desktop("clipboard")?;
        clipboard::set(data)
    }

    fn map_path(&self, guest_path: &str) -> DesktopResult<PathBuf> {
        super::winsys::check_guest_path(guest_path)?;
        Ok(PathBuf::from(guest_path))
    }

    fn unmap_path(&self, local: &Path) -> DesktopResult<String> {
        let s = local
            .to_str()
            .ok_or_else(|| DesktopError::InvalidInput(format!("{} is not valid Unicode", local.display())))?;
        Ok(super::winsys::unverbatim(s))
    }

    fn env_var(&self, name: &str) -> Option<String> {
        if name.is_empty() || name.contains(['=', '\0']) {
            return None;
        }
        std::env::var(name).ok()
    }

    fn known_folder(&self, folder: KnownFolder) -> DesktopResult<String> {
        system::known_folder(folder)
    }

    fn recycle(&self, guest_path: &str) -> DesktopResult<()> {
        super::winsys::check_guest_path(guest_path)?;
        system::recycle(guest_path)
    }

    fn open_path(&self, guest_path: &str) -> DesktopResult<()> {
        super::winsys::check_guest_path(guest_path)?;
        process::open(guest_path)
    }

    fn registry_read(&self, key: &str, value: Option<&str>) -> DesktopResult<RegistryValue> {
        system::registry_read(key, value)
    }

    fn registry_write(&self, key: &str, value: Option<&str>, data: &RegistryValue) -> DesktopResult<()> {
        system::registry_write(key, value, data)
    }

    fn wallpaper(&self) -> DesktopResult<Option<String>> {
        system::wallpaper()
    }

    fn set_wallpaper(&self, guest_path: &str) -> DesktopResult<()> {
        super::winsys::check_guest_path(guest_path)?;
        system::set_wallpaper(guest_path)
    }

    fn is_hidden(&self, local: &Path) -> bool {
        use std::os::windows::fs::MetadataExt as _;
        const FILE_ATTRIBUTE_HIDDEN: u32 = 0x2;
        let dot_file = local.file_name().is_some_and(|name| name.to_string_lossy().starts_with('.'));
        let attribute = std::fs::metadata(local).is_ok_and(|meta| meta.file_attributes() & FILE_ATTRIBUTE_HIDDEN != 0);
        dot_file || attribute
    }

    fn directory_access_mask(&self, guest_path: &str, user: &str) -> DesktopResult<Option<u32>> {
        super::winsys::check_guest_path(guest_path)?;
        system::directory_access_mask(guest_path, user)
    }

    fn run(&self, cmd: &CommandSpec, limits: &ExecLimits) -> DesktopResult<ExecOutput> {
        if let Some(cwd) = &limits.cwd {
            super::winsys::check_guest_path(cwd)?;
            if !Path::new(cwd).is_dir() {
                return Err(DesktopError::NotFound(format!("working directory {cwd} not found")));
            }
        }
        process::run(cmd, limits)
    }

    fn spawn(&self, cmd: &CommandSpec) -> DesktopResult<u32> {
        process::spawn(cmd)
    }

    fn shell_command(&self, line: &str) -> CommandSpec {
        crate::desktop::powershell_command(line)
    }

    fn shutdown(&self) -> DesktopResult<()> {
        tracing::warn!("shutting the machine down as asked");
        system::shutdown()
    }

    fn set_system_time(&self, unix_ms: i64) -> DesktopResult<()> {
        system::set_system_time(unix_ms)
    }

    fn defender(&self) -> DesktopResult<crate::desktop::defender::DefenderStatus> {
        use crate::desktop::defender;
        let limits =
            crate::desktop::ExecLimits { timeout_ms: 60_000, max_output_bytes: 1 << 20, cwd: None, stdin: None };
        let out = self.run(&crate::desktop::powershell_command(defender::SCRIPT), &limits)?;
        if out.timed_out {
            return Err(DesktopError::Timeout { op: "Get-MpComputerStatus", ms: limits.timeout_ms });
        }
        defender::parse(&out.stdout).map_err(|why| DesktopError::Os { op: "Get-MpComputerStatus", message: why })
    }
}
