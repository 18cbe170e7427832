//! The diagnostic bundle `arena vm prepare` keeps in its folder whatever
//! happens, so that a first install on real hardware that fails (or is
//! interrupted) teaches everything it saw:
//!
//! - `timeline.log`: one line per event (a stage entered, a reboot, QEMU
//!   started, a screendump, a failure) with the wall clock and the seconds since
//!   the prepare started; `state.json` keeps the seconds spent in each stage;
//! - `serial.log` (the running QEMU's) and `serial-N.log` (each earlier QEMU's:
//!   QEMU truncates the file when it starts);
//! - `screens/NNN-STAGE.png`: a QMP screendump at every stage change and every
//!   [`SCREEN_EVERY`] in between, a flip-book of the install;
//! - `commands.txt`: the xorriso, swtpm and QEMU command lines of every start;
//! - `autounattend.xml`: the answer file (written there by prepare);
//! - on a failure, `failures/STAGE-N/`: the serial and QEMU logs, a screendump,
//!   the guest's doctor report when it answers, and the Setup logs
//!   ([`SETUP_LOGS`]): from the guest while it answers (`GET /v1/files`), else
//!   off the disk image once QEMU has stopped ([`copy_logs_off_disk`]).
//!
//! Every file is appended to or written whole as it happens, so a prepare killed
//! outright leaves what it had.

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant, SystemTime};

use super::disk::QemuImg;
use super::Vm;

/// How often a screendump is taken while nothing changes.
pub const SCREEN_EVERY: Duration = Duration::from_secs(180);

/// The logs copied on a failure, by their path on the Windows volume (`C:\`):
/// Windows Setup's (Microsoft's "Windows Setup log files and event logs": the
/// down-level phase under `$WINDOWS.~BT\Sources\Panther`, the installed system's
/// under `Windows\Panther`, specialize and OOBE under `Windows\Panther\UnattendGC`)
/// and the OEM install's.
pub const SETUP_LOGS: &[&str] = &[
    "$WINDOWS.~BT/Sources/Panther/setupact.log",
    "$WINDOWS.~BT/Sources/Panther/setuperr.log",
    "Windows/Panther/setupact.log",
    "Windows/Panther/setuperr.log",
    "Windows/Panther/UnattendGC/setupact.log",
    "Windows/Panther/UnattendGC/setuperr.log",
    "ProgramData/arena/logs/setup.log",
    "ProgramData/arena/logs/install.log",
    "ProgramData/arena/setup-status.json",
];

/// The bundle of one prepare run, in its folder.
#[derive(Debug)]
pub struct Bundle {
    dir: PathBuf,
    started: Instant,
    screens: u32,
    last_screen: Option<Instant>,
}

impl Bundle {
    /// The bundle in `dir` (the prepare's folder), its clock starting now.
    pub fn new(dir: &Path) -> Bundle {
        let screens = std::fs::read_dir(dir.join("screens")).map(|d| d.count() as u32).unwrap_or(0);
        Bundle { dir: dir.to_owned(), started: Instant::now(), screens, last_screen: None }
    }

    /// Appends one line to `timeline.log`.
    pub fn note(&self, what: &str) {
        let now = SystemTime::now().duration_since(SystemTime::UNIX_EPOCH).map(|d| d.as_secs()).unwrap_or(0);
        let line = format!(
            "{} +{:.1}s {what}\n",
            arena_shared::calendar::iso_seconds(i64::try_from(now).unwrap_or(0)),
            self.started.elapsed().as_secs_f64()
        );
        append(&self.dir.join("timeline.log"), line.as_bytes());
    }

    /// Appends a command line to `commands.txt`.
    pub fn command(&self, line: &str) {
        append(&self.dir.join("commands.txt"), format!("{line}\n").as_bytes());
    }

    /// Keeps the serial log of the QEMU that ran before as `serial-N.log`, so the
    /// next QEMU (which truncates `serial.log`) does not lose it.
    pub fn keep_serial(&self) {
        let serial = self.dir.join("serial.log");
        if std::fs::metadata(&serial).map(|m| m.len() == 0).unwrap_or(true) {
            return;
        }
        let mut n = 1;
        while self.dir.join(format!("serial-{n}.log")).exists() {
            n += 1;
        }
        if std::fs::rename(&serial, self.dir.join(format!("serial-{n}.log"))).is_ok() {
            self.note(&format!("the serial log so far is kept as serial-{n}.log"));
        }
    }

