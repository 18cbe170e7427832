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
use std::sync::Arc;
use std::time::Duration;

use anyhow::{bail, Context};
use clap::{Args, ValueEnum};

use super::{emit, stub, Connection};
use crate::agent::cu::openai::SafetyChecks;
use crate::agent::factory::{self, AgentKind, AgentOptions, ChosenAgent};
use crate::agent::llm::{ApiKind, Refusals};
use crate::agent::navi::NaviStyle;
use crate::episode::{EpisodeConfig, EpisodeRunner};
use crate::run::pool::PoolConfig;
use crate::run::shard::Shard;
use crate::run::{load_tasks, run_tasks, RunOptions, TaskOrder};
use crate::som::SomOrigin;
use arena_actionspace::uitars::UiTarsVersion;
use arena_actionspace::Coords;
use arena_client::cache::DownloadCache;
use arena_exec::ExecOptions;
use arena_results::html::write_report;
use arena_results::summary::Summary;
use arena_results::RunLayout;
use arena_setup::Settle;
use arena_task::Difficulty;

/// Arguments of `arena run`.
#[derive(Debug, Clone, Args)]
pub struct RunArgs {
    /// A task folder (or a corpus root holding `examples/`), or an index file such as `test_all.json`.
    #[arg(long, value_name = "PATH")]
    pub tasks: PathBuf,
    /// Which variant of the corpus an index or root resolves into.
    #[arg(long, value_enum, default_value_t = DifficultyArg::Normal)]
    pub difficulty: DifficultyArg,
    #[arg(long, value_enum, default_value_t = AgentKind::Scripted)]
    pub agent: AgentKind,
    #[command(flatten)]
    pub external: super::external::ExternalArgs,
    /// Navi agent: reproduce one row of the WAA paper's Navi table (upstream's
    /// README, "Available Configurations"): that row's Set-of-Marks origin and
    /// accessibility backend, upstream's model parameters, step cap and pauses, and
    /// upstream's prompts from --waa-root (required). Recorded in the results.
    /// The model is still --model. See docs/compatibility.md, "Presets".
    #[arg(
        long,
        value_enum,
        value_name = "PRESET",
        conflicts_with_all = ["som_origin", "a11y_backend", "temperature", "max_tokens", "navi_style", "max_steps", "sleep_after", "fast", "pauses", "no_a11y"]
    )]
    pub preset: Option<Preset>,
    /// Scripted agent: one plan file for every task, or a folder of `<task name>.json`
    /// plans [default: `<tasks>/plans` when it exists, else each task's `plan` key].
    #[arg(long, value_name = "PATH")]
    pub plans: Option<PathBuf>,
    /// Replay agent: a `traj.jsonl` for every task, or a result folder
    /// (`<out>/<agent>/<observation>/<model>`) holding `<domain>/<task>/traj.jsonl`.
    #[arg(long, value_name = "PATH")]
    pub replay: Option<PathBuf>,
    /// Model agents (navi, anthropic-cu, openai-cu, ui-tars): base URL of the API. Navi
    /// and ui-tars: OpenAI-compatible (`.../v1`) or a classic Azure OpenAI deployment
    /// (`https://NAME.openai.azure.com/openai/deployments/D?api-version=V`). The key
    /// comes from ARENA_LLM_KEY, else OPENAI_API_KEY (ANTHROPIC_API_KEY for anthropic-cu).
    #[arg(long, env = "ARENA_LLM_URL", value_name = "URL")]
    pub llm_url: Option<String>,
    /// Model agents (navi, anthropic-cu, openai-cu, ui-tars): the model name.
    #[arg(long, env = "ARENA_LLM_MODEL")]
    pub model: Option<String>,
    /// Navi agent: sampling temperature (upstream's Navi: 1.0).
    #[arg(long, default_value_t = 1.0)]
    pub temperature: f64,
    /// Model agents (navi, anthropic-cu, openai-cu, ui-tars): longest answer in tokens
    /// (upstream's Navi: 4096); Navi sends it as `max_completion_tokens` to reasoning
    /// models (o1, o3, o4, gpt-5), else `max_tokens`.
    #[arg(long, default_value_t = 4096)]
    pub max_tokens: u32,
    /// Navi agent: `waa`, upstream's message layout and reply rules (our words for its
    /// prose), or `arena`, this project's earlier prompt and lenient reply reader.
    #[arg(long, value_enum, default_value_t = NaviStyleArg::Waa)]
    pub navi_style: NaviStyleArg,
    /// Navi agent: where the Set-of-Marks boxes come from, upstream's --som_origin:
    /// `a11y` (the accessibility tree), `oss` (OCR with Tesseract, the Grounding DINO
    /// service and the browser's DOM), `omni` (OmniParser's server), `mixed-oss` or
    /// `mixed-omni` (the tree, then what the other source adds). See docs/som.md.
    #[arg(long, default_value = "a11y", value_parser = parse_som_origin, value_name = "ORIGIN")]
    pub som_origin: SomOrigin,
    /// Which accessibility tree is read, upstream's --a11y_backend: `uia` (UI
    /// Automation, upstream's default) or `win32` (window enumeration, faster).
    #[arg(long, value_enum, default_value_t = A11yBackendArg::Uia)]
    pub a11y_backend: A11yBackendArg,
    /// Navi agent: what a model refusal (`message.refusal` without content) does:
    /// `unfinished` (upstream: the task is left without a result) or `answer` (its
    /// text is a reply without actions and the task is scored). Recorded in the results.
    #[arg(long, value_enum, default_value_t = RefusalsArg::Unfinished)]
    pub refusals: RefusalsArg,
    /// Navi agent: base URL of the Grounding DINO service (`oss`, `mixed-oss`); see docs/som.md.
    #[arg(long, env = "ARENA_DETECTOR_URL", value_name = "URL")]
    pub detector_url: Option<String>,
    /// Navi agent: base URL of OmniParser's server (`omni`, `mixed-omni`), e.g. http://127.0.0.1:8000.
    #[arg(long, env = "ARENA_OMNIPARSER_URL", value_name = "URL")]
    pub omniparser_url: Option<String>,
    /// Navi agent: the user's WindowsAgentArena checkout, to send upstream's own
    /// prompt texts (read from its mm_agents/navi files at start); without it the
    /// prompts are this project's words in upstream's layout.
    #[arg(long, env = "ARENA_WAA_ROOT", value_name = "PATH")]
    pub waa_root: Option<PathBuf>,
    /// Navi agent: which API the URL speaks; `auto` detects Azure by its host or `api-version`.
    #[arg(long, value_enum, default_value_t = LlmApi::Auto)]
    pub llm_api: LlmApi,
    /// Navi agent: deadline of one model call, in seconds.
    #[arg(long, default_value_t = 120.0, value_name = "SECONDS")]
    pub llm_timeout: f64,
    /// Navi agent: how long a failing model (429, 5xx, timeouts) is tried again,
    /// in seconds of waiting, before the task is left unfinished.
    #[arg(long, default_value_t = 300.0, value_name = "SECONDS")]
    pub llm_retry: f64,
    /// What the coordinates of agents that answer in pyautogui or `computer_13` are
    /// measured in: `pixels`, `fraction` (0 to 1) or `grid1000` (0 to 1000). The
    /// computer-use agents use their model's own convention. Recorded in the results.
    #[arg(long, default_value = "pixels", value_parser = parse_coords, value_name = "CONVENTION")]
    pub coords: Coords,
    /// anthropic-cu and openai-cu: the tool form. Without it the model's row of the
    /// table in docs/agents.md chooses (a model not in it gets its vendor's newest form,
    /// with a notice). Recorded in the results.
    #[arg(long, value_enum, value_name = "TOOL")]
    pub computer_tool: Option<ComputerTool>,
    /// anthropic-cu and openai-cu: the longest side, in pixels, of the screenshots sent
    /// (scaled down, never up; coordinates are mapped back). Without it the model's row
    /// of the table chooses. Recorded in the results.
    #[arg(long, value_name = "PIXELS")]
    pub max_image_side: Option<u32>,
    /// anthropic-cu with computer_toolset_20260801: withhold a member tool from the model
    /// (its `configs` entry says `enabled: false`); may be given more than once.
    #[arg(long, value_name = "MEMBER")]
    pub toolset_disable: Vec<String>,
    /// anthropic-cu: offer zoom (computer_20251124, or the toolset's `zoom` member,
    /// which is withheld without this).
    #[arg(long)]
    pub zoom: bool,
    /// anthropic-cu: the extended-thinking budget in tokens (at least 1024, below --max-tokens),
    /// for models that think.
    #[arg(long, value_name = "TOKENS")]
    pub thinking_budget: Option<u32>,
    /// anthropic-cu: do not mark the system prompt and tools for prompt caching.
    #[arg(long)]
    pub no_prompt_cache: bool,
    /// anthropic-cu and ui-tars: how many screenshots each request carries, the newest
    /// [default: 3 for anthropic-cu, 5 for ui-tars].
    #[arg(long, value_name = "N")]
    pub keep_images: Option<usize>,
    /// openai-cu: what to do with a call's pending safety checks: `ack` acknowledges them
    /// and acts, `fail` ends the episode as FAIL. Recorded in the results.
    #[arg(long, value_enum, default_value_t = SafetyChecks::Ack)]
    pub safety_checks: SafetyChecks,
    /// ui-tars: the prompt template, as the UI-TARS project publishes it, with
    /// `{instruction}` (and `{language}`) placeholders; read at start.
    #[arg(long, value_name = "FILE")]
    pub prompt_file: Option<PathBuf>,
    /// ui-tars: the model's coordinate convention: `1.0` (a 0..1000 grid, UI-TARS
    /// 2B/7B/72B) or `1.5` (pixels of the smart-resized screenshot, UI-TARS-1.5).
    #[arg(long, value_enum, default_value_t = UiTarsVersionArg::V1_5)]
    pub uitars_version: UiTarsVersionArg,
    #[command(flatten)]
    pub source: GuestSource,
    /// This machine's slice, i/n with i from 1 (a 0-based JOB_COMPLETION_INDEX is $((INDEX + 1))/N).
    #[arg(long, default_value = "1/1", value_parser = parse_shard)]
    pub shard: Shard,
    /// Result folder.
    #[arg(long, default_value = "results", value_name = "DIR")]
    pub out: PathBuf,
    /// Download cache [default: <out>/download-cache].
    #[arg(long, value_name = "DIR")]
    pub cache: Option<PathBuf>,
    /// Step cap per episode (upstream: 15).
    #[arg(long, default_value_t = crate::episode::DEFAULT_MAX_STEPS)]
    pub max_steps: u32,
    /// Pause after each action, in seconds (upstream: 3; --fast makes it 0).
    #[arg(long, value_name = "SECONDS")]
    pub sleep_after: Option<f64>,
    /// The same as `--pauses fast` (the default with --stub-guests).
    #[arg(long)]
    pub fast: bool,
    /// What stderr shows while the run goes: `auto` (a live display of tasks done,
    /// solved so far, ETA and each guest's task and step on a terminal; `plain`
    /// otherwise or under CI), `bar`, `plain` (one line per finished task) or `none`.
    #[arg(long, value_enum, default_value_t = super::progress::ProgressArg::Auto)]
    pub progress: super::progress::ProgressArg,
    /// Resume into a results folder whose recorded options differ from this run's
    /// (refused otherwise, naming the differences). Recorded as `force_resume=on`.
    #[arg(long)]
    pub force_resume: bool,
    /// Run every task of the shard again, even those with a result.txt.
    #[arg(long)]
    pub no_resume: bool,
    /// Skip the checks before the first task (the outside agent's hello, one
    /// minimal request to the model endpoint, the guests' health).
    #[arg(long)]
    pub no_preflight: bool,
    /// Tries per task after infrastructure errors, the first included.
    #[arg(long, default_value_t = 3)]
    pub attempts: u32,
    /// Seconds the run waits, with tasks left and every guest down, for one to
    /// answer again before it ends and lists the unfinished tasks.
    #[arg(long, default_value_t = 600, value_name = "SECS")]
    pub guest_wait: u64,
    /// Leave the accessibility tree out of observations.
    #[arg(long)]
    pub no_a11y: bool,
    /// The observation label of the result folders (upstream's --observation_type).
    #[arg(long, default_value = "a11y_tree")]
    pub observation: String,
    /// The first folder level of the results (upstream's --action_space). Default:
    /// `pyautogui` for Navi, as upstream files it; the agent's name for the
    /// scripted and replay agents, which upstream does not have.
    #[arg(long, value_name = "LABEL")]
    pub action_space_label: Option<String>,
    /// The order tasks go to the guests in: `index` (the index file's, as
    /// upstream runs them), `sorted` (by domain and name) or `shuffle` (with --seed).
    #[arg(long, value_enum, default_value_t = OrderArg::Index)]
    pub order: OrderArg,
    /// The seed of `--order shuffle`.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// `upstream`: upstream's pauses (5 s after closing windows and after setup,
    /// --sleep-after after every action, DONE and FAIL included, twice that for
    /// WAIT). `fast`: none, for the stub guest and tests. Recorded in the results.
    #[arg(long, value_enum)]
    pub pauses: Option<PausesArg>,
    /// Bring the window of a non-strict `activate_window` setup step to the front
    /// (upstream finds it and does nothing). Recorded in the results.
    #[arg(long)]
    pub activate_non_strict: bool,
    /// When a key an agent pressed with keyDown and never released is let go:
    /// `episode` (default, as upstream within a task: it stays down across steps)
    /// releases it after the evaluation; `action` at the end of the action that pressed
    /// it. Recorded in the results.
    #[arg(long, value_enum, default_value_t = HeldKeysArg::Episode)]
    pub held_keys: HeldKeysArg,
    /// Translate agents' pyautogui code into input and clipboard steps only: code
    /// reaching for files, processes or saved screenshots does nothing and is the
    /// step's error. Without it the code runs with its effects, as upstream's
    /// `python -c` does (files, processes and screenshots through the guest's API).
    /// Recorded in the results as `pyautogui_effects=off`.
    #[arg(long)]
    pub pyautogui_translate_only: bool,
    /// The trial folder level of the results (upstream's --trial_id).
    #[arg(long, default_value = arena_results::DEFAULT_TRIAL_ID, value_name = "ID")]
    pub trial_id: String,
    /// Run each task K times, trial k in trial folder k (0..K-1, upstream's trial
    /// level), trial-major: every task of trial 0, then of trial 1, ...; each trial
    /// resumes on its own. The summary gains pass@k, pass^k and the flaky tasks.
    /// Recorded in the results when above 1.
    #[arg(long, default_value_t = 1, value_name = "K", value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub trials: u32,
    /// The cost ledger's prices: a JSON file of model name -> {"input": USD, "output":
    /// USD, "cached_input": USD} per million tokens (docs/results.md); each task's
    /// tokens are priced into its `cost_usd`. No price is built in.
    #[arg(long, value_name = "FILE")]
    pub prices: Option<PathBuf>,
    /// Start no new task once the folder's tasks have cost this many US dollars
    /// (needs --prices); running tasks finish. Recorded in summary.json (`budget`).
    #[arg(long, value_name = "USD", requires = "prices")]
    pub max_cost: Option<f64>,
    /// Start no new task once the folder's tasks have used this many tokens, input
    /// and output together; running tasks finish. Recorded in summary.json (`budget`).
    /// (--max-tokens is the model's longest answer, upstream's parameter.)
    #[arg(long, value_name = "N")]
    pub max_total_tokens: Option<u64>,
    /// Task certificates (an `arena certify --out` folder, or its `certificates`
    /// folder): the summary and report mark the tasks they call broken. Recorded
    /// in the result folder (`certified_broken.json`) and the summary.
    #[arg(long, value_name = "DIR")]
    pub certificates: Option<PathBuf>,
}

