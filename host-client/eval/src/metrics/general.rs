//! Metrics of upstream's `metrics/general.py` and the `infeasible` rule.

use serde_json::Value;

use super::{score, MetricError, MetricInput};
use crate::value::{py_contains, py_eq, Fetched};
use crate::LastAction;

/// `exact_match(result, rules)`: `result == rules["expected"]` with Python's
/// equality (so `True` matches `1.0`).
pub(super) fn exact_match(input: &MetricInput) -> Result<f64, MetricError> {
    let expected = input.rule("expected")?;
    Ok(score(py_eq(&input.result.to_json(), expected)))
}

/// `infeasible`: 1 when the agent's last word was FAIL. Tasks whose only
/// metric is `infeasible` never get here ([`crate::evaluate`] scores them
/// directly); in a list it is the same rule.
pub(super) fn infeasible(input: &MetricInput) -> Result<f64, MetricError> {
    Ok(score(input.last_action == Some(LastAction::Fail)))
}

/// `check_direct_json_object(result, rules)`.
///
/// A string result is stripped, its single quotes made double, and parsed as
/// JSON (a parse failure is an error, as upstream raises). Then, by default,
/// every key of `rules["expected"]` must map to an equal value in the result
/// (a missing key compares as `None`). With `rules["expect_in_result"]`, an
/// expected list passes when any of its items is in the result's list, and an
/// expected string passes when it is a substring of the result's value; any
/// other expected type fails.
pub(super) fn check_direct_json_object(input: &MetricInput) -> Result<f64, MetricError> {
    let result = match &input.result {
        Fetched::Text(text) => parse_loose_json(text)?,
        Fetched::Json(Value::String(text)) => parse_loose_json(text)?,
        other => other.to_json(),
    };
    if result.is_null() {
        return Ok(0.0);
    }
    let rules = input.rules()?;
    let Some(Value::Object(expected)) = rules.get("expected") else {
        return Err(MetricError::BadInput("rules[\"expected\"] must be a dict".into()));
    };
    // Upstream wraps the comparison in a bare `except` that scores 0, so a
    // result that is not a dict (no `.get`) scores 0 rather than failing.
    let Value::Object(result) = result else {
        return Ok(0.0);
    };
    let expect_in_result = rules.get("expect_in_result").is_some_and(crate::value::py_truthy);
    for (key, want) in expected {
        let have = result.get(key).unwrap_or(&Value::Null);
        let ok = if !expect_in_result {
            py_eq(want, have)
        } else {
            match want {
                Value::Array(options) => {
                    matches!(have, Value::Array(_))
                        && options.iter().any(|option| py_contains(have, option) == Some(true))
                }
                // `want not in have` raises for a `None` or number `have`; the bare
                // `except` turns that into 0 as well.
                Value::String(_) => py_contains(have, want) == Some(true),
                _ => false,
            }
        };
        if !ok {
            return Ok(0.0);
        }
    }
    Ok(1.0)
}

/// Upstream's `json.loads(text.strip().replace("'", '"'))`.
fn parse_loose_json(text: &str) -> Result<Value, MetricError> {
    let text = text.trim().replace('\'', "\"");
    serde_json::from_str(&text)
        .map_err(|err| MetricError::Parse { what: "the result as JSON".into(), message: err.to_string() })
}
