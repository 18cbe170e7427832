//! The guest client against a real in-process stub guest on `127.0.0.1:0`,
//! and against a scripted raw-HTTP peer for what a correct guest never does
//! (wrong hashes, proxy error pages, answers that never come).

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpListener;

use arena_client::client::{sha256_hex, ClientConfig, GuestClient, WindowOp};
use arena_client::error::ClientError;
use arena_shared::action::{Action, ActionBatch, MouseButton};
use arena_shared::clipboard::ClipboardContent;
use arena_shared::error::ErrorCode;
use arena_shared::exec::{ExecRequest, LaunchRequest};
use arena_shared::files::{FileKind, KnownFolder};
use arena_shared::health::{Component, Readiness};
use arena_shared::observation::{A11yNode, A11yQuery, ImageFormat, ScreenshotQuery, WindowTarget};
use arena_shared::registry::{RegistryValue, RegistryWrite};
use arena_test_support::StubGuest;

const TOKEN: &str = "test-token-0123456789abcdef";

/// A stub guest (the shared test launcher), with the token when given.
async fn start_guest(token: Option<&str>) -> StubGuest {
    let token = token.map(str::to_owned);
    StubGuest::start_with(|config| config.token = token).await
}

fn client(url: &str) -> GuestClient {
    GuestClient::new(url, ClientConfig { token: None, timeout: Duration::from_secs(20), retries: 1 }).expect("client")
}

fn authed(url: &str) -> GuestClient {
    GuestClient::new(url, ClientConfig { token: Some(TOKEN.to_owned()), timeout: Duration::from_secs(20), retries: 1 })
        .expect("client")
}

/// Asserts `err` is an API error with this status and code whose message names the guest and the call.
fn assert_api(err: &ClientError, url: &str, call: &str, status: u16, code: ErrorCode) {
    assert_eq!(err.status(), Some(status), "{err}");
    assert_eq!(err.code(), Some(code), "{err}");
    let text = err.to_string();
    assert!(text.starts_with(&format!("guest {url}: {call}: HTTP {status}")), "{text}");
    let ClientError::Api { message, .. } = err else { unreachable!("checked by status()") };
    assert!(!message.is_empty(), "{err}");
}

fn find<'a>(node: &'a A11yNode, needle: &str) -> Option<&'a A11yNode> {
    let holds = |s: Option<&str>| s.is_some_and(|s| s.contains(needle));
    if holds(node.value.as_deref()) || holds(node.text.as_deref()) || holds(Some(&node.name)) {
        return Some(node);
    }
    node.children.iter().find_map(|c| find(c, needle))
}

#[tokio::test]
async fn health_and_wait_ready() {
    let guest = start_guest(None).await;
    let c = client(guest.url());
    let report = c.wait_ready(&[], Duration::from_secs(20), Duration::from_millis(50)).await.expect("ready");
    for component in Component::ALL {
        assert!(report.is_up(component), "{component:?} down: {report:?}");
    }
    let report = c.health().await.expect("health");
    assert_eq!(report.backend, "stub");
    assert_eq!(report.status, Readiness::Ready);
    assert!(!report.auth_required);
    let only =
        c.wait_ready(&[Component::Files], Duration::from_secs(5), Duration::from_millis(50)).await.expect("files up");
    assert!(only.is_up(Component::Files));
}

#[tokio::test]
async fn screen_and_screenshots() {
    let guest = start_guest(None).await;
    let c = client(guest.url());
    let screen = c.screen().await.expect("screen");
    assert_eq!((screen.physical_width, screen.physical_height), (1440, 900));

    let png = c.screenshot(&ScreenshotQuery::default()).await.expect("png");
    assert!(png.bytes.starts_with(b"\x89PNG\r\n\x1a\n"), "not a PNG");
    assert_eq!((png.meta.width, png.meta.height), (1440, 900));
    assert_eq!(png.meta.format, ImageFormat::Png);

    let query =
        ScreenshotQuery { format: ImageFormat::Jpeg, quality: Some(70), max_side: Some(720), cursor: Some(false) };
    let jpeg = c.screenshot(&query).await.expect("jpeg");
    assert!(jpeg.bytes.starts_with(&[0xff, 0xd8]), "not a JPEG");
    assert_eq!(jpeg.meta.width, 720);
    assert!((jpeg.meta.scale - 2.0).abs() < 0.01, "scale {}", jpeg.meta.scale);
}

