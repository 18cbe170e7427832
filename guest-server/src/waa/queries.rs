//! The evaluator helper routes: `/is_details_view`, `/are_files_sorted_by_modified_time`,
//! `/check_if_timer_started`, `/check_if_world_clock_exists` (over the foreground
//! window's accessibility tree), `/is_directory_read_only_for_user`,
//! `/are_all_images_tagged` and `/library_folders` (over the file system).
//!
//! Hosts only look at the status code (200 true, 400 false), but the messages and
//! fields are upstream's. Paths are taken as given: upstream does not expand them here.

use std::path::Path;
use std::time::Duration;

use axum::extract::State;
use axum::http::StatusCode;
use serde_json::{json, Value};

use arena_shared::action::{Action, MouseButton};
use arena_shared::files::KnownFolder;
use arena_shared::observation::{A11yBackend, A11yNode, A11yTree, TreeBudget};

use crate::desktop::Desktop;
use crate::error::WaaError;
use crate::paths;
use crate::state::AppState;
use crate::waa::body::{Data, PyJson};
use crate::waa::py::{self, OsCall};
use crate::waa::{json, json_err, on_backend, on_backend_within, path_arg, WaaResult};

// ----- accessibility-tree search -----

/// The first descendant of `node` (not `node` itself), depth first in document order,
/// whose name satisfies `matches`; direct children named exactly `exact` are tried first,
/// as upstream's `find_element_by_name` does with `FindFirst` before walking.
pub(crate) fn find_element<'a>(
    node: &'a A11yNode,
    exact: Option<&str>,
    matches: &dyn Fn(&str) -> bool,
) -> Option<&'a A11yNode> {
    if let Some(exact) = exact {
        if let Some(child) = node.children.iter().find(|c| c.name == exact) {
            return Some(child);
        }
    }
    fn walk<'a>(node: &'a A11yNode, matches: &dyn Fn(&str) -> bool) -> Option<&'a A11yNode> {
        for child in &node.children {
            if matches(&child.name) {
                return Some(child);
            }
            if let Some(found) = walk(child, matches) {
                return Some(found);
            }
        }
        None
    }
    walk(node, matches)
}

/// [`find_element`] over every root of a (foreground-only) tree.
pub(crate) fn find_in_tree<'a>(
    tree: &'a A11yTree,
    exact: Option<&str>,
    matches: &dyn Fn(&str) -> bool,
) -> Option<&'a A11yNode> {
    tree.windows.iter().find_map(|w| find_element(w, exact, matches))
}

/// `re.match(".*<text>.*", name)`: `.` stops at a newline, so the text must be on the first line.
pub(crate) fn first_line_contains(name: &str, text: &str) -> bool {
    name.split('\n').next().unwrap_or("").contains(text)
}

async fn foreground_tree(state: &AppState) -> Result<A11yTree, WaaError> {
    on_backend_within(state, "accessibility", state.config.a11y_timeout(), |desktop| {
        Ok(desktop.accessibility(A11yBackend::Uia, &TreeBudget::WAA, true)?)
    })
    .await
}

/// The names of the items of File Explorer's item list (the first child of the
/// "Shell Folder View" element) in the foreground window, in display order.
pub(crate) fn explorer_items(tree: &A11yTree) -> Option<Vec<String>> {
    let view = find_in_tree(tree, Some("Shell Folder View"), &|n| n == "Shell Folder View")?;
    Some(view.children.first().map(|list| list.children.iter().map(|c| c.name.clone()).collect()).unwrap_or_default())
}

pub(crate) fn guest_exists(desktop: &dyn Desktop, guest: &str) -> bool {
    desktop.map_path(guest).is_ok_and(|local| std::fs::metadata(local).is_ok())
}

fn join_str(base: &Value, name: &str) -> Result<String, WaaError> {
    match base {
        Value::String(base) => Ok(paths::join(base, name)),
        other => Err(WaaError::catch(format!(
            "join() argument must be str, bytes, or os.PathLike object, not '{}'",
            py::type_name(other)
        ))),
    }
}

