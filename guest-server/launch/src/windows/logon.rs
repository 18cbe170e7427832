//! The logon task's launcher loop: what `arena-guest-logon.exe` (the GUI-subsystem
//! binary Task Scheduler starts at logon, `guest-server/launch/src/main.rs`) runs.
//!
//! The launcher is a GUI-subsystem program, so Windows gives it no console at all:
//! nothing flashes on the user's desktop at logon, and nothing lands in screenshots,
//! window lists or trees. (Until it became a binary of its own the launcher was
//! `arena-guest.exe logon-task run`, a console program: Task Scheduler opened a console
//! window for it, which it closed with `FreeConsole` a moment later.) It starts
//! [`crate::exes::SERVER_EXE`] from its own folder as a child with
//! `CREATE_NO_WINDOW`: the server gets a console of its own that has no window, so the
//! console programs it runs for agents share that hidden console instead of each
//! opening a window, as under upstream's hidden PowerShell. The server is
//! `"<arena-guest.exe>" SERVE OPTIONS --worker`, as the service's worker: its standard
//! input is a pipe only the launcher holds, so when the task is ended (the launcher
//! terminated) the pipe closes and the server shuts down gracefully. A server that dies
//! is started again after [`Backoff`]'s delay. Everything goes to
//! `%ProgramData%\arena\logon-task.log` (the launcher's own lines and the server's
//! output), moved aside past 10 MB.
//!
//! FFI glue only: the serve options' checks, the backoff and the log handling are in
//! this crate's neutral modules, and the task's definition in `arena_guest::service`,
//! all tested natively.

use std::convert::Infallible;
use std::fs::File;
use std::io::Write as _;
use std::os::windows::process::CommandExt as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

use windows_sys::Win32::System::Threading::{CREATE_NEW_PROCESS_GROUP, CREATE_NO_WINDOW};

use crate::error::ServiceCliError;
use crate::logs::{log_dir, rotate_log, LOGON_TASK_LOG, LOG_MAX_BYTES};
use crate::restart::Backoff;

/// `%ProgramData%\arena\logon-task.log`.
fn log_path() -> PathBuf {
    log_dir(std::env::var_os("ProgramData").as_deref()).join(LOGON_TASK_LOG)
}

/// The log, rotated first when it has grown past [`LOG_MAX_BYTES`].
fn open_log(path: &Path) -> Result<File, ServiceCliError> {
    let _ = rotate_log(path, LOG_MAX_BYTES);
    std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
        .map_err(|source| ServiceCliError::Io { what: format!("opening {}", path.display()), source })
}

/// One line of the launcher's own in the log (the server writes its own lines there too).
fn note(log: &mut File, line: &str) {
    let _ = writeln!(log, "logon-task launcher (pid {}): {line}", std::process::id());
}

/// See [`super::note_launcher_failure`].
pub(super) fn note_failure(err: &ServiceCliError) {
    let path = log_path();
    if let Some(folder) = path.parent() {
        let _ = std::fs::create_dir_all(folder);
    }
    if let Ok(mut log) = open_log(&path) {
        note(&mut log, &format!("error: {err}"));
    }
}

/// Runs `server` hidden until this process is ended; see the module documentation.
pub(super) fn run(server: &Path, serve_args: &[String]) -> Result<Infallible, ServiceCliError> {
    let log_path = log_path();
    if let Some(logs) = log_path.parent() {
        std::fs::create_dir_all(logs)
            .map_err(|source| ServiceCliError::Io { what: format!("creating {}", logs.display()), source })?;
    }
    let mut log = open_log(&log_path)?;
    let folder: Option<PathBuf> = server.parent().map(Path::to_path_buf);
    let mut backoff = Backoff::new();
    loop {
        let started = Instant::now();
        let mut command = Command::new(server);
        command.args(serve_args).arg("--worker");
        if let Some(folder) = &folder {
            command.current_dir(folder);
        }
        let output = |log: &File| {
            log.try_clone().map_err(|source| ServiceCliError::Io { what: "sharing the log file".into(), source })
        };
        command
            .stdin(Stdio::piped())
            .stdout(output(&log)?)
            .stderr(output(&log)?)
            .creation_flags(CREATE_NO_WINDOW | CREATE_NEW_PROCESS_GROUP);
        let mut child = command.spawn().map_err(|source| {
            note(&mut log, &format!("cannot start the server {}: {source}", server.display()));
            ServiceCliError::Io { what: format!("starting {}", server.display()), source }
        })?;
        note(&mut log, &format!("started the server (pid {}) with {serve_args:?}", child.id()));
        // Never written to: the server stops when this pipe closes, which is when this
        // launcher ends. `wait` would close it first, so it is taken out and kept.
        let stop_pipe = child.stdin.take();
        let status = child.wait();
        drop(stop_pipe);
        let ran = started.elapsed();
        let delay = backoff.after_exit(ran);
        log = open_log(&log_path)?;
        let status = status.map_or_else(|err| format!("cannot be waited for ({err})"), |s| format!("ended ({s})"));
        note(
            &mut log,
            &format!("the server {status} after {} s; starting it again in {} s", ran.as_secs(), delay.as_secs()),
        );
        std::thread::sleep(delay);
    }
}
