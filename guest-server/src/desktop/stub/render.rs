//! Draws the stub desktop into an RGBA frame: background or wallpaper, the windows
//! bottom to top (border, title bar, caption buttons, body text), the taskbar and the cursor.
//!
//! It is a picture of the state for screenshots and agents, not a widget toolkit:
//! text uses the 8x8 `font8x8` glyphs and large areas are filled row by row.

use arena_shared::geometry::Rect;
use font8x8::UnicodeFonts;
use image::RgbaImage;

use super::window::{
    layout, Caption, Dialog, Listings, State, Window, BODY_PAD, EXPLORER_NAV, GLYPH_W, LINE_H, RUN_FIELD_LABEL,
    RUN_PROMPT, TASKBAR_H,
};

/// Desktop background when there is no wallpaper.
pub(crate) const BACKGROUND: [u8; 4] = [0, 99, 177, 255];
/// Title bar of the foreground window.
pub(crate) const TITLE_FOCUSED: [u8; 4] = [0, 84, 153, 255];
/// Title bar of the other windows.
pub(crate) const TITLE_UNFOCUSED: [u8; 4] = [222, 222, 222, 255];
const TITLE_TEXT_FOCUSED: [u8; 4] = [255, 255, 255, 255];
const TITLE_TEXT_UNFOCUSED: [u8; 4] = [90, 90, 90, 255];
const BORDER_FOCUSED: [u8; 4] = [0, 60, 120, 255];
const BORDER_UNFOCUSED: [u8; 4] = [150, 150, 150, 255];
const BODY: [u8; 4] = [255, 255, 255, 255];
const BODY_TEXT: [u8; 4] = [20, 20, 20, 255];
/// File Explorer's navigation pane.
const EXPLORER_NAV_FILL: [u8; 4] = [243, 243, 243, 255];
const SELECTION: [u8; 4] = [153, 201, 255, 255];
const CLOSE_HOVER: [u8; 4] = [196, 43, 28, 255];
/// The taskbar along the bottom of the screen.
pub(crate) const TASKBAR: [u8; 4] = [32, 32, 32, 255];
const TASKBAR_BUTTON: [u8; 4] = [64, 64, 64, 255];
const TASKBAR_ACTIVE: [u8; 4] = [96, 96, 96, 255];
const TASKBAR_TEXT: [u8; 4] = [240, 240, 240, 255];
const DESKTOP_TEXT: [u8; 4] = [255, 255, 255, 255];
/// A dialog's face, its buttons and their borders.
const DIALOG_FACE: [u8; 4] = [240, 240, 240, 255];
const DIALOG_BUTTON: [u8; 4] = [253, 253, 253, 255];
const CONTROL_BORDER: [u8; 4] = [122, 122, 122, 255];
const DEFAULT_BORDER: [u8; 4] = [0, 120, 215, 255];

/// Width of one taskbar button.
pub(crate) const TASKBAR_BUTTON_W: i32 = 160;

/// A canvas over an RGBA buffer that clips everything to its bounds.
struct Canvas<'a> {
    buf: &'a mut [u8],
    width: i32,
    height: i32,
}

impl Canvas<'_> {
    /// Fills `rect` clipped to `clip` and the canvas.
    fn fill(&mut self, rect: Rect, clip: Rect, color: [u8; 4]) {
        let bounds = Rect::new(0, 0, self.width, self.height);
        let Some(r) = intersect(rect, clip).and_then(|r| intersect(r, bounds)) else {
            return;
        };
        let row: Vec<u8> = color.repeat(r.width as usize);
        for y in r.y..r.bottom() {
            let start = ((y * self.width + r.x) * 4) as usize;
            self.buf[start..start + row.len()].copy_from_slice(&row);
        }
    }

    /// Draws the 1-pixel outline of `rect`.
    fn outline(&mut self, rect: Rect, clip: Rect, color: [u8; 4]) {
        self.fill(Rect::new(rect.x, rect.y, rect.width, 1), clip, color);
        self.fill(Rect::new(rect.x, rect.bottom() - 1, rect.width, 1), clip, color);
        self.fill(Rect::new(rect.x, rect.y, 1, rect.height), clip, color);
        self.fill(Rect::new(rect.right() - 1, rect.y, 1, rect.height), clip, color);
    }

    /// Draws `text` with its top-left at `x`, `y`, one 8x8 glyph a character, clipped to `clip`.
    /// Characters the font lacks are drawn as `?`.
    fn text(&mut self, x: i32, y: i32, text: &str, clip: Rect, color: [u8; 4]) {
        let Some(clip) = intersect(clip, Rect::new(0, 0, self.width, self.height)) else {
            return;
        };
        if y >= clip.bottom() || y + 8 <= clip.y {
            return;
        }
        let (row_from, row_to) = ((clip.y - y).max(0), (clip.bottom() - y).min(8));
        let mut gx = x;
        for c in text.chars() {
            if gx >= clip.right() {
                break;
            }
            if gx + GLYPH_W > clip.x && !c.is_whitespace() {
                let glyph = glyph(c);
                let (col_from, col_to) = ((clip.x - gx).max(0), (clip.right() - gx).min(8));
                for row in row_from..row_to {
                    let bits = glyph[row as usize];
                    if bits == 0 {
                        continue;
                    }
                    let line = ((y + row) * self.width) as usize;
                    for col in col_from..col_to {
                        if bits & (1 << col) != 0 {
                            let at = (line + (gx + col) as usize) * 4;
                            self.buf[at..at + 4].copy_from_slice(&color);
                        }
                    }
                }
            }
            gx += GLYPH_W;
        }
    }
}

