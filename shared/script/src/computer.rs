//! The Navi `Computer` object of WAA's `/execute_windows` (waa-api.md §c),
//! over [`ComputerState`] that `/update_computer` sets.
//!
//! Methods keep upstream's signatures and effects, including its printing
//! (`clipboard.copy_text` prints its text; `os.open_program` prints
//! `error: Program X is not installed`, which makes the request fail) and the
//! sleep after each action ([`super::Globals::computer_action_delay`], 0.25 s).
//!
//! Deliberate differences from upstream:
//! - `mouse.drag` accepts both its real signature `drag(screen_x, screen_y)`
//!   (absolute pixels, also positionally) and the `drag(x=0.35, y=0.48)` form the
//!   LLM prompt advertises (fractions of `window_rect`, like `move_abs`); upstream
//!   raises `TypeError` for the latter (Q9).
//! - `os.open_program` never waits for the program to exit (Q10); the host decides
//!   whether it is installed.
//! - `human.*` dialogs are refused: nobody answers them on this guest.

use arena_shared::keys::parse_chord;

use super::compose::Composed as _;
use super::difflib::get_close_matches;
use super::error::{not_supported, type_error, value_error, ErrorKind, ScriptError};
use super::pyautogui::{coord, hotkey, perform, press_keys, type_text};
use super::value::{Object, Value};
use crate::args::{is_none, no_attribute, static_name, to_f64, to_i64, to_str, Args};
use crate::runtime::{ComputerState, Runtime};
use arena_shared::action::{Action, MouseButton};
use arena_shared::geometry::Point;

const MOUSE: &[&str] = &["move_id", "move_abs", "single_click", "double_click", "right_click", "scroll", "drag"];
const KEYBOARD: &[&str] = &["write", "press"];
const CLIPBOARD: &[&str] = &["copy_text", "copy_image", "paste", "view_clipboard"];
const OS: &[&str] = &["open_program", "maximize_window"];
const WINDOW_MANAGER: &[&str] = &["find_open_applications", "switch_to_application"];
const HUMAN: &[&str] = &["ask_question", "ask_action", "get_past_input"];

fn state<'s>(it: &'s mut Runtime<'_, '_>) -> Result<&'s mut ComputerState, ScriptError> {
    it.computer.as_deref_mut().ok_or_else(|| {
        ScriptError::new(ErrorKind::Attribute, "'NoneType' object has no attribute (the computer is not set up)")
    })
}

/// An attribute of one of the `Computer` objects.
pub(crate) fn attr(it: &mut Runtime<'_, '_>, object: &Object, name: &str) -> Result<Value, ScriptError> {
    let obj = Value::Object(object.clone());
    let methods: &[&'static str] = match object {
        Object::Computer => {
            return match name {
                "mouse" => Ok(Value::Object(Object::Mouse)),
                "keyboard" => Ok(Value::Object(Object::Keyboard)),
                "clipboard" => Ok(Value::Object(Object::Clipboard)),
                "os" => Ok(Value::Object(Object::ComputerOs)),
                "window_manager" => Ok(Value::Object(Object::WindowManager)),
                "search" => Ok(Value::None),
                _ => Err(no_attribute(&obj, name)),
            }
        }
        Object::Mouse => {
            let s = state(it)?;
            match name {
                "current_id" => {
                    return Ok(s.current_id.map_or(Value::None, |i| Value::Int(i64::try_from(i).unwrap_or(i64::MAX))))
                }
                "rects" => {
                    return Ok(Value::list(
                        s.rects
                            .iter()
                            .map(|r| Value::list(r.iter().map(|v| Value::Int(i64::from(*v))).collect()))
                            .collect(),
                    ))
                }
                "window_rect" => {
                    return Ok(Value::list(s.window_rect.iter().map(|v| Value::Int(i64::from(*v))).collect()))
                }
                "scale" => return Ok(Value::list(vec![Value::Float(s.scale.0), Value::Float(s.scale.1)])),
                _ => MOUSE,
            }
        }
        Object::Clipboard if name == "clipboard_content" => {
            return Ok(state(it)?.clipboard_content.clone().map_or(Value::None, Value::str));
        }
        Object::Keyboard => KEYBOARD,
        Object::Clipboard => CLIPBOARD,
        Object::ComputerOs => OS,
        Object::WindowManager => WINDOW_MANAGER,
        Object::Human => HUMAN,
        _ => &[],
    };
    static_name(methods, name).map(|m| Value::Method(Box::new(obj.clone()), m)).ok_or_else(|| no_attribute(&obj, name))
}

