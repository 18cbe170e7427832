//! `arena run`, `arena merge` and `arena report`: benchmark runs from the command line.
//!
//! `run` loads a task folder or index, keeps its `--shard`, skips finished
//! tasks, spreads the rest over the guests (`--guest`, `--guests`,
//! `--guests-file`, or `--stub-guests N` embedded stub guests) with the chosen
//! agent, and writes upstream's result folders plus `summary.json`,
//! `summary.md` and `report.html` under `--out`. `merge` combines shard
//! folders; `report` rebuilds the summary and report of a folder.
//!
//! The global `--guest` names one guest; a pool is given with `--guests
//! URL,URL,...` (repeatable) or a file of URLs, one per line (`#` comments).
//! It is not the run machinery itself ([`crate::run`], [`crate::episode`]).

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Duration;

use anyhow::{bail, Context};
use clap::ValueEnum;

use super::preset::reproduction;
use super::run_args::{
    A11yBackendArg, CompareArgs, ComputerTool, HeldKeysArg, LlmApi, MergeArgs, NaviStyleArg, OrderArg, PausesArg,
    RefusalsArg, ReportArgs, RunArgs, UiTarsVersionArg,
};
use super::{emit, Connection};
use crate::driver::{self, GuestPlan, Guests, Played, Prepared, RunPlan, VmPlan};
use crate::run::TaskOrder;
use arena_actionspace::uitars::UiTarsVersion;
use arena_agents::factory::AgentOptions;
use arena_agents::llm::{ApiKind, Refusals};
use arena_agents::navi::NaviStyle;
use arena_results::html::write_report;
use arena_results::summary::Summary;
use tokio_util::sync::CancellationToken;

fn guests_from_file(path: &Path) -> anyhow::Result<Vec<String>> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading --guests-file {}", path.display()))?;
    Ok(text
        .lines()
        .map(|l| l.split('#').next().unwrap_or("").trim())
        .filter(|l| !l.is_empty())
        .map(str::to_owned)
        .collect())
}

impl RunArgs {
    /// What an exec agent must not see: the tasks (an index file's whole folder,
    /// which holds the corpus), the output and the download cache.
    fn hidden_from_agents(&self) -> Vec<PathBuf> {
        let tasks = if self.tasks.is_file() {
            self.tasks
                .parent()
                .filter(|p| !p.as_os_str().is_empty())
                .map_or_else(|| PathBuf::from("."), Path::to_path_buf)
        } else {
            self.tasks.clone()
        };
        let mut hidden = vec![tasks, self.out.clone()];
        hidden.extend(self.cache.clone());
        hidden
    }

    /// What these flags say about the agent, for [`arena_agents::factory::build`].
    pub fn agent_options(&self) -> AgentOptions {
        AgentOptions {
            kind: self.agent,
            tasks: self.tasks.clone(),
            plans: self.plans.clone(),
            replay: self.replay.clone(),
            llm_url: self.llm_url.clone(),
            model: self.model.clone(),
            temperature: self.temperature,
            max_tokens: self.max_tokens,
            navi_style: match self.navi_style {
                NaviStyleArg::Waa => NaviStyle::Waa,
                NaviStyleArg::Arena => NaviStyle::Arena,
            },
            som_origin: self.som_origin,
            detector_url: self.detector_url.clone(),
            omniparser_url: self.omniparser_url.clone(),
            waa_root: self.waa_root.clone(),
            refusals: match self.refusals {
                RefusalsArg::Unfinished => Refusals::Unfinished,
                RefusalsArg::Answer => Refusals::Answer,
            },
            llm_api: match self.llm_api {
                LlmApi::Auto => None,
                LlmApi::Openai => Some(ApiKind::OpenAi),
                LlmApi::Azure => Some(ApiKind::Azure),
            },
            llm_timeout: self.llm_timeout,
            llm_retry: self.llm_retry,
            model_down: arena_agents::llm::EndpointDown::new(self.llm_unreachable.policy()),
            coords: self.coords,
            computer_tool: self.computer_tool.map(ComputerTool::form),
            max_image_side: self.max_image_side,
            toolset_disable: self.toolset_disable.clone(),
            zoom: self.zoom,
            thinking_budget: self.thinking_budget,
            prompt_caching: !self.no_prompt_cache,
            keep_images: self.keep_images,
            safety_checks: self.safety_checks,
            prompt_file: self.prompt_file.clone(),
            uitars_version: match self.uitars_version {
                UiTarsVersionArg::V1 => UiTarsVersion::V1,
                UiTarsVersionArg::V1_5 => UiTarsVersion::V1_5,
            },
            agent_cmd: self.external.agent_cmd.clone(),
            agent_url: self.external.agent_url.clone(),
            agent_timeout: self.external.agent_timeout,
            sandbox: self.external.sandbox(self.hidden_from_agents()),
        }
    }
}

