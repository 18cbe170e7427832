//! The stub backend: a deterministic, in-memory, Windows-like desktop.
//!
//! It is good enough to run real benchmark episodes in tests and on machines
//! without Windows: windows with z-order, focus, title bars and text documents; a
//! rendered screen; mouse and keyboard input; a clipboard; guest paths mapped under a
//! root directory; a registry; known programs that open windows and real host
//! processes for everything else. It is not an emulator: programs have no behaviour
//! beyond their window and document, and nothing here runs Windows code.
//!
//! Determinism: no randomness; fake process ids count from 1000 and window ids from
//! `0x10010`. All mutable state sits behind one mutex, so calls from many threads
//! serialise.
//!
//! Layout: [`scenario`] (the seed file format), `window` (state, windows, documents),
//! `input` (actions), `render` (screenshots), `a11y` (accessibility trees), `fs` (path
//! mapping and the profile), `registry`, `process` (programs and real processes), `recorder`
//! (the input recorder's model: what its window would receive, written to its log).

mod a11y;
mod fs;
mod input;
mod process;
mod recorder;
mod registry;
mod render;
pub mod scenario;
mod window;

#[cfg(test)]
mod tests;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard};

use arena_shared::action::Action;
use arena_shared::files::KnownFolder;
use arena_shared::geometry::{CoordinateSpace, Point, Rect};
use arena_shared::health::Component;
use arena_shared::observation::{A11yBackend, A11yTree, MonitorInfo, ScreenInfo, TreeBudget, WindowInfo};
use arena_shared::registry::RegistryValue;

use self::process::Program;
pub use self::scenario::{Scenario, ScenarioError};
use self::window::{Listings, NewWindow, State, WallpaperCache, WindowModel};

/// The folder a bare `explorer` (and Win+E) opens: the user's own.
const EXPLORER_HOME: &str = r"C:\Users\Docker";
use super::{
    ClipboardData, CommandSpec, Desktop, DesktopError, DesktopResult, ExecLimits, ExecOutput, Frame, WindowState,
};
use crate::desktop::windows::target;

/// Files larger than this open without their text in the window.
const MAX_DOCUMENT_BYTES: u64 = 1024 * 1024;

/// How to start the stub.
#[derive(Debug, Clone)]
pub struct StubConfig {
    /// Directory the guest drives live under; `None` makes a temporary one owned by the stub.
    pub root: Option<PathBuf>,
    /// Screen size in pixels (a scenario's `screen` wins).
    pub screen: (u32, u32),
    pub scenario: Option<Scenario>,
    /// Whether a command that is none of the simulated programs runs as a real
    /// host process (`--stub-host-exec`); off, it is refused ([`process::refusal`]).
    pub host_exec: bool,
    /// When the modelled shell shows its taskbar, after the stub starts
    /// (`--stub-shell-after-ms`); the CPU counts as busy until then.
    pub shell_after: std::time::Duration,
}

impl Default for StubConfig {
    fn default() -> StubConfig {
        StubConfig {
            root: None,
            screen: (1440, 900),
            scenario: None,
            host_exec: false,
            shell_after: std::time::Duration::ZERO,
        }
    }
}

/// The stub desktop. See the module documentation.
#[derive(Debug)]
pub struct StubDesktop {
    root: PathBuf,
    /// Keeps a temporary root alive as long as the stub.
    _temp: Option<tempfile::TempDir>,
    /// Environment, by upper-case name: (name as written, value).
    env: BTreeMap<String, (String, String)>,
    programs: BTreeMap<String, Program>,
    associations: BTreeMap<String, String>,
    /// Folded guest folder -> upper-case user -> mask.
    acls: BTreeMap<String, BTreeMap<String, u32>>,
    state: Mutex<State>,
    /// The modelled UI Automation client's faults and re-creations.
    uia: Mutex<a11y::UiaModel>,
    /// Real host processes allowed (`StubConfig::host_exec`).
    host_exec: bool,
    /// The input recorder, while its window is open.
    recorder: Mutex<Option<recorder::Model>>,
    /// The modelled wall clock: this process's clock plus this offset, which
    /// `set_system_time` changes. In the stand-in VM the process's own clock is
    /// the VM's, which a snapshot restore puts back, as Windows' is.
    clock_offset_ms: std::sync::atomic::AtomicI64,
    /// When the stub started, and when its shell shows (the `shell` component's model).
    started: std::time::Instant,
    shell_after: std::time::Duration,
}

impl StubDesktop {
    /// A 1440x900 desktop with only Program Manager, its drives under `root`.
    ///
    /// # Errors
    ///
    /// The I/O error of creating the user profile under `root`.
    pub fn new(root: PathBuf) -> DesktopResult<StubDesktop> {
        StubDesktop::with_config(StubConfig { root: Some(root), ..StubConfig::default() })
    }

