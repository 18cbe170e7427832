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
    GetKeyboardLayout, MapVirtualKeyW, SendInput, VkKeyScanExW, INPUT, INPUT_0, INPUT_KEYBOARD, INPUT_MOUSE,
    KEYBDINPUT, KEYBD_EVENT_FLAGS, KEYEVENTF_EXTENDEDKEY, KEYEVENTF_KEYUP, KEYEVENTF_UNICODE, MAPVK_VK_TO_VSC,
    MOUSEEVENTF_ABSOLUTE, MOUSEEVENTF_HWHEEL, MOUSEEVENTF_LEFTDOWN, MOUSEEVENTF_LEFTUP, MOUSEEVENTF_MIDDLEDOWN,
    MOUSEEVENTF_MIDDLEUP, MOUSEEVENTF_MOVE, MOUSEEVENTF_RIGHTDOWN, MOUSEEVENTF_RIGHTUP, MOUSEEVENTF_VIRTUALDESK,
    MOUSEEVENTF_WHEEL, MOUSEINPUT, MOUSE_EVENT_FLAGS, VIRTUAL_KEY,
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
/// Pause between the steps of a drag, so programs see the press, the motion and the release apart.
const DRAG_STEP: Duration = Duration::from_millis(20);

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

/// What the keyboard layout of the foreground window's thread says about each
/// character: what the keys the agent presses mean to the program that gets them
/// (this thread's own layout may differ). The layout is looked up once, here.
fn foreground_layout() -> impl Fn(char) -> Option<CharKey> {
    // SAFETY: no preconditions; a missing foreground window gives thread 0, whose layout
    // query answers the system default.
    let hkl = unsafe { GetKeyboardLayout(GetWindowThreadProcessId(GetForegroundWindow(), None)) };
    move |c| {
        let unit = u16::try_from(u32::from(c)).ok()?;
        // SAFETY: VkKeyScanExW takes any UTF-16 unit and layout handle.
        CharKey::from_vk_scan(unsafe { VkKeyScanExW(unit, hkl) })
    }
}

fn key_input(stroke: Stroke) -> INPUT {
    let ki = match stroke {
        Stroke::Vk { vk: code, up } => {
            // SAFETY: MapVirtualKeyW has no preconditions.
            let scan = unsafe { MapVirtualKeyW(u32::from(code), MAPVK_VK_TO_VSC) } as u16;
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

fn send_strokes(strokes: &[Stroke], what: &str) -> DesktopResult<()> {
    let inputs: Vec<INPUT> = strokes.iter().map(|&s| key_input(s)).collect();
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
/// counts above 1000; [`DesktopError::Os`] when Windows refused the input.
pub(super) fn perform(action: &Action) -> DesktopResult<()> {
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
            std::thread::sleep(DRAG_STEP);
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
                    std::thread::sleep(DRAG_STEP);
                    move_to(*to)?;
                }
            }
            std::thread::sleep(DRAG_STEP);
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
            let layout = foreground_layout();
            let once =
                if let [single] = keys.as_slice() { vk::press(*single, &layout) } else { vk::chord(&keys, &layout) };
            let strokes: Vec<Stroke> = (0..*presses).flat_map(|_| once.iter().copied()).collect();
            send_strokes(&strokes, "key press")
        }
        Action::Hotkey { keys } => {
            let mut parsed = Vec::new();
            for key in keys {
                parsed.extend(parse_keys(key)?);
            }
            send_strokes(&vk::chord(&parsed, &foreground_layout()), "hotkey")
        }
        Action::KeyDown { key } => {
            let layout = foreground_layout();
            let strokes: Vec<Stroke> = parse_keys(key)?.into_iter().flat_map(|k| vk::key_down(k, &layout)).collect();
            send_strokes(&strokes, "key down")
        }
        Action::KeyUp { key } => {
            let layout = foreground_layout();
            let strokes: Vec<Stroke> =
                parse_keys(key)?.into_iter().rev().flat_map(|k| vk::key_up(k, &layout)).collect();
            send_strokes(&strokes, "key up")
        }
        Action::TypeText { text, interval_ms } => {
            let groups = vk::type_text(text, &foreground_layout());
            match interval_ms.filter(|&ms| ms > 0) {
                None => send_strokes(&groups.concat(), "type text"),
                Some(ms) => {
                    let pause = Duration::from_millis(ms.min(10_000));
                    for (i, group) in groups.iter().enumerate() {
                        if i > 0 {
                            // Stops here when the call timed out: no keys after the answer.
                            crate::desktop::cancel::sleep(pause)?;
                        }
                        send_strokes(group, "type text")?;
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
