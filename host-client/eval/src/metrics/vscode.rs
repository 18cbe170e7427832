//! Metrics of upstream's `metrics/vscode.py`: text files, JSON settings, and
//! the substring check the corpus uses for command output (`is_extension_installed`).

use serde_json::Value;

use super::{file_of, read_text, score, MetricError, MetricInput};
use crate::value::{dict_contains, json_kind, py_contains, py_truthy, Fetched};

/// `compare_text_file(actual, expected, ignore_blanks=False, ignore_case=False)`:
/// both files read as text (universal newlines) and compared exactly. With
/// `ignore_blanks`, tabs and newlines become spaces, the ends are stripped and
/// runs of whitespace collapse to one space; with `ignore_case`, both are lower-cased.
/// A missing result (`None`, a file the agent never saved) scores 0.
pub(super) fn compare_text_file(input: &MetricInput) -> Result<f64, MetricError> {
    if !result_present(&input.result) {
        return Ok(0.0);
    }
    let actual = read_text(file_of(&input.result, "result")?)?;
    let expected = read_text(file_of(input.expected()?, "expected")?)?;
    let (mut actual, mut expected) = if input.flag("ignore_blanks", false) {
        (squash_blanks(&actual), squash_blanks(&expected))
    } else {
        (actual, expected)
    };
    if input.flag("ignore_case", false) {
        actual = actual.to_lowercase();
        expected = expected.to_lowercase();
    }
    Ok(score(actual == expected))
}

/// Python's `re.sub(r'\s+', ' ', re.sub(r'[\t\n]', ' ', text).strip())`.
fn squash_blanks(text: &str) -> String {
    text.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// `check_json_settings(actual, expected)`: the settings file parses as JSON
/// and already holds every top-level key of `expected["expected"]` with an
/// equal value (upstream: `data.update(expect)` leaves `data` unchanged).
/// A missing result scores 0; a file that does not parse is an error.
pub(super) fn check_json_settings(input: &MetricInput) -> Result<f64, MetricError> {
    if !result_present(&input.result) {
        return Ok(0.0);
    }
    let path = file_of(&input.result, "result")?;
    let text = read_text(path)?;
    let data: Value = serde_json::from_str(&text)
        .map_err(|err| MetricError::Parse { what: path.display().to_string(), message: err.to_string() })?;
    let expect = match input.rule("expected")? {
        Value::Object(expect) => expect,
        other => return Err(MetricError::BadInput(format!("rules[\"expected\"] must be a dict, not {other}"))),
    };
    match data {
        Value::Object(data) => Ok(score(dict_contains(&data, expect))),
        other => Err(MetricError::Malformed(format!(
            "{} holds {}, not a settings object",
            path.display(),
            json_kind(&other)
        ))),
    }
}

/// `is_extension_installed(actual, rules)`: `rules["type"]` is `contain` (the
/// result holds `rules["expected"]`: a substring of text, an item of a list)
/// or `not_contain`.
pub(super) fn is_extension_installed(input: &MetricInput) -> Result<f64, MetricError> {
    let kind = input.rule("type")?;
    let expected = input.rule("expected")?;
    let haystack = match &input.result {
        Fetched::Text(text) => Value::String(text.clone()),
        Fetched::Json(value) => value.clone(),
        other => {
            return Err(MetricError::Malformed(format!("the result must be text or a list, not {}", other.kind())))
        }
    };
    let contains = py_contains(&haystack, expected).ok_or_else(|| {
        let message = format!("cannot look for {expected} in {}", json_kind(&haystack));
        // A string rule is the shape every task gives: the result cannot hold it.
        if expected.is_string() {
            MetricError::Malformed(message)
        } else {
            MetricError::BadInput(message)
        }
    })?;
    match kind.as_str() {
        Some("contain") => Ok(score(contains)),
        Some("not_contain") => Ok(score(!contains)),
        _ => Err(MetricError::BadInput(format!("rules[\"type\"] must be \"contain\" or \"not_contain\", not {kind}"))),
    }
}

/// Upstream's `if not actual: return 0.` guard.
fn result_present(result: &Fetched) -> bool {
    match result {
        Fetched::None => false,
        Fetched::Json(value) => py_truthy(value),
        Fetched::Text(text) => !text.is_empty(),
        _ => true,
    }
}

/// `check_json_keybindings(actual, rules)`: the keybindings file parses as a
/// JSON list, either whole or after its first line (VS Code starts the file
/// with a `// Place your key bindings ...` comment), and holds an entry equal
/// to `rules["expected"]` (whole-dict equality, so extra keys in the entry
/// fail, as upstream's `expected in data`). A missing result scores 0; a file
/// that is not a list either way is an error with the reason (upstream scores it 0).
pub(super) fn check_json_keybindings(input: &MetricInput) -> Result<f64, MetricError> {
    if !result_present(&input.result) {
        return Ok(0.0);
    }
    let expected = input.rule("expected")?;
    let path = file_of(&input.result, "result")?;
    let text = read_text(path)?;
    let as_list = |source: &str| serde_json::from_str::<Value>(source).ok().filter(Value::is_array);
    let after_first_line = text.split_once('\n').map_or("", |(_, rest)| rest);
    let Some(data) = as_list(&text).or_else(|| as_list(after_first_line)) else {
        return Err(MetricError::Parse {
            what: path.display().to_string(),
            message: "not a JSON list of keybindings, whole or after its first line".into(),
        });
    };
    Ok(score(py_contains(&data, expected) == Some(true)))
}