/// Where a run's guests come from: URLs, embedded stub guests, or VMs it starts
/// (shared by `arena run` and `arena certify`).
#[derive(Debug, Clone, clap::Args)]
pub struct GuestSource {
    /// Guests of the pool, comma-separated (repeatable); the global --guest is added to them.
    #[arg(long, value_delimiter = ',', value_name = "URL,...")]
    pub guests: Vec<String>,
    /// A file of guest URLs, one per line (blank lines and `#` comments ignored).
    #[arg(long, value_name = "FILE")]
    pub guests_file: Option<PathBuf>,
    /// Start N embedded stub guests for the run (demos and tests); implies --fast.
    #[arg(long, value_name = "N")]
    pub stub_guests: Option<u16>,
    /// The embedded stub guests run commands that are none of their simulated
    /// programs as REAL processes on this machine (off: refused, so agent code
    /// starts nothing on the host). Recorded in the results as `stub_host_exec=on`.
    #[arg(long, requires = "stub_guests")]
    pub stub_host_exec: bool,
    /// Run the tasks in VMs this run starts with QEMU, each on an overlay of this
    /// read-only golden image, restored to its `ready` snapshot as --reset says.
    #[arg(long, value_name = "IMAGE")]
    pub vm_image: Option<PathBuf>,
    /// How many VMs --vm-image starts.
    #[arg(long, default_value_t = 1, value_name = "N", requires = "vm_image")]
    pub vms: usize,
    /// When a VM goes back to its `ready` snapshot: `per-task`, `every:K` tasks, or
    /// `never` (tasks meet what the ones before left, as upstream runs). Recorded.
    #[arg(long, default_value = "per-task", value_parser = super::vm::parse_reset, value_name = "POLICY")]
    pub reset: arena_vm::fleet::ResetPolicy,
    /// The VMs' folders (overlays, QMP sockets, logs) [default: <out>/vms].
    #[arg(long, value_name = "DIR")]
    pub vm_dir: Option<PathBuf>,
    #[command(flatten)]
    pub vm: super::vm::VmArgs,
}

