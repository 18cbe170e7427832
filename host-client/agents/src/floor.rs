//! The floor agents: [`FloorAgent`], which answers one decision at its first
//! step and does nothing else: `--agent noop` answers DONE, `--agent fail`
//! answers FAIL.
//!
//! They measure a task list, not a model: what an agent that does nothing
//! scores (a task it passes is broken: its evaluator accepts the untouched
//! desktop), and what one that gives up on everything scores (the infeasible
//! tasks' share, upstream's `infeasible` scoring). `arena certify` runs both.
//! They never look at the observation and need no guest feature.

use super::{Agent, AgentError, Prediction};
use crate::observation::Observation;
use arena_exec::AgentAction;
use arena_task::Task;

/// Which decision a [`FloorAgent`] answers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Floor {
    /// DONE at the first step, without acting.
    Noop,
    /// FAIL at the first step.
    Fail,
}

impl Floor {
    /// `noop` or `fail`: the agent's name, its action-space and model folder levels.
    pub fn name(self) -> &'static str {
        match self {
            Floor::Noop => "noop",
            Floor::Fail => "fail",
        }
    }
}

/// Answers its [`Floor`]'s decision at every step (the first ends the episode).
#[derive(Debug, Clone)]
pub struct FloorAgent {
    floor: Floor,
}

impl FloorAgent {
    pub fn new(floor: Floor) -> FloorAgent {
        FloorAgent { floor }
    }
}

#[async_trait::async_trait]
impl Agent for FloorAgent {
    fn name(&self) -> &str {
        self.floor.name()
    }

    async fn reset(&mut self, _task: &Task) {}

    async fn predict(&mut self, _obs: &Observation) -> Result<Prediction, AgentError> {
        let (word, action) = match self.floor {
            Floor::Noop => ("DONE", AgentAction::Done),
            Floor::Fail => ("FAIL", AgentAction::Fail),
        };
        Ok(Prediction { response: word.to_owned(), actions: vec![action], ..Prediction::default() })
    }
}
