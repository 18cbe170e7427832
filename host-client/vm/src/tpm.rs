//! A TPM 2.0 for a VM: Debian's `swtpm`, one process per QEMU, its state in
//! the VM's folder beside the overlay.
//!
//! QEMU's `tpm-emulator` backend connects to swtpm's control socket (QEMU's
//! docs/specs/tpm.rst, "The QEMU TPM emulator device"); with `--terminate`
//! swtpm ends when QEMU closes it, and it also dies with this program. The
//! emulator's state is part of QEMU's migration stream, so `savevm` snapshots
//! in the overlay include the TPM, and `loadvm` puts it back with the rest.

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::Duration;

use super::VmError;

/// The Debian package that carries `swtpm`.
pub const SWTPM_PACKAGE: &str = "swtpm";

/// The TPM's state folder in a VM's folder.
pub const STATE_DIR: &str = "tpm";

/// swtpm's control socket in a VM's folder (QEMU's `-chardev socket,path=`).
pub const SOCKET: &str = "swtpm.sock";

/// Where one VM's swtpm keeps things.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SwtpmSpec {
    pub program: PathBuf,
    pub state: PathBuf,
    pub socket: PathBuf,
    pub log: PathBuf,
}

impl SwtpmSpec {
    /// The layout in VM folder `dir`.
    pub fn in_dir(program: PathBuf, dir: &Path) -> SwtpmSpec {
        SwtpmSpec { program, state: dir.join(STATE_DIR), socket: dir.join(SOCKET), log: dir.join("swtpm.log") }
    }

    /// The arguments after the program name.
    pub fn args(&self) -> Vec<OsString> {
        let mut dir = OsString::from("dir=");
        dir.push(&self.state);
        let mut ctrl = OsString::from("type=unixio,path=");
        ctrl.push(&self.socket);
        let mut log = OsString::from("file=");
        log.push(&self.log);
        log.push(",level=2");
        vec![
            "socket".into(),
            "--tpm2".into(),
            "--tpmstate".into(),
            dir,
            "--ctrl".into(),
            ctrl,
            "--log".into(),
            log,
            "--terminate".into(),
        ]
    }
}

/// `swtpm`: `explicit`, or on `PATH`.
///
/// # Errors
///
/// [`VmError::Missing`] naming the package.
pub fn find_swtpm(explicit: Option<&Path>) -> Result<PathBuf, VmError> {
    super::qemu::find_program(explicit, "swtpm", SWTPM_PACKAGE)
}

/// A running swtpm.
#[derive(Debug)]
pub struct Swtpm {
    pub spec: SwtpmSpec,
    child: tokio::process::Child,
}

impl Swtpm {
    /// Starts swtpm on `spec` (a new state when the folder is empty) and waits
    /// for its socket.
    ///
    /// # Errors
    ///
    /// swtpm cannot start or exits before its socket exists, with its log.
    pub async fn start(spec: &SwtpmSpec) -> Result<Swtpm, VmError> {
        std::fs::create_dir_all(&spec.state)
            .map_err(|source| VmError::Io { what: format!("creating {}", spec.state.display()), source })?;
        let _ = std::fs::remove_file(&spec.socket);
        let mut command = tokio::process::Command::new(&spec.program);
        command.args(spec.args()).stdin(Stdio::null()).stdout(Stdio::null()).stderr(Stdio::null()).kill_on_drop(true);
        crate::child::die_with_this_process(&mut command);
        let mut child = command
            .spawn()
            .map_err(|source| VmError::Io { what: format!("starting {}", spec.program.display()), source })?;
        for _ in 0..100 {
            if spec.socket.exists() {
                return Ok(Swtpm { spec: spec.clone(), child });
            }
            if let Ok(Some(status)) = child.try_wait() {
                return Err(VmError::Exited {
                    name: "swtpm".into(),
                    status: status.to_string(),
                    log: super::log_tail(&spec.log),
                });
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        let _ = child.kill().await;
        Err(VmError::Invalid(format!(
            "swtpm made no socket at {} within 5 s{}",
            spec.socket.display(),
            super::log_tail(&spec.log)
        )))
    }

    /// Ends swtpm (it ends by itself when QEMU closes its socket).
    pub async fn stop(&mut self) {
        if tokio::time::timeout(Duration::from_secs(2), self.child.wait()).await.is_err() {
            let _ = self.child.kill().await;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_command_line_keeps_state_and_socket_in_the_vm_folder() {
        let spec = SwtpmSpec::in_dir("swtpm".into(), Path::new("/v/vm-1"));
        let line: Vec<String> = spec.args().iter().map(|a| a.to_string_lossy().into_owned()).collect();
        assert_eq!(
            line,
            [
                "socket",
                "--tpm2",
                "--tpmstate",
                "dir=/v/vm-1/tpm",
                "--ctrl",
                "type=unixio,path=/v/vm-1/swtpm.sock",
                "--log",
                "file=/v/vm-1/swtpm.log,level=2",
                "--terminate"
            ]
        );
    }

    #[tokio::test]
    async fn swtpm_starts_and_makes_its_socket() {
        let Ok(program) = find_swtpm(None) else {
            arena_test_support::skip(
                "swtpm_starts_and_makes_its_socket",
                "swtpm not found (Debian's swtpm package)",
                "ARENA_REQUIRE_QEMU",
            );
            return;
        };
        let dir = tempfile::tempdir().unwrap();
        let mut tpm = Swtpm::start(&SwtpmSpec::in_dir(program, dir.path())).await.unwrap();
        assert!(dir.path().join(SOCKET).exists());
        tpm.stop().await;
        let err = find_swtpm(Some(Path::new("/nonexistent/swtpm"))).unwrap_err().to_string();
        assert!(err.contains("swtpm"), "{err}");
    }
}
