//! Input for the stub: mouse and keyboard actions applied to the desktop state.
//!
//! The model is what a benchmark needs, not a full window manager: clicks raise and
//! focus windows and press caption and taskbar buttons, title bars drag windows, the
//! wheel scrolls the focused window, and keys edit the focused window's document with
//! a caret and all-or-nothing selection (`ctrl+a`). Shortcuts: `ctrl+a/c/x/v/s`,
//! `alt+f4`, `alt+tab`, `win+d` and `win+m` (show the desktop), `win+e` (File Explorer, as
//! the `explorer` command starts it) and `win+r` (the Run dialog). In the Run dialog typing
//! edits the command, `enter` (or its OK button) runs it through the stub's launch path and
//! `esc` (or Cancel) closes it; `enter`, `space` and `esc` dismiss a message box. Elsewhere
//! `esc` and unknown combinations do nothing visible.

use arena_shared::action::{Action, MouseButton};
use arena_shared::geometry::Point;
use arena_shared::keys::{parse_chord, Key};

use super::render::taskbar_buttons;
use super::window::{
    layout, Caption, Dialog, DialogButton, Effect, Grab, Hit, Press, State, Window, BODY_PAD, GLYPH_W, LINE_H,
    TASKBAR_H,
};
use crate::desktop::{ClipboardData, DesktopError, DesktopResult, WindowState};

/// The most clicks or key presses one action may ask for.
const MAX_REPEAT: u32 = 1000;
/// Vertical pitch of desktop icons, from the top-left corner.
pub(crate) const ICON_PITCH: i32 = 24;
/// Width of a desktop icon's clickable area.
const ICON_W: i32 = 140;

/// Applies one action.
///
/// Key names are all parsed before anything happens, so a bad name changes nothing.
///
/// # Errors
///
/// [`DesktopError::InvalidInput`] naming an unknown key, for [`Action::Unknown`], and for
/// counts above [`MAX_REPEAT`]; the I/O error of a `ctrl+s` save.
pub(crate) fn perform(state: &mut State, action: &Action) -> DesktopResult<Vec<Effect>> {
    state.effects.clear();
    let mut effects = apply(state, action)?;
    effects.append(&mut state.effects);
    Ok(effects)
}

fn apply(state: &mut State, action: &Action) -> DesktopResult<Vec<Effect>> {
    let mut effects = Vec::new();
    match action {
        Action::MoveTo { x, y } => move_to(state, Point::new(*x, *y)),
        Action::MoveRel { dx, dy } => {
            let p = Point::new(state.cursor.x.saturating_add(*dx), state.cursor.y.saturating_add(*dy));
            move_to(state, p);
        }
        Action::Click { x, y, button, count } => {
            check_repeat("count", *count)?;
            let button = known_button(*button)?;
            move_opt(state, *x, *y);
            click(state, button, *count, &mut effects)?;
        }
        Action::DoubleClick { x, y } => {
            move_opt(state, *x, *y);
            click(state, MouseButton::Left, 2, &mut effects)?;
        }
        Action::RightClick { x, y } => {
            move_opt(state, *x, *y);
            click(state, MouseButton::Right, 1, &mut effects)?;
        }
        Action::MouseDown { button, x, y } => {
            let button = known_button(*button)?;
            move_opt(state, *x, *y);
            press(state, button);
        }
        Action::MouseUp { button, x, y } => {
            let button = known_button(*button)?;
            move_opt(state, *x, *y);
            release(state, button)?;
        }
        // The stub has no timing to model: the drag lands at once.
        Action::Drag { from, to, button, duration_ms: _ } => {
            let button = known_button(*button)?;
            if let Some(from) = from {
                move_to(state, *from);
            }
            press(state, button);
            move_to(state, *to);
            release(state, button)?;
        }
        Action::Scroll { x, y, dx: _, dy } => {
            move_opt(state, *x, *y);
            scroll(state, *dy);
        }
        Action::KeyPress { key, presses } => {
            check_repeat("presses", *presses)?;
            let keys = parse_keys(key)?;
            for _ in 0..*presses {
                chord(state, &keys)?;
            }
        }
        Action::Hotkey { keys } => {
            let mut parsed = Vec::new();
            for key in keys {
                parsed.extend(parse_keys(key)?);
            }
            chord(state, &parsed)?;
        }
        Action::KeyDown { key } => {
            for key in parse_keys(key)? {
                key_down(state, key)?;
            }
        }
        Action::KeyUp { key } => {
            for key in parse_keys(key)?.into_iter().rev() {
                key_up(state, key);
            }
        }
        Action::TypeText { text, interval_ms: _ } => {
            arena_shared::action::check_typed_length(text).map_err(DesktopError::InvalidInput)?;
            let mods = state.mods;
            // A dialog has keys of its own (`enter` runs the Run dialog's command), so text
            // typed into one goes key by key.
            let in_dialog = state.focused_app_mut().is_some_and(|w| w.dialog.is_some());
            if !(mods.ctrl || mods.alt || mods.win || in_dialog) {
                // Plain typing is one edit, not one per character: laying the text out
                // again after every character made long texts quadratic.
                let text: String = text
                    .chars()
                    .filter(|c| *c != '\r')
                    .map(|c| if mods.shift { c.to_uppercase().next().unwrap_or(c) } else { c })
                    .collect();
                // In slices, asking between them whether the call still stands: a call
                // that timed out or whose client went away stops typing.
                for slice in char_slices(&text, TYPE_SLICE_CHARS) {
                    crate::desktop::cancel::checkpoint()?;
                    edit(state, |buf| buf.insert(slice));
                }
                return Ok(effects);
            }
            for c in text.chars() {
                crate::desktop::cancel::checkpoint()?;
                let key = match c {
                    '\n' => Key::Named("enter"),
                    '\r' => continue,
                    '\t' => Key::Named("tab"),
                    ' ' => Key::Named("space"),
                    c => Key::Char(c),
                };
                key_down(state, key)?;
            }
        }
        // The caller waits; a stray Wait here has nothing to do under the lock.
        Action::Wait { .. } => {}
        Action::Unknown => return Err(DesktopError::InvalidInput("unknown action type".into())),
    }
    Ok(effects)
}

