//! The doctor: every capability checked end to end on the desktop the server
//! drives, each with its timing and what it saw (see [`arena_shared::doctor`]).
//!
//! It runs against any [`Desktop`], so the same checks run on the stub (where
//! they must all pass: the tests hold them to it), under Wine, and on a real
//! Windows 11 image. A capability the platform has not got (UI Automation
//! under Wine answers [`DesktopError::Unsupported`]) is reported unavailable,
//! not failed. The checks run one after another because several of them use
//! the one keyboard, cursor and clipboard; each leaves things as it found them
//! where it can (the clipboard is restored, Notepad is closed, the cursor goes back
//! where it was).
//!
//! Entry points: [`run`] (the `arena-guest doctor` subcommand and
//! `GET /v1/doctor` both call it; the route through a deadline).

use std::time::{Duration, Instant};

use arena_shared::action::Action;
use arena_shared::doctor::{CheckStatus, DeepReport, DoctorCheck, DoctorReport, RoundTrip, TreeTiming};
use arena_shared::files::KnownFolder;
use arena_shared::geometry::Point;
use arena_shared::observation::{A11yBackend, A11yNode, A11yTree, TreeBudget, WindowInfo};
use arena_shared::registry::RegistryValue;

use crate::desktop::{ClipboardData, CommandSpec, Desktop, DesktopError, ExecLimits};

/// What the doctor needs to know beyond the desktop.
#[derive(Debug, Clone, Default)]
pub struct DoctorOptions {
    /// The address the server listens on (or would), for the reachability hint.
    pub bind: Option<std::net::SocketAddr>,
    /// Whether requests need a token.
    pub token: bool,
    /// How long a window may take to appear after its program starts.
    pub window_wait: Option<Duration>,
    /// Also time the trees of the heavy applications running and input round
    /// trips ([`deep`], `arena doctor --deep`).
    pub deep: bool,
}

impl DoctorOptions {
    /// The options of a server configured with `config` (its bind address) and
    /// `token` (whether one is in force).
    pub fn for_server(config: &crate::config::ServerConfig, token: bool) -> DoctorOptions {
        DoctorOptions {
            bind: Some(std::net::SocketAddr::new(config.bind, config.port)),
            token,
            window_wait: None,
            deep: false,
        }
    }
}

/// The text typed into Notepad and looked for afterwards.
const TYPED: &str = "arena doctor 42";

/// The tree budget of the tree check: upstream's caps, as a run uses them.
const TREE_BUDGET: TreeBudget = TreeBudget::WAA;

/// The command the exec check starts and must stop: `timeout_ms` is far shorter
/// than the child and the grandchild it starts in the background.
const EXEC_TIMEOUT_MS: u64 = 1500;

/// An exec check passes when the command came back within this much of its timeout.
const EXEC_SLACK: Duration = Duration::from_secs(10);

/// Runs every check in order and returns the report.
pub fn run(desktop: &dyn Desktop, options: &DoctorOptions) -> DoctorReport {
    let started = Instant::now();
    let cursor_before = desktop.cursor_position().ok();
    let mut checks = Vec::new();
    let mut time = |name: &str, check: &mut dyn FnMut() -> Outcome| {
        let began = Instant::now();
        let (status, detail) = match check() {
            Ok(pair) => pair,
            Err(Problem::Unavailable(why)) => (CheckStatus::Unavailable, why),
            Err(Problem::Failed(why)) => (CheckStatus::Fail, why),
        };
        checks.push(DoctorCheck { name: name.to_owned(), status, ms: millis(began.elapsed()), detail });
    };
    time("session", &mut || session(desktop));
    time("integrity", &mut || integrity(desktop));
    time("screen", &mut || screen(desktop));
    time("capture", &mut || capture(desktop));
    time("cursor", &mut || cursor(desktop));
    time("clipboard_text", &mut || clipboard_text(desktop));
    time("clipboard_image", &mut || clipboard_image(desktop));
    let wait = options.window_wait.unwrap_or(Duration::from_secs(10));
    let mut notepad: Option<WindowInfo> = None;
    time("notepad_start", &mut || start_notepad(desktop, wait, &mut notepad));
    time("activation", &mut || activation(desktop, notepad.as_ref()));
    time("notepad_typing", &mut || typing(desktop, notepad.as_ref()));
    time("read_back_uia", &mut || read_back(desktop, notepad.as_ref(), A11yBackend::Uia));
    time("read_back_win32", &mut || read_back(desktop, notepad.as_ref(), A11yBackend::Win32));
    time("uia_tree", &mut || tree(desktop));
    if let Some(typed_into) = &notepad {
        remove(desktop, typed_into);
    }
    time("window_close", &mut || close(desktop, wait));
    time("exec_timeout", &mut || exec_timeout(desktop));
    time("files", &mut || files(desktop));
    time("reachability", &mut || reachability(options));
    time("defender", &mut || defender(desktop));
    let deep = options.deep.then(|| deep(desktop, wait));
    if let Some(Point { x, y }) = cursor_before {
        if let Err(err) = desktop.perform(&Action::MoveTo { x, y }) {
            tracing::warn!(error = %err, "the doctor could not put the cursor back");
        }
    }
    DoctorReport {
        backend: desktop.kind().to_owned(),
        version: env!("CARGO_PKG_VERSION").to_owned(),
        checks,
        total_ms: millis(started.elapsed()),
        deep,
    }
}

