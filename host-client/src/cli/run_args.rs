//! The arguments of `arena run`, `merge`, `report` and `compare` (and the parts
//! `arena certify` and `arena env serve` share): clap's definitions and the value
//! parsers, nothing else. What they mean is resolved in `runs` (the run driver's
//! plan) and `preset`.

use std::path::PathBuf;

use clap::Args;

use crate::run::shard::Shard;
use arena_actionspace::Coords;
use arena_agents::cu::openai::SafetyChecks;
use arena_agents::factory::AgentKind;
use arena_som::SomOrigin;
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
    /// Model agents: a model endpoint where nothing answers (connection refused, a
    /// host name that does not resolve). `stop`: the preflight ends the run before
    /// any task, and during the run, once one call has waited its --llm-retry window
    /// for it, later calls give up at once and after three such calls in a row no new
    /// task starts. `wait`: every call waits its whole window.
    #[arg(long, value_enum, default_value_t = LlmUnreachable::Stop, value_name = "POLICY")]
    pub llm_unreachable: LlmUnreachable,
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
    pub fn form(self) -> arena_agents::cu::models::Form {
        use arena_agents::cu::models::Form;
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

/// `--llm-unreachable`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum LlmUnreachable {
    Stop,
    Wait,
}

impl LlmUnreachable {
    pub fn policy(self) -> arena_agents::llm::Unreachable {
        match self {
            LlmUnreachable::Stop => arena_agents::llm::Unreachable::Stop,
            LlmUnreachable::Wait => arena_agents::llm::Unreachable::Wait,
        }
    }
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
