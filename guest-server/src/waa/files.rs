//! File transfer and file-system setup routes: `/file`, `/setup/upload`,
//! `/setup/create_folder`, `/setup/create_file`, `/setup/recycle`, `/folder_exists`,
//! `/file_exists`, `/list_directory`, `/wallpaper`, `/setup/change_wallpaper`,
//! `/setup/download_file`, `/setup/open_file` and `/setup/clear_task_files`.
//!
//! Guest paths are expanded where upstream expands them (`expandvars(expanduser(p))`),
//! mapped to local paths by the backend ([`Desktop::map_path`]) and then handled with
//! `std::fs`, on the backend pool.

use std::path::Path;
use std::time::Duration;

use axum::extract::State;
use axum::http::{header, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use serde_json::{json, Value};

use arena_shared::files::KnownFolder;
use arena_shared::ntpath;

use crate::desktop::Desktop;
use crate::error::WaaError;
use crate::state::AppState;
use crate::waa::body::{Data, FileData, PyForm, PyJson};
use crate::waa::py::{self, OsCall};
use crate::waa::{expand, json, json_err, on_backend, path_arg, text, text_err, WaaResult};
use arena_shared::cmdline::truthy;

/// Most entries `/list_directory` walks before it stops (upstream has no limit and can
/// spend minutes on `C:\`).
pub(crate) const MAX_LIST_ENTRIES: usize = 100_000;

/// Deepest directory nesting `/list_directory` descends into; a junction loop would
/// otherwise recurse until the entry cap.
const MAX_LIST_DEPTH: usize = 256;

/// Whether a local path names anything, counting links that cannot be followed
/// (app-execution aliases under `WindowsApps` exist for Python's `os.stat`).
fn exists(local: &Path) -> bool {
    std::fs::metadata(local).is_ok() || std::fs::symlink_metadata(local).is_ok()
}

// ----- /file -----

/// Werkzeug's `Content-Disposition` for `send_file(as_attachment=True)`.
fn content_disposition(name: &str) -> String {
    let is_token = |c: char| c.is_ascii_alphanumeric() || "!#$%&'*+-.^_`|~".contains(c);
    let quoted = |s: &str| {
        if !s.is_empty() && s.chars().all(is_token) {
            s.to_owned()
        } else {
            format!("\"{}\"", s.replace('\\', "\\\\").replace('"', "\\\""))
        }
    };
    if name.is_ascii() {
        return format!("attachment; filename={}", quoted(name));
    }
    let simple: String = name.chars().filter(char::is_ascii).collect();
    let mut encoded = String::new();
    for b in name.bytes() {
        if b.is_ascii_alphanumeric() || b"_.-~!#$&+^`|".contains(&b) {
            encoded.push(b as char);
        } else {
            encoded.push_str(&format!("%{b:02X}"));
        }
    }
    format!("attachment; filename={}; filename*=UTF-8''{encoded}", quoted(&simple))
}

/// The `Content-Type` Flask's `send_file` guesses from a name.
fn guess_content_type(name: &str) -> String {
    let mime = mime_guess::from_path(name).first_raw().unwrap_or("application/octet-stream");
    let wants_charset = mime.starts_with("text/")
        || mime.ends_with("+xml")
        || matches!(mime, "application/javascript" | "application/ecmascript" | "application/xml" | "application/sql");
    if wants_charset {
        format!("{mime}; charset=utf-8")
    } else {
        mime.to_owned()
    }
}

fn not_found_file() -> WaaError {
    json_err(StatusCode::NOT_FOUND, json!({"error": "File not found"}))
}

/// `POST /file`: the bytes of one file as an attachment.
pub(crate) async fn file(State(state): State<AppState>, form: PyForm) -> WaaResult {
    let Some(raw) = form.field("file_path").map(str::to_owned) else {
        return Err(json_err(StatusCode::BAD_REQUEST, json!({"error": "file_path is required"})));
    };
    on_backend(&state, "file", move |desktop| {
        let path = expand(desktop, &raw);
        // An unmappable (relative or foreign) path names nothing this server can send.
        let local = desktop.map_path(&path).map_err(|_| not_found_file())?;
        let read_error = |err: std::io::Error| match err.kind() {
            std::io::ErrorKind::NotFound | std::io::ErrorKind::NotADirectory => not_found_file(),
            _ => WaaError::catch(py::os_error(OsCall::Open, &err, &path)),
        };
        let meta = std::fs::metadata(&local).map_err(read_error)?;
        if meta.is_dir() {
            return Err(WaaError::catch(py::os_error(
                OsCall::Open,
                &std::io::ErrorKind::PermissionDenied.into(),
                &path,
            )));
        }
        // Sent from disk as it is read (Flask's send_file streams too): a large file
        // costs a chunk of memory, not its size.
        let file = std::fs::File::open(&local).map_err(read_error)?;
        let body = axum::body::Body::from_stream(tokio_util::io::ReaderStream::with_capacity(
            tokio::fs::File::from_std(file),
            256 << 10,
        ));
        let name = ntpath::basename(&path);
        let mut res = body.into_response();
        let headers = res.headers_mut();
        headers.insert(header::CONTENT_LENGTH, HeaderValue::from(meta.len()));
        if let Ok(v) = HeaderValue::from_str(&guess_content_type(name)) {
            headers.insert(header::CONTENT_TYPE, v);
        }
        if let Ok(v) = HeaderValue::from_str(&content_disposition(name)) {
            headers.insert(header::CONTENT_DISPOSITION, v);
        }
        headers.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
        Ok(res)
    })
    .await
}

// ----- /setup/upload -----

/// Writes `bytes` to `target` atomically (see [`arena_shared::atomic`]), so a failed
/// upload never leaves a half-written file. Like upstream it does not create missing
/// parent directories, and a folder in the way is Python's `PermissionError`.
fn write_atomically(target: &Path, data: FileData) -> std::io::Result<()> {
    use std::io::ErrorKind;
    if !target.parent().is_some_and(Path::is_dir) {
        return Err(ErrorKind::NotFound.into());
    }
    if target.is_dir() {
        return Err(ErrorKind::PermissionDenied.into());
    }
    let mut out = arena_shared::atomic::AtomicFile::create(target)?;
    data.copy_to(out.file())?;
    out.commit()
}

/// `POST /setup/upload`: multipart `file_path` + `file_data`.
pub(crate) async fn upload(State(state): State<AppState>, mut form: PyForm) -> WaaResult {
    let (Some(raw), Some(file)) = (form.field("file_path").map(str::to_owned), form.take_file("file_data")) else {
        return Err(json_err(StatusCode::BAD_REQUEST, json!({"error": "file_path and file_data are required"})));
    };
    on_backend(&state, "upload", move |desktop| {
        let path = expand(desktop, &raw);
        let local = desktop.map_path(&path)?;
        write_atomically(&local, file.data).map_err(|err| WaaError::catch(py::os_error(OsCall::Open, &err, &path)))?;
        Ok(text(StatusCode::OK, "File Uploaded"))
    })
    .await
}

// ----- create, recycle, exists -----

/// `POST /setup/create_folder`.
pub(crate) async fn create_folder(State(state): State<AppState>, PyJson(body): PyJson) -> WaaResult {
    let Some(path) = Data(&body).required("path")?.cloned() else {
        return Err(json_err(StatusCode::BAD_REQUEST, json!({"error": "path required"})));
    };
    on_backend(&state, "create_folder", move |desktop| {
        let shown = py::str_of(&path);
        let failed = || {
            json_err(
                StatusCode::BAD_REQUEST,
                json!({"status": "error", "message": format!("Failed to create {shown}.")}),
            )
        };
        let Value::String(guest) = &path else { return Err(failed()) };
        let local = desktop.map_path(guest).map_err(|_| failed())?;
        if exists(&local) {
            return Ok(json(
                StatusCode::OK,
                json!({"status": "success", "message": format!("{shown} already exists.")}),
            ));
        }
        std::fs::create_dir_all(&local).map_err(|_| failed())?;
        Ok(json(StatusCode::OK, json!({"status": "success", "message": format!("{shown} created.")})))
    })
    .await
}

/// `POST /setup/create_file`: text written with CRLF line ends (Python's text mode on
/// Windows), encoded as UTF-8 where upstream uses the ANSI code page.
pub(crate) async fn create_file(State(state): State<AppState>, PyJson(body): PyJson) -> WaaResult {
    let data = Data(&body);
    let Some(path) = data.required("path")? else {
        return Err(json_err(StatusCode::BAD_REQUEST, json!({"error": "path required"})));
    };
    let path = path_arg(path)?;
    let content = data.get("content")?.cloned().unwrap_or_else(|| json!(""));
    on_backend(&state, "create_file", move |desktop| {
        let shown = py::windows_path_str(&path);
        let local = desktop.map_path(&path);
        if local.as_ref().is_ok_and(|l| l.is_dir()) {
            return Err(json_err(StatusCode::BAD_REQUEST, json!({"status": "error", "message": "path is not a file"})));
        }
        let failed = || {
            json_err(
                StatusCode::BAD_REQUEST,
                json!({"status": "error", "message": format!("Failed to create {shown}.")}),
            )
        };
        let local = local.map_err(|_| failed())?;
        if let Some(parent) = local.parent() {
            std::fs::create_dir_all(parent).map_err(|_| failed())?;
        }
        // Upstream opens (and so truncates) the file before `write` rejects a non-string.
        let text = match &content {
            Value::String(s) => s.replace('\n', "\r\n"),
            _ => {
                let _ = std::fs::write(&local, b"");
                return Err(failed());
            }
        };
        std::fs::write(&local, text).map_err(|_| failed())?;
        Ok(json(StatusCode::OK, json!({"status": "success", "message": format!("{shown} created.")})))
    })
    .await
}

/// `POST /setup/recycle`: to the Recycle Bin.
pub(crate) async fn recycle(State(state): State<AppState>, PyJson(body): PyJson) -> WaaResult {
    let Some(path) = Data(&body).required("path")?.cloned() else {
        return Err(json_err(StatusCode::BAD_REQUEST, json!({"error": "Missing 'path' parameter"})));
    };
    on_backend(&state, "recycle", move |desktop| {
        let shown = py::str_of(&path);
        let recycled = match &path {
            Value::String(guest) => {
                // A protected folder is refused outright (403), on every backend.
                crate::protect::refuse_destructive(desktop, "recycle", guest).map_err(|err| {
                    json_err(StatusCode::FORBIDDEN, json!({"status": "error", "message": err.to_string()}))
                })?;
                desktop.recycle(guest).map_err(|err| tracing::debug!(error = %err, "recycle failed")).is_ok()
            }
            _ => false,
        };
        if recycled {
            Ok(json(StatusCode::OK, json!({"status": "success", "message": format!("{shown} recycled")})))
        } else {
            Err(json_err(
                StatusCode::BAD_REQUEST,
                json!({"status": "error", "message": format!("Failed to recycle {shown}")}),
            ))
        }
    })
    .await
}

/// `os.path.join(path, name)` with the `TypeError` a non-string raises.
fn join_args(path: &Value, name: &Value) -> Result<String, WaaError> {
    for v in [path, name] {
        if !v.is_string() {
            return Err(WaaError::catch(format!(
                "join() argument must be str, bytes, or os.PathLike object, not '{}'",
                py::type_name(v)
            )));
        }
    }
    Ok(ntpath::join(&[path.as_str().unwrap_or_default(), name.as_str().unwrap_or_default()]))
}

#[derive(Clone, Copy)]
enum Kind {
    Folder,
    File,
}

async fn exists_route(state: AppState, body: Value, kind: Kind) -> WaaResult {
    let data = Data(&body);
    let (name_key, noun) = match kind {
        Kind::Folder => ("folder_name", "Folder"),
        Kind::File => ("file_name", "File"),
    };
    let Some(name) = data.required(name_key)?.cloned() else {
        return Err(json_err(StatusCode::BAD_REQUEST, json!({"error": format!("{name_key} required")})));
    };
    let Some(path) = data.required("path")?.cloned() else {
        return Err(json_err(StatusCode::BAD_REQUEST, json!({"error": "path required"})));
    };
    let full = join_args(&path, &name)?;
    let found = on_backend(&state, "exists", move |desktop| {
        let meta = desktop.map_path(&full).ok().and_then(|local| std::fs::metadata(local).ok());
        Ok(meta.is_some_and(|m| match kind {
            Kind::Folder => m.is_dir(),
            Kind::File => m.is_file(),
        }))
    })
    .await?;
    let (name, path) = (py::str_of(&name), py::str_of(&path));
    if found {
        Ok(json(StatusCode::OK, json!({"status": "success", "message": format!("{noun} {name} exists in {path}.")})))
    } else {
        Err(json_err(
            StatusCode::BAD_REQUEST,
            json!({"status": "error", "message": format!("{noun} {name} does not exist in {path}.")}),
        ))
    }
}

/// `POST /folder_exists`.
pub(crate) async fn folder_exists(State(state): State<AppState>, PyJson(body): PyJson) -> WaaResult {
    exists_route(state, body, Kind::Folder).await
}

/// `POST /file_exists`.
pub(crate) async fn file_exists(State(state): State<AppState>, PyJson(body): PyJson) -> WaaResult {
    exists_route(state, body, Kind::File).await
}

// ----- /list_directory -----

struct ListBudget {
    entries: usize,
    capped: bool,
}

/// Upstream's `_list_dir_contents`: `{"type": "directory", "name", "children"}`, files as
/// `{"type": "file", "name"}`, and `{"error": msg}` for a directory that cannot be listed.
fn list_tree(local: &Path, guest: &str, budget: &mut ListBudget, depth: usize) -> Value {
    let names = match arena_shared::ntfs::list_dir(local) {
        Ok(names) => names,
        Err(err) => return json!({"error": py::os_error(OsCall::Win32Dir, &err, guest)}),
    };
    let mut children = Vec::new();
    for name in names {
        if budget.entries >= MAX_LIST_ENTRIES {
            if !budget.capped {
                budget.capped = true;
                children.push(json!({"error": format!("listing stopped after {MAX_LIST_ENTRIES} entries")}));
            }
            break;
        }
        budget.entries += 1;
        let child_local = local.join(&name);
        let child_guest = ntpath::join(&[guest, &name]);
        if child_local.is_dir() {
            if depth + 1 >= MAX_LIST_DEPTH {
                children.push(json!({"error": format!("{child_guest}: nested more than {MAX_LIST_DEPTH} levels deep; not listed")}));
            } else {
                children.push(list_tree(&child_local, &child_guest, budget, depth + 1));
            }
        } else {
            children.push(json!({"type": "file", "name": name}));
        }
    }
    json!({"type": "directory", "name": ntpath::basename(guest), "children": children})
}

/// `POST /list_directory`.
pub(crate) async fn list_directory(State(state): State<AppState>, PyJson(body): PyJson) -> WaaResult {
    let Some(path) = Data(&body).required("path")?.cloned() else {
        return Err(json_err(StatusCode::BAD_REQUEST, json!({"error": "Missing 'path' parameter"})));
    };
    let not_a_dir = || json_err(StatusCode::BAD_REQUEST, json!({"error": "The provided path is not a directory"}));
    let Value::String(start) = path else { return Err(not_a_dir()) };
    on_backend(&state, "list_directory", move |desktop| {
        let local = desktop.map_path(&start).ok().filter(|l| l.is_dir()).ok_or_else(not_a_dir)?;
        let mut budget = ListBudget { entries: 0, capped: false };
        let tree = list_tree(&local, &start, &mut budget, 0);
        if budget.capped {
            tracing::warn!(path = %start, "list_directory stopped at {MAX_LIST_ENTRIES} entries");
        }
        Ok(json(StatusCode::OK, json!({"directory_tree": tree})))
    })
    .await
}

// ----- wallpaper -----

/// `POST /wallpaper`: the wallpaper file's bytes, always labelled PNG as upstream does.
pub(crate) async fn wallpaper(State(state): State<AppState>) -> WaaResult {
    on_backend(&state, "wallpaper", |desktop| {
        let Some(path) = desktop.wallpaper()?.filter(|p| !p.is_empty()) else {
            return Err(WaaError::catch("404 Not Found: Wallpaper file not found"));
        };
        let bytes = desktop.map_path(&path).ok().and_then(|local| std::fs::read(local).ok());
        let Some(bytes) = bytes else {
            return Err(WaaError::catch("500 Internal Server Error: Unable to serve the wallpaper file"));
        };
        let mut res = bytes.into_response();
        res.headers_mut().insert(header::CONTENT_TYPE, HeaderValue::from_static("image/png"));
        res.headers_mut().insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
        Ok(res)
    })
    .await
}

/// A truthy string `path` argument of a text route, expanded and printed as `WindowsPath`.
/// `None` when the argument is missing or falsy.
fn text_path_arg(value: Option<&Value>) -> Result<Option<String>, WaaError> {
    match value {
        Some(v) if truthy(v) => path_arg(v).map(Some),
        _ => Ok(None),
    }
}

/// `POST /setup/change_wallpaper`.
pub(crate) async fn change_wallpaper(State(state): State<AppState>, PyJson(body): PyJson) -> WaaResult {
    let Some(raw) = text_path_arg(Data(&body).get("path")?)? else {
        return Err(text_err(StatusCode::BAD_REQUEST, "Path not supplied!"));
    };
    on_backend(&state, "change_wallpaper", move |desktop| {
        let path = py::windows_path_str(&expand(desktop, &raw));
        if !desktop.map_path(&path).is_ok_and(|l| exists(&l)) {
            return Err(text_err(StatusCode::NOT_FOUND, format!("File not found: {path}")));
        }
        match desktop.set_wallpaper(&path) {
            Ok(()) => Ok(text(StatusCode::OK, "Wallpaper changed successfully")),
            Err(err) => {
                Err(text_err(StatusCode::INTERNAL_SERVER_ERROR, format!("Failed to change wallpaper. Error: {err}")))
            }
        }
    })
    .await
}

/// `POST /setup/download_file`: refused. A guest that fetches arbitrary URLs is an SSRF
/// primitive, and the upstream host never uses this route (it downloads, then uploads).
pub(crate) async fn download_file(PyJson(body): PyJson) -> WaaResult {
    let data = Data(&body);
    let url = data.get("url")?.cloned().unwrap_or(Value::Null);
    let path = data.get("path")?.cloned().unwrap_or(Value::Null);
    if !truthy(&url) || !truthy(&path) {
        return Err(text_err(StatusCode::BAD_REQUEST, "Path or URL not supplied!"));
    }
    Err(text_err(
        StatusCode::INTERNAL_SERVER_ERROR,
        format!(
            "Failed to download {}. No retries left. Error: guest-side downloads are disabled; the host uploads files",
            py::str_of(&url)
        ),
    ))
}

/// `POST /setup/open_file`: open with the associated program, then let it settle
/// (upstream sleeps 5 s).
pub(crate) async fn open_file(State(state): State<AppState>, PyJson(body): PyJson) -> WaaResult {
    let Some(raw) = text_path_arg(Data(&body).get("path")?)? else {
        return Err(text_err(StatusCode::BAD_REQUEST, "Path not supplied!"));
    };
    on_backend(&state, "open_file", move |desktop| {
        let path = py::windows_path_str(&expand(desktop, &raw));
        if !desktop.map_path(&path).is_ok_and(|l| exists(&l)) {
            return Err(text_err(StatusCode::NOT_FOUND, format!("File not found: {path}")));
        }
        desktop
            .open_path(&path)
            .map_err(|err| text_err(StatusCode::INTERNAL_SERVER_ERROR, format!("Failed to open {path}. Error: {err}")))
    })
    .await?;
    tokio::time::sleep(Duration::from_millis(state.config.open_settle_ms)).await;
    Ok(text(StatusCode::OK, "File opened successfully"))
}

// ----- /setup/clear_task_files -----

/// Deletes the files (not the folders, not dot-files, not `desktop.ini`) in Downloads.
fn clear_downloads(desktop: &dyn Desktop) -> Result<Response, WaaError> {
    let dir = desktop.known_folder(KnownFolder::Downloads)?;
    let local = desktop.map_path(&dir)?;
    let names = arena_shared::ntfs::list_dir(&local)
        .map_err(|err| WaaError::catch(py::os_error(OsCall::Win32Dir, &err, &dir)))?;
    let (mut removed, mut failed) = (Vec::new(), Vec::new());
    // `glob("...\\*")` skips names starting with a dot.
    for name in names.into_iter().filter(|n| !n.starts_with('.')) {
        if name == "desktop.ini" {
            continue;
        }
        let guest = ntpath::join(&[&dir, &name]);
        let entry = local.join(&name);
        // `os.remove` refuses directories; they stay and are reported as failures.
        let is_dir = std::fs::symlink_metadata(&entry).is_ok_and(|m| m.is_dir());
        if !is_dir && std::fs::remove_file(&entry).is_ok() {
            removed.push(guest);
        } else {
            failed.push(guest);
        }
    }
    let (removed_repr, failed_repr, dir_repr) =
        (py::repr_str_list(&removed), py::repr_str_list(&failed), py::repr_str(&dir));
    let message = match (failed.is_empty(), removed.is_empty()) {
        (false, false) => {
            format!("Failed to remove ({failed_repr}) but sucessfully cleared ({removed_repr}) from {dir_repr}.")
        }
        (false, true) => format!("Failed to remove ({failed_repr}) from {dir_repr}."),
        (true, false) => format!("All task files ({removed_repr}) cleared successfully from {dir_repr}."),
        (true, true) => format!("No task files to clear from {dir_repr}."),
    };
    Ok(text(StatusCode::OK, message))
}

/// `POST /setup/clear_task_files`.
pub(crate) async fn clear_task_files(State(state): State<AppState>) -> WaaResult {
    on_backend(&state, "clear_task_files", clear_downloads).await
}

#[cfg(test)]
mod tests {
    use super::*;
    use axum::body::Bytes;

    #[test]
    fn content_disposition_quotes_like_werkzeug() {
        assert_eq!(content_disposition("a.txt"), "attachment; filename=a.txt");
        assert_eq!(content_disposition("my file.txt"), "attachment; filename=\"my file.txt\"");
        assert_eq!(
            content_disposition("résumé.pdf"),
            "attachment; filename=rsum.pdf; filename*=UTF-8''r%C3%A9sum%C3%A9.pdf"
        );
    }

    #[test]
    fn content_types_are_guessed_from_the_name() {
        assert_eq!(guess_content_type("a.txt"), "text/plain; charset=utf-8");
        assert_eq!(guess_content_type("a.png"), "image/png");
        assert_eq!(guess_content_type("History"), "application/octet-stream");
    }

    #[test]
    fn atomic_write_replaces_and_leaves_nothing_on_failure() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("a.bin");
        write_atomically(&target, FileData::Memory(Bytes::from_static(b"one"))).unwrap();
        write_atomically(&target, FileData::Memory(Bytes::from_static(b"two"))).unwrap();
        assert_eq!(std::fs::read(&target).unwrap(), b"two");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);

        let missing = dir.path().join("nope").join("a.bin");
        assert_eq!(
            write_atomically(&missing, FileData::Memory(Bytes::from_static(b"x"))).unwrap_err().kind(),
            std::io::ErrorKind::NotFound
        );
        std::fs::create_dir(dir.path().join("sub")).unwrap();
        assert!(write_atomically(&dir.path().join("sub"), FileData::Memory(Bytes::from_static(b"x"))).is_err());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 2);
    }
}
