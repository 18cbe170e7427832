//! How the harness reaches an outside agent: a child process speaking
//! newline-delimited JSON on its stdin/stdout ([`ProcessPool`], `--agent exec`),
//! or an HTTP server taking each message as a POST ([`HttpAgent`], `--agent http`).
//!
//! A process is kept between episodes: the pool holds the idle ones, so a run
//! with N guest workers has at most N processes, each serving one episode at a
//! time. A process that broke the protocol, timed out or died is killed and
//! never reused; the next episode starts a fresh one (and shakes hands again).
//! Each process's stderr goes into the run's log (`tracing`, target
//! `arena::agent`), bounded per task ([`super::stderr`]). A process runs in a
//! group of its own and ends with everything it started ([`super::tree`]).
//! An answer is at most [`MAX_ANSWER`] bytes over either transport.

use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use serde_json::Value;
use tokio::io::{AsyncBufReadExt, AsyncReadExt, AsyncWriteExt, BufReader};
use tokio::process::{Child, ChildStdin, ChildStdout};

use super::protocol::AgentHello;
use super::stderr::StderrBudget;
use super::{check_hello, hello_message, short, Connector, Transport};

use crate::body::MAX_ANSWER;

/// Agent processes started from one command line, one per episode running at once.
#[derive(Debug)]
pub struct ProcessPool {
    argv: Vec<String>,
    idle: Mutex<Vec<AgentProcess>>,
    /// Screenshot files of `screenshot: path`, one folder per process.
    files: tempfile::TempDir,
    started: std::sync::atomic::AtomicU32,
    /// Where each process runs (`--agent-sandbox`); `None` runs it as the harness does.
    sandbox: Option<Arc<super::sandbox::Sandbox>>,
}

impl ProcessPool {
    /// A pool for `command` (split as a POSIX shell splits words; no shell runs).
    ///
    /// # Errors
    ///
    /// An empty or unbalanced command line, or no temporary folder.
    pub fn new(command: &str) -> Result<ProcessPool, String> {
        let argv =
            arena_shared::cmdline::shlex_split(command).map_err(|err| format!("--agent-cmd {command:?}: {err}"))?;
        if argv.is_empty() {
            return Err("--agent-cmd is empty".to_owned());
        }
        let files = tempfile::Builder::new()
            .prefix("arena-agent-")
            .tempdir()
            .map_err(|err| format!("a folder for the agent's screenshots: {err}"))?;
        Ok(ProcessPool { argv, idle: Mutex::new(Vec::new()), files, started: Default::default(), sandbox: None })
    }

    /// The same pool starting each process in `sandbox`.
    #[must_use]
    pub fn with_sandbox(mut self, sandbox: super::sandbox::Sandbox) -> ProcessPool {
        self.sandbox = Some(Arc::new(sandbox));
        self
    }

    /// How many processes this pool has started (restarts included).
    pub fn started(&self) -> u32 {
        self.started.load(std::sync::atomic::Ordering::Relaxed)
    }

    async fn spawn(&self) -> Result<AgentProcess, String> {
        let n = self.started.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
        let dir = self.files.path().join(format!("process-{n}"));
        std::fs::create_dir_all(&dir).map_err(|err| format!("creating {}: {err}", dir.display()))?;
        let mut command = match &self.sandbox {
            Some(sandbox) => sandbox.command(&self.argv),
            None => {
                let mut command = tokio::process::Command::new(&self.argv[0]);
                command.args(&self.argv[1..]);
                command
            }
        };
        // Never the guest's token, sandboxed or not.
        for name in super::sandbox::NEVER_ENV {
            command.env_remove(name);
        }
        command.stdin(Stdio::piped()).stdout(Stdio::piped()).stderr(Stdio::piped());
        command.kill_on_drop(true);
        arena_vm::child::tree::own_group(&mut command);
        let mut child = command.spawn().map_err(|err| format!("cannot start {:?}: {err}", self.argv[0]))?;
        let pid = arena_vm::child::tree::register(&mut child)?;
        tracing::info!(pid, command = %self.argv.join(" "), "agent process started");
        let budget = StderrBudget::new(pid);
        if let Some(stderr) = child.stderr.take() {
            tokio::spawn(super::stderr::pump(stderr, budget.clone()));
        }
        let (Some(stdin), Some(stdout)) = (child.stdin.take(), child.stdout.take()) else {
            return Err("the agent process has no pipes".to_owned());
        };
        let mut process = AgentProcess {
            child,
            pid,
            stdin,
            stdout: BufReader::new(stdout),
            hello: None,
            dir,
            poisoned: false,
            budget,
        };
        let answer = process.exchange(&hello_message()).await?;
        process.hello = Some(check_hello(answer)?);
        Ok(process)
    }
}

