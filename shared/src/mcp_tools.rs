//! The MCP desktop tools both MCP servers offer (the host's `arena run --agent
//! mcp` endpoint and the guest's `arena-guest --mcp`): their names, argument
//! names and input schemas, and each call's arguments checked and turned into
//! what is done. The names and argument names are part of the interface
//! (docs/agents.md): any client may rely on them. No MCP transport here: the
//! servers speak it with the `rmcp` SDK.
//!
//! One table serves both servers: a benchmark episode's endpoint (`with_task`) adds
//! `get_task`, `done` and `fail`; the guest's own server adds the tools of
//! [`GUEST_ONLY`] (windows, programs, the clipboard, the shell, numbered elements),
//! which an episode does not offer (docs/agents.md, "What a benchmark episode offers").

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
    /// Starts a program by name (guest only, as every variant below).
    LaunchApp { name: String },
    /// Brings a window to the front, restoring it when minimised.
    SwitchWindow { title: String },
    /// Moves, resizes, maximises, minimises or restores a window.
    ResizeWindow(WindowChange),
    /// The clipboard's contents.
    ClipboardGet,
    /// Puts text on the clipboard.
    ClipboardSet(String),
    /// A command line for the guest's shell (PowerShell on Windows), run to its end or
    /// its timeout; refused unless the guest allows it (`--mcp-shell`).
    Shell { command: String, timeout_ms: u64 },
    /// The windows and the numbered interactive elements ([`crate::interactive`]).
    State,
    /// Clicks a numbered element of the latest state.
    ClickElement { element: u64, button: MouseButton, clicks: u32 },
    /// Clicks a numbered element, then types into it.
    TypeIntoElement { element: u64, text: String, clear: bool, press_enter: bool },
}

/// The tools only the guest's own MCP server (`arena-guest --mcp`) offers; a benchmark
/// episode's endpoint (host `--agent mcp`) offers the others. docs/agents.md says why.
pub const GUEST_ONLY: [&str; 9] = [
    "launch_app",
    "switch_window",
    "resize_window",
    "clipboard_get",
    "clipboard_set",
    "shell",
    "state",
    "click_element",
    "type_into_element",
];

/// A window's show state, as `resize_window` sets it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ShowState {
    /// Restored from minimised or maximised.
    Normal,
    Maximized,
    Minimized,
}

/// What `resize_window` asks of a window: the one titled `title` (else the foreground
/// one), moved to `x`, `y` and sized `width` by `height` where given, in `show` where given.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct WindowChange {
    pub title: Option<String>,
    pub x: Option<i32>,
    pub y: Option<i32>,
    pub width: Option<i32>,
    pub height: Option<i32>,
    pub show: Option<ShowState>,
}

impl WindowChange {
    /// Whether it moves or resizes (rather than only changing the show state).
    pub fn moves(&self) -> bool {
        self.x.is_some() || self.y.is_some() || self.width.is_some() || self.height.is_some()
    }
}

/// Longest `shell` timeout one call may ask for, and the default.
pub const MAX_SHELL_SECONDS: f64 = 600.0;
pub const DEFAULT_SHELL_SECONDS: f64 = 30.0;

/// Farthest a window's corner may be moved from the screen's origin, and its largest size.
pub const MAX_WINDOW_PIXELS: i32 = 16_384;

/// Longest program name (`launch_app`) or window title (`switch_window`,
/// `resize_window`) a call may give, in characters.
pub const MAX_NAME_CHARS: usize = 1024;

/// Longest `shell` command line, in UTF-16 code units: PowerShell gets it as
/// `-EncodedCommand` (base64 of UTF-16LE, 8/3 characters a unit), and the whole
/// Windows command line holds at most 32,767 characters.
pub const MAX_SHELL_COMMAND_UNITS: usize = 8192;

/// Most bytes of text `clipboard_set` puts on the clipboard (as much as one `type_text` types).
pub const MAX_CLIPBOARD_TEXT_BYTES: usize = crate::action::MAX_TYPE_TEXT_BYTES;

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
    if !with_task {
        tools.extend(guest_tools());
    }
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
        guest if !with_task && GUEST_ONLY.contains(&guest) => guest_call(&mut args)?,
        other => return Err(format!("unknown tool {other:?}")),
    };
    args.finish()?;
    Ok(call)
}

