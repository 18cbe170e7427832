//! The stub's accessibility tree, derived from its windows, and the budget pruning.
//!
//! Each shown window becomes a node (UIA: role `Window` with a `TitleBar` of caption
//! buttons; Win32: roles from window classes, no title bar), then the scenario's
//! `elements`, then a document node when the window holds text. Program Manager comes
//! last, as UIA lists it, with its Desktop icon list. This is a model of the shapes
//! agents read, not a UI Automation provider.

use std::time::{Duration, Instant};

use arena_shared::geometry::{CoordinateSpace, Rect};
use arena_shared::observation::{A11yBackend, A11yNode, A11yStates, A11yTree, TreeBudget};

use super::input::ICON_PITCH;
use super::window::{Caption, State, Window};
use crate::desktop::{DesktopError, DesktopResult};

/// The Win32 role (pywinauto's friendly class name) of a window class, or `fallback`.
fn win32_role(class_name: &str, fallback: &str) -> String {
    let known = match class_name {
        "Edit" | "RichEdit20W" | "RICHEDIT50W" => "Edit",
        "Button" => "Button",
        "Static" => "Static",
        "ComboBox" | "ComboBoxEx32" => "ComboBox",
        "ListBox" => "ListBox",
        "SysListView32" => "ListView",
        "SysTreeView32" => "TreeView",
        "SysTabControl32" => "TabControl",
        "ToolbarWindow32" => "Toolbar",
        "msctls_statusbar32" => "StatusBar",
        "#32770" => "Dialog",
        "" => fallback,
        other => other,
    };
    known.to_owned()
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

/// The running count and limits of one walk.
struct Walk {
    budget: TreeBudget,
    deadline: Option<Instant>,
    count: u32,
    truncated: bool,
}

impl Walk {
    fn out_of_budget(&mut self) -> bool {
        let over_time = self.deadline.is_some_and(|d| Instant::now() >= d);
        if self.count >= self.budget.max_nodes || over_time {
            self.truncated = true;
            return true;
        }
        false
    }

    /// Emits `node` at `depth` (top-level windows are 1) with as much of its subtree as
    /// the budget allows; `None` when the budget is spent.
    fn emit(&mut self, mut node: A11yNode, depth: u32, window_id: u64) -> Option<A11yNode> {
        if depth > self.budget.max_depth || self.out_of_budget() {
            self.truncated = true;
            return None;
        }
        self.count += 1;
        node.window_id = Some(window_id);
        let children = std::mem::take(&mut node.children);
        if depth >= self.budget.max_depth {
            self.truncated |= !children.is_empty();
            return Some(node);
        }
        let keep = self.budget.max_children as usize;
        if children.len() > keep {
            self.truncated = true;
        }
        for child in children.into_iter().take(keep) {
            match self.emit(child, depth + 1, window_id) {
                Some(child) => node.children.push(child),
                None => break,
            }
        }
        Some(node)
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
    let started = Instant::now();
    let mut walk = Walk {
        budget: *budget,
        deadline: started.checked_add(Duration::from_millis(budget.max_ms)),
        count: 0,
        truncated: false,
    };
    let windows: Vec<&Window> =
        state.windows.iter().filter(|w| w.shown() && (!foreground_only || w.id == state.focus)).collect();
    let keep = budget.max_children as usize;
    if windows.len() > keep {
        walk.truncated = true;
    }
    let mut out = Vec::new();
    for window in windows.into_iter().take(keep) {
        let node = window_node(window, window.id == state.focus, backend, desktop_items);
        match walk.emit(node, 1, window.id) {
            Some(node) => out.push(node),
            None => break,
        }
    }
    Ok(A11yTree {
        backend,
        windows: out,
        truncated: walk.truncated,
        node_count: walk.count,
        elapsed_ms: u64::try_from(started.elapsed().as_millis()).unwrap_or(u64::MAX),
        coordinate_space: CoordinateSpace::Physical,
    })
}
