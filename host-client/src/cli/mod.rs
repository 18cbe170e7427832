//! The `arena` command line: its arguments ([`Cli`]) and what each subcommand does ([`run`]).
//!
//! This module is the body of the binary, kept in the library so it is
//! tested like the rest: it parses nothing itself (clap does), talks to the
//! guest only through [`arena_client::client::GuestClient`], and is the one place in
//! the crate that writes to stdout, because that output is its interface.
//! Diagnostics go to stderr through `tracing`.
//!
//! # Layout
//!
//! - [`act`]: the `act` words and JSON batches.
//! - [`render`]: tables and outlines.
//! - [`local`]: atomic local writes.
//! - [`demo`]: the end-to-end demonstration.
//! - [`env`]: `arena env serve`, the harness as an environment a program drives.
//! - [`progress`]: what `arena run` shows while it goes (`--progress`).
//! - [`runs`]: `arena run`, `merge`, `report` and `compare`: their flags resolved into the run driver's plan (`crate::driver`), and what they print.
//! - `signals`: Ctrl-C and SIGTERM.
//! - [`preset`]: `--preset` and how a run stands to upstream's.
//! - [`run_args`]: the flags of `run`, `merge`, `report` and `compare`.

pub mod act;
pub mod certify;
pub mod corpus;
pub mod demo;
pub mod env;
pub mod external;
pub mod local;
pub mod oem;
pub mod preset;
pub mod progress;
pub mod render;
pub mod run_args;
pub mod runs;
pub(crate) mod signals;
pub mod validate;
pub mod vm;

use std::io::{IsTerminal, Write};
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::Context;
use clap::{Args, Parser, Subcommand, ValueEnum};

#[cfg(feature = "stub-guest")]
use crate::driver::stub;

use arena_shared::clipboard::ClipboardContent;
use arena_shared::exec::{ExecRequest, LaunchRequest};
use arena_shared::health::Readiness;
use arena_shared::observation::{A11yBackend, A11yQuery, ImageFormat, ScreenshotQuery, WindowTarget};

use arena_client::client::{ClientConfig, GuestClient, WindowOp};
use arena_client::error::ClientError;

/// Where the guest is when neither `--guest` nor `ARENA_GUEST` says.
pub const DEFAULT_GUEST: &str = "http://127.0.0.1:5000";

/// Drive a Windows agent-arena guest from the host.
#[derive(Debug, Clone, Parser)]
#[command(name = "arena", version, about, propagate_version = true)]
pub struct Cli {
    #[command(flatten)]
    pub connection: Connection,

    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands that never reach a guest: their help leaves out the connection
/// options, which every other subcommand takes (and which they accept and ignore).
pub const OFFLINE_SUBCOMMANDS: [&str; 5] = ["validate", "merge", "report", "compare", "corpus"];

/// The connection options that are global (given before or after the subcommand).
const CONNECTION_GLOBALS: [&str; 3] = ["guest", "token", "token_file"];

impl Cli {
    /// The command line's definition, with the connection options hidden from the
    /// help of [`OFFLINE_SUBCOMMANDS`].
    pub fn definition() -> clap::Command {
        let mut command = <Cli as clap::CommandFactory>::command();
        let globals: Vec<clap::Arg> =
            command.get_arguments().filter(|a| CONNECTION_GLOBALS.contains(&a.get_id().as_str())).cloned().collect();
        for name in OFFLINE_SUBCOMMANDS {
            let globals = globals.clone();
            // clap copies a global option into a subcommand only where the subcommand has
            // none of that name: a hidden copy of its own keeps it out of the help.
            command = command.mut_subcommand(name, move |sub| {
                globals.into_iter().fold(sub, |sub, arg| sub.arg(arg.global(false).env(None::<&str>).hide(true)))
            });
        }
        command
    }

    /// Parses the process's arguments (exiting with clap's message on an error).
    pub fn parse_args() -> Cli {
        let matches = Cli::definition().get_matches();
        <Cli as clap::FromArgMatches>::from_arg_matches(&matches).unwrap_or_else(|err| err.exit())
    }
}

/// How to reach the guest: the settings every subcommand shares.
#[derive(Debug, Clone, Args)]
pub struct Connection {
    /// Base URL of the guest [default: http://127.0.0.1:5000].
    #[arg(long, env = "ARENA_GUEST", global = true, value_name = "URL")]
    pub guest: Option<String>,