/// Heavy applications by their process (and, for hosts shared by several, the
/// window's class or title): what `--deep` times the trees of.
const HEAVY_APPS: &[(&str, &str, &str)] = &[
    ("msedge.exe", "", "Edge"),
    ("chrome.exe", "", "Chrome"),
    ("explorer.exe", "CabinetWClass", "File Explorer"),
    ("systemsettings.exe", "", "Settings"),
    ("applicationframehost.exe", "Settings", "Settings"),
    ("notepad.exe", "", "Notepad"),
    ("winword.exe", "", "Word"),
    ("excel.exe", "", "Excel"),
    ("powerpnt.exe", "", "PowerPoint"),
    ("outlook.exe", "", "Outlook"),
    ("onenote.exe", "", "OneNote"),
    ("soffice.bin", "", "LibreOffice"),
    ("soffice.exe", "", "LibreOffice"),
    ("code.exe", "", "VS Code"),
];

/// The heavy application a window belongs to, if it is one.
fn heavy_app(w: &WindowInfo) -> Option<&'static str> {
    HEAVY_APPS.iter().find_map(|(process, class_or_title, app)| {
        let matches_process = w.process_name.eq_ignore_ascii_case(process);
        let matches_rest = class_or_title.is_empty()
            || w.class_name.eq_ignore_ascii_case(class_or_title)
            || w.title.contains(class_or_title);
        (matches_process && matches_rest).then_some(*app)
    })
}

