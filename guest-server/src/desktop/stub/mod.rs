//! PLACEHOLDER: the stub backend is being written; every call is unsupported for now.

use std::path::{Path, PathBuf};

use arena_shared::action::Action;
use arena_shared::files::KnownFolder;
use arena_shared::geometry::Point;
use arena_shared::health::Component;
use arena_shared::observation::{A11yBackend, A11yTree, ScreenInfo, TreeBudget, WindowInfo};
use arena_shared::registry::RegistryValue;

use super::{ClipboardData, CommandSpec, Desktop, DesktopError, DesktopResult, ExecLimits, ExecOutput, Frame, WindowState};

/// A scenario seeding the stub.
#[derive(Debug, Clone, Default, serde::Deserialize)]
pub struct Scenario {}

/// A scenario file could not be used.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct ScenarioError(String);

impl Scenario {
    /// Loads a scenario file.
    ///
    /// # Errors
    ///
    /// Unreadable or invalid files.
    pub fn load(path: &Path) -> Result<Scenario, ScenarioError> {
        let text = std::fs::read_to_string(path).map_err(|e| ScenarioError(e.to_string()))?;
        serde_json::from_str(&text).map_err(|e| ScenarioError(e.to_string()))
    }
}

/// How to start the stub.
#[derive(Debug, Clone)]
pub struct StubConfig {
    pub root: Option<PathBuf>,
    pub screen: (u32, u32),
    pub scenario: Option<Scenario>,
}

/// The stub desktop.
#[derive(Debug)]
pub struct StubDesktop {
    root: PathBuf,
}

impl StubDesktop {
    /// # Errors
    /// Never yet.
    pub fn new(root: PathBuf) -> DesktopResult<StubDesktop> {
        Ok(StubDesktop { root })
    }

    /// # Errors
    /// Never yet.
    pub fn with_config(config: StubConfig) -> DesktopResult<StubDesktop> {
        Ok(StubDesktop { root: config.root.unwrap_or_else(std::env::temp_dir) })
    }
}

fn todo_err<T>() -> DesktopResult<T> {
    Err(DesktopError::Unsupported("stub not written yet".into()))
}

impl Desktop for StubDesktop {
    fn kind(&self) -> &'static str { "stub" }
    fn probe(&self, _: Component) -> DesktopResult<String> { todo_err() }
    fn screen(&self) -> DesktopResult<ScreenInfo> { todo_err() }
    fn capture(&self, _: bool) -> DesktopResult<Frame> { todo_err() }
    fn cursor_position(&self) -> DesktopResult<Point> { todo_err() }
    fn perform(&self, _: &Action) -> DesktopResult<()> { todo_err() }
    fn windows(&self) -> DesktopResult<Vec<WindowInfo>> { todo_err() }
    fn activate_window(&self, _: u64) -> DesktopResult<()> { todo_err() }
    fn set_window_state(&self, _: u64, _: WindowState) -> DesktopResult<()> { todo_err() }
    fn close_window(&self, _: u64) -> DesktopResult<()> { todo_err() }
    fn accessibility(&self, _: A11yBackend, _: &TreeBudget, _: bool) -> DesktopResult<A11yTree> { todo_err() }
    fn clipboard_get(&self) -> DesktopResult<ClipboardData> { todo_err() }
    fn clipboard_set(&self, _: &ClipboardData) -> DesktopResult<()> { todo_err() }
    fn map_path(&self, _: &str) -> DesktopResult<PathBuf> { let _ = &self.root; todo_err() }
    fn unmap_path(&self, _: &Path) -> DesktopResult<String> { todo_err() }
    fn env_var(&self, _: &str) -> Option<String> { None }
    fn known_folder(&self, _: KnownFolder) -> DesktopResult<String> { todo_err() }
    fn recycle(&self, _: &str) -> DesktopResult<()> { todo_err() }
    fn open_path(&self, _: &str) -> DesktopResult<()> { todo_err() }
    fn registry_read(&self, _: &str, _: Option<&str>) -> DesktopResult<RegistryValue> { todo_err() }
    fn registry_write(&self, _: &str, _: Option<&str>, _: &RegistryValue) -> DesktopResult<()> { todo_err() }
    fn wallpaper(&self) -> DesktopResult<Option<String>> { todo_err() }
    fn set_wallpaper(&self, _: &str) -> DesktopResult<()> { todo_err() }
    fn directory_access_mask(&self, _: &str, _: &str) -> DesktopResult<Option<u32>> { todo_err() }
    fn run(&self, _: &CommandSpec, _: &ExecLimits) -> DesktopResult<ExecOutput> { todo_err() }
    fn spawn(&self, _: &CommandSpec) -> DesktopResult<u32> { todo_err() }
    fn shutdown(&self) -> DesktopResult<()> { todo_err() }
}
