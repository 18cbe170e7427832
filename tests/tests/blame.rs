//! Whose failure a dead guest is, end to end (issue 30, items 1 and 2): `arena
//! run --agent exec` against the real `arena-guest --backend stub` as a separate
//! process, with a shell-script agent that answers FAIL on every task but one.
//!
//! - Its pyautogui code ends the guest (`kill -9 $PPID` through `subprocess.run`,
//!   which the stub runs as a real host process under `--stub-host-exec`): the task
//!   is the agent's failure (score 0, "Failed by: agent", one attempt), and the run,
//!   left without a guest, ends by itself after `--guest-wait` with the unfinished
//!   tasks listed.
//! - The agent kills the guest while it decides (before any action of the step ran):
//!   the task is the environment's, unfinished, without `result.txt`.
//! - The same kill while it decides its second step, after its first step's action
//!   reached the guest (a kill or reboot it scheduled, landing late): the agent's
//!   failure again, scored 0 and not retried (issue 43, item 2).
//!
//! In both, `summary.json`'s `overall.strict_rate`, `overall.complete` and
//! `missing` count every task of the task list, and `summary.md` and
//! `report.html` say the run is incomplete. The index puts the infeasible task
//! first (FAIL scores 1), then the victim, then two tasks no guest is left for.

#![cfg(unix)]

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use arena_results::RESULT_FILE;
use arena_test_support::{workspace_binary, Served};
use serde_json::{json, Value};

const VICTIM: &str = "stub-notepad-count";

/// The stub tasks' examples, copied beside an index of four of them.
fn corpus(dir: &Path) -> PathBuf {
    let tasks = [
        ("settings", "stub-settings-infeasible"),
        ("notepad", "stub-notepad-count"),
        ("notepad", "stub-notepad-append"),
        ("notepad", "stub-notepad-draft"),
    ];
    for (domain, name) in tasks {
        arena_test_support::copy_stub_task(domain, name, &dir.join("examples").join(domain));
    }
    let index = dir.join("test_some.json");
    let text = r#"{"settings": ["stub-settings-infeasible"], "notepad": ["stub-notepad-count", "stub-notepad-append", "stub-notepad-draft"]}"#;
    std::fs::write(&index, text).expect("the index");
    index
}

/// A step-protocol agent as a shell script: FAIL on every task but the victim,
/// where it runs `victim` (shell lines) and then answers `act` (a JSON file).
fn agent(dir: &Path, victim: &str, act: &Value) -> String {
    let act_file = dir.join("victim-act.json");
    std::fs::write(&act_file, act.to_string()).expect("the victim's act");
    let hello = r#"{"type":"hello","protocol":1,"agent":"sh","action_space":"pyautogui","observation":{"screenshot":"none","a11y":"none","windows":false,"clipboard":false}}"#;
    let script = format!(
        r#"read -r line
printf '%s\n' '{hello}'
task=other
while read -r line; do
  case "$line" in
    *'"type":"reset"'*)
      case "$line" in *'"task_name":"{VICTIM}"'*) task=victim ;; *) task=other ;; esac
      printf '%s\n' '{{"type":"ready"}}' ;;
    *)
      if [ "$task" = victim ]; then
        {victim}
        cat '{act}'; printf '\n'
      else
        printf '%s\n' '{{"type":"act","actions":["FAIL"]}}'
      fi ;;
  esac
done
"#,
        act = act_file.display()
    );
    let path = dir.join("agent.sh");
    std::fs::write(&path, script).expect("the agent script");
    format!("sh {}", path.display())
}

