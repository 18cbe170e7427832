//! The standard-library modules a script may import: `time`, `os`, `os.path`
//! (Python 3.10's `ntpath`, the one copy in [`arena_shared::ntpath`]), `subprocess`, `platform`, `sys`,
//! `PIL` (as names; `ImageGrab.grab` works, `Image.open` does not) and
//! `pyperclip`.
//!
//! They are Windows-flavoured stand-ins, never real imports: `platform.system()`
//! is `"Windows"` and every effect (environment, files, processes, clipboard)
//! goes through the [`super::host::ScriptHost`]. A child process's output that
//! Python would not capture is appended to the script's own stdout/stderr, as
//! it would appear in a real `python -c` run.

use super::compose::Composed as _;
use super::error::{not_supported, type_error, value_error, ErrorKind, ScriptError};
use super::host::{CommandArg, CommandOutput, PathKind};
use super::value::{Object, Value};
use crate::args::{is_none, static_name, to_f64, to_i64, to_str, Args};
use crate::runtime::Runtime;
use arena_shared::ntpath;

const TIME: &[&str] = &["sleep"];
const OS: &[&str] = &["getenv", "system", "listdir", "startfile"];
const OS_PATH: &[&str] = &[
    "join",
    "basename",
    "dirname",
    "exists",
    "isfile",
    "isdir",
    "expanduser",
    "split",
    "splitext",
    "isabs",
    "splitdrive",
];
const SUBPROCESS: &[&str] = &["call", "run", "Popen", "check_call", "check_output"];
const PLATFORM: &[&str] = &["system", "platform", "release", "version", "machine", "node"];
const SYS: &[&str] = &["exit"];
const PIL_IMAGE: &[&str] = &["open"];
const PIL_IMAGEGRAB: &[&str] = &["grab"];
const PYPERCLIP: &[&str] = &["copy", "paste"];

/// `subprocess.PIPE`, `STDOUT` and `DEVNULL`.
const PIPE: i64 = -1;
const STDOUT: i64 = -2;
const DEVNULL: i64 = -3;

/// `<module>.<name>` for the non-pyautogui modules, or `None` when not provided.
pub(crate) fn attr(module: &'static str, name: &str) -> Option<Value> {
    let functions: &[&'static str] = match module {
        "time" => TIME,
        "os" => OS,
        "os.path" | "ntpath" => OS_PATH,
        "subprocess" => SUBPROCESS,
        "platform" => PLATFORM,
        "sys" => SYS,
        "PIL.Image" => PIL_IMAGE,
        "PIL.ImageGrab" => PIL_IMAGEGRAB,
        "pyperclip" => PYPERCLIP,
        _ => &[],
    };
    if let Some(f) = static_name(functions, name) {
        // `ntpath` and `os.path` are the same module on Windows.
        let module = if module == "ntpath" { "os.path" } else { module };
        return Some(Value::Function { module, name: f });
    }
    let s = |v: &str| Some(Value::str(v.to_owned()));
    match (module, name) {
        ("os", "path") => Some(Value::Module("os.path")),
        ("os", "environ") => Some(Value::Object(Object::Environ)),
        ("os", "name") => s("nt"),
        ("os", "sep") | ("os.path" | "ntpath", "sep") => s("\\"),
        ("os", "altsep") | ("os.path" | "ntpath", "altsep") => s("/"),
        ("os", "linesep") => s("\r\n"),
        ("os", "pathsep") | ("os.path" | "ntpath", "pathsep") => s(";"),
        ("os", "curdir") | ("os.path" | "ntpath", "curdir") => s("."),
        ("subprocess", "PIPE") => Some(Value::Int(PIPE)),
        ("subprocess", "STDOUT") => Some(Value::Int(STDOUT)),
        ("subprocess", "DEVNULL") => Some(Value::Int(DEVNULL)),
        ("subprocess", "CREATE_NEW_CONSOLE") => Some(Value::Int(0x10)),
        ("subprocess", "CREATE_NO_WINDOW") => Some(Value::Int(0x0800_0000)),
        ("subprocess", "DETACHED_PROCESS") => Some(Value::Int(0x8)),
        ("sys", "platform") => s("win32"),
        ("sys", "argv") => Some(Value::list(vec![Value::str("-c")])),
        ("sys", "maxsize") => Some(Value::Int(i64::MAX)),
        ("PIL", "Image") => Some(Value::Module("PIL.Image")),
        ("PIL", "ImageGrab") => Some(Value::Module("PIL.ImageGrab")),
        ("PIL.Image", "Image") => Some(Value::Type("PIL.Image.Image")),
        _ => None,
    }
}

