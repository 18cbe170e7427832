//! A child dies with us: every process the host side starts (QEMU, swtpm,
//! `qemu-img`, an exec agent and whatever it starts) ends when this program
//! ends, however it ends. This module is the only place on the host side with
//! system calls of its own: `unsafe`, `rustix` and `windows-sys` are used here
//! and nowhere else, so the crates above it forbid `unsafe` outright.
//!
//! - VMs' helpers (this file): on Linux a child started with
//!   [`die_with_this_process`] gets SIGKILL when the thread that started it
//!   ends (`PR_SET_PDEATHSIG`, prctl(2)); and the few plain calls the VM code
//!   needs ([`kill`], [`effective_uid`], [`writable`]).
//! - [`tree`]: an exec agent's process tree: a process group (Unix) or a job
//!   object (Windows, [`windows`]) of its own, ended as a whole.

pub mod tree;
pub mod windows;

use std::path::Path;

/// Makes the child `command` starts (QEMU, swtpm) end with this program even
/// when it is killed outright, so no VM outlives the run that owns it. (The
/// signal follows the thread that started the child: a runtime worker, which
/// lives as long as the runtime.)
pub fn die_with_this_process(command: &mut tokio::process::Command) {
    die_with_this_process_std(command.as_std_mut());
}

/// [`die_with_this_process`] for a child run to its end (`qemu-img`, `xorriso`):
/// the thread that starts it waits for it, so the signal comes exactly when
/// this program dies. Without it a `qemu-img` of a killed prepare runs on and
/// keeps the disk's lock, and the rerun cannot open the disk.
pub fn die_with_this_process_std(command: &mut std::process::Command) {
    #[cfg(target_os = "linux")]
    {
        use std::os::unix::process::CommandExt;
        #[allow(unsafe_code)]
        // SAFETY: the hook runs in the child between fork and exec and only makes
        // two system calls (prctl and getppid, through rustix's raw syscalls), which
        // are async-signal-safe, and allocates nothing.
        unsafe {
            command.pre_exec(parent_death_hook());
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = command;
}

/// The child's side: SIGKILL when the parent dies (`PR_SET_PDEATHSIG`, prctl(2)),
/// and a refusal to start when the parent already died between fork and prctl
/// (then no signal would ever come: the child has been handed to another parent).
#[cfg(target_os = "linux")]
fn parent_death_hook() -> impl FnMut() -> std::io::Result<()> + Send + Sync + 'static {
    use rustix::process::{getppid, set_parent_process_death_signal, Signal};
    let parent = std::process::id();
    move || {
        set_parent_process_death_signal(Some(Signal::KILL))?;
        if getppid().map(|p| p.as_raw_nonzero().get()).and_then(|p| u32::try_from(p).ok()) != Some(parent) {
            return Err(rustix::io::Errno::SRCH.into());
        }
        Ok(())
    }
}

/// Sends SIGKILL to `pid` (Unix; elsewhere nothing). An error (the process is
/// gone, or not ours) is ignored: the caller only wants it gone.
pub fn kill(pid: u32) {
    #[cfg(unix)]
    if let Some(pid) = i32::try_from(pid).ok().and_then(rustix::process::Pid::from_raw) {
        let _ = rustix::process::kill_process(pid, rustix::process::Signal::KILL);
    }
    #[cfg(not(unix))]
    let _ = pid;
}

/// This process's effective user id (Unix).
#[cfg(unix)]
pub fn effective_uid() -> u32 {
    rustix::process::geteuid().as_raw()
}

/// Whether this process may write `path` (access(2) with `W_OK`, which also
/// says no for root on a read-only mount); `None` where there is no such call.
pub fn writable(path: &Path) -> Option<bool> {
    #[cfg(unix)]
    {
        Some(rustix::fs::access(path, rustix::fs::Access::WRITE_OK).is_ok())
    }
    #[cfg(not(unix))]
    {
        let _ = path;
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    /// A child started with the hook (as prepare starts `qemu-img`) dies when the
    /// process that started it ends: this test runs itself again as that parent.
    #[cfg(target_os = "linux")]
    #[test]
    fn a_child_started_with_the_hook_dies_with_its_parent() {
        const PARENT: &str = "ARENA_TEST_PARENT_DEATH_PIDFILE";
        if let Some(pidfile) = std::env::var_os(PARENT) {
            let mut command = std::process::Command::new("sleep");
            command
                .arg("600")
                .stdin(std::process::Stdio::null())
                .stdout(std::process::Stdio::null())
                .stderr(std::process::Stdio::null());
            die_with_this_process_std(&mut command);
            let child = command.spawn().expect("sleep starts");
            std::fs::write(pidfile, child.id().to_string()).expect("pid written");
            // Not waited for: the parent ends with the child still running.
            std::mem::forget(child);
            return;
        }
        let dir = tempfile::tempdir().expect("dir");
        let pidfile = dir.path().join("pid");
        let status = std::process::Command::new(std::env::current_exe().expect("the test binary"))
            .args(["--exact", "child::tests::a_child_started_with_the_hook_dies_with_its_parent", "--test-threads=1"])
            .env(PARENT, &pidfile)
            .stdin(std::process::Stdio::null())
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .status()
            .expect("the parent runs");
        assert!(status.success(), "{status}");
        let pid: u32 = std::fs::read_to_string(&pidfile).expect("pid").trim().parse().expect("a pid");
        // Gone, or a zombie waiting for its new parent to reap it: either way dead.
        let running = || {
            std::fs::read_to_string(format!("/proc/{pid}/status"))
                .ok()
                .and_then(|s| s.lines().find(|l| l.starts_with("State:")).map(|l| !l.contains('Z')))
                .unwrap_or(false)
        };
        let until = std::time::Instant::now() + Duration::from_secs(10);
        while running() && std::time::Instant::now() < until {
            std::thread::sleep(Duration::from_millis(20));
        }
        let alive = running();
        if alive {
            kill(pid);
        }
        assert!(!alive, "sleep {pid} outlived the process that started it");
    }
}
