//! The run summary: the success rate per domain, per upstream group and
//! overall, as the WAA paper's table gives it, plus steps, time and errors per
//! task; written as `summary.json` and `summary.md` at the root of a result
//! folder, with upstream's `all_result.json` and `missing.json` in each trial
//! folder.
//!
//! A summary is computed from the folders on disk ([`super::scan`]), never
//! from memory, so `arena report` rebuilds exactly what `arena run` wrote and a
//! merged folder summarises like one run.
//!
//! The success rate is upstream's figure: the **mean score × 100** over the
//! finished tasks (folders with a `result.txt`), as `show_result.py` and
//! `run.py` compute it, so partial credit counts. The strict count of tasks
//! that scored 1 is given beside it as "solved". Unfinished tasks are listed
//! apart and are in no denominator, as upstream's readers skip them.
//!
//! Beside it, the **strict rate**: the mean score × 100 over every task of the
//! task list (the run's `task_list.json`, [`super::task_list`]), a task without
//! a result counted as 0, which no unfinished task can raise; `complete` says
//! whether every task has a result, and `missing` lists those that do not.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::{scan, task_list, write_atomic, FoundTask, ResultsError, SUMMARY_JSON, SUMMARY_MD};

/// Upstream's groups of domains, in the order they are printed. Upstream's
/// `show_result.py` at 6d39ed88 prints the first three (Office, Daily,
/// Professional); the other five come from a later fork's `show_result.py`
/// (FanbinLu/WindowsAgentArena 4567840, 2025-03-16). docs/compatibility.md lists it.
pub const GROUPS: &[(&str, &[&str])] = &[
    ("Office", &["libreoffice_calc", "libreoffice_impress", "libreoffice_writer"]),
    ("Daily", &["vlc", "thunderbird", "chrome"]),
    ("Professional", &["gimp", "vs_code"]),
    ("Web browser", &["chrome", "msedge"]),
    ("Windows System", &["file_explorer", "settings"]),
    ("Coding", &["vs_code"]),
    ("Media", &["vlc"]),
    ("Windows Utilities", &["windows_calc", "notepad", "clock", "microsoft_paint"]),
];

/// Upstream's per-trial files, written by `show_result.py` into the folder it reads.
pub const ALL_RESULT_JSON: &str = "all_result.json";
/// See [`ALL_RESULT_JSON`].
pub const MISSING_JSON: &str = "missing.json";

/// One row of the table: a domain, or the overall total.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DomainRow {
    pub domain: String,
    /// Finished tasks (with a score).
    pub tasks: u32,
    /// Finished tasks that scored 1.
    pub successes: u32,
    /// Upstream's success rate: mean score × 100 over the finished tasks (0 when there are none).
    pub success_rate: f64,
    /// `successes / tasks` in percent: the strict solved rate.
    #[serde(default)]
    pub solved_rate: f64,
    /// Mean score of the finished tasks.
    pub mean_score: f64,
    /// Mean steps per finished task.
    pub avg_steps: f64,
    /// Mean wall time per finished task, in seconds.
    pub avg_seconds: f64,
    /// Finished tasks whose agent failed.
    pub agent_errors: u32,
    /// Tasks with no score: unfinished, or listed and never started.
    pub unfinished: u32,
    /// Mean score × 100 over every task (finished or not, unfinished as 0).
    #[serde(default)]
    pub strict_rate: f64,
    /// Whether every task has a result.
    #[serde(default)]
    pub complete: bool,
}

/// A task of the task list without a result.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct MissingTask {
    pub domain: String,
    pub name: String,
    /// Its folder, relative to the summary's root, with `/` separators (it may not exist).
    pub path: String,
}

/// One task in the summary.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TaskRow {
    pub domain: String,
    pub name: String,
    /// The task folder, relative to the summary's root, with `/` separators.
    pub path: String,
    /// `None` when the task is unfinished.
    pub score: Option<f64>,
    pub success: bool,
    /// `completed`, `agent_error`, `infra_error`, or `unknown` when `episode.json` is missing.
    pub status: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    pub steps: u32,
    pub elapsed_ms: u64,
    pub attempt: u32,
    #[serde(default)]
    pub guest: String,
    /// Whose failure this is ([`super::Blame::name`]: `passed`, `agent`, `guest`,
    /// `vm`, `evaluator`, `model`, `interrupted`; `unknown` without `episode.json`).
    #[serde(default)]
    pub blame: String,
    /// `passed`, `agent`, `environment`, `interrupted` or `unknown`: the side of [`TaskRow::blame`].
    #[serde(default)]
    pub failed_by: String,
}

