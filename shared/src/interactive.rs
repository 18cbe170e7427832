//! The interactive elements of an accessibility tree, numbered for the MCP `state`
//! tool and acted on by `click_element` and `type_into_element`.
//!
//! An element is interactive when UI Automation gives it a control type a person
//! operates ([`ROLES`]), or it is an editable `Document` (the text area of Notepad and
//! of most editors), and it is visible and enabled, with a rectangle whose centre is on
//! the screen and not under a window above its own. The walk descends only through
//! visible nodes and keeps the tree's order (windows topmost first, then document
//! order), so the numbers read top to bottom through each window.
//!
//! Numbers ([`Numbering`]) are never reused within a session: each `state` numbers its
//! elements after the last number the one before gave, so a number from an earlier
//! state is recognised as stale rather than taken for another element. An element of
//! the latest state is stale too once its window has closed, been minimised, moved or
//! resized ([`check_current`]); what changed inside a window that stayed put is not
//! seen until the next `state`.

use crate::geometry::{Point, Rect};
use crate::observation::{A11yNode, A11yTree, WindowInfo};

/// The UI Automation control types a person operates (UIA's `ControlType` names, as
/// the guest's UIA tree gives its roles).
pub const ROLES: [&str; 15] = [
    "Button",
    "CheckBox",
    "ComboBox",
    "DataItem",
    "Edit",
    "HeaderItem",
    "Hyperlink",
    "ListItem",
    "MenuItem",
    "RadioButton",
    "Slider",
    "Spinner",
    "SplitButton",
    "TabItem",
    "TreeItem",
];

/// Most elements one state lists; the rest are left out and the state says so.
pub const MAX_ELEMENTS: usize = 1000;

/// Longest name or value kept per element, in characters; longer ones end in `…`.
pub const MAX_TEXT_CHARS: usize = 200;

/// One interactive element.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Element {
    /// The UIA control type (`Button`, `Edit`, `Document`, ...).
    pub role: String,
    pub name: String,
    /// The element's value (a text field's text), when it has one.
    pub value: Option<String>,
    /// Where it is, in screen pixels.
    pub rect: Rect,
    /// The top-level window it belongs to, and that window's title.
    pub window_id: u64,
    pub window: String,
    /// The window's rectangle in the window list when the state was taken.
    pub window_rect: Option<Rect>,
    pub focused: bool,
}

impl Element {
    /// Where a click on it lands: its rectangle's centre.
    pub fn centre(&self) -> Point {
        self.rect.center()
    }
}

/// Whether `node` itself is an element a person operates (visibility aside).
pub fn is_interactive(node: &A11yNode) -> bool {
    ROLES.contains(&node.role.as_str()) || (node.role == "Document" && node.states.editable == Some(true))
}

fn cut(text: &str) -> String {
    if text.chars().count() <= MAX_TEXT_CHARS {
        return text.to_owned();
    }
    let mut kept: String = text.chars().take(MAX_TEXT_CHARS - 1).collect();
    kept.push('…');
    kept
}

/// The interactive elements of `tree` on a `screen` of width by height pixels, with
/// their windows' rectangles from `windows` (the window list read with the tree), and
/// whether any were left out ([`MAX_ELEMENTS`]).
pub fn collect(tree: &A11yTree, windows: &[WindowInfo], screen: (u32, u32)) -> (Vec<Element>, bool) {
    let (w, h) = (i32::try_from(screen.0).unwrap_or(i32::MAX), i32::try_from(screen.1).unwrap_or(i32::MAX));
    let on_screen = Rect::new(0, 0, w, h);
    let mut higher: Vec<Rect> = Vec::new();
    let mut found = Vec::new();
    let mut capped = false;
    for window in &tree.windows {
        if !window.visible || window.states.minimized == Some(true) {
            continue;
        }
        let context = Window { id: window.window_id.unwrap_or(0), title: &window.name, higher: &higher, on_screen };
        let start = found.len();
        walk(window, &context, &mut found, &mut capped);
        for element in &mut found[start..] {
            element.window_rect = windows.iter().find(|w| w.id == element.window_id).map(|w| w.rect);
        }
        if let Some(rect) = window.rect.filter(|r| !r.is_empty()) {
            higher.push(rect);
        }
    }
    (found, capped)
}

/// The top-level window a walk is in, and the windows above it.
struct Window<'a> {
    id: u64,
    title: &'a str,
    higher: &'a [Rect],
    on_screen: Rect,
}

fn walk(node: &A11yNode, window: &Window<'_>, found: &mut Vec<Element>, capped: &mut bool) {
    if !node.visible || *capped {
        return;
    }
    if node.enabled && is_interactive(node) {
        if let Some(rect) = node.rect.filter(|r| !r.is_empty()) {
            let centre = rect.center();
            if window.on_screen.contains(centre) && !window.higher.iter().any(|r| r.contains(centre)) {
                if found.len() >= MAX_ELEMENTS {
                    *capped = true;
                    return;
                }
                found.push(Element {
                    role: node.role.clone(),
                    name: cut(&node.name),
                    value: node.value.as_deref().map(cut),
                    rect,
                    window_id: node.window_id.unwrap_or(window.id),
                    window: window.title.to_owned(),
                    window_rect: None,
                    focused: node.focused,
                });
            }
        }
    }
    for child in &node.children {
        walk(child, window, found, capped);
    }
}

