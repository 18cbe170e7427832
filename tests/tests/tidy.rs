//! Tidy: the house rules, checked over the repository's own files on every test run.
//!
//! Each rule is a function from a file's path and text to its violations, shown to
//! catch an inline bad sample and to accept a good one; [`the_repository_is_tidy`]
//! runs them all over the tracked files (`git ls-files`, or a walk without git) and
//! lists every `file:line: rule` it finds.
//!
//! The rules:
//! - no `println!`, `eprintln!`, `print!`, `eprint!` or `dbg!` in library code (binaries'
//!   `main.rs`, the `arena` CLI and test code print on purpose; libraries emit tracing events);
//! - every `unsafe` block, function or impl has a `SAFETY:` comment (or a `# Safety`
//!   section) just before it, and nothing is `unsafe impl Send` or `Sync`;
//! - `cfg(windows)`, as an attribute or as the `cfg!(windows)` macro, is written only
//!   inside folders named `windows/`;
//! - every source folder and every module a crate root or a folder's `mod.rs` declares
//!   is named in `ARCHITECTURE.md` (in a code span), so the code map stays whole;
//! - every Rust file under a `src/` folder opens with a `//!` doc;
//! - docs and comments name no machine paths (`/work/`, `/tmp/`, `/root/`, `/home/`,
//!   `C:\Users\<someone>` other than the benchmark's `Docker` user or a placeholder);
//! - no `#[ignore]` and no `#[should_panic]`.

use std::path::{Path, PathBuf};

#[derive(Debug, Clone, PartialEq, Eq)]
struct Violation {
    line: usize,
    rule: &'static str,
}

fn at(line: usize, rule: &'static str) -> Violation {
    Violation { line, rule }
}

/// Where the library code lives, and which of it may print.
fn is_library_code(path: &str) -> bool {
    let libraries = ["shared/src/", "guest-server/src/", "host-client/src/", "tests/support/src/"];
    let printing_on_purpose = [
        // Binaries' entry points report to their user.
        "guest-server/src/main.rs",
        "guest-server/launch/src/main.rs",
        "host-client/src/main.rs",
        // The `arena` command line is the host's user interface.
        "host-client/src/cli/",
    ];
    path.ends_with(".rs")
        && libraries.iter().any(|p| path.starts_with(p))
        && !printing_on_purpose.iter().any(|p| path.starts_with(p))
        && !is_test_file(path)
}

fn is_test_file(path: &str) -> bool {
    let name = path.rsplit('/').next().unwrap_or(path);
    name == "tests.rs" || name.ends_with("_tests.rs")
}

/// The lines of Rust code before the file's `#[cfg(test)]` module (test code may print),
/// with comments cut off (roughly: from `//` outside a string to the end of the line).
fn code_lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    text.lines()
        .enumerate()
        .take_while(|(_, line)| line.trim() != "#[cfg(test)]")
        .map(|(i, line)| (i + 1, strip_comment(line)))
}

/// `line` without its `//` comment, ignoring `//` inside a string literal.
fn strip_comment(line: &str) -> &str {
    let mut in_string = false;
    let mut prev = ' ';
    for (i, c) in line.char_indices() {
        match c {
            '"' if prev != '\\' => in_string = !in_string,
            '/' if !in_string && prev == '/' => return &line[..i - 1],
            _ => {}
        }
        prev = c;
    }
    line
}

/// `line` with the contents of its string literals blanked out.
fn strip_strings(line: &str) -> String {
    let mut out = String::with_capacity(line.len());
    let mut in_string = false;
    let mut prev = ' ';
    for c in line.chars() {
        if c == '"' && prev != '\\' {
            in_string = !in_string;
            out.push(c);
        } else if !in_string {
            out.push(c);
        }
        prev = c;
    }
    out
}

fn no_printing(path: &str, text: &str) -> Vec<Violation> {
    if !is_library_code(path) {
        return Vec::new();
    }
    let macros = ["println!(", "eprintln!(", "print!(", "eprint!(", "dbg!("];
    code_lines(text)
        .map(|(n, line)| (n, strip_strings(line)))
        .filter(|(_, line)| {
            macros.iter().any(|m| line.match_indices(m).any(|(i, _)| !line[..i].ends_with(char::is_alphanumeric)))
        })
        .map(|(n, _)| at(n, "printing in library code (emit a tracing event instead)"))
        .collect()
}

