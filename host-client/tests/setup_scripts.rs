//! The PowerShell of `setup-scripts/` parses and follows the house rules, checked
//! on Linux with tree-sitter and the tree-sitter-powershell grammar (no PowerShell
//! needed): no `ERROR` or `MISSING` node, a `param()` block before any other code,
//! and `Set-StrictMode -Version Latest` and `$ErrorActionPreference = 'Stop'` as the
//! first two statements after it. The checker is shown to fail on broken samples.
//!
//! The other files of the folder are checked for what a typo would break on the
//! VM: the answer-file snippet is well-formed XML that runs `C:\OEM\install.bat`,
//! `install.bat` has Windows line endings and runs `setup.ps1`, and `apps.json`
//! covers the applications the task corpus uses.

use std::path::{Path, PathBuf};

use tree_sitter::{Node, Parser};

fn scripts_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join("setup-scripts")
}

fn ps1_files(dir: &Path) -> Vec<PathBuf> {
    let mut found = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap_or_else(|err| panic!("listing {}: {err}", dir.display())) {
        let path = entry.expect("directory entry").path();
        if path.is_dir() {
            found.extend(ps1_files(&path));
        } else if path.extension().is_some_and(|e| e.eq_ignore_ascii_case("ps1")) {
            found.push(path);
        }
    }
    found.sort();
    found
}

/// Every syntax problem (`ERROR` and `MISSING` nodes) with its line.
fn syntax_problems(node: Node<'_>, out: &mut Vec<String>) {
    if node.is_error() {
        out.push(format!("line {}: syntax error", node.start_position().row + 1));
    } else if node.is_missing() {
        out.push(format!("line {}: missing {}", node.start_position().row + 1, node.kind()));
    }
    if node.has_error() {
        let mut cursor = node.walk();
        for child in node.children(&mut cursor) {
            syntax_problems(child, out);
        }
    }
}

/// A statement's text with runs of whitespace folded and case ignored, for comparing.
fn normalized(text: &str) -> String {
    text.split_whitespace().collect::<Vec<_>>().join(" ").to_ascii_lowercase()
}

/// Everything wrong with one script; empty when it passes.
fn check_script(source: &str) -> Vec<String> {
    let mut parser = Parser::new();
    parser.set_language(&tree_sitter_powershell::LANGUAGE.into()).expect("the PowerShell grammar loads");
    let Some(tree) = parser.parse(source, None) else {
        return vec!["the parser gave no tree".into()];
    };
    let root = tree.root_node();
    let mut problems = Vec::new();
    syntax_problems(root, &mut problems);

    let mut cursor = root.walk();
    let top: Vec<Node<'_>> = root.named_children(&mut cursor).filter(|n| n.kind() != "comment").collect();
    if top.first().map(Node::kind) != Some("param_block") {
        problems.push("no param() block before the first statement".into());
    }
    // The statements after the param block, comments left out.
    let statements: Vec<String> = top
        .iter()
        .filter(|n| n.kind() == "statement_list")
        .flat_map(|list| {
            let mut c = list.walk();
            list.named_children(&mut c).filter(|n| n.kind() != "comment").collect::<Vec<_>>()
        })
        .map(|n| normalized(n.utf8_text(source.as_bytes()).unwrap_or("")))
        .collect();
    let first_two: Vec<&str> = statements.iter().take(2).map(String::as_str).collect();
    if !first_two.contains(&"set-strictmode -version latest") {
        problems.push("`Set-StrictMode -Version Latest` is not one of the first two statements".into());
    }
    if !first_two.iter().any(|s| *s == "$erroractionpreference = 'stop'" || *s == "$erroractionpreference = \"stop\"") {
        problems.push("`$ErrorActionPreference = 'Stop'` is not one of the first two statements".into());
    }
    problems
}

/// `source` passes when `expected` is empty, else fails with a problem containing each string.
fn check(source: &str, expected: &[&str]) {
    let problems = check_script(source);
    if expected.is_empty() {
        assert!(problems.is_empty(), "expected no problems, got {problems:?} for:\n{source}");
    }
    for want in expected {
        assert!(
            problems.iter().any(|p| p.contains(want)),
            "expected a problem with {want:?}, got {problems:?} for:\n{source}"
        );
    }
}

#[test]
fn every_setup_script_parses_and_follows_the_house_rules() {
    let files = ps1_files(&scripts_dir());
    let names: Vec<String> =
        files.iter().filter_map(|p| p.file_name()).map(|n| n.to_string_lossy().into_owned()).collect();
    for required in [
        "install-guest.ps1",
        "uninstall-guest.ps1",
        "setup.ps1",
        "prep-autologon.ps1",
        "prep-apps.ps1",
        "prep-automation.ps1",
        "prep-display.ps1",
        "prep-browser.ps1",
    ] {
        assert!(names.iter().any(|n| n == required), "{required} is missing from setup-scripts (found {names:?})");
    }
    let mut failures = Vec::new();
    for file in &files {
        let source = std::fs::read_to_string(file).unwrap_or_else(|err| panic!("reading {}: {err}", file.display()));
        for problem in check_script(&source) {
            failures.push(format!("{}: {problem}", file.display()));
        }
    }
    assert!(failures.is_empty(), "setup scripts break the rules:\n{}", failures.join("\n"));
}

