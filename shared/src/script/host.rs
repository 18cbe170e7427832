//! The interpreter's only way to touch the world: the [`ScriptHost`] trait.
//!
//! Every effect a script can have (input, sleeping, screenshots, the
//! environment, files, processes, the clipboard, windows) is one method here,
//! so this crate stays free of I/O and a host decides what each effect means:
//! the guest performs them on the desktop, [`RecordingHost`] turns them into
//! [`Action`]s for the host client.
//! Methods fail with a [`HostError`]: an ordinary failure the interpreter raises as
//! an `OSError` with its message, or one that stops the script (the deadline
//! passed, the desktop is out of reach), which the caller tells apart by the
//! error's [`ErrorKind`](super::ErrorKind), with no state on the side.

use crate::action::Action;

/// A command for `subprocess` or `os.system`: one string or an argument list, as written.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum CommandArg {
    Line(String),
    Args(Vec<String>),
}

/// Why a host could not carry out an effect.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum HostError {
    /// The effect failed (a missing file, a refused window); the script sees an
    /// `OSError` with this message and may go on.
    #[error("{0}")]
    Failed(String),
    /// The run's deadline passed; the script stops.
    #[error("{0}")]
    TimedOut(String),
    /// What the host acts on (the guest, the desktop) is out of reach; the script stops.
    #[error("{0}")]
    Unreachable(String),
}

impl From<String> for HostError {
    fn from(message: String) -> HostError {
        HostError::Failed(message)
    }
}

impl From<&str> for HostError {
    fn from(message: &str) -> HostError {
        HostError::Failed(message.to_owned())
    }
}

/// Result of a [`ScriptHost`] call.
pub type HostResult<T> = Result<T, HostError>;

/// What a finished command printed and returned.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct CommandOutput {
    pub code: i32,
    /// Decoded text with universal newlines, as `subprocess.run(text=True)` gives it.
    pub stdout: String,
    pub stderr: String,
}

/// What a path names.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PathKind {
    File,
    Dir,
}

/// Everything a running script can do to the outside world.
///
/// Object-safe and synchronous; the interpreter calls it on the thread that runs the script.
pub trait ScriptHost {
    /// Performs one input action.
    fn perform(&mut self, action: Action) -> HostResult<()>;

    /// Waits `seconds` (never negative). A host with a deadline may refuse with `Err`,
    /// which stops the script.
    fn sleep(&mut self, seconds: f64) -> HostResult<()>;

    /// The cursor position in physical pixels.
    fn cursor_position(&mut self) -> HostResult<(i32, i32)>;

    /// The primary screen's size in physical pixels.
    fn screen_size(&mut self) -> HostResult<(u32, u32)>;

    /// The foreground window's title (`""` when there is none).
    fn active_window_title(&mut self) -> HostResult<String>;

    /// Captures the screen (or `region` as left, top, width, height) and saves it as an
    /// image file at the guest path `path`; the format follows the extension.
    fn save_screenshot(&mut self, path: &str, region: Option<[i32; 4]>) -> HostResult<()>;

    /// An environment variable of the guest session (case-insensitive on Windows).
    fn env_var(&mut self, name: &str) -> Option<String>;

    /// Whether `path` exists and what it is.
    fn path_kind(&mut self, path: &str) -> Option<PathKind>;

    /// The names in a directory, like `os.listdir`.
    fn list_dir(&mut self, path: &str) -> HostResult<Vec<String>>;

    /// Runs a command to completion (`subprocess.run/call`, `os.system`).
    /// `shell` runs it through `cmd.exe /c`.
    fn run_command(&mut self, cmd: &CommandArg, shell: bool) -> HostResult<CommandOutput>;

    /// Starts a command without waiting (`subprocess.Popen`, `os.startfile`); returns its pid.
    fn spawn_command(&mut self, cmd: &CommandArg, shell: bool) -> HostResult<u32>;

    /// The Windows version as `platform.version()` prints it, e.g. `10.0.22631`.
    fn os_version(&mut self) -> HostResult<String>;

    fn clipboard_set_text(&mut self, text: &str) -> HostResult<()>;

    fn clipboard_get_text(&mut self) -> HostResult<String>;

    /// Puts the crop `[x1, y1, x2, y2]` of the screenshot last given to
    /// `/update_computer` on the clipboard as an image (`Computer.clipboard.copy_image`).
    fn clipboard_set_image_from_screenshot_crop(&mut self, rect: [i32; 4]) -> HostResult<()>;

    /// `Computer.os.open_program`: if `name` is installed (App Paths or on the search
    /// path), starts it with `start NAME` and returns `true`; returns `false` when it is
    /// not installed. Never waits for the program to exit (upstream's Q10 is fixed).
    fn open_program(&mut self, name: &str) -> HostResult<bool>;

