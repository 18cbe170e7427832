//! `GET /v1/doctor`: every capability checked end to end ([`crate::doctor`]).
//!
//! Slow by design (it starts Notepad, types, walks trees, waits out a command's
//! timeout), so it has its own long deadline, needs the token like every route
//! but health, and runs one at a time: two doctors would type into each other's
//! Notepad. It takes the desktop's input alone ([`AppState::input`]): it waits for the
//! action batches running and no batch starts until it is done, so a doctor run
//! during an episode never types into the agent's windows.

use std::time::Duration;

use axum::extract::State;
use axum::routing::get;
use axum::Router;

use arena_shared::doctor::DoctorReport;

use crate::call::blocking;
use crate::doctor::{run, DoctorOptions};
use crate::error::{ApiError, AppJson};
use crate::state::AppState;

/// Longest a whole doctor run may take.
const DEADLINE: Duration = Duration::from_secs(180);

pub(crate) fn routes() -> Router<AppState> {
    Router::new().route("/v1/doctor", get(doctor))
}

async fn doctor(State(state): State<AppState>) -> Result<AppJson<DoctorReport>, ApiError> {
    static ONE_AT_A_TIME: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());
    let _turn = ONE_AT_A_TIME.lock().await;
    let _input = state.input.write().await;
    let options = DoctorOptions::for_server(&state.config, state.token.is_some());
    let report = blocking(&state.desktop, "doctor", DEADLINE, move |d| Ok(run(d, &options))).await?;
    Ok(AppJson(report))
}
