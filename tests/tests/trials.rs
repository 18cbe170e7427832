//! Repeated trials end to end: `arena run --trials 3` over the stub tasks with a
//! deterministic flaky step-protocol agent (`trials/flaky_agent.py`: the
//! oracle, giving up on a task's n-th visit as a pattern says), checked against
//! figures this test computes itself: trial folders 0..2, trial-major order,
//! pass@k, pass^k, the flaky tasks, the interval (its bounds hold the rate and
//! a rebuilt report gives the same), resuming one trial of one task, and
//! `arena compare` of two runs listing the tasks that moved each way.
//!
//! Needs `python3`: without it each test prints `SKIPPED: <test>: python3 not
//! found` and returns, unless `ARENA_REQUIRE_PYTHON` is set.

#![cfg(unix)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use arena_test_support::workspace_binary;
use serde_json::Value;

const TASKS: [(&str, &str); 6] = [
    ("file_explorer", "stub-explorer-fill-file"),
    ("file_explorer", "stub-explorer-open-folder"),
    ("notepad", "stub-notepad-append"),
    ("notepad", "stub-notepad-count"),
    ("notepad", "stub-notepad-draft"),
    ("settings", "stub-settings-infeasible"),
];

/// Run A: per task, whether trial 0, 1, 2 passes.
const PATTERN_A: [&str; 6] = ["PPP", "FFF", "PFP", "FPF", "PPP", "FFP"];
/// Run B, one trial.
const PATTERN_B: [&str; 6] = ["F", "P", "P", "F", "P", "P"];

fn arena() -> PathBuf {
    workspace_binary("arena-host", "arena").expect("the arena binary")
}

/// `arena run` of the flaky agent with `pattern`; answers stdout and stderr.
fn run_flaky(out: &Path, state: &Path, pattern: &[&str; 6], trials: u32) -> String {
    std::fs::create_dir_all(state).expect("state folder");
    let pattern: BTreeMap<&str, &str> = TASKS.iter().map(|(_, n)| *n).zip(pattern.iter().copied()).collect();
    let output = Command::new(arena())
        .args(["run", "--stub-guests", "1", "--pauses", "fast"])
        .args(arena_test_support::exec_sandbox_args())
        .arg("--tasks")
        .arg(arena_test_support::workspace_root().join("tasks/stub"))
        .arg("--out")
        .arg(out)
        .args(["--trials", &trials.to_string(), "--agent", "exec", "--agent-timeout", "60", "--agent-cmd"])
        .arg("python3 -m arena_agent flaky_agent:Flaky")
        .env("PYTHONPATH", arena_test_support::agent_pythonpath(&["tests/tests/agent_protocol", "tests/tests/trials"]))
        // The sandbox lets the agent keep its state folder and the two variables.
        .arg("--agent-writable")
        .arg(state)
        .args(["--agent-env", "ARENA_FLAKY_DIR", "--agent-env", "ARENA_FLAKY_PATTERN"])
        .env("ARENA_FLAKY_DIR", state)
        .env("ARENA_FLAKY_PATTERN", serde_json::to_string(&pattern).expect("JSON"))
        .output()
        .expect("arena run starts");
    format!("{}\n{}", String::from_utf8_lossy(&output.stdout), String::from_utf8_lossy(&output.stderr))
}

fn summary(out: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(out.join("summary.json")).expect("summary.json")).expect("JSON")
}

fn choose(n: u32, k: u32) -> f64 {
    if k > n {
        return 0.0;
    }
    (0..k).map(|i| f64::from(n - i) / f64::from(i + 1)).product()
}

/// pass@k and pass^k in percent over `counts` (n, c), k = 1..=3, from the binomial definitions.
fn expected(counts: &[(u32, u32)]) -> (Vec<f64>, Vec<f64>) {
    let mean =
        |f: &dyn Fn(u32, u32) -> f64| 100.0 * counts.iter().map(|&(n, c)| f(n, c)).sum::<f64>() / counts.len() as f64;
    let at = (1..=3).map(|k| mean(&|n, c| 1.0 - choose(n - c, k) / choose(n, k))).collect();
    let hat = (1..=3).map(|k| mean(&|n, c| choose(c, k) / choose(n, k))).collect();
    (at, hat)
}

