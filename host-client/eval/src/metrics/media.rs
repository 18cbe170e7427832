//! Metrics of upstream's `metrics/vlc.py` and kin: VLC settings in `vlcrc`,
//! image similarity (SSIM), audio similarity (MFCC + DTW, `media_audio.rs`),
//! video comparison (perceptual hashes of frames, `media_video.rs`), and
//! archive comparison (zip, and 7z with an optional password).
//! `check_json_keybindings` lives in `vscode.rs` and is registered here.
//!
//! Every metric reads host files only. A file that cannot be read or parsed
//! is a [`MetricError`] (scored 0 with the reason), never a panic.

#[path = "media_audio.rs"]
mod audio;
#[path = "media_video.rs"]
mod video;

#[cfg(test)]
#[path = "media_tests.rs"]
mod media_tests;

use std::collections::BTreeMap;
use std::io::{Cursor, Read};
use std::path::Path;

use serde_json::Value;

use super::{file_of, score, MetricError, MetricFn, MetricInput};
use crate::value::Fetched;

/// The metric of this family named `name`, if implemented.
pub(super) fn lookup(name: &str) -> Option<MetricFn> {
    let f: MetricFn = match name {
        "compare_images" => compare_images,
        "compare_audios" => audio::compare_audios,
        "compare_videos" => video::compare_videos,
        "compare_zip_files" => compare_zip_files,
        "check_qt_max_volume" => check_qt_max_volume,
        "check_qt_slider_colours" => check_qt_slider_colours,
        "check_qt_bgcone" => check_qt_bgcone,
        "check_qt_minimal_view" => check_qt_minimal_view,
        "check_qt_video_resize" => check_qt_video_resize,
        "is_vlc_recordings_folder" => is_vlc_recordings_folder,
        "check_global_key_play_pause" => check_global_key_play_pause,
        "check_one_instance_when_started_from_file" => check_one_instance_when_started_from_file,
        "check_json_keybindings" => super::vscode::check_json_keybindings,
        _ => return None,
    };
    Some(f)
}

fn read_bytes(path: &Path) -> Result<Vec<u8>, MetricError> {
    std::fs::read(path).map_err(|source| MetricError::Io { path: path.to_owned(), source })
}

fn parse_error(path: &Path, message: impl Into<String>) -> MetricError {
    MetricError::Parse { what: path.display().to_string(), message: message.into() }
}

/// Upstream's `if not path: return 0` guard for a result getter that found no file.
fn missing(value: &Fetched) -> bool {
    value.is_none()
}

// ----- VLC settings (vlcrc) -----

/// The `vlcrc` text, decoded as upstream does (`.decode('utf-8')`, which fails on other bytes).
fn vlcrc_text(input: &MetricInput) -> Result<String, MetricError> {
    let path = file_of(&input.result, "result")?;
    let bytes = read_bytes(path)?;
    String::from_utf8(bytes).map_err(|err| parse_error(path, format!("not UTF-8 text: {err}")))
}

/// Upstream's `if isinstance(expected, int): expected = str(expected)`: an
/// integer (or bool) becomes its Python `str`, a string stays; anything else
/// never equals a setting's text, so it is `None`.
fn setting_text(value: &Value) -> Option<String> {
    match value {
        Value::String(s) => Some(s.clone()),
        Value::Bool(b) => Some(if *b { "True" } else { "False" }.into()),
        Value::Number(n) if n.is_i64() || n.is_u64() => Some(n.to_string()),
        _ => None,
    }
}

/// The value of the last line containing `needle` (`line.split('=')[-1].strip()`),
/// or `default`. Upstream looks at every line, commented ones included: VLC
/// writes a default as `#qt-max-volume=125`, which reads as that default.
fn last_setting(text: &str, needle: &str, default: &str) -> String {
    text.split('\n')
        .rfind(|line| line.contains(needle))
        .map_or_else(|| default.to_owned(), |line| line.rsplit('=').next().unwrap_or("").trim().to_owned())
}

/// The shared shape of upstream's `check_qt_*` rules: the setting (or its
/// default) must equal `rules[rule_key]` as text.
fn vlc_setting_equals(input: &MetricInput, rule_key: &str, needle: &str, default: &str) -> Result<f64, MetricError> {
    let expected = setting_text(input.rule(rule_key)?);
    let text = vlcrc_text(input)?;
    Ok(score(expected.is_some_and(|want| last_setting(&text, needle, default) == want)))
}