fn unsafe_has_safety(path: &str, text: &str) -> Vec<Violation> {
    if !path.ends_with(".rs") {
        return Vec::new();
    }
    let lines: Vec<&str> = text.lines().collect();
    let mut out = Vec::new();
    for (i, raw) in lines.iter().enumerate() {
        let line = strip_comment(raw);
        let Some(pos) = line.find("unsafe") else { continue };
        let word_start = pos == 0 || !line[..pos].ends_with(|c: char| c.is_alphanumeric() || c == '_');
        let after = line[pos + "unsafe".len()..].trim_start();
        let is_unsafe = word_start
            && (after.starts_with('{')
                || after.starts_with("fn ")
                || after.starts_with("impl")
                || after.starts_with("extern"));
        if !is_unsafe || raw.contains("unsafe_op_in_unsafe_fn") {
            continue;
        }
        if after.starts_with("impl") && (after.contains("Send") || after.contains("Sync")) {
            out.push(at(i + 1, "unsafe impl Send/Sync (own the object on one thread instead)"));
            continue;
        }
        let before = &lines[i.saturating_sub(6)..i];
        let explained =
            raw.contains("SAFETY:") || before.iter().any(|l| l.contains("SAFETY:") || l.trim() == "/// # Safety");
        if !explained {
            out.push(at(i + 1, "unsafe without a SAFETY: comment (or a # Safety section) just before it"));
        }
    }
    out
}

fn cfg_windows_in_windows_folders(path: &str, text: &str) -> Vec<Violation> {
    if !path.ends_with(".rs") || !path.contains("/src/") || path.split('/').any(|part| part == "windows") {
        return Vec::new();
    }
    let names_windows = |cfg: &str| cfg.contains("windows");
    code_lines(text)
        .filter(|(_, line)| {
            let trimmed = line.trim_start();
            let attribute = trimmed.starts_with("#[cfg") && names_windows(trimmed);
            // A `cfg!` outside string literals, whose argument (read with its strings, for
            // `target_os = "windows"`) names Windows.
            let mac = strip_strings(line).contains("cfg!(")
                && line.match_indices("cfg!(").any(|(i, _)| names_windows(line[i..].split(')').next().unwrap_or("")));
            attribute || mac
        })
        .map(|(n, _)| at(n, "cfg(windows) outside a windows/ folder (move the code into the Windows backend's folder)"))
        .collect()
}

/// The words inside the code spans (`` `...` ``) of a Markdown text.
fn code_span_words(markdown: &str) -> std::collections::HashSet<&str> {
    markdown
        .split('`')
        .skip(1)
        .step_by(2)
        .flat_map(|span| span.split(|c: char| !(c.is_alphanumeric() || c == '_')))
        .filter(|w| !w.is_empty())
        .collect()
}

/// The modules a crate root or a folder's `mod.rs` declares with `mod NAME;` (test
/// modules aside), with their lines.
fn declared_modules(text: &str) -> Vec<(usize, &str)> {
    let mut out = Vec::new();
    let mut previous = "";
    for (n, line) in code_lines(text) {
        let trimmed = line.trim();
        let rest =
            ["pub mod ", "pub(crate) mod ", "pub(super) mod ", "mod "].iter().find_map(|p| trimmed.strip_prefix(p));
        if let Some(name) = rest.and_then(|r| r.strip_suffix(';')) {
            if name != "tests" && !previous.contains("cfg(test)") {
                out.push((n, name.trim()));
            }
        }
        previous = trimmed;
    }
    out
}

/// Whether `path` is a crate root or a folder's `mod.rs` under a `src/` folder.
fn declares_top_level_modules(path: &str) -> bool {
    let Some((_, inside)) = path.split_once("/src/") else { return false };
    inside == "lib.rs" || inside == "main.rs" || inside.ends_with("/mod.rs")
}

