//! The trajectory viewer's parts of a step, read from the records: what the
//! model replied (its text and tool calls, for every agent family) and where
//! each pointer action landed on the step's screenshot.
//!
//! Replies: a step's `response` is the agent's text (Navi, UI-TARS, the
//! external step agents, the scripted plans), except for the agents that keep
//! their vendor's answer as a record beside the trajectory (the computer-use
//! agents, `response-step_<i>_<time>.json`, named in the line's `log_response`;
//! older folders have the name in `response` itself, where upstream's recorder
//! puts a log of that name). [`reply_of`] reads such a record and
//! takes the text, reasoning and tool calls out of it in whichever vendor shape
//! it has: Anthropic's Messages (`content` blocks), OpenAI's Responses
//! (`output` items), chat completions (`choices[0].message`), and the
//! `{"content": reply}` UI-TARS keeps. An MCP client's step is its tool call
//! (`tool`, `arguments`).
//!
//! Markers: typed actions carry physical screen pixels
//! (`arena_shared::action`), which is the screenshot's own pixel space (the
//! guest captures the physical screen; a computer-use agent scales its model's
//! coordinates back to the screen before it records them). pyautogui code is
//! translated again here by [`arena_actionspace`] in the coordinate convention
//! the run or the agent recorded (`coords`). Navi's `computer.*` code resolves
//! element ids against marks at run time, so its steps get the cursor the
//! executor reported after each action ([`MarkKind::CursorAfter`]).
//!
//! It does no rendering ([`super::html`] draws the marks over the image at view
//! time) and never changes a file.

use std::path::Path;

use serde_json::Value;

use arena_actionspace::{ActionSpace, Context, Coords, Step};
use arena_shared::action::{Action, MouseButton};

use super::StepRecord;
use arena_exec::AgentAction;

/// The largest response record read for the page (a vendor answer is a few kilobytes).
pub const MAX_RECORD_BYTES: u64 = 4 << 20;
/// The most characters of one text shown on the page; the rest is left to the record.
pub const MAX_TEXT_CHARS: usize = 64 * 1024;

/// What a model replied in one step.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Reply {
    /// The reply's texts, in order, each with its kind (`text`, `thinking`, `reasoning`, `refusal`).
    pub texts: Vec<(String, String)>,
    /// The tool calls, in order.
    pub tool_calls: Vec<ToolCall>,
    /// The record the reply was read from, a file of the task folder.
    pub record: Option<String>,
    /// Why the record could not be read, when it could not.
    pub problem: Option<String>,
}

/// One tool call of a reply.
#[derive(Debug, Clone, PartialEq)]
pub struct ToolCall {
    /// The tool (`computer`, a toolset member, a function's name).
    pub name: String,
    /// Its input, as pretty JSON.
    pub input: String,
}

/// `text` cut to [`MAX_TEXT_CHARS`] characters, with a note of what was left out.
pub fn bounded(text: &str) -> String {
    match text.char_indices().nth(MAX_TEXT_CHARS) {
        None => text.to_owned(),
        Some((end, _)) => {
            format!("{}\n… ({} more bytes in the record)", &text[..end], text.len() - end)
        }
    }
}

/// Whether `name` can be a log file the episode wrote beside the trajectory:
/// one plain file name (no folder, not hidden) of the kind upstream's recorder names.
fn is_record_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= 255
        && !name.starts_with('.')
        && name.ends_with(".json")
        && name.contains("-step_")
        && name.chars().all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.' | '@' | '+'))
}

/// The reply of `step`, whose `traj.jsonl` line is `line`, in the task folder `dir`.
pub fn reply_of(dir: &Path, step: &StepRecord, line: &Value) -> Reply {
    let mut reply = Reply::default();
    // The record's name: in `log_response` beside the model's text (older folders have
    // it in `response` itself, as upstream's recorder left it there).
    let logged = line.get(format!("{}response", super::LOG_PREFIX)).and_then(Value::as_str).map(str::trim);
    let response = logged.filter(|name| is_record_name(name)).unwrap_or_else(|| step.response.trim());
    if is_record_name(response) {
        reply.record = Some(response.to_owned());
        match read_record(&dir.join(response)) {
            Ok(value) => match vendor_reply(&value) {
                Some(found) => {
                    reply.texts = found.texts;
                    reply.tool_calls = found.tool_calls;
                }
                None => reply.texts.push(("record".into(), pretty(&value))),
            },
            Err(problem) => {
                // Not a record after all (or one that is gone): the text as it was recorded.
                reply.texts.push(("text".into(), step.response.clone()));
                reply.problem = Some(problem);
            }
        }
    } else if !response.is_empty() {
        reply.texts.push(("text".into(), step.response.clone()));
    }
    // An MCP client's step: the tool it called with its arguments.
    if let Some(tool) = line.get("tool").and_then(Value::as_str) {
        let arguments = line.get("arguments").cloned().unwrap_or(Value::Null);
        reply.tool_calls.push(ToolCall { name: tool.to_owned(), input: pretty(&arguments) });
    }
    reply
}

