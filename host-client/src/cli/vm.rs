//! `arena vm`: Windows VMs run directly with QEMU, and the VM options
//! `arena run --vm-image` shares.
//!
//! `start` boots a VM on a new overlay of a golden image, waits for its guest,
//! saves the `ready` snapshot and keeps the VM up (started again from that
//! snapshot if QEMU dies) until Ctrl-C or SIGTERM, which shut it down through
//! ACPI. `snapshot`, `restore`, `screendump` and `stop` talk to a running VM
//! through the QMP socket in its folder. `prepare` makes a golden image from
//! an installer ISO; `verify` boots one once and writes what it found. The
//! work is in [`arena_vm`].

use std::net::IpAddr;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Duration;

use anyhow::Context;
use clap::{Args, Subcommand, ValueEnum};

use super::{emit, parse_seconds, Connection};
use arena_vm::fleet::ResetPolicy;
use arena_vm::prepare::{self, Answer, PrepareEvent, PrepareOptions, Stage, StageTimeouts};
use arena_vm::qemu::{Accel, DiskBus, NicModel};
use arena_vm::qmp::Qmp;
use arena_vm::unattend::{choose_image, AnswerOptions, FirmwareKind, Uac};
use arena_vm::{Boot, Uefi, Vm, VmConfig, READY_SNAPSHOT};

/// `--vm-accel`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum AccelArg {
    /// KVM when /dev/kvm works, else software emulation (said in the log).
    Auto,
    Kvm,
    Tcg,
}

/// How VMs are built, for `arena vm` and `arena run --vm-image`.
#[derive(Debug, Clone, Args)]
pub struct VmArgs {
    /// Memory of each VM, in MiB.
    #[arg(long, default_value_t = 8192, value_name = "MIB")]
    pub vm_memory: u32,
    /// Processors of each VM.
    #[arg(long, default_value_t = 4, value_name = "N")]
    pub vm_cpus: u32,
    /// QEMU machine type.
    #[arg(long, default_value = "q35", value_name = "TYPE")]
    pub vm_machine: String,
    /// The system disk's bus: `ahci` needs no drivers in Windows; dockur's images
    /// also have the virtio ones.
    #[arg(long, value_enum, default_value_t = DiskBus::Ahci)]
    pub vm_disk_bus: DiskBus,
    /// The network card.
    #[arg(long, value_enum, default_value_t = NicModel::E1000e)]
    pub vm_nic: NicModel,
    #[arg(long, value_enum, default_value_t = AccelArg::Auto)]
    pub vm_accel: AccelArg,
    /// The firmware: `bios` (SeaBIOS), or `uefi`: OVMF with Secure Boot
    /// (Debian's ovmf: OVMF_CODE_4M.secboot.fd with SMM, OVMF_VARS_4M.ms.fd with Microsoft's keys).
    #[arg(long, value_enum, default_value_t = FirmwareKind::Bios)]
    pub vm_firmware: FirmwareKind,
    /// UEFI with this OVMF code file instead of Debian's secure-boot build (implies --vm-firmware uefi).
    #[arg(long, value_name = "FILE", requires = "vm_uefi_vars")]
    pub vm_uefi_code: Option<PathBuf>,
    /// The UEFI variables template each VM copies (OVMF_VARS_4M.fd, or the one the image was installed with).
    #[arg(long, value_name = "FILE", requires = "vm_uefi_code")]
    pub vm_uefi_vars: Option<PathBuf>,
    /// Whether --vm-uefi-code is a secure-boot build (it then runs with SMM and locked flash).
    #[arg(long, requires = "vm_uefi_code")]
    pub vm_uefi_secure_boot: bool,
    /// A TPM 2.0 from swtpm (state in each VM's folder) [default: on with UEFI].
    #[arg(long, value_name = "on|off")]
    pub vm_tpm: Option<OnOff>,
    /// Under KVM, show the processor's virtualisation extensions (VMX) to the guest
    /// (hidden by default, so Windows does not turn on virtualisation-based security).
    #[arg(long)]
    pub vm_nested: bool,
    /// swtpm [default: on PATH].
    #[arg(long, value_name = "PATH")]
    pub swtpm: Option<PathBuf>,
    /// The guest server's port inside the VM.
    #[arg(long, default_value_t = 5000, value_name = "PORT")]
    pub vm_guest_port: u16,
    /// How long a boot or a restore may take to reach a healthy guest.
    #[arg(long, default_value = "900", value_parser = parse_seconds, value_name = "SECONDS")]
    pub vm_boot_timeout: Duration,
    /// The least time from a healthy guest to its `ready` snapshot. The snapshot
    /// also waits for the guest to say its desktop has settled (taskbar shown, the
    /// desktop in front, the CPU idle: its `shell` health component); this is a floor
    /// on top, for what the guest cannot see.
    #[arg(long, default_value = "0", value_parser = parse_settle, value_name = "SECONDS")]
    pub vm_settle: Duration,
    /// The screen under UEFI, WIDTHxHEIGHT (OVMF's preferred resolution, which Windows'
    /// basic display driver keeps; 1440x900 is upstream's).
    #[arg(long, default_value = "1440x900", value_parser = parse_screen, value_name = "WxH")]
    pub vm_screen: (u32, u32),
    /// A VNC display for each VM (5900 + N, on the forwarded address; the next VMs take N+1, ...).
    #[arg(long, value_name = "N")]
    pub vm_vnc: Option<u16>,
    /// qemu-system-x86_64 [default: on PATH].
    #[arg(long, value_name = "PATH")]
    pub qemu: Option<PathBuf>,
    /// qemu-img [default: on PATH].
    #[arg(long, value_name = "PATH")]
    pub qemu_img: Option<PathBuf>,
}

