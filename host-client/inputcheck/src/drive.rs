//! The check against a guest: start the recorder there, focus it, send every case of
//! the catalogue in every chosen action space (through the host's translation and a
//! [`StepRunner`], the host's executor), a separator key after each, read the log back
//! through the file routes, cut it at the separators and compare; then a [`Report`].

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use arena_actionspace::{ActionSpace, Step};
use arena_client::GuestClient;
use arena_shared::action::{Action, ActionBatch};
use arena_shared::exec::LaunchRequest;
use arena_shared::input_log::{parse_log, Recorded};
use arena_shared::observation::WindowTarget;
use serde::Serialize;

use crate::catalogue::{context, translate, Catalogue, Check};
use crate::compare::{compare, compare_text, describe, split, Difference, SEPARATOR_KEY};

/// The recorder's window title (`arena-input-recorder`'s default), by which the check finds it.
pub const RECORDER_TITLE: &str = "Arena input recorder";

/// Carries out a case's steps on the guest as the host's executor does.
#[async_trait::async_trait]
pub trait StepRunner: Send + Sync {
    /// Performs `steps`.
    ///
    /// # Errors
    ///
    /// A message saying what failed (the guest refused an action, or is out of reach).
    async fn run(&self, steps: &[Step]) -> Result<(), String>;
}

/// What to check and where the recorder is.
#[derive(Debug, Clone)]
pub struct CheckOptions {
    /// The recorder's program as the guest starts it (`arena-input-recorder.exe`'s
    /// path in the guest; the stub models a program of that name).
    pub recorder: String,
    /// The guest path of the log the recorder writes.
    pub log: String,
    /// The action spaces to check, in order.
    pub spaces: Vec<ActionSpace>,
    /// Only the cases with these names (all when empty).
    pub only: Vec<String>,
    /// How long to wait for the recorder's window and for its last line.
    pub wait: Duration,
}

/// Why the check could not run at all (a case that fails is in the [`Report`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CheckError(pub String);

impl std::fmt::Display for CheckError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for CheckError {}

/// One case in one space that did not deliver what it should.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Mismatch {
    pub case: String,
    pub space: String,
    pub intent: String,
    /// Where expected and received parted, when the case ran.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub difference: Option<Difference>,
    /// The translation or the guest refusing, when it did not.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    pub expected: Vec<String>,
    pub received: Vec<String>,
}

/// Cases and passes of one space.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub struct Tally {
    pub cases: usize,
    pub passed: usize,
}

/// What the check found: `cases` counts each case once per space it ran in.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize)]
pub struct Report {
    pub cases: usize,
    pub passed: usize,
    pub by_space: BTreeMap<String, Tally>,
    pub mismatches: Vec<Mismatch>,
}

impl Report {
    /// Whether every case passed.
    pub fn all_passed(&self) -> bool {
        self.cases == self.passed
    }

    /// A table per action space (cases, passed), then each mismatch with expected
    /// against received.
    pub fn render_table(&self) -> String {
        let mut out = format!("{:<28} {:>6} {:>7}\n", "action space", "cases", "passed");
        for (space, tally) in &self.by_space {
            out.push_str(&format!("{space:<28} {:>6} {:>7}\n", tally.cases, tally.passed));
        }
        out.push_str(&format!("{:<28} {:>6} {:>7}\n", "all", self.cases, self.passed));
        for m in &self.mismatches {
            out.push_str(&format!("\nMISMATCH {} in {} ({})\n", m.case, m.space, m.intent));
            if let Some(error) = &m.error {
                out.push_str(&format!("  error: {error}\n"));
            }
            if let Some(d) = &m.difference {
                out.push_str(&format!(
                    "  at event {}: expected {:?}, received {:?}\n",
                    d.at,
                    if d.expected.is_empty() { "nothing more" } else { d.expected.as_str() },
                    if d.received.is_empty() { "nothing" } else { d.received.as_str() }
                ));
            }
            out.push_str(&format!("  expected: {}\n  received: {}\n", m.expected.join(" | "), m.received.join(" | ")));
        }
        out
    }
}

fn guest(what: &str) -> impl Fn(arena_client::ClientError) -> CheckError + '_ {
    move |err| CheckError(format!("{what}: {err}"))
}

