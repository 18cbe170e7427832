//! The guards around the guest, each case asserting its bound and its answer: protected
//! folders under every spelling, body limits by route family, caps on typing and on a
//! batch's duration, the browser forward that reads no body without a browser, image
//! bombs counted as RGBA, bounded echoes, and stub typing that stops when its call is
//! cancelled. Router tests (`tower::ServiceExt::oneshot`, no socket) on the stub.
//!
//! Memory is measured with a counting allocator: the peak of live bytes during one
//! request, over what was live before it. The tests take turns (one lock), so one
//! test's allocations never count in another's peak.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;

use axum::body::{Body, Bytes};
use axum::http::{header, Method, Request, StatusCode};
use axum::Router;
use base64::Engine as _;
use serde_json::{json, Value};
use tower::ServiceExt as _;

use arena_guest::config::ServerConfig;
use arena_guest::desktop::stub::StubDesktop;
use arena_guest::desktop::{CommandSpec, Desktop, DesktopError};
use arena_guest::state::AppState;
use arena_shared::action::Action;

pub mod harness;

/// Counts the bytes live now and the most live since the last [`reset_peak`].
struct Counting;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

fn grew(by: usize) {
    let now = LIVE.fetch_add(by, Ordering::Relaxed) + by;
    PEAK.fetch_max(now, Ordering::Relaxed);
}

// SAFETY: every call is forwarded to the system allocator with the caller's own
// arguments, so its contract is the system allocator's; the counters are only
// arithmetic beside it.
unsafe impl GlobalAlloc for Counting {
    // SAFETY: as the system allocator's `alloc`.
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: the caller upholds `alloc`'s contract, which is passed on unchanged.
        let ptr = unsafe { System.alloc(layout) };
        if !ptr.is_null() {
            grew(layout.size());
        }
        ptr
    }

    // SAFETY: as the system allocator's `dealloc`.
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: `ptr` came from this allocator (hence the system's) with `layout`.
        unsafe { System.dealloc(ptr, layout) };
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
    }

    // SAFETY: as the system allocator's `realloc`.
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY: the caller upholds `realloc`'s contract, which is passed on unchanged.
        let new = unsafe { System.realloc(ptr, layout, new_size) };
        if !new.is_null() {
            LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
            grew(new_size);
        }
        new
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// One test at a time, so that peaks are each test's own.
static SERIAL: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

fn reset_peak() -> usize {
    let live = LIVE.load(Ordering::Relaxed);
    PEAK.store(live, Ordering::Relaxed);
    live
}

const MIB: usize = 1 << 20;

struct App {
    router: Router,
    stub: Arc<StubDesktop>,
    /// The server's input lock, as the doctor takes it.
    input: Arc<tokio::sync::RwLock<()>>,
    dir: tempfile::TempDir,
}

fn app_with(configure: impl FnOnce(&mut ServerConfig)) -> App {
    let dir = tempfile::tempdir().expect("temp dir");
    let stub = Arc::new(harness::stub_in(dir.path(), None, false));
    let mut config = ServerConfig::for_stub();
    configure(&mut config);
    let state = AppState::new(stub.clone(), config, None);
    let input = state.input.clone();
    App { router: arena_guest::router(state), stub, input, dir }
}

fn app() -> App {
    app_with(|_| {})
}

/// What a request answered, and the peak of live bytes while it ran (over those before).
struct Answer {
    status: StatusCode,
    body: Bytes,
    peak: usize,
}

impl Answer {
    fn text(&self) -> String {
        String::from_utf8_lossy(&self.body).into_owned()
    }

    fn message(&self) -> String {
        let body: Value = serde_json::from_slice(&self.body).unwrap_or_else(|_| panic!("not JSON: {}", self.text()));
        body["message"].as_str().unwrap_or_default().to_owned()
    }
}

impl App {
    async fn send(&self, request: Request<Body>) -> Answer {
        let before = reset_peak();
        let (status, _headers, body) = harness::send(&self.router, request).await;
        let peak = PEAK.load(Ordering::Relaxed).saturating_sub(before);
        Answer { status, body, peak }
    }

    async fn json(&self, method: Method, uri: &str, body: Vec<u8>) -> Answer {
        let request = Request::builder()
            .method(method)
            .uri(uri)
            .header(header::HOST, "127.0.0.1")
            .header(header::CONTENT_TYPE, "application/json")
            .body(Body::from(body))
            .expect("request");
        self.send(request).await
    }

