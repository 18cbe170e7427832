//! Screen recording (`/start_recording`, `/end_recording`) and the snapshot routes
//! (`/save_state`, `/revert_to_snapshot`), which upstream never implemented.
//!
//! Recording starts upstream's exact ffmpeg command through the backend. The backend's
//! `spawn` keeps no handle to the child's standard input, so `/end_recording` cannot send
//! ffmpeg the `q` upstream sends; it ends the process with `taskkill` instead, which may
//! leave the MP4 without its index (see `docs/compatibility.md`).

use std::path::PathBuf;
use std::time::Duration;

use axum::extract::State;
use axum::http::StatusCode;
use serde_json::json;

use arena_shared::files::KnownFolder;
use arena_shared::ntpath;

use crate::desktop::{CommandSpec, Desktop, DesktopError, ExecLimits};
use crate::error::WaaError;
use crate::state::AppState;
use crate::waa::body::PyForm;
use crate::waa::WaaState;
use crate::waa::{json, json_err, on_backend, WaaResult};
use arena_shared::cmdline::shlex_split;
use std::sync::Arc;

/// A running recording: the ffmpeg process and the file it writes.
#[derive(Debug, Clone)]
pub(crate) struct Recording {
    pid: u32,
    path: String,
}

/// The guest folder recordings go to: `recordings` beside the server executable, as
/// upstream keeps them beside `main.py`; the guest's temp folder when the executable
/// lies outside what the backend serves (the stub).
fn recordings_dir(desktop: &dyn Desktop) -> Result<String, WaaError> {
    let beside_exe = std::env::current_exe()
        .ok()
        .and_then(|exe| exe.parent().map(|dir| dir.join("recordings")))
        .and_then(|dir: PathBuf| desktop.unmap_path(&dir).ok());
    match beside_exe {
        Some(dir) => Ok(dir),
        None => Ok(ntpath::join(&[&desktop.known_folder(KnownFolder::Temp)?, "arena-recordings"])),
    }
}

/// `POST /start_recording`.
pub(crate) async fn start_recording(State(state): State<AppState>, State(session): State<Arc<WaaState>>) -> WaaResult {
    let mut recording = session.recording.lock().await;
    if recording.is_some() {
        return Err(json_err(
            StatusCode::BAD_REQUEST,
            json!({"status": "error", "message": "Recording is already in progress."}),
        ));
    }
    let (pid, path, command) = on_backend(&state, "start_recording", |desktop| {
        let dir = recordings_dir(desktop)?;
        if let Ok(local) = desktop.map_path(&dir) {
            std::fs::create_dir_all(&local).map_err(|err| WaaError::catch(format!("creating {dir}: {err}")))?;
        }
        let path = ntpath::join(&[&dir, "recording.mp4"]);
        let screen = desktop.screen()?;
        let command = format!(
            "ffmpeg -y -f gdigrab -draw_mouse 1 -video_size {}x{} -i desktop -pix_fmt yuv420p -c:v libx264 -r 30 '{path}'",
            screen.physical_width, screen.physical_height
        );
        let argv = shlex_split(&command).map_err(|err| WaaError::catch(err.to_string()))?;
        let pid = desktop.spawn(&CommandSpec::Argv(argv)).map_err(|err| match err {
            DesktopError::NotFound(_) => WaaError::catch("[WinError 2] The system cannot find the file specified"),
            other => WaaError::from(other),
        })?;
        Ok((pid, path, command))
    })
    .await?;
    *recording = Some(Recording { pid, path: path.clone() });
    Ok(json(
        StatusCode::OK,
        json!({"status": "success", "message": format!("Started recording to: {path}.\nCOMMAND: {command}")}),
    ))
}

/// `POST /end_recording`.
pub(crate) async fn end_recording(State(state): State<AppState>, State(session): State<Arc<WaaState>>) -> WaaResult {
    let mut recording = session.recording.lock().await;
    let Some(current) = recording.take() else {
        return Err(json_err(
            StatusCode::BAD_REQUEST,
            json!({"status": "error", "message": "No recording in progress to stop."}),
        ));
    };
    let path = current.path.clone();
    let saved = on_backend(&state, "end_recording", move |desktop| {
        let stop = CommandSpec::Argv(vec![
            "taskkill".into(),
            "/PID".into(),
            current.pid.to_string(),
            "/T".into(),
            "/F".into(),
        ]);
        let limits = ExecLimits { timeout_ms: 10_000, max_output_bytes: 64 << 10, cwd: None, stdin: None };
        if let Err(err) = desktop.run(&stop, &limits) {
            tracing::warn!(error = %err, pid = current.pid, "could not stop the recording process");
        }
        // Give the file system a moment to settle after the process is gone.
        std::thread::sleep(Duration::from_millis(200));
        Ok(desktop.map_path(&current.path).is_ok_and(|local| local.is_file()))
    })
    .await?;
    if saved {
        Ok(json(StatusCode::OK, json!({"status": "success", "message": format!("record saved to: {path}")})))
    } else {
        Err(WaaError::catch("404 Not Found: Recording failed"))
    }
}

/// `POST /save_state`: upstream checks `snapshot_name`, then reads `file_path` (its bug),
/// then would create a restore point. This server never checkpoints the VM, so past the
/// same checks it answers 501 like `/revert_to_snapshot`.
pub(crate) async fn save_state(form: PyForm) -> WaaResult {
    if form.field("snapshot_name").is_none() {
        return Err(json_err(StatusCode::BAD_REQUEST, json!({"error": "snapshot_name is required"})));
    }
    if form.field("file_path").is_none() {
        return Err(WaaError::catch(
            "400 Bad Request: The browser (or proxy) sent a request that this server could not understand.\nKeyError: 'file_path'",
        ));
    }
    Err(json_err(StatusCode::NOT_IMPLEMENTED, json!({"error": "Save snapshot not implemented"})))
}

/// `POST /revert_to_snapshot`: always 501, with upstream's text.
pub(crate) async fn revert_to_snapshot() -> WaaResult {
    Err(json_err(StatusCode::NOT_IMPLEMENTED, json!({"error": "Restore snapshot no implemented"})))
}
