//! Starting and killing programs with `std::process`, as the stub backend does on
//! whatever machine it runs on (Linux in tests, Windows inside `arena-guest.exe`).
//!
//! The two things that differ by platform: how a shell line starts (`sh -c LINE`;
//! on Windows `cmd.exe` with the line as Python's `subprocess` writes it, see
//! [`arena_shared::cmdline::cmd_arguments`]), and how a whole process tree is
//! killed (a process group on Unix, `taskkill /T` on Windows).

use std::process::{Child, Command, Stdio};

/// A command that runs `line` through the platform's shell.
pub(crate) fn shell_command(line: &str) -> Command {
    #[cfg(windows)]
    {
        use std::os::windows::process::CommandExt;
        let comspec = std::env::var("COMSPEC").unwrap_or_else(|_| "cmd.exe".into());
        let mut command = Command::new(comspec);
        // cmd.exe parses its own command line, so the arguments are passed as written.
        command.raw_arg(arena_shared::cmdline::cmd_arguments(line));
        command
    }
    #[cfg(not(windows))]
    {
        let mut command = Command::new("sh");
        command.arg("-c").arg(line);
        command
    }
}

/// Puts the child in its own process group so a timeout can kill everything it started.
pub(crate) fn isolate(command: &mut Command) {
    #[cfg(unix)]
    {
        use std::os::unix::process::CommandExt;
        command.process_group(0);
    }
    #[cfg(not(unix))]
    let _ = command;
}

/// Kills the child and everything it started: its process group on Unix (see
/// [`isolate`]), its process tree on Windows.
pub(crate) fn kill_tree(child: &mut Child) {
    let pid = child.id();
    let quiet =
        |mut command: Command| command.stdin(Stdio::null()).stdout(Stdio::null()).stderr(Stdio::null()).status();
    #[cfg(unix)]
    {
        let mut kill = Command::new("kill");
        kill.args(["-KILL", "--", &format!("-{pid}")]);
        if let Err(err) = quiet(kill) {
            tracing::warn!(pid, %err, "could not run kill for the process group");
        }
    }
    #[cfg(windows)]
    {
        let mut taskkill = Command::new("taskkill");
        taskkill.args(["/T", "/F", "/PID", &pid.to_string()]);
        let _ = quiet(taskkill);
    }
    #[cfg(not(any(unix, windows)))]
    let _ = (pid, quiet);
    let _ = child.kill();
}

#[cfg(all(test, unix))]
mod tests {
    use super::*;

    #[test]
    fn shell_lines_keep_their_quotes() {
        let out = shell_command(r#"printf '%s|' "a b" c"#).output().expect("sh runs");
        assert_eq!(String::from_utf8_lossy(&out.stdout), "a b|c|");
    }
}
