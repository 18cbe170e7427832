//! The driver of `arena run` (and of `arena certify` and `arena env serve`,
//! which reuse its parts): a [`RunPlan`] the command line resolved from its
//! flags becomes a [`Prepared`] run (tasks loaded, agent built, prices and
//! certificates read) before any guest starts; [`Guests`] starts what a
//! [`GuestPlan`] asks for (stub guests, VMs) beside the URLs given; [`play`]
//! runs the preflight, records and checks the options, and hands the tasks to
//! the pool ([`crate::run`]), each an episode ([`crate::episode`]).
//!
//! It prints nothing and listens for no signal: what a user reads, and Ctrl-C,
//! are the command line's (`crate::cli`).
//!
//! # Layout
//!
//! - `mod.rs`: the plans, [`Prepared`], [`Guests`], [`play`] and the preflight.
//! - `mcp`: the MCP endpoint of `--agent mcp` as a run binds and serves it (the endpoint itself is `crate::mcp`).
//! - [`stub`]: the embedded stub guest (`serve-stub`, `--stub-guests`, the demo's guest).

pub(crate) mod mcp;
pub mod stub;

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use anyhow::{bail, Context};
use tokio_util::sync::CancellationToken;

use self::mcp::{McpEndpoint, McpPlan};
use self::stub::{RunningStub, StubArgs};
use crate::episode::{EpisodeConfig, EpisodeRunner};
use crate::run::pool::PoolConfig;
use crate::run::shard::Shard;
use crate::run::watch::RunWatch;
use crate::run::{load_tasks, run_tasks, RunOptions, RunOutcome, TaskOrder};
use arena_actionspace::Coords;
use arena_agents::factory::{self, AgentKind, AgentOptions, ChosenAgent};
use arena_client::cache::DownloadCache;
use arena_client::client::{ClientConfig, GuestClient};
use arena_exec::ExecOptions;
use arena_results::RunLayout;
use arena_setup::Settle;
use arena_task::Difficulty;
use arena_vm::fleet::{ResetPolicy, VmFleet};

/// A run as the command line resolved it: nothing left to interpret.
#[derive(Debug, Clone)]
pub(crate) struct RunPlan {
    /// The task folder or index file, and the difficulty kept.
    pub(crate) tasks: PathBuf,
    pub(crate) difficulty: Difficulty,
    /// The output folder.
    pub(crate) out: PathBuf,
    /// The agent: its kind, the name recorded for it, its options, and the MCP
    /// endpoint's when it is `mcp`.
    pub(crate) agent: AgentKind,
    pub(crate) agent_name: String,
    pub(crate) agent_options: AgentOptions,
    pub(crate) mcp: McpPlan,
    /// `--model` as given (else the factory's name for it).
    pub(crate) model: Option<String>,
    pub(crate) max_steps: u32,
    pub(crate) trials: u32,
    pub(crate) trial_id: String,
    pub(crate) certificates: Option<PathBuf>,
    pub(crate) prices: Option<PathBuf>,
    pub(crate) max_cost: Option<f64>,
    pub(crate) max_total_tokens: Option<u64>,
    /// Check the agent and the guests before the first task.
    pub(crate) preflight: bool,
    /// What pyautogui coordinates are rescaled from (agents that state no convention).
    pub(crate) coords: Coords,
    pub(crate) cache: Option<PathBuf>,
    /// No pauses (tests, stub guests) rather than upstream's.
    pub(crate) fast: bool,
    pub(crate) a11y: bool,
    /// Read the tree with the Win32 backend (recorded as `a11y_backend=win32`).
    pub(crate) a11y_win32: bool,
    /// How the run stands to upstream's (`preset`, `differs_from_upstream`), recorded.
    pub(crate) reproduction: Vec<(String, String)>,
    pub(crate) sleep_after: Option<f64>,
    pub(crate) order: TaskOrder,
    pub(crate) activate_non_strict: bool,
    pub(crate) stub_host_exec: bool,
    /// When VMs go back to their snapshot (recorded when the run has VMs).
    pub(crate) vm_reset: ResetPolicy,
    pub(crate) pyautogui_translate_only: bool,
    /// Keys an action left held are released after it (`--held-keys action`).
    pub(crate) release_held_keys: bool,
    pub(crate) action_space_label: Option<String>,
    pub(crate) observation: String,
    pub(crate) force_resume: bool,
    /// Who is told of the run as it goes (the progress display).
    pub(crate) watch: Arc<dyn RunWatch>,
    pub(crate) shard: Shard,
    pub(crate) resume: bool,
    pub(crate) attempts: u32,
    pub(crate) guest_wait: Duration,
}