#[async_trait::async_trait]
impl Connector for ProcessPool {
    async fn connect(&self) -> Result<Box<dyn Transport>, String> {
        let kept = self.idle.lock().map(|mut idle| idle.pop()).unwrap_or(None);
        if let Some(mut process) = kept {
            if process.alive() {
                process.clear_files();
                process.budget.end_task();
                return Ok(Box::new(process));
            }
            tracing::warn!(pid = process.child.id(), "the agent process died between episodes; starting another");
        }
        Ok(Box::new(self.spawn().await?))
    }

    fn release(&self, transport: Box<dyn Transport>) {
        // Only processes come from this pool; anything else is dropped.
        let Ok(process) = transport.into_any().downcast::<AgentProcess>() else { return };
        if process.poisoned {
            return;
        }
        if let Ok(mut idle) = self.idle.lock() {
            idle.push(*process);
        }
    }

    fn label(&self) -> String {
        format!("exec {}", self.argv.join(" "))
    }
}

/// One running agent process.
#[derive(Debug)]
pub struct AgentProcess {
    child: Child,
    /// The process's id, which leads its process group.
    pid: u32,
    stdin: ChildStdin,
    stdout: BufReader<ChildStdout>,
    hello: Option<AgentHello>,
    dir: PathBuf,
    poisoned: bool,
    /// Its stderr's share of the run's log.
    budget: Arc<StderrBudget>,
}

impl Drop for AgentProcess {
    /// The process and everything it started end with it: when it broke the
    /// protocol and is replaced, when its episode worker stops, when the run ends.
    fn drop(&mut self) {
        arena_vm::child::tree::end(self.pid);
        self.budget.end_task();
    }
}

impl AgentProcess {
    fn alive(&mut self) -> bool {
        !self.poisoned && matches!(self.child.try_wait(), Ok(None))
    }

    fn clear_files(&self) {
        if let Ok(entries) = std::fs::read_dir(&self.dir) {
            for entry in entries.flatten() {
                let _ = std::fs::remove_file(entry.path());
            }
        }
    }

    async fn exchange(&mut self, message: &Value) -> Result<Value, String> {
        let mut line = message.to_string();
        line.push('\n');
        if let Err(err) = self.stdin.write_all(line.as_bytes()).await {
            return Err(self.gone(&format!("writing to the agent failed ({err})")).await);
        }
        let _ = self.stdin.flush().await;
        let mut answer = Vec::new();
        let read = (&mut self.stdout).take(MAX_ANSWER as u64 + 1).read_until(b'\n', &mut answer).await;
        match read {
            Ok(0) => return Err(self.gone("the agent closed its output").await),
            Ok(_) if answer.len() > MAX_ANSWER => {
                return Err(crate::body::BodyError::TooLong { whose: "the agent's", limit: MAX_ANSWER }.to_string());
            }
            Ok(_) => {}
            Err(err) => return Err(format!("reading the agent's answer: {err}")),
        }
        let text = String::from_utf8_lossy(&answer);
        let text = text.trim();
        super::check_action_count(text.as_bytes())?;
        match serde_json::from_str::<Value>(text) {
            Ok(value @ Value::Object(_)) => Ok(value),
            Ok(other) => Err(format!("the agent answered {}, not a JSON object", short(&other))),
            Err(err) => {
                let shown: String = text.chars().take(200).collect();
                Err(format!("the agent answered a line that is not JSON ({err}): {shown:?}"))
            }
        }
    }

    /// Why the process stopped answering, with its exit status when it has one.
    async fn gone(&mut self, what: &str) -> String {
        self.poisoned = true;
        match tokio::time::timeout(Duration::from_secs(1), self.child.wait()).await {
            Ok(Ok(status)) => format!("{what}: the agent process exited ({status})"),
            _ => format!("{what}: the agent process is still running"),
        }
    }
}

#[async_trait::async_trait]
impl Transport for AgentProcess {
    async fn call(&mut self, message: &Value) -> Result<Value, String> {
        if self.poisoned {
            return Err("the agent process broke the protocol earlier".to_owned());
        }
        // Until an answer arrives the process is in an unknown state: a timeout
        // that drops this future leaves it poisoned.
        self.poisoned = true;
        let answer = self.exchange(message).await;
        self.poisoned = answer.is_err();
        answer
    }

    fn hello(&self) -> &AgentHello {
        self.hello.as_ref().unwrap_or(&PLACEHOLDER_HELLO)
    }

    fn local(&self) -> bool {
        true
    }

    fn files(&self) -> Option<&Path> {
        Some(&self.dir)
    }