fn assert_maps(row: &Value, at: &[f64], hat: &[f64], what: &str) {
    for k in 1..=3usize {
        let got_at = row["pass_at_k"][k.to_string()].as_f64().unwrap_or(f64::NAN);
        let got_hat = row["pass_hat_k"][k.to_string()].as_f64().unwrap_or(f64::NAN);
        assert!((got_at - at[k - 1]).abs() < 1e-9, "{what} pass@{k}: {got_at} != {}\n{row:#}", at[k - 1]);
        assert!((got_hat - hat[k - 1]).abs() < 1e-9, "{what} pass^{k}: {got_hat} != {}\n{row:#}", hat[k - 1]);
    }
}

#[test]
fn three_trials_of_a_flaky_agent_give_pass_at_k_pass_hat_k_and_flaky_tasks() {
    let test = "three_trials_of_a_flaky_agent_give_pass_at_k_pass_hat_k_and_flaky_tasks";
    if !arena_test_support::python3_or_skip(test) {
        return;
    }
    let tmp = tempfile::tempdir().expect("tmp");
    let (out, state) = (tmp.path().join("a"), tmp.path().join("state-a"));
    let log = run_flaky(&out, &state, &PATTERN_A, 3);

    // Trial-major: the six tasks in the run's order, three times over.
    let order: Vec<String> =
        std::fs::read_to_string(state.join("order.txt")).expect("order.txt").lines().map(str::to_owned).collect();
    let once: Vec<String> = TASKS.iter().map(|(_, n)| (*n).to_owned()).collect();
    assert_eq!(order, [once.clone(), once.clone(), once].concat(), "{log}");

    // Each trial in its own folder, scored as the pattern says.
    let summary_json = summary(&out);
    let trials: Vec<&str> =
        summary_json["trials"].as_array().expect("trials").iter().filter_map(Value::as_str).collect();
    assert_eq!(trials.len(), 3, "{trials:?}");
    for (t, trial) in trials.iter().enumerate() {
        assert!(trial.ends_with(&format!("/{t}")), "trial folder {t}: {trial}");
        for ((domain, name), pattern) in TASKS.iter().zip(PATTERN_A) {
            let result = out.join(trial).join(domain).join(name).join("result.txt");
            let score: f64 = std::fs::read_to_string(&result).expect("result.txt").trim().parse().expect("a score");
            let pass = pattern.as_bytes()[t] == b'P';
            assert_eq!(score, if pass { 1.0 } else { 0.0 }, "{name} trial {t}\n{log}");
        }
    }
    assert_eq!(summary_json["options"]["trials"], serde_json::json!(["3"]));

    // pass@k and pass^k, overall and per domain, from the definitions.
    let counts: Vec<(u32, u32)> =
        PATTERN_A.iter().map(|p| (3, p.bytes().filter(|&b| b == b'P').count() as u32)).collect();
    let (at, hat) = expected(&counts);
    assert_maps(&summary_json["overall"], &at, &hat, "overall");
    for domain in summary_json["domains"].as_array().expect("domains") {
        let name = domain["domain"].as_str().expect("name");
        let mine: Vec<(u32, u32)> =
            TASKS.iter().zip(&counts).filter(|((d, _), _)| *d == name).map(|(_, c)| *c).collect();
        let (at, hat) = expected(&mine);
        assert_maps(domain, &at, &hat, name);
    }

    // The flaky tasks: passed in some trials and failed in others.
    let flaky: Vec<&str> = summary_json["flaky_tasks"]
        .as_array()
        .expect("flaky_tasks")
        .iter()
        .filter_map(|t| t["name"].as_str())
        .collect();
    let want: Vec<&str> =
        TASKS.iter().zip(PATTERN_A).filter(|(_, p)| p.contains('P') && p.contains('F')).map(|((_, n), _)| *n).collect();
    assert_eq!(flaky, want);

    // The interval holds the rate, stays in 0..100, and a rebuilt report gives the same one.
    let rate = summary_json["overall"]["success_rate"].as_f64().expect("rate");
    let expected_rate = 100.0 * counts.iter().map(|(_, c)| f64::from(*c)).sum::<f64>() / 18.0;
    assert!((rate - expected_rate).abs() < 1e-9, "{rate} != {expected_rate}");
    let ci: Vec<f64> =
        summary_json["overall"]["rate_ci95"].as_array().expect("rate_ci95").iter().filter_map(Value::as_f64).collect();
    assert!(ci.len() == 2 && 0.0 <= ci[0] && ci[0] < rate && rate < ci[1] && ci[1] <= 100.0, "{ci:?} around {rate}");
    let report = Command::new(arena()).arg("report").arg(&out).output().expect("arena report");
    assert!(report.status.success());
    assert_eq!(summary(&out)["overall"]["rate_ci95"], summary_json["overall"]["rate_ci95"]);
    let md = std::fs::read_to_string(out.join("summary.md")).expect("summary.md");
    assert!(
        md.contains("| pass@3 | pass^3 |") && md.contains("`notepad/stub-notepad-append`: 2 of 3 trials passed"),
        "{md}"
    );
    let html = std::fs::read_to_string(out.join("report.html")).expect("report.html");
    assert!(html.contains("<table id=\"trials\">") && html.contains("stub-notepad-count: 1 of 3 trials passed"));

    // Resuming: one trial of one task without its result runs again, alone.
    let victim = out.join(trials[1]).join("notepad/stub-notepad-count/result.txt");
    std::fs::remove_file(&victim).expect("remove a result");
    let log = run_flaky(&out, &state, &PATTERN_A, 3);
    assert!(log.contains("1 task(s) run, 17 already finished"), "{log}");
    assert!(victim.is_file(), "the trial ran again");
    let order = std::fs::read_to_string(state.join("order.txt")).expect("order.txt");
    assert_eq!(order.lines().count(), 19);
    assert_eq!(order.lines().last(), Some("stub-notepad-count"));
}

