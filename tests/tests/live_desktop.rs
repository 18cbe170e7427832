//! The live-desktop suite: the real `arena-guest` with its Windows backend on a
//! real Windows desktop, driven by the real host client: a window of our own
//! (`tests/live/testpad.ps1`, WinForms) whose buttons are clicked through Set-of-Marks
//! ids and whose context menu must show in the tree, Explorer and Notepad through UI
//! Automation, the UI Automation health stage, activation, the clipboard, exec
//! timeouts and the doctor.
//!
//! It only runs where `ARENA_LIVE_DESKTOP=1` is set, which the Windows workflow
//! (`.github/workflows/windows.yml`) does on a Windows runner with an interactive
//! desktop; anywhere else it prints a `SKIPPED:` line and passes, so it can never
//! drive a developer's own desktop by accident. It is not counted among the corpus
//! skips: Linux CI cannot run it at all (Wine has no UI Automation).
//!
//! Hosted `windows-latest` runners are Windows Server images: there `calc.exe` starts
//! the classic win32calc, not the Windows 11 Calculator, so the Calculator check runs
//! only with `ARENA_LIVE_WIN11=1` (a Windows 11 client image; the workflow's
//! `windows11-client` job), and the Notepad check runs only where
//! `%SystemRoot%\System32\notepad.exe` exists; each says `SKIPPED:` otherwise.

use std::time::{Duration, Instant};

use arena_client::client::{ClientConfig, GuestClient};
use arena_shared::action::{Action, MouseButton};
use arena_shared::clipboard::ClipboardContent;
use arena_shared::exec::{ExecRequest, LaunchRequest};
use arena_shared::health::Component;
use arena_shared::observation::{A11yNode, A11yQuery, WindowInfo, WindowTarget};
use arena_test_support::{eventually, workspace_binary, Served};

/// Whether this machine asked for the suite.
fn live() -> bool {
    if std::env::var("ARENA_LIVE_DESKTOP").as_deref() == Ok("1") {
        return true;
    }
    arena_test_support::skip(
        "the live-desktop suite",
        "ARENA_LIVE_DESKTOP is not 1 (it drives the real Windows desktop)",
        "ARENA_REQUIRE_LIVE_DESKTOP",
    );
    false
}

fn client(url: &str) -> GuestClient {
    GuestClient::new(url, ClientConfig { token: None, timeout: Duration::from_secs(60), retries: 1 })
        .expect("valid url")
}

fn find<'a>(node: &'a A11yNode, pred: &dyn Fn(&A11yNode) -> bool) -> Option<&'a A11yNode> {
    if pred(node) {
        return Some(node);
    }
    node.children.iter().find_map(|child| find(child, pred))
}

/// Starts `argv` and waits for a new visible window whose title contains `title`.
async fn open(c: &GuestClient, argv: &[&str], title: &str) -> WindowInfo {
    let before: Vec<u64> = c.windows().await.expect("windows").iter().map(|w| w.id).collect();
    c.launch(&LaunchRequest { shell: None, argv: argv.iter().map(|s| (*s).to_owned()).collect() })
        .await
        .unwrap_or_else(|err| panic!("launching {argv:?}: {err}"));
    eventually(&format!("a window titled *{title}*"), Duration::from_secs(30), || async {
        let windows = c.windows().await.ok()?;
        windows.into_iter().find(|w| w.visible && w.title.contains(title) && !before.contains(&w.id))
    })
    .await
}

/// The UIA tree of the foreground window.
async fn foreground_tree(c: &GuestClient) -> A11yNode {
    let tree = c.a11y(&A11yQuery { foreground_only: true, ..A11yQuery::default() }).await.expect("the UIA tree");
    tree.windows.into_iter().next().expect("a foreground window in the tree")
}

