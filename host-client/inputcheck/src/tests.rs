//! Unit tests of the notation, the comparison, the catalogue and its translation.

use arena_actionspace::ActionSpace;
use arena_shared::input_log::{Button, Mods, Press, Recorded};

use crate::catalogue::Catalogue;
use crate::compare::{compare, compare_text, split};
use crate::expect::Expected;

fn key(down: bool, vk: u16, mods: &str) -> Recorded {
    Recorded::Key {
        down,
        sys: false,
        vk,
        scan: 0,
        extended: false,
        repeat: false,
        mods: Mods::parse(mods).unwrap(),
        time: 0,
    }
}

fn button(press: Press, x: i32, y: i32, mods: &str) -> Recorded {
    Recorded::Button { button: Button::Left, press, x, y, mods: Mods::parse(mods).unwrap(), mk: 0, time: 0 }
}

fn expected(lines: &[&str]) -> Vec<Expected> {
    lines.iter().map(|l| Expected::parse(l).unwrap()).collect()
}

#[test]
fn a_shift_click_compares_in_screen_coordinates() {
    let want = expected(&["kd shift +shift", "down left 400,300 +shift", "up left 400,300 +shift", "ku shift"]);
    let got = vec![
        key(true, 0x10, "shift"),
        Recorded::Move { x: 390, y: 280, mods: Mods::NONE, mk: 0, time: 0 },
        button(Press::Down, 390, 280, "shift"),
        button(Press::Up, 390, 280, "shift"),
        key(false, 0x10, ""),
    ];
    assert_eq!(compare(&want, &got, (10, 20)), Ok(()));
    // The same events from a window elsewhere are elsewhere on the screen.
    let err = compare(&want, &got, (0, 0)).unwrap_err();
    assert_eq!(
        (err.at, err.expected.as_str(), err.received.as_str()),
        (1, "down left 400,300 +shift", "down left 390,280 +shift")
    );
}

#[test]
fn a_modifier_released_too_early_or_left_down_fails() {
    let want = expected(&["kd ctrl +ctrl", "kd c +ctrl", "ku c +ctrl", "ku ctrl"]);
    let early = vec![key(true, 0x11, "ctrl"), key(true, 0x43, "ctrl"), key(false, 0x11, ""), key(false, 0x43, "")];
    let err = compare(&want, &early, (0, 0)).unwrap_err();
    assert_eq!((err.at, err.received.as_str()), (2, "ku ctrl !ext scan=0x00"));
    let left_down = vec![key(true, 0x11, "ctrl"), key(true, 0x43, "ctrl"), key(false, 0x43, "ctrl")];
    let err = compare(&want, &left_down, (0, 0)).unwrap_err();
    assert_eq!((err.at, err.received.as_str()), (3, ""));
}

#[test]
fn extra_events_and_expected_moves_are_checked() {
    let want = expected(&["down left 10,10", "move 50,60", "up left 50,60"]);
    let moves = |pts: &[(i32, i32)]| -> Vec<Recorded> {
        pts.iter().map(|&(x, y)| Recorded::Move { x, y, mods: Mods::NONE, mk: 1, time: 0 }).collect()
    };
    let mut got = vec![button(Press::Down, 10, 10, "")];
    got.extend(moves(&[(20, 30), (50, 60), (50, 60)]));
    got.push(button(Press::Up, 50, 60, ""));
    assert_eq!(compare(&want, &got, (0, 0)), Ok(()));
    // A drag that never reaches its end.
    let mut short = vec![button(Press::Down, 10, 10, "")];
    short.extend(moves(&[(20, 30)]));
    short.push(button(Press::Up, 20, 30, ""));
    assert_eq!(compare(&want, &short, (0, 0)).unwrap_err().at, 1);
    // A click that arrives twice.
    let click = expected(&["down left 1,1", "up left 1,1"]);
    let twice = vec![button(Press::Down, 1, 1, ""), button(Press::Up, 1, 1, ""), button(Press::Down, 1, 1, "")];
    let err = compare(&click, &twice, (0, 0)).unwrap_err();
    assert_eq!((err.at, err.expected.as_str(), err.received.as_str()), (2, "", "down left 1,1"));
}

#[test]
fn wheel_deltas_and_text_are_compared_exactly() {
    let want = expected(&["wheel -360 400,300"]);
    let got =
        vec![Recorded::Wheel { horizontal: false, delta: -360, x: 400, y: 300, mods: Mods::NONE, mk: 0, time: 0 }];
    assert_eq!(compare(&want, &got, (0, 0)), Ok(()));
    let notches =
        vec![Recorded::Wheel { horizontal: false, delta: -3, x: 400, y: 300, mods: Mods::NONE, mk: 0, time: 0 }];
    assert!(compare(&want, &notches, (0, 0)).is_err());
    let chars: Vec<Recorded> = ["n", "a", "ï", "😀"]
        .iter()
        .map(|t| Recorded::Char { text: (*t).into(), sys: false, mods: Mods::NONE, time: 0 })
        .collect();
    assert_eq!(compare_text("naï😀", &chars), Ok(()));
    assert_eq!(compare_text("naive😀", &chars).unwrap_err().received, "text naï😀");
}

