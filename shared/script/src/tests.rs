//! End-to-end tests of the interpreter: the WAA corpus programs, the upstream
//! host's getters and computer_13 templates, the `Computer` object, literal
//! forms, precise errors, and property tests for the parser.

use std::collections::HashMap;

use super::*;
use arena_shared::action::{Action, MouseButton};
use arena_shared::geometry::Point;

/// A scripted host: it records actions (sleeps as `Wait`) and every other effect.
#[derive(Debug)]
pub(crate) struct FakeHost {
    pub(crate) actions: Vec<Action>,
    calls: Vec<String>,
    cursor: (i32, i32),
    screen: (u32, u32),
    env: HashMap<String, String>,
    /// Titles of unfocused windows, topmost first (ids 1, 2, ...).
    windows: Vec<String>,
    /// The focused window's title (id 100); none when empty.
    active_title: String,
    /// Programs with an `App Paths` entry.
    installed: Vec<String>,
    /// Programs that do not exist at all.
    missing: Vec<String>,
    paths: Vec<(String, PathKind)>,
    command: CommandOutput,
    clipboard: String,
}

impl FakeHost {
    pub(crate) fn new() -> FakeHost {
        let env = [
            ("USERPROFILE", r"C:\Users\Docker"),
            ("USERNAME", "Docker"),
            ("LOCALAPPDATA", r"C:\Users\Docker\AppData\Local"),
            ("COMPUTERNAME", "WAA-VM"),
        ];
        FakeHost {
            actions: Vec::new(),
            calls: Vec::new(),
            cursor: (10, 20),
            screen: (1440, 900),
            env: env.iter().map(|(k, v)| ((*k).to_owned(), (*v).to_owned())).collect(),
            windows: Vec::new(),
            active_title: "Untitled - Paint".to_owned(),
            installed: vec!["msedge".to_owned(), "notepad".to_owned()],
            missing: vec!["gimp".to_owned()],
            paths: vec![
                (r"C:\Users\Docker\Desktop".to_owned(), PathKind::Dir),
                (r"C:\Users\Docker\Downloads".to_owned(), PathKind::Dir),
                (r"C:\x.txt".to_owned(), PathKind::File),
            ],
            command: CommandOutput { code: 0, stdout: String::new(), stderr: String::new() },
            clipboard: "clip".to_owned(),
        }
    }
}

impl ScriptHost for FakeHost {
    fn perform(&mut self, action: Action) -> HostResult<()> {
        self.cursor = host::cursor_after(&action, self.cursor);
        self.actions.push(action);
        Ok(())
    }
    fn sleep(&mut self, seconds: f64) -> HostResult<()> {
        self.actions.push(Action::Wait { ms: (seconds * 1000.0).round() as u64 });
        Ok(())
    }
    fn cursor_position(&mut self) -> HostResult<(i32, i32)> {
        Ok(self.cursor)
    }
    fn screen_size(&mut self) -> HostResult<(u32, u32)> {
        Ok(self.screen)
    }
    fn capture(&mut self) -> HostResult<image::RgbaImage> {
        Ok(image::RgbaImage::new(self.screen.0, self.screen.1))
    }
    fn observed_screenshot(&mut self) -> HostResult<image::RgbaImage> {
        self.capture()
    }
    fn windows(&mut self) -> HostResult<Vec<arena_shared::observation::WindowInfo>> {
        let window = |id: u64, title: &str, z_order: u32, focused: bool| arena_shared::observation::WindowInfo {
            id,
            title: title.to_owned(),
            class_name: "C".to_owned(),
            process_id: 1,
            process_name: "p.exe".to_owned(),
            rect: arena_shared::geometry::Rect::new(0, 0, 10, 10),
            visible: true,
            minimized: false,
            maximized: false,
            focused,
            z_order,
        };
        let mut out: Vec<_> = (1..).zip(&self.windows).map(|(id, t)| window(id, t, id as u32 + 1, false)).collect();
        if !self.active_title.is_empty() {
            out.push(window(100, &self.active_title, 0, true));
        }
        Ok(out)
    }
    fn change_window(&mut self, id: u64, change: WindowChange) -> HostResult<()> {
        self.calls.push(format!("change_window {id} {change:?}"));
        Ok(())
    }
    fn path_kind(&mut self, path: &str) -> Option<PathKind> {
        self.paths.iter().find(|(p, _)| p.eq_ignore_ascii_case(path)).map(|(_, k)| *k)
    }
    fn list_dir(&mut self, path: &str) -> HostResult<Vec<String>> {
        self.calls.push(format!("list_dir {path}"));
        Ok(vec!["a.txt".to_owned(), "b".to_owned()])
    }
    fn write_file(&mut self, path: &str, bytes: Vec<u8>) -> HostResult<()> {
        assert!(!bytes.is_empty(), "an encoded image");
        self.calls.push(format!("write_file {path}"));
        Ok(())
    }
    fn run(&mut self, command: &arena_shared::cmdline::CommandSpec) -> HostResult<CommandOutput> {
        self.calls.push(format!("run {command:?}"));
        Ok(self.command.clone())
    }
    fn launch(&mut self, command: &arena_shared::cmdline::CommandSpec) -> HostResult<Option<u32>> {
        if let arena_shared::cmdline::CommandSpec::Argv(argv) = command {
            if self.missing.contains(&argv[0]) {
                return Ok(None);
            }
        }
        self.calls.push(format!("launch {command:?}"));
        Ok(Some(4242))
    }
    fn registry_read(
        &mut self,
        key: &str,
        value: Option<&str>,
    ) -> HostResult<Option<arena_shared::registry::RegistryValue>> {
        use arena_shared::registry::RegistryValue;
        if key == compose::CURRENT_VERSION {
            return Ok(match value {
                Some("CurrentMajorVersionNumber") => Some(RegistryValue::Dword(10)),
                Some("CurrentMinorVersionNumber") => Some(RegistryValue::Qword(0)),
                Some("CurrentBuildNumber") => Some(RegistryValue::String("22631".to_owned())),
                _ => None,
            });
        }
        let installed = self.installed.iter().any(|p| key == format!(r"{}\{p}.exe", compose::APP_PATHS[0]));
        Ok(installed.then(|| RegistryValue::String(format!(r"C:\Program Files\{key}"))))
    }
    fn clipboard_set_text(&mut self, text: &str) -> HostResult<()> {
        self.calls.push(format!("clipboard_set_text {text}"));
        self.clipboard = text.to_owned();
        Ok(())
    }
    fn clipboard_get_text(&mut self) -> HostResult<String> {
        Ok(self.clipboard.clone())
    }
    fn clipboard_set_image(&mut self, image: image::RgbaImage) -> HostResult<()> {
        self.calls.push(format!("clipboard_set_image {}x{}", image.width(), image.height()));
        Ok(())
    }
    fn env_var(&mut self, name: &str) -> Option<String> {
        self.env.iter().find(|(k, _)| k.eq_ignore_ascii_case(name)).map(|(_, v)| v.clone())
    }
}

