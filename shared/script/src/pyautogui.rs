//! The `pyautogui` module, with pyautogui 0.9.54's signatures and Windows
//! semantics, mapped onto [`Action`]s.
//!
//! Coordinates go through `_normalizeXYArgs` as upstream does: `None` means the
//! current position, a 2-sequence (or a 4-sequence box, meaning its centre) may
//! replace `x, y`, and floats are truncated with `int()` ("rounded down", as
//! pyautogui documents it). `duration` and `tween` are checked and ignored:
//! every move is a jump. `pyautogui.PAUSE` defaults to 0 here (upstream 0.1 s);
//! an explicit `PAUSE = x` sleeps `x` after each input call.
//!
//! Deliberate differences from pyautogui, each fixing something an agent
//! cannot have meant:
//! - an unknown key name is an error, where pyautogui silently ignores it;
//! - `hscroll` scrolls horizontally (on Windows pyautogui scrolls vertically);
//! - `scroll(x=, y=)` moves to the point first (on Windows pyautogui ignores it);
//! - `moveRel(None, 10)` moves by (0, 10) (pyautogui fills a `None` offset with the
//!   current coordinate);
//! - `write()` types every character, including non-ASCII ones (upstream Q12 drops them).

use arena_shared::action::{Action, MouseButton};
use arena_shared::geometry::Point;
use arena_shared::keys::Key;

use super::compose::Composed as _;
use super::error::{not_supported, type_error, value_error, ScriptError};
use super::value::{heap, Object, Value};
use crate::args::{is_none, iterate, static_name, to_f64, to_str, Args};
use crate::runtime::{RunOutput, Runtime};

/// The most repetitions (`clicks`, `presses`) one call may ask for.
const MAX_REPEAT: i64 = 1000;

/// Functions that only ask (or wait) and take no automatic pause.
const QUERIES: &[&str] =
    &["position", "size", "onScreen", "screenshot", "getActiveWindowTitle", "getAllTitles", "sleep", "isValidKey"];

/// Functions that end with pyautogui's automatic pause.
const PAUSED: &[&str] = &[
    "moveTo",
    "moveRel",
    "move",
    "dragTo",
    "dragRel",
    "drag",
    "click",
    "leftClick",
    "rightClick",
    "middleClick",
    "doubleClick",
    "tripleClick",
    "mouseDown",
    "mouseUp",
    "scroll",
    "hscroll",
    "vscroll",
    "typewrite",
    "write",
    "press",
    "keyDown",
    "keyUp",
    "hotkey",
];

/// pytweening's easing functions, re-exported by pyautogui; accepted as `tween` values.
const EASINGS: &[&str] = &[
    "linear",
    "easeInQuad",
    "easeOutQuad",
    "easeInOutQuad",
    "easeInCubic",
    "easeOutCubic",
    "easeInOutCubic",
    "easeInQuart",
    "easeOutQuart",
    "easeInOutQuart",
    "easeInQuint",
    "easeOutQuint",
    "easeInOutQuint",
    "easeInSine",
    "easeOutSine",
    "easeInOutSine",
    "easeInExpo",
    "easeOutExpo",
    "easeInOutExpo",
    "easeInCirc",
    "easeOutCirc",
    "easeInOutCirc",
    "easeInElastic",
    "easeOutElastic",
    "easeInOutElastic",
    "easeInBack",
    "easeOutBack",
    "easeInOutBack",
    "easeInBounce",
    "easeOutBounce",
    "easeInOutBounce",
];

/// `pyautogui.<name>`, or `None` when this interpreter does not provide it.
pub(crate) fn attr(name: &str, out: &RunOutput) -> Option<Value> {
    if let Some(f) = static_name(PAUSED, name).or_else(|| static_name(QUERIES, name)) {
        return Some(Value::Function { module: "pyautogui", name: f });
    }
    if let Some(e) = static_name(EASINGS, name) {
        return Some(Value::Marker(e));
    }
    Some(match name {
        "FAILSAFE" => Value::Bool(out.failsafe.unwrap_or(true)),
        "PAUSE" => Value::Float(out.pause.unwrap_or(0.0)),
        "MINIMUM_DURATION" => Value::Float(0.1),
        "MINIMUM_SLEEP" => Value::Float(0.05),
        "LEFT" => Value::str("left"),
        "MIDDLE" => Value::str("middle"),
        "RIGHT" => Value::str("right"),
        "PRIMARY" => Value::str("primary"),
        "SECONDARY" => Value::str("secondary"),
        "KEYBOARD_KEYS" | "KEY_NAMES" => {
            let chars = (' '..='~').chain(['\t', '\n', '\r']).map(|c| Value::str(c.to_string()));
            let named = arena_shared::keys::NAMED_KEYS.iter().map(|k| Value::str((*k).to_owned()));
            Value::list(chars.chain(named).collect())
        }
        _ => return None,
    })
}

