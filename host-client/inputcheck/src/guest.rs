//! The check as `arena doctor --input` runs it against one guest: the recorder and its
//! log where the guest's backend has them unless told otherwise, every action space
//! unless told which, and each case's steps carried out by the host's own executor
//! ([`Executor`], `arena_exec::perform_steps` with an episode's options), so what is
//! checked is what an agent's action does.

use std::time::Duration;

use arena_actionspace::{ActionSpace, Step};
use arena_client::GuestClient;
use arena_exec::{perform_steps, ExecOptions};

use crate::catalogue::Catalogue;
use crate::drive::{default_log, default_recorder, run_check, CheckError, CheckOptions, Report, StepRunner};

/// What `arena doctor --input` was asked for; `None` and empty mean the defaults.
#[derive(Debug, Clone)]
pub struct GuestCheck {
    /// The recorder's program in the guest (default: [`default_recorder`] of the
    /// guest's backend).
    pub recorder: Option<String>,
    /// The log's path in the guest (default: [`default_log`]).
    pub log: Option<String>,
    /// The action spaces, in order (default: every one).
    pub spaces: Vec<ActionSpace>,
    /// Only these cases (default: all).
    pub only: Vec<String>,
    /// How long to wait for the recorder's window and for its log.
    pub wait: Duration,
}

impl Default for GuestCheck {
    fn default() -> GuestCheck {
        GuestCheck { recorder: None, log: None, spaces: Vec::new(), only: Vec::new(), wait: Duration::from_secs(30) }
    }
}

/// The host's executor as a [`StepRunner`]: [`perform_steps`] with `options`.
pub struct Executor<'a> {
    pub client: &'a GuestClient,
    pub options: ExecOptions,
}

impl std::fmt::Debug for Executor<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Executor").finish_non_exhaustive()
    }
}

#[async_trait::async_trait]
impl StepRunner for Executor<'_> {
    async fn run(&self, steps: &[Step]) -> Result<(), String> {
        let outcome = perform_steps(self.client, steps, &self.options).await.map_err(|err| err.to_string())?;
        outcome.error.map_or(Ok(()), Err)
    }
}

/// The options [`run_check`] gets for `check` on this guest: its defaults filled in.
///
/// # Errors
///
/// [`CheckError`] when the guest does not answer its health or names no temporary
/// folder for the log.
pub async fn resolve(client: &GuestClient, check: &GuestCheck) -> Result<CheckOptions, CheckError> {
    let recorder = match &check.recorder {
        Some(recorder) => recorder.clone(),
        None => {
            let health =
                client.health().await.map_err(|err| CheckError(format!("asking the guest for its health: {err}")))?;
            default_recorder(&health.backend).to_owned()
        }
    };
    let log = match &check.log {
        Some(log) => log.clone(),
        None => default_log(client).await?,
    };
    let spaces = if check.spaces.is_empty() { ActionSpace::ALL.to_vec() } else { check.spaces.clone() };
    Ok(CheckOptions { recorder, log, spaces, only: check.only.clone(), wait: check.wait })
}

/// Runs `catalogue` on the guest as `check` says, with the host's [`Executor`] and an
/// episode's timings ([`ExecOptions::default`]); the [`Report`] it answers is what
/// `arena doctor --input` prints.
///
/// # Errors
///
/// [`CheckError`] when the check cannot run (see [`run_check`] and [`resolve`]).
pub async fn check_guest(
    client: &GuestClient,
    catalogue: &Catalogue,
    check: &GuestCheck,
) -> Result<Report, CheckError> {
    let options = resolve(client, check).await?;
    let runner = Executor { client, options: ExecOptions::default() };
    run_check(client, &runner, catalogue, &options).await
}
