//! Mouse arithmetic for `SendInput`: absolute coordinates normalised over the
//! virtual desktop, clamping to it, and the wheel's raw deltas.
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
}
