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

use super::{scan, task_list, write_atomic, write_json, FoundTask, ResultsError, SUMMARY_JSON, SUMMARY_MD};

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
    /// The agents' failed actions, over every task of the row (the episodes went on).
    #[serde(default)]
    pub action_errors: u32,
    /// Tasks with no score: unfinished, or listed and never started.
    pub unfinished: u32,
    /// Of the unfinished, those whose evaluation failed for a reason not the
    /// agent's (`evaluator_error`: the task's evaluator or the harness).
    #[serde(default)]
    pub evaluator_errors: u32,
    /// Mean score × 100 over every task (finished or not, unfinished as 0).
    #[serde(default)]
    pub strict_rate: f64,
    /// Whether every task has a result.
    #[serde(default)]
    pub complete: bool,
    /// k → percent: the unbiased pass@k over the tasks with at least k finished
    /// trials ([`super::stats`]); `{1: solved rate}` for one trial.
    #[serde(default)]
    pub pass_at_k: BTreeMap<u32, f64>,
    /// k → percent: pass^k, all of k trials succeed ([`super::stats`]).
    #[serde(default)]
    pub pass_hat_k: BTreeMap<u32, f64>,
    /// `[low, high]` in percent: the seeded bootstrap 95 % interval over tasks of
    /// the success rate (each task its mean score over its trials); `null` without a finished task.
    #[serde(default)]
    pub rate_ci95: Option<[f64; 2]>,
    /// Tokens and model time of every task of the row, finished or not (the cost ledger).
    #[serde(default)]
    pub tokens: crate::ledger::Usage,
    /// What they cost in US dollars (`--prices`), when priced.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cost_usd: Option<f64>,
    /// The FAIL-always floor, in percent: the share of the row's listed tasks
    /// (every trial) whose evaluator is `infeasible`, which is what an agent
    /// answering FAIL to every task scores under upstream's rules; `null` when
    /// the folder's task lists do not say ([`super::task_list::listed_kinds`]).
    #[serde(default)]
    pub fail_floor: Option<f64>,
}

/// A task of the task list without a result.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct MissingTask {
    pub domain: String,
    pub name: String,
    /// Its folder, relative to the summary's root, with `/` separators (it may not exist).
    pub path: String,
}

/// A task whose trials both passed and failed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FlakyTask {
    pub domain: String,
    pub name: String,
    /// The task across its trials: its path with the trial level left out.
    pub key: String,
    /// Finished trials.
    pub trials: u32,
    /// Trials that scored 1.
    pub passes: u32,
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
    /// The task's tokens and model time, when its agent reported them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tokens: Option<crate::ledger::Usage>,
    /// What they cost in US dollars (`--prices`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cost_usd: Option<f64>,
    /// Certificates given with `--certificates` call this task broken.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub certified_broken: bool,
    /// The agent's failed actions in this task ([`super::EpisodeResult::action_errors`]).
    #[serde(default)]
    pub action_errors: u32,
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
    /// The tasks whose finished trials both passed and failed (`arena run --trials K`).
    #[serde(default)]
    pub flaky_tasks: Vec<FlakyTask>,
    /// One row per agent and model (`<action space>/<observation>/<model>`) when
    /// the folder holds more than one: the rows above pool them, and say so.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub agents: Vec<DomainRow>,
    /// The run's budget (`--max-cost`, `--max-total-tokens`): limits, spend, and
    /// whether it stopped the run starting tasks (`budget.json`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub budget: Option<super::ledger::BudgetRecord>,
    /// The certificates the folder was given (`--certificates`, `certified_broken.json`):
    /// where from, and the tasks they call broken.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub certificates: Option<super::certificate::CertifiedRecord>,
}

impl Summary {
    /// Scans `root` and summarises every task folder below it.
    ///
    /// # Errors
    ///
    /// `root` cannot be read.
    pub fn from_dir(root: &Path) -> Result<Summary, ResultsError> {
        let mut summary = Summary::from_found_in(root, &scan(root)?);
        summary.budget = super::ledger::BudgetRecord::read(root);
        Ok(summary)
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
        let mut summary = Summary::summarise(found, never_started);
        if let Some(kinds) = task_list::listed_kinds(root) {
            summary.set_fail_floor(&kinds);
        }
        if let Some(record) = super::certificate::CertifiedRecord::read(root) {
            for task in &mut summary.tasks {
                task.certified_broken = record.broken(&task.domain, &task.name).is_some();
            }
            summary.certificates = Some(record);
        }
        summary
    }

