//! Anthropic's `computer` tool input (`computer_20250124`, `computer_20251124`).
//!
//! The actions and parameters are those of Anthropic's published computer-use
//! tool documentation for these versions:
//!
//! | action | parameters | becomes |
//! |---|---|---|
//! | `key` | `text`: xdotool key syntax, chords joined by `+`, several separated by spaces | a press or hotkey per chord |
//! | `hold_key` | `text`, `duration` (seconds) | key downs, a wait, key ups |
//! | `type` | `text` | typed text |
//! | `cursor_position` | | [`Step::CursorPosition`] (the agent answers) |
//! | `mouse_move` | `coordinate` | a move |
//! | `left_mouse_down`, `left_mouse_up` | | a left press or release where the cursor is |
//! | `left_click`, `right_click`, `middle_click`, `double_click`, `triple_click` | `coordinate` (optional), `text` (modifier keys held during the click, optional) | a click |
//! | `left_click_drag` | `start_coordinate`, `coordinate` | a drag |
//! | `scroll` | `coordinate` (optional), `scroll_direction` (`up`/`down`/`left`/`right`), `scroll_amount` (wheel notches), `text` (modifiers, optional) | wheel turns of 120 per notch |
//! | `wait` | `duration` (seconds) | a wait |
//! | `screenshot` | | [`Step::Screenshot`] |
//! | `zoom` (`computer_20251124` only) | `region` `[x1, y1, x2, y2]` | [`Step::Zoom`] (the agent answers) |
//!
//! `computer_toolset_20260801` ([`parse_member`]) offers the same actions as
//! member tools: a `tool_use` block is named by its member (`left_click`) and its
//! `input` holds the parameters above without `action`; `key` also takes `repeat`
//! (1 to [`MAX_KEY_REPEAT`] presses of the whole key string), and `zoom` is a
//! member. The member names and parameters are the `anthropic` SDK's
//! (`types/computer_member_name.py` and `computer_*_input.py`, release 2.14.0).
//!
//! Coordinates are pixels of the screenshot the model was shown; the agent
//! passes that size as [`Coords::Image`](super::Coords::Image). Keys are xdotool
//! keysym names (`Return`, `Page_Down`, `super`, `KP_0`), mapped by [`KEYS`].

use serde_json::Value;

use arena_shared::action::{Action, MouseButton};
use arena_shared::geometry::Point;

use super::{chord, json_type, key_name, millis, number, opt_number, string, ActionError, ActionSpace, Context, Step};

