//! Running programs and agent code: `/execute` and `/setup/execute` (one handler, as
//! upstream), `/setup/launch`, `/update_computer` and `/execute_windows`.
//!
//! Commands follow Python's `subprocess` on Windows: a string without `shell` is split
//! with POSIX `shlex`, a list becomes one MSVC command line, `shell` (Python truthiness)
//! runs it through `cmd /c`. A Python invocation with `-c` (`python -c CODE`, any
//! spelling of the program, also inside a shell line) is not started as a process:
//! the code runs natively with `arena_script` over [`DesktopHost`], and the
//! answer is what the Python process would have printed and returned. Code outside
//! that subset runs with a real Python only when `--python` names one that exists;
//! otherwise it is refused loudly, naming the construct. Other programs are whatever
//! the backend finds. `/execute_windows` code runs with the same interpreter, with
//! `computer` bound to the `/update_computer` state ([`run_computer_code`]).

use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant};

use axum::extract::State;
use axum::http::StatusCode;
use base64::Engine;
use serde_json::{json, Value};

use arena_script::{self as script, ErrorKind, Globals, MemoryPool, ParseError, ScriptError};

use crate::desktop::{CommandSpec, Desktop, DesktopError, ExecLimits};
use crate::error::WaaError;
use crate::script_host::DesktopHost;
use crate::state::AppState;
use crate::waa::body::{Data, PyJson};
use crate::waa::WaaState;
use crate::waa::{expand_user, json, json_err, on_backend, on_backend_within, py, text, WaaResult};
use arena_shared::cmdline::{list2cmdline, shlex_split};
use arena_shared::ntpath;

/// Output kept per stream: far above anything upstream ever returned, so nothing is lost,
/// while a runaway program cannot exhaust the server's memory.
const MAX_OUTPUT_BYTES: u64 = 64 << 20;

/// Extra time the backend call gets beyond the command's own timeout, for process start and teardown.
const EXEC_MARGIN: Duration = Duration::from_secs(15);

/// Python's `FileNotFoundError` text when `CreateProcess` cannot find the program.
const PROGRAM_NOT_FOUND: &str = "[WinError 2] The system cannot find the file specified";

/// The state `/update_computer` stores (upstream's `computer.update(...)`), read by
/// `/execute_windows` and `/obs_winagent`.
///
/// Values other than the screenshot are kept as sent: upstream does not check them
/// either, and the interpreter reads them with Python's semantics when code uses them.
#[derive(Clone)]
pub struct ComputerState {
    /// Set-of-Marks element boxes `[[x1, y1, x2, y2], ...]`; the element id is the index.
    pub rects: Option<Value>,
    /// `[x0, y0, x1, y1]` of the observed view.
    pub window_rect: Option<Value>,
    /// The decoded screenshot, used by `clipboard.copy_image` (shared, so that
    /// writing back what a script changed does not copy the pixels).
    pub screenshot: Arc<image::RgbaImage>,
    /// `[sx, sy]` multiplying element centres.
    pub scale: Option<Value>,
    /// The virtual clipboard echoed by `/obs_winagent` (`null` when not sent).
    pub clipboard_content: Value,
    /// Use alt+c / alt+v instead of ctrl.
    pub swap_ctrl_alt: bool,
    /// The element `mouse.move_id` last moved to (upstream's `Mouse.current_id`);
    /// reset by `/update_computer`.
    pub current_id: Option<usize>,
}

impl std::fmt::Debug for ComputerState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // The screenshot's pixels would flood any log; its size is what matters.
        f.debug_struct("ComputerState")
            .field("rects", &self.rects)
            .field("window_rect", &self.window_rect)
            .field("screenshot", &(self.screenshot.width(), self.screenshot.height()))
            .field("scale", &self.scale)
            .field("clipboard_content", &self.clipboard_content)
            .field("swap_ctrl_alt", &self.swap_ctrl_alt)
            .field("current_id", &self.current_id)
            .finish()
    }
}