/// Every module declared in a crate root or a folder's `mod.rs`, and every folder of a
/// module file, is named in a code span of `architecture`.
fn modules_in_the_code_map(path: &str, text: &str, architecture: &str) -> Vec<Violation> {
    if !path.ends_with(".rs") || !path.contains("/src/") {
        return Vec::new();
    }
    let named = code_span_words(architecture);
    let mut out = Vec::new();
    if declares_top_level_modules(path) {
        for (n, module) in declared_modules(text) {
            if !named.contains(module) {
                out.push(at(n, "a module missing from ARCHITECTURE.md (name it in the code map)"));
            }
        }
    }
    let (_, inside) = path.split_once("/src/").unwrap_or(("", ""));
    let folders: Vec<&str> = inside.split('/').collect();
    if folders[..folders.len() - 1].iter().any(|folder| !folder.is_empty() && !named.contains(folder)) {
        out.push(at(1, "a source folder missing from ARCHITECTURE.md (name it in the code map)"));
    }
    out
}

fn opens_with_module_doc(path: &str, text: &str) -> Vec<Violation> {
    if !path.ends_with(".rs") || !path.contains("/src/") {
        return Vec::new();
    }
    match text.lines().next() {
        Some(first) if first.starts_with("//!") => Vec::new(),
        _ => vec![at(1, "no //! doc at the top (what this file is, and what it is not)")],
    }
}

/// The comment part of a line in a file of `kind`, if any (Markdown is all prose).
fn prose_of<'a>(path: &str, line: &'a str) -> Option<&'a str> {
    let ext = path.rsplit('.').next().unwrap_or("");
    let trimmed = line.trim_start();
    match ext {
        "md" => Some(line),
        "rs" => trimmed.starts_with("//").then_some(trimmed),
        "sh" | "ps1" | "py" | "toml" | "yml" | "yaml" => trimmed.starts_with('#').then_some(trimmed),
        _ => None,
    }
}

/// Whether `text` names a real user's profile folder (`C:\Users\name`) rather than the
/// benchmark's user, a shared profile or a placeholder.
fn names_a_user_folder(text: &str) -> bool {
    let lower = text.to_ascii_lowercase();
    lower.match_indices(r"c:\users\").any(|(i, m)| {
        let rest = &text[i + m.len()..];
        let name: String = rest.chars().take_while(|c| c.is_alphanumeric() || "._-".contains(*c)).collect();
        let allowed = ["Docker", "Public", "Default", ""];
        !allowed.iter().any(|a| name.eq_ignore_ascii_case(a))
    })
}

/// Whether `text` names a path under one of this machine's folders (`/work/x`); the
/// folder alone (`/work/`, as this file's rules name it) is no path.
fn names_a_machine_path(text: &str) -> bool {
    let machine = ["/work/", "/tmp/", "/root/", "/home/"];
    machine.iter().any(|m| {
        text.match_indices(m)
            .any(|(i, _)| text[i + m.len()..].starts_with(|c: char| c.is_alphanumeric() || "._-".contains(c)))
    })
}

fn no_machine_paths(path: &str, text: &str) -> Vec<Violation> {
    text.lines()
        .enumerate()
        .filter_map(|(i, line)| prose_of(path, line).map(|prose| (i + 1, prose)))
        .filter(|(_, prose)| names_a_machine_path(prose) || names_a_user_folder(prose))
        .map(|(n, _)| at(n, "a machine path in a doc or comment"))
        .collect()
}

fn no_ignored_tests(path: &str, text: &str) -> Vec<Violation> {
    if !path.ends_with(".rs") {
        return Vec::new();
    }
    code_lines_all(text)
        .filter(|(_, line)| line.contains("#[ignore") || line.contains("#[should_panic"))
        .map(|(n, _)| at(n, "#[ignore] or #[should_panic] (a test runs and says what it needs, or asserts the error)"))
        .collect()
}

/// Every line of a Rust file with comments cut off, test modules included.
fn code_lines_all(text: &str) -> impl Iterator<Item = (usize, &str)> {
    text.lines().enumerate().map(|(i, line)| (i + 1, strip_comment(line)))
}

type Rule = fn(&str, &str) -> Vec<Violation>;

const RULES: [Rule; 6] = [
    no_printing,
    unsafe_has_safety,
    cfg_windows_in_windows_folders,
    opens_with_module_doc,
    no_machine_paths,
    no_ignored_tests,
];

/// The repository's files, relative to its root.
fn tracked_files(root: &Path) -> Vec<String> {
    let listed = std::process::Command::new("git").arg("-C").arg(root).args(["ls-files", "-z"]).output();
    match listed {
        Ok(out) if out.status.success() => String::from_utf8_lossy(&out.stdout)
            .split('\0')
            .filter(|p| !p.is_empty() && root.join(p).is_file())
            .map(str::to_owned)
            .collect(),
        _ => {
            let mut files = Vec::new();
            walk(root, root, &mut files);
            files
        }
    }
}

