//! The guest's [`ScriptHost`]: what the native Python-subset interpreter
//! (`arena_script`) does when `/execute` or `/execute_windows` code acts on
//! the world. Every primitive becomes a call on the one [`Desktop`] backend, so the
//! interpreter works the same over the stub and the Windows backend; what is made of
//! primitives (the window list, `open_program`, `platform.version()`, saved
//! screenshots) is `arena_script::compose`'s, the same code the host runs.
//!
//! It is not the interpreter (that lives in `arena_script`, whose only I/O is its host)
//! and not a route: `waa::execute` decides which requests run code and how the
//! answers look.
//!
//! Every call checks one deadline (the `/execute` timeout): sleeps past it and
//! commands that would outlive it stop the script with a [`HostError::TimedOut`],
//! which the route sees as the script error's kind and answers with Python's
//! `TimeoutExpired` text.
//! [`DesktopHost::effects`] counts the effects performed, so a route knows whether
//! re-running the code with a real Python would repeat something.

use std::path::Path;
use std::time::{Duration, Instant};

use arena_script::compose::PROGRAM_NOT_FOUND;
use arena_script::{CommandOutput, HostError, HostResult, PathKind, ScriptHost, WindowChange};
use arena_shared::action::Action;
use arena_shared::observation::WindowInfo;
use arena_shared::registry::RegistryValue;
use image::RgbaImage;

use crate::desktop::{ClipboardData, CommandSpec, Desktop, DesktopError, ExecLimits, WindowState};

/// Output kept per stream of a command a script runs (as `/execute` keeps).
const MAX_OUTPUT_BYTES: u64 = 64 << 20;

/// A [`ScriptHost`] over a [`Desktop`], with a deadline.
#[derive(Debug)]
pub struct DesktopHost<'a> {
    desktop: &'a dyn Desktop,
    deadline: Instant,
    /// The `/update_computer` screenshot that `clipboard.copy_image` crops.
    screenshot: Option<&'a image::RgbaImage>,
    effects: usize,
}