    /// Bearer token of the guest.
    #[arg(long, env = "ARENA_TOKEN", global = true, hide_env_values = true, conflicts_with = "token_file")]
    pub token: Option<String>,

    /// File holding the bearer token (first line).
    #[arg(long, env = "ARENA_TOKEN_FILE", global = true, value_name = "FILE")]
    pub token_file: Option<PathBuf>,

    /// Default deadline of one call, in seconds (give it before the subcommand).
    #[arg(long, env = "ARENA_TIMEOUT", default_value = "30", value_parser = parse_seconds, value_name = "SECONDS")]
    pub timeout: Duration,

    /// Retries of idempotent calls after connection errors, timeouts and 502-504.
    #[arg(long, env = "ARENA_RETRIES", default_value_t = 3)]
    pub retries: u32,
}

impl Connection {
    /// The guest URL, given or default.
    pub fn guest_url(&self) -> &str {
        self.guest.as_deref().unwrap_or(DEFAULT_GUEST)
    }

    /// The token from `--token` or `--token-file`.
    ///
    /// # Errors
    ///
    /// The token file cannot be read or is empty.
    pub fn resolve_token(&self) -> anyhow::Result<Option<String>> {
        match (&self.token, &self.token_file) {
            (Some(token), _) => Ok(Some(arena_shared::token::parse(token).context("--token")?)),
            (None, Some(path)) => {
                let text = std::fs::read_to_string(path)
                    .with_context(|| format!("reading --token-file {}", path.display()))?;
                Ok(Some(arena_shared::token::parse(&text).with_context(|| format!("--token-file {}", path.display()))?))
            }
            (None, None) => Ok(None),
        }
    }

    /// A client of `url` with these settings.
    ///
    /// # Errors
    ///
    /// An unreadable token file or an invalid URL.
    pub fn client_for(&self, url: &str) -> anyhow::Result<GuestClient> {
        Ok(GuestClient::new(url, self.client_config()?)?)
    }

    /// How a client talks with these settings: the token, the deadline, the retries.
    ///
    /// # Errors
    ///
    /// An unreadable token file.
    pub fn client_config(&self) -> anyhow::Result<ClientConfig> {
        Ok(ClientConfig { token: self.resolve_token()?, timeout: self.timeout, retries: self.retries })
    }

