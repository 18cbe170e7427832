//! Disk images through `qemu-img`: what an image is (format, size, backing
//! file), the checks a golden image must pass, and copy-on-write overlays.
//!
//! A golden image is read-only on disk: every overlay depends on it, so one
//! stray write would silently change every VM built from it.

use std::path::{Path, PathBuf};
use std::process::Command;

use serde::Deserialize;

use super::VmError;

/// What `qemu-img info` says of one image.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
pub struct ImageInfo {
    pub format: String,
    #[serde(rename = "virtual-size")]
    pub virtual_size: u64,
    #[serde(rename = "backing-filename", default)]
    pub backing_filename: Option<String>,
    #[serde(rename = "full-backing-filename", default)]
    pub full_backing_filename: Option<String>,
    #[serde(rename = "backing-filename-format", default)]
    pub backing_format: Option<String>,
    #[serde(default)]
    pub snapshots: Vec<SnapshotInfo>,
}

/// An internal snapshot of a qcow2 image.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
pub struct SnapshotInfo {
    pub name: String,
    #[serde(rename = "vm-state-size", default)]
    pub vm_state_size: u64,
}

/// `qemu-img`, found once.
#[derive(Debug, Clone)]
pub struct QemuImg {
    pub program: PathBuf,
}

impl QemuImg {
    fn run(&self, args: &[&std::ffi::OsStr], what: &str) -> Result<Vec<u8>, VmError> {
        let mut command = Command::new(&self.program);
        command.args(args);
        // A prepare killed while qemu-img works (a snapshot, the sealing copy)
        // takes it along, so the disk's lock is not left held.
        crate::child::die_with_this_process_std(&mut command);
        let output = command
            .output()
            .map_err(|source| VmError::Io { what: format!("starting {}", self.program.display()), source })?;
        if !output.status.success() {
            return Err(VmError::Image {
                what: what.to_owned(),
                message: String::from_utf8_lossy(&output.stderr).trim().to_owned(),
            });
        }
        Ok(output.stdout)
    }

    /// `qemu-img info` of `path` (shared read: the image may be in use by a VM).
    ///
    /// # Errors
    ///
    /// The image does not exist or cannot be read.
    pub fn info(&self, path: &Path) -> Result<ImageInfo, VmError> {
        if !path.exists() {
            return Err(VmError::Image {
                what: format!("reading the image {}", path.display()),
                message: "no such file".into(),
            });
        }
        let out = self.run(
            &["info".as_ref(), "--output=json".as_ref(), "--force-share".as_ref(), path.as_os_str()],
            &format!("reading the image {}", path.display()),
        )?;
        serde_json::from_slice(&out).map_err(|err| VmError::Image {
            what: format!("reading the image {}", path.display()),
            message: format!("qemu-img info printed something unexpected: {err}"),
        })
    }

    /// Checks that `path` can serve as a golden image: it exists, it is a disk
    /// image QEMU reads, and it is read-only on disk.
    ///
    /// # Errors
    ///
    /// [`VmError::Golden`] saying what is wrong and how to fix it.
    pub fn check_golden(&self, path: &Path) -> Result<ImageInfo, VmError> {
        let golden = |message: String| VmError::Golden { path: path.to_owned(), message };
        let meta = std::fs::metadata(path).map_err(|err| golden(format!("cannot be read: {err}")))?;
        if !meta.is_file() {
            return Err(golden("is not a file".into()));
        }
        if !is_read_only(path, &meta) {
            return Err(golden(format!(
                "is writable; every VM's overlay depends on it unchanged, so make it read-only first (chmod a-w {})",
                path.display()
            )));
        }
        let info = self.info(path).map_err(|err| golden(err.to_string()))?;
        if let Some(backing) = &info.full_backing_filename {
            if !Path::new(backing).exists() {
                return Err(golden(format!("is itself an overlay of {backing}, which does not exist")));
            }
        }
        Ok(info)
    }

