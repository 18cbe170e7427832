//! Guest path expansion: upstream WAA's order over Python's `ntpath` rules.
//!
//! Upstream expands a caller's path with `os.path.expandvars(os.path.expanduser(p))`
//! on Windows; hosts rely on `%LOCALAPPDATA%`, `$USERPROFILE` and `~` working in
//! `/file`, `/setup/upload` and friends. The path rules themselves are
//! [`arena_shared::ntpath`] (Python 3.10's, the interpreter's too); this module only
//! fixes the order, with the environment supplied by the caller (the backend's
//! [`crate::desktop::Desktop::env_var`]).

pub use arena_shared::ntpath::basename;
use arena_shared::ntpath::{expanduser, expandvars};

/// `expandvars(expanduser(path))`, the order upstream uses.
pub fn expand(path: &str, env: &mut dyn FnMut(&str) -> Option<String>) -> String {
    expandvars(&expanduser(path, env), env)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env(name: &str) -> Option<String> {
        match name.to_ascii_uppercase().as_str() {
            "USERPROFILE" => Some(r"C:\Users\Docker".into()),
            "USERNAME" => Some("Docker".into()),
            "LOCALAPPDATA" => Some(r"C:\Users\Docker\AppData\Local".into()),
            _ => None,
        }
    }

    fn check(input: &str, expected: &str) {
        assert_eq!(expand(input, &mut env), expected, "expanding {input:?}");
    }

    #[test]
    fn expands_user_then_variables() {
        check(r"~\Desktop\a.txt", r"C:\Users\Docker\Desktop\a.txt");
        check("~/Desktop", r"C:\Users\Docker/Desktop");
        check("~", r"C:\Users\Docker");
        check(r"~Bob\x", r"C:\Users\Bob\x");
        check(r"%LOCALAPPDATA%\Google", r"C:\Users\Docker\AppData\Local\Google");
        check(r"%localappdata%\x", r"C:\Users\Docker\AppData\Local\x");
        check(r"$LOCALAPPDATA\x", r"C:\Users\Docker\AppData\Local\x");
        check(r"${LOCALAPPDATA}\x", r"C:\Users\Docker\AppData\Local\x");
        check(r"%NOPE%\x", r"%NOPE%\x");
        check(r"C:\plain\path", r"C:\plain\path");
        // A variable's value is not expanded again, and `~` only counts at the start.
        check(r"%USERPROFILE%\~x", r"C:\Users\Docker\~x");
        check(r"x\~", r"x\~");
    }
}
