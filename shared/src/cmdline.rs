//! How programs are started, decided once for both sides: Python's `shlex.split`
//! (POSIX mode), `subprocess.list2cmdline` (the MSVC quoting rules), the MSVC
//! runtime's splitting of a command line, what `subprocess.run(cmd, shell=...)`
//! starts on Windows ([`subprocess_command`]), and Python truthiness of JSON values.
//!
//! The guest's `/execute` routes and script host, the host's agent executor and its
//! setup steps all build their commands here, so a command string reaches the
//! guest's process launcher the same way whichever path it took.
//! Platform-neutral and free of I/O. It is not a shell: nothing here expands
//! variables, globs or redirections.

/// A command as a Python caller wrote it for `subprocess` or `os.system`: one
/// string or an argument list. (The interpreter and the `/execute` routes build it;
/// this module owns the type so that it imports nothing from the interpreter.)
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum CommandArg {
    Line(String),
    Args(Vec<String>),
}

/// How to start a program.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum CommandSpec {
    /// Program and arguments, no shell. On Windows the command line is built
    /// with [`list2cmdline`], as Python's `subprocess` builds it.
    Argv(Vec<String>),
    /// A command line given to the shell unchanged: `%COMSPEC% /c "<line>"` on
    /// Windows (Python's `subprocess` with `shell=True`), `sh -c <line>` elsewhere.
    /// Quotes inside the line reach `cmd.exe` as written.
    Shell(String),
}

/// The arguments `cmd.exe` gets for a shell line, as Python's `subprocess` writes
/// them with `shell=True`: `/c "<line>"`. `cmd.exe` strips the outer quotes again
/// (its `/c` rule), so the line runs exactly as written, inner quotes included.
/// Every Windows path that starts a shell line (the Windows backend, the stub
/// running inside the Windows exe) appends this to the shell's program name.
pub fn cmd_arguments(line: &str) -> String {
    format!("/c \"{line}\"")
}

/// What Python's `subprocess.run(cmd, shell=shell)` (and `Popen`, `call`) starts on
/// Windows: with the shell, one command line (a list is joined with
/// [`list2cmdline`] first); without it, an argument vector (a string is the
/// command line `CreateProcess` gets, split as the program's runtime splits it).
pub fn subprocess_command(cmd: &CommandArg, shell: bool) -> CommandSpec {
    match (cmd, shell) {
        (CommandArg::Line(line), true) => CommandSpec::Shell(line.clone()),
        (CommandArg::Args(args), true) => CommandSpec::Shell(list2cmdline(args)),
        (CommandArg::Line(line), false) => CommandSpec::Argv(split_windows_command_line(line)),
        (CommandArg::Args(args), false) => CommandSpec::Argv(args.clone()),
    }
}

/// What upstream's `/execute` route runs for a request's `command` and `shell`:
/// a string without the shell is first split with POSIX [`shlex_split`] (the
/// route's own step), words of a list that start with `~/` are expanded with
/// `home` (Python's `os.path.expanduser`, when the caller knows the home folder),
/// then [`subprocess_command`]. Used by the host's setup steps and getters, which
/// send what upstream's host sent to that route.
///
/// # Errors
///
/// The string does not split (an unclosed quote, a trailing backslash).
pub fn execute_command(cmd: &CommandArg, shell: bool, home: Option<&str>) -> Result<CommandSpec, ShlexError> {
    let mut words = match cmd {
        CommandArg::Line(line) if shell => return Ok(CommandSpec::Shell(line.clone())),
        CommandArg::Line(line) => shlex_split(line)?,
        CommandArg::Args(words) => words.clone(),
    };
    if let Some(home) = home {
        for word in words.iter_mut().filter(|w| w.starts_with("~/")) {
            *word = format!("{home}{}", &word[1..]);
        }
    }
    Ok(subprocess_command(&CommandArg::Args(words), shell))
}

/// Why [`shlex_split`] rejected a string; the messages are Python's `ValueError` texts.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ShlexError {
    /// A `'` or `"` was opened and never closed.
    #[error("No closing quotation")]
    NoClosingQuotation,
    /// The string ends with a lone backslash.
    #[error("No escaped character")]
    NoEscapedCharacter,
}