/// `--difficulty`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum DifficultyArg {
    /// `examples/`.
    #[default]
    Normal,
    /// `examples_noctxt/` (upstream's `--diff_lvl hard`).
    Hard,
}

impl From<DifficultyArg> for Difficulty {
    fn from(arg: DifficultyArg) -> Difficulty {
        match arg {
            DifficultyArg::Normal => Difficulty::Normal,
            DifficultyArg::Hard => Difficulty::Hard,
        }
    }
}

/// `--uitars-version`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum UiTarsVersionArg {
    /// UI-TARS 2B/7B/72B (Qwen2-VL): a 0..1000 grid.
    #[value(name = "1.0")]
    V1,
    /// UI-TARS-1.5 (Qwen2.5-VL): pixels of the `smart_resize`d screenshot.
    #[value(name = "1.5")]
    V1_5,
}

/// `--a11y-backend`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum A11yBackendArg {
    Uia,
    Win32,
}

/// `--refusals`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum RefusalsArg {
    Unfinished,
    Answer,
}

/// `--preset`: the rows of the WAA paper's Navi comparison that this project
/// can run, as upstream's README lists them ("Available Configurations",
/// microsoft/WindowsAgentArena at 6d39ed88, whose `run-local.sh` takes
/// `--som-origin` and `--a11y-backend` and passes them to `run.py`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Preset {
    /// `--som-origin mixed-omni --a11y-backend uia`: OmniParser with the UIA tree, the paper's best row.
    PaperMixedOmni,
    /// `--som-origin omni`: OmniParser alone.
    PaperOmni,
    /// `--som-origin oss`: webparse, Grounding DINO and Tesseract OCR, the baseline.
    PaperOss,
    /// `--som-origin a11y --a11y-backend uia`: the UIA tree.
    PaperA11yUia,
    /// `--som-origin a11y --a11y-backend win32`: the win32 tree, the fastest.
    PaperA11yWin32,
    /// `--som-origin mixed-oss --a11y-backend uia`: the `oss` sources with the UIA tree.
    PaperMixedOss,
}

