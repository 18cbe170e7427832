//! The events a case expects, written as short lines in the catalogue:
//!
//! | line | event |
//! |---|---|
//! | `kd KEY`, `ku KEY` | `WM_KEYDOWN`/`WM_KEYUP` of the virtual key `KEY` (`arena_shared::vkeys::vk_code` names: `a`, `shift`, `f5`, `packet`) |
//! | `char TEXT`, `syschar TEXT` | `WM_CHAR`/`WM_SYSCHAR` with `TEXT` (everything after one space, control characters included; the modifiers after a tab) |
//! | `down BUTTON X,Y`, `up ...`, `dbl ...` | a button message (`left`, `right`, `middle`, `x1`, `x2`) at screen point `X,Y` |
//! | `move X,Y` | a `WM_MOUSEMOVE` at `X,Y` somewhere before the next event (other moves are skipped) |
//! | `wheel DELTA [X,Y]`, `hwheel DELTA [X,Y]` | a wheel message with that signed delta (and point) |
//!
//! Words after these: `+shift+ctrl` the modifiers held (none when absent; they are
//! always compared, so a key left down shows), `sys` for the `WM_SYS*` form of a key,
//! `ext` / `!ext` the extended-key bit, `scan=0x1e` the scan code (bit and scan code
//! are compared only when written). Points are screen pixels; the recorder's client
//! coordinates are moved by the origin its first line gives.

use std::fmt;

use arena_shared::input_log::{Button, Mods, Press};
use arena_shared::vkeys;

/// One expected event.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Expected {
    Key { down: bool, vk: u16, sys: bool, mods: Mods, extended: Option<bool>, scan: Option<u16> },
    Char { text: String, sys: bool, mods: Mods },
    Button { button: Button, press: Press, at: (i32, i32), mods: Mods },
    Move { at: (i32, i32) },
    Wheel { horizontal: bool, delta: i32, at: Option<(i32, i32)>, mods: Mods },
}

impl Expected {
    /// Reads one line of the notation above.
    ///
    /// # Errors
    ///
    /// A message naming what is wrong: an unknown event word, key, button or
    /// modifier, a point that is not `X,Y`, a word that does not belong.
    pub fn parse(line: &str) -> Result<Expected, String> {
        let (head, rest) = line.split_once(' ').unwrap_or((line, ""));
        if head == "char" || head == "syschar" {
            if rest.is_empty() {
                return Err(format!("{line:?}: {head} needs the text"));
            }
            // The modifiers, when given, follow the text after a tab (a tab that is the
            // text itself, `char \t`, is followed by none).
            let (text, mods) = match rest.rsplit_once('\t') {
                Some((text, mods)) if !text.is_empty() && mods.starts_with('+') => (text, parse_mods(mods)?),
                _ => (rest, Mods::NONE),
            };
            return Ok(Expected::Char { text: text.to_owned(), sys: head == "syschar", mods });
        }
        let mut words = rest.split_whitespace();
        let mut first = || words.next().ok_or_else(|| format!("{line:?}: {head} needs an argument"));
        let event = match head {
            "kd" | "ku" => {
                let name = first()?;
                let vk = vkeys::vk_code(name).ok_or_else(|| format!("{line:?}: unknown key {name:?}"))?;
                Expected::Key { down: head == "kd", vk, sys: false, mods: Mods::NONE, extended: None, scan: None }
            }
            "down" | "up" | "dbl" => {
                let name = first()?;
                let button = Button::from_name(name).ok_or_else(|| format!("{line:?}: unknown button {name:?}"))?;
                let press = match head {
                    "down" => Press::Down,
                    "up" => Press::Up,
                    _ => Press::Double,
                };
                Expected::Button { button, press, at: point(line, first()?)?, mods: Mods::NONE }
            }
            "move" => Expected::Move { at: point(line, first()?)? },
            "wheel" | "hwheel" => {
                let text = first()?;
                let delta = text.parse().map_err(|_| format!("{line:?}: the delta {text:?} is not a number"))?;
                Expected::Wheel { horizontal: head == "hwheel", delta, at: None, mods: Mods::NONE }
            }
            other => return Err(format!("{line:?}: unknown event {other:?} (expected kd, ku, char, syschar, down, up, dbl, move, wheel or hwheel)")),
        };
        let mut event = event;
        for word in words {
            match (&mut event, word) {
                (Expected::Key { sys, .. }, "sys") => *sys = true,
                (Expected::Key { extended, .. }, "ext") => *extended = Some(true),
                (Expected::Key { extended, .. }, "!ext") => *extended = Some(false),
                (Expected::Key { scan, .. }, w) if w.starts_with("scan=") => {
                    let hex = w.trim_start_matches("scan=").trim_start_matches("0x");
                    *scan = Some(u16::from_str_radix(hex, 16).map_err(|_| format!("{line:?}: bad scan code {w:?}"))?);
                }
                (Expected::Wheel { at, .. }, w) if at.is_none() && w.contains(',') => *at = Some(point(line, w)?),
                (Expected::Key { mods, .. } | Expected::Button { mods, .. } | Expected::Wheel { mods, .. }, w)
                    if w.starts_with('+') =>
                {
                    *mods = parse_mods(w)?;
                }
                (_, w) => return Err(format!("{line:?}: {w:?} does not belong here")),
            }
        }
        Ok(event)
    }
}