/// `arena run`.
///
/// # Errors
///
/// Unusable arguments, tasks that do not load, no guest, or results that cannot be written.
pub async fn run(conn: &Connection, args: RunArgs) -> anyhow::Result<ExitCode> {
    let prepared = prepare(&args).await?;
    let guests = start_guests(conn, &args).await?;
    let guest_count = guests.urls.len();
    let played = with_ctrl_c(prepared, &guests).await;
    guests.stop().await;
    let played = played?;
    let Played { outcome, interrupted, shard, model_down } = played;

    emit(&format!(
        "shard {}: {} task(s) run, {} already finished, {} episode(s) on {} guest(s)\n\n",
        shard, outcome.todo, outcome.skipped, outcome.pool.episodes, guest_count
    ))?;
    emit(&outcome.summary.markdown())?;
    emit(&format!("\nreport: {}\n", outcome.report.display()))?;
    let unfinished: Vec<&arena_results::EpisodeResult> =
        outcome.pool.results.iter().filter(|r| r.status.is_unfinished()).collect();
    let count = outcome.pool.not_run.len() + unfinished.len();
    if count > 0 {
        let mut lines =
            format!("{count} task(s) are unfinished (no result.txt); run the same command again to retry them:\n");
        for r in &unfinished {
            let why = r.status.message().unwrap_or_default();
            lines.push_str(&format!("  {}/{}: {}: {why}\n", r.domain, r.task_name, r.status.kind()));
        }
        let budget = outcome.summary.budget.as_ref().and_then(|b| b.stopped.as_deref());
        for task in &outcome.pool.not_run {
            let why = match (budget, &model_down) {
                (Some(why), _) => format!("not started: the budget is reached ({why})"),
                (None, Some(why)) => format!("not started: {why}"),
                (None, None) => "not run (no healthy guest left)".to_owned(),
            };
            lines.push_str(&format!("  {task}: {why}\n"));
        }
        if let Some(why) = &outcome.pool.ended_early {
            let down = outcome.pool.guests_down.join(", ");
            lines.push_str(&format!("the run ended early: {why} (guests down: {down})\n"));
        }
        emit(&lines)?;
        return Ok(ExitCode::from(if interrupted { 130 } else { 2 }));
    }
    Ok(ExitCode::SUCCESS)
}

/// Prepares the run `args` ask for (a preset applied): see [`Prepared::new`];
/// prints where the MCP endpoint of `--agent mcp` listens.
///
/// # Errors
///
/// As [`Prepared::new`], and a preset that refuses the arguments.
pub(crate) async fn prepare(args: &RunArgs) -> anyhow::Result<Prepared> {
    let prepared = Prepared::new(args.plan()?).await?;
    if let Some(endpoint) = &prepared.mcp {
        if let Some(file) = endpoint.token_file() {
            emit(&format!("MCP token (also in {}): {}\n", file.display(), endpoint.token()))?;
        }
        emit(&format!("MCP endpoint: {}\n", endpoint.url()))?;
    }
    Ok(prepared)
}