/// Calls `<module>.<name>`.
pub(crate) fn call(it: &mut Runtime<'_, '_>, module: &str, name: &str, args: Args) -> Result<Value, ScriptError> {
    match module {
        "time" | "pyperclip" | "sys" | "platform" | "PIL.Image" | "PIL.ImageGrab" => misc(it, module, name, args),
        "os" => os(it, name, args),
        "os.path" => os_path(it, name, args),
        "subprocess" => subprocess(it, name, args),
        _ => Err(not_supported(format!("{module}.{name} is not supported"))),
    }
}

fn arg(a: &[Option<Value>], i: usize) -> &Value {
    a.get(i).and_then(Option::as_ref).unwrap_or(&Value::None)
}

/// A path argument, with the message `os.path` functions give for other types.
fn path_arg(v: &Value) -> Result<&str, ScriptError> {
    match v {
        Value::Str(s) => Ok(s),
        other => Err(type_error(format!("expected str, bytes or os.PathLike object, not {}", other.type_name()))),
    }
}

fn misc(it: &mut Runtime<'_, '_>, module: &str, name: &str, args: Args) -> Result<Value, ScriptError> {
    match (module, name) {
        ("time", "sleep") => {
            let a = args.bind("sleep", &["secs"], 1)?;
            let secs = to_f64(arg(&a, 0), "sleep() argument")?;
            it.sleep(secs)?;
            Ok(Value::None)
        }
        ("pyperclip", "copy") => {
            let a = args.bind("copy", &["text"], 1)?;
            let text = match arg(&a, 0) {
                v @ (Value::Str(_) | Value::Int(_) | Value::Float(_) | Value::Bool(_)) => v.to_str(),
                other => {
                    return Err(type_error(format!(
                        "only str, int, float, and bool values can be copied to the clipboard, not {}",
                        other.type_name()
                    )))
                }
            };
            let result = it.host.clipboard_set_text(&text);
            it.host(result)?;
            Ok(Value::None)
        }
        ("pyperclip", "paste") => {
            args.bind("paste", &[], 0)?;
            let text = it.host.clipboard_get_text();
            Ok(Value::str(it.host(text)?))
        }
        ("sys", "exit") => {
            let a = args.bind("exit", &["status"], 0)?;
            Err(exit_with(it, a[0].clone()))
        }
        ("platform", _) => {
            args.bind(name, &[], 0)?;
            Ok(Value::str(match name {
                "system" => "Windows".to_owned(),
                "release" => "10".to_owned(),
                "machine" => "AMD64".to_owned(),
                "node" => it.host.env_var("COMPUTERNAME").unwrap_or_default(),
                "version" => {
                    let v = it.host.os_version();
                    it.host(v)?
                }
                _ => {
                    let v = it.host.os_version();
                    format!("Windows-10-{}-SP0", it.host(v)?)
                }
            }))
        }
        ("PIL.ImageGrab", "grab") => {
            let a = args.bind("grab", &["bbox", "include_layered_windows", "all_screens", "xdisplay"], 0)?;
            let region = match a[0].as_ref().filter(|v| !matches!(v, Value::None)) {
                None => None,
                Some(bbox) => {
                    let items = crate::args::iterate(bbox)?;
                    let [l, t, r, b] = items.as_slice() else {
                        return Err(value_error("bbox must be (left, top, right, bottom)"));
                    };
                    let (l, t) = (to_i64(l, "left")?, to_i64(t, "top")?);
                    let (r, b) = (to_i64(r, "right")?, to_i64(b, "bottom")?);
                    Some(Value::tuple(vec![Value::Int(l), Value::Int(t), Value::Int(r - l), Value::Int(b - t)]))
                }
            };
            super::pyautogui::screenshot_image(it, &region)
        }
        _ => Err(not_supported(format!("{module}.{name} is not supported: this interpreter has no image library"))),
    }
}

/// `SystemExit(status)`: `None` is 0, an int is the code, anything else is printed to stderr and is 1.
pub(crate) fn exit_with(it: &mut Runtime<'_, '_>, status: Option<Value>) -> ScriptError {
    let code = match status.unwrap_or(Value::None) {
        Value::None => 0,
        Value::Int(i) => i32::try_from(i).unwrap_or(-1),
        Value::Bool(b) => i32::from(b),
        other => {
            it.out.stderr.push_str(&other.to_str());
            it.out.stderr.push('\n');
            1
        }
    };
    it.system_exit(code)
}