/// `--deep`: each visible window of a heavy application (and a Notepad of the
/// doctor's own, so there is always one) is brought to the front and its tree
/// walked with upstream's budget, through UI Automation and the win32 source;
/// then input round trips: the cursor moved and read back, and a key typed into
/// the doctor's Notepad until its tree shows it.
pub fn deep(desktop: &dyn Desktop, wait: Duration) -> DeepReport {
    let mut report = DeepReport::default();
    let mut own = None;
    let _ = start_notepad(desktop, wait, &mut own);
    let windows = desktop.windows().unwrap_or_default();
    // At most a dozen windows, so the whole run stays within the route's deadline.
    let heavy = windows.iter().filter(|w| w.visible && !w.minimized).filter_map(|w| Some((w, heavy_app(w)?)));
    for (w, app) in heavy.take(12) {
        let _ = desktop.activate_window(w.id);
        for (backend, source) in [(A11yBackend::Uia, "uia"), (A11yBackend::Win32, "win32")] {
            let began = Instant::now();
            let walked = desktop.accessibility(backend, &TREE_BUDGET, true);
            let ms = millis(began.elapsed());
            let (nodes, truncated, partial, error) = match walked {
                Ok(tree) => (tree.node_count, tree.truncated, tree.windows_walked.iter().any(|ww| ww.partial), None),
                Err(err) => (0, false, false, Some(err.to_string())),
            };
            report.trees.push(TreeTiming {
                app: app.to_owned(),
                window: w.title.clone(),
                source: source.to_owned(),
                nodes,
                ms,
                truncated,
                partial,
                error,
            });
        }
    }
    // The cursor moved and read back.
    let mut moves = Vec::new();
    if let Ok(screen) = desktop.screen() {
        let target = cursor_target(screen.physical_width, screen.physical_height);
        for i in 0..20 {
            let began = Instant::now();
            if desktop.perform(&Action::MoveTo { x: target.x + i, y: target.y }).is_err() {
                break;
            }
            if desktop.cursor_position().ok() == Some(Point { x: target.x + i, y: target.y }) {
                moves.push(began.elapsed().as_secs_f64() * 1000.0);
            }
        }
    }
    report.input.push(RoundTrip::of("cursor moved and read back", &moves));
    // A key typed into the doctor's Notepad until its tree shows it.
    let mut keys = Vec::new();
    if let Some(notepad) = &own {
        for (i, letter) in ["q", "w", "e"].iter().enumerate() {
            if desktop.activate_window(notepad.id).is_err() {
                break;
            }
            let began = Instant::now();
            if desktop.perform(&Action::TypeText { text: (*letter).to_owned(), interval_ms: None }).is_err() {
                break;
            }
            let typed = ["q", "w", "e"][..=i].concat();
            while began.elapsed() < READ_BACK_WAIT {
                let seen = [A11yBackend::Win32, A11yBackend::Uia].iter().any(|backend| {
                    desktop
                        .accessibility(*backend, &TREE_BUDGET, true)
                        .is_ok_and(|tree| tree.windows.iter().any(|w| tree_holds(w, &typed)))
                });
                if seen {
                    keys.push(began.elapsed().as_secs_f64() * 1000.0);
                    break;
                }
                std::thread::sleep(Duration::from_millis(20));
            }
        }
        remove(desktop, notepad);
    }
    report.input.push(RoundTrip::of("key typed into Notepad, seen in its tree", &keys));
    report
}

/// Why a check did not pass.
enum Problem {
    Unavailable(String),
    Failed(String),
}

type Outcome = Result<(CheckStatus, String), Problem>;

impl From<DesktopError> for Problem {
    fn from(err: DesktopError) -> Problem {
        match err {
            DesktopError::Unsupported(why) => Problem::Unavailable(why),
            other => Problem::Failed(other.to_string()),
        }
    }
}

fn fail(why: impl Into<String>) -> Problem {
    Problem::Failed(why.into())
}

fn pass(detail: impl Into<String>) -> Outcome {
    Ok((CheckStatus::Pass, detail.into()))
}

fn millis(d: Duration) -> u64 {
    u64::try_from(d.as_millis()).unwrap_or(u64::MAX)
}

fn session(desktop: &dyn Desktop) -> Outcome {
    let session = desktop.session_id().map_or_else(|| "no session id".to_owned(), |id| format!("session {id}"));
    // Session 0 has no interactive desktop: a service's own process lands there.
    if desktop.session_id() == Some(0) {
        return Err(fail(format!("{session}: the server runs in the services' session, which has no desktop")));
    }
    let uac = match desktop.registry_read(
        r"HKEY_LOCAL_MACHINE\SOFTWARE\Microsoft\Windows\CurrentVersion\Policies\System",
        Some("EnableLUA"),
    ) {
        Ok(RegistryValue::Dword(0)) => "UAC off (EnableLUA=0)".to_owned(),
        Ok(RegistryValue::Dword(n)) => format!("UAC on (EnableLUA={n})"),
        Ok(other) => format!("UAC unknown (EnableLUA is {other:?})"),
        Err(err) => format!("UAC unknown ({err})"),
    };
    Ok((CheckStatus::Info, format!("{session}; {uac}")))
}

/// Microsoft Defender: Tamper Protection, real-time protection and detections
/// (a fact, `INFO`), failing when a detection names the guest's own files.
fn defender(desktop: &dyn Desktop) -> Outcome {
    let status = desktop.defender()?;
    let taken = status.guest_detections();
    if !taken.is_empty() {
        return Err(fail(format!(
            "Defender detected the guest's own files ({}): {}",
            taken.iter().map(|d| d.threat.as_str()).collect::<Vec<_>>().join(", "),
            status.summary()
        )));
    }
    Ok((CheckStatus::Info, status.summary()))
}

