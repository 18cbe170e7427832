//! `GET` and `PUT /v1/clock`: the guest's wall clock, read and set.
//!
//! The host sets it after every snapshot restore (a restored VM wakes with the
//! time it was saved at). Setting the clock changes the whole machine, so, like
//! every route but the readiness probes, it answers only with the token.

use axum::extract::State;
use axum::routing::get;
use axum::Router;

use arena_shared::clock::{ClockReading, ClockSet, ClockSetResult};

use crate::call::blocking;
use crate::error::{ApiError, AppJson};
use crate::state::AppState;

pub(crate) fn routes() -> Router<AppState> {
    Router::new().route("/v1/clock", get(read).put(set))
}

async fn read(State(state): State<AppState>) -> Result<AppJson<ClockReading>, ApiError> {
    let unix_ms = blocking(&state.desktop, "system_time", state.call_timeout(), |d| d.system_time()).await?;
    Ok(AppJson(ClockReading { unix_ms }))
}

async fn set(
    State(state): State<AppState>,
    AppJson(request): AppJson<ClockSet>,
) -> Result<AppJson<ClockSetResult>, ApiError> {
    arena_shared::clock::check(request.unix_ms).map_err(ApiError::BadRequest)?;
    let unix_ms = request.unix_ms;
    let previous_unix_ms = blocking(&state.desktop, "set_system_time", state.call_timeout(), move |d| {
        let previous = d.system_time()?;
        d.set_system_time(unix_ms)?;
        Ok(previous)
    })
    .await?;
    Ok(AppJson(ClockSetResult { previous_unix_ms, unix_ms }))
}
