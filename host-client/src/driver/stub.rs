//! The embedded stub guest: `arena serve-stub`, the guests of `arena run
//! --stub-guests`, and the guest `arena demo` starts when it is given none.
//!
//! It runs the real `arena-guest` router over its deterministic stub desktop
//! in this process, so the host side can be tried without a VM.
//! It is not a second server implementation: everything is `arena_guest`'s.
//!
//! The embedded guest is the `stub-guest` feature (on by default). A host built
//! without it (`--no-default-features`) has no server code in it; then `serve-stub`
//! does not exist, and `demo` and `run --stub-guests` without a guest say so.

use std::net::{IpAddr, SocketAddr};
use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use tokio::task::JoinHandle;

#[cfg(feature = "stub-guest")]
use arena_guest::config::ServerConfig;

/// A stub guest's settings; also the arguments of `arena serve-stub`.
#[derive(Debug, Clone, Args)]
pub struct StubArgs {
    /// TCP port (0 picks a free one).
    #[arg(long, default_value_t = 5000)]
    pub port: u16,
    /// Address to bind; anything but loopback needs --token.
    #[arg(long, default_value = "127.0.0.1")]
    pub bind: IpAddr,
    /// Directory the guest's drives are mapped into (default: a temporary directory).
    #[arg(long, value_name = "DIR")]
    pub root: Option<PathBuf>,
    /// JSON scenario seeding windows, files, clipboard, registry and programs.
    #[arg(long, value_name = "FILE")]
    pub scenario: Option<PathBuf>,
    /// Screen size as WIDTHxHEIGHT.
    #[arg(long, default_value = "1440x900", value_parser = parse_screen)]
    pub screen: (u32, u32),
    /// Run commands that are none of the stub's simulated programs as REAL processes
    /// on this machine (off: refused, so agent code starts nothing on the host).
    #[arg(long)]
    pub stub_host_exec: bool,
}

impl Default for StubArgs {
    fn default() -> StubArgs {
        StubArgs {
            port: 0,
            bind: IpAddr::from([127, 0, 0, 1]),
            root: None,
            scenario: None,
            screen: (1440, 900),
            stub_host_exec: false,
        }
    }
}

/// A stub guest serving in a background task.
#[derive(Debug)]
pub struct RunningStub {
    pub addr: SocketAddr,
    task: JoinHandle<std::io::Result<()>>,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
}

impl RunningStub {
    /// `http://ADDR`.
    pub fn url(&self) -> String {
        format!("http://{}", self.addr)
    }

    /// Stops serving and waits for the server to finish.
    ///
    /// # Errors
    ///
    /// The server failed while serving.
    pub async fn stop(mut self) -> anyhow::Result<()> {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        (&mut self.task).await.context("the stub guest task failed")?.context("the stub guest failed")
    }
}

/// What a host built without the embedded guest answers where one is needed.
#[cfg(not(feature = "stub-guest"))]
fn not_built_in() -> anyhow::Error {
    anyhow::format_err!(
        "this arena was built without the embedded stub guest (the stub-guest feature); \
         point it at a guest with --guest, or run arena-guest --backend stub"
    )
}

#[cfg(feature = "stub-guest")]
fn server_config(args: &StubArgs, token: Option<String>) -> ServerConfig {
    let mut config = ServerConfig::for_stub();
    config.bind = args.bind;
    config.port = args.port;
    config.stub_root = args.root.clone();
    config.scenario = args.scenario.clone();
    config.screen = args.screen;
    config.stub_host_exec = args.stub_host_exec;
    config.token = token;
    config
}

/// Binds and builds the stub guest; returns the listener and state to serve.
#[cfg(feature = "stub-guest")]
async fn prepare(
    args: &StubArgs,
    token: Option<String>,
) -> anyhow::Result<(tokio::net::TcpListener, arena_guest::state::AppState)> {
    let config = server_config(args, token);
    let addr = SocketAddr::new(config.bind, config.port);
    let state = arena_guest::build_state(config).context("building the stub guest")?;
    let listener = tokio::net::TcpListener::bind(addr).await.with_context(|| format!("binding {addr}"))?;
    Ok((listener, state))
}

/// Starts a stub guest in a background task of the current runtime.
///
/// # Errors
///
/// The address cannot be bound, or the scenario or root is unusable; or this host
/// was built without the embedded guest.
#[cfg(feature = "stub-guest")]
pub async fn start(args: &StubArgs, token: Option<String>) -> anyhow::Result<RunningStub> {
    let (listener, state) = prepare(args, token).await?;
    let addr = listener.local_addr().context("reading the bound address")?;
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let task = tokio::spawn(arena_guest::serve(listener, state, async move {
        let _ = stopped.await;
    }));
    tracing::info!(%addr, "stub guest started");
    Ok(RunningStub { addr, task, stop: Some(stop) })
}

/// Serves a stub guest in the foreground until `shutdown` completes,
/// calling `on_listening` with the bound address first.
///
/// # Errors
///
/// As [`start`], and I/O errors while serving.
#[cfg(feature = "stub-guest")]
pub async fn serve_until(
    args: &StubArgs,
    token: Option<String>,
    on_listening: impl FnOnce(SocketAddr),
    shutdown: impl std::future::Future<Output = ()> + Send + 'static,
) -> anyhow::Result<()> {
    let (listener, state) = prepare(args, token).await?;
    let addr = listener.local_addr().context("reading the bound address")?;
    on_listening(addr);
    arena_guest::serve(listener, state, shutdown).await.with_context(|| format!("serving on {addr}"))
}

/// Without the embedded guest: always the error saying how to get a guest.
///
/// # Errors
///
/// Always.
#[cfg(not(feature = "stub-guest"))]
pub async fn start(_args: &StubArgs, _token: Option<String>) -> anyhow::Result<RunningStub> {
    Err(not_built_in())
}

fn parse_screen(text: &str) -> Result<(u32, u32), String> {
    let (w, h) = text.split_once(['x', 'X']).ok_or_else(|| format!("{text:?} is not WIDTHxHEIGHT"))?;
    let number = |s: &str| s.trim().parse::<u32>().ok().filter(|n| (16..=16384).contains(n));
    match (number(w), number(h)) {
        (Some(w), Some(h)) => Ok((w, h)),
        _ => Err(format!("{text:?} needs two whole numbers from 16 to 16384, as in 1440x900")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn screen_sizes() {
        fn check(input: &str, expected: Result<(u32, u32), ()>) {
            assert_eq!(parse_screen(input).map_err(drop), expected, "{input:?}");
        }
        check("1440x900", Ok((1440, 900)));
        check("800X600", Ok((800, 600)));
        check("1440", Err(()));
        check("0x900", Err(()));
        check("axb", Err(()));
    }
}
