//! The `a11y` proposal: element boxes from the accessibility tree, and the
//! box filters upstream's Navi applies to them before they are numbered or merged.
//!
//! The rules are those of upstream's `a11y_demo.propose_ents` (waa-api.md §c.3)
//! over our JSON tree instead of pywinauto's XML:
//!
//! 1. Top-level windows are processed bottom-up (the tree lists them topmost
//!    first, so in reverse). Before a visible window's elements are collected,
//!    every element already collected whose centre lies inside that window is
//!    dropped: the window covers it. The centre is `x + w // 2` (integer floor),
//!    and the window's edges count as inside.
//! 2. A depth-first walk descends only through visible nodes and collects the
//!    leaves that are visible and enabled. Upstream's XML gives every node a
//!    position and a size, `(0, 0)` when UIA has no rectangle, so a leaf without
//!    a rectangle here is an entity with an empty box at the origin: it takes an
//!    id, and the ids after it are the ones upstream gives. The entity's text is
//!    the node's `name` (not its value or text).
//! 3. Near-duplicates are removed by upstream's `filter_reduntant_entities`:
//!    for each position `i` of the *live* list, the first later entity whose
//!    Dice overlap `2|A∩B|/(|A|+|B|)` exceeds 0.8 is removed from the list,
//!    then the search for that `i` stops. Because the list shrinks as it is
//!    walked, three identical boxes keep two and four keep two.

use arena_shared::geometry::Rect;
use arena_shared::observation::{A11yNode, A11yTree};

use super::ProposedEntity;

/// Upstream's `filter_reduntant_entities` threshold.
pub const REDUNDANCY_THRESHOLD: f64 = 0.8;

/// The type upstream gives every accessibility entity.
pub const A11Y_KIND: &str = "a11y";

/// An empty box at the origin: what upstream's XML says of an element without a rectangle.
const NO_RECT: Rect = Rect::new(0, 0, 0, 0);

/// Upstream's `center_of_bbox`: integer halves, rounded down as Python's `//`.
fn centre(r: &Rect) -> (i64, i64) {
    (i64::from(r.x) + i64::from(r.width).div_euclid(2), i64::from(r.y) + i64::from(r.height).div_euclid(2))
}

/// Upstream's `rect_overlaps`: whether a point lies in `r`, edges included.
fn inside(r: &Rect, (x, y): (i64, i64)) -> bool {
    let (x0, y0) = (i64::from(r.x), i64::from(r.y));
    x >= x0 && y >= y0 && x <= x0 + i64::from(r.width) && y <= y0 + i64::from(r.height)
}

/// Upstream's `iter_tree`: collects visible, enabled leaves, descending only through visible nodes.
fn collect_leaves(node: &A11yNode, out: &mut Vec<ProposedEntity>) {
    if !node.visible {
        return;
    }
    if node.children.is_empty() {
        if node.enabled {
            out.push(ProposedEntity::new(A11Y_KIND, node.rect.unwrap_or(NO_RECT), Some(node.name.clone())));
        }
        return;
    }
    for child in &node.children {
        collect_leaves(child, out);
    }
}

/// Steps 1 and 2 of the module doc: occlusion by higher windows, then the leaf walk.
fn collect(tree: &A11yTree) -> Vec<ProposedEntity> {
    let mut entities: Vec<ProposedEntity> = Vec::new();
    for window in tree.windows.iter().rev() {
        if !window.visible {
            continue;
        }
        let rect = window.rect.unwrap_or(NO_RECT);
        entities.retain(|e| !inside(&rect, centre(&e.rect)));
        collect_leaves(window, &mut entities);
    }
    entities
}

/// Upstream's `overlap_ratio`: the Dice coefficient `2|A∩B| / (|A|+|B|)` with
/// areas taken as the signed products `w·h`; 0 when either area is 0 (and when
/// the two areas cancel, which Python would raise on).
pub(crate) fn dice(a: &Rect, b: &Rect) -> f64 {
    let area = |r: &Rect| i64::from(r.width) * i64::from(r.height);
    let (area_a, area_b) = (area(a), area(b));
    if area_a == 0 || area_b == 0 || area_a + area_b == 0 {
        return 0.0;
    }
    let w = (i64::from(a.right()).min(i64::from(b.right())) - i64::from(a.x).max(i64::from(b.x))).max(0);
    let h = (i64::from(a.bottom()).min(i64::from(b.bottom())) - i64::from(a.y).max(i64::from(b.y))).max(0);
    2.0 * (w * h) as f64 / (area_a + area_b) as f64
}