fn read_record(path: &Path) -> Result<Value, String> {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let meta = std::fs::metadata(path).map_err(|err| format!("{name}: {err}"))?;
    if meta.len() > MAX_RECORD_BYTES {
        return Err(format!("{name}: {} bytes, more than the {MAX_RECORD_BYTES} shown here", meta.len()));
    }
    let bytes = std::fs::read(path).map_err(|err| format!("{name}: {err}"))?;
    serde_json::from_slice(&bytes).map_err(|err| format!("{name}: not JSON: {err}"))
}

fn pretty(value: &Value) -> String {
    serde_json::to_string_pretty(value).unwrap_or_default()
}

fn text_of(value: Option<&Value>) -> Option<String> {
    value.and_then(Value::as_str).map(str::to_owned)
}

/// A tool call's arguments: a JSON string (chat completions, Responses' function
/// calls) shown as the JSON it holds, anything else as it is.
fn arguments(value: Option<&Value>) -> String {
    match value {
        Some(Value::String(s)) => serde_json::from_str::<Value>(s).map_or_else(|_| s.clone(), |v| pretty(&v)),
        Some(other) => pretty(other),
        None => "{}".into(),
    }
}

/// The text and tool calls of a vendor's answer, `None` when it has none of the known shapes.
pub fn vendor_reply(value: &Value) -> Option<Reply> {
    let mut reply = Reply::default();
    if let Some(content) = value.get("content") {
        match content {
            // UI-TARS's kept reply.
            Value::String(text) => reply.texts.push(("text".into(), text.clone())),
            // Anthropic's Messages: content blocks.
            Value::Array(blocks) => {
                for block in blocks {
                    match block.get("type").and_then(Value::as_str).unwrap_or_default() {
                        "text" => reply.texts.extend(text_of(block.get("text")).map(|t| ("text".into(), t))),
                        "thinking" => {
                            reply.texts.extend(text_of(block.get("thinking")).map(|t| ("thinking".into(), t)));
                        }
                        "redacted_thinking" => reply.texts.push(("thinking".into(), "(redacted)".into())),
                        "tool_use" | "server_tool_use" => reply.tool_calls.push(ToolCall {
                            name: text_of(block.get("name")).unwrap_or_default(),
                            input: arguments(block.get("input")),
                        }),
                        other => reply.texts.push((other.to_owned(), pretty(block))),
                    }
                }
            }
            _ => return None,
        }
        return Some(reply);
    }
    if let Some(items) = value.get("output").and_then(Value::as_array) {
        // OpenAI's Responses: output items.
        for item in items {
            match item.get("type").and_then(Value::as_str).unwrap_or_default() {
                "message" => {
                    for part in item.get("content").and_then(Value::as_array).into_iter().flatten() {
                        match part.get("type").and_then(Value::as_str).unwrap_or_default() {
                            "output_text" => {
                                reply.texts.extend(text_of(part.get("text")).map(|t| ("text".into(), t)));
                            }
                            "refusal" => {
                                reply.texts.extend(text_of(part.get("refusal")).map(|t| ("refusal".into(), t)));
                            }
                            other => reply.texts.push((other.to_owned(), pretty(part))),
                        }
                    }
                }
                "reasoning" => {
                    for part in item.get("summary").and_then(Value::as_array).into_iter().flatten() {
                        reply.texts.extend(text_of(part.get("text")).map(|t| ("reasoning".into(), t)));
                    }
                }
                "computer_call" => {
                    let mut input = serde_json::Map::new();
                    for key in ["action", "actions", "pending_safety_checks"] {
                        if let Some(v) = item.get(key).filter(|v| !v.is_null()) {
                            input.insert(key.to_owned(), v.clone());
                        }
                    }
                    reply.tool_calls.push(ToolCall { name: "computer".into(), input: pretty(&Value::Object(input)) });
                }
                "function_call" => reply.tool_calls.push(ToolCall {
                    name: text_of(item.get("name")).unwrap_or_default(),
                    input: arguments(item.get("arguments")),
                }),
                other => reply.texts.push((other.to_owned(), pretty(item))),
            }
        }
        return Some(reply);
    }
    if let Some(message) = value.pointer("/choices/0/message") {
        // Chat completions.
        if let Some(reasoning) = text_of(message.get("reasoning_content")).filter(|t| !t.is_empty()) {
            reply.texts.push(("reasoning".into(), reasoning));
        }
        match message.get("content") {
            Some(Value::String(text)) => reply.texts.push(("text".into(), text.clone())),
            Some(Value::Array(parts)) => {
                for part in parts {
                    reply.texts.extend(text_of(part.get("text")).map(|t| ("text".into(), t)));
                }
            }
            _ => {}
        }
        for call in message.get("tool_calls").and_then(Value::as_array).into_iter().flatten() {
            reply.tool_calls.push(ToolCall {
                name: text_of(call.pointer("/function/name")).unwrap_or_default(),
                input: arguments(call.pointer("/function/arguments")),
            });
        }
        return Some(reply);
    }
    None
}

