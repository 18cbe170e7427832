//! The server's configuration: one struct, filled by clap from flags and `ARENA_*`
//! variables, which the server runs with and the service, the logon task and its
//! launcher check before they store serve options (so it lives in this crate, below
//! both; `arena_guest::config` re-exports it).

use std::net::{IpAddr, Ipv4Addr};
use std::path::PathBuf;
use std::time::Duration;

/// Which backend drives the desktop.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum BackendKind {
    /// The deterministic in-memory desktop (every platform).
    Stub,
    /// The real Windows desktop (Windows builds only).
    Windows,
}

/// Which UI Automation view the Windows backend's `uia` tree walks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum UiaView {
    /// Every element, as pywinauto's `backend="uia"` (which produced upstream's trees
    /// and Set-of-Marks) walks it.
    #[default]
    Raw,
    /// Only the elements UI Automation marks as controls (Narrator's view): smaller
    /// trees, without the layout panes and text runs many programs expose.
    Control,
}

/// Log output format.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum LogFormat {
    Text,
    Json,
}

/// Everything the server needs to start.
#[derive(Debug, Clone, clap::Parser)]
#[command(
    name = "arena-guest",
    version,
    about = "Desktop-control server for Windows agent benchmarks (WAA-compatible)"
)]
pub struct ServerConfig {
    /// Backend: `windows` (default on Windows) or `stub`.
    #[arg(long, env = "ARENA_BACKEND", value_enum)]
    pub backend: Option<BackendKind>,

    /// Address to bind. Anything but loopback needs a token or --allow-unauthenticated.
    #[arg(long, env = "ARENA_BIND", default_value_t = IpAddr::V4(Ipv4Addr::LOCALHOST))]
    pub bind: IpAddr,

    /// TCP port (upstream WAA uses 5000; 0 picks a free one).
    #[arg(long, env = "ARENA_PORT", default_value_t = 5000)]
    pub port: u16,

    /// Bearer token every request except `/probe` and `/v1/health` must carry.
    #[arg(long, env = "ARENA_TOKEN", hide_env_values = true, conflicts_with = "token_file")]
    pub token: Option<String>,

    /// File holding the bearer token (first line, whitespace trimmed).
    #[arg(long, env = "ARENA_TOKEN_FILE")]
    pub token_file: Option<PathBuf>,

    /// Serve a non-loopback address without a token, as upstream WAA does. Logs a warning.
    #[arg(long, env = "ARENA_ALLOW_UNAUTHENTICATED")]
    pub allow_unauthenticated: bool,

    /// Without a token, also accept requests whose Host header names this host (a DNS
    /// name the host side reaches the guest by). Repeat or separate with commas.
    #[arg(long, env = "ARENA_ALLOW_HOST", value_delimiter = ',', value_name = "NAME")]
    pub allow_host: Vec<String>,

    /// Stub backend: directory the guest's `C:\` and other drives are mapped into
    /// (default: a fresh temporary directory, removed at exit).
    #[arg(long, env = "ARENA_STUB_ROOT")]
    pub stub_root: Option<PathBuf>,

    /// Stub backend: JSON scenario seeding windows, files, clipboard, registry and programs.
    #[arg(long, env = "ARENA_SCENARIO")]
    pub scenario: Option<PathBuf>,

    /// Stub backend: run commands that are none of its simulated programs as REAL
    /// processes on this machine, as the user running the server (tests that need
    /// a real process). Without it such a command is refused, so agent code on the
    /// stub cannot start anything on the host.
    #[arg(long, env = "ARENA_STUB_HOST_EXEC")]
    pub stub_host_exec: bool,

    /// Stub backend: screen size as WIDTHxHEIGHT.
    #[arg(long, env = "ARENA_SCREEN", default_value = "1440x900", value_parser = parse_size)]
    pub screen: (u32, u32),

    /// Most connections served at once; one more is answered 503 and closed.
    #[arg(long, env = "ARENA_MAX_CONNECTIONS", default_value_t = 1024)]
    pub max_connections: usize,

    /// Time a client has to send a request's headers, and that an idle keep-alive
    /// connection stays open, in milliseconds.
    #[arg(long, env = "ARENA_HEADER_TIMEOUT_MS", default_value_t = 10_000)]
    pub header_timeout_ms: u64,

    /// On shutdown, how long requests in flight may take before their connections are
    /// dropped, in milliseconds.
    #[arg(long, env = "ARENA_SHUTDOWN_GRACE_MS", default_value_t = 5_000)]
    pub shutdown_grace_ms: u64,

    /// How long one health report is reused, in milliseconds: a flood of `/v1/health`
    /// polls costs one probe of each component per period.
    #[arg(long, env = "ARENA_HEALTH_CACHE_MS", default_value_t = 1000)]
    pub health_cache_ms: u64,