/// Applies upstream's loop `for i, arg in enumerate(command): if arg.startswith("~/"): ...`
/// to a command value, with the exceptions Python raises for values it cannot iterate.
fn expand_home_args(desktop: &dyn Desktop, command: Value) -> Result<Value, WaaError> {
    match command {
        Value::Array(items) => items
            .into_iter()
            .map(|item| match item {
                Value::String(arg) if arg.starts_with("~/") => Ok(Value::String(expand_user(desktop, &arg))),
                Value::String(arg) => Ok(Value::String(arg)),
                other => {
                    Err(WaaError::catch(format!("'{}' object has no attribute 'startswith'", py::type_name(&other))))
                }
            })
            .collect::<Result<Vec<_>, _>>()
            .map(Value::Array),
        // Iterating a string visits single characters, none of which starts with "~/".
        Value::String(s) => Ok(Value::String(s)),
        Value::Object(map) => Ok(Value::Object(map)),
        other => Err(WaaError::catch(format!("'{}' object is not iterable", py::type_name(&other)))),
    }
}

fn string_list(items: &[Value]) -> Vec<String> {
    items.iter().map(|v| v.as_str().unwrap_or_default().to_owned()).collect()
}

/// Python's `TimeoutExpired` text: `Command '<cmd>' timed out after <n> seconds`.
fn timeout_message(command: &Value, timeout_ms: u64) -> String {
    let seconds = if timeout_ms % 1000 == 0 {
        (timeout_ms / 1000).to_string()
    } else {
        py::float_repr(timeout_ms as f64 / 1000.0)
    };
    format!("Command '{}' timed out after {seconds} seconds", py::str_of(command))
}

/// `POST /execute` and `POST /setup/execute`.
pub(crate) async fn execute(State(state): State<AppState>, PyJson(body): PyJson) -> WaaResult {
    let data = Data(&body);
    let shell = data.flag("shell")?;
    let command = data.get("command")?.cloned().unwrap_or_else(|| if shell { json!("") } else { json!([]) });
    let command = match command {
        Value::String(s) if !shell => {
            let words = shlex_split(&s).map_err(|err| WaaError::catch(err.to_string()))?;
            Value::Array(words.into_iter().map(Value::String).collect())
        }
        other => other,
    };
    let timeout_ms = state.config.exec_timeout_ms;
    let python = state.config.python.clone();
    let deadline = Duration::from_millis(timeout_ms) + EXEC_MARGIN;
    let place = state.programs.admit().await.map_err(busy)?;
    let _input = state.input_share().await;
    on_backend_within(&state, "execute", deadline, move |desktop| {
        // The place is the work's: it is given back when the program has stopped.
        let memory = place.memory();
        let command = expand_home_args(desktop, command)?;
        let mut spec = match (&command, shell) {
            (Value::String(line), _) => CommandSpec::Shell(line.clone()),
            (Value::Array(items), true) => CommandSpec::Shell(list2cmdline(&string_list(items))),
            (Value::Array(items), false) if items.is_empty() => return Err(WaaError::catch("[WinError 87] The parameter is incorrect")),
            (Value::Array(items), false) => CommandSpec::Argv(string_list(items)),
            (other, _) => {
                return Err(WaaError::catch(format!("expected str, bytes or os.PathLike object, not {}", py::type_name(other))));
            }
        };
        if let Some(code) = python_code(&spec) {
            match run_python(desktop, &code, &command, timeout_ms, memory) {
                Native::Answer(answer) => return answer,
                Native::Unsupported(message) => match python.as_deref().filter(|p| arena_shared::search_path::find_program(p).is_some()) {
                    Some(program) => {
                        tracing::info!(%message, python = %program.display(), "running code outside the native subset with a real Python");
                        spec = with_program(spec, program);
                    }
                    None => {
                        tracing::warn!(%message, "refusing Python code outside the native subset (no --python configured)");
                        return Err(WaaError::catch(format!("{message}{NO_PYTHON}")));
                    }
                },
            }
        }
        let limits = ExecLimits { timeout_ms, max_output_bytes: MAX_OUTPUT_BYTES, cwd: None, stdin: None };
        match desktop.run(&spec, &limits) {
            Ok(out) if out.timed_out => Err(WaaError::catch(timeout_message(&command, timeout_ms))),
            Ok(out) => Ok(json(StatusCode::OK, execute_answer(out))),
            Err(DesktopError::NotFound(_)) => Err(WaaError::catch(PROGRAM_NOT_FOUND)),
            Err(DesktopError::Timeout { .. }) => Err(WaaError::catch(timeout_message(&command, timeout_ms))),
            Err(err) => Err(WaaError::from(err)),
        }
    })
    .await
}