/// What a marker stands for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MarkKind {
    Click,
    DoubleClick,
    RightClick,
    MiddleClick,
    /// A press and release at different points, or a drag action.
    Drag,
    Scroll,
    /// A button pressed (or released) without its other half at another point.
    Press,
    Move,
    /// Where the executor reported the cursor after an action it ran as code it
    /// does not show the points of (Navi's `computer.*`).
    CursorAfter,
}

impl MarkKind {
    /// The name on the page (`data-kind`, the legend).
    pub fn name(self) -> &'static str {
        match self {
            MarkKind::Click => "click",
            MarkKind::DoubleClick => "double-click",
            MarkKind::RightClick => "right-click",
            MarkKind::MiddleClick => "middle-click",
            MarkKind::Drag => "drag",
            MarkKind::Scroll => "scroll",
            MarkKind::Press => "press",
            MarkKind::Move => "move",
            MarkKind::CursorAfter => "cursor-after",
        }
    }
}

/// One marker, in screenshot pixels.
#[derive(Debug, Clone, PartialEq)]
pub struct Mark {
    pub kind: MarkKind,
    pub at: (i32, i32),
    /// Where a drag ended.
    pub to: Option<(i32, i32)>,
    /// A scroll's wheel deltas (120 a notch; positive `dy` scrolls up).
    pub scroll: (i32, i32),
    /// The 1-based action of the step the marker belongs to.
    pub action: usize,
}

impl Mark {
    /// The marker in words, for the legend.
    pub fn describe(&self) -> String {
        let (x, y) = self.at;
        match (self.kind, self.to) {
            (MarkKind::Drag, Some((x2, y2))) => format!("drag from ({x}, {y}) to ({x2}, {y2})"),
            (MarkKind::Scroll, _) => {
                let (dx, dy) = self.scroll;
                let mut parts = Vec::new();
                if dy != 0 {
                    parts.push(format!("{} {}", if dy > 0 { "up" } else { "down" }, dy.unsigned_abs()));
                }
                if dx != 0 {
                    parts.push(format!("{} {}", if dx > 0 { "right" } else { "left" }, dx.unsigned_abs()));
                }
                format!("scroll {} at ({x}, {y})", parts.join(", "))
            }
            (MarkKind::CursorAfter, _) => format!("cursor after the action at ({x}, {y})"),
            (kind, _) => format!("{} at ({x}, {y})", kind.name()),
        }
    }
}

/// The coordinate convention a run or an agent recorded (`pixels`, `fraction`,
/// `grid1000`, `image:<w>x<h>`), `None` for anything else.
pub fn coords_named(name: &str) -> Option<Coords> {
    if let Some(size) = name.strip_prefix("image:") {
        let (w, h) = size.split_once('x')?;
        return Some(Coords::Image { width: w.parse().ok()?, height: h.parse().ok()? });
    }
    name.parse().ok()
}

