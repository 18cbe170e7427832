//! The stub's model of the input recorder (`arena-input-recorder`): started like the
//! real one (`arena-input-recorder LOG`), it opens a window and writes to `LOG` the
//! lines (`arena_shared::input_log`) the real recorder would write for each action,
//! so the host's input check (`arena-inputcheck`) runs on the stub too.
//!
//! Actions become the strokes the Windows backend would send (the neutral
//! `desktop::windows::vk` planner, on a US layout), and strokes become window messages
//! as Windows makes them: the key state as each message is read, `WM_SYSKEY*` for keys
//! while Alt is held without Ctrl, for Alt going down without Ctrl and for its release
//! when no other key went down meanwhile (and Ctrl's release under Alt, and F10), characters as `TranslateMessage` makes
//! them on a US layout (Ctrl+letter control characters, Alt+key `WM_SYSCHAR`, none with
//! Ctrl+Alt), `VK_PACKET` characters joined across surrogate halves, double clicks
//! within the double-click time and distance of the last press of the same button (and
//! a third press a plain one), moves and wheels at the cursor. Keys reach it while its
//! window has the focus, the mouse while the cursor is over its client area or a button
//! is held (the real recorder captures the mouse).

use std::collections::BTreeSet;
use std::io::Write;
use std::path::PathBuf;
use std::time::Instant;

use arena_shared::action::{Action, MouseButton};
use arena_shared::geometry::Point;
use arena_shared::input_log::{mk, Button, Mods, Press, Recorded};
use arena_shared::keys::{parse_chord, Key};
use arena_shared::vkeys::{self, VK_PACKET};

use super::window::State;
use crate::desktop::windows::vk::{self, CharKey, Stroke};
use crate::desktop::{DesktopError, DesktopResult};

/// The program's name, as `launch` is asked for it.
pub(crate) const PROGRAM: &str = "arena-input-recorder";
/// Its window's title (the real recorder's).
pub(crate) const TITLE: &str = "Arena input recorder";
/// The double-click time this desktop is set to (shorter than Windows' default 500 ms, so
/// the input check, which waits it out after each click, runs fast) and the half-size of
/// the double-click rectangle (`SM_CXDOUBLECLK` of 4 pixels).
const DOUBLE_CLICK_MS: u128 = 150;
const DOUBLE_CLICK_HALF: i32 = 2;

const SHIFTS: [u16; 3] = [vk::VK_SHIFT, 0xA0, 0xA1];
const CTRLS: [u16; 3] = [vk::VK_CONTROL, 0xA2, 0xA3];
const ALTS: [u16; 3] = [vk::VK_MENU, 0xA4, 0xA5];
const WINS: [u16; 2] = [0x5B, 0x5C];
const VK_F10: u16 = 0x79;

/// The recorder's state between actions.
#[derive(Debug)]
pub(crate) struct Model {
    pub(crate) window: u64,
    log: PathBuf,
    started: Instant,
    keys: BTreeSet<u16>,
    buttons: Vec<Button>,
    /// The last press that may start a double click: its button, place and time.
    last_press: Option<(Button, Point, Instant)>,
    high_surrogate: Option<u16>,
    /// Alt went down as a system key and no other key has since: its release is one too.
    alt_alone: bool,
}

/// The US layout's key for a character: `(vk, shift)`.
fn us_key(c: char) -> Option<(u16, bool)> {
    const PUNCT: [(char, char, u16); 11] = [
        (';', ':', 0xBA),
        ('=', '+', 0xBB),
        (',', '<', 0xBC),
        ('-', '_', 0xBD),
        ('.', '>', 0xBE),
        ('/', '?', 0xBF),
        ('`', '~', 0xC0),
        ('[', '{', 0xDB),
        ('\\', '|', 0xDC),
        (']', '}', 0xDD),
        ('\'', '"', 0xDE),
    ];
    const SHIFTED_DIGITS: &str = ")!@#$%^&*(";
    match c {
        'a'..='z' => Some((c.to_ascii_uppercase() as u16, false)),
        'A'..='Z' => Some((c as u16, true)),
        '0'..='9' => Some((c as u16, false)),
        ' ' => Some((0x20, false)),
        _ => {
            if let Some(i) = SHIFTED_DIGITS.find(c) {
                return Some((0x30 + i as u16, true));
            }
            PUNCT.iter().find_map(|&(plain, shifted, code)| {
                (c == plain).then_some((code, false)).or((c == shifted).then_some((code, true)))
            })
        }
    }
}

