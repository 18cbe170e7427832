//! Ctrl-C during `arena run`: the real binary is sent SIGINT mid-run, exits 130
//! with what finished kept and the rest unfinished, and the same command run
//! again completes the run with the outcomes of a run never interrupted.

#![cfg(unix)]

use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use arena_results::summary::Summary;
use arena_results::RESULT_FILE;
use arena_test_support::workspace_binary;

fn stub_index() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tasks/stub/test_all.json")
}

/// `arena run` over the stub task set on one embedded stub guest, with a short
/// pause after each action so that the run lasts a few seconds.
fn run(out: &Path) -> Child {
    let exe = workspace_binary("arena-host", "arena").expect("the arena binary");
    Command::new(exe)
        .args(["run", "--stub-guests", "1", "--pauses", "fast", "--sleep-after", "0.3", "--tasks"])
        .arg(stub_index())
        .arg("--out")
        .arg(out)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("arena run starts")
}

/// Waits for `child` to exit, failing the test after `within`; answers its status and stderr.
fn finish(mut child: Child, within: Duration) -> (ExitStatus, String) {
    let deadline = Instant::now() + within;
    loop {
        if let Some(status) = child.try_wait().expect("wait") {
            let mut err = String::new();
            if let Some(mut pipe) = child.stderr.take() {
                let _ = std::io::Read::read_to_string(&mut pipe, &mut err);
            }
            return (status, err);
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            panic!("arena run did not exit within {within:?}");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn results_below(dir: &Path) -> usize {
    fn walk(dir: &Path, n: &mut usize) {
        let Ok(entries) = std::fs::read_dir(dir) else { return };
        for entry in entries.flatten() {
            let path = entry.path();
            if path.is_dir() {
                walk(&path, n);
            } else if path.file_name().is_some_and(|name| name == RESULT_FILE) {
                *n += 1;
            }
        }
    }
    let mut n = 0;
    walk(dir, &mut n);
    n
}

#[test]
fn ctrl_c_stops_the_run_and_the_same_command_finishes_it_as_if_never_stopped() {
    let tmp = tempfile::tempdir().expect("tmp");
    let (whole, stopped) = (tmp.path().join("whole"), tmp.path().join("stopped"));

    let (status, err) = finish(run(&whole), Duration::from_secs(120));
    assert!(status.success(), "the uninterrupted run: {status:?}\n{err}");
    let total = Summary::from_dir(&whole).expect("summary").tasks.len();
    assert!(total >= 4, "the stub set has tasks enough to stop in the middle: {total}");

    // Interrupt once the first task is finished.
    let child = run(&stopped);
    let deadline = Instant::now() + Duration::from_secs(60);
    while results_below(&stopped) == 0 {
        assert!(Instant::now() < deadline, "no task finished within a minute");
        std::thread::sleep(Duration::from_millis(20));
    }
    let sent = Command::new("kill").args(["-INT", &child.id().to_string()]).status().expect("kill");
    assert!(sent.success());
    let (status, err) = finish(child, Duration::from_secs(60));
    assert_eq!(status.code(), Some(130), "a stopped run exits 130\n{err}");
    assert!(err.contains("interrupted"), "{err}");
    let finished = results_below(&stopped);
    assert!(finished >= 1 && finished < total, "{finished} of {total} finished when stopped");
    let after_stop = Summary::from_dir(&stopped).expect("summary");
    assert!(
        after_stop.tasks.iter().filter(|t| t.score.is_none()).all(|t| t.status == "interrupted"),
        "a task started and not finished is recorded as interrupted: {:?}",
        after_stop.tasks
    );

    // The same command again finishes the job.
    let (status, err) = finish(run(&stopped), Duration::from_secs(120));
    assert!(status.success(), "the resumed run: {status:?}\n{err}");
    let resumed = Summary::from_dir(&stopped).expect("summary");
    let reference = Summary::from_dir(&whole).expect("summary");
    assert_eq!(resumed.outcomes(), reference.outcomes(), "the same outcomes as a run never stopped");
    assert_eq!(resumed.table(), reference.table());
}