/// The markers of a step's actions on a screenshot of `screen` pixels, with the
/// cursor known before the step (the last one the executor reported), and the
/// cursor after it. `coords` is what the step's pyautogui code measures in.
pub fn marks_of(
    step: &StepRecord,
    screen: (u32, u32),
    coords: Coords,
    cursor: Option<(i32, i32)>,
) -> (Vec<Mark>, Option<(i32, i32)>) {
    let mut tracker = Tracker { cursor, pressed: None, marks: Vec::new() };
    let mut outcomes = step.outcomes.iter();
    for (k, action) in step.actions.iter().enumerate() {
        let n = k + 1;
        // Decisions have no outcome; every other action has one, in order.
        let outcome = if action.decision().is_some() { None } else { outcomes.next() };
        let reported = outcome
            .and_then(|o| o.get("cursor"))
            .and_then(|c| Some((c.get("x")?.as_i64()?, c.get("y")?.as_i64()?)))
            .and_then(|(x, y)| Some((i32::try_from(x).ok()?, i32::try_from(y).ok()?)));
        match action {
            AgentAction::Typed(actions) => actions.iter().for_each(|a| tracker.act(a, n)),
            AgentAction::Pyautogui(code) => {
                let ctx = Context { screen, cursor: tracker.cursor.unwrap_or((0, 0)), coords };
                if let Ok(steps) =
                    arena_actionspace::parse(ActionSpace::Pyautogui, &Value::String(code.to_string()), &ctx)
                {
                    for s in &steps {
                        if let Step::Act(a) = s {
                            tracker.act(a, n);
                        }
                    }
                }
            }
            AgentAction::Computer(_) => {
                if let Some(at) = reported {
                    tracker.marks.push(Mark { kind: MarkKind::CursorAfter, at, to: None, scroll: (0, 0), action: n });
                }
            }
            AgentAction::Clipboard(_) | AgentAction::Wait | AgentAction::Done | AgentAction::Fail => {}
        }
        if reported.is_some() {
            tracker.cursor = reported;
        }
    }
    (tracker.marks, tracker.cursor)
}

struct Tracker {
    cursor: Option<(i32, i32)>,
    /// A button held down: where, which, and the action it belongs to.
    pressed: Option<((i32, i32), MouseButton, usize)>,
    marks: Vec<Mark>,
}

impl Tracker {
    /// The point of an action: its own, else the cursor (unknown before the first report).
    fn point(&self, x: Option<i32>, y: Option<i32>) -> Option<(i32, i32)> {
        match (x, y) {
            (Some(x), Some(y)) => Some((x, y)),
            _ => self.cursor,
        }
    }

    fn mark(&mut self, kind: MarkKind, at: Option<(i32, i32)>, action: usize) {
        if let Some(at) = at {
            self.marks.push(Mark { kind, at, to: None, scroll: (0, 0), action });
            self.cursor = Some(at);
        }
    }