/// Characters typed in one edit of plain typing, between two cancellation checks.
const TYPE_SLICE_CHARS: usize = 16 << 10;

/// `text` in slices of at most `n` characters.
fn char_slices(text: &str, n: usize) -> impl Iterator<Item = &str> {
    let mut rest = text;
    std::iter::from_fn(move || {
        if rest.is_empty() {
            return None;
        }
        let end = rest.char_indices().nth(n).map_or(rest.len(), |(i, _)| i);
        let (slice, tail) = rest.split_at(end);
        rest = tail;
        Some(slice)
    })
}

fn check_repeat(what: &str, n: u32) -> DesktopResult<()> {
    if n > MAX_REPEAT {
        return Err(DesktopError::InvalidInput(format!("{what} {n} is more than {MAX_REPEAT}")));
    }
    Ok(())
}

fn known_button(button: MouseButton) -> DesktopResult<MouseButton> {
    if button == MouseButton::Unknown {
        return Err(DesktopError::InvalidInput("unknown mouse button".into()));
    }
    Ok(button)
}

fn parse_keys(name: &str) -> DesktopResult<Vec<Key>> {
    parse_chord(name).map_err(|err| DesktopError::InvalidInput(err.to_string()))
}

fn move_opt(state: &mut State, x: Option<i32>, y: Option<i32>) {
    if x.is_some() || y.is_some() {
        let p = Point::new(x.unwrap_or(state.cursor.x), y.unwrap_or(state.cursor.y));
        move_to(state, p);
    }
}

/// Moves the cursor, dragging a grabbed title bar along.
fn move_to(state: &mut State, p: Point) {
    let p = state.clamp(p);
    state.cursor = p;
    if let Some(grab) = state.grab {
        let max_y = (state.screen.1 as i32 - TASKBAR_H - 1).max(0);
        if let Some(window) = state.window_mut(grab.window) {
            window.rect.x = p.x - grab.dx;
            window.rect.y = (p.y - grab.dy).clamp(0, max_y);
            window.restore_rect = window.rect;
        }
    }
}

/// What is under the cursor: a taskbar button, a window part, or nothing (the bare taskbar).
fn target_at(state: &State, p: Point) -> Option<(u64, Hit)> {
    if p.y >= state.screen.1 as i32 - TASKBAR_H {
        return taskbar_buttons(state).into_iter().find(|(_, r)| r.contains(p)).map(|(id, _)| (id, Hit::Taskbar));
    }
    let window = state.window_at(p)?;
    Some((window.id, window.hit(p)?))
}

