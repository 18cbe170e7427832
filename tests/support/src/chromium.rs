//! A headless Chromium for the tests that drive a real browser, or a loud skip; and
//! one launcher that starts it with DevTools on a free port.

use std::path::PathBuf;

/// The environment variable naming the Chromium to use.
pub const CHROMIUM_VAR: &str = "CHROMIUM";

/// The environment variable that, set to `1`, turns a missing Chromium into a failure (CI).
pub const REQUIRE_CHROMIUM_VAR: &str = "ARENA_REQUIRE_CHROMIUM";

/// Where Debian puts its Chromium builds (`chromium`, `chromium-headless-shell`).
const DEBIAN_CHROMIUMS: [&str; 3] =
    ["/usr/bin/chromium", "/usr/bin/chromium-headless-shell", "/usr/lib/chromium/chromium-headless-shell"];

/// A headless Chromium: `$CHROMIUM`, else one of Debian's.
pub fn find_chromium() -> Option<PathBuf> {
    std::env::var_os(CHROMIUM_VAR)
        .map(PathBuf::from)
        .into_iter()
        .chain(DEBIAN_CHROMIUMS.map(PathBuf::from))
        .find(|path| path.is_file())
}

/// A headless Chromium for `test`, or `None` after a `SKIPPED: <test>: chromium not
/// installed …` line on stderr (which libtest does not capture).
///
/// # Panics
///
/// When there is none and `ARENA_REQUIRE_CHROMIUM=1`.
pub fn chromium_or_skip(test: &str) -> Option<PathBuf> {
    let found = find_chromium();
    if found.is_none() {
        let required = std::env::var(REQUIRE_CHROMIUM_VAR).as_deref() == Ok("1");
        skip(test, required, &mut std::io::stderr());
    }
    found
}

fn skip(test: &str, required: bool, out: &mut dyn std::io::Write) {
    assert!(!required, "{REQUIRE_CHROMIUM_VAR}=1 but no chromium was found (set {CHROMIUM_VAR})");
    let _ = writeln!(
        out,
        "{}{test}: chromium not installed (apt-get install chromium-headless-shell, or set {CHROMIUM_VAR})",
        crate::SKIP_PREFIX
    );
}

/// A headless Chromium with DevTools on a free port, its profile in a temporary
/// folder, killed on drop.
#[cfg(feature = "guest")]
#[derive(Debug)]
pub struct Chromium {
    child: tokio::process::Child,
    /// Where DevTools listens, on 127.0.0.1.
    pub port: u16,
    _profile: tempfile::TempDir,
}

#[cfg(feature = "guest")]
impl Chromium {
    /// Starts `binary` on `url` with `args` beside the headless ones, and waits until
    /// DevTools listens.
    ///
    /// # Panics
    ///
    /// When it does not start or exits before DevTools listens (a test's failure).
    pub async fn start(binary: &std::path::Path, args: &[&str], url: &str) -> Chromium {
        use tokio::io::AsyncBufReadExt as _;
        let profile = tempfile::tempdir().expect("a profile folder");
        let mut child = tokio::process::Command::new(binary)
            .args(["--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--remote-debugging-port=0"])
            .args(args)
            .arg(format!("--user-data-dir={}", profile.path().display()))
            .arg(url)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped())
            .kill_on_drop(true)
            .spawn()
            .expect("chromium starts");
        // Ready when it prints "DevTools listening on ws://127.0.0.1:<port>/devtools/browser/<id>".
        let mut lines = tokio::io::BufReader::new(child.stderr.take().expect("stderr")).lines();
        let port = loop {
            let line =
                lines.next_line().await.expect("chromium's stderr").expect("chromium exited before DevTools listened");
            if let Some(rest) = line.split("ws://127.0.0.1:").nth(1) {
                break rest.split('/').next().and_then(|p| p.parse::<u16>().ok()).expect("a port");
            }
        };
        // Its log is drained so that it never blocks on a full pipe.
        tokio::spawn(async move { while let Ok(Some(_)) = lines.next_line().await {} });
        Chromium { child, port, _profile: profile }
    }
}

#[cfg(feature = "guest")]
impl Drop for Chromium {
    fn drop(&mut self) {
        let _ = self.child.start_kill();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_chromium_is_a_counted_skip_or_a_failure_when_required() {
        let mut out = Vec::new();
        skip("some_test", false, &mut out);
        let said = String::from_utf8(out).expect("utf-8");
        assert!(said.starts_with("SKIPPED: some_test: chromium not installed"), "{said}");
        let failed = std::panic::catch_unwind(|| skip("some_test", true, &mut Vec::new()));
        let message = *failed.expect_err("fails").downcast::<String>().expect("message");
        assert!(message.contains("ARENA_REQUIRE_CHROMIUM=1"), "{message}");
    }
}