    /// Sets each row's FAIL-always floor from the listed tasks' kinds: (domain, name, infeasible).
    fn set_fail_floor(&mut self, kinds: &[(String, String, bool)]) {
        let floor = |members: &dyn Fn(&str) -> bool| {
            let rows: Vec<bool> = kinds.iter().filter(|k| members(&k.0)).map(|k| k.2).collect();
            (!rows.is_empty()).then(|| 100.0 * rows.iter().filter(|i| **i).count() as f64 / rows.len() as f64)
        };
        self.overall.fail_floor = floor(&|_| true);
        for row in &mut self.domains {
            row.fail_floor = floor(&|d| d == row.domain);
        }
        for row in &mut self.groups {
            let members = GROUPS.iter().find(|(name, _)| *name == row.domain).map_or(&[][..], |(_, m)| *m);
            row.fail_floor = floor(&|d| members.contains(&d));
        }
    }

    /// The listed tasks (or finished ones) the certificates call broken: (domain, name, why).
    pub fn certified_broken(&self) -> Vec<(&str, &str, String)> {
        let Some(record) = &self.certificates else { return Vec::new() };
        let mut seen = std::collections::BTreeSet::new();
        self.tasks
            .iter()
            .map(|t| (t.domain.as_str(), t.name.as_str()))
            .chain(self.missing.iter().map(|m| (m.domain.as_str(), m.name.as_str())))
            .filter(|key| seen.insert(*key))
            .filter_map(|(d, n)| record.broken(d, n).map(|b| (d, n, b.because.join("; "))))
            .collect()
    }

    /// The words beside the rate about the FAIL-always floor, when it is known.
    pub fn floor_words(&self) -> Option<String> {
        self.overall.fail_floor.map(|floor| {
            format!(
                "FAIL-always floor {floor:.1}% (the share of the task list whose evaluator is `infeasible`: what an agent answering FAIL to every task scores)"
            )
        })
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
        let agents = agent_rows(&tasks, &never_started);
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
        let flaky_tasks = per_task(&all)
            .into_iter()
            .filter(|t| t.passes > 0 && t.passes < t.trials)
            .map(|t| FlakyTask {
                domain: t.domain.to_owned(),
                name: t.name.to_owned(),
                key: t.key,
                trials: t.trials,
                passes: t.passes,
            })
            .collect();
        Summary {
            overall,
            domains,
            groups,
            tasks,
            options,
            trials,
            missing,
            flaky_tasks,
            agents,
            budget: None,
            certificates: None,
        }
    }

    /// The words that say the rows pool different agents or models, or `None`
    /// when the folder holds one.
    pub fn pooled_words(&self) -> Option<String> {
        (self.agents.len() > 1).then(|| {
            let names: Vec<&str> = self.agents.iter().map(|a| a.domain.as_str()).collect();
            format!(
                "This folder holds the results of {} different agents or models ({}): every rate above pools them into one row, which compares nothing. The rows by agent give each alone; `arena report` on one agent's folder gives its full report.",
                names.len(),
                names.join(", ")
            )
        })
    }

