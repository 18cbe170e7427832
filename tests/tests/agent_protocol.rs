//! The step protocol end to end: `arena run --agent exec` and `--agent http`
//! over the six stub tasks with a Python oracle agent (one action space per
//! task, through the `python/` package's runner), every message both ways
//! checked against `schemas/agent-protocol/`, and agents that print garbage,
//! hang or exit mid-run, each ending its task as a recorded agent error while
//! the other tasks finish.
//!
//! Where `ARENA_WAA_ROOT` names a WindowsAgentArena checkout (with its Python
//! requirements installed), upstream's own Navi runs through the runner against a
//! mock model, and its first request must equal the built-in Navi's with
//! `--waa-root`; without a checkout that test prints `SKIPPED: ...`.
//!
//! Needs `python3`: without it each test prints `SKIPPED: <test>: python3 not
//! found` and returns, unless `ARENA_REQUIRE_PYTHON` is set.

#![cfg(unix)]

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use arena_results::summary::{Summary, TaskRow};
use arena_test_support::workspace_binary;
use serde_json::Value;

#[path = "agent_protocol/mock_model.rs"]
pub mod mock_model;

const VICTIM: &str = "stub-notepad-append";

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn here() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/agent_protocol")
}

/// PYTHONPATH with the package and the test's agents.
fn pythonpath() -> String {
    arena_test_support::agent_pythonpath(&["tests/tests/agent_protocol"])
}

/// `arena run` over the stub tasks on two stub guests with `agent_args`; answers its stderr.
fn arena_run(out: &Path, agent_args: &[&str]) -> String {
    let exe = workspace_binary("arena-host", "arena").expect("the arena binary");
    let mut child = Command::new(exe)
        .args(["run", "--stub-guests", "2", "--pauses", "fast"])
        .args(arena_test_support::exec_sandbox_args())
        .arg("--tasks")
        .arg(repo().join("tasks/stub"))
        .arg("--out")
        .arg(out)
        .args(agent_args)
        .env("PYTHONPATH", pythonpath())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("arena run starts");
    let mut err = String::new();
    if let Some(mut pipe) = child.stderr.take() {
        let _ = std::io::Read::read_to_string(&mut pipe, &mut err);
    }
    let _ = child.wait();
    err
}

fn rows(out: &Path) -> BTreeMap<String, TaskRow> {
    let summary = Summary::from_dir(out).expect("the run's summary");
    summary.tasks.into_iter().map(|t| (t.name.clone(), t)).collect()
}

fn trajectory(out: &Path, row: &TaskRow) -> Vec<Value> {
    let text = std::fs::read_to_string(out.join(&row.path).join("traj.jsonl")).expect("traj.jsonl");
    text.lines().map(|l| serde_json::from_str(l).expect("a JSON line")).collect()
}

/// The oracle's scores: every task solved.
fn assert_oracle_scores(out: &Path, stderr: &str) {
    let rows = rows(out);
    assert_eq!(rows.len(), 6, "six stub tasks\n{stderr}");
    for (name, row) in &rows {
        assert_eq!(row.status, "completed", "{name}: {row:?}\n{stderr}");
        assert_eq!(row.score, Some(1.0), "{name} solved: {row:?}\n{stderr}");
    }
    // The free-form fields of each answer are in the trajectory.
    let count = &rows["stub-notepad-count"];
    let traj = trajectory(out, count);
    let first = traj.iter().find(|l| l.get("step_num") == Some(&Value::from(1))).expect("step 1");
    assert_eq!(first["oracle_step"], Value::from(1), "{first}");
    assert_eq!(first["action_space"], Value::from("typed"), "{first}");
}

fn schema(name: &str) -> jsonschema::Validator {
    let path = repo().join("schemas/agent-protocol").join(name);
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let value: Value = serde_json::from_str(&text).expect("a schema is JSON");
    jsonschema::validator_for(&value).unwrap_or_else(|e| panic!("{name} is a valid schema: {e}"))
}

/// Checks every logged message against its schema; answers how many were checked per direction.
fn validate_logs(dir: &Path) -> (usize, usize, usize) {
    let to_agent: BTreeMap<&str, jsonschema::Validator> =
        [("hello", schema("hello.json")), ("reset", schema("reset.json")), ("observe", schema("observe.json"))].into();
    let to_harness: BTreeMap<&str, jsonschema::Validator> = [
        ("hello", schema("agent-hello.json")),
        ("ready", schema("ready.json")),
        ("act", schema("act.json")),
        ("error", schema("error.json")),
    ]
    .into();
    let (mut sent, mut answered, mut files) = (0, 0, 0);
    for entry in std::fs::read_dir(dir).expect("the log folder") {
        files += 1;
        let text = std::fs::read_to_string(entry.expect("entry").path()).expect("a log");
        for line in text.lines() {
            let logged: Value = serde_json::from_str(line).expect("a log line");
            let message: Value = serde_json::from_str(logged["line"].as_str().expect("line")).expect("JSON message");
            let kind = message["type"].as_str().expect("a type");
            let (table, counter) =
                if logged["dir"] == "to_agent" { (&to_agent, &mut sent) } else { (&to_harness, &mut answered) };
            let validator = table.get(kind).unwrap_or_else(|| panic!("no schema for {kind} {}", logged["dir"]));
            let errors: Vec<String> = validator.iter_errors(&message).map(|e| e.to_string()).collect();
            assert!(errors.is_empty(), "{kind} {} does not match its schema: {errors:?}\n{message}", logged["dir"]);
            *counter += 1;
        }
    }
    (sent, answered, files)
}

