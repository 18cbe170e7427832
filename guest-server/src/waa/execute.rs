//! Running programs and agent code: `/execute` and `/setup/execute` (one handler, as
//! upstream), `/setup/launch`, `/update_computer` and `/execute_windows`.
//!
//! Commands follow Python's `subprocess` on Windows: a string without `shell` is split
//! with POSIX `shlex`, a list becomes one MSVC command line, `shell` (Python truthiness)
//! runs it through `cmd /c`. The programs themselves are whatever the backend finds;
//! nothing here interprets Python. `/execute_windows` code goes through
//! [`run_computer_code`], the seam where the `computer.*` interpreter plugs in.

use std::time::Duration;

use axum::extract::State;
use axum::http::StatusCode;
use base64::Engine;
use serde_json::{json, Value};

use crate::cmdline::{list2cmdline, shlex_split};
use crate::desktop::{CommandSpec, Desktop, DesktopError, ExecLimits};
use crate::error::WaaError;
use crate::state::AppState;
use crate::waa::body::{Data, PyJson};
use crate::waa::{expand_user, json, json_err, on_backend, on_backend_within, py, text, WaaResult};

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
    /// The decoded screenshot, used by `clipboard.copy_image`.
    pub screenshot: image::RgbaImage,
    /// `[sx, sy]` multiplying element centres.
    pub scale: Option<Value>,
    /// The virtual clipboard echoed by `/obs_winagent` (`null` when not sent).
    pub clipboard_content: Value,
    /// Use alt+c / alt+v instead of ctrl.
    pub swap_ctrl_alt: bool,
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
                other => Err(WaaError::catch(format!("'{}' object has no attribute 'startswith'", py::type_name(&other)))),
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
    let seconds = if timeout_ms % 1000 == 0 { (timeout_ms / 1000).to_string() } else { py::float_repr(timeout_ms as f64 / 1000.0) };
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
    let deadline = Duration::from_millis(timeout_ms) + EXEC_MARGIN;
    on_backend_within(&state, "execute", deadline, move |desktop| {
        let command = expand_home_args(desktop, command)?;
        let spec = match (&command, shell) {
            (Value::String(line), _) => CommandSpec::Shell(line.clone()),
            (Value::Array(items), true) => CommandSpec::Shell(list2cmdline(&string_list(items))),
            (Value::Array(items), false) if items.is_empty() => return Err(WaaError::catch("[WinError 87] The parameter is incorrect")),
            (Value::Array(items), false) => CommandSpec::Argv(string_list(items)),
            (other, _) => {
                return Err(WaaError::catch(format!("expected str, bytes or os.PathLike object, not {}", py::type_name(other))));
            }
        };
        let limits = ExecLimits { timeout_ms, max_output_bytes: MAX_OUTPUT_BYTES, cwd: None, stdin: None };
        match desktop.run(&spec, &limits) {
            Ok(out) if out.timed_out => Err(WaaError::catch(timeout_message(&command, timeout_ms))),
            Ok(out) => Ok(json(
                StatusCode::OK,
                json!({"status": "success", "output": out.stdout, "error": out.stderr, "returncode": out.exit_code.unwrap_or(-1)}),
            )),
            Err(DesktopError::NotFound(_)) => Err(WaaError::catch(PROGRAM_NOT_FOUND)),
            Err(DesktopError::Timeout { .. }) => Err(WaaError::catch(timeout_message(&command, timeout_ms))),
            Err(err) => Err(WaaError::from(err)),
        }
    })
    .await
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
            Ok(_) | Err(DesktopError::NotFound(_)) => Ok(text(StatusCode::OK, format!("{} launched successfully", py::str_of(&command)))),
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
pub(crate) async fn update_computer(State(state): State<AppState>, PyJson(body): PyJson) -> WaaResult {
    let data = Data(&body);
    let rects = data.get("rects")?.cloned();
    let window_rect = data.get("window_rect")?.cloned();
    let encoded = match data.get("screenshot")? {
        Some(Value::String(s)) => s.clone(),
        other => {
            let type_name = other.map_or("NoneType", py::type_name);
            return Err(WaaError::catch(format!("argument should be a bytes-like object or ASCII string, not '{type_name}'")));
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
    state.waa.set_computer(ComputerState { rects, window_rect, screenshot, scale, clipboard_content, swap_ctrl_alt });
    Ok(json(StatusCode::OK, json!({"success": true})))
}

/// `POST /execute_windows`.
pub(crate) async fn execute_windows(State(state): State<AppState>, PyJson(body): PyJson) -> WaaResult {
    let data = Data(&body);
    let code = match data.get("command")? {
        Some(Value::String(code)) => code.clone(),
        _ => return Ok(exec_failure("exec() arg 1 must be a string, bytes or code object".to_owned())),
    };
    let computer = state.waa.computer();
    let deadline = Duration::from_millis(state.config.exec_timeout_ms) + EXEC_MARGIN;
    let outcome = on_backend_within(&state, "execute_windows", deadline, move |desktop| {
        Ok(run_computer_code(desktop, &code, computer.as_deref()))
    })
    .await?;
    Ok(match outcome {
        Ok(()) => json(StatusCode::OK, json!({"status": "success"})),
        Err(message) => exec_failure(message),
    })
}

/// Upstream's own failure answer of `/execute_windows` (the same shape as the catch-all).
fn exec_failure(message: String) -> axum::response::Response {
    tracing::warn!(%message, "execute_windows failed");
    json(StatusCode::INTERNAL_SERVER_ERROR, json!({"status": "error", "message": message}))
}

/// Runs `/execute_windows` code (upstream: `exec(code, {'computer': ..., 'human': ...})`)
/// against the `/update_computer` state.
///
/// This build has no interpreter for the `computer.*` call language yet. It does what it
/// can answer exactly: code without statements succeeds (as `exec` of a blank program
/// does), and before the first `/update_computer` a `computer.<part>.<method>` call fails
/// with Python's `AttributeError` text. Everything else fails loudly, naming the first
/// statement, so a host never mistakes an unperformed action for a success.
///
/// # Errors
///
/// The message of the 500 answer.
pub fn run_computer_code(desktop: &dyn Desktop, code: &str, computer: Option<&ComputerState>) -> Result<(), String> {
    let _ = desktop;
    let Some(first) = statements(code).into_iter().next() else {
        return Ok(());
    };
    if computer.is_none() {
        if let Some(attribute) = none_attribute(&first) {
            return Err(format!("'NoneType' object has no attribute '{attribute}'"));
        }
    }
    Err(format!(
        "computer.* code execution is not available in this build yet (the interpreter is still to come); nothing was run. First statement: {first}"
    ))
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
    fn none_attribute_names_the_method() {
        let check = |stmt: &str, expected: Option<&str>| assert_eq!(none_attribute(stmt).as_deref(), expected, "{stmt:?}");
        check("computer.mouse.move_id(id=78)", Some("move_id"));
        check("computer.keyboard.write('a.b')", Some("write"));
        check("x = 1; computer.clipboard.copy_text('x')", Some("copy_text"));
        check("mycomputer.mouse.move_id(1)", None);
        check("import time; time.sleep(1)", None);
        check("computer.mouse", None);
    }

    #[test]
    fn timeout_messages_quote_the_command_like_python() {
        assert_eq!(timeout_message(&json!(["python", "-c", "x"]), 120_000), "Command '['python', '-c', 'x']' timed out after 120 seconds");
        assert_eq!(timeout_message(&json!("dir"), 1_500), "Command 'dir' timed out after 1.5 seconds");
    }

    #[test]
    fn base64_is_lenient_like_python() {
        assert_eq!(b64decode("aGVs\nbG8=").ok(), Some(b"hello".to_vec()));
        assert_eq!(b64decode("aGVsbG8").ok(), Some(b"hello".to_vec()));
        assert!(b64decode("é").is_err());
    }
}
