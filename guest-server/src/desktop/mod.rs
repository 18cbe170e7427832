//! The one backend trait, [`Desktop`], and the platform-neutral types it speaks.
//!
//! The trait knows no HTTP: routes in [`crate::waa`] and [`crate::native`]
//! call it, through [`crate::call::blocking`], which gives every call a deadline.
//! It is synchronous and object-safe; the server holds it as `Arc<dyn Desktop>`.
//! Backends are chosen at run time: [`stub`] builds everywhere (and runs inside
//! the Windows exe too); [`windows`] holds the Windows backend, whose FFI glue is
//! compiled only for Windows and whose neutral halves everywhere.
//! `arena_a11y_walk` (its own crate) is the accessibility walker every backend feeds its trees through;
//! [`uia_health`] decides the UI Automation health stage (and re-creation) for both;
//! [`defender`] reads Microsoft Defender's state for the doctor.
//!
//! # Coordinates
//!
//! Every point and rectangle is in physical pixels of the virtual screen,
//! the space a per-monitor DPI-aware process sees.

pub mod cancel;
pub mod defender;
pub mod settle;
pub mod stub;
pub mod uia_health;
pub mod uia_process;
pub mod windows;

use std::path::PathBuf;

use arena_shared::action::Action;
use arena_shared::files::KnownFolder;
use arena_shared::geometry::{Point, Rect};
use arena_shared::health::Component;
use arena_shared::observation::{A11yBackend, A11yTree, ScreenInfo, TreeBudget, WindowInfo};
use arena_shared::registry::RegistryValue;

/// What went wrong in a backend call (defined beside the answers it becomes, so that
/// `error` needs nothing from this module).
pub use crate::error::DesktopError;

/// Result alias for backend calls.
pub type DesktopResult<T> = Result<T, DesktopError>;

/// A captured frame of the whole primary screen, in physical pixels.
#[derive(Debug, Clone)]
pub struct Frame {
    pub image: image::RgbaImage,
    /// Cursor position at capture time.
    pub cursor: Option<Point>,
    /// Whether the backend drew the cursor into `image`.
    pub cursor_drawn: bool,
}

/// A window state change.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WindowState {
    Minimized,
    Maximized,
    /// Restored from minimised or maximised.
    Normal,
}

/// Clipboard contents in backend form.
#[derive(Debug, Clone, PartialEq)]
pub enum ClipboardData {
    Empty,
    Text(String),
    Image(image::RgbaImage),
}

pub use arena_shared::cmdline::CommandSpec;

/// The line [`powershell_command`] puts before a script: its output in the ANSI code
/// page, which is how the Windows backend decodes a program's output
/// (`[Console]::OutputEncoding` is the OEM code page otherwise); in a `try`, since a
/// process without a console cannot set it, and the script runs either way.
pub const POWERSHELL_PROLOGUE: &str = "try { [Console]::OutputEncoding = [System.Text.Encoding]::Default } catch {}";

/// Windows PowerShell running `script`: no profile, no prompts, the script passed as
/// `-EncodedCommand` (base64 of UTF-16LE, so no quoting of the line can go wrong), after
/// [`POWERSHELL_PROLOGUE`].
pub fn powershell_command(script: &str) -> CommandSpec {
    use base64::Engine as _;
    let whole = format!("{POWERSHELL_PROLOGUE}\n{script}");
    let utf16: Vec<u8> = whole.encode_utf16().flat_map(u16::to_le_bytes).collect();
    let encoded = base64::engine::general_purpose::STANDARD.encode(utf16);
    CommandSpec::Argv(
        ["powershell.exe", "-NoLogo", "-NoProfile", "-NonInteractive", "-ExecutionPolicy", "Bypass", "-EncodedCommand"]
            .iter()
            .map(|s| (*s).to_owned())
            .chain(std::iter::once(encoded))
            .collect(),
    )
}

/// Limits on [`Desktop::run`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ExecLimits {
    /// Kill the process (and on Windows its whole job) after this many milliseconds.
    pub timeout_ms: u64,
    /// Keep at most this many bytes of each output stream; the rest is read and dropped.
    pub max_output_bytes: u64,
    /// Working directory (a guest path); `None` keeps the server's.
    pub cwd: Option<String>,
    /// Bytes for standard input.
    pub stdin: Option<Vec<u8>>,
}

/// Output of a finished (or killed) program.
///
/// Streams are decoded text: on Windows from the ANSI code page, with CRLF and CR folded to LF
/// (Python's `text=True`); elsewhere as lossy UTF-8 with the same newline folding.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ExecOutput {
    pub exit_code: Option<i32>,
    pub stdout: String,
    pub stderr: String,
    pub stdout_truncated: bool,
    pub stderr_truncated: bool,
    pub timed_out: bool,
    pub duration_ms: u64,
}