/// `/execute`'s answer when `--max-programs` are running and none finished in time:
/// 503 with upstream's error shape, naming the limit.
fn busy(busy: crate::programs::Busy) -> WaaError {
    json_err(StatusCode::SERVICE_UNAVAILABLE, json!({"status": "error", "message": busy.to_string()}))
}

/// `/execute`'s answer for a finished process: upstream's four fields, and
/// `output_truncated` / `error_truncated` (`true`) when a stream was cut at
/// [`MAX_OUTPUT_BYTES`], so that a cut answer is never taken for the whole one.
fn execute_answer(out: crate::desktop::ExecOutput) -> Value {
    let mut answer = json!({
        "status": "success",
        "output": out.stdout,
        "error": out.stderr,
        "returncode": out.exit_code.unwrap_or(-1),
    });
    if out.stdout_truncated {
        answer["output_truncated"] = json!(true);
    }
    if out.stderr_truncated {
        answer["error_truncated"] = json!(true);
    }
    answer
}

/// The code of a `python -c CODE` command, however it is spelled.
fn python_code(spec: &CommandSpec) -> Option<String> {
    match spec {
        CommandSpec::Argv(argv) => script::python_code_from_argv(argv).map(str::to_owned),
        CommandSpec::Shell(line) => script::python_code_from_command_line(line),
    }
}

/// The command with the configured Python as its program (and without a `py`
/// launcher's version selector such as `-3`, which python itself rejects). A shell
/// line is left as it is: the shell finds `python` the way upstream's did.
fn with_program(spec: CommandSpec, program: &Path) -> CommandSpec {
    match spec {
        CommandSpec::Argv(mut argv) if !argv.is_empty() => {
            let base = ntpath::basename(&argv[0]).to_ascii_lowercase();
            let launcher = matches!(base.strip_suffix(".exe").unwrap_or(&base), "py" | "pyw");
            let selector = argv.get(1).is_some_and(|a| {
                a.starts_with("-V:") || a.strip_prefix('-').is_some_and(|v| v.starts_with(|c: char| c.is_ascii_digit()))
            });
            if launcher && selector {
                argv.remove(1);
            }
            argv[0] = program.display().to_string();
            CommandSpec::Argv(argv)
        }
        other => other,
    }
}

/// What running `python -c` code natively came to.
enum Native {
    /// The answer to send, as the Python process would have produced it.
    Answer(Result<axum::response::Response, WaaError>),
    /// The code needs something outside the subset and nothing was performed yet;
    /// the message names the construct.
    Unsupported(String),
}

/// Whether a failure means "this interpreter does not cover that", rather than an
/// exception CPython would raise too.
fn outside_subset(err: &ScriptError) -> bool {
    match err.kind {
        ErrorKind::Syntax | ErrorKind::NotSupported | ErrorKind::ModuleNotFound | ErrorKind::Import => true,
        // A module attribute the interpreter lacks (`os.walk`) is an AttributeError
        // whose text says so; real modules have those attributes.
        ErrorKind::Attribute => err.message.contains("not supported by this interpreter"),
        _ => false,
    }
}

/// Why `/execute` refuses code outside the subset, after the message naming the construct.
const NO_PYTHON: &str =
    " (this guest runs Python code natively; start it with --python PATH to run other code with a real Python)";

fn unsupported_parse(err: &ParseError) -> String {
    format!("unsupported Python at line {}, column {}: {}", err.line, err.column, err.message)
}

fn unsupported_runtime(err: &ScriptError) -> String {
    format!("unsupported Python at line {}: {}: {}", err.line, err.kind, err.message)
}

