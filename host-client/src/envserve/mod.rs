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
//! `observe` message ([`arena_agents::external::observe`]); the actions are its
//! `act` actions ([`arena_agents::external::spaces`]).
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
//! Each episode's result folder is `<out>/<session>/env/env/env/<n>/<domain>/<task>`
//! (`n` counting the session's episodes from 1), so sessions never share one.
//!
//! Bounded: a body of at most [`MAX_REQUEST`] (1 MiB, refused before it is parsed), at most
//! `MAX_ACTIONS` actions a step, one session per guest, and a session whose client
//! sends nothing for `idle` ends as an agent error and frees its guest.
//!
//! Guarded ([`guard`]): with a token ([`EnvOptions::token`]) every request needs it as
//! a bearer token; without one the server listens on loopback only (the command refuses
//! any other address) and takes only loopback `Host` names, so a web page that rebinds
//! its name to 127.0.0.1 cannot drive the guests; and a request with an `Origin` (a
//! browser's) is refused either way.

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

use crate::episode::EpisodeConfig;
use arena_actionspace::Coords;
use arena_agents::external::protocol::{AgentHello, ObservationWants, ACTION_SPACES, MAX_ACTIONS};
use arena_agents::observation::Observation;
use arena_agents::{Agent, AgentError, Prediction};
use arena_client::client::GuestClient;
use arena_exec::AgentAction;
use arena_results::{EpisodeResult, RunLayout};
use arena_task::Task;

/// How the server behaves.
#[derive(Debug, Clone)]
pub struct EnvOptions {
    /// Where each episode's result folder goes (`<out>/<session>/env/env/env/<n>/<domain>/<task>`).
    pub out: PathBuf,
    /// The episodes' configuration (step cap, pauses, downloads).
    pub config: EpisodeConfig,
    /// A session whose client sends nothing for this long ends and frees its guest.
    pub idle: Duration,
    /// The guests' screen in pixels (the first guest's), for clients that size
    /// their observation space before the first reset.
    pub screen: Option<(u32, u32)>,
    /// The bearer token every request must carry; `None` serves loopback clients only.
    pub token: Option<String>,
    /// `--allow-downloads`: a task object may fetch URLs from this machine (`download` steps).
    pub allow_downloads: bool,
}

/// The largest request body: a reset's task object or a step's actions are far
/// smaller; past it the request is refused (413) before any of it is parsed.
pub const MAX_REQUEST: usize = 1024 * 1024;

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
            arena_agents::external::observe::observe_message(obs, &self.hello, false, None).map_err(agent_error)?;
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
    id: String,
    guest: GuestClient,
    /// Episodes begun, for their folders' names.
    episodes: u32,
    /// When its client last asked something.
    touched: std::time::Instant,
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

