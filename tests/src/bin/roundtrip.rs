//! `roundtrip`: measures loopback round trips between the host client and a
//! stub guest, and prints the figures.
//!
//! The guest runs in this process (the `arena_guest` library serving a real
//! TCP listener on 127.0.0.1), and every call goes through the real
//! `GuestClient` over HTTP, so the figures include HTTP, JSON, the backend
//! call on the blocking pool and, for screenshots, rendering and PNG encoding.
//! Run it in release mode: `cargo run --release -p arena-tests --bin roundtrip`.

#![forbid(unsafe_code)]

use std::process::ExitCode;
use std::time::{Duration, Instant};

use anyhow::Context;
use arena_client::client::{ClientConfig, GuestClient};
use arena_shared::action::Action;
use arena_shared::exec::LaunchRequest;
use arena_shared::observation::{A11yQuery, ImageFormat, ScreenshotQuery};

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

struct Stats {
    name: &'static str,
    samples: Vec<Duration>,
}

impl Stats {
    fn print(&mut self) {
        self.samples.sort();
        let n = self.samples.len();
        let pct = |p: f64| self.samples[((n as f64 - 1.0) * p).round() as usize];
        let mean = self.samples.iter().sum::<Duration>() / n as u32;
        println!(
            "{:<34} n={:<5} min={:>9.3} ms  p50={:>9.3} ms  p95={:>9.3} ms  mean={:>9.3} ms",
            self.name,
            n,
            ms(self.samples[0]),
            ms(pct(0.5)),
            ms(pct(0.95)),
            ms(mean)
        );
    }
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1000.0
}

async fn measure<F, Fut, T>(name: &'static str, warmup: usize, n: usize, mut f: F) -> anyhow::Result<Stats>
where
    F: FnMut() -> Fut,
    Fut: std::future::Future<Output = anyhow::Result<T>>,
{
    for _ in 0..warmup {
        f().await.with_context(|| format!("warming up {name}"))?;
    }
    let mut samples = Vec::with_capacity(n);
    for _ in 0..n {
        let start = Instant::now();
        f().await.with_context(|| format!("measuring {name}"))?;
        samples.push(start.elapsed());
    }
    Ok(Stats { name, samples })
}

async fn run() -> anyhow::Result<()> {
    // The one test launcher; the guest stops when `stub` is dropped at the end.
    let stub = arena_test_support::StubGuest::start().await;
    let url = stub.url().to_owned();

    let client = GuestClient::new(&url, ClientConfig { token: None, timeout: Duration::from_secs(30), retries: 0 })?;
    client
        .wait_ready(&arena_shared::health::Component::ALL, Duration::from_secs(30), Duration::from_millis(20))
        .await?;
    client.launch(&LaunchRequest { shell: None, argv: vec!["notepad".into()] }).await?;
    let raw = reqwest::Client::new();

    println!("arena round-trip bench: stub guest on {url} (in-process server, real HTTP on loopback)");
    let mut x = 0;
    let mut all = vec![
        measure("small action (move_to)", 50, 1000, || {
            x = (x + 7) % 1400;
            let action = Action::MoveTo { x, y: 300 };
            let client = &client;
            async move { Ok(client.act_one(action).await?) }
        })
        .await?,
        measure("WAA GET /probe (raw reqwest)", 50, 1000, || {
            let raw = &raw;
            let url = &url;
            async move { Ok(raw.get(format!("{url}/probe")).send().await?.bytes().await?) }
        })
        .await?,
        measure("screenshot 1440x900 PNG", 5, 60, || async {
            let shot = client.screenshot(&ScreenshotQuery::default()).await?;
            anyhow::ensure!(shot.meta.width == 1440 && shot.meta.height == 900, "unexpected size");
            Ok(shot.bytes.len())
        })
        .await?,
        measure("screenshot 1440x900 JPEG q80", 5, 60, || async {
            let query = ScreenshotQuery { format: ImageFormat::Jpeg, quality: Some(80), ..ScreenshotQuery::default() };
            Ok(client.screenshot(&query).await?.bytes.len())
        })
        .await?,
        measure("screenshot PNG downscaled to 720", 5, 60, || async {
            let query = ScreenshotQuery { max_side: Some(720), ..ScreenshotQuery::default() };
            Ok(client.screenshot(&query).await?.bytes.len())
        })
        .await?,
        measure("accessibility tree (uia, json)", 10, 300, || async {
            Ok(client.a11y(&A11yQuery::default()).await?.node_count)
        })
        .await?,
        measure("push+pull 1 MiB with sha256", 3, 50, || async {
            let bytes = vec![0x5a_u8; 1 << 20];
            let path = r"C:\Users\Docker\Desktop\bench.bin";
            client.push_file(path, bytes, Some(true)).await?;
            Ok(client.pull_file(path).await?.bytes.len())
        })
        .await?,
    ];
    for stats in &mut all {
        stats.print();
    }
    let png = client.screenshot(&ScreenshotQuery::default()).await?;
    println!("PNG size of one 1440x900 stub frame: {} bytes", png.bytes.len());

    drop(stub);
    Ok(())
}