    fn keep_files_in(&mut self, dir: &Path) {
        self.budget.keep_in(dir);
    }

    fn poison(&mut self) {
        self.poisoned = true;
        arena_vm::child::tree::end(self.pid);
        let _ = self.child.start_kill();
    }

    fn into_any(self: Box<Self>) -> Box<dyn std::any::Any + Send> {
        self
    }
}

/// What a transport answers before its handshake (never seen by callers: a
/// transport is handed out only after `hello`).
static PLACEHOLDER_HELLO: AgentHello = AgentHello {
    protocol: super::protocol::PROTOCOL_VERSION,
    agent: None,
    action_space: String::new(),
    coords: None,
    observation: super::protocol::ObservationWants {
        screenshot: None,
        a11y: super::protocol::TreeMode::None,
        windows: false,
        clipboard: false,
        som: false,
    },
};

/// An agent served over HTTP: each message is POSTed as JSON to one URL and
/// the answer is the response body.
#[derive(Debug, Clone)]
pub struct HttpAgent {
    url: String,
    client: reqwest::Client,
}

impl HttpAgent {
    /// An agent at `url`, each call bounded by `timeout`.
    ///
    /// # Errors
    ///
    /// A URL that is not http(s), or a client that cannot be built.
    pub fn new(url: &str, timeout: Duration) -> Result<HttpAgent, String> {
        let parsed = reqwest::Url::parse(url).map_err(|err| format!("--agent-url {url:?}: {err}"))?;
        if !matches!(parsed.scheme(), "http" | "https") {
            return Err(format!("--agent-url {url:?}: expected an http or https URL"));
        }
        let client =
            reqwest::Client::builder().timeout(timeout).build().map_err(|err| format!("an HTTP client: {err}"))?;
        Ok(HttpAgent { url: url.to_owned(), client })
    }

    async fn post(&self, message: &Value) -> Result<Value, String> {
        let response = self
            .client
            .post(&self.url)
            .json(message)
            .send()
            .await
            .map_err(|err| format!("POST {}: {err}", self.url))?;
        let status = response.status();
        // Only the start of an error body is shown.
        let (limit, cut) = if status.is_success() { (MAX_ANSWER, false) } else { (4096, true) };
        let body = crate::body::read_bounded(response, "the agent's", limit, cut)
            .await
            .map_err(|err| format!("POST {}: {err}", self.url))?;
        if !status.is_success() {
            let shown: String = String::from_utf8_lossy(&body).chars().take(200).collect();
            return Err(format!("POST {}: HTTP {status}: {shown}", self.url));
        }
        super::check_action_count(&body)?;
        match serde_json::from_slice::<Value>(&body) {
            Ok(value @ Value::Object(_)) => Ok(value),
            Ok(other) => Err(format!("the agent answered {}, not a JSON object", short(&other))),
            Err(err) => {
                let shown: String = String::from_utf8_lossy(&body).chars().take(200).collect();
                Err(format!("the agent answered a body that is not JSON ({err}): {shown:?}"))
            }
        }
    }
}

/// An [`HttpAgent`] after its handshake.
#[derive(Debug)]
struct HttpTransport {
    agent: HttpAgent,
    hello: AgentHello,
    /// Sent in every message, so that one agent server can hold one agent per harness connection.
    session: String,
}

/// Adds the `session` field to a message.
fn with_session(message: &Value, session: &str) -> Value {
    let mut message = message.clone();
    if let Value::Object(map) = &mut message {
        map.insert("session".into(), Value::String(session.to_owned()));
    }
    message
}

#[async_trait::async_trait]
impl Transport for HttpTransport {
    async fn call(&mut self, message: &Value) -> Result<Value, String> {
        self.agent.post(&with_session(message, &self.session)).await
    }

    fn hello(&self) -> &AgentHello {
        &self.hello
    }

    fn local(&self) -> bool {
        false
    }

    fn into_any(self: Box<Self>) -> Box<dyn std::any::Any + Send> {
        self
    }
}

#[async_trait::async_trait]
impl Connector for HttpAgent {
    async fn connect(&self) -> Result<Box<dyn Transport>, String> {
        static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
        let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let session = format!("{}-{n}-{:016x}", std::process::id(), rand::random::<u64>());
        let answer = self.post(&with_session(&hello_message(), &session)).await?;
        Ok(Box::new(HttpTransport { agent: self.clone(), hello: check_hello(answer)?, session }))
    }

    fn label(&self) -> String {
        format!("http {}", self.url)
    }
}

/// Either connector, shared by every episode of a run.
pub type SharedConnector = Arc<dyn Connector>;
