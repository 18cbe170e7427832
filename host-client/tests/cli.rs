//! The `arena` command line run through the library's [`arena_host::run`],
//! against embedded stub guests and a guest that never answers.

use std::process::ExitCode;
use std::time::Duration;

use clap::Parser;

use arena_host::driver::stub::{start, StubArgs};
use arena_host::Cli;

fn cli(words: &[&str]) -> Cli {
    let mut cli = Cli::try_parse_from(std::iter::once("arena").chain(words.iter().copied())).expect("arguments parse");
    // Keep a developer's ARENA_* environment out of the test's way.
    cli.connection.token = None;
    cli.connection.token_file = None;
    cli
}

#[tokio::test]
async fn demo_passes_against_its_own_stub_guest() {
    let dir = tempfile::tempdir().expect("temp dir");
    let shot = dir.path().join("demo.png");
    let mut demo = cli(&["demo", "-o", shot.to_str().expect("utf-8 path")]);
    demo.connection.guest = None;
    let code = arena_host::run(demo).await.expect("demo runs");
    assert_eq!(code, ExitCode::SUCCESS);
    let bytes = std::fs::read(&shot).expect("screenshot written");
    assert!(bytes.starts_with(b"\x89PNG"), "not a PNG");
}

#[tokio::test]
async fn push_then_pull_round_trips_through_local_files() {
    let stub = start(&StubArgs::default(), None).await.expect("stub");
    let url = stub.url();
    let dir = tempfile::tempdir().expect("temp dir");
    let up = dir.path().join("up.bin");
    let down = dir.path().join("down.bin");
    std::fs::write(&up, b"bytes through the cli").expect("write");
    let guest_path = r"C:\Users\Docker\cli\up.bin";

    let push = cli(&["push", "--guest", &url, up.to_str().expect("utf-8"), guest_path]);
    assert_eq!(arena_host::run(push).await.expect("push"), ExitCode::SUCCESS);
    let pull = cli(&["pull", "--guest", &url, guest_path, down.to_str().expect("utf-8")]);
    assert_eq!(arena_host::run(pull).await.expect("pull"), ExitCode::SUCCESS);
    assert_eq!(std::fs::read(&down).expect("pulled"), b"bytes through the cli");

    // A failed pull leaves the local file as it was.
    let missing = cli(&["pull", "--guest", &url, r"C:\Users\Docker\cli\absent.bin", down.to_str().expect("utf-8")]);
    let err = arena_host::run(missing).await.expect_err("absent");
    assert!(format!("{err:#}").contains("404 not_found"), "{err:#}");
    assert_eq!(std::fs::read(&down).expect("kept"), b"bytes through the cli");

    let health = cli(&["health", "--guest", &url]);
    assert_eq!(arena_host::run(health).await.expect("health"), ExitCode::SUCCESS);
    stub.stop().await.expect("stub stops");
}

#[tokio::test]
async fn doctor_reports_a_healthy_stub_and_exits_zero() {
    let stub = start(&StubArgs::default(), None).await.expect("stub");
    let url = stub.url();
    for words in [&["doctor", "--guest", &url][..], &["doctor", "--json", "--guest", &url][..]] {
        assert_eq!(arena_host::run(cli(words)).await.expect("doctor"), ExitCode::SUCCESS, "{words:?}");
    }
    let client = arena_client::GuestClient::new(&url, arena_client::ClientConfig::default()).expect("client");
    let report = client.doctor().await.expect("doctor report");
    assert!(report.passed(), "{}", report.render_text());
    assert!(report.check("notepad_typing").is_some(), "{}", report.render_text());
    assert!(report.deep.is_none());
    // `--deep`: the table of tree timings (the doctor's own Notepad at least) and round trips.
    let deep = cli(&["doctor", "--deep", "--guest", &url]);
    assert_eq!(arena_host::run(deep).await.expect("doctor --deep"), ExitCode::SUCCESS);
    let deep = client.doctor_deep().await.expect("deep report").deep.expect("the deep part");
    assert!(deep.trees.iter().any(|t| t.app == "Notepad" && t.source == "uia" && t.nodes > 0), "{deep:?}");
    assert!(deep.input.iter().all(|r| r.samples > 0), "{deep:?}");
    let table = deep.render_table();
    println!("{table}");
    assert!(table.contains("| Notepad |") && table.contains("| cursor moved and read back |"), "{table}");
    stub.stop().await.expect("stub stops");
}

/// A server that accepts connections and never answers, as a hung guest does.
async fn hung_guest() -> String {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.expect("bind");
    let url = format!("http://{}", listener.local_addr().expect("addr"));
    tokio::spawn(async move {
        let mut held = Vec::new();
        while let Ok((socket, _)) = listener.accept().await {
            held.push(socket);
        }
    });
    url
}

/// `arena health` against a hung guest ends within its wait plus one call's deadline,
/// however many retries the connection allows. Time is paused (tokio's test clock
/// jumps to the next timer when everything waits), so this measures the deadlines
/// the command sets, not the machine's speed.
#[tokio::test(start_paused = true)]
async fn health_against_a_hung_guest_ends_within_its_deadlines() {
    let url = hung_guest().await;
    let run = |args: &[&str]| {
        let mut argv = vec!["arena", "--guest", url.as_str(), "--timeout", "7", "--retries", "3", "health"];
        argv.extend_from_slice(args);
        arena_host::run(arena_host::Cli::parse_from(argv))
    };
    let started = tokio::time::Instant::now();
    let err = run(&["--wait", "2"]).await.expect_err("never ready");
    let waited = started.elapsed();
    assert!(waited <= Duration::from_secs(2 + 7), "--wait 2 took {waited:?}");
    let text = format!("{err:#}");
    assert!(text.contains("--timeout") && text.contains('7'), "{text}");

    let started = tokio::time::Instant::now();
    let err = run(&[]).await.expect_err("no answer");
    let waited = started.elapsed();
    assert!(waited <= Duration::from_secs(7), "one call of 7 s, no retries: took {waited:?}");
    assert!(format!("{err:#}").contains("--timeout"), "{err:#}");
}
