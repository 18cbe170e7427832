//! The stub's accessibility tree, derived from its windows, and the budget pruning.
//!
//! Each window a person sees (the Windows backend's root filter,
//! [`shell::seen_on_desktop`], over the scenario's styles) becomes a node (UIA: role
//! `Window` with a `TitleBar` of caption buttons; Win32: roles from window classes, no
//! title bar), then the scenario's `elements`, then File Explorer's navigation tree and
//! items list for a window showing a folder, then a document node when the window
//! holds text. A popup menu is a `Menu` (UIA) or `PopupMenu` (win32) of its items. Program Manager comes
//! last, as UIA lists it, with its Desktop icon list. This is a model of the shapes
//! agents read, not a UI Automation provider.
//!
//! The budget pruning is not the stub's own: the windows' trees are fed through the
//! same walker as the Windows backend's ([`arena_a11y_walk`]), so fair
//! shares, caps, the bulk fetch's part of a window's time and the `truncated` flag
//! behave the same in every stub run. A scenario can make UI Automation slow per
//! window (`bulk_fetch_ms`, `element_ms`) or empty ([`UiaModel`]).

use std::time::Duration;

use arena_shared::geometry::Rect;
use arena_shared::observation::{A11yBackend, A11yNode, A11yStates, A11yTree, TreeBudget};

