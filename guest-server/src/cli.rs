//! The command line of `arena-guest`: serve flags (no subcommand: serve), or the
//! `service`, `logon-task` and `doctor` subcommands. Only the clap definitions: what
//! the subcommands do is in [`crate::service`] and [`crate::doctor`], the serve options
//! themselves in [`crate::config`].

use crate::config::ServerConfig;

/// The service name used when `--name` is not given.
pub const DEFAULT_SERVICE_NAME: &str = "ArenaGuest";

/// The scheduled task name used when `--name` is not given.
pub const DEFAULT_TASK_NAME: &str = "ArenaGuest";

/// The whole command line: serve flags (no subcommand: serve, as before), or a subcommand.
#[derive(Debug, Clone, clap::Parser)]
#[command(
    name = "arena-guest",
    version,
    about = "Desktop-control server for Windows agent benchmarks (WAA-compatible)",
    args_conflicts_with_subcommands = true
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Option<Command>,

    #[command(flatten)]
    pub serve: ServerConfig,
}

/// The subcommands.
#[derive(Debug, Clone, clap::Subcommand)]
pub enum Command {
    /// Run as a Windows service that starts the server in the logged-on user's session (Windows only).
    #[command(subcommand)]
    Service(ServiceCommand),
    /// Start the server at every logon through a scheduled task, as upstream WAA does (Windows only).
    #[command(subcommand)]
    LogonTask(LogonTaskCommand),
    /// Check every capability end to end on this desktop (capture, cursor, typing into
    /// Notepad, clipboard, trees, exec timeouts, files) and report pass or fail with timings.
    /// A server already serving on `--port` runs the checks itself, in turn with its actions.
    Doctor(Box<DoctorArgs>),
}

/// `arena-guest doctor`: the backend options of the server, and the output format.
#[derive(Debug, Clone, clap::Args)]
pub struct DoctorArgs {
    /// Print the report as JSON (the shape of `GET /v1/doctor`).
    #[arg(long)]
    pub json: bool,

    #[command(flatten)]
    pub serve: ServerConfig,
}

/// `arena-guest service ...`.
#[derive(Debug, Clone, clap::Subcommand)]
pub enum ServiceCommand {
    /// Register the service (automatic start, LocalSystem) and leave it stopped.
    /// An existing service of that name gets the new command line.
    Install(SupervisorOptions),
    /// Stop the service if it runs, and delete it.
    Uninstall(NameOption),
    /// Print the service's state and command line.
    Status(NameOption),
    /// The supervisor itself: what the Service Control Manager starts. Not for interactive use.
    Run(SupervisorOptions),
}

/// `arena-guest logon-task ...`.
#[derive(Debug, Clone, clap::Subcommand)]
pub enum LogonTaskCommand {
    /// Create (or replace) a task that starts the server at every logon of this user,
    /// elevated, with no time limit, at normal priority and without a console window.
    /// The task runs arena-guest-logon.exe, which must be in this exe's folder.
    Install(TaskOptions),
    /// Delete the task.
    Uninstall(TaskNameOption),
}

/// Just a service name.
#[derive(Debug, Clone, clap::Args)]
pub struct NameOption {
    /// Service name.
    #[arg(long, default_value = DEFAULT_SERVICE_NAME)]
    pub name: String,
}

/// Just a task name.
#[derive(Debug, Clone, clap::Args)]
pub struct TaskNameOption {
    /// Scheduled task name.
    #[arg(long, default_value = DEFAULT_TASK_NAME)]
    pub name: String,
}

/// The options of `service install` and `service run`.
#[derive(Debug, Clone, PartialEq, Eq, clap::Args)]
pub struct SupervisorOptions {
    /// Service name.
    #[arg(long, default_value = DEFAULT_SERVICE_NAME)]
    pub name: String,

    /// When the logged-on user's token cannot be had (Wine has no real sessions), start
    /// the worker in the service's own session instead of waiting. On real Windows that
    /// is session 0, where desktop calls are refused: for tests only.
    #[arg(long)]
    pub allow_same_session: bool,

    /// Which of the logged-on user's tokens the worker runs with. `elevated` (the
    /// default): an administrator's full token when UAC splits it, so the worker can
    /// read a token file only Administrators may read, drive elevated windows, and
    /// start programs that need elevation. `user`: the token the session has (medium
    /// integrity when UAC is on), as a program the user starts would get.
    #[arg(long, value_enum, default_value_t = WorkerToken::Elevated)]
    pub worker_token: WorkerToken,

    /// The serve options the worker gets, exactly as `arena-guest` takes them
    /// (e.g. `--bind 0.0.0.0 --port 5000 --token-file C:\arena\token`). They come last.
    #[arg(trailing_var_arg = true, allow_hyphen_values = true, value_name = "SERVE OPTIONS")]
    pub serve_args: Vec<String>,
}

/// `service install --worker-token`: which user token starts the worker.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum WorkerToken {
    /// The full administrator token when UAC gave the session a filtered one.
    #[default]
    Elevated,
    /// The session's own token, filtered or not.
    User,
}

/// The options of `logon-task install`.
#[derive(Debug, Clone, PartialEq, Eq, clap::Args)]
pub struct TaskOptions {
    /// Scheduled task name.
    #[arg(long, default_value = DEFAULT_TASK_NAME)]
    pub name: String,

    /// The serve options the task passes to `arena-guest`. They come last.
    #[arg(trailing_var_arg = true, allow_hyphen_values = true, value_name = "SERVE OPTIONS")]
    pub serve_args: Vec<String>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser as _;

    fn strings(words: &[&str]) -> Vec<String> {
        words.iter().map(|s| (*s).to_owned()).collect()
    }

    fn parse(words: &[&str]) -> Result<Cli, clap::Error> {
        Cli::try_parse_from(std::iter::once("arena-guest").chain(words.iter().copied()))
    }

    #[test]
    fn flags_alone_still_mean_serve() {
        let cli = parse(&["--port", "5001", "--backend", "stub"]).unwrap();
        assert!(cli.command.is_none());
        assert_eq!(cli.serve.port, 5001);
        assert!(!cli.serve.worker);
        let worker = parse(&["--port", "5001", "--worker"]).unwrap();
        assert!(worker.serve.worker);
    }

    #[test]
    fn service_install_takes_its_options_then_the_serve_options() {
        let cli = parse(&["service", "install", "--name", "Svc", "--port", "5002", "--bind", "0.0.0.0"]).unwrap();
        let Some(Command::Service(ServiceCommand::Install(options))) = cli.command else {
            panic!("not service install: {:?}", cli.command)
        };
        assert_eq!(options.name, "Svc");
        assert!(!options.allow_same_session);
        assert_eq!(options.serve_args, strings(&["--port", "5002", "--bind", "0.0.0.0"]));

        let cli = parse(&["service", "status"]).unwrap();
        let Some(Command::Service(ServiceCommand::Status(name))) = cli.command else { panic!("not status") };
        assert_eq!(name.name, DEFAULT_SERVICE_NAME);

        // Serve flags before the subcommand are a mistake, not silently dropped.
        assert!(parse(&["--port", "5003", "service", "install"]).is_err());
        assert!(parse(&["service", "install", "--worker-token", "root"]).is_err());
    }

    #[test]
    fn logon_task_run_is_gone() {
        // The launcher is a program of its own (`arena-guest-logon`).
        assert!(parse(&["logon-task", "run", "--", "--port", "5000"]).is_err());
    }
}
