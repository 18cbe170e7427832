//! `arena env serve`: the harness as an environment a program drives over HTTP
//! (`crate::envserve`, feature `env-server`), on guests given as `arena run` takes
//! them (URLs, embedded stub guests, VMs). Serves until Ctrl-C or SIGTERM, then
//! stops the guests it started.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Args, Parser, Subcommand};

use super::run_args::{DifficultyArg, GuestSource, PausesArg, RunArgs};
use super::Connection;

/// `arena env`.
#[derive(Debug, Clone, Args)]
pub struct EnvArgs {
    #[command(subcommand)]
    pub command: EnvCommand,
}

/// What `arena env` does.
#[derive(Debug, Clone, Subcommand)]
pub enum EnvCommand {
    /// Serve reset/step/evaluate over HTTP (docs/env.md): each session plays the
    /// served tasks' episodes on a guest of its own, as `arena run` plays them.
    Serve(Box<ServeArgs>),
}

/// `arena env serve`.
#[derive(Debug, Clone, Args)]
pub struct ServeArgs {
    /// Where to listen, e.g. 127.0.0.1:8766 (port 0 picks a free one; the address is printed).
    #[arg(long, value_name = "ADDR")]
    pub listen: String,
    /// The tasks a session may reset to by id or name: a task folder, a corpus root
    /// or an index file (`test_all.json`), as `arena run --tasks` takes them.
    #[arg(long, value_name = "PATH")]
    pub tasks: PathBuf,
    /// Which variant of the tasks an index resolves to.
    #[arg(long, value_enum, default_value_t = DifficultyArg::default())]
    pub difficulty: DifficultyArg,
    /// Where each episode's result folder goes.
    #[arg(long, default_value = "env-results", value_name = "DIR")]
    pub out: PathBuf,
    /// Step cap per episode (upstream: 15).
    #[arg(long, default_value_t = crate::episode::DEFAULT_MAX_STEPS)]
    pub max_steps: u32,
    /// `upstream` or `fast` pauses, as `arena run --pauses` (fast with --stub-guests).
    #[arg(long, value_enum)]
    pub pauses: Option<PausesArg>,
    /// Pause after each action, in seconds.
    #[arg(long, value_name = "SECONDS")]
    pub sleep_after: Option<f64>,
    /// A session whose client sends nothing for this many seconds ends and frees its guest.
    #[arg(long, default_value_t = 600, value_name = "SECONDS")]
    pub idle_secs: u64,
    /// A bearer token every client must send (`Authorization: Bearer TOKEN`;
    /// `ArenaEnv(url, token=...)` or `ARENA_ENV_TOKEN` on the client's side). Without
    /// one, --listen must be a loopback address.
    #[arg(long, env = "ARENA_ENV_TOKEN", value_name = "TOKEN", hide_env_values = true)]
    pub env_token: Option<String>,
    /// Let a task sent whole (a task object in a reset) fetch URLs from this machine
    /// (its `download` steps); without it such a task is refused. Tasks served from
    /// --tasks may always.
    #[arg(long)]
    pub allow_downloads: bool,
    #[command(flatten)]
    pub source: GuestSource,
}

/// `arena run`'s arguments alone, for its defaults (the guests are started as a run starts them).
#[derive(Parser)]
struct RunOnly {
    #[command(flatten)]
    run: RunArgs,
}

/// `arena env ...`.
///
/// # Errors
///
/// Unusable arguments, tasks that do not load, no guest, an address that cannot be bound.
pub async fn run(conn: &Connection, args: EnvArgs) -> anyhow::Result<ExitCode> {
    match args.command {
        EnvCommand::Serve(serve) => serve_env(conn, *serve).await,
    }
}

#[cfg(not(feature = "env-server"))]
async fn serve_env(_conn: &Connection, _args: ServeArgs) -> anyhow::Result<ExitCode> {
    anyhow::bail!("this arena was built without the env-server feature: arena env serve is not available")
}

#[cfg(feature = "env-server")]
async fn serve_env(conn: &Connection, args: ServeArgs) -> anyhow::Result<ExitCode> {
    use std::sync::Arc;
    use std::time::Duration;

    use anyhow::Context as _;

    let tasks = crate::run::load_tasks(&args.tasks, args.difficulty.into())?;
    let parsed =
        RunOnly::try_parse_from([std::ffi::OsStr::new("arena-run"), "--tasks".as_ref(), args.tasks.as_os_str()])
            .context("the run's defaults")?;
    let mut run = parsed.run;
    run.source = args.source.clone();
    run.out = args.out.clone();
    let cache_dir = args.out.join("download-cache");
    let cache = arena_client::cache::DownloadCache::new(&cache_dir)
        .with_context(|| format!("opening the download cache {}", cache_dir.display()))?;
    let fast = match args.pauses {
        Some(PausesArg::Fast) => true,
        Some(PausesArg::Upstream) => false,
        None => args.source.stub_guests.is_some(),
    };
    let mut config = if fast {
        crate::episode::EpisodeConfig::instant(cache)
    } else {
        crate::episode::EpisodeConfig::upstream(cache)
    };
    config.max_steps = args.max_steps;
    if let Some(secs) = args.sleep_after {
        config.sleep_after_action =
            Duration::try_from_secs_f64(secs).context("--sleep-after must be a number of seconds, 0 or more")?;
    }
    config.options.insert("env".into(), "on".into());
    let token = args.env_token.clone().filter(|t| !t.trim().is_empty());
    let listener = tokio::net::TcpListener::bind(args.listen.as_str())
        .await
        .with_context(|| format!("binding --listen {}", args.listen))?;
    let addr = listener.local_addr().context("the listener's address")?;
    if token.is_none() && !addr.ip().is_loopback() {
        anyhow::bail!(
            "--listen {} is not a loopback address: anyone who reaches it could drive the guests, so give \
             --env-token TOKEN (or ARENA_ENV_TOKEN) for clients to send, or listen on 127.0.0.1",
            args.listen
        );
    }
    let guests = super::runs::start_guests(conn, &run).await?;
    let stop = tokio_util::sync::CancellationToken::new();
    config.stop = stop.clone();
    let screen = match guests.clients.first() {
        Some(guest) => guest.screen().await.ok().map(|s| (s.physical_width, s.physical_height)),
        None => None,
    };
    let options = crate::envserve::EnvOptions {
        out: args.out.clone(),
        config,
        idle: Duration::from_secs(args.idle_secs),
        screen,
        token,
        allow_downloads: args.allow_downloads,
    };
    super::emit(&format!("{}\n", crate::envserve::describe(addr, &tasks, guests.clients.len())))?;
    let server = crate::envserve::EnvServer::new(tasks, guests.clients.clone(), options);
    let served = tokio::spawn(crate::envserve::serve(Arc::clone(&server), listener, stop.clone()));
    crate::cli::signals::interrupt().await;
    stop.cancel();
    let outcome = served.await;
    drop(server);
    guests.stop().await;
    match outcome {
        Ok(Ok(())) => Ok(ExitCode::SUCCESS),
        Ok(Err(err)) => Err(anyhow::Error::new(err).context("serving the environment")),
        Err(err) => Err(anyhow::anyhow!("the environment's server stopped: {err}")),
    }
}