impl Episode {
    /// Takes in what the episode handed over: its latest observation, or its end.
    fn record(&mut self, turn: Turn) {
        match turn {
            Turn::Observed { observation, step, screen } => {
                self.last = observation;
                self.step = step;
                self.screen = screen;
            }
            Turn::Ended(result) => self.ended = Some(result),
        }
    }
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
            .layer(axum::extract::DefaultBodyLimit::max(MAX_REQUEST))
            .layer(axum::middleware::from_fn_with_state(Arc::clone(self), guard))
            .with_state(Arc::clone(self))
    }

    fn session(&self, id: &str) -> Result<Arc<Mutex<Session>>, Refusal> {
        let sessions =
            self.sessions.lock().map_err(|_| Refusal(StatusCode::INTERNAL_SERVER_ERROR, "poisoned".into()))?;
        sessions.get(id).cloned().ok_or_else(|| {
            Refusal(StatusCode::NOT_FOUND, format!("no session {id:?}: reset without a session to open one"))
        })
    }

    /// The task `spec` names: a served task's id or name, or a task given whole;
    /// refused when its evaluator's `host_file` gold cannot be read, since the
    /// episode could not be scored (a task object has no folder to read it from).
    fn task(&self, spec: &Value) -> Result<Task, Refusal> {
        let task = self.named_task(spec)?;
        if spec.is_object() {
            self.object_may_run(&task)?;
        }
        let task_dir = if spec.is_string() { task.path.parent() } else { None };
        let unresolved = arena_eval::unresolved_host_files(&task.evaluator, task_dir);
        if unresolved.is_empty() {
            return Ok(task);
        }
        Err(bad(format!(
            "task {:?}: its evaluator's host_file gold cannot be read, so it could not be scored: {}{}",
            task.name,
            unresolved.join("; "),
            if task_dir.is_none() {
                " (a task object has no folder; serve the task from a file with --tasks)"
            } else {
                ""
            }
        )))
    }

    /// What a task sent whole may not do: read files of this machine (`upload_file`,
    /// which it has no folder for) or fetch URLs from it (`download`) unless the
    /// server allows downloads.
    fn object_may_run(&self, task: &Task) -> Result<(), Refusal> {
        for step in task.config.iter().chain(&task.evaluator.postconfig) {
            match step {
                arena_task::SetupStep::UploadFile { files } => {
                    let paths: Vec<String> = files.iter().map(|(local, _)| local.display().to_string()).collect();
                    return Err(bad(format!(
                        "task {:?}: its upload_file step would read files of the server's machine ({}); a task \
                         object may not (serve the task from a file with --tasks)",
                        task.name,
                        paths.join(", ")
                    )));
                }
                arena_task::SetupStep::Download { files } if !self.options.allow_downloads => {
                    let urls: Vec<&str> = files.iter().map(|f| f.url.as_str()).collect();
                    return Err(bad(format!(
                        "task {:?}: its download step would fetch {} from the server's machine; start the server \
                         with --allow-downloads to let task objects do that",
                        task.name,
                        urls.join(", ")
                    )));
                }
                _ => {}
            }
        }
        Ok(())
    }

    fn named_task(&self, spec: &Value) -> Result<Task, Refusal> {
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
                // The harness's own keys (a trial number that picks the result folder).
                if let Some(key) = fields.keys().find(|k| k.starts_with("_arena")) {
                    return Err(bad(format!("task: {key:?} is the harness's own key; a task object may not set it")));
                }
                let domain = fields.get("domain").and_then(Value::as_str).unwrap_or("custom");
                let id = fields.get("id").and_then(Value::as_str).unwrap_or("task");
                let path = PathBuf::from("env-tasks")
                    .join(arena_results::safe_component(domain))
                    .join(format!("{}.json", arena_results::safe_component(id)));
                Task::parse(&spec.to_string(), &path).map_err(|err| bad(format!("task: {err}")))
            }
            other => Err(bad(format!(
                "task: a task id or name, or a task object; got {}",
                arena_shared::error::json_kind(other)
            ))),
        }
    }

    /// Starts `task` on `session`'s guest and waits for its first observation.
    async fn start(&self, session: &mut Session, task: Task, hello: AgentHello) -> Result<Value, Refusal> {
        session.episode = None;
        let (turns_tx, mut turns) = mpsc::channel(1);
        let (actions, actions_rx) = mpsc::channel(1);
        let agent = EnvAgent { turns: turns_tx.clone(), actions: actions_rx, hello, idle: self.options.idle };
        // A folder per session and episode: two sessions on one task never share one.
        session.episodes += 1;
        let layout = RunLayout {
            root: self.options.out.join(&session.id),
            agent: "env".into(),
            observation: "env".into(),
            model: "env".into(),
            trial: session.episodes.to_string(),
        };
        let (guest, config, played) = (session.guest.clone(), self.options.config.clone(), task.clone());
        let worker = tokio::spawn(async move {
            let mut agent = agent;
            let out = layout.task_dir(&played);
            let result = crate::episode::run_attempt(&guest, &played, &mut agent, &config, &out, 1, None).await;
            let _ = turns_tx.send(Turn::Ended(Box::new(result))).await;
        });
        let first = turns.recv().await;
        let mut episode =
            Episode { task, actions, turns, last: Value::Null, step: 0, screen: (0, 0), ended: None, worker };
        match first {
            Some(turn @ Turn::Observed { .. }) => {
                episode.record(turn);
                let observation = episode.last.clone();
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
            let session = Arc::new(Mutex::new(Session {
                id: id.clone(),
                guest,
                episodes: 0,
                episode: None,
                touched: std::time::Instant::now(),
            }));
            if let Ok(mut sessions) = server.sessions.lock() {
                sessions.insert(id.clone(), Arc::clone(&session));
            }
            (id, session)
        }
    };
    let mut held = session.lock().await;
    held.touched = std::time::Instant::now();
    let info = json!({
        "task_id": task.id,
        "task_name": task.name,
        "domain": task.domain,
        "instruction": task.instruction,
        "max_steps": server.options.config.max_steps,
    });
    let observation = match server.start(&mut held, task, hello).await {
        Ok(observation) => observation,
        Err(refusal) => {
            // A session this reset opened gives its guest back at once.
            if request.session.is_none() {
                let detached = held.detach();
                drop(held);
                server.forget(&id, detached);
            }
            return Err(refusal);
        }
    };
    let mut info = info;
    info["screen_width"] = json!(observation["screen_width"]);
    info["screen_height"] = json!(observation["screen_height"]);
    Ok(Json(json!({"session": id, "observation": observation, "info": info})))
}

