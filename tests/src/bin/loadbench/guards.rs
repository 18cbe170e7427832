//! The guards section of `loadbench`: the probe's hostile requests of issue 25 and the
//! two lockout scenarios, against real guest processes (stub backend, loopback), each
//! case on a fresh process so that its peak resident memory is its own.
//!
//! With `ARENA_LOADBENCH_BASELINE=<path of an older arena-guest>` every case runs on
//! that build too, and the two are printed side by side ("before" and "after");
//! `ARENA_LOADBENCH_GUEST=<path>` names the "after" build (by default this tree's
//! debug build), so two release builds can be compared.
//!
//! Lockout scenarios, each for [`LOCKOUT`] with a legitimate client making one request
//! at a time on a fresh connection (a client whose pooled connection was opened before
//! the attack would not notice it):
//! - slow body: [`ATTACKERS`] connections send a request head with
//!   `Content-Length: 1000000`, then one body byte every 5 s (no token configured);
//! - reconnecting idle: [`ATTACKERS`] connections send nothing and reconnect as soon as
//!   they are closed (a token configured; the legitimate client has it).
//!
//! The guests serve at most [`SLOTS`] connections, fewer than the attackers.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use arena_test_support::Served;
use tokio::io::AsyncWriteExt as _;

/// How long each lockout scenario runs.
const LOCKOUT: Duration = Duration::from_secs(30);
/// Connection slots of the guests under attack.
const SLOTS: usize = 256;
/// Attacking connections, more than the slots.
const ATTACKERS: usize = 300;
/// The token of the scenario that has one.
const TOKEN: &str = "loadbench-token-0123456789";
/// Bytes of the oversize bodies (the probe sent 900 MiB; this keeps the bench's own memory modest).
const BIG: usize = 200 << 20;

/// The first word of a `/proc/<pid>/status` field of `pid` (Linux).
fn status_field(pid: u32, field: &str) -> Option<String> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let line = status.lines().find(|l| l.starts_with(field))?;
    Some(line[field.len()..].split_whitespace().next()?.to_owned())
}

/// A `/proc/<pid>/status` memory field of `pid` in MiB (Linux).
fn memory_of(pid: u32, field: &str) -> Option<f64> {
    let kb: f64 = status_field(pid, field)?.parse().ok()?;
    Some(kb / 1024.0)
}

fn mib(value: Option<f64>) -> String {
    value.map_or_else(|| "unknown".to_owned(), |v| format!("{v:.0} MiB"))
}

/// The builds to compare: the baseline, when given, and this one.
fn builds() -> anyhow::Result<Vec<(&'static str, PathBuf)>> {
    let mut builds = Vec::new();
    if let Some(baseline) = std::env::var_os("ARENA_LOADBENCH_BASELINE") {
        builds.push(("before", PathBuf::from(baseline)));
    }
    // ARENA_LOADBENCH_GUEST: this build as a release binary (the debug build is the default).
    let after = match std::env::var_os("ARENA_LOADBENCH_GUEST") {
        Some(path) => PathBuf::from(path),
        None => arena_test_support::workspace_binary("arena-guest", "arena-guest")?,
    };
    builds.push(("after", after));
    Ok(builds)
}

/// Address space each guest may map: a build that grows without bound (the baseline
/// on the probe's programs) dies at this cap instead of taking the machine's memory.
const ADDRESS_SPACE: &str = "8589934592";

/// Starts `exe` with the stub backend on a free loopback port, with `extra` options,
/// under `prlimit --as` (util-linux) when it is installed.
fn start(exe: &Path, extra: &[&str]) -> anyhow::Result<Served> {
    let root = tempfile::tempdir().context("creating the stub root")?;
    let root_path = root.path().to_str().context("non-UTF-8 temp path")?.to_owned();
    let exe_arg = exe.to_str().context("non-UTF-8 guest path")?.to_owned();
    let cap = format!("--as={ADDRESS_SPACE}");
    let mut args = vec!["--backend", "stub", "--port", "0", "--stub-root", &root_path];
    args.extend_from_slice(extra);
    match arena_shared::search_path::find_program(Path::new("prlimit")) {
        Some(prlimit) => {
            let mut capped = vec![cap.as_str(), "--", exe_arg.as_str()];
            capped.extend_from_slice(&args);
            Served::start(&prlimit, &capped, Some(root))
        }
        None => Served::start(exe, &args, Some(root)),
    }
}

