//! Router tests of the native `/v1/` API against the stub backend, driven with
//! `tower::ServiceExt::oneshot` (no sockets).

use std::sync::Arc;

use axum::body::{Body, Bytes};
use axum::http::{header, HeaderMap, Method, Request, StatusCode};
use axum::Router;
use base64::Engine as _;
use serde::de::DeserializeOwned;
use serde_json::{json, Value};
use tower::ServiceExt as _;

use arena_guest::config::ServerConfig;
use arena_guest::desktop::stub::{StubConfig, StubDesktop};
use arena_guest::state::AppState;
use arena_shared::action::ActionReport;
use arena_shared::clipboard::ClipboardContent;
use arena_shared::error::{ErrorBody, ErrorCode};
use arena_shared::exec::{ExecResult, LaunchResult};
use arena_shared::files::{DirListing, Exists, FileKind, FileStat, FileWritten, KnownFolder, KnownFolders};
use arena_shared::geometry::{CoordinateSpace, Point};
use arena_shared::health::{Component, HealthReport, Readiness};
use arena_shared::observation::{A11yNode, A11yTree, ImageFormat, ScreenInfo, ScreenshotMeta, WindowInfo};
use arena_shared::registry::{RegistryRead, RegistryValue};

const TOKEN: &str = "0123456789abcdef0123";

/// A router over a fresh stub whose drives live in a temporary directory.
struct TestApp {
    router: Router,
    dir: tempfile::TempDir,
}

/// What a request answered.
struct Answer {
    status: StatusCode,
    headers: HeaderMap,
    body: Bytes,
}

impl Answer {
    fn json<T: DeserializeOwned>(&self) -> T {
        match serde_json::from_slice(&self.body) {
            Ok(v) => v,
            Err(err) => panic!(
                "status {}: body {:?} is not the expected JSON: {err}",
                self.status,
                String::from_utf8_lossy(&self.body)
            ),
        }
    }

    /// Asserts an error answer: its status, the one error body shape, and a message mentioning `needle`.
    fn assert_error(&self, status: StatusCode, code: ErrorCode, needle: &str) {
        assert_eq!(self.status, status, "body: {}", String::from_utf8_lossy(&self.body));
        let body: ErrorBody = self.json();
        assert_eq!(body.error, code, "{body:?}");
        assert!(body.message.contains(needle), "message {:?} lacks {needle:?}", body.message);
    }

    fn assert_status(&self, status: StatusCode) {
        assert_eq!(self.status, status, "body: {}", String::from_utf8_lossy(&self.body));
    }
}

fn app_with(token: Option<&str>) -> TestApp {
    let dir = tempfile::tempdir().expect("temp dir");
    let stub = crate::harness::stub_in(dir.path(), None, true);
    let state = AppState::new(Arc::new(stub), ServerConfig::for_stub(), token.map(str::to_owned));
    TestApp { router: arena_guest::router(state), dir }
}

fn app() -> TestApp {
    app_with(None)
}

impl TestApp {
    async fn send(&self, request: Request<Body>) -> Answer {
        let (status, headers, body) = crate::harness::send(&self.router, request).await;
        Answer { status, headers, body }
    }

    async fn get(&self, uri: &str) -> Answer {
        self.send(Request::get(uri).body(Body::empty()).unwrap()).await
    }

    async fn json(&self, method: Method, uri: &str, body: Value) -> Answer {
        let request = Request::builder()
            .method(method)
            .uri(uri)
            .header(header::CONTENT_TYPE, "application/json")
            .body(Body::from(body.to_string()))
            .unwrap();
        self.send(request).await
    }

    async fn post(&self, uri: &str, body: Value) -> Answer {
        self.json(Method::POST, uri, body).await
    }

    async fn put_bytes(&self, uri: &str, bytes: &[u8]) -> Answer {
        self.send(Request::put(uri).body(Body::from(bytes.to_vec())).unwrap()).await
    }

    async fn delete(&self, uri: &str) -> Answer {
        self.send(Request::delete(uri).body(Body::empty()).unwrap()).await
    }

    /// Launches notepad and answers its window.
    async fn notepad(&self) -> WindowInfo {
        self.post("/v1/launch", json!({"argv": ["notepad"]})).await.assert_status(StatusCode::OK);
        let windows: Vec<WindowInfo> = self.get("/v1/windows").await.json();
        windows.into_iter().find(|w| w.title.contains("Notepad")).expect("a notepad window")
    }
}

/// Percent-encodes a query value.
fn q(value: &str) -> String {
    let mut out = String::new();
    for b in value.bytes() {
        if b.is_ascii_alphanumeric() || b"-_.~".contains(&b) {
            out.push(b as char);
        } else {
            out.push_str(&format!("%{b:02X}"));
        }
    }
    out
}

fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::Digest as _;
    hex::encode(sha2::Sha256::digest(bytes))
}

fn find_node<'a>(node: &'a A11yNode, pred: &dyn Fn(&A11yNode) -> bool) -> Option<&'a A11yNode> {
    if pred(node) {
        return Some(node);
    }
    node.children.iter().find_map(|c| find_node(c, pred))
}

// ----- health and screen -----

#[tokio::test]
async fn health_lists_every_component_ok_on_the_stub() {
    let app = app();
    let answer = app.get("/v1/health").await;
    answer.assert_status(StatusCode::OK);
    let report: HealthReport = answer.json();
    assert_eq!(report.status, Readiness::Ready, "{report:?}");
    assert_eq!(report.backend, "stub");
    assert_eq!(report.api_version, arena_shared::API_VERSION);
    assert!(!report.auth_required);
    for component in Component::ALL {
        assert!(report.is_up(component), "{component:?} is not up: {report:?}");
    }
    assert_eq!(report.components.len(), Component::REPORTED.len());
}

/// The `shell` component: down while the stub's modelled shell is still starting
/// or a window is in front, without holding readiness; up on a settled desktop.
#[tokio::test]
async fn the_shell_component_waits_for_the_taskbar_and_the_desktop_in_front() {
    let late = |after: std::time::Duration| {
        let dir = tempfile::tempdir().expect("temp dir");
        let stub = StubDesktop::with_config(StubConfig {
            root: Some(dir.path().into()),
            shell_after: after,
            ..StubConfig::default()
        })
        .expect("stub");
        let mut config = ServerConfig::for_stub();
        config.health_cache_ms = 0;
        TestApp { router: arena_guest::router(AppState::new(Arc::new(stub), config, None)), dir }
    };
    let starting = late(std::time::Duration::from_secs(3600));
    let report: HealthReport = starting.get("/v1/health").await.json();
    let shell = report.shell().expect("a shell component");
    assert!(!shell.ok && shell.detail.contains("taskbar is not shown yet"), "{shell:?}");
    assert_eq!(report.status, Readiness::Ready, "the shell does not hold readiness: {report:?}");
    assert!(report.gated_up());

    let settled = late(std::time::Duration::ZERO);
    let report: HealthReport = settled.get("/v1/health").await.json();
    assert!(report.is_up(Component::Shell), "{report:?}");
    settled.post("/v1/launch", json!({"argv": ["notepad"]})).await.assert_status(StatusCode::OK);
    let report: HealthReport = settled.get("/v1/health").await.json();
    let shell = report.shell().unwrap();
    assert!(
        !shell.ok && shell.detail.contains("a window is in front") && shell.detail.contains("Notepad"),
        "{shell:?}"
    );
}

#[tokio::test]
async fn screen_reports_the_stub_size_in_physical_pixels() {
    let info: ScreenInfo = app().get("/v1/screen").await.json();
    assert_eq!((info.physical_width, info.physical_height), (1440, 900));
    assert_eq!(info.coordinate_space, CoordinateSpace::Physical);
}

#[tokio::test]
async fn screenshot_png_is_full_size_with_its_meta_header() {
    let answer = app().get("/v1/screenshot").await;
    answer.assert_status(StatusCode::OK);
    assert_eq!(answer.headers[header::CONTENT_TYPE], "image/png");
    let meta: ScreenshotMeta = serde_json::from_str(answer.headers["x-arena-screenshot"].to_str().unwrap()).unwrap();
    let image = image::load_from_memory_with_format(&answer.body, image::ImageFormat::Png).expect("a PNG");
    assert_eq!((image.width(), image.height()), (1440, 900));
    assert_eq!((meta.width, meta.height, meta.physical_width, meta.physical_height), (1440, 900, 1440, 900));
    assert_eq!(meta.scale, 1.0);
    assert_eq!(meta.format, ImageFormat::Png);
    assert_eq!(meta.coordinate_space, CoordinateSpace::Physical);
    assert!(meta.cursor.is_some() && meta.cursor_drawn);
    assert!(!meta.black_frame);
}