/// Where the splitter is, as in Python's `shlex` state machine.
#[derive(Clone, Copy, PartialEq, Eq)]
enum State {
    /// Between words.
    Between,
    /// Inside an unquoted word.
    Word,
    /// Inside `'...'` or `"..."`; the char is the quote.
    Quoted(char),
    /// After a backslash; the char is the state to return to (`'a'` for a word, `'"'` inside double quotes).
    Escaped(char),
}

/// Splits `s` like Python's `shlex.split(s)` (POSIX mode, no comments).
///
/// Words are separated by space, tab, CR and LF. `'...'` is literal; inside `"..."` a
/// backslash only escapes `"` and `\`; outside quotes a backslash escapes any character.
/// Quoted empty strings (`''`) are words of their own.
///
/// # Errors
///
/// [`ShlexError::NoClosingQuotation`] for an unterminated quote and
/// [`ShlexError::NoEscapedCharacter`] for a trailing backslash.
pub fn shlex_split(s: &str) -> Result<Vec<String>, ShlexError> {
    let mut words = Vec::new();
    let mut token = String::new();
    // `Word` is only entered once the word exists (a character, an escape or a quote
    // was seen), so a quoted empty string still makes a word.
    let mut state = State::Between;
    for c in s.chars() {
        state = match state {
            State::Between | State::Word => match c {
                ' ' | '\t' | '\r' | '\n' => {
                    if state == State::Word {
                        words.push(std::mem::take(&mut token));
                    }
                    State::Between
                }
                '\\' => State::Escaped('a'),
                '\'' | '"' => State::Quoted(c),
                _ => {
                    token.push(c);
                    State::Word
                }
            },
            State::Quoted(q) => {
                if c == q {
                    State::Word
                } else if c == '\\' && q == '"' {
                    State::Escaped('"')
                } else {
                    token.push(c);
                    State::Quoted(q)
                }
            }
            State::Escaped(back) => {
                // Inside double quotes only `"` and `\` are escapable; any other
                // character keeps the backslash in front of it.
                if back == '"' && c != '"' && c != '\\' {
                    token.push('\\');
                }
                token.push(c);
                if back == '"' {
                    State::Quoted('"')
                } else {
                    State::Word
                }
            }
        };
    }
    match state {
        State::Quoted(_) => Err(ShlexError::NoClosingQuotation),
        State::Escaped(_) => Err(ShlexError::NoEscapedCharacter),
        State::Word => {
            words.push(token);
            Ok(words)
        }
        State::Between => Ok(words),
    }
}

/// Joins arguments into one Windows command line exactly as Python's
/// `subprocess.list2cmdline` does (the MSVC C runtime rules).
///
/// An argument is wrapped in double quotes when it contains a space or tab or is empty;
/// backslashes are doubled only when they precede a double quote (or the closing
/// quote), and embedded double quotes are escaped as `\"`. Shell metacharacters such
/// as `|` and `>` are left unquoted, so `cmd /c` still interprets them.
pub fn list2cmdline(args: &[String]) -> String {
    let mut line = String::new();
    for (i, arg) in args.iter().enumerate() {
        if i > 0 {
            line.push(' ');
        }
        let needs_quotes = arg.is_empty() || arg.contains([' ', '\t']);
        if needs_quotes {
            line.push('"');
        }
        let mut backslashes = 0usize;
        for c in arg.chars() {
            match c {
                '\\' => backslashes += 1,
                '"' => {
                    // The backslashes before a quote are doubled, then the quote is escaped.
                    line.extend(std::iter::repeat_n('\\', backslashes * 2 + 1));
                    line.push('"');
                    backslashes = 0;
                }
                _ => {
                    line.extend(std::iter::repeat_n('\\', backslashes));
                    backslashes = 0;
                    line.push(c);
                }
            }
        }
        // Trailing backslashes are doubled only when a closing quote follows them.
        let trailing = if needs_quotes { backslashes * 2 } else { backslashes };
        line.extend(std::iter::repeat_n('\\', trailing));
        if needs_quotes {
            line.push('"');
        }
    }
    line
}

