//! `agentbench`: the harness's overhead per step of each outside-agent route
//! (`--agent exec`, `--agent http`, `--agent mcp`) against the built-in Navi
//! path, measured side by side in one run.
//!
//! Each route runs `arena run` over the six stub tasks on one embedded stub
//! guest, with `--max-steps 8` and an agent that answers every step at once
//! (`WAIT`): a Python agent over the step protocol (stdin/stdout, then HTTP),
//! an `rmcp` client calling `wait` with 0 seconds, and Navi against a local
//! mock chat endpoint that always answers a `WAIT` decision. The figure is the
//! step's `predict_ms` from `traj.jsonl` (asking the agent and having its
//! answer; for Navi also its prompt, Set-of-Marks and annotated image, and for
//! MCP the client's round trip to its next call), and `observe_ms` beside it,
//! which every route shares.
//!
//! Run: `cargo run -p arena-tests --bin agentbench` (needs `python3`).

#![forbid(unsafe_code)]

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitCode, Stdio};
use std::time::{Duration, Instant};

use anyhow::Context;
use arena_test_support::workspace_binary;
use rmcp::model::{CallToolRequestParams, ClientConfig, ProtocolVersion};
use rmcp::transport::streamable_http_client::StreamableHttpClientTransportConfig;
use rmcp::transport::StreamableHttpClientTransport;
use rmcp::ServiceExt;
use serde_json::{json, Value};

#[path = "../../tests/agent_protocol/mock_model.rs"]
mod mock_model;

const MAX_STEPS: &str = "8";
const TOKEN: &str = "agentbench-token-0123456789";

const WAITER: &str = r#"
from arena_agent import Agent

class Waiter(Agent):
    action_space = "pyautogui"
    def predict(self, obs):
        return {"decision": "WAIT"}
"#;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn arena(out: &Path, extra: &[&str], env: &[(&str, String)]) -> anyhow::Result<Child> {
    let exe = workspace_binary("arena-host", "arena")?;
    let mut cmd = Command::new(exe);
    cmd.args(["run", "--stub-guests", "1", "--pauses", "fast", "--max-steps", MAX_STEPS, "--tasks"])
        .arg(repo().join("tasks/stub"))
        .arg("--out")
        .arg(out)
        .args(extra)
        .stdout(Stdio::piped())
        .stderr(Stdio::null());
    for (k, v) in env {
        cmd.env(k, v);
    }
    Ok(cmd.spawn()?)
}

/// Every step's (`predict_ms`, `observe_ms`) below `out`.
fn timings(out: &Path) -> Vec<(f64, f64)> {
    fn walk(dir: &Path, acc: &mut Vec<(f64, f64)>) {
        let Ok(entries) = std::fs::read_dir(dir) else { return };
        for entry in entries.flatten() {
            let path = entry.path();
            if path.is_dir() {
                walk(&path, acc);
            } else if path.file_name().is_some_and(|n| n == "traj.jsonl") {
                let text = std::fs::read_to_string(&path).unwrap_or_default();
                for line in text.lines() {
                    let Ok(v) = serde_json::from_str::<Value>(line) else { continue };
                    if let (Some(p), Some(o)) =
                        (v["timings"]["predict_ms"].as_f64(), v["timings"]["observe_ms"].as_f64())
                    {
                        acc.push((p, o));
                    }
                }
            }
        }
    }
    let mut acc = Vec::new();
    walk(out, &mut acc);
    acc
}

fn report(route: &str, out: &Path, wall: Duration) {
    let t = timings(out);
    let n = t.len().max(1) as f64;
    let mut predict: Vec<f64> = t.iter().map(|x| x.0).collect();
    predict.sort_by(f64::total_cmp);
    let median = predict.get(predict.len() / 2).copied().unwrap_or(0.0);
    let mean_predict = t.iter().map(|x| x.0).sum::<f64>() / n;
    let mean_observe = t.iter().map(|x| x.1).sum::<f64>() / n;
    println!(
        "{route:<6} steps {:>3}  predict mean {mean_predict:>7.2} ms  median {median:>5.0} ms  observe mean {mean_observe:>7.2} ms  run wall {:>6.2} s",
        t.len(),
        wall.as_secs_f64()
    );
}