    /// Moves the foreground window to (0, 0) and maximizes it.
    fn maximize_foreground(&mut self) -> HostResult<()>;

    /// Titles of the visible top-level windows with a non-empty title, de-duplicated.
    fn window_titles(&mut self) -> HostResult<Vec<String>>;

    /// Restores, maximizes and brings to the foreground the first visible window with
    /// exactly this title.
    fn switch_to_window(&mut self, title: &str) -> HostResult<()>;
}

/// The cursor position after `action`, starting from `cursor`, for hosts that simulate it.
pub fn cursor_after(action: &Action, cursor: (i32, i32)) -> (i32, i32) {
    let at = |x: &Option<i32>, y: &Option<i32>| (x.unwrap_or(cursor.0), y.unwrap_or(cursor.1));
    match action {
        Action::MoveTo { x, y } => (*x, *y),
        Action::MoveRel { dx, dy } => (cursor.0.saturating_add(*dx), cursor.1.saturating_add(*dy)),
        Action::Click { x, y, .. }
        | Action::DoubleClick { x, y }
        | Action::RightClick { x, y }
        | Action::MouseDown { x, y, .. }
        | Action::MouseUp { x, y, .. }
        | Action::Scroll { x, y, .. } => at(x, y),
        Action::Drag { to, .. } => (to.x, to.y),
        _ => cursor,
    }
}

/// A host without I/O that records input actions and turns sleeps into
/// [`Action::Wait`]; it simulates the cursor so that relative moves and
/// `position()` work. Every other effect fails with a message saying it
/// cannot be expressed as an input action.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordingHost {
    pub actions: Vec<Action>,
    pub screen: (u32, u32),
    pub cursor: (i32, i32),
}

impl RecordingHost {
    pub fn new(screen: (u32, u32), cursor: (i32, i32)) -> RecordingHost {
        RecordingHost { actions: Vec::new(), screen, cursor }
    }
}

fn not_an_action<T>(what: &str) -> HostResult<T> {
    Err(HostError::Failed(format!("{what} cannot be translated into input actions")))
}

impl ScriptHost for RecordingHost {
    fn perform(&mut self, action: Action) -> HostResult<()> {
        self.cursor = cursor_after(&action, self.cursor);
        self.actions.push(action);
        Ok(())
    }

    fn sleep(&mut self, seconds: f64) -> HostResult<()> {
        let ms = (seconds * 1000.0).round();
        if ms >= 1.0 {
            // The cast saturates for absurd values, which is the intent.
            self.actions.push(Action::Wait { ms: ms as u64 });
        }
        Ok(())
    }

    fn cursor_position(&mut self) -> HostResult<(i32, i32)> {
        Ok(self.cursor)
    }

    fn screen_size(&mut self) -> HostResult<(u32, u32)> {
        Ok(self.screen)
    }

    fn active_window_title(&mut self) -> HostResult<String> {
        not_an_action("reading the active window title")
    }

    fn save_screenshot(&mut self, _path: &str, _region: Option<[i32; 4]>) -> HostResult<()> {
        not_an_action("saving a screenshot")
    }

    fn env_var(&mut self, _name: &str) -> Option<String> {
        None
    }

    fn path_kind(&mut self, _path: &str) -> Option<PathKind> {
        None
    }

    fn list_dir(&mut self, _path: &str) -> HostResult<Vec<String>> {
        not_an_action("listing a directory")
    }

    fn run_command(&mut self, _cmd: &CommandArg, _shell: bool) -> HostResult<CommandOutput> {
        not_an_action("running a command")
    }

    fn spawn_command(&mut self, _cmd: &CommandArg, _shell: bool) -> HostResult<u32> {
        not_an_action("starting a process")
    }

    fn os_version(&mut self) -> HostResult<String> {
        not_an_action("reading the OS version")
    }

    fn clipboard_set_text(&mut self, _text: &str) -> HostResult<()> {
        not_an_action("setting the clipboard")
    }

    fn clipboard_get_text(&mut self) -> HostResult<String> {
        not_an_action("reading the clipboard")
    }

    fn clipboard_set_image_from_screenshot_crop(&mut self, _rect: [i32; 4]) -> HostResult<()> {
        not_an_action("copying an image")
    }

    fn open_program(&mut self, _name: &str) -> HostResult<bool> {
        not_an_action("opening a program")
    }

    fn maximize_foreground(&mut self) -> HostResult<()> {
        not_an_action("maximizing a window")
    }

    fn window_titles(&mut self) -> HostResult<Vec<String>> {
        not_an_action("listing windows")
    }

    fn switch_to_window(&mut self, _title: &str) -> HostResult<()> {
        not_an_action("switching windows")
    }
}
