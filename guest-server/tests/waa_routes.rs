//! Router tests of the 44 upstream WAA routes against the stub backend, driven with
//! `tower::ServiceExt::oneshot` (no sockets). Each test is named after its route;
//! the expected bodies are upstream's (waa-api.md §a) unless `docs/compatibility.md`
//! lists a deviation.

use std::sync::Arc;

use axum::body::{Body, Bytes};
use axum::http::{header, HeaderMap, Method, Request, StatusCode};
use axum::Router;
use base64::Engine as _;
use serde_json::{json, Value};

use arena_guest::config::ServerConfig;
use arena_guest::desktop::stub::{Scenario, StubDesktop};
use arena_guest::desktop::Desktop;
use arena_guest::state::AppState;
use arena_shared::action::Action;

/// A router over a fresh stub whose drives live in a temporary directory.
struct TestApp {
    router: Router,
    stub: Arc<StubDesktop>,
    _dir: tempfile::TempDir,
}

/// What a request answered.
struct Answer {
    status: StatusCode,
    headers: HeaderMap,
    body: Bytes,
}

impl Answer {
    fn json(&self) -> Value {
        match serde_json::from_slice(&self.body) {
            Ok(v) => v,
            Err(err) => panic!("status {}: body {:?} is not JSON: {err}", self.status, self.text()),
        }
    }

    fn text(&self) -> String {
        String::from_utf8_lossy(&self.body).into_owned()
    }

    fn content_type(&self) -> &str {
        self.headers.get(header::CONTENT_TYPE).and_then(|v| v.to_str().ok()).unwrap_or("")
    }

    /// Asserts a JSON answer exactly.
    fn assert_json(&self, status: StatusCode, expected: Value) {
        assert_eq!(self.status, status, "body: {}", self.text());
        assert!(self.content_type().starts_with("application/json"), "content type {}", self.content_type());
        assert_eq!(self.json(), expected);
    }

    /// Asserts upstream's catch-all answer: 500 `{"status": "error", "message": message}`.
    fn assert_catch(&self, message: &str) {
        self.assert_json(StatusCode::INTERNAL_SERVER_ERROR, json!({"status": "error", "message": message}));
    }

    /// Asserts a string a Flask view returned.
    fn assert_text(&self, status: StatusCode, expected: &str) {
        assert_eq!(self.status, status, "body: {}", self.text());
        assert_eq!(self.content_type(), "text/html; charset=utf-8");
        assert_eq!(self.text(), expected);
    }
}

fn scenario(value: Value) -> Scenario {
    match Scenario::parse(&value.to_string(), "test") {
        Ok(s) => s,
        Err(err) => panic!("test scenario: {err}"),
    }
}

fn app_with(scenario: Option<Scenario>, config: ServerConfig) -> TestApp {
    let dir = tempfile::tempdir().expect("temp dir");
    let stub = Arc::new(crate::harness::stub_in(dir.path(), scenario, true));
    let state = AppState::new(stub.clone(), config, None);
    TestApp { router: arena_guest::router(state), stub, _dir: dir }
}

fn app() -> TestApp {
    app_with(None, ServerConfig::for_stub())
}

fn app_scenario(value: Value) -> TestApp {
    app_with(Some(scenario(value)), ServerConfig::for_stub())
}

/// An accessibility node for scenario `elements`.
fn el(role: &str, name: &str, children: Vec<Value>) -> Value {
    json!({"role": role, "class_name": "", "name": name, "enabled": true, "visible": true, "children": children})
}

const BOUNDARY: &str = "arena-test-boundary-7d1f";

/// A multipart body with text fields and file parts.
fn multipart(fields: &[(&str, &str)], files: &[(&str, &str, &[u8])]) -> Vec<u8> {
    let mut body = Vec::new();
    for (name, value) in fields {
        body.extend_from_slice(
            format!("--{BOUNDARY}\r\nContent-Disposition: form-data; name=\"{name}\"\r\n\r\n{value}\r\n").as_bytes(),
        );
    }
    for (name, filename, data) in files {
        body.extend_from_slice(
            format!("--{BOUNDARY}\r\nContent-Disposition: form-data; name=\"{name}\"; filename=\"{filename}\"\r\nContent-Type: application/octet-stream\r\n\r\n")
                .as_bytes(),
        );
        body.extend_from_slice(data);
        body.extend_from_slice(b"\r\n");
    }
    body.extend_from_slice(format!("--{BOUNDARY}--\r\n").as_bytes());
    body
}

impl TestApp {
    async fn send(&self, request: Request<Body>) -> Answer {
        let (status, headers, body) = crate::harness::send(&self.router, request).await;
        Answer { status, headers, body }
    }

    async fn raw(&self, method: Method, path: &str, content_type: Option<&str>, body: impl Into<Body>) -> Answer {
        let mut request = Request::builder().method(method).uri(path);
        if let Some(ct) = content_type {
            request = request.header(header::CONTENT_TYPE, ct);
        }
        self.send(request.body(body.into()).expect("request")).await
    }

    async fn get(&self, path: &str) -> Answer {
        self.raw(Method::GET, path, None, Body::empty()).await
    }

    async fn post(&self, path: &str) -> Answer {
        self.raw(Method::POST, path, None, Body::empty()).await
    }

    async fn post_json(&self, path: &str, body: Value) -> Answer {
        self.raw(Method::POST, path, Some("application/json"), body.to_string()).await
    }

    async fn post_form(&self, path: &str, body: &str) -> Answer {
        self.raw(Method::POST, path, Some("application/x-www-form-urlencoded"), body.to_owned()).await
    }

    async fn post_multipart(&self, path: &str, fields: &[(&str, &str)], files: &[(&str, &str, &[u8])]) -> Answer {
        let ct = format!("multipart/form-data; boundary={BOUNDARY}");
        self.raw(Method::POST, path, Some(&ct), multipart(fields, files)).await
    }

    /// The local path of a guest path.
    fn local(&self, guest: &str) -> std::path::PathBuf {
        self.stub.map_path(guest).expect("mappable guest path")
    }

    fn write(&self, guest: &str, bytes: &[u8]) {
        let local = self.local(guest);
        std::fs::create_dir_all(local.parent().expect("parent")).expect("mkdir");
        std::fs::write(local, bytes).expect("write");
    }

    fn focused_title(&self) -> Option<String> {
        self.stub.windows().expect("windows").into_iter().find(|w| w.focused).map(|w| w.title)
    }
}

// ----- routing and the error model -----

#[tokio::test]
async fn unknown_route_is_a_500_with_werkzeugs_404_text() {
    app().get("/nope").await.assert_catch(
        "404 Not Found: The requested URL was not found on the server. If you entered the URL manually please check your spelling and try again.",
    );
}

#[tokio::test]
async fn wrong_method_is_a_500_with_werkzeugs_405_text() {
    let app = app();
    app.get("/execute").await.assert_catch("405 Method Not Allowed: The method is not allowed for the requested URL.");
    app.post("/probe").await.assert_catch("405 Method Not Allowed: The method is not allowed for the requested URL.");
}

#[tokio::test]
async fn options_answers_like_flask() {
    let answer = app().raw(Method::OPTIONS, "/execute", None, Body::empty()).await;
    assert_eq!(answer.status, StatusCode::OK);
    assert_eq!(answer.headers.get(header::ALLOW).and_then(|v| v.to_str().ok()), Some("OPTIONS, POST"));
    let head = app().raw(Method::HEAD, "/probe", None, Body::empty()).await;
    assert_eq!((head.status, head.body.len()), (StatusCode::OK, 0));
}

