//! `arena vm prepare`: a golden image from an installer ISO.
//!
//! A blank disk is booted with the ISO as a CD-ROM (the disk first in the boot
//! order, so once Setup has made it bootable every reboot lands there) and the
//! OEM media as a second CD-ROM: an ISO 9660 image (no size cap below what
//! users stage; Joliet names for Windows) holding `autounattend.xml` at its
//! root, where Windows Setup's implicit search looks on removable read-only
//! media, the OEM folder as `OEM\`, and a marker file by which the answer
//! file's specialize pass finds the drive and copies `OEM\` to `C:\OEM`
//! ([`super::unattend`]). With `--firmware uefi` the VM has OVMF's secure-boot
//! build with Microsoft's keys, SMM, and a TPM 2.0 from swtpm.
//!
//! The install goes through stages, each with its own deadline
//! (`--stage-timeout STAGE=DURATION`): `setup` (per reboot, counted over QMP),
//! `oobe`, `first-logon` and `oem-install` (told by lines `arena-stage: NAME`
//! that the answer file's commands and `setup.ps1` write to the first serial
//! port), `healthy` (the guest answers with every component up), then the
//! guest is saved as a snapshot, shut down through ACPI (`shut-down`), the
//! snapshot is dropped and the disk becomes the read-only golden image
//! (`sealed`).
//!
//! Progress is kept in `<out>.prepare/state.json`. A resume goes on from the
//! last boundary that is safe: after `healthy` from the saved snapshot; before
//! it, Windows' disk is half-installed (a power cut there makes Windows say
//! "The computer restarted unexpectedly"), so the install starts over from a
//! blank disk, with the answer file and the OEM media built again from this
//! run's options and OEM folder, and says so. A rerun first ends what the
//! interrupted run left running on the folder's files ([`end_leftovers`]);
//! on Linux QEMU, swtpm, `qemu-img` and `xorriso` die with prepare anyway
//! (`PR_SET_PDEATHSIG`).
//!
//! On every failure the serial log, a screendump and the guest's doctor report
//! (when it answers) are kept in `<out>.prepare/failures/`.

use std::collections::BTreeMap;
use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};

use super::bundle::{self, Bundle};
use super::disk::{make_read_only, QemuImg};
use super::qemu::{self, Accel};
use super::sidecar::{self, ImageFacts};
use super::tpm::{self, SwtpmSpec};
use super::unattend::{self, AnswerOptions};
use super::{claim_dir, Vm, VmConfig, VmError, UEFI_VARS_FILE};

/// Where a prepare is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Stage {
    /// The blank disk and the OEM media exist.
    Created,
    /// Windows Setup runs (WinPE, then its reboots into the new system).
    #[serde(alias = "installing")]
    Setup,
    /// The specialize pass is done; OOBE runs.
    Oobe,
    /// The user logged on; the first logon commands run.
    FirstLogon,
    /// `C:\OEM\install.bat` runs `setup.ps1`.
    OemInstall,
    /// `setup.ps1` finished every step (`arena-stage: oem-done`); the guest must
    /// answer with every component up, its setup included, within the `healthy`
    /// deadline.
    OemDone,
    /// The guest answered with every component up and was saved as a snapshot;
    /// it still has to shut down.
    Healthy,
    /// The guest shut down cleanly; the disk has to become the golden image.
    ShutDown,
    /// The golden image is in place, read-only.
    Sealed,
}

/// The stages a deadline can be set for, in order.
pub const TIMED_STAGES: &[Stage] =
    &[Stage::Setup, Stage::Oobe, Stage::FirstLogon, Stage::OemInstall, Stage::Healthy, Stage::ShutDown];

impl Stage {
    pub fn name(self) -> &'static str {
        match self {
            Stage::Created => "created",
            Stage::Setup => "setup",
            Stage::Oobe => "oobe",
            Stage::FirstLogon => "first-logon",
            Stage::OemInstall => "oem-install",
            Stage::OemDone => "oem-done",
            Stage::Healthy => "healthy",
            Stage::ShutDown => "shut-down",
            Stage::Sealed => "sealed",
        }
    }

    fn from_name(name: &str) -> Option<Stage> {
        [
            Stage::Created,
            Stage::Setup,
            Stage::Oobe,
            Stage::FirstLogon,
            Stage::OemInstall,
            Stage::OemDone,
            Stage::Healthy,
            Stage::ShutDown,
            Stage::Sealed,
        ]
        .into_iter()
        .find(|s| s.name() == name)
    }

    /// Whether the disk is mid-install in this stage (a resume starts over).
    fn mid_install(self) -> bool {
        matches!(self, Stage::Setup | Stage::Oobe | Stage::FirstLogon | Stage::OemInstall | Stage::OemDone)
    }

    /// The deadline that applies in this stage: `oem-done` waits on the guest's
    /// health, so it has `healthy`'s.
    fn deadline(self, timeouts: &StageTimeouts) -> Duration {
        timeouts.get(if self == Stage::OemDone { Stage::Healthy } else { self })
    }
}

/// The serial-port line prefix by which the guest tells its stage.
pub const STAGE_LINE: &str = "arena-stage: ";

/// The snapshot a prepare saves once the guest is healthy, dropped before sealing.
pub const HEALTHY_SNAPSHOT: &str = "prepare-healthy";

/// Each stage's deadline.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StageTimeouts(pub BTreeMap<Stage, Duration>);

impl Default for StageTimeouts {
    /// Windows Setup takes 10-40 minutes per boot under KVM; OOBE a few; the
    /// OEM install downloads the task apps (the longest part); a shutdown a minute.
    fn default() -> StageTimeouts {
        let m = |minutes: u64| Duration::from_secs(minutes * 60);
        StageTimeouts(BTreeMap::from([
            (Stage::Setup, m(60)),
            (Stage::Oobe, m(30)),
            (Stage::FirstLogon, m(20)),
            (Stage::OemInstall, m(120)),
            (Stage::Healthy, m(15)),
            (Stage::ShutDown, m(5)),
        ]))
    }
}

/// How much longer each stage may take under software emulation (TCG) than
/// under KVM, where the defaults are set: Windows Setup, OOBE, the first logon,
/// the guest's start and the shutdown are processor-bound and run many times
/// slower emulated (docs/vm.md gives the figures); the OEM install is largely
/// downloads, so it gets less.
pub const TCG_FACTOR: &[(Stage, u32)] = &[
    (Stage::Setup, 4),
    (Stage::Oobe, 4),
    (Stage::FirstLogon, 4),
    (Stage::OemInstall, 2),
    (Stage::Healthy, 4),
    (Stage::ShutDown, 4),
];

impl StageTimeouts {
    /// The defaults for a VM that runs under `accel`: scaled by [`TCG_FACTOR`] under emulation.
    pub fn for_accel(accel: Accel) -> StageTimeouts {
        let mut timeouts = StageTimeouts::default();
        if accel == Accel::Tcg {
            for (stage, factor) in TCG_FACTOR {
                if let Some(limit) = timeouts.0.get_mut(stage) {
                    *limit *= *factor;
                }
            }
        }
        timeouts
    }

    pub fn get(&self, stage: Stage) -> Duration {
        self.0.get(&stage).copied().unwrap_or(Duration::from_secs(3600))
    }

    /// Sets one from `STAGE=DURATION` (`90m`, `2h`, `300s` or `300`).
    ///
    /// # Errors
    ///
    /// A message naming the stages or the duration's forms.
    pub fn set(&mut self, text: &str) -> Result<(), String> {
        let names: Vec<&str> = TIMED_STAGES.iter().map(|s| s.name()).collect();
        let (stage, duration) = text
            .split_once('=')
            .ok_or_else(|| format!("--stage-timeout {text:?}: use STAGE=DURATION, e.g. setup=90m"))?;
        let stage = Stage::from_name(stage.trim())
            .filter(|s| TIMED_STAGES.contains(s))
            .ok_or_else(|| format!("--stage-timeout {text:?}: the stages are {}", names.join(", ")))?;
        let duration = parse_duration(duration.trim()).ok_or_else(|| {
            format!("--stage-timeout {text:?}: a duration is a number with s, m or h (300s, 90m, 2h)")
        })?;
        self.0.insert(stage, duration);
        Ok(())
    }
}

