//! Recognising `python -c CODE` invocations, so that the guest can run the
//! code with this interpreter instead of a Python it does not have.
//!
//! [`python_code_from_argv`] takes an argument list (what `/execute` gets as a
//! JSON list, or after upstream's `shlex.split` of a string with `shell=False`).
//! [`python_code_from_command_line`] takes one Windows command line (a string
//! with `shell=True`, which `cmd.exe /c` would run) and splits it with the MSVC
//! runtime's rules, as `python.exe` itself would.
//! Anything else (a script path, `-m module`, stdin, cmd.exe syntax) is `None`:
//! not a program this interpreter can stand in for.

use arena_shared::cmdline::split_windows_command_line;

/// Whether `program` names a Python interpreter: `python`, `python3`, `python3.10`,
/// `pythonw`, `py` or `pyw`, with or without a directory and `.exe`, in any case.
pub fn is_python_program(program: &str) -> bool {
    let base = program.rsplit(['/', '\\']).next().unwrap_or(program).to_ascii_lowercase();
    let base = base.strip_suffix(".exe").unwrap_or(&base);
    if base == "py" || base == "pyw" {
        return true;
    }
    let Some(rest) = base.strip_prefix("python") else { return false };
    let rest = rest.strip_suffix('w').unwrap_or(rest);
    // An optional version: `3`, `3.10`.
    let mut parts = rest.split('.');
    let major_ok = parts.next().is_some_and(|m| m.is_empty() || m.chars().all(|c| c.is_ascii_digit()));
    let rest_ok = parts.all(|p| !p.is_empty() && p.chars().all(|c| c.is_ascii_digit()));
    major_ok && rest_ok && !(rest.starts_with('.'))
}

/// The program text of `python [flags] -c CODE [args...]`, or `None` when `argv` is
/// not such an invocation. Flags before `-c` may be combined (`-uBc`), and `-X opt`
/// or `-W arg` take an argument; for the `py` launcher a version selector such as
/// `-3` or `-3.10` is skipped.
pub fn python_code_from_argv(argv: &[String]) -> Option<&str> {
    let program = argv.first()?;
    if !is_python_program(program) {
        return None;
    }
    let is_launcher = {
        let base = program.rsplit(['/', '\\']).next().unwrap_or(program).to_ascii_lowercase();
        matches!(base.strip_suffix(".exe").unwrap_or(&base), "py" | "pyw")
    };
    let mut i = 1;
    while let Some(arg) = argv.get(i) {
        if arg == "-" || !arg.starts_with('-') || arg.starts_with("--") {
            return None;
        }
        if is_launcher && i == 1 && is_version_selector(arg) {
            i += 1;
            continue;
        }
        let flags = &arg[1..];
        let mut takes_next = false;
        for (k, c) in flags.char_indices() {
            let rest = &flags[k + c.len_utf8()..];
            match c {
                'c' => return if rest.is_empty() { argv.get(i + 1).map(String::as_str) } else { Some(rest) },
                'W' | 'X' => {
                    takes_next = rest.is_empty();
                    break;
                }
                'b' | 'B' | 'd' | 'E' | 'i' | 'I' | 'O' | 'q' | 's' | 'S' | 'u' | 'v' | 'x' | 'R' | 'P' => {}
                _ => return None,
            }
        }
        i += if takes_next { 2 } else { 1 };
    }
    None
}

/// `-3`, `-3.10`, `-3-64`, `-V:3.10`: the py launcher's version selectors.
fn is_version_selector(arg: &str) -> bool {
    if arg.starts_with("-V:") {
        return true;
    }
    let rest = &arg[1..];
    !rest.is_empty()
        && rest.starts_with(|c: char| c.is_ascii_digit())
        && rest.chars().all(|c| c.is_ascii_digit() || c == '.' || c == '-')
}

/// The program text of a `python -c "CODE"` command line run with `shell=True`.
///
/// `None` when the line is not a Python invocation, or when `cmd.exe` would change
/// it before Python saw it: any `%` (variable expansion), or `^ & | < >` outside
/// double quotes.
pub fn python_code_from_command_line(line: &str) -> Option<String> {
    if line.contains('%') {
        return None;
    }
    let mut quoted = false;
    for c in line.chars() {
        match c {
            '"' => quoted = !quoted,
            '^' | '&' | '|' | '<' | '>' if !quoted => return None,
            _ => {}
        }
    }
    let argv = split_windows_command_line(line);
    python_code_from_argv(&argv).map(str::to_owned)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn argv(parts: &[&str]) -> Vec<String> {
        parts.iter().map(|s| (*s).to_owned()).collect()
    }

    #[test]
    fn recognises_python_invocations() {
        let check = |parts: &[&str], expected: Option<&str>| {
            let v = argv(parts);
            assert_eq!(python_code_from_argv(&v), expected, "{parts:?}");
        };
        check(&["python", "-c", "print(1)"], Some("print(1)"));
        check(&["python3", "-c", "x"], Some("x"));
        check(&["Python3.10.EXE", "-c", "x"], Some("x"));
        check(&[r"C:\Python310\python.exe", "-u", "-B", "-c", "x", "arg"], Some("x"));
        check(&["/usr/bin/python3", "-X", "utf8", "-c", "x"], Some("x"));
        check(&["pythonw", "-Xutf8", "-c", "x"], Some("x"));
        check(&["python", "-uBc", "x"], Some("x"));
        check(&["python", "-cprint(2)"], Some("print(2)"));
        check(&["py", "-3", "-c", "x"], Some("x"));
        check(&["py", "-3.10", "-c", "x"], Some("x"));
        check(&["python", "-c"], None);
        check(&["python", "script.py"], None);
        check(&["python", "-m", "pip"], None);
        check(&["python", "--version"], None);
        check(&["python", "-", "x"], None);
        check(&["pythonista", "-c", "x"], None);
        check(&["cmd", "/c", "python -c x"], None);
        check(&["python3.", "-c", "x"], None);
        check(&[], None);
    }

    #[test]
    fn command_lines_with_cmd_syntax_are_refused() {
        assert_eq!(python_code_from_command_line(r#"python -c "print('a & b')""#).as_deref(), Some("print('a & b')"));
        assert_eq!(python_code_from_command_line(r#"python -c "print(1)" & calc"#), None);
        assert_eq!(python_code_from_command_line(r#"python -c "print('%PATH%')""#), None);
        assert_eq!(python_code_from_command_line("notepad.exe"), None);
    }
}
