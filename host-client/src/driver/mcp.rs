//! The MCP endpoint of `arena run --agent mcp` as a run uses it: bound and
//! handed to the agent factory before the run ([`mcp`]), served beside the
//! tasks while they run ([`run_with_mcp`]). The endpoint itself is `crate::mcp`.
//!
//! It serves HTTP, so it is built only with the `mcp-endpoint` feature (a
//! default feature); without it `--agent mcp` is an error that says so.

#[cfg(feature = "mcp-endpoint")]
pub(crate) use with_mcp::{mcp, run_with_mcp, McpEndpoint};
#[cfg(not(feature = "mcp-endpoint"))]
pub(crate) use without_mcp::{mcp, run_with_mcp, McpEndpoint};

/// What `--agent mcp` was given: where to listen, the token clients must send
/// (else one is generated) and the longest wait for a session or a tool call.
#[derive(Debug, Clone, Default)]
// Read only by the endpoint, which a build without `mcp-endpoint` does not have.
#[cfg_attr(not(feature = "mcp-endpoint"), allow(dead_code))]
pub(crate) struct McpPlan {
    pub(crate) listen: Option<String>,
    pub(crate) token: Option<String>,
    pub(crate) agent_timeout: f64,
}

#[cfg(feature = "mcp-endpoint")]
mod with_mcp {
    use std::sync::Arc;
    use std::time::Duration;

    use anyhow::{bail, Context};
    use tokio_util::sync::CancellationToken;

    use super::McpPlan;
    use crate::episode::EpisodeRunner;
    use crate::run::{run_tasks, RunOptions, RunOutcome};
    use arena_agents::factory::{agent_timeout, ChosenAgent};
    use arena_agents::{Agent, AgentFactory};
    use arena_client::GuestClient;
    use arena_results::ResultsError;
    use arena_task::Task;

    /// The MCP endpoint of a run: its hub, where it listens and its token.
    pub(crate) struct McpEndpoint {
        hub: Arc<crate::mcp::Hub>,
        listener: tokio::net::TcpListener,
        token: String,
        token_file: Option<std::path::PathBuf>,
    }

    impl McpEndpoint {
        /// `http://ADDR/mcp`.
        pub(crate) fn url(&self) -> String {
            match self.listener.local_addr() {
                Ok(addr) => format!("http://{addr}/mcp"),
                Err(_) => "(unknown address)".to_owned(),
            }
        }

        /// The bearer token clients must send.
        pub(crate) fn token(&self) -> &str {
            &self.token
        }

        /// Where a generated token was written (the command line prints it).
        pub(crate) fn token_file(&self) -> Option<&std::path::Path> {
            self.token_file.as_deref()
        }
    }