/// Whether `element` is still where its state saw it, by the window list `now`: its
/// window is still open, not minimised, at the same place and size.
///
/// # Errors
///
/// What changed, naming the element (`number`) and its window.
pub fn check_current(number: u64, element: &Element, now: &[WindowInfo]) -> Result<(), String> {
    let stale = |what: &str| {
        Err(format!(
            "element {number} is stale: its window {:?} {what} since its state; call state again",
            element.window
        ))
    };
    let Some(window) = now.iter().find(|w| w.id == element.window_id) else {
        return stale("closed");
    };
    if window.minimized || !window.visible {
        return stale("was minimised or hidden");
    }
    if element.window_rect.is_some_and(|r| r != window.rect) {
        return stale("moved or was resized");
    }
    Ok(())
}

/// A session's numbered elements: the latest state's, and how far numbering has gone.
#[derive(Debug, Clone, Default)]
pub struct Numbering {
    /// How many states have been numbered; the latest one's id.
    states: u64,
    /// The first number of the latest state.
    first: u64,
    elements: Vec<Element>,
}

impl Numbering {
    /// Numbers `elements` as a new state, replacing the one before; answers the state's
    /// id and its first number (the elements are numbered from there in order).
    pub fn number(&mut self, elements: Vec<Element>) -> (u64, u64) {
        let next = if self.states == 0 { 1 } else { self.first + self.elements.len() as u64 };
        self.states += 1;
        self.first = next;
        self.elements = elements;
        (self.states, self.first)
    }

    /// The latest state's id (0 before the first).
    pub fn state(&self) -> u64 {
        self.states
    }

