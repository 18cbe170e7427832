//! The accessibility-tree walker of every backend, behind a small adapter.
//!
//! Every tree walks the same way (the two Windows sources and the stub's model): the visible top-level windows,
//! topmost first, each within a fair share of the node and time budget, depth and
//! width caps as upstream WAA (50 and 2048), and a `truncated` flag when anything was
//! left out. What differs is where elements come from, so that sits behind
//! [`TreeSource`]:
//!
//! - `uia`: IUIAutomation with a cache request; [`TreeSource::prepare`] is one
//!   `BuildUpdatedCache(TreeScope_Subtree)` per window and the walk then reads the cache;
//! - `win32`: `EnumWindows`/`EnumChildWindows`, `WM_GETTEXT` with a timeout and MSAA values;
//! - the stub: its windows' modelled trees, read by reference.
//!
//! The Windows sources live in `desktop/windows/`, the stub's in `desktop/stub/a11y.rs`; this module holds the walk, the budget
//! arithmetic and the mapping from raw properties ([`UiaProps`], [`Win32Props`]) to
//! [`A11yNode`]s, and is tested natively with a fake tree. Nothing here calls the OS.

use std::time::{Duration, Instant};

use arena_shared::geometry::{CoordinateSpace, Rect};
use arena_shared::observation::{A11yBackend, A11yNode, A11yStates, A11yTree, TreeBudget, WindowWalk};

use super::{DesktopError, DesktopResult};

/// A window that gets less than this many milliseconds is still given this much, so
/// a share never rounds down to nothing.
const MIN_WINDOW_MS: u64 = 50;
/// Likewise for nodes.
const MIN_WINDOW_NODES: u32 = 16;

/// Where elements come from. `Elem` is whatever handle the source uses (an HWND, a
/// cached UIA element); it never leaves the thread the walk runs on.
pub trait TreeSource {
    type Elem: Clone;

    /// The visible top-level windows, topmost first, with their window ids (HWNDs);
    /// only the foreground one when `foreground_only`.
    ///
    /// # Errors
    ///
    /// The enumeration failing as a whole.
    fn roots(&mut self, foreground_only: bool) -> DesktopResult<Vec<(u64, Self::Elem)>>;

    /// The foreground window's id, when the source knows it: that window is walked
    /// first and with the larger share, since it is the one the agent works in.
    fn foreground_id(&mut self) -> Option<u64> {
        None
    }

    /// Readies one window for reading, given the time it may take (UIA: one cached
    /// subtree fetch, all or nothing). The default does nothing.
    ///
    /// # Errors
    ///
    /// The window being gone, hung or refusing; the walk then tries [`TreeSource::prepare_partial`].
    fn prepare(&mut self, root: &Self::Elem, _time: Duration) -> DesktopResult<Self::Elem> {
        Ok(root.clone())
    }

    /// A slower way to read a window whose [`TreeSource::prepare`] failed, element by
    /// element, so that what can be read within `time` is kept (UIA: a small cache
    /// request per element instead of the whole subtree at once). The default gives up
    /// with `failed`, and the walk skips the window.
    ///
    /// # Errors
    ///
    /// The window cannot be read at all.
    fn prepare_partial(
        &mut self,
        _root: &Self::Elem,
        _time: Duration,
        failed: DesktopError,
    ) -> DesktopResult<Self::Elem> {
        Err(failed)
    }

    /// The element's properties.
    fn record(&mut self, elem: &Self::Elem) -> A11yNode;

    /// Up to `limit + 1` children of the element, in order (one more than kept, so the
    /// walk can tell the list was cut).
    fn children(&mut self, elem: &Self::Elem, limit: usize) -> Vec<Self::Elem>;
}

/// The running counts and limits of one walk.
struct Walk {
    budget: TreeBudget,
    count: u32,
    truncated: bool,
}

/// The share of one window: the node count and the instant it must stop at.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Share {
    nodes: u32,
    time: Duration,
}

/// Of what is left, the part the foreground window gets when other windows follow it.
const FOREGROUND_PART: (u32, u32) = (3, 4);