fn integrity(desktop: &dyn Desktop) -> Outcome {
    let level = desktop.integrity_level()?;
    Ok((CheckStatus::Info, level))
}

fn screen(desktop: &dyn Desktop) -> Outcome {
    let s = desktop.screen()?;
    if s.physical_width == 0 || s.physical_height == 0 {
        return Err(fail(format!("the screen is {}x{}", s.physical_width, s.physical_height)));
    }
    pass(format!(
        "{}x{} physical, {}x{} logical, scale {} ({} dpi), {} monitor(s)",
        s.physical_width,
        s.physical_height,
        s.logical_width,
        s.logical_height,
        s.scale_factor,
        (s.scale_factor * 96.0).round(),
        s.monitors.len().max(1)
    ))
}

fn capture(desktop: &dyn Desktop) -> Outcome {
    let screen = desktop.screen()?;
    let frame = desktop.capture(false)?;
    let (w, h) = frame.image.dimensions();
    if crate::imaging::is_black(&frame.image) {
        return Err(fail(format!("the {w}x{h} frame is entirely black (locked, secure or disconnected desktop?)")));
    }
    if (w, h) != (screen.physical_width, screen.physical_height) {
        return Err(fail(format!(
            "the frame is {w}x{h} but the screen is {}x{}",
            screen.physical_width, screen.physical_height
        )));
    }
    pass(format!("{w}x{h}, not black"))
}

/// Where the cursor check moves to: a third of the way in, away from the taskbar and corners.
fn cursor_target(width: u32, height: u32) -> Point {
    Point { x: i32::try_from(width / 3).unwrap_or(0), y: i32::try_from(height / 3).unwrap_or(0) }
}

fn cursor(desktop: &dyn Desktop) -> Outcome {
    let screen = desktop.screen()?;
    let target = cursor_target(screen.physical_width, screen.physical_height);
    desktop.perform(&Action::MoveTo { x: target.x, y: target.y })?;
    let at = desktop.cursor_position()?;
    if at != target {
        return Err(fail(format!("moved to ({}, {}) but the cursor is at ({}, {})", target.x, target.y, at.x, at.y)));
    }
    let frame = desktop.capture(true)?;
    if !frame.cursor_drawn {
        return Err(fail("the capture with the cursor did not draw it"));
    }
    let bare = desktop.capture(false)?;
    // The cursor sprite must change pixels right at its hot spot's neighbourhood.
    let changed = pixels_differ_near(&frame.image, &bare.image, at, 24);
    if !changed {
        return Err(fail(format!("no cursor is visible near ({}, {}) in the capture", at.x, at.y)));
    }
    pass(format!("moved to ({}, {}); the capture shows it there", at.x, at.y))
}

/// Whether the two images differ anywhere in the `size`-pixel square right and below `at`.
fn pixels_differ_near(a: &image::RgbaImage, b: &image::RgbaImage, at: Point, size: u32) -> bool {
    if a.dimensions() != b.dimensions() {
        return true;
    }
    let (w, h) = a.dimensions();
    let x0 = u32::try_from(at.x.max(0)).unwrap_or(0);
    let y0 = u32::try_from(at.y.max(0)).unwrap_or(0);
    (y0..(y0 + size).min(h)).any(|y| (x0..(x0 + size).min(w)).any(|x| a.get_pixel(x, y) != b.get_pixel(x, y)))
}

/// Runs `check` with the clipboard as it was before put back afterwards.
fn keeping_clipboard(desktop: &dyn Desktop, check: impl FnOnce() -> Outcome) -> Outcome {
    let saved = desktop.clipboard_get()?;
    let outcome = check();
    if let Err(err) = desktop.clipboard_set(&saved) {
        return Err(fail(format!("the check ran, but restoring the clipboard failed: {err}")));
    }
    outcome
}

