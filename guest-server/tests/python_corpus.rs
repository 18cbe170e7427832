//! The guest runs the Python that WAA hosts send without a Python: every `python -c`
//! command of the upstream corpus (config and post-config), every action string the
//! upstream host generates (waa-api.md §b.6), the evaluator getters' programs (§b.2)
//! and Navi's `computer.*` code for `/execute_windows` (§c) go through the real router
//! (`tower::ServiceExt::oneshot`) against the stub, and their effects on the stub are
//! asserted. Code outside the interpreter's subset must fail loudly, naming the construct.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use axum::body::Body;
use axum::http::{header, Method, Request, StatusCode};
use axum::Router;
use base64::Engine as _;
use http_body_util::BodyExt as _;
use serde_json::{json, Value};
use tower::ServiceExt as _;

use arena_guest::config::ServerConfig;
use arena_guest::desktop::stub::{Scenario, StubConfig, StubDesktop};
use arena_guest::desktop::{ClipboardData, Desktop};
use arena_guest::state::AppState;
use arena_script::{python_code_from_argv, python_code_from_command_line};
use arena_shared::action::{Action, MouseButton};
use arena_shared::cmdline::{shlex_split, truthy};
use arena_shared::geometry::Point;

/// The upstream host's prefix for every `python -c` command (waa-api.md §b.2).
const PREFIX: &str = "import pyautogui; import time; pyautogui.FAILSAFE = False; ";

/// A router over a fresh stub whose drives live in a temporary directory.
struct App {
    router: Router,
    stub: Arc<StubDesktop>,
    _dir: tempfile::TempDir,
}

impl App {
    fn new(scenario: Value, config: ServerConfig) -> App {
        let scenario =
            Scenario::parse(&scenario.to_string(), "test").unwrap_or_else(|err| panic!("test scenario: {err}"));
        let dir = tempfile::tempdir().expect("temp dir");
        let config_stub = StubConfig {
            root: Some(dir.path().into()),
            screen: (1440, 900),
            scenario: Some(scenario),
            host_exec: true,
            ..StubConfig::default()
        };
        let stub = Arc::new(StubDesktop::with_config(config_stub).expect("stub desktop"));
        let state = AppState::new(stub.clone(), config, None);
        App { router: arena_guest::router(state), stub, _dir: dir }
    }

    fn with(scenario: Value) -> App {
        App::new(scenario, ServerConfig::for_stub())
    }

    async fn request(&self, method: Method, path: &str, body: Option<Value>) -> (StatusCode, Value) {
        let mut request = Request::builder().method(method).uri(path);
        if body.is_some() {
            request = request.header(header::CONTENT_TYPE, "application/json");
        }
        let body = body.map_or_else(Body::empty, |b| Body::from(b.to_string()));
        let response =
            self.router.clone().oneshot(request.body(body).expect("request")).await.expect("infallible router");
        let status = response.status();
        let bytes = response.into_body().collect().await.expect("body").to_bytes();
        let value = serde_json::from_slice(&bytes)
            .unwrap_or_else(|err| panic!("status {status}: {:?} is not JSON: {err}", String::from_utf8_lossy(&bytes)));
        (status, value)
    }

    async fn post(&self, path: &str, body: Value) -> (StatusCode, Value) {
        self.request(Method::POST, path, Some(body)).await
    }

    /// `POST /execute` of `["python", "-c", code]`, as the upstream host sends it.
    async fn python(&self, code: &str) -> (StatusCode, Value) {
        self.post("/execute", json!({"command": ["python", "-c", code], "shell": false})).await
    }

    /// Asserts a 200 success with exactly this output, error text and exit code.
    async fn python_ok(&self, code: &str, output: &str, error: &str, returncode: i64) {
        let (status, body) = self.python(code).await;
        assert_eq!(status, StatusCode::OK, "{code}: {body}");
        assert_eq!(
            body,
            json!({"status": "success", "output": output, "error": error, "returncode": returncode}),
            "{code}"
        );
    }

    fn focused_title(&self) -> Option<String> {
        self.stub.windows().expect("windows").into_iter().find(|w| w.focused).map(|w| w.title)
    }