/// Where a run's guests come from, as the command line resolved it.
#[derive(Debug, Clone)]
pub(crate) struct GuestPlan {
    /// The guests given by URL, in order.
    pub(crate) urls: Vec<String>,
    /// VMs to boot, when the run has a golden image.
    pub(crate) vms: Option<VmPlan>,
    /// Embedded stub guests to start, and whether they run unknown programs for real.
    pub(crate) stubs: u16,
    pub(crate) stub_host_exec: bool,
    /// How every guest's client talks (the token, the call deadline, retries).
    pub(crate) client: ClientConfig,
}

/// The VMs of a run: `count` copies of `template`, reset as `reset` says.
#[derive(Debug, Clone)]
pub(crate) struct VmPlan {
    pub(crate) template: arena_vm::VmConfig,
    pub(crate) count: usize,
    pub(crate) reset: ResetPolicy,
}

/// A run's plan checked, its tasks loaded and its agent built, before any
/// guest or VM starts.
pub(crate) struct Prepared {
    pub(crate) plan: RunPlan,
    pub(crate) tasks: Vec<arena_task::Task>,
    chosen: ChosenAgent,
    /// The MCP endpoint of `--agent mcp`, bound.
    pub(crate) mcp: Option<McpEndpoint>,
    price: Option<arena_results::ledger::Price>,
    certificates: Option<arena_results::certificate::CertifiedRecord>,
}

impl Prepared {
    /// Checks `plan`, loads the tasks and builds the agent.
    ///
    /// # Errors
    ///
    /// Options that do not go together, tasks that do not load, an agent that
    /// cannot be built, prices or certificates that cannot be read.
    pub(crate) async fn new(plan: RunPlan) -> anyhow::Result<Prepared> {
        if plan.trials > 1 && plan.trial_id != arena_results::DEFAULT_TRIAL_ID {
            bail!(
                "--trials {} writes trial folders 0..{}; it cannot be combined with --trial-id {}",
                plan.trials,
                plan.trials - 1,
                plan.trial_id
            );
        }
        if let Some(max) = plan.max_cost.filter(|m| !m.is_finite() || *m < 0.0) {
            bail!("--max-cost {max}: give a number of US dollars, 0 or more");
        }
        let tasks = load_tasks(&plan.tasks, plan.difficulty)?;
        let certificates = match &plan.certificates {
            Some(dir) => Some(
                arena_results::certificate::CertifiedRecord::from_dir(dir)
                    .with_context(|| format!("--certificates {}", dir.display()))?,
            ),
            None => None,
        };
        let (chosen, mcp) = if plan.agent == AgentKind::Mcp {
            let (chosen, endpoint) = self::mcp::mcp(&plan.mcp, plan.max_steps, &plan.out, plan.model.clone()).await?;
            (chosen, Some(endpoint))
        } else {
            (factory::build(&plan.agent_options)?, None)
        };
        // The cost ledger's price is checked before any guest or VM starts.
        let price = match &plan.prices {
            Some(path) => Some(arena_results::ledger::Prices::load(path)?.of(&chosen.model, path)?),
            None => None,
        };
        Ok(Prepared { plan, tasks, chosen, mcp, price, certificates })
    }
}

/// A run's guests: those given by URL, and the stub guests and VMs it started
/// (stopped by [`Guests::stop`]). `arena certify` plays its agents on one set.
pub(crate) struct Guests {
    pub(crate) urls: Vec<String>,
    pub(crate) clients: Vec<GuestClient>,
    stubs: Vec<RunningStub>,
    pub(crate) fleet: Option<Arc<VmFleet>>,
}