fn clipboard_text(desktop: &dyn Desktop) -> Outcome {
    keeping_clipboard(desktop, || {
        let text = "arena doctor: ünïcode ✓ and a\nsecond line";
        desktop.clipboard_set(&ClipboardData::Text(text.to_owned()))?;
        match desktop.clipboard_get()? {
            ClipboardData::Text(back) if back.replace("\r\n", "\n") == text => {
                pass(format!("{} characters round-tripped", text.chars().count()))
            }
            ClipboardData::Text(back) => Err(fail(format!("set {text:?}, read back {back:?}"))),
            other => Err(fail(format!("set text, read back {}", clipboard_kind(&other)))),
        }
    })
}

fn clipboard_image(desktop: &dyn Desktop) -> Outcome {
    keeping_clipboard(desktop, || {
        let image = image::RgbaImage::from_fn(17, 9, |x, y| image::Rgba([(x * 15) as u8, (y * 28) as u8, 200, 255]));
        desktop.clipboard_set(&ClipboardData::Image(image.clone()))?;
        match desktop.clipboard_get()? {
            ClipboardData::Image(back) if back == image => pass("a 17x9 image round-tripped pixel for pixel"),
            ClipboardData::Image(back) => {
                Err(fail(format!("set a 17x9 image, read back a {}x{} one that differs", back.width(), back.height())))
            }
            other => Err(fail(format!("set an image, read back {}", clipboard_kind(&other)))),
        }
    })
}

fn clipboard_kind(data: &ClipboardData) -> &'static str {
    match data {
        ClipboardData::Empty => "an empty clipboard",
        ClipboardData::Text(_) => "text",
        ClipboardData::Image(_) => "an image",
    }
}

fn is_notepad(w: &WindowInfo) -> bool {
    w.process_name.eq_ignore_ascii_case("notepad.exe") || w.class_name.eq_ignore_ascii_case("Notepad")
}

fn start_notepad(desktop: &dyn Desktop, wait: Duration, found: &mut Option<WindowInfo>) -> Outcome {
    let before: Vec<u64> = desktop.windows()?.iter().filter(|w| is_notepad(w)).map(|w| w.id).collect();
    let pid = desktop.spawn(&CommandSpec::Argv(vec!["notepad.exe".to_owned()]))?;
    let started = Instant::now();
    loop {
        let windows = desktop.windows()?;
        if let Some(w) = windows.into_iter().find(|w| is_notepad(w) && w.visible && !before.contains(&w.id)) {
            let detail = format!("pid {pid}; window {:?} appeared after {} ms", w.title, millis(started.elapsed()));
            *found = Some(w);
            return pass(detail);
        }
        if started.elapsed() >= wait {
            return Err(fail(format!(
                "started pid {pid} but no new Notepad window appeared within {} s",
                wait.as_secs()
            )));
        }
        std::thread::sleep(Duration::from_millis(200));
    }
}

fn need(window: Option<&WindowInfo>) -> Result<&WindowInfo, Problem> {
    window.ok_or_else(|| fail("skipped: Notepad did not start"))
}

fn activation(desktop: &dyn Desktop, notepad: Option<&WindowInfo>) -> Outcome {
    let notepad = need(notepad)?;
    desktop.activate_window(notepad.id)?;
    let windows = desktop.windows()?;
    match windows.iter().find(|w| w.focused) {
        Some(w) if w.id == notepad.id => pass(format!("{:?} is the foreground window", w.title)),
        Some(w) => Err(fail(format!("activated {:?} but {:?} is in the foreground", notepad.title, w.title))),
        None => Err(fail(format!("activated {:?} but no window is in the foreground", notepad.title))),
    }
}

fn typing(desktop: &dyn Desktop, notepad: Option<&WindowInfo>) -> Outcome {
    let notepad = need(notepad)?;
    desktop.activate_window(notepad.id)?;
    desktop.perform(&Action::TypeText { text: TYPED.to_owned(), interval_ms: None })?;
    pass(format!("typed {TYPED:?} into {:?}", notepad.title))
}

/// Whether `text` is the name, value or text of `node` or of a node below it.
fn tree_holds(node: &A11yNode, text: &str) -> bool {
    let here =
        [Some(&node.name), node.value.as_ref(), node.text.as_ref()].into_iter().flatten().any(|s| s.contains(text));
    here || node.children.iter().any(|c| tree_holds(c, text))
}

fn node_count(node: &A11yNode) -> usize {
    1 + node.children.iter().map(node_count).sum::<usize>()
}

