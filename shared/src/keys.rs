//! pyautogui key names and key-chord parsing.
//!
//! Hosts name keys the way pyautogui does (`enter`, `ctrl`, `pgdn`, `f5`, or a
//! single printable character).
//! [`Key::parse`] accepts exactly pyautogui's `KEYBOARD_KEYS` (multi-character
//! names case-insensitively, as pyautogui lowercases them) and folds its
//! aliases onto one canonical name, so backends match on a small closed set.

use std::fmt;

/// A key, either a printable character or a canonical named key.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Key {
    /// A character key, typed with whatever modifiers the layout needs.
    Char(char),
    /// A named key, by its canonical pyautogui name (see [`NAMED_KEYS`]).
    Named(&'static str),
}

/// Canonical named keys. Aliases are folded onto these by [`Key::parse`].
pub const NAMED_KEYS: &[&str] = &[
    "accept",
    "add",
    "alt",
    "altleft",
    "altright",
    "apps",
    "backspace",
    "browserback",
    "browserfavorites",
    "browserforward",
    "browserhome",
    "browserrefresh",
    "browsersearch",
    "browserstop",
    "capslock",
    "clear",
    "convert",
    "ctrl",
    "ctrlleft",
    "ctrlright",
    "decimal",
    "delete",
    "divide",
    "down",
    "end",
    "enter",
    "esc",
    "execute",
    "f1",
    "f2",
    "f3",
    "f4",
    "f5",
    "f6",
    "f7",
    "f8",
    "f9",
    "f10",
    "f11",
    "f12",
    "f13",
    "f14",
    "f15",
    "f16",
    "f17",
    "f18",
    "f19",
    "f20",
    "f21",
    "f22",
    "f23",
    "f24",
    "final",
    "fn",
    "hangul",
    "hanja",
    "help",
    "home",
    "insert",
    "junja",
    "kana",
    "kanji",
    "launchapp1",
    "launchapp2",
    "launchmail",
    "launchmediaselect",
    "left",
    "modechange",
    "multiply",
    "nexttrack",
    "nonconvert",
    "num0",
    "num1",
    "num2",
    "num3",
    "num4",
    "num5",
    "num6",
    "num7",
    "num8",
    "num9",
    "numlock",
    "pagedown",
    "pageup",
    "pause",
    "playpause",
    "prevtrack",
    "printscreen",
    "right",
    "scrolllock",
    "select",
    "separator",
    "shift",
    "shiftleft",
    "shiftright",
    "sleep",
    "space",
    "stop",
    "subtract",
    "tab",
    "up",
    "volumedown",
    "volumemute",
    "volumeup",
    "win",
    "winleft",
    "winright",
    "yen",
];

/// pyautogui's alternative spellings and the canonical name each stands for.
const ALIASES: &[(&str, &str)] = &[
    ("escape", "esc"),
    ("return", "enter"),
    ("del", "delete"),
    ("pgdn", "pagedown"),
    ("pgup", "pageup"),
    ("hanguel", "hangul"),
    ("print", "printscreen"),
    ("prntscrn", "printscreen"),
    ("prtsc", "printscreen"),
    ("prtscr", "printscreen"),
    ("command", "ctrl"),
    ("option", "alt"),
    ("optionleft", "altleft"),
    ("optionright", "altright"),
    ("control", "ctrl"),
];

/// The keys an agent pressed with `keyDown` and has not released, so they can be
/// let go when its action ends.
///
/// pyautogui's `keyDown` leaves a key down until a `keyUp`; an agent that forgets
/// the `keyUp` (or whose code stops at an error between the two) leaves Shift or
/// Ctrl held for every later step, which then types capitals or opens menus.
/// Both sides feed every action they perform through [`HeldKeys::track`] and
/// send [`HeldKeys::releases`] when the agent's action (a code block, a typed
/// batch) is over. Keys compare by their parsed name, so `Shift` and `shift`
/// are one key and `shiftleft` another, as they are to the keyboard.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct HeldKeys {
    /// Oldest first.
    held: Vec<Key>,
}

impl HeldKeys {
    /// Notes what `action` does to the held keys: `KeyDown` holds, `KeyUp` releases.
    /// Other actions, and names that do not parse (the backend refused those), change nothing.
    pub fn track(&mut self, action: &crate::action::Action) {
        match action {
            crate::action::Action::KeyDown { key } => {
                if let Ok(key) = Key::parse(key) {
                    if !self.held.contains(&key) {
                        self.held.push(key);
                    }
                }
            }
            crate::action::Action::KeyUp { key } => {
                if let Ok(key) = Key::parse(key) {
                    self.held.retain(|k| *k != key);
                }
            }
            _ => {}
        }
    }

    /// Whether no key is held.
    pub fn is_empty(&self) -> bool {
        self.held.is_empty()
    }

    /// The `KeyUp` actions that let every held key go, the most recently pressed
    /// first (as a chord is released); afterwards nothing counts as held.
    pub fn releases(&mut self) -> Vec<crate::action::Action> {
        self.held.drain(..).rev().map(|key| crate::action::Action::KeyUp { key: key.to_string() }).collect()
    }
}

/// A key name that pyautogui does not know.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown key name {0:?} (expected a pyautogui key name such as \"enter\", \"ctrl\" or \"a\")")]
pub struct UnknownKey(pub String);