#[test]
fn the_stub_tasks_through_an_exec_agent_in_four_action_spaces() {
    if !arena_test_support::python3_or_skip("the_stub_tasks_through_an_exec_agent_in_four_action_spaces") {
        return;
    }
    let tmp = tempfile::tempdir().expect("tmp");
    let (out, logs) = (tmp.path().join("out"), tmp.path().join("logs"));
    std::fs::create_dir_all(&logs).expect("logs");
    let cmd = format!(
        "python3 {} {} python3 -m arena_agent oracle_agent:Oracle",
        here().join("tee.py").display(),
        logs.display()
    );
    // In the default sandbox, with its log folder writable.
    let logs_arg = logs.display().to_string();
    let args = ["--agent", "exec", "--agent-cmd", &cmd, "--agent-timeout", "60", "--agent-writable", &logs_arg];
    let stderr = arena_run(&out, &args);
    assert_oracle_scores(&out, &stderr);
    assert!(stderr.contains("oracle: stub-notepad-count step 1"), "the agent's stderr is in the log:\n{stderr}");
    let (sent, answered, processes) = validate_logs(&logs);
    assert!(sent >= 6 * 2 + 2 && sent == answered, "{sent} messages sent, {answered} answered");
    // One process per guest worker, kept across episodes (a computer_13 refusal
    // is the agent's answer, not a broken protocol, so nothing is restarted).
    assert!(processes <= 2, "{processes} agent processes for two guests");
}

/// `python -m arena_agent --http 127.0.0.1:0 ...`, and the URL it listens on.
fn http_agent(class: &str) -> (Child, String) {
    let mut child = Command::new("python3")
        .args(["-m", "arena_agent", "--http", "127.0.0.1:0", class])
        .env("PYTHONPATH", pythonpath())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the HTTP agent starts");
    let mut lines = BufReader::new(child.stderr.take().expect("stderr")).lines();
    let deadline = Instant::now() + Duration::from_secs(30);
    let url = loop {
        assert!(Instant::now() < deadline, "the HTTP agent did not say where it listens");
        let line = lines.next().expect("a line").expect("text");
        if let Some(url) = line.strip_prefix("arena_agent: listening on ") {
            break url.trim().to_owned();
        }
    };
    // Keep draining its log so it never blocks on a full pipe.
    std::thread::spawn(move || lines.for_each(drop));
    (child, url)
}

#[test]
fn the_stub_tasks_through_an_http_agent() {
    if !arena_test_support::python3_or_skip("the_stub_tasks_through_an_http_agent") {
        return;
    }
    let tmp = tempfile::tempdir().expect("tmp");
    let out = tmp.path().join("out");
    let (mut agent, url) = http_agent("oracle_agent:Oracle");
    let stderr = arena_run(&out, &["--agent", "http", "--agent-url", &url, "--agent-timeout", "60"]);
    let _ = agent.kill();
    let _ = agent.wait();
    assert_oracle_scores(&out, &stderr);
}

/// A run with an agent that breaks on [`VICTIM`]: that task is a recorded agent
/// error naming `cause`; the others finish as the oracle's do.
fn misbehaving(class: &str, cause: &str) {
    let tmp = tempfile::tempdir().expect("tmp");
    let out = tmp.path().join("out");
    let cmd = format!("python3 -m arena_agent oracle_agent:{class}");
    let stderr = arena_run(&out, &["--agent", "exec", "--agent-cmd", &cmd, "--agent-timeout", "3"]);
    let rows = rows(&out);
    assert_eq!(rows.len(), 6, "every task has a result\n{stderr}");
    let victim = &rows[VICTIM];
    assert_eq!(victim.status, "agent_error", "{victim:?}\n{stderr}");
    let error = victim.error.clone().unwrap_or_default();
    assert!(error.contains(cause), "the error says {cause:?}: {error}");
    let traj = trajectory(&out, victim);
    assert!(
        traj.iter().any(|l| l["error"].as_str().is_some_and(|e| e.contains(cause))),
        "the step with the error is in the trajectory: {traj:?}"
    );
    for (name, row) in &rows {
        if name == VICTIM {
            continue;
        }
        assert_eq!((row.status.as_str(), row.score), ("completed", Some(1.0)), "{name}: {row:?}\n{stderr}");
    }
}

