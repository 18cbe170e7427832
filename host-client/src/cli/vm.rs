//! `arena vm`: Windows VMs run directly with QEMU, and the VM options
//! `arena run --vm-image` shares.
//!
//! `start` boots a VM on a new overlay of a golden image, waits for its guest,
//! saves the `ready` snapshot and keeps the VM up (started again from that
//! snapshot if QEMU dies) until Ctrl-C or SIGTERM, which shut it down through
//! ACPI. `snapshot`, `restore`, `screendump` and `stop` talk to a running VM
//! through the QMP socket in its folder. `prepare` makes a golden image from
//! an installer ISO. The work is in [`crate::vm`].

use std::net::IpAddr;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Duration;

use anyhow::Context;
use clap::{Args, Subcommand, ValueEnum};

use super::{emit, parse_seconds, Connection};
use crate::vm::fleet::ResetPolicy;
use crate::vm::prepare::{self, PrepareEvent, PrepareOptions};
use crate::vm::qemu::{Accel, DiskBus, NicModel};
use crate::vm::qmp::Qmp;
use crate::vm::{Boot, Vm, VmConfig, READY_SNAPSHOT};

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
    /// Boot with UEFI: OVMF's code file (read-only), e.g. Debian's ovmf package's OVMF_CODE_4M.fd.
    #[arg(long, value_name = "FILE", requires = "vm_uefi_vars")]
    pub vm_uefi_code: Option<PathBuf>,
    /// The UEFI variables template each VM copies (OVMF_VARS_4M.fd, or the one the image was installed with).
    #[arg(long, value_name = "FILE", requires = "vm_uefi_code")]
    pub vm_uefi_vars: Option<PathBuf>,
    /// The guest server's port inside the VM.
    #[arg(long, default_value_t = 5000, value_name = "PORT")]
    pub vm_guest_port: u16,
    /// How long a boot or a restore may take to reach a healthy guest.
    #[arg(long, default_value = "900", value_parser = parse_seconds, value_name = "SECONDS")]
    pub vm_boot_timeout: Duration,
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

impl VmArgs {
    /// A VM config for `golden` in `dir`.
    pub fn config(&self, golden: &Path, dir: &Path, name: &str, token: Option<String>) -> VmConfig {
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
        config.uefi = self.vm_uefi_code.clone().zip(self.vm_uefi_vars.clone());
        config.guest_port = self.vm_guest_port;
        config.boot_timeout = self.vm_boot_timeout;
        config.vnc = self.vm_vnc;
        config.token = token;
        config
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
        #[command(flatten)]
        vm: VmArgs,
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
    /// Make a golden image from an installer ISO and an OEM folder (`arena prep stage`);
    /// started again after an interruption, it goes on from its stage.
    Prepare {
        #[arg(long, value_name = "ISO", required_unless_present = "status")]
        iso: Option<PathBuf>,
        /// The folder `arena prep stage` filled.
        #[arg(long, value_name = "DIR", required_unless_present = "status")]
        oem: Option<PathBuf>,
        /// An answer file shown to the installer as autounattend.xml on removable media.
        #[arg(long, value_name = "FILE")]
        answer: Option<PathBuf>,
        /// The golden image to write (read-only when done).
        #[arg(long, value_name = "IMAGE")]
        out: PathBuf,
        /// The disk's size.
        #[arg(long, default_value = "64G")]
        size: String,
        /// How long the guest has to shut down after the power button.
        #[arg(long, default_value = "300", value_parser = parse_seconds, value_name = "SECONDS")]
        shutdown_timeout: Duration,
        /// Only say which stage a prepare of --out is at.
        #[arg(long)]
        status: bool,
        #[command(flatten)]
        vm: VmArgs,
    },
}

/// `--reset` of `arena run`.
pub fn parse_reset(text: &str) -> Result<ResetPolicy, String> {
    text.parse()
}

async fn qmp_of(dir: &Path) -> anyhow::Result<Qmp> {
    let socket = dir.join(crate::vm::CONTROL_SOCKET);
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
            let took = qmp_of(&dir).await?.restore_snapshot(&name, &dir.join(crate::vm::OVERLAY_FILE)).await?;
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
                    if name == "SHUTDOWN" || name == crate::vm::qmp::CLOSED {
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
        VmCommand::Prepare { iso, oem, answer, out, size, shutdown_timeout, status, vm } => {
            if status {
                return Ok(match prepare::read_state(&out)? {
                    Some(state) => {
                        emit(&format!(
                            "{}: stage {} ({} reboots so far)\n",
                            out.display(),
                            state.stage.name(),
                            state.reboots
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
            let (Some(iso), Some(oem)) = (iso, oem) else { anyhow::bail!("arena vm prepare needs --iso and --oem") };
            let token = match conn.resolve_token()? {
                Some(token) => Some(token),
                None => read_oem_token(&oem),
            };
            let options = PrepareOptions {
                iso,
                oem,
                answer,
                out: out.clone(),
                size,
                vm: vm.config(&out, &out, "prepare", token),
                shutdown_timeout,
            };
            let golden = prepare::prepare(&options, |event| {
                let line = match event {
                    PrepareEvent::Stage { stage, resumed: true } => format!("stage {} (resumed)\n", stage.name()),
                    PrepareEvent::Stage { stage, resumed: false } => format!("stage {}\n", stage.name()),
                    PrepareEvent::QemuStarted { pid, accel } => {
                        format!("QEMU started (pid {}, {accel})\n", pid.map(|p| p.to_string()).unwrap_or_default())
                    }
                    PrepareEvent::Reboot { count } => format!("the VM rebooted ({count})\n"),
                };
                let _ = emit(&line);
            })
            .await?;
            emit(&format!("golden image ready: {}\n", golden.display()))?;
            Ok(ExitCode::SUCCESS)
        }
    }
}

/// The token `arena prep stage` put in the OEM folder, for waiting on the guest it installs.
fn read_oem_token(oem: &Path) -> Option<String> {
    let text = std::fs::read_to_string(oem.join(crate::prep::TOKEN_NAME)).ok()?;
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
    let mut config = args.config(image, dir, "vm", conn.resolve_token()?);
    config.host_port = port;
    config.host_addr = bind;
    let has_ready = reuse
        && crate::vm::disk::QemuImg { program: crate::vm::qemu::find_qemu_img(args.qemu_img.as_deref())? }
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
        let took = vm.save_snapshot(READY_SNAPSHOT).await?;
        emit(&format!("saved snapshot {READY_SNAPSHOT} in {:.1} s\n", took.as_secs_f64()))?;
    }
    emit(&format!("guest ready: {}\n", vm.url()))?;
    // Watch: a QEMU that dies is started again from the ready snapshot; a
    // guest that shuts down (the power button, `arena vm stop`) ends the watch.
    let mut term =
        tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()).context("listening for SIGTERM")?;
    let mut events = vm.qmp.events();
    loop {
        tokio::select! {
            _ = tokio::signal::ctrl_c() => break,
            _ = term.recv() => break,
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
