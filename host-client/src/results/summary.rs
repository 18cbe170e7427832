//! The run summary: success per domain and overall, as the WAA paper's table
//! gives it, plus steps, time and errors per task; written as `summary.json`
//! and `summary.md` at the root of a result folder.
//!
//! A summary is computed from the folders on disk ([`super::scan`]), never
//! from memory, so `arena report` rebuilds exactly what `arena run` wrote and a
//! merged folder summarises like one run. Success is a score of 1, as upstream
//! counts it; the mean score is given too since a few metrics give partial
//! credit. Tasks that ended in an infrastructure error and were never finished
//! are listed apart and are not in the success rate's denominator (upstream's
//! `show_result.py` only counts folders with a `result.txt` too).

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::{scan, write_atomic, FoundTask, ResultsError, SUMMARY_JSON, SUMMARY_MD};

/// One row of the table: a domain, or the overall total.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DomainRow {
    pub domain: String,
    /// Finished tasks (with a score).
    pub tasks: u32,
    /// Finished tasks that scored 1.
    pub successes: u32,
    /// `successes / tasks` in percent (0 when there are no tasks).
    pub success_rate: f64,
    /// Mean score of the finished tasks.
    pub mean_score: f64,
    /// Mean steps per finished task.
    pub avg_steps: f64,
    /// Mean wall time per finished task, in seconds.
    pub avg_seconds: f64,
    /// Finished tasks whose agent failed.
    pub agent_errors: u32,
    /// Tasks with no score because the infrastructure failed.
    pub unfinished: u32,
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
}

/// The summary of a result folder.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    pub overall: DomainRow,
    /// By domain name.
    pub domains: Vec<DomainRow>,
    /// By domain, then name.
    pub tasks: Vec<TaskRow>,
}

impl Summary {
    /// Scans `root` and summarises every task folder below it.
    ///
    /// # Errors
    ///
    /// `root` cannot be read.
    pub fn from_dir(root: &Path) -> Result<Summary, ResultsError> {
        Ok(Summary::from_found(&scan(root)?))
    }

    /// Summarises task folders already found.
    pub fn from_found(found: &[FoundTask]) -> Summary {
        let mut tasks: Vec<TaskRow> = found.iter().map(task_row).collect();
        tasks.sort_by(|a, b| (&a.domain, &a.name, &a.path).cmp(&(&b.domain, &b.name, &b.path)));
        let mut by_domain: BTreeMap<&str, Vec<&TaskRow>> = BTreeMap::new();
        for row in &tasks {
            by_domain.entry(row.domain.as_str()).or_default().push(row);
        }
        let domains = by_domain.iter().map(|(domain, rows)| domain_row(domain, rows)).collect();
        let all: Vec<&TaskRow> = tasks.iter().collect();
        let overall = domain_row("Overall", &all);
        Summary { overall, domains, tasks }
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

    /// The paper's table, without timings: (domain, tasks, successes, rate).
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
        Ok((json_path, md_path))
    }

    /// The summary as Markdown: the domain table, then every task, then the errors.
    pub fn markdown(&self) -> String {
        let mut md = String::new();
        md.push_str("# Run summary\n\n");
        md.push_str("| Domain | Tasks | Successes | Success rate | Mean score | Avg steps | Avg time (s) | Agent errors | Unfinished |\n");
        md.push_str("|---|---:|---:|---:|---:|---:|---:|---:|---:|\n");
        let rows = self
            .domains
            .iter()
            .map(|row| (md_escape(&row.domain), row))
            .chain(std::iter::once((format!("**{}**", self.overall.domain), &self.overall)));
        for (name, row) in rows {
            let _ = writeln!(
                md,
                "| {name} | {} | {} | {:.1}% | {:.3} | {:.1} | {:.1} | {} | {} |",
                row.tasks,
                row.successes,
                row.success_rate,
                row.mean_score,
                row.avg_steps,
                row.avg_seconds,
                row.agent_errors,
                row.unfinished
            );
        }
        md.push_str("\n## Tasks\n\n| Domain | Task | Score | Status | Steps | Time (s) | Attempt |\n|---|---|---:|---|---:|---:|---:|\n");
        for t in &self.tasks {
            let score = t.score.map_or_else(|| "-".to_owned(), super::python_float);
            let _ = writeln!(
                md,
                "| {} | {} | {score} | {} | {} | {:.1} | {} |",
                md_escape(&t.domain),
                md_escape(&t.name),
                t.status,
                t.steps,
                t.elapsed_ms as f64 / 1000.0,
                t.attempt
            );
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

fn md_escape(text: &str) -> String {
    text.replace('|', "\\|").replace('\n', " ")
}

fn task_row(found: &FoundTask) -> TaskRow {
    let episode = found.episode.as_ref();
    let status = episode.map_or("unknown", |e| e.status.kind()).to_owned();
    let score = found.score;
    TaskRow {
        domain: found.domain(),
        name: found.name(),
        path: found
            .relative
            .components()
            .map(|c| c.as_os_str().to_string_lossy().into_owned())
            .collect::<Vec<_>>()
            .join("/"),
        score,
        success: score.is_some_and(|s| s >= 1.0 - 1e-9),
        status,
        error: episode.and_then(|e| e.status.message().map(str::to_owned)),
        steps: episode.map_or(0, |e| e.steps),
        elapsed_ms: episode.map_or(0, |e| e.elapsed_ms),
        attempt: episode.map_or(1, |e| e.attempt),
        guest: episode.map(|e| e.guest.clone()).unwrap_or_default(),
    }
}

fn domain_row(domain: &str, rows: &[&TaskRow]) -> DomainRow {
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
        success_rate: if n == 0 { 0.0 } else { 100.0 * f64::from(successes) / f64::from(n) },
        mean_score: mean(&|r| r.score.unwrap_or(0.0)),
        avg_steps: mean(&|r| f64::from(r.steps)),
        avg_seconds: mean(&|r| r.elapsed_ms as f64 / 1000.0),
        agent_errors: finished.iter().filter(|r| r.status == "agent_error").count() as u32,
        unfinished: rows.len() as u32 - n,
    }
}
