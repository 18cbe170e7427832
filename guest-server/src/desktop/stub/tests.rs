//! Behaviour tests of the whole stub desktop through the `Desktop` trait.

#[cfg(unix)]
use std::time::{Duration, Instant};

use arena_shared::action::MouseButton;
use arena_shared::observation::A11yNode;

use super::render::{BACKGROUND, TITLE_FOCUSED, TITLE_UNFOCUSED};
use super::*;

/// A stub that runs unknown programs as real host processes (`--stub-host-exec`),
/// for the tests of that path; [`StubConfig::default`] refuses them.
fn stub() -> StubDesktop {
    StubDesktop::with_config(StubConfig { host_exec: true, ..StubConfig::default() }).unwrap()
}

fn stub_with(json: &str) -> StubDesktop {
    let scenario = Scenario::parse(json, "test").unwrap();
    StubDesktop::with_config(StubConfig { scenario: Some(scenario), ..StubConfig::default() }).unwrap()
}

fn key(name: &str) -> Action {
    Action::KeyPress { key: name.into(), presses: 1 }
}

fn hotkey(keys: &[&str]) -> Action {
    Action::Hotkey { keys: keys.iter().map(|k| (*k).to_owned()).collect() }
}

fn type_text(text: &str) -> Action {
    Action::TypeText { text: text.into(), interval_ms: None }
}

fn click(x: i32, y: i32) -> Action {
    Action::Click { x: Some(x), y: Some(y), button: MouseButton::Left, count: 1 }
}

fn open_notepad(d: &StubDesktop) -> u64 {
    d.spawn(&CommandSpec::Shell("notepad".into())).unwrap();
    d.find_window("Notepad").unwrap()
}

fn titles(d: &StubDesktop) -> Vec<String> {
    d.windows().unwrap().into_iter().map(|w| w.title).collect()
}

fn focused_title(d: &StubDesktop) -> String {
    d.windows().unwrap().into_iter().find(|w| w.focused).map(|w| w.title).unwrap_or_default()
}

fn limits(timeout_ms: u64) -> ExecLimits {
    ExecLimits { timeout_ms, max_output_bytes: 1 << 20, cwd: None, stdin: None }
}

#[test]
fn a_fresh_desktop_has_only_program_manager() {
    let d = stub();
    let windows = d.windows().unwrap();
    assert_eq!(windows.len(), 1);
    let pm = &windows[0];
    assert_eq!(
        (pm.title.as_str(), pm.class_name.as_str(), pm.process_name.as_str()),
        ("Program Manager", "Progman", "explorer.exe")
    );
    assert_eq!((pm.id, pm.process_id), (0x10010, 1000));
    assert_eq!(pm.rect, Rect::new(0, 0, 1440, 900));
    assert!(pm.focused);
    let screen = d.screen().unwrap();
    assert_eq!((screen.physical_width, screen.physical_height, screen.scale_factor), (1440, 900, 1.0));
    assert_eq!(screen.coordinate_space, CoordinateSpace::Physical);
    assert_eq!(d.session_id(), None);
}

#[test]
fn program_manager_cannot_be_closed() {
    let d = stub();
    let err = d.close_window(0x10010).unwrap_err();
    assert!(matches!(err, DesktopError::PermissionDenied(_)), "{err:?}");
    assert_eq!(d.windows().unwrap().len(), 1);
    let err = d.close_window(0xdead).unwrap_err();
    assert!(matches!(&err, DesktopError::NotFound(m) if m == "no window with id 0xdead"), "{err:?}");
}

#[test]
fn typing_editing_and_the_clipboard() {
    let d = stub();
    let id = open_notepad(&d);
    d.perform(&type_text("hello")).unwrap();
    d.perform(&key("enter")).unwrap();
    d.perform(&type_text("world")).unwrap();
    d.perform(&key("tab")).unwrap();
    d.perform(&key("backspace")).unwrap();
    d.perform(&key("backspace")).unwrap();
    assert_eq!(d.window_text(id).unwrap(), "hello\nworl");
    d.perform(&key("home")).unwrap();
    d.perform(&key("delete")).unwrap();
    assert_eq!(d.window_text(id).unwrap(), "hello\norl");

    // Select all, copy, type over it, paste it back twice.
    d.perform(&hotkey(&["ctrl", "a"])).unwrap();
    d.perform(&key("ctrl+c")).unwrap();
    assert_eq!(d.clipboard_get().unwrap(), ClipboardData::Text("hello\norl".into()));
    d.perform(&type_text("X")).unwrap();
    assert_eq!(d.window_text(id).unwrap(), "X");
    d.perform(&hotkey(&["ctrl", "v"])).unwrap();
    d.perform(&hotkey(&["ctrl", "v"])).unwrap();
    assert_eq!(d.window_text(id).unwrap(), "Xhello\norlhello\norl");

    // Cut empties the document; backspace after select-all clears too.
    d.perform(&hotkey(&["ctrl", "a"])).unwrap();
    d.perform(&hotkey(&["ctrl", "x"])).unwrap();
    assert_eq!(d.window_text(id).unwrap(), "");
    assert_eq!(d.clipboard_get().unwrap(), ClipboardData::Text("Xhello\norlhello\norl".into()));
    d.perform(&type_text("abc")).unwrap();
    d.perform(&hotkey(&["ctrl", "a"])).unwrap();
    d.perform(&key("backspace")).unwrap();
    assert_eq!(d.window_text(id).unwrap(), "");

    // Held modifiers make characters shortcuts, not text; esc changes nothing.
    d.perform(&type_text("q")).unwrap();
    d.perform(&Action::KeyDown { key: "ctrl".into() }).unwrap();
    d.perform(&type_text("a")).unwrap();
    d.perform(&Action::KeyUp { key: "ctrl".into() }).unwrap();
    d.perform(&key("esc")).unwrap();
    d.perform(&type_text("z")).unwrap();
    assert_eq!(d.window_text(id).unwrap(), "z", "ctrl+a selected all, so z replaced q");
    d.perform(&hotkey(&["shift", "b"])).unwrap();
    assert_eq!(d.window_text(id).unwrap(), "zB");
}

#[test]
fn unknown_keys_and_actions_are_invalid_and_change_nothing() {
    let d = stub();
    let id = open_notepad(&d);
    let err = d.perform(&hotkey(&["ctrl", "nosuchkey"])).unwrap_err();
    assert!(matches!(&err, DesktopError::InvalidInput(m) if m.contains("nosuchkey")), "{err:?}");
    let err = d.perform(&key("enterr")).unwrap_err();
    assert!(matches!(&err, DesktopError::InvalidInput(m) if m.contains("enterr")), "{err:?}");
    assert!(matches!(d.perform(&Action::Unknown), Err(DesktopError::InvalidInput(_))));
    assert_eq!(d.window_text(id).unwrap(), "");
    // Failed actions are not logged.
    assert!(d.action_log().is_empty());
    d.perform(&type_text("x")).unwrap();
    assert_eq!(d.action_log(), vec![type_text("x")]);
}

