//! UI-TARS's reply grammar and coordinate conventions.
//!
//! A reply is `Thought: ...` (or `Reflection: ... Action_Summary: ...`) and then
//! `Action: ` with one call, or several separated by blank lines, in the form the
//! UI-TARS project publishes (`codes/ui_tars/prompt.py`, `action_parser.py` in
//! bytedance/UI-TARS):
//!
//! | call | becomes |
//! |---|---|
//! | `click(start_box=...)`, `left_single(...)` | a left click at the box's centre |
//! | `left_double(start_box=...)` | a double click |
//! | `right_single(start_box=...)` | a right-button click |
//! | `hover(start_box=...)` | a move |
//! | `drag(start_box=..., end_box=...)`, `select(...)` | a move to the start, then a 1 s left drag to the end (the published parser's `moveTo` and `dragTo(..., duration=1.0)`) |
//! | `hotkey(key='ctrl c')` | the space-separated keys as one `hotkey` (one key too) |
//! | `press(key=...)`, `keydown(key=...)`, `keyup(key=...)`, `release(key=...)` | a press, a key down, a key up |
//! | `type(content='...')` | the text put on the clipboard and pasted with ctrl+v, a 0.5 s pause, and Enter when the content ends with a newline (the published parser's default, `input_swap=True`) |
//! | `scroll(start_box=..., direction='up'/'down'/'left'/'right')` | 5 wheel units at the point (the published parser's `scroll(±5)`); `left`/`right` scroll horizontally |
//! | `wait()` | the decision `WAIT` |
//! | `finished(...)` | `DONE` |
//! | `call_user()` | `FAIL` (nobody answers during a benchmark, as OSWorld's UI-TARS agent decides) |
//!
//! Several calls in one reply are separated by a 1 s pause, as the published
//! parser's `time.sleep(1)` between them.
//!
//! Positions may be written `'(x,y)'`, `'(x1,y1,x2,y2)'` (a box: its centre),
//! with `<|box_start|>`/`<|box_end|>` tokens, as `<point>x y</point>` or
//! `<bbox>x1 y1 x2 y2</bbox>`, under the names `start_box`, `end_box`, `point`,
//! `start_point`, `end_point`.
//!
//! Coordinates ([`UiTarsVersion`]): UI-TARS 1.0 (the Qwen2-VL models) answers on a
//! 0..1000 grid of the screenshot (the published parser's `factor=1000`);
//! UI-TARS-1.5 (Qwen2.5-VL) answers in pixels of the screenshot after
//! Qwen2.5-VL's `smart_resize` (factor 28, at least 100·28² and at most 16384·28²
//! pixels), per the project's `README_coordinates.md` and `action_parser.py`.
//! A position becomes screen pixels as the published parser's code does it: each
//! number a fraction of the image (or grid), a box's centre the mean of its
//! fractions, times the screen's size, rounded to 3 decimals (its `round(..., 3)`),
//! then truncated as pyautogui's `int()` does.
//!
//! `tests/tests/uitars_parity.rs` runs the `ui-tars` PyPI package and this parser
//! on a corpus of replies; where they differ on purpose, `docs/compatibility.md`
//! says how and which way it moves scores.

use arena_shared::action::{Action, MouseButton};
use arena_shared::geometry::Point;

use super::{key_name, ActionError, ActionSpace, Context, Coords, Step};

const SPACE: ActionSpace = ActionSpace::UiTars;

/// UI-TARS's key names (lowercased) to pyautogui names, as the published parser
/// renames them; others are pyautogui's own.
pub const KEYS: super::KeyTable = &[
    ("arrowleft", "left"),
    ("arrowright", "right"),
    ("arrowup", "up"),
    ("arrowdown", "down"),
    ("cmd", "win"),
    ("command", "win"),
    ("meta", "win"),
    ("super", "win"),
    ("control", "ctrl"),
    ("escape", "esc"),
    ("return", "enter"),
    ("pgup", "pageup"),
    ("pgdn", "pagedown"),
];

/// The published parser's wheel amount per `scroll`.
pub const SCROLL_UNITS: i32 = 5;

/// The published parser's pause between the calls of one reply (`time.sleep(1)`).
pub const BETWEEN_CALLS_MS: u64 = 1000;

/// Which UI-TARS, by its coordinate convention.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum UiTarsVersion {
    /// UI-TARS 2B/7B/72B (Qwen2-VL): a 0..1000 grid.
    V1,
    /// UI-TARS-1.5 (Qwen2.5-VL): pixels of the `smart_resize`d screenshot.
    #[default]
    V1_5,
}