fn parse_mods(word: &str) -> Result<Mods, String> {
    Mods::parse(word.trim_start_matches('+'))
}

fn point(line: &str, text: &str) -> Result<(i32, i32), String> {
    let bad = || format!("{line:?}: {text:?} is not a point X,Y");
    let (x, y) = text.split_once(',').ok_or_else(bad)?;
    Ok((x.trim().parse().map_err(|_| bad())?, y.trim().parse().map_err(|_| bad())?))
}

fn mods_suffix(mods: Mods) -> String {
    if mods == Mods::NONE {
        String::new()
    } else {
        format!(" +{mods}")
    }
}

/// A character as the notation shows it: control characters escaped.
pub(crate) fn shown_text(text: &str) -> String {
    text.chars().map(|c| if c.is_control() { c.escape_default().to_string() } else { c.to_string() }).collect()
}

impl fmt::Display for Expected {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Expected::Key { down, vk, sys, mods, extended, scan } => {
                write!(f, "{} {}{}", if *down { "kd" } else { "ku" }, vkeys::vk_name(*vk), mods_suffix(*mods))?;
                if *sys {
                    f.write_str(" sys")?;
                }
                match extended {
                    Some(true) => f.write_str(" ext")?,
                    Some(false) => f.write_str(" !ext")?,
                    None => {}
                }
                if let Some(scan) = scan {
                    write!(f, " scan={scan:#04x}")?;
                }
                Ok(())
            }
            Expected::Char { text, sys, mods } => {
                write!(f, "{} {}{}", if *sys { "syschar" } else { "char" }, shown_text(text), mods_suffix(*mods))
            }
            Expected::Button { button, press, at, mods } => {
                let word = match press {
                    Press::Down => "down",
                    Press::Up => "up",
                    Press::Double => "dbl",
                };
                write!(f, "{word} {} {},{}{}", button.name(), at.0, at.1, mods_suffix(*mods))
            }
            Expected::Move { at } => write!(f, "move {},{}", at.0, at.1),
            Expected::Wheel { horizontal, delta, at, mods } => {
                write!(f, "{} {delta}", if *horizontal { "hwheel" } else { "wheel" })?;
                if let Some((x, y)) = at {
                    write!(f, " {x},{y}")?;
                }
                f.write_str(&mods_suffix(*mods))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_read_and_print_back() {
        for line in [
            "kd shift +shift",
            "ku a +shift",
            "kd left ext scan=0x4b",
            "kd tab +alt sys",
            "down left 400,300 +shift",
            "dbl right 10,20",
            "move 5,6",
            "wheel -360 400,300",
            "hwheel 120",
            "char A +shift",
            "syschar x +alt",
        ] {
            // The modifiers of a character follow a tab.
            let written = if line.starts_with("char") || line.starts_with("syschar") {
                line.replacen(" +", "\t+", 1)
            } else {
                line.to_owned()
            };
            let event = Expected::parse(&written).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(event.to_string(), line);
        }
        assert_eq!(
            Expected::parse("char \t").unwrap(),
            Expected::Char { text: "\t".into(), sys: false, mods: Mods::NONE }
        );
        assert_eq!(
            Expected::parse("syschar \t\t+alt").unwrap(),
            Expected::Char { text: "\t".into(), sys: true, mods: Mods::parse("alt").unwrap() }
        );
        assert_eq!(
            Expected::parse("char  ").unwrap(),
            Expected::Char { text: " ".into(), sys: false, mods: Mods::NONE }
        );
    }

    #[test]
    fn bad_lines_say_what_is_wrong() {
        for (line, says) in [
            ("kd nosuchkey", "unknown key"),
            ("kd", "needs an argument"),
            ("down thumb 1,2", "unknown button"),
            ("down left 1;2", "not a point"),
            ("wheel many", "not a number"),
            ("jump 1,2", "unknown event"),
            ("kd a +hyper", "unknown modifier"),
            ("move 1,2 sys", "does not belong"),
            ("kd a scan=zz", "bad scan code"),
            ("char", "needs the text"),
        ] {
            let err = Expected::parse(line).unwrap_err();
            assert!(err.contains(says), "{line}: {err}");
        }
    }
}
