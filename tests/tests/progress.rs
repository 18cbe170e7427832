//! What `arena run` shows while it goes (issue 32, item 1): on a terminal (a real
//! pseudo-terminal here, held by util-linux's `script`) the live display of tasks done, solved so far, ETA and each
//! guest's task and step; with `--progress plain` one line per finished task; with
//! `--progress none` neither.

#![cfg(unix)]

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

/// `command` with its stderr on a pseudo-terminal of 160x40 and its stdout in
/// `stdout`: util-linux's `script` holds the terminal's other side and copies what
/// it shows to its own stdout, which this answers with the command's exit status.
#[cfg(target_os = "linux")]
fn on_a_terminal(command: &Command, stdout: &Path) -> (std::process::ExitStatus, String) {
    let quote = |word: &std::ffi::OsStr| format!("'{}'", word.to_str().expect("a UTF-8 word").replace('\'', "'\\''"));
    let words: Vec<String> = std::iter::once(command.get_program()).chain(command.get_args()).map(quote).collect();
    let line = format!("stty cols 160 rows 40; exec {} >{}", words.join(" "), quote(stdout.as_os_str()));
    let output = Command::new("script")
        .args(["--quiet", "--return", "--command", &line, "/dev/null"])
        .env_remove("CI")
        .stdin(Stdio::null())
        .output()
        .expect("util-linux's script runs");
    (output.status, String::from_utf8_lossy(&output.stdout).into_owned())
}

#[cfg(target_os = "linux")]
#[test]
fn a_run_on_a_terminal_shows_the_live_display() {
    let tmp = tempfile::tempdir().expect("tmp");
    let stdout = tmp.path().join("stdout.txt");
    let (status, screen) = on_a_terminal(&run_command(&tmp.path().join("out"), "auto"), &stdout);
    assert!(status.success(), "{screen}");
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
    assert!(!screen.lines().any(|l| is_task_line(l.trim_end_matches('\r'))), "no plain lines on a terminal: {screen}");
    // The summary stays on stdout, out of the display's way.
    let summary = std::fs::read_to_string(&stdout).expect("the run's stdout");
    assert!(!summary.is_empty() && !screen.contains(summary.lines().next().unwrap_or("-")), "{summary}");
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
