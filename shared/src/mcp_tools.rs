//! The MCP desktop tools both MCP servers offer (the host's `arena run --agent
//! mcp` endpoint and the guest's `arena-guest --mcp`): their names, argument
//! names and input schemas, and each call's arguments checked and turned into
//! what is done. The names and argument names are part of the interface
//! (docs/agents.md): any client may rely on them. No MCP transport here: the
//! servers speak it with the `rmcp` SDK.

use serde_json::{json, Map, Value};

use crate::action::{Action, MouseButton};
use crate::geometry::Point;

/// What a tool call asks for.
#[derive(Debug, Clone, PartialEq)]
pub enum ToolCall {
    /// The episode's task, waiting for one when none is ready.
    GetTask,
    /// The step's screenshot.
    Screenshot,
    /// The step's accessibility tree as upstream's XML (`uia`) or the Win32 backend's.
    AccessibilityTree { win32: bool },
    /// The visible windows' titles and the foreground one.
    ListWindows,
    /// One input action.
    Input(Action),
    /// WAA `computer` code or pyautogui code, for the script interpreter.
    RunPython(String),
    /// The agent says the task is done.
    Done,
    /// The agent says the task cannot be done.
    Fail,
}

/// Longest `wait` one call may ask for.
pub const MAX_WAIT_SECONDS: f64 = 60.0;

fn point(x: &str, y: &str, what: &str) -> Value {
    json!({
        x: {"type": "integer", "description": format!("{what}: pixels from the screen's left edge")},
        y: {"type": "integer", "description": format!("{what}: pixels from the screen's top edge")},
    })
}

fn object(properties: Value, required: &[&str]) -> Value {
    json!({"type": "object", "properties": properties, "required": required, "additionalProperties": false})
}

fn merge(a: Value, b: Value) -> Value {
    let (Value::Object(mut a), Value::Object(b)) = (a, b) else { return Value::Null };
    a.extend(b);
    Value::Object(a)
}

/// Every tool: name, description, input schema. `with_task` adds the task and
/// decision tools of a benchmark episode (`get_task`, `done`, `fail`).
pub fn tool_list(with_task: bool) -> Vec<(&'static str, &'static str, Value)> {
    let none = object(json!({}), &[]);
    let mut tools = Vec::new();
    if with_task {
        tools.push((
            "get_task",
            "The task of this session's episode as JSON text (instruction, task_id, domain, screen_width, \
             screen_height, steps_left); waits while no task is ready; {\"task_id\": null} when the run has none left.",
            none.clone(),
        ));
    }
    tools.extend([
        ("screenshot", "The screen as a PNG image.", none.clone()),
        (
            "accessibility_tree",
            "The accessibility tree as upstream WindowsAgentArena's XML.",
            object(json!({"backend": {"type": "string", "enum": ["uia", "win32"], "default": "uia"}}), &[]),
        ),
        ("list_windows", "The visible windows' titles, and the foreground window's, as JSON text.", none.clone()),
        (
            "click",
            "Clicks at a point of the screen (guest pixels).",
            object(
                merge(
                    point("x", "y", "where"),
                    json!({
                        "button": {"type": "string", "enum": ["left", "right", "middle"], "default": "left"},
                        "clicks": {"type": "integer", "minimum": 1, "maximum": 3, "default": 1},
                    }),
                ),
                &["x", "y"],
            ),
        ),
        ("double_click", "Double-clicks with the left button.", object(point("x", "y", "where"), &["x", "y"])),
        ("move", "Moves the pointer.", object(point("x", "y", "where"), &["x", "y"])),
        (
            "drag",
            "Drags with the left button from one point to another.",
            object(
                merge(
                    merge(point("from_x", "from_y", "start"), point("to_x", "to_y", "end")),
                    json!({"duration": {"type": "number", "minimum": 0, "description": "seconds the move takes"}}),
                ),
                &["from_x", "from_y", "to_x", "to_y"],
            ),
        ),
        (
            "scroll",
            "Turns the wheel at a point: dx, dy in pyautogui's amounts (raw wheel units, 120 a notch; positive dy up, positive dx right).",
            object(
                merge(point("x", "y", "where"), json!({"dx": {"type": "integer"}, "dy": {"type": "integer"}})),
                &["x", "y", "dx", "dy"],
            ),
        ),
        ("type_text", "Types text as Unicode.", object(json!({"text": {"type": "string"}}), &["text"])),
        (
            "press_keys",
            "Presses keys as one chord (pyautogui's key names), e.g. [\"ctrl\", \"s\"].",
            object(json!({"keys": {"type": "array", "items": {"type": "string"}, "minItems": 1}}), &["keys"]),
        ),
        (
            "run_python",
            "Runs WindowsAgentArena `computer` code or pyautogui code with the interpreter the harness runs Navi's code in.",
            object(json!({"code": {"type": "string"}}), &["code"]),
        ),
        (
            "wait",
            "Waits a number of seconds (60 at most).",
            object(json!({"seconds": {"type": "number", "minimum": 0, "maximum": MAX_WAIT_SECONDS}}), &["seconds"]),
        ),
    ]);
    if with_task {
        tools.push(("done", "Says the task is done: the episode ends and is evaluated.", none.clone()));
        tools.push(("fail", "Says the task cannot be done: the episode ends and is evaluated.", none));
    }
    tools
}