async fn step(State(server): State<Arc<EnvServer>>, payload: Result<Json<StepRequest>, JsonRejection>) -> Answer {
    let request = body(payload)?;
    let session = server.session(&request.session)?;
    let mut held = session.lock().await;
    held.touched = std::time::Instant::now();
    let Some(episode) = held.episode.as_mut() else {
        return Err(Refusal(StatusCode::CONFLICT, "the session has no episode: reset it to a task".into()));
    };
    // A step whose client hung up before its answer left that answer here: take it in,
    // so this step's answer is this step's.
    while let Ok(turn) = episode.turns.try_recv() {
        episode.record(turn);
    }
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
    let actions = arena_agents::external::spaces::to_actions(&request.action_space, &list, episode.screen, coords)
        .map_err(bad)?;
    if episode.actions.send((actions, coords)).await.is_err() {
        return Err(Refusal(StatusCode::CONFLICT, "the episode is no longer waiting for a step".into()));
    }
    let Some(turn) = episode.turns.recv().await else {
        return Err(Refusal(StatusCode::INTERNAL_SERVER_ERROR, "the episode stopped".into()));
    };
    episode.record(turn);
    let answer = match &episode.ended {
        None => json!({
            "observation": episode.last,
            "reward": 0.0,
            "done": false,
            "info": {"step": episode.step, "task_id": episode.task.id},
        }),
        Some(result) => json!({
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
        }),
    };
    Ok(Json(answer))
}

async fn evaluate(
    State(server): State<Arc<EnvServer>>,
    payload: Result<Json<SessionRequest>, JsonRejection>,
) -> Answer {
    let request = body(payload)?;
    let session = server.session(&request.session)?;
    let mut held = session.lock().await;
    held.touched = std::time::Instant::now();
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
        guard.detach()
    };
    server.forget(&request.session, held);
    Ok(Json(json!({"closed": true})))
}

impl Session {
    /// This session's guest and episode, taken out (the episode, dropped, stops).
    fn detach(&mut self) -> Session {
        Session {
            id: self.id.clone(),
            guest: self.guest.clone(),
            episodes: self.episodes,
            episode: self.episode.take(),
            touched: self.touched,
        }
    }
}

impl EnvServer {
    /// Closes the sessions whose client asked nothing for `idle` (a client that went
    /// away without `close`), freeing their guests; answers how many.
    pub async fn sweep(&self) -> usize {
        let sessions: Vec<(String, Arc<Mutex<Session>>)> = match self.sessions.lock() {
            Ok(sessions) => sessions.iter().map(|(id, s)| (id.clone(), Arc::clone(s))).collect(),
            Err(_) => return 0,
        };
        let mut closed = 0;
        for (id, session) in sessions {
            // A session busy with a request is in use.
            let Ok(mut guard) = session.try_lock() else { continue };
            if guard.touched.elapsed() < self.options.idle {
                continue;
            }
            tracing::info!(session = %id, idle_secs = self.options.idle.as_secs(), "closing an idle environment session");
            let held = guard.detach();
            drop(guard);
            self.forget(&id, held);
            closed += 1;
        }
        closed
    }
}

/// Refuses what must not reach the routes (see the module's notes): a browser's
/// request (`Origin`), a request without the token when there is one, and a `Host`
/// that is not loopback when there is none.
async fn guard(
    State(server): State<Arc<EnvServer>>,
    request: axum::extract::Request,
    next: axum::middleware::Next,
) -> Response {
    let headers = request.headers();
    if headers.contains_key(axum::http::header::ORIGIN) {
        return Refusal(StatusCode::FORBIDDEN, "requests from web pages (with an Origin header) are refused".into())
            .into_response();
    }
    match &server.options.token {
        Some(token) => {
            let given = headers.get(axum::http::header::AUTHORIZATION).map(|v| v.as_bytes());
            if !arena_shared::token::bearer_matches(given, token) {
                let mut refused =
                    Refusal(StatusCode::UNAUTHORIZED, "a bearer token is required (the server's --env-token)".into())
                        .into_response();
                refused
                    .headers_mut()
                    .insert(axum::http::header::WWW_AUTHENTICATE, axum::http::HeaderValue::from_static("Bearer"));
                return refused;
            }
        }
        None => {
            let host = headers.get(axum::http::header::HOST).and_then(|v| v.to_str().ok()).unwrap_or_default();
            if !arena_shared::host_header::is_loopback(host) {
                return Refusal(
                    StatusCode::FORBIDDEN,
                    format!(
                        "Host {host:?} is not a loopback name; without --env-token only loopback clients are served"
                    ),
                )
                .into_response();
            }
        }
    }
    next.run(request).await
}

