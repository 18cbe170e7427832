//! Floors and certificates end to end on the stub tasks (`tasks/stub`, in the
//! repository): `arena certify` with the stub tasks' oracle plans writes
//! certificates in which the oracle passes every task, noop passes none and
//! fail passes exactly the infeasible one; `arena run --agent noop` and
//! `--agent fail` score as those agents must, in folders of their own, and the
//! summary shows the FAIL-always floor; certificates that call a task broken
//! (an oracle plan that answers DONE without acting) mark it in the summary and
//! report of `arena run --certificates` and `arena report --certificates`.

use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use arena_test_support::workspace_binary;
use serde_json::Value;

const INFEASIBLE: &str = "stub-settings-infeasible";

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn index() -> PathBuf {
    repo().join("tasks/stub/test_all.json")
}

/// `arena ARGS`, its output.
fn arena<S: AsRef<OsStr>>(args: impl IntoIterator<Item = S>) -> Output {
    let bin = workspace_binary("arena-host", "arena").expect("the arena binary");
    Command::new(bin).args(args).output().expect("arena starts")
}

fn os<S: AsRef<OsStr> + ?Sized>(s: &S) -> &OsStr {
    s.as_ref()
}

fn text(output: &Output) -> String {
    format!("{}\n{}", String::from_utf8_lossy(&output.stdout), String::from_utf8_lossy(&output.stderr))
}

fn json(path: &Path) -> Value {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_slice(&bytes).expect("JSON")
}

/// Every certificate below `out/certificates`, by task name.
fn certificates(out: &Path) -> std::collections::BTreeMap<String, Value> {
    let all = json(&out.join("certificates.json"));
    all.as_array().expect("a list").iter().map(|c| (c["task"].as_str().expect("task").to_owned(), c.clone())).collect()
}

#[test]
fn certify_on_the_stub_tasks_passes_the_oracle_fails_noop_and_floors_the_infeasible_task() {
    let tmp = tempfile::tempdir().expect("tmp");
    let out = tmp.path().join("cert");
    let output = arena([
        os("certify"),
        os("--stub-guests"),
        os("2"),
        os("--pauses"),
        os("fast"),
        os("--trials"),
        os("2"),
        os("--out"),
        os(&out),
        os(&index()),
    ]);
    let all = text(&output);
    assert!(output.status.success(), "{all}");
    // Three runs of the run machinery, each a result folder of its own.
    for agent in ["noop", "fail", "oracle"] {
        let summary = json(&out.join(agent).join("summary.json"));
        assert_eq!(summary["overall"]["complete"], true, "{agent}: {all}");
        assert_eq!(summary["overall"]["tasks"], 12, "{agent}: 6 tasks x 2 trials");
    }
    assert!(out.join("noop/noop/a11y_tree/noop/1").is_dir(), "noop's own folders");
    assert!(out.join("fail/fail/a11y_tree/fail/0").is_dir(), "fail's own folders");
    let certs = certificates(&out);
    assert_eq!(certs.len(), 6, "{certs:?}");
    for (name, cert) in &certs {
        let infeasible = name == INFEASIBLE;
        assert_eq!(cert["certificate_version"], 1);
        assert_eq!(cert["task_id"], name.as_str(), "{cert}");
        assert_eq!(cert["trials"], 2);
        assert_eq!(cert["infeasible"], infeasible, "{name}");
        assert_eq!(cert["passes_without_acting"], false, "{name}: noop passes nothing");
        assert_eq!(
            cert["infeasible_floor"],
            if infeasible { 1.0 } else { 0.0 },
            "{name}: fail passes only the infeasible task"
        );
        assert_eq!(cert["oracle_pass_rate"], 1.0, "{name}: the oracle passes every task");
        assert_eq!(cert["flake_rate"], 0.0, "{name}");
        assert_eq!(cert["certified_broken"], false, "{name}");
        assert_eq!(cert["agents"]["noop"]["scores"], serde_json::json!([0.0, 0.0]), "{name}");
        let images = cert["guest_images"].as_array().expect("images");
        assert_eq!(images.len(), 1, "{cert}");
        assert_eq!(images[0]["backend"], "stub");
        assert!(images[0]["os"].as_str().is_some_and(|os| os.contains("build 22631")), "{cert}");
        let domain = cert["domain"].as_str().expect("domain");
        assert!(out.join("certificates").join(domain).join(format!("{name}.json")).is_file());
    }
    let table = std::fs::read_to_string(out.join("certificates.md")).expect("certificates.md");
    assert!(table.contains("0 of 6 task(s) certified broken"), "{table}");
    assert!(all.contains("| settings | stub-settings-infeasible | yes | no | 100% | 100% | 0% | ok |"), "{all}");
}