/// Upstream's default run, the reference a non-preset Navi run is compared with:
/// `run.py` and `start_client.sh` at 6d39ed88 (`--som_origin oss`, `--a11y_backend uia`,
/// `--temperature 1.0`, `--max_steps 15`, `--sleep_after_execution 3`), Navi's
/// `max_tokens` of 4096 (its planner's request), and the prompts of the checkout.
pub mod upstream_default {
    use super::SomOrigin;
    pub const SOM_ORIGIN: SomOrigin = SomOrigin::Oss;
    pub const A11Y_BACKEND: &str = "uia";
    pub const TEMPERATURE: f64 = 1.0;
    pub const MAX_TOKENS: u32 = 4096;
    pub const MAX_STEPS: u32 = crate::episode::DEFAULT_MAX_STEPS;
    pub const SLEEP_AFTER_SECONDS: f64 = 3.0;
}

impl Preset {
    /// `paper-mixed-omni`, ...
    pub fn name(self) -> &'static str {
        match self {
            Preset::PaperMixedOmni => "paper-mixed-omni",
            Preset::PaperOmni => "paper-omni",
            Preset::PaperOss => "paper-oss",
            Preset::PaperA11yUia => "paper-a11y-uia",
            Preset::PaperA11yWin32 => "paper-a11y-win32",
            Preset::PaperMixedOss => "paper-mixed-oss",
        }
    }

    /// The row's Set-of-Marks origin and accessibility backend.
    pub fn row(self) -> (SomOrigin, A11yBackendArg) {
        match self {
            Preset::PaperMixedOmni => (SomOrigin::MixedOmni, A11yBackendArg::Uia),
            // Upstream's default backend is uia; the row does not change it.
            Preset::PaperOmni => (SomOrigin::Omni, A11yBackendArg::Uia),
            Preset::PaperOss => (SomOrigin::Oss, A11yBackendArg::Uia),
            Preset::PaperA11yUia => (SomOrigin::A11y, A11yBackendArg::Uia),
            Preset::PaperA11yWin32 => (SomOrigin::A11y, A11yBackendArg::Win32),
            Preset::PaperMixedOss => (SomOrigin::MixedOss, A11yBackendArg::Uia),
        }
    }

    /// `args` with the row's settings and upstream's model parameters, step cap and pauses.
    ///
    /// # Errors
    ///
    /// Without --waa-root (a reproduction sends upstream's own prompts), or with an agent other than Navi.
    pub fn apply(self, args: &RunArgs) -> anyhow::Result<RunArgs> {
        if args.agent != AgentKind::Navi {
            bail!("--preset {} is a Navi configuration: give --agent navi", self.name());
        }
        if args.waa_root.is_none() {
            bail!(
                "--preset {} reproduces upstream's run and needs upstream's prompts: give --waa-root (or ARENA_WAA_ROOT), a WindowsAgentArena checkout",
                self.name()
            );
        }
        let (som_origin, a11y_backend) = self.row();
        Ok(RunArgs {
            som_origin,
            a11y_backend,
            temperature: upstream_default::TEMPERATURE,
            max_tokens: upstream_default::MAX_TOKENS,
            navi_style: NaviStyleArg::Waa,
            max_steps: upstream_default::MAX_STEPS,
            sleep_after: None,
            fast: false,
            pauses: Some(PausesArg::Upstream),
            no_a11y: false,
            ..args.clone()
        })
    }
}