/// Whether `pid` is running (not gone, not a zombie waiting to be reaped; Linux).
fn alive(pid: u32) -> bool {
    status_field(pid, "State:").is_some_and(|state| state != "Z")
}

/// CPU seconds `pid` has used (user and system; Linux).
fn cpu_seconds(pid: u32) -> Option<f64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // The fields after the command name, which is in parentheses and may hold spaces.
    let rest = stat.rsplit_once(')')?.1;
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let ticks: f64 = fields.get(11)?.parse::<f64>().ok()? + fields.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0)
}

/// One hostile request: its answer's status (or what happened instead), the time to
/// it, and the guest's peak resident memory.
async fn probe_case(exe: &Path, request: &(dyn Fn(&str) -> reqwest::RequestBuilder + Sync)) -> anyhow::Result<String> {
    let guest = start(exe, &["--exec-timeout-ms", "10000"])?;
    // The peak as sampled while the request runs: a guest that dies has none to read after.
    let pid = guest.pid();
    let sampling = Arc::new(AtomicBool::new(true));
    let sampler = tokio::spawn({
        let sampling = Arc::clone(&sampling);
        async move {
            let mut peak = None;
            while sampling.load(Ordering::Relaxed) {
                peak = memory_of(pid, "VmHWM:").or(peak);
                tokio::time::sleep(Duration::from_millis(50)).await;
            }
            peak
        }
    });
    let started = Instant::now();
    let outcome = match request(&guest.url).timeout(Duration::from_secs(40)).send().await {
        Ok(answer) => {
            let status = answer.status().as_u16();
            let body = answer.bytes().await.map(|b| b.len()).unwrap_or(0);
            format!("{status} ({body} B)")
        }
        Err(err) if err.is_timeout() => "no answer in 40 s".to_owned(),
        Err(_) if !alive(guest.pid()) => "the guest died".to_owned(),
        // The guest answered (or closed) before taking the whole body.
        Err(_) => "closed while sending".to_owned(),
    };
    let took = started.elapsed();
    // Work that goes on after the answer (typing, decoding, a program past its deadline)
    // shows in the peak and in the CPU used over the next two seconds.
    let cpu_then = cpu_seconds(guest.pid());
    tokio::time::sleep(Duration::from_secs(2)).await;
    let after = match (cpu_then, cpu_seconds(guest.pid())) {
        (Some(then), Some(now)) => format!("{:>4.0}%", (now - then) / 2.0 * 100.0),
        _ => "gone".to_owned(),
    };
    sampling.store(false, Ordering::Relaxed);
    let sampled = sampler.await.ok().flatten();
    let peak = memory_of(guest.pid(), "VmHWM:").or(sampled);
    Ok(format!("{outcome:<22} {:>7.2} s  peak RSS {:>9}  CPU after the answer {after}", took.as_secs_f64(), mib(peak)))
}

/// A gray 16384 x 16000 PNG (the probe's bomb: 250 KB of file, 1000 MiB as RGBA).
fn gray_bomb() -> anyhow::Result<Vec<u8>> {
    use image::ImageEncoder as _;
    let pixels = vec![0u8; 16_384 * 16_000];
    let mut png = Vec::new();
    image::codecs::png::PngEncoder::new_with_quality(
        &mut png,
        image::codecs::png::CompressionType::Best,
        image::codecs::png::FilterType::NoFilter,
    )
    .write_image(&pixels, 16_384, 16_000, image::ExtendedColorType::L8)
    .context("encoding the gray bomb")?;
    Ok(png)
}

