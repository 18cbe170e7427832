//! Agents outside this program, in any language: the step protocol, in which
//! the harness drives and the agent answers (`--agent exec` over a child
//! process's stdin/stdout, `--agent http` as POSTs to an agent served elsewhere).
//!
//! [`ExternalAgent`] implements [`Agent`] over a [`Transport`]. Per episode it
//! sends `reset` (with the first observation, which is when the screen size is
//! known) and then, per step, `observe`; each `act` answer becomes a
//! [`Prediction`]. A malformed answer, a timeout, an `error` message or a dead
//! agent process is an [`AgentError::External`]: the episode records the step and
//! ends as an agent error; the process is replaced before the next episode.
//!
//! It is not the MCP endpoint (the agent drives there: `arena_host::mcp`), nor the
//! action spaces themselves: code runs through the action port
//! (`arena_exec`), and `computer_13` and typed actions go through
//! `arena_actionspace::parse` ([`spaces`]).
//!
//! # Layout
//!
//! - [`protocol`]: the messages and [`protocol::PROTOCOL_VERSION`].
//! - [`transport`]: [`transport::ProcessPool`] (one process per guest worker,
//!   its stderr into the log) and [`transport::HttpAgent`].
//! - [`observe`]: the one adapter from an [`Observation`] to an `observe` message.
//! - [`spaces`]: answers' actions to [`AgentAction`]s, with the `computer_13` seam.
//! - [`stderr`]: an exec agent's stderr into the run's log, bounded per task.
//! - [`sandbox`]: where an exec agent's process runs (bubblewrap on Linux by default).
//!
//! An exec agent's process tree (its group or job object, ended with it) is
//! `arena_vm::child::tree`, with the host side's other system calls.

pub mod observe;
pub mod protocol;
pub mod sandbox;
pub mod spaces;
pub mod stderr;
pub mod transport;

use std::time::Duration;

use serde_json::{json, Value};

use crate::observation::Observation;
use crate::{Agent, AgentError, LogValue, Prediction, StepLog};
use arena_actionspace::Coords;
use arena_exec::AgentAction;
use arena_som::Marks;
use arena_task::Task;

use protocol::{AgentHello, AgentMessage, PROTOCOL_VERSION};

/// One exchange with an outside agent: a message out, one answer back.
#[async_trait::async_trait]
pub trait Transport: Send {
    /// Sends `message` and answers the agent's reply as JSON.
    ///
    /// # Errors
    ///
    /// A message naming what went wrong: no answer in time, a dead process, an
    /// answer that is not one JSON object.
    async fn call(&mut self, message: &Value) -> Result<Value, String>;

    /// What the agent said in its `hello` (the transport shakes hands when it
    /// connects, so a process kept between episodes does so once).
    fn hello(&self) -> &AgentHello;

    /// Whether observations may name files on this machine (`screenshot: path`).
    fn local(&self) -> bool;

    /// A folder for this episode's screenshot files, for `screenshot: path`.
    fn files(&self) -> Option<&std::path::Path> {
        None
    }

    /// Keeps what the agent writes on the side (an exec agent's stderr) in
    /// `dir`, the episode's result folder, from now on.
    fn keep_files_in(&mut self, _dir: &std::path::Path) {}

    /// Marks the connection unusable after a protocol error, so that it is not
    /// reused for another episode.
    fn poison(&mut self) {}

    /// The transport as `Any`, for a connector to take back its own kind.
    fn into_any(self: Box<Self>) -> Box<dyn std::any::Any + Send>;
}

/// The harness's `hello`.
pub fn hello_message() -> Value {
    json!({
        "type": "hello",
        "protocol": PROTOCOL_VERSION,
        "harness": format!("arena {}", env!("CARGO_PKG_VERSION")),
        "action_spaces": protocol::ACTION_SPACES,
    })
}