fn os(it: &mut Runtime<'_, '_>, name: &str, args: Args) -> Result<Value, ScriptError> {
    match name {
        "getenv" => {
            let a = args.bind("getenv", &["key", "default"], 1)?;
            let key = match arg(&a, 0) {
                Value::Str(s) => s,
                other => return Err(type_error(format!("str expected, not {}", other.type_name()))),
            };
            Ok(it.host.env_var(key).map(Value::str).unwrap_or_else(|| arg(&a, 1).clone()))
        }
        "system" => {
            let a = args.bind("system", &["command"], 1)?;
            let command = to_str(arg(&a, 0), "system() argument")?.to_owned();
            let result = it.host.run_command(&CommandArg::Line(command), true);
            let output = it.host(result)?;
            it.out.stdout.push_str(&output.stdout);
            it.out.stderr.push_str(&output.stderr);
            Ok(Value::Int(i64::from(output.code)))
        }
        "listdir" => {
            let a = args.bind("listdir", &["path"], 0)?;
            let path = match arg(&a, 0) {
                Value::None => ".",
                v => path_arg(v)?,
            }
            .to_owned();
            let names = it.host.list_dir(&path);
            Ok(Value::list(it.host(names)?.into_iter().map(Value::str).collect()))
        }
        "startfile" => {
            let a = args.bind("startfile", &["path", "operation"], 1)?;
            if !is_none(&a[1]) {
                return Err(not_supported("os.startfile(operation=...) is not supported"));
            }
            let path = path_arg(arg(&a, 0))?;
            if path.contains('"') {
                return Err(value_error("os.startfile() path must not contain '\"'"));
            }
            let command = CommandArg::Line(format!("start \"\" \"{path}\""));
            let result = it.host.spawn_command(&command, true);
            it.host(result)?;
            Ok(Value::None)
        }
        other => Err(not_supported(format!("os.{other} is not supported"))),
    }
}

fn os_path(it: &mut Runtime<'_, '_>, name: &str, args: Args) -> Result<Value, ScriptError> {
    let s = |v: String| Ok(Value::str(v));
    let pair = |(a, b): (&str, &str)| Ok(Value::tuple(vec![Value::str(a.to_owned()), Value::str(b.to_owned())]));
    if name == "join" {
        if !args.kw.is_empty() {
            return Err(type_error("join() takes no keyword arguments"));
        }
        let Some((first, rest)) = args.pos.split_first() else {
            return Err(type_error("join() missing 1 required positional argument: 'path'"));
        };
        let mut parts = vec![path_arg(first)?];
        for p in rest {
            parts.push(path_arg(p)?);
        }
        return s(ntpath::join(&parts));
    }
    let a = args.bind(name, &["path"], 1)?;
    let path = path_arg(arg(&a, 0))?.to_owned();
    match name {
        "basename" => s(ntpath::basename(&path).to_owned()),
        "dirname" => s(ntpath::dirname(&path).to_owned()),
        "split" => pair(ntpath::split(&path)),
        "splitext" => pair(ntpath::splitext(&path)),
        "splitdrive" => pair(ntpath::splitdrive(&path)),
        "isabs" => Ok(Value::Bool(ntpath::isabs(&path))),
        "expanduser" => {
            let host = &mut *it.host;
            s(ntpath::expanduser(&path, &mut |var| host.env_var(var)))
        }
        _ => {
            let kind = it.host.path_kind(&path);
            Ok(Value::Bool(match name {
                "isfile" => kind == Some(PathKind::File),
                "isdir" => kind == Some(PathKind::Dir),
                _ => kind.is_some(),
            }))
        }
    }
}

/// What a `subprocess` call does with one output stream.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Stream {
    /// Inherited: appended to the script's own output.
    Inherit,
    Capture,
    Discard,
    /// `stderr=STDOUT`.
    ToStdout,
}

fn stream(v: Option<&Value>, what: &str) -> Result<Stream, ScriptError> {
    match v {
        None | Some(Value::None) => Ok(Stream::Inherit),
        Some(Value::Int(PIPE)) => Ok(Stream::Capture),
        Some(Value::Int(DEVNULL)) => Ok(Stream::Discard),
        Some(Value::Int(STDOUT)) if what == "stderr" => Ok(Stream::ToStdout),
        Some(_) => {
            Err(not_supported(format!("subprocess {what}= accepts only None, PIPE, DEVNULL (or STDOUT for stderr)")))
        }
    }
}