#[test]
fn an_agent_that_prints_garbage_is_an_agent_error_and_the_run_goes_on() {
    if arena_test_support::python3_or_skip("an_agent_that_prints_garbage_is_an_agent_error_and_the_run_goes_on") {
        misbehaving("Garbage", "not JSON");
    }
}

#[test]
fn an_agent_that_hangs_is_an_agent_error_and_the_run_goes_on() {
    if arena_test_support::python3_or_skip("an_agent_that_hangs_is_an_agent_error_and_the_run_goes_on") {
        misbehaving("Hang", "no answer to observe within 3 s");
    }
}

#[test]
fn an_agent_that_exits_is_an_agent_error_and_the_run_goes_on() {
    if arena_test_support::python3_or_skip("an_agent_that_exits_is_an_agent_error_and_the_run_goes_on") {
        misbehaving("Exit", "the agent process exited");
    }
}

#[test]
fn the_step_protocol_example_agent_runs() {
    if !arena_test_support::python3_or_skip("the_step_protocol_example_agent_runs") {
        return;
    }
    let tmp = tempfile::tempdir().expect("tmp");
    let tasks = tmp.path().join("tasks/mixed");
    for (domain, name) in [("notepad", "stub-notepad-draft"), ("settings", "stub-settings-infeasible")] {
        arena_test_support::copy_stub_task(domain, name, &tasks);
    }
    let out = tmp.path().join("out");
    let exe = workspace_binary("arena-host", "arena").expect("the arena binary");
    let cmd = format!("python3 {}", repo().join("examples/step_agent.py").display());
    let status = Command::new(exe)
        .args(["run", "--stub-guests", "1", "--pauses", "fast", "--agent", "exec", "--agent-cmd", &cmd])
        .args(arena_test_support::exec_sandbox_args())
        .arg("--tasks")
        .arg(tmp.path().join("tasks"))
        .arg("--out")
        .arg(&out)
        .env("PYTHONPATH", repo().join("python"))
        .stdout(Stdio::null())
        .status()
        .expect("arena run");
    assert!(status.success(), "{status:?}");
    let rows = rows(&out);
    assert_eq!(rows.len(), 2);
    assert!(rows.values().all(|r| r.score == Some(1.0)), "{rows:?}");
}

/// The built-in Navi counts what its model reports in `usage` (the chat-completions
/// `prompt_tokens` and `completion_tokens`; the mock reports 1 and 1): in the
/// step's `traj.jsonl` line, the task's `episode.json` and the run's summary.
#[test]
fn the_built_in_navi_records_its_models_usage_per_step_task_and_run() {
    let tmp = tempfile::tempdir().expect("tmp");
    let args = ["--agent", "navi", "--model", "gpt-4o", "--navi-style", "arena", "--som-origin", "a11y"];
    first_request(tmp.path(), "navi", &args, &[]);
    let out = tmp.path().join("navi/out");
    let summary: Value = serde_json::from_slice(&std::fs::read(out.join("summary.json")).expect("summary")).unwrap();
    assert_eq!(summary["overall"]["tokens"]["input"], 1, "{summary}");
    assert_eq!(summary["overall"]["tokens"]["output"], 1, "{summary}");
    let task = out.join("pyautogui/a11y_tree/gpt-4o/0/notepad/stub-notepad-draft");
    let episode: Value = serde_json::from_slice(&std::fs::read(task.join("episode.json")).expect("episode")).unwrap();
    assert_eq!((episode["tokens"]["input"].as_u64(), episode["tokens"]["output"].as_u64()), (Some(1), Some(1)));
    let traj = std::fs::read_to_string(task.join("traj.jsonl")).expect("traj");
    // The first line is the reset's; the step follows.
    let step: Value = serde_json::from_str(traj.lines().nth(1).expect("a step")).unwrap();
    assert_eq!((step["usage"]["input"].as_u64(), step["usage"]["output"].as_u64()), (Some(1), Some(1)), "{traj}");
}

