//! The real `arena-guest` binary (stub backend) driven by the real host client
//! and the real `arena` CLI over loopback.

use std::process::Command;
use std::time::Duration;

use arena_client::client::{ClientConfig, GuestClient};
use arena_shared::action::{Action, ActionBatch};
use arena_shared::exec::{ExecRequest, LaunchRequest};
use arena_shared::health::{Component, Readiness};
use arena_shared::observation::{A11yNode, A11yQuery, ScreenshotQuery, WindowTarget};
use arena_test_support::{workspace_binary, Served};

fn client(url: &str, token: Option<&str>) -> GuestClient {
    let config = ClientConfig { token: token.map(str::to_owned), timeout: Duration::from_secs(30), retries: 1 };
    GuestClient::new(url, config).expect("valid url")
}

fn find<'a>(node: &'a A11yNode, pred: &dyn Fn(&A11yNode) -> bool) -> Option<&'a A11yNode> {
    if pred(node) {
        return Some(node);
    }
    node.children.iter().find_map(|child| find(child, pred))
}

#[tokio::test]
async fn client_drives_the_real_guest_binary() {
    let guest = Served::guest(&["--stub-host-exec"]).expect("guest starts");
    let client = client(&guest.url, None);

    let health = client.wait_ready(&Component::ALL, Duration::from_secs(30), Duration::from_millis(50)).await.unwrap();
    assert_eq!(health.status, Readiness::Ready);
    assert_eq!(health.backend, "stub");
    assert!(!health.auth_required);

    // Launch a program, type into it, read the text back through the accessibility tree.
    client.launch(&LaunchRequest { shell: None, argv: vec!["notepad".into()] }).await.unwrap();
    let windows = client.windows().await.unwrap();
    let notepad = windows.iter().find(|w| w.title == "Untitled - Notepad").expect("notepad window");
    assert!(notepad.focused);
    let report = client
        .act(&ActionBatch {
            actions: vec![
                Action::Click {
                    x: Some(notepad.rect.x + 50),
                    y: Some(notepad.rect.y + 80),
                    button: Default::default(),
                    count: 1,
                },
                Action::TypeText { text: "héllo wörld".into(), interval_ms: None },
                Action::KeyPress { key: "enter".into(), presses: 1 },
                Action::TypeText { text: "line two".into(), interval_ms: None },
            ],
        })
        .await
        .unwrap();
    assert_eq!(report.executed, 4);
    let tree = client.a11y(&A11yQuery { foreground_only: true, ..A11yQuery::default() }).await.unwrap();
    let edit = tree.windows.iter().find_map(|w| find(w, &|n| n.value.is_some())).expect("an element with a value");
    assert_eq!(edit.value.as_deref(), Some("héllo wörld\nline two"));

    // Screenshot: a real 1440x900 PNG at scale 1.
    let shot = client.screenshot(&ScreenshotQuery::default()).await.unwrap();
    assert_eq!((shot.meta.width, shot.meta.height, shot.meta.scale), (1440, 900, 1.0));
    assert_eq!(&shot.bytes[..8], b"\x89PNG\r\n\x1a\n");
    let small =
        client.screenshot(&ScreenshotQuery { max_side: Some(720), ..ScreenshotQuery::default() }).await.unwrap();
    assert_eq!((small.meta.width, small.meta.height, small.meta.scale), (720, 450, 2.0));

    // Files round trip with hashes; a wrong path is a clear error.
    let path = r"C:\Users\Docker\Desktop\e2e\data.bin";
    let bytes: Vec<u8> = (0..=255u8).cycle().take(300_000).collect();
    let written = client.push_file(path, bytes.clone(), Some(true)).await.unwrap();
    assert_eq!(written.size, 300_000);
    let pulled = client.pull_file(path).await.unwrap();
    assert_eq!(pulled.bytes, bytes);
    assert_eq!(pulled.sha256, written.sha256);
    let err = client.pull_file(r"C:\Users\Docker\Desktop\missing.txt").await.unwrap_err();
    assert_eq!(err.status(), Some(404));
    let message = err.to_string();
    assert!(message.contains(&guest.url) && message.contains("/v1/files"), "{message}");

    // Exec with argv, exit codes and output.
    let res = client
        .exec(&ExecRequest {
            shell: None,
            argv: vec!["sh".into(), "-c".into(), "echo out; echo err >&2; exit 7".into()],
            timeout_ms: Some(10_000),
            max_output_bytes: None,
            cwd: None,
            stdin: None,
        })
        .await
        .unwrap();
    assert_eq!((res.exit_code, res.stdout.as_str(), res.stderr.as_str()), (Some(7), "out\n", "err\n"));

    // Window management by title.
    let closed = client.close_window(&WindowTarget { id: None, title: Some("notepad".into()) }).await.unwrap();
    assert_eq!(closed.title, "Untitled - Notepad");
    assert!(client.windows().await.unwrap().iter().all(|w| w.title != "Untitled - Notepad"));
}