#[tokio::test]
async fn json_routes_reject_other_content_types_with_415_text() {
    let app = app();
    for path in ["/execute", "/setup/create_folder", "/list_directory", "/update_computer"] {
        app.post_form(path, "path=x").await.assert_catch(
            "415 Unsupported Media Type: Did not attempt to load JSON data because the request Content-Type was not 'application/json'.",
        );
    }
}

#[tokio::test]
async fn malformed_json_is_a_500_with_400_text() {
    let answer = app().raw(Method::POST, "/execute", Some("application/json"), "{not json").await;
    assert_eq!(answer.status, StatusCode::INTERNAL_SERVER_ERROR);
    let message = answer.json()["message"].as_str().unwrap_or_default().to_owned();
    assert!(message.starts_with("400 Bad Request: Failed to decode JSON object: "), "{message}");
}

#[tokio::test]
async fn non_object_json_bodies_raise_pythons_errors() {
    let app = app();
    app.post_json("/execute", json!(["command"])).await.assert_catch("'list' object has no attribute 'get'");
    app.post_json("/setup/create_folder", json!(null))
        .await
        .assert_catch("argument of type 'NoneType' is not iterable");
}

// ----- 1, 2: /update_computer, /execute_windows -----

fn png_b64(width: u32, height: u32) -> String {
    let img = image::RgbaImage::from_pixel(width, height, image::Rgba([9, 8, 7, 255]));
    let mut bytes = Vec::new();
    image::DynamicImage::ImageRgba8(img)
        .write_to(&mut std::io::Cursor::new(&mut bytes), image::ImageFormat::Png)
        .expect("png");
    base64::engine::general_purpose::STANDARD.encode(bytes)
}

#[tokio::test]
async fn update_computer_stores_the_state_and_obs_winagent_echoes_the_clipboard() {
    let app = app();
    let body = json!({
        "rects": [[0, 0, 10, 10]], "window_rect": [0, 0, 1440, 900], "screenshot": png_b64(4, 3),
        "scale": [1.0, 1.0], "clipboard_content": "copied text", "swap_ctrl_alt": false,
    });
    app.post_json("/update_computer", body).await.assert_json(StatusCode::OK, json!({"success": true}));
    let obs = app.get("/obs_winagent").await;
    assert_eq!(obs.json()["computer_clipboard"], json!("copied text"));
}

#[tokio::test]
async fn update_computer_without_a_screenshot_fails_like_upstream() {
    let app = app();
    app.post_json("/update_computer", json!({"rects": []}))
        .await
        .assert_catch("argument should be a bytes-like object or ASCII string, not 'NoneType'");
    app.post_json("/update_computer", json!({"screenshot": "aGVsbG8="}))
        .await
        .assert_catch("cannot identify image file <_io.BytesIO object>");
}

#[tokio::test]
async fn execute_windows_before_update_computer_is_an_attribute_error() {
    app()
        .post_json(
            "/execute_windows",
            json!({"command": "computer.mouse.move_id(id=78)\ncomputer.mouse.single_click()"}),
        )
        .await
        .assert_catch("'NoneType' object has no attribute 'move_id'");
}

#[tokio::test]
async fn execute_windows_runs_the_code() {
    // The interpreter's own tests are in python_corpus.rs; this pins the route's success shape.
    let app = app();
    app.post_json("/update_computer", json!({"screenshot": png_b64(2, 2)}))
        .await
        .assert_json(StatusCode::OK, json!({"success": true}));
    let answer = app.post_json("/execute_windows", json!({"command": "# click\ncomputer.mouse.single_click()"})).await;
    answer.assert_json(StatusCode::OK, json!({"status": "success"}));
    assert_eq!(
        app.stub.action_log(),
        vec![Action::Click { x: None, y: None, button: arena_shared::action::MouseButton::Left, count: 1 }]
    );
}

#[tokio::test]
async fn execute_windows_blank_code_succeeds_and_non_strings_fail() {
    let app = app();
    app.post_json("/execute_windows", json!({"command": "\n# only a comment\n"}))
        .await
        .assert_json(StatusCode::OK, json!({"status": "success"}));
    app.post_json("/execute_windows", json!({}))
        .await
        .assert_catch("exec() arg 1 must be a string, bytes or code object");
}

// ----- 3, 4: /execute and /setup/execute -----

#[tokio::test]
async fn execute_runs_a_shell_string_and_reports_output() {
    let answer = app().post_json("/execute", json!({"command": "echo hello", "shell": true})).await;
    answer.assert_json(StatusCode::OK, json!({"status": "success", "output": "hello\n", "error": "", "returncode": 0}));
}

#[tokio::test]
async fn setup_execute_shares_the_handler_and_nonzero_exit_is_200() {
    let answer = app().post_json("/setup/execute", json!({"command": "echo oops 1>&2; exit 3", "shell": true})).await;
    answer.assert_json(StatusCode::OK, json!({"status": "success", "output": "", "error": "oops\n", "returncode": 3}));
}

#[tokio::test]
async fn execute_treats_the_string_true_and_false_as_truthy_shell() {
    let app = app();
    for shell in ["true", "false"] {
        let answer = app.post_json("/execute", json!({"command": "echo a && echo b", "shell": shell})).await;
        assert_eq!(answer.json()["output"], json!("a\nb\n"), "shell {shell:?}: {}", answer.text());
    }
}

#[cfg(unix)]
#[tokio::test]
async fn execute_splits_a_string_command_with_posix_shlex() {
    // Without a shell the string is split: quotes group, and `&&` is just an argument.
    let answer = app().post_json("/execute", json!({"command": "printf '%s|' 'a b' \"c\\\"d\" && x"})).await;
    answer.assert_json(
        StatusCode::OK,
        json!({"status": "success", "output": "a b|c\"d|&&|x|", "error": "", "returncode": 0}),
    );
}

#[cfg(unix)]
#[tokio::test]
async fn execute_joins_a_shell_list_with_list2cmdline() {
    // waa-api.md §d.2: the words with spaces are quoted, the metacharacters stay bare for the shell.
    let answer = app()
        .post_json("/execute", json!({"command": ["echo", "Hello  World 1", "|", "tr", "a-z", "A-Z"], "shell": "true"}))
        .await;
    answer.assert_json(
        StatusCode::OK,
        json!({"status": "success", "output": "HELLO  WORLD 1\n", "error": "", "returncode": 0}),
    );
}

#[cfg(unix)]
#[tokio::test]
async fn execute_expands_tilde_slash_arguments() {
    let answer = app().post_json("/execute", json!({"command": ["echo", "~/x", "a~/y"]})).await;
    assert_eq!(answer.json()["output"], json!("C:\\Users\\Docker/x a~/y\n"));
}

#[tokio::test]
async fn execute_error_cases_match_python() {
    let app = app();
    app.post_json("/execute", json!({"command": ["arena-no-such-program-xyz"]}))
        .await
        .assert_catch("[WinError 2] The system cannot find the file specified");
    app.post_json("/execute", json!({"command": ["echo", 5]}))
        .await
        .assert_catch("'int' object has no attribute 'startswith'");
    app.post_json("/execute", json!({"command": "echo 'open"})).await.assert_catch("No closing quotation");
    app.post_json("/execute", json!({"command": "echo x\\"})).await.assert_catch("No escaped character");
    app.post_json("/execute", json!({"command": 7})).await.assert_catch("'int' object is not iterable");
}