/// Reads a call's arguments.
struct Args<'a> {
    tool: &'a str,
    map: Map<String, Value>,
}

impl Args<'_> {
    fn bad(&self, why: impl std::fmt::Display) -> String {
        format!("{}: {why}", self.tool)
    }

    fn take(&mut self, name: &str) -> Option<Value> {
        self.map.remove(name).filter(|v| !v.is_null())
    }

    fn int(&mut self, name: &str) -> Result<i32, String> {
        match self.take(name) {
            None => Err(self.bad(format!("missing argument {name:?}"))),
            Some(v) => self.as_int(name, &v),
        }
    }

    fn as_int(&self, name: &str, v: &Value) -> Result<i32, String> {
        let n = v.as_i64().or_else(|| v.as_f64().filter(|f| f.fract() == 0.0).map(|f| f as i64));
        n.and_then(|n| i32::try_from(n).ok()).ok_or_else(|| self.bad(format!("{name} must be an integer, not {v}")))
    }

    fn number(&mut self, name: &str) -> Result<Option<f64>, String> {
        match self.take(name) {
            None => Ok(None),
            Some(v) => match v.as_f64() {
                Some(f) if f.is_finite() && f >= 0.0 => Ok(Some(f)),
                _ => Err(self.bad(format!("{name} must be a number of seconds, 0 or more, not {v}"))),
            },
        }
    }

    fn string(&mut self, name: &str) -> Result<String, String> {
        match self.take(name) {
            Some(Value::String(s)) => Ok(s),
            None => Err(self.bad(format!("missing argument {name:?}"))),
            Some(v) => Err(self.bad(format!("{name} must be a string, not {v}"))),
        }
    }

    /// No argument left over: an unknown name is an error, not ignored.
    fn finish(self) -> Result<(), String> {
        match self.map.keys().next() {
            None => Ok(()),
            Some(name) => Err(self.bad(format!("unknown argument {name:?}"))),
        }
    }
}

/// A point checked against the screen, when its size is known.
fn on_screen(args: &Args<'_>, x: i32, y: i32, screen: Option<(u32, u32)>) -> Result<(), String> {
    if let Some((w, h)) = screen {
        let inside = |v: i32, max: u32| v >= 0 && u32::try_from(v).is_ok_and(|v| v < max);
        if !inside(x, w) || !inside(y, h) {
            return Err(args.bad(format!("({x}, {y}) is off the {w}x{h} screen")));
        }
    }
    Ok(())
}