fn glyph(c: char) -> [u8; 8] {
    let c = if c == '\t' { ' ' } else { c };
    font8x8::BASIC_FONTS
        .get(c)
        .or_else(|| font8x8::LATIN_FONTS.get(c))
        .or_else(|| font8x8::BASIC_FONTS.get('?'))
        .unwrap_or([0; 8])
}

/// The overlap of two rectangles, if any.
pub(crate) fn intersect(a: Rect, b: Rect) -> Option<Rect> {
    let (x0, y0) = (a.x.max(b.x), a.y.max(b.y));
    let (x1, y1) = (a.right().min(b.right()), a.bottom().min(b.bottom()));
    (x1 > x0 && y1 > y0).then(|| Rect::from_ltrb(x0, y0, x1, y1))
}

/// The taskbar buttons: one per shown-or-minimised application window, oldest first.
pub(crate) fn taskbar_buttons(state: &State) -> Vec<(u64, Rect)> {
    let (w, h) = (state.screen.0 as i32, state.screen.1 as i32);
    let mut apps: Vec<&Window> = state.windows.iter().filter(|w| !w.is_desktop && w.visible).collect();
    apps.sort_by_key(|w| w.id);
    apps.iter()
        .enumerate()
        .map(|(i, win)| {
            (
                win.id,
                Rect::new(48 + i as i32 * (TASKBAR_BUTTON_W + 4), h - TASKBAR_H + 4, TASKBAR_BUTTON_W, TASKBAR_H - 8),
            )
        })
        .take_while(|(_, r)| r.right() <= w)
        .collect()
}

/// Renders the desktop; `background` is the wallpaper already scaled to the screen, if any.
pub(crate) fn render(state: &State, background: Option<&RgbaImage>, listings: &Listings) -> RgbaImage {
    let (w, h) = state.screen;
    let raw = match background {
        Some(img) if img.width() == w && img.height() == h => img.as_raw().clone(),
        _ => BACKGROUND.repeat((w as usize) * (h as usize)),
    };
    let mut raw = raw;
    {
        let mut canvas = Canvas { buf: &mut raw, width: w as i32, height: h as i32 };
        let screen = Rect::new(0, 0, w as i32, h as i32);
        draw_icons(&mut canvas, screen, &listings.desktop);
        for window in state.windows.iter().rev().filter(|w| w.shown() && !w.is_desktop) {
            draw_window(&mut canvas, window, window.id == state.focus, screen);
            if let Some(items) = listings.folders.get(&window.id) {
                draw_explorer(&mut canvas, window, items, screen);
            }
        }
        draw_taskbar(&mut canvas, state, screen);
    }
    RgbaImage::from_raw(w, h, raw).unwrap_or_else(|| RgbaImage::new(w, h))
}

/// Desktop icons: a label per Desktop folder entry, in a column from the top-left.
fn draw_icons(canvas: &mut Canvas<'_>, screen: Rect, icons: &[String]) {
    for (i, name) in icons.iter().enumerate() {
        let y = 12 + i as i32 * 24;
        if y + 8 > screen.bottom() - TASKBAR_H {
            break;
        }
        let label: String = name.chars().take(14).collect();
        canvas.fill(Rect::new(8, y - 2, 12, 12), screen, [240, 200, 80, 255]);
        canvas.text(24, y, &label, screen, DESKTOP_TEXT);
    }
}