#[tokio::test]
async fn execute_times_out_with_pythons_message() {
    let mut config = ServerConfig::for_stub();
    config.exec_timeout_ms = 300;
    let app = app_with(None, config);
    app.post_json("/execute", json!({"command": "sleep 5", "shell": true}))
        .await
        .assert_catch("Command 'sleep 5' timed out after 0.3 seconds");
}

// ----- 5, 6: /probe, /shutdown -----

#[tokio::test]
async fn probe_answers_upstreams_json() {
    app()
        .get("/probe")
        .await
        .assert_json(StatusCode::OK, json!({"status": "Probe successful", "message": "Service is operational"}));
}

#[tokio::test]
async fn shutdown_asks_the_backend_and_answers_upstreams_json() {
    let app = app();
    app.post("/shutdown").await.assert_json(
        StatusCode::OK,
        json!({"status": "Shutdown started successfully", "message": "Shutdown started successfully"}),
    );
    assert!(app.stub.shutdown_requested());
}

// ----- 7: /setup/launch -----

#[tokio::test]
async fn setup_launch_maps_google_chrome_and_answers_the_list_repr() {
    let app = app();
    app.post_json("/setup/launch", json!({"command": ["google-chrome", "--remote-debugging-port=1337"]}))
        .await
        .assert_text(StatusCode::OK, "['chrome', '--remote-debugging-port=1337'] launched successfully");
    assert!(app.stub.find_window("Google Chrome").is_some());
}

#[tokio::test]
async fn setup_launch_string_and_missing_program_still_succeed() {
    let app = app();
    app.post_json("/setup/launch", json!({"command": "calc", "shell": false}))
        .await
        .assert_text(StatusCode::OK, "calc launched successfully");
    assert!(app.stub.find_window("Calculator").is_some());
    app.post_json("/setup/launch", json!({"command": ["arena-no-such-program-xyz", "tcp-listen:9222,fork"]}))
        .await
        .assert_text(StatusCode::OK, "['arena-no-such-program-xyz', 'tcp-listen:9222,fork'] launched successfully");
}

#[tokio::test]
async fn setup_launch_google_chrome_string_fails_with_the_request_attached() {
    let body = json!({"command": "google-chrome --x"});
    app().post_json("/setup/launch", body.clone()).await.assert_json(
        StatusCode::INTERNAL_SERVER_ERROR,
        json!({"status": "error", "message": "'str' object does not support item assignment", "shell": "True", "command": "google-chrome --x", "data": body}),
    );
}

// ----- 8-15: observation and system information -----

#[tokio::test]
async fn screenshot_is_a_full_screen_png() {
    let answer = app().get("/screenshot").await;
    assert_eq!(answer.status, StatusCode::OK);
    assert_eq!(answer.content_type(), "image/png");
    let img = image::load_from_memory(&answer.body).expect("png");
    assert_eq!((img.width(), img.height()), (1440, 900));
}

#[tokio::test]
async fn terminal_is_not_implemented_on_windows() {
    app().get("/terminal").await.assert_text(
        StatusCode::INTERNAL_SERVER_ERROR,
        "Currently not implemented for platform Windows-10-10.0.22631-SP0.",
    );
}

#[tokio::test]
async fn obs_winagent_crops_the_foreground_window() {
    let app = app_scenario(json!({"windows": [
        {"title": "Doc - Notepad", "class_name": "Notepad", "rect": {"x": 100, "y": 50, "width": 400, "height": 300}, "focused": true},
        {"title": "Other", "rect": {"x": 0, "y": 0, "width": 200, "height": 200}},
        {"title": "Doc - Notepad", "rect": {"x": 10, "y": 10, "width": 20, "height": 20}},
    ]}));
    let answer = app.get("/obs_winagent").await;
    assert_eq!(answer.status, StatusCode::OK, "{}", answer.text());
    let obs = answer.json();
    assert_eq!(obs["window_title"], json!("Doc - Notepad"));
    assert_eq!(obs["rect"], json!([100, 50, 500, 350]));
    assert_eq!(obs["status"], json!("success"));
    assert_eq!(obs["computer_clipboard"], Value::Null);
    assert_eq!(obs["human_input"], json!("Question: No question asked yet\nAnswer: No answer given yet"));
    let names: Vec<&str> = obs["window_names_str"].as_str().unwrap_or_default().split('\n').collect();
    assert_eq!(&names[..2], &["Doc - Notepad", "Other"]);
    assert_eq!(names.iter().filter(|n| **n == "Doc - Notepad").count(), 1);
    let png =
        base64::engine::general_purpose::STANDARD.decode(obs["image"].as_str().unwrap_or_default()).expect("base64");
    let img = image::load_from_memory(&png).expect("png");
    assert_eq!((img.width(), img.height()), (400, 300));
}

#[tokio::test]
async fn obs_winagent_on_the_bare_desktop_reports_x_y_w_h() {
    let obs = app().get("/obs_winagent").await.json();
    assert_eq!(obs["window_title"], json!("Desktop"));
    assert_eq!(obs["rect"], json!([0, 0, 1440, 900]));
}

fn parse_xml(xml: &str) -> roxmltree::Document<'_> {
    match roxmltree::Document::parse(xml) {
        Ok(doc) => doc,
        Err(err) => panic!("not XML ({err}): {xml}"),
    }
}

#[tokio::test]
async fn accessibility_defaults_to_win32_and_serves_uia() {
    let app = app_scenario(json!({"windows": [{"title": "Doc - Notepad", "class_name": "Notepad", "focused": true,
        "elements": [el("Edit", "Address and search bar", vec![])]}]}));
    let win32 = app.get("/accessibility").await;
    assert_eq!(win32.status, StatusCode::OK, "{}", win32.text());
    let xml = win32.json()["AT"].as_str().unwrap_or_default().to_owned();
    let doc = parse_xml(&xml);
    assert_eq!(doc.root_element().tag_name().name(), "desktop");
    assert!(xml.contains("st:unicode=\"true\"") && xml.contains("hwndwrapper.HwndWrapper"), "{xml}");
    let notepad =
        doc.root_element().children().find(|n| n.attribute("name") == Some("Doc - Notepad")).expect("window node");
    assert_eq!(notepad.tag_name().name(), "notepad");
    assert_eq!(notepad.attribute(("uri:deskat:state.at-spi.gnome.org", "active")), Some("true"));

    let uia = app.get("/accessibility?backend=uia").await.json()["AT"].as_str().unwrap_or_default().to_owned();
    let doc = parse_xml(&uia);
    assert!(uia.contains("selection=\"true\"") && uia.contains("uiawrapper.UIAWrapper"), "{uia}");
    assert!(doc.descendants().any(|n| n.attribute("name") == Some("Address and search bar")));
}

#[tokio::test]
async fn accessibility_rejects_unknown_backends_with_400_text() {
    let app = app();
    app.get("/accessibility?backend=atspi").await.assert_text(StatusCode::BAD_REQUEST, "Invalid backend specified");
    app.get("/accessibility?backend=").await.assert_text(StatusCode::BAD_REQUEST, "Invalid backend specified");
}

#[tokio::test]
async fn screen_size_ignores_the_body() {
    let app = app();
    app.post("/screen_size").await.assert_json(StatusCode::OK, json!({"width": 1440, "height": 900}));
    app.post_form("/screen_size", "x=1").await.assert_json(StatusCode::OK, json!({"width": 1440, "height": 900}));
}

