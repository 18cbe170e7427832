//! The input recorder's log: what a window received, one JSON object a line.
//!
//! The recorder (`arena-input-recorder`, `guest-server/recorder/`) writes one
//! [`Recorded`] per input message its window gets, and the stub's model of it writes
//! the same lines; the host's input check (`arena-inputcheck`) reads them back through
//! the guest's file routes and compares them with what each case expects.
//!
//! Mouse positions are client coordinates of the recorder's window; its first line,
//! [`Recorded::Ready`], says where that client area is on the screen. `mods` is the
//! modifier state (`GetKeyState` of Shift, Ctrl, Alt and the Windows keys) when the
//! message was read, and `time` is `GetMessageTime` (milliseconds, wrapping).

use std::fmt;

use serde::{Deserialize, Serialize};

/// The modifier keys held when a message was read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Hash, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub struct Mods {
    pub shift: bool,
    pub ctrl: bool,
    pub alt: bool,
    pub win: bool,
}

impl Mods {
    /// No modifier held.
    pub const NONE: Mods = Mods { shift: false, ctrl: false, alt: false, win: false };

    /// Reads `shift+ctrl` (any order, `""` for none).
    ///
    /// # Errors
    ///
    /// A message naming a word that is not `shift`, `ctrl`, `alt` or `win`.
    pub fn parse(text: &str) -> Result<Mods, String> {
        let mut mods = Mods::NONE;
        for word in text.split('+').map(str::trim).filter(|w| !w.is_empty()) {
            match word {
                "shift" => mods.shift = true,
                "ctrl" => mods.ctrl = true,
                "alt" => mods.alt = true,
                "win" => mods.win = true,
                other => return Err(format!("unknown modifier {other:?} (expected shift, ctrl, alt or win)")),
            }
        }
        Ok(mods)
    }
}

impl fmt::Display for Mods {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let names = [(self.shift, "shift"), (self.ctrl, "ctrl"), (self.alt, "alt"), (self.win, "win")];
        let held: Vec<&str> = names.iter().filter(|(on, _)| *on).map(|(_, name)| *name).collect();
        f.write_str(&held.join("+"))
    }
}

impl TryFrom<String> for Mods {
    type Error = String;

    fn try_from(text: String) -> Result<Mods, String> {
        Mods::parse(&text)
    }
}

impl From<Mods> for String {
    fn from(mods: Mods) -> String {
        mods.to_string()
    }
}

/// A mouse button as the window messages name them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Button {
    Left,
    Right,
    Middle,
    X1,
    X2,
}

impl Button {
    /// The name as written in logs and expectations.
    pub fn name(self) -> &'static str {
        match self {
            Button::Left => "left",
            Button::Right => "right",
            Button::Middle => "middle",
            Button::X1 => "x1",
            Button::X2 => "x2",
        }
    }

    /// The button a name stands for.
    pub fn from_name(name: &str) -> Option<Button> {
        [Button::Left, Button::Right, Button::Middle, Button::X1, Button::X2].into_iter().find(|b| b.name() == name)
    }
}

/// What a button message says happened.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Press {
    /// `WM_*BUTTONDOWN`.
    Down,
    /// `WM_*BUTTONUP`.
    Up,
    /// `WM_*BUTTONDBLCLK`: the second press of a double click (the class has `CS_DBLCLKS`).
    Double,
}

