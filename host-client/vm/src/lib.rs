//! Windows VMs this program runs itself with QEMU (`arena-vm`).
//!
//! Each VM runs on a copy-on-write overlay (qcow2 with a backing file) of a
//! read-only golden image, with a QMP control socket, user-mode networking that
//! forwards one host port to the guest server's port, and an optional VNC
//! display. [`Vm`] is one such QEMU process; [`fleet`] keeps several for a run
//! and restores each one's `ready` snapshot before every task; [`prepare`] makes
//! a golden image from an installer ISO.
//!
//! - [`qemu`]: the command line, as data; where QEMU is; KVM or software emulation.
//! - [`disk`]: `qemu-img`: image facts, golden-image checks, overlays.
//! - [`qmp`]: the control socket (commands, monitor lines, events).
//! - [`child`]: a child dies with us: the host side's only system calls (QEMU's
//!   helpers and an exec agent's process tree end with this program).
//! - [`oem`]: staging a Windows image's OEM folder and waiting for its guest.
//! - [`sidecar`]: what a golden image knows of itself, checked before a VM boots on it.
//!
//! It is not the guest: the server inside the VM is `arena-guest`, reached over
//! HTTP like any other guest.

#![deny(unsafe_code)]

pub mod bundle;
pub mod child;
pub mod disk;
pub mod fleet;
pub mod iso;
pub mod oem;
pub mod ovmf;
pub mod prepare;
pub mod qemu;
pub mod qmp;
pub mod sidecar;
pub mod tpm;
pub mod unattend;
pub mod verify;

use std::net::{IpAddr, Ipv4Addr, SocketAddr, TcpListener};
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::Duration;

use arena_shared::health::HealthReport;

use crate::oem::{PrepError, WaitEvent};
use arena_client::client::{ClientConfig, GuestClient};
use disk::{ImageInfo, QemuImg};
use qemu::{Accel, DiskBus, Firmware, FolderDrive, NicModel, VmSpec};
use qmp::Qmp;

/// The file that marks a folder as one of our VM folders. A folder without it
/// that holds anything is refused: starting a VM replaces the overlay, sockets
/// and logs in its folder, and those must never be someone else's files.
pub const DIR_MARKER: &str = ".arena-vm";

/// A VM's overlay of the golden image, in its folder.
pub const OVERLAY_FILE: &str = "overlay.qcow2";

/// The QMP socket other `arena vm` commands use, in a VM's folder.
pub const CONTROL_SOCKET: &str = "control.sock";

/// The name of the snapshot a run restores before each task.
pub const READY_SNAPSHOT: &str = "ready";

/// Everything that can go wrong with a VM, each naming what and why.
#[derive(Debug, thiserror::Error)]
pub enum VmError {
    #[error("{program} cannot be run: {hint}")]
    Missing { program: String, hint: String },
    #[error("golden image {path}: {message}")]
    Golden { path: PathBuf, message: String },
    #[error("overlay {path}: {message}")]
    Overlay { path: PathBuf, message: String },
    #[error("{what}: {message}")]
    Image { what: String, message: String },
    #[error("port {port} on {addr} is already in use (another VM or program holds it); choose another with --port or 0 for a free one")]
    PortTaken { addr: IpAddr, port: u16 },
    #[error("QMP {what}: {message}")]
    Qmp { what: String, message: String },
    #[error("snapshot {name:?} does not exist in {disk}{known}")]
    NoSnapshot { name: String, disk: PathBuf, known: String },
    #[error("VM {name}: QEMU exited ({status}){log}")]
    Exited { name: String, status: String, log: String },
    #[error("VM {name}: {source}")]
    NotHealthy { name: String, source: PrepError },
    #[error("{what}: {source}")]
    Io { what: String, source: std::io::Error },
    #[error("{0}")]
    Invalid(String),
}

/// What [`Vm::wait_settled`] waited for.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Settled {
    /// From a healthy guest to its settled shell.
    pub settled_after: Duration,
    /// In all, with the `--vm-settle` floor.
    pub waited: Duration,
    /// The `shell` component's detail, or `None` from a guest that reports none.
    pub shell: Option<String>,
}

