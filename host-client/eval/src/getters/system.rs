//! System getters: registry-backed settings (night light, storage sense,
//! notifications, time zone, desktop background), File Explorer and Clock
//! queries, VLC's configuration, files and images in guest folders, a
//! password-protected 7z on the desktop, and the relative-date rule.
//!
//! Upstream answers these with `python -c` scripts, PowerShell one-liners and
//! bespoke WAA routes; here every question goes through the native API: known
//! folders, files, the registry, and the evaluation queries under `/v1/eval/`
//! (which reuse the guest's WAA query logic). Return values keep upstream's
//! types exactly (the string `"true"`, the bool `true`, `None`), because the
//! corpus compares them with `exact_match`.
//!
//! This module does not hold Chrome or Edge getters (`browser.rs`) nor the
//! plain file and folder checks of `file.rs` and `explorer.rs`.

use std::io::Cursor;
use std::time::{SystemTime, UNIX_EPOCH};

use arena_shared::eval::{
    DetailsViewQuery, ImagesTaggedQuery, LibraryQuery, ReadOnlyQuery, SortedByModifiedQuery, TimerQuery,
    WorldClockQuery,
};
use arena_shared::files::{FileKind, KnownFolder};
use arena_shared::registry::RegistryValue;
use serde_json::{Map, Value};

use super::explorer::known_folder;
use super::{dest_path, guest_join, pull_optional, GetterError, Params};
use crate::value::{json_kind, Fetched};
use crate::EvalContext;
use arena_client::error::ClientError;
use arena_shared::calendar::civil_from_days;

#[cfg(test)]
#[path = "system_tests.rs"]
mod system_tests;

/// A getter of this family.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SystemGetter {
    VlcConfig,
    IsFileSavedDesktop,
    CheckIfTimerStarted,
    CheckIfWorldClockExists,
    AllPngFileNames,
    AreAllImagesTagged,
    AreFilesSortedByModifiedTime,
    DesktopBackground,
    ImageDimensionMatchesInput,
    IsAllDocxInArchive,
    IsDetailsView,
    IsDirectoryReadOnlyForUser,
    IsFileDesktop,
    IsFileHidden,
    IsFilesMovedDownloads,
    IsRedCirclePresentOnCanvas,
    NightLightState,
    StorageSenseRunFrequency,
    SystemNotifications,
    SystemTimezone,
    VmLibraryFolders,
    ZippedFolderInDesktop,
    RuleRelativeTime,
}

/// Upstream names, one per variant.
const NAMES: [(&str, SystemGetter); 23] = [
    ("vlc_config", SystemGetter::VlcConfig),
    ("is_file_saved_desktop", SystemGetter::IsFileSavedDesktop),
    ("check_if_timer_started", SystemGetter::CheckIfTimerStarted),
    ("check_if_world_clock_exists", SystemGetter::CheckIfWorldClockExists),
    ("all_png_file_names", SystemGetter::AllPngFileNames),
    ("are_all_images_tagged", SystemGetter::AreAllImagesTagged),
    ("are_files_sorted_by_modified_time", SystemGetter::AreFilesSortedByModifiedTime),
    ("desktop_background", SystemGetter::DesktopBackground),
    ("image_dimension_matches_input", SystemGetter::ImageDimensionMatchesInput),
    ("is_all_docx_in_archive", SystemGetter::IsAllDocxInArchive),
    ("is_details_view", SystemGetter::IsDetailsView),
    ("is_directory_read_only_for_user", SystemGetter::IsDirectoryReadOnlyForUser),
    ("is_file_desktop", SystemGetter::IsFileDesktop),
    ("is_file_hidden", SystemGetter::IsFileHidden),
    ("is_files_moved_downloads", SystemGetter::IsFilesMovedDownloads),
    ("is_red_circle_present_on_canvas", SystemGetter::IsRedCirclePresentOnCanvas),
    ("night_light_state", SystemGetter::NightLightState),
    ("storage_sense_run_frequency", SystemGetter::StorageSenseRunFrequency),
    ("system_notifications", SystemGetter::SystemNotifications),
    ("system_timezone", SystemGetter::SystemTimezone),
    ("vm_library_folders", SystemGetter::VmLibraryFolders),
    ("zipped_folder_in_desktop", SystemGetter::ZippedFolderInDesktop),
    ("rule_relativeTime", SystemGetter::RuleRelativeTime),
];

/// The getter of this family named `name`, if implemented.
pub(super) fn lookup(name: &str) -> Option<SystemGetter> {
    super::by_name(&NAMES, name)
}

impl SystemGetter {
    /// The upstream name.
    fn name(self) -> &'static str {
        super::name_of(&NAMES, self).unwrap_or("system getter")
    }

    pub(super) async fn fetch(self, ctx: &EvalContext, params: &Map<String, Value>) -> Result<Fetched, GetterError> {
        use SystemGetter as G;
        let p = &Params::new(self.name(), params);
        match self {
            G::VlcConfig => vlc_config(ctx, p).await,
            G::IsFileSavedDesktop => is_file_saved_desktop(ctx, p).await,
            G::CheckIfTimerStarted => check_if_timer_started(ctx, p).await,
            G::CheckIfWorldClockExists => check_if_world_clock_exists(ctx, p).await,
            G::AllPngFileNames => all_png_file_names(ctx, p).await,
            G::AreAllImagesTagged => are_all_images_tagged(ctx, p).await,
            G::AreFilesSortedByModifiedTime => are_files_sorted_by_modified_time(ctx, p).await,
            G::DesktopBackground => desktop_background(ctx, p).await,
            G::ImageDimensionMatchesInput => image_dimension_matches_input(ctx, p).await,
            G::IsAllDocxInArchive => is_all_docx_in_archive(ctx, p).await,
            G::IsDetailsView => is_details_view(ctx, p).await,
            G::IsDirectoryReadOnlyForUser => is_directory_read_only_for_user(ctx, p).await,
            G::IsFileDesktop => is_file_desktop(ctx, p).await,
            G::IsFileHidden => is_file_hidden(ctx, p).await,
            G::IsFilesMovedDownloads => is_files_moved_downloads(ctx, p).await,
            G::IsRedCirclePresentOnCanvas => is_red_circle_present_on_canvas(ctx, p).await,
            G::NightLightState => night_light_state(ctx, p).await,
            G::StorageSenseRunFrequency => storage_sense_run_frequency(ctx, p).await,
            G::SystemNotifications => system_notifications(ctx, p).await,
            G::SystemTimezone => system_timezone(ctx, p).await,
            G::VmLibraryFolders => vm_library_folders(ctx, p).await,
            G::ZippedFolderInDesktop => zipped_folder_in_desktop(ctx, p).await,
            G::RuleRelativeTime => rule_relative_time(p, SystemTime::now()),
        }
    }
}

