//! What `arena run` shows while it goes (issue 32, item 1): on a terminal (a real
//! pseudo-terminal here) the live display of tasks done, solved so far, ETA and each
//! guest's task and step; with `--progress plain` one line per finished task; with
//! `--progress none` neither.

#![cfg(unix)]

use std::io::Read as _;
use std::path::Path;
use std::process::{Command, Stdio};

use arena_test_support::{stub_tasks_dir, workspace_binary};

/// `arena run` of the stub tasks on two stub guests with their plans, a short pause
/// after each action so that steps are seen, and `progress`.
fn run_command(out: &Path, progress: &str) -> Command {
    let mut command = Command::new(workspace_binary("arena-host", "arena").expect("the arena binary"));
    command
        .args(["run", "--stub-guests", "2", "--agent", "scripted", "--sleep-after", "0.3", "--progress", progress])
        .arg("--tasks")
        .arg(stub_tasks_dir().join("examples"))
        .arg("--plans")
        .arg(stub_tasks_dir().join("plans"))
        .arg("--out")
        .arg(out)
        .env_remove("CI")
        .stdin(Stdio::null());
    command
}

/// The stub tasks' count, as the run counts them.
fn stub_task_count() -> usize {
    walk(&stub_tasks_dir().join("examples"))
}

fn walk(dir: &Path) -> usize {
    std::fs::read_dir(dir)
        .expect("a folder")
        .map(|e| e.expect("an entry").path())
        .map(|p| if p.is_dir() { walk(&p) } else { usize::from(p.extension().is_some_and(|e| e == "json")) })
        .sum()
}

/// Whether `line` is a plain progress line: `[k/n] domain/task: score ...`.
fn is_task_line(line: &str) -> bool {
    line.starts_with('[') && line.contains("] ") && line.contains(": score ")
}

#[test]
fn a_run_on_a_terminal_shows_the_live_display() {
    use rustix::pty::{grantpt, openpt, ptsname, unlockpt, OpenptFlags};
    let tmp = tempfile::tempdir().expect("tmp");
    let master = openpt(OpenptFlags::RDWR | OpenptFlags::NOCTTY).expect("a pseudo-terminal");
    grantpt(&master).expect("grantpt");
    unlockpt(&master).expect("unlockpt");
    let size = rustix::termios::Winsize { ws_row: 40, ws_col: 160, ws_xpixel: 0, ws_ypixel: 0 };
    rustix::termios::tcsetwinsize(&master, size).expect("the terminal's size");
    let name = ptsname(&master, Vec::new()).expect("its name");
    let terminal = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(name.to_str().expect("a path"))
        .expect("the terminal's side");
    let child = {
        let mut command = run_command(&tmp.path().join("out"), "auto");
        command.stdout(Stdio::piped()).stderr(Stdio::from(terminal)).spawn().expect("arena run starts")
        // The command, and with it this side's handle of the terminal, goes here:
        // the reader below sees the end once the run exits.
    };
    let mut screen = Vec::new();
    // Linux answers EIO once the last handle of the terminal's side is closed.
    let _ = std::fs::File::from(master).read_to_end(&mut screen);
    let output = child.wait_with_output().expect("the run ends");
    let screen = String::from_utf8_lossy(&screen);
    assert!(output.status.success(), "{screen}");
    let total = stub_task_count();
    // The run's bar, its final state left on screen.
    assert!(screen.contains(&format!("{total}/{total} tasks")), "{screen}");
    assert!(screen.contains("solved (") && screen.contains("ETA"), "{screen}");
    // A line per guest naming its task and step while they ran.
    for guest in ["guest 1 (http://", "guest 2 (http://"] {
        assert!(screen.contains(guest), "{guest}: {screen}");
    }
    assert!(screen.contains(" · step 1"), "a guest's step is shown: {screen}");
    // Drawn in place (cursor movements), not one line per task.
    assert!(screen.contains('\u{1b}'), "terminal escapes: {screen}");
    assert!(!screen.lines().any(is_task_line), "no plain lines on a terminal: {screen}");
    // The summary stays on stdout, out of the display's way.
    assert!(!String::from_utf8_lossy(&output.stdout).is_empty());
}

#[test]
fn plain_progress_is_one_line_per_task_and_none_is_quiet() {
    let tmp = tempfile::tempdir().expect("tmp");
    let plain = run_command(&tmp.path().join("plain"), "plain").output().expect("arena run");
    let stderr = String::from_utf8_lossy(&plain.stderr);
    assert!(plain.status.success(), "{stderr}");
    let total = stub_task_count();
    let lines: Vec<&str> = stderr.lines().filter(|l| is_task_line(l)).collect();
    assert_eq!(lines.len(), total, "one line per task: {stderr}");
    assert!(lines[total - 1].starts_with(&format!("[{total}/{total}] ")), "{stderr}");
    assert!(lines.iter().all(|l| l.contains(" solved (")), "{stderr}");
    // The stub tasks' own plans solve every one of them.
    assert!(lines[total - 1].ends_with(&format!("{total} solved (100.0 %)")), "{stderr}");
    assert!(!stderr.contains('\u{1b}'), "no terminal escapes: {stderr}");

    let quiet = run_command(&tmp.path().join("none"), "none").output().expect("arena run");
    let stderr = String::from_utf8_lossy(&quiet.stderr);
    assert!(quiet.status.success(), "{stderr}");
    assert!(!stderr.lines().any(is_task_line), "{stderr}");
}