fn command_arg(v: &Value) -> Result<CommandArg, ScriptError> {
    match v {
        Value::Str(s) => Ok(CommandArg::Line(s.to_string())),
        Value::List(items) | Value::Tuple(items) => items
            .iter()
            .map(|item| match item {
                Value::Str(s) => Ok(s.to_string()),
                other => {
                    Err(type_error(format!("expected str, bytes or os.PathLike object, not {}", other.type_name())))
                }
            })
            .collect::<Result<Vec<_>, _>>()
            .map(CommandArg::Args),
        other => Err(type_error(format!("subprocess args must be a str or a list of str, not {}", other.type_name()))),
    }
}

pub(crate) fn called_process_error(
    cmd: &Value,
    code: i64,
    stdout: Option<String>,
    stderr: Option<String>,
) -> ScriptError {
    let _ = (stdout, stderr);
    ScriptError::new(
        ErrorKind::CalledProcess,
        format!("Command '{}' returned non-zero exit status {code}.", cmd.to_str()),
    )
}

fn subprocess(it: &mut Runtime<'_, '_>, name: &str, args: Args) -> Result<Value, ScriptError> {
    let mut pos = args.pos.into_iter();
    let Some(cmd_value) = pos.next() else {
        return Err(type_error(format!("{name}() missing 1 required positional argument: 'args'")));
    };
    if pos.next().is_some() {
        return Err(not_supported(format!("subprocess.{name}() accepts only the command as a positional argument")));
    }
    let command = command_arg(&cmd_value)?;
    let mut shell = false;
    let mut out_stream = None;
    let mut err_stream = None;
    let mut capture = false;
    let mut check = name.starts_with("check_");
    for (k, v) in &args.kw {
        match k.as_str() {
            "shell" => shell = v.truthy(),
            "stdout" => out_stream = Some(v.clone()),
            "stderr" => err_stream = Some(v.clone()),
            "capture_output" if name == "run" => capture = v.truthy(),
            "check" if name == "run" => check = v.truthy(),
            "text" | "universal_newlines" | "encoding" | "errors" | "timeout" | "creationflags" | "close_fds"
            | "bufsize" | "startupinfo" => {}
            "cwd" | "env" | "stdin" | "input" | "executable" | "preexec_fn" if matches!(v, Value::None) => {}
            other => return Err(not_supported(format!("subprocess.{name}({other}=...) is not supported"))),
        }
    }
    if name == "Popen" {
        let result = it.host.spawn_command(&command, shell);
        let pid = it.host(result)?;
        return Ok(Value::Object(Object::Popen { args: Box::new(cmd_value), pid: i64::from(pid) }));
    }
    let (mut out_mode, mut err_mode) = (stream(out_stream.as_ref(), "stdout")?, stream(err_stream.as_ref(), "stderr")?);
    if capture {
        if out_stream.is_some() || err_stream.is_some() {
            return Err(value_error("stdout and stderr arguments may not be used with capture_output."));
        }
        (out_mode, err_mode) = (Stream::Capture, Stream::Capture);
    }
    if name == "check_output" {
        out_mode = Stream::Capture;
    }
    let result = it.host.run_command(&command, shell);
    let CommandOutput { code, stdout, stderr } = it.host(result)?;
    let (mut captured_out, mut captured_err) = (None, None);
    let mut stdout = stdout;
    if err_mode == Stream::ToStdout {
        stdout.push_str(&stderr);
    }
    match out_mode {
        Stream::Inherit => it.out.stdout.push_str(&stdout),
        Stream::Capture => captured_out = Some(stdout),
        Stream::Discard | Stream::ToStdout => {}
    }
    match err_mode {
        Stream::Inherit => it.out.stderr.push_str(&stderr),
        Stream::Capture => captured_err = Some(stderr),
        Stream::Discard | Stream::ToStdout => {}
    }
    let code = i64::from(code);
    if check && code != 0 {
        return Err(called_process_error(&cmd_value, code, captured_out, captured_err));
    }
    Ok(match name {
        "run" => Value::Object(Object::Completed {
            args: Box::new(cmd_value),
            returncode: code,
            stdout: captured_out,
            stderr: captured_err,
        }),
        "check_output" => Value::str(captured_out.unwrap_or_default()),
        "check_call" => Value::Int(0),
        _ => Value::Int(code),
    })
}
