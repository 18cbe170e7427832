//! Tesseract OCR for the `oss` proposal, run as upstream's `TesseractOCR` runs
//! it through pytesseract's `image_to_data`: the `tesseract` program on an RGB
//! PNG with `--psm 11 --oem 3` (sparse text, the default engine) and the `tsv`
//! output, read from its standard output.
//!
//! The TSV is read as pytesseract's dictionary output reads it (numbers through
//! `int(float(v))`, the text column as it is), and, as upstream's
//! `_parse_raw_ocr_data`, every row whose confidence is not -1 becomes one
//! entity: with Tesseract that is every word (level 5) and nothing else, so
//! entities are words, not lines. Words are not filtered by confidence, and an
//! empty word is kept. The entity is of type `text`, its box the word's.

use std::path::Path;
use std::process::Stdio;
use std::time::Duration;

use arena_shared::geometry::Rect;

use super::{ProposedEntity, SomError};

/// The program looked up on `PATH` by default.
pub const DEFAULT_PROGRAM: &str = "tesseract";

/// Upstream's `config='--psm 11 --oem 3'`.
pub const CONFIG: [&str; 4] = ["--psm", "11", "--oem", "3"];

/// The type upstream gives OCR entities.
pub const OCR_KIND: &str = "text";

/// The command line pytesseract builds for `image_to_data`, with the output sent to standard output.
pub fn command_args(image: &Path) -> Vec<std::ffi::OsString> {
    let mut args: Vec<std::ffi::OsString> = vec![image.as_os_str().to_owned(), "stdout".into()];
    args.extend(CONFIG.iter().map(Into::into));
    args.push("tsv".into());
    args
}

/// pytesseract's `int(float(v))` for a number column; `None` where Python would keep the string.
fn py_int(v: &str) -> Option<i64> {
    let f: f64 = v.trim().parse().ok()?;
    f.is_finite().then(|| f.trunc() as i64)
}

/// Reads Tesseract's TSV into entities (the module doc's rules). Rows with too
/// few columns are skipped, except that a last row missing only its text has
/// an empty text, as pytesseract pads it.
pub fn parse_tsv(tsv: &str) -> Vec<ProposedEntity> {
    let mut rows = tsv.trim().split('\n').map(|l| l.strip_suffix('\r').unwrap_or(l).split('\t').collect::<Vec<_>>());
    let Some(header) = rows.next() else { return Vec::new() };
    let col = |name: &str| header.iter().position(|h| *h == name);
    let (Some(left), Some(top), Some(width), Some(height), Some(conf), Some(text)) =
        (col("left"), col("top"), col("width"), col("height"), col("conf"), col("text"))
    else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for mut row in rows {
        if row.len() + 1 == header.len() {
            row.push("");
        }
        if row.len() < header.len() {
            continue;
        }
        // A confidence that is not a number stays a string in pytesseract, and a string is not -1.
        if py_int(row[conf]) == Some(-1) {
            continue;
        }
        let num = |i: usize| py_int(row[i]).and_then(|v| i32::try_from(v).ok());
        let (Some(x), Some(y), Some(w), Some(h)) = (num(left), num(top), num(width), num(height)) else {
            continue;
        };
        out.push(ProposedEntity::new(OCR_KIND, Rect::new(x, y, w, h), Some(row[text].to_owned())));
    }
    out
}

/// Runs Tesseract on the screenshot's pixels (written to a PNG file, the edge
/// where they leave the host) and returns its words as entities, in the image's pixels.
///
/// # Errors
///
/// [`SomError::Ocr`] when the program is missing (the message says how to
/// install it), fails, or outlives `timeout`.
pub async fn recognise(
    program: &str,
    screenshot: &image::RgbaImage,
    timeout: Duration,
) -> Result<Vec<ProposedEntity>, SomError> {
    // Upstream's ScreenParser converts the screenshot to RGB before OCR: the colours
    // are kept and the image made opaque, then encoded by the host's one PNG encoder.
    let mut opaque = screenshot.clone();
    opaque.pixels_mut().for_each(|px| px.0[3] = 255);
    let png = arena_client::frame::encode_png(&opaque);
    let file = tempfile::Builder::new()
        .prefix("arena-ocr-")
        .suffix(".png")
        .tempfile()
        .map_err(|e| SomError::Ocr(format!("cannot create the image file for Tesseract: {e}")))?;
    std::fs::write(file.path(), &png)
        .map_err(|e| SomError::Ocr(format!("cannot write the image file for Tesseract: {e}")))?;
    let child = tokio::process::Command::new(program)
        .args(command_args(file.path()))
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .kill_on_drop(true)
        .spawn()
        .map_err(|e| {
            if e.kind() == std::io::ErrorKind::NotFound {
                SomError::Ocr(format!(
                    "the Tesseract program `{program}` was not found: install Tesseract OCR (Debian and Ubuntu: \
                     apt-get install tesseract-ocr tesseract-ocr-eng) or choose another --som-origin"
                ))
            } else {
                SomError::Ocr(format!("cannot start `{program}`: {e}"))
            }
        })?;
    let output = tokio::time::timeout(timeout, child.wait_with_output())
        .await
        .map_err(|_| SomError::Ocr(format!("`{program}` gave no answer within {} s", timeout.as_secs())))?
        .map_err(|e| SomError::Ocr(format!("`{program}` failed: {e}")))?;
    if !output.status.success() {
        let stderr = String::from_utf8_lossy(&output.stderr);
        return Err(SomError::Ocr(format!("`{program}` exited with {}: {}", output.status, stderr.trim())));
    }
    Ok(parse_tsv(&String::from_utf8_lossy(&output.stdout)))
}
