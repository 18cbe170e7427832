//! WAA task files (`arena-task`): loading, validation, the task model and
//! upstream's vocabulary. The bottom of the harness's layers: the setup steps
//! (`arena-setup`) and the evaluators (`arena-eval`) are built on its types, and
//! it knows neither.
//!
//! Files are read in two layers. `raw` mirrors upstream's JSON as written
//! (stray keys such as `_comments` accepted); [`Task::from_data`] checks it and
//! builds the model: typed [`SetupStep`]s, and an [`Evaluator`] whose getter and
//! metric names are known upstream names ([`names`]). An unknown step, getter or
//! metric fails here, at load time, with the file and the name, never mid-episode.
//! Whether this build *implements* a name is the evaluators' registry's business,
//! checked against [`names`] by their own tests and reported by `arena validate`.
//!
//! This crate does no network or guest I/O.

#![forbid(unsafe_code)]

pub mod gold;
pub mod names;
mod raw;

use std::path::{Path, PathBuf};

use serde_json::{Map, Value};

use raw::{EvaluatorData, OneOrMany, StepData, TaskData};

/// A task file could not be used. Always names the file.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum TaskError {
    #[error("{path}: {source}")]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: invalid JSON: {message}")]
    Json { path: PathBuf, message: String },
    #[error("{path}: {message}")]
    Invalid { path: PathBuf, message: String },
}

/// Largest task file read (upstream's biggest is a few KB): 4 MiB.
pub const MAX_TASK_FILE_BYTES: u64 = 4 << 20;
/// Largest index file read (upstream's `test_all.json` is 12 KB): 16 MiB.
pub const MAX_INDEX_FILE_BYTES: u64 = 16 << 20;
/// Longest instruction, in bytes (upstream's longest is under 1 KB; it goes into every
/// prompt and every result file): 64 KiB.
pub const MAX_INSTRUCTION_BYTES: usize = 64 << 10;

/// Reads `path` as text, refusing a file over `cap` bytes before reading it (and a
/// file that grows past it while it is read).
fn read_capped(path: &Path, cap: u64, what: &str) -> Result<String, TaskError> {
    use std::io::Read as _;
    let read_err = |source| TaskError::Read { path: path.to_owned(), source };
    let file = std::fs::File::open(path).map_err(read_err)?;
    let too_big = |size: u64| TaskError::Invalid {
        path: path.to_owned(),
        message: format!("the {what} is {size} bytes; at most {cap} are read"),
    };
    let size = file.metadata().map_err(read_err)?.len();
    if size > cap {
        return Err(too_big(size));
    }
    let mut text = String::new();
    file.take(cap + 1).read_to_string(&mut text).map_err(read_err)?;
    if text.len() as u64 > cap {
        return Err(too_big(text.len() as u64));
    }
    Ok(text)
}

/// Checks that an index's domain or task id names one file in one folder: not empty,
/// no path separator, no `..`, no drive or absolute path, no NUL.
fn check_index_name(name: &str, what: &str) -> Result<(), String> {
    let shown: String = name.chars().take(80).collect();
    if name.trim().is_empty() {
        return Err(format!("an index {what} is empty"));
    }
    if name.contains(['/', '\\', ':', '\0']) || name == "." || name == ".." || name.contains("..") {
        return Err(format!(
            "the index {what} {shown:?} is not a plain name (no path separators, drive letters or `..`); \
             index entries are task ids, resolved inside the corpus"
        ));
    }
    if Path::new(name).is_absolute() || Path::new(name).components().count() != 1 {
        return Err(format!("the index {what} {shown:?} is not a plain name"));
    }
    Ok(())
}

/// Task difficulty: which folder of the corpus a task index resolves into.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Difficulty {
    /// `examples/`.
    #[default]
    Normal,
    /// `examples_noctxt/` (upstream's `--diff_lvl hard`).
    Hard,
}

impl Difficulty {
    pub fn folder(self) -> &'static str {
        match self {
            Difficulty::Normal => "examples",
            Difficulty::Hard => "examples_noctxt",
        }
    }
}

