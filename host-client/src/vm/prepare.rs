//! `arena vm prepare`: a golden image from an installer ISO.
//!
//! A blank disk is booted with the ISO as a CD-ROM (the disk first in the boot
//! order, so once the installer has made it bootable every reboot lands there),
//! the OEM folder of `arena prep stage` as a read-only FAT disk, and an
//! answer file on removable media, where Windows Setup looks for
//! `autounattend.xml`. The install is followed through QMP (the installer's
//! reboots) and the guest's staged health; when every component is up the
//! guest is shut down through ACPI, and the disk becomes the read-only golden
//! image.
//!
//! Progress is kept in `<out>.prepare/state.json`, so an interrupted prepare
//! started again with the same arguments goes on from its stage.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};

use super::disk::{make_read_only, QemuImg};
use super::qemu::{self, FolderDrive};
use super::{Vm, VmConfig, VmError};

/// Where a prepare is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Stage {
    /// The blank disk exists.
    Created,
    /// The installer runs (or the installed system's first boots).
    Installing,
    /// The guest answered with every component up; it still has to shut down.
    Healthy,
    /// The guest shut down cleanly; the disk has to become the golden image.
    ShutDown,
    /// The golden image is in place, read-only.
    Sealed,
}

impl Stage {
    pub fn name(self) -> &'static str {
        match self {
            Stage::Created => "created",
            Stage::Installing => "installing",
            Stage::Healthy => "healthy",
            Stage::ShutDown => "shut-down",
            Stage::Sealed => "sealed",
        }
    }
}

/// `state.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct State {
    pub stage: Stage,
    /// The ISO and OEM folder it was started with; a resume must use the same.
    pub iso: PathBuf,
    pub oem: PathBuf,
    /// QEMU's process id while one runs, so that a resume after a crash can end it.
    #[serde(default)]
    pub qemu_pid: Option<u32>,
    /// Reboots seen so far.
    #[serde(default)]
    pub reboots: u32,
    /// Seconds spent in each stage so far.
    #[serde(default)]
    pub seconds: std::collections::BTreeMap<String, f64>,
}

/// What `arena vm prepare` was given.
#[derive(Debug, Clone)]
pub struct PrepareOptions {
    pub iso: PathBuf,
    /// The folder `arena prep stage` wrote.
    pub oem: PathBuf,
    /// An answer file, shown to the installer as `autounattend.xml` on removable media.
    pub answer: Option<PathBuf>,
    /// The golden image to make.
    pub out: PathBuf,
    /// The disk's size (`qemu-img` syntax: `64G`).
    pub size: String,
    /// Memory, processors, buses, firmware, token and the boot timeout (the
    /// install's limit); its `golden` and `dir` are not used.
    pub vm: VmConfig,
    /// How long the guest has to shut down after the power button.
    pub shutdown_timeout: Duration,
}

/// What a prepare tells as it goes.
#[derive(Debug)]
#[non_exhaustive]
pub enum PrepareEvent<'a> {
    /// Entering a stage (`resumed` when it was reached by an earlier run).
    Stage { stage: Stage, resumed: bool },
    /// QEMU started (the installer, or a reboot of the installed system).
    QemuStarted { pid: Option<u32>, accel: &'a str },
    /// The VM reset itself (the installer's reboots).
    Reboot { count: u32 },
}

/// The folder a prepare keeps its disk, logs and state in: `<out>.prepare`.
pub fn work_dir(out: &Path) -> PathBuf {
    let mut name = out.file_name().map(|n| n.to_os_string()).unwrap_or_default();
    name.push(".prepare");
    out.with_file_name(name)
}

/// Reads the state of a prepare of `out`, if one was started.
///
/// # Errors
///
/// The state file exists but cannot be read.
pub fn read_state(out: &Path) -> Result<Option<State>, VmError> {
    let path = work_dir(out).join("state.json");
    match std::fs::read(&path) {
        Ok(bytes) => serde_json::from_slice(&bytes)
            .map(Some)
            .map_err(|err| VmError::Invalid(format!("{}: {err}; delete the folder to start over", path.display()))),
        Err(err) if err.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(source) => Err(VmError::Io { what: format!("reading {}", path.display()), source }),
    }
}