    /// A screendump into `screens/`, named by its number and `label`.
    pub async fn screendump(&mut self, vm: &Vm, label: &str) {
        let screens = self.dir.join("screens");
        if std::fs::create_dir_all(&screens).is_err() {
            return;
        }
        self.screens += 1;
        let path = screens.join(format!("{:03}-{label}.png", self.screens));
        match tokio::time::timeout(Duration::from_secs(10), vm.qmp.screendump(&path)).await {
            Ok(Ok(())) => {
                self.note(&format!("screendump screens/{}", path.file_name().unwrap_or_default().to_string_lossy()))
            }
            Ok(Err(err)) => self.note(&format!("no screendump: {err}")),
            Err(_) => self.note("no screendump: QEMU did not answer in 10 s"),
        }
        self.last_screen = Some(Instant::now());
    }

    /// A screendump when [`SCREEN_EVERY`] has passed since the last one.
    pub async fn screendump_if_due(&mut self, vm: &Vm, label: &str) {
        if self.last_screen.is_none_or(|at| at.elapsed() >= SCREEN_EVERY) {
            self.screendump(vm, label).await;
        }
    }
}

fn append(path: &Path, bytes: &[u8]) {
    if let Ok(mut file) = std::fs::OpenOptions::new().create(true).append(true).open(path) {
        let _ = file.write_all(bytes);
    }
}

/// Copies [`SETUP_LOGS`] from the guest while it answers, into `into`; the names copied.
pub async fn copy_logs_from_guest(client: &arena_client::client::GuestClient, into: &Path) -> Vec<String> {
    let mut copied = Vec::new();
    for log in SETUP_LOGS {
        let guest_path = format!("C:\\{}", log.replace('/', "\\"));
        if let Ok(Ok(file)) = tokio::time::timeout(Duration::from_secs(20), client.pull_file(&guest_path)).await {
            let local = into.join(local_name(log));
            if std::fs::write(&local, &file.bytes).is_ok() {
                copied.push((*log).to_owned());
            }
        }
    }
    copied
}

/// The file name a log is kept under: its path with `/` as `_`.
fn local_name(log: &str) -> String {
    log.replace(['/', '$', '~'], "_").trim_start_matches('_').to_owned()
}

/// A volume of the disk: where it starts and how long it is, in bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Volume {
    pub offset: u64,
    pub size: u64,
    pub kind: VolumeKind,
}

/// The file systems whose files are read off the disk.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum VolumeKind {
    Ntfs,
    Fat,
}

/// The volumes the first sectors of a disk describe: the disk itself when it
/// is one file system (a superfloppy, as the stand-in's), else the partitions
/// of its GPT or MBR (the layouts of [`super::unattend`]'s disk configuration)
/// whose boot sectors `sector_at` shows to be NTFS or FAT.
pub fn volumes(head: &[u8], disk_size: u64, sector_at: &mut dyn FnMut(u64) -> Option<Vec<u8>>) -> Vec<Volume> {
    if let Some(kind) = head.get(..512).and_then(volume_kind) {
        return vec![Volume { offset: 0, size: disk_size, kind }];
    }
    let mut parts: Vec<(u64, u64)> = Vec::new();
    if head.get(512..520) == Some(b"EFI PART".as_slice()) {
        let u64_at = |at: usize| head.get(at..at + 8).map(|b| u64::from_le_bytes(b.try_into().unwrap_or([0; 8])));
        let u32_at = |at: usize| head.get(at..at + 4).map(|b| u32::from_le_bytes(b.try_into().unwrap_or([0; 4])));
        let (Some(entries_lba), Some(count), Some(entry_size)) = (u64_at(512 + 72), u32_at(512 + 80), u32_at(512 + 84))
        else {
            return Vec::new();
        };
        for i in 0..u64::from(count.min(128)) {
            let at = usize::try_from(entries_lba * 512 + i * u64::from(entry_size)).unwrap_or(usize::MAX);
            let (Some(first), Some(last)) = (u64_at(at + 32), u64_at(at + 40)) else { break };
            if first > 0 && last >= first {
                parts.push((first * 512, (last - first + 1) * 512));
            }
        }
    } else if head.get(510..512) == Some([0x55, 0xAA].as_slice()) {
        for i in 0..4 {
            let entry = &head[446 + i * 16..462 + i * 16];
            let start = u64::from(u32::from_le_bytes([entry[8], entry[9], entry[10], entry[11]]));
            let sectors = u64::from(u32::from_le_bytes([entry[12], entry[13], entry[14], entry[15]]));
            if entry[4] != 0 && start > 0 && sectors > 0 {
                parts.push((start * 512, sectors * 512));
            }
        }
    }
    parts
        .into_iter()
        .filter_map(|(offset, size)| {
            let boot = sector_at(offset)?;
            volume_kind(&boot).map(|kind| Volume { offset, size, kind })
        })
        .collect()
}

