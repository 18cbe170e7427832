//! `GET /v1/health`: the staged readiness report.
//!
//! Every [`Component`] is probed at once, each through its own short-deadline
//! backend call, so one hung part (say, a stuck accessibility provider) costs
//! only its own probe. The route always answers 200: the body says what is up.
//! It is not a liveness check of the HTTP server alone; that is `/probe`.

use std::time::{Duration, Instant};

use axum::extract::State;
use axum::routing::get;
use axum::Router;

use arena_shared::health::{Component, ComponentHealth, HealthReport, Readiness};

use crate::call::blocking;
use crate::error::AppJson;
use crate::state::AppState;

use super::millis;

/// How long one component probe may take before it counts as down.
const PROBE_DEADLINE: Duration = Duration::from_secs(5);

pub(crate) fn routes() -> Router<AppState> {
    Router::new().route("/v1/health", get(health))
}

async fn health(State(state): State<AppState>) -> AppJson<HealthReport> {
    let probes = Component::ALL.into_iter().map(|component| probe(&state, component));
    let components = futures_util::future::join_all(probes).await;
    let up = components.iter().filter(|c| c.ok).count();
    let status = match up {
        0 => Readiness::Starting,
        n if n == components.len() => Readiness::Ready,
        _ => Readiness::Degraded,
    };
    AppJson(HealthReport {
        status,
        version: env!("CARGO_PKG_VERSION").to_owned(),
        api_version: arena_shared::API_VERSION.to_owned(),
        backend: state.desktop.kind().to_owned(),
        components,
        uptime_ms: millis(state.started.elapsed()),
        auth_required: state.token.is_some(),
        session_id: state.desktop.session_id(),
    })
}

async fn probe(state: &AppState, component: Component) -> ComponentHealth {
    let started = Instant::now();
    let res = blocking(&state.desktop, "probe", PROBE_DEADLINE, move |d| d.probe(component)).await;
    let elapsed_ms = millis(started.elapsed());
    match res {
        Ok(detail) => ComponentHealth { component, ok: true, detail, elapsed_ms },
        Err(err) => ComponentHealth { component, ok: false, detail: err.to_string(), elapsed_ms },
    }
}
