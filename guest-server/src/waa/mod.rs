//! PLACEHOLDER: the WAA compatibility routes are being written.

use axum::Router;

use crate::state::AppState;

/// State upstream keeps in module globals.
#[derive(Debug, Default)]
pub struct WaaState {}

/// The 44 upstream routes.
pub fn routes() -> Router<AppState> {
    Router::new()
}
