//! The options of the outside agents of `arena run` (`--agent exec`, `--agent
//! http`, `--agent mcp`) and the factories that build them; `runs` flattens
//! [`ExternalArgs`] into its arguments and calls [`exec_or_http`] and [`mcp`].

use std::sync::Arc;
use std::time::Duration;

use anyhow::{bail, Context};
use clap::Args;

use crate::actionspace::Coords;
use crate::agent::external::transport::{HttpAgent, ProcessPool};
use crate::agent::external::{Connector, ExternalAgent};
use crate::agent::Agent;
use crate::episode::AgentFactory;

/// Options of the outside agents.
#[derive(Debug, Clone, Args)]
pub struct ExternalArgs {
    /// Exec agent: the agent program and its arguments, split as a POSIX shell
    /// splits words (no shell runs), e.g. "python3 -m arena_agent my_agent:Agent".
    /// One process per guest worker speaks the step protocol (docs/agents.md) on
    /// its stdin/stdout; its stderr goes into the log.
    #[arg(long, value_name = "COMMAND")]
    pub agent_cmd: Option<String>,
    /// HTTP agent: the URL each step-protocol message is POSTed to.
    #[arg(long, env = "ARENA_AGENT_URL", value_name = "URL")]
    pub agent_url: Option<String>,
    /// Exec and HTTP agents: longest wait for one answer, in seconds; past it
    /// the episode ends as an agent error (and the process is replaced).
    #[arg(long, default_value_t = 300.0, value_name = "SECONDS")]
    pub agent_timeout: f64,
    /// MCP agent: where to serve MCP (`http://ADDR/mcp`), e.g. 127.0.0.1:8765.
    #[arg(long, value_name = "ADDR")]
    pub mcp_listen: Option<String>,
    /// MCP agent: the bearer token clients must send [default: generated, printed
    /// and written to `<out>/mcp-token`].
    #[arg(long, env = "ARENA_MCP_TOKEN", value_name = "TOKEN", hide_env_values = true)]
    pub mcp_token: Option<String>,
}

/// What `runs` needs to know about the chosen outside agent.
pub(crate) struct Built {
    pub(crate) factory: AgentFactory,
    pub(crate) label: String,
    pub(crate) options: Vec<(String, String)>,
}

fn timeout(args: &ExternalArgs) -> anyhow::Result<Duration> {
    let timeout = Duration::try_from_secs_f64(args.agent_timeout)
        .context("--agent-timeout must be a number of seconds, 0 or more")?;
    if timeout.is_zero() {
        bail!("--agent-timeout must be more than 0 seconds");
    }
    Ok(timeout)
}

/// `--agent exec` (`http` false) or `--agent http`.
///
/// # Errors
///
/// The option the agent needs is missing or unusable.
pub(crate) fn exec_or_http(args: &ExternalArgs, http: bool, coords: Coords) -> anyhow::Result<Built> {
    let timeout = timeout(args)?;
    let (connector, label, option): (Arc<dyn Connector>, &str, (String, String)) = if http {
        let Some(url) = &args.agent_url else { bail!("--agent http needs --agent-url URL (or ARENA_AGENT_URL)") };
        let agent = HttpAgent::new(url, timeout).map_err(anyhow::Error::msg)?;
        (Arc::new(agent), "http", ("agent_url".to_owned(), url.clone()))
    } else {
        let Some(cmd) = &args.agent_cmd else { bail!("--agent exec needs --agent-cmd \"PROGRAM ARGS\"") };
        let pool = ProcessPool::new(cmd).map_err(anyhow::Error::msg)?;
        (Arc::new(pool), "exec", ("agent_cmd".to_owned(), cmd.clone()))
    };
    let options = vec![
        option,
        ("agent_protocol".to_owned(), crate::agent::external::protocol::PROTOCOL_VERSION.to_string()),
        ("agent_timeout".to_owned(), format!("{}", args.agent_timeout)),
    ];
    let factory: AgentFactory = Arc::new(move || {
        Ok(Box::new(ExternalAgent::new(label, Arc::clone(&connector), timeout).with_coords(coords)) as Box<dyn Agent>)
    });
    Ok(Built { factory, label: label.to_owned(), options })
}

/// The MCP endpoint of a run: its hub, where it listens and its token.
pub(crate) struct McpEndpoint {
    pub(crate) hub: Arc<crate::mcp::Hub>,
    pub(crate) listener: tokio::net::TcpListener,
    pub(crate) token: String,
}

impl std::fmt::Debug for McpEndpoint {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("McpEndpoint").field("listener", &self.listener.local_addr().ok()).finish_non_exhaustive()
    }
}

/// `--agent mcp`: binds `--mcp-listen`, settles the token (given, or generated,
/// printed and written to `<out>/mcp-token`), and answers the agent factory.
///
/// # Errors
///
/// No `--mcp-listen`, an address that cannot be bound, a token file that cannot be written.
pub(crate) async fn mcp(
    args: &ExternalArgs,
    max_steps: u32,
    out: &std::path::Path,
) -> anyhow::Result<(Built, McpEndpoint)> {
    let timeout = timeout(args)?;
    let Some(listen) = &args.mcp_listen else { bail!("--agent mcp needs --mcp-listen ADDR (e.g. 127.0.0.1:8765)") };
    let listener = tokio::net::TcpListener::bind(listen.as_str())
        .await
        .with_context(|| format!("binding --mcp-listen {listen}"))?;
    let addr = listener.local_addr().context("the MCP listener's address")?;
    let token = match &args.mcp_token {
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
            super::emit(&format!("MCP token (also in {}): {token}\n", file.display()))?;
            token
        }
    };
    super::emit(&format!("MCP endpoint: http://{addr}/mcp\n"))?;
    let hub = crate::mcp::Hub::new();
    let agent_hub = Arc::clone(&hub);
    let factory: AgentFactory = Arc::new(move || {
        Ok(Box::new(crate::mcp::McpAgent::new(Arc::clone(&agent_hub), max_steps, timeout)) as Box<dyn Agent>)
    });
    let options = vec![
        ("mcp_listen".to_owned(), addr.to_string()),
        ("agent_timeout".to_owned(), format!("{}", args.agent_timeout)),
    ];
    Ok((Built { factory, label: "mcp".to_owned(), options }, McpEndpoint { hub, listener, token }))
}