#[tokio::test]
async fn actions_move_the_cursor_and_bad_keys_are_api_errors() {
    let guest = start_guest(None).await;
    let c = client(guest.url());
    let report = c
        .act(&ActionBatch {
            actions: vec![
                Action::MoveTo { x: 10, y: 20 },
                Action::Click { x: Some(100), y: Some(200), button: MouseButton::Left, count: 1 },
                Action::Wait { ms: 10 },
            ],
        })
        .await
        .expect("batch");
    assert_eq!(report.executed, 3);
    assert_eq!((report.cursor.x, report.cursor.y), (100, 200));

    let err = c.act_one(Action::KeyPress { key: "no-such-key".into(), presses: 1 }).await.expect_err("bad key");
    assert_api(&err, guest.url(), "POST /v1/actions", 400, ErrorCode::BadRequest);
    assert!(err.to_string().contains("no-such-key"), "{err}");
}

#[tokio::test]
async fn notepad_typing_shows_in_windows_and_the_tree() {
    let guest = start_guest(None).await;
    let c = client(guest.url());
    let launched = c.launch(&LaunchRequest { shell: None, argv: vec!["notepad.exe".into()] }).await.expect("launch");
    assert!(launched.pid > 0);
    let windows = c.windows().await.expect("windows");
    let notepad = windows.iter().find(|w| w.title.contains("Notepad")).expect("a Notepad window").clone();
    let target = WindowTarget { id: Some(notepad.id), title: None };
    let active = c.activate_window(&target).await.expect("activate");
    assert!(active.focused);

    c.act_one(Action::TypeText { text: "typed by the client".into(), interval_ms: None }).await.expect("type");
    let tree = c.a11y(&A11yQuery::default()).await.expect("tree");
    assert!(tree.windows.iter().any(|w| find(w, "typed by the client").is_some()), "text not in tree: {tree:?}");
    let fg = c
        .a11y(&A11yQuery { foreground_only: true, max_depth: Some(1), ..A11yQuery::default() })
        .await
        .expect("foreground tree");
    assert_eq!(fg.windows.len(), 1);

    let min = c.minimize_window(&target).await.expect("minimize");
    assert!(min.minimized);
    let restored = c.restore_window(&target).await.expect("restore");
    assert!(!restored.minimized);
    let max = c.maximize_window(&target).await.expect("maximize");
    assert!(max.maximized);
    c.window(WindowOp::Close, &target).await.expect("close");
    let after = c.windows().await.expect("windows");
    assert!(after.iter().all(|w| w.id != notepad.id), "closed window still listed");

    let err = c
        .activate_window(&WindowTarget { id: None, title: Some("no such window title".into()) })
        .await
        .expect_err("missing");
    assert_api(&err, guest.url(), "POST /v1/windows/activate", 404, ErrorCode::NotFound);
}

#[tokio::test]
async fn clipboard_round_trip() {
    let guest = start_guest(None).await;
    let c = client(guest.url());
    c.clipboard_set(&ClipboardContent::Text { text: "copied ✓".into() }).await.expect("set");
    assert_eq!(c.clipboard_get().await.expect("get"), ClipboardContent::Text { text: "copied ✓".into() });
}

