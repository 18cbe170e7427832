//! Pins the JSON wire form of every shared type with insta snapshots, one
//! hand-built example each, so a change to a field name, tag or default shows
//! up as a snapshot diff rather than as a host that cannot talk to its guest.

use arena_shared::action::{Action, ActionBatch, ActionReport, MouseButton};
use arena_shared::clipboard::ClipboardContent;
use arena_shared::cmdline::CommandSpec;
use arena_shared::error::{ErrorBody, ErrorCode};
use arena_shared::exec::{ExecRequest, ExecResult, LaunchRequest, LaunchResult};
use arena_shared::files::{
    DirEntry, DirListing, Exists, FileKind, FileStat, FileWritten, KnownFolder, KnownFolders, MkdirRequest, PathQuery,
    WriteQuery,
};
use arena_shared::geometry::{CoordinateSpace, Point, Rect};
use arena_shared::health::{Component, ComponentHealth, HealthReport, Readiness};
use arena_shared::observation::{
    A11yBackend, A11yNode, A11yQuery, A11yStates, A11yTree, ImageFormat, MonitorInfo, ScreenInfo, ScreenshotMeta,
    ScreenshotQuery, TreeBudget, WindowInfo, WindowTarget,
};
use arena_shared::registry::{RegistryQuery, RegistryRead, RegistryValue, RegistryWrite};
use insta::assert_json_snapshot;

#[test]
fn geometry() {
    assert_json_snapshot!("point", Point::new(10, -20));
    assert_json_snapshot!("rect", Rect::new(0, 0, 1440, 900));
    assert_json_snapshot!(
        "coordinate_spaces",
        [CoordinateSpace::Physical, CoordinateSpace::Logical, CoordinateSpace::Image]
    );
}

#[test]
fn actions() {
    let batch = ActionBatch {
        actions: vec![
            Action::MoveTo { x: 10, y: 20 },
            Action::MoveRel { dx: -5, dy: 5 },
            Action::Click { x: Some(100), y: Some(200), button: MouseButton::Left, count: 1 },
            Action::Click { x: None, y: None, button: MouseButton::Right, count: 2 },
            Action::DoubleClick { x: Some(1), y: Some(2) },
            Action::RightClick { x: None, y: None },
            Action::MouseDown { button: MouseButton::Middle, x: None, y: None },
            Action::MouseUp { button: MouseButton::Left, x: Some(3), y: Some(4) },
            Action::Drag {
                from: Some(Point::new(1, 1)),
                to: Point::new(50, 60),
                button: MouseButton::Left,
                duration_ms: Some(500),
            },
            Action::Scroll { x: Some(700), y: Some(400), dx: 0, dy: -240 },
            Action::KeyPress { key: "enter".into(), presses: 1 },
            Action::KeyPress { key: "tab".into(), presses: 3 },
            Action::Hotkey { keys: vec!["ctrl".into(), "shift".into(), "s".into()] },
            Action::KeyDown { key: "shift".into() },
            Action::KeyUp { key: "shift".into() },
            Action::TypeText { text: "héllo\n".into(), interval_ms: Some(20) },
            Action::Wait { ms: 500 },
        ],
    };
    assert_json_snapshot!("action_batch", batch);
    assert_json_snapshot!("action_report", ActionReport { executed: 17, cursor: Point::new(50, 60), elapsed_ms: 612 });
}

fn rect() -> Rect {
    Rect::new(100, 50, 800, 600)
}