/// `check_qt_max_volume`: `qt-max-volume` (default 125) equals `rules["expected_qt_max_volume"]`.
fn check_qt_max_volume(input: &MetricInput) -> Result<f64, MetricError> {
    vlc_setting_equals(input, "expected_qt_max_volume", "qt-max-volume=", "125")
}

/// `check_qt_bgcone`: `qt-bgcone` (default 1) equals `rules["expected_qt_bgcone"]`.
fn check_qt_bgcone(input: &MetricInput) -> Result<f64, MetricError> {
    vlc_setting_equals(input, "expected_qt_bgcone", "qt-bgcone=", "1")
}

/// `check_qt_minimal_view`: `qt-minimal-view` (default 0) equals `rules["expected_qt_minimal_view"]`.
fn check_qt_minimal_view(input: &MetricInput) -> Result<f64, MetricError> {
    vlc_setting_equals(input, "expected_qt_minimal_view", "qt-minimal-view=", "0")
}

/// `check_qt_video_resize`: `qt-video-autoresize` equals `rules["qt-video-autoresize"]`.
/// With no such line upstream starts from "0" (not VLC's own default of 1).
fn check_qt_video_resize(input: &MetricInput) -> Result<f64, MetricError> {
    vlc_setting_equals(input, "qt-video-autoresize", "qt-video-autoresize=", "0")
}

/// `check_one_instance_when_started_from_file`: the setting (default 1)
/// equals `rules["expected_one_instance_when_started_from_file"]`.
fn check_one_instance_when_started_from_file(input: &MetricInput) -> Result<f64, MetricError> {
    vlc_setting_equals(
        input,
        "expected_one_instance_when_started_from_file",
        "one-instance-when-started-from-file=",
        "1",
    )
}

/// `check_global_key_play_pause`: a global play/pause hot key is set ("1")
/// when the last `global-key-play-pause=` line has a value, else "0"; that
/// must equal `rules["expected_global_key_play_pause"]`.
fn check_global_key_play_pause(input: &MetricInput) -> Result<f64, MetricError> {
    let expected = setting_text(input.rule("expected_global_key_play_pause")?);
    let text = vlcrc_text(input)?;
    let value = text.split('\n').rfind(|line| line.contains("global-key-play-pause=")).map_or("0", |line| {
        if line.rsplit('=').next().unwrap_or("").trim().is_empty() {
            "0"
        } else {
            "1"
        }
    });
    Ok(score(expected.is_some_and(|want| want == value)))
}

/// `is_vlc_recordings_folder`: the first uncommented, non-blank line naming
/// `input-record-path` must hold `rules["recording_file_path"]`; no such line scores 0.
fn is_vlc_recordings_folder(input: &MetricInput) -> Result<f64, MetricError> {
    let expected = input.rule("recording_file_path")?;
    let text = vlcrc_text(input)?;
    let line = text
        .split('\n')
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .find(|l| l.contains("input-record-path"));
    Ok(match line {
        Some(line) => score(expected.as_str() == Some(line.rsplit('=').next().unwrap_or("").trim())),
        None => 0.0,
    })
}

/// VLC's default slider colours (`qt-slider-colours`).
const DEFAULT_SLIDER_COLOURS: &str = "153;210;153;20;210;20;255;199;15;245;39;29";

/// `check_qt_slider_colours`: with `rules["type"] == "match"`, the colours
/// text equals `rules["expected_qt_slider_colours"]`; with `"blackish"`, every
/// complete RGB triple has all channels below 100 (a list that does not parse
/// as integers scores 0, as upstream's `except` does). Another type scores 0.
fn check_qt_slider_colours(input: &MetricInput) -> Result<f64, MetricError> {
    let kind = input.rule("type")?;
    let text = vlcrc_text(input)?;
    let colours = last_setting(&text, "qt-slider-colours", DEFAULT_SLIDER_COLOURS);
    match kind.as_str() {
        Some("match") => {
            let expected = input.rule("expected_qt_slider_colours")?;
            Ok(score(expected.as_str() == Some(colours.as_str())))
        }
        Some("blackish") => {
            let Ok(values) = colours.split(';').map(|v| v.trim().parse::<i64>()).collect::<Result<Vec<_>, _>>() else {
                return Ok(0.0);
            };
            Ok(score(values.chunks_exact(3).all(|rgb| rgb.iter().all(|v| *v < 100))))
        }
        _ => Ok(0.0),
    }
}