/// A program and its arguments, as a task writes them: one string or a list.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum CommandArg {
    Str(String),
    List(Vec<String>),
}

/// A file to download into the guest.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DownloadFile {
    pub url: String,
    /// Guest path.
    pub path: String,
}

/// The `until` condition of an `execute` step: repeat until one of these matches.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Until {
    pub returncode: Option<i64>,
    pub stdout: Option<String>,
    pub stderr: Option<String>,
}

/// Which browser a history step writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Browser {
    Chrome,
    Edge,
}

/// One visit of a browse-history step.
#[derive(Debug, Clone, PartialEq)]
pub struct HistoryEntry {
    pub url: String,
    pub title: String,
    pub visit_time_from_now_in_seconds: f64,
}

/// A setup step (`config` or `evaluator.postconfig`), with upstream's parameters and defaults.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum SetupStep {
    /// `launch`: start a program through the shell, never wait.
    Launch { command: CommandArg, shell: bool },
    /// `download`: the host fetches (cached) and uploads.
    Download { files: Vec<DownloadFile> },
    /// `sleep` on the host.
    Sleep { seconds: f64 },
    /// `open`: open a guest file with its program.
    Open { path: String },
    /// `activate_window`.
    ActivateWindow { window_name: String, strict: bool, by_class: bool },
    /// `execute` and its alias `command`.
    Execute { command: CommandArg, shell: bool, stdout: Option<String>, stderr: Option<String>, until: Option<Until> },
    /// `create_folder`.
    CreateFolder { path: String },
    /// `recycle_file`.
    RecycleFile { path: String },
    /// `chrome_open_tabs` (and `edge_open_tabs`).
    OpenTabs { urls: Vec<String> },
    /// `chrome_close_tabs`.
    CloseTabs { urls: Vec<String> },
    /// `update_browse_history` and `update_browse_history_edge`.
    UpdateBrowseHistory { browser: Browser, history: Vec<HistoryEntry> },
    /// `upload_file`: host files into the guest.
    UploadFile { files: Vec<(PathBuf, String)> },
    /// `change_wallpaper`.
    ChangeWallpaper { path: String },
    /// `close_window`.
    CloseWindow { window_name: String, strict: bool, by_class: bool },
    /// `create_file`.
    CreateFile { path: String, content: String },
    /// `close_all`.
    CloseAll,
}

impl SetupStep {
    /// The step's type name as a task writes it (`command` reads as `execute`).
    pub fn kind(&self) -> &'static str {
        match self {
            SetupStep::Launch { .. } => "launch",
            SetupStep::Download { .. } => "download",
            SetupStep::Sleep { .. } => "sleep",
            SetupStep::Open { .. } => "open",
            SetupStep::ActivateWindow { .. } => "activate_window",
            SetupStep::Execute { .. } => "execute",
            SetupStep::CreateFolder { .. } => "create_folder",
            SetupStep::RecycleFile { .. } => "recycle_file",
            SetupStep::OpenTabs { .. } => "chrome_open_tabs",
            SetupStep::CloseTabs { .. } => "chrome_close_tabs",
            SetupStep::UpdateBrowseHistory { browser: Browser::Chrome, .. } => "update_browse_history",
            SetupStep::UpdateBrowseHistory { browser: Browser::Edge, .. } => "update_browse_history_edge",
            SetupStep::UploadFile { .. } => "upload_file",
            SetupStep::ChangeWallpaper { .. } => "change_wallpaper",
            SetupStep::CloseWindow { .. } => "close_window",
            SetupStep::CreateFile { .. } => "create_file",
            SetupStep::CloseAll => "close_all",
        }
    }
}

/// A getter call: `{"type": "vm_file", "path": ..., "dest": ...}`.
#[derive(Debug, Clone, PartialEq)]
pub struct GetterSpec {
    /// The getter name (`type`), a known upstream name.
    pub kind: String,
    /// Every other key of the object.
    pub params: Map<String, Value>,
}

