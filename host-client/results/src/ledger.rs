//! The cost ledger: what tokens cost (`--prices FILE`), and the budget that
//! stops a run from starting new tasks (`--max-cost`, `--max-total-tokens`).
//!
//! Tokens are counted per step from the model agents' responses and from an
//! outside agent's `act` ([`Usage`]); a task's total is in its
//! `episode.json`, with its cost when a price file was given. No price is
//! built in: prices change, and a stale one would be a wrong number.
//!
//! The price file is JSON, a model name to its prices in US dollars per
//! million tokens:
//!
//! ```json
//! {"gpt-4o": {"input": 2.5, "output": 10.0, "cached_input": 1.25}}
//! ```
//!
//! `cached_input` (the price of input tokens read from the prompt cache) is
//! optional and defaults to `input`. A task costs
//! `((input − cached) × input + cached × cached_input + output × output) / 10⁶`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::{write_json, ResultsError};

/// Tokens and model time: of one step, a task, a domain or a run (the cost ledger).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Usage {
    /// Prompt tokens, those read from a cache included.
    #[serde(default)]
    pub input: u64,
    /// Completion tokens (reasoning included where the vendor counts it there).
    #[serde(default)]
    pub output: u64,
    /// The part of [`Usage::input`] read from the vendor's prompt cache.
    #[serde(default)]
    pub cached: u64,
    /// Wall time of the model calls that answered, in milliseconds.
    #[serde(default)]
    pub model_ms: u64,
}

impl Usage {
    /// Adds `other` into this one (saturating).
    pub fn add(&mut self, other: &Usage) {
        self.input = self.input.saturating_add(other.input);
        self.output = self.output.saturating_add(other.output);
        self.cached = self.cached.saturating_add(other.cached);
        self.model_ms = self.model_ms.saturating_add(other.model_ms);
    }

    /// Input plus output tokens.
    pub fn total(&self) -> u64 {
        self.input.saturating_add(self.output)
    }

    /// The `usage` object of a model response, whichever vendor's shape it has:
    /// chat completions (`prompt_tokens`, `completion_tokens`,
    /// `prompt_tokens_details.cached_tokens`; openai-python's `CompletionUsage`),
    /// the Responses API (`input_tokens`, `output_tokens`,
    /// `input_tokens_details.cached_tokens`; `ResponseUsage`), and Anthropic's
    /// Messages (`input_tokens` without the cache, `cache_read_input_tokens`,
    /// `cache_creation_input_tokens`, `output_tokens`; anthropic-python's `Usage`),
    /// whose input here is the three input counts together. `None` without a
    /// `usage` object or counts in it.
    pub fn of_response(answer: &serde_json::Value) -> Option<Usage> {
        let usage = answer.get("usage")?;
        let n = |v: &serde_json::Value, key: &str| v.get(key).and_then(serde_json::Value::as_u64);
        if let (Some(input), Some(output)) = (n(usage, "prompt_tokens"), n(usage, "completion_tokens")) {
            let cached = usage.get("prompt_tokens_details").and_then(|d| n(d, "cached_tokens")).unwrap_or(0);
            return Some(Usage { input, output, cached: cached.min(input), model_ms: 0 });
        }
        let (input, output) = (n(usage, "input_tokens")?, n(usage, "output_tokens")?);
        let read = n(usage, "cache_read_input_tokens");
        let written = n(usage, "cache_creation_input_tokens");
        if read.is_some() || written.is_some() {
            let (read, written) = (read.unwrap_or(0), written.unwrap_or(0));
            return Some(Usage {
                input: input.saturating_add(read).saturating_add(written),
                output,
                cached: read,
                model_ms: 0,
            });
        }
        let cached = usage.get("input_tokens_details").and_then(|d| n(d, "cached_tokens")).unwrap_or(0);
        Some(Usage { input, output, cached: cached.min(input), model_ms: 0 })
    }
}

/// The run's budget record, at the root of the result folder; the summary shows it.
pub const BUDGET_JSON: &str = "budget.json";

