//! The tree an agent sees, end to end on the stub: a stub guest seeded by a scenario
//! that models what real Windows desktops do to UI Automation (a heavy window whose
//! bulk fetch times out, an open popup menu, tool and cloaked windows, a UI
//! Automation that answers empty trees), read through the real host client, and the
//! accessibility Set-of-Marks built from that tree as the host builds it.
//!
//! The stub feeds these windows through the same walker and root filter as the
//! Windows backend (`arena-a11y-walk`, `desktop/windows/shell.rs`), so what is
//! asserted here is what those decide.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use arena_client::client::{ClientConfig, GuestClient};
use arena_client::error::ClientError;
use arena_shared::health::Component;
use arena_shared::observation::{A11yBackend, A11yNode, A11yQuery, A11yTree};
use arena_som::marks_from_tree;
use arena_test_support::StubGuest;
use serde_json::{json, Value};

fn client(url: &str) -> GuestClient {
    let config = ClientConfig { token: None, timeout: Duration::from_secs(30), retries: 0 };
    GuestClient::new(url, config).expect("valid url")
}

/// A stub guest seeded with `scenario` (written to a file, as `--scenario` takes it).
async fn guest(scenario: Value) -> (StubGuest, tempfile::TempDir) {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let path: PathBuf = dir.path().join("scenario.json");
    std::fs::write(&path, scenario.to_string()).expect("writing the scenario");
    let guest = StubGuest::start_with(|config| config.scenario = Some(path)).await;
    (guest, dir)
}

fn node(role: &str, name: &str, rect: [i32; 4]) -> Value {
    json!({
        "role": role, "class_name": "", "name": name, "enabled": true, "visible": true,
        "rect": {"x": rect[0], "y": rect[1], "width": rect[2], "height": rect[3]}
    })
}

fn names(node: &A11yNode, out: &mut Vec<String>) {
    out.push(node.name.clone());
    for child in &node.children {
        names(child, out);
    }
}

fn all_names(tree: &A11yTree) -> Vec<String> {
    let mut out = Vec::new();
    for window in &tree.windows {
        names(window, &mut out);
    }
    out
}

fn query(backend: A11yBackend, max_ms: u64) -> A11yQuery {
    A11yQuery { backend, max_ms: Some(max_ms), ..A11yQuery::default() }
}

#[tokio::test]
async fn a_window_whose_bulk_fetch_exceeds_its_share_comes_back_partial_with_nodes_within_the_deadline() {
    // 400 controls, each read alone in 2 ms; the bulk fetch would take a minute.
    let controls: Vec<Value> = (0..400)
        .map(|i| node("Button", &format!("control {i}"), [20 + i % 20 * 30, 80 + i / 20 * 20, 28, 18]))
        .collect();
    let scenario = json!({"windows": [
        {"title": "Heavy page - Google Chrome", "class_name": "Chrome_WidgetWin_1", "process_name": "chrome.exe",
         "rect": {"x": 0, "y": 0, "width": 1200, "height": 800},
         "bulk_fetch_ms": 60000, "element_ms": 2, "elements": controls},
        {"title": "notes.txt - Notepad", "class_name": "Notepad", "process_name": "notepad.exe", "text": "hello"}
    ]});
    let (guest, _dir) = guest(scenario).await;
    let client = client(guest.url());
    let max_ms = 800;
    let started = Instant::now();
    let tree = client.a11y(&query(A11yBackend::Uia, max_ms)).await.expect("the tree");
    let took = started.elapsed();

    let heavy =
        tree.windows.iter().find(|w| w.name == "Heavy page - Google Chrome").expect("the heavy window is listed");
    let mut kept = Vec::new();
    names(heavy, &mut kept);
    let controls_kept = kept.iter().filter(|n| n.starts_with("control ")).count();
    assert!(controls_kept > 0 && controls_kept < 400, "{controls_kept} of its controls kept");
    let walked = tree.windows_walked.iter().find(|w| w.partial).expect("a partial window in windows_walked");
    assert_eq!(Some(walked.window_id), heavy.window_id);
    assert!(walked.nodes > 1, "{walked:?}");
    let reason = walked.reason.as_deref().expect("the reason is recorded");
    assert!(reason.contains("subtree fetch failed") && reason.contains("bulk_fetch_ms"), "{reason}");
    assert!(tree.truncated);
    // The other window still gets its turn, and the answer keeps to the request's deadline.
    assert!(tree.windows.iter().any(|w| w.name == "notes.txt - Notepad"));
    assert!(tree.elapsed_ms <= max_ms + 100, "the walk took {} ms of {max_ms}", tree.elapsed_ms);
    assert!(took < Duration::from_millis(max_ms + 2_000), "the request took {took:?}");
}

fn menu_scenario() -> Value {
    json!({"windows": [
        {"title": "", "popup": true, "process_name": "notepad.exe",
         "rect": {"x": 300, "y": 200, "width": 220, "height": 96},
         "elements": [
            node("MenuItem", "Undo", [302, 202, 216, 22]),
            node("MenuItem", "Cut", [302, 226, 216, 22]),
            node("MenuItem", "Paste", [302, 250, 216, 22])
         ]},
        {"title": "Helper", "tool_window": true, "process_name": "updater.exe",
         "rect": {"x": 900, "y": 600, "width": 200, "height": 100},
         "elements": [node("Button", "Helper button", [910, 640, 80, 24])]},
        {"title": "Find", "tool_window": true, "process_name": "notepad.exe",
         "rect": {"x": 700, "y": 100, "width": 300, "height": 120},
         "elements": [node("Button", "Find Next", [720, 180, 80, 24])]},
        {"title": "Microsoft Store", "cloaked": true, "process_name": "WinStore.App.exe",
         "rect": {"x": 100, "y": 100, "width": 800, "height": 600},
         "elements": [node("Button", "Store button", [120, 200, 80, 24])]},
        {"title": "Untitled - Notepad", "class_name": "Notepad", "process_name": "notepad.exe",
         "rect": {"x": 200, "y": 100, "width": 800, "height": 600}, "text": "", "focused": true}
    ]})
}

