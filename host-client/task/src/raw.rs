//! The raw layer: serde structs that mirror upstream's task files as written,
//! stray keys included. Nothing here is validated; [`super::Task::from_data`]
//! turns it into the checked model.

use serde::Deserialize;
use serde_json::{Map, Value};

/// One value or a list of them, as upstream writes `func`, `result`, `expected` and `options`.
#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
pub(crate) enum OneOrMany<T> {
    Many(Vec<T>),
    One(T),
}

impl<T> OneOrMany<T> {
    pub(crate) fn into_vec(self) -> Vec<T> {
        match self {
            OneOrMany::One(it) => vec![it],
            OneOrMany::Many(items) => items,
        }
    }

    pub(crate) fn is_many(&self) -> bool {
        matches!(self, OneOrMany::Many(_))
    }
}

/// A task file.
#[derive(Debug, Clone, Deserialize)]
pub(crate) struct TaskData {
    pub(crate) id: String,
    pub(crate) instruction: String,
    #[serde(default)]
    pub(crate) snapshot: Option<String>,
    #[serde(default)]
    pub(crate) source: Option<Value>,
    #[serde(default)]
    pub(crate) config: Vec<StepData>,
    #[serde(default)]
    pub(crate) related_apps: Vec<String>,
    pub(crate) evaluator: EvaluatorData,
    /// `trajectory`, `_comments`, `comments`, `_commments` and whatever else upstream adds.
    #[serde(flatten)]
    pub(crate) extra: Map<String, Value>,
}

/// `{"type": ..., "parameters": {...}}`.
#[derive(Debug, Clone, Deserialize)]
pub(crate) struct StepData {
    #[serde(rename = "type")]
    pub(crate) kind: String,
    #[serde(default)]
    pub(crate) parameters: Map<String, Value>,
}

/// The `evaluator` object.
#[derive(Debug, Clone, Deserialize)]
pub(crate) struct EvaluatorData {
    #[serde(default)]
    pub(crate) postconfig: Vec<StepData>,
    pub(crate) func: OneOrMany<String>,
    #[serde(default)]
    pub(crate) conj: Option<String>,
    #[serde(default)]
    pub(crate) result: Option<OneOrMany<Value>>,
    #[serde(default)]
    pub(crate) expected: Option<OneOrMany<Value>>,
    #[serde(default)]
    pub(crate) options: Option<OneOrMany<Value>>,
}
