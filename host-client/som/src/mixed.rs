//! The `mixed-oss` and `mixed-omni` merge: the accessibility entities first,
//! then the pixel parser's entities that the accessibility boxes do not
//! already cover, as upstream's `agent.py` merges them.
//!
//! - The mask is upstream's `get_mask_from_entities`: a screen-sized grid where
//!   every accessibility box is set. Its corner is clamped into the screen but
//!   its width and height are only clamped to the screen's, not shortened by
//!   the clamp, as upstream does.
//! - A pixel entity is kept when the masked share of its area is under 0.5
//!   (upstream's `filter_entities_with_mask(th=0.5)`). Its box is read from the
//!   mask as a numpy slice `mask[y:y+h, x:x+w]`: a negative start counts from
//!   the far edge, ends are cut at the edge. An entity with no area is dropped
//!   (numpy's 0/0 is NaN, which is not under 0.5).
//! - In `mixed-omni` the accessibility entities are then re-typed as upstream
//!   does so its colour map applies: `icon` when the width/height ratio is within
//!   0.9–1.1, else `text`.

use super::a11y::A11Y_KIND;
use super::ProposedEntity;

/// Upstream's mask threshold in both mixed modes.
pub const MASK_THRESHOLD: f64 = 0.5;

/// A screen-sized grid of covered pixels.
#[derive(Debug, Clone)]
pub struct Mask {
    width: usize,
    height: usize,
    cells: Vec<bool>,
}

/// Python's `seq[start:stop]` bounds over a length `len`.
fn py_slice(start: i64, stop: i64, len: usize) -> std::ops::Range<usize> {
    let len = len as i64;
    let norm = |v: i64| if v < 0 { (v + len).max(0) } else { v.min(len) };
    let (a, b) = (norm(start), norm(stop));
    // Both are within 0..=len, which came from a usize.
    (a as usize)..(b.max(a) as usize)
}

impl Mask {
    /// Upstream's `get_mask_from_entities`.
    pub fn from_entities(entities: &[ProposedEntity], (width, height): (u32, u32)) -> Mask {
        let (w, h) = (width as usize, height as usize);
        let mut mask = Mask { width: w, height: h, cells: vec![false; w * h] };
        let (wi, hi) = (i64::from(width), i64::from(height));
        for e in entities {
            let r = e.rect;
            let x = i64::from(r.x).clamp(0, wi);
            let y = i64::from(r.y).clamp(0, hi);
            let ew = i64::from(r.width).clamp(0, wi);
            let eh = i64::from(r.height).clamp(0, hi);
            for row in py_slice(y, y + eh, h) {
                for col in py_slice(x, x + ew, w) {
                    mask.cells[row * w + col] = true;
                }
            }
        }
        mask
    }

    /// How many pixels of `mask[y:y+h, x:x+w]` are set.
    fn covered(&self, e: &ProposedEntity) -> u64 {
        let r = e.rect;
        let rows = py_slice(i64::from(r.y), i64::from(r.y) + i64::from(r.height), self.height);
        let cols = py_slice(i64::from(r.x), i64::from(r.x) + i64::from(r.width), self.width);
        let mut n = 0;
        for row in rows {
            n += self.cells[row * self.width..][cols.clone()].iter().filter(|c| **c).count() as u64;
        }
        n
    }

    /// Upstream's `filter_entities_with_mask`: the entities whose masked share is under `threshold`.
    pub fn keep_uncovered(&self, entities: Vec<ProposedEntity>, threshold: f64) -> Vec<ProposedEntity> {
        entities
            .into_iter()
            .filter(|e| {
                let area = i64::from(e.rect.width) * i64::from(e.rect.height);
                (self.covered(e) as f64 / area as f64) < threshold
            })
            .collect()
    }
}

/// The accessibility entities, then the pixel entities they leave uncovered.
pub fn merge(a11y: Vec<ProposedEntity>, pixel: Vec<ProposedEntity>, size: (u32, u32)) -> Vec<ProposedEntity> {
    let mask = Mask::from_entities(&a11y, size);
    let mut out = a11y;
    out.extend(mask.keep_uncovered(pixel, MASK_THRESHOLD));
    out
}

/// `mixed-omni`'s re-typing of accessibility entities into `icon` (nearly square) or `text`.
pub fn retype_a11y(entities: &mut [ProposedEntity]) {
    for e in entities.iter_mut().filter(|e| e.kind == A11Y_KIND) {
        let ratio = f64::from(e.rect.width) / f64::from(e.rect.height);
        e.kind = if (0.9..=1.1).contains(&ratio) { "icon" } else { "text" }.to_owned();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use arena_shared::geometry::Rect;

    fn e(kind: &str, x: i32, y: i32, w: i32, h: i32) -> ProposedEntity {
        ProposedEntity::new(kind, Rect::new(x, y, w, h), Some(format!("{kind}@{x},{y}")))
    }

    fn texts(v: &[ProposedEntity]) -> Vec<&str> {
        v.iter().map(|e| e.text.as_deref().unwrap_or("-")).collect()
    }

    #[test]
    fn pixel_entities_half_covered_by_a11y_boxes_are_dropped() {
        let a11y = vec![e("a11y", 0, 0, 100, 100)];
        let pixel = vec![
            e("text", 10, 10, 20, 20),   // inside: dropped
            e("icon", 50, 0, 100, 100),  // exactly half covered: 0.5 is not under 0.5, dropped
            e("icon", 60, 0, 100, 100),  // 40 % covered: kept
            e("text", 200, 200, 10, 10), // outside: kept
            e("icon", 300, 300, 0, 10),  // no area: dropped
        ];
        let merged = merge(a11y, pixel, (400, 400));
        assert_eq!(texts(&merged), vec!["a11y@0,0", "icon@60,0", "text@200,200"]);
    }

    #[test]
    fn the_mask_clamps_the_corner_but_not_the_size() {
        // An a11y box at x=-50 w=100 masks columns 0..100, not 0..50.
        let mask = Mask::from_entities(&[e("a11y", -50, 0, 100, 100)], (400, 400));
        let kept = mask.keep_uncovered(vec![e("icon", 60, 0, 30, 30)], MASK_THRESHOLD);
        assert!(kept.is_empty());
    }

    #[test]
    fn a_negative_start_reads_the_mask_as_python_slices_do() {
        // mask[-10:10] over 400 rows is empty: nothing covered, so kept.
        let mask = Mask::from_entities(&[e("a11y", 0, 0, 400, 400)], (400, 400));
        let kept = mask.keep_uncovered(vec![e("icon", 5, -10, 20, 20)], MASK_THRESHOLD);
        assert_eq!(kept.len(), 1);
        assert_eq!(py_slice(-10, 10, 400), 390..390);
        assert_eq!(py_slice(390, 420, 400), 390..400);
    }

    #[test]
    fn a11y_entities_become_icons_when_nearly_square() {
        let mut v = vec![
            e("a11y", 0, 0, 20, 21),
            e("a11y", 0, 0, 100, 20),
            e("image", 0, 0, 100, 20),
            e("a11y", 0, 0, 10, 11),
            e("a11y", 0, 0, 10, 9),
        ];
        retype_a11y(&mut v);
        let kinds: Vec<&str> = v.iter().map(|e| e.kind.as_str()).collect();
        assert_eq!(kinds, vec!["icon", "text", "image", "icon", "text"]);
    }
}
