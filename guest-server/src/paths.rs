//! Guest path expansion with Python's `ntpath` semantics.
//!
//! Upstream WAA expands paths with `os.path.expandvars(os.path.expanduser(p))`
//! on Windows; hosts rely on `%LOCALAPPDATA%`, `$USERPROFILE` and `~` working
//! in `/file`, `/setup/upload` and friends. These functions reproduce that,
//! with the environment supplied by the backend ([`crate::desktop::Desktop::env_var`]).

/// `ntpath.expanduser`: a leading `~` or `~user` becomes the user's profile folder.
///
/// The home folder is `USERPROFILE`, else `HOMEDRIVE` + `HOMEPATH`; for
/// `~other` the last component of the home folder is replaced by `other`.
/// Without a home folder the path is returned unchanged.
pub fn expand_user(path: &str, env: &dyn Fn(&str) -> Option<String>) -> String {
    if !path.starts_with('~') {
        return path.to_owned();
    }
    let end = path.find(['/', '\\']).unwrap_or(path.len());
    let home = match env("USERPROFILE") {
        Some(home) => home,
        None => match (env("HOMEDRIVE"), env("HOMEPATH")) {
            (Some(drive), Some(home_path)) => format!("{drive}{home_path}"),
            (None, Some(home_path)) => home_path,
            _ => return path.to_owned(),
        },
    };
    let mut home = home;
    if end != 1 {
        let target_user = &path[1..end];
        let current_user = env("USERNAME");
        if current_user.as_deref() != Some(target_user) {
            let parent_end = home.rfind(['/', '\\']).map_or(0, |i| i + 1);
            home = format!("{}{target_user}", &home[..parent_end]);
        }
    }
    format!("{home}{}", &path[end..])
}

/// `ntpath.expandvars`: `%VAR%`, `$VAR` and `${VAR}` are replaced by their values;
/// unknown variables are left as written; `%%` and `$$` are a literal `%` and `$`;
/// text between single quotes is left alone.
pub fn expand_vars(path: &str, env: &dyn Fn(&str) -> Option<String>) -> String {
    if !path.contains(['$', '%']) {
        return path.to_owned();
    }
    let chars: Vec<char> = path.chars().collect();
    let is_var_char = |c: char| c.is_ascii_alphanumeric() || c == '_' || c == '-';
    let mut res = String::with_capacity(path.len());
    let mut idx = 0;
    while idx < chars.len() {
        let c = chars[idx];
        match c {
            '\'' => match chars[idx + 1..].iter().position(|&c| c == '\'') {
                Some(n) => {
                    res.extend(&chars[idx..idx + n + 2]);
                    idx += n + 2;
                }
                None => {
                    res.extend(&chars[idx..]);
                    idx = chars.len();
                }
            },
            '%' => {
                if chars.get(idx + 1) == Some(&'%') {
                    res.push('%');
                    idx += 2;
                    continue;
                }
                match chars[idx + 1..].iter().position(|&c| c == '%') {
                    Some(n) => {
                        let name: String = chars[idx + 1..idx + 1 + n].iter().collect();
                        match env(&name) {
                            Some(value) => res.push_str(&value),
                            None => {
                                res.push('%');
                                res.push_str(&name);
                                res.push('%');
                            }
                        }
                        idx += n + 2;
                    }
                    None => {
                        res.extend(&chars[idx..]);
                        idx = chars.len();
                    }
                }
            }
            '$' => {
                if chars.get(idx + 1) == Some(&'$') {
                    res.push('$');
                    idx += 2;
                } else if chars.get(idx + 1) == Some(&'{') {
                    match chars[idx + 2..].iter().position(|&c| c == '}') {
                        Some(n) => {
                            let name: String = chars[idx + 2..idx + 2 + n].iter().collect();
                            match env(&name) {
                                Some(value) => res.push_str(&value),
                                None => res.push_str(&format!("${{{name}}}")),
                            }
                            idx += n + 3;
                        }
                        None => {
                            res.extend(&chars[idx..]);
                            idx = chars.len();
                        }
                    }
                } else {
                    let n = chars[idx + 1..].iter().take_while(|&&c| is_var_char(c)).count();
                    let name: String = chars[idx + 1..idx + 1 + n].iter().collect();
                    match (n, env(&name)) {
                        (0, _) => res.push('$'),
                        (_, Some(value)) => res.push_str(&value),
                        (_, None) => {
                            res.push('$');
                            res.push_str(&name);
                        }
                    }
                    idx += n + 1;
                }
            }
            c => {
                res.push(c);
                idx += 1;
            }
        }
    }
    res
}

/// `expandvars(expanduser(path))`, the order upstream uses.
pub fn expand(path: &str, env: &dyn Fn(&str) -> Option<String>) -> String {
    expand_vars(&expand_user(path, env), env)
}

/// The last component of a Windows or POSIX path (`ntpath.basename`).
pub fn basename(path: &str) -> &str {
    let path = path.get(2..).filter(|_| path.as_bytes().get(1) == Some(&b':')).unwrap_or(path);
    path.rsplit(['/', '\\']).next().unwrap_or(path)
}

/// Joins two guest path parts with `\` the way `ntpath.join` does for the simple cases:
/// an absolute second part wins, and no separator is doubled.
pub fn join(base: &str, part: &str) -> String {
    let is_absolute = part.starts_with(['\\', '/']) || part.as_bytes().get(1) == Some(&b':');
    if is_absolute || base.is_empty() {
        return part.to_owned();
    }
    if base.ends_with(['\\', '/']) || base.ends_with(':') {
        format!("{base}{part}")
    } else {
        format!("{base}\\{part}")
    }
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
        assert_eq!(expand(input, &env), expected, "expanding {input:?}");
    }

    #[test]
    fn expands_like_ntpath() {
        check(r"~\Desktop\a.txt", r"C:\Users\Docker\Desktop\a.txt");
        check("~/Desktop", r"C:\Users\Docker/Desktop");
        check("~", r"C:\Users\Docker");
        check(r"~Bob\x", r"C:\Users\Bob\x");
        check(r"%LOCALAPPDATA%\Google", r"C:\Users\Docker\AppData\Local\Google");
        check(r"%localappdata%\x", r"C:\Users\Docker\AppData\Local\x");
        check(r"$LOCALAPPDATA\x", r"C:\Users\Docker\AppData\Local\x");
        check(r"${LOCALAPPDATA}\x", r"C:\Users\Docker\AppData\Local\x");
        check(r"%NOPE%\x", r"%NOPE%\x");
        check(r"$NOPE\x", r"$NOPE\x");
        check("100%% sure", "100% sure");
        check("a$$b", "a$b");
        check("'%LOCALAPPDATA%'", "'%LOCALAPPDATA%'");
        check("50% off", "50% off");
        check(r"C:\plain\path", r"C:\plain\path");
        check("$", "$");
    }

    #[test]
    fn basename_and_join() {
        assert_eq!(basename(r"C:\Users\Docker\a.txt"), "a.txt");
        assert_eq!(basename("C:a.txt"), "a.txt");
        assert_eq!(basename(r"C:\dir\"), "");
        assert_eq!(join(r"C:\Users", "a"), r"C:\Users\a");
        assert_eq!(join(r"C:\Users\", "a"), r"C:\Users\a");
        assert_eq!(join(r"C:\Users", r"D:\x"), r"D:\x");
    }

    proptest::proptest! {
        #[test]
        fn expansion_never_panics(s in "[~%$'{}a-zA-Z_\\\\/ ]{0,24}") {
            let _ = expand(&s, &env);
        }
    }
}
