//! The `computer` behaviours made of [`ScriptHost`] primitives, written once for the
//! guest's script host and the host's agent executor: [`Composed`].
//!
//! A behaviour lives here when it is a rule over primitives rather than a primitive
//! itself, so the guest (over its `Desktop` backend) and the host (over the guest's
//! `/v1` API) cannot drift apart. Each follows upstream's guest on Windows
//! (`vm/setup/server/computer.py` and Python's own modules, WindowsAgentArena at
//! 6d39ed88):
//!
//! - [`Composed::window_titles`]: `WindowManager.find_open_applications`, by
//!   [`arena_shared::window_list::window_names`] (visible, titled, minimised included, each
//!   title once, topmost first).
//! - [`Composed::switch_to_window`]: `switch_to_application`'s effect on the window it
//!   picked: the topmost visible window with that title is restored, maximised and
//!   brought to the front (`window.restore()`, `window.maximize()`,
//!   `SetForegroundWindow`). The fuzzy match and the `esc` after it are the `computer`
//!   object's, in `computer.rs`.
//! - [`Composed::maximize_foreground`]: `OS.maximize_window()` on the foreground window.
//! - [`Composed::open_program`]: `OS.is_installed` and `open_program`: a program is
//!   installed when `App Paths\NAME.exe` (native or `Wow6432Node`) has a non-empty
//!   default value, and is then started with `start NAME` through the shell; otherwise
//!   starting `[NAME]` itself is the check, and a program that does not exist is "not
//!   installed". Deliberately unlike upstream, the fallback starts the program once and
//!   never waits for it (upstream waits for it to exit, then starts it again: Q10), and
//!   a name with `cmd.exe` syntax in it is refused rather than run.
//! - [`Composed::os_version`]: `platform.version()`, which CPython's `platform.win32_ver`
//!   formats as `'{0}.{1}.{2}'.format(major, minor, build)` of integers (for example
//!   `10.0.22631`). Windows keeps the same three numbers under
//!   `HKLM\SOFTWARE\Microsoft\Windows NT\CurrentVersion` as `CurrentMajorVersionNumber`
//!   and `CurrentMinorVersionNumber` (`REG_DWORD`) and `CurrentBuildNumber` (`REG_SZ`);
//!   each is read as an integer whatever its registry type, and a missing or
//!   non-numeric value is an error naming it.
//! - [`Composed::save_screenshot`]: `pyautogui.screenshot(path, region)` and
//!   `Image.save(path, format)`: Pillow takes the format from `format` or else from the
//!   extension (`.png`; `.jpg`, `.jpeg`, `.jpe`, `.jfif`), refuses an unknown one
//!   before touching the file, and cannot create a file in a missing folder
//!   (`[Errno 2]`). JPEG is written at Pillow's default quality 75 by the one JPEG
//!   encoder ([`arena_shared::fastimg`], through [`arena_shared::imaging::encode`]). Formats Pillow
//!   knows but this project does not encode (BMP, GIF, TIFF, ...) are refused with a
//!   message saying so.
//! - [`Composed::copy_image`]: `Clipboard.copy_image`: Pillow's crop
//!   ([`arena_shared::imaging::crop_padded`]) of the observed screenshot, put on the clipboard.
//! - [`Composed::run_command`] and [`Composed::spawn_command`]: `subprocess` and
//!   `os.system`, through [`arena_shared::cmdline::subprocess_command`].
//!
//! It is not a host: it has no state and performs nothing but primitives. The trait is
//! implemented for every [`ScriptHost`] and cannot be implemented again, so no host can
//! give a behaviour its own meaning.

use image::RgbaImage;

use super::host::{CommandArg, CommandOutput, HostError, HostResult, PathKind, ScriptHost, WindowChange};
use arena_shared::cmdline::{subprocess_command, CommandSpec};
use arena_shared::fastimg::PILLOW_JPEG_QUALITY;
use arena_shared::imaging::{crop_padded, encode};
use arena_shared::ntpath;
use arena_shared::observation::{ImageFormat, WindowInfo};
use arena_shared::registry::RegistryValue;
use arena_shared::window_list::window_names;

/// Where `OS.is_installed` looks, in its order.
pub const APP_PATHS: [&str; 2] = [
    r"HKLM\SOFTWARE\Microsoft\Windows\CurrentVersion\App Paths",
    r"HKLM\SOFTWARE\Wow6432Node\Microsoft\Windows\CurrentVersion\App Paths",
];

/// Where Windows keeps the version numbers `platform.version()` prints.
pub const CURRENT_VERSION: &str = r"HKLM\SOFTWARE\Microsoft\Windows NT\CurrentVersion";