/// One metric with its getters and options.
#[derive(Debug, Clone, PartialEq)]
pub struct MetricCall {
    /// Metric name (`func`), a known upstream name.
    pub metric: String,
    pub result: Option<GetterSpec>,
    pub expected: Option<GetterSpec>,
    pub options: Map<String, Value>,
}

/// How several metrics combine (`conj`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Conj {
    /// Every metric must pass: stop at the first 0; the score is the mean.
    #[default]
    And,
    /// One metric is enough: stop at the first 1; the score is the max.
    Or,
}

/// What decides the score.
#[derive(Debug, Clone, PartialEq)]
pub enum Scoring {
    /// `func: "infeasible"`: 1 when the agent said FAIL, else 0.
    Infeasible,
    /// One or more metrics. `listed`: `func` was a list (upstream's `evaluate`
    /// then takes its list path, whose failure rules differ from one metric's).
    Metrics { conj: Conj, calls: Vec<MetricCall>, listed: bool },
}

/// The `evaluator` object.
#[derive(Debug, Clone, PartialEq)]
pub struct Evaluator {
    pub postconfig: Vec<SetupStep>,
    pub scoring: Scoring,
}

/// A validated task.
#[derive(Debug, Clone, PartialEq)]
pub struct Task {
    /// The `id` field (may differ from the file stem upstream; see [`Task::name`]).
    pub id: String,
    /// The file stem, which is what upstream's runner uses to name and find the task.
    pub name: String,
    /// The domain (the task's folder: `chrome`, `libreoffice_calc`, ...).
    pub domain: String,
    pub path: PathBuf,
    pub instruction: String,
    pub snapshot: Option<String>,
    pub related_apps: Vec<String>,
    pub config: Vec<SetupStep>,
    pub evaluator: Evaluator,
    /// Top-level keys the model does not use (`trajectory`, `_comments`, `source`, ...), kept as written.
    pub extra: Map<String, Value>,
}

impl Task {
    /// The order tasks are listed and sharded in: domain, then name, then path
    /// (for two files of one name).
    pub fn order_key(&self) -> (&str, &str, &Path) {
        (&self.domain, &self.name, &self.path)
    }

    /// Loads and validates one task file. The domain is the name of its folder.
    ///
    /// # Errors
    ///
    /// [`TaskError`] naming the file and what is wrong (unreadable, bad JSON,
    /// unknown step/getter/metric, missing or mistyped parameter).
    pub fn load(path: &Path) -> Result<Task, TaskError> {
        let text = read_capped(path, MAX_TASK_FILE_BYTES, "task file")?;
        Task::parse(&text, path)
    }

    /// Parses a task from its text; `path` names it in errors and gives its name and domain.
    ///
    /// # Errors
    ///
    /// See [`Task::load`].
    pub fn parse(text: &str, path: &Path) -> Result<Task, TaskError> {
        let data: TaskData = serde_json::from_str(text)
            .map_err(|err| TaskError::Json { path: path.to_owned(), message: err.to_string() })?;
        Task::from_data(data, path).map_err(|message| TaskError::Invalid { path: path.to_owned(), message })
    }

    fn from_data(data: TaskData, path: &Path) -> Result<Task, String> {
        if data.instruction.len() > MAX_INSTRUCTION_BYTES {
            return Err(format!(
                "the instruction is {} bytes; at most {MAX_INSTRUCTION_BYTES} are accepted",
                data.instruction.len()
            ));
        }
        let name = path.file_stem().and_then(|s| s.to_str()).unwrap_or(&data.id).to_owned();
        let domain = path.parent().and_then(|p| p.file_name()).and_then(|s| s.to_str()).unwrap_or("").to_owned();
        let config = steps(&data.config, "config")?;
        let evaluator = evaluator(data.evaluator)?;
        let mut extra = data.extra;
        if let Some(source) = data.source {
            extra.insert("source".into(), source);
        }
        Ok(Task {
            id: data.id,
            name,
            domain,
            path: path.to_owned(),
            instruction: data.instruction,
            snapshot: data.snapshot,
            related_apps: data.related_apps,
            config,
            evaluator,
            extra,
        })
    }