/// `on` or `off`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum OnOff {
    On,
    Off,
}

impl VmArgs {
    /// The UEFI firmware these options ask for, if any.
    ///
    /// # Errors
    ///
    /// `--vm-firmware uefi` without Debian's ovmf files.
    pub fn uefi(&self) -> anyhow::Result<Option<Uefi>> {
        Ok(match (&self.vm_uefi_code, &self.vm_uefi_vars) {
            (Some(code), Some(vars)) => {
                Some(Uefi { code: code.clone(), vars_template: vars.clone(), secure_boot: self.vm_uefi_secure_boot })
            }
            _ if self.vm_firmware == FirmwareKind::Uefi => Some(Uefi::debian_secure_boot()?),
            _ => None,
        })
    }

    /// A VM config for `golden` in `dir`.
    ///
    /// # Errors
    ///
    /// The firmware asked for is not installed.
    pub fn config(&self, golden: &Path, dir: &Path, name: &str, token: Option<String>) -> anyhow::Result<VmConfig> {
        let mut config = VmConfig::new(golden, dir, name);
        config.qemu = self.qemu.clone();
        config.qemu_img = self.qemu_img.clone();
        config.memory_mib = self.vm_memory;
        config.cpus = self.vm_cpus;
        config.machine = self.vm_machine.clone();
        config.disk_bus = self.vm_disk_bus;
        config.nic = self.vm_nic;
        config.accel = match self.vm_accel {
            AccelArg::Auto => None,
            AccelArg::Kvm => Some(Accel::Kvm),
            AccelArg::Tcg => Some(Accel::Tcg),
        };
        config.uefi = self.uefi()?;
        config.tpm = match self.vm_tpm {
            Some(OnOff::On) => true,
            Some(OnOff::Off) => false,
            None => config.uefi.is_some(),
        };
        config.swtpm = self.swtpm.clone();
        config.nested = self.vm_nested;
        config.guest_port = self.vm_guest_port;
        config.boot_timeout = self.vm_boot_timeout;
        config.settle_floor = self.vm_settle;
        config.vnc = self.vm_vnc;
        config.token = token;
        config.screen = self.vm_screen;
        Ok(config)
    }
}

/// Arguments of `arena vm`.
#[derive(Debug, Clone, Args)]
pub struct VmCommandArgs {
    #[command(subcommand)]
    pub command: VmCommand,
}

