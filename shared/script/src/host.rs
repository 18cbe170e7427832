//! The interpreter's only way to touch the world: the [`ScriptHost`] trait of primitives.
//!
//! Every primitive effect a script can have (input, sleeping, capture, windows,
//! files, processes, the registry, the clipboard, the environment) is one method
//! here, so the interpreter does no I/O of its own and a host decides what each
//! primitive means: the guest's `DesktopHost` calls its `Desktop` backend, the host's
//! `GuestHost` calls the guest's `/v1` API, and [`RecordingHost`] turns input into
//! [`Action`]s. What is composed of primitives is written once in [`super::compose`].
//! Methods fail with a [`HostError`]: an ordinary failure the interpreter raises as
//! an `OSError` with its message, or one that stops the script (the deadline
//! passed, the desktop is out of reach), which the caller tells apart by the
//! error's [`ErrorKind`](super::ErrorKind), with no state on the side.

use image::RgbaImage;

use arena_shared::action::Action;
use arena_shared::cmdline::CommandSpec;
use arena_shared::observation::WindowInfo;
use arena_shared::registry::RegistryValue;

pub use arena_shared::cmdline::CommandArg;

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

/// A change to a top-level window, by its id (`POST /v1/windows/{op}` on the host,
/// `Desktop::set_window_state` and `activate_window` in the guest).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WindowChange {
    /// Restore from minimised or maximised (pygetwindow's `restore`).
    Restore,
    /// Maximise (`ShowWindow(SW_MAXIMIZE)`).
    Maximize,
    /// Bring to the foreground (`SetForegroundWindow`).
    Activate,
}

/// The primitives a running script needs from the outside world: the calls that
/// really differ between the guest (a `Desktop` backend) and the host (the guest's
/// `/v1` API).
///
/// Everything a script does that is made of these calls (the window list, switching
/// windows, opening a program, the OS version, saving a screenshot, `subprocess`)
/// is written once, over this trait, in [`super::compose`].
///
/// Object-safe and synchronous; the interpreter calls it on the thread that runs the script.
pub trait ScriptHost {
    // ----- input -----

    /// Performs one input action.
    fn perform(&mut self, action: Action) -> HostResult<()>;

    /// Waits `seconds` (never negative). A host with a deadline may refuse with `Err`,
    /// which stops the script.
    fn sleep(&mut self, seconds: f64) -> HostResult<()>;

    /// Whether the host keeps what it is asked to do instead of doing it (a recorder
    /// collecting actions): the run then counts each action and pause against its own
    /// memory budget and its pool ([`action_bytes`]), so that a program cannot make its
    /// host hold more than it may hold itself (`pyautogui.write('a' * 10**7)` would
    /// otherwise be ten million recorded actions beside a 10 MB string).
    fn keeps_actions(&self) -> bool {
        false
    }

    /// The cursor position in physical pixels.
    fn cursor_position(&mut self) -> HostResult<(i32, i32)>;

    /// The primary screen's size in physical pixels.
    fn screen_size(&mut self) -> HostResult<(u32, u32)>;

    // ----- capture -----

    /// The whole screen now, without the cursor (pyautogui's screenshots never show it).
    fn capture(&mut self) -> HostResult<RgbaImage>;

    /// The screenshot `computer.clipboard.copy_image` crops: in the guest, the one the
    /// last `/update_computer` stored; on the host, a fresh [`capture`](Self::capture).
    fn observed_screenshot(&mut self) -> HostResult<RgbaImage>;

    // ----- windows -----

    /// Every top-level window, with its title, visibility, focus and z-order.
    fn windows(&mut self) -> HostResult<Vec<WindowInfo>>;

    /// Changes one window's state.
    fn change_window(&mut self, id: u64, change: WindowChange) -> HostResult<()>;

    // ----- files -----

    /// Whether `path` exists and what it is.
    fn path_kind(&mut self, path: &str) -> Option<PathKind>;