/// The largest price file read.
const MAX_PRICES_BYTES: u64 = 1 << 20;

/// One model's prices, in US dollars per million tokens.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Price {
    pub input: f64,
    pub output: f64,
    #[serde(default)]
    pub cached_input: Option<f64>,
}

/// A price file: model name → [`Price`].
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Prices(pub BTreeMap<String, Price>);

impl Prices {
    /// Reads and checks a price file (every price a finite number, 0 or more).
    ///
    /// # Errors
    ///
    /// The file cannot be read, is not the format above, or holds a negative or non-finite price.
    pub fn load(path: &Path) -> Result<Prices, ResultsError> {
        let bad = |message: String| ResultsError::Format { path: path.to_owned(), message };
        let meta =
            std::fs::metadata(path).map_err(|source| ResultsError::Io { path: path.to_owned(), reason: source })?;
        if meta.len() > MAX_PRICES_BYTES {
            return Err(bad(format!("a price file of {} bytes is over the limit of {MAX_PRICES_BYTES}", meta.len())));
        }
        let text = std::fs::read_to_string(path)
            .map_err(|source| ResultsError::Io { path: path.to_owned(), reason: source })?;
        let prices: Prices = serde_json::from_str(&text).map_err(|err| {
            bad(format!(
                "{err}; expected {{\"MODEL\": {{\"input\": USD, \"output\": USD, \"cached_input\": USD}}}} per million tokens"
            ))
        })?;
        for (model, price) in &prices.0 {
            for (name, value) in
                [("input", Some(price.input)), ("output", Some(price.output)), ("cached_input", price.cached_input)]
            {
                if let Some(value) = value.filter(|v| !v.is_finite() || *v < 0.0) {
                    return Err(bad(format!("{model}: {name} is {value}; a price is a number of dollars, 0 or more")));
                }
            }
        }
        Ok(prices)
    }

    /// The price of `model`.
    ///
    /// # Errors
    ///
    /// The file has no entry for it (the message lists those it has).
    pub fn of(&self, model: &str, path: &Path) -> Result<Price, ResultsError> {
        self.0.get(model).copied().ok_or_else(|| ResultsError::Format {
            path: path.to_owned(),
            message: format!(
                "no price for the run's model {model:?} (the file prices {})",
                if self.0.is_empty() {
                    "nothing".to_owned()
                } else {
                    self.0.keys().map(|k| format!("{k:?}")).collect::<Vec<_>>().join(", ")
                }
            ),
        })
    }
}

impl Price {
    /// What `usage` costs, in US dollars.
    pub fn cost(&self, usage: &Usage) -> f64 {
        let cached = usage.cached.min(usage.input);
        let fresh = usage.input - cached;
        (fresh as f64 * self.input
            + cached as f64 * self.cached_input.unwrap_or(self.input)
            + usage.output as f64 * self.output)
            / 1e6
    }
}

/// `--max-cost` and `--max-total-tokens`: when either is reached, no new task starts.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Budget {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_cost_usd: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_tokens: Option<u64>,
}

impl Budget {
    /// Whether the budget has any limit.
    pub fn is_set(&self) -> bool {
        self.max_cost_usd.is_some() || self.max_tokens.is_some()
    }

    /// Whether `spent` reaches a limit: in words, which one.
    pub fn reached(&self, spent: &Spent) -> Option<String> {
        if let Some(max) = self.max_cost_usd.filter(|max| spent.cost_usd >= *max) {
            return Some(format!("spent ${:.4} of --max-cost ${max}", spent.cost_usd));
        }
        if let Some(max) = self.max_tokens.filter(|max| spent.tokens.total() >= *max) {
            return Some(format!("used {} tokens of --max-total-tokens {max}", spent.tokens.total()));
        }
        None
    }
}

/// What the output folder's tasks have spent.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Spent {
    pub tokens: Usage,
    pub cost_usd: f64,
}