    /// A client of the configured guest.
    ///
    /// # Errors
    ///
    /// As [`Connection::client_for`].
    pub fn client(&self) -> anyhow::Result<GuestClient> {
        self.client_for(self.guest_url())
    }
}

/// What to do.
#[derive(Debug, Clone, Subcommand)]
pub enum Command {
    /// Serve an in-process stub guest until Ctrl-C.
    #[cfg(feature = "stub-guest")]
    ServeStub(stub::StubArgs),
    /// Show the guest's staged health; exits 0 only when it is ready.
    Health {
        /// Wait up to SECONDS for every component to come up.
        #[arg(long, value_parser = parse_seconds, value_name = "SECONDS")]
        wait: Option<Duration>,
        /// Print the report as JSON.
        #[arg(long)]
        json: bool,
    },
    /// Check every capability of the guest's desktop end to end (capture, cursor, typing
    /// into Notepad, clipboard, trees, exec timeouts, files); exits 0 when nothing failed.
    /// With --input, the input catalogue against the guest's recorder instead.
    Doctor {
        /// Print the report as JSON.
        #[arg(long)]
        json: bool,
        /// Also time the tree of each heavy application running (Edge, File Explorer,
        /// Settings, Notepad, Office) and input round trips, printed as a table to paste.
        #[arg(long, conflicts_with = "input")]
        deep: bool,
        /// Instead, send the input catalogue in every action space to the guest's input
        /// recorder and compare what its window received; exits 0 when every case passed.
        #[arg(long)]
        input: bool,
        /// With --input: the recorder's program in the guest [default: C:\OEM's, or the stub's].
        #[arg(long, requires = "input", value_name = "PATH")]
        recorder: Option<String>,
        /// With --input: where in the guest the recorder writes its log [default: in its temp folder].
        #[arg(long, requires = "input", value_name = "PATH")]
        recorder_log: Option<String>,
        /// With --input: only this action space (repeatable) [default: all].
        #[arg(long = "space", requires = "input", value_name = "NAME")]
        spaces: Vec<arena_actionspace::ActionSpace>,
        /// With --input: only the case of this name (repeatable) [default: all].
        #[arg(long = "case", requires = "input", value_name = "NAME")]
        cases: Vec<String>,
    },
    /// Show screen size, scale and monitors (JSON).
    Screen,
    /// Save a screenshot and print its metadata.
    Screenshot {
        /// Where to write the image.
        #[arg(short, long, default_value = "screenshot.png")]
        output: PathBuf,
        /// JPEG instead of PNG.
        #[arg(long)]
        jpeg: bool,
        /// JPEG quality, 1 to 100.
        #[arg(long, value_parser = clap::value_parser!(u8).range(1..=100))]
        quality: Option<u8>,
        /// Downscale so the longest side is at most N pixels.
        #[arg(long, value_name = "N")]
        max_side: Option<u32>,
        /// Do not draw the cursor.
        #[arg(long)]
        no_cursor: bool,
    },
    /// Print the accessibility tree as an outline (or JSON).
    Tree(TreeArgs),
    /// List top-level windows, topmost first.
    Windows {
        #[arg(long)]
        json: bool,
    },
    /// Activate, close, minimise, maximise or restore a window.
    Window {
        #[arg(value_enum)]
        op: WindowOpArg,
        /// Case-insensitive substring of the title.
        #[arg(required_unless_present = "id")]
        title: Option<String>,
        /// Exact window id instead of a title.
        #[arg(long, conflicts_with = "title")]
        id: Option<u64>,
    },
    /// Perform one input action, or a JSON batch.
    Act(act::ActArgs),
    /// Run a program to completion; prints its output and exits with its code.
    Exec(ExecArgs),
    /// Start a program without waiting for it.
    Launch {
        #[arg(required = true, num_args = 1.., trailing_var_arg = true, allow_hyphen_values = true, value_name = "PROGRAM ARGS")]
        argv: Vec<String>,
    },
    /// Open a guest path with its associated program.
    Open { path: String },
    /// Upload a local file to a guest path (hash-checked).
    Push {
        local: PathBuf,
        guest_path: String,
        /// Fail instead of creating missing parent directories.
        #[arg(long)]
        no_parents: bool,
    },
    /// Download a guest file (hash-checked; the local file is replaced atomically).
    Pull { guest_path: String, local: PathBuf },
    /// List a guest directory.
    Ls {
        guest_path: String,
        #[arg(long)]
        json: bool,
    },
    /// Show a guest path's kind, size and times.
    Stat { guest_path: String },
    /// Delete a guest file (or directory with -r).
    Rm {
        guest_path: String,
        #[arg(short, long)]
        recursive: bool,
    },
    /// Create a guest directory and its parents.
    Mkdir { guest_path: String },
    /// Show the guest's well-known folders.
    Folders,
    /// Read or set the clipboard.
    Clipboard {
        #[command(subcommand)]
        command: ClipboardCommand,
    },
    /// Read the registry.
    Registry {
        #[command(subcommand)]
        command: RegistryCommand,
    },
    /// Start a stub guest (unless --guest is given) and run every kind of call against it.
    Demo(demo::DemoArgs),
    /// Load a task folder and report what each task needs and whether this build supports it.
    Validate(validate::ValidateArgs),
    /// Run tasks over a pool of guests and write result folders and a report.
    Run(Box<run_args::RunArgs>),
    /// Merge shard result folders into one, with its summary and report.
    Merge(run_args::MergeArgs),
    /// Rebuild summary.json, summary.md and report.html of a result folder.
    Report(run_args::ReportArgs),
    /// Certify a task list: play it with `noop` (DONE at once), `fail` (FAIL at once) and,
    /// where plans exist, the oracle, K times each, and write one certificate per task
    /// (passes without acting, infeasible floor, oracle pass rate, flake rate, guest image).
    Certify(Box<certify::CertifyArgs>),
    /// Compare two result folders task by task: the difference in success rate with a
    /// paired bootstrap interval, and the tasks that did better or worse.
    Compare(run_args::CompareArgs),
    /// Stage an OEM folder for a new Windows image, verify one, or wait for a prepared guest.
    Prep(oem::PrepArgs),
    /// Get the upstream WAA task corpus without cloning WindowsAgentArena.
    Corpus(corpus::CorpusArgs),
    /// Run Windows VMs with QEMU: start one on an overlay of a golden image, snapshot,
    /// restore, screendump, stop, or prepare a golden image from an installer ISO.
    Vm(vm::VmCommandArgs),
    /// The harness as an environment a program drives (`arena env serve`: reset,
    /// step and evaluate over HTTP, for RL trainers, notebooks and `arena_agent.env`).
    Env(env::EnvArgs),
}

/// Arguments of `arena tree`.
#[derive(Debug, Clone, Args)]
pub struct TreeArgs {
    #[arg(long, value_enum, default_value_t = BackendArg::Uia)]
    pub backend: BackendArg,
    /// Print the A11yTree JSON instead of the outline.
    #[arg(long)]
    pub json: bool,
    /// Only the foreground window.
    #[arg(long)]
    pub foreground: bool,
    #[arg(long)]
    pub max_depth: Option<u32>,
    #[arg(long)]
    pub max_children: Option<u32>,
    #[arg(long)]
    pub max_nodes: Option<u32>,
    /// Time budget of the walk in milliseconds.
    #[arg(long)]
    pub max_ms: Option<u64>,
}

/// Accessibility backend names on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum BackendArg {
    Uia,
    Win32,
}