// ----- images -----

/// `compare_images(result, expected, reference_base_result=None)`: the SSIM
/// of the two images in grayscale, both resized (Lanczos) to the smaller size
/// (Python's tuple `min`: the narrower, then the shorter). With
/// `reference_base_result` `b`, scores `(ssim - b) / (1 - b)` when
/// `ssim >= b + 0.01`, else 0. A missing result scores 0.
fn compare_images(input: &MetricInput) -> Result<f64, MetricError> {
    let expected = input.expected()?;
    if missing(&input.result) || missing(expected) {
        return Ok(0.0);
    }
    let a = gray_image(file_of(&input.result, "result")?)?;
    let b = gray_image(file_of(expected, "expected")?)?;
    let size = std::cmp::min(a.dimensions(), b.dimensions());
    let resize = |img: image::GrayImage| {
        if img.dimensions() == size {
            img
        } else {
            image::imageops::resize(&img, size.0, size.1, image::imageops::FilterType::Lanczos3)
        }
    };
    let ssim = ssim(&resize(a), &resize(b)).map_err(MetricError::BadInput)?;
    match input.options.get("reference_base_result").and_then(Value::as_f64) {
        Some(base) if ssim >= base + 0.01 => Ok((ssim - base) / (1.0 - base)),
        Some(_) => Ok(0.0),
        None => Ok(ssim),
    }
}

/// An image in grayscale as PIL's `convert('L')` makes it (ITU-R 601 weights,
/// alpha dropped).
fn gray_image(path: &Path) -> Result<image::GrayImage, MetricError> {
    let bytes = read_bytes(path)?;
    // The host's one decoder (with its size and memory limits).
    let rgba =
        arena_shared::fastimg::decode_rgba(&bytes).map_err(|err| parse_error(path, format!("not an image: {err}")))?;
    let rgb = image::DynamicImage::ImageRgba8(rgba).to_rgb8();
    Ok(image::GrayImage::from_fn(rgb.width(), rgb.height(), |x, y| {
        let [r, g, b] = rgb.get_pixel(x, y).0.map(u32::from);
        // PIL's fixed-point L = R*299/1000 + G*587/1000 + B*114/1000, rounded.
        image::Luma([((r * 19_595 + g * 38_470 + b * 7_471 + 0x8000) >> 16) as u8])
    }))
}

/// scikit-image's `structural_similarity` with its defaults for 8-bit images:
/// a 7×7 uniform window, `K1 = 0.01`, `K2 = 0.03`, data range 255, sample
/// covariances (`N / (N - 1)`), and the mean over the pixels whose window lies
/// inside the image (the border of 3 pixels is cropped, as skimage does).
///
/// # Errors
///
/// A message when either side is smaller than the window, as skimage raises.
pub(crate) fn ssim(a: &image::GrayImage, b: &image::GrayImage) -> Result<f64, String> {
    const WIN: usize = 7;
    let (w, h) = (a.width() as usize, a.height() as usize);
    if (w, h) != (b.width() as usize, b.height() as usize) {
        return Err("the images differ in size".into());
    }
    if w < WIN || h < WIN {
        return Err(format!("the images are {w}x{h}, smaller than the 7x7 SSIM window"));
    }
    // Summed-area tables of x, y, x², y² and xy.
    let stride = w + 1;
    let mut tables = vec![[0f64; 5]; stride * (h + 1)];
    for y in 0..h {
        let mut row = [0f64; 5];
        for x in 0..w {
            let p = f64::from(a.get_pixel(x as u32, y as u32).0[0]);
            let q = f64::from(b.get_pixel(x as u32, y as u32).0[0]);
            for (acc, v) in row.iter_mut().zip([p, q, p * p, q * q, p * q]) {
                *acc += v;
            }
            let above = tables[y * stride + x + 1];
            let cell = &mut tables[(y + 1) * stride + x + 1];
            for k in 0..5 {
                cell[k] = above[k] + row[k];
            }
        }
    }
    let n = (WIN * WIN) as f64;
    let cov_norm = n / (n - 1.0);
    let (c1, c2) = ((0.01 * 255.0f64).powi(2), (0.03 * 255.0f64).powi(2));
    let mut total = 0.0;
    let mut count = 0usize;
    for y0 in 0..=h - WIN {
        for x0 in 0..=w - WIN {
            let (x1, y1) = (x0 + WIN, y0 + WIN);
            let mut s = [0f64; 5];
            for (k, slot) in s.iter_mut().enumerate() {
                *slot = tables[y1 * stride + x1][k] - tables[y0 * stride + x1][k] - tables[y1 * stride + x0][k]
                    + tables[y0 * stride + x0][k];
            }
            let (ux, uy) = (s[0] / n, s[1] / n);
            let vx = cov_norm * (s[2] / n - ux * ux);
            let vy = cov_norm * (s[3] / n - uy * uy);
            let vxy = cov_norm * (s[4] / n - ux * uy);
            total += ((2.0 * ux * uy + c1) * (2.0 * vxy + c2)) / ((ux * ux + uy * uy + c1) * (vx + vy + c2));
            count += 1;
        }
    }
    Ok(total / count as f64)
}

