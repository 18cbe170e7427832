//! How upstream's Python would print things: `repr` and `str` of JSON values, the
//! `str()` of a `WindowsPath`, and the texts of Python's `OSError`s.
//!
//! Upstream messages interpolate request values with f-strings and exception texts,
//! and hosts compare some of them (`/setup/launch` answers with the repr of the
//! command list). This module reproduces those renderings; it does not evaluate Python.

use serde_json::Value;

/// Python's type name of a JSON value, as it appears in `TypeError` and `AttributeError` texts.
pub(crate) fn type_name(value: &Value) -> &'static str {
    match value {
        Value::Null => "NoneType",
        Value::Bool(_) => "bool",
        Value::Number(n) if n.is_i64() || n.is_u64() => "int",
        Value::Number(_) => "float",
        Value::String(_) => "str",
        Value::Array(_) => "list",
        Value::Object(_) => "dict",
    }
}

/// `str(value)`: strings as they are, everything else as its `repr`.
pub(crate) fn str_of(value: &Value) -> String {
    match value {
        Value::String(s) => s.clone(),
        other => repr(other),
    }
}

/// `repr(value)` of the Python object `json.loads` makes of `value`.
pub(crate) fn repr(value: &Value) -> String {
    match value {
        Value::Null => "None".to_owned(),
        Value::Bool(true) => "True".to_owned(),
        Value::Bool(false) => "False".to_owned(),
        Value::Number(n) => {
            if let Some(i) = n.as_i64() {
                i.to_string()
            } else if let Some(u) = n.as_u64() {
                u.to_string()
            } else {
                float_repr(n.as_f64().unwrap_or(f64::NAN))
            }
        }
        Value::String(s) => repr_str(s),
        Value::Array(items) => format!("[{}]", items.iter().map(repr).collect::<Vec<_>>().join(", ")),
        Value::Object(map) => format!(
            "{{{}}}",
            map.iter().map(|(k, v)| format!("{}: {}", repr_str(k), repr(v))).collect::<Vec<_>>().join(", ")
        ),
    }
}

/// `repr` of a list of strings, e.g. `['chrome', '--x']`.
pub(crate) fn repr_str_list(items: &[String]) -> String {
    format!("[{}]", items.iter().map(|s| repr_str(s)).collect::<Vec<_>>().join(", "))
}

/// `repr(s)` of a Python `str` (shared with the script interpreter).
pub(crate) fn repr_str(s: &str) -> String {
    arena_script::str_repr(s)
}

/// `repr(float)` (shared with the script interpreter).
pub(crate) fn float_repr(f: f64) -> String {
    arena_script::float_repr(f)
}

/// `str(pathlib.WindowsPath(s))`: forward slashes become backslashes, empty and `.`
/// components and a trailing separator disappear, and an empty path is `.`.
pub(crate) fn windows_path_str(s: &str) -> String {
    let s = s.replace('/', "\\");
    let (prefix, rest) = if let Some(rest) = s.strip_prefix("\\\\") {
        ("\\\\".to_owned(), rest.to_owned())
    } else if s.as_bytes().get(1) == Some(&b':') {
        (s[..2].to_owned(), s[2..].to_owned())
    } else {
        (String::new(), s.clone())
    };
    let rooted = prefix == "\\\\" || rest.starts_with('\\');
    let parts: Vec<&str> = rest.split('\\').filter(|p| !p.is_empty() && *p != ".").collect();
    let mut out = prefix.clone();
    if rooted && prefix != "\\\\" {
        out.push('\\');
    }
    out.push_str(&parts.join("\\"));
    if out.is_empty() {
        ".".to_owned()
    } else {
        out
    }
}

/// Which Python call failed, because Windows Python words the same failure differently.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum OsCall {
    /// `open()`: C runtime errno texts (`[Errno 2] No such file or directory`).
    Open,
    /// `os.listdir`, `os.remove`, `os.stat`: Win32 texts (`[WinError 3] ...`).
    Win32Dir,
    /// `os.remove`, `os.stat` of a file: Win32 texts (`[WinError 2] ...`).
    Win32File,
}

