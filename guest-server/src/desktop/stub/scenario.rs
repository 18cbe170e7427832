//! The scenario file format that seeds the stub desktop, and its loader.
//!
//! A scenario is our own JSON format (so unknown keys are errors, unlike task
//! files). Every field is optional; an empty object `{}` is the default desktop.
//!
//! | field | type | meaning |
//! |---|---|---|
//! | `screen` | `{width, height}` | screen size in pixels; overrides the server's `--screen` |
//! | `cursor` | `{x, y}` | initial cursor position (default: the screen centre) |
//! | `windows` | list of [`ScenarioWindow`] | open windows, **first = topmost**; Program Manager is always added at the bottom |
//! | `files` | map guest path → content | files to create: a string is written as UTF-8, `{"base64": "..."}` as bytes; parents are created |
//! | `dirs` | list of guest paths | folders to create |
//! | `clipboard` | string | initial clipboard text |
//! | `registry` | list of [`ScenarioRegistryValue`] | registry values to write (`{key, value?, data}`; `data` is an `arena_shared::registry::RegistryValue` such as `{"type": "dword", "data": 1}`) |
//! | `wallpaper` | guest path | the wallpaper (`HKCU\Control Panel\Desktop` `Wallpaper`); the file may be created by `files` |
//! | `programs` | map name → [`ScenarioProgram`] | programs `spawn` and `open_path` know, by lower-case name without `.exe`; they override the built-in ones |
//! | `associations` | map `.ext` → program name | which program `open_path` uses for an extension; overrides the built-in ones |
//! | `env` | map name → value | environment variables; override the built-in ones (names are case-insensitive) |
//! | `acls` | map guest folder → map user → mask | access masks `directory_access_mask` reports instead of deriving one |
//! | `uia_empty_until_recreated` | bool | UI Automation answers empty trees until the automation client is re-created (the health stage does that), as reported after a snapshot restore |
//! | `uia_empty` | bool | UI Automation answers empty trees even after it is re-created (the health stage reports it down) |
//!
//! A window ([`ScenarioWindow`]) has `title` (required), `class_name`, `process_name`,
//! `rect` `{x, y, width, height}`, `text` (its document), `file` (guest path `ctrl+s` saves
//! the document to), `visible` (default true), `minimized`, `maximized`, `focused` (at most
//! one; default: the topmost visible, non-minimised window), `refuse_close` (the window stays
//! on `close_window` and `alt+f4`, modelling an unsaved-changes prompt) and `elements`
//! (accessibility subtrees, `arena_shared::observation::A11yNode` JSON, shown under the window).
//! What the trees see of it, through the same walker and root filter as the Windows backend:
//! `bulk_fetch_ms` (UI Automation's whole-subtree fetch of the window takes this long, and
//! fails as a UIA timeout does when that is more than the time it is offered),
//! `bulk_fetch_hangs` (the fetch ignores its timeout and runs its whole `bulk_fetch_ms`, as
//! a provider kept busy does: the walk abandons it and reads element by element at once), `element_ms`
//! (each element read one by one takes this long), `tool_window` (`WS_EX_TOOLWINDOW`: left
//! out of the trees unless it belongs to the foreground window's process), `popup` (a popup
//! menu or drop-down owned by another window: class `#32768` unless `class_name` says
//! otherwise, `WS_POPUP`, topmost, never focused, its `elements` are its items) and
//! `cloaked` (DWM hides it: never drawn, clicked or walked).
//!
//! A program ([`ScenarioProgram`]) has `title` (required), `class_name`, `process_name`,
//! `text` (initial document; `null` for a window without one) and `app_name` (the suffix of
//! `"<file> - <app_name>"` titles when the program opens a file; default: the part of `title`
//! after its last `" - "`).
//!
//! This module only parses and validates; [`super::StubDesktop::with_config`] applies a scenario.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use arena_shared::geometry::{Point, Rect};
use arena_shared::observation::A11yNode;
use arena_shared::registry::RegistryValue;
use base64::Engine as _;
use serde::Deserialize;

/// A scenario seeding the stub: see the module documentation for every field.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    #[serde(default)]
    pub screen: Option<ScenarioScreen>,
    #[serde(default)]
    pub cursor: Option<Point>,
    #[serde(default)]
    pub windows: Vec<ScenarioWindow>,
    #[serde(default)]
    pub files: BTreeMap<String, FileContent>,
    #[serde(default)]
    pub dirs: Vec<String>,
    #[serde(default)]
    pub clipboard: Option<String>,
    #[serde(default)]
    pub registry: Vec<ScenarioRegistryValue>,
    #[serde(default)]
    pub wallpaper: Option<String>,
    #[serde(default)]
    pub programs: BTreeMap<String, ScenarioProgram>,
    #[serde(default)]
    pub associations: BTreeMap<String, String>,
    #[serde(default)]
    pub env: BTreeMap<String, String>,
    #[serde(default)]
    pub acls: BTreeMap<String, BTreeMap<String, u32>>,
    #[serde(default)]
    pub uia_empty_until_recreated: bool,
    #[serde(default)]
    pub uia_empty: bool,
}

