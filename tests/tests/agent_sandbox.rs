//! An exec agent in its sandbox (issue 43, item 1): a hostile agent that looks for
//! the answers and the results from inside its process finds neither, and the same
//! agent run with `--agent-sandbox none` finds both, which shows the probes work.
//!
//! The agent (a shell script) answers each step after four probes: reading the gold
//! task file under `--tasks`, writing `1` over the first task's `result.txt` under
//! `--out`, finding `--out` on its parent's command line, and finding the guest
//! token in its environment. When any probe succeeds it answers `DONE`, else
//! `FAIL`; the second task is the infeasible one, which only `FAIL` solves.

#![cfg(target_os = "linux")]

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use arena_test_support::workspace_binary;

/// The two stub tasks, copied under `dir/tasks`.
fn tasks(dir: &Path) -> PathBuf {
    for (domain, name) in [("notepad", "stub-notepad-count"), ("settings", "stub-settings-infeasible")] {
        arena_test_support::copy_stub_task(domain, name, &dir.join("tasks").join(domain));
    }
    dir.join("tasks")
}

/// The probing agent, as a script that knows the run's paths.
fn agent(dir: &Path, tasks: &Path, out: &Path) -> String {
    let gold = tasks.join("settings").join("stub-settings-infeasible.json");
    let first = out.join("exec/a11y_tree/m/0/notepad/stub-notepad-count/result.txt");
    let hello = r#"{"type":"hello","protocol":1,"agent":"prober","action_space":"pyautogui","observation":{"screenshot":"none","a11y":"none","windows":false,"clipboard":false}}"#;
    let script = format!(
        r#"read -r line
printf '%s\n' '{hello}'
while read -r line; do
  case "$line" in
    *'"type":"reset"'*) printf '%s\n' '{{"type":"ready"}}' ;;
    *)
      found=""
      cat '{gold}' >/dev/null 2>&1 && found="$found gold"
      [ -f '{first}' ] && printf '1' > '{first}' 2>/dev/null && found="$found result"
      tr '\0' ' ' < /proc/$PPID/cmdline 2>/dev/null | grep -q -- '--out' && found="$found cmdline"
      env | grep -q '^ARENA_TOKEN=' && found="$found token"
      echo "probes found:$found" >&2
      if [ -n "$found" ]; then
        printf '%s\n' '{{"type":"act","actions":["DONE"]}}'
      else
        printf '%s\n' '{{"type":"act","actions":["FAIL"]}}'
      fi ;;
  esac
done
"#,
        gold = gold.display(),
        first = first.display(),
    );
    let path = dir.join("prober.sh");
    std::fs::write(&path, script).expect("the agent script");
    format!("sh {}", path.display())
}

/// `arena run` of the prober with `extra`; its exit code and output.
fn run(tasks: &Path, out: &Path, cmd: &str, extra: &[&str]) -> (Option<i32>, String) {
    let exe = workspace_binary("arena-host", "arena").expect("the arena binary");
    let output = Command::new(exe)
        .args(["run", "--stub-guests", "1", "--pauses", "fast", "--order", "sorted", "--agent", "exec"])
        .args(["--model", "m", "--agent-cmd", cmd, "--tasks"])
        .arg(tasks)
        .arg("--out")
        .arg(out)
        .args(extra)
        .env("ARENA_TOKEN", "a-token-no-agent-may-read")
        .stdin(Stdio::null())
        .output()
        .expect("arena run runs");
    let text = format!("{}{}", String::from_utf8_lossy(&output.stderr), String::from_utf8_lossy(&output.stdout));
    (output.status.code(), text)
}

fn score(out: &Path, domain: &str, name: &str) -> String {
    let file = out.join("exec/a11y_tree/m/0").join(domain).join(name).join("result.txt");
    std::fs::read_to_string(&file).unwrap_or_else(|err| panic!("{}: {err}", file.display()))
}

fn summary_options(out: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(out.join("summary.json")).expect("summary.json");
    serde_json::from_str::<serde_json::Value>(&text).expect("JSON")["options"].clone()
}

#[test]
fn a_sandboxed_exec_agent_reads_no_answer_and_changes_no_result() {
    if !arena_test_support::bwrap_or_skip("a_sandboxed_exec_agent_reads_no_answer_and_changes_no_result") {
        return;
    }
    let tmp = tempfile::tempdir().expect("tmp");
    let tasks = tasks(tmp.path());

    let out = tmp.path().join("sandboxed");
    let cmd = agent(tmp.path(), &tasks, &out);
    let (code, text) = run(&tasks, &out, &cmd, &[]);
    assert_eq!(code, Some(0), "{text}");
    let found: Vec<&str> = text.lines().filter(|l| l.contains("probes found:")).collect();
    assert_eq!(found.len(), 2, "one line per step: {text}");
    for probe in ["gold", "result", "cmdline", "token"] {
        assert!(found.iter().all(|l| !l.contains(&format!(" {probe}"))), "{probe} found in the sandbox: {text}");
    }
    assert_eq!(score(&out, "notepad", "stub-notepad-count").trim(), "0", "the first result is untouched");
    assert_eq!(score(&out, "settings", "stub-settings-infeasible").trim(), "1", "FAIL: nothing was found");
    let options = summary_options(&out);
    assert_eq!(options["agent_sandbox"], serde_json::json!(["bwrap"]), "{options}");
    assert_eq!(options["agent_network"], serde_json::json!(["host"]), "{options}");

    // The same agent with the harness's view finds everything, so the probes work.
    let out = tmp.path().join("open");
    let cmd = agent(tmp.path(), &tasks, &out);
    let (code, text) = run(&tasks, &out, &cmd, &["--agent-sandbox", "none"]);
    assert_eq!(code, Some(0), "{text}");
    assert!(text.contains("probes found: gold result cmdline"), "{text}");
    assert!(!text.contains("token"), "the guest token is withheld even without the sandbox: {text}");
    assert_eq!(score(&out, "notepad", "stub-notepad-count").trim(), "1", "rewritten from outside a sandbox");
    assert_eq!(score(&out, "settings", "stub-settings-infeasible").trim(), "0", "DONE: it found the answers");
    assert_eq!(summary_options(&out)["agent_sandbox"], serde_json::json!(["none"]));
}
