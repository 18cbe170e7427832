//! Command lines for the `launch` and `execute` steps: what command the guest's
//! `/v1/launch` and `/v1/exec` get for a task's `command`, and whether it is a
//! `python -c` invocation the host can translate into input actions.
//!
//! Upstream's guest ran these with Python's `subprocess`: `launch` always
//! through the shell (`cmd /c "<line>"`), `execute` through the shell only with
//! `shell` set, a string command without the shell split with POSIX `shlex`,
//! and elements starting with `~/` expanded. A shell command goes to the guest
//! as one line ([`CommandSpec::Shell`]) that reaches `cmd.exe` unchanged, quotes
//! and all, exactly as upstream's `subprocess` built it; the quoting decisions
//! are [`arena_shared::cmdline`]'s, the same the guest's own routes use.
//! Pure and free of I/O.

use arena_script::{python_code_from_argv, python_code_from_command_line, CommandArg as ScriptCommand};
use arena_shared::cmdline::{cmd_arguments, execute_command, list2cmdline, CommandSpec};

use arena_task::CommandArg;

/// What an `execute` step sends to the guest.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) enum ExecPlan {
    /// `python -c CODE`: translate `code` into actions; `command` is what to run
    /// instead when the code does more than input.
    Python { code: String, command: CommandSpec },
    /// Any other program.
    Run(CommandSpec),
}

/// Whether any word of `command` starts with `~/`, so the guest's home folder is needed.
pub(super) fn needs_home(command: &CommandArg) -> bool {
    match command {
        CommandArg::Str(line) => line.split_whitespace().any(|w| w.starts_with("~/")),
        CommandArg::List(words) => words.iter().any(|w| w.starts_with("~/")),
    }
}

/// Python's `os.path.expanduser` of the words that start with `~/` (only those, as upstream).
fn expand_home(words: &mut [String], home: Option<&str>) {
    let Some(home) = home else { return };
    for word in words.iter_mut().filter(|w| w.starts_with("~/")) {
        *word = format!("{home}{}", &word[1..]);
    }
}

/// The command of a `launch` step: always through the shell.
///
/// Upstream's host splits a string with spaces on whitespace when `shell` is
/// false, making it a list; its guest forces the shell, expands `~/` words of a
/// list, and turns the word `google-chrome` into `chrome` (the program's name on
/// Windows), then runs `cmd /c "<list2cmdline(list) or the string>"`.
pub(super) fn launch_command(command: &CommandArg, shell: bool, home: Option<&str>) -> CommandSpec {
    let mut words = match command {
        CommandArg::Str(line) if shell || !line.contains(' ') => return CommandSpec::Shell(line.clone()),
        CommandArg::Str(line) => line.split_whitespace().map(str::to_owned).collect(),
        CommandArg::List(words) => words.clone(),
    };
    expand_home(&mut words, home);
    for word in words.iter_mut().filter(|w| *w == "google-chrome") {
        *word = "chrome".to_owned();
    }
    CommandSpec::Shell(list2cmdline(&words))
}

/// What an `execute` (or `command`) step sends.
///
/// # Errors
///
/// Python's `shlex` message for a string command that does not split (an
/// unclosed quote), or a command with no words.
pub(super) fn exec_plan(command: &CommandArg, shell: bool, home: Option<&str>) -> Result<ExecPlan, String> {
    let arg = match command {
        CommandArg::Str(line) => ScriptCommand::Line(line.clone()),
        CommandArg::List(words) => ScriptCommand::Args(words.clone()),
    };
    let spec = execute_command(&arg, shell, home).map_err(|err| format!("cannot split the command: {err}"))?;
    let code = match &spec {
        CommandSpec::Shell(line) if line.trim().is_empty() => return Err("the command is empty".into()),
        CommandSpec::Shell(line) => python_code_from_command_line(line),
        CommandSpec::Argv(argv) if argv.first().is_none_or(|p| p.trim().is_empty()) => {
            return Err("the command names no program".into())
        }
        CommandSpec::Argv(argv) => python_code_from_argv(argv).map(str::to_owned),
    };
    Ok(match code {
        Some(code) => ExecPlan::Python { code, command: spec },
        None => ExecPlan::Run(spec),
    })
}

