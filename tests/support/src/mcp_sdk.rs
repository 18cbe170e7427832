//! A Python with the official MCP SDK (the `mcp` package), or a loud, counted skip.

use std::process::Command;

use crate::corpus::SKIP_PREFIX;

/// The environment variable naming the Python to use (`.ci/run` makes one under `target/`).
pub const MCP_PYTHON_VAR: &str = "ARENA_MCP_PYTHON";

/// The environment variable that, set to `1`, turns a missing SDK into a failure (CI).
pub const REQUIRE_MCP_SDK_VAR: &str = "ARENA_REQUIRE_MCP_SDK";

/// The reason a skipped test gives, which `test.sh` counts.
pub const MCP_SDK_SKIP: &str = "no Python with the MCP SDK (set ARENA_MCP_PYTHON to one)";

/// A Python that imports the MCP SDK for `test`: `ARENA_MCP_PYTHON`, else `python3`.
///
/// Without one the skip is said on the process's standard error directly (libtest does
/// not capture it), as `SKIPPED: <test>: MCP SDK not installed`, so `test.sh` counts it;
/// the test should then return.
///
/// # Panics
///
/// When there is none and `ARENA_REQUIRE_MCP_SDK=1`.
pub fn python_with_mcp(test: &str) -> Option<String> {
    let candidate = std::env::var(MCP_PYTHON_VAR).unwrap_or_else(|_| "python3".to_owned());
    let ok = Command::new(&candidate).args(["-c", "import mcp, httpx2"]).output().is_ok_and(|o| o.status.success());
    if ok {
        return Some(candidate);
    }
    let required = std::env::var(REQUIRE_MCP_SDK_VAR).is_ok_and(|v| v == "1");
    skip(test, &candidate, required, &mut std::io::stderr());
    None
}

/// The skip's line, or the failure when the SDK is required.
fn skip(test: &str, candidate: &str, required: bool, out: &mut dyn std::io::Write) {
    assert!(
        !required,
        "{test}: {candidate} cannot import the MCP SDK and {REQUIRE_MCP_SDK_VAR}=1 (set {MCP_PYTHON_VAR})"
    );
    // One write of the whole line, so output from other test threads cannot split it.
    let line = format!(
        "{SKIP_PREFIX}{test}: {MCP_SDK_SKIP}\n  ({candidate} cannot import mcp; .ci/run makes a venv with it)\n"
    );
    let _ = out.write_all(line.as_bytes());
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_sdk_is_a_counted_skip_or_a_failure_when_required() {
        let mut out = Vec::new();
        skip("some_test", "python9", false, &mut out);
        let said = String::from_utf8(out).expect("utf-8");
        assert!(
            said.starts_with("SKIPPED: some_test: no Python with the MCP SDK (set ARENA_MCP_PYTHON to one)\n"),
            "{said}"
        );
        let failed = std::panic::catch_unwind(|| skip("some_test", "python9", true, &mut Vec::new()));
        let message = *failed.expect_err("fails").downcast::<String>().expect("message");
        assert!(message.contains("ARENA_REQUIRE_MCP_SDK=1"), "{message}");
    }
}
