//! Top-level windows: enumeration, activation, show state and closing.

use std::collections::HashMap;
use std::time::{Duration, Instant};

use arena_shared::geometry::Rect;
use arena_shared::observation::WindowInfo;
use windows::core::PWSTR;
use windows::Win32::Foundation::{HWND, LPARAM, RECT, WPARAM};
use windows::Win32::Graphics::Dwm::{DwmGetWindowAttribute, DWMWA_CLOAKED};
use windows::Win32::System::Threading::{
    AttachThreadInput, GetCurrentThreadId, OpenProcess, QueryFullProcessImageNameW, PROCESS_NAME_WIN32,
    PROCESS_QUERY_LIMITED_INFORMATION,
};
use windows::Win32::UI::Input::KeyboardAndMouse::{
    SendInput, INPUT, INPUT_0, INPUT_KEYBOARD, KEYBDINPUT, KEYEVENTF_KEYUP, VIRTUAL_KEY,
};
use windows::Win32::UI::WindowsAndMessaging::{
    BringWindowToTop, EnumWindows, GetClassNameW, GetForegroundWindow, GetWindowLongPtrW, GetWindowRect,
    GetWindowTextW, GetWindowThreadProcessId, IsIconic, IsWindow, IsWindowVisible, IsZoomed, PostMessageW,
    SetForegroundWindow, SetWindowPos, ShowWindow, GWL_EXSTYLE, GWL_STYLE, SWP_NOACTIVATE, SWP_NOZORDER, SW_MAXIMIZE,
    SW_MINIMIZE, SW_RESTORE, WM_CLOSE,
};

use super::shell;
use super::sys::{os, Hwnd, OwnedHandle};
use crate::desktop::{DesktopError, DesktopResult, WindowState};

/// How long activation waits for the foreground to change before it gives up.
const ACTIVATE_WAIT: Duration = Duration::from_millis(300);

/// Every top-level window handle, topmost first (EnumWindows walks the z-order).
pub(super) fn top_level() -> Vec<HWND> {
    // SAFETY: a callback for EnumWindows below, which passes the LPARAM it was given.
    unsafe extern "system" fn collect(hwnd: HWND, lparam: LPARAM) -> windows::core::BOOL {
        // SAFETY: lparam is the &mut Vec<HWND> passed by top_level below, alive for the whole EnumWindows call.
        let list = unsafe { &mut *(lparam.0 as *mut Vec<HWND>) };
        list.push(hwnd);
        true.into()
    }
    let mut list: Vec<HWND> = Vec::new();
    // SAFETY: the callback only pushes into `list`, which outlives the call.
    if let Err(err) = unsafe { EnumWindows(Some(collect), LPARAM(&mut list as *mut Vec<HWND> as isize)) } {
        tracing::debug!(%err, "EnumWindows stopped early");
    }
    list
}

/// A window's title (`GetWindowTextW`; for other processes' windows this reads the
/// cached caption and never sends a message, so it cannot hang).
pub(super) fn title(hwnd: HWND) -> String {
    let mut buf = [0u16; 512];
    // SAFETY: the buffer is valid for its length; a dead hwnd just yields 0.
    let n = unsafe { GetWindowTextW(hwnd, &mut buf) };
    String::from_utf16_lossy(&buf[..usize::try_from(n).unwrap_or(0).min(buf.len())])
}

pub(super) fn class_name(hwnd: HWND) -> String {
    let mut buf = [0u16; 256];
    // SAFETY: as for GetWindowTextW.
    let n = unsafe { GetClassNameW(hwnd, &mut buf) };
    String::from_utf16_lossy(&buf[..usize::try_from(n).unwrap_or(0).min(buf.len())])
}

pub(super) fn rect(hwnd: HWND) -> Rect {
    let mut r = RECT::default();
    // SAFETY: r is a valid out-pointer; failure leaves it zeroed.
    let _ = unsafe { GetWindowRect(hwnd, &mut r) };
    Rect::from_ltrb(r.left, r.top, r.right, r.bottom)
}

/// The process id and thread id that own `hwnd`.
pub(super) fn owner(hwnd: HWND) -> (u32, u32) {
    let mut pid = 0u32;
    // SAFETY: pid is a valid out-pointer.
    let tid = unsafe { GetWindowThreadProcessId(hwnd, Some(&mut pid)) };
    (pid, tid)
}

/// Whether `hwnd` is minimised.
pub(super) fn is_minimized(hwnd: HWND) -> bool {
    // SAFETY: IsIconic accepts any window handle and only reads its state.
    unsafe { IsIconic(hwnd).as_bool() }
}

/// Whether the taskbar window (`Shell_TrayWnd`) exists and is visible.
pub(super) fn taskbar_shown() -> bool {
    top_level().into_iter().any(|hwnd| {
        // SAFETY: IsWindowVisible accepts any window handle and only reads its state.
        class_name(hwnd) == "Shell_TrayWnd" && unsafe { IsWindowVisible(hwnd) }.as_bool()
    })
}