/// `POST /is_details_view`: File Explorer shows column headers only in Details view.
pub(crate) async fn is_details_view(State(state): State<AppState>, PyJson(body): PyJson) -> WaaResult {
    let Some(path) = Data(&body).required("path")?.cloned() else {
        return Err(json_err(StatusCode::BAD_REQUEST, json!({"error": "path is required"})));
    };
    let tree = foreground_tree(&state).await?;
    let items = explorer_items(&tree).unwrap_or_default();
    let is_details = on_backend(&state, "is_details_view", move |desktop| {
        for name in items.iter().filter(|n| n.as_str() == "Header") {
            if !guest_exists(desktop, &join_str(&path, name)?) {
                return Ok(true);
            }
        }
        Ok(false)
    })
    .await?;
    if is_details {
        Ok(json(
            StatusCode::OK,
            json!({"status": "success", "message": "File Explorer is in Details view", "is_details_view": true}),
        ))
    } else {
        Err(json_err(
            StatusCode::BAD_REQUEST,
            json!({"status": "error", "message": "File Explorer is not in Details view", "is_details_view": false}),
        ))
    }
}

/// Whether `names` (display order) equals the names sorted by modification time,
/// either files first newest first, or folders first oldest first (upstream's two keys).
pub(crate) fn sorted_by_mtime(names: &[String], items: &[(String, i64, bool)]) -> bool {
    let mut desc = items.to_vec();
    desc.sort_by(|a, b| (a.2, -a.1, &a.0).cmp(&(b.2, -b.1, &b.0)));
    let mut asc = items.to_vec();
    asc.sort_by(|a, b| (!a.2, a.1, &a.0).cmp(&(!b.2, b.1, &b.0)));
    let names_of = |v: &[(String, i64, bool)]| v.iter().map(|i| i.0.clone()).collect::<Vec<_>>();
    names == names_of(&desc) || names == names_of(&asc)
}

/// `POST /are_files_sorted_by_modified_time`.
pub(crate) async fn are_files_sorted_by_modified_time(
    State(state): State<AppState>,
    PyJson(body): PyJson,
) -> WaaResult {
    let Some(directory) = Data(&body).required("directory")?.cloned() else {
        return Err(json_err(StatusCode::BAD_REQUEST, json!({"error": "directory is required"})));
    };
    let tree = foreground_tree(&state).await?;
    let Some(items) = explorer_items(&tree) else {
        return Err(WaaError::catch(
            "the foreground window has no \"Shell Folder View\" element (is File Explorer in front?)",
        ));
    };
    let shown = py::str_of(&directory);
    let sorted = on_backend(&state, "are_files_sorted_by_modified_time", move |desktop| {
        let mut names = Vec::new();
        let mut stats = Vec::new();
        for name in items {
            let guest = join_str(&directory, &name)?;
            let Some(meta) = desktop.map_path(&guest).ok().and_then(|local| std::fs::metadata(local).ok()) else {
                continue;
            };
            let mtime =
                meta.modified().map_err(|err| WaaError::catch(py::os_error(OsCall::Win32File, &err, &guest)))?;
            let secs = match mtime.duration_since(std::time::UNIX_EPOCH) {
                Ok(d) => d.as_secs() as i64,
                Err(before) => -(before.duration().as_secs_f64().ceil() as i64),
            };
            stats.push((name.clone(), secs, meta.is_dir()));
            names.push(name);
        }
        Ok(sorted_by_mtime(&names, &stats))
    })
    .await?;
    if sorted {
        Ok(json(
            StatusCode::OK,
            json!({"status": "success", "message": format!("{shown}: files are sorted by modified time")}),
        ))
    } else {
        Err(json_err(
            StatusCode::BAD_REQUEST,
            json!({"status": "error", "message": format!("{shown}: files are not sorted by modified time")}),
        ))
    }
}

/// Python's `int(value)` for the JSON values a task may send.
fn py_int(value: &Value) -> Result<i64, WaaError> {
    match value {
        Value::Bool(b) => Ok(i64::from(*b)),
        Value::Number(n) => Ok(n.as_i64().unwrap_or_else(|| n.as_f64().unwrap_or(0.0).trunc() as i64)),
        Value::String(s) => s
            .trim()
            .replace('_', "")
            .parse::<i64>()
            .map_err(|_| WaaError::catch(format!("invalid literal for int() with base 10: {}", py::repr_str(s)))),
        other => Err(WaaError::catch(format!(
            "int() argument must be a string, a bytes-like object or a real number, not '{}'",
            py::type_name(other)
        ))),
    }
}