#[tokio::test]
async fn screenshot_jpeg_downscales_and_reports_the_scale() {
    let answer = app().get("/v1/screenshot?format=jpeg&quality=70&max_side=720&cursor=false").await;
    answer.assert_status(StatusCode::OK);
    assert_eq!(answer.headers[header::CONTENT_TYPE], "image/jpeg");
    let meta: ScreenshotMeta = serde_json::from_str(answer.headers["x-arena-screenshot"].to_str().unwrap()).unwrap();
    let image = image::load_from_memory_with_format(&answer.body, image::ImageFormat::Jpeg).expect("a JPEG");
    assert_eq!((image.width(), image.height()), (720, 450));
    assert_eq!((meta.width, meta.height), (720, 450));
    assert_eq!((meta.physical_width, meta.physical_height), (1440, 900));
    assert_eq!(meta.scale, 2.0);
    assert_eq!(meta.coordinate_space, CoordinateSpace::Image);
    assert!(!meta.cursor_drawn);
}

#[tokio::test]
async fn screenshot_rejects_bad_quality_and_sizes() {
    let app = app();
    app.get("/v1/screenshot?format=jpeg&quality=0").await.assert_error(
        StatusCode::BAD_REQUEST,
        ErrorCode::BadRequest,
        "quality",
    );
    app.get("/v1/screenshot?format=jpeg&quality=101").await.assert_error(
        StatusCode::BAD_REQUEST,
        ErrorCode::BadRequest,
        "quality",
    );
    app.get("/v1/screenshot?max_side=0").await.assert_error(StatusCode::BAD_REQUEST, ErrorCode::BadRequest, "max_side");
    app.get("/v1/screenshot?max_side=15").await.assert_error(
        StatusCode::BAD_REQUEST,
        ErrorCode::BadRequest,
        "max_side",
    );
    app.get("/v1/screenshot?format=gif").await.assert_error(StatusCode::BAD_REQUEST, ErrorCode::BadRequest, "format");
}

// ----- input and accessibility -----

#[tokio::test]
async fn actions_move_the_cursor_and_type_into_a_launched_notepad() {
    let app = app();
    let launched: LaunchResult = app.post("/v1/launch", json!({"argv": ["notepad"]})).await.json();
    assert!(launched.pid > 0);
    let windows: Vec<WindowInfo> = app.get("/v1/windows").await.json();
    let notepad = windows.iter().find(|w| w.title.contains("Notepad")).expect("notepad window");
    let body = notepad.rect.center();
    let batch = json!({"actions": [
        {"type": "move_to", "x": 5, "y": 5},
        {"type": "click", "x": body.x, "y": body.y},
        {"type": "wait", "ms": 10},
        {"type": "type_text", "text": "hello arena"},
        {"type": "move_to", "x": 300, "y": 200},
    ]});
    let answer = app.post("/v1/actions", batch).await;
    answer.assert_status(StatusCode::OK);
    let report: ActionReport = answer.json();
    assert_eq!(report.executed, 5);
    assert_eq!(report.cursor, Point::new(300, 200));

    // The cursor is reported after a batch that ends with a wait, and after an empty one.
    for actions in [json!([{"type": "move_to", "x": 40, "y": 50}, {"type": "wait", "ms": 1}]), json!([])] {
        let report: ActionReport = app.post("/v1/actions", json!({"actions": actions})).await.json();
        assert_eq!(report.cursor, Point::new(40, 50), "{actions}");
    }
    app.post("/v1/actions", json!({"actions": [{"type": "move_to", "x": 300, "y": 200}]})).await;

    let tree: A11yTree = app.get("/v1/a11y?backend=uia&foreground_only=true").await.json();
    let edit = tree
        .windows
        .iter()
        .find_map(|w| find_node(w, &|n| n.class_name == "Edit" && n.value.is_some()))
        .expect("an Edit node with a value");
    assert_eq!(edit.value.as_deref(), Some("hello arena"));
}

#[tokio::test]
async fn an_unknown_key_is_refused_before_anything_runs() {
    let app = app();
    let batch = json!({"actions": [
        {"type": "move_to", "x": 123, "y": 45},
        {"type": "hotkey", "keys": ["ctrl", "sup3rkey"]},
    ]});
    app.post("/v1/actions", batch).await.assert_error(StatusCode::BAD_REQUEST, ErrorCode::BadRequest, "sup3rkey");
    let report: ActionReport = app.post("/v1/actions", json!({"actions": []})).await.json();
    assert_eq!(report.executed, 0);
    assert_ne!(report.cursor, Point::new(123, 45), "the move before the bad key must not have run");
}

#[tokio::test]
async fn an_unknown_action_type_is_refused_with_its_index() {
    let batch = json!({"actions": [{"type": "wait", "ms": 1}, {"type": "teleport"}]});
    app().post("/v1/actions", batch).await.assert_error(StatusCode::BAD_REQUEST, ErrorCode::BadRequest, "action 1");
}

#[tokio::test]
async fn a11y_walks_the_desktop_and_rejects_bad_budgets() {
    let app = app();
    app.notepad().await;
    let tree: A11yTree = app.get("/v1/a11y?max_depth=3&max_nodes=500").await.json();
    assert!(!tree.windows.is_empty());
    assert!(tree.node_count > 0);
    app.get("/v1/a11y?max_depth=0").await.assert_error(StatusCode::BAD_REQUEST, ErrorCode::BadRequest, "max_depth");
    app.get("/v1/a11y?max_ms=200000").await.assert_error(StatusCode::BAD_REQUEST, ErrorCode::BadRequest, "max_ms");
    app.get("/v1/a11y?backend=atk").await.assert_error(StatusCode::BAD_REQUEST, ErrorCode::BadRequest, "backend");
}

// ----- windows -----

#[tokio::test]
async fn windows_activate_by_title_and_change_state() {
    let app = app();
    let notepad = app.notepad().await;
    let active: WindowInfo = app.post("/v1/windows/activate", json!({"title": "untitled - NOTEPAD"})).await.json();
    assert_eq!(active.id, notepad.id);
    assert!(active.focused);

    let minimized: WindowInfo = app.post("/v1/windows/minimize", json!({"id": notepad.id})).await.json();
    assert!(minimized.minimized);
    let restored: WindowInfo = app.post("/v1/windows/restore", json!({"id": notepad.id})).await.json();
    assert!(!restored.minimized);
    let maximized: WindowInfo = app.post("/v1/windows/maximize", json!({"id": notepad.id})).await.json();
    assert!(maximized.maximized);

    let closed: WindowInfo = app.post("/v1/windows/close", json!({"id": notepad.id})).await.json();
    assert_eq!(closed.id, notepad.id);
    let windows: Vec<WindowInfo> = app.get("/v1/windows").await.json();
    assert!(windows.iter().all(|w| w.id != notepad.id), "closed window still listed");
}

#[tokio::test]
async fn windows_targets_must_name_exactly_one_existing_window() {
    let app = app();
    let notepad = app.notepad().await;
    app.post("/v1/windows/activate", json!({"title": "No Such Program"})).await.assert_error(
        StatusCode::NOT_FOUND,
        ErrorCode::NotFound,
        "No Such Program",
    );
    app.post("/v1/windows/activate", json!({"id": notepad.id, "title": "Notepad"})).await.assert_error(
        StatusCode::BAD_REQUEST,
        ErrorCode::BadRequest,
        "exactly one",
    );
    app.post("/v1/windows/close", json!({})).await.assert_error(
        StatusCode::BAD_REQUEST,
        ErrorCode::BadRequest,
        "exactly one",
    );
    app.post("/v1/windows/close", json!({"id": 1})).await.assert_error(
        StatusCode::NOT_FOUND,
        ErrorCode::NotFound,
        "id 1",
    );
}

// ----- clipboard -----

#[tokio::test]
async fn clipboard_round_trips_text() {
    let app = app();
    let text = ClipboardContent::Text { text: "zwölf ✓".into() };
    app.json(Method::PUT, "/v1/clipboard", serde_json::to_value(&text).unwrap())
        .await
        .assert_status(StatusCode::NO_CONTENT);
    let back: ClipboardContent = app.get("/v1/clipboard").await.json();
    assert_eq!(back, text);
}