/// The `str()` of the `OSError` Windows Python raises for `err` on `path`.
pub(crate) fn os_error(call: OsCall, err: &std::io::Error, path: &str) -> String {
    use std::io::ErrorKind;
    let path = repr_str(path);
    let text = match (call, err.kind()) {
        (OsCall::Open, ErrorKind::NotFound) => "[Errno 2] No such file or directory",
        (OsCall::Open, ErrorKind::PermissionDenied | ErrorKind::IsADirectory) => "[Errno 13] Permission denied",
        (OsCall::Open, ErrorKind::AlreadyExists) => "[Errno 17] File exists",
        (OsCall::Win32Dir, ErrorKind::NotFound) => "[WinError 3] The system cannot find the path specified",
        (OsCall::Win32File, ErrorKind::NotFound) => "[WinError 2] The system cannot find the file specified",
        (_, ErrorKind::PermissionDenied | ErrorKind::IsADirectory) => "[WinError 5] Access is denied",
        (_, ErrorKind::NotADirectory) => "[WinError 267] The directory name is invalid",
        (_, ErrorKind::AlreadyExists) => "[WinError 183] Cannot create a file when that file already exists",
        _ => return format!("{err}: {path}"),
    };
    format!("{text}: {path}")
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn reprs_match_python() {
        let check = |v: Value, expected: &str| assert_eq!(repr(&v), expected, "repr of {v}");
        check(json!(null), "None");
        check(json!(true), "True");
        check(json!(12), "12");
        check(json!(-3), "-3");
        check(json!(1.0), "1.0");
        check(json!(0.5), "0.5");
        check(json!(1e16), "1e+16");
        check(json!(1.5e-7), "1.5e-07");
        check(json!(123456.789), "123456.789");
        check(json!(0.0001), "0.0001");
        check(json!(-2.5), "-2.5");
        check(json!("a"), "'a'");
        check(json!("it's"), "\"it's\"");
        check(json!("it's \"x\""), "'it\\'s \"x\"'");
        check(json!(r"C:\Users"), r"'C:\\Users'");
        check(json!("a\nb\t\u{1}"), r"'a\nb\t\x01'");
        check(json!("héllo\u{a0}"), r"'héllo\xa0'");
        check(json!(["chrome", "--x"]), "['chrome', '--x']");
        check(json!({"a": [1, null]}), "{'a': [1, None]}");
        assert_eq!(str_of(&json!("plain")), "plain");
        assert_eq!(str_of(&json!(3)), "3");
        assert_eq!(type_name(&json!(2.5)), "float");
        assert_eq!(type_name(&json!([])), "list");
    }

    #[test]
    fn windows_paths_print_like_pathlib() {
        let check = |input: &str, expected: &str| assert_eq!(windows_path_str(input), expected, "{input:?}");
        check(r"C:\Users\Docker\a.txt", r"C:\Users\Docker\a.txt");
        check("C:/Users/Docker/", r"C:\Users\Docker");
        check(r"C:\\Users\.\x", r"C:\Users\x");
        check(r"C:\", r"C:\");
        check("a/b", r"a\b");
        check("", ".");
        check(r"\\host.lan\Data\x", r"\\host.lan\Data\x");
    }

    #[test]
    fn os_errors_read_like_windows_python() {
        let nf = std::io::Error::from(std::io::ErrorKind::NotFound);
        assert_eq!(os_error(OsCall::Open, &nf, r"C:\x\a.txt"), r"[Errno 2] No such file or directory: 'C:\\x\\a.txt'");
        assert_eq!(
            os_error(OsCall::Win32Dir, &nf, r"C:\x"),
            r"[WinError 3] The system cannot find the path specified: 'C:\\x'"
        );
        let denied = std::io::Error::from(std::io::ErrorKind::PermissionDenied);
        assert_eq!(os_error(OsCall::Open, &denied, r"C:\x"), r"[Errno 13] Permission denied: 'C:\\x'");
        assert_eq!(os_error(OsCall::Win32File, &denied, r"C:\x"), r"[WinError 5] Access is denied: 'C:\\x'");
    }
}
