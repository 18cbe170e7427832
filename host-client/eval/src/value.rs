//! What a getter hands to a metric ([`Fetched`]), and Python's equality and
//! truthiness over JSON values, which upstream's metrics rely on (`True == 1.0`,
//! `{"a": 1} == {"a": 1.0}`).
//!
//! This is not a general dynamic-value library: it holds exactly the shapes
//! upstream's getters return (a path, a string, a bool, a number or JSON-like
//! data, a list of those, or `None`).

use std::path::{Path, PathBuf};

use serde_json::{Map, Number, Value};

/// The longest text kept in a [`Fetched::summary`] (in characters).
const SUMMARY_CHARS: usize = 2000;

/// A getter's value, as upstream's `get_<type>` functions return it.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum Fetched {
    /// Python's `None`: a missing file, a failed lookup upstream reports as `None`.
    None,
    Bool(bool),
    /// A string (command output, a window title, a setting).
    Text(String),
    /// Raw bytes that were not saved to a file.
    Bytes(Vec<u8>),
    /// A host file the getter saved under the task's work folder (or the download cache).
    File(PathBuf),
    /// Numbers, dicts and lists of plain data (rules, parsed settings, tab lists).
    Json(Value),
    /// Several values, as `vm_file`/`cloud_file` with `multi` and `gives` return them.
    List(Vec<Fetched>),
}

impl Fetched {
    /// A number as upstream returns floats (`1.0`, `0.0`).
    pub fn number(value: f64) -> Fetched {
        Number::from_f64(value).map_or(Fetched::None, |n| Fetched::Json(Value::Number(n)))
    }

    pub fn is_none(&self) -> bool {
        matches!(self, Fetched::None | Fetched::Json(Value::Null))
    }

    /// The file path, when this is one.
    pub fn as_path(&self) -> Option<&Path> {
        match self {
            Fetched::File(path) => Some(path),
            _ => None,
        }
    }

    /// The value as Python code would see it in JSON terms: a file is its path
    /// string, bytes are a list of numbers (only small values are ever compared).
    pub fn to_json(&self) -> Value {
        match self {
            Fetched::None => Value::Null,
            Fetched::Bool(b) => Value::Bool(*b),
            Fetched::Text(s) => Value::String(s.clone()),
            Fetched::Bytes(bytes) => Value::Array(bytes.iter().map(|b| Value::from(*b)).collect()),
            Fetched::File(path) => Value::String(path.display().to_string()),
            Fetched::Json(value) => value.clone(),
            Fetched::List(items) => Value::Array(items.iter().map(Fetched::to_json).collect()),
        }
    }

    /// A short JSON description for result files: long text is cut, bytes are
    /// counted, files are named by path.
    pub fn summary(&self) -> Value {
        match self {
            Fetched::Text(s) => Value::String(truncate(s)),
            Fetched::Bytes(bytes) => Value::String(format!("<{} bytes>", bytes.len())),
            Fetched::Json(value) => {
                let text = value.to_string();
                if text.chars().count() > SUMMARY_CHARS {
                    Value::String(truncate(&text))
                } else {
                    value.clone()
                }
            }
            Fetched::List(items) => Value::Array(items.iter().map(Fetched::summary).collect()),
            other => other.to_json(),
        }
    }

    /// A word for error messages: what kind of value this is.
    pub fn kind(&self) -> &'static str {
        match self {
            Fetched::None => "None",
            Fetched::Bool(_) => "a bool",
            Fetched::Text(_) => "a string",
            Fetched::Bytes(_) => "bytes",
            Fetched::File(_) => "a file",
            Fetched::Json(value) => json_kind(value),
            Fetched::List(_) => "a list",
        }
    }
}

/// A word for error messages: the Python type of a JSON value.
pub fn json_kind(value: &Value) -> &'static str {
    match value {
        Value::Null => "None",
        Value::Bool(_) => "a bool",
        Value::Number(_) => "a number",
        Value::String(_) => "a string",
        Value::Array(_) => "a list",
        Value::Object(_) => "a dict",
    }
}

fn truncate(text: &str) -> String {
    match text.char_indices().nth(SUMMARY_CHARS) {
        Some((cut, _)) => format!("{}… ({} chars)", &text[..cut], text.chars().count()),
        None => text.to_owned(),
    }
}

/// Python's `==` over JSON values: booleans are the integers 0 and 1, integers
/// and floats compare by value, lists and dicts compare element-wise.
pub fn py_eq(a: &Value, b: &Value) -> bool {
    match (a, b) {
        (Value::Null, Value::Null) => true,
        (Value::String(x), Value::String(y)) => x == y,
        (Value::Array(x), Value::Array(y)) => x.len() == y.len() && x.iter().zip(y).all(|(p, q)| py_eq(p, q)),
        (Value::Object(x), Value::Object(y)) => {
            x.len() == y.len() && x.iter().all(|(key, p)| y.get(key).is_some_and(|q| py_eq(p, q)))
        }
        (Value::Bool(_) | Value::Number(_), Value::Bool(_) | Value::Number(_)) => numeric_eq(a, b),
        _ => false,
    }
}

