//! Running a task's setup steps (`config` and `evaluator.postconfig`) and
//! resetting the guest between episodes (`arena-setup`), with upstream WAA's
//! semantics but over the guest's native `/v1/` API.
//!
//! Upstream's host (`SetupController`) sends each step to a legacy route
//! (`/setup/launch`, `/setup/execute`, ...) and the guest does the work. Here
//! the host does what upstream's host *and* guest did together, one typed call
//! at a time: a `download` is fetched into the host's content-addressed cache
//! (`arena_client::cache`, which the getters share) and pushed as bytes, an `execute`
//! of `python -c <pyautogui code>` that is input alone is carried out by the
//! executor agents' actions go through (`arena_exec`, policy `InputOnly`), the browser
//! tab steps talk to the browser's DevTools HTTP
//! endpoint through the guest, and the browse-history steps build Chrome's
//! SQLite database on the host.
//!
//! Failures follow upstream: a failed step is logged and recorded in its
//! [`StepReport`] and the next step runs, except `download`, whose failure
//! aborts the rest ([`run_step`] answers `Err` for it). Pauses that upstream
//! sleeps go through [`Settle`], so tests run them at no cost.
//!
//! This crate is not the episode loop (`arena-host`'s `episode`) and does not evaluate.
//!
//! # Layout
//!
//! - `steps`: one function per step type, and [`run_step`]'s dispatch.
//! - `command`: command lines for `launch` and `execute` (pure, unit-tested).
//! - `cdp`: tab steps over the DevTools HTTP endpoint; [`compare_urls`].
//! - `outcome`: what one step did, shared by `steps` and `cdp` (so neither imports the other).
//! - [`history`] builds Chrome's `History` database.

#![forbid(unsafe_code)]

mod cdp;
mod command;
pub mod history;
mod outcome;
mod steps;

use std::path::PathBuf;
use std::time::{Duration, Instant};

use serde::Serialize;

use arena_shared::files::{FileKind, KnownFolder};

use arena_client::cache::{CacheError, DownloadCache};
use arena_client::client::GuestClient;
use arena_client::error::ClientError;
use arena_task::SetupStep;

pub use cdp::compare_urls;

/// How long [`reset`] waits for the guest's staged health (upstream polls `/probe` 20 × 5 s).
const READY_WAIT: Duration = Duration::from_secs(100);
/// How often [`reset`] polls the guest's health.
const READY_POLL: Duration = Duration::from_millis(250);

/// A setup step or reset could not be done in a way that must stop the episode's setup.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SetupError {
    /// A file could not be downloaded and is not in the cache. Names the URL.
    #[error("download of {url} failed: {reason}")]
    Download { url: String, reason: String },
    /// The download cache on the host could not be read or written.
    #[error("download cache {}: {reason}", path.display())]
    Cache { path: PathBuf, reason: String },
    /// A guest call that reset depends on failed.
    #[error(transparent)]
    Guest(#[from] ClientError),
}

impl From<CacheError> for SetupError {
    fn from(err: CacheError) -> SetupError {
        match err {
            CacheError::Download { url, reason } => SetupError::Download { url, reason },
            CacheError::Cache { path, reason } => SetupError::Cache { path, reason },
            other => SetupError::Cache { path: PathBuf::new(), reason: other.to_string() },
        }
    }
}

/// Scales the pauses upstream sleeps (after opening a file, between the steps of
/// a strict window activation, between `until` retries and browser connection
/// attempts, the pauses of the reset, and `sleep` steps themselves).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settle {
    /// Multiplies every pause; 1.0 is upstream's timing, 0.0 skips them all.
    pub factor: f64,
    /// No pause lasts longer than this, whatever the factor.
    pub max_pause: Option<Duration>,
}

impl Settle {
    /// Upstream's timing: every pause as long as upstream's.
    pub fn upstream() -> Settle {
        Settle { factor: 1.0, max_pause: None }
    }

    /// No pauses at all, for tests against the stub (which needs none).
    pub fn none() -> Settle {
        Settle { factor: 0.0, max_pause: Some(Duration::ZERO) }
    }

    /// Upstream's pauses, each cut to at most `max`.
    pub fn capped(max: Duration) -> Settle {
        Settle { factor: 1.0, max_pause: Some(max) }
    }

