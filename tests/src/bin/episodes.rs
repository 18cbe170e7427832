//! `episodes`: measures the host's overhead per episode step on the stub guest,
//! and the wall time of a 20-task run over a pool of 1 versus 4 guests.
//!
//! Per step (excluding any model): the observation as the episode makes it
//! (`observe::observe`: screenshot, accessibility tree, windows and clipboard
//! fetched concurrently, the screenshot decoded once as soon as it is here),
//! Set-of-Marks (element selection and the annotated screenshot, on the decoded
//! pixels), and one action (a pyautogui line run by the host-side interpreter,
//! which becomes a typed `/v1/actions` call). Builds before 2026-12-02 counted
//! the decode in Set-of-Marks and the observation without it; the total is
//! the same work either way. The guests are real `arena-guest` stub
//! processes on loopback; the pool runs use the oracle plans of
//! `tasks/stub` repeated to 20 tasks, without pauses and with a 250 ms pause
//! after each action.
//!
//! Run: `cargo run -p arena-tests --bin episodes` (add `--release` for
//! release figures).
//!
//! Side by side: with `ARENA_BENCH_HOSTS=LABEL=PATH,...`, each PATH another build's
//! `episodes` binary (built alike, say from an older commit in a worktree of its
//! own), it first runs this build's and each named build's bench as processes of
//! their own, in rotated rounds, and prints the per-step p50 of every build and
//! round, then each build's median round. Each process starts its own stub guests
//! (the `arena-guest` beside it), so a build is measured with its own guest, as a
//! user would run it. `ARENA_BENCH_PER_STEP_ONLY=1` stops a run after the per-step
//! figures (an older build without it runs whole; only its per-step lines are read).

#![forbid(unsafe_code)]

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use arena_agents::observation::observe::{self, ObserveConfig};
use arena_agents::scripted::{PlanSource, ScriptedAgent};
use arena_agents::Agent;
use arena_agents::AgentFactory;
use arena_client::cache::DownloadCache;
use arena_client::client::{ClientConfig, GuestClient};
use arena_exec::AgentAction;
use arena_exec::{execute_with, ExecOptions};
use arena_host::episode::{EpisodeConfig, EpisodeRunner};
use arena_host::run::pool::PoolConfig;
use arena_host::run::shard::Shard;
use arena_host::run::{load_tasks, run_tasks, RunOptions};
use arena_results::RunLayout;
use arena_script::ComputerState;
use arena_shared::exec::LaunchRequest;
use arena_som::{annotate, marks_from_tree};
use arena_task::{Difficulty, Task};
use arena_test_support::Served;

const STEPS: usize = 40;
const TASKS: usize = 20;
/// Rounds of the side-by-side comparison.
const ROUNDS: usize = 3;
/// The per-step lines, by the name each starts with, in the order printed.
const PER_STEP: [&str; 4] = ["observe", "set-of-marks", "action", "total"];

#[tokio::main]
async fn main() -> ExitCode {
    match run().await {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("error: {err:#}");
            ExitCode::FAILURE
        }
    }
}

fn client(url: &str) -> anyhow::Result<GuestClient> {
    Ok(GuestClient::new(url, ClientConfig { token: None, timeout: Duration::from_secs(30), retries: 1 })?)
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1000.0
}

/// Median and 90th percentile of `samples`, in milliseconds.
fn stats(samples: &mut [Duration]) -> (f64, f64, f64) {
    samples.sort();
    let n = samples.len();
    let mean = samples.iter().sum::<Duration>() / u32::try_from(n.max(1)).unwrap_or(1);
    (ms(samples[n / 2]), ms(samples[((n as f64 - 1.0) * 0.9).round() as usize]), ms(mean))
}

fn print(name: &str, samples: &mut [Duration]) {
    let (p50, p90, mean) = stats(samples);
    println!("  {name:<34} p50 {p50:>7.2} ms   p90 {p90:>7.2} ms   mean {mean:>7.2} ms");
}