/// The first request a mock model was sent for `arena run ARGS` on the draft task, one step.
fn first_request(tmp: &Path, label: &str, args: &[&str], env: &[(&str, String)]) -> Value {
    let model = mock_model::start("Saving.\n```decision\nDONE\n```").expect("a mock model");
    arena_test_support::copy_stub_task("notepad", "stub-notepad-draft", &tmp.join(label).join("tasks/notepad"));
    let exe = workspace_binary("arena-host", "arena").expect("the arena binary");
    let mut cmd = Command::new(exe);
    cmd.args(["run", "--stub-guests", "1", "--pauses", "fast", "--max-steps", "1", "--tasks"])
        .arg(tmp.join(label).join("tasks"))
        .arg("--out")
        .arg(tmp.join(label).join("out"))
        .args(args)
        .env("PYTHONPATH", pythonpath())
        .env("OPENAI_BASE_URL", &model.url)
        .env("OPENAI_API_KEY", "sk-mock")
        .env("ARENA_LLM_KEY", "sk-mock")
        .args(["--llm-url", &model.url])
        .stdout(Stdio::null());
    for (k, v) in env {
        cmd.env(k, v);
    }
    let status = cmd.status().expect("arena run");
    assert!(status.success(), "{label}: {status:?}");
    let requests = model.requests.lock().expect("requests");
    requests.first().cloned().unwrap_or_else(|| panic!("{label}: the model was never asked"))
}

#[test]
fn upstream_navi_through_the_runner_asks_what_the_built_in_navi_asks() {
    let test = "upstream_navi_through_the_runner_asks_what_the_built_in_navi_asks";
    let Some(root) = std::env::var_os("ARENA_WAA_ROOT").map(PathBuf::from) else {
        arena_test_support::skip(test, arena_test_support::UPSTREAM_CHECKOUT_SKIP, "ARENA_REQUIRE_WAA_ROOT");
        return;
    };
    if !arena_test_support::python3_or_skip(test) {
        return;
    }
    let tmp = tempfile::tempdir().expect("tmp");
    let client = root.join("src/win-arena-container/client");
    let root_text = root.display().to_string();
    let built_in = first_request(
        tmp.path(),
        "built-in",
        &["--agent", "navi", "--model", "gpt-4o", "--som-origin", "a11y", "--waa-root", &root_text],
        &[],
    );
    let kwargs = r#"{"server": "oai", "model": "gpt-4o", "som_origin": "a11y", "temperature": 1.0}"#;
    let cmd = format!(
        "python3 -m arena_agent --adapter waa --path {} --kwargs '{kwargs}' mm_agents.navi.agent:NaviAgent",
        client.display()
    );
    let upstream = first_request(tmp.path(), "upstream", &["--agent", "exec", "--agent-cmd", &cmd], &[]);
    if let Some(dir) = std::env::var_os("ARENA_TEST_DUMP") {
        let dir = PathBuf::from(dir);
        std::fs::write(dir.join("upstream.json"), upstream.to_string()).expect("dump");
        std::fs::write(dir.join("built-in.json"), built_in.to_string()).expect("dump");
    }
    assert_eq!(upstream["model"], built_in["model"]);
    assert_eq!(upstream["temperature"], built_in["temperature"]);
    assert_eq!(upstream["max_tokens"], built_in["max_tokens"]);
    same_messages(&upstream["messages"], &built_in["messages"]);
}

/// The same messages: every text part byte for byte; every image of the same
/// size and, decoded, within 1 level on average (upstream encodes its JPEGs
/// with Pillow's libjpeg, the harness with its own encoder, and the
/// Set-of-Marks labels are drawn with different fonts).
fn same_messages(upstream: &Value, built_in: &Value) {
    let (a, b) = (upstream.as_array().expect("messages"), built_in.as_array().expect("messages"));
    assert_eq!(a.len(), b.len(), "as many messages");
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        assert_eq!(x["role"], y["role"], "message {i}");
        let parts = |m: &Value| match &m["content"] {
            Value::Array(parts) => parts.clone(),
            text => vec![serde_json::json!({"type": "text", "text": text})],
        };
        let (px, py) = (parts(x), parts(y));
        assert_eq!(px.len(), py.len(), "message {i}: as many parts");
        for (j, (p, q)) in px.iter().zip(&py).enumerate() {
            if p["type"] != "image_url" {
                assert_eq!(p, q, "message {i} part {j}");
                continue;
            }
            let decode = |v: &Value| {
                let url = v["image_url"]["url"].as_str().expect("a data URL");
                let b64 = url.split_once(',').expect("data URL").1;
                let bytes = base64::Engine::decode(&base64::engine::general_purpose::STANDARD, b64).expect("base64");
                image::load_from_memory(&bytes).expect("an image").to_rgb8()
            };
            let (ip, iq) = (decode(p), decode(q));
            assert_eq!(ip.dimensions(), iq.dimensions(), "message {i} part {j}: image size");
            let total: u64 = ip.as_raw().iter().zip(iq.as_raw()).map(|(a, b)| u64::from(a.abs_diff(*b))).sum();
            let mean = total as f64 / ip.as_raw().len().max(1) as f64;
            assert!(mean <= 1.0, "message {i} part {j}: images differ by {mean:.3} levels on average");
            assert_eq!(p["image_url"]["detail"], q["image_url"]["detail"], "message {i} part {j}: detail");
        }
    }
}