#[test]
fn clicks_focus_and_raise_windows() {
    let d = stub_with(
        r#"{"windows": [
            {"title": "Top", "rect": {"x": 100, "y": 100, "width": 400, "height": 300}},
            {"title": "Bottom", "rect": {"x": 300, "y": 200, "width": 400, "height": 300}}
        ]}"#,
    );
    assert_eq!(titles(&d), ["Top", "Bottom", "Program Manager"]);
    assert_eq!(focused_title(&d), "Top");
    // (600, 450) is only inside Bottom.
    d.perform(&click(600, 450)).unwrap();
    assert_eq!(titles(&d), ["Bottom", "Top", "Program Manager"]);
    assert_eq!(focused_title(&d), "Bottom");
    let z: Vec<u32> = d.windows().unwrap().iter().map(|w| w.z_order).collect();
    assert_eq!(z, [0, 1, 2]);
    // The overlap belongs to the topmost window.
    d.perform(&click(350, 250)).unwrap();
    assert_eq!(focused_title(&d), "Bottom");
    // The bare desktop focuses Program Manager and raises nothing.
    d.perform(&click(1300, 100)).unwrap();
    assert_eq!(focused_title(&d), "Program Manager");
    assert_eq!(titles(&d), ["Bottom", "Top", "Program Manager"]);
    assert_eq!(d.cursor_position().unwrap(), Point::new(1300, 100));
    // The cursor is clamped to the screen.
    d.perform(&Action::MoveTo { x: 5000, y: -20 }).unwrap();
    assert_eq!(d.cursor_position().unwrap(), Point::new(1439, 0));
}

#[test]
fn dragging_a_title_bar_moves_the_window() {
    let d = stub_with(r#"{"windows": [{"title": "W", "rect": {"x": 100, "y": 100, "width": 400, "height": 300}}]}"#);
    let id = d.find_window("W").unwrap();
    d.perform(&Action::Drag {
        from: Some(Point::new(150, 110)),
        to: Point::new(450, 310),
        button: MouseButton::Left,
        duration_ms: None,
    })
    .unwrap();
    let w = d.windows().unwrap().into_iter().find(|w| w.id == id).unwrap();
    assert_eq!(w.rect, Rect::new(400, 300, 400, 300));
    // Dragging the body moves only the cursor.
    d.perform(&Action::Drag {
        from: Some(Point::new(500, 500)),
        to: Point::new(700, 600),
        button: MouseButton::Left,
        duration_ms: None,
    })
    .unwrap();
    let w = d.windows().unwrap().into_iter().find(|w| w.id == id).unwrap();
    assert_eq!(w.rect, Rect::new(400, 300, 400, 300));
    assert_eq!(d.cursor_position().unwrap(), Point::new(700, 600));
    // Mouse down, moves and up do the same as a drag.
    d.perform(&Action::MouseDown { button: MouseButton::Left, x: Some(450), y: Some(310) }).unwrap();
    d.perform(&Action::MoveRel { dx: -100, dy: -50 }).unwrap();
    d.perform(&Action::MouseUp { button: MouseButton::Left, x: None, y: None }).unwrap();
    d.perform(&Action::MoveRel { dx: 100, dy: 100 }).unwrap();
    let w = d.windows().unwrap().into_iter().find(|w| w.id == id).unwrap();
    assert_eq!(w.rect, Rect::new(300, 250, 400, 300));
}

#[test]
fn window_states_and_caption_buttons() {
    let d = stub_with(r#"{"windows": [{"title": "W", "rect": {"x": 100, "y": 100, "width": 400, "height": 300}}]}"#);
    let id = d.find_window("W").unwrap();
    d.set_window_state(id, WindowState::Maximized).unwrap();
    let w = &d.windows().unwrap()[0];
    assert!(w.maximized);
    assert_eq!(w.rect, Rect::new(0, 0, 1440, 860));
    d.set_window_state(id, WindowState::Normal).unwrap();
    assert_eq!(d.windows().unwrap()[0].rect, Rect::new(100, 100, 400, 300));
    d.set_window_state(id, WindowState::Minimized).unwrap();
    assert!(d.windows().unwrap()[0].minimized);
    assert_eq!(focused_title(&d), "Program Manager");
    d.activate_window(id).unwrap();
    let w = &d.windows().unwrap()[0];
    assert!(!w.minimized && w.focused);
    // Double-clicking the title bar maximises; the caption buttons minimise and close.
    d.perform(&Action::DoubleClick { x: Some(200), y: Some(110) }).unwrap();
    assert!(d.windows().unwrap()[0].maximized);
    d.perform(&Action::DoubleClick { x: Some(200), y: Some(10) }).unwrap();
    assert!(!d.windows().unwrap()[0].maximized);
    // Close button: the rightmost 46 pixels of the title bar.
    d.perform(&click(490, 110)).unwrap();
    assert_eq!(titles(&d), ["Program Manager"]);
}

#[test]
fn close_alt_f4_and_refuse_close() {
    let d = stub_with(
        r#"{"windows": [
            {"title": "Stubborn", "refuse_close": true},
            {"title": "Meek"}
        ]}"#,
    );
    let stubborn = d.find_window("Stubborn").unwrap();
    let meek = d.find_window("Meek").unwrap();
    d.close_window(stubborn).unwrap();
    assert!(d.find_window("Stubborn").is_some(), "refuse_close keeps the window");
    d.perform(&hotkey(&["alt", "f4"])).unwrap();
    assert!(d.find_window("Stubborn").is_some());
    d.activate_window(meek).unwrap();
    d.perform(&hotkey(&["alt", "f4"])).unwrap();
    assert!(d.find_window("Meek").is_none());
    assert_eq!(focused_title(&d), "Stubborn");
    d.close_window(meek).unwrap_err();
}

#[test]
fn scrolling_moves_the_focused_document() {
    let text: String = (0..200).map(|i| format!("line {i}\n")).collect();
    let json = serde_json::json!({"windows": [{"title": "Doc", "text": text}]}).to_string();
    let d = stub_with(&json);
    d.perform(&Action::Scroll { x: None, y: None, dx: 0, dy: -240 }).unwrap();
    assert_eq!(d.lock().windows[0].scroll, 6);
    d.perform(&Action::Scroll { x: None, y: None, dx: 0, dy: 120 }).unwrap();
    assert_eq!(d.lock().windows[0].scroll, 3);
    d.perform(&Action::Scroll { x: None, y: None, dx: 0, dy: 12000 }).unwrap();
    assert_eq!(d.lock().windows[0].scroll, 0);
}