impl UiTarsVersion {
    pub fn name(self) -> &'static str {
        match self {
            UiTarsVersion::V1 => "1.0",
            UiTarsVersion::V1_5 => "1.5",
        }
    }

    /// The coordinate convention of this version for a screenshot of `screen` pixels.
    pub fn coords(self, screen: (u32, u32)) -> Coords {
        match self {
            UiTarsVersion::V1 => Coords::Grid1000,
            UiTarsVersion::V1_5 => {
                let (h, w) = smart_resize(screen.1, screen.0);
                Coords::Image { width: w, height: h }
            }
        }
    }
}

/// Qwen2.5-VL's `smart_resize` with UI-TARS's constants: both sides multiples of
/// 28, the pixel count within 100·28² and 16384·28², the aspect ratio kept as
/// closely as that allows. Takes and answers (height, width), as the original does.
pub fn smart_resize(height: u32, width: u32) -> (u32, u32) {
    const FACTOR: f64 = 28.0;
    const MIN_PIXELS: f64 = 100.0 * 28.0 * 28.0;
    const MAX_PIXELS: f64 = 16384.0 * 28.0 * 28.0;
    let (h, w) = (f64::from(height.max(1)), f64::from(width.max(1)));
    // Python's round() rounds halves to even.
    let round_by = |v: f64| FACTOR * (v / FACTOR).round_ties_even();
    let mut h_bar = FACTOR.max(round_by(h));
    let mut w_bar = FACTOR.max(round_by(w));
    if h_bar * w_bar > MAX_PIXELS {
        let beta = (h * w / MAX_PIXELS).sqrt();
        h_bar = FACTOR * (h / beta / FACTOR).floor();
        w_bar = FACTOR * (w / beta / FACTOR).floor();
    } else if h_bar * w_bar < MIN_PIXELS {
        let beta = (MIN_PIXELS / (h * w)).sqrt();
        h_bar = FACTOR * (h * beta / FACTOR).ceil();
        w_bar = FACTOR * (w * beta / FACTOR).ceil();
    }
    (h_bar as u32, w_bar as u32)
}

/// A parsed reply.
#[derive(Debug, Clone, PartialEq)]
pub struct Reply {
    /// The `Thought:` (or `Action_Summary:`) text, which the agent's history keeps.
    pub thought: Option<String>,
    /// The text of the calls after `Action:`.
    pub action_text: String,
    pub steps: Vec<Step>,
}

/// One call: its name and keyword arguments.
#[derive(Debug, Clone, PartialEq)]
struct Call {
    name: String,
    args: Vec<(String, String)>,
}

/// Parses a reply.
///
/// # Errors
///
/// [`ActionError`] when there is no `Action:`, a call does not parse, a call or
/// key is unknown, or a position is missing or malformed.
pub fn parse(text: &str, ctx: &Context) -> Result<Reply, ActionError> {
    let text = text.trim();
    let Some(at) = text.rfind("Action:") else {
        return Err(ActionError::new(SPACE, "the reply has no `Action:` line"));
    };
    let thought = ["Thought:", "Action_Summary:"].iter().find_map(|label| {
        let start = text.find(label)? + label.len();
        let end = text[start..].find("Action:").map_or(text.len(), |e| start + e);
        Some(text[start..end].trim().to_owned()).filter(|t| !t.is_empty())
    });
    let action_text = text[at + "Action:".len()..].trim().to_owned();
    let calls = calls(&action_text)?;
    if calls.is_empty() {
        return Err(ActionError::new(SPACE, "`Action:` is followed by no call"));
    }
    let mut steps = Vec::new();
    for (i, call) in calls.iter().enumerate() {
        if i > 0 {
            steps.push(Step::Act(Action::Wait { ms: BETWEEN_CALLS_MS }));
        }
        steps.extend(call_steps(call, ctx)?);
    }
    Ok(Reply { thought, action_text, steps })
}