/// The values under [`CURRENT_VERSION`] that make `major.minor.build`.
pub const VERSION_VALUES: [&str; 3] = ["CurrentMajorVersionNumber", "CurrentMinorVersionNumber", "CurrentBuildNumber"];

/// Characters that would make `start NAME` run more than one program.
const SHELL_SYNTAX: [char; 9] = ['&', '|', '<', '>', '^', '%', '"', '\n', '\r'];

/// The `computer` behaviours over the primitives; see the module doc for each one's source.
pub trait Composed: ScriptHost {
    /// The titles upstream's `find_open_applications` lists.
    ///
    /// # Errors
    ///
    /// The window listing failed.
    fn window_titles(&mut self) -> HostResult<Vec<String>> {
        Ok(window_names(&self.windows()?))
    }

    /// The foreground window's title as `pyautogui.getActiveWindowTitle()` gives it
    /// (`""` when no window is in front).
    ///
    /// # Errors
    ///
    /// The window listing failed.
    fn active_window_title(&mut self) -> HostResult<String> {
        Ok(foreground(&self.windows()?).map(|w| w.title.clone()).unwrap_or_default())
    }

    /// Restores, maximises and brings to the front the topmost visible window titled `title`.
    ///
    /// # Errors
    ///
    /// No visible window has that title, or a primitive failed.
    fn switch_to_window(&mut self, title: &str) -> HostResult<()> {
        let mut windows = self.windows()?;
        windows.sort_by_key(|w| w.z_order);
        let id = windows
            .iter()
            .find(|w| w.visible && w.title == title)
            .map(|w| w.id)
            .ok_or_else(|| format!("no visible window is titled {title:?}"))?;
        self.change_window(id, WindowChange::Restore)?;
        self.change_window(id, WindowChange::Maximize)?;
        self.change_window(id, WindowChange::Activate)
    }

    /// Maximises the foreground window; nothing when no window is in front.
    ///
    /// # Errors
    ///
    /// A primitive failed.
    fn maximize_foreground(&mut self) -> HostResult<()> {
        match foreground(&self.windows()?).map(|w| w.id) {
            Some(id) => self.change_window(id, WindowChange::Maximize),
            None => Ok(()),
        }
    }

    /// Starts `name` if it is installed and says whether it was.
    ///
    /// # Errors
    ///
    /// A name with shell syntax in it, or a primitive failed (other than the program
    /// not existing, which is `Ok(false)`).
    fn open_program(&mut self, name: &str) -> HostResult<bool> {
        if name.trim().is_empty() || name.contains(SHELL_SYNTAX) {
            return Err(format!("{name:?} is not a program name").into());
        }
        let mut registered = false;
        for key in APP_PATHS {
            // Upstream's `if executable:`: the key's default value names the program.
            let value = self.registry_read(&format!(r"{key}\{name}.exe"), None)?;
            if value.is_some_and(|v| v != RegistryValue::String(String::new())) {
                registered = true;
                break;
            }
        }
        if registered {
            // Upstream's `os.system(f"start {program}")`, whose status it ignores.
            self.launch(&CommandSpec::Shell(format!("start {name}")))?;
            return Ok(true);
        }
        Ok(self.launch(&CommandSpec::Argv(vec![name.to_owned()]))?.is_some())
    }

    /// `platform.version()`, for example `10.0.22631`.
    ///
    /// # Errors
    ///
    /// A version value is missing or not a number, or the registry could not be read.
    fn os_version(&mut self) -> HostResult<String> {
        let mut parts = Vec::with_capacity(VERSION_VALUES.len());
        for value in VERSION_VALUES {
            let not_a_number = |shown: String| format!(r"{CURRENT_VERSION}\{value} is not a number: {shown}");
            let number =
                match self.registry_read(CURRENT_VERSION, Some(value))? {
                    Some(RegistryValue::Dword(n)) => u64::from(n),
                    Some(RegistryValue::Qword(n)) => n,
                    Some(RegistryValue::String(s)) => {
                        s.trim().parse::<u64>().map_err(|_| not_a_number(format!("{s:?}")))?
                    }
                    Some(other) => return Err(not_a_number(format!("{other:?}")).into()),
                    None => return Err(format!(
                        r"the Windows version is not recorded on this desktop: {CURRENT_VERSION}\{value} does not exist"
                    )
                    .into()),
                };
            parts.push(number.to_string());
        }
        Ok(parts.join("."))
    }

