//! The prompt image: boxes and id labels drawn on the screenshot as upstream's
//! `draw_som` draws them with its prompt colour map, in our own renderer.
//!
//! - Only marks with a colour are drawn ([`super::Mark::colour`]); every box
//!   first, then every label.
//! - A box is Pillow's `rectangle([x, y, x + w, y + h], width=2)`: both corners
//!   inclusive, a 2-pixel outline inside them.
//! - A label is the id in white on the box colour, padded 2 pixels above and
//!   below and 5 left and right. Upstream sets it in 12-point Arial; we use the
//!   8x8 bitmap font, which makes a label 12 pixels high as upstream's are.
//! - Placement is upstream's `draw_labels`: eight (position on the box, anchor
//!   on the label) pairs are tried in order: the four outer corners (below the
//!   box at its right edge first, then below-left, above-left, above-right),
//!   then the four inner corners (bottom-right, bottom-left, top-left,
//!   top-right). The first whose label rectangle overlaps no earlier label and
//!   no listed `text` entity's box (shrunk by one pixel) is taken; when none is
//!   free the last is used. Touching edges do not count as overlap.

use font8x8::UnicodeFonts;
use image::{Rgba, RgbaImage};

use super::{Mark, Marks};

/// Outline thickness of a box, in image pixels (upstream's `outlineWidth`).
const BORDER: i64 = 2;
/// Label padding: top, right, bottom, left (upstream's `'2 5'`).
const PADDING: [i64; 4] = [2, 5, 2, 5];
/// Width and height of one glyph of the bitmap font.
const GLYPH: i64 = 8;
const WHITE: Rgba<u8> = Rgba([255, 255, 255, 255]);

/// A rectangle as upstream's label code holds it: left, top, width, height.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct LabelRect {
    pub(crate) x: i64,
    pub(crate) y: i64,
    pub(crate) w: i64,
    pub(crate) h: i64,
}

impl LabelRect {
    /// Upstream's `check_overlap`: shared area, edges that only touch do not count.
    fn overlaps(&self, o: &LabelRect) -> bool {
        !(self.x + self.w <= o.x || o.x + o.w <= self.x || self.y + self.h <= o.y || o.y + o.h <= self.y)
    }
}

/// A corner as a fraction of a rectangle's width and height.
#[derive(Debug, Clone, Copy)]
enum Corner {
    TopLeft,
    TopRight,
    BottomLeft,
    BottomRight,
}

impl Corner {
    fn fractions(self) -> (i64, i64) {
        match self {
            Corner::TopLeft => (0, 0),
            Corner::TopRight => (1, 0),
            Corner::BottomLeft => (0, 1),
            Corner::BottomRight => (1, 1),
        }
    }
}

/// Upstream's placements: (the box's corner, the label's corner put on it), in the order tried.
const PLACEMENTS: [(Corner, Corner); 8] = [
    (Corner::BottomRight, Corner::TopRight),
    (Corner::BottomLeft, Corner::TopLeft),
    (Corner::TopLeft, Corner::BottomLeft),
    (Corner::TopRight, Corner::BottomRight),
    (Corner::BottomRight, Corner::BottomRight),
    (Corner::BottomLeft, Corner::BottomLeft),
    (Corner::TopLeft, Corner::TopLeft),
    (Corner::TopRight, Corner::TopRight),
];

/// The size of a label holding `text`, padding included.
fn label_size(text: &str) -> (i64, i64) {
    let chars = text.chars().count() as i64;
    (chars * GLYPH + PADDING[1] + PADDING[3], GLYPH + PADDING[0] + PADDING[2])
}

/// Upstream's `get_label_rect`: the label's corner `anchor` on the box's corner `position`.
fn label_rect(b: &LabelRect, (w, h): (i64, i64), position: Corner, anchor: Corner) -> LabelRect {
    let (px, py) = position.fractions();
    let (ax, ay) = anchor.fractions();
    LabelRect { x: b.x + b.w * px - w * ax, y: b.y + b.h * py - h * ay, w, h }
}

/// Where each drawn mark's label goes, in the order of `boxes` (`None`: not drawn).
/// `boxes` are the marks' boxes in image pixels with whether the mark is drawn
/// and whether it is a `text` entity, and its label text.
pub(crate) fn place_labels(boxes: &[(LabelRect, bool, bool, String)]) -> Vec<Option<LabelRect>> {
    // Listed text entities are kept clear of labels, drawn or not.
    let mut taken: Vec<LabelRect> = boxes
        .iter()
        .filter(|(_, _, is_text, _)| *is_text)
        .map(|(b, _, _, _)| LabelRect { x: b.x + 1, y: b.y + 1, w: b.w - 1, h: b.h - 1 })
        .collect();
    let mut out = Vec::with_capacity(boxes.len());
    for (b, drawn, _, text) in boxes {
        if !drawn {
            out.push(None);
            continue;
        }
        let size = label_size(text);
        let last = PLACEMENTS.len() - 1;
        let chosen = PLACEMENTS
            .iter()
            .enumerate()
            .map(|(i, &(position, anchor))| (i, label_rect(b, size, position, anchor)))
            .find(|(i, r)| *i == last || !taken.iter().any(|t| r.overlaps(t)))
            .map(|(_, r)| r);
        if let Some(r) = chosen {
            taken.push(r);
        }
        out.push(chosen);
    }
    out
}