/// xdotool keysym names (lowercased) to pyautogui names; names not listed
/// (`a`, `f5`, `ctrl`, `alt`, `shift`, `tab`, `up`, `home`, ...) are pyautogui's own.
pub const KEYS: super::KeyTable = &[
    ("return", "enter"),
    ("kp_enter", "enter"),
    ("escape", "esc"),
    ("control", "ctrl"),
    ("control_l", "ctrlleft"),
    ("control_r", "ctrlright"),
    ("alt_l", "altleft"),
    ("alt_r", "altright"),
    ("shift_l", "shiftleft"),
    ("shift_r", "shiftright"),
    ("super", "win"),
    ("super_l", "winleft"),
    ("super_r", "winright"),
    ("meta", "win"),
    ("cmd", "win"),
    ("page_up", "pageup"),
    ("prior", "pageup"),
    ("page_down", "pagedown"),
    ("next", "pagedown"),
    ("caps_lock", "capslock"),
    ("num_lock", "numlock"),
    ("scroll_lock", "scrolllock"),
    ("print", "printscreen"),
    ("menu", "apps"),
    ("kp_0", "num0"),
    ("kp_1", "num1"),
    ("kp_2", "num2"),
    ("kp_3", "num3"),
    ("kp_4", "num4"),
    ("kp_5", "num5"),
    ("kp_6", "num6"),
    ("kp_7", "num7"),
    ("kp_8", "num8"),
    ("kp_9", "num9"),
    ("kp_add", "add"),
    ("kp_subtract", "subtract"),
    ("kp_multiply", "multiply"),
    ("kp_divide", "divide"),
    ("kp_decimal", "decimal"),
    ("kp_separator", "separator"),
    ("xf86audiomute", "volumemute"),
    ("xf86audioraisevolume", "volumeup"),
    ("xf86audiolowervolume", "volumedown"),
    ("xf86audioplay", "playpause"),
    ("xf86audionext", "nexttrack"),
    ("xf86audioprev", "prevtrack"),
    ("xf86audiostop", "stop"),
    ("xf86back", "browserback"),
    ("xf86forward", "browserforward"),
    ("xf86reload", "browserrefresh"),
    ("xf86homepage", "browserhome"),
    ("xf86search", "browsersearch"),
    ("xf86mail", "launchmail"),
    ("kp_home", "home"),
    ("kp_end", "end"),
    ("kp_up", "up"),
    ("kp_down", "down"),
    ("kp_left", "left"),
    ("kp_right", "right"),
    ("kp_page_up", "pageup"),
    ("kp_page_down", "pagedown"),
    ("kp_insert", "insert"),
    ("kp_delete", "delete"),
    ("minus", "-"),
    ("plus", "+"),
    ("equal", "="),
    ("comma", ","),
    ("period", "."),
    ("slash", "/"),
    ("backslash", "\\"),
    ("semicolon", ";"),
    ("apostrophe", "'"),
    ("grave", "`"),
    ("bracketleft", "["),
    ("bracketright", "]"),
    ("quotedbl", "\""),
    ("exclam", "!"),
    ("at", "@"),
    ("numbersign", "#"),
    ("dollar", "$"),
    ("percent", "%"),
    ("asciicircum", "^"),
    ("ampersand", "&"),
    ("asterisk", "*"),
    ("parenleft", "("),
    ("parenright", ")"),
    ("underscore", "_"),
    ("braceleft", "{"),
    ("braceright", "}"),
    ("bar", "|"),
    ("colon", ":"),
    ("less", "<"),
    ("greater", ">"),
    ("question", "?"),
    ("asciitilde", "~"),
];

/// The members of `computer_toolset_20260801`, as the SDK lists them
/// (`BETA_COMPUTER_MEMBER_NAME_VALUES`): the actions of `computer_20251124`, in
/// the same order.
pub const TOOLSET_MEMBERS: [&str; 17] = [
    "key",
    "hold_key",
    "type",
    "cursor_position",
    "mouse_move",
    "left_mouse_down",
    "left_mouse_up",
    "left_click",
    "left_click_drag",
    "right_click",
    "middle_click",
    "double_click",
    "triple_click",
    "scroll",
    "wait",
    "screenshot",
    "zoom",
];

/// The actions of `computer_20250124`: every member but `zoom`.
pub const ACTIONS_20250124: &[&str] = TOOLSET_MEMBERS.split_at(16).0;

/// The most presses one toolset `key` call may ask for (`repeat`).
pub const MAX_KEY_REPEAT: u32 = 100;

/// One `tool_use` block of a `computer_toolset_20260801` member,
/// `{"name": member, "input": {...}}` (other keys of the block, `id`, `type` and
/// `toolset_name`, are ignored).
///
/// # Errors
///
/// [`ActionError`] naming the member: an unknown member, an input that is not an
/// object or carries `action`, a `repeat` out of range, or what [`parse`] finds
/// wrong with the member's parameters.
pub fn parse_member(block: &Value, ctx: &Context) -> Result<Vec<Step>, ActionError> {
    let space = ActionSpace::AnthropicToolset20260801;
    if !block.is_object() {
        return Err(ActionError::new(space, format!("expected a tool_use block object, got {}", json_type(block))));
    }
    let name = string(space, block, "name")?;
    if !TOOLSET_MEMBERS.contains(&name) {
        return Err(ActionError::new(
            space,
            format!("unknown member {name:?} (expected one of {})", TOOLSET_MEMBERS.join(", ")),
        ));
    }
    let member = |message: String| ActionError::new(space, format!("{name}: {message}"));
    let mut input = match block.get("input") {
        None | Some(Value::Null) => serde_json::Map::new(),
        Some(Value::Object(map)) => map.clone(),
        Some(other) => return Err(member(format!("`input` must be an object, got {}", json_type(other)))),
    };
    if input.contains_key("action") {
        return Err(member("a member's input carries no `action` (the member's name is the action)".into()));
    }
    let repeat = match input.remove("repeat") {
        None | Some(Value::Null) => 1,
        Some(_) if name != "key" => return Err(member("only `key` takes `repeat`".into())),
        Some(Value::Number(n)) => match n.as_u64() {
            Some(r) if (1..=u64::from(MAX_KEY_REPEAT)).contains(&r) => r as usize,
            _ => return Err(member(format!("`repeat` must be a whole number from 1 to {MAX_KEY_REPEAT}, got {n}"))),
        },
        Some(other) => return Err(member(format!("`repeat` must be a number, got {}", json_type(&other)))),
    };
    input.insert("action".into(), Value::String(name.to_owned()));
    let steps = parse(space, &Value::Object(input), ctx).map_err(|err| member(err.message))?;
    Ok(steps.iter().cloned().cycle().take(steps.len() * repeat).collect())
}

