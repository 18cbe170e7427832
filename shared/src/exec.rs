//! Running programs in the guest.

use serde::{Deserialize, Serialize};

use crate::cmdline::CommandSpec;

/// Body of `POST /v1/exec`: run a program from an argument vector, or one command
/// line through the guest's shell.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ExecRequest {
    /// Program and arguments; `argv[0]` is looked up on the guest's `PATH`.
    /// Empty when `shell` is given.
    #[serde(default)]
    pub argv: Vec<String>,
    /// A command line run through the shell unchanged (`cmd.exe /c "<line>"` on
    /// Windows, as Python's `subprocess` with `shell=True`); `argv` must then be empty.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shell: Option<String>,
    /// Kill the process (tree) after this long; the guest caps it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub timeout_ms: Option<u64>,
    /// Keep at most this many bytes of each of stdout and stderr.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_output_bytes: Option<u64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cwd: Option<String>,
    /// Bytes written to the program's standard input.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stdin: Option<String>,
}

/// What a finished program left behind.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ExecResult {
    /// Exit code; `None` when it was killed (timeout or signal).
    pub exit_code: Option<i32>,
    pub stdout: String,
    pub stderr: String,
    #[serde(default)]
    pub stdout_truncated: bool,
    #[serde(default)]
    pub stderr_truncated: bool,
    #[serde(default)]
    pub timed_out: bool,
    pub duration_ms: u64,
}

/// Body of `POST /v1/launch`: start a program and do not wait for it.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct LaunchRequest {
    /// Program and arguments; empty when `shell` is given.
    #[serde(default)]
    pub argv: Vec<String>,
    /// A command line run through the shell unchanged, as in [`ExecRequest::shell`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shell: Option<String>,
}

/// Which program a request names: its argument vector or its shell line, exactly one.
///
/// # Errors
///
/// A message naming the problem: neither given, both given, an empty program, or a NUL
/// character anywhere.
fn command_of(argv: &[String], shell: Option<&str>) -> Result<CommandSpec, String> {
    // No program can receive a NUL: the operating system's command line ends there.
    if let Some(i) = argv.iter().position(|a| a.contains('\0')) {
        return Err(format!("argv[{i}] contains a NUL character, which no command line can carry"));
    }
    if shell.is_some_and(|line| line.contains('\0')) {
        return Err("shell contains a NUL character, which no command line can carry".into());
    }
    match (argv.first(), shell) {
        (Some(_), Some(_)) => Err("give either argv or shell, not both".into()),
        (None, None) => Err("argv must name a program, or shell give a command line".into()),
        (None, Some(line)) if line.trim().is_empty() => Err("shell must not be empty".into()),
        (None, Some(line)) => Ok(CommandSpec::Shell(line.to_owned())),
        (Some(program), None) if program.trim().is_empty() => Err("argv[0] must not be empty".into()),
        (Some(_), None) => Ok(CommandSpec::Argv(argv.to_vec())),
    }
}

impl ExecRequest {
    /// A request to run `command` with the guest's default limits.
    pub fn new(command: CommandSpec) -> ExecRequest {
        let (argv, shell) = split_command(command);
        ExecRequest { argv, shell, ..ExecRequest::default() }
    }

    /// The command this request names.
    ///
    /// # Errors
    ///
    /// See [`command_of`]: neither or both of `argv` and `shell`, or an empty program.
    pub fn command(&self) -> Result<CommandSpec, String> {
        command_of(&self.argv, self.shell.as_deref())
    }
}

impl LaunchRequest {
    /// A request to start `command`.
    pub fn new(command: CommandSpec) -> LaunchRequest {
        let (argv, shell) = split_command(command);
        LaunchRequest { argv, shell }
    }

    /// The command this request names.
    ///
    /// # Errors
    ///
    /// Neither or both of `argv` and `shell`, or an empty program.
    pub fn command(&self) -> Result<CommandSpec, String> {
        command_of(&self.argv, self.shell.as_deref())
    }
}

fn split_command(command: CommandSpec) -> (Vec<String>, Option<String>) {
    match command {
        CommandSpec::Argv(argv) => (argv, None),
        CommandSpec::Shell(line) => (Vec::new(), Some(line)),
    }
}

/// A started program.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LaunchResult {
    pub pid: u32,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_request_names_exactly_one_usable_command() {
        let argv = |w: &[&str]| w.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        let check = |argv: Vec<String>, shell: Option<&str>, expected: Result<CommandSpec, &str>| {
            let request = ExecRequest { argv: argv.clone(), shell: shell.map(str::to_owned), ..ExecRequest::default() };
            match (request.command(), expected) {
                (Ok(got), Ok(want)) => assert_eq!(got, want),
                (Err(got), Err(needle)) => assert!(got.contains(needle), "{got}"),
                (got, want) => panic!("{argv:?} {shell:?}: got {got:?}, want {want:?}"),
            }
        };
        check(argv(&["notepad", "a.txt"]), None, Ok(CommandSpec::Argv(argv(&["notepad", "a.txt"]))));
        check(Vec::new(), Some("dir"), Ok(CommandSpec::Shell("dir".into())));
        check(argv(&["dir"]), Some("dir"), Err("not both"));
        check(Vec::new(), None, Err("argv must name a program"));
        check(argv(&[" "]), None, Err("argv[0] must not be empty"));
        check(Vec::new(), Some("  "), Err("shell must not be empty"));
        check(argv(&["echo", "a\0b"]), None, Err("argv[1] contains a NUL"));
        check(Vec::new(), Some("echo \0"), Err("shell contains a NUL"));
    }
}
