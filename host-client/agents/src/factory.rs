//! A run's agent, built from its options: [`build`] checks an [`AgentOptions`]
//! once (so an unusable configuration fails before any task starts) and answers
//! the [`AgentFactory`] that makes a fresh agent per episode, with the result
//! folders' labels and the agent's named options recorded in the results.
//!
//! It builds every agent kind of this layer: scripted, replay, Navi, the
//! computer-use agents, the outside agents over the step protocol and the
//! floor agents (`noop`, `fail`). It is not
//! the command line (`arena_host::cli` turns flags into [`AgentOptions`]), and it does
//! not build the MCP agent, whose endpoint serves HTTP (`arena_host::mcp`, feature
//! `mcp-endpoint`).

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use anyhow::{bail, Context as _};

use arena_actionspace::uitars::UiTarsVersion;
use arena_actionspace::{ActionSpace, Coords};

use super::cu::anthropic::{AnthropicAgent, AnthropicConfig};
use super::cu::models::{Form, ImageLimit, Vendor};
use super::cu::openai::{OpenAiAgent, OpenAiConfig, SafetyChecks};
use super::cu::uitars::{UiTarsAgent, UiTarsConfig};
use super::cu::Endpoint;
use super::external::transport::{HttpAgent, ProcessPool};
use super::external::{Connector, ExternalAgent};
use super::floor::{Floor, FloorAgent};
use super::llm::{ApiKind, Refusals};
use super::navi::{NaviAgent, NaviConfig, NaviStyle};
use super::replay::{ReplayAgent, ReplaySource};
use super::scripted::{Plan, PlanSource, ScriptedAgent};
use super::waa_prompts::WaaPrompts;
use super::{Agent, AgentFactory};
use arena_som::SomOrigin;

/// Which agent plays.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum AgentKind {
    /// Follows plan files (`--plans`), or each task's own `plan` key.
    Scripted,
    /// Repeats recorded trajectories (`--replay`).
    Replay,
    /// Navi-style prompting of an OpenAI-compatible chat endpoint (`--llm-url`, `--model`).
    Navi,
    /// Claude with Anthropic's computer tool over the Messages API (`--llm-url
    /// https://api.anthropic.com`, `--model`; key from ARENA_LLM_KEY or ANTHROPIC_API_KEY).
    AnthropicCu,
    /// OpenAI's computer-use model over the Responses API (`--llm-url https://api.openai.com/v1`,
    /// `--model computer-use-preview`; key from ARENA_LLM_KEY or OPENAI_API_KEY).
    OpenaiCu,
    /// UI-TARS over an OpenAI-compatible chat endpoint such as vLLM (`--llm-url`, `--model`,
    /// `--prompt-file`).
    UiTars,
    /// An agent program speaking the step protocol on its stdin/stdout (`--agent-cmd`).
    Exec,
    /// An agent server taking the step protocol as HTTP POSTs (`--agent-url`).
    Http,
    /// An MCP client driving each episode through the tools served at `--mcp-listen`
    /// (feature `mcp-endpoint`).
    Mcp,
    /// Does nothing: answers DONE at its first step (a task it passes is broken).
    Noop,
    /// Gives up at once: answers FAIL at its first step (the infeasible tasks' floor).
    Fail,
}

/// Where the behaviour constants a run uses come from, whatever `--waa-root` says:
/// this project's code, written from upstream at 6d39ed88 (docs/compatibility.md,
/// "Provenance").
pub const BEHAVIOUR_CONSTANTS: &str = "arena (compiled in, from upstream 6d39ed88; not read from --waa-root)";

/// Upstream's default `--action_space`, the first folder level of its results,
/// under which Navi's results are filed.
pub const DEFAULT_ACTION_SPACE_LABEL: &str = "pyautogui";