/// `arena run` on one outside guest; answers its exit code and stderr, failing
/// the test when the run does not end by itself within `within`.
fn arena_run(guest: &str, index: &Path, out: &Path, agent_cmd: &str, within: Duration) -> (Option<i32>, String) {
    let exe = workspace_binary("arena-host", "arena").expect("the arena binary");
    let mut child = Command::new(exe)
        .args(["--guest", guest, "run", "--pauses", "fast", "--agent", "exec", "--guest-wait", "2"])
        // The agents here kill the guest's process on this machine, which the sandbox
        // (its own PID namespace) would not let them see.
        .args(["--agent-sandbox", "none"])
        .args(["--attempts", "2", "--agent-cmd", agent_cmd, "--tasks"])
        .arg(index)
        .arg("--out")
        .arg(out)
        .env_remove("ARENA_TOKEN")
        .env_remove("ARENA_TOKEN_FILE")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("arena run starts");
    let readers: Vec<std::thread::JoinHandle<String>> = [
        child.stdout.take().map(|p| Box::new(p) as Box<dyn std::io::Read + Send>),
        child.stderr.take().map(|p| Box::new(p) as Box<dyn std::io::Read + Send>),
    ]
    .into_iter()
    .flatten()
    .map(|mut pipe| {
        std::thread::spawn(move || {
            let mut text = String::new();
            let _ = pipe.read_to_string(&mut text);
            text
        })
    })
    .collect();
    let deadline = Instant::now() + within;
    loop {
        if let Some(status) = child.try_wait().expect("wait") {
            let text: String = readers.into_iter().map(|r| r.join().unwrap_or_default()).collect();
            return (status.code(), text);
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            panic!("arena run did not end by itself within {within:?}");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn summary(out: &Path) -> Value {
    let text = std::fs::read_to_string(out.join("summary.json")).expect("summary.json");
    serde_json::from_str(&text).expect("summary.json is JSON")
}

fn task<'a>(summary: &'a Value, name: &str) -> Option<&'a Value> {
    summary["tasks"].as_array().expect("tasks").iter().find(|t| t["name"] == name)
}

fn missing_names(summary: &Value) -> Vec<String> {
    let mut names: Vec<String> = summary["missing"]
        .as_array()
        .expect("a missing list")
        .iter()
        .map(|m| format!("{}/{}", m["domain"].as_str().expect("domain"), m["name"].as_str().expect("name")))
        .collect();
    names.sort();
    names
}

/// The victim's row as the agent's failure: score 0, "Failed by: agent", one
/// attempt, `result.txt` written; answers its error.
fn assert_the_agents_zero(out: &Path, summary: &Value, text: &str) -> String {
    let victim = task(summary, VICTIM).unwrap_or_else(|| panic!("the victim has a row\n{text}"));
    assert_eq!(victim["score"], json!(0.0), "{victim}\n{text}");
    assert_eq!(victim["status"], "agent_error", "{victim}");
    assert_eq!(victim["failed_by"], "agent", "{victim}");
    assert_eq!(victim["attempt"], json!(1), "not retried: {victim}");
    assert!(out.join(victim["path"].as_str().expect("path")).join(RESULT_FILE).is_file(), "result.txt written");
    victim["error"].as_str().unwrap_or_default().to_owned()
}

/// What both runs share: the infeasible task scored 1, the two after the victim
/// never ran, the run ended early saying so, and the summary files say it is incomplete.
fn assert_incomplete(out: &Path, summary: &Value, code: Option<i32>, text: &str) {
    assert_eq!(code, Some(2), "a run with unfinished tasks exits 2\n{text}");
    assert!(text.contains("the run ended early: no healthy guest left"), "{text}");
    for name in ["stub-notepad-append", "stub-notepad-draft"] {
        assert!(text.contains(&format!("notepad/{name}: not run (no healthy guest left)")), "{name}\n{text}");
        assert!(task(summary, name).is_none(), "{name} never started");
    }
    let infeasible = task(summary, "stub-settings-infeasible").expect("the infeasible task");
    assert_eq!(infeasible["score"], json!(1.0), "{infeasible}");
    assert_eq!(summary["overall"]["complete"], json!(false), "{}", summary["overall"]);
    let md = std::fs::read_to_string(out.join("summary.md")).expect("summary.md");
    assert!(md.contains("This run is incomplete"), "{md}");
    assert!(md.contains("Strict rate"), "{md}");
    let html = std::fs::read_to_string(out.join("report.html")).expect("report.html");
    assert!(html.contains("This run is incomplete") && html.contains("Strict rate"), "report.html says so");
}

#[test]
fn an_agent_whose_code_ends_the_guest_fails_the_task_and_the_run_ends_by_itself() {
    let tmp = tempfile::tempdir().expect("tmp");
    let index = corpus(tmp.path());
    let guest = Served::guest(&["--stub-host-exec"]).expect("the stub guest");
    let code = "import subprocess\nsubprocess.run(['sh', '-c', 'kill -9 $PPID'])";
    let agent_cmd = agent(tmp.path(), ":", &json!({"type": "act", "actions": [code]}));
    let out = tmp.path().join("out");
    let (code, text) = arena_run(&guest.url, &index, &out, &agent_cmd, Duration::from_secs(60));

    let summary = summary(&out);
    let error = assert_the_agents_zero(&out, &summary, &text);
    assert!(error.contains("after the agent's action"), "{error}");
    assert_incomplete(&out, &summary, code, &text);
    let md = std::fs::read_to_string(out.join("summary.md")).expect("summary.md");
    assert!(md.contains(&format!("| notepad | {VICTIM} | 0.0 | agent_error | agent |")), "{md}");

    // Two finished (1 and 0) of four listed: upstream's 50 %, strict 25 %.
    let overall = &summary["overall"];
    assert_eq!(overall["success_rate"], json!(50.0), "{overall}");
    assert_eq!(overall["strict_rate"], json!(25.0), "{overall}");
    assert_eq!(missing_names(&summary), ["notepad/stub-notepad-append", "notepad/stub-notepad-draft"]);
}

#[test]
fn a_guest_that_dies_while_the_agent_decides_leaves_the_task_unfinished() {
    let tmp = tempfile::tempdir().expect("tmp");
    let index = corpus(tmp.path());
    let guest = Served::guest(&[]).expect("the stub guest");
    // The agent kills the guest before answering: no action of the step ran.
    let kill = format!("kill -9 {}; sleep 0.3", guest.pid());
    let agent_cmd = agent(tmp.path(), &kill, &json!({"type": "act", "actions": ["pyautogui.click(10, 10)"]}));
    let out = tmp.path().join("out");
    let (code, text) = arena_run(&guest.url, &index, &out, &agent_cmd, Duration::from_secs(60));

    let summary = summary(&out);
    let victim = task(&summary, VICTIM).unwrap_or_else(|| panic!("the victim has a row\n{text}"));
    assert_eq!(victim["score"], Value::Null, "unfinished: {victim}\n{text}");
    assert_eq!(victim["status"], "infra_error", "{victim}");
    assert_eq!(victim["failed_by"], "environment", "{victim}");
    let error = victim["error"].as_str().unwrap_or_default();
    assert!(error.contains("while the agent was deciding"), "{error}");
    assert!(!out.join(victim["path"].as_str().expect("path")).join(RESULT_FILE).exists(), "no result.txt");
    assert!(text.contains(&format!("notepad/{VICTIM}")), "the victim is listed as unfinished\n{text}");
    assert_incomplete(&out, &summary, code, &text);

    // One finished (1) of four listed: upstream's 100 %, strict 25 %.
    let overall = &summary["overall"];
    assert_eq!(overall["success_rate"], json!(100.0), "{overall}");
    assert_eq!(overall["strict_rate"], json!(25.0), "{overall}");
    assert_eq!(
        missing_names(&summary),
        ["notepad/stub-notepad-append", "notepad/stub-notepad-count", "notepad/stub-notepad-draft"]
    );
}

#[test]
fn a_guest_that_dies_while_the_agent_decides_after_its_first_action_is_the_agents_failure() {
    let tmp = tempfile::tempdir().expect("tmp");
    let index = corpus(tmp.path());
    let guest = Served::guest(&[]).expect("the stub guest");
    // The first step's click reaches the guest; the kill lands while the agent decides step 2.
    let kill = format!("n=$((n+1)); if [ \"$n\" -ge 2 ]; then kill -9 {}; sleep 0.3; fi", guest.pid());
    let agent_cmd = agent(tmp.path(), &kill, &json!({"type": "act", "actions": ["pyautogui.click(10, 10)"]}));
    let out = tmp.path().join("out");
    let (code, text) = arena_run(&guest.url, &index, &out, &agent_cmd, Duration::from_secs(60));

    let summary = summary(&out);
    let error = assert_the_agents_zero(&out, &summary, &text);
    assert!(error.contains("after the agent's action in step 1") && error.contains("decided step 2"), "{error}");
    assert_incomplete(&out, &summary, code, &text);
    let overall = &summary["overall"];
    assert_eq!(overall["success_rate"], json!(50.0), "{overall}");
    assert_eq!(overall["strict_rate"], json!(25.0), "{overall}");
}
