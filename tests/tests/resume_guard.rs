//! Runs that refuse to mix agents (issue 30, item 4): the results path's model
//! level of an outside agent names it (its hello's name, else a fingerprint of
//! `--agent-cmd`), the options record what its hello declared, and
//! resuming into a folder whose recorded options differ is refused with the
//! differences named, unless `--force-resume` (recorded).

#![cfg(unix)]

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use arena_test_support::workspace_binary;

/// A folder `name` holding the stub tasks `tasks` (domain, name).
fn tasks(dir: &Path, name: &str, tasks: &[(&str, &str)]) -> PathBuf {
    let root = dir.join(name);
    for (domain, task) in tasks {
        arena_test_support::copy_stub_task(domain, task, &root.join(domain));
    }
    root
}

/// A step-protocol agent named `name` answering FAIL at once.
fn agent(dir: &Path, name: &str) -> String {
    let hello = format!(
        r#"{{"type":"hello","protocol":1,"agent":"{name}","action_space":"pyautogui","observation":{{"screenshot":"none","a11y":"none","windows":false,"clipboard":false}}}}"#
    );
    let script = format!(
        "read -r line\nprintf '%s\\n' '{hello}'\nwhile read -r line; do\n  case \"$line\" in\n    *'\"type\":\"reset\"'*) printf '%s\\n' '{{\"type\":\"ready\"}}' ;;\n    *) printf '%s\\n' '{{\"type\":\"act\",\"actions\":[\"FAIL\"]}}' ;;\n  esac\ndone\n"
    );
    let path = dir.join(format!("{name}.sh"));
    std::fs::write(&path, script).expect("the agent script");
    format!("sh {}", path.display())
}

fn arena_run(tasks: &Path, out: &Path, args: &[&str]) -> (Option<i32>, String) {
    let exe = workspace_binary("arena-host", "arena").expect("the arena binary");
    let output = Command::new(exe)
        .args(["run", "--stub-guests", "1", "--agent", "exec"])
        .args(arena_test_support::exec_sandbox_args())
        .arg("--tasks")
        .arg(tasks)
        .arg("--out")
        .arg(out)
        .args(args)
        .env_remove("ARENA_LLM_MODEL")
        .stdin(Stdio::null())
        .output()
        .expect("arena run runs");
    (output.status.code(), String::from_utf8_lossy(&output.stderr).into_owned())
}

fn model_folders(out: &Path) -> Vec<String> {
    let dir = out.join("exec").join("a11y_tree");
    let mut names: Vec<String> = std::fs::read_dir(&dir)
        .map(|entries| entries.flatten().map(|e| e.file_name().to_string_lossy().into_owned()).collect())
        .unwrap_or_default();
    names.sort();
    names
}