/// The calls of an `Action:` text, in order.
fn calls(text: &str) -> Result<Vec<Call>, ActionError> {
    let chars: Vec<char> = text.chars().collect();
    let mut i = 0;
    let mut out = Vec::new();
    loop {
        while i < chars.len() && chars[i].is_whitespace() {
            i += 1;
        }
        if i >= chars.len() {
            return Ok(out);
        }
        let start = i;
        while i < chars.len() && (chars[i].is_alphanumeric() || chars[i] == '_') {
            i += 1;
        }
        let name: String = chars[start..i].iter().collect();
        if name.is_empty() || chars.get(i) != Some(&'(') {
            let rest: String = chars[start..].iter().take(60).collect();
            return Err(ActionError::new(SPACE, format!("expected a call such as click(...), got {rest:?}")));
        }
        i += 1;
        let mut args = Vec::new();
        loop {
            while i < chars.len() && (chars[i].is_whitespace() || chars[i] == ',') {
                i += 1;
            }
            match chars.get(i) {
                // A reply cut short before its `)` counts as closed, as the published parser appends one.
                None => break,
                Some(')') => {
                    i += 1;
                    break;
                }
                Some(_) => {}
            }
            let key_start = i;
            while i < chars.len() && (chars[i].is_alphanumeric() || chars[i] == '_') {
                i += 1;
            }
            let key: String = chars[key_start..i].iter().collect();
            while i < chars.len() && chars[i].is_whitespace() {
                i += 1;
            }
            if key.is_empty() || chars.get(i) != Some(&'=') {
                return Err(ActionError::new(SPACE, format!("{name}(...): expected `name='value'` arguments")));
            }
            i += 1;
            while i < chars.len() && chars[i].is_whitespace() {
                i += 1;
            }
            let value = match chars.get(i) {
                Some(&q @ ('\'' | '"')) => {
                    i += 1;
                    let mut v = String::new();
                    while i < chars.len() && chars[i] != q {
                        if chars[i] == '\\' && i + 1 < chars.len() {
                            i += 1;
                            v.push(match chars[i] {
                                'n' => '\n',
                                't' => '\t',
                                'r' => '\r',
                                other => other,
                            });
                        } else {
                            v.push(chars[i]);
                        }
                        i += 1;
                    }
                    i += 1;
                    v
                }
                _ => {
                    let vs = i;
                    while i < chars.len() && chars[i] != ',' && chars[i] != ')' {
                        i += 1;
                    }
                    chars[vs..i].iter().collect::<String>().trim().to_owned()
                }
            };
            args.push((key, value));
        }
        out.push(Call { name, args });
    }
}

impl Call {
    fn arg(&self, names: &[&str]) -> Option<&str> {
        self.args.iter().find(|(k, _)| names.contains(&k.as_str())).map(|(_, v)| v.as_str())
    }

    /// The centre of a position argument, in screen pixels.
    fn point(&self, names: &[&str], ctx: &Context) -> Result<(i32, i32), ActionError> {
        let raw = self
            .arg(names)
            .ok_or_else(|| ActionError::new(SPACE, format!("{}(...) needs `{}`", self.name, names[0])))?;
        let cleaned = ["<|box_start|>", "<|box_end|>", "<point>", "</point>", "<bbox>", "</bbox>"]
            .iter()
            .fold(raw.to_owned(), |s, token| s.replace(token, " "));
        let numbers: Vec<f64> = cleaned
            .split(|c: char| c == ',' || c == '(' || c == ')' || c == '[' || c == ']' || c.is_whitespace())
            .filter(|s| !s.is_empty())
            .map(str::parse::<f64>)
            .collect::<Result<_, _>>()
            .map_err(|_| ActionError::new(SPACE, format!("{}: cannot read the position {raw:?}", self.name)))?;
        // Each number as a fraction of the screen, as the published parser divides them.
        let (fx, fy) = (fraction(ctx, 0), fraction(ctx, 1));
        let (x, y) = match numbers.as_slice() {
            [x, y] => (fx(*x), fy(*y)),
            [x1, y1, x2, y2] => ((fx(*x1) + fx(*x2)) / 2.0, (fy(*y1) + fy(*y2)) / 2.0),
            _ => {
                return Err(ActionError::new(
                    SPACE,
                    format!("{}: a position is (x,y) or (x1,y1,x2,y2), got {raw:?}", self.name),
                ))
            }
        };
        Ok((screen_pixel(x, ctx.screen.0), screen_pixel(y, ctx.screen.1)))
    }

    fn key(&self) -> Result<&str, ActionError> {
        self.arg(&["key", "hotkey", "press"])
            .filter(|k| !k.trim().is_empty())
            .ok_or_else(|| ActionError::new(SPACE, format!("{}(...) needs `key`", self.name)))
    }
}

/// A number of the reply on `axis` (0 for x, 1 for y) as a fraction of the screen.
fn fraction(ctx: &Context, axis: usize) -> impl Fn(f64) -> f64 {
    let screen = f64::from(if axis == 0 { ctx.screen.0 } else { ctx.screen.1 });
    let unit = match ctx.coords {
        Coords::Pixels => screen,
        Coords::Fraction => 1.0,
        Coords::Grid1000 => 1000.0,
        Coords::Image { width, height } => f64::from(if axis == 0 { width } else { height }.max(1)),
    };
    move |v| v / unit
}