/// The foreground window's share: three quarters of what is left when other windows
/// follow (they split the rest, plus whatever it leaves unused), all of it otherwise.
fn foreground_share(nodes_left: u32, time_left: Duration, windows_left: usize) -> Share {
    if windows_left <= 1 {
        return share(nodes_left, time_left, 1);
    }
    let (num, den) = FOREGROUND_PART;
    let nodes = u32::try_from(u64::from(nodes_left) * u64::from(num) / u64::from(den)).unwrap_or(nodes_left);
    let ms = u64::try_from(time_left.as_millis()).unwrap_or(u64::MAX);
    Share {
        nodes: nodes.max(MIN_WINDOW_NODES).min(nodes_left),
        time: Duration::from_millis((ms / u64::from(den) * u64::from(num)).max(MIN_WINDOW_MS).min(ms)),
    }
}

/// A fair share of what is left for the next window, with `windows_left` windows
/// (including this one) still to walk. What a window leaves unused flows to the next.
fn share(nodes_left: u32, time_left: Duration, windows_left: usize) -> Share {
    let n = u32::try_from(windows_left.max(1)).unwrap_or(u32::MAX);
    let nodes = (nodes_left / n).max(MIN_WINDOW_NODES).min(nodes_left);
    let ms = u64::try_from(time_left.as_millis()).unwrap_or(u64::MAX);
    let time_ms = (ms / u64::from(n)).max(MIN_WINDOW_MS).min(ms);
    Share { nodes, time: Duration::from_millis(time_ms) }
}

impl Walk {
    /// Emits `elem` at `depth` (top-level windows are 1) with as much of its subtree as
    /// fits in `limit` nodes before `deadline`; `None` when nothing fits.
    fn emit<S: TreeSource>(
        &mut self,
        source: &mut S,
        elem: &S::Elem,
        depth: u32,
        window_id: u64,
        limit: u32,
        deadline: Instant,
    ) -> Option<A11yNode> {
        // A depth cap of 0 keeps nothing, not even the windows.
        if depth > self.budget.max_depth || self.count >= limit || Instant::now() >= deadline {
            self.truncated = true;
            return None;
        }
        self.count += 1;
        let mut node = source.record(elem);
        node.window_id = Some(window_id);
        node.children.clear();
        let keep = self.budget.max_children as usize;
        if depth >= self.budget.max_depth {
            // Upstream silently drops what is below the depth cap; say the tree is partial.
            self.truncated |= !source.children(elem, 0).is_empty();
            return Some(node);
        }
        let children = source.children(elem, keep);
        if children.len() > keep {
            self.truncated = true;
        }
        for child in children.iter().take(keep) {
            match self.emit(source, child, depth + 1, window_id, limit, deadline) {
                Some(child) => node.children.push(child),
                None => break,
            }
        }
        Some(node)
    }
}