impl Spent {
    /// Adds one episode's tokens and cost.
    pub fn add(&mut self, tokens: Option<&Usage>, cost_usd: Option<f64>) {
        if let Some(tokens) = tokens {
            self.tokens.add(tokens);
        }
        self.cost_usd += cost_usd.unwrap_or(0.0);
    }
}

/// The budget's record (`budget.json`): the limits, what was spent, and
/// whether the run stopped starting tasks because of it.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct BudgetRecord {
    #[serde(flatten)]
    pub budget: Budget,
    /// Spent by every task of the folder when the run ended (earlier runs of it included).
    pub spent: Spent,
    /// Why the run stopped starting tasks, when the budget stopped it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stopped: Option<String>,
    /// The tasks (`domain/name`, with `#trial` in a run of several trials) the budget kept from starting.
    #[serde(default)]
    pub not_started: Vec<String>,
}

impl BudgetRecord {
    /// Writes `budget.json` into `root`.
    ///
    /// # Errors
    ///
    /// The file cannot be written.
    pub fn write(&self, root: &Path) -> Result<PathBuf, ResultsError> {
        let path = root.join(BUDGET_JSON);
        write_json(&path, self)?;
        Ok(path)
    }

    /// Reads `budget.json` from `root`; `None` when there is none or it does not parse.
    pub fn read(root: &Path) -> Option<BudgetRecord> {
        let bytes = std::fs::read(root.join(BUDGET_JSON)).ok()?;
        serde_json::from_slice(&bytes).ok()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_price_file_prices_fresh_cached_and_output_tokens() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("prices.json");
        std::fs::write(
            &path,
            r#"{"m": {"input": 2.0, "output": 10.0, "cached_input": 0.5}, "n": {"input": 1, "output": 1}}"#,
        )
        .unwrap();
        let prices = Prices::load(&path).unwrap();
        let usage = Usage { input: 1_000_000, output: 100_000, cached: 400_000, model_ms: 0 };
        let cost = prices.of("m", &path).unwrap().cost(&usage);
        assert!((cost - (0.6 * 2.0 + 0.4 * 0.5 + 0.1 * 10.0)).abs() < 1e-12, "{cost}");
        // Without a cached price, cached tokens cost as input.
        assert!((prices.of("n", &path).unwrap().cost(&usage) - 1.1).abs() < 1e-12);
        let err = prices.of("gpt-x", &path).unwrap_err().to_string();
        assert!(err.contains("\"gpt-x\"") && err.contains("\"m\", \"n\""), "{err}");
    }

    #[test]
    fn bad_price_files_are_refused_by_name() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("prices.json");
        for (text, says) in [
            (r#"{"m": {"input": -1, "output": 1}}"#, "m: input is -1"),
            (r#"{"m": {"input": 1}}"#, "missing field `output`"),
            (r#"{"m": {"input": 1, "output": 1, "cache": 1}}"#, "unknown field `cache`"),
            ("[1]", "expected {"),
        ] {
            std::fs::write(&path, text).unwrap();
            let err = Prices::load(&path).unwrap_err().to_string();
            assert!(err.contains(says) && err.contains("prices.json"), "{text}: {err}");
        }
    }

    #[test]
    fn the_budget_is_reached_at_either_limit() {
        let spent = Spent { tokens: Usage { input: 90, output: 10, cached: 0, model_ms: 0 }, cost_usd: 0.5 };
        assert_eq!(Budget::default().reached(&spent), None);
        assert!(Budget { max_cost_usd: Some(0.5), max_tokens: None }.reached(&spent).unwrap().contains("--max-cost"));
        assert_eq!(Budget { max_cost_usd: Some(0.6), max_tokens: None }.reached(&spent), None);
        assert!(Budget { max_cost_usd: None, max_tokens: Some(100) }.reached(&spent).unwrap().contains("100 tokens"));
        assert_eq!(Budget { max_cost_usd: None, max_tokens: Some(101) }.reached(&spent), None);
    }
}
