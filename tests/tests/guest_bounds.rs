//! The guest bounded as a whole (issue 33): many programs at once through every way
//! in leave the real `arena-guest` binary alive, within its shared interpreter
//! memory (`--program-memory-mib`) and its limit on programs at once
//! (`--max-programs`), each refused program told why.

#![cfg(target_os = "linux")]

use std::time::Duration;

use arena_test_support::Served;
use serde_json::{json, Value};

/// The process's peak resident memory in MiB (`VmHWM`).
fn peak_mib(pid: u32) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).expect("the guest's /proc status");
    let kib: u64 = status
        .lines()
        .find_map(|line| line.strip_prefix("VmHWM:"))
        .and_then(|rest| rest.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .expect("a VmHWM line");
    kib / 1024
}

/// A program holding 240 MB (24 strings of 10 MB, the interpreter's longest) for a second.
const BIG: &str = "import time\nx = ['a' * 9999000 + str(i) for i in range(24)]\ntime.sleep(1)\nprint(len(x))";

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sixteen_programs_of_240_mb_leave_the_guest_alive_and_within_its_budget() {
    const POOL_MIB: u64 = 512;
    let guest = Served::guest(&["--program-memory-mib", "512", "--max-programs", "8", "--program-wait-ms", "60000"])
        .expect("guest starts");
    let client = reqwest::Client::new();
    let calls = (0..16).map(|_| {
        let client = client.clone();
        let url = format!("{}/execute", guest.url);
        async move {
            let response = client.post(url).json(&json!({"command": ["python", "-c", BIG]})).send().await?;
            let status = response.status().as_u16();
            Ok::<_, reqwest::Error>((status, response.json::<Value>().await?))
        }
    });
    let answers = futures_util::future::join_all(calls).await;
    let (mut done, mut refused) = (0, 0);
    for answer in answers {
        let (status, body) = answer.expect("every program is answered");
        assert_eq!(status, 200, "{body}");
        if body["returncode"] == 0 {
            assert_eq!(body["output"], "24\n");
            done += 1;
        } else {
            let error = body["error"].as_str().unwrap_or_default();
            assert!(error.contains("MemoryError") && error.contains("512 MiB together"), "{body}");
            refused += 1;
        }
    }
    assert!(refused >= 1, "16 x 240 MB do not fit in 512 MiB at once: {done} done, {refused} refused");
    // Every program gave its share back: one alone fits again.
    let alone = client
        .post(format!("{}/execute", guest.url))
        .json(&json!({"command": ["python", "-c", BIG]}))
        .send()
        .await
        .expect("answered");
    let body: Value = alone.json().await.expect("a body");
    assert_eq!(body["output"], "24\n", "{body}");
    let health = client.get(format!("{}/v1/health", guest.url)).send().await.expect("the guest is alive");
    assert!(health.status().is_success());
    let peak = peak_mib(guest.pid());
    eprintln!("guest peak under 16 x 240 MB programs: {peak} MiB ({done} done, {refused} MemoryError)");
    // The pool bounds what the programs hold in values at once; above it are the
    // server itself, the copies a built-in makes while it builds, and what the
    // allocator keeps of freed memory in its per-thread arenas (about 330 MiB here).
    // Without the pool the same programs take the guest to several GiB.
    assert!(
        peak < POOL_MIB + 512,
        "the guest peaked at {peak} MiB, past its {POOL_MIB} MiB pool and 512 MiB of overhead"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_program_past_the_limit_of_programs_is_answered_503_naming_it() {
    let guest = Served::guest(&["--max-programs", "1", "--program-wait-ms", "100"]).expect("guest starts");
    let client = reqwest::Client::new();
    // One program that holds its place until it is told to stop (its deadline).
    let long = {
        let client = client.clone();
        let url = format!("{}/execute", guest.url);
        tokio::spawn(
            async move { client.post(url).json(&json!({"command": ["python", "-c", CPU_BOUND]})).send().await },
        )
    };
    let url = format!("{}/v1/exec", guest.url);
    let busy = arena_test_support::eventually("the second program to be refused", Duration::from_secs(30), || {
        let client = client.clone();
        let url = url.clone();
        async move {
            let response = client.post(&url).json(&json!({"argv": ["true"]})).send().await.ok()?;
            (response.status() == 503).then_some(response)
        }
    })
    .await;
    let body: Value = busy.json().await.expect("an error body");
    let message = body["message"].as_str().unwrap_or_default();
    assert!(message.contains("--max-programs 1") && message.contains("100 ms"), "{body}");
    let waa = client
        .post(format!("{}/execute", guest.url))
        .json(&json!({"command": ["python", "-c", "print(1)"]}))
        .send()
        .await
        .expect("answered");
    assert_eq!(waa.status(), 503);
    let body: Value = waa.json().await.expect("upstream's error shape");
    assert_eq!(body["status"], "error");
    long.abort();
}

/// The guest's CPU time so far (user and system), from `/proc/PID/stat`.
fn cpu_time(pid: u32) -> Duration {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).expect("the guest's /proc stat");
    // After the command name in parentheses: state is field 3, utime 14, stime 15.
    let after = &stat[stat.rfind(')').expect("a command name") + 2..];
    let fields: Vec<u64> = after.split_whitespace().map(|f| f.parse().unwrap_or(0)).collect();
    // In clock ticks of USER_HZ, 100 a second on Linux whatever the kernel's own HZ.
    Duration::from_millis((fields[11] + fields[12]) * 10)
}

/// An MCP client over plain HTTP, enough to open sessions and start calls.
struct Mcp {
    http: reqwest::Client,
    url: String,
}

impl Mcp {
    fn new(base: &str) -> Mcp {
        Mcp { http: reqwest::Client::new(), url: format!("{base}/mcp") }
    }

    fn post(&self, session: Option<&str>, body: &Value) -> reqwest::RequestBuilder {
        let mut request = self
            .http
            .post(&self.url)
            .header("Accept", "application/json, text/event-stream")
            .header("Content-Type", "application/json")
            .json(body);
        if let Some(session) = session {
            request = request.header("Mcp-Session-Id", session).header("MCP-Protocol-Version", "2025-06-18");
        }
        request
    }

    /// `initialize` and `notifications/initialized`; answers the session id.
    async fn open(&self) -> String {
        let init = json!({"jsonrpc": "2.0", "id": 0, "method": "initialize", "params": {
            "protocolVersion": "2025-06-18", "capabilities": {}, "clientInfo": {"name": "bounds", "version": "0"}}});
        let response = self.post(None, &init).send().await.expect("initialize answered");
        assert_eq!(response.status(), 200);
        let session = response.headers()["mcp-session-id"].to_str().expect("text").to_owned();
        let _ = response.bytes().await;
        let ready = json!({"jsonrpc": "2.0", "method": "notifications/initialized"});
        let response = self.post(Some(&session), &ready).send().await.expect("initialized accepted");
        assert_eq!(response.status(), 202);
        session
    }

    /// One `tools/call`, answered in full: the result's text and whether it is an error.
    async fn call(&self, session: &str, tool: &str, arguments: Value) -> (String, bool) {
        let call = json!({"jsonrpc": "2.0", "id": 1, "method": "tools/call", "params": {"name": tool, "arguments": arguments}});
        let body = self.post(Some(session), &call).send().await.expect("answered").text().await.expect("a body");
        let data = body.lines().filter_map(|l| l.strip_prefix("data:")).map(str::trim).find(|d| !d.is_empty());
        let message: Value = serde_json::from_str(data.expect("an answer event")).expect("JSON");
        let result = &message["result"];
        (result["content"][0]["text"].as_str().unwrap_or_default().to_owned(), result["isError"] == true)
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn mcp_sessions_past_the_cap_close_the_one_idle_longest() {
    let guest = Served::guest(&["--mcp", "--mcp-max-sessions", "8"]).expect("guest starts");
    let mcp = Mcp::new(&guest.url);
    let first = mcp.open().await;
    let mut last = String::new();
    for _ in 0..500 {
        last = mcp.open().await;
    }
    let (text, error) = mcp.call(&last, "list_windows", json!({})).await;
    assert!(!error && text.contains("windows"), "the newest session works: {text}");
    let gone = mcp
        .post(Some(&first), &json!({"jsonrpc": "2.0", "id": 2, "method": "tools/list"}))
        .send()
        .await
        .expect("answered");
    assert_eq!(gone.status(), 404, "the first session was closed to make room");
    eprintln!("guest peak after 501 MCP sessions (cap 8): {} MiB", peak_mib(guest.pid()));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn mcp_input_tools_have_the_checks_of_the_actions_route() {
    let guest = Served::guest(&["--mcp"]).expect("guest starts");
    let mcp = Mcp::new(&guest.url);
    let session = mcp.open().await;
    let drag = json!({"from_x": 1, "from_y": 1, "to_x": 5, "to_y": 5, "duration": 1e300});
    let (text, error) = mcp.call(&session, "drag", drag).await;
    assert!(error && text.contains("a drag lasts at most 60000 ms"), "{text}");
    let keys = vec!["a"; 200_000];
    let (text, error) = mcp.call(&session, "press_keys", json!({"keys": keys})).await;
    assert!(error && text.contains("at most 64 keys"), "{text}");
    let (text, error) = mcp.call(&session, "press_keys", json!({"keys": ["ctrl", "s"]})).await;
    assert!(!error, "a chord still works: {text}");
}

/// Burns a core for far longer than any test: each step is a megabyte of work, so the
/// interpreter's step budget does not end it first.
const CPU_BOUND: &str = "while True:\n    x = ('ab' * 500000).upper()";

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_hung_up_run_python_stops_burning_cpu() {
    let guest = Served::guest(&["--mcp"]).expect("guest starts");
    let pid = guest.pid();
    let mcp = Mcp::new(&guest.url);
    let session = mcp.open().await;
    let call = json!({"jsonrpc": "2.0", "id": 7, "method": "tools/call",
        "params": {"name": "run_python", "arguments": {"code": CPU_BOUND}}});
    let response = mcp.post(Some(&session), &call).send().await.expect("the call's stream opens");
    assert_eq!(response.status(), 200);
    // The loop burns a core: wait (bounded) until the guest's CPU time climbs.
    let busy = |window: Duration| async move {
        let before = cpu_time(pid);
        tokio::time::sleep(window).await;
        cpu_time(pid).saturating_sub(before)
    };
    arena_test_support::eventually("the loop to run", Duration::from_secs(20), || async {
        (busy(Duration::from_millis(300)).await >= Duration::from_millis(150)).then_some(())
    })
    .await;
    // The client hangs up.
    drop(response);
    let hung_up = std::time::Instant::now();
    arena_test_support::eventually("the loop to stop after the hang-up", Duration::from_secs(20), || async {
        (busy(Duration::from_millis(300)).await <= Duration::from_millis(40)).then_some(())
    })
    .await;
    // The 30 s call deadline did not end it: the hang-up did.
    let quiet = hung_up.elapsed();
    eprintln!("run_python stopped burning CPU within {} ms of the hang-up", quiet.as_millis());
    assert!(quiet < Duration::from_secs(20));
    // The session lives on.
    let (text, error) = mcp.call(&session, "run_python", json!({"code": "print(6 * 7)"})).await;
    assert!(!error && text.contains("42"), "{text}");
}