#[tokio::test]
async fn token_is_required_when_configured() {
    let token = "e2e-token-0123456789abcdef";
    let guest = Served::guest(&["--token", token, "--stub-host-exec"]).expect("guest starts");

    let anonymous = client(&guest.url, None);
    // Readiness stays open so hosts can poll before they have the token.
    assert!(anonymous.health().await.unwrap().auth_required);
    let err = anonymous.windows().await.unwrap_err();
    assert_eq!(err.status(), Some(401), "{err}");
    let wrong = client(&guest.url, Some("wrong-token-0123456789abcdef"));
    assert_eq!(wrong.windows().await.unwrap_err().status(), Some(401));
    let right = client(&guest.url, Some(token));
    right.windows().await.unwrap();

    // The legacy routes are guarded too, with upstream's error shape.
    let res = reqwest::Client::new()
        .post(format!("{}/execute", guest.url))
        .json(&serde_json::json!({"command": ["echo", "x"]}))
        .send()
        .await
        .unwrap();
    assert_eq!(res.status(), 401);
    let body: serde_json::Value = res.json().await.unwrap();
    assert_eq!(body["status"], "error");
}

#[test]
fn non_loopback_bind_without_token_is_refused() {
    let exe = workspace_binary("arena-guest", "arena-guest").unwrap();
    let out = Command::new(exe).args(["--backend", "stub", "--bind", "0.0.0.0", "--port", "0"]).output().unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("without a token"), "{stderr}");
}

#[test]
fn bad_scenario_is_a_clear_startup_error() {
    let exe = workspace_binary("arena-guest", "arena-guest").unwrap();
    let dir = tempfile::tempdir().unwrap();
    let scenario = dir.path().join("broken.json");
    std::fs::write(&scenario, "{\"windows\": [ {\"title\": 5} ]}").unwrap();
    let out =
        Command::new(exe).args(["--backend", "stub", "--port", "0", "--scenario"]).arg(&scenario).output().unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("broken.json"), "{stderr}");
}

fn arena(url: &str, args: &[&str]) -> std::process::Output {
    let exe = workspace_binary("arena-host", "arena").unwrap();
    Command::new(exe).arg("--guest").arg(url).args(args).output().unwrap()
}

#[test]
fn cli_drives_a_guest_started_by_serve_stub() {
    let exe = workspace_binary("arena-host", "arena").unwrap();
    let guest =
        Served::start(&exe, &["serve-stub", "--port", "0", "--stub-host-exec"], None).expect("serve-stub starts");
    let url = guest.url.as_str();

    let out = arena(url, &["health"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let out = arena(url, &["launch", "--", "notepad"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    for args in [&["act", "type", "from the cli"][..], &["act", "key", "enter"], &["act", "hotkey", "ctrl", "a"]] {
        let out = arena(url, args);
        assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
    }
    let out = arena(url, &["windows"]);
    assert!(String::from_utf8_lossy(&out.stdout).contains("Untitled - Notepad"));
    let out = arena(url, &["tree", "--json"]);
    let tree: serde_json::Value = serde_json::from_slice(&out.stdout).expect("tree --json prints JSON");
    assert!(tree["windows"].as_array().is_some_and(|w| !w.is_empty()));

    // Bad input is a clear error with a failing exit code.
    let out = arena(url, &["act", "key", "enterr"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("enterr"));

    // Files through the CLI.
    let dir = tempfile::tempdir().unwrap();
    let local = dir.path().join("in.txt");
    std::fs::write(&local, "pushed by the cli").unwrap();
    let out = arena(url, &["push", local.to_str().unwrap(), r"C:\Users\Docker\Documents\in.txt"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let back = dir.path().join("back.txt");
    let out = arena(url, &["pull", r"C:\Users\Docker\Documents\in.txt", back.to_str().unwrap()]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(std::fs::read_to_string(&back).unwrap(), "pushed by the cli");

    let shot = dir.path().join("s.png");
    let out = arena(url, &["screenshot", "-o", shot.to_str().unwrap()]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(&std::fs::read(&shot).unwrap()[..4], b"\x89PNG");

    let out = arena(url, &["exec", "--", "sh", "-c", "exit 3"]);
    assert_eq!(out.status.code(), Some(3));
}

#[test]
fn demo_runs_end_to_end_on_the_embedded_stub() {
    let exe = workspace_binary("arena-host", "arena").unwrap();
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(exe).arg("demo").current_dir(dir.path()).output().unwrap();
    assert!(
        out.status.success(),
        "stdout:\n{}\nstderr:\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(dir.path().join("arena-demo.png").exists());
}
