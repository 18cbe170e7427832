//! The real `arena-guest` and `arena` binaries as child processes: built on first
//! use with the cargo that runs the tests, started on port 0, and asked where they
//! listen (their `listening on URL` line).

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use anyhow::Context;

/// Path of a workspace binary, built on first use with the same cargo that runs the tests.
///
/// It is built as `cargo test --workspace` builds it (`--no-run`), so that the
/// binary has the features the workspace's test build gives its dependencies:
/// under `./test.sh` that build is already done and this one does nothing, where
/// a narrower build (`cargo build -p arena-host`) would resolve other features,
/// rebuild dozens of crates and relink both binaries (three minutes on CI).
///
/// # Errors
///
/// The build failing or the binary still missing afterwards.
pub fn workspace_binary(package: &str, bin: &str) -> anyhow::Result<PathBuf> {
    static BUILT: OnceLock<Result<(), String>> = OnceLock::new();
    let built = BUILT.get_or_init(|| {
        let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
        let status = Command::new(cargo)
            .args(["test", "--workspace", "--no-run", "--quiet"])
            .current_dir(workspace_root())
            .status();
        match status {
            Ok(s) if s.success() => Ok(()),
            Ok(s) => Err(format!("cargo test --workspace --no-run (which builds the binaries) exited with {s}")),
            Err(err) => Err(format!("running cargo test --workspace --no-run: {err}")),
        }
    });
    if let Err(err) = built {
        anyhow::bail!("building {package}/{bin}: {err}");
    }
    let exe = target_dir().join(format!("{bin}{}", std::env::consts::EXE_SUFFIX));
    anyhow::ensure!(exe.exists(), "{} does not exist after building {package}", exe.display());
    Ok(exe)
}

/// The workspace this crate sits in, two folders up (`tests/support/`).
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The `PYTHONPATH` of a test's step-protocol agent written in Python: the
/// project's `python/` package (`arena_agent`), then each of `dirs` (folders
/// relative to the workspace root that hold the test's agents), `:`-separated.
pub fn agent_pythonpath(dirs: &[&str]) -> String {
    let root = workspace_root();
    std::iter::once("python")
        .chain(dirs.iter().copied())
        .map(|dir| root.join(dir).display().to_string())
        .collect::<Vec<_>>()
        .join(":")
}

/// The directory cargo puts binaries of the current profile in: the test
/// executable lives in `<target>/<profile>/deps/`.
fn target_dir() -> PathBuf {
    let exe = std::env::current_exe().unwrap_or_default();
    let mut dir = exe.parent().map(Path::to_path_buf).unwrap_or_default();
    if dir.ends_with("deps") {
        dir.pop();
    }
    dir
}

/// A child process that prints `listening on http://ADDR` and is killed on drop.
#[derive(Debug)]
pub struct Served {
    child: Child,
    pub url: String,
    /// Kept so the guest's root outlives the process.
    _root: Option<tempfile::TempDir>,
}

impl Served {
    /// Starts `exe args...` and waits (up to 60 s) for its `listening on` line.
    ///
    /// # Errors
    ///
    /// The process failing to start, exiting early, or never printing the line.
    pub fn start(exe: &Path, args: &[&str], root: Option<tempfile::TempDir>) -> anyhow::Result<Served> {
        let mut child = Command::new(exe)
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .with_context(|| format!("starting {}", exe.display()))?;
        let stdout = child.stdout.take().context("no stdout")?;
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if let Some(url) = line.strip_prefix("listening on ") {
                    let _ = tx.send(url.trim().to_owned());
                }
            }
        });
        let deadline = Instant::now() + Duration::from_secs(60);
        loop {
            if let Ok(url) = rx.recv_timeout(Duration::from_millis(50)) {
                return Ok(Served { child, url, _root: root });
            }
            if let Some(status) = child.try_wait()? {
                anyhow::bail!("{} exited with {status} before listening", exe.display());
            }
            if Instant::now() > deadline {
                let _ = child.kill();
                anyhow::bail!("{} did not print its listening line within 60 s", exe.display());
            }
        }
    }

    /// Starts the real guest binary with the stub backend on a free loopback port.
    ///
    /// # Errors
    ///
    /// See [`Served::start`].
    pub fn guest(extra: &[&str]) -> anyhow::Result<Served> {
        let exe = workspace_binary("arena-guest", "arena-guest")?;
        Served::guest_of(&exe, extra)
    }

    /// Starts the guest binary `exe` (this tree's or another build's) with the stub
    /// backend on a free loopback port, no settle pauses, and `extra` options. Every
    /// option given here exists in every build since the stub backend did, so that
    /// benches can start older builds the same way.
    ///
    /// # Errors
    ///
    /// See [`Served::start`].
    pub fn guest_of(exe: &Path, extra: &[&str]) -> anyhow::Result<Served> {
        let root = tempfile::tempdir().context("creating the stub root")?;
        let root_path = root.path().to_str().context("non-UTF-8 temp path")?.to_owned();
        let mut args = vec![
            "--backend",
            "stub",
            "--port",
            "0",
            "--stub-root",
            &root_path,
            "--open-settle-ms",
            "0",
            "--activate-settle-ms",
            "0",
        ];
        args.extend_from_slice(extra);
        Served::start(exe, &args, Some(root))
    }

    /// Process id of the child.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }
}

