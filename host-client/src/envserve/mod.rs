//! `arena env serve`: the harness as an environment a program drives, for RL
//! trainers and notebooks (OSWorld's `DesktopEnv` shape: reset, step, evaluate).
//! A client resets a session to a task and steps it with actions in any of the
//! step protocol's action spaces; each session holds one guest for its episode,
//! so several sessions play side by side on several guests.
//!
//! An episode here is the same episode `arena run` plays ([`crate::episode`]):
//! the reset, the task's setup, observations, the actions through the action
//! spaces, the pauses, the evaluation with the task's getters and metrics, and
//! its result folder. Only the agent differs: [`EnvAgent`]'s every prediction
//! waits for the client's next `step`. The observation is the step protocol's
//! `observe` message ([`crate::agent::external::observe`]); the actions are its
//! `act` actions ([`crate::agent::external::spaces`]).
//!
//! HTTP, JSON bodies (schemas in `schemas/env/`, docs in docs/env.md):
//!
//! - `GET /info`: the served tasks, the guests, the step cap and the action spaces;
//! - `POST /reset` `{"task", "session"?, "observation"?}`: starts an episode of a
//!   served task (its id or name) or of a task given whole, on the session's guest
//!   (a new session takes a free one); answers `session`, `observation`, `info`;
//! - `POST /step` `{"session", "actions", "action_space"?}`: one step (one action or
//!   a list; the decisions `DONE` and `FAIL` end the episode); answers
//!   `observation`, `reward` (the score once the episode ends, 0 before), `done`, `info`;
//! - `POST /evaluate` `{"session"}`: the ended episode's score;
//! - `POST /close` `{"session"}`: ends the episode and frees the guest.
//!
//! Bounded as the step protocol is: a body of at most `MAX_ANSWER`, at most
//! `MAX_ACTIONS` actions a step, one session per guest, and a session whose client
//! sends nothing for `idle` ends as an agent error and frees its guest.

use std::collections::{BTreeMap, HashMap};
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use axum::extract::{rejection::JsonRejection, State};
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Json, Router};
use serde::Deserialize;
use serde_json::{json, Value};
use tokio::sync::{mpsc, Mutex};
use tokio_util::sync::CancellationToken;

use crate::agent::external::protocol::{AgentHello, ObservationWants, ACTION_SPACES, MAX_ACTIONS};
use crate::agent::external::transport::MAX_ANSWER;
use crate::agent::{Agent, AgentError, Prediction};
use crate::episode::EpisodeConfig;
use crate::ports::{AgentAction, Observation};
use crate::results::{EpisodeResult, RunLayout};
use arena_actionspace::Coords;
use arena_client::client::GuestClient;
use arena_task::Task;

/// How the server behaves.
#[derive(Debug, Clone)]
pub struct EnvOptions {
    /// Where each episode's result folder goes (`<out>/env/<observation>/env/0/<domain>/<task>`).
    pub out: PathBuf,
    /// The episodes' configuration (step cap, pauses, downloads).
    pub config: EpisodeConfig,
    /// A session whose client sends nothing for this long ends and frees its guest.
    pub idle: Duration,
    /// The guests' screen in pixels (the first guest's), for clients that size
    /// their observation space before the first reset.
    pub screen: Option<(u32, u32)>,
}

/// What one turn of an episode hands the waiting request.
#[derive(Debug)]
enum Turn {
    /// The episode observed and waits for the client's actions.
    Observed { observation: Value, step: u32, screen: (u32, u32) },
    /// The episode ended (decided, out of steps, or failed) and was evaluated.
    Ended(Box<EpisodeResult>),
}

/// The agent of an episode played through the environment: each prediction hands
/// the observation to the client and waits for its next step.
#[derive(Debug)]
pub struct EnvAgent {
    turns: mpsc::Sender<Turn>,
    actions: mpsc::Receiver<(Vec<AgentAction>, Coords)>,
    hello: AgentHello,
    idle: Duration,
}

fn agent_error(reason: impl Into<String>) -> AgentError {
    AgentError::External { agent: "env".into(), reason: reason.into() }
}

#[async_trait::async_trait]
impl Agent for EnvAgent {
    fn name(&self) -> &str {
        "env"
    }

    async fn reset(&mut self, _task: &Task) {}

    async fn predict(&mut self, obs: &Observation) -> Result<Prediction, AgentError> {
        let (observation, marks) =
            crate::agent::external::observe::observe_message(obs, &self.hello, false, None).map_err(agent_error)?;
        let turn = Turn::Observed { observation, step: obs.step, screen: obs.screen_size() };
        if self.turns.send(turn).await.is_err() {
            return Err(agent_error("the environment's session was closed"));
        }
        match tokio::time::timeout(self.idle, self.actions.recv()).await {
            Ok(Some((actions, coords))) => Ok(Prediction {
                response: "env step".into(),
                actions,
                marks,
                coords: Some(coords),
                ..Prediction::default()
            }),
            Ok(None) => Err(agent_error("the environment's session was closed")),
            Err(_) => Err(agent_error(format!("no step within {} s", self.idle.as_secs()))),
        }
    }
}

