//! Where the stand-in guest image for the QEMU tests is (`scripts/build-standin-image.sh`
//! builds it; docs/vm-standin.md), or a loud skip that `test.sh` counts.

use std::path::{Path, PathBuf};

use crate::skip::SKIP_PREFIX;

/// The environment variable that names the folder the image was built into.
pub const STANDIN_DIR_VAR: &str = "ARENA_STANDIN_DIR";

/// The environment variable that, set to `1`, turns a missing image or QEMU into a failure (CI).
pub const REQUIRE_QEMU_VAR: &str = "ARENA_REQUIRE_QEMU";

/// The emulator the QEMU tests run, looked up on `PATH`.
const QEMU: &str = "qemu-system-x86_64";

/// The stand-in image's files, and the emulator to boot them with.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StandinImage {
    /// The BIOS-bootable disk: boot an overlay on it, never the file itself.
    pub golden: PathBuf,
    /// The installer CD (`arena.mode=install`): writes the disk onto the first virtio disk.
    pub installer: PathBuf,
    /// `standin.json`: kernel, guest binary sha256, guest port, screen size, files.
    pub manifest: PathBuf,
    /// `qemu-system-x86_64`, as found on `PATH`.
    pub qemu: PathBuf,
}

/// Where the image is by default: `target/standin` of the workspace.
fn default_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../target/standin")
}

/// The stand-in image for `test`: from `ARENA_STANDIN_DIR` when set, else
/// `target/standin` of the workspace, with `qemu-system-x86_64` found on `PATH`.
///
/// When the image or QEMU is missing, the skip is said on the process's standard error
/// directly (libtest does not capture it), as `SKIPPED: <test>: QEMU stand-in image not
/// found (...)`, so `test.sh` can count it; the test should then return.
///
/// # Panics
///
/// When `ARENA_STANDIN_DIR` names something that is not a folder (a typo must not turn
/// into a quiet skip), and when the image or QEMU is missing while `ARENA_REQUIRE_QEMU=1`.
pub fn standin_image(test: &str) -> Option<StandinImage> {
    let required = std::env::var(REQUIRE_QEMU_VAR).is_ok_and(|v| v == "1");
    let qemu = arena_shared::search_path::find_program(Path::new(QEMU));
    locate(
        test,
        std::env::var_os(STANDIN_DIR_VAR).map(PathBuf::from),
        default_dir(),
        qemu,
        required,
        &mut std::io::stderr(),
    )
}

/// [`standin_image`] with its inputs given, for testing it.
fn locate(
    test: &str,
    from_env: Option<PathBuf>,
    default: PathBuf,
    qemu: Option<PathBuf>,
    required: bool,
    out: &mut dyn std::io::Write,
) -> Option<StandinImage> {
    if let Some(dir) = &from_env {
        assert!(
            dir.is_dir(),
            "{STANDIN_DIR_VAR}={} is not a folder (it should hold golden.qcow2, installer.iso and standin.json)",
            dir.display()
        );
    }
    let dir = from_env.unwrap_or(default);
    let image = StandinImage {
        golden: dir.join("golden.qcow2"),
        installer: dir.join("installer.iso"),
        manifest: dir.join("standin.json"),
        qemu: qemu.clone().unwrap_or_else(|| PathBuf::from(QEMU)),
    };
    let absent = [&image.golden, &image.installer, &image.manifest].into_iter().find(|f| !f.is_file()).cloned();
    let why = match (absent, qemu) {
        (Some(absent), _) => {
            format!("{} is missing (run scripts/build-standin-image.sh, or set {STANDIN_DIR_VAR})", absent.display())
        }
        (None, None) => format!("{QEMU} is not on PATH (apt-get install qemu-system-x86)"),
        (None, Some(_)) => return Some(image),
    };
    assert!(!required, "{REQUIRE_QEMU_VAR}=1 but {test} cannot run: {why}");
    // One write of the whole line, so output from other test threads cannot split it.
    let line = format!("{SKIP_PREFIX}{test}: QEMU stand-in image not found: {why}\n");
    let _ = out.write_all(line.as_bytes());
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A folder holding the three files of a built image.
    fn built() -> tempfile::TempDir {
        let dir = tempfile::tempdir().expect("dir");
        for name in ["golden.qcow2", "installer.iso", "standin.json"] {
            std::fs::write(dir.path().join(name), b"").expect("write");
        }
        dir
    }

    fn run(
        from_env: Option<PathBuf>,
        default: PathBuf,
        qemu: Option<PathBuf>,
        required: bool,
    ) -> (Option<StandinImage>, String) {
        let mut out = Vec::new();
        let found = locate("some_test", from_env, default, qemu, required, &mut out);
        (found, String::from_utf8(out).expect("utf-8"))
    }

    #[test]
    fn the_variable_wins_then_the_default() {
        let a = built();
        let b = built();
        let qemu = Some(PathBuf::from("/q/qemu-system-x86_64"));
        let (found, said) = run(Some(a.path().into()), b.path().into(), qemu.clone(), true);
        assert_eq!(found.expect("found").golden, a.path().join("golden.qcow2"));
        assert_eq!(said, "");
        let (found, said) = run(None, b.path().into(), qemu.clone(), true);
        let found = found.expect("found");
        assert_eq!(found.installer, b.path().join("installer.iso"));
        assert_eq!(found.manifest, b.path().join("standin.json"));
        assert_eq!(found.qemu, PathBuf::from("/q/qemu-system-x86_64"));
        assert_eq!(said, "");
    }

    #[test]
    fn a_missing_image_or_qemu_is_a_loud_skip() {
        let empty = tempfile::tempdir().expect("dir");
        let (found, said) = run(None, empty.path().join("missing"), Some("/q/qemu".into()), false);
        assert_eq!(found, None);
        assert!(said.starts_with("SKIPPED: some_test: QEMU stand-in image not found: "), "{said}");
        assert!(said.contains("golden.qcow2 is missing"), "{said}");
        assert!(said.ends_with('\n') && said.lines().count() == 1, "{said}");

        let image = built();
        let (found, said) = run(None, image.path().into(), None, false);
        assert_eq!(found, None);
        assert!(said.contains("qemu-system-x86_64 is not on PATH"), "{said}");
    }

    #[test]
    fn a_required_image_that_is_missing_fails() {
        let image = built();
        let result = std::panic::catch_unwind(|| run(None, image.path().into(), None, true));
        let message = *result.expect_err("fails").downcast::<String>().expect("message");
        assert!(message.contains("ARENA_REQUIRE_QEMU=1"), "{message}");
    }

    #[test]
    fn a_variable_that_names_no_folder_fails_rather_than_skips() {
        let dir = tempfile::tempdir().expect("dir");
        let typo = dir.path().join("wrong");
        let result = std::panic::catch_unwind(|| run(Some(typo), dir.path().into(), None, false));
        let message = *result.expect_err("fails").downcast::<String>().expect("message");
        assert!(message.contains("is not a folder"), "{message}");
    }
}