/// Checks the agent's answer to `hello`.
///
/// # Errors
///
/// A message naming what is wrong (not a `hello`, another protocol version, an unknown action space).
pub fn check_hello(answer: Value) -> Result<AgentHello, String> {
    let hello = match parse_message(answer)? {
        AgentMessage::Hello(hello) => hello,
        AgentMessage::Error { message } => return Err(format!("the agent refused the handshake: {message}")),
        other => return Err(format!("expected a hello answer, got {}", kind(&other))),
    };
    if hello.protocol != PROTOCOL_VERSION {
        return Err(format!(
            "the agent speaks protocol version {}, this harness version {PROTOCOL_VERSION}",
            hello.protocol
        ));
    }
    spaces::check_space(&hello.action_space)?;
    if let Some(coords) = &hello.coords {
        hello_coords(coords)?;
    }
    Ok(hello)
}

/// A coordinate convention named in a `hello`.
fn hello_coords(name: &str) -> Result<Coords, String> {
    if !protocol::COORDS.contains(&name) {
        return Err(format!(
            "unknown coordinate convention {name:?} in hello; this harness accepts {}",
            protocol::COORDS.join(", ")
        ));
    }
    name.parse()
}

/// Reads one agent message, naming what was wrong with it; an `act` with more
/// than [`protocol::MAX_ACTIONS`] actions is refused.
fn parse_message(answer: Value) -> Result<AgentMessage, String> {
    if let Some(actions) = answer.get("actions").and_then(Value::as_array) {
        if actions.len() > protocol::MAX_ACTIONS {
            return Err(too_many_actions(actions.len()));
        }
    }
    <AgentMessage as serde::Deserialize>::deserialize(&answer)
        .map_err(|err| format!("malformed message {}: {err}", short(&answer)))
}

fn too_many_actions(count: usize) -> String {
    format!("the agent answered {count} actions in one act; at most {} are taken", protocol::MAX_ACTIONS)
}

/// Refuses an answer whose `actions` lists hold more than
/// [`protocol::MAX_ACTIONS`] actions together, by counting them in the raw
/// answer, before it becomes a JSON tree (a million small actions would take a
/// tree of most of a GiB). Anything else, malformed JSON included, passes, for
/// [`parse_message`] to name.
pub(crate) fn check_action_count(answer: &[u8]) -> Result<(), String> {
    use serde::de::{Deserializer, IgnoredAny, MapAccess, SeqAccess, Visitor};

    /// How many elements a list has (0 for `null`), none of them kept.
    struct Count(usize);
    impl<'de> serde::Deserialize<'de> for Count {
        fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Count, D::Error> {
            struct Elements;
            impl<'de> Visitor<'de> for Elements {
                type Value = Count;
                fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                    f.write_str("a list")
                }
                fn visit_unit<E>(self) -> Result<Count, E> {
                    Ok(Count(0))
                }
                fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Count, A::Error> {
                    let mut n = 0;
                    while seq.next_element::<IgnoredAny>()?.is_some() {
                        n += 1;
                    }
                    Ok(Count(n))
                }
            }
            deserializer.deserialize_any(Elements)
        }
    }
    /// The actions of every `actions` key of an object (a repeated key counts each time).
    struct Probe(usize);
    impl<'de> serde::Deserialize<'de> for Probe {
        fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Probe, D::Error> {
            struct Fields;
            impl<'de> Visitor<'de> for Fields {
                type Value = Probe;
                fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                    f.write_str("an object")
                }
                fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Probe, A::Error> {
                    let mut n = 0;
                    while let Some(key) = map.next_key::<String>()? {
                        if key == "actions" {
                            n += map.next_value::<Count>()?.0;
                        } else {
                            map.next_value::<IgnoredAny>()?;
                        }
                    }
                    Ok(Probe(n))
                }
            }
            deserializer.deserialize_map(Fields)
        }
    }
    match serde_json::from_slice::<Probe>(answer) {
        Ok(Probe(n)) if n > protocol::MAX_ACTIONS => Err(too_many_actions(n)),
        _ => Ok(()),
    }
}

fn kind(message: &AgentMessage) -> &'static str {
    match message {
        AgentMessage::Hello(_) => "hello",
        AgentMessage::Ready {} => "ready",
        AgentMessage::Act(_) => "act",
        AgentMessage::Error { .. } => "error",
    }
}