#[tokio::test]
async fn clipboard_round_trips_images() {
    let app = app();
    let image = image::RgbaImage::from_fn(7, 5, |x, y| image::Rgba([x as u8 * 30, y as u8 * 40, 200, 255]));
    let mut png = Vec::new();
    image::DynamicImage::ImageRgba8(image.clone())
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .unwrap();
    let content = json!({"kind": "image", "width": 7, "height": 5, "png_base64": base64::engine::general_purpose::STANDARD.encode(&png)});
    app.json(Method::PUT, "/v1/clipboard", content).await.assert_status(StatusCode::NO_CONTENT);
    match app.get("/v1/clipboard").await.json::<ClipboardContent>() {
        ClipboardContent::Image { width, height, png_base64 } => {
            assert_eq!((width, height), (7, 5));
            let bytes = base64::engine::general_purpose::STANDARD.decode(png_base64).unwrap();
            let back = image::load_from_memory(&bytes).unwrap().to_rgba8();
            assert_eq!(back, image);
        }
        other => panic!("expected an image, got {other:?}"),
    }
}

#[tokio::test]
async fn clipboard_refuses_bad_images_and_unknown_kinds() {
    let app = app();
    app.json(
        Method::PUT,
        "/v1/clipboard",
        json!({"kind": "image", "width": 1, "height": 1, "png_base64": "not base64!"}),
    )
    .await
    .assert_error(StatusCode::BAD_REQUEST, ErrorCode::BadRequest, "base64");
    app.json(Method::PUT, "/v1/clipboard", json!({"kind": "image", "width": 1, "height": 1, "png_base64": "aGVsbG8="}))
        .await
        .assert_error(StatusCode::BAD_REQUEST, ErrorCode::BadRequest, "png_base64");
    app.json(Method::PUT, "/v1/clipboard", json!({"kind": "rtf"})).await.assert_error(
        StatusCode::BAD_REQUEST,
        ErrorCode::BadRequest,
        "unknown clipboard kind",
    );
}

// ----- files -----

#[tokio::test]
async fn files_round_trip_with_sha256() {
    let app = app();
    let path = r"C:\Users\Docker\Desktop\notes\a.txt";
    let content = b"hello\r\nworld\n";
    let sha = sha256_hex(content);
    let answer = app.put_bytes(&format!("/v1/files?path={}&sha256={sha}", q(path)), content).await;
    answer.assert_status(StatusCode::OK);
    let written: FileWritten = answer.json();
    assert_eq!(written, FileWritten { path: path.into(), size: content.len() as u64, sha256: sha.clone() });

    // `~` is expanded with the guest's profile folder.
    let read = app.get(&format!("/v1/files?path={}", q(r"~\Desktop\notes\a.txt"))).await;
    read.assert_status(StatusCode::OK);
    assert_eq!(&read.body[..], content);
    assert_eq!(read.headers["x-arena-sha256"], sha.as_str());
    assert_eq!(read.headers[header::CONTENT_LENGTH], content.len().to_string().as_str());
    assert_eq!(read.headers[header::CONTENT_TYPE], "application/octet-stream");

    let stat: FileStat = app.get(&format!("/v1/files/stat?path={}", q(path))).await.json();
    assert_eq!((stat.kind, stat.size, stat.hidden), (FileKind::File, content.len() as u64, false));
    assert!(stat.modified_ms.is_some());

    let exists: Exists = app.get(&format!("/v1/files/exists?path={}", q(path))).await.json();
    assert_eq!(exists, Exists { exists: true, kind: Some(FileKind::File) });

    app.put_bytes(&format!("/v1/files?path={}", q(r"C:\Users\Docker\Desktop\notes\0.txt")), b"0")
        .await
        .assert_status(StatusCode::OK);
    app.post("/v1/files/mkdir", json!({"path": r"C:\Users\Docker\Desktop\notes\sub\deeper"}))
        .await
        .assert_status(StatusCode::NO_CONTENT);
    let listing: DirListing =
        app.get(&format!("/v1/files/list?path={}", q(r"C:\Users\Docker\Desktop\notes"))).await.json();
    let names: Vec<(&str, FileKind)> = listing.entries.iter().map(|e| (e.name.as_str(), e.kind)).collect();
    assert_eq!(names, [("0.txt", FileKind::File), ("a.txt", FileKind::File), ("sub", FileKind::Dir)]);

    app.delete(&format!("/v1/files?path={}", q(path))).await.assert_status(StatusCode::NO_CONTENT);
    let exists: Exists = app.get(&format!("/v1/files/exists?path={}", q(path))).await.json();
    assert_eq!(exists, Exists { exists: false, kind: None });
    app.get(&format!("/v1/files?path={}", q(path))).await.assert_error(
        StatusCode::NOT_FOUND,
        ErrorCode::NotFound,
        "a.txt",
    );
}

#[tokio::test]
async fn a_sha256_mismatch_writes_nothing() {
    let app = app();
    let path = q(r"C:\Users\Docker\keep.txt");
    app.put_bytes(&format!("/v1/files?path={path}"), b"old content").await.assert_status(StatusCode::OK);
    let wrong = sha256_hex(b"something else");
    app.put_bytes(&format!("/v1/files?path={path}&sha256={wrong}"), b"new content").await.assert_error(
        StatusCode::CONFLICT,
        ErrorCode::Conflict,
        "nothing was written",
    );
    assert_eq!(&app.get(&format!("/v1/files?path={path}")).await.body[..], b"old content");
    app.put_bytes(&format!("/v1/files?path={path}&sha256=xyz"), b"new content").await.assert_error(
        StatusCode::BAD_REQUEST,
        ErrorCode::BadRequest,
        "sha256",
    );
    let local = app.dir.path().join("C/Users/Docker");
    let stray: Vec<_> = std::fs::read_dir(&local)
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with(".tmp"))
        .collect();
    assert!(stray.is_empty(), "temporary files left behind: {stray:?}");
}

#[tokio::test]
async fn writes_without_create_parents_need_the_parent() {
    let app = app();
    let path = q(r"C:\Users\Docker\missing\dir\a.txt");
    app.put_bytes(&format!("/v1/files?path={path}&create_parents=false"), b"x").await.assert_error(
        StatusCode::NOT_FOUND,
        ErrorCode::NotFound,
        "create_parents",
    );
    let exists: Exists = app.get(&format!("/v1/files/exists?path={}", q(r"C:\Users\Docker\missing"))).await.json();
    assert!(!exists.exists);
    app.put_bytes(&format!("/v1/files?path={path}"), b"x").await.assert_status(StatusCode::OK);
}

#[tokio::test]
async fn file_paths_must_stay_absolute_and_inside_the_guest() {
    let app = app();
    let escape = q(r"C:\..\..\etc\passwd");
    app.get(&format!("/v1/files?path={escape}")).await.assert_error(
        StatusCode::BAD_REQUEST,
        ErrorCode::BadRequest,
        "climbs",
    );
    app.put_bytes(&format!("/v1/files?path={escape}"), b"x").await.assert_error(
        StatusCode::BAD_REQUEST,
        ErrorCode::BadRequest,
        "climbs",
    );
    assert!(!app.dir.path().join("etc").exists() && !app.dir.path().parent().unwrap().join("etc/passwd").exists());
    app.get(&format!("/v1/files/exists?path={}", q(r"Users\Docker\a.txt"))).await.assert_error(
        StatusCode::BAD_REQUEST,
        ErrorCode::BadRequest,
        "relative",
    );
    app.get("/v1/files/stat?path=").await.assert_error(StatusCode::BAD_REQUEST, ErrorCode::BadRequest, "empty");
    app.get("/v1/files/stat").await.assert_error(StatusCode::BAD_REQUEST, ErrorCode::BadRequest, "path");
}

