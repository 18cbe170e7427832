//! The action spaces an outside agent may answer in, mapped to [`AgentAction`]s:
//! WAA `computer` code and pyautogui code (run by the host's interpreter, as
//! Navi's are), `computer_13` JSON actions (OSWorld's), and typed actions
//! (`arena_shared::action::Action` as JSON). In every space the strings `DONE`,
//! `FAIL` and `WAIT` are the decisions, as upstream's and OSWorld's agents put
//! them among their actions.

use serde_json::Value;

use arena_shared::action::Action;

use crate::agent::AgentAction;

/// Whether `computer_13` answers are translated. The translation lives with
/// the other action-space parsers (`crate::actionspace::computer13`, issue 22);
/// until that module is in this branch, the seam below refuses with a clear error.
///
/// PLACEHOLDER (merge): set this to `true` and make [`computer13`] call
/// `crate::actionspace::computer13::parse(value)` once that module is merged.
pub const COMPUTER13_WIRED: bool = false;

/// `computer_13` actions as typed actions: the seam to the action-space parsers.
///
/// PLACEHOLDER (merge): replace the body with
/// `crate::actionspace::computer13::parse(value).map_err(|err| err.to_string())`.
fn computer13(value: &Value) -> Result<Vec<Action>, String> {
    let _ = value;
    Err("computer_13 not wired yet".to_owned())
}

/// Checks that `space` is one the harness accepts.
///
/// # Errors
///
/// The unknown name, with the accepted ones.
pub fn check_space(space: &str) -> Result<(), String> {
    if super::protocol::ACTION_SPACES.contains(&space) {
        Ok(())
    } else {
        Err(format!(
            "unknown action space {space:?}; this harness accepts {}",
            super::protocol::ACTION_SPACES.join(", ")
        ))
    }
}

/// The answer's `actions` in `space`, in order.
///
/// # Errors
///
/// An unknown space, or an action that is not of its space (a code action that
/// is not a string, a typed action that does not parse), named by its index.
pub fn to_actions(space: &str, actions: &[Value]) -> Result<Vec<AgentAction>, String> {
    check_space(space)?;
    let mut out = Vec::with_capacity(actions.len());
    for (i, action) in actions.iter().enumerate() {
        if let Some(word) = action.as_str().and_then(decision) {
            out.push(word);
            continue;
        }
        let bad = |why: String| format!("actions[{i}] in action space {space}: {why}");
        let converted = match space {
            "computer" | "pyautogui" => {
                let Some(code) = action.as_str() else {
                    return Err(bad(format!("expected a code string, got {}", super::short(action))));
                };
                if space == "computer" {
                    AgentAction::Computer(code.to_owned())
                } else {
                    AgentAction::Pyautogui(code.to_owned())
                }
            }
            "computer_13" => AgentAction::Typed(computer13(action).map_err(bad)?),
            _ => {
                let typed: Action = serde_json::from_value(action.clone()).map_err(|err| bad(err.to_string()))?;
                if typed == Action::Unknown {
                    return Err(bad(format!("unknown typed action {}", super::short(action))));
                }
                AgentAction::Typed(vec![typed])
            }
        };
        out.push(converted);
    }
    Ok(out)
}

/// `DONE`, `FAIL` or `WAIT` as an action.
fn decision(word: &str) -> Option<AgentAction> {
    match word.trim() {
        "DONE" => Some(AgentAction::Done),
        "FAIL" => Some(AgentAction::Fail),
        "WAIT" => Some(AgentAction::Wait),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn each_space_maps_its_actions_and_the_decision_words() {
        assert_eq!(
            to_actions("pyautogui", &[json!("pyautogui.click(1, 2)"), json!("DONE")]).expect("pyautogui"),
            vec![AgentAction::Pyautogui("pyautogui.click(1, 2)".into()), AgentAction::Done]
        );
        assert_eq!(
            to_actions("computer", &[json!("computer.keyboard.write('x')")]).expect("computer"),
            vec![AgentAction::Computer("computer.keyboard.write('x')".into())]
        );
        assert_eq!(
            to_actions("typed", &[json!({"type": "type_text", "text": "3"}), json!("WAIT")]).expect("typed"),
            vec![AgentAction::Typed(vec![Action::TypeText { text: "3".into(), interval_ms: None }]), AgentAction::Wait]
        );
    }

    #[test]
    fn bad_actions_are_named_by_index_and_space() {
        let err = to_actions("pyautogui", &[json!("DONE"), json!({"x": 1})]).expect_err("an object is no code");
        assert!(err.starts_with("actions[1] in action space pyautogui: expected a code string"), "{err}");
        let err = to_actions("typed", &[json!({"type": "teleport"})]).expect_err("unknown typed action");
        assert!(err.contains("actions[0]") && err.contains("teleport"), "{err}");
        let err = to_actions("morse", &[]).expect_err("unknown space");
        assert!(err.contains("\"morse\"") && err.contains("computer_13"), "{err}");
    }

    #[test]
    fn computer_13_goes_through_the_seam() {
        let got = to_actions("computer_13", &[json!({"action_type": "TYPING", "parameters": {"text": "3"}})]);
        if COMPUTER13_WIRED {
            assert!(got.is_ok(), "{got:?}");
        } else {
            assert_eq!(
                got.expect_err("placeholder"),
                "actions[0] in action space computer_13: computer_13 not wired yet"
            );
        }
    }
}