/// Serves `server` on `listener` until `stop`, closing idle sessions as it goes.
///
/// # Errors
///
/// The listener fails.
pub async fn serve(
    server: Arc<EnvServer>,
    listener: tokio::net::TcpListener,
    stop: CancellationToken,
) -> std::io::Result<()> {
    let sweeper = {
        let (server, stop) = (Arc::clone(&server), stop.clone());
        let period = (server.options.idle / 4).clamp(Duration::from_millis(100), Duration::from_secs(30));
        tokio::spawn(async move {
            while tokio::time::timeout(period, stop.cancelled()).await.is_err() {
                server.sweep().await;
            }
        })
    };
    let served = axum::serve(listener, server.router()).with_graceful_shutdown(stop.cancelled_owned()).await;
    sweeper.abort();
    served
}

/// The address a listener took, for the banner.
pub fn describe(addr: SocketAddr, tasks: &[Task], guests: usize) -> String {
    let domains: BTreeMap<&str, usize> = tasks.iter().fold(BTreeMap::new(), |mut m, t| {
        *m.entry(t.domain.as_str()).or_default() += 1;
        m
    });
    format!("environment: http://{addr}/ ({} task(s) in {} domain(s), {guests} guest(s))", tasks.len(), domains.len())
}

#[cfg(test)]
mod tests {
    use super::*;
    use arena_client::client::ClientConfig;

    /// A server over two guests nothing listens on, with `idle` as its limit.
    fn server(idle: Duration, dir: &std::path::Path) -> Arc<EnvServer> {
        let guests = ["http://127.0.0.1:9/", "http://127.0.0.1:10/"]
            .iter()
            .map(|url| {
                GuestClient::new(url, ClientConfig { token: None, timeout: Duration::from_secs(1), retries: 0 })
                    .expect("a client")
            })
            .collect();
        let cache = arena_client::cache::DownloadCache::new(dir.join("cache")).expect("a cache");
        let options = EnvOptions {
            out: dir.to_owned(),
            config: EpisodeConfig::instant(cache),
            idle,
            screen: None,
            token: None,
            allow_downloads: false,
        };
        EnvServer::new(Vec::new(), guests, options)
    }

    /// Opens a session as a reset does, without an episode.
    fn open(server: &EnvServer, id: &str) {
        let guest = server.free.lock().expect("free").pop().expect("a free guest");
        let session = Session { id: id.into(), guest, episodes: 0, episode: None, touched: std::time::Instant::now() };
        server.sessions.lock().expect("sessions").insert(id.into(), Arc::new(Mutex::new(session)));
    }

    #[tokio::test]
    async fn idle_sessions_are_closed_and_their_guests_freed() {
        let dir = tempfile::tempdir().expect("tmp");
        let patient = server(Duration::from_secs(600), dir.path());
        open(&patient, "a");
        assert_eq!(patient.sweep().await, 0, "a session used just now stays");
        let strict = server(Duration::ZERO, dir.path());
        open(&strict, "a");
        open(&strict, "b");
        assert_eq!(strict.free.lock().expect("free").len(), 0);
        // A session busy with a request is left alone.
        let busy = strict.session("b").expect("b");
        let held = busy.lock().await;
        assert_eq!(strict.sweep().await, 1);
        drop(held);
        assert_eq!(strict.sweep().await, 1);
        assert_eq!(strict.free.lock().expect("free").len(), 2, "both guests back");
        assert_eq!(strict.session("a").expect_err("gone").0, StatusCode::NOT_FOUND);
    }