#[tokio::test]
async fn files_round_trip_with_hashes() {
    let guest = start_guest(None).await;
    let c = client(guest.url());
    let folders = c.folders().await.expect("folders");
    assert!(folders.folders.iter().any(|(k, _)| *k == KnownFolder::Desktop), "{folders:?}");

    let dir = r"C:\Users\Docker\arena-test";
    let path = format!(r"{dir}\sub\data.bin");
    let bytes: Vec<u8> = (0..=255u8).cycle().take(70_000).collect();
    let written = c.push_file(&path, bytes.clone(), None).await.expect("push");
    assert_eq!(written.size, bytes.len() as u64);
    assert_eq!(written.sha256, sha256_hex(&bytes));

    let pulled = c.pull_file(&path).await.expect("pull");
    assert_eq!(pulled.bytes, bytes);
    assert_eq!(pulled.sha256, sha256_hex(&bytes));

    let stat = c.stat(&path).await.expect("stat");
    assert_eq!((stat.kind, stat.size), (FileKind::File, bytes.len() as u64));
    assert!(c.exists(&path).await.expect("exists").exists);
    let listing = c.list_dir(&format!(r"{dir}\sub")).await.expect("list");
    assert_eq!(listing.entries.iter().map(|e| e.name.as_str()).collect::<Vec<_>>(), ["data.bin"]);

    c.mkdir(&format!(r"{dir}\made\deeper")).await.expect("mkdir");
    assert_eq!(c.stat(&format!(r"{dir}\made\deeper")).await.expect("stat dir").kind, FileKind::Dir);

    c.push_file(&format!(r"{dir}\bin.txt"), b"to the bin".to_vec(), None).await.expect("push");
    c.recycle(&format!(r"{dir}\bin.txt")).await.expect("recycle");
    assert!(!c.exists(&format!(r"{dir}\bin.txt")).await.expect("exists").exists);

    c.delete(&path, false).await.expect("delete");
    assert!(!c.exists(&path).await.expect("exists").exists);
    c.delete(dir, true).await.expect("delete tree");
    assert!(!c.exists(dir).await.expect("exists").exists);

    let err = c.pull_file(&path).await.expect_err("gone");
    assert_api(&err, guest.url(), "GET /v1/files", 404, ErrorCode::NotFound);
    let err = c.stat(&path).await.expect_err("gone");
    assert_api(&err, guest.url(), "GET /v1/files/stat", 404, ErrorCode::NotFound);
}

#[tokio::test]
async fn exec_launch_and_open() {
    // `/v1/exec` of a real command: the stub runs host processes only when told to.
    let guest = StubGuest::start_with(|config| config.stub_host_exec = true).await;
    let c = client(guest.url());
    let argv: Vec<String> = if cfg!(windows) {
        vec!["cmd".into(), "/c".into(), "echo".into(), "hi there".into()]
    } else {
        vec!["echo".into(), "hi there".into()]
    };
    let result = c
        .exec(&ExecRequest {
            shell: None,
            argv,
            timeout_ms: Some(20_000),
            max_output_bytes: None,
            cwd: None,
            stdin: None,
        })
        .await
        .expect("exec");
    assert_eq!(result.exit_code, Some(0), "{result:?}");
    assert!(result.stdout.contains("hi there"), "{result:?}");
    assert!(!result.timed_out);

    c.push_file(r"C:\Users\Docker\note.txt", b"open me".to_vec(), None).await.expect("push");
    c.open(r"C:\Users\Docker\note.txt").await.expect("open");
    let windows = c.windows().await.expect("windows");
    assert!(windows.iter().any(|w| w.title.contains("note.txt")), "{windows:?}");
}

#[tokio::test]
async fn registry_round_trip() {
    let guest = start_guest(None).await;
    let c = client(guest.url());
    let key = r"HKCU\Software\ArenaTest";
    c.registry_set(&RegistryWrite { key: key.into(), value: Some("Answer".into()), data: RegistryValue::Dword(42) })
        .await
        .expect("set");
    let read = c.registry_get(key, Some("Answer")).await.expect("get");
    assert_eq!(read.data, RegistryValue::Dword(42));
    let err = c.registry_get(key, Some("Missing")).await.expect_err("missing");
    assert_api(&err, guest.url(), "GET /v1/registry", 404, ErrorCode::NotFound);
}

#[tokio::test]
async fn the_token_is_sent_and_required() {
    let guest = start_guest(Some(TOKEN)).await;
    let anonymous = client(guest.url());
    // Health is open, so readiness can be polled before the token is known.
    let report = anonymous.health().await.expect("open health");
    assert!(report.auth_required);
    let err = anonymous.screen().await.expect_err("no token");
    assert_api(&err, guest.url(), "GET /v1/screen", 401, ErrorCode::Unauthorized);
    authed(guest.url()).screen().await.expect("with token");
}

#[tokio::test]
async fn a_closed_port_fails_fast_naming_the_url() {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
    let port = listener.local_addr().expect("addr").port();
    drop(listener);
    let url = format!("http://127.0.0.1:{port}");
    let c = client(&url);
    let started = Instant::now();
    let err = c.screen().await.expect_err("nothing listens");
    assert!(matches!(err, ClientError::Connect { .. }), "{err:?}");
    assert!(err.to_string().starts_with(&format!("guest {url}: GET /v1/screen: cannot connect")), "{err}");
    assert!(started.elapsed() < Duration::from_secs(10), "took {:?}", started.elapsed());

    let err = c.wait_ready(&[], Duration::from_millis(300), Duration::from_millis(50)).await.expect_err("never ready");
    let text = err.to_string();
    assert!(matches!(err, ClientError::NotReady { .. }), "{err:?}");
    assert!(text.contains(&url) && text.contains("cannot connect"), "{text}");
}