/// The layout closure the stroke planner asks.
fn us_layout(c: char) -> Option<CharKey> {
    us_key(c).map(|(code, shift)| CharKey { vk: code, shift, ctrl: false, alt: false, dead: false })
}

/// What `ToUnicode` gives for `code` on a US layout with `shift` (and `ctrl`).
fn us_char(code: u16, shift: bool, ctrl: bool) -> Option<char> {
    if ctrl {
        return match code {
            0x41..=0x5A => char::from_u32(u32::from(code) - 0x40),
            0x0D => Some('\n'),
            0x08 => Some('\u{7f}'),
            0x1B | 0xDB => Some('\u{1b}'),
            0xDC => Some('\u{1c}'),
            0xDD => Some('\u{1d}'),
            0x20 => Some(' '),
            _ => None,
        };
    }
    match code {
        0x08 => Some('\u{8}'),
        0x09 => Some('\t'),
        0x0D => Some('\r'),
        0x1B => Some('\u{1b}'),
        0x6A => Some('*'),
        0x6B => Some('+'),
        0x6D => Some('-'),
        0x6F => Some('/'),
        _ => (' '..='~').find(|&c| us_key(c) == Some((code, shift))),
    }
}

/// The US set-1 scan code of a virtual key (what `MapVirtualKey` answers), 0 when none.
fn scan_code(code: u16) -> u16 {
    const LETTERS: &[u8; 26] =
        b"\x1e\x30\x2e\x20\x12\x21\x22\x23\x17\x24\x25\x26\x32\x31\x18\x19\x10\x13\x1f\x14\x16\x2f\x11\x2d\x15\x2c";
    match code {
        0x41..=0x5A => u16::from(LETTERS[usize::from(code - 0x41)]),
        0x31..=0x39 => code - 0x31 + 0x02,
        0x30 => 0x0B,
        0x70..=0x79 => code - 0x70 + 0x3B,
        0x7A => 0x57,
        0x7B => 0x58,
        _ => {
            let table: [(u16, u16); 34] = [
                (0x08, 0x0E),
                (0x09, 0x0F),
                (0x0D, 0x1C),
                (0x10, 0x2A),
                (0x11, 0x1D),
                (0x12, 0x38),
                (0x14, 0x3A),
                (0x1B, 0x01),
                (0x20, 0x39),
                (0x21, 0x49),
                (0x22, 0x51),
                (0x23, 0x4F),
                (0x24, 0x47),
                (0x25, 0x4B),
                (0x26, 0x48),
                (0x27, 0x4D),
                (0x28, 0x50),
                (0x2D, 0x52),
                (0x2E, 0x53),
                (0x5B, 0x5B),
                (0x5C, 0x5C),
                (0x5D, 0x5D),
                (0x6A, 0x37),
                (0x6F, 0x35),
                (0xBA, 0x27),
                (0xBB, 0x0D),
                (0xBC, 0x33),
                (0xBD, 0x0C),
                (0xBE, 0x34),
                (0xBF, 0x35),
                (0xC0, 0x29),
                (0xDB, 0x1A),
                (0xDC, 0x2B),
                (0xDD, 0x1B),
            ];
            table.iter().find(|(v, _)| *v == code).map_or(0, |(_, s)| *s)
        }
    }
}

fn button_of(button: MouseButton) -> Option<Button> {
    match button {
        MouseButton::Left => Some(Button::Left),
        MouseButton::Right => Some(Button::Right),
        MouseButton::Middle => Some(Button::Middle),
        MouseButton::Unknown => None,
    }
}

fn parse_keys(name: &str) -> DesktopResult<Vec<Key>> {
    parse_chord(name).map_err(|err| DesktopError::InvalidInput(err.to_string()))
}

