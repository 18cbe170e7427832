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
//! The Windows sources live in the guest's `desktop/windows/`, the stub's in its `desktop/stub/a11y.rs`; this module holds the walk, the budget
//! arithmetic and the mapping from raw properties ([`UiaProps`], [`Win32Props`]) to
//! [`A11yNode`]s, and is tested natively with a fake tree. Nothing here calls the OS,
//! and nothing here knows the guest server: a source's failures are its own
//! [`TreeSource::Error`], which the walk only shows.

#![forbid(unsafe_code)]

use std::time::{Duration, Instant};

use arena_shared::geometry::{CoordinateSpace, Rect};
use arena_shared::observation::{A11yBackend, A11yNode, A11yStates, A11yTree, TreeBudget, WindowWalk};

/// A window that gets less than this many milliseconds is still given this much, so
/// a share never rounds down to nothing.
const MIN_WINDOW_MS: u64 = 50;
/// Likewise for nodes.
const MIN_WINDOW_NODES: u32 = 16;

/// Of a window's time share, the part its all-or-nothing bulk fetch
/// ([`TreeSource::prepare`]) may use: one half. The other half is kept for the
/// element-by-element read ([`TreeSource::prepare_partial`]) when the bulk fetch fails.
///
/// Why a half: a bulk fetch that has not finished in half the share is a heavy
/// window (a browser page, LibreOffice, VS Code) that would rarely finish in the
/// whole share either, while the element-by-element read keeps what it reads, top
/// levels first, so the time left to it turns straight into nodes. A window that
/// fetches in time loses nothing: the read after a bulk fetch comes from the cache
/// and costs no cross-process calls.
const BULK_PART: (u32, u32) = (1, 2);

/// The longest text kept in one node's `name`, `value` or `text`, in characters.
///
/// An edit control or a document can hold megabytes (one 100-node tree came back
/// at 100 MB); a longer text is cut here and ends with [`text_cut_marker`], and the
/// window's [`WindowWalk::reason`] counts the cuts. Upstream's trees have no cap
/// (a deliberate deviation: `docs/compatibility.md`).
pub const MAX_NODE_TEXT_CHARS: usize = 4096;

/// What ends a text cut at [`MAX_NODE_TEXT_CHARS`]: says how much was left out, so
/// neither an agent nor a reader takes the cut text for the whole.
pub fn text_cut_marker(left_out: usize) -> String {
    format!("\u{2026} [cut: {left_out} more characters]")
}

/// Cuts `text` to [`MAX_NODE_TEXT_CHARS`] characters plus the marker; whether it cut.
fn cap_text(text: &mut String) -> bool {
    // Fast path: a text of at most the cap in bytes is at most the cap in characters.
    if text.len() <= MAX_NODE_TEXT_CHARS {
        return false;
    }
    let Some((at, _)) = text.char_indices().nth(MAX_NODE_TEXT_CHARS) else {
        return false;
    };
    let left_out = text[at..].chars().count();
    text.truncate(at);
    text.push_str(&text_cut_marker(left_out));
    true
}

/// Caps a node's `name`, `value` and `text`; whether any was cut.
fn cap_node_text(node: &mut A11yNode) -> bool {
    let mut cut = cap_text(&mut node.name);
    for text in [&mut node.value, &mut node.text].into_iter().flatten() {
        cut |= cap_text(text);
    }
    cut
}

/// Where elements come from. `Elem` is whatever handle the source uses (an HWND, a
/// cached UIA element); it never leaves the thread the walk runs on.
pub trait TreeSource {
    type Elem: Clone;
    /// What a failed enumeration or read says (the backend's own error); the walk
    /// only shows it, in a skipped window's reason.
    type Error: std::fmt::Display;

    /// The visible top-level windows, topmost first, with their window ids (HWNDs);
    /// only the foreground one when `foreground_only`.
    ///
    /// # Errors
    ///
    /// The enumeration failing as a whole.
    fn roots(&mut self, foreground_only: bool) -> Result<Vec<(u64, Self::Elem)>, Self::Error>;

    /// Windows [`TreeSource::roots`] saw but could not open (UIA: `ElementFromHandle`
    /// failing on a busy window), with the reason: the walk lists them as skipped, so
    /// no window a person sees is dropped without a word.
    fn root_failures(&mut self) -> Vec<(u64, String)> {
        Vec::new()
    }

