//! [`ScriptedAgent`]: follows a plan, one step per prediction. Used for oracle
//! solutions of tasks and in tests.
//!
//! A plan is JSON:
//!
//! ```json
//! {"steps": [
//!   {"code": "computer.mouse.move_id(id=3)\ncomputer.mouse.single_click()"},
//!   {"code": "pyautogui.hotkey('ctrl', 's')", "lang": "pyautogui"},
//!   {"actions": [{"type": "type_text", "text": "hello"}]},
//!   {"space": "computer_20250124", "input": {"action": "key", "text": "ctrl+s"}},
//!   "WAIT",
//!   "DONE"
//! ]}
//! ```
//!
//! `lang` is `computer` (the default) or `pyautogui`. A `space` step is an
//! answer in one of the action spaces a computer-use agent answers in
//! (`arena_actionspace::ActionSpace`'s names: `computer_20250124`,
//! `openai_computer`, `uitars`, ...), its `input` what such an agent sends (one
//! action or a list), translated by `arena_actionspace::parse` against the
//! observation's screen in pixels when the step is played, as that agent's
//! answer would be. Where the plan comes
//! from is a [`PlanSource`]: one plan for every task, a folder with one plan
//! per task, or a `plan` key inside the task file itself (task files keep
//! unknown top-level keys).
//!
//! It is not a model and never looks at the screen, except to compute the
//! Set-of-Marks boxes so that `move_id` in a plan means what it would mean
//! for Navi.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use arena_actionspace::{ActionSpace, Context, Coords};
use arena_shared::action::Action;

use super::{Agent, AgentError, Prediction};
use crate::observation::Observation;
use arena_exec::AgentAction;
use arena_task::Task;

/// One plan step as written.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum PlanStep {
    /// `"DONE"`, `"FAIL"` or `"WAIT"`.
    Control(String),
    Code {
        code: String,
        #[serde(default)]
        lang: CodeLang,
    },
    Actions {
        actions: Vec<Action>,
    },
    /// An answer in a computer-use action space, by the space's name.
    Space {
        space: String,
        input: serde_json::Value,
    },
}

/// A plan step ready to play: an action, or an answer in an action space that is
/// translated against the screen of the observation it answers.
#[derive(Debug, Clone, PartialEq)]
enum Planned {
    Action(AgentAction),
    Space(ActionSpace, serde_json::Value),
}

impl Planned {
    fn summary(&self) -> String {
        match self {
            Planned::Action(action) => action.summary(),
            Planned::Space(space, input) => format!("{} {input}", space.name()),
        }
    }
}

/// The language of a code step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CodeLang {
    #[default]
    Computer,
    Pyautogui,
}

/// A plan file.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Plan {
    pub steps: Vec<PlanStep>,
}

impl PlanStep {
    fn planned(&self) -> Result<Planned, String> {
        if let PlanStep::Space { space, input } = self {
            let space: ActionSpace = space.parse()?;
            // Checked now against a stand-in screen, so a bad step fails when the plan loads.
            arena_actionspace::parse(space, input, &Context::new((1920, 1080), Coords::Pixels))
                .map_err(|err| format!("in action space {}: {err}", space.name()))?;
            return Ok(Planned::Space(space, input.clone()));
        }
        self.action().map(Planned::Action)
    }

    fn action(&self) -> Result<AgentAction, String> {
        Ok(match self {
            PlanStep::Control(word) => match arena_actionspace::Decision::parse(word) {
                Some(decision) => decision.into(),
                None => return Err(format!("unknown step {:?} (expected DONE, FAIL or WAIT)", word.trim())),
            },
            PlanStep::Code { code, lang: CodeLang::Computer } => AgentAction::Computer(code.clone().into()),
            PlanStep::Code { code, lang: CodeLang::Pyautogui } => AgentAction::Pyautogui(code.clone().into()),
            PlanStep::Actions { actions } => AgentAction::Typed(actions.clone()),
            PlanStep::Space { .. } => return Err("an action-space step is translated when it is played".into()),
        })
    }
}

impl Plan {
    /// Parses a plan; `origin` names it in errors.
    ///
    /// # Errors
    ///
    /// [`AgentError::Plan`] for bad JSON or an unknown control word, naming the step.
    pub fn parse(text: &str, origin: &str) -> Result<Plan, AgentError> {
        let plan: Plan = serde_json::from_str(text).map_err(|e| plan_error(origin, e.to_string()))?;
        plan.planned(origin)?;
        Ok(plan)
    }

    /// Reads and parses a plan file.
    ///
    /// # Errors
    ///
    /// [`AgentError::Plan`] when the file cannot be read or parsed.
    pub fn load(path: &Path) -> Result<Plan, AgentError> {
        let origin = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| plan_error(&origin, e.to_string()))?;
        Plan::parse(&text, &origin)
    }

    /// The plan's steps ready to play, one per step.
    fn planned(&self, origin: &str) -> Result<Vec<Planned>, AgentError> {
        self.steps
            .iter()
            .enumerate()
            .map(|(i, s)| s.planned().map_err(|e| plan_error(origin, format!("step {}: {e}", i + 1))))
            .collect()
    }
}

fn plan_error(origin: &str, reason: String) -> AgentError {
    AgentError::Plan { path: origin.to_owned(), reason }
}

/// Where a [`ScriptedAgent`] gets the plan for a task.
#[derive(Debug, Clone, PartialEq)]
pub enum PlanSource {
    /// The same plan for every task.
    Fixed(Plan),
    /// `<dir>/<domain>/<task name>.json`, else `<dir>/<task name>.json`, else the task's own `plan` key.
    Dir(PathBuf),
    /// The `plan` key of the task file.
    TaskKey,
}