impl Guests {
    /// The guests `plan` names, the stub guests and VMs it asks for started.
    ///
    /// # Errors
    ///
    /// A VM or stub guest that does not start, an invalid URL, or no guest at all.
    pub(crate) async fn start(plan: &GuestPlan) -> anyhow::Result<Guests> {
        let mut urls = plan.urls.clone();
        let fleet = match &plan.vms {
            Some(vms) => {
                let configs = arena_vm::fleet::configs(&vms.template, vms.count.max(1));
                let fleet = VmFleet::boot(configs, vms.reset).await?;
                urls.extend(fleet.urls());
                Some(Arc::new(fleet))
            }
            None => None,
        };
        let mut guests = Guests { urls, clients: Vec::new(), stubs: Vec::new(), fleet };
        for _ in 0..plan.stubs {
            let stub_args = StubArgs { stub_host_exec: plan.stub_host_exec, ..StubArgs::default() };
            match self::stub::start(&stub_args, plan.client.token.clone()).await {
                Ok(running) => {
                    guests.urls.push(running.url());
                    guests.stubs.push(running);
                }
                Err(err) => {
                    guests.stop().await;
                    return Err(err);
                }
            }
        }
        guests.urls.dedup();
        if guests.urls.is_empty() {
            guests.stop().await;
            bail!("no guest: give --guest, --guests, --guests-file or --stub-guests");
        }
        let vm_urls = guests.fleet.as_ref().map(|f| f.urls()).unwrap_or_default();
        let clients = guests
            .urls
            .iter()
            .map(|u| {
                let client = GuestClient::new(u, plan.client.clone())?;
                // A VM restored to its snapshot has forgotten every connection made since.
                Ok(if vm_urls.contains(u) { client.without_kept_connections()? } else { client })
            })
            .collect::<anyhow::Result<Vec<_>>>();
        match clients {
            Ok(clients) => guests.clients = clients,
            Err(err) => {
                guests.stop().await;
                return Err(err);
            }
        }
        Ok(guests)
    }

    /// Stops the VMs and stub guests this run started.
    pub(crate) async fn stop(self) {
        if let Some(fleet) = self.fleet {
            // The runs' options held the fleet; they are dropped by now.
            match Arc::try_unwrap(fleet) {
                Ok(fleet) => fleet.stop().await,
                Err(_) => tracing::warn!("the VMs are still in use; they stop when this program ends"),
            }
        }
        for stub in self.stubs {
            if let Err(err) = stub.stop().await {
                tracing::warn!(error = format!("{err:#}"), "stopping a stub guest");
            }
        }
    }
}

/// What [`play`] did.
pub(crate) struct Played {
    pub(crate) outcome: RunOutcome,
    /// Ctrl-C stopped it.
    pub(crate) interrupted: bool,
    pub(crate) shard: Shard,
    /// Why no new task started after the model endpoint was found down (`--llm-unreachable stop`).
    pub(crate) model_down: Option<String>,
}