/// When code run natively must stop: at its deadline, or when its backend call is
/// cancelled (the route's deadline passed or the request went away; see
/// [`crate::desktop::cancel`]), so a timed-out program does not run on.
fn code_stop(deadline: Instant) -> script::Stop {
    script::Stop::new(Some(deadline), crate::desktop::cancel::flag())
}

/// Runs `python -c` code natively and answers like upstream's `subprocess.run` would:
/// 200 with stdout, stderr and the exit code (1 and a traceback for an exception).
fn run_python(desktop: &dyn Desktop, code: &str, command: &Value, timeout_ms: u64, memory: Arc<MemoryPool>) -> Native {
    let program = match script::parse(code) {
        Ok(program) => program,
        Err(err) => return Native::Unsupported(unsupported_parse(&err)),
    };
    let deadline = Instant::now() + Duration::from_millis(timeout_ms);
    let mut host = DesktopHost::new(desktop, deadline);
    let globals = Globals::python().with_stop(code_stop(deadline)).with_memory(Some(memory));
    let (stdout, stderr, returncode) = match script::run(&program, &mut host, globals) {
        Ok(out) => (out.stdout, out.stderr, out.exit_code),
        Err(err) if err.kind == ErrorKind::Timeout && err.message.contains("would outlast") => {
            // Refused at once rather than waited out: Python's own words, and why.
            let message = format!("{} ({})", timeout_message(command, timeout_ms), err.message);
            return Native::Answer(Err(WaaError::catch(message)));
        }
        Err(err) if err.kind == ErrorKind::Timeout => {
            return Native::Answer(Err(WaaError::catch(timeout_message(command, timeout_ms))))
        }
        Err(err) if outside_subset(&err) && host.effects() == 0 => {
            return Native::Unsupported(unsupported_runtime(&err))
        }
        Err(err) if outside_subset(&err) => {
            // Running it again with a real Python would repeat what was already done.
            let message = format!(
                "{}; it stopped there after {} action(s) had been performed",
                unsupported_runtime(&err),
                host.effects()
            );
            return Native::Answer(Err(WaaError::catch(message)));
        }
        Err(err) => {
            let stderr = format!("{}{}", err.stderr, err.traceback());
            (err.stdout, stderr, 1)
        }
    };
    Native::Answer(Ok(json(
        StatusCode::OK,
        json!({"status": "success", "output": stdout, "error": stderr, "returncode": returncode}),
    )))
}

/// `POST /setup/launch`: always through the shell, never waited for.
pub(crate) async fn launch(State(state): State<AppState>, PyJson(body): PyJson) -> WaaResult {
    let data = Data(&body);
    // Upstream reads `shell` (so a non-object body fails here) and then forces it on.
    let _ = data.get("shell")?;
    let command = data.get("command")?.cloned().unwrap_or_else(|| json!(""));
    let request = body.clone();
    on_backend(&state, "launch", move |desktop| {
        let command = expand_home_args(desktop, command)?;
        // From here on upstream is inside `try`, whose failure answer carries the request.
        let failure = |command: &Value, message: String| {
            json_err(
                StatusCode::INTERNAL_SERVER_ERROR,
                json!({"status": "error", "message": message, "shell": "True", "command": command, "data": request}),
            )
        };
        let (command, line) = match command {
            Value::String(s) if s.contains("google-chrome") => {
                // `command[index] = 'chrome'` on a str.
                return Err(failure(&Value::String(s), "'str' object does not support item assignment".to_owned()));
            }
            Value::String(s) => {
                let line = s.clone();
                (Value::String(s), line)
            }
            Value::Array(items) => {
                let mut args = string_list(&items);
                if let Some(slot) = args.iter_mut().find(|a| a.as_str() == "google-chrome") {
                    "chrome".clone_into(slot);
                }
                let line = list2cmdline(&args);
                (Value::Array(args.into_iter().map(Value::String).collect()), line)
            }
            other => {
                let message = format!("expected str, bytes or os.PathLike object, not {}", py::type_name(&other));
                return Err(failure(&other, message));
            }
        };
        match desktop.spawn(&CommandSpec::Shell(line)) {
            // `cmd /c` starts even when the program it names does not exist; upstream "succeeds".
            Ok(_) | Err(DesktopError::NotFound(_)) => {
                Ok(text(StatusCode::OK, format!("{} launched successfully", py::str_of(&command))))
            }
            Err(err) => Err(failure(&command, err.to_string())),
        }
    })
    .await
}