    /// Captures the screen (or `region` as left, top, width, height) and saves it at
    /// `path` as Pillow's `save` would, in `format` or the one the extension names.
    ///
    /// # Errors
    ///
    /// An unknown format or extension, a missing folder, a region Pillow refuses, or a
    /// primitive failed.
    fn save_screenshot(&mut self, path: &str, region: Option<[i32; 4]>, format: Option<&str>) -> HostResult<()> {
        let format = pillow_format(path, format)?;
        let folder = ntpath::dirname(path);
        if !folder.is_empty() && self.path_kind(folder) != Some(PathKind::Dir) {
            return Err(format!("[Errno 2] No such file or directory: '{path}'").into());
        }
        let image = self.capture()?;
        let image = match region {
            None => image,
            Some([left, top, width, height]) => {
                let (l, t) = (i64::from(left), i64::from(top));
                crop(&image, [l, t, l + i64::from(width), t + i64::from(height)])?
            }
        };
        let bytes = encode(&image, format, PILLOW_JPEG_QUALITY).map_err(|err| format!("{path}: {err}"))?;
        self.write_file(path, bytes)
    }

    /// Puts the crop `[x1, y1, x2, y2]` of the observed screenshot on the clipboard.
    ///
    /// # Errors
    ///
    /// There is no observed screenshot, the box is inverted or too large, or a primitive failed.
    fn copy_image(&mut self, rect: [i32; 4]) -> HostResult<()> {
        let image = crop(&self.observed_screenshot()?, rect.map(i64::from))?;
        self.clipboard_set_image(image)
    }

    /// `subprocess.run(cmd, shell=shell)` (and `call`, `os.system`) to completion.
    ///
    /// # Errors
    ///
    /// The primitive failed.
    fn run_command(&mut self, cmd: &CommandArg, shell: bool) -> HostResult<CommandOutput> {
        self.run(&subprocess_command(cmd, shell))
    }

    /// `subprocess.Popen(cmd, shell=shell)` (and `os.startfile`): starts it and gives its pid.
    ///
    /// # Errors
    ///
    /// Python's `FileNotFoundError` text when the program does not exist, or the primitive failed.
    fn spawn_command(&mut self, cmd: &CommandArg, shell: bool) -> HostResult<u32> {
        self.launch(&subprocess_command(cmd, shell))?.ok_or_else(|| HostError::Failed(PROGRAM_NOT_FOUND.to_owned()))
    }
}

impl<H: ScriptHost + ?Sized> Composed for H {}

/// Python's `FileNotFoundError` text when `CreateProcess` cannot find a program.
pub const PROGRAM_NOT_FOUND: &str = "[WinError 2] The system cannot find the file specified";

/// The window Windows reports in front.
fn foreground(windows: &[WindowInfo]) -> Option<&WindowInfo> {
    windows.iter().find(|w| w.focused)
}

fn crop(image: &RgbaImage, [x1, y1, x2, y2]: [i64; 4]) -> HostResult<RgbaImage> {
    crop_padded(image, x1, y1, x2, y2).map_err(|err| HostError::Failed(err.to_string()))
}

/// The format Pillow's `save` writes: `format` when given (any case), else the one the
/// file's extension names; Pillow's `ValueError` text when it knows neither.
pub fn pillow_format(path: &str, format: Option<&str>) -> HostResult<ImageFormat> {
    const ENCODED: &str = "this project saves screenshots as PNG or JPEG";
    if let Some(format) = format {
        return match format.to_ascii_uppercase().as_str() {
            "PNG" => Ok(ImageFormat::Png),
            "JPEG" | "JPG" => Ok(ImageFormat::Jpeg),
            _ => Err(format!("unknown file format: {format} ({ENCODED})").into()),
        };
    }
    let (_, ext) = ntpath::splitext(path);
    match ext.to_ascii_lowercase().as_str() {
        ".png" => Ok(ImageFormat::Png),
        ".jpg" | ".jpeg" | ".jpe" | ".jfif" => Ok(ImageFormat::Jpeg),
        _ => Err(format!("unknown file extension: {ext} ({ENCODED})").into()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_format_follows_the_argument_then_the_extension_as_in_pillow() {
        assert_eq!(pillow_format(r"C:\a\b.PNG", None), Ok(ImageFormat::Png));
        assert_eq!(pillow_format("x.jpeg", None), Ok(ImageFormat::Jpeg));
        assert_eq!(pillow_format("x.jfif", None), Ok(ImageFormat::Jpeg));
        assert_eq!(pillow_format("x.png", Some("jpeg")), Ok(ImageFormat::Jpeg));
        let err = pillow_format("x.bmp", None).expect_err("bmp is not encoded here");
        assert!(err.to_string().starts_with("unknown file extension: .bmp"), "{err}");
        let err = pillow_format(r"C:\dir.d\shot", None).expect_err("no extension");
        assert!(err.to_string().starts_with("unknown file extension:  ("), "{err}");
        assert!(pillow_format("x.png", Some("TIFF")).is_err());
    }
}