#[test]
fn compare_lists_the_tasks_that_moved_each_way() {
    let test = "compare_lists_the_tasks_that_moved_each_way";
    if !arena_test_support::python3_or_skip(test) {
        return;
    }
    let tmp = tempfile::tempdir().expect("tmp");
    let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
    let log_a = run_flaky(&a, &tmp.path().join("state-a"), &PATTERN_A, 3);
    let log_b = run_flaky(&b, &tmp.path().join("state-b"), &PATTERN_B, 1);
    // One trial keeps upstream's layout: trial folder 0 and no `trials` option.
    let sb = summary(&b);
    assert_eq!(sb["trials"].as_array().map(Vec::len), Some(1), "{log_b}");
    assert!(sb["trials"][0].as_str().is_some_and(|t| t.ends_with("/0")));
    assert!(sb["options"].get("trials").is_none(), "{:#}", sb["options"]);

    // What moved, from the patterns: A's mean over three trials against B's one.
    let mean = |p: &str| p.bytes().filter(|&b| b == b'P').count() as f64 / p.len() as f64;
    let (mut better, mut worse) = (Vec::new(), Vec::new());
    for (((_, name), pa), pb) in TASKS.iter().zip(PATTERN_A).zip(PATTERN_B) {
        match mean(pb).partial_cmp(&mean(pa)) {
            Some(std::cmp::Ordering::Greater) => better.push(*name),
            Some(std::cmp::Ordering::Less) => worse.push(*name),
            _ => {}
        }
    }
    let output = Command::new(arena()).arg("compare").args([&a, &b]).output().expect("arena compare");
    let text = String::from_utf8_lossy(&output.stdout);
    assert!(output.status.success(), "{text}\n{}\n{log_a}", String::from_utf8_lossy(&output.stderr));
    assert!(text.contains(&format!("better in B ({}):", better.len())), "{text}");
    assert!(text.contains(&format!("worse in B ({}):", worse.len())), "{text}");
    for name in better.iter().chain(&worse) {
        assert!(text.contains(&format!("/{name}: ")), "{name} is listed\n{text}");
    }
    let json = Command::new(arena()).arg("compare").arg("--json").args([&a, &b]).output().expect("arena compare");
    let json: Value = serde_json::from_slice(&json.stdout).expect("compare --json");
    let names = |key: &str| -> Vec<String> {
        json[key].as_array().expect(key).iter().filter_map(|f| f["name"].as_str().map(str::to_owned)).collect()
    };
    assert_eq!(names("better_in_b"), better);
    assert_eq!(names("worse_in_b"), worse);
    assert_eq!(json["paired_tasks"], 6);
    let rate_a = 100.0 * PATTERN_A.iter().map(|p| mean(p)).sum::<f64>() / 6.0;
    let rate_b = 100.0 * PATTERN_B.iter().map(|p| mean(p)).sum::<f64>() / 6.0;
    let difference = json["difference"].as_f64().expect("difference");
    assert!((difference - (rate_b - rate_a)).abs() < 1e-9, "{difference}");
    let ci: Vec<f64> = json["difference_ci95"].as_array().expect("ci").iter().filter_map(Value::as_f64).collect();
    assert!(ci[0] <= difference && difference <= ci[1], "{ci:?} around {difference}");
}