/// Python's lenient `base64.b64decode`: characters outside the alphabet are skipped.
fn b64decode(s: &str) -> Result<Vec<u8>, WaaError> {
    if !s.is_ascii() {
        return Err(WaaError::catch("string argument should contain only ASCII characters"));
    }
    let cleaned: String = s.chars().filter(|c| c.is_ascii_alphanumeric() || *c == '+' || *c == '/').collect();
    let engine = base64::engine::GeneralPurpose::new(
        &base64::alphabet::STANDARD,
        base64::engine::GeneralPurposeConfig::new()
            .with_decode_padding_mode(base64::engine::DecodePaddingMode::Indifferent)
            .with_decode_allow_trailing_bits(true),
    );
    engine.decode(cleaned).map_err(|_| WaaError::catch("Incorrect padding"))
}

/// `POST /update_computer`.
pub(crate) async fn update_computer(
    State(state): State<AppState>,
    State(session): State<Arc<WaaState>>,
    PyJson(body): PyJson,
) -> WaaResult {
    let data = Data(&body);
    let rects = data.get("rects")?.cloned();
    let window_rect = data.get("window_rect")?.cloned();
    let encoded = match data.get("screenshot")? {
        Some(Value::String(s)) => s.clone(),
        other => {
            let type_name = other.map_or("NoneType", py::type_name);
            return Err(WaaError::catch(format!(
                "argument should be a bytes-like object or ASCII string, not '{type_name}'"
            )));
        }
    };
    let scale = data.get("scale")?.cloned();
    let clipboard_content = data.get("clipboard_content")?.cloned().unwrap_or(Value::Null);
    let swap_ctrl_alt = data.flag("swap_ctrl_alt")?;
    // Decoding a full-screen PNG is real CPU work: keep it off the async workers.
    let screenshot = on_backend(&state, "update_computer", move |_| {
        let bytes = b64decode(&encoded)?;
        crate::imaging::decode(&bytes).map_err(|err| {
            tracing::debug!(error = %err, "update_computer screenshot is not an image");
            WaaError::catch("cannot identify image file <_io.BytesIO object>")
        })
    })
    .await?;
    let screenshot = Arc::new(screenshot);
    session.set_computer(ComputerState {
        rects,
        window_rect,
        screenshot,
        scale,
        clipboard_content,
        swap_ctrl_alt,
        current_id: None,
    });
    Ok(json(StatusCode::OK, json!({"success": true})))
}

/// `POST /execute_windows`.
pub(crate) async fn execute_windows(
    State(state): State<AppState>,
    State(session): State<Arc<WaaState>>,
    PyJson(body): PyJson,
) -> WaaResult {
    let data = Data(&body);
    let code = match data.get("command")? {
        Some(Value::String(code)) => code.clone(),
        _ => return Ok(exec_failure("exec() arg 1 must be a string, bytes or code object".to_owned())),
    };
    let computer = session.computer();
    let started_from = computer.clone();
    let options = CodeOptions {
        action_delay: Duration::from_millis(state.config.computer_action_delay_ms),
        timeout: Duration::from_millis(state.config.exec_timeout_ms),
    };
    let deadline = options.timeout + EXEC_MARGIN;
    let place = state.programs.admit().await.map_err(busy)?;
    let _input = state.input_share().await;
    let run = on_backend_within(&state, "execute_windows", deadline, move |desktop| {
        Ok(run_computer_code(desktop, &code, computer.as_deref(), &options, Some(place.memory())))
    })
    .await?;
    if let (Some(before), Some(after)) = (started_from, run.state) {
        // Upstream's `Mouse` and `Clipboard` objects keep what the code changed until the
        // next `/update_computer`, which wins if it came in while the code ran.
        if before.current_id != after.current_id || before.clipboard_content != after.clipboard_content {
            let next = ComputerState {
                current_id: after.current_id,
                clipboard_content: after.clipboard_content,
                ..(*before).clone()
            };
            session.replace_computer(&before, next);
        }
    }
    Ok(match run.result {
        Ok(()) => json(StatusCode::OK, json!({"status": "success"})),
        Err(message) => exec_failure(message),
    })
}