    async fn empty(&self, method: Method, uri: &str) -> Answer {
        let request =
            Request::builder().method(method).uri(uri).header(header::HOST, "127.0.0.1").body(Body::empty()).unwrap();
        self.send(request).await
    }
}

fn to_vec(value: &Value) -> Vec<u8> {
    serde_json::to_vec(value).expect("json")
}

#[tokio::test]
async fn rooted_spellings_of_protected_folders_are_refused_on_every_route() {
    let _turn = SERIAL.lock().await;
    let app = app();
    let c = app.dir.path().join("C");
    std::fs::write(c.join("Users/Docker/Desktop/keep.txt"), b"mine").unwrap();
    // The probe's cases: each answered 204 or 200 and removed the folder before.
    for path in
        ["/", "%5C", "%2F%2F", "%5CUsers%5CDocker", "/Users", "/Windows", "/Users/Docker/Desktop/.", "%5CUsers."]
    {
        let answer = app.empty(Method::DELETE, &format!("/v1/files?path={path}&recursive=true")).await;
        assert!(
            matches!(answer.status, StatusCode::FORBIDDEN | StatusCode::BAD_REQUEST),
            "DELETE {path}: {} {}",
            answer.status,
            answer.text()
        );
    }
    for path in ["/Windows", "\\", "/Users/Docker/Documents"] {
        let answer = app.json(Method::POST, "/v1/files/recycle", to_vec(&json!({ "path": path }))).await;
        assert_eq!(answer.status, StatusCode::FORBIDDEN, "recycle {path}: {}", answer.text());
        let answer = app.json(Method::POST, "/setup/recycle", to_vec(&json!({ "path": path }))).await;
        assert_eq!(answer.status, StatusCode::FORBIDDEN, "WAA recycle {path}: {}", answer.text());
    }
    let answer = app.json(Method::POST, "/setup/recycle", to_vec(&json!({"path": "/Users"}))).await;
    assert_eq!(answer.status, StatusCode::FORBIDDEN, "{}", answer.text());
    let answer = app
        .send(
            Request::builder()
                .method(Method::PUT)
                .uri("/v1/files?path=%5CUsers%5CDocker%5CDesktop")
                .header(header::HOST, "127.0.0.1")
                .body(Body::from("x"))
                .unwrap(),
        )
        .await;
    assert_eq!(answer.status, StatusCode::FORBIDDEN, "overwrite: {}", answer.text());
    // Everything is still there, and a file inside is still the agent's to delete.
    assert_eq!(std::fs::read(c.join("Users/Docker/Desktop/keep.txt")).unwrap(), b"mine");
    assert!(c.join("Windows").is_dir() && c.join("Users/Docker/Documents").is_dir());
    let answer = app.empty(Method::DELETE, "/v1/files?path=/Users/Docker/Desktop/keep.txt").await;
    assert_eq!(answer.status, StatusCode::NO_CONTENT, "{}", answer.text());
}

#[tokio::test]
async fn json_routes_refuse_big_bodies_before_buffering_them() {
    let _turn = SERIAL.lock().await;
    let app = app();
    // A 16 MiB window title: 413, and the body is never parsed or echoed.
    let title = "t".repeat(16 * MIB);
    let body = to_vec(&json!({ "title": title }));
    drop(title);
    let answer = app.json(Method::POST, "/v1/windows/activate", body).await;
    assert_eq!(answer.status, StatusCode::PAYLOAD_TOO_LARGE, "{}", answer.text());
    assert!(answer.peak < 4 * MIB, "peak {} bytes", answer.peak);
    assert!(answer.body.len() < 1024, "{}", answer.text());
    // Within the limit, a title that matches nothing is echoed only as a prefix.
    let body = to_vec(&json!({ "title": "t".repeat(900_000) }));
    let answer = app.json(Method::POST, "/v1/windows/activate", body).await;
    assert_eq!(answer.status, StatusCode::NOT_FOUND, "{}", answer.text());
    assert!(answer.body.len() < 1024 && answer.message().contains("900000 bytes in all"), "{}", answer.text());
    // The Python routes: at most 2 MiB (upstream's error text, Flask's 413 through its catch-all).
    let body = to_vec(&json!({ "command": format!("python -c \"x = '{}'\"", "a".repeat(3 * MIB)) }));
    let answer = app.json(Method::POST, "/execute", body).await;
    assert!(answer.text().contains("413 Request Entity Too Large"), "{} {}", answer.status, answer.text());
    assert!(answer.peak < 8 * MIB, "peak {} bytes", answer.peak);
}

