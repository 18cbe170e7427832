//! The evaluator helper routes: `/is_details_view`, `/are_files_sorted_by_modified_time`,
//! `/check_if_timer_started`, `/check_if_world_clock_exists` (over the foreground
//! window's accessibility tree), `/is_directory_read_only_for_user`,
//! `/are_all_images_tagged` and `/library_folders` (over the file system).
//!
//! Hosts only look at the status code (200 true, 400 false), but the messages and
//! fields are upstream's. Paths are taken as given: upstream does not expand them here.

use std::time::Duration;

use axum::extract::State;
use axum::http::StatusCode;
use serde_json::{json, Value};

use arena_shared::action::{Action, MouseButton};
use arena_shared::files::KnownFolder;
use arena_shared::ntpath;
use arena_shared::observation::{A11yBackend, A11yTree, TreeBudget};

use crate::error::WaaError;
use crate::inspect::{
    decode_xml_text, exif_strings, explorer_items, find_element, find_in_tree, first_line_contains, guest_exists,
    library_urls, mask_is_read_only, sorted_by_mtime,
};
use crate::state::AppState;
use crate::waa::body::{Data, PyJson};
use crate::waa::py::{self, OsCall};
use crate::waa::{json, json_err, on_backend, on_backend_within, path_arg, WaaResult};

async fn foreground_tree(state: &AppState) -> Result<A11yTree, WaaError> {
    on_backend_within(state, "accessibility", state.config.a11y_timeout(), |desktop| {
        Ok(desktop.accessibility(A11yBackend::Uia, &TreeBudget::WAA, true)?)
    })
    .await
}

fn join_str(base: &Value, name: &str) -> Result<String, WaaError> {
    match base {
        Value::String(base) => Ok(ntpath::join(&[base, name])),
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
    let _input = state.input_share().await;
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
        let names = arena_shared::ntfs::list_dir(&local).map_err(listing_error)?;
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
        let guest = ntpath::join(&[&appdata, &format!("Microsoft\\Windows\\Libraries\\{name}.library-ms")]);
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
    fn python_int_conversion() {
        assert_eq!(py_int(&json!(1)).ok(), Some(1));
        assert_eq!(py_int(&json!(1.9)).ok(), Some(1));
        assert_eq!(py_int(&json!(" 1 ")).ok(), Some(1));
        assert_eq!(py_int(&json!(true)).ok(), Some(1));
        assert!(py_int(&json!("x")).is_err());
        assert!(py_int(&json!(null)).is_err());
    }
}