#[tokio::test]
async fn file_routes_refuse_the_wrong_kind_of_thing() {
    let app = app();
    let dir = q(r"C:\Users\Docker\Documents\d");
    let file = q(r"C:\Users\Docker\Documents\d\f.txt");
    app.put_bytes(&format!("/v1/files?path={file}"), b"x").await.assert_status(StatusCode::OK);
    app.get(&format!("/v1/files?path={dir}")).await.assert_error(
        StatusCode::BAD_REQUEST,
        ErrorCode::BadRequest,
        "is a directory",
    );
    app.put_bytes(&format!("/v1/files?path={dir}"), b"x").await.assert_error(
        StatusCode::BAD_REQUEST,
        ErrorCode::BadRequest,
        "is a directory",
    );
    app.get(&format!("/v1/files/list?path={file}")).await.assert_error(
        StatusCode::BAD_REQUEST,
        ErrorCode::BadRequest,
        "not a directory",
    );
    app.get(&format!("/v1/files/list?path={}", q(r"C:\nope"))).await.assert_error(
        StatusCode::NOT_FOUND,
        ErrorCode::NotFound,
        "nope",
    );
    app.get(&format!("/v1/files/stat?path={}", q(r"C:\nope"))).await.assert_error(
        StatusCode::NOT_FOUND,
        ErrorCode::NotFound,
        "nope",
    );
    app.delete(&format!("/v1/files?path={dir}")).await.assert_error(
        StatusCode::CONFLICT,
        ErrorCode::Conflict,
        "not empty",
    );
    app.delete(&format!("/v1/files?path={}", q(r"C:\nope"))).await.assert_error(
        StatusCode::NOT_FOUND,
        ErrorCode::NotFound,
        "nope",
    );
    app.post("/v1/files/mkdir", json!({"path": r"C:\Users\Docker\Documents\d\f.txt"})).await.assert_error(
        StatusCode::CONFLICT,
        ErrorCode::Conflict,
        "not a directory",
    );
    app.delete(&format!("/v1/files?path={dir}&recursive=true")).await.assert_status(StatusCode::NO_CONTENT);
    let exists: Exists = app.get(&format!("/v1/files/exists?path={dir}")).await.json();
    assert!(!exists.exists);
}

#[tokio::test]
async fn recycle_moves_a_file_away_and_needs_it_to_exist() {
    let app = app();
    let path = r"C:\Users\Docker\Desktop\old.txt";
    app.put_bytes(&format!("/v1/files?path={}", q(path)), b"bin me").await.assert_status(StatusCode::OK);
    app.post("/v1/files/recycle", json!({"path": path})).await.assert_status(StatusCode::NO_CONTENT);
    let exists: Exists = app.get(&format!("/v1/files/exists?path={}", q(path))).await.json();
    assert!(!exists.exists);
    app.post("/v1/files/recycle", json!({"path": path})).await.assert_error(
        StatusCode::NOT_FOUND,
        ErrorCode::NotFound,
        "old.txt",
    );
}

#[tokio::test]
async fn folders_name_every_known_folder() {
    let app = app();
    let folders: KnownFolders = app.get("/v1/folders").await.json();
    let names: Vec<KnownFolder> = folders.folders.iter().map(|(f, _)| *f).collect();
    assert_eq!(names, KnownFolder::ALL);
    assert!(folders.folders.contains(&(KnownFolder::Desktop, r"C:\Users\Docker\Desktop".to_owned())), "{folders:?}");
    app.post("/v1/folders", json!({})).await.assert_error(
        StatusCode::METHOD_NOT_ALLOWED,
        ErrorCode::BadRequest,
        "POST",
    );
}

// ----- programs -----

#[tokio::test]
async fn exec_runs_a_program_and_reports_its_output() {
    let app = app();
    let answer = app.post("/v1/exec", json!({"argv": ["echo", "hello", "a b"]})).await;
    answer.assert_status(StatusCode::OK);
    let result: ExecResult = answer.json();
    assert_eq!(result.exit_code, Some(0));
    assert_eq!(result.stdout, "hello a b\n");
    assert!(!result.timed_out);

    let failing: ExecResult = app.post("/v1/exec", json!({"argv": ["sh", "-c", "echo oops >&2; exit 3"]})).await.json();
    assert_eq!((failing.exit_code, failing.stderr.as_str()), (Some(3), "oops\n"));
}

#[tokio::test]
async fn exec_times_out_with_a_200_result() {
    let result: ExecResult = app().post("/v1/exec", json!({"argv": ["sleep", "5"], "timeout_ms": 200})).await.json();
    assert!(result.timed_out, "{result:?}");
    assert_eq!(result.exit_code, None);
    assert!(result.duration_ms < 4000, "{result:?}");
}

#[tokio::test]
async fn a_read_only_file_is_not_replaced() {
    let app = app();
    let local = app.dir.path().join("C/Users/Docker/Desktop/locked.txt");
    std::fs::create_dir_all(local.parent().unwrap()).unwrap();
    std::fs::write(&local, b"old").unwrap();
    let mut permissions = std::fs::metadata(&local).unwrap().permissions();
    permissions.set_readonly(true);
    std::fs::set_permissions(&local, permissions).unwrap();
    let request =
        Request::put("/v1/files?path=C:%5CUsers%5CDocker%5CDesktop%5Clocked.txt").body(Body::from("new")).unwrap();
    app.send(request).await.assert_error(StatusCode::FORBIDDEN, ErrorCode::Forbidden, "read-only");
    assert_eq!(std::fs::read(&local).unwrap(), b"old");
    assert!(std::fs::metadata(&local).unwrap().permissions().readonly(), "the mode is kept");
}

#[tokio::test]
async fn a_nul_in_a_command_is_a_bad_request() {
    let app = app();
    app.post("/v1/exec", json!({"argv": ["echo", "a\0b"]})).await.assert_error(
        StatusCode::BAD_REQUEST,
        ErrorCode::BadRequest,
        "argv[1] contains a NUL",
    );
    app.post("/v1/launch", json!({"shell": "echo \0"})).await.assert_error(
        StatusCode::BAD_REQUEST,
        ErrorCode::BadRequest,
        "NUL",
    );
}

#[tokio::test]
async fn a_query_that_is_not_utf8_is_refused_with_the_offset() {
    let app = app();
    app.get("/v1/files/stat?path=C:%5Cab%FFc").await.assert_error(
        StatusCode::BAD_REQUEST,
        ErrorCode::BadRequest,
        "byte 0xff at offset 5",
    );
    app.get("/v1/files/exists?path=C:%5C%C3%A9t%C3%A9.txt").await.assert_status(StatusCode::OK);
}

#[tokio::test]
async fn exec_and_launch_refuse_missing_programs_and_empty_argv() {
    let app = app();
    app.post("/v1/exec", json!({"argv": ["no-such-program-xyz"]})).await.assert_error(
        StatusCode::NOT_FOUND,
        ErrorCode::NotFound,
        "no-such-program-xyz",
    );
    app.post("/v1/exec", json!({"argv": []})).await.assert_error(
        StatusCode::BAD_REQUEST,
        ErrorCode::BadRequest,
        "argv",
    );
    app.post("/v1/exec", json!({"argv": ["echo"], "timeout_ms": 0})).await.assert_error(
        StatusCode::BAD_REQUEST,
        ErrorCode::BadRequest,
        "timeout_ms",
    );
    app.post("/v1/launch", json!({"argv": []})).await.assert_error(
        StatusCode::BAD_REQUEST,
        ErrorCode::BadRequest,
        "argv",
    );
    app.post("/v1/launch", json!({"argv": ["no-such-program-xyz"]})).await.assert_error(
        StatusCode::NOT_FOUND,
        ErrorCode::NotFound,
        "no-such-program-xyz",
    );
}

#[tokio::test]
async fn open_shows_an_existing_file_and_refuses_a_missing_one() {
    let app = app();
    let path = r"C:\Users\Docker\Documents\todo.txt";
    app.put_bytes(&format!("/v1/files?path={}", q(path)), b"buy milk").await.assert_status(StatusCode::OK);
    app.post("/v1/open", json!({"path": path})).await.assert_status(StatusCode::NO_CONTENT);
    let windows: Vec<WindowInfo> = app.get("/v1/windows").await.json();
    assert!(windows.iter().any(|w| w.title.contains("todo.txt")), "{windows:?}");
    app.post("/v1/open", json!({"path": r"C:\Users\Docker\Documents\gone.txt"})).await.assert_error(
        StatusCode::NOT_FOUND,
        ErrorCode::NotFound,
        "gone.txt",
    );
}

// ----- registry and wallpaper -----