use super::input::ICON_PITCH;
use super::window::{Caption, Dialog, Listings, State, Window, WindowModel, EXPLORER_NAV, RUN_FIELD_LABEL, RUN_PROMPT};
use crate::desktop::cancel;
use crate::desktop::windows::shell;
use crate::desktop::{DesktopError, DesktopResult};
use arena_a11y_walk::{self as a11y_walk, TreeSource};

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
fn window_node(window: &Window, focused: bool, backend: A11yBackend, listings: &Listings) -> A11yNode {
    let uia = backend != A11yBackend::Win32;
    let mut node = leaf(
        &if window.is_desktop {
            if uia {
                "Pane".to_owned()
            } else {
                win32_role(&window.class_name, "Pane")
            }
        } else if uia {
            // UI Automation's HWND proxy gives a popup menu (`#32768`) the Menu control type.
            if window.model.popup && window.class_name == "#32768" { "Menu" } else { "Window" }.to_owned()
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
        list.children = listings
            .desktop
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
    if window.model.popup {
        // A popup has no caption and no window states: just its items.
        node.children = window.elements.clone();
        if !uia {
            node.children.iter_mut().for_each(to_win32_roles);
        }
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
    if window.dialog.is_some() {
        let mut controls = dialog_controls(window, focused);
        if !uia {
            controls.iter_mut().for_each(to_win32_roles);
        }
        node.children.extend(controls);
        return node;
    }
    if let Some(items) = listings.folders.get(&window.id) {
        node.children.extend(explorer_panes(window, items, uia));
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

/// A File Explorer window's panes as UI Automation shows them: the navigation pane's
/// tree and the items view's list, an item per entry of the folder, where they are drawn.
fn explorer_panes(window: &Window, items: &[String], uia: bool) -> [A11yNode; 2] {
    let (nav_rect, list_rect) = window.explorer_panes();
    let (tree_role, tree_item, list_role, list_item) = if uia {
        ("Tree", "TreeItem", "List", "ListItem")
    } else {
        ("TreeView", "TreeItem", "ListView", "ListViewItem")
    };
    let rows = |pane: Rect, names: &mut dyn Iterator<Item = &str>, role: &str| -> Vec<A11yNode> {
        names
            .enumerate()
            .map(|(i, name)| {
                let mut row = leaf(role, "", name, Window::explorer_row(pane, i));
                // A row below the pane is there but scrolled out of view.
                row.visible = row.rect.is_some_and(|r| r.bottom() <= pane.bottom());
                row
            })
            .collect()
    };
    let mut nav = leaf(tree_role, "SysTreeView32", "Navigation Pane", nav_rect);
    nav.children = rows(nav_rect, &mut EXPLORER_NAV.iter().copied(), tree_item);
    let mut list = leaf(list_role, "UIItemsView", "Items View", list_rect);
    list.children = rows(list_rect, &mut items.iter().map(String::as_str), list_item);
    [nav, list]
}

/// A dialog's controls with UI Automation's control types and their Win32 classes: its
/// text (`Static`), the Run dialog's `Open:` combo box holding the command's edit field,
/// and its buttons.
fn dialog_controls(window: &Window, focused: bool) -> Vec<A11yNode> {
    let (Some(dialog), Some(parts)) = (&window.dialog, window.dialog_parts()) else {
        return Vec::new();
    };
    let text = match dialog {
        Dialog::Run => RUN_PROMPT,
        Dialog::Message(message) => message.as_str(),
    };
    let body = window.body();
    let text_rect =
        Rect::new(parts.text_at.x, parts.text_at.y, body.right() - parts.text_at.x, 3 * super::window::LINE_H);
    let mut controls = vec![leaf("Text", "Static", text, text_rect)];
    if let (Some((label_at, field)), Some(buf)) = (parts.field, &window.text) {
        let label_w = RUN_FIELD_LABEL.len() as i32 * super::window::GLYPH_W;
        controls.push(leaf("Text", "Static", RUN_FIELD_LABEL, Rect::new(label_at.x, field.y, label_w, field.height)));
        let mut edit = leaf("Edit", "Edit", RUN_FIELD_LABEL, field);
        edit.value = Some(buf.text.clone());
        edit.focused = focused;
        edit.states.editable = Some(true);
        let mut combo = leaf("ComboBox", "ComboBox", RUN_FIELD_LABEL, field);
        combo.value = Some(buf.text.clone());
        combo.children.push(edit);
        controls.push(combo);
    }
    controls.extend(parts.buttons.iter().map(|(button, r)| leaf("Button", "Button", button.label(), *r)));
    controls
}

fn to_win32_roles(node: &mut A11yNode) {
    node.role = win32_role(&node.class_name, &node.role);
    for child in &mut node.children {
        to_win32_roles(child);
    }
}

/// The modelled UI Automation client: whether it answers empty trees, and how often
/// it was re-created (see the scenario's `uia_empty_until_recreated` and `uia_empty`).
#[derive(Debug, Default)]
pub(crate) struct UiaModel {
    /// Empty trees until the next re-creation.
    empty_until_recreated: bool,
    /// Empty trees whatever happens.
    always_empty: bool,
    pub(crate) recreations: u32,
}

impl UiaModel {
    pub(crate) fn new(empty_until_recreated: bool, always_empty: bool) -> UiaModel {
        UiaModel { empty_until_recreated, always_empty, recreations: 0 }
    }

    pub(crate) fn answers_empty(&self) -> bool {
        self.always_empty || self.empty_until_recreated
    }

    /// A new automation client: the fault a re-creation cures is gone.
    pub(crate) fn recreate(&mut self) {
        self.recreations += 1;
        self.empty_until_recreated = false;
    }
}

/// One window a tree may walk: its full tree, copied out of the desktop's state,
/// and what its scenario says UI Automation costs.
#[derive(Debug)]
pub(crate) struct StubRoot {
    id: u64,
    node: A11yNode,
    model: WindowModel,
    focused: bool,
}

/// The windows the trees walk, topmost first: those the shell's own rule
/// ([`shell::seen_on_desktop`], the Windows backend's root filter) says a person sees,
/// minimised ones left out; only the focused one when `foreground_only`.
///
/// # Errors
///
/// [`DesktopError::InvalidInput`] for [`A11yBackend::Unknown`].
pub(crate) fn roots(
    state: &State,
    backend: A11yBackend,
    foreground_only: bool,
    listings: &Listings,
) -> DesktopResult<Vec<StubRoot>> {
    if backend == A11yBackend::Unknown {
        return Err(DesktopError::InvalidInput("unknown accessibility backend".into()));
    }
    let foreground_pid = state.window(state.focus).map_or(0, |w| w.pid);
    Ok(state
        .windows
        .iter()
        .filter(|w| !w.minimized && shell::seen_on_desktop(w.facts(foreground_pid)))
        .filter(|w| !foreground_only || w.id == state.focus)
        .map(|w| StubRoot {
            id: w.id,
            node: window_node(w, w.id == state.focus, backend, listings),
            model: w.model,
            focused: w.id == state.focus,
        })
        .collect())
}

/// The stub's windows as a [`TreeSource`]: the walker reads the copied trees by
/// reference, and each window's modelled costs are paid as UI Automation would
/// charge them: `bulk_fetch_ms` in [`TreeSource::prepare`] (UIA only: the win32
/// source has no bulk fetch), `element_ms` per element read one by one (win32
/// always, UIA after a failed bulk fetch; a bulk fetch that worked reads a cache).
struct StubSource<'a> {
    windows: &'a [StubRoot],
    backend: A11yBackend,
    /// The costs of the window being read.
    current: WindowModel,
    /// Elements are being read one by one.
    live: bool,
    /// The threads of bulk fetches abandoned while they hang.
    fetches: crate::desktop::uia_health::ThreadCap,
}

impl<'a> TreeSource for StubSource<'a> {
    type Elem = &'a A11yNode;
    type Error = DesktopError;

    fn roots(&mut self, _foreground_only: bool) -> DesktopResult<Vec<(u64, &'a A11yNode)>> {
        // `roots` above already kept only the foreground window when asked to.
        Ok(self.windows.iter().map(|root| (root.id, &root.node)).collect())
    }

    fn foreground_id(&mut self) -> Option<u64> {
        self.windows.iter().find(|root| root.focused).map(|root| root.id)
    }

    fn prepare(&mut self, root: &&'a A11yNode, time: Duration) -> DesktopResult<&'a A11yNode> {
        self.current =
            self.windows.iter().find(|w| std::ptr::eq(&w.node, *root)).map_or_else(WindowModel::default, |w| w.model);
        self.live = self.backend == A11yBackend::Win32;
        let bulk = self.current.bulk_fetch_ms;
        if self.backend == A11yBackend::Uia && bulk > 0 && self.current.bulk_fetch_hangs {
            // A fetch that ignores its timeout runs on a thread of its own, as the
            // Windows source's does, and is abandoned at the time offered: the
            // element-by-element read starts then, not when the fetch ends.
            let fetch = move || std::thread::sleep(Duration::from_millis(bulk));
            crate::desktop::uia_health::call_detached(
                &self.fetches,
                time,
                "BuildUpdatedCache (a hung provider)",
                fetch,
            )?;
            return Ok(*root);
        }
        if self.backend == A11yBackend::Uia && bulk > 0 {
            let offered = u64::try_from(time.as_millis()).unwrap_or(u64::MAX);
            if bulk > offered {
                // As a UIA transaction timeout: the whole time offered, then a failure.
                cancel::sleep(time)?;
                return Err(DesktopError::Timeout {
                    op: "BuildUpdatedCache (the scenario's bulk_fetch_ms)",
                    ms: offered,
                });
            }
            cancel::sleep(Duration::from_millis(bulk))?;
        }
        Ok(*root)
    }

    fn prepare_partial(
        &mut self,
        root: &&'a A11yNode,
        _time: Duration,
        _failed: DesktopError,
    ) -> DesktopResult<&'a A11yNode> {
        self.live = true;
        Ok(*root)
    }

    fn record(&mut self, elem: &&'a A11yNode) -> A11yNode {
        if self.live && self.current.element_ms > 0 {
            // A cancelled call stops paying; the walker's deadline ends the walk.
            let _ = cancel::sleep(Duration::from_millis(self.current.element_ms));
        }
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

/// Walks `roots` within `budget` through the shared walker; `uia_empty` models a UI
/// Automation that answers empty trees (no top-level windows at all).
pub(crate) fn walk(
    roots: Vec<StubRoot>,
    backend: A11yBackend,
    budget: &TreeBudget,
    foreground_only: bool,
    uia_empty: bool,
) -> DesktopResult<A11yTree> {
    let windows = if uia_empty { Vec::new() } else { roots };
    let mut source = StubSource {
        windows: &windows,
        backend,
        current: WindowModel::default(),
        live: false,
        fetches: crate::desktop::uia_health::ThreadCap::new(4),
    };
    a11y_walk::walk(&mut source, backend, budget, foreground_only)
}
