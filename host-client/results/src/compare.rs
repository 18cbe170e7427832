//! `arena compare RUN_A RUN_B`: two result folders compared task by task.
//!
//! Each task's value in a run is its mean score over its finished trials
//! (one trial: its score). Over the tasks both runs finished, the difference
//! of the success rates (B − A, in points) is given with a paired bootstrap
//! 95 % interval over those tasks ([`super::stats::bootstrap_ci95`] of the
//! per-task differences), and the tasks that moved are listed each way: better
//! in B, worse in B. Tasks only one run finished are listed apart and are in
//! no paired figure.
//!
//! Beside it, the **strict** difference: over every task both runs listed or
//! played, a task one run left unfinished (an `evaluator_error`, a guest that
//! failed, never started) counted 0 there, as the strict rate counts it. A run
//! cannot gain on the other by leaving the tasks it fails unfinished: those
//! tasks are named (`unfinished_in_a`, `unfinished_in_b`) and move the strict
//! figure.
//!
//! A task is named by domain and name, so the two folders may hold different
//! agents or models; a folder that itself holds more than one
//! `<action space>/<observation>/<model>` level is refused, since its tasks
//! would pool different agents.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use serde::{Deserialize, Serialize};

use super::summary::{per_task, Summary, TaskRow};
use super::ResultsError;

/// A task whose value differs between the runs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Flip {
    pub domain: String,
    pub name: String,
    /// Mean score over A's finished trials.
    pub a: f64,
    /// Mean score over B's finished trials.
    pub b: f64,
}

/// The comparison of two result folders.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Comparison {
    pub run_a: String,
    pub run_b: String,
    /// Tasks both runs finished (the pairs).
    pub paired_tasks: usize,
    /// A's success rate over the paired tasks, in percent.
    pub rate_a: f64,
    /// B's success rate over the paired tasks, in percent.
    pub rate_b: f64,
    /// `rate_b - rate_a`, in points.
    pub difference: f64,
    /// The paired bootstrap 95 % interval of [`Comparison::difference`], `[low, high]` in points.
    pub difference_ci95: Option<[f64; 2]>,
    /// Paired tasks that did better in B, by domain and name.
    pub better_in_b: Vec<Flip>,
    /// Paired tasks that did worse in B.
    pub worse_in_b: Vec<Flip>,
    /// `domain/name` of tasks only A finished.
    pub only_a: Vec<String>,
    /// `domain/name` of tasks only B finished.
    pub only_b: Vec<String>,
    /// Tasks both runs listed or played, finished or not: the strict pairs.
    #[serde(default)]
    pub strict_tasks: usize,
    /// A's mean score × 100 over the strict pairs, a task it left unfinished as 0.
    #[serde(default)]
    pub strict_rate_a: f64,
    /// B's, the same way.
    #[serde(default)]
    pub strict_rate_b: f64,
    /// `strict_rate_b - strict_rate_a`, in points.
    #[serde(default)]
    pub strict_difference: f64,
    /// The paired bootstrap 95 % interval of [`Comparison::strict_difference`].
    #[serde(default)]
    pub strict_difference_ci95: Option<[f64; 2]>,
    /// `domain/name` of tasks B finished and A listed or played but left unfinished.
    #[serde(default)]
    pub unfinished_in_a: Vec<String>,
    /// `domain/name` of tasks A finished and B left unfinished.
    #[serde(default)]
    pub unfinished_in_b: Vec<String>,
}

/// Each task a folder's summary knows, finished or not: `(domain, name)` → its
/// mean score over every trial listed or played, an unfinished trial as 0.
fn strict_values(summary: &Summary) -> BTreeMap<(String, String), f64> {
    let mut trials: BTreeMap<(String, String), (f64, u32)> = BTreeMap::new();
    let played: std::collections::BTreeSet<&str> = summary.tasks.iter().map(|t| t.path.as_str()).collect();
    let rows = summary.tasks.iter().map(|t| (&t.domain, &t.name, t.score.unwrap_or(0.0)));
    let never_started =
        summary.missing.iter().filter(|m| !played.contains(m.path.as_str())).map(|m| (&m.domain, &m.name, 0.0));
    for (domain, name, score) in rows.chain(never_started) {
        let entry = trials.entry((domain.clone(), name.clone())).or_default();
        entry.0 += score;
        entry.1 += 1;
    }
    trials.into_iter().map(|(key, (sum, n))| (key, sum / f64::from(n.max(1)))).collect()
}

