//! The clipboard through arboard: Unicode text (`CF_UNICODETEXT`) and images
//! (written as `CF_DIBV5` plus PNG; read from PNG or `CF_DIBV5`, which Windows
//! synthesises from a plain `CF_DIB` such as WAA's `copy_image` puts there).
//!
//! Another process may hold the clipboard open for a moment (clipboard managers,
//! RDP, Office): every operation is retried for up to [`OPEN_WAIT`] while it is occupied.

use std::borrow::Cow;
use std::time::{Duration, Instant};

use crate::desktop::{ClipboardData, DesktopError, DesktopResult};

/// How long to keep trying while another process holds the clipboard.
const OPEN_WAIT: Duration = Duration::from_millis(1000);
const RETRY_PAUSE: Duration = Duration::from_millis(20);

fn map_err(op: &'static str, err: arboard::Error) -> DesktopError {
    match err {
        arboard::Error::ClipboardOccupied => DesktopError::Timeout { op, ms: OPEN_WAIT.as_millis() as u64 },
        other => DesktopError::Os { op, message: other.to_string() },
    }
}

/// Runs `f` on a fresh clipboard handle, retrying while the clipboard is occupied.
fn with_retry<T>(
    op: &'static str,
    mut f: impl FnMut(&mut arboard::Clipboard) -> Result<T, arboard::Error>,
) -> DesktopResult<T> {
    let started = Instant::now();
    loop {
        let attempt = arboard::Clipboard::new().and_then(|mut cb| f(&mut cb));
        match attempt {
            Err(arboard::Error::ClipboardOccupied) if started.elapsed() < OPEN_WAIT => std::thread::sleep(RETRY_PAUSE),
            other => return other.map_err(|err| map_err(op, err)),
        }
    }
}

/// What the clipboard holds: text when there is text, else an image, else nothing.
pub(super) fn get() -> DesktopResult<ClipboardData> {
    match with_retry("clipboard read", |cb| cb.get_text()) {
        Ok(text) => return Ok(ClipboardData::Text(text)),
        Err(DesktopError::Os { .. }) => {}
        Err(err) => return Err(err),
    }
    match with_retry("clipboard read", |cb| cb.get_image()) {
        Ok(img) => {
            let (w, h) = (img.width as u32, img.height as u32);
            image::RgbaImage::from_raw(w, h, img.bytes.into_owned()).map(ClipboardData::Image).ok_or_else(|| {
                DesktopError::Os {
                    op: "clipboard read",
                    message: format!("a {w}x{h} clipboard image had the wrong number of bytes"),
                }
            })
        }
        // Neither text nor an image (empty, or only formats this server does not read).
        Err(DesktopError::Os { .. }) => Ok(ClipboardData::Empty),
        Err(err) => Err(err),
    }
}

/// Replaces the clipboard's contents.
pub(super) fn set(data: &ClipboardData) -> DesktopResult<()> {
    match data {
        ClipboardData::Empty => with_retry("clipboard clear", |cb| cb.clear()),
        ClipboardData::Text(text) => with_retry("clipboard write", |cb| cb.set_text(text.as_str())),
        ClipboardData::Image(img) => with_retry("clipboard write", |cb| {
            cb.set_image(arboard::ImageData {
                width: img.width() as usize,
                height: img.height() as usize,
                bytes: Cow::Borrowed(img.as_raw()),
            })
        }),
    }
}
