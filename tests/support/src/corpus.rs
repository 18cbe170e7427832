//! Where the upstream WAA task corpus is, or a loud skip that `test.sh` counts.

use crate::skip::SKIP_PREFIX;
use std::path::{Path, PathBuf};

/// The environment variable that names the corpus folder (holding `examples/`,
/// `examples_noctxt/` and the index files).
pub const CORPUS_VAR: &str = "ARENA_WAA_TASKS";

/// The environment variable that, set to `1`, turns a missing corpus into a failure (CI).
pub const REQUIRE_CORPUS_VAR: &str = "ARENA_REQUIRE_CORPUS";

/// Where the corpus is by default: `shared/reference/waa-tasks` beside the workspace.
fn default_corpus() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/reference/waa-tasks")
}

/// The WAA corpus folder for `test`: `ARENA_WAA_TASKS` when set, else
/// `../shared/reference/waa-tasks` beside the workspace.
///
/// When there is none, the skip is said on the process's standard error directly
/// (libtest does not capture it), as `SKIPPED: <test>: WAA corpus not found (set
/// ARENA_WAA_TASKS)`, so `test.sh` can count it; the test should then return.
///
/// # Panics
///
/// When `ARENA_WAA_TASKS` names something that is not a folder (a typo must not
/// turn into a quiet skip), and when the corpus is missing while
/// `ARENA_REQUIRE_CORPUS=1`.
pub fn waa_corpus(test: &str) -> Option<PathBuf> {
    let required = std::env::var(REQUIRE_CORPUS_VAR).is_ok_and(|v| v == "1");
    locate(test, std::env::var_os(CORPUS_VAR).map(PathBuf::from), default_corpus(), required, &mut std::io::stderr())
}

/// [`waa_corpus`] with its inputs given, for testing it.
fn locate(
    test: &str,
    from_env: Option<PathBuf>,
    default: PathBuf,
    required: bool,
    out: &mut dyn std::io::Write,
) -> Option<PathBuf> {
    if let Some(dir) = from_env {
        assert!(
            dir.is_dir(),
            "{CORPUS_VAR}={} is not a folder (it should hold examples/ and test_all.json)",
            dir.display()
        );
        return Some(dir);
    }
    if default.is_dir() {
        return Some(default);
    }
    assert!(
        !required,
        "{REQUIRE_CORPUS_VAR}=1 but the WAA corpus was not found for {test}: set {CORPUS_VAR} or put it at {}",
        default.display()
    );
    // One write of the whole line, so output from other test threads cannot split it.
    let line = format!("{SKIP_PREFIX}{test}: WAA corpus not found (set {CORPUS_VAR})\n");
    let _ = out.write_all(line.as_bytes());
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(from_env: Option<PathBuf>, default: PathBuf, required: bool) -> (Option<PathBuf>, String) {
        let mut out = Vec::new();
        let found = locate("some_test", from_env, default, required, &mut out);
        (found, String::from_utf8(out).expect("utf-8"))
    }

    #[test]
    fn the_variable_wins_then_the_default_then_a_loud_skip() {
        let a = tempfile::tempdir().expect("dir");
        let b = tempfile::tempdir().expect("dir");
        let missing = b.path().join("missing");
        assert_eq!(run(Some(a.path().into()), b.path().into(), false), (Some(a.path().into()), String::new()));
        assert_eq!(run(None, b.path().into(), true), (Some(b.path().into()), String::new()));
        let (found, said) = run(None, missing, false);
        assert_eq!(found, None);
        assert_eq!(said, "SKIPPED: some_test: WAA corpus not found (set ARENA_WAA_TASKS)\n");
    }

    #[test]
    fn a_required_corpus_that_is_missing_fails() {
        let dir = tempfile::tempdir().expect("dir");
        let missing = dir.path().join("missing");
        let result = std::panic::catch_unwind(|| run(None, missing, true));
        let message = *result.expect_err("fails").downcast::<String>().expect("message");
        assert!(message.contains("ARENA_REQUIRE_CORPUS=1"), "{message}");
    }

    #[test]
    fn a_variable_that_names_no_folder_fails_rather_than_skips() {
        let dir = tempfile::tempdir().expect("dir");
        let typo = dir.path().join("wrong");
        let result = std::panic::catch_unwind(|| run(Some(typo), dir.path().into(), false));
        let message = *result.expect_err("fails").downcast::<String>().expect("message");
        assert!(message.contains("is not a folder"), "{message}");
    }
}
