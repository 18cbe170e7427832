//! The QEMU command line of one VM, built from a [`VmSpec`] as plain data so
//! that every device choice is tested without starting QEMU; and where the
//! QEMU programs are found.

use std::ffi::OsString;
use std::net::IpAddr;
use std::path::{Path, PathBuf};

use super::VmError;

/// The Debian package that carries `qemu-system-x86_64`.
pub const QEMU_PACKAGE: &str = "qemu-system-x86";
/// The Debian package that carries `qemu-img`.
pub const QEMU_IMG_PACKAGE: &str = "qemu-utils";

/// How the system disk is attached. Windows needs drivers for the virtio
/// buses (dockur's images have them); AHCI works on any Windows install.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DiskBus {
    /// SATA on the q35 machine's AHCI controller (IDE on `pc`).
    Ahci,
    VirtioBlk,
    VirtioScsi,
}

/// The network card.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum NicModel {
    /// Intel 82574, which Windows drives without extra drivers.
    E1000e,
    VirtioNet,
}

/// How the guest's code runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Accel {
    Kvm,
    /// Software emulation: everything works, many times slower.
    Tcg,
}

/// The firmware the VM boots with.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Firmware {
    /// SeaBIOS, QEMU's default.
    Bios,
    /// OVMF: `code` is read-only, `vars` is this VM's own copy (qcow2, so that
    /// snapshots can include it). `secure_boot`: the code is a secure-boot build
    /// (Debian's `OVMF_CODE_4M.secboot.fd`), which needs SMM (`smm=on`) and its
    /// flash locked to SMM (`cfi.pflash01` `secure=on`), as OVMF's README says.
    Uefi { code: PathBuf, vars: PathBuf, secure_boot: bool },
}

/// What the VM's real-time clock holds at power-on (`-rtc base=`). Windows
/// reads the RTC as local time, so a guest whose zone is UTC needs the RTC in
/// UTC; `localtime` (the host's zone) is what dockur's images run with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum RtcBase {
    Utc,
    #[default]
    Localtime,
}

impl RtcBase {
    /// The RTC a guest whose Windows time zone is `zone` needs: UTC for
    /// Microsoft's `UTC` zone ("Coordinated Universal Time", also written
    /// `UTC+00`/`Etc/UTC`), the host's local time otherwise.
    pub fn for_zone(zone: &str) -> RtcBase {
        match zone.trim() {
            "UTC" | "Etc/UTC" | "Coordinated Universal Time" => RtcBase::Utc,
            _ => RtcBase::Localtime,
        }
    }

    fn arg(self) -> &'static str {
        match self {
            RtcBase::Utc => "base=utc",
            RtcBase::Localtime => "base=localtime",
        }
    }
}

/// The processor the guest sees.
///
/// - Software emulation: `Nehalem`, the oldest of QEMU's named models with
///   SSE4.2 and POPCNT (x86-64-v2), which Windows 11 24H2's boot loader requires
///   and QEMU's default `qemu64` lacks; every feature of it is one TCG
///   implements, and a named model stays the same across QEMU versions, so
///   snapshots load on the next QEMU too (`max` would change with it).
/// - KVM: the host's processor with the Hyper-V enlightenments Windows uses
///   when it finds a Hyper-V-compatible hypervisor (QEMU's docs/system/i386/hyperv.rst:
///   relaxed timing, virtual APIC, spinlock hints, synthetic timers and clock,
///   TLB flush and IPI hypercalls), so the guest neither crawls nor drifts after
///   `loadvm`; the virtualisation extensions, Intel's VMX and AMD's SVM, are
///   hidden unless `nested`, so Windows does not turn on virtualisation-based
///   security inside the VM (with `nested`, `host` shows the host's own).
pub fn cpu_model(accel: Accel, nested: bool) -> String {
    match accel {
        Accel::Tcg => TCG_CPU.to_owned(),
        Accel::Kvm => {
            let mut cpu = format!("host,{}", HYPERV_ENLIGHTENMENTS.join(","));
            if !nested {
                cpu.push_str(",vmx=off,svm=off");
            }
            cpu
        }
    }
}

