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
//!   is named in a code span of its own crate's section of `ARCHITECTURE.md` (the
//!   `## `<folder>/` (<crate>)` heading and what follows it up to the next `## `), so
//!   the code map stays whole and a module named only elsewhere does not count;
//! - no import loop between the top-level modules of a crate: an edge is a `crate::X`
//!   or `super::X` path (reaching the crate root) in a module's files, comments, test
//!   modules and test files aside; every strongly connected component of more than one
//!   module is reported (a loop that is the nature of the thing is one folder module);
//! - every crate root (`src/lib.rs`, `src/main.rs`, `src/bin/*.rs`) whose crate has no
//!   `unsafe` code says `#![forbid(unsafe_code)]`, so none creeps in unseen;
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

/// Where the library code lives (every crate's `src/` but the bench binaries'), and
/// which of it may print.
fn is_library_code(path: &str) -> bool {
    let printing_on_purpose = [
        // Binaries' entry points report to their user; the bench binaries print figures.
        "guest-server/src/main.rs",
        "guest-server/launch/src/main.rs",
        "guest-server/recorder/src/main.rs",
        "host-client/src/main.rs",
        "tests/src/",
        // The `arena` command line is the host's user interface.
        "host-client/src/cli/",
    ];
    path.ends_with(".rs")
        && path.contains("/src/")
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

/// The folder of the crate a source file belongs to (`guest-server/launch/` for
/// `guest-server/launch/src/lib.rs`), if it is under a `src/` folder.
fn crate_folder(path: &str) -> Option<String> {
    let (folder, _) = path.split_once("/src/")?;
    Some(format!("{folder}/"))
}

/// The section of `architecture` about the crate in `folder`: its `## ` heading naming
/// `` `folder` `` in a code span and the text up to the next `## ` heading.
fn crate_section<'a>(architecture: &'a str, folder: &str) -> Option<&'a str> {
    let span = format!("`{folder}`");
    let mut start = None;
    let mut offset = 0;
    for line in architecture.split_inclusive('\n') {
        if line.starts_with("## ") {
            if let Some(begin) = start {
                return Some(&architecture[begin..offset]);
            }
            if line.contains(&span) {
                start = Some(offset);
            }
        }
        offset += line.len();
    }
    start.map(|begin| &architecture[begin..])
}

/// Every module declared in a crate root or a folder's `mod.rs`, and every folder of a
/// module file, is named in a code span of its own crate's section of `architecture`.
fn modules_in_the_code_map(path: &str, text: &str, architecture: &str) -> Vec<Violation> {
    if !path.ends_with(".rs") || !path.contains("/src/") {
        return Vec::new();
    }
    let Some(section) = crate_folder(path).and_then(|folder| crate_section(architecture, &folder)) else {
        return vec![at(1, "a crate without its section in ARCHITECTURE.md (## `<folder>/` (<crate>))")];
    };
    let named = code_span_words(section);
    let mut out = Vec::new();
    if declares_top_level_modules(path) {
        for (n, module) in declared_modules(text) {
            if !named.contains(module) {
                out.push(at(
                    n,
                    "a module missing from its crate's section of ARCHITECTURE.md (name it in the code map)",
                ));
            }
        }
    }
    let (_, inside) = path.split_once("/src/").unwrap_or(("", ""));
    let folders: Vec<&str> = inside.split('/').collect();
    if folders[..folders.len() - 1].iter().any(|folder| !folder.is_empty() && !named.contains(folder)) {
        out.push(at(
            1,
            "a source folder missing from its crate's section of ARCHITECTURE.md (name it in the code map)",
        ));
    }
    out
}

// ----- test files that no target compiles -----

