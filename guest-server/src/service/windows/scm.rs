//! The Windows service mode: registration with the Service Control Manager
//! (`service install | uninstall | status`) and the supervisor the SCM starts
//! (`service run`).
//!
//! The supervisor runs as LocalSystem in session 0 and never touches a desktop. It
//! finds the active console session, takes the logged-on user's token and starts the
//! worker (`"<exe>" SERVE OPTIONS --worker`) into that session's `winsta0\default`
//! desktop with `CreateProcessAsUserW`, the user's environment block, standard input
//! from a pipe only the supervisor holds, and output appended to
//! `%ProgramData%\arena\worker.log`. It starts the worker again when it dies (with
//! [`Backoff`]) or when the console session changes. Closing the pipe asks the worker
//! to stop; after a grace period it is terminated.
//!
//! FFI glue only: the decisions ([`supervisor_step`]), the command lines, option
//! checks, backoff and log handling are in [`crate::service`], all tested natively.

use std::ffi::OsString;
use std::os::windows::io::AsRawHandle;
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::sync::{Mutex, OnceLock};
use std::time::{Duration, Instant};

use tracing_subscriber::filter::FilterExt as _;
use tracing_subscriber::layer::SubscriberExt as _;
use tracing_subscriber::util::SubscriberInitExt as _;
use tracing_subscriber::Layer as _;

use windows::core::{PCWSTR, PWSTR};
use windows::Win32::Foundation::{
    SetHandleInformation, ERROR_FAILED_SERVICE_CONTROLLER_CONNECT, ERROR_NO_TOKEN, HANDLE, HANDLE_FLAGS,
    HANDLE_FLAG_INHERIT, WAIT_OBJECT_0,
};
use windows::Win32::Security::{
    DuplicateTokenEx, SecurityImpersonation, TokenElevationType, TokenLinkedToken, TokenPrimary, SECURITY_ATTRIBUTES,
    TOKEN_ALL_ACCESS, TOKEN_ELEVATION_TYPE, TOKEN_LINKED_TOKEN,
};
use windows::Win32::System::Environment::{CreateEnvironmentBlock, DestroyEnvironmentBlock};
use windows::Win32::System::Pipes::CreatePipe;
use windows::Win32::System::RemoteDesktop::{WTSGetActiveConsoleSessionId, WTSQueryUserToken};
use windows::Win32::System::Threading::{
    CreateProcessAsUserW, CreateProcessW, GetExitCodeProcess, TerminateProcess, WaitForSingleObject,
    CREATE_NEW_PROCESS_GROUP, CREATE_NO_WINDOW, CREATE_UNICODE_ENVIRONMENT, PROCESS_INFORMATION, STARTF_USESTDHANDLES,
    STARTUPINFOW,
};
use windows_service::service::{
    ServiceAccess, ServiceAction, ServiceActionType, ServiceControl, ServiceControlAccept, ServiceErrorControl,
    ServiceExitCode, ServiceFailureActions, ServiceFailureResetPeriod, ServiceInfo, ServiceStartType, ServiceState,
    ServiceStatus, ServiceType,
};
use windows_service::service_control_handler::{self, ServiceControlHandlerResult, ServiceStatusHandle};
use windows_service::service_manager::{ServiceManager, ServiceManagerAccess};

use windows::Win32::UI::Shell::{FOLDERID_ProgramData, SHGetKnownFolderPath, KF_FLAG_DEFAULT};

use crate::desktop::windows::sys::{describe, token_info, CoTaskString, OwnedHandle};
use arena_guest_launch::error::ServiceCliError;
use arena_guest_launch::logs::{log_dir, rotate_log, LOG_MAX_BYTES};
use arena_guest_launch::restart::Backoff;

use crate::cli::{ServiceCommand, SupervisorOptions, WorkerToken};
use crate::service::{
    choose_worker_token, service_run_args, supervisor_step, worker_command_line, SupervisorStep, TokenChoice,
};