/// Calls `pyautogui.<name>`.
pub(crate) fn call(it: &mut Runtime<'_, '_>, name: &'static str, args: Args) -> Result<Value, ScriptError> {
    let result = dispatch(it, name, args)?;
    if PAUSED.contains(&name) {
        if let Some(pause) = it.out.pause.filter(|p| *p > 0.0) {
            it.sleep(pause)?;
        }
    }
    Ok(result)
}

const CLICK: &[&str] = &["x", "y", "clicks", "interval", "button", "duration", "tween", "logScreenshot", "_pause"];
const NAMED_CLICK: &[&str] = &["x", "y", "interval", "duration", "tween", "logScreenshot", "_pause"];
const MULTI_CLICK: &[&str] = &["x", "y", "interval", "button", "duration", "tween", "logScreenshot", "_pause"];
const MOUSE_BUTTON: &[&str] = &["x", "y", "button", "duration", "tween", "logScreenshot", "_pause"];
const MOVE_TO: &[&str] = &["x", "y", "duration", "tween", "logScreenshot", "_pause"];
const MOVE_REL: &[&str] = &["xOffset", "yOffset", "duration", "tween", "logScreenshot", "_pause"];
const DRAG_TO: &[&str] = &["x", "y", "duration", "tween", "button", "logScreenshot", "_pause", "mouseDownUp"];
const DRAG_REL: &[&str] =
    &["xOffset", "yOffset", "duration", "tween", "button", "logScreenshot", "_pause", "mouseDownUp"];
const SCROLL: &[&str] = &["clicks", "x", "y", "logScreenshot", "_pause"];

