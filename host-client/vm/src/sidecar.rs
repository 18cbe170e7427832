//! What a golden image knows of itself: `<image>.arena.json`, written beside
//! the image when `arena vm prepare` seals it, read by every VM that boots on
//! it ([`crate::Vm::start`]: `arena vm start`, `arena run --vm-image`).
//!
//! It records the machine the image was installed on (firmware, screen,
//! machine type, disk bus, network card, TPM), what Windows it holds (edition,
//! build, language, time zone, install date, the evaluation's licence expiry
//! where known), the start-up apps its answer file turned off, and the
//! prepare's final UEFI variables file, copied beside the image. A VM whose machine differs from the recorded one is refused before
//! QEMU starts, with the flag that matches (a UEFI image booted on SeaBIOS
//! would otherwise wait out its boot deadline as "not healthy"); a licence with
//! under [`LICENCE_WARN_DAYS`] days left is warned about. An image without a
//! sidecar (dockur's, WAA's, or one sealed before this) is booted as asked.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::qemu::{DiskBus, NicModel};
use super::{VmConfig, VmError};

/// The sidecar's name beside `image`: `golden.qcow2` -> `golden.qcow2.arena.json`.
pub fn path_for(image: &Path) -> PathBuf {
    let mut name = image.file_name().map(|n| n.to_os_string()).unwrap_or_default();
    name.push(".arena.json");
    image.with_file_name(name)
}

/// The prepare's final UEFI variables beside `image`: `golden.qcow2.uefi-vars.qcow2`.
pub fn uefi_vars_for(image: &Path) -> PathBuf {
    let mut name = image.file_name().map(|n| n.to_os_string()).unwrap_or_default();
    name.push(".uefi-vars.qcow2");
    image.with_file_name(name)
}

/// The sidecar's format; a newer one is read for what this build knows.
pub const FORMAT: u32 = 1;

/// A licence with fewer days left than this is warned about.
pub const LICENCE_WARN_DAYS: i64 = 14;

/// How long Microsoft's Windows 11 Enterprise evaluation runs from its install
/// (the Evaluation Center's download page: 90 days).
pub const EVALUATION_DAYS: i64 = 90;

/// The sidecar.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ImageFacts {
    pub format: u32,
    /// `bios` or `uefi`.
    pub firmware: String,
    /// The UEFI code was a secure-boot build.
    #[serde(default)]
    pub secure_boot: bool,
    /// The screen the firmware and the display's EDID offered, `[width, height]`.
    pub screen: (u32, u32),
    /// QEMU's machine type (`q35`, `pc`).
    pub machine: String,
    pub disk_bus: DiskBus,
    pub nic: NicModel,
    pub tpm: bool,
    /// The edition: Windows' `EditionID` when the guest told it, else the image chosen.
    #[serde(default)]
    pub edition: Option<String>,
    /// Windows' build (`CurrentBuild.UBR`), when the guest told it.
    #[serde(default)]
    pub build: Option<String>,
    /// `--locale`: Setup's and the user's language.
    #[serde(default)]
    pub language: Option<String>,
    /// The Windows time zone the answer file set.
    #[serde(default)]
    pub timezone: Option<String>,
    /// When Windows was installed, seconds since the Unix epoch: Windows'
    /// `InstallDate` when the guest told it, else when the prepare began.
    pub installed_unix: i64,
    /// When the licence ends, when known (an evaluation edition:
    /// [`EVALUATION_DAYS`] after the install).
    #[serde(default)]
    pub licence_expires_unix: Option<i64>,
    /// The prepare's UEFI variables at the seal (Secure Boot keys and boot
    /// entries as Windows left them), beside the image.
    #[serde(default)]
    pub uefi_vars: Option<PathBuf>,
    /// The start-up apps the answer file turned off, so the first desktop settles
    /// (`unattend::startup_apps_off`); empty with an answer file of one's own.
    #[serde(default)]
    pub startup_apps_off: Vec<String>,
    /// OEM steps that failed and were let through by `--allow-failed-step`
    /// (`prep-apps.ps1 (exit code 3)`): the image lacks what they install.
    #[serde(default)]
    pub allowed_failed_steps: Vec<String>,
}

/// What the guest said of its Windows at the end of the prepare (all optional:
/// the stub guest has no `CurrentVersion` key).
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct GuestFacts {
    pub edition_id: Option<String>,
    pub build: Option<String>,
    pub install_date_unix: Option<i64>,
}

/// `HKLM\SOFTWARE\Microsoft\Windows NT\CurrentVersion`, where Windows keeps its
/// `EditionID`, `CurrentBuild`, `UBR` and `InstallDate` (seconds since 1970).
pub const CURRENT_VERSION_KEY: &str = r"HKLM\SOFTWARE\Microsoft\Windows NT\CurrentVersion";