/// One session: a guest, and the episode it plays now.
#[derive(Debug)]
struct Session {
    guest: GuestClient,
    episode: Option<Episode>,
}

#[derive(Debug)]
struct Episode {
    task: Task,
    actions: mpsc::Sender<(Vec<AgentAction>, Coords)>,
    turns: mpsc::Receiver<Turn>,
    last: Value,
    step: u32,
    screen: (u32, u32),
    ended: Option<Box<EpisodeResult>>,
    worker: tokio::task::JoinHandle<()>,
}

impl Drop for Episode {
    fn drop(&mut self) {
        self.worker.abort();
    }
}

/// The server's state.
#[derive(Debug)]
pub struct EnvServer {
    tasks: Vec<Task>,
    free: std::sync::Mutex<Vec<GuestClient>>,
    guests: usize,
    sessions: std::sync::Mutex<HashMap<String, Arc<Mutex<Session>>>>,
    options: EnvOptions,
}

/// An error answer: a status and a message naming what was wrong.
#[derive(Debug)]
struct Refusal(StatusCode, String);

impl IntoResponse for Refusal {
    fn into_response(self) -> Response {
        (self.0, Json(json!({"error": self.1}))).into_response()
    }
}

fn bad(message: impl Into<String>) -> Refusal {
    Refusal(StatusCode::BAD_REQUEST, message.into())
}

type Answer = Result<Json<Value>, Refusal>;