fn press(state: &mut State, button: MouseButton) {
    if !state.buttons.contains(&button) {
        state.buttons.push(button);
    }
    let p = state.cursor;
    let Some((id, hit)) = target_at(state, p) else {
        state.press = None;
        return;
    };
    state.press = Some(Press { button, window: id, hit });
    if hit == Hit::Taskbar {
        return;
    }
    // Activation cannot fail: the id came from the window list just now.
    let _ = state.activate(id);
    let mut grab = None;
    if let Some(window) = state.window_mut(id) {
        match (button, hit) {
            (MouseButton::Left, Hit::TitleBar) if !window.maximized && !window.is_desktop => {
                grab = Some(Grab { window: id, dx: p.x - window.rect.x, dy: p.y - window.rect.y });
            }
            (MouseButton::Left, Hit::Body) if window.text.is_some() && window.dialog.is_none() => {
                place_caret(window, p)
            }
            _ => {}
        }
    }
    if grab.is_some() {
        state.grab = grab;
    }
}

fn place_caret(window: &mut Window, p: Point) {
    let body = window.body();
    let (cols, _) = window.text_grid();
    let row = ((p.y - body.y - BODY_PAD).max(0) / LINE_H) as usize + window.scroll;
    let col = ((p.x - body.x - BODY_PAD).max(0) + GLYPH_W / 2) / GLYPH_W;
    if let Some(buf) = window.text.as_mut() {
        let lines = layout(&buf.text, cols);
        buf.place_caret(&lines, row, col as usize);
    }
}

fn release(state: &mut State, button: MouseButton) -> DesktopResult<()> {
    state.buttons.retain(|b| *b != button);
    if button == MouseButton::Left {
        state.grab = None;
    }
    let Some(press) = state.press.take() else {
        return Ok(());
    };
    if press.button != button || button != MouseButton::Left {
        return Ok(());
    }
    // A button acts when released over the same thing it was pressed on.
    if target_at(state, state.cursor) != Some((press.window, press.hit)) {
        return Ok(());
    }
    match press.hit {
        Hit::Button(Caption::Minimize) => state.set_state(press.window, WindowState::Minimized),
        Hit::Button(Caption::Maximize) => toggle_maximized(state, press.window),
        Hit::Button(Caption::Close) => state.close(press.window),
        Hit::Taskbar => {
            let shown = state.window(press.window).is_some_and(Window::shown);
            if shown && state.focus == press.window {
                state.set_state(press.window, WindowState::Minimized)
            } else if !shown {
                state.set_state(press.window, WindowState::Normal)
            } else {
                state.activate(press.window)
            }
        }
        Hit::Body => match state.window(press.window).and_then(|w| w.dialog_button_at(state.cursor)) {
            Some(button) => press_dialog_button(state, press.window, button),
            None => Ok(()),
        },
        Hit::TitleBar => Ok(()),
    }
}

/// A dialog button pushed: OK runs the Run dialog's command or dismisses a message box,
/// Cancel closes the dialog; Browse opens a file picker the stub does not model.
fn press_dialog_button(state: &mut State, id: u64, button: DialogButton) -> DesktopResult<()> {
    let Some(window) = state.window(id) else {
        return Ok(());
    };
    match (button, &window.dialog) {
        (DialogButton::Ok, Some(Dialog::Run)) => {
            let line = window.text.as_ref().map(|b| b.text.trim().to_owned()).unwrap_or_default();
            // As on Windows, OK does nothing while the command is empty.
            if !line.is_empty() {
                state.effects.push(Effect::RunDialog { dialog: id, line });
            }
            Ok(())
        }
        (DialogButton::Ok | DialogButton::Cancel, Some(_)) => state.close(id),
        _ => Ok(()),
    }
}

/// A key for the focused dialog, when the focused window is one: `Some` when the dialog
/// handled it, `None` when it is an ordinary edit of the command field.
fn dialog_key(state: &mut State, name: &str) -> Option<DesktopResult<()>> {
    let window = state.focused_app_mut()?;
    let id = window.id;
    match (window.dialog.as_ref()?, name) {
        (Dialog::Run, "enter") => Some(press_dialog_button(state, id, DialogButton::Ok)),
        (Dialog::Message(_), "enter" | "space") => Some(press_dialog_button(state, id, DialogButton::Ok)),
        (_, "esc") => Some(press_dialog_button(state, id, DialogButton::Cancel)),
        // Tab moves between controls and up/down open the command history: nothing the
        // stub draws changes, and the command field takes neither.
        (_, "tab" | "up" | "down" | "pageup" | "pagedown") => Some(Ok(())),
        (Dialog::Run, _) => None,
        (Dialog::Message(_), _) => Some(Ok(())),
    }
}

