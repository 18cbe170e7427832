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

/// How long `arena-guest doctor` waits to connect to a server that may be running.
const CONNECT: Duration = Duration::from_secs(2);

/// For `arena-guest doctor`: the report of the server already serving on the
/// configured port, if one is, so that the check runs inside it, in turn with its
/// actions, instead of typing over an episode from a second process.
///
/// `Ok(None)` when nothing listens there (or the port is 0): the caller checks in
/// its own process.
///
/// # Errors
///
/// Something answers on the port but gives no report (a wrong token, another
/// program): the message says what it answered.
pub async fn ask_running_server(
    config: &crate::config::ServerConfig,
    token: Option<&str>,
) -> Result<Option<DoctorReport>, String> {
    if config.port == 0 {
        return Ok(None);
    }
    let host = if config.bind.is_unspecified() {
        if config.bind.is_ipv4() {
            std::net::IpAddr::V4(std::net::Ipv4Addr::LOCALHOST)
        } else {
            std::net::IpAddr::V6(std::net::Ipv6Addr::LOCALHOST)
        }
    } else {
        config.bind
    };
    let url = format!("http://{}/v1/doctor", std::net::SocketAddr::new(host, config.port));
    let client = reqwest::Client::builder()
        .connect_timeout(CONNECT)
        .timeout(DEADLINE + Duration::from_secs(30))
        .no_proxy()
        .build()
        .map_err(|err| format!("building an HTTP client: {err}"))?;
    let mut request = client.get(&url);
    if let Some(token) = token {
        request = request.bearer_auth(token);
    }
    let answer = match request.send().await {
        Ok(answer) => answer,
        Err(err) if err.is_connect() => return Ok(None),
        Err(err) => return Err(format!("{url}: {err}")),
    };
    let status = answer.status();
    let body = answer.bytes().await.map_err(|err| format!("{url}: reading the answer: {err}"))?;
    if status.is_success() {
        if let Ok(report) = serde_json::from_slice::<DoctorReport>(&body) {
            return Ok(Some(report));
        }
    }
    let text = String::from_utf8_lossy(&body);
    let text = crate::error::clip(text.trim());
    Err(format!(
        "something answers on port {} but gave no doctor report ({status}: {text}); a running arena-guest needs the \
         same --token or --token-file, and another program must leave the port or the doctor must be given --port",
        config.port
    ))
}

pub(crate) fn routes() -> Router<AppState> {
    Router::new().route("/v1/doctor", get(doctor))
}

/// `?deep=true`: also the heavy applications' trees and input round trips.
#[derive(Debug, Default, serde::Deserialize)]
struct DoctorQuery {
    #[serde(default)]
    deep: bool,
}

async fn doctor(
    State(state): State<AppState>,
    axum::extract::Query(query): axum::extract::Query<DoctorQuery>,
) -> Result<AppJson<DoctorReport>, ApiError> {
    static ONE_AT_A_TIME: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());
    let _turn = ONE_AT_A_TIME.lock().await;
    let _input = state.input.write().await;
    let mut options = DoctorOptions::for_server(&state.config, state.token.is_some());
    options.deep = query.deep;
    let report = blocking(&state.desktop, "doctor", DEADLINE, move |d| Ok(run(d, &options))).await?;
    Ok(AppJson(report))
}