/// One line of the recorder's log.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Recorded {
    /// The first line: the window is up; where its client area is on the screen, and
    /// the system's double-click time.
    Ready { x: i32, y: i32, width: i32, height: i32, double_click_ms: u32 },
    /// `WM_KEYDOWN`/`WM_KEYUP`, or with `sys` `WM_SYSKEYDOWN`/`WM_SYSKEYUP`.
    Key {
        down: bool,
        #[serde(default)]
        sys: bool,
        vk: u16,
        #[serde(default)]
        scan: u16,
        #[serde(default)]
        extended: bool,
        /// The previous key state bit: the key was already down (auto-repeat).
        #[serde(default)]
        repeat: bool,
        #[serde(default)]
        mods: Mods,
        #[serde(default)]
        time: u32,
    },
    /// `WM_CHAR`, `WM_UNICHAR` or with `sys` `WM_SYSCHAR`: one character (a surrogate
    /// pair's two messages joined).
    Char {
        text: String,
        #[serde(default)]
        sys: bool,
        #[serde(default)]
        mods: Mods,
        #[serde(default)]
        time: u32,
    },
    /// A button message at client coordinates; `mk` is its `MK_*` flags as sent.
    Button {
        button: Button,
        press: Press,
        x: i32,
        y: i32,
        #[serde(default)]
        mods: Mods,
        #[serde(default)]
        mk: u32,
        #[serde(default)]
        time: u32,
    },
    /// `WM_MOUSEMOVE` at client coordinates.
    Move {
        x: i32,
        y: i32,
        #[serde(default)]
        mods: Mods,
        #[serde(default)]
        mk: u32,
        #[serde(default)]
        time: u32,
    },
    /// `WM_MOUSEWHEEL` (or `WM_MOUSEHWHEEL` when `horizontal`): the signed delta
    /// (120 a notch; positive is up, or right), at client coordinates.
    Wheel {
        #[serde(default)]
        horizontal: bool,
        delta: i32,
        x: i32,
        y: i32,
        #[serde(default)]
        mods: Mods,
        #[serde(default)]
        mk: u32,
        #[serde(default)]
        time: u32,
    },
    /// A line a newer recorder wrote that this build does not know.
    #[serde(other)]
    Unknown,
}

/// `MK_*` flags of mouse messages.
pub mod mk {
    pub const LBUTTON: u32 = 0x0001;
    pub const RBUTTON: u32 = 0x0002;
    pub const SHIFT: u32 = 0x0004;
    pub const CONTROL: u32 = 0x0008;
    pub const MBUTTON: u32 = 0x0010;
    pub const XBUTTON1: u32 = 0x0020;
    pub const XBUTTON2: u32 = 0x0040;
}

/// Reads a log: one [`Recorded`] per non-empty line.
///
/// # Errors
///
/// The line number and what was wrong with the first line that is not a record (a line
/// cut short by a recorder still writing is one).
pub fn parse_log(text: &str) -> Result<Vec<Recorded>, String> {
    text.lines()
        .enumerate()
        .filter(|(_, line)| !line.trim().is_empty())
        .map(|(n, line)| serde_json::from_str(line).map_err(|err| format!("line {}: {err}", n + 1)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_round_trip_as_json_lines() {
        let records = vec![
            Recorded::Ready { x: 0, y: 0, width: 800, height: 600, double_click_ms: 500 },
            Recorded::Key {
                down: true,
                sys: false,
                vk: 0x41,
                scan: 0x1e,
                extended: false,
                repeat: false,
                mods: Mods { shift: true, ..Mods::NONE },
                time: 7,
            },
            Recorded::Char { text: "😀".into(), sys: false, mods: Mods::NONE, time: 8 },
            Recorded::Button {
                button: Button::Left,
                press: Press::Double,
                x: 3,
                y: 4,
                mods: Mods::NONE,
                mk: mk::LBUTTON,
                time: 9,
            },
        ];
        let text: String = records.iter().map(|r| serde_json::to_string(r).unwrap() + "\n").collect();
        assert!(text.contains(r#""mods":"shift""#), "{text}");
        assert_eq!(parse_log(&text).unwrap(), records);
        assert_eq!(parse_log(r#"{"kind":"telepathy"}"#).unwrap(), vec![Recorded::Unknown]);
        let err = parse_log("{\"kind\":\"key\",\"down\":tr").unwrap_err();
        assert!(err.starts_with("line 1:"), "{err}");
    }

    #[test]
    fn modifiers_parse_and_print() {
        assert_eq!(Mods::parse("ctrl+shift").unwrap().to_string(), "shift+ctrl");
        assert_eq!(Mods::parse("").unwrap(), Mods::NONE);
        assert!(Mods::parse("hyper").unwrap_err().contains("hyper"));
    }
}
