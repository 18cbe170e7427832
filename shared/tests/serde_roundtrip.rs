//! Property tests: every [`Action`] and [`A11yNode`] survives a JSON round trip,
//! and unknown tags from a newer peer decode to the `Unknown` fallbacks.

use arena_shared::action::{Action, MouseButton};
use arena_shared::geometry::{Point, Rect};
use arena_shared::observation::{A11yNode, A11yStates};
use proptest::prelude::*;

fn button() -> impl Strategy<Value = MouseButton> {
    prop_oneof![Just(MouseButton::Left), Just(MouseButton::Right), Just(MouseButton::Middle)]
}

fn point() -> impl Strategy<Value = Point> {
    (any::<i32>(), any::<i32>()).prop_map(|(x, y)| Point::new(x, y))
}

fn action() -> impl Strategy<Value = Action> {
    let opt = || proptest::option::of(any::<i32>());
    prop_oneof![
        (any::<i32>(), any::<i32>()).prop_map(|(x, y)| Action::MoveTo { x, y }),
        (any::<i32>(), any::<i32>()).prop_map(|(dx, dy)| Action::MoveRel { dx, dy }),
        (opt(), opt(), button(), 0u32..10).prop_map(|(x, y, button, count)| Action::Click { x, y, button, count }),
        (opt(), opt()).prop_map(|(x, y)| Action::DoubleClick { x, y }),
        (opt(), opt()).prop_map(|(x, y)| Action::RightClick { x, y }),
        (button(), opt(), opt()).prop_map(|(button, x, y)| Action::MouseDown { button, x, y }),
        (button(), opt(), opt()).prop_map(|(button, x, y)| Action::MouseUp { button, x, y }),
        (proptest::option::of(point()), point(), button(), proptest::option::of(0u64..10_000))
            .prop_map(|(from, to, button, duration_ms)| Action::Drag { from, to, button, duration_ms },),
        (opt(), opt(), any::<i32>(), any::<i32>()).prop_map(|(x, y, dx, dy)| Action::Scroll { x, y, dx, dy }),
        (".{0,12}", 0u32..5).prop_map(|(key, presses)| Action::KeyPress { key, presses }),
        proptest::collection::vec(".{0,8}", 0..4).prop_map(|keys| Action::Hotkey { keys }),
        ".{0,8}".prop_map(|key| Action::KeyDown { key }),
        ".{0,8}".prop_map(|key| Action::KeyUp { key }),
        (any::<String>(), proptest::option::of(any::<u64>()))
            .prop_map(|(text, interval_ms)| Action::TypeText { text, interval_ms }),
        any::<u64>().prop_map(|ms| Action::Wait { ms }),
    ]
}

fn states() -> impl Strategy<Value = A11yStates> {
    let b = || proptest::option::of(any::<bool>());
    (b(), b(), b(), b(), b(), b()).prop_map(|(minimized, maximized, expanded, selected, checked, editable)| {
        A11yStates { minimized, maximized, expanded, selected, checked, editable }
    })
}

fn leaf() -> impl Strategy<Value = A11yNode> {
    let rect = (any::<i32>(), any::<i32>(), any::<i32>(), any::<i32>()).prop_map(|(x, y, w, h)| Rect::new(x, y, w, h));
    (
        (".{0,10}", ".{0,10}", any::<String>()),
        (proptest::option::of(any::<String>()), proptest::option::of(any::<String>()), proptest::option::of(rect)),
        (any::<bool>(), any::<bool>(), any::<bool>(), states(), proptest::option::of(any::<u64>())),
    )
        .prop_map(
            |((role, class_name, name), (value, text, rect), (enabled, visible, focused, states, window_id))| {
                A11yNode {
                    role,
                    class_name,
                    name,
                    value,
                    text,
                    rect,
                    enabled,
                    visible,
                    focused,
                    states,
                    window_id,
                    children: Vec::new(),
                }
            },
        )
}

fn node() -> impl Strategy<Value = A11yNode> {
    leaf().prop_recursive(4, 32, 4, |inner| {
        (leaf(), proptest::collection::vec(inner, 0..4)).prop_map(|(mut node, children)| {
            node.children = children;
            node
        })
    })
}

proptest! {
    #[test]
    fn actions_round_trip(action in action()) {
        let json = serde_json::to_string(&action).unwrap();
        let back: Action = serde_json::from_str(&json).unwrap();
        prop_assert_eq!(back, action);
    }

    #[test]
    fn a11y_nodes_round_trip(node in node()) {
        let json = serde_json::to_string(&node).unwrap();
        let back: A11yNode = serde_json::from_str(&json).unwrap();
        prop_assert_eq!(back, node);
    }
}

#[test]
fn unknown_tags_from_a_newer_peer_fall_back() {
    let action: Action = serde_json::from_str(r#"{"type": "teleport"}"#).unwrap();
    assert_eq!(action, Action::Unknown);
    let click: Action = serde_json::from_str(r#"{"type": "click", "button": "x1"}"#).unwrap();
    assert_eq!(click, Action::Click { x: None, y: None, button: MouseButton::Unknown, count: 1 });
}
