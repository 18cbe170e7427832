//! The step protocol's messages (version [`PROTOCOL_VERSION`]): what the harness
//! sends an outside agent and what the agent answers, as JSON objects tagged by
//! `type`. `docs/agents.md` specifies them and `schemas/agent-protocol/` holds a
//! JSON Schema for each; the tests validate both sides against those schemas.
//!
//! The exchange is strictly one answer per message: `hello` → `hello`, `reset` →
//! `ready`, `observe` → `act`. An agent may answer any message with `error`,
//! which ends the episode as an agent error.

use arena_actionspace::Decision;
use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};

/// The protocol version this harness speaks. A `hello` answer with another
/// version is refused with a message naming both.
pub const PROTOCOL_VERSION: u32 = 1;

/// The action spaces an answer may use.
pub const ACTION_SPACES: [&str; 4] = ["computer", "pyautogui", "computer_13", "typed"];

/// The most actions one `act` may carry (decision apart): an answer with more is
/// refused before any of them runs, as an agent error naming the count. Every
/// action is followed by the run's pause and an observation, so this bounds a
/// step to minutes even before its deadline; agents answer one to a few.
pub const MAX_ACTIONS: usize = 256;

/// The coordinate conventions an agent may name in its `hello` (`--coords`'s).
pub const COORDS: [&str; 3] = ["pixels", "fraction", "grid1000"];

/// The harness's first message.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Hello {
    pub protocol: u32,
    /// `arena` and its version.
    pub harness: String,
    /// The action spaces this harness accepts ([`ACTION_SPACES`]).
    pub action_spaces: Vec<String>,
}

/// How the agent wants its screenshot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ScreenshotMode {
    /// A PNG file the harness writes; its absolute path (only for local agents).
    Path,
    /// The PNG inline, base64-encoded.
    Inline,
    /// No screenshot.
    None,
}

/// How the agent wants the accessibility tree.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TreeMode {
    /// Upstream's XML text (what WAA's `get_accessibility_tree` answers).
    Xml,
    /// The typed tree (`arena_shared::observation::A11yTree` as JSON).
    Tree,
    /// No tree.
    None,
}

/// What the agent wants in each observation; every field has a default.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObservationWants {
    /// `path` (the default over stdin/stdout) or `inline` (the default over HTTP) or `none`.
    #[serde(default)]
    pub screenshot: Option<ScreenshotMode>,
    #[serde(default = "xml")]
    pub a11y: TreeMode,
    /// The titles of the visible windows and the foreground window's title.
    #[serde(default = "yes")]
    pub windows: bool,
    /// The clipboard's text.
    #[serde(default = "yes")]
    pub clipboard: bool,
    /// Set-of-Marks: the element boxes numbered from the tree (the ids
    /// `computer.mouse.move_id` takes).
    #[serde(default)]
    pub som: bool,
}

fn xml() -> TreeMode {
    TreeMode::Xml
}

fn yes() -> bool {
    true
}

impl Default for ObservationWants {
    fn default() -> ObservationWants {
        ObservationWants { screenshot: None, a11y: TreeMode::Xml, windows: true, clipboard: true, som: false }
    }
}

/// The agent's answer to `hello`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AgentHello {
    pub protocol: u32,
    /// The agent's name, for results and logs.
    #[serde(default)]
    pub agent: Option<String>,
    /// The action space its answers use unless an answer names another.
    pub action_space: String,
    /// What the coordinates of its `pyautogui` and `computer_13` answers are
    /// measured in ([`COORDS`]); absent, the run's `--coords`.
    #[serde(default)]
    pub coords: Option<String>,
    #[serde(default)]
    pub observation: ObservationWants,
}

/// Every message the agent may send, tagged by `type`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum AgentMessage {
    Hello(AgentHello),
    Ready {},
    Act(Act),
    Error { message: String },
}

/// The agent's answer to `observe`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Act {
    /// The model's reply or the agent's reasoning, recorded as the step's response.
    #[serde(default)]
    pub response: String,
    /// The action space of `actions`, when not the one named in `hello`.
    #[serde(default)]
    pub action_space: Option<String>,
    /// In the action space: code strings (`computer`, `pyautogui`), `computer_13`
    /// objects, or typed action objects; the strings `DONE`, `FAIL` and `WAIT`
    /// are the decisions in any space, as upstream's and OSWorld's agents write them.
    #[serde(default)]
    pub actions: Vec<Value>,
    /// Taken after the actions.
    #[serde(default)]
    pub decision: Option<Decision>,
    /// Free-form fields, each recorded as a field of the step's `traj.jsonl` line.
    #[serde(default)]
    pub record: Map<String, Value>,
    /// Navi's `computer` update (upstream's `computer_update_args`): `rects`,
    /// the element boxes `computer.mouse.move_id` resolves against.
    #[serde(default)]
    pub computer_update: Option<ComputerUpdate>,
    /// What the step cost the agent's model, as the agent reports it (the cost ledger).
    #[serde(default)]
    pub usage: Option<ActUsage>,
}

/// An `act`'s optional `usage`: tokens the agent's model took for the step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct ActUsage {
    pub input_tokens: u64,
    pub output_tokens: u64,
    /// The part of `input_tokens` read from a prompt cache.
    #[serde(default)]
    pub cached_tokens: u64,
    /// Wall time of the agent's model calls, in milliseconds.
    #[serde(default)]
    pub model_ms: u64,
}

/// The part of upstream's `/update_computer` arguments the harness uses.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ComputerUpdate {
    /// `[x1, y1, x2, y2]` for each element id, in the view's pixels.
    #[serde(default)]
    pub rects: Vec<[f64; 4]>,
    /// The view on the screen, `[x1, y1, x2, y2]` (default: the whole screen).
    #[serde(default)]
    pub window_rect: Option<[f64; 4]>,
    /// Screen pixels per view pixel, `[x, y]` (default `[1, 1]`).
    #[serde(default)]
    pub scale: Option<[f64; 2]>,
}

impl ComputerUpdate {
    /// The boxes in screen pixels, each keeping the point upstream's `move_id`
    /// aims at: the box's integer centre (`(x1 + x2) // 2`) times the scale,
    /// plus the view's corner. The box is kept as wide as it is scaled, about
    /// that point, so the harness's own `move_id` lands on the same pixel.
    pub fn screen_rects(&self) -> Vec<[i32; 4]> {
        let [sx, sy] = self.scale.unwrap_or([1.0, 1.0]);
        let [wx, wy, _, _] = self.window_rect.unwrap_or([0.0; 4]);
        let clamp = |v: f64| v.round().clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32;
        self.rects
            .iter()
            .map(|r| {
                let cx = ((r[0] + r[2]) / 2.0).floor() * sx + wx;
                let cy = ((r[1] + r[3]) / 2.0).floor() * sy + wy;
                let hw = ((r[2] - r[0]).abs() * sx / 2.0).floor();
                let hh = ((r[3] - r[1]).abs() * sy / 2.0).floor();
                let (cx, cy) = (clamp(cx), clamp(cy));
                let (hw, hh) = (clamp(hw), clamp(hh));
                [cx.saturating_sub(hw), cy.saturating_sub(hh), cx.saturating_add(hw), cy.saturating_add(hh)]
            })
            .collect()
    }
}