/// What is in front of the desktop, for the shell's settle.
pub(super) fn front() -> crate::desktop::settle::Front {
    let hwnd = foreground();
    let seen = (!hwnd.is_invalid()).then(|| (class_name(hwnd), title(hwnd)));
    crate::desktop::settle::Front::of_window(seen.as_ref().map(|(class, title)| (class.as_str(), title.as_str())))
}

pub(super) fn foreground() -> HWND {
    // SAFETY: no preconditions.
    unsafe { GetForegroundWindow() }
}

/// The executable's file name of process `pid` (`notepad.exe`), or empty when the
/// process cannot be opened (another session, protected, or gone).
pub(super) fn process_name(pid: u32) -> String {
    // SAFETY: OpenProcess has no preconditions; the handle is owned by the guard at once.
    let Some(process) =
        (unsafe { OpenProcess(PROCESS_QUERY_LIMITED_INFORMATION, false, pid) }).ok().and_then(OwnedHandle::new)
    else {
        return String::new();
    };
    let mut buf = vec![0u16; 1024];
    let mut len = buf.len() as u32;
    // SAFETY: buf holds len UTF-16 units; the call writes at most that many and updates len.
    if unsafe { QueryFullProcessImageNameW(process.raw(), PROCESS_NAME_WIN32, PWSTR(buf.as_mut_ptr()), &mut len) }
        .is_err()
    {
        return String::new();
    }
    let full = String::from_utf16_lossy(&buf[..(len as usize).min(buf.len())]);
    full.rsplit(['\\', '/']).next().unwrap_or_default().to_owned()
}

/// A live top-level window, or [`DesktopError::NotFound`].
pub(super) fn live(id: u64) -> DesktopResult<HWND> {
    let hwnd = Hwnd::from_id(id).get();
    // SAFETY: IsWindow accepts any value and only answers whether it names a window.
    if id == 0 || !unsafe { IsWindow(Some(hwnd)) }.as_bool() {
        return Err(DesktopError::NotFound(format!("no window with id {id:#x}")));
    }
    Ok(hwnd)
}

/// Every top-level window, topmost first.
pub(super) fn list() -> Vec<WindowInfo> {
    let fg = foreground();
    let mut names: HashMap<u32, String> = HashMap::new();
    top_level()
        .into_iter()
        .enumerate()
        .map(|(z, hwnd)| {
            let (pid, _) = owner(hwnd);
            let process_name = names.entry(pid).or_insert_with(|| process_name(pid)).clone();
            // SAFETY: these queries accept any window handle and only read its state.
            let (minimized, maximized) = unsafe { (IsIconic(hwnd).as_bool(), IsZoomed(hwnd).as_bool()) };
            // A window DWM cloaks (a suspended UWP app, the closed Start menu) is never drawn.
            let facts = facts(hwnd, 0);
            let visible = facts.visible && facts.cloaked == 0;
            WindowInfo {
                id: Hwnd::id(hwnd),
                title: title(hwnd),
                class_name: class_name(hwnd),
                process_id: pid,
                process_name,
                rect: rect(hwnd),
                visible,
                minimized,
                maximized,
                focused: hwnd == fg,
                z_order: u32::try_from(z).unwrap_or(u32::MAX),
            }
        })
        .collect()
}

/// Sends the keys that give this process the foreground right (see
/// [`shell::foreground_unlock_keys`]: Alt with an unassigned key inside it, so no
/// program enters menu mode), then lets them reach the input queue.
fn unlock_foreground() {
    let inputs: Vec<INPUT> = shell::foreground_unlock_keys()
        .iter()
        .map(|k| INPUT {
            r#type: INPUT_KEYBOARD,
            Anonymous: INPUT_0 {
                ki: KEYBDINPUT {
                    wVk: VIRTUAL_KEY(k.vk),
                    wScan: 0,
                    dwFlags: if k.up { KEYEVENTF_KEYUP } else { Default::default() },
                    time: 0,
                    dwExtraInfo: 0,
                },
            },
        })
        .collect();
    // SAFETY: the slice holds initialised INPUT structures of the size passed.
    let sent = unsafe { SendInput(&inputs, std::mem::size_of::<INPUT>() as i32) };
    if sent as usize != inputs.len() {
        // Activation goes on with its other ways; say why this one may not have helped.
        tracing::warn!(sent, of = inputs.len(), "the foreground unlock keys were not accepted in full");
    }
    std::thread::sleep(Duration::from_millis(shell::UNLOCK_SETTLE_MS));
}

