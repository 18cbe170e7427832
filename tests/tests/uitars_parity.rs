//! The `ui-tars` agent's reply parser against ByteDance's published one (the
//! `ui-tars` PyPI package), on a corpus of replies written for this test
//! (`uitars_parity/corpus.json`: every action, every coordinate and box form,
//! odd spacing and quoting, several calls in one reply, thoughts, UI-TARS 1.0 and
//! 1.5 coordinates, several screen sizes).
//!
//! `uitars_parity/package.py` runs the package's `parse_action_to_structure_output`
//! and `parsing_response_to_pyautogui_code` on each reply; its pyautogui code is
//! translated by our `pyautogui` action space (pyautogui's own semantics: `int()`
//! truncation, key names) and compared, step by step, with what our `uitars`
//! action space makes of the same reply, and so are the thoughts. An entry's
//! `expect` is `same`, or the name of a difference listed in
//! `docs/compatibility.md` (with which way it moves scores): a difference that is
//! not named, or a named one that is gone, fails the test.
//!
//! Needs a Python with `ui-tars`: `ARENA_UI_TARS_PYTHON`, else `python3` when it
//! has it; without one `SKIPPED: <test>: ui-tars not installed` (counted by
//! `./test.sh`), a failure with `ARENA_REQUIRE_UI_TARS=1`. `.ci/run` installs it.

#![cfg(unix)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

// The one place this test reaches into the host's crate: the two action spaces.
use arena_actionspace::{parse as parse_space, uitars, ActionSpace, Context, Coords, Step};
use serde_json::Value;

fn here() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/uitars_parity")
}

/// ByteDance's published `ui-tars` parser; without it, a loud skip (a failure with
/// `ARENA_REQUIRE_UI_TARS=1`).
const UI_TARS: arena_test_support::PythonNeed = arena_test_support::PythonNeed {
    python_var: "ARENA_UI_TARS_PYTHON",
    require_var: "ARENA_REQUIRE_UI_TARS",
    imports: "import ui_tars.action_parser",
    what: "ui_tars",
    reason: "ui-tars not installed",
};

/// What one parser made of a reply: its steps and thought, or why it refused.
type Outcome = Result<(Vec<Step>, Option<String>), String>;

fn ours(entry: &Value) -> Outcome {
    let screen = screen(entry);
    let version = if entry["version"] == "1.0" { uitars::UiTarsVersion::V1 } else { uitars::UiTarsVersion::V1_5 };
    let ctx = Context::new(screen, version.coords(screen));
    let reply = uitars::parse(entry["reply"].as_str().expect("reply"), &ctx).map_err(|e| e.to_string())?;
    Ok((reply.steps, reply.thought))
}

fn theirs(entry: &Value, answer: &Value) -> Outcome {
    if let Some(error) = answer["error"].as_str() {
        return Err(format!("the package raised {error}"));
    }
    let code = answer["code"].as_str().expect("code");
    let ctx = Context::new(screen(entry), Coords::Pixels);
    let steps = parse_space(ActionSpace::Pyautogui, &Value::from(code), &ctx)
        .map_err(|e| format!("its code does not run as pyautogui: {e}"))?;
    Ok((steps, answer["thought"].as_str().map(str::to_owned)))
}

fn screen(entry: &Value) -> (u32, u32) {
    let size = |i: usize| entry["screen"][i].as_u64().and_then(|v| u32::try_from(v).ok()).expect("screen");
    (size(0), size(1))
}

#[test]
fn our_uitars_parser_agrees_with_the_published_package() {
    let test = "our_uitars_parser_agrees_with_the_published_package";
    let Some(python) = UI_TARS.find(test) else { return };
    let corpus_path = here().join("corpus.json");
    let corpus: Value = serde_json::from_str(&std::fs::read_to_string(&corpus_path).expect("corpus")).expect("JSON");
    let entries = corpus["entries"].as_array().expect("entries");
    let run = Command::new(&python).arg(here().join("package.py")).arg(&corpus_path).output().expect("package.py");
    assert!(run.status.success(), "package.py: {}", String::from_utf8_lossy(&run.stderr));
    let mut lines = std::str::from_utf8(&run.stdout).expect("UTF-8").lines();
    let version: Value = serde_json::from_str(lines.next().expect("the version line")).expect("JSON");
    println!("ui-tars {} against our parser on {} replies", version["version"], entries.len());
    let answers: BTreeMap<String, Value> = lines
        .map(|l| serde_json::from_str::<Value>(l).expect("a JSON line"))
        .map(|a| (a["id"].as_str().expect("id").to_owned(), a))
        .collect();
    let compatibility = std::fs::read_to_string(here().join("../../../docs/compatibility.md")).expect("the doc");

    let mut failures = Vec::new();
    let mut named: BTreeMap<&str, usize> = BTreeMap::new();
    for entry in entries {
        let id = entry["id"].as_str().expect("id");
        let expect = entry["expect"].as_str().expect("expect");
        let answer = answers.get(id).unwrap_or_else(|| panic!("no answer for {id}"));
        let (ours, theirs) = (ours(entry), theirs(entry, answer));
        // Both refusing a reply is agreement, whatever each says.
        let same = ours == theirs || (ours.is_err() && theirs.is_err());
        let shown = || format!("{id}: {:?}\n  package: {theirs:?}\n  ours:    {ours:?}", entry["reply"]);
        if expect == "same" {
            if !same {
                failures.push(format!("differs (name it in docs/compatibility.md or fix it): {}", shown()));
            }
        } else {
            *named.entry(expect).or_default() += 1;
            if same {
                failures.push(format!("now agrees, so `expect` should be `same`, not {expect:?}: {}", shown()));
            }
            if !compatibility.contains(&format!("`{expect}`")) {
                failures.push(format!("{id}: the difference `{expect}` is not in docs/compatibility.md"));
            }
        }
    }
    let same = entries.iter().filter(|e| e["expect"] == "same").count();
    println!("{same} replies agree; known differences: {named:?}");
    assert!(failures.is_empty(), "{} of {} replies:\n{}", failures.len(), entries.len(), failures.join("\n"));
}