/// The `tests/*.rs` files of a crate whose `Cargo.toml` turns `autotests` off that are
/// neither the path of one of its `[[test]]` targets nor a module such a target
/// declares (`mod NAME;`): cargo would never compile them, and their tests would pass
/// by never running. `crate_dir` is the crate's folder (`host-client/`), `manifest`
/// its `Cargo.toml`, `files` every file of the repository.
fn unlisted_test_files(crate_dir: &str, manifest: &str, files: &Files<'_>) -> Vec<String> {
    let autotests_off = manifest.lines().any(|l| l.replace(' ', "") == "autotests=false");
    if !autotests_off {
        return Vec::new();
    }
    let roots: Vec<String> = manifest
        .lines()
        .filter_map(|l| l.trim().strip_prefix("path = \"").and_then(|r| r.strip_suffix('"')))
        .filter(|p| p.starts_with("tests/"))
        .map(|p| format!("{crate_dir}{p}"))
        .collect();
    let declared: Vec<&str> = roots
        .iter()
        .filter_map(|r| files.get(r.as_str()))
        .flat_map(|text| declared_modules(text))
        .map(|(_, m)| m)
        .collect();
    let folder = format!("{crate_dir}tests/");
    files
        .keys()
        .filter_map(|path| path.strip_prefix(folder.as_str()).map(|name| (*path, name)))
        .filter(|(_, name)| !name.contains('/'))
        .filter_map(|(path, name)| Some((path, name.strip_suffix(".rs")?)))
        .filter(|(path, name)| !roots.iter().any(|r| r == path) && !declared.contains(name))
        .map(|(path, _)| {
            format!("{path}:1: a test file no [[test]] target compiles (autotests is off: name it in tests/main.rs)")
        })
        .collect()
}

// ----- crates as module trees: import loops and `forbid(unsafe_code)` -----

/// A crate's files, by path relative to the repository, and their texts.
type Files<'a> = std::collections::BTreeMap<&'a str, &'a str>;

/// The crate roots among `files`: `src/lib.rs`, `src/main.rs`, `src/bin/NAME.rs` and
/// `src/bin/NAME/main.rs`.
fn crate_roots<'a>(files: &Files<'a>) -> Vec<&'a str> {
    files
        .keys()
        .copied()
        .filter(|path| {
            let Some((_, inside)) = path.split_once("/src/") else { return false };
            let bin = inside.strip_prefix("bin/");
            inside == "lib.rs"
                || inside == "main.rs"
                || bin.is_some_and(|b| (b.ends_with(".rs") && !b.contains('/')) || b.ends_with("/main.rs"))
        })
        .collect()
}

/// The folder a module file's children live in: `src/` for a crate root or a
/// `mod.rs`, `src/a/` for `src/a.rs`.
fn children_folder(path: &str, is_root: bool) -> String {
    let (dir, name) = path.rsplit_once('/').unwrap_or(("", path));
    if is_root || name == "mod.rs" {
        format!("{dir}/")
    } else {
        format!("{dir}/{}/", name.trim_end_matches(".rs"))
    }
}

/// The modules `text` declares (`mod NAME;`, test modules aside) with the files they
/// are in, `#[path]` attributes followed.
fn declared_module_files<'a>(path: &str, text: &str, is_root: bool, files: &Files<'a>) -> Vec<(String, &'a str)> {
    let mut out = Vec::new();
    let lines: Vec<&str> = text.lines().collect();
    for (n, name) in declared_modules(text) {
        let attribute = lines.get(n.wrapping_sub(2)).map(|l| l.trim()).unwrap_or("");
        let candidates = match attribute.strip_prefix("#[path = \"").and_then(|a| a.strip_suffix("\"]")) {
            Some(relative) => {
                let dir = path.rsplit_once('/').map_or("", |(d, _)| d);
                vec![normalize(&format!("{dir}/{relative}"))]
            }
            None => {
                let folder = children_folder(path, is_root);
                vec![format!("{folder}{name}.rs"), format!("{folder}{name}/mod.rs")]
            }
        };
        if let Some(found) = candidates.iter().find_map(|c| files.get_key_value(c.as_str()).map(|(k, _)| *k)) {
            out.push((name.to_owned(), found));
        }
    }
    out
}