#[test]
fn open_path_titles_follow_the_associations() {
    let d = stub_with(
        r#"{"files": {
            "C:\\Users\\Docker\\Desktop\\a.txt": "hello",
            "C:\\Users\\Docker\\Desktop\\b.xlsx": "",
            "C:\\Users\\Docker\\Desktop\\c.docx": "",
            "C:\\Users\\Docker\\Desktop\\d.pdf": "",
            "C:\\Users\\Docker\\Desktop\\e.png": "",
            "C:\\Users\\Docker\\Desktop\\f.mp4": "",
            "C:\\Users\\Docker\\Desktop\\g.xcf": "",
            "C:\\Users\\Docker\\Desktop\\h.unknownext": ""
        },
        "programs": {"gimp": {"title": "GIMP"}},
        "associations": {".xcf": "gimp"}}"#,
    );
    let check = |guest: &str, title: &str| {
        d.open_path(guest).unwrap();
        assert_eq!(d.windows().unwrap()[0].title, title, "opening {guest}");
        assert!(d.windows().unwrap()[0].focused);
    };
    check(r"C:\Users\Docker\Desktop\a.txt", "a.txt - Notepad");
    check(r"c:/users/docker/desktop/B.XLSX", "B.XLSX - LibreOffice Calc");
    check(r"C:\Users\Docker\Desktop\c.docx", "c.docx - LibreOffice Writer");
    check(r"C:\Users\Docker\Desktop\d.pdf", "d.pdf - Microsoft Edge");
    check(r"C:\Users\Docker\Desktop\e.png", "e.png - Photos");
    check(r"C:\Users\Docker\Desktop\f.mp4", "f.mp4 - VLC media player");
    check(r"C:\Users\Docker\Desktop\g.xcf", "g.xcf - GIMP");
    check(r"C:\Users\Docker\Documents", "Documents");
    let notepad = d.find_window("a.txt - Notepad").unwrap();
    assert_eq!(d.window_text(notepad).unwrap(), "hello");
    assert!(matches!(d.open_path(r"C:\Users\Docker\Desktop\missing.txt"), Err(DesktopError::NotFound(_))));
    assert!(matches!(d.open_path(r"C:\Users\Docker\Desktop\h.unknownext"), Err(DesktopError::Os { .. })));
}