/// Calls a method of one of the `Computer` objects.
pub(crate) fn call_method(
    it: &mut Runtime<'_, '_>,
    object: Object,
    name: &str,
    args: Args,
) -> Result<Value, ScriptError> {
    let delay = it.action_delay;
    let result = match (&object, name) {
        (Object::Mouse, "move_id") => {
            let a = args.bind("move_id", &["id"], 1)?;
            let s = state(it)?;
            let (index, rect) = element(s, a[0].as_ref().unwrap_or(&Value::None))?;
            // Python: (r[0] + r[2]) // 2 * scale, then int() in pyautogui.
            let centre = |lo: i32, hi: i32| (i64::from(lo) + i64::from(hi)).div_euclid(2) as f64;
            let cx = centre(rect[0], rect[2]) * s.scale.0 + f64::from(s.window_rect[0]);
            let cy = centre(rect[1], rect[3]) * s.scale.1 + f64::from(s.window_rect[1]);
            s.current_id = Some(index);
            let (x, y) = (coord(&Value::Float(cx), "x")?, coord(&Value::Float(cy), "y")?);
            perform(it, Action::MoveTo { x, y })?;
            Value::None
        }
        (Object::Mouse, "move_abs") => {
            let a = args.bind("move_abs", &["x", "y"], 2)?;
            let (x, y) = fraction_to_screen(state(it)?, a[0].as_ref(), a[1].as_ref())?;
            perform(it, Action::MoveTo { x, y })?;
            Value::None
        }
        (Object::Mouse, "single_click") => {
            args.bind(name, &[], 0)?;
            perform(it, Action::Click { x: None, y: None, button: MouseButton::Left, count: 1 })?;
            Value::None
        }
        (Object::Mouse, "double_click") => {
            args.bind(name, &[], 0)?;
            perform(it, Action::DoubleClick { x: None, y: None })?;
            Value::None
        }
        (Object::Mouse, "right_click") => {
            args.bind(name, &[], 0)?;
            perform(it, Action::RightClick { x: None, y: None })?;
            Value::None
        }
        (Object::Mouse, "scroll") => {
            let a = args.bind("scroll", &["dir"], 0)?;
            let dy = match a[0].as_ref() {
                None => -400,
                Some(Value::Str(d)) if d == "down" => -400,
                Some(Value::Str(d)) if d == "up" => 400,
                Some(other) => {
                    return Err(value_error(format!(
                        "invalid scroll direction {} (expected \"up\" or \"down\")",
                        other.repr()
                    )))
                }
            };
            perform(it, Action::Scroll { x: None, y: None, dx: 0, dy })?;
            Value::None
        }
        (Object::Mouse, "drag") => {
            let (x, y) = drag_target(it, args)?;
            // Upstream's `Computer.mouse.drag` is `pyautogui.dragTo(x, y, button='left', duration=1)`.
            let to = Point::new(x, y);
            perform(it, Action::Drag { from: None, to, button: MouseButton::Left, duration_ms: Some(1000) })?;
            Value::None
        }
        (Object::Keyboard, "write") => {
            let a = args.bind("write", &["text"], 1)?;
            let text = to_str(a[0].as_ref().unwrap_or(&Value::None), "write() text")?.to_owned();
            type_text(it, &text, 0.0)?;
            Value::None
        }
        (Object::Keyboard, "press") => {
            let a = args.bind("press", &["key"], 1)?;
            let key = to_str(a[0].as_ref().unwrap_or(&Value::None), "press() key")?.to_owned();
            let keys = parse_chord(&key).map_err(|e| value_error(format!("press(): {e}")))?;
            let names: Vec<String> = keys.iter().map(ToString::to_string).collect();
            if names.len() > 1 {
                hotkey(it, names, 0.0)?;
            } else {
                press_keys(it, &names, 1, 0.0)?;
            }
            Value::None
        }
        (Object::Clipboard, "copy_text") => {
            let a = args.bind("copy_text", &["text"], 0)?;
            let text = a[0].clone().unwrap_or(Value::None);
            it.print(&format!("{}\n", text.to_str()))?;
            let content = match &text {
                Value::None => {
                    perform(it, Action::DoubleClick { x: None, y: None })?;
                    let keys = vec![ctrl_or_alt(it)?, "c".to_owned()];
                    hotkey(it, keys, 0.0)?;
                    None
                }
                Value::Str(_) | Value::Int(_) | Value::Float(_) | Value::Bool(_) => {
                    let text = text.to_str();
                    let result = it.host.clipboard_set_text(&text);
                    it.host(result)?;
                    Some(text)
                }
                other => {
                    return Err(type_error(format!(
                        "only str, int, float, and bool values can be copied to the clipboard, not {}",
                        other.type_name()
                    )))
                }
            };
            state(it)?.clipboard_content = content;
            return Ok(Value::None);
        }
        (Object::Clipboard, "copy_image") => {
            let a = args.bind("copy_image", &["id", "description"], 1)?;
            let description = match &a[1] {
                None => String::new(),
                Some(v) => to_str(v, "description")?.to_owned(),
            };
            let (_, rect) = element(state(it)?, a[0].as_ref().unwrap_or(&Value::None))?;
            let result = it.host.copy_image(rect);
            it.host(result)?;
            state(it)?.clipboard_content = Some(description);
            return Ok(Value::None);
        }
        (Object::Clipboard, "paste") => {
            args.bind("paste", &[], 0)?;
            let keys = vec![ctrl_or_alt(it)?, "v".to_owned()];
            hotkey(it, keys, 0.0)?;
            Value::None
        }
        (Object::Clipboard, "view_clipboard") => {
            args.bind("view_clipboard", &[], 0)?;
            let text = it.host.clipboard_get_text();
            return Ok(Value::str(it.host(text)?));
        }
        (Object::ComputerOs, "open_program") => {
            let a = args.bind("open_program", &["program"], 1)?;
            let program = to_str(a[0].as_ref().unwrap_or(&Value::None), "program")?.to_owned();
            let opened = it.host.open_program(&program);
            if !it.host(opened)? {
                it.print(&format!("error: Program {program} is not installed\n"))?;
                return Ok(Value::None);
            }
            let esc = |it: &mut Runtime<'_, '_>| press_keys(it, &["esc".to_owned()], 1, 0.0);
            it.sleep(2.0)?;
            esc(it)?;
            let maximized = it.host.maximize_foreground();
            it.host(maximized)?;
            esc(it)?;
            it.sleep(1.0)?;
            esc(it)?;
            it.sleep(1.0)?;
            esc(it)?;
            Value::None
        }
        (Object::ComputerOs, "maximize_window") => {
            let a = args.bind("maximize_window", &["window"], 0)?;
            if !is_none(&a[0]) {
                return Err(not_supported(
                    "maximize_window(window=...) is not supported; it maximizes the foreground window",
                ));
            }
            let maximized = it.host.maximize_foreground();
            it.host(maximized)?;
            Value::None
        }
        (Object::WindowManager, "find_open_applications") => {
            args.bind(name, &[], 0)?;
            let titles = it.host.window_titles();
            return Ok(Value::list(it.host(titles)?.into_iter().map(Value::str).collect()));
        }
        (Object::WindowManager, "switch_to_application") => {
            let a = args.bind(name, &["app_name"], 1)?;
            let app_name = to_str(a[0].as_ref().unwrap_or(&Value::None), "app_name")?.to_owned();
            let titles = it.host.window_titles();
            let titles = it.host(titles)?;
            let normalized: Vec<String> = titles.iter().map(|t| normalize_whitespace(t)).collect();
            let best = get_close_matches(&normalize_whitespace(&app_name), &normalized, 1, 0.6)
                .first()
                .map(|s| (*s).to_owned());
            let target =
                best.and_then(|m| normalized.iter().position(|n| *n == m)).and_then(|i| titles.get(i).cloned());
            let Some(title) = target else {
                it.print(&format!("No open window matches '{app_name}'.\n"))?;
                return Ok(Value::None);
            };
            let switched = it.host.switch_to_window(&title);
            it.host(switched)?;
            press_keys(it, &["esc".to_owned()], 1, 0.0)?;
            Value::None
        }
        (Object::Human, _) => {
            return Err(not_supported(format!("human.{name} is not supported: nobody answers dialogs on this guest")))
        }
        _ => return Err(no_attribute(&Value::Object(object.clone()), name)),
    };
    if delay > 0.0 {
        it.sleep(delay)?;
    }
    Ok(result)
}