/// `path` with its `..` and `.` components resolved.
fn normalize(path: &str) -> String {
    let mut parts: Vec<&str> = Vec::new();
    for part in path.split('/') {
        match part {
            ".." => {
                parts.pop();
            }
            "." | "" => {}
            other => parts.push(other),
        }
    }
    parts.join("/")
}

/// A module of a crate: its path below the crate root (empty for the root), its own
/// file, and its child modules.
struct ModuleNode<'a> {
    path: Vec<String>,
    file: &'a str,
    children: Vec<ModuleNode<'a>>,
}

impl<'a> ModuleNode<'a> {
    /// The module tree of the crate rooted at `root`.
    fn of_crate(root: &'a str, files: &Files<'a>) -> ModuleNode<'a> {
        fn grow<'a>(node: &mut ModuleNode<'a>, files: &Files<'a>) {
            let is_root = node.path.is_empty();
            for (name, file) in declared_module_files(node.file, files[node.file], is_root, files) {
                let mut path = node.path.clone();
                path.push(name);
                let mut child = ModuleNode { path, file, children: Vec::new() };
                grow(&mut child, files);
                node.children.push(child);
            }
        }
        let mut node = ModuleNode { path: Vec::new(), file: root, children: Vec::new() };
        if files.contains_key(root) {
            grow(&mut node, files);
        }
        node
    }

    /// This module's files and those of every module below it, each with its depth
    /// below the crate root (the length of its module path).
    fn all_files(&self) -> Vec<(&'a str, usize)> {
        let mut out = vec![(self.file, self.path.len())];
        for child in &self.children {
            out.extend(child.all_files());
        }
        out
    }

    /// Every module of the tree, this one first.
    fn all_modules(&self) -> Vec<&ModuleNode<'a>> {
        let mut out = vec![self];
        for child in &self.children {
            out.extend(child.all_modules());
        }
        out
    }
}

/// `text` without comments, string contents and `#[cfg(test)]` modules.
fn code_without_tests(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut lines = text.lines().map(|l| strip_strings(strip_comment(l))).peekable();
    while let Some(line) = lines.next() {
        if line.trim() == "#[cfg(test)]" {
            let next = lines.peek().map(|l| l.trim().to_owned()).unwrap_or_default();
            let is_module =
                ["mod ", "pub mod ", "pub(crate) mod ", "pub(super) mod "].iter().any(|p| next.starts_with(p));
            if is_module {
                let mut depth = 0i64;
                let mut opened = false;
                for line in lines.by_ref() {
                    depth += line.matches('{').count() as i64 - line.matches('}').count() as i64;
                    opened |= line.contains('{');
                    if (opened && depth <= 0) || (!opened && line.trim_end().ends_with(';')) {
                        break;
                    }
                }
                continue;
            }
        }
        out.push_str(&line);
        out.push('\n');
    }
    out
}

/// The first names of the paths in a `{...}` group starting at `group` (just after
/// its `{`), at its own level only.
fn group_heads(group: &str) -> Vec<&str> {
    let mut heads = Vec::new();
    let mut depth = 0;
    let mut expect_head = true;
    let mut start = None;
    for (i, c) in group.char_indices() {
        let word = c.is_alphanumeric() || c == '_';
        if word {
            if start.is_none() && expect_head && depth == 0 {
                start = Some(i);
            }
            continue;
        }
        if let Some(s) = start.take() {
            heads.push(&group[s..i]);
        }
        match c {
            '{' => depth += 1,
            '}' if depth == 0 => break,
            '}' => depth -= 1,
            ',' if depth == 0 => {
                expect_head = true;
                continue;
            }
            _ => {}
        }
        if !c.is_whitespace() {
            expect_head = false;
        }
    }
    heads
}