/// What a run says about its agent; each field names the `arena run` flag it comes from.
#[derive(Debug, Clone)]
pub struct AgentOptions {
    pub kind: AgentKind,
    /// `--tasks`: where a scripted run looks for its default `plans` folder.
    pub tasks: PathBuf,
    /// `--plans`.
    pub plans: Option<PathBuf>,
    /// `--replay`.
    pub replay: Option<PathBuf>,
    /// `--llm-url`.
    pub llm_url: Option<String>,
    /// `--model`.
    pub model: Option<String>,
    /// `--temperature` (Navi).
    pub temperature: f64,
    /// `--max-tokens`.
    pub max_tokens: u32,
    /// `--navi-style`.
    pub navi_style: NaviStyle,
    /// `--som-origin` (Navi).
    pub som_origin: SomOrigin,
    /// `--detector-url`.
    pub detector_url: Option<String>,
    /// `--omniparser-url`.
    pub omniparser_url: Option<String>,
    /// `--waa-root`: upstream's prompt texts.
    pub waa_root: Option<PathBuf>,
    /// `--refusals` (Navi).
    pub refusals: Refusals,
    /// `--llm-api`: `None` detects Azure by the URL.
    pub llm_api: Option<ApiKind>,
    /// `--llm-timeout`, seconds.
    pub llm_timeout: f64,
    /// `--llm-retry`, seconds.
    pub llm_retry: f64,
    /// `--llm-unreachable`: made once per run and shared by all its agents' model clients.
    pub model_down: super::llm::EndpointDown,
    /// `--coords`: the outside agents' convention unless their `hello` names one.
    pub coords: Coords,
    /// `--computer-tool`; `None` lets the model table choose ([`super::cu::models`]).
    pub computer_tool: Option<super::cu::models::Form>,
    /// `--max-image-side`: the longest side of a screenshot sent to a computer-use model.
    pub max_image_side: Option<u32>,
    /// `--toolset-disable`: members of the computer toolset withheld from the model.
    pub toolset_disable: Vec<String>,
    /// `--zoom`.
    pub zoom: bool,
    /// `--thinking-budget`.
    pub thinking_budget: Option<u32>,
    /// Not `--no-prompt-cache`.
    pub prompt_caching: bool,
    /// `--keep-images`.
    pub keep_images: Option<usize>,
    /// `--safety-checks`.
    pub safety_checks: SafetyChecks,
    /// `--prompt-file` (UI-TARS).
    pub prompt_file: Option<PathBuf>,
    /// `--uitars-version`.
    pub uitars_version: UiTarsVersion,
    /// `--agent-cmd`.
    pub agent_cmd: Option<String>,
    /// `--agent-url`.
    pub agent_url: Option<String>,
    /// `--agent-timeout`, seconds.
    pub agent_timeout: f64,
    /// `--agent-sandbox`, `--agent-network`, `--agent-env`, and the paths an exec agent must not see.
    pub sandbox: super::external::sandbox::SandboxOptions,
}

/// The agent a run plays with.
pub struct ChosenAgent {
    pub factory: AgentFactory,
    /// The action-space level of the result folders.
    pub label: String,
    /// The model level of the result folders.
    pub model: String,
    /// The agent's named options, recorded in the results.
    pub options: Vec<(String, String)>,
    /// What `arena run` checks before the first task ([`Preflight::check`]).
    pub preflight: Option<Preflight>,
}

/// A check of the agent before a run's first task, so that a setup mistake ends
/// the run before any score is written (docs/agents.md, "Preflight").
#[derive(Clone)]
pub enum Preflight {
    /// An outside agent's `hello` round trip (a process started, or a URL answering).
    Hello(Arc<dyn Connector>),
    /// One minimal request to a model agent's endpoint.
    Model(Box<super::llm::ModelClient>, serde_json::Value),
}

impl std::fmt::Debug for Preflight {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Preflight::Hello(c) => write!(f, "Preflight::Hello({})", c.label()),
            Preflight::Model(client, _) => write!(f, "Preflight::Model({})", client.endpoint()),
        }
    }
}

impl Preflight {
    /// A model agent's preflight: `body`, one minimal request of its API.
    pub fn model(client: &super::llm::ModelClient, body: serde_json::Value) -> Preflight {
        Preflight::Model(Box::new(client.clone()), body)
    }

    /// Runs the check: a note when something is off that does not stop the run
    /// (a model endpoint answering 500), and an outside agent's `hello`.
    ///
    /// # Errors
    ///
    /// The agent did not answer its `hello`, or the model endpoint answered 401, 403 or 404.
    pub async fn check(&self) -> anyhow::Result<Checked> {
        match self {
            Preflight::Hello(connector) => match connector.connect().await {
                Ok(transport) => {
                    let hello = transport.hello().clone();
                    connector.release(transport);
                    Ok(Checked { note: None, hello: Some(hello) })
                }
                Err(err) => bail!("the agent {} did not answer its hello: {err}", connector.label()),
            },
            Preflight::Model(client, body) => {
                let note = client.preflight(body).await.map_err(anyhow::Error::msg)?;
                Ok(Checked { note, hello: None })
            }
        }
    }
}