/// How long a worker gets to stop after its standard input closes, before it is terminated.
const WORKER_GRACE: Duration = Duration::from_secs(5);

/// How often the supervisor looks at its worker and the console session between events.
const POLL: Duration = Duration::from_millis(500);

/// Runs a `service` subcommand.
///
/// # Errors
///
/// The SCM refusing (not elevated: access denied), a missing service for `status`,
/// or `run` started from a console instead of by the SCM.
pub fn execute(command: &ServiceCommand) -> Result<String, ServiceCliError> {
    match command {
        ServiceCommand::Install(options) => install(options),
        ServiceCommand::Uninstall(name) => uninstall(&name.name),
        ServiceCommand::Status(name) => status(&name.name),
        ServiceCommand::Run(options) => run(options),
    }
}

/// `%ProgramData%\arena`, from the known folder rather than the variable: under Wine the
/// SCM gives services a `ProgramData` that differs from the users' one, and the log
/// path `service install` prints must be the one the service writes to.
fn logs_dir() -> PathBuf {
    // SAFETY: a valid GUID; the returned string goes to a guard that frees it.
    let known = unsafe { SHGetKnownFolderPath(&FOLDERID_ProgramData, KF_FLAG_DEFAULT, None) }
        .map(|path| OsString::from(CoTaskString(path).to_string_lossy()))
        .ok();
    log_dir(known.as_deref().or(std::env::var_os("ProgramData").as_deref()))
}

fn scm_error(op: impl Into<String>, err: &windows_service::Error) -> ServiceCliError {
    let message = match err {
        windows_service::Error::Winapi(io) => io.to_string(),
        other => other.to_string(),
    };
    ServiceCliError::Os { op: op.into(), message }
}

/// The Win32 error code inside a windows-service error, if it has one.
fn raw_code(err: &windows_service::Error) -> Option<i32> {
    match err {
        windows_service::Error::Winapi(io) => io.raw_os_error(),
        _ => None,
    }
}

const ERROR_SERVICE_DOES_NOT_EXIST: i32 = 1060;
const ERROR_SERVICE_NOT_ACTIVE: i32 = 1062;

fn manager(access: ServiceManagerAccess) -> Result<ServiceManager, ServiceCliError> {
    ServiceManager::local_computer(None::<&str>, access)
        .map_err(|err| scm_error("opening the Service Control Manager (installing needs an elevated prompt)", &err))
}

fn install(options: &SupervisorOptions) -> Result<String, ServiceCliError> {
    let exe = crate::service::current_exe()?;
    let info = ServiceInfo {
        name: OsString::from(&options.name),
        display_name: OsString::from("Arena guest (desktop-control server)"),
        service_type: ServiceType::OWN_PROCESS,
        start_type: ServiceStartType::AutoStart,
        error_control: ServiceErrorControl::Normal,
        executable_path: exe.clone(),
        launch_arguments: service_run_args(options).into_iter().map(OsString::from).collect(),
        dependencies: Vec::new(),
        // None is LocalSystem, which may read user tokens and start processes in other sessions.
        account_name: None,
        account_password: None,
    };
    let scm = manager(ServiceManagerAccess::CONNECT | ServiceManagerAccess::CREATE_SERVICE)?;
    let access = ServiceAccess::QUERY_CONFIG | ServiceAccess::CHANGE_CONFIG | ServiceAccess::QUERY_STATUS;
    let (service, verb) = match scm.open_service(&options.name, access) {
        Ok(service) => {
            let before =
                service.query_config().map_err(|err| scm_error("reading the service's configuration", &err))?;
            service.change_config(&info).map_err(|err| scm_error("updating the service", &err))?;
            let after = service.query_config().map_err(|err| scm_error("reading the service's configuration", &err))?;
            let verb = if before.executable_path == after.executable_path
                && before.start_type == after.start_type
                && before.account_name == after.account_name
            {
                "was already installed with this command line; left as is"
            } else {
                "was already installed: its command line is updated (restart the service to use it)"
            };
            (service, verb)
        }
        Err(err) if raw_code(&err) == Some(ERROR_SERVICE_DOES_NOT_EXIST) => {
            let service = scm.create_service(&info, access).map_err(|err| scm_error("creating the service", &err))?;
            (service, "is installed (automatic start, LocalSystem); start it with `sc start` or reboot")
        }
        Err(err) => return Err(scm_error("opening the service", &err)),
    };
    // Niceties: a description, and restarts by the SCM if the supervisor itself crashes.
    // Wine's SCM lacks some of this; the service works without them.
    if let Err(err) = service.set_description(
        "Starts arena-guest, the WAA-compatible desktop-control server, in the logged-on user's session.",
    ) {
        tracing::warn!(err = %scm_error("", &err), "could not set the service description");
    }
    let restart = ServiceAction { action_type: ServiceActionType::Restart, delay: Duration::from_secs(5) };
    if let Err(err) = service.update_failure_actions(ServiceFailureActions {
        reset_period: ServiceFailureResetPeriod::After(Duration::from_secs(24 * 3600)),
        reboot_msg: None,
        command: None,
        actions: Some(vec![restart.clone(), restart.clone(), restart]),
    }) {
        tracing::warn!(err = %scm_error("", &err), "could not set the service's failure actions");
    }
    let line = service
        .query_config()
        .map(|c| c.executable_path.display().to_string())
        .unwrap_or_else(|_| exe.display().to_string());
    Ok(format!("service {:?} {verb}\ncommand line: {line}\nlogs: {}", options.name, logs_dir().display()))
}

