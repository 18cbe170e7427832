//! Outside agents that attack the harness, run through the real `arena` binary
//! on two stub tasks (one guest): on the victim task each misbehaves, and the
//! test checks that the harness names it an agent error, keeps the other task's
//! result, and stays bounded. An HTTP agent answering 1 GiB (announced, chunked,
//! or until the connection closes) costs the run no more than a few hundred MiB
//! (the `arena` process's peak resident size, sampled from `/proc`).
//!
//! An act of a million actions is refused at once; SIGTERM during a long act
//! ends the run with the finished task kept, the victim interrupted and
//! `summary.json` written; a stderr flood (lines, or no newline at all) leaves
//! a run log under its cap, and the stream itself in the task's
//! `agent-stderr.log` under that file's cap; an agent's children (plain, and in
//! a new session) are gone when the run ends.
//!
//! The exec agents are `hostile_agent/hostile.py` (needs `python3`: without it
//! those tests print `SKIPPED: <test>: python3 not found`, unless
//! `ARENA_REQUIRE_PYTHON` is set).

#![cfg(target_os = "linux")]

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use arena_agents::external::stderr;
use arena_results::summary::{Summary, TaskRow};
use arena_test_support::workspace_binary;
use serde_json::{json, Value};

const VICTIM: &str = "stub-notepad-append";
/// Runs first (`--order sorted`: its domain sorts before the victim's).
const OTHER: &str = "stub-explorer-open-folder";

/// A task folder with the victim and one other stub task.
fn tasks(tmp: &Path) -> PathBuf {
    for (domain, name) in [("notepad", VICTIM), ("file_explorer", OTHER)] {
        arena_test_support::copy_stub_task(domain, name, &tmp.join("tasks").join(domain));
    }
    tmp.join("tasks")
}

/// `arena run` of the two tasks on one stub guest with `agent_args`.
fn start(tmp: &Path, agent_args: &[&str]) -> Child {
    let exe = workspace_binary("arena-host", "arena").expect("the arena binary");
    // The suite's default sandbox, unless the test chose one.
    let sandbox: &[&str] =
        if agent_args.contains(&"--agent-sandbox") { &[] } else { &arena_test_support::exec_sandbox_args() };
    Command::new(exe)
        .args(["run", "--stub-guests", "1", "--pauses", "fast", "--order", "sorted", "--tasks"])
        .arg(tasks(tmp))
        .arg("--out")
        .arg(tmp.join("out"))
        .args(agent_args)
        .args(sandbox)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("arena run starts")
}