/// Screen size in physical pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScenarioScreen {
    pub width: u32,
    pub height: u32,
}

/// One window of a scenario.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScenarioWindow {
    pub title: String,
    #[serde(default)]
    pub class_name: String,
    /// Default: `app.exe`.
    #[serde(default)]
    pub process_name: Option<String>,
    /// Default: a cascade position.
    #[serde(default)]
    pub rect: Option<Rect>,
    #[serde(default)]
    pub text: Option<String>,
    #[serde(default)]
    pub file: Option<String>,
    #[serde(default = "yes")]
    pub visible: bool,
    #[serde(default)]
    pub minimized: bool,
    #[serde(default)]
    pub maximized: bool,
    #[serde(default)]
    pub focused: bool,
    #[serde(default)]
    pub refuse_close: bool,
    #[serde(default)]
    pub elements: Vec<A11yNode>,
    #[serde(default)]
    pub bulk_fetch_ms: u64,
    #[serde(default)]
    pub bulk_fetch_hangs: bool,
    #[serde(default)]
    pub element_ms: u64,
    #[serde(default)]
    pub tool_window: bool,
    #[serde(default)]
    pub popup: bool,
    #[serde(default)]
    pub cloaked: bool,
}

fn yes() -> bool {
    true
}

/// The longest modelled UI Automation delay (`bulk_fetch_ms`, `element_ms`): a minute.
const MAX_MODEL_MS: u64 = 60_000;

/// Content of a seeded file.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(untagged)]
pub enum FileContent {
    /// Written as UTF-8.
    Text(String),
    /// Written as the decoded bytes.
    Base64 { base64: String },
}

impl FileContent {
    /// The bytes to write.
    ///
    /// # Errors
    ///
    /// The base64 decoder's message for invalid base64.
    pub fn bytes(&self) -> Result<Vec<u8>, String> {
        match self {
            FileContent::Text(text) => Ok(text.as_bytes().to_vec()),
            FileContent::Base64 { base64 } => base64::engine::general_purpose::STANDARD
                .decode(base64.trim())
                .map_err(|err| format!("invalid base64: {err}")),
        }
    }
}

/// One registry value of a scenario.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScenarioRegistryValue {
    pub key: String,
    /// `None` is the key's default value.
    #[serde(default)]
    pub value: Option<String>,
    pub data: RegistryValue,
}

/// A program the stub can start without a real process.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScenarioProgram {
    pub title: String,
    #[serde(default)]
    pub class_name: String,
    /// Default: `<name>.exe`.
    #[serde(default)]
    pub process_name: Option<String>,
    #[serde(default)]
    pub text: Option<String>,
    #[serde(default)]
    pub app_name: Option<String>,
}

/// A scenario file could not be used.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ScenarioError {
    /// The file could not be read.
    #[error("reading scenario {}: {source}", path.display())]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The JSON does not match the format; `at` is the path of the offending element.
    #[error("scenario {origin}: at `{at}`: {message}")]
    Parse { origin: String, at: String, message: String },
    /// The JSON parsed but a value is unusable.
    #[error("scenario {origin}: {message}")]
    Invalid { origin: String, message: String },
}

impl Scenario {
    /// Loads and validates a scenario file.
    ///
    /// # Errors
    ///
    /// [`ScenarioError::Read`] for an unreadable file, [`ScenarioError::Parse`] naming the
    /// element path, line and column of a format error, [`ScenarioError::Invalid`] for a
    /// value that parses but cannot be used (a relative guest path, bad base64, two focused windows).
    pub fn load(path: &Path) -> Result<Scenario, ScenarioError> {
        let text =
            std::fs::read_to_string(path).map_err(|source| ScenarioError::Read { path: path.to_path_buf(), source })?;
        Scenario::parse(&text, &path.display().to_string())
    }

    /// Parses and validates scenario JSON; `origin` names it in errors.
    ///
    /// # Errors
    ///
    /// As [`Scenario::load`], minus reading.
    pub fn parse(text: &str, origin: &str) -> Result<Scenario, ScenarioError> {
        let mut de = serde_json::Deserializer::from_str(text);
        let scenario: Scenario = serde_path_to_error::deserialize(&mut de).map_err(|err| {
            let at = err.path().to_string();
            ScenarioError::Parse { origin: origin.to_owned(), at, message: err.into_inner().to_string() }
        })?;
        de.end().map_err(|err| ScenarioError::Parse {
            origin: origin.to_owned(),
            at: ".".into(),
            message: err.to_string(),
        })?;
        scenario.validate().map_err(|message| ScenarioError::Invalid { origin: origin.to_owned(), message })?;
        Ok(scenario)
    }