/// Window operations on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum WindowOpArg {
    Activate,
    Close,
    Minimize,
    Maximize,
    Restore,
}

/// Arguments of `arena exec`.
#[derive(Debug, Clone, Args)]
pub struct ExecArgs {
    /// Kill the program after SECONDS (the guest caps it).
    #[arg(long, value_parser = parse_seconds, value_name = "SECONDS")]
    pub timeout: Option<Duration>,
    /// Working directory on the guest.
    #[arg(long)]
    pub cwd: Option<String>,
    /// Text for the program's standard input.
    #[arg(long)]
    pub stdin: Option<String>,
    /// Print the ExecResult JSON instead of the output.
    #[arg(long)]
    pub json: bool,
    /// Program and arguments, after `--`.
    #[arg(required = true, num_args = 1.., trailing_var_arg = true, allow_hyphen_values = true, value_name = "PROGRAM ARGS")]
    pub argv: Vec<String>,
}

/// `arena clipboard ...`.
#[derive(Debug, Clone, Subcommand)]
pub enum ClipboardCommand {
    /// Print the clipboard text (or describe an image).
    Get,
    /// Put TEXT on the clipboard.
    Set {
        #[arg(allow_hyphen_values = true)]
        text: String,
    },
}

/// `arena registry ...`.
#[derive(Debug, Clone, Subcommand)]
pub enum RegistryCommand {
    /// Print a value of KEY (the default value when VALUE is left out).
    Get { key: String, value: Option<String> },
}

/// Parses a positive number of seconds (fractions allowed).
fn parse_seconds(text: &str) -> Result<Duration, String> {
    let secs: f64 = text.trim().parse().map_err(|_| format!("{text:?} is not a number of seconds"))?;
    if !secs.is_finite() || secs <= 0.0 || secs > 86_400.0 * 7.0 {
        return Err(format!("{text:?} seconds is out of range (more than 0, at most a week)"));
    }
    Ok(Duration::from_secs_f64(secs))
}

/// Writes command output to stdout; a closed pipe (`arena tree | head`) is not an error.
fn emit(text: &str) -> anyhow::Result<()> {
    let mut stdout = std::io::stdout().lock();
    match stdout.write_all(text.as_bytes()).and_then(|()| stdout.flush()) {
        Err(err) if err.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        other => other.context("writing to stdout"),
    }
}

fn emit_json<T: serde::Serialize>(value: &T) -> anyhow::Result<()> {
    let mut text = serde_json::to_string_pretty(value).context("encoding JSON")?;
    text.push('\n');
    emit(&text)
}

/// A spinner on stderr while `future` runs, when stderr is a terminal; nothing otherwise.
pub(crate) async fn with_spinner<F: std::future::Future>(message: &str, future: F) -> F::Output {
    if !std::io::stderr().is_terminal() {
        return future.await;
    }
    let bar = indicatif::ProgressBar::new_spinner().with_message(message.to_owned());
    bar.enable_steady_tick(Duration::from_millis(100));
    let output = future.await;
    bar.finish_and_clear();
    output
}