/// What a Navi run that is no preset changes from upstream's default run, one
/// `name=ours (upstream: theirs)` item each; empty when nothing differs.
pub fn differences_from_upstream(args: &RunArgs, fast: bool) -> Vec<String> {
    let mut out = Vec::new();
    let mut differs = |name: &str, ours: String, theirs: String| {
        if ours != theirs {
            out.push(format!("{name}={ours} (upstream: {theirs})"));
        }
    };
    differs("som_origin", args.som_origin.name().to_owned(), upstream_default::SOM_ORIGIN.name().to_owned());
    let backend = if args.a11y_backend == A11yBackendArg::Win32 { "win32" } else { "uia" };
    differs("a11y_backend", backend.to_owned(), upstream_default::A11Y_BACKEND.to_owned());
    let prompt = match (args.navi_style, &args.waa_root) {
        (NaviStyleArg::Arena, _) => "arena (this project's prompt and reply reader)",
        (NaviStyleArg::Waa, None) => "ours (no --waa-root)",
        (NaviStyleArg::Waa, Some(_)) => "the checkout's",
    };
    differs("prompt", prompt.to_owned(), "the checkout's".to_owned());
    differs("temperature", format!("{}", args.temperature), format!("{}", upstream_default::TEMPERATURE));
    differs("max_tokens", args.max_tokens.to_string(), upstream_default::MAX_TOKENS.to_string());
    differs("max_steps", args.max_steps.to_string(), upstream_default::MAX_STEPS.to_string());
    let upstream_pauses = "5 s after the reset and the setup, 3 s after each action";
    let pauses = if fast { "fast (none)" } else { upstream_pauses };
    differs("pauses", pauses.to_owned(), upstream_pauses.to_owned());
    if let Some(secs) = args.sleep_after {
        differs("sleep_after", format!("{secs}"), format!("{}", upstream_default::SLEEP_AFTER_SECONDS));
    }
    if args.no_a11y {
        differs("a11y", "off".to_owned(), "on".to_owned());
    }
    if args.refusals == RefusalsArg::Answer {
        differs("refusals", "answer".to_owned(), "unfinished".to_owned());
    }
    out
}

/// `--computer-tool`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ComputerTool {
    /// Anthropic's tool, beta header computer-use-2025-01-24.
    #[value(name = "computer_20250124")]
    Computer20250124,
    /// Anthropic's tool with zoom, beta header computer-use-2025-11-24.
    #[value(name = "computer_20251124")]
    Computer20251124,
    /// Anthropic's computer toolset: one tool per action.
    #[value(name = "computer_toolset_20260801")]
    ComputerToolset20260801,
    /// OpenAI's preview tool (computer-use-preview).
    #[value(name = "computer_use_preview")]
    ComputerUsePreview,
    /// OpenAI's GA tool, batched actions.
    #[value(name = "computer")]
    Computer,
}

impl ComputerTool {
    /// The form it names.
    pub fn form(self) -> crate::agent::cu::models::Form {
        use crate::agent::cu::models::Form;
        match self {
            ComputerTool::Computer20250124 => Form::Computer20250124,
            ComputerTool::Computer20251124 => Form::Computer20251124,
            ComputerTool::ComputerToolset20260801 => Form::ComputerToolset20260801,
            ComputerTool::ComputerUsePreview => Form::ComputerUsePreview,
            ComputerTool::Computer => Form::Computer,
        }
    }
}

/// `--navi-style`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum NaviStyleArg {
    Waa,
    Arena,
}

/// `--llm-api`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum LlmApi {
    Auto,
    Openai,
    Azure,
}

/// `--order`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum OrderArg {
    Index,
    Sorted,
    Shuffle,
}

/// `--pauses`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum PausesArg {
    Upstream,
    Fast,
}

/// `--held-keys`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum HeldKeysArg {
    /// Released after the evaluation.
    Episode,
    /// Released when the action that pressed them ends.
    Action,
}

/// Arguments of `arena merge`.
#[derive(Debug, Clone, Args)]
pub struct MergeArgs {
    /// The merged folder (created).
    pub out: PathBuf,
    /// Shard result folders.
    #[arg(required = true)]
    pub shards: Vec<PathBuf>,
}

/// Arguments of `arena report`.
#[derive(Debug, Clone, Args)]
pub struct ReportArgs {
    /// A result folder.
    pub dir: PathBuf,
    /// Task certificates (an `arena certify --out` folder, or its `certificates`
    /// folder) whose broken tasks the report marks; kept in the folder
    /// (`certified_broken.json`) for later reports.
    #[arg(long, value_name = "DIR")]
    pub certificates: Option<PathBuf>,
}

/// Arguments of `arena compare`.
#[derive(Debug, Clone, Args)]
pub struct CompareArgs {
    /// The first result folder (A).
    pub run_a: PathBuf,
    /// The second result folder (B); differences are B - A.
    pub run_b: PathBuf,
    /// Print the comparison as JSON.
    #[arg(long)]
    pub json: bool,
}

fn parse_shard(text: &str) -> Result<Shard, String> {
    text.parse()
}

fn parse_som_origin(text: &str) -> Result<SomOrigin, String> {
    text.parse()
}

fn parse_coords(text: &str) -> Result<Coords, String> {
    text.parse()
}

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
    /// What these flags say about the agent, for [`factory::build`].
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
        }
    }
}