/// Starts the recorder and waits for its window; answers the window's id.
async fn start_recorder(client: &GuestClient, options: &CheckOptions) -> Result<u64, CheckError> {
    client
        .launch(&LaunchRequest { argv: vec![options.recorder.clone(), options.log.clone()], shell: None })
        .await
        .map_err(guest("starting the recorder"))?;
    let started = Instant::now();
    loop {
        let windows = client.windows().await.map_err(guest("listing windows"))?;
        if let Some(w) = windows.iter().find(|w| w.title == RECORDER_TITLE) {
            return Ok(w.id);
        }
        if started.elapsed() > options.wait {
            return Err(CheckError(format!(
                "the recorder's window ({RECORDER_TITLE:?}) did not open within {} s",
                options.wait.as_secs()
            )));
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

/// The log as far as it is written (a last line cut short is left for later).
async fn read_log(client: &GuestClient, path: &str) -> Result<Vec<Recorded>, CheckError> {
    let file = client.pull_file(path).await.map_err(guest("reading the recorder's log"))?;
    let text = String::from_utf8_lossy(&file.bytes);
    let whole = text.rfind('\n').map_or("", |end| &text[..=end]);
    parse_log(whole).map_err(|err| CheckError(format!("the recorder's log: {err}")))
}

async fn separator(client: &GuestClient, pause_ms: u64) -> Result<(), CheckError> {
    let mut actions = Vec::new();
    if pause_ms > 0 {
        actions.push(Action::Wait { ms: pause_ms });
    }
    actions.push(Action::KeyPress { key: SEPARATOR_KEY.into(), presses: 1 });
    client.act(&ActionBatch { actions }).await.map_err(guest("pressing the separator key")).map(|_| ())
}

fn lines(check: &Check) -> Vec<String> {
    match check {
        Check::Events(events) => events.iter().map(ToString::to_string).collect(),
        Check::Text(text) => vec![format!("text {}", crate::expect::shown_text(text))],
    }
}

/// One run of a case: which, where, and what went wrong before any event.
struct Slot {
    case: usize,
    space: ActionSpace,
    error: Option<String>,
}

/// Runs the check. See the module documentation.
///
/// # Errors
///
/// [`CheckError`] when the check cannot run: the guest out of reach, the recorder not
/// starting, its log unreadable or never complete.
pub async fn run_check(
    client: &GuestClient,
    runner: &dyn StepRunner,
    catalogue: &Catalogue,
    options: &CheckOptions,
) -> Result<Report, CheckError> {
    for name in &options.only {
        if !catalogue.cases.iter().any(|c| &c.name == name) {
            return Err(CheckError(format!("no case is named {name:?}")));
        }
    }
    let screen = client.screen().await.map_err(guest("reading the screen"))?;
    let ctx = context((screen.physical_width, screen.physical_height));
    let window = start_recorder(client, options).await?;
    let started = Instant::now();
    let double_click_ms = loop {
        let log = read_log(client, &options.log).await.unwrap_or_default();
        if let Some(Recorded::Ready { double_click_ms, .. }) = log.first() {
            break u64::from(*double_click_ms);
        }
        if started.elapsed() > options.wait {
            return Err(CheckError("the recorder wrote no `ready` line".into()));
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    };

    // None: the gap between two spaces, where the window is focused again.
    let mut slots: Vec<Option<Slot>> = Vec::new();
    for (n, space) in options.spaces.iter().enumerate() {
        if n > 0 {
            slots.push(None);
        }
        client
            .activate_window(&WindowTarget { id: Some(window), title: None })
            .await
            .map_err(guest("focusing the recorder"))?;
        separator(client, 0).await?;
        for (index, case) in catalogue.cases.iter().enumerate() {
            if !options.only.is_empty() && !options.only.contains(&case.name) {
                continue;
            }
            let Some((_, input)) = case.inputs.iter().find(|(s, _)| s == space) else {
                continue;
            };
            let error = match translate(*space, input, &ctx) {
                Ok(steps) => runner.run(&steps).await.err(),
                Err(err) => Some(err),
            };
            slots.push(Some(Slot { case: index, space: *space, error }));
            // Clicks of the next case must not pair with this one's into a double click.
            separator(client, if case.clicks() { double_click_ms + 100 } else { 0 }).await?;
        }
    }

    let started = Instant::now();
    let cut = loop {
        let cut = split(&read_log(client, &options.log).await?);
        if cut.cases.len() >= slots.len() {
            break cut;
        }
        if started.elapsed() > options.wait {
            return Err(CheckError(format!(
                "the recorder's log shows {} of the {} cases sent (is its window still in front?)",
                cut.cases.len(),
                slots.len()
            )));
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
    };
    let _ = client.close_window(&WindowTarget { id: Some(window), title: None }).await;
    let origin = cut.origin.unwrap_or((0, 0));

    let mut report = Report::default();
    for (slot, received) in slots.iter().zip(&cut.cases) {
        let Some(slot) = slot else {
            continue;
        };
        let case = &catalogue.cases[slot.case];
        let check = case.check_for(slot.space);
        let tally = report.by_space.entry(slot.space.name().to_owned()).or_default();
        tally.cases += 1;
        report.cases += 1;
        let outcome = match (&slot.error, check) {
            (Some(_), _) => Err(None),
            (None, Check::Events(events)) => compare(events, received, origin).map_err(Some),
            (None, Check::Text(text)) => compare_text(text, received).map_err(Some),
        };
        match outcome {
            Ok(()) => {
                tally.passed += 1;
                report.passed += 1;
            }
            Err(difference) => report.mismatches.push(Mismatch {
                case: case.name.clone(),
                space: slot.space.name().to_owned(),
                intent: case.intent.clone(),
                difference,
                error: slot.error.clone(),
                expected: lines(check),
                received: received.iter().map(|r| describe(r, origin)).collect(),
            }),
        }
    }
    Ok(report)
}

/// Where a prepared image has the recorder: the OEM folder `arena prep stage` fills,
/// which Windows keeps at `C:\OEM`.
pub const OEM_RECORDER: &str = r"C:\OEM\arena-input-recorder.exe";
/// The program the stub guest models as the recorder.
pub const STUB_RECORDER: &str = "arena-input-recorder";

/// The recorder to start on a guest whose backend is `backend` (its health says which).
pub fn default_recorder(backend: &str) -> &'static str {
    if backend == "stub" {
        STUB_RECORDER
    } else {
        OEM_RECORDER
    }
}

/// A log path in the guest's temporary folder.
///
/// # Errors
///
/// [`CheckError`] when the guest does not answer or names no temporary folder.
pub async fn default_log(client: &GuestClient) -> Result<String, CheckError> {
    let folders = client.folders().await.map_err(guest("asking for the guest's folders"))?;
    let temp = folders
        .folders
        .iter()
        .find(|(folder, _)| *folder == arena_shared::files::KnownFolder::Temp)
        .map(|(_, path)| path.clone())
        .ok_or_else(|| CheckError("the guest names no temporary folder (give --recorder-log)".into()))?;
    Ok(format!("{}\\arena-input-log.jsonl", temp.trim_end_matches('\\')))
}