/// A fraction of a screen side in pixels: `round(f * side, 3)`, then `int()`.
fn screen_pixel(fraction: f64, side: u32) -> i32 {
    let v = ((fraction * f64::from(side)) * 1000.0).round_ties_even() / 1000.0;
    // Saturating: absurd numbers land off screen, where the guest refuses them.
    v.trunc() as i32
}

const START: &[&str] = &["start_box", "point", "start_point"];
const END: &[&str] = &["end_box", "end_point"];

fn call_steps(call: &Call, ctx: &Context) -> Result<Vec<Step>, ActionError> {
    let act = |a: Action| Ok(vec![Step::Act(a)]);
    match call.name.as_str() {
        "click" | "left_single" => {
            let (x, y) = call.point(START, ctx)?;
            act(Action::Click { x: Some(x), y: Some(y), button: MouseButton::Left, count: 1 })
        }
        "left_double" => {
            let (x, y) = call.point(START, ctx)?;
            act(Action::DoubleClick { x: Some(x), y: Some(y) })
        }
        "right_single" => {
            let (x, y) = call.point(START, ctx)?;
            act(Action::Click { x: Some(x), y: Some(y), button: MouseButton::Right, count: 1 })
        }
        "hover" => {
            let (x, y) = call.point(START, ctx)?;
            act(Action::MoveTo { x, y })
        }
        "drag" | "select" => {
            let (fx, fy) = call.point(START, ctx)?;
            let (tx, ty) = call.point(END, ctx)?;
            Ok(vec![
                Step::Act(Action::MoveTo { x: fx, y: fy }),
                Step::Act(Action::Drag {
                    from: None,
                    to: Point { x: tx, y: ty },
                    button: MouseButton::Left,
                    duration_ms: Some(1000),
                }),
            ])
        }
        "hotkey" => {
            let keys =
                call.key()?.split_whitespace().map(|k| key_name(SPACE, KEYS, k)).collect::<Result<Vec<_>, _>>()?;
            act(Action::Hotkey { keys })
        }
        "press" => act(Action::KeyPress { key: key_name(SPACE, KEYS, call.key()?.trim())?, presses: 1 }),
        "keydown" => act(Action::KeyDown { key: key_name(SPACE, KEYS, call.key()?.trim())? }),
        "keyup" | "release" => act(Action::KeyUp { key: key_name(SPACE, KEYS, call.key()?.trim())? }),
        "type" => {
            let content = call.arg(&["content"]).unwrap_or_default();
            let enter = content.ends_with('\n');
            let text = content.trim_end_matches('\n');
            let mut steps = Vec::new();
            if !text.is_empty() {
                steps.push(Step::SetClipboard(text.to_owned()));
                steps.push(Step::Act(Action::Hotkey { keys: vec!["ctrl".into(), "v".into()] }));
                steps.push(Step::Act(Action::Wait { ms: 500 }));
            }
            if enter {
                steps.push(Step::Act(Action::KeyPress { key: "enter".into(), presses: 1 }));
            }
            Ok(steps)
        }
        "scroll" => {
            let at = if call.arg(START).is_some() { Some(call.point(START, ctx)?) } else { None };
            let direction = call.arg(&["direction"]).unwrap_or_default().to_lowercase();
            let (dx, dy) = if direction.contains("up") {
                (0, SCROLL_UNITS)
            } else if direction.contains("down") {
                (0, -SCROLL_UNITS)
            } else if direction.contains("left") {
                (-SCROLL_UNITS, 0)
            } else if direction.contains("right") {
                (SCROLL_UNITS, 0)
            } else {
                return Err(ActionError::new(
                    SPACE,
                    format!("scroll: unknown direction {direction:?} (expected up, down, left or right)"),
                ));
            };
            act(Action::Scroll { x: at.map(|p| p.0), y: at.map(|p| p.1), dx, dy })
        }
        "wait" => Ok(vec![Step::Wait]),
        "finished" => Ok(vec![Step::Done]),
        "call_user" => Ok(vec![Step::Fail]),
        other => Err(ActionError::new(
            SPACE,
            format!(
                "unknown call {other:?} (expected click, left_single, left_double, right_single, hover, drag, select, \
                 hotkey, press, keydown, keyup, release, type, scroll, wait, finished or call_user)"
            ),
        )),
    }
}