async fn notepad(c: &GuestClient) -> WindowInfo {
    let window = open(c, &["notepad.exe"], "Notepad").await;
    c.activate_window(&WindowTarget { id: Some(window.id), title: None }).await.expect("activate Notepad");
    let typed = "typed by the live suite";
    c.act_one(Action::TypeText { text: typed.into(), interval_ms: None }).await.expect("type");
    let tree = foreground_tree(c).await;
    let edit = find(&tree, &|n| {
        matches!(n.role.as_str(), "Edit" | "Document") && n.value.as_deref().is_some_and(|v| v.contains(typed))
    });
    assert!(edit.is_some(), "Notepad's edit control does not hold {typed:?}: {tree:#?}");
    window
}

/// Clicks `buttons` in the foreground window through Set-of-Marks ids, as
/// `computer.mouse.move_id(id)` and a click would.
async fn click_marks(c: &GuestClient, buttons: &[&str]) {
    let screen = c.screen().await.expect("screen");
    for &button in buttons {
        let tree = c.a11y(&A11yQuery { foreground_only: true, ..A11yQuery::default() }).await.expect("tree");
        let marks = arena_som::marks_from_tree(&tree, (screen.physical_width, screen.physical_height));
        let mark = marks
            .entities
            .iter()
            .find(|m| m.text == button)
            .unwrap_or_else(|| panic!("no Set-of-Marks element named {button:?}: {}", marks.candidate_list()));
        // What `computer.mouse.move_id(id)` targets: the centre of rects[id].
        let [x1, y1, x2, y2] = marks.rects[mark.id];
        let (x, y) = ((x1 + x2) / 2, (y1 + y2) / 2);
        c.act_one(Action::Click { x: Some(x), y: Some(y), button: MouseButton::Left, count: 1 })
            .await
            .unwrap_or_else(|err| panic!("clicking {button} at ({x}, {y}): {err}"));
    }
}

/// Our own window (`tests/live/testpad.ps1`): 7 + 2 = through Set-of-Marks ids, 9 on its
/// display, then its context menu open, whose items must be in the tree and in
/// Set-of-Marks (a popup is a tool window the trees keep).
async fn testpad(c: &GuestClient) {
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/live/testpad.ps1");
    let argv = ["powershell.exe", "-NoProfile", "-ExecutionPolicy", "Bypass", "-File", script];
    let window = open(c, &argv, "Arena Testpad").await;
    c.activate_window(&WindowTarget { id: Some(window.id), title: None }).await.expect("activate the testpad");
    click_marks(c, &["Seven", "Plus", "Two", "Equals"]).await;
    eventually("the testpad's display to read 9", Duration::from_secs(10), || async {
        let tree = foreground_tree(c).await;
        find(&tree, &|n| n.name == "Display is 9").map(drop)
    })
    .await;

    // Right-click the window's free area below the notes box: its context menu opens.
    let r = window.rect;
    let (x, y) = (r.x + r.width / 2, r.y + r.height - 20);
    c.act_one(Action::Click { x: Some(x), y: Some(y), button: MouseButton::Right, count: 1 })
        .await
        .expect("right click");
    let screen = c.screen().await.expect("screen");
    eventually("the context menu's items in the tree and in Set-of-Marks", Duration::from_secs(10), || async {
        let tree = c.a11y(&A11yQuery::default()).await.ok()?;
        let in_tree = tree.windows.iter().any(|w| find(w, &|n| n.name == "Select All").is_some());
        let marks = arena_som::marks_from_tree(&tree, (screen.physical_width, screen.physical_height));
        (in_tree && marks.entities.iter().any(|m| m.text == "Select All")).then_some(())
    })
    .await;
    c.act_one(Action::KeyPress { key: "escape".into(), presses: 1 }).await.expect("close the menu");
    c.close_window(&WindowTarget { id: Some(window.id), title: None }).await.expect("close the testpad");
}

/// Clicks Calculator's 7, +, 2, = through Set-of-Marks ids and reads 9 off its display
/// (the Windows 11 Calculator's names: a client image only).
async fn calculator(c: &GuestClient) {
    let window = open(c, &["calc.exe"], "Calculator").await;
    c.activate_window(&WindowTarget { id: Some(window.id), title: None }).await.expect("activate Calculator");
    click_marks(c, &["Seven", "Plus", "Two", "Equals"]).await;
    eventually("Calculator's display to read 9", Duration::from_secs(10), || async {
        let tree = foreground_tree(c).await;
        find(&tree, &|n| n.name.contains("Display is 9")).map(drop)
    })
    .await;
    c.close_window(&WindowTarget { id: Some(window.id), title: None }).await.expect("close Calculator");
}