// ----- a scripted peer for misbehaviour -----

/// A raw HTTP/1.1 peer that answers every request with `response` (or never,
/// when it is `None`) and counts the requests.
async fn scripted(response: Option<&'static str>) -> (String, Arc<AtomicUsize>) {
    let listener = TcpListener::bind("127.0.0.1:0").await.expect("bind");
    let url = format!("http://{}", listener.local_addr().expect("addr"));
    let hits = Arc::new(AtomicUsize::new(0));
    let counter = hits.clone();
    tokio::spawn(async move {
        while let Ok((mut socket, _)) = listener.accept().await {
            let counter = counter.clone();
            tokio::spawn(async move {
                let mut seen = Vec::new();
                let mut buf = [0u8; 4096];
                // Read the request head (these tests send small bodies, if any, with the head).
                while !seen.windows(4).any(|w| w == b"\r\n\r\n") {
                    match socket.read(&mut buf).await {
                        Ok(0) | Err(_) => return,
                        Ok(n) => seen.extend_from_slice(&buf[..n]),
                    }
                }
                counter.fetch_add(1, Ordering::SeqCst);
                match response {
                    Some(text) => {
                        let _ = socket.write_all(text.as_bytes()).await;
                        let _ = socket.shutdown().await;
                    }
                    None => tokio::time::sleep(Duration::from_secs(60)).await,
                }
            });
        }
    });
    (url, hits)
}

#[tokio::test]
async fn a_wrong_sha256_header_is_an_integrity_error() {
    let (url, _) = scripted(Some(
        "HTTP/1.1 200 OK\r\nContent-Length: 5\r\nx-arena-sha256: 0000000000000000000000000000000000000000000000000000000000000000\r\nConnection: close\r\n\r\nhello",
    ))
    .await;
    let err = client(&url).pull_file(r"C:\a.txt").await.expect_err("mismatch");
    assert!(matches!(err, ClientError::Integrity { .. }), "{err:?}");
    let text = err.to_string();
    assert!(text.contains(&url) && text.contains("GET /v1/files") && text.contains(&sha256_hex(b"hello")), "{text}");
}

#[tokio::test]
async fn gateway_errors_are_retried_for_gets_only_and_keep_a_non_json_body() {
    let (url, hits) = scripted(Some(
        "HTTP/1.1 502 Bad Gateway\r\nContent-Type: text/html\r\nContent-Length: 20\r\nConnection: close\r\n\r\n<h1>bad gateway</h1>",
    ))
    .await;
    let c = GuestClient::new(&url, ClientConfig { token: None, timeout: Duration::from_secs(5), retries: 2 })
        .expect("client");
    let err = c.windows().await.expect_err("502");
    assert_eq!(hits.load(Ordering::SeqCst), 3, "one try and two retries");
    assert_eq!(err.status(), Some(502));
    assert_eq!(err.code(), Some(ErrorCode::Internal));
    assert!(err.to_string().ends_with("HTTP 502 internal: <h1>bad gateway</h1>"), "{err}");

    hits.store(0, Ordering::SeqCst);
    let err = c.act_one(Action::Wait { ms: 1 }).await.expect_err("502");
    assert_eq!(hits.load(Ordering::SeqCst), 1, "actions are never retried");
    assert!(err.to_string().contains("POST /v1/actions"), "{err}");
}

#[tokio::test]
async fn a_silent_guest_times_out_at_the_deadline() {
    let (url, hits) = scripted(None).await;
    let c = GuestClient::new(&url, ClientConfig { token: None, timeout: Duration::from_millis(300), retries: 1 })
        .expect("client");
    let err = c.screen().await.expect_err("no answer");
    assert!(matches!(err, ClientError::Timeout { after, .. } if after == Duration::from_millis(300)), "{err:?}");
    assert_eq!(err.to_string(), format!("guest {url}: GET /v1/screen: no answer within 300 ms"));
    assert_eq!(hits.load(Ordering::SeqCst), 2, "a timed-out GET is retried once");
}
