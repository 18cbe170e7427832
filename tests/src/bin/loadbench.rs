//! `loadbench`: the guest under load and under attack, on loopback, bounded in count
//! and time; prints figures.
//!
//! The guest is the real server (`arena_guest::serve` on 127.0.0.1 in this process,
//! stub backend) driven over HTTP:
//! - a mixed workload (health, screen, a small action, a file stat, the foreground
//!   accessibility tree) from 50 and from 200 concurrent clients for a few seconds
//!   each: requests/s, p50/p99 and the number of errors;
//! - the same 50 clients while 500 connections hold half-sent requests open;
//! - resident memory: peak and settled, and the peak around a PNG bomb sent as a
//!   clipboard image (six at once), a 1 GiB file read and a 1023 MiB upload.
//!
//! - issue 25's hostile requests and two lockout scenarios (a slow body, reconnecting
//!   idle sockets), against guest processes: what a legitimate client gets, the time to
//!   each answer and the guest's peak memory, side by side with an older build when
//!   `ARENA_LOADBENCH_BASELINE` names its binary (see [`guards`]).
//!
//! Memory figures read `/proc/self/status` (Linux); elsewhere they print as unknown.
//! Run it in release mode: `cargo run --release -p arena-tests --bin loadbench`
//! (`-- guards` runs the guards section alone). With `ARENA_BENCH_GUESTS=LABEL=PATH,...`
//! it first runs the mixed workload against a process of each named guest build, side
//! by side in rotated rounds (`-- side-by-side` runs that alone). There the clients
//! run on one thread of their own (a current-thread runtime), so the other core is the
//! guest's and no client waits on another client's scheduler, and each phase is run
//! twice: with the host's [`GuestClient`], as every earlier round measured, and with a
//! lean client ([`lean`]) that spends far less CPU per request. Each phase prints
//! p50/p99 by kind of request as well.

#![forbid(unsafe_code)]

#[path = "loadbench/guards.rs"]
mod guards;
#[path = "loadbench/lean.rs"]
mod lean;

use std::process::ExitCode;
use std::time::{Duration, Instant};

use anyhow::Context;
use arena_client::client::{ClientConfig, GuestClient};
use arena_shared::action::Action;
use arena_shared::observation::A11yQuery;
use tokio::io::AsyncWriteExt as _;

/// How long each load phase runs.
const PHASE: Duration = Duration::from_secs(4);

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

/// A `/proc/self/status` field in MiB (`VmRSS`, `VmHWM`), when the platform has it.
fn memory(field: &str) -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with(field))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

fn mib(value: Option<f64>) -> String {
    value.map_or_else(|| "unknown".to_owned(), |v| format!("{v:.0} MiB"))
}

/// The requests of the mixed workload, in the order each client cycles through them.
const KINDS: [&str; 5] = ["health", "screen", "action", "stat", "a11y"];

/// One client's loop: the mixed workload until `until`; each answer's kind (an index
/// into [`KINDS`]) and latency, and the number of errors.
async fn client_loop(client: GuestClient, until: Instant, id: usize) -> (Vec<(usize, Duration)>, usize) {
    let (mut latencies, mut errors) = (Vec::new(), 0);
    let mut n = id;
    while Instant::now() < until {
        let started = Instant::now();
        let kind = n % KINDS.len();
        let result = match kind {
            0 => client.health().await.map(drop),
            1 => client.screen().await.map(drop),
            2 => client.act_one(Action::MoveTo { x: (n % 1400) as i32, y: 300 }).await.map(drop),
            3 => client.stat(r"C:\Users\Docker\Desktop").await.map(drop),
            _ => client.a11y(&A11yQuery { foreground_only: true, ..A11yQuery::default() }).await.map(drop),
        };
        match result {
            Ok(()) => latencies.push((kind, started.elapsed())),
            Err(_) => errors += 1,
        }
        n += 1;
    }
    (latencies, errors)
}

