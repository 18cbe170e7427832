//! pyautogui key names to Windows virtual-key strokes.
//!
//! The Windows backend sends keys with `SendInput`; this module decides *which*
//! strokes: the virtual-key code of each named key (`arena_shared::vkeys`, pyautogui's `_pyautogui_win`
//! table), which keys need the extended-key flag, which modifiers a character needs
//! on the current layout (from `VkKeyScanW`, asked through a closure), and the order
//! of downs and ups for presses, chords and typed text.
//!
//! It is platform-neutral and tested natively; the `SendInput` and `MapVirtualKeyW`
//! calls are in `desktop/windows/input.rs`.
//!
//! Typed text ([`type_text`]) goes as pyautogui's `write` sends it: every character the
//! foreground window's layout has a key for is that key (with Shift when it needs it),
//! so `keydown` handlers (a checkbox's Space, a web page, Calculator) see real keys.
//! Differences from pyautogui, on purpose: a character the layout cannot type, or only
//! with Ctrl or AltGr (which could fire a shortcut), is sent as a Unicode keystroke
//! (`KEYEVENTF_UNICODE`) instead of being dropped silently. Keys pyautogui knows but
//! Windows has no key for (`fn`, `yen`) are no-ops, as in pyautogui.

use arena_shared::keys::Key;

pub use arena_shared::vkeys::{is_extended, named_vk, VK_BACK, VK_CONTROL, VK_MENU, VK_RETURN, VK_SHIFT, VK_TAB};

/// What `VkKeyScanW` says about a character on the current layout.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CharKey {
    pub vk: u16,
    pub shift: bool,
    pub ctrl: bool,
    pub alt: bool,
    /// A dead key on this layout (US-International's `'`, `"`, `` ` ``, `~`, `^`):
    /// pressing it types nothing until the next key, which it may turn into an
    /// accented letter (`'` then `e` is `é`). [`type_text`] types these as Unicode.
    pub dead: bool,
}

impl CharKey {
    /// Decodes `VkKeyScanW`'s answer: low byte the key, high byte the shift state
    /// (1 shift, 2 ctrl, 4 alt); -1 (or a key byte of 0xFF) means the layout has no key.
    pub fn from_vk_scan(value: i16) -> Option<CharKey> {
        let bits = value as u16;
        let vk = bits & 0xFF;
        let state = bits >> 8;
        if value == -1 || vk == 0xFF || state & !0x7 != 0 {
            return None;
        }
        Some(CharKey { vk, shift: state & 1 != 0, ctrl: state & 2 != 0, alt: state & 4 != 0, dead: false })
    }

    fn modifiers(&self) -> Vec<u16> {
        let mut mods = Vec::new();
        if self.alt {
            mods.push(VK_MENU);
        }
        if self.ctrl {
            mods.push(VK_CONTROL);
        }
        if self.shift {
            mods.push(VK_SHIFT);
        }
        mods
    }
}

/// One keyboard event.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stroke {
    /// A virtual key going down or up.
    Vk { vk: u16, up: bool },
    /// One UTF-16 unit sent with `KEYEVENTF_UNICODE`.
    Unicode { unit: u16, up: bool },
}

fn vk(vk: u16, up: bool) -> Stroke {
    Stroke::Vk { vk, up }
}

/// How a key is typed on this layout.
enum Plan {
    /// No key on Windows: nothing to send.
    Nothing,
    /// A virtual key, with the modifiers it needs held around its down stroke.
    Key { vk: u16, mods: Vec<u16> },
    /// A character the layout cannot type: Unicode strokes.
    Unicode(char),
}

fn plan(key: Key, layout: &dyn Fn(char) -> Option<CharKey>) -> Plan {
    match key {
        Key::Named(name) => match named_vk(name) {
            Some(code) => Plan::Key { vk: code, mods: Vec::new() },
            None => Plan::Nothing,
        },
        Key::Char(c) => match layout(c) {
            Some(ck) => Plan::Key { vk: ck.vk, mods: ck.modifiers() },
            None => Plan::Unicode(c),
        },
    }
}

fn unicode(c: char, up: bool) -> Vec<Stroke> {
    let mut buf = [0u16; 2];
    c.encode_utf16(&mut buf).iter().map(|&unit| Stroke::Unicode { unit, up }).collect()
}

/// Strokes that hold `key` down, as pyautogui's `keyDown`: the modifiers a character
/// needs go down, the key goes down, the modifiers come back up.
pub fn key_down(key: Key, layout: &dyn Fn(char) -> Option<CharKey>) -> Vec<Stroke> {
    match plan(key, layout) {
        Plan::Nothing => Vec::new(),
        Plan::Key { vk: code, mods } => {
            let mut out: Vec<Stroke> = mods.iter().map(|&m| vk(m, false)).collect();
            out.push(vk(code, false));
            out.extend(mods.iter().rev().map(|&m| vk(m, true)));
            out
        }
        Plan::Unicode(c) => unicode(c, false),
    }
}

