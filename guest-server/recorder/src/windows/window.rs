//! The recorder's window: a class registered with `CS_DBLCLKS` (so double clicks arrive
//! as `WM_*BUTTONDBLCLK`), a topmost popup over the given rectangle, and a window
//! procedure that writes one JSON line per input message, flushed at once.
//!
//! System keys (`WM_SYSKEYDOWN`, `WM_SYSCHAR`, `SC_KEYMENU`) are recorded and not passed
//! on, so Alt neither enters a menu loop nor closes the window (Alt+F4 is recorded like
//! any chord); the mouse is captured while a button is down, so a drag that leaves the
//! window is still recorded to its release.

use std::cell::RefCell;
use std::fs::File;
use std::io::Write;

use arena_shared::input_log::{mk, Button, Mods, Press, Recorded};
use windows::core::{w, PCWSTR};
use windows::Win32::Foundation::{HINSTANCE, HWND, LPARAM, LRESULT, POINT, RECT, WPARAM};
use windows::Win32::Graphics::Gdi::{ClientToScreen, GetStockObject, ScreenToClient, HBRUSH, WHITE_BRUSH};
use windows::Win32::System::LibraryLoader::GetModuleHandleW;
use windows::Win32::UI::Input::KeyboardAndMouse::{
    GetDoubleClickTime, GetKeyState, ReleaseCapture, SetCapture, SetFocus, VK_CONTROL, VK_LWIN, VK_MENU, VK_RWIN,
    VK_SHIFT,
};
use windows::Win32::UI::WindowsAndMessaging::{
    CreateWindowExW, DefWindowProcW, DestroyWindow, DispatchMessageW, GetClientRect, GetMessageTime, GetMessageW,
    GetSystemMetrics, LoadCursorW, PostQuitMessage, RegisterClassExW, SetForegroundWindow, TranslateMessage,
    CS_DBLCLKS, IDC_ARROW, MSG, SC_KEYMENU, SM_CXSCREEN, SM_CYSCREEN, WM_CHAR, WM_CLOSE, WM_DESTROY, WM_KEYDOWN,
    WM_KEYUP, WM_LBUTTONDBLCLK, WM_LBUTTONDOWN, WM_LBUTTONUP, WM_MBUTTONDBLCLK, WM_MBUTTONDOWN, WM_MBUTTONUP,
    WM_MOUSEHWHEEL, WM_MOUSEMOVE, WM_MOUSEWHEEL, WM_RBUTTONDBLCLK, WM_RBUTTONDOWN, WM_RBUTTONUP, WM_SYSCHAR,
    WM_SYSCOMMAND, WM_SYSKEYDOWN, WM_SYSKEYUP, WM_UNICHAR, WM_XBUTTONDBLCLK, WM_XBUTTONDOWN, WM_XBUTTONUP, WNDCLASSEXW,
    WS_EX_TOPMOST, WS_POPUP, WS_VISIBLE,
};

use crate::decode::{self, Utf16Joiner};

/// The log and what the window procedure keeps between messages.
struct Recorder {
    log: File,
    chars: Utf16Joiner,
    /// The first write that failed; the loop ends with it.
    failed: Option<String>,
}

thread_local! {
    static RECORDER: RefCell<Option<Recorder>> = const { RefCell::new(None) };
}

fn write(record: &Recorded) {
    RECORDER.with(|cell| {
        if let Some(rec) = cell.borrow_mut().as_mut() {
            if rec.failed.is_some() {
                return;
            }
            let mut line = serde_json::to_string(record).unwrap_or_default();
            line.push('\n');
            if let Err(err) = rec.log.write_all(line.as_bytes()).and_then(|()| rec.log.flush()) {
                rec.failed = Some(format!("writing the log: {err}"));
                // SAFETY: no preconditions; ends the loop of this thread.
                unsafe { PostQuitMessage(1) };
            }
        }
    });
}

fn held(vk: u16) -> bool {
    // SAFETY: GetKeyState takes any virtual key.
    unsafe { GetKeyState(i32::from(vk)) < 0 }
}

/// The modifier state as of the message being handled.
fn mods() -> Mods {
    Mods {
        shift: held(VK_SHIFT.0),
        ctrl: held(VK_CONTROL.0),
        alt: held(VK_MENU.0),
        win: held(VK_LWIN.0) || held(VK_RWIN.0),
    }
}

