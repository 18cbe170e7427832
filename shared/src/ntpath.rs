//! Python's `ntpath` (3.10, the `os.path` of upstream's Windows guest), on `&str`:
//! the one copy of Windows path rules for the guest's routes and the interpreter's
//! `os.path`.
//!
//! Both separators, `\` and `/`, are accepted everywhere and `\` is the one written.
//! A drive is `C:` or a UNC `\\server\share` prefix. The environment is read through
//! a caller's lookup (`env`), so this module does no I/O: the guest answers from the
//! backend's environment and the interpreter from its host's. Windows compares
//! variable names without regard to case; the lookup is where that is decided.
//!
//! Only the functions both sides need are here; each follows CPython 3.10's,
//! corner cases included (the tests hold the cases CPython's own tests document).

/// Whether `c` separates path components (`\` or `/`).
fn is_sep(c: char) -> bool {
    c == '\\' || c == '/'
}

/// `ntpath.splitdrive`: (`C:` or `\\server\share`, the rest). A UNC prefix needs
/// both the server and the share and no doubled separator between them.
pub fn splitdrive(p: &str) -> (&str, &str) {
    let bytes = p.as_bytes();
    let sep_at = |i: usize| bytes.get(i).is_some_and(|&b| b == b'\\' || b == b'/');
    if sep_at(0) && sep_at(1) && !sep_at(2) {
        // Both separators are ASCII, so every index found here is a character boundary.
        let Some(index) = p[2..].find(is_sep).map(|i| i + 2) else {
            return ("", p);
        };
        let index2 = match p[index + 1..].find(is_sep).map(|i| i + index + 1) {
            Some(i) if i == index + 1 => return ("", p),
            Some(i) => i,
            None => p.len(),
        };
        return p.split_at(index2);
    }
    // `X:`, where X is any one character (Python counts characters, not bytes).
    let mut chars = p.char_indices();
    if let (Some(_), Some((colon, ':'))) = (chars.next(), chars.next()) {
        return p.split_at(colon + 1);
    }
    ("", p)
}

/// `ntpath.join`: an absolute part restarts the path (keeping the drive), a part on
/// another drive replaces it, and one `\` goes between parts that lack a separator.
pub fn join(parts: &[&str]) -> String {
    let first = parts.first().copied().unwrap_or("");
    let (first_drive, first_path) = splitdrive(first);
    let mut drive = first_drive.to_owned();
    let mut path = first_path.to_owned();
    for part in parts.iter().skip(1) {
        let (p_drive, p_path) = splitdrive(part);
        if p_path.starts_with(is_sep) {
            if !p_drive.is_empty() || drive.is_empty() {
                drive = p_drive.to_owned();
            }
            path = p_path.to_owned();
            continue;
        } else if !p_drive.is_empty() && p_drive != drive {
            if p_drive.to_lowercase() != drive.to_lowercase() {
                drive = p_drive.to_owned();
                path = p_path.to_owned();
                continue;
            }
            // The same drive spelled in another case: the new spelling wins.
            drive = p_drive.to_owned();
        }
        if !path.is_empty() && !path.ends_with(is_sep) {
            path.push('\\');
        }
        path.push_str(p_path);
    }
    // A UNC drive and a relative path still need a separator between them.
    if !path.is_empty() && !path.starts_with(is_sep) && !drive.is_empty() && !drive.ends_with(':') {
        return format!("{drive}\\{path}");
    }
    drive + &path
}

/// `ntpath.split`: (head, tail) where tail has no separator and head keeps the drive
/// but loses its trailing separators, unless it is nothing but separators.
pub fn split(p: &str) -> (&str, &str) {
    let (drive, rest) = splitdrive(p);
    let i = rest.rfind(is_sep).map_or(0, |i| i + 1);
    let (head, tail) = rest.split_at(i);
    let stripped = head.trim_end_matches(is_sep);
    let head = if stripped.is_empty() { head } else { stripped };
    (&p[..drive.len() + head.len()], tail)
}

/// `ntpath.basename`: the tail of [`split`].
pub fn basename(p: &str) -> &str {
    split(p).1
}

/// `ntpath.dirname`: the head of [`split`].
pub fn dirname(p: &str) -> &str {
    split(p).0
}

