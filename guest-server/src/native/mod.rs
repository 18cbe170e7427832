//! PLACEHOLDER: the native /v1 routes are being written.

use axum::Router;

use crate::state::AppState;

/// The native API.
pub fn routes() -> Router<AppState> {
    Router::new()
}
