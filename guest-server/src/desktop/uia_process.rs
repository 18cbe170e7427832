//! UI Automation in a worker process of its own, and the protocol between the
//! guest and it.
//!
//! COM's multithreaded apartment is process-wide, and so is UI Automation's
//! client-side state: a client re-created in the same process (a new thread, a
//! new `CUIAutomation`) joins the same apartment and can inherit what broke the
//! old one (empty trees after a snapshot restore). The only fresh start is a new
//! process. So the Windows backend walks its trees in `arena-guest uia-worker`,
//! a child it starts on first use ([`WorkerProcess`]); the `uia` health stage's
//! revival, and a request the worker does not answer in time, end that process,
//! and the next request starts a new one.
//!
//! The protocol is one JSON line per request on the child's standard input
//! ([`WorkerRequest`]) and one per answer on its standard output
//! ([`WorkerAnswer`]); the child ends when its input closes (the guest ended).
//! Platform-neutral, tested natively with a stand-in child.

use std::io::{BufRead, BufReader, Write};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

use arena_shared::observation::{A11yTree, TreeBudget};
use serde::{Deserialize, Serialize};

use super::{DesktopError, DesktopResult};

/// The subcommand the child runs (`arena-guest uia-worker --view raw|control`).
pub const SUBCOMMAND: &str = "uia-worker";

/// One walk asked of the worker.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct WorkerRequest {
    pub budget: TreeBudget,
    pub foreground_only: bool,
}

/// The worker's answer to one request.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WorkerAnswer {
    Tree(A11yTree),
    /// UI Automation does not exist here (Wine).
    Unsupported(String),
    Timeout {
        op: String,
        ms: u64,
    },
    Failed(String),
}

impl WorkerAnswer {
    /// The answer for a walk's result.
    pub fn from_result(result: DesktopResult<A11yTree>) -> WorkerAnswer {
        match result {
            Ok(tree) => WorkerAnswer::Tree(tree),
            Err(DesktopError::Unsupported(why)) => WorkerAnswer::Unsupported(why),
            Err(DesktopError::Timeout { op, ms }) => WorkerAnswer::Timeout { op: op.to_owned(), ms },
            Err(other) => WorkerAnswer::Failed(other.to_string()),
        }
    }

    fn into_result(self) -> DesktopResult<A11yTree> {
        match self {
            WorkerAnswer::Tree(tree) => Ok(tree),
            WorkerAnswer::Unsupported(why) => Err(DesktopError::Unsupported(why)),
            WorkerAnswer::Timeout { ms, .. } => Err(DesktopError::Timeout { op: "uia tree", ms }),
            WorkerAnswer::Failed(message) => Err(DesktopError::Os { op: "uia worker", message }),
        }
    }
}

/// The child's side: answers each request line of `input` on `output` with
/// `walk`, until `input` ends.
///
/// # Errors
///
/// Writing an answer fails (the guest went away).
pub fn serve(
    input: impl BufRead,
    mut output: impl Write,
    mut walk: impl FnMut(WorkerRequest) -> WorkerAnswer,
) -> std::io::Result<()> {
    for line in input.lines() {
        let line = line?;
        if line.trim().is_empty() {
            continue;
        }
        let answer = match serde_json::from_str::<WorkerRequest>(&line) {
            Ok(request) => walk(request),
            Err(err) => WorkerAnswer::Failed(format!("a request the worker cannot read: {err}")),
        };
        let text = serde_json::to_string(&answer).map_err(std::io::Error::other)?;
        writeln!(output, "{text}")?;
        output.flush()?;
    }
    Ok(())
}

/// The running child: its input and the lines it answers.
#[derive(Debug)]
struct Running {
    child: Child,
    input: ChildStdin,
    answers: mpsc::Receiver<String>,
}

/// The guest's side: the worker process, started on first use, ended and
/// started anew by [`WorkerProcess::restart`] or when it does not answer in time.
pub struct WorkerProcess {
    command: Box<dyn Fn() -> Command + Send>,
    running: Option<Running>,
    starts: u32,
}