/// Upstream's own failure answer of `/execute_windows` (the same shape as the catch-all).
fn exec_failure(message: String) -> axum::response::Response {
    tracing::warn!(%message, "execute_windows failed");
    json(StatusCode::INTERNAL_SERVER_ERROR, json!({"status": "error", "message": message}))
}

/// How `/execute_windows` code runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CodeOptions {
    /// The pause after each `computer.*` action (upstream: 0.25 s).
    pub action_delay: Duration,
    /// How long the code may run.
    pub timeout: Duration,
}

/// What running `/execute_windows` code did.
#[derive(Debug)]
pub struct ComputerRun {
    /// `Err` holds the message of the 500 answer.
    pub result: Result<(), String>,
    /// The state's `current_id` and `clipboard_content` after the run (also after a
    /// failure: effects are not undone), `None` when there was no state.
    pub state: Option<ComputerChanges>,
}

/// The parts of the `/update_computer` state a script may change.
#[derive(Debug, Clone, PartialEq)]
pub struct ComputerChanges {
    pub current_id: Option<usize>,
    pub clipboard_content: Value,
}

/// Runs `/execute_windows` code (upstream: `exec(code, {'computer': ..., 'human': ...})`)
/// natively against the `/update_computer` state.
///
/// Upstream's rules hold: anything printed that contains "error" (any case) fails the
/// request after all effects happened (Q8); an exception answers with its message.
/// Code outside the interpreter's subset fails naming the construct, line and column.
/// Before the first `/update_computer`, `computer.<part>.<method>` fails with Python's
/// `AttributeError` text, as upstream's `None` parts do.
pub fn run_computer_code(
    desktop: &dyn Desktop,
    code: &str,
    computer: Option<&ComputerState>,
    options: &CodeOptions,
    memory: Option<Arc<MemoryPool>>,
) -> ComputerRun {
    let fail = |message: String| ComputerRun { result: Err(message), state: None };
    let program = match script::parse(code) {
        Ok(program) => program,
        Err(err) => return fail(unsupported_parse(&err)),
    };
    let deadline = Instant::now() + options.timeout;
    let Some(stored) = computer else {
        if let Some(attribute) = statements(code).iter().find_map(|s| none_attribute(s)) {
            return fail(format!("'NoneType' object has no attribute '{attribute}'"));
        }
        let mut host = DesktopHost::new(desktop, deadline);
        let globals = Globals { computer_action_delay: 0.0, ..Globals::python() }
            .with_stop(code_stop(deadline))
            .with_memory(memory);
        let result = script::run(&program, &mut host, globals);
        return ComputerRun { result: code_result(result, options), state: None };
    };
    let mut state = match script_state(stored) {
        Ok(state) => state,
        Err(message) => return fail(message),
    };
    let initial_clipboard = state.clipboard_content.clone();
    let mut host = DesktopHost::new(desktop, deadline).with_screenshot(&stored.screenshot);
    let globals = Globals {
        computer: Some(&mut state),
        computer_action_delay: options.action_delay.as_secs_f64(),
        preimport: &[],
        stop: code_stop(deadline),
        memory,
    };
    let result = script::run(&program, &mut host, globals);
    let result = code_result(result, options);
    let clipboard_content = if state.clipboard_content == initial_clipboard {
        stored.clipboard_content.clone()
    } else {
        state.clipboard_content.map_or(Value::Null, Value::String)
    };
    ComputerRun { result, state: Some(ComputerChanges { current_id: state.current_id, clipboard_content }) }
}

/// Upstream's verdict on a finished `exec`: an exception's text, or the captured
/// stdout when it mentions "error".
fn code_result(result: Result<script::RunOutput, ScriptError>, options: &CodeOptions) -> Result<(), String> {
    match result {
        Ok(out) if out.stdout.to_lowercase().contains("error") => Err(out.stdout),
        Ok(_) => Ok(()),
        Err(err) if err.kind == ErrorKind::Timeout => {
            Err(format!("the code did not finish within {} seconds", py::float_repr(options.timeout.as_secs_f64())))
        }
        Err(err) if outside_subset(&err) => Err(unsupported_runtime(&err)),
        // `str(e)`: the exception's message without its class, as upstream answers.
        Err(err) => Err(err.message),
    }
}