/// Strokes that release `key`.
pub fn key_up(key: Key, layout: &dyn Fn(char) -> Option<CharKey>) -> Vec<Stroke> {
    match plan(key, layout) {
        Plan::Nothing => Vec::new(),
        Plan::Key { vk: code, .. } => vec![vk(code, true)],
        Plan::Unicode(c) => unicode(c, true),
    }
}

/// Strokes that press and release `key` once, its modifiers held for the whole press.
pub fn press(key: Key, layout: &dyn Fn(char) -> Option<CharKey>) -> Vec<Stroke> {
    match plan(key, layout) {
        Plan::Nothing => Vec::new(),
        Plan::Key { vk: code, mods } => {
            let mut out: Vec<Stroke> = mods.iter().map(|&m| vk(m, false)).collect();
            out.push(vk(code, false));
            out.push(vk(code, true));
            out.extend(mods.iter().rev().map(|&m| vk(m, true)));
            out
        }
        Plan::Unicode(c) => {
            let mut out = unicode(c, false);
            out.extend(unicode(c, true));
            out
        }
    }
}

/// Strokes of a chord, as pyautogui's `hotkey`: every key down in order, then every
/// key up in reverse. A character that needs a modifier the chord already holds (the
/// `A` of `shift`+`A`) is not given it again: pressing and releasing Shift around the
/// key would let Shift go in the middle of the chord.
pub fn chord(keys: &[Key], layout: &dyn Fn(char) -> Option<CharKey>) -> Vec<Stroke> {
    let mut out = Vec::new();
    let mut held: Vec<u16> = Vec::new();
    for &key in keys {
        match plan(key, layout) {
            Plan::Key { vk: code, mods } => {
                let extra: Vec<u16> = mods.into_iter().filter(|&m| !holds(&held, m)).collect();
                out.extend(extra.iter().map(|&m| vk(m, false)));
                out.push(vk(code, false));
                out.extend(extra.iter().rev().map(|&m| vk(m, true)));
                held.push(code);
            }
            _ => out.extend(key_down(key, layout)),
        }
    }
    out.extend(keys.iter().rev().flat_map(|&k| key_up(k, layout)));
    out
}

/// Whether the keys `held` hold the modifier `m` (`VK_SHIFT`, `VK_CONTROL` or
/// `VK_MENU`), by its generic or its left or right key.
fn holds(held: &[u16], m: u16) -> bool {
    let sides: &[u16] = match m {
        VK_SHIFT => &[VK_SHIFT, 0xA0, 0xA1],
        VK_CONTROL => &[VK_CONTROL, 0xA2, 0xA3],
        VK_MENU => &[VK_MENU, 0xA4, 0xA5],
        other => return held.contains(&other),
    };
    held.iter().any(|h| sides.contains(h))
}

/// Strokes that type `text`, one group per character (so a caller can pause between
/// characters, as pyautogui's `interval` does): line breaks (CRLF, CR or LF give one
/// Enter) and tabs as their keys, a character the layout types plainly or with Shift
/// as that key press, anything else as Unicode strokes.
pub fn type_text(text: &str, layout: &dyn Fn(char) -> Option<CharKey>) -> Vec<Vec<Stroke>> {
    let mut groups = Vec::new();
    let mut chars = text.chars().peekable();
    while let Some(c) = chars.next() {
        let group = match c {
            '\r' => {
                if chars.peek() == Some(&'\n') {
                    chars.next();
                }
                vec![vk(VK_RETURN, false), vk(VK_RETURN, true)]
            }
            '\n' => vec![vk(VK_RETURN, false), vk(VK_RETURN, true)],
            '\t' => vec![vk(VK_TAB, false), vk(VK_TAB, true)],
            c => match layout(c) {
                // A dead key would wait for the next character and may merge with it
                // (`'` then `e` typing `é` on US-International): a Unicode packet types
                // the character itself, whatever the layout.
                Some(key) if !key.ctrl && !key.alt && !key.dead => press(Key::Char(c), layout),
                _ => {
                    let mut g = unicode(c, false);
                    g.extend(unicode(c, true));
                    g
                }
            },
        };
        groups.push(group);
    }
    groups
}

#[cfg(test)]
mod tests {
    use super::*;
    use arena_shared::keys::{Key, NAMED_KEYS};