    /// The foreground window's id, when the source knows it: that window is walked
    /// first and with the larger share, since it is the one the agent works in.
    fn foreground_id(&mut self) -> Option<u64> {
        None
    }

    /// Readies one window for reading, given the time it may take (UIA: one cached
    /// subtree fetch, all or nothing). The walk offers it [`BULK_PART`] of the
    /// window's share. The default does nothing.
    ///
    /// # Errors
    ///
    /// The window being gone, hung or refusing; the walk then tries [`TreeSource::prepare_partial`].
    fn prepare(&mut self, root: &Self::Elem, _time: Duration) -> Result<Self::Elem, Self::Error> {
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
        failed: Self::Error,
    ) -> Result<Self::Elem, Self::Error> {
        Err(failed)
    }

    /// The element's properties.
    fn record(&mut self, elem: &Self::Elem) -> A11yNode;

    /// Up to `limit + 1` children of the element, in order (one more than kept, so the
    /// walk can tell the list was cut).
    fn children(&mut self, elem: &Self::Elem, limit: usize) -> Vec<Self::Elem>;
}

/// Which caps cut one window, for its [`WindowWalk::reason`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct Cuts {
    depth: bool,
    width: bool,
    nodes: bool,
    time: bool,
    /// Node texts cut at [`MAX_NODE_TEXT_CHARS`].
    texts: u32,
}

impl Cuts {
    fn any(&self) -> bool {
        self.depth || self.width || self.nodes || self.time || self.texts > 0
    }

    fn describe(&self, share: Share) -> Vec<String> {
        let mut out = Vec::new();
        if self.nodes {
            out.push(format!("its share of {} nodes was used up", share.nodes));
        }
        if self.time {
            out.push(format!("its share of {} ms ran out", share.time.as_millis()));
        }
        if self.depth {
            out.push("the depth cap cut it".to_owned());
        }
        if self.width {
            out.push("the children cap cut it".to_owned());
        }
        if self.texts > 0 {
            out.push(format!("{} node texts were cut at {MAX_NODE_TEXT_CHARS} characters", self.texts));
        }
        out
    }
}

