//! The typed native API under `/v1/`, spoken by the Rust host client.
//!
//! Every route takes and returns the wire types of `arena_shared`, answers
//! errors with the one [`arena_shared::error::ErrorBody`] shape (through
//! [`crate::error::ApiError`], [`crate::error::AppJson`] and
//! [`crate::error::AppQuery`]), and reaches the desktop only through
//! [`crate::call::blocking`], so every backend call has a deadline.
//! It is not the legacy WAA surface (see [`crate::waa`]) and holds no
//! platform code: the backend behind [`crate::desktop::Desktop`] does that.
//!
//! The reference with every route, its types and statuses is `docs/native-api.md`.
//!
//! # Layout
//!
//! One private module per resource, each exposing its own `routes()`:
//! `health`, `screen`, `input`, `a11y`, `windows`, `clipboard`, `files`,
//! `exec` (exec, launch, open), `registry` (registry, wallpaper), `clock` (the
//! wall clock the host sets after a restore), `doctor`
//! (every capability end to end), `browser` (the browser's DevTools HTTP endpoint,
//! forwarded) and `browser_ws` (its DevTools websocket, relayed).
//!
//! Body limits by route family: `/v1/actions` [`crate::config::ACTIONS_BODY_BYTES`],
//! `/v1/clipboard` [`crate::config::CLIPBOARD_BODY_BYTES`], `PUT /v1/files` streams up
//! to `--max-body-bytes`, and every other route [`crate::config::JSON_BODY_BYTES`].

mod a11y;
mod browser;
mod browser_ws;
mod clipboard;
mod clock;
mod doctor;
pub use doctor::ask_running_server;
mod eval_queries;
mod exec;
mod files;
mod health;
pub(crate) mod input;
mod registry;
mod screen;
mod windows;

use std::time::Duration;

use axum::Router;

use crate::state::AppState;

/// The native API: every `/v1/` route.
pub fn routes() -> Router<AppState> {
    use crate::config::{CLIPBOARD_BODY_BYTES, JSON_BODY_BYTES};
    use axum::extract::DefaultBodyLimit;
    let control = Router::new()
        .merge(health::routes())
        .merge(screen::routes())
        .merge(a11y::routes())
        .merge(windows::routes())
        .merge(doctor::routes())
        // `PUT /v1/files` reads its body as a stream, bounded by `--max-body-bytes` itself.
        .merge(files::routes())
        .merge(exec::routes())
        .merge(registry::routes())
        .merge(clock::routes())
        .merge(browser::routes())
        .merge(browser_ws::routes())
        .merge(eval_queries::routes())
        .layer(DefaultBodyLimit::max(JSON_BODY_BYTES));
    Router::new()
        .merge(control)
        // Its own limit, set in `input::routes`.
        .merge(input::routes())
        .merge(clipboard::routes().layer(DefaultBodyLimit::max(CLIPBOARD_BODY_BYTES)))
}

/// Milliseconds of `d`, saturating (a `u64` of milliseconds outlasts any uptime).
fn millis(d: Duration) -> u64 {
    u64::try_from(d.as_millis()).unwrap_or(u64::MAX)
}