/// The backend: everything the server can ask of a desktop.
///
/// Implementations must be cheap to call from many threads at once; they
/// serialise internally where the platform needs it.
pub trait Desktop: Send + Sync + std::fmt::Debug {
    /// `"stub"` or `"windows"`.
    fn kind(&self) -> &'static str;

    /// Checks that `component` works right now and says what was checked.
    ///
    /// # Errors
    ///
    /// Why the component is not usable.
    fn probe(&self, component: Component) -> DesktopResult<String>;

    /// One look at the shell for the `shell` health component ([`settle`]):
    /// the taskbar, what is in front, the CPU's times.
    ///
    /// # Errors
    ///
    /// [`DesktopError::Unsupported`] where the backend cannot look.
    fn shell_sample(&self) -> DesktopResult<settle::ShellSample> {
        Err(DesktopError::Unsupported(format!("the {} backend cannot look at the shell", self.kind())))
    }

    /// Windows session id of the server process, where the platform has sessions.
    fn session_id(&self) -> Option<u32> {
        None
    }

    /// The server process's integrity level and elevation, as the doctor and
    /// health report it (`High, elevated (full token)`, `Medium, limited token`).
    ///
    /// # Errors
    ///
    /// [`DesktopError::Unsupported`] where the platform has no integrity levels.
    fn integrity_level(&self) -> DesktopResult<String> {
        Err(DesktopError::Unsupported(format!("the {} backend has no integrity levels", self.kind())))
    }

    // ----- screen -----

    /// Screen size, scale and monitors.
    fn screen(&self) -> DesktopResult<ScreenInfo>;

    /// Captures the primary screen; draws the cursor when `draw_cursor`.
    fn capture(&self, draw_cursor: bool) -> DesktopResult<Frame>;

    /// Cursor position.
    fn cursor_position(&self) -> DesktopResult<Point>;

    // ----- input -----

    /// Performs one input action. [`Action::Wait`] is done by the caller, never sent here.
    ///
    /// # Errors
    ///
    /// [`DesktopError::InvalidInput`] for unknown key names or `Action::Unknown`.
    fn perform(&self, action: &Action) -> DesktopResult<()>;

    // ----- windows -----

    /// Top-level windows, topmost first (z-order), with hidden ones flagged `visible: false`.
    fn windows(&self) -> DesktopResult<Vec<WindowInfo>>;

    /// Brings a window to the foreground (restoring it if minimised).
    fn activate_window(&self, id: u64) -> DesktopResult<()>;

    /// Minimises, maximises or restores a window.
    fn set_window_state(&self, id: u64, state: WindowState) -> DesktopResult<()>;

    /// Asks a window to close (`WM_CLOSE`): the program may refuse or prompt.
    fn close_window(&self, id: u64) -> DesktopResult<()>;

    /// Moves and sizes a window to `rect` (its outer rectangle), restoring it first
    /// when it is minimised or maximised. The desktop itself cannot be moved.
    ///
    /// # Errors
    ///
    /// [`DesktopError::NotFound`] for a window that is gone; [`DesktopError::Unsupported`]
    /// where the backend cannot move windows.
    fn move_window(&self, id: u64, rect: Rect) -> DesktopResult<()> {
        let _ = (id, rect);
        Err(DesktopError::Unsupported(format!("the {} backend cannot move windows", self.kind())))
    }

    // ----- accessibility -----

    /// Walks the accessibility tree of the visible top-level windows within `budget`.
    fn accessibility(
        &self,
        backend: A11yBackend,
        budget: &TreeBudget,
        foreground_only: bool,
    ) -> DesktopResult<A11yTree>;

    // ----- clipboard -----

    fn clipboard_get(&self) -> DesktopResult<ClipboardData>;

    fn clipboard_set(&self, data: &ClipboardData) -> DesktopResult<()>;

    // ----- paths and system -----

    /// Maps a guest path (already `~`- and `%VAR%`-expanded, absolute) onto a path
    /// this process can open with `std::fs`. Identity on Windows; the stub maps
    /// `C:\Users\Docker\a.txt` under its root directory.
    ///
    /// # Errors
    ///
    /// [`DesktopError::InvalidInput`] for a relative path, a path that climbs out of its
    /// root, or a device or UNC path the backend does not serve.
    fn map_path(&self, guest_path: &str) -> DesktopResult<PathBuf>;

    /// The inverse of [`Desktop::map_path`], for listing results.
    fn unmap_path(&self, local: &std::path::Path) -> DesktopResult<String>;

    /// An environment variable as programs in the guest see it (`USERPROFILE`, `APPDATA`, ...).
    fn env_var(&self, name: &str) -> Option<String>;

    /// A known folder's guest path.
    fn known_folder(&self, folder: KnownFolder) -> DesktopResult<String>;