/// Walks `source` within `budget`: the shown top-level windows, listed topmost first.
///
/// The foreground window is walked first with three quarters of the budget (see
/// [`foreground_share`]); the others then get fair shares of the nodes and time
/// still left (see the module documentation), so one huge window cannot starve the
/// others. A window whose [`TreeSource::prepare`] fails is read element by element
/// through [`TreeSource::prepare_partial`] and keeps what fits; one that cannot be
/// read at all is skipped. Any cut flags the tree `truncated`, and
/// [`A11yTree::windows_walked`] says per window how many nodes, how long, and whether
/// it was cut, partial or skipped.
///
/// # Errors
///
/// Only the source failing to list the windows; per-window failures are skipped.
pub fn walk<S: TreeSource>(
    source: &mut S,
    backend: A11yBackend,
    budget: &TreeBudget,
    foreground_only: bool,
) -> DesktopResult<A11yTree> {
    let started = Instant::now();
    let total_time = Duration::from_millis(budget.max_ms);
    let mut walk = Walk { budget: *budget, count: 0, truncated: false };
    let mut roots = source.roots(foreground_only)?;
    let keep = budget.max_children as usize;
    if roots.len() > keep {
        walk.truncated = true;
        roots.truncate(keep);
    }
    let total = roots.len();
    // The order of walking: the foreground window first, then the others topmost first.
    let foreground = source.foreground_id().and_then(|id| roots.iter().position(|(w, _)| *w == id));
    let mut order: Vec<usize> = (0..total).collect();
    if let Some(pos) = foreground {
        order.remove(pos);
        order.insert(0, pos);
    }
    let mut slots: Vec<Option<A11yNode>> = vec![None; total];
    let mut walked: Vec<Option<WindowWalk>> = vec![None; total];
    for (k, &i) in order.iter().enumerate() {
        let (window_id, root) = &roots[i];
        let window_id = *window_id;
        let time_left = total_time.saturating_sub(started.elapsed());
        let nodes_left = budget.max_nodes.saturating_sub(walk.count);
        if time_left.is_zero() || nodes_left == 0 {
            walk.truncated = true;
            for &j in &order[k..] {
                walked[j] = Some(WindowWalk::skipped(roots[j].0, "the tree's budget was spent"));
            }
            break;
        }
        let share = if Some(i) == foreground {
            foreground_share(nodes_left, time_left, total - k)
        } else {
            share(nodes_left, time_left, total - k)
        };
        let window_started = Instant::now();
        let deadline = window_started + share.time;
        let (prepared, partial) = match source.prepare(root, share.time) {
            Ok(prepared) => (Ok(prepared), false),
            Err(err) => {
                tracing::debug!(window_id, %err, "the window's cached fetch failed; reading it element by element");
                let left = deadline.saturating_duration_since(Instant::now());
                (source.prepare_partial(root, left, err), true)
            }
        };
        let root = match prepared {
            Ok(root) => root,
            Err(err) => {
                tracing::debug!(window_id, %err, "skipping a window the accessibility source could not read");
                walk.truncated = true;
                walked[i] = Some(WindowWalk::skipped(window_id, &err.to_string()));
                continue;
            }
        };
        let (count_before, truncated_before) = (walk.count, walk.truncated);
        walk.truncated = partial;
        let limit = walk.count.saturating_add(share.nodes);
        slots[i] = walk.emit(source, &root, 1, window_id, limit, deadline);
        let cut = walk.truncated;
        walk.truncated |= truncated_before;
        walked[i] = Some(WindowWalk {
            window_id,
            nodes: walk.count - count_before,
            ms: u64::try_from(window_started.elapsed().as_millis()).unwrap_or(u64::MAX),
            truncated: cut,
            partial,
            skipped: None,
        });
    }
    Ok(A11yTree {
        backend,
        windows: slots.into_iter().flatten().collect(),
        truncated: walk.truncated,
        node_count: walk.count,
        elapsed_ms: u64::try_from(started.elapsed().as_millis()).unwrap_or(u64::MAX),
        coordinate_space: CoordinateSpace::Physical,
        windows_walked: walked.into_iter().flatten().collect(),
    })
}

/// The UIA properties and pattern states the cache request fetches for one element.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct UiaProps {
    pub control_type: i32,
    pub class_name: String,
    pub name: String,
    /// BoundingRectangle as left, top, width, height (UIA's own order); all zero when absent.
    pub bounds: [f64; 4],
    pub enabled: bool,
    pub offscreen: bool,
    pub has_keyboard_focus: bool,
    /// ValuePattern.Value, when the element supports the pattern.
    pub value: Option<String>,
    /// ValuePattern.IsReadOnly.
    pub value_read_only: Option<bool>,
    /// WindowPattern.WindowVisualState (0 normal, 1 maximised, 2 minimised).
    pub window_visual_state: Option<i32>,
    /// ExpandCollapsePattern.ExpandCollapseState (0 collapsed, 1 expanded, 2 partial, 3 leaf).
    pub expand_collapse_state: Option<i32>,
    /// SelectionItemPattern.IsSelected.
    pub selected: Option<bool>,
    /// TogglePattern.ToggleState (0 off, 1 on, 2 indeterminate).
    pub toggle_state: Option<i32>,
}

