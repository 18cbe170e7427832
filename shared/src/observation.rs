//! What the guest reports about the screen: its size and scale, screenshots,
//! windows and the accessibility tree.

use serde::{Deserialize, Serialize};

use crate::geometry::{CoordinateSpace, Point, Rect};

/// One monitor, in physical pixels of the virtual screen.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MonitorInfo {
    pub name: String,
    pub rect: Rect,
    /// DPI scale factor (1.0 at 96 DPI, 1.5 at 144 DPI).
    pub scale_factor: f64,
    pub primary: bool,
}

/// The screen as the guest sees it.
///
/// Physical pixels are what input and screenshots use; logical pixels are
/// what a DPI-unaware program sees (`physical / scale_factor`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScreenInfo {
    pub physical_width: u32,
    pub physical_height: u32,
    pub logical_width: u32,
    pub logical_height: u32,
    /// Scale factor of the primary monitor.
    pub scale_factor: f64,
    #[serde(default)]
    pub monitors: Vec<MonitorInfo>,
    /// The space that input actions and window rectangles use.
    pub coordinate_space: CoordinateSpace,
}

/// Image formats a screenshot can be encoded in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ImageFormat {
    #[default]
    Png,
    Jpeg,
    #[serde(other)]
    Unknown,
}

impl ImageFormat {
    pub fn mime(&self) -> &'static str {
        match self {
            ImageFormat::Png | ImageFormat::Unknown => "image/png",
            ImageFormat::Jpeg => "image/jpeg",
        }
    }
}

/// Query of `GET /v1/screenshot`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct ScreenshotQuery {
    #[serde(default)]
    pub format: ImageFormat,
    /// JPEG quality, 1 to 100.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub quality: Option<u8>,
    /// Longest side of the returned image in pixels; the image is downscaled to fit.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_side: Option<u32>,
    /// Whether to draw the cursor (default true, as upstream's `/screenshot`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cursor: Option<bool>,
}

/// Metadata of a screenshot, sent in `X-Arena-Screenshot` next to the image bytes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScreenshotMeta {
    /// Size of the returned image.
    pub width: u32,
    pub height: u32,
    /// Size of the captured screen in physical pixels.
    pub physical_width: u32,
    pub physical_height: u32,
    /// Physical pixels per image pixel: multiply image coordinates by this to act on them.
    pub scale: f64,
    pub format: ImageFormat,
    /// Coordinate space of the image pixels.
    pub coordinate_space: CoordinateSpace,
    /// Cursor position in physical pixels, if known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cursor: Option<Point>,
    #[serde(default)]
    pub cursor_drawn: bool,
    /// The frame was entirely black, which usually means a locked or secure desktop.
    #[serde(default)]
    pub black_frame: bool,
    #[serde(default)]
    pub capture_ms: u64,
}

/// A top-level window.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct WindowInfo {
    /// Opaque window id (the HWND on Windows).
    pub id: u64,
    pub title: String,
    pub class_name: String,
    pub process_id: u32,
    pub process_name: String,
    /// Outer rectangle in physical pixels.
    pub rect: Rect,
    pub visible: bool,
    pub minimized: bool,
    #[serde(default)]
    pub maximized: bool,
    /// Whether this is the foreground window.
    pub focused: bool,
    /// 0 is the topmost window.
    pub z_order: u32,
}

/// Which accessibility API a tree came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum A11yBackend {
    /// UI Automation.
    #[default]
    Uia,
    /// Window and child-window enumeration (plus MSAA values).
    Win32,
    #[serde(other)]
    Unknown,
}

/// One node of the accessibility tree.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct A11yNode {
    /// UIA control type (`Button`, `Edit`, `Window`) or the win32 role.
    pub role: String,
    /// UIA ClassName or Win32 window class.
    pub class_name: String,
    pub name: String,
    /// ValuePattern value or an edit control's text.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub value: Option<String>,
    /// Text content when it differs from the name.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub text: Option<String>,
    /// Bounding rectangle in physical pixels, if the element has one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rect: Option<Rect>,
    pub enabled: bool,
    /// Not off-screen (UIA) or visible (win32).
    pub visible: bool,
    #[serde(default)]
    pub focused: bool,
    /// Optional states, present only when the element supports them.
    #[serde(default, skip_serializing_if = "A11yStates::is_empty")]
    pub states: A11yStates,
    /// Top-level window this node belongs to.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub window_id: Option<u64>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub children: Vec<A11yNode>,
}

/// States that only some elements support; `None` means "not supported".
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct A11yStates {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub minimized: Option<bool>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub maximized: Option<bool>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub expanded: Option<bool>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub selected: Option<bool>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub checked: Option<bool>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub editable: Option<bool>,
}

impl A11yStates {
    pub fn is_empty(&self) -> bool {
        *self == A11yStates::default()
    }
}

/// Limits on a tree walk. A walk that hits one returns what it has, flagged `truncated`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct TreeBudget {
    /// Deepest level kept; top-level windows are depth 1 (upstream: 50).
    pub max_depth: u32,
    /// Most children kept per node (upstream: 2048).
    pub max_children: u32,
    /// Most nodes in the whole tree.
    pub max_nodes: u32,
    /// Wall-clock budget for the whole walk.
    pub max_ms: u64,
}

impl TreeBudget {
    /// Upstream WAA's caps (depth 50, 2048 children), with node and time budgets added.
    pub const WAA: TreeBudget = TreeBudget { max_depth: 50, max_children: 2048, max_nodes: 20_000, max_ms: 10_000 };
}

/// Query of `GET /v1/a11y`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct A11yQuery {
    #[serde(default)]
    pub backend: A11yBackend,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_depth: Option<u32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_children: Option<u32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_nodes: Option<u32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_ms: Option<u64>,
    /// Only the foreground window.
    #[serde(default)]
    pub foreground_only: bool,
}

/// An accessibility tree: one root node per visible top-level window, topmost first.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct A11yTree {
    pub backend: A11yBackend,
    pub windows: Vec<A11yNode>,
    /// A budget was hit and the tree is partial.
    pub truncated: bool,
    pub node_count: u32,
    pub elapsed_ms: u64,
    /// Rectangles are in this space.
    pub coordinate_space: CoordinateSpace,
    /// How each top-level window's walk went, in the tree's window order (skipped
    /// windows included): where the budget went and which windows came back partial.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub windows_walked: Vec<WindowWalk>,
}

/// One top-level window's walk.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct WindowWalk {
    /// The window's id (the HWND on Windows).
    pub window_id: u64,
    /// Nodes kept from it.
    pub nodes: u32,
    /// Time spent on it.
    pub ms: u64,
    /// A budget, depth or width cap cut it.
    #[serde(default)]
    pub truncated: bool,
    /// Its whole-subtree fetch failed and it was read element by element instead.
    #[serde(default)]
    pub partial: bool,
    /// Why it was left out, when it was.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub skipped: Option<String>,
    /// Why it is `truncated` or `partial` (which cap or budget cut it, why its
    /// subtree fetch failed, how many node texts were cut), when it is.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
}

impl WindowWalk {
    /// A window that was not walked, and why.
    pub fn skipped(window_id: u64, why: &str) -> WindowWalk {
        WindowWalk { window_id, skipped: Some(why.to_owned()), ..WindowWalk::default() }
    }
}

/// Body of `POST /v1/windows/activate` and `/v1/windows/close`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WindowTarget {
    /// Exact window id, or
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub id: Option<u64>,
    /// a case-insensitive substring of the title (the first match in z-order wins).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub title: Option<String>,
}