#[tokio::test]
async fn window_size_needs_the_field_then_fails_like_upstream_on_windows() {
    let app = app();
    app.post("/window_size").await.assert_json(StatusCode::BAD_REQUEST, json!({"error": "app_class_name is required"}));
    app.post_form("/window_size", "app_class_name=notepad").await.assert_catch("Bad display name \"\"");
}

#[tokio::test]
async fn desktop_path_answers_the_guest_path_or_404() {
    let app = app();
    app.post("/desktop_path").await.assert_json(StatusCode::OK, json!({"desktop_path": "C:\\Users\\Docker\\Desktop"}));
    std::fs::remove_dir_all(app.local(r"C:\Users\Docker\Desktop")).expect("rm");
    app.post("/desktop_path")
        .await
        .assert_json(StatusCode::NOT_FOUND, json!({"error": "Unsupported operating system or desktop path not found"}));
}

#[tokio::test]
async fn documents_path_answers_the_guest_path_or_400() {
    let app = app();
    app.post("/documents_path")
        .await
        .assert_json(StatusCode::OK, json!({"documents_path": "C:\\Users\\Docker\\Documents"}));
    std::fs::remove_dir_all(app.local(r"C:\Users\Docker\Documents")).expect("rm");
    app.post("/documents_path").await.assert_json(
        StatusCode::BAD_REQUEST,
        json!({"error": "Unsupported operating system or documents path not found"}),
    );
}

// ----- 16-20: create, recycle, exists -----

#[tokio::test]
async fn setup_create_folder_creates_reports_existing_and_failures() {
    let app = app();
    let path = r"C:\Users\Docker\Downloads\Test\Sub";
    app.post_json("/setup/create_folder", json!({"path": path}))
        .await
        .assert_json(StatusCode::OK, json!({"status": "success", "message": format!("{path} created.")}));
    assert!(app.local(path).is_dir());
    app.post_json("/setup/create_folder", json!({"path": path}))
        .await
        .assert_json(StatusCode::OK, json!({"status": "success", "message": format!("{path} already exists.")}));
    app.post_json("/setup/create_folder", json!({}))
        .await
        .assert_json(StatusCode::BAD_REQUEST, json!({"error": "path required"}));
    app.post_json("/setup/create_folder", json!({"path": 5}))
        .await
        .assert_json(StatusCode::BAD_REQUEST, json!({"status": "error", "message": "Failed to create 5."}));
}

#[tokio::test]
async fn setup_create_file_writes_crlf_text() {
    let app = app();
    let path = r"C:\Users\Docker\Desktop\new\example.txt";
    app.post_json("/setup/create_file", json!({"path": path, "content": "line1\nline2 é"}))
        .await
        .assert_json(StatusCode::OK, json!({"status": "success", "message": format!("{path} created.")}));
    assert_eq!(std::fs::read(app.local(path)).expect("read"), "line1\r\nline2 é".as_bytes());
    app.post_json("/setup/create_file", json!({"path": r"C:\Users\Docker\Desktop"}))
        .await
        .assert_json(StatusCode::BAD_REQUEST, json!({"status": "error", "message": "path is not a file"}));
    app.post_json("/setup/create_file", json!({"content": "x"}))
        .await
        .assert_json(StatusCode::BAD_REQUEST, json!({"error": "path required"}));
    app.post_json("/setup/create_file", json!({"path": 3}))
        .await
        .assert_catch("expected str, bytes or os.PathLike object, not int");
}

#[tokio::test]
async fn setup_recycle_moves_files_away_and_reports_failures() {
    let app = app();
    let path = r"C:\Users\Docker\Desktop\old.txt";
    app.write(path, b"x");
    app.post_json("/setup/recycle", json!({"path": path}))
        .await
        .assert_json(StatusCode::OK, json!({"status": "success", "message": format!("{path} recycled")}));
    assert!(!app.local(path).exists());
    app.post_json("/setup/recycle", json!({"path": path})).await.assert_json(
        StatusCode::BAD_REQUEST,
        json!({"status": "error", "message": format!("Failed to recycle {path}")}),
    );
    app.post_json("/setup/recycle", json!({}))
        .await
        .assert_json(StatusCode::BAD_REQUEST, json!({"error": "Missing 'path' parameter"}));
}

#[tokio::test]
async fn setup_recycle_refuses_drive_roots_and_the_users_folders() {
    let app = app();
    app.write(r"C:\Users\Docker\Desktop\keep.txt", b"x");
    for path in [r"C:\", r"C:\Users\Docker", r"C:\Users\Docker\Desktop", r"C:\Windows"] {
        let answer = app.post_json("/setup/recycle", json!({"path": path})).await;
        assert_eq!(answer.status, StatusCode::FORBIDDEN, "{path}");
        let body: Value = serde_json::from_slice(&answer.body).expect("json");
        assert_eq!(body["status"], "error");
        assert!(body["message"].as_str().is_some_and(|m| m.contains("never removes")), "{body}");
    }
    assert!(app.local(r"C:\Users\Docker\Desktop\keep.txt").exists(), "nothing moved");
}

#[tokio::test]
async fn folder_exists_answers_200_or_400() {
    let app = app();
    let docs = r"C:\Users\Docker\Documents";
    std::fs::create_dir_all(app.local(r"C:\Users\Docker\Documents\Projects")).expect("mkdir");
    app.post_json("/folder_exists", json!({"folder_name": "Projects", "path": docs})).await.assert_json(
        StatusCode::OK,
        json!({"status": "success", "message": format!("Folder Projects exists in {docs}.")}),
    );
    app.post_json("/folder_exists", json!({"folder_name": "Nope", "path": docs})).await.assert_json(
        StatusCode::BAD_REQUEST,
        json!({"status": "error", "message": format!("Folder Nope does not exist in {docs}.")}),
    );
    app.post_json("/folder_exists", json!({"path": docs}))
        .await
        .assert_json(StatusCode::BAD_REQUEST, json!({"error": "folder_name required"}));
    app.post_json("/folder_exists", json!({"folder_name": "x"}))
        .await
        .assert_json(StatusCode::BAD_REQUEST, json!({"error": "path required"}));
}

#[tokio::test]
async fn file_exists_answers_200_or_400() {
    let app = app();
    let desk = r"C:\Users\Docker\Desktop";
    app.write(r"C:\Users\Docker\Desktop\a.txt", b"a");
    app.post_json("/file_exists", json!({"file_name": "a.txt", "path": desk}))
        .await
        .assert_json(StatusCode::OK, json!({"status": "success", "message": format!("File a.txt exists in {desk}.")}));
    // A folder is not a file.
    app.post_json("/file_exists", json!({"file_name": "Desktop", "path": r"C:\Users\Docker"})).await.assert_json(
        StatusCode::BAD_REQUEST,
        json!({"status": "error", "message": "File Desktop does not exist in C:\\Users\\Docker."}),
    );
    app.post_json("/file_exists", json!({"path": desk}))
        .await
        .assert_json(StatusCode::BAD_REQUEST, json!({"error": "file_name required"}));
    app.post_json("/file_exists", json!({"file_name": 1, "path": desk}))
        .await
        .assert_catch("join() argument must be str, bytes, or os.PathLike object, not 'int'");
}

// ----- 21, 39, 43, 44: evaluator helpers over the foreground tree -----

fn explorer(items: &[&str]) -> Value {
    let list = el("List", "Items View", items.iter().map(|n| el("ListItem", n, vec![])).collect());
    json!({"title": "Downloads - File Explorer", "class_name": "CabinetWClass", "process_name": "explorer.exe", "focused": true,
        "elements": [el("Pane", "Shell Folder View", vec![list])]})
}

