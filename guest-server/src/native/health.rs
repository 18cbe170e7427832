//! `GET /v1/health`: the staged readiness report.
//!
//! Every [`Component`] is probed at once, each through its own short-deadline
//! backend call, so one hung part (say, a stuck accessibility provider) costs
//! only its own probe. The route always answers 200: the body says what is up.
//! It is not a liveness check of the HTTP server alone; that is `/probe`.
//!
//! The route is open (readiness is polled before the token is provisioned), so it
//! is kept cheap and discreet: one report is reused for `--health-cache-ms` (1 s by
//! default) and concurrent polls wait for the same probes, and a caller without the
//! token sees the stages' states only, not what each probe read (a cursor
//! position, a clipboard length, a path).

use std::time::{Duration, Instant};

use axum::extract::State;
use axum::routing::get;
use axum::Extension;
use axum::Router;

use arena_shared::health::{Component, ComponentHealth, HealthReport, Readiness};

use crate::auth::Authorized;
use crate::call::blocking;
use crate::error::AppJson;
use crate::state::AppState;

use super::millis;

/// How long one component probe may take before it counts as down.
const PROBE_DEADLINE: Duration = Duration::from_secs(5);

pub(crate) fn routes() -> Router<AppState> {
    Router::new().route("/v1/health", get(health))
}

async fn health(State(state): State<AppState>, authorized: Option<Extension<Authorized>>) -> AppJson<HealthReport> {
    let report = cached_report(&state).await;
    let authorized = authorized.is_some_and(|Extension(Authorized(yes))| yes);
    AppJson(if authorized { report } else { redacted(report) })
}

/// The last report if it is fresh enough, else a new one; concurrent callers wait
/// for the one being made.
async fn cached_report(state: &AppState) -> HealthReport {
    let mut slot = state.health.lock().await;
    let ttl = Duration::from_millis(state.config.health_cache_ms);
    if let Some((made, report)) = slot.as_ref() {
        if made.elapsed() < ttl {
            let mut report = report.clone();
            report.uptime_ms = millis(state.started.elapsed());
            return report;
        }
    }
    let report = fresh_report(state).await;
    *slot = Some((Instant::now(), report.clone()));
    report
}

/// What a caller without the token may see: which stages are up, and nothing they read.
fn redacted(mut report: HealthReport) -> HealthReport {
    for component in &mut report.components {
        component.detail = if component.ok { "up".into() } else { "down".into() };
    }
    report.session_id = None;
    report.integrity = None;
    report
}

async fn fresh_report(state: &AppState) -> HealthReport {
    let probes = Component::REPORTED.into_iter().map(|component| probe(state, component));
    let components = futures_util::future::join_all(probes).await;
    // The shell's settle is reported beside readiness, not part of it.
    let gating = components.iter().filter(|c| c.component.gates_readiness());
    let (up, total) = (gating.clone().filter(|c| c.ok).count(), gating.count());
    let status = match up {
        0 => Readiness::Starting,
        n if n == total => Readiness::Ready,
        _ => Readiness::Degraded,
    };
    HealthReport {
        status,
        version: env!("CARGO_PKG_VERSION").to_owned(),
        api_version: arena_shared::API_VERSION.to_owned(),
        backend: state.desktop.kind().to_owned(),
        components,
        uptime_ms: millis(state.started.elapsed()),
        auth_required: state.token.is_some(),
        session_id: state.desktop.session_id(),
        integrity: state.desktop.integrity_level().ok(),
        boot_id: Some(boot_id().to_owned()),
    }
}

/// This server process's boot id ([`HealthReport::boot_id`]): random, made once.
fn boot_id() -> &'static str {
    static ID: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    ID.get_or_init(|| format!("{:016x}", rand::random::<u64>()))
}

async fn probe(state: &AppState, component: Component) -> ComponentHealth {
    let started = Instant::now();
    if component == Component::Setup {
        let (ok, detail) = setup_state(crate::setup_status_file(&state.config).as_deref());
        return ComponentHealth { component, ok, detail, elapsed_ms: millis(started.elapsed()) };
    }
    if component == Component::Shell {
        let sample = blocking(&state.desktop, "shell sample", PROBE_DEADLINE, |d| d.shell_sample()).await;
        let (ok, detail) = match sample {
            Ok(sample) => {
                let judged = state
                    .settle
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner)
                    .judge(Instant::now(), &sample);
                match judged {
                    Ok(detail) => (true, detail),
                    Err(detail) => (false, detail),
                }
            }
            Err(err) => (false, err.to_string()),
        };
        return ComponentHealth { component, ok, detail, elapsed_ms: millis(started.elapsed()) };
    }
    let res = blocking(&state.desktop, "probe", PROBE_DEADLINE, move |d| d.probe(component)).await;
    let elapsed_ms = millis(started.elapsed());
    match res {
        Ok(detail) => ComponentHealth { component, ok: true, detail, elapsed_ms },
        Err(err) => ComponentHealth { component, ok: false, detail: err.to_string(), elapsed_ms },
    }
}

/// The `setup` component: what the setup record says, or up when there is none
/// (a guest installed another way, the stub).
fn setup_state(file: Option<&std::path::Path>) -> (bool, String) {
    let Some(file) = file else {
        return (true, "no setup record is kept here".to_owned());
    };
    match std::fs::read(file) {
        Ok(bytes) => match arena_shared::health::SetupProgress::parse(&bytes) {
            Ok(progress) => progress.judge(),
            Err(err) => (false, format!("{}: {err}", file.display())),
        },
        Err(err) if err.kind() == std::io::ErrorKind::NotFound => {
            (true, format!("no setup record at {}: this guest was not installed by setup.ps1", file.display()))
        }
        Err(err) => (false, format!("{}: {err}", file.display())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_setup_component_follows_the_record() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("setup-status.json");
        assert!(setup_state(None).0);
        assert!(setup_state(Some(&file)).0, "no record: up");
        std::fs::write(&file, r#"{"state":"running","step":"prep-apps.ps1","done":4,"total":6}"#).unwrap();
        let (ok, detail) = setup_state(Some(&file));
        assert!(!ok && detail.contains("prep-apps.ps1"), "{detail}");
        std::fs::write(&file, r#"{"state":"done","done":6,"total":6}"#).unwrap();
        assert!(setup_state(Some(&file)).0);
        std::fs::write(&file, "{").unwrap();
        assert!(!setup_state(Some(&file)).0);
    }
}
