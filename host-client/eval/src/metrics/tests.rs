//! Table-driven tests of every metric: a passing and a failing case each,
//! on real files written to a temporary folder, plus the errors upstream raises.

use std::path::Path;

use serde_json::{json, Map, Value};

use super::{lookup, MetricInput};
use crate::value::Fetched;
use crate::LastAction;

/// What a case should give: a score, a score in a range, or an error whose
/// message contains the text. Shared with the media metrics' tests.
#[derive(Debug)]
pub(crate) enum Want {
    Score(f64),
    /// A score in `[lo, hi]`.
    Between(f64, f64),
    Error(&'static str),
}

/// Runs the registered `metric` on `input` and checks it gives `want`.
pub(crate) fn check(metric: &str, input: MetricInput, want: Want) {
    let f = lookup(metric).unwrap_or_else(|| panic!("metric {metric} is not registered"));
    let got = f(&input);
    match (&got, &want) {
        (Ok(score), Want::Score(expected)) => assert_eq!(score, expected, "{metric} on {input:?}"),
        (Ok(score), Want::Between(lo, hi)) => {
            assert!(lo <= score && score <= hi, "{metric} on {input:?}: {score} not in [{lo}, {hi}]")
        }
        (Err(err), Want::Error(text)) => {
            assert!(err.to_string().contains(text), "{metric}: error {err:?} lacks {text:?}")
        }
        _ => panic!("{metric} on {input:?}: got {got:?}, want {want:?}"),
    }
}

/// A metric's input after `DONE`, its options from a JSON object (anything else: none).
pub(crate) fn input(result: Fetched, expected: Option<Fetched>, options: Value) -> MetricInput {
    let options = match options {
        Value::Object(map) => map,
        _ => Map::new(),
    };
    MetricInput { result, expected, options, last_action: Some(LastAction::Done) }
}

/// Expected rules, as a `rule` getter hands them over.
pub(crate) fn rules(value: Value) -> Option<Fetched> {
    Some(Fetched::Json(value))
}

/// `bytes` written to `dir/name`, fetched as a file.
pub(crate) fn file(dir: &Path, name: &str, bytes: &[u8]) -> Fetched {
    let path = dir.join(name);
    std::fs::write(&path, bytes).expect("write test file");
    Fetched::File(path)
}

#[test]
fn exact_match_uses_python_equality() {
    use Want::*;
    let cases = [
        (Fetched::Bool(true), json!({"expected": true}), Score(1.0)),
        (Fetched::number(1.0), json!({"expected": true}), Score(1.0)),
        (Fetched::number(0.0), json!({"expected": 1.0}), Score(0.0)),
        (Fetched::Text("Documents".into()), json!({"expected": "Documents"}), Score(1.0)),
        (Fetched::Text("Documents ".into()), json!({"expected": "Documents"}), Score(0.0)),
        (Fetched::None, json!({"expected": null}), Score(1.0)),
        (Fetched::Json(json!(["a", 1])), json!({"expected": ["a", 1.0]}), Score(1.0)),
        (Fetched::Text("x".into()), json!({"other": 1}), Error("no `expected`")),
    ];
    for (result, rule, want) in cases {
        check("exact_match", input(result, rules(rule), json!({})), want);
    }
}

#[test]
fn infeasible_follows_the_last_action() {
    for (last, want) in
        [(Some(LastAction::Fail), 1.0), (Some(LastAction::Done), 0.0), (None, 0.0), (Some(LastAction::Wait), 0.0)]
    {
        let mut case = input(Fetched::None, None, json!({}));
        case.last_action = last;
        check("infeasible", case, Want::Score(want));
    }
}

#[test]
fn compare_text_file_reads_text_like_python() {
    use Want::*;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let gold = file(d, "gold.txt", b"line one\nline two\n");
    let cases = [
        // Universal newlines: a Notepad CRLF file equals its LF gold.
        (file(d, "crlf.txt", b"line one\r\nline two\r\n"), json!({}), Score(1.0)),
        (file(d, "other.txt", b"line one\nline 2\n"), json!({}), Score(0.0)),
        (file(d, "spaced.txt", b"  line   one\n\tline two"), json!({}), Score(0.0)),
        (file(d, "spaced2.txt", b"  line   one\n\tline two"), json!({"ignore_blanks": true}), Score(1.0)),
        (file(d, "case.txt", b"LINE one\nline TWO\n"), json!({"ignore_case": true}), Score(1.0)),
        (file(d, "case2.txt", b"LINE one\nline TWO\n"), json!({"ignore_case": false}), Score(0.0)),
        (Fetched::None, json!({}), Score(0.0)),
        (file(d, "binary.txt", &[0xff, 0xfe, 0x00]), json!({}), Error("not UTF-8")),
        (Fetched::Text("not a file".into()), json!({}), Error("must be a file")),
    ];
    for (result, options, want) in cases {
        check("compare_text_file", input(result, Some(gold.clone()), options), want);
    }
    let missing_gold = Some(Fetched::File(d.join("absent.txt")));
    check("compare_text_file", input(file(d, "a.txt", b"x"), missing_gold, json!({})), Error("absent.txt"));
}

#[test]
fn check_json_settings_needs_every_expected_key() {
    use Want::*;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let settings = file(
        d,
        "settings.json",
        br#"{"files.autoSave": "afterDelay", "files.autoSaveDelay": 1000, "files.exclude": {"**/__pycache__": true, "x": 1}}"#,
    );
    let cases = [
        (settings.clone(), json!({"files.autoSave": "afterDelay", "files.autoSaveDelay": 1000.0}), Score(1.0)),
        (settings.clone(), json!({"files.autoSaveDelay": 500}), Score(0.0)),
        (settings.clone(), json!({"editor.wordWrapColumn": 50}), Score(0.0)),
        // A nested dict is compared whole, as `dict.update` replaces it whole.
        (settings.clone(), json!({"files.exclude": {"**/__pycache__": true}}), Score(0.0)),
        (Fetched::None, json!({"a": 1}), Score(0.0)),
        (file(d, "broken.json", b"{\"a\": "), json!({"a": 1}), Error("broken.json")),
        (file(d, "list.json", b"[1, 2]"), json!({"a": 1}), Error("not a settings object")),
    ];
    for (result, expected, want) in cases {
        check("check_json_settings", input(result, rules(json!({"expected": expected})), json!({})), want);
    }
}

#[test]
fn check_direct_json_object_compares_keys() {
    use Want::*;
    let expected = json!({"expected": {"fromStation": "BOM", "toStation": "STO"}});
    let cases = [
        (Fetched::Json(json!({"fromStation": "BOM", "toStation": "STO", "extra": 1})), expected.clone(), Score(1.0)),
        (Fetched::Json(json!({"fromStation": "BOM", "toStation": "LHR"})), expected.clone(), Score(0.0)),
        (Fetched::Json(json!({"fromStation": "BOM"})), expected.clone(), Score(0.0)),
        // Strings are parsed after single quotes become double ones.
        (Fetched::Text(" {'fromStation': 'BOM', 'toStation': 'STO'} ".into()), expected.clone(), Score(1.0)),
        (Fetched::Text("{not json".into()), expected.clone(), Error("the result as JSON")),
        (Fetched::None, expected.clone(), Score(0.0)),
        (Fetched::Json(json!([1])), expected.clone(), Score(0.0)),
        (
            Fetched::Json(json!({"q": "hotels in paris", "tags": ["a", "b"]})),
            json!({"expect_in_result": true, "expected": {"q": "paris", "tags": ["z", "b"]}}),
            Score(1.0),
        ),
        (
            Fetched::Json(json!({"q": "hotels in rome", "tags": ["a", "b"]})),
            json!({"expect_in_result": true, "expected": {"q": "paris", "tags": ["z", "b"]}}),
            Score(0.0),
        ),
        (Fetched::Json(json!({"n": 3})), json!({"expect_in_result": true, "expected": {"n": 3}}), Score(0.0)),
    ];
    for (result, rule, want) in cases {
        check("check_direct_json_object", input(result, rules(rule), json!({})), want);
    }
}

#[test]
fn is_extension_installed_contains_or_not() {
    use Want::*;
    let output = || Fetched::Text("ms-python.python\r\nms-toolsai.jupyter\r\n".into());
    let cases = [
        (output(), json!({"type": "contain", "expected": "ms-python.python"}), Score(1.0)),
        (output(), json!({"type": "contain", "expected": "njpwerner.autodocstring"}), Score(0.0)),
        (output(), json!({"type": "not_contain", "expected": "ToDoLists"}), Score(1.0)),
        (output(), json!({"type": "not_contain", "expected": "jupyter"}), Score(0.0)),
        (Fetched::Json(json!(["a", "b"])), json!({"type": "contain", "expected": "b"}), Score(1.0)),
        (output(), json!({"type": "equal", "expected": "x"}), Error("contain")),
        (Fetched::None, json!({"type": "contain", "expected": "x"}), Error("text or a list")),
    ];
    for (result, rule, want) in cases {
        check("is_extension_installed", input(result, rules(rule), json!({})), want);
    }
}

#[test]
fn metrics_without_rules_say_so() {
    check("exact_match", input(Fetched::Bool(true), None, json!({})), Want::Error("needs an `expected` getter"));
    check(
        "exact_match",
        input(Fetched::Bool(true), Some(Fetched::Text("x".into())), json!({})),
        Want::Error("rules dict"),
    );
}

#[test]
fn unknown_metrics_are_not_registered() {
    assert!(lookup("no_such_metric").is_none());
    for name in [
        "exact_match",
        "infeasible",
        "compare_text_file",
        "check_json_settings",
        "check_direct_json_object",
        "is_extension_installed",
    ] {
        assert!(lookup(name).is_some(), "{name}");
        assert!(arena_task::names::METRICS.contains(&name), "{name} is not an upstream metric name");
    }
}