async fn per_step(url: &str) -> anyhow::Result<()> {
    let client = client(url)?;
    client.wait_ready(&[], Duration::from_secs(30), Duration::from_millis(50)).await?;
    client.launch(&LaunchRequest { shell: None, argv: vec!["notepad".into()] }).await?;
    let screen = client.screen().await?;
    let size = (screen.physical_width, screen.physical_height);
    let mut computer = ComputerState::for_screen(i32::try_from(size.0)?, i32::try_from(size.1)?);
    let observe_config = ObserveConfig::default();
    let action = AgentAction::Pyautogui("pyautogui.write('a')".into());
    let options = ExecOptions::instant();
    let (mut observe, mut som, mut act, mut total) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut marks_count = 0;
    for _ in 0..STEPS {
        let t0 = Instant::now();
        let obs = observe::observe(&client, &observe_config, &screen, 1, "bench")
            .await
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        let t1 = Instant::now();
        let tree = obs.a11y.as_ref().context("the stub answered no accessibility tree")?;
        let marks = marks_from_tree(tree, size);
        // Annotated on the observation's pixels, decoded once there.
        let annotated = annotate(&obs.screenshot.pixels, &marks);
        anyhow::ensure!(annotated.width() > 0);
        marks_count = marks.entities.len();
        let t2 = Instant::now();
        let outcome = execute_with(&client, &action, Some(marks.boxes()), &mut computer, &options).await?;
        anyhow::ensure!(outcome.error.is_none(), "the action failed: {:?}", outcome.error);
        let t3 = Instant::now();
        observe.push(t1 - t0);
        som.push(t2 - t1);
        act.push(t3 - t2);
        total.push(t3 - t0);
    }
    println!(
        "host overhead per step on the stub ({STEPS} steps, 1440x900, Notepad open, {marks_count} marks; no model):"
    );
    print("observe (shot+tree+windows+clip, decode)", &mut observe);
    print("set-of-marks (select + annotate)", &mut som);
    print("action (pyautogui line)", &mut act);
    print("total", &mut total);
    Ok(())
}

fn stub_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tasks/stub")
}

/// The stub tasks repeated to `n`, each with its oracle plan inline.
fn repeated(n: usize) -> anyhow::Result<Vec<Task>> {
    let base = load_tasks(&stub_dir(), Difficulty::Normal)?;
    (0..n)
        .map(|i| {
            let mut task = base[i % base.len()].clone();
            let plan = std::fs::read_to_string(stub_dir().join("plans").join(format!("{}.json", task.name)))?;
            task.extra.insert("plan".into(), serde_json::from_str(&plan)?);
            task.name = format!("{}-{i:02}", task.name);
            Ok(task)
        })
        .collect()
}

async fn pool_run(guests: &[Served], pause: Duration) -> anyhow::Result<(Duration, u32, f64, f64)> {
    let tmp = tempfile::tempdir()?;
    let layout = RunLayout {
        root: tmp.path().join("out"),
        agent: "scripted".into(),
        observation: "a11y_tree".into(),
        model: "oracle".into(),
        trial: "0".into(),
    };
    let mut config = EpisodeConfig::instant(DownloadCache::new(tmp.path().join("cache"))?);
    config.sleep_after_action = pause;
    let agents: AgentFactory = Arc::new(|| Ok(Box::new(ScriptedAgent::new(PlanSource::TaskKey)) as Box<dyn Agent>));
    let runner = EpisodeRunner { layout: layout.clone(), config, agents };
    let options = RunOptions {
        layout,
        shard: Shard::ALL,
        resume: true,
        pool: PoolConfig::default(),
        watch: std::sync::Arc::new(arena_host::run::watch::Unwatched),
        title: "bench".into(),
        order: Default::default(),
        trials: 1,
        budget: Default::default(),
    };
    let clients = guests.iter().map(|g| client(&g.url)).collect::<anyhow::Result<Vec<_>>>()?;
    let started = Instant::now();
    let outcome = run_tasks(repeated(TASKS)?, clients, Arc::new(runner), &options).await?;
    let wall = started.elapsed();
    let steps: Vec<_> = outcome.pool.results.iter().flat_map(|r| r.timings.iter().cloned()).collect();
    let n = steps.len().max(1) as f64;
    let observe = steps.iter().map(|t| t.observe_ms as f64).sum::<f64>() / n;
    let act = steps.iter().map(|t| t.act_ms as f64).sum::<f64>() / n;
    anyhow::ensure!(
        outcome.summary.overall.successes as usize == TASKS,
        "not every task was solved: {:?}",
        outcome.summary.overall
    );
    Ok((wall, outcome.summary.overall.successes, observe, act))
}

/// The builds `ARENA_BENCH_HOSTS` names, as (label, path).
fn other_builds() -> anyhow::Result<Vec<(String, PathBuf)>> {
    let Ok(list) = std::env::var("ARENA_BENCH_HOSTS") else { return Ok(Vec::new()) };
    list.split(',')
        .filter(|entry| !entry.trim().is_empty())
        .map(|entry| {
            let (label, path) = entry
                .split_once('=')
                .with_context(|| format!("ARENA_BENCH_HOSTS entry {entry:?} is not LABEL=PATH"))?;
            let path = PathBuf::from(path.trim());
            anyhow::ensure!(path.is_file(), "ARENA_BENCH_HOSTS: {label}'s bench {} is not a file", path.display());
            Ok((label.trim().to_owned(), path))
        })
        .collect()
}

