//! The statistics of repeated trials: pass@k and pass^k, bootstrap intervals
//! over tasks, and the paired comparison of two runs.
//!
//! A trial succeeds when its score is 1 (within rounding). For a task with `n`
//! finished trials of which `c` succeeded:
//!
//! - pass@k, the chance that at least one of `k` trials drawn without
//!   replacement succeeds, by the unbiased estimator 1 − C(n−c, k)/C(n, k)
//!   (Chen et al. 2021, "Evaluating Large Language Models Trained on Code",
//!   computed as their product form 1 − ∏_{i=n−c+1}^{n} (1 − k/i));
//! - pass^k, the chance that all `k` succeed, C(c, k)/C(n, k) (Yao et al. 2024,
//!   τ-bench), computed as ∏_{i=0}^{k−1} (c−i)/(n−i).
//!
//! Both are averaged over the tasks that have at least `k` finished trials.
//!
//! The 95 % interval of a rate is a percentile bootstrap over tasks: the tasks
//! are drawn with replacement [`BOOTSTRAP_RESAMPLES`] times by ChaCha8 seeded
//! with [`BOOTSTRAP_SEED`] (a fixed stream, so the same results give the same
//! interval in every build), each draw's mean is taken, and the 2.5th and
//! 97.5th percentiles of those means are the bounds. The paired interval of
//! two runs does the same over the per-task differences of the tasks both ran.
//!
//! No I/O: the summary ([`super::summary`]) and `arena compare` call these.

use std::collections::BTreeMap;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// The seed of every bootstrap (documented in docs/results.md).
pub const BOOTSTRAP_SEED: u64 = 20_260_530;
/// Draws per bootstrap.
pub const BOOTSTRAP_RESAMPLES: usize = 10_000;

/// The unbiased pass@k of one task: `n` trials, `c` successes; `None` when `k` is 0 or above `n`.
pub fn pass_at_k(n: u32, c: u32, k: u32) -> Option<f64> {
    if k == 0 || k > n || c > n {
        return None;
    }
    if n - c < k {
        return Some(1.0);
    }
    let fail_all: f64 = (n - c + 1..=n).map(|i| 1.0 - f64::from(k) / f64::from(i)).product();
    Some(1.0 - fail_all)
}

/// pass^k of one task: `n` trials, `c` successes; `None` when `k` is 0 or above `n`.
pub fn pass_hat_k(n: u32, c: u32, k: u32) -> Option<f64> {
    if k == 0 || k > n || c > n {
        return None;
    }
    if c < k {
        return Some(0.0);
    }
    Some((0..k).map(|i| f64::from(c - i) / f64::from(n - i)).product())
}

/// Per task `(n, c)`: the maps k → percent of pass@k and pass^k for k = 1..max n,
/// each averaged over the tasks with at least k trials.
pub fn pass_maps(tasks: &[(u32, u32)]) -> (BTreeMap<u32, f64>, BTreeMap<u32, f64>) {
    let max = tasks.iter().map(|(n, _)| *n).max().unwrap_or(0);
    let mut at = BTreeMap::new();
    let mut hat = BTreeMap::new();
    for k in 1..=max {
        let mean = |f: fn(u32, u32, u32) -> Option<f64>| {
            let values: Vec<f64> = tasks.iter().filter_map(|&(n, c)| f(n, c, k)).collect();
            100.0 * values.iter().sum::<f64>() / values.len().max(1) as f64
        };
        at.insert(k, mean(pass_at_k));
        hat.insert(k, mean(pass_hat_k));
    }
    (at, hat)
}