    /// A desktop set up from `config` and its scenario.
    ///
    /// # Errors
    ///
    /// [`DesktopError::InvalidInput`] for an unusable screen size or scenario value, and
    /// the I/O errors of creating the root, the profile and the scenario's files.
    pub fn with_config(config: StubConfig) -> DesktopResult<StubDesktop> {
        let scenario = config.scenario.unwrap_or_default();
        let (temp, root) = match config.root {
            Some(root) => {
                std::fs::create_dir_all(&root)
                    .map_err(|err| DesktopError::io("creating the stub root", &root.display().to_string(), err))?;
                (None, root)
            }
            None => {
                let temp = tempfile::Builder::new()
                    .prefix("arena-stub-")
                    .tempdir()
                    .map_err(|err| DesktopError::io("creating the stub root", "a temporary directory", err))?;
                let root = temp.path().to_path_buf();
                (Some(temp), root)
            }
        };
        // Canonical, so that unmapping paths the OS hands back (resolved symlinks) works.
        let root = root
            .canonicalize()
            .map_err(|err| DesktopError::io("resolving the stub root", &root.display().to_string(), err))?;
        let screen = scenario.screen.map_or(config.screen, |s| (s.width, s.height));
        if !(64..=16384).contains(&screen.0) || !(64..=16384).contains(&screen.1) {
            return Err(DesktopError::InvalidInput(format!(
                "screen {}x{} is out of range (64 to 16384 pixels a side)",
                screen.0, screen.1
            )));
        }
        fs::create_profile(&root)?;

        let mut env: BTreeMap<String, (String, String)> =
            fs::default_env().into_iter().map(|(k, v)| (k.to_uppercase(), (k, v))).collect();
        for (k, v) in &scenario.env {
            env.insert(k.to_uppercase(), (k.clone(), v.clone()));
        }
        let mut programs = process::default_programs();
        for (name, program) in &scenario.programs {
            let key = process::program_key(name);
            programs.insert(key.clone(), Program::from_scenario(&key, program));
        }
        let mut associations = process::default_associations();
        for (ext, program) in &scenario.associations {
            associations.insert(ext.to_lowercase(), process::program_key(program));
        }
        let mut acls = BTreeMap::new();
        for (path, users) in &scenario.acls {
            let key = fold_guest(path)?;
            acls.insert(key, users.iter().map(|(u, m)| (u.to_uppercase(), *m)).collect());
        }

        let uia = a11y::UiaModel::new(scenario.uia_empty_until_recreated, scenario.uia_empty);
        let stub = StubDesktop {
            root,
            _temp: temp,
            env,
            programs,
            associations,
            acls,
            state: Mutex::new(State::new(screen)),
            uia: Mutex::new(uia),
            host_exec: config.host_exec,
            recorder: Mutex::new(None),
            clock_offset_ms: std::sync::atomic::AtomicI64::new(0),
            started: std::time::Instant::now(),
            shell_after: config.shell_after,
        };
        stub.apply_scenario(&scenario)?;
        Ok(stub)
    }

    fn apply_scenario(&self, scenario: &Scenario) -> DesktopResult<()> {
        for dir in &scenario.dirs {
            let local = self.map_path(dir)?;
            std::fs::create_dir_all(&local).map_err(|err| DesktopError::io("creating a scenario folder", dir, err))?;
        }
        for (path, content) in &scenario.files {
            let local = self.map_path(path)?;
            let bytes = content.bytes().map_err(|err| DesktopError::InvalidInput(format!("{path}: {err}")))?;
            if let Some(parent) = local.parent() {
                std::fs::create_dir_all(parent)
                    .map_err(|err| DesktopError::io("creating a scenario folder", path, err))?;
            }
            std::fs::write(&local, bytes).map_err(|err| DesktopError::io("writing a scenario file", path, err))?;
        }
        let mut state = self.lock();
        if let Some(cursor) = scenario.cursor {
            state.cursor = state.clamp(cursor);
        }
        if let Some(text) = &scenario.clipboard {
            state.clipboard = ClipboardData::Text(text.clone());
        }
        for value in &scenario.registry {
            state.registry.write(&value.key, value.value.as_deref(), &value.data)?;
        }
        if let Some(wallpaper) = &scenario.wallpaper {
            state.registry.write(
                registry::DESKTOP_KEY,
                Some(registry::WALLPAPER_VALUE),
                &RegistryValue::String(wallpaper.clone()),
            )?;
        }
        // Windows are listed topmost first; opening each on top means opening them in reverse.
        let mut pids: BTreeMap<String, u32> = BTreeMap::new();
        pids.insert("explorer.exe".into(), state.windows[state.windows.len() - 1].pid);
        let mut focused = None;
        let mut ids = Vec::new();
        for spec in &scenario.windows {
            let process_name = spec.process_name.clone().unwrap_or_else(|| "app.exe".into());
            // Windows of one process share its pid, as File Explorer windows share explorer.exe.
            let pid = match pids.get(&process_name.to_lowercase()) {
                Some(pid) => *pid,
                None => {
                    let pid = state.alloc_pid();
                    pids.insert(process_name.to_lowercase(), pid);
                    pid
                }
            };
            let file = match &spec.file {
                Some(f) => Some(self.map_path(f)?),
                None => None,
            };
            ids.push((spec, pid, process_name, file));
        }
        for (spec, pid, process_name, file) in ids.into_iter().rev() {
            let id = state.open(NewWindow {
                title: spec.title.clone(),
                class_name: spec.class_name.clone(),
                process_name,
                pid: Some(pid),
                rect: spec.rect,
                text: spec.text.clone(),
                file,
                folder: None,
                elements: spec.elements.clone(),
                refuse_close: spec.refuse_close,
                dialog: None,
            });
            let work = state.work_area();
            if let Some(window) = state.window_mut(id) {
                window.model = WindowModel {
                    tool_window: spec.tool_window,
                    popup: spec.popup,
                    cloaked: spec.cloaked,
                    bulk_fetch_ms: spec.bulk_fetch_ms,
                    bulk_fetch_hangs: spec.bulk_fetch_hangs,
                    element_ms: spec.element_ms,
                };
                if spec.popup && window.class_name.is_empty() {
                    window.class_name = "#32768".into();
                }
                window.visible = spec.visible;
                window.minimized = spec.minimized;
                if spec.maximized {
                    window.maximized = true;
                    window.rect = work;
                }
            }
            if spec.focused {
                focused = Some(id);
            }
        }
        match focused {
            Some(id) => state.focus = id,
            None => state.refocus(),
        }
        Ok(())
    }