#[test]
fn the_checker_accepts_a_good_script_and_refuses_broken_ones() {
    let good = "<# help #>\n[CmdletBinding()]\nparam([string]$Name = 'x')\n\nSet-StrictMode -Version Latest\n$ErrorActionPreference = 'Stop'\nWrite-Host $Name\n";
    check(good, &[]);
    // An unclosed block: the grammar reports an error or a missing token.
    check(
        "param()\nSet-StrictMode -Version Latest\n$ErrorActionPreference = 'Stop'\nif ($true) {\n    Write-Host 'never closed'\n",
        &["line "],
    );
    // An unterminated string.
    check("param()\nSet-StrictMode -Version Latest\n$ErrorActionPreference = 'Stop'\nWrite-Host 'oops\n", &["line "]);
    check("Set-StrictMode -Version Latest\n$ErrorActionPreference = 'Stop'\nWrite-Host hi\n", &["no param() block"]);
    check("param()\n$ErrorActionPreference = 'Stop'\nWrite-Host hi\n", &["Set-StrictMode"]);
    check("param()\nSet-StrictMode -Version 2\n$ErrorActionPreference = 'Stop'\n", &["Set-StrictMode"]);
    check("param()\nSet-StrictMode -Version Latest\n$ErrorActionPreference = 'Continue'\n", &["ErrorActionPreference"]);
    // Strict mode set only after other code has already run does not count.
    check(
        "param()\nWrite-Host first\nWrite-Host second\nSet-StrictMode -Version Latest\n$ErrorActionPreference = 'Stop'\n",
        &["Set-StrictMode", "ErrorActionPreference"],
    );
}

#[test]
fn the_answer_file_snippet_runs_install_bat_at_first_logon() {
    let path = scripts_dir().join("unattend").join("autounattend-snippet.xml");
    let text = std::fs::read_to_string(&path).unwrap_or_else(|err| panic!("reading {}: {err}", path.display()));
    let doc = roxmltree::Document::parse(&text)
        .unwrap_or_else(|err| panic!("{} is not well-formed XML: {err}", path.display()));
    let commands: Vec<&str> =
        doc.descendants().filter(|n| n.has_tag_name("CommandLine")).filter_map(|n| n.text()).collect();
    assert!(
        commands.iter().any(|c| c.contains(r"C:\OEM\install.bat")),
        "no FirstLogonCommand runs C:\\OEM\\install.bat: {commands:?}"
    );
    let logon_user = doc
        .descendants()
        .find(|n| n.has_tag_name("AutoLogon"))
        .and_then(|n| n.children().find(|c| c.has_tag_name("Username")))
        .and_then(|n| n.text());
    assert_eq!(logon_user, Some("Docker"));
}

#[test]
fn install_bat_runs_setup_with_the_policy_bypassed_and_logs_its_exit_code() {
    let bytes = std::fs::read(scripts_dir().join("install.bat")).expect("install.bat");
    let text = String::from_utf8(bytes).expect("install.bat is ASCII");
    assert!(
        text.split('\n').all(|l| l.is_empty() || l.ends_with('\r')),
        "install.bat must have CRLF line endings for cmd.exe"
    );
    assert!(
        text.contains("-ExecutionPolicy Bypass") && text.contains("-NoProfile") && text.contains("setup.ps1"),
        "{text}"
    );
    assert!(
        text.contains("%ERRORLEVEL%")
            && text.contains(r"%ProgramData%\arena\logs\install.log")
            && text.contains("exit /b %RC%"),
        "{text}"
    );
}

#[test]
fn the_app_manifest_covers_the_task_corpus() {
    let text = std::fs::read_to_string(scripts_dir().join("apps.json")).expect("apps.json");
    let manifest: serde_json::Value = serde_json::from_str(&text).expect("apps.json is JSON");
    let apps = manifest["apps"].as_array().expect("an apps array");
    let mut names = Vec::new();
    for app in apps {
        let name = app["name"].as_str().expect("every app has a name");
        assert!(app["file"].as_str().is_some_and(|f| !f.is_empty()), "{name}: no installer file name");
        assert!(
            app["url"].as_str().is_some_and(|u| u.starts_with("https://")),
            "{name}: the download URL must be https"
        );
        assert!(matches!(app["kind"].as_str(), Some("exe" | "msi")), "{name}: kind must be exe or msi");
        assert!(
            app["detect"].as_array().is_some_and(|d| !d.is_empty()),
            "{name}: no detect paths, so it would be reinstalled every run"
        );
        names.push(name.to_ascii_lowercase());
    }
    // Edge, Paint, Notepad, Clock, Calculator and Settings come with Windows 11.
    for needed in ["libreoffice", "vlc", "visual studio code", "chrome", "7-zip", "gimp"] {
        assert!(names.iter().any(|n| n.contains(needed)), "apps.json lacks {needed} (has {names:?})");
    }
}