/// Plays a prepared run ([`driver::play`]) with Ctrl-C listened for: the first
/// stops the run gently, the second abandons it.
///
/// # Errors
///
/// As [`driver::play`].
pub(crate) async fn with_ctrl_c(prepared: Prepared, guests: &Guests) -> anyhow::Result<Played> {
    let stop = CancellationToken::new();
    let watcher = tokio::spawn(watch_interrupts(stop.clone()));
    let played = driver::play(prepared, guests, stop).await;
    watcher.abort();
    played
}

/// The first Ctrl-C cancels `stop`: no new task starts and running episodes end
/// at once, in the middle of a step whatever the agent answered, unevaluated
/// (they run again next time). The second exits at once with 130; every file
/// already written stays, as each is written whole.
async fn watch_interrupts(stop: CancellationToken) {
    // SIGTERM (a pod being deleted, `docker stop`) counts as the first Ctrl-C.
    if !crate::cli::signals::interrupt().await {
        return;
    }
    eprintln!(
        "\ninterrupted: no new task starts; running episodes stop now, unevaluated, and summary.json is written (Ctrl-C again to exit at once)"
    );
    stop.cancel();
    if tokio::signal::ctrl_c().await.is_ok() {
        eprintln!("abandoned: finished tasks are kept; the others run again with the same command");
        // No destructor runs past this: outside agents are ended here.
        arena_vm::child::tree::end_all();
        std::process::exit(130);
    }
}

/// Starts the guests `args` name (see [`Guests::start`]), saying when VMs boot.
///
/// # Errors
///
/// As [`RunArgs::guest_plan`] and [`Guests::start`].
pub(crate) async fn start_guests(conn: &Connection, args: &RunArgs) -> anyhow::Result<Guests> {
    let plan = args.guest_plan(conn)?;
    if let (Some(vms), Some(image)) = (&plan.vms, &args.source.vm_image) {
        emit(&format!("booting {} VM(s) on {}\n", vms.count.max(1), image.display()))?;
    }
    Guests::start(&plan).await
}

impl RunArgs {
    /// The run these flags ask for, a preset applied; says how it stands to upstream's.
    ///
    /// # Errors
    ///
    /// A preset that refuses the other flags.
    pub(crate) fn plan(&self) -> anyhow::Result<RunPlan> {
        let preset;
        let args = match self.preset {
            Some(p) => {
                preset = p.apply(self)?;
                &preset
            }
            None => self,
        };
        let fast = match args.pauses {
            Some(PausesArg::Fast) => true,
            Some(PausesArg::Upstream) => false,
            None => args.fast || args.source.stub_guests.is_some(),
        };
        Ok(RunPlan {
            tasks: args.tasks.clone(),
            difficulty: args.difficulty.into(),
            out: args.out.clone(),
            agent: args.agent,
            agent_name: args.agent.to_possible_value().map(|v| v.get_name().to_owned()).unwrap_or_default(),
            agent_options: args.agent_options(),
            mcp: args.external.mcp_plan(),
            model: args.model.clone(),
            max_steps: args.max_steps,
            trials: args.trials,
            trial_id: args.trial_id.clone(),
            certificates: args.certificates.clone(),
            prices: args.prices.clone(),
            max_cost: args.max_cost,
            max_total_tokens: args.max_total_tokens,
            preflight: !args.no_preflight,
            coords: args.coords,
            cache: args.cache.clone(),
            fast,
            a11y: !args.no_a11y,
            a11y_win32: args.a11y_backend == A11yBackendArg::Win32,
            reproduction: reproduction(args, fast)?,
            sleep_after: args.sleep_after,
            order: match args.order {
                OrderArg::Index => TaskOrder::Index,
                OrderArg::Sorted => TaskOrder::Sorted,
                OrderArg::Shuffle => TaskOrder::Shuffle { seed: args.seed },
            },
            activate_non_strict: args.activate_non_strict,
            stub_host_exec: args.source.stub_host_exec,
            vm_reset: args.source.reset,
            pyautogui_translate_only: args.pyautogui_translate_only,
            release_held_keys: args.held_keys == HeldKeysArg::Action,
            action_space_label: args.action_space_label.clone(),
            observation: args.observation.clone(),
            force_resume: args.force_resume,
            watch: super::progress::watch(args.progress),
            shard: args.shard,
            resume: !args.no_resume,
            attempts: args.attempts,
            guest_wait: Duration::from_secs(args.guest_wait),
        })
    }

