//! The checks before a run's first task (issue 30, item 5): a mistyped
//! `--agent-cmd`, an `--agent-url` nobody listens on and a model endpoint that
//! answers 401 each end `arena run` before the first task, saying why, with no
//! `result.txt` written; the model endpoint is asked once, never retried. A model
//! endpoint where nothing listens ends the run there too (issue 43, item 6), and
//! one that dies once the run is under way stops new tasks within a few calls.

#![cfg(unix)]

use std::io::{BufRead, BufReader, Read, Write};
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;

use arena_results::RESULT_FILE;
use arena_test_support::workspace_binary;

fn stub_tasks() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tasks/stub")
}

/// `arena run` on one embedded stub guest with `agent_args`: its exit code, and its
/// stderr followed by its stdout (where the closing list of unfinished tasks goes).
fn arena_run(out: &Path, agent_args: &[&str]) -> (Option<i32>, String) {
    let exe = workspace_binary("arena-host", "arena").expect("the arena binary");
    let output = Command::new(exe)
        .args(["run", "--stub-guests", "1"])
        .args(arena_test_support::exec_sandbox_args())
        .arg("--tasks")
        .arg(stub_tasks())
        .arg("--out")
        .arg(out)
        .args(agent_args)
        .env_remove("ARENA_LLM_URL")
        .env_remove("ARENA_LLM_MODEL")
        .env_remove("ARENA_AGENT_URL")
        .env("ARENA_LLM_KEY", "wrong-key")
        .stdin(Stdio::null())
        .output()
        .expect("arena run runs");
    let text = format!("{}{}", String::from_utf8_lossy(&output.stderr), String::from_utf8_lossy(&output.stdout));
    (output.status.code(), text)
}

/// Whether any `result.txt` exists below `dir`.
fn any_result(dir: &Path) -> bool {
    let Ok(entries) = std::fs::read_dir(dir) else { return false };
    entries.flatten().any(|e| {
        let path = e.path();
        if path.is_dir() {
            any_result(&path)
        } else {
            path.file_name().is_some_and(|n| n == RESULT_FILE)
        }
    })
}

fn assert_ended_before_the_first_task(out: &Path, code: Option<i32>, stderr: &str, why: &str) {
    assert_ne!(code, Some(0), "{stderr}");
    assert!(stderr.contains("preflight:") && stderr.contains(why), "{why}\n{stderr}");
    assert!(stderr.contains("no task was run"), "{stderr}");
    assert!(!any_result(out), "no result.txt written");
    assert!(!out.join("summary.json").exists(), "no summary written");
}

#[test]
fn a_broken_agent_cmd_ends_the_run_before_the_first_task() {
    let tmp = tempfile::tempdir().expect("tmp");
    let out = tmp.path().join("out");
    let (code, stderr) = arena_run(&out, &["--agent", "exec", "--agent-cmd", "arena-no-such-agent-program --flag"]);
    assert_ended_before_the_first_task(&out, code, &stderr, "did not answer its hello");
}

#[test]
fn a_closed_agent_url_ends_the_run_before_the_first_task() {
    let tmp = tempfile::tempdir().expect("tmp");
    let out = tmp.path().join("out");
    // A port that was free a moment ago: nobody listens on it.
    let port = std::net::TcpListener::bind("127.0.0.1:0").expect("bind").local_addr().expect("addr").port();
    let url = format!("http://127.0.0.1:{port}/agent");
    let (code, stderr) = arena_run(&out, &["--agent", "http", "--agent-url", &url, "--agent-timeout", "10"]);
    assert_ended_before_the_first_task(&out, code, &stderr, "did not answer its hello");
}