/// The interpreter's view of the stored `/update_computer` values.
///
/// Missing values get the defaults Navi sends (`window_rect` the screenshot, `scale`
/// 1); values of the wrong shape fail the request naming the field, where upstream
/// would raise only when a method used them.
fn script_state(stored: &ComputerState) -> Result<script::ComputerState, String> {
    let number = |v: &Value, what: &str| -> Result<f64, String> {
        v.as_f64().filter(|f| f.is_finite()).ok_or_else(|| format!("{what} must hold numbers, not {}", py::repr(v)))
    };
    // Python's `int()` of a float truncates; the boxes are whole pixels anyway.
    let pixel = |v: &Value, what: &str| -> Result<i32, String> {
        let f = number(v, what)?;
        Ok(f.trunc().clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32)
    };
    let four = |v: &Value, what: &str| -> Result<[i32; 4], String> {
        match v.as_array().map(Vec::as_slice) {
            Some([a, b, c, d]) => Ok([pixel(a, what)?, pixel(b, what)?, pixel(c, what)?, pixel(d, what)?]),
            _ => Err(format!("{what} must be [x1, y1, x2, y2], not {}", py::repr(v))),
        }
    };
    let (width, height) = stored.screenshot.dimensions();
    let mut state = script::ComputerState::for_screen(
        i32::try_from(width).unwrap_or(i32::MAX),
        i32::try_from(height).unwrap_or(i32::MAX),
    );
    match &stored.rects {
        None | Some(Value::Null) => {}
        Some(Value::Array(items)) => {
            for (i, item) in items.iter().enumerate() {
                state.rects.push(four(item, &format!("rects[{i}]"))?);
            }
        }
        Some(other) => return Err(format!("rects must be a list of [x1, y1, x2, y2], not {}", py::repr(other))),
    }
    if let Some(rect) = stored.window_rect.as_ref().filter(|v| !v.is_null()) {
        state.window_rect = four(rect, "window_rect")?;
    }
    if let Some(scale) = stored.scale.as_ref().filter(|v| !v.is_null()) {
        match scale.as_array().map(Vec::as_slice) {
            Some([sx, sy]) => state.scale = (number(sx, "scale")?, number(sy, "scale")?),
            _ => return Err(format!("scale must be [sx, sy], not {}", py::repr(scale))),
        }
    }
    state.clipboard_content = match &stored.clipboard_content {
        Value::Null => None,
        Value::String(s) => Some(s.clone()),
        other => Some(py::str_of(other)),
    };
    state.swap_ctrl_alt = stored.swap_ctrl_alt;
    state.current_id = stored.current_id;
    Ok(state)
}

/// The statements of a program, roughly: non-blank lines that are not comments.
fn statements(code: &str) -> Vec<String> {
    code.lines().map(str::trim).filter(|line| !line.is_empty() && !line.starts_with('#')).map(str::to_owned).collect()
}