#[tokio::test]
async fn registry_values_round_trip() {
    let app = app();
    let key = r"HKCU\Software\Arena\Test";
    let write = json!({"key": key, "value": "Count", "data": {"type": "dword", "data": 42}});
    app.json(Method::PUT, "/v1/registry", write).await.assert_status(StatusCode::NO_CONTENT);
    let read: RegistryRead = app.get(&format!("/v1/registry?key={}&value=Count", q(key))).await.json();
    assert_eq!(read, RegistryRead { key: key.into(), value: Some("Count".into()), data: RegistryValue::Dword(42) });

    app.get(&format!("/v1/registry?key={}&value=Missing", q(key))).await.assert_error(
        StatusCode::NOT_FOUND,
        ErrorCode::NotFound,
        "Missing",
    );
    app.json(Method::PUT, "/v1/registry", json!({"key": key, "data": {"type": "reg_link"}})).await.assert_error(
        StatusCode::BAD_REQUEST,
        ErrorCode::BadRequest,
        "registry value type",
    );
    // A newer peer's type with data decodes to Unknown, which cannot be written either.
    app.json(Method::PUT, "/v1/registry", json!({"key": key, "data": {"type": "reg_link", "data": 1}}))
        .await
        .assert_error(StatusCode::BAD_REQUEST, ErrorCode::BadRequest, "registry value type");
    app.get("/v1/registry?key=").await.assert_error(StatusCode::BAD_REQUEST, ErrorCode::BadRequest, "key");
}

#[tokio::test]
async fn wallpaper_answers_a_path_or_null() {
    let answer = app().get("/v1/wallpaper").await;
    answer.assert_status(StatusCode::OK);
    let body: Value = answer.json();
    assert!(body["path"].is_string() || body["path"].is_null(), "{body}");
}

#[tokio::test]
async fn wallpaper_is_set_from_an_existing_image_only() {
    let app = app();
    let path = r"C:\Users\Docker\Pictures\sky.png";
    app.put_bytes(&format!("/v1/files?path={}", q(path)), b"not really a png").await.assert_status(StatusCode::OK);
    app.json(Method::PUT, "/v1/wallpaper", json!({"path": path})).await.assert_status(StatusCode::NO_CONTENT);
    let body: Value = app.get("/v1/wallpaper").await.json();
    assert_eq!(body["path"], json!(path));
    app.json(Method::PUT, "/v1/wallpaper", json!({"path": r"C:\Users\Docker\Pictures\gone.png"})).await.assert_error(
        StatusCode::NOT_FOUND,
        ErrorCode::NotFound,
        "gone.png",
    );
    let body: Value = app.get("/v1/wallpaper").await.json();
    assert_eq!(body["path"], json!(path), "a refused change keeps the old wallpaper");
}

// ----- browser (DevTools HTTP forwarded) -----

/// A router over a fresh stub whose browser debugging port is `cdp_port`.
fn app_with_cdp_port(cdp_port: u16) -> TestApp {
    let dir = tempfile::tempdir().expect("temp dir");
    let stub = crate::harness::stub_in(dir.path(), None, false);
    let mut config = ServerConfig::for_stub();
    config.cdp_port = cdp_port;
    let state = AppState::new(Arc::new(stub), config, None);
    TestApp { router: arena_guest::router(state), dir }
}

/// A fake DevTools endpoint that echoes what it received as JSON; answers its port.
async fn fake_devtools() -> u16 {
    async fn echo(method: Method, uri: axum::http::Uri, body: Bytes) -> axum::response::Response {
        let text = json!({"method": method.as_str(), "path": uri.path(), "query": uri.query(), "body": String::from_utf8_lossy(&body)});
        match uri.path() {
            // A redirect elsewhere (another port of the machine, another host).
            "/json/redirect" => {
                (StatusCode::FOUND, [(header::LOCATION, "http://127.0.0.1:9/secret")], String::new()).into_response()
            }
            "/json/huge" => (StatusCode::OK, "x".repeat(17 << 20)).into_response(),
            "/json/missing" => (StatusCode::NOT_FOUND, text.to_string()).into_response(),
            _ => (StatusCode::OK, [(header::CONTENT_TYPE, "application/json; charset=UTF-8")], text.to_string())
                .into_response(),
        }
    }
    use axum::response::IntoResponse as _;
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.expect("bind");
    let port = listener.local_addr().expect("addr").port();
    tokio::spawn(async move {
        let _ = axum::serve(listener, Router::new().fallback(echo)).await;
    });
    port
}

#[tokio::test]
async fn browser_requests_are_forwarded_with_query_body_and_status() {
    let app = app_with_cdp_port(fake_devtools().await);
    let answer = app.get("/v1/browser/json/list").await;
    answer.assert_status(StatusCode::OK);
    assert_eq!(answer.headers[header::CONTENT_TYPE], "application/json; charset=UTF-8");
    let body: Value = answer.json();
    assert_eq!((body["method"].as_str(), body["path"].as_str()), (Some("GET"), Some("/json/list")));

    let answer =
        app.send(Request::put("/v1/browser/json/new?https://example.com/a?b=1").body(Body::empty()).unwrap()).await;
    answer.assert_status(StatusCode::OK);
    let body: Value = answer.json();
    assert_eq!(body["method"], "PUT");
    assert_eq!(body["query"], "https://example.com/a?b=1");

    let answer = app.send(Request::post("/v1/browser/json/echo").body(Body::from("payload")).unwrap()).await;
    let body: Value = answer.json();
    assert_eq!((body["method"].as_str(), body["body"].as_str()), (Some("POST"), Some("payload")));

    app.get("/v1/browser/json/missing").await.assert_status(StatusCode::NOT_FOUND);
    app.delete("/v1/browser/json/list").await.assert_error(StatusCode::BAD_REQUEST, ErrorCode::BadRequest, "DELETE");
}

#[tokio::test]
async fn browser_redirects_are_not_followed_and_answers_are_bounded() {
    let app = app_with_cdp_port(fake_devtools().await);
    let redirect = app.get("/v1/browser/json/redirect").await;
    redirect.assert_status(StatusCode::FOUND);
    assert_eq!(redirect.headers[header::LOCATION], "http://127.0.0.1:9/secret", "handed back, not followed");
    app.get("/v1/browser/json/huge").await.assert_error(StatusCode::BAD_GATEWAY, ErrorCode::Internal, "over 16777216");
}

#[tokio::test]
async fn browser_requests_without_a_browser_are_a_502_naming_the_port() {
    // Bind and drop a listener to get a port nothing listens on.
    let port = {
        let listener = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
        listener.local_addr().expect("addr").port()
    };
    let app = app_with_cdp_port(port);
    app.get("/v1/browser/json/version").await.assert_error(
        StatusCode::BAD_GATEWAY,
        ErrorCode::Internal,
        &format!(
            "no browser is listening on the debugging port {port}: start Chrome with --remote-debugging-port={port}"
        ),
    );
}

// ----- protocol: errors, methods, auth -----

#[tokio::test]
async fn a_bad_json_body_is_a_400_error_body() {
    let app = app();
    let request = Request::post("/v1/actions")
        .header(header::CONTENT_TYPE, "application/json")
        .body(Body::from("{not json"))
        .unwrap();
    app.send(request).await.assert_error(StatusCode::BAD_REQUEST, ErrorCode::BadRequest, "JSON");
    app.post("/v1/actions", json!({"acts": []})).await.assert_error(
        StatusCode::BAD_REQUEST,
        ErrorCode::BadRequest,
        "actions",
    );
}

#[tokio::test]
async fn unknown_routes_and_wrong_methods_get_error_bodies() {
    let app = app();
    app.get("/v1/nothing-here").await.assert_error(StatusCode::NOT_FOUND, ErrorCode::NotFound, "/v1/nothing-here");
    app.delete("/v1/screenshot").await.assert_error(StatusCode::METHOD_NOT_ALLOWED, ErrorCode::BadRequest, "DELETE");
}

#[tokio::test]
async fn a_token_is_required_except_for_health() {
    let app = app_with(Some(TOKEN));
    app.get("/v1/screen").await.assert_error(StatusCode::UNAUTHORIZED, ErrorCode::Unauthorized, "Bearer");
    let wrong = Request::get("/v1/screen")
        .header(header::AUTHORIZATION, "Bearer 0123456789abcdef0124")
        .body(Body::empty())
        .unwrap();
    app.send(wrong).await.assert_error(StatusCode::UNAUTHORIZED, ErrorCode::Unauthorized, "Bearer");
    let right = Request::get("/v1/screen")
        .header(header::AUTHORIZATION, format!("Bearer {TOKEN}"))
        .body(Body::empty())
        .unwrap();
    app.send(right).await.assert_status(StatusCode::OK);
    // The scheme compares without regard to case (RFC 7235).
    for scheme in ["bearer", "BEARER"] {
        let right = Request::get("/v1/screen")
            .header(header::AUTHORIZATION, format!("{scheme} {TOKEN}"))
            .body(Body::empty())
            .unwrap();
        app.send(right).await.assert_status(StatusCode::OK);
    }
    let health = app.get("/v1/health").await;
    health.assert_status(StatusCode::OK);
    assert!(health.json::<HealthReport>().auth_required);
}