/// A model endpoint answering 401 to everything; counts the requests.
fn unauthorized_endpoint() -> (String, Arc<AtomicUsize>) {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
    let url = format!("http://{}/v1", listener.local_addr().expect("addr"));
    let count = Arc::new(AtomicUsize::new(0));
    let seen = Arc::clone(&count);
    std::thread::spawn(move || {
        for stream in listener.incoming().flatten() {
            let mut reader = BufReader::new(stream);
            let (mut length, mut line) = (0usize, String::new());
            loop {
                line.clear();
                if reader.read_line(&mut line).unwrap_or(0) == 0 {
                    break;
                }
                if let Some(v) = line.to_ascii_lowercase().strip_prefix("content-length:") {
                    length = v.trim().parse().unwrap_or(0);
                }
                if line == "\r\n" {
                    break;
                }
            }
            let mut body = vec![0; length];
            let _ = reader.read_exact(&mut body);
            seen.fetch_add(1, Ordering::SeqCst);
            let reply = r#"{"error": {"message": "Incorrect API key provided", "type": "invalid_request_error", "code": "invalid_api_key"}}"#;
            let response = format!(
                "HTTP/1.1 401 Unauthorized\r\nContent-Type: application/json\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{reply}",
                reply.len()
            );
            let _ = reader.get_mut().write_all(response.as_bytes());
        }
    });
    (url, count)
}

#[test]
fn a_model_endpoint_answering_401_ends_the_run_before_the_first_task() {
    let tmp = tempfile::tempdir().expect("tmp");
    let out = tmp.path().join("out");
    let (url, requests) = unauthorized_endpoint();
    let (code, stderr) = arena_run(&out, &["--agent", "navi", "--llm-url", &url, "--model", "gpt-4o"]);
    assert_ended_before_the_first_task(&out, code, &stderr, "401");
    assert_eq!(requests.load(Ordering::SeqCst), 1, "one request, not retried\n{stderr}");
}

/// A URL on a loopback port where nothing listens (bound a moment ago, then let go).
fn dead_model_url() -> String {
    let port = std::net::TcpListener::bind("127.0.0.1:0").expect("bind").local_addr().expect("addr").port();
    format!("http://127.0.0.1:{port}/v1")
}

#[test]
fn a_model_endpoint_where_nothing_listens_ends_the_run_before_the_first_task() {
    let tmp = tempfile::tempdir().expect("tmp");
    let out = tmp.path().join("out");
    let url = dead_model_url();
    let (code, stderr) = arena_run(&out, &["--agent", "navi", "--llm-url", &url, "--model", "gpt-4o"]);
    assert_ended_before_the_first_task(&out, code, &stderr, "nothing answers at the model endpoint");
    assert!(stderr.contains(&url), "the URL named: {stderr}");
}

#[test]
fn a_model_endpoint_dead_during_the_run_stops_new_tasks_after_three_calls() {
    let tmp = tempfile::tempdir().expect("tmp");
    let out = tmp.path().join("out");
    let url = dead_model_url();
    // No preflight: the endpoint "dies" before the first call. A short retry window
    // stands for the real one; the calls after the first give up at once.
    let args = ["--agent", "navi", "--llm-url", &url, "--model", "gpt-4o", "--no-preflight", "--llm-retry", "0.5"];
    let (code, stderr) = arena_run(&out, &args);
    assert_eq!(code, Some(2), "unfinished tasks: {stderr}");
    assert!(
        stderr.contains("not started: the model endpoint") && stderr.contains("did not answer in 3 calls in a row"),
        "{stderr}"
    );
    assert!(!any_result(&out), "no task is scored: {stderr}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).expect("summary.json")).expect("JSON");
    let tasks = stub_tasks_count();
    let not_started = stderr.lines().filter(|l| l.contains("not started: the model endpoint")).count();
    assert!(not_started >= 1 && not_started < tasks, "some tasks never started ({not_started} of {tasks}): {stderr}");
    assert_eq!(summary["overall"]["successes"], 0, "{summary}");
}

/// How many tasks `tasks/stub` holds.
fn stub_tasks_count() -> usize {
    arena_host::run::load_tasks(&stub_tasks(), arena_task::Difficulty::Normal).expect("the stub tasks").len()
}