/// What a passed [`Preflight`] learnt.
#[derive(Debug, Clone, Default)]
pub struct Checked {
    /// Something off that does not stop the run.
    pub note: Option<String>,
    /// The outside agent's `hello`: its name, action space and coordinates.
    pub hello: Option<super::external::protocol::AgentHello>,
}

/// The chat-completions request of a preflight: one short user message.
fn chat_probe(model: &str) -> serde_json::Value {
    let mut body = serde_json::json!({"model": model, "messages": [{"role": "user", "content": PROBE_TEXT}]});
    body[super::llm::TokensField::for_model(model).name()] = serde_json::json!(16);
    body
}

/// What a preflight asks a model.
const PROBE_TEXT: &str = "Reply with OK.";

impl std::fmt::Debug for ChosenAgent {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ChosenAgent")
            .field("label", &self.label)
            .field("model", &self.model)
            .field("options", &self.options)
            .finish_non_exhaustive()
    }
}

/// `value` seconds as a duration, naming `flag` when it is not a number of seconds.
fn seconds(value: f64, flag: &str) -> anyhow::Result<Duration> {
    Duration::try_from_secs_f64(value).with_context(|| format!("{flag} must be a number of seconds, 0 or more"))
}

/// The agent `options` choose, checked now.
///
/// # Errors
///
/// A flag the agent needs is missing or unusable (named), a plan, prompt or
/// checkout cannot be read, or the agent is [`AgentKind::Mcp`] (set up by `arena run`).
pub fn build(options: &AgentOptions) -> anyhow::Result<ChosenAgent> {
    match options.kind {
        AgentKind::Scripted => scripted(options),
        AgentKind::Replay => {
            let Some(path) = options.replay.clone() else { bail!("--agent replay needs --replay FILE_OR_DIR") };
            let source = if path.is_dir() { ReplaySource::Dir(path) } else { ReplaySource::File(path) };
            let factory: AgentFactory =
                Arc::new(move || Ok(Box::new(ReplayAgent::new(source.clone())) as Box<dyn Agent>));
            Ok(ChosenAgent {
                factory,
                label: "replay".into(),
                model: "replay".into(),
                options: Vec::new(),
                preflight: None,
            })
        }
        AgentKind::Navi => navi(options),
        AgentKind::AnthropicCu | AgentKind::OpenaiCu | AgentKind::UiTars => computer_use(options),
        AgentKind::Exec | AgentKind::Http => external(options),
        AgentKind::Mcp => bail!("--agent mcp is set up by `arena run` itself"),
        AgentKind::Noop => Ok(floor(Floor::Noop)),
        AgentKind::Fail => Ok(floor(Floor::Fail)),
    }
}

/// `noop` or `fail`: both folder levels name the floor, so their results never
/// share a folder with another agent's.
fn floor(floor: Floor) -> ChosenAgent {
    let factory: AgentFactory = Arc::new(move || Ok(Box::new(FloorAgent::new(floor)) as Box<dyn Agent>));
    ChosenAgent {
        factory,
        label: floor.name().into(),
        model: floor.name().into(),
        options: Vec::new(),
        preflight: None,
    }
}

/// Where the scripted agent of `options` finds its plans: `--plans` (a file for
/// every task, or a folder), else the `plans` folder beside `--tasks` when it
/// exists, else each task's own `plan` key.
///
/// # Errors
///
/// `--plans` names a plan file that does not load.
pub fn plan_source(options: &AgentOptions) -> anyhow::Result<PlanSource> {
    let default_dir = if options.tasks.is_dir() {
        Some(options.tasks.join("plans"))
    } else {
        options.tasks.parent().map(|p| p.join("plans"))
    };
    Ok(match &options.plans {
        Some(path) if path.is_dir() => PlanSource::Dir(path.clone()),
        Some(path) => PlanSource::Fixed(Plan::load(path)?),
        None => match default_dir.filter(|d| d.is_dir()) {
            Some(dir) => PlanSource::Dir(dir),
            None => PlanSource::TaskKey,
        },
    })
}

fn scripted(options: &AgentOptions) -> anyhow::Result<ChosenAgent> {
    let source = plan_source(options)?;
    let factory: AgentFactory = Arc::new(move || Ok(Box::new(ScriptedAgent::new(source.clone())) as Box<dyn Agent>));
    Ok(ChosenAgent { factory, label: "scripted".into(), model: "plan".into(), options: Vec::new(), preflight: None })
}