#[tokio::test]
async fn health_without_the_token_shows_stages_only() {
    let app = app_with(Some(TOKEN));
    let anonymous: HealthReport = app.get("/v1/health").await.json();
    assert!(!anonymous.components.is_empty());
    assert!(anonymous.components.iter().all(|c| c.detail == "up" || c.detail == "down"), "{anonymous:?}");
    let authed =
        Request::get("/v1/health").header(header::AUTHORIZATION, format!("Bearer {TOKEN}")).body(Body::empty());
    let full: HealthReport = app.send(authed.unwrap()).await.json();
    assert!(full.components.iter().any(|c| c.detail != "up" && c.detail != "down"), "{full:?}");
    assert_eq!(
        full.components.iter().map(|c| (c.component, c.ok)).collect::<Vec<_>>(),
        anonymous.components.iter().map(|c| (c.component, c.ok)).collect::<Vec<_>>(),
        "the same stages, with or without the token"
    );
}

/// Five health polls against a stub that counts its probes, with `cache_ms` of reuse.
async fn probes_for_five_polls(cache_ms: u64) -> usize {
    let dir = tempfile::tempdir().unwrap();
    let inner = crate::harness::stub_in(dir.path(), None, false);
    let desktop = Arc::new(HangsOnText::new(inner, "never"));
    let mut config = ServerConfig::for_stub();
    config.health_cache_ms = cache_ms;
    let app = TestApp { router: arena_guest::router(AppState::new(desktop.clone(), config, None)), dir };
    for _ in 0..5 {
        app.get("/v1/health").await.assert_status(StatusCode::OK);
    }
    desktop.probes.load(std::sync::atomic::Ordering::Relaxed)
}

#[tokio::test]
async fn health_reports_are_reused_within_the_cache_period() {
    // Every component but `setup`, which the server reads from its record, not the desktop.
    let per_report = Component::ALL.iter().filter(|c| **c != Component::Setup).count();
    assert_eq!(probes_for_five_polls(3_600_000).await, per_report, "one report for five polls");
    assert_eq!(probes_for_five_polls(0).await, 5 * per_report, "no reuse when the period is 0");
}

#[tokio::test]
async fn cross_site_requests_are_refused() {
    let app = app();
    let request = Request::get("/v1/screen").header(header::ORIGIN, "http://evil.example").body(Body::empty()).unwrap();
    app.send(request).await.assert_error(StatusCode::FORBIDDEN, ErrorCode::Forbidden, "cross-site");
}

#[tokio::test]
async fn drive_roots_system_folders_and_the_profile_are_never_deleted_or_recycled() {
    let app = app();
    let keep_local = app.dir.path().join("C/Users/Docker/Desktop/keep.txt");
    std::fs::create_dir_all(keep_local.parent().unwrap()).unwrap();
    std::fs::write(&keep_local, b"x").unwrap();
    for path in ["C:%5C", "C:", "C:%5CUsers", "C:%5CUsers%5CDocker", "C:%5CUsers%5CDocker%5CDesktop", "C:%5CWindows"] {
        let uri = format!("/v1/files?path={path}&recursive=true");
        app.delete(&uri).await.assert_error(StatusCode::FORBIDDEN, ErrorCode::Forbidden, "never removes");
        let recycle = app.json(Method::POST, "/v1/files/recycle", json!({"path": path.replace("%5C", "\\")})).await;
        recycle.assert_error(StatusCode::FORBIDDEN, ErrorCode::Forbidden, "never removes");
    }
    assert!(keep_local.exists(), "a file on the Desktop is still there");
    app.delete("/v1/files?path=C:%5CUsers%5CDocker%5CDesktop%5Ckeep.txt").await.assert_status(StatusCode::NO_CONTENT);
    assert!(!keep_local.exists());
}

/// A request for `uri` that says it is for `host`, as a browser's would.
fn for_host(uri: &str, host: &str) -> Request<Body> {
    Request::get(uri).header(header::HOST, host).body(Body::empty()).unwrap()
}

#[tokio::test]
async fn without_a_token_only_this_servers_host_names_are_served() {
    let app = app();
    // DNS rebinding: a page on a domain that resolves to the guest sends its own name.
    let refused = app.send(for_host("/v1/files/list?path=C:%5CUsers%5CDocker", "evil.example:5000")).await;
    refused.assert_error(StatusCode::FORBIDDEN, ErrorCode::Forbidden, "evil.example");
    app.send(for_host("/v1/clipboard", "attacker.test")).await.assert_error(
        StatusCode::FORBIDDEN,
        ErrorCode::Forbidden,
        "--allow-host",
    );
    for host in ["127.0.0.1:5000", "localhost:5000", "LOCALHOST", "[::1]:5000", "20.20.20.21:5000", "app.localhost"] {
        app.send(for_host("/v1/screen", host)).await.assert_status(StatusCode::OK);
    }
    // The legacy routes are guarded the same way, with upstream's error shape.
    let legacy = app.send(for_host("/probe", "evil.example")).await;
    assert_eq!(legacy.status, StatusCode::FORBIDDEN);
    assert_eq!(legacy.json::<Value>()["status"], "error");
}

#[tokio::test]
async fn allowed_host_names_and_a_token_let_other_names_through() {
    let dir = tempfile::tempdir().expect("temp dir");
    let stub = crate::harness::stub_in(dir.path(), None, false);
    let mut config = ServerConfig::for_stub();
    config.allow_host = vec!["guest-7.cluster.local".into()];
    let app = TestApp { router: arena_guest::router(AppState::new(Arc::new(stub), config, None)), dir };
    app.send(for_host("/v1/screen", "Guest-7.cluster.local:5000")).await.assert_status(StatusCode::OK);
    app.send(for_host("/v1/screen", "guest-8.cluster.local")).await.assert_error(
        StatusCode::FORBIDDEN,
        ErrorCode::Forbidden,
        "guest-8",
    );
    // With a token, the token is the guard: any name may carry it.
    let app = app_with(Some(TOKEN));
    let request = Request::get("/v1/screen")
        .header(header::HOST, "vm-17.example")
        .header(header::AUTHORIZATION, format!("Bearer {TOKEN}"))
        .body(Body::empty())
        .unwrap();
    app.send(request).await.assert_status(StatusCode::OK);
}

// ----- a batch that fails part-way -----

/// The stub, except that typing `fail_on` times out, as a hung window would; it
/// also counts component probes.
#[derive(Debug)]
struct HangsOnText {
    inner: StubDesktop,
    fail_on: &'static str,
    probes: std::sync::atomic::AtomicUsize,
}

impl HangsOnText {
    fn new(inner: StubDesktop, fail_on: &'static str) -> HangsOnText {
        HangsOnText { inner, fail_on, probes: std::sync::atomic::AtomicUsize::new(0) }
    }
}

mod delegate {
    use std::path::{Path, PathBuf};

    use arena_guest::desktop::{
        ClipboardData, CommandSpec, Desktop, DesktopError, DesktopResult, ExecLimits, ExecOutput, Frame, WindowState,
    };
    use arena_shared::action::Action;
    use arena_shared::files::KnownFolder;
    use arena_shared::geometry::Point;
    use arena_shared::health::Component;
    use arena_shared::observation::{A11yBackend, A11yTree, ScreenInfo, TreeBudget, WindowInfo};
    use arena_shared::registry::RegistryValue;

    use super::HangsOnText;