fn draw_window(canvas: &mut Canvas<'_>, window: &Window, focused: bool, screen: Rect) {
    let clip = intersect(window.rect, screen).unwrap_or(Rect::new(0, 0, 0, 0));
    if clip.is_empty() {
        return;
    }
    canvas.outline(window.rect, clip, if focused { BORDER_FOCUSED } else { BORDER_UNFOCUSED });
    let bar = window.title_bar();
    canvas.fill(bar, clip, if focused { TITLE_FOCUSED } else { TITLE_UNFOCUSED });
    let text_color = if focused { TITLE_TEXT_FOCUSED } else { TITLE_TEXT_UNFOCUSED };
    let captions = window.captions();
    let title_clip =
        intersect(Rect::from_ltrb(bar.x, bar.y, captions[0].1.x, bar.bottom()), clip).unwrap_or(Rect::new(0, 0, 0, 0));
    canvas.text(bar.x + 10, bar.y + (bar.height - 8) / 2, &window.title, title_clip, text_color);
    for (caption, r) in captions {
        let label = match caption {
            Caption::Minimize => "_",
            Caption::Maximize if window.maximized => "=",
            Caption::Maximize => "#",
            Caption::Close => "X",
        };
        if caption == Caption::Close && focused {
            canvas.fill(Rect::new(r.x + 8, r.y + 6, r.width - 16, r.height - 12), clip, CLOSE_HOVER);
        }
        canvas.text(r.x + (r.width - GLYPH_W) / 2, r.y + (r.height - 8) / 2, label, clip, text_color);
    }
    let body = window.body();
    if window.dialog.is_some() {
        draw_dialog(canvas, window, focused, clip);
        return;
    }
    canvas.fill(body, clip, BODY);
    let Some(buf) = &window.text else {
        return;
    };
    let inner = Rect::new(body.x + BODY_PAD, body.y + BODY_PAD, body.width - 2 * BODY_PAD, body.height - 2 * BODY_PAD);
    let Some(text_clip) = intersect(inner, clip) else {
        return;
    };
    let (cols, rows) = window.text_grid();
    let chars: Vec<char> = buf.text.chars().collect();
    for (row, line) in layout(&buf.text, cols).iter().skip(window.scroll).take(rows + 1).enumerate() {
        let y = inner.y + row as i32 * LINE_H;
        if buf.all_selected && !chars.is_empty() {
            canvas.fill(Rect::new(inner.x, y - 2, line.len.max(1) as i32 * GLYPH_W, LINE_H), text_clip, SELECTION);
        }
        let text: String = chars[line.start..line.start + line.len].iter().collect();
        canvas.text(inner.x, y, &text, text_clip, BODY_TEXT);
        if focused && !buf.all_selected && buf.caret >= line.start && buf.caret <= line.start + line.len {
            let next_starts_here =
                buf.caret == line.start + line.len && chars.get(buf.caret).is_some_and(|c| *c != '\n');
            if !next_starts_here {
                let x = inner.x + (buf.caret - line.start) as i32 * GLYPH_W;
                canvas.fill(Rect::new(x, y - 1, 1, 10), text_clip, BODY_TEXT);
            }
        }
    }
}

/// A File Explorer window's panes: the navigation entries on the left, the folder's
/// entries on the right, a row each (rows past the body are not drawn).
fn draw_explorer(canvas: &mut Canvas<'_>, window: &Window, items: &[String], screen: Rect) {
    let Some(clip) = intersect(window.rect, screen) else {
        return;
    };
    let (nav, list) = window.explorer_panes();
    canvas.fill(nav, clip, EXPLORER_NAV_FILL);
    draw_rows(canvas, nav, clip, EXPLORER_NAV.iter().copied());
    draw_rows(canvas, list, clip, items.iter().map(String::as_str));
}

/// `names` a row each down `pane` (File Explorer's rows), stopping at its bottom.
fn draw_rows<'a>(canvas: &mut Canvas<'_>, pane: Rect, clip: Rect, names: impl Iterator<Item = &'a str>) {
    let Some(pane_clip) = intersect(pane, clip) else {
        return;
    };
    for (i, name) in names.enumerate() {
        let row = Window::explorer_row(pane, i);
        if row.y > pane.bottom() {
            break;
        }
        canvas.text(row.x, row.y + (row.height - 8) / 2, name, pane_clip, BODY_TEXT);
    }
}