/// The programmatic name of a UIA control type id (`UIA_ButtonControlTypeId` is 50000).
pub fn control_type_name(id: i32) -> &'static str {
    const NAMES: [&str; 41] = [
        "Button",
        "Calendar",
        "CheckBox",
        "ComboBox",
        "Edit",
        "Hyperlink",
        "Image",
        "ListItem",
        "List",
        "Menu",
        "MenuBar",
        "MenuItem",
        "ProgressBar",
        "RadioButton",
        "ScrollBar",
        "Slider",
        "Spinner",
        "StatusBar",
        "Tab",
        "TabItem",
        "Text",
        "ToolBar",
        "ToolTip",
        "Tree",
        "TreeItem",
        "Custom",
        "Group",
        "Thumb",
        "DataGrid",
        "DataItem",
        "Document",
        "SplitButton",
        "Window",
        "Pane",
        "Header",
        "HeaderItem",
        "Table",
        "TitleBar",
        "Separator",
        "SemanticZoom",
        "AppBar",
    ];
    usize::try_from(id - 50000).ok().and_then(|i| NAMES.get(i)).copied().unwrap_or("Custom")
}

/// Converts a UIA rectangle (left, top, width, height in physical pixels) into a [`Rect`];
/// `None` for an empty or non-finite one (UIA's "no rectangle").
pub fn uia_rect(bounds: [f64; 4]) -> Option<Rect> {
    if bounds.iter().any(|v| !v.is_finite()) || bounds[2] <= 0.0 || bounds[3] <= 0.0 {
        return None;
    }
    let clamp = |v: f64| v.round().clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32;
    Some(Rect::new(clamp(bounds[0]), clamp(bounds[1]), clamp(bounds[2]), clamp(bounds[3])))
}

impl UiaProps {
    /// The node these properties describe (children not included).
    pub fn into_node(self) -> A11yNode {
        let states = A11yStates {
            minimized: self.window_visual_state.map(|s| s == 2),
            maximized: self.window_visual_state.map(|s| s == 1),
            // A leaf node (3) has nothing to expand: report no state, as pywinauto does.
            expanded: self.expand_collapse_state.filter(|&s| s != 3).map(|s| s == 1 || s == 2),
            selected: self.selected,
            checked: self.toggle_state.filter(|&s| s != 2).map(|s| s == 1),
            editable: self.value_read_only.map(|ro| !ro),
        };
        A11yNode {
            role: control_type_name(self.control_type).to_owned(),
            class_name: self.class_name,
            name: self.name,
            value: self.value,
            text: None,
            rect: uia_rect(self.bounds),
            enabled: self.enabled,
            visible: !self.offscreen,
            focused: self.has_keyboard_focus,
            states,
            window_id: None,
            children: Vec::new(),
        }
    }
}

/// What the win32 backend reads about one window or child window.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Win32Props {
    pub class_name: String,
    /// `WM_GETTEXT` (or `None` when the window did not answer in time).
    pub text: Option<String>,
    /// Outer rectangle: left, top, right, bottom.
    pub ltrb: [i32; 4],
    pub visible: bool,
    pub enabled: bool,
    pub focused: bool,
    /// Minimised / maximised, for top-level windows.
    pub minimized: Option<bool>,
    pub maximized: Option<bool>,
    /// The MSAA value (`IAccessible::get_accValue`) where the window has one.
    pub msaa_value: Option<String>,
    /// Whether an edit control is read-only (`ES_READONLY`).
    pub read_only: Option<bool>,
    /// Button check state for check boxes and radio buttons (`BM_GETCHECK`).
    pub checked: Option<bool>,
}

/// pywinauto's friendly class name (the win32 role) of a window class.
pub fn win32_role(class_name: &str) -> &str {
    let lower = class_name.to_ascii_lowercase();
    match lower.as_str() {
        "edit" | "richedit" | "richedit20a" | "richedit20w" | "richedit50w" | "tmemo" | "tedit" => "Edit",
        "button" => "Button",
        "static" => "Static",
        "combobox" | "comboboxex32" => "ComboBox",
        "listbox" => "ListBox",
        "syslistview32" => "ListView",
        "systreeview32" => "TreeView",
        "systabcontrol32" => "TabControl",
        "toolbarwindow32" => "Toolbar",
        "msctls_statusbar32" => "StatusBar",
        "msctls_progress32" => "Progress",
        "msctls_trackbar32" => "Trackbar",
        "msctls_updown32" => "UpDown",
        "sysheader32" => "Header",
        "#32770" => "Dialog",
        "" => "Window",
        _ => class_name,
    }
}

