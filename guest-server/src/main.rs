//! `arena-guest`: parses the command line ([`arena_guest::cli`]), sets up logging, and
//! serves (the default) or runs a `service` / `logon-task` subcommand from
//! [`arena_guest::service`], or the `doctor` ([`arena_guest::doctor`]).

#![forbid(unsafe_code)]

use std::net::SocketAddr;
use std::process::ExitCode;

use clap::Parser;
use tracing_subscriber::filter::FilterExt as _;
use tracing_subscriber::layer::SubscriberExt as _;
use tracing_subscriber::util::SubscriberInitExt as _;
use tracing_subscriber::Layer as _;

use arena_guest::cli::{Cli, Command, ServiceCommand};
use arena_guest::config::{LogFormat, ServerConfig};

fn main() -> ExitCode {
    // The Windows backend's UI Automation worker process (a hidden subcommand).
    if let Some(ended) = arena_guest::desktop::windows::uia_worker_from_args() {
        return match ended {
            Ok(()) => ExitCode::SUCCESS,
            Err(err) => {
                eprintln!("error: {err}");
                ExitCode::FAILURE
            }
        };
    }
    let cli = Cli::parse();
    let outcome = match &cli.command {
        None => return serve(cli.serve),
        // The supervisor logs to its own file (a service has no console); see service.
        Some(Command::Service(command @ ServiceCommand::Run(_))) => arena_guest::service::execute_service(command),
        Some(Command::Service(command)) => {
            init_tracing(LogFormat::Text, false);
            arena_guest::service::execute_service(command)
        }
        Some(Command::Doctor(args)) => return doctor(args),
        Some(Command::LogonTask(command)) => {
            init_tracing(LogFormat::Text, false);
            arena_guest::service::execute_logon_task(command)
        }
    };
    match outcome {
        Ok(message) => {
            if !message.is_empty() {
                println!("{message}");
            }
            ExitCode::SUCCESS
        }
        Err(err) => {
            eprintln!("error: {err}");
            ExitCode::from(err.exit_code())
        }
    }
}

/// `arena-guest doctor`: asks the server running on its port, or builds the backend as
/// the server would and checks it.
fn doctor(args: &arena_guest::cli::DoctorArgs) -> ExitCode {
    init_tracing(LogFormat::Text, false);
    let token = match arena_guest::resolve_token(&args.serve) {
        Ok(token) => token,
        Err(err) => {
            eprintln!("error: {err:#}");
            return ExitCode::FAILURE;
        }
    };
    // A server on this port drives the same desktop: its own doctor takes turns with
    // its actions, where one run from here would type over a running episode. Only
    // when none answers is a backend of this process built.
    let running = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|err| format!("starting the async runtime: {err}"))
        .and_then(|rt| rt.block_on(arena_guest::native::ask_running_server(&args.serve, token.as_deref())));
    let report = match running {
        Ok(Some(report)) => {
            eprintln!("(the checks ran inside the arena-guest serving on port {})", args.serve.port);
            report
        }
        Ok(None) => match arena_guest::build_state(args.serve.clone()) {
            Ok(state) => {
                let options = arena_guest::doctor::DoctorOptions::for_server(&args.serve, state.token.is_some());
                arena_guest::doctor::run(state.desktop.as_ref(), &options)
            }
            Err(err) => {
                eprintln!("error: {err:#}");
                return ExitCode::FAILURE;
            }
        },
        Err(err) => {
            eprintln!("error: {err}");
            return ExitCode::FAILURE;
        }
    };
    if args.json {
        match serde_json::to_string_pretty(&report) {
            Ok(json) => println!("{json}"),
            Err(err) => {
                eprintln!("error: writing the report as JSON: {err}");
                return ExitCode::FAILURE;
            }
        }
    } else {
        print!("{}", report.render_text());
    }
    if report.passed() {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}

fn serve(config: ServerConfig) -> ExitCode {
    // A worker's output goes to a log file: no colour codes there.
    init_tracing(config.log_format, config.worker);
    let runtime = match tokio::runtime::Runtime::new() {
        Ok(rt) => rt,
        Err(err) => {
            eprintln!("error: starting the async runtime: {err}");
            return ExitCode::FAILURE;
        }
    };
    let result = runtime.block_on(run(config));
    // Backend calls were told to stop at shutdown; one stuck inside the operating
    // system must not keep the process alive (dropping the runtime would wait for it).
    runtime.shutdown_timeout(std::time::Duration::from_secs(2));
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("error: {err:#}");
            ExitCode::FAILURE
        }
    }
}

async fn run(config: ServerConfig) -> anyhow::Result<()> {
    use anyhow::Context;
    let addr = SocketAddr::new(config.bind, config.port);
    let worker = config.worker;
    if worker {
        tracing::info!(
            pid = std::process::id(),
            "started as the service's worker; stops when its standard input closes"
        );
    }
    let state = arena_guest::build_state(config)?;
    let listener = tokio::net::TcpListener::bind(addr).await.with_context(|| format!("binding {addr}"))?;
    let local = listener.local_addr().context("reading the bound address")?;
    // Scripts and tests read this exact line to learn the port.
    tracing::info!(backend = state.desktop.kind(), "listening on http://{local}");
    println!("listening on http://{local}");
    arena_guest::serve(listener, state, shutdown_signal(worker)).await.context("serving")?;
    tracing::info!("shut down");
    Ok(())
}

fn init_tracing(format: LogFormat, plain: bool) {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| "arena_guest=info,arena_mcp=warn,tower_http=warn".into());
    let layer = tracing_subscriber::fmt::layer().with_writer(std::io::stderr).with_ansi(!plain);
    // A client asking for MCP sessions while all are busy gets a counted warning, not
    // one error line per request.
    let filter = filter.and(arena_mcp::without_refusal_noise());
    let registry = tracing_subscriber::registry();
    match format {
        LogFormat::Text => registry.with(layer.with_filter(filter)).init(),
        LogFormat::Json => registry.with(layer.json().with_filter(filter)).init(),
    }
}

async fn shutdown_signal(worker: bool) {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let terminate = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut sig) => {
                sig.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let terminate = std::future::pending::<()>();
    // The supervisor's stop signal: it closes the worker's standard input.
    let supervisor = async {
        if worker {
            arena_guest::service::stdin_closed().await;
            tracing::info!("standard input closed: the supervisor asks this worker to stop");
        } else {
            std::future::pending::<()>().await;
        }
    };
    tokio::select! {
        () = ctrl_c => {},
        () = terminate => {},
        () = supervisor => {},
    }
}