/// For `computer.<part>.<method>...`, where `<part>` is one of the objects that are
/// `None` before `/update_computer`, the method name Python's `AttributeError` names.
fn none_attribute(statement: &str) -> Option<String> {
    const PARTS: [&str; 6] = ["mouse", "keyboard", "clipboard", "os", "window_manager", "search"];
    let is_ident = |c: char| c.is_alphanumeric() || c == '_';
    let mut rest = statement;
    while let Some(at) = rest.find("computer.") {
        let preceded_by_ident = rest[..at].chars().next_back().is_some_and(is_ident);
        let after = &rest[at + "computer.".len()..];
        let part_len = after.find(|c: char| !is_ident(c)).unwrap_or(after.len());
        let part = &after[..part_len];
        if !preceded_by_ident && PARTS.contains(&part) {
            if let Some(method_start) = after[part_len..].trim_start().strip_prefix('.') {
                let method_start = method_start.trim_start();
                let method_len = method_start.find(|c: char| !is_ident(c)).unwrap_or(method_start.len());
                if method_len > 0 {
                    return Some(method_start[..method_len].to_owned());
                }
            }
        }
        rest = after;
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cut_stream_is_flagged_in_the_answer() {
        let out = |stdout_truncated, stderr_truncated| crate::desktop::ExecOutput {
            exit_code: Some(0),
            stdout: "x".into(),
            stderr: String::new(),
            stdout_truncated,
            stderr_truncated,
            timed_out: false,
            duration_ms: 1,
        };
        let whole = execute_answer(out(false, false));
        assert_eq!(
            whole,
            json!({"status": "success", "output": "x", "error": "", "returncode": 0}),
            "upstream's shape"
        );
        let cut = execute_answer(out(true, false));
        assert_eq!(cut["output_truncated"], true);
        assert!(cut.get("error_truncated").is_none());
        assert_eq!(execute_answer(out(false, true))["error_truncated"], true);
    }

    #[test]
    fn none_attribute_names_the_method() {
        let check =
            |stmt: &str, expected: Option<&str>| assert_eq!(none_attribute(stmt).as_deref(), expected, "{stmt:?}");
        check("computer.mouse.move_id(id=78)", Some("move_id"));
        check("computer.keyboard.write('a.b')", Some("write"));
        check("x = 1; computer.clipboard.copy_text('x')", Some("copy_text"));
        check("mycomputer.mouse.move_id(1)", None);
        check("import time; time.sleep(1)", None);
        check("computer.mouse", None);
    }

    #[test]
    fn timeout_messages_quote_the_command_like_python() {
        assert_eq!(
            timeout_message(&json!(["python", "-c", "x"]), 120_000),
            "Command '['python', '-c', 'x']' timed out after 120 seconds"
        );
        assert_eq!(timeout_message(&json!("dir"), 1_500), "Command 'dir' timed out after 1.5 seconds");
    }

    #[test]
    fn a_configured_python_replaces_the_program() {
        let check = |argv: &[&str], expected: &[&str]| {
            let spec = CommandSpec::Argv(argv.iter().map(|s| (*s).to_owned()).collect());
            let expected = CommandSpec::Argv(expected.iter().map(|s| (*s).to_owned()).collect());
            assert_eq!(with_program(spec, Path::new("/opt/py/bin/python3")), expected, "{argv:?}");
        };
        check(&["python", "-c", "x"], &["/opt/py/bin/python3", "-c", "x"]);
        check(&[r"C:\Python310\python.exe", "-u", "-c", "x"], &["/opt/py/bin/python3", "-u", "-c", "x"]);
        check(&["py", "-3.10", "-c", "x"], &["/opt/py/bin/python3", "-c", "x"]);
        let shell = CommandSpec::Shell("python -c x".into());
        assert_eq!(with_program(shell.clone(), Path::new("/p")), shell);
    }

    #[test]
    fn failures_outside_the_subset_are_told_apart_from_python_exceptions() {
        let err = |src: &str| {
            let program = script::parse(src).expect("parses");
            let dir = tempfile::tempdir().expect("temp dir");
            let stub = crate::desktop::stub::StubDesktop::new(dir.path().to_path_buf()).expect("stub");
            let mut host = DesktopHost::new(&stub, Instant::now() + Duration::from_secs(5));
            script::run(&program, &mut host, Globals::python()).expect_err("fails")
        };
        assert!(outside_subset(&err("import numpy")));
        assert!(outside_subset(&err("import os; os.walk('C:/')")));
        assert!(outside_subset(&err("from os import walk")));
        assert!(!outside_subset(&err("undefined_name")));
        assert!(!outside_subset(&err("[1][3]")));
    }

    #[test]
    fn base64_is_lenient_like_python() {
        assert_eq!(b64decode("aGVs\nbG8=").ok(), Some(b"hello".to_vec()));
        assert_eq!(b64decode("aGVsbG8").ok(), Some(b"hello".to_vec()));
        assert!(b64decode("é").is_err());
    }
}