/// The chords of an xdotool key string: `"ctrl+a Delete"` is two.
///
/// # Errors
///
/// [`ActionError`] naming an unknown key or an empty chord.
pub fn chords(space: ActionSpace, text: &str) -> Result<Vec<Vec<String>>, ActionError> {
    let text = text.trim();
    if text.is_empty() {
        return Err(ActionError::new(space, "`text` names no key"));
    }
    text.split_whitespace()
        .map(|c| {
            // A lone `+` is the plus key; otherwise `+` joins the keys of a chord.
            let parts: Vec<&str> = if c == "+" { vec!["+"] } else { c.split('+').collect() };
            parts
                .into_iter()
                .map(|k| {
                    if k.is_empty() {
                        Err(ActionError::new(space, format!("empty key in {c:?}")))
                    } else {
                        key_name(space, KEYS, k)
                    }
                })
                .collect()
        })
        .collect()
}

/// One `computer` tool input of `space` (either Anthropic version).
///
/// # Errors
///
/// [`ActionError`] for an unknown action (or `zoom` in `computer_20250124`), a
/// missing or malformed parameter, or an unknown key.
pub fn parse(space: ActionSpace, input: &Value, ctx: &Context) -> Result<Vec<Step>, ActionError> {
    if !input.is_object() {
        return Err(ActionError::new(space, format!("expected a tool input object, got {}", json_type(input))));
    }
    let action = string(space, input, "action")?;
    let coordinate = |key: &str| -> Result<Option<(i32, i32)>, ActionError> {
        match input.get(key) {
            None | Some(Value::Null) => Ok(None),
            Some(Value::Array(xy)) if xy.len() == 2 && xy.iter().all(Value::is_number) => {
                let (x, y) = (xy[0].as_f64().unwrap_or_default(), xy[1].as_f64().unwrap_or_default());
                if x < 0.0 || y < 0.0 {
                    return Err(ActionError::new(space, format!("`{key}` must not be negative, got [{x}, {y}]")));
                }
                Ok(Some(ctx.point(x, y)))
            }
            Some(other) => Err(ActionError::new(space, format!("`{key}` must be [x, y], got {other}"))),
        }
    };
    let required =
        |key: &str| coordinate(key)?.ok_or_else(|| ActionError::new(space, format!("{action} needs `{key}`")));
    // Modifier keys held during a click or scroll (`text` on those actions).
    let modifiers = || -> Result<Vec<String>, ActionError> {
        match input.get("text") {
            None | Some(Value::Null) => Ok(Vec::new()),
            Some(Value::String(t)) if t.trim().is_empty() => Ok(Vec::new()),
            Some(Value::String(t)) => Ok(chords(space, t)?.concat()),
            Some(other) => Err(ActionError::new(space, format!("`text` must be a string, got {other}"))),
        }
    };
    let held = |mods: Vec<String>, inner: Vec<Action>| -> Vec<Step> {
        let downs = mods.iter().map(|k| Action::KeyDown { key: k.clone() });
        let ups = mods.iter().rev().map(|k| Action::KeyUp { key: k.clone() });
        downs.chain(inner).chain(ups).map(Step::Act).collect()
    };
    let click = |button: MouseButton, count: u32| -> Result<Vec<Step>, ActionError> {
        let at = coordinate("coordinate")?;
        let (x, y) = (at.map(|p| p.0), at.map(|p| p.1));
        Ok(held(modifiers()?, vec![Action::Click { x, y, button, count }]))
    };
    match action {
        "key" => Ok(chords(space, string(space, input, "text")?)?.into_iter().map(|c| Step::Act(chord(c))).collect()),
        "hold_key" => {
            let keys = chords(space, string(space, input, "text")?)?.concat();
            let ms = millis(space, "duration", number(space, input, "duration")?)?;
            Ok(held(keys, vec![Action::Wait { ms }]))
        }
        "type" => {
            Ok(vec![Step::Act(Action::TypeText { text: string(space, input, "text")?.to_owned(), interval_ms: None })])
        }
        "cursor_position" => Ok(vec![Step::CursorPosition]),
        "screenshot" => Ok(vec![Step::Screenshot]),
        "mouse_move" => {
            let (x, y) = required("coordinate")?;
            Ok(vec![Step::Act(Action::MoveTo { x, y })])
        }
        "left_mouse_down" | "left_mouse_up" => {
            let at = coordinate("coordinate")?;
            let (x, y) = (at.map(|p| p.0), at.map(|p| p.1));
            let a = if action == "left_mouse_down" {
                Action::MouseDown { button: MouseButton::Left, x, y }
            } else {
                Action::MouseUp { button: MouseButton::Left, x, y }
            };
            Ok(vec![Step::Act(a)])
        }
        "left_click" => click(MouseButton::Left, 1),
        "right_click" => click(MouseButton::Right, 1),
        "middle_click" => click(MouseButton::Middle, 1),
        "double_click" => click(MouseButton::Left, 2),
        "triple_click" => click(MouseButton::Left, 3),
        "left_click_drag" => {
            let (fx, fy) = required("start_coordinate")?;
            let (tx, ty) = required("coordinate")?;
            Ok(held(
                modifiers()?,
                vec![Action::Drag {
                    from: Some(Point { x: fx, y: fy }),
                    to: Point { x: tx, y: ty },
                    button: MouseButton::Left,
                    duration_ms: None,
                }],
            ))
        }
        "scroll" => {
            let at = coordinate("coordinate")?;
            let direction = string(space, input, "scroll_direction")?;
            let amount = opt_number(space, input, "scroll_amount")?.unwrap_or(1.0);
            if !(0.0..=1000.0).contains(&amount) {
                return Err(ActionError::new(space, format!("`scroll_amount` must be 0 to 1000, got {amount}")));
            }
            let notches = (amount.round() as i32) * 120;
            let (dx, dy) = match direction {
                "up" => (0, notches),
                "down" => (0, -notches),
                "left" => (-notches, 0),
                "right" => (notches, 0),
                other => {
                    return Err(ActionError::new(
                        space,
                        format!("unknown scroll_direction {other:?} (expected up, down, left or right)"),
                    ))
                }
            };
            Ok(held(modifiers()?, vec![Action::Scroll { x: at.map(|p| p.0), y: at.map(|p| p.1), dx, dy }]))
        }
        "wait" => {
            let ms = millis(space, "duration", opt_number(space, input, "duration")?.unwrap_or(1.0))?;
            Ok(vec![Step::Act(Action::Wait { ms })])
        }
        "zoom" if space != ActionSpace::Anthropic20250124 => {
            let region = match input.get("region") {
                Some(Value::Array(r)) if r.len() == 4 && r.iter().all(Value::is_number) => {
                    let n: Vec<f64> = r.iter().map(|v| v.as_f64().unwrap_or_default()).collect();
                    let (x1, y1) = ctx.point(n[0], n[1]);
                    let (x2, y2) = ctx.point(n[2], n[3]);
                    if x2 <= x1 || y2 <= y1 {
                        return Err(ActionError::new(
                            space,
                            format!("`region` must have x2 > x1 and y2 > y1, got {n:?}"),
                        ));
                    }
                    [x1, y1, x2, y2]
                }
                other => {
                    return Err(ActionError::new(space, format!("zoom needs `region` [x1, y1, x2, y2], got {other:?}")))
                }
            };
            Ok(vec![Step::Zoom(region)])
        }
        other => {
            let zoom = if space == ActionSpace::Anthropic20250124 { "" } else { ", zoom" };
            Err(ActionError::new(
                space,
                format!("unknown action {other:?} (expected one of {}{zoom})", ACTIONS_20250124.join(", ")),
            ))
        }
    }
}
