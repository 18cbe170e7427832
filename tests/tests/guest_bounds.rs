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
    assert!(done >= 1, "at least one program fits: {done} done, {refused} refused");
    assert!(refused >= 1, "16 x 240 MB do not fit in 512 MiB at once: {done} done, {refused} refused");
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
        tokio::spawn(async move {
            client.post(url).json(&json!({"command": ["python", "-c", "while True: pass"]})).send().await
        })
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