/// The running counts and limits of one walk.
struct Walk {
    budget: TreeBudget,
    count: u32,
    /// The cuts of the window being walked.
    cuts: Cuts,
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

/// The part of a window's time share its bulk fetch may use ([`BULK_PART`]).
fn bulk_time(share_time: Duration) -> Duration {
    let (num, den) = BULK_PART;
    share_time * num / den
}

impl Walk {
    /// Emits `elem` at `depth` (top-level windows are 1) with as much of its subtree as
    /// fits in `limit` nodes before `deadline`; `None` when nothing fits. A window's
    /// own node (depth 1) is kept even past the deadline, so a window the source could
    /// open is never listed with nothing.
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
        if depth > self.budget.max_depth {
            self.cuts.depth = true;
            return None;
        }
        if self.count >= limit {
            self.cuts.nodes = true;
            return None;
        }
        if depth > 1 && Instant::now() >= deadline {
            self.cuts.time = true;
            return None;
        }
        self.count += 1;
        let mut node = source.record(elem);
        node.window_id = Some(window_id);
        node.children.clear();
        if cap_node_text(&mut node) {
            self.cuts.texts += 1;
        }
        let keep = self.budget.max_children as usize;
        if depth >= self.budget.max_depth {
            // Upstream silently drops what is below the depth cap; say the tree is partial.
            self.cuts.depth |= !source.children(elem, 0).is_empty();
            return Some(node);
        }
        let children = source.children(elem, keep);
        if children.len() > keep {
            self.cuts.width = true;
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

fn millis(d: Duration) -> u64 {
    u64::try_from(d.as_millis()).unwrap_or(u64::MAX)
}

/// Walks `source` within `budget`: the shown top-level windows, listed topmost first.
///
/// The foreground window is walked first with three quarters of the budget (see
/// [`foreground_share`]); the others then get fair shares of the nodes and time
/// still left (see the module documentation), so one huge window cannot starve the
/// others. Each window's bulk fetch ([`TreeSource::prepare`]) may use half of its
/// time share ([`BULK_PART`]); when it fails, the window is read element by element
/// through [`TreeSource::prepare_partial`] in the time left and keeps what fits, so a
/// heavy window comes back partial with nodes instead of empty. One that cannot be
/// read at all is skipped. Any cut flags the tree `truncated`, and
/// [`A11yTree::windows_walked`] says per window how many nodes, how long, whether it
/// was cut, partial or skipped, and why.
///
/// # Errors
///
/// Only the source failing to list the windows; per-window failures are skipped.
pub fn walk<S: TreeSource>(
    source: &mut S,
    backend: A11yBackend,
    budget: &TreeBudget,
    foreground_only: bool,
) -> Result<A11yTree, S::Error> {
    let started = Instant::now();
    let total_time = Duration::from_millis(budget.max_ms);
    let walk_end = started + total_time;
    let mut walk = Walk { budget: *budget, count: 0, cuts: Cuts::default() };
    let mut truncated = false;
    let mut roots = source.roots(foreground_only)?;
    let failures = source.root_failures();
    let keep = budget.max_children as usize;
    let mut over_width = Vec::new();
    if roots.len() > keep {
        truncated = true;
        over_width = roots.split_off(keep).into_iter().map(|(id, _)| id).collect();
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
            truncated = true;
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
        let mut deadline = window_started + share.time;
        let bulk = bulk_time(share.time);
        let mut partial_reason = None;
        let prepared = match source.prepare(root, bulk) {
            Ok(prepared) => Ok(prepared),
            Err(err) => {
                tracing::debug!(window_id, %err, "the window's bulk fetch failed; reading it element by element");
                partial_reason = Some(format!(
                    "its subtree fetch failed after {} ms of the {} ms it was offered ({err}), so it was read element by element",
                    millis(window_started.elapsed()),
                    bulk.as_millis()
                ));
                // A bulk fetch that overran its part still leaves the element-by-element
                // read a minimum, within the walk's own end.
                deadline = deadline.max((Instant::now() + Duration::from_millis(MIN_WINDOW_MS)).min(walk_end));
                let left = deadline.saturating_duration_since(Instant::now());
                source.prepare_partial(root, left, err)
            }
        };
        let root = match prepared {
            Ok(root) => root,
            Err(err) => {
                tracing::debug!(window_id, %err, "skipping a window the accessibility source could not read");
                truncated = true;
                walked[i] = Some(WindowWalk::skipped(window_id, &err.to_string()));
                continue;
            }
        };
        let count_before = walk.count;
        walk.cuts = Cuts::default();
        let limit = walk.count.saturating_add(share.nodes);
        slots[i] = walk.emit(source, &root, 1, window_id, limit, deadline);
        let cut = walk.cuts.any();
        let partial = partial_reason.is_some();
        truncated |= cut || partial;
        let mut reasons: Vec<String> = partial_reason.into_iter().collect();
        reasons.extend(walk.cuts.describe(share));
        walked[i] = Some(WindowWalk {
            window_id,
            nodes: walk.count - count_before,
            ms: millis(window_started.elapsed()),
            truncated: cut,
            partial,
            skipped: None,
            reason: (!reasons.is_empty()).then(|| reasons.join("; ")),
        });
    }
    let mut windows_walked: Vec<WindowWalk> = walked.into_iter().flatten().collect();
    for id in over_width {
        windows_walked.push(WindowWalk::skipped(id, "more top-level windows than the children cap"));
    }
    for (id, why) in failures {
        truncated = true;
        windows_walked.push(WindowWalk::skipped(id, &why));
    }
    Ok(A11yTree {
        backend,
        windows: slots.into_iter().flatten().collect(),
        truncated,
        node_count: walk.count,
        elapsed_ms: millis(started.elapsed()),
        coordinate_space: CoordinateSpace::Physical,
        windows_walked,
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
        "listbox" | "combolbox" => "ListBox",
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
        "#32768" => "PopupMenu",
        "tooltips_class32" => "ToolTips",
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
        /// `prepare` sleeps the whole time it is offered, then times out (as a UIA
        /// transaction timeout would); `prepare_partial` reads it.
        pub(crate) slow_bulk: bool,
        /// Text `record` gives as the node's value.
        pub(crate) value: Option<String>,
    }

    #[derive(Debug, Default)]
    pub(crate) struct FakeTree {
        pub(crate) nodes: Vec<FakeNode>,
        pub(crate) roots: Vec<usize>,
        pub(crate) foreground: Option<usize>,
        pub(crate) prepared: Vec<(usize, Duration)>,
        /// Windows `roots` saw but could not open, with the reason.
        pub(crate) failures: Vec<(u64, String)>,
    }

    impl FakeTree {
        pub(crate) fn add(&mut self, name: &str, children: Vec<usize>) -> usize {
            self.nodes.push(FakeNode {
                name: name.to_owned(),
                children,
                cost_ms: 0,
                broken: false,
                partial: false,
                slow_bulk: false,
                value: None,
            });
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

    /// A fake source's failure, worded as the guest's timeout is.
    #[derive(Debug)]
    pub(crate) struct FakeTimeout {
        pub(crate) op: &'static str,
        pub(crate) ms: u64,
    }

    impl std::fmt::Display for FakeTimeout {
        fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            write!(f, "{} timed out after {} ms", self.op, self.ms)
        }
    }

    impl TreeSource for FakeTree {
        type Elem = usize;
        type Error = FakeTimeout;

        fn roots(&mut self, foreground_only: bool) -> Result<Vec<(u64, usize)>, FakeTimeout> {
            Ok(self
                .roots
                .iter()
                .filter(|&&r| !foreground_only || Some(r) == self.foreground)
                .map(|&r| (r as u64 + 100, r))
                .collect())
        }

        fn root_failures(&mut self) -> Vec<(u64, String)> {
            std::mem::take(&mut self.failures)
        }

        fn foreground_id(&mut self) -> Option<u64> {
            self.foreground.map(|r| r as u64 + 100)
        }

        fn prepare(&mut self, root: &usize, time: Duration) -> Result<usize, FakeTimeout> {
            self.prepared.push((*root, time));
            if self.nodes[*root].slow_bulk {
                std::thread::sleep(time);
                return Err(FakeTimeout { op: "BuildUpdatedCache", ms: millis(time) });
            }
            if self.nodes[*root].broken || self.nodes[*root].partial {
                return Err(FakeTimeout { op: "prepare", ms: 1 });
            }
            Ok(*root)
        }

        fn prepare_partial(
            &mut self,
            root: &usize,
            _time: Duration,
            failed: FakeTimeout,
        ) -> Result<usize, FakeTimeout> {
            if self.nodes[*root].partial || self.nodes[*root].slow_bulk {
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
                value: node.value.clone(),
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
        // The first of two windows gets half of the time, and its bulk fetch half of that.
        let offered = tree.prepared[0].1;
        assert!(offered <= Duration::from_millis(2_500) && offered >= Duration::from_millis(2_450), "{offered:?}");
        assert_eq!(out.windows_walked[0].skipped.as_deref(), Some("prepare timed out after 1 ms"));
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
                // Read whole element by element: partial, but no cap cut it.
                (heavy as u64 + 100, 6, true, false, false),
                (broken as u64 + 100, 0, false, false, true),
                (tree.roots[2] as u64 + 100, 3, false, false, false),
            ]
        );
    }

    #[test]
    fn a_heavy_window_whose_bulk_fetch_sleeps_its_whole_part_keeps_nodes_within_the_deadline() {
        let mut tree = FakeTree::default();
        let heavy = tree.window("heavy", 400);
        tree.nodes[heavy].slow_bulk = true;
        for i in 0..400 {
            let child = tree.nodes[heavy].children[i];
            tree.nodes[child].cost_ms = 2;
        }
        tree.foreground = Some(heavy);
        let small = tree.window("small", 2);
        let max_ms = 400;
        let started = Instant::now();
        let out = walk(&mut tree, A11yBackend::Uia, &budget(50, 2048, 10_000, max_ms), false).unwrap();
        let elapsed = started.elapsed();
        // The bulk fetch slept all it was offered: half of the window's 300 ms share.
        assert_eq!(tree.prepared[0].0, heavy);
        let offered = tree.prepared[0].1;
        assert!(offered >= Duration::from_millis(140) && offered <= Duration::from_millis(150), "{offered:?}");
        // The window is listed with nodes read in the other half, marked partial, with the reason.
        assert_eq!(out.windows[0].name, "heavy");
        let kept = out.windows[0].children.len();
        assert!(kept > 10 && kept < 400, "{kept} children kept");
        let stats = &out.windows_walked[0];
        assert!(stats.partial && stats.truncated, "{stats:?}");
        assert_eq!(stats.nodes as usize, kept + 1);
        let reason = stats.reason.as_deref().unwrap();
        assert!(reason.contains("subtree fetch failed") && reason.contains("BuildUpdatedCache timed out"), "{reason}");
        assert!(reason.contains("ms ran out"), "{reason}");
        assert!(out.truncated);
        // The next window still gets its turn, and the walk keeps to the request's deadline.
        assert_eq!(out.windows[1].name, "small");
        assert_eq!(out.windows_walked[1].window_id, small as u64 + 100);
        assert!(elapsed < Duration::from_millis(max_ms + 200), "{elapsed:?}");
    }

    #[test]
    fn a_window_that_the_bulk_part_leaves_no_time_still_lists_its_own_node() {
        let mut tree = FakeTree::default();
        let heavy = tree.window("heavy", 3);
        tree.nodes[heavy].slow_bulk = true;
        tree.nodes[heavy].cost_ms = 60;
        let out = walk(&mut tree, A11yBackend::Uia, &budget(50, 2048, 100, 60), false).unwrap();
        assert_eq!(out.windows.len(), 1);
        assert_eq!(out.windows[0].name, "heavy");
        assert!(out.windows_walked[0].partial);
    }

    #[test]
    fn windows_the_source_could_not_open_are_listed_as_skipped() {
        let mut tree = FakeTree::default();
        tree.window("fine", 1);
        tree.failures.push((0xBEEF, "ElementFromHandle timed out after 500 ms".into()));
        let out = walk(&mut tree, A11yBackend::Uia, &TreeBudget::WAA, false).unwrap();
        assert!(out.truncated);
        assert_eq!(out.windows.len(), 1);
        let last = out.windows_walked.last().unwrap();
        assert_eq!(
            (last.window_id, last.skipped.as_deref()),
            (0xBEEF, Some("ElementFromHandle timed out after 500 ms"))
        );
    }

    #[test]
    fn long_node_texts_are_cut_and_the_cut_is_marked() {
        let mut tree = FakeTree::default();
        let w = tree.window("w", 2);
        let big = tree.nodes[w].children[0];
        tree.nodes[big].value = Some("é".repeat(MAX_NODE_TEXT_CHARS + 10));
        tree.nodes[big].name = "n".repeat(100_000);
        let exact = tree.nodes[w].children[1];
        tree.nodes[exact].value = Some("x".repeat(MAX_NODE_TEXT_CHARS));
        let out = walk(&mut tree, A11yBackend::Uia, &budget(50, 2048, 100, 10_000), false).unwrap();
        let node = &out.windows[0].children[0];
        let value = node.value.as_deref().unwrap();
        assert_eq!(value, format!("{}{}", "é".repeat(MAX_NODE_TEXT_CHARS), text_cut_marker(10)));
        assert!(node.name.starts_with(&"n".repeat(MAX_NODE_TEXT_CHARS)));
        assert!(node.name.ends_with(&text_cut_marker(100_000 - MAX_NODE_TEXT_CHARS)));
        // Exactly at the cap is whole.
        assert_eq!(out.windows[0].children[1].value.as_deref().map(str::len), Some(MAX_NODE_TEXT_CHARS));
        assert!(out.truncated);
        let reason = out.windows_walked[0].reason.as_deref().unwrap();
        assert!(reason.contains("1 node texts were cut at 4096 characters"), "{reason}");
    }

    #[test]
    fn the_foreground_window_is_walked_first_with_most_of_the_budget_and_listed_in_z_order() {
        let mut tree = FakeTree::default();
        tree.window("top", 200);
        let fg = tree.window("working", 200);
        tree.window("bottom", 200);
        tree.foreground = Some(fg);
        let out = walk(&mut tree, A11yBackend::Uia, &budget(50, 2048, 100, 10_000), false).unwrap();
        // Walked (prepared) first with three quarters of the time, half of it for the bulk fetch.
        assert_eq!(tree.prepared[0].0, fg);
        let offered = tree.prepared[0].1;
        assert!(offered >= Duration::from_millis(3_700) && offered <= Duration::from_millis(3_750), "{offered:?}");
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
        assert_eq!(win32_role("#32768"), "PopupMenu");
        assert_eq!(win32_role("ComboLBox"), "ListBox");
        assert_eq!(win32_role("Notepad"), "Notepad");
    }
}