/// `arena vm ...`.
#[derive(Debug, Clone, Subcommand)]
pub enum VmCommand {
    /// Boot a VM on a new overlay of IMAGE, wait for its guest, save the `ready`
    /// snapshot and keep it running until Ctrl-C or SIGTERM.
    Start {
        /// The read-only golden image (qcow2, raw, ...).
        #[arg(long, value_name = "IMAGE")]
        image: PathBuf,
        /// The VM's folder (overlay, QMP socket, logs).
        #[arg(long, value_name = "DIR")]
        dir: PathBuf,
        /// The host port forwarded to the guest server (0: a free one).
        #[arg(long, default_value_t = 5000)]
        port: u16,
        /// The address the port is forwarded on (0.0.0.0 for a pod's other containers).
        #[arg(long, default_value = "127.0.0.1")]
        bind: IpAddr,
        /// Boot the overlay already in DIR (from its `ready` snapshot when it has one) instead of a new one.
        #[arg(long)]
        reuse: bool,
        /// (Boxed: the VM options make the variant large.)
        #[command(flatten)]
        vm: Box<VmArgs>,
    },
    /// Save the running VM in DIR as snapshot NAME (memory and disk).
    Snapshot {
        #[arg(long, value_name = "DIR")]
        dir: PathBuf,
        name: String,
    },
    /// Put the running VM in DIR back to snapshot NAME.
    Restore {
        #[arg(long, value_name = "DIR")]
        dir: PathBuf,
        name: String,
    },
    /// Save the VM's display, as QEMU sees it, as a PNG.
    Screendump {
        #[arg(long, value_name = "DIR")]
        dir: PathBuf,
        #[arg(short, long, default_value = "screendump.png")]
        output: PathBuf,
    },
    /// Shut the VM in DIR down (ACPI power button, then quit after the grace time).
    Stop {
        #[arg(long, value_name = "DIR")]
        dir: PathBuf,
        #[arg(long, default_value = "120", value_parser = parse_seconds, value_name = "SECONDS")]
        grace: Duration,
    },
    /// Boot IMAGE once and check what a run would meet (a healthy guest, a settled
    /// desktop, the screen, the watermark, the clock, Defender, the browsers'
    /// folders, the licence, the guest's deep doctor); write the report and what a
    /// bug report needs into OUT (verify.txt, verify.json, screenshots, logs).
    /// Exits 1 when a check failed.
    Verify {
        /// The read-only golden image.
        image: PathBuf,
        /// The bundle's folder (made if missing; the VM runs in OUT/vm, removed at the end).
        #[arg(long, value_name = "OUT")]
        out: PathBuf,
        #[command(flatten)]
        vm: Box<VmArgs>,
    },
    /// Make a golden image from an installer ISO and an OEM folder (`arena prep stage`),
    /// with an answer file written from the options below; started again after an
    /// interruption, it goes on from the last safe stage.
    Prepare(Box<PrepareArgs>),
}

