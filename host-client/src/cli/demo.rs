//! `arena demo`: one command that shows the whole host-to-guest path working.
//!
//! Without `--guest` it starts an embedded stub guest on a free loopback
//! port; then it waits for readiness, launches Notepad, types a sentence,
//! reads it back from the accessibility tree, round-trips a file with SHA-256
//! checks, runs a command, saves a screenshot, and prints each step with its
//! timing. Once the guest is ready, every step runs even when an earlier one
//! failed, so one report shows everything that is broken; the exit code is
//! non-zero if any failed.
//!
//! It is not a benchmark episode: there is no task, agent or evaluator here.

use std::future::Future;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use anyhow::{bail, Context};
use clap::Args;

use arena_shared::action::Action;
use arena_shared::cmdline::CommandSpec;
use arena_shared::exec::{ExecRequest, LaunchRequest};
use arena_shared::files::KnownFolder;
use arena_shared::observation::{A11yNode, A11yQuery, ScreenshotQuery, WindowInfo, WindowTarget};

use super::{emit, local, render, with_spinner, Connection};
use crate::driver::stub;
use arena_client::client::GuestClient;

/// The sentence typed into Notepad and looked for in the tree.
const SENTENCE: &str = "The quick brown fox jumps over the lazy arena.";
/// What the demo command prints.
const GREETING: &str = "hello from arena";

/// Arguments of `arena demo` (plus the global `--guest`: without it a stub guest is started).
#[derive(Debug, Clone, Args)]
pub struct DemoArgs {
    /// Where to save the screenshot.
    #[arg(short, long, default_value = "arena-demo.png")]
    pub output: PathBuf,
    /// How long to wait for the guest to become ready, in seconds.
    #[arg(long, default_value = "60", value_parser = super::parse_seconds, value_name = "SECONDS")]
    pub ready_timeout: Duration,
}

/// One step's outcome.
#[derive(Debug, Clone)]
struct Step {
    name: &'static str,
    ok: bool,
    elapsed: Duration,
    detail: String,
}

#[derive(Debug, Default)]
struct Report {
    steps: Vec<Step>,
}

impl Report {
    /// Runs one step, recording its time and outcome; returns its value when it succeeded.
    async fn step<T>(
        &mut self,
        name: &'static str,
        work: impl Future<Output = anyhow::Result<(T, String)>>,
    ) -> Option<T> {
        let started = Instant::now();
        let outcome = with_spinner(name, work).await;
        let elapsed = started.elapsed();
        match outcome {
            Ok((value, detail)) => {
                tracing::info!(step = name, elapsed_ms = elapsed.as_millis() as u64, "demo step passed");
                self.steps.push(Step { name, ok: true, elapsed, detail });
                Some(value)
            }
            Err(err) => {
                tracing::debug!(step = name, error = format!("{err:#}"), "demo step failed");
                self.steps.push(Step { name, ok: false, elapsed, detail: format!("{err:#}") });
                None
            }
        }
    }

    fn render(&self, total: Duration) -> String {
        let rows: Vec<Vec<String>> = self
            .steps
            .iter()
            .map(|s| {
                vec![
                    s.name.to_owned(),
                    if s.ok { "ok" } else { "FAILED" }.to_owned(),
                    render::duration(s.elapsed),
                    s.detail.clone(),
                ]
            })
            .collect();
        let passed = self.steps.iter().filter(|s| s.ok).count();
        format!(
            "{}{passed}/{} steps passed in {}\n",
            render::table(&["STEP", "RESULT", "TIME", "DETAIL"], &rows),
            self.steps.len(),
            render::duration(total)
        )
    }

    fn all_ok(&self) -> bool {
        self.steps.iter().all(|s| s.ok)
    }
}