/// The children of the module at `parent` (a path below the crate root) that a file
/// at `depth` below the crate root names: `crate::<parent>::X`, `crate::<parent>::{X, Y}`,
/// and `super::` chains that reach `parent`. With an empty `parent`: the top-level modules.
fn named_children<'c>(code: &'c str, depth: usize, parent: &[String]) -> Vec<&'c str> {
    let mut out = Vec::new();
    let word_start = |i: usize| i == 0 || !code[..i].ends_with(|c: char| c.is_alphanumeric() || c == '_' || c == ':');
    let mut after_parent = Vec::new();
    for (i, _) in code.match_indices("crate::") {
        if !word_start(i) {
            continue;
        }
        let mut at = i + "crate::".len();
        let reached = parent.iter().all(|component| {
            let step = format!("{component}::");
            let rest = &code[at..];
            let ok = rest.starts_with(&step);
            if ok {
                at += step.len();
            }
            ok
        });
        if reached {
            after_parent.push(at);
        }
    }
    for (i, _) in code.match_indices("super::") {
        if !word_start(i) {
            continue;
        }
        let mut end = i;
        let mut levels = 0;
        while code[end..].starts_with("super::") {
            end += "super::".len();
            levels += 1;
        }
        if depth.checked_sub(levels) == Some(parent.len()) {
            after_parent.push(end);
        }
    }
    for start in after_parent {
        let rest = &code[start..];
        if let Some(group) = rest.strip_prefix('{') {
            out.extend(group_heads(group));
        } else {
            let len = rest.find(|c: char| !(c.is_alphanumeric() || c == '_')).unwrap_or(rest.len());
            if len > 0 {
                out.push(&rest[..len]);
            }
        }
    }
    out
}

/// The strongly connected components of more than one node (Tarjan's algorithm),
/// each sorted, in a stable order.
fn loops(edges: &std::collections::BTreeMap<String, std::collections::BTreeSet<String>>) -> Vec<Vec<String>> {
    struct Walk<'a> {
        edges: &'a std::collections::BTreeMap<String, std::collections::BTreeSet<String>>,
        index: std::collections::HashMap<&'a str, usize>,
        low: std::collections::HashMap<&'a str, usize>,
        stack: Vec<&'a str>,
        on_stack: std::collections::HashSet<&'a str>,
        found: Vec<Vec<String>>,
    }
    impl<'a> Walk<'a> {
        fn visit(&mut self, v: &'a str) {
            let n = self.index.len();
            self.index.insert(v, n);
            self.low.insert(v, n);
            self.stack.push(v);
            self.on_stack.insert(v);
            for w in self.edges.get(v).into_iter().flatten() {
                let w = w.as_str();
                if !self.index.contains_key(w) {
                    self.visit(w);
                    let low = self.low[v].min(self.low[w]);
                    self.low.insert(v, low);
                } else if self.on_stack.contains(w) {
                    let low = self.low[v].min(self.index[w]);
                    self.low.insert(v, low);
                }
            }
            if self.low[v] == self.index[v] {
                let mut component = Vec::new();
                while let Some(w) = self.stack.pop() {
                    self.on_stack.remove(w);
                    component.push(w.to_owned());
                    if w == v {
                        break;
                    }
                }
                if component.len() > 1 {
                    component.sort();
                    self.found.push(component);
                }
            }
        }
    }
    let mut walk = Walk {
        edges,
        index: Default::default(),
        low: Default::default(),
        stack: Vec::new(),
        on_stack: Default::default(),
        found: Vec::new(),
    };
    for v in edges.keys() {
        if !walk.index.contains_key(v.as_str()) {
            walk.visit(v);
        }
    }
    walk.found.sort();
    walk.found
}