/// NTFS or FAT, by the boot sector's OEM name and file system type fields.
fn volume_kind(boot: &[u8]) -> Option<VolumeKind> {
    if boot.len() < 512 || boot[510..512] != [0x55, 0xAA] {
        return None;
    }
    if &boot[3..11] == b"NTFS    " {
        return Some(VolumeKind::Ntfs);
    }
    if &boot[82..87] == b"FAT32" || &boot[54..59] == b"FAT16" || &boot[54..59] == b"FAT12" {
        return Some(VolumeKind::Fat);
    }
    None
}

/// Copies [`SETUP_LOGS`] off the disk image `disk` (QEMU stopped) into `into`,
/// without mounting anything or root: each NTFS or FAT volume of it
/// ([`volumes`]) is copied out sparsely as a raw file (`qemu-img convert` with
/// the raw driver's `offset` and `size`), the logs are read from it with
/// `mcopy` (mtools) for FAT or `ntfscat` (ntfs-3g) for NTFS, and the raw copy is
/// deleted. Returns the logs copied and what could not be done.
pub fn copy_logs_off_disk(img: &QemuImg, disk: &Path, into: &Path) -> (Vec<String>, Vec<String>) {
    let mut copied = Vec::new();
    let mut problems = Vec::new();
    let scratch = into.join("volume.raw");
    let disk_size = img.info(disk).map(|i| i.virtual_size).unwrap_or(0);
    let read = |offset: u64, size: u64, to: &Path| img.extract_raw(disk, offset, size, to);
    if let Err(err) = read(0, (2 << 20).min(disk_size.max(512)), &scratch) {
        return (copied, vec![format!("reading the disk's first sectors: {err}")]);
    }
    let head = std::fs::read(&scratch).unwrap_or_default();
    let mut sector_at = |offset: u64| {
        read(offset, 512, &scratch).ok()?;
        std::fs::read(&scratch).ok()
    };
    let found = volumes(&head, disk_size, &mut sector_at);
    if found.is_empty() {
        problems.push("no NTFS or FAT volume on the disk (Setup had not formatted it yet)".to_owned());
    }
    for volume in found {
        if let Err(err) = read(volume.offset, volume.size, &scratch) {
            problems.push(format!("copying the volume at {}: {err}", volume.offset));
            continue;
        }
        for log in SETUP_LOGS {
            let out = into.join(local_name(log));
            if out.exists() {
                continue;
            }
            let ok = match volume.kind {
                VolumeKind::Fat => Command::new("mcopy")
                    .arg("-n")
                    .arg("-i")
                    .arg(&scratch)
                    .arg(format!("::/{log}"))
                    .arg(&out)
                    .output()
                    .map(|o| o.status.success())
                    .map_err(|err| format!("mcopy (Debian's mtools) cannot run: {err}")),
                VolumeKind::Ntfs => Command::new("ntfscat")
                    .arg(&scratch)
                    .arg(format!("/{log}"))
                    .output()
                    .map_err(|err| format!("ntfscat (Debian's ntfs-3g) cannot run: {err}"))
                    .map(|o| o.status.success() && std::fs::write(&out, &o.stdout).is_ok()),
            };
            match ok {
                Ok(true) => copied.push((*log).to_owned()),
                Ok(false) => {
                    let _ = std::fs::remove_file(&out);
                }
                Err(why) => {
                    if !problems.contains(&why) {
                        problems.push(why);
                    }
                }
            }
        }
    }
    let _ = std::fs::remove_file(&scratch);
    (copied, problems)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn boot_sector(kind: &str) -> Vec<u8> {
        let mut s = vec![0u8; 512];
        s[510] = 0x55;
        s[511] = 0xAA;
        match kind {
            "ntfs" => s[3..11].copy_from_slice(b"NTFS    "),
            "fat32" => s[82..87].copy_from_slice(b"FAT32"),
            _ => {}
        }
        s
    }

    #[test]
    fn a_superfloppy_is_one_volume() {
        let v = volumes(&boot_sector("fat32"), 1 << 30, &mut |_| None);
        assert_eq!(v, vec![Volume { offset: 0, size: 1 << 30, kind: VolumeKind::Fat }]);
    }

    #[test]
    fn mbr_and_gpt_partitions_are_read_and_only_known_file_systems_kept() {
        // MBR: an active 100 MiB NTFS system partition and Windows after it (BIOS layout).
        let mut mbr = vec![0u8; 1 << 20];
        mbr[510] = 0x55;
        mbr[511] = 0xAA;
        for (i, (start, sectors)) in [(2048u32, 204_800u32), (206_848, 1_000_000)].iter().enumerate() {
            let e = 446 + i * 16;
            mbr[e + 4] = 0x07;
            mbr[e + 8..e + 12].copy_from_slice(&start.to_le_bytes());
            mbr[e + 12..e + 16].copy_from_slice(&sectors.to_le_bytes());
        }
        let mut asked = Vec::new();
        let found = volumes(&mbr, 1 << 40, &mut |offset| {
            asked.push(offset);
            Some(boot_sector("ntfs"))
        });
        assert_eq!(asked, vec![2048 * 512, 206_848 * 512]);
        assert_eq!(found[1], Volume { offset: 206_848 * 512, size: 1_000_000 * 512, kind: VolumeKind::Ntfs });

        // GPT: EFI (FAT32), MSR (no file system), Windows (NTFS), entries at LBA 2.
        let mut gpt = vec![0u8; 1 << 20];
        gpt[510] = 0x55;
        gpt[511] = 0xAA;
        gpt[512..520].copy_from_slice(b"EFI PART");
        gpt[512 + 72..512 + 80].copy_from_slice(&2u64.to_le_bytes());
        gpt[512 + 80..512 + 84].copy_from_slice(&128u32.to_le_bytes());
        gpt[512 + 84..512 + 88].copy_from_slice(&128u32.to_le_bytes());
        for (i, (first, last)) in [(2048u64, 206_847u64), (206_848, 239_615), (239_616, 999_999)].iter().enumerate() {
            let e = 1024 + i * 128;
            gpt[e + 32..e + 40].copy_from_slice(&first.to_le_bytes());
            gpt[e + 40..e + 48].copy_from_slice(&last.to_le_bytes());
        }
        let found = volumes(&gpt, 1 << 40, &mut |offset| {
            Some(match offset / 512 {
                2048 => boot_sector("fat32"),
                239_616 => boot_sector("ntfs"),
                _ => boot_sector("none"),
            })
        });
        let kinds: Vec<(u64, VolumeKind)> = found.iter().map(|v| (v.offset / 512, v.kind)).collect();
        assert_eq!(kinds, vec![(2048, VolumeKind::Fat), (239_616, VolumeKind::Ntfs)]);
        assert!(volumes(&vec![0u8; 4096], 1 << 30, &mut |_| None).is_empty());
    }

    #[test]
    fn logs_keep_distinct_local_names() {
        let names: std::collections::BTreeSet<String> = SETUP_LOGS.iter().map(|l| local_name(l)).collect();
        assert_eq!(names.len(), SETUP_LOGS.len());
        assert_eq!(local_name("Windows/Panther/setupact.log"), "Windows_Panther_setupact.log");
    }
}