#[tokio::test]
async fn is_details_view_looks_for_the_header_in_the_item_list() {
    let app = app_scenario(json!({"windows": [explorer(&["Header", "a.txt"])]}));
    let path = r"C:\Users\Docker\Downloads";
    app.post_json("/is_details_view", json!({"path": path})).await.assert_json(
        StatusCode::OK,
        json!({"status": "success", "message": "File Explorer is in Details view", "is_details_view": true}),
    );
    app.post_json("/is_details_view", json!({}))
        .await
        .assert_json(StatusCode::BAD_REQUEST, json!({"error": "path is required"}));

    let app = app_scenario(json!({"windows": [explorer(&["a.txt"])]}));
    app.post_json("/is_details_view", json!({"path": path})).await.assert_json(
        StatusCode::BAD_REQUEST,
        json!({"status": "error", "message": "File Explorer is not in Details view", "is_details_view": false}),
    );
}

fn set_mtime(path: &std::path::Path, secs: u64) {
    let file = std::fs::File::options().write(true).open(path).expect("open");
    file.set_modified(std::time::UNIX_EPOCH + std::time::Duration::from_secs(secs)).expect("set mtime");
}

#[tokio::test]
async fn are_files_sorted_by_modified_time_compares_the_display_order() {
    let dir = r"C:\Users\Docker\Downloads";
    let check = |items: &'static [&'static str], ok: bool| async move {
        let app = app_scenario(json!({"windows": [explorer(items)]}));
        for (name, secs) in [("old.txt", 1_000_000), ("new.txt", 2_000_000)] {
            let guest = format!(r"{dir}\{name}");
            app.write(&guest, b"x");
            set_mtime(&app.local(&guest), secs);
        }
        let answer = app.post_json("/are_files_sorted_by_modified_time", json!({"directory": dir})).await;
        if ok {
            answer.assert_json(
                StatusCode::OK,
                json!({"status": "success", "message": format!("{dir}: files are sorted by modified time")}),
            );
        } else {
            answer.assert_json(
                StatusCode::BAD_REQUEST,
                json!({"status": "error", "message": format!("{dir}: files are not sorted by modified time")}),
            );
        }
    };
    // "Header" and other names that are not files in the folder are ignored.
    check(&["Header", "new.txt", "old.txt"], true).await;
    check(&["old.txt", "new.txt"], true).await;
    check(&["old.txt", "gone.txt", "new.txt", "old.txt"], false).await;
    app()
        .post_json("/are_files_sorted_by_modified_time", json!({}))
        .await
        .assert_json(StatusCode::BAD_REQUEST, json!({"error": "directory is required"}));
}

fn clock(elements: Vec<Value>) -> Value {
    json!({"windows": [{"title": "Clock", "class_name": "ApplicationFrameWindow", "focused": true,
        "rect": {"x": 0, "y": 0, "width": 800, "height": 600}, "elements": elements}]})
}

#[tokio::test]
async fn check_if_timer_started_finds_a_running_timer() {
    let timer =
        el("Group", "Timer 1, 0 hours 30 minutes 0 seconds", vec![el("Button", "Timer running, Pause", vec![])]);
    let app = app_scenario(clock(vec![timer]));
    app.post_json("/check_if_timer_started", json!({"hours": 0, "minutes": 30, "seconds": 0}))
        .await
        .assert_json(StatusCode::OK, json!({"status": "success", "message": "Timer exists"}));
    app.post_json("/check_if_timer_started", json!({"hours": 1, "minutes": 30, "seconds": 0}))
        .await
        .assert_json(StatusCode::BAD_REQUEST, json!({"status": "error", "message": "Timer does not exist"}));
    app.post_json("/check_if_timer_started", json!({"hours": 0, "seconds": 0}))
        .await
        .assert_json(StatusCode::BAD_REQUEST, json!({"error": "minutes is required"}));

    let paused = el("Group", "Timer 1, 1 hour 1 minute 1 second", vec![el("Button", "Start", vec![])]);
    let app = app_scenario(clock(vec![paused]));
    app.post_json("/check_if_timer_started", json!({"hours": 1, "minutes": "1", "seconds": 1}))
        .await
        .assert_json(StatusCode::BAD_REQUEST, json!({"status": "error", "message": "Timer does not exist"}));
}

#[tokio::test]
async fn check_if_world_clock_exists_presses_maximize_clock_first() {
    let mut maximize = el("Button", "Maximize Clock", vec![]);
    maximize["rect"] = json!({"x": 700, "y": 10, "width": 40, "height": 20});
    let london = el("ListItem", "London, United Kingdom, 3:00 PM", vec![]);
    let app = app_scenario(clock(vec![maximize, london]));
    app.post_json("/check_if_world_clock_exists", json!({"city": "London", "country": "United Kingdom"}))
        .await
        .assert_json(StatusCode::OK, json!({"status": "success", "message": "World clock exists"}));
    let clicked = app.stub.action_log().iter().any(|a| matches!(a, Action::Click { x: Some(720), y: Some(20), .. }));
    assert!(clicked, "Maximize Clock was not clicked: {:?}", app.stub.action_log());
    app.post_json("/check_if_world_clock_exists", json!({"city": "Paris", "country": "France"}))
        .await
        .assert_json(StatusCode::BAD_REQUEST, json!({"status": "error", "message": "World clock does not exist"}));
    app.post_json("/check_if_world_clock_exists", json!({"city": "Paris"}))
        .await
        .assert_json(StatusCode::BAD_REQUEST, json!({"error": "city and country are required"}));
}

// ----- 22, 28: wallpaper -----

#[tokio::test]
async fn wallpaper_without_one_is_upstreams_abort_text() {
    app().post("/wallpaper").await.assert_catch("404 Not Found: Wallpaper file not found");
}

#[tokio::test]
async fn setup_change_wallpaper_then_wallpaper_serves_the_file() {
    let app = app();
    let png = base64::engine::general_purpose::STANDARD.decode(png_b64(3, 3)).expect("png");
    let path = r"C:\Users\Docker\Pictures\wall.png";
    app.write(path, &png);
    app.post_json("/setup/change_wallpaper", json!({}))
        .await
        .assert_text(StatusCode::BAD_REQUEST, "Path not supplied!");
    app.post_json("/setup/change_wallpaper", json!({"path": "C:/Users/Docker/Pictures/none.png"}))
        .await
        .assert_text(StatusCode::NOT_FOUND, r"File not found: C:\Users\Docker\Pictures\none.png");
    app.post_json("/setup/change_wallpaper", json!({"path": "~\\Pictures\\wall.png"}))
        .await
        .assert_text(StatusCode::OK, "Wallpaper changed successfully");
    let answer = app.post("/wallpaper").await;
    assert_eq!(answer.status, StatusCode::OK);
    assert_eq!(answer.content_type(), "image/png");
    assert_eq!(&answer.body[..], &png[..]);
}

// ----- 23: /list_directory -----