    #[test]
    fn a_task_object_may_not_set_harness_keys_read_host_files_or_download_unless_allowed() {
        let dir = tempfile::tempdir().expect("tmp");
        let evaluator = json!({"func": "exact_match", "result": {"type": "vm_file", "path": "C:\\a.txt", "dest": "a.txt"},
            "expected": {"type": "rule", "rules": {"expected": "x"}}});
        let task = |config: Value, extra: Option<(&str, Value)>| {
            let mut task = json!({"id": "t", "instruction": "i", "config": config, "evaluator": evaluator});
            if let Some((key, value)) = extra {
                task[key] = value;
            }
            task
        };
        let env = server(Duration::from_secs(600), dir.path());
        assert_eq!(env.task(&task(json!([]), None)).expect("a plain task object").name, "t");
        let refused = env.task(&task(json!([]), Some(("_arena_trial", json!(3))))).expect_err("refused");
        assert!(refused.1.contains("\"_arena_trial\" is the harness's own key"), "{}", refused.1);
        let upload = json!([{"type": "upload_file", "parameters": {"files": [{"local_path": "/etc/passwd", "path": "C:\\p.txt"}]}}]);
        let refused = env.task(&task(upload, None)).expect_err("refused");
        assert!(refused.1.contains("upload_file") && refused.1.contains("/etc/passwd"), "{}", refused.1);
        let download =
            json!([{"type": "download", "parameters": {"files": [{"url": "http://10.0.0.1/x", "path": "C:\\x"}]}}]);
        let refused = env.task(&task(download.clone(), None)).expect_err("refused");
        assert!(refused.1.contains("--allow-downloads") && refused.1.contains("http://10.0.0.1/x"), "{}", refused.1);
        let mut allowing = server(Duration::from_secs(600), dir.path());
        Arc::get_mut(&mut allowing).expect("one owner").options.allow_downloads = true;
        assert_eq!(allowing.task(&task(download, None)).expect("allowed").name, "t");
    }

    #[tokio::test]
    async fn a_reset_that_fails_gives_its_guest_back() {
        let dir = tempfile::tempdir().expect("tmp");
        let env = server(Duration::from_secs(600), dir.path());
        let evaluator = json!({"func": "exact_match", "result": {"type": "vm_file", "path": "C:\\a.txt", "dest": "a.txt"},
            "expected": {"type": "rule", "rules": {"expected": "x"}}});
        let request = ResetRequest {
            task: json!({"id": "t", "instruction": "i", "evaluator": evaluator}),
            session: None,
            observation: None,
            coords: None,
        };
        // Nothing listens at the guests' addresses: the episode cannot start.
        let refused = reset(State(Arc::clone(&env)), Ok(Json(request))).await.expect_err("refused");
        assert_eq!(refused.0, StatusCode::BAD_GATEWAY, "{}", refused.1);
        assert_eq!(env.free.lock().expect("free").len(), 2, "the guest is free again");
        assert!(env.sessions.lock().expect("sessions").is_empty(), "no session is left open");
    }

    #[test]
    fn a_task_whose_host_file_gold_cannot_be_read_is_refused_naming_it() {
        let dir = tempfile::tempdir().expect("tmp");
        let evaluator = json!({"func": "compare_text_file",
            "result": {"type": "vm_file", "path": "C:\\a.txt", "dest": "a.txt"},
            "expected": {"type": "host_file", "path": "gold/a.txt", "dest": "gold.txt"}});
        let text = json!({"id": "gold-task", "instruction": "i", "evaluator": evaluator}).to_string();
        let folder = dir.path().join("tasks").join("notepad");
        std::fs::create_dir_all(&folder).expect("folder");
        let served = Task::parse(&text, &folder.join("gold-task.json")).expect("a task");
        let mut env = server(Duration::from_secs(600), dir.path());
        Arc::get_mut(&mut env).expect("one owner").tasks = vec![served];
        // Served from a file whose folder lacks the gold.
        let refused = env.task(&json!("gold-task")).expect_err("refused");
        assert_eq!(refused.0, StatusCode::BAD_REQUEST);
        assert!(refused.1.contains("gold-task") && refused.1.contains("gold/a.txt"), "{}", refused.1);
        assert!(refused.1.contains("compare_text_file (expected)"), "{}", refused.1);
        // With the gold beside it, the same task is served.
        std::fs::create_dir_all(folder.join("gold")).expect("gold folder");
        std::fs::write(folder.join("gold").join("a.txt"), "x").expect("gold");
        assert_eq!(env.task(&json!("gold-task")).expect("served").name, "gold-task");
        // Sent whole, the task has no folder: refused, saying so.
        let object: Value = serde_json::from_str(&text).expect("json");
        let refused = env.task(&object).expect_err("refused");
        assert!(refused.1.contains("a task object has no folder"), "{}", refused.1);
        assert!(refused.1.contains("task file's folder is not known"), "{}", refused.1);
    }
}