    fn uia_model(&self) -> MutexGuard<'_, a11y::UiaModel> {
        self.uia.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// How often the modelled UI Automation client was re-created (by the health stage).
    pub fn uia_recreations(&self) -> u32 {
        self.uia_model().recreations
    }

    fn lock(&self) -> MutexGuard<'_, State> {
        // A panic elsewhere while holding the lock leaves plain data behind; keep serving it.
        self.state.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// The directory the guest drives live under (`<root>/C` is `C:\`).
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// The actions performed most recently, oldest first (the last
    /// 1000, with long typed texts shortened).
    pub fn action_log(&self) -> Vec<Action> {
        self.lock().log.iter().cloned().collect()
    }

    /// Types `text` one character at a time with `pause` between, as pyautogui's
    /// `write(interval=...)` does. The desktop is locked for one character at a time, so
    /// other calls (health, screenshots) go on meanwhile, and the typing stops at once
    /// when its call is cancelled.
    fn type_slowly(&self, action: &Action, text: &str, pause: std::time::Duration) -> DesktopResult<()> {
        self.lock().record(action);
        for (i, c) in text.chars().enumerate() {
            if i > 0 {
                super::cancel::sleep(pause)?;
            }
            let one = Action::TypeText { text: c.to_string(), interval_ms: None };
            let effects = self.perform_locked(&mut self.lock(), &one)?;
            self.apply_effects(effects)?;
        }
        Ok(())
    }

    /// Does what input asked of the rest of the desktop, with the state unlocked.
    fn apply_effects(&self, effects: Vec<window::Effect>) -> DesktopResult<()> {
        for effect in effects {
            match effect {
                window::Effect::OpenDesktopItem(n) => {
                    if let Some(name) = self.desktop_items().get(n) {
                        self.open_path(&format!(r"C:\Users\Docker\Desktop\{name}"))?;
                    }
                }
                window::Effect::Launch(line) => {
                    if self.launch_modelled(&CommandSpec::Shell(line.clone()))?.is_none() {
                        return Err(DesktopError::NotFound(format!("program {line} not found")));
                    }
                }
                window::Effect::RunDialog { dialog, line } => self.run_dialog(dialog, &line),
            }
        }
        Ok(())
    }

    /// The Run dialog's OK: the line goes through the stub's launch path
    /// ([`StubDesktop::launch_modelled`]), and a line that names a guest path opens it
    /// even with spaces and no quotes, as the shell takes the whole line for a path
    /// first. What starts closes the dialog. A line that names nothing the stub models
    /// (it starts no real host process from typed text) gets a message box naming it,
    /// titled with the line, as Windows answers; the dialog stays open behind it.
    fn run_dialog(&self, dialog: u64, line: &str) {
        let whole = line.trim().trim_matches('"');
        let as_path = self.map_path(whole).ok().filter(|local| is_drive_path(whole) && local.exists());
        let started = match as_path {
            Some(_) => self.open_path(whole).map(|()| true),
            None => self.launch_modelled(&CommandSpec::Shell(line.to_owned())).map(|pid| pid.is_some()),
        };
        let mut state = self.lock();
        state.run_mru = Some(line.to_owned());
        match started {
            Ok(true) => {
                // The dialog is still listed: nothing else closes it while the state is unlocked
                // but a caller closing it by id, and then there is nothing left to close.
                let _ = state.close(dialog);
            }
            Ok(false) => {
                let name = process::tokenize(line).first().map_or_else(|| line.to_owned(), |t| t.text.clone());
                let message = format!("Windows cannot find '{name}'. Check the name, then try again.");
                state.open_message_box(line, &message);
            }
            Err(err) => {
                state.open_message_box(line, &err.to_string());
            }
        }
    }

