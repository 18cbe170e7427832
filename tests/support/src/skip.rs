//! The one way a test says it was skipped: a `SKIPPED: <test>: <reason>` line
//! written to the process's standard error directly (libtest captures `println!`
//! and `eprintln!` of a passing test, so a skip said through them is never seen and
//! never counted), or a failure when the test's `ARENA_REQUIRE_*` switch is `1`.
//! `./test.sh` counts the lines by their reason; `.ci/run` sets every switch it
//! can satisfy, so in CI a skip is a failure unless nothing on the machine could
//! provide what the test needs (`./test.sh` lists those by name too).

use std::process::Command;

/// What every skip line starts with.
pub const SKIP_PREFIX: &str = "SKIPPED: ";

/// The reason of the tests that read upstream's own files from a user's
/// WindowsAgentArena checkout: none can be had on CI's machines (no registry
/// serves it), so `./test.sh` counts these skips apart.
pub const UPSTREAM_CHECKOUT_SKIP: &str = "ARENA_WAA_ROOT names no WindowsAgentArena checkout";

/// Skips `test` for `reason` (a loud, counted line), unless `require_var` is `1`.
///
/// # Panics
///
/// When `require_var` is `1`: what the test needs must be there.
pub fn skip(test: &str, reason: &str, require_var: &str) {
    skip_to(test, reason, require_var, std::env::var(require_var).as_deref() == Ok("1"), &mut std::io::stderr());
}

fn skip_to(test: &str, reason: &str, require_var: &str, required: bool, out: &mut dyn std::io::Write) {
    assert!(!required, "{test}: {reason}, and {require_var}=1 makes that a failure");
    // One write of the whole line, so output from other test threads cannot split it.
    let _ = out.write_all(format!("{SKIP_PREFIX}{test}: {reason}\n").as_bytes());
}

/// Whether `program` runs here (`program args` starts and exits 0); otherwise
/// [`skip`]s `test` with `reason`.
///
/// # Panics
///
/// When it does not run and `require_var` is `1`.
pub fn program_or_skip(test: &str, program: &str, args: &[&str], reason: &str, require_var: &str) -> bool {
    if Command::new(program).args(args).output().is_ok_and(|o| o.status.success()) {
        return true;
    }
    skip(test, reason, require_var);
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_skip_is_one_counted_line_or_a_failure_when_required() {
        let mut out = Vec::new();
        skip_to("t", "tesseract not found", "ARENA_REQUIRE_X", false, &mut out);
        assert_eq!(String::from_utf8(out).unwrap(), "SKIPPED: t: tesseract not found\n");
        let failed = std::panic::catch_unwind(|| skip_to("t", "why", "ARENA_REQUIRE_X", true, &mut Vec::new()));
        let message = failed.expect_err("required");
        let text = message.downcast_ref::<String>().cloned().unwrap_or_default();
        assert!(text.contains("ARENA_REQUIRE_X=1"), "{text}");
    }

    #[test]
    fn a_program_that_runs_is_found_and_one_that_does_not_is_skipped() {
        assert!(program_or_skip("t", "sh", &["-c", "exit 0"], "sh not found", "ARENA_REQUIRE_NOTHING_HERE"));
        assert!(!program_or_skip("t", "sh", &["-c", "exit 3"], "sh fails", "ARENA_REQUIRE_NOTHING_HERE"));
        assert!(!program_or_skip("t", "no-such-program-here", &[], "absent", "ARENA_REQUIRE_NOTHING_HERE"));
    }
}