#[tokio::test]
async fn typing_and_batches_are_capped_before_anything_runs() {
    let _turn = SERIAL.lock().await;
    let app = app();
    let before = app.stub.cursor_position().unwrap();
    // A 2 MiB text: over the 1 MiB cap, refused by name; the move before it never ran.
    let batch = json!({"actions": [
        {"type": "move_to", "x": 7, "y": 9},
        {"type": "type_text", "text": "x".repeat(2 * MIB)},
    ]});
    let answer = app.json(Method::POST, "/v1/actions", to_vec(&batch)).await;
    assert_eq!(answer.status, StatusCode::BAD_REQUEST, "{}", answer.text());
    assert!(answer.message().contains("at most 1048576"), "{}", answer.message());
    assert_eq!(app.stub.cursor_position().unwrap(), before, "nothing ran");
    // 50 M characters: over the 8 MiB body limit of the route.
    let batch = json!({"actions": [{"type": "type_text", "text": "x".repeat(50_000_000)}]});
    let answer = app.json(Method::POST, "/v1/actions", to_vec(&batch)).await;
    assert_eq!(answer.status, StatusCode::PAYLOAD_TOO_LARGE, "{}", answer.text());
    // A thousand one-minute waits (16.7 hours) are refused at once.
    let batch = json!({"actions": vec![json!({"type": "wait", "ms": 60_000}); 1000]});
    let answer = app.json(Method::POST, "/v1/actions", to_vec(&batch)).await;
    assert_eq!(answer.status, StatusCode::BAD_REQUEST, "{}", answer.text());
    assert!(answer.message().contains("300 s"), "{}", answer.message());
}

#[tokio::test]
async fn stub_typing_stops_when_its_call_is_cancelled() {
    let _turn = SERIAL.lock().await;
    let app = app();
    app.stub.spawn(&CommandSpec::Shell("notepad".into())).unwrap();
    let id = app.stub.find_window("Notepad").expect("notepad");
    let text = Action::TypeText { text: "x".repeat(1 << 20), interval_ms: None };
    // A call whose client went away (or whose deadline passed) before the typing began.
    let cancelled = Arc::new(AtomicBool::new(true));
    let scope = arena_guest::desktop::cancel::Scope::enter("perform", 5, cancelled);
    let res = app.stub.perform(&text);
    drop(scope);
    assert!(matches!(res, Err(DesktopError::Timeout { op: "perform", .. })), "{res:?}");
    assert_eq!(app.stub.window_text(id).unwrap_or_default(), "", "not a character was typed");
    // Outside a cancelled call the same text is typed whole; one byte more is refused.
    app.stub.perform(&text).unwrap();
    assert_eq!(app.stub.window_text(id).unwrap().len(), 1 << 20);
    let over = Action::TypeText { text: "x".repeat((1 << 20) + 1), interval_ms: None };
    assert!(matches!(app.stub.perform(&over), Err(DesktopError::InvalidInput(m)) if m.contains("1048576")));
}

#[tokio::test]
async fn the_browser_forward_reads_no_body_when_no_browser_listens() {
    let _turn = SERIAL.lock().await;
    // A port nobody listens on: bound, then released.
    let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let app = app_with(|c| c.cdp_port = port);
    let polled = Arc::new(AtomicUsize::new(0));
    let counter = polled.clone();
    let chunks = futures_util::stream::iter((0..900).map(move |_| {
        counter.fetch_add(1, Ordering::Relaxed);
        Ok::<_, std::io::Error>(Bytes::from(vec![b'x'; MIB]))
    }));
    let request = Request::builder()
        .method(Method::POST)
        .uri("/v1/browser/json/new")
        .header(header::HOST, "127.0.0.1")
        .body(Body::from_stream(chunks))
        .unwrap();
    let answer = app.send(request).await;
    assert_eq!(answer.status, StatusCode::BAD_GATEWAY, "{}", answer.text());
    assert!(answer.message().contains("no browser is listening"), "{}", answer.text());
    assert_eq!(polled.load(Ordering::Relaxed), 0, "not a byte of the body was read");
}

