//! `pyexec`: what one pyautogui action through WAA's `/execute` costs when the guest
//! runs the code natively, against what upstream pays for the same action: starting
//! a Python process (`python3 -c "pass"`, before any import).
//!
//! The guest runs in this process (the `arena_guest` library serving a real TCP
//! listener on 127.0.0.1) over the stub backend, and every request is a real HTTP
//! `POST /execute` with the upstream host's exact body, so the native figure
//! includes HTTP, JSON, parsing, interpreting and the stub's click. The process
//! figure is only the spawn-and-wait of a bare interpreter on this machine.
//! It then runs the probe programs of issue 25 (memory and time bounds) in this
//! process through the interpreter and prints, for each, its answer, the peak bytes
//! by the interpreter's own accounting and the time to that answer.
//! Run it in release mode: `cargo run --release -p arena-tests --bin pyexec`.
//! With `ARENA_BENCH_GUESTS=LABEL=PATH,...` it first measures the same request against
//! each named guest binary (a process of each build, started alike) side by side.

#![forbid(unsafe_code)]

use std::process::ExitCode;
use std::time::{Duration, Instant};

use anyhow::Context;

/// The upstream host's body for `pyautogui.click(x=100, y=200)` (waa-api.md §b.2).
const CODE: &str = "import pyautogui; import time; pyautogui.FAILSAFE = False; pyautogui.click(x=100, y=200)";

const NATIVE_RUNS: usize = 200;
const PROCESS_RUNS: usize = 50;

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

/// Sorted samples with their median and mean.
struct Stats {
    samples: Vec<Duration>,
}

impl Stats {
    fn new(mut samples: Vec<Duration>) -> Stats {
        samples.sort();
        Stats { samples }
    }

    fn p50(&self) -> Duration {
        self.samples[self.samples.len() / 2]
    }

    fn mean(&self) -> Duration {
        self.samples.iter().sum::<Duration>() / u32::try_from(self.samples.len()).unwrap_or(u32::MAX)
    }

    fn print(&self, name: &str) {
        let n = self.samples.len();
        let p95 = self.samples[((n as f64 - 1.0) * 0.95).round() as usize];
        println!(
            "{name:<46} n={n:<4} min={:>9.3} ms  p50={:>9.3} ms  p95={:>9.3} ms  mean={:>9.3} ms",
            ms(self.samples[0]),
            ms(self.p50()),
            ms(p95),
            ms(self.mean())
        );
    }
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1000.0
}

/// Starts `program -c "pass"` once to warm the file cache, then `PROCESS_RUNS` times.
fn spawn_python(program: &str) -> anyhow::Result<Stats> {
    let spawn = || {
        let status = std::process::Command::new(program)
            .args(["-c", "pass"])
            .stdin(std::process::Stdio::null())
            .status()
            .with_context(|| format!("starting {program} (is it on PATH?)"))?;
        anyhow::ensure!(status.success(), "{program} -c pass exited with {status}");
        Ok(())
    };
    spawn()?;
    let mut samples = Vec::with_capacity(PROCESS_RUNS);
    for _ in 0..PROCESS_RUNS {
        let start = Instant::now();
        spawn()?;
        samples.push(start.elapsed());
    }
    Ok(Stats::new(samples))
}

/// `runs` timed `POST /execute` of [`CODE`] against the guest at `base`, after 20 to warm up.
async fn execute_samples(http: &reqwest::Client, base: &str, runs: usize) -> anyhow::Result<Vec<Duration>> {
    let url = format!("{base}/execute");
    let body = serde_json::json!({"command": ["python", "-c", CODE], "shell": false});
    let post = || async {
        let answer: serde_json::Value = http.post(&url).json(&body).send().await?.error_for_status()?.json().await?;
        anyhow::ensure!(answer["returncode"] == 0 && answer["status"] == "success", "unexpected answer {answer}");
        Ok::<_, anyhow::Error>(())
    };
    for _ in 0..20 {
        post().await.context("warming up")?;
    }
    let mut samples = Vec::with_capacity(runs);
    for _ in 0..runs {
        let start = Instant::now();
        post().await.context("measuring /execute")?;
        samples.push(start.elapsed());
    }
    Ok(samples)
}

/// Rounds of the side-by-side comparison; each build measures [`NATIVE_RUNS`] / `ROUNDS`
/// requests per round, builds in a rotated order, so that drift of the machine spreads
/// over all of them.
const ROUNDS: usize = 5;