/// `rects[id]` with Python's indexing (negative ids count from the end).
fn element(s: &ComputerState, id: &Value) -> Result<(usize, [i32; 4]), ScriptError> {
    let id = match id {
        Value::Int(_) | Value::Bool(_) => to_i64(id, "id")?,
        other => return Err(type_error(format!("list indices must be integers or slices, not {}", other.type_name()))),
    };
    let len = i64::try_from(s.rects.len()).unwrap_or(i64::MAX);
    let resolved = if id < 0 { id + len } else { id };
    usize::try_from(resolved)
        .ok()
        .and_then(|i| s.rects.get(i).map(|r| (i, *r)))
        .ok_or_else(|| ScriptError::new(ErrorKind::Index, "list index out of range"))
}

/// `move_abs` maths: `int(x * (wr[2] - wr[0])) + wr[0]`, likewise for y.
fn fraction_to_screen(s: &ComputerState, x: Option<&Value>, y: Option<&Value>) -> Result<(i32, i32), ScriptError> {
    let wr = s.window_rect;
    let fx = to_f64(x.unwrap_or(&Value::None), "x")?;
    let fy = to_f64(y.unwrap_or(&Value::None), "y")?;
    let extent = |lo: i32, hi: i32| (i64::from(hi) - i64::from(lo)) as f64;
    let px = coord(&Value::Float(fx * extent(wr[0], wr[2])), "x")?;
    let py = coord(&Value::Float(fy * extent(wr[1], wr[3])), "y")?;
    Ok((px.saturating_add(wr[0]), py.saturating_add(wr[1])))
}

