//! The exec agents' sandbox (bubblewrap) as the suites meet it.
//!
//! `arena run --agent exec` runs its agent under bubblewrap on Linux by default, and
//! refuses when `bwrap` is missing. The suite about the sandbox itself needs it
//! ([`bwrap_or_skip`]); the suites about other things pass [`exec_sandbox_args`],
//! which keeps the default where bubblewrap is installed and otherwise runs the
//! agent outside a sandbox, saying so (a failure with `ARENA_REQUIRE_BWRAP=1`,
//! which `.ci/run` sets).

use std::io::Write as _;
use std::process::Command;

/// The variable that makes a missing bubblewrap a failure.
pub const REQUIRE_BWRAP_VAR: &str = "ARENA_REQUIRE_BWRAP";

fn bwrap_runs() -> bool {
    Command::new("bwrap").arg("--version").output().is_ok_and(|o| o.status.success())
}

/// Whether bubblewrap runs; a counted skip for `test` otherwise.
pub fn bwrap_or_skip(test: &str) -> bool {
    crate::program_or_skip(test, "bwrap", &["--version"], "bwrap not found", REQUIRE_BWRAP_VAR)
}

/// `arena run` flags for a suite's exec agent: `--agent-sandbox bwrap` where
/// bubblewrap runs, else `--agent-sandbox none` with a note on stderr (a failure
/// when [`REQUIRE_BWRAP_VAR`] is `1`).
pub fn exec_sandbox_args() -> [&'static str; 2] {
    if bwrap_runs() {
        return ["--agent-sandbox", "bwrap"];
    }
    assert!(
        std::env::var(REQUIRE_BWRAP_VAR).as_deref() != Ok("1"),
        "bwrap is not installed and {REQUIRE_BWRAP_VAR}=1 (apt-get install bubblewrap)"
    );
    // Straight to the process's stderr, as a skip line is (libtest captures eprintln!).
    let _ =
        writeln!(std::io::stderr(), "NOTE: bwrap not found: this suite's exec agent runs with --agent-sandbox none");
    ["--agent-sandbox", "none"]
}
