//! What an input message's parameters say, as the Win32 documentation lays them out:
//! the keystroke bits of `lParam` (scan code bits 16-23, extended bit 24, previous-state
//! bit 30), signed client coordinates in `lParam`'s two words, the wheel's signed delta
//! in `wParam`'s high word, the `MK_*` flags in its low word, and UTF-16 units joined
//! into characters (a surrogate pair arrives as two `WM_CHAR`s).
//!
//! Platform-neutral: the window procedure in [`crate::windows`] hands the raw numbers here.

/// The keystroke bits of a key message's `lParam`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct KeyBits {
    pub scan: u16,
    pub extended: bool,
    pub repeat: bool,
}

/// Decodes a `WM_KEYDOWN`-family `lParam`.
pub fn key_bits(lparam: isize) -> KeyBits {
    let bits = lparam as u32;
    KeyBits { scan: ((bits >> 16) & 0xFF) as u16, extended: bits & (1 << 24) != 0, repeat: bits & (1 << 30) != 0 }
}

/// The signed x and y in the low and high words of a mouse message's `lParam`
/// (`GET_X_LPARAM`, `GET_Y_LPARAM`).
pub fn point(lparam: isize) -> (i32, i32) {
    let bits = lparam as u32;
    (i32::from((bits & 0xFFFF) as u16 as i16), i32::from((bits >> 16) as u16 as i16))
}

/// The signed high word of `wParam` (`GET_WHEEL_DELTA_WPARAM`), and for X buttons
/// which one (`GET_XBUTTON_WPARAM`).
pub fn high_word(wparam: usize) -> i16 {
    ((wparam as u32) >> 16) as u16 as i16
}

/// The `MK_*` flags in the low word of `wParam` (`GET_KEYSTATE_WPARAM`).
pub fn low_word(wparam: usize) -> u32 {
    (wparam as u32) & 0xFFFF
}

/// Joins UTF-16 units into characters: a high surrogate waits for its low half; a
/// lone half is U+FFFD, as a lossy decoder gives it.
#[derive(Debug, Default)]
pub struct Utf16Joiner {
    high: Option<u16>,
}

impl Utf16Joiner {
    /// The text `unit` completes, if any (a lone high surrogate left waiting comes out
    /// as U+FFFD before it).
    pub fn push(&mut self, unit: u16) -> Option<String> {
        if (0xD800..0xDC00).contains(&unit) {
            let lone = self.high.replace(unit).map(|_| "\u{FFFD}".to_owned());
            return lone;
        }
        let units: Vec<u16> = match self.high.take() {
            Some(high) if (0xDC00..0xE000).contains(&unit) => vec![high, unit],
            Some(_) => return Some(format!("\u{FFFD}{}", String::from_utf16_lossy(&[unit]))),
            None => vec![unit],
        };
        Some(String::from_utf16_lossy(&units))
    }
}

/// A `WM_UNICHAR` code point as text (`None` for `UNICODE_NOCHAR`, the query whether
/// the window takes the message, and for what is no character).
pub fn code_point(value: usize) -> Option<String> {
    let value = u32::try_from(value).ok()?;
    if value == 0xFFFF {
        return None;
    }
    char::from_u32(value).map(String::from)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keystroke_bits_are_read_where_windows_puts_them() {
        // Left arrow: scan 0x4B, extended; the previous-state bit of an auto-repeat.
        let lparam = (0x4B << 16) | (1 << 24) | (1 << 30) | 1;
        assert_eq!(key_bits(lparam), KeyBits { scan: 0x4B, extended: true, repeat: true });
        // A key-up's transition bit (31) makes lParam negative as an isize on 32 bits.
        let up = (0x1Eu32 << 16 | 1 << 30 | 1 << 31 | 1) as i32 as isize;
        assert_eq!(key_bits(up), KeyBits { scan: 0x1E, extended: false, repeat: true });
    }

    #[test]
    fn coordinates_and_wheel_deltas_are_signed() {
        let lparam = ((-5i16 as u16 as u32) | (300u32 << 16)) as isize;
        assert_eq!(point(lparam), (-5, 300));
        let wparam = ((-240i16 as u16 as usize) << 16) | 0x0004;
        assert_eq!(high_word(wparam), -240);
        assert_eq!(low_word(wparam), 0x0004);
    }

    #[test]
    fn surrogate_pairs_are_joined_and_lone_halves_replaced() {
        let mut j = Utf16Joiner::default();
        let units: Vec<u16> = "a😀".encode_utf16().collect();
        let out: Vec<Option<String>> = units.iter().map(|&u| j.push(u)).collect();
        assert_eq!(out, vec![Some("a".into()), None, Some("😀".into())]);
        assert_eq!(j.push(0xD83D), None);
        assert_eq!(j.push(u16::from(b'b')), Some("\u{FFFD}b".into()));
        assert_eq!(j.push(0xDE00), Some("\u{FFFD}".into()));
        assert_eq!(code_point(0x1F600), Some("😀".into()));
        assert_eq!(code_point(0xFFFF), None);
    }
}