    /// Starts what a command line names when the stub models it: a guest document or
    /// folder (`start "" C:\...\a.txt`), or a known program with its arguments. This is
    /// the one launch path of [`Desktop::run`], [`Desktop::spawn`], the Run dialog and
    /// `win+e`. `Ok(None)` when it names neither.
    fn launch_modelled(&self, cmd: &CommandSpec) -> DesktopResult<Option<u32>> {
        if let Some(path) = self.document_launch(cmd) {
            self.open_path(&path)?;
            return Ok(Some(self.lock().windows.first().map_or(0, |w| w.pid)));
        }
        if let Some(launch) = process::known_launch(cmd, &self.programs) {
            return self.launch_known(&launch.key, &launch.args).map(Some);
        }
        Ok(None)
    }

    /// The document text of a window, if it has one.
    pub fn window_text(&self, id: u64) -> Option<String> {
        self.lock().window(id).and_then(|w| w.text.as_ref()).map(|b| b.text.clone())
    }

    /// Whether [`Desktop::shutdown`] was called.
    pub fn shutdown_requested(&self) -> bool {
        self.lock().shutdown
    }

    /// The id of the first window, topmost first, whose title contains `needle` (ignoring case).
    pub fn find_window(&self, needle: &str) -> Option<u64> {
        let needle = needle.to_lowercase();
        self.lock().windows.iter().find(|w| w.title.to_lowercase().contains(&needle)).map(|w| w.id)
    }

    /// Starts the input recorder's model: its window over the work area, focused, and
    /// its log (the first argument, a guest path) begun with the `ready` line.
    fn launch_recorder(&self, program: &Program, args: &[String]) -> DesktopResult<u32> {
        let Some(log) = args.first() else {
            return Err(DesktopError::InvalidInput(format!("{} needs the log file to write", recorder::PROGRAM)));
        };
        let local = self.map_path(log)?;
        let mut state = self.lock();
        let rect = state.work_area();
        let id = state.open(NewWindow {
            title: program.title.clone(),
            class_name: program.class_name.clone(),
            process_name: program.process_name.clone(),
            rect: Some(rect),
            ..NewWindow::default()
        });
        let model = recorder::Model::start(id, local, &state)?;
        let pid = state.window(id).map_or(0, |w| w.pid);
        *self.recorder.lock().unwrap_or_else(std::sync::PoisonError::into_inner) = Some(model);
        Ok(pid)
    }

    /// One action on the locked desktop, and what the input recorder (when one is open)
    /// received from it.
    fn perform_locked(&self, state: &mut State, action: &Action) -> DesktopResult<Vec<window::Effect>> {
        let mut guard = self.recorder.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        if guard.as_ref().is_some_and(|model| state.window(model.window).is_none()) {
            *guard = None;
        }
        let records = match guard.as_mut() {
            Some(model) => model.observe(state, action)?,
            None => Vec::new(),
        };
        let effects = input::perform(state, action)?;
        if let Some(model) = guard.as_ref() {
            model.commit(&records)?;
        }
        Ok(effects)
    }

    /// Opens a known program's window; `args` may name a file or folder to open in it.
    fn launch_known(&self, key: &str, args: &[String]) -> DesktopResult<u32> {
        let Some(program) = self.programs.get(key) else {
            return Err(DesktopError::NotFound(format!("program {key} not found")));
        };
        if key == recorder::PROGRAM {
            return self.launch_recorder(program, args);
        }
        // The first argument that names an existing guest file or folder is opened in the program.
        let target = args.iter().filter(|a| !a.starts_with(['-', '/'])).find_map(|a| {
            let local = self.map_path(a).ok()?;
            local.exists().then_some((a.clone(), local))
        });
        let mut new = NewWindow {
            title: program.title.clone(),
            class_name: program.class_name.clone(),
            process_name: program.process_name.clone(),
            text: program.text.clone(),
            ..NewWindow::default()
        };
        let explorer = program.process_name.eq_ignore_ascii_case("explorer.exe");
        if explorer && target.is_none() {
            // Bare `explorer` (and Win+E): the user's folder, under the program's own title.
            new.folder = self.map_path(EXPLORER_HOME).ok().filter(|local| local.is_dir());
        }
        if let Some((guest, local)) = target {
            let name = display_name(&guest);
            if local.is_dir() {
                new.title = name;
                new.text = None;
                new.folder = Some(local);
            } else {
                new.title = format!("{name} - {}", program.app_name);
                new.text = read_document(&local);
                new.file = Some(local);
            }
        }
        let mut state = self.lock();
        // File Explorer windows belong to the shell's explorer.exe, as on Windows.
        if program.process_name.eq_ignore_ascii_case("explorer.exe") {
            new.pid = Some(state.shell_pid());
        }
        let id = state.open(new);
        let pid = state.window(id).map_or(0, |w| w.pid);
        tracing::debug!(program = key, pid, id, "stub opened a program window");
        Ok(pid)
    }

