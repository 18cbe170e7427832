//! The options of the outside agents of `arena run` (`--agent exec`, `--agent
//! http`, `--agent mcp`); `runs` flattens [`ExternalArgs`] into its arguments.
//! The exec and HTTP agents are built by `arena_agents::factory` from them, the
//! MCP endpoint by `crate::run::mcp` from [`ExternalArgs::mcp_plan`].

use clap::Args;

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
    /// Exec, HTTP and MCP agents: longest wait for one answer, in seconds (for MCP:
    /// for a session to take an offered episode, and for each tool call after);
    /// past it the episode ends as an agent error (an exec process is replaced).
    #[arg(long, default_value_t = 300.0, value_name = "SECONDS")]
    pub agent_timeout: f64,
    /// Exec agent: where its process runs. `bwrap` (the default on Linux; needs
    /// Debian's `bubblewrap`): its own user, PID and mount namespaces, the file system
    /// read-only with --tasks, --out and the download cache hidden, a home of its own,
    /// and only the listed variables (docs/agents.md, "What each transport trusts").
    /// `none` (the default elsewhere): as the harness's user with its view. Recorded.
    #[arg(long, value_enum, value_name = "MODE")]
    pub agent_sandbox: Option<SandboxArg>,
    /// Exec agent in a sandbox: `host` (its model calls go out as the harness's do)
    /// or `none` (loopback only). Recorded.
    #[arg(long, value_enum, default_value_t = NetworkArg::Host, value_name = "NETWORK")]
    pub agent_network: NetworkArg,
    /// Exec agent in a sandbox: one more environment variable it keeps (repeatable);
    /// it keeps PATH, the locale, Python's and the model providers' usual key and URL
    /// variables anyway, and never the guest's token.
    #[arg(long, value_name = "NAME")]
    pub agent_env: Vec<String>,
    /// Exec agent in a sandbox: a folder it may write in (its own logs, a cache),
    /// bound at the same path (repeatable); it may not overlap --tasks, --out or the cache.
    #[arg(long, value_name = "DIR")]
    pub agent_writable: Vec<std::path::PathBuf>,
    /// MCP agent: where to serve MCP (`http://ADDR/mcp`), e.g. 127.0.0.1:8765.
    #[arg(long, value_name = "ADDR")]
    pub mcp_listen: Option<String>,
    /// MCP agent: the bearer token clients must send [default: generated, printed
    /// and written to `<out>/mcp-token`].
    #[arg(long, env = "ARENA_MCP_TOKEN", value_name = "TOKEN", hide_env_values = true)]
    pub mcp_token: Option<String>,
}

/// `--agent-sandbox`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum SandboxArg {
    Bwrap,
    None,
}

/// `--agent-network`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum NetworkArg {
    Host,
    None,
}

impl ExternalArgs {
    /// The exec agent's sandbox, hiding `hidden` (the run's tasks, output and cache).
    pub(crate) fn sandbox(&self, hidden: Vec<std::path::PathBuf>) -> arena_agents::external::sandbox::SandboxOptions {
        use arena_agents::external::sandbox::{AgentNetwork, SandboxMode, SandboxOptions};
        SandboxOptions {
            mode: match self.agent_sandbox {
                Some(SandboxArg::Bwrap) => SandboxMode::Bwrap,
                Some(SandboxArg::None) => SandboxMode::None,
                None => SandboxMode::default_here(),
            },
            network: match self.agent_network {
                NetworkArg::Host => AgentNetwork::Host,
                NetworkArg::None => AgentNetwork::None,
            },
            hidden,
            env: self.agent_env.clone(),
            writable: self.agent_writable.clone(),
        }
    }

    /// What `--agent mcp` takes from these options.
    pub(crate) fn mcp_plan(&self) -> crate::driver::mcp::McpPlan {
        crate::driver::mcp::McpPlan {
            listen: self.mcp_listen.clone(),
            token: self.mcp_token.clone(),
            agent_timeout: self.agent_timeout,
        }
    }
}
