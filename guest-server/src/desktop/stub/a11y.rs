//! The stub's accessibility tree, derived from its windows, and the budget pruning.
//!
//! Each shown window becomes a node (UIA: role `Window` with a `TitleBar` of caption
//! buttons; Win32: roles from window classes, no title bar), then the scenario's
//! `elements`, then a document node when the window holds text. Program Manager comes
//! last, as UIA lists it, with its Desktop icon list. This is a model of the shapes
//! agents read, not a UI Automation provider.
//!
//! The budget pruning is not the stub's own: the windows' trees are fed through the
//! same walker as the Windows backend's ([`crate::desktop::a11y_walk`]), so fair
//! shares, caps and the `truncated` flag behave the same in every stub run.

use arena_shared::geometry::Rect;
use arena_shared::observation::{A11yBackend, A11yNode, A11yStates, A11yTree, TreeBudget};

use super::input::ICON_PITCH;
use super::window::{Caption, State, Window};
use crate::desktop::a11y_walk::{self, TreeSource};
use crate::desktop::{DesktopError, DesktopResult};

/// The Win32 role (pywinauto's friendly class name) of a window class, or `fallback`
/// for a node without a class.
fn win32_role(class_name: &str, fallback: &str) -> String {
    if class_name.is_empty() {
        return fallback.to_owned();
    }
    a11y_walk::win32_role(class_name).to_owned()
}

fn leaf(role: &str, class_name: &str, name: &str, rect: Rect) -> A11yNode {
    A11yNode {
        role: role.to_owned(),
        class_name: class_name.to_owned(),
        name: name.to_owned(),
        rect: Some(rect),
        enabled: true,
        visible: true,
        ..A11yNode::default()
    }
}

/// The full (unpruned) tree of one window.
fn window_node(window: &Window, focused: bool, backend: A11yBackend, desktop_items: &[String]) -> A11yNode {
    let uia = backend != A11yBackend::Win32;
    let mut node = leaf(
        &if window.is_desktop {
            if uia {
                "Pane".to_owned()
            } else {
                win32_role(&window.class_name, "Pane")
            }
        } else if uia {
            "Window".to_owned()
        } else {
            win32_role(&window.class_name, "Window")
        },
        &window.class_name,
        &window.title,
        window.rect,
    );
    node.focused = focused;
    if window.is_desktop {
        let mut list = leaf(if uia { "List" } else { "ListView" }, "SysListView32", "Desktop", window.rect);
        list.children = desktop_items
            .iter()
            .enumerate()
            .map(|(i, name)| {
                leaf(
                    if uia { "ListItem" } else { "ListViewItem" },
                    "",
                    name,
                    Rect::new(4, i as i32 * ICON_PITCH + 6, 140, ICON_PITCH - 2),
                )
            })
            .collect();
        node.children.push(list);
        return node;
    }
    node.states =
        A11yStates { minimized: Some(window.minimized), maximized: Some(window.maximized), ..A11yStates::default() };
    if uia {
        let mut bar = leaf("TitleBar", "", &window.title, window.title_bar());
        bar.children = window
            .captions()
            .iter()
            .map(|(caption, rect)| {
                let name = match caption {
                    Caption::Minimize => "Minimize",
                    Caption::Maximize if window.maximized => "Restore",
                    Caption::Maximize => "Maximize",
                    Caption::Close => "Close",
                };
                leaf("Button", "", name, *rect)
            })
            .collect();
        node.children.push(bar);
    }
    for element in &window.elements {
        let mut element = element.clone();
        if !uia {
            to_win32_roles(&mut element);
        }
        node.children.push(element);
    }
    if let Some(buf) = &window.text {
        let mut doc = leaf(if uia { "Document" } else { "Edit" }, "Edit", "Text Editor", window.body());
        doc.value = Some(buf.text.clone());
        doc.focused = focused;
        doc.states.editable = Some(true);
        node.children.push(doc);
    }
    node
}

fn to_win32_roles(node: &mut A11yNode) {
    node.role = win32_role(&node.class_name, &node.role);
    for child in &mut node.children {
        to_win32_roles(child);
    }
}

/// The stub's windows as a [`TreeSource`]: each shown window's full tree is built
/// first, and the walker reads it by reference.
struct StubSource<'a> {
    windows: &'a [(u64, A11yNode)],
}

impl<'a> TreeSource for StubSource<'a> {
    type Elem = &'a A11yNode;

    fn roots(&mut self, _foreground_only: bool) -> DesktopResult<Vec<(u64, &'a A11yNode)>> {
        // `tree` already kept only the foreground window when asked to.
        Ok(self.windows.iter().map(|(id, node)| (*id, node)).collect())
    }

    fn record(&mut self, elem: &&'a A11yNode) -> A11yNode {
        let A11yNode {
            role, class_name, name, value, text, rect, enabled, visible, focused, states, window_id, ..
        } = *elem;
        A11yNode {
            role: role.clone(),
            class_name: class_name.clone(),
            name: name.clone(),
            value: value.clone(),
            text: text.clone(),
            rect: *rect,
            enabled: *enabled,
            visible: *visible,
            focused: *focused,
            states: states.clone(),
            window_id: *window_id,
            children: Vec::new(),
        }
    }

    fn children(&mut self, elem: &&'a A11yNode, limit: usize) -> Vec<&'a A11yNode> {
        elem.children.iter().take(limit.saturating_add(1)).collect()
    }
}

/// Walks the shown windows, topmost first, within `budget`.
///
/// # Errors
///
/// [`DesktopError::InvalidInput`] for [`A11yBackend::Unknown`].
pub(crate) fn tree(
    state: &State,
    backend: A11yBackend,
    budget: &TreeBudget,
    foreground_only: bool,
    desktop_items: &[String],
) -> DesktopResult<A11yTree> {
    if backend == A11yBackend::Unknown {
        return Err(DesktopError::InvalidInput("unknown accessibility backend".into()));
    }
    let windows: Vec<(u64, A11yNode)> = state
        .windows
        .iter()
        .filter(|w| w.shown() && (!foreground_only || w.id == state.focus))
        .map(|w| (w.id, window_node(w, w.id == state.focus, backend, desktop_items)))
        .collect();
    a11y_walk::walk(&mut StubSource { windows: &windows }, backend, budget, foreground_only)
}
