//! What the desktop shell decides about top-level windows, as data: which
//! windows a person can see (so the trees and Set-of-Marks walk only those),
//! and the key sequence that lets the server take the foreground without
//! leaving the target program in menu mode.
//!
//! Platform-neutral and tested natively; `window.rs`, `uia.rs` and
//! `win32_tree.rs` make the calls (`IsWindowVisible`, `DwmGetWindowAttribute`
//! with `DWMWA_CLOAKED`, `GetWindowLongPtrW(GWL_EXSTYLE)`, `SendInput`).

/// `WS_EX_TOOLWINDOW`: a floating tool window, left out of the taskbar and Alt+Tab.
pub const WS_EX_TOOLWINDOW: u32 = 0x0000_0080;
/// `WS_EX_APPWINDOW`: forces a window onto the taskbar even when it is a tool window.
pub const WS_EX_APPWINDOW: u32 = 0x0004_0000;

/// What the shell says about one top-level window.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct WindowFacts {
    /// `IsWindowVisible`: the window has `WS_VISIBLE` (and so do its owners).
    pub visible: bool,
    /// `DWMWA_CLOAKED`: non-zero when DWM hides it (a suspended UWP app, a window
    /// on another virtual desktop, the Start and Search hosts while closed).
    pub cloaked: u32,
    /// `GWL_EXSTYLE`.
    pub ex_style: u32,
}

/// Whether a person looking at the screen could see this window as a window of
/// its own: visible, not cloaked by DWM, and not a tool window (unless it asks
/// for a taskbar button). Cloaked windows are `IsWindowVisible` but never drawn;
/// walking them costs tree budget and adds elements nobody can click.
pub fn seen_on_desktop(facts: WindowFacts) -> bool {
    let tool = facts.ex_style & WS_EX_TOOLWINDOW != 0 && facts.ex_style & WS_EX_APPWINDOW == 0;
    facts.visible && facts.cloaked == 0 && !tool
}

/// `VK_MENU`, the Alt key.
pub const VK_ALT: u16 = 0x12;

/// A virtual-key code no keyboard layout assigns (0xE8 is listed as unassigned),
/// pressed between Alt's down and up so the Alt release is not a bare Alt tap.
pub const VK_MENU_MASK: u16 = 0xE8;

/// One keyboard event: a virtual-key code going down or up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct KeyEvent {
    pub vk: u16,
    pub up: bool,
}

/// The input that gives this process the right to set the foreground window.
///
/// Windows lets the process that sent the last input event take the foreground.
/// A bare Alt tap is the usual way, but a lone Alt release tells the program that
/// has the focus to enter menu mode (LibreOffice, VLC, VS Code, Chrome, Edge and
/// Explorer underline their menus and eat the next keystroke). An unassigned key
/// pressed while Alt is down makes Alt a modifier of that key instead, so its
/// release opens no menu, and no program acts on the unassigned key.
pub fn foreground_unlock_keys() -> [KeyEvent; 4] {
    [
        KeyEvent { vk: VK_ALT, up: false },
        KeyEvent { vk: VK_MENU_MASK, up: false },
        KeyEvent { vk: VK_MENU_MASK, up: true },
        KeyEvent { vk: VK_ALT, up: true },
    ]
}

/// How long to let the unlock keys reach the input queue before asking for the
/// foreground: `SendInput` returns before the events are processed, and the right
/// is granted when they are.
pub const UNLOCK_SETTLE_MS: u64 = 30;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_visible_uncloaked_non_tool_windows_are_seen() {
        let shown = WindowFacts { visible: true, cloaked: 0, ex_style: 0 };
        assert!(seen_on_desktop(shown));
        assert!(!seen_on_desktop(WindowFacts { visible: false, ..shown }));
        // DWM_CLOAKED_APP (1), DWM_CLOAKED_SHELL (2), DWM_CLOAKED_INHERITED (4).
        for cloaked in [1, 2, 4] {
            assert!(!seen_on_desktop(WindowFacts { cloaked, ..shown }), "cloaked {cloaked}");
        }
        assert!(!seen_on_desktop(WindowFacts { ex_style: WS_EX_TOOLWINDOW, ..shown }));
        assert!(seen_on_desktop(WindowFacts { ex_style: WS_EX_TOOLWINDOW | WS_EX_APPWINDOW, ..shown }));
    }

    #[test]
    fn the_unlock_sequence_never_releases_a_bare_alt() {
        let keys = foreground_unlock_keys();
        // Every key that goes down comes up, and Alt comes up last with another key
        // pressed and released while it was held: no bare Alt tap.
        let alt_down = keys.iter().position(|k| k.vk == VK_ALT && !k.up).unwrap();
        let alt_up = keys.iter().position(|k| k.vk == VK_ALT && k.up).unwrap();
        assert!(alt_down < alt_up);
        let between: Vec<_> = keys[alt_down + 1..alt_up].iter().collect();
        assert!(between.iter().any(|k| k.vk != VK_ALT && !k.up), "{keys:?}");
        for k in keys.iter().filter(|k| !k.up) {
            assert!(keys.iter().any(|u| u.vk == k.vk && u.up), "{:#x} is never released", k.vk);
        }
        assert_eq!(keys.last(), Some(&KeyEvent { vk: VK_ALT, up: true }));
    }
}
