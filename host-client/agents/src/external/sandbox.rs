//! An exec agent's sandbox (`--agent-sandbox`, `--agent-network`, `--agent-env`).
//!
//! An exec agent is a program of someone else's run on the harness's machine. Left
//! as it is, it runs as the harness: it could read `--tasks` (the gold files and
//! oracle plans), rewrite `--out` (earlier tasks' `result.txt` and `episode.json`),
//! find both in `/proc/$PPID/cmdline`, and read the guest token from its
//! environment to drive a guest unrecorded. On Linux it therefore runs under
//! bubblewrap (`bwrap`, Debian's `bubblewrap`), which builds the sandbox from the
//! kernel's namespaces:
//!
//! - its own user, PID, IPC, UTS and (where it can) cgroup namespaces: no other
//!   process of the machine is visible, the harness included;
//! - the whole file system read-only, with `--tasks`, `--out` and the download cache
//!   each covered by an empty folder (a file by an empty file), and a fresh writable
//!   home of its own (`HOME`, `TMPDIR`, the working folder), removed with the run,
//!   and the folders `--agent-writable` names (its logs), which may not overlap those;
//! - an environment of `PATH`, the locale, Python's own variables, the model
//!   providers' usual key and URL variables that are set, and what `--agent-env`
//!   names: never the guest token (`ARENA_TOKEN`, `ARENA_TOKEN_FILE`);
//! - the network as the harness's unless `--agent-network none` (loopback only);
//! - it dies with the harness (`--die-with-parent`) and cannot reach the harness's
//!   terminal (`--new-session`).
//!
//! `--agent-sandbox none` runs it as before (still without the guest token), and is
//! recorded in the results. The protocol itself (stdin and stdout) is unchanged.

use std::ffi::OsString;
use std::path::{Path, PathBuf};

/// Variables an agent keeps inside the sandbox when the harness has them: the
/// platform's, Python's, and the model providers' usual keys and URLs.
pub const KEPT_ENV: &[&str] = &[
    "PATH",
    "LANG",
    "LANGUAGE",
    "LC_ALL",
    "LC_CTYPE",
    "TZ",
    "TERM",
    "PYTHONPATH",
    "PYTHONHOME",
    "PYTHONUNBUFFERED",
    "PYTHONDONTWRITEBYTECODE",
    "VIRTUAL_ENV",
    "ARENA_LLM_URL",
    "ARENA_LLM_MODEL",
    "ARENA_LLM_KEY",
    "OPENAI_API_KEY",
    "OPENAI_BASE_URL",
    "ANTHROPIC_API_KEY",
    "ANTHROPIC_BASE_URL",
    "GEMINI_API_KEY",
    "GOOGLE_API_KEY",
    "AZURE_OPENAI_API_KEY",
    "AZURE_OPENAI_ENDPOINT",
    "OPENROUTER_API_KEY",
    "DASHSCOPE_API_KEY",
    "HF_TOKEN",
];

/// Variables no agent is ever handed, sandboxed or not: the guest's token.
pub const NEVER_ENV: &[&str] = &["ARENA_TOKEN", "ARENA_TOKEN_FILE"];

/// `--agent-network`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum AgentNetwork {
    /// The harness's network (the agent calls its model).
    #[default]
    Host,
    /// Loopback only.
    None,
}

impl AgentNetwork {
    /// `host` or `none`.
    pub fn name(self) -> &'static str {
        match self {
            AgentNetwork::Host => "host",
            AgentNetwork::None => "none",
        }
    }
}

/// `--agent-sandbox`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SandboxMode {
    /// bubblewrap, as the module says (the default on Linux).
    Bwrap,
    /// The agent runs as the harness's user with the harness's view (recorded).
    None,
}

impl SandboxMode {
    /// `bwrap` on Linux, `none` elsewhere (where bubblewrap does not exist).
    pub fn default_here() -> SandboxMode {
        if cfg!(target_os = "linux") {
            SandboxMode::Bwrap
        } else {
            SandboxMode::None
        }
    }

    /// `bwrap` or `none`.
    pub fn name(self) -> &'static str {
        match self {
            SandboxMode::Bwrap => "bwrap",
            SandboxMode::None => "none",
        }
    }
}

impl Default for SandboxMode {
    fn default() -> SandboxMode {
        SandboxMode::default_here()
    }
}

/// What a run asks of its exec agents' sandbox.
#[derive(Debug, Clone, Default)]
pub struct SandboxOptions {
    pub mode: SandboxMode,
    pub network: AgentNetwork,
    /// Paths the agent must not see: `--tasks`, `--out`, the download cache.
    pub hidden: Vec<PathBuf>,
    /// `--agent-env NAME`: more variables it keeps.
    pub env: Vec<String>,
    /// `--agent-writable DIR`: folders it may write in (its own logs, a cache).
    pub writable: Vec<PathBuf>,
}