impl Win32Props {
    /// The node these properties describe. An edit control's text is its value (the
    /// MSAA value when there is one), as pywinauto's `EditWrapper` reports it.
    pub fn into_node(self) -> A11yNode {
        let role = win32_role(&self.class_name).to_owned();
        let is_edit = role == "Edit";
        let text = self.text.unwrap_or_default();
        let (name, value) =
            if is_edit { (String::new(), Some(self.msaa_value.unwrap_or(text))) } else { (text, self.msaa_value) };
        let [l, t, r, b] = self.ltrb;
        let rect = Rect::from_ltrb(l, t, r, b);
        A11yNode {
            role,
            class_name: self.class_name,
            name,
            value,
            text: None,
            rect: Some(rect),
            enabled: self.enabled,
            visible: self.visible,
            focused: self.focused,
            states: A11yStates {
                minimized: self.minimized,
                maximized: self.maximized,
                checked: self.checked,
                editable: if is_edit { Some(!self.read_only.unwrap_or(false)) } else { None },
                ..A11yStates::default()
            },
            window_id: None,
            children: Vec::new(),
        }
    }
}

/// A fake tree for tests: nodes in a flat arena, children by index.
#[cfg(test)]
pub(crate) mod fake {
    use super::*;

    #[derive(Debug, Clone)]
    pub(crate) struct FakeNode {
        pub(crate) name: String,
        pub(crate) children: Vec<usize>,
        /// Milliseconds `record` takes, to exercise time budgets.
        pub(crate) cost_ms: u64,
        /// `prepare` fails for this root.
        pub(crate) broken: bool,
        /// `prepare` times out for this root but `prepare_partial` reads it.
        pub(crate) partial: bool,
    }

    #[derive(Debug, Default)]
    pub(crate) struct FakeTree {
        pub(crate) nodes: Vec<FakeNode>,
        pub(crate) roots: Vec<usize>,
        pub(crate) foreground: Option<usize>,
        pub(crate) prepared: Vec<(usize, Duration)>,
    }

    impl FakeTree {
        pub(crate) fn add(&mut self, name: &str, children: Vec<usize>) -> usize {
            self.nodes.push(FakeNode { name: name.to_owned(), children, cost_ms: 0, broken: false, partial: false });
            self.nodes.len() - 1
        }

        /// A root with `n` leaf children named `{name}.{i}`.
        pub(crate) fn window(&mut self, name: &str, n: usize) -> usize {
            let kids = (0..n).map(|i| self.add(&format!("{name}.{i}"), Vec::new())).collect();
            let id = self.add(name, kids);
            self.roots.push(id);
            id
        }
    }

    impl TreeSource for FakeTree {
        type Elem = usize;

        fn roots(&mut self, foreground_only: bool) -> DesktopResult<Vec<(u64, usize)>> {
            Ok(self
                .roots
                .iter()
                .filter(|&&r| !foreground_only || Some(r) == self.foreground)
                .map(|&r| (r as u64 + 100, r))
                .collect())
        }

        fn foreground_id(&mut self) -> Option<u64> {
            self.foreground.map(|r| r as u64 + 100)
        }

        fn prepare(&mut self, root: &usize, time: Duration) -> DesktopResult<usize> {
            self.prepared.push((*root, time));
            if self.nodes[*root].broken || self.nodes[*root].partial {
                return Err(crate::desktop::DesktopError::Timeout { op: "prepare", ms: 1 });
            }
            Ok(*root)
        }

        fn prepare_partial(&mut self, root: &usize, _time: Duration, failed: DesktopError) -> DesktopResult<usize> {
            if self.nodes[*root].partial {
                Ok(*root)
            } else {
                Err(failed)
            }
        }