/// The processor model under software emulation (see [`cpu_model`]).
pub const TCG_CPU: &str = "Nehalem";

/// The Hyper-V enlightenments given under KVM (see [`cpu_model`]).
pub const HYPERV_ENLIGHTENMENTS: &[&str] = &[
    "hv-relaxed",
    "hv-vapic",
    "hv-spinlocks=0x1fff",
    "hv-vpindex",
    "hv-runtime",
    "hv-time",
    "hv-synic",
    "hv-stimer",
    "hv-frequencies",
    "hv-reset",
    "hv-tlbflush",
    "hv-ipi",
];

/// A folder shown to the guest as a read-only FAT disk (QEMU's vvfat).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FolderDrive {
    pub folder: PathBuf,
    /// As removable USB media (where Windows Setup looks for `autounattend.xml`)
    /// instead of a disk on the system disk's bus.
    pub removable: bool,
}

/// Everything one QEMU process is started with.
#[derive(Debug, Clone)]
pub struct VmSpec {
    pub qemu: PathBuf,
    /// The VM's name (shown by QEMU, used in logs).
    pub name: String,
    /// The VM's writable disk: an overlay of the golden image.
    pub disk: PathBuf,
    pub disk_bus: DiskBus,
    pub nic: NicModel,
    pub machine: String,
    pub memory_mib: u32,
    pub cpus: u32,
    pub accel: Accel,
    /// Expose VMX to the guest under KVM (nested virtualisation).
    pub nested: bool,
    pub firmware: Firmware,
    /// A TPM 2.0 (`tpm-tis`) backed by the swtpm whose control socket this is.
    pub tpm_socket: Option<PathBuf>,
    /// Where the guest's port is forwarded from on this machine.
    pub host_addr: IpAddr,
    pub host_port: u16,
    /// The guest server's port inside the VM.
    pub guest_port: u16,
    pub qmp_socket: PathBuf,
    /// A second QMP monitor, for `arena vm snapshot|restore|screendump|stop`
    /// while the owner holds the first (a monitor serves one client at a time).
    pub control_socket: PathBuf,
    /// The guest's first serial port is written here.
    pub serial_log: PathBuf,
    /// VNC display number (5900 + n), on `host_addr`.
    pub vnc: Option<u16>,
    /// An installer ISO as a CD-ROM, booted when the disk does not boot.
    pub cdrom: Option<PathBuf>,
    /// More read-only CD-ROMs, never booted (the OEM media of a prepare).
    pub media: Vec<PathBuf>,
    pub folders: Vec<FolderDrive>,
    /// A snapshot to start from (`-loadvm`).
    pub loadvm: Option<String>,
    /// The screen, as the display's EDID offers it (its preferred mode).
    pub screen: (u32, u32),
    /// What the real-time clock starts at.
    pub rtc: RtcBase,
}

