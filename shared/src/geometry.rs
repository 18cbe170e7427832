//! Points and rectangles.
//!
//! All native-API coordinates are physical screen pixels of the virtual
//! screen unless a type says otherwise, and every observation names the space
//! it uses with [`CoordinateSpace`].

use serde::{Deserialize, Serialize};

/// A point in pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Point {
    pub x: i32,
    pub y: i32,
}

impl Point {
    pub const fn new(x: i32, y: i32) -> Point {
        Point { x, y }
    }
}

/// A rectangle given by its top-left corner and its size, in pixels.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Rect {
    pub x: i32,
    pub y: i32,
    pub width: i32,
    pub height: i32,
}

impl Rect {
    pub const fn new(x: i32, y: i32, width: i32, height: i32) -> Rect {
        Rect { x, y, width, height }
    }

    /// Builds a rectangle from its left, top, right and bottom edges, as Win32 `RECT` gives them.
    pub const fn from_ltrb(left: i32, top: i32, right: i32, bottom: i32) -> Rect {
        Rect { x: left, y: top, width: right - left, height: bottom - top }
    }

    pub const fn right(&self) -> i32 {
        self.x + self.width
    }

    pub const fn bottom(&self) -> i32 {
        self.y + self.height
    }

    /// Whether `p` lies inside, counting the left and top edges but not the right and bottom ones.
    pub const fn contains(&self, p: Point) -> bool {
        p.x >= self.x && p.y >= self.y && p.x < self.right() && p.y < self.bottom()
    }

    pub const fn center(&self) -> Point {
        Point { x: self.x + self.width / 2, y: self.y + self.height / 2 }
    }

    pub const fn is_empty(&self) -> bool {
        self.width <= 0 || self.height <= 0
    }

    /// Whether the two rectangles share at least one pixel.
    pub const fn intersects(&self, other: &Rect) -> bool {
        !self.is_empty()
            && !other.is_empty()
            && self.x < other.right()
            && other.x < self.right()
            && self.y < other.bottom()
            && other.y < self.bottom()
    }
}

/// Which pixels a coordinate counts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CoordinateSpace {
    /// Physical pixels of the virtual screen, as a per-monitor DPI-aware process sees them.
    Physical,
    /// Logical (DPI-scaled) pixels, as a DPI-unaware process sees them.
    Logical,
    /// Pixels of a downscaled screenshot; multiply by the screenshot's scale to get physical pixels.
    Image,
    #[serde(other)]
    Unknown,
}