        fn record(&mut self, elem: &usize) -> A11yNode {
            let node = &self.nodes[*elem];
            if node.cost_ms > 0 {
                std::thread::sleep(Duration::from_millis(node.cost_ms));
            }
            A11yNode {
                role: "Pane".into(),
                name: node.name.clone(),
                enabled: true,
                visible: true,
                ..A11yNode::default()
            }
        }

        fn children(&mut self, elem: &usize, limit: usize) -> Vec<usize> {
            self.nodes[*elem].children.iter().take(limit + 1).copied().collect()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::fake::FakeTree;
    use super::*;

    fn budget(max_depth: u32, max_children: u32, max_nodes: u32, max_ms: u64) -> TreeBudget {
        TreeBudget { max_depth, max_children, max_nodes, max_ms }
    }

    fn names(node: &A11yNode) -> Vec<String> {
        node.children.iter().map(|c| c.name.clone()).collect()
    }

    #[test]
    fn a_small_tree_is_walked_whole_in_order() {
        let mut tree = FakeTree::default();
        let leaf = tree.add("deep", Vec::new());
        let mid = tree.add("mid", vec![leaf]);
        let top = tree.add("top", vec![mid]);
        tree.roots.push(top);
        tree.window("second", 2);
        let out = walk(&mut tree, A11yBackend::Uia, &TreeBudget::WAA, false).unwrap();
        assert!(!out.truncated);
        assert_eq!(out.node_count, 6);
        assert_eq!(out.windows.len(), 2);
        assert_eq!(out.windows[0].children[0].children[0].name, "deep");
        assert_eq!(out.windows[0].children[0].children[0].window_id, Some(top as u64 + 100));
        assert_eq!(names(&out.windows[1]), ["second.0", "second.1"]);
    }

    #[test]
    fn depth_cap_keeps_the_node_and_flags_the_cut() {
        let mut tree = FakeTree::default();
        let leaf = tree.add("deep", Vec::new());
        let top = tree.add("top", vec![leaf]);
        tree.roots.push(top);
        let out = walk(&mut tree, A11yBackend::Uia, &budget(1, 10, 100, 10_000), false).unwrap();
        assert!(out.truncated);
        assert!(out.windows[0].children.is_empty());
        // Exactly at the cap, with nothing below, is not a cut.
        let mut tree = FakeTree::default();
        tree.window("w", 0);
        assert!(!walk(&mut tree, A11yBackend::Uia, &budget(1, 10, 100, 10_000), false).unwrap().truncated);
    }

    #[test]
    fn width_cap_keeps_the_first_children() {
        let mut tree = FakeTree::default();
        tree.window("w", 5);
        let out = walk(&mut tree, A11yBackend::Win32, &budget(50, 3, 100, 10_000), false).unwrap();
        assert!(out.truncated);
        assert_eq!(names(&out.windows[0]), ["w.0", "w.1", "w.2"]);
        // Exactly as many as allowed is whole.
        let mut tree = FakeTree::default();
        tree.window("w", 3);
        assert!(!walk(&mut tree, A11yBackend::Win32, &budget(50, 3, 100, 10_000), false).unwrap().truncated);
    }

    #[test]
    fn a_huge_window_cannot_starve_the_next_one() {
        let mut tree = FakeTree::default();
        tree.window("huge", 500);
        tree.window("small", 3);
        let out = walk(&mut tree, A11yBackend::Uia, &budget(50, 2048, 100, 10_000), false).unwrap();
        assert!(out.truncated);
        assert_eq!(out.windows.len(), 2);
        // The huge window got half the nodes; the small one is complete.
        assert_eq!(out.windows[0].children.len(), 49);
        assert_eq!(names(&out.windows[1]), ["small.0", "small.1", "small.2"]);
        assert!(out.node_count <= 100);
    }

    #[test]
    fn unused_share_flows_to_later_windows() {
        let mut tree = FakeTree::default();
        tree.window("small", 1);
        tree.window("big", 80);
        let out = walk(&mut tree, A11yBackend::Uia, &budget(50, 2048, 100, 10_000), false).unwrap();
        assert!(!out.truncated, "2 + 81 nodes fit in 100");
        assert_eq!(out.windows[1].children.len(), 80);
    }

    #[test]
    fn time_budget_cuts_a_slow_window_and_says_so() {
        let mut tree = FakeTree::default();
        let slow = tree.window("slow", 50);
        for i in 0..50 {
            let child = tree.nodes[slow].children[i];
            tree.nodes[child].cost_ms = 5;
        }
        let started = Instant::now();
        let out = walk(&mut tree, A11yBackend::Uia, &budget(50, 2048, 10_000, 60), false).unwrap();
        assert!(out.truncated);
        assert!(out.windows[0].children.len() < 50);
        assert!(started.elapsed() < Duration::from_millis(500), "{:?}", started.elapsed());
    }

    #[test]
    fn a_window_that_fails_to_prepare_is_skipped() {
        let mut tree = FakeTree::default();
        let broken = tree.window("broken", 1);
        tree.nodes[broken].broken = true;
        tree.window("fine", 1);
        let out = walk(&mut tree, A11yBackend::Uia, &TreeBudget::WAA, false).unwrap();
        assert!(out.truncated);
        assert_eq!(out.windows.len(), 1);
        assert_eq!(out.windows[0].name, "fine");
        // The first of two windows is offered half of the time.
        let offered = tree.prepared[0].1;
        assert!(offered <= Duration::from_millis(5_000) && offered >= Duration::from_millis(4_900), "{offered:?}");
    }

    #[test]
    fn a_window_whose_cached_fetch_times_out_still_yields_a_partial_tree() {
        let mut tree = FakeTree::default();
        let heavy = tree.window("heavy", 5);
        tree.nodes[heavy].partial = true;
        let broken = tree.window("broken", 1);
        tree.nodes[broken].broken = true;
        tree.window("fine", 2);
        let out = walk(&mut tree, A11yBackend::Uia, &TreeBudget::WAA, false).unwrap();
        let listed: Vec<&str> = out.windows.iter().map(|w| w.name.as_str()).collect();
        assert_eq!(listed, ["heavy", "fine"]);
        assert_eq!(out.windows[0].children.len(), 5, "the partial read keeps what it reads");
        assert!(out.truncated);
        let stats: Vec<(u64, u32, bool, bool, bool)> = out
            .windows_walked
            .iter()
            .map(|w| (w.window_id, w.nodes, w.partial, w.truncated, w.skipped.is_some()))
            .collect();
        assert_eq!(
            stats,
            [
                (heavy as u64 + 100, 6, true, true, false),
                (broken as u64 + 100, 0, false, false, true),
                (tree.roots[2] as u64 + 100, 3, false, false, false),
            ]
        );
    }

    #[test]
    fn the_foreground_window_is_walked_first_with_most_of_the_budget_and_listed_in_z_order() {
        let mut tree = FakeTree::default();
        tree.window("top", 200);
        let fg = tree.window("working", 200);
        tree.window("bottom", 200);
        tree.foreground = Some(fg);
        let out = walk(&mut tree, A11yBackend::Uia, &budget(50, 2048, 100, 10_000), false).unwrap();
        // Walked (prepared) first, offered three quarters of the time.
        assert_eq!(tree.prepared[0].0, fg);
        let offered = tree.prepared[0].1;
        assert!(offered >= Duration::from_millis(7_400) && offered <= Duration::from_millis(7_500), "{offered:?}");
        // Listed in z-order all the same, and it got 75 of the 100 nodes.
        let listed: Vec<&str> = out.windows.iter().map(|w| w.name.as_str()).collect();
        assert_eq!(listed, ["top", "working", "bottom"]);
        assert_eq!(out.windows[1].children.len(), 74);
        assert!(out.windows[0].children.len() < 20, "{}", out.windows[0].children.len());
        assert!(out.node_count <= 100);
        assert_eq!(foreground_share(100, Duration::from_millis(1000), 1), share(100, Duration::from_millis(1000), 1));
    }

    #[test]
    fn foreground_only_walks_one_window() {
        let mut tree = FakeTree::default();
        tree.window("a", 1);
        let b = tree.window("b", 1);
        tree.foreground = Some(b);
        let out = walk(&mut tree, A11yBackend::Uia, &TreeBudget::WAA, true).unwrap();
        assert_eq!(out.windows.len(), 1);
        assert_eq!(out.windows[0].name, "b");
    }

    #[test]
    fn window_count_is_capped_by_the_width() {
        let mut tree = FakeTree::default();
        for i in 0..4 {
            tree.window(&format!("w{i}"), 0);
        }
        let out = walk(&mut tree, A11yBackend::Uia, &budget(50, 2, 100, 10_000), false).unwrap();
        assert!(out.truncated);
        assert_eq!(out.windows.len(), 2);
    }

    #[test]
    fn shares_are_fair_and_never_zero() {
        assert_eq!(share(100, Duration::from_millis(1000), 4), Share { nodes: 25, time: Duration::from_millis(250) });
        assert_eq!(share(5, Duration::from_millis(10), 4), Share { nodes: 5, time: Duration::from_millis(10) });
        assert_eq!(share(1000, Duration::from_millis(1000), 100), Share { nodes: 16, time: Duration::from_millis(50) });
        assert_eq!(share(100, Duration::from_millis(1000), 0), Share { nodes: 100, time: Duration::from_millis(1000) });
    }

    #[test]
    fn uia_properties_map_onto_nodes() {
        let node = UiaProps {
            control_type: 50004,
            class_name: "OmniboxViewViews".into(),
            name: "Address and search bar".into(),
            bounds: [120.0, 48.0, 900.0, 28.0],
            enabled: true,
            offscreen: false,
            has_keyboard_focus: true,
            value: Some("www.example.com".into()),
            value_read_only: Some(false),
            ..UiaProps::default()
        }
        .into_node();
        assert_eq!(node.role, "Edit");
        assert_eq!(node.rect, Some(Rect::new(120, 48, 900, 28)));
        assert!(node.visible && node.focused);
        assert_eq!(node.value.as_deref(), Some("www.example.com"));
        assert_eq!(node.states.editable, Some(true));
        assert_eq!(node.states.minimized, None);

        let window =
            UiaProps { control_type: 50032, window_visual_state: Some(1), offscreen: true, ..UiaProps::default() }
                .into_node();
        assert_eq!(window.role, "Window");
        assert_eq!((window.states.minimized, window.states.maximized), (Some(false), Some(true)));
        assert!(!window.visible);
        assert_eq!(window.rect, None);

        let item = UiaProps {
            control_type: 50024,
            expand_collapse_state: Some(3),
            toggle_state: Some(1),
            ..UiaProps::default()
        }
        .into_node();
        assert_eq!((item.states.expanded, item.states.checked), (None, Some(true)));
        assert_eq!(control_type_name(49999), "Custom");
        assert_eq!(control_type_name(50040), "AppBar");
        assert_eq!(uia_rect([f64::INFINITY, 0.0, 1.0, 1.0]), None);
    }

    #[test]
    fn win32_edit_text_is_the_value() {
        let edit = Win32Props {
            class_name: "Edit".into(),
            text: Some("typed".into()),
            ltrb: [10, 20, 110, 70],
            visible: true,
            enabled: true,
            ..Win32Props::default()
        }
        .into_node();
        assert_eq!((edit.role.as_str(), edit.name.as_str(), edit.value.as_deref()), ("Edit", "", Some("typed")));
        assert_eq!(edit.rect, Some(Rect::new(10, 20, 100, 50)));
        assert_eq!(edit.states.editable, Some(true));

        let button = Win32Props {
            class_name: "Button".into(),
            text: Some("OK".into()),
            checked: Some(false),
            ..Win32Props::default()
        }
        .into_node();
        assert_eq!((button.role.as_str(), button.name.as_str(), button.value), ("Button", "OK", None));
        assert_eq!(button.states.checked, Some(false));
        assert_eq!(win32_role("#32770"), "Dialog");
        assert_eq!(win32_role("Notepad"), "Notepad");
    }
}