    /// Every setup step type, getter and metric this task names, for `validate`.
    pub fn needs(&self) -> TaskNeeds {
        let mut needs = TaskNeeds::default();
        for step in self.config.iter().chain(&self.evaluator.postconfig) {
            push_unique(&mut needs.steps, step.kind());
        }
        if let Scoring::Metrics { calls, .. } = &self.evaluator.scoring {
            for call in calls {
                push_unique(&mut needs.metrics, &call.metric);
                for getter in call.result.iter().chain(&call.expected) {
                    push_unique(&mut needs.getters, &getter.kind);
                }
            }
        } else {
            push_unique(&mut needs.metrics, "infeasible");
        }
        needs.apps = self.related_apps.clone();
        needs
    }
}

/// What a task needs from this build.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct TaskNeeds {
    pub steps: Vec<String>,
    pub getters: Vec<String>,
    pub metrics: Vec<String>,
    pub apps: Vec<String>,
}

fn push_unique(list: &mut Vec<String>, item: &str) {
    if !list.iter().any(|it| it == item) {
        list.push(item.to_owned());
    }
}

fn steps(data: &[StepData], place: &str) -> Result<Vec<SetupStep>, String> {
    data.iter()
        .enumerate()
        .map(|(idx, step)| setup_step(step).map_err(|err| format!("{place}[{idx}] ({}): {err}", step.kind)))
        .collect()
}

fn setup_step(step: &StepData) -> Result<SetupStep, String> {
    let p = Params(&step.parameters);
    let res = match step.kind.as_str() {
        "launch" => SetupStep::Launch { command: p.command("command")?, shell: p.truthy("shell") },
        "download" => SetupStep::Download {
            files: p
                .list("files")?
                .iter()
                .enumerate()
                .map(|(idx, file)| {
                    let file = file.as_object().ok_or_else(|| format!("files[{idx}] is not an object"))?;
                    let f = Params(file);
                    Ok(DownloadFile { url: f.string("url")?, path: f.string("path")? })
                })
                .collect::<Result<_, String>>()?,
        },
        "sleep" => {
            let seconds = p.number("seconds")?;
            if !(0.0..=86_400.0).contains(&seconds) {
                return Err(format!("`seconds` must be between 0 and 86400, not {seconds}"));
            }
            SetupStep::Sleep { seconds }
        }
        "open" => SetupStep::Open { path: p.string("path")? },
        "activate_window" => SetupStep::ActivateWindow {
            window_name: p.string("window_name")?,
            strict: p.truthy("strict"),
            by_class: p.truthy("by_class"),
        },
        "close_window" => SetupStep::CloseWindow {
            window_name: p.string("window_name")?,
            strict: p.truthy("strict"),
            by_class: p.truthy("by_class"),
        },
        "execute" | "command" => SetupStep::Execute {
            command: p.command("command")?,
            shell: p.truthy("shell"),
            stdout: p.opt_string("stdout")?.filter(|s| !s.is_empty()),
            stderr: p.opt_string("stderr")?.filter(|s| !s.is_empty()),
            until: match step.parameters.get("until") {
                None | Some(Value::Null) => None,
                Some(Value::Object(until)) => {
                    let u = Params(until);
                    Some(Until {
                        returncode: match until.get("returncode") {
                            None | Some(Value::Null) => None,
                            Some(v) => Some(v.as_i64().ok_or("`until.returncode` must be an integer")?),
                        },
                        stdout: u.opt_string("stdout")?,
                        stderr: u.opt_string("stderr")?,
                    })
                }
                Some(_) => return Err("`until` must be an object".into()),
            },
        },
        "create_folder" => SetupStep::CreateFolder { path: p.string("path")? },
        "recycle_file" => SetupStep::RecycleFile { path: p.string("path")? },
        "chrome_open_tabs" | "edge_open_tabs" => SetupStep::OpenTabs { urls: p.strings("urls_to_open")? },
        "chrome_close_tabs" => SetupStep::CloseTabs { urls: p.strings("urls_to_close")? },
        "update_browse_history" | "update_browse_history_edge" => SetupStep::UpdateBrowseHistory {
            browser: if step.kind.ends_with("_edge") { Browser::Edge } else { Browser::Chrome },
            history: p
                .list("history")?
                .iter()
                .enumerate()
                .map(|(idx, entry)| {
                    let entry = entry.as_object().ok_or_else(|| format!("history[{idx}] is not an object"))?;
                    let e = Params(entry);
                    Ok(HistoryEntry {
                        url: e.string("url")?,
                        title: e.string("title")?,
                        visit_time_from_now_in_seconds: e.number("visit_time_from_now_in_seconds")?,
                    })
                })
                .collect::<Result<_, String>>()?,
        },
        "upload_file" => SetupStep::UploadFile {
            files: p
                .list("files")?
                .iter()
                .enumerate()
                .map(|(idx, file)| {
                    let file = file.as_object().ok_or_else(|| format!("files[{idx}] is not an object"))?;
                    let f = Params(file);
                    Ok((PathBuf::from(f.string("local_path")?), f.string("path")?))
                })
                .collect::<Result<_, String>>()?,
        },
        "change_wallpaper" => SetupStep::ChangeWallpaper { path: p.string("path")? },
        "create_file" => {
            SetupStep::CreateFile { path: p.string("path")?, content: p.opt_string("content")?.unwrap_or_default() }
        }
        "close_all" => SetupStep::CloseAll,
        other => return Err(format!("unknown setup step type `{other}` (known: {})", names::SETUP_STEPS.join(", "))),
    };
    Ok(res)
}

