//! `navibench`: the host's overhead per Navi step, through the harness's own
//! episode loop, against the in-process stub guest and a mock chat-completions
//! endpoint that answers at once.
//!
//! Each episode opens Notepad and lets Navi (upstream's message layout, the
//! `a11y` Set-of-Marks) take `STEPS` steps, each a `move_abs` command, so a
//! step is: the observation (screenshot, tree, windows, clipboard), the
//! Set-of-Marks and annotated image, the request with its two JPEG images, the
//! mock's answer, the action and the next observation. It prints the mean of
//! the harness's per-step timings and the step loop's wall time per step
//! (episode time less setup and evaluation, which includes writing the files).
//!
//! It uses only interfaces older versions of this crate also have, so the same
//! file can be built against an earlier commit to compare the two side by side.
//!
//! Run: `cargo run --release -p arena-tests --bin navibench`.

#![forbid(unsafe_code)]

use std::process::ExitCode;
use std::time::Duration;

use arena_agents::navi::{NaviAgent, NaviConfig};
use arena_agents::Agent;
use arena_client::cache::DownloadCache;
use arena_client::client::{ClientConfig, GuestClient};
use arena_host::episode::{run_episode, EpisodeConfig};
use arena_results::TaskDir;
use arena_task::Task;
use arena_test_support::StubGuest;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpListener;

const STEPS: u32 = 10;
const EPISODES: usize = 4;

/// The model's reply: one pointer move, kept going.
const REPLY: &str =
    "Move.\n```python\ncomputer.mouse.move_abs(x=0.5, y=0.5)\n```\n```decision\nCOMMAND\n```\n```memory\nmoving\n```";

/// A chat-completions endpoint that answers every request at once with [`REPLY`]
/// (HTTP/1.1, one request per connection).
async fn mock_model() -> anyhow::Result<String> {
    let listener = TcpListener::bind("127.0.0.1:0").await?;
    let addr = listener.local_addr()?;
    let body = serde_json::json!({"choices": [{"message": {"role": "assistant", "content": REPLY}}]}).to_string();
    tokio::spawn(async move {
        while let Ok((mut socket, _)) = listener.accept().await {
            let body = body.clone();
            tokio::spawn(async move {
                let mut seen = Vec::new();
                let mut buf = vec![0u8; 1 << 16];
                // Read the headers, then as much body as Content-Length says.
                loop {
                    let Ok(n) = socket.read(&mut buf).await else { return };
                    if n == 0 {
                        return;
                    }
                    seen.extend_from_slice(&buf[..n]);
                    let text = String::from_utf8_lossy(&seen);
                    if let Some(end) = text.find("\r\n\r\n") {
                        let length = text[..end]
                            .lines()
                            .find_map(|l| {
                                let (k, v) = l.split_once(':')?;
                                k.eq_ignore_ascii_case("content-length").then(|| v.trim().parse::<usize>().ok())?
                            })
                            .unwrap_or(0);
                        if seen.len() >= end + 4 + length {
                            break;
                        }
                    }
                }
                let answer = format!(
                    "HTTP/1.1 200 OK\r\ncontent-type: application/json\r\ncontent-length: {}\r\nconnection: close\r\n\r\n{body}",
                    body.len()
                );
                let _ = socket.write_all(answer.as_bytes()).await;
                let _ = socket.shutdown().await;
            });
        }
    });
    Ok(format!("http://{addr}/v1"))
}

fn task() -> anyhow::Result<Task> {
    let text = r#"{"id": "bench", "instruction": "Move the pointer about in Notepad.",
        "config": [{"type": "launch", "parameters": {"command": "notepad"}}],
        "evaluator": {"func": "infeasible"}}"#;
    Ok(Task::parse(text, std::path::Path::new("/tasks/notepad/bench.json"))?)
}

fn mean(values: &[f64]) -> f64 {
    values.iter().sum::<f64>() / values.len().max(1) as f64
}

async fn bench() -> anyhow::Result<()> {
    let guest = StubGuest::start().await;
    let client =
        GuestClient::new(guest.url(), ClientConfig { token: None, timeout: Duration::from_secs(30), retries: 1 })?;
    let url = mock_model().await?;
    let dir = tempfile::tempdir()?;
    let task = task()?;
    let (mut observe, mut predict, mut act, mut step_wall) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for episode in 0..EPISODES {
        let mut config = EpisodeConfig::instant(DownloadCache::new(dir.path().join("cache"))?);
        config.max_steps = STEPS;
        config.model = "mock".into();
        let mut agent = NaviAgent::new(NaviConfig::new(&url, "mock"))?;
        let out = TaskDir::new(dir.path().join(format!("out-{episode}")));
        let result = run_episode(&client, &task, &mut agent as &mut dyn Agent, &config, &out).await;
        anyhow::ensure!(result.steps == STEPS, "the episode stopped early: {:?}", result.status);
        // The first episode warms caches up; it is not counted.
        if episode == 0 {
            continue;
        }
        for t in &result.timings {
            observe.push(t.observe_ms as f64);
            predict.push(t.predict_ms as f64);
            act.push(t.act_ms as f64);
        }
        let looping = result.elapsed_ms.saturating_sub(result.setup_ms).saturating_sub(result.eval_ms);
        step_wall.push(looping as f64 / f64::from(STEPS));
    }
    println!(
        "BENCH navi step on the stub ({} episodes x {STEPS} steps, 1440x900, Notepad, a11y marks, instant mock model):",
        EPISODES - 1
    );
    println!("  observe (harness)            mean {:7.1} ms", mean(&observe));
    println!("  predict (marks+image+model)  mean {:7.1} ms", mean(&predict));
    println!("  act (one move)               mean {:7.1} ms", mean(&act));
    println!("  host overhead per step       mean {:7.1} ms (the step loop's wall time per step)", mean(&step_wall));
    Ok(())
}

#[tokio::main(flavor = "current_thread")]
async fn main() -> ExitCode {
    match bench().await {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("navibench: {err:#}");
            ExitCode::FAILURE
        }
    }
}