/// The `p`th quantile of sorted latencies (zero when there are none).
fn quantile(sorted: &[Duration], p: f64) -> Duration {
    sorted.get(((sorted.len().max(1) - 1) as f64 * p) as usize).copied().unwrap_or_default()
}

/// Which client drives the mixed workload.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Driver {
    /// The host's own [`GuestClient`].
    Host,
    /// [`lean::client_loop`]: one HTTP/1.1 connection per client, answers not decoded.
    Lean,
}

impl Driver {
    fn name(self) -> &'static str {
        match self {
            Driver::Host => "GuestClient",
            Driver::Lean => "lean client",
        }
    }
}

/// What one load phase measured.
#[derive(Debug, Clone, Copy)]
struct Figures {
    per_second: f64,
    p50: Duration,
    p99: Duration,
    errors: usize,
    /// p50 and p99 of each kind of request, as in [`KINDS`].
    kinds: [(Duration, Duration); KINDS.len()],
}

impl Figures {
    fn print(&self, name: &str) {
        println!(
            "{name:<46} {:>8.0} req/s  p50 {:>7.2} ms  p99 {:>7.2} ms  errors {}",
            self.per_second,
            self.p50.as_secs_f64() * 1000.0,
            self.p99.as_secs_f64() * 1000.0,
            self.errors
        );
    }

    /// One line of p50/p99 by kind of request, to tell which one makes the tail.
    fn print_kinds(&self) {
        let by_kind: Vec<String> = KINDS
            .iter()
            .zip(self.kinds)
            .map(|(kind, (p50, p99))| {
                format!("{kind} {:.2}/{:.2}", p50.as_secs_f64() * 1000.0, p99.as_secs_f64() * 1000.0)
            })
            .collect();
        println!("{:<46} p50/p99 ms by request: {}", "", by_kind.join(", "));
    }
}

/// Runs `clients` concurrent clients for [`PHASE`] and prints the figures.
async fn phase(url: &str, name: &str, clients: usize) -> anyhow::Result<()> {
    let figures = measure(url, clients, Driver::Host).await?;
    figures.print(name);
    figures.print_kinds();
    Ok(())
}

/// Runs `clients` concurrent clients for [`PHASE`] against `url`.
///
/// The clock starts once every client is built (a `GuestClient` loads the system's
/// root certificates, a few milliseconds each, which earlier rounds counted into the
/// phase), and requests per second are over the time the phase really took.
async fn measure(url: &str, clients: usize, driver: Driver) -> anyhow::Result<Figures> {
    let built: Vec<Option<GuestClient>> = (0..clients)
        .map(|_| match driver {
            Driver::Lean => Ok(None),
            Driver::Host => {
                let config = ClientConfig { token: None, timeout: Duration::from_secs(30), retries: 0 };
                GuestClient::new(url, config).map(Some)
            }
        })
        .collect::<Result<_, _>>()?;
    let started = Instant::now();
    let until = started + PHASE;
    let mut tasks = tokio::task::JoinSet::new();
    for (id, client) in built.into_iter().enumerate() {
        match client {
            None => tasks.spawn(lean::client_loop(url.trim_start_matches("http://").to_owned(), until, id)),
            Some(client) => tasks.spawn(async move { Ok(client_loop(client, until, id).await) }),
        };
    }
    let (mut latencies, mut errors) = (Vec::new(), 0);
    while let Some(done) = tasks.join_next().await {
        let (l, e) = done.context("a client task failed")??;
        latencies.extend(l);
        errors += e;
    }
    let took = started.elapsed();
    let mut kinds = [(Duration::ZERO, Duration::ZERO); KINDS.len()];
    for (k, figures) in kinds.iter_mut().enumerate() {
        let mut of_kind: Vec<Duration> = latencies.iter().filter(|(kind, _)| *kind == k).map(|(_, l)| *l).collect();
        of_kind.sort();
        *figures = (quantile(&of_kind, 0.5), quantile(&of_kind, 0.99));
    }
    let mut all: Vec<Duration> = latencies.into_iter().map(|(_, l)| l).collect();
    all.sort();
    Ok(Figures {
        per_second: all.len() as f64 / took.as_secs_f64(),
        p50: quantile(&all, 0.5),
        p99: quantile(&all, 0.99),
        errors,
        kinds,
    })
}