    /// Largest request body accepted by the upload routes (`PUT /v1/files`,
    /// `/setup/upload`), in bytes. The JSON routes have small limits of their own
    /// (see `JSON_BODY_BYTES` and its neighbours in `arena_guest::config`).
    #[arg(long, env = "ARENA_MAX_BODY", default_value_t = 1 << 30)]
    pub max_body_bytes: usize,

    /// Deadline of one ordinary backend call, in milliseconds.
    #[arg(long, env = "ARENA_CALL_TIMEOUT_MS", default_value_t = 30_000)]
    pub call_timeout_ms: u64,

    /// Deadline of an accessibility-tree walk, in milliseconds (upstream's client waits 300 s).
    #[arg(long, env = "ARENA_A11Y_TIMEOUT_MS", default_value_t = 60_000)]
    pub a11y_timeout_ms: u64,

    /// Timeout of `/execute` commands in milliseconds (upstream: 120 s).
    #[arg(long, env = "ARENA_EXEC_TIMEOUT_MS", default_value_t = 120_000)]
    pub exec_timeout_ms: u64,

    /// Most programs run at once (`/execute`, `/setup/execute`, `/execute_windows`,
    /// `/v1/exec` and MCP `run_python`); one more waits for a free place up to
    /// `--program-wait-ms`, then is answered 503 naming this limit.
    #[arg(long, env = "ARENA_MAX_PROGRAMS", default_value_t = 8, value_parser = clap::value_parser!(u32).range(1..=1024))]
    pub max_programs: u32,

    /// How long a program waits for a free place under `--max-programs`, in milliseconds.
    #[arg(long, env = "ARENA_PROGRAM_WAIT_MS", default_value_t = 10_000)]
    pub program_wait_ms: u64,

    /// The interpreter memory all programs running at once share, in MiB (each also
    /// has its own 256 MiB); past it a program fails with `MemoryError` naming it.
    #[arg(long, env = "ARENA_PROGRAM_MEMORY_MIB", default_value_t = 512, value_parser = clap::value_parser!(u64).range(16..=1_048_576))]
    pub program_memory_mib: u64,

    /// With `--mcp`: most MCP sessions open at once; a new one closes the session idle
    /// longest (none when every session has a call running: then it is refused).
    #[arg(long, env = "ARENA_MCP_MAX_SESSIONS", default_value_t = 64, value_parser = clap::value_parser!(u32).range(1..=100_000))]
    pub mcp_max_sessions: u32,

    /// With `--mcp`: an MCP session with no call for this many seconds is closed.
    #[arg(long, env = "ARENA_MCP_IDLE_SECS", default_value_t = 120, value_parser = clap::value_parser!(u64).range(1..=86_400))]
    pub mcp_idle_secs: u64,

    /// Pause after `/setup/open_file` opens a file, in milliseconds (upstream sleeps 5 s).
    #[arg(long, env = "ARENA_OPEN_SETTLE_MS", default_value_t = 5_000)]
    pub open_settle_ms: u64,

    /// Pause between minimise and restore (and after restore) in strict `/setup/activate_window`,
    /// in milliseconds (upstream sleeps 1 s each).
    #[arg(long, env = "ARENA_ACTIVATE_SETTLE_MS", default_value_t = 1_000)]
    pub activate_settle_ms: u64,

    /// A real Python for `/execute` code outside the natively interpreted subset
    /// (default: none, so such code is refused with a message naming the construct).
    #[arg(long, env = "ARENA_PYTHON")]
    pub python: Option<PathBuf>,

    /// Pause after each `computer.*` action of `/execute_windows`, in milliseconds (upstream sleeps 0.25 s).
    #[arg(long, env = "ARENA_COMPUTER_ACTION_DELAY_MS", default_value_t = 250)]
    pub computer_action_delay_ms: u64,

    /// Loopback port of the browser's DevTools HTTP endpoint that `/v1/browser/...`
    /// forwards to (upstream starts Chrome and Edge with `--remote-debugging-port=1337`).
    #[arg(long, env = "ARENA_CDP_PORT", default_value_t = 1337)]
    pub cdp_port: u16,

    /// Windows backend: the UI Automation view the `uia` tree walks (`raw`, as pywinauto
    /// walks it for upstream, or `control`).
    #[arg(long, env = "ARENA_UIA_VIEW", value_enum, default_value_t = UiaView::Raw)]
    pub uia_view: UiaView,

    /// Windows backend: capture the screen with `CAPTUREBLT`, as Pillow's
    /// `ImageGrab.grab(include_layered_windows=True)` does. Off by default, as in
    /// Pillow's plain `grab()`, which pyautogui's screenshots use.
    #[arg(long, env = "ARENA_CAPTURE_LAYERED")]
    pub capture_layered: bool,