/// Plays a prepared run on `guests`: the preflight, the options recorded and
/// checked against the folder's, the tasks, the summary and report. Cancelling
/// `stop` (the command line's first Ctrl-C) starts no new task and ends the
/// running episodes at once, unevaluated (they run again next time).
///
/// # Errors
///
/// The preflight fails, the folder holds results of other options, or results cannot be written.
pub(crate) async fn play(prepared: Prepared, guests: &Guests, stop: CancellationToken) -> anyhow::Result<Played> {
    let Prepared { plan, tasks, chosen, mcp, price, certificates } = prepared;
    let ChosenAgent { factory: agents, label: agent_label, model, options: mut agent_options, preflight } = chosen;
    // Every run records who played, in which action space and coordinates.
    agent_options.push(("agent".into(), plan.agent_name.clone()));
    agent_options.push(("model".into(), model.clone()));
    // Agents with their own convention (the computer-use agents) state it; for every
    // other agent the plan's coordinates are what its pyautogui code is rescaled from.
    let run_coords = !agent_options.iter().any(|(k, _)| k == "action_space");
    if run_coords {
        agent_options.push(("action_space".into(), agent_label.clone()));
        agent_options.push(("coords".into(), plan.coords.name()));
    }
    let fleet = guests.fleet.clone();

    let mut hello = None;
    if plan.preflight {
        // A setup mistake ends the run here, before any score is written.
        hello = self::preflight(preflight.as_ref(), &guests.clients).await?;
    }
    // An outside agent is named by its hello (else by the fingerprint the factory
    // gave), and what it declared is recorded, not the run's defaults.
    let mut model = model;
    if let Some(hello) = &hello {
        if let Some(name) = hello.agent.as_deref().map(str::trim).filter(|n| !n.is_empty()) {
            if plan.model.is_none() {
                model = arena_results::safe_component(name);
            }
            agent_options.push(("agent_name".into(), name.to_owned()));
        }
        agent_options.retain(|(k, _)| k != "model" && k != "action_space" && k != "coords");
        agent_options.push(("model".into(), model.clone()));
        agent_options.push(("action_space".into(), hello.action_space.clone()));
        agent_options.push(("coords".into(), hello.coords.clone().unwrap_or_else(|| plan.coords.name())));
    }
    let cache_dir = plan.cache.clone().unwrap_or_else(|| plan.out.join("download-cache"));
    let cache = DownloadCache::new(&cache_dir)
        .with_context(|| format!("opening the download cache {}", cache_dir.display()))?;
    let mut config = if plan.fast { EpisodeConfig::instant(cache) } else { EpisodeConfig::upstream(cache) };
    config.max_steps = plan.max_steps;
    // Both change what an episode is, so a resume compares them like any option.
    config.options.insert("max_steps".into(), plan.max_steps.to_string());
    config.options.insert("difficulty".into(), difficulty_name(plan.difficulty).into());
    config.a11y = plan.a11y;
    if plan.a11y_win32 {
        config.a11y_query.backend = arena_shared::observation::A11yBackend::Win32;
        config.options.insert("a11y_backend".into(), "win32".into());
    }
    config.options.extend(plan.reproduction.iter().cloned());
    config.model = model.clone();
    config.price = price;
    if let Some(secs) = plan.sleep_after {
        config.sleep_after_action =
            Duration::try_from_secs_f64(secs).context("--sleep-after must be a number of seconds, 0 or more")?;
        config.options.insert("sleep_after".into(), format!("{secs}"));
    }
    config.options.insert("order".into(), plan.order.to_string());
    if plan.agent_options.model_down.policy() == arena_agents::llm::Unreachable::Wait {
        config.options.insert("llm_unreachable".into(), "wait".into());
    }
    config.options.extend(agent_options);
    if plan.trials > 1 {
        config.options.insert("trials".into(), plan.trials.to_string());
    }
    if plan.activate_non_strict {
        config.options.insert("activate_non_strict".into(), "on".into());
    }
    if plan.stub_host_exec {
        config.options.insert("stub_host_exec".into(), "on".into());
    }
    if plan.fast {
        config.settle = Settle::none();
        config.exec = ExecOptions::instant();
    }
    if let Some(fleet) = &fleet {
        config.options.insert("vm_reset".into(), plan.vm_reset.to_string());
        config.screen_source = Some(Arc::clone(fleet) as Arc<dyn arena_agents::observation::observe::ScreenSource>);
        config.guest_watch = Some(Arc::clone(fleet) as Arc<dyn crate::run::blame::GuestWatch>);
    }
    if run_coords {
        config.exec.coords = plan.coords;
    }
    if plan.pyautogui_translate_only {
        config.exec.pyautogui = arena_exec::PyautoguiPolicy::TranslateOnly;
        config.options.insert("pyautogui_effects".into(), "off".into());
    }
    if plan.release_held_keys {
        config.exec.release_held_keys = true;
        config.options.insert("held_keys".into(), "action".into());
    }
    let layout = RunLayout {
        root: plan.out.clone(),
        agent: plan.action_space_label.clone().unwrap_or(agent_label),
        observation: plan.observation.clone(),
        model,
        trial: plan.trial_id.clone(),
    };
    // Every folder this run writes in: each trial's with --trials, else the one trial's.
    let folders: Vec<PathBuf> = if plan.trials > 1 {
        (0..plan.trials).map(|k| layout.trial_base(&k.to_string())).collect()
    } else {
        vec![layout.base()]
    };
    let mut differences = Vec::new();
    for folder in &folders {
        let lines = option_differences(folder, &config.options)?;
        differences.extend(lines.into_iter().map(|line| format!("{}: {line}", folder.display())));
    }
    if !differences.is_empty() {
        if !plan.force_resume {
            bail!(
                "{} holds results run with other options; resuming would mix two runs in one number:\n  {}\nuse another --out, or --force-resume to mix them anyway (recorded)",
                plan.out.display(),
                differences.join("\n  ")
            );
        }
        tracing::warn!(differences = %differences.join("; "), "--force-resume: mixing runs with different options");
        config.options.insert(FORCE_RESUME.into(), "on".into());
    }
    config.watch = Some(Arc::clone(&plan.watch));
    let options = RunOptions {
        layout: layout.clone(),
        shard: plan.shard,
        resume: plan.resume,
        pool: PoolConfig {
            max_attempts: plan.attempts.max(1),
            no_guest_timeout: plan.guest_wait,
            lifecycle: fleet.clone().map(|f| f as Arc<dyn crate::run::pool::GuestLifecycle>),
            stop: stop.clone(),
            ..PoolConfig::default()
        },
        watch: Arc::clone(&plan.watch),
        title: format!("arena run: {} ({})", plan.tasks.display(), layout.base().display()),
        order: plan.order,
        trials: plan.trials,
        budget: arena_results::ledger::Budget { max_cost_usd: plan.max_cost, max_tokens: plan.max_total_tokens },
    };
    config.stop = stop.clone();
    // A model endpoint found down for good (`--llm-unreachable stop`) starts no new task.
    let model_down = plan.agent_options.model_down.clone();
    let no_new_tasks = options.pool.no_new_tasks.clone();
    let run_watch = Arc::clone(&plan.watch);
    let down_watcher = tokio::spawn(async move {
        let why = model_down.tripped().await;
        tracing::error!(%why, "the model endpoint is down: no new task starts");
        run_watch.note(&format!("{why}; running tasks finish"));
        no_new_tasks.cancel();
    });
    let runner = EpisodeRunner { layout, config, agents };
    if let Some(record) = &certificates {
        record.write(&plan.out)?;
    }
    let clients = guests.clients.clone();
    let outcome = match mcp {
        Some(endpoint) => self::mcp::run_with_mcp(endpoint, tasks, clients, runner, &options).await,
        None => run_tasks(tasks, clients, Arc::new(runner), &options).await,
    };
    drop(options);
    down_watcher.abort();
    let model_down = plan.agent_options.model_down.why().map(str::to_owned);
    Ok(Played { outcome: outcome?, interrupted: stop.is_cancelled(), shard: plan.shard, model_down })
}