/// Runs the demo against `--guest`, or an embedded stub guest.
///
/// # Errors
///
/// Only for failures before any step runs (an unreadable token file); step
/// failures are reported in the table and the exit code.
pub async fn run(conn: &Connection, args: DemoArgs) -> anyhow::Result<ExitCode> {
    let started = Instant::now();
    let mut report = Report::default();
    let token = conn.resolve_token()?;

    let (url, stub) = match &conn.guest {
        Some(url) => (url.clone(), None),
        None => {
            let stub = report
                .step("start stub guest", async {
                    // No agent plays here: the demo's own `echo` is the one command it
                    // runs, so its stub runs real processes (`--stub-host-exec`).
                    let args = stub::StubArgs { stub_host_exec: true, ..stub::StubArgs::default() };
                    let stub = stub::start(&args, token.clone()).await?;
                    let detail = format!("listening on {}", stub.url());
                    Ok((stub, detail))
                })
                .await;
            match stub {
                Some(stub) => (stub.url(), Some(stub)),
                None => {
                    emit(&report.render(started.elapsed()))?;
                    return Ok(ExitCode::FAILURE);
                }
            }
        }
    };
    emit(&format!("arena demo against {url}{}\n", if stub.is_some() { " (embedded stub guest)" } else { "" }))?;
    let client = conn.client_for(&url)?;

    let backend = report
        .step("wait for readiness", async {
            let health = client.wait_ready(&[], args.ready_timeout, Duration::from_millis(200)).await?;
            let detail = format!("backend {}, {} components up", health.backend, health.components.len());
            Ok((health.backend, detail))
        })
        .await;
    // Without a ready guest every further step would only repeat the connection error.
    if backend.is_none() {
        finish(stub).await;
        emit(&report.render(started.elapsed()))?;
        return Ok(ExitCode::FAILURE);
    }

    report.step("launch notepad", launch_notepad(&client)).await;

    report
        .step("type a sentence", async {
            let done = client.act_one(Action::TypeText { text: SENTENCE.to_owned(), interval_ms: None }).await?;
            Ok(((), format!("{} characters, {} ms", SENTENCE.chars().count(), done.elapsed_ms)))
        })
        .await;

    report.step("read it back (a11y)", read_back(&client)).await;

    let pushed = report.step("push a file", push(&client)).await;

    report
        .step("pull it back", async {
            let Some((path, sent)) = pushed else { bail!("nothing was pushed") };
            let file = client.pull_file(&path).await?;
            if file.bytes != sent {
                bail!("pulled {} bytes that differ from the {} pushed", file.bytes.len(), sent.len());
            }
            Ok((
                (),
                format!("{} bytes, sha256 {} verified", file.bytes.len(), &file.sha256[..16.min(file.sha256.len())]),
            ))
        })
        .await;

    report
        .step("run a command", async {
            // A shell line: `echo` is a built-in of cmd.exe and of sh alike, so the same
            // request works whatever the guest runs on.
            let shown = format!("echo {GREETING}");
            let request =
                ExecRequest { timeout_ms: Some(30_000), ..ExecRequest::new(CommandSpec::Shell(shown.clone())) };
            let result = client.exec(&request).await?;
            if result.exit_code != Some(0) {
                bail!("`{shown}` exited with {:?}: {}", result.exit_code, result.stderr.trim());
            }
            if !result.stdout.contains(GREETING) {
                bail!("`{shown}` printed {:?}, not the greeting", result.stdout.trim());
            }
            Ok(((), format!("`{shown}` -> {:?} in {} ms", result.stdout.trim(), result.duration_ms)))
        })
        .await;

    report
        .step("take a screenshot", async {
            let shot = client.screenshot(&ScreenshotQuery::default()).await?;
            local::write_atomic(&args.output, &shot.bytes)?;
            Ok((
                (),
                format!(
                    "{}x{}, {} -> {}",
                    shot.meta.width,
                    shot.meta.height,
                    render::size(shot.bytes.len() as u64),
                    args.output.display()
                ),
            ))
        })
        .await;

    finish(stub).await;
    emit(&report.render(started.elapsed()))?;
    Ok(if report.all_ok() { ExitCode::SUCCESS } else { ExitCode::FAILURE })
}

async fn finish(stub: Option<stub::RunningStub>) {
    if let Some(stub) = stub {
        if let Err(err) = stub.stop().await {
            tracing::warn!(error = format!("{err:#}"), "stopping the stub guest");
        }
    }
}

fn is_notepad(window: &WindowInfo) -> bool {
    window.process_name.eq_ignore_ascii_case("notepad.exe") || window.title.to_lowercase().contains("notepad")
}

async fn launch_notepad(client: &GuestClient) -> anyhow::Result<((), String)> {
    let launched = client.launch(&LaunchRequest { shell: None, argv: vec!["notepad.exe".to_owned()] }).await?;
    // The window appears some time after the process starts: poll for it.
    let deadline = Instant::now() + Duration::from_secs(15);
    let window = loop {
        let windows = client.windows().await?;
        if let Some(window) = windows.into_iter().find(is_notepad) {
            break window;
        }
        if Instant::now() >= deadline {
            bail!("started pid {}, but no Notepad window appeared within 15 s", launched.pid);
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
    };
    let active = client.activate_window(&WindowTarget { id: Some(window.id), title: None }).await?;
    Ok(((), format!("pid {}, window {:?} focused", launched.pid, active.title)))
}

/// Finds a node whose value, text or name holds `needle`, depth first.
fn find_text<'a>(node: &'a A11yNode, needle: &str) -> Option<&'a A11yNode> {
    let holds = |s: Option<&str>| s.is_some_and(|s| s.contains(needle));
    if holds(node.value.as_deref()) || holds(node.text.as_deref()) || holds(Some(&node.name)) {
        return Some(node);
    }
    node.children.iter().find_map(|child| find_text(child, needle))
}

async fn read_back(client: &GuestClient) -> anyhow::Result<((), String)> {
    // Typing lands asynchronously on a real desktop: look a few times before giving up.
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        let tree = client.a11y(&A11yQuery { max_ms: Some(20_000), ..A11yQuery::default() }).await?;
        if let Some(node) = tree.windows.iter().find_map(|w| find_text(w, SENTENCE)) {
            return Ok((
                (),
                format!("found in {} {:?} ({} nodes, {} ms)", node.role, node.name, tree.node_count, tree.elapsed_ms),
            ));
        }
        if Instant::now() >= deadline {
            bail!(
                "the sentence is not in the accessibility tree ({} nodes, truncated: {})",
                tree.node_count,
                tree.truncated
            );
        }
        tokio::time::sleep(Duration::from_millis(300)).await;
    }
}

async fn push(client: &GuestClient) -> anyhow::Result<((String, Vec<u8>), String)> {
    let temp = client
        .folders()
        .await
        .ok()
        .and_then(|f| f.folders.into_iter().find(|(kind, _)| *kind == KnownFolder::Temp).map(|(_, path)| path))
        .unwrap_or_else(|| "~".to_owned());
    let path = format!("{}\\arena-demo\\hello.txt", temp.trim_end_matches(['\\', '/']));
    let stamp = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.as_millis()).unwrap_or(0);
    let bytes = format!("arena demo file\nwritten at {stamp} ms since the epoch\n{SENTENCE}\n").into_bytes();
    let written = client.push_file(&path, bytes.clone(), None).await.with_context(|| format!("pushing {path}"))?;
    let detail = format!("{} bytes -> {}", written.size, written.path);
    Ok(((path, bytes), detail))
}
