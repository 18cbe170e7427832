//! The in-guest desktop-control server.
//!
//! It serves two APIs over one [`desktop::Desktop`] backend:
//!
//! - the upstream WindowsAgentArena Flask server's 44 routes, byte-compatible
//!   in methods, request fields, response shapes and status codes ([`waa`]), so
//!   existing WAA hosts keep working;
//! - a typed native API under `/v1/` ([`native`]) that the Rust host client uses.
//!
//! It is not the host side (see `arena-host`), and it holds no Win32 code outside
//! its `windows/` folders (`desktop/windows/`, the backend; `service/windows/`, the
//! Service Control Manager glue).
//!
//! # Layout
//!
//! - [`cli`]: the whole command line (clap). [`config`]: the one [`config::ServerConfig`]
//!   (defined in `arena_guest_launch`, which the logon launcher shares) and the body limits.
//! - [`serve`]: the HTTP/1 server loop and its connection limits.
//! - [`desktop`]: the backend trait and its backends ([`desktop::stub`]).
//! - [`call`]: backend calls with deadlines.
//! - [`waa`], [`native`]: the routes. [`auth`]: token and cross-site guards.
//! - [`error`]: the error shapes. [`state`]: handler state.
//! - [`paths`], [`imaging`], [`urlencoded`]: platform-neutral helpers the routes share
//!   (the path rules themselves are `arena_shared::ntpath`).
//! - [`inspect`]: the logic of the evaluator queries both APIs answer.
//! - [`protect`]: what no route may delete, move or recycle.
//! - [`script_host`]: the desktop side of the native Python-subset interpreter.
//! - [`mcp`]: `--mcp`, the desktop tools over the Model Context Protocol at `/mcp` (over
//!   `arena_mcp`, the glue the host's endpoint shares). [`doctor`]: every capability
//!   checked end to end.
//! - [`service`]: the `service` and `logon-task` subcommands (running in the user's session), with the
//!   Windows service supervisor in `service/windows/`; the logon task's launcher is the
//!   binary of `arena_guest_launch`.

pub mod auth;
pub mod call;
pub mod cli;
pub mod config;
pub mod desktop;
pub mod doctor;
pub mod error;
pub mod imaging;
pub mod inspect;
pub mod mcp;
pub mod native;
pub mod paths;
pub mod programs;
pub mod protect;
pub mod script_host;
pub mod serve;
pub mod service;
pub mod state;
pub mod urlencoded;
pub mod waa;

use std::future::Future;
use std::sync::Arc;

use anyhow::Context;
use axum::extract::{DefaultBodyLimit, Request};
use axum::response::IntoResponse;
use axum::Router;
use tower_http::trace::TraceLayer;

use crate::config::{BackendKind, ServerConfig};
use crate::desktop::stub::{Scenario, StubConfig, StubDesktop};
use crate::desktop::Desktop;
use crate::error::{ApiError, WaaError};
use crate::state::AppState;

/// Builds the whole application: both APIs, the guards and the limits.
pub fn router(state: AppState) -> Router {
    let max_body = state.config.max_body_bytes;
    let mut app = Router::new().merge(native::routes()).merge(waa::routes(&state));
    if state.config.mcp {
        app = app.nest_service("/mcp", mcp::service(state.clone()));
    }
    app.fallback(fallback)
        .method_not_allowed_fallback(method_not_allowed)
        .layer(axum::middleware::from_fn_with_state(state.clone(), auth::guard))
        .layer(DefaultBodyLimit::max(max_body))
        .layer(TraceLayer::new_for_http())
        .with_state(state)
}

async fn fallback(request: Request) -> axum::response::Response {
    let path = request.uri().path();
    if path.starts_with("/v1/") {
        ApiError::NotFound(format!("no route {} {path}", request.method())).into_response()
    } else {
        WaaError::not_found_route().into_response()
    }
}

async fn method_not_allowed(request: Request) -> axum::response::Response {
    let path = request.uri().path();
    if path.starts_with("/v1/") {
        let mut res =
            ApiError::BadRequest(format!("method {} is not allowed on {path}", request.method())).into_response();
        *res.status_mut() = axum::http::StatusCode::METHOD_NOT_ALLOWED;
        res
    } else {
        WaaError::method_not_allowed().into_response()
    }
}

/// The backend `config` asks for: `--backend`, else the platform's own.
fn backend_kind(config: &ServerConfig) -> BackendKind {
    config.backend.unwrap_or(if crate::desktop::windows::target::IS_WINDOWS {
        BackendKind::Windows
    } else {
        BackendKind::Stub
    })
}

/// The setup record the `setup` health component reads: `--setup-status`, or the
/// platform's default ([`desktop::windows::target::default_setup_status`]).
pub fn setup_status_file(config: &ServerConfig) -> Option<std::path::PathBuf> {
    config.setup_status.clone().or_else(crate::desktop::windows::target::default_setup_status)
}

