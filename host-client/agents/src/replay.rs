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

use super::{Agent, AgentError, Prediction};
use crate::observation::Observation;
use arena_exec::AgentAction;
use arena_task::Task;

/// What a replay reads from one trajectory line.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrajectoryStep {
    pub step: u32,
    #[serde(default)]
    pub actions: Vec<AgentAction>,
}

/// Parses a trajectory; `origin` names it in errors. Blank lines are skipped.
///
/// Two formats are read, line by line:
/// - ours: `{"step": n, "actions": [...]}`, one line per step;
/// - upstream's `traj.jsonl` (`trajectory_recorder.py`): one line per action,
///   `{"step_num": n, "action": "<code>" | "DONE" | "FAIL" | "WAIT", ...}`, where
///   consecutive lines of one `step_num` form one step, the `step_num` 0 line is
///   the reset (skipped), and `{"Error": ...}` lines that `run.py` appends after
///   an exception are skipped with a warning. Upstream's code is Navi's
///   `code_block` action space, so it replays as [`AgentAction::Computer`].
///
/// # Errors
///
/// [`AgentError::Plan`] naming the line that is neither.
pub fn parse_trajectory(text: &str, origin: &str) -> Result<Vec<TrajectoryStep>, AgentError> {
    let bad = |i: usize, reason: String| AgentError::Plan {
        path: origin.to_owned(),
        reason: format!("line {}: {reason}", i + 1),
    };
    let mut steps: Vec<TrajectoryStep> = Vec::new();
    let mut upstream_step: Option<u64> = None;
    let mut ours: Option<u64> = None;
    for (i, line) in text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty()) {
        let value: serde_json::Value = serde_json::from_str(line).map_err(|e| bad(i, e.to_string()))?;
        if value.get("Error").is_some() {
            tracing::warn!(origin, line = i + 1, error = %value["Error"], "skipping an error line of an upstream trajectory");
            continue;
        }
        if value.get("step").is_some() {
            let step: TrajectoryStep = serde_json::from_value(value).map_err(|e| bad(i, e.to_string()))?;
            // Our line holds the whole step: the upstream lines after it for the
            // step's further actions repeat what `actions` already has.
            ours = Some(u64::from(step.step));
            steps.push(step);
            continue;
        }
        let Some(number) = value.get("step_num").and_then(serde_json::Value::as_u64) else {
            return Err(bad(i, "neither a step (`step`) nor an upstream trajectory line (`step_num`)".into()));
        };
        if number == 0 || ours == Some(number) {
            continue;
        }
        let action = match value.get("action") {
            Some(serde_json::Value::String(code)) => match arena_actionspace::Decision::parse(code) {
                Some(decision) => decision.into(),
                None => AgentAction::Computer(code.clone().into()),
            },
            other => return Err(bad(i, format!("`action` is not a string: {other:?}"))),
        };
        if upstream_step == Some(number) {
            if let Some(last) = steps.last_mut() {
                last.actions.push(action);
                continue;
            }
        }
        upstream_step = Some(number);
        steps.push(TrajectoryStep { step: u32::try_from(number).unwrap_or(u32::MAX), actions: vec![action] });
    }
    Ok(steps)
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
            logs: Vec::new(),
            timings: Default::default(),
            coords: None,
            usage: None,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn upstream_trajectories_replay_step_by_step() {
        // Laid out as upstream's recorder and run.py write them (keys from
        // trajectory_recorder.py; values made up here).
        let text = [
            r#"{"step_num": 0, "action_timestamp": "20261124@101500", "action": null, "screenshot": "screenshot-step_reset_20261124@101500.png"}"#,
            r#"{"step_num": 1, "action_timestamp": "20261124@101510", "action": "computer.mouse.move_id(id=3)", "reward": 0, "done": false, "info": {}}"#,
            r#"{"step_num": 1, "action_timestamp": "20261124@101512", "action": "computer.mouse.single_click()", "reward": 0, "done": false, "info": {}}"#,
            r#"{"step_num": 2, "action_timestamp": "20261124@101520", "action": "WAIT", "reward": 0, "done": false, "info": {}}"#,
            r#"{"Error": "Exception in notepad/t", "Exception": "boom", "Traceback": "..."}"#,
            r#"{"step_num": 3, "action_timestamp": "20261124@101530", "action": "DONE", "reward": 0, "done": true, "info": {"done": true}}"#,
        ]
        .join("\n");
        let steps = parse_trajectory(&text, "t").expect("an upstream trajectory reads");
        assert_eq!(
            steps,
            vec![
                TrajectoryStep {
                    step: 1,
                    actions: vec![
                        AgentAction::Computer("computer.mouse.move_id(id=3)".into()),
                        AgentAction::Computer("computer.mouse.single_click()".into()),
                    ],
                },
                TrajectoryStep { step: 2, actions: vec![AgentAction::Wait] },
                TrajectoryStep { step: 3, actions: vec![AgentAction::Done] },
            ]
        );
        // Our own format still reads: a step's first line holds all its actions,
        // and the upstream-only lines after it are not counted twice.
        let ours = [
            r#"{"step_num": 0, "action": null}"#,
            r#"{"step_num": 1, "step": 1, "action": "WAIT", "actions": [{"kind": "wait"}, {"kind": "done"}]}"#,
            r#"{"step_num": 1, "action": "DONE", "done": true}"#,
        ]
        .join("\n");
        let ours = parse_trajectory(&ours, "t").unwrap();
        assert_eq!(ours, vec![TrajectoryStep { step: 1, actions: vec![AgentAction::Wait, AgentAction::Done] }]);
        let err = parse_trajectory("{\"what\": 1}", "t").unwrap_err().to_string();
        assert!(err.contains("line 1") && err.contains("step_num"), "{err}");
        let err = parse_trajectory(r#"{"step_num": 1, "action": 3}"#, "t").unwrap_err().to_string();
        assert!(err.contains("not a string"), "{err}");
    }
}