/// The summary of a result folder.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    pub overall: DomainRow,
    /// By domain name.
    pub domains: Vec<DomainRow>,
    /// Upstream's groups of domains (`show_result.py`), those with finished tasks.
    #[serde(default)]
    pub groups: Vec<DomainRow>,
    /// By domain, then name.
    pub tasks: Vec<TaskRow>,
    /// Each named option in force and the values the tasks ran with (more than
    /// one value means the folder mixes runs that are not comparable).
    #[serde(default)]
    pub options: BTreeMap<String, Vec<String>>,
    /// The trial folders (`<action space>/<observation>/<model>/<trial>`) the
    /// summary pools; upstream's `show_result.py` reads one.
    #[serde(default)]
    pub trials: Vec<String>,
    /// Every task of the task list (and every task folder) without a result.
    #[serde(default)]
    pub missing: Vec<MissingTask>,
}

impl Summary {
    /// Scans `root` and summarises every task folder below it.
    ///
    /// # Errors
    ///
    /// `root` cannot be read.
    pub fn from_dir(root: &Path) -> Result<Summary, ResultsError> {
        Ok(Summary::from_found_in(root, &scan(root)?))
    }

    /// Summarises task folders already found under `root`, with the tasks its
    /// task lists name that have no folder.
    pub fn from_found_in(root: &Path, found: &[FoundTask]) -> Summary {
        let known: std::collections::BTreeSet<PathBuf> = found.iter().map(|f| f.relative.clone()).collect();
        let never_started: Vec<MissingTask> = task_list::listed_tasks(root)
            .into_iter()
            .filter(|(_, _, path)| !known.contains(path))
            .map(|(domain, name, path)| MissingTask { domain, name, path: slash_path(&path) })
            .collect();
        Summary::summarise(found, never_started)
    }

    /// Summarises task folders already found, knowing no task list.
    pub fn from_found(found: &[FoundTask]) -> Summary {
        Summary::summarise(found, Vec::new())
    }

    fn summarise(found: &[FoundTask], never_started: Vec<MissingTask>) -> Summary {
        let mut tasks: Vec<TaskRow> = found.iter().map(task_row).collect();
        // The same order as the run's (`Task::order_key`), on the rows read back from the folders.
        tasks.sort_by(|a, b| (&a.domain, &a.name, &a.path).cmp(&(&b.domain, &b.name, &b.path)));
        let mut by_domain: BTreeMap<&str, Vec<&TaskRow>> = BTreeMap::new();
        for row in &tasks {
            by_domain.entry(row.domain.as_str()).or_default().push(row);
        }
        for m in &never_started {
            by_domain.entry(m.domain.as_str()).or_default();
        }
        let not_run = |members: &dyn Fn(&str) -> bool| never_started.iter().filter(|m| members(&m.domain)).count();
        let domains =
            by_domain.iter().map(|(domain, rows)| domain_row(domain, rows, not_run(&|d| d == *domain))).collect();
        let groups = GROUPS
            .iter()
            .map(|(name, members)| {
                let rows: Vec<&TaskRow> = tasks.iter().filter(|t| members.contains(&t.domain.as_str())).collect();
                domain_row(name, &rows, not_run(&|d| members.contains(&d)))
            })
            .filter(|row| row.tasks > 0)
            .collect();
        let all: Vec<&TaskRow> = tasks.iter().collect();
        let overall = domain_row("Overall", &all, never_started.len());
        let mut missing: Vec<MissingTask> = tasks
            .iter()
            .filter(|t| t.score.is_none())
            .map(|t| MissingTask { domain: t.domain.clone(), name: t.name.clone(), path: t.path.clone() })
            .chain(never_started)
            .collect();
        missing.sort_by(|a, b| (&a.domain, &a.name, &a.path).cmp(&(&b.domain, &b.name, &b.path)));
        let mut options: BTreeMap<String, Vec<String>> = BTreeMap::new();
        for episode in found.iter().filter_map(|f| f.episode.as_ref()) {
            for (name, value) in &episode.options {
                let values = options.entry(name.clone()).or_default();
                if !values.contains(value) {
                    values.push(value.clone());
                    values.sort();
                }
            }
        }
        let mut trials: Vec<String> =
            tasks.iter().filter_map(|t| t.path.rsplitn(3, '/').nth(2).map(str::to_owned)).collect();
        trials.sort();
        trials.dedup();
        Summary { overall, domains, groups, tasks, options, trials, missing }
    }