/// How to run one VM.
#[derive(Debug, Clone)]
pub struct VmConfig {
    /// `qemu-system-x86_64` [default: on PATH].
    pub qemu: Option<PathBuf>,
    /// `qemu-img` [default: on PATH].
    pub qemu_img: Option<PathBuf>,
    /// The read-only golden image (qcow2, raw or any format QEMU reads).
    pub golden: PathBuf,
    /// This VM's folder: `overlay.qcow2`, `qmp.sock`, `serial.log`, `qemu.log`.
    pub dir: PathBuf,
    pub name: String,
    pub memory_mib: u32,
    pub cpus: u32,
    pub machine: String,
    pub disk_bus: DiskBus,
    pub nic: NicModel,
    /// `None`: OVMF is not used (SeaBIOS).
    pub uefi: Option<Uefi>,
    /// A TPM 2.0 from swtpm, its state in the VM's folder.
    pub tpm: bool,
    /// `swtpm` [default: on PATH].
    pub swtpm: Option<PathBuf>,
    /// Expose VMX under KVM (nested virtualisation; Windows may then turn on VBS).
    pub nested: bool,
    /// `None`: KVM when it works, else software emulation.
    pub accel: Option<Accel>,
    pub host_addr: IpAddr,
    /// 0 picks a free port.
    pub host_port: u16,
    pub guest_port: u16,
    pub vnc: Option<u16>,
    /// The guest's bearer token, when it has one.
    pub token: Option<String>,
    /// How long a boot (or a restore) may take to reach a healthy guest.
    pub boot_timeout: Duration,
    /// The screen the firmware starts with under UEFI (OVMF's `PlatformConfig`,
    /// [`ovmf`]): Windows' basic display driver keeps it.
    pub screen: (u32, u32),
    /// The real-time clock's base: UTC for a guest whose zone is UTC.
    pub rtc: qemu::RtcBase,
    /// `--vm-settle`: the least time between a healthy guest and the `ready`
    /// snapshot, whatever the guest's `shell` component says ([`Vm::wait_settled`]).
    pub settle_floor: Duration,
}

impl VmConfig {
    /// Defaults for a Windows 11 guest on `golden`, in folder `dir`.
    pub fn new(golden: &Path, dir: &Path, name: &str) -> VmConfig {
        VmConfig {
            qemu: None,
            qemu_img: None,
            golden: golden.to_owned(),
            dir: dir.to_owned(),
            name: name.to_owned(),
            memory_mib: 8192,
            cpus: 4,
            machine: "q35".into(),
            disk_bus: DiskBus::Ahci,
            nic: NicModel::E1000e,
            uefi: None,
            tpm: false,
            swtpm: None,
            nested: false,
            accel: None,
            host_addr: IpAddr::V4(Ipv4Addr::LOCALHOST),
            host_port: 0,
            guest_port: 5000,
            vnc: None,
            token: None,
            boot_timeout: Duration::from_secs(900),
            screen: (1440, 900),
            rtc: qemu::RtcBase::Localtime,
            settle_floor: Duration::ZERO,
        }
    }

    pub fn overlay(&self) -> PathBuf {
        self.dir.join(OVERLAY_FILE)
    }

    fn qemu_img(&self) -> Result<QemuImg, VmError> {
        Ok(QemuImg { program: qemu::find_qemu_img(self.qemu_img.as_deref())? })
    }

    /// The QEMU command line of this VM on `disk` (no CD-ROM, folders or
    /// snapshot: callers add those), with a free or checked host port, the
    /// accelerator (said in the log when it is software emulation) and, for UEFI,
    /// this VM's copy of the variables (made again when `fresh_vars`).
    ///
    /// # Errors
    ///
    /// The port is taken, or the UEFI variables cannot be copied.
    pub fn spec(
        &self,
        qemu: PathBuf,
        disk: PathBuf,
        img: &QemuImg,
        fresh_vars: bool,
    ) -> Result<(VmSpec, String), VmError> {
        let firmware = match &self.uefi {
            None => Firmware::Bios,
            Some(uefi) => {
                let vars = self.dir.join(UEFI_VARS_FILE);
                if !vars.exists() || fresh_vars {
                    self.make_uefi_vars(img, &uefi.vars_template, &vars)?;
                }
                Firmware::Uefi { code: uefi.code.clone(), vars, secure_boot: uefi.secure_boot }
            }
        };
        let tpm_socket = self.tpm.then(|| self.dir.join(tpm::SOCKET));
        let host_port = pick_port(self.host_addr, self.host_port)?;
        let (accel, accel_note) = match self.accel {
            Some(accel) => (accel, format!("{accel:?} (chosen)")),
            None => qemu::detect_accel(),
        };
        if accel == Accel::Tcg {
            tracing::warn!(vm = %self.name, "{accel_note}; expect boots and tasks to be many times slower");
        }
        let qmp_socket = self.dir.join("qmp.sock");
        let control_socket = self.dir.join(CONTROL_SOCKET);
        for stale in [&qmp_socket, &control_socket] {
            let _ = std::fs::remove_file(stale);
        }
        let spec = VmSpec {
            qemu,
            name: self.name.clone(),
            disk,
            disk_bus: self.disk_bus,
            nic: self.nic,
            machine: self.machine.clone(),
            memory_mib: self.memory_mib,
            cpus: self.cpus,
            accel,
            nested: self.nested,
            firmware,
            tpm_socket,
            host_addr: self.host_addr,
            host_port,
            guest_port: self.guest_port,
            qmp_socket,
            control_socket,
            serial_log: self.dir.join("serial.log"),
            vnc: self.vnc,
            cdrom: None,
            media: Vec::new(),
            folders: Vec::new(),
            loadvm: None,
            screen: self.screen,
            rtc: self.rtc,
        };
        Ok((spec, accel_note))
    }
}