/// Typed access to a step's or getter's parameters, with errors naming the key.
struct Params<'a>(&'a Map<String, Value>);

impl Params<'_> {
    fn get(&self, key: &str) -> Result<&Value, String> {
        self.0.get(key).ok_or_else(|| format!("missing parameter `{key}`"))
    }

    fn string(&self, key: &str) -> Result<String, String> {
        match self.get(key)? {
            Value::String(s) => Ok(s.clone()),
            other => Err(format!("`{key}` must be a string, not {}", kind_of(other))),
        }
    }

    fn opt_string(&self, key: &str) -> Result<Option<String>, String> {
        match self.0.get(key) {
            None | Some(Value::Null) => Ok(None),
            Some(Value::String(s)) => Ok(Some(s.clone())),
            Some(other) => Err(format!("`{key}` must be a string, not {}", kind_of(other))),
        }
    }

    fn number(&self, key: &str) -> Result<f64, String> {
        match self.get(key)? {
            Value::Number(n) => n.as_f64().ok_or_else(|| format!("`{key}` is not a finite number")),
            other => Err(format!("`{key}` must be a number, not {}", kind_of(other))),
        }
    }

    fn list(&self, key: &str) -> Result<&Vec<Value>, String> {
        match self.get(key)? {
            Value::Array(items) => Ok(items),
            other => Err(format!("`{key}` must be a list, not {}", kind_of(other))),
        }
    }

    fn strings(&self, key: &str) -> Result<Vec<String>, String> {
        self.list(key)?
            .iter()
            .enumerate()
            .map(|(idx, v)| v.as_str().map(str::to_owned).ok_or_else(|| format!("`{key}[{idx}]` must be a string")))
            .collect()
    }

    fn command(&self, key: &str) -> Result<CommandArg, String> {
        match self.get(key)? {
            Value::String(s) => Ok(CommandArg::Str(s.clone())),
            Value::Array(items) => items
                .iter()
                .enumerate()
                .map(|(idx, v)| v.as_str().map(str::to_owned).ok_or_else(|| format!("`{key}[{idx}]` must be a string")))
                .collect::<Result<_, _>>()
                .map(CommandArg::List),
            other => Err(format!("`{key}` must be a string or a list of strings, not {}", kind_of(other))),
        }
    }

    /// Python truthiness, as upstream's server applies it (`"false"` is true).
    fn truthy(&self, key: &str) -> bool {
        match self.0.get(key) {
            None | Some(Value::Null) | Some(Value::Bool(false)) => false,
            Some(Value::Bool(true)) => true,
            Some(Value::Number(n)) => n.as_f64().is_some_and(|f| f != 0.0),
            Some(Value::String(s)) => !s.is_empty(),
            Some(Value::Array(a)) => !a.is_empty(),
            Some(Value::Object(o)) => !o.is_empty(),
        }
    }
}