/// Splits a Windows command line the way the MSVC runtime builds `argv`:
/// the program name ends at the first space (or closing quote, with no escapes);
/// later arguments are separated by spaces or tabs outside quotes; `2n` backslashes
/// before `"` give `n` backslashes and a quote toggle, `2n+1` give `n` and a literal
/// `"`; other backslashes are literal; `""` inside quotes is a literal `"`.
pub fn split_windows_command_line(line: &str) -> Vec<String> {
    let chars: Vec<char> = line.chars().collect();
    let mut args = Vec::new();
    let mut i = 0;
    while i < chars.len() && matches!(chars[i], ' ' | '\t') {
        i += 1;
    }
    if i >= chars.len() {
        return args;
    }
    // The program name.
    let mut program = String::new();
    if chars[i] == '"' {
        i += 1;
        while i < chars.len() && chars[i] != '"' {
            program.push(chars[i]);
            i += 1;
        }
        i += 1;
    } else {
        while i < chars.len() && !matches!(chars[i], ' ' | '\t') {
            program.push(chars[i]);
            i += 1;
        }
    }
    args.push(program);
    loop {
        while i < chars.len() && matches!(chars[i], ' ' | '\t') {
            i += 1;
        }
        if i >= chars.len() {
            return args;
        }
        let mut arg = String::new();
        let mut quoted = false;
        while i < chars.len() {
            let c = chars[i];
            if c == '\\' {
                let start = i;
                while i < chars.len() && chars[i] == '\\' {
                    i += 1;
                }
                let n = i - start;
                if i < chars.len() && chars[i] == '"' {
                    arg.extend(std::iter::repeat_n('\\', n / 2));
                    if n % 2 == 1 {
                        arg.push('"');
                        i += 1;
                    }
                } else {
                    arg.extend(std::iter::repeat_n('\\', n));
                }
                continue;
            }
            if c == '"' {
                if quoted && chars.get(i + 1) == Some(&'"') {
                    arg.push('"');
                    i += 2;
                    continue;
                }
                quoted = !quoted;
                i += 1;
                continue;
            }
            if !quoted && matches!(c, ' ' | '\t') {
                break;
            }
            arg.push(c);
            i += 1;
        }
        args.push(arg);
    }
}