/// The probe's cases, on each build.
pub(crate) async fn probe_cases() -> anyhow::Result<()> {
    let builds = builds()?;
    let client = reqwest::Client::builder().pool_max_idle_per_host(0).build()?;
    let bomb = gray_bomb()?;
    let bomb_json = serde_json::json!({
        "kind": "image", "width": 16_384, "height": 16_000,
        "png_base64": base64::Engine::encode(&base64::engine::general_purpose::STANDARD, &bomb),
    })
    .to_string();
    let typing = format!(r#"{{"actions": [{{"type": "type_text", "text": "{}"}}]}}"#, "x".repeat(BIG));
    let title = format!(r#"{{"title": "{}"}}"#, "t".repeat(BIG));
    let waits =
        serde_json::json!({"actions": vec![serde_json::json!({"type": "wait", "ms": 60_000}); 1000]}).to_string();
    let filler = "x".repeat(BIG);
    println!();
    println!(
        "issue 25 probe cases (each on a fresh stub guest with --exec-timeout-ms 10000 under an 8 GiB address-space cap;"
    );
    println!("status, time to the answer, the guest's peak RSS, the CPU it used in the 2 s after answering):");
    type Case<'a> = (&'a str, Box<dyn Fn(&str) -> reqwest::RequestBuilder + Sync + 'a>);
    let json = |method: reqwest::Method, path: &'static str, body: &str| {
        let body = body.to_owned();
        let client = client.clone();
        Box::new(move |url: &str| {
            client
                .request(method.clone(), format!("{url}{path}"))
                .header("content-type", "application/json")
                .body(body.clone())
        }) as Box<dyn Fn(&str) -> reqwest::RequestBuilder + Sync>
    };
    // The probe's programs, through `/execute` as upstream's host sends them (`python -c`).
    let program = |code: &str| serde_json::json!({"command": ["python", "-c", code], "shell": false}).to_string();
    let cases: Vec<Case<'_>> = vec![
        ("x = ['a'*10**6] * 10**6", json(reqwest::Method::POST, "/execute", &program("x = ['a' * 10**6] * 10**6"))),
        ("x = [[0]*10**6] * 10**6", json(reqwest::Method::POST, "/execute", &program("x = [[0] * 10**6] * 10**6"))),
        (
            "s = 'a'*3000, 99999 times",
            json(reqwest::Method::POST, "/execute", &program("for i in range(99999):\n    s = 'a' * 3000")),
        ),
        (
            "d[i] = i, 99999 times",
            json(reqwest::Method::POST, "/execute", &program("d = {}\nfor i in range(99999):\n    d[i] = i")),
        ),
        (
            "x.reverse() of 999999 items, 99999 times",
            json(
                reqwest::Method::POST,
                "/execute",
                &program("x = list(range(999999))\nfor i in range(99999):\n    x.reverse()"),
            ),
        ),
        ("gray PNG bomb as clipboard image", json(reqwest::Method::PUT, "/v1/clipboard", &bomb_json)),
        ("type_text of 200 MiB", json(reqwest::Method::POST, "/v1/actions", &typing)),
        ("window title of 200 MiB", json(reqwest::Method::POST, "/v1/windows/activate", &title)),
        ("200 MiB to /v1/browser/json/new, no browser", json(reqwest::Method::POST, "/v1/browser/json/new", &filler)),
        ("1000 waits of 60 s", json(reqwest::Method::POST, "/v1/actions", &waits)),
        (
            "DELETE /v1/files?path=/&recursive=true",
            Box::new(|url: &str| client.delete(format!("{url}/v1/files?path=/&recursive=true"))),
        ),
        (
            "POST /setup/recycle {\"path\": \"/Users\"}",
            json(reqwest::Method::POST, "/setup/recycle", r#"{"path": "/Users"}"#),
        ),
    ];
    for (name, request) in &cases {
        for (build, exe) in &builds {
            println!("  {name:<44} {build:<6} {}", probe_case(exe, request.as_ref()).await?);
        }
    }
    Ok(())
}

/// What a legitimate client got during one lockout scenario.
async fn legitimate_client(url: &str, token: Option<&str>, until: Instant) -> (usize, usize) {
    let Ok(client) = reqwest::Client::builder().pool_max_idle_per_host(0).timeout(Duration::from_secs(2)).build()
    else {
        return (0, 0);
    };
    let (mut ok, mut total) = (0, 0);
    while Instant::now() < until {
        let mut request = client.get(format!("{url}/v1/screen"));
        if let Some(token) = token {
            request = request.bearer_auth(token);
        }
        total += 1;
        match request.send().await {
            Ok(answer) if answer.status().is_success() => ok += 1,
            _ => tokio::time::sleep(Duration::from_millis(100)).await,
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    (ok, total)
}

/// One slow-body attacker: a request head, then a byte every 5 s until it is closed.
async fn trickle(addr: String, stop: Arc<AtomicBool>) {
    let Ok(mut stream) = tokio::net::TcpStream::connect(&addr).await else { return };
    let head = "POST /v1/actions HTTP/1.1\r\nhost: 127.0.0.1\r\ncontent-type: application/json\r\ncontent-length: 1000000\r\n\r\n{";
    if stream.write_all(head.as_bytes()).await.is_err() {
        return;
    }
    while !stop.load(Ordering::Relaxed) {
        tokio::time::sleep(Duration::from_secs(5)).await;
        if stream.write_all(b" ").await.is_err() {
            return;
        }
    }
}

/// One reconnecting idle attacker: connects, waits to be closed, connects again.
async fn idle(addr: String, stop: Arc<AtomicBool>) {
    use tokio::io::AsyncReadExt as _;
    while !stop.load(Ordering::Relaxed) {
        let Ok(mut stream) = tokio::net::TcpStream::connect(&addr).await else {
            tokio::time::sleep(Duration::from_millis(10)).await;
            continue;
        };
        let mut buf = [0u8; 1024];
        loop {
            tokio::select! {
                read = stream.read(&mut buf) => if matches!(read, Ok(0) | Err(_)) { break },
                () = tokio::time::sleep(Duration::from_millis(500)) => if stop.load(Ordering::Relaxed) { return },
            }
        }
    }
}

/// The two lockout scenarios, on each build.
pub(crate) async fn lockout() -> anyhow::Result<()> {
    let builds = builds()?;
    let slots = SLOTS.to_string();
    println!();
    println!(
        "lockout scenarios ({ATTACKERS} attacking connections, {SLOTS} slots, {} s each; a legitimate client, one request at a time):",
        LOCKOUT.as_secs()
    );
    for scenario in ["slow body, no token", "reconnecting idle, token"] {
        for (build, exe) in &builds {
            let token = scenario.ends_with("token").then_some(TOKEN);
            let mut extra = vec!["--max-connections", slots.as_str()];
            if let Some(token) = token {
                extra.extend_from_slice(&["--token", token]);
            }
            let guest = start(exe, &extra)?;
            let addr = guest.url.trim_start_matches("http://").to_owned();
            let stop = Arc::new(AtomicBool::new(false));
            let mut attackers = tokio::task::JoinSet::new();
            for _ in 0..ATTACKERS {
                if token.is_some() {
                    attackers.spawn(idle(addr.clone(), stop.clone()));
                } else {
                    attackers.spawn(trickle(addr.clone(), stop.clone()));
                }
            }
            tokio::time::sleep(Duration::from_millis(500)).await;
            let (ok, total) = legitimate_client(&guest.url, token, Instant::now() + LOCKOUT).await;
            stop.store(true, Ordering::Relaxed);
            attackers.abort_all();
            println!(
                "  {scenario:<28} {build:<6} legitimate client: {ok:>3} OK of {total:>3} requests; guest peak RSS {}",
                mib(memory_of(guest.pid(), "VmHWM:"))
            );
        }
    }
    Ok(())
}