/// The import loops of the crate rooted at `root`, at every depth: between the
/// top-level modules, and between the child modules of any folder module (a loop
/// inside `agent/` counts as much as one between `agent` and `run`), each as a line
/// naming the module, the loop's members and their edges.
fn import_loops(root: &str, files: &Files<'_>) -> Vec<String> {
    let tree = ModuleNode::of_crate(root, files);
    let mut found = Vec::new();
    for parent in tree.all_modules() {
        if parent.children.len() < 2 {
            continue;
        }
        let names: std::collections::BTreeSet<&str> =
            parent.children.iter().filter_map(|c| c.path.last().map(String::as_str)).collect();
        let mut edges: std::collections::BTreeMap<String, std::collections::BTreeSet<String>> = Default::default();
        for child in &parent.children {
            let name = child.path.last().cloned().unwrap_or_default();
            let targets = edges.entry(name.clone()).or_default();
            for (path, depth) in child.all_files() {
                if is_test_file(path) || path.contains("/tests/") {
                    continue;
                }
                let code = code_without_tests(files[path]);
                for target in named_children(&code, depth, &parent.path) {
                    if target != name && names.contains(target) {
                        targets.insert(target.to_owned());
                    }
                }
            }
        }
        let place = if parent.path.is_empty() { String::new() } else { format!(" in {}", parent.path.join("::")) };
        for component in loops(&edges) {
            let inside = |m: &String| {
                let to: Vec<&str> = edges[m].iter().filter(|t| component.contains(t)).map(String::as_str).collect();
                format!("{m} -> {}", to.join(", "))
            };
            found.push(format!(
                "import loop{place} between {}: {}",
                component.join(", "),
                component.iter().map(inside).collect::<Vec<_>>().join("; ")
            ));
        }
    }
    found
}

/// Whether `text` has `unsafe` code (a block, function, impl or extern block).
fn has_unsafe(text: &str) -> bool {
    text.lines().map(|l| strip_strings(strip_comment(l))).any(|line| {
        line.match_indices("unsafe").any(|(pos, _)| {
            let word_start = pos == 0 || !line[..pos].ends_with(|c: char| c.is_alphanumeric() || c == '_');
            let after = line[pos + "unsafe".len()..].trim_start();
            word_start
                && (after.starts_with('{')
                    || after.starts_with("fn ")
                    || after.starts_with("impl")
                    || after.starts_with("extern"))
        })
    })
}