/// Upstream's `filter_reduntant_entities`, step 3 of the module doc.
pub(crate) fn drop_redundant(mut entities: Vec<ProposedEntity>, threshold: f64) -> Vec<ProposedEntity> {
    // `range(len(entities))` is taken once, before anything is removed.
    let n = entities.len();
    for i in 0..n {
        let mut j = i + 1;
        while j < entities.len() {
            if dice(&entities[i].rect, &entities[j].rect) > threshold {
                entities.remove(j);
                break;
            }
            j += 1;
        }
    }
    entities
}

/// Upstream's `propose_ents` over our tree: the accessibility entities in id order.
pub fn propose(tree: &A11yTree) -> Vec<ProposedEntity> {
    drop_redundant(collect(tree), REDUNDANCY_THRESHOLD)
}

/// Upstream's `filter_entities`: what is drawn and listed (`x >= 0`, `y >= 0`,
/// `w > 0`, `h > 0` and `w·h > 1`).
pub fn drawable(r: &Rect) -> bool {
    r.x >= 0 && r.y >= 0 && r.width > 0 && r.height > 0 && i64::from(r.width) * i64::from(r.height) > 1
}

/// Upstream's `filter_nonvis_and_oob_entities` (the `mixed-omni` mode): boxes are
/// clipped to the screen and those left with an area under 5 pixels are dropped.
pub fn clip_to_screen(entities: Vec<ProposedEntity>, (width, height): (u32, u32)) -> Vec<ProposedEntity> {
    let (width, height) = (i64::from(width), i64::from(height));
    entities
        .into_iter()
        .filter_map(|mut e| {
            let r = e.rect;
            let x = i64::from(r.x).clamp(0, width);
            let y = i64::from(r.y).clamp(0, height);
            let x2 = (i64::from(r.x) + i64::from(r.width)).clamp(0, width);
            let y2 = (i64::from(r.y) + i64::from(r.height)).clamp(0, height);
            let (w, h) = (x2 - x, y2 - y);
            if x2 < x || y2 < y || w * h < 5 {
                return None;
            }
            // All four are within the screen, whose sides fit in i32 (they came from a u32 screen size).
            let fit = |v: i64| i32::try_from(v).unwrap_or(i32::MAX);
            e.rect = Rect::new(fit(x), fit(y), fit(w), fit(h));
            Some(e)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{marks_from_tree, Marks};
    use arena_shared::geometry::CoordinateSpace;
    use arena_shared::observation::A11yBackend;

    pub(crate) fn node(name: &str, rect: Option<Rect>, children: Vec<A11yNode>) -> A11yNode {
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

    pub(crate) fn leaf(name: &str, x: i32, y: i32, w: i32, h: i32) -> A11yNode {
        node(name, Some(Rect::new(x, y, w, h)), Vec::new())
    }

    pub(crate) fn window(rect: Rect, children: Vec<A11yNode>) -> A11yNode {
        node("window", Some(rect), children)
    }

    pub(crate) fn tree(windows: Vec<A11yNode>) -> A11yTree {
        A11yTree {
            backend: A11yBackend::Uia,
            windows,
            truncated: false,
            node_count: 0,
            elapsed_ms: 0,
            coordinate_space: CoordinateSpace::Physical,
            windows_walked: Vec::new(),
        }
    }

    fn names(marks: &Marks) -> Vec<(usize, &str)> {
        marks.entities.iter().map(|m| (m.id, m.given_text().unwrap_or("-"))).collect()
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
        let group = node("panel", Some(Rect::new(0, 300, 400, 100)), vec![leaf("deep", 10, 310, 30, 30)]);
        let t = tree(vec![window(
            Rect::new(0, 0, 800, 600),
            vec![disabled, invisible, hidden_group, leaf("ok", 100, 10, 50, 20), group],
        )]);
        let marks = marks_from_tree(&t, (800, 600));
        assert_eq!(names(&marks), vec![(0, "ok"), (1, "deep")]);
        assert_eq!(marks.rects, vec![[100, 10, 150, 30], [10, 310, 40, 340]]);
    }

    #[test]
    fn a_leaf_without_a_rectangle_takes_an_id_as_upstream_numbers_it() {
        // Upstream's XML writes `(0, 0)` for both, so the leaf is an entity: it is
        // not drawn or listed, but the ids after it do not shift.
        let t = tree(vec![window(
            Rect::new(0, 0, 800, 600),
            vec![leaf("first", 10, 10, 30, 30), node("no rect", None, Vec::new()), leaf("after", 100, 10, 50, 20)],
        )]);
        let marks = marks_from_tree(&t, (800, 600));
        assert_eq!(names(&marks), vec![(0, "first"), (2, "after")]);
        assert_eq!(marks.rects, vec![[10, 10, 40, 40], [0, 0, 0, 0], [100, 10, 150, 30]]);
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
                // Centre 279 + 43 // 2 = 300 lies on the edge: covered (a float centre, 300.5, would not be).
                leaf("odd width", 279, 200, 43, 20),
            ],
        );
        let marks = marks_from_tree(&tree(vec![top, bottom]), (1000, 800));
        assert_eq!(names(&marks), vec![(0, "beside"), (1, "top button")]);
    }

    fn stacked(n: usize) -> Vec<A11yNode> {
        (0..n).map(|i| leaf(&format!("s{i}"), 0, 0, 100, 100)).collect()
    }

    #[test]
    fn redundancy_pops_from_the_live_list_as_upstream() {
        // Three identical: i=0 removes s1; the list is [s0, s2] and i=1 has no later entity.
        let marks = marks_from_tree(&tree(vec![window(Rect::new(0, 0, 500, 500), stacked(3))]), (500, 500));
        assert_eq!(names(&marks), vec![(0, "s0"), (1, "s2")]);
        // Four identical: i=0 removes s1, i=1 (now s2) removes s3: two are left.
        let marks = marks_from_tree(&tree(vec![window(Rect::new(0, 0, 500, 500), stacked(4))]), (500, 500));
        assert_eq!(names(&marks), vec![(0, "s0"), (1, "s2")]);
        // Five identical: s1 and s3 go, s4 is kept (i=2 is s4 with no later entity).
        let marks = marks_from_tree(&tree(vec![window(Rect::new(0, 0, 500, 500), stacked(5))]), (500, 500));
        assert_eq!(names(&marks), vec![(0, "s0"), (1, "s2"), (2, "s4")]);
    }

    #[test]
    fn redundancy_removes_only_the_first_later_near_duplicate() {
        // b duplicates a (Dice 0.889) and goes; c duplicates a too but the search for
        // i=0 stopped; i=1 is now c, whose later d overlaps it by 0.714: kept.
        let a = leaf("a", 0, 0, 100, 100);
        let b = leaf("b", 0, 0, 100, 80);
        let c = leaf("c", 0, 0, 100, 90);
        let d = leaf("d", 0, 0, 100, 50);
        let marks = marks_from_tree(&tree(vec![window(Rect::new(0, 0, 500, 500), vec![a, b, c, d])]), (500, 500));
        assert_eq!(names(&marks), vec![(0, "a"), (1, "c"), (2, "d")]);

        check_dice(Rect::new(0, 0, 100, 100), Rect::new(0, 0, 100, 100), 1.0);
        check_dice(Rect::new(0, 0, 100, 100), Rect::new(200, 0, 100, 100), 0.0);
        check_dice(Rect::new(0, 0, 10, 10), Rect::new(5, 0, 10, 10), 0.5);
        check_dice(Rect::new(0, 0, 0, 0), Rect::new(0, 0, 0, 0), 0.0);
        check_dice(Rect::new(0, 0, 0, 10), Rect::new(0, 0, 10, 10), 0.0);
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
    fn clipping_keeps_what_is_on_the_screen() {
        let e = |x, y, w, h| ProposedEntity::new(A11Y_KIND, Rect::new(x, y, w, h), None);
        let clipped =
            clip_to_screen(vec![e(-10, -10, 30, 30), e(90, 90, 50, 50), e(0, 0, 2, 2), e(200, 0, 10, 10)], (100, 100));
        let rects: Vec<Rect> = clipped.iter().map(|e| e.rect).collect();
        assert_eq!(rects, vec![Rect::new(0, 0, 20, 20), Rect::new(90, 90, 10, 10)]);
    }
}