/// The body as JSON, or a 400 naming what is wrong with it.
fn body<T>(payload: Result<Json<T>, JsonRejection>) -> Result<T, Refusal> {
    payload.map(|Json(v)| v).map_err(|err| bad(format!("the request body: {}", err.body_text())))
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ResetRequest {
    task: Value,
    #[serde(default)]
    session: Option<String>,
    #[serde(default)]
    observation: Option<ObservationWants>,
    #[serde(default)]
    coords: Option<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct StepRequest {
    session: String,
    actions: Value,
    #[serde(default = "pyautogui")]
    action_space: String,
    #[serde(default)]
    coords: Option<String>,
}

fn pyautogui() -> String {
    "pyautogui".into()
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SessionRequest {
    session: String,
}

fn coords_of(name: Option<&str>) -> Result<Coords, Refusal> {
    match name {
        None => Ok(Coords::Pixels),
        Some(name) => name.parse().map_err(|err: String| bad(format!("coords: {err}"))),
    }
}

impl EnvServer {
    /// A server of `tasks` over `guests`.
    pub fn new(tasks: Vec<Task>, guests: Vec<GuestClient>, options: EnvOptions) -> Arc<EnvServer> {
        let count = guests.len();
        Arc::new(EnvServer {
            tasks,
            free: std::sync::Mutex::new(guests),
            guests: count,
            sessions: std::sync::Mutex::new(HashMap::new()),
            options,
        })
    }

    /// The routes.
    pub fn router(self: &Arc<Self>) -> Router {
        Router::new()
            .route("/info", get(info))
            .route("/reset", post(reset))
            .route("/step", post(step))
            .route("/evaluate", post(evaluate))
            .route("/close", post(close))
            .layer(axum::extract::DefaultBodyLimit::max(MAX_ANSWER))
            .with_state(Arc::clone(self))
    }

    fn session(&self, id: &str) -> Result<Arc<Mutex<Session>>, Refusal> {
        let sessions =
            self.sessions.lock().map_err(|_| Refusal(StatusCode::INTERNAL_SERVER_ERROR, "poisoned".into()))?;
        sessions.get(id).cloned().ok_or_else(|| {
            Refusal(StatusCode::NOT_FOUND, format!("no session {id:?}: reset without a session to open one"))
        })
    }

    /// The task `spec` names: a served task's id or name, or a task given whole.
    fn task(&self, spec: &Value) -> Result<Task, Refusal> {
        match spec {
            Value::String(key) => {
                self.tasks.iter().find(|t| t.id == *key || t.name == *key).cloned().ok_or_else(|| {
                    Refusal(
                        StatusCode::NOT_FOUND,
                        format!("no served task has the id or name {key:?} (GET /info lists them)"),
                    )
                })
            }
            Value::Object(fields) => {
                let domain = fields.get("domain").and_then(Value::as_str).unwrap_or("custom");
                let id = fields.get("id").and_then(Value::as_str).unwrap_or("task");
                let path = PathBuf::from("env-tasks")
                    .join(crate::results::safe_component(domain))
                    .join(format!("{}.json", crate::results::safe_component(id)));
                Task::parse(&spec.to_string(), &path).map_err(|err| bad(format!("task: {err}")))
            }
            other => Err(bad(format!("task: a task id or name, or a task object; got {}", kind(other)))),
        }
    }

    /// Starts `task` on `session`'s guest and waits for its first observation.
    async fn start(&self, session: &mut Session, task: Task, hello: AgentHello) -> Result<Value, Refusal> {
        session.episode = None;
        let (turns_tx, mut turns) = mpsc::channel(1);
        let (actions, actions_rx) = mpsc::channel(1);
        let agent = EnvAgent { turns: turns_tx.clone(), actions: actions_rx, hello, idle: self.options.idle };
        let layout = RunLayout {
            root: self.options.out.clone(),
            agent: "env".into(),
            observation: "env".into(),
            model: "env".into(),
            trial: crate::results::DEFAULT_TRIAL_ID.into(),
        };
        let (guest, config, played) = (session.guest.clone(), self.options.config.clone(), task.clone());
        let worker = tokio::spawn(async move {
            let mut agent = agent;
            let out = layout.task_dir(&played);
            let result = crate::episode::run_attempt(&guest, &played, &mut agent, &config, &out, 1, None).await;
            drop(agent);
            let _ = turns_tx.send(Turn::Ended(Box::new(result))).await;
        });
        let mut episode = Episode {
            task,
            actions,
            turns: mpsc::channel(1).1,
            last: Value::Null,
            step: 0,
            screen: (0, 0),
            ended: None,
            worker,
        };
        let first = turns.recv().await;
        episode.turns = turns;
        match first {
            Some(Turn::Observed { observation, step, screen }) => {
                episode.last = observation.clone();
                episode.step = step;
                episode.screen = screen;
                session.episode = Some(episode);
                Ok(observation)
            }
            Some(Turn::Ended(result)) => Err(Refusal(
                StatusCode::BAD_GATEWAY,
                format!(
                    "the episode ended before its first observation ({}): {}",
                    result.status.kind(),
                    result.status.message().unwrap_or("")
                ),
            )),
            None => Err(Refusal(StatusCode::INTERNAL_SERVER_ERROR, "the episode stopped".into())),
        }
    }

    /// Frees `id`'s guest and forgets the session.
    fn forget(&self, id: &str, session: Session) {
        if let Ok(mut sessions) = self.sessions.lock() {
            sessions.remove(id);
        }
        drop(session.episode);
        if let Ok(mut free) = self.free.lock() {
            free.push(session.guest);
        }
    }
}

fn kind(value: &Value) -> &'static str {
    match value {
        Value::Null => "null",
        Value::Bool(_) => "a boolean",
        Value::Number(_) => "a number",
        Value::String(_) => "a string",
        Value::Array(_) => "a list",
        Value::Object(_) => "an object",
    }
}

async fn info(State(server): State<Arc<EnvServer>>) -> Json<Value> {
    let tasks: Vec<Value> = server
        .tasks
        .iter()
        .map(|t| json!({"id": t.id, "name": t.name, "domain": t.domain, "instruction": t.instruction}))
        .collect();
    let free = server.free.lock().map(|f| f.len()).unwrap_or(0);
    Json(json!({
        "tasks": tasks,
        "guests": server.guests,
        "free_guests": free,
        "max_steps": server.options.config.max_steps,
        "action_spaces": ACTION_SPACES,
        "max_actions": MAX_ACTIONS,
        "screen": server.options.screen.map(|(w, h)| json!({"width": w, "height": h})),
    }))
}

async fn reset(State(server): State<Arc<EnvServer>>, payload: Result<Json<ResetRequest>, JsonRejection>) -> Answer {
    let request = body(payload)?;
    let task = server.task(&request.task)?;
    let coords = coords_of(request.coords.as_deref())?;
    let hello = AgentHello {
        protocol: 1,
        agent: Some("env".into()),
        action_space: "pyautogui".into(),
        coords: Some(coords.name()),
        observation: request.observation.unwrap_or_default(),
    };
    let (id, session) = match &request.session {
        Some(id) => (id.clone(), server.session(id)?),
        None => {
            let guest = server.free.lock().ok().and_then(|mut f| f.pop()).ok_or_else(|| {
                Refusal(
                    StatusCode::SERVICE_UNAVAILABLE,
                    format!("every guest ({}) is held by a session: close one, or reset an open one", server.guests),
                )
            })?;
            let id = format!("{:016x}", rand::random::<u64>());
            let session = Arc::new(Mutex::new(Session { guest, episode: None }));
            if let Ok(mut sessions) = server.sessions.lock() {
                sessions.insert(id.clone(), Arc::clone(&session));
            }
            (id, session)
        }
    };
    let mut held = session.lock().await;
    let info = json!({
        "task_id": task.id,
        "task_name": task.name,
        "domain": task.domain,
        "instruction": task.instruction,
        "max_steps": server.options.config.max_steps,
    });
    let observation = server.start(&mut held, task, hello).await?;
    let mut info = info;
    info["screen_width"] = json!(observation["screen_width"]);
    info["screen_height"] = json!(observation["screen_height"]);
    Ok(Json(json!({"session": id, "observation": observation, "info": info})))
}

async fn step(State(server): State<Arc<EnvServer>>, payload: Result<Json<StepRequest>, JsonRejection>) -> Answer {
    let request = body(payload)?;
    let session = server.session(&request.session)?;
    let mut held = session.lock().await;
    let Some(episode) = held.episode.as_mut() else {
        return Err(Refusal(StatusCode::CONFLICT, "the session has no episode: reset it to a task".into()));
    };
    if let Some(result) = &episode.ended {
        return Err(Refusal(
            StatusCode::CONFLICT,
            format!("the episode ended ({}): evaluate it, or reset to a task", result.status.kind()),
        ));
    }
    let list = match request.actions {
        Value::Array(list) => list,
        one => vec![one],
    };
    if list.len() > MAX_ACTIONS {
        return Err(bad(format!("{} actions in one step; the most is {MAX_ACTIONS}", list.len())));
    }
    let coords = coords_of(request.coords.as_deref())?;
    let actions = crate::agent::external::spaces::to_actions(&request.action_space, &list, episode.screen, coords)
        .map_err(bad)?;
    if episode.actions.send((actions, coords)).await.is_err() {
        return Err(Refusal(StatusCode::CONFLICT, "the episode is no longer waiting for a step".into()));
    }
    match episode.turns.recv().await {
        Some(Turn::Observed { observation, step, screen }) => {
            episode.last = observation.clone();
            episode.step = step;
            episode.screen = screen;
            Ok(Json(json!({
                "observation": observation,
                "reward": 0.0,
                "done": false,
                "info": {"step": step, "task_id": episode.task.id},
            })))
        }
        Some(Turn::Ended(result)) => {
            let answer = json!({
                "observation": episode.last,
                "reward": result.score,
                "done": true,
                "info": {
                    "step": episode.step,
                    "task_id": episode.task.id,
                    "score": result.score,
                    "status": result.status.kind(),
                    "error": result.status.message(),
                    "steps": result.steps,
                    "action_errors": result.action_errors,
                },
            });
            episode.ended = Some(result);
            Ok(Json(answer))
        }
        None => Err(Refusal(StatusCode::INTERNAL_SERVER_ERROR, "the episode stopped".into())),
    }
}

async fn evaluate(
    State(server): State<Arc<EnvServer>>,
    payload: Result<Json<SessionRequest>, JsonRejection>,
) -> Answer {
    let request = body(payload)?;
    let session = server.session(&request.session)?;
    let held = session.lock().await;
    match held.episode.as_ref().map(|e| e.ended.as_ref()) {
        Some(Some(result)) => Ok(Json(json!({
            "score": result.score,
            "status": result.status.kind(),
            "error": result.status.message(),
        }))),
        Some(None) => Err(Refusal(
            StatusCode::CONFLICT,
            "the episode is still running: step DONE or FAIL (or use up its steps), then evaluate".into(),
        )),
        None => Err(Refusal(StatusCode::CONFLICT, "the session has no episode: reset it to a task".into())),
    }
}

async fn close(State(server): State<Arc<EnvServer>>, payload: Result<Json<SessionRequest>, JsonRejection>) -> Answer {
    let request = body(payload)?;
    let session = server.session(&request.session)?;
    let held = {
        let mut guard = session.lock().await;
        Session { guest: guard.guest.clone(), episode: guard.episode.take() }
    };
    server.forget(&request.session, held);
    Ok(Json(json!({"closed": true})))
}

/// Serves `server` on `listener` until `stop`.
///
/// # Errors
///
/// The listener fails.
pub async fn serve(
    server: Arc<EnvServer>,
    listener: tokio::net::TcpListener,
    stop: CancellationToken,
) -> std::io::Result<()> {
    axum::serve(listener, server.router()).with_graceful_shutdown(stop.cancelled_owned()).await
}

/// The address a listener took, for the banner.
pub fn describe(addr: SocketAddr, tasks: &[Task], guests: usize) -> String {
    let domains: BTreeMap<&str, usize> = tasks.iter().fold(BTreeMap::new(), |mut m, t| {
        *m.entry(t.domain.as_str()).or_default() += 1;
        m
    });
    format!("environment: http://{addr}/ ({} task(s) in {} domain(s), {guests} guest(s))", tasks.len(), domains.len())
}