/// Checks a call of `tool` with `arguments` against its schema and the
/// screen's size (`screen`, when known), and answers what it asks for.
///
/// # Errors
///
/// An unknown tool (or a task tool outside a benchmark), a missing, unknown or
/// mistyped argument, a point off the screen, an unknown key: each named.
pub fn parse(
    tool: &str,
    arguments: Option<Map<String, Value>>,
    screen: Option<(u32, u32)>,
    with_task: bool,
) -> Result<ToolCall, String> {
    let mut args = Args { tool, map: arguments.unwrap_or_default() };
    let typed = ToolCall::Input;
    let call = match tool {
        "get_task" if with_task => ToolCall::GetTask,
        "done" if with_task => ToolCall::Done,
        "fail" if with_task => ToolCall::Fail,
        "screenshot" => ToolCall::Screenshot,
        "list_windows" => ToolCall::ListWindows,
        "accessibility_tree" => match args.take("backend") {
            None => ToolCall::AccessibilityTree { win32: false },
            Some(Value::String(b)) if b == "uia" => ToolCall::AccessibilityTree { win32: false },
            Some(Value::String(b)) if b == "win32" => ToolCall::AccessibilityTree { win32: true },
            Some(v) => return Err(args.bad(format!("backend must be \"uia\" or \"win32\", not {v}"))),
        },
        "click" => {
            let (x, y) = (args.int("x")?, args.int("y")?);
            on_screen(&args, x, y, screen)?;
            let button = match args.take("button") {
                None => MouseButton::Left,
                Some(Value::String(b)) if ["left", "right", "middle"].contains(&b.as_str()) => {
                    MouseButton::from_name(&b).unwrap_or_default()
                }
                Some(v) => return Err(args.bad(format!("button must be left, right or middle, not {v}"))),
            };
            let count = match args.take("clicks") {
                None => 1,
                Some(v) => match args.as_int("clicks", &v)? {
                    n @ 1..=3 => n.unsigned_abs(),
                    n => return Err(args.bad(format!("clicks must be 1, 2 or 3, not {n}"))),
                },
            };
            typed(Action::Click { x: Some(x), y: Some(y), button, count })
        }
        "double_click" => {
            let (x, y) = (args.int("x")?, args.int("y")?);
            on_screen(&args, x, y, screen)?;
            typed(Action::DoubleClick { x: Some(x), y: Some(y) })
        }
        "move" => {
            let (x, y) = (args.int("x")?, args.int("y")?);
            on_screen(&args, x, y, screen)?;
            typed(Action::MoveTo { x, y })
        }
        "drag" => {
            let (fx, fy, tx, ty) = (args.int("from_x")?, args.int("from_y")?, args.int("to_x")?, args.int("to_y")?);
            on_screen(&args, fx, fy, screen)?;
            on_screen(&args, tx, ty, screen)?;
            let duration_ms = args.number("duration")?.map(|s| (s * 1000.0).round() as u64);
            typed(Action::Drag {
                from: Some(Point { x: fx, y: fy }),
                to: Point { x: tx, y: ty },
                button: MouseButton::Left,
                duration_ms,
            })
        }
        "scroll" => {
            let (x, y, dx, dy) = (args.int("x")?, args.int("y")?, args.int("dx")?, args.int("dy")?);
            on_screen(&args, x, y, screen)?;
            typed(Action::Scroll { x: Some(x), y: Some(y), dx, dy })
        }
        "type_text" => typed(Action::TypeText { text: args.string("text")?, interval_ms: None }),
        "press_keys" => {
            let keys = match args.take("keys") {
                Some(Value::Array(items)) if !items.is_empty() => items
                    .iter()
                    .map(|k| {
                        k.as_str().map(str::to_owned).ok_or_else(|| args.bad(format!("keys must be strings, not {k}")))
                    })
                    .collect::<Result<Vec<String>, String>>()?,
                None => return Err(args.bad("missing argument \"keys\"")),
                Some(v) => return Err(args.bad(format!("keys must be a list of key names, not {v}"))),
            };
            for key in &keys {
                crate::keys::Key::parse(key).map_err(|err| args.bad(err))?;
            }
            typed(Action::Hotkey { keys })
        }
        "run_python" => ToolCall::RunPython(args.string("code")?),
        "wait" => {
            let seconds = args.number("seconds")?.ok_or_else(|| args.bad("missing argument \"seconds\""))?;
            if seconds > MAX_WAIT_SECONDS {
                return Err(args.bad(format!("seconds must be {MAX_WAIT_SECONDS} or less, not {seconds}")));
            }
            typed(Action::Wait { ms: (seconds * 1000.0).round() as u64 })
        }
        other => return Err(format!("unknown tool {other:?}")),
    };
    args.finish()?;
    Ok(call)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn call(tool: &str, args: Value) -> Result<ToolCall, String> {
        let Value::Object(map) = args else { panic!("arguments are an object") };
        parse(tool, Some(map), Some((1280, 800)), true)
    }

    #[test]
    fn the_tools_have_the_documented_names() {
        let names: Vec<&str> = tool_list(true).iter().map(|t| t.0).collect();
        assert_eq!(
            names,
            [
                "get_task",
                "screenshot",
                "accessibility_tree",
                "list_windows",
                "click",
                "double_click",
                "move",
                "drag",
                "scroll",
                "type_text",
                "press_keys",
                "run_python",
                "wait",
                "done",
                "fail"
            ]
        );
        let desktop: Vec<&str> = tool_list(false).iter().map(|t| t.0).collect();
        assert!(!desktop.contains(&"get_task") && !desktop.contains(&"done") && desktop.len() == 12);
    }

    #[test]
    fn calls_become_actions() {
        assert_eq!(
            call("click", json!({"x": 10, "y": 20, "button": "right", "clicks": 2})),
            Ok(ToolCall::Input(Action::Click { x: Some(10), y: Some(20), button: MouseButton::Right, count: 2 }))
        );
        assert_eq!(
            call("press_keys", json!({"keys": ["ctrl", "s"]})),
            Ok(ToolCall::Input(Action::Hotkey { keys: vec!["ctrl".into(), "s".into()] }))
        );
        assert_eq!(
            call("run_python", json!({"code": "computer.keyboard.write('x')"})),
            Ok(ToolCall::RunPython("computer.keyboard.write('x')".into()))
        );
        assert_eq!(call("done", json!({})), Ok(ToolCall::Done));
    }

    #[test]
    fn bad_arguments_are_named() {
        let err = |tool: &str, args: Value| call(tool, args).expect_err("refused");
        assert_eq!(err("click", json!({"x": 1})), "click: missing argument \"y\"");
        assert_eq!(err("click", json!({"x": "a", "y": 1})), "click: x must be an integer, not \"a\"");
        assert_eq!(err("click", json!({"x": 5000, "y": 1})), "click: (5000, 1) is off the 1280x800 screen");
        assert_eq!(err("move", json!({"x": 1, "y": 1, "z": 2})), "move: unknown argument \"z\"");
        assert!(err("press_keys", json!({"keys": ["ctrl", "nosuchkey"]})).contains("unknown key name \"nosuchkey\""));
        assert_eq!(err("teleport", json!({})), "unknown tool \"teleport\"");
        assert_eq!(parse("get_task", None, None, false), Err("unknown tool \"get_task\"".to_owned()));
    }
}