// ----- shared helpers -----

/// Upstream's lower-case string booleans (`"true"` / `"false"`).
fn text_bool(value: bool) -> Fetched {
    Fetched::Text(if value { "true" } else { "false" }.into())
}

/// Upstream's capitalised string booleans (`"True"` / `"False"`), as `str(bool)` gives them.
fn py_text_bool(value: bool) -> Fetched {
    Fetched::Text(if value { "True" } else { "False" }.into())
}

/// Python's `int(value)` of a parameter: an integer, a float (truncated), a
/// numeric string or a bool.
fn int_param(p: &Params<'_>, key: &str) -> Result<i64, GetterError> {
    let value = p.get(key)?;
    let parsed = match value {
        Value::Bool(b) => Some(i64::from(*b)),
        Value::Number(n) => n.as_i64().or_else(|| n.as_f64().filter(|f| f.is_finite()).map(|f| f.trunc() as i64)),
        Value::String(s) => s.trim().parse::<i64>().ok(),
        _ => None,
    };
    parsed.ok_or_else(|| p.bad(format!("`{key}` must be an integer, not {value}")))
}

/// A parameter that must be a non-empty string (upstream: `if not config[key]: raise`).
fn required_text<'a>(p: &Params<'a>, key: &str) -> Result<&'a str, GetterError> {
    let text = p.string(key)?;
    if text.is_empty() {
        return Err(p.bad(format!("`{key}` is required")));
    }
    Ok(text)
}

/// Text of a file as Windows programs save it: UTF-8 (a BOM is dropped) or
/// UTF-16 with a BOM (Notepad's "Unicode"); undecodable bytes are replaced.
pub(crate) fn decode_text(bytes: &[u8]) -> String {
    fn utf16(body: &[u8], big_endian: bool) -> String {
        let units = body.chunks_exact(2).map(|c| {
            if big_endian {
                u16::from_be_bytes([c[0], c[1]])
            } else {
                u16::from_le_bytes([c[0], c[1]])
            }
        });
        char::decode_utf16(units).map(|c| c.unwrap_or(char::REPLACEMENT_CHARACTER)).collect()
    }
    match bytes {
        [0xef, 0xbb, 0xbf, rest @ ..] => String::from_utf8_lossy(rest).into_owned(),
        [0xff, 0xfe, rest @ ..] => utf16(rest, false),
        [0xfe, 0xff, rest @ ..] => utf16(rest, true),
        _ => String::from_utf8_lossy(bytes).into_owned(),
    }
}

/// A registry value, or `None` when the key or value does not exist.
async fn registry_optional(
    ctx: &EvalContext,
    p: &Params<'_>,
    key: &str,
    value: &str,
) -> Result<Option<RegistryValue>, GetterError> {
    match ctx.client.registry_get(key, Some(value)).await {
        Ok(read) => Ok(Some(read.data)),
        Err(ClientError::Api { status: 404, .. }) => Ok(None),
        Err(err) => Err(p.guest(err)),
    }
}

/// A registry value as PowerShell's `Get-ItemPropertyValue` prints it, which is
/// what upstream parses: numbers in decimal, strings as they are, one line per
/// string of a multi-string and per byte of a binary value.
fn registry_text(value: &RegistryValue) -> String {
    match value {
        RegistryValue::String(s) => s.clone(),
        RegistryValue::Dword(n) => n.to_string(),
        RegistryValue::Qword(n) => n.to_string(),
        RegistryValue::MultiString(items) => items.join("\n"),
        RegistryValue::Binary(bytes) => bytes.iter().map(u8::to_string).collect::<Vec<_>>().join("\n"),
        RegistryValue::Unknown => String::new(),
    }
}

// ----- files and folders -----

/// `get_vlc_config`: VLC's `%APPDATA%\vlc\vlcrc`, saved as `dest`. A missing
/// file is an error (upstream fails writing `None`).
async fn vlc_config(ctx: &EvalContext, p: &Params<'_>) -> Result<Fetched, GetterError> {
    let local = dest_path(ctx, p, p.string("dest")?)?;
    let appdata = known_folder(ctx, p, KnownFolder::AppData).await?;
    let path = guest_join(&appdata, r"vlc\vlcrc");
    let file = ctx.client.pull_file(&path).await.map_err(|err| p.guest(err))?;
    std::fs::write(&local, &file.bytes).map_err(|err| p.io(&local, err))?;
    Ok(Fetched::File(local))
}