/// A message cut to a readable length for an error (written no further than
/// that, however long the message).
pub(crate) fn short(value: &Value) -> String {
    /// A writer that keeps the first bytes and then refuses more.
    struct Head(Vec<u8>);
    impl std::io::Write for Head {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            if self.0.len() >= 1024 {
                return Err(std::io::ErrorKind::WriteZero.into());
            }
            self.0.extend_from_slice(buf);
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }
    let mut head = Head(Vec::new());
    let _ = serde_json::to_writer(&mut head, value);
    let text = String::from_utf8_lossy(&head.0);
    if text.chars().count() > 200 {
        format!("{}...", text.chars().take(200).collect::<String>())
    } else {
        text.into_owned()
    }
}

/// How an [`ExternalAgent`] reaches its agent: a fresh transport per episode
/// (a process taken from the pool, or an HTTP client).
#[async_trait::async_trait]
pub trait Connector: Send + Sync {
    /// A transport that has shaken hands.
    ///
    /// # Errors
    ///
    /// The agent cannot be started or reached, or its handshake is refused.
    async fn connect(&self) -> Result<Box<dyn Transport>, String>;

    /// Takes back a transport at the end of an episode (a process goes back to the pool).
    fn release(&self, _transport: Box<dyn Transport>) {}

    /// The agent's label for errors (`exec: CMD`, `http: URL`).
    fn label(&self) -> String;
}

/// An outside agent driven by the step protocol.
pub struct ExternalAgent {
    name: String,
    connector: std::sync::Arc<dyn Connector>,
    transport: Option<Box<dyn Transport>>,
    /// The task of this episode, sent as `reset` with the first observation.
    task: Option<Task>,
    /// Whether `reset` went out this episode.
    reset_sent: bool,
    /// Longest wait for one answer.
    timeout: Duration,
    /// The run's coordinate convention (`--coords`), unless the agent's `hello` names one.
    coords: Coords,
    /// The episode's result folder, handed to the transport when it connects.
    files_in: Option<std::path::PathBuf>,
}

impl ExternalAgent {
    /// An agent reached through `connector`, waiting at most `timeout` for each answer.
    pub fn new(name: &str, connector: std::sync::Arc<dyn Connector>, timeout: Duration) -> ExternalAgent {
        ExternalAgent {
            name: name.to_owned(),
            connector,
            transport: None,
            task: None,
            reset_sent: false,
            timeout,
            coords: Coords::Pixels,
            files_in: None,
        }
    }

    /// The run's coordinate convention (`--coords`) for this agent's `pyautogui` and
    /// `computer_13` answers; a convention named in its `hello` wins.
    #[must_use]
    pub fn with_coords(mut self, coords: Coords) -> ExternalAgent {
        self.coords = coords;
        self
    }

    fn error(&self, reason: impl Into<String>) -> AgentError {
        AgentError::External { agent: self.connector.label(), reason: reason.into() }
    }

    /// One exchange under the timeout; any failure poisons the transport.
    async fn exchange(&mut self, message: &Value) -> Result<Value, AgentError> {
        let timeout = self.timeout;
        let Some(transport) = self.transport.as_mut() else { return Err(self.error("not connected")) };
        let answer = match tokio::time::timeout(timeout, transport.call(message)).await {
            Ok(Ok(answer)) => Ok(answer),
            Ok(Err(reason)) => Err(reason),
            Err(_) => Err(format!(
                "no answer to {} within {} s",
                message["type"].as_str().unwrap_or("a message"),
                timeout.as_secs_f64()
            )),
        };
        answer.map_err(|reason| {
            if let Some(transport) = self.transport.as_mut() {
                transport.poison();
            }
            self.error(reason)
        })
    }

    async fn ensure_connected(&mut self) -> Result<(), AgentError> {
        if self.transport.is_none() {
            let connect = self.connector.connect();
            let transport = match tokio::time::timeout(self.timeout, connect).await {
                Ok(Ok(transport)) => transport,
                Ok(Err(reason)) => return Err(self.error(reason)),
                Err(_) => return Err(self.error(format!("no handshake within {} s", self.timeout.as_secs_f64()))),
            };
            let mut transport = transport;
            if let Some(dir) = &self.files_in {
                transport.keep_files_in(dir);
            }
            self.transport = Some(transport);
        }
        Ok(())
    }