/// `drag(screen_x, screen_y)` in pixels, or `drag(x=..., y=...)` in fractions of `window_rect`.
fn drag_target(it: &mut Runtime<'_, '_>, args: Args) -> Result<(i32, i32), ScriptError> {
    let normalized = args.kw.iter().any(|(k, _)| k == "x" || k == "y");
    if !normalized {
        let a = args.bind("drag", &["screen_x", "screen_y"], 2)?;
        let x = coord(a[0].as_ref().unwrap_or(&Value::None), "screen_x")?;
        let y = coord(a[1].as_ref().unwrap_or(&Value::None), "screen_y")?;
        return Ok((x, y));
    }
    if !args.pos.is_empty() || args.kw.iter().any(|(k, _)| k.starts_with("screen_")) {
        return Err(type_error("drag() takes either screen_x/screen_y (pixels) or x/y (fractions), not both"));
    }
    let a = args.bind("drag", &["x", "y"], 2)?;
    for (v, what) in [(&a[0], "x"), (&a[1], "y")] {
        let f = to_f64(v.as_ref().unwrap_or(&Value::None), what)?;
        if !(0.0..=1.0).contains(&f) {
            return Err(value_error(format!(
                "drag({what}={}) takes a fraction in [0, 1] of the window; pass screen_x/screen_y for pixels",
                super::value::float_repr(f)
            )));
        }
    }
    fraction_to_screen(state(it)?, a[0].as_ref(), a[1].as_ref())
}

fn ctrl_or_alt(it: &mut Runtime<'_, '_>) -> Result<String, ScriptError> {
    Ok(if state(it)?.swap_ctrl_alt { "alt" } else { "ctrl" }.to_owned())
}

/// `" ".join(s.split())`.
fn normalize_whitespace(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}