fn walk(root: &Path, dir: &Path, out: &mut Vec<String>) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for entry in entries.flatten() {
        let path: PathBuf = entry.path();
        let name = entry.file_name().to_string_lossy().into_owned();
        if name == "target" || name.starts_with('.') {
            continue;
        }
        if path.is_dir() {
            walk(root, &path, out);
        } else if let Ok(relative) = path.strip_prefix(root) {
            out.push(relative.to_string_lossy().replace('\\', "/"));
        }
    }
}

#[test]
fn the_repository_is_tidy() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let files = tracked_files(&root);
    assert!(files.iter().any(|f| f == "shared/src/lib.rs"), "the repository's files were not found under {root:?}");
    let architecture = std::fs::read_to_string(root.join("ARCHITECTURE.md")).expect("ARCHITECTURE.md");
    let mut problems = Vec::new();
    let mut checked = 0;
    for file in &files {
        let checked_kind = [".rs", ".md", ".sh", ".ps1", ".py", ".toml", ".yml", ".yaml"];
        if !checked_kind.iter().any(|k| file.ends_with(k)) {
            continue;
        }
        let Ok(text) = std::fs::read_to_string(root.join(file)) else { continue };
        checked += 1;
        // This file's own samples break every rule on purpose (inside string literals).
        let rules: &[Rule] = if file == "tests/tests/tidy.rs" { &[opens_with_module_doc] } else { &RULES };
        for rule in rules {
            problems.extend(rule(file, &text).into_iter().map(|v| format!("{file}:{}: {}", v.line, v.rule)));
        }
        let mapped = modules_in_the_code_map(file, &text, &architecture);
        problems.extend(mapped.into_iter().map(|v| format!("{file}:{}: {}", v.line, v.rule)));
    }
    assert!(checked > 100, "only {checked} files were checked");
    assert!(problems.is_empty(), "{} tidy problems:\n{}", problems.len(), problems.join("\n"));
}

// ----- each rule catches a bad sample and accepts a good one -----

fn lines_of(violations: Vec<Violation>) -> Vec<usize> {
    violations.into_iter().map(|v| v.line).collect()
}

#[test]
fn printing_is_caught_in_libraries_only() {
    let bad = "//! A module.\nfn f() {\n    println!(\"hi\");\n    tracing::info!(\"ok\");\n    dbg!(1);\n}\n";
    assert_eq!(lines_of(no_printing("guest-server/src/a.rs", bad)), [3, 5]);
    let commented = "//! A module.\n// println!(\"in a comment\")\nlet s = \"eprintln!(x)\";\n";
    assert_eq!(lines_of(no_printing("shared/src/a.rs", commented)), Vec::<usize>::new());
    let in_tests = "//! A module.\n#[cfg(test)]\nmod tests {\n    fn f() { println!(\"x\"); }\n}\n";
    assert!(no_printing("host-client/src/a.rs", in_tests).is_empty());
    assert!(no_printing("host-client/src/cli/render.rs", bad).is_empty());
    assert!(no_printing("host-client/src/main.rs", bad).is_empty());
    assert!(no_printing("tests/src/bin/roundtrip.rs", bad).is_empty());
}

#[test]
fn unsafe_needs_a_safety_comment() {
    let bad = "fn f() {\n    let x = unsafe { g() };\n}\nunsafe impl Send for X {}\n";
    let found = unsafe_has_safety("a/src/x.rs", bad);
    assert_eq!(lines_of(found.clone()), [2, 4]);
    assert!(found[1].rule.contains("Send"));
    let good = "fn f() {\n    // SAFETY: g has no preconditions.\n    let x = unsafe { g() };\n}\n\
                /// Does h.\n///\n/// # Safety\n///\n/// p must be live.\npub unsafe fn h(p: *const u8) {}\n";
    assert!(unsafe_has_safety("a/src/x.rs", good).is_empty(), "{:?}", unsafe_has_safety("a/src/x.rs", good));
    let words = "#![warn(unsafe_op_in_unsafe_fn)]\nlet not_unsafe = 1;\n// unsafe { in a comment }\n";
    assert!(unsafe_has_safety("a/src/x.rs", words).is_empty());
}