/// Checks the configuration, builds the backend and the state.
///
/// # Errors
///
/// A non-loopback bind without a token or `--allow-unauthenticated`, an
/// unreadable token file or scenario, or a backend this build does not have.
pub fn build_state(config: ServerConfig) -> anyhow::Result<AppState> {
    let token = resolve_token(&config)?;
    if !config.bind.is_loopback() && token.is_none() {
        if !config.allow_unauthenticated {
            anyhow::bail!(
                "refusing to serve {} without a token: pass --token or --token-file, or --allow-unauthenticated for WAA drop-in use",
                config.bind
            );
        }
        tracing::warn!(bind = %config.bind, "serving a non-loopback address WITHOUT authentication: anyone who can reach this port can run programs and read files");
    }
    let desktop: Arc<dyn Desktop> = match backend_kind(&config) {
        BackendKind::Stub => {
            let scenario = match &config.scenario {
                Some(path) => {
                    Some(Scenario::load(path).with_context(|| format!("loading scenario {}", path.display()))?)
                }
                None => None,
            };
            let stub = StubDesktop::with_config(StubConfig {
                root: config.stub_root.clone(),
                screen: config.screen,
                scenario,
                host_exec: config.stub_host_exec,
                shell_after: std::time::Duration::from_millis(config.stub_shell_after_ms),
            })
            .context("starting the stub desktop")?;
            Arc::new(stub)
        }
        BackendKind::Windows => crate::desktop::windows::start(&config)?,
    };
    let sweep = Arc::clone(&desktop);
    std::thread::Builder::new()
        .name("leftover-sweep".into())
        .spawn(move || sweep_leftovers(sweep.as_ref()))
        .context("starting the leftover sweep")?;
    Ok(AppState::new(desktop, config, token))
}

/// How old a temporary file must be before the start-up sweep removes it: a writer
/// that old died (a write takes seconds at most).
const LEFTOVER_AGE: std::time::Duration = std::time::Duration::from_secs(60);
/// How deep below each known folder the sweep looks.
const SWEEP_DEPTH: usize = 3;

/// Removes the temporary files that writers killed mid-write (a `kill -9`, a reset VM)
/// left in the user's folders ([`arena_shared::atomic::TEMP_PREFIX`] files older than a
/// minute), a few levels deep; logs what it removed.
pub fn sweep_leftovers(desktop: &dyn Desktop) -> usize {
    use arena_shared::files::KnownFolder;
    fn sweep(dir: &std::path::Path, depth: usize) -> usize {
        let mut removed = arena_shared::atomic::remove_leftovers(dir, LEFTOVER_AGE);
        if depth == 0 {
            return removed;
        }
        let Ok(entries) = std::fs::read_dir(dir) else { return removed };
        for entry in entries.flatten().take(10_000) {
            if entry.file_type().is_ok_and(|t| t.is_dir()) {
                removed += sweep(&entry.path(), depth - 1);
            }
        }
        removed
    }
    // The user's document folders; the profile itself and AppData are too big to walk at start-up.
    let folders = KnownFolder::ALL.into_iter().filter(|f| {
        !matches!(f, KnownFolder::Home | KnownFolder::AppData | KnownFolder::LocalAppData | KnownFolder::Temp)
    });
    let mut removed = 0;
    for folder in folders {
        let Ok(local) = desktop.known_folder(folder).and_then(|guest| desktop.map_path(&guest)) else { continue };
        removed += sweep(&local, SWEEP_DEPTH);
    }
    if removed > 0 {
        tracing::info!(removed, "removed temporary files that interrupted writes left behind");
    }
    removed
}

/// The bearer token `config` names (`--token` or the first line of `--token-file`),
/// checked; `None` when it names none.
///
/// # Errors
///
/// A malformed token or an unreadable token file.
pub fn resolve_token(config: &ServerConfig) -> anyhow::Result<Option<String>> {
    let token = match (&config.token, &config.token_file) {
        (Some(token), _) => Some(arena_shared::token::parse(token).context("--token")?),
        (None, Some(path)) => {
            let text =
                std::fs::read_to_string(path).with_context(|| format!("reading token file {}", path.display()))?;
            Some(arena_shared::token::parse(&text).with_context(|| format!("token file {}", path.display()))?)
        }
        (None, None) => None,
    };
    match token {
        Some(token) if token.len() < 16 => {
            anyhow::bail!("the token must be at least 16 characters (got {})", token.len())
        }
        token => Ok(token),
    }
}

/// Serves `state` on `listener` until `shutdown` completes, within the connection
/// limits of its configuration (see [`serve`](crate::serve)).
///
/// # Errors
///
/// I/O errors of the listener.
pub async fn serve(
    listener: tokio::net::TcpListener,
    state: AppState,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> std::io::Result<()> {
    let config = &state.config;
    let limits = serve::ConnLimits {
        max_connections: config.max_connections,
        header_timeout: std::time::Duration::from_millis(config.header_timeout_ms.max(1)),
        shutdown_grace: std::time::Duration::from_millis(config.shutdown_grace_ms),
        max_head_bytes: 256 << 10,
        min_body_rate: serve::MIN_BODY_RATE,
        probation_slots: state.token.is_some().then(|| serve::probation_slots(config.max_connections)),
    };
    let desktop = Arc::clone(&state.desktop);
    let shutdown = async move {
        shutdown.await;
        // Running work (typing, interpreter runs, waits in a backend call) is told to
        // stop now; requests in flight then answer within the grace period.
        let told = call::cancel_all(&desktop);
        tracing::info!(running_calls = told, "shutting down: running backend calls told to stop");
    };
    serve::serve(listener, router(state), limits, shutdown).await
}
