//! Mouse and keyboard input through `SendInput`, with pyautogui's semantics.
//!
//! Which strokes to send is decided by the neutral [`crate::desktop::windows::vk`] and
//! [`crate::desktop::windows::pointer`] modules; this file turns them into `INPUT` records.

use std::time::Duration;

use arena_shared::action::{Action, MouseButton};
use arena_shared::geometry::{Point, Rect};
use arena_shared::keys::{parse_chord, Key};
use windows::Win32::Foundation::POINT;
use windows::Win32::UI::Input::KeyboardAndMouse::{
    GetKeyboardLayout, MapVirtualKeyExW, SendInput, ToUnicodeEx, VkKeyScanExW, HKL, INPUT, INPUT_0, INPUT_KEYBOARD,
    INPUT_MOUSE, KEYBDINPUT, KEYBD_EVENT_FLAGS, KEYEVENTF_EXTENDEDKEY, KEYEVENTF_KEYUP, KEYEVENTF_UNICODE,
    MAPVK_VK_TO_VSC, MOUSEEVENTF_ABSOLUTE, MOUSEEVENTF_HWHEEL, MOUSEEVENTF_LEFTDOWN, MOUSEEVENTF_LEFTUP,
    MOUSEEVENTF_MIDDLEDOWN, MOUSEEVENTF_MIDDLEUP, MOUSEEVENTF_MOVE, MOUSEEVENTF_RIGHTDOWN, MOUSEEVENTF_RIGHTUP,
    MOUSEEVENTF_VIRTUALDESK, MOUSEEVENTF_WHEEL, MOUSEINPUT, MOUSE_EVENT_FLAGS, VIRTUAL_KEY, VK_CONTROL, VK_MENU,
    VK_SHIFT,
};
use windows::Win32::UI::WindowsAndMessaging::{
    GetCursorPos, GetForegroundWindow, GetSystemMetrics, GetWindowThreadProcessId, SetCursorPos, SM_CXVIRTUALSCREEN,
    SM_CYVIRTUALSCREEN, SM_XVIRTUALSCREEN, SM_YVIRTUALSCREEN,
};

use super::sys::os;
use crate::desktop::windows::pointer;
use crate::desktop::windows::vk::{self, CharKey, Stroke};
use crate::desktop::{DesktopError, DesktopResult};

/// The most clicks or key presses one action may ask for (as the stub).
const MAX_REPEAT: u32 = 1000;

/// The virtual screen: all monitors, in physical pixels.
pub(super) fn virtual_screen() -> Rect {
    // SAFETY: GetSystemMetrics has no preconditions.
    unsafe {
        Rect::new(
            GetSystemMetrics(SM_XVIRTUALSCREEN),
            GetSystemMetrics(SM_YVIRTUALSCREEN),
            GetSystemMetrics(SM_CXVIRTUALSCREEN),
            GetSystemMetrics(SM_CYVIRTUALSCREEN),
        )
    }
}

/// The cursor position.
///
/// # Errors
///
/// The OS refusing, which happens on a secure desktop (UAC, lock screen).
pub(super) fn cursor() -> DesktopResult<Point> {
    let mut p = POINT::default();
    // SAFETY: p is a valid out-pointer.
    unsafe { GetCursorPos(&mut p) }.map_err(|err| os("GetCursorPos", &err))?;
    Ok(Point::new(p.x, p.y))
}

fn send(inputs: &[INPUT], what: &str) -> DesktopResult<()> {
    if inputs.is_empty() {
        return Ok(());
    }
    // SAFETY: the slice holds initialised INPUT records of the size passed.
    let sent = unsafe { SendInput(inputs, std::mem::size_of::<INPUT>() as i32) };
    if sent as usize != inputs.len() {
        return Err(DesktopError::Os {
            op: "SendInput",
            message: format!(
                "{what}: {sent} of {} input events were accepted (input is blocked by a secure desktop or by UIPI, \
                 e.g. an elevated window in front)",
                inputs.len()
            ),
        });
    }
    Ok(())
}

fn mouse(flags: MOUSE_EVENT_FLAGS, dx: i32, dy: i32, data: u32) -> INPUT {
    INPUT {
        r#type: INPUT_MOUSE,
        Anonymous: INPUT_0 { mi: MOUSEINPUT { dx, dy, mouseData: data, dwFlags: flags, time: 0, dwExtraInfo: 0 } },
    }
}