impl VmSpec {
    /// The arguments after the program name.
    pub fn args(&self) -> Vec<OsString> {
        let mut a = Args::default();
        a.push("-name").push(format!("{},process={}", self.name, self.name));
        let secure_boot = matches!(self.firmware, Firmware::Uefi { secure_boot: true, .. });
        a.push("-machine").push(format!(
            "{},accel={}{}",
            self.machine,
            match self.accel {
                Accel::Kvm => "kvm",
                Accel::Tcg => "tcg",
            },
            if secure_boot { ",smm=on" } else { "" }
        ));
        a.push("-cpu").push(cpu_model(self.accel, self.nested));
        a.push("-m").push(format!("{}M", self.memory_mib));
        a.push("-smp").push(self.cpus.to_string());
        a.push("-nodefaults");
        // QEMU's standard VGA, its EDID naming the screen as the preferred mode:
        // what Windows' display settings and the stand-in's kernel start with.
        a.push("-vga").push("none");
        a.push("-device").push(format!("VGA,edid=on,xres={},yres={}", self.screen.0, self.screen.1));
        a.push("-rtc").push(self.rtc.arg());
        if let Firmware::Uefi { code, vars, secure_boot } = &self.firmware {
            if *secure_boot {
                a.push("-global").push("driver=cfi.pflash01,property=secure,value=on");
            }
            a.push("-drive").push(drive_opts("if=pflash,format=raw,readonly=on", code));
            a.push("-drive").push(drive_opts("if=pflash,format=qcow2", vars));
        }

        // The system disk, first in the boot order.
        a.push("-drive")
            .push(drive_opts("if=none,id=disk0,format=qcow2,discard=unmap,detect-zeroes=unmap", &self.disk));
        let ahci_bus =
            |n: usize| if self.machine.starts_with("pc") { format!("ide.{}", n / 2) } else { format!("ide.{n}") };
        let mut ahci_ports = 0usize;
        match self.disk_bus {
            DiskBus::Ahci => {
                a.push("-device").push(format!("ide-hd,drive=disk0,bus={},bootindex=1", ahci_bus(ahci_ports)));
                ahci_ports += 1;
            }
            DiskBus::VirtioBlk => {
                a.push("-device").push("virtio-blk-pci,drive=disk0,bootindex=1");
            }
            DiskBus::VirtioScsi => {
                a.push("-device").push("virtio-scsi-pci,id=scsi0");
                a.push("-device").push("scsi-hd,drive=disk0,bus=scsi0.0,bootindex=1");
            }
        }
        if let Some(iso) = &self.cdrom {
            a.push("-drive").push(drive_opts("if=none,id=cd0,media=cdrom,readonly=on", iso));
            // On the last port, away from the disks.
            let bus = if self.machine.starts_with("pc") { "ide.1".to_owned() } else { "ide.5".to_owned() };
            a.push("-device").push(format!("ide-cd,drive=cd0,bus={bus},bootindex=2"));
        }
        for (i, iso) in self.media.iter().enumerate() {
            let id = format!("media{i}");
            a.push("-drive").push(drive_opts(&format!("if=none,id={id},media=cdrom,readonly=on"), iso));
            // The ports below the installer's (q35), or the second IDE bus's free unit (pc).
            let bus = if self.machine.starts_with("pc") { "ide.1".to_owned() } else { format!("ide.{}", 4 - i.min(3)) };
            a.push("-device").push(format!("ide-cd,drive={id},bus={bus}"));
        }
        let mut usb = false;
        for (i, drive) in self.folders.iter().enumerate() {
            let id = format!("folder{i}");
            a.push("-drive")
                .push(format!("if=none,id={id},format=raw,readonly=on,file=fat:ro:{}", escape(&drive.folder)));
            if drive.removable {
                if !usb {
                    a.push("-device").push("qemu-xhci,id=xhci");
                    usb = true;
                }
                a.push("-device").push(format!("usb-storage,drive={id},removable=on"));
                continue;
            }
            match self.disk_bus {
                DiskBus::Ahci => {
                    a.push("-device").push(format!("ide-hd,drive={id},bus={}", ahci_bus(ahci_ports)));
                    ahci_ports += 1;
                }
                DiskBus::VirtioBlk => {
                    a.push("-device").push(format!("virtio-blk-pci,drive={id}"));
                }
                DiskBus::VirtioScsi => {
                    a.push("-device").push(format!("scsi-hd,drive={id},bus=scsi0.0"));
                }
            }
        }

        if let Some(socket) = &self.tpm_socket {
            a.push("-chardev").push(format!("socket,id=chrtpm,path={}", escape(socket)));
            a.push("-tpmdev").push("emulator,id=tpm0,chardev=chrtpm");
            a.push("-device").push("tpm-tis,tpmdev=tpm0");
        }

        // User-mode networking: the guest reaches out, the host reaches the
        // guest server through one forwarded port.
        a.push("-netdev")
            .push(format!("user,id=net0,hostfwd=tcp:{}:{}-:{}", self.host_addr, self.host_port, self.guest_port));
        a.push("-device").push(match self.nic {
            NicModel::E1000e => "e1000e,netdev=net0",
            NicModel::VirtioNet => "virtio-net-pci,netdev=net0",
        });

        a.push("-qmp").push(format!("unix:{},server=on,wait=off", escape(&self.qmp_socket)));
        a.push("-qmp").push(format!("unix:{},server=on,wait=off", escape(&self.control_socket)));
        a.push("-serial").push(format!("file:{}", escape(&self.serial_log)));
        match self.vnc {
            Some(display) => a.push("-display").push(format!("vnc={}:{display}", self.host_addr)),
            None => a.push("-display").push("none"),
        };
        if let Some(name) = &self.loadvm {
            a.push("-loadvm").push(name.clone());
        }
        a.0
    }
}