    impl std::fmt::Debug for McpEndpoint {
        fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            f.debug_struct("McpEndpoint").field("listener", &self.listener.local_addr().ok()).finish_non_exhaustive()
        }
    }

    /// `--agent mcp`: binds `--mcp-listen`, settles the token (given, or generated
    /// and written to `<out>/mcp-token`), and answers the agent factory.
    ///
    /// # Errors
    ///
    /// No `--mcp-listen`, an address that cannot be bound, a token file that cannot be written.
    pub(crate) async fn mcp(
        args: &McpPlan,
        max_steps: u32,
        out: &std::path::Path,
        model: Option<String>,
    ) -> anyhow::Result<(ChosenAgent, McpEndpoint)> {
        let timeout = agent_timeout(args.agent_timeout)?;
        let Some(listen) = &args.listen else { bail!("--agent mcp needs --mcp-listen ADDR (e.g. 127.0.0.1:8765)") };
        let listener = tokio::net::TcpListener::bind(listen.as_str())
            .await
            .with_context(|| format!("binding --mcp-listen {listen}"))?;
        let addr = listener.local_addr().context("the MCP listener's address")?;
        let mut token_file = None;
        let token = match &args.token {
            Some(token) => arena_shared::token::parse(token).map_err(|err| anyhow::anyhow!("--mcp-token: {err}"))?,
            None => {
                let token = crate::mcp::generate_token();
                std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
                let file = out.join("mcp-token");
                arena_shared::atomic::write_atomic(&file, token.as_bytes())
                    .with_context(|| format!("writing {}", file.display()))?;
                #[cfg(unix)]
                {
                    use std::os::unix::fs::PermissionsExt as _;
                    let _ = std::fs::set_permissions(&file, std::fs::Permissions::from_mode(0o600));
                }
                token_file = Some(file);
                token
            }
        };
        let hub = crate::mcp::Hub::new();
        let agent_hub = Arc::clone(&hub);
        let factory: AgentFactory = Arc::new(move || {
            Ok(Box::new(crate::mcp::McpAgent::new(Arc::clone(&agent_hub), max_steps, timeout)) as Box<dyn Agent>)
        });
        let options = vec![
            ("mcp_listen".to_owned(), addr.to_string()),
            ("agent_timeout".to_owned(), format!("{}", args.agent_timeout)),
        ];
        let model = model.unwrap_or_else(|| "external".to_owned());
        // An MCP client connects when it will; there is no agent to ask first.
        let chosen = ChosenAgent { factory, label: "mcp".to_owned(), model, options, preflight: None };
        Ok((chosen, McpEndpoint { hub, listener, token, token_file }))
    }

    /// Runs `tasks` with the MCP endpoint served beside them; at the end, sessions
    /// waiting for a task are told there is none, then the server stops.
    ///
    /// # Errors
    ///
    /// As [`run_tasks`].
    pub(crate) async fn run_with_mcp(
        endpoint: McpEndpoint,
        tasks: Vec<Task>,
        guests: Vec<GuestClient>,
        runner: EpisodeRunner,
        options: &RunOptions,
    ) -> Result<RunOutcome, ResultsError> {
        let served = CancellationToken::new();
        let server = tokio::spawn(crate::mcp::server::serve(
            endpoint.listener,
            Arc::clone(&endpoint.hub),
            endpoint.token.clone(),
            served.clone(),
        ));
        endpoint.hub.set_watch(Arc::clone(&options.watch));
        let runner = crate::mcp::McpRunner { inner: runner, hub: Arc::clone(&endpoint.hub) };
        let outcome = run_tasks(tasks, guests, Arc::new(runner), options).await;
        endpoint.hub.close();
        tokio::time::sleep(Duration::from_millis(200)).await;
        served.cancel();
        let _ = server.await;
        outcome
    }
}

#[cfg(not(feature = "mcp-endpoint"))]
mod without_mcp {
    use super::McpPlan;
    use crate::episode::EpisodeRunner;
    use crate::run::{RunOptions, RunOutcome};
    use arena_agents::factory::ChosenAgent;
    use arena_client::GuestClient;
    use arena_results::ResultsError;
    use arena_task::Task;

    /// No MCP endpoint in this build: nothing can hold one.
    #[derive(Debug)]
    pub(crate) enum McpEndpoint {}

    impl McpEndpoint {
        pub(crate) fn url(&self) -> String {
            match *self {}
        }

        pub(crate) fn token(&self) -> &str {
            match *self {}
        }

        pub(crate) fn token_file(&self) -> Option<&std::path::Path> {
            match *self {}
        }
    }

    /// `--agent mcp` in a build without the endpoint.
    ///
    /// # Errors
    ///
    /// Always: this build has no MCP endpoint.
    pub(crate) async fn mcp(
        _args: &McpPlan,
        _max_steps: u32,
        _out: &std::path::Path,
        _model: Option<String>,
    ) -> anyhow::Result<(ChosenAgent, McpEndpoint)> {
        anyhow::bail!(
            "--agent mcp: this arena was built without the MCP endpoint (cargo feature `mcp-endpoint`, \
             a default feature; build with `cargo build -p arena-host --features mcp-endpoint`)"
        )
    }

    /// Never called: there is no endpoint to run with.
    ///
    /// # Errors
    ///
    /// None.
    pub(crate) async fn run_with_mcp(
        endpoint: McpEndpoint,
        _tasks: Vec<Task>,
        _guests: Vec<GuestClient>,
        _runner: EpisodeRunner,
        _options: &RunOptions,
    ) -> Result<RunOutcome, ResultsError> {
        match endpoint {}
    }
}