impl Model {
    /// A recorder writing to `log` (created or emptied) for `window`, whose client area
    /// (the window's body) the `ready` line places.
    pub(crate) fn start(window: u64, log: PathBuf, state: &State) -> DesktopResult<Model> {
        let body = state.window(window).map(super::window::Window::body).unwrap_or_default();
        std::fs::write(&log, "")
            .map_err(|err| DesktopError::io("creating the log", &log.display().to_string(), err))?;
        let model = Model {
            window,
            log,
            started: Instant::now(),
            keys: BTreeSet::new(),
            buttons: Vec::new(),
            last_press: None,
            high_surrogate: None,
            alt_alone: false,
        };
        let ready = Recorded::Ready {
            x: body.x,
            y: body.y,
            width: body.width,
            height: body.height,
            double_click_ms: DOUBLE_CLICK_MS as u32,
        };
        model.write(&[ready])?;
        Ok(model)
    }

    fn write(&self, records: &[Recorded]) -> DesktopResult<()> {
        if records.is_empty() {
            return Ok(());
        }
        let mut text = String::new();
        for record in records {
            text.push_str(&serde_json::to_string(record).unwrap_or_default());
            text.push('\n');
        }
        let mut file = std::fs::OpenOptions::new()
            .append(true)
            .open(&self.log)
            .map_err(|err| DesktopError::io("appending to the log", &self.log.display().to_string(), err))?;
        file.write_all(text.as_bytes())
            .map_err(|err| DesktopError::io("appending to the log", &self.log.display().to_string(), err))
    }

    fn held(&self, codes: &[u16]) -> bool {
        codes.iter().any(|c| self.keys.contains(c))
    }

    fn mods(&self) -> Mods {
        Mods { shift: self.held(&SHIFTS), ctrl: self.held(&CTRLS), alt: self.held(&ALTS), win: self.held(&WINS) }
    }

    fn mk(&self) -> u32 {
        let mut flags = 0;
        for b in &self.buttons {
            flags |= match b {
                Button::Left => mk::LBUTTON,
                Button::Right => mk::RBUTTON,
                Button::Middle => mk::MBUTTON,
                Button::X1 => mk::XBUTTON1,
                Button::X2 => mk::XBUTTON2,
            };
        }
        if self.held(&SHIFTS) {
            flags |= mk::SHIFT;
        }
        if self.held(&CTRLS) {
            flags |= mk::CONTROL;
        }
        flags
    }

    fn time(&self) -> u32 {
        self.started.elapsed().as_millis() as u32
    }

    /// The messages of one stroke.
    fn stroke(&mut self, stroke: Stroke, out: &mut Vec<Recorded>) {
        let (code, up, unit) = match stroke {
            Stroke::Vk { vk, up } => (vk, up, None),
            Stroke::Unicode { unit, up } => (VK_PACKET, up, Some(unit)),
        };
        if unit.is_none() {
            if up {
                self.keys.remove(&code);
            } else {
                self.keys.insert(code);
            }
        }
        let mods = self.mods();
        let sys = self.system_key(code, up, mods, unit.is_some());
        out.push(Recorded::Key {
            down: !up,
            sys,
            vk: code,
            scan: unit.map_or_else(|| scan_code(code), |u| u & 0xFF),
            extended: vkeys::is_extended(code),
            repeat: false,
            mods,
            time: self.time(),
        });
        if up {
            return;
        }
        let text = match unit {
            Some(unit) => self.unit(unit),
            None if mods.ctrl && mods.alt => None,
            None => us_char(code, mods.shift, mods.ctrl).map(String::from),
        };
        if let Some(text) = text {
            out.push(Recorded::Char { text, sys: sys && unit.is_none(), mods, time: self.time() });
        }
    }

    /// Whether a stroke of `code` is a `WM_SYSKEY*` message, `mods` being the key state
    /// after it, and the Alt-alone state moved on.
    fn system_key(&mut self, code: u16, up: bool, mods: Mods, packet: bool) -> bool {
        if packet {
            return false;
        }
        if ALTS.contains(&code) {
            if up {
                return std::mem::take(&mut self.alt_alone);
            }
            self.alt_alone = !mods.ctrl;
            return !mods.ctrl;
        }
        let sys = if CTRLS.contains(&code) { up && mods.alt } else { code == VK_F10 || (mods.alt && !mods.ctrl) };
        if sys {
            self.alt_alone = false;
        }
        sys
    }