fn uninstall(name: &str) -> Result<String, ServiceCliError> {
    let scm = manager(ServiceManagerAccess::CONNECT)?;
    let access = ServiceAccess::QUERY_STATUS | ServiceAccess::STOP | ServiceAccess::DELETE;
    let service = match scm.open_service(name, access) {
        Ok(service) => service,
        Err(err) if raw_code(&err) == Some(ERROR_SERVICE_DOES_NOT_EXIST) => {
            return Ok(format!("service {name:?} is not installed; nothing to do"));
        }
        Err(err) => return Err(scm_error("opening the service", &err)),
    };
    let mut stopped = String::new();
    let running = service.query_status().map(|s| s.current_state != ServiceState::Stopped).unwrap_or(true);
    match if running { service.stop().map(|_| ()) } else { Ok(()) } {
        Ok(()) if !running => {}
        Ok(()) => {
            let deadline = Instant::now() + WORKER_GRACE + Duration::from_secs(15);
            loop {
                match service.query_status() {
                    Ok(status) if status.current_state == ServiceState::Stopped => break,
                    Ok(_) if Instant::now() < deadline => std::thread::sleep(Duration::from_millis(200)),
                    Ok(status) => {
                        tracing::warn!(state = ?status.current_state, "the service did not stop in time; deleting it anyway");
                        break;
                    }
                    Err(err) => return Err(scm_error("waiting for the service to stop", &err)),
                }
            }
            stopped = "stopped and ".to_owned();
        }
        Err(err) if raw_code(&err) == Some(ERROR_SERVICE_NOT_ACTIVE) => {}
        Err(err) => return Err(scm_error("stopping the service", &err)),
    }
    service.delete().map_err(|err| scm_error("deleting the service", &err))?;
    Ok(format!("service {name:?} {stopped}deleted"))
}

