//! The staged readiness report of `GET /v1/health`.
//!
//! Instead of one boolean, the guest says which of its parts work and how
//! long each probe took, so a host can wait for exactly what it needs.

use serde::{Deserialize, Serialize};

/// A part of the guest whose readiness is probed separately.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Component {
    Capture,
    Input,
    Accessibility,
    Clipboard,
    Files,
    Exec,
    /// UI Automation itself: a bounded walk of the foreground window that must
    /// return nodes when a window is in front (the `accessibility` stage walks the
    /// win32 source, which stays up when UI Automation answers empty trees, as it
    /// can after a snapshot restore).
    Uia,
    #[serde(other)]
    Unknown,
}

impl Component {
    pub const ALL: [Component; 7] = [
        Component::Capture,
        Component::Input,
        Component::Accessibility,
        Component::Clipboard,
        Component::Files,
        Component::Exec,
        Component::Uia,
    ];
}

/// Result of probing one component.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ComponentHealth {
    pub component: Component,
    pub ok: bool,
    /// What was checked, or why it failed.
    pub detail: String,
    pub elapsed_ms: u64,
}

/// Overall state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Readiness {
    /// Every component is up.
    Ready,
    /// Some components are up.
    Degraded,
    /// Nothing is up yet.
    Starting,
    #[serde(other)]
    Unknown,
}

/// `GET /v1/health`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HealthReport {
    pub status: Readiness,
    pub version: String,
    pub api_version: String,
    /// `stub` or `windows`.
    pub backend: String,
    pub components: Vec<ComponentHealth>,
    pub uptime_ms: u64,
    /// Whether requests need a bearer token.
    #[serde(default)]
    pub auth_required: bool,
    /// Windows session id the server runs in, where known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub session_id: Option<u32>,
    /// The server process's integrity level and elevation (`High, elevated (full
    /// administrator token)`), where the platform has them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub integrity: Option<String>,
}

impl HealthReport {
    /// Whether `component` was probed and is up.
    pub fn is_up(&self, component: Component) -> bool {
        self.components.iter().any(|c| c.component == component && c.ok)
    }
}