    /// Checks what serde cannot: guest paths, base64, sizes and the single focus.
    fn validate(&self) -> Result<(), String> {
        let check_path = |what: &str, p: &str| {
            super::fs::guest_components(p).map(|_| ()).map_err(|err| format!("{what} {p:?}: {err}"))
        };
        if let Some(screen) = self.screen {
            if !(64..=16384).contains(&screen.width) || !(64..=16384).contains(&screen.height) {
                return Err(format!(
                    "screen {}x{} is out of range (64 to 16384 pixels a side)",
                    screen.width, screen.height
                ));
            }
        }
        for (path, content) in &self.files {
            check_path("files:", path)?;
            content.bytes().map_err(|err| format!("files: {path:?}: {err}"))?;
        }
        for dir in &self.dirs {
            check_path("dirs:", dir)?;
        }
        if let Some(wallpaper) = &self.wallpaper {
            check_path("wallpaper:", wallpaper)?;
        }
        for path in self.acls.keys() {
            check_path("acls:", path)?;
        }
        for (i, window) in self.windows.iter().enumerate() {
            if let Some(file) = &window.file {
                check_path(&format!("windows[{i}].file:"), file)?;
            }
            if let Some(rect) = window.rect {
                if rect.width <= 0 || rect.height <= 0 {
                    return Err(format!("windows[{i}] ({:?}): rect must have a positive size", window.title));
                }
            }
            for (field, ms) in [("bulk_fetch_ms", window.bulk_fetch_ms), ("element_ms", window.element_ms)] {
                if ms > MAX_MODEL_MS {
                    return Err(format!(
                        "windows[{i}] ({:?}): {field} {ms} is more than {MAX_MODEL_MS} ms",
                        window.title
                    ));
                }
            }
            if window.popup && window.focused {
                return Err(format!("windows[{i}] ({:?}): a popup is never focused", window.title));
            }
        }
        let focused = self.windows.iter().filter(|w| w.focused).count();
        if focused > 1 {
            return Err(format!("{focused} windows say focused: true; at most one may"));
        }
        for (i, value) in self.registry.iter().enumerate() {
            super::registry::normalize_key(&value.key).map_err(|err| format!("registry[{i}]: {err}"))?;
            if value.data == RegistryValue::Unknown {
                return Err(format!("registry[{i}] ({}): unknown value type", value.key));
            }
        }
        for (ext, program) in &self.associations {
            if !ext.starts_with('.') {
                return Err(format!("associations: {ext:?} must start with a dot"));
            }
            if program.trim().is_empty() {
                return Err(format!("associations: {ext:?} names no program"));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn example_path() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios").join("example.json")
    }

    #[test]
    fn the_example_scenario_loads() {
        let scenario = Scenario::load(&example_path()).unwrap();
        assert!(scenario.windows.len() >= 2);
        assert!(!scenario.files.is_empty());
        assert!(!scenario.registry.is_empty());
        assert!(scenario.wallpaper.is_some());
        assert!(!scenario.programs.is_empty());
        assert!(!scenario.acls.is_empty());
    }

    #[test]
    fn an_empty_object_is_the_default() {
        assert_eq!(Scenario::parse("{}", "t").unwrap(), Scenario::default());
    }

    fn check_error(json: &str, needles: &[&str]) {
        let err = Scenario::parse(json, "test.json").unwrap_err().to_string();
        for needle in needles {
            assert!(err.contains(needle), "error {err:?} lacks {needle:?}");
        }
    }

    #[test]
    fn errors_name_the_origin_the_element_and_the_line() {
        check_error(r#"{"windows": [{"title": "a", "titel": "b"}]}"#, &["test.json", "windows[0]", "titel", "line 1"]);
        check_error("{\n  \"screen\": {\"width\": \"wide\", \"height\": 1}\n}", &["screen.width", "line 2"]);
        check_error(r#"{"files": {"relative\\a.txt": "x"}}"#, &["files:", "relative"]);
        check_error(r#"{"files": {"C:\\a.bin": {"base64": "!!"}}}"#, &["invalid base64"]);
        check_error(
            r#"{"windows": [{"title": "a", "focused": true}, {"title": "b", "focused": true}]}"#,
            &["at most one"],
        );
        check_error(
            r#"{"registry": [{"key": "HKXX\\a", "data": {"type": "dword", "data": 1}}]}"#,
            &["registry[0]", "HKXX"],
        );
        check_error(r#"{"associations": {"txt": "notepad"}}"#, &["dot"]);
        check_error("{} {}", &["trailing"]);
        check_error(r#"{"windows": [{"title": "a", "element_ms": 600000}]}"#, &["windows[0]", "element_ms", "60000"]);
        check_error(r#"{"windows": [{"title": "m", "popup": true, "focused": true}]}"#, &["popup is never focused"]);
        check_error(r#"{"windows": [{"title": "a", "bulk_fetch_ms": -1}]}"#, &["windows[0].bulk_fetch_ms"]);
    }

    #[test]
    fn a_missing_file_names_its_path() {
        let err = Scenario::load(Path::new("/no/such/scenario.json")).unwrap_err().to_string();
        assert!(err.contains("/no/such/scenario.json"), "{err}");
    }

    #[test]
    fn file_content_decodes_text_and_base64() {
        let s = Scenario::parse(r#"{"files": {"C:\\a.txt": "hi", "C:\\b.bin": {"base64": "AAEC"}}}"#, "t").unwrap();
        assert_eq!(s.files["C:\\a.txt"].bytes().unwrap(), b"hi");
        assert_eq!(s.files["C:\\b.bin"].bytes().unwrap(), vec![0, 1, 2]);
    }
}