    impl Desktop for HangsOnText {
        fn perform(&self, action: &Action) -> DesktopResult<()> {
            match action {
                Action::TypeText { text, .. } if text == self.fail_on => {
                    Err(DesktopError::Timeout { op: "perform", ms: 1 })
                }
                other => self.inner.perform(other),
            }
        }
        fn kind(&self) -> &'static str {
            self.inner.kind()
        }
        fn probe(&self, c: Component) -> DesktopResult<String> {
            self.probes.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            self.inner.probe(c)
        }
        fn screen(&self) -> DesktopResult<ScreenInfo> {
            self.inner.screen()
        }
        fn capture(&self, c: bool) -> DesktopResult<Frame> {
            self.inner.capture(c)
        }
        fn cursor_position(&self) -> DesktopResult<Point> {
            self.inner.cursor_position()
        }
        fn windows(&self) -> DesktopResult<Vec<WindowInfo>> {
            self.inner.windows()
        }
        fn activate_window(&self, id: u64) -> DesktopResult<()> {
            self.inner.activate_window(id)
        }
        fn set_window_state(&self, id: u64, s: WindowState) -> DesktopResult<()> {
            self.inner.set_window_state(id, s)
        }
        fn close_window(&self, id: u64) -> DesktopResult<()> {
            self.inner.close_window(id)
        }
        fn accessibility(&self, b: A11yBackend, t: &TreeBudget, f: bool) -> DesktopResult<A11yTree> {
            self.inner.accessibility(b, t, f)
        }
        fn clipboard_get(&self) -> DesktopResult<ClipboardData> {
            self.inner.clipboard_get()
        }
        fn clipboard_set(&self, d: &ClipboardData) -> DesktopResult<()> {
            self.inner.clipboard_set(d)
        }
        fn map_path(&self, p: &str) -> DesktopResult<PathBuf> {
            self.inner.map_path(p)
        }
        fn unmap_path(&self, p: &Path) -> DesktopResult<String> {
            self.inner.unmap_path(p)
        }
        fn env_var(&self, n: &str) -> Option<String> {
            self.inner.env_var(n)
        }
        fn known_folder(&self, f: KnownFolder) -> DesktopResult<String> {
            self.inner.known_folder(f)
        }
        fn recycle(&self, p: &str) -> DesktopResult<()> {
            self.inner.recycle(p)
        }
        fn open_path(&self, p: &str) -> DesktopResult<()> {
            self.inner.open_path(p)
        }
        fn registry_read(&self, k: &str, v: Option<&str>) -> DesktopResult<RegistryValue> {
            self.inner.registry_read(k, v)
        }
        fn registry_write(&self, k: &str, v: Option<&str>, d: &RegistryValue) -> DesktopResult<()> {
            self.inner.registry_write(k, v, d)
        }
        fn wallpaper(&self) -> DesktopResult<Option<String>> {
            self.inner.wallpaper()
        }
        fn set_wallpaper(&self, p: &str) -> DesktopResult<()> {
            self.inner.set_wallpaper(p)
        }
        fn directory_access_mask(&self, p: &str, u: &str) -> DesktopResult<Option<u32>> {
            self.inner.directory_access_mask(p, u)
        }
        fn run(&self, c: &CommandSpec, l: &ExecLimits) -> DesktopResult<ExecOutput> {
            self.inner.run(c, l)
        }
        fn spawn(&self, c: &CommandSpec) -> DesktopResult<u32> {
            self.inner.spawn(c)
        }
        fn shutdown(&self) -> DesktopResult<()> {
            self.inner.shutdown()
        }
    }
}

#[tokio::test]
async fn a_failing_action_stops_the_batch_and_says_where() {
    let dir = tempfile::tempdir().unwrap();
    let inner = crate::harness::stub_in(dir.path(), None, false);
    let state = AppState::new(Arc::new(HangsOnText::new(inner, "boom")), ServerConfig::for_stub(), None);
    let app = TestApp { router: arena_guest::router(state), dir };
    let batch = json!({"actions": [
        {"type": "move_to", "x": 10, "y": 10},
        {"type": "type_text", "text": "boom"},
        {"type": "move_to", "x": 99, "y": 99},
    ]});
    app.post("/v1/actions", batch).await.assert_error(
        StatusCode::GATEWAY_TIMEOUT,
        ErrorCode::Timeout,
        "action 1 (type_text) failed after 1 of 3 actions ran",
    );
    let report: ActionReport = app.post("/v1/actions", json!({"actions": []})).await.json();
    assert_eq!(report.cursor, Point::new(10, 10), "the action after the failure must not run");
}

#[tokio::test]
async fn exec_passes_stdin_and_a_guest_working_folder() {
    let app = app();
    let result: ExecResult = app.post("/v1/exec", json!({"argv": ["cat"], "stdin": "piped in"})).await.json();
    assert_eq!(result.stdout, "piped in");
    app.post("/v1/files/mkdir", json!({"path": r"C:\work\here"})).await.assert_status(StatusCode::NO_CONTENT);
    let result: ExecResult = app.post("/v1/exec", json!({"argv": ["pwd"], "cwd": r"C:\work\here"})).await.json();
    assert!(result.stdout.trim_end().ends_with("/C/work/here"), "{result:?}");
}

#[tokio::test]
async fn token_files_are_read_like_an_editor_wrote_them_and_bad_tokens_stop_start_up() {
    let dir = tempfile::tempdir().unwrap();
    let state = |text: &str| {
        let file = dir.path().join("token");
        std::fs::write(&file, text).unwrap();
        let mut config = ServerConfig::for_stub();
        config.stub_root = Some(dir.path().join("root"));
        config.token_file = Some(file);
        arena_guest::build_state(config)
    };
    // A byte-order mark and CRLF, as PowerShell's Out-File writes them.
    let app = TestApp {
        router: arena_guest::router(state(&format!("\u{feff}{TOKEN}\r\n")).unwrap()),
        dir: tempfile::tempdir().unwrap(),
    };
    let request =
        Request::get("/v1/screen").header(header::AUTHORIZATION, format!("Bearer {TOKEN}")).body(Body::empty());
    app.send(request.unwrap()).await.assert_status(StatusCode::OK);
    let err = state("0123456789abcdéf0123").unwrap_err();
    assert!(format!("{err:#}").contains("printable ASCII"), "{err:#}");
    let err = state("\n").unwrap_err();
    assert!(format!("{err:#}").contains("empty"), "{err:#}");
}