/// A crate root whose crate has no `unsafe` code and that does not forbid it.
fn forbids_unsafe_where_none(root: &str, files: &Files<'_>) -> Option<&'static str> {
    let text = files.get(root)?;
    let any_unsafe = ModuleNode::of_crate(root, files).all_files().into_iter().any(|(path, _)| has_unsafe(files[path]));
    let forbids = text.lines().any(|l| l.trim() == "#![forbid(unsafe_code)]");
    (!any_unsafe && !forbids).then_some("a crate without unsafe code whose root does not say #![forbid(unsafe_code)]")
}

/// The longest line the code map may have, in characters: a map whose lines run
/// on restates behaviour, which is what drifts; a long line is a sign to say less.
const CODE_MAP_LINE: usize = 400;

/// Lines of ARCHITECTURE.md longer than [`CODE_MAP_LINE`] characters.
fn code_map_lines(path: &str, text: &str) -> Vec<Violation> {
    if path != "ARCHITECTURE.md" {
        return Vec::new();
    }
    text.lines()
        .enumerate()
        .filter(|(_, line)| line.chars().count() > CODE_MAP_LINE)
        .map(|(i, _)| at(i + 1, "a line of the code map over 400 characters: say less, or split it"))
        .collect()
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

const RULES: [Rule; 7] = [
    no_printing,
    unsafe_has_safety,
    cfg_windows_in_windows_folders,
    opens_with_module_doc,
    no_machine_paths,
    no_ignored_tests,
    code_map_lines,
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
    let sources: Vec<(String, String)> = files
        .iter()
        .filter(|f| f.ends_with(".rs"))
        .filter_map(|f| Some((f.clone(), std::fs::read_to_string(root.join(f)).ok()?)))
        .collect();
    let sources: Files<'_> = sources.iter().map(|(p, t)| (p.as_str(), t.as_str())).collect();
    for crate_root in crate_roots(&sources) {
        problems.extend(import_loops(crate_root, &sources).into_iter().map(|l| format!("{crate_root}: {l}")));
        problems.extend(forbids_unsafe_where_none(crate_root, &sources).map(|rule| format!("{crate_root}:1: {rule}")));
    }
    for (manifest_path, manifest) in files
        .iter()
        .filter(|f| f.ends_with("Cargo.toml"))
        .filter_map(|f| Some((f.as_str(), std::fs::read_to_string(root.join(f)).ok()?)))
    {
        let crate_dir = manifest_path.strip_suffix("Cargo.toml").unwrap_or_default();
        problems.extend(unlisted_test_files(crate_dir, &manifest, &sources));
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
fn modules_and_folders_must_be_in_their_crates_section() {
    let architecture = "# Map\n\nIntro naming `elsewhere` and `missing`.\n\n\
        ## `shared/` (arena-shared)\n\n| `action`, `script::{host, compose}` |\n| `desktop/stub/` | the stub |\nnot code: missing\n\n\
        ## `guest-server/` (arena-guest)\n\n| `desktop/`, `stub/`, `elsewhere` |\n\n\
        ## `tests/` (arena-tests) and `tests/support/` (arena-test-support)\n\n| `guest` |\n";
    let root = "//! The crate.\npub mod action;\nmod missing;\npub(crate) mod script;\n#[cfg(test)]\nmod helpers;\nmod tests;\n";
    assert_eq!(lines_of(modules_in_the_code_map("shared/src/lib.rs", root, architecture)), [3]);
    let folder = "//! A folder.\nmod host;\nmod compose;\nmod extra;\n";
    assert_eq!(lines_of(modules_in_the_code_map("shared/src/script/mod.rs", folder, architecture)), [4]);
    // Named in another crate's section, or outside any section: not named.
    let other = "//! The crate.\nmod elsewhere;\nmod action;\n";
    assert_eq!(lines_of(modules_in_the_code_map("shared/src/lib.rs", other, architecture)), [2]);
    assert_eq!(lines_of(modules_in_the_code_map("guest-server/src/lib.rs", other, architecture)), [3]);
    // A crate whose section's heading names it with another crate.
    assert!(modules_in_the_code_map("tests/support/src/lib.rs", "//! x\nmod guest;\n", architecture).is_empty());
    // A file's folders must be named too; a file that is not a root declares nothing checked.
    assert_eq!(
        lines_of(modules_in_the_code_map("guest-server/src/desktop/stub/a.rs", "mod z;\n", architecture)),
        Vec::<usize>::new()
    );
    assert_eq!(lines_of(modules_in_the_code_map("guest-server/src/unmapped/a.rs", "", architecture)), [1]);
    // `shared/script/` is another crate than `shared/`, and has no section here.
    let found = modules_in_the_code_map("shared/script/src/lib.rs", root, architecture);
    assert_eq!(lines_of(found.clone()), [1]);
    assert!(found[0].rule.contains("without its section"));
    assert!(modules_in_the_code_map("docs/x.md", root, architecture).is_empty());
}

fn files_of<'a>(files: &'a [(&'a str, &'a str)]) -> Files<'a> {
    files.iter().copied().collect()
}

#[test]
fn import_loops_between_top_level_modules_are_caught() {
    let crate_files = [
        ("x/src/lib.rs", "//! Root.\npub mod a;\nmod b;\nmod c;\nmod d;\nmod e;\n#[cfg(test)]\nmod tests;\n"),
        // a -> b through a grouped `use` over two lines.
        ("x/src/a.rs", "//! A.\nuse crate::{\n    b::Thing,\n    e,\n};\n"),
        // b -> a through `super::` in a folder module's own file.
        ("x/src/b/mod.rs", "//! B.\nmod inner;\npub(crate) use super::a::f;\n"),
        // c -> d from a child file, two levels down: `super::super::d`.
        ("x/src/c.rs", "//! C.\nmod deep;\n"),
        ("x/src/c/deep.rs", "//! Deep.\nfn g() { super::super::d::h() }\n"),
        // d -> c in a comment, a string and a test module only: no edge.
        (
            "x/src/d.rs",
            "//! D, which never says crate::c.\n// crate::c::x\nconst S: &str = \"crate::c\";\n\
             #[cfg(test)]\nmod tests {\n    use crate::c;\n}\npub fn h() {}\n",
        ),
        // e -> c -> d: no loop; a file named tests.rs is test code.
        ("x/src/e.rs", "//! E.\nuse crate::c as _;\n"),
        ("x/src/b/inner.rs", "//! Inner: `super::` is b here.\nuse super::Thing;\n"),
        ("x/src/tests.rs", "use crate::{a, b, c, d, e};\n"),
    ];
    let files = files_of(&crate_files);
    let found = import_loops("x/src/lib.rs", &files);
    assert_eq!(found, ["import loop between a, b: a -> b; b -> a"], "{found:?}");
    // Three modules in a ring, with a `#[path]` module.
    let ring = [
        ("y/src/main.rs", "//! Bin.\nmod p;\n#[path = \"q_impl.rs\"]\nmod q;\nmod r;\n"),
        ("y/src/p.rs", "//! P.\nuse crate::q;\n"),
        ("y/src/q_impl.rs", "//! Q.\nuse crate::r::x;\n"),
        ("y/src/r.rs", "//! R.\nuse super::p;\n"),
    ];
    let found = import_loops("y/src/main.rs", &files_of(&ring));
    assert_eq!(found, ["import loop between p, q, r: p -> q; q -> r; r -> p"], "{found:?}");
    assert_eq!(crate_roots(&files_of(&ring)), ["y/src/main.rs"]);
}

#[test]
fn import_loops_inside_a_folder_module_are_caught() {
    let nested = [
        (
            "z/src/lib.rs",
            "//! Root.
pub mod agent;
pub mod run;
",
        ),
        (
            "z/src/agent/mod.rs",
            "//! Agent.
pub mod body;
pub mod llm;
pub mod external;
pub mod cu;
",
        ),
        // body -> llm by its full path from the crate root.
        (
            "z/src/agent/body.rs",
            "//! Body.
use crate::agent::llm::Client;
",
        ),
        // llm -> external through `super::`.
        (
            "z/src/agent/llm.rs",
            "//! Llm.
use super::external::transport;
",
        ),
        // external -> body from a file one level further down: `super::super::body`.
        (
            "z/src/agent/external/mod.rs",
            "//! External.
pub mod transport;
",
        ),
        (
            "z/src/agent/external/transport.rs",
            "//! Transport.
use super::super::body::read;
",
        ),
        // Two levels down: cu's children a and m name each other; a grouped use.
        (
            "z/src/agent/cu/mod.rs",
            "//! Cu.
mod anthropic;
mod models;
",
        ),
        (
            "z/src/agent/cu/anthropic.rs",
            "//! A.
use crate::agent::cu::{models::Row, anthropic as _};
",
        ),
        (
            "z/src/agent/cu/models.rs",
            "//! M.
use super::anthropic::Tool;
",
        ),
        // run names agent and agent names nothing above it: no top-level loop.
        (
            "z/src/run.rs",
            "//! Run.
use crate::agent::body;
",
        ),
    ];
    let found = import_loops("z/src/lib.rs", &files_of(&nested));
    assert_eq!(
        found,
        [
            "import loop in agent between body, external, llm: body -> llm; external -> body; llm -> external",
            "import loop in agent::cu between anthropic, models: anthropic -> models; models -> anthropic",
        ],
        "{found:?}"
    );
    // Without the edge back, nothing.
    let mut fixed = nested;
    fixed[5] = ("z/src/agent/external/transport.rs", "//! Transport.\n");
    fixed[8] = (
        "z/src/agent/cu/models.rs",
        "//! M.
",
    );
    assert!(import_loops("z/src/lib.rs", &files_of(&fixed)).is_empty());
}

#[test]
fn the_code_map_has_no_overlong_line() {
    let map = format!("# Architecture\n\nshort\n{}\nshort again\n{}\n", "x".repeat(401), "y".repeat(400));
    assert_eq!(lines_of(code_map_lines("ARCHITECTURE.md", &map)), [4]);
    // Other Markdown files are not the code map.
    assert!(code_map_lines("docs/x.md", &"z".repeat(900)).is_empty());
    // Characters, not bytes: 400 accented letters are within the limit.
    assert!(code_map_lines("ARCHITECTURE.md", &"é".repeat(400)).is_empty());
}

#[test]
fn crates_without_unsafe_code_forbid_it() {
    let safe =
        [("s/src/lib.rs", "//! Safe.\nmod m;\n"), ("s/src/m.rs", "//! M.\n// unsafe { in a comment }\nfn f() {}\n")];
    let found = forbids_unsafe_where_none("s/src/lib.rs", &files_of(&safe));
    assert!(found.is_some_and(|rule| rule.contains("forbid(unsafe_code)")));
    let forbidden = [("s/src/lib.rs", "//! Safe.\n\n#![forbid(unsafe_code)]\nmod m;\n"), ("s/src/m.rs", "//! M.\n")];
    assert_eq!(forbids_unsafe_where_none("s/src/lib.rs", &files_of(&forbidden)), None);
    // Unsafe code in a module (a test module counts) excuses the root.
    let not_safe = [
        ("u/src/lib.rs", "//! Unsafe inside.\nmod m;\n"),
        (
            "u/src/m.rs",
            "//! M.\n#[cfg(test)]\nmod tests {\n    // SAFETY: none needed.\n    fn f() { unsafe { g() } }\n}\n",
        ),
    ];
    assert_eq!(forbids_unsafe_where_none("u/src/lib.rs", &files_of(&not_safe)), None);
    let bins = [("t/src/bin/bench.rs", "//! A bench.\nfn main() {}\n"), ("t/src/bin/other/main.rs", "//! Other.\n")];
    assert_eq!(crate_roots(&files_of(&bins)), ["t/src/bin/bench.rs", "t/src/bin/other/main.rs"]);
    assert!(forbids_unsafe_where_none("t/src/bin/bench.rs", &files_of(&bins)).is_some());
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

#[test]
fn a_test_file_no_target_compiles_is_caught() {
    let manifest = "[package]\nname = \"x\"\nautotests = false\n\n[[test]]\nname = \"suite\"\npath = \"tests/main.rs\"\n\n[[test]]\nname = \"alone\"\npath = \"tests/alone.rs\"\n";
    let files = [
        ("x/tests/main.rs", "//! Suite.\npub mod listed;\n"),
        ("x/tests/listed.rs", "//! Listed.\n"),
        ("x/tests/alone.rs", "//! Alone.\n"),
        ("x/tests/forgotten.rs", "//! Forgotten.\n"),
        ("x/tests/listed/helper.rs", "//! A module of listed.\n"),
    ];
    let found = unlisted_test_files("x/", manifest, &files_of(&files));
    assert_eq!(found.len(), 1, "{found:?}");
    assert!(found[0].starts_with("x/tests/forgotten.rs:1: "), "{found:?}");
    // With cargo's own discovery every file is a target of its own.
    let auto = manifest.replace("autotests = false\n", "");
    assert!(unlisted_test_files("x/", &auto, &files_of(&files)).is_empty());
}