/// Rounds of the side-by-side load comparison (builds rotated each round).
const ROUNDS: usize = 3;

/// The mixed workload at 50 and 200 clients against a process of each guest build of
/// `ARENA_BENCH_GUESTS`, all started alike, in interleaved rounds; every round's row
/// and each build's median round (by p99) are printed.
async fn side_by_side(builds: &[(String, std::path::PathBuf)]) -> anyhow::Result<()> {
    println!(
        "side by side, guest processes ({ROUNDS} rounds of {} s per phase, builds rotated; clients on one thread of their own):",
        PHASE.as_secs()
    );
    let extra = ["--computer-action-delay-ms", "0", "--max-connections", "1024"];
    let served: Vec<arena_test_support::Served> = builds
        .iter()
        .map(|(label, exe)| {
            arena_test_support::Served::guest_of(exe, &extra).with_context(|| format!("starting the {label} guest"))
        })
        .collect::<anyhow::Result<_>>()?;
    for (driver, clients) in [(Driver::Host, 50), (Driver::Host, 200), (Driver::Lean, 50), (Driver::Lean, 200)] {
        let how = driver.name();
        let mut rounds = vec![Vec::new(); builds.len()];
        for round in 0..ROUNDS {
            for i in 0..builds.len() {
                let b = (i + round) % builds.len();
                let figures = measure(&served[b].url, clients, driver).await?;
                figures.print(&format!("{}: {clients} {how}, round {}", builds[b].0, round + 1));
                rounds[b].push(figures);
            }
        }
        for ((label, _), mut figures) in builds.iter().zip(rounds) {
            figures.sort_by_key(|f| f.p99);
            let median = figures[figures.len() / 2];
            median.print(&format!("{label}: {clients} {how}, median"));
            median.print_kinds();
        }
    }
    Ok(())
}

async fn run() -> anyhow::Result<()> {
    let builds = arena_test_support::bench_guests()?;
    if !builds.is_empty() {
        // The clients on a thread and runtime of their own (see the module's notes).
        tokio::task::spawn_blocking(move || {
            tokio::runtime::Builder::new_current_thread().enable_all().build()?.block_on(side_by_side(&builds))
        })
        .await
        .context("the side-by-side thread failed")??;
    }
    if std::env::args().nth(1).as_deref() == Some("side-by-side") {
        return Ok(());
    }
    if std::env::args().nth(1).as_deref() != Some("guards") {
        load().await?;
    }
    guards::probe_cases().await?;
    guards::lockout().await
}