/// The foreground tree, after pressing the Clock app's "Maximize Clock" button if it has one.
async fn clock_tree(state: &AppState) -> Result<A11yTree, WaaError> {
    let tree = foreground_tree(state).await?;
    let button = find_in_tree(&tree, Some("Maximize Clock"), &|n| n == "Maximize Clock").and_then(|b| b.rect);
    let Some(rect) = button else {
        return Ok(tree);
    };
    let centre = rect.center();
    on_backend(state, "maximize_clock", move |desktop| {
        Ok(desktop.perform(&Action::Click {
            x: Some(centre.x),
            y: Some(centre.y),
            button: MouseButton::Left,
            count: 1,
        })?)
    })
    .await?;
    // Upstream sleeps a second for the window to grow before it reads the tree again.
    tokio::time::sleep(Duration::from_millis(state.config.activate_settle_ms)).await;
    foreground_tree(state).await
}

/// `POST /check_if_timer_started`.
pub(crate) async fn check_if_timer_started(State(state): State<AppState>, PyJson(body): PyJson) -> WaaResult {
    let data = Data(&body);
    let mut values = Vec::new();
    for key in ["hours", "minutes", "seconds"] {
        match data.required(key)? {
            Some(v) => values.push(v.clone()),
            None => return Err(json_err(StatusCode::BAD_REQUEST, json!({"error": format!("{key} is required")}))),
        }
    }
    let mut parts = Vec::new();
    for (value, unit) in values.iter().zip(["hour", "minute", "second"]) {
        let plural = if py_int(value)? == 1 { "" } else { "s" };
        parts.push(format!("{} {unit}{plural}", py::str_of(value)));
    }
    let text = parts.join(" ");
    let tree = clock_tree(&state).await?;
    let running = find_in_tree(&tree, None, &|n| first_line_contains(n, &text))
        .and_then(|timer| find_element(timer, Some("Timer running, Pause"), &|n| n == "Timer running, Pause"))
        .is_some();
    if running {
        Ok(json(StatusCode::OK, json!({"status": "success", "message": "Timer exists"})))
    } else {
        Err(json_err(StatusCode::BAD_REQUEST, json!({"status": "error", "message": "Timer does not exist"})))
    }
}

/// `POST /check_if_world_clock_exists`.
pub(crate) async fn check_if_world_clock_exists(State(state): State<AppState>, PyJson(body): PyJson) -> WaaResult {
    let data = Data(&body);
    if !data.contains("city")? || !data.contains("country")? {
        return Err(json_err(StatusCode::BAD_REQUEST, json!({"error": "city and country are required"})));
    }
    let text = format!("{}, {}", py::str_of(data.index("city")?), py::str_of(data.index("country")?));
    let tree = clock_tree(&state).await?;
    if find_in_tree(&tree, None, &|n| first_line_contains(n, &text)).is_some() {
        Ok(json(StatusCode::OK, json!({"status": "success", "message": "World clock exists"})))
    } else {
        Err(json_err(StatusCode::BAD_REQUEST, json!({"status": "error", "message": "World clock does not exist"})))
    }
}

// ----- file-system helpers -----

const FILE_GENERIC_READ: u32 = 0x0012_0089;
const FILE_GENERIC_EXECUTE: u32 = 0x0012_00a0;
const FILE_WRITE_DATA: u32 = 0x0002;
const FILE_APPEND_DATA: u32 = 0x0004;
const FILE_WRITE_EA: u32 = 0x0010;
const FILE_WRITE_ATTRIBUTES: u32 = 0x0100;

/// Upstream's rule on the first ACE naming the user: some read or execute right, and no write right.
pub(crate) fn mask_is_read_only(mask: u32) -> bool {
    mask & (FILE_GENERIC_READ | FILE_GENERIC_EXECUTE) != 0
        && mask & (FILE_APPEND_DATA | FILE_WRITE_ATTRIBUTES | FILE_WRITE_DATA | FILE_WRITE_EA) == 0
}

