//! Typed input actions.
//!
//! One [`Action`] enum describes everything an agent can do with the mouse and
//! keyboard; the guest executes a batch of them in order.
//! Coordinates are physical screen pixels; an action without coordinates acts
//! at the current cursor position, as pyautogui does.

use serde::{Deserialize, Serialize};

/// A mouse button.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MouseButton {
    #[default]
    Left,
    Right,
    Middle,
    #[serde(other)]
    Unknown,
}

impl MouseButton {
    /// Parses pyautogui's button names (`left`, `right`, `middle`, and `primary`/`secondary`).
    pub fn from_name(name: &str) -> Option<MouseButton> {
        match name.to_ascii_lowercase().as_str() {
            "left" | "primary" => Some(MouseButton::Left),
            "right" | "secondary" => Some(MouseButton::Right),
            "middle" => Some(MouseButton::Middle),
            _ => None,
        }
    }
}

fn one() -> u32 {
    1
}

fn is_one(n: &u32) -> bool {
    *n == 1
}

/// Most bytes of UTF-8 text one `type_text` action types (1 MiB): a page of text is a
/// few kilobytes, and typing is one keystroke per character, so more is a runaway, not
/// an agent's intent. Both the guest's routes and its backends refuse more up front.
pub const MAX_TYPE_TEXT_BYTES: usize = 1 << 20;

/// Refuses a `type_text` of more than [`MAX_TYPE_TEXT_BYTES`] with a message that
/// gives both sizes; every route and backend that types checks with this.
///
/// # Errors
///
/// The message, when `text` is too long.
pub fn check_typed_length(text: &str) -> Result<(), String> {
    if text.len() > MAX_TYPE_TEXT_BYTES {
        return Err(format!(
            "type_text holds {} bytes; at most {MAX_TYPE_TEXT_BYTES} are typed in one action",
            text.len()
        ));
    }
    Ok(())
}

/// One input action.
///
/// Scroll amounts are raw wheel deltas, as pyautogui passes them on Windows:
/// 120 is one notch, positive `dy` scrolls up and positive `dx` scrolls right.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum Action {
    /// Moves the cursor to an absolute position.
    MoveTo { x: i32, y: i32 },
    /// Moves the cursor by an offset.
    MoveRel { dx: i32, dy: i32 },
    /// Clicks `count` times, first moving to `x`, `y` when they are given.
    Click {
        #[serde(default, skip_serializing_if = "Option::is_none")]
        x: Option<i32>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        y: Option<i32>,
        #[serde(default)]
        button: MouseButton,
        #[serde(default = "one", skip_serializing_if = "is_one")]
        count: u32,
    },
    /// A left double click.
    DoubleClick {
        #[serde(default, skip_serializing_if = "Option::is_none")]
        x: Option<i32>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        y: Option<i32>,
    },
    /// A right click.
    RightClick {
        #[serde(default, skip_serializing_if = "Option::is_none")]
        x: Option<i32>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        y: Option<i32>,
    },
    /// Presses a button (at `x`, `y` when given).
    MouseDown {
        #[serde(default)]
        button: MouseButton,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        x: Option<i32>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        y: Option<i32>,
    },
    /// Releases a button (at `x`, `y` when given).
    MouseUp {
        #[serde(default)]
        button: MouseButton,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        x: Option<i32>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        y: Option<i32>,
    },
    /// Presses `button` at the current position (or `from`), moves to `to`, releases.
    /// With `duration_ms` (pyautogui's `duration`), the move is spread over that time
    /// in small steps, as pyautogui's `dragTo` moves.
    Drag {
        #[serde(default, skip_serializing_if = "Option::is_none")]
        from: Option<crate::geometry::Point>,
        to: crate::geometry::Point,
        #[serde(default)]
        button: MouseButton,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        duration_ms: Option<u64>,
    },
    /// Turns the wheel by raw wheel deltas (120 a notch), at `x`, `y` when given.
    Scroll {
        #[serde(default, skip_serializing_if = "Option::is_none")]
        x: Option<i32>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        y: Option<i32>,
        #[serde(default)]
        dx: i32,
        #[serde(default)]
        dy: i32,
    },
    /// Presses and releases one key `presses` times (pyautogui key names).
    KeyPress {
        key: String,
        #[serde(default = "one", skip_serializing_if = "is_one")]
        presses: u32,
    },
    /// Presses the keys in order and releases them in reverse (`ctrl`, `shift`, `t`).
    Hotkey { keys: Vec<String> },
    /// Holds a key down.
    KeyDown { key: String },
    /// Releases a held key.
    KeyUp { key: String },
    /// Types Unicode text, independent of the keyboard layout.
    TypeText {
        text: String,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        interval_ms: Option<u64>,
    },
    /// Waits before the next action of the batch.
    Wait { ms: u64 },
    /// An action this build does not know, sent by a newer peer.
    #[serde(other)]
    Unknown,
}

/// A batch of actions executed in order; the first failure stops the batch.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ActionBatch {
    pub actions: Vec<Action>,
}

/// What a batch did.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ActionReport {
    /// How many actions completed.
    pub executed: usize,
    /// Cursor position after the batch, in physical pixels.
    pub cursor: crate::geometry::Point,
    #[serde(default)]
    pub elapsed_ms: u64,
}