/// The load, memory and bomb figures of the in-process guest.
async fn load() -> anyhow::Result<()> {
    let stub = arena_test_support::StubGuest::start().await;
    let url = stub.url().to_owned();
    println!("arena load bench: stub guest on {url} (in-process server, real HTTP on loopback)");
    println!("resident memory at start: {}", mib(memory("VmRSS:")));
    phase(&url, "mixed workload, 50 concurrent clients", 50).await?;
    phase(&url, "mixed workload, 200 concurrent clients", 200).await?;

    // 500 connections that send half a request and wait, as a slow-loris client does.
    let addr = url.trim_start_matches("http://").to_owned();
    let mut slow = Vec::new();
    for _ in 0..500 {
        let mut stream = tokio::net::TcpStream::connect(&addr).await.context("connecting a slow client")?;
        stream.write_all(b"GET /v1/screen HTTP/1.1\r\nhost: 127.0.0.1\r\n").await?;
        slow.push(stream);
    }
    phase(&url, "50 clients while 500 connections hang", 50).await?;
    drop(slow);

    println!("resident memory after the load: peak {}, now {}", mib(memory("VmHWM:")), mib(memory("VmRSS:")));

    // Six PNG bombs at once: headers claiming 60 000 x 60 000 pixels, sent as clipboard images.
    let before = memory("VmRSS:");
    let bomb = arena_test_support::png_claiming(60_000, 60_000, 8, 6);
    let image = arena_shared::clipboard::ClipboardContent::Image {
        width: 60_000,
        height: 60_000,
        png_base64: base64::Engine::encode(&base64::engine::general_purpose::STANDARD, &bomb),
    };
    let mut bombs = tokio::task::JoinSet::new();
    for _ in 0..6 {
        let client =
            GuestClient::new(&url, ClientConfig { token: None, timeout: Duration::from_secs(30), retries: 0 })?;
        let image = image.clone();
        bombs.spawn(async move { client.clipboard_set(&image).await.is_err() });
    }
    let mut refused = 0;
    while let Some(done) = bombs.join_next().await {
        refused += usize::from(done.context("a bomb task failed")?);
    }
    println!(
        "6 concurrent PNG bombs (60000x60000 claimed) as clipboard images: {refused} of 6 refused, resident memory {} -> {}",
        mib(before),
        mib(memory("VmRSS:"))
    );

    // A 1 GiB file (sparse on disk) read through GET /v1/files, counted as it streams.
    let big = stub.root().join("C/Users/Docker/Downloads/big.bin");
    std::fs::File::create(&big)?.set_len(1 << 30)?;
    let before = memory("VmRSS:");
    let started = Instant::now();
    let read = reqwest::get(format!("{url}/v1/files?path=C:%5CUsers%5CDocker%5CDownloads%5Cbig.bin")).await?;
    let mut body = read.bytes_stream();
    let mut total = 0usize;
    while let Some(chunk) = futures_util::StreamExt::next(&mut body).await {
        total += chunk?.len();
    }
    println!(
        "1 GiB file read: {total} bytes in {:.1} s, resident memory {} -> {} (peak {})",
        started.elapsed().as_secs_f64(),
        mib(before),
        mib(memory("VmRSS:")),
        mib(memory("VmHWM:"))
    );

    // 1023 MiB of it (the body limit is 1 GiB, multipart framing included) sent to
    // upstream's upload route as a file part streamed from disk by the client: the
    // guest spools it to a temporary file, not to memory.
    const UPLOAD: u64 = (1 << 30) - (1 << 20);
    let before = memory("VmRSS:");
    let started = Instant::now();
    let source = tokio::io::AsyncReadExt::take(tokio::fs::File::open(&big).await?, UPLOAD);
    let part = reqwest::multipart::Part::stream_with_length(
        reqwest::Body::wrap_stream(tokio_util::io::ReaderStream::new(source)),
        UPLOAD,
    )
    .file_name("big.bin");
    let form = reqwest::multipart::Form::new()
        .text("file_path", r"C:\Users\Docker\Downloads\uploaded.bin")
        .part("file_data", part);
    let answer = reqwest::Client::new().post(format!("{url}/setup/upload")).multipart(form).send().await?;
    let status = answer.status();
    let text = answer.text().await.unwrap_or_default();
    let stored = std::fs::metadata(stub.root().join("C/Users/Docker/Downloads/uploaded.bin")).map_or(0, |m| m.len());
    println!(
        "1023 MiB /setup/upload: {status} {:?}, {stored} bytes stored in {:.1} s, resident memory {} -> {} (peak {})",
        text.chars().take(80).collect::<String>(),
        started.elapsed().as_secs_f64(),
        mib(before),
        mib(memory("VmRSS:")),
        mib(memory("VmHWM:"))
    );

    tokio::time::sleep(Duration::from_secs(2)).await;
    println!("resident memory settled (2 s after the last request): {}", mib(memory("VmRSS:")));
    drop(stub);
    Ok(())
}