/// Each finished task of a folder's summary: `(domain, name)` → mean score.
///
/// # Errors
///
/// The folder mixes more than one agent, observation or model folder.
fn values(summary: &Summary, dir: &Path) -> Result<BTreeMap<(String, String), f64>, ResultsError> {
    let rows: Vec<&TaskRow> = summary.tasks.iter().collect();
    let mut out = BTreeMap::new();
    let mut configs: Vec<String> = summary
        .trials
        .iter()
        .map(|t| t.rsplit_once('/').map_or(String::new(), |(config, _)| config.to_owned()))
        .collect();
    configs.sort();
    configs.dedup();
    if configs.len() > 1 {
        return Err(ResultsError::Format {
            path: dir.to_owned(),
            message: format!(
                "holds the results of more than one agent or model ({}); compare one of those folders",
                configs.join(", ")
            ),
        });
    }
    for task in per_task(&rows) {
        out.insert((task.domain.to_owned(), task.name.to_owned()), task.mean_score);
    }
    Ok(out)
}

impl Comparison {
    /// Compares the result folders `a` and `b`.
    ///
    /// # Errors
    ///
    /// A folder cannot be read, or one mixes agents ([`values`]).
    pub fn of_dirs(a: &Path, b: &Path) -> Result<Comparison, ResultsError> {
        let (sa, sb) = (Summary::from_dir(a)?, Summary::from_dir(b)?);
        let (va, vb) = (values(&sa, a)?, values(&sb, b)?);
        let mut comparison = Comparison::of(&a.display().to_string(), &va, &b.display().to_string(), &vb);
        comparison.set_strict(&va, &strict_values(&sa), &vb, &strict_values(&sb));
        Ok(comparison)
    }

    /// Sets the strict figures from each run's finished values and its strict
    /// values (every task it knows, unfinished as 0; [`strict_values`]).
    pub fn set_strict(
        &mut self,
        finished_a: &BTreeMap<(String, String), f64>,
        strict_a: &BTreeMap<(String, String), f64>,
        finished_b: &BTreeMap<(String, String), f64>,
        strict_b: &BTreeMap<(String, String), f64>,
    ) {
        let name = |(d, n): &(String, String)| format!("{d}/{n}");
        let pairs: Vec<(f64, f64)> =
            strict_a.iter().filter_map(|(key, &va)| strict_b.get(key).map(|&vb| (va, vb))).collect();
        let n = pairs.len().max(1) as f64;
        self.strict_tasks = pairs.len();
        self.strict_rate_a = 100.0 * pairs.iter().map(|p| p.0).sum::<f64>() / n;
        self.strict_rate_b = 100.0 * pairs.iter().map(|p| p.1).sum::<f64>() / n;
        self.strict_difference = self.strict_rate_b - self.strict_rate_a;
        let diffs: Vec<f64> = pairs.iter().map(|(x, y)| y - x).collect();
        self.strict_difference_ci95 = super::stats::bootstrap_ci95(&diffs).map(|[l, h]| [100.0 * l, 100.0 * h]);
        let left = |finished: &BTreeMap<(String, String), f64>,
                    strict: &BTreeMap<(String, String), f64>,
                    other_finished: &BTreeMap<(String, String), f64>| {
            other_finished.keys().filter(|k| strict.contains_key(*k) && !finished.contains_key(*k)).map(name).collect()
        };
        self.unfinished_in_a = left(finished_a, strict_a, finished_b);
        self.unfinished_in_b = left(finished_b, strict_b, finished_a);
    }