/// What DWM and the window's styles say about `hwnd`; `foreground_pid` is the
/// process of the foreground window.
pub(super) fn facts(hwnd: HWND, foreground_pid: u32) -> shell::WindowFacts {
    let mut cloaked = 0u32;
    // SAFETY: `cloaked` is a writable u32 of the size passed; a failure leaves it 0 (not cloaked).
    let _ = unsafe {
        DwmGetWindowAttribute(hwnd, DWMWA_CLOAKED, (&raw mut cloaked).cast(), std::mem::size_of::<u32>() as u32)
    };
    // SAFETY: these queries accept any window handle and only read its state.
    let (visible, ex_style, style) = unsafe {
        (
            IsWindowVisible(hwnd).as_bool(),
            GetWindowLongPtrW(hwnd, GWL_EXSTYLE) as u32,
            GetWindowLongPtrW(hwnd, GWL_STYLE) as u32,
        )
    };
    let (pid, _) = owner(hwnd);
    shell::WindowFacts {
        visible,
        cloaked,
        ex_style,
        style,
        foreground_process: pid != 0 && pid == foreground_pid,
        shell_class: shell::shell_class(&class_name(hwnd)),
    }
}

/// Whether a person could see `hwnd`: the roots the trees walk ([`shell::seen_on_desktop`]).
pub(super) fn seen(hwnd: HWND) -> bool {
    let (foreground_pid, _) = owner(foreground());
    !hwnd.is_invalid() && shell::seen_on_desktop(facts(hwnd, foreground_pid))
}

fn wait_foreground(hwnd: HWND) -> bool {
    let started = Instant::now();
    loop {
        if foreground() == hwnd {
            return true;
        }
        if started.elapsed() > ACTIVATE_WAIT {
            return false;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// Brings `id` to the foreground, restoring it if minimised.
///
/// Tries plain `SetForegroundWindow`, then the Alt tap, then attaching this thread's
/// input to the current foreground thread (which lifts the foreground lock).
pub(super) fn activate(id: u64) -> DesktopResult<()> {
    let hwnd = live(id)?;
    // SAFETY: hwnd was checked to be a window; ShowWindow's result is the previous visibility, not an error.
    unsafe {
        if IsIconic(hwnd).as_bool() {
            let _ = ShowWindow(hwnd, SW_RESTORE);
        }
        if SetForegroundWindow(hwnd).as_bool() && wait_foreground(hwnd) {
            return Ok(());
        }
    }
    unlock_foreground();
    // SAFETY: as above.
    if unsafe { SetForegroundWindow(hwnd) }.as_bool() && wait_foreground(hwnd) {
        return Ok(());
    }
    let (_, fg_thread) = owner(foreground());
    // SAFETY: no preconditions.
    let me = unsafe { GetCurrentThreadId() };
    // SAFETY: attaching two live threads' input queues; detached again right after.
    unsafe {
        let attached = fg_thread != 0 && fg_thread != me && AttachThreadInput(me, fg_thread, true).as_bool();
        let _ = BringWindowToTop(hwnd);
        let _ = SetForegroundWindow(hwnd);
        if attached {
            let _ = AttachThreadInput(me, fg_thread, false);
        }
    }
    if wait_foreground(hwnd) {
        Ok(())
    } else {
        Err(DesktopError::Os {
            op: "activate window",
            message: format!(
                "window {id:#x} ({:?}) did not come to the foreground; the foreground lock refused",
                title(hwnd)
            ),
        })
    }
}

/// Minimises, maximises or restores `id`.
pub(super) fn set_state(id: u64, state: WindowState) -> DesktopResult<()> {
    let hwnd = live(id)?;
    let cmd = match state {
        WindowState::Minimized => SW_MINIMIZE,
        WindowState::Maximized => SW_MAXIMIZE,
        WindowState::Normal => SW_RESTORE,
    };
    // SAFETY: hwnd names a window; the return value is the previous visibility, not an error.
    let _ = unsafe { ShowWindow(hwnd, cmd) };
    Ok(())
}

/// Moves and sizes `id` to `rect`, restoring it first when it is minimised or
/// maximised (a maximised window's position is the work area's, not its own).
pub(super) fn move_to(id: u64, rect: Rect) -> DesktopResult<()> {
    let hwnd = live(id)?;
    // SAFETY: hwnd names a window; ShowWindow's result is the previous visibility, not an error.
    unsafe {
        if IsIconic(hwnd).as_bool() || IsZoomed(hwnd).as_bool() {
            let _ = ShowWindow(hwnd, SW_RESTORE);
        }
    }
    // SAFETY: hwnd names a window; no z-order or activation change is asked for.
    unsafe { SetWindowPos(hwnd, None, rect.x, rect.y, rect.width, rect.height, SWP_NOZORDER | SWP_NOACTIVATE) }
        .map_err(|err| os("move window", &err))
}

/// Posts `WM_CLOSE` to `id` (never waits for the program).
pub(super) fn close(id: u64) -> DesktopResult<()> {
    let hwnd = live(id)?;
    // SAFETY: posting a message to a window is asynchronous and cannot block.
    unsafe { PostMessageW(Some(hwnd), WM_CLOSE, WPARAM(0), LPARAM(0)) }.map_err(|err| os("close window", &err))
}
