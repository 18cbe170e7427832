//! What the desktop shell decides about top-level windows, as data: which
//! windows a person can see (so the trees and Set-of-Marks walk only those),
//! and the key sequence that lets the server take the foreground without
//! leaving the target program in menu mode.
//!
//! Platform-neutral and tested natively; `window.rs`, `uia.rs` and
//! `win32_tree.rs` make the calls (`IsWindowVisible`, `DwmGetWindowAttribute`
//! with `DWMWA_CLOAKED`, `GetWindowLongPtrW` with `GWL_STYLE` and `GWL_EXSTYLE`,
//! `GetClassNameW`, `GetWindowThreadProcessId`, `SendInput`), and the stub feeds its
//! scenario windows' facts through the same [`seen_on_desktop`].

/// `WS_EX_TOOLWINDOW`: a floating tool window, left out of the taskbar and Alt+Tab.
pub const WS_EX_TOOLWINDOW: u32 = 0x0000_0080;
/// `WS_EX_APPWINDOW`: forces a window onto the taskbar even when it is a tool window.
pub const WS_EX_APPWINDOW: u32 = 0x0004_0000;
/// `WS_EX_TOPMOST`: stays above every non-topmost window.
pub const WS_EX_TOPMOST: u32 = 0x0000_0008;
/// `WS_POPUP`: a pop-up window (menus, drop-down lists, tooltips, Chromium's pop-ups).
pub const WS_POPUP: u32 = 0x8000_0000;

/// Window classes USER32 and the shell give to windows a person sees although they
/// are tool windows, by what they are.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ShellClass {
    /// `#32768`: a popup menu (context menus, menu-bar menus).
    Menu,
    /// `ComboLBox`: a combo box's drop-down list.
    DropDown,
    /// `tooltips_class32`: a tooltip.
    ToolTip,
    /// `Shell_TrayWnd`, `Shell_SecondaryTrayWnd`: the taskbar (upstream lists it).
    Taskbar,
}

/// The [`ShellClass`] of a window class name, if it is one of them.
pub fn shell_class(class_name: &str) -> Option<ShellClass> {
    match class_name {
        "#32768" => Some(ShellClass::Menu),
        "ComboLBox" => Some(ShellClass::DropDown),
        c if c.eq_ignore_ascii_case("tooltips_class32") => Some(ShellClass::ToolTip),
        "Shell_TrayWnd" | "Shell_SecondaryTrayWnd" => Some(ShellClass::Taskbar),
        _ => None,
    }
}

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
    /// `GWL_STYLE`.
    pub style: u32,
    /// It belongs to the process of the foreground window (`GetWindowThreadProcessId`).
    pub foreground_process: bool,
    /// Its class, when it is a menu, drop-down, tooltip or the taskbar.
    pub shell_class: Option<ShellClass>,
}

/// Whether a person looking at the screen could see this window: visible and not
/// cloaked by DWM. Cloaked windows are `IsWindowVisible` but never drawn; walking
/// them costs tree budget and adds elements nobody can click.
///
/// Tool windows (`WS_EX_TOOLWINDOW` without `WS_EX_APPWINDOW`) are kept when a person
/// sees them as part of what they work with: pop-ups (`WS_POPUP`: an open menu, a
/// drop-down list, Chromium's and Electron's pop-ups), menus, drop-downs and tooltips
/// by class, topmost ones (the taskbar, on-screen overlays), those of the foreground
/// window's process (its palettes and floating toolbars), and the taskbar. What is
/// left out are the remaining tool windows of background processes: invisible-in-
/// practice helpers (zero-size or transparent message windows some programs keep
/// visible), which upstream's pywinauto enumeration lists but nobody can act on.
pub fn seen_on_desktop(facts: WindowFacts) -> bool {
    if !facts.visible || facts.cloaked != 0 {
        return false;
    }
    let tool = facts.ex_style & WS_EX_TOOLWINDOW != 0 && facts.ex_style & WS_EX_APPWINDOW == 0;
    !tool
        || facts.style & WS_POPUP != 0
        || facts.ex_style & WS_EX_TOPMOST != 0
        || facts.foreground_process
        || facts.shell_class.is_some()
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
    fn hidden_and_cloaked_windows_are_never_seen() {
        let shown = WindowFacts { visible: true, ..WindowFacts::default() };
        assert!(seen_on_desktop(shown));
        let popup_menu = WindowFacts {
            style: WS_POPUP,
            ex_style: WS_EX_TOOLWINDOW | WS_EX_TOPMOST,
            shell_class: shell_class("#32768"),
            ..shown
        };
        assert!(!seen_on_desktop(WindowFacts { visible: false, ..popup_menu }));
        // DWM_CLOAKED_APP (1), DWM_CLOAKED_SHELL (2), DWM_CLOAKED_INHERITED (4).
        for cloaked in [1, 2, 4] {
            assert!(!seen_on_desktop(WindowFacts { cloaked, ..shown }), "cloaked {cloaked}");
            assert!(!seen_on_desktop(WindowFacts { cloaked, ..popup_menu }), "cloaked popup {cloaked}");
        }
    }

    #[test]
    fn tool_windows_a_person_sees_are_kept() {
        let tool = WindowFacts { visible: true, ex_style: WS_EX_TOOLWINDOW, ..WindowFacts::default() };
        // A background process's plain tool window is left out.
        assert!(!seen_on_desktop(tool));
        // Unless it asks for a taskbar button, pops up, stays on top, belongs to the
        // foreground process or is a menu, drop-down, tooltip or the taskbar.
        assert!(seen_on_desktop(WindowFacts { ex_style: WS_EX_TOOLWINDOW | WS_EX_APPWINDOW, ..tool }));
        assert!(seen_on_desktop(WindowFacts { style: WS_POPUP, ..tool }));
        assert!(seen_on_desktop(WindowFacts { ex_style: WS_EX_TOOLWINDOW | WS_EX_TOPMOST, ..tool }));
        assert!(seen_on_desktop(WindowFacts { foreground_process: true, ..tool }));
        for class in ["#32768", "ComboLBox", "tooltips_class32", "Shell_TrayWnd", "Shell_SecondaryTrayWnd"] {
            assert!(seen_on_desktop(WindowFacts { shell_class: shell_class(class), ..tool }), "{class}");
        }
        assert_eq!(shell_class("Notepad"), None);
        assert_eq!(shell_class("#32770"), None, "a dialog is not a menu");
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