fn finish(mut child: Child) -> anyhow::Result<()> {
    let status = child.wait()?;
    anyhow::ensure!(status.success(), "arena run exited with {status}");
    Ok(())
}

/// Plays every task over MCP, calling `wait` until each episode ends.
async fn mcp_client(url: &str) -> anyhow::Result<()> {
    let transport = StreamableHttpClientTransport::from_config(
        StreamableHttpClientTransportConfig::with_uri(url).auth_header(TOKEN),
    );
    let client = ClientConfig::default().with_protocol_version(ProtocolVersion::V_2025_06_18).serve(transport).await?;
    let text = |r: &rmcp::model::CallToolResult| -> Value {
        let content = serde_json::to_value(&r.content[0]).unwrap_or(Value::Null);
        serde_json::from_str(content["text"].as_str().unwrap_or("null")).unwrap_or(Value::Null)
    };
    loop {
        let task = client.call_tool(CallToolRequestParams::new("get_task")).await?;
        if text(&task)["task_id"].is_null() {
            break;
        }
        loop {
            let args = json!({"seconds": 0}).as_object().cloned().unwrap_or_default();
            let r = client.call_tool(CallToolRequestParams::new("wait").with_arguments(args)).await?;
            if text(&r)["episode_ended"] == json!(true) {
                break;
            }
        }
    }
    let _ = client.cancel().await;
    Ok(())
}

async fn bench() -> anyhow::Result<()> {
    let tmp = tempfile::tempdir()?;
    std::fs::write(tmp.path().join("bench_waiter.py"), WAITER)?;
    let pythonpath = format!("{}:{}", repo().join("python").display(), tmp.path().display());
    let env = [("PYTHONPATH", pythonpath.clone())];
    println!("agentbench: per step, {MAX_STEPS} steps x 6 stub tasks per route, one stub guest");

    let out = tmp.path().join("navi");
    let started = Instant::now();
    let model = mock_model::start("Waiting.\n```decision\nWAIT\n```")?;
    finish(arena(&out, &["--agent", "navi", "--llm-url", &model.url, "--model", "mock"], &[])?)?;
    report("navi", &out, started.elapsed());
    let asked = model.requests.lock().map(|r| r.len()).unwrap_or(0);
    println!("       (navi asked the mock model {asked} times)");

    let out = tmp.path().join("exec");
    let started = Instant::now();
    finish(arena(&out, &["--agent", "exec", "--agent-cmd", "python3 -m arena_agent bench_waiter:Waiter"], &env)?)?;
    report("exec", &out, started.elapsed());

    let out = tmp.path().join("http");
    let mut server = Command::new("python3")
        .args(["-m", "arena_agent", "--http", "127.0.0.1:0", "bench_waiter:Waiter"])
        .env("PYTHONPATH", &pythonpath)
        .stderr(Stdio::piped())
        .spawn()?;
    let mut lines = BufReader::new(server.stderr.take().context("stderr")?).lines();
    let url = loop {
        let line = lines.next().context("the HTTP agent ended")??;
        if let Some(url) = line.strip_prefix("arena_agent: listening on ") {
            break url.trim().to_owned();
        }
    };
    std::thread::spawn(move || lines.for_each(drop));
    let started = Instant::now();
    let run = finish(arena(&out, &["--agent", "http", "--agent-url", &url], &[])?);
    let _ = server.kill();
    let _ = server.wait();
    run?;
    report("http", &out, started.elapsed());

    let out = tmp.path().join("mcp");
    let started = Instant::now();
    let mut child = arena(&out, &["--agent", "mcp", "--mcp-listen", "127.0.0.1:0", "--mcp-token", TOKEN], &[])?;
    let mut stdout = BufReader::new(child.stdout.take().context("stdout")?).lines();
    let url = loop {
        let line = stdout.next().context("arena run ended")??;
        if let Some(url) = line.strip_prefix("MCP endpoint: ") {
            break url.trim().to_owned();
        }
    };
    std::thread::spawn(move || stdout.for_each(drop));
    mcp_client(&url).await?;
    finish(child)?;
    report("mcp", &out, started.elapsed());
    Ok(())
}

#[tokio::main]
async fn main() -> ExitCode {
    match bench().await {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("agentbench: {err:#}");
            ExitCode::FAILURE
        }
    }
}