fn dispatch(it: &mut Runtime<'_, '_>, name: &'static str, args: Args) -> Result<Value, ScriptError> {
    match name {
        "click" => {
            let a = args.bind(name, CLICK, 0)?;
            let button = button(&a[4])?;
            let at = normalize_xy(it, &a[0], &a[1])?;
            let clicks = count(&a[2], "clicks")?;
            let interval = seconds(&a[3], "interval")?;
            check_number(&a[5], "duration")?;
            clicks_at(it, at, button, clicks, interval, ClickKind::Generic)?;
        }
        "leftClick" | "rightClick" | "middleClick" => {
            let a = args.bind(name, NAMED_CLICK, 0)?;
            let at = normalize_xy(it, &a[0], &a[1])?;
            let interval = seconds(&a[2], "interval")?;
            check_number(&a[3], "duration")?;
            let (button, kind) = match name {
                "leftClick" => (MouseButton::Left, ClickKind::Generic),
                "rightClick" => (MouseButton::Right, ClickKind::Right),
                _ => (MouseButton::Middle, ClickKind::Generic),
            };
            clicks_at(it, at, button, 1, interval, kind)?;
        }
        "doubleClick" | "tripleClick" => {
            let a = args.bind(name, MULTI_CLICK, 0)?;
            let at = normalize_xy(it, &a[0], &a[1])?;
            let interval = seconds(&a[2], "interval")?;
            let button = button(&a[3])?;
            check_number(&a[4], "duration")?;
            let (clicks, kind) = if name == "doubleClick" { (2, ClickKind::Double) } else { (3, ClickKind::Generic) };
            clicks_at(it, at, button, clicks, interval, kind)?;
        }
        "mouseDown" | "mouseUp" => {
            let a = args.bind(name, MOUSE_BUTTON, 0)?;
            let button = button(&a[2])?;
            let at = normalize_xy(it, &a[0], &a[1])?;
            let (x, y) = (at.map(|p| p.0), at.map(|p| p.1));
            let action =
                if name == "mouseDown" { Action::MouseDown { button, x, y } } else { Action::MouseUp { button, x, y } };
            perform(it, action)?;
        }
        "moveTo" => {
            let a = args.bind(name, MOVE_TO, 0)?;
            let (x, y) = full_xy(it, &a[0], &a[1])?;
            check_number(&a[2], "duration")?;
            perform(it, Action::MoveTo { x, y })?;
        }
        "moveRel" | "move" => {
            let a = args.bind(name, MOVE_REL, 0)?;
            let (dx, dy) = offsets(&a[0], &a[1])?;
            check_number(&a[2], "duration")?;
            if (dx, dy) != (0, 0) {
                perform(it, Action::MoveRel { dx, dy })?;
            }
        }
        "dragTo" => {
            let a = args.bind(name, DRAG_TO, 0)?;
            let (x, y) = full_xy(it, &a[0], &a[1])?;
            let duration = duration_ms(&a[2])?;
            let button = button(&a[4])?;
            let down_up = a[7].as_ref().is_none_or(Value::truthy);
            drag_to(it, x, y, button, down_up, duration)?;
        }
        "dragRel" | "drag" => {
            let a = args.bind(name, DRAG_REL, 0)?;
            let (dx, dy) = offsets(&a[0], &a[1])?;
            let duration = duration_ms(&a[2])?;
            let button = button(&a[4])?;
            let down_up = a[7].as_ref().is_none_or(Value::truthy);
            if (dx, dy) != (0, 0) {
                let cursor = it.host.cursor_position();
                let (cx, cy) = it.host(cursor)?;
                drag_to(it, cx.saturating_add(dx), cy.saturating_add(dy), button, down_up, duration)?;
            }
        }
        "scroll" | "vscroll" | "hscroll" => {
            let a = args.bind(name, SCROLL, 1)?;
            let amount = coord(a[0].as_ref().unwrap_or(&Value::None), "clicks")?;
            let (x, y) = match &a[1] {
                Some(seq @ (Value::List(_) | Value::Tuple(_))) => {
                    let items = iterate(seq)?;
                    (items.first().cloned(), items.get(1).cloned())
                }
                other => (other.clone(), a[2].clone()),
            };
            let at = normalize_xy(it, &x, &y)?;
            let (dx, dy) = if name == "hscroll" { (amount, 0) } else { (0, amount) };
            perform(it, Action::Scroll { x: at.map(|p| p.0), y: at.map(|p| p.1), dx, dy })?;
        }
        "typewrite" | "write" => {
            let a = args.bind(name, &["message", "interval", "logScreenshot", "_pause"], 1)?;
            let interval = seconds(&a[1], "interval")?;
            match a[0].as_ref().unwrap_or(&Value::None) {
                Value::Str(text) => type_text(it, text, interval)?,
                seq @ (Value::List(_) | Value::Tuple(_)) => {
                    let keys = key_list(name, seq)?;
                    for key in keys {
                        perform(it, Action::KeyPress { key, presses: 1 })?;
                        if interval > 0.0 {
                            it.sleep(interval)?;
                        }
                    }
                }
                other => {
                    return Err(type_error(format!(
                        "{name}() message must be a str or a list of key names, not {}",
                        other.type_name()
                    )))
                }
            }
        }
        "press" => {
            let a = args.bind(name, &["keys", "presses", "interval", "logScreenshot", "_pause"], 1)?;
            let keys = match a[0].as_ref().unwrap_or(&Value::None) {
                Value::Str(k) => vec![key_name(name, k)?],
                other => key_list(name, other)?,
            };
            let presses = count(&a[1], "presses")?;
            let interval = seconds(&a[2], "interval")?;
            press_keys(it, &keys, presses, interval)?;
        }
        "keyDown" | "keyUp" => {
            let a = args.bind(name, &["key", "logScreenshot", "_pause"], 1)?;
            let key = key_name(name, to_str(a[0].as_ref().unwrap_or(&Value::None), "key")?)?;
            let action = if name == "keyDown" { Action::KeyDown { key } } else { Action::KeyUp { key } };
            perform(it, action)?;
        }
        "hotkey" => {
            let mut interval = 0.0;
            for (k, v) in &args.kw {
                match k.as_str() {
                    "interval" => interval = seconds(&Some(v.clone()), "interval")?,
                    "logScreenshot" | "_pause" => {}
                    other => return Err(type_error(format!("hotkey() got an unexpected keyword argument '{other}'"))),
                }
            }
            // A single list argument is accepted too, as later pyautogui versions do.
            let keys = match args.pos.as_slice() {
                [seq @ (Value::List(_) | Value::Tuple(_))] => key_list(name, seq)?,
                pos => key_list(name, &Value::tuple(pos.to_vec()))?,
            };
            hotkey(it, keys, interval)?;
        }
        "position" => {
            let a = args.bind(name, &["x", "y"], 0)?;
            let cursor = it.host.cursor_position();
            let (mut x, mut y) = it.host(cursor)?;
            if !is_none(&a[0]) {
                x = coord(a[0].as_ref().unwrap_or(&Value::None), "x")?;
            }
            if !is_none(&a[1]) {
                y = coord(a[1].as_ref().unwrap_or(&Value::None), "y")?;
            }
            return Ok(Value::Point(i64::from(x), i64::from(y)));
        }
        "size" => {
            args.bind(name, &[], 0)?;
            let (w, h) = screen(it)?;
            return Ok(Value::Size(w, h));
        }
        "onScreen" => {
            let a = args.bind(name, &["x", "y"], 1)?;
            let (x, y) = match normalize_xy(it, &a[0], &a[1])? {
                Some(p) => p,
                None => return Err(type_error("onScreen() needs coordinates")),
            };
            let (w, h) = screen(it)?;
            let (x, y) = (i64::from(x), i64::from(y));
            return Ok(Value::Bool(x >= 0 && y >= 0 && x < w && y < h));
        }
        "screenshot" => {
            let a = args.bind(name, &["imageFilename", "region"], 0)?;
            let image = screenshot_image(it, &a[1])?;
            if let Some(path) = a[0].as_ref().filter(|v| !matches!(v, Value::None)) {
                let path = to_str(path, "imageFilename")?.to_owned();
                let region = match &image {
                    Value::Object(Object::Image { region, .. }) => *region,
                    _ => None,
                };
                let saved = it.host.save_screenshot(&path, region, None);
                it.host(saved)?;
            }
            return Ok(image);
        }
        "getActiveWindowTitle" => {
            args.bind(name, &[], 0)?;
            let title = it.host.active_window_title();
            return Ok(Value::str(it.host(title)?));
        }
        "getAllTitles" => {
            args.bind(name, &[], 0)?;
            let titles = it.host.window_titles();
            return Ok(Value::list(it.host(titles)?.into_iter().map(Value::str).collect()));
        }
        "sleep" => {
            let a = args.bind(name, &["seconds"], 1)?;
            let secs = to_f64(a[0].as_ref().unwrap_or(&Value::None), "seconds")?;
            it.sleep(secs)?;
        }
        "isValidKey" => {
            let a = args.bind(name, &["key"], 1)?;
            let key = to_str(a[0].as_ref().unwrap_or(&Value::None), "key")?;
            return Ok(Value::Bool(Key::parse(key).is_ok()));
        }
        other => return Err(not_supported(format!("pyautogui.{other} is not supported"))),
    }
    Ok(Value::None)
}