    /// The words that mark an incomplete run, or `None` when every task has a result.
    pub fn incomplete_words(&self) -> Option<String> {
        let o = &self.overall;
        (!o.complete).then(|| {
            let evaluator = match o.evaluator_errors {
                0 => String::new(),
                n => format!(
                    " ({n} of them because their evaluation failed for a reason not the agent's: `evaluator_error`)"
                ),
            };
            format!(
                "This run is incomplete: {} of {} tasks have no result{evaluator}; the success rate is over the finished tasks only, the strict rate counts the others as 0.",
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
        write_json(&json_path, self)?;
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

    /// The cost ledger per domain and overall, and the budget, when any task reported tokens.
    fn ledger_markdown(&self) -> String {
        let mut md = String::new();
        let o = &self.overall;
        if o.tokens == crate::ledger::Usage::default() && o.cost_usd.is_none() && self.budget.is_none() {
            return md;
        }
        md.push_str("\n## Cost\n\n| Domain | Input tokens | Cached | Output tokens | Model time (s) | Cost (USD) |\n|---|---:|---:|---:|---:|---:|\n");
        for (name, row) in self
            .domains
            .iter()
            .map(|row| (md_escape(&row.domain), row))
            .chain(std::iter::once((format!("**{}**", o.domain), o)))
        {
            let t = &row.tokens;
            let cost = row.cost_usd.map_or("-".to_owned(), |c| format!("{c:.4}"));
            let _ = writeln!(
                md,
                "| {name} | {} | {} | {} | {:.1} | {cost} |",
                t.input,
                t.cached,
                t.output,
                t.model_ms as f64 / 1000.0
            );
        }
        if let Some(b) = &self.budget {
            let limits: Vec<String> = [
                b.budget.max_cost_usd.map(|c| format!("--max-cost ${c}")),
                b.budget.max_tokens.map(|n| format!("--max-total-tokens {n}")),
            ]
            .into_iter()
            .flatten()
            .collect();
            let _ = write!(
                md,
                "\nBudget {}: spent ${:.4} and {} tokens.",
                limits.join(", "),
                b.spent.cost_usd,
                b.spent.tokens.total()
            );
            match &b.stopped {
                Some(why) => {
                    let _ = writeln!(md, " Reached ({why}): {} task(s) not started.", b.not_started.len());
                }
                None => md.push_str(" Not reached.\n"),
            }
        }
        md
    }

    /// The tasks certificates call broken, when certificates were given.
    fn certificates_markdown(&self) -> String {
        let Some(record) = &self.certificates else { return String::new() };
        let broken = self.certified_broken();
        let mut md = format!(
            "Certificates from {} ({} task(s)): {} task(s) of this run certified broken{}\n",
            record.source,
            record.certificates,
            broken.len(),
            if broken.is_empty() { "." } else { " (their scores say nothing of the agent):" }
        );
        for (domain, name, why) in &broken {
            let _ = writeln!(md, "- `{domain}/{name}`: certified broken: {}", md_escape(why));
        }
        md.push('\n');
        md
    }

    /// The interval, and with more than one trial per task pass@k, pass^k and the flaky tasks.
    fn trials_markdown(&self) -> String {
        let mut md = String::new();
        if let Some([low, high]) = self.overall.rate_ci95 {
            let _ = writeln!(md, "\nSuccess rate 95% interval (seeded bootstrap over tasks): [{low:.1}%, {high:.1}%].");
        }
        let most = self.overall.pass_at_k.keys().next_back().copied().unwrap_or(0);
        if most > 1 {
            let ks: Vec<u32> = (1..=most).collect();
            let _ = writeln!(md, "\n## Trials\n\nUp to {most} trials per task; a trial passes when it scores 1. pass@k: at least one of k trials passes; pass^k: all k pass (unbiased estimators, averaged over the tasks with at least k trials).\n");
            let head: Vec<String> = ks.iter().flat_map(|k| [format!("pass@{k}"), format!("pass^{k}")]).collect();
            let _ = writeln!(md, "| Domain | {} | 95% interval |", head.join(" | "));
            let _ = writeln!(md, "|---|{}---|", "---:|".repeat(head.len()));
            for (name, row) in self
                .domains
                .iter()
                .map(|row| (md_escape(&row.domain), row))
                .chain(std::iter::once((format!("**{}**", self.overall.domain), &self.overall)))
            {
                let cells: Vec<String> = ks
                    .iter()
                    .flat_map(|k| {
                        [&row.pass_at_k, &row.pass_hat_k]
                            .map(|m| m.get(k).map_or("-".to_owned(), |v| format!("{v:.1}%")))
                    })
                    .collect();
                let ci = row.rate_ci95.map_or("-".to_owned(), |[l, h]| format!("[{l:.1}%, {h:.1}%]"));
                let _ = writeln!(md, "| {name} | {} | {ci} |", cells.join(" | "));
            }
            if self.flaky_tasks.is_empty() {
                md.push_str("\nNo flaky task: every task passed in all its trials or in none.\n");
            } else {
                let _ = writeln!(
                    md,
                    "\nFlaky tasks (passed in some trials, failed in others): {}.",
                    self.flaky_tasks.len()
                );
                for t in &self.flaky_tasks {
                    let _ = writeln!(md, "- `{}/{}`: {} of {} trials passed", t.domain, t.name, t.passes, t.trials);
                }
            }
        }
        md
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
        if let Some(words) = self.floor_words() {
            let _ = writeln!(md, "{words}.\n");
        }
        if let Some(words) = self.incomplete_words() {
            let _ = writeln!(md, "**{words}**\n");
        }
        if let Some(words) = self.pooled_words() {
            let _ = writeln!(md, "**{words}**\n");
            md.push_str("| Agent and model | Tasks | Success rate | Strict rate | Solved | Unfinished |\n|---|---:|---:|---:|---:|---:|\n");
            for row in &self.agents {
                let _ = writeln!(
                    md,
                    "| {} | {} | {:.1}% | {:.1}% | {} | {} |",
                    md_escape(&row.domain),
                    row.tasks,
                    row.success_rate,
                    row.strict_rate,
                    row.successes,
                    row.unfinished
                );
            }
            md.push('\n');
        }
        md.push_str(&self.certificates_markdown());
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
        if self.overall.action_errors > 0 {
            let _ = writeln!(
                md,
                "Action errors: {} (actions that failed while their episodes went on, as upstream's do; per task below).\n",
                self.overall.action_errors
            );
        }
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
        md.push_str(&self.trials_markdown());
        md.push_str(&self.ledger_markdown());
        md.push_str("\n## Tasks\n\n| Domain | Task | Score | Status | Failed by | Steps | Time (s) | Attempt | Action errors |\n|---|---|---:|---|---|---:|---:|---:|---:|\n");
        for t in &self.tasks {
            let score = t.score.map_or_else(|| "-".to_owned(), super::python_float);
            let mark = if t.certified_broken { " (certified broken)" } else { "" };
            let _ = writeln!(
                md,
                "| {} | {}{mark} | {score} | {} | {} | {} | {:.1} | {} | {} |",
                md_escape(&t.domain),
                md_escape(&t.name),
                t.status,
                failed_by_text(t),
                t.steps,
                t.elapsed_ms as f64 / 1000.0,
                t.attempt,
                t.action_errors
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
        tokens: episode.and_then(|e| e.tokens),
        cost_usd: episode.and_then(|e| e.cost_usd),
        certified_broken: false,
        action_errors: episode.map_or(0, |e| e.action_errors),
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
    let tasks = per_task(rows);
    let counts: Vec<(u32, u32)> = tasks.iter().map(|t| (t.trials, t.passes)).collect();
    let (pass_at_k, pass_hat_k) = super::stats::pass_maps(&counts);
    let means: Vec<f64> = tasks.iter().map(|t| t.mean_score).collect();
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
        evaluator_errors: rows.iter().filter(|r| r.score.is_none() && r.status == "evaluator_error").count() as u32,
        action_errors: rows.iter().map(|r| r.action_errors).sum(),
        unfinished: (rows.len() + not_run) as u32 - n,
        strict_rate: if rows.len() + not_run == 0 {
            0.0
        } else {
            100.0 * finished.iter().map(|r| r.score.unwrap_or(0.0)).sum::<f64>() / (rows.len() + not_run) as f64
        },
        complete: rows.len() + not_run == n as usize,
        pass_at_k,
        pass_hat_k,
        rate_ci95: super::stats::bootstrap_ci95(&means).map(|[low, high]| [100.0 * low, 100.0 * high]),
        tokens: rows.iter().filter_map(|r| r.tokens.as_ref()).fold(crate::ledger::Usage::default(), |mut sum, t| {
            sum.add(t);
            sum
        }),
        cost_usd: rows.iter().any(|r| r.cost_usd.is_some()).then(|| rows.iter().filter_map(|r| r.cost_usd).sum()),
        fail_floor: None,
    }
}

/// One task across its trial folders.
#[derive(Debug)]
pub(crate) struct TaskTrials<'a> {
    pub key: String,
    pub domain: &'a str,
    pub name: &'a str,
    /// Finished trials.
    pub trials: u32,
    /// Finished trials that scored 1.
    pub passes: u32,
    /// The mean score of the finished trials.
    pub mean_score: f64,
}

/// The agent-and-model level of a task folder's path (`<action space>/<observation>/<model>`,
/// everything above the trial, domain and task levels).
fn agent_of(path: &str) -> &str {
    path.rsplitn(4, '/').nth(3).unwrap_or("")
}

/// [`Summary::agents`]: a row per agent and model when there is more than one.
fn agent_rows(tasks: &[TaskRow], never_started: &[MissingTask]) -> Vec<DomainRow> {
    let mut by_agent: BTreeMap<&str, Vec<&TaskRow>> = BTreeMap::new();
    for row in tasks {
        by_agent.entry(agent_of(&row.path)).or_default().push(row);
    }
    for m in never_started {
        by_agent.entry(agent_of(&m.path)).or_default();
    }
    if by_agent.len() < 2 {
        return Vec::new();
    }
    by_agent
        .iter()
        .map(|(agent, rows)| {
            domain_row(agent, rows, never_started.iter().filter(|m| agent_of(&m.path) == *agent).count())
        })
        .collect()
}

/// A task's identity across trials: its path without the trial level
/// (`<action space>/<observation>/<model>/<domain>/<task>`), so trial folders
/// of one agent and model pool and different ones do not.
pub(crate) fn trial_key(path: &str) -> String {
    let mut parts: Vec<&str> = path.split('/').collect();
    if parts.len() >= 3 {
        parts.remove(parts.len() - 3);
    }
    parts.join("/")
}

/// The rows grouped into tasks across trials (tasks with at least one finished trial), by key.
pub(crate) fn per_task<'a>(rows: &[&'a TaskRow]) -> Vec<TaskTrials<'a>> {
    let mut by_key: BTreeMap<String, TaskTrials<'a>> = BTreeMap::new();
    for row in rows {
        let Some(score) = row.score else { continue };
        let key = trial_key(&row.path);
        let entry = by_key.entry(key.clone()).or_insert(TaskTrials {
            key,
            domain: &row.domain,
            name: &row.name,
            trials: 0,
            passes: 0,
            mean_score: 0.0,
        });
        entry.trials += 1;
        entry.passes += u32::from(row.success);
        entry.mean_score += score;
    }
    by_key
        .into_values()
        .map(|mut t| {
            t.mean_score /= f64::from(t.trials);
            t
        })
        .collect()
}