/// The tools of [`GUEST_ONLY`], in its order.
fn guest_tools() -> Vec<(&'static str, &'static str, Value)> {
    let none = object(json!({}), &[]);
    let string =
        |what: &str| json!({"type": "string", "minLength": 1, "maxLength": MAX_NAME_CHARS, "description": what});
    let click = json!({
        "button": {"type": "string", "enum": ["left", "right", "middle"], "default": "left"},
        "clicks": {"type": "integer", "minimum": 1, "maximum": 3, "default": 1},
    });
    let element =
        json!({"element": {"type": "integer", "minimum": 1, "description": "a number from the latest state"}});
    let coordinate = |what: &str| json!({"type": "integer", "minimum": -MAX_WINDOW_PIXELS, "maximum": MAX_WINDOW_PIXELS, "description": what});
    let size = |what: &str| json!({"type": "integer", "minimum": 1, "maximum": MAX_WINDOW_PIXELS, "description": what});
    vec![
        (
            "launch_app",
            "Starts a program by name: one Windows registers under App Paths or finds on the PATH (notepad, msedge, \
             chrome, code, calc), else a Start menu shortcut with that name; answers the title of the window it \
             opened (waiting up to 10 seconds for one).",
            object(json!({"name": string("the program's name, e.g. notepad")}), &["name"]),
        ),
        (
            "switch_window",
            "Brings a window to the front, restoring it when minimised: the window titled exactly so, else the \
             topmost whose title contains the text (any case).",
            object(json!({"title": string("the window's title, or a part of it")}), &["title"]),
        ),
        (
            "resize_window",
            "Moves, resizes, maximises, minimises or restores a window (the one titled so, as switch_window finds \
             it, else the foreground window). A maximised or minimised window is restored before it is moved.",
            object(
                json!({
                    "title": string("the window's title, or a part of it; the foreground window without it"),
                    "x": coordinate("the left edge, in screen pixels"),
                    "y": coordinate("the top edge, in screen pixels"),
                    "width": size("pixels"),
                    "height": size("pixels"),
                    "state": {"type": "string", "enum": ["normal", "maximized", "minimized"]},
                }),
                &[],
            ),
        ),
        ("clipboard_get", "The clipboard: its text as JSON text, or its image as a PNG.", none.clone()),
        ("clipboard_set", "Puts text on the clipboard.", object(json!({"text": {"type": "string"}}), &["text"])),
        (
            "shell",
            "Runs a command line in the guest's shell and answers its exit code and output: Windows PowerShell \
             on Windows; on the stub backend, the stub's simulated programs, or `sh -c` on the stub's machine \
             when the guest also has --stub-host-exec. Refused unless the guest was started with --mcp-shell.",
            object(
                json!({
                    "command": {"type": "string", "minLength": 1, "maxLength": MAX_SHELL_COMMAND_UNITS, "description": "the command line"},
                    "timeout": {"type": "number", "exclusiveMinimum": 0, "maximum": MAX_SHELL_SECONDS, "default": DEFAULT_SHELL_SECONDS, "description": "seconds before the command is ended"},
                }),
                &["command"],
            ),
        ),
        (
            "state",
            "The foreground window, the open windows and the interactive elements on the screen (buttons, fields, \
             list and menu items...), each with a number that click_element and type_into_element take. Numbers are \
             valid for the latest state only: call state again after the screen changes.",
            none,
        ),
        (
            "click_element",
            "Clicks the centre of a numbered element of the latest state.",
            object(merge(element.clone(), click), &["element"]),
        ),
        (
            "type_into_element",
            "Clicks a numbered element of the latest state, then types text into it; clear first empties it \
             (ctrl+a, backspace), press_enter presses Enter after.",
            object(
                merge(
                    element,
                    json!({
                        "text": {"type": "string"},
                        "clear": {"type": "boolean", "default": false},
                        "press_enter": {"type": "boolean", "default": false},
                    }),
                ),
                &["element", "text"],
            ),
        ),
    ]
}