/// How long typed text may take to show in a tree: `SendInput` returns before the
/// program has handled the keys.
const READ_BACK_WAIT: Duration = Duration::from_secs(5);

fn read_back(desktop: &dyn Desktop, notepad: Option<&WindowInfo>, backend: A11yBackend) -> Outcome {
    let notepad = need(notepad)?;
    let started = Instant::now();
    let tree = loop {
        let tree = desktop.accessibility(backend, &TREE_BUDGET, true)?;
        let holds = tree.windows.iter().any(|w| tree_holds(w, TYPED));
        if holds || started.elapsed() >= READ_BACK_WAIT {
            break tree;
        }
        std::thread::sleep(Duration::from_millis(200));
    };
    let window = tree.windows.iter().find(|w| w.window_id == Some(notepad.id)).or(tree.windows.first());
    match window {
        Some(w) if tree_holds(w, TYPED) => pass(format!(
            "the typed text is in the {:?} tree of {:?} ({} nodes, {} ms)",
            backend,
            notepad.title,
            node_count(w),
            tree.elapsed_ms
        )),
        Some(w) => {
            Err(fail(format!("the {backend:?} tree of {:?} ({} nodes) does not hold {TYPED:?}", w.name, node_count(w))))
        }
        None => Err(fail(format!("the {backend:?} tree of the foreground window is empty"))),
    }
}

/// One line per top-level window: its name, node count and whether it was cut short.
fn per_window(tree: &A11yTree) -> String {
    tree.windows.iter().map(|w| format!("{:?}: {}", w.name, node_count(w))).collect::<Vec<_>>().join(", ")
}

fn tree(desktop: &dyn Desktop) -> Outcome {
    let tree = desktop.accessibility(A11yBackend::Uia, &TREE_BUDGET, false)?;
    let detail = format!(
        "{} windows, {} nodes in {} ms{} [{}]",
        tree.windows.len(),
        tree.node_count,
        tree.elapsed_ms,
        if tree.truncated { ", truncated by the budget" } else { "" },
        per_window(&tree)
    );
    if tree.windows.is_empty() {
        return Err(fail(format!("no window in the tree: {detail}")));
    }
    if tree.elapsed_ms > TREE_BUDGET.max_ms + 2000 {
        return Err(fail(format!("the walk overran its {} ms budget: {detail}", TREE_BUDGET.max_ms)));
    }
    pass(detail)
}