    /// How long a pause upstream makes `d` lasts under this policy.
    pub fn scale(&self, d: Duration) -> Duration {
        let factor = if self.factor.is_finite() && self.factor > 0.0 { self.factor } else { 0.0 };
        let scaled = Duration::try_from_secs_f64(d.as_secs_f64() * factor).unwrap_or(Duration::MAX);
        match self.max_pause {
            Some(max) => scaled.min(max),
            None => scaled,
        }
    }

    /// Sleeps for the scaled `d`.
    pub async fn pause(&self, d: Duration) {
        let d = self.scale(d);
        if !d.is_zero() {
            tokio::time::sleep(d).await;
        }
    }
}

impl Default for Settle {
    fn default() -> Settle {
        Settle::upstream()
    }
}

/// Everything a step needs.
#[derive(Debug, Clone)]
pub struct SetupContext {
    pub client: GuestClient,
    pub cache: DownloadCache,
    /// Per-task host folder where `execute` writes its `stdout`/`stderr` files.
    pub host_dir: PathBuf,
    pub settle: Settle,
    /// Bring the window of a non-strict `activate_window` to the front. Off by
    /// default: upstream's non-strict activation does nothing (its code is
    /// commented out), and 33 corpus steps rely on that. `--activate-non-strict`.
    pub activate_non_strict: bool,
}

/// What one step did, for the trajectory.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct StepReport {
    /// The step type (`command` reads as `execute`).
    pub kind: &'static str,
    /// Whether it did what it should; upstream would have logged an error otherwise.
    pub ok: bool,
    /// What happened, in a line or a few: the command run, the window found, the error.
    pub detail: String,
    pub elapsed_ms: u64,
}

/// Runs one step.
///
/// A step that fails as upstream would only log is an `Ok` report with `ok: false`.
///
/// # Errors
///
/// [`SetupError::Download`] (or [`SetupError::Cache`]) when a `download` step
/// cannot get its file: upstream raises there, and the remaining steps must not run.
pub async fn run_step(ctx: &SetupContext, step: &SetupStep) -> Result<StepReport, SetupError> {
    let started = Instant::now();
    let kind = step.kind();
    let outcome = steps::run(ctx, step).await?;
    let elapsed_ms = u64::try_from(started.elapsed().as_millis()).unwrap_or(u64::MAX);
    if outcome.ok {
        tracing::info!(step = kind, elapsed_ms, detail = %outcome.detail, "setup step done");
    } else {
        tracing::warn!(step = kind, elapsed_ms, detail = %outcome.detail, "setup step failed");
    }
    Ok(StepReport { kind, ok: outcome.ok, detail: outcome.detail, elapsed_ms })
}

/// Runs `steps` in order, as upstream's `SetupController.setup` does: a failed
/// step is recorded and the next one runs. A step that answers `Err` (a
/// `download` that cannot get its file) is recorded with `ok: false` and a
/// detail starting with `aborted:`, and no further step runs, so fewer reports
/// than steps means setup was aborted.
pub async fn run_steps(ctx: &SetupContext, steps: &[SetupStep]) -> Vec<StepReport> {
    let mut reports = Vec::with_capacity(steps.len());
    for step in steps {
        let started = Instant::now();
        match run_step(ctx, step).await {
            Ok(report) => reports.push(report),
            Err(err) => {
                tracing::error!(step = step.kind(), error = %err, "setup aborted");
                reports.push(StepReport {
                    kind: step.kind(),
                    ok: false,
                    detail: format!("aborted: {err}"),
                    elapsed_ms: u64::try_from(started.elapsed().as_millis()).unwrap_or(u64::MAX),
                });
                break;
            }
        }
    }
    reports
}

/// Whether `run_steps` stopped early: its last report is an abort.
pub fn aborted(reports: &[StepReport]) -> bool {
    reports.last().is_some_and(|r| !r.ok && r.detail.starts_with("aborted:"))
}