#[test]
fn ctrl_s_saves_an_opened_document() {
    let d = stub_with(r#"{"files": {"C:\\Users\\Docker\\Documents\\n.txt": "old"}}"#);
    d.open_path(r"C:\Users\Docker\Documents\n.txt").unwrap();
    d.perform(&type_text(" and new")).unwrap();
    d.perform(&hotkey(&["ctrl", "s"])).unwrap();
    let saved = std::fs::read_to_string(d.map_path(r"C:\Users\Docker\Documents\n.txt").unwrap()).unwrap();
    assert_eq!(saved, "old and new");
}

#[test]
fn spawning_a_known_program_opens_its_window() {
    let d = stub();
    let pid = d.spawn(&CommandSpec::Shell("start notepad.exe".into())).unwrap();
    assert_eq!(pid, 1001);
    let w = &d.windows().unwrap()[0];
    assert_eq!(
        (w.title.as_str(), w.class_name.as_str(), w.process_name.as_str()),
        ("Untitled - Notepad", "Notepad", "notepad.exe")
    );
    assert_eq!((w.id, w.process_id, w.focused), (0x10011, 1001, true));
    let pid =
        d.spawn(&CommandSpec::Argv(vec![r"C:\Program Files\Google\Chrome\Application\chrome.exe".into()])).unwrap();
    assert_eq!(pid, 1002);
    assert_eq!(d.windows().unwrap()[0].title, "New Tab - Google Chrome");
    let out = d.run(&CommandSpec::Shell("calc".into()), &limits(1000)).unwrap();
    assert_eq!((out.exit_code, out.stdout.as_str()), (Some(0), ""));
    assert_eq!(d.windows().unwrap()[0].title, "Calculator");
    let err = d.spawn(&CommandSpec::Argv(vec!["no-such-program-xyz".into()])).unwrap_err();
    assert!(matches!(&err, DesktopError::NotFound(m) if m.contains("no-such-program-xyz")), "{err:?}");
    let err = d.spawn(&CommandSpec::Shell("no-such-program-xyz --flag".into())).unwrap_err();
    assert!(matches!(&err, DesktopError::NotFound(m) if m.contains("no-such-program-xyz")), "{err:?}");
}

#[test]
fn a_known_program_opens_a_file_argument() {
    let d = stub_with(r#"{"files": {"C:\\Users\\Docker\\Desktop\\x.txt": "from file"}}"#);
    d.spawn(&CommandSpec::Shell(r#"notepad "C:\Users\Docker\Desktop\x.txt""#.into())).unwrap();
    let w = &d.windows().unwrap()[0];
    assert_eq!(w.title, "x.txt - Notepad");
    assert_eq!(d.window_text(w.id).unwrap(), "from file");
}

#[test]
fn without_host_exec_only_simulated_programs_run_and_the_rest_is_refused() {
    let d = StubDesktop::with_config(StubConfig::default()).unwrap();
    let marker = std::env::temp_dir().join(format!("arena-stub-refused-{}", std::process::id()));
    let _ = std::fs::remove_file(&marker);
    let touch = format!("touch '{}'", marker.display());
    let refused = [
        d.spawn(&CommandSpec::Shell(touch.clone())).unwrap_err(),
        d.run(&CommandSpec::Shell(touch.clone()), &limits(1000)).unwrap_err(),
        d.run(&CommandSpec::Argv(vec!["sh".into(), "-c".into(), touch.clone()]), &limits(1000)).unwrap_err(),
        d.spawn(&CommandSpec::Argv(vec!["no-such-program-xyz".into()])).unwrap_err(),
    ];
    for err in refused {
        assert!(
            matches!(&err, DesktopError::NotFound(m) if m.contains("only its simulated programs") && m.contains("--stub-host-exec")),
            "{err:?}"
        );
    }
    // An executable file in the guest is not started either.
    let exe = d.root().join("C").join("Users").join("Docker").join("Desktop").join("tool.exe");
    std::fs::write(&exe, format!("#!/bin/sh\n{touch}\n")).unwrap();
    assert!(matches!(d.open_path(r"C:\Users\Docker\Desktop\tool.exe"), Err(DesktopError::NotFound(_))));
    assert!(!marker.exists(), "nothing ran on the host");
    // The simulated programs still open their windows.
    d.spawn(&CommandSpec::Shell("notepad".into())).unwrap();
    assert_eq!(d.windows().unwrap()[0].title, "Untitled - Notepad");
    assert!(d.probe(Component::Exec).unwrap().contains("simulated programs only"));
}

#[cfg(unix)]
#[test]
fn spawn_runs_unknown_programs_for_real() {
    let d = stub();
    let marker = d.root().join("spawned");
    let pid = d.spawn(&CommandSpec::Shell(format!("touch '{}'", marker.display()))).unwrap();
    assert!(pid > 0);
    let started = Instant::now();
    while !marker.exists() && started.elapsed() < Duration::from_secs(5) {
        std::thread::sleep(Duration::from_millis(10));
    }
    assert!(marker.exists());
}

#[cfg(unix)]
#[test]
fn run_captures_output_and_exit_codes() {
    let d = stub();
    let out = d.run(&CommandSpec::Argv(vec!["echo".into(), "hello world".into()]), &limits(5000)).unwrap();
    assert_eq!((out.exit_code, out.stdout.as_str(), out.timed_out), (Some(0), "hello world\n", false));
    let out =
        d.run(&CommandSpec::Shell("printf 'a\\r\\nb\\rc' ; echo oops >&2; exit 3".into()), &limits(5000)).unwrap();
    assert_eq!(out.exit_code, Some(3));
    assert_eq!(out.stdout, "a\nb\nc");
    assert_eq!(out.stderr, "oops\n");
    let stdin = ExecLimits { stdin: Some(b"piped in".to_vec()), ..limits(5000) };
    let out = d.run(&CommandSpec::Argv(vec!["cat".into()]), &stdin).unwrap();
    assert_eq!(out.stdout, "piped in");
    let in_docs = ExecLimits { cwd: Some(r"C:\Users\Docker\Documents".into()), ..limits(5000) };
    let out = d.run(&CommandSpec::Shell("pwd".into()), &in_docs).unwrap();
    assert!(out.stdout.trim_end().ends_with("C/Users/Docker/Documents"), "{}", out.stdout);
    let err = d.run(&CommandSpec::Argv(vec!["no-such-program-xyz".into()]), &limits(5000)).unwrap_err();
    assert!(matches!(&err, DesktopError::NotFound(m) if m.contains("no-such-program-xyz")), "{err:?}");
}

#[cfg(unix)]
#[test]
fn run_times_out_and_kills_the_group() {
    let d = stub();
    let started = Instant::now();
    let out = d.run(&CommandSpec::Shell("sleep 5; echo late".into()), &limits(200)).unwrap();
    let took = started.elapsed();
    assert!(out.timed_out);
    assert_eq!(out.exit_code, None);
    assert!(!out.stdout.contains("late"));
    assert!(took < Duration::from_secs(3), "took {took:?}");
}

#[cfg(unix)]
#[test]
fn run_caps_output_and_keeps_draining() {
    let d = stub();
    let capped = ExecLimits { max_output_bytes: 1000, ..limits(10_000) };
    let out =
        d.run(&CommandSpec::Shell("head -c 300000 /dev/zero | tr '\\0' x; echo done >&2".into()), &capped).unwrap();
    assert_eq!(out.exit_code, Some(0), "the writer was not blocked by the cap");
    assert_eq!(out.stdout.len(), 1000);
    assert!(out.stdout_truncated);
    assert!(!out.stderr_truncated);
    assert_eq!(out.stderr, "done\n");
}

#[test]
fn registry_and_wallpaper() {
    let d = stub_with(r#"{"files": {"C:\\Users\\Docker\\Pictures\\w.png": "not really a png"}}"#);
    assert_eq!(d.wallpaper().unwrap(), None);
    d.registry_write(r"HKEY_CURRENT_USER\Software\Test", Some("N"), &RegistryValue::Qword(5)).unwrap();
    assert_eq!(d.registry_read(r"hkcu\software\test", Some("n")).unwrap(), RegistryValue::Qword(5));
    assert!(matches!(d.registry_read(r"HKCU\Software\Test", Some("M")), Err(DesktopError::NotFound(_))));
    assert!(matches!(d.registry_read(r"HKCU\Software\Nope", None), Err(DesktopError::NotFound(_))));
    assert!(matches!(d.set_wallpaper(r"C:\Users\Docker\Pictures\missing.png"), Err(DesktopError::NotFound(_))));
    d.set_wallpaper(r"C:\Users\Docker\Pictures\w.png").unwrap();
    assert_eq!(d.wallpaper().unwrap().as_deref(), Some(r"C:\Users\Docker\Pictures\w.png"));
    assert_eq!(
        d.registry_read(r"HKCU\Control Panel\Desktop", Some("Wallpaper")).unwrap(),
        RegistryValue::String(r"C:\Users\Docker\Pictures\w.png".into())
    );
    // A wallpaper that does not decode leaves the plain background.
    let frame = d.capture(false).unwrap();
    assert_eq!(frame.image.get_pixel(1000, 500).0, BACKGROUND);
}

#[test]
fn files_env_and_recycle() {
    let d = stub_with(r#"{"env": {"Extra": "1", "TEMP": "C:\\T"}}"#);
    for dir in [
        r"C:\Users\Docker\Desktop",
        r"C:\Users\Docker\AppData\Local\Temp",
        r"C:\Users\Docker\AppData\Roaming",
        r"C:\Windows",
    ] {
        assert!(d.map_path(dir).unwrap().is_dir(), "{dir}");
    }
    assert_eq!(d.env_var("userprofile").as_deref(), Some(r"C:\Users\Docker"));
    assert_eq!(d.env_var("SYSTEMROOT").as_deref(), Some(r"C:\Windows"));
    assert_eq!(d.env_var("extra").as_deref(), Some("1"));
    assert_eq!(d.env_var("TEMP").as_deref(), Some(r"C:\T"));
    assert_eq!(d.env_var("NOPE"), None);
    let local = d.map_path(r"C:\Users\Docker\Desktop\a.txt").unwrap();
    std::fs::write(&local, "x").unwrap();
    assert_eq!(d.unmap_path(&local).unwrap(), r"C:\Users\Docker\Desktop\a.txt");
    d.recycle(r"C:\Users\Docker\Desktop\a.txt").unwrap();
    assert!(!local.exists());
    assert!(d.map_path(r"C:\$Recycle.Bin\a.txt").unwrap().exists());
    assert!(matches!(d.recycle(r"C:\Users\Docker\Desktop\a.txt"), Err(DesktopError::NotFound(_))));
    assert!(matches!(d.map_path(r"\\server\share"), Err(DesktopError::InvalidInput(_))));
}

#[test]
fn a_given_root_is_used_and_kept() {
    let dir = tempfile::tempdir().unwrap();
    let d = StubDesktop::new(dir.path().to_path_buf()).unwrap();
    assert_eq!(d.map_path(r"C:\x").unwrap(), dir.path().canonicalize().unwrap().join("C").join("x"));
    drop(d);
    assert!(dir.path().join("C").join("Users").join("Docker").is_dir());
}

#[test]
fn access_masks_come_from_the_scenario_or_the_permissions() {
    let d = stub_with(r#"{"dirs": ["C:\\Locked", "C:\\Open"], "acls": {"c:\\locked": {"Docker": 1179817}}}"#);
    assert_eq!(d.directory_access_mask(r"C:\LOCKED", "docker").unwrap(), Some(1179817));
    assert_eq!(d.directory_access_mask(r"C:\Locked", "Guest").unwrap(), None);
    assert_eq!(d.directory_access_mask(r"C:\Open", "Docker").unwrap(), Some(0x1F01FF));
    assert_eq!(d.directory_access_mask(r"C:\Open", "Guest").unwrap(), None);
    assert!(matches!(d.directory_access_mask(r"C:\Missing", "Docker"), Err(DesktopError::NotFound(_))));
    let open = d.map_path(r"C:\Open").unwrap();
    let mut perms = std::fs::metadata(&open).unwrap().permissions();
    perms.set_readonly(true);
    std::fs::set_permissions(&open, perms.clone()).unwrap();
    assert_eq!(d.directory_access_mask(r"C:\Open", "Docker").unwrap(), Some(0x1200A9));
    #[allow(clippy::permissions_set_readonly_false)]
    perms.set_readonly(false);
    std::fs::set_permissions(&open, perms).unwrap();
}

fn count(nodes: &[A11yNode]) -> u32 {
    nodes.iter().map(|n| 1 + count(&n.children)).sum()
}

fn depth(nodes: &[A11yNode]) -> u32 {
    nodes.iter().map(|n| 1 + depth(&n.children)).max().unwrap_or(0)
}

const A11Y_SCENARIO: &str = r#"{"windows": [
    {"title": "Explorer", "class_name": "CabinetWClass", "text": "doc", "elements": [
        {"role": "List", "class_name": "UIItemsView", "name": "Items", "enabled": true, "visible": true, "children": [
            {"role": "ListItem", "class_name": "", "name": "a", "enabled": true, "visible": true},
            {"role": "ListItem", "class_name": "", "name": "b", "enabled": true, "visible": true},
            {"role": "ListItem", "class_name": "", "name": "c", "enabled": true, "visible": true}
        ]}
    ]},
    {"title": "Hidden", "minimized": true},
    {"title": "Invisible", "visible": false}
]}"#;

#[test]
fn accessibility_mirrors_the_windows() {
    let d = stub_with(A11Y_SCENARIO);
    let tree = d.accessibility(A11yBackend::Uia, &TreeBudget::WAA, false).unwrap();
    assert!(!tree.truncated);
    let names: Vec<&str> = tree.windows.iter().map(|w| w.name.as_str()).collect();
    assert_eq!(
        names,
        ["Explorer", "Program Manager"],
        "minimised and hidden windows are left out, the desktop is last"
    );
    let listed = d.windows().unwrap();
    assert!(listed.iter().any(|w| w.title == "Invisible" && !w.visible), "hidden windows are listed, flagged");
    let explorer = &tree.windows[0];
    assert_eq!((explorer.role.as_str(), explorer.focused), ("Window", true));
    assert_eq!(explorer.states.maximized, Some(false));
    let roles: Vec<&str> = explorer.children.iter().map(|c| c.role.as_str()).collect();
    assert_eq!(roles, ["TitleBar", "List", "Document"]);
    let buttons: Vec<&str> = explorer.children[0].children.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(buttons, ["Minimize", "Maximize", "Close"]);
    assert_eq!(explorer.children[2].value.as_deref(), Some("doc"));
    assert_eq!(tree.node_count, count(&tree.windows));
    let id = d.find_window("Explorer").unwrap();
    assert!(explorer.children[1].children.iter().all(|n| n.window_id == Some(id)));
    assert_eq!(tree.coordinate_space, CoordinateSpace::Physical);

    let win32 = d.accessibility(A11yBackend::Win32, &TreeBudget::WAA, true).unwrap();
    assert_eq!(win32.windows.len(), 1, "foreground only");
    let roles: Vec<&str> = win32.windows[0].children.iter().map(|c| c.role.as_str()).collect();
    assert_eq!(roles, ["UIItemsView", "Edit"]);
    assert_eq!(win32.windows[0].role, "CabinetWClass");
}

#[test]
fn accessibility_honours_every_budget() {
    let d = stub_with(A11Y_SCENARIO);
    let full = d.accessibility(A11yBackend::Uia, &TreeBudget::WAA, false).unwrap();
    let check = |budget: TreeBudget, nodes: u32, max_depth: u32| {
        let tree = d.accessibility(A11yBackend::Uia, &budget, false).unwrap();
        assert!(tree.truncated, "{budget:?}");
        assert_eq!(tree.node_count, nodes, "{budget:?}");
        assert_eq!(count(&tree.windows), nodes, "{budget:?}");
        assert!(depth(&tree.windows) <= max_depth, "{budget:?}");
    };
    // Depth 1: the two windows alone.
    check(TreeBudget { max_depth: 1, ..TreeBudget::WAA }, 2, 1);
    // Depth 2: windows, their direct children (3 under Explorer, 1 under the desktop).
    check(TreeBudget { max_depth: 2, ..TreeBudget::WAA }, 6, 2);
    // One child a node: one window, its title bar, one button.
    check(TreeBudget { max_children: 1, ..TreeBudget::WAA }, 3, 3);
    check(TreeBudget { max_nodes: 5, ..TreeBudget::WAA }, 5, 50);
    check(TreeBudget { max_depth: 0, ..TreeBudget::WAA }, 0, 0);
    check(TreeBudget { max_ms: 0, ..TreeBudget::WAA }, 0, 0);
    let exact = TreeBudget { max_nodes: full.node_count, ..TreeBudget::WAA };
    assert!(!d.accessibility(A11yBackend::Uia, &exact, false).unwrap().truncated);
    assert!(matches!(
        d.accessibility(A11yBackend::Unknown, &TreeBudget::WAA, false),
        Err(DesktopError::InvalidInput(_))
    ));
}

#[test]
fn capture_shows_focus_and_the_cursor() {
    let d = stub_with(
        r#"{"windows": [
            {"title": "Front", "rect": {"x": 100, "y": 100, "width": 400, "height": 300}},
            {"title": "Back", "rect": {"x": 700, "y": 100, "width": 400, "height": 300}}
        ], "cursor": {"x": 1000, "y": 600}}"#,
    );
    // A point in each title bar, clear of the title text and the caption buttons.
    let front = (300, 104);
    let back = (900, 104);
    let frame = d.capture(false).unwrap();
    assert_eq!((frame.image.width(), frame.image.height()), (1440, 900));
    assert_eq!(frame.image.get_pixel(front.0, front.1).0, TITLE_FOCUSED);
    assert_eq!(frame.image.get_pixel(back.0, back.1).0, TITLE_UNFOCUSED);
    assert_eq!(frame.image.get_pixel(1300, 50).0, BACKGROUND);
    assert!(!frame.cursor_drawn);
    assert_eq!(frame.image.get_pixel(1001, 602).0, BACKGROUND);
    d.activate_window(d.find_window("Back").unwrap()).unwrap();
    let frame = d.capture(true).unwrap();
    assert_eq!(frame.image.get_pixel(front.0, front.1).0, TITLE_UNFOCUSED);
    assert_eq!(frame.image.get_pixel(back.0, back.1).0, TITLE_FOCUSED);
    assert!(frame.cursor_drawn);
    assert_eq!(frame.cursor, Some(Point::new(1000, 600)));
    assert_eq!(frame.image.get_pixel(1000, 600).0, [0, 0, 0, 255], "the cursor's tip");
    assert_eq!(frame.image.get_pixel(1001, 602).0, [255, 255, 255, 255], "the cursor's fill");
    // The title text is drawn: some pixel of the title area differs from the bar colour.
    let title_area = (110..200).flat_map(|x| (108..124).map(move |y| (x, y)));
    assert!(title_area.into_iter().any(|(x, y)| frame.image.get_pixel(x, y).0 != TITLE_UNFOCUSED));
}

#[test]
fn capture_draws_a_decodable_wallpaper() {
    let d = StubDesktop::with_config(StubConfig {
        scenario: Some(Scenario::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/example.json")).unwrap()),
        ..StubConfig::default()
    })
    .unwrap();
    let frame = d.capture(false).unwrap();
    assert_eq!((frame.image.width(), frame.image.height()), (1280, 800), "the scenario's screen wins");
    // The 2x2 wallpaper is scaled up: its top-right quadrant is green.
    let p = frame.image.get_pixel(1270, 10).0;
    assert!(p[1] > 150 && p[0] < 100, "{p:?}");
}

#[test]
fn the_example_scenario_seeds_everything() {
    let scenario = Scenario::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/example.json")).unwrap();
    let d = StubDesktop::with_config(StubConfig { scenario: Some(scenario), ..StubConfig::default() }).unwrap();
    assert_eq!(titles(&d), ["notes.txt - Notepad", "Documents", "New Tab - Google Chrome", "Program Manager"]);
    assert_eq!(focused_title(&d), "notes.txt - Notepad");
    let windows = d.windows().unwrap();
    assert_eq!(windows[1].process_id, windows[3].process_id, "explorer windows share explorer.exe");
    assert!(windows[2].minimized);
    assert_eq!(d.clipboard_get().unwrap(), ClipboardData::Text("copied earlier".into()));
    assert_eq!(d.registry_read(r"HKCU\Software\Arena\Example", Some("Enabled")).unwrap(), RegistryValue::Dword(1));
    assert_eq!(
        d.registry_read(r"HKCU\Software\Arena\Example", None).unwrap(),
        RegistryValue::String("default value".into())
    );
    assert_eq!(d.env_var("arena_example").as_deref(), Some("yes"));
    assert!(d.map_path(r"D:\Data").unwrap().is_dir());
    assert_eq!(
        d.directory_access_mask(r"C:\Users\Docker\Documents\Projects", "Administrators").unwrap(),
        Some(2032127)
    );
    assert_eq!(d.cursor_position().unwrap(), Point::new(640, 400));
    d.open_path(r"C:\Users\Docker\Documents\report.csv").unwrap();
    assert_eq!(titles(&d)[0], "report.csv - LibreOffice Calc");
}

#[test]
fn desktop_icons_open_on_double_click() {
    let d = stub_with(
        r#"{"files": {"C:\\Users\\Docker\\Desktop\\b.txt": "bee", "C:\\Users\\Docker\\Desktop\\a.txt": "ay"}}"#,
    );
    let tree = d.accessibility(A11yBackend::Uia, &TreeBudget::WAA, false).unwrap();
    let icons: Vec<&str> = tree.windows[0].children[0].children.iter().map(|n| n.name.as_str()).collect();
    assert_eq!(icons, ["a.txt", "b.txt"]);
    let second = tree.windows[0].children[0].children[1].rect.unwrap().center();
    d.perform(&Action::DoubleClick { x: Some(second.x), y: Some(second.y) }).unwrap();
    assert_eq!(titles(&d)[0], "b.txt - Notepad");
}

#[test]
fn the_taskbar_switches_windows() {
    let d = stub_with(r#"{"windows": [{"title": "One"}, {"title": "Two"}]}"#);
    let buttons = render::taskbar_buttons(&d.lock());
    assert_eq!(buttons.len(), 2);
    // Oldest first: "Two" was opened first (the list is topmost first).
    let two = buttons[0].1.center();
    d.perform(&click(two.x, two.y)).unwrap();
    assert_eq!(focused_title(&d), "Two");
    d.perform(&click(two.x, two.y)).unwrap();
    assert!(d.windows().unwrap().iter().any(|w| w.title == "Two" && w.minimized));
    d.perform(&click(two.x, two.y)).unwrap();
    assert_eq!(focused_title(&d), "Two");
}

#[test]
fn probes_exercise_each_component() {
    let d = stub();
    for component in Component::ALL {
        let detail = d.probe(component).unwrap();
        assert!(!detail.is_empty(), "{component:?}");
    }
    assert!(matches!(d.probe(Component::Unknown), Err(DesktopError::InvalidInput(_))));
    assert!(!d.shutdown_requested());
    d.shutdown().unwrap();
    assert!(d.shutdown_requested());
}

#[test]
fn the_clipboard_holds_images() {
    let d = stub();
    let img = image::RgbaImage::from_pixel(3, 2, image::Rgba([1, 2, 3, 255]));
    d.clipboard_set(&ClipboardData::Image(img.clone())).unwrap();
    assert_eq!(d.clipboard_get().unwrap(), ClipboardData::Image(img));
    d.clipboard_set(&ClipboardData::Empty).unwrap();
    assert_eq!(d.clipboard_get().unwrap(), ClipboardData::Empty);
}

#[test]
fn the_stub_is_shared_across_threads() {
    let d = std::sync::Arc::new(stub());
    let id = open_notepad(&d);
    let handles: Vec<_> = (0..4)
        .map(|_| {
            let d = std::sync::Arc::clone(&d);
            std::thread::spawn(move || {
                for _ in 0..25 {
                    d.perform(&type_text("x")).unwrap();
                }
            })
        })
        .collect();
    for h in handles {
        h.join().unwrap();
    }
    assert_eq!(d.window_text(id).unwrap().len(), 100);
    assert_eq!(d.action_log().len(), 100);
}

#[test]
fn starting_a_document_opens_it() {
    let d = stub_with(r#"{"files": {"C:\\Users\\Docker\\Desktop\\r.csv": "a,b"}}"#);
    d.spawn(&CommandSpec::Shell(r#"start "" "C:\Users\Docker\Desktop\r.csv""#.into())).unwrap();
    assert_eq!(titles(&d)[0], "r.csv - LibreOffice Calc");
    let out = d.run(&CommandSpec::Shell(r"cmd /c start C:\Users\Docker\Desktop".into()), &limits(1000)).unwrap();
    assert_eq!(out.exit_code, Some(0));
    assert_eq!(titles(&d)[0], "Desktop");
}

#[test]
fn the_uia_stage_recreates_an_empty_ui_automation_exactly_once_per_check() {
    let window = r#"{"title": "Untitled - Notepad", "class_name": "Notepad", "text": "x"}"#;
    let cured = stub_with(&format!(r#"{{"uia_empty_until_recreated": true, "windows": [{window}]}}"#));
    assert!(cured.probe(Component::Uia).unwrap().contains("re-created"));
    assert_eq!(cured.uia_recreations(), 1);
    // Cured: the next check reads nodes at once and re-creates nothing.
    assert!(cured.probe(Component::Uia).unwrap().contains("nodes of the foreground window"));
    assert_eq!(cured.uia_recreations(), 1);

    let broken = stub_with(&format!(r#"{{"uia_empty": true, "windows": [{window}]}}"#));
    let err = broken.probe(Component::Uia).unwrap_err().to_string();
    assert!(err.contains("after re-creating"), "{err}");
    assert_eq!(broken.uia_recreations(), 1);

    // Nothing in front: an empty tree is the right answer, and nothing is re-created.
    let desktop_only = stub_with(r#"{"uia_empty": true}"#);
    assert!(desktop_only.probe(Component::Uia).unwrap().contains("no window in front"));
    assert_eq!(desktop_only.uia_recreations(), 0);
}

#[test]
fn a_slow_bulk_fetch_is_paid_only_by_uia_and_element_costs_by_both() {
    let d = stub_with(
        r#"{"windows": [{"title": "Slow", "bulk_fetch_ms": 5000, "elements": [
            {"role": "Button", "class_name": "", "name": "b", "enabled": true, "visible": true}]}]}"#,
    );
    let budget = TreeBudget { max_ms: 400, ..TreeBudget::WAA };
    let uia = d.accessibility(A11yBackend::Uia, &budget, false).unwrap();
    let walked = &uia.windows_walked[0];
    assert!(walked.partial, "{walked:?}");
    let win32 = d.accessibility(A11yBackend::Win32, &budget, false).unwrap();
    assert!(!win32.windows_walked[0].partial, "the win32 source has no bulk fetch");
    assert!(!win32.truncated);
}

/// A bulk fetch that a busy provider keeps past its timeout (the scenario's
/// `bulk_fetch_hangs`) is abandoned at its half of the window's time, and the
/// element-by-element read runs at once, not after the fetch: the walk ends
/// within its budget with the window's elements, while the fetch still runs.
#[test]
fn the_element_by_element_read_never_waits_behind_a_hung_bulk_fetch() {
    let d = stub_with(
        r#"{"windows": [{"title": "Heavy", "bulk_fetch_ms": 30000, "bulk_fetch_hangs": true, "elements": [
            {"role": "Button", "class_name": "", "name": "first", "enabled": true, "visible": true},
            {"role": "Button", "class_name": "", "name": "second", "enabled": true, "visible": true}]}]}"#,
    );
    let budget = TreeBudget { max_ms: 1000, ..TreeBudget::WAA };
    let started = std::time::Instant::now();
    let tree = d.accessibility(A11yBackend::Uia, &budget, true).unwrap();
    let took = started.elapsed();
    assert!(took < std::time::Duration::from_secs(10), "the walk waited for the hung fetch: {took:?}");
    let walked = &tree.windows_walked[0];
    assert!(walked.partial, "{walked:?}");
    let names: Vec<&str> = tree.windows[0].children.iter().map(|c| c.name.as_str()).collect();
    assert!(names.contains(&"first") && names.contains(&"second"), "{names:?}");
}

/// The Run dialog's command field and buttons, from its window.
fn run_dialog_parts(d: &StubDesktop) -> super::window::DialogParts {
    let state = d.lock();
    let run = state.windows.iter().find(|w| w.title == "Run" && w.class_name == "#32770").expect("a Run dialog");
    run.dialog_parts().expect("the Run dialog's controls")
}

#[test]
fn win_r_opens_the_run_dialog_which_types_draws_and_walks() {
    let d = stub();
    d.perform(&hotkey(&["win", "r"])).unwrap();
    let run = d.windows().unwrap().into_iter().next().unwrap();
    assert_eq!(
        (run.title.as_str(), run.class_name.as_str(), run.process_name.as_str(), run.process_id, run.focused),
        ("Run", "#32770", "explorer.exe", 1000, true),
        "the shell's dialog, owned by explorer.exe"
    );
    assert!(run.rect.x < 100 && run.rect.bottom() > 700, "bottom left, as Windows places it: {:?}", run.rect);
    let parts = run_dialog_parts(&d);
    let (_, field) = parts.field.unwrap();
    let blank = d.capture(false).unwrap();
    assert_eq!(blank.image.get_pixel(field.x as u32 + 20, field.y as u32 + 2).0, [255, 255, 255, 255], "the field");

    d.perform(&type_text("notepaX")).unwrap();
    d.perform(&key("backspace")).unwrap();
    d.perform(&type_text("d")).unwrap();
    assert_eq!(d.window_text(run.id).as_deref(), Some("notepad"));
    let typed = d.capture(false).unwrap();
    let field_pixels = |img: &image::RgbaImage| -> Vec<[u8; 4]> {
        (field.x..field.right())
            .flat_map(|x| (field.y..field.bottom()).map(move |y| (x as u32, y as u32)))
            .map(|(x, y)| img.get_pixel(x, y).0)
            .collect()
    };
    assert_ne!(field_pixels(&blank.image), field_pixels(&typed.image), "the command is drawn in the field");

    for backend in [A11yBackend::Uia, A11yBackend::Win32] {
        let tree = d.accessibility(backend, &TreeBudget::WAA, true).unwrap();
        let node = &tree.windows[0];
        assert_eq!(node.name, "Run");
        let mut edits = Vec::new();
        let mut stack: Vec<&A11yNode> = vec![node];
        while let Some(n) = stack.pop() {
            if n.role == "Edit" {
                edits.push(n);
            }
            stack.extend(n.children.iter());
        }
        assert_eq!(edits.len(), 1, "{backend:?}: one edit field");
        assert_eq!((edits[0].name.as_str(), edits[0].value.as_deref()), ("Open:", Some("notepad")), "{backend:?}");
        assert_eq!(edits[0].states.editable, Some(true));
        let buttons: Vec<&str> = node.children.iter().filter(|c| c.role == "Button").map(|c| c.name.as_str()).collect();
        assert!(buttons.ends_with(&["OK", "Cancel", "Browse..."]), "{backend:?}: {buttons:?}");
    }
    assert_eq!(
        d.accessibility(A11yBackend::Win32, &TreeBudget::WAA, true).unwrap().windows[0].role,
        "Dialog",
        "class #32770"
    );
}

#[test]
fn the_run_dialog_opens_folders_and_documents_through_the_launch_path() {
    let d = stub_with(
        r#"{"dirs": ["C:\\Users\\Docker\\Documents\\Reports", "C:\\Users\\Docker\\My Stuff"],
            "files": {"C:\\Users\\Docker\\Documents\\notes.txt": "hello"}}"#,
    );
    // `explorer <folder>`: a File Explorer window of the shell's process, titled after the folder.
    d.perform(&hotkey(&["win", "r"])).unwrap();
    d.perform(&type_text(r"explorer C:\Users\Docker\Documents\Reports")).unwrap();
    d.perform(&key("enter")).unwrap();
    let top = d.windows().unwrap().into_iter().next().unwrap();
    assert_eq!(
        (top.title.as_str(), top.class_name.as_str(), top.process_id, top.focused),
        ("Reports", "CabinetWClass", 1000, true)
    );
    assert!(!titles(&d).contains(&"Run".to_owned()), "the dialog closed: {:?}", titles(&d));

    // A bare folder path, with a space and no quotes, typed with its Enter as pyautogui types "\n".
    d.perform(&hotkey(&["win", "r"])).unwrap();
    assert_eq!(
        d.window_text(d.find_window("Run").unwrap()).as_deref(),
        Some(r"explorer C:\Users\Docker\Documents\Reports")
    );
    d.perform(&type_text("C:\\Users\\Docker\\My Stuff\n")).unwrap();
    assert_eq!(focused_title(&d), "My Stuff", "typing replaced the offered command: {:?}", titles(&d));

    // `notepad <file>`, typed a character at a time.
    d.perform(&hotkey(&["win", "r"])).unwrap();
    d.perform(&Action::TypeText {
        text: "notepad C:\\Users\\Docker\\Documents\\notes.txt\n".into(),
        interval_ms: Some(1),
    })
    .unwrap();
    let top = d.windows().unwrap().into_iter().next().unwrap();
    assert_eq!((top.title.as_str(), top.focused), ("notes.txt - Notepad", true));
    assert_eq!(d.window_text(top.id).as_deref(), Some("hello"));
    assert!(d.find_window("Run").is_none());
}

#[test]
fn a_run_command_that_names_nothing_gets_a_message_box() {
    let d = stub();
    d.perform(&hotkey(&["win", "r"])).unwrap();
    let run = d.find_window("Run").unwrap();
    // An empty command does nothing, as Windows' OK button is disabled then.
    d.perform(&key("enter")).unwrap();
    assert_eq!(focused_title(&d), "Run");
    d.perform(&type_text("no-such-program-xyz --flag")).unwrap();
    d.perform(&key("enter")).unwrap();
    let top = d.windows().unwrap().into_iter().next().unwrap();
    assert_eq!(
        (top.title.as_str(), top.class_name.as_str(), top.process_name.as_str(), top.focused),
        ("no-such-program-xyz --flag", "#32770", "explorer.exe", true)
    );
    let tree = d.accessibility(A11yBackend::Uia, &TreeBudget::WAA, true).unwrap();
    let texts: Vec<&str> = tree.windows[0].children.iter().map(|c| c.name.as_str()).collect();
    assert!(texts.iter().any(|t| t.contains("cannot find 'no-such-program-xyz'")), "{texts:?}");
    // Typing into the message box changes nothing; Enter dismisses it and the Run dialog is back.
    d.perform(&type_text("abc")).unwrap();
    d.perform(&key("enter")).unwrap();
    assert_eq!(focused_title(&d), "Run");
    assert_eq!(d.window_text(run).as_deref(), Some("no-such-program-xyz --flag"));
    // A shell line with operators is nothing the dialog starts either: no host process runs.
    d.perform(&hotkey(&["ctrl", "a"])).unwrap();
    d.perform(&type_text("touch x && echo y")).unwrap();
    d.perform(&key("enter")).unwrap();
    assert_eq!(focused_title(&d), "touch x && echo y");
    d.perform(&key("esc")).unwrap();
    d.perform(&key("esc")).unwrap();
    assert_eq!(titles(&d), ["Program Manager"], "esc closed both");
}

#[test]
fn the_run_dialog_buttons_click() {
    let d = stub_with(r#"{"dirs": ["C:\\Users\\Docker\\Documents\\Reports"]}"#);
    d.perform(&hotkey(&["win", "r"])).unwrap();
    let parts = run_dialog_parts(&d);
    let cancel = parts.buttons.iter().find(|(b, _)| *b == super::window::DialogButton::Cancel).unwrap().1;
    d.perform(&click(cancel.center().x, cancel.center().y)).unwrap();
    assert_eq!(titles(&d), ["Program Manager"]);
    d.perform(&hotkey(&["win", "r"])).unwrap();
    d.perform(&type_text(r"C:\Users\Docker\Documents\Reports")).unwrap();
    let ok = parts.buttons[0].1;
    d.perform(&click(ok.center().x, ok.center().y)).unwrap();
    assert_eq!(focused_title(&d), "Reports");
    assert!(d.find_window("Run").is_none());
}

#[test]
fn win_e_opens_file_explorer() {
    let d = stub_with(r#"{"dirs": ["C:\\Users\\Docker\\Documents"]}"#);
    d.perform(&hotkey(&["win", "e"])).unwrap();
    let top = d.windows().unwrap().into_iter().next().unwrap();
    assert_eq!(
        (top.title.as_str(), top.class_name.as_str(), top.process_name.as_str(), top.process_id, top.focused),
        ("File Explorer", "CabinetWClass", "explorer.exe", 1000, true)
    );
    // A window like the others File Explorer opens: the user's folder listed, nothing to type into.
    d.perform(&type_text("hello")).unwrap();
    assert_eq!(d.window_text(top.id), None, "no text document in File Explorer");
    let tree = d.accessibility(A11yBackend::Uia, &TreeBudget::WAA, true).unwrap();
    let roles: Vec<&str> = tree.windows[0].children.iter().map(|c| c.role.as_str()).collect();
    assert_eq!(roles, ["TitleBar", "Tree", "List"], "no Document: {roles:?}");
    let items: Vec<&str> = tree.windows[0].children[2].children.iter().map(|c| c.name.as_str()).collect();
    assert!(items.contains(&"Documents") && items.contains(&"Desktop"), "{items:?}");
}

#[test]
fn file_explorer_lists_its_folder_in_the_tree_and_on_the_screen() {
    let d = stub_with(
        r#"{"dirs": ["C:\\Users\\Docker\\Documents\\Reports\\2024"],
            "files": {"C:\\Users\\Docker\\Documents\\Reports\\b.txt": "b",
                      "C:\\Users\\Docker\\Documents\\Reports\\a.xlsx": "a"}}"#,
    );
    d.open_path(r"C:\Users\Docker\Documents\Reports").unwrap();
    let id = d.find_window("Reports").unwrap();
    let blank = d.capture(false).unwrap();
    let tree = d.accessibility(A11yBackend::Uia, &TreeBudget::WAA, true).unwrap();
    let window = &tree.windows[0];
    let nav = &window.children[1];
    assert_eq!((nav.role.as_str(), nav.name.as_str()), ("Tree", "Navigation Pane"));
    assert!(nav.children.iter().any(|n| n.role == "TreeItem" && n.name == "Documents"));
    let list = &window.children[2];
    assert_eq!((list.role.as_str(), list.name.as_str()), ("List", "Items View"));
    let names: Vec<&str> = list.children.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, ["2024", "a.xlsx", "b.txt"], "the folder's entries, sorted as the shell sorts them");
    assert!(list.children.iter().all(|c| c.role == "ListItem" && c.window_id == Some(id)));
    // Each item is drawn where the tree says it is: its row holds text pixels.
    let row = list.children[1].rect.expect("a rect");
    let inked = (row.x..row.x + 40)
        .flat_map(|x| (row.y..row.bottom()).map(move |y| (x, y)))
        .filter(|&(x, y)| blank.image.get_pixel(x as u32, y as u32).0 == [20, 20, 20, 255])
        .count();
    assert!(inked > 10, "the name is drawn in its row ({inked} dark pixels)");
    // A file that appears is listed at once, as File Explorer refreshes.
    std::fs::write(d.map_path(r"C:\Users\Docker\Documents\Reports\c.md").unwrap(), "c").unwrap();
    let tree = d.accessibility(A11yBackend::Win32, &TreeBudget::WAA, true).unwrap();
    let list = tree.windows[0].children.iter().find(|c| c.name == "Items View").expect("the list");
    assert_eq!(list.role, "ListView");
    assert_eq!(list.children.last().map(|c| c.name.as_str()), Some("c.md"));
}