    /// A command whose first word is a guest document (`start "" C:\\...\\a.txt`): that path.
    fn document_launch(&self, cmd: &CommandSpec) -> Option<String> {
        let words = process::launch_words(cmd)?;
        let first = words.first()?;
        if words.len() != 1 || !is_drive_path(first) {
            return None;
        }
        let local = self.map_path(first).ok()?;
        local.exists().then(|| first.clone())
    }

    fn map_cwd(&self, limits: &ExecLimits) -> DesktopResult<Option<PathBuf>> {
        let Some(cwd) = &limits.cwd else {
            return Ok(None);
        };
        let local = self.map_path(cwd)?;
        if !local.is_dir() {
            return Err(DesktopError::NotFound(format!("working directory {cwd} not found")));
        }
        Ok(Some(local))
    }

    /// What the windows show of the file system: the desktop's icons and each File
    /// Explorer window's entries, read with the state unlocked.
    fn listings(&self) -> Listings {
        let folders: Vec<(u64, PathBuf)> =
            self.lock().windows.iter().filter_map(|w| w.folder.clone().map(|f| (w.id, f))).collect();
        let folders = folders
            .into_iter()
            .map(|(id, folder)| {
                let mut names = arena_shared::ntfs::list_dir(&folder).unwrap_or_default();
                names.truncate(window::EXPLORER_MAX_ITEMS);
                (id, names)
            })
            .collect();
        Listings { desktop: self.desktop_items(), folders }
    }

    /// Names in the Desktop folder, sorted, as the desktop icons show them.
    fn desktop_items(&self) -> Vec<String> {
        let Ok(dir) = self.map_path(r"C:\Users\Docker\Desktop") else {
            return Vec::new();
        };
        let mut names = arena_shared::ntfs::list_dir(&dir).unwrap_or_default();
        names.truncate(500);
        names
    }

    /// The wallpaper scaled to the screen, decoded once per file version and screen size.
    fn wallpaper_image(&self, state: &mut State) -> Option<image::RgbaImage> {
        let guest = match state.registry.read(registry::DESKTOP_KEY, Some(registry::WALLPAPER_VALUE)) {
            Ok(RegistryValue::String(s)) if !s.is_empty() => s,
            _ => return None,
        };
        let local = self.map_path(&guest).ok()?;
        let meta = std::fs::metadata(&local).ok()?;
        let key = (local.clone(), meta.len(), meta.modified().ok(), state.screen);
        if let Some(cache) = &state.wallpaper {
            if cache.key == key {
                return cache.image.clone();
            }
        }
        let image = std::fs::read(&local).ok().and_then(|bytes| match crate::imaging::decode(&bytes) {
            Ok(img) => Some(image::imageops::resize(&img, state.screen.0, state.screen.1, image::imageops::FilterType::Triangle)),
            Err(err) => {
                tracing::debug!(wallpaper = %guest, %err, "the wallpaper does not decode; drawing the plain background");
                None
            }
        });
        state.wallpaper = Some(WallpaperCache { key, image: image.clone() });
        image
    }

    fn render_frame(&self, draw_cursor: bool) -> Frame {
        let listings = self.listings();
        let mut state = self.lock();
        let wallpaper = self.wallpaper_image(&mut state);
        let mut image = render::render(&state, wallpaper.as_ref(), &listings);
        let cursor = state.cursor;
        drop(state);
        if draw_cursor {
            crate::imaging::draw_cursor(&mut image, cursor);
        }
        Frame { image, cursor: Some(cursor), cursor_drawn: draw_cursor }
    }
}

/// Whether `path` starts with a drive letter (`C:\\...`). Only those are guest paths a
/// command line opens: a Unix path such as /bin/echo is a host program.
fn is_drive_path(path: &str) -> bool {
    let bytes = path.as_bytes();
    bytes.len() >= 3 && bytes[0].is_ascii_alphabetic() && bytes[1] == b':'
}

/// The display name of a guest path: its last component, or `Local Disk (C:)` for a drive.
fn display_name(guest: &str) -> String {
    match fs::guest_components(guest) {
        Ok((_, parts)) if !parts.is_empty() => parts[parts.len() - 1].clone(),
        Ok((drive, _)) => format!("Local Disk ({drive}:)"),
        Err(_) => crate::paths::basename(guest).to_owned(),
    }
}