impl Drop for Served {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The guest builds a bench compares side by side, from `ARENA_BENCH_GUESTS`:
/// `LABEL=PATH` pairs separated by commas (`old=../old/target/release/arena-guest,new=target/release/arena-guest`).
/// Empty when the variable is unset.
///
/// # Errors
///
/// A pair without `=`, an empty label, or a path that is not a file.
pub fn bench_guests() -> anyhow::Result<Vec<(String, PathBuf)>> {
    let Some(value) = std::env::var_os(BENCH_GUESTS_VAR) else {
        return Ok(Vec::new());
    };
    let value = value.to_str().with_context(|| format!("{BENCH_GUESTS_VAR} is not UTF-8"))?.to_owned();
    let mut builds = Vec::new();
    for pair in value.split(',').filter(|p| !p.trim().is_empty()) {
        let (label, path) =
            pair.split_once('=').with_context(|| format!("{BENCH_GUESTS_VAR}: {pair:?} is not LABEL=PATH"))?;
        anyhow::ensure!(!label.trim().is_empty(), "{BENCH_GUESTS_VAR}: {pair:?} has an empty label");
        let path = PathBuf::from(path.trim());
        anyhow::ensure!(path.is_file(), "{BENCH_GUESTS_VAR}: {} is not a file", path.display());
        builds.push((label.trim().to_owned(), path));
    }
    Ok(builds)
}

/// The variable [`bench_guests`] reads.
pub const BENCH_GUESTS_VAR: &str = "ARENA_BENCH_GUESTS";

/// Whether `python3` runs here. Without it the test is skipped loudly (a
/// `SKIPPED: <test>: python3 not found` line on stderr, which libtest does not
/// capture, so `./test.sh` counts it), or fails when `ARENA_REQUIRE_PYTHON` is set.
///
/// # Panics
///
/// When `python3` is missing and `ARENA_REQUIRE_PYTHON` is set.
pub fn python3_or_skip(test: &str) -> bool {
    crate::program_or_skip(test, "python3", &["--version"], "python3 not found", "ARENA_REQUIRE_PYTHON")
}

/// A Python a test needs: what it must import, the variable naming it, the variable
/// that makes its absence a failure (CI), and the reason a skip gives (`test.sh`
/// counts skips by their reason).
#[derive(Debug, Clone, Copy)]
pub struct PythonNeed {
    /// The environment variable naming the Python (`.ci/run` makes one under `target/`).
    pub python_var: &'static str,
    /// The environment variable that, set to `1`, turns a missing Python into a failure.
    pub require_var: &'static str,
    /// The statement that must run, e.g. `import mcp`.
    pub imports: &'static str,
    /// What is missing, in words, for the messages.
    pub what: &'static str,
    /// The skip's reason: `SKIPPED: <test>: <reason>`.
    pub reason: &'static str,
}

impl PythonNeed {
    /// A Python that runs [`PythonNeed::imports`] for `test`: `$python_var`, else
    /// `python3`. Without one the skip is said on the process's standard error
    /// directly (libtest does not capture it), so `test.sh` counts it; the test
    /// should then return.
    ///
    /// # Panics
    ///
    /// When there is none and `$require_var` is `1`.
    pub fn find(&self, test: &str) -> Option<String> {
        let candidate = std::env::var(self.python_var).unwrap_or_else(|_| "python3".to_owned());
        if Command::new(&candidate).args(["-c", self.imports]).output().is_ok_and(|o| o.status.success()) {
            return Some(candidate);
        }
        let required = std::env::var(self.require_var).is_ok_and(|v| v == "1");
        self.skip(test, &candidate, required, &mut std::io::stderr());
        None
    }

    /// The skip's line, or the failure when the Python is required.
    pub fn skip(&self, test: &str, candidate: &str, required: bool, out: &mut dyn std::io::Write) {
        assert!(
            !required,
            "{test}: {candidate} cannot import {} and {}=1 (set {})",
            self.what, self.require_var, self.python_var
        );
        // One write of the whole line, so output from other test threads cannot split it.
        let line = format!(
            "{}{test}: {}\n  ({candidate} cannot import {}: set {} to a Python with it; .ci/run makes a venv with it)\n",
            crate::SKIP_PREFIX,
            self.reason,
            self.what,
            self.python_var
        );
        let _ = out.write_all(line.as_bytes());
    }
}

/// `gui-agents` and the vendor SDKs it pins (`openai`, `anthropic`, with `pydantic`,
/// `numpy`, Pillow).
pub const GUI_AGENTS: PythonNeed = PythonNeed {
    python_var: "ARENA_GUI_AGENTS_PYTHON",
    require_var: "ARENA_REQUIRE_GUI_AGENTS",
    imports:
        "import gui_agents.s3.agents.agent_s, gui_agents.s3.agents.grounding, openai, anthropic, pydantic, numpy, PIL",
    what: "gui-agents",
    reason: "gui-agents not installed",
};

/// A Python that has the `gui-agents` package ([`GUI_AGENTS`]), or a loud, counted skip.
///
/// # Panics
///
/// When there is none and `ARENA_REQUIRE_GUI_AGENTS=1` (CI, where `.ci/run` installs it).
pub fn gui_agents_python_or_skip(test: &str) -> Option<String> {
    GUI_AGENTS.find(test)
}