/// A dialog's face: its text wrapped, the Run dialog's labelled command field with the
/// caret or the selection, and its buttons (the first is the default, with a blue border).
fn draw_dialog(canvas: &mut Canvas<'_>, window: &Window, focused: bool, clip: Rect) {
    let (Some(dialog), Some(parts)) = (&window.dialog, window.dialog_parts()) else {
        return;
    };
    canvas.fill(window.body(), clip, DIALOG_FACE);
    let text = match dialog {
        Dialog::Run => RUN_PROMPT,
        Dialog::Message(message) => message.as_str(),
    };
    for (row, line) in layout(text, parts.text_cols).iter().enumerate() {
        let piece: String = text.chars().skip(line.start).take(line.len).collect();
        canvas.text(parts.text_at.x, parts.text_at.y + row as i32 * LINE_H, &piece, clip, BODY_TEXT);
    }
    if let (Some((label_at, field)), Some(buf)) = (parts.field, &window.text) {
        canvas.text(label_at.x, label_at.y, RUN_FIELD_LABEL, clip, BODY_TEXT);
        canvas.fill(field, clip, BODY);
        canvas.outline(field, clip, if focused { DEFAULT_BORDER } else { CONTROL_BORDER });
        let inner = Rect::new(field.x + 4, field.y + 1, field.width - 8, field.height - 2);
        let inner_clip = intersect(inner, clip).unwrap_or(Rect::new(0, 0, 0, 0));
        // One line that scrolls sideways to keep the caret in view.
        let cols = (inner.width / GLYPH_W).max(1) as usize;
        let first = (buf.caret + 1).saturating_sub(cols);
        let shown: String = buf.text.chars().skip(first).take(cols).collect();
        let y = field.y + (field.height - 8) / 2;
        if buf.all_selected && !buf.text.is_empty() {
            let w = shown.chars().count() as i32 * GLYPH_W;
            canvas.fill(Rect::new(inner.x, y - 2, w, LINE_H), inner_clip, SELECTION);
        }
        canvas.text(inner.x, y, &shown, inner_clip, BODY_TEXT);
        if focused && !buf.all_selected {
            let x = inner.x + (buf.caret - first) as i32 * GLYPH_W;
            canvas.fill(Rect::new(x, y - 1, 1, 10), inner_clip, BODY_TEXT);
        }
    }
    for (i, (button, r)) in parts.buttons.iter().enumerate() {
        canvas.fill(*r, clip, DIALOG_BUTTON);
        canvas.outline(*r, clip, if i == 0 { DEFAULT_BORDER } else { CONTROL_BORDER });
        let label = button.label();
        let x = r.x + (r.width - label.len() as i32 * GLYPH_W) / 2;
        canvas.text(x, r.y + (r.height - 8) / 2, label, clip, BODY_TEXT);
    }
}

fn draw_taskbar(canvas: &mut Canvas<'_>, state: &State, screen: Rect) {
    let bar = Rect::new(0, screen.bottom() - TASKBAR_H, screen.width, TASKBAR_H);
    canvas.fill(bar, screen, TASKBAR);
    // The Start button.
    canvas.fill(Rect::new(10, bar.y + 10, 20, 20), screen, [0, 120, 215, 255]);
    for (id, r) in taskbar_buttons(state) {
        let color = if id == state.focus { TASKBAR_ACTIVE } else { TASKBAR_BUTTON };
        canvas.fill(r, screen, color);
        if let Some(window) = state.window(id) {
            let clip = intersect(Rect::new(r.x + 6, r.y, r.width - 12, r.height), screen).unwrap_or(r);
            canvas.text(r.x + 6, r.y + (r.height - 8) / 2, &window.title, clip, TASKBAR_TEXT);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn intersection_clips_and_rejects_disjoint() {
        assert_eq!(intersect(Rect::new(0, 0, 10, 10), Rect::new(5, 5, 10, 10)), Some(Rect::new(5, 5, 5, 5)));
        assert_eq!(intersect(Rect::new(0, 0, 10, 10), Rect::new(10, 0, 5, 5)), None);
    }

    #[test]
    fn text_draws_glyph_pixels() {
        let mut raw = vec![0u8; 16 * 8 * 4];
        let mut canvas = Canvas { buf: &mut raw, width: 16, height: 8 };
        canvas.text(0, 0, "H", Rect::new(0, 0, 16, 8), [255, 255, 255, 255]);
        let lit = raw.chunks_exact(4).filter(|p| p[0] == 255).count();
        assert!(lit > 10, "H lit {lit} pixels");
    }
}
