//! The action spaces an outside agent may answer in, mapped to [`AgentAction`]s:
//! WAA `computer` code (run by the host's interpreter, as Navi's is), pyautogui
//! code (carried out by `arena_exec` as every pyautogui answer is: with its
//! effects, or translated under `--pyautogui-translate-only`), and OSWorld's `computer_13` JSON actions and typed
//! actions (`arena_shared::action::Action` as JSON), both through the one entry
//! point of the action spaces, `arena_actionspace::parse`. In every space the
//! strings `DONE`, `FAIL` and `WAIT` are the decisions ([`Decision::parse`]), as
//! upstream's and OSWorld's agents put them among their actions.

use serde_json::Value;

use arena_actionspace::{ActionSpace, Context, Coords, Decision};

use arena_exec::AgentAction;

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
/// `coords` (pyautogui code is read in them where it runs, `arena_exec`).
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
    let ctx = Context::new(screen, coords);
    let mut out = Vec::with_capacity(actions.len());
    for (i, action) in actions.iter().enumerate() {
        if let Some(decision) = action.as_str().and_then(Decision::parse) {
            out.push(decision.into());
            continue;
        }
        let bad = |why: String| format!("actions[{i}] in action space {space}: {why}");
        let grammar = match space {
            "computer" | "pyautogui" => {
                let Some(code) = action.as_str() else {
                    return Err(bad(format!("expected a code string, got {}", super::short(action))));
                };
                out.push(if space == "computer" {
                    AgentAction::Computer(code.into())
                } else {
                    AgentAction::Pyautogui(code.into())
                });
                continue;
            }
            "computer_13" => ActionSpace::Computer13,
            _ => ActionSpace::Typed,
        };
        let steps = arena_actionspace::parse(grammar, action, &ctx).map_err(|err| bad(err.to_string()))?;
        out.extend(AgentAction::from_steps(&steps));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use arena_shared::action::Action;
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
