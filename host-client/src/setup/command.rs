//! Command lines for the `launch` and `execute` steps: what argument vector the
//! guest's `/v1/launch` and `/v1/exec` get for a task's `command`, and whether
//! it is a `python -c` invocation the host can translate into input actions.
//!
//! Upstream's guest ran these with Python's `subprocess`: `launch` always
//! through the shell (`cmd /c "<line>"`), `execute` through the shell only with
//! `shell` set, a string command without the shell split with POSIX `shlex`,
//! and elements starting with `~/` expanded. The native API runs an argument
//! vector whose command line the guest builds with `list2cmdline`, so a shell
//! command is sent as `cmd /c` followed by its words: `list2cmdline` of that
//! vector is the very line `cmd.exe` got upstream. Pure and free of I/O.

use arena_guest::cmdline::{list2cmdline, shlex_split};
use arena_shared::script::{python_code_from_argv, python_code_from_command_line};

use crate::task::CommandArg;

/// What an `execute` step sends to the guest.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) enum ExecPlan {
    /// `python -c CODE`: translate `code` into actions; `argv` is the command to
    /// run instead when the code does more than input.
    Python { code: String, argv: Vec<String> },
    /// Any other program.
    Argv(Vec<String>),
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

/// The words of a line `cmd.exe` is to run. A line without double quotes is
/// split on whitespace, which `list2cmdline` joins back into the same line; a
/// line with quotes is kept whole, since `list2cmdline` would escape them for
/// the MSVC runtime, not for `cmd.exe` (a limit of running an argument vector).
fn shell_words(line: &str) -> Vec<String> {
    if line.contains('"') {
        vec![line.to_owned()]
    } else {
        line.split_whitespace().map(str::to_owned).collect()
    }
}

fn through_cmd(words: Vec<String>) -> Vec<String> {
    let mut argv = vec!["cmd".to_owned(), "/c".to_owned()];
    argv.extend(words);
    argv
}

/// The argument vector of a `launch` step.
///
/// Upstream's host splits a string with spaces on whitespace when `shell` is
/// false; its guest forces the shell, expands `~/` words of a list, and turns
/// the word `google-chrome` into `chrome` (the program's name on Windows).
pub(super) fn launch_argv(command: &CommandArg, shell: bool, home: Option<&str>) -> Vec<String> {
    let mut words = match command {
        CommandArg::Str(line) if !shell => line.split_whitespace().map(str::to_owned).collect(),
        CommandArg::Str(line) => shell_words(line),
        CommandArg::List(words) => {
            let mut words = words.clone();
            expand_home(&mut words, home);
            words
        }
    };
    for word in words.iter_mut().filter(|w| *w == "google-chrome") {
        *word = "chrome".to_owned();
    }
    through_cmd(words)
}

/// What an `execute` (or `command`) step sends.
///
/// # Errors
///
/// Python's `shlex` message for a string command that does not split (an
/// unclosed quote), or a command with no words.
pub(super) fn exec_plan(command: &CommandArg, shell: bool, home: Option<&str>) -> Result<ExecPlan, String> {
    if shell {
        let (line, argv) = match command {
            CommandArg::Str(line) => (line.clone(), through_cmd(shell_words(line))),
            CommandArg::List(words) => {
                let mut words = words.clone();
                expand_home(&mut words, home);
                (list2cmdline(&words), through_cmd(words))
            }
        };
        if line.trim().is_empty() {
            return Err("the command is empty".into());
        }
        return Ok(match python_code_from_command_line(&line) {
            Some(code) => ExecPlan::Python { code, argv },
            None => ExecPlan::Argv(argv),
        });
    }
    let mut argv = match command {
        CommandArg::Str(line) => shlex_split(line).map_err(|err| format!("cannot split the command: {err}"))?,
        CommandArg::List(words) => words.clone(),
    };
    expand_home(&mut argv, home);
    if argv.first().is_none_or(|p| p.trim().is_empty()) {
        return Err("the command names no program".into());
    }
    Ok(match python_code_from_argv(&argv) {
        Some(code) => ExecPlan::Python { code: code.to_owned(), argv: argv.clone() },
        None => ExecPlan::Argv(argv),
    })
}

