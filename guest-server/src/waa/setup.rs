//! Window setup routes: `/setup/activate_window`, `/setup/close_window` and `/setup/close_all`.
//!
//! Windows are matched as pygetwindow's `getWindowsWithTitle` does: a case-insensitive
//! substring of the title, over the visible top-level windows in z-order.

use std::time::Duration;

use axum::extract::State;
use axum::http::StatusCode;
use serde_json::Value;

use arena_shared::observation::WindowInfo;

use crate::desktop::{DesktopError, WindowState};
use crate::error::WaaError;
use crate::state::AppState;
use crate::waa::body::{Data, PyJson};
use crate::waa::observe::visible_windows;
use crate::waa::{on_backend, py, text, text_err, WaaResult};

/// `getWindowsWithTitle(name)`: the visible windows whose title contains `name`, ignoring case.
fn windows_with_title(windows: Vec<WindowInfo>, name: &str) -> Vec<WindowInfo> {
    let needle = name.to_uppercase();
    windows.into_iter().filter(|w| w.title.to_uppercase().contains(&needle)).collect()
}

/// The window name as a string, or the `AttributeError` `.upper()` raises on anything else.
fn name_arg(value: &Value) -> Result<String, WaaError> {
    match value {
        Value::String(s) => Ok(s.clone()),
        other => Err(WaaError::catch(format!("'{}' object has no attribute 'upper'", py::type_name(other)))),
    }
}

/// `POST /setup/activate_window`.
///
/// Strict mode minimises and restores the first match, then requires it to be the
/// foreground window (an empty-message 500 otherwise, as upstream's bare `assert`).
/// Non-strict mode is a no-op upstream; here it activates the first match, so the
/// window the task asks for really is in front.
pub(crate) async fn activate_window(State(state): State<AppState>, PyJson(body): PyJson) -> WaaResult {
    let data = Data(&body);
    let name = match data.get("window_name")? {
        Some(v) if arena_shared::cmdline::truthy(v) => v.clone(),
        _ => return Err(text_err(StatusCode::BAD_REQUEST, "window_name required")),
    };
    let strict = data.flag("strict")?;
    if data.flag("by_class")? {
        return Err(text_err(
            StatusCode::INTERNAL_SERVER_ERROR,
            "Get window by class name is currently not supported on Windows.",
        ));
    }
    let name = name_arg(&name)?;
    let lookup = name.clone();
    let matches = on_backend(&state, "activate_window", move |desktop| {
        Ok(windows_with_title(visible_windows(desktop)?, &lookup))
    })
    .await?;
    let Some(target) = matches.first().map(|w| w.id) else {
        return Err(text_err(StatusCode::NOT_FOUND, format!("Window {name} not found (empty results)")));
    };
    let settle = Duration::from_millis(state.config.activate_settle_ms);
    if strict {
        on_backend(&state, "activate_window", move |desktop| {
            Ok(desktop.set_window_state(target, WindowState::Minimized)?)
        })
        .await?;
        tokio::time::sleep(settle).await;
        on_backend(&state, "activate_window", move |desktop| {
            desktop.set_window_state(target, WindowState::Normal)?;
            Ok(desktop.activate_window(target)?)
        })
        .await?;
        tokio::time::sleep(settle).await;
        let active = on_backend(&state, "activate_window", move |desktop| {
            Ok(desktop.windows()?.iter().any(|w| w.id == target && w.focused))
        })
        .await?;
        if !active {
            return Err(WaaError::catch(""));
        }
    } else {
        let activated =
            on_backend(&state, "activate_window", move |desktop| Ok(desktop.activate_window(target)?)).await;
        if let Err(err) = activated {
            // Upstream does nothing here, so a refused activation is not a failure either.
            tracing::warn!(?err, window = target, "non-strict activate_window could not activate the window");
        }
    }
    Ok(text(StatusCode::OK, "Window activated successfully"))
}

/// `POST /setup/close_window`. Strict mode always answers 404: upstream compares a
/// window with its own title (Q7), and that is kept.
pub(crate) async fn close_window(State(state): State<AppState>, PyJson(body): PyJson) -> WaaResult {
    let data = Data(&body);
    let Some(name) = data.required("window_name")?.cloned() else {
        return Err(text_err(StatusCode::BAD_REQUEST, "window_name required"));
    };
    let strict = data.flag("strict")?;
    if data.flag("by_class")? {
        return Err(text_err(
            StatusCode::INTERNAL_SERVER_ERROR,
            "Get window by class name is not supported on Windows currently.",
        ));
    }
    let name = name_arg(&name)?;
    let lookup = name.clone();
    let matches =
        on_backend(&state, "close_window", move |desktop| Ok(windows_with_title(visible_windows(desktop)?, &lookup)))
            .await?;
    let Some(target) = matches.first().map(|w| w.id) else {
        return Err(text_err(StatusCode::NOT_FOUND, format!("Window {name} not found (empty results)")));
    };
    if strict {
        return Err(text_err(StatusCode::NOT_FOUND, format!("Window {name} not found (strict mode).")));
    }
    on_backend(&state, "close_window", move |desktop| Ok(desktop.close_window(target)?)).await?;
    Ok(text(StatusCode::OK, "Window closed successfully."))
}

/// `POST /setup/close_all`: `WM_CLOSE` to every visible titled window except the desktop
/// (`Program Manager`), upstream's server console, and this server's own windows.
pub(crate) async fn close_all(State(state): State<AppState>) -> WaaResult {
    let own_pid = std::process::id();
    on_backend(&state, "close_all", move |desktop| {
        for window in visible_windows(desktop)? {
            if arena_shared::close_all::spares(&window, Some(own_pid)) {
                continue;
            }
            match desktop.close_window(window.id) {
                // A window that vanished since the listing is as closed as it gets.
                Ok(()) | Err(DesktopError::NotFound(_)) => {}
                Err(err) => return Err(WaaError::from(err)),
            }
        }
        Ok(text(StatusCode::OK, "All windows closed successfully."))
    })
    .await
}
