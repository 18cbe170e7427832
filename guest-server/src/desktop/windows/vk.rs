//! pyautogui key names to Windows virtual-key strokes.
//!
//! The Windows backend sends keys with `SendInput`; this module decides *which*
//! strokes: the virtual-key code of each named key (pyautogui's `_pyautogui_win`
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

pub const VK_BACK: u16 = 0x08;
pub const VK_TAB: u16 = 0x09;
pub const VK_RETURN: u16 = 0x0D;
pub const VK_SHIFT: u16 = 0x10;
pub const VK_CONTROL: u16 = 0x11;
pub const VK_MENU: u16 = 0x12;

/// The virtual-key code of a canonical pyautogui key name, or `None` when Windows has
/// no such key (`fn`, `yen`) or the name is not a canonical one.
pub fn named_vk(name: &str) -> Option<u16> {
    let vk = match name {
        "backspace" => VK_BACK,
        "tab" => VK_TAB,
        "clear" => 0x0C,
        "enter" => VK_RETURN,
        "shift" => VK_SHIFT,
        "ctrl" => VK_CONTROL,
        "alt" => VK_MENU,
        "pause" => 0x13,
        "capslock" => 0x14,
        "kana" | "hangul" => 0x15,
        "junja" => 0x17,
        "final" => 0x18,
        "hanja" | "kanji" => 0x19,
        "esc" => 0x1B,
        "convert" => 0x1C,
        "nonconvert" => 0x1D,
        "accept" => 0x1E,
        "modechange" => 0x1F,
        "space" => 0x20,
        "pageup" => 0x21,
        "pagedown" => 0x22,
        "end" => 0x23,
        "home" => 0x24,
        "left" => 0x25,
        "up" => 0x26,
        "right" => 0x27,
        "down" => 0x28,
        "select" => 0x29,
        "execute" => 0x2B,
        "printscreen" => 0x2C,
        "insert" => 0x2D,
        "delete" => 0x2E,
        "help" => 0x2F,
        "win" | "winleft" => 0x5B,
        "winright" => 0x5C,
        "apps" => 0x5D,
        "sleep" => 0x5F,
        "multiply" => 0x6A,
        "add" => 0x6B,
        "separator" => 0x6C,
        "subtract" => 0x6D,
        "decimal" => 0x6E,
        "divide" => 0x6F,
        "numlock" => 0x90,
        "scrolllock" => 0x91,
        "shiftleft" => 0xA0,
        "shiftright" => 0xA1,
        "ctrlleft" => 0xA2,
        "ctrlright" => 0xA3,
        "altleft" => 0xA4,
        "altright" => 0xA5,
        "browserback" => 0xA6,
        "browserforward" => 0xA7,
        "browserrefresh" => 0xA8,
        "browserstop" => 0xA9,
        "browsersearch" => 0xAA,
        "browserfavorites" => 0xAB,
        "browserhome" => 0xAC,
        "volumemute" => 0xAD,
        "volumedown" => 0xAE,
        "volumeup" => 0xAF,
        "nexttrack" => 0xB0,
        "prevtrack" => 0xB1,
        "stop" => 0xB2,
        "playpause" => 0xB3,
        "launchmail" => 0xB4,
        "launchmediaselect" => 0xB5,
        "launchapp1" => 0xB6,
        "launchapp2" => 0xB7,
        other => {
            if let Some(n) = other.strip_prefix("num").and_then(|d| d.parse::<u16>().ok()).filter(|n| *n <= 9) {
                return Some(0x60 + n);
            }
            if let Some(n) =
                other.strip_prefix('f').and_then(|d| d.parse::<u16>().ok()).filter(|n| (1..=24).contains(n))
            {
                return Some(0x6F + n);
            }
            return None;
        }
    };
    Some(vk)
}

/// Whether `vk` is an extended key: its scan code needs `KEYEVENTF_EXTENDEDKEY`, or
/// the arrows act as the numeric keypad's.
pub fn is_extended(vk: u16) -> bool {
    matches!(
        vk,
        0x21..=0x28 // page up/down, end, home, arrows
            | 0x2C | 0x2D | 0x2E // print screen, insert, delete
            | 0x5B | 0x5C | 0x5D // windows keys, apps
            | 0x6F // divide
            | 0x90 // num lock
            | 0xA3 | 0xA5 // right ctrl, right alt
            | 0xA6..=0xB7 // browser, media and launch keys
    )
}

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
/// key up in reverse.
pub fn chord(keys: &[Key], layout: &dyn Fn(char) -> Option<CharKey>) -> Vec<Stroke> {
    let mut out: Vec<Stroke> = keys.iter().flat_map(|&k| key_down(k, layout)).collect();
    out.extend(keys.iter().rev().flat_map(|&k| key_up(k, layout)));
    out
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