impl PlanSource {
    /// Whether this source has a plan for `task` (a file or the task's `plan`
    /// key; a plan that exists but does not parse counts: playing it fails loudly).
    pub fn has_plan(&self, task: &Task) -> bool {
        match self {
            PlanSource::Fixed(_) => true,
            PlanSource::TaskKey => task.extra.contains_key(TASK_PLAN_KEY),
            PlanSource::Dir(dir) => {
                dir.join(&task.domain).join(format!("{}.json", task.name)).is_file()
                    || dir.join(format!("{}.json", task.name)).is_file()
                    || task.extra.contains_key(TASK_PLAN_KEY)
            }
        }
    }
}

/// Follows a plan: step `n` of the episode answers the plan's step `n`.
#[derive(Debug)]
pub struct ScriptedAgent {
    source: PlanSource,
    /// The current task's steps, or why they could not be had.
    steps: Result<Vec<Planned>, String>,
    origin: String,
    next: usize,
}

/// The task-file key holding an inline plan.
pub const TASK_PLAN_KEY: &str = "plan";

impl ScriptedAgent {
    pub fn new(source: PlanSource) -> ScriptedAgent {
        let mut agent = ScriptedAgent { source, steps: Ok(Vec::new()), origin: String::from("plan"), next: 0 };
        if let PlanSource::Fixed(plan) = &agent.source {
            agent.steps = plan.planned("plan").map_err(|e| e.to_string());
        }
        agent
    }

    /// An agent that runs these actions, one per step, for any task.
    pub fn from_actions(actions: Vec<AgentAction>) -> ScriptedAgent {
        let steps = Ok(actions.into_iter().map(Planned::Action).collect());
        ScriptedAgent { source: PlanSource::Fixed(Plan::default()), steps, origin: "plan".into(), next: 0 }
    }

    /// An agent that runs the plan file at `path` for any task.
    ///
    /// # Errors
    ///
    /// [`AgentError::Plan`] when the file cannot be read or parsed.
    pub fn from_file(path: &Path) -> Result<ScriptedAgent, AgentError> {
        let plan = Plan::load(path)?;
        let mut agent = ScriptedAgent::new(PlanSource::Fixed(plan));
        agent.origin = path.display().to_string();
        Ok(agent)
    }

    fn load_for(&self, task: &Task) -> Result<(Vec<Planned>, String), AgentError> {
        let inline = || -> Result<(Vec<Planned>, String), AgentError> {
            let origin = format!("{} ({TASK_PLAN_KEY} key)", task.path.display());
            let value =
                task.extra.get(TASK_PLAN_KEY).ok_or_else(|| plan_error(&origin, "the task has no plan".into()))?;
            let plan: Plan = serde_json::from_value(value.clone()).map_err(|e| plan_error(&origin, e.to_string()))?;
            Ok((plan.planned(&origin)?, origin))
        };
        match &self.source {
            PlanSource::Fixed(plan) => Ok((plan.planned(&self.origin)?, self.origin.clone())),
            PlanSource::TaskKey => inline(),
            PlanSource::Dir(dir) => {
                let candidates = [
                    dir.join(&task.domain).join(format!("{}.json", task.name)),
                    dir.join(format!("{}.json", task.name)),
                ];
                match candidates.iter().find(|p| p.is_file()) {
                    Some(path) => {
                        Ok((Plan::load(path)?.planned(&path.display().to_string())?, path.display().to_string()))
                    }
                    None if task.extra.contains_key(TASK_PLAN_KEY) => inline(),
                    None => Err(plan_error(
                        &candidates[0].display().to_string(),
                        format!("no plan for task {} (also looked for {})", task.name, candidates[1].display()),
                    )),
                }
            }
        }
    }
}

#[async_trait::async_trait]
impl Agent for ScriptedAgent {
    fn name(&self) -> &str {
        "scripted"
    }

    async fn reset(&mut self, task: &Task) {
        self.next = 0;
        if let (PlanSource::Fixed(_), Ok(steps)) = (&self.source, &self.steps) {
            if !steps.is_empty() {
                return;
            }
        }
        match self.load_for(task) {
            Ok((steps, origin)) => {
                self.steps = Ok(steps);
                self.origin = origin;
            }
            Err(err) => self.steps = Err(err.to_string()),
        }
    }

    async fn predict(&mut self, obs: &Observation) -> Result<Prediction, AgentError> {
        let steps =
            self.steps.as_ref().map_err(|e| AgentError::Plan { path: self.origin.clone(), reason: e.clone() })?;
        let step = steps.get(self.next).cloned().ok_or_else(|| AgentError::Exhausted(self.origin.clone()))?;
        self.next += 1;
        let response = format!("plan step {}: {}", self.next, step.summary());
        let actions = match step {
            Planned::Action(action) => vec![action],
            Planned::Space(space, input) => {
                let ctx = Context::new(obs.screen_size(), Coords::Pixels);
                let steps = arena_actionspace::parse(space, &input, &ctx).map_err(|err| AgentError::Plan {
                    path: self.origin.clone(),
                    reason: format!("step {}: in action space {}: {err}", self.next, space.name()),
                })?;
                AgentAction::from_steps(&steps)
            }
        };
        let uses_marks = actions.iter().any(|a| matches!(a, AgentAction::Computer(_)));
        Ok(Prediction {
            response,
            marks: if uses_marks { obs.marks() } else { None },
            actions,
            raw_error: None,
            logs: Vec::new(),
            timings: Default::default(),
            coords: None,
            usage: None,
        })
    }
}