fn still_open(desktop: &dyn Desktop, id: u64, within: Duration) -> Result<bool, Problem> {
    let started = Instant::now();
    loop {
        if !desktop.windows()?.iter().any(|w| w.id == id) {
            return Ok(false);
        }
        if started.elapsed() >= within {
            return Ok(true);
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Closes a Notepad of its own, with nothing typed in it (so no program asks to save):
/// `WM_CLOSE` must make the window go away.
fn close(desktop: &dyn Desktop, wait: Duration) -> Outcome {
    let mut fresh = None;
    start_notepad(desktop, wait, &mut fresh)?;
    let fresh = need(fresh.as_ref())?;
    desktop.close_window(fresh.id)?;
    if still_open(desktop, fresh.id, Duration::from_secs(5))? {
        remove(desktop, fresh);
        return Err(fail(format!("{:?} is still open 5 s after WM_CLOSE", fresh.title)));
    }
    pass(format!("{:?} closed on WM_CLOSE", fresh.title))
}

/// Leaves no doctor's Notepad behind: asks it to close, and on Windows ends its
/// process when it waits on a save prompt (the typed text is the doctor's own). The
/// stub's process ids are its own, never the host's, so nothing is killed there.
fn remove(desktop: &dyn Desktop, notepad: &WindowInfo) {
    let _ = desktop.close_window(notepad.id);
    if !matches!(still_open(desktop, notepad.id, Duration::from_secs(2)), Ok(true)) {
        return;
    }
    if desktop.kind() == "windows" {
        let limits = ExecLimits { timeout_ms: 10_000, max_output_bytes: 4096, cwd: None, stdin: None };
        let kill = vec!["taskkill".to_owned(), "/F".to_owned(), "/PID".to_owned(), notepad.process_id.to_string()];
        let _ = desktop.run(&CommandSpec::Argv(kill), &limits);
    }
}

/// A shell line whose child outlives the timeout and starts a grandchild that
/// holds the output pipe too: only killing the whole tree ends the call early.
fn slow_shell_line() -> String {
    crate::desktop::windows::target::SLOW_SHELL_LINE.to_owned()
}

fn exec_timeout(desktop: &dyn Desktop) -> Outcome {
    let limits = ExecLimits { timeout_ms: EXEC_TIMEOUT_MS, max_output_bytes: 1 << 16, cwd: None, stdin: None };
    let started = Instant::now();
    let out = match desktop.run(&CommandSpec::Shell(slow_shell_line()), &limits) {
        // A desktop that runs no real programs (the stub without --stub-host-exec)
        // has no command to time out: not a failure of this desktop.
        Err(DesktopError::NotFound(why)) => return Err(Problem::Unavailable(why)),
        other => other?,
    };
    let took = started.elapsed();
    if !out.timed_out {
        return Err(fail(format!(
            "a 60 s command with a {EXEC_TIMEOUT_MS} ms timeout ended without timing out: {out:?}"
        )));
    }
    if took > Duration::from_millis(EXEC_TIMEOUT_MS) + EXEC_SLACK {
        return Err(fail(format!(
            "the timeout was {EXEC_TIMEOUT_MS} ms but the call took {} ms: a grandchild kept the output open",
            millis(took)
        )));
    }
    pass(format!("timed out and returned after {} ms, child and grandchild stopped", millis(took)))
}

fn files(desktop: &dyn Desktop) -> Outcome {
    let mut found = Vec::new();
    for folder in [KnownFolder::Home, KnownFolder::Desktop, KnownFolder::Documents, KnownFolder::Downloads] {
        found.push(format!("{folder:?}={}", desktop.known_folder(folder)?));
    }
    let documents = desktop.known_folder(KnownFolder::Documents)?;
    let guest_path = format!("{}\\arena-doctor-{}.txt", documents.trim_end_matches('\\'), std::process::id());
    let local = desktop.map_path(&guest_path)?;
    let content = b"written by arena-guest doctor\n";
    arena_shared::atomic::write_atomic(&local, content).map_err(|err| fail(format!("writing {guest_path}: {err}")))?;
    let back = std::fs::read(&local).map_err(|err| fail(format!("reading {guest_path} back: {err}")));
    let removed = std::fs::remove_file(&local);
    if back? != content {
        return Err(fail(format!("{guest_path} read back different bytes")));
    }
    removed.map_err(|err| fail(format!("deleting {guest_path}: {err}")))?;
    pass(format!("wrote, read and deleted a file in Documents; {}", found.join(", ")))
}

fn reachability(options: &DoctorOptions) -> Outcome {
    let Some(bind) = options.bind else {
        return Ok((CheckStatus::Info, "not serving: no address to report".to_owned()));
    };
    let auth = if options.token { "with a token" } else { "without a token" };
    if bind.port() == 0 {
        return Ok((CheckStatus::Info, format!("would listen on a free port of {} {auth}", bind.ip())));
    }
    let hint = if bind.ip().is_loopback() {
        format!(
            "listening on {bind} {auth}: only programs in this machine can reach it (pass --bind 0.0.0.0 for the host)"
        )
    } else {
        format!(
            "listening on {bind} {auth}: the host reaches it if the firewall allows TCP {} in (not tested from here)",
            bind.port()
        )
    };
    Ok((CheckStatus::Info, hint))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `--deep` on the stub: the doctor's Notepad and a scenario's Edge and
    /// Explorer windows get their tree timed through both sources (Edge's bulk
    /// fetch hangs, so it is read element by element), and both round trips are
    /// measured.
    #[test]
    fn deep_times_the_trees_of_heavy_applications_and_input_round_trips() {
        let scenario = r#"{"windows": [
            {"title": "New tab - Microsoft Edge", "process_name": "msedge.exe", "bulk_fetch_ms": 40000, "bulk_fetch_hangs": true,
             "elements": [{"role": "Button", "class_name": "", "name": "Back", "enabled": true, "visible": true}]},
            {"title": "Documents", "class_name": "CabinetWClass", "process_name": "explorer.exe"},
            {"title": "Calculator", "process_name": "calc.exe"}]}"#;
        let scenario = crate::desktop::stub::scenario::Scenario::parse(scenario, "test").unwrap();
        let desktop = crate::desktop::stub::StubDesktop::with_config(crate::desktop::stub::StubConfig {
            scenario: Some(scenario),
            ..crate::desktop::stub::StubConfig::default()
        })
        .unwrap();
        let options = DoctorOptions { deep: true, ..DoctorOptions::default() };
        let report = run(&desktop, &options);
        let deep = report.deep.expect("the deep report");
        let apps: Vec<(&str, &str)> = deep.trees.iter().map(|t| (t.app.as_str(), t.source.as_str())).collect();
        for wanted in [("Edge", "uia"), ("Edge", "win32"), ("File Explorer", "uia"), ("Notepad", "uia")] {
            assert!(apps.contains(&wanted), "{wanted:?} not in {apps:?}");
        }
        assert!(!apps.iter().any(|(app, _)| *app == "Calculator"), "{apps:?}");
        let edge = deep.trees.iter().find(|t| t.app == "Edge" && t.source == "uia").unwrap();
        assert!(edge.partial && edge.nodes > 0 && edge.error.is_none(), "{edge:?}");
        // Abandoned at its half of the 10 s budget, not after its 40 s.
        assert!(edge.ms < 20_000, "the walk waited for the hung fetch: {edge:?}");
        assert_eq!(deep.input.len(), 2);
        assert!(deep.input.iter().all(|r| r.samples > 0), "{:?}", deep.input);
        let table = deep.render_table();
        assert!(table.contains("| Edge | New tab - Microsoft Edge | uia |"), "{table}");
        assert!(table.contains("| key typed into Notepad, seen in its tree | 3 |"), "{table}");
    }

    #[test]
    fn the_cursor_target_is_inside_the_screen_away_from_the_edges() {
        assert_eq!(cursor_target(1440, 900), Point { x: 480, y: 300 });
        assert_eq!(cursor_target(0, 0), Point { x: 0, y: 0 });
    }

    #[test]
    fn differing_pixels_count_only_near_the_point() {
        let a = image::RgbaImage::new(100, 100);
        let mut b = a.clone();
        b.put_pixel(90, 90, image::Rgba([255, 0, 0, 255]));
        assert!(!pixels_differ_near(&a, &b, Point { x: 10, y: 10 }, 24));
        assert!(pixels_differ_near(&a, &b, Point { x: 80, y: 80 }, 24));
        assert!(pixels_differ_near(&a, &image::RgbaImage::new(5, 5), Point { x: 0, y: 0 }, 24));
    }

    #[test]
    fn text_is_found_in_values_deep_in_the_tree() {
        let leaf = A11yNode { value: Some(format!("x {TYPED} y")), ..A11yNode::default() };
        let root = A11yNode {
            children: vec![A11yNode { children: vec![leaf], ..A11yNode::default() }],
            ..A11yNode::default()
        };
        assert!(tree_holds(&root, TYPED));
        assert!(!tree_holds(&A11yNode::default(), TYPED));
        assert_eq!(node_count(&root), 3);
    }

    #[test]
    fn unsupported_means_unavailable_and_other_errors_fail() {
        assert!(matches!(Problem::from(DesktopError::Unsupported("no UIA".into())), Problem::Unavailable(_)));
        assert!(matches!(Problem::from(DesktopError::NotFound("x".into())), Problem::Failed(_)));
    }

    #[test]
    fn reachability_is_a_hint_about_the_bind_address() {
        let local = DoctorOptions { bind: Some("127.0.0.1:5000".parse().unwrap()), ..DoctorOptions::default() };
        let (status, text) = reachability(&local).ok().unwrap();
        assert_eq!(status, CheckStatus::Info);
        assert!(text.contains("only programs in this machine"), "{text}");
        let open =
            DoctorOptions { bind: Some("0.0.0.0:5000".parse().unwrap()), token: true, ..DoctorOptions::default() };
        let (_, text) = reachability(&open).ok().unwrap();
        assert!(text.contains("with a token") && text.contains("TCP 5000"), "{text}");
    }
}