/// The largest `VmHWM` (peak resident set) seen in `/proc/PID/status`, in bytes.
fn peak_rss(pid: u32) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// Waits for `child` (a safety net of `within`, never reached when it works),
/// sampling its peak resident size; answers its status, stderr and that peak.
fn finish(mut child: Child, within: Duration) -> (ExitStatus, String, u64) {
    let pid = child.id();
    let mut pipe = child.stderr.take().expect("stderr");
    let reader = std::thread::spawn(move || {
        let mut err = String::new();
        let _ = pipe.read_to_string(&mut err);
        err
    });
    let deadline = Instant::now() + within;
    let mut peak = 0;
    let status = loop {
        if let Some(status) = child.try_wait().expect("wait") {
            break status;
        }
        peak = peak.max(peak_rss(pid).unwrap_or(0));
        if Instant::now() > deadline {
            let _ = child.kill();
            panic!("arena run did not exit within {within:?}");
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    (status, reader.join().expect("stderr"), peak)
}

fn rows(out: &Path) -> BTreeMap<String, TaskRow> {
    let summary = Summary::from_dir(out).expect("the run's summary");
    summary.tasks.into_iter().map(|t| (t.name.clone(), t)).collect()
}

/// The victim is an agent error whose message contains `cause`; the other task ran to its end.
fn assert_victim_only(out: &Path, cause: &str, stderr: &str) {
    let rows = rows(out);
    assert_eq!(rows.len(), 2, "both tasks have a result\n{stderr}");
    let victim = &rows[VICTIM];
    assert_eq!(victim.status, "agent_error", "{victim:?}\n{stderr}");
    let error = victim.error.clone().unwrap_or_default();
    assert!(error.contains(cause), "the error says {cause:?}: {error}");
    assert_eq!(rows[OTHER].status, "completed", "{:?}\n{stderr}", rows[OTHER]);
}

/// How the test server sends its huge answer.
#[derive(Clone, Copy, Debug)]
enum Huge {
    /// With `Content-Length`.
    Announced,
    /// `Transfer-Encoding: chunked`.
    Chunked,
    /// Neither: the body ends when the connection closes.
    UntilClose,
}

const GIB: u64 = 1 << 30;

/// One HTTP/1.1 request: its JSON body, or `None` when the connection closed.
fn read_request(reader: &mut BufReader<TcpStream>) -> Option<Value> {
    let mut length = 0;
    loop {
        let mut line = String::new();
        if reader.read_line(&mut line).ok()? == 0 {
            return None;
        }
        let line = line.trim_end();
        if line.is_empty() {
            break;
        }
        if let Some((name, value)) = line.split_once(':') {
            if name.eq_ignore_ascii_case("content-length") {
                length = value.trim().parse().ok()?;
            }
        }
    }
    let mut body = vec![0; length];
    reader.read_exact(&mut body).ok()?;
    serde_json::from_slice(&body).ok()
}

/// Writes 1 GiB of an unfinished JSON string, generated as it goes; stops when the reader hangs up.
fn send_huge(stream: &mut TcpStream, how: Huge) -> std::io::Result<()> {
    let head = match how {
        Huge::Announced => {
            format!("HTTP/1.1 200 OK\r\nContent-Type: application/json\r\nContent-Length: {GIB}\r\n\r\n")
        }
        Huge::Chunked => {
            "HTTP/1.1 200 OK\r\nContent-Type: application/json\r\nTransfer-Encoding: chunked\r\n\r\n".into()
        }
        Huge::UntilClose => "HTTP/1.1 200 OK\r\nContent-Type: application/json\r\nConnection: close\r\n\r\n".into(),
    };
    stream.write_all(head.as_bytes())?;
    let chunk = vec![b'a'; 1 << 20];
    let mut first = br#"{"type": "act", "response": ""#.to_vec();
    first.resize(1 << 20, b'a');
    for i in 0..(GIB >> 20) {
        let data = if i == 0 { &first } else { &chunk };
        if let Huge::Chunked = how {
            stream.write_all(format!("{:x}\r\n", data.len()).as_bytes())?;
            stream.write_all(data)?;
            stream.write_all(b"\r\n")?;
        } else {
            stream.write_all(data)?;
        }
    }
    if let Huge::Chunked = how {
        stream.write_all(b"0\r\n\r\n")?;
    }
    Ok(())
}

fn send_json(stream: &mut TcpStream, value: &Value) -> std::io::Result<()> {
    let body = value.to_string();
    let head = format!("HTTP/1.1 200 OK\r\nContent-Type: application/json\r\nContent-Length: {}\r\n\r\n", body.len());
    stream.write_all(head.as_bytes())?;
    stream.write_all(body.as_bytes())
}

/// An HTTP agent on a loopback port that behaves, except that it answers the
/// victim's first `observe` with 1 GiB sent as `how`; answers its URL.
fn huge_http_agent(how: Huge) -> String {
    let listener = TcpListener::bind("127.0.0.1:0").expect("bind");
    let url = format!("http://{}/", listener.local_addr().expect("address"));
    let tasks: Arc<Mutex<BTreeMap<String, String>>> = Arc::default();
    std::thread::spawn(move || {
        for stream in listener.incoming().flatten() {
            let tasks = tasks.clone();
            std::thread::spawn(move || {
                let mut writer = stream.try_clone().expect("clone");
                let mut reader = BufReader::new(stream);
                while let Some(message) = read_request(&mut reader) {
                    let session = message["session"].as_str().unwrap_or_default().to_owned();
                    let answer = match message["type"].as_str() {
                        Some("hello") => json!({"type": "hello", "protocol": 1, "action_space": "typed"}),
                        Some("reset") => {
                            let task = message["task_name"].as_str().unwrap_or_default().to_owned();
                            tasks.lock().expect("tasks").insert(session, task);
                            json!({"type": "ready"})
                        }
                        _ => {
                            let task = tasks.lock().expect("tasks").get(&session).cloned().unwrap_or_default();
                            if task == VICTIM {
                                let _ = send_huge(&mut writer, how);
                                return;
                            }
                            json!({"type": "act", "decision": "DONE"})
                        }
                    };
                    if send_json(&mut writer, &answer).is_err() {
                        return;
                    }
                }
            });
        }
    });
    url
}

fn huge_http_answer(how: Huge) {
    let tmp = tempfile::tempdir().expect("tmp");
    let url = huge_http_agent(how);
    let child = start(tmp.path(), &["--agent", "http", "--agent-url", &url, "--agent-timeout", "60"]);
    let (status, stderr, peak) = finish(child, Duration::from_secs(300));
    println!("{how:?}: the run's peak resident size {} MiB", peak >> 20);
    assert!(status.code().is_some(), "arena run ended by a signal: {status:?}\n{stderr}");
    assert_victim_only(&tmp.path().join("out"), "longer than 64 MiB", &stderr);
    assert!(peak < 400 << 20, "{how:?}: the run peaked at {} MiB\n{stderr}", peak >> 20);
}

#[test]
fn an_http_agent_announcing_a_1_gib_answer_is_an_agent_error_and_the_run_stays_small() {
    huge_http_answer(Huge::Announced);
}

#[test]
fn an_http_agent_sending_a_1_gib_chunked_answer_is_an_agent_error_and_the_run_stays_small() {
    huge_http_answer(Huge::Chunked);
}

#[test]
fn an_http_agent_sending_1_gib_until_it_closes_is_an_agent_error_and_the_run_stays_small() {
    huge_http_answer(Huge::UntilClose);
}

/// The `--agent exec` arguments of `hostile.py MODE ARG MARKER`.
fn hostile(mode: &str, arg: &str, marker: &Path) -> Vec<String> {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/hostile_agent/hostile.py");
    let cmd = format!("python3 {} {mode} {arg} {}", script.display(), marker.display());
    vec!["--agent".into(), "exec".into(), "--agent-cmd".into(), cmd, "--agent-timeout".into(), "60".into()]
}

fn run_hostile(tmp: &Path, mode: &str, arg: &str, extra: &[&str]) -> (ExitStatus, String, u64) {
    let mut args = hostile(mode, arg, &tmp.join("marker"));
    args.extend(extra.iter().map(|s| (*s).to_owned()));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    finish(start(tmp, &args), Duration::from_secs(300))
}

#[test]
fn an_act_of_a_million_actions_is_refused_at_once_and_the_run_goes_on() {
    let test = "an_act_of_a_million_actions_is_refused_at_once_and_the_run_goes_on";
    if !arena_test_support::python3_or_skip(test) {
        return;
    }
    let tmp = tempfile::tempdir().expect("tmp");
    // A second per action were each run: refused at once, the run is short.
    let (status, stderr, peak) = run_hostile(tmp.path(), "actions", "1000000", &["--sleep-after", "1"]);
    println!("a million actions: the run's peak resident size {} MiB", peak >> 20);
    assert_eq!(status.code(), Some(0), "{stderr}");
    assert_victim_only(&tmp.path().join("out"), "1000000 actions in one act; at most 256", &stderr);
    // Counted in the answer's text, never made a JSON tree (which took 868 MiB).
    assert!(peak < 300 << 20, "the run peaked at {} MiB\n{stderr}", peak >> 20);
}

#[test]
fn sigterm_during_a_long_act_ends_the_run_with_its_summary() {
    let test = "sigterm_during_a_long_act_ends_the_run_with_its_summary";
    if !arena_test_support::python3_or_skip(test) {
        return;
    }
    let tmp = tempfile::tempdir().expect("tmp");
    let marker = tmp.path().join("marker");
    // 250 actions, each followed by a 5 s pause: the act alone would last 20 minutes.
    let mut args = hostile("long", "250", &marker);
    // Outside the sandbox, so the agent can leave its marker in the test's folder.
    args.extend(["--sleep-after".into(), "5".into(), "--agent-sandbox".into(), "none".into()]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let child = start(tmp.path(), &args);
    let deadline = Instant::now() + Duration::from_secs(120);
    while !marker.exists() {
        assert!(Instant::now() < deadline, "the agent's act never started");
        std::thread::sleep(Duration::from_millis(20));
    }
    let sent = Command::new("kill").args(["-TERM", &child.id().to_string()]).status().expect("kill");
    assert!(sent.success(), "SIGTERM sent");
    let (status, stderr, _) = finish(child, Duration::from_secs(120));
    assert_eq!(status.code(), Some(130), "a stopped run exits 130\n{stderr}");
    let out = tmp.path().join("out");
    assert!(out.join("summary.json").exists(), "summary.json is written\n{stderr}");
    let rows = rows(&out);
    assert_eq!(rows[VICTIM].status, "interrupted", "{:?}\n{stderr}", rows[VICTIM]);
    assert_eq!(rows[OTHER].status, "completed", "the finished task is kept: {:?}\n{stderr}", rows[OTHER]);
}

fn stderr_flood(mode: &str) {
    let tmp = tempfile::tempdir().expect("tmp");
    let (status, stderr, _) = run_hostile(tmp.path(), mode, "64", &[]);
    println!("{mode}: 64 MiB of agent stderr made a run log of {} KiB", stderr.len() >> 10);
    assert_eq!(status.code(), Some(0), "{}", &stderr[stderr.len().saturating_sub(4000)..]);
    let rows = rows(&tmp.path().join("out"));
    assert!(rows.values().all(|r| r.status == "completed"), "{rows:?}");
    let cap = usize::try_from(stderr::TASK_CAP).expect("cap");
    assert!(stderr.len() < cap + cap / 2, "the run log is {} bytes", stderr.len());
    assert!(stderr.contains("were not logged"), "the log notes what it dropped");
    // The stream itself is in the victim's result folder, up to its own cap.
    let file = task_dir(&tmp.path().join("out"), VICTIM).join(stderr::FILE_NAME);
    let kept = std::fs::read(&file).expect("the victim's agent-stderr.log");
    let file_cap = usize::try_from(stderr::FILE_CAP).expect("cap");
    let note = String::from_utf8_lossy(&kept[file_cap.min(kept.len())..]);
    assert!(
        kept.len() > file_cap && note.contains("more bytes of stderr were not kept"),
        "{} bytes: {note}",
        kept.len()
    );
    let byte = if mode == "lines" { b'x' } else { b'y' };
    assert!(kept[..1000].iter().all(|&b| b == byte), "the stream as the agent wrote it");
    assert!(stderr.contains(&file.display().to_string()), "the log names the file");
}

/// The result folder of `task` under `out`, wherever the layout puts it.
fn task_dir(out: &Path, task: &str) -> PathBuf {
    let mut todo = vec![out.to_owned()];
    while let Some(dir) = todo.pop() {
        for entry in std::fs::read_dir(&dir).expect("a results folder").flatten() {
            if entry.file_type().is_ok_and(|t| t.is_dir()) {
                if entry.file_name() == task {
                    return entry.path();
                }
                todo.push(entry.path());
            }
        }
    }
    panic!("no result folder for {task} under {}", out.display());
}

#[test]
fn a_flood_of_stderr_lines_leaves_a_run_log_under_its_cap() {
    if arena_test_support::python3_or_skip("a_flood_of_stderr_lines_leaves_a_run_log_under_its_cap") {
        stderr_flood("lines");
    }
}

#[test]
fn a_flood_of_stderr_without_a_newline_leaves_a_run_log_under_its_cap() {
    if arena_test_support::python3_or_skip("a_flood_of_stderr_without_a_newline_leaves_a_run_log_under_its_cap") {
        stderr_flood("raw");
    }
}

/// Whether `pid` runs (a zombie, which has ended, does not).
fn alive(pid: u32) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .ok()
        .and_then(|stat| stat.rfind(')').map(|i| stat[i + 1..].trim_start().starts_with('Z')))
        .is_some_and(|zombie| !zombie)
}

#[test]
fn an_exec_agents_children_are_gone_after_its_run() {
    if !arena_test_support::python3_or_skip("an_exec_agents_children_are_gone_after_its_run") {
        return;
    }
    let tmp = tempfile::tempdir().expect("tmp");
    // Outside the sandbox: its children are found by their pids on this machine
    // (inside it they would have the sandbox's own, and end with its namespace).
    let (status, stderr, _) = run_hostile(tmp.path(), "children", "-", &["--agent-sandbox", "none"]);
    assert_eq!(status.code(), Some(0), "{stderr}");
    let text = std::fs::read_to_string(tmp.path().join("marker")).expect("the agent wrote its children's pids");
    let pids: Vec<u32> = text.lines().map(|l| l.trim().parse().expect("a pid")).collect();
    assert_eq!(pids.len(), 3, "a plain child, a new session and its child: {pids:?}");
    // Killed before the run ended; a process being torn down may take a moment to exit.
    for _ in 0..100 {
        if !pids.iter().any(|&p| alive(p)) {
            break;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let left: Vec<u32> = pids.into_iter().filter(|&p| alive(p)).collect();
    for &p in &left {
        let _ = Command::new("kill").args(["-KILL", &p.to_string()]).status();
    }
    assert!(left.is_empty(), "still running after the run: {left:?}");
}