fn navi(options: &AgentOptions) -> anyhow::Result<ChosenAgent> {
    let (Some(url), Some(model)) = (options.llm_url.clone(), options.model.clone()) else {
        bail!("--agent navi needs --llm-url (or ARENA_LLM_URL) and --model (or ARENA_LLM_MODEL)");
    };
    let mut config = NaviConfig::new(&url, &model);
    config.temperature = options.temperature;
    config.max_tokens = options.max_tokens;
    config.style = options.navi_style;
    if let Some(root) = &options.waa_root {
        let prompts = WaaPrompts::load(root)
            .with_context(|| format!("reading Navi's prompts from the WAA checkout {}", root.display()))?;
        config.waa_prompts = Some(Arc::new(prompts));
    }
    // Which prompt text runs: upstream's from a checkout (`waa@<commit>`) or ours.
    let (style, prompt) = match (config.style, &config.waa_prompts) {
        (NaviStyle::Waa, Some(prompts)) => ("waa", prompts.source.clone()),
        (NaviStyle::Waa, None) => ("waa", "arena".to_owned()),
        (NaviStyle::Arena, _) => ("arena", "arena".to_owned()),
    };
    config.som.origin = options.som_origin;
    config.som.detector_url = options.detector_url.clone();
    config.som.omniparser_url = options.omniparser_url.clone();
    config.refusals = options.refusals;
    let recorded = vec![
        ("navi_style".to_owned(), style.to_owned()),
        ("som_origin".to_owned(), options.som_origin.name().to_owned()),
        ("prompt".to_owned(), prompt),
        // Only the prompt texts follow --waa-root; every behaviour constant
        // (pauses, step cap, budgets, image sizes, colours) is compiled in.
        ("behaviour_constants".to_owned(), BEHAVIOUR_CONSTANTS.to_owned()),
        ("temperature".to_owned(), format!("{}", options.temperature)),
        ("max_tokens".to_owned(), options.max_tokens.to_string()),
        ("refusals".to_owned(), config.refusals.name().to_owned()),
    ];
    config.api = options.llm_api;
    config.timeout = seconds(options.llm_timeout, "--llm-timeout")?;
    config.retry.give_up_after = seconds(options.llm_retry, "--llm-retry")?;
    config.down = options.model_down.clone();
    // Fail now, not once per task, when the configuration is unusable.
    let probe = NaviAgent::new(config.clone())?;
    let preflight = Some(Preflight::model(probe.client(), chat_probe(&model)));
    let factory: AgentFactory = Arc::new(move || Ok(Box::new(NaviAgent::new(config.clone())?) as Box<dyn Agent>));
    // Upstream files Navi's results under its action space.
    Ok(ChosenAgent { factory, label: DEFAULT_ACTION_SPACE_LABEL.into(), model, options: recorded, preflight })
}

/// The endpoint options the computer-use agents share with Navi's.
fn cu_endpoint(options: &AgentOptions, name: &str) -> anyhow::Result<Endpoint> {
    let (Some(url), Some(model)) = (options.llm_url.clone(), options.model.clone()) else {
        bail!("--agent {name} needs --llm-url (or ARENA_LLM_URL) and --model (or ARENA_LLM_MODEL)");
    };
    let mut endpoint = Endpoint::new(&url, &model);
    endpoint.timeout = seconds(options.llm_timeout, "--llm-timeout")?;
    endpoint.retry.give_up_after = seconds(options.llm_retry, "--llm-retry")?;
    endpoint.down = options.model_down.clone();
    endpoint.max_tokens = options.max_tokens;
    Ok(endpoint)
}

/// Options to record, by name.
type Recorded = Vec<(String, String)>;

