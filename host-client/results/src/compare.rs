//! `arena compare RUN_A RUN_B`: two result folders compared task by task.
//!
//! Each task's value in a run is its mean score over its finished trials
//! (one trial: its score). Over the tasks both runs finished, the difference
//! of the success rates (B − A, in points) is given with a paired bootstrap
//! 95 % interval over those tasks ([`super::stats::bootstrap_ci95`] of the
//! per-task differences), and the tasks that moved are listed each way: better
//! in B, worse in B. Tasks only one run finished are listed apart and are in
//! no figure.
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
        Ok(Comparison::of(&a.display().to_string(), &va, &b.display().to_string(), &vb))
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
}