/// The command line a command stands for, for reports: what `CreateProcess` gets
/// (the shell's line shown as `cmd /c "<line>"`, as upstream's `subprocess` ran it).
pub(super) fn display(command: &CommandSpec) -> String {
    match command {
        CommandSpec::Argv(argv) => list2cmdline(argv),
        CommandSpec::Shell(line) => format!("cmd {}", cmd_arguments(line)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(line: &str) -> CommandArg {
        CommandArg::Str(line.to_owned())
    }

    fn l(words: &[&str]) -> CommandArg {
        CommandArg::List(words.iter().map(|w| (*w).to_owned()).collect())
    }

    fn words(ws: &[&str]) -> Vec<String> {
        ws.iter().map(|w| (*w).to_owned()).collect()
    }

    fn shell(line: &str) -> CommandSpec {
        CommandSpec::Shell(line.to_owned())
    }

    #[test]
    fn launch_goes_through_the_shell_with_upstream_splitting_and_chrome_renamed() {
        let check = |command: CommandArg, shell_flag: bool, expected: CommandSpec| {
            assert_eq!(
                launch_command(&command, shell_flag, Some(r"C:\Users\Docker")),
                expected,
                "{command:?} shell={shell_flag}"
            );
        };
        check(s("vlc"), false, shell("vlc"));
        check(s("start ms-clock://Timers"), false, shell("start ms-clock://Timers"));
        check(
            l(&["google-chrome", "--remote-debugging-port=1337", "--force-renderer-accessibility"]),
            false,
            shell("chrome --remote-debugging-port=1337 --force-renderer-accessibility"),
        );
        check(l(&["code", "~/project"]), false, shell(r"code C:\Users\Docker/project"));
        // A string with the shell keeps its quotes: cmd.exe reads them as written.
        check(s(r#"start "" msedge"#), true, shell(r#"start "" msedge"#));
        check(s("calc"), true, shell("calc"));
        // A list element with a space is quoted the MSVC way, as list2cmdline does upstream.
        check(l(&["start", "msedge", "https://x.org/a b"]), false, shell(r#"start msedge "https://x.org/a b""#));
    }

    #[test]
    fn execute_splits_strings_with_shlex_unless_shell() {
        let check = |command: CommandArg, shell_flag: bool, expected: Result<ExecPlan, &str>| {
            let got = exec_plan(&command, shell_flag, Some(r"C:\Users\Docker"));
            assert_eq!(got, expected.map_err(str::to_owned), "{command:?} shell={shell_flag}");
        };
        let argv = |ws: &[&str]| ExecPlan::Run(CommandSpec::Argv(words(ws)));
        check(s(r#"echo "a b" c\ d"#), false, Ok(argv(&["echo", "a b", "c d"])));
        check(s("taskkill /F /IM soffice.bin"), true, Ok(ExecPlan::Run(shell("taskkill /F /IM soffice.bin"))));
        // Quotes in a shell string arrive intact (they were mangled when the line was an argv).
        check(
            s(r#"echo "Hello World" > "C:\Users\Docker\a b.txt""#),
            true,
            Ok(ExecPlan::Run(shell(r#"echo "Hello World" > "C:\Users\Docker\a b.txt""#))),
        );
        check(
            l(&["cmd", "/c", "rmdir", "/s", "/q", r"C:\x", "|", "echo", "Hello World 1", ">", r"C:\h.txt"]),
            false,
            Ok(argv(&["cmd", "/c", "rmdir", "/s", "/q", r"C:\x", "|", "echo", "Hello World 1", ">", r"C:\h.txt"])),
        );
        check(l(&["dir", "~/Desktop"]), true, Ok(ExecPlan::Run(shell(r"dir C:\Users\Docker/Desktop"))));
        check(l(&["ls", "~/Desktop"]), false, Ok(argv(&["ls", r"C:\Users\Docker/Desktop"])));
        check(s("echo 'unclosed"), false, Err("cannot split the command: No closing quotation"));
        check(s(""), false, Err("the command names no program"));
        check(s("  "), true, Err("the command is empty"));
    }

    #[test]
    fn python_dash_c_is_recognised_in_every_form() {
        let code = "import pyautogui; pyautogui.hotkey('ctrl', 's')";
        let plan = exec_plan(&l(&["python", "-c", code]), false, None).unwrap();
        assert_eq!(
            plan,
            ExecPlan::Python { code: code.into(), command: CommandSpec::Argv(words(&["python", "-c", code])) }
        );
        let plan = exec_plan(&s(&format!("python -c \"{code}\"")), false, None).unwrap();
        assert!(matches!(&plan, ExecPlan::Python { code: c, .. } if c == code), "{plan:?}");
        let line = format!("python -c \"{code}\"");
        let plan = exec_plan(&s(&line), true, None).unwrap();
        assert_eq!(plan, ExecPlan::Python { code: code.into(), command: shell(&line) });
        assert!(matches!(exec_plan(&l(&["python", "script.py"]), false, None).unwrap(), ExecPlan::Run(_)));
    }

    #[test]
    fn reports_show_the_line_the_guest_runs() {
        assert_eq!(display(&CommandSpec::Argv(words(&["notepad", "a b.txt"]))), r#"notepad "a b.txt""#);
        assert_eq!(display(&shell(r#"echo "x" > y"#)), r#"cmd /c "echo "x" > y""#);
    }

    #[test]
    fn home_is_needed_only_for_tilde_words() {
        assert!(needs_home(&l(&["code", "~/x"])));
        assert!(needs_home(&s("ls ~/x")));
        assert!(!needs_home(&l(&["code", "C:\\x~/"])));
    }
}
