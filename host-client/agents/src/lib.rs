//! The agents of a run (`arena-agents`): what decides the next actions from an
//! observation, and the observation it decides from.
//!
//! Every agent implements [`Agent`]: it gets an [`Observation`] (built by
//! [`observation::observe`]) and answers a [`Prediction`] holding [`AgentAction`]s,
//! which the episode carries out through the executor (`arena-exec`). [`factory`]
//! builds the agent of a run from its options.
//!
//! It is not the episode loop (observe, predict, execute, evaluate: that is
//! `arena_host::episode`, above this crate), it does not carry actions out
//! (`arena-exec`, below it), and it does not decide when a step counts or when to
//! stop. It imports only the crates below it: the client, the action spaces, the
//! executor, the task files, the setup steps' clock, the results' timings and
//! ledger, Set-of-Marks (`arena-som`) and `arena_vm::child` for an exec agent's
//! process tree.
//!
//! # Layout
//!
//! - [`observation`]: [`Observation`], what an agent sees at one step, and its one builder ([`observation::observe`]).
//! - [`parse`]: code blocks, `DONE`/`FAIL`/`WAIT` and the memory block in model output.
//! - [`navi`]: [`navi::NaviAgent`], Navi-style prompting of any OpenAI-compatible chat endpoint;
//!   [`waa_prompts`], upstream's prompt texts read from a WAA checkout; [`llm`], the chat client.
//! - [`scripted`]: [`scripted::ScriptedAgent`], which follows a plan file (oracle solutions, tests).
//! - [`replay`]: [`replay::ReplayAgent`], which repeats a recorded trajectory.
//! - [`cu`]: the computer-use agents (Anthropic's `computer` tool, OpenAI's Responses API, UI-TARS).
//! - [`external`]: [`external::ExternalAgent`], an agent in another program over the step protocol.
//! - [`floor`]: [`floor::FloorAgent`], `--agent noop` (DONE at once) and `--agent fail` (FAIL at once).
//! - [`factory`]: [`factory::build`], a run's agent from its [`factory::AgentOptions`].
//! - [`body`]: the bounds on what an agent sends (the answer cap) and error chains.

#![forbid(unsafe_code)]

pub mod body;
pub mod cu;
pub mod external;
pub mod factory;
pub mod floor;
pub mod llm;
pub mod navi;
pub mod observation;
pub mod parse;
pub mod replay;
pub mod scripted;
pub mod waa_prompts;

use std::sync::Arc;

use serde::{Deserialize, Serialize};

use arena_client::error::ClientError;

use crate::observation::Observation;
use arena_exec::AgentAction;
use arena_exec::ExecError;
use arena_results::ledger::Usage;
use arena_results::timings::PredictTimings;
use arena_som::Marks;
use arena_task::Task;

/// An agent's answer for one step.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Prediction {
    /// The model's full reply (or a description of the plan step).
    pub response: String,
    /// What to do, in order. Empty when the output was malformed.
    pub actions: Vec<AgentAction>,
    /// The element boxes `move_id` resolves against, when the agent used Set-of-Marks.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub marks: Option<Marks>,
    /// Why the output could not be used (no code block, a parse error). The
    /// step is spent and the agent is asked again; the agent keeps the error
    /// to tell the model.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub raw_error: Option<String>,
    /// What the agent wants kept about this step (the request it sent, the
    /// annotated image, the element list), written beside the trajectory as
    /// upstream's recorder writes an agent's `logs`.
    #[serde(skip)]
    pub logs: Vec<StepLog>,
    /// How long the agent's own parts took (Set-of-Marks, the model), for `traj.jsonl`.
    #[serde(skip)]
    pub timings: PredictTimings,
    /// What this prediction's pyautogui code measures coordinates in, when the agent
    /// said (an outside agent's `hello`); `None` is the run's `--coords`.
    #[serde(skip)]
    pub coords: Option<arena_actionspace::Coords>,
    /// The tokens and model time this prediction cost, when the agent knows
    /// (the built-in model agents from their responses' `usage`, an outside
    /// agent from its `act`'s `usage`).
    #[serde(skip)]
    pub usage: Option<Usage>,
}

/// One entry of an agent's per-step logs.
#[derive(Debug, Clone, PartialEq)]
pub struct StepLog {
    /// The key, which names the file (`<key>-step_<i>_<time>.<ext>`) and the trajectory field.
    pub key: String,
    pub value: LogValue,
}

/// A log entry's value: how it is kept.
#[derive(Debug, Clone, PartialEq)]
pub enum LogValue {
    /// A `.txt` file.
    Text(String),
    /// A `.png` file.
    Png(Vec<u8>),
    /// A `.png` file, encoded from these pixels when it is written.
    Image(std::sync::Arc<image::RgbaImage>),
    /// A `.json` file.
    Json(serde_json::Value),
    /// Inline in the trajectory line.
    Inline(serde_json::Value),
}

