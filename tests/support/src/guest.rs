//! The in-process stub guest every test starts the same way.

use std::path::Path;

use arena_guest::config::ServerConfig;

/// A stub guest serving on `127.0.0.1:0` in a task of the current runtime, over its
/// own temporary root; it stops (and the root is removed) when dropped.
#[derive(Debug)]
pub struct StubGuest {
    url: String,
    root: tempfile::TempDir,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
}

impl StubGuest {
    /// A stub guest with the defaults of `ServerConfig::for_stub()` and no token.
    ///
    /// # Panics
    ///
    /// When the guest cannot start (a test cannot go on without it).
    pub async fn start() -> StubGuest {
        StubGuest::start_with(|_| {}).await
    }

    /// A stub guest whose configuration `configure` adjusts first (token, token
    /// file, DevTools port, scenario, ...). The stub root is the guest's own.
    ///
    /// # Panics
    ///
    /// When the guest cannot start with that configuration.
    pub async fn start_with(configure: impl FnOnce(&mut ServerConfig)) -> StubGuest {
        let root = tempfile::tempdir().expect("a temporary stub root");
        let mut config = ServerConfig::for_stub();
        config.token = None;
        configure(&mut config);
        config.stub_root = Some(root.path().to_path_buf());
        let state =
            arena_guest::build_state(config).unwrap_or_else(|err| panic!("the stub guest did not start: {err:#}"));
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.expect("binding 127.0.0.1:0");
        let url = format!("http://{}", listener.local_addr().expect("the bound address"));
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        tokio::spawn(arena_guest::serve(listener, state, async move {
            let _ = stopped.await;
        }));
        StubGuest { url, root, stop: Some(stop) }
    }

    /// `http://127.0.0.1:PORT`.
    pub fn url(&self) -> &str {
        &self.url
    }

    /// The folder the guest's drives are mapped into.
    pub fn root(&self) -> &Path {
        self.root.path()
    }
}

impl Drop for StubGuest {
    fn drop(&mut self) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
    }
}