#[derive(Default)]
struct Args(Vec<OsString>);

impl Args {
    fn push(&mut self, arg: impl Into<OsString>) -> &mut Args {
        self.0.push(arg.into());
        self
    }
}

/// A QEMU option value holding a path: commas are doubled, as QEMU's option parser wants.
fn escape(path: &Path) -> String {
    path.display().to_string().replace(',', ",,")
}

fn drive_opts(opts: &str, file: &Path) -> String {
    format!("{opts},file={}", escape(file))
}

/// The QEMU system emulator: `explicit`, or `qemu-system-x86_64` on `PATH`.
///
/// # Errors
///
/// [`VmError::Missing`] naming the package to install.
pub fn find_qemu(explicit: Option<&Path>) -> Result<PathBuf, VmError> {
    find_program(explicit, "qemu-system-x86_64", QEMU_PACKAGE)
}

/// `qemu-img`: `explicit`, or on `PATH`.
///
/// # Errors
///
/// [`VmError::Missing`] naming the package to install.
pub fn find_qemu_img(explicit: Option<&Path>) -> Result<PathBuf, VmError> {
    find_program(explicit, "qemu-img", QEMU_IMG_PACKAGE)
}

pub(crate) fn find_program(explicit: Option<&Path>, name: &str, package: &str) -> Result<PathBuf, VmError> {
    match explicit {
        // A bare name is looked up on PATH; a path is checked as given.
        Some(path) if arena_shared::search_path::find_program(path).is_some() => Ok(path.to_owned()),
        Some(path) => Err(VmError::Missing {
            program: path.display().to_string(),
            hint: format!("it is not an executable file; install Debian's {package} package or give the right path"),
        }),
        None => arena_shared::search_path::find_program(Path::new(name)).ok_or_else(|| VmError::Missing {
            program: name.to_owned(),
            hint: format!(
                "it is not on PATH; install it with `apt-get install {package}` (Debian's {package} package)"
            ),
        }),
    }
}

