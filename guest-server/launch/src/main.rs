//! `arena-guest-logon`: the logon task's launcher, what Task Scheduler starts at each
//! logon (`arena-guest logon-task install` registers it). It takes the serve options
//! as its whole command line and runs [`arena_guest_launch::run_logon_launcher`]:
//! `arena-guest.exe` from the same folder, without a console window, restarted when it
//! dies, until the task is ended.
//!
//! It is a GUI-subsystem program (`windows_subsystem = "windows"`): Windows gives a
//! GUI process no console, so nothing flashes at logon. It creates no window either.
//! Having no console, it reports a failure in `%ProgramData%\arena\logon-task.log` and
//! through its exit code (2: bad options or a missing `arena-guest.exe`; 1: the server
//! could not be started). Elsewhere than Windows it only says that it needs Windows.

#![windows_subsystem = "windows"]
#![forbid(unsafe_code)]

use std::process::ExitCode;

fn main() -> ExitCode {
    let Err(err) = arena_guest_launch::run_logon_launcher(std::env::args_os().skip(1));
    arena_guest_launch::windows::note_launcher_failure(&err);
    // Nowhere to go under Windows (no console: the write is dropped); seen elsewhere.
    eprintln!("error: {err}");
    ExitCode::from(err.exit_code())
}