/// Where the episode's pauses go: the real clock, or a test's record of them.
#[async_trait::async_trait]
pub trait Clock: Send + Sync + std::fmt::Debug {
    /// Sleeps `d` (nothing for zero); `why` names the pause for a test's record.
    async fn sleep(&self, d: Duration, why: &'static str);
}

/// The real clock: `tokio::time::sleep`.
#[derive(Debug, Clone, Copy, Default)]
pub struct RealClock;

#[async_trait::async_trait]
impl Clock for RealClock {
    async fn sleep(&self, d: Duration, _why: &'static str) {
        if !d.is_zero() {
            tokio::time::sleep(d).await;
        }
    }
}

/// Upstream's `env.reset` sleeps this long after closing every window.
pub const AFTER_CLOSE_ALL: Duration = Duration::from_secs(5);
/// Upstream's `env.reset` sleeps this long after the task's setup, before the first observation.
pub const AFTER_SETUP: Duration = Duration::from_secs(5);

/// Resets the guest between episodes, as upstream's `env.reset` does: closes
/// every window (but the desktop, upstream's server console and the guest
/// server's own), pauses `pause` on `clock` (upstream: [`AFTER_CLOSE_ALL`]), waits until every component of the guest's staged health is
/// up (where upstream polls `/probe`), and removes
/// the files in Downloads (not folders, not dot-files, not `desktop.ini`).
///
/// Windows or files that refuse to go are logged, as upstream does, not errors.
///
/// # Errors
///
/// [`SetupError::Guest`] when the windows cannot be listed, the guest does not
/// become ready within 100 s, or Downloads cannot be found or listed.
pub async fn reset(client: &GuestClient, pause: Duration, clock: &dyn Clock) -> Result<(), SetupError> {
    close_all(client).await?;
    clock.sleep(pause, "after closing the windows").await;
    client.wait_ready(&[], READY_WAIT, READY_POLL).await?;
    clear_downloads(client).await?;
    Ok(())
}

/// Asks every visible window `close_all` does not spare to close; answers how many were asked.
pub(crate) async fn close_all(client: &GuestClient) -> Result<usize, ClientError> {
    let mut asked = 0;
    for window in client.windows().await? {
        // The guest's server process id is not known here; the rule spares it by name.
        if arena_shared::close_all::spares(&window, None) {
            continue;
        }
        let target = arena_shared::observation::WindowTarget { id: Some(window.id), title: None };
        match client.close_window(&target).await {
            Ok(_) => asked += 1,
            // A window that went away since the listing is as closed as it gets.
            Err(err) if err.status() == Some(404) => {}
            Err(err) => tracing::warn!(window = %window.title, error = %err, "close_all: a window did not close"),
        }
    }
    Ok(asked)
}

/// Whether upstream's `clear_task_files` removes this Downloads entry.
fn clears(name: &str, kind: FileKind) -> bool {
    kind != FileKind::Dir && !name.starts_with('.') && !name.eq_ignore_ascii_case("desktop.ini")
}

async fn clear_downloads(client: &GuestClient) -> Result<(), SetupError> {
    let folders = client.folders().await?;
    let Some((_, downloads)) = folders.folders.iter().find(|(folder, _)| *folder == KnownFolder::Downloads) else {
        tracing::warn!("the guest names no Downloads folder; nothing to clear");
        return Ok(());
    };
    let listing = client.list_dir(downloads).await?;
    for entry in listing.entries.iter().filter(|e| clears(&e.name, e.kind)) {
        let path = format!("{}\\{}", downloads.trim_end_matches(['\\', '/']), entry.name);
        if let Err(err) = client.delete(&path, false).await {
            tracing::warn!(%path, error = %err, "clearing Downloads: a file stayed");
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settle_scales_and_caps_pauses() {
        let five = Duration::from_secs(5);
        assert_eq!(Settle::upstream().scale(five), five);
        assert_eq!(Settle::none().scale(five), Duration::ZERO);
        assert_eq!(Settle::capped(Duration::from_millis(20)).scale(five), Duration::from_millis(20));
        assert_eq!(Settle { factor: 0.1, max_pause: None }.scale(five), Duration::from_millis(500));
        assert_eq!(Settle { factor: f64::NAN, max_pause: None }.scale(five), Duration::ZERO);
        assert_eq!(Settle { factor: 1e300, max_pause: None }.scale(five), Duration::MAX);
    }

    #[test]
    fn downloads_keep_folders_dot_files_and_desktop_ini() {
        assert!(clears("report.pdf", FileKind::File));
        assert!(!clears("sub", FileKind::Dir));
        assert!(!clears(".hidden", FileKind::File));
        assert!(!clears("desktop.ini", FileKind::File));
        assert!(!clears("Desktop.INI", FileKind::File));
    }

    #[test]
    fn an_abort_is_the_last_report() {
        let report = |ok, detail: &str| StepReport { kind: "download", ok, detail: detail.into(), elapsed_ms: 0 };
        assert!(aborted(&[report(true, "ok"), report(false, "aborted: download of u failed")]));
        assert!(!aborted(&[report(false, "Window x not found")]));
        assert!(!aborted(&[]));
    }
}