/// `get_is_file_saved_desktop`: `"true"` when `Desktop\<filename>` holds
/// `textcontent` (a substring; with `exact`, the whole text after newline
/// folding and stripping), `"false"` otherwise or when the file is missing.
async fn is_file_saved_desktop(ctx: &EvalContext, p: &Params<'_>) -> Result<Fetched, GetterError> {
    let name = p.string("filename")?;
    let expected = match p.get("textcontent")? {
        Value::String(s) => s.clone(),
        other => other.to_string(),
    };
    let desktop = known_folder(ctx, p, KnownFolder::Desktop).await?;
    let Some(bytes) = pull_optional(ctx, p, &guest_join(&desktop, name)).await? else {
        return Ok(text_bool(false));
    };
    let text = decode_text(&bytes);
    if p.truthy("exact") {
        let fold = |s: &str| s.replace("\r\n", "\n").replace('\r', "\n").trim().to_owned();
        return Ok(text_bool(fold(&text) == fold(&expected)));
    }
    Ok(text_bool(text.contains(&expected)))
}

/// `get_is_file_desktop`: `"true"` when `Desktop\<filename>` is a file the guest serves.
async fn is_file_desktop(ctx: &EvalContext, p: &Params<'_>) -> Result<Fetched, GetterError> {
    let name = p.string("filename")?;
    let desktop = known_folder(ctx, p, KnownFolder::Desktop).await?;
    let exists = ctx.client.exists(&guest_join(&desktop, name)).await.map_err(|err| p.guest(err))?;
    Ok(text_bool(exists.exists && exists.kind == Some(FileKind::File)))
}

/// `get_is_file_hidden`: `"true"` when the file has the hidden attribute;
/// `"false"` when it has not or does not exist.
async fn is_file_hidden(ctx: &EvalContext, p: &Params<'_>) -> Result<Fetched, GetterError> {
    let path = p.string("file_path")?;
    match ctx.client.stat(path).await {
        Ok(stat) => Ok(text_bool(stat.hidden)),
        Err(ClientError::Api { .. }) => Ok(text_bool(false)),
        Err(err) => Err(p.guest(err)),
    }
}

/// The entries of a guest folder, or `None` when the guest has no such folder.
async fn list_optional(
    ctx: &EvalContext,
    p: &Params<'_>,
    path: &str,
) -> Result<Option<Vec<arena_shared::files::DirEntry>>, GetterError> {
    match ctx.client.list_dir(path).await {
        Ok(listing) => Ok(Some(listing.entries)),
        Err(ClientError::Api { .. }) => Ok(None),
        Err(err) => Err(p.guest(err)),
    }
}

/// Python's `str.splitlines()` after universal newlines, as a set.
fn line_set(text: &str) -> std::collections::BTreeSet<String> {
    text.replace("\r\n", "\n").replace('\r', "\n").lines().map(str::to_owned).collect()
}

/// `get_all_png_file_names`: `"true"` when the lines of `file_path` are
/// exactly the names in `folder_path` ending in `.png` (any case), as sets;
/// `"false"` otherwise or when the text file is missing.
async fn all_png_file_names(ctx: &EvalContext, p: &Params<'_>) -> Result<Fetched, GetterError> {
    let file_path = p.string("file_path")?;
    let folder_path = p.string("folder_path")?;
    let Some(bytes) = pull_optional(ctx, p, file_path).await? else {
        return Ok(text_bool(false));
    };
    let listed = line_set(&decode_text(&bytes));
    let entries = ctx.client.list_dir(folder_path).await.map_err(|err| p.guest(err))?.entries;
    let pngs: std::collections::BTreeSet<String> =
        entries.into_iter().map(|e| e.name).filter(|n| n.to_lowercase().ends_with(".png")).collect();
    Ok(text_bool(listed == pngs))
}

/// `get_is_all_docx_in_archive`: `"true"` when `folder_path\Archive` exists,
/// holds at least one file and only `.docx` files (folders aside), and no
/// `.docx` file is left directly in `folder_path`.
async fn is_all_docx_in_archive(ctx: &EvalContext, p: &Params<'_>) -> Result<Fetched, GetterError> {
    let folder = p.string("folder_path")?;
    if folder.is_empty() {
        return Ok(text_bool(false));
    }
    let is_docx = |name: &str| name.to_lowercase().ends_with(".docx");
    let files = |entries: Vec<arena_shared::files::DirEntry>| {
        entries.into_iter().filter(|e| e.kind == FileKind::File).map(|e| e.name).collect::<Vec<_>>()
    };
    let Some(root) = list_optional(ctx, p, folder).await? else {
        return Ok(text_bool(false));
    };
    let Some(archive) = list_optional(ctx, p, &guest_join(folder, "Archive")).await? else {
        return Ok(text_bool(false));
    };
    let archived = files(archive);
    // Upstream splits an empty listing into `[""]`, which is not a .docx name: an empty Archive fails.
    if archived.is_empty() || !archived.iter().all(|n| is_docx(n)) {
        return Ok(text_bool(false));
    }
    Ok(text_bool(!files(root).iter().any(|n| is_docx(n))))
}

/// Every entry name under `path`, depth first, at most `MAX_TREE_ENTRIES`.
async fn tree_names(ctx: &EvalContext, p: &Params<'_>, path: &str) -> Result<Option<Vec<String>>, GetterError> {
    const MAX_TREE_ENTRIES: usize = 10_000;
    const MAX_DEPTH: usize = 16;
    let Some(top) = list_optional(ctx, p, path).await? else {
        return Ok(None);
    };
    let mut names = Vec::new();
    let mut stack: Vec<(String, arena_shared::files::DirEntry, usize)> =
        top.into_iter().map(|e| (path.to_owned(), e, 1)).collect();
    while let Some((parent, entry, depth)) = stack.pop() {
        if names.len() >= MAX_TREE_ENTRIES {
            break;
        }
        names.push(entry.name.clone());
        if entry.kind == FileKind::Dir && depth < MAX_DEPTH {
            let child = guest_join(&parent, &entry.name);
            if let Some(children) = list_optional(ctx, p, &child).await? {
                stack.extend(children.into_iter().map(|e| (child.clone(), e, depth + 1)));
            }
        }
    }
    Ok(Some(names))
}