/// `POST /is_directory_read_only_for_user`.
pub(crate) async fn is_directory_read_only_for_user(State(state): State<AppState>, PyJson(body): PyJson) -> WaaResult {
    let data = Data(&body);
    let Some(directory) = data.required("directory")?.cloned() else {
        return Err(json_err(StatusCode::BAD_REQUEST, json!({"error": "directory is required"})));
    };
    let Some(user) = data.required("user")?.cloned() else {
        return Err(json_err(StatusCode::BAD_REQUEST, json!({"error": "user is required"})));
    };
    let (dir, who) = (path_arg(&directory)?, path_arg(&user)?);
    let (shown_dir, shown_user) = (dir.clone(), who.clone());
    let mask =
        on_backend(&state, "directory_access_mask", move |desktop| Ok(desktop.directory_access_mask(&dir, &who)?))
            .await?;
    if mask.is_some_and(mask_is_read_only) {
        Ok(json(
            StatusCode::OK,
            json!({"status": "success", "message": format!("{shown_dir} is read-only for {shown_user}")}),
        ))
    } else {
        Err(json_err(
            StatusCode::BAD_REQUEST,
            json!({"status": "error", "message": format!("{shown_dir} is not read-only for {shown_user}")}),
        ))
    }
}

/// Python's `bytes.decode("utf-16", errors="ignore")`: a BOM picks the byte order
/// (little-endian without one), an odd last byte and unpaired surrogates are dropped.
fn decode_utf16_lossy(bytes: &[u8]) -> String {
    let (big_endian, body) = match bytes {
        [0xfe, 0xff, rest @ ..] => (true, rest),
        [0xff, 0xfe, rest @ ..] => (false, rest),
        _ => (false, bytes),
    };
    let units = body.chunks_exact(2).map(|c| {
        if big_endian {
            u16::from_be_bytes([c[0], c[1]])
        } else {
            u16::from_le_bytes([c[0], c[1]])
        }
    });
    char::decode_utf16(units).filter_map(Result::ok).collect()
}

/// The string forms of an image's EXIF values, as upstream makes them from `_getexif()`:
/// byte strings (the `XP*` tags Windows writes its tags to) decoded as UTF-16, text as
/// text, numbers and tuples of numbers joined with spaces.
pub(crate) fn exif_strings(path: &Path) -> Vec<String> {
    let Ok(file) = std::fs::File::open(path) else {
        return Vec::new();
    };
    let Ok(exif) = exif::Reader::new().read_from_container(&mut std::io::BufReader::new(file)) else {
        return Vec::new();
    };
    let join = |parts: Vec<String>| parts.join(" ");
    exif.fields()
        .map(|field| match &field.value {
            exif::Value::Byte(bytes) | exif::Value::Undefined(bytes, _) => decode_utf16_lossy(bytes),
            exif::Value::Ascii(strings) => {
                join(strings.iter().map(|s| String::from_utf8_lossy(s).into_owned()).collect())
            }
            exif::Value::Short(v) => join(v.iter().map(u16::to_string).collect()),
            exif::Value::Long(v) => join(v.iter().map(u32::to_string).collect()),
            exif::Value::SByte(v) => join(v.iter().map(i8::to_string).collect()),
            exif::Value::SShort(v) => join(v.iter().map(i16::to_string).collect()),
            exif::Value::SLong(v) => join(v.iter().map(i32::to_string).collect()),
            exif::Value::Rational(v) => join(v.iter().map(|r| py::float_repr(r.to_f64())).collect()),
            exif::Value::SRational(v) => join(v.iter().map(|r| py::float_repr(r.to_f64())).collect()),
            exif::Value::Float(v) => join(v.iter().map(|f| py::float_repr(f64::from(*f))).collect()),
            exif::Value::Double(v) => join(v.iter().map(|f| py::float_repr(*f)).collect()),
            _ => String::new(),
        })
        .collect()
}

