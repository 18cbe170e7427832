//! Command-line handling with the exact semantics of the Python functions upstream WAA
//! hosts depend on: `shlex.split` (POSIX mode), `subprocess.list2cmdline` (the MSVC
//! quoting rules) and Python truthiness of JSON values.
//!
//! Platform-neutral and free of I/O: the `/execute` route builds command lines with
//! these and hands them to the backend. It is not a shell: nothing here expands
//! variables, globs or redirections.

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
