//! A Python with the official MCP SDK (the `mcp` package), or a loud, counted skip.

use crate::process::PythonNeed;

/// The environment variable naming the Python to use (`.ci/run` makes one under `target/`).
pub const MCP_PYTHON_VAR: &str = "ARENA_MCP_PYTHON";

/// The environment variable that, set to `1`, turns a missing SDK into a failure (CI).
pub const REQUIRE_MCP_SDK_VAR: &str = "ARENA_REQUIRE_MCP_SDK";

/// The reason a skipped test gives, which `test.sh` counts.
pub const MCP_SDK_SKIP: &str = "no Python with the MCP SDK (set ARENA_MCP_PYTHON to one)";

/// What the MCP tests need of Python.
pub const MCP_SDK: PythonNeed = PythonNeed {
    python_var: MCP_PYTHON_VAR,
    require_var: REQUIRE_MCP_SDK_VAR,
    imports: "import mcp, httpx2",
    what: "the MCP SDK",
    reason: MCP_SDK_SKIP,
};

/// A Python that imports the MCP SDK for `test` ([`MCP_SDK`]), or a loud, counted skip.
///
/// # Panics
///
/// When there is none and `ARENA_REQUIRE_MCP_SDK=1`.
pub fn python_with_mcp(test: &str) -> Option<String> {
    MCP_SDK.find(test)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_sdk_is_a_counted_skip_or_a_failure_when_required() {
        let mut out = Vec::new();
        MCP_SDK.skip("some_test", "python9", false, &mut out);
        let said = String::from_utf8(out).expect("utf-8");
        assert!(
            said.starts_with("SKIPPED: some_test: no Python with the MCP SDK (set ARENA_MCP_PYTHON to one)\n"),
            "{said}"
        );
        let failed = std::panic::catch_unwind(|| MCP_SDK.skip("some_test", "python9", true, &mut Vec::new()));
        let message = *failed.expect_err("fails").downcast::<String>().expect("message");
        assert!(message.contains("ARENA_REQUIRE_MCP_SDK=1"), "{message}");
    }
}