impl VmConfig {
    /// This VM's UEFI variables: the template with OVMF's preferred resolution
    /// set to [`VmConfig::screen`], as qcow2. A template that is not an edk2
    /// variables file is used as it is (said in the log).
    fn make_uefi_vars(&self, img: &QemuImg, template: &Path, vars: &Path) -> Result<(), VmError> {
        let mut bytes = std::fs::read(template)
            .map_err(|source| VmError::Io { what: format!("reading {}", template.display()), source })?;
        let (width, height) = self.screen;
        if let Err(why) = ovmf::set_resolution(&mut bytes, width, height) {
            tracing::warn!(template = %template.display(), %why, "the UEFI screen cannot be set; OVMF chooses it");
            return img.convert_to_qcow2(template, vars);
        }
        let raw = self.dir.join("uefi-vars.raw.tmp");
        std::fs::write(&raw, &bytes)
            .map_err(|source| VmError::Io { what: format!("writing {}", raw.display()), source })?;
        let made = img.convert_to_qcow2(&raw, vars);
        let _ = std::fs::remove_file(&raw);
        made
    }
}

/// OVMF for a VM: the firmware code and the variables each VM copies.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Uefi {
    pub code: PathBuf,
    pub vars_template: PathBuf,
    /// The code is a secure-boot build (SMM on, flash locked to SMM).
    pub secure_boot: bool,
}

/// Debian's `ovmf` package: the secure-boot build (it needs SMM).
pub const OVMF_SECBOOT_CODE: &str = "/usr/share/OVMF/OVMF_CODE_4M.secboot.fd";
/// Debian's `ovmf` package: variables with Microsoft's keys enrolled, so Secure
/// Boot is on and Windows' boot loader, signed by Microsoft, is trusted.
pub const OVMF_MS_VARS: &str = "/usr/share/OVMF/OVMF_VARS_4M.ms.fd";

impl Uefi {
    /// Secure Boot as a Windows 11 PC has it, from Debian's `ovmf`.
    ///
    /// # Errors
    ///
    /// [`VmError::Missing`] when the files are not there.
    pub fn debian_secure_boot() -> Result<Uefi, VmError> {
        for file in [OVMF_SECBOOT_CODE, OVMF_MS_VARS] {
            if !Path::new(file).is_file() {
                return Err(VmError::Missing {
                    program: file.to_owned(),
                    hint: "install Debian's ovmf package (apt-get install ovmf), or give --vm-uefi-code and --vm-uefi-vars"
                        .into(),
                });
            }
        }
        Ok(Uefi { code: OVMF_SECBOOT_CODE.into(), vars_template: OVMF_MS_VARS.into(), secure_boot: true })
    }
}

/// The VM's own copy of the UEFI variables (qcow2, so `savevm` includes it).
pub const UEFI_VARS_FILE: &str = "uefi-vars.qcow2";

/// Makes `dir` a VM folder of ours: creates it with the marker, marks it when
/// it is empty, accepts it when marked.
///
/// # Errors
///
/// [`VmError::Invalid`] when it holds anything and has no marker (nothing in
/// it is touched), or it cannot be created.
pub fn claim_dir(dir: &Path) -> Result<(), VmError> {
    let marker = dir.join(DIR_MARKER);
    if marker.is_file() {
        return Ok(());
    }
    match std::fs::read_dir(dir) {
        Ok(mut entries) => {
            if entries.next().is_some() {
                return Err(VmError::Invalid(format!(
                    "{} is not empty and is not a VM folder of arena's (it has no {DIR_MARKER}); a VM replaces the overlay, sockets and logs in its folder, so give a new or empty folder (nothing in this one was changed)",
                    dir.display()
                )));
            }
        }
        Err(err) if err.kind() == std::io::ErrorKind::NotFound => {
            std::fs::create_dir_all(dir)
                .map_err(|source| VmError::Io { what: format!("creating {}", dir.display()), source })?;
        }
        Err(source) => return Err(VmError::Io { what: format!("reading {}", dir.display()), source }),
    }
    std::fs::write(&marker, b"a VM folder of arena (arena vm start, arena run --vm-dir, arena vm prepare)\n")
        .map_err(|source| VmError::Io { what: format!("writing {}", marker.display()), source })
}