#[tokio::test]
async fn gray_and_one_bit_png_bombs_are_refused_before_decoding() {
    let _turn = SERIAL.lock().await;
    let app = app();
    // The probe's bomb (16384 x 16000 gray: 250 MiB natively, 1000 MiB as RGBA) and a
    // 1-bit one (32 MiB natively, 1 GiB as RGBA).
    for (width, height, depth) in [(16_384, 16_000, 8), (16_384, 16_384, 1)] {
        let png = arena_test_support::png_claiming(width, height, depth, 0);
        let content = json!({
            "kind": "image",
            "width": width,
            "height": height,
            "png_base64": base64::engine::general_purpose::STANDARD.encode(png),
        });
        let answer = app.json(Method::PUT, "/v1/clipboard", to_vec(&content)).await;
        assert_eq!(answer.status, StatusCode::BAD_REQUEST, "{}", answer.text());
        assert!(answer.message().contains("png_base64"), "{}", answer.text());
        assert!(answer.peak < 16 * MIB, "{width}x{height} at {depth} bits: peak {} bytes", answer.peak);
    }
}

#[tokio::test]
async fn a_request_without_the_token_closes_its_connection() {
    let _turn = SERIAL.lock().await;
    let dir = tempfile::tempdir().expect("temp dir");
    let stub = harness::stub_in(dir.path(), None, false);
    let state = AppState::new(Arc::new(stub), ServerConfig::for_stub(), Some("0123456789abcdef0123".into()));
    let router = arena_guest::router(state);
    let request = Request::builder().uri("/v1/screen").header(header::HOST, "127.0.0.1").body(Body::empty()).unwrap();
    let response = router.oneshot(request).await.unwrap();
    assert_eq!(response.status(), StatusCode::UNAUTHORIZED);
    assert_eq!(response.headers().get(header::CONNECTION).map(|v| v.as_bytes()), Some(&b"close"[..]));
}

#[tokio::test]
async fn the_doctor_waits_for_running_actions_and_puts_the_cursor_back() {
    let _turn = SERIAL.lock().await;
    let App { router, stub, input, dir: _dir } = app();
    stub.perform(&Action::MoveTo { x: 123, y: 456 }).unwrap();
    // An action batch is running.
    let batch = input.read().await;
    let request = Request::get("/v1/doctor").header(header::HOST, "127.0.0.1").body(Body::empty()).unwrap();
    let doctor = tokio::spawn(router.oneshot(request));
    // The doctor queues for the input alone: new batches now wait too.
    for _ in 0..3000 {
        if input.try_read().is_err() {
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(10)).await;
    }
    assert!(input.try_read().is_err(), "the doctor asked for the input");
    assert!(!doctor.is_finished(), "the doctor waits for the running batch");
    drop(batch);
    let response = doctor.await.expect("joined").expect("infallible");
    assert_eq!(response.status(), StatusCode::OK);
    assert_eq!(stub.cursor_position().unwrap(), arena_shared::geometry::Point::new(123, 456), "the cursor is back");
}

#[tokio::test]
async fn agent_code_and_programs_wait_while_the_doctor_has_the_input() {
    let _turn = SERIAL.lock().await;
    let App { router, stub, input, dir: _dir } = app();
    let post = |uri: &str, body: Value| {
        Request::post(uri)
            .header(header::HOST, "127.0.0.1")
            .header(header::CONTENT_TYPE, "application/json")
            .body(Body::from(to_vec(&body)))
            .unwrap()
    };
    let requests = [
        ("/execute", json!({"command": ["python", "-c", "import pyautogui; pyautogui.moveTo(11, 12)"]}), (11, 12)),
        ("/execute_windows", json!({"command": "import pyautogui\npyautogui.moveTo(21, 22)"}), (21, 22)),
        ("/v1/actions", json!({"actions": [{"type": "move_to", "x": 31, "y": 32}]}), (31, 32)),
    ];
    for (uri, body, (x, y)) in requests {
        stub.perform(&Action::MoveTo { x: 1, y: 1 }).unwrap();
        // The doctor has the keyboard and mouse.
        let doctor = input.write().await;
        let call = tokio::spawn(router.clone().oneshot(post(uri, body)));
        // A stub call takes milliseconds; a request that did not wait would have moved the cursor.
        tokio::time::sleep(std::time::Duration::from_millis(300)).await;
        assert!(!call.is_finished(), "{uri} ran while the doctor had the input");
        assert_eq!(stub.cursor_position().unwrap(), arena_shared::geometry::Point::new(1, 1), "{uri}");
        drop(doctor);
        let response = call.await.expect("joined").expect("infallible");
        assert_eq!(response.status(), StatusCode::OK, "{uri}");
        assert_eq!(stub.cursor_position().unwrap(), arena_shared::geometry::Point::new(x, y), "{uri}");
    }
}