/// Python truthiness of a JSON value: `null`, `false`, `0`, `0.0`, `""`, `[]` and `{}`
/// are false, everything else (including the string `"false"`) is true.
pub fn truthy(value: &serde_json::Value) -> bool {
    use serde_json::Value;
    match value {
        Value::Null => false,
        Value::Bool(b) => *b,
        Value::Number(n) => {
            if let Some(i) = n.as_i64() {
                i != 0
            } else if let Some(u) = n.as_u64() {
                u != 0
            } else {
                n.as_f64().is_some_and(|f| f != 0.0)
            }
        }
        Value::String(s) => !s.is_empty(),
        Value::Array(a) => !a.is_empty(),
        Value::Object(o) => !o.is_empty(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn check(input: &str, expected: &[&str]) {
        assert_eq!(
            shlex_split(input).as_deref(),
            Ok(&expected.iter().map(|s| s.to_string()).collect::<Vec<_>>()[..]),
            "splitting {input:?}"
        );
    }

    #[test]
    fn shlex_splits_like_python_posix() {
        check("", &[]);
        check("   \t\n ", &[]);
        check("a b  c", &["a", "b", "c"]);
        check("'a b' c", &["a b", "c"]);
        check(r#""a b" c"#, &["a b", "c"]);
        check(r#"a"b c"d"#, &["ab cd"]);
        check("''", &[""]);
        check(r#""""#, &[""]);
        check("a '' b", &["a", "", "b"]);
        check("a''", &["a"]);
        check(r"a\ b", &["a b"]);
        check(r"C:\Users\Docker", &["C:UsersDocker"]);
        check(r#""C:\Users\Docker""#, &[r"C:\Users\Docker"]);
        check(r"'C:\Users\Docker'", &[r"C:\Users\Docker"]);
        check(r#""a\"b""#, &[r#"a"b"#]);
        check(r#""a\\b""#, &[r"a\b"]);
        check(r#""a\nb""#, &[r"a\nb"]);
        check(r"'a\'", &[r"a\"]);
        check(r"\'", &["'"]);
        check("a\\\nb", &["a\nb"]);
        check("# not a comment", &["#", "not", "a", "comment"]);
        check("héllo wörld", &["héllo", "wörld"]);
        check(
            r#"powershell -Command "Get-ItemPropertyValue -Path 'HKCU:\Control Panel\Desktop' -Name 'Wallpaper'""#,
            &["powershell", "-Command", r"Get-ItemPropertyValue -Path 'HKCU:\Control Panel\Desktop' -Name 'Wallpaper'"],
        );
    }

    #[test]
    fn shlex_reports_python_errors() {
        assert_eq!(shlex_split("'abc"), Err(ShlexError::NoClosingQuotation));
        assert_eq!(shlex_split(r#"a "b"#), Err(ShlexError::NoClosingQuotation));
        assert_eq!(shlex_split(r#""a\""#), Err(ShlexError::NoClosingQuotation));
        assert_eq!(shlex_split("abc\\"), Err(ShlexError::NoEscapedCharacter));
        assert_eq!(ShlexError::NoClosingQuotation.to_string(), "No closing quotation");
        assert_eq!(ShlexError::NoEscapedCharacter.to_string(), "No escaped character");
    }

    fn line(args: &[&str]) -> String {
        list2cmdline(&args.iter().map(|s| s.to_string()).collect::<Vec<_>>())
    }

    #[test]
    fn list2cmdline_matches_python() {
        assert_eq!(line(&[]), "");
        assert_eq!(line(&["a", "b"]), "a b");
        assert_eq!(line(&[""]), r#""""#);
        assert_eq!(line(&["a b"]), r#""a b""#);
        assert_eq!(line(&["a\tb"]), "\"a\tb\"");
        assert_eq!(line(&[r#"a"b"#]), r#"a\"b"#);
        assert_eq!(line(&[r#"a\"b"#]), r#"a\\\"b"#);
        assert_eq!(line(&[r"a\b"]), r"a\b");
        assert_eq!(line(&[r"a\\b"]), r"a\\b");
        assert_eq!(line(&[r"a\"]), r"a\");
        assert_eq!(line(&[r"a b\"]), r#""a b\\""#);
        assert_eq!(line(&[r"C:\Program Files\x\"]), r#""C:\Program Files\x\\""#);
        assert_eq!(line(&["|", ">", "&&"]), "| > &&");
        assert_eq!(
            line(&["python", "-c", "import pyautogui; pyautogui.press('a')"]),
            r#"python -c "import pyautogui; pyautogui.press('a')""#
        );
    }

    #[test]
    fn list2cmdline_builds_the_cmd_chain_of_the_corpus() {
        // waa-api.md §d.2: metacharacters stay bare so cmd interprets them,
        // and the echoed text keeps its quotes.
        assert_eq!(
            line(&[
                "cmd",
                "/c",
                "rmdir",
                "/s",
                "/q",
                r"C:\Users\Docker\Pictures\Photos",
                "|",
                "mkdir",
                r"C:\Users\Docker\Pictures\Photos",
                "|",
                "echo",
                "Hello World 1",
                ">",
                r"C:\Users\Docker\Pictures\Photos\HelloWorld1.txt",
            ]),
            r#"cmd /c rmdir /s /q C:\Users\Docker\Pictures\Photos | mkdir C:\Users\Docker\Pictures\Photos | echo "Hello World 1" > C:\Users\Docker\Pictures\Photos\HelloWorld1.txt"#
        );
    }

    #[test]
    fn splits_windows_command_lines() {
        let check = |line: &str, expected: &[&str]| {
            assert_eq!(
                split_windows_command_line(line),
                expected.iter().map(|s| s.to_string()).collect::<Vec<_>>(),
                "{line}"
            )
        };
        check(r#"python -c "import os; print(1)""#, &["python", "-c", "import os; print(1)"]);
        check(r#""C:\Program Files\py.exe" a"#, &[r"C:\Program Files\py.exe", "a"]);
        check(r#"p a\\b "c\"d" e\\\"f "g\\" h"#, &["p", r"a\\b", r#"c"d"#, r#"e\"f"#, r"g\", "h"]);
        check(r#"p "a""b" c"#, &["p", r#"a"b"#, "c"]);
        check("  p   a\tb  ", &["p", "a", "b"]);
        check("", &[]);
    }

    #[test]
    fn shell_lines_reach_cmd_as_python_writes_them() {
        assert_eq!(cmd_arguments("dir"), r#"/c "dir""#);
        assert_eq!(cmd_arguments(r#"echo "a b" > "x y.txt""#), r#"/c "echo "a b" > "x y.txt"""#);
    }

    #[test]
    fn subprocess_commands_follow_python_on_windows() {
        let check = |cmd: CommandArg, shell: bool, expected: CommandSpec| {
            assert_eq!(subprocess_command(&cmd, shell), expected, "{cmd:?} shell={shell}");
        };
        let words = |w: &[&str]| w.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        // A shell line keeps its quotes exactly: cmd.exe reads them, not the MSVC runtime.
        let quoted = r#"echo "a b" > "C:\Users\Docker\x y.txt""#;
        check(CommandArg::Line(quoted.into()), true, CommandSpec::Shell(quoted.into()));
        check(
            CommandArg::Args(words(&["echo", "a b", "|", "more"])),
            true,
            CommandSpec::Shell(r#"echo "a b" | more"#.into()),
        );
        check(
            CommandArg::Line(r#""C:\Program Files\x.exe" -v "a\"b""#.into()),
            false,
            CommandSpec::Argv(words(&[r"C:\Program Files\x.exe", "-v", r#"a"b"#])),
        );
        check(
            CommandArg::Args(words(&["notepad", "a b.txt"])),
            false,
            CommandSpec::Argv(words(&["notepad", "a b.txt"])),
        );
    }

    #[test]
    fn execute_commands_follow_upstreams_route() {
        let words = |w: &[&str]| w.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        let home = Some(r"C:\Users\Docker");
        let check = |cmd: CommandArg, shell: bool, expected: Result<CommandSpec, ShlexError>| {
            assert_eq!(execute_command(&cmd, shell, home), expected, "{cmd:?} shell={shell}");
        };
        check(
            CommandArg::Line(r#"echo "a b" c\ d"#.into()),
            false,
            Ok(CommandSpec::Argv(words(&["echo", "a b", "c d"]))),
        );
        check(CommandArg::Line(r#"echo "a b" > x"#.into()), true, Ok(CommandSpec::Shell(r#"echo "a b" > x"#.into())));
        check(
            CommandArg::Args(words(&["dir", "~/Desktop", "a b"])),
            true,
            Ok(CommandSpec::Shell(r#"dir C:\Users\Docker/Desktop "a b""#.into())),
        );
        check(
            CommandArg::Args(words(&["ls", "~/x", "x~/"])),
            false,
            Ok(CommandSpec::Argv(words(&["ls", r"C:\Users\Docker/x", "x~/"]))),
        );
        // A shell string is not split, so a `~/` inside it stays as written.
        check(CommandArg::Line("dir ~/x".into()), true, Ok(CommandSpec::Shell("dir ~/x".into())));
        check(CommandArg::Line("echo 'open".into()), false, Err(ShlexError::NoClosingQuotation));
    }

    #[test]
    fn truthiness_follows_python() {
        for falsy in [json!(null), json!(false), json!(0), json!(0.0), json!(-0.0), json!(""), json!([]), json!({})] {
            assert!(!truthy(&falsy), "{falsy} should be falsy");
        }
        for truthy_value in [
            json!(true),
            json!(1),
            json!(-1),
            json!(0.5),
            json!("false"),
            json!("0"),
            json!([0]),
            json!({"a": null}),
            json!(u64::MAX),
        ] {
            assert!(truthy(&truthy_value), "{truthy_value} should be truthy");
        }
    }

    proptest::proptest! {
        #[test]
        fn shlex_never_panics(s in "[a-z '\"\\\\\t\n#|>é]{0,32}") {
            let _ = shlex_split(&s);
        }

        #[test]
        fn list2cmdline_never_panics(args in proptest::collection::vec("[a-z \"\\\\\t]{0,8}", 0..5)) {
            let _ = list2cmdline(&args);
        }

        /// Quoting simple words with shlex-safe characters and splitting them back is the identity.
        #[test]
        fn single_quoting_round_trips(args in proptest::collection::vec("[a-zA-Z0-9 \"\\\\.:-]{0,10}", 0..5)) {
            let line: Vec<String> = args.iter().map(|a| format!("'{a}'")).collect();
            proptest::prop_assert_eq!(shlex_split(&line.join(" ")), Ok(args));
        }
    }
}