    async fn send_reset(&mut self, obs: &Observation) -> Result<(), AgentError> {
        let Some(task) = self.task.as_ref() else { return Ok(()) };
        let message = observe::reset_message(task, obs);
        let answer = self.exchange(&message).await?;
        match parse_message(answer).map_err(|reason| self.error(reason))? {
            AgentMessage::Ready {} => Ok(()),
            AgentMessage::Error { message } => Err(self.error(format!("the agent refused the task: {message}"))),
            other => Err(self.error(format!("expected a ready answer to reset, got {}", kind(&other)))),
        }
    }
}

impl std::fmt::Debug for ExternalAgent {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ExternalAgent")
            .field("agent", &self.connector.label())
            .field("connected", &self.transport.is_some())
            .field("timeout", &self.timeout)
            .finish_non_exhaustive()
    }
}

impl Drop for ExternalAgent {
    fn drop(&mut self) {
        if let Some(transport) = self.transport.take() {
            self.connector.release(transport);
        }
    }
}

#[async_trait::async_trait]
impl Agent for ExternalAgent {
    fn name(&self) -> &str {
        &self.name
    }

    fn keep_files_in(&mut self, dir: &std::path::Path) {
        self.files_in = Some(dir.to_owned());
        if let Some(transport) = self.transport.as_mut() {
            transport.keep_files_in(dir);
        }
    }

    async fn reset(&mut self, task: &Task) {
        self.task = Some(task.clone());
        self.reset_sent = false;
    }

    async fn predict(&mut self, obs: &Observation) -> Result<Prediction, AgentError> {
        self.ensure_connected().await?;
        if !self.reset_sent {
            self.send_reset(obs).await?;
            self.reset_sent = true;
        }
        let (message, marks) = {
            let Some(transport) = self.transport.as_ref() else { return Err(self.error("not connected")) };
            observe::observe_message(obs, transport.hello(), transport.local(), transport.files())
                .map_err(|reason| AgentError::External { agent: self.connector.label(), reason })?
        };
        let answer = self.exchange(&message).await?;
        let act = match parse_message(answer).map_err(|reason| self.error(reason))? {
            AgentMessage::Act(act) => act,
            AgentMessage::Error { message } => return Err(self.error(format!("the agent gave up: {message}"))),
            other => return Err(self.error(format!("expected an act answer to observe, got {}", kind(&other)))),
        };
        let hello = self.transport.as_ref().map(|t| t.hello());
        let default_space = hello.map(|h| h.action_space.clone()).unwrap_or_default();
        // The handshake checked the name.
        let coords = hello.and_then(|h| h.coords.as_deref()).and_then(|c| hello_coords(c).ok()).unwrap_or(self.coords);
        // An action outside its space is the agent's mistake, not a broken
        // exchange: the episode ends, and the process serves the next one.
        prediction(act, &default_space, marks, obs.screen_size(), coords).map_err(|reason| self.error(reason))
    }
}

