//! Shared server state handed to every handler.

use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::config::ServerConfig;
use crate::desktop::Desktop;

/// State of every handler: the backend and the configuration. (The WAA layer's
/// session state is its own: see [`crate::waa::routes`].)
///
/// One `Arc` around all of it: the router clones the state for every request (the
/// middleware and the handler each take a copy), so a clone is one reference count,
/// not one per field.
#[derive(Debug, Clone)]
pub struct AppState(Arc<Shared>);

/// What [`AppState`] holds.
#[derive(Debug)]
pub struct Shared {
    pub desktop: Arc<dyn Desktop>,
    pub config: Arc<ServerConfig>,
    /// The bearer token in force, if any.
    pub token: Option<Arc<str>>,
    pub started: Instant,
    /// The last health report and when it was made, shared by concurrent polls.
    pub health: Arc<tokio::sync::Mutex<Option<(Instant, arena_shared::health::HealthReport)>>>,
    /// Who drives the keyboard and mouse: action batches share it (read), the doctor
    /// takes it alone (write), so it waits for running batches and none starts while
    /// it types into its Notepad.
    pub input: Arc<tokio::sync::RwLock<()>>,
    /// The programs running now and the interpreter memory they share.
    pub programs: Arc<crate::programs::Programs>,
    /// The shell's history for the `shell` health component (`--settle-idle-ms`).
    pub settle: Arc<std::sync::Mutex<crate::desktop::settle::Settle>>,
}

impl std::ops::Deref for AppState {
    type Target = Shared;

    fn deref(&self) -> &Shared {
        &self.0
    }
}

impl AppState {
    pub fn new(desktop: Arc<dyn Desktop>, config: ServerConfig, token: Option<String>) -> AppState {
        let programs = Arc::new(crate::programs::Programs::from_config(&config));
        let settle = crate::desktop::settle::Settle::new(Duration::from_millis(config.settle_idle_ms));
        AppState(Arc::new(Shared {
            desktop,
            programs,
            config: Arc::new(config),
            token: token.map(Arc::from),
            started: Instant::now(),
            health: Arc::default(),
            input: Arc::default(),
            settle: Arc::new(std::sync::Mutex::new(settle)),
        }))
    }

    /// A share of the keyboard and mouse, held by every request that may drive them
    /// (action batches, `/execute` and `/execute_windows` code, `/v1/exec` programs,
    /// MCP input and Python tools): the doctor, which takes them alone, waits until
    /// every share is given back, and no share is given while it runs.
    pub async fn input_share(&self) -> tokio::sync::RwLockReadGuard<'_, ()> {
        self.input.read().await
    }

    /// Deadline of an ordinary backend call.
    pub fn call_timeout(&self) -> Duration {
        self.config.call_timeout()
    }
}