    /// The words that mark an incomplete run, or `None` when every task has a result.
    pub fn incomplete_words(&self) -> Option<String> {
        let o = &self.overall;
        (!o.complete).then(|| {
            format!(
                "This run is incomplete: {} of {} tasks have no result; the success rate is over the finished tasks only, the strict rate counts the others as 0.",
                o.unfinished,
                o.tasks + o.unfinished
            )
        })
    }

    /// How many finished-or-not tasks failed on each side: (the agent's, the environment's).
    pub fn failures(&self) -> (usize, usize) {
        let count = |side: &str| self.tasks.iter().filter(|t| t.failed_by == side).count();
        (count("agent"), count("environment"))
    }

    /// The tasks that have no score.
    pub fn unfinished(&self) -> impl Iterator<Item = &TaskRow> {
        self.tasks.iter().filter(|t| t.score.is_none())
    }

    /// The outcome of each task without the timings, guests and attempts, which
    /// differ between two runs of the same tasks: what "the same result" means
    /// when comparing a merged run with a single one.
    pub fn outcomes(&self) -> Vec<(String, String, Option<f64>, String, u32)> {
        self.tasks.iter().map(|t| (t.domain.clone(), t.name.clone(), t.score, t.status.clone(), t.steps)).collect()
    }

    /// The paper's table, without timings: (domain, tasks, successes, upstream's rate).
    pub fn table(&self) -> Vec<(String, u32, u32, f64)> {
        self.domains
            .iter()
            .chain(std::iter::once(&self.overall))
            .map(|d| (d.domain.clone(), d.tasks, d.successes, d.success_rate))
            .collect()
    }

    /// Writes `summary.json` and `summary.md` into `root`.
    ///
    /// # Errors
    ///
    /// A file cannot be written.
    pub fn write(&self, root: &Path) -> Result<(PathBuf, PathBuf), ResultsError> {
        let json_path = root.join(SUMMARY_JSON);
        let json = serde_json::to_vec_pretty(self)
            .map_err(|err| ResultsError::Format { path: json_path.clone(), message: err.to_string() })?;
        write_atomic(&json_path, &json)?;
        let md_path = root.join(SUMMARY_MD);
        write_atomic(&md_path, self.markdown().as_bytes())?;
        self.write_trial_files(root)?;
        Ok((json_path, md_path))
    }

    /// Writes upstream's `all_result.json` (domain -> task -> score, finished
    /// tasks) and `missing.json` (domain -> tasks without `result.txt`) into each
    /// trial folder: the folder two levels above a task folder
    /// (`<trial>/<domain>/<task>`), as `show_result.py` writes them.
    ///
    /// # Errors
    ///
    /// A file cannot be written.
    pub fn write_trial_files(&self, root: &Path) -> Result<(), ResultsError> {
        type PerDomain = BTreeMap<String, BTreeMap<String, serde_json::Value>>;
        let mut trials: BTreeMap<PathBuf, (PerDomain, BTreeMap<String, Vec<String>>)> = BTreeMap::new();
        for task in &self.tasks {
            let relative: PathBuf = task.path.split('/').collect();
            let (Some(task_dir), Some(domain_dir)) = (relative.file_name(), relative.parent()) else { continue };
            let (Some(domain), Some(trial)) = (domain_dir.file_name(), domain_dir.parent()) else { continue };
            let (domain, name) = (domain.to_string_lossy().into_owned(), task_dir.to_string_lossy().into_owned());
            let entry = trials.entry(root.join(trial)).or_default();
            match task.score {
                Some(score) => {
                    let value = serde_json::Number::from_f64(score).map_or(serde_json::Value::Null, Into::into);
                    entry.0.entry(domain).or_default().insert(name, value);
                }
                None => entry.1.entry(domain).or_default().push(name),
            }
        }
        for (trial, (results, missing)) in trials {
            write_atomic(&trial.join(ALL_RESULT_JSON), python_json(&results).as_bytes())?;
            write_atomic(&trial.join(MISSING_JSON), python_json(&missing).as_bytes())?;
        }
        Ok(())
    }