// ----- archives -----

/// `compare_zip_files(result, expected)`: 1 when both archives hold the same
/// set of names and every entry matches: a `.pdf` entry (any case) by its
/// extracted text, whose `difflib.SequenceMatcher` ratio must reach
/// [`PDF_TEXT_THRESHOLD`], any other entry by its bytes. A missing result
/// scores 0; a file that is not an archive, or a PDF entry that cannot be
/// read, is an error (upstream raises). Besides zip, 7z archives are read too
/// (with `options["password"]` when encrypted), under the same rule.
fn compare_zip_files(input: &MetricInput) -> Result<f64, MetricError> {
    let expected = input.expected()?;
    if missing(&input.result) {
        return Ok(0.0);
    }
    let password = input.options.get("password").and_then(Value::as_str);
    let actual = archive_entries(file_of(&input.result, "result")?, password)?;
    let wanted = archive_entries(file_of(expected, "expected")?, password)?;
    if !actual.keys().eq(wanted.keys()) {
        return Ok(0.0);
    }
    for ((name, a), b) in actual.iter().zip(wanted.values()) {
        let same = if name.to_lowercase().ends_with(".pdf") {
            let text_a = super::office::pdf_text_of_bytes(a, &format!("the result's entry {name}"))?;
            let text_b = super::office::pdf_text_of_bytes(b, &format!("the expected entry {name}"))?;
            arena_script::sequence_ratio(&text_a, &text_b) >= PDF_TEXT_THRESHOLD
        } else {
            a == b
        };
        if !same {
            return Ok(0.0);
        }
    }
    Ok(1.0)
}

/// Upstream's similarity bar for the text of two PDF entries.
const PDF_TEXT_THRESHOLD: f64 = 0.95;

/// The 7z signature.
const SEVEN_ZIP_MAGIC: &[u8] = b"7z\xbc\xaf\x27\x1c";

/// Every entry of a zip or 7z archive, by name, with its bytes (directories have none).
fn archive_entries(path: &Path, password: Option<&str>) -> Result<BTreeMap<String, Vec<u8>>, MetricError> {
    let bytes = read_bytes(path)?;
    let mut entries = BTreeMap::new();
    if bytes.starts_with(SEVEN_ZIP_MAGIC) {
        let password = password.map_or_else(sevenz_rust2::Password::empty, sevenz_rust2::Password::from);
        let mut reader = sevenz_rust2::ArchiveReader::new(Cursor::new(bytes), password)
            .map_err(|err| parse_error(path, err.to_string()))?;
        reader
            .for_each_entries(|entry, data| {
                let mut content = Vec::new();
                data.read_to_end(&mut content)?;
                entries.insert(entry.name().replace('\\', "/"), content);
                Ok(true)
            })
            .map_err(|err| parse_error(path, err.to_string()))?;
        return Ok(entries);
    }
    let mut archive =
        zip::ZipArchive::new(Cursor::new(bytes)).map_err(|err| parse_error(path, format!("not a zip file: {err}")))?;
    for index in 0..archive.len() {
        let mut file = archive.by_index(index).map_err(|err| parse_error(path, err.to_string()))?;
        let mut content = Vec::new();
        file.read_to_end(&mut content).map_err(|err| parse_error(path, format!("{}: {err}", file.name())))?;
        entries.insert(file.name().to_owned(), content);
    }
    Ok(entries)
}