/// The licence's end for `edition_id` installed at `installed_unix`: only an
/// evaluation edition's (`EnterpriseEval`, ...) is known here.
pub fn licence_expiry(edition_id: Option<&str>, installed_unix: i64) -> Option<i64> {
    edition_id.filter(|e| e.ends_with("Eval")).map(|_| installed_unix + EVALUATION_DAYS * 86_400)
}

/// `bios` or `uefi` for a config.
pub fn firmware_name(config: &VmConfig) -> &'static str {
    if config.uefi.is_some() {
        "uefi"
    } else {
        "bios"
    }
}

fn bus_name(bus: DiskBus) -> &'static str {
    match bus {
        DiskBus::Ahci => "ahci",
        DiskBus::VirtioBlk => "virtio-blk",
        DiskBus::VirtioScsi => "virtio-scsi",
    }
}

fn nic_name(nic: NicModel) -> &'static str {
    match nic {
        NicModel::E1000e => "e1000e",
        NicModel::VirtioNet => "virtio-net",
    }
}

/// Reads `image`'s sidecar; `None` when it has none.
///
/// # Errors
///
/// The sidecar exists but cannot be read or is not one.
pub fn read(image: &Path) -> Result<Option<ImageFacts>, VmError> {
    let path = path_for(image);
    match std::fs::read(&path) {
        Ok(bytes) => serde_json::from_slice(&bytes).map(Some).map_err(|err| {
            VmError::Invalid(format!(
                "{}: not an image sidecar of arena's ({err}); delete or fix it to boot {} as the flags say",
                path.display(),
                image.display()
            ))
        }),
        Err(err) if err.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(source) => Err(VmError::Io { what: format!("reading {}", path.display()), source }),
    }
}

/// Writes `facts` beside `image`, atomically.
///
/// # Errors
///
/// The file cannot be written.
pub fn write(image: &Path, facts: &ImageFacts) -> Result<(), VmError> {
    let path = path_for(image);
    let text = serde_json::to_string_pretty(facts).map_err(|err| VmError::Invalid(err.to_string()))?;
    arena_shared::atomic::write_atomic(&path, format!("{text}\n").as_bytes())
        .map_err(|err| VmError::Invalid(format!("writing {}: {err}", path.display())))
}