/// The tool form and screenshot limit of a computer-use run: `--computer-tool`
/// and `--max-image-side` when given, else the model table's row for `model`
/// (a model it does not know gets the newest form, and a notice). Answers them
/// with the options to record: `computer_tool` and `image_limit`, each with where
/// it came from.
///
/// # Errors
///
/// A `--computer-tool` of the other vendor's API, or a `--max-image-side` below 64.
fn form_and_image(options: &AgentOptions, vendor: Vendor, model: &str) -> anyhow::Result<(Form, ImageLimit, Recorded)> {
    let choice = super::cu::models::choose(vendor, model);
    let form = match options.computer_tool {
        Some(form) if form.vendor() != vendor => {
            let theirs: Vec<&str> = Form::ALL.iter().filter(|f| f.vendor() == vendor).map(|f| f.name()).collect();
            bail!("--computer-tool {} is not a tool of this agent's API (it takes {})", form.name(), theirs.join(", "))
        }
        Some(form) => (form, "--computer-tool"),
        None => {
            if let Some(notice) = &choice.notice {
                tracing::warn!("{notice}");
            }
            (choice.form, if choice.notice.is_some() { "newest, model not in the table" } else { "model table" })
        }
    };
    let image = match options.max_image_side {
        Some(side) if side < 64 => bail!("--max-image-side {side} is too small to see a desktop (at least 64)"),
        Some(side) => (ImageLimit::Within { side, pixels: u64::from(side) * u64::from(side) }, "--max-image-side"),
        None if form.0 != choice.form => {
            // A form the table would not give this model: the form's own default limit.
            let of_form = super::cu::models::ANTHROPIC
                .iter()
                .chain(super::cu::models::OPENAI)
                .find(|row| row.form == form.0)
                .map_or(choice.image, |row| row.image);
            (of_form, "the tool's default")
        }
        None => (choice.image, if choice.notice.is_some() { "newest, model not in the table" } else { "model table" }),
    };
    let recorded = vec![
        ("computer_tool".to_owned(), format!("{} ({})", form.0.name(), form.1)),
        ("image_limit".to_owned(), format!("{} ({})", image.0.describe(), image.1)),
    ];
    Ok((form.0, image.0, recorded))
}

/// `anthropic-cu`, `openai-cu` and `ui-tars`.
fn computer_use(options: &AgentOptions) -> anyhow::Result<ChosenAgent> {
    let option = |k: &str, v: String| (k.to_owned(), v);
    let model = options.model.clone().unwrap_or_default();
    #[allow(clippy::type_complexity)]
    let (factory, space, coords, mut recorded, preflight): (
        AgentFactory,
        ActionSpace,
        String,
        Vec<(String, String)>,
        Preflight,
    ) = match options.kind {
        AgentKind::AnthropicCu => {
            let (form, image, mut recorded) = form_and_image(options, Vendor::Anthropic, &model)?;
            let mut config = AnthropicConfig::new("", "");
            config.endpoint = cu_endpoint(options, "anthropic-cu")?;
            config.tool = form;
            config.image = image;
            config.disabled_members = options.toolset_disable.clone();
            config.enable_zoom = options.zoom;
            config.thinking_budget = options.thinking_budget;
            config.prompt_caching = options.prompt_caching;
            config.keep_images = options.keep_images.unwrap_or(config.keep_images);
            let probe = AnthropicAgent::new(config.clone())?;
            let body = serde_json::json!({"model": model, "max_tokens": 16, "messages": [{"role": "user", "content": PROBE_TEXT}]});
            let preflight = Preflight::model(probe.client(), body);
            recorded.extend([
                option("keep_images", config.keep_images.to_string()),
                option("thinking_budget", config.thinking_budget.map_or("off".into(), |b| b.to_string())),
                option("prompt_caching", if config.prompt_caching { "on" } else { "off" }.into()),
                option("zoom", if config.enable_zoom { "on" } else { "off" }.into()),
            ]);
            if !config.disabled_members.is_empty() {
                recorded.push(option("toolset_disable", config.disabled_members.join(",")));
            }
            let space = config.space();
            let coords = format!("image:{}", config.image.describe());
            let factory: AgentFactory =
                Arc::new(move || Ok(Box::new(AnthropicAgent::new(config.clone())?) as Box<dyn Agent>));
            (factory, space, coords, recorded, preflight)
        }
        AgentKind::OpenaiCu => {
            let (form, image, mut recorded) = form_and_image(options, Vendor::OpenAi, &model)?;
            let mut config = OpenAiConfig::new("", "");
            config.endpoint = cu_endpoint(options, "openai-cu")?;
            config.safety_checks = options.safety_checks;
            config.tool = form;
            config.image = image;
            let probe = OpenAiAgent::new(config.clone())?;
            let body = serde_json::json!({"model": model, "input": PROBE_TEXT, "max_output_tokens": 16});
            let preflight = Preflight::model(probe.client(), body);
            recorded.push(option("safety_checks", config.safety_checks.name().into()));
            let coords = format!("image:{}", config.image.describe());
            let factory: AgentFactory =
                Arc::new(move || Ok(Box::new(OpenAiAgent::new(config.clone())?) as Box<dyn Agent>));
            (factory, ActionSpace::OpenAi, coords, recorded, preflight)
        }
        _ => {
            let Some(path) = &options.prompt_file else {
                bail!("--agent ui-tars needs --prompt-file: the UI-TARS prompt template, as its project publishes it");
            };
            let template = UiTarsConfig::read_prompt(path)?;
            let mut config = UiTarsConfig::new("", "", &template);
            config.endpoint = cu_endpoint(options, "ui-tars")?;
            config.version = options.uitars_version;
            config.history_images = options.keep_images.unwrap_or(config.history_images);
            let probe = UiTarsAgent::new(config.clone())?;
            let preflight = Preflight::model(probe.client(), chat_probe(&model));
            let coords = match config.version {
                UiTarsVersion::V1 => Coords::Grid1000.name(),
                UiTarsVersion::V1_5 => "image:smart-resize".into(),
            };
            let recorded = vec![
                option("uitars_version", config.version.name().into()),
                option("keep_images", config.history_images.to_string()),
                option("prompt_file", path.display().to_string()),
            ];
            let factory: AgentFactory =
                Arc::new(move || Ok(Box::new(UiTarsAgent::new(config.clone())?) as Box<dyn Agent>));
            (factory, ActionSpace::UiTars, coords, recorded, preflight)
        }
    };
    recorded.push(option("action_space", space.name().into()));
    recorded.push(option("coords", coords));
    Ok(ChosenAgent { factory, label: space.name().into(), model, options: recorded, preflight: Some(preflight) })
}