/// `POST /are_all_images_tagged`.
pub(crate) async fn are_all_images_tagged(State(state): State<AppState>, PyJson(body): PyJson) -> WaaResult {
    let data = Data(&body);
    let Some(directory) = data.required("directory")?.cloned() else {
        return Err(json_err(StatusCode::BAD_REQUEST, json!({"error": "directory is required"})));
    };
    let Some(tag) = data.required("tag")?.cloned() else {
        return Err(json_err(StatusCode::BAD_REQUEST, json!({"error": "tag is required"})));
    };
    let dir = path_arg(&directory)?;
    let (shown_tag, shown_dir) = (py::str_of(&tag), dir.clone());
    let untagged = on_backend(&state, "are_all_images_tagged", move |desktop| {
        let listing_error = |err: std::io::Error| WaaError::catch(py::os_error(OsCall::Win32Dir, &err, &dir));
        let local = desktop.map_path(&dir).map_err(|_| listing_error(std::io::ErrorKind::NotFound.into()))?;
        let mut names: Vec<String> = std::fs::read_dir(&local)
            .map_err(listing_error)?
            .filter_map(|e| e.ok())
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        names.sort_by(|a, b| a.to_uppercase().cmp(&b.to_uppercase()).then_with(|| a.cmp(b)));
        for name in names {
            let lower = name.to_lowercase();
            if !(lower.ends_with("jpg") || lower.ends_with("jpeg") || lower.ends_with("tiff")) {
                continue;
            }
            let Value::String(tag) = &tag else {
                return Err(WaaError::catch(format!(
                    "'in <string>' requires string as left operand, not {}",
                    py::type_name(&tag)
                )));
            };
            if !exif_strings(&local.join(&name)).iter().any(|value| value.contains(tag.as_str())) {
                return Ok(Some(name));
            }
        }
        Ok(None)
    })
    .await?;
    match untagged {
        None => Ok(json(
            StatusCode::OK,
            json!({"status": "success", "message": format!("All images in {shown_dir} are tagged with {shown_tag}")}),
        )),
        Some(name) => Err(json_err(
            StatusCode::BAD_REQUEST,
            json!({"status": "error", "message": format!("{name} in {shown_dir} is not tagged with {shown_tag}")}),
        )),
    }
}

const LIBRARY_NS: &str = "http://schemas.microsoft.com/windows/2009/library";

/// Text of a `.library-ms` file: UTF-8 (with or without BOM) or UTF-16 with a BOM.
pub(crate) fn decode_xml_text(bytes: &[u8]) -> String {
    match bytes {
        [0xef, 0xbb, 0xbf, rest @ ..] => String::from_utf8_lossy(rest).into_owned(),
        [0xff, 0xfe, ..] | [0xfe, 0xff, ..] => decode_utf16_lossy(bytes),
        _ => String::from_utf8_lossy(bytes).into_owned(),
    }
}

/// The folder URLs of a Windows library description, sorted.
///
/// # Errors
///
/// The parser's message for malformed XML.
pub(crate) fn library_urls(xml: &str) -> Result<Vec<String>, String> {
    let doc = roxmltree::Document::parse(xml).map_err(|err| err.to_string())?;
    let is = |node: &roxmltree::Node<'_, '_>, name: &str| {
        node.is_element() && node.tag_name().name() == name && node.tag_name().namespace() == Some(LIBRARY_NS)
    };
    let mut urls: Vec<String> = doc
        .descendants()
        .filter(|n| is(n, "searchConnectorDescriptionList"))
        .flat_map(|list| list.children().filter(|n| is(n, "searchConnectorDescription")))
        .flat_map(|desc| desc.children().filter(|n| is(n, "simpleLocation")))
        .flat_map(|loc| loc.children().filter(|n| is(n, "url")))
        .filter_map(|url| url.text().map(str::to_owned))
        .collect();
    urls.sort();
    Ok(urls)
}