#[test]
fn the_log_is_cut_at_the_separators() {
    let f24 = 0x87;
    let log = vec![
        Recorded::Ready { x: 5, y: 6, width: 100, height: 100, double_click_ms: 500 },
        key(true, 0x12, "alt"),
        key(true, f24, ""),
        key(false, f24, ""),
        key(true, 0x41, ""),
        key(false, 0x41, ""),
        key(true, f24, "shift"),
        key(false, f24, "shift"),
        key(true, f24, ""),
        key(false, f24, ""),
    ];
    let split = split(&log);
    assert_eq!(split.origin, Some((5, 6)));
    assert_eq!(split.cases, vec![vec![key(true, 0x41, ""), key(false, 0x41, "")], vec![]]);
    assert_eq!(split.held_at, vec![(1, Mods::parse("shift").unwrap())]);
}

#[test]
fn the_catalogue_loads_and_every_case_translates_in_every_space_it_names() {
    let catalogue = Catalogue::builtin().unwrap_or_else(|e| panic!("{e}"));
    assert!(catalogue.cases.len() >= 60, "{} cases", catalogue.cases.len());
    let ctx = crate::catalogue::context((1440, 900));
    let mut per_space = std::collections::BTreeMap::new();
    for case in &catalogue.cases {
        assert!(!case.inputs.is_empty(), "{} has no action space", case.name);
        for (space, input) in &case.inputs {
            let steps = crate::catalogue::translate(*space, input, &ctx)
                .unwrap_or_else(|e| panic!("{} in {space}: {e}", case.name));
            assert!(!steps.is_empty(), "{} in {space}: no steps", case.name);
            *per_space.entry(space.name()).or_insert(0) += 1;
        }
    }
    for space in arena_actionspace::ActionSpace::ALL {
        assert!(per_space.get(space.name()).copied().unwrap_or(0) >= 10, "{space}: {per_space:?}");
    }
}

#[test]
fn a_broken_catalogue_is_refused_with_the_case_named() {
    let bad = r#"{"cases": [{"name": "x", "intent": "i", "expect": ["kd nokey"], "typed": {"type": "key_press", "key": "a"}}]}"#;
    let err = Catalogue::parse(bad).unwrap_err();
    assert!(err.contains("x") && err.contains("unknown key"), "{err}");
    let unknown_space = r#"{"cases": [{"name": "y", "intent": "i", "expect": [], "telepathy": "a"}]}"#;
    assert!(Catalogue::parse(unknown_space).unwrap_err().contains("telepathy"));
    let duplicate = r#"{"cases": [{"name": "z", "intent": "i", "expect": [], "typed": []}, {"name": "z", "intent": "i", "expect": [], "typed": []}]}"#;
    assert!(Catalogue::parse(duplicate).unwrap_err().contains("twice"));
}

#[test]
fn a_wine_exception_is_read_with_its_reason_and_spaces_and_a_bad_one_is_refused() {
    let case = |wine: &str| {
        format!(
            r#"{{"cases": [{{"name": "w", "intent": "i", "expect": [], "typed": [], "pyautogui": "pass", "wine": {wine}}}]}}"#
        )
    };
    let all = Catalogue::parse(&case(r#"{"reason": "Wine has no such message"}"#)).unwrap_or_else(|e| panic!("{e}"));
    let wine = all.cases[0].wine.clone().expect("the exception");
    assert_eq!(wine.reason, "Wine has no such message");
    assert!(wine.covers(ActionSpace::Typed) && wine.covers(ActionSpace::Pyautogui));
    let one = Catalogue::parse(&case(r#"{"reason": "r", "spaces": ["typed"]}"#)).unwrap_or_else(|e| panic!("{e}"));
    let wine = one.cases[0].wine.clone().expect("the exception");
    assert!(wine.covers(ActionSpace::Typed) && !wine.covers(ActionSpace::Pyautogui) && !wine.sometimes);
    let racy = Catalogue::parse(&case(r#"{"reason": "r", "sometimes": true}"#)).unwrap_or_else(|e| panic!("{e}"));
    assert!(racy.cases[0].wine.as_ref().is_some_and(|w| w.sometimes));
    for (wine, says) in [
        (r#"{"spaces": ["typed"]}"#, "reason"),
        (r#"{"reason": "r", "spaces": ["telepathy"]}"#, "telepathy"),
        (r#"{"reason": "r", "spaces": ["uitars"]}"#, "not expressed in"),
        (r#"{"reason": "r", "spaces": []}"#, "non-empty"),
        (r#"{"reason": "r", "why": "x"}"#, "unknown member"),
        (r#"{"reason": "r", "sometimes": "often"}"#, "true or false"),
        (r#""because""#, "must be an object"),
    ] {
        let err = Catalogue::parse(&case(wine)).unwrap_err();
        assert!(err.contains("case w") && err.contains(says), "{wine}: {err}");
    }
}
