//! Action spaces (`arena-actionspace`): the grammars agents answer in, each
//! translated into the guest's typed [`Action`]s and the step decisions `WAIT`,
//! `DONE` and `FAIL`.
//!
//! One entry point serves every caller (the computer-use agents, the executor
//! `arena-exec` for pyautogui answers under `--pyautogui-translate-only` and for a
//! setup step's input-only `python -c`, `arena act`, tests):
//!
//! ```text
//! actionspace::parse(space, &input, &ctx) -> Result<Vec<Step>, ActionError>
//! ```
//!
//! - `space` ([`ActionSpace`]) names the grammar; `input` is a JSON value: a
//!   string for the text grammars (pyautogui code, a UI-TARS reply), an object
//!   (or a list of objects) for the JSON ones (OSWorld's `computer_13`,
//!   Anthropic's `computer` tool input, OpenAI's `computer_call.action`, typed actions).
//! - `ctx` ([`Context`]) gives the guest's screen in physical pixels, the cursor,
//!   and the coordinate convention ([`Coords`]) the agent's numbers are in.
//! - A [`Step`] is one typed input action, a clipboard write (pyperclip, UI-TARS
//!   typing), a decision, or a request only the agent can answer (a
//!   screenshot, the cursor position, a zoomed region). Steps are all this crate
//!   answers: carrying them out is the executor's business (`arena-exec`).
//!
//! An unknown action, parameter value or key is an [`ActionError`] naming the
//! grammar and what was wrong, never a silent no-op.
//!
//! It is not an agent and does no I/O: pyautogui code runs in the shared
//! interpreter against a host that records instead of acting.
//!
//! # Layout
//!
//! - [`decision`]: [`Decision`], the one reading of the words `WAIT`, `DONE` and `FAIL`.
//! - [`typed_action`]: the one check of a typed action as JSON (`arena_shared::action::Action`).
//! - [`pyautogui`]: pyautogui code as OSWorld agents write it (the shared interpreter, pyperclip, coordinates rescaled).
//! - [`computer13`]: OSWorld's `computer_13` JSON actions.
//! - [`anthropic`]: Anthropic's `computer` tool, versions `computer_20250124` and `computer_20251124`.
//! - [`openai`]: OpenAI's `computer_call` actions (`computer_use_preview`).
//! - [`uitars`]: UI-TARS's reply grammar and its coordinate conventions.
//!
//! Each grammar has its own key table into pyautogui's names (`arena_shared::keys`), which the guest speaks.

#![forbid(unsafe_code)]

pub mod anthropic;
pub mod computer13;
pub mod decision;
pub mod openai;
pub mod pyautogui;
pub mod uitars;

use std::fmt;

use serde_json::Value;

use arena_shared::action::Action;
use arena_shared::error::json_kind as json_type;
use arena_shared::keys::Key;

pub use decision::Decision;

/// A grammar agents answer in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ActionSpace {
    /// pyautogui code (OSWorld's `pyautogui` action space), with pyperclip and `time.sleep`.
    Pyautogui,
    /// OSWorld's `computer_13` JSON actions.
    Computer13,
    /// Anthropic's `computer_20250124` tool input.
    Anthropic20250124,
    /// Anthropic's `computer_20251124` tool input (adds `zoom`).
    Anthropic20251124,
    /// Anthropic's `computer_toolset_20260801`: member-named `tool_use` blocks
    /// (`{"name": "left_click", "input": {...}}`).
    AnthropicToolset20260801,
    /// OpenAI's `computer_call` action objects (`computer_use_preview`).
    OpenAi,
    /// UI-TARS replies (`Thought: ... Action: click(...)`).
    UiTars,
    /// This project's typed actions (`arena_shared::action::Action` as JSON).
    Typed,
}

impl ActionSpace {
    /// Every space, in the order the docs list them.
    pub const ALL: [ActionSpace; 8] = [
        ActionSpace::Pyautogui,
        ActionSpace::Computer13,
        ActionSpace::Anthropic20250124,
        ActionSpace::Anthropic20251124,
        ActionSpace::AnthropicToolset20260801,
        ActionSpace::OpenAi,
        ActionSpace::UiTars,
        ActionSpace::Typed,
    ];