fn toggle_maximized(state: &mut State, id: u64) -> DesktopResult<()> {
    let maximized = state.window(id).is_some_and(|w| w.maximized);
    state.set_state(id, if maximized { WindowState::Normal } else { WindowState::Maximized })
}

fn click(state: &mut State, button: MouseButton, count: u32, effects: &mut Vec<Effect>) -> DesktopResult<()> {
    for _ in 0..count {
        press(state, button);
        release(state, button)?;
    }
    if count >= 2 && button == MouseButton::Left {
        double_click(state, effects)?;
    }
    Ok(())
}

/// A double click maximises or restores by the title bar and opens desktop icons.
fn double_click(state: &mut State, effects: &mut Vec<Effect>) -> DesktopResult<()> {
    let p = state.cursor;
    let Some((id, hit)) = target_at(state, p) else {
        return Ok(());
    };
    let is_desktop = state.window(id).is_some_and(|w| w.is_desktop);
    if is_desktop {
        if (4..4 + ICON_W).contains(&p.x) && p.y >= 6 && (p.y - 6) % ICON_PITCH < ICON_PITCH - 2 {
            effects.push(Effect::OpenDesktopItem(((p.y - 6) / ICON_PITCH) as usize));
        }
        return Ok(());
    }
    if hit == Hit::TitleBar {
        return toggle_maximized(state, id);
    }
    Ok(())
}

/// Turns the wheel over the focused window: 3 lines a notch (120), at least one line a turn.
fn scroll(state: &mut State, dy: i32) {
    if dy == 0 {
        return;
    }
    let Some(window) = state.focused_app_mut() else {
        return;
    };
    let lines = ((i64::from(dy).abs() * 3 + 119) / 120) as usize;
    let total = window.text.as_ref().map_or(0, |buf| layout(&buf.text, window.text_grid().0).len());
    window.scroll = if dy > 0 { window.scroll.saturating_sub(lines) } else { window.scroll + lines };
    window.scroll = window.scroll.min(total.saturating_sub(1));
}

/// Presses the keys in order and releases them in reverse.
fn chord(state: &mut State, keys: &[Key]) -> DesktopResult<()> {
    let mut result = Ok(());
    for key in keys {
        result = key_down(state, *key);
        if result.is_err() {
            break;
        }
    }
    for key in keys.iter().rev() {
        key_up(state, *key);
    }
    result
}

fn modifier_slot(state: &mut State, key: Key) -> Option<&mut bool> {
    let Key::Named(name) = key else {
        return None;
    };
    match name {
        "ctrl" | "ctrlleft" | "ctrlright" => Some(&mut state.mods.ctrl),
        "alt" | "altleft" | "altright" => Some(&mut state.mods.alt),
        "shift" | "shiftleft" | "shiftright" => Some(&mut state.mods.shift),
        "win" | "winleft" | "winright" => Some(&mut state.mods.win),
        _ => None,
    }
}

fn key_up(state: &mut State, key: Key) {
    if let Some(slot) = modifier_slot(state, key) {
        *slot = false;
    }
}

/// A key going down: modifiers are held, other keys act at once with the held modifiers.
fn key_down(state: &mut State, key: Key) -> DesktopResult<()> {
    if let Some(slot) = modifier_slot(state, key) {
        *slot = true;
        return Ok(());
    }
    let mods = state.mods;
    match key {
        Key::Char(c) if mods.ctrl && !mods.alt => shortcut(state, c.to_ascii_lowercase()),
        Key::Char(c) if mods.win => {
            match c.to_ascii_lowercase() {
                'd' | 'm' => show_desktop(state),
                'r' => state.open_run_dialog(),
                'e' => state.effects.push(Effect::Launch("explorer".into())),
                _ => {}
            }
            Ok(())
        }
        Key::Char(_) if mods.alt => Ok(()),
        Key::Char(c) => {
            let c = if mods.shift { c.to_uppercase().next().unwrap_or(c) } else { c };
            edit(state, |buf| buf.insert(c.encode_utf8(&mut [0; 4])));
            Ok(())
        }
        Key::Named(name) => named_key(state, name),
    }
}