#[test]
fn two_agents_get_two_folders_and_resuming_into_another_agents_folder_is_refused() {
    let tmp = tempfile::tempdir().expect("tmp");
    let infeasible = ("settings", "stub-settings-infeasible");
    let tasks_one = tasks(tmp.path(), "one", &[infeasible]);
    let tasks_two = tasks(tmp.path(), "two", &[infeasible, ("notepad", "stub-notepad-count")]);
    let tasks = &tasks_one;
    let (a, b) = (agent(tmp.path(), "agent-a"), agent(tmp.path(), "agent-b"));

    // Without --model, each command is its own folder.
    let out = tmp.path().join("out");
    for cmd in [&a, &b] {
        let (code, stderr) = arena_run(tasks, &out, &["--agent-cmd", cmd]);
        assert_eq!(code, Some(0), "{stderr}");
    }
    assert_eq!(model_folders(&out), ["agent-a", "agent-b"], "named by their hello");
    let summary = std::fs::read_to_string(out.join("summary.json")).expect("summary.json");
    let summary: serde_json::Value = serde_json::from_str(&summary).expect("JSON");
    let options = &summary["options"];
    assert_eq!(options["agent_name"], serde_json::json!(["agent-a", "agent-b"]), "{options}");
    assert_eq!(options["action_space"], serde_json::json!(["pyautogui"]), "what the hello declared: {options}");
    assert_eq!(options["coords"], serde_json::json!(["pixels"]), "{options}");
    // Without the preflight's hello, a fingerprint of the command names the folder.
    let unnamed = tmp.path().join("unnamed");
    let (code, stderr) = arena_run(tasks, &unnamed, &["--agent-cmd", &a, "--no-preflight"]);
    assert_eq!(code, Some(0), "{stderr}");
    let folders = model_folders(&unnamed);
    assert!(folders.len() == 1 && folders[0].starts_with("external-") && folders[0].len() == 17, "{folders:?}");

    // The same --model for both: the second would resume into the first's results.
    let shared = tmp.path().join("shared");
    let (code, stderr) = arena_run(tasks, &shared, &["--agent-cmd", &a, "--model", "m"]);
    assert_eq!(code, Some(0), "{stderr}");
    let (code, stderr) = arena_run(tasks, &shared, &["--agent-cmd", &b, "--model", "m"]);
    assert_ne!(code, Some(0), "refused\n{stderr}");
    assert!(stderr.contains("resuming would mix two runs") && stderr.contains("agent_cmd:"), "{stderr}");
    assert!(stderr.contains("agent-a.sh") && stderr.contains("agent-b.sh"), "both commands named: {stderr}");

    // --force-resume goes on and says so in the results of the task it runs.
    let (code, stderr) = arena_run(&tasks_two, &shared, &["--agent-cmd", &b, "--model", "m", "--force-resume"]);
    assert_eq!(code, Some(0), "{stderr}");
    let summary = std::fs::read_to_string(shared.join("summary.json")).expect("summary.json");
    let summary: serde_json::Value = serde_json::from_str(&summary).expect("JSON");
    assert_eq!(summary["options"]["force_resume"], serde_json::json!(["on"]), "{}", summary["options"]);
}

#[test]
fn a_resume_compares_max_steps_difficulty_and_every_trial_folder() {
    let tmp = tempfile::tempdir().expect("tmp");
    let tasks = tasks(tmp.path(), "one", &[("settings", "stub-settings-infeasible")]);
    let a = agent(tmp.path(), "agent-a");
    let out = tmp.path().join("out");
    let run = |extra: &[&str]| {
        let mut args = vec!["--agent-cmd", a.as_str(), "--model", "m"];
        args.extend_from_slice(extra);
        arena_run(&tasks, &out, &args)
    };
    let (code, stderr) = run(&["--max-steps", "5"]);
    assert_eq!(code, Some(0), "{stderr}");
    // The same options resume (nothing to run again)...
    let (code, stderr) = run(&["--max-steps", "5"]);
    assert_eq!(code, Some(0), "{stderr}");
    // ...another step limit or difficulty is another run.
    let (code, stderr) = run(&["--max-steps", "6"]);
    assert_ne!(code, Some(0), "refused\n{stderr}");
    assert!(stderr.contains("max_steps: the folder has 5, this run 6"), "{stderr}");
    let (code, stderr) = run(&["--max-steps", "5", "--difficulty", "hard"]);
    assert_ne!(code, Some(0), "refused\n{stderr}");
    assert!(stderr.contains("difficulty: the folder has normal, this run hard"), "{stderr}");

    // A trial folder other than 0 written with other coordinates: a run of two
    // trials would resume into it, so it is compared too.
    let (code, stderr) = run(&["--max-steps", "5", "--trial-id", "1", "--coords", "grid1000"]);
    assert_eq!(code, Some(0), "{stderr}");
    let (code, stderr) = run(&["--max-steps", "5", "--trials", "2"]);
    assert_ne!(code, Some(0), "refused\n{stderr}");
    let trial_one = Path::new("m").join("1");
    let named = stderr.lines().find(|l| l.contains("coords: the folder has grid1000, this run pixels"));
    assert!(named.is_some_and(|l| l.contains(&*trial_one.to_string_lossy())), "trial folder 1 named: {stderr}");
}