/// `arena vm prepare`.
#[derive(Debug, Clone, Args)]
pub struct PrepareArgs {
    #[arg(long, value_name = "ISO", required_unless_present_any = ["status", "list_editions"])]
    pub iso: Option<PathBuf>,
    /// The folder `arena prep stage` filled.
    #[arg(long, value_name = "DIR", required_unless_present_any = ["status", "list_editions"])]
    pub oem: Option<PathBuf>,
    /// Your own answer file instead of the generated one (put on the OEM media as autounattend.xml).
    #[arg(long, value_name = "FILE")]
    pub answer: Option<PathBuf>,
    /// The golden image to write (read-only when done).
    #[arg(long, value_name = "IMAGE", required_unless_present = "list_editions")]
    pub out: Option<PathBuf>,
    /// Only print the images the installer ISO (or an install.wim) holds: index, edition and name.
    #[arg(long, value_name = "ISO", exclusive = true)]
    pub list_editions: Option<PathBuf>,
    /// The disk's size (Windows 11 Setup wants 64 GB at least).
    #[arg(long, default_value = "64G")]
    pub size: String,
    /// The firmware: `uefi` is OVMF with Secure Boot and Microsoft's keys, SMM and a
    /// TPM 2.0 from swtpm, as a Windows 11 PC; `bios` is SeaBIOS, with Setup's
    /// LabConfig bypass keys in the answer file.
    #[arg(long, value_enum, default_value_t = FirmwareKind::Bios)]
    pub firmware: FirmwareKind,
    /// The edition to install: pro, pro-n, pro-workstations, pro-education, education,
    /// education-n, enterprise, enterprise-n (with Microsoft's generic key for it), or an
    /// image's name as the ISO lists it ("Windows 11 Pro"); Home is refused.
    #[arg(long, value_name = "EDITION", conflicts_with = "image_index")]
    pub edition: Option<String>,
    /// The image to install, by index in install.wim/install.esd [default: 1] (`--list-editions`).
    #[arg(long, value_name = "N")]
    pub image_index: Option<u32>,
    /// A product key, instead of the edition's generic one (XXXXX-XXXXX-XXXXX-XXXXX-XXXXX).
    #[arg(long, value_name = "KEY")]
    pub product_key: Option<String>,
    /// The local administrator account that logs on automatically (WAA's is Docker).
    #[arg(long, default_value = "Docker")]
    pub user: String,
    /// Its password (WAA's is empty).
    #[arg(long, default_value = "")]
    pub password: String,
    #[arg(long, default_value = "en-US", value_name = "TAG")]
    pub locale: String,
    /// Go on when --locale is not the installer's default language (Setup then
    /// stops at its language page unless the media hold that language too).
    #[arg(long)]
    pub force_locale: bool,
    /// The input locale (0409:00000409 is US English).
    #[arg(long, default_value = "0409:00000409", value_name = "LOCALE")]
    pub keyboard: String,
    /// A Windows time zone name.
    #[arg(long, default_value = "UTC", value_name = "NAME")]
    pub timezone: String,
    /// The computer's name (* lets Windows choose one).
    #[arg(long, default_value = "*", value_name = "NAME")]
    pub computer_name: String,
    /// User Account Control: off as in WAA's and dockur's images (docs/compatibility.md).
    #[arg(long, value_enum, default_value_t = Uac::Off)]
    pub uac: Uac,
    /// A stage's deadline, STAGE=DURATION (setup is per reboot; 90m, 2h, 300s); repeatable.
    /// Stages: setup, oobe, first-logon, oem-install, healthy, shut-down.
    #[arg(long, value_name = "STAGE=DURATION")]
    pub stage_timeout: Vec<String>,
    /// The same as --stage-timeout shut-down=SECONDS.
    #[arg(long, value_parser = parse_seconds, value_name = "SECONDS")]
    pub shutdown_timeout: Option<Duration>,
    /// Write the answer file, the OEM media and the UEFI variables into <out>.prepare/,
    /// print the swtpm and QEMU command lines, and stop.
    #[arg(long)]
    pub dry_run: bool,
    /// Only say which stage a prepare of --out is at.
    #[arg(long)]
    pub status: bool,
    /// xorriso, which builds the OEM media [default: on PATH].
    #[arg(long, value_name = "PATH")]
    pub xorriso: Option<PathBuf>,
    /// Let the OEM install's step STEP fail (`prep-apps.ps1`, or `prep-apps`) and seal
    /// the image anyway, once the guest is healthy but for its `setup` record; the
    /// prepare's state and the image's sidecar record the failure. Repeatable.
    #[arg(long, value_name = "STEP")]
    pub allow_failed_step: Vec<String>,
    /// A folder of Windows drivers Setup loads (put on the OEM media as `$WinPEDriver$`):
    /// virtio-win's, needed for `--vm-disk-bus virtio-blk|virtio-scsi`.
    #[arg(long, value_name = "DIR")]
    pub drivers: Option<PathBuf>,
    #[command(flatten)]
    pub vm: VmArgs,
}

impl PrepareArgs {
    /// The answer file's options; the image and key from the ISO's image list
    /// when it can be read ([`arena_vm::iso::list_images`]), else from the options alone.
    fn answer(&self, uefi: bool, tpm: bool, iso: &Path) -> anyhow::Result<AnswerOptions> {
        let mut a = AnswerOptions::new();
        let images = match arena_vm::iso::list_images(iso) {
            Ok(images) => Some(images),
            Err(why) => {
                tracing::info!(%why, "the ISO's image list could not be read; the image is chosen from the options alone");
                None
            }
        };
        if let Some(images) = &images {
            match arena_vm::iso::check_locale(images, &self.locale) {
                Ok(()) => {}
                Err(why) if self.force_locale => tracing::warn!(%why, "--force-locale: going on"),
                Err(why) => anyhow::bail!(why),
            }
        }
        let (image, key) =
            choose_image(self.edition.as_deref(), self.image_index, self.product_key.clone(), images.as_deref())
                .map_err(anyhow::Error::msg)?;
        a.image = image;
        a.product_key = key;
        a.user = self.user.clone();
        a.password = self.password.clone();
        a.locale = self.locale.clone();
        a.keyboard = self.keyboard.clone();
        a.timezone = self.timezone.clone();
        a.computer_name = self.computer_name.clone();
        a.uac = self.uac;
        a.firmware = if uefi { FirmwareKind::Uefi } else { FirmwareKind::Bios };
        // Setup checks for a TPM 2.0 and Secure Boot capable firmware; the keys only where they are absent.
        a.bypass_checks = !(uefi && tpm);
        Ok(a)
    }
}

