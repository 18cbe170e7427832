//! An exec agent's processes end with it. On Unix the agent starts in a process
//! group of its own; ending it ends that group, every process descending from
//! the agent (found through `/proc` on Linux, so a child that left the group or
//! started a new session goes too) and the groups those lead. On Windows the
//! agent starts suspended, is put in a job object of its own
//! (`JOB_OBJECT_LIMIT_KILL_ON_JOB_CLOSE`, see [`super::windows`]) and only then
//! runs; ending it terminates the job, which holds everything it started,
//! detached processes and new consoles included, and the system closes the job
//! (ending them too) if this program dies first. The agents of a run are
//! registered here, so that an exit that skips destructors (a second Ctrl-C)
//! can end them all ([`end_all`]).
//!
//! Not covered: on Unix, a process that double-forks away from a dead parent and
//! out of the agent's group before the end (no ancestry is left to follow
//! without cgroups).

use std::sync::Mutex;

/// What ends one agent's processes besides its pid: nothing more on Unix (the
/// pid leads its group), its job object on Windows.
#[cfg(unix)]
type Hold = ();
#[cfg(not(unix))]
type Hold = super::windows::Job;

/// The agents running now, by pid.
static LIVE: Mutex<Vec<(u32, Hold)>> = Mutex::new(Vec::new());

/// Prepares the agent's command: a process group of its own (Unix); created
/// suspended, to be resumed inside its job by [`register`] (Windows).
pub fn own_group(command: &mut tokio::process::Command) {
    #[cfg(unix)]
    command.process_group(0);
    #[cfg(not(unix))]
    super::windows::start_suspended(command);
}

/// Registers the agent just started from a command [`own_group`] prepared,
/// for [`end`] and [`end_all`], and answers its pid. On Windows this puts it
/// in its job object and lets it run.
///
/// # Errors
///
/// Windows: the job object cannot be made or the process put in it (the process
/// is then killed: better no agent than one whose children could outlive it).
pub fn register(child: &mut tokio::process::Child) -> Result<u32, String> {
    let pid = child.id().unwrap_or_default();
    let entry = (pid, hold(child)?);
    if let Ok(mut live) = LIVE.lock() {
        live.push(entry);
    }
    Ok(pid)
}

#[cfg(unix)]
fn hold(_child: &mut tokio::process::Child) -> Result<Hold, String> {
    Ok(())
}

#[cfg(not(unix))]
fn hold(child: &mut tokio::process::Child) -> Result<Hold, String> {
    super::windows::Job::adopt(child)
}

/// Ends the agent `pid` with everything it started, and forgets it; once only
/// (after that the number may name another process).
pub fn end(pid: u32) {
    let found = LIVE.lock().ok().and_then(|mut live| {
        let at = live.iter().position(|&(p, _)| p == pid)?;
        Some(live.swap_remove(at))
    });
    if let Some((pid, hold)) = found {
        end_tree(pid, hold);
    }
}

/// Ends every registered agent with everything it started.
pub fn end_all() {
    let live = LIVE.lock().map(|mut live| std::mem::take(&mut *live)).unwrap_or_default();
    for (pid, hold) in live {
        end_tree(pid, hold);
    }
}

#[cfg(unix)]
fn end_tree(pid: u32, (): Hold) {
    use rustix::process::{getpgid, getpgrp, kill_process, kill_process_group, Pid, Signal};
    let Some(leader) = i32::try_from(pid).ok().and_then(Pid::from_raw) else { return };
    if leader.is_init() {
        return;
    }
    // This program's own group is never signalled.
    let ours = getpgrp();
    // Twice: a process forked while the first round ran is found by the second.
    // Errors are processes already gone.
    for _ in 0..2 {
        let below = descendants(leader.as_raw_nonzero().get());
        if leader != ours {
            let _ = kill_process_group(leader, Signal::KILL);
        }
        for p in below.into_iter().filter_map(Pid::from_raw) {
            let group = getpgid(Some(p));
            let _ = kill_process(p, Signal::KILL);
            if let Ok(group) = group {
                if !group.is_init() && group != ours {
                    let _ = kill_process_group(group, Signal::KILL);
                }
            }
        }
    }
}

/// Terminates the job (and closes it, as `job` drops).
#[cfg(not(unix))]
fn end_tree(_pid: u32, job: Hold) {
    job.end();
}

/// Every process below `root`, by the parent each names in `/proc/PID/stat`
/// (empty where there is no `/proc`). Read by hand: a dozen lines, where the
/// `procfs` crate would add a dependency tree for one field.
#[cfg(unix)]
fn descendants(root: i32) -> Vec<i32> {
    let Ok(entries) = std::fs::read_dir("/proc") else { return Vec::new() };
    let mut parents: Vec<(i32, i32)> = Vec::new();
    for entry in entries.flatten() {
        let Some(pid) = entry.file_name().to_str().and_then(|s| s.parse::<i32>().ok()) else { continue };
        let Ok(stat) = std::fs::read_to_string(entry.path().join("stat")) else { continue };
        // "PID (COMM) STATE PPID ...": the name may hold spaces and parentheses.
        let Some(after) = stat.rfind(')').map(|i| &stat[i + 1..]) else { continue };
        if let Some(ppid) = after.split_whitespace().nth(1).and_then(|s| s.parse().ok()) {
            parents.push((pid, ppid));
        }
    }
    let mut found = vec![root];
    let mut i = 0;
    while i < found.len() {
        let parent = found[i];
        found.extend(parents.iter().filter(|&&(_, pp)| pp == parent).map(|&(p, _)| p));
        i += 1;
    }
    found.remove(0);
    found
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    use super::*;

    fn alive(pid: u32) -> bool {
        std::fs::read_to_string(format!("/proc/{pid}/stat"))
            .ok()
            .and_then(|stat| stat.rfind(')').map(|i| stat[i + 1..].trim_start().starts_with('Z')))
            .is_some_and(|zombie| !zombie)
    }

    #[tokio::test]
    async fn a_group_and_a_new_session_below_the_agent_end_with_it() {
        let script = "sleep 1000 & setsid sleep 1000 & echo $! $!; wait";
        let mut command = tokio::process::Command::new("sh");
        command.args(["-c", script]).stdout(std::process::Stdio::piped()).kill_on_drop(true);
        own_group(&mut command);
        let mut child = command.spawn().expect("sh starts");
        let pid = register(&mut child).expect("registered");
        let mut line = String::new();
        let stdout = child.stdout.take().expect("stdout");
        tokio::io::AsyncBufReadExt::read_line(&mut tokio::io::BufReader::new(stdout), &mut line).await.expect("a line");
        let below = descendants(i32::try_from(pid).expect("pid"));
        assert!(below.len() >= 2, "two sleeps below the shell: {below:?}");
        end(pid);
        let _ = child.wait().await;
        for p in below {
            let p = u32::try_from(p).expect("pid");
            // SIGKILL is delivered before kill(2) returns; the exit follows at once.
            for _ in 0..200 {
                if !alive(p) {
                    break;
                }
                tokio::time::sleep(std::time::Duration::from_millis(5)).await;
            }
            assert!(!alive(p), "{p} outlived its agent");
        }
    }
}