fn run_python(host: &mut FakeHost, src: &str) -> Result<RunOutput, ScriptError> {
    run_source(src, host, Globals::python())
}

/// Runs `src` as `python -c` and returns (actions, stdout, other host calls).
fn python(src: &str) -> (Vec<Action>, String, Vec<String>) {
    let mut host = FakeHost::new();
    let out = run_python(&mut host, src).unwrap_or_else(|e| panic!("{src}\n{e}\n{}", e.traceback()));
    (host.actions, out.stdout, host.calls)
}

fn python_err(src: &str) -> String {
    let mut host = FakeHost::new();
    match run_python(&mut host, src) {
        Ok(out) => panic!("{src} should fail, printed {:?}", out.stdout),
        Err(e) => e.to_string(),
    }
}

fn wait(ms: u64) -> Action {
    Action::Wait { ms }
}

fn key(k: &str) -> Action {
    Action::KeyPress { key: k.to_owned(), presses: 1 }
}

fn hotkey(keys: &[&str]) -> Action {
    Action::Hotkey { keys: keys.iter().map(|k| (*k).to_owned()).collect() }
}

fn text(t: &str) -> Action {
    Action::TypeText { text: t.to_owned(), interval_ms: None }
}

fn click_at(x: i32, y: i32) -> Action {
    Action::Click { x: Some(x), y: Some(y), button: MouseButton::Left, count: 1 }
}

// ---- The corpus -------------------------------------------------------------------------

#[test]
fn corpus_save_hotkeys() {
    let check = |src: &str, expected: &[Action]| {
        let (actions, stdout, calls) = python(src);
        assert_eq!(actions, expected, "{src}");
        assert_eq!(stdout, "", "{src}");
        assert!(calls.is_empty(), "{src}: {calls:?}");
    };
    check("import pyautogui; pyautogui.hotkey('ctrl', 's');", &[hotkey(&["ctrl", "s"])]);
    check(
        "import pyautogui; import time; pyautogui.hotkey('ctrl', 's'); time.sleep(0.5);",
        &[hotkey(&["ctrl", "s"]), wait(500)],
    );
    check(
        "import pyautogui; import time; pyautogui.hotkey('ctrl', 's'); time.sleep(0.5);;",
        &[hotkey(&["ctrl", "s"]), wait(500)],
    );
    check(
        "import pyautogui; import time; pyautogui.click(960, 540); time.sleep(0.5);",
        &[click_at(960, 540), wait(500)],
    );
    check(
        "import pyautogui; import time; pyautogui.hotkey('alt', 'f10'); time.sleep(0.5);",
        &[hotkey(&["alt", "f10"]), wait(500)],
    );
    check("import pyautogui; pyautogui.press('f11');", &[key("f11")]);
}