#[tokio::test]
async fn list_directory_builds_upstreams_tree() {
    let app = app();
    let root = r"C:\Users\Docker\Music\Album";
    app.write(r"C:\Users\Docker\Music\Album\b.mp3", b"b");
    app.write(r"C:\Users\Docker\Music\Album\A.mp3", b"a");
    app.write(r"C:\Users\Docker\Music\Album\Disc 2\c.mp3", b"c");
    std::fs::create_dir_all(app.local(r"C:\Users\Docker\Music\Album\Empty")).expect("mkdir");
    app.post_json("/list_directory", json!({"path": root})).await.assert_json(
        StatusCode::OK,
        json!({"directory_tree": {"type": "directory", "name": "Album", "children": [
            {"type": "file", "name": "A.mp3"},
            {"type": "file", "name": "b.mp3"},
            {"type": "directory", "name": "Disc 2", "children": [{"type": "file", "name": "c.mp3"}]},
            {"type": "directory", "name": "Empty", "children": []},
        ]}}),
    );
    app.post_json("/list_directory", json!({"path": format!("{root}\\")})).await.json()["directory_tree"]["name"]
        .as_str()
        .map(|name| assert_eq!(name, ""))
        .expect("name");
    app.post_json("/list_directory", json!({}))
        .await
        .assert_json(StatusCode::BAD_REQUEST, json!({"error": "Missing 'path' parameter"}));
    app.post_json("/list_directory", json!({"path": r"C:\Users\Docker\Music\Album\A.mp3"}))
        .await
        .assert_json(StatusCode::BAD_REQUEST, json!({"error": "The provided path is not a directory"}));
}

// ----- 24, 25: /file and /setup/upload -----

#[tokio::test]
async fn setup_upload_takes_names_up_to_the_file_system_limit() {
    let app = app();
    // 250 bytes: a legal NTFS (and ext4) name, too long for a temporary name built from it.
    let name = format!("{}.txt", "n".repeat(246));
    let path = format!(r"C:\Users\Docker\Downloads\{name}");
    app.post_multipart("/setup/upload", &[("file_path", &path)], &[("file_data", "x.txt", b"long")])
        .await
        .assert_text(StatusCode::OK, "File Uploaded");
    assert_eq!(std::fs::read(app.local(&path)).expect("read"), b"long");
}

#[tokio::test]
async fn setup_upload_then_file_round_trips_binary_bytes() {
    let app = app();
    let bytes: Vec<u8> = (0..=255u8).chain([0, 0, 13, 10, 255]).collect();
    let path = r"C:\Users\Docker\Downloads\data.bin";
    app.post_multipart("/setup/upload", &[("file_path", path)], &[("file_data", "data.bin", &bytes)])
        .await
        .assert_text(StatusCode::OK, "File Uploaded");
    assert_eq!(std::fs::read(app.local(path)).expect("read"), bytes);

    let answer = app.post_form("/file", "file_path=%USERPROFILE%%5CDownloads%5Cdata.bin").await;
    assert_eq!(answer.status, StatusCode::OK, "{}", answer.text());
    assert_eq!(&answer.body[..], &bytes[..]);
    assert_eq!(answer.content_type(), "application/octet-stream");
    assert_eq!(
        answer.headers.get(header::CONTENT_DISPOSITION).and_then(|v| v.to_str().ok()),
        Some("attachment; filename=data.bin")
    );

    // Multipart works for /file too, and a text file gets a text type.
    app.write(r"C:\Users\Docker\Desktop\notes.txt", b"hi");
    let answer = app.post_multipart("/file", &[("file_path", r"~\Desktop\notes.txt")], &[]).await;
    assert_eq!(
        (answer.status, answer.text().as_str(), answer.content_type()),
        (StatusCode::OK, "hi", "text/plain; charset=utf-8")
    );
}

#[tokio::test]
async fn setup_upload_takes_files_larger_than_the_in_memory_part_limit() {
    // 5 MiB: the guest spools it to a temporary file on the way (see waa::body).
    let app = app();
    let bytes: Vec<u8> = (0..5u32 << 20).map(|i| (i % 253) as u8).collect();
    let path = r"C:\Users\Docker\Downloads\big.bin";
    app.post_multipart("/setup/upload", &[("file_path", path)], &[("file_data", "big.bin", &bytes)])
        .await
        .assert_text(StatusCode::OK, "File Uploaded");
    assert!(std::fs::read(app.local(path)).expect("read") == bytes, "the 5 MiB upload arrived intact");
}

#[tokio::test]
async fn setup_upload_overwrites_atomically() {
    let app = app();
    let path = r"C:\Users\Docker\Desktop\x.txt";
    app.write(path, b"old contents that are longer");
    app.post_multipart("/setup/upload", &[("file_path", path)], &[("file_data", "x.txt", b"new")])
        .await
        .assert_text(StatusCode::OK, "File Uploaded");
    assert_eq!(std::fs::read(app.local(path)).expect("read"), b"new");
    let names: Vec<_> = std::fs::read_dir(app.local(r"C:\Users\Docker\Desktop"))
        .expect("ls")
        .map(|e| e.expect("entry").file_name())
        .collect();
    assert_eq!(names, vec![std::ffi::OsString::from("x.txt")]);
}

#[tokio::test]
async fn setup_upload_to_a_missing_folder_fails_and_leaves_nothing_behind() {
    let app = app();
    let before: Vec<_> =
        std::fs::read_dir(app.local(r"C:\Users\Docker")).expect("ls").map(|e| e.expect("entry").file_name()).collect();
    let path = r"C:\Users\Docker\NoSuchFolder\a.txt";
    app.post_multipart("/setup/upload", &[("file_path", path)], &[("file_data", "a.txt", b"data")])
        .await
        .assert_catch(r"[Errno 2] No such file or directory: 'C:\\Users\\Docker\\NoSuchFolder\\a.txt'");
    assert!(!app.local(r"C:\Users\Docker\NoSuchFolder").exists());
    let after: Vec<_> =
        std::fs::read_dir(app.local(r"C:\Users\Docker")).expect("ls").map(|e| e.expect("entry").file_name()).collect();
    assert_eq!(before, after);
}

#[tokio::test]
async fn setup_upload_needs_both_parts() {
    let app = app();
    let missing = json!({"error": "file_path and file_data are required"});
    app.post_multipart("/setup/upload", &[("file_path", r"C:\a.txt")], &[])
        .await
        .assert_json(StatusCode::BAD_REQUEST, missing.clone());
    // file_data sent as a plain field is not a file part.
    app.post_multipart("/setup/upload", &[("file_path", r"C:\a.txt"), ("file_data", "x")], &[])
        .await
        .assert_json(StatusCode::BAD_REQUEST, missing.clone());
    app.post_form("/setup/upload", "file_path=C%3A%5Ca.txt")
        .await
        .assert_json(StatusCode::BAD_REQUEST, missing.clone());
    app.post("/setup/upload").await.assert_json(StatusCode::BAD_REQUEST, missing);
}

#[tokio::test]
async fn file_error_cases_match_upstream() {
    let app = app();
    app.post("/file").await.assert_json(StatusCode::BAD_REQUEST, json!({"error": "file_path is required"}));
    app.post_form("/file", "file_path=C%3A%5Cnope.txt")
        .await
        .assert_json(StatusCode::NOT_FOUND, json!({"error": "File not found"}));
    app.post_form("/file", "file_path=C%3A%5CUsers").await.assert_catch(r"[Errno 13] Permission denied: 'C:\\Users'");
}

// ----- 26, 27: /platform, /cursor_position -----

#[tokio::test]
async fn platform_is_windows_text() {
    app().get("/platform").await.assert_text(StatusCode::OK, "Windows");
}

#[tokio::test]
async fn cursor_position_answers_json_instead_of_crashing() {
    let app = app_scenario(json!({"cursor": {"x": 12, "y": 34}}));
    app.get("/cursor_position").await.assert_json(StatusCode::OK, json!({"x": 12, "y": 34}));
}

