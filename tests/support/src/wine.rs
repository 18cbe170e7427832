//! Whether the Wine suite can run here, or a loud skip that says why.

use std::path::PathBuf;

/// Where the Wine pieces are, when a Wine test can run.
#[derive(Debug, Clone)]
pub struct WineSetup {
    /// The `wine` launcher (`ARENA_WINE`, else `/usr/bin/wine`).
    pub wine: PathBuf,
    /// The cross-built `arena-guest.exe` (`ARENA_WINDOWS_EXE`).
    pub exe: PathBuf,
}

/// Finds Wine, the exe and a prepared prefix (`scripts/wine-test.sh` sets them up),
/// or prints a loud `SKIPPED:` banner naming `suite` and why, and returns `None`.
///
/// # Panics
///
/// When `ARENA_REQUIRE_WINE=1` (CI) and the suite cannot run: a skip is then a failure.
pub fn wine_or_skip(suite: &str) -> Option<WineSetup> {
    let required = std::env::var("ARENA_REQUIRE_WINE").is_ok_and(|v| v == "1");
    let skip = |why: String| -> Option<WineSetup> {
        // Straight to the stderr handle, past the test harness's output capture, so the
        // skip shows in every `cargo test` log and is never mistaken for a pass.
        use std::io::Write;
        let banner = format!(
            "\n==============================================================\n\
             SKIPPED: {suite} did not run: {why}\n\
             Run scripts/wine-test.sh (it builds the exe and sets up Wine).\n\
             ==============================================================\n"
        );
        let _ = std::io::stderr().write_all(banner.as_bytes());
        assert!(!required, "ARENA_REQUIRE_WINE=1 but {suite} cannot run: {why}");
        None
    };
    let Some(exe) = std::env::var_os("ARENA_WINDOWS_EXE").map(PathBuf::from) else {
        return skip("ARENA_WINDOWS_EXE is not set".into());
    };
    if !exe.is_file() {
        return skip(format!("{} does not exist", exe.display()));
    }
    let wine = std::env::var_os("ARENA_WINE").map(PathBuf::from).unwrap_or_else(|| PathBuf::from("/usr/bin/wine"));
    if !wine.is_file() {
        return skip(format!("{} does not exist (apt-get install wine wine64)", wine.display()));
    }
    if std::env::var_os("DISPLAY").is_none() || std::env::var_os("WINEPREFIX").is_none() {
        return skip("DISPLAY and WINEPREFIX must be set (Xvfb and a prepared prefix)".into());
    }
    Some(WineSetup { wine, exe })
}