fn status(name: &str) -> Result<String, ServiceCliError> {
    let scm = manager(ServiceManagerAccess::CONNECT)?;
    let service = match scm.open_service(name, ServiceAccess::QUERY_STATUS | ServiceAccess::QUERY_CONFIG) {
        Ok(service) => service,
        Err(err) if raw_code(&err) == Some(ERROR_SERVICE_DOES_NOT_EXIST) => {
            return Err(ServiceCliError::Os { op: format!("service {name:?}"), message: "not installed".into() });
        }
        Err(err) => return Err(scm_error("opening the service", &err)),
    };
    let status = service.query_status().map_err(|err| scm_error("querying the service", &err))?;
    let config = service.query_config().map_err(|err| scm_error("reading the service's configuration", &err))?;
    let state = match status.current_state {
        ServiceState::Stopped => "stopped",
        ServiceState::StartPending => "starting",
        ServiceState::StopPending => "stopping",
        ServiceState::Running => "running",
        ServiceState::ContinuePending => "continuing",
        ServiceState::PausePending => "pausing",
        ServiceState::Paused => "paused",
    };
    let pid = status.process_id.map(|p| format!(" (pid {p})")).unwrap_or_default();
    Ok(format!(
        "service {name:?}: {state}{pid}\nstart: {:?}\ncommand line: {}\nlogs: {}",
        config.start_type,
        config.executable_path.display(),
        logs_dir().display()
    ))
}

/// What `service_main` needs; set once before the dispatcher starts, since the SCM
/// passes `service_main` only the `sc start` arguments, not the command line.
#[derive(Debug)]
struct RunContext {
    options: SupervisorOptions,
    exe: PathBuf,
    logs: PathBuf,
}

static RUN: OnceLock<RunContext> = OnceLock::new();

windows_service::define_windows_service!(ffi_service_main, service_main);

fn run(options: &SupervisorOptions) -> Result<String, ServiceCliError> {
    let exe = crate::service::current_exe()?;
    let logs = logs_dir();
    init_file_logging(&logs)?;
    tracing::info!(name = %options.name, exe = %exe.display(), serve = ?options.serve_args, "service process started");
    let _ = RUN.set(RunContext { options: options.clone(), exe, logs });
    // Blocks until the service stops; service_main runs on a thread of the SCM's.
    match windows_service::service_dispatcher::start(&options.name, ffi_service_main) {
        Ok(()) => Ok(String::new()),
        Err(err) if raw_code(&err) == Some(ERROR_FAILED_SERVICE_CONTROLLER_CONNECT.0 as i32) => {
            Err(ServiceCliError::Os {
                op: "service run".into(),
                message: "this is what the Service Control Manager starts, not a command to run by hand: \
                          use `arena-guest service install ...` and `sc start` (or run the server directly)"
                    .into(),
            })
        }
        Err(err) => Err(scm_error("starting the service dispatcher", &err)),
    }
}

/// Sends the supervisor's tracing to `service.log` in `dir`: a service has no console.
fn init_file_logging(dir: &Path) -> Result<(), ServiceCliError> {
    let io = |what: String| move |source| ServiceCliError::Io { what, source };
    std::fs::create_dir_all(dir).map_err(io(format!("creating {}", dir.display())))?;
    let path = dir.join("service.log");
    let _ = rotate_log(&path, LOG_MAX_BYTES);
    let file = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&path)
        .map_err(io(format!("opening {}", path.display())))?;
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| "arena_guest=info,arena_mcp=warn".into());
    // A second initialisation (never expected) keeps the first subscriber.
    let layer = tracing_subscriber::fmt::layer()
        .with_ansi(false)
        .with_writer(Mutex::new(file))
        .with_filter(filter.and(arena_mcp::without_refusal_noise()));
    let _ = tracing_subscriber::registry().with(layer).try_init();
    Ok(())
}

/// What the control handler tells the supervisor loop.
#[derive(Debug)]
enum Event {
    Stop,
    SessionChange(String),
}

fn service_main(_arguments: Vec<OsString>) {
    let Some(context) = RUN.get() else {
        return;
    };
    if let Err(err) = supervise(context) {
        tracing::error!(%err, "the supervisor failed");
    }
}

fn status_of(state: ServiceState, accept: ServiceControlAccept, exit: u32, wait: Duration) -> ServiceStatus {
    ServiceStatus {
        service_type: ServiceType::OWN_PROCESS,
        current_state: state,
        controls_accepted: accept,
        exit_code: ServiceExitCode::Win32(exit),
        checkpoint: 0,
        wait_hint: wait,
        process_id: None,
    }
}