fn time() -> u32 {
    // SAFETY: no preconditions.
    unsafe { GetMessageTime() as u32 }
}

fn button_of(msg: u32, wparam: WPARAM) -> Option<(Button, Press)> {
    let x = || if decode::high_word(wparam.0) == 2 { Button::X2 } else { Button::X1 };
    Some(match msg {
        WM_LBUTTONDOWN => (Button::Left, Press::Down),
        WM_LBUTTONUP => (Button::Left, Press::Up),
        WM_LBUTTONDBLCLK => (Button::Left, Press::Double),
        WM_RBUTTONDOWN => (Button::Right, Press::Down),
        WM_RBUTTONUP => (Button::Right, Press::Up),
        WM_RBUTTONDBLCLK => (Button::Right, Press::Double),
        WM_MBUTTONDOWN => (Button::Middle, Press::Down),
        WM_MBUTTONUP => (Button::Middle, Press::Up),
        WM_MBUTTONDBLCLK => (Button::Middle, Press::Double),
        WM_XBUTTONDOWN => (x(), Press::Down),
        WM_XBUTTONUP => (x(), Press::Up),
        WM_XBUTTONDBLCLK => (x(), Press::Double),
        _ => return None,
    })
}

const ANY_BUTTON: u32 = mk::LBUTTON | mk::RBUTTON | mk::MBUTTON | mk::XBUTTON1 | mk::XBUTTON2;

extern "system" fn window_proc(hwnd: HWND, msg: u32, wparam: WPARAM, lparam: LPARAM) -> LRESULT {
    match msg {
        WM_KEYDOWN | WM_KEYUP | WM_SYSKEYDOWN | WM_SYSKEYUP => {
            let bits = decode::key_bits(lparam.0);
            write(&Recorded::Key {
                down: matches!(msg, WM_KEYDOWN | WM_SYSKEYDOWN),
                sys: matches!(msg, WM_SYSKEYDOWN | WM_SYSKEYUP),
                vk: (wparam.0 & 0xFFFF) as u16,
                scan: bits.scan,
                extended: bits.extended,
                repeat: bits.repeat,
                mods: mods(),
                time: time(),
            });
            return LRESULT(0);
        }
        WM_CHAR | WM_SYSCHAR => {
            let unit = (wparam.0 & 0xFFFF) as u16;
            let text = RECORDER.with(|cell| cell.borrow_mut().as_mut().and_then(|rec| rec.chars.push(unit)));
            if let Some(text) = text {
                write(&Recorded::Char { text, sys: msg == WM_SYSCHAR, mods: mods(), time: time() });
            }
            return LRESULT(0);
        }
        WM_UNICHAR => {
            // UNICODE_NOCHAR asks whether the window takes WM_UNICHAR: it does.
            if let Some(text) = decode::code_point(wparam.0) {
                write(&Recorded::Char { text, sys: false, mods: mods(), time: time() });
            }
            return LRESULT(1);
        }
        WM_MOUSEMOVE => {
            let (x, y) = decode::point(lparam.0);
            write(&Recorded::Move { x, y, mods: mods(), mk: decode::low_word(wparam.0), time: time() });
            return LRESULT(0);
        }
        WM_MOUSEWHEEL | WM_MOUSEHWHEEL => {
            // The wheel's position is in screen coordinates.
            let (sx, sy) = decode::point(lparam.0);
            let mut p = POINT { x: sx, y: sy };
            // SAFETY: hwnd is this window; p is a valid in-out pointer.
            let _ = unsafe { ScreenToClient(hwnd, &mut p) };
            write(&Recorded::Wheel {
                horizontal: msg == WM_MOUSEHWHEEL,
                delta: i32::from(decode::high_word(wparam.0)),
                x: p.x,
                y: p.y,
                mods: mods(),
                mk: decode::low_word(wparam.0),
                time: time(),
            });
            return LRESULT(0);
        }
        WM_SYSCOMMAND if (wparam.0 & 0xFFF0) as u32 == SC_KEYMENU => return LRESULT(0),
        WM_CLOSE => {
            // SAFETY: hwnd is this thread's window.
            let _ = unsafe { DestroyWindow(hwnd) };
            return LRESULT(0);
        }
        WM_DESTROY => {
            // SAFETY: no preconditions; ends this thread's loop.
            unsafe { PostQuitMessage(0) };
            return LRESULT(0);
        }
        _ => {}
    }
    if let Some((button, press)) = button_of(msg, wparam) {
        let (x, y) = decode::point(lparam.0);
        let flags = decode::low_word(wparam.0);
        write(&Recorded::Button { button, press, x, y, mods: mods(), mk: flags, time: time() });
        // A drag that leaves the window is still this window's until the last button is up.
        if press == Press::Up {
            if flags & ANY_BUTTON == 0 {
                // SAFETY: no preconditions.
                let _ = unsafe { ReleaseCapture() };
            }
        } else {
            // SAFETY: hwnd is this thread's window.
            unsafe { SetCapture(hwnd) };
        }
        // X buttons answer TRUE, as the documentation asks.
        return LRESULT(isize::from(matches!(msg, WM_XBUTTONDOWN | WM_XBUTTONUP | WM_XBUTTONDBLCLK)));
    }
    // SAFETY: the parameters are the ones this procedure was called with.
    unsafe { DefWindowProcW(hwnd, msg, wparam, lparam) }
}