    /// The summary as Markdown: the domain table, then every task, then the errors.
    pub fn markdown(&self) -> String {
        let mut md = String::new();
        md.push_str("# Run summary\n\n");
        md.push_str("Success rate as upstream computes it: mean score × 100 over the finished tasks. Solved: tasks that scored 1.\n\n");
        let o = &self.overall;
        let _ = writeln!(
            md,
            "**Success rate {:.1}%** (over the {} finished tasks) · **Strict rate {:.1}%** (over all {} tasks, those without a result counted as 0).\n",
            o.success_rate,
            o.tasks,
            o.strict_rate,
            o.tasks + o.unfinished
        );
        if let Some(words) = self.incomplete_words() {
            let _ = writeln!(md, "**{words}**\n");
        }
        if !self.options.is_empty() {
            let list: Vec<String> = self.options.iter().map(|(k, v)| format!("{k}={}", v.join("|"))).collect();
            let _ = writeln!(md, "Options in force: {}.\n", list.join(", "));
        }
        if self.trials.len() > 1 {
            let _ = writeln!(
                md,
                "Pooled from {} trial folders ({}); upstream's show_result.py reads one trial folder at a time.\n",
                self.trials.len(),
                self.trials.join(", ")
            );
        }
        let (agent, environment) = self.failures();
        let mut parts: BTreeMap<&str, usize> = BTreeMap::new();
        for t in self.tasks.iter().filter(|t| t.failed_by == "environment") {
            *parts.entry(t.blame.as_str()).or_default() += 1;
        }
        let parts: Vec<String> = parts.iter().map(|(k, n)| format!("{k} {n}")).collect();
        let parts = if parts.is_empty() { String::new() } else { format!(" ({})", parts.join(", ")) };
        let _ = writeln!(md, "Failures: {agent} the agent's, {environment} the environment's{parts}.\n");
        md.push_str("| Domain | Tasks | Success rate | Solved | Solved rate | Avg steps | Avg time (s) | Agent errors | Unfinished |\n");
        md.push_str("|---|---:|---:|---:|---:|---:|---:|---:|---:|\n");
        let rows = self
            .domains
            .iter()
            .map(|row| (md_escape(&row.domain), row))
            .chain(std::iter::once((format!("**{}**", self.overall.domain), &self.overall)))
            .chain(self.groups.iter().map(|row| (format!("*{}*", row.domain), row)));
        for (name, row) in rows {
            let _ = writeln!(
                md,
                "| {name} | {} | {:.1}% | {} | {:.1}% | {:.1} | {:.1} | {} | {} |",
                row.tasks,
                row.success_rate,
                row.successes,
                row.solved_rate,
                row.avg_steps,
                row.avg_seconds,
                row.agent_errors,
                row.unfinished
            );
        }
        md.push_str("\n## Tasks\n\n| Domain | Task | Score | Status | Failed by | Steps | Time (s) | Attempt |\n|---|---|---:|---|---|---:|---:|---:|\n");
        for t in &self.tasks {
            let score = t.score.map_or_else(|| "-".to_owned(), super::python_float);
            let _ = writeln!(
                md,
                "| {} | {} | {score} | {} | {} | {} | {:.1} | {} |",
                md_escape(&t.domain),
                md_escape(&t.name),
                t.status,
                failed_by_text(t),
                t.steps,
                t.elapsed_ms as f64 / 1000.0,
                t.attempt
            );
        }
        if !self.missing.is_empty() {
            md.push_str("\n## Missing\n\nTasks of the task list without a result (run the same command again to play them):\n\n");
            for m in &self.missing {
                let _ = writeln!(md, "- `{}/{}`", m.domain, m.name);
            }
        }
        let errors: Vec<&TaskRow> = self.tasks.iter().filter(|t| t.error.is_some()).collect();
        if !errors.is_empty() {
            md.push_str("\n## Errors\n\n");
            for t in errors {
                let _ = writeln!(
                    md,
                    "- `{}/{}` ({}): {}",
                    t.domain,
                    t.name,
                    t.status,
                    md_escape(t.error.as_deref().unwrap_or(""))
                );
            }
        }
        md
    }
}