// ----- 29, 30: /setup/download_file, /setup/open_file -----

#[tokio::test]
async fn setup_download_file_is_disabled() {
    let app = app();
    app.post_json("/setup/download_file", json!({"url": "http://x"}))
        .await
        .assert_text(StatusCode::BAD_REQUEST, "Path or URL not supplied!");
    app.post_json("/setup/download_file", json!({"url": "http://example.com/a.txt", "path": r"C:\Users\Docker\a.txt"}))
        .await
        .assert_text(
            StatusCode::INTERNAL_SERVER_ERROR,
            "Failed to download http://example.com/a.txt. No retries left. Error: guest-side downloads are disabled; the host uploads files",
        );
    assert!(!app.local(r"C:\Users\Docker\a.txt").exists());
}

#[tokio::test]
async fn setup_open_file_opens_existing_files() {
    let app = app();
    let path = r"C:\Users\Docker\Desktop\example.txt";
    app.write(path, b"hello");
    app.post_json("/setup/open_file", json!({"path": path}))
        .await
        .assert_text(StatusCode::OK, "File opened successfully");
    assert!(app.stub.find_window("example.txt").is_some());
    app.post_json("/setup/open_file", json!({"path": ""}))
        .await
        .assert_text(StatusCode::BAD_REQUEST, "Path not supplied!");
    app.post_json("/setup/open_file", json!({"path": "~/Desktop/missing.docx"}))
        .await
        .assert_text(StatusCode::NOT_FOUND, r"File not found: C:\Users\Docker\Desktop\missing.docx");
}

// ----- 31, 33, 34: windows -----

fn two_windows() -> Value {
    json!({"windows": [
        {"title": "Untitled - Notepad", "class_name": "Notepad", "focused": true},
        {"title": "VLC media player", "class_name": "Qt5QWindowIcon"},
    ]})
}

#[tokio::test]
async fn setup_activate_window_strict_brings_the_window_forward() {
    let app = app_scenario(two_windows());
    app.post_json("/setup/activate_window", json!({"window_name": "vlc MEDIA", "strict": true}))
        .await
        .assert_text(StatusCode::OK, "Window activated successfully");
    assert_eq!(app.focused_title().as_deref(), Some("VLC media player"));
}

#[tokio::test]
async fn setup_activate_window_non_strict_also_activates() {
    let app = app_scenario(two_windows());
    app.post_json("/setup/activate_window", json!({"window_name": "VLC", "strict": false}))
        .await
        .assert_text(StatusCode::OK, "Window activated successfully");
    assert_eq!(app.focused_title().as_deref(), Some("VLC media player"));
}

#[tokio::test]
async fn setup_activate_window_error_texts() {
    let app = app_scenario(two_windows());
    app.post_json("/setup/activate_window", json!({"window_name": ""}))
        .await
        .assert_text(StatusCode::BAD_REQUEST, "window_name required");
    app.post_json("/setup/activate_window", json!({"window_name": "x", "by_class": "yes"})).await.assert_text(
        StatusCode::INTERNAL_SERVER_ERROR,
        "Get window by class name is currently not supported on Windows.",
    );
    app.post_json("/setup/activate_window", json!({"window_name": "Word"}))
        .await
        .assert_text(StatusCode::NOT_FOUND, "Window Word not found (empty results)");
}

#[tokio::test]
async fn setup_close_window_closes_the_first_match_and_strict_is_always_404() {
    let app = app_scenario(two_windows());
    app.post_json("/setup/close_window", json!({"window_name": "notepad", "strict": true}))
        .await
        .assert_text(StatusCode::NOT_FOUND, "Window notepad not found (strict mode).");
    assert!(app.stub.find_window("Notepad").is_some());
    app.post_json("/setup/close_window", json!({"window_name": "notepad"}))
        .await
        .assert_text(StatusCode::OK, "Window closed successfully.");
    assert!(app.stub.find_window("Notepad").is_none());
    app.post_json("/setup/close_window", json!({"window_name": "notepad"}))
        .await
        .assert_text(StatusCode::NOT_FOUND, "Window notepad not found (empty results)");
    app.post_json("/setup/close_window", json!({})).await.assert_text(StatusCode::BAD_REQUEST, "window_name required");
    app.post_json("/setup/close_window", json!({"window_name": "x", "by_class": true})).await.assert_text(
        StatusCode::INTERNAL_SERVER_ERROR,
        "Get window by class name is not supported on Windows currently.",
    );
}

#[tokio::test]
async fn setup_close_all_closes_every_titled_window_but_program_manager() {
    let app = app_scenario(json!({"windows": [
        {"title": "Untitled - Notepad"},
        {"title": "Administrator: C:\\Windows\\System32\\WindowsPowerShell\\v1.0\\powershell.exe"},
        {"title": "VLC media player"},
    ]}));
    app.post("/setup/close_all").await.assert_text(StatusCode::OK, "All windows closed successfully.");
    let titles: Vec<String> = app.stub.windows().expect("windows").into_iter().map(|w| w.title).collect();
    assert_eq!(
        titles,
        vec![
            "Administrator: C:\\Windows\\System32\\WindowsPowerShell\\v1.0\\powershell.exe".to_owned(),
            "Program Manager".to_owned()
        ]
    );
}

// ----- 32: /setup/clear_task_files -----

#[tokio::test]
async fn setup_clear_task_files_removes_files_and_reports_folders() {
    let app = app();
    for name in ["a.txt", "B.docx", ".hidden", "desktop.ini"] {
        app.write(&format!(r"C:\Users\Docker\Downloads\{name}"), b"x");
    }
    std::fs::create_dir_all(app.local(r"C:\Users\Docker\Downloads\sub")).expect("mkdir");
    app.post("/setup/clear_task_files").await.assert_text(
        StatusCode::OK,
        r"Failed to remove (['C:\\Users\\Docker\\Downloads\\sub']) but sucessfully cleared (['C:\\Users\\Docker\\Downloads\\a.txt', 'C:\\Users\\Docker\\Downloads\\B.docx']) from 'C:\\Users\\Docker\\Downloads'.",
    );
    let mut left: Vec<String> = std::fs::read_dir(app.local(r"C:\Users\Docker\Downloads"))
        .expect("ls")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    left.sort();
    assert_eq!(left, vec![".hidden", "desktop.ini", "sub"]);

    std::fs::remove_dir(app.local(r"C:\Users\Docker\Downloads\sub")).expect("rmdir");
    app.post_json("/setup/clear_task_files", json!({}))
        .await
        .assert_text(StatusCode::OK, r"No task files to clear from 'C:\\Users\\Docker\\Downloads'.");
    app.write(r"C:\Users\Docker\Downloads\c.txt", b"x");
    app.post("/setup/clear_task_files")
        .await
        .assert_text(StatusCode::OK, r"All task files (['C:\\Users\\Docker\\Downloads\\c.txt']) cleared successfully from 'C:\\Users\\Docker\\Downloads'.");
}

// ----- 35-38: recording and snapshots -----

#[tokio::test]
async fn end_recording_without_a_recording_is_400() {
    app().post("/end_recording").await.assert_json(
        StatusCode::BAD_REQUEST,
        json!({"status": "error", "message": "No recording in progress to stop."}),
    );
}