/// `--vm-screen`: WIDTHxHEIGHT, each 640 to 7680.
fn parse_screen(text: &str) -> Result<(u32, u32), String> {
    let (w, h) = text.split_once(['x', 'X']).ok_or_else(|| format!("{text:?}: use WIDTHxHEIGHT, e.g. 1440x900"))?;
    let side = |s: &str| s.trim().parse::<u32>().ok().filter(|n| (480..=7680).contains(n));
    match (side(w), side(h)) {
        (Some(w), Some(h)) => Ok((w, h)),
        _ => Err(format!("{text:?}: each side is a number from 480 to 7680")),
    }
}

/// `--vm-settle`: seconds, 0 to an hour.
fn parse_settle(text: &str) -> Result<Duration, String> {
    match text.trim().parse::<f64>() {
        Ok(secs) if secs.is_finite() && (0.0..=3600.0).contains(&secs) => Ok(Duration::from_secs_f64(secs)),
        _ => Err(format!("--vm-settle {text:?}: use a number of seconds from 0 to 3600")),
    }
}

/// `--reset` of `arena run`.
pub fn parse_reset(text: &str) -> Result<ResetPolicy, String> {
    text.parse()
}

async fn qmp_of(dir: &Path) -> anyhow::Result<Qmp> {
    let socket = dir.join(arena_vm::CONTROL_SOCKET);
    if !socket.exists() {
        anyhow::bail!(
            "no VM runs in {}: {} does not exist (start one with `arena vm start --dir`)",
            dir.display(),
            socket.display()
        );
    }
    Ok(Qmp::connect(&socket, Duration::from_secs(2)).await?)
}

/// `arena vm`.
///
/// # Errors
///
/// Whatever the VM operation reports, naming what was wrong.
pub async fn run(conn: &Connection, args: VmCommandArgs) -> anyhow::Result<ExitCode> {
    match args.command {
        VmCommand::Start { image, dir, port, bind, reuse, vm } => {
            start(conn, &image, &dir, port, bind, reuse, &vm).await
        }
        VmCommand::Snapshot { dir, name } => {
            let took = qmp_of(&dir).await?.save_snapshot(&name).await?;
            emit(&format!("saved snapshot {name} in {:.1} s\n", took.as_secs_f64()))?;
            Ok(ExitCode::SUCCESS)
        }
        VmCommand::Restore { dir, name } => {
            let took = qmp_of(&dir).await?.restore_snapshot(&name, &dir.join(arena_vm::OVERLAY_FILE)).await?;
            emit(&format!("restored snapshot {name} in {:.1} s\n", took.as_secs_f64()))?;
            Ok(ExitCode::SUCCESS)
        }
        VmCommand::Screendump { dir, output } => {
            let qmp = qmp_of(&dir).await?;
            let output = std::path::absolute(&output).context("resolving --output")?;
            qmp.screendump(&output).await?;
            emit(&format!("{}\n", output.display()))?;
            Ok(ExitCode::SUCCESS)
        }
        VmCommand::Stop { dir, grace } => {
            let qmp = qmp_of(&dir).await?;
            let mut events = qmp.events();
            qmp.powerdown().await?;
            let ended = tokio::time::timeout(grace, async {
                while let Ok(name) = events.recv().await {
                    if name == "SHUTDOWN" || name == arena_vm::qmp::CLOSED {
                        return;
                    }
                }
            })
            .await;
            if ended.is_err() {
                let _ = qmp.quit().await;
                emit(&format!("the guest did not shut down within {} s; QEMU was stopped\n", grace.as_secs()))?;
                return Ok(ExitCode::from(1));
            }
            emit("the VM shut down\n")?;
            Ok(ExitCode::SUCCESS)
        }
        VmCommand::Prepare(args) => prepare_command(conn, *args).await,
        VmCommand::Verify { image, out, vm } => verify(conn, &image, &out, &vm).await,
    }
}