    /// The element numbered `number` in the latest state.
    ///
    /// # Errors
    ///
    /// A number no state gave, or one an earlier state gave (stale), named with what to do.
    pub fn get(&self, number: u64) -> Result<&Element, String> {
        if self.states == 0 {
            return Err(format!(
                "element {number} is unknown: no state has numbered any element yet; call state first"
            ));
        }
        let end = self.first + self.elements.len() as u64;
        let latest = if self.elements.is_empty() {
            format!("state {} numbered no element", self.states)
        } else {
            format!("state {} numbers its elements {} to {}", self.states, self.first, end - 1)
        };
        if number >= self.first && number < end {
            let index = usize::try_from(number - self.first).unwrap_or(usize::MAX);
            return self.elements.get(index).ok_or_else(|| format!("element {number} is unknown; {latest}"));
        }
        if number >= 1 && number < self.first {
            return Err(format!(
                "element {number} is stale: an earlier state numbered it, and {latest}; call state again for the screen as it is"
            ));
        }
        Err(format!("element {number} is unknown: no state numbered it; {latest}"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::observation::{A11yBackend, A11yStates};

    fn node(role: &str, name: &str, rect: Rect, children: Vec<A11yNode>) -> A11yNode {
        A11yNode {
            role: role.into(),
            name: name.into(),
            rect: Some(rect),
            enabled: true,
            visible: true,
            window_id: Some(7),
            children,
            ..A11yNode::default()
        }
    }

    fn tree(windows: Vec<A11yNode>) -> A11yTree {
        A11yTree {
            backend: A11yBackend::Uia,
            windows,
            truncated: false,
            node_count: 0,
            elapsed_ms: 0,
            coordinate_space: crate::geometry::CoordinateSpace::Physical,
            windows_walked: Vec::new(),
        }
    }

    #[test]
    fn elements_are_operable_visible_enabled_on_screen_and_uncovered() {
        let mut doc = node("Document", "Text Editor", Rect::new(10, 40, 300, 200), vec![]);
        doc.states = A11yStates { editable: Some(true), ..A11yStates::default() };
        let mut disabled = node("Button", "Greyed", Rect::new(20, 20, 10, 10), vec![]);
        disabled.enabled = false;
        let mut hidden = node(
            "Pane",
            "hidden",
            Rect::new(0, 0, 50, 50),
            vec![node("Button", "Inside", Rect::new(1, 1, 5, 5), vec![])],
        );
        hidden.visible = false;
        let pane = node(
            "Pane",
            "body",
            Rect::new(0, 0, 400, 300),
            vec![
                node("Text", "Label", Rect::new(0, 0, 40, 10), vec![]),
                node("Button", "Save", Rect::new(350, 10, 40, 20), vec![]),
                node("Button", "Off screen", Rect::new(-100, 10, 40, 20), vec![]),
                node("Button", "No size", Rect::new(5, 5, 0, 0), vec![]),
                disabled,
                hidden,
                doc,
            ],
        );
        let back = node("Window", "Back", Rect::new(0, 0, 800, 600), vec![pane]);
        // A window above covers the Save button's centre.
        let mut front = node(
            "Window",
            "Front",
            Rect::new(340, 0, 100, 100),
            vec![node("Button", "OK", Rect::new(360, 50, 30, 20), vec![])],
        );
        front.window_id = Some(9);
        front.children[0].window_id = Some(9);
        let windows = [WindowInfo { id: 9, rect: Rect::new(340, 0, 100, 100), ..WindowInfo::default() }];
        let (found, capped) = collect(&tree(vec![front, back]), &windows, (1024, 768));
        let names: Vec<(&str, &str, &str)> =
            found.iter().map(|e| (e.window.as_str(), e.role.as_str(), e.name.as_str())).collect();
        assert_eq!(names, [("Front", "Button", "OK"), ("Back", "Document", "Text Editor")]);
        assert!(!capped);
        assert_eq!((found[0].window_id, found[0].window_rect), (9, Some(Rect::new(340, 0, 100, 100))));
        assert_eq!(found[1].window_rect, None, "a window the list does not have");
        assert_eq!(found[1].centre(), Point::new(160, 140));
    }

    #[test]
    fn minimised_windows_neither_list_nor_cover() {
        let mut min =
            node("Window", "Min", Rect::new(0, 0, 800, 600), vec![node("Button", "A", Rect::new(1, 1, 9, 9), vec![])]);
        min.states.minimized = Some(true);
        let back =
            node("Window", "Back", Rect::new(0, 0, 800, 600), vec![node("Button", "B", Rect::new(1, 1, 9, 9), vec![])]);
        let (found, _) = collect(&tree(vec![min, back]), &[], (1024, 768));
        assert_eq!(found.iter().map(|e| e.name.as_str()).collect::<Vec<_>>(), ["B"]);
    }

    #[test]
    fn long_texts_are_cut_and_the_list_is_capped() {
        let long = "x".repeat(MAX_TEXT_CHARS + 5);
        let buttons = (0..MAX_ELEMENTS + 3).map(|_| node("Button", &long, Rect::new(1, 1, 9, 9), vec![])).collect();
        let (found, capped) =
            collect(&tree(vec![node("Window", "W", Rect::new(0, 0, 100, 100), buttons)]), &[], (100, 100));
        assert_eq!(found.len(), MAX_ELEMENTS);
        assert!(capped);
        assert_eq!(found[0].name.chars().count(), MAX_TEXT_CHARS);
        assert!(found[0].name.ends_with('…'));
    }

    #[test]
    fn numbers_run_on_across_states_and_old_ones_are_stale() {
        let element = |name: &str| Element {
            role: "Button".into(),
            name: name.into(),
            value: None,
            rect: Rect::new(0, 0, 2, 2),
            window_id: 1,
            window: "W".into(),
            window_rect: None,
            focused: false,
        };
        let mut numbering = Numbering::default();
        assert!(numbering.get(1).expect_err("none yet").contains("call state first"));
        assert_eq!(numbering.number(vec![element("a"), element("b")]), (1, 1));
        assert_eq!(numbering.get(2).map(|e| e.name.as_str()), Ok("b"));
        assert_eq!(numbering.number(vec![element("c")]), (2, 3));
        assert_eq!(numbering.get(3).map(|e| e.name.as_str()), Ok("c"));
        let stale = numbering.get(2).expect_err("stale");
        assert!(
            stale.starts_with("element 2 is stale") && stale.contains("state 2 numbers its elements 3 to 3"),
            "{stale}"
        );
        let unknown = numbering.get(4).expect_err("unknown");
        assert!(unknown.starts_with("element 4 is unknown"), "{unknown}");
        assert!(numbering.get(0).expect_err("unknown").starts_with("element 0 is unknown"));
        assert_eq!(numbering.number(Vec::new()), (3, 4));
        assert!(numbering.get(4).expect_err("none").contains("state 3 numbered no element"));
        assert_eq!(numbering.number(vec![element("d")]), (4, 4), "an empty state used no number");
    }

    #[test]
    fn an_element_whose_window_changed_is_stale() {
        let rect = Rect::new(10, 10, 300, 200);
        let element = Element {
            role: "Edit".into(),
            name: "Name".into(),
            value: None,
            rect: Rect::new(20, 50, 100, 20),
            window_id: 5,
            window: "Form".into(),
            window_rect: Some(rect),
            focused: false,
        };
        let window = WindowInfo { id: 5, rect, visible: true, ..WindowInfo::default() };
        assert_eq!(check_current(3, &element, std::slice::from_ref(&window)), Ok(()));
        let said = |now: &[WindowInfo]| check_current(3, &element, now).expect_err("stale");
        assert_eq!(said(&[]), "element 3 is stale: its window \"Form\" closed since its state; call state again");
        let moved = WindowInfo { rect: Rect::new(11, 10, 300, 200), ..window.clone() };
        assert!(said(&[moved]).contains("moved or was resized"));
        let minimised = WindowInfo { minimized: true, ..window };
        assert!(said(&[minimised]).contains("minimised"));
    }
}