impl SandboxOptions {
    /// The options a run records: `agent_sandbox`, and `agent_network` when sandboxed.
    pub fn recorded(&self) -> Vec<(String, String)> {
        let mut out = vec![("agent_sandbox".to_owned(), self.mode.name().to_owned())];
        if self.mode == SandboxMode::Bwrap {
            out.push(("agent_network".to_owned(), self.network.name().to_owned()));
        }
        out
    }
}

/// A ready sandbox: bubblewrap found, the hidden paths resolved, the environment
/// chosen, a home made.
#[derive(Debug)]
pub struct Sandbox {
    bwrap: PathBuf,
    network: AgentNetwork,
    /// Canonical paths to cover, with whether each is a folder.
    hidden: Vec<(PathBuf, bool)>,
    /// Canonical folders bound writable.
    writable: Vec<PathBuf>,
    env: Vec<(String, OsString)>,
    home: tempfile::TempDir,
}

impl Sandbox {
    /// A sandbox as `options` say; `Ok(None)` for [`SandboxMode::None`].
    ///
    /// # Errors
    ///
    /// bubblewrap not installed (naming the package and `--agent-sandbox none`), an
    /// `--agent-env` naming the guest token, a hidden folder that cannot be made, or
    /// no temporary folder for the home.
    pub fn new(options: &SandboxOptions) -> Result<Option<Sandbox>, String> {
        for name in &options.env {
            if NEVER_ENV.contains(&name.as_str()) {
                return Err(format!("--agent-env {name}: the guest's token is never handed to an agent"));
            }
        }
        if options.mode == SandboxMode::None {
            return Ok(None);
        }
        let Some(bwrap) = arena_shared::search_path::find_program(Path::new("bwrap")) else {
            return Err("an exec agent runs in a bubblewrap sandbox, and `bwrap` is not on PATH: install it \
                        (Debian and Ubuntu: apt-get install bubblewrap), or pass --agent-sandbox none to run the \
                        agent with the harness's own view of the machine (recorded in the results)"
                .to_owned());
        };
        let mut hidden = Vec::new();
        for path in &options.hidden {
            // A folder the run will make later (its --out) is made now, so that it is
            // covered when the agent's process starts, before the run writes in it.
            if !path.exists() {
                std::fs::create_dir_all(path).map_err(|err| format!("creating {}: {err}", path.display()))?;
            }
            let canonical =
                std::fs::canonicalize(path).map_err(|err| format!("resolving {}: {err}", path.display()))?;
            let is_dir = canonical.is_dir();
            if !hidden.iter().any(|(p, _)| p == &canonical) {
                hidden.push((canonical, is_dir));
            }
        }
        let mut writable = Vec::new();
        for dir in &options.writable {
            let canonical =
                std::fs::canonicalize(dir).map_err(|err| format!("--agent-writable {}: {err}", dir.display()))?;
            if !canonical.is_dir() {
                return Err(format!("--agent-writable {}: not a folder", dir.display()));
            }
            if let Some((hidden, _)) =
                hidden.iter().find(|(h, _)| canonical.starts_with(h) || h.starts_with(&canonical))
            {
                return Err(format!(
                    "--agent-writable {}: it overlaps {}, which the agent must not see (--tasks, --out or the cache)",
                    dir.display(),
                    hidden.display()
                ));
            }
            writable.push(canonical);
        }
        let mut env: Vec<(String, OsString)> = Vec::new();
        for name in KEPT_ENV.iter().copied().chain(options.env.iter().map(String::as_str)) {
            if env.iter().any(|(n, _)| n == name) {
                continue;
            }
            if let Some(value) = std::env::var_os(name) {
                env.push((name.to_owned(), value));
            }
        }
        let home = tempfile::Builder::new()
            .prefix("arena-agent-home-")
            .tempdir()
            .map_err(|err| format!("a home folder for the agent: {err}"))?;
        Ok(Some(Sandbox { bwrap, network: options.network, hidden, writable, env, home }))
    }

    /// The agent's home inside the sandbox (writable, its own).
    pub fn home(&self) -> &Path {
        self.home.path()
    }

    /// The command that runs `argv` in the sandbox.
    pub fn command(&self, argv: &[String]) -> tokio::process::Command {
        let mut command = tokio::process::Command::new(&self.bwrap);
        command.args(self.args()).arg("--").args(argv);
        command.env_clear();
        command
    }