#[test]
fn corpus_paint_save_and_kill() {
    let src = r#"import pyautogui; import time; from PIL import Image;import subprocess; pyautogui.hotkey('ctrl', 's'); time.sleep(1); pyautogui.typewrite(r'"C:\Users\Docker\Downloads\CanvasSize.png"'); time.sleep(2); pyautogui.press('enter'); time.sleep(2); subprocess.call("taskkill /f /im mspaint.exe")"#;
    let mut host = FakeHost::new();
    host.command.stdout = "SUCCESS: The process \"mspaint.exe\" with PID 1 has been terminated.\n".to_owned();
    let out = run_python(&mut host, src).unwrap();
    assert_eq!(
        host.actions,
        [
            hotkey(&["ctrl", "s"]),
            wait(1000),
            text(r#""C:\Users\Docker\Downloads\CanvasSize.png""#),
            wait(2000),
            key("enter"),
            wait(2000),
        ]
    );
    assert_eq!(host.calls, [r#"run Argv(["taskkill", "/f", "/im", "mspaint.exe"])"#]);
    // The child's output is not captured by subprocess.call, so it lands in ours.
    assert_eq!(out.stdout, host.command.stdout);
}

#[test]
fn corpus_screenshot_type_and_save() {
    let src = r#"import pyautogui;from PIL import Image;import subprocess;screenshot=pyautogui.screenshot();print(type(screenshot));screenshot.save(r"C:\Users\Docker\Downloads\Screenshot.png");subprocess.call("taskkill /f /im mspaint.exe");"#;
    let (actions, stdout, calls) = python(src);
    assert!(actions.is_empty());
    assert_eq!(stdout, "<class 'PIL.Image.Image'>\n");
    assert_eq!(
        calls,
        [
            r"write_file C:\Users\Docker\Downloads\Screenshot.png".to_owned(),
            r#"run Argv(["taskkill", "/f", "/im", "mspaint.exe"])"#.to_owned(),
        ]
    );
}

#[test]
fn upstream_prefix_records_failsafe() {
    let mut host = FakeHost::new();
    let src = "import pyautogui; import time; pyautogui.FAILSAFE = False; pyautogui.click(x=100, y=200)";
    let out = run_python(&mut host, src).unwrap();
    assert_eq!(out.failsafe, Some(false));
    assert_eq!(host.actions, [click_at(100, 200)]);
}

#[test]
fn explicit_pause_sleeps_after_each_input_call() {
    let (actions, ..) = python(
        "import pyautogui\npyautogui.PAUSE = 0.2\npyautogui.press('a')\npyautogui.position()\npyautogui.press('b')",
    );
    assert_eq!(actions, [key("a"), wait(200), key("b"), wait(200)]);
}

// ---- Getters ------------------------------------------------------------------------------

#[test]
fn getter_programs_print_like_python() {
    let check = |src: &str, expected: &str| assert_eq!(python(src).1, expected, "{src}");
    check("import platform; print(platform.system())", "Windows\n");
    check(
        r"import os; print(os.path.join(os.getenv('LOCALAPPDATA'), 'Google\\Chrome\\User Data\\Default\\History'))",
        "C:\\Users\\Docker\\AppData\\Local\\Google\\Chrome\\User Data\\Default\\History\n",
    );
    check("import pyautogui; print(pyautogui.getActiveWindowTitle())", "Untitled - Paint\n");
    check("import os; print(os.path.expanduser('~'))", "C:\\Users\\Docker\n");
    check("import platform; print(platform.platform())", "Windows-10-10.0.22631-SP0\n");
    check(
        "import os; print(os.environ.get('USERNAME'), os.environ['COMPUTERNAME'], os.getenv('NOPE', 'dflt'))",
        "Docker WAA-VM dflt\n",
    );
    check(
        r"import os; print(os.path.exists(r'C:\x.txt'), os.path.isdir(r'C:\x.txt'), os.path.isfile('C:\\x.txt'))",
        "True False True\n",
    );
    check(r"import os; print(os.path.basename(r'C:\a\b.txt'), os.path.dirname(r'C:\a\b.txt'))", "b.txt C:\\a\n");
    check("import os; print(os.listdir('C:\\\\'))", "['a.txt', 'b']\n");
    check("import os.path; print(os.path.splitext('a.tar.gz'))", "('a.tar', '.gz')\n");
    check("import sys; print(sys.platform)", "win32\n");
}

#[test]
fn hidden_file_getter_fails_precisely() {
    let src = r"import os; print(1 if os.path.basename(r'C:\x') .startswith('.') or (os.name == 'nt' and bool(os.stat(r'C:\x').st_file_attributes & 2)) else 0)";
    let err = python_err(src);
    // The conditional expression and the boolean logic run now; `os.stat` is what the interpreter lacks.
    assert_eq!(
        err,
        "line 1: AttributeError: module 'os' has no attribute 'stat' (os.stat is not supported by this interpreter)"
    );
}

#[test]
fn subprocess_and_os_system() {
    let mut host = FakeHost::new();
    host.command = CommandOutput { code: 3, stdout: "out\n".into(), stderr: "err\n".into() };
    let src = "import subprocess, os\nr = subprocess.run(['cmd', '/c', 'ver'], capture_output=True, text=True)\nprint(r.returncode, repr(r.stdout), repr(r.stderr))\nprint(os.system('dir'))\np = subprocess.Popen('notepad.exe', shell=True)\nprint(p.pid)";
    let out = run_python(&mut host, src).unwrap();
    assert_eq!(out.stdout, "3 'out\\n' 'err\\n'\nout\n3\n4242\n");
    assert_eq!(out.stderr, "err\n");
    assert_eq!(
        host.calls,
        [r#"run Argv(["cmd", "/c", "ver"])"#, r#"run Shell("dir")"#, r#"launch Shell("notepad.exe")"#,]
    );
    let err = run_python(&mut host, "import subprocess\nsubprocess.check_output(['x', 'y'])").unwrap_err();
    assert_eq!(
        err.python_message(),
        "subprocess.CalledProcessError: Command '['x', 'y']' returned non-zero exit status 3."
    );
}

#[test]
fn sys_exit_ends_the_run_with_a_code() {
    let mut host = FakeHost::new();
    let out = run_python(&mut host, "import sys\nprint('a')\nsys.exit(4)\nprint('b')").unwrap();
    assert_eq!((out.stdout.as_str(), out.exit_code), ("a\n", 4));
    let out = run_python(&mut host, "import sys; sys.exit('bad')").unwrap();
    assert_eq!((out.stderr.as_str(), out.exit_code), ("bad\n", 1));
}

#[test]
fn position_size_and_points_print_like_pyautogui() {
    let (_, stdout, _) = python(
        "import pyautogui\npyautogui.moveTo(3, 4)\np = pyautogui.position()\nprint(p, p.x, p[1], len(p))\nprint(pyautogui.size())\nprint(pyautogui.onScreen(1439, 0), pyautogui.onScreen(1440, 0))\nprint(pyautogui.screenshot(region=(0, 0, 10, 20)).size)",
    );
    assert_eq!(stdout, "Point(x=3, y=4) 3 4 2\nSize(width=1440, height=900)\nTrue False\n(10, 20)\n");
}

// ---- The Computer object --------------------------------------------------------------------

fn computer_state() -> ComputerState {
    ComputerState {
        rects: vec![[0, 0, 10, 10], [100, 50, 201, 151], [10, 20, 30, 40]],
        window_rect: [5, 7, 1445, 907],
        scale: (1.5, 2.0),
        clipboard_content: None,
        swap_ctrl_alt: false,
        current_id: None,
    }
}

fn navi(state: &mut ComputerState, host: &mut FakeHost, src: &str) -> Result<RunOutput, ScriptError> {
    let globals = Globals::computer(state);
    run_source(src, host, globals)
}

#[test]
fn move_id_uses_centre_scale_and_window_offset() {
    let mut state = computer_state();
    let mut host = FakeHost::new();
    navi(&mut state, &mut host, "computer.mouse.move_id(id=1)\ncomputer.mouse.single_click()").unwrap();
    // centre (150, 100) * scale (1.5, 2.0) + offset (5, 7)
    assert_eq!(
        host.actions,
        [
            Action::MoveTo { x: 230, y: 207 },
            wait(250),
            Action::Click { x: None, y: None, button: MouseButton::Left, count: 1 },
            wait(250),
        ]
    );
    assert_eq!(state.current_id, Some(1));
    let err = navi(&mut state, &mut host, "computer.mouse.move_id(7)").unwrap_err();
    assert_eq!(err.python_message(), "IndexError: list index out of range");
    navi(&mut state, &mut host, "computer.mouse.move_id(-1)").unwrap();
    assert_eq!(state.current_id, Some(2));
}

#[test]
fn move_abs_and_both_drag_signatures() {
    let mut state = computer_state();
    let check = |state: &mut ComputerState, src: &str, expected: Action| {
        let mut host = FakeHost::new();
        navi(state, &mut host, src).unwrap_or_else(|e| panic!("{src}: {e}"));
        assert_eq!(host.actions, [expected, wait(250)], "{src}");
    };
    // int(0.5 * 1440) + 5, int(0.25 * 900) + 7
    check(&mut state, "computer.mouse.move_abs(x=0.5, y=0.25)", Action::MoveTo { x: 725, y: 232 });
    check(&mut state, "computer.mouse.move_abs(0.999, 0.001)", Action::MoveTo { x: 1443, y: 7 });
    let drag =
        |x, y| Action::Drag { from: None, to: Point::new(x, y), button: MouseButton::Left, duration_ms: Some(1000) };
    check(&mut state, "computer.mouse.drag(x=0.35, y=0.48)", drag(508, 439));
    check(&mut state, "computer.mouse.drag(screen_x=300, screen_y=200)", drag(300, 200));
    check(&mut state, "computer.mouse.drag(300, 200)", drag(300, 200));
    let mut host = FakeHost::new();
    let err = navi(&mut state, &mut host, "computer.mouse.drag(x=35, y=48)").unwrap_err();
    assert!(err.message.contains("fraction in [0, 1]"), "{err}");
    let err = navi(&mut state, &mut host, "computer.mouse.drag(screen_x=3)").unwrap_err();
    assert_eq!(err.python_message(), "TypeError: drag() missing 1 required positional argument: 'screen_y'");
}

#[test]
fn keyboard_press_splits_chords() {
    let check = |src: &str, expected: Action| {
        let mut state = computer_state();
        let mut host = FakeHost::new();
        navi(&mut state, &mut host, src).unwrap_or_else(|e| panic!("{src}: {e}"));
        assert_eq!(host.actions, [expected, wait(250)], "{src}");
    };
    check("computer.keyboard.press('ctrl+c')", hotkey(&["ctrl", "c"]));
    check("computer.keyboard.press('ctrl-shift-s')", hotkey(&["ctrl", "shift", "s"]));
    check("computer.keyboard.press('Enter')", key("enter"));
    check("computer.keyboard.press('-')", key("-"));
    check("computer.keyboard.write('hi')", text("hi"));
    check("computer.mouse.scroll(dir='up')", Action::Scroll { x: None, y: None, dx: 0, dy: 400 });
    check("computer.mouse.scroll()", Action::Scroll { x: None, y: None, dx: 0, dy: -400 });
    let mut state = computer_state();
    let err = navi(&mut state, &mut FakeHost::new(), "computer.keyboard.press('ctrl+enterr')").unwrap_err();
    assert!(err.message.contains("unknown key name \"enterr\""), "{err}");
}

#[test]
fn clipboard_copy_text_prints_and_paste_swaps() {
    let mut state = computer_state();
    let mut host = FakeHost::new();
    let out = navi(&mut state, &mut host, "computer.clipboard.copy_text('an error here')").unwrap();
    assert_eq!(out.stdout, "an error here\n");
    assert_eq!(host.calls, ["clipboard_set_text an error here"]);
    assert_eq!(state.clipboard_content.as_deref(), Some("an error here"));
    assert!(host.actions.is_empty(), "copy_text does not sleep");

    let mut host = FakeHost::new();
    state.swap_ctrl_alt = true;
    let out = navi(&mut state, &mut host, "computer.clipboard.copy_text()\ncomputer.clipboard.paste()").unwrap();
    assert_eq!(out.stdout, "None\n");
    assert_eq!(state.clipboard_content, None);
    assert_eq!(
        host.actions,
        [Action::DoubleClick { x: None, y: None }, hotkey(&["alt", "c"]), hotkey(&["alt", "v"]), wait(250)]
    );

    let mut host = FakeHost::new();
    let out = navi(
        &mut state,
        &mut host,
        "computer.clipboard.copy_image(id=1, description='logo')\nprint(computer.clipboard.view_clipboard())",
    )
    .unwrap();
    assert_eq!(host.calls, ["clipboard_set_image 101x101"]);
    assert_eq!(state.clipboard_content.as_deref(), Some("logo"));
    assert_eq!(out.stdout, "clip\n");
}

#[test]
fn open_program_prints_upstream_error_when_missing() {
    let mut state = computer_state();
    let mut host = FakeHost::new();
    let out = navi(&mut state, &mut host, "computer.os.open_program('gimp')").unwrap();
    assert_eq!(out.stdout, "error: Program gimp is not installed\n");
    assert!(host.actions.is_empty());

    let mut host = FakeHost::new();
    navi(&mut state, &mut host, "computer.os.open_program('msedge')").unwrap();
    assert_eq!(host.calls, [r#"launch Shell("start msedge")"#, "change_window 100 Maximize"]);
    assert_eq!(
        host.actions,
        [wait(2000), key("esc"), key("esc"), wait(1000), key("esc"), wait(1000), key("esc"), wait(250)]
    );
}

#[test]
fn switch_to_application_matches_like_difflib() {
    let windows = ["Untitled - Notepad", "Settings", "File  Explorer", "Google Chrome", "Document1 - Word"];
    let check = |name: &str, expected: Option<&str>| {
        let mut state = computer_state();
        let mut host = FakeHost::new();
        host.windows = windows.iter().map(|w| (*w).to_owned()).collect();
        host.active_title.clear();
        let out =
            navi(&mut state, &mut host, &format!("computer.window_manager.switch_to_application({name:?})")).unwrap();
        match expected {
            Some(title) => {
                let id = windows.iter().position(|w| w == &title).expect("listed") + 1;
                let changes = ["Restore", "Maximize", "Activate"].map(|c| format!("change_window {id} {c}"));
                assert_eq!(host.calls, changes, "{name}");
                assert_eq!(host.actions, [key("esc"), wait(250)], "{name}");
                assert_eq!(out.stdout, "");
            }
            None => {
                assert!(host.calls.is_empty(), "{name}: {:?}", host.calls);
                assert_eq!(out.stdout, format!("No open window matches '{name}'.\n"));
            }
        }
    };
    check("Settings", Some("Settings"));
    check("settings", Some("Settings"));
    check("File Explorer", Some("File  Explorer"));
    check("Explorer", Some("File  Explorer"));
    check("Chrome", Some("Google Chrome"));
    check("Notepad", None);
    check("Untitled -   Notepad", Some("Untitled - Notepad"));
    check("Document1 - Word", Some("Document1 - Word"));
    check("Excel", None);
}

#[test]
fn computer_is_only_bound_for_execute_windows() {
    let err = python_err("computer.mouse.single_click()");
    assert_eq!(err, "line 1: NameError: name 'computer' is not defined (it is only bound for /execute_windows)");
    let mut state = computer_state();
    let err = navi(&mut state, &mut FakeHost::new(), "computer.mouse.clik()").unwrap_err();
    assert_eq!(err.python_message(), "AttributeError: 'Mouse' object has no attribute 'clik'");
    let err = navi(&mut state, &mut FakeHost::new(), "human.ask_question('x?')").unwrap_err();
    assert_eq!(err.kind, ErrorKind::NotSupported);
    let out = navi(&mut state, &mut FakeHost::new(), "import time; time.sleep(1); print(computer.mouse.window_rect)")
        .unwrap();
    assert_eq!(out.stdout, "[5, 7, 1445, 907]\n");
}

// ---- Literals and printing ------------------------------------------------------------------

fn printed(src: &str) -> String {
    python(src).1
}

#[test]
fn string_literal_forms() {
    let check = |literal: &str, expected: &str| {
        assert_eq!(printed(&format!("print({literal}, end='')")), expected, "{literal}");
    };
    check(r"'single'", "single");
    check(r#""double""#, "double");
    check(r#"'''tri'ple''"'''"#, r#"tri'ple''""#);
    check("\"\"\"line1\nline2\"\"\"", "line1\nline2");
    check(r"r'C:\Users\new'", r"C:\Users\new");
    check(r"R'a\'b'", r"a\'b");
    check(r"u'unicode é'", "unicode é");
    check(r#"'a\nb\tc\\d\'e\"f'"#, "a\nb\tc\\d'e\"f");
    check(r"'\x41\101\u00e9\U0001F600\0'", "AAé😀\0");
    check(r"'\d\w unknown escapes'", r"\d\w unknown escapes");
    check(r"'adj' 'acent' r'\raw'", r"adjacent\raw");
    check("('a'\n 'b')", "ab");
    check("'line \\\ncontinued'", "line continued");
    check(r"''", "");
}

#[test]
fn values_print_like_python() {
    let check =
        |expr: &str, expected: &str| assert_eq!(printed(&format!("print({expr})")), format!("{expected}\n"), "{expr}");
    check("1, 2.0", "1 2.0");
    check("0.1 + 0.2", "0.30000000000000004");
    check("1e-05, 1e16, 1e15, -0.0", "1e-05 1e+16 1000000000000000.0 -0.0");
    check("float('inf'), float('-inf')", "inf -inf");
    check("7 // 2, -7 // 2, 7 % -2, 7 / 2, 2 ** 10, 2 ** -1", "3 -4 -1 3.5 1024 0.5");
    check("None, True, False", "None True False");
    check("[1, 'a', (2,), (), {'k': None}]", "[1, 'a', (2,), (), {'k': None}]");
    check("repr('it\\'s'), str(3), int('42'), int(3.9), float('1.5')", "\"it's\" 3 42 3 1.5");
    check("round(2.5), round(3.5), round(2.675, 2), round(-0.5)", "2 4 2.67 0");
    check("min(3, 1, 2), max([1.5, 2]), abs(-3), len('héllo'), sum([1, 2, 3])", "1 2 3 5 6");
    check("'a' + 'b', 'ab' * 2, [1] + [2], 0x_ff, 1_000", "ab abab [1, 2] 255 1000");
    check("'x'.upper(), ' a b '.strip(), 'a,b'.split(','), '-'.join(['a', 'b'])", "X a b ['a', 'b'] a-b");
    check("type(1), type('s'), type(None), type([])", "<class 'int'> <class 'str'> <class 'NoneType'> <class 'list'>");
    check("bool(0), bool('x'), list('ab'), tuple([1])", "False True ['a', 'b'] (1,)");
    check("{'a': 1}['a'], {'a': 1}.get('b', 9), [5, 6][-1], 'abc'[1]", "1 9 6 b");
}

#[test]
fn print_keywords() {
    assert_eq!(printed("print(1, 2, sep='-', end='!')"), "1-2!");
    assert_eq!(printed("print()"), "\n");
    assert_eq!(printed("print('a', 'b', sep=None)"), "a b\n");
}

// ---- Errors ---------------------------------------------------------------------------------

#[test]
fn parse_errors_name_the_construct_and_position() {
    let check = |src: &str, line: usize, column: usize, message: &str| {
        let err = parse(src).expect_err(src);
        assert_eq!((err.line, err.column, err.message.as_str()), (line, column, message), "{src}");
    };
    check("class A: pass", 1, 1, "class definitions (`class`) are not supported");
    check("import os\nwith open('x') as f: pass", 2, 1, "`with` statements are not supported");
    check("def f(*args): pass", 1, 1, "`*args` and `**kwargs` parameters are not supported");
    check("@dec\ndef f(): pass", 2, 1, "decorators are not supported");
    check("def f():\n    yield 1", 2, 5, "generators (`yield`) are not supported");
    check("async def f(): pass", 1, 1, "`async` code is not supported");
    check("f(*args)", 1, 3, "unpacking (`*`) in calls is not supported");
    check("f(**kw)", 1, 3, "unpacking (`**`) in calls is not supported");
    check("a, *b = [1, 2]", 1, 4, "starred assignment targets (`a, *b = ...`) are not supported");
    check("if (n := 3): pass", 1, 5, "assignment expressions (`:=`) are not supported");
    check("x = b'y'", 1, 5, "bytes literals (b'...') are not supported");
    check("x = 1j", 1, 5, "complex number literals are not supported");
    check("x = 99999999999999999999", 1, 5, "integer literal too large (this interpreter's integers are 64-bit)");
    check("from os import *", 1, 1, "`from ... import *` is not supported");
    check("from . import x", 1, 1, "relative imports are not supported");
    check("nonlocal x", 1, 1, "`nonlocal` statements are not supported");
    check("x = a @ b", 1, 5, "the matrix operator (`@`) is not supported");
    check("break", 1, 1, "'break' outside loop");
    check("return 1", 1, 1, "'return' outside function");
    check("raise ValueError('x') from None", 1, 1, "`raise ... from ...` is not supported");
    // Syntax errors refuse the program with the position the parser reports.
    let err = parse("x = 1\nfor i in range(3)\n    pass").unwrap_err();
    assert_eq!((err.line, err.message.starts_with("invalid syntax")), (2, true), "{err}");
    let err = parse("print('a'").unwrap_err();
    assert_eq!(err.line, 1, "{err}");
    let err = parse("x = 'abc").unwrap_err();
    assert_eq!(err.line, 1, "{err}");
    let err = parse("if x:\npass").unwrap_err();
    assert_eq!(err.message, "expected an indented block", "{err}");
    // Nesting limits keep hostile input from exhausting the stack.
    let deep = format!("x = {}1{}", "(".repeat(100), ")".repeat(100));
    assert!(parse(&deep).unwrap_err().message.contains("nested too deeply"));
    let long_chain = format!("x = 1{}", " + 1".repeat(3000));
    assert!(parse(&long_chain).unwrap_err().message.contains("line too long"));
    let unary = format!("x = {}1", "-".repeat(200));
    assert!(parse(&unary).unwrap_err().message.contains("nested too deeply"));
    let blocks: String =
        (0..40).map(|i| format!("{}if x:\n", "    ".repeat(i))).collect::<String>() + &"    ".repeat(40) + "pass";
    assert!(parse(&blocks).unwrap_err().message.contains("blocks nested too deeply"));
    assert!(parse(&format!("x = 1{}", " + 1".repeat(40))).is_ok());
    // Empty statements are accepted, as the WAA corpus's `...;;` needs.
    assert!(parse("a = 1;; b = 2;").is_ok());
}

#[test]
fn runtime_errors_are_python_exceptions() {
    let check = |src: &str, expected: &str| assert_eq!(python_err(src), expected, "{src}");
    check("print(x)", "line 1: NameError: name 'x' is not defined");
    check("import pyautogui\n\npyautogui.clik(1, 2)", "line 3: AttributeError: module 'pyautogui' has no attribute 'clik' (pyautogui.clik is not supported by this interpreter)");
    check("import numpy", "line 1: ModuleNotFoundError: No module named 'numpy' (this interpreter provides: pyautogui, time, os, os.path, ntpath, subprocess, platform, sys, PIL, PIL.Image, PIL.ImageGrab, pyperclip)");
    check(
        "import pyautogui; pyautogui.dragTo(1, 2, foo=3)",
        "line 1: TypeError: dragTo() got an unexpected keyword argument 'foo'",
    );
    check("import pyautogui; pyautogui.press('enterr')", "line 1: ValueError: press(): unknown key name \"enterr\" (expected a pyautogui key name such as \"enter\", \"ctrl\" or \"a\"); pyautogui would silently ignore it, this interpreter refuses");
    check("import pyautogui; pyautogui.click(button='Left')", "line 1: ValueError: button argument must be one of ('left', 'middle', 'right', 'primary', 'secondary', 1, 2, 3), not 'Left'");
    check("import time; time.sleep(-1)", "line 1: ValueError: sleep length must be non-negative");
    check("print(1 / 0)", "line 1: ZeroDivisionError: division by zero");
    check("print('a' + 1)", "line 1: TypeError: can only concatenate str (not \"int\") to str");
    check("open('x')", "line 1: NotImplementedError: open() is not supported by this interpreter");
    check(
        "import os; os.path.join(os.getenv('NOPE'), 'x')",
        "line 1: TypeError: expected str, bytes or os.PathLike object, not NoneType",
    );
    check(
        "import PIL.Image; PIL.Image.open('x.png')",
        "line 1: NotImplementedError: PIL.Image.open is not supported: this interpreter has no image library",
    );
    check("print([1][3])", "line 1: IndexError: list index out of range");
    check("print({'a': 1}['b'])", "line 1: KeyError: 'b'");
    check("x = 2 ** 70", "line 1: OverflowError: integer overflow (this interpreter's integers are 64-bit)");
    check("x = 'a' * 100000000", "line 1: MemoryError: result would exceed 10000000 items");
    check("print(len(5))", "line 1: TypeError: object of type 'int' has no len()");
    check("(1)()", "line 1: TypeError: 'int' object is not callable");
    check("import pyautogui; pyautogui.locateOnScreen('a.png')", "line 1: AttributeError: module 'pyautogui' has no attribute 'locateOnScreen' (pyautogui.locateOnScreen is not supported by this interpreter)");
}

#[test]
fn resource_limits_stop_hostile_programs() {
    let nested = format!("a = 1\n{}", "a = [a]\n".repeat(150));
    assert_eq!(python_err(&nested), "line 102: MemoryError: value nested more than 100 levels deep");
    let appended = "a = []\nfor i in range(500):\n    a.append(a)\n";
    assert!(python_err(appended).contains("MemoryError: value nested more than 100 levels deep"));
    let inner = "a = [[]]\nfor i in range(500):\n    a[0].append(a)\n";
    assert!(python_err(inner).contains("MemoryError: value nested more than 100 levels deep"));
    let prints = "x = 'a' * 5000000\n".to_owned() + &"print(x)\n".repeat(60);
    assert!(python_err(&prints).contains("MemoryError: the program would hold more than 256 MiB"));
    assert!(python_err("x = ('ab' * 1000000).replace('a', 'aaaaaaaaaa')").contains("MemoryError"));
    assert!(python_err("x = list('a' * 2000000)").contains("MemoryError"));
    assert!(python_err("x = [1] * 2000000").contains("MemoryError"));
    assert!(python_err("x = sum([[1]] * 1000, [])").contains("NotImplementedError"));
    assert_eq!(printed("print(len([] * 10**18), len('' * 10**18))"), "0 0\n");
}

// ---- Memory and time bounds (issue 25, items 1 and 2) ----------------------------------------

#[test]
fn a_program_over_the_source_cap_is_refused_before_parsing() {
    let at_cap = format!("x = 1\n{}", "#".repeat(parser::MAX_SOURCE_BYTES - 6));
    assert_eq!(at_cap.len(), parser::MAX_SOURCE_BYTES);
    assert!(parse(&at_cap).is_ok());
    let over = format!("{at_cap}#");
    let err = parse(&over).unwrap_err();
    assert_eq!((err.line, err.column), (1, 1));
    assert_eq!(err.message, "the program is 262145 bytes long; this interpreter reads programs of at most 256 KiB");
}

/// Runs `src` as `python -c`, stopping as `stop` says, with what it cost.
fn measured(src: &str, stop: Stop) -> (Result<RunOutput, ScriptError>, RunStats) {
    let program = parse(src).unwrap_or_else(|e| panic!("{src}\n{e}"));
    let mut host = FakeHost::new();
    run_measured(&program, &mut host, Globals::python().with_stop(stop))
}

const MIB: usize = 1 << 20;

/// The bytes a list of `n` items holds (one value slot each, as the interpreter counts them).
fn list_bytes(n: usize) -> usize {
    n * std::mem::size_of::<super::value::Value>()
}

#[test]
fn repetition_shares_its_items_instead_of_copying_them() {
    // The probe's 35-byte program: a million references to one 1 MB string, as in CPython.
    let (result, stats) = measured("x = ['a' * 10**6] * 10**6\nprint(len(x), len(x[5]))", Stop::never());
    assert_eq!(result.map(|o| o.stdout).unwrap(), "1000000 1000000\n");
    assert!(stats.peak_bytes < MIB + list_bytes(1_000_000) + MIB, "peak {}", stats.peak_bytes);
    assert_eq!(stats.live_bytes_after, 0, "everything the program held was given back");
    for src in ["x = [[0] * 10**6] * 10**6", "x = (('a' * 10**6,) * 10**6)", "x = [{'k': 'a' * 10**6}] * 10**6"] {
        let (result, stats) = measured(src, Stop::never());
        assert!(result.is_ok(), "{src}: {result:?}");
        assert!(stats.peak_bytes < 2 * list_bytes(1_000_000) + 2 * MIB, "{src}: peak {}", stats.peak_bytes);
    }
}

#[test]
fn an_allocation_past_the_budget_fails_before_it_happens() {
    // Joining the shared strings would make 10**12 bytes: refused before anything is built.
    let (result, stats) = measured("x = ['a' * 10**6] * 10**6\ny = ''.join(x)", Stop::never());
    let err = result.unwrap_err();
    assert_eq!(err.kind, ErrorKind::Memory, "{err}");
    assert!(stats.peak_bytes < MIB + list_bytes(1_000_000) * 2 + MIB, "peak {}", stats.peak_bytes);
    // Distinct values: the run stops at the budget, never far past it.
    for src in [
        "x = ['a' * 10**6 + str(i) for i in range(10**6)]",
        "d = {i: 'a' * 10**6 + str(i) for i in range(10**6)}",
        "x = []\nfor i in range(10**5):\n    x.append('b' * 10**6 + str(i))",
        "x = [list(range(10**5)) for i in range(10**4)]",
    ] {
        let (result, stats) = measured(src, Stop::never());
        let err = result.unwrap_err();
        assert_eq!(err.kind, ErrorKind::Memory, "{src}: {err}");
        assert_eq!(err.message, "the program would hold more than 256 MiB", "{src}");
        assert!(stats.peak_bytes <= MAX_MEMORY + 4 * MIB, "{src}: peak {}", stats.peak_bytes);
        assert_eq!(stats.live_bytes_after, 0, "{src}");
    }
}

#[test]
fn the_budget_counts_what_is_held_now_not_what_was_ever_made() {
    // CPython runs these; each iteration's value replaces the last.
    let (result, stats) = measured("for i in range(99999):\n    s = 'a' * 3000\nprint(len(s))", Stop::never());
    assert_eq!(result.unwrap().stdout, "3000\n");
    assert!(stats.peak_bytes < 64 * 1024, "peak {}", stats.peak_bytes);
    assert_eq!(stats.live_bytes_after, 0);
    // Membership, sums and counts read the items in place.
    let src = "x = list(range(10000))\nn = 0\nfor i in range(300):\n    n += (-1 in x) + sum(x) + x.count(-1) + x.index(9999)\nprint(n)";
    let (result, stats) = measured(src, Stop::never());
    assert_eq!(result.unwrap().stdout, format!("{}\n", 300_u64 * (49_995_000 + 9999)));
    assert!(stats.peak_bytes < 3 * list_bytes(10_000), "peak {}", stats.peak_bytes);
    // A big string reassigned in a loop is given back each time.
    let src = "for i in range(1000):\n    s = 'x' * (10**7 - 1)\n    t = s + 'y'";
    let (result, stats) = measured(src, Stop::never());
    assert!(result.is_ok(), "{result:?}");
    assert!(stats.peak_bytes < 3 * 10_000_000 + MIB, "peak {}", stats.peak_bytes);
}

#[test]
fn dicts_and_sets_are_hash_tables_in_insertion_order() {
    let src = "d = {}\nfor i in range(99999):\n    d[i] = i\ns = set(d)\nprint(len(d), d[77777], 5 in s, list(d)[:3], d.get(99998.0))";
    let (result, stats) = measured(src, Stop::never());
    assert_eq!(result.unwrap().stdout, "99999 77777 True [0, 1, 2] 99998\n");
    // The probe's case, whose linear lists did 5 * 10**9 comparisons, is a bounded amount of work now.
    assert!(stats.work < 1_000, "work {}", stats.work);
    assert_eq!(
        printed("d = {1: 'a', True: 'b', 1.0: 'c', (1, 2): 'd'}\nprint(d, {(1, 2)} == {(1.0, 2)})"),
        "{1: 'c', (1, 2): 'd'} True\n"
    );
    assert_eq!(
        printed("d = {'b': 1, 'a': 2}\nd['c'] = 3\ndel d['b']\nd['b'] = 4\nprint(d)"),
        "{'a': 2, 'c': 3, 'b': 4}\n"
    );
    assert_eq!(printed("s = {3, 1, 2, 1}\ns.discard(1)\ns.add(0)\nprint(s, s.pop(), s)"), "{3, 2, 0} 3 {2, 0}\n");
    assert!(python_err("d = {[1]: 2}").contains("TypeError: unhashable type: 'list'"));
    assert!(python_err("print([1] in {1: 2})").contains("TypeError: unhashable type: 'list'"));
}

#[test]
fn values_stay_values_when_shared() {
    // Copy on write: changing a shared list copies it, so the other name keeps its value.
    let src = "a = b = [1]\nb.append(2)\nc = a\nc[0] = 9\nd = {'k': a}\nd['k'].append(3)\nprint(a, b, c, d)";
    assert_eq!(printed(src), "[1] [1, 2] [9] {'k': [1, 3]}\n");
    let src = "x = [1, 2]\nfor v in x:\n    x.append(v)\nprint(x)";
    assert_eq!(printed(src), "[1, 2, 1, 2]\n");
}

#[test]
fn a_passed_deadline_stops_loops_and_long_builtins_within_one_slice() {
    let passed = Stop::new(Some(std::time::Instant::now()), None);
    for src in [
        "while True:\n    pass",
        "def f():\n    return f()\nf()",
        "x = list(range(10**6))",
        "x = [0] * 10**6",
        "x = sorted([3, 1, 2] * 300000)",
        "x = [1] * 10**6\nx.reverse()",
        "x = ','.join(['a'] * 10**6)",
        "x = sum([1] * 10**6)",
        "x = ([1] * 10**6).count(2)",
    ] {
        let (result, stats) = measured(src, passed.clone());
        let err = result.unwrap_err();
        assert_eq!(err.kind, ErrorKind::Timeout, "{src}: {err}");
        assert_eq!(err.message, "the program ran past its deadline", "{src}");
        assert!(!err.is_catchable());
        // Nothing ran on past the first check: at most one loop step and one slice of work.
        assert!(stats.steps <= 1, "{src}: {} steps", stats.steps);
        assert!(stats.work <= 2 * super::stop::WORK_SLICE + 1_000_000, "{src}: {} units", stats.work);
        assert_eq!(stats.live_bytes_after, 0, "{src}: the run holds nothing afterwards");
    }
    // `try` does not catch it.
    let (result, _) = measured("try:\n    while True:\n        pass\nexcept Exception:\n    print('caught')", passed);
    assert_eq!(result.unwrap_err().kind, ErrorKind::Timeout);
}

#[test]
fn a_cancel_flag_set_from_another_thread_stops_a_busy_program() {
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::sync::Arc;
    let flag = Arc::new(AtomicBool::new(false));
    let setter = {
        let flag = Arc::clone(&flag);
        std::thread::spawn(move || flag.store(true, Ordering::Relaxed))
    };
    // The probe's CPU-bound loop: a million-item list reversed again and again.
    let src = "x = list(range(999999))\nfor i in range(99999):\n    x.reverse()";
    let (result, stats) = measured(src, Stop::new(None, Some(Arc::clone(&flag))));
    setter.join().unwrap();
    let err = result.unwrap_err();
    assert_eq!(err.kind, ErrorKind::Timeout, "{err}");
    assert!(err.message.contains("cancelled"), "{err}");
    assert!(stats.steps < 99_999, "it stopped early: {} steps", stats.steps);
    assert_eq!(stats.live_bytes_after, 0);
    // Checks come at a bounded interval of work: one per step and one per slice.
    assert!(stats.stop_checks >= stats.steps + stats.work / super::stop::WORK_SLICE, "{stats:?}");
}

#[test]
fn a_set_cancel_flag_stops_a_program_before_its_first_step() {
    use std::sync::atomic::AtomicBool;
    use std::sync::Arc;
    let (result, stats) =
        measured("for i in range(10):\n    print(i)", Stop::new(None, Some(Arc::new(AtomicBool::new(true)))));
    let err = result.unwrap_err();
    assert_eq!(err.kind, ErrorKind::Timeout);
    assert_eq!(err.stdout, "", "nothing ran");
    assert_eq!(stats.steps, 0);
}

#[test]
fn errors_keep_output_and_effects_before_them() {
    let mut host = FakeHost::new();
    let err =
        run_python(&mut host, "import pyautogui\nprint('before')\npyautogui.press('a')\nundefined_name").unwrap_err();
    assert_eq!(err.stdout, "before\n");
    assert_eq!(err.line, 4);
    assert_eq!(host.actions, [key("a")]);
    assert_eq!(
        err.traceback(),
        "Traceback (most recent call last):\n  File \"<string>\", line 4, in <module>\nNameError: name 'undefined_name' is not defined\n"
    );
}

// ---- Properties -----------------------------------------------------------------------------

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig { cases: 512, ..Default::default() })]

    #[test]
    fn parse_never_panics(src in "\\PC{0,80}") {
        let _ = parse(&src);
    }

    #[test]
    fn parse_never_panics_on_token_soup(src in "[\\[\\](){}\"'\\\\\n;#a1.=,+*rbfu _:-]{0,60}") {
        let _ = parse(&src);
    }

    #[test]
    fn running_token_soup_never_panics(src in "[\\[\\]()'\"a-c1-3.,=+*/% ;\n]{0,40}") {
        let mut host = FakeHost::new();
        let _ = run_python(&mut host, &src);
    }

    #[test]
    fn int_literals_round_trip(i in (i64::MIN + 1)..=i64::MAX, hex in proptest::bool::ANY) {
        let literal = if hex && i >= 0 { format!("{i:#x}") } else { i.to_string() };
        proptest::prop_assert_eq!(printed(&format!("print({literal})")), format!("{i}\n"));
    }

    #[test]
    fn float_literals_round_trip(f in proptest::num::f64::NORMAL | proptest::num::f64::SUBNORMAL | proptest::num::f64::ZERO) {
        let repr = float_repr(f);
        // Python's repr is itself a valid literal that reads back as the same float.
        proptest::prop_assert_eq!(repr.parse::<f64>().ok(), Some(f));
        proptest::prop_assert_eq!(printed(&format!("print({repr})")), format!("{repr}\n"));
        proptest::prop_assert_eq!(printed(&format!("print({f:?})")), format!("{repr}\n"));
    }

    #[test]
    fn string_literals_round_trip(s in "\\PC{0,20}|[\\x00-\\x7f]{0,20}") {
        let literal = str_repr(&s);
        proptest::prop_assert_eq!(printed(&format!("print({literal}, end='')")), s.clone());
        proptest::prop_assert_eq!(printed(&format!("print(repr({literal}), end='')")), literal);
    }
}

#[test]
fn a_sleep_past_the_deadline_is_refused_at_once() {
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(30);
    let globals = Globals::python().with_stop(Stop::new(Some(deadline), None));
    let mut host = FakeHost::new();
    let started = std::time::Instant::now();
    let err = run_source("import time\ntime.sleep(10**6)", &mut host, globals).expect_err("refused");
    assert!(started.elapsed() < std::time::Duration::from_secs(5), "refused at once, not waited out");
    assert_eq!(err.kind, ErrorKind::Timeout);
    assert!(err.message.contains("time.sleep(1000000)") && err.message.contains("deadline"), "{}", err.message);
    assert!(host.actions.is_empty(), "the host was never asked to sleep");
    // Within the deadline the host sleeps as before.
    let globals = Globals::python().with_stop(Stop::new(Some(deadline), None));
    run_source("import time\ntime.sleep(1.5)", &mut host, globals).expect("runs");
    assert_eq!(host.actions, vec![Action::Wait { ms: 1500 }]);
}