/// `POST /library_folders`.
pub(crate) async fn library_folders(State(state): State<AppState>, PyJson(body): PyJson) -> WaaResult {
    let Some(name) = Data(&body).required("library_name")?.cloned() else {
        return Err(json_err(StatusCode::BAD_REQUEST, json!({"error": "library_name is required"})));
    };
    let name = path_arg(&name)?;
    let urls = on_backend(&state, "library_folders", move |desktop| {
        let appdata = match desktop.env_var("APPDATA") {
            Some(dir) => dir,
            None => desktop.known_folder(KnownFolder::AppData)?,
        };
        let guest = paths::join(&appdata, &format!("Microsoft\\Windows\\Libraries\\{name}.library-ms"));
        let bytes = desktop.map_path(&guest).ok().and_then(|local| std::fs::read(local).ok());
        let Some(bytes) = bytes else {
            return Err(json_err(StatusCode::BAD_REQUEST, json!({"error": format!("{name} does not exist")})));
        };
        library_urls(&decode_xml_text(&bytes)).map_err(WaaError::catch)
    })
    .await?;
    Ok(json(StatusCode::OK, json!({"status": "success", "output": urls})))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mask_rule_matches_upstream() {
        let check = |mask: u32, expected: bool| assert_eq!(mask_is_read_only(mask), expected, "{mask:#x}");
        check(0x0012_00a9, true); // read and execute
        check(0x0012_0089, true); // read
        check(0x001f_01ff, false); // full control
        check(0x0013_01bf, false); // modify
        check(0, false);
        check(0x0012_0089 | FILE_WRITE_EA, false);
    }

    #[test]
    fn mtime_sorting_accepts_both_upstream_orders() {
        let items =
            vec![("b.txt".to_owned(), 30, false), ("a.txt".to_owned(), 10, false), ("dir".to_owned(), 20, true)];
        let names = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        assert!(sorted_by_mtime(&names(&["b.txt", "a.txt", "dir"]), &items));
        assert!(sorted_by_mtime(&names(&["dir", "a.txt", "b.txt"]), &items));
        assert!(!sorted_by_mtime(&names(&["a.txt", "b.txt", "dir"]), &items));
    }

    #[test]
    fn utf16_decoding_ignores_errors() {
        let mut bytes: Vec<u8> = "cat;dog\0".encode_utf16().flat_map(u16::to_le_bytes).collect();
        bytes.push(0x41);
        assert_eq!(decode_utf16_lossy(&bytes), "cat;dog\0");
        assert_eq!(decode_utf16_lossy(&[0xfe, 0xff, 0x00, 0x41, 0xd8, 0x00]), "A");
    }

    #[test]
    fn library_urls_are_read_with_the_namespace_and_sorted() {
        let xml = r#"<?xml version="1.0" encoding="UTF-8"?>
<libraryDescription xmlns="http://schemas.microsoft.com/windows/2009/library">
  <name>@shell32.dll,-34575</name>
  <searchConnectorDescriptionList>
    <searchConnectorDescription><simpleLocation><url>C:\Users\Docker\Pictures</url></simpleLocation></searchConnectorDescription>
    <searchConnectorDescription><simpleLocation><url>C:\Data\Art</url></simpleLocation></searchConnectorDescription>
  </searchConnectorDescriptionList>
  <other xmlns="urn:x"><url>ignored</url></other>
</libraryDescription>"#;
        assert_eq!(library_urls(xml).unwrap(), vec![r"C:\Data\Art".to_owned(), r"C:\Users\Docker\Pictures".to_owned()]);
        assert!(library_urls("<broken").is_err());
    }

    #[test]
    fn timer_text_matches_on_the_first_line() {
        assert!(first_line_contains("Timer 1, 0 hours 30 minutes 0 seconds", "0 hours 30 minutes 0 seconds"));
        assert!(!first_line_contains("Timer\n0 hours 30 minutes 0 seconds", "0 hours 30 minutes 0 seconds"));
    }

    #[test]
    fn python_int_conversion() {
        assert_eq!(py_int(&json!(1)).ok(), Some(1));
        assert_eq!(py_int(&json!(1.9)).ok(), Some(1));
        assert_eq!(py_int(&json!(" 1 ")).ok(), Some(1));
        assert_eq!(py_int(&json!(true)).ok(), Some(1));
        assert!(py_int(&json!("x")).is_err());
        assert!(py_int(&json!(null)).is_err());
    }
}