/// An `act` answer as the episode's [`Prediction`]: actions in order, then the
/// decision; each `record` field becomes a field of the step's trajectory line.
/// `coords` is the convention of the answer's `computer_13` actions (translated
/// here) and of its pyautogui code (read in it where code runs, `arena_exec`).
///
/// # Errors
///
/// An unknown action space, or an action that does not belong to its space.
pub fn prediction(
    act: protocol::Act,
    default_space: &str,
    marks: Option<Marks>,
    screen: (u32, u32),
    coords: Coords,
) -> Result<Prediction, String> {
    let space = act.action_space.as_deref().unwrap_or(default_space);
    let mut actions = spaces::to_actions(space, &act.actions, screen, coords)?;
    actions.extend(act.decision.map(AgentAction::from));
    let marks = match act.computer_update {
        Some(update) => Some(Marks { entities: Vec::new(), rects: update.screen_rects(), size: screen }),
        None => marks,
    };
    let mut logs: Vec<StepLog> =
        act.record.into_iter().map(|(key, value)| StepLog { key, value: LogValue::Inline(value) }).collect();
    logs.push(StepLog { key: "action_space".into(), value: LogValue::Inline(Value::String(space.to_owned())) });
    logs.push(StepLog { key: "coords".into(), value: LogValue::Inline(Value::String(coords.name())) });
    Ok(Prediction {
        response: act.response,
        actions,
        marks,
        raw_error: None,
        logs,
        timings: Default::default(),
        coords: Some(coords),
        usage: act.usage.map(|u| arena_results::ledger::Usage {
            input: u.input_tokens,
            output: u.output_tokens,
            cached: u.cached_tokens.min(u.input_tokens),
            model_ms: u.model_ms,
        }),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hello(extra: Value) -> Value {
        let mut hello = json!({"type": "hello", "protocol": 1, "action_space": "pyautogui"});
        if let (Some(hello), Some(extra)) = (hello.as_object_mut(), extra.as_object()) {
            hello.extend(extra.clone());
        }
        hello
    }

    #[test]
    fn a_hello_may_name_a_coordinate_convention_and_an_unknown_one_is_refused() {
        assert_eq!(check_hello(hello(json!({}))).expect("no coords").coords, None);
        let named = check_hello(hello(json!({"coords": "grid1000"}))).expect("grid1000");
        assert_eq!(named.coords.as_deref(), Some("grid1000"));
        let err = check_hello(hello(json!({"coords": "percent"}))).expect_err("an unknown convention");
        assert!(err.contains("\"percent\"") && err.contains("pixels, fraction, grid1000"), "{err}");
        for name in protocol::COORDS {
            assert_eq!(hello_coords(name).expect("each named convention parses").name(), name);
        }
    }

    #[test]
    fn an_act_of_a_million_actions_is_refused_naming_the_count_and_the_schema_says_the_limit() {
        // Counted in the raw answer, never made a tree.
        let action = r#"{"type": "key_press", "key": "a"}"#;
        let many = format!(r#"{{"type": "act", "actions": [{}]}}"#, vec![action; 1_000_000].join(","));
        let err = check_action_count(many.as_bytes()).expect_err("too many actions");
        assert!(err.contains("1000000 actions") && err.contains("at most 256"), "{err}");
        // A repeated key counts each time; the limit itself passes.
        let split = format!(r#"{{"actions": [{0}], "type": "act", "actions": [{0}]}}"#, vec![action; 200].join(","));
        assert!(check_action_count(split.as_bytes()).expect_err("400 actions").contains("400 actions"));
        let most = format!(r#"{{"type": "act", "actions": [{}]}}"#, vec!["\"WAIT\""; protocol::MAX_ACTIONS].join(","));
        check_action_count(most.as_bytes()).expect("the limit passes");
        for other in
            [r#"{"type": "act", "actions": null}"#, r#"{"actions": 3}"#, "[1, 2]", "not JSON", r#"{"type": "act"}"#]
        {
            check_action_count(other.as_bytes()).expect("left for parse_message to name");
        }
        let value: Value = serde_json::from_str(&most).expect("JSON");
        assert!(
            matches!(parse_message(value), Ok(AgentMessage::Act(act)) if act.actions.len() == protocol::MAX_ACTIONS)
        );
        let over = json!({"type": "act", "actions": vec![json!("WAIT"); protocol::MAX_ACTIONS + 1]});
        assert!(parse_message(over).expect_err("257").contains("257 actions"));

        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../schemas/agent-protocol/act.json");
        let schema: Value = serde_json::from_str(&std::fs::read_to_string(path).expect("the schema")).expect("JSON");
        assert_eq!(schema["properties"]["actions"]["maxItems"], json!(protocol::MAX_ACTIONS));
    }

    #[test]
    fn a_long_message_is_shown_short_without_writing_it_whole() {
        let long = json!({"response": "a".repeat(10_000_000)});
        let shown = short(&long);
        assert!(shown.len() < 300 && shown.ends_with("..."), "{shown}");
        assert_eq!(short(&json!({"a": 1})), r#"{"a":1}"#);
    }

    #[test]
    fn the_hello_schema_lists_the_coordinate_conventions_the_harness_accepts() {
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../schemas/agent-protocol/agent-hello.json");
        let schema: Value = serde_json::from_str(&std::fs::read_to_string(path).expect("the schema")).expect("JSON");
        let listed: Vec<&str> = schema["properties"]["coords"]["enum"]
            .as_array()
            .expect("an enum")
            .iter()
            .filter_map(Value::as_str)
            .collect();
        assert_eq!(listed, protocol::COORDS);
    }
}