fn named_key(state: &mut State, name: &str) -> DesktopResult<()> {
    let mods = state.mods;
    if !(mods.ctrl || mods.alt || mods.win) {
        if let Some(handled) = dialog_key(state, name) {
            return handled;
        }
    }
    let text = match name {
        "enter" => Some("\n"),
        "space" => Some(" "),
        "tab" if !mods.alt && !mods.ctrl => Some("\t"),
        "add" => Some("+"),
        "subtract" => Some("-"),
        "multiply" => Some("*"),
        "divide" => Some("/"),
        "decimal" => Some("."),
        _ => None,
    };
    let digit = name.strip_prefix("num").filter(|d| d.len() == 1 && d.as_bytes()[0].is_ascii_digit());
    if mods.ctrl || mods.alt || mods.win {
        match name {
            "f4" if mods.alt => return close_focused(state),
            "tab" if mods.alt => return switch_window(state),
            "home" | "end" | "left" | "right" | "up" | "down" if mods.ctrl => {
                edit(state, |buf| buf.navigate(name, true));
                return Ok(());
            }
            _ => return Ok(()),
        }
    }
    if let Some(text) = text.or(digit) {
        edit(state, |buf| buf.insert(text));
        return Ok(());
    }
    match name {
        "backspace" => edit(state, super::window::TextBuf::backspace),
        "delete" => edit(state, super::window::TextBuf::delete),
        "left" | "right" | "up" | "down" | "home" | "end" | "pageup" | "pagedown" => {
            edit(state, |buf| buf.navigate(name, false))
        }
        // Escape, function keys and the rest change nothing the stub models.
        _ => {}
    }
    Ok(())
}

/// Applies `f` to the focused window's document, creating an empty one for a window without;
/// typing on the desktop goes nowhere.
fn edit(state: &mut State, f: impl FnOnce(&mut super::window::TextBuf)) {
    let Some(window) = state.focused_app_mut() else {
        return;
    };
    if matches!(window.dialog, Some(Dialog::Message(_))) || window.folder.is_some() {
        // A message box, and File Explorer's lists, have nothing to type into.
        return;
    }
    let buf = window.text.get_or_insert_with(Default::default);
    f(buf);
    follow_caret(window);
}

/// Scrolls so that the caret's row is visible.
fn follow_caret(window: &mut Window) {
    let (cols, rows) = window.text_grid();
    let Some(buf) = &window.text else {
        return;
    };
    let lines = layout(&buf.text, cols);
    let row = lines.iter().rposition(|l| l.start <= buf.caret).unwrap_or(0);
    let rows = rows.max(1);
    if row < window.scroll {
        window.scroll = row;
    } else if row >= window.scroll + rows {
        window.scroll = row + 1 - rows;
    }
}

fn shortcut(state: &mut State, c: char) -> DesktopResult<()> {
    match c {
        'a' => edit(state, super::window::TextBuf::select_all),
        'c' | 'x' => {
            let Some(buf) = state.focused_app_mut().and_then(|w| w.text.as_mut()) else {
                return Ok(());
            };
            let copied = if c == 'x' { buf.take_selection() } else { buf.selection().map(str::to_owned) };
            if let Some(text) = copied {
                state.clipboard = ClipboardData::Text(text);
            }
        }
        'v' => {
            if let ClipboardData::Text(text) = state.clipboard.clone() {
                edit(state, |buf| buf.insert(&text));
            }
        }
        's' => save(state)?,
        _ => {}
    }
    Ok(())
}

/// `ctrl+s`: writes the focused document to its file, when it has one.
fn save(state: &mut State) -> DesktopResult<()> {
    let Some(window) = state.focused_app_mut() else {
        return Ok(());
    };
    let (Some(path), Some(buf)) = (&window.file, &window.text) else {
        return Ok(());
    };
    std::fs::write(path, buf.text.as_bytes()).map_err(|err| DesktopError::io("saving a document", &window.title, err))
}

fn close_focused(state: &mut State) -> DesktopResult<()> {
    let focus = state.focus;
    if state.window(focus).is_some_and(|w| w.is_desktop) {
        // alt+f4 on the desktop opens the shut-down dialog, which the stub does not model.
        return Ok(());
    }
    state.close(focus)
}

/// `alt+tab`: the most recent other window comes to the front.
fn switch_window(state: &mut State) -> DesktopResult<()> {
    let shown: Vec<u64> = state.windows.iter().filter(|w| w.shown() && !w.is_desktop).map(|w| w.id).collect();
    let target = match shown.as_slice() {
        [first, second, ..] if *first == state.focus => Some(*second),
        [first, ..] if *first != state.focus => Some(*first),
        _ => None,
    };
    match target {
        Some(id) => state.activate(id),
        None => Ok(()),
    }
}

/// `win+d`: every window minimised, the desktop focused.
fn show_desktop(state: &mut State) {
    for window in state.windows.iter_mut().filter(|w| !w.is_desktop) {
        window.minimized = true;
    }
    state.focus = state.desktop_id();
}