fn wide(text: &str) -> Vec<u16> {
    text.encode_utf16().chain(std::iter::once(0)).collect()
}

pub(super) fn run(options: &crate::Options) -> Result<(), String> {
    let log = File::create(&options.log).map_err(|err| format!("creating the log {}: {err}", options.log.display()))?;
    RECORDER.with(|cell| *cell.borrow_mut() = Some(Recorder { log, chars: Utf16Joiner::default(), failed: None }));

    // SAFETY: GetModuleHandleW(None) is this exe's module; the class structure and the
    // strings outlive the calls; the window procedure has the WNDPROC signature.
    let hwnd = unsafe {
        let module = GetModuleHandleW(None).map_err(|err| format!("GetModuleHandleW: {err}"))?;
        let instance = HINSTANCE(module.0);
        let class_name = w!("ArenaInputRecorder");
        let class = WNDCLASSEXW {
            cbSize: std::mem::size_of::<WNDCLASSEXW>() as u32,
            style: CS_DBLCLKS,
            lpfnWndProc: Some(window_proc),
            hInstance: instance,
            hCursor: LoadCursorW(None, IDC_ARROW).unwrap_or_default(),
            hbrBackground: HBRUSH(GetStockObject(WHITE_BRUSH).0),
            lpszClassName: class_name,
            ..WNDCLASSEXW::default()
        };
        if RegisterClassExW(&class) == 0 {
            return Err(format!("RegisterClassExW: {}", windows::core::Error::from_thread()));
        }
        let width = options.width.unwrap_or_else(|| GetSystemMetrics(SM_CXSCREEN));
        let height = options.height.unwrap_or_else(|| GetSystemMetrics(SM_CYSCREEN));
        let title = wide(&options.title);
        CreateWindowExW(
            WS_EX_TOPMOST,
            class_name,
            PCWSTR(title.as_ptr()),
            WS_POPUP | WS_VISIBLE,
            options.x.unwrap_or(0),
            options.y.unwrap_or(0),
            width,
            height,
            None,
            None,
            Some(instance),
            None,
        )
        .map_err(|err| format!("CreateWindowExW: {err}"))?
    };
    // SAFETY: hwnd is this thread's window; the out-pointers are valid.
    let (origin, client) = unsafe {
        let _ = SetForegroundWindow(hwnd);
        let _ = SetFocus(Some(hwnd));
        let mut origin = POINT::default();
        let _ = ClientToScreen(hwnd, &mut origin);
        let mut client = RECT::default();
        let _ = GetClientRect(hwnd, &mut client);
        (origin, client)
    };
    // SAFETY: no preconditions.
    let double_click_ms = unsafe { GetDoubleClickTime() };
    write(&Recorded::Ready {
        x: origin.x,
        y: origin.y,
        width: client.right - client.left,
        height: client.bottom - client.top,
        double_click_ms,
    });

    let mut msg = MSG::default();
    // SAFETY: msg is a valid out-pointer; the loop runs on the window's thread.
    unsafe {
        while GetMessageW(&mut msg, None, 0, 0).as_bool() {
            let _ = TranslateMessage(&msg);
            DispatchMessageW(&msg);
        }
    }
    match RECORDER.with(|cell| cell.borrow_mut().take().and_then(|rec| rec.failed)) {
        Some(failed) => Err(failed),
        None => Ok(()),
    }
}