/// `arena run`.
///
/// # Errors
///
/// Unusable arguments, tasks that do not load, no guest, or results that cannot be written.
pub async fn run(conn: &Connection, args: RunArgs) -> anyhow::Result<ExitCode> {
    let prepared = Prepared::new(args).await?;
    let guests = Guests::start(conn, &prepared.args).await?;
    let guest_count = guests.urls.len();
    let played = play(prepared, &guests).await;
    guests.stop().await;
    let played = played?;
    let Played { outcome, interrupted, shard } = played;

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
            let why = match budget {
                Some(why) => format!("not started: the budget is reached ({why})"),
                None => "not run (no healthy guest left)".to_owned(),
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

/// A run's arguments checked, its tasks loaded and its agent built, before any
/// guest or VM starts.
pub(crate) struct Prepared {
    pub(crate) args: RunArgs,
    pub(crate) tasks: Vec<arena_task::Task>,
    chosen: ChosenAgent,
    mcp: Option<super::external::McpEndpoint>,
    price: Option<arena_results::ledger::Price>,
    certificates: Option<arena_results::certificate::CertifiedRecord>,
}

impl Prepared {
    /// Checks `args` (a preset applied), loads the tasks and builds the agent.
    ///
    /// # Errors
    ///
    /// Unusable arguments, tasks that do not load, an agent that cannot be built,
    /// prices or certificates that cannot be read.
    pub(crate) async fn new(args: RunArgs) -> anyhow::Result<Prepared> {
        let args = match args.preset {
            Some(preset) => preset.apply(&args)?,
            None => args,
        };
        if args.trials > 1 && args.trial_id != arena_results::DEFAULT_TRIAL_ID {
            bail!(
                "--trials {} writes trial folders 0..{}; it cannot be combined with --trial-id {}",
                args.trials,
                args.trials - 1,
                args.trial_id
            );
        }
        let tasks = load_tasks(&args.tasks, args.difficulty.into())?;
        let certificates = match &args.certificates {
            Some(dir) => Some(
                arena_results::certificate::CertifiedRecord::from_dir(dir)
                    .with_context(|| format!("--certificates {}", dir.display()))?,
            ),
            None => None,
        };
        let (chosen, mcp) = if args.agent == AgentKind::Mcp {
            let (chosen, endpoint) =
                super::external::mcp(&args.external, args.max_steps, &args.out, args.model.clone()).await?;
            (chosen, Some(endpoint))
        } else {
            (factory::build(&args.agent_options())?, None)
        };
        // The cost ledger's price and budget are checked before any guest or VM starts.
        let price = match &args.prices {
            Some(path) => Some(arena_results::ledger::Prices::load(path)?.of(&chosen.model, path)?),
            None => None,
        };
        if let Some(max) = args.max_cost.filter(|m| !m.is_finite() || *m < 0.0) {
            bail!("--max-cost {max}: give a number of US dollars, 0 or more");
        }
        Ok(Prepared { args, tasks, chosen, mcp, price, certificates })
    }
}

/// A run's guests: those given by URL, and the stub guests and VMs it started
/// (stopped by [`Guests::stop`]). `arena certify` plays its agents on one set.
pub(crate) struct Guests {
    pub(crate) urls: Vec<String>,
    pub(crate) clients: Vec<arena_client::GuestClient>,
    stubs: Vec<stub::RunningStub>,
    pub(crate) fleet: Option<Arc<arena_vm::fleet::VmFleet>>,
}

impl Guests {
    /// The guests `args` name, the stub guests and VMs they ask for started.
    ///
    /// # Errors
    ///
    /// A guests file that cannot be read, a VM or stub guest that does not start, or no guest at all.
    pub(crate) async fn start(conn: &Connection, args: &RunArgs) -> anyhow::Result<Guests> {
        let mut urls: Vec<String> = conn.guest.iter().cloned().collect();
        urls.extend(args.source.guests.iter().map(|s| s.trim().to_owned()).filter(|s| !s.is_empty()));
        if let Some(file) = &args.source.guests_file {
            urls.extend(guests_from_file(file)?);
        }
        let fleet = match &args.source.vm_image {
            Some(image) => {
                let dir = args.source.vm_dir.clone().unwrap_or_else(|| args.out.join("vms"));
                let template = args.source.vm.config(image, &dir, "vm", conn.resolve_token()?)?;
                let configs = arena_vm::fleet::configs(&template, args.source.vms.max(1));
                emit(&format!("booting {} VM(s) on {}\n", configs.len(), image.display()))?;
                let fleet = arena_vm::fleet::VmFleet::boot(configs, args.source.reset).await?;
                urls.extend(fleet.urls());
                Some(Arc::new(fleet))
            }
            None => None,
        };
        let mut guests = Guests { urls, clients: Vec::new(), stubs: Vec::new(), fleet };
        for _ in 0..args.source.stub_guests.unwrap_or(0) {
            let stub_args = stub::StubArgs { stub_host_exec: args.source.stub_host_exec, ..stub::StubArgs::default() };
            let token = match conn.resolve_token() {
                Ok(token) => token,
                Err(err) => {
                    guests.stop().await;
                    return Err(err);
                }
            };
            match stub::start(&stub_args, token).await {
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
            bail!("no guest: give --guest, --guests, --guests-file or --stub-guests");
        }
        let vm_urls = guests.fleet.as_ref().map(|f| f.urls()).unwrap_or_default();
        let clients = guests
            .urls
            .iter()
            .map(|u| {
                let client = conn.client_for(u)?;
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
    pub(crate) outcome: crate::run::RunOutcome,
    /// Ctrl-C stopped it.
    pub(crate) interrupted: bool,
    pub(crate) shard: Shard,
}

/// Plays a prepared run on `guests`: the preflight, the options recorded and
/// checked against the folder's, the tasks, the summary and report.
///
/// # Errors
///
/// The preflight fails, the folder holds results of other options, or results cannot be written.
pub(crate) async fn play(prepared: Prepared, guests: &Guests) -> anyhow::Result<Played> {
    let Prepared { args, tasks, chosen, mcp, price, certificates } = prepared;
    let ChosenAgent { factory: agents, label: agent_label, model, options: mut agent_options, preflight } = chosen;
    // Every run records who played, in which action space and coordinates.
    let agent_name = args.agent.to_possible_value().map(|v| v.get_name().to_owned()).unwrap_or_default();
    agent_options.push(("agent".into(), agent_name));
    agent_options.push(("model".into(), model.clone()));
    // Agents with their own convention (the computer-use agents) state it; for every
    // other agent `--coords` is what its pyautogui code is rescaled from.
    let run_coords = !agent_options.iter().any(|(k, _)| k == "action_space");
    if run_coords {
        agent_options.push(("action_space".into(), agent_label.clone()));
        agent_options.push(("coords".into(), args.coords.name()));
    }
    let fleet = guests.fleet.clone();

    let mut hello = None;
    if !args.no_preflight {
        // A setup mistake ends the run here, before any score is written.
        hello = self::preflight(preflight.as_ref(), &guests.clients).await?;
    }
    // An outside agent is named by its hello (else by the fingerprint the factory
    // gave), and what it declared is recorded, not the run's defaults.
    let mut model = model;
    if let Some(hello) = &hello {
        if let Some(name) = hello.agent.as_deref().map(str::trim).filter(|n| !n.is_empty()) {
            if args.model.is_none() {
                model = arena_results::safe_component(name);
            }
            agent_options.push(("agent_name".into(), name.to_owned()));
        }
        agent_options.retain(|(k, _)| k != "model" && k != "action_space" && k != "coords");
        agent_options.push(("model".into(), model.clone()));
        agent_options.push(("action_space".into(), hello.action_space.clone()));
        agent_options.push(("coords".into(), hello.coords.clone().unwrap_or_else(|| args.coords.name())));
    }
    let cache_dir = args.cache.clone().unwrap_or_else(|| args.out.join("download-cache"));
    let cache = DownloadCache::new(&cache_dir)
        .with_context(|| format!("opening the download cache {}", cache_dir.display()))?;
    let fast = match args.pauses {
        Some(PausesArg::Fast) => true,
        Some(PausesArg::Upstream) => false,
        None => args.fast || args.source.stub_guests.is_some(),
    };
    let mut config = if fast { EpisodeConfig::instant(cache) } else { EpisodeConfig::upstream(cache) };
    config.max_steps = args.max_steps;
    config.a11y = !args.no_a11y;
    if args.a11y_backend == A11yBackendArg::Win32 {
        config.a11y_query.backend = arena_shared::observation::A11yBackend::Win32;
        config.options.insert("a11y_backend".into(), "win32".into());
    }
    config.options.extend(reproduction(&args, fast)?);
    config.model = model.clone();
    config.price = price;
    if let Some(secs) = args.sleep_after {
        config.sleep_after_action =
            Duration::try_from_secs_f64(secs).context("--sleep-after must be a number of seconds, 0 or more")?;
        config.options.insert("sleep_after".into(), format!("{secs}"));
    }
    let order = match args.order {
        OrderArg::Index => TaskOrder::Index,
        OrderArg::Sorted => TaskOrder::Sorted,
        OrderArg::Shuffle => TaskOrder::Shuffle { seed: args.seed },
    };
    config.options.insert("order".into(), order.to_string());
    config.options.extend(agent_options);
    if args.trials > 1 {
        config.options.insert("trials".into(), args.trials.to_string());
    }
    if args.activate_non_strict {
        config.options.insert("activate_non_strict".into(), "on".into());
    }
    if args.source.stub_host_exec {
        config.options.insert("stub_host_exec".into(), "on".into());
    }
    if fast {
        config.settle = Settle::none();
        config.exec = ExecOptions::instant();
    }
    if let Some(fleet) = &fleet {
        config.options.insert("vm_reset".into(), args.source.reset.to_string());
        config.screen_source = Some(Arc::clone(fleet) as Arc<dyn crate::ports::observe::ScreenSource>);
        config.guest_watch = Some(Arc::clone(fleet) as Arc<dyn crate::run::blame::GuestWatch>);
    }
    if run_coords {
        config.exec.coords = args.coords;
    }
    if args.pyautogui_translate_only {
        config.exec.pyautogui = arena_exec::PyautoguiPolicy::TranslateOnly;
        config.options.insert("pyautogui_effects".into(), "off".into());
    }
    if args.held_keys == HeldKeysArg::Action {
        config.exec.release_held_keys = true;
        config.options.insert("held_keys".into(), "action".into());
    }
    let layout = RunLayout {
        root: args.out.clone(),
        agent: args.action_space_label.clone().unwrap_or(agent_label),
        observation: args.observation.clone(),
        model,
        trial: args.trial_id.clone(),
    };
    let differences = option_differences(&layout.base(), &config.options)?;
    if !differences.is_empty() {
        if !args.force_resume {
            bail!(
                "{} holds results run with other options; resuming would mix two runs in one number:\n  {}\nuse another --out, or --force-resume to mix them anyway (recorded)",
                layout.base().display(),
                differences.join("\n  ")
            );
        }
        tracing::warn!(differences = %differences.join("; "), "--force-resume: mixing runs with different options");
        config.options.insert(FORCE_RESUME.into(), "on".into());
    }
    let watch = super::progress::watch(args.progress);
    config.watch = Some(Arc::clone(&watch));
    let options = RunOptions {
        layout: layout.clone(),
        shard: args.shard,
        resume: !args.no_resume,
        pool: PoolConfig {
            max_attempts: args.attempts.max(1),
            no_guest_timeout: Duration::from_secs(args.guest_wait),
            lifecycle: fleet.clone().map(|f| f as Arc<dyn crate::run::pool::GuestLifecycle>),
            ..PoolConfig::default()
        },
        watch: Arc::clone(&watch),
        title: format!("arena run: {} ({})", args.tasks.display(), layout.base().display()),
        order,
        trials: args.trials,
        budget: arena_results::ledger::Budget { max_cost_usd: args.max_cost, max_tokens: args.max_total_tokens },
    };
    // Ctrl-C: the first stops the run gently, the second abandons it.
    let stop = options.pool.stop.clone();
    config.stop = stop.clone();
    let watcher = tokio::spawn(watch_interrupts(stop.clone()));
    let runner = EpisodeRunner { layout, config, agents };
    if let Some(record) = &certificates {
        record.write(&args.out)?;
    }
    let clients = guests.clients.clone();
    let outcome = match mcp {
        Some(endpoint) => super::external::run_with_mcp(endpoint, tasks, clients, runner, &options).await,
        None => run_tasks(tasks, clients, Arc::new(runner), &options).await,
    };
    watcher.abort();
    drop(options);
    Ok(Played { outcome: outcome?, interrupted: stop.is_cancelled(), shard: args.shard })
}

/// The checks before a run's first task: the agent's ([`factory::Preflight`]),
/// then the guests' health (at least one must answer; the others are said).
async fn preflight(
    agent: Option<&factory::Preflight>,
    guests: &[arena_client::GuestClient],
) -> anyhow::Result<Option<crate::agent::external::protocol::AgentHello>> {
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

/// The option `--force-resume` records, left out of the comparison.
const FORCE_RESUME: &str = "force_resume";

/// How the options recorded in the task folders below `base` differ from `ours`,
/// one line per option (`name: the folder has A, this run B`); empty for a new
/// folder or the same options.
fn option_differences(base: &Path, ours: &std::collections::BTreeMap<String, String>) -> anyhow::Result<Vec<String>> {
    if !base.is_dir() {
        return Ok(Vec::new());
    }
    let found = arena_results::scan(base)?;
    let mut theirs: std::collections::BTreeMap<&str, std::collections::BTreeSet<&str>> = Default::default();
    let episodes: Vec<&arena_results::EpisodeResult> = found.iter().filter_map(|f| f.episode.as_ref()).collect();
    if episodes.is_empty() {
        return Ok(Vec::new());
    }
    for episode in &episodes {
        for (name, value) in &episode.options {
            theirs.entry(name).or_default().insert(value);
        }
    }
    let mut names: std::collections::BTreeSet<&str> = theirs.keys().copied().collect();
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

/// How the run stands to upstream's, as named options: `preset` for a preset,
/// else, for Navi, `differs_from_upstream` listing what differs, announced in one
/// line now (and shown by the report, which lists the options).
fn reproduction(args: &RunArgs, fast: bool) -> anyhow::Result<Vec<(String, String)>> {
    if let Some(preset) = args.preset {
        emit(&format!("preset {}: reproducing that row of upstream's Navi table\n", preset.name()))?;
        return Ok(vec![("preset".into(), preset.name().into())]);
    }
    if args.agent != AgentKind::Navi {
        return Ok(Vec::new());
    }
    let differences = differences_from_upstream(args, fast);
    let text = if differences.is_empty() { "none".to_owned() } else { differences.join("; ") };
    emit(&format!("not a reproduction: differs from upstream's default Navi run in {text}\n"))?;
    Ok(vec![("differs_from_upstream".into(), text)])
}

/// The first Ctrl-C cancels `stop`: no new task starts and running episodes end
/// at once, in the middle of a step whatever the agent answered, unevaluated
/// (they run again next time). The second exits
/// at once with 130; every file already written stays, as each is written whole.
async fn watch_interrupts(stop: tokio_util::sync::CancellationToken) {
    // SIGTERM (a pod being deleted, `docker stop`) counts as the first Ctrl-C.
    if !super::interrupt().await {
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

#[cfg(test)]
mod tests {
    use clap::Parser;

    use super::*;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        run: RunArgs,
    }

    fn parse(args: &[&str]) -> Result<RunArgs, clap::Error> {
        Cli::try_parse_from(["arena", "--tasks", "t"].iter().chain(args)).map(|c| c.run)
    }

    const NAVI: [&str; 6] = ["--agent", "navi", "--llm-url", "http://127.0.0.1:9/v1", "--model", "m"];

    #[test]
    fn each_preset_sets_its_rows_origin_and_backend_and_upstreams_parameters_and_pauses() {
        let rows = [
            ("paper-mixed-omni", SomOrigin::MixedOmni, A11yBackendArg::Uia),
            ("paper-omni", SomOrigin::Omni, A11yBackendArg::Uia),
            ("paper-oss", SomOrigin::Oss, A11yBackendArg::Uia),
            ("paper-a11y-uia", SomOrigin::A11y, A11yBackendArg::Uia),
            ("paper-a11y-win32", SomOrigin::A11y, A11yBackendArg::Win32),
            ("paper-mixed-oss", SomOrigin::MixedOss, A11yBackendArg::Uia),
        ];
        for (name, origin, backend) in rows {
            let mut args = NAVI.to_vec();
            args.extend(["--preset", name, "--waa-root", "/waa", "--stub-guests", "1"]);
            let parsed = parse(&args).unwrap();
            let preset = parsed.preset.expect("a preset");
            assert_eq!(preset.name(), name);
            let applied = preset.apply(&parsed).unwrap();
            assert_eq!((applied.som_origin, applied.a11y_backend), (origin, backend), "{name}");
            assert_eq!((applied.temperature, applied.max_tokens, applied.max_steps), (1.0, 4096, 15), "{name}");
            assert_eq!(applied.navi_style, NaviStyleArg::Waa, "{name}");
            // Upstream's pauses even against stub guests, which would otherwise run fast.
            assert_eq!(applied.pauses, Some(PausesArg::Upstream), "{name}");
            // Only the prompt source and the refusal rule could still differ; neither does.
            let differences = differences_from_upstream(&applied, false);
            let allowed = ["som_origin=", "a11y_backend="];
            assert!(differences.iter().all(|d| allowed.iter().any(|a| d.starts_with(a))), "{name}: {differences:?}");

            // A preset needs the checkout's prompts and the Navi agent.
            let without_root: Vec<&str> = NAVI.iter().copied().chain(["--preset", name]).collect();
            let err = preset.apply(&parse(&without_root).unwrap()).unwrap_err().to_string();
            assert!(err.contains("--waa-root") && err.contains(name), "{err}");
            let scripted = parse(&["--preset", name, "--waa-root", "/waa"]).unwrap();
            assert!(preset.apply(&scripted).unwrap_err().to_string().contains("--agent navi"));
        }
    }

    #[test]
    fn a_preset_refuses_settings_that_would_change_its_row() {
        for extra in [["--som-origin", "oss"], ["--temperature", "0.5"], ["--max-steps", "30"], ["--pauses", "fast"]] {
            let mut args = NAVI.to_vec();
            args.extend(["--preset", "paper-oss", "--waa-root", "/waa"]);
            args.extend(extra);
            let err = parse(&args).err().unwrap_or_else(|| panic!("{extra:?} accepted"));
            assert_eq!(err.kind(), clap::error::ErrorKind::ArgumentConflict, "{extra:?}");
        }
    }

    #[test]
    fn a_default_navi_run_names_every_difference_from_upstreams_default_run() {
        let args = parse(&NAVI).unwrap();
        assert_eq!(
            differences_from_upstream(&args, true),
            [
                "som_origin=a11y (upstream: oss)",
                "prompt=ours (no --waa-root) (upstream: the checkout's)",
                "pauses=fast (none) (upstream: 5 s after the reset and the setup, 3 s after each action)",
            ]
        );
        let mut close = NAVI.to_vec();
        close.extend(["--som-origin", "oss", "--waa-root", "/waa", "--refusals", "answer", "--a11y-backend", "win32"]);
        assert_eq!(
            differences_from_upstream(&parse(&close).unwrap(), false),
            ["a11y_backend=win32 (upstream: uia)", "refusals=answer (upstream: unfinished)"]
        );
    }
}