fn parse_duration(text: &str) -> Option<Duration> {
    let (number, unit) = match text.char_indices().find(|(_, c)| !c.is_ascii_digit()) {
        Some((i, _)) => text.split_at(i),
        None => (text, "s"),
    };
    let n: u64 = number.parse().ok()?;
    let seconds = match unit {
        "s" => n,
        "m" => n.checked_mul(60)?,
        "h" => n.checked_mul(3600)?,
        _ => return None,
    };
    (seconds > 0).then(|| Duration::from_secs(seconds))
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
    /// How often the install started over from a blank disk.
    #[serde(default)]
    pub restarts: u32,
    /// Seconds spent in each stage so far.
    #[serde(default)]
    pub seconds: BTreeMap<String, f64>,
    /// When this prepare began (seconds since 1970): the install date when
    /// Windows does not say its own.
    #[serde(default)]
    pub started_unix: Option<i64>,
    /// What the healthy guest said of its Windows, for the image's sidecar.
    #[serde(default)]
    pub guest: Option<sidecar::GuestFacts>,
    /// The OEM steps that failed and were let through (`--allow-failed-step`),
    /// each as `setup.ps1` named it (`prep-apps.ps1 (exit code 3)`).
    #[serde(default)]
    pub allowed_failures: Vec<String>,
}

/// The answer file: generated from options, or the user's own.
#[derive(Debug, Clone)]
pub enum Answer {
    Generated(AnswerOptions),
    File(PathBuf),
}

/// What `arena vm prepare` was given.
#[derive(Debug, Clone)]
pub struct PrepareOptions {
    pub iso: PathBuf,
    /// The folder `arena prep stage` wrote.
    pub oem: PathBuf,
    pub answer: Answer,
    /// The golden image to make.
    pub out: PathBuf,
    /// The disk's size (`qemu-img` syntax: `64G`).
    pub size: String,
    /// Memory, processors, buses, firmware, TPM and token; its `golden` and `dir` are not used.
    pub vm: VmConfig,
    pub timeouts: StageTimeouts,
    /// `xorriso` [default: on PATH].
    pub xorriso: Option<PathBuf>,
    /// Drivers Setup loads from the OEM media's `$WinPEDriver$` folder (virtio-win's,
    /// for a virtio disk bus), or `None`.
    pub drivers: Option<PathBuf>,
    /// OEM steps whose failure does not stop the prepare (`--allow-failed-step`,
    /// by script name, `.ps1` optional): the image is sealed once the guest is
    /// healthy but for its `setup` component, and the state and sidecar record them.
    pub allow_failed_steps: Vec<String>,
}