impl Args<'_> {
    fn optional_int(&mut self, name: &str, min: i32, max: i32) -> Result<Option<i32>, String> {
        match self.take(name) {
            None => Ok(None),
            Some(v) => match self.as_int(name, &v)? {
                n if (min..=max).contains(&n) => Ok(Some(n)),
                n => Err(self.bad(format!("{name} must be from {min} to {max}, not {n}"))),
            },
        }
    }

    fn flag(&mut self, name: &str) -> Result<bool, String> {
        match self.take(name) {
            None => Ok(false),
            Some(Value::Bool(b)) => Ok(b),
            Some(v) => Err(self.bad(format!("{name} must be true or false, not {v}"))),
        }
    }

    fn nonempty(&mut self, name: &str) -> Result<String, String> {
        let s = self.string(name)?;
        if s.trim().is_empty() {
            return Err(self.bad(format!("{name} must not be empty")));
        }
        Ok(s)
    }

    /// A program's name or a window's title: not empty, at most [`MAX_NAME_CHARS`].
    fn name(&mut self, name: &str) -> Result<String, String> {
        let s = self.nonempty(name)?;
        let chars = s.chars().count();
        if chars > MAX_NAME_CHARS {
            return Err(self.bad(format!("{name} is {chars} characters long; at most {MAX_NAME_CHARS}")));
        }
        Ok(s)
    }

    fn element(&mut self) -> Result<u64, String> {
        match self.take("element") {
            None => Err(self.bad("missing argument \"element\"")),
            Some(v) => match v.as_u64() {
                Some(n) if n >= 1 => Ok(n),
                _ => Err(self.bad(format!("element must be a number from the latest state (1 or more), not {v}"))),
            },
        }
    }

    fn button_and_clicks(&mut self) -> Result<(MouseButton, u32), String> {
        let button = match self.take("button") {
            None => MouseButton::Left,
            Some(Value::String(b)) if ["left", "right", "middle"].contains(&b.as_str()) => {
                MouseButton::from_name(&b).unwrap_or_default()
            }
            Some(v) => return Err(self.bad(format!("button must be left, right or middle, not {v}"))),
        };
        let clicks = match self.take("clicks") {
            None => 1,
            Some(v) => match self.as_int("clicks", &v)? {
                n @ 1..=3 => n.unsigned_abs(),
                n => return Err(self.bad(format!("clicks must be 1, 2 or 3, not {n}"))),
            },
        };
        Ok((button, clicks))
    }
}