/// `get_is_files_moved_downloads`: `"false"` while Downloads still holds both
/// names anywhere in its tree (upstream looks for them as substrings of the
/// tree's JSON, so a name containing them counts too); then `"true"` when
/// `OldDownloads\<folder_name>\<file_name>` exists, directly.
async fn is_files_moved_downloads(ctx: &EvalContext, p: &Params<'_>) -> Result<Fetched, GetterError> {
    let file_name = p.string("file_name")?;
    let folder_name = p.string("folder_name")?;
    let downloads = known_folder(ctx, p, KnownFolder::Downloads).await?;
    if let Some(names) = tree_names(ctx, p, &downloads).await? {
        let holds = |needle: &str| names.iter().any(|n| n.contains(needle));
        if holds(file_name) && holds(folder_name) {
            return Ok(text_bool(false));
        }
    }
    let home = known_folder(ctx, p, KnownFolder::Home).await?;
    let old = guest_join(&home, "OldDownloads");
    let Some(top) = list_optional(ctx, p, &old).await? else {
        return Ok(text_bool(false));
    };
    if !top.iter().any(|e| e.kind == FileKind::Dir && e.name == folder_name) {
        return Ok(text_bool(false));
    }
    let inner = list_optional(ctx, p, &guest_join(&old, folder_name)).await?.unwrap_or_default();
    Ok(text_bool(inner.iter().any(|e| e.name == file_name)))
}

// ----- images and archives -----

/// `get_image_dimension_matches_input`: whether the image at `filepath` is
/// `width` by `height` pixels; `false` when the file is missing. A file that
/// is not an image is an error, as upstream's PIL raises.
async fn image_dimension_matches_input(ctx: &EvalContext, p: &Params<'_>) -> Result<Fetched, GetterError> {
    let path = p.string("filepath")?;
    let (width, height) = (int_param(p, "width")?, int_param(p, "height")?);
    let Some(bytes) = pull_optional(ctx, p, path).await? else {
        return Ok(Fetched::Bool(false));
    };
    let (w, h) = image::ImageReader::new(Cursor::new(&bytes))
        .with_guessed_format()
        .map_err(|err| p.failed(format!("{path}: {err}")))?
        .into_dimensions()
        .map_err(|err| p.failed(format!("{path} is not an image: {err}")))?;
    Ok(Fetched::Bool(i64::from(w) == width && i64::from(h) == height))
}

/// `get_is_red_circle_present_on_canvas`: whether the screenshot at `filepath`
/// shows a red circle (see [`has_red_circle`]); `false` when the file is missing.
async fn is_red_circle_present_on_canvas(ctx: &EvalContext, p: &Params<'_>) -> Result<Fetched, GetterError> {
    let path = p.string("filepath")?;
    let Some(bytes) = pull_optional(ctx, p, path).await? else {
        return Ok(Fetched::Bool(false));
    };
    let rgba =
        arena_shared::fastimg::decode_rgba(&bytes).map_err(|err| p.failed(format!("{path} is not an image: {err}")))?;
    Ok(Fetched::Bool(has_red_circle(&image::DynamicImage::ImageRgba8(rgba).to_rgb8())))
}

/// Whether a pixel is red by OpenCV's HSV ranges (hue within 10 of 0 on the
/// 0..180 scale, saturation ≥ 120, value ≥ 70), the test upstream's Paint check uses.
fn is_red(px: &image::Rgb<u8>) -> bool {
    let [r, g, b] = px.0.map(i32::from);
    let max = r.max(g).max(b);
    let min = r.min(g).min(b);
    if max < 70 || max == 0 || max != r {
        return false;
    }
    let saturation = (max - min) * 255 / max;
    if saturation < 120 {
        return false;
    }
    // With red the largest channel, hue in degrees is 60 * (g - b) / (max - min), in [-60, 60].
    let hue_deg = 60.0 * f64::from(g - b) / f64::from(max - min);
    hue_deg.abs() <= 20.0
}

/// Whether the image holds a red circle, drawn as an outline or filled.
///
/// Upstream's helper masks red pixels and looks for a round red shape; this
/// takes each 8-connected red region of at least 60 pixels whose bounding box
/// is nearly square (aspect within 0.7..1.43, both sides ≥ 10 px) and accepts
/// it when either
/// - it is a filled disk: it covers 65–90 % of its bounding box (a disk covers
///   π/4 ≈ 78.5 %, a square 100 %, a triangle or diamond 50 %) and nearly all
///   its pixels lie inside the inscribed ellipse; or
/// - it is a ring: at least 90 % of its pixels lie near the inscribed ellipse
///   (normalised radius 0.55–1.15) and they cover at least 28 of 32 angular
///   sectors around the centre (a square outline fails the radius test at its
///   corners, an arc fails the sector test).
pub(crate) fn has_red_circle(image: &image::RgbImage) -> bool {
    const MIN_PIXELS: usize = 60;
    const MIN_SIDE: u32 = 10;
    let (width, height) = image.dimensions();
    let mut seen = vec![false; (width as usize) * (height as usize)];
    let index = |x: u32, y: u32| (y as usize) * (width as usize) + x as usize;
    for start_y in 0..height {
        for start_x in 0..width {
            if seen[index(start_x, start_y)] || !is_red(image.get_pixel(start_x, start_y)) {
                continue;
            }
            // Flood-fill one region.
            let mut region = Vec::new();
            let mut stack = vec![(start_x, start_y)];
            seen[index(start_x, start_y)] = true;
            while let Some((x, y)) = stack.pop() {
                region.push((x, y));
                for dy in -1i64..=1 {
                    for dx in -1i64..=1 {
                        let (nx, ny) = (i64::from(x) + dx, i64::from(y) + dy);
                        if nx < 0 || ny < 0 || nx >= i64::from(width) || ny >= i64::from(height) {
                            continue;
                        }
                        let (nx, ny) = (nx as u32, ny as u32);
                        if !seen[index(nx, ny)] && is_red(image.get_pixel(nx, ny)) {
                            seen[index(nx, ny)] = true;
                            stack.push((nx, ny));
                        }
                    }
                }
            }
            if region.len() >= MIN_PIXELS && region_is_circle(&region, MIN_SIDE) {
                return true;
            }
        }
    }
    false
}