#[tokio::test]
async fn start_recording_reports_a_missing_ffmpeg() {
    let app = app();
    let answer = app.post("/start_recording").await;
    if answer.status == StatusCode::OK {
        // This machine has an ffmpeg: then a second start must be refused.
        let message = answer.json()["message"].as_str().unwrap_or_default().to_owned();
        assert!(
            message.starts_with("Started recording to: ") && message.contains("\nCOMMAND: ffmpeg -y -f gdigrab"),
            "{message}"
        );
        app.post("/start_recording").await.assert_json(
            StatusCode::BAD_REQUEST,
            json!({"status": "error", "message": "Recording is already in progress."}),
        );
    } else {
        answer.assert_catch("[WinError 2] The system cannot find the file specified");
        app.post("/end_recording").await.assert_json(
            StatusCode::BAD_REQUEST,
            json!({"status": "error", "message": "No recording in progress to stop."}),
        );
    }
}

#[tokio::test]
async fn save_state_reproduces_upstreams_checks_then_501() {
    let app = app();
    // The upstream client posts a form body labelled JSON, so the form is empty.
    app.raw(Method::POST, "/save_state", Some("application/json"), "snapshot_name=init")
        .await
        .assert_json(StatusCode::BAD_REQUEST, json!({"error": "snapshot_name is required"}));
    app.post_form("/save_state", "snapshot_name=init").await.assert_catch(
        "400 Bad Request: The browser (or proxy) sent a request that this server could not understand.\nKeyError: 'file_path'",
    );
    app.post_form("/save_state", "snapshot_name=init&file_path=x")
        .await
        .assert_json(StatusCode::NOT_IMPLEMENTED, json!({"error": "Save snapshot not implemented"}));
}

#[tokio::test]
async fn revert_to_snapshot_is_501() {
    app()
        .post("/revert_to_snapshot")
        .await
        .assert_json(StatusCode::NOT_IMPLEMENTED, json!({"error": "Restore snapshot no implemented"}));
}

// ----- 40-42: file-system evaluator helpers -----

#[tokio::test]
async fn is_directory_read_only_for_user_applies_the_mask_rule() {
    let app = app_scenario(json!({
        "dirs": [r"C:\Users\Docker\Documents\ReadOnly", r"C:\Users\Docker\Documents\Open"],
        "acls": {r"C:\Users\Docker\Documents\ReadOnly": {"Docker": 0x1200A9}, r"C:\Users\Docker\Documents\Open": {"Docker": 0x1F01FF}},
    }));
    app.post_json(
        "/is_directory_read_only_for_user",
        json!({"directory": r"C:\Users\Docker\Documents\ReadOnly", "user": "Docker"}),
    )
    .await
    .assert_json(
        StatusCode::OK,
        json!({"status": "success", "message": "C:\\Users\\Docker\\Documents\\ReadOnly is read-only for Docker"}),
    );
    app.post_json(
        "/is_directory_read_only_for_user",
        json!({"directory": r"C:\Users\Docker\Documents\Open", "user": "Docker"}),
    )
    .await
    .assert_json(
        StatusCode::BAD_REQUEST,
        json!({"status": "error", "message": "C:\\Users\\Docker\\Documents\\Open is not read-only for Docker"}),
    );
    app.post_json("/is_directory_read_only_for_user", json!({"directory": "x"}))
        .await
        .assert_json(StatusCode::BAD_REQUEST, json!({"error": "user is required"}));
    app.post_json("/is_directory_read_only_for_user", json!({"user": "x"}))
        .await
        .assert_json(StatusCode::BAD_REQUEST, json!({"error": "directory is required"}));
}

/// A minimal JPEG holding only an EXIF segment with `XPKeywords` (UTF-16LE, as Windows writes tags).
fn jpeg_with_keywords(keywords: &str) -> Vec<u8> {
    let data: Vec<u8> = keywords.encode_utf16().chain([0]).flat_map(u16::to_le_bytes).collect();
    let mut tiff = b"II*\0".to_vec();
    tiff.extend_from_slice(&8u32.to_le_bytes());
    tiff.extend_from_slice(&1u16.to_le_bytes());
    tiff.extend_from_slice(&0x9c9eu16.to_le_bytes());
    tiff.extend_from_slice(&1u16.to_le_bytes());
    tiff.extend_from_slice(&(data.len() as u32).to_le_bytes());
    tiff.extend_from_slice(&26u32.to_le_bytes());
    tiff.extend_from_slice(&0u32.to_le_bytes());
    tiff.extend_from_slice(&data);
    let mut jpeg = vec![0xff, 0xd8, 0xff, 0xe1];
    jpeg.extend_from_slice(&((2 + 6 + tiff.len()) as u16).to_be_bytes());
    jpeg.extend_from_slice(b"Exif\0\0");
    jpeg.extend_from_slice(&tiff);
    jpeg.extend_from_slice(&[0xff, 0xd9]);
    jpeg
}

#[tokio::test]
async fn are_all_images_tagged_reads_windows_tags_from_exif() {
    let app = app();
    let dir = r"C:\Users\Docker\Pictures\Trip";
    app.write(&format!(r"{dir}\a.jpg"), &jpeg_with_keywords("beach;holiday"));
    app.write(&format!(r"{dir}\b.JPEG"), &jpeg_with_keywords("holiday"));
    app.write(&format!(r"{dir}\notes.txt"), b"not an image");
    app.post_json("/are_all_images_tagged", json!({"directory": dir, "tag": "holiday"})).await.assert_json(
        StatusCode::OK,
        json!({"status": "success", "message": format!("All images in {dir} are tagged with holiday")}),
    );
    app.post_json("/are_all_images_tagged", json!({"directory": dir, "tag": "beach"})).await.assert_json(
        StatusCode::BAD_REQUEST,
        json!({"status": "error", "message": format!("b.JPEG in {dir} is not tagged with beach")}),
    );
    app.post_json("/are_all_images_tagged", json!({"directory": dir}))
        .await
        .assert_json(StatusCode::BAD_REQUEST, json!({"error": "tag is required"}));
    app.post_json("/are_all_images_tagged", json!({"directory": r"C:\Users\Docker\Nope", "tag": "x"}))
        .await
        .assert_catch(r"[WinError 3] The system cannot find the path specified: 'C:\\Users\\Docker\\Nope'");
}

#[tokio::test]
async fn library_folders_lists_the_library_urls_sorted() {
    let xml = r#"<?xml version="1.0" encoding="UTF-8"?>
<libraryDescription xmlns="http://schemas.microsoft.com/windows/2009/library">
  <searchConnectorDescriptionList>
    <searchConnectorDescription><simpleLocation><url>C:\Users\Docker\Pictures</url></simpleLocation></searchConnectorDescription>
    <searchConnectorDescription><simpleLocation><url>C:\Art</url></simpleLocation></searchConnectorDescription>
  </searchConnectorDescriptionList>
</libraryDescription>"#;
    let app = app_scenario(
        json!({"files": {r"C:\Users\Docker\AppData\Roaming\Microsoft\Windows\Libraries\Pictures.library-ms": format!("\u{feff}{xml}")}}),
    );
    app.post_json("/library_folders", json!({"library_name": "Pictures"}))
        .await
        .assert_json(StatusCode::OK, json!({"status": "success", "output": [r"C:\Art", r"C:\Users\Docker\Pictures"]}));
    app.post_json("/library_folders", json!({"library_name": "Videos"}))
        .await
        .assert_json(StatusCode::BAD_REQUEST, json!({"error": "Videos does not exist"}));
    app.post_json("/library_folders", json!({}))
        .await
        .assert_json(StatusCode::BAD_REQUEST, json!({"error": "library_name is required"}));
}