    /// A US layout for the characters the tests use.
    fn us(c: char) -> Option<CharKey> {
        let plain = |vk| Some(CharKey { vk, shift: false, ctrl: false, alt: false, dead: false });
        let shifted = |vk| Some(CharKey { vk, shift: true, ctrl: false, alt: false, dead: false });
        match c {
            'a'..='z' => plain(c.to_ascii_uppercase() as u16),
            'A'..='Z' => shifted(c as u16),
            '0'..='9' => plain(c as u16),
            '!' => shifted(0x31),
            '+' => shifted(0xBB),
            _ => None,
        }
    }

    fn check(strokes: Vec<Stroke>, expected: &[(u16, bool)]) {
        let want: Vec<Stroke> = expected.iter().map(|&(v, up)| Stroke::Vk { vk: v, up }).collect();
        assert_eq!(strokes, want);
    }

    #[test]
    fn every_canonical_name_has_a_key_except_fn_and_yen() {
        for name in NAMED_KEYS {
            let got = named_vk(name);
            if matches!(*name, "fn" | "yen") {
                assert_eq!(got, None, "{name}");
            } else {
                assert!(got.is_some(), "{name} has no virtual key");
            }
        }
        assert_eq!(named_vk("f1"), Some(0x70));
        assert_eq!(named_vk("f24"), Some(0x87));
        assert_eq!(named_vk("f25"), None);
        assert_eq!(named_vk("num0"), Some(0x60));
        assert_eq!(named_vk("num9"), Some(0x69));
        assert_eq!(named_vk("num10"), None);
        assert_eq!(named_vk("printscreen"), Some(0x2C));
        assert_eq!(named_vk("winleft"), Some(0x5B));
    }

    #[test]
    fn extended_keys_are_the_navigation_cluster_and_right_modifiers() {
        for code in [0x25, 0x2E, 0x24, 0xA3, 0xA5, 0x5B, 0x6F] {
            assert!(is_extended(code), "{code:#x}");
        }
        for code in [VK_RETURN, 0x41, VK_SHIFT, 0xA2, 0x60] {
            assert!(!is_extended(code), "{code:#x}");
        }
    }

    #[test]
    fn vk_scan_answers_decode() {
        assert_eq!(
            CharKey::from_vk_scan(0x0141),
            Some(CharKey { vk: 0x41, shift: true, ctrl: false, alt: false, dead: false })
        );
        assert_eq!(
            CharKey::from_vk_scan(0x0641),
            Some(CharKey { vk: 0x41, shift: false, ctrl: true, alt: true, dead: false })
        );
        assert_eq!(CharKey::from_vk_scan(-1), None);
        assert_eq!(CharKey::from_vk_scan(0x00FF), None);
    }

    #[test]
    fn a_shifted_character_is_pressed_with_shift_around_it() {
        check(press(Key::Char('A'), &us), &[(VK_SHIFT, false), (0x41, false), (0x41, true), (VK_SHIFT, true)]);
        check(press(Key::Char('a'), &us), &[(0x41, false), (0x41, true)]);
        check(press(Key::Named("enter"), &us), &[(VK_RETURN, false), (VK_RETURN, true)]);
        assert!(press(Key::Named("fn"), &us).is_empty());
    }

    #[test]
    fn a_chord_does_not_press_again_a_modifier_it_holds() {
        // The input catalogue's `press_upper_a` in OpenAI's space: keys SHIFT and A.
        check(
            chord(&[Key::Named("shift"), Key::Char('A')], &us),
            &[(VK_SHIFT, false), (0x41, false), (0x41, true), (VK_SHIFT, true)],
        );
        // Held by its left key, it is held too (a modifier the chord lacks still comes and
        // goes around its character: ctrl and `+` in `chords_release_in_reverse`).
        check(
            chord(&[Key::Named("shiftleft"), Key::Char('!')], &us),
            &[(0xA0, false), (0x31, false), (0x31, true), (0xA0, true)],
        );
    }

    #[test]
    fn chords_release_in_reverse() {
        let keys = [Key::Named("ctrl"), Key::Named("shift"), Key::Char('s')];
        check(
            chord(&keys, &us),
            &[
                (VK_CONTROL, false),
                (VK_SHIFT, false),
                (0x53, false),
                (0x53, true),
                (VK_SHIFT, true),
                (VK_CONTROL, true),
            ],
        );
        // A character that needs shift holds it only around its own down stroke, as pyautogui does.
        check(
            chord(&[Key::Named("ctrl"), Key::Char('+')], &us),
            &[
                (VK_CONTROL, false),
                (VK_SHIFT, false),
                (0xBB, false),
                (VK_SHIFT, true),
                (0xBB, true),
                (VK_CONTROL, true),
            ],
        );
    }

