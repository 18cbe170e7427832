//! A failed action is counted, not hidden (issue 32, item 2): an agent whose
//! action names a key no keyboard has goes on as upstream goes on, and the
//! task's `action_errors` shows in `summary.json`, `summary.md`, `report.html`
//! and on the console.

use std::process::Command;

use arena_test_support::{copy_stub_task, workspace_binary};
use serde_json::Value;

#[test]
fn an_unknown_key_is_one_action_error_in_the_summary_the_report_and_on_the_console() {
    let tmp = tempfile::tempdir().unwrap();
    let tasks = tmp.path().join("tasks");
    copy_stub_task("notepad", "stub-notepad-draft", &tasks.join("notepad"));
    let plans = tmp.path().join("plans");
    std::fs::create_dir_all(&plans).unwrap();
    // The unknown key fails; the typing and the save after it still run.
    let plan = r#"{"steps": [
        {"code": "pyautogui.press('nosuchkey')", "lang": "pyautogui"},
        {"code": "pyautogui.write('This is a draft.')\npyautogui.hotkey('ctrl', 's')", "lang": "pyautogui"},
        "DONE"]}"#;
    std::fs::write(plans.join("stub-notepad-draft.json"), plan).unwrap();
    let out = tmp.path().join("out");
    let run = Command::new(workspace_binary("arena-host", "arena").unwrap())
        .args(["run", "--stub-guests", "1", "--tasks"])
        .arg(&tasks)
        .arg("--plans")
        .arg(&plans)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    let console = format!("{}{}", String::from_utf8_lossy(&run.stdout), String::from_utf8_lossy(&run.stderr));
    assert!(run.status.success(), "{console}");
    let summary: Value = serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["tasks"][0]["action_errors"], 1, "{summary:#}");
    assert_eq!(summary["overall"]["action_errors"], 1);
    assert_eq!(summary["domains"][0]["action_errors"], 1);
    // Upstream's rule: the episode went on and scored.
    assert_eq!(summary["tasks"][0]["score"], 1.0, "{summary:#}");
    let md = std::fs::read_to_string(out.join("summary.md")).unwrap();
    assert!(md.contains("Action errors: 1 "), "{md}");
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(html.contains("<td class=\"num action-errors\">1</td>"), "the report's task row");
    // The run's line for the task (plain progress, as stderr is no terminal here).
    assert!(console.contains("1 action error(s)"), "{console}");
}
