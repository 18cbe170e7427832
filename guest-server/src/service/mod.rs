//! The command line of `arena-guest` beyond serving: the `service` and `logon-task`
//! subcommands, and the platform-neutral parts of running the server in the user's
//! session from a Windows service or a logon task.
//!
//! What is here: the clap definitions ([`Cli`]), the checks on the serve options a
//! service or task passes on, the command lines the supervisor and the logon task run
//! (quoted with [`arena_shared::cmdline::list2cmdline`]), the logon task's definition
//! ([`task_xml`]) and the `schtasks.exe` arguments that register it, where the logon
//! task's launcher ([`LAUNCHER_EXE`], a binary of its own) and the server find each
//! other, the worker's relaunch backoff, the log folder and log rotation, and the
//! worker's stop signal (its standard input closing). All of it is tested natively.
//!
//! The supervisor's decisions ([`supervisor_step`]) are here too.
//!
//! What is not: the Service Control Manager, tokens and `CreateProcessAsUserW`, and
//! the logon task's launcher loop; those are FFI glue in
//! [`windows`] (compiled for Windows only), which follows [`supervisor_step`]. On other platforms [`execute_service`] answers
//! [`ServiceCliError::OnlyOnWindows`].
//! The service is not part of a desktop backend: it starts the server, whose
//! backend then drives the desktop.

pub mod task_xml;
pub mod windows;

use std::path::{Path, PathBuf};
use std::time::Duration;

use clap::Parser as _;

use crate::config::ServerConfig;
use arena_shared::cmdline::list2cmdline;

/// The service name used when `--name` is not given.
pub const DEFAULT_SERVICE_NAME: &str = "ArenaGuest";

/// The scheduled task name used when `--name` is not given.
pub const DEFAULT_TASK_NAME: &str = "ArenaGuest";

/// The logon task's log file in [`log_dir`]: the launcher's lines and the server's output.
pub const LOGON_TASK_LOG: &str = "logon-task.log";

/// The server's file name, which the logon task's launcher starts from its own folder.
pub const SERVER_EXE: &str = "arena-guest.exe";

/// The logon task's launcher (`guest-server/src/logon_main.rs`): a GUI-subsystem
/// program, so Windows gives it no console and no window flashes at logon (see
/// `docs/windows.md`, "The logon task"). It ships beside [`SERVER_EXE`].
pub const LAUNCHER_EXE: &str = "arena-guest-logon.exe";

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

/// What to start the worker with, given the session token's `TOKEN_ELEVATION_TYPE`
/// (1 default, 2 full, 3 limited; `None` when it could not be read).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TokenChoice {
    /// The session's token as it is.
    Session,
    /// The token linked to it (`TokenLinkedToken`): the administrator's full token.
    Linked,
}