    /// The name used on the command line and in recorded options.
    pub fn name(self) -> &'static str {
        match self {
            ActionSpace::Pyautogui => "pyautogui",
            ActionSpace::Computer13 => "computer_13",
            ActionSpace::Anthropic20250124 => "computer_20250124",
            ActionSpace::Anthropic20251124 => "computer_20251124",
            ActionSpace::AnthropicToolset20260801 => "computer_toolset_20260801",
            ActionSpace::OpenAi => "openai_computer",
            ActionSpace::UiTars => "uitars",
            ActionSpace::Typed => "typed",
        }
    }
}

impl fmt::Display for ActionSpace {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for ActionSpace {
    type Err = String;

    fn from_str(s: &str) -> Result<ActionSpace, String> {
        ActionSpace::ALL.into_iter().find(|space| space.name() == s).ok_or_else(|| {
            let names: Vec<&str> = ActionSpace::ALL.iter().map(|space| space.name()).collect();
            format!("unknown action space {s:?} (expected one of {})", names.join(", "))
        })
    }
}

/// What an agent's coordinates are measured in.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Coords {
    /// Screen pixels of the guest.
    #[default]
    Pixels,
    /// Fractions of the screen's width and height, 0 to 1.
    Fraction,
    /// A 0..1000 grid over the screen (UI-TARS 1.0, many grounding models).
    Grid1000,
    /// Pixels of an image of this size that stands for the whole screen (a
    /// scaled screenshot, UI-TARS 1.5's resized image).
    Image { width: u32, height: u32 },
}

impl Coords {
    /// The name recorded in the run's options.
    pub fn name(self) -> String {
        match self {
            Coords::Pixels => "pixels".into(),
            Coords::Fraction => "fraction".into(),
            Coords::Grid1000 => "grid1000".into(),
            Coords::Image { width, height } => format!("image:{width}x{height}"),
        }
    }

    /// Screen pixels per unit of this convention, for x and for y.
    pub fn factors(self, screen: (u32, u32)) -> (f64, f64) {
        let (w, h) = (f64::from(screen.0), f64::from(screen.1));
        match self {
            Coords::Pixels => (1.0, 1.0),
            Coords::Fraction => (w, h),
            Coords::Grid1000 => (w / 1000.0, h / 1000.0),
            Coords::Image { width, height } => (w / f64::from(width.max(1)), h / f64::from(height.max(1))),
        }
    }

    /// A point in this convention as screen pixels (rounded to the nearest pixel,
    /// except for [`Coords::Pixels`], which truncates as pyautogui's `int()` does).
    pub fn to_screen(self, x: f64, y: f64, screen: (u32, u32)) -> (i32, i32) {
        let (fx, fy) = self.factors(screen);
        let conv = |v: f64| {
            let v = if self == Coords::Pixels { v.trunc() } else { v.round() };
            // Saturating casts: absurd numbers land off screen, where the guest refuses them.
            v as i32
        };
        (conv(x * fx), conv(y * fy))
    }

    /// A screen pixel in this convention (the cursor position an agent is told).
    pub fn from_screen(self, x: i32, y: i32, screen: (u32, u32)) -> (f64, f64) {
        let (fx, fy) = self.factors(screen);
        (f64::from(x) / fx, f64::from(y) / fy)
    }
}

impl std::str::FromStr for Coords {
    type Err = String;

    fn from_str(s: &str) -> Result<Coords, String> {
        match s {
            "pixels" => Ok(Coords::Pixels),
            "fraction" => Ok(Coords::Fraction),
            "grid1000" => Ok(Coords::Grid1000),
            other => Err(format!("unknown coordinate convention {other:?} (expected pixels, fraction or grid1000)")),
        }
    }
}

/// What a grammar's numbers are translated against.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Context {
    /// The guest's screen in physical pixels.
    pub screen: (u32, u32),
    /// The cursor in physical pixels (relative moves start here).
    pub cursor: (i32, i32),
    pub coords: Coords,
}