/// Checks a VM's machine against the image's: every difference, each with
/// the flag that matches the image, or the warnings to give (a licence near
/// its end, or past it) at `now_unix`.
///
/// # Errors
///
/// [`VmError::Invalid`] naming every difference and its flag.
pub fn check(facts: &ImageFacts, config: &VmConfig, image: &Path, now_unix: i64) -> Result<Vec<String>, VmError> {
    let mut wrong = Vec::new();
    let firmware = firmware_name(config);
    if facts.firmware != firmware {
        wrong.push(format!(
            "it was installed on {} firmware, this VM has {firmware}: use --vm-firmware {}",
            facts.firmware, facts.firmware
        ));
    }
    if facts.disk_bus != config.disk_bus {
        wrong.push(format!(
            "its system disk was on {}, this VM's is on {} (Windows stops at boot without that disk's driver): use --vm-disk-bus {}",
            bus_name(facts.disk_bus),
            bus_name(config.disk_bus),
            bus_name(facts.disk_bus)
        ));
    }
    if facts.nic != config.nic {
        wrong.push(format!(
            "its network card was {}, this VM's is {}: use --vm-nic {}",
            nic_name(facts.nic),
            nic_name(config.nic),
            nic_name(facts.nic)
        ));
    }
    if facts.machine != config.machine {
        wrong.push(format!(
            "its machine type was {}, this VM's is {}: use --vm-machine {}",
            facts.machine, config.machine, facts.machine
        ));
    }
    if facts.tpm != config.tpm {
        let flag = if facts.tpm { "on" } else { "off" };
        wrong.push(format!(
            "it was installed {} a TPM, this VM has {}: use --vm-tpm {flag}",
            if facts.tpm { "with" } else { "without" },
            if config.tpm { "one" } else { "none" }
        ));
    }
    if facts.screen != config.screen {
        wrong.push(format!(
            "its screen was {}x{}, this VM's is {}x{}: use --vm-screen {}x{}",
            facts.screen.0, facts.screen.1, config.screen.0, config.screen.1, facts.screen.0, facts.screen.1
        ));
    }
    if !wrong.is_empty() {
        return Err(VmError::Invalid(format!(
            "{} does not match this VM ({}): {}",
            image.display(),
            path_for(image).display(),
            wrong.join("; ")
        )));
    }
    let mut warnings = Vec::new();
    if let Some(expires) = facts.licence_expires_unix {
        let days = (expires - now_unix).div_euclid(86_400);
        let date = arena_shared::calendar::iso_seconds(expires);
        if expires <= now_unix {
            warnings.push(format!(
                "the Windows licence of {} ended on {date} UTC: an evaluation past its end shuts down every hour (prepare a new image)",
                image.display()
            ));
        } else if days < LICENCE_WARN_DAYS {
            warnings.push(format!(
                "the Windows licence of {} ends in {days} days, on {date} UTC (prepare a new image before then)",
                image.display()
            ));
        }
    }
    Ok(warnings)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn facts() -> ImageFacts {
        ImageFacts {
            format: FORMAT,
            firmware: "uefi".into(),
            secure_boot: true,
            screen: (1440, 900),
            machine: "q35".into(),
            disk_bus: DiskBus::Ahci,
            nic: NicModel::E1000e,
            tpm: true,
            edition: Some("EnterpriseEval".into()),
            build: Some("26100.1742".into()),
            language: Some("en-US".into()),
            timezone: Some("UTC".into()),
            installed_unix: 1_790_000_000,
            licence_expires_unix: licence_expiry(Some("EnterpriseEval"), 1_790_000_000),
            uefi_vars: Some("/g/golden.qcow2.uefi-vars.qcow2".into()),
            startup_apps_off: crate::unattend::startup_apps_off(),
            allowed_failed_steps: Vec::new(),
        }
    }

    fn uefi_config() -> VmConfig {
        let mut config = VmConfig::new("/g/golden.qcow2".as_ref(), "/v/vm-1".as_ref(), "vm-1");
        config.uefi = Some(crate::Uefi {
            code: "/usr/share/OVMF/OVMF_CODE_4M.secboot.fd".into(),
            vars_template: "/usr/share/OVMF/OVMF_VARS_4M.ms.fd".into(),
            secure_boot: true,
        });
        config.tpm = true;
        config
    }

    #[test]
    fn sidecars_sit_beside_the_image_and_read_back() {
        assert_eq!(path_for(Path::new("/g/golden.qcow2")), Path::new("/g/golden.qcow2.arena.json"));
        assert_eq!(uefi_vars_for(Path::new("golden.qcow2")), Path::new("golden.qcow2.uefi-vars.qcow2"));
        let dir = tempfile::tempdir().unwrap();
        let image = dir.path().join("golden.qcow2");
        assert_eq!(read(&image).unwrap(), None, "no sidecar: nothing to check");
        write(&image, &facts()).unwrap();
        assert_eq!(read(&image).unwrap(), Some(facts()));
        let text = std::fs::read_to_string(path_for(&image)).unwrap();
        assert!(text.contains("\"disk_bus\": \"ahci\"") && text.contains("\"nic\": \"e1000e\""), "{text}");
        std::fs::write(path_for(&image), "{\"format\": 1}").unwrap();
        let err = read(&image).unwrap_err().to_string();
        assert!(err.contains("golden.qcow2.arena.json: not an image sidecar"), "{err}");
    }

    #[test]
    fn a_matching_vm_passes_and_every_difference_names_its_flag() {
        let image = Path::new("/g/golden.qcow2");
        let now = 1_790_000_000 + 86_400;
        assert_eq!(check(&facts(), &uefi_config(), image, now).unwrap(), Vec::<String>::new());

        // The UEFI image run without --vm-firmware uefi: refused, naming the flag.
        let mut bios = uefi_config();
        bios.uefi = None;
        let err = check(&facts(), &bios, image, now).unwrap_err().to_string();
        assert!(err.contains("installed on uefi firmware, this VM has bios: use --vm-firmware uefi"), "{err}");
        assert!(err.contains("golden.qcow2.arena.json"), "{err}");

        let mut other = uefi_config();
        other.disk_bus = DiskBus::VirtioBlk;
        other.nic = NicModel::VirtioNet;
        other.machine = "pc".into();
        other.tpm = false;
        other.screen = (1920, 1080);
        let err = check(&facts(), &other, image, now).unwrap_err().to_string();
        for flag in ["--vm-disk-bus ahci", "--vm-nic e1000e", "--vm-machine q35", "--vm-tpm on", "--vm-screen 1440x900"]
        {
            assert!(err.contains(flag), "{flag} missing: {err}");
        }
        assert!(!err.contains("--vm-firmware"), "{err}");
    }

    #[test]
    fn an_evaluation_warns_under_fourteen_days_and_after_its_end() {
        let image = Path::new("/g/golden.qcow2");
        let f = facts();
        let expires = f.licence_expires_unix.unwrap();
        assert_eq!(expires, 1_790_000_000 + 90 * 86_400);
        let config = uefi_config();
        assert!(check(&f, &config, image, expires - 15 * 86_400).unwrap().is_empty());
        let near = check(&f, &config, image, expires - 13 * 86_400 - 60).unwrap();
        assert_eq!(near.len(), 1);
        assert!(near[0].contains("ends in 13 days"), "{near:?}");
        let past = check(&f, &config, image, expires + 1).unwrap();
        assert!(past[0].contains("ended on"), "{past:?}");
        // A retail or volume edition's end is not known here: no warning.
        assert_eq!(licence_expiry(Some("Professional"), 0), None);
        assert_eq!(licence_expiry(None, 0), None);
    }
}