    /// Compares per-task values (`(domain, name)` → mean score).
    pub fn of(
        run_a: &str,
        a: &BTreeMap<(String, String), f64>,
        run_b: &str,
        b: &BTreeMap<(String, String), f64>,
    ) -> Comparison {
        let name = |(d, n): &(String, String)| format!("{d}/{n}");
        let mut pairs = Vec::new();
        let (mut better_in_b, mut worse_in_b) = (Vec::new(), Vec::new());
        for (key, &va) in a {
            let Some(&vb) = b.get(key) else { continue };
            pairs.push((va, vb));
            let flip = Flip { domain: key.0.clone(), name: key.1.clone(), a: va, b: vb };
            if vb > va + 1e-9 {
                better_in_b.push(flip);
            } else if vb < va - 1e-9 {
                worse_in_b.push(flip);
            }
        }
        let n = pairs.len().max(1) as f64;
        let rate_a = 100.0 * pairs.iter().map(|p| p.0).sum::<f64>() / n;
        let rate_b = 100.0 * pairs.iter().map(|p| p.1).sum::<f64>() / n;
        let diffs: Vec<f64> = pairs.iter().map(|(x, y)| y - x).collect();
        Comparison {
            run_a: run_a.to_owned(),
            run_b: run_b.to_owned(),
            paired_tasks: pairs.len(),
            rate_a,
            rate_b,
            difference: rate_b - rate_a,
            difference_ci95: super::stats::bootstrap_ci95(&diffs).map(|[l, h]| [100.0 * l, 100.0 * h]),
            better_in_b,
            worse_in_b,
            only_a: a.keys().filter(|k| !b.contains_key(*k)).map(name).collect(),
            only_b: b.keys().filter(|k| !a.contains_key(*k)).map(name).collect(),
            strict_tasks: 0,
            strict_rate_a: 0.0,
            strict_rate_b: 0.0,
            strict_difference: 0.0,
            strict_difference_ci95: None,
            unfinished_in_a: Vec::new(),
            unfinished_in_b: Vec::new(),
        }
    }