/// Which action a click call becomes when it is one action.
#[derive(Clone, Copy, PartialEq, Eq)]
enum ClickKind {
    Generic,
    Double,
    Right,
}

pub(crate) fn perform(it: &mut Runtime<'_, '_>, action: Action) -> Result<(), ScriptError> {
    if it.host.keeps_actions() {
        heap::hold(crate::host::action_bytes(&action))?;
    }
    let result = it.host.perform(action);
    it.host(result)
}

fn screen(it: &mut Runtime<'_, '_>) -> Result<(i64, i64), ScriptError> {
    let size = it.host.screen_size();
    let (w, h) = it.host(size)?;
    Ok((i64::from(w), i64::from(h)))
}

/// The image object `screenshot(region=...)` returns.
pub(crate) fn screenshot_image(it: &mut Runtime<'_, '_>, region: &Option<Value>) -> Result<Value, ScriptError> {
    match region.as_ref().filter(|v| !matches!(v, Value::None)) {
        None => {
            let (width, height) = screen(it)?;
            Ok(Value::Object(Object::Image { width, height, region: None }))
        }
        Some(r) => {
            let items = iterate(r)?;
            let [l, t, w, h] = items.as_slice() else {
                return Err(value_error("region must be a 4-item sequence (left, top, width, height)"));
            };
            let rect = [coord(l, "left")?, coord(t, "top")?, coord(w, "width")?, coord(h, "height")?];
            if rect[2] <= 0 || rect[3] <= 0 {
                return Err(value_error("region width and height must be positive"));
            }
            Ok(Value::Object(Object::Image {
                width: i64::from(rect[2]),
                height: i64::from(rect[3]),
                region: Some(rect),
            }))
        }
    }
}