    /// A `VK_PACKET` unit: a character, or the wait for a surrogate's other half.
    fn unit(&mut self, unit: u16) -> Option<String> {
        if (0xD800..0xDC00).contains(&unit) {
            self.high_surrogate = Some(unit);
            return None;
        }
        let units = match self.high_surrogate.take() {
            Some(high) => vec![high, unit],
            None => vec![unit],
        };
        Some(String::from_utf16_lossy(&units))
    }

    fn strokes(&mut self, strokes: &[Stroke], out: &mut Vec<Recorded>) {
        for &s in strokes {
            self.stroke(s, out);
        }
    }

    /// Whether the mouse at `p` reaches the recorder: over its client area and on
    /// top there, or anywhere while a button is held (captured).
    fn reaches(&self, state: &State, p: Point) -> bool {
        if !self.buttons.is_empty() {
            return true;
        }
        state.window_at(p).is_some_and(|w| w.id == self.window && w.body().contains(p))
    }

    fn client(&self, state: &State, p: Point) -> (i32, i32) {
        let body = state.window(self.window).map(super::window::Window::body).unwrap_or_default();
        (p.x - body.x, p.y - body.y)
    }

    fn move_to(&mut self, state: &State, cursor: &mut Point, p: Point, out: &mut Vec<Recorded>) {
        *cursor = state.clamp(p);
        if self.reaches(state, *cursor) {
            let (x, y) = self.client(state, *cursor);
            out.push(Recorded::Move { x, y, mods: self.mods(), mk: self.mk(), time: self.time() });
        }
    }

    fn move_opt(&mut self, state: &State, cursor: &mut Point, x: Option<i32>, y: Option<i32>, out: &mut Vec<Recorded>) {
        if x.is_some() || y.is_some() {
            let p = Point::new(x.unwrap_or(cursor.x), y.unwrap_or(cursor.y));
            self.move_to(state, cursor, p, out);
        }
    }

    fn button(&mut self, state: &State, at: Point, button: Button, down: bool, out: &mut Vec<Recorded>) {
        let reached = self.reaches(state, at);
        let press = if down {
            if !self.buttons.contains(&button) {
                self.buttons.push(button);
            }
            let now = Instant::now();
            let double = self.last_press.is_some_and(|(b, p, t)| {
                b == button
                    && (p.x - at.x).abs() <= DOUBLE_CLICK_HALF
                    && (p.y - at.y).abs() <= DOUBLE_CLICK_HALF
                    && now.duration_since(t).as_millis() <= DOUBLE_CLICK_MS
            });
            // After a double click the next press starts afresh, as Windows counts.
            self.last_press = if double { None } else { Some((button, at, now)) };
            if double {
                Press::Double
            } else {
                Press::Down
            }
        } else {
            self.buttons.retain(|b| *b != button);
            Press::Up
        };
        if reached {
            let (x, y) = self.client(state, at);
            out.push(Recorded::Button { button, press, x, y, mods: self.mods(), mk: self.mk(), time: self.time() });
        }
    }

    fn click(&mut self, state: &State, at: Point, button: Button, count: u32, out: &mut Vec<Recorded>) {
        for _ in 0..count {
            self.button(state, at, button, true, out);
            self.button(state, at, button, false, out);
        }
    }