impl<'a> DesktopHost<'a> {
    /// A host acting on `desktop` until `deadline`.
    pub fn new(desktop: &'a dyn Desktop, deadline: Instant) -> DesktopHost<'a> {
        DesktopHost { desktop, deadline, screenshot: None, effects: 0 }
    }

    /// Sets the screenshot `copy_image` crops (the one `/update_computer` stored).
    #[must_use]
    pub fn with_screenshot(mut self, screenshot: &'a image::RgbaImage) -> DesktopHost<'a> {
        self.screenshot = Some(screenshot);
        self
    }

    /// How many effects (input actions, files, processes, clipboard and window
    /// changes) the script has performed so far.
    pub fn effects(&self) -> usize {
        self.effects
    }

    fn remaining(&self) -> Duration {
        self.deadline.saturating_duration_since(Instant::now())
    }

    /// Refuses new work once the deadline has passed.
    fn check_deadline(&mut self) -> HostResult<()> {
        if self.remaining().is_zero() {
            return Err(HostError::TimedOut("the script ran out of time".to_owned()));
        }
        Ok(())
    }

    /// Counts an effect about to happen, after checking the deadline.
    fn effect(&mut self) -> HostResult<()> {
        self.check_deadline()?;
        self.effects += 1;
        Ok(())
    }
}

/// A backend failure as the script sees it: a backend deadline stops the script,
/// anything else is an `OSError` it may handle.
fn fail(err: DesktopError) -> HostError {
    match err {
        DesktopError::Timeout { .. } => HostError::TimedOut(err.to_string()),
        other => HostError::Failed(other.to_string()),
    }
}

impl ScriptHost for DesktopHost<'_> {
    fn perform(&mut self, action: Action) -> HostResult<()> {
        if let Action::Wait { ms } = action {
            // The backend never sees waits; they are sleeps of the script.
            return self.sleep(ms as f64 / 1000.0);
        }
        self.effect()?;
        self.desktop.perform(&action).map_err(fail)
    }

    fn sleep(&mut self, seconds: f64) -> HostResult<()> {
        if seconds.is_nan() || seconds < 0.0 {
            return Err(format!("cannot sleep {seconds} s").into());
        }
        let remaining = self.remaining();
        // Infinity lands here too, so it never reaches `Duration::from_secs_f64`.
        if seconds > remaining.as_secs_f64() {
            // Refused at once: waiting out the rest would only delay the same failure.
            return Err(HostError::TimedOut(format!(
                "sleeping {seconds} s would outlast the command's timeout ({:.3} s left); nothing was waited",
                remaining.as_secs_f64()
            )));
        }
        if seconds > 0.0 {
            std::thread::sleep(Duration::from_secs_f64(seconds));
        }
        Ok(())
    }

    fn cursor_position(&mut self) -> HostResult<(i32, i32)> {
        let p = self.desktop.cursor_position().map_err(fail)?;
        Ok((p.x, p.y))
    }

    fn screen_size(&mut self) -> HostResult<(u32, u32)> {
        let screen = self.desktop.screen().map_err(fail)?;
        Ok((screen.physical_width, screen.physical_height))
    }

    fn capture(&mut self) -> HostResult<RgbaImage> {
        self.check_deadline()?;
        // pyautogui's screenshots never show the cursor.
        Ok(self.desktop.capture(false).map_err(fail)?.image)
    }

    fn observed_screenshot(&mut self) -> HostResult<RgbaImage> {
        self.screenshot.cloned().ok_or_else(|| "there is no /update_computer screenshot to copy from".into())
    }

    fn windows(&mut self) -> HostResult<Vec<WindowInfo>> {
        self.desktop.windows().map_err(fail)
    }

    fn change_window(&mut self, id: u64, change: WindowChange) -> HostResult<()> {
        self.effect()?;
        match change {
            WindowChange::Restore => self.desktop.set_window_state(id, WindowState::Normal),
            WindowChange::Maximize => self.desktop.set_window_state(id, WindowState::Maximized),
            WindowChange::Activate => self.desktop.activate_window(id),
        }
        .map_err(fail)
    }

    fn path_kind(&mut self, path: &str) -> Option<PathKind> {
        let local = self.desktop.map_path(path).ok()?;
        let meta = std::fs::metadata(local).ok()?;
        Some(if meta.is_dir() { PathKind::Dir } else { PathKind::File })
    }

    fn list_dir(&mut self, path: &str) -> HostResult<Vec<String>> {
        let local = self.desktop.map_path(path).map_err(fail)?;
        let names = arena_shared::ntfs::list_dir(&local).map_err(|err| match err.kind() {
            std::io::ErrorKind::NotFound => format!("[WinError 3] The system cannot find the path specified: '{path}'"),
            std::io::ErrorKind::NotADirectory => format!("[WinError 267] The directory name is invalid: '{path}'"),
            _ => format!("{path}: {err}"),
        })?;
        Ok(names)
    }

    fn write_file(&mut self, path: &str, bytes: Vec<u8>) -> HostResult<()> {
        self.effect()?;
        let local = self.desktop.map_path(path).map_err(fail)?;
        // Like Python's `open(path, "wb")`, it does not create missing folders.
        if !local.parent().is_some_and(Path::is_dir) {
            return Err(format!("[Errno 2] No such file or directory: '{path}'").into());
        }
        // Atomically, so a reader never sees half a file.
        arena_shared::atomic::write_atomic(&local, &bytes).map_err(|err| format!("{path}: {err}").into())
    }

    fn run(&mut self, command: &CommandSpec) -> HostResult<CommandOutput> {
        self.effect()?;
        let timeout_ms = u64::try_from(self.remaining().as_millis()).unwrap_or(u64::MAX).max(1);
        let limits = ExecLimits { timeout_ms, max_output_bytes: MAX_OUTPUT_BYTES, cwd: None, stdin: None };
        match self.desktop.run(command, &limits) {
            Ok(out) if out.timed_out => Err(HostError::TimedOut("the command ran out of time".to_owned())),
            Ok(out) => Ok(CommandOutput { code: out.exit_code.unwrap_or(-1), stdout: out.stdout, stderr: out.stderr }),
            Err(DesktopError::Timeout { .. }) => Err(HostError::TimedOut("the command ran out of time".to_owned())),
            Err(DesktopError::NotFound(_)) => Err(HostError::Failed(PROGRAM_NOT_FOUND.to_owned())),
            Err(err) => Err(fail(err)),
        }
    }

    fn launch(&mut self, command: &CommandSpec) -> HostResult<Option<u32>> {
        self.effect()?;
        match self.desktop.spawn(command) {
            Ok(pid) => Ok(Some(pid)),
            Err(DesktopError::NotFound(_)) => Ok(None),
            Err(err) => Err(fail(err)),
        }
    }

    fn registry_read(&mut self, key: &str, value: Option<&str>) -> HostResult<Option<RegistryValue>> {
        match self.desktop.registry_read(key, value) {
            Ok(read) => Ok(Some(read)),
            Err(DesktopError::NotFound(_)) => Ok(None),
            Err(err) => Err(fail(err)),
        }
    }

    fn clipboard_set_text(&mut self, text: &str) -> HostResult<()> {
        self.effect()?;
        self.desktop.clipboard_set(&ClipboardData::Text(text.to_owned())).map_err(fail)
    }

    fn clipboard_get_text(&mut self) -> HostResult<String> {
        match self.desktop.clipboard_get().map_err(fail)? {
            ClipboardData::Text(text) => Ok(text),
            // pyperclip.paste() gives "" when the clipboard holds no text.
            ClipboardData::Empty | ClipboardData::Image(_) => Ok(String::new()),
        }
    }

    fn clipboard_set_image(&mut self, image: RgbaImage) -> HostResult<()> {
        self.effect()?;
        self.desktop.clipboard_set(&ClipboardData::Image(image)).map_err(fail)
    }

    fn env_var(&mut self, name: &str) -> Option<String> {
        self.desktop.env_var(name)
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use arena_script::{run_source, Composed as _, Globals};

    use super::*;
    use crate::desktop::stub::StubDesktop;

    fn stub() -> (tempfile::TempDir, Arc<StubDesktop>) {
        let dir = tempfile::tempdir().expect("temp dir");
        let stub = Arc::new(StubDesktop::new(dir.path().to_path_buf()).expect("stub"));
        (dir, stub)
    }

    fn far() -> Instant {
        Instant::now() + Duration::from_secs(60)
    }

    #[test]
    fn sleeping_past_the_deadline_stops_the_script() {
        let (_dir, stub) = stub();
        let mut host = DesktopHost::new(stub.as_ref(), Instant::now() + Duration::from_millis(30));
        let err = run_source("import time; time.sleep(5)", &mut host, Globals::python()).expect_err("times out");
        assert_eq!(err.kind, arena_script::ErrorKind::Timeout, "{err}");
        let mut host = DesktopHost::new(stub.as_ref(), far());
        assert!(host.sleep(f64::NAN).is_err());
    }

    #[test]
    fn scripts_act_on_the_desktop_and_count_effects() {
        let (_dir, stub) = stub();
        let mut host = DesktopHost::new(stub.as_ref(), far());
        let out = run_source(
            "import pyautogui, os\npyautogui.click(10, 20)\nprint(pyautogui.size(), os.path.exists(r'C:\\Users\\Docker\\Desktop'))",
            &mut host,
            Globals::python(),
        )
        .expect("runs");
        assert_eq!(out.stdout, "Size(width=1440, height=900) True\n");
        assert_eq!(host.effects(), 1);
        assert_eq!(stub.action_log().len(), 1);
    }

    #[test]
    fn screenshots_are_saved_as_png_files() {
        let (_dir, stub) = stub();
        let mut host = DesktopHost::new(stub.as_ref(), far());
        host.save_screenshot(r"C:\Users\Docker\Downloads\s.png", Some([0, 0, 30, 20]), None).expect("saved");
        let bytes = std::fs::read(stub.map_path(r"C:\Users\Docker\Downloads\s.png").expect("maps")).expect("file");
        let image = crate::imaging::decode(&bytes).expect("png");
        assert_eq!(image.dimensions(), (30, 20));
        let err = host.save_screenshot(r"C:\Users\Docker\Nope\s.png", None, None).expect_err("no folder");
        assert!(err.to_string().contains("No such file or directory"), "{err}");
    }

    #[test]
    fn open_program_starts_known_programs_and_reports_unknown_ones() {
        let (_dir, stub) = stub();
        let mut host = DesktopHost::new(stub.as_ref(), far());
        assert_eq!(host.open_program("notepad"), Ok(true));
        assert!(stub.find_window("Notepad").is_some());
        // Without --stub-host-exec, a program that is not simulated is not installed.
        assert_eq!(host.open_program("arena-no-such-program-xyz"), Ok(false));
        assert!(host.open_program("notepad & calc").is_err());
        assert_eq!(host.active_window_title().as_deref(), Ok("Untitled - Notepad"));
        assert!(host.window_titles().expect("titles").contains(&"Untitled - Notepad".to_owned()));
    }

    #[test]
    fn with_host_exec_open_program_reports_a_missing_program_as_not_opened() {
        let dir = tempfile::tempdir().expect("tmp");
        let config = crate::desktop::stub::StubConfig {
            root: Some(dir.path().to_path_buf()),
            host_exec: true,
            ..crate::desktop::stub::StubConfig::default()
        };
        let stub = StubDesktop::with_config(config).expect("stub");
        let mut host = DesktopHost::new(&stub, far());
        assert_eq!(host.open_program("arena-no-such-program-xyz"), Ok(false));
    }

    #[test]
    fn the_os_version_is_read_from_the_registry_as_platform_version_prints_it() {
        let (_dir, stub) = stub();
        let mut host = DesktopHost::new(stub.as_ref(), far());
        assert_eq!(host.os_version().as_deref(), Ok("10.0.22631"));
        let key = arena_script::compose::CURRENT_VERSION;
        stub.registry_write(key, Some("CurrentBuildNumber"), &RegistryValue::Binary(vec![1])).expect("written");
        let err = host.os_version().expect_err("not a number");
        assert!(err.to_string().contains(r"CurrentVersion\CurrentBuildNumber is not a number"), "{err}");
    }
}
