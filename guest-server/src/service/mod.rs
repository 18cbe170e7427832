//! The `service` and `logon-task` subcommands of `arena-guest`, and the
//! platform-neutral parts of running the server in the user's session from a Windows
//! service or a logon task.
//!
//! What is here: the command lines the supervisor and the logon task run (quoted with
//! [`arena_shared::cmdline::list2cmdline`]), the logon task's definition ([`task_xml`])
//! and the `schtasks.exe` arguments that register it, which user token the worker gets,
//! the worker's stop signal (its standard input closing) and the supervisor's decisions
//! ([`supervisor_step`]). All of it is tested natively. The serve options' checks, the
//! exes' names, the restart backoff and the logs are `arena_guest_launch`'s, which the
//! logon task's launcher (a binary of that crate) shares; the subcommands' clap
//! definitions are [`crate::cli`].
//!
//! What is not: the Service Control Manager, tokens and `CreateProcessAsUserW`; those
//! are FFI glue in [`windows`] (compiled for Windows only), which follows
//! [`supervisor_step`]. On other platforms [`execute_service`] answers
//! [`ServiceCliError::OnlyOnWindows`]. The service is not part of a desktop backend:
//! it starts the server, whose backend then drives the desktop.

pub mod task_xml;
pub mod windows;

use std::path::{Path, PathBuf};

use arena_guest_launch::error::ServiceCliError;
use arena_guest_launch::exes::{companion, current_exe, LAUNCHER_EXE};
use arena_guest_launch::logs::{log_dir, LOGON_TASK_LOG};
use arena_guest_launch::options::validate_serve_args;
use arena_shared::cmdline::list2cmdline;

use crate::cli::{LogonTaskCommand, ServiceCommand, SupervisorOptions, WorkerToken};

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
            if !arena_guest_launch::windows::IS_WINDOWS {
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
            if !arena_guest_launch::windows::IS_WINDOWS {
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
    use crate::cli::{Cli, Command, TaskNameOption, TaskOptions, DEFAULT_SERVICE_NAME, DEFAULT_TASK_NAME};
    use clap::Parser as _;

    fn strings(words: &[&str]) -> Vec<String> {
        words.iter().map(|s| (*s).to_owned()).collect()
    }

    fn parse(words: &[&str]) -> Result<Cli, clap::Error> {
        Cli::try_parse_from(std::iter::once("arena-guest").chain(words.iter().copied()))
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
    fn the_stop_signal_is_the_end_of_input() {
        // Returns (instead of hanging) at the end of input, however much came first.
        drain_to_eof(std::io::Cursor::new(vec![7u8; 1000]));
        drain_to_eof(std::io::empty());
    }

    #[test]
    fn other_platforms_say_windows_only() {
        if arena_guest_launch::windows::IS_WINDOWS {
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