/// `ntpath.splitext`: (root, extension) at the last dot of the last component;
/// leading dots of a name (`.bashrc`) do not start an extension. Drives are not
/// split off first (`c:a.b` is `("c:a", ".b")`).
pub fn splitext(p: &str) -> (&str, &str) {
    let name_start = p.rfind(is_sep).map_or(0, |i| i + 1);
    if let Some(dot) = p.rfind('.').filter(|d| *d >= name_start) {
        if p[name_start..dot].chars().any(|c| c != '.') {
            return p.split_at(dot);
        }
    }
    (p, "")
}

/// `ntpath.isabs` (3.10): a separator right after the drive, or a `\\?\` prefix.
pub fn isabs(p: &str) -> bool {
    let verbatim = p.len() >= 4
        && p.as_bytes()[..4].iter().zip(b"\\\\?\\").all(|(&b, &want)| b == want || (b == b'/' && want == b'\\'));
    verbatim || splitdrive(p).1.starts_with(is_sep)
}

/// `ntpath.expanduser`: a leading `~` becomes the home folder (`USERPROFILE`, else
/// `HOMEDRIVE` joined with `HOMEPATH`; without either the path is unchanged), and a
/// leading `~user` the folder beside it named `user`, but only when the home folder's
/// name is the current `USERNAME` (otherwise the guess would be wrong and the path is
/// left as written).
pub fn expanduser(path: &str, env: &mut dyn FnMut(&str) -> Option<String>) -> String {
    if !path.starts_with('~') {
        return path.to_owned();
    }
    let end = path[1..].find(is_sep).map_or(path.len(), |i| i + 1);
    let mut home = match env("USERPROFILE") {
        Some(home) => home,
        None => match env("HOMEPATH") {
            None => return path.to_owned(),
            Some(home_path) => join(&[&env("HOMEDRIVE").unwrap_or_default(), &home_path]),
        },
    };
    if end != 1 {
        let target = &path[1..end];
        let current = env("USERNAME");
        if current.as_deref() != Some(target) {
            let (parent, name) = split(&home);
            if current.as_deref() != Some(name) {
                return path.to_owned();
            }
            home = join(&[parent, target]);
        }
    }
    format!("{home}{}", &path[end..])
}

/// `ntpath.expandvars`: `%NAME%`, `$NAME` and `${NAME}` become the variable's value;
/// an unknown variable stays as written, `%%` and `$$` are one `%` and one `$`, and
/// nothing between single quotes is expanded. `$NAME` takes ASCII letters, digits,
/// `_` and `-`.
pub fn expandvars(path: &str, env: &mut dyn FnMut(&str) -> Option<String>) -> String {
    if !path.contains(['$', '%']) {
        return path.to_owned();
    }
    let is_var_byte = |b: u8| b.is_ascii_alphanumeric() || b == b'_' || b == b'-';
    let bytes = path.as_bytes();
    let mut res = String::with_capacity(path.len());
    // Always a character boundary: it only moves past ASCII delimiters or to what `find` returns.
    let mut i = 0;
    // The value of the variable `name`, or the variable as `written` when it has none.
    let mut expand = |res: &mut String, name: &str, written: &str| match env(name) {
        Some(value) => res.push_str(&value),
        None => res.push_str(written),
    };
    while i < bytes.len() {
        match (bytes[i], bytes.get(i + 1)) {
            (b'\'', _) => match path[i + 1..].find('\'') {
                Some(n) => {
                    res.push_str(&path[i..i + n + 2]);
                    i += n + 2;
                }
                None => {
                    res.push_str(&path[i..]);
                    i = bytes.len();
                }
            },
            (b'%', Some(b'%')) => {
                res.push('%');
                i += 2;
            }
            (b'%', _) => match path[i + 1..].find('%') {
                Some(n) => {
                    expand(&mut res, &path[i + 1..i + 1 + n], &path[i..i + n + 2]);
                    i += n + 2;
                }
                None => {
                    res.push_str(&path[i..]);
                    i = bytes.len();
                }
            },
            (b'$', Some(b'$')) => {
                res.push('$');
                i += 2;
            }
            (b'$', Some(b'{')) => match path[i + 2..].find('}') {
                Some(n) => {
                    expand(&mut res, &path[i + 2..i + 2 + n], &path[i..i + n + 3]);
                    i += n + 3;
                }
                None => {
                    res.push_str(&path[i..]);
                    i = bytes.len();
                }
            },
            (b'$', _) => {
                let n = bytes[i + 1..].iter().take_while(|&&b| is_var_byte(b)).count();
                if n == 0 {
                    res.push('$');
                } else {
                    expand(&mut res, &path[i + 1..i + 1 + n], &path[i..i + 1 + n]);
                }
                i += n + 1;
            }
            _ => {
                let next = path[i..].find(['\'', '%', '$']).map_or(bytes.len(), |n| i + n);
                res.push_str(&path[i..next]);
                i = next;
            }
        }
    }
    res
}