/// `int(v)` of a coordinate: ints as they are, floats truncated toward zero.
pub(crate) fn coord(v: &Value, what: &str) -> Result<i32, ScriptError> {
    let i = match v {
        Value::Bool(b) => i64::from(*b),
        Value::Int(i) => *i,
        Value::Float(f) => {
            if !f.is_finite() {
                return Err(value_error(format!(
                    "{what} must be a finite number, not {}",
                    super::value::float_repr(*f)
                )));
            }
            let t = f.trunc();
            if t.abs() > 1e15 {
                return Err(value_error(format!(
                    "{what} {} is outside the screen coordinate range",
                    super::value::float_repr(*f)
                )));
            }
            t as i64
        }
        Value::Str(_) => {
            return Err(not_supported(
                "locating an image on screen (a file name as a coordinate) is not supported; pass x and y",
            ))
        }
        other => {
            return Err(type_error(format!(
                "{what}: int() argument must be a string, a bytes-like object or a real number, not '{}'",
                other.type_name()
            )))
        }
    };
    i32::try_from(i).map_err(|_| value_error(format!("{what} {i} is outside the screen coordinate range")))
}

/// pyautogui's `_normalizeXYArgs`, returning `None` when both are absent (the current position).
pub(crate) fn normalize_xy(
    it: &mut Runtime<'_, '_>,
    x: &Option<Value>,
    y: &Option<Value>,
) -> Result<Option<(i32, i32)>, ScriptError> {
    let x = x.as_ref().filter(|v| !matches!(v, Value::None));
    let y = y.as_ref().filter(|v| !matches!(v, Value::None));
    let cursor = |it: &mut Runtime<'_, '_>| {
        let pos = it.host.cursor_position();
        it.host(pos)
    };
    match (x, y) {
        (None, None) => Ok(None),
        (Some(seq @ (Value::List(_) | Value::Tuple(_) | Value::Point(..) | Value::Size(..))), y) => {
            if let Some(y) = y {
                return Err(value_error(format!(
                    "When passing a sequence for firstArg, secondArg must not be passed (received {}).",
                    y.repr()
                )));
            }
            let items = iterate(seq)?;
            match items.as_slice() {
                [x, y] => Ok(Some((coord(x, "x")?, coord(y, "y")?))),
                [l, t, w, h] => {
                    // pyscreeze.center: left + int(width / 2), top + int(height / 2).
                    let half = |v: &Value, what| -> Result<i32, ScriptError> {
                        coord(&Value::Float(to_f64(v, what)? / 2.0), what)
                    };
                    Ok(Some((
                        coord(l, "left")?.saturating_add(half(w, "width")?),
                        coord(t, "top")?.saturating_add(half(h, "height")?),
                    )))
                }
                other => Err(value_error(format!(
                    "The supplied sequence must have exactly 2 or exactly 4 elements ({} were received).",
                    other.len()
                ))),
            }
        }
        (None, Some(y)) => {
            let y = coord(y, "y")?;
            Ok(Some((cursor(it)?.0, y)))
        }
        (Some(x), None) => {
            let x = coord(x, "x")?;
            Ok(Some((x, cursor(it)?.1)))
        }
        (Some(x), Some(y)) => Ok(Some((coord(x, "x")?, coord(y, "y")?))),
    }
}

/// Like [`normalize_xy`], with the current position filled in.
pub(crate) fn full_xy(
    it: &mut Runtime<'_, '_>,
    x: &Option<Value>,
    y: &Option<Value>,
) -> Result<(i32, i32), ScriptError> {
    match normalize_xy(it, x, y)? {
        Some(p) => Ok(p),
        None => {
            let pos = it.host.cursor_position();
            it.host(pos)
        }
    }
}