fn region_is_circle(region: &[(u32, u32)], min_side: u32) -> bool {
    let (min_x, max_x) = region.iter().fold((u32::MAX, 0), |(lo, hi), &(x, _)| (lo.min(x), hi.max(x)));
    let (min_y, max_y) = region.iter().fold((u32::MAX, 0), |(lo, hi), &(_, y)| (lo.min(y), hi.max(y)));
    let (w, h) = (max_x - min_x + 1, max_y - min_y + 1);
    if w < min_side || h < min_side {
        return false;
    }
    let aspect = f64::from(w) / f64::from(h);
    if !(0.7..=1.43).contains(&aspect) {
        return false;
    }
    let (cx, cy) = (f64::from(min_x) + f64::from(w - 1) / 2.0, f64::from(min_y) + f64::from(h - 1) / 2.0);
    let (rx, ry) = (f64::from(w) / 2.0, f64::from(h) / 2.0);
    let n = region.len() as f64;
    let fill = n / (f64::from(w) * f64::from(h));
    let radius = |x: u32, y: u32| {
        let (dx, dy) = ((f64::from(x) - cx) / rx, (f64::from(y) - cy) / ry);
        (dx * dx + dy * dy).sqrt()
    };
    let inside = region.iter().filter(|&&(x, y)| radius(x, y) <= 1.08).count() as f64;
    if (0.65..=0.9).contains(&fill) && inside / n >= 0.97 {
        return true;
    }
    let near = region.iter().filter(|&&(x, y)| (0.55..=1.15).contains(&radius(x, y))).count() as f64;
    let mut sectors = [false; 32];
    for &(x, y) in region {
        let angle = (f64::from(y) - cy).atan2(f64::from(x) - cx);
        let sector = (((angle + std::f64::consts::PI) / (2.0 * std::f64::consts::PI)) * 32.0) as usize;
        sectors[sector.min(31)] = true;
    }
    fill < 0.65 && near / n >= 0.9 && sectors.iter().filter(|s| **s).count() >= 28
}

/// `get_zipped_folder_in_desktop`: `"true"` when `filename` is a 7z archive
/// that needs a password and, opened with `password`, holds the entry
/// `OldProjects/example.txt` (upstream's fixed name; `entry` overrides it).
/// A missing file, an archive without a password, or a wrong password is `"false"`.
async fn zipped_folder_in_desktop(ctx: &EvalContext, p: &Params<'_>) -> Result<Fetched, GetterError> {
    let path = p.string("filename")?;
    let password = match p.get("password")? {
        Value::String(s) => s.clone(),
        other => other.to_string(),
    };
    let entry = match p.map.get("entry") {
        Some(_) => p.string("entry")?,
        None => "OldProjects/example.txt",
    };
    let Some(bytes) = pull_optional(ctx, p, path).await? else {
        return Ok(text_bool(false));
    };
    match protected_7z_holds(&bytes, &password, entry) {
        Ok(found) => Ok(text_bool(found)),
        Err(reason) => {
            tracing::debug!(getter = p.getter, %path, %reason, "not a readable protected 7z archive");
            Ok(text_bool(false))
        }
    }
}

/// Whether a 7z archive is password-protected (py7zr's `needs_password`: an
/// encrypted header or an AES-coded block) and, decrypted with `password`,
/// holds a file named `entry` (separators compared as `/`).
///
/// # Errors
///
/// A message when the bytes are not a 7z archive or do not decrypt with the password.
pub(crate) fn protected_7z_holds(bytes: &[u8], password: &str, entry: &str) -> Result<bool, String> {
    use sevenz_rust2::{Archive, ArchiveReader, EncoderMethod, Error, Password};
    let encrypted = match Archive::read(&mut Cursor::new(bytes), &Password::empty()) {
        Ok(archive) => archive
            .blocks
            .iter()
            .any(|block| block.coders.iter().any(|coder| coder.encoder_method_id() == EncoderMethod::ID_AES256_SHA256)),
        Err(Error::PasswordRequired | Error::MaybeBadPassword(_)) => true,
        Err(err) => return Err(err.to_string()),
    };
    if !encrypted {
        return Ok(false);
    }
    let mut reader = ArchiveReader::new(Cursor::new(bytes), Password::from(password)).map_err(|err| err.to_string())?;
    let mut names = Vec::new();
    // Read every entry through, as upstream's `readall()` does, so a wrong password fails here.
    reader
        .for_each_entries(|item, data| {
            std::io::copy(data, &mut std::io::sink())?;
            if !item.is_directory() {
                names.push(item.name().replace('\\', "/"));
            }
            Ok(true)
        })
        .map_err(|err| err.to_string())?;
    let want = entry.replace('\\', "/");
    Ok(names.contains(&want))
}