/// Compares two numbers (or bools) exactly when both are integers, else as floats.
fn numeric_eq(a: &Value, b: &Value) -> bool {
    fn int(v: &Value) -> Option<i128> {
        match v {
            Value::Bool(b) => Some(i128::from(*b)),
            Value::Number(n) => n.as_i64().map(i128::from).or_else(|| n.as_u64().map(i128::from)),
            _ => None,
        }
    }
    fn float(v: &Value) -> Option<f64> {
        match v {
            Value::Bool(b) => Some(f64::from(u8::from(*b))),
            Value::Number(n) => n.as_f64(),
            _ => None,
        }
    }
    match (int(a), int(b)) {
        (Some(x), Some(y)) => x == y,
        _ => matches!((float(a), float(b)), (Some(x), Some(y)) if x == y),
    }
}

/// Python's `needle in haystack` for a list (membership by `==`) or a string (substring).
/// `None` when the haystack supports neither.
pub fn py_contains(haystack: &Value, needle: &Value) -> Option<bool> {
    match (haystack, needle) {
        (Value::String(h), Value::String(n)) => Some(h.contains(n.as_str())),
        (Value::Array(items), _) => Some(items.iter().any(|item| py_eq(item, needle))),
        (Value::Object(map), Value::String(key)) => Some(map.contains_key(key)),
        _ => None,
    }
}

/// Python truthiness: `None`, `False`, `0`, `""`, `[]`, `{}` are false.
pub fn py_truthy(value: &Value) -> bool {
    match value {
        Value::Null => false,
        Value::Bool(b) => *b,
        Value::Number(n) => n.as_f64().is_some_and(|f| f != 0.0),
        Value::String(s) => !s.is_empty(),
        Value::Array(items) => !items.is_empty(),
        Value::Object(map) => !map.is_empty(),
    }
}

/// `dict.update` followed by `==`: whether every key of `expected` is in
/// `actual` with an equal value (so updating `actual` with it changes nothing).
pub fn dict_contains(actual: &Map<String, Value>, expected: &Map<String, Value>) -> bool {
    expected.iter().all(|(key, want)| actual.get(key).is_some_and(|have| py_eq(have, want)))
}

#[cfg(test)]
mod tests {
    use serde_json::json;

    use super::*;

    fn check(a: Value, b: Value, equal: bool) {
        assert_eq!(py_eq(&a, &b), equal, "{a} == {b}");
        assert_eq!(py_eq(&b, &a), equal, "{b} == {a}");
    }

    #[test]
    fn python_equality_table() {
        check(json!(true), json!(1.0), true);
        check(json!(true), json!(1), true);
        check(json!(false), json!(0), true);
        check(json!(true), json!(2), false);
        check(json!(1), json!(1.0), true);
        check(json!(1), json!(1.5), false);
        check(json!("1"), json!(1), false);
        check(json!(null), json!(false), false);
        check(json!(null), json!(null), true);
        check(json!({"a": [1, true]}), json!({"a": [1.0, 1]}), true);
        check(json!({"a": 1}), json!({"a": 1, "b": 2}), false);
        check(json!([1, 2]), json!([2, 1]), false);
        check(json!(u64::MAX), json!(u64::MAX), true);
        check(json!(u64::MAX), json!(i64::MAX), false);
    }

    #[test]
    fn contains_and_truthiness() {
        assert_eq!(py_contains(&json!("ms-python.python\r\n"), &json!("ms-python")), Some(true));
        assert_eq!(py_contains(&json!([1, "a"]), &json!(1.0)), Some(true));
        assert_eq!(py_contains(&json!([1, "a"]), &json!("b")), Some(false));
        assert_eq!(py_contains(&json!(3), &json!("b")), None);
        assert!(!py_truthy(&json!("")) && !py_truthy(&json!(0.0)) && !py_truthy(&json!({})));
        assert!(py_truthy(&json!("false")) && py_truthy(&json!([0])));
    }

    #[test]
    fn summaries_cut_long_text_and_count_bytes() {
        let long = "x".repeat(SUMMARY_CHARS + 10);
        let Value::String(cut) = Fetched::Text(long).summary() else { panic!("not a string") };
        assert!(cut.ends_with(&format!("({} chars)", SUMMARY_CHARS + 10)), "{cut}");
        assert_eq!(Fetched::Bytes(vec![0; 7]).summary(), json!("<7 bytes>"));
        assert_eq!(Fetched::List(vec![Fetched::None, Fetched::number(1.0)]).summary(), json!([null, 1.0]));
    }
}