impl std::fmt::Debug for WorkerProcess {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("WorkerProcess").field("running", &self.running.is_some()).field("starts", &self.starts).finish()
    }
}

impl WorkerProcess {
    /// A worker started by `command` (its standard streams are set here).
    pub fn new(command: impl Fn() -> Command + Send + 'static) -> WorkerProcess {
        WorkerProcess { command: Box::new(command), running: None, starts: 0 }
    }

    /// How many worker processes were started so far.
    pub fn starts(&self) -> u32 {
        self.starts
    }

    /// Ends the worker process (the next request starts a new one).
    pub fn restart(&mut self) {
        if let Some(mut running) = self.running.take() {
            let _ = running.child.kill();
            let _ = running.child.wait();
        }
    }

    fn start(&mut self) -> DesktopResult<&mut Running> {
        if self.running.is_none() {
            let mut command = (self.command)();
            command.stdin(Stdio::piped()).stdout(Stdio::piped()).stderr(Stdio::null());
            let mut child = command.spawn().map_err(|err| DesktopError::Os {
                op: "uia worker",
                message: format!("starting the UI Automation worker process: {err}"),
            })?;
            let (Some(input), Some(output)) = (child.stdin.take(), child.stdout.take()) else {
                let _ = child.kill();
                return Err(DesktopError::Os { op: "uia worker", message: "the worker has no pipes".into() });
            };
            let (tx, answers) = mpsc::channel();
            std::thread::Builder::new()
                .name("uia-worker-reader".into())
                .spawn(move || {
                    // Answers are JSON objects, one a line; anything else the child prints is not one.
                    let answers = BufReader::new(output).lines().map_while(Result::ok).filter(|l| l.starts_with('{'));
                    for line in answers {
                        if tx.send(line).is_err() {
                            break;
                        }
                    }
                })
                .map_err(|err| DesktopError::Os { op: "uia worker", message: format!("starting a reader: {err}") })?;
            self.starts += 1;
            self.running = Some(Running { child, input, answers });
        }
        self.running.as_mut().ok_or_else(|| DesktopError::Os { op: "uia worker", message: "not running".into() })
    }

    /// Asks the worker for one walk and waits at most `wait` for the answer; a
    /// worker that does not answer in time, or has ended, is ended and the call fails.
    ///
    /// # Errors
    ///
    /// What the worker answered, [`DesktopError::Timeout`] when it did not in
    /// time, [`DesktopError::Os`] when it cannot be started or ended without answering.
    pub fn request(&mut self, request: WorkerRequest, wait: Duration) -> DesktopResult<A11yTree> {
        let line = serde_json::to_string(&request)
            .map_err(|err| DesktopError::Os { op: "uia worker", message: err.to_string() })?;
        let running = self.start()?;
        let sent = writeln!(running.input, "{line}").and_then(|()| running.input.flush());
        let answer = match sent {
            Ok(()) => running.answers.recv_timeout(wait),
            Err(_) => Err(mpsc::RecvTimeoutError::Disconnected),
        };
        match answer {
            Ok(text) => serde_json::from_str::<WorkerAnswer>(&text)
                .map_err(|err| DesktopError::Os {
                    op: "uia worker",
                    message: format!("an answer it cannot read: {err}"),
                })?
                .into_result(),
            Err(mpsc::RecvTimeoutError::Timeout) => {
                tracing::warn!(
                    wait_ms = wait.as_millis() as u64,
                    "the UI Automation worker process is stuck; ending it"
                );
                self.restart();
                Err(DesktopError::Timeout { op: "uia tree", ms: u64::try_from(wait.as_millis()).unwrap_or(u64::MAX) })
            }
            Err(mpsc::RecvTimeoutError::Disconnected) => {
                self.restart();
                Err(DesktopError::Os {
                    op: "uia worker",
                    message: "the UI Automation worker process ended without answering".into(),
                })
            }
        }
    }
}