impl Key {
    /// Parses one pyautogui key name.
    ///
    /// Single characters are taken as they are (`"A"` is shift+a when typed);
    /// longer names are lowercased first, as pyautogui does.
    /// The control characters `\n`, `\r` and `\t` are Enter and Tab, and `" "` is Space.
    ///
    /// # Errors
    ///
    /// [`UnknownKey`] for a name pyautogui would silently ignore.
    pub fn parse(name: &str) -> Result<Key, UnknownKey> {
        let mut chars = name.chars();
        if let (Some(c), None) = (chars.next(), chars.next()) {
            return match c {
                '\n' | '\r' => Ok(Key::Named("enter")),
                '\t' => Ok(Key::Named("tab")),
                ' ' => Ok(Key::Named("space")),
                c if c.is_control() => Err(UnknownKey(name.to_owned())),
                c => Ok(Key::Char(c)),
            };
        }
        let lower = name.to_lowercase();
        if let Some(&canonical) = NAMED_KEYS.iter().find(|k| **k == lower) {
            return Ok(Key::Named(canonical));
        }
        if let Some((_, canonical)) = ALIASES.iter().find(|(alias, _)| *alias == lower) {
            let canonical = NAMED_KEYS.iter().find(|k| *k == canonical).copied();
            return canonical.map(Key::Named).ok_or_else(|| UnknownKey(name.to_owned()));
        }
        Err(UnknownKey(name.to_owned()))
    }

    /// Whether this is a modifier (ctrl, alt, shift, win and their sided forms).
    pub fn is_modifier(&self) -> bool {
        matches!(
            self,
            Key::Named(
                "ctrl"
                    | "ctrlleft"
                    | "ctrlright"
                    | "alt"
                    | "altleft"
                    | "altright"
                    | "shift"
                    | "shiftleft"
                    | "shiftright"
                    | "win"
                    | "winleft"
                    | "winright"
                    | "fn"
            )
        )
    }
}

impl fmt::Display for Key {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Key::Char(c) => write!(f, "{c}"),
            Key::Named(name) => f.write_str(name),
        }
    }
}

/// Splits a chord such as `"ctrl+shift+s"` or `"ctrl-c"` into keys.
///
/// This follows the WAA `Computer.keyboard.press` rule: a name longer than
/// one character that contains `+` is split on `+`, otherwise one that
/// contains `-` is split on `-`; parts are trimmed.
/// A single `"+"` or `"-"` is the key itself.
///
/// # Errors
///
/// [`UnknownKey`] naming the first part that is not a key.
pub fn parse_chord(chord: &str) -> Result<Vec<Key>, UnknownKey> {
    let parts: Vec<&str> = if chord.chars().count() > 1 && chord.contains('+') {
        chord.split('+').collect()
    } else if chord.chars().count() > 1 && chord.contains('-') {
        chord.split('-').collect()
    } else {
        vec![chord]
    };
    parts
        .into_iter()
        .map(|part| {
            let trimmed = if part.chars().count() > 1 { part.trim() } else { part };
            if trimmed.is_empty() {
                return Err(UnknownKey(chord.to_owned()));
            }
            Key::parse(trimmed)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(input: &str, expected: &[Key]) {
        assert_eq!(parse_chord(input).unwrap(), expected, "chord {input:?}");
    }

    #[test]
    fn chords_split_like_waa() {
        check("ctrl+c", &[Key::Named("ctrl"), Key::Char('c')]);
        check("ctrl-shift-s", &[Key::Named("ctrl"), Key::Named("shift"), Key::Char('s')]);
        check("Ctrl + Alt + Delete", &[Key::Named("ctrl"), Key::Named("alt"), Key::Named("delete")]);
        check("+", &[Key::Char('+')]);
        check("-", &[Key::Char('-')]);
        check("enter", &[Key::Named("enter")]);
        check("ENTER", &[Key::Named("enter")]);
        check("pgdn", &[Key::Named("pagedown")]);
        check("\n", &[Key::Named("enter")]);
        check("A", &[Key::Char('A')]);
    }

    #[test]
    fn unknown_names_are_errors() {
        assert_eq!(Key::parse("enterr"), Err(UnknownKey("enterr".into())));
        assert!(parse_chord("ctrl+").is_err());
        assert!(Key::parse("\u{7}").is_err());
    }

    #[test]
    fn every_alias_resolves() {
        for (alias, _) in ALIASES {
            assert!(Key::parse(alias).is_ok(), "{alias}");
        }
    }

    proptest::proptest! {
        #[test]
        fn chord_parser_never_panics(s in "\\PC{0,12}") {
            let _ = parse_chord(&s);
        }
    }

    #[test]
    fn held_keys_are_released_newest_first_and_only_once() {
        use crate::action::Action;
        let mut held = HeldKeys::default();
        for action in [
            Action::KeyDown { key: "Shift".into() },
            Action::KeyDown { key: "ctrl".into() },
            Action::KeyDown { key: "shift".into() },
            Action::Click { x: None, y: None, button: crate::action::MouseButton::Left, count: 1 },
            Action::KeyDown { key: "a".into() },
            Action::KeyUp { key: "A".into() },
            Action::KeyDown { key: "no-such-key".into() },
        ] {
            held.track(&action);
        }
        // `A` is not `a` (a character key keeps its case), so `a` stays held.
        assert_eq!(
            held.releases(),
            vec![
                Action::KeyUp { key: "a".into() },
                Action::KeyUp { key: "ctrl".into() },
                Action::KeyUp { key: "shift".into() },
            ]
        );
        assert!(held.is_empty());
        assert!(held.releases().is_empty());
        held.track(&Action::KeyDown { key: "alt".into() });
        held.track(&Action::KeyUp { key: "ALT".into() });
        assert!(held.is_empty(), "{held:?}");
    }
}