use arena_shared::error::json_kind as kind_of;

fn evaluator(data: EvaluatorData) -> Result<Evaluator, String> {
    let postconfig = steps(&data.postconfig, "evaluator.postconfig")?;
    let listed = data.func.is_many();
    let funcs = data.func.into_vec();
    for func in &funcs {
        if !names::METRICS.contains(&func.as_str()) {
            return Err(format!("unknown metric `{func}` in evaluator.func"));
        }
    }
    if !listed && funcs.first().map(String::as_str) == Some("infeasible") {
        return Ok(Evaluator { postconfig, scoring: Scoring::Infeasible });
    }
    let conj = match data.conj.as_deref() {
        None | Some("and") => Conj::And,
        Some("or") => Conj::Or,
        Some(other) => return Err(format!("evaluator.conj must be \"and\" or \"or\", not {other:?}")),
    };
    let n = funcs.len();
    let spread = |field: &str, value: Option<OneOrMany<Value>>| -> Result<Vec<Value>, String> {
        match value {
            None => Ok(vec![Value::Null; n]),
            Some(OneOrMany::Many(items)) if listed => {
                if items.len() != n {
                    return Err(format!("evaluator.{field} has {} entries for {n} metrics", items.len()));
                }
                Ok(items)
            }
            Some(OneOrMany::One(item)) if listed => Ok(vec![item; n]),
            Some(OneOrMany::Many(items)) if items.is_empty() => Ok(vec![Value::Null; n]),
            Some(OneOrMany::Many(_)) => {
                Err(format!("evaluator.{field} is a list but evaluator.func is a single metric"))
            }
            Some(OneOrMany::One(item)) => Ok(vec![item]),
        }
    };
    let results = spread("result", data.result)?;
    let expecteds = spread("expected", data.expected)?;
    let options = spread("options", data.options)?;
    let mut calls = Vec::with_capacity(n);
    for (idx, (((metric, result), expected), options)) in
        funcs.into_iter().zip(results).zip(expecteds).zip(options).enumerate()
    {
        let place = if listed { format!("[{idx}]") } else { String::new() };
        let result = getter(result, names::RESULT_GETTERS).map_err(|err| format!("evaluator.result{place}: {err}"))?;
        let expected = getter(expected, &[names::EXPECTED_GETTERS, names::ARENA_EXPECTED_GETTERS].concat())
            .map_err(|err| format!("evaluator.expected{place}: {err}"))?;
        let options = match options {
            Value::Null => Map::new(),
            Value::Object(map) => map,
            other => return Err(format!("evaluator.options{place} must be an object, not {}", kind_of(&other))),
        };
        calls.push(MetricCall { metric, result, expected, options });
    }
    Ok(Evaluator { postconfig, scoring: Scoring::Metrics { conj, calls, listed } })
}

fn getter(value: Value, known: &[&str]) -> Result<Option<GetterSpec>, String> {
    let mut map = match value {
        Value::Null => return Ok(None),
        Value::Object(map) if map.is_empty() => return Ok(None),
        Value::Object(map) => map,
        other => return Err(format!("a getter must be an object, not {}", kind_of(&other))),
    };
    let kind = match map.remove("type") {
        Some(Value::String(kind)) => kind,
        Some(other) => return Err(format!("getter `type` must be a string, not {}", kind_of(&other))),
        None => return Err("getter has no `type`".into()),
    };
    if !known.contains(&kind.as_str()) {
        return Err(format!("unknown getter `{kind}`"));
    }
    Ok(Some(GetterSpec { kind, params: map }))
}

