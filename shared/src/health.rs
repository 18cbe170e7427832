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
    /// The image's setup (`setup.ps1`): up once every step has finished (or
    /// when this guest was not installed by it), down while a step runs or after
    /// one failed; the detail says which step ([`SetupProgress`]).
    Setup,
    /// The desktop settled after a boot: the taskbar shown, the desktop or the
    /// taskbar in front, and the CPU idle for the guest's `--settle-idle-ms`.
    /// Reported beside readiness, not part of it ([`Component::gates_readiness`]):
    /// a host waits for it before it saves a snapshot tasks start from.
    Shell,
    #[serde(other)]
    Unknown,
}

impl Component {
    /// Every component readiness waits for (all but [`Component::Shell`]).
    pub const ALL: [Component; 8] = [
        Component::Capture,
        Component::Input,
        Component::Accessibility,
        Component::Clipboard,
        Component::Files,
        Component::Exec,
        Component::Uia,
        Component::Setup,
    ];

    /// Every component a guest reports: [`Component::ALL`] and the shell's settle.
    pub const REPORTED: [Component; 9] = [
        Component::Capture,
        Component::Input,
        Component::Accessibility,
        Component::Clipboard,
        Component::Files,
        Component::Exec,
        Component::Uia,
        Component::Setup,
        Component::Shell,
    ];

    /// Whether the guest's readiness waits for this component. The shell's settle
    /// does not: a restored snapshot is settled already, and a guest in use (a
    /// window in front, a busy CPU) is still ready for requests.
    pub fn gates_readiness(self) -> bool {
        self != Component::Shell
    }
}

/// Where the image's setup is, as `setup.ps1` records it in
/// `%ProgramData%\arena\setup-status.json` step by step (the guest reads it for
/// [`Component::Setup`]; `arena vm prepare` reads it off a failed install's disk).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct SetupProgress {
    pub state: SetupState,
    /// The step running, or the one that failed.
    #[serde(default)]
    pub step: String,
    /// Steps finished so far, and how many there are.
    #[serde(default)]
    pub done: u32,
    #[serde(default)]
    pub total: u32,
    /// Steps that failed, each with its exit code (`prep-apps.ps1 (exit code 3)`).
    #[serde(default)]
    pub failed: Vec<String>,
    /// The setup's log in the guest.
    #[serde(default)]
    pub log: String,
}

/// [`SetupProgress::state`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SetupState {
    Running,
    Done,
    Failed,
    #[serde(other)]
    Unknown,
}

impl SetupProgress {
    /// Reads the record `setup.ps1` writes (UTF-8, a byte-order mark allowed).
    ///
    /// # Errors
    ///
    /// Not the record's JSON, with serde's reason.
    pub fn parse(bytes: &[u8]) -> Result<SetupProgress, String> {
        let bytes = bytes.strip_prefix(b"\xef\xbb\xbf").unwrap_or(bytes);
        serde_json::from_slice(bytes).map_err(|err| format!("the setup record is not readable: {err}"))
    }

    /// Whether the setup is over with every step done, and what to say about it.
    pub fn judge(&self) -> (bool, String) {
        let failed =
            if self.failed.is_empty() { String::new() } else { format!("; failed: {}", self.failed.join(", ")) };
        match self.state {
            SetupState::Done if self.failed.is_empty() => {
                (true, format!("setup finished: {} of {} steps", self.done, self.total))
            }
            SetupState::Running => (
                false,
                format!(
                    "setup running: step {} of {} ({}){failed}; log {}",
                    self.done + 1,
                    self.total,
                    self.step,
                    self.log
                ),
            ),
            _ => (false, format!("setup failed at {}{failed}; log {}", self.step, self.log)),
        }
    }
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
    /// Every component that gates readiness is up (all but [`Component::Shell`]).
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
    /// Made up anew each time the server starts (a reboot, a crash, a restart by the
    /// service), and the same for its whole life: a host that saw one id at an
    /// episode's start and another later knows the guest restarted in between,
    /// even when it answered every time it was asked.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub boot_id: Option<String>,
}

impl HealthReport {
    /// Whether `component` was probed and is up.
    pub fn is_up(&self, component: Component) -> bool {
        self.components.iter().any(|c| c.component == component && c.ok)
    }

    /// Whether every component reported that gates readiness is up (and one was).
    pub fn gated_up(&self) -> bool {
        let gating = || self.components.iter().filter(|c| c.component.gates_readiness());
        gating().next().is_some() && gating().all(|c| c.ok)
    }

    /// The shell's settle as reported, or `None` from a guest that reports none
    /// (one older than [`Component::Shell`]).
    pub fn shell(&self) -> Option<&ComponentHealth> {
        self.components.iter().find(|c| c.component == Component::Shell)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn readiness_waits_for_every_component_but_the_shell() {
        let part = |component, ok| ComponentHealth { component, ok, detail: String::new(), elapsed_ms: 0 };
        let mut report = HealthReport {
            status: Readiness::Ready,
            version: "0".into(),
            api_version: "1".into(),
            backend: "stub".into(),
            components: Component::ALL.iter().map(|c| part(*c, true)).collect(),
            uptime_ms: 0,
            auth_required: false,
            session_id: None,
            integrity: None,
            boot_id: None,
        };
        assert!(report.gated_up());
        assert_eq!(report.shell(), None, "an older guest reports no shell");
        report.components.push(part(Component::Shell, false));
        assert!(report.gated_up(), "a shell still settling does not hold readiness");
        assert!(!report.shell().unwrap().ok);
        report.components[0].ok = false;
        assert!(!report.gated_up());
        report.components = vec![part(Component::Shell, true)];
        assert!(!report.gated_up(), "the shell alone is not a ready guest");
        assert!(Component::REPORTED.iter().filter(|c| !c.gates_readiness()).eq([Component::Shell].iter()));
        assert!(Component::ALL.iter().all(|c| Component::REPORTED.contains(c) && c.gates_readiness()));
    }

    #[test]
    fn the_setup_record_reads_with_a_byte_order_mark_and_is_judged() {
        let running = SetupProgress::parse(
            b"\xef\xbb\xbf{\"state\":\"running\",\"step\":\"prep-apps.ps1\",\"done\":4,\"total\":6,\"log\":\"C:\\\\ProgramData\\\\arena\\\\logs\\\\setup.log\"}",
        )
        .unwrap();
        let (ok, detail) = running.judge();
        assert!(!ok && detail.contains("step 5 of 6 (prep-apps.ps1)"), "{detail}");
        let done = SetupProgress { state: SetupState::Done, done: 6, total: 6, ..running.clone() };
        assert_eq!(done.judge(), (true, "setup finished: 6 of 6 steps".to_owned()));
        let failed = SetupProgress {
            state: SetupState::Failed,
            failed: vec!["prep-apps.ps1 (exit code 3)".into()],
            ..running.clone()
        };
        let (ok, detail) = failed.judge();
        assert!(!ok && detail.contains("failed at prep-apps.ps1") && detail.contains("exit code 3"), "{detail}");
        // A run that finished with a failed step is not a finished setup.
        let (ok, _) = SetupProgress { state: SetupState::Done, ..failed }.judge();
        assert!(!ok);
        assert!(SetupProgress::parse(b"not json").unwrap_err().contains("not readable"));
        let newer: SetupProgress = serde_json::from_str(r#"{"state":"paused"}"#).unwrap();
        assert_eq!(newer.state, SetupState::Unknown);
    }
}
