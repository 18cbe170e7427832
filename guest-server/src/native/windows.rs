//! `/v1/windows`: list top-level windows and activate, close, minimise,
//! maximise or restore one.
//!
//! A [`WindowTarget`] names a window by exact id or by a case-insensitive
//! substring of its title, where the first visible match in z-order wins.
//! Finding the window and acting on it happen in one backend call, so the
//! window found is the window changed.

use axum::extract::State;
use axum::routing::{get, post};
use axum::Router;

use arena_shared::observation::{WindowInfo, WindowTarget};

use crate::call::blocking;
use crate::desktop::{Desktop, DesktopError, DesktopResult, WindowState};
use crate::error::{ApiError, AppJson};
use crate::state::AppState;

pub(crate) fn routes() -> Router<AppState> {
    Router::new()
        .route("/v1/windows", get(list))
        .route("/v1/windows/activate", post(activate))
        .route("/v1/windows/close", post(close))
        .route("/v1/windows/minimize", post(minimize))
        .route("/v1/windows/maximize", post(maximize))
        .route("/v1/windows/restore", post(restore))
}

/// What to do with the targeted window.
#[derive(Debug, Clone, Copy)]
enum Change {
    Activate,
    Close,
    State(WindowState),
}

async fn list(State(state): State<AppState>) -> Result<AppJson<Vec<WindowInfo>>, ApiError> {
    let windows = blocking(&state.desktop, "windows", state.call_timeout(), |d| d.windows()).await?;
    Ok(AppJson(windows))
}

async fn activate(
    State(state): State<AppState>,
    AppJson(target): AppJson<WindowTarget>,
) -> Result<AppJson<WindowInfo>, ApiError> {
    change(state, target, Change::Activate).await
}

async fn close(
    State(state): State<AppState>,
    AppJson(target): AppJson<WindowTarget>,
) -> Result<AppJson<WindowInfo>, ApiError> {
    change(state, target, Change::Close).await
}

async fn minimize(
    State(state): State<AppState>,
    AppJson(target): AppJson<WindowTarget>,
) -> Result<AppJson<WindowInfo>, ApiError> {
    change(state, target, Change::State(WindowState::Minimized)).await
}

async fn maximize(
    State(state): State<AppState>,
    AppJson(target): AppJson<WindowTarget>,
) -> Result<AppJson<WindowInfo>, ApiError> {
    change(state, target, Change::State(WindowState::Maximized)).await
}

async fn restore(
    State(state): State<AppState>,
    AppJson(target): AppJson<WindowTarget>,
) -> Result<AppJson<WindowInfo>, ApiError> {
    change(state, target, Change::State(WindowState::Normal)).await
}

/// How a request names its window, once checked.
#[derive(Debug, Clone)]
enum Selector {
    Id(u64),
    Title(String),
}

fn selector(target: WindowTarget) -> Result<Selector, ApiError> {
    match (target.id, target.title) {
        (Some(id), None) => Ok(Selector::Id(id)),
        (None, Some(title)) if title.is_empty() => Err(ApiError::BadRequest("title must not be empty".into())),
        (None, Some(title)) => Ok(Selector::Title(title)),
        (Some(_), Some(_)) => Err(ApiError::BadRequest("give exactly one of id and title, not both".into())),
        (None, None) => Err(ApiError::BadRequest("give exactly one of id and title".into())),
    }
}

/// Applies `change` to the targeted window and answers it: as it is after an
/// activation or state change, as it was before a close.
async fn change(state: AppState, target: WindowTarget, change: Change) -> Result<AppJson<WindowInfo>, ApiError> {
    let selector = selector(target)?;
    let info = blocking(&state.desktop, "window", state.call_timeout(), move |d| apply(d, &selector, change)).await?;
    Ok(AppJson(info))
}

fn apply(d: &dyn Desktop, selector: &Selector, change: Change) -> DesktopResult<WindowInfo> {
    let before = find(d.windows()?, selector)?;
    match change {
        Change::Close => {
            d.close_window(before.id)?;
            return Ok(before);
        }
        Change::Activate => d.activate_window(before.id)?,
        Change::State(window_state) => d.set_window_state(before.id, window_state)?,
    }
    // The window may vanish right after the change; then its last known state is the answer.
    let after = d.windows()?.into_iter().find(|w| w.id == before.id);
    Ok(after.unwrap_or(before))
}

/// The window `selector` names: by id any window, by title the first visible match in z-order.
fn find(mut windows: Vec<WindowInfo>, selector: &Selector) -> DesktopResult<WindowInfo> {
    match selector {
        Selector::Id(id) => windows
            .into_iter()
            .find(|w| w.id == *id)
            .ok_or_else(|| DesktopError::NotFound(format!("no window with id {id}"))),
        Selector::Title(title) => {
            let needle = title.to_lowercase();
            windows.sort_by_key(|w| w.z_order);
            windows.into_iter().find(|w| w.visible && w.title.to_lowercase().contains(&needle)).ok_or_else(|| {
                DesktopError::NotFound(format!(
                    "no visible window whose title contains {:?}",
                    crate::error::clip(title)
                ))
            })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use arena_shared::geometry::Rect;

    fn window(id: u64, title: &str, z_order: u32, visible: bool) -> WindowInfo {
        WindowInfo {
            id,
            title: title.into(),
            class_name: "C".into(),
            process_id: 1,
            process_name: "p.exe".into(),
            rect: Rect::new(0, 0, 10, 10),
            visible,
            minimized: false,
            maximized: false,
            focused: false,
            z_order,
        }
    }

    fn check(selector: Selector, expected: Option<u64>) {
        let windows = vec![
            window(1, "Untitled - Notepad", 2, true),
            window(2, "notes.txt - Notepad", 1, true),
            window(3, "Hidden Notepad", 0, false),
            window(4, "Calculator", 3, true),
        ];
        let got = find(windows, &selector).ok().map(|w| w.id);
        assert_eq!(got, expected, "{selector:?}");
    }

    #[test]
    fn titles_match_case_insensitively_first_visible_in_z_order() {
        check(Selector::Title("NOTEPAD".into()), Some(2));
        check(Selector::Title("untitled".into()), Some(1));
        check(Selector::Title("hidden".into()), None);
        check(Selector::Title("paint".into()), None);
        check(Selector::Id(3), Some(3));
        check(Selector::Id(9), None);
    }

    #[test]
    fn exactly_one_of_id_and_title() {
        assert!(selector(WindowTarget { id: Some(1), title: Some("a".into()) }).is_err());
        assert!(selector(WindowTarget { id: None, title: None }).is_err());
        assert!(selector(WindowTarget { id: None, title: Some(String::new()) }).is_err());
        assert!(matches!(selector(WindowTarget { id: Some(7), title: None }), Ok(Selector::Id(7))));
    }
}