/// Why an agent could not answer, or an action could not be carried out.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum AgentError {
    /// The model endpoint failed (unreachable, HTTP error, an answer that is not a chat completion).
    #[error("model endpoint {endpoint}: {reason}")]
    Model { endpoint: String, reason: String },
    /// A plan or trajectory file is missing or malformed.
    #[error("{path}: {reason}")]
    Plan { path: String, reason: String },
    /// A scripted or replayed agent has no steps left.
    #[error("{0}: no steps left")]
    Exhausted(String),
    /// The guest could not be reached while carrying out an action (an infrastructure error,
    /// not the agent's fault).
    #[error(transparent)]
    Guest(#[from] ClientError),
    /// The model refused to answer (`message.refusal` without content). Upstream's
    /// Navi cannot read such an answer, and the task is left unfinished, as for
    /// [`AgentError::Model`] but without asking again.
    #[error("model endpoint {endpoint} refused: {text}")]
    Refused { endpoint: String, text: String },
    /// The agent's configuration is unusable.
    #[error("agent configuration: {0}")]
    Config(String),
    /// The worker thread that ran a script died.
    #[error("the script worker failed: {0}")]
    Worker(String),
    /// An outside agent broke the step protocol, did not answer in time, gave
    /// up, or its process died (`--agent exec`, `--agent http`, `--agent mcp`).
    #[error("agent {agent}: {reason}")]
    External { agent: String, reason: String },
}

/// Something that picks actions from observations.
#[async_trait::async_trait]
pub trait Agent: Send {
    /// A short name for results and logs (`navi`, `scripted`, `replay`).
    fn name(&self) -> &str;

    /// Forgets the previous episode and prepares for `task`.
    async fn reset(&mut self, task: &Task);

    /// The next actions for `obs`.
    ///
    /// # Errors
    ///
    /// [`AgentError`] when no answer can be had at all (model endpoint down,
    /// plan missing or used up). Malformed model output is not an error: it is a
    /// [`Prediction`] with no actions and [`Prediction::raw_error`] set.
    async fn predict(&mut self, obs: &Observation) -> Result<Prediction, AgentError>;

    /// The episode's result folder, named before [`Agent::reset`], for files an
    /// agent keeps beside the trajectory (an exec agent's stderr).
    fn keep_files_in(&mut self, _dir: &std::path::Path) {}

    /// Whether each observation should carry the browser's DOM elements
    /// ([`Observation::dom`]); reading them costs a DevTools round trip per step.
    fn wants_dom(&self) -> bool {
        false
    }

    /// The tokens and model time spent since the last call, for the cost ledger:
    /// the built-in model agents answer their client's count (every answered
    /// call, a prediction that then failed included); `None` for agents without a model.
    fn take_usage(&mut self) -> Option<Usage> {
        None
    }
}

impl From<ExecError> for AgentError {
    fn from(err: ExecError) -> AgentError {
        match err {
            ExecError::Guest(err) => AgentError::Guest(err),
            ExecError::Worker(reason) => AgentError::Worker(reason),
        }
    }
}

/// Makes a fresh agent for each episode.
pub type AgentFactory = Arc<dyn Fn() -> Result<Box<dyn Agent>, AgentError> + Send + Sync>;

#[cfg(test)]
mod tests {
    use super::Usage;
    use serde_json::json;

    #[test]
    fn usage_is_read_from_each_vendors_response() {
        // Chat completions (openai-python's CompletionUsage).
        let chat = json!({"usage": {"prompt_tokens": 120, "completion_tokens": 30, "total_tokens": 150,
            "prompt_tokens_details": {"cached_tokens": 100}}});
        assert_eq!(Usage::of_response(&chat), Some(Usage { input: 120, output: 30, cached: 100, model_ms: 0 }));
        // The Responses API (ResponseUsage).
        let responses = json!({"usage": {"input_tokens": 50, "output_tokens": 7, "total_tokens": 57,
            "input_tokens_details": {"cached_tokens": 20}, "output_tokens_details": {"reasoning_tokens": 3}}});
        assert_eq!(Usage::of_response(&responses), Some(Usage { input: 50, output: 7, cached: 20, model_ms: 0 }));
        // Anthropic's Messages: input_tokens leaves the cache out.
        let anthropic = json!({"usage": {"input_tokens": 10, "cache_read_input_tokens": 200,
            "cache_creation_input_tokens": 5, "output_tokens": 9}});
        assert_eq!(Usage::of_response(&anthropic), Some(Usage { input: 215, output: 9, cached: 200, model_ms: 0 }));
        assert_eq!(Usage::of_response(&json!({"choices": []})), None);
        assert_eq!(Usage::of_response(&json!({"usage": {"prompt_tokens": -1}})), None);
        // A cached count above the input is bounded by it.
        let odd = json!({"usage": {"prompt_tokens": 1, "completion_tokens": 1, "prompt_tokens_details": {"cached_tokens": 9}}});
        assert_eq!(Usage::of_response(&odd).map(|u| u.cached), Some(1));
    }
}
