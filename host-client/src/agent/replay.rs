//! [`ReplayAgent`]: repeats a recorded trajectory, one recorded step per prediction.
//!
//! A trajectory is JSON Lines, one object per step as the episode runner
//! writes it; only `step` and `actions` are read ([`TrajectoryStep`]), so the
//! writer may add anything else (timings, screenshots, outcomes):
//!
//! ```json
//! {"step": 1, "actions": [{"kind": "computer", "code": "computer.mouse.move_id(id=3)"}], "response": "..."}
//! {"step": 2, "actions": [{"kind": "done"}]}
//! ```
//!
//! Steps are replayed in file order. A recorded step with no actions (the
//! model's output was malformed) is replayed as an empty step, so a replay
//! spends its steps as the original did. `move_id` is resolved against the
//! marks of the replay's own observation, as it was when recorded.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::{Agent, AgentAction, AgentError, Observation, Prediction};
use crate::task::Task;

/// What a replay reads from one trajectory line.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrajectoryStep {
    pub step: u32,
    #[serde(default)]
    pub actions: Vec<AgentAction>,
}

/// Parses a trajectory; `origin` names it in errors. Blank lines are skipped.
///
/// # Errors
///
/// [`AgentError::Plan`] naming the line that is not a step.
pub fn parse_trajectory(text: &str, origin: &str) -> Result<Vec<TrajectoryStep>, AgentError> {
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, line)| {
            serde_json::from_str(line)
                .map_err(|e| AgentError::Plan { path: origin.to_owned(), reason: format!("line {}: {e}", i + 1) })
        })
        .collect()
}

/// Where a [`ReplayAgent`] finds the trajectory of a task.
#[derive(Debug, Clone, PartialEq)]
pub enum ReplaySource {
    /// The same trajectory for every task.
    File(PathBuf),
    /// A result folder: `<dir>/<domain>/<task name>/traj.jsonl`, as upstream lays results out.
    Dir(PathBuf),
}

/// Repeats a recorded trajectory.
#[derive(Debug)]
pub struct ReplayAgent {
    source: ReplaySource,
    steps: Result<Vec<TrajectoryStep>, String>,
    origin: String,
    next: usize,
}

/// The trajectory file name inside a task's result folder.
pub const TRAJECTORY_FILE: &str = "traj.jsonl";

impl ReplayAgent {
    pub fn new(source: ReplaySource) -> ReplayAgent {
        ReplayAgent { source, steps: Ok(Vec::new()), origin: String::from("trajectory"), next: 0 }
    }

    /// A replay of these steps for any task.
    pub fn from_steps(steps: Vec<TrajectoryStep>) -> ReplayAgent {
        ReplayAgent {
            source: ReplaySource::File(PathBuf::new()),
            steps: Ok(steps),
            origin: "trajectory".into(),
            next: 0,
        }
    }

    fn path_for(&self, task: &Task) -> PathBuf {
        match &self.source {
            ReplaySource::File(path) => path.clone(),
            ReplaySource::Dir(dir) => dir.join(&task.domain).join(&task.name).join(TRAJECTORY_FILE),
        }
    }

    fn load(path: &Path) -> Result<Vec<TrajectoryStep>, AgentError> {
        let origin = path.display().to_string();
        let text = std::fs::read_to_string(path)
            .map_err(|e| AgentError::Plan { path: origin.clone(), reason: e.to_string() })?;
        parse_trajectory(&text, &origin)
    }
}

#[async_trait::async_trait]
impl Agent for ReplayAgent {
    fn name(&self) -> &str {
        "replay"
    }

    async fn reset(&mut self, task: &Task) {
        self.next = 0;
        let path = self.path_for(task);
        if path.as_os_str().is_empty() {
            // Built from steps: nothing to load.
            return;
        }
        self.origin = path.display().to_string();
        self.steps = ReplayAgent::load(&path).map_err(|e| e.to_string());
    }

    async fn predict(&mut self, obs: &Observation) -> Result<Prediction, AgentError> {
        let steps =
            self.steps.as_ref().map_err(|e| AgentError::Plan { path: self.origin.clone(), reason: e.clone() })?;
        let step = steps.get(self.next).cloned().ok_or_else(|| AgentError::Exhausted(self.origin.clone()))?;
        self.next += 1;
        let uses_marks = step.actions.iter().any(|a| matches!(a, AgentAction::Computer(_)));
        let summary: Vec<String> = step.actions.iter().map(AgentAction::summary).collect();
        Ok(Prediction {
            response: format!("replayed step {}: {}", step.step, summary.join(" | ")),
            marks: if uses_marks { obs.marks() } else { None },
            raw_error: step.actions.is_empty().then(|| format!("recorded step {} had no actions", step.step)),
            actions: step.actions,
        })
    }
}