    /// Creates `overlay`, a qcow2 image backed by `golden` (by its absolute path),
    /// replacing an older overlay there.
    ///
    /// # Errors
    ///
    /// `qemu-img create` fails.
    pub fn create_overlay(&self, golden: &Path, golden_format: &str, overlay: &Path) -> Result<(), VmError> {
        let golden = std::fs::canonicalize(golden)
            .map_err(|source| VmError::Io { what: format!("resolving {}", golden.display()), source })?;
        if overlay.exists() {
            std::fs::remove_file(overlay).map_err(|source| VmError::Io {
                what: format!("removing the old overlay {}", overlay.display()),
                source,
            })?;
        }
        self.run(
            &[
                "create".as_ref(),
                "-q".as_ref(),
                "-f".as_ref(),
                "qcow2".as_ref(),
                "-F".as_ref(),
                golden_format.as_ref(),
                "-b".as_ref(),
                golden.as_os_str(),
                overlay.as_os_str(),
            ],
            &format!("creating the overlay {}", overlay.display()),
        )?;
        Ok(())
    }

    /// Checks that an existing overlay's backing file is still where it was.
    ///
    /// # Errors
    ///
    /// [`VmError::Overlay`] naming the missing backing file.
    pub fn check_overlay(&self, overlay: &Path) -> Result<ImageInfo, VmError> {
        let info = self.info(overlay)?;
        match (&info.backing_filename, &info.full_backing_filename) {
            (Some(_), Some(full)) if !Path::new(full).exists() => Err(VmError::Overlay {
                path: overlay.to_owned(),
                message: format!("its backing file {full} does not exist (was the golden image moved or renamed?); put it back or delete the overlay to build a new one"),
            }),
            (Some(name), None) => Err(VmError::Overlay {
                path: overlay.to_owned(),
                message: format!("its backing file {name} cannot be found"),
            }),
            _ => Ok(info),
        }
    }

    /// Creates an empty qcow2 disk of `size` (`64G`).
    ///
    /// # Errors
    ///
    /// `qemu-img create` fails.
    pub fn create_blank(&self, path: &Path, size: &str) -> Result<(), VmError> {
        self.run(
            &["create".as_ref(), "-q".as_ref(), "-f".as_ref(), "qcow2".as_ref(), path.as_os_str(), size.as_ref()],
            &format!("creating the disk {}", path.display()),
        )?;
        Ok(())
    }

    /// Deletes internal snapshot `name` of the qcow2 image `path` (which no QEMU may hold).
    ///
    /// # Errors
    ///
    /// `qemu-img` fails (no such snapshot, the image is in use).
    pub fn delete_snapshot(&self, path: &Path, name: &str) -> Result<(), VmError> {
        self.run(
            &["snapshot".as_ref(), "-d".as_ref(), name.as_ref(), path.as_os_str()],
            &format!("deleting snapshot {name} of {}", path.display()),
        )?;
        Ok(())
    }

    /// Copies `size` bytes from `offset` of the qcow2 disk `disk` into a new
    /// sparse raw file `to` (replacing it): one volume of the disk, read without
    /// mounting it. Shared read (`-U`), so a disk still locked is read too.
    ///
    /// # Errors
    ///
    /// `qemu-img convert` fails.
    pub fn extract_raw(&self, disk: &Path, offset: u64, size: u64, to: &Path) -> Result<(), VmError> {
        let _ = std::fs::remove_file(to);
        let source = format!(
            "driver=raw,offset={offset},size={size},file.driver=qcow2,file.file.filename={}",
            disk.display().to_string().replace(',', ",,")
        );
        self.run(
            &[
                "convert".as_ref(),
                "-U".as_ref(),
                "--image-opts".as_ref(),
                source.as_ref(),
                "-O".as_ref(),
                "raw".as_ref(),
                to.as_os_str(),
            ],
            &format!("copying {size} bytes at {offset} of {}", disk.display()),
        )?;
        Ok(())
    }

