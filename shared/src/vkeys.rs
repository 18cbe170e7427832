//! Windows virtual-key codes of pyautogui's key names (pyautogui's `_pyautogui_win`
//! table) and which of them are extended keys.
//!
//! One table for both sides: the guest's Windows backend sends these codes with
//! `SendInput` (`guest-server/src/desktop/windows/vk.rs` plans the strokes), the stub's
//! model of the input recorder writes them, and the host's input check
//! (`arena-inputcheck`) names the keys it expects a recorder to see with them.

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

/// `VK_PACKET`: the key of a `KEYEVENTF_UNICODE` stroke, whose scan code is the UTF-16 unit.
pub const VK_PACKET: u16 = 0xE7;

/// The virtual-key code a key name stands for: a canonical pyautogui name
/// ([`named_vk`]), a letter or digit (its upper-case ASCII code, as Windows numbers
/// them), `packet` ([`VK_PACKET`]), or a code in hex (`0xbf`, the US layout's `/` key).
pub fn vk_code(name: &str) -> Option<u16> {
    let mut chars = name.chars();
    if let (Some(c), None) = (chars.next(), chars.next()) {
        if c.is_ascii_alphanumeric() {
            return Some(c.to_ascii_uppercase() as u16);
        }
    }
    if name == "packet" {
        return Some(VK_PACKET);
    }
    if let Some(hex) = name.strip_prefix("0x") {
        return u16::from_str_radix(hex, 16).ok();
    }
    named_vk(name)
}

/// A name for `vk` that [`vk_code`] reads back (the first canonical name with that
/// code), or the code in hex (`0xba`) when it has none.
pub fn vk_name(vk: u16) -> String {
    if let Ok(b) = u8::try_from(vk) {
        if b.is_ascii_digit() || b.is_ascii_uppercase() {
            return char::from(b.to_ascii_lowercase()).to_string();
        }
    }
    if vk == VK_PACKET {
        return "packet".into();
    }
    crate::keys::NAMED_KEYS
        .iter()
        .find(|name| named_vk(name) == Some(vk))
        .map_or_else(|| format!("{vk:#04x}"), |name| (*name).to_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_and_codes_go_both_ways() {
        for name in ["a", "z", "0", "9", "shift", "ctrl", "alt", "esc", "f5", "f24", "left", "packet", "win"] {
            let code = vk_code(name).unwrap_or_else(|| panic!("{name} has no code"));
            assert_eq!(vk_code(&vk_name(code)), Some(code), "{name}");
        }
        assert_eq!(vk_code("A"), Some(0x41));
        assert_eq!(vk_code("enter"), Some(0x0D));
        assert_eq!(vk_code("nosuchkey"), None);
        assert_eq!(vk_name(0xBA), "0xba");
        assert_eq!(vk_code("0xba"), Some(0xBA));
        assert_eq!(vk_name(0x5B), "win");
    }
}