/// JSON as Python's `json.dump(value, f, indent=4)` lays it out.
fn python_json(value: &impl Serialize) -> String {
    let mut out = Vec::new();
    let formatter = serde_json::ser::PrettyFormatter::with_indent(b"    ");
    let mut serializer = serde_json::Serializer::with_formatter(&mut out, formatter);
    if value.serialize(&mut serializer).is_err() {
        return "{}".to_owned();
    }
    String::from_utf8(out).unwrap_or_default()
}

/// The "Failed by" cell: `-` for a pass, `agent`, `environment (guest)`, ...
pub(crate) fn failed_by_text(t: &TaskRow) -> String {
    match t.failed_by.as_str() {
        "passed" => "-".to_owned(),
        "environment" => format!("environment ({})", t.blame),
        other => other.to_owned(),
    }
}

fn md_escape(text: &str) -> String {
    text.replace('|', "\\|").replace('\n', " ")
}

fn task_row(found: &FoundTask) -> TaskRow {
    let episode = found.episode.as_ref();
    let status = episode.map_or("unknown", |e| e.status.kind()).to_owned();
    let score = found.score;
    let blame = episode.map(super::EpisodeResult::blame);
    TaskRow {
        domain: found.domain(),
        name: found.name(),
        path: slash_path(&found.relative),
        score,
        success: score.is_some_and(|s| s >= 1.0 - 1e-9),
        status,
        error: episode.and_then(|e| e.status.message().map(str::to_owned)),
        steps: episode.map_or(0, |e| e.steps),
        elapsed_ms: episode.map_or(0, |e| e.elapsed_ms),
        attempt: episode.map_or(1, |e| e.attempt),
        guest: episode.map(|e| e.guest.clone()).unwrap_or_default(),
        blame: blame.map_or("unknown", super::Blame::name).to_owned(),
        failed_by: blame.map_or("unknown", super::Blame::side).to_owned(),
    }
}

/// A relative path with `/` separators.
fn slash_path(path: &Path) -> String {
    path.components().map(|c| c.as_os_str().to_string_lossy().into_owned()).collect::<Vec<_>>().join("/")
}

/// The row of `rows`, with `not_run` more tasks of the task list that have no folder.
fn domain_row(domain: &str, rows: &[&TaskRow], not_run: usize) -> DomainRow {
    let finished: Vec<&&TaskRow> = rows.iter().filter(|r| r.score.is_some()).collect();
    let n = finished.len() as u32;
    let successes = finished.iter().filter(|r| r.success).count() as u32;
    let mean = |f: &dyn Fn(&TaskRow) -> f64| {
        if n == 0 {
            0.0
        } else {
            finished.iter().map(|r| f(r)).sum::<f64>() / f64::from(n)
        }
    };
    DomainRow {
        domain: domain.to_owned(),
        tasks: n,
        successes,
        success_rate: 100.0 * mean(&|r| r.score.unwrap_or(0.0)),
        solved_rate: if n == 0 { 0.0 } else { 100.0 * f64::from(successes) / f64::from(n) },
        mean_score: mean(&|r| r.score.unwrap_or(0.0)),
        avg_steps: mean(&|r| f64::from(r.steps)),
        avg_seconds: mean(&|r| r.elapsed_ms as f64 / 1000.0),
        agent_errors: finished.iter().filter(|r| r.status == "agent_error").count() as u32,
        unfinished: (rows.len() + not_run) as u32 - n,
        strict_rate: if rows.len() + not_run == 0 {
            0.0
        } else {
            100.0 * finished.iter().map(|r| r.score.unwrap_or(0.0)).sum::<f64>() / (rows.len() + not_run) as f64
        },
        complete: rows.len() + not_run == n as usize,
    }
}