    /// Copies `from` (any format QEMU reads) into a new qcow2 image at `to`.
    ///
    /// # Errors
    ///
    /// `qemu-img convert` fails.
    pub fn convert_to_qcow2(&self, from: &Path, to: &Path) -> Result<(), VmError> {
        self.run(
            &["convert".as_ref(), "-O".as_ref(), "qcow2".as_ref(), from.as_os_str(), to.as_os_str()],
            &format!("converting {} to qcow2", from.display()),
        )?;
        Ok(())
    }
}

/// Whether `path` cannot be written: it has no write bits, or the system
/// refuses writing it (`access(W_OK)`: a read-only mount, as a Kubernetes
/// `readOnly` volume, whose file CSI driver may still show write bits).
pub fn is_read_only(path: &Path, meta: &std::fs::Metadata) -> bool {
    if meta.permissions().readonly() {
        return true;
    }
    // root may write a file without write bits, but not on a read-only mount: EROFS is what counts.
    crate::child::writable(path).is_some_and(|writable| !writable)
}

/// Removes the write bits of `path`.
///
/// # Errors
///
/// The permissions cannot be changed.
pub fn make_read_only(path: &Path) -> Result<(), VmError> {
    let mut perms = std::fs::metadata(path)
        .map_err(|source| VmError::Io { what: format!("reading {}", path.display()), source })?
        .permissions();
    perms.set_readonly(true);
    std::fs::set_permissions(path, perms)
        .map_err(|source| VmError::Io { what: format!("making {} read-only", path.display()), source })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn qemu_img() -> Option<QemuImg> {
        super::super::qemu::find_qemu_img(None).ok().map(|program| QemuImg { program })
    }

    #[test]
    fn info_is_parsed_from_qemu_img_json() {
        let text = r#"{"virtual-size": 1073741824, "filename": "o.qcow2", "format": "qcow2",
            "backing-filename": "g.qcow2", "full-backing-filename": "/x/g.qcow2",
            "backing-filename-format": "raw",
            "snapshots": [{"name": "ready", "vm-state-size": 123, "id": "1"}]}"#;
        let info: ImageInfo = serde_json::from_str(text).unwrap();
        assert_eq!(info.format, "qcow2");
        assert_eq!(info.backing_format.as_deref(), Some("raw"));
        assert_eq!(info.snapshots[0].name, "ready");
    }

    /// Golden images must be read-only, and an overlay whose golden image moved
    /// says so. Runs `qemu-img` (Debian's qemu-utils, on every machine of this kind).
    #[test]
    fn golden_and_overlay_checks_name_what_is_wrong() {
        let Some(img) = qemu_img() else {
            arena_test_support::skip(
                "golden_and_overlay_checks_name_what_is_wrong",
                "qemu-img not found",
                "ARENA_REQUIRE_QEMU",
            );
            return;
        };
        let dir = tempfile::tempdir().unwrap();
        let golden = dir.path().join("golden.qcow2");
        let missing = img.check_golden(&golden).unwrap_err().to_string();
        assert!(missing.contains("golden.qcow2") && missing.contains("cannot be read"), "{missing}");

        img.create_blank(&golden, "16M").unwrap();
        let writable = img.check_golden(&golden).unwrap_err().to_string();
        assert!(writable.contains("is writable") && writable.contains("chmod a-w"), "{writable}");
        make_read_only(&golden).unwrap();
        let info = img.check_golden(&golden).unwrap();
        assert_eq!((info.format.as_str(), info.virtual_size), ("qcow2", 16 << 20));

        let overlay = dir.path().join("vm/overlay.qcow2");
        std::fs::create_dir_all(overlay.parent().unwrap()).unwrap();
        img.create_overlay(&golden, &info.format, &overlay).unwrap();
        let o = img.check_overlay(&overlay).unwrap();
        assert_eq!(o.full_backing_filename.as_deref().map(Path::new), Some(golden.canonicalize().unwrap().as_path()));

        let moved = dir.path().join("moved.qcow2");
        std::fs::rename(&golden, &moved).unwrap();
        let err = img.check_overlay(&overlay).unwrap_err().to_string();
        assert!(err.contains("does not exist") && err.contains("golden.qcow2"), "{err}");
    }
}