/// What a prepare tells as it goes.
#[derive(Debug)]
pub enum PrepareEvent<'a> {
    /// Entering a stage (`resumed` when it was reached by an earlier run), with its deadline.
    Stage { stage: Stage, resumed: bool, limit: Option<Duration> },
    /// QEMU started (the installer, or a reboot of the installed system).
    QemuStarted { pid: Option<u32>, accel: &'a str },
    /// The VM reset itself (the installer's reboots).
    Reboot { count: u32 },
    /// An interrupted install starts over from a blank disk, and why.
    StartOver { from: Stage, why: &'a str },
}

/// The folder a prepare keeps its disk, logs and state in: `<out>.prepare`.
pub fn work_dir(out: &Path) -> PathBuf {
    let mut name = out.file_name().map(|n| n.to_os_string()).unwrap_or_default();
    name.push(".prepare");
    out.with_file_name(name)
}

/// The answer file in the work folder (also on the OEM media's root).
pub const ANSWER_FILE: &str = "autounattend.xml";
/// The OEM media in the work folder.
pub const MEDIA_FILE: &str = "oem-media.iso";
/// The OEM media's volume label.
pub const MEDIA_LABEL: &str = "ARENA_OEM";

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

fn io(what: String) -> impl FnOnce(std::io::Error) -> VmError {
    move |source| VmError::Io { what, source }
}

/// The programs of a prepare that hold files of its folder: QEMU and
/// `qemu-img` (the disk's lock), swtpm (the TPM state's lock).
#[cfg_attr(not(target_os = "linux"), expect(dead_code, reason = "found only through /proc"))]
const HOLDERS: &[&str] = &["qemu-system", "qemu-img", "swtpm"];

/// How long a leftover `qemu-img` may take to finish on its own (a snapshot
/// deletion ended midway can leave the disk with leaked clusters).
const QEMU_IMG_GRACE: Duration = Duration::from_secs(20);

/// Ends what an interrupted prepare left running on the files of `dir`, so the
/// rerun can open them: a QEMU or swtpm at once; a `qemu-img` once it had
/// [`QEMU_IMG_GRACE`] to finish. (Each child dies with prepare on Linux, but a
/// prepare from an older build, or a child started in the instant its prepare
/// died, may not have.) Only this user's processes whose program is one of
/// [`HOLDERS`] and whose arguments name a file in `dir` are touched.
fn end_leftovers(dir: &Path) {
    let started = Instant::now();
    loop {
        let leftovers = holders_of(dir);
        if leftovers.is_empty() {
            return;
        }
        for (pid, program) in &leftovers {
            let let_finish = program.starts_with("qemu-img") && started.elapsed() < QEMU_IMG_GRACE;
            if !let_finish {
                tracing::warn!(pid, program = %program, "ending what an interrupted prepare left running");
                // The process is this user's and runs one of our programs on our files (checked just now).
                crate::child::kill(*pid);
            }
        }
        if started.elapsed() > QEMU_IMG_GRACE + Duration::from_secs(10) {
            tracing::warn!(?leftovers, "processes of an interrupted prepare do not end");
            return;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// This user's running processes of [`HOLDERS`] with an argument naming a file
/// in `dir`: their ids and program names. QEMU's arguments name files inside
/// options (`file=PATH,format=qcow2`), so each part between `,` and `=` is
/// read as a path, relative to the process's working folder.
fn holders_of(dir: &Path) -> Vec<(u32, String)> {
    #[cfg_attr(not(target_os = "linux"), expect(unused_mut, reason = "found only through /proc"))]
    let mut found = Vec::new();
    #[cfg(target_os = "linux")]
    {
        use std::os::unix::fs::MetadataExt;
        let folders: Vec<PathBuf> =
            [std::path::absolute(dir).ok(), std::fs::canonicalize(dir).ok()].into_iter().flatten().collect();
        let me = crate::child::effective_uid();
        let own = std::process::id();
        for entry in std::fs::read_dir("/proc").into_iter().flatten().flatten() {
            let Ok(pid) = entry.file_name().to_string_lossy().parse::<u32>() else { continue };
            if pid == own || entry.metadata().map(|m| m.uid()).ok() != Some(me) {
                continue;
            }
            // Empty for a process that has ended (a zombie) or is gone.
            let cmdline = std::fs::read(entry.path().join("cmdline")).unwrap_or_default();
            let mut args = cmdline.split(|b| *b == 0).map(|arg| String::from_utf8_lossy(arg).into_owned());
            let Some(program) = args.next() else { continue };
            let program = program.rsplit('/').next().unwrap_or_default().to_owned();
            if !HOLDERS.iter().any(|h| program.starts_with(h)) {
                continue;
            }
            let cwd = std::fs::read_link(entry.path().join("cwd")).unwrap_or_default();
            let names_ours = |arg: String| {
                arg.split([',', '=']).filter(|part| !part.is_empty()).any(|part| {
                    let path = cwd.join(part);
                    folders.iter().any(|folder| path.starts_with(folder)) && path.exists()
                })
            };
            if args.any(names_ours) {
                found.push((pid, program));
            }
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = dir;
    found
}

/// Checks the inputs of a new prepare.
fn check_inputs(options: &PrepareOptions) -> Result<(), VmError> {
    for (what, path) in [("--iso", &options.iso), ("--oem", &options.oem)] {
        if !path.exists() {
            return Err(VmError::Invalid(format!("{what} {}: no such file or folder", path.display())));
        }
    }
    if !options.iso.is_file() {
        return Err(VmError::Invalid(format!("--iso {} is not a file", options.iso.display())));
    }
    if !options.oem.is_dir() {
        return Err(VmError::Invalid(format!("--oem {} is not a folder", options.oem.display())));
    }
    check_drivers(options.vm.disk_bus, options.drivers.as_deref())?;
    match &options.answer {
        Answer::Generated(answer) => answer.check().map_err(VmError::Invalid)?,
        Answer::File(path) => {
            let text = std::fs::read_to_string(path).map_err(io(format!("reading --answer {}", path.display())))?;
            roxmltree::Document::parse(&text)
                .map_err(|err| VmError::Invalid(format!("--answer {}: not XML: {err}", path.display())))?;
        }
    }
    Ok(())
}

/// The folder on the OEM media Windows Setup loads drivers from, at the root of
/// every medium it sees (Microsoft Learn, "Add device drivers to Windows during
/// Windows Setup": the `$WinPEDriver$` folder), so no drive letter is guessed.
pub const DRIVERS_FOLDER: &str = "$WinPEDriver$";

/// A virtio disk bus needs a driver Windows Setup does not have (virtio-win's
/// `viostor` or `vioscsi`): without one Setup finds no disk to install on and
/// waits. Refused unless `--drivers` gives a folder of drivers.
///
/// # Errors
///
/// A virtio bus without `--drivers`, or `--drivers` that is not a folder.
pub fn check_drivers(bus: qemu::DiskBus, drivers: Option<&Path>) -> Result<(), VmError> {
    if let Some(folder) = drivers {
        if !folder.is_dir() {
            return Err(VmError::Invalid(format!("--drivers {}: not a folder", folder.display())));
        }
        return Ok(());
    }
    let name = match bus {
        qemu::DiskBus::Ahci => return Ok(()),
        qemu::DiskBus::VirtioBlk => "virtio-blk (virtio-win's viostor)",
        qemu::DiskBus::VirtioScsi => "virtio-scsi (virtio-win's vioscsi)",
    };
    Err(VmError::Invalid(format!(
        "--vm-disk-bus {name}: Windows Setup has no driver for this disk and would find none to install on; give --drivers DIR (a folder of Windows drivers, such as virtio-win's, which Setup loads from the OEM media's {DRIVERS_FOLDER}) or use --vm-disk-bus ahci"
    )))
}

/// Writes the answer file and the OEM media into `dir`.
fn write_media(options: &PrepareOptions, dir: &Path) -> Result<PathBuf, VmError> {
    let answer = dir.join(ANSWER_FILE);
    let text = match &options.answer {
        Answer::Generated(o) => {
            let text = unattend::render(o);
            // Setup refuses (or skips) a value past its documented maximum: never hand it one.
            unattend::check_limits(&text, true).map_err(VmError::Invalid)?;
            text
        }
        Answer::File(path) => {
            let text = std::fs::read_to_string(path).map_err(io(format!("reading --answer {}", path.display())))?;
            unattend::check_limits(&text, false)
                .map_err(|err| VmError::Invalid(format!("--answer {}: {err}", path.display())))?;
            text
        }
    };
    arena_shared::atomic::write_atomic(&answer, text.as_bytes())
        .map_err(|err| VmError::Invalid(format!("writing {}: {err}", answer.display())))?;
    let marker = dir.join(unattend::OEM_MARKER);
    std::fs::write(&marker, "The arena's OEM media: OEM\\ becomes C:\\OEM.\r\n")
        .map_err(io(format!("writing {}", marker.display())))?;
    let script = dir.join(unattend::OEM_SCRIPT);
    std::fs::write(&script, unattend::oem_copy_script()).map_err(io(format!("writing {}", script.display())))?;
    let iso = dir.join(MEDIA_FILE);
    let xorriso = find_xorriso(options.xorriso.as_deref())?;
    let args = media_args(&answer, &marker, &script, &options.oem, options.drivers.as_deref(), &iso);
    let mut command = std::process::Command::new(&xorriso);
    command.args(&args);
    crate::child::die_with_this_process_std(&mut command);
    Bundle::new(dir).command(&shell_line(&xorriso, &args));
    let out = command.output().map_err(io(format!("starting {}", xorriso.display())))?;
    if !out.status.success() {
        return Err(VmError::Image {
            what: format!("building the OEM media {}", iso.display()),
            message: String::from_utf8_lossy(&out.stderr).trim().to_owned(),
        });
    }
    Ok(iso)
}

/// `xorriso`: `explicit`, or on `PATH`.
///
/// # Errors
///
/// [`VmError::Missing`] naming Debian's package.
pub fn find_xorriso(explicit: Option<&Path>) -> Result<PathBuf, VmError> {
    qemu::find_program(explicit, "xorriso", "xorriso")
}

/// xorriso's arguments for the OEM media: ISO 9660 level 3 (files over 4 GiB
/// in several extents), Joliet with long names (what Windows reads), Rock
/// Ridge (what Linux reads), the label, and the three parts grafted in place.
pub fn media_args(
    answer: &Path,
    marker: &Path,
    script: &Path,
    oem: &Path,
    drivers: Option<&Path>,
    iso: &Path,
) -> Vec<OsString> {
    let graft = |name: &str, path: &Path| {
        let mut arg = OsString::from(format!("{name}="));
        arg.push(path);
        arg
    };
    let mut args: Vec<OsString> =
        ["-as", "mkisofs", "-quiet", "-iso-level", "3", "-J", "-joliet-long", "-r", "-V", MEDIA_LABEL, "-o"]
            .iter()
            .map(OsString::from)
            .collect();
    args.push(iso.into());
    args.push("-graft-points".into());
    args.push(graft(ANSWER_FILE, answer));
    args.push(graft(unattend::OEM_MARKER, marker));
    args.push(graft(unattend::OEM_SCRIPT, script));
    args.push(graft(&format!("{}/", unattend::OEM_MEDIA_FOLDER), oem));
    if let Some(drivers) = drivers {
        args.push(graft(&format!("{DRIVERS_FOLDER}/"), drivers));
    }
    args
}

/// One command line as the user reads it: the program, then each argument,
/// quoted for a POSIX shell where needed.
pub fn shell_line(program: &Path, args: &[OsString]) -> String {
    // A program found on PATH is shown by its name, as the user would type it.
    let name = program
        .file_name()
        .filter(|name| arena_shared::search_path::find_program(Path::new(name)).as_deref() == Some(program));
    std::iter::once(name.unwrap_or(program.as_os_str()))
        .chain(args.iter().map(OsString::as_os_str))
        .map(|a| {
            let a = a.to_string_lossy();
            if !a.is_empty() && a.chars().all(|c| c.is_ascii_alphanumeric() || "-_=./:,+@%".contains(c)) {
                a.into_owned()
            } else {
                format!("'{}'", a.replace('\'', r"'\''"))
            }
        })
        .collect::<Vec<_>>()
        .join(" ")
}

/// `--dry-run`: writes into `<out>.prepare/` everything the install would
/// attach (the answer file, the OEM media, the UEFI variables) and returns the
/// command lines it would run (xorriso's already ran), one per line, each
/// starting with its program: swtpm's (with a TPM), then QEMU's.
///
/// # Errors
///
/// Bad inputs, a missing program, or a file that cannot be written.
pub fn dry_run(options: &PrepareOptions) -> Result<Vec<String>, VmError> {
    check_inputs(options)?;
    let img = QemuImg { program: qemu::find_qemu_img(options.vm.qemu_img.as_deref())? };
    let qemu = qemu::find_qemu(options.vm.qemu.as_deref())?;
    let dir = work_dir(&options.out);
    claim_dir(&dir)?;
    let media = write_media(options, &dir)?;
    let config = prepare_config(options, &dir);
    let disk = dir.join("disk.qcow2");
    let (mut spec, _) = config.spec(qemu.clone(), disk, &img, true)?;
    spec.cdrom = Some(options.iso.clone());
    spec.media = vec![media];
    let mut lines = Vec::new();
    if config.tpm {
        let program = tpm::find_swtpm(config.swtpm.as_deref())?;
        let swtpm = SwtpmSpec::in_dir(program.clone(), &dir);
        lines.push(shell_line(&program, &swtpm.args()));
    }
    lines.push(shell_line(&qemu, &spec.args()));
    Ok(lines)
}

fn prepare_config(options: &PrepareOptions, dir: &Path) -> VmConfig {
    let mut config = options.vm.clone();
    config.dir = dir.to_owned();
    config.golden = dir.join("disk.qcow2");
    config.name = "prepare".into();
    if let Some(zone) = guest_zone(&options.answer) {
        config.rtc = qemu::RtcBase::for_zone(&zone);
    }
    config
}

/// The Windows time zone the answer file gives the guest: `--timezone`, or
/// the first `TimeZone` of the user's own answer file (`None` without one).
pub fn guest_zone(answer: &Answer) -> Option<String> {
    match answer {
        Answer::Generated(options) => Some(options.timezone.clone()),
        Answer::File(path) => {
            let text = std::fs::read_to_string(path).ok()?;
            let doc = roxmltree::Document::parse(&text).ok()?;
            let zone = doc.descendants().find(|n| n.tag_name().name() == "TimeZone")?.text()?.trim().to_owned();
            Some(zone)
        }
    }
}

/// Runs (or resumes) a prepare to the sealed golden image.
///
/// # Errors
///
/// Missing inputs, an `out` that already exists, a stage past its deadline
/// (with the evidence kept), or a guest that did not shut down.
pub async fn prepare(options: &PrepareOptions, mut progress: impl FnMut(PrepareEvent<'_>)) -> Result<PathBuf, VmError> {
    let img = QemuImg { program: qemu::find_qemu_img(options.vm.qemu_img.as_deref())? };
    let qemu = qemu::find_qemu(options.vm.qemu.as_deref())?;
    let dir = work_dir(&options.out);
    let disk = dir.join("disk.qcow2");
    let mut resumed = true;
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
            check_inputs(options)?;
            claim_dir(&dir)?;
            let state = State {
                stage: Stage::Created,
                iso: options.iso.clone(),
                oem: options.oem.clone(),
                qemu_pid: None,
                reboots: 0,
                restarts: 0,
                seconds: Default::default(),
                started_unix: Some(arena_shared::clock::now_unix_ms().div_euclid(1000)),
                guest: None,
                allowed_failures: Vec::new(),
            };
            write_media(options, &dir)?;
            img.create_blank(&disk, &options.size)?;
            write_state(&dir, &state)?;
            resumed = false;
            state
        }
    };
    state.qemu_pid = None;
    end_leftovers(&dir);
    let mut bundle = Bundle::new(&dir);
    bundle.note(&format!(
        "arena vm prepare {} at stage {} (iso {}, oem {})",
        if resumed { "resumed" } else { "started" },
        state.stage.name(),
        options.iso.display(),
        options.oem.display()
    ));
    let config = prepare_config(options, &dir);
    // The stage last announced, so none is announced twice.
    let mut announced = None;
    loop {
        // A resume in the middle of the install: Windows cannot go on from a disk
        // whose power was cut, so the install starts again from a blank disk.
        if resumed {
            let snapshot = state.stage == Stage::Healthy && has_snapshot(&img, &disk, HEALTHY_SNAPSHOT);
            if let Some(why) = start_over_reason(state.stage, snapshot) {
                progress(PrepareEvent::StartOver { from: state.stage, why });
                bundle.note(&format!("starting over from stage {}: {why}", state.stage.name()));
                start_over(options, &img, &dir, &disk, &mut state)?;
            }
        }
        let stage_started = Instant::now();
        let limit = TIMED_STAGES.contains(&state.stage).then(|| options.timeouts.get(state.stage));
        if announced != Some(state.stage) {
            progress(PrepareEvent::Stage { stage: state.stage, resumed, limit });
            bundle.note(&format!("stage {}{}", state.stage.name(), if resumed { " (resumed)" } else { "" }));
        }
        resumed = false;
        let next = match state.stage {
            Stage::Created => Stage::Setup,
            Stage::Setup | Stage::Oobe | Stage::FirstLogon | Stage::OemInstall | Stage::OemDone => {
                let mut vm = launch(options, &config, &qemu, &img, &disk, None, &bundle).await?;
                state.qemu_pid = vm.pid();
                write_state(&dir, &state)?;
                progress(PrepareEvent::QemuStarted { pid: vm.pid(), accel: &vm.accel_note });
                if let Err(err) = follow(&mut vm, options, &dir, &mut state, &mut bundle, &mut progress).await {
                    bundle.note(&format!("failed in stage {}: {err}", state.stage.name()));
                    let evidence = keep_evidence(&vm, &dir, state.stage).await;
                    vm.kill().await;
                    state.qemu_pid = None;
                    write_state(&dir, &state)?;
                    return Err(finish_evidence(evidence, &img, &disk, &bundle, err));
                }
                state.guest = Some(guest_facts(&vm).await);
                // Healthy: a safe point to come back to, then the shutdown.
                if let Err(err) = vm.save_snapshot(HEALTHY_SNAPSHOT).await {
                    vm.kill().await;
                    state.qemu_pid = None;
                    write_state(&dir, &state)?;
                    return Err(err);
                }
                state.stage = Stage::Healthy;
                write_state(&dir, &state)?;
                bundle.note("healthy: the guest, its setup done, was saved as snapshot prepare-healthy");
                // Said once the snapshot is there: from here a resume goes on from it.
                progress(PrepareEvent::Stage { stage: Stage::Healthy, resumed: false, limit: None });
                announced = Some(Stage::ShutDown);
                shut_down(vm, options, &dir, &mut state, &mut progress).await?
            }
            Stage::Healthy => {
                let mut vm =
                    launch(options, &config, &qemu, &img, &disk, Some(HEALTHY_SNAPSHOT.into()), &bundle).await?;
                state.qemu_pid = vm.pid();
                write_state(&dir, &state)?;
                progress(PrepareEvent::QemuStarted { pid: vm.pid(), accel: &vm.accel_note });
                let limit = options.timeouts.get(Stage::Healthy);
                // A failed step let through leaves the `setup` component down for good.
                let ignore: &[arena_shared::health::Component] =
                    if state.allowed_failures.is_empty() { &[] } else { &[arena_shared::health::Component::Setup] };
                if let Err(err) = vm.wait_healthy_but(limit, ignore, |_| {}).await {
                    bundle.note(&format!("failed in stage healthy: {err}"));
                    let evidence = keep_evidence(&vm, &dir, Stage::Healthy).await;
                    vm.kill().await;
                    state.qemu_pid = None;
                    write_state(&dir, &state)?;
                    return Err(finish_evidence(evidence, &img, &disk, &bundle, err));
                }
                if state.guest.is_none() {
                    state.guest = Some(guest_facts(&vm).await);
                    write_state(&dir, &state)?;
                }
                announced = Some(Stage::ShutDown);
                shut_down(vm, options, &dir, &mut state, &mut progress).await?
            }
            Stage::ShutDown if !disk.exists() && options.out.exists() => Stage::Sealed,
            Stage::ShutDown => {
                if has_snapshot(&img, &disk, HEALTHY_SNAPSHOT) {
                    img.delete_snapshot(&disk, HEALTHY_SNAPSHOT)?;
                }
                // A fresh copy: qcow2 keeps the clusters of a deleted snapshot (the
                // guest's whole memory), and the golden image should not carry them.
                let sealing = dir.join("sealing.qcow2");
                img.convert_to_qcow2(&disk, &sealing)?;
                std::fs::rename(&sealing, &options.out).map_err(io(format!(
                    "moving {} to {}",
                    sealing.display(),
                    options.out.display()
                )))?;
                make_read_only(&options.out)?;
                write_sidecar(options, &config, &state, &dir)?;
                let _ = std::fs::remove_file(&disk);
                Stage::Sealed
            }
            Stage::Sealed => {
                bundle.note(&format!("sealed: {}", options.out.display()));
                // Done: the folder keeps its logs, the answer file and the media for review.
                for file in ["qmp.sock", super::CONTROL_SOCKET, tpm::SOCKET] {
                    let _ = std::fs::remove_file(dir.join(file));
                }
                return Ok(options.out.clone());
            }
        };
        *state.seconds.entry(state.stage.name().to_owned()).or_default() += stage_started.elapsed().as_secs_f64();
        state.stage = next;
        write_state(&dir, &state)?;
    }
}

/// What the healthy guest says of its Windows (`EditionID`, the build,
/// `InstallDate` under [`sidecar::CURRENT_VERSION_KEY`]); each fact it cannot
/// read is left out.
async fn guest_facts(vm: &Vm) -> sidecar::GuestFacts {
    use arena_shared::registry::RegistryValue;
    let read = |value: &'static str| async move {
        vm.client().registry_get(sidecar::CURRENT_VERSION_KEY, Some(value)).await.ok().map(|r| r.data)
    };
    let text = |data: Option<RegistryValue>| match data {
        Some(RegistryValue::String(s)) if !s.trim().is_empty() => Some(s.trim().to_owned()),
        _ => None,
    };
    let edition_id = text(read("EditionID").await);
    let ubr = match read("UBR").await {
        Some(RegistryValue::Dword(ubr)) => Some(ubr),
        _ => None,
    };
    let build = text(read("CurrentBuild").await).map(|build| match ubr {
        Some(ubr) => format!("{build}.{ubr}"),
        None => build,
    });
    let install_date_unix = match read("InstallDate").await {
        Some(RegistryValue::Dword(secs)) => Some(i64::from(secs)),
        _ => None,
    };
    sidecar::GuestFacts { edition_id, build, install_date_unix }
}

/// Writes the sealed image's sidecar ([`sidecar`]), with a copy of the
/// prepare's final UEFI variables beside the image (read-only, as the image).
fn write_sidecar(options: &PrepareOptions, config: &VmConfig, state: &State, dir: &Path) -> Result<(), VmError> {
    let uefi_vars = match &config.uefi {
        Some(_) if dir.join(UEFI_VARS_FILE).is_file() => {
            let copy = sidecar::uefi_vars_for(&options.out);
            std::fs::copy(dir.join(UEFI_VARS_FILE), &copy)
                .map_err(io(format!("copying the UEFI variables to {}", copy.display())))?;
            make_read_only(&copy)?;
            Some(copy)
        }
        _ => None,
    };
    let guest = state.guest.clone().unwrap_or_default();
    let (chosen, language, startup_apps_off) = match &options.answer {
        Answer::Generated(answer) => (
            match &answer.image {
                unattend::ImageChoice::Name(name) => Some(name.clone()),
                unattend::ImageChoice::Index(_) | unattend::ImageChoice::ByKey => None,
            },
            Some(answer.locale.clone()),
            unattend::startup_apps_off(),
        ),
        Answer::File(_) => (None, None, Vec::new()),
    };
    let installed_unix = guest
        .install_date_unix
        .or(state.started_unix)
        .unwrap_or_else(|| arena_shared::clock::now_unix_ms().div_euclid(1000));
    let facts = ImageFacts {
        format: sidecar::FORMAT,
        firmware: sidecar::firmware_name(config).to_owned(),
        secure_boot: config.uefi.as_ref().is_some_and(|u| u.secure_boot),
        screen: config.screen,
        machine: config.machine.clone(),
        disk_bus: config.disk_bus,
        nic: config.nic,
        tpm: config.tpm,
        licence_expires_unix: sidecar::licence_expiry(guest.edition_id.as_deref(), installed_unix),
        edition: guest.edition_id.or(chosen),
        build: guest.build,
        language,
        timezone: guest_zone(&options.answer),
        installed_unix,
        uefi_vars,
        startup_apps_off,
        allowed_failed_steps: state.allowed_failures.clone(),
    };
    sidecar::write(&options.out, &facts)
}

/// Why a prepare resumed at `stage` must start the install over, or `None`
/// when it goes on from there (`snapshot`: the healthy snapshot exists).
pub fn start_over_reason(stage: Stage, snapshot: bool) -> Option<&'static str> {
    if stage.mid_install() {
        Some(
            "the install was interrupted before the guest was healthy; Windows Setup cannot continue on a disk whose power was cut, so the install starts over from a blank disk",
        )
    } else if stage == Stage::Healthy && !snapshot {
        Some("the healthy guest's snapshot is missing, so there is no safe point to shut down from")
    } else {
        None
    }
}

fn has_snapshot(img: &QemuImg, disk: &Path, name: &str) -> bool {
    img.info(disk).is_ok_and(|info| info.snapshots.iter().any(|s| s.name == name))
}

/// A blank disk, a new TPM and new UEFI variables; the stage back to `setup`.
fn start_over(
    options: &PrepareOptions,
    img: &QemuImg,
    dir: &Path,
    disk: &Path,
    state: &mut State,
) -> Result<(), VmError> {
    let _ = std::fs::remove_file(disk);
    img.create_blank(disk, &options.size)?;
    let tpm_state = dir.join(tpm::STATE_DIR);
    if tpm_state.exists() {
        std::fs::remove_dir_all(&tpm_state).map_err(io(format!("removing {}", tpm_state.display())))?;
    }
    let _ = std::fs::remove_file(dir.join(UEFI_VARS_FILE));
    // A new install takes the answer file and the OEM folder as they are now
    // (the user may have fixed what made the last one fail).
    write_media(options, dir)?;
    state.stage = Stage::Setup;
    state.restarts += 1;
    state.reboots = 0;
    write_state(dir, state)
}

async fn launch(
    options: &PrepareOptions,
    config: &VmConfig,
    qemu: &Path,
    img: &QemuImg,
    disk: &Path,
    loadvm: Option<String>,
    bundle: &Bundle,
) -> Result<Vm, VmError> {
    let dir = config.dir.as_path();
    let fresh_vars = !dir.join(UEFI_VARS_FILE).exists();
    let (mut spec, accel_note) = config.spec(qemu.to_owned(), disk.to_owned(), img, fresh_vars)?;
    spec.cdrom = Some(options.iso.clone());
    spec.media = vec![dir.join(MEDIA_FILE)];
    spec.loadvm = loadvm;
    bundle.keep_serial();
    if spec.tpm_socket.is_some() {
        let program = tpm::find_swtpm(config.swtpm.as_deref()).unwrap_or_else(|_| "swtpm".into());
        bundle.command(&shell_line(&program, &SwtpmSpec::in_dir(program.clone(), dir).args()));
    }
    bundle.command(&shell_line(&spec.qemu, &spec.args()));
    bundle.note(&format!("starting QEMU ({accel_note})"));
    Vm::launch(config, spec, accel_note).await
}

/// Shuts the healthy guest down within the `shut-down` deadline.
async fn shut_down(
    vm: Vm,
    options: &PrepareOptions,
    dir: &Path,
    state: &mut State,
    progress: &mut impl FnMut(PrepareEvent<'_>),
) -> Result<Stage, VmError> {
    let limit = options.timeouts.get(Stage::ShutDown);
    progress(PrepareEvent::Stage { stage: Stage::ShutDown, resumed: false, limit: Some(limit) });
    let clean = vm.shutdown(limit).await;
    state.qemu_pid = None;
    if !clean {
        write_state(dir, state)?;
        return Err(VmError::Invalid(format!(
            "the guest did not shut down within {} s of the power button; the disk may not be clean, so it was not sealed (run the same command again: it goes on from the healthy snapshot)",
            limit.as_secs()
        )));
    }
    Ok(Stage::ShutDown)
}

/// Under UEFI, Windows' CD boot loader waits for a key ("Press any key to boot
/// from CD or DVD") and otherwise falls through to the next boot option. The
/// prepare presses the space bar over QMP about once a second while Windows
/// Setup's first stage has not answered: across the VM's resets (the firmware
/// may reset once before the loader runs, as OVMF does after enrolling its
/// variables), until the first `arena-stage:` line or the first reboot from
/// the disk Setup made bootable, and for at most this long from the start:
/// the prompt shows for a few seconds once the firmware has started, later
/// under emulation. A remastered ISO with `efisys_noprompt.bin` would avoid the
/// presses, but Windows ISOs keep their files in UDF, which xorriso does not
/// write, so remastering needs the whole ISO unpacked and a UDF writer.
fn keypress_window(accel: Accel) -> Duration {
    match accel {
        Accel::Kvm => Duration::from_secs(180),
        Accel::Tcg => Duration::from_secs(1200),
    }
}

/// Resets after which the disk is what boots (Setup's WinPE stage wrote it and
/// rebooted): from then on a press could only reach the installer's prompt,
/// which must not boot again. Two: the firmware's own reset, then Setup's.
const PRESS_RESETS: u32 = 2;

/// What the guest's serial line says: a stage, or the OEM install's failure.
#[derive(Debug, Clone, PartialEq, Eq)]
enum StageEvent {
    Enter(Stage),
    Failed(String),
}

/// Follows the install from QEMU's start to a healthy guest whose setup is done,
/// stage by stage, each within its deadline: the guest's health is awaited only
/// once `setup.ps1` has said `oem-done` (so the seal never races the OEM
/// install), and an `oem-failed` line ends the prepare at once, naming the step.
async fn follow(
    vm: &mut Vm,
    options: &PrepareOptions,
    dir: &Path,
    state: &mut State,
    bundle: &mut Bundle,
    progress: &mut impl FnMut(PrepareEvent<'_>),
) -> Result<(), VmError> {
    let mut events = vm.qmp.events();
    let serial = dir.join("serial.log");
    let started = Instant::now();
    let press_keys =
        matches!(vm.spec.firmware, qemu::Firmware::Uefi { .. }) && state.stage == Stage::Setup && state.reboots == 0;
    let press_until = started + keypress_window(vm.spec.accel);
    let mut resets_here = 0u32;
    let mut stage_since = Instant::now();
    let mut stages = StageLines::default();
    // QEMU's forwarder accepts connections before the guest listens: short questions.
    let client = vm.client().with_timeout(Duration::from_secs(2));
    let mut health: Option<std::pin::Pin<Box<dyn std::future::Future<Output = _> + Send + '_>>> = None;
    let mut tick = tokio::time::interval(Duration::from_secs(1));
    bundle.screendump(vm, state.stage.name()).await;
    loop {
        tokio::select! {
            result = async {
                match health.as_mut() {
                    Some(wait) => wait.await,
                    None => std::future::pending().await,
                }
            } => {
                let result: Result<arena_shared::health::HealthReport, crate::oem::PrepError> = result;
                *state.seconds.entry(state.stage.name().to_owned()).or_default() += stage_since.elapsed().as_secs_f64();
                return match result {
                    Ok(report) => {
                        let setup = report.components.iter().find(|c| c.component == arena_shared::health::Component::Setup);
                        bundle.note(&format!(
                            "the guest answers with every component up ({})",
                            setup.map_or("it reports no setup component", |c| c.detail.as_str())
                        ));
                        Ok(())
                    }
                    Err(source) => Err(VmError::NotHealthy { name: "prepare".into(), source }),
                };
            }
            Ok(name) = events.recv() => {
                if name == "RESET" {
                    state.reboots += 1;
                    resets_here += 1;
                    progress(PrepareEvent::Reboot { count: state.reboots });
                    bundle.note(&format!("the VM reset ({} so far)", state.reboots));
                    write_state(dir, state)?;
                    // Setup's deadline is per boot.
                    if state.stage == Stage::Setup {
                        stage_since = Instant::now();
                    }
                    bundle.screendump(vm, &format!("{}-reset", state.stage.name())).await;
                } else if name == "SHUTDOWN" || name == super::qmp::CLOSED {
                    // Setup powers off only when it cannot go on: its last words say why.
                    let text = std::fs::read(&serial).unwrap_or_default();
                    return Err(VmError::Invalid(format!(
                        "the VM powered off during stage {}; {}",
                        state.stage.name(),
                        last_serial_lines(&String::from_utf8_lossy(&text))
                    )));
                }
            }
            _ = tick.tick() => {
                // The guest's own stage lines on the serial port.
                let text = std::fs::read(&serial).unwrap_or_default();
                let text = String::from_utf8_lossy(&text);
                let new = stages.take_new(&text);
                // Setup's first stage answered: no key may reach the installer's prompt again.
                let answered = stages.any || resets_here >= PRESS_RESETS;
                if press_keys && !answered && Instant::now() < press_until {
                    let _ = vm.qmp.hmp("sendkey spc", Duration::from_secs(2)).await;
                }
                for event in new {
                    match event {
                        StageEvent::Enter(stage) => {
                            if enter_stage(stage, options, dir, state, &mut stage_since, progress)? {
                                bundle.note(&format!("stage {}", stage.name()));
                                bundle.screendump(vm, stage.name()).await;
                            }
                            if stage == Stage::OemDone && health.is_none() {
                                let limit = Stage::OemDone.deadline(&options.timeouts);
                                health = Some(Box::pin(crate::oem::wait_healthy(&client, limit, Duration::from_millis(500), |_| {})));
                            }
                        }
                        StageEvent::Failed(why) => {
                            if let Some(steps) = allowed_failure(&why, &options.allow_failed_steps) {
                                bundle.note(&format!("the OEM install failed, allowed by --allow-failed-step: {why}"));
                                tracing::warn!(%why, "OEM steps failed and are let through (--allow-failed-step)");
                                state.allowed_failures = steps;
                                write_state(dir, state)?;
                                if enter_stage(Stage::OemDone, options, dir, state, &mut stage_since, progress)? {
                                    bundle.screendump(vm, Stage::OemDone.name()).await;
                                }
                                if health.is_none() {
                                    let limit = Stage::OemDone.deadline(&options.timeouts);
                                    // The `setup` component stays down on a failed record: every other must be up.
                                    health = Some(Box::pin(crate::oem::wait_healthy_but(&client, limit, Duration::from_millis(500), &[arena_shared::health::Component::Setup], |_| {})));
                                }
                                continue;
                            }
                            bundle.note(&format!("the OEM install failed: {why}"));
                            return Err(VmError::Invalid(format!(
                                "the OEM install failed in stage {}: {why} (the guest's log is %ProgramData%\\arena\\logs\\setup.log; fix the cause in the OEM folder and run the same command again, or let a step that does not matter fail with --allow-failed-step STEP)",
                                state.stage.name()
                            )));
                        }
                    }
                }
                bundle.screendump_if_due(vm, state.stage.name()).await;
                let limit = state.stage.deadline(&options.timeouts);
                if stage_since.elapsed() > limit {
                    let waited = if state.stage == Stage::OemDone {
                        " for the guest to answer with every component up"
                    } else {
                        ""
                    };
                    return Err(VmError::Invalid(format!(
                        "stage {} took longer than its {} s{waited} (--stage-timeout {}=DURATION to allow more); {}",
                        state.stage.name(),
                        limit.as_secs(),
                        if state.stage == Stage::OemDone { "healthy" } else { state.stage.name() },
                        last_serial_lines(&text)
                    )));
                }
                if let Some(status) = vm.exited() {
                    return Err(VmError::Exited {
                        name: "prepare".into(),
                        status,
                        log: super::log_tail(&dir.join("qemu.log")),
                    });
                }
            }
        }
    }
}

/// The guest's `arena-stage: NAME` lines, read from the serial log as it grows.
#[derive(Default)]
struct StageLines {
    /// Bytes of the log already read, up to the end of its last complete line
    /// (a line still being written is read again once it is whole).
    read: usize,
    /// Whether any stage line was seen.
    any: bool,
}

impl StageLines {
    /// The stage lines among the complete lines after the ones already read.
    fn take_new(&mut self, text: &str) -> Vec<StageEvent> {
        // QEMU truncates the log when it starts: a shorter log is a new one.
        if text.len() < self.read {
            self.read = 0;
        }
        let Some(whole) = text.get(self.read..).and_then(|rest| rest.rfind('\n').map(|end| &rest[..=end])) else {
            return Vec::new();
        };
        self.read += whole.len();
        let found: Vec<StageEvent> = stages_named(whole).collect();
        self.any |= !found.is_empty();
        found
    }
}

/// Moves `state` on to `stage` if it is a later stage of the install, saying
/// so; whether it did.
fn enter_stage(
    stage: Stage,
    options: &PrepareOptions,
    dir: &Path,
    state: &mut State,
    stage_since: &mut Instant,
    progress: &mut impl FnMut(PrepareEvent<'_>),
) -> Result<bool, VmError> {
    if stage > state.stage && stage.mid_install() {
        *state.seconds.entry(state.stage.name().to_owned()).or_default() += stage_since.elapsed().as_secs_f64();
        state.stage = stage;
        *stage_since = Instant::now();
        write_state(dir, state)?;
        let limit = stage.deadline(&options.timeouts);
        progress(PrepareEvent::Stage { stage, resumed: false, limit: Some(limit) });
        return Ok(true);
    }
    Ok(false)
}

/// The failed steps of an `oem-failed` line (`prep-apps.ps1 (exit code 3),
/// prep-x.ps1 (exit code 1); log C:\...`, as `setup.ps1` says them) when every one
/// is allowed (by script name, case aside, `.ps1` optional), or `None`.
pub fn allowed_failure(why: &str, allowed: &[String]) -> Option<Vec<String>> {
    if allowed.is_empty() {
        return None;
    }
    let steps_text = why.split("; log").next().unwrap_or(why);
    let steps: Vec<String> =
        steps_text.split(", ").map(str::trim).filter(|s| !s.is_empty()).map(str::to_owned).collect();
    let bare = |name: &str| {
        let name = name.trim();
        let lower = name.to_ascii_lowercase();
        lower.strip_suffix(".ps1").map(str::to_owned).unwrap_or(lower)
    };
    let is_allowed = |step: &String| {
        let script = step.split(" (").next().unwrap_or(step);
        allowed.iter().any(|a| bare(a) == bare(script))
    };
    (!steps.is_empty() && steps.iter().all(is_allowed)).then_some(steps)
}

/// The stage lines in `text`, in order: `arena-stage: NAME` for a stage,
/// `arena-stage: oem-failed WHY` for the OEM install's failure.
fn stages_named(text: &str) -> impl Iterator<Item = StageEvent> + '_ {
    text.lines().filter_map(|line| {
        let said = line.trim().strip_prefix(STAGE_LINE)?.trim();
        if let Some(why) = said.strip_prefix("oem-failed") {
            let why = why.trim();
            return Some(StageEvent::Failed(if why.is_empty() { "a step failed".to_owned() } else { why.to_owned() }));
        }
        Stage::from_name(said).map(StageEvent::Enter)
    })
}

fn last_serial_lines(text: &str) -> String {
    let lines: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
    if lines.is_empty() {
        return "the serial port said nothing".into();
    }
    format!("the serial port's last lines: {}", lines[lines.len().saturating_sub(5)..].join(" | "))
}

/// What a failed stage left in `failures/<stage>-<n>/` while QEMU still ran.
struct Evidence {
    folder: PathBuf,
    doctor: String,
    /// The Setup logs copied from the guest.
    logs: Vec<String>,
}

/// Keeps the serial and QEMU logs, a screendump, the doctor's report and the
/// Setup logs ([`bundle::SETUP_LOGS`]) of a failed stage in
/// `failures/<stage>-<n>/`, asking the guest while it answers; [`finish_evidence`]
/// reads the logs off the disk once QEMU is stopped if the guest gave none.
async fn keep_evidence(vm: &Vm, dir: &Path, stage: Stage) -> Option<Evidence> {
    let failures = dir.join("failures");
    let mut n = 1;
    let folder = loop {
        let candidate = failures.join(format!("{}-{n}", stage.name()));
        if !candidate.exists() {
            break candidate;
        }
        n += 1;
    };
    std::fs::create_dir_all(&folder).ok()?;
    let _ = std::fs::copy(dir.join("serial.log"), folder.join("serial.log"));
    let _ = std::fs::copy(dir.join("qemu.log"), folder.join("qemu.log"));
    let shot = folder.join("screendump.png");
    let _ = tokio::time::timeout(Duration::from_secs(10), vm.qmp.screendump(&shot)).await;
    // Whether the guest answers at all, before the slow questions.
    let answers = vm.client().with_timeout(Duration::from_secs(3)).health_once(Duration::from_secs(3)).await.is_ok();
    let mut doctor = String::new();
    let mut logs = Vec::new();
    if answers {
        logs = bundle::copy_logs_from_guest(&vm.client().with_timeout(Duration::from_secs(20)), &folder).await;
        if let Ok(Ok(report)) =
            tokio::time::timeout(Duration::from_secs(150), vm.client().with_timeout(Duration::from_secs(120)).doctor())
                .await
        {
            let text = serde_json::to_string_pretty(&report).unwrap_or_default();
            let _ = std::fs::write(folder.join("doctor.json"), &text);
            doctor = format!("\nthe guest's doctor report:\n{text}");
        }
    }
    Some(Evidence { folder, doctor, logs })
}

/// Completes the evidence once QEMU has stopped: the Setup logs off the disk
/// image when the guest gave none; the error names the folder and what it holds.
fn finish_evidence(evidence: Option<Evidence>, img: &QemuImg, disk: &Path, bundle: &Bundle, err: VmError) -> VmError {
    let Some(Evidence { folder, doctor, mut logs }) = evidence else { return err };
    let mut how = "from the guest".to_owned();
    let mut problems = Vec::new();
    if logs.is_empty() {
        (logs, problems) = bundle::copy_logs_off_disk(img, disk, &folder);
        how = "off the disk image".to_owned();
    }
    let logs = if logs.is_empty() {
        format!(
            "no Setup log could be read ({})",
            if problems.is_empty() { "none was on the disk yet".to_owned() } else { problems.join("; ") }
        )
    } else {
        format!("the Setup logs ({}) copied {how}", logs.join(", "))
    };
    bundle.note(&format!("evidence kept in {}: {logs}", folder.display()));
    VmError::Invalid(format!(
        "{err}{doctor}\n(the serial log, a screendump, {logs} and what the guest said are in {}; the whole install's timeline, screendumps and command lines are in {}; run the same command again: the install starts over from a blank disk)",
        folder.display(),
        folder.parent().and_then(Path::parent).unwrap_or(&folder).display()
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failure_is_let_through_only_when_every_failed_step_is_allowed() {
        let allow = |names: &[&str]| names.iter().map(|n| (*n).to_owned()).collect::<Vec<_>>();
        let one = r"prep-apps.ps1 (exit code 3); log C:\ProgramData\arena\logs\setup.log";
        assert_eq!(
            allowed_failure(one, &allow(&["prep-apps.ps1"])),
            Some(vec!["prep-apps.ps1 (exit code 3)".to_owned()])
        );
        assert_eq!(allowed_failure(one, &allow(&["PREP-APPS"])).map(|s| s.len()), Some(1), "case and .ps1 aside");
        assert_eq!(allowed_failure(one, &allow(&[])), None);
        assert_eq!(allowed_failure(one, &allow(&["prep-browser.ps1"])), None);
        let two = "prep-apps.ps1 (exit code 3), prep-office.ps1 (exit code 1); log setup.log";
        assert_eq!(allowed_failure(two, &allow(&["prep-apps.ps1"])), None, "one step not allowed holds it");
        let both = allowed_failure(two, &allow(&["prep-apps.ps1", "prep-office"])).unwrap();
        assert_eq!(both, vec!["prep-apps.ps1 (exit code 3)", "prep-office.ps1 (exit code 1)"]);
        // The stand-in's and an older script's line without a log.
        assert!(allowed_failure("prep-apps.ps1 (exit code 3)", &allow(&["prep-apps.ps1"])).is_some());
        assert_eq!(allowed_failure("a step failed", &allow(&["prep-apps.ps1"])), None);
    }

    #[test]
    fn stage_lines_are_read_once_and_only_when_whole() {
        use StageEvent::{Enter, Failed};
        let mut lines = StageLines::default();
        let mut log = String::from("boot\r\narena-stage: oobe\r\narena-stage: first-lo");
        assert_eq!(lines.take_new(&log), vec![Enter(Stage::Oobe)]);
        assert_eq!(lines.take_new(&log), vec![]);
        log.push_str("gon\r\nnoise arena-stage: setup\narena-stage: oem-install\n");
        assert_eq!(lines.take_new(&log), vec![Enter(Stage::FirstLogon), Enter(Stage::OemInstall)]);
        assert_eq!(lines.take_new(&log), vec![]);
        // The OEM install's end, or its failure naming the step.
        log.push_str(
            "arena-stage: oem-done\r\narena-stage: oem-failed prep-apps.ps1 (exit code 3)\r\narena-stage: oem-failed\n",
        );
        assert_eq!(
            lines.take_new(&log),
            vec![Enter(Stage::OemDone), Failed("prep-apps.ps1 (exit code 3)".into()), Failed("a step failed".into())]
        );
        // A new QEMU truncates the log: it is read from its start again.
        assert_eq!(lines.take_new("arena-stage: oobe\n"), vec![Enter(Stage::Oobe)]);
        let mut fresh = StageLines::default();
        assert_eq!(fresh.take_new("arena-stage: unknown\narena-stage:\n\n"), vec![]);
        assert!(!fresh.any && lines.any);
    }

    #[test]
    fn emulation_scales_the_deadlines_and_oem_done_waits_as_long_as_healthy() {
        let kvm = StageTimeouts::for_accel(Accel::Kvm);
        let tcg = StageTimeouts::for_accel(Accel::Tcg);
        assert_eq!(kvm, StageTimeouts::default());
        assert_eq!(tcg.get(Stage::Setup), kvm.get(Stage::Setup) * 4);
        assert_eq!(tcg.get(Stage::OemInstall), kvm.get(Stage::OemInstall) * 2);
        assert_eq!(Stage::OemDone.deadline(&kvm), kvm.get(Stage::Healthy));
        assert!(Stage::OemDone.mid_install() && Stage::OemInstall < Stage::OemDone && Stage::OemDone < Stage::Healthy);
        assert_eq!(Stage::from_name("oem-done"), Some(Stage::OemDone));
    }

    /// A leftover QEMU (here a shell named like one, its arguments naming a
    /// file of the folder as QEMU's options do) is found and ended; a process
    /// naming another folder is not touched.
    #[cfg(target_os = "linux")]
    #[test]
    fn leftovers_naming_the_folder_are_ended_and_no_other() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("golden.qcow2.prepare");
        let other = tmp.path().join("other").join("golden.qcow2.prepare");
        for folder in [&dir, &other] {
            std::fs::create_dir_all(folder).unwrap();
            std::fs::write(folder.join("disk.qcow2"), b"").unwrap();
        }
        let fake = tmp.path().join("qemu-system-x86_64");
        std::os::unix::fs::symlink("/bin/sh", &fake).unwrap();
        let start = |folder: &Path| {
            std::process::Command::new(&fake)
                .args(["-c", "while :; do sleep 1; done", "sh"])
                .arg(format!("file={},format=qcow2", folder.join("disk.qcow2").display()))
                .spawn()
                .unwrap()
        };
        let (mut ours, mut theirs) = (start(&dir), start(&other));
        // A child is only visible by its command line once it has exec'd: on a loaded
        // machine that comes after spawn() returns, so wait for it (bounded).
        for child in [&ours, &theirs] {
            let cmdline = format!("/proc/{}/cmdline", child.id());
            let exec_done = (0..500).any(|_| {
                let seen = std::fs::read(&cmdline).is_ok_and(|c| c.windows(11).any(|w| w == b"format=qcow"));
                if !seen {
                    std::thread::sleep(Duration::from_millis(10));
                }
                seen
            });
            assert!(exec_done, "the stand-in process {} never showed its command line", child.id());
        }
        let found = holders_of(&dir);
        assert_eq!(found, vec![(ours.id(), "qemu-system-x86_64".to_owned())]);
        end_leftovers(&dir);
        use std::os::unix::process::ExitStatusExt;
        assert_eq!(ours.wait().unwrap().signal(), Some(9), "SIGKILL");
        assert!(theirs.try_wait().unwrap().is_none(), "a process of another folder was ended");
        assert_eq!(holders_of(&other).len(), 1);
        theirs.kill().unwrap();
        theirs.wait().unwrap();
    }

    #[test]
    fn stage_timeouts_parse_and_name_what_is_wrong() {
        let mut t = StageTimeouts::default();
        t.set("setup=90m").unwrap();
        t.set("oem-install=2h").unwrap();
        t.set("shut-down=300").unwrap();
        assert_eq!(t.get(Stage::Setup), Duration::from_secs(5400));
        assert_eq!(t.get(Stage::OemInstall), Duration::from_secs(7200));
        assert_eq!(t.get(Stage::ShutDown), Duration::from_secs(300));
        for (bad, needle) in [
            ("setup", "STAGE=DURATION"),
            ("sealed=1m", "the stages are"),
            ("setup=1d", "a duration"),
            ("oobe=0", "a duration"),
        ] {
            let err = t.set(bad).unwrap_err();
            assert!(err.contains(needle), "{bad}: {err}");
        }
    }

    /// A resume in every stage: before the guest is healthy the install starts
    /// over (the VM tests kill a prepare in `setup` and at `healthy` for real).
    #[test]
    fn a_resume_in_each_stage_goes_on_only_from_a_safe_point() {
        for stage in [Stage::Setup, Stage::Oobe, Stage::FirstLogon, Stage::OemInstall] {
            for snapshot in [false, true] {
                let why = start_over_reason(stage, snapshot).unwrap_or_else(|| panic!("{stage:?}"));
                assert!(why.contains("starts over from a blank disk"), "{why}");
            }
        }
        assert_eq!(start_over_reason(Stage::Healthy, true), None);
        assert!(start_over_reason(Stage::Healthy, false).unwrap().contains("snapshot is missing"));
        for stage in [Stage::Created, Stage::ShutDown, Stage::Sealed] {
            assert_eq!(start_over_reason(stage, false), None, "{stage:?}");
        }
    }

    #[test]
    fn the_old_state_name_still_reads_and_stages_are_ordered() {
        let state: State = serde_json::from_str(r#"{"stage":"installing","iso":"/a.iso","oem":"/oem"}"#).unwrap();
        assert_eq!(state.stage, Stage::Setup);
        assert!(Stage::Setup < Stage::Oobe && Stage::OemInstall < Stage::Healthy);
        assert!(Stage::OemInstall.mid_install() && !Stage::Healthy.mid_install());
        for stage in TIMED_STAGES {
            assert_eq!(Stage::from_name(stage.name()), Some(*stage));
        }
    }

    #[test]
    fn a_virtio_disk_bus_needs_a_driver_folder() {
        use qemu::DiskBus;
        assert!(check_drivers(DiskBus::Ahci, None).is_ok());
        for (bus, driver) in [(DiskBus::VirtioBlk, "viostor"), (DiskBus::VirtioScsi, "vioscsi")] {
            let err = check_drivers(bus, None).unwrap_err().to_string();
            assert!(
                err.contains(driver) && err.contains("give --drivers DIR") && err.contains("--vm-disk-bus ahci"),
                "{err}"
            );
        }
        let dir = tempfile::tempdir().unwrap();
        assert!(check_drivers(DiskBus::VirtioBlk, Some(dir.path())).is_ok());
        let missing = dir.path().join("nope");
        let err = check_drivers(DiskBus::VirtioScsi, Some(&missing)).unwrap_err().to_string();
        assert!(err.contains("--drivers") && err.contains("not a folder"), "{err}");
    }

    #[test]
    fn media_and_command_lines_read_as_typed() {
        let args = media_args(
            Path::new("/w/autounattend.xml"),
            Path::new("/w/ARENA-OEM.TXT"),
            Path::new("/w/ARENA-OEM.CMD"),
            Path::new("/stage/oem"),
            None,
            Path::new("/w/oem-media.iso"),
        );
        let line = shell_line(Path::new("xorriso"), &args);
        assert_eq!(
            line,
            "xorriso -as mkisofs -quiet -iso-level 3 -J -joliet-long -r -V ARENA_OEM -o /w/oem-media.iso -graft-points autounattend.xml=/w/autounattend.xml ARENA-OEM.TXT=/w/ARENA-OEM.TXT ARENA-OEM.CMD=/w/ARENA-OEM.CMD OEM/=/stage/oem"
        );
        let with_drivers = media_args(
            Path::new("/w/autounattend.xml"),
            Path::new("/w/ARENA-OEM.TXT"),
            Path::new("/w/ARENA-OEM.CMD"),
            Path::new("/stage/oem"),
            Some(Path::new("/virtio-win")),
            Path::new("/w/oem-media.iso"),
        );
        assert!(
            shell_line(Path::new("xorriso"), &with_drivers).ends_with(" OEM/=/stage/oem '$WinPEDriver$/=/virtio-win'"),
            "{}",
            shell_line(Path::new("xorriso"), &with_drivers)
        );
        let quoted = shell_line(Path::new("qemu-system-x86_64"), &["a b".into(), "it's".into(), "".into()]);
        assert_eq!(quoted, r"qemu-system-x86_64 'a b' 'it'\''s' ''");
    }
}