/// Fills the inclusive rectangle `x0..=x1`, `y0..=y1` (clipped to the image).
fn fill(img: &mut RgbaImage, x0: i64, y0: i64, x1: i64, y1: i64, colour: Rgba<u8>) {
    let (w, h) = (i64::from(img.width()), i64::from(img.height()));
    for y in y0.max(0)..=y1.min(h - 1) {
        for x in x0.max(0)..=x1.min(w - 1) {
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
                    let (px, py) = (cx + col, y0 + row as i64);
                    fill(img, px, py, px, py, colour);
                }
            }
        }
    }
}

fn rgba(c: [u8; 3]) -> Rgba<u8> {
    Rgba([c[0], c[1], c[2], 255])
}

/// A mark's box in image pixels (x, y, w, h), scaled from the marks' screen size.
fn image_box(m: &Mark, (sx, sy): (f64, f64)) -> LabelRect {
    let scale = |v: i32, s: f64| (f64::from(v) * s).round() as i64;
    let (x, y) = (scale(m.rect.x, sx), scale(m.rect.y, sy));
    LabelRect { x, y, w: scale(m.rect.right(), sx) - x, h: scale(m.rect.bottom(), sy) - y }
}

/// Draws the listed marks that have a colour on a copy of the screenshot's
/// pixels, as the module doc describes, and returns it (encoded only where it
/// leaves the host: the model request and the step's log file).
///
/// Boxes are scaled from [`Marks::size`] to the image's size, so a downscaled
/// screenshot is annotated in the right places; labels keep their size.
pub fn annotate(screenshot: &RgbaImage, marks: &Marks) -> RgbaImage {
    let mut img = screenshot.clone();
    let scale = (
        f64::from(img.width()) / f64::from(marks.size.0.max(1)),
        f64::from(img.height()) / f64::from(marks.size.1.max(1)),
    );
    let boxes: Vec<(LabelRect, bool, bool, String)> = marks
        .entities
        .iter()
        .map(|m| (image_box(m, scale), m.colour.is_some(), m.kind == "text", m.id.to_string()))
        .collect();
    for (m, (b, _, _, _)) in marks.entities.iter().zip(&boxes) {
        let Some(c) = m.colour else { continue };
        let c = rgba(c);
        let (x1, y1) = (b.x + b.w, b.y + b.h);
        fill(&mut img, b.x, b.y, x1, b.y + BORDER - 1, c);
        fill(&mut img, b.x, y1 - BORDER + 1, x1, y1, c);
        fill(&mut img, b.x, b.y, b.x + BORDER - 1, y1, c);
        fill(&mut img, x1 - BORDER + 1, b.y, x1, y1, c);
    }
    for ((m, (_, _, _, text)), label) in marks.entities.iter().zip(&boxes).zip(place_labels(&boxes)) {
        let (Some(c), Some(r)) = (m.colour, label) else { continue };
        fill(&mut img, r.x, r.y, r.x + r.w, r.y + r.h, rgba(c));
        draw_text(&mut img, r.x + PADDING[3], r.y + PADDING[0], text, WHITE);
    }
    img
}

#[cfg(test)]
mod tests {
    use super::*;

    fn b(x: i64, y: i64, w: i64, h: i64) -> LabelRect {
        LabelRect { x, y, w, h }
    }

    fn drawn(r: LabelRect, id: &str) -> (LabelRect, bool, bool, String) {
        (r, true, false, id.to_owned())
    }

    #[test]
    fn a_label_goes_below_the_box_at_its_right_edge() {
        // One digit: 8 + 10 wide, 8 + 4 high; its top-right corner on the box's bottom-right.
        let placed = place_labels(&[drawn(b(100, 50, 60, 30), "7")]);
        assert_eq!(placed, vec![Some(b(142, 80, 18, 12))]);
    }

    #[test]
    fn labels_avoid_earlier_labels_in_upstreams_order() {
        // Identical boxes: each next label takes the next free placement.
        let boxes: Vec<_> = (0..9).map(|i| drawn(b(100, 100, 60, 40), &i.to_string())).collect();
        let placed: Vec<LabelRect> = place_labels(&boxes).into_iter().map(Option::unwrap).collect();
        let expected = [
            b(142, 140, 18, 12), // below, right-aligned
            b(100, 140, 18, 12), // below, left-aligned
            b(100, 88, 18, 12),  // above, left-aligned
            b(142, 88, 18, 12),  // above, right-aligned
            b(142, 128, 18, 12), // inside bottom-right
            b(100, 128, 18, 12), // inside bottom-left
            b(100, 100, 18, 12), // inside top-left
            b(142, 100, 18, 12), // inside top-right
            b(142, 100, 18, 12), // nothing free: the last placement anyway
        ];
        assert_eq!(placed, expected);
    }

    #[test]
    fn labels_keep_off_text_entities_and_touching_is_not_overlap() {
        // A listed (undrawn) text entity right below the box pushes the label above... unless
        // it only touches: the shrunk text box starts one pixel in.
        let text_below = (b(100, 80, 60, 20), false, true, "1".to_owned());
        let placed = place_labels(&[drawn(b(100, 50, 60, 30), "0"), text_below.clone()]);
        assert_eq!(placed, vec![Some(b(100, 38, 18, 12)), None]);
        // A text box that ends where the label would start does not count.
        let text_left = (b(0, 80, 142, 20), false, true, "1".to_owned());
        let placed = place_labels(&[drawn(b(100, 50, 60, 30), "0"), text_left]);
        assert_eq!(placed[0], Some(b(142, 80, 18, 12)));
    }

    #[test]
    fn undrawn_marks_take_no_place() {
        let placed = place_labels(&[(b(100, 50, 60, 30), false, false, "0".into()), drawn(b(100, 50, 60, 30), "1")]);
        assert_eq!(placed, vec![None, Some(b(142, 80, 18, 12))]);
    }
}