/// Runs the parsed command line and says how the process should exit.
///
/// # Errors
///
/// Whatever failed, with context naming the guest, the call or the local file.
pub async fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    let conn = &cli.connection;
    match cli.command {
        #[cfg(feature = "stub-guest")]
        Command::ServeStub(args) => {
            let token = conn.resolve_token()?;
            let shutdown = async {
                let _ = tokio::signal::ctrl_c().await;
                tracing::info!("Ctrl-C: stopping");
            };
            stub::serve_until(
                &args,
                token,
                |addr| {
                    let _ = emit(&format!("listening on http://{addr}\n"));
                },
                shutdown,
            )
            .await?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Health { wait, json } => health(conn, wait, json).await,
        Command::Doctor { json, input: true, recorder, recorder_log, spaces, cases, .. } => {
            let check =
                arena_inputcheck::GuestCheck { recorder, log: recorder_log, spaces, only: cases, ..Default::default() };
            let catalogue = arena_inputcheck::Catalogue::builtin().map_err(anyhow::Error::msg)?;
            let client = conn.client()?;
            let spin = "the input catalogue is running through the guest's recorder";
            let report = with_spinner(spin, arena_inputcheck::check_guest(&client, &catalogue, &check)).await?;
            if json {
                emit_json(&report)?
            } else {
                emit(&report.render_table())?
            }
            Ok(if report.all_passed() { ExitCode::SUCCESS } else { ExitCode::FAILURE })
        }
        Command::Doctor { json, deep, .. } => {
            let client = conn.client()?;
            let report = if deep {
                with_spinner("the guest is checking its desktop and timing its trees", client.doctor_deep()).await?
            } else {
                with_spinner("the guest is checking its desktop", client.doctor()).await?
            };
            if json {
                emit_json(&report)?;
            } else {
                emit(&report.render_text())?;
                if let Some(deep) = &report.deep {
                    emit(&format!("\n{}", deep.render_table()))?;
                }
            }
            Ok(if report.passed() { ExitCode::SUCCESS } else { ExitCode::FAILURE })
        }
        Command::Screen => {
            emit_json(&conn.client()?.screen().await?)?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Screenshot { output, jpeg, quality, max_side, no_cursor } => {
            let query = ScreenshotQuery {
                format: if jpeg { ImageFormat::Jpeg } else { ImageFormat::Png },
                quality,
                max_side,
                cursor: no_cursor.then_some(false),
            };
            let shot = conn.client()?.screenshot(&query).await?;
            local::write_atomic(&output, &shot.bytes)?;
            emit(&render::screenshot(&shot.meta, shot.bytes.len(), &output.display().to_string()))?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Tree(args) => {
            let query = A11yQuery {
                backend: match args.backend {
                    BackendArg::Uia => A11yBackend::Uia,
                    BackendArg::Win32 => A11yBackend::Win32,
                },
                max_depth: args.max_depth,
                max_children: args.max_children,
                max_nodes: args.max_nodes,
                max_ms: args.max_ms,
                foreground_only: args.foreground,
            };
            let client = conn.client()?;
            let tree = with_spinner("walking the accessibility tree", client.a11y(&query)).await?;
            if args.json {
                emit_json(&tree)?;
            } else {
                emit(&render::outline(&tree))?;
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Windows { json } => {
            let list = conn.client()?.windows().await?;
            if json {
                emit_json(&list)?;
            } else {
                emit(&render::windows(&list))?;
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Window { op, title, id } => {
            let op = match op {
                WindowOpArg::Activate => WindowOp::Activate,
                WindowOpArg::Close => WindowOp::Close,
                WindowOpArg::Minimize => WindowOp::Minimize,
                WindowOpArg::Maximize => WindowOp::Maximize,
                WindowOpArg::Restore => WindowOp::Restore,
            };
            let info = conn.client()?.window(op, &WindowTarget { id, title }).await?;
            emit(&render::windows(&[info]))?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Act(args) => {
            let client = conn.client()?;
            let steps = args.steps_for(&client).await?;
            let started = std::time::Instant::now();
            let outcome = arena_exec::perform_steps(&client, &steps, &arena_exec::ExecOptions::default()).await?;
            if let Some(error) = outcome.error {
                anyhow::bail!("{error}");
            }
            let cursor = outcome.cursor.map(|c| format!("; cursor at {},{}", c.x, c.y)).unwrap_or_default();
            emit(&format!(
                "executed {} action(s) in {} ms{cursor}\n",
                outcome.performed,
                started.elapsed().as_millis()
            ))?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Exec(args) => exec(conn, args).await,
        Command::Launch { argv } => {
            let result = conn.client()?.launch(&LaunchRequest { shell: None, argv }).await?;
            emit(&format!("started pid {}\n", result.pid))?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Open { path } => {
            conn.client()?.open(&path).await?;
            emit(&format!("opened {path}\n"))?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Push { local: from, guest_path, no_parents } => {
            let bytes = local::read(&from)?;
            let client = conn.client()?;
            let written =
                with_spinner("uploading", client.push_file(&guest_path, bytes, no_parents.then_some(false))).await?;
            emit(&format!(
                "wrote {} ({}) to {} sha256 {}\n",
                written.size,
                render::size(written.size),
                written.path,
                written.sha256
            ))?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Pull { guest_path, local: to } => {
            let client = conn.client()?;
            let file = with_spinner("downloading", client.pull_file(&guest_path)).await?;
            local::write_atomic(&to, &file.bytes)?;
            emit(&format!("wrote {} bytes to {} sha256 {}\n", file.bytes.len(), to.display(), file.sha256))?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Ls { guest_path, json } => {
            let listing = conn.client()?.list_dir(&guest_path).await?;
            if json {
                emit_json(&listing)?;
            } else {
                emit(&render::listing(&listing))?;
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Stat { guest_path } => {
            emit(&render::stat(&conn.client()?.stat(&guest_path).await?))?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Rm { guest_path, recursive } => {
            conn.client()?.delete(&guest_path, recursive).await?;
            emit(&format!("deleted {guest_path}\n"))?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Mkdir { guest_path } => {
            conn.client()?.mkdir(&guest_path).await?;
            emit(&format!("created {guest_path}\n"))?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Folders => {
            let folders = conn.client()?.folders().await?;
            let rows: Vec<Vec<String>> = folders
                .folders
                .iter()
                .map(|(folder, path)| {
                    let name = serde_json::to_value(folder)
                        .ok()
                        .and_then(|v| v.as_str().map(str::to_owned))
                        .unwrap_or_default();
                    vec![name, path.clone()]
                })
                .collect();
            emit(&render::table(&["FOLDER", "PATH"], &rows))?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Clipboard { command } => {
            let client = conn.client()?;
            match command {
                ClipboardCommand::Get => match client.clipboard_get().await? {
                    ClipboardContent::Text { text } => emit(&format!("{text}\n"))?,
                    ClipboardContent::Empty => emit("(the clipboard is empty)\n")?,
                    ClipboardContent::Image { width, height, .. } => emit(&format!("(an image, {width}x{height})\n"))?,
                    ClipboardContent::Unknown => emit("(content this client does not know)\n")?,
                },
                ClipboardCommand::Set { text } => {
                    client.clipboard_set(&ClipboardContent::Text { text }).await?;
                    emit("clipboard set\n")?;
                }
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Registry { command: RegistryCommand::Get { key, value } } => {
            let read = conn.client()?.registry_get(&key, value.as_deref()).await?;
            emit(&format!("{}\n", render::registry_value(&read.data)))?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Demo(args) => demo::run(conn, args).await,
        Command::Validate(args) => validate::run(&args),
        Command::Run(args) => runs::run(conn, *args).await,
        Command::Merge(args) => runs::merge(&args),
        Command::Report(args) => runs::report(&args),
        Command::Compare(args) => runs::compare(&args),
        Command::Certify(args) => certify::run(conn, *args).await,
        Command::Prep(args) => oem::run(conn, args).await,
        Command::Corpus(args) => corpus::run(args).await,
        Command::Vm(args) => vm::run(conn, args).await,
        Command::Env(args) => env::run(conn, args).await,
    }
}

async fn health(conn: &Connection, wait: Option<Duration>, json: bool) -> anyhow::Result<ExitCode> {
    let client = conn.client()?;
    let show = |report: &arena_shared::health::HealthReport| -> anyhow::Result<()> {
        if json {
            emit_json(report)
        } else {
            emit(&render::health(client.base_url(), report))
        }
    };
    // Each call gets --timeout once, no retries: `health` answers within --wait plus
    // one call, whatever state the guest is in.
    let per_call = conn.timeout;
    let report = match wait {
        Some(overall) => {
            let waited =
                with_spinner("waiting for the guest", client.wait_ready(&[], overall, Duration::from_millis(500)))
                    .await;
            match waited {
                Ok(report) => report,
                Err(err @ ClientError::NotReady { .. }) => {
                    // Show the last state before failing, so the table says what is down;
                    // a guest that did not answer at all is not asked again.
                    if let ClientError::NotReady { last_error: None, .. } = &err {
                        if let Ok(report) = client.health_once(per_call).await {
                            show(&report)?;
                        }
                    }
                    return Err(anyhow::Error::new(err)
                        .context(format!("each health call may take up to {} s (--timeout)", per_call.as_secs_f64())));
                }
                Err(err) => return Err(err.into()),
            }
        }
        None => client
            .health_once(per_call)
            .await
            .with_context(|| format!("one health call of up to {} s (--timeout)", per_call.as_secs_f64()))?,
    };
    show(&report)?;
    let ready = report.status == Readiness::Ready || report.gated_up();
    Ok(if ready { ExitCode::SUCCESS } else { ExitCode::FAILURE })
}

async fn exec(conn: &Connection, args: ExecArgs) -> anyhow::Result<ExitCode> {
    let request = ExecRequest {
        shell: None,
        argv: args.argv,
        timeout_ms: args.timeout.map(|d| d.as_millis() as u64),
        max_output_bytes: None,
        cwd: args.cwd,
        stdin: args.stdin,
    };
    let result = conn.client()?.exec(&request).await?;
    if args.json {
        emit_json(&result)?;
    } else {
        emit(&result.stdout)?;
        let mut stderr = std::io::stderr().lock();
        let _ = stderr.write_all(result.stderr.as_bytes());
        if result.stdout_truncated || result.stderr_truncated {
            tracing::warn!("the program's output was truncated by the guest");
        }
    }
    if result.timed_out {
        tracing::warn!(duration_ms = result.duration_ms, "the program was killed after its timeout");
        return Ok(ExitCode::from(124));
    }
    Ok(exit_code(result.exit_code))
}

/// The process exit code for a guest program's: its own when it fits in a
/// byte, 1 for other failures (Windows NTSTATUS codes), 125 when killed.
fn exit_code(code: Option<i32>) -> ExitCode {
    match code {
        Some(0) => ExitCode::SUCCESS,
        Some(code @ 1..=255) => ExitCode::from(code as u8),
        Some(_) => ExitCode::FAILURE,
        None => ExitCode::from(125),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(words: &[&str]) -> Result<Cli, clap::Error> {
        let matches = Cli::definition().try_get_matches_from(std::iter::once("arena").chain(words.iter().copied()))?;
        <Cli as clap::FromArgMatches>::from_arg_matches(&matches)
    }

    #[test]
    fn the_command_line_is_consistent() {
        use clap::CommandFactory;
        Cli::command().debug_assert();
        Cli::definition().debug_assert();
    }

    #[test]
    fn offline_subcommands_leave_the_connection_options_out_of_their_help() {
        let help = |name: &str| {
            let mut command = Cli::definition();
            command.build();
            let sub = command.find_subcommand_mut(name).unwrap_or_else(|| panic!("{name}"));
            sub.render_long_help().to_string()
        };
        for name in OFFLINE_SUBCOMMANDS {
            let text = help(name);
            for option in ["--guest", "--token", "--token-file"] {
                assert!(!text.contains(option), "{name} --help shows {option}: {text}");
            }
        }
        assert!(help("health").contains("--guest"), "a guest command keeps them");
        assert!(help("run").contains("--token-file"));
        // Given anyway, they are accepted as before (and ignored).
        let cli = parse(&["report", "--guest", "http://10.0.0.2:5000", "results"]).expect("parses");
        assert!(matches!(cli.command, Command::Report(_)));
        let cli = parse(&["--guest", "http://10.0.0.9:5000", "health"]).expect("parses");
        assert_eq!(cli.connection.guest_url(), "http://10.0.0.9:5000");
    }

    #[test]
    fn exec_takes_everything_after_the_separator() {
        let cli = parse(&["exec", "--timeout", "5", "--", "cmd", "/c", "echo", "--flag"]).unwrap();
        let Command::Exec(args) = cli.command else { panic!("not exec") };
        assert_eq!(args.argv, ["cmd", "/c", "echo", "--flag"]);
        assert_eq!(args.timeout, Some(Duration::from_secs(5)));
    }

    #[test]
    fn global_options_go_anywhere_and_timeout_before_the_subcommand() {
        let cli = parse(&["--timeout", "2.5", "health", "--guest", "http://10.0.0.2:5000", "--token", "abc"]).unwrap();
        assert_eq!(cli.connection.guest_url(), "http://10.0.0.2:5000");
        assert_eq!(cli.connection.timeout, Duration::from_millis(2500));
        assert_eq!(cli.connection.resolve_token().unwrap().as_deref(), Some("abc"));
    }

    #[test]
    fn bad_numbers_are_refused_with_the_value() {
        let err = parse(&["--timeout", "soon", "health"]).unwrap_err().to_string();
        assert!(err.contains("\"soon\""), "{err}");
        let err = parse(&["--timeout", "-1", "health"]).unwrap_err().to_string();
        assert!(err.contains("out of range") || err.contains("-1"), "{err}");
    }

    #[test]
    fn token_files_are_read_and_checked() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("token");
        std::fs::write(&path, "  sekrit-token-value \nsecond line\n").unwrap();
        let cli = parse(&["--token-file", path.to_str().unwrap(), "health"]).unwrap();
        assert_eq!(cli.connection.resolve_token().unwrap().as_deref(), Some("sekrit-token-value"));
        std::fs::write(&path, "\n").unwrap();
        let err = cli.connection.resolve_token().unwrap_err();
        assert!(format!("{err:#}").contains("is empty"), "{err:#}");
        let missing = dir.path().join("absent");
        let cli = parse(&["--token-file", missing.to_str().unwrap(), "health"]).unwrap();
        let err = cli.connection.resolve_token().unwrap_err();
        assert!(format!("{err:#}").contains("absent"), "{err:#}");
    }

    #[test]
    fn som_origin_takes_upstreams_names_and_is_recorded() {
        let cli = parse(&["run", "--tasks", "t", "--agent", "navi"]).unwrap();
        let Command::Run(args) = cli.command else { panic!("not run") };
        assert_eq!(args.som_origin, arena_som::SomOrigin::A11y);
        let cli = parse(&[
            "run",
            "--tasks",
            "t",
            "--agent",
            "navi",
            "--llm-url",
            "http://127.0.0.1:9/v1",
            "--model",
            "m",
            "--som-origin",
            "mixed-omni",
            "--omniparser-url",
            "http://127.0.0.1:8000",
        ])
        .unwrap();
        let Command::Run(args) = cli.command else { panic!("not run") };
        assert_eq!(args.som_origin, arena_som::SomOrigin::MixedOmni);
        let chosen = arena_agents::factory::build(&args.agent_options()).unwrap();
        assert!(chosen.options.contains(&("som_origin".to_owned(), "mixed-omni".to_owned())), "{:?}", chosen.options);
        // The service a pixel origin needs is checked before the run starts.
        let cli = parse(&[
            "run",
            "--tasks",
            "t",
            "--agent",
            "navi",
            "--llm-url",
            "http://127.0.0.1:9/v1",
            "--model",
            "m",
            "--som-origin",
            "oss",
        ])
        .unwrap();
        let Command::Run(args) = cli.command else { panic!("not run") };
        if std::env::var_os("ARENA_DETECTOR_URL").is_none() {
            let err = format!("{:#}", arena_agents::factory::build(&args.agent_options()).expect_err("refused"));
            assert!(err.contains("--detector-url"), "{err}");
        }
        let err = parse(&["run", "--tasks", "t", "--som-origin", "mixed"]).unwrap_err().to_string();
        assert!(err.contains("mixed-oss"), "{err}");
    }

    #[test]
    fn exit_codes_follow_the_program() {
        assert_eq!(exit_code(Some(0)), ExitCode::SUCCESS);
        assert_eq!(exit_code(Some(3)), ExitCode::from(3));
        assert_eq!(exit_code(Some(-1073741819)), ExitCode::FAILURE);
        assert_eq!(exit_code(None), ExitCode::from(125));
    }
}