/// A call of a [`GUEST_ONLY`] tool.
fn guest_call(args: &mut Args<'_>) -> Result<ToolCall, String> {
    Ok(match args.tool {
        "launch_app" => ToolCall::LaunchApp { name: args.name("name")? },
        "switch_window" => ToolCall::SwitchWindow { title: args.name("title")? },
        "resize_window" => {
            let title = match args.map.get("title") {
                None | Some(Value::Null) => None,
                Some(_) => Some(args.name("title")?),
            };
            let show = match args.take("state") {
                None => None,
                Some(Value::String(s)) if s == "normal" => Some(ShowState::Normal),
                Some(Value::String(s)) if s == "maximized" => Some(ShowState::Maximized),
                Some(Value::String(s)) if s == "minimized" => Some(ShowState::Minimized),
                Some(v) => return Err(args.bad(format!("state must be normal, maximized or minimized, not {v}"))),
            };
            let limit = MAX_WINDOW_PIXELS;
            let change = WindowChange {
                title,
                x: args.optional_int("x", -limit, limit)?,
                y: args.optional_int("y", -limit, limit)?,
                width: args.optional_int("width", 1, limit)?,
                height: args.optional_int("height", 1, limit)?,
                show,
            };
            if change.moves() && matches!(show, Some(ShowState::Maximized | ShowState::Minimized)) {
                return Err(args.bad("a maximised or minimised window has no position or size of its own: give state normal (or none) with x, y, width or height"));
            }
            if !change.moves() && show.is_none() {
                return Err(args.bad("nothing to do: give x, y, width, height or state"));
            }
            ToolCall::ResizeWindow(change)
        }
        "clipboard_get" => ToolCall::ClipboardGet,
        "clipboard_set" => {
            let text = args.string("text")?;
            if text.len() > MAX_CLIPBOARD_TEXT_BYTES {
                return Err(args.bad(format!(
                    "text holds {} bytes; at most {MAX_CLIPBOARD_TEXT_BYTES} go on the clipboard in one call",
                    text.len()
                )));
            }
            ToolCall::ClipboardSet(text)
        }
        "shell" => {
            let command = args.nonempty("command")?;
            let units = command.encode_utf16().count();
            if units > MAX_SHELL_COMMAND_UNITS {
                return Err(args.bad(format!(
                    "command is {units} UTF-16 units long; at most {MAX_SHELL_COMMAND_UNITS} fit a Windows command \
                     line (write a longer script to a file and run that)"
                )));
            }
            let seconds = match args.take("timeout") {
                None => DEFAULT_SHELL_SECONDS,
                Some(v) => match v.as_f64() {
                    Some(s) if s > 0.0 && s <= MAX_SHELL_SECONDS => s,
                    _ => {
                        return Err(args.bad(format!(
                            "timeout must be a number of seconds above 0 and at most {MAX_SHELL_SECONDS}, not {v}"
                        )))
                    }
                },
            };
            ToolCall::Shell { command, timeout_ms: (seconds * 1000.0).round() as u64 }
        }
        "state" => ToolCall::State,
        "click_element" => {
            let element = args.element()?;
            let (button, clicks) = args.button_and_clicks()?;
            ToolCall::ClickElement { element, button, clicks }
        }
        "type_into_element" => ToolCall::TypeIntoElement {
            element: args.element()?,
            text: args.string("text")?,
            clear: args.flag("clear")?,
            press_enter: args.flag("press_enter")?,
        },
        other => return Err(format!("unknown tool {other:?}")),
    })
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
        assert!(!desktop.contains(&"get_task") && !desktop.contains(&"done") && desktop.len() == 12 + GUEST_ONLY.len());
        assert_eq!(desktop[12..], GUEST_ONLY, "the guest's own tools follow the shared ones");
        assert!(GUEST_ONLY.iter().all(|t| !names.contains(t)), "a benchmark episode offers none of them");
        for (name, _, schema) in tool_list(false) {
            assert_eq!(schema["type"], "object", "{name}");
            assert_eq!(schema["additionalProperties"], false, "{name}");
        }
    }

    fn guest(tool: &str, args: Value) -> Result<ToolCall, String> {
        let Value::Object(map) = args else { panic!("arguments are an object") };
        parse(tool, Some(map), Some((1280, 800)), false)
    }

    #[test]
    fn the_guest_tools_are_checked_into_calls() {
        assert_eq!(guest("launch_app", json!({"name": "notepad"})), Ok(ToolCall::LaunchApp { name: "notepad".into() }));
        assert_eq!(guest("state", json!({})), Ok(ToolCall::State));
        assert_eq!(
            guest("type_into_element", json!({"element": 4, "text": "hi", "press_enter": true})),
            Ok(ToolCall::TypeIntoElement { element: 4, text: "hi".into(), clear: false, press_enter: true })
        );
        assert_eq!(
            guest("click_element", json!({"element": 2, "button": "right"})),
            Ok(ToolCall::ClickElement { element: 2, button: MouseButton::Right, clicks: 1 })
        );
        assert_eq!(
            guest("resize_window", json!({"title": "Notepad", "width": 640, "height": 480})),
            Ok(ToolCall::ResizeWindow(WindowChange {
                title: Some("Notepad".into()),
                width: Some(640),
                height: Some(480),
                ..WindowChange::default()
            }))
        );
        assert_eq!(
            guest("shell", json!({"command": "Get-Date"})),
            Ok(ToolCall::Shell { command: "Get-Date".into(), timeout_ms: 30_000 })
        );
        assert_eq!(guest("clipboard_set", json!({"text": ""})), Ok(ToolCall::ClipboardSet(String::new())));
        // Outside the guest they do not exist.
        assert_eq!(call("launch_app", json!({"name": "notepad"})), Err("unknown tool \"launch_app\"".to_owned()));
        assert_eq!(call("shell", json!({"command": "dir"})), Err("unknown tool \"shell\"".to_owned()));
    }

    #[test]
    fn bad_guest_arguments_are_named() {
        let err = |tool: &str, args: Value| guest(tool, args).expect_err("refused");
        assert_eq!(err("launch_app", json!({"name": " "})), "launch_app: name must not be empty");
        assert_eq!(
            err("click_element", json!({"element": 0})),
            "click_element: element must be a number from the latest state (1 or more), not 0"
        );
        assert_eq!(err("click_element", json!({})), "click_element: missing argument \"element\"");
        assert_eq!(
            err("type_into_element", json!({"element": 1, "text": "a", "clear": "yes"})),
            "type_into_element: clear must be true or false, not \"yes\""
        );
        assert_eq!(err("resize_window", json!({})), "resize_window: nothing to do: give x, y, width, height or state");
        assert!(err("resize_window", json!({"state": "maximized", "x": 3})).contains("give state normal"));
        assert_eq!(err("resize_window", json!({"width": 0})), "resize_window: width must be from 1 to 16384, not 0");
        assert_eq!(
            err("resize_window", json!({"state": "huge"})),
            "resize_window: state must be normal, maximized or minimized, not \"huge\""
        );
        assert!(err("shell", json!({"command": "dir", "timeout": 601})).starts_with("shell: timeout must be"));
        let long = "x".repeat(MAX_SHELL_COMMAND_UNITS + 1);
        assert!(err("shell", json!({"command": long})).starts_with("shell: command is 8193 UTF-16 units long"));
        let title = "t".repeat(MAX_NAME_CHARS + 1);
        assert_eq!(
            err("switch_window", json!({"title": title})),
            "switch_window: title is 1025 characters long; at most 1024"
        );
        assert_eq!(
            err("resize_window", json!({"title": " ", "state": "normal"})),
            "resize_window: title must not be empty"
        );
        assert_eq!(
            err("resize_window", json!({"title": 3, "state": "normal"})),
            "resize_window: title must be a string, not 3"
        );
        let big = "c".repeat(MAX_CLIPBOARD_TEXT_BYTES + 1);
        assert!(err("clipboard_set", json!({"text": big})).starts_with("clipboard_set: text holds 1048577 bytes"));
        assert_eq!(err("state", json!({"window": "x"})), "state: unknown argument \"window\"");
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