fn supervise(context: &RunContext) -> Result<(), ServiceCliError> {
    let (tx, rx) = mpsc::channel::<Event>();
    let handler = move |control: ServiceControl| -> ServiceControlHandlerResult {
        match control {
            ServiceControl::Stop | ServiceControl::Shutdown => {
                let _ = tx.send(Event::Stop);
                ServiceControlHandlerResult::NoError
            }
            ServiceControl::SessionChange(change) => {
                let _ = tx.send(Event::SessionChange(format!(
                    "{:?} of session {}",
                    change.reason, change.notification.session_id
                )));
                ServiceControlHandlerResult::NoError
            }
            ServiceControl::Interrogate => ServiceControlHandlerResult::NoError,
            _ => ServiceControlHandlerResult::NotImplemented,
        }
    };
    let status: ServiceStatusHandle = service_control_handler::register(&context.options.name, handler)
        .map_err(|err| scm_error("registering the service control handler", &err))?;
    let accept = ServiceControlAccept::STOP | ServiceControlAccept::SHUTDOWN | ServiceControlAccept::SESSION_CHANGE;
    status
        .set_service_status(status_of(ServiceState::Running, accept, 0, Duration::ZERO))
        .map_err(|err| scm_error("reporting the service running", &err))?;
    tracing::info!("service running; supervising the worker");

    let mut supervisor = Supervisor::new(context);
    loop {
        supervisor.tick();
        match rx.recv_timeout(POLL) {
            Ok(Event::Stop) | Err(mpsc::RecvTimeoutError::Disconnected) => break,
            Ok(Event::SessionChange(what)) => {
                tracing::info!(change = %what, "session change");
                // A logon is worth acting on at once, not after a pending backoff.
                supervisor.not_before = Instant::now();
            }
            Err(mpsc::RecvTimeoutError::Timeout) => {}
        }
    }

    tracing::info!("stop requested");
    let _ = status.set_service_status(status_of(
        ServiceState::StopPending,
        ServiceControlAccept::empty(),
        0,
        WORKER_GRACE + Duration::from_secs(10),
    ));
    supervisor.stop_worker();
    let _ =
        status.set_service_status(status_of(ServiceState::Stopped, ServiceControlAccept::empty(), 0, Duration::ZERO));
    tracing::info!("service stopped");
    Ok(())
}

/// The worker process the supervisor started.
#[derive(Debug)]
struct Worker {
    process: OwnedHandle,
    pid: u32,
    /// The session it was started for (see [`Supervisor::launch`] for the same-session fallback).
    session: u32,
    /// The write end of its standard input; dropping it asks the worker to stop.
    stdin: Option<OwnedHandle>,
    started: Instant,
}

impl Worker {
    /// Its exit code, once it has ended.
    fn exit_code(&self) -> Option<u32> {
        // SAFETY: the process handle is owned and live; a zero timeout only polls.
        if unsafe { WaitForSingleObject(self.process.raw(), 0) } != WAIT_OBJECT_0 {
            return None;
        }
        let mut code = 0u32;
        // SAFETY: as above, with a valid out-pointer.
        let _ = unsafe { GetExitCodeProcess(self.process.raw(), &mut code) };
        Some(code)
    }

    /// Closes its standard input, waits [`WORKER_GRACE`] for it to end, then terminates it.
    fn stop(mut self) {
        drop(self.stdin.take());
        let grace = WORKER_GRACE.as_millis() as u32;
        // SAFETY: the process handle is owned and live for these calls.
        unsafe {
            if WaitForSingleObject(self.process.raw(), grace) == WAIT_OBJECT_0 {
                tracing::info!(pid = self.pid, "worker stopped");
                return;
            }
            tracing::warn!(pid = self.pid, "worker did not stop within {grace} ms; terminating it");
            if let Err(err) = TerminateProcess(self.process.raw(), 1) {
                tracing::error!(pid = self.pid, err = %describe(&err), "TerminateProcess failed");
            }
            let _ = WaitForSingleObject(self.process.raw(), 5_000);
        }
    }
}