    /// The names in a directory, like `os.listdir`.
    fn list_dir(&mut self, path: &str) -> HostResult<Vec<String>>;

    /// Writes `bytes` to the file `path` (atomically), in a folder that exists.
    fn write_file(&mut self, path: &str, bytes: Vec<u8>) -> HostResult<()>;

    // ----- processes -----

    /// Runs a command to completion.
    fn run(&mut self, command: &CommandSpec) -> HostResult<CommandOutput>;

    /// Starts a command without waiting; `Ok(None)` when its program does not exist.
    fn launch(&mut self, command: &CommandSpec) -> HostResult<Option<u32>>;

    // ----- registry, clipboard, environment -----

    /// Reads a registry value (`value: None` is the key's default value); `Ok(None)`
    /// when the key or the value does not exist.
    fn registry_read(&mut self, key: &str, value: Option<&str>) -> HostResult<Option<RegistryValue>>;

    fn clipboard_set_text(&mut self, text: &str) -> HostResult<()>;

    fn clipboard_get_text(&mut self) -> HostResult<String>;

    fn clipboard_set_image(&mut self, image: RgbaImage) -> HostResult<()>;

    /// An environment variable of the guest session (case-insensitive on Windows).
    fn env_var(&mut self, name: &str) -> Option<String>;
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

/// The bytes one recorded action holds: its own size and the text it owns.
pub fn action_bytes(action: &Action) -> usize {
    let owned = match action {
        Action::KeyPress { key, .. } | Action::KeyDown { key } | Action::KeyUp { key } => key.capacity(),
        Action::Hotkey { keys } => {
            keys.capacity() * std::mem::size_of::<String>() + keys.iter().map(String::capacity).sum::<usize>()
        }
        Action::TypeText { text, .. } => text.capacity(),
        _ => 0,
    };
    std::mem::size_of::<Action>() + owned
}

fn not_an_action<T>(what: &str) -> HostResult<T> {
    Err(HostError::Failed(format!("{what} cannot be translated into input actions")))
}

impl ScriptHost for RecordingHost {
    fn keeps_actions(&self) -> bool {
        true
    }

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

    fn capture(&mut self) -> HostResult<RgbaImage> {
        not_an_action("saving a screenshot")
    }

    fn observed_screenshot(&mut self) -> HostResult<RgbaImage> {
        not_an_action("copying an image")
    }

    fn windows(&mut self) -> HostResult<Vec<WindowInfo>> {
        not_an_action("listing windows")
    }

    fn change_window(&mut self, _id: u64, _change: WindowChange) -> HostResult<()> {
        not_an_action("changing a window")
    }

    fn path_kind(&mut self, _path: &str) -> Option<PathKind> {
        None
    }

    fn list_dir(&mut self, _path: &str) -> HostResult<Vec<String>> {
        not_an_action("listing a directory")
    }

    fn write_file(&mut self, _path: &str, _bytes: Vec<u8>) -> HostResult<()> {
        not_an_action("writing a file")
    }

    fn run(&mut self, _command: &CommandSpec) -> HostResult<CommandOutput> {
        not_an_action("running a command")
    }

    fn launch(&mut self, _command: &CommandSpec) -> HostResult<Option<u32>> {
        not_an_action("starting a process")
    }

    fn registry_read(&mut self, _key: &str, _value: Option<&str>) -> HostResult<Option<RegistryValue>> {
        not_an_action("reading the registry")
    }

    fn clipboard_set_text(&mut self, _text: &str) -> HostResult<()> {
        not_an_action("setting the clipboard")
    }

    fn clipboard_get_text(&mut self) -> HostResult<String> {
        not_an_action("reading the clipboard")
    }

    fn clipboard_set_image(&mut self, _image: RgbaImage) -> HostResult<()> {
        not_an_action("copying an image")
    }

    fn env_var(&mut self, _name: &str) -> Option<String> {
        None
    }
}