    #[test]
    fn characters_without_a_key_become_unicode_strokes() {
        assert_eq!(
            press(Key::Char('é'), &us),
            vec![Stroke::Unicode { unit: 0xE9, up: false }, Stroke::Unicode { unit: 0xE9, up: true }]
        );
        // Outside the BMP: both surrogates go down, then both come up.
        let strokes = press(Key::Char('😀'), &us);
        assert_eq!(strokes.len(), 4);
        assert_eq!(strokes[0], Stroke::Unicode { unit: 0xD83D, up: false });
        assert_eq!(strokes[3], Stroke::Unicode { unit: 0xDE00, up: true });
    }

    #[test]
    fn typed_text_is_unicode_with_enter_and_tab_as_keys() {
        let groups = type_text("a\r\nb\tü\n", &us);
        assert_eq!(groups.len(), 6);
        // `a` is on the layout: its real key.
        assert_eq!(groups[0], vec![Stroke::Vk { vk: 0x41, up: false }, Stroke::Vk { vk: 0x41, up: true }]);
        assert_eq!(groups[1], vec![Stroke::Vk { vk: VK_RETURN, up: false }, Stroke::Vk { vk: VK_RETURN, up: true }]);
        assert_eq!(groups[3], vec![Stroke::Vk { vk: VK_TAB, up: false }, Stroke::Vk { vk: VK_TAB, up: true }]);
        // `ü` is not on a US layout: Unicode strokes.
        assert_eq!(
            groups[4],
            vec![Stroke::Unicode { unit: 0xFC, up: false }, Stroke::Unicode { unit: 0xFC, up: true }]
        );
        assert_eq!(type_text("\r\r", &us).len(), 2);
        assert!(type_text("", &us).is_empty());
        // A capital holds Shift around its key.
        let shifted = [
            Stroke::Vk { vk: VK_SHIFT, up: false },
            Stroke::Vk { vk: 0x48, up: false },
            Stroke::Vk { vk: 0x48, up: true },
            Stroke::Vk { vk: VK_SHIFT, up: true },
        ];
        assert_eq!(type_text("H", &us), vec![shifted.to_vec()]);
        // On a German layout `ü` has its own key, and `@` needs AltGr (Ctrl+Alt): Unicode.
        let de = |c: char| match c {
            'ü' => Some(CharKey { vk: 0xBA, shift: false, ctrl: false, alt: false, dead: false }),
            '@' => Some(CharKey { vk: 0x51, shift: false, ctrl: true, alt: true, dead: false }),
            other => us(other),
        };
        assert_eq!(
            type_text("ü", &de),
            vec![vec![Stroke::Vk { vk: 0xBA, up: false }, Stroke::Vk { vk: 0xBA, up: true }]]
        );
        assert_eq!(
            type_text("@", &de),
            vec![vec![Stroke::Unicode { unit: 0x40, up: false }, Stroke::Unicode { unit: 0x40, up: true }]]
        );
    }

    #[test]
    fn dead_keys_of_us_international_are_typed_as_unicode() {
        // US-International (KBDUSX): `'` and `"` (VK_OEM_7), `` ` `` and `~` (VK_OEM_3) and
        // `^` (Shift+6) are dead keys; `é` is AltGr+E.
        let intl = |c: char| {
            let dead = |vk, shift| Some(CharKey { vk, shift, ctrl: false, alt: false, dead: true });
            match c {
                '\'' => dead(0xDE, false),
                '"' => dead(0xDE, true),
                '`' => dead(0xC0, false),
                '~' => dead(0xC0, true),
                '^' => dead(0x36, true),
                'é' => Some(CharKey { vk: 0x45, shift: false, ctrl: true, alt: true, dead: false }),
                other => us(other),
            }
        };
        let typed = type_text("it's \"e\" ^~`é", &intl);
        let unicode = |c: char| {
            let unit = u16::try_from(u32::from(c)).unwrap();
            vec![Stroke::Unicode { unit, up: false }, Stroke::Unicode { unit, up: true }]
        };
        // Letters keep their keys; every dead-key character is its own Unicode packet, so
        // `'` before `s` and `"` before `e` cannot merge into accents.
        assert_eq!(typed[0], press(Key::Char('i'), &intl));
        assert_eq!(typed[2], unicode('\''));
        assert_eq!(typed[3], press(Key::Char('s'), &intl));
        assert_eq!(typed[5], unicode('"'));
        assert_eq!(typed[6], press(Key::Char('e'), &intl));
        assert_eq!(typed[7], unicode('"'));
        assert_eq!(&typed[9..12], &[unicode('^'), unicode('~'), unicode('`')]);
        assert_eq!(typed[12], unicode('é'));
        // A key press of a dead key is still the key, as a person pressing it gets.
        assert_eq!(
            press(Key::Char('\''), &intl),
            vec![Stroke::Vk { vk: 0xDE, up: false }, Stroke::Vk { vk: 0xDE, up: true }]
        );
    }
}