    /// The comparison in words, for the terminal.
    pub fn text(&self) -> String {
        let mut t = String::new();
        let _ = writeln!(t, "A: {}\nB: {}", self.run_a, self.run_b);
        let _ = writeln!(
            t,
            "{} task(s) finished in both: A {:.1}%, B {:.1}%, B - A = {:+.1} points",
            self.paired_tasks, self.rate_a, self.rate_b, self.difference
        );
        if let Some([low, high]) = self.difference_ci95 {
            let _ = writeln!(t, "95% interval of B - A (paired bootstrap over tasks): [{low:+.1}, {high:+.1}] points");
        }
        let flips = |t: &mut String, title: &str, list: &[Flip]| {
            let _ = writeln!(t, "{title} ({}):", list.len());
            for f in list {
                let _ = writeln!(
                    t,
                    "  {}/{}: {} -> {}",
                    f.domain,
                    f.name,
                    super::python_float(f.a),
                    super::python_float(f.b)
                );
            }
        };
        if self.strict_tasks > 0 {
            let _ = writeln!(
                t,
                "strict, over {} task(s) both runs listed or played (a task left unfinished counts 0): A {:.1}%, B {:.1}%, B - A = {:+.1} points",
                self.strict_tasks, self.strict_rate_a, self.strict_rate_b, self.strict_difference
            );
            if let Some([low, high]) = self.strict_difference_ci95 {
                let _ = writeln!(t, "95% interval of the strict B - A: [{low:+.1}, {high:+.1}] points");
            }
        }
        let left = [("left unfinished in A", &self.unfinished_in_a), ("left unfinished in B", &self.unfinished_in_b)];
        for (title, list) in left {
            if !list.is_empty() {
                let _ = writeln!(t, "{title} ({}, 0 in the strict figure): {}", list.len(), list.join(", "));
            }
        }
        flips(&mut t, "better in B", &self.better_in_b);
        flips(&mut t, "worse in B", &self.worse_in_b);
        for (title, list) in [("only in A", &self.only_a), ("only in B", &self.only_b)] {
            if !list.is_empty() {
                let _ = writeln!(t, "{title} ({}, in no figure): {}", list.len(), list.join(", "));
            }
        }
        t
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(pairs: &[(&str, f64)]) -> BTreeMap<(String, String), f64> {
        pairs.iter().map(|(n, v)| (("d".to_owned(), (*n).to_owned()), *v)).collect()
    }

    #[test]
    fn tasks_pair_by_name_and_flips_are_listed_each_way() {
        let a = run(&[("x", 1.0), ("y", 0.0), ("z", 1.0), ("only-a", 1.0)]);
        let b = run(&[("x", 1.0), ("y", 1.0), ("z", 0.0 + 1.0 / 3.0), ("only-b", 0.0)]);
        let c = Comparison::of("A", &a, "B", &b);
        assert_eq!(c.paired_tasks, 3);
        assert!((c.rate_a - 200.0 / 3.0).abs() < 1e-9);
        assert!((c.difference - (c.rate_b - c.rate_a)).abs() < 1e-9);
        assert_eq!(c.better_in_b.iter().map(|f| f.name.as_str()).collect::<Vec<_>>(), ["y"]);
        assert_eq!(c.worse_in_b.iter().map(|f| f.name.as_str()).collect::<Vec<_>>(), ["z"]);
        assert_eq!((c.only_a.clone(), c.only_b.clone()), (vec!["d/only-a".to_owned()], vec!["d/only-b".to_owned()]));
        let [low, high] = c.difference_ci95.unwrap();
        assert!(low <= c.difference && c.difference <= high);
        let text = c.text();
        assert!(text.contains("better in B (1):\n  d/y: 0.0 -> 1.0"), "{text}");
        assert!(text.contains("worse in B (1):\n  d/z: 1.0 -> 0.3333333333333333"), "{text}");
    }

    #[test]
    fn the_same_run_twice_differs_by_nothing() {
        let a = run(&[("x", 1.0), ("y", 0.0)]);
        let c = Comparison::of("A", &a, "A", &a);
        assert_eq!((c.difference, c.difference_ci95), (0.0, Some([0.0, 0.0])));
        assert!(c.better_in_b.is_empty() && c.worse_in_b.is_empty());
    }

    #[test]
    fn a_task_one_run_left_unfinished_counts_in_the_strict_difference() {
        use crate::fixtures::write_task;
        use crate::EpisodeStatus;
        let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
        write_task(a.path(), "notepad", "x", 1.0, EpisodeStatus::Completed);
        write_task(a.path(), "notepad", "y", 1.0, EpisodeStatus::Completed);
        write_task(b.path(), "notepad", "x", 1.0, EpisodeStatus::Completed);
        write_task(b.path(), "notepad", "y", 0.0, EpisodeStatus::EvaluatorError("is_expected_tabs: no browser".into()));
        let c = Comparison::of_dirs(a.path(), b.path()).unwrap();
        // The paired figure sees only x, where the runs agree.
        assert_eq!((c.paired_tasks, c.difference), (1, 0.0));
        assert!(c.only_a.contains(&"notepad/y".to_owned()), "{c:?}");
        // The strict one counts y, which B left unfinished, as B's 0.
        assert_eq!((c.strict_tasks, c.strict_rate_a, c.strict_rate_b, c.strict_difference), (2, 100.0, 50.0, -50.0));
        assert_eq!((c.unfinished_in_a.clone(), c.unfinished_in_b.clone()), (vec![], vec!["notepad/y".to_owned()]));
        let text = c.text();
        assert!(text.contains("left unfinished in B (1, 0 in the strict figure): notepad/y"), "{text}");
        assert!(text.contains("strict, over 2 task(s)") && text.contains("B - A = -50.0 points"), "{text}");
        let json = serde_json::to_value(&c).unwrap();
        assert_eq!(json["unfinished_in_b"], serde_json::json!(["notepad/y"]));
    }
}
