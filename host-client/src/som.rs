//! Set-of-Marks: numbered element boxes proposed from the accessibility tree,
//! the candidate list the model reads, and the annotated screenshot it sees.
//!
//! This reproduces upstream Navi's `a11y` proposal (`--som_origin a11y`,
//! waa-api.md §c.3) over our JSON tree instead of pywinauto's XML:
//!
//! 1. Top-level windows are processed bottom-up (the tree lists them topmost
//!    first, so in reverse). Before a visible window's elements are collected,
//!    every element already collected whose centre lies inside that window is
//!    dropped: the window covers it.
//! 2. A depth-first walk descends only through visible nodes and collects the
//!    leaves that are visible, enabled and have a rectangle. The entity's text
//!    is the node's `name` (not its value or text), as upstream's.
//! 3. Near-duplicates are removed: for each `i`, the first later `j` whose Dice
//!    overlap `2|A∩B|/(|A|+|B|)` exceeds 0.8 is dropped.
//! 4. Ids are indices into that list. Only the entities with `x >= 0`, `y >= 0`,
//!    `w > 0`, `h > 0` and `w·h > 1` are drawn and listed, but `rects` keeps one
//!    box per id, so `computer.mouse.move_id(id)` indexes it exactly as upstream's
//!    `/update_computer` `rects` list.
//!
//! It is not the OCR, DOM or icon-detector proposals of upstream's other
//! `som_origin` modes, and it does not talk to the guest: callers pass the tree.

use std::io::Cursor;

use font8x8::UnicodeFonts;
use image::{ImageFormat, Rgba, RgbaImage};
use serde::{Deserialize, Serialize};

use arena_shared::geometry::Rect;
use arena_shared::observation::{A11yNode, A11yTree};
use arena_shared::script::float_repr;

/// Upstream's `filter_reduntant_entities` threshold.
pub const REDUNDANCY_THRESHOLD: f64 = 0.8;

/// The header row of the candidate list, exactly as upstream's prompt has it.
pub const CANDIDATE_HEADER: &str = "ID | Type | Text content or description | Normalized location [x1, y1, x2, y2]";

/// One proposed element, listed and drawn with its id.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Mark {
    /// Index into [`Marks::rects`]; what `move_id` takes.
    pub id: usize,
    /// The proposal's type (`a11y` for every element of this proposal).
    pub kind: String,
    /// The element's accessible name; may be empty.
    pub text: String,
    /// Box in screen pixels (the same space as the tree).
    pub rect: Rect,
}

/// The element boxes of one observation.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Marks {
    /// The entities that are drawn and listed (a subset of the ids, in id order).
    pub entities: Vec<Mark>,
    /// `[x1, y1, x2, y2]` for every id, listed or not: `computer.mouse.move_id` targets the centre of `rects[id]`.
    pub rects: Vec<[i32; 4]>,
    /// Width and height the boxes are measured against (the screen, in the tree's pixels);
    /// the denominators of the normalized locations.
    pub size: (u32, u32),
}

/// An entity before ids are given: upstream's `{"type", "shape", "text"}` dict.
#[derive(Debug, Clone, PartialEq)]
struct Entity {
    rect: Rect,
    text: String,
}

impl Entity {
    fn centre(&self) -> (f64, f64) {
        (
            f64::from(self.rect.x) + f64::from(self.rect.width) / 2.0,
            f64::from(self.rect.y) + f64::from(self.rect.height) / 2.0,
        )
    }
}

/// Whether a point lies in `r`, edges included (a centre on the border of a covering window counts as covered).
fn inside(r: &Rect, (x, y): (f64, f64)) -> bool {
    let (x0, y0) = (f64::from(r.x), f64::from(r.y));
    x >= x0 && y >= y0 && x <= x0 + f64::from(r.width) && y <= y0 + f64::from(r.height)
}

/// Upstream's `iter_tree`: collects visible, enabled leaves with a rectangle,
/// descending only through visible nodes.
fn collect_leaves(node: &A11yNode, out: &mut Vec<Entity>) {
    if !node.visible {
        return;
    }
    if node.children.is_empty() {
        if let (true, Some(rect)) = (node.enabled, node.rect) {
            out.push(Entity { rect, text: node.name.clone() });
        }
        return;
    }
    for child in &node.children {
        collect_leaves(child, out);
    }
}

/// Steps 1 and 2 of the module doc: occlusion by higher windows, then the leaf walk.
fn propose(tree: &A11yTree) -> Vec<Entity> {
    let mut entities: Vec<Entity> = Vec::new();
    for window in tree.windows.iter().rev() {
        if !window.visible {
            continue;
        }
        if let Some(rect) = window.rect {
            entities.retain(|e| !inside(&rect, e.centre()));
        }
        collect_leaves(window, &mut entities);
    }
    entities
}