    /// bubblewrap's options, before `--` and the agent's command line.
    pub fn args(&self) -> Vec<OsString> {
        let mut args: Vec<OsString> = Vec::new();
        let mut push = |parts: &[&std::ffi::OsStr]| args.extend(parts.iter().map(|p| p.to_os_string()));
        push(&["--die-with-parent".as_ref(), "--new-session".as_ref()]);
        push(&["--unshare-user".as_ref(), "--unshare-pid".as_ref(), "--unshare-ipc".as_ref()]);
        push(&["--unshare-uts".as_ref(), "--unshare-cgroup-try".as_ref()]);
        if self.network == AgentNetwork::None {
            push(&["--unshare-net".as_ref()]);
        }
        push(&["--ro-bind".as_ref(), "/".as_ref(), "/".as_ref()]);
        push(&["--dev".as_ref(), "/dev".as_ref(), "--proc".as_ref(), "/proc".as_ref()]);
        for (path, is_dir) in &self.hidden {
            if *is_dir {
                push(&["--tmpfs".as_ref(), path.as_os_str()]);
            } else {
                push(&["--ro-bind".as_ref(), "/dev/null".as_ref(), path.as_os_str()]);
            }
        }
        for dir in &self.writable {
            push(&["--bind".as_ref(), dir.as_os_str(), dir.as_os_str()]);
        }
        let home = self.home.path().as_os_str();
        push(&["--bind".as_ref(), home, home, "--chdir".as_ref(), home]);
        push(&["--clearenv".as_ref()]);
        for (name, value) in &self.env {
            push(&["--setenv".as_ref(), name.as_ref(), value.as_os_str()]);
        }
        push(&["--setenv".as_ref(), "HOME".as_ref(), home, "--setenv".as_ref(), "TMPDIR".as_ref(), home]);
        args
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_guest_token_is_never_asked_for_and_none_needs_no_bwrap() {
        let options = SandboxOptions { env: vec!["ARENA_TOKEN".into()], ..SandboxOptions::default() };
        let err = Sandbox::new(&options).unwrap_err();
        assert!(err.contains("never handed"), "{err}");
        let none = SandboxOptions { mode: SandboxMode::None, ..SandboxOptions::default() };
        assert!(Sandbox::new(&none).unwrap().is_none());
        assert_eq!(none.recorded(), vec![("agent_sandbox".to_owned(), "none".to_owned())]);
    }

    #[test]
    fn the_arguments_cover_the_hidden_paths_and_keep_only_the_listed_variables() {
        if arena_shared::search_path::find_program(Path::new("bwrap")).is_none() {
            // Sandbox::new refuses without bubblewrap; the suite's end-to-end test
            // (tests/tests/agent_sandbox.rs) requires it in CI.
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        let tasks = dir.path().join("tasks");
        std::fs::create_dir(&tasks).unwrap();
        let index = dir.path().join("index.json");
        std::fs::write(&index, "{}").unwrap();
        let out = dir.path().join("out-not-yet");
        let options = SandboxOptions {
            mode: SandboxMode::Bwrap,
            network: AgentNetwork::None,
            hidden: vec![tasks.clone(), index.clone(), out.clone()],
            env: vec!["ARENA_SANDBOX_TEST_EXTRA".into()],
            writable: vec![],
        };
        let inside = SandboxOptions { writable: vec![tasks.join("..").join("tasks")], ..options.clone() };
        assert!(
            Sandbox::new(&inside).unwrap_err().contains("overlaps"),
            "a writable folder cannot uncover a hidden one"
        );
        let sandbox = Sandbox::new(&options).unwrap().expect("a sandbox");
        assert!(out.is_dir(), "a folder the run makes later is made now, to be covered");
        let args: Vec<String> = sandbox.args().iter().map(|a| a.to_string_lossy().into_owned()).collect();
        let joined = args.join(" ");
        let canon = |p: &Path| std::fs::canonicalize(p).unwrap().display().to_string();
        assert!(joined.contains(&format!("--tmpfs {}", canon(&tasks))), "{joined}");
        assert!(joined.contains(&format!("--tmpfs {}", canon(&out))), "{joined}");
        assert!(joined.contains(&format!("--ro-bind /dev/null {}", canon(&index))), "{joined}");
        assert!(joined.contains("--unshare-net") && joined.contains("--unshare-pid"), "{joined}");
        assert!(joined.contains("--clearenv"), "{joined}");
        assert!(!joined.contains("ARENA_TOKEN"), "{joined}");
        assert_eq!(
            options.recorded(),
            vec![("agent_sandbox".to_owned(), "bwrap".to_owned()), ("agent_network".to_owned(), "none".to_owned())]
        );
    }
}