    /// The lines `action` makes the recorder write, from the desktop as it is before
    /// the action (the model's own key and button state moves on); nothing is written
    /// until [`Model::commit`], once the action has succeeded.
    pub(crate) fn observe(&mut self, state: &State, action: &Action) -> DesktopResult<Vec<Recorded>> {
        let mut out = Vec::new();
        let mut cursor = state.cursor;
        let focused = state.focus == self.window;
        let keys = |out: &mut Vec<Recorded>, model: &mut Model, strokes: Vec<Stroke>| {
            if focused {
                model.strokes(&strokes, out);
            }
        };
        match action {
            Action::MoveTo { x, y } => self.move_to(state, &mut cursor, Point::new(*x, *y), &mut out),
            Action::MoveRel { dx, dy } => {
                let p = Point::new(cursor.x.saturating_add(*dx), cursor.y.saturating_add(*dy));
                self.move_to(state, &mut cursor, p, &mut out);
            }
            Action::Click { x, y, button, count } => {
                self.move_opt(state, &mut cursor, *x, *y, &mut out);
                if let Some(button) = button_of(*button) {
                    self.click(state, cursor, button, *count, &mut out);
                }
            }
            Action::DoubleClick { x, y } => {
                self.move_opt(state, &mut cursor, *x, *y, &mut out);
                self.click(state, cursor, Button::Left, 2, &mut out);
            }
            Action::RightClick { x, y } => {
                self.move_opt(state, &mut cursor, *x, *y, &mut out);
                self.click(state, cursor, Button::Right, 1, &mut out);
            }
            Action::MouseDown { button, x, y } | Action::MouseUp { button, x, y } => {
                self.move_opt(state, &mut cursor, *x, *y, &mut out);
                if let Some(button) = button_of(*button) {
                    self.button(state, cursor, button, matches!(action, Action::MouseDown { .. }), &mut out);
                }
            }
            Action::Drag { from, to, button, .. } => {
                if let Some(from) = from {
                    self.move_to(state, &mut cursor, *from, &mut out);
                }
                if let Some(button) = button_of(*button) {
                    let start = cursor;
                    self.button(state, start, button, true, &mut out);
                    let mid = Point::new(start.x + (to.x - start.x) / 2, start.y + (to.y - start.y) / 2);
                    self.move_to(state, &mut cursor, mid, &mut out);
                    self.move_to(state, &mut cursor, *to, &mut out);
                    self.button(state, cursor, button, false, &mut out);
                }
            }
            Action::Scroll { x, y, dx, dy } => {
                self.move_opt(state, &mut cursor, *x, *y, &mut out);
                if self.reaches(state, cursor) {
                    let (cx, cy) = self.client(state, cursor);
                    for (horizontal, delta) in [(false, *dy), (true, *dx)] {
                        if delta != 0 {
                            let (mods, mk, time) = (self.mods(), self.mk(), self.time());
                            out.push(Recorded::Wheel { horizontal, delta, x: cx, y: cy, mods, mk, time });
                        }
                    }
                }
            }
            Action::KeyPress { key, presses } => {
                let parsed = parse_keys(key)?;
                let once = match parsed.as_slice() {
                    [single] => vk::press(*single, &us_layout),
                    many => vk::chord(many, &us_layout),
                };
                let strokes: Vec<Stroke> = (0..*presses).flat_map(|_| once.iter().copied()).collect();
                keys(&mut out, self, strokes);
            }
            Action::Hotkey { keys: names } => {
                let mut parsed = Vec::new();
                for name in names {
                    parsed.extend(parse_keys(name)?);
                }
                keys(&mut out, self, vk::chord(&parsed, &us_layout));
            }
            Action::KeyDown { key } => {
                let strokes = parse_keys(key)?.into_iter().flat_map(|k| vk::key_down(k, &us_layout)).collect();
                keys(&mut out, self, strokes);
            }
            Action::KeyUp { key } => {
                let strokes = parse_keys(key)?.into_iter().rev().flat_map(|k| vk::key_up(k, &us_layout)).collect();
                keys(&mut out, self, strokes);
            }
            Action::TypeText { text, .. } => keys(&mut out, self, vk::type_text(text, &us_layout).concat()),
            Action::Wait { .. } | Action::Unknown => {}
        }
        Ok(out)
    }

    /// Writes what [`Model::observe`] found, once the action has succeeded.
    pub(crate) fn commit(&self, records: &[Recorded]) -> DesktopResult<()> {
        self.write(records)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_us_layout_types_what_its_keys_say() {
        for c in (' '..='~').filter(|c| *c != '\u{7f}') {
            let (code, shift) = us_key(c).unwrap_or_else(|| panic!("{c:?} has no key"));
            assert_eq!(us_char(code, shift, false), Some(c), "{c:?}");
        }
        assert_eq!(us_char(0x43, false, true), Some('\u{3}'));
        assert_eq!(us_char(0x25, false, false), None);
        assert_eq!(scan_code(0x41), 0x1E);
        assert_eq!(scan_code(0x4D), 0x32);
        assert_eq!(scan_code(0x25), 0x4B);
    }
}