/// A task index file (`test_all.json`): domain → task names. Domains and names are
/// plain names (no separators, no `..`), so an index only names files inside the
/// corpus; the file is read up to [`MAX_INDEX_FILE_BYTES`].
///
/// # Errors
///
/// [`TaskError`] for an unreadable, oversize or malformed index, or an entry that is
/// not a plain name.
pub fn read_index(path: &Path) -> Result<Vec<(String, Vec<String>)>, TaskError> {
    let text = read_capped(path, MAX_INDEX_FILE_BYTES, "index file")?;
    let invalid = |message: String| TaskError::Invalid { path: path.to_owned(), message };
    // Checked as JSON first, so a syntax error is reported as one.
    let value: Value = serde_json::from_str(&text)
        .map_err(|err| TaskError::Json { path: path.to_owned(), message: err.to_string() })?;
    if !value.is_object() {
        return Err(invalid("an index is an object of domain -> list of task ids".into()));
    }
    // Read again keeping the file's order of domains, as Python's json.load does
    // (a `Value` object is sorted by key).
    let InOrder(entries) = serde_json::from_str(&text)
        .map_err(|err| TaskError::Json { path: path.to_owned(), message: err.to_string() })?;
    entries
        .into_iter()
        .map(|(domain, ids)| {
            check_index_name(&domain, "domain").map_err(invalid)?;
            let ids = ids
                .as_array()
                .ok_or_else(|| invalid(format!("`{domain}` must be a list of task ids")))?
                .iter()
                .map(|id| {
                    let id = id.as_str().ok_or_else(|| invalid(format!("`{domain}` holds a non-string id")))?;
                    check_index_name(id, "task id").map_err(invalid)?;
                    Ok(id.to_owned())
                })
                .collect::<Result<Vec<_>, _>>()?;
            Ok((domain, ids))
        })
        .collect()
}

/// A JSON object's entries in the order the text has them.
struct InOrder(Vec<(String, Value)>);

impl<'de> serde::Deserialize<'de> for InOrder {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<InOrder, D::Error> {
        struct Entries;
        impl<'de> serde::de::Visitor<'de> for Entries {
            type Value = InOrder;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("an object")
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(self, mut map: A) -> Result<InOrder, A::Error> {
                let mut entries = Vec::new();
                while let Some(entry) = map.next_entry::<String, Value>()? {
                    entries.push(entry);
                }
                Ok(InOrder(entries))
            }
        }
        deserializer.deserialize_map(Entries)
    }
}

/// Loads the tasks an index names, from `root/<difficulty folder>/<domain>/<name>.json`.
///
/// # Errors
///
/// The first task that is missing or invalid, naming its file.
pub fn load_index(root: &Path, index: &Path, difficulty: Difficulty) -> Result<Vec<Task>, TaskError> {
    let entries = read_index(index)?;
    let mut tasks = Vec::new();
    for (domain, names) in entries {
        for name in names {
            let path = root.join(difficulty.folder()).join(&domain).join(format!("{name}.json"));
            tasks.push(Task::load(&path)?);
        }
    }
    Ok(tasks)
}

/// Loads every task file below `dir` (recursively; index files named `test_*.json` are skipped),
/// sorted by path so runs are deterministic. Errors are collected, not fatal, so `validate` can
/// report every broken file at once.
pub fn load_dir(dir: &Path) -> (Vec<Task>, Vec<TaskError>) {
    let mut files = Vec::new();
    collect_json(dir, &mut files);
    files.sort();
    let mut tasks = Vec::new();
    let mut errors = Vec::new();
    for file in files {
        match Task::load(&file) {
            Ok(task) => tasks.push(task),
            Err(err) => errors.push(err),
        }
    }
    (tasks, errors)
}

fn collect_json(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let path = entry.path();
        if path.is_dir() {
            collect_json(&path, out);
        } else if path.extension().is_some_and(|e| e == "json")
            && !path.file_name().and_then(|n| n.to_str()).is_some_and(|n| n.starts_with("test_"))
        {
            out.push(path);
        }
    }
}

#[cfg(test)]
mod tests;