#[test]
fn noop_and_fail_runs_score_their_floors_and_the_summary_shows_the_fail_always_floor() {
    let tmp = tempfile::tempdir().expect("tmp");
    let expected_floor = 100.0 / 6.0;
    for (agent, rate) in [("noop", 0.0), ("fail", expected_floor)] {
        let out = tmp.path().join(agent);
        let index = index();
        let output = arena([
            os("run"),
            os("--stub-guests"),
            os("1"),
            os("--pauses"),
            os("fast"),
            os("--agent"),
            os(agent),
            os("--tasks"),
            os(&index),
            os("--out"),
            os(&out),
        ]);
        let all = text(&output);
        assert!(output.status.success(), "{agent}: {all}");
        let summary = json(&out.join("summary.json"));
        let overall = &summary["overall"];
        assert!((overall["success_rate"].as_f64().expect("rate") - rate).abs() < 1e-9, "{agent}: {overall}");
        assert!((overall["fail_floor"].as_f64().expect("floor") - expected_floor).abs() < 1e-9, "{agent}: {overall}");
        // The settings domain is all infeasible, notepad none.
        let domain =
            |name: &str| summary["domains"].as_array().expect("domains").iter().find(|d| d["domain"] == name).cloned();
        assert_eq!(domain("settings").expect("settings")["fail_floor"], 100.0);
        assert_eq!(domain("notepad").expect("notepad")["fail_floor"], 0.0);
        for task in summary["tasks"].as_array().expect("tasks") {
            let passed = task["score"] == 1.0;
            assert_eq!(passed, agent == "fail" && task["name"] == INFEASIBLE, "{agent}: {task}");
            assert_eq!(task["steps"], 1, "{agent} answers at its first step: {task}");
            assert!(
                task["path"].as_str().expect("path").starts_with(&format!("{agent}/a11y_tree/{agent}/0/")),
                "{task}"
            );
        }
        assert_eq!(summary["options"]["agent"], serde_json::json!([agent]));
        let md = std::fs::read_to_string(out.join("summary.md")).expect("summary.md");
        assert!(md.contains("FAIL-always floor 16.7%"), "{md}");
        assert!(all.contains("FAIL-always floor 16.7%"), "printed too: {all}");
        let html = std::fs::read_to_string(out.join("report.html")).expect("report.html");
        assert!(html.contains("id=\"floor\"") && html.contains("FAIL-always floor 16.7%"), "the report");
    }
}