/// Area of a rectangle as upstream computes it (`w * h`, negative sizes count as empty).
fn area(r: &Rect) -> f64 {
    f64::from(r.width.max(0)) * f64::from(r.height.max(0))
}

/// The Dice coefficient `2|A∩B| / (|A|+|B|)` of two boxes; 0 when both are empty.
fn dice(a: &Rect, b: &Rect) -> f64 {
    let w = (i64::from(a.right()).min(i64::from(b.right())) - i64::from(a.x).max(i64::from(b.x))).max(0);
    let h = (i64::from(a.bottom()).min(i64::from(b.bottom())) - i64::from(a.y).max(i64::from(b.y))).max(0);
    let total = area(a) + area(b);
    if total <= 0.0 {
        return 0.0;
    }
    2.0 * (w as f64) * (h as f64) / total
}

/// Upstream's `filter_reduntant_entities`: for each `i`, the first later `j`
/// overlapping it by more than `threshold` is dropped, then the search for that
/// `i` stops. An `i` that was itself dropped still drops its own duplicate, as upstream's.
fn drop_redundant(entities: Vec<Entity>, threshold: f64) -> Vec<Entity> {
    let mut dropped = vec![false; entities.len()];
    for i in 0..entities.len() {
        for j in i + 1..entities.len() {
            if dice(&entities[i].rect, &entities[j].rect) > threshold {
                dropped[j] = true;
                break;
            }
        }
    }
    entities.into_iter().zip(dropped).filter(|(_, d)| !*d).map(|(e, _)| e).collect()
}

/// Upstream's `filter_entities`: what is drawn and listed.
fn drawable(r: &Rect) -> bool {
    r.x >= 0 && r.y >= 0 && r.width > 0 && r.height > 0 && area(r) > 1.0
}

/// Proposes the Set-of-Marks elements of `tree` for a screen of `size` pixels
/// (width, height: the screenshot's size in the tree's pixels).
pub fn marks_from_tree(tree: &A11yTree, size: (u32, u32)) -> Marks {
    let regions = drop_redundant(propose(tree), REDUNDANCY_THRESHOLD);
    let rects = regions.iter().map(|e| [e.rect.x, e.rect.y, e.rect.right(), e.rect.bottom()]).collect();
    let entities = regions
        .into_iter()
        .enumerate()
        .filter(|(_, e)| drawable(&e.rect))
        .map(|(id, e)| Mark { id, kind: "a11y".to_owned(), text: e.text, rect: e.rect })
        .collect();
    Marks { entities, rects, size }
}

/// Python's `round(v, 2)` printed as Python prints a float (`0.5`, `0.12`, `1.0`).
fn round2(v: f64) -> String {
    // Formatting rounds the exact binary value to two decimals, as CPython's
    // round() does; parsing it back gives the float Python would hold.
    let rounded: f64 = format!("{v:.2}").parse().unwrap_or(v);
    float_repr(rounded)
}

impl Marks {
    /// The element with this id, if it is listed.
    pub fn get(&self, id: usize) -> Option<&Mark> {
        self.entities.iter().find(|m| m.id == id)
    }

    /// The candidate list of upstream's prompt: the header, then one row per
    /// listed element, `id | type | text or '-' | [x1, y1, x2, y2]` with
    /// coordinates as fractions of the screen rounded to two decimals.
    pub fn candidate_list(&self) -> String {
        let w = f64::from(self.size.0.max(1));
        let h = f64::from(self.size.1.max(1));
        let mut out = String::from(CANDIDATE_HEADER);
        for m in &self.entities {
            let r = &m.rect;
            let text = if m.text.is_empty() { "-" } else { m.text.as_str() };
            out.push_str(&format!(
                "\n{} | {} | {} | [{}, {}, {}, {}]",
                m.id,
                m.kind,
                text,
                round2(f64::from(r.x) / w),
                round2(f64::from(r.y) / h),
                round2(f64::from(r.right()) / w),
                round2(f64::from(r.bottom()) / h),
            ));
        }
        out
    }
}

/// Why a screenshot could not be annotated.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SomError {
    #[error("cannot decode the screenshot: {0}")]
    Decode(String),
    #[error("cannot encode the annotated screenshot: {0}")]
    Encode(String),
}

/// Distinct, saturated box colours, picked by id.
const PALETTE: [[u8; 3]; 10] = [
    [230, 25, 75],
    [60, 180, 75],
    [0, 130, 200],
    [245, 130, 48],
    [145, 30, 180],
    [240, 50, 230],
    [0, 128, 128],
    [170, 110, 40],
    [128, 0, 0],
    [0, 0, 128],
];