/// One running QEMU process.
#[derive(Debug)]
pub struct Vm {
    pub config: VmConfig,
    pub spec: VmSpec,
    child: tokio::process::Child,
    pub qmp: Qmp,
    client: GuestClient,
    /// The VM's TPM, when it has one.
    tpm: Option<tpm::Swtpm>,
    /// How the VM runs (`KVM (/dev/kvm)` or why it is software emulation).
    pub accel_note: String,
}

/// How [`Vm::start`] treats the overlay.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Boot {
    /// A new overlay of the golden image, booted from cold.
    Fresh,
    /// The existing overlay, booted from cold.
    Existing,
    /// The existing overlay, resumed from one of its snapshots.
    FromSnapshot(String),
}

impl Vm {
    /// Starts QEMU for `config` (it does not wait for the guest: see [`Vm::wait_healthy`]).
    ///
    /// # Errors
    ///
    /// QEMU or `qemu-img` is missing, the golden image is writable or missing, the
    /// overlay's backing file moved, the port is taken, or QEMU exits at once.
    pub async fn start(config: &VmConfig, boot: Boot) -> Result<Vm, VmError> {
        linux_host()?;
        let qemu = qemu::find_qemu(config.qemu.as_deref())?;
        let img = config.qemu_img()?;
        let info = img.check_golden(&config.golden)?;
        // The image's own record of its machine, before anything is touched.
        let facts = sidecar::read(&config.golden)?;
        if let Some(facts) = &facts {
            let now = arena_shared::clock::now_unix_ms().div_euclid(1000);
            for warning in sidecar::check(facts, config, &config.golden, now)? {
                tracing::warn!(vm = %config.name, "{warning}");
            }
        }
        claim_dir(&config.dir)?;
        let overlay = config.overlay();
        let mut loadvm = None;
        match &boot {
            Boot::Fresh => {
                img.create_overlay(&config.golden, &info.format, &overlay)?;
                // A new machine gets a new TPM.
                let state = config.dir.join(tpm::STATE_DIR);
                if state.exists() {
                    std::fs::remove_dir_all(&state)
                        .map_err(|source| VmError::Io { what: format!("removing {}", state.display()), source })?;
                }
            }
            Boot::Existing | Boot::FromSnapshot(_) => {
                let o = img.check_overlay(&overlay)?;
                if let Boot::FromSnapshot(name) = &boot {
                    require_snapshot(&o, name, &overlay)?;
                    loadvm = Some(name.clone());
                }
            }
        }
        let (mut spec, accel_note) = config.spec(qemu, overlay, &img, boot == Boot::Fresh)?;
        spec.loadvm = loadvm;
        // The RTC as the image's time zone needs it (Windows reads it as local time).
        if let Some(zone) = facts.as_ref().and_then(|f| f.timezone.as_deref()) {
            spec.rtc = qemu::RtcBase::for_zone(zone);
        }
        Vm::launch(config, spec, accel_note).await
    }

    /// Starts QEMU with `spec` as it is (used by [`Vm::start`] and by [`prepare`]).
    ///
    /// # Errors
    ///
    /// QEMU cannot be started or exits before its control socket answers.
    pub async fn launch(config: &VmConfig, spec: VmSpec, accel_note: String) -> Result<Vm, VmError> {
        let log_path = config.dir.join("qemu.log");
        let log = std::fs::File::create(&log_path)
            .map_err(|source| VmError::Io { what: format!("creating {}", log_path.display()), source })?;
        let log_err = log
            .try_clone()
            .map_err(|source| VmError::Io { what: format!("opening {}", log_path.display()), source })?;
        let tpm = match &spec.tpm_socket {
            Some(_) => {
                let program = tpm::find_swtpm(config.swtpm.as_deref())?;
                Some(tpm::Swtpm::start(&tpm::SwtpmSpec::in_dir(program, &config.dir)).await?)
            }
            None => None,
        };
        tracing::info!(vm = %config.name, port = spec.host_port, accel = %accel_note, tpm = tpm.is_some(), "starting QEMU");
        let mut command = tokio::process::Command::new(&spec.qemu);
        command
            .args(spec.args())
            .stdin(Stdio::null())
            .stdout(Stdio::from(log))
            .stderr(Stdio::from(log_err))
            .kill_on_drop(true);
        child::die_with_this_process(&mut command);
        let mut child = command
            .spawn()
            .map_err(|source| VmError::Io { what: format!("starting {}", spec.qemu.display()), source })?;
        let qmp = tokio::select! {
            qmp = Qmp::connect(&spec.qmp_socket, qmp_deadline(&spec)) => qmp,
            status = child.wait() => {
                let mut status = status.map(|s| s.to_string()).unwrap_or_else(|e| e.to_string());
                if spec.accel == Accel::Kvm {
                    status.push_str("; it ran with KVM: if KVM is broken here (nested virtualisation), try --vm-accel tcg");
                }
                return Err(VmError::Exited { name: config.name.clone(), status, log: log_tail(&log_path) });
            }
        };
        let qmp = match qmp {
            Ok(qmp) => qmp,
            Err(err) => {
                let _ = child.kill().await;
                return Err(match child.try_wait() {
                    Ok(Some(status)) => VmError::Exited {
                        name: config.name.clone(),
                        status: status.to_string(),
                        log: log_tail(&log_path),
                    },
                    _ => err,
                });
            }
        };
        let url = format!("http://{}", SocketAddr::new(connect_addr(config.host_addr), spec.host_port));
        let client = GuestClient::new(
            &url,
            ClientConfig { token: config.token.clone(), timeout: Duration::from_secs(10), retries: 0 },
        )
        .and_then(|c| c.without_kept_connections())
        .map_err(|err| VmError::Invalid(err.to_string()))?;
        Ok(Vm { config: config.clone(), spec, child, qmp, client, tpm, accel_note })
    }