async fn verify(conn: &Connection, image: &Path, out: &Path, args: &VmArgs) -> anyhow::Result<ExitCode> {
    use arena_vm::verify::{VerifyOptions, REPORT_TEXT};
    let config = args.config(image, &arena_vm::verify::vm_dir(out), "verify", conn.resolve_token()?)?;
    let options = VerifyOptions { config, out: out.to_owned() };
    let report = arena_vm::verify::verify(&options, |check| {
        let _ =
            emit(&format!("{:<5} {}: {}\n", format!("{:?}", check.verdict).to_uppercase(), check.name, check.detail));
    })
    .await?;
    emit(&format!("report: {}\n", out.join(REPORT_TEXT).display()))?;
    Ok(if report.passed() { ExitCode::SUCCESS } else { ExitCode::from(1) })
}

async fn prepare_command(conn: &Connection, args: PrepareArgs) -> anyhow::Result<ExitCode> {
    if let Some(iso) = &args.list_editions {
        let images = arena_vm::iso::list_images(iso).map_err(anyhow::Error::msg)?;
        emit(&arena_vm::iso::render_list(&images))?;
        return Ok(ExitCode::SUCCESS);
    }
    let Some(out) = args.out.clone() else { anyhow::bail!("arena vm prepare needs --out") };
    if args.status {
        return Ok(match prepare::read_state(&out)? {
            Some(state) => {
                emit(&format!(
                    "{}: stage {} ({} reboots, {} restarts so far)\n",
                    out.display(),
                    state.stage.name(),
                    state.reboots,
                    state.restarts
                ))?;
                ExitCode::SUCCESS
            }
            None if out.exists() => {
                emit(&format!("{}: no prepare in progress; the image exists\n", out.display()))?;
                ExitCode::SUCCESS
            }
            None => {
                emit(&format!("{}: no prepare was started\n", out.display()))?;
                ExitCode::from(1)
            }
        });
    }
    let (Some(iso), Some(oem)) = (args.iso.clone(), args.oem.clone()) else {
        anyhow::bail!("arena vm prepare needs --iso and --oem")
    };
    let token = match conn.resolve_token()? {
        Some(token) => Some(token),
        None => read_oem_token(&oem),
    };
    let mut vm = args.vm.clone();
    if args.firmware == FirmwareKind::Uefi {
        vm.vm_firmware = FirmwareKind::Uefi;
    }
    let config = vm.config(&out, &out, "prepare", token)?;
    // Stage deadlines fit the accelerator the VM will run under (emulation is several times slower).
    let accel = match args.vm.vm_accel {
        AccelArg::Kvm => Accel::Kvm,
        AccelArg::Tcg => Accel::Tcg,
        AccelArg::Auto => arena_vm::qemu::detect_accel().0,
    };
    let mut timeouts = StageTimeouts::for_accel(accel);
    if let Some(grace) = args.shutdown_timeout {
        timeouts.0.insert(Stage::ShutDown, grace);
    }
    for text in &args.stage_timeout {
        timeouts.set(text).map_err(anyhow::Error::msg)?;
    }
    let answer = match &args.answer {
        Some(file) => Answer::File(file.clone()),
        None => Answer::Generated(args.answer(config.uefi.is_some(), config.tpm, &iso)?),
    };
    let options = PrepareOptions {
        iso,
        oem,
        answer,
        out: out.clone(),
        size: args.size.clone(),
        vm: config,
        timeouts,
        xorriso: args.xorriso.clone(),
        drivers: args.drivers.clone(),
        allow_failed_steps: args.allow_failed_step.clone(),
    };
    if args.dry_run {
        let lines = prepare::dry_run(&options)?;
        let dir = prepare::work_dir(&out);
        tracing::info!(dir = %dir.display(), "dry run: the answer file, the OEM media and the firmware variables are written");
        for line in lines {
            emit(&format!("{line}\n"))?;
        }
        return Ok(ExitCode::SUCCESS);
    }
    let golden = prepare::prepare(&options, |event| {
        let line = match event {
            PrepareEvent::Stage { stage, resumed, limit } => format!(
                "stage {}{}{}\n",
                stage.name(),
                if resumed { " (resumed)" } else { "" },
                limit.map(|l| format!(" (deadline {} s)", l.as_secs())).unwrap_or_default()
            ),
            PrepareEvent::QemuStarted { pid, accel } => {
                format!("QEMU started (pid {}, {accel})\n", pid.map(|p| p.to_string()).unwrap_or_default())
            }
            PrepareEvent::Reboot { count } => format!("the VM rebooted ({count})\n"),
            PrepareEvent::StartOver { from, why } => format!("starting over from stage {}: {why}\n", from.name()),
        };
        let _ = emit(&line);
    })
    .await?;
    emit(&format!("golden image ready: {}\n", golden.display()))?;
    Ok(ExitCode::SUCCESS)
}