    /// Moves a file or folder to the Recycle Bin.
    fn recycle(&self, guest_path: &str) -> DesktopResult<()>;

    /// Opens a file with its associated program (ShellExecute "open").
    fn open_path(&self, guest_path: &str) -> DesktopResult<()>;

    /// Reads a registry value; `value: None` is the key's default value.
    fn registry_read(&self, key: &str, value: Option<&str>) -> DesktopResult<RegistryValue>;

    /// Writes a registry value, creating the key.
    fn registry_write(&self, key: &str, value: Option<&str>, data: &RegistryValue) -> DesktopResult<()>;

    /// The current wallpaper's guest path, or `None` when there is none.
    fn wallpaper(&self) -> DesktopResult<Option<String>>;

    /// Sets the wallpaper to an image file.
    fn set_wallpaper(&self, guest_path: &str) -> DesktopResult<()>;

    /// Whether the file at `local` (a mapped path) is hidden. The default is the
    /// dot-file rule, which is how the stub, whose files live on a host file system,
    /// models hidden files; the Windows backend adds `FILE_ATTRIBUTE_HIDDEN` (what
    /// Python's `os.stat(p).st_file_attributes` reports upstream).
    fn is_hidden(&self, local: &std::path::Path) -> bool {
        local.file_name().is_some_and(|name| name.to_string_lossy().starts_with('.'))
    }

    /// The access mask of the first ACE in a directory's DACL that names `user`, if any.
    fn directory_access_mask(&self, guest_path: &str, user: &str) -> DesktopResult<Option<u32>>;

    // ----- processes -----

    /// Runs a program to completion (or its timeout) and captures its output.
    ///
    /// # Errors
    ///
    /// [`DesktopError::NotFound`] when the program does not exist. A non-zero exit
    /// code and a timeout are not errors: see [`ExecOutput`].
    fn run(&self, cmd: &CommandSpec, limits: &ExecLimits) -> DesktopResult<ExecOutput>;

    /// Starts a program without waiting; returns its process id.
    fn spawn(&self, cmd: &CommandSpec) -> DesktopResult<u32>;

    /// How the desktop's shell runs a command line a person types (the MCP `shell`
    /// tool): the stub's shell (`sh -c`, `cmd /c` in the Windows exe) by default;
    /// PowerShell on the Windows backend ([`powershell_command`]).
    fn shell_command(&self, line: &str) -> CommandSpec {
        CommandSpec::Shell(line.to_owned())
    }

    /// Shuts the machine down.
    fn shutdown(&self) -> DesktopResult<()>;

    // ----- the clock -----

    /// The machine's wall clock, milliseconds since the Unix epoch (UTC).
    ///
    /// # Errors
    ///
    /// The backend cannot read it.
    fn system_time(&self) -> DesktopResult<i64> {
        Ok(arena_shared::clock::now_unix_ms())
    }

    /// Sets the machine's wall clock to `unix_ms` (checked by
    /// [`arena_shared::clock::check`] first): `SetSystemTime` on Windows, a
    /// modelled offset in the stub.
    ///
    /// # Errors
    ///
    /// [`DesktopError::Unsupported`] by default; the system's refusal.
    fn set_system_time(&self, unix_ms: i64) -> DesktopResult<()> {
        let _ = unix_ms;
        Err(DesktopError::Unsupported(format!("the {} backend cannot set the clock", self.kind())))
    }

    // ----- Microsoft Defender -----

    /// Defender's Tamper Protection, real-time protection and detections, for
    /// the doctor. By default (the stub) there is no Defender: every fact is
    /// unknown and there are no detections.
    ///
    /// # Errors
    ///
    /// Defender's state could not be asked at all.
    fn defender(&self) -> DesktopResult<defender::DefenderStatus> {
        Ok(defender::DefenderStatus::absent(&format!("the {} backend has no Microsoft Defender", self.kind())))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn powershell_gets_the_script_encoded_whole() {
        let script = "Get-ChildItem \"C:\\a b\" | % { $_.Name } # ü";
        let CommandSpec::Argv(argv) = powershell_command(script) else { panic!("an argument vector") };
        assert_eq!(
            argv[..7],
            [
                "powershell.exe",
                "-NoLogo",
                "-NoProfile",
                "-NonInteractive",
                "-ExecutionPolicy",
                "Bypass",
                "-EncodedCommand"
            ]
        );
        use base64::Engine as _;
        let bytes = base64::engine::general_purpose::STANDARD.decode(&argv[7]).expect("base64");
        let units: Vec<u16> = bytes.chunks_exact(2).map(|p| u16::from_le_bytes([p[0], p[1]])).collect();
        let decoded = String::from_utf16(&units).expect("UTF-16LE");
        assert_eq!(decoded, format!("{POWERSHELL_PROLOGUE}\n{script}"));
    }
}
