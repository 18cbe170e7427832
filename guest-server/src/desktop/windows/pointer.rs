//! Mouse arithmetic for `SendInput`: absolute coordinates normalised over the
//! virtual desktop, clamping to it, the wheel's raw deltas, and the path a drag
//! with a duration takes.
//!
//! Platform-neutral and tested natively; the calls are in `desktop/windows/input.rs`.

use arena_shared::geometry::{Point, Rect};

/// Maps pixel `pos` on an axis that starts at `origin` and is `extent` pixels long
/// onto `MOUSEEVENTF_ABSOLUTE | MOUSEEVENTF_VIRTUALDESK`'s 0..=65535 range.
///
/// Windows maps a normalised value back with `value * extent / 65536` rounded down,
/// so this rounds up: then the pixel the system lands on is exactly `pos`.
pub fn normalize(pos: i32, origin: i32, extent: i32) -> i32 {
    if extent <= 1 {
        return 0;
    }
    let offset = i64::from(pos.clamp(origin, origin + extent - 1) - origin);
    let value = (offset * 65536 + i64::from(extent) - 1) / i64::from(extent);
    value.clamp(0, 65535) as i32
}

/// `p` moved inside the virtual screen `screen`.
pub fn clamp_to(p: Point, screen: Rect) -> Point {
    if screen.is_empty() {
        return p;
    }
    Point::new(p.x.clamp(screen.x, screen.right() - 1), p.y.clamp(screen.y, screen.bottom() - 1))
}

/// A wheel delta as `MOUSEINPUT::mouseData` carries it (a signed value in a `u32`).
pub fn wheel_data(delta: i32) -> u32 {
    delta as u32
}

/// pyautogui's `MINIMUM_DURATION`: a move asked to take less is made at once.
pub const MINIMUM_DURATION_MS: u64 = 100;
/// pyautogui's `MINIMUM_SLEEP`: the shortest pause between two steps of a move.
pub const MINIMUM_SLEEP_MS: u64 = 50;

/// The points a move from `start` to `to` passes through over `duration_ms`, with
/// the pause after each, as pyautogui's `_mouseMoveDrag` spreads a move: one step a
/// pixel along the longer axis, fewer when that would make the pauses shorter than
/// [`MINIMUM_SLEEP_MS`], on a straight line (`linear` tween), ending exactly at `to`.
/// Under [`MINIMUM_DURATION_MS`] it is the target alone.
pub fn drag_path(start: Point, to: Point, duration_ms: u64) -> Vec<(Point, u64)> {
    if duration_ms <= MINIMUM_DURATION_MS {
        return vec![(to, 0)];
    }
    let (dx, dy) = (i64::from(to.x) - i64::from(start.x), i64::from(to.y) - i64::from(start.y));
    let mut steps = u64::try_from(dx.abs().max(dy.abs())).unwrap_or(u64::MAX).max(1);
    if duration_ms / steps < MINIMUM_SLEEP_MS {
        steps = (duration_ms / MINIMUM_SLEEP_MS).max(1);
    }
    let pause = duration_ms / steps;
    let mut path: Vec<(Point, u64)> = (0..steps)
        .map(|n| {
            let at = |from: i32, delta: i64| {
                let moved =
                    i64::from(from) + delta * i64::try_from(n).unwrap_or(i64::MAX) / i64::try_from(steps).unwrap_or(1);
                i32::try_from(moved).unwrap_or(from)
            };
            (Point::new(at(start.x, dx), at(start.y, dy)), pause)
        })
        .collect();
    path.push((to, 0));
    path
}

#[cfg(test)]
mod tests {
    use super::*;

    /// How Windows turns a normalised value back into a pixel.
    fn windows_pixel(value: i32, origin: i32, extent: i32) -> i32 {
        origin + ((i64::from(value) * i64::from(extent)) >> 16) as i32
    }

    #[test]
    fn every_pixel_round_trips_through_normalisation() {
        for (origin, extent) in [(0, 1440), (0, 900), (-1920, 3360), (0, 1), (0, 3840), (0, 7)] {
            for pos in origin..origin + extent {
                let value = normalize(pos, origin, extent);
                assert!((0..=65535).contains(&value));
                assert_eq!(windows_pixel(value, origin, extent), pos, "pos {pos} origin {origin} extent {extent}");
            }
        }
    }

    #[test]
    fn positions_outside_are_clamped() {
        assert_eq!(normalize(-5, 0, 100), 0);
        assert_eq!(windows_pixel(normalize(500, 0, 100), 0, 100), 99);
        let screen = Rect::new(0, 0, 1440, 900);
        assert_eq!(clamp_to(Point::new(-3, 2000), screen), Point::new(0, 899));
        assert_eq!(clamp_to(Point::new(10, 20), screen), Point::new(10, 20));
    }

    #[test]
    fn wheel_deltas_keep_their_sign_bits() {
        assert_eq!(wheel_data(120), 120);
        assert_eq!(wheel_data(-400) as i32, -400);
    }

    #[test]
    fn drags_are_spread_over_their_duration_as_pyautogui_spreads_them() {
        let (a, b) = (Point::new(100, 100), Point::new(400, 200));
        // Short: at once.
        assert_eq!(drag_path(a, b, 100), vec![(b, 0)]);
        // One second over 300 px: a step a pixel would pause 3 ms, under 50 ms, so 20 steps of 50 ms.
        let path = drag_path(a, b, 1000);
        assert_eq!(path.len(), 21);
        assert_eq!(path[0], (a, 50));
        assert_eq!(path[10], (Point::new(250, 150), 50));
        assert_eq!(path.last(), Some(&(b, 0)));
        assert_eq!(path.iter().map(|(_, ms)| ms).sum::<u64>(), 1000);
        // Long and short distance: a step a pixel.
        let path = drag_path(a, Point::new(104, 100), 1000);
        assert_eq!(path.iter().map(|(p, _)| p.x).collect::<Vec<_>>(), [100, 101, 102, 103, 104]);
        assert_eq!(path[0].1, 250);
        // No distance: one step, then the target.
        assert_eq!(drag_path(a, a, 500), vec![(a, 500), (a, 0)]);
    }
}