/// A file's text, when it is small and valid UTF-8 (a leading BOM dropped).
fn read_document(local: &Path) -> Option<String> {
    let meta = std::fs::metadata(local).ok()?;
    if meta.len() > MAX_DOCUMENT_BYTES {
        return None;
    }
    let bytes = std::fs::read(local).ok()?;
    let text = String::from_utf8(bytes).ok()?;
    Some(text.strip_prefix('\u{feff}').map(str::to_owned).unwrap_or(text))
}

/// A guest path folded for case-insensitive comparison: `c:/users/docker/x/` -> `c:\users\docker\x`.
fn fold_guest(path: &str) -> DesktopResult<String> {
    let (drive, parts) = fs::guest_components(path).map_err(DesktopError::InvalidInput)?;
    Ok(format!("{drive}:\\{}", parts.join("\\")).to_lowercase())
}

fn elapsed_note(started: std::time::Instant) -> String {
    format!("{} ms", started.elapsed().as_millis())
}

impl Desktop for StubDesktop {
    fn kind(&self) -> &'static str {
        "stub"
    }

    fn shell_sample(&self) -> DesktopResult<crate::desktop::settle::ShellSample> {
        use crate::desktop::settle::{CpuTimes, Front, ShellSample};
        // The model: a shell that starts for `shell_after` with the CPU busy, then
        // shows its taskbar and leaves the CPU idle. Times in microseconds.
        let up = self.started.elapsed();
        let total = u64::try_from(up.as_micros()).unwrap_or(u64::MAX);
        let busy = u64::try_from(up.min(self.shell_after).as_micros()).unwrap_or(u64::MAX);
        let front = {
            let state = self.lock();
            match state.window(state.focus).filter(|w| w.shown()) {
                Some(w) if !w.is_desktop => Front::Window(w.title.clone()),
                _ => Front::Desktop,
            }
        };
        Ok(ShellSample { taskbar: up >= self.shell_after, front, cpu: Some(CpuTimes { idle: total - busy, total }) })
    }

    fn probe(&self, component: Component) -> DesktopResult<String> {
        let started = std::time::Instant::now();
        match component {
            Component::Capture => {
                let frame = self.render_frame(false);
                let (w, h) = self.lock().screen;
                if (frame.image.width(), frame.image.height()) != (w, h) {
                    return Err(DesktopError::Os {
                        op: "probe capture",
                        message: format!("rendered {}x{}, expected {w}x{h}", frame.image.width(), frame.image.height()),
                    });
                }
                Ok(format!("rendered a {w}x{h} frame in {}", elapsed_note(started)))
            }
            Component::Input => {
                let p = self.cursor_position()?;
                Ok(format!("cursor at {},{}", p.x, p.y))
            }
            Component::Accessibility => {
                let tree = self.accessibility(A11yBackend::Win32, &TreeBudget::WAA, false)?;
                Ok(format!("walked {} windows, {} nodes", tree.windows.len(), tree.node_count))
            }
            Component::Uia => {
                // As on Windows: a window in front over a lit screen (the stub's is always lit).
                let in_front = {
                    let state = self.lock();
                    state.window(state.focus).filter(|w| !w.is_desktop && w.shown()).map(|w| w.title.clone())
                };
                let budget = crate::desktop::uia_health::HEALTH_BUDGET;
                crate::desktop::uia_health::check(
                    in_front.as_deref(),
                    &mut || self.accessibility(A11yBackend::Uia, &budget, true),
                    &mut || {
                        self.uia_model().recreate();
                        Ok(())
                    },
                )
            }
            Component::Clipboard => Ok(match self.clipboard_get()? {
                ClipboardData::Empty => "clipboard is empty".to_owned(),
                ClipboardData::Text(t) => format!("clipboard holds {} characters of text", t.chars().count()),
                ClipboardData::Image(img) => format!("clipboard holds a {}x{} image", img.width(), img.height()),
            }),
            Component::Files => {
                static PROBES: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
                let n = PROBES.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                let probe = self.root.join(format!(".arena-probe-{}-{n}", std::process::id()));
                let what = probe.display().to_string();
                std::fs::write(&probe, b"arena probe").map_err(|err| DesktopError::io("probe files", &what, err))?;
                let back = std::fs::read(&probe).map_err(|err| DesktopError::io("probe files", &what, err));
                let removed = std::fs::remove_file(&probe).map_err(|err| DesktopError::io("probe files", &what, err));
                if back? != b"arena probe" {
                    return Err(DesktopError::Os {
                        op: "probe files",
                        message: format!("{what} read back different bytes"),
                    });
                }
                removed?;
                Ok(format!("wrote, read back and deleted a file under {}", self.root.display()))
            }
            Component::Exec if !self.host_exec => {
                Ok("simulated programs only (host processes need --stub-host-exec)".to_owned())
            }
            Component::Exec => {
                let shell = target::SHELL;
                if target::SHELL_REPORTS_MISSING_PROGRAMS || process::on_path(shell) {
                    Ok(format!("{shell} is available"))
                } else {
                    Err(DesktopError::NotFound(format!("{shell} is not on PATH")))
                }
            }
            // The server reads the setup record itself (`native::health`); nothing of the desktop's.
            Component::Setup => Ok("the setup record is the server's to read".to_owned()),
            // The server keeps the shell's history itself (`native::health`, `settle`).
            Component::Shell => Ok("the shell's settle is the server's to judge".to_owned()),
            Component::Unknown => Err(DesktopError::InvalidInput("unknown component".into())),
        }
    }

    fn screen(&self) -> DesktopResult<ScreenInfo> {
        let (w, h) = self.lock().screen;
        Ok(ScreenInfo {
            physical_width: w,
            physical_height: h,
            logical_width: w,
            logical_height: h,
            scale_factor: 1.0,
            monitors: vec![MonitorInfo {
                name: r"\\.\DISPLAY1".into(),
                rect: Rect::new(0, 0, w as i32, h as i32),
                scale_factor: 1.0,
                primary: true,
            }],
            coordinate_space: CoordinateSpace::Physical,
        })
    }

    fn capture(&self, draw_cursor: bool) -> DesktopResult<Frame> {
        Ok(self.render_frame(draw_cursor))
    }

    fn cursor_position(&self) -> DesktopResult<Point> {
        Ok(self.lock().cursor)
    }

    fn perform(&self, action: &Action) -> DesktopResult<()> {
        if let Action::TypeText { text, interval_ms: Some(ms) } = action {
            if *ms > 0 {
                return self.type_slowly(action, text, std::time::Duration::from_millis(*ms));
            }
        }
        let effects = {
            let mut state = self.lock();
            let effects = self.perform_locked(&mut state, action)?;
            state.record(action);
            effects
        };
        self.apply_effects(effects)
    }

    fn windows(&self) -> DesktopResult<Vec<WindowInfo>> {
        Ok(self.lock().infos())
    }

    fn activate_window(&self, id: u64) -> DesktopResult<()> {
        let mut state = self.lock();
        let index = state.index(id)?;
        if state.windows[index].minimized {
            state.windows[index].minimized = false;
        }
        state.activate(id)
    }

    fn set_window_state(&self, id: u64, window_state: WindowState) -> DesktopResult<()> {
        self.lock().set_state(id, window_state)
    }

    fn close_window(&self, id: u64) -> DesktopResult<()> {
        self.lock().close(id)
    }

    fn move_window(&self, id: u64, rect: Rect) -> DesktopResult<()> {
        self.lock().move_window(id, rect)
    }

    fn accessibility(
        &self,
        backend: A11yBackend,
        budget: &TreeBudget,
        foreground_only: bool,
    ) -> DesktopResult<A11yTree> {
        let listings = self.listings();
        // The windows' trees are copied under the lock and walked without it, so a
        // scenario's slow UI Automation does not hold up the rest of the desktop.
        let roots = a11y::roots(&self.lock(), backend, foreground_only, &listings)?;
        let empty = backend == A11yBackend::Uia && self.uia_model().answers_empty();
        a11y::walk(roots, backend, budget, foreground_only, empty)
    }

    fn clipboard_get(&self) -> DesktopResult<ClipboardData> {
        Ok(self.lock().clipboard.clone())
    }

    fn clipboard_set(&self, data: &ClipboardData) -> DesktopResult<()> {
        self.lock().clipboard = data.clone();
        Ok(())
    }

    fn map_path(&self, guest_path: &str) -> DesktopResult<PathBuf> {
        fs::map_path(&self.root, guest_path)
    }

    fn unmap_path(&self, local: &Path) -> DesktopResult<String> {
        fs::unmap_path(&self.root, local)
    }

    fn env_var(&self, name: &str) -> Option<String> {
        self.env.get(&name.to_uppercase()).map(|(_, v)| v.clone())
    }

    fn known_folder(&self, folder: KnownFolder) -> DesktopResult<String> {
        fs::known_folder(folder)
    }

    fn recycle(&self, guest_path: &str) -> DesktopResult<()> {
        let local = self.map_path(guest_path)?;
        fs::recycle(&self.root, guest_path, &local)
    }

    fn open_path(&self, guest_path: &str) -> DesktopResult<()> {
        let local = self.map_path(guest_path)?;
        let meta = std::fs::metadata(&local).map_err(|err| DesktopError::io("open", guest_path, err))?;
        let name = display_name(guest_path);
        if meta.is_dir() {
            let mut state = self.lock();
            let pid = state.shell_pid();
            state.open(NewWindow {
                title: name,
                class_name: "CabinetWClass".into(),
                process_name: "explorer.exe".into(),
                pid: Some(pid),
                folder: Some(local),
                ..NewWindow::default()
            });
            return Ok(());
        }
        let ext = Path::new(&name)
            .extension()
            .map(|e| format!(".{}", e.to_string_lossy().to_lowercase()))
            .unwrap_or_default();
        if ext == ".exe" {
            let key = process::program_key(&name);
            if self.programs.contains_key(&key) {
                return self.launch_known(&key, &[]).map(|_| ());
            }
            let cmd = CommandSpec::Argv(vec![local.display().to_string()]);
            if !self.host_exec {
                return Err(process::refusal(&cmd));
            }
            return process::spawn_real(&cmd, None).map(|_| ());
        }
        let program = self.associations.get(&ext).and_then(|key| self.programs.get(key).map(|p| (key, p)));
        let Some((key, _)) = program else {
            return Err(DesktopError::Os {
                op: "open",
                message: format!(
                    "{guest_path}: no application is associated with {}",
                    if ext.is_empty() { "files without an extension" } else { &ext }
                ),
            });
        };
        let key = key.clone();
        self.launch_known(&key, &[guest_path.to_owned()]).map(|_| ())
    }

    fn registry_read(&self, key: &str, value: Option<&str>) -> DesktopResult<RegistryValue> {
        self.lock().registry.read(key, value)
    }

    fn registry_write(&self, key: &str, value: Option<&str>, data: &RegistryValue) -> DesktopResult<()> {
        self.lock().registry.write(key, value, data)
    }

    fn wallpaper(&self) -> DesktopResult<Option<String>> {
        match self.lock().registry.read(registry::DESKTOP_KEY, Some(registry::WALLPAPER_VALUE)) {
            Ok(RegistryValue::String(s)) if !s.is_empty() => Ok(Some(s)),
            Ok(_) | Err(DesktopError::NotFound(_)) => Ok(None),
            Err(err) => Err(err),
        }
    }

    fn system_time(&self) -> DesktopResult<i64> {
        let offset = self.clock_offset_ms.load(std::sync::atomic::Ordering::Relaxed);
        Ok(arena_shared::clock::now_unix_ms().saturating_add(offset))
    }

    fn set_system_time(&self, unix_ms: i64) -> DesktopResult<()> {
        arena_shared::clock::check(unix_ms).map_err(DesktopError::InvalidInput)?;
        let offset = unix_ms.saturating_sub(arena_shared::clock::now_unix_ms());
        self.clock_offset_ms.store(offset, std::sync::atomic::Ordering::Relaxed);
        Ok(())
    }

    fn set_wallpaper(&self, guest_path: &str) -> DesktopResult<()> {
        let local = self.map_path(guest_path)?;
        if !local.is_file() {
            return Err(DesktopError::NotFound(format!("{guest_path}: not found")));
        }
        self.lock().registry.write(
            registry::DESKTOP_KEY,
            Some(registry::WALLPAPER_VALUE),
            &RegistryValue::String(guest_path.to_owned()),
        )
    }

    fn directory_access_mask(&self, guest_path: &str, user: &str) -> DesktopResult<Option<u32>> {
        let local = self.map_path(guest_path)?;
        let meta = std::fs::metadata(&local)
            .map_err(|err| DesktopError::io("reading a security descriptor", guest_path, err))?;
        if let Some(users) = self.acls.get(&fold_guest(guest_path)?) {
            return Ok(users.get(&user.to_uppercase()).copied());
        }
        if !user.eq_ignore_ascii_case("Docker") {
            return Ok(None);
        }
        // FILE_GENERIC_READ | FILE_GENERIC_EXECUTE for read-only, FILE_ALL_ACCESS otherwise.
        Ok(Some(if meta.permissions().readonly() { 0x1200A9 } else { 0x1F01FF }))
    }

    fn run(&self, cmd: &CommandSpec, limits: &ExecLimits) -> DesktopResult<ExecOutput> {
        if self.launch_modelled(cmd)?.is_some() {
            return Ok(ExecOutput {
                exit_code: Some(0),
                stdout: String::new(),
                stderr: String::new(),
                stdout_truncated: false,
                stderr_truncated: false,
                timed_out: false,
                duration_ms: 0,
            });
        }
        if !self.host_exec {
            return Err(process::refusal(cmd));
        }
        let cwd = self.map_cwd(limits)?;
        process::run_real(cmd, limits, cwd)
    }

    fn spawn(&self, cmd: &CommandSpec) -> DesktopResult<u32> {
        if let Some(pid) = self.launch_modelled(cmd)? {
            return Ok(pid);
        }
        if !self.host_exec {
            return Err(process::refusal(cmd));
        }
        process::spawn_real(cmd, None)
    }

    fn shutdown(&self) -> DesktopResult<()> {
        tracing::info!("stub desktop: shutdown requested (the process keeps running)");
        self.lock().shutdown = true;
        Ok(())
    }
}