/// The same `/execute` figure for each guest build of `ARENA_BENCH_GUESTS`, each a
/// separate process started the same way, measured in interleaved rounds.
async fn side_by_side(http: &reqwest::Client, builds: &[(String, std::path::PathBuf)]) -> anyhow::Result<()> {
    println!("side by side, guest processes ({ROUNDS} rounds, builds rotated each round):");
    let extra = ["--computer-action-delay-ms", "0"];
    let served: Vec<arena_test_support::Served> = builds
        .iter()
        .map(|(label, exe)| {
            arena_test_support::Served::guest_of(exe, &extra).with_context(|| format!("starting the {label} guest"))
        })
        .collect::<anyhow::Result<_>>()?;
    let mut samples = vec![Vec::new(); builds.len()];
    for round in 0..ROUNDS {
        for i in 0..builds.len() {
            let b = (i + round) % builds.len();
            samples[b].extend(execute_samples(http, &served[b].url, NATIVE_RUNS / ROUNDS).await?);
        }
    }
    for ((label, _), samples) in builds.iter().zip(samples) {
        Stats::new(samples).print(&format!("{label}: POST /execute pyautogui.click"));
    }
    Ok(())
}

async fn run() -> anyhow::Result<()> {
    let http = reqwest::Client::new();
    let builds = arena_test_support::bench_guests()?;
    if !builds.is_empty() {
        side_by_side(&http, &builds).await?;
    }
    // The one test launcher; the guest stops when `stub` is dropped at the end.
    let stub = arena_test_support::StubGuest::start().await;
    println!("arena pyexec bench: one pyautogui click through POST /execute, natively, vs. a Python process start");
    let native = Stats::new(execute_samples(&http, stub.url(), NATIVE_RUNS).await?);
    native.print("native POST /execute pyautogui.click");

    let process = spawn_python("python3")?;
    process.print("process python3 -c \"pass\"");
    // `python3` on PATH may be a wrapper (pyenv's shim is a shell script); the
    // interpreter itself shows what a guest whose `python` is the real exe pays.
    let exe = std::process::Command::new("python3")
        .args(["-c", "import sys; print(sys.executable)"])
        .output()
        .context("asking python3 for its executable")?;
    let exe = String::from_utf8_lossy(&exe.stdout).trim().to_owned();
    let direct = if exe.is_empty() { None } else { Some(spawn_python(&exe)?) };
    if let Some(direct) = &direct {
        direct.print(&format!("process {exe} -c \"pass\""));
    }

    let ratio = |a: Duration, b: Duration| a.as_secs_f64() / b.as_secs_f64().max(1e-9);
    println!(
        "ratio (python3 process / native): p50 {:.1}x, mean {:.1}x",
        ratio(process.p50(), native.p50()),
        ratio(process.mean(), native.mean())
    );
    if let Some(direct) = &direct {
        println!(
            "ratio (interpreter exe process / native): p50 {:.1}x, mean {:.1}x",
            ratio(direct.p50(), native.p50()),
            ratio(direct.mean(), native.mean())
        );
    }

    drop(stub);
    probes();
    Ok(())
}

/// Issue 25's probe programs (items 1 and 2).
const PROBES: &[(&str, &str)] = &[
    ("shared repetition", "x = ['a' * 10**6] * 10**6"),
    ("nested repetition", "x = [[0] * 10**6] * 10**6"),
    ("join past the budget", "x = ['a' * 10**6] * 10**6\ny = ''.join(x)"),
    ("distinct strings past the budget", "x = ['a' * 10**6 + str(i) for i in range(10**6)]"),
    ("3 KB string reassigned 99999 times", "for i in range(99999):\n    s = 'a' * 3000"),
    (
        "in/sum/count over 10**5 items, 300 times",
        "x = list(range(10**5))\nfor i in range(300):\n    n = (-1 in x) + sum(x) + x.count(-1)",
    ),
    ("dict of 99999 ints", "d = {}\nfor i in range(99999):\n    d[i] = i"),
    (
        "reverse 999999 items 99999 times, 2 s deadline",
        "x = list(range(999999))\nfor i in range(99999):\n    x.reverse()",
    ),
];

/// Runs each probe with a 2 s deadline and prints what it answered and cost.
fn probes() {
    use arena_script::{parse, run_measured, Globals, RecordingHost, Stop};
    println!("issue 25 probes, in process (peak = the interpreter's own accounting):");
    for (name, src) in PROBES {
        let program = match parse(src) {
            Ok(program) => program,
            Err(err) => {
                println!("{name:<46} does not parse: {err}");
                continue;
            }
        };
        let mut host = RecordingHost::new((1920, 1080), (0, 0));
        let start = Instant::now();
        let stop = Stop::new(Some(start + Duration::from_secs(2)), None);
        let (result, stats) = run_measured(&program, &mut host, Globals::python().with_stop(stop));
        let elapsed = start.elapsed();
        let answer = match result {
            Ok(_) => "ok".to_owned(),
            Err(err) => format!("{}: {}", err.kind, err.message),
        };
        println!(
            "{name:<46} {:>9.1} ms  peak {:>8.1} MiB  steps {:>6}  held after {} B  {answer}",
            ms(elapsed),
            stats.peak_bytes as f64 / f64::from(1 << 20),
            stats.steps,
            stats.live_bytes_after
        );
    }
}
