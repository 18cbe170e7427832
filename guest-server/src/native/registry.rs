//! `GET` and `PUT /v1/registry`, and `GET` and `PUT /v1/wallpaper`: system
//! settings a task sets up or checks.
//!
//! Keys are written the way `reg.exe` names them (`HKCU\Control Panel\Desktop`);
//! an absent value name is the key's default value.

use axum::extract::State;
use axum::http::StatusCode;
use axum::routing::get;
use axum::{Json, Router};

use arena_shared::files::PathQuery;
use arena_shared::registry::{RegistryQuery, RegistryRead, RegistryValue, RegistryWrite};

use crate::call::blocking;
use crate::error::{ApiError, AppJson, AppQuery};
use crate::state::AppState;

pub(crate) fn routes() -> Router<AppState> {
    Router::new().route("/v1/registry", get(read).put(write)).route("/v1/wallpaper", get(wallpaper).put(set_wallpaper))
}

fn check_key(key: &str, value: Option<&str>) -> Result<(), ApiError> {
    if key.trim().is_empty() {
        return Err(ApiError::BadRequest("key must not be empty".into()));
    }
    crate::desktop::windows::winsys::check_registry_limits(key, value).map_err(ApiError::BadRequest)
}

async fn read(
    State(state): State<AppState>,
    AppQuery(query): AppQuery<RegistryQuery>,
) -> Result<AppJson<RegistryRead>, ApiError> {
    check_key(&query.key, query.value.as_deref())?;
    let RegistryQuery { key, value } = query;
    let read = blocking(&state.desktop, "registry_read", state.call_timeout(), move |d| {
        let data = d.registry_read(&key, value.as_deref())?;
        Ok(RegistryRead { key, value, data })
    })
    .await?;
    Ok(AppJson(read))
}

async fn write(
    State(state): State<AppState>,
    AppJson(request): AppJson<RegistryWrite>,
) -> Result<StatusCode, ApiError> {
    check_key(&request.key, request.value.as_deref())?;
    if request.data == RegistryValue::Unknown {
        return Err(ApiError::BadRequest(
            "unknown registry value type (expected string, dword, qword, multi_string or binary)".into(),
        ));
    }
    blocking(&state.desktop, "registry_write", state.call_timeout(), move |d| {
        d.registry_write(&request.key, request.value.as_deref(), &request.data)
    })
    .await?;
    Ok(StatusCode::NO_CONTENT)
}

/// `{"path": "C:\\...\\img.jpg"}`, or `{"path": null}` when no wallpaper is set.
async fn wallpaper(State(state): State<AppState>) -> Result<Json<serde_json::Value>, ApiError> {
    let path = blocking(&state.desktop, "wallpaper", state.call_timeout(), |d| d.wallpaper()).await?;
    Ok(Json(serde_json::json!({ "path": path })))
}

/// `PUT /v1/wallpaper` `{"path": "C:\\...\\img.jpg"}`: sets the wallpaper (upstream's
/// `/setup/change_wallpaper`); `~` and `%VAR%` are expanded, a missing file is `404`.
async fn set_wallpaper(
    State(state): State<AppState>,
    AppJson(request): AppJson<PathQuery>,
) -> Result<StatusCode, ApiError> {
    let set = blocking(&state.desktop, "set_wallpaper", state.call_timeout(), move |d| {
        Ok(super::files::existing_guest_path(d, &request.path).and_then(|guest| Ok(d.set_wallpaper(&guest)?)))
    })
    .await?;
    set?;
    Ok(StatusCode::NO_CONTENT)
}