    fn local(&self, guest: &str) -> PathBuf {
        self.stub.map_path(guest).expect("mappable guest path")
    }
}

fn notepad_scenario() -> Value {
    json!({"windows": [{"title": "notes.txt - Notepad", "process_name": "notepad.exe", "text": "", "focused": true}]})
}

fn paint_scenario() -> Value {
    json!({"windows": [
        {"title": "Untitled - Paint", "process_name": "mspaint.exe", "class_name": "MSPaintApp", "focused": true},
        {"title": "notes.txt - Notepad", "process_name": "notepad.exe", "text": ""},
    ]})
}

fn click(x: i32, y: i32) -> Action {
    Action::Click { x: Some(x), y: Some(y), button: MouseButton::Left, count: 1 }
}

fn here_click() -> Action {
    Action::Click { x: None, y: None, button: MouseButton::Left, count: 1 }
}

fn key(k: &str) -> Action {
    Action::KeyPress { key: k.to_owned(), presses: 1 }
}

fn hotkey(keys: &[&str]) -> Action {
    Action::Hotkey { keys: keys.iter().map(|k| (*k).to_owned()).collect() }
}

fn typed(text: &str) -> Action {
    Action::TypeText { text: text.to_owned(), interval_ms: None }
}

// ----- the upstream corpus -----

/// One `execute`/`command` step of the corpus that runs Python.
#[derive(Debug, Clone)]
struct CorpusCommand {
    origin: String,
    /// The request body the host sends: the step's `command` and `shell`.
    body: Value,
    code: String,
}

fn json_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let entries = std::fs::read_dir(dir).unwrap_or_else(|err| panic!("reading {}: {err}", dir.display()));
    for entry in entries {
        let path = entry.expect("directory entry").path();
        if path.is_dir() {
            json_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "json") {
            out.push(path);
        }
    }
}

/// The code of a step's command when it is a Python invocation, following the route:
/// a string without a shell is split with POSIX shlex first.
fn step_code(command: &Value, shell: bool) -> Option<String> {
    let strings =
        |items: &[Value]| items.iter().map(|v| v.as_str().map(str::to_owned)).collect::<Option<Vec<String>>>();
    match (command, shell) {
        (Value::Array(items), false) => python_code_from_argv(&strings(items)?).map(str::to_owned),
        (Value::Array(items), true) => {
            python_code_from_command_line(&arena_shared::cmdline::list2cmdline(&strings(items)?))
        }
        (Value::String(line), true) => python_code_from_command_line(line),
        (Value::String(line), false) => python_code_from_argv(&shlex_split(line).ok()?).map(str::to_owned),
        _ => None,
    }
}

/// The corpus's Python commands, or `None` after a loud, counted skip.
fn corpus_commands(test: &str) -> Option<Vec<CorpusCommand>> {
    let dir = arena_test_support::waa_corpus(test)?;
    let mut files = Vec::new();
    json_files(&dir, &mut files);
    files.sort();
    let mut commands = Vec::new();
    for file in files {
        let text = std::fs::read_to_string(&file).unwrap_or_else(|err| panic!("reading {}: {err}", file.display()));
        let task: Value = serde_json::from_str(&text).unwrap_or_else(|err| panic!("{}: {err}", file.display()));
        let config = task.get("config").and_then(Value::as_array).cloned().unwrap_or_default();
        let postconfig = task.pointer("/evaluator/postconfig").and_then(Value::as_array).cloned().unwrap_or_default();
        for (place, steps) in [("config", config), ("postconfig", postconfig)] {
            for (i, step) in steps.iter().enumerate() {
                if !matches!(step.get("type").and_then(Value::as_str), Some("execute" | "command")) {
                    continue;
                }
                let params = step.get("parameters").cloned().unwrap_or(Value::Null);
                let command = params.get("command").cloned().unwrap_or(Value::Null);
                let shell = params.get("shell").cloned().unwrap_or(Value::Bool(false));
                if let Some(code) = step_code(&command, truthy(&shell)) {
                    let origin = format!("{} {place}[{i}]", file.strip_prefix(&dir).unwrap_or(&file).display());
                    commands.push(CorpusCommand { origin, body: json!({"command": command, "shell": shell}), code });
                }
            }
        }
    }
    Some(commands)
}