// ----- File Explorer and Clock (evaluation queries) -----

/// `get_is_details_view`: `false` for an empty `folder_path`, else the guest's answer.
async fn is_details_view(ctx: &EvalContext, p: &Params<'_>) -> Result<Fetched, GetterError> {
    let folder_path = p.string("folder_path")?;
    if folder_path.is_empty() {
        return Ok(Fetched::Bool(false));
    }
    let answer = ctx
        .client
        .eval_is_details_view(&DetailsViewQuery { folder_path: folder_path.into() })
        .await
        .map_err(|err| p.guest(err))?;
    Ok(Fetched::Bool(answer.value))
}

/// `get_are_files_sorted_by_modified_time`: `false` for an empty `directory`, else the guest's answer.
async fn are_files_sorted_by_modified_time(ctx: &EvalContext, p: &Params<'_>) -> Result<Fetched, GetterError> {
    let directory = p.string("directory")?;
    if directory.is_empty() {
        return Ok(Fetched::Bool(false));
    }
    let query = SortedByModifiedQuery { directory: directory.into() };
    let answer = ctx.client.eval_files_sorted_by_modified(&query).await.map_err(|err| p.guest(err))?;
    Ok(Fetched::Bool(answer.value))
}

/// `get_check_if_timer_started`: `"True"` when the Clock app runs a timer of
/// `hours`, `minutes` and `seconds`, else `"False"`.
async fn check_if_timer_started(ctx: &EvalContext, p: &Params<'_>) -> Result<Fetched, GetterError> {
    let query = TimerQuery {
        hours: int_param(p, "hours")?,
        minutes: int_param(p, "minutes")?,
        seconds: int_param(p, "seconds")?,
    };
    let answer = ctx.client.eval_timer_started(&query).await.map_err(|err| p.guest(err))?;
    Ok(py_text_bool(answer.value))
}

/// `get_check_if_world_clock_exists`: `"True"` when the Clock app lists `"<city>, <country>"`.
async fn check_if_world_clock_exists(ctx: &EvalContext, p: &Params<'_>) -> Result<Fetched, GetterError> {
    let query = WorldClockQuery { city: p.string("city")?.into(), country: p.string("country")?.into() };
    let answer = ctx.client.eval_world_clock_exists(&query).await.map_err(|err| p.guest(err))?;
    Ok(py_text_bool(answer.value))
}

/// `get_is_directory_read_only_for_user`: both parameters are required. A
/// missing directory is `false` (upstream's route answers 400 for it).
async fn is_directory_read_only_for_user(ctx: &EvalContext, p: &Params<'_>) -> Result<Fetched, GetterError> {
    let query =
        ReadOnlyQuery { directory: required_text(p, "directory")?.into(), user: required_text(p, "user")?.into() };
    match ctx.client.eval_read_only_for_user(&query).await {
        Ok(answer) => Ok(Fetched::Bool(answer.value)),
        Err(ClientError::Api { status: 404, .. }) => Ok(Fetched::Bool(false)),
        Err(err) => Err(p.guest(err)),
    }
}

/// `get_are_all_images_tagged`: both parameters are required; a missing
/// directory is `false` (upstream's route fails listing it).
async fn are_all_images_tagged(ctx: &EvalContext, p: &Params<'_>) -> Result<Fetched, GetterError> {
    let query =
        ImagesTaggedQuery { directory: required_text(p, "directory")?.into(), tag: required_text(p, "tag")?.into() };
    match ctx.client.eval_images_tagged(&query).await {
        Ok(answer) => Ok(Fetched::Bool(answer.value)),
        Err(ClientError::Api { status: 404, .. }) => Ok(Fetched::Bool(false)),
        Err(err) => Err(p.guest(err)),
    }
}

/// `get_vm_library_folders`: the library's folders, sorted; `None` when the library does not exist.
async fn vm_library_folders(ctx: &EvalContext, p: &Params<'_>) -> Result<Fetched, GetterError> {
    let query = LibraryQuery { library_name: p.string("library_name")?.into() };
    let answer = ctx.client.eval_library_folders(&query).await.map_err(|err| p.guest(err))?;
    if !answer.exists {
        return Ok(Fetched::None);
    }
    Ok(Fetched::Json(Value::Array(answer.folders.into_iter().map(Value::String).collect())))
}

// ----- registry-backed settings -----

const NIGHT_LIGHT_KEY: &str = r"HKCU\Software\Microsoft\Windows\CurrentVersion\CloudStore\Store\DefaultAccount\Current\default$windows.data.bluelightreduction.settings\windows.data.bluelightreduction.settings";
const STORAGE_POLICY_KEY: &str =
    r"HKCU\Software\Microsoft\Windows\CurrentVersion\StorageSense\Parameters\StoragePolicy";
const PUSH_NOTIFICATIONS_KEY: &str = r"HKCU\Software\Microsoft\Windows\CurrentVersion\PushNotifications";
const DESKTOP_KEY: &str = r"HKCU\Control Panel\Desktop";
const TIME_ZONE_INFO_KEY: &str = r"HKLM\SYSTEM\CurrentControlSet\Control\TimeZoneInformation";
const TIME_ZONES_KEY: &str = r"HKLM\SOFTWARE\Microsoft\Windows NT\CurrentVersion\Time Zones";

