//! The `win32` accessibility source: window and child-window enumeration.
//!
//! Text comes from `WM_GETTEXT` through `SendMessageTimeoutW`, so a hung window costs
//! [`MESSAGE_TIMEOUT`] and never the server; windows Windows already knows are hung
//! (`IsHungAppWindow`) are not asked at all. Edit controls also get their MSAA value
//! (`AccessibleObjectFromWindow` + `get_accValue`), as pywinauto's win32 backend reports
//! it, when the window answered in time. The walk itself is
//! [`arena_a11y_walk::walk`].

use std::collections::HashSet;
use std::time::Duration;

use arena_shared::observation::A11yNode;
use windows::Win32::Foundation::{HWND, LPARAM, WPARAM};
use windows::Win32::System::Com::COINIT_MULTITHREADED;
use windows::Win32::System::Variant::{VARIANT, VT_I4};
use windows::Win32::UI::Accessibility::{AccessibleObjectFromWindow, IAccessible};
use windows::Win32::UI::Input::KeyboardAndMouse::IsWindowEnabled;
use windows::Win32::UI::WindowsAndMessaging::{
    EnumChildWindows, GetAncestor, GetGUIThreadInfo, GetWindowLongPtrW, IsHungAppWindow, IsIconic, IsWindowVisible,
    IsZoomed, SendMessageTimeoutW, BM_GETCHECK, BS_TYPEMASK, ES_READONLY, GA_PARENT, GUITHREADINFO, GWL_STYLE,
    OBJID_CLIENT, SMTO_ABORTIFHUNG, SMTO_BLOCK, WM_GETTEXT, WM_GETTEXTLENGTH,
};

use super::sys::ComApartment;
use super::window;
use crate::desktop::DesktopResult;
use arena_a11y_walk::{win32_role, TreeSource, Win32Props};

/// The longest a window may take to answer one message.
const MESSAGE_TIMEOUT: Duration = Duration::from_millis(150);
/// The most text read from one window (edit controls can hold megabytes).
const MAX_TEXT_UNITS: usize = 1 << 20;

/// Sends `msg` with a timeout; `None` when the window did not answer in time.
fn send(hwnd: HWND, msg: u32, wparam: usize, lparam: isize) -> Option<usize> {
    let mut result = 0usize;
    // SAFETY: a message to a window with a bounded wait; lparam is either 0 or a buffer
    // the caller keeps alive and sized as wparam says.
    let ok = unsafe {
        SendMessageTimeoutW(
            hwnd,
            msg,
            WPARAM(wparam),
            LPARAM(lparam),
            SMTO_ABORTIFHUNG | SMTO_BLOCK,
            MESSAGE_TIMEOUT.as_millis() as u32,
            Some(&mut result),
        )
    };
    (ok.0 != 0).then_some(result)
}

/// A window's text by `WM_GETTEXT`, `None` if it did not answer.
fn text(hwnd: HWND) -> Option<String> {
    let len = send(hwnd, WM_GETTEXTLENGTH, 0, 0)?.min(MAX_TEXT_UNITS);
    if len == 0 {
        return Some(String::new());
    }
    let mut buf = vec![0u16; len + 1];
    let copied = send(hwnd, WM_GETTEXT, buf.len(), buf.as_mut_ptr() as isize)?;
    Some(String::from_utf16_lossy(&buf[..copied.min(len)]))
}

/// The MSAA value of `hwnd`'s client object, if it has one.
fn msaa_value(hwnd: HWND) -> Option<String> {
    let mut raw: *mut core::ffi::c_void = std::ptr::null_mut();
    // SAFETY: asks for IAccessible into a valid out-pointer; ownership passes to `acc` below.
    unsafe {
        AccessibleObjectFromWindow(
            hwnd,
            OBJID_CLIENT.0 as u32,
            &<IAccessible as windows::core::Interface>::IID,
            &mut raw,
        )
    }
    .ok()?;
    if raw.is_null() {
        return None;
    }
    // SAFETY: the call succeeded, so `raw` is an owned IAccessible reference.
    let acc = unsafe { <IAccessible as windows::core::Interface>::from_raw(raw) };
    let mut child = VARIANT::default();
    // SAFETY: writes the VT_I4 tag and value (CHILDID_SELF = 0) of a zeroed VARIANT.
    unsafe {
        (*child.Anonymous.Anonymous).vt = VT_I4;
        (*child.Anonymous.Anonymous).Anonymous.lVal = 0;
    }
    // SAFETY: a COM call on a live interface with a valid VARIANT.
    let value = unsafe { acc.get_accValue(&child) }.ok()?;
    Some(value.to_string())
}

/// The walk's view of the desktop's windows.
pub(super) struct Win32Source {
    roots: HashSet<isize>,
    foreground: HWND,
    focus: HWND,
    /// COM for MSAA on this thread, when it could be initialised.
    com: Option<ComApartment>,
}