fn write_state(dir: &Path, state: &State) -> Result<(), VmError> {
    let path = dir.join("state.json");
    let bytes = serde_json::to_vec_pretty(state).map_err(|err| VmError::Invalid(err.to_string()))?;
    arena_shared::atomic::write_atomic(&path, &bytes)
        .map_err(|err| VmError::Invalid(format!("writing {}: {err}", path.display())))
}

/// Ends a QEMU an interrupted prepare left running on this disk.
fn end_leftover(pid: u32, disk: &Path) {
    let cmdline = std::fs::read(format!("/proc/{pid}/cmdline")).unwrap_or_default();
    let disk = disk.display().to_string();
    if String::from_utf8_lossy(&cmdline).contains(disk.as_str()) {
        tracing::warn!(pid, "ending the QEMU an interrupted prepare left running");
        // The process is ours (it holds our disk); nothing else is signalled.
        let _ = std::process::Command::new("kill").arg("-KILL").arg(pid.to_string()).status();
        for _ in 0..50 {
            if !Path::new(&format!("/proc/{pid}")).exists() {
                break;
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    }
}

/// Runs (or resumes) a prepare to the sealed golden image.
///
/// # Errors
///
/// Missing inputs, an `out` that already exists, a guest that never became
/// healthy (with the doctor's report when the guest answers), or one that
/// did not shut down.
pub async fn prepare(options: &PrepareOptions, mut progress: impl FnMut(PrepareEvent<'_>)) -> Result<PathBuf, VmError> {
    let img = QemuImg { program: qemu::find_qemu_img(options.vm.qemu_img.as_deref())? };
    let qemu = qemu::find_qemu(options.vm.qemu.as_deref())?;
    let dir = work_dir(&options.out);
    let mut state = match read_state(&options.out)? {
        Some(state) => {
            if state.iso != options.iso || state.oem != options.oem {
                return Err(VmError::Invalid(format!(
                    "{} holds a prepare of {} with {}; give the same --iso and --oem to resume it, or delete the folder",
                    dir.display(),
                    state.iso.display(),
                    state.oem.display()
                )));
            }
            state
        }
        None => {
            if options.out.exists() {
                return Err(VmError::Invalid(format!(
                    "{} already exists; choose another --out (nothing was changed)",
                    options.out.display()
                )));
            }
            for (what, path) in [("--iso", &options.iso), ("--oem", &options.oem)] {
                if !path.exists() {
                    return Err(VmError::Invalid(format!("{what} {}: no such file or folder", path.display())));
                }
            }
            if !options.oem.is_dir() {
                return Err(VmError::Invalid(format!("--oem {} is not a folder", options.oem.display())));
            }
            std::fs::create_dir_all(&dir)
                .map_err(|source| VmError::Io { what: format!("creating {}", dir.display()), source })?;
            let state = State {
                stage: Stage::Created,
                iso: options.iso.clone(),
                oem: options.oem.clone(),
                qemu_pid: None,
                reboots: 0,
                seconds: Default::default(),
            };
            img.create_blank(&dir.join("disk.qcow2"), &options.size)?;
            write_state(&dir, &state)?;
            progress(PrepareEvent::Stage { stage: Stage::Created, resumed: false });
            state
        }
    };
    let disk = dir.join("disk.qcow2");
    if let Some(pid) = state.qemu_pid.take() {
        end_leftover(pid, &disk);
    }
    let mut resumed = true;
    loop {
        let stage_started = Instant::now();
        progress(PrepareEvent::Stage { stage: state.stage, resumed });
        resumed = false;
        let next = match state.stage {
            Stage::Created => Stage::Installing,
            Stage::Installing | Stage::Healthy => {
                let mut vm = launch(options, &qemu, &img, &dir, &disk).await?;
                state.qemu_pid = vm.pid();
                write_state(&dir, &state)?;
                progress(PrepareEvent::QemuStarted { pid: vm.pid(), accel: &vm.accel_note });
                let outcome = follow(&mut vm, options, &mut state, &mut progress).await;
                if let Err(err) = outcome {
                    vm.kill().await;
                    state.qemu_pid = None;
                    write_state(&dir, &state)?;
                    return Err(err);
                }
                // Healthy: now the clean shutdown.
                state.stage = Stage::Healthy;
                write_state(&dir, &state)?;
                progress(PrepareEvent::Stage { stage: Stage::Healthy, resumed: false });
                if !vm.shutdown(options.shutdown_timeout).await {
                    state.qemu_pid = None;
                    write_state(&dir, &state)?;
                    return Err(VmError::Invalid(format!(
                        "the guest did not shut down within {} s of the power button; the disk may not be clean, so it was not sealed (run the same command again to retry)",
                        options.shutdown_timeout.as_secs()
                    )));
                }
                state.qemu_pid = None;
                Stage::ShutDown
            }
            Stage::ShutDown => {
                std::fs::rename(&disk, &options.out).map_err(|source| VmError::Io {
                    what: format!("moving {} to {}", disk.display(), options.out.display()),
                    source,
                })?;
                make_read_only(&options.out)?;
                Stage::Sealed
            }
            Stage::Sealed => {
                // Done: the state folder has nothing left worth keeping but its logs.
                let _ = std::fs::remove_file(dir.join("qmp.sock"));
                return Ok(options.out.clone());
            }
        };
        *state.seconds.entry(state.stage.name().to_owned()).or_default() += stage_started.elapsed().as_secs_f64();
        state.stage = next;
        write_state(&dir, &state)?;
    }
}

async fn launch(options: &PrepareOptions, qemu: &Path, img: &QemuImg, dir: &Path, disk: &Path) -> Result<Vm, VmError> {
    let mut config = options.vm.clone();
    config.dir = dir.to_owned();
    config.golden = disk.to_owned();
    config.name = "prepare".into();
    let mut folders = vec![FolderDrive { folder: options.oem.clone(), removable: false }];
    if let Some(answer) = &options.answer {
        let answer_dir = dir.join("answer");
        std::fs::create_dir_all(&answer_dir)
            .map_err(|source| VmError::Io { what: format!("creating {}", answer_dir.display()), source })?;
        std::fs::copy(answer, answer_dir.join("autounattend.xml"))
            .map_err(|source| VmError::Io { what: format!("copying {}", answer.display()), source })?;
        folders.push(FolderDrive { folder: answer_dir, removable: true });
    }
    let (mut spec, accel_note) = config.spec(qemu.to_owned(), disk.to_owned(), img, false)?;
    spec.cdrom = Some(options.iso.clone());
    spec.folders = folders;
    Vm::launch(&config, spec, accel_note).await
}

/// Waits for the guest to become healthy, counting the VM's resets.
async fn follow(
    vm: &mut Vm,
    options: &PrepareOptions,
    state: &mut State,
    progress: &mut impl FnMut(PrepareEvent<'_>),
) -> Result<(), VmError> {
    let mut events = vm.qmp.events();
    let limit = options.vm.boot_timeout;
    let client = vm.client().clone();
    // Health events and resets interleave; both are reported as they come.
    let (tx, mut rx) = tokio::sync::mpsc::unbounded_channel::<String>();
    let wait = vm.wait_healthy(limit, move |event| {
        let _ = tx.send(format!("{event:?}"));
    });
    tokio::pin!(wait);
    let result = loop {
        tokio::select! {
            result = &mut wait => break result,
            Ok(name) = events.recv() => {
                if name == "RESET" {
                    state.reboots += 1;
                    progress(PrepareEvent::Reboot { count: state.reboots });
                }
            }
            Some(line) = rx.recv() => tracing::info!(health = %line, "prepare"),
        }
    };
    match result {
        Ok(_) => Ok(()),
        Err(err) => {
            // The doctor says why when the guest answers at all.
            let doctor = match client.with_timeout(Duration::from_secs(120)).doctor().await {
                Ok(report) => format!(
                    "\nthe guest's doctor report:\n{}",
                    serde_json::to_string_pretty(&report).unwrap_or_default()
                ),
                Err(_) => String::new(),
            };
            Err(VmError::Invalid(format!(
                "{err}{doctor}\n(the prepare stays at stage installing; run the same command again to go on)"
            )))
        }
    }
}