/// Moves the cursor to `p` (clamped to the virtual screen): an absolute `SendInput`
/// move, so hooks and drag logic see real motion, then `SetCursorPos` as pyautogui
/// does if the system landed elsewhere (scaling rounding, a clip rectangle).
fn move_to(p: Point) -> DesktopResult<()> {
    let screen = virtual_screen();
    let p = pointer::clamp_to(p, screen);
    let dx = pointer::normalize(p.x, screen.x, screen.width);
    let dy = pointer::normalize(p.y, screen.y, screen.height);
    send(&[mouse(MOUSEEVENTF_MOVE | MOUSEEVENTF_ABSOLUTE | MOUSEEVENTF_VIRTUALDESK, dx, dy, 0)], "move")?;
    if cursor().ok() != Some(p) {
        // SAFETY: SetCursorPos has no preconditions.
        unsafe { SetCursorPos(p.x, p.y) }.map_err(|err| os("SetCursorPos", &err))?;
    }
    Ok(())
}

fn move_opt(x: Option<i32>, y: Option<i32>) -> DesktopResult<()> {
    if x.is_none() && y.is_none() {
        return Ok(());
    }
    let here = cursor()?;
    move_to(Point::new(x.unwrap_or(here.x), y.unwrap_or(here.y)))
}

fn button_flags(button: MouseButton) -> DesktopResult<(MOUSE_EVENT_FLAGS, MOUSE_EVENT_FLAGS)> {
    match button {
        MouseButton::Left => Ok((MOUSEEVENTF_LEFTDOWN, MOUSEEVENTF_LEFTUP)),
        MouseButton::Right => Ok((MOUSEEVENTF_RIGHTDOWN, MOUSEEVENTF_RIGHTUP)),
        MouseButton::Middle => Ok((MOUSEEVENTF_MIDDLEDOWN, MOUSEEVENTF_MIDDLEUP)),
        MouseButton::Unknown => Err(DesktopError::InvalidInput("unknown mouse button".into())),
    }
}

fn click(button: MouseButton, count: u32) -> DesktopResult<()> {
    check_repeat("count", count)?;
    let (down, up) = button_flags(button)?;
    let inputs: Vec<INPUT> = (0..count).flat_map(|_| [mouse(down, 0, 0, 0), mouse(up, 0, 0, 0)]).collect();
    send(&inputs, "click")
}

fn check_repeat(what: &str, n: u32) -> DesktopResult<()> {
    if n > MAX_REPEAT {
        return Err(DesktopError::InvalidInput(format!("{what} {n} is more than {MAX_REPEAT}")));
    }
    Ok(())
}

/// The keyboard layout of the foreground window's thread: what the keys the agent
/// presses mean to the program that gets them (this thread's own layout may differ).
fn foreground_hkl() -> HKL {
    // SAFETY: no preconditions; a missing foreground window gives thread 0, whose layout
    // query answers the system default.
    unsafe { GetKeyboardLayout(GetWindowThreadProcessId(GetForegroundWindow(), None)) }
}

/// What layout `hkl` says about each character: its key, modifiers, and whether the key
/// is a dead key there.
fn layout(hkl: HKL) -> impl Fn(char) -> Option<CharKey> {
    move |c| {
        let unit = u16::try_from(u32::from(c)).ok()?;
        // SAFETY: VkKeyScanExW takes any UTF-16 unit and layout handle.
        let key = CharKey::from_vk_scan(unsafe { VkKeyScanExW(unit, hkl) })?;
        Some(CharKey { dead: is_dead_key(key, hkl), ..key })
    }
}

/// `ToUnicodeEx`'s "do not change the keyboard state" flag (Windows 10 1607 and later;
/// older systems ignore it, and this thread takes no keyboard input whose state it could
/// disturb).
const TO_UNICODE_KEEP_STATE: u32 = 0x4;