/// The p50 of each [`PER_STEP`] line in a bench's output, in milliseconds.
fn per_step_p50(output: &str) -> anyhow::Result<[f64; 4]> {
    let mut found = [None; 4];
    for line in output.lines() {
        let line = line.trim_start();
        let Some(i) = PER_STEP.iter().position(|name| line.starts_with(name)) else { continue };
        let p50 = line
            .split_once(" p50 ")
            .and_then(|(_, rest)| rest.split_whitespace().next())
            .and_then(|n| n.parse::<f64>().ok());
        found[i] = found[i].or(p50);
    }
    let mut out = [0.0; 4];
    for (i, value) in found.into_iter().enumerate() {
        out[i] = value.with_context(|| format!("no {} p50 line in the bench's output:\n{output}", PER_STEP[i]))?;
    }
    Ok(out)
}

/// One run of a build's bench as a process of its own; its per-step p50s.
async fn bench_process(exe: &Path) -> anyhow::Result<[f64; 4]> {
    let output = tokio::process::Command::new(exe)
        .env("ARENA_BENCH_PER_STEP_ONLY", "1")
        .env_remove("ARENA_BENCH_HOSTS")
        .env("RUST_LOG", "off")
        .stdin(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .kill_on_drop(true)
        .output()
        .await
        .with_context(|| format!("running {}", exe.display()))?;
    let stdout = String::from_utf8_lossy(&output.stdout);
    anyhow::ensure!(output.status.success(), "{} failed ({}):\n{stdout}", exe.display(), output.status);
    per_step_p50(&stdout)
}

/// This build and the `ARENA_BENCH_HOSTS` builds, each as a process, in rotated rounds.
async fn side_by_side(others: Vec<(String, PathBuf)>) -> anyhow::Result<()> {
    let mut builds = vec![("this build".to_owned(), std::env::current_exe()?)];
    builds.extend(others);
    println!(
        "side by side: per-step p50 in ms ({ROUNDS} rounds, builds rotated; each a process with its own stub guests)"
    );
    println!(
        "  {:<24} {:>5}  {:>9} {:>13} {:>8} {:>8}",
        "build", "round", PER_STEP[0], PER_STEP[1], PER_STEP[2], PER_STEP[3]
    );
    let row = |label: &str, round: &str, f: &[f64; 4]| {
        println!("  {label:<24} {round:>5}  {:>9.2} {:>13.2} {:>8.2} {:>8.2}", f[0], f[1], f[2], f[3]);
    };
    let mut rounds = vec![Vec::new(); builds.len()];
    for round in 0..ROUNDS {
        for k in 0..builds.len() {
            let b = (k + round) % builds.len();
            let figures = bench_process(&builds[b].1).await.with_context(|| format!("the {} bench", builds[b].0))?;
            row(&builds[b].0, &(round + 1).to_string(), &figures);
            rounds[b].push(figures);
        }
    }
    for ((label, _), mut figures) in builds.iter().zip(rounds) {
        // The median round by total.
        figures.sort_by(|a, b| a[3].total_cmp(&b[3]));
        row(label, "median", &figures[figures.len() / 2]);
    }
    Ok(())
}

async fn run() -> anyhow::Result<()> {
    let others = other_builds()?;
    if !others.is_empty() {
        return side_by_side(others).await;
    }
    let guests: Vec<Served> =
        (0..4).map(|_| Served::guest(&[])).collect::<anyhow::Result<_>>().context("starting stub guests")?;
    println!(
        "arena episode bench ({} build, {} CPUs)",
        if cfg!(debug_assertions) { "debug" } else { "release" },
        std::thread::available_parallelism().map_or(1, |n| n.get())
    );
    per_step(&guests[0].url).await?;
    if std::env::var_os("ARENA_BENCH_PER_STEP_ONLY").is_some_and(|v| v == "1") {
        return Ok(());
    }
    // Without pauses the stub's work is all CPU, on the same cores as the
    // host; with a pause after each action (upstream waits 3 s) the guests'
    // time is mostly waiting, as with real VMs, and the pool's gain shows.
    for pause in [Duration::ZERO, Duration::from_millis(250)] {
        println!(
            "{TASKS}-task run of the stub tasks (oracle plans, {} ms pause after each action), wall time:",
            pause.as_millis()
        );
        for n in [1usize, 4] {
            // A fresh set of guests per run, so every run starts from the same state.
            let fresh: Vec<Served> = (0..n).map(|_| Served::guest(&[])).collect::<anyhow::Result<_>>()?;
            let (wall, solved, observe, act) = pool_run(&fresh, pause).await?;
            println!(
                "  {n} guest(s): {:>7.0} ms  ({:.0} ms per task; {solved}/{TASKS} solved; mean observe {observe:.1} ms, act {act:.1} ms per step)",
                ms(wall),
                ms(wall) / TASKS as f64
            );
        }
    }
    Ok(())
}