/// Relative offsets: `None` is 0, a 2-sequence may stand for both.
fn offsets(x: &Option<Value>, y: &Option<Value>) -> Result<(i32, i32), ScriptError> {
    if let Some(seq @ (Value::List(_) | Value::Tuple(_) | Value::Point(..))) = x {
        let items = iterate(seq)?;
        return match items.as_slice() {
            [x, y] => Ok((coord(x, "xOffset")?, coord(y, "yOffset")?)),
            other => Err(value_error(format!(
                "The supplied sequence must have exactly 2 elements ({} were received).",
                other.len()
            ))),
        };
    }
    let one = |v: &Option<Value>, what| match v {
        None | Some(Value::None) => Ok(0),
        Some(v) => coord(v, what),
    };
    Ok((one(x, "xOffset")?, one(y, "yOffset")?))
}

/// pyautogui's `_normalizeButton`.
pub(crate) fn button(v: &Option<Value>) -> Result<MouseButton, ScriptError> {
    match v {
        None => Ok(MouseButton::Left),
        Some(Value::Str(s)) if matches!(s.as_str(), "left" | "primary") => Ok(MouseButton::Left),
        Some(Value::Str(s)) if matches!(s.as_str(), "right" | "secondary") => Ok(MouseButton::Right),
        Some(Value::Str(s)) if s == "middle" => Ok(MouseButton::Middle),
        Some(Value::Int(1)) => Ok(MouseButton::Left),
        Some(Value::Int(2)) => Ok(MouseButton::Middle),
        Some(Value::Int(3)) => Ok(MouseButton::Right),
        Some(other) => Err(value_error(format!(
            "button argument must be one of ('left', 'middle', 'right', 'primary', 'secondary', 1, 2, 3), not {}",
            other.repr()
        ))),
    }
}

/// A repetition count (`clicks`, `presses`): default 1, negative means none.
fn count(v: &Option<Value>, what: &str) -> Result<u32, ScriptError> {
    let n = match v {
        None => 1,
        Some(v @ (Value::Int(_) | Value::Bool(_))) => crate::args::to_i64(v, what)?,
        Some(other) => {
            return Err(type_error(format!(
                "'{}' object cannot be interpreted as an integer ({what})",
                other.type_name()
            )))
        }
    };
    if n > MAX_REPEAT {
        return Err(value_error(format!("{what}={n} is more than this interpreter allows ({MAX_REPEAT})")));
    }
    Ok(u32::try_from(n.max(0)).unwrap_or(0))
}

/// A non-negative duration in seconds (`interval`); absent is 0.
fn seconds(v: &Option<Value>, what: &str) -> Result<f64, ScriptError> {
    let s = match v {
        None | Some(Value::None) => 0.0,
        Some(v) => to_f64(v, what)?,
    };
    if s.is_nan() || s < 0.0 {
        return Err(value_error(format!("{what}: sleep length must be non-negative")));
    }
    Ok(s)
}

/// Checks that an ignored numeric argument such as `duration` is a number.
fn check_number(v: &Option<Value>, what: &str) -> Result<(), ScriptError> {
    match v {
        None | Some(Value::None) => Ok(()),
        Some(v) => to_f64(v, what).map(drop),
    }
}

fn clicks_at(
    it: &mut Runtime<'_, '_>,
    at: Option<(i32, i32)>,
    button: MouseButton,
    clicks: u32,
    interval: f64,
    kind: ClickKind,
) -> Result<(), ScriptError> {
    let (x, y) = (at.map(|p| p.0), at.map(|p| p.1));
    if clicks == 0 {
        if let Some((x, y)) = at {
            perform(it, Action::MoveTo { x, y })?;
        }
        return Ok(());
    }
    if interval > 0.0 {
        // pyautogui sleeps `interval` after every click, including the last.
        for i in 0..clicks {
            let (x, y) = if i == 0 { (x, y) } else { (None, None) };
            perform(it, Action::Click { x, y, button, count: 1 })?;
            it.sleep(interval)?;
        }
        return Ok(());
    }
    let action = match (kind, button, clicks) {
        (ClickKind::Double, MouseButton::Left, 2) => Action::DoubleClick { x, y },
        (ClickKind::Right, MouseButton::Right, 1) => Action::RightClick { x, y },
        _ => Action::Click { x, y, button, count: clicks },
    };
    perform(it, action)
}