    /// Windows backend: how long each phase of a drag lasts (after the press, at the
    /// midpoint, at the target before the release), in milliseconds. The default is OLE's
    /// drag delay (`DD_DEFDRAGDELAY`, 200 ms, in the SDK's `oleidl.h`): a drag source that
    /// waits it out has started its drag before the pointer moves on, and the target has
    /// seen the pointer over it before the button comes up (OLE and HTML5 drag and drop
    /// lose faster drags).
    #[arg(long, env = "ARENA_DRAG_STEP_MS", default_value_t = 200, value_parser = clap::value_parser!(u64).range(0..=5_000))]
    pub drag_step_ms: u64,

    /// The image setup's record (`setup.ps1` writes it step by step), which the
    /// `setup` health component reports [default: `%ProgramData%\arena\setup-status.json`
    /// on Windows, none elsewhere]; without a record the component is up.
    #[arg(long, env = "ARENA_SETUP_STATUS", value_name = "FILE")]
    pub setup_status: Option<PathBuf>,

    /// How long the CPU must stay idle before the `shell` health component says the
    /// desktop has settled (with the taskbar shown and the desktop in front), in
    /// milliseconds; 0 leaves the CPU out. A host waits for it before it saves the
    /// snapshot its tasks start from.
    #[arg(long, env = "ARENA_SETTLE_IDLE_MS", default_value_t = 5_000, value_parser = clap::value_parser!(u64).range(0..=3_600_000))]
    pub settle_idle_ms: u64,

    /// Stub backend: the modelled shell shows its taskbar this many milliseconds
    /// after the server starts, and the CPU counts as busy until then (a shell that
    /// settles late, for tests of hosts that wait for it).
    #[arg(long, env = "ARENA_STUB_SHELL_AFTER_MS", default_value_t = 0, value_parser = clap::value_parser!(u64).range(0..=3_600_000))]
    pub stub_shell_after_ms: u64,

    /// Log format.
    #[arg(long, env = "ARENA_LOG_FORMAT", value_enum, default_value_t = LogFormat::Text)]
    pub log_format: LogFormat,

    /// Also serve the Model Context Protocol at `/mcp` (streamable HTTP), with the
    /// desktop tools, behind the same token and guards as every route.
    #[arg(long, env = "ARENA_MCP")]
    pub mcp: bool,

    /// With `--mcp`: let MCP clients run command lines in the guest's shell (the `shell`
    /// tool: PowerShell on Windows, the stub's shell elsewhere). Off by default, and
    /// `shell` is then refused: a shell reaches everything the server's account can.
    #[arg(long, env = "ARENA_MCP_SHELL", requires = "mcp")]
    pub mcp_shell: bool,

    /// Set by the Windows service's supervisor on the worker it starts: the worker shuts
    /// down gracefully when its standard input closes (the supervisor's stop signal, which
    /// also fires when the supervisor dies) and logs without colours, since its output
    /// goes to a file.
    #[arg(long, hide = true)]
    pub worker: bool,
}

impl ServerConfig {
    pub fn call_timeout(&self) -> Duration {
        Duration::from_millis(self.call_timeout_ms)
    }

    pub fn a11y_timeout(&self) -> Duration {
        Duration::from_millis(self.a11y_timeout_ms)
    }

    /// A configuration for tests and embedding: stub backend on loopback, port 0, no token,
    /// no settle pauses, no action delay and no real Python.
    pub fn for_stub() -> ServerConfig {
        ServerConfig {
            backend: Some(BackendKind::Stub),
            bind: IpAddr::V4(Ipv4Addr::LOCALHOST),
            port: 0,
            token: None,
            token_file: None,
            allow_unauthenticated: false,
            allow_host: Vec::new(),
            stub_root: None,
            scenario: None,
            stub_host_exec: false,
            screen: (1440, 900),
            max_body_bytes: 1 << 30,
            health_cache_ms: 1000,
            max_connections: 1024,
            header_timeout_ms: 10_000,
            shutdown_grace_ms: 5_000,
            call_timeout_ms: 30_000,
            a11y_timeout_ms: 60_000,
            exec_timeout_ms: 120_000,
            max_programs: 8,
            program_wait_ms: 10_000,
            program_memory_mib: 512,
            mcp_max_sessions: 64,
            mcp_idle_secs: 120,
            open_settle_ms: 0,
            activate_settle_ms: 0,
            python: None,
            computer_action_delay_ms: 0,
            cdp_port: 1337,
            uia_view: UiaView::Raw,
            capture_layered: false,
            drag_step_ms: 200,
            setup_status: None,
            settle_idle_ms: 0,
            stub_shell_after_ms: 0,
            log_format: LogFormat::Text,
            mcp: false,
            mcp_shell: false,
            worker: false,
        }
    }
}

fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(|| format!("screen size {s:?} is not WIDTHxHEIGHT"))?;
    let parse = |v: &str| v.trim().parse::<u32>().ok().filter(|n| (16..=16384).contains(n));
    match (parse(w), parse(h)) {
        (Some(w), Some(h)) => Ok((w, h)),
        _ => Err(format!("screen size {s:?} needs two whole numbers from 16 to 16384")),
    }
}
