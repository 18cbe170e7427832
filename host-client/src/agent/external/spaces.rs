//! The action spaces an outside agent may answer in, mapped to [`AgentAction`]s:
//! WAA `computer` code and pyautogui code (run by the host's interpreter, as
//! Navi's are), `computer_13` JSON actions (OSWorld's), and typed actions
//! (`arena_shared::action::Action` as JSON). In every space the strings `DONE`,
//! `FAIL` and `WAIT` are the decisions, as upstream's and OSWorld's agents put
//! them among their actions.

use serde_json::Value;

use arena_shared::action::Action;

use crate::actionspace::{Context, Coords};
use crate::agent::AgentAction;

/// `computer_13` actions (OSWorld's JSON actions, in `coords`: screen pixels as OSWorld's
/// are, unless the run or the agent says otherwise) as the episode's actions, through the
/// action-space parsers of `crate::actionspace`.
fn computer13(value: &Value, screen: (u32, u32), coords: Coords) -> Result<Vec<AgentAction>, String> {
    let ctx = Context::new(screen, coords);
    let steps = crate::actionspace::computer13::parse(value, &ctx).map_err(|err| err.to_string())?;
    Ok(crate::actionspace::to_agent_actions(&steps))
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

/// The answer's `actions` in `space`, in order; `computer_13` coordinates are in
/// `coords` (pyautogui code is rescaled where it runs, `crate::agent::exec`).
///
/// # Errors
///
/// An unknown space, or an action that is not of its space (a code action that
/// is not a string, a typed action that does not parse), named by its index.
pub fn to_actions(
    space: &str,
    actions: &[Value],
    screen: (u32, u32),
    coords: Coords,
) -> Result<Vec<AgentAction>, String> {
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
            "computer_13" => {
                out.extend(computer13(action, screen, coords).map_err(bad)?);
                continue;
            }
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
            to_actions("pyautogui", &[json!("pyautogui.click(1, 2)"), json!("DONE")], (1440, 900), Coords::Pixels)
                .expect("pyautogui"),
            vec![AgentAction::Pyautogui("pyautogui.click(1, 2)".into()), AgentAction::Done]
        );
        assert_eq!(
            to_actions("computer", &[json!("computer.keyboard.write('x')")], (1440, 900), Coords::Pixels)
                .expect("computer"),
            vec![AgentAction::Computer("computer.keyboard.write('x')".into())]
        );
        assert_eq!(
            to_actions(
                "typed",
                &[json!({"type": "type_text", "text": "3"}), json!("WAIT")],
                (1440, 900),
                Coords::Pixels
            )
            .expect("typed"),
            vec![AgentAction::Typed(vec![Action::TypeText { text: "3".into(), interval_ms: None }]), AgentAction::Wait]
        );
    }

    #[test]
    fn bad_actions_are_named_by_index_and_space() {
        let err = to_actions("pyautogui", &[json!("DONE"), json!({"x": 1})], (1440, 900), Coords::Pixels)
            .expect_err("an object is no code");
        assert!(err.starts_with("actions[1] in action space pyautogui: expected a code string"), "{err}");
        let err = to_actions("typed", &[json!({"type": "teleport"})], (1440, 900), Coords::Pixels)
            .expect_err("unknown typed action");
        assert!(err.contains("actions[0]") && err.contains("teleport"), "{err}");
        let err = to_actions("morse", &[], (1440, 900), Coords::Pixels).expect_err("unknown space");
        assert!(err.contains("\"morse\"") && err.contains("computer_13"), "{err}");
    }

    #[test]
    fn computer_13_goes_through_the_action_space_parser() {
        let got = to_actions(
            "computer_13",
            &[json!({"action_type": "TYPING", "parameters": {"text": "3"}})],
            (1440, 900),
            Coords::Pixels,
        )
        .expect("computer_13");
        assert_eq!(got, vec![AgentAction::Typed(vec![Action::TypeText { text: "3".into(), interval_ms: None }])]);
        let err = to_actions("computer_13", &[json!({"action_type": "TELEPORT"})], (1440, 900), Coords::Pixels)
            .expect_err("unknown");
        let click = json!({"action_type": "CLICK", "x": 250, "y": 750});
        let got = to_actions("computer_13", &[click], (1440, 900), Coords::Grid1000).expect("computer_13 on the grid");
        let AgentAction::Typed(actions) = &got[0] else { panic!("typed actions: {got:?}") };
        assert!(
            matches!(actions[..], [Action::Click { x: Some(360), y: Some(675), .. }]),
            "the run's grid1000 puts (250, 750) at (360, 675) of 1440x900: {actions:?}"
        );
        assert!(err.contains("actions[0] in action space computer_13"), "{err}");
    }
}