    /// The guest server's URL on this machine.
    pub fn url(&self) -> &str {
        self.client.base_url()
    }

    /// A client of the guest in this VM.
    pub fn client(&self) -> &GuestClient {
        &self.client
    }

    /// QEMU's process id.
    pub fn pid(&self) -> Option<u32> {
        self.child.id()
    }

    /// Whether QEMU has exited, and how.
    pub fn exited(&mut self) -> Option<String> {
        match self.child.try_wait() {
            Ok(Some(status)) => Some(status.to_string()),
            Ok(None) => None,
            Err(err) => Some(err.to_string()),
        }
    }

    /// Whether QEMU has ended for a reason outside the guest, and which: killed
    /// or crashed (an exit by a signal or with an error), or told to quit by the
    /// host. `None` while it runs, and when it ended because the guest powered off.
    pub fn ended_outside_guest(&mut self) -> Option<String> {
        let status = match self.child.try_wait() {
            Ok(Some(status)) => status,
            Ok(None) => return None,
            Err(err) => return Some(format!("QEMU's state is unknown: {err}")),
        };
        outside_guest(status, self.qmp.shutdown_reason().as_deref())
    }

    /// Waits until the guest reports every component up, or `within` passes, or
    /// QEMU exits.
    ///
    /// # Errors
    ///
    /// [`VmError::NotHealthy`] with what is still down, [`VmError::Exited`].
    pub async fn wait_healthy(
        &mut self,
        within: Duration,
        progress: impl FnMut(WaitEvent<'_>),
    ) -> Result<HealthReport, VmError> {
        self.wait_healthy_but(within, &[], progress).await
    }

    /// [`Vm::wait_healthy`] with the components in `ignore` left out (a prepare
    /// that let a failed OEM step through does not wait for `setup`).
    ///
    /// # Errors
    ///
    /// As [`Vm::wait_healthy`].
    pub async fn wait_healthy_but(
        &mut self,
        within: Duration,
        ignore: &[arena_shared::health::Component],
        progress: impl FnMut(WaitEvent<'_>),
    ) -> Result<HealthReport, VmError> {
        // QEMU's forwarder accepts connections before the guest listens, and such
        // a call waits for its whole deadline: keep each question short.
        let client = self.client.with_timeout(Duration::from_secs(2));
        let poll = Duration::from_millis(250);
        tokio::select! {
            report = crate::oem::wait_healthy_but(&client, within, poll, ignore, progress) => {
                report.map_err(|source| VmError::NotHealthy { name: self.config.name.clone(), source })
            }
            status = self.child.wait() => {
                let status = status.map(|s| s.to_string()).unwrap_or_else(|e| e.to_string());
                Err(VmError::Exited { name: self.config.name.clone(), status, log: log_tail(&self.config.dir.join("qemu.log")) })
            }
            state = stopped(&self.qmp) => {
                let hint = if self.spec.accel == Accel::Kvm {
                    "; under KVM this is often a nested-virtualisation problem: try --vm-accel tcg"
                } else {
                    ""
                };
                Err(VmError::Invalid(format!(
                    "VM {}: QEMU stopped the guest ({state}){hint}{}",
                    self.config.name,
                    log_tail(&self.config.dir.join("qemu.log"))
                )))
            }
        }
    }

    /// After [`Vm::wait_healthy`], before a snapshot tasks start from: waits
    /// until the guest says its desktop has settled (the `shell` health
    /// component: taskbar shown, the desktop in front, the CPU idle) and at
    /// least `floor` (`--vm-settle`) has passed, within `within`. A guest that
    /// reports no `shell` component (one older than it) gets the floor alone.
    ///
    /// # Errors
    ///
    /// [`VmError::Invalid`] naming what had not settled when `within` passed,
    /// or the guest stopped answering.
    pub async fn wait_settled(&self, floor: Duration, within: Duration) -> Result<Settled, VmError> {
        let started = std::time::Instant::now();
        let client = self.client.with_timeout(Duration::from_secs(5));
        let detail = loop {
            let last = match client.health().await {
                Ok(report) => match report.shell() {
                    None => break None,
                    Some(shell) if shell.ok => break Some(shell.detail.clone()),
                    Some(shell) => shell.detail.clone(),
                },
                Err(err) => format!("the guest did not answer: {err}"),
            };
            if started.elapsed() >= within {
                return Err(VmError::Invalid(format!(
                    "VM {}: the desktop did not settle within {} s of a healthy guest: {last} (the guest's `shell` health component; its --settle-idle-ms is how long the CPU must stay idle)",
                    self.config.name,
                    within.as_secs()
                )));
            }
            tokio::time::sleep(Duration::from_millis(500)).await;
        };
        let settled_after = started.elapsed();
        if settled_after < floor {
            tokio::time::sleep(floor - settled_after).await;
        }
        Ok(Settled { settled_after, waited: started.elapsed(), shell: detail })
    }

    /// Saves the running VM's memory and disk as snapshot `name` in its overlay
    /// (replacing one of that name). Returns how long it took.
    ///
    /// # Errors
    ///
    /// [`VmError::Qmp`] with QEMU's reason.
    pub async fn save_snapshot(&self, name: &str) -> Result<Duration, VmError> {
        self.qmp.save_snapshot(name).await
    }

    /// The snapshots in the VM's disk, by name.
    ///
    /// # Errors
    ///
    /// [`VmError::Qmp`].
    pub async fn snapshots(&self) -> Result<Vec<String>, VmError> {
        self.qmp.snapshots().await
    }

    /// Puts the VM back to snapshot `name` (memory and disk) and lets it run.
    /// Returns how long the restore took (not counting the guest's health).
    ///
    /// # Errors
    ///
    /// [`VmError::NoSnapshot`] naming the snapshots there are, or [`VmError::Qmp`].
    pub async fn restore_snapshot(&self, name: &str) -> Result<Duration, VmError> {
        self.qmp.restore_snapshot(name, &self.spec.disk).await
    }

    /// The VM's display as QEMU shows it (not the guest's own screenshot).
    ///
    /// # Errors
    ///
    /// [`VmError::Qmp`], or the PNG cannot be read.
    pub async fn screendump(&self) -> Result<ScreenDump, VmError> {
        let path = self.config.dir.join("screendump.png");
        let _ = std::fs::remove_file(&path);
        self.qmp.screendump(&path).await?;
        let bytes = std::fs::read(&path)
            .map_err(|source| VmError::Io { what: format!("reading {}", path.display()), source })?;
        ScreenDump::from_png(bytes)
    }

    /// Shuts the VM down: the ACPI power button, then QEMU's `quit` after
    /// `grace`, then a kill. Returns whether the guest shut down by itself.
    pub async fn shutdown(mut self, grace: Duration) -> bool {
        let _ = self.qmp.powerdown().await;
        if tokio::time::timeout(grace, self.child.wait()).await.is_ok() {
            return true;
        }
        tracing::warn!(vm = %self.config.name, "the guest did not shut down within {} s; stopping QEMU", grace.as_secs());
        self.kill().await;
        false
    }

    /// Stops QEMU at once (its overlay stays as it was).
    pub async fn kill(&mut self) {
        let _ = tokio::time::timeout(Duration::from_secs(2), self.qmp.quit()).await;
        if tokio::time::timeout(Duration::from_secs(5), self.child.wait()).await.is_err() {
            let _ = self.child.kill().await;
        }
        if let Some(tpm) = &mut self.tpm {
            tpm.stop().await;
        }
    }
}

/// How long QEMU may take to greet on QMP: a started machine at once, but one
/// started with `-loadvm` only once it has loaded the snapshot (all of a large
/// guest's memory, slow under emulation on a busy machine). Giving up kills
/// QEMU (SIGKILL): with 10 s for every greeting, a slow `-loadvm` ended so.
fn qmp_deadline(spec: &VmSpec) -> Duration {
    if spec.loadvm.is_some() {
        qmp::SNAPSHOT_TIMEOUT
    } else {
        Duration::from_secs(30)
    }
}

/// VMs run on a Linux host: QEMU's monitor and the TPM speak over Unix sockets,
/// and QEMU's processes end with this one through Linux's `PR_SET_PDEATHSIG`.
/// Elsewhere (a Windows host) starting one is refused with a clear error; runs
/// there use guests served from elsewhere (`--guest URL`) or the stub.
fn linux_host() -> Result<(), VmError> {
    if cfg!(unix) {
        return Ok(());
    }
    Err(VmError::Invalid(
        "VMs are driven from a Linux host (QEMU's monitor and TPM are Unix sockets): start them there and pass the guest's URL with --guest".to_owned(),
    ))
}

/// Returns once QEMU reports that the guest can no longer run (an emulation
/// failure, a panic), with QEMU's name for the state; never otherwise.
async fn stopped(qmp: &Qmp) -> String {
    loop {
        tokio::time::sleep(Duration::from_secs(2)).await;
        if let Ok((false, state)) = qmp.status().await {
            if is_dead_state(&state) {
                return state;
            }
        }
    }
}

/// QEMU run states a guest does not leave by itself.
fn is_dead_state(state: &str) -> bool {
    matches!(state, "internal-error" | "guest-panicked" | "io-error" | "shutdown")
}

/// The address a client on this machine uses for a forward bound to `addr`.
fn connect_addr(addr: IpAddr) -> IpAddr {
    if addr.is_unspecified() {
        IpAddr::V4(Ipv4Addr::LOCALHOST)
    } else {
        addr
    }
}

/// `port` when it is free on `addr`, or a free one for 0.
fn pick_port(addr: IpAddr, port: u16) -> Result<u16, VmError> {
    match TcpListener::bind(SocketAddr::new(addr, port)) {
        Ok(listener) => listener
            .local_addr()
            .map(|a| a.port())
            .map_err(|source| VmError::Io { what: "reading a free port".into(), source }),
        Err(err) if err.kind() == std::io::ErrorKind::AddrInUse => Err(VmError::PortTaken { addr, port }),
        Err(source) => Err(VmError::Io { what: format!("binding {addr}:{port}"), source }),
    }
}

pub(crate) fn check_snapshot_name(name: &str) -> Result<(), VmError> {
    if name.is_empty() || !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_' || c == '.') {
        return Err(VmError::Invalid(format!("snapshot name {name:?}: use letters, digits, '-', '_' and '.' only")));
    }
    Ok(())
}

fn require_snapshot(info: &ImageInfo, name: &str, disk: &Path) -> Result<(), VmError> {
    if info.snapshots.iter().any(|s| s.name == name) {
        return Ok(());
    }
    let known: Vec<String> = info.snapshots.iter().map(|s| s.name.clone()).collect();
    Err(VmError::NoSnapshot { name: name.to_owned(), disk: disk.to_owned(), known: known_list(&known) })
}

pub(crate) fn known_list(known: &[String]) -> String {
    if known.is_empty() {
        " (it has none)".to_owned()
    } else {
        format!(" (it has: {})", known.join(", "))
    }
}

/// The names in the monitor's `info snapshots` table.
pub(crate) fn parse_snapshot_list(text: &str) -> Vec<String> {
    // ID        TAG               VM SIZE                DATE     VM CLOCK     ICOUNT
    // --        ready              45.2 MiB 2026-11-26 01:02:03 00:00:12.345
    text.lines()
        .filter_map(|line| {
            let mut words = line.split_whitespace();
            // Data rows start with the snapshot's id, or `--` for one present on all disks.
            let id = words.next()?;
            if id != "--" && !id.chars().all(|c| c.is_ascii_digit()) {
                return None;
            }
            words.next().map(str::to_owned)
        })
        .collect()
}

/// The last lines QEMU wrote, for error messages.
pub fn log_tail(path: &Path) -> String {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let lines: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
    if lines.is_empty() {
        return String::new();
    }
    let start = lines.len().saturating_sub(5);
    format!(": {}", lines[start..].join(" | "))
}

/// Why a QEMU that ended with `status`, after a `SHUTDOWN` event of `reason`
/// if any, ended for a cause outside its guest: an exit by a signal or with an
/// error code (killed, crashed), or a clean exit the host asked for (QEMU's
/// `host-...` reasons). `None` for a clean exit the guest caused (it powered off).
fn outside_guest(status: std::process::ExitStatus, reason: Option<&str>) -> Option<String> {
    if !status.success() {
        return Some(format!("QEMU ended ({status})"));
    }
    match reason {
        Some(reason) if reason.starts_with("host") => Some(format!("QEMU quit at the host's request ({reason})")),
        _ => None,
    }
}

/// The VM's display as QEMU's `screendump` gives it.
#[derive(Debug, Clone)]
pub struct ScreenDump {
    pub width: u32,
    pub height: u32,
    /// The PNG QEMU wrote.
    pub png: Vec<u8>,
    /// Whether every pixel is (nearly) black.
    pub black: bool,
}

impl ScreenDump {
    /// Decodes QEMU's PNG.
    ///
    /// # Errors
    ///
    /// [`VmError::Invalid`] when it is not a PNG.
    pub fn from_png(png: Vec<u8>) -> Result<ScreenDump, VmError> {
        let decoded = ::image::load_from_memory_with_format(&png, ::image::ImageFormat::Png)
            .map_err(|err| VmError::Invalid(format!("QEMU's screendump is not a readable PNG: {err}")))?
            .to_rgb8();
        let black = decoded.pixels().all(|p| p.0.iter().all(|&c| c <= 16));
        Ok(ScreenDump { width: decoded.width(), height: decoded.height(), png, black })
    }
}

/// A folder the guest sees as a disk, for [`prepare`].
pub fn folder_drive(folder: &Path, removable: bool) -> FolderDrive {
    FolderDrive { folder: folder.to_owned(), removable }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// QEMU killed (signal 9), crashed (signal 11, exit 1) or quit by the host is
    /// the environment's; a guest that powered off (exit 0) is not.
    #[cfg(unix)]
    #[test]
    fn a_qemu_that_ended_outside_its_guest_is_told_from_a_guest_that_powered_off() {
        use std::os::unix::process::ExitStatusExt;
        let status = std::process::ExitStatus::from_raw;
        let killed = outside_guest(status(9), None).unwrap();
        assert!(killed.contains("signal: 9"), "{killed}");
        assert!(outside_guest(status(11), Some("guest-shutdown")).is_some());
        assert!(outside_guest(status(1 << 8), None).unwrap().contains("exit status: 1"));
        let quit = outside_guest(status(0), Some("host-signal")).unwrap();
        assert!(quit.contains("host-signal"), "{quit}");
        assert_eq!(outside_guest(status(0), Some("guest-shutdown")), None);
        assert_eq!(outside_guest(status(0), None), None);
    }

    #[test]
    fn the_monitor_snapshot_table_gives_names() {
        let text = "List of snapshots present on all disks:\r\nID        TAG               VM SIZE                DATE     VM CLOCK     ICOUNT\r\n--        ready              45.2 MiB 2026-11-26 01:02:03 00:00:12.345\r\n--        after-login        1 GiB 2026-11-26 01:05:03 00:03:12.345\r\n";
        assert_eq!(parse_snapshot_list(text), vec!["ready", "after-login"]);
        // As QEMU 7.2 prints it (trailing blanks), and a numbered row.
        let text = "List of snapshots present on all disks:\r\nID        TAG               VM SIZE                DATE     VM CLOCK     ICOUNT\r\n--        ready             128 MiB 2026-11-26 00:57:44 00:00:06.391           \r\n1         other  1 MiB 2026-11-26 00:57:44 00:00:06.391\r\n";
        assert_eq!(parse_snapshot_list(text), vec!["ready", "other"]);
        assert!(parse_snapshot_list("There is no snapshot available.\r\n").is_empty());
    }

    #[test]
    fn only_states_a_guest_cannot_leave_end_the_wait() {
        for dead in ["internal-error", "guest-panicked", "io-error", "shutdown"] {
            assert!(is_dead_state(dead), "{dead}");
        }
        // Paused for a snapshot, starting, or loading one: the wait goes on.
        for alive in ["paused", "running", "prelaunch", "restore-vm", "save-vm", "finish-migrate"] {
            assert!(!is_dead_state(alive), "{alive}");
        }
    }

    #[test]
    fn a_taken_port_is_named() {
        let held = TcpListener::bind("127.0.0.1:0").unwrap();
        let port = held.local_addr().unwrap().port();
        let err = pick_port(IpAddr::V4(Ipv4Addr::LOCALHOST), port).unwrap_err().to_string();
        assert!(err.contains(&format!("port {port}")) && err.contains("already in use"), "{err}");
        assert_ne!(pick_port(IpAddr::V4(Ipv4Addr::LOCALHOST), 0).unwrap(), 0);
    }

    #[test]
    fn snapshot_names_are_checked_and_missing_ones_list_the_others() {
        assert!(check_snapshot_name("ready").is_ok());
        let err = check_snapshot_name("a b; quit").unwrap_err().to_string();
        assert!(err.contains("letters, digits"), "{err}");
        let info: ImageInfo =
            serde_json::from_str(r#"{"format":"qcow2","virtual-size":1,"snapshots":[{"name":"boot"}]}"#).unwrap();
        let err = require_snapshot(&info, "ready", Path::new("/v/o.qcow2")).unwrap_err().to_string();
        assert_eq!(err, "snapshot \"ready\" does not exist in /v/o.qcow2 (it has: boot)");
    }
}