impl Context {
    pub fn new(screen: (u32, u32), coords: Coords) -> Context {
        Context { screen, cursor: (0, 0), coords }
    }

    /// A point of the agent's as screen pixels.
    pub fn point(&self, x: f64, y: f64) -> (i32, i32) {
        self.coords.to_screen(x, y, self.screen)
    }
}

/// One thing a parsed answer asks for.
#[derive(Debug, Clone, PartialEq)]
pub enum Step {
    /// A typed input action for the guest.
    Act(Action),
    /// Puts text on the clipboard (`pyperclip.copy`, UI-TARS typing by paste).
    SetClipboard(String),
    /// The decision `WAIT`: nothing this step, look again.
    Wait,
    /// The decision `DONE`.
    Done,
    /// The decision `FAIL`.
    Fail,
    /// A fresh screenshot (the next observation brings it; nothing is done).
    Screenshot,
    /// The cursor position, which the agent reports back in its own coordinates.
    CursorPosition,
    /// A zoomed view of `[x1, y1, x2, y2]` (screen pixels) of the current screenshot.
    Zoom([i32; 4]),
}

impl From<Decision> for Step {
    fn from(decision: Decision) -> Step {
        match decision {
            Decision::Wait => Step::Wait,
            Decision::Done => Step::Done,
            Decision::Fail => Step::Fail,
        }
    }
}

/// An answer that does not translate: which grammar, and what was wrong.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{space} action: {message}")]
pub struct ActionError {
    pub space: ActionSpace,
    pub message: String,
}

impl ActionError {
    pub fn new(space: ActionSpace, message: impl Into<String>) -> ActionError {
        ActionError { space, message: message.into() }
    }
}

/// Translates `input`, an answer in `space`, into steps.
///
/// # Errors
///
/// [`ActionError`] for input of the wrong JSON type, an unknown action, a
/// missing or malformed parameter, or an unknown key, naming which.
pub fn parse(space: ActionSpace, input: &Value, ctx: &Context) -> Result<Vec<Step>, ActionError> {
    let text = || {
        input.as_str().ok_or_else(|| ActionError::new(space, format!("expected a string, got {}", json_type(input))))
    };
    match space {
        ActionSpace::Pyautogui => pyautogui::parse(text()?, ctx),
        ActionSpace::UiTars => uitars::parse(text()?, ctx).map(|reply| reply.steps),
        ActionSpace::Computer13 => each(space, input, |v| computer13::parse(v, ctx)),
        ActionSpace::Anthropic20250124 | ActionSpace::Anthropic20251124 => {
            each(space, input, |v| anthropic::parse(space, v, ctx))
        }
        ActionSpace::AnthropicToolset20260801 => each(space, input, |v| anthropic::parse_member(v, ctx)),
        ActionSpace::OpenAi => each(space, input, |v| openai::parse(v, ctx)),
        ActionSpace::Typed => each(space, input, |v| {
            typed_action(v).map(|a| vec![Step::Act(a)]).map_err(|why| ActionError::new(space, why))
        }),
    }
}

/// The one check of a typed action as JSON: `value` must be an
/// `arena_shared::action::Action` this build knows (a newer peer's kind, which
/// reads as `Action::Unknown`, is refused).
///
/// # Errors
///
/// A message naming what was wrong: not an action, or an unknown `type`.
pub fn typed_action(value: &Value) -> Result<Action, String> {
    let shown = || {
        let text = value.to_string();
        if text.chars().count() > 200 {
            format!("{}...", text.chars().take(200).collect::<String>())
        } else {
            text
        }
    };
    match serde_json::from_value::<Action>(value.clone()) {
        Ok(Action::Unknown) => Err(format!("unknown typed action {}", shown())),
        Ok(action) => Ok(action),
        Err(err) => Err(format!("not a typed action: {}: {err}", shown())),
    }
}