async fn explorer(c: &GuestClient) {
    let window = open(c, &["explorer.exe", r"C:\Windows"], "Windows").await;
    let tree = foreground_tree(c).await;
    let count = |n: &A11yNode| -> usize {
        fn walk(n: &A11yNode) -> usize {
            1 + n.children.iter().map(walk).sum::<usize>()
        }
        walk(n)
    };
    assert!(count(&tree) > 20, "Explorer's tree is nearly empty: {tree:#?}");
    assert!(find(&tree, &|n| n.name == "System32").is_some(), "no System32 item in Explorer's tree");
    c.close_window(&WindowTarget { id: Some(window.id), title: None }).await.expect("close Explorer");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_windows_backend_drives_a_real_desktop() {
    if !live() {
        return;
    }
    let exe = workspace_binary("arena-guest", "arena-guest").expect("the guest binary");
    let served = Served::start(&exe, &["--backend", "windows", "--port", "0"], None).expect("the guest starts");
    let c = client(&served.url);

    let report = c.doctor().await.expect("the doctor's report");
    println!("{}", report.render_text());
    assert!(report.passed(), "the doctor failed on a live desktop:\n{}", report.render_text());

    let health = c.health().await.expect("health");
    let uia = health.components.iter().find(|s| s.component == Component::Uia).expect("the uia stage");
    assert!(uia.ok, "the UI Automation stage is down on a live desktop: {uia:?}");

    testpad(&c).await;
    let system_root = std::env::var("SystemRoot").unwrap_or_else(|_| r"C:\Windows".into());
    let pad = if std::path::Path::new(&system_root).join(r"System32\notepad.exe").is_file() {
        Some(notepad(&c).await)
    } else {
        let why = format!("no notepad.exe in {system_root}\\System32");
        arena_test_support::skip("the live-desktop suite's Notepad check", &why, "ARENA_REQUIRE_LIVE_NOTEPAD");
        None
    };
    if std::env::var("ARENA_LIVE_WIN11").as_deref() == Ok("1") {
        calculator(&c).await;
    } else {
        arena_test_support::skip(
            "the live-desktop suite's Calculator check",
            "it needs a Windows 11 client image (ARENA_LIVE_WIN11=1)",
            "ARENA_REQUIRE_LIVE_WIN11",
        );
    }
    explorer(&c).await;

    // Activation, on whichever of our windows is open.
    let target = match &pad {
        Some(pad) => pad.clone(),
        None => open(&c, &["explorer.exe", r"C:\Windows"], "Windows").await,
    };
    let active = c.activate_window(&WindowTarget { id: Some(target.id), title: None }).await.expect("activate");
    assert_eq!(active.id, target.id);
    let focused = c.windows().await.expect("windows").into_iter().find(|w| w.focused).expect("a foreground window");
    assert_eq!(focused.id, target.id, "{} is not in the foreground after activation", target.title);

    let text = ClipboardContent::Text { text: "live clipboard ✓".into() };
    c.clipboard_set(&text).await.expect("clipboard set");
    assert_eq!(c.clipboard_get().await.expect("clipboard get"), text);

    let started = Instant::now();
    let slow = ExecRequest {
        shell: Some("start /b ping -n 60 127.0.0.1 >nul & ping -n 60 127.0.0.1".into()),
        timeout_ms: Some(2000),
        ..ExecRequest::default()
    };
    let out = c.exec(&slow).await.expect("exec");
    assert!(out.timed_out, "{out:?}");
    assert!(started.elapsed() < Duration::from_secs(15), "a grandchild held the call for {:?}", started.elapsed());

    c.close_window(&WindowTarget { id: Some(target.id), title: None }).await.expect("close the activated window");
}