/// Whether `key`, with its modifiers held, is a dead key on `hkl`: `ToUnicodeEx` answers
/// a negative count for one.
fn is_dead_key(key: CharKey, hkl: HKL) -> bool {
    let mut state = [0u8; 256];
    for (held, vk) in [(key.shift, VK_SHIFT), (key.ctrl, VK_CONTROL), (key.alt, VK_MENU)] {
        if held {
            state[usize::from(vk.0)] = 0x80;
        }
    }
    let mut out = [0u16; 8];
    // SAFETY: MapVirtualKeyExW and ToUnicodeEx take any key and layout; the state and
    // output buffers are valid for the sizes the bindings pass.
    unsafe {
        let scan = MapVirtualKeyExW(u32::from(key.vk), MAPVK_VK_TO_VSC, Some(hkl));
        ToUnicodeEx(u32::from(key.vk), scan, &state, &mut out, TO_UNICODE_KEEP_STATE, Some(hkl)) < 0
    }
}

/// One keyboard record. Scan codes come from the target's layout `hkl`, which is what
/// the program that reads them (games, remote desktops, some editors) expects.
fn key_input(stroke: Stroke, hkl: HKL) -> INPUT {
    let ki = match stroke {
        Stroke::Vk { vk: code, up } => {
            // SAFETY: MapVirtualKeyExW has no preconditions.
            let scan = unsafe { MapVirtualKeyExW(u32::from(code), MAPVK_VK_TO_VSC, Some(hkl)) } as u16;
            let mut flags = KEYBD_EVENT_FLAGS(0);
            if vk::is_extended(code) {
                flags |= KEYEVENTF_EXTENDEDKEY;
            }
            if up {
                flags |= KEYEVENTF_KEYUP;
            }
            KEYBDINPUT { wVk: VIRTUAL_KEY(code), wScan: scan, dwFlags: flags, time: 0, dwExtraInfo: 0 }
        }
        Stroke::Unicode { unit, up } => {
            let flags = if up { KEYEVENTF_UNICODE | KEYEVENTF_KEYUP } else { KEYEVENTF_UNICODE };
            KEYBDINPUT { wVk: VIRTUAL_KEY(0), wScan: unit, dwFlags: flags, time: 0, dwExtraInfo: 0 }
        }
    };
    INPUT { r#type: INPUT_KEYBOARD, Anonymous: INPUT_0 { ki } }
}

fn send_strokes(strokes: &[Stroke], what: &str, hkl: HKL) -> DesktopResult<()> {
    let inputs: Vec<INPUT> = strokes.iter().map(|&s| key_input(s, hkl)).collect();
    send(&inputs, what)
}

fn parse_keys(name: &str) -> DesktopResult<Vec<Key>> {
    parse_chord(name).map_err(|err| DesktopError::InvalidInput(err.to_string()))
}

/// Performs one action.
///
/// # Errors
///
/// [`DesktopError::InvalidInput`] for unknown key names, buttons or action types and
/// counts above 1000; [`DesktopError::Os`] when Windows refused the input. `drag_step`
/// is how long each phase of a drag lasts (`--drag-step-ms`), so programs see the
/// press, the motion and the release apart.
pub(super) fn perform(action: &Action, drag_step: Duration) -> DesktopResult<()> {
    match action {
        Action::MoveTo { x, y } => move_to(Point::new(*x, *y)),
        Action::MoveRel { dx, dy } => {
            let here = cursor()?;
            move_to(Point::new(here.x.saturating_add(*dx), here.y.saturating_add(*dy)))
        }
        Action::Click { x, y, button, count } => {
            button_flags(*button)?;
            check_repeat("count", *count)?;
            move_opt(*x, *y)?;
            click(*button, *count)
        }
        Action::DoubleClick { x, y } => {
            move_opt(*x, *y)?;
            click(MouseButton::Left, 2)
        }
        Action::RightClick { x, y } => {
            move_opt(*x, *y)?;
            click(MouseButton::Right, 1)
        }
        Action::MouseDown { button, x, y } => {
            let (down, _) = button_flags(*button)?;
            move_opt(*x, *y)?;
            send(&[mouse(down, 0, 0, 0)], "mouse down")
        }
        Action::MouseUp { button, x, y } => {
            let (_, up) = button_flags(*button)?;
            move_opt(*x, *y)?;
            send(&[mouse(up, 0, 0, 0)], "mouse up")
        }
        Action::Drag { from, to, button, duration_ms } => {
            let (down, up) = button_flags(*button)?;
            if let Some(from) = from {
                move_to(*from)?;
            }
            let start = cursor()?;
            send(&[mouse(down, 0, 0, 0)], "drag")?;
            std::thread::sleep(drag_step);
            match duration_ms.filter(|&ms| ms > pointer::MINIMUM_DURATION_MS) {
                // Spread over the duration as pyautogui's dragTo moves; stops between
                // steps when the call was abandoned, and releases the button even then.
                Some(ms) => {
                    for (at, pause) in pointer::drag_path(start, *to, ms) {
                        move_to(at)?;
                        if let Err(err) = crate::desktop::cancel::sleep(Duration::from_millis(pause)) {
                            let _ = send(&[mouse(up, 0, 0, 0)], "drag");
                            return Err(err);
                        }
                    }
                }
                // A first step past the drag threshold, then the target, so programs start a drag.
                None => {
                    let mid = Point::new(start.x + (to.x - start.x) / 2, start.y + (to.y - start.y) / 2);
                    move_to(mid)?;
                    std::thread::sleep(drag_step);
                    move_to(*to)?;
                }
            }
            std::thread::sleep(drag_step);
            send(&[mouse(up, 0, 0, 0)], "drag")
        }
        Action::Scroll { x, y, dx, dy } => {
            move_opt(*x, *y)?;
            let mut inputs = Vec::new();
            if *dy != 0 {
                inputs.push(mouse(MOUSEEVENTF_WHEEL, 0, 0, pointer::wheel_data(*dy)));
            }
            if *dx != 0 {
                inputs.push(mouse(MOUSEEVENTF_HWHEEL, 0, 0, pointer::wheel_data(*dx)));
            }
            send(&inputs, "scroll")
        }
        Action::KeyPress { key, presses } => {
            check_repeat("presses", *presses)?;
            let keys = parse_keys(key)?;
            let hkl = foreground_hkl();
            let layout = layout(hkl);
            let once =
                if let [single] = keys.as_slice() { vk::press(*single, &layout) } else { vk::chord(&keys, &layout) };
            let strokes: Vec<Stroke> = (0..*presses).flat_map(|_| once.iter().copied()).collect();
            send_strokes(&strokes, "key press", hkl)
        }
        Action::Hotkey { keys } => {
            let mut parsed = Vec::new();
            for key in keys {
                parsed.extend(parse_keys(key)?);
            }
            let hkl = foreground_hkl();
            send_strokes(&vk::chord(&parsed, &layout(hkl)), "hotkey", hkl)
        }
        Action::KeyDown { key } => {
            let hkl = foreground_hkl();
            let layout = layout(hkl);
            let strokes: Vec<Stroke> = parse_keys(key)?.into_iter().flat_map(|k| vk::key_down(k, &layout)).collect();
            send_strokes(&strokes, "key down", hkl)
        }
        Action::KeyUp { key } => {
            let hkl = foreground_hkl();
            let layout = layout(hkl);
            let strokes: Vec<Stroke> =
                parse_keys(key)?.into_iter().rev().flat_map(|k| vk::key_up(k, &layout)).collect();
            send_strokes(&strokes, "key up", hkl)
        }
        Action::TypeText { text, interval_ms } => {
            arena_shared::action::check_typed_length(text).map_err(DesktopError::InvalidInput)?;
            let hkl = foreground_hkl();
            let groups = vk::type_text(text, &layout(hkl));
            match interval_ms.filter(|&ms| ms > 0) {
                None => send_strokes(&groups.concat(), "type text", hkl),
                Some(ms) => {
                    let pause = Duration::from_millis(ms.min(10_000));
                    for (i, group) in groups.iter().enumerate() {
                        if i > 0 {
                            // Stops here when the call timed out: no keys after the answer.
                            crate::desktop::cancel::sleep(pause)?;
                        }
                        send_strokes(group, "type text", hkl)?;
                    }
                    Ok(())
                }
            }
        }
        // The caller waits; nothing to do here.
        Action::Wait { .. } => Ok(()),
        Action::Unknown => Err(DesktopError::InvalidInput("unknown action type".into())),
    }
}