/// Only a limited (filtered) administrator token has a linked full token worth
/// taking; a default token (UAC off, or a standard user) and a full one are used
/// as they are.
pub fn choose_worker_token(wanted: WorkerToken, elevation_type: Option<i32>) -> TokenChoice {
    match (wanted, elevation_type) {
        (WorkerToken::Elevated, Some(3)) => TokenChoice::Linked,
        _ => TokenChoice::Session,
    }
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

/// Why a `service` or `logon-task` subcommand failed.
#[derive(Debug, thiserror::Error)]
pub enum ServiceCliError {
    /// The subcommand needs Windows.
    #[error("`arena-guest {0}` works only on Windows (this build is for another platform)")]
    OnlyOnWindows(&'static str),
    /// The serve options to pass on are not valid.
    #[error("invalid serve options: {0}")]
    InvalidServeOptions(String),
    /// An OS call failed.
    #[error("{op}: {message}")]
    Os { op: String, message: String },
    /// One of the two exes that ship together is not beside the other.
    #[error(
        "{name} is missing: expected at {}, beside {} (the two exes ship together: \
         scripts/build-windows.sh builds both, install-guest.ps1 copies both)",
        path.display(),
        beside.display()
    )]
    MissingCompanion { name: &'static str, path: PathBuf, beside: PathBuf },
    /// A file or program could not be used.
    #[error("{what}: {source}")]
    Io {
        what: String,
        #[source]
        source: std::io::Error,
    },
}

impl ServiceCliError {
    /// The process exit code for this error: 2 for a usage problem (wrong platform,
    /// bad options, one of the two exes missing beside the other), 1 for a failure
    /// while doing the work.
    pub fn exit_code(&self) -> u8 {
        match self {
            ServiceCliError::OnlyOnWindows(_)
            | ServiceCliError::InvalidServeOptions(_)
            | ServiceCliError::MissingCompanion { .. } => 2,
            ServiceCliError::Os { .. } | ServiceCliError::Io { .. } => 1,
        }
    }
}

/// Checks the serve options a service or logon task will pass to `arena-guest`, by
/// parsing them as the server will, and returns the configuration they give.
///
/// Beyond what the server itself checks, this refuses `--worker` (the supervisor adds
/// it), `--token` (a command line stored in the service or task is readable by every
/// local user: use `--token-file`) and port 0 (nobody could find the server).
///
/// # Errors
///
/// [`ServiceCliError::InvalidServeOptions`] saying what is wrong.
pub fn validate_serve_args(serve_args: &[String]) -> Result<ServerConfig, ServiceCliError> {
    let invalid = |why: String| Err(ServiceCliError::InvalidServeOptions(why));
    for arg in serve_args {
        let flag = arg.split_once('=').map_or(arg.as_str(), |(flag, _)| flag);
        match flag {
            "--worker" => return invalid("--worker is added by the supervisor; leave it out".into()),
            "--token" => {
                return invalid(
                    "--token would be stored in a command line every local user can read; use --token-file".into(),
                )
            }
            _ => {}
        }
    }
    let argv = std::iter::once("arena-guest").chain(serve_args.iter().map(String::as_str));
    let config = ServerConfig::try_parse_from(argv).map_err(|err| {
        // clap's rendering ends with a usage hint over several lines; the first line says it all.
        let text = err.to_string();
        ServiceCliError::InvalidServeOptions(text.lines().next().unwrap_or("").trim_start_matches("error: ").to_owned())
    })?;
    if config.port == 0 {
        return invalid("--port 0 picks a random port nobody could find; give a fixed port".into());
    }
    Ok(config)
}

/// The arguments the Service Control Manager starts the exe with (after the exe path):
/// `service run --name NAME [--allow-same-session] -- SERVE OPTIONS`.
///
/// The `--` keeps serve options that happen to look like supervisor options (`--name`)
/// with the worker.
pub fn service_run_args(options: &SupervisorOptions) -> Vec<String> {
    let mut args = vec!["service".to_owned(), "run".to_owned(), "--name".to_owned(), options.name.clone()];
    if options.allow_same_session {
        args.push("--allow-same-session".to_owned());
    }
    if options.worker_token != WorkerToken::default() {
        args.push("--worker-token".to_owned());
        args.push("user".to_owned());
    }
    args.push("--".to_owned());
    args.extend(options.serve_args.iter().cloned());
    args
}

/// `exe` quoted as the program of a command line. Program names are not parsed by
/// the C runtime's backslash rules, only split at the closing quote, and Windows
/// paths cannot contain `"`, so plain quotes always do.
pub fn quote_program(exe: &Path) -> String {
    format!("\"{}\"", exe.display())
}

/// `program` followed by `args` joined with [`list2cmdline`].
pub fn command_line(exe: &Path, args: &[String]) -> String {
    if args.is_empty() {
        quote_program(exe)
    } else {
        format!("{} {}", quote_program(exe), list2cmdline(args))
    }
}

/// The worker's command line: `"<exe>" SERVE OPTIONS --worker`.
pub fn worker_command_line(exe: &Path, serve_args: &[String]) -> String {
    let mut args = serve_args.to_vec();
    args.push("--worker".to_owned());
    command_line(exe, &args)
}

/// `name`, in the folder of `exe`, when it is a file there; otherwise
/// [`ServiceCliError::MissingCompanion`] naming both.
///
/// # Errors
///
/// As above.
pub fn companion(exe: &Path, name: &'static str) -> Result<PathBuf, ServiceCliError> {
    let path = exe.with_file_name(name);
    if path.is_file() {
        Ok(path)
    } else {
        Err(ServiceCliError::MissingCompanion { name, path, beside: exe.to_path_buf() })
    }
}

/// The serve options the logon task's launcher was started with (all its arguments:
/// it has no options of its own), checked as [`validate_serve_args`] checks them.
///
/// # Errors
///
/// [`ServiceCliError::InvalidServeOptions`] for an argument that is not Unicode or
/// options the server would refuse.
pub fn launcher_serve_args(args: impl IntoIterator<Item = std::ffi::OsString>) -> Result<Vec<String>, ServiceCliError> {
    let args = args
        .into_iter()
        .map(|arg| {
            arg.into_string().map_err(|arg| {
                ServiceCliError::InvalidServeOptions(format!("the argument {arg:?} is not valid Unicode"))
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    validate_serve_args(&args)?;
    Ok(args)
}

/// Runs the logon task's launcher ([`LAUNCHER_EXE`]) with its command-line arguments:
/// starts [`SERVER_EXE`] from the launcher's folder without a console window, and
/// again whenever it dies, until the launcher is ended. Returns only on failure.
///
/// # Errors
///
/// Invalid serve options, the server missing from the launcher's folder, the log
/// folder or the server not starting; [`ServiceCliError::OnlyOnWindows`] elsewhere.
pub fn run_logon_launcher(
    args: impl IntoIterator<Item = std::ffi::OsString>,
) -> Result<std::convert::Infallible, ServiceCliError> {
    let serve_args = launcher_serve_args(args)?;
    if !crate::desktop::windows::target::IS_WINDOWS {
        return Err(ServiceCliError::OnlyOnWindows("logon-task"));
    }
    let launcher = current_exe()?;
    let server = companion(&launcher, SERVER_EXE)?;
    windows::run_logon_task(&server, &serve_args)
}

/// The user a logon task is for, `DOMAIN\name`, from the installing shell's
/// `USERDOMAIN` and `USERNAME`; `None` when the name is unknown.
pub fn task_user(domain: Option<&str>, name: Option<&str>) -> Option<String> {
    let name = name.map(str::trim).filter(|n| !n.is_empty())?;
    Some(match domain.map(str::trim).filter(|d| !d.is_empty()) {
        Some(domain) => format!("{domain}\\{name}"),
        None => name.to_owned(),
    })
}

/// The logon task's definition (see [`task_xml`]): the `launcher` ([`LAUNCHER_EXE`])
/// with `serve_args` as its arguments, in its folder, for `user`.
pub fn logon_task_definition(launcher: &Path, serve_args: &[String], user: Option<&str>) -> String {
    let arguments = list2cmdline(serve_args);
    task_xml::logon_task_xml(&task_xml::LogonTask {
        user,
        command: launcher,
        arguments: &arguments,
        working_dir: exe_folder(launcher).as_deref(),
    })
}

/// The folder of a Windows program path (either separator, so tests of Windows paths
/// run on every platform); `None` for a bare name.
pub fn exe_folder(exe: &Path) -> Option<PathBuf> {
    let text = exe.to_string_lossy();
    let (folder, _) = text.rsplit_once(['\\', '/'])?;
    // `C:\arena-guest.exe` lives in the drive's root, `C:\`.
    let folder = if folder.ends_with(':') { format!("{folder}\\") } else { folder.to_owned() };
    (!folder.is_empty()).then(|| PathBuf::from(folder))
}

/// The arguments of `schtasks.exe` that register the task defined in `xml_file` as
/// `name`, replacing a task of that name.
pub fn schtasks_create_args(name: &str, xml_file: &Path) -> Vec<String> {
    ["/Create", "/XML", &xml_file.display().to_string(), "/TN", name, "/F"].iter().map(|s| (*s).to_owned()).collect()
}

/// The arguments of `schtasks.exe` that end the logon task's running instance.
pub fn schtasks_end_args(name: &str) -> Vec<String> {
    ["/End", "/TN", name].iter().map(|s| (*s).to_owned()).collect()
}

/// The arguments of `schtasks.exe` that delete the logon task.
pub fn schtasks_delete_args(name: &str) -> Vec<String> {
    ["/Delete", "/TN", name, "/F"].iter().map(|s| (*s).to_owned()).collect()
}

/// How long the supervisor waits before starting a worker again after one ended.
///
/// A worker that keeps dying at once (a taken port, a bad option) is restarted after
/// 1, 2, 4, ... up to 30 seconds, so it does not spin; one that ran for a minute or
/// more is restarted after a second again.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Backoff {
    next: Duration,
}

impl Backoff {
    /// The first delay.
    pub const MIN: Duration = Duration::from_secs(1);
    /// The longest delay.
    pub const MAX: Duration = Duration::from_secs(30);
    /// A worker that ran this long counts as healthy: the delay starts over.
    pub const HEALTHY: Duration = Duration::from_secs(60);

    pub fn new() -> Backoff {
        Backoff { next: Backoff::MIN }
    }

    /// The delay before the next start, given how long the worker that ended ran.
    pub fn after_exit(&mut self, ran_for: Duration) -> Duration {
        if ran_for >= Backoff::HEALTHY {
            self.next = Backoff::MIN;
        }
        let delay = self.next;
        self.next = (self.next * 2).min(Backoff::MAX);
        delay
    }
}

impl Default for Backoff {
    fn default() -> Backoff {
        Backoff::new()
    }
}

/// The folder the service logs into: `%ProgramData%\arena` (`C:\ProgramData\arena` when
/// the variable is missing). A service has no console, so its logs go to files there:
/// `service.log` (the supervisor) and `worker.log` (the worker's output).
pub fn log_dir(program_data: Option<&std::ffi::OsStr>) -> PathBuf {
    let base = program_data.filter(|p| !p.is_empty()).map_or_else(|| PathBuf::from(r"C:\ProgramData"), PathBuf::from);
    base.join("arena")
}

/// Largest log file kept before it is rotated.
pub const LOG_MAX_BYTES: u64 = 10 * 1024 * 1024;

/// Moves `path` to `<path>.old` (replacing an older one) when it is larger than
/// `max_bytes`, so logs that are only ever appended to stay bounded.
///
/// # Errors
///
/// The rename failing; a missing file is not an error.
pub fn rotate_log(path: &Path, max_bytes: u64) -> std::io::Result<bool> {
    match std::fs::metadata(path) {
        Ok(meta) if meta.len() > max_bytes => {
            let mut old = path.as_os_str().to_owned();
            old.push(".old");
            let old = PathBuf::from(old);
            // Windows' rename does not replace an existing file.
            let _ = std::fs::remove_file(&old);
            std::fs::rename(path, &old)?;
            Ok(true)
        }
        Ok(_) => Ok(false),
        Err(err) if err.kind() == std::io::ErrorKind::NotFound => Ok(false),
        Err(err) => Err(err),
    }
}

/// Reads `input` to its end (or to an error), discarding what it reads.
///
/// The worker's standard input is a pipe whose other end only the supervisor holds;
/// it never writes to it, so the end of input means "stop": the supervisor closed it,
/// or died.
pub fn drain_to_eof(mut input: impl std::io::Read) {
    let mut buf = [0u8; 256];
    loop {
        match input.read(&mut buf) {
            Ok(0) => return,
            Ok(_) => {}
            Err(err) if err.kind() == std::io::ErrorKind::Interrupted => {}
            Err(_) => return,
        }
    }
}

/// Completes when this process's standard input reaches its end (see [`drain_to_eof`]).
///
/// The read runs on a plain thread, not the runtime's blocking pool, so a process that
/// stops for another reason is not held up by a read that never returns.
pub async fn stdin_closed() {
    let (tx, rx) = tokio::sync::oneshot::channel::<()>();
    let spawned = std::thread::Builder::new().name("worker-stdin".into()).spawn(move || {
        drain_to_eof(std::io::stdin().lock());
        let _ = tx.send(());
    });
    match spawned {
        Ok(_) => {
            let _ = rx.await;
        }
        // Without the watcher the worker can still be stopped by its process being ended.
        Err(err) => {
            tracing::warn!(%err, "cannot watch standard input; the supervisor will have to terminate this worker");
            std::future::pending::<()>().await;
        }
    }
}

/// Runs a `service` subcommand and returns what to tell the user.
///
/// # Errors
///
/// [`ServiceCliError::OnlyOnWindows`] on other platforms; invalid serve options; the
/// Service Control Manager refusing (not an administrator, ...).
pub fn execute_service(command: &ServiceCommand) -> Result<String, ServiceCliError> {
    if let ServiceCommand::Install(options) | ServiceCommand::Run(options) = command {
        validate_serve_args(&options.serve_args)?;
    }
    windows::execute(command)
}

/// Runs a `logon-task` subcommand and returns what to tell the user: `install` and
/// `uninstall` through `schtasks.exe`. What the task runs is [`LAUNCHER_EXE`], which
/// `install` requires beside this exe.
///
/// # Errors
///
/// [`ServiceCliError::OnlyOnWindows`] on other platforms; invalid serve options;
/// [`ServiceCliError::MissingCompanion`] when the launcher is not beside this exe;
/// `schtasks.exe` missing or failing (its output is in the message).
pub fn execute_logon_task(command: &LogonTaskCommand) -> Result<String, ServiceCliError> {
    match command {
        LogonTaskCommand::Install(options) => {
            validate_serve_args(&options.serve_args)?;
            if !crate::desktop::windows::target::IS_WINDOWS {
                return Err(ServiceCliError::OnlyOnWindows("logon-task"));
            }
            let launcher = companion(&current_exe()?, LAUNCHER_EXE)?;
            let user =
                task_user(std::env::var("USERDOMAIN").ok().as_deref(), std::env::var("USERNAME").ok().as_deref());
            let xml = logon_task_definition(&launcher, &options.serve_args, user.as_deref());
            let file = std::env::temp_dir().join(format!("arena-guest-task-{}.xml", std::process::id()));
            std::fs::write(&file, task_xml::to_utf16_file(&xml))
                .map_err(|source| ServiceCliError::Io { what: format!("writing {}", file.display()), source })?;
            let outcome = schtasks(&schtasks_create_args(&options.name, &file));
            let _ = std::fs::remove_file(&file);
            let said = outcome?;
            let logs = log_dir(std::env::var_os("ProgramData").as_deref()).join(LOGON_TASK_LOG);
            Ok(format!(
                "logon task {:?} created: at {}'s logon it runs {} (no time limit, normal priority, no console \
                 window; output in {})\n{said}",
                options.name,
                user.as_deref().unwrap_or("the user"),
                command_line(&launcher, &options.serve_args),
                logs.display(),
            ))
        }
        LogonTaskCommand::Uninstall(name) => {
            if !crate::desktop::windows::target::IS_WINDOWS {
                return Err(ServiceCliError::OnlyOnWindows("logon-task"));
            }
            // End a running launcher first: its server then stops through its closed
            // input, and nothing restarts it. Not running is not an error.
            let _ = schtasks(&schtasks_end_args(&name.name));
            let said = schtasks(&schtasks_delete_args(&name.name))?;
            Ok(format!("logon task {:?} deleted\n{said}", name.name))
        }
    }
}

/// Runs `schtasks.exe` with `args`; its output when it succeeds.
fn schtasks(args: &[String]) -> Result<String, ServiceCliError> {
    let output = std::process::Command::new("schtasks.exe")
        .args(args)
        .output()
        .map_err(|source| ServiceCliError::Io { what: "running schtasks.exe".into(), source })?;
    let text = format!("{}{}", String::from_utf8_lossy(&output.stdout), String::from_utf8_lossy(&output.stderr));
    let text = text.trim();
    if output.status.success() {
        Ok(text.to_owned())
    } else {
        let code = output.status.code().map_or_else(|| "no exit code".to_owned(), |c| format!("exit code {c}"));
        let said = if text.is_empty() { "no output".to_owned() } else { text.to_owned() };
        Err(ServiceCliError::Os { op: format!("schtasks {}", list2cmdline(args)), message: format!("{code}: {said}") })
    }
}

/// This program's path, for the command lines stored in the service or task.
///
/// # Errors
///
/// The OS not telling.
pub fn current_exe() -> Result<PathBuf, ServiceCliError> {
    std::env::current_exe().map_err(|source| ServiceCliError::Io { what: "finding this program's path".into(), source })
}

/// What the service supervisor should do about its worker.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SupervisorStep {
    /// Nobody is logged on at the console: wait and look again.
    WaitForLogon,
    /// Start a worker in this session.
    Launch(u32),
    /// The worker runs in the wrong session (the user switched): stop it, then launch in this one.
    Relaunch { from: u32, to: u32 },
    /// All is well.
    Keep,
}

/// Decides the supervisor's next step from the active console session (`None` or
/// `0xFFFFFFFF` when nobody is attached) and the session of the running worker, if any.
pub fn supervisor_step(console_session: Option<u32>, worker_session: Option<u32>) -> SupervisorStep {
    let console = console_session.filter(|&s| s != u32::MAX && s != crate::desktop::windows::session::SERVICE_SESSION);
    match (console, worker_session) {
        (None, _) => SupervisorStep::WaitForLogon,
        (Some(to), None) => SupervisorStep::Launch(to),
        (Some(to), Some(from)) if from != to => SupervisorStep::Relaunch { from, to },
        (Some(_), Some(_)) => SupervisorStep::Keep,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
    }

    #[test]
    fn the_service_command_line_parses_back_to_the_same_options() {
        let mut options = SupervisorOptions {
            name: "Arena Guest".into(),
            allow_same_session: true,
            worker_token: WorkerToken::Elevated,
            // A serve option that looks like a supervisor option stays a serve option.
            serve_args: strings(&["--port", "5004", "--token-file", r"C:\Program Files\arena\token", "--name"]),
        };
        let args = service_run_args(&options);
        assert_eq!(
            &args[..6],
            strings(&["service", "run", "--name", "Arena Guest", "--allow-same-session", "--"]).as_slice()
        );
        let cli = Cli::try_parse_from(std::iter::once("arena-guest".to_owned()).chain(args)).unwrap();
        let Some(Command::Service(ServiceCommand::Run(back))) = cli.command else { panic!("not service run") };
        assert_eq!(back, options);

        options.worker_token = WorkerToken::User;
        let args = service_run_args(&options);
        assert!(args.windows(2).any(|w| w == ["--worker-token", "user"]), "{args:?}");
        let cli = Cli::try_parse_from(std::iter::once("arena-guest".to_owned()).chain(args)).unwrap();
        let Some(Command::Service(ServiceCommand::Run(back))) = cli.command else { panic!("not service run") };
        assert_eq!(back, options);
    }

    #[test]
    fn only_a_filtered_administrator_token_is_swapped_for_its_linked_full_token() {
        use TokenChoice::{Linked, Session};
        // TOKEN_ELEVATION_TYPE: 1 default, 2 full, 3 limited.
        let cases = [
            (WorkerToken::Elevated, Some(3), Linked),
            (WorkerToken::Elevated, Some(2), Session),
            (WorkerToken::Elevated, Some(1), Session),
            (WorkerToken::Elevated, None, Session),
            (WorkerToken::User, Some(3), Session),
        ];
        for (wanted, kind, expected) in cases {
            assert_eq!(choose_worker_token(wanted, kind), expected, "{wanted:?} {kind:?}");
        }
        let cli = parse(&["service", "install", "--worker-token", "user", "--port", "5000"]).unwrap();
        let Some(Command::Service(ServiceCommand::Install(options))) = cli.command else { panic!("not install") };
        assert_eq!(options.worker_token, WorkerToken::User);
        assert!(parse(&["service", "install", "--worker-token", "root"]).is_err());
    }

    fn check_line(exe: &str, args: &[&str], expected: &str) {
        assert_eq!(command_line(Path::new(exe), &strings(args)), expected, "{exe} {args:?}");
    }

    #[test]
    fn command_lines_quote_the_program_and_the_arguments() {
        check_line(r"C:\arena\arena-guest.exe", &[], r#""C:\arena\arena-guest.exe""#);
        check_line(
            r"C:\Program Files\arena\arena-guest.exe",
            &["--port", "5000", "--token-file", r"C:\My Token\t.txt"],
            r#""C:\Program Files\arena\arena-guest.exe" --port 5000 --token-file "C:\My Token\t.txt""#,
        );
        check_line(r"C:\a.exe", &["--scenario", r#"say "hi""#, ""], r#""C:\a.exe" --scenario "say \"hi\"" """#);
        assert_eq!(
            worker_command_line(Path::new(r"C:\a b\g.exe"), &strings(&["--port", "5000"])),
            r#""C:\a b\g.exe" --port 5000 --worker"#
        );
    }

    fn check_invalid(args: &[&str], expected: &str) {
        match validate_serve_args(&strings(args)) {
            Err(ServiceCliError::InvalidServeOptions(why)) => assert!(why.contains(expected), "{args:?}: {why}"),
            other => panic!("{args:?} gave {other:?}"),
        }
    }

    #[test]
    fn serve_options_are_checked_before_they_are_stored() {
        let config = validate_serve_args(&strings(&["--port", "5005", "--backend", "stub"])).unwrap();
        assert_eq!(config.port, 5005);
        check_invalid(&["--port", "5005", "--worker"], "--worker");
        check_invalid(&["--token", "0123456789abcdef0123"], "--token-file");
        check_invalid(&["--token=0123456789abcdef0123"], "--token-file");
        check_invalid(&["--port", "0"], "--port 0");
        check_invalid(&["--port", "notaport"], "notaport");
        check_invalid(&["--no-such-flag"], "--no-such-flag");
        let err = validate_serve_args(&strings(&["--port", "0"])).unwrap_err();
        assert_eq!(err.exit_code(), 2);
        assert_eq!(ServiceCliError::OnlyOnWindows("service").exit_code(), 2);
    }

    #[test]
    fn schtasks_registers_the_launcher_from_an_xml_definition() {
        let launcher = Path::new(r"C:\Program Files\Arena\arena-guest-logon.exe");
        let serve = strings(&["--port", "5000", "--token-file", r"C:\ProgramData\arena\token"]);
        let xml = logon_task_definition(launcher, &serve, Some(r"VM\Docker"));
        // The GUI-subsystem launcher, not arena-guest.exe (a console program), with the
        // serve options as its whole command line.
        assert!(xml.contains(r"<Command>C:\Program Files\Arena\arena-guest-logon.exe</Command>"), "{xml}");
        assert!(!xml.contains(r"\arena-guest.exe"), "{xml}");
        assert!(xml.contains(r"<Arguments>--port 5000 --token-file C:\ProgramData\arena\token</Arguments>"), "{xml}");
        assert!(xml.contains(r"<WorkingDirectory>C:\Program Files\Arena</WorkingDirectory>"), "{xml}");
        assert!(xml.contains(r"<UserId>VM\Docker</UserId>"), "{xml}");
        assert_eq!(exe_folder(Path::new(r"C:\arena-guest.exe")), Some(PathBuf::from(r"C:\")));
        assert_eq!(exe_folder(Path::new("arena-guest.exe")), None);
        // A long command line is fine: /TR's 261-character limit does not apply to XML.
        let long = vec!["--scenario".to_owned(), "x".repeat(300)];
        assert!(logon_task_definition(launcher, &long, None).contains(&"x".repeat(300)));

        assert_eq!(
            schtasks_create_args("ArenaGuest", Path::new(r"C:\Temp\t.xml")),
            strings(&["/Create", "/XML", r"C:\Temp\t.xml", "/TN", "ArenaGuest", "/F"])
        );
        assert_eq!(schtasks_delete_args("T"), strings(&["/Delete", "/TN", "T", "/F"]));
        assert_eq!(schtasks_end_args("T"), strings(&["/End", "/TN", "T"]));
    }

    #[test]
    fn the_task_is_for_the_installing_user() {
        assert_eq!(task_user(Some("VM"), Some("Docker")).as_deref(), Some(r"VM\Docker"));
        assert_eq!(task_user(None, Some("Docker")).as_deref(), Some("Docker"));
        assert_eq!(task_user(Some(" "), Some("Docker")).as_deref(), Some("Docker"));
        assert_eq!(task_user(Some("VM"), None), None);
        assert_eq!(task_user(Some("VM"), Some("")), None);
    }

    #[test]
    fn the_launcher_takes_its_whole_command_line_as_serve_options() {
        let args = ["--port", "5000", "--token-file", r"C:\My Token\t.txt", "--backend", "stub"];
        let os = |words: &[&str]| words.iter().map(std::ffi::OsString::from).collect::<Vec<_>>();
        assert_eq!(launcher_serve_args(os(&args)).unwrap(), strings(&args));
        assert_eq!(launcher_serve_args(Vec::new()).unwrap(), Vec::<String>::new());
        // Checked as the service's and the task's serve options are, before anything starts.
        for (bad, said) in [(&["--port", "5000", "--worker"][..], "--worker"), (&["--port", "0"][..], "--port 0")] {
            match launcher_serve_args(os(bad)) {
                Err(ServiceCliError::InvalidServeOptions(why)) => assert!(why.contains(said), "{bad:?}: {why}"),
                other => panic!("{bad:?} gave {other:?}"),
            }
        }
        // `logon-task run` is gone: the launcher is a program of its own.
        assert!(parse(&["logon-task", "run", "--", "--port", "5000"]).is_err());
    }

    #[cfg(unix)]
    #[test]
    fn a_launcher_argument_that_is_not_unicode_is_named() {
        use std::os::unix::ffi::OsStringExt as _;
        let bad = std::ffi::OsString::from_vec(b"--port\xff".to_vec());
        let err = launcher_serve_args([bad]).unwrap_err();
        assert!(
            matches!(&err, ServiceCliError::InvalidServeOptions(why) if why.contains("not valid Unicode")),
            "{err}"
        );
        assert_eq!(err.exit_code(), 2);
    }

    #[test]
    fn each_exe_finds_the_other_beside_it_or_names_the_missing_one() {
        let dir = tempfile::tempdir().unwrap();
        let server = dir.path().join(SERVER_EXE);
        let launcher = dir.path().join(LAUNCHER_EXE);
        std::fs::write(&server, b"MZ").unwrap();
        let err = companion(&server, LAUNCHER_EXE).unwrap_err();
        let text = err.to_string();
        assert!(text.starts_with("arena-guest-logon.exe is missing: expected at "), "{text}");
        assert!(
            text.contains(&launcher.display().to_string()) && text.contains(&server.display().to_string()),
            "{text}"
        );
        assert_eq!(err.exit_code(), 2);
        std::fs::write(&launcher, b"MZ").unwrap();
        assert_eq!(companion(&server, LAUNCHER_EXE).unwrap(), launcher);
        assert_eq!(companion(&launcher, SERVER_EXE).unwrap(), server);
        // A folder of that name is not the program.
        std::fs::remove_file(&server).unwrap();
        std::fs::create_dir(&server).unwrap();
        assert!(
            matches!(companion(&launcher, SERVER_EXE), Err(ServiceCliError::MissingCompanion { name, .. }) if name == SERVER_EXE)
        );
    }

    #[test]
    fn backoff_grows_while_the_worker_keeps_dying_and_resets_after_a_good_run() {
        let mut backoff = Backoff::new();
        let quick = Duration::from_millis(200);
        let delays: Vec<u64> = (0..7).map(|_| backoff.after_exit(quick).as_secs()).collect();
        assert_eq!(delays, [1, 2, 4, 8, 16, 30, 30]);
        assert_eq!(backoff.after_exit(Backoff::HEALTHY), Backoff::MIN);
        assert_eq!(backoff.after_exit(quick), Duration::from_secs(2));
    }

    #[test]
    fn logs_go_under_program_data() {
        let dir = log_dir(Some(std::ffi::OsStr::new("/data")));
        assert_eq!(dir, Path::new("/data").join("arena"));
        assert_eq!(log_dir(None), PathBuf::from(r"C:\ProgramData").join("arena"));
        assert_eq!(log_dir(Some(std::ffi::OsStr::new(""))), PathBuf::from(r"C:\ProgramData").join("arena"));
    }

    #[test]
    fn a_large_log_is_moved_aside() {
        let dir = tempfile::tempdir().unwrap();
        let log = dir.path().join("service.log");
        assert!(!rotate_log(&log, 10).unwrap(), "a missing log is left alone");
        std::fs::write(&log, b"0123456789").unwrap();
        assert!(!rotate_log(&log, 10).unwrap());
        std::fs::write(dir.path().join("service.log.old"), b"older").unwrap();
        std::fs::write(&log, b"0123456789ab").unwrap();
        assert!(rotate_log(&log, 10).unwrap());
        assert!(!log.exists());
        assert_eq!(std::fs::read(dir.path().join("service.log.old")).unwrap(), b"0123456789ab");
    }

    #[test]
    fn the_stop_signal_is_the_end_of_input() {
        // Returns (instead of hanging) at the end of input, however much came first.
        drain_to_eof(std::io::Cursor::new(vec![7u8; 1000]));
        drain_to_eof(std::io::empty());
    }

    #[test]
    fn other_platforms_say_windows_only() {
        if crate::desktop::windows::target::IS_WINDOWS {
            return;
        }
        let install = ServiceCommand::Install(SupervisorOptions {
            name: DEFAULT_SERVICE_NAME.into(),
            allow_same_session: false,
            worker_token: WorkerToken::Elevated,
            serve_args: strings(&["--port", "5000"]),
        });
        let err = execute_service(&install).unwrap_err();
        assert!(matches!(err, ServiceCliError::OnlyOnWindows("service")), "{err}");
        assert!(err.to_string().contains("only on Windows"));
        let task = LogonTaskCommand::Uninstall(TaskNameOption { name: DEFAULT_TASK_NAME.into() });
        assert!(matches!(execute_logon_task(&task), Err(ServiceCliError::OnlyOnWindows("logon-task"))));
        let task = LogonTaskCommand::Install(TaskOptions { name: DEFAULT_TASK_NAME.into(), serve_args: Vec::new() });
        assert!(matches!(execute_logon_task(&task), Err(ServiceCliError::OnlyOnWindows("logon-task"))));
        let launched = run_logon_launcher(["--port".into(), "5000".into()]);
        assert!(matches!(launched, Err(ServiceCliError::OnlyOnWindows("logon-task"))), "{launched:?}");
    }

    fn check(console: Option<u32>, worker: Option<u32>, expected: SupervisorStep) {
        assert_eq!(supervisor_step(console, worker), expected, "console {console:?}, worker {worker:?}");
    }

    #[test]
    fn supervisor_follows_the_console_session() {
        check(None, None, SupervisorStep::WaitForLogon);
        check(Some(u32::MAX), Some(1), SupervisorStep::WaitForLogon);
        check(Some(0), None, SupervisorStep::WaitForLogon);
        check(Some(1), None, SupervisorStep::Launch(1));
        check(Some(2), Some(1), SupervisorStep::Relaunch { from: 1, to: 2 });
        check(Some(1), Some(1), SupervisorStep::Keep);
    }
}