    fn act(&mut self, a: &Action, n: usize) {
        match a {
            Action::MoveTo { x, y } => self.mark(MarkKind::Move, Some((*x, *y)), n),
            Action::MoveRel { dx, dy } => {
                self.cursor = self.cursor.map(|(x, y)| (x.saturating_add(*dx), y.saturating_add(*dy)));
            }
            Action::Click { x, y, button, count } => {
                let kind = match (button, count) {
                    (MouseButton::Right, _) => MarkKind::RightClick,
                    (MouseButton::Middle, _) => MarkKind::MiddleClick,
                    (_, c) if *c >= 2 => MarkKind::DoubleClick,
                    _ => MarkKind::Click,
                };
                self.mark(kind, self.point(*x, *y), n);
            }
            Action::DoubleClick { x, y } => self.mark(MarkKind::DoubleClick, self.point(*x, *y), n),
            Action::RightClick { x, y } => self.mark(MarkKind::RightClick, self.point(*x, *y), n),
            Action::MouseDown { button, x, y } => {
                if let Some(at) = self.point(*x, *y) {
                    self.pressed = Some((at, *button, n));
                    self.cursor = Some(at);
                }
            }
            Action::MouseUp { x, y, .. } => {
                let up = self.point(*x, *y);
                match (self.pressed.take(), up) {
                    (Some((from, _, _)), Some(to)) if from != to => {
                        self.marks.push(Mark {
                            kind: MarkKind::Drag,
                            at: from,
                            to: Some(to),
                            scroll: (0, 0),
                            action: n,
                        });
                        self.cursor = Some(to);
                    }
                    (Some((from, button, _)), _) => {
                        let kind = match button {
                            MouseButton::Right => MarkKind::RightClick,
                            MouseButton::Middle => MarkKind::MiddleClick,
                            _ => MarkKind::Click,
                        };
                        self.mark(kind, Some(from), n);
                    }
                    (None, up) => self.mark(MarkKind::Press, up, n),
                }
            }
            Action::Drag { from, to, .. } => {
                let start = from.map(|p| (p.x, p.y)).or(self.cursor);
                let end = (to.x, to.y);
                match start {
                    Some(at) => {
                        self.marks.push(Mark { kind: MarkKind::Drag, at, to: Some(end), scroll: (0, 0), action: n });
                        self.cursor = Some(end);
                    }
                    None => self.mark(MarkKind::Drag, Some(end), n),
                }
            }
            Action::Scroll { x, y, dx, dy } => {
                if let Some(at) = self.point(*x, *y) {
                    self.marks.push(Mark { kind: MarkKind::Scroll, at, to: None, scroll: (*dx, *dy), action: n });
                    self.cursor = Some(at);
                }
            }
            _ => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use serde_json::json;

    use super::*;
    use arena_shared::geometry::Point;

    fn step_with(actions: Vec<AgentAction>, outcomes: Vec<Value>) -> StepRecord {
        let line = json!({
            "step_num": 1, "action_timestamp": "t", "action": "", "done": false,
            "step": 1, "response": "", "screenshot_file": "s.png", "actions": actions, "outcomes": outcomes,
        });
        serde_json::from_value(line).expect("a step record")
    }

    #[test]
    fn pyautogui_code_is_marked_in_the_recorded_convention_and_navi_code_by_the_reported_cursor() {
        let code = "pyautogui.click(0.5, 0.25)\npyautogui.scroll(-5)\npyautogui.dragTo(0.75, 0.5)";
        let step = step_with(
            vec![
                AgentAction::Pyautogui(code.into()),
                AgentAction::Computer("computer.mouse.move_id(3); computer.mouse.single_click()".into()),
                AgentAction::Done,
            ],
            vec![
                json!({"performed": 3, "elapsed_ms": 1}),
                json!({"cursor": {"x": 7, "y": 9}, "performed": 2, "elapsed_ms": 1}),
            ],
        );
        let (marks, after) = marks_of(&step, (200, 100), Coords::Fraction, None);
        type Seen = (MarkKind, (i32, i32), Option<(i32, i32)>, usize);
        let seen: Vec<Seen> = marks.iter().map(|m| (m.kind, m.at, m.to, m.action)).collect();
        assert_eq!(
            seen,
            [
                (MarkKind::Click, (100, 25), None, 1),
                (MarkKind::Scroll, (100, 25), None, 1),
                (MarkKind::Drag, (100, 25), Some((150, 50)), 1),
                (MarkKind::CursorAfter, (7, 9), None, 2),
            ],
            "{marks:?}"
        );
        assert_eq!(marks[1].scroll.1.signum(), -1, "scrolled down");
        assert_eq!(marks[1].describe(), format!("scroll down {} at (100, 25)", marks[1].scroll.1.unsigned_abs()));
        assert_eq!(after, Some((7, 9)));
    }

    #[test]
    fn a_press_and_release_apart_is_a_drag_and_clicks_without_a_point_land_at_the_cursor() {
        let typed = vec![
            Action::MouseDown { button: MouseButton::Left, x: Some(10), y: Some(10) },
            Action::MouseUp { button: MouseButton::Left, x: Some(40), y: Some(20) },
            Action::Click { x: None, y: None, button: MouseButton::Right, count: 1 },
            Action::MoveRel { dx: 5, dy: 5 },
            Action::Click { x: None, y: None, button: MouseButton::Left, count: 2 },
            Action::Drag { from: None, to: Point::new(1, 2), button: MouseButton::Left, duration_ms: None },
        ];
        let step = step_with(vec![AgentAction::Typed(typed)], vec![json!({"performed": 6, "elapsed_ms": 1})]);
        let (marks, after) = marks_of(&step, (100, 100), Coords::Pixels, None);
        let seen: Vec<String> = marks.iter().map(Mark::describe).collect();
        assert_eq!(
            seen,
            [
                "drag from (10, 10) to (40, 20)",
                "right-click at (40, 20)",
                "double-click at (45, 25)",
                "drag from (45, 25) to (1, 2)"
            ]
        );
        assert_eq!(after, Some((1, 2)));
        // Before any known cursor, a click without a point has no marker.
        let lone = step_with(
            vec![AgentAction::Typed(vec![Action::Click { x: None, y: None, button: MouseButton::Left, count: 1 }])],
            Vec::new(),
        );
        assert!(marks_of(&lone, (100, 100), Coords::Pixels, None).0.is_empty());
        assert_eq!(marks_of(&lone, (100, 100), Coords::Pixels, Some((3, 4))).0[0].at, (3, 4));
    }

    #[test]
    fn conventions_are_read_as_recorded() {
        assert_eq!(coords_named("pixels"), Some(Coords::Pixels));
        assert_eq!(coords_named("grid1000"), Some(Coords::Grid1000));
        assert_eq!(coords_named("image:1280x800"), Some(Coords::Image { width: 1280, height: 800 }));
        assert_eq!(coords_named("image:axb"), None);
        assert_eq!(coords_named("percent"), None);
        let long = "é".repeat(MAX_TEXT_CHARS + 3);
        assert!(bounded(&long).ends_with("(6 more bytes in the record)"));
        assert_eq!(bounded("short"), "short");
    }
}