/// Why a worker could not be started.
#[derive(Debug)]
enum LaunchError {
    /// Nobody is logged on in the session yet (no user token): wait for a logon.
    NoUser(String),
    /// Anything else.
    Failed(String),
}

/// The supervisor's state between ticks.
#[derive(Debug)]
struct Supervisor<'a> {
    context: &'a RunContext,
    worker: Option<Worker>,
    backoff: Backoff,
    not_before: Instant,
    /// Whether "waiting for a logon" was logged already (so it is logged once per wait).
    waiting: bool,
}

impl<'a> Supervisor<'a> {
    fn new(context: &'a RunContext) -> Supervisor<'a> {
        Supervisor { context, worker: None, backoff: Backoff::new(), not_before: Instant::now(), waiting: false }
    }

    /// Reaps a dead worker, then does what [`supervisor_step`] says.
    fn tick(&mut self) {
        if let Some(code) = self.worker.as_ref().and_then(Worker::exit_code) {
            if let Some(worker) = self.worker.take() {
                let ran = worker.started.elapsed();
                let delay = self.backoff.after_exit(ran);
                tracing::warn!(
                    pid = worker.pid,
                    exit_code = code,
                    ran_s = ran.as_secs(),
                    "worker exited; starting another in {} s (see worker.log)",
                    delay.as_secs()
                );
                self.not_before = Instant::now() + delay;
            }
        }
        // SAFETY: no preconditions; 0xFFFFFFFF means no session is attached to the console.
        let console = unsafe { WTSGetActiveConsoleSessionId() };
        match supervisor_step(Some(console), self.worker.as_ref().map(|w| w.session)) {
            SupervisorStep::Keep => {}
            SupervisorStep::WaitForLogon => {
                self.note_waiting(&format!("no user session at the console ({console:#x})"))
            }
            SupervisorStep::Launch(session) => {
                if Instant::now() >= self.not_before {
                    self.launch(session);
                }
            }
            SupervisorStep::Relaunch { from, to } => {
                tracing::info!(from, to, "the console moved to another session; moving the worker");
                self.stop_worker();
                self.launch(to);
            }
        }
    }

    fn note_waiting(&mut self, why: &str) {
        if !self.waiting {
            tracing::info!("waiting for a user to log on: {why}");
            self.waiting = true;
        }
    }

    fn launch(&mut self, session: u32) {
        match launch_worker(self.context, session) {
            Ok(worker) => {
                tracing::info!(pid = worker.pid, session, "worker started");
                self.waiting = false;
                self.worker = Some(worker);
            }
            Err(LaunchError::NoUser(why)) => {
                self.note_waiting(&why);
                self.not_before = Instant::now() + Duration::from_secs(2);
            }
            Err(LaunchError::Failed(why)) => {
                let delay = self.backoff.after_exit(Duration::ZERO);
                tracing::error!(
                    "starting the worker in session {session} failed: {why}; retrying in {} s",
                    delay.as_secs()
                );
                self.not_before = Instant::now() + delay;
            }
        }
    }

    fn stop_worker(&mut self) {
        if let Some(worker) = self.worker.take() {
            worker.stop();
        }
    }
}

/// An environment block from `CreateEnvironmentBlock`, destroyed on drop.
struct EnvironmentBlock(*mut core::ffi::c_void);

impl Drop for EnvironmentBlock {
    fn drop(&mut self) {
        // SAFETY: the block came from CreateEnvironmentBlock and is destroyed once.
        let _ = unsafe { DestroyEnvironmentBlock(self.0) };
    }
}

fn wide(s: &str) -> Vec<u16> {
    s.encode_utf16().chain(std::iter::once(0)).collect()
}

/// The token the worker starts with: the session's, or (when `--worker-token elevated`
/// and UAC gave the session a filtered administrator token) the linked full token as a
/// primary token. Any failure keeps the session's token and says so in the log.
fn worker_token(session_token: OwnedHandle, wanted: WorkerToken) -> OwnedHandle {
    // SAFETY: TokenElevationType is written as a TOKEN_ELEVATION_TYPE; the token is live.
    let read = unsafe { token_info::<TOKEN_ELEVATION_TYPE>(session_token.raw(), TokenElevationType) }.ok().map(|e| e.0);
    if choose_worker_token(wanted, read) == TokenChoice::Session {
        tracing::info!(elevation_type = ?read, ?wanted, "the worker runs with the session's token");
        return session_token;
    }
    // SAFETY: TokenLinkedToken is written as a TOKEN_LINKED_TOKEN; the token is live.
    let linked = match unsafe { token_info::<TOKEN_LINKED_TOKEN>(session_token.raw(), TokenLinkedToken) } {
        Ok(linked) => linked,
        Err(err) => {
            tracing::warn!(err = %describe(&err), "no linked token: the worker runs with the filtered (medium) token");
            return session_token;
        }
    };
    let Some(linked) = OwnedHandle::new(linked.LinkedToken) else {
        tracing::warn!("the linked token is empty: the worker runs with the filtered (medium) token");
        return session_token;
    };
    let mut primary = HANDLE::default();
    // SAFETY: the linked token is live; `primary` is a valid out-pointer owned right after.
    let duplicated = unsafe {
        DuplicateTokenEx(linked.raw(), TOKEN_ALL_ACCESS, None, SecurityImpersonation, TokenPrimary, &mut primary)
    };
    match duplicated.ok().and_then(|()| OwnedHandle::new(primary)) {
        Some(primary) => {
            tracing::info!("the worker runs with the user's full administrator token (high integrity)");
            primary
        }
        None => {
            tracing::warn!("could not make a primary token of the linked token: the worker runs with the filtered one");
            session_token
        }
    }
}

/// Starts the worker in `session` as its logged-on user; or, when that user's token
/// cannot be had and `--allow-same-session` was given, in this process's own session.
///
/// The recorded session is always `session`, the one [`supervisor_step`] asked for, so
/// a same-session worker is kept rather than "moved" on every tick.
fn launch_worker(context: &RunContext, session: u32) -> Result<Worker, LaunchError> {
    let failed = |what: &str, err: &windows::core::Error| LaunchError::Failed(format!("{what}: {}", describe(err)));
    let mut raw_token = HANDLE::default();
    // SAFETY: a valid out-pointer; the handle is owned right after.
    let token = match unsafe { WTSQueryUserToken(session, &mut raw_token) } {
        Ok(()) => OwnedHandle::new(raw_token),
        Err(err) if context.options.allow_same_session => {
            tracing::warn!(
                session,
                err = %describe(&err),
                "no user token; --allow-same-session: starting the worker in the service's own session"
            );
            None
        }
        Err(err) if err.code() == ERROR_NO_TOKEN.to_hresult() => {
            return Err(LaunchError::NoUser(format!("session {session} has no logged-on user yet")));
        }
        Err(err) => return Err(failed("WTSQueryUserToken (the service must run as LocalSystem)", &err)),
    };
    let token = token.map(|session_token| worker_token(session_token, context.options.worker_token));

    let environment = match &token {
        Some(token) => {
            let mut block = std::ptr::null_mut();
            // SAFETY: a valid out-pointer and a live primary token; the block is owned right after.
            match unsafe { CreateEnvironmentBlock(&mut block, Some(token.raw()), false) } {
                Ok(()) => Some(EnvironmentBlock(block)),
                Err(err) => return Err(failed("CreateEnvironmentBlock", &err)),
            }
        }
        None => None,
    };

    // Standard input: a pipe whose write end only the supervisor holds.
    let inheritable = SECURITY_ATTRIBUTES {
        nLength: size_of::<SECURITY_ATTRIBUTES>() as u32,
        lpSecurityDescriptor: std::ptr::null_mut(),
        bInheritHandle: true.into(),
    };
    let (mut read, mut write) = (HANDLE::default(), HANDLE::default());
    // SAFETY: valid out-pointers and attributes; both ends are owned right after.
    unsafe { CreatePipe(&mut read, &mut write, Some(&inheritable), 0) }.map_err(|err| failed("CreatePipe", &err))?;
    let (read, write) = match (OwnedHandle::new(read), OwnedHandle::new(write)) {
        (Some(read), Some(write)) => (read, write),
        _ => return Err(LaunchError::Failed("CreatePipe returned no handles".into())),
    };
    // SAFETY: a live handle we own; only its inheritance flag changes.
    unsafe { SetHandleInformation(write.raw(), HANDLE_FLAG_INHERIT.0, HANDLE_FLAGS(0)) }
        .map_err(|err| failed("SetHandleInformation", &err))?;

    // Output: appended to worker.log, opened by the supervisor so the user needs no rights on it.
    let log_path = context.logs.join("worker.log");
    let _ = rotate_log(&log_path, LOG_MAX_BYTES);
    let log = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&log_path)
        .map_err(|err| LaunchError::Failed(format!("opening {}: {err}", log_path.display())))?;
    let log_handle = HANDLE(log.as_raw_handle());
    // SAFETY: the file is open (kept alive until after CreateProcess); only its inheritance flag changes.
    unsafe { SetHandleInformation(log_handle, HANDLE_FLAG_INHERIT.0, HANDLE_FLAG_INHERIT) }
        .map_err(|err| failed("SetHandleInformation", &err))?;