#[cfg(test)]
mod tests {
    //! The cases CPython 3.10's `test_ntpath` documents, each checked against
    //! CPython 3.10's `ntpath`; every case also runs with `/` for `\` where
    //! CPython's tester does.

    use super::*;

    fn env_of<'a>(vars: &'a [(&'a str, &'a str)]) -> impl FnMut(&str) -> Option<String> + 'a {
        move |name: &str| vars.iter().find(|(k, _)| *k == name).map(|(_, v)| (*v).to_owned())
    }

    #[test]
    fn splitdrive_cases() {
        let check = |p: &str, drive: &str, rest: &str| assert_eq!(splitdrive(p), (drive, rest), "{p:?}");
        check(r"c:\foo\bar", "c:", r"\foo\bar");
        check("c:/foo/bar", "c:", "/foo/bar");
        check(r"\\conky\mountpoint\foo\bar", r"\\conky\mountpoint", r"\foo\bar");
        check("//conky/mountpoint/foo/bar", "//conky/mountpoint", "/foo/bar");
        check(r"\\\conky\mountpoint\foo\bar", "", r"\\\conky\mountpoint\foo\bar");
        check("///conky/mountpoint/foo/bar", "", "///conky/mountpoint/foo/bar");
        check(r"\\conky\\mountpoint\foo\bar", "", r"\\conky\\mountpoint\foo\bar");
        check("//conky//mountpoint/foo/bar", "", "//conky//mountpoint/foo/bar");
        check("//conky/MOUNTPOİNT/foo/bar", "//conky/MOUNTPOİNT", "/foo/bar");
        check(r"\\server", "", r"\\server");
        check(r"\\server\share", r"\\server\share", "");
        check("é:x", "é:", "x");
        check("c", "", "c");
        check("", "", "");
    }

    #[test]
    fn split_cases() {
        let check = |p: &str, head: &str, tail: &str| {
            assert_eq!(split(p), (head, tail), "{p:?}");
            assert_eq!((dirname(p), basename(p)), (head, tail), "{p:?}");
        };
        check(r"c:\foo\bar", r"c:\foo", "bar");
        check(r"\\conky\mountpoint\foo\bar", r"\\conky\mountpoint\foo", "bar");
        check(r"c:\", r"c:\", "");
        check(r"\\conky\mountpoint\", r"\\conky\mountpoint\", "");
        check("c:/", "c:/", "");
        check("//conky/mountpoint/", "//conky/mountpoint/", "");
        check(r"C:\Users\Docker\file.txt", r"C:\Users\Docker", "file.txt");
        check("C:a.txt", "C:", "a.txt");
        check(r"a\\b", "a", "b");
        check(r"\\server\share", r"\\server\share", "");
        check("file", "", "file");
        check("", "", "");
    }

    #[test]
    fn splitext_cases() {
        let check = |p: &str, root: &str, ext: &str| {
            assert_eq!(splitext(p), (root, ext), "{p:?}");
            let slashed = p.replace('\\', "/");
            assert_eq!(splitext(&slashed), (&*root.replace('\\', "/"), ext), "{slashed:?}");
        };
        check("foo.ext", "foo", ".ext");
        check("/foo/foo.ext", "/foo/foo", ".ext");
        check(".ext", ".ext", "");
        check(r"\foo.ext\foo", r"\foo.ext\foo", "");
        check(r"foo.ext\", r"foo.ext\", "");
        check("", "", "");
        check("foo.bar.ext", "foo.bar", ".ext");
        check("xx/foo.bar.ext", "xx/foo.bar", ".ext");
        check(r"xx\foo.bar.ext", r"xx\foo.bar", ".ext");
        check(r"c:a/b\c.d", r"c:a/b\c", ".d");
        check("..bashrc", "..bashrc", "");
        check("...x.y", "...x", ".y");
        check("c:a.b", "c:a", ".b");
    }

    #[test]
    fn isabs_cases() {
        for p in [r"c:\", r"\\conky\mountpoint\", r"\foo", r"\foo\bar", "/x", r"\\?\C:", "//?/x", r"\\?\"] {
            assert!(isabs(p), "{p:?}");
        }
        for p in ["c:", "c:x", "x", "", r"\\conky\mountpoint", "~"] {
            assert!(!isabs(p), "{p:?}");
        }
    }

    #[test]
    fn join_cases() {
        let check = |parts: &[&str], expected: &str| {
            assert_eq!(join(parts), expected, "{parts:?}");
            let slashed: Vec<String> = parts.iter().map(|p| p.replace('\\', "/")).collect();
            // With `/` written, only the separators `join` adds stay `\`.
            let got = join(&slashed.iter().map(String::as_str).collect::<Vec<_>>());
            assert_eq!(got.replace('/', "\\"), expected.replace('/', "\\"), "{slashed:?}");
        };
        check(&[""], "");
        check(&["", "", ""], "");
        check(&["a"], "a");
        check(&["/a"], "/a");
        check(&[r"\a"], r"\a");
        check(&["a:"], "a:");
        check(&["a:", r"\b"], r"a:\b");
        check(&["a", r"\b"], r"\b");
        check(&["a", "b", "c"], r"a\b\c");
        check(&[r"a\", "b", "c"], r"a\b\c");
        check(&["a", r"b\", "c"], r"a\b\c");
        check(&["a", "b", r"\c"], r"\c");
        check(&[r"d:\", r"\pleep"], r"d:\pleep");
        check(&[r"d:\", "a", "b"], r"d:\a\b");
        check(&["", "a"], "a");
        check(&["", "", "", "", "a"], "a");
        check(&["a", ""], r"a\");
        check(&["a", "", "", "", ""], r"a\");
        check(&[r"a\", ""], r"a\");
        check(&[r"a\", "", "", "", ""], r"a\");
        check(&["a/", ""], "a/");
        check(&["a/b", "x/y"], r"a/b\x/y");
        check(&["/a/b", "x/y"], r"/a/b\x/y");
        check(&["/a/b/", "x/y"], "/a/b/x/y");
        check(&["c:", "x/y"], "c:x/y");
        check(&["c:a/b", "x/y"], r"c:a/b\x/y");
        check(&["c:a/b/", "x/y"], "c:a/b/x/y");
        check(&["c:/", "x/y"], "c:/x/y");
        check(&["c:/a/b", "x/y"], r"c:/a/b\x/y");
        check(&["c:/a/b/", "x/y"], "c:/a/b/x/y");
        check(&["//computer/share", "x/y"], r"//computer/share\x/y");
        check(&["//computer/share/", "x/y"], "//computer/share/x/y");
        check(&["//computer/share/a/b", "x/y"], r"//computer/share/a/b\x/y");
        check(&["a/b", "/x/y"], "/x/y");
        check(&["/a/b", "/x/y"], "/x/y");
        check(&["c:", "/x/y"], "c:/x/y");
        check(&["c:a/b", "/x/y"], "c:/x/y");
        check(&["c:/", "/x/y"], "c:/x/y");
        check(&["c:/a/b", "/x/y"], "c:/x/y");
        check(&["//computer/share", "/x/y"], "//computer/share/x/y");
        check(&["//computer/share/", "/x/y"], "//computer/share/x/y");
        check(&["//computer/share/a", "/x/y"], "//computer/share/x/y");
        check(&["c:", "C:x/y"], "C:x/y");
        check(&["c:a/b", "C:x/y"], r"C:a/b\x/y");
        check(&["c:/", "C:x/y"], "C:/x/y");
        check(&["c:/a/b", "C:x/y"], r"C:/a/b\x/y");
        // A part on another drive replaces everything before it.
        for x in [
            "",
            "a/b",
            "/a/b",
            "c:",
            "c:a/b",
            "c:/",
            "c:/a/b",
            "//computer/share",
            "//computer/share/",
            "//computer/share/a/b",
        ] {
            for y in ["d:", "d:x/y", "d:/", "d:/x/y", "//machine/common", "//machine/common/", "//machine/common/x/y"] {
                check(&[x, y], y);
            }
        }
        check(&[r"\\computer\share\", "a", "b"], r"\\computer\share\a\b");
        check(&[r"\\computer\share", "a", "b"], r"\\computer\share\a\b");
        check(&[r"\\computer\share", r"a\b"], r"\\computer\share\a\b");
        check(&["//computer/share/", "a", "b"], r"//computer/share/a\b");
        check(&["//computer/share", "a", "b"], r"//computer/share\a\b");
        check(&["//computer/share", "a/b"], r"//computer/share\a/b");
        check(
            &[r"C:\Users\Docker\AppData\Local", r"Google\Chrome\User Data\Default\History"],
            r"C:\Users\Docker\AppData\Local\Google\Chrome\User Data\Default\History",
        );
    }

    #[test]
    fn expanduser_cases() {
        let check = |vars: &[(&str, &str)], path: &str, expected: &str| {
            assert_eq!(expanduser(path, &mut env_of(vars)), expected, "{path:?} with {vars:?}");
        };
        check(&[], "~test", "~test");
        let drive_and_path = [("HOMEDRIVE", r"C:\"), ("HOMEPATH", r"Users\eric"), ("USERNAME", "eric")];
        check(&drive_and_path, "~test", r"C:\Users\test");
        check(&drive_and_path, "~", r"C:\Users\eric");
        let path_only = [("HOMEPATH", r"Users\eric"), ("USERNAME", "eric")];
        check(&path_only, "~test", r"Users\test");
        check(&path_only, "~", r"Users\eric");
        let profile = [("USERPROFILE", r"C:\Users\eric"), ("USERNAME", "eric")];
        check(&profile, "~test", r"C:\Users\test");
        check(&profile, "~", r"C:\Users\eric");
        check(&profile, r"~test\foo\bar", r"C:\Users\test\foo\bar");
        check(&profile, "~test/foo/bar", r"C:\Users\test/foo/bar");
        check(&profile, r"~\foo\bar", r"C:\Users\eric\foo\bar");
        check(&profile, "~/foo/bar", r"C:\Users\eric/foo/bar");
        check(&profile, "~eric", r"C:\Users\eric");
        check(&profile, "x~", "x~");
        // HOME is not read on Windows.
        check(&[("HOME", r"F:\"), ("USERPROFILE", r"C:\Users\eric"), ("USERNAME", "eric")], "~test", r"C:\Users\test");
        // Another user's folder is not guessed when the profile is not named after the current user.
        let other = [("USERPROFILE", r"C:\Users\eric"), ("USERNAME", "idle")];
        check(&other, "~test", "~test");
        check(&other, "~", r"C:\Users\eric");
    }

    #[test]
    fn expandvars_cases() {
        let vars = [("foo", "bar"), ("{foo", "baz1"), ("{foo}", "baz2")];
        let check = |path: &str, expected: &str| assert_eq!(expandvars(path, &mut env_of(&vars)), expected, "{path:?}");
        check("foo", "foo");
        check("$foo bar", "bar bar");
        check("${foo}bar", "barbar");
        check("$[foo]bar", "$[foo]bar");
        check("$bar bar", "$bar bar");
        check("$?bar", "$?bar");
        check("$foo}bar", "bar}bar");
        check("${foo", "${foo");
        check("${{foo}}", "baz1}");
        check("$foo$foo", "barbar");
        check("$bar$bar", "$bar$bar");
        check("%foo% bar", "bar bar");
        check("%foo%bar", "barbar");
        check("%foo%%foo%", "barbar");
        check("%%foo%%foo%foo%", "%foo%foobar");
        check("%?bar%", "%?bar%");
        check("%foo%%bar", "bar%bar");
        check("'%foo%'%bar", "'%foo%'%bar");
        check("bar'%foo%", "bar'%foo%");
        check("$", "$");
        check("a$$b", "a$b");
        check("50% off", "50% off");
        check("é%foo%ü$foo", "ébarübar");
    }

    proptest::proptest! {
        #[test]
        fn never_panics(s in "[~%$'{}a-zA-Zé:_\\\\/ ?.]{0,24}") {
            let mut env = env_of(&[("USERPROFILE", r"C:\Users\Docker"), ("USERNAME", "Docker"), ("a", "é")]);
            let _ = (expandvars(&s, &mut env), expanduser(&s, &mut env), splitdrive(&s), split(&s), splitext(&s), isabs(&s));
            let _ = join(&[s.as_str(), s.as_str()]);
        }
    }
}
