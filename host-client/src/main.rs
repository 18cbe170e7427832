//! `arena`: the host command line. Parses, sets up logging on stderr, and
//! hands over to [`arena_host::run`]; everything else lives in the library.

#![forbid(unsafe_code)]

use std::io::IsTerminal;
use std::process::ExitCode;

use tracing_subscriber::layer::SubscriberExt as _;
use tracing_subscriber::util::SubscriberInitExt as _;
use tracing_subscriber::{EnvFilter, Layer as _};

#[tokio::main]
async fn main() -> ExitCode {
    let cli = arena_host::Cli::parse_args();
    // An outside agent's stderr (target `arena::agent`) is part of the run's log.
    let filter = EnvFilter::try_from_env("ARENA_LOG").unwrap_or_else(|_| EnvFilter::new("warn,arena::agent=info"));
    // An MCP agent asking for sessions while all are busy gets a counted warning, not
    // one error line per request.
    #[cfg(feature = "mcp-endpoint")]
    let filter = tracing_subscriber::filter::FilterExt::and(filter, arena_mcp::without_refusal_noise());
    let layer = tracing_subscriber::fmt::layer()
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal())
        .with_filter(filter);
    tracing_subscriber::registry().with(layer).init();
    match arena_host::run(cli).await {
        Ok(code) => code,
        Err(err) => {
            eprintln!("error: {err:#}");
            ExitCode::FAILURE
        }
    }
}