/// Outline thickness of a box, in image pixels.
const BORDER: i64 = 2;
/// Glyphs are the 8x8 font drawn at this scale.
const GLYPH_SCALE: i64 = 2;
const GLYPH: i64 = 8 * GLYPH_SCALE;

fn fill(img: &mut RgbaImage, x0: i64, y0: i64, x1: i64, y1: i64, colour: Rgba<u8>) {
    let (w, h) = (i64::from(img.width()), i64::from(img.height()));
    for y in y0.max(0)..y1.min(h) {
        for x in x0.max(0)..x1.min(w) {
            // Both are within the image, whose sides fit in u32.
            img.put_pixel(x as u32, y as u32, colour);
        }
    }
}

fn draw_text(img: &mut RgbaImage, x0: i64, y0: i64, text: &str, colour: Rgba<u8>) {
    for (i, c) in text.chars().enumerate() {
        let Some(rows) = font8x8::BASIC_FONTS.get(c) else { continue };
        let cx = x0 + i as i64 * GLYPH;
        for (row, bits) in rows.iter().enumerate() {
            for col in 0..8 {
                if bits & (1 << col) != 0 {
                    let px = cx + col * GLYPH_SCALE;
                    let py = y0 + row as i64 * GLYPH_SCALE;
                    fill(img, px, py, px + GLYPH_SCALE, py + GLYPH_SCALE, colour);
                }
            }
        }
    }
}