#[tokio::test]
async fn an_open_popup_menu_is_in_both_trees_and_in_set_of_marks_and_cloaked_windows_are_not() {
    let (guest, _dir) = guest(menu_scenario()).await;
    let client = client(guest.url());
    for backend in [A11yBackend::Uia, A11yBackend::Win32] {
        let tree = client.a11y(&query(backend, 10_000)).await.expect("the tree");
        let names = all_names(&tree);
        for item in ["Undo", "Cut", "Paste"] {
            assert!(names.iter().any(|n| n == item), "{backend:?}: {item} missing from {names:?}");
        }
        let menu = &tree.windows[0];
        assert_eq!(menu.role, if backend == A11yBackend::Uia { "Menu" } else { "PopupMenu" });
        // The foreground process's tool window is kept; a background one and a cloaked window are not.
        assert!(names.iter().any(|n| n == "Find Next"), "{backend:?}: {names:?}");
        for absent in ["Helper button", "Microsoft Store", "Store button"] {
            assert!(!names.iter().any(|n| n == absent), "{backend:?}: {absent} is listed: {names:?}");
        }
        assert!(!tree.truncated, "{:?}", tree.windows_walked);
    }
    // The popup does not take the focus from its owner.
    let windows = client.windows().await.expect("the window list");
    assert!(windows.iter().any(|w| w.title == "Untitled - Notepad" && w.focused));

    // Set-of-Marks from the accessibility tree, as the host builds it for `--som_origin a11y`.
    let tree = client.a11y(&A11yQuery::default()).await.expect("the default tree");
    let screen = client.screen().await.expect("the screen");
    let marks = marks_from_tree(&tree, (screen.physical_width, screen.physical_height));
    for item in ["Undo", "Cut", "Paste"] {
        let mark = marks.entities.iter().find(|m| m.text == item).unwrap_or_else(|| panic!("no mark for {item}"));
        assert_eq!(marks.rects[mark.id][0], 302);
    }
    assert!(!marks.entities.iter().any(|m| m.text == "Store button" || m.text == "Helper button"));
}

#[tokio::test]
async fn a_ui_automation_that_answers_empty_is_recreated_once_by_the_health_stage() {
    let notepad =
        json!({"title": "Untitled - Notepad", "class_name": "Notepad", "process_name": "notepad.exe", "text": "x"});
    // Cured by one re-creation: the stage is up and says what it did; trees are whole again.
    let (cured, _dir) = guest(json!({"uia_empty_until_recreated": true, "windows": [notepad.clone()]})).await;
    let c = client(cured.url());
    let before = c.a11y(&query(A11yBackend::Uia, 5_000)).await.expect("the tree");
    assert!(before.windows.is_empty(), "the modelled fault answers empty trees");
    let health = c.wait_ready(&[Component::Uia], Duration::from_secs(10), Duration::from_millis(50)).await.unwrap();
    let stage = health.components.iter().find(|c| c.component == Component::Uia).expect("the uia stage");
    assert!(stage.ok && stage.detail.contains("re-created"), "{stage:?}");
    let after = c.a11y(&query(A11yBackend::Uia, 5_000)).await.expect("the tree");
    assert!(after.windows.iter().any(|w| w.name == "Untitled - Notepad"));

    // Not cured: the stage is down with the reason, and the harness's readiness wait says so.
    let (broken, _dir2) = guest(json!({"uia_empty": true, "windows": [notepad]})).await;
    let c = client(broken.url());
    let health = c.health().await.expect("health");
    let stage = health.components.iter().find(|c| c.component == Component::Uia).expect("the uia stage");
    assert!(!stage.ok, "{stage:?}");
    assert!(stage.detail.contains("empty tree") && stage.detail.contains("after re-creating"), "{stage:?}");
    assert!(health.is_up(Component::Accessibility), "the win32 stage is unaffected");
    match c.wait_ready(&[], Duration::from_millis(600), Duration::from_millis(100)).await {
        Err(ClientError::NotReady { down, .. }) => assert_eq!(down, [Component::Uia]),
        other => panic!("expected NotReady on the uia stage, got {other:?}"),
    }
}

#[tokio::test]
async fn node_values_are_capped_and_the_cut_is_marked() {
    let big = "x".repeat(200_000);
    let scenario = json!({"windows": [{"title": "Big - Notepad", "class_name": "Notepad", "text": big}]});
    let (guest, _dir) = guest(scenario).await;
    let client = client(guest.url());
    let tree = client.a11y(&A11yQuery { max_nodes: Some(100), ..A11yQuery::default() }).await.expect("the tree");
    let json = serde_json::to_string(&tree).unwrap();
    assert!(json.len() < 64 * 1024, "the tree is {} bytes", json.len());
    let value = tree.windows[0].children.iter().find_map(|c| c.value.as_deref()).expect("the document's value");
    assert!(value.starts_with(&"x".repeat(4096)));
    assert!(value.ends_with(&arena_a11y_walk::text_cut_marker(200_000 - 4096)), "{}", &value[4090..]);
    assert!(tree.truncated);
    let reason = tree.windows_walked[0].reason.as_deref().unwrap_or_default();
    assert!(reason.contains("node texts were cut at 4096 characters"), "{reason}");
}