fn drag_to(
    it: &mut Runtime<'_, '_>,
    x: i32,
    y: i32,
    button: MouseButton,
    down_up: bool,
    duration_ms: Option<u64>,
) -> Result<(), ScriptError> {
    let action = if down_up {
        Action::Drag { from: None, to: Point::new(x, y), button, duration_ms }
    } else {
        Action::MoveTo { x, y }
    };
    perform(it, action)
}

/// pyautogui's `duration` in milliseconds, `None` when there is none to spread the
/// move over (none, zero, or negative, which pyautogui treats as instant); a value
/// that is not a number is a `TypeError` as in pyautogui.
fn duration_ms(v: &Option<Value>) -> Result<Option<u64>, ScriptError> {
    match v {
        None | Some(Value::None) => Ok(None),
        Some(v) => {
            let seconds = to_f64(v, "duration")?;
            // At most an hour: the guest refuses longer actions anyway.
            let ms = (seconds.clamp(0.0, 3600.0) * 1000.0).round() as u64;
            Ok((ms > 0).then_some(ms))
        }
    }
}

/// Validates a key name and returns its canonical pyautogui name.
pub(crate) fn key_name(func: &str, name: &str) -> Result<String, ScriptError> {
    Key::parse(name).map(|k| k.to_string()).map_err(|e| {
        value_error(format!("{func}(): {e}; pyautogui would silently ignore it, this interpreter refuses"))
    })
}

fn key_list(func: &str, seq: &Value) -> Result<Vec<String>, ScriptError> {
    let items = match seq {
        Value::List(items) | Value::Tuple(items) => items,
        other => {
            return Err(type_error(format!("{func}() keys must be a str or a list of str, not {}", other.type_name())))
        }
    };
    items
        .iter()
        .map(|item| match item {
            Value::Str(s) => key_name(func, s),
            other => Err(type_error(format!("{func}() key names must be str, not {}", other.type_name()))),
        })
        .collect()
}

pub(crate) fn press_keys(
    it: &mut Runtime<'_, '_>,
    keys: &[String],
    presses: u32,
    interval: f64,
) -> Result<(), ScriptError> {
    if let ([key], 0.0) = (keys, interval) {
        if presses > 0 {
            perform(it, Action::KeyPress { key: key.clone(), presses })?;
        }
        return Ok(());
    }
    for _ in 0..presses {
        for key in keys {
            perform(it, Action::KeyPress { key: key.clone(), presses: 1 })?;
        }
        if interval > 0.0 {
            it.sleep(interval)?;
        }
    }
    Ok(())
}

pub(crate) fn hotkey(it: &mut Runtime<'_, '_>, keys: Vec<String>, interval: f64) -> Result<(), ScriptError> {
    if keys.is_empty() {
        return Ok(());
    }
    if interval <= 0.0 {
        return perform(it, Action::Hotkey { keys });
    }
    for key in &keys {
        perform(it, Action::KeyDown { key: key.clone() })?;
        it.sleep(interval)?;
    }
    for key in keys.iter().rev() {
        perform(it, Action::KeyUp { key: key.clone() })?;
        it.sleep(interval)?;
    }
    Ok(())
}

/// `pyautogui.write(text)`: runs of text are typed as Unicode; `\n` and `\r`
/// press Enter, `\t` Tab and `\b` Backspace, as pyautogui maps those characters to keys.
pub(crate) fn type_text(it: &mut Runtime<'_, '_>, text: &str, interval: f64) -> Result<(), ScriptError> {
    let interval_ms = (interval > 0.0).then(|| (interval * 1000.0).round() as u64);
    let mut run = String::new();
    for c in text.chars() {
        let key = match c {
            '\n' | '\r' => "enter",
            '\t' => "tab",
            '\x08' => "backspace",
            c => {
                run.push(c);
                continue;
            }
        };
        if !run.is_empty() {
            perform(it, Action::TypeText { text: std::mem::take(&mut run), interval_ms })?;
        }
        perform(it, Action::KeyPress { key: key.to_owned(), presses: 1 })?;
        if interval > 0.0 {
            it.sleep(interval)?;
        }
    }
    if !run.is_empty() {
        perform(it, Action::TypeText { text: run, interval_ms })?;
    }
    Ok(())
}