/// The command line an argument vector stands for, for reports.
pub(super) fn display(argv: &[String]) -> String {
    list2cmdline(argv)
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

    #[test]
    fn launch_goes_through_cmd_with_upstream_splitting_and_chrome_renamed() {
        let check = |command: CommandArg, shell: bool, expected: &[&str]| {
            assert_eq!(
                launch_argv(&command, shell, Some(r"C:\Users\Docker")),
                words(expected),
                "{command:?} shell={shell}"
            );
        };
        check(s("vlc"), false, &["cmd", "/c", "vlc"]);
        check(s("start ms-clock://Timers"), false, &["cmd", "/c", "start", "ms-clock://Timers"]);
        check(
            l(&["google-chrome", "--remote-debugging-port=1337", "--force-renderer-accessibility"]),
            false,
            &["cmd", "/c", "chrome", "--remote-debugging-port=1337", "--force-renderer-accessibility"],
        );
        check(l(&["code", "~/project"]), false, &["cmd", "/c", "code", r"C:\Users\Docker/project"]);
        check(s(r#"start "" msedge"#), true, &["cmd", "/c", r#"start "" msedge"#]);
        check(s("calc"), true, &["cmd", "/c", "calc"]);
    }

    #[test]
    fn launch_words_rejoin_into_upstreams_cmd_line() {
        // Upstream ran `cmd /c "<list2cmdline(list)>"`; cmd.exe strips the outer quotes.
        let list = words(&["start", "msedge", "--remote-debugging-port=1337", "https://x.org/a b"]);
        let argv = launch_argv(&CommandArg::List(list.clone()), false, None);
        assert_eq!(display(&argv), format!("cmd /c {}", list2cmdline(&list)));
    }

    #[test]
    fn execute_splits_strings_with_shlex_unless_shell() {
        let check = |command: CommandArg, shell: bool, expected: Result<ExecPlan, &str>| {
            let got = exec_plan(&command, shell, Some(r"C:\Users\Docker"));
            assert_eq!(got, expected.map_err(str::to_owned), "{command:?} shell={shell}");
        };
        check(s(r#"echo "a b" c\ d"#), false, Ok(ExecPlan::Argv(words(&["echo", "a b", "c d"]))));
        check(
            s("taskkill /F /IM soffice.bin"),
            true,
            Ok(ExecPlan::Argv(words(&["cmd", "/c", "taskkill", "/F", "/IM", "soffice.bin"]))),
        );
        check(
            l(&["cmd", "/c", "rmdir", "/s", "/q", r"C:\x", "|", "echo", "Hello World 1", ">", r"C:\h.txt"]),
            false,
            Ok(ExecPlan::Argv(words(&[
                "cmd",
                "/c",
                "rmdir",
                "/s",
                "/q",
                r"C:\x",
                "|",
                "echo",
                "Hello World 1",
                ">",
                r"C:\h.txt",
            ]))),
        );
        check(l(&["ls", "~/Desktop"]), false, Ok(ExecPlan::Argv(words(&["ls", r"C:\Users\Docker/Desktop"]))));
        check(s("echo 'unclosed"), false, Err("cannot split the command: No closing quotation"));
        check(s(""), false, Err("the command names no program"));
        check(s("  "), true, Err("the command is empty"));
    }

    #[test]
    fn python_dash_c_is_recognised_in_every_form() {
        let code = "import pyautogui; pyautogui.hotkey('ctrl', 's')";
        let plan = exec_plan(&l(&["python", "-c", code]), false, None).unwrap();
        assert_eq!(plan, ExecPlan::Python { code: code.into(), argv: words(&["python", "-c", code]) });
        let plan = exec_plan(&s(&format!("python -c \"{code}\"")), false, None).unwrap();
        assert!(matches!(&plan, ExecPlan::Python { code: c, .. } if c == code), "{plan:?}");
        let plan = exec_plan(&s(&format!("python -c \"{code}\"")), true, None).unwrap();
        assert!(matches!(&plan, ExecPlan::Python { code: c, argv } if c == code && argv.len() == 3), "{plan:?}");
        assert!(matches!(exec_plan(&l(&["python", "script.py"]), false, None).unwrap(), ExecPlan::Argv(_)));
    }

    #[test]
    fn home_is_needed_only_for_tilde_words() {
        assert!(needs_home(&l(&["code", "~/x"])));
        assert!(needs_home(&s("ls ~/x")));
        assert!(!needs_home(&l(&["code", "C:\\x~/"])));
    }
}