impl Win32Source {
    pub(super) fn new() -> Win32Source {
        let foreground = window::foreground();
        let (_, thread) = window::owner(foreground);
        let mut info = GUITHREADINFO { cbSize: std::mem::size_of::<GUITHREADINFO>() as u32, ..Default::default() };
        // SAFETY: info's cbSize is set; on failure the focus stays unknown.
        let focus = if thread != 0 && unsafe { GetGUIThreadInfo(thread, &mut info) }.is_ok() {
            info.hwndFocus
        } else {
            HWND::default()
        };
        let com = ComApartment::init(COINIT_MULTITHREADED)
            .map_err(|err| tracing::debug!(%err, "no COM for MSAA values"))
            .ok();
        Win32Source { roots: HashSet::new(), foreground, focus, com }
    }
}

impl TreeSource for Win32Source {
    type Elem = HWND;
    type Error = crate::desktop::DesktopError;

    fn foreground_id(&mut self) -> Option<u64> {
        (!self.foreground.is_invalid()).then(|| super::sys::Hwnd::id(self.foreground))
    }

    fn roots(&mut self, foreground_only: bool) -> DesktopResult<Vec<(u64, HWND)>> {
        // Hidden, cloaked (suspended UWP apps, Start and Search) and tool windows are not walked.
        let visible = |hwnd: &HWND| window::seen(*hwnd);
        let roots: Vec<HWND> = if foreground_only {
            Some(self.foreground).filter(|h| !h.is_invalid() && visible(h)).into_iter().collect()
        } else {
            window::top_level().into_iter().filter(visible).collect()
        };
        self.roots = roots.iter().map(|h| h.0 as isize).collect();
        Ok(roots.into_iter().map(|h| (super::sys::Hwnd::id(h), h)).collect())
    }

    fn record(&mut self, hwnd: &HWND) -> A11yNode {
        let hwnd = *hwnd;
        let class_name = window::class_name(hwnd);
        // SAFETY: these accept any handle and only read window state.
        let hung = unsafe { IsHungAppWindow(hwnd) }.as_bool();
        let text = if hung { None } else { text(hwnd) };
        let r = window::rect(hwnd);
        let is_root = self.roots.contains(&(hwnd.0 as isize));
        // SAFETY: as above.
        let style = unsafe { GetWindowLongPtrW(hwnd, GWL_STYLE) } as i32;
        let role = win32_role(&class_name);
        let is_edit = role == "Edit";
        let checkable = role == "Button" && matches!(style & BS_TYPEMASK, 2..=6 | 9);
        let checked = if checkable && !hung { send(hwnd, BM_GETCHECK, 0, 0).map(|v| v == 1) } else { None };
        let msaa = if is_edit && text.is_some() && self.com.is_some() { msaa_value(hwnd) } else { None };
        // SAFETY: as above.
        let (visible, enabled, minimized, maximized) = unsafe {
            (
                IsWindowVisible(hwnd).as_bool(),
                IsWindowEnabled(hwnd).as_bool(),
                IsIconic(hwnd).as_bool(),
                IsZoomed(hwnd).as_bool(),
            )
        };
        Win32Props {
            class_name,
            text,
            ltrb: [r.x, r.y, r.right(), r.bottom()],
            visible,
            enabled,
            focused: hwnd == self.focus || (is_root && hwnd == self.foreground),
            minimized: is_root.then_some(minimized),
            maximized: is_root.then_some(maximized),
            msaa_value: msaa,
            read_only: is_edit.then_some(style & ES_READONLY != 0),
            checked,
        }
        .into_node()
    }

    fn children(&mut self, hwnd: &HWND, limit: usize) -> Vec<HWND> {
        struct Collect {
            parent: HWND,
            limit: usize,
            out: Vec<HWND>,
        }
        // SAFETY: a callback for EnumChildWindows below, which passes the LPARAM it was given.
        unsafe extern "system" fn each(child: HWND, lparam: LPARAM) -> windows::core::BOOL {
            // SAFETY: lparam is the &mut Collect passed below, alive for the whole call.
            let c = unsafe { &mut *(lparam.0 as *mut Collect) };
            // EnumChildWindows visits all descendants; keep the direct children.
            // SAFETY: GetAncestor accepts any handle.
            if unsafe { GetAncestor(child, GA_PARENT) } == c.parent {
                c.out.push(child);
            }
            (c.out.len() <= c.limit).into()
        }
        let mut c = Collect { parent: *hwnd, limit, out: Vec::new() };
        // SAFETY: the callback only touches `c`, which outlives the call.
        let _ = unsafe { EnumChildWindows(Some(*hwnd), Some(each), LPARAM(&mut c as *mut Collect as isize)) };
        c.out
    }
}