/// `one` over an object, or over each element of a list of objects, in order.
fn each(
    space: ActionSpace,
    input: &Value,
    mut one: impl FnMut(&Value) -> Result<Vec<Step>, ActionError>,
) -> Result<Vec<Step>, ActionError> {
    match input {
        Value::Array(items) => {
            let mut steps = Vec::new();
            for item in items {
                steps.extend(one(item)?);
            }
            Ok(steps)
        }
        Value::Object(_) | Value::String(_) => one(input),
        other => Err(ActionError::new(space, format!("expected an action object, got {}", json_type(other)))),
    }
}

/// One grammar's key table: its names (lowercase) and the pyautogui names they stand for.
pub(crate) type KeyTable = &'static [(&'static str, &'static str)];

/// A key of `space` as the guest's (pyautogui's) canonical name: through
/// `table` first (matched without case), then pyautogui's own names.
pub(crate) fn key_name(space: ActionSpace, table: KeyTable, name: &str) -> Result<String, ActionError> {
    let lower = name.to_lowercase();
    let mapped = table.iter().find(|(from, _)| *from == lower).map_or(name, |(_, to)| *to);
    Key::parse(mapped).map(|k| k.to_string()).map_err(|_| ActionError::new(space, format!("unknown key {name:?}")))
}

/// A JSON list of key names (`HOTKEY`'s `keys`, `keypress`'s `keys`) as guest
/// key names, through `table`; `action` names the action in messages.
pub(crate) fn key_list(
    space: ActionSpace,
    table: KeyTable,
    keys: Option<&Value>,
    action: &str,
) -> Result<Vec<String>, ActionError> {
    let Some(Value::Array(keys)) = keys else {
        return Err(ActionError::new(space, format!("{action} needs `keys`, a list of key names")));
    };
    let keys = keys
        .iter()
        .map(|k| match k {
            Value::String(k) => key_name(space, table, k),
            other => Err(ActionError::new(space, format!("a key must be a string, got {other}"))),
        })
        .collect::<Result<Vec<_>, _>>()?;
    if keys.is_empty() {
        return Err(ActionError::new(space, format!("{action} needs at least one key")));
    }
    Ok(keys)
}

/// The actions that press `keys` as one chord: one key is a press, more a hotkey.
pub(crate) fn chord(keys: Vec<String>) -> Action {
    if keys.len() == 1 {
        Action::KeyPress { key: keys.into_iter().next().unwrap_or_default(), presses: 1 }
    } else {
        Action::Hotkey { keys }
    }
}

/// A required number parameter.
pub(crate) fn number(space: ActionSpace, obj: &Value, key: &str) -> Result<f64, ActionError> {
    match obj.get(key) {
        Some(v) => v.as_f64().ok_or_else(|| ActionError::new(space, format!("`{key}` must be a number, got {v}"))),
        None => Err(ActionError::new(space, format!("`{key}` is missing"))),
    }
}

/// An optional number parameter (`null` counts as absent).
pub(crate) fn opt_number(space: ActionSpace, obj: &Value, key: &str) -> Result<Option<f64>, ActionError> {
    match obj.get(key) {
        None | Some(Value::Null) => Ok(None),
        Some(_) => number(space, obj, key).map(Some),
    }
}

/// A required string parameter.
pub(crate) fn string<'a>(space: ActionSpace, obj: &'a Value, key: &str) -> Result<&'a str, ActionError> {
    match obj.get(key) {
        Some(Value::String(s)) => Ok(s),
        Some(v) => Err(ActionError::new(space, format!("`{key}` must be a string, got {v}"))),
        None => Err(ActionError::new(space, format!("`{key}` is missing"))),
    }
}

/// Seconds as whole milliseconds, refusing negative or absurd values.
pub(crate) fn millis(space: ActionSpace, what: &str, seconds: f64) -> Result<u64, ActionError> {
    if !seconds.is_finite() || !(0.0..=3600.0).contains(&seconds) {
        return Err(ActionError::new(space, format!("`{what}` must be 0 to 3600 seconds, got {seconds}")));
    }
    Ok((seconds * 1000.0).round() as u64)
}

#[cfg(test)]
mod tests;