/// Polls `f` until it holds, for at most ten seconds.
async fn eventually(what: &str, mut f: impl FnMut() -> bool) {
    for _ in 0..1000 {
        if f() {
            return;
        }
        tokio::time::sleep(std::time::Duration::from_millis(10)).await;
    }
    panic!("{what} did not happen within 10 s");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn slow_typing_leaves_the_desktop_to_other_calls_and_stops_when_abandoned() {
    let dir = tempfile::tempdir().unwrap();
    let stub = Arc::new(crate::harness::stub_in(dir.path(), None, false));
    let app = TestApp { router: arena_guest::router(AppState::new(stub.clone(), ServerConfig::for_stub(), None)), dir };
    app.post("/v1/launch", json!({"argv": ["notepad"]})).await.assert_status(StatusCode::OK);
    let notepad = stub.find_window("Notepad").expect("notepad opened");
    let typed = || stub.window_text(notepad).unwrap_or_default().chars().count();

    // Ten characters a second apart: nine seconds of typing in one call.
    let body = json!({"actions": [{"type": "type_text", "text": "abcdefghij", "interval_ms": 1000}]});
    let request = Request::post("/v1/actions")
        .header(header::CONTENT_TYPE, "application/json")
        .body(Body::from(body.to_string()))
        .unwrap();
    let typing = tokio::spawn(app.router.clone().oneshot(request));
    eventually("the first character", || typed() >= 1).await;

    // Meanwhile the desktop answers: the typing holds it one character at a time.
    app.get("/v1/health").await.assert_status(StatusCode::OK);
    app.get("/v1/screenshot").await.assert_status(StatusCode::OK);
    app.get("/v1/windows").await.assert_status(StatusCode::OK);
    let while_typing = typed();
    assert!(while_typing < 10, "the other calls were answered while typing was under way ({while_typing} typed)");

    // The client goes away: the call is cancelled and no more keys arrive.
    typing.abort();
    let _ = typing.await;
    let at_abort = typed();
    tokio::time::sleep(std::time::Duration::from_millis(2500)).await;
    assert!(typed() <= at_abort + 1, "typing went on after the request was dropped: {at_abort} -> {}", typed());
    assert!(typed() < 10);
}

#[tokio::test]
async fn registry_paths_past_windows_limits_are_refused_and_not_stored() {
    let app = app();
    // 39 KiB of short key names: 20 000 levels, where Windows allows 512.
    let deep = format!(r"HKCU\Software{}", r"\k".repeat(20_000));
    let write = json!({"key": deep, "value": "v", "data": {"type": "dword", "data": 1}});
    app.json(Method::PUT, "/v1/registry", write).await.assert_error(
        StatusCode::BAD_REQUEST,
        ErrorCode::BadRequest,
        "levels deep",
    );
    let long = json!({"key": format!(r"HKCU\{}", "n".repeat(300)), "data": {"type": "dword", "data": 1}});
    app.json(Method::PUT, "/v1/registry", long).await.assert_error(
        StatusCode::BAD_REQUEST,
        ErrorCode::BadRequest,
        "255",
    );
    app.get(r"/v1/registry?key=HKCU%5CSoftware%5Ck").await.assert_error(
        StatusCode::NOT_FOUND,
        ErrorCode::NotFound,
        "not found",
    );
}

#[tokio::test]
async fn temporary_files_of_interrupted_writes_are_swept_at_start_up() {
    let dir = tempfile::tempdir().unwrap();
    let stub = crate::harness::stub_in(dir.path(), None, false);
    let folder = dir.path().join("C/Users/Docker/Documents/reports");
    std::fs::create_dir_all(&folder).unwrap();
    let stale = folder.join(format!("{}x1y2z3", arena_shared::atomic::TEMP_PREFIX));
    let fresh = folder.join(format!("{}being-written", arena_shared::atomic::TEMP_PREFIX));
    let mine = folder.join("report.txt");
    for path in [&stale, &fresh, &mine] {
        std::fs::write(path, b"x").unwrap();
    }
    let hour_ago = std::time::SystemTime::now() - std::time::Duration::from_secs(3600);
    std::fs::File::options().write(true).open(&stale).unwrap().set_modified(hour_ago).unwrap();
    assert_eq!(arena_guest::sweep_leftovers(&stub), 1);
    assert!(!stale.exists(), "an old leftover is removed");
    assert!(fresh.exists(), "a file a live writer may still be writing is kept");
    assert!(mine.exists(), "the user's files are kept");
}

#[tokio::test]
async fn large_files_stream_both_ways_and_an_oversized_body_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let stub = crate::harness::stub_in(dir.path(), None, false);
    let mut config = ServerConfig::for_stub();
    config.max_body_bytes = 3 << 20;
    let app = TestApp { router: arena_guest::router(AppState::new(Arc::new(stub), config, None)), dir };
    // 2.5 MiB: several chunks each way.
    let bytes: Vec<u8> = (0..(5 << 19)).map(|i: u32| (i % 253) as u8).collect();
    let uri = "/v1/files?path=C:%5CUsers%5CDocker%5CDownloads%5Cbig.bin";
    let put = app.send(Request::put(uri).body(Body::from(bytes.clone())).unwrap()).await;
    put.assert_status(StatusCode::OK);
    let written: Value = put.json();
    assert_eq!(written["size"], bytes.len());
    let got = app.get(uri).await;
    got.assert_status(StatusCode::OK);
    assert_eq!(&got.body[..], &bytes[..]);
    assert_eq!(got.headers["x-arena-sha256"].to_str().unwrap(), written["sha256"].as_str().unwrap());

    let too_big = vec![1u8; 4 << 20];
    let over = app.send(Request::put(uri).body(Body::from(too_big)).unwrap()).await;
    over.assert_error(StatusCode::PAYLOAD_TOO_LARGE, ErrorCode::PayloadTooLarge, "--max-body-bytes");
    let downloads = app.dir.path().join("C/Users/Docker/Downloads");
    let names: Vec<String> =
        std::fs::read_dir(&downloads).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert_eq!(names, ["big.bin"], "no temporary file stays behind");
    assert_eq!(std::fs::read(downloads.join("big.bin")).unwrap(), bytes, "the old content is kept");
}

#[tokio::test]
async fn doctor_needs_the_token_and_passes_every_check_on_the_stub() {
    let app = app_with(Some(TOKEN));
    app.get("/v1/doctor").await.assert_status(StatusCode::UNAUTHORIZED);
    let request = Request::get("/v1/doctor")
        .header(header::AUTHORIZATION, format!("Bearer {TOKEN}"))
        .body(Body::empty())
        .unwrap();
    let answer = app.send(request).await;
    answer.assert_status(StatusCode::OK);
    let report: arena_shared::doctor::DoctorReport = answer.json();
    assert_eq!(report.backend, "stub");
    assert!(report.passed(), "{}", report.render_text());
    use arena_shared::doctor::CheckStatus::{Info, Pass, Unavailable};
    let expected = [
        ("session", Info),
        ("integrity", Unavailable),
        ("screen", Pass),
        ("capture", Pass),
        ("cursor", Pass),
        ("clipboard_text", Pass),
        ("clipboard_image", Pass),
        ("notepad_start", Pass),
        ("activation", Pass),
        ("notepad_typing", Pass),
        ("read_back_uia", Pass),
        ("read_back_win32", Pass),
        ("uia_tree", Pass),
        ("window_close", Pass),
        ("exec_timeout", Pass),
        ("files", Pass),
        ("reachability", Info),
        ("defender", Info),
    ];
    let got: Vec<_> = report.checks.iter().map(|c| (c.name.as_str(), c.status)).collect();
    assert_eq!(got, expected, "{}", report.render_text());
    // The stub has no Defender: every fact unknown, no detections.
    let defender = report.check("defender").unwrap();
    assert!(defender.detail.starts_with("Tamper Protection unknown, real-time protection unknown"), "{defender:?}");
    let close = report.check("window_close").unwrap();
    assert!(close.detail.contains("closed"), "{close:?}");
    // The doctor leaves the desktop as it found it: no Notepad, the clipboard as it was.
    let windows: Vec<WindowInfo> = {
        let request =
            Request::get("/v1/windows").header(header::AUTHORIZATION, format!("Bearer {TOKEN}")).body(Body::empty());
        app.send(request.unwrap()).await.json()
    };
    assert!(!windows.iter().any(|w| w.title.contains("Notepad")), "{windows:?}");
}

#[tokio::test]
async fn the_clock_is_read_set_and_guarded_by_the_token() {
    use arena_shared::clock::{now_unix_ms, ClockReading, ClockSetResult};
    let app = app_with(Some(TOKEN));
    let with_token = |method: Method, body: Option<Value>| {
        let builder = Request::builder()
            .method(method)
            .uri("/v1/clock")
            .header(header::AUTHORIZATION, format!("Bearer {TOKEN}"))
            .header(header::CONTENT_TYPE, "application/json");
        builder.body(body.map_or_else(Body::empty, |b| Body::from(b.to_string()))).unwrap()
    };
    // Without the token neither reading nor setting is served.
    app.get("/v1/clock").await.assert_error(StatusCode::UNAUTHORIZED, ErrorCode::Unauthorized, "Bearer");
    app.json(Method::PUT, "/v1/clock", json!({"unix_ms": now_unix_ms()})).await.assert_error(
        StatusCode::UNAUTHORIZED,
        ErrorCode::Unauthorized,
        "Bearer",
    );

    // Put back an hour, as a restore does, then set right again.
    let hour = 3_600_000;
    let back = app.send(with_token(Method::PUT, Some(json!({"unix_ms": now_unix_ms() - hour})))).await;
    back.assert_status(StatusCode::OK);
    let read: ClockReading = app.send(with_token(Method::GET, None)).await.json();
    let behind = now_unix_ms() - read.unix_ms;
    assert!((hour - 5_000..=hour + 5_000).contains(&behind), "the stub's clock is {behind} ms behind, not an hour");
    let host = now_unix_ms();
    let set: ClockSetResult = app.send(with_token(Method::PUT, Some(json!({"unix_ms": host})))).await.json();
    assert_eq!(set.unix_ms, host);
    assert!((hour - 5_000..=hour + 5_000).contains(&set.corrected_ms()), "corrected {} ms", set.corrected_ms());
    let read: ClockReading = app.send(with_token(Method::GET, None)).await.json();
    assert!((now_unix_ms() - read.unix_ms).abs() < 5_000, "the clock was not set: {read:?}");

    // Bad input is named, and the clock is left alone.
    let zero = app.send(with_token(Method::PUT, Some(json!({"unix_ms": 0})))).await;
    zero.assert_error(StatusCode::BAD_REQUEST, ErrorCode::BadRequest, "milliseconds since 1970");
    let text = app.send(with_token(Method::PUT, Some(json!({"unix_ms": "now"})))).await;
    assert_eq!(text.status, StatusCode::BAD_REQUEST, "{}", String::from_utf8_lossy(&text.body));
    let read: ClockReading = app.send(with_token(Method::GET, None)).await.json();
    assert!((now_unix_ms() - read.unix_ms).abs() < 5_000, "a refused set changed the clock: {read:?}");
}