/// `get_night_light_state`: `[true, "<start>", "<end>"]` when night light is
/// on with a schedule, `[true]` when on without one, `false` when off.
async fn night_light_state(ctx: &EvalContext, p: &Params<'_>) -> Result<Fetched, GetterError> {
    let data = registry_optional(ctx, p, NIGHT_LIGHT_KEY, "Data").await?;
    let bytes = match data {
        Some(RegistryValue::Binary(bytes)) => bytes,
        Some(other) => return Err(p.failed(format!("the night light Data value is not binary: {other:?}"))),
        None => return Err(p.failed("the guest has no night light settings (Data value missing)")),
    };
    decode_night_light(&bytes)
        .map(Fetched::Json)
        .ok_or_else(|| p.failed(format!("the night light Data value is too short ({} bytes)", bytes.len())))
}

/// Upstream's decoding of the blue-light-reduction blob: byte 24 is 1 when
/// night light is on; byte 28 is the start hour (202 when no schedule is set);
/// byte 29 is non-zero when a start minute follows in byte 30, which moves the
/// end hour from byte 33 to 35; the end minute follows the same rule.
/// `None` when the blob is too short for the indices upstream reads.
pub(crate) fn decode_night_light(bytes: &[u8]) -> Option<Value> {
    let at = |i: usize| bytes.get(i).copied();
    if at(24)? != 1 {
        return Some(Value::Bool(false));
    }
    let start_hour = at(28)?;
    if start_hour == 202 {
        return Some(Value::Array(vec![Value::Bool(true)]));
    }
    let start_minute = if at(29)? != 0 { at(30)? } else { 0 };
    let end_index = if start_minute == 0 { 33 } else { 35 };
    let end_hour = at(end_index)?;
    let end_minute = if at(end_index + 1)? != 0 { at(end_index + 2)? } else { 0 };
    Some(Value::Array(vec![
        Value::Bool(true),
        Value::String(twelve_hour(start_hour, start_minute)),
        Value::String(twelve_hour(end_hour, end_minute)),
    ]))
}

/// Upstream's `generate_time`: `"07:00 PM"`; hours 0–11 are AM as they are,
/// 12 and later are PM less twelve (so noon is `"00:00 PM"`).
fn twelve_hour(hour: u8, minute: u8) -> String {
    if hour < 12 {
        format!("{hour:02}:{minute:02} AM")
    } else {
        format!("{:02}:{minute:02} PM", hour - 12)
    }
}

/// `get_storage_sense_run_frequency`: the `2048` value (days between runs) as
/// text when Storage Sense is on (`01` is 1), else `None`.
async fn storage_sense_run_frequency(ctx: &EvalContext, p: &Params<'_>) -> Result<Fetched, GetterError> {
    let enabled = registry_optional(ctx, p, STORAGE_POLICY_KEY, "01").await?;
    if enabled.as_ref().map(registry_text).as_deref() != Some("1") {
        return Ok(Fetched::None);
    }
    match registry_optional(ctx, p, STORAGE_POLICY_KEY, "2048").await? {
        Some(value) => Ok(Fetched::Text(registry_text(&value).lines().next().unwrap_or("").to_owned())),
        None => Ok(Fetched::None),
    }
}

/// `get_system_notifications`: `"True"` when notifications are turned off
/// (`ToastEnabled` is 0), `"False"` when the value is missing (on by
/// default), and `None` when it is set to anything else, as upstream falls through.
async fn system_notifications(ctx: &EvalContext, p: &Params<'_>) -> Result<Fetched, GetterError> {
    match registry_optional(ctx, p, PUSH_NOTIFICATIONS_KEY, "ToastEnabled").await? {
        None => Ok(py_text_bool(false)),
        Some(value) => {
            let text = registry_text(&value);
            if text.is_empty() {
                Ok(py_text_bool(false))
            } else if text.trim() == "0" {
                Ok(py_text_bool(true))
            } else {
                Ok(Fetched::None)
            }
        }
    }
}

/// `get_desktop_background`: `"True"` when no wallpaper image is set (a solid
/// colour: the `WallPaper` value is empty or missing), else `"False"`.
async fn desktop_background(ctx: &EvalContext, p: &Params<'_>) -> Result<Fetched, GetterError> {
    let value = registry_optional(ctx, p, DESKTOP_KEY, "WallPaper").await?;
    let path = value.as_ref().map(registry_text).unwrap_or_default();
    Ok(py_text_bool(path.replace('\n', "").is_empty()))
}

/// `get_system_timezone`: the time zone's display name, e.g.
/// `"(UTC-08:00) Pacific Time (US & Canada)"`, read where .NET's
/// `TimeZoneInfo` reads it: the zone's `Display` value under `Time Zones`.
async fn system_timezone(ctx: &EvalContext, p: &Params<'_>) -> Result<Fetched, GetterError> {
    let key_name = match registry_optional(ctx, p, TIME_ZONE_INFO_KEY, "TimeZoneKeyName").await? {
        Some(RegistryValue::String(name)) if !name.trim().is_empty() => name.trim_end_matches('\0').to_owned(),
        _ => return Err(p.failed("the guest does not name its time zone (TimeZoneKeyName)")),
    };
    match registry_optional(ctx, p, &format!(r"{TIME_ZONES_KEY}\{key_name}"), "Display").await? {
        Some(RegistryValue::String(display)) => Ok(Fetched::Text(display)),
        _ => Err(p.failed(format!("the guest has no display name for time zone {key_name}"))),
    }
}

// ----- rule_relativeTime -----

const MONTH_ABBR: [&str; 12] = ["Jan", "Feb", "Mar", "Apr", "May", "Jun", "Jul", "Aug", "Sep", "Oct", "Nov", "Dec"];
const MONTH_FULL: [&str; 12] = [
    "January",
    "February",
    "March",
    "April",
    "May",
    "June",
    "July",
    "August",
    "September",
    "October",
    "November",
    "December",
];
const WEEKDAY_ABBR: [&str; 7] = ["Mon", "Tue", "Wed", "Thu", "Fri", "Sat", "Sun"];