    /// Where this run's guests come from: the global `--guest`, `--guests`,
    /// `--guests-file`, the VMs of `--vm-image` and the stub guests.
    ///
    /// # Errors
    ///
    /// A guests file or token file that cannot be read, or VM options that do not make a VM.
    pub(crate) fn guest_plan(&self, conn: &Connection) -> anyhow::Result<GuestPlan> {
        let mut urls: Vec<String> = conn.guest.iter().cloned().collect();
        urls.extend(self.source.guests.iter().map(|s| s.trim().to_owned()).filter(|s| !s.is_empty()));
        if let Some(file) = &self.source.guests_file {
            urls.extend(guests_from_file(file)?);
        }
        let client = conn.client_config()?;
        let vms = match &self.source.vm_image {
            Some(image) => {
                let dir = self.source.vm_dir.clone().unwrap_or_else(|| self.out.join("vms"));
                Some(VmPlan {
                    template: self.source.vm.config(image, &dir, "vm", client.token.clone())?,
                    count: self.source.vms.max(1),
                    reset: self.source.reset,
                })
            }
            None => None,
        };
        Ok(GuestPlan {
            urls,
            vms,
            stubs: self.source.stub_guests.unwrap_or(0),
            stub_host_exec: self.source.stub_host_exec,
            client,
        })
    }
}

/// `arena merge`.
///
/// # Errors
///
/// A shard that cannot be read, or an output that cannot be written.
pub fn merge(args: &MergeArgs) -> anyhow::Result<ExitCode> {
    let report =
        crate::run::merge::merge(&args.out, &args.shards, &format!("arena merge of {} shard(s)", args.shards.len()))?;
    for (task, kept) in &report.duplicates {
        tracing::warn!(%task, kept = %kept.display(), "task found in more than one shard");
    }
    emit(&format!(
        "merged {} task folder(s) from {} shard(s) into {}\n\n",
        report.copied,
        args.shards.len(),
        args.out.display()
    ))?;
    emit(&report.summary.markdown())?;
    emit(&format!("\nreport: {}\n", report.report.display()))?;
    Ok(ExitCode::SUCCESS)
}

/// `arena report`.
///
/// # Errors
///
/// The folder cannot be read or the files cannot be written.
pub fn report(args: &ReportArgs) -> anyhow::Result<ExitCode> {
    if let Some(dir) = &args.certificates {
        if !args.dir.is_dir() {
            bail!("{}: no such result folder", args.dir.display());
        }
        arena_results::certificate::CertifiedRecord::from_dir(dir)
            .with_context(|| format!("--certificates {}", dir.display()))?
            .write(&args.dir)?;
    }
    let (summary, path): (Summary, PathBuf) =
        write_report(&args.dir, &format!("arena report: {}", args.dir.display()))?;
    emit(&summary.markdown())?;
    emit(&format!("\nreport: {}\n", path.display()))?;
    Ok(ExitCode::SUCCESS)
}

/// `arena compare`.
///
/// # Errors
///
/// A folder cannot be read or mixes agents.
pub fn compare(args: &CompareArgs) -> anyhow::Result<ExitCode> {
    let comparison = arena_results::compare::Comparison::of_dirs(&args.run_a, &args.run_b)?;
    if args.json {
        emit(&format!("{}\n", serde_json::to_string_pretty(&comparison)?))?;
    } else {
        emit(&comparison.text())?;
    }
    Ok(ExitCode::SUCCESS)
}