/// The token `arena prep stage` put in the OEM folder, for waiting on the guest it installs.
fn read_oem_token(oem: &Path) -> Option<String> {
    let text = std::fs::read_to_string(oem.join(arena_vm::oem::TOKEN_NAME)).ok()?;
    arena_shared::token::parse(&text).ok()
}

async fn start(
    conn: &Connection,
    image: &Path,
    dir: &Path,
    port: u16,
    bind: IpAddr,
    reuse: bool,
    args: &VmArgs,
) -> anyhow::Result<ExitCode> {
    let mut config = args.config(image, dir, "vm", conn.resolve_token()?)?;
    config.host_port = port;
    config.host_addr = bind;
    let has_ready = reuse
        && arena_vm::disk::QemuImg { program: arena_vm::qemu::find_qemu_img(args.qemu_img.as_deref())? }
            .check_overlay(&config.overlay())
            .is_ok_and(|info| info.snapshots.iter().any(|s| s.name == READY_SNAPSHOT));
    let boot = match (reuse, has_ready) {
        (false, _) => Boot::Fresh,
        (true, true) => Boot::FromSnapshot(READY_SNAPSHOT.into()),
        (true, false) => Boot::Existing,
    };
    let mut vm = Vm::start(&config, boot.clone()).await?;
    config.host_port = vm.spec.host_port;
    emit(&format!("VM started: {} (QEMU pid {}, {})\n", vm.url(), vm.pid().unwrap_or(0), vm.accel_note))?;
    vm.wait_healthy(config.boot_timeout, |_| {}).await?;
    if !matches!(boot, Boot::FromSnapshot(_)) {
        let settled = vm.wait_settled(config.settle_floor, config.boot_timeout).await?;
        match &settled.shell {
            Some(shell) => {
                emit(&format!("desktop settled after {:.1} s: {shell}\n", settled.settled_after.as_secs_f64()))?
            }
            None => emit("the guest reports no shell component (an older guest): only --vm-settle was waited\n")?,
        }
        let took = vm.save_snapshot(READY_SNAPSHOT).await?;
        emit(&format!("saved snapshot {READY_SNAPSHOT} in {:.1} s\n", took.as_secs_f64()))?;
    }
    emit(&format!("guest ready: {}\n", vm.url()))?;
    // Watch: a QEMU that dies is started again from the ready snapshot; a
    // guest that shuts down (the power button, `arena vm stop`) ends the watch.
    let term = crate::cli::signals::terminate_requested().context("listening for SIGTERM")?;
    tokio::pin!(term);
    let mut events = vm.qmp.events();
    loop {
        tokio::select! {
            _ = tokio::signal::ctrl_c() => break,
            () = &mut term => break,
            Ok(name) = events.recv() => {
                if name == "SHUTDOWN" {
                    emit("the guest shut down\n")?;
                    vm.kill().await;
                    return Ok(ExitCode::SUCCESS);
                }
            }
            () = tokio::time::sleep(Duration::from_secs(2)) => {
                if let Some(status) = vm.exited() {
                    tracing::warn!(%status, "QEMU exited; starting the VM again from its ready snapshot");
                    vm = Vm::start(&config, Boot::FromSnapshot(READY_SNAPSHOT.into())).await?;
                    vm.wait_healthy(config.boot_timeout, |_| {}).await?;
                    events = vm.qmp.events();
                    emit(&format!("guest ready again: {}\n", vm.url()))?;
                }
            }
        }
    }
    emit("shutting the VM down\n")?;
    let clean = vm.shutdown(Duration::from_secs(120)).await;
    emit(if clean { "the VM shut down\n" } else { "the VM was stopped\n" })?;
    Ok(ExitCode::SUCCESS)
}