/// Draws a coloured box and an id label for every listed element on the PNG
/// screenshot `png`, and returns the annotated PNG.
///
/// Boxes are scaled from [`Marks::size`] to the image's size, so a downscaled
/// screenshot is annotated in the right places. The label (white digits on the
/// box colour) sits just above the box's top-left corner, or inside it when the
/// box touches the top of the screen.
///
/// # Errors
///
/// [`SomError::Decode`] when `png` is not an image the `image` crate reads,
/// [`SomError::Encode`] when encoding fails.
pub fn annotate(png: &[u8], marks: &Marks) -> Result<Vec<u8>, SomError> {
    let mut img = image::load_from_memory(png).map_err(|e| SomError::Decode(e.to_string()))?.to_rgba8();
    let sx = f64::from(img.width()) / f64::from(marks.size.0.max(1));
    let sy = f64::from(img.height()) / f64::from(marks.size.1.max(1));
    let scale = |v: i32, s: f64| (f64::from(v) * s).round() as i64;
    for m in &marks.entities {
        let [r, g, b] = PALETTE[m.id % PALETTE.len()];
        let colour = Rgba([r, g, b, 255]);
        let (x0, y0) = (scale(m.rect.x, sx), scale(m.rect.y, sy));
        let (x1, y1) = (scale(m.rect.right(), sx).max(x0 + 1), scale(m.rect.bottom(), sy).max(y0 + 1));
        fill(&mut img, x0, y0, x1, y0 + BORDER, colour);
        fill(&mut img, x0, y1 - BORDER, x1, y1, colour);
        fill(&mut img, x0, y0, x0 + BORDER, y1, colour);
        fill(&mut img, x1 - BORDER, y0, x1, y1, colour);
        let label = m.id.to_string();
        let label_w = label.len() as i64 * GLYPH + 2;
        let label_h = GLYPH + 2;
        let ly = if y0 >= label_h { y0 - label_h } else { y0 };
        fill(&mut img, x0, ly, x0 + label_w, ly + label_h, colour);
        draw_text(&mut img, x0 + 1, ly + 1, &label, Rgba([255, 255, 255, 255]));
    }
    let mut out = Cursor::new(Vec::new());
    img.write_to(&mut out, ImageFormat::Png).map_err(|e| SomError::Encode(e.to_string()))?;
    Ok(out.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;
    use arena_shared::geometry::CoordinateSpace;
    use arena_shared::observation::A11yBackend;

    fn node(name: &str, rect: Option<Rect>, children: Vec<A11yNode>) -> A11yNode {
        A11yNode {
            role: "Button".into(),
            name: name.into(),
            rect,
            enabled: true,
            visible: true,
            children,
            ..A11yNode::default()
        }
    }

    fn leaf(name: &str, x: i32, y: i32, w: i32, h: i32) -> A11yNode {
        node(name, Some(Rect::new(x, y, w, h)), Vec::new())
    }

    fn window(rect: Rect, children: Vec<A11yNode>) -> A11yNode {
        node("window", Some(rect), children)
    }

    fn tree(windows: Vec<A11yNode>) -> A11yTree {
        A11yTree {
            backend: A11yBackend::Uia,
            windows,
            truncated: false,
            node_count: 0,
            elapsed_ms: 0,
            coordinate_space: CoordinateSpace::Physical,
        }
    }

    fn names(marks: &Marks) -> Vec<(usize, &str)> {
        marks.entities.iter().map(|m| (m.id, m.text.as_str())).collect()
    }

    #[test]
    fn collects_visible_enabled_leaves_through_visible_nodes_only() {
        let mut disabled = leaf("disabled", 10, 10, 20, 20);
        disabled.enabled = false;
        let mut invisible = leaf("invisible", 40, 10, 20, 20);
        invisible.visible = false;
        let mut hidden_group =
            node("group", Some(Rect::new(0, 100, 200, 100)), vec![leaf("under hidden", 10, 110, 20, 20)]);
        hidden_group.visible = false;
        let no_rect = node("no rect", None, Vec::new());
        let group = node("panel", Some(Rect::new(0, 300, 400, 100)), vec![leaf("deep", 10, 310, 30, 30)]);
        let t = tree(vec![window(
            Rect::new(0, 0, 800, 600),
            vec![disabled, invisible, hidden_group, no_rect, leaf("ok", 100, 10, 50, 20), group],
        )]);
        let marks = marks_from_tree(&t, (800, 600));
        assert_eq!(names(&marks), vec![(0, "ok"), (1, "deep")]);
        assert_eq!(marks.rects, vec![[100, 10, 150, 30], [10, 310, 40, 340]]);
    }

    #[test]
    fn an_invisible_window_is_skipped_and_a_childless_window_is_its_own_leaf() {
        let mut hidden = window(Rect::new(0, 0, 100, 100), vec![leaf("in hidden", 1, 1, 10, 10)]);
        hidden.visible = false;
        let bare = window(Rect::new(500, 500, 50, 50), Vec::new());
        let marks = marks_from_tree(&tree(vec![hidden, bare]), (1000, 1000));
        assert_eq!(names(&marks), vec![(0, "window")]);
    }

    #[test]
    fn a_higher_window_hides_the_elements_whose_centre_it_covers() {
        // The tree lists the topmost window first.
        let top = window(Rect::new(0, 0, 300, 300), vec![leaf("top button", 10, 10, 40, 20)]);
        let bottom = window(
            Rect::new(0, 0, 1000, 800),
            vec![
                leaf("covered", 100, 100, 40, 20),
                // Centre (310, 110) is right of the top window: kept.
                leaf("beside", 290, 100, 40, 20),
                // Centre (300, 110) is exactly on the top window's right edge: covered.
                leaf("on the edge", 280, 100, 40, 20),
            ],
        );
        let marks = marks_from_tree(&tree(vec![top, bottom]), (1000, 800));
        assert_eq!(names(&marks), vec![(0, "beside"), (1, "top button")]);
    }

    #[test]
    fn redundancy_drops_the_first_later_near_duplicate_only() {
        // a and b overlap by Dice 0.9 (> 0.8); c duplicates a too, but only the first
        // later duplicate per i is dropped; c is then dropped for b (i = 1).
        let a = leaf("a", 0, 0, 100, 100);
        let b = leaf("b", 0, 0, 100, 80); // 2*8000/(10000+8000) = 0.889
        let c = leaf("c", 0, 0, 100, 90);
        let d = leaf("d", 0, 0, 100, 50); // 2*5000/15000 = 0.667 with a: kept
        let marks = marks_from_tree(&tree(vec![window(Rect::new(0, 0, 500, 500), vec![a, b, c, d])]), (500, 500));
        assert_eq!(names(&marks), vec![(0, "a"), (1, "d")]);

        check_dice(Rect::new(0, 0, 100, 100), Rect::new(0, 0, 100, 100), 1.0);
        check_dice(Rect::new(0, 0, 100, 100), Rect::new(200, 0, 100, 100), 0.0);
        check_dice(Rect::new(0, 0, 10, 10), Rect::new(5, 0, 10, 10), 0.5);
        check_dice(Rect::new(0, 0, 0, 0), Rect::new(0, 0, 0, 0), 0.0);
    }

    fn check_dice(a: Rect, b: Rect, expected: f64) {
        let got = dice(&a, &b);
        assert!((got - expected).abs() < 1e-9, "dice({a:?}, {b:?}) = {got}, expected {expected}");
    }

    #[test]
    fn exactly_at_the_threshold_is_kept() {
        // 2*4000/(6000+4000) = 0.8: not strictly above.
        let marks = marks_from_tree(
            &tree(vec![window(Rect::new(0, 0, 500, 500), vec![leaf("a", 0, 0, 100, 60), leaf("b", 0, 0, 100, 40)])]),
            (500, 500),
        );
        assert_eq!(names(&marks), vec![(0, "a"), (1, "b")]);
    }

    #[test]
    fn ids_count_unlisted_entities_and_rects_keep_every_id() {
        let children = vec![
            leaf("offscreen", -10, 5, 30, 30),
            leaf("zero width", 5, 5, 0, 30),
            leaf("one pixel", 50, 50, 1, 1),
            leaf("real", 100, 100, 40, 20),
        ];
        let marks = marks_from_tree(&tree(vec![window(Rect::new(0, 0, 500, 500), children)]), (500, 500));
        assert_eq!(names(&marks), vec![(3, "real")]);
        assert_eq!(marks.rects.len(), 4);
        assert_eq!(marks.rects[3], [100, 100, 140, 120]);
        assert_eq!(marks.rects[0], [-10, 5, 20, 35]);
        assert!(marks.get(3).is_some() && marks.get(0).is_none());
    }

    #[test]
    fn candidate_list_is_upstreams_text() {
        let children = vec![leaf("OK", 192, 108, 96, 54), leaf("", 0, 0, 1920, 1080), leaf("Half", 960, 540, 480, 270)];
        let marks = marks_from_tree(&tree(vec![window(Rect::new(0, 0, 1920, 1080), children)]), (1920, 1080));
        let expected = "ID | Type | Text content or description | Normalized location [x1, y1, x2, y2]\n\
            0 | a11y | OK | [0.1, 0.1, 0.15, 0.15]\n\
            1 | a11y | - | [0.0, 0.0, 1.0, 1.0]\n\
            2 | a11y | Half | [0.5, 0.5, 0.75, 0.75]";
        assert_eq!(marks.candidate_list(), expected);
    }

    #[test]
    fn rounding_matches_python() {
        for (v, expected) in
            [(0.125, "0.12"), (0.375, "0.38"), (1.0 / 3.0, "0.33"), (0.999, "1.0"), (0.005, "0.01"), (0.0, "0.0")]
        {
            assert_eq!(round2(v), expected, "round({v}, 2)");
        }
    }

    fn png(w: u32, h: u32) -> Vec<u8> {
        let img = RgbaImage::from_pixel(w, h, Rgba([250, 250, 250, 255]));
        let mut out = Cursor::new(Vec::new());
        img.write_to(&mut out, ImageFormat::Png).expect("encode");
        out.into_inner()
    }

    #[test]
    fn annotate_draws_boxes_and_labels_where_the_marks_are() {
        let marks = marks_from_tree(
            &tree(vec![window(Rect::new(0, 0, 200, 100), vec![leaf("box", 100, 40, 60, 40)])]),
            (200, 100),
        );
        let original = png(200, 100);
        let annotated = annotate(&original, &marks).expect("annotate");
        assert_ne!(annotated, original);
        let img = image::load_from_memory(&annotated).expect("decode").to_rgba8();
        assert_eq!(img.dimensions(), (200, 100));
        let [r, g, b] = PALETTE[0];
        // The box's outline, bottom-right corner.
        assert_eq!(img.get_pixel(159, 79), &Rgba([r, g, b, 255]));
        // Inside the box is untouched, and so is a far corner.
        assert_eq!(img.get_pixel(130, 60), &Rgba([250, 250, 250, 255]));
        assert_eq!(img.get_pixel(5, 95), &Rgba([250, 250, 250, 255]));
        // The label sits above the box and holds white glyph pixels.
        let label_white = (22..40)
            .flat_map(|y| (100..118).map(move |x| (x, y)))
            .any(|(x, y)| img.get_pixel(x, y) == &Rgba([255, 255, 255, 255]));
        assert!(label_white, "no label drawn above the box");
    }

    #[test]
    fn annotate_scales_to_a_downscaled_screenshot() {
        let marks = marks_from_tree(
            &tree(vec![window(Rect::new(0, 0, 400, 200), vec![leaf("box", 200, 80, 120, 80)])]),
            (400, 200),
        );
        let annotated = annotate(&png(200, 100), &marks).expect("annotate");
        let img = image::load_from_memory(&annotated).expect("decode").to_rgba8();
        let [r, g, b] = PALETTE[0];
        assert_eq!(img.get_pixel(159, 79), &Rgba([r, g, b, 255]));
    }

    #[test]
    fn annotate_rejects_garbage() {
        assert!(matches!(annotate(b"not a png", &Marks::default()), Err(SomError::Decode(_))));
    }
}