/// The checks before a run's first task: the agent's ([`factory::Preflight`]),
/// then the guests' health (at least one must answer; the others are said).
async fn preflight(
    agent: Option<&factory::Preflight>,
    guests: &[GuestClient],
) -> anyhow::Result<Option<arena_agents::external::protocol::AgentHello>> {
    let mut hello = None;
    if let Some(check) = agent {
        match check.check().await {
            Ok(checked) => {
                if let Some(note) = checked.note {
                    tracing::warn!(%note, "preflight: the model endpoint did not answer well; going on");
                }
                hello = checked.hello;
            }
            Err(err) => {
                bail!("preflight: {err:#}\nno task was run and no result written (--no-preflight skips these checks)")
            }
        }
    }
    let mut down = Vec::new();
    for guest in guests {
        if let Err(err) = guest.with_timeout(Duration::from_secs(30)).health().await {
            down.push(format!("{}: {err}", guest.base_url()));
        }
    }
    if !guests.is_empty() && down.len() == guests.len() {
        bail!(
            "preflight: no guest answers its health check:\n  {}\nno task was run and no result written (--no-preflight skips these checks)",
            down.join("\n  ")
        );
    }
    for line in down {
        tracing::warn!(guest = %line, "preflight: a guest does not answer; the run goes on without it until it does");
    }
    Ok(hello)
}

/// How the results record a difficulty: upstream's `--diff_lvl` words.
fn difficulty_name(difficulty: Difficulty) -> &'static str {
    match difficulty {
        Difficulty::Normal => "normal",
        Difficulty::Hard => "hard",
    }
}

/// The option `--force-resume` records, left out of the comparison.
const FORCE_RESUME: &str = "force_resume";

/// How the options recorded in the task folders below `base` differ from `ours`,
/// one line per option (`name: the folder has A, this run B`); empty for a new
/// folder or the same options.
fn option_differences(base: &Path, ours: &BTreeMap<String, String>) -> anyhow::Result<Vec<String>> {
    if !base.is_dir() {
        return Ok(Vec::new());
    }
    let found = arena_results::scan(base)?;
    let mut theirs: BTreeMap<&str, BTreeSet<&str>> = BTreeMap::new();
    let episodes: Vec<&arena_results::EpisodeResult> = found.iter().filter_map(|f| f.episode.as_ref()).collect();
    if episodes.is_empty() {
        return Ok(Vec::new());
    }
    for episode in &episodes {
        for (name, value) in &episode.options {
            theirs.entry(name).or_default().insert(value);
        }
    }
    let mut names: BTreeSet<&str> = theirs.keys().copied().collect();
    names.extend(ours.keys().map(String::as_str));
    names.remove(FORCE_RESUME);
    let mut out = Vec::new();
    for name in names {
        let had: Vec<&str> = theirs.get(name).map(|v| v.iter().copied().collect()).unwrap_or_default();
        let have = ours.get(name).map(String::as_str);
        let same = match have {
            Some(v) => had.len() == 1 && had[0] == v && episodes.iter().all(|e| e.options.contains_key(name)),
            None => had.is_empty(),
        };
        if !same {
            let had = if had.is_empty() { "not set".to_owned() } else { had.join(" | ") };
            out.push(format!("{name}: the folder has {had}, this run {}", have.unwrap_or("not set")));
        }
    }
    Ok(out)
}