impl Drop for WorkerProcess {
    fn drop(&mut self) {
        self.restart();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use arena_shared::geometry::CoordinateSpace;
    use arena_shared::observation::A11yBackend;

    /// Set when this test binary runs as the stand-in worker: what it does.
    const ROLE: &str = "ARENA_TEST_UIA_WORKER";

    fn tree(nodes: u32) -> A11yTree {
        A11yTree {
            backend: A11yBackend::Uia,
            windows: Vec::new(),
            truncated: false,
            node_count: nodes,
            elapsed_ms: 1,
            coordinate_space: CoordinateSpace::Physical,
            windows_walked: Vec::new(),
        }
    }

    /// The stand-in worker: answers with its own process id as the node count,
    /// or hangs on a request for a depth of 1 (a provider that never answers).
    #[test]
    fn stand_in_worker() {
        if std::env::var_os(ROLE).is_none() {
            return;
        }
        let stdin = std::io::stdin();
        let mut stdout = std::io::stdout();
        // libtest has begun a line ("test NAME ... "): the answers start on their own.
        let _ = writeln!(stdout);
        let _ = serve(stdin.lock(), stdout.lock(), |request| {
            if request.budget.max_depth == 1 {
                std::thread::sleep(Duration::from_secs(600));
            }
            WorkerAnswer::Tree(tree(std::process::id()))
        });
        std::process::exit(0);
    }

    fn worker() -> WorkerProcess {
        WorkerProcess::new(|| {
            let mut command = Command::new(std::env::current_exe().expect("the test binary"));
            command.args([
                "--exact",
                "desktop::uia_process::tests::stand_in_worker",
                "--nocapture",
                "--test-threads=1",
            ]);
            command.env(ROLE, "1");
            command
        })
    }

    const ASK: WorkerRequest = WorkerRequest { budget: TreeBudget::WAA, foreground_only: true };

    #[test]
    fn a_restart_answers_from_a_new_process() {
        let mut w = worker();
        let first = w.request(ASK, Duration::from_secs(60)).unwrap().node_count;
        assert_eq!(w.request(ASK, Duration::from_secs(60)).unwrap().node_count, first, "the same process");
        w.restart();
        let second = w.request(ASK, Duration::from_secs(60)).unwrap().node_count;
        assert_ne!(first, second, "the restart started a new process");
        assert_eq!(w.starts(), 2);
    }

    #[test]
    fn a_worker_that_does_not_answer_is_ended_and_the_next_request_gets_a_new_one() {
        let mut w = worker();
        let first = w.request(ASK, Duration::from_secs(60)).unwrap().node_count;
        let hang = WorkerRequest { budget: TreeBudget { max_depth: 1, ..TreeBudget::WAA }, foreground_only: true };
        let err = w.request(hang, Duration::from_millis(300)).unwrap_err();
        assert!(matches!(err, DesktopError::Timeout { .. }), "{err}");
        let next = w.request(ASK, Duration::from_secs(60)).unwrap().node_count;
        assert_ne!(next, first);
        assert_eq!(w.starts(), 2);
    }

    #[test]
    fn answers_and_errors_travel_both_ways() {
        let mut out = Vec::new();
        let input = format!("{}\nnot json\n", serde_json::to_string(&ASK).unwrap());
        serve(input.as_bytes(), &mut out, |_| WorkerAnswer::from_result(Err(DesktopError::Unsupported("Wine".into()))))
            .unwrap();
        let lines: Vec<WorkerAnswer> =
            String::from_utf8(out).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect();
        assert_eq!(lines[0], WorkerAnswer::Unsupported("Wine".into()));
        assert!(matches!(&lines[1], WorkerAnswer::Failed(m) if m.contains("cannot read")));
        assert!(matches!(lines[0].clone().into_result(), Err(DesktopError::Unsupported(_))));
    }
}