/// KVM when `/dev/kvm` opens for reading and writing, otherwise software
/// emulation, with the reason.
pub fn detect_accel() -> (Accel, String) {
    match std::fs::OpenOptions::new().read(true).write(true).open("/dev/kvm") {
        Ok(_) => (Accel::Kvm, "KVM (/dev/kvm)".to_owned()),
        Err(err) => (Accel::Tcg, format!("software emulation (TCG): /dev/kvm cannot be used: {err}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec() -> VmSpec {
        VmSpec {
            qemu: "qemu-system-x86_64".into(),
            name: "vm-1".into(),
            disk: "/v/vm-1/disk,1.qcow2".into(),
            disk_bus: DiskBus::Ahci,
            nic: NicModel::E1000e,
            machine: "q35".into(),
            memory_mib: 4096,
            cpus: 2,
            accel: Accel::Kvm,
            nested: false,
            firmware: Firmware::Bios,
            tpm_socket: None,
            host_addr: "127.0.0.1".parse().unwrap(),
            host_port: 5123,
            guest_port: 5000,
            qmp_socket: "/v/vm-1/qmp.sock".into(),
            control_socket: "/v/vm-1/control.sock".into(),
            serial_log: "/v/vm-1/serial.log".into(),
            vnc: None,
            cdrom: None,
            media: Vec::new(),
            folders: Vec::new(),
            loadvm: None,
            screen: (1440, 900),
            rtc: RtcBase::Localtime,
        }
    }

    fn line(spec: &VmSpec) -> String {
        spec.args().iter().map(|a| a.to_string_lossy().into_owned()).collect::<Vec<_>>().join(" ")
    }

    #[test]
    fn a_plain_vm_forwards_one_port_and_has_no_display() {
        let text = line(&spec());
        assert!(text.contains("-machine q35,accel=kvm -cpu host,hv-relaxed,"), "{text}");
        assert!(text.contains(",hv-ipi,vmx=off,svm=off -m 4096M -smp 2"), "{text}");
        assert!(!text.contains("smm=on") && !text.contains("tpm"), "{text}");
        // Commas in paths are doubled for QEMU's option parser.
        assert!(
            text.contains(
                "-drive if=none,id=disk0,format=qcow2,discard=unmap,detect-zeroes=unmap,file=/v/vm-1/disk,,1.qcow2"
            ),
            "{text}"
        );
        assert!(text.contains("-device ide-hd,drive=disk0,bus=ide.0,bootindex=1"), "{text}");
        assert!(
            text.contains("-netdev user,id=net0,hostfwd=tcp:127.0.0.1:5123-:5000 -device e1000e,netdev=net0"),
            "{text}"
        );
        assert!(
            text.contains(
                "-qmp unix:/v/vm-1/qmp.sock,server=on,wait=off -qmp unix:/v/vm-1/control.sock,server=on,wait=off"
            ),
            "{text}"
        );
        assert!(text.contains("-display none"), "{text}");
        assert!(text.contains("-vga none -device VGA,edid=on,xres=1440,yres=900"), "{text}");
        assert!(!text.contains("-loadvm"), "{text}");
    }

    #[test]
    fn the_rtc_is_utc_for_a_utc_guest_and_local_time_otherwise() {
        let mut s = spec();
        assert!(line(&s).contains(" -rtc base=localtime "), "{}", line(&s));
        s.rtc = RtcBase::for_zone("UTC");
        assert!(line(&s).contains(" -rtc base=utc "), "{}", line(&s));
        assert!(!line(&s).contains("localtime"), "{}", line(&s));
        assert_eq!(RtcBase::for_zone(" Etc/UTC "), RtcBase::Utc);
        for zone in ["Pacific Standard Time", "W. Europe Standard Time", "UTC-11", "GMT Standard Time", ""] {
            assert_eq!(RtcBase::for_zone(zone), RtcBase::Localtime, "{zone}");
        }
    }

    #[test]
    fn software_emulation_uses_no_host_cpu() {
        let mut s = spec();
        s.accel = Accel::Tcg;
        let text = line(&s);
        assert!(text.contains("accel=tcg -cpu Nehalem -m"), "{text}");
        assert!(!text.contains("-cpu host"), "{text}");
        // Nested virtualisation is asked for explicitly, and only means something under KVM.
        s.accel = Accel::Kvm;
        s.nested = true;
        assert!(line(&s).contains(",hv-ipi -m") && !line(&s).contains("vmx"), "{}", line(&s));
    }

    #[test]
    fn secure_boot_needs_smm_locked_flash_and_a_tpm_device_on_the_swtpm_socket() {
        let mut s = spec();
        s.firmware = Firmware::Uefi {
            code: "/usr/share/OVMF/OVMF_CODE_4M.secboot.fd".into(),
            vars: "/v/vm-1/uefi-vars.qcow2".into(),
            secure_boot: true,
        };
        s.tpm_socket = Some("/v/vm-1/swtpm.sock".into());
        let text = line(&s);
        assert!(text.contains("-machine q35,accel=kvm,smm=on "), "{text}");
        assert!(
            text.contains("-global driver=cfi.pflash01,property=secure,value=on -drive if=pflash,format=raw,readonly=on,file=/usr/share/OVMF/OVMF_CODE_4M.secboot.fd"),
            "{text}"
        );
        assert!(
            text.contains("-chardev socket,id=chrtpm,path=/v/vm-1/swtpm.sock -tpmdev emulator,id=tpm0,chardev=chrtpm -device tpm-tis,tpmdev=tpm0"),
            "{text}"
        );
    }

    #[test]
    fn buses_cdrom_folders_vnc_and_snapshot() {
        let mut s = spec();
        s.disk_bus = DiskBus::VirtioScsi;
        s.nic = NicModel::VirtioNet;
        s.cdrom = Some("/isos/Win11.iso".into());
        s.folders = vec![
            FolderDrive { folder: "/stage/oem".into(), removable: false },
            FolderDrive { folder: "/v/answer".into(), removable: true },
        ];
        s.vnc = Some(3);
        s.loadvm = Some("ready".into());
        let text = line(&s);
        assert!(
            text.contains("-device virtio-scsi-pci,id=scsi0 -device scsi-hd,drive=disk0,bus=scsi0.0,bootindex=1"),
            "{text}"
        );
        assert!(text.contains("-device ide-cd,drive=cd0,bus=ide.5,bootindex=2"), "{text}");
        assert!(text.contains("file=fat:ro:/stage/oem -device scsi-hd,drive=folder0,bus=scsi0.0"), "{text}");
        assert!(text.contains("-device qemu-xhci,id=xhci -device usb-storage,drive=folder1,removable=on"), "{text}");
        assert!(text.contains("virtio-net-pci,netdev=net0"), "{text}");
        assert!(text.contains("-display vnc=127.0.0.1:3"), "{text}");
        assert!(text.ends_with("-loadvm ready"), "{text}");
    }

    #[test]
    fn the_pc_machine_puts_two_drives_on_each_ide_bus() {
        let mut s = spec();
        s.machine = "pc".into();
        s.folders = vec![FolderDrive { folder: "/oem".into(), removable: false }];
        s.cdrom = Some("/x.iso".into());
        let text = line(&s);
        assert!(text.contains("ide-hd,drive=disk0,bus=ide.0"), "{text}");
        assert!(text.contains("ide-hd,drive=folder0,bus=ide.0"), "{text}");
        assert!(text.contains("ide-cd,drive=cd0,bus=ide.1"), "{text}");
    }

    #[test]
    fn uefi_vars_are_qcow2_so_snapshots_include_them() {
        let mut s = spec();
        s.firmware =
            Firmware::Uefi { code: "/fw/OVMF_CODE.fd".into(), vars: "/v/vm-1/vars.qcow2".into(), secure_boot: false };
        let text = line(&s);
        assert!(text.contains("-drive if=pflash,format=raw,readonly=on,file=/fw/OVMF_CODE.fd"), "{text}");
        assert!(text.contains("-drive if=pflash,format=qcow2,file=/v/vm-1/vars.qcow2"), "{text}");
    }

    #[test]
    fn a_missing_program_names_the_package() {
        let err = find_program(None, "surely-not-a-program-here", QEMU_PACKAGE).unwrap_err().to_string();
        assert!(err.contains("apt-get install qemu-system-x86"), "{err}");
        let err = find_qemu(Some(Path::new("/nonexistent/qemu"))).unwrap_err().to_string();
        assert!(err.contains("/nonexistent/qemu") && err.contains("qemu-system-x86"), "{err}");
    }
}