/// A calendar date and its weekday (Monday = 0, as Python's `weekday()`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Day {
    days: i64,
    year: i64,
    month: u32,
    day: u32,
    weekday: u32,
}

impl Day {
    fn from_days(days: i64) -> Day {
        let (year, month, day) = civil_from_days(days);
        // 1970-01-01 was a Thursday (weekday 3).
        let weekday = (days + 3).rem_euclid(7) as u32;
        Day { days, year, month, day, weekday }
    }

    fn plus(self, n: i64) -> Day {
        Day::from_days(self.days + n)
    }
}

/// Day `nth` of the month `months_later` months after `day`'s month.
fn nth_of_later_month(day: Day, months_later: i64, nth: u32) -> Day {
    let index = day.year * 12 + i64::from(day.month - 1) + months_later;
    let target = (index.div_euclid(12), index.rem_euclid(12) as u32 + 1);
    // Step from the 1st of this month a month at a time (28 days, then back to
    // the 1st); at most a few hundred days for the phrases upstream knows.
    let mut cursor = day.plus(1 - i64::from(day.day));
    while (cursor.year, cursor.month) < target {
        cursor = cursor.plus(32);
        cursor = cursor.plus(1 - i64::from(cursor.day));
    }
    cursor.plus(i64::from(nth) - 1)
}

/// The date a relative phrase of upstream's table names, from `today`.
fn resolve_relative(phrase: &str, today: Day) -> Option<Day> {
    let wd = i64::from(today.weekday);
    Some(match phrase {
        "today" => today,
        "tomorrow" => today.plus(1),
        "this Saturday" => today.plus(5 - wd),
        "this Sunday" => today.plus(6 - wd),
        "next Monday" => today.plus(7 - wd),
        "next Friday" => today.plus(if wd < 4 { 4 - wd } else { 11 - wd }),
        "5th next month" => nth_of_later_month(today, 1, 5),
        "10th next month" => nth_of_later_month(today, 1, 10),
        "11th next month" => nth_of_later_month(today, 1, 11),
        "first monday four months later" | "first monday eight months later" => {
            let later = if phrase.contains("four") { 4 } else { 8 };
            let first = nth_of_later_month(today, later, 1);
            first.plus((7 - i64::from(first.weekday)) % 7)
        }
        _ => return None,
    })
}

/// Upstream's `apply_rules_to_timeFormat`: fills the first occurrence of each placeholder.
fn fill_time_format(format: &str, day: Day) -> String {
    let month = day.month as usize - 1;
    let replacements = [
        ("{DoW}", WEEKDAY_ABBR[day.weekday as usize].to_owned()),
        ("{Month}", MONTH_ABBR[month].to_owned()),
        ("{DayD}", day.day.to_string()),
        ("{Year}", day.year.to_string()),
        ("{Month0D}", format!("{:02}", day.month)),
        ("{month}", MONTH_FULL[month].to_lowercase()),
        ("{MonthFull}", MONTH_FULL[month].to_owned()),
        ("{Day0D}", format!("{:02}", day.day)),
        ("{MonthD}", day.month.to_string()),
    ];
    let mut out = format.to_owned();
    for (placeholder, value) in replacements {
        out = out.replacen(placeholder, &value, 1);
    }
    out
}

/// `get_rule_relativeTime`: the task's `rules` with dates filled in. `rules`
/// holds `relativeTime` (`{"from": "next Monday"}`, optionally with `"to"`)
/// and `expected`, whose `time` (or, with `"to"`, `from` and `to`) are
/// formats like `"{Year}-{Month0D}-{Day0D}"`. Dates are today's in UTC, or in
/// `timezone` when it is `"UTC"`; other time zones are an error here.
fn rule_relative_time(p: &Params<'_>, now: SystemTime) -> Result<Fetched, GetterError> {
    let Value::Object(rules) = p.get("rules")? else {
        return Err(p.bad("`rules` must be a dict"));
    };
    if let Some(zone) = rules.get("timezone") {
        if zone.as_str() != Some("UTC") {
            return Err(p.bad(format!("time zone {zone} is not supported (only UTC)")));
        }
    }
    let secs = now.duration_since(UNIX_EPOCH).map_or(0, |d| d.as_secs());
    let today = Day::from_days(i64::try_from(secs / 86_400).unwrap_or(0));
    let relative = match rules.get("relativeTime") {
        Some(Value::Object(map)) => map,
        _ => return Err(p.bad("`rules.relativeTime` must be a dict")),
    };
    let phrase = |key: &str| -> Result<Day, GetterError> {
        let text = relative
            .get(key)
            .and_then(Value::as_str)
            .ok_or_else(|| p.bad(format!("`relativeTime.{key}` must be a string")))?;
        resolve_relative(text, today).ok_or_else(|| p.bad(format!("relative time {text:?} is not supported")))
    };
    let mut filled = rules.clone();
    let Some(Value::Object(expected)) = filled.get_mut("expected") else {
        return Err(p.bad("`rules.expected` must be a dict"));
    };
    let targets: Vec<(&str, Day)> = if relative.contains_key("to") {
        vec![("from", phrase("from")?), ("to", phrase("to")?)]
    } else {
        vec![("time", phrase("from")?)]
    };
    for (key, day) in targets {
        match expected.get_mut(key) {
            Some(Value::String(format)) => *format = fill_time_format(format, day),
            Some(other) => return Err(p.bad(format!("`expected.{key}` must be a string, not {}", json_kind(other)))),
            None => return Err(p.bad(format!("`expected` has no `{key}` to fill"))),
        }
    }
    Ok(Fetched::Json(Value::Object(filled)))
}
