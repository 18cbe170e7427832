//! The logon task's launcher (`logon-task run`), what Task Scheduler starts at logon.
//!
//! `arena-guest.exe` is a console program, so Task Scheduler gives the task a console
//! window on the user's desktop, where it would be in screenshots, window lists and
//! trees. The launcher detaches from that console at once (`FreeConsole`; the window
//! closes as soon as nothing is attached to it) and starts the server as a child with
//! `CREATE_NO_WINDOW`: the server gets a console of its own that has no window, so the
//! console programs it runs for agents share that hidden console instead of each
//! opening a window, as under upstream's hidden PowerShell. The server is
//! `"<exe>" SERVE OPTIONS --worker`, as the service's worker: its standard input is a
//! pipe only the launcher holds, so when the task is ended (the launcher terminated)
//! the pipe closes and the server shuts down gracefully. A server that dies is started
//! again after [`Backoff`]'s delay. Everything goes to `%ProgramData%\arena\logon-task.log`
//! (the launcher's own lines and the server's output), moved aside past 10 MB.
//!
//! FFI glue only: the task's definition, the command lines, the backoff and the log
//! handling are in [`crate::service`], tested natively.

use std::fs::File;
use std::io::Write as _;
use std::os::windows::io::IntoRawHandle as _;
use std::os::windows::process::CommandExt as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

use windows::Win32::System::Threading::{CREATE_NEW_PROCESS_GROUP, CREATE_NO_WINDOW};

use crate::service::{
    current_exe, log_dir, rotate_log, Backoff, LauncherOptions, ServiceCliError, LOGON_TASK_LOG, LOG_MAX_BYTES,
};

// The two console calls the launcher needs; the `windows` crate has them only behind a
// feature this crate does not otherwise use.
#[link(name = "kernel32")]
extern "system" {
    fn FreeConsole() -> i32;
    fn SetStdHandle(which: u32, handle: *mut core::ffi::c_void) -> i32;
}

/// `STD_INPUT_HANDLE`, `STD_OUTPUT_HANDLE`, `STD_ERROR_HANDLE` ((DWORD)-10, -11, -12).
const STD_HANDLES: [u32; 3] = [-10i32 as u32, -11i32 as u32, -12i32 as u32];

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

/// Leaves the console Task Scheduler created, so its window closes, and points this
/// process's standard output and error at the log (standard input at nothing), so
/// nothing written later goes to a console handle that no longer exists.
fn detach_console(log: &File) {
    // SAFETY: FreeConsole has no preconditions; failing (no console) is harmless.
    let _ = unsafe { FreeConsole() };
    let out = log.try_clone().map(|file| file.into_raw_handle()).unwrap_or(std::ptr::null_mut());
    for (which, handle) in STD_HANDLES.into_iter().zip([std::ptr::null_mut(), out, out]) {
        // SAFETY: `handle` is null or a file handle that is never closed (leaked on purpose).
        let _ = unsafe { SetStdHandle(which, handle) };
    }
}

/// Runs the server hidden until this process is ended; see the module documentation.
pub(super) fn run(options: &LauncherOptions) -> Result<String, ServiceCliError> {
    let exe = current_exe()?;
    let logs = log_dir(std::env::var_os("ProgramData").as_deref());
    std::fs::create_dir_all(&logs)
        .map_err(|source| ServiceCliError::Io { what: format!("creating {}", logs.display()), source })?;
    let log_path = logs.join(LOGON_TASK_LOG);
    let mut log = open_log(&log_path)?;
    detach_console(&log);
    let folder: Option<PathBuf> = exe.parent().map(Path::to_path_buf);
    let mut backoff = Backoff::new();
    loop {
        let started = Instant::now();
        let mut command = Command::new(&exe);
        command.args(&options.serve_args).arg("--worker");
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
            .creation_flags((CREATE_NO_WINDOW | CREATE_NEW_PROCESS_GROUP).0);
        let mut child = command.spawn().map_err(|source| {
            note(&mut log, &format!("cannot start the server: {source}"));
            ServiceCliError::Io { what: format!("starting {}", exe.display()), source }
        })?;
        note(&mut log, &format!("started the server (pid {}) with {:?}", child.id(), options.serve_args));
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