#[test]
fn observations() {
    assert_json_snapshot!(
        "screen_info",
        ScreenInfo {
            physical_width: 2880,
            physical_height: 1800,
            logical_width: 1440,
            logical_height: 900,
            scale_factor: 2.0,
            monitors: vec![MonitorInfo {
                name: r"\\.\DISPLAY1".into(),
                rect: Rect::new(0, 0, 2880, 1800),
                scale_factor: 2.0,
                primary: true
            }],
            coordinate_space: CoordinateSpace::Physical,
        }
    );
    assert_json_snapshot!(
        "screenshot_query",
        ScreenshotQuery { format: ImageFormat::Jpeg, quality: Some(80), max_side: Some(1280), cursor: Some(false) }
    );
    assert_json_snapshot!(
        "screenshot_meta",
        ScreenshotMeta {
            width: 1280,
            height: 800,
            physical_width: 2560,
            physical_height: 1600,
            scale: 2.0,
            format: ImageFormat::Png,
            coordinate_space: CoordinateSpace::Image,
            cursor: Some(Point::new(640, 400)),
            cursor_drawn: true,
            black_frame: false,
            capture_ms: 31,
        }
    );
    assert_json_snapshot!(
        "window_info",
        WindowInfo {
            id: 0x10010,
            title: "Untitled - Notepad".into(),
            class_name: "Notepad".into(),
            process_id: 1000,
            process_name: "notepad.exe".into(),
            rect: rect(),
            visible: true,
            minimized: false,
            maximized: false,
            focused: true,
            z_order: 0,
        }
    );
    assert_json_snapshot!(
        "window_target",
        [WindowTarget { id: Some(65552), title: None }, WindowTarget { id: None, title: Some("notepad".into()) }]
    );
    let edit = A11yNode {
        role: "Edit".into(),
        class_name: "Edit".into(),
        name: "Text Editor".into(),
        value: Some("hello".into()),
        text: None,
        rect: Some(Rect::new(110, 90, 780, 550)),
        enabled: true,
        visible: true,
        focused: true,
        states: A11yStates { editable: Some(true), ..A11yStates::default() },
        window_id: Some(0x10010),
        children: vec![],
    };
    let window = A11yNode {
        role: "Window".into(),
        class_name: "Notepad".into(),
        name: "Untitled - Notepad".into(),
        rect: Some(rect()),
        enabled: true,
        visible: true,
        states: A11yStates { minimized: Some(false), maximized: Some(false), ..A11yStates::default() },
        window_id: Some(0x10010),
        children: vec![edit],
        ..A11yNode::default()
    };
    assert_json_snapshot!(
        "a11y_tree",
        A11yTree {
            backend: A11yBackend::Uia,
            windows: vec![window],
            truncated: false,
            node_count: 2,
            elapsed_ms: 4,
            coordinate_space: CoordinateSpace::Physical,
            windows_walked: Vec::new(),
        }
    );
    assert_json_snapshot!(
        "a11y_query",
        A11yQuery {
            backend: A11yBackend::Win32,
            max_depth: Some(10),
            max_children: None,
            max_nodes: Some(5000),
            max_ms: Some(2000),
            foreground_only: true
        }
    );
    assert_json_snapshot!("tree_budget_waa", TreeBudget::WAA);
}