    let line = worker_command_line(&context.exe, &context.options.serve_args);
    tracing::info!(session, command = %line, "starting the worker");
    let mut command = wide(&line);
    let mut desktop = wide("winsta0\\default");
    let cwd = context.exe.parent().map(|p| wide(&p.display().to_string()));
    let cwd_ptr = cwd.as_ref().map_or(PCWSTR::null(), |c| PCWSTR(c.as_ptr()));
    let startup = STARTUPINFOW {
        cb: size_of::<STARTUPINFOW>() as u32,
        lpDesktop: PWSTR(desktop.as_mut_ptr()),
        dwFlags: STARTF_USESTDHANDLES,
        hStdInput: read.raw(),
        hStdOutput: log_handle,
        hStdError: log_handle,
        ..Default::default()
    };
    // No console window on the user's desktop; the worker's own process group, so a
    // console event sent to it never reaches anything else.
    let flags = CREATE_UNICODE_ENVIRONMENT | CREATE_NO_WINDOW | CREATE_NEW_PROCESS_GROUP;
    let mut info = PROCESS_INFORMATION::default();
    let env_ptr = environment.as_ref().map(|e| e.0 as *const core::ffi::c_void);
    // SAFETY: every pointer (command line, desktop name, directory, startup info,
    // environment block) lives until the call returns; the command line buffer is
    // mutable as CreateProcess requires; handles to inherit are live.
    let created = unsafe {
        match &token {
            Some(token) => CreateProcessAsUserW(
                Some(token.raw()),
                PCWSTR::null(),
                Some(PWSTR(command.as_mut_ptr())),
                None,
                None,
                true,
                flags,
                env_ptr,
                cwd_ptr,
                &startup,
                &mut info,
            ),
            None => CreateProcessW(
                PCWSTR::null(),
                Some(PWSTR(command.as_mut_ptr())),
                None,
                None,
                true,
                flags,
                None,
                cwd_ptr,
                &startup,
                &mut info,
            ),
        }
    };
    drop(read);
    drop(log);
    created.map_err(|err| failed(if token.is_some() { "CreateProcessAsUserW" } else { "CreateProcessW" }, &err))?;
    drop(OwnedHandle::new(info.hThread));
    let process = OwnedHandle::new(info.hProcess)
        .ok_or_else(|| LaunchError::Failed("CreateProcess returned no process handle".into()))?;
    Ok(Worker { process, pid: info.dwProcessId, session, stdin: Some(write), started: Instant::now() })
}