/// The 95 % percentile-bootstrap interval of the mean of `values`, `[low, high]`
/// in the values' unit; `None` without values.
pub fn bootstrap_ci95(values: &[f64]) -> Option<[f64; 2]> {
    if values.is_empty() {
        return None;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(BOOTSTRAP_SEED);
    let n = values.len();
    let mut means: Vec<f64> = (0..BOOTSTRAP_RESAMPLES)
        .map(|_| (0..n).map(|_| values[rng.random_range(0..n)]).sum::<f64>() / n as f64)
        .collect();
    means.sort_by(f64::total_cmp);
    Some([percentile(&means, 0.025), percentile(&means, 0.975)])
}

/// The `q` quantile of sorted `values` by linear interpolation between ranks
/// (numpy's default, `method="linear"`).
fn percentile(sorted: &[f64], q: f64) -> f64 {
    let pos = q * (sorted.len() - 1) as f64;
    let (lo, hi) = (pos.floor() as usize, pos.ceil() as usize);
    sorted[lo] + (sorted[hi] - sorted[lo]) * (pos - lo as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// C(n, k) by the definition, for checking the product forms.
    fn choose(n: u32, k: u32) -> f64 {
        if k > n {
            return 0.0;
        }
        (0..k).map(|i| f64::from(n - i) / f64::from(i + 1)).product()
    }

    #[test]
    fn pass_at_k_and_pass_hat_k_are_the_binomial_estimators() {
        for n in 1..=8u32 {
            for c in 0..=n {
                for k in 1..=n {
                    let at = 1.0 - choose(n - c, k) / choose(n, k);
                    let hat = choose(c, k) / choose(n, k);
                    assert!((pass_at_k(n, c, k).unwrap() - at).abs() < 1e-12, "pass@{k} n={n} c={c}");
                    assert!((pass_hat_k(n, c, k).unwrap() - hat).abs() < 1e-12, "pass^{k} n={n} c={c}");
                }
            }
        }
        assert_eq!(pass_at_k(3, 1, 4), None);
        assert_eq!(pass_hat_k(3, 1, 0), None);
        // One trial: both are the success itself.
        assert_eq!((pass_at_k(1, 1, 1), pass_hat_k(1, 0, 1)), (Some(1.0), Some(0.0)));
    }

    #[test]
    fn pass_maps_average_over_tasks_with_enough_trials() {
        // Three tasks of three trials: 3, 1 and 0 successes.
        let (at, hat) = pass_maps(&[(3, 3), (3, 1), (3, 0)]);
        assert!((at[&1] - 100.0 * (1.0 + 1.0 / 3.0) / 3.0).abs() < 1e-9);
        assert!((at[&2] - 100.0 * (1.0 + 2.0 / 3.0) / 3.0).abs() < 1e-9);
        assert!((at[&3] - 100.0 * 2.0 / 3.0).abs() < 1e-9);
        assert!((hat[&3] - 100.0 / 3.0).abs() < 1e-9);
        // A task with one trial counts for k = 1 only.
        let (at, _) = pass_maps(&[(2, 2), (1, 0)]);
        assert_eq!((at[&1], at[&2]), (50.0, 100.0));
        assert!(pass_maps(&[]).0.is_empty());
    }

    #[test]
    fn the_bootstrap_is_seeded_and_brackets_the_mean() {
        let values = [1.0, 0.0, 1.0, 1.0, 0.5, 0.0, 1.0, 0.0];
        let mean = values.iter().sum::<f64>() / values.len() as f64;
        let [low, high] = bootstrap_ci95(&values).unwrap();
        assert!(low < mean && mean < high, "{low} < {mean} < {high}");
        assert!(low >= 0.0 && high <= 1.0);
        assert_eq!(bootstrap_ci95(&values), Some([low, high]), "the same values give the same interval");
        // All equal: no spread.
        assert_eq!(bootstrap_ci95(&[0.5, 0.5, 0.5]), Some([0.5, 0.5]));
        assert_eq!(bootstrap_ci95(&[]), None);
    }

    #[test]
    fn percentiles_interpolate_like_numpy() {
        let sorted = [0.0, 1.0, 2.0, 3.0, 4.0];
        assert_eq!(percentile(&sorted, 0.5), 2.0);
        assert!((percentile(&sorted, 0.025) - 0.1).abs() < 1e-12);
        assert!((percentile(&sorted, 0.975) - 3.9).abs() < 1e-12);
    }
}