#[test]
fn programs() {
    assert_json_snapshot!(
        "exec_request",
        ExecRequest {
            argv: vec!["cmd.exe".into(), "/c".into(), "echo hi".into()],
            shell: None,
            timeout_ms: Some(10_000),
            max_output_bytes: None,
            cwd: Some(r"C:\Users\Docker".into()),
            stdin: Some("input\n".into()),
        }
    );
    assert_json_snapshot!(
        "exec_result",
        ExecResult {
            exit_code: Some(0),
            stdout: "hi\n".into(),
            stderr: String::new(),
            stdout_truncated: false,
            stderr_truncated: false,
            timed_out: false,
            duration_ms: 42,
        }
    );
    assert_json_snapshot!(
        "launch_request",
        LaunchRequest { argv: vec!["notepad.exe".into(), r"C:\a.txt".into()], shell: None }
    );
    // A shell line travels unchanged, quotes and all; argv is then empty.
    assert_json_snapshot!(
        "exec_request_shell",
        ExecRequest::new(CommandSpec::Shell(r#"echo "a b" > "C:\Users\Docker\x y.txt""#.into()))
    );
    assert_json_snapshot!("launch_request_shell", LaunchRequest::new(CommandSpec::Shell("start notepad".into())));
    assert_json_snapshot!("launch_result", LaunchResult { pid: 4242 });
}

#[test]
fn files() {
    let path = r"C:\Users\Docker\Desktop\a.txt";
    assert_json_snapshot!("path_query", PathQuery { path: path.into(), recursive: true });
    assert_json_snapshot!(
        "file_stat",
        FileStat {
            path: path.into(),
            kind: FileKind::File,
            size: 12,
            modified_ms: Some(1_700_000_000_000),
            readonly: false,
            hidden: false
        }
    );
    assert_json_snapshot!(
        "exists",
        [Exists { exists: true, kind: Some(FileKind::Dir) }, Exists { exists: false, kind: None }]
    );
    assert_json_snapshot!(
        "dir_listing",
        DirListing {
            path: r"C:\Users\Docker\Desktop".into(),
            entries: vec![
                DirEntry { name: "a.txt".into(), kind: FileKind::File, size: 12, modified_ms: Some(1_700_000_000_000) },
                DirEntry { name: "sub".into(), kind: FileKind::Dir, size: 0, modified_ms: None },
            ],
        }
    );
    assert_json_snapshot!(
        "file_written",
        FileWritten {
            path: path.into(),
            size: 0,
            sha256: "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855".into()
        }
    );
    assert_json_snapshot!("write_query", WriteQuery { path: path.into(), create_parents: Some(false), sha256: None });
    assert_json_snapshot!("mkdir_request", MkdirRequest { path: r"C:\Users\Docker\new".into() });
    assert_json_snapshot!(
        "known_folders",
        KnownFolders {
            folders: vec![
                (KnownFolder::Desktop, r"C:\Users\Docker\Desktop".into()),
                (KnownFolder::Temp, r"C:\Users\Docker\AppData\Local\Temp".into())
            ]
        }
    );
}

#[test]
fn clipboard() {
    assert_json_snapshot!(
        "clipboard",
        [
            ClipboardContent::Empty,
            ClipboardContent::Text { text: "copied".into() },
            ClipboardContent::Image { width: 1, height: 1, png_base64: "iVBORw0KGgo=".into() },
        ]
    );
}

#[test]
fn registry() {
    let key = r"HKCU\Control Panel\Desktop";
    assert_json_snapshot!("registry_query", RegistryQuery { key: key.into(), value: Some("Wallpaper".into()) });
    assert_json_snapshot!(
        "registry_values",
        [
            RegistryValue::String("C:\\a.jpg".into()),
            RegistryValue::Dword(1),
            RegistryValue::Qword(1 << 40),
            RegistryValue::MultiString(vec!["a".into(), "b".into()]),
            RegistryValue::Binary(vec![0, 255]),
        ]
    );
    assert_json_snapshot!(
        "registry_write",
        RegistryWrite { key: key.into(), value: None, data: RegistryValue::Dword(0) }
    );
    assert_json_snapshot!(
        "registry_read",
        RegistryRead { key: key.into(), value: Some("Wallpaper".into()), data: RegistryValue::String(String::new()) }
    );
}

#[test]
fn health() {
    assert_json_snapshot!(
        "health_report",
        HealthReport {
            status: Readiness::Degraded,
            version: "0.1.0".into(),
            api_version: "1".into(),
            backend: "windows".into(),
            components: vec![
                ComponentHealth {
                    component: Component::Capture,
                    ok: true,
                    detail: "captured 1440x900".into(),
                    elapsed_ms: 12
                },
                ComponentHealth {
                    component: Component::Accessibility,
                    ok: false,
                    detail: "probe timed out after 5000 ms".into(),
                    elapsed_ms: 5000
                },
            ],
            uptime_ms: 60_000,
            auth_required: true,
            session_id: Some(1),
            integrity: Some("High, elevated (full administrator token)".into()),
            boot_id: Some("5f0c3a9e12d4b7a1".into()),
        }
    );
}

#[test]
fn errors() {
    assert_json_snapshot!(
        "error_body",
        ErrorBody { error: ErrorCode::NotFound, message: r"C:\nope: not found".into() }
    );
}

#[test]
fn enum_variants() {
    assert_json_snapshot!("mouse_buttons", [MouseButton::Left, MouseButton::Right, MouseButton::Middle]);
    assert_json_snapshot!("image_formats", [ImageFormat::Png, ImageFormat::Jpeg]);
    assert_json_snapshot!("a11y_backends", [A11yBackend::Uia, A11yBackend::Win32]);
    assert_json_snapshot!("file_kinds", [FileKind::File, FileKind::Dir, FileKind::Other]);
    assert_json_snapshot!("known_folder_names", KnownFolder::ALL);
    assert_json_snapshot!("components", Component::REPORTED);
    assert_json_snapshot!("readiness", [Readiness::Ready, Readiness::Degraded, Readiness::Starting]);
    assert_json_snapshot!(
        "error_codes",
        [
            ErrorCode::BadRequest,
            ErrorCode::Unauthorized,
            ErrorCode::NotFound,
            ErrorCode::Conflict,
            ErrorCode::PayloadTooLarge,
            ErrorCode::Unsupported,
            ErrorCode::Timeout,
            ErrorCode::Internal,
        ]
    );
}