/// The first 8 hex digits of the SHA-256 of `text`: a short, stable name for an
/// outside agent's command or URL.
pub fn fingerprint(text: &str) -> String {
    use sha2::Digest as _;
    sha2::Sha256::digest(text.as_bytes()).iter().take(4).map(|b| format!("{b:02x}")).collect()
}

/// The longest wait for one answer of an outside agent (`--agent-timeout`).
///
/// # Errors
///
/// Not a number of seconds, or 0.
pub fn agent_timeout(seconds_given: f64) -> anyhow::Result<Duration> {
    let timeout = seconds(seconds_given, "--agent-timeout")?;
    if timeout.is_zero() {
        bail!("--agent-timeout must be more than 0 seconds");
    }
    Ok(timeout)
}

/// `exec` or `http`: an outside agent over the step protocol.
fn external(options: &AgentOptions) -> anyhow::Result<ChosenAgent> {
    let timeout = agent_timeout(options.agent_timeout)?;
    let http = options.kind == AgentKind::Http;
    let (connector, label, option): (Arc<dyn Connector>, &str, (String, String)) = if http {
        let Some(url) = &options.agent_url else { bail!("--agent http needs --agent-url URL (or ARENA_AGENT_URL)") };
        let agent = HttpAgent::new(url, timeout).map_err(anyhow::Error::msg)?;
        (Arc::new(agent), "http", ("agent_url".to_owned(), url.clone()))
    } else {
        let Some(cmd) = &options.agent_cmd else { bail!("--agent exec needs --agent-cmd \"PROGRAM ARGS\"") };
        let mut pool = ProcessPool::new(cmd).map_err(anyhow::Error::msg)?;
        if let Some(sandbox) = super::external::sandbox::Sandbox::new(&options.sandbox).map_err(anyhow::Error::msg)? {
            pool = pool.with_sandbox(sandbox);
        }
        (Arc::new(pool), "exec", ("agent_cmd".to_owned(), cmd.clone()))
    };
    let mut recorded = vec![
        option,
        ("agent_protocol".to_owned(), super::external::protocol::PROTOCOL_VERSION.to_string()),
        ("agent_timeout".to_owned(), format!("{}", options.agent_timeout)),
    ];
    if !http {
        recorded.extend(options.sandbox.recorded());
    }
    let coords = options.coords;
    let preflight = Some(Preflight::Hello(Arc::clone(&connector)));
    let factory: AgentFactory = Arc::new(move || {
        Ok(Box::new(ExternalAgent::new(label, Arc::clone(&connector), timeout).with_coords(coords)) as Box<dyn Agent>)
    });
    // The model level names the agent: a different command or URL is another folder.
    let model = options.model.clone().unwrap_or_else(|| format!("external-{}", fingerprint(&recorded[0].1)));
    Ok(ChosenAgent { factory, label: label.to_owned(), model, options: recorded, preflight })
}