/// Runs one corpus command on a fresh stub and asserts its effects; returns whether it
/// was handled natively (a 200 success rather than a refusal).
async fn run_corpus_command(cmd: CorpusCommand) -> bool {
    let code = cmd.code.as_str();
    let scenario = if code.contains("mspaint") { paint_scenario() } else { notepad_scenario() };
    let app = App::with(scenario);
    let (status, body) = app.post("/setup/execute", cmd.body.clone()).await;
    if status != StatusCode::OK || body["status"] != json!("success") {
        eprintln!("NOT handled natively: {}: {code}\n  -> {status} {body}", cmd.origin);
        return false;
    }
    let log = app.stub.action_log();
    let at = &cmd.origin;
    // How many of the effects below this command has: each command must have one.
    let checked = std::cell::Cell::new(0);
    let expect = |needle: &str, action: Action| {
        if code.contains(needle) {
            checked.set(checked.get() + 1);
            assert!(log.contains(&action), "{at}: {code}\n  expected {action:?} in {log:?}");
        }
    };
    expect("hotkey('ctrl', 's')", hotkey(&["ctrl", "s"]));
    expect("hotkey('alt', 'f10')", hotkey(&["alt", "f10"]));
    expect("click(960, 540)", click(960, 540));
    expect("click(500, 500)", click(500, 500));
    expect("press('f11')", key("f11"));
    expect("press('enter')", key("enter"));
    expect("typewrite(", typed(r#""C:\Users\Docker\Downloads\CanvasSize.png""#));
    let output = body["output"].as_str().unwrap_or_default();
    if code.contains("screenshot.save(") {
        let file = app.local(r"C:\Users\Docker\Downloads\Screenshot.png");
        let bytes = std::fs::read(&file)
            .unwrap_or_else(|err| panic!("{at}: the screenshot {} was not written: {err}", file.display()));
        assert!(bytes.starts_with(b"\x89PNG\r\n\x1a\n"), "{at}: the screenshot is not a PNG");
        assert_eq!(output, "<class 'PIL.Image.Image'>\n", "{at}");
        checked.set(checked.get() + 1);
    } else {
        assert_eq!(output, "", "{at}");
    }
    assert!(checked.get() > 0, "{at}: the test knows no effect of {code}");
    let error = body["error"].as_str().unwrap_or_default();
    if code.contains("taskkill") && !cfg!(windows) {
        // The stub runs unknown programs as host processes, and this host has no
        // taskkill: Python would stop there too, after every earlier effect.
        assert_eq!(body["returncode"], json!(1), "{at}: {body}");
        assert!(
            error.starts_with("Traceback (most recent call last):\n  File \"<string>\", line 1, in <module>\n"),
            "{at}: {error}"
        );
        assert!(error.contains("[WinError 2] The system cannot find the file specified"), "{at}: {error}");
    } else {
        assert_eq!((body["returncode"].clone(), error), (json!(0), ""), "{at}: {body}");
    }
    true
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn every_corpus_python_command_runs_natively() {
    let Some(commands) = corpus_commands("python_corpus::every_corpus_python_command_runs_natively") else { return };
    let total = commands.len();
    assert!(total >= 100, "expected the corpus's python -c commands (126), found {total}");
    // The commands sleep 0.5 to 5 s each (their own `time.sleep`s); each gets its own
    // stub and they run side by side.
    let mut tasks = tokio::task::JoinSet::new();
    for cmd in commands {
        tasks.spawn(run_corpus_command(cmd));
    }
    let mut handled = 0;
    while let Some(result) = tasks.join_next().await {
        match result {
            Ok(true) => handled += 1,
            Ok(false) => {}
            Err(err) => std::panic::resume_unwind(err.into_panic()),
        }
    }
    println!("natively handled: {handled} of {total} corpus python commands");
    assert_eq!(handled, total, "natively handled: {handled} of {total} corpus python commands");
}

// ----- the upstream host's action strings (waa-api.md §b.6) -----

#[tokio::test]
async fn computer_13_templates_and_code_blocks_run_natively() {
    let check = |code: &'static str, expected: Vec<Action>| async move {
        let app = App::with(notepad_scenario());
        app.python_ok(&format!("{PREFIX}{code}"), "", "", 0).await;
        assert_eq!(app.stub.action_log(), expected, "{code}");
    };
    let left = MouseButton::Left;
    check("pyautogui.moveTo(100, 200, 0.7, pyautogui.easeInQuad)", vec![Action::MoveTo { x: 100, y: 200 }]).await;
    check("pyautogui.click(x=300, y=400)", vec![click(300, 400)]).await;
    check(
        "pyautogui.click(button='right', x=300, y=400, clicks=2)",
        vec![Action::Click { x: Some(300), y: Some(400), button: MouseButton::Right, count: 2 }],
    )
    .await;
    check("pyautogui.click()", vec![here_click()]).await;
    check("pyautogui.mouseDown(button='left')", vec![Action::MouseDown { button: left, x: None, y: None }]).await;
    check("pyautogui.mouseUp(button='left')", vec![Action::MouseUp { button: left, x: None, y: None }]).await;
    check("pyautogui.rightClick(x=10, y=20)", vec![Action::RightClick { x: Some(10), y: Some(20) }]).await;
    check("pyautogui.doubleClick(x=10, y=20)", vec![Action::DoubleClick { x: Some(10), y: Some(20) }]).await;
    check(
        "pyautogui.dragTo(500, 400, duration=1.0, button='left', mouseDownUp=True)",
        vec![Action::Drag { from: None, to: Point::new(500, 400), button: left, duration_ms: Some(1000) }],
    )
    .await;
    check("pyautogui.hscroll(-120)", vec![Action::Scroll { x: None, y: None, dx: -120, dy: 0 }]).await;
    check("pyautogui.vscroll(240)", vec![Action::Scroll { x: None, y: None, dx: 0, dy: 240 }]).await;
    check("pyautogui.typewrite('hello world')", vec![typed("hello world")]).await;
    check("pyautogui.press('enter')", vec![key("enter")]).await;
    check("pyautogui.keyDown('shift')", vec![Action::KeyDown { key: "shift".into() }]).await;
    check("pyautogui.keyUp('shift')", vec![Action::KeyUp { key: "shift".into() }]).await;
    check("pyautogui.hotkey('ctrl', 'c')", vec![hotkey(&["ctrl", "c"])]).await;
    // A code_block action: several statements after the prefix.
    check("pyautogui.click(x=100, y=200)\npyautogui.typewrite('abc')", vec![click(100, 200), typed("abc")]).await;
}

#[tokio::test]
async fn typing_reaches_the_focused_window() {
    let app = App::with(notepad_scenario());
    app.python_ok(&format!("{PREFIX}pyautogui.typewrite('hello'); pyautogui.press('enter')"), "", "", 0).await;
    let id = app.stub.find_window("notes.txt").expect("notepad window");
    assert_eq!(app.stub.window_text(id).as_deref(), Some("hello\n"));
}

// ----- the evaluator getters' programs (waa-api.md §b.2, §d.3) -----

#[tokio::test]
async fn getter_programs_print_what_python_would() {
    let app = App::with(notepad_scenario());
    app.python_ok(&format!("{PREFIX}import platform; print(platform.system())"), "Windows\n", "", 0).await;
    app.python_ok(
        &format!(r"{PREFIX}import os; print(os.path.join(os.getenv('LOCALAPPDATA'), 'Google\\Chrome\\User Data\\Default\\Preferences'))"),
        "C:\\Users\\Docker\\AppData\\Local\\Google\\Chrome\\User Data\\Default\\Preferences\n",
        "",
        0,
    )
    .await;
    app.python_ok(&format!("{PREFIX}print(pyautogui.getActiveWindowTitle())"), "notes.txt - Notepad\n", "", 0).await;
    app.python_ok(
        &format!(r"{PREFIX}import os; print(os.path.exists(r'C:\Users\Docker\Desktop'), os.path.isfile(r'C:\Users\Docker\nope.txt'))"),
        "True False\n",
        "",
        0,
    )
    .await;
    app.python_ok("import pyautogui; print(pyautogui.size())", "Size(width=1440, height=900)\n", "", 0).await;
}

const HIDDEN_GETTER: &str = r"import os; print(1 if os.path.basename(r'C:\Users\Docker\Desktop\a.txt').startswith('.') or (os.name == 'nt' and bool(os.stat(r'C:\Users\Docker\Desktop\a.txt').st_file_attributes & 2)) else 0)";

#[tokio::test]
async fn the_hidden_file_getter_is_refused_loudly_without_a_python() {
    let app = App::with(json!({}));
    let code = format!("{PREFIX}{HIDDEN_GETTER}");
    let (status, body) = app.python(&code).await;
    assert_eq!(status, StatusCode::INTERNAL_SERVER_ERROR, "{body}");
    assert_eq!(body["status"], json!("error"));
    assert!(body.get("output").is_none(), "upstream's error shape has no output: {body}");
    let message = body["message"].as_str().unwrap_or_default();
    // The conditional expression and boolean logic run; `os.stat` is what the interpreter lacks.
    assert!(
        message.starts_with("unsupported Python at line 1: AttributeError: module 'os' has no attribute 'stat'"),
        "{message}"
    );
    assert!(message.contains("--python"), "{message}");
}

#[cfg(unix)]
#[tokio::test]
async fn code_outside_the_subset_runs_with_a_configured_python() {
    use std::os::unix::fs::PermissionsExt as _;
    let bin = tempfile::tempdir().expect("temp dir");
    let fake = bin.path().join("fake-python");
    std::fs::write(&fake, "#!/bin/sh\necho \"real python ran: $1\"\n").expect("write");
    std::fs::set_permissions(&fake, std::fs::Permissions::from_mode(0o755)).expect("chmod");
    let mut config = ServerConfig::for_stub();
    config.python = Some(fake.clone());
    let app = App::new(json!({}), config);
    let (status, body) = app.python(HIDDEN_GETTER).await;
    assert_eq!(status, StatusCode::OK, "{body}");
    assert_eq!(body["output"], json!("real python ran: -c\n"));
    // Supported code still runs natively, never through the configured program.
    app.python_ok("print(2)", "2\n", "", 0).await;
    // A configured program that does not exist counts as no Python.
    let mut config = ServerConfig::for_stub();
    config.python = Some(bin.path().join("missing-python"));
    let (status, body) = App::new(json!({}), config).python(HIDDEN_GETTER).await;
    assert_eq!(status, StatusCode::INTERNAL_SERVER_ERROR, "{body}");
}

// ----- how /execute answers -----

#[tokio::test]
async fn exceptions_answer_like_a_python_process_that_died() {
    let app = App::with(json!({}));
    app.python_ok(
        "print('a')\nx = 1\nundefined_name",
        "a\n",
        "Traceback (most recent call last):\n  File \"<string>\", line 3, in <module>\nNameError: name 'undefined_name' is not defined\n",
        1,
    )
    .await;
    app.python_ok("import sys; print('bye'); sys.exit(3)", "bye\n", "", 3).await;
}

#[tokio::test]
async fn every_spelling_of_a_python_invocation_is_recognised() {
    let app = App::with(notepad_scenario());
    let check = |body: Value, output: &'static str| {
        let app = &app;
        async move {
            let (status, answer) = app.post("/execute", body.clone()).await;
            assert_eq!(status, StatusCode::OK, "{body}: {answer}");
            assert_eq!(answer, json!({"status": "success", "output": output, "error": "", "returncode": 0}), "{body}");
        }
    };
    check(json!({"command": "python -c \"print('shlex')\""}), "shlex\n").await;
    check(json!({"command": "python3 -c \"print('shell')\"", "shell": "true"}), "shell\n").await;
    check(json!({"command": ["py", "-3", "-c", "print('launcher')"]}), "launcher\n").await;
    check(json!({"command": [r"C:\Python310\python.exe", "-u", "-c", "print('full path')"]}), "full path\n").await;
    check(json!({"command": ["python", "-c", "import pyautogui; pyautogui.press('f11')"], "shell": true}), "").await;
    assert_eq!(app.stub.action_log(), vec![key("f11")]);
}

#[tokio::test]
async fn unsupported_code_after_an_effect_is_not_rerun() {
    let app = App::with(json!({}));
    let (status, body) = app.python("import pyautogui; pyautogui.click(5, 6); import numpy").await;
    assert_eq!(status, StatusCode::INTERNAL_SERVER_ERROR, "{body}");
    let message = body["message"].as_str().unwrap_or_default();
    assert!(message.contains("No module named 'numpy'") && message.contains("after 1 action(s)"), "{message}");
    assert_eq!(app.stub.action_log(), vec![click(5, 6)]);
}

#[tokio::test]
async fn a_sleep_past_the_timeout_answers_pythons_timeout_text() {
    let mut config = ServerConfig::for_stub();
    config.exec_timeout_ms = 300;
    let app = App::new(json!({}), config);
    let (status, body) = app.python("import time; time.sleep(5)").await;
    assert_eq!(status, StatusCode::INTERNAL_SERVER_ERROR, "{body}");
    // Python's own words first, then why it came at once (docs/compatibility.md).
    let message = body["message"].as_str().unwrap_or_default();
    let python = "Command '['python', '-c', 'import time; time.sleep(5)']' timed out after 0.3 seconds";
    assert!(message.starts_with(python), "{message}");
    assert!(message[python.len()..].contains("would outlast"), "{message}");
}

// ----- /execute_windows (Navi's computer.* code, waa-api.md §c) -----

fn png_b64(width: u32, height: u32) -> String {
    let img = image::RgbaImage::from_fn(width, height, |x, y| image::Rgba([(x % 256) as u8, (y % 256) as u8, 7, 255]));
    let mut bytes = Vec::new();
    image::DynamicImage::ImageRgba8(img)
        .write_to(&mut std::io::Cursor::new(&mut bytes), image::ImageFormat::Png)
        .expect("png");
    base64::engine::general_purpose::STANDARD.encode(bytes)
}

/// A stub with Paint focused over Notepad and an `/update_computer` state with two elements.
async fn computer_app() -> App {
    let app = App::with(paint_scenario());
    let update = json!({
        "rects": [[0, 0, 10, 10], [100, 100, 200, 300]], "window_rect": [0, 0, 1440, 900],
        "screenshot": png_b64(400, 400), "scale": [1.0, 1.0], "clipboard_content": null, "swap_ctrl_alt": false,
    });
    assert_eq!(app.post("/update_computer", update).await, (StatusCode::OK, json!({"success": true})));
    app
}

async fn windows_code(app: &App, code: &str) -> (StatusCode, Value) {
    app.post("/execute_windows", json!({"command": code})).await
}

async fn windows_ok(app: &App, code: &str) {
    assert_eq!(windows_code(app, code).await, (StatusCode::OK, json!({"status": "success"})), "{code}");
}

#[tokio::test]
async fn computer_mouse_and_keyboard_act_on_the_desktop() {
    let app = computer_app().await;
    windows_ok(&app, "computer.mouse.move_id(id=1)\ncomputer.mouse.single_click()").await;
    windows_ok(&app, "# the element is remembered between calls\ncomputer.mouse.move_id(computer.mouse.current_id)")
        .await;
    windows_ok(
        &app,
        "computer.keyboard.write('hi'); computer.keyboard.press('ctrl+shift+s'); computer.keyboard.press('enter')",
    )
    .await;
    windows_ok(&app, "computer.mouse.drag(500, 400)\ncomputer.mouse.drag(x=0.5, y=0.25)").await;
    windows_ok(&app, "computer.mouse.move_abs(x=0.1, y=0.2); computer.mouse.scroll(dir='up')").await;
    let left = MouseButton::Left;
    assert_eq!(
        app.stub.action_log(),
        vec![
            Action::MoveTo { x: 150, y: 200 },
            here_click(),
            Action::MoveTo { x: 150, y: 200 },
            typed("hi"),
            hotkey(&["ctrl", "shift", "s"]),
            key("enter"),
            Action::Drag { from: None, to: Point::new(500, 400), button: left, duration_ms: Some(1000) },
            Action::Drag { from: None, to: Point::new(720, 225), button: left, duration_ms: Some(1000) },
            Action::MoveTo { x: 144, y: 180 },
            Action::Scroll { x: None, y: None, dx: 0, dy: 400 },
        ]
    );
}

#[tokio::test]
async fn computer_clipboard_is_reported_by_obs_winagent() {
    let app = computer_app().await;
    windows_ok(&app, "computer.clipboard.copy_text('copied words')").await;
    let (_, obs) = app.request(Method::GET, "/obs_winagent", None).await;
    assert_eq!(obs["computer_clipboard"], json!("copied words"));
    assert_eq!(app.stub.clipboard_get().expect("clipboard"), ClipboardData::Text("copied words".into()));
    windows_ok(&app, "computer.clipboard.copy_image(id=1, description='a chart')").await;
    let (_, obs) = app.request(Method::GET, "/obs_winagent", None).await;
    assert_eq!(obs["computer_clipboard"], json!("a chart"));
    match app.stub.clipboard_get().expect("clipboard") {
        ClipboardData::Image(image) => {
            assert_eq!(image.dimensions(), (100, 200));
            assert_eq!(image.get_pixel(0, 0).0, [100, 100, 7, 255]);
        }
        other => panic!("expected the cropped image on the clipboard, got {other:?}"),
    }
    // A new /update_computer replaces what the code set.
    let update = json!({"screenshot": png_b64(4, 4), "clipboard_content": "fresh"});
    app.post("/update_computer", update).await;
    let (_, obs) = app.request(Method::GET, "/obs_winagent", None).await;
    assert_eq!(obs["computer_clipboard"], json!("fresh"));
}

#[tokio::test]
async fn computer_os_and_window_manager_open_and_switch_windows() {
    let app = computer_app().await;
    windows_ok(&app, "computer.window_manager.switch_to_application('notes.txt - Notepad')").await;
    assert_eq!(app.focused_title().as_deref(), Some("notes.txt - Notepad"));
    windows_ok(&app, "computer.os.open_program('calc')").await;
    assert_eq!(app.focused_title().as_deref(), Some("Calculator"));
    let calc = app.stub.windows().expect("windows").into_iter().find(|w| w.title == "Calculator").expect("calc");
    assert!(calc.maximized, "open_program maximizes the new window");
}

#[tokio::test]
async fn printed_errors_and_exceptions_fail_like_upstream() {
    let app = computer_app().await;
    // Q8: printed text containing "error" fails the call after its effects.
    let (status, body) = windows_code(&app, "computer.clipboard.copy_text('an Error here')").await;
    assert_eq!(
        (status, body),
        (StatusCode::INTERNAL_SERVER_ERROR, json!({"status": "error", "message": "an Error here\n"}))
    );
    assert_eq!(app.stub.clipboard_get().expect("clipboard"), ClipboardData::Text("an Error here".into()));
    let (status, body) = windows_code(&app, "computer.os.open_program('arena-no-such-program')").await;
    assert_eq!(
        (status, body),
        (
            StatusCode::INTERNAL_SERVER_ERROR,
            json!({"status": "error", "message": "error: Program arena-no-such-program is not installed\n"})
        )
    );
    // An exception answers with str(e).
    let (status, body) = windows_code(&app, "computer.mouse.move_id(id=7)").await;
    assert_eq!(
        (status, body),
        (StatusCode::INTERNAL_SERVER_ERROR, json!({"status": "error", "message": "list index out of range"}))
    );
}

#[tokio::test]
async fn unsupported_computer_code_is_refused_naming_the_construct() {
    let app = computer_app().await;
    let (status, body) = windows_code(&app, "computer.mouse.single_click()\nclass A:\n    pass").await;
    assert_eq!(status, StatusCode::INTERNAL_SERVER_ERROR, "{body}");
    assert_eq!(
        body["message"],
        json!("unsupported Python at line 2, column 1: class definitions (`class`) are not supported")
    );
    assert!(app.stub.action_log().is_empty(), "nothing runs when the code does not parse");
    let (status, body) = windows_code(&app, "human.ask_question('ok?')").await;
    assert_eq!(status, StatusCode::INTERNAL_SERVER_ERROR, "{body}");
    assert!(body["message"].as_str().unwrap_or_default().contains("human.ask_question is not supported"), "{body}");
}
