//! Shared server state handed to every handler.

use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::config::ServerConfig;
use crate::desktop::Desktop;

/// State of every handler: the backend, the configuration and the WAA session state.
#[derive(Debug, Clone)]
pub struct AppState {
    pub desktop: Arc<dyn Desktop>,
    pub config: Arc<ServerConfig>,
    /// The bearer token in force, if any.
    pub token: Option<Arc<str>>,
    pub started: Instant,
    /// State that upstream keeps in module globals (`computer`, recording, human input).
    pub waa: Arc<crate::waa::WaaState>,
}

impl AppState {
    pub fn new(desktop: Arc<dyn Desktop>, config: ServerConfig, token: Option<String>) -> AppState {
        AppState {
            desktop,
            config: Arc::new(config),
            token: token.map(Arc::from),
            started: Instant::now(),
            waa: Arc::new(crate::waa::WaaState::default()),
        }
    }

    /// Deadline of an ordinary backend call.
    pub fn call_timeout(&self) -> Duration {
        self.config.call_timeout()
    }
}
