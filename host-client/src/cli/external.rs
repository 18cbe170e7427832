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
    /// MCP agent: where to serve MCP (`http://ADDR/mcp`), e.g. 127.0.0.1:8765.
    #[arg(long, value_name = "ADDR")]
    pub mcp_listen: Option<String>,
    /// MCP agent: the bearer token clients must send [default: generated, printed
    /// and written to `<out>/mcp-token`].
    #[arg(long, env = "ARENA_MCP_TOKEN", value_name = "TOKEN", hide_env_values = true)]
    pub mcp_token: Option<String>,
}

impl ExternalArgs {
    /// What `--agent mcp` takes from these options.
    pub(crate) fn mcp_plan(&self) -> crate::driver::mcp::McpPlan {
        crate::driver::mcp::McpPlan {
            listen: self.mcp_listen.clone(),
            token: self.mcp_token.clone(),
            agent_timeout: self.agent_timeout,
        }
    }
}