#[test]
fn cfg_windows_belongs_in_windows_folders() {
    let text = "//! A module.\n#[cfg(windows)]\nfn a() {}\n#[cfg(not(windows))]\nfn b() {}\n#[cfg(unix)]\nfn c() {}\nlet d = cfg!(windows);\n";
    assert_eq!(lines_of(cfg_windows_in_windows_folders("guest-server/src/lib.rs", text)), [2, 4, 8]);
    let mac = "//! A module.\nlet shell = if cfg!(windows) { \"cmd\" } else { \"sh\" };\nlet u = cfg!(unix);\nlet s = \"cfg!(windows)\";\nif !cfg!(target_os = \"windows\") {}\n";
    assert_eq!(lines_of(cfg_windows_in_windows_folders("host-client/src/cli/demo.rs", mac)), [2, 5]);
    assert!(cfg_windows_in_windows_folders("guest-server/src/desktop/windows/target.rs", mac).is_empty());
    assert!(cfg_windows_in_windows_folders("guest-server/src/desktop/windows/mod.rs", text).is_empty());
    assert!(cfg_windows_in_windows_folders("guest-server/src/service/windows/scm.rs", text).is_empty());
    let any = "#[cfg(any(windows, target_os = \"macos\"))]\n";
    assert_eq!(lines_of(cfg_windows_in_windows_folders("x/src/a.rs", any)), [1]);
}

#[test]
fn modules_and_folders_must_be_in_the_code_map() {
    let architecture =
        "| `shared/` | `action`, `script::{host, compose}` |\n| `desktop/stub/` | the stub |\nnot code: missing\n";
    let root = "//! The crate.\npub mod action;\nmod missing;\npub(crate) mod script;\n#[cfg(test)]\nmod helpers;\nmod tests;\n";
    assert_eq!(lines_of(modules_in_the_code_map("shared/src/lib.rs", root, architecture)), [3]);
    let folder = "//! A folder.\nmod host;\nmod compose;\nmod extra;\n";
    assert_eq!(lines_of(modules_in_the_code_map("shared/src/script/mod.rs", folder, architecture)), [4]);
    // A file's folders must be named too; a file that is not a root declares nothing checked.
    assert_eq!(
        lines_of(modules_in_the_code_map("guest-server/src/desktop/stub/a.rs", "mod z;\n", architecture)),
        Vec::<usize>::new()
    );
    assert_eq!(lines_of(modules_in_the_code_map("guest-server/src/unmapped/a.rs", "", architecture)), [1]);
    assert!(modules_in_the_code_map("docs/x.md", root, architecture).is_empty());
}

#[test]
fn source_files_open_with_a_module_doc() {
    assert_eq!(lines_of(opens_with_module_doc("x/src/a.rs", "use std::io;\n")), [1]);
    assert!(opens_with_module_doc("x/src/a.rs", "//! What a is.\nuse std::io;\n").is_empty());
    assert!(opens_with_module_doc("x/tests/a.rs", "use std::io;\n").is_empty());
}

#[test]
fn docs_and_comments_name_no_machine_paths() {
    let rust = "//! Reads /work/shared/x.\nlet p = \"/tmp/ok-in-code\";\n// See C:\\Users\\alice\\notes.\n// C:\\Users\\Docker\\Desktop is the guest's.\n";
    assert_eq!(lines_of(no_machine_paths("a/src/x.rs", rust)), [1, 3]);
    let markdown = "Put it in `/root/cache`.\nThe guest's `C:\\Users\\Docker\\Desktop`.\n";
    assert_eq!(lines_of(no_machine_paths("docs/x.md", markdown)), [1]);
    let shell = "#!/usr/bin/env bash\n# writes /home/me/x\necho /tmp/fine\n";
    assert_eq!(lines_of(no_machine_paths("scripts/x.sh", shell)), [2]);
    assert!(no_machine_paths("data/x.json", "/work/anything").is_empty());
}

#[test]
fn tests_are_never_ignored() {
    let text = "#[test]\n#[ignore]\nfn a() {}\n#[test]\n#[should_panic(expected = \"x\")]\nfn b() {}\n// #[ignore] in a comment\n";
    assert_eq!(lines_of(no_ignored_tests("a/tests/x.rs", text)), [2, 5]);
}