#[test]
fn certificates_that_call_a_task_broken_mark_it_in_the_summary_and_report() {
    let tmp = tempfile::tempdir().expect("tmp");
    // An oracle plan for one task that answers DONE without acting: it fails, so the task is certified broken.
    let plans = tmp.path().join("plans");
    std::fs::create_dir_all(&plans).expect("plans");
    std::fs::write(plans.join("stub-notepad-count.json"), r#"{"steps": ["DONE"]}"#).expect("plan");
    let cert = tmp.path().join("cert");
    let index = index();
    let output = arena([
        os("certify"),
        os("--stub-guests"),
        os("1"),
        os("--trials"),
        os("1"),
        os("--out"),
        os(&cert),
        os("--plans"),
        os(&plans),
        os(&index),
    ]);
    let all = text(&output);
    assert!(output.status.success(), "{all}");
    let certs = certificates(&cert);
    let broken = &certs["stub-notepad-count"];
    assert_eq!(broken["certified_broken"], true, "{broken}");
    assert_eq!(broken["oracle_pass_rate"], 0.0);
    assert!(broken["broken_because"][0].as_str().expect("why").contains("the oracle failed 1 of 1"), "{broken}");
    // The other tasks have no plan here: no oracle, not broken.
    assert_eq!(certs["stub-notepad-append"]["oracle_pass_rate"], Value::Null);
    assert_eq!(certs["stub-notepad-append"]["certified_broken"], false);
    assert!(all.contains("**certified broken**"), "{all}");

    // A run given the certificates marks the task, and records them.
    let run = tmp.path().join("run");
    let output = arena([
        os("run"),
        os("--stub-guests"),
        os("1"),
        os("--agent"),
        os("fail"),
        os("--tasks"),
        os(&index),
        os("--out"),
        os(&run),
        os("--certificates"),
        os(&cert),
    ]);
    let all = text(&output);
    assert!(output.status.success(), "{all}");
    let check = |dir: &Path, printed: &str| {
        let summary = json(&dir.join("summary.json"));
        let listed: Vec<&str> = summary["certificates"]["broken"]
            .as_array()
            .expect("broken tasks")
            .iter()
            .map(|b| b["task"].as_str().expect("task"))
            .collect();
        assert_eq!(listed, ["stub-notepad-count"], "{summary}");
        for task in summary["tasks"].as_array().expect("tasks") {
            let marked = task.get("certified_broken") == Some(&Value::Bool(true));
            assert_eq!(marked, task["name"] == "stub-notepad-count", "{task}");
        }
        let md = std::fs::read_to_string(dir.join("summary.md")).expect("summary.md");
        assert!(md.contains("1 task(s) of this run certified broken"), "{md}");
        assert!(md.contains("| stub-notepad-count (certified broken) |"), "{md}");
        assert!(printed.contains("`notepad/stub-notepad-count`: certified broken"), "{printed}");
        let html = std::fs::read_to_string(dir.join("report.html")).expect("report.html");
        assert!(html.contains("id=\"certified-broken\"") && html.contains("notepad/stub-notepad-count"), "the report");
        assert_eq!(html.matches("(certified broken)</span>").count(), 1, "the task's own section is marked");
    };
    check(&run, &all);
    // `arena report` keeps the record without the flag.
    let output = arena([os("report"), os(&run)]);
    assert!(output.status.success(), "{}", text(&output));
    check(&run, &text(&output));
    // A merge of the run keeps the record.
    let merged = tmp.path().join("merged");
    let output = arena([os("merge"), os(&merged), os(&run)]);
    assert!(output.status.success(), "{}", text(&output));
    check(&merged, &text(&output));

    // A run made without certificates is marked by `arena report --certificates`.
    let plain = tmp.path().join("plain");
    let output = arena([
        os("run"),
        os("--stub-guests"),
        os("1"),
        os("--agent"),
        os("noop"),
        os("--tasks"),
        os(&index),
        os("--out"),
        os(&plain),
    ]);
    assert!(output.status.success(), "{}", text(&output));
    assert!(json(&plain.join("summary.json")).get("certificates").is_none());
    let output = arena([os("report"), os(&plain), os("--certificates"), os(&cert)]);
    assert!(output.status.success(), "{}", text(&output));
    check(&plain, &text(&output));
    // A folder without certificates is refused by name.
    let output = arena([os("report"), os(&plain), os("--certificates"), os(&plans)]);
    assert!(!output.status.success());
    assert!(text(&output).contains("no task certificate"), "{}", text(&output));
}
