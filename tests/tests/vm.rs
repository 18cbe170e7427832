//! VMs under QEMU with the stand-in guest image (docs/vm-standin.md), under
//! software emulation: boot to healthy, snapshot, change, restore, screendump;
//! a run on two VMs with per-task resets that scores as a run on plain stub
//! guests while one VM's QEMU is killed mid-run; `vm prepare` from the
//! stand-in installer (which enforces Windows 11 Setup's rules), killed in
//! every stage (the stand-in held in the mid-install ones by its test hook)
//! and resumed to a sealed image, with a 1 GiB OEM payload; Setup's
//! refusals; `--dry-run`; the install on the UEFI machine with Secure Boot and
//! swtpm, and the sealed image's sidecar (a VM on other firmware refused at
//! once); the clock a restore puts back, set right by the fleet; the `ready`
//! snapshot waiting for a shell that settles late; `arena vm verify`'s report
//! and bundle; foreign VM folders;
//! and the errors bad input gets.
//!
//! Without the image or QEMU each test says `SKIPPED:` (counted by test.sh;
//! a failure with ARENA_REQUIRE_QEMU=1).

#![cfg(target_os = "linux")]

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use arena_client::client::{ClientConfig, GuestClient};
use arena_results::{read_episode, EPISODE_FILE, RESULT_FILE};
use arena_shared::exec::LaunchRequest;
use arena_test_support::{standin_image, workspace_binary};
use arena_vm::fleet::check_screen;
use arena_vm::qemu::{Accel, DiskBus, NicModel};
use arena_vm::{Boot, Vm, VmConfig, VmError, READY_SNAPSHOT};

/// The VM options every test uses: the stand-in's small machine, emulated.
const VM_FLAGS: &[&str] = &[
    "--vm-accel",
    "tcg",
    "--vm-memory",
    "512",
    "--vm-cpus",
    "1",
    "--vm-machine",
    "pc",
    "--vm-disk-bus",
    "virtio-blk",
    "--vm-nic",
    "virtio-net",
    "--vm-boot-timeout",
    "180",
];

fn config(golden: &Path, dir: &Path, name: &str) -> VmConfig {
    let mut config = VmConfig::new(golden, dir, name);
    config.accel = Some(Accel::Tcg);
    config.memory_mib = 512;
    config.cpus = 1;
    config.machine = "pc".into();
    config.disk_bus = DiskBus::VirtioBlk;
    config.nic = NicModel::VirtioNet;
    config.boot_timeout = Duration::from_secs(180);
    config
}

fn arena() -> Command {
    Command::new(workspace_binary("arena-host", "arena").expect("the arena binary"))
}

/// QEMU processes whose command line names `needle`.
fn qemus_naming(needle: &str) -> Vec<u32> {
    programs_naming(&["qemu-system"], needle)
}

/// Processes of any of `programs` whose command line names `needle`.
fn programs_naming(programs: &[&str], needle: &str) -> Vec<u32> {
    let mut pids = Vec::new();
    for entry in std::fs::read_dir("/proc").into_iter().flatten().flatten() {
        let Ok(pid) = entry.file_name().to_string_lossy().parse::<u32>() else { continue };
        let cmdline = std::fs::read(entry.path().join("cmdline")).unwrap_or_default();
        let text = String::from_utf8_lossy(&cmdline).replace('\0', " ");
        if programs.iter().any(|program| text.contains(program)) && text.contains(needle) {
            pids.push(pid);
        }
    }
    pids
}

fn kill(pid: u32) {
    let _ = Command::new("kill").arg("-KILL").arg(pid.to_string()).status();
}

fn wait_child(child: &mut Child, within: Duration) -> std::process::ExitStatus {
    let deadline = Instant::now() + within;
    loop {
        if let Some(status) = child.try_wait().expect("wait") {
            return status;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            panic!("the process did not exit within {within:?}");
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_vm_boots_snapshots_restores_and_shuts_down() {
    let Some(image) = standin_image("a_vm_boots_snapshots_restores_and_shuts_down") else { return };
    let dir = tempfile::tempdir().unwrap();
    let config = config(&image.golden, &dir.path().join("vm"), "t-boot");

    let mut vm = Vm::start(&config, Boot::Fresh).await.unwrap();
    vm.wait_healthy(config.boot_timeout, |_| {}).await.unwrap();
    vm.save_snapshot(READY_SNAPSHOT).await.unwrap();
    assert_eq!(vm.snapshots().await.unwrap(), vec![READY_SNAPSHOT.to_owned()]);

    // QEMU's own view of the screen agrees with the guest's screenshot, at the
    // size upstream's image has (the VGA's EDID offers it; BIOS path).
    let screen = check_screen(&vm).await.unwrap();
    assert!(!screen.dump_black, "{screen:?}");
    assert_eq!((screen.dump_width, screen.dump_height), (1440, 900), "{screen:?}");
    assert_eq!((screen.dump_width, screen.dump_height), (screen.guest_width, screen.guest_height), "{screen:?}");
    assert_eq!(screen.problem, None);

    // Change the guest: a file and a window.
    let client = vm.client().clone();
    let path = r"C:\Users\Docker\Desktop\after-snapshot.txt";
    client.push_file(path, b"changed".to_vec(), None).await.unwrap();
    let before = client.windows().await.unwrap().len();
    client.launch(&LaunchRequest { argv: vec!["notepad.exe".into()], shell: None }).await.unwrap();
    assert!(client.exists(path).await.unwrap().exists);
    assert_eq!(client.windows().await.unwrap().len(), before + 1);

    // Back to the snapshot: the changes are gone.
    let took = vm.restore_snapshot(READY_SNAPSHOT).await.unwrap();
    vm.wait_healthy(config.boot_timeout, |_| {}).await.unwrap();
    assert!(!client.exists(path).await.unwrap().exists, "the file written after the snapshot survived the restore");
    assert_eq!(client.windows().await.unwrap().len(), before);
    assert!(took < Duration::from_secs(60), "{took:?}");

    // A snapshot that does not exist is named, with the ones that do.
    let err = vm.restore_snapshot("nope").await.unwrap_err().to_string();
    assert!(err.contains("\"nope\" does not exist") && err.contains("(it has: ready)"), "{err}");

    assert!(vm.shutdown(Duration::from_secs(60)).await, "the guest did not power off on the ACPI button");
    assert!(qemus_naming(&dir.path().display().to_string()).is_empty());

    // The overlay keeps its snapshot; asking a cold start for another one fails before QEMU runs.
    let err = Vm::start(&config, Boot::FromSnapshot("other".into())).await.unwrap_err();
    assert!(matches!(err, VmError::NoSnapshot { .. }), "{err}");
}

/// A restore puts the guest's clock back to the snapshot's, and the fleet's
/// `sync_clock` (which `before_task` runs after every restore) sets it to the
/// host's and says by how much (`vm.clock` in `episode.json`).
///
/// Windows keeps the snapshot's wall time across `loadvm`; the stand-in's Linux
/// kernel under TCG does not (its TSC follows the host's clock), so its clock is
/// put an hour back before the snapshot is saved: the restore brings that hour
/// back, as it brings back the time Windows saved.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_restore_puts_the_clock_back_and_the_fleet_sets_it_right() {
    use arena_shared::clock::now_unix_ms;
    use arena_vm::fleet::sync_clock;
    const HOUR_MS: i64 = 3_600_000;
    let Some(image) = standin_image("a_restore_puts_the_clock_back_and_the_fleet_sets_it_right") else { return };
    let dir = tempfile::tempdir().unwrap();
    let config = config(&image.golden, &dir.path().join("vm"), "t-clock");
    let mut vm = Vm::start(&config, Boot::Fresh).await.unwrap();
    vm.wait_healthy(config.boot_timeout, |_| {}).await.unwrap();
    let client = vm.client().clone();

    client.set_clock(now_unix_ms() - HOUR_MS).await.unwrap();
    vm.save_snapshot(READY_SNAPSHOT).await.unwrap();
    // Set right again, then back to the snapshot: the hour comes back with it.
    client.set_clock(now_unix_ms()).await.unwrap();
    vm.restore_snapshot(READY_SNAPSHOT).await.unwrap();
    vm.wait_healthy(config.boot_timeout, |_| {}).await.unwrap();
    let behind = now_unix_ms() - client.clock().await.unwrap().unix_ms;
    assert!((HOUR_MS - 60_000..HOUR_MS + 60_000).contains(&behind), "the restored guest is {behind} ms behind");

    let sync = sync_clock(&client, "t-clock").await;
    assert_eq!(sync.error, None);
    let corrected = sync.corrected_ms.expect("a correction");
    assert!((HOUR_MS - 60_000..HOUR_MS + 60_000).contains(&corrected), "corrected {corrected} ms");
    let after = now_unix_ms() - client.clock().await.unwrap().unix_ms;
    assert!(after.abs() < 5_000, "the guest is still {after} ms off after the set");
    // Recorded as episode.json records it.
    assert_eq!(serde_json::to_value(&sync).unwrap()["corrected_ms"], serde_json::json!(corrected));
    assert!(vm.shutdown(Duration::from_secs(60)).await, "the guest did not power off on the ACPI button");
}

/// `image` as a read-only raw copy with `name` (holding `text`) added to its FAT volume:
/// the stand-in's test hooks on the boot disk.
fn golden_with(image: &Path, name: &str, text: &str, scratch: &Path) -> PathBuf {
    let raw = scratch.join("golden-hooked.raw");
    let made = Command::new("qemu-img").args(["convert", "-O", "raw"]).arg(image).arg(&raw).status().unwrap();
    assert!(made.success());
    let hook = scratch.join(name);
    std::fs::write(&hook, text).unwrap();
    let copied = Command::new("mcopy").arg("-i").arg(&raw).arg(&hook).arg(format!("::{name}")).output().unwrap();
    assert!(copied.status.success(), "mcopy: {}", String::from_utf8_lossy(&copied.stderr));
    let mut permissions = std::fs::metadata(&raw).unwrap().permissions();
    permissions.set_readonly(true);
    std::fs::set_permissions(&raw, permissions).unwrap();
    raw
}

/// The fleet saves `ready` only once the guest's desktop has settled: on a
/// stand-in whose shell settles late (its taskbar shows 20 s after the guest
/// starts, then 5 s of idle CPU), the guest answers healthy while its `shell`
/// component is still down, and the fleet's boot returns only once it is up.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_ready_snapshot_waits_for_a_shell_that_settles_late() {
    use arena_vm::fleet::{ResetPolicy, VmFleet};
    let Some(image) = standin_image("the_ready_snapshot_waits_for_a_shell_that_settles_late") else { return };
    let dir = tempfile::tempdir().unwrap();
    let golden = golden_with(&image.golden, "arena-standin-shell-seconds", "20\n", dir.path());
    let mut config = config(&golden, &dir.path().join("vms/vm-1"), "t-settle");
    config.host_port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let quick = || ClientConfig { token: None, timeout: Duration::from_secs(2), retries: 0 };
    let client = GuestClient::new(&format!("http://127.0.0.1:{}", config.host_port), quick()).unwrap();

    // Watch the guest while the fleet boots it: a healthy guest whose shell is not settled yet.
    let watch = tokio::spawn(async move {
        loop {
            if let Ok(report) = client.health().await {
                if report.gated_up() && report.shell().is_some_and(|s| !s.ok) {
                    return report;
                }
            }
            tokio::time::sleep(Duration::from_millis(250)).await;
        }
    });
    let fleet = VmFleet::boot(vec![config.clone()], ResetPolicy::PerTask).await.unwrap();
    if !watch.is_finished() {
        watch.abort();
        panic!("the guest was never seen healthy with its shell still settling");
    }
    let unsettled = watch.await.unwrap();
    let shell = unsettled.shell().unwrap();
    assert!(shell.detail.contains("taskbar is not shown yet") || shell.detail.contains("CPU"), "{shell:?}");

    // At once after the boot: the shell has settled, after the hook's 20 s.
    let client = GuestClient::new(&fleet.urls()[0], quick()).unwrap();
    let report = client.health().await.unwrap();
    let shell = report.shell().expect("the stand-in's guest reports its shell");
    assert!(shell.ok && shell.detail.starts_with("settled"), "{report:?}");
    assert!(report.uptime_ms >= 20_000, "ready came {} ms after the guest started", report.uptime_ms);
    fleet.stop().await;

    // --vm-settle is a floor on top of a settled shell.
    let mut vm = Vm::start(&config_with_dir(&config, &dir.path().join("floor")), Boot::Fresh).await.unwrap();
    vm.wait_healthy(config.boot_timeout, |_| {}).await.unwrap();
    let first = vm.wait_settled(Duration::ZERO, config.boot_timeout).await.unwrap();
    assert!(first.shell.as_deref().is_some_and(|s| s.starts_with("settled")), "{first:?}");
    let floored = vm.wait_settled(Duration::from_secs(3), config.boot_timeout).await.unwrap();
    assert!(floored.waited >= Duration::from_secs(3) && floored.settled_after < Duration::from_secs(3), "{floored:?}");
    vm.kill().await;
}

/// `arena vm verify` on the stand-in: it boots the image once, writes its report
/// (JSON and text) and the bundle, and removes its VM. The image's sidecar (a
/// copy's, with an evaluation licence 5 days from its end) is read and kept.
#[test]
fn verify_boots_the_image_once_and_writes_its_report_and_bundle() {
    use arena_vm::verify::{Verdict, VerifyReport, REPORT_JSON, REPORT_TEXT};
    let Some(image) = standin_image("verify_boots_the_image_once_and_writes_its_report_and_bundle") else { return };
    let dir = tempfile::tempdir().unwrap();
    let golden = dir.path().join("golden.qcow2");
    std::fs::copy(&image.golden, &golden).unwrap();
    let mut permissions = std::fs::metadata(&golden).unwrap().permissions();
    permissions.set_readonly(true);
    std::fs::set_permissions(&golden, permissions).unwrap();
    let now = arena_shared::clock::now_unix_ms() / 1000;
    let facts = arena_vm::sidecar::ImageFacts {
        format: arena_vm::sidecar::FORMAT,
        firmware: "bios".into(),
        secure_boot: false,
        screen: (1440, 900),
        machine: "pc".into(),
        disk_bus: DiskBus::VirtioBlk,
        nic: NicModel::VirtioNet,
        tpm: false,
        edition: Some("EnterpriseEval".into()),
        build: None,
        language: Some("en-US".into()),
        timezone: Some("UTC".into()),
        installed_unix: now - 85 * 86_400,
        licence_expires_unix: arena_vm::sidecar::licence_expiry(Some("EnterpriseEval"), now - 85 * 86_400),
        uefi_vars: None,
        startup_apps_off: Vec::new(),
        allowed_failed_steps: Vec::new(),
    };
    arena_vm::sidecar::write(&golden, &facts).unwrap();

    let out = dir.path().join("verify");
    let run = arena().args(["vm", "verify"]).arg(&golden).arg("--out").arg(&out).args(VM_FLAGS).output().unwrap();
    let stdout = String::from_utf8_lossy(&run.stdout);
    let stderr = String::from_utf8_lossy(&run.stderr);
    let report: VerifyReport = serde_json::from_slice(
        &std::fs::read(out.join(REPORT_JSON)).unwrap_or_else(|err| panic!("no report ({err}): {stdout}{stderr}")),
    )
    .unwrap();
    let verdict = |name: &str| report.check(name).unwrap_or_else(|| panic!("no {name} check: {report:?}")).verdict;
    for name in ["healthy", "settled", "screen", "clock", "doctor"] {
        assert_eq!(verdict(name), Verdict::Pass, "{name}: {report:?}");
    }
    // The stand-in has no watermark cache and no browser; its sidecar's licence ends in 5 days.
    assert_eq!(verdict("watermark"), Verdict::Warn, "{report:?}");
    assert!(matches!(verdict("browser-chrome"), Verdict::Warn | Verdict::Pass), "{report:?}");
    let licence = report.check("licence").unwrap();
    // Five days less the seconds the boot took: 4 or 5 whole days, by where the count rounds.
    let days = licence.detail.contains("4 days left") || licence.detail.contains("5 days left");
    assert!(licence.verdict == Verdict::Warn && days, "{licence:?}");
    assert!(report.check("defender").is_some());
    // Exit code and text follow the report.
    assert_eq!(run.status.success(), report.passed(), "{stdout}{stderr}");
    let text = std::fs::read_to_string(out.join(REPORT_TEXT)).unwrap();
    assert!(text.contains("PASS settled") && text.contains("WARN licence"), "{text}");
    assert!(stdout.contains("report: ") && stdout.contains(REPORT_TEXT), "{stdout}");
    // The bundle: every file it lists is there, with the screens and the logs; the VM is gone.
    for name in ["screendump.png", "screenshot.png", "health.json", "doctor.json", "sidecar.json", "serial.log"] {
        assert!(report.files.iter().any(|f| f == name), "{name} not listed: {:?}", report.files);
    }
    for name in &report.files {
        assert!(out.join(name).is_file(), "{name} listed but missing");
    }
    assert!(image_size(&out.join("screendump.png")) == (1440, 900));
    assert!(!out.join("vm").exists(), "the VM's folder is left");
    assert!(qemus_naming(&out.display().to_string()).is_empty(), "QEMU still runs");
}

fn image_size(png: &Path) -> (u32, u32) {
    let dump = arena_vm::ScreenDump::from_png(std::fs::read(png).unwrap()).unwrap();
    (dump.width, dump.height)
}

fn config_with_dir(config: &VmConfig, dir: &Path) -> VmConfig {
    let mut config = config.clone();
    config.dir = dir.to_owned();
    config.host_port = 0;
    config
}

fn stub_index() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tasks/stub/test_all.json")
}

/// Every file named `name` below `root`.
fn files_named(root: &Path, name: &str) -> Vec<PathBuf> {
    let mut found = Vec::new();
    let mut stack = vec![root.to_owned()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).into_iter().flatten().flatten() {
            let path = entry.path();
            if path.is_dir() {
                stack.push(path);
            } else if path.file_name().is_some_and(|n| n == name) {
                found.push(path);
            }
        }
    }
    found
}

/// The `result.txt` of every task under `root`, by `domain/task`.
fn results(root: &Path) -> std::collections::BTreeMap<String, String> {
    files_named(root, RESULT_FILE)
        .into_iter()
        .map(|path| {
            let task = path.parent().unwrap();
            let domain = task.parent().unwrap().file_name().unwrap().to_string_lossy();
            let key = format!("{domain}/{}", task.file_name().unwrap().to_string_lossy());
            (key, std::fs::read_to_string(&path).unwrap())
        })
        .collect()
}

fn episodes(root: &Path) -> Vec<arena_results::EpisodeResult> {
    files_named(root, EPISODE_FILE).iter().map(|path| read_episode(path).unwrap()).collect()
}

#[test]
fn a_run_on_two_vms_scores_as_on_stub_guests_and_rebuilds_a_killed_vm() {
    let Some(image) = standin_image("a_run_on_two_vms_scores_as_on_stub_guests_and_rebuilds_a_killed_vm") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let (plain, vms, vm_dir) = (dir.path().join("plain"), dir.path().join("vms"), dir.path().join("vm-dir"));

    let out = arena()
        .args(["run", "--stub-guests", "2", "--pauses", "fast", "--tasks"])
        .arg(stub_index())
        .arg("--out")
        .arg(&plain)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));

    let mut child = arena()
        .args(["run", "--vms", "2", "--reset", "per-task", "--pauses", "fast", "--tasks"])
        .arg(stub_index())
        .arg("--vm-image")
        .arg(&image.golden)
        .arg("--vm-dir")
        .arg(&vm_dir)
        .args(VM_FLAGS)
        .arg("--out")
        .arg(&vms)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Once the first task is done, kill VM 1's QEMU outright.
    let overlay = vm_dir.join("vm-1/overlay.qcow2").display().to_string();
    let deadline = Instant::now() + Duration::from_secs(300);
    let killed = loop {
        if !episodes(&vms).is_empty() {
            let pids = qemus_naming(&overlay);
            pids.iter().copied().for_each(kill);
            break !pids.is_empty();
        }
        assert!(Instant::now() < deadline, "no task finished in 300 s");
        assert!(child.try_wait().unwrap().is_none(), "the run ended before any task finished");
        std::thread::sleep(Duration::from_millis(200));
    };
    assert!(killed, "VM 1's QEMU was not found");
    let status = wait_child(&mut child, Duration::from_secs(600));
    let mut stderr = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut stderr).unwrap();
    assert!(status.success(), "{status}: {stderr}");

    // The same scores, task by task.
    let (expected, got) = (results(&plain), results(&vms));
    assert_eq!(expected.len(), 6, "{expected:?}");
    assert_eq!(got, expected);

    // Every task started from the snapshot; the killed VM was rebuilt and the
    // task it failed was tried again.
    let episodes = episodes(&vms);
    for ep in &episodes {
        let vm = ep.vm.as_ref().unwrap_or_else(|| panic!("{} has no vm record", ep.task_name));
        assert_eq!(vm.snapshot.as_deref(), Some(READY_SNAPSHOT), "{}", ep.task_name);
        assert!(vm.restore_ms > 0, "{}", ep.task_name);
        assert_eq!(ep.options.get("vm_reset").map(String::as_str), Some("per-task"));
    }
    assert!(
        episodes.iter().any(|ep| ep.attempt > 1 || ep.vm.as_ref().is_some_and(|v| v.rebuilt)),
        "no task shows the rebuild: {stderr}"
    );
    // Nothing is left running.
    assert!(qemus_naming(&vm_dir.display().to_string()).is_empty(), "QEMU still runs after the run");
}

/// The prepares run one at a time: each VM has the 4 GiB Windows 11 Setup asks
/// for, and a restored snapshot of one holds all of it in QEMU's memory.
static PREPARES: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn one_prepare_at_a_time() -> std::sync::MutexGuard<'static, ()> {
    PREPARES.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// The VM options of a prepare of the stand-in: what Windows 11 Setup asks of a
/// machine (4 GiB, 2 processors; the disk is --size), emulated.
/// (A test's own value of any of these options replaces this one.)
const PREPARE_FLAGS: &[&str] = &[
    "--vm-accel",
    "tcg",
    "--vm-memory",
    "4096",
    "--vm-cpus",
    "2",
    "--vm-machine",
    "pc",
    "--vm-disk-bus",
    "virtio-blk",
    "--vm-nic",
    "virtio-net",
];

/// An OEM folder as `arena prep stage` leaves it, as far as the stand-in reads
/// it, and an empty driver folder beside it (`drivers`).
fn oem_folder(root: &Path, token: &str) -> PathBuf {
    let oem = root.join("oem");
    std::fs::create_dir_all(&oem).unwrap();
    std::fs::create_dir_all(root.join("drivers")).unwrap();
    std::fs::write(oem.join(arena_vm::oem::TOKEN_NAME), format!("{token}\n")).unwrap();
    std::fs::write(oem.join("install.bat"), "@echo off\r\n").unwrap();
    oem
}

fn prepare_command(image: &arena_test_support::StandinImage, oem: &Path, out: &Path, extra: &[&str]) -> Command {
    let mut command = arena();
    command
        .args(["vm", "prepare", "--iso"])
        .arg(&image.installer)
        .arg("--oem")
        .arg(oem)
        .arg("--out")
        .arg(out)
        // Each option and value of PREPARE_FLAGS that `extra` does not give itself.
        .args(PREPARE_FLAGS.chunks(2).filter(|pair| !extra.contains(&pair[0])).flatten())
        // The stand-in needs no drivers, but prepare refuses a virtio bus without a folder of them.
        .arg("--drivers")
        .arg(oem.parent().unwrap_or(oem).join("drivers"))
        .args(["--stage-timeout", "setup=10m", "--stage-timeout", "shut-down=120"])
        .args(extra)
        .env_remove("ARENA_TOKEN")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    command
}

/// Reads a child's stdout line by line until `stop` says so; returns what it read.
fn read_until(child: &mut Child, mut stop: impl FnMut(&str) -> bool) -> String {
    use std::io::BufRead;
    let stdout = child.stdout.as_mut().unwrap();
    let mut reader = std::io::BufReader::new(stdout);
    let mut said = String::new();
    let mut line = String::new();
    while reader.read_line(&mut line).unwrap() > 0 {
        said.push_str(&line);
        if stop(&line) {
            break;
        }
        line.clear();
    }
    said
}

fn kill_and_reap(child: &mut Child, work: &Path) {
    child.kill().unwrap();
    child.wait().unwrap();
    nothing_left(work);
}

fn nothing_left(work: &Path) {
    // QEMU, swtpm and any qemu-img it started (snapshots, sealing) die with it
    // (PR_SET_PDEATHSIG): the signal is sent as it dies, so they are gone within
    // moments, and none keeps the disk's lock from the rerun.
    let gone = Instant::now() + Duration::from_secs(10);
    loop {
        let left = programs_naming(&["qemu-system", "qemu-img", "swtpm"], &work.display().to_string());
        if left.is_empty() {
            break;
        }
        assert!(Instant::now() < gone, "processes {left:?} outlived the killed prepare");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Waits until the serial log of a prepare says `what` (the stand-in holds
/// there, so it stays said); fails if prepare ends first.
fn wait_serial(child: &mut Child, work: &Path, what: &str) {
    let deadline = Instant::now() + Duration::from_secs(300);
    loop {
        let serial = std::fs::read_to_string(work.join("serial.log")).unwrap_or_default();
        if serial.contains(what) {
            return;
        }
        assert!(Instant::now() < deadline, "the serial port never said {what:?}: {serial}");
        assert!(child.try_wait().unwrap().is_none(), "prepare ended before the serial port said {what:?}");
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// The stand-in's test hook (docs/vm-standin.md): it stays in `stage`.
fn hold_in(oem: &Path, stage: &str) {
    std::fs::write(oem.join("arena-standin-hold"), format!("{stage}\n")).unwrap();
}

/// `name` copied out of the FAT volume of a (sealed) stand-in disk image; returns the copy.
fn file_in_image(image: &Path, name: &str, scratch: &Path) -> PathBuf {
    let raw = scratch.join("golden.raw");
    let made = Command::new("qemu-img").args(["convert", "-O", "raw"]).arg(image).arg(&raw).status().unwrap();
    assert!(made.success());
    let out = scratch.join("extracted");
    let copied = Command::new("mcopy")
        .arg("-n")
        .arg("-i")
        .arg(&raw)
        .arg(format!("::{name}"))
        .arg(&out)
        .output()
        .expect("mcopy (mtools) runs");
    assert!(copied.status.success(), "mcopy: {}", String::from_utf8_lossy(&copied.stderr));
    let _ = std::fs::remove_file(&raw);
    out
}

/// The whole install on the BIOS path with Setup's bypass keys, killed in
/// each stage: in `setup` (once the disk is written), `oobe`, `first-logon` and
/// `oem-install`, where the stand-in is held by its test hook (each rerun says
/// it starts over from a blank disk, with the OEM folder as it is now); once
/// the guest is healthy (the rerun goes on from the healthy snapshot); and while
/// a qemu-img of the shut-down stage works on the disk (it dies with prepare;
/// the rerun goes on from the shut-down stage and seals). The last install
/// carries a 1 GiB payload in the OEM folder that arrives in `C:\OEM` byte for
/// byte.
#[test]
fn prepare_is_killed_in_every_stage_and_the_reruns_seal_it() {
    let Some(image) = standin_image("prepare_is_killed_in_every_stage_and_the_reruns_seal_it") else {
        return;
    };
    let _one = one_prepare_at_a_time();
    let started = Instant::now();
    let dir = tempfile::tempdir().unwrap();
    let token = "7f".repeat(32);
    let oem = oem_folder(dir.path(), &token);
    let out = dir.path().join("golden.qcow2");
    let work = arena_vm::prepare::work_dir(&out);
    let status_says = |stage: &str| {
        let status = arena().args(["vm", "prepare", "--status", "--out"]).arg(&out).output().unwrap();
        let text = String::from_utf8_lossy(&status.stdout).into_owned();
        assert!(text.contains(&format!("stage {stage}")), "--status after the kill in {stage}: {text}");
    };

    // 1. Killed in Windows Setup (the stand-in's installer), held once it has
    // written the disk and before it reboots.
    hold_in(&oem, "setup");
    let mut run = prepare_command(&image, &oem, &out, &["--size", "64G"]).spawn().unwrap();
    let said = read_until(&mut run, |line| line.starts_with("stage setup"));
    wait_serial(&mut run, &work, "held in stage setup");
    kill_and_reap(&mut run, &work);
    assert!(!said.contains("starting over"), "{said}");
    status_says("setup");
    // The interrupted prepare left its bundle: the timeline, screendumps, the command
    // lines, the answer file and the serial log.
    assert_bundle(&work);

    // 2.-4. Each rerun starts over from a blank disk and is killed in the next
    // stage, which the guest said on the serial port and prepare on its stdout.
    let mut previous = "setup";
    for stage in ["oobe", "first-logon", "oem-install"] {
        hold_in(&oem, stage);
        let mut run = prepare_command(&image, &oem, &out, &["--size", "64G"]).spawn().unwrap();
        let said = read_until(&mut run, |line| line.starts_with(&format!("stage {stage}")));
        wait_serial(&mut run, &work, &format!("held in stage {stage}"));
        kill_and_reap(&mut run, &work);
        assert!(
            said.contains(&format!("starting over from stage {previous}")) && said.contains("blank disk"),
            "the rerun after the kill in {previous}: {said}"
        );
        status_says(stage);
        previous = stage;
    }
    let killed_mid_install = started.elapsed();

    // 5. No hold, and 1 GiB more in the OEM folder (not all zeros: zeros would
    // pass a broken copy of sparse files). The rerun starts over with the
    // folder as it is now, and is killed once the guest is healthy.
    std::fs::remove_file(oem.join("arena-standin-hold")).unwrap();
    let payload = oem.join("payload.bin");
    {
        use std::io::Write;
        let mut file = std::io::BufWriter::new(std::fs::File::create(&payload).unwrap());
        let mut block = vec![0u8; 1 << 20];
        for i in 0..1024u32 {
            for (j, byte) in block.iter_mut().enumerate().step_by(4096) {
                *byte = (i as usize ^ j) as u8;
            }
            block[..4].copy_from_slice(&i.to_le_bytes());
            file.write_all(&block).unwrap();
        }
    }
    let expected = sha256_of(&payload);
    let mut run = prepare_command(&image, &oem, &out, &["--size", "64G"]).spawn().unwrap();
    let said = read_until(&mut run, |line| line.starts_with("stage healthy") || line.starts_with("stage shut-down"));
    kill_and_reap(&mut run, &work);
    assert!(said.contains("starting over from stage oem-install") && said.contains("blank disk"), "{said}");
    for stage in ["stage oobe", "stage first-logon", "stage oem-install"] {
        assert!(said.contains(stage), "{stage} was not shown: {said}");
    }
    status_says("healthy");

    // 6. The rerun goes on from the healthy snapshot, shuts the guest down and
    // runs qemu-img on the disk (dropping the snapshot, then the sealing copy
    // of the 1 GiB): killed during the copy, which must die with it.
    let mut run = prepare_command(&image, &oem, &out, &["--size", "64G"]).spawn().unwrap();
    let deadline = Instant::now() + Duration::from_secs(300);
    let qemu_img = loop {
        // Not a quick `qemu-img info` or the snapshot's deletion: the sealing copy.
        let working = programs_naming(&["qemu-img"], &work.display().to_string()).into_iter().find(|pid| {
            let cmdline = std::fs::read(format!("/proc/{pid}/cmdline")).unwrap_or_default();
            cmdline.split(|b| *b == 0).any(|arg| arg == b"convert")
        });
        if let Some(pid) = working {
            break pid;
        }
        assert!(Instant::now() < deadline, "no qemu-img of the shut-down stage was seen");
        if let Some(status) = run.try_wait().unwrap() {
            let said = read_until(&mut run, |_| false);
            let mut err = String::new();
            std::io::Read::read_to_string(run.stderr.as_mut().unwrap(), &mut err).unwrap();
            panic!("prepare ended ({status}) before a qemu-img of it was seen: {said}\n{err}");
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    run.kill().unwrap();
    run.wait().unwrap();
    // Far sooner than it would finish the copy of 1 GiB on its own.
    let gone = Instant::now() + Duration::from_secs(5);
    while Path::new(&format!("/proc/{qemu_img}/exe")).exists() {
        assert!(Instant::now() < gone, "qemu-img {qemu_img} outlived prepare");
        std::thread::sleep(Duration::from_millis(20));
    }
    nothing_left(&work);
    let said = read_until(&mut run, |_| false);
    assert!(said.contains("stage healthy (resumed)") && !said.contains("starting over"), "{said}");
    status_says("shut-down");

    // 7. The last rerun goes on from the shut-down stage and seals the image.
    let third: Output = prepare_command(&image, &oem, &out, &["--size", "64G"]).output().unwrap();
    let said = String::from_utf8_lossy(&third.stdout);
    assert!(third.status.success(), "{said}\n{}", String::from_utf8_lossy(&third.stderr));
    assert!(said.contains("(resumed)") && !said.contains("starting over"), "{said}");
    assert!(said.contains("golden image ready"), "{said}");
    assert!(std::fs::metadata(&out).unwrap().permissions().readonly());
    let info = Command::new("qemu-img").args(["info", "--output=json"]).arg(&out).output().unwrap();
    assert!(!String::from_utf8_lossy(&info.stdout).contains("prepare-healthy"), "the snapshot was not dropped");

    // The payload arrived in C:\OEM intact; the answer file was on the media.
    assert_eq!(sha256_of(&file_in_image(&out, "OEM/payload.bin", dir.path())), expected);
    std::fs::remove_file(dir.path().join("extracted")).unwrap();
    let answer = std::fs::read_to_string(work.join("autounattend.xml")).unwrap();
    assert!(answer.contains("BypassTPMCheck"), "BIOS without a TPM needs the bypass keys");
    eprintln!(
        "prepare (BIOS, killed in setup, oobe, first-logon, oem-install, healthy and shut-down; 1 GiB OEM payload): {:.0} s, the four mid-install kills {:.0} s",
        started.elapsed().as_secs_f64(),
        killed_mid_install.as_secs_f64()
    );

    // The golden image boots into the installed guest, which wants the OEM token.
    let rt = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().unwrap();
    rt.block_on(async {
        let mut config = config(&out, &dir.path().join("vm"), "t-golden");
        config.token = Some(token.clone());
        let mut vm = Vm::start(&config, Boot::Fresh).await.unwrap();
        vm.wait_healthy(config.boot_timeout, |_| {}).await.unwrap();
        let anonymous =
            GuestClient::new(vm.url(), ClientConfig { token: None, timeout: Duration::from_secs(10), retries: 0 })
                .unwrap();
        let err = anonymous.folders().await.unwrap_err().to_string();
        assert!(err.contains("401"), "{err}");
        vm.client().folders().await.unwrap();
        vm.kill().await;
    });
}

/// `sha256sum` of a file (coreutils; the stand-in's build needs it too).
fn sha256_of(path: &Path) -> String {
    let out = Command::new("sha256sum").arg(path).output().expect("sha256sum runs");
    assert!(out.status.success());
    String::from_utf8_lossy(&out.stdout).split_whitespace().next().unwrap_or_default().to_owned()
}

/// What the stand-in's Windows Setup refuses, each with Setup's message, and
/// before the disk is written (so each fails in one short boot, not on a timeout).
#[test]
fn the_stand_in_setup_refuses_what_windows_setup_refuses() {
    let Some(image) = standin_image("the_stand_in_setup_refuses_what_windows_setup_refuses") else { return };
    let _one = one_prepare_at_a_time();
    let started = Instant::now();
    let dir = tempfile::tempdir().unwrap();
    let oem = oem_folder(dir.path(), &"7f".repeat(32));
    // The generated answer file, as --dry-run writes it, for the edited copies.
    let probe = dir.path().join("probe.qcow2");
    let dry = prepare_command(&image, &oem, &probe, &["--dry-run"]).output().unwrap();
    assert!(dry.status.success(), "{}", String::from_utf8_lossy(&dry.stderr));
    let generated = std::fs::read_to_string(arena_vm::prepare::work_dir(&probe).join("autounattend.xml")).unwrap();
    let without =
        |needle: &str| -> String { generated.lines().filter(|l| !l.contains(needle)).collect::<Vec<_>>().join("\n") };
    let no_bypass = dir.path().join("no-bypass.xml");
    std::fs::write(&no_bypass, without("LabConfig")).unwrap();
    let no_image = dir.path().join("no-image.xml");
    std::fs::write(&no_image, without("/IMAGE/INDEX")).unwrap();

    let cases: [(&str, Vec<&str>, &str); 4] = [
        ("no-tpm", vec!["--size", "64G", "--answer", no_bypass.to_str().unwrap()], "The PC must support TPM 2.0."),
        ("small-ram", vec!["--size", "64G", "--vm-memory", "2048"], "The PC must have at least 4 GB of memory."),
        ("small-disk", vec!["--size", "32G"], "The system disk must be 64 GB or larger."),
        (
            "no-image",
            vec!["--size", "64G", "--answer", no_image.to_str().unwrap()],
            "Select the operating system you want to install",
        ),
    ];
    for (name, extra, message) in cases {
        let out = dir.path().join(format!("{name}.qcow2"));
        let run = prepare_command(&image, &oem, &out, &extra).output().unwrap();
        let err = String::from_utf8_lossy(&run.stderr);
        assert!(!run.status.success(), "{name}: the prepare succeeded");
        assert!(err.contains("Windows Setup:") && err.contains(message), "{name}: {err}");
        assert!(err.contains("powered off during stage setup"), "{name}: {err}");
        assert!(!out.exists(), "{name}: an image was sealed");
    }
    eprintln!("four refusals: {:.0} s", started.elapsed().as_secs_f64());
}

/// `--dry-run` on any file named as an ISO: both command lines, each starting
/// with its program, and with UEFI the secure-boot code, SMM and a TPM on the
/// swtpm socket; everything it would attach is written, nothing runs.
#[test]
fn dry_run_writes_what_it_would_attach_and_prints_both_command_lines() {
    let Some(_image) = standin_image("dry_run_writes_what_it_would_attach_and_prints_both_command_lines") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let iso = dir.path().join("X.iso");
    std::fs::write(&iso, b"not really an ISO").unwrap();
    let oem = oem_folder(dir.path(), &"7f".repeat(32));
    let out = dir.path().join("golden.qcow2");
    let run = arena()
        .args(["vm", "prepare", "--dry-run", "--firmware", "uefi", "--iso"])
        .arg(&iso)
        .arg("--oem")
        .arg(&oem)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&run.stdout);
    assert!(run.status.success(), "{said}\n{}", String::from_utf8_lossy(&run.stderr));
    let lines: Vec<&str> = said.lines().collect();
    assert_eq!(lines.len(), 2, "{said}");
    assert!(lines[0].starts_with("swtpm socket --tpm2"), "{said}");
    let swtpm_socket = arena_vm::prepare::work_dir(&out).join("swtpm.sock");
    assert!(lines[0].contains(&format!("type=unixio,path={}", swtpm_socket.display())), "{said}");
    let q = lines[1];
    assert!(q.starts_with("qemu-system-x86_64 "), "{said}");
    assert!(q.contains(",smm=on") && q.contains("OVMF_CODE_4M.secboot.fd") && q.contains("property=secure,value=on"));
    assert!(q.contains(&format!("-chardev socket,id=chrtpm,path={}", swtpm_socket.display())), "{q}");
    assert!(q.contains("-tpmdev emulator,id=tpm0,chardev=chrtpm -device tpm-tis,tpmdev=tpm0"), "{q}");
    let work = arena_vm::prepare::work_dir(&out);
    for file in ["autounattend.xml", "oem-media.iso", "uefi-vars.qcow2"] {
        assert!(work.join(file).is_file(), "{file} was not written");
    }
    // With TPM and Secure Boot there are no bypass keys; the disk is GPT.
    let answer = std::fs::read_to_string(work.join("autounattend.xml")).unwrap();
    assert!(!answer.contains("LabConfig") && answer.contains("<Type>EFI</Type>"), "{answer}");
    // The guest's zone is UTC (the default --timezone): the RTC is UTC, not the host's local time.
    assert!(q.contains(" -rtc base=utc ") && !q.contains("localtime"), "{q}");
    // Defender's path exclusions for the guest's folders and C:\OEM, by policy in specialize.
    for folder in [r"C:\Program Files\Arena", r"C:\ProgramData\arena", r"C:\OEM"] {
        let line = format!(
            r#"reg.exe add &quot;HKLM\SOFTWARE\Policies\Microsoft\Windows Defender\Exclusions\Paths&quot; /v &quot;{folder}&quot; /t REG_DWORD /d 0 /f"#
        );
        assert!(answer.contains(&line), "{line} is not in the answer file");
    }
    assert!(answer.contains("/v Exclusions_Paths /t REG_DWORD /d 1 /f"), "{answer}");
    assert!(!out.exists() && qemus_naming(&dir.path().display().to_string()).is_empty());
}

/// The whole install on the UEFI path, as a Windows 11 machine has it: q35 with
/// its AHCI CD-ROMs, OVMF's secure-boot build with Microsoft's keys, SMM, locked
/// flash and a TPM 2.0 from swtpm, so the answer file needs no bypass keys. The
/// stand-in boots with Secure Boot on through Debian's signed shim, GRUB and
/// kernel, from the installer CD and then from the disk; the sealed image boots
/// healthy on the same machine with a fresh TPM.
#[test]
fn prepare_on_uefi_with_secure_boot_and_swtpm_seals_an_image_that_boots_healthy() {
    const TEST: &str = "prepare_on_uefi_with_secure_boot_and_swtpm_seals_an_image_that_boots_healthy";
    let Some(image) = standin_image(TEST) else {
        return;
    };
    let uefi = match arena_vm::Uefi::debian_secure_boot() {
        Ok(uefi) => uefi,
        Err(err) => {
            arena_test_support::skip(TEST, &format!("no secure-boot UEFI firmware: {err}"), "ARENA_REQUIRE_QEMU");
            return;
        }
    };
    let _one = one_prepare_at_a_time();
    let started = Instant::now();
    let dir = tempfile::tempdir().unwrap();
    let token = "5e".repeat(32);
    let oem = oem_folder(dir.path(), &token);
    let out = dir.path().join("golden.qcow2");
    let work = arena_vm::prepare::work_dir(&out);
    let done: Output =
        prepare_command(&image, &oem, &out, &["--size", "64G", "--firmware", "uefi", "--vm-machine", "q35"])
            .output()
            .unwrap();
    let said = String::from_utf8_lossy(&done.stdout);
    let serial = std::fs::read_to_string(work.join("serial.log")).unwrap_or_default();
    assert!(done.status.success(), "{said}\n{}\n{serial}", String::from_utf8_lossy(&done.stderr));
    assert!(said.contains("golden image ready"), "{said}");
    for stage in ["stage oobe", "stage first-logon", "stage oem-install"] {
        assert!(said.contains(stage), "{stage} was not shown: {said}");
    }
    let answer = std::fs::read_to_string(work.join("autounattend.xml")).unwrap();
    assert!(!answer.contains("LabConfig"), "a TPM and Secure Boot need no bypass keys");
    eprintln!("prepare (UEFI, Secure Boot, swtpm): {:.0} s", started.elapsed().as_secs_f64());

    // The image knows itself: the sidecar says how it was installed, the final
    // UEFI variables sit beside it, and a VM on other firmware is refused at once.
    let facts = arena_vm::sidecar::read(&out).unwrap().expect("the sealed image's sidecar");
    assert_eq!((facts.firmware.as_str(), facts.secure_boot, facts.tpm), ("uefi", true, true), "{facts:?}");
    assert_eq!((facts.machine.as_str(), facts.disk_bus, facts.screen), ("q35", DiskBus::VirtioBlk, (1440, 900)));
    assert_eq!((facts.language.as_deref(), facts.timezone.as_deref()), (Some("en-US"), Some("UTC")));
    assert!(facts.installed_unix > 1_700_000_000, "{facts:?}");
    // The start-up apps the answer file turned off, so the first desktop settles.
    for what in ["AutoDownload=2", "AllowNewsAndInterests", "OneDrive"] {
        assert!(facts.startup_apps_off.iter().any(|s| s.contains(what)), "{what}: {:?}", facts.startup_apps_off);
    }
    let vars = facts.uefi_vars.clone().expect("the UEFI variables' copy");
    assert!(vars.is_file() && vars.parent() == out.parent(), "{vars:?}");
    let asked = Instant::now();
    let refused = arena()
        .args(["vm", "start", "--image"])
        .arg(&out)
        .arg("--dir")
        .arg(dir.path().join("vm-bios"))
        .args(VM_FLAGS.chunks(2).filter(|pair| pair[0] != "--vm-machine").flatten())
        .args(["--vm-machine", "q35", "--port", "0"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success(), "a UEFI image booted on SeaBIOS: {err}");
    assert!(err.contains("use --vm-firmware uefi") && err.contains("golden.qcow2.arena.json"), "{err}");
    assert!(asked.elapsed() < Duration::from_secs(30), "refused only after {:?}", asked.elapsed());
    assert!(!dir.path().join("vm-bios").exists(), "the refused VM's folder was made");

    // The sealed image boots healthy on the UEFI machine, with Secure Boot on.
    let rt = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().unwrap();
    rt.block_on(async {
        let mut config = config(&out, &dir.path().join("vm"), "t-uefi");
        config.machine = "q35".into();
        config.uefi = Some(uefi);
        config.tpm = true;
        config.token = Some(token.clone());
        let mut vm = Vm::start(&config, Boot::Fresh).await.unwrap();
        assert!(vm.spec.args().iter().any(|a| a.to_string_lossy().contains("smm=on")));
        // The image's zone is UTC (its sidecar says so): the RTC is UTC too.
        assert!(vm.spec.args().iter().any(|a| a == "base=utc"), "{:?}", vm.spec.args());
        let tpm = vm.qmp.hmp("info tpm", Duration::from_secs(10)).await.unwrap();
        assert!(tpm.contains("tpm-tis") && tpm.contains("emulator"), "{tpm}");
        vm.wait_healthy(config.boot_timeout, |_| {}).await.unwrap();
        vm.client().folders().await.unwrap();
        // The screen under UEFI is the one asked for, as under BIOS.
        let dump = vm.screendump().await.unwrap();
        assert_eq!((dump.width, dump.height), (1440, 900));
        assert!(!dump.black);
        vm.kill().await;
    });
    let booted = std::fs::read_to_string(dir.path().join("vm/serial.log")).unwrap();
    assert!(booted.contains("firmware: UEFI, Secure Boot on"), "{booted}");
    assert!(dir.path().join("vm/tpm").is_dir() && dir.path().join("vm").join(arena_vm::UEFI_VARS_FILE).is_file());
    // Setup saw the TPM and Secure Boot it asks for, not bypass keys.
    assert!(serial.contains("firmware: UEFI, Secure Boot on"), "{serial}");
    assert!(serial.contains("TPM 2.0 present"), "{serial}");
}

/// A VM folder that holds anything and is not ours is refused before anything
/// in it changes (`arena vm start --dir`, `arena run --vm-dir`).
#[test]
fn a_foreign_folder_is_never_used_as_a_vm_folder() {
    let Some(image) = standin_image("a_foreign_folder_is_never_used_as_a_vm_folder") else { return };
    let dir = tempfile::tempdir().unwrap();
    let foreign = dir.path().join("mine");
    std::fs::create_dir_all(&foreign).unwrap();
    for name in ["overlay.qcow2", "qmp.sock", "control.sock", "qemu.log", "serial.log"] {
        std::fs::write(foreign.join(name), b"precious").unwrap();
    }
    let start = arena()
        .args(["vm", "start", "--dir"])
        .arg(&foreign)
        .arg("--image")
        .arg(&image.golden)
        .args(VM_FLAGS)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&start.stderr);
    assert!(!start.status.success() && err.contains("is not a VM folder of arena's"), "{err}");
    let run = arena()
        .args(["run", "--vms", "1", "--tasks"])
        .arg(stub_index())
        .arg("--vm-image")
        .arg(&image.golden)
        .arg("--vm-dir")
        .arg(&foreign)
        .args(VM_FLAGS)
        .arg("--out")
        .arg(dir.path().join("out"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success() && err.contains("is not a VM folder of arena's"), "{err}");
    for name in ["overlay.qcow2", "qmp.sock", "control.sock", "qemu.log", "serial.log"] {
        assert_eq!(std::fs::read(foreign.join(name)).unwrap(), b"precious", "{name} was changed");
    }
    assert!(!foreign.join(arena_vm::DIR_MARKER).exists());
    // An empty folder becomes ours.
    let empty = dir.path().join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    arena_vm::claim_dir(&empty).unwrap();
    assert!(empty.join(arena_vm::DIR_MARKER).is_file());
    assert!(qemus_naming(&dir.path().display().to_string()).is_empty());
}

#[test]
fn bad_input_gets_errors_that_name_it() {
    let Some(image) = standin_image("bad_input_gets_errors_that_name_it") else { return };
    let dir = tempfile::tempdir().unwrap();
    let start = |image: &Path, extra: &[&str]| -> String {
        let out = arena()
            .args(["vm", "start", "--dir"])
            .arg(dir.path().join("vm"))
            .arg("--image")
            .arg(image)
            .args(VM_FLAGS)
            .args(extra)
            .output()
            .unwrap();
        assert!(!out.status.success());
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let missing = start(&dir.path().join("nope.qcow2"), &[]);
    assert!(missing.contains("nope.qcow2") && missing.contains("cannot be read"), "{missing}");

    let writable = dir.path().join("writable.qcow2");
    std::fs::copy(&image.golden, &writable).unwrap();
    let mut perms = std::fs::metadata(&writable).unwrap().permissions();
    #[allow(clippy::permissions_set_readonly_false)]
    perms.set_readonly(false);
    std::fs::set_permissions(&writable, perms).unwrap();
    let err = start(&writable, &[]);
    assert!(err.contains("is writable") && err.contains("chmod a-w"), "{err}");
    // `arena vm verify` boots the image as `start` does: the same refusal, and no VM folder is left.
    let verify_out = dir.path().join("verify");
    let refused =
        arena().args(["vm", "verify"]).arg(&writable).arg("--out").arg(&verify_out).args(VM_FLAGS).output().unwrap();
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success() && err.contains("is writable"), "{err}");
    assert!(!verify_out.join("vm").join(arena_vm::OVERLAY_FILE).exists(), "{err}");

    let err = start(&image.golden, &["--vm-settle", "5000"]);
    assert!(err.contains("--vm-settle") && err.contains("0 to 3600"), "{err}");

    let err = start(&image.golden, &["--qemu", "/nonexistent/qemu-system-x86_64"]);
    assert!(err.contains("/nonexistent/qemu-system-x86_64") && err.contains("qemu-system-x86"), "{err}");

    let held = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = held.local_addr().unwrap().port().to_string();
    let err = start(&image.golden, &["--port", &port]);
    assert!(err.contains(&format!("port {port}")) && err.contains("already in use"), "{err}");

    // An overlay whose golden image moved.
    let golden = dir.path().join("g.qcow2");
    std::fs::copy(&image.golden, &golden).unwrap();
    let vm_dir = dir.path().join("vm");
    std::fs::create_dir_all(&vm_dir).unwrap();
    let made = Command::new("qemu-img")
        .args(["create", "-q", "-f", "qcow2", "-F", "qcow2", "-b"])
        .arg(&golden)
        .arg(vm_dir.join("overlay.qcow2"))
        .status()
        .unwrap();
    assert!(made.success());
    std::fs::rename(&golden, dir.path().join("moved.qcow2")).unwrap();
    let err = start(&image.golden, &["--reuse"]);
    assert!(err.contains("g.qcow2") && err.contains("does not exist"), "{err}");

    // An image whose sidecar says it was installed on UEFI, started on SeaBIOS:
    // refused at once, naming the flag, before its VM folder is made.
    let sided = dir.path().join("sided.qcow2");
    std::fs::copy(&image.golden, &sided).unwrap();
    let mut perms = std::fs::metadata(&sided).unwrap().permissions();
    perms.set_readonly(true);
    std::fs::set_permissions(&sided, perms).unwrap();
    let facts = arena_vm::sidecar::ImageFacts {
        format: arena_vm::sidecar::FORMAT,
        firmware: "uefi".into(),
        secure_boot: true,
        screen: (1440, 900),
        machine: "pc".into(),
        disk_bus: DiskBus::VirtioBlk,
        nic: NicModel::VirtioNet,
        tpm: false,
        edition: None,
        build: None,
        language: None,
        timezone: Some("UTC".into()),
        installed_unix: 1_790_000_000,
        licence_expires_unix: None,
        uefi_vars: None,
        startup_apps_off: Vec::new(),
        allowed_failed_steps: Vec::new(),
    };
    arena_vm::sidecar::write(&sided, &facts).unwrap();
    let asked = Instant::now();
    let start_sided = || {
        arena()
            .args(["vm", "start", "--dir"])
            .arg(dir.path().join("vm-sided"))
            .arg("--image")
            .arg(&sided)
            .args(VM_FLAGS)
            .output()
            .unwrap()
    };
    let out = start_sided();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("installed on uefi firmware, this VM has bios: use --vm-firmware uefi"),
        "{err}"
    );
    assert!(asked.elapsed() < Duration::from_secs(30) && !dir.path().join("vm-sided").exists(), "{err}");
    std::fs::write(arena_vm::sidecar::path_for(&sided), "{\"format\": 1}").unwrap();
    let out = start_sided();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("sided.qcow2.arena.json: not an image sidecar"), "{err}");

    // Commands for a VM that is not running.
    let out = arena().args(["vm", "restore", "--dir"]).arg(dir.path().join("none")).arg("ready").output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("no VM runs in"), "{err}");

    // Nothing was started by any of them.
    assert!(qemus_naming(&dir.path().display().to_string()).is_empty());
}

/// The diagnostic bundle every prepare keeps in its folder (docs/vm.md): the
/// timeline with stage timings, at least one screendump, the command lines of
/// xorriso and QEMU, the answer file and the serial log.
fn assert_bundle(work: &Path) {
    let timeline = std::fs::read_to_string(work.join("timeline.log")).expect("timeline.log");
    assert!(timeline.contains("stage setup") && timeline.contains("starting QEMU"), "{timeline}");
    // Each line has the clock and the seconds since the start.
    assert!(timeline.lines().all(|l| l.contains(" +") && l.contains("s ")), "{timeline}");
    let screens: Vec<_> = std::fs::read_dir(work.join("screens")).expect("screens/").flatten().collect();
    assert!(!screens.is_empty(), "no screendump in screens/");
    for shot in &screens {
        let png = std::fs::read(shot.path()).unwrap();
        assert!(png.starts_with(b"\x89PNG"), "{:?}", shot.path());
    }
    let commands = std::fs::read_to_string(work.join("commands.txt")).expect("commands.txt");
    assert!(commands.lines().any(|l| l.starts_with("xorriso ")), "{commands}");
    assert!(commands.lines().any(|l| l.starts_with("qemu-system-x86_64 ")), "{commands}");
    assert!(work.join("autounattend.xml").is_file() && work.join("serial.log").is_file());
}

/// The stand-in's test hooks for the OEM install (docs/vm-standin.md): the
/// steps after the guest's install take `seconds`; with `fail`, that step fails.
fn oem_hooks(oem: &Path, seconds: u32, fail: Option<&str>) {
    std::fs::write(oem.join("arena-standin-oem-seconds"), format!("{seconds}\n")).unwrap();
    let fail_file = oem.join("arena-standin-oem-fail");
    match fail {
        Some(step) => std::fs::write(&fail_file, format!("{step}\n")).unwrap(),
        None => {
            let _ = std::fs::remove_file(&fail_file);
        }
    }
}

/// The seal waits for the OEM install: the stand-in's guest answers healthy
/// within seconds of its first logon, while the rest of its OEM install holds
/// for 40 s more (as the app downloads of a real one do, with the guest
/// already up). Prepare must wait for `arena-stage: oem-done` and for the
/// guest's `setup` component, and seal after it: the sealed image's setup
/// record says the setup finished. The old prepare, which sealed once every
/// component was up, sealed during the hold: its image's record said running.
#[test]
fn prepare_seals_only_after_the_oem_install_says_it_is_done() {
    let Some(image) = standin_image("prepare_seals_only_after_the_oem_install_says_it_is_done") else { return };
    let _one = one_prepare_at_a_time();
    let started = Instant::now();
    let dir = tempfile::tempdir().unwrap();
    let token = "6a".repeat(32);
    let oem = oem_folder(dir.path(), &token);
    oem_hooks(&oem, 40, None);
    let out = dir.path().join("golden.qcow2");
    let work = arena_vm::prepare::work_dir(&out);
    let mut run = prepare_command(&image, &oem, &out, &["--size", "64G"]).spawn().unwrap();
    // The guest answers healthy during the hold, with its setup component down.
    let said = read_until(&mut run, |line| line.starts_with("stage oem-install"));
    let client = GuestClient::new(
        &format!("http://127.0.0.1:{}", forwarded_port(&work)),
        ClientConfig { token: Some(token.clone()), timeout: Duration::from_secs(3), retries: 0 },
    )
    .unwrap();
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    let during = rt.block_on(async {
        let deadline = Instant::now() + Duration::from_secs(120);
        loop {
            if let Ok(report) = client.health().await {
                let others_up = report
                    .components
                    .iter()
                    .filter(|c| c.component != arena_shared::health::Component::Setup)
                    .all(|c| c.ok);
                if others_up {
                    return report;
                }
            }
            assert!(Instant::now() < deadline, "the guest never answered during the OEM install");
            tokio::time::sleep(Duration::from_millis(500)).await;
        }
    });
    let setup = during.components.iter().find(|c| c.component == arena_shared::health::Component::Setup).unwrap();
    assert!(!setup.ok && setup.detail.contains("setup running"), "{setup:?}");
    let status = wait_child(&mut run, Duration::from_secs(600));
    let rest = read_until(&mut run, |_| false);
    let said = format!("{said}{rest}");
    let mut err = String::new();
    std::io::Read::read_to_string(run.stderr.as_mut().unwrap(), &mut err).unwrap();
    assert!(status.success(), "{said}\n{err}");
    let done_at = said.find("stage oem-done").unwrap_or_else(|| panic!("no oem-done stage: {said}"));
    let healthy_at = said.find("stage healthy").unwrap_or_else(|| panic!("no healthy stage: {said}"));
    assert!(done_at < healthy_at, "{said}");
    // The sealed image holds the finished setup's record.
    let record = std::fs::read(file_in_image(&out, "ProgramData/arena/setup-status.json", dir.path())).unwrap();
    let record = arena_shared::health::SetupProgress::parse(&record).unwrap();
    assert_eq!(record.state, arena_shared::health::SetupState::Done, "{record:?}");
    let timeline = std::fs::read_to_string(work.join("timeline.log")).unwrap();
    assert!(timeline.contains("stage oem-done") && timeline.contains("setup finished"), "{timeline}");
    assert_bundle(&work);
    eprintln!("prepare with a 40 s OEM hold (BIOS): {:.0} s", started.elapsed().as_secs_f64());
}

/// The host port a running prepare's QEMU forwards to the guest, from its command line.
fn forwarded_port(work: &Path) -> u16 {
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        let commands = std::fs::read_to_string(work.join("commands.txt")).unwrap_or_default();
        if let Some(port) = commands
            .lines()
            .rev()
            .find_map(|l| l.split("hostfwd=tcp:127.0.0.1:").nth(1))
            .and_then(|rest| rest.split('-').next())
            .and_then(|p| p.parse().ok())
        {
            return port;
        }
        assert!(Instant::now() < deadline, "no QEMU command line in commands.txt");
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// A failed OEM step is a failed prepare that names the step; the folder holds
/// the bundle and the failure's evidence, with the stand-in's Setup logs and the
/// OEM install's log copied off the disk image. Run again with
/// `--allow-failed-step` for that step, it seals, and the sidecar records it.
#[test]
fn a_failed_oem_step_fails_prepare_naming_it_and_keeps_the_logs() {
    let Some(image) = standin_image("a_failed_oem_step_fails_prepare_naming_it_and_keeps_the_logs") else { return };
    let _one = one_prepare_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let oem = oem_folder(dir.path(), &"5b".repeat(32));
    oem_hooks(&oem, 2, Some("prep-apps.ps1"));
    let out = dir.path().join("golden.qcow2");
    let work = arena_vm::prepare::work_dir(&out);
    let run = prepare_command(&image, &oem, &out, &["--size", "64G"]).output().unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success(), "the prepare succeeded");
    assert!(err.contains("the OEM install failed") && err.contains("prep-apps.ps1 (exit code 3)"), "{err}");
    assert!(err.contains("copied off the disk image"), "{err}");
    assert!(!out.exists());
    let failure = work.join("failures").join("oem-install-1");
    for file in ["serial.log", "screendump.png", "Windows_Panther_setupact.log", "ProgramData_arena_logs_setup.log"] {
        assert!(failure.join(file).is_file(), "{file} is not in {}: {err}", failure.display());
    }
    let setup_log = std::fs::read_to_string(failure.join("ProgramData_arena_logs_setup.log")).unwrap();
    assert!(setup_log.contains("prep-apps.ps1 exited with 3"), "{setup_log}");
    let setupact = std::fs::read_to_string(failure.join("Windows_Panther_setupact.log")).unwrap();
    assert!(setupact.contains("stand-in Windows Setup"), "{setupact}");
    assert_bundle(&work);
    let timeline = std::fs::read_to_string(work.join("timeline.log")).unwrap();
    assert!(timeline.contains("the OEM install failed") && timeline.contains("evidence kept"), "{timeline}");
    assert!(err.contains("--allow-failed-step"), "{err}");

    // The same prepare, letting that step fail: it seals, and the image says which step failed.
    let run =
        prepare_command(&image, &oem, &out, &["--size", "64G", "--allow-failed-step", "prep-apps"]).output().unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{err}");
    let facts = arena_vm::sidecar::read(&out).unwrap().expect("the sealed image's sidecar");
    assert_eq!(facts.allowed_failed_steps, vec!["prep-apps.ps1 (exit code 3)".to_owned()], "{facts:?}");
    let state: serde_json::Value = serde_json::from_slice(&std::fs::read(work.join("state.json")).unwrap()).unwrap();
    assert_eq!(state["allowed_failures"], serde_json::json!(["prep-apps.ps1 (exit code 3)"]), "{state}");
}

/// `--list-editions` reads a UDF disc as Windows ISOs are (made here with
/// genisoimage's UDF): the images of its `sources/install.wim`; `--dry-run`
/// refuses a `--locale` its images' default language is not, unless forced.
#[test]
fn list_editions_reads_the_image_list_of_a_udf_iso() {
    let Some(genisoimage) = arena_shared::search_path::find_program(Path::new("genisoimage")) else {
        arena_test_support::skip(
            "list_editions_reads_the_image_list_of_a_udf_iso",
            "genisoimage not found",
            "ARENA_REQUIRE_QEMU",
        );
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("iso");
    std::fs::create_dir_all(root.join("sources")).unwrap();
    let xml = r#"<WIM><IMAGE INDEX="1"><NAME>Windows 11 Home</NAME><WINDOWS><EDITIONID>Core</EDITIONID><LANGUAGES><LANGUAGE>en-US</LANGUAGE><DEFAULT>en-US</DEFAULT></LANGUAGES></WINDOWS></IMAGE><IMAGE INDEX="2"><NAME>Windows 10 Pro</NAME><DISPLAYNAME>Windows 11 Pro</DISPLAYNAME><WINDOWS><EDITIONID>Professional</EDITIONID><LANGUAGES><LANGUAGE>en-US</LANGUAGE><DEFAULT>en-US</DEFAULT></LANGUAGES></WINDOWS></IMAGE></WIM>"#;
    let list: Vec<u8> = std::iter::once(0xfeffu16).chain(xml.encode_utf16()).flat_map(u16::to_le_bytes).collect();
    let mut wim = vec![0u8; 208];
    wim[..8].copy_from_slice(b"MSWIM\0\0\0");
    wim[72..79].copy_from_slice(&(list.len() as u64).to_le_bytes()[..7]);
    wim[80..88].copy_from_slice(&4096u64.to_le_bytes());
    wim[88..96].copy_from_slice(&(list.len() as u64).to_le_bytes());
    wim.resize(4096, 0);
    wim.extend(&list);
    std::fs::write(root.join("sources").join("install.wim"), &wim).unwrap();
    let iso = dir.path().join("win.iso");
    let made = Command::new(genisoimage).args(["-quiet", "-udf", "-o"]).arg(&iso).arg(&root).output().unwrap();
    assert!(made.status.success(), "{}", String::from_utf8_lossy(&made.stderr));
    let run = arena().args(["vm", "prepare", "--list-editions"]).arg(&iso).output().unwrap();
    let said = String::from_utf8_lossy(&run.stdout);
    assert!(run.status.success(), "{said}{}", String::from_utf8_lossy(&run.stderr));
    assert!(said.contains("    1  Core") && said.contains("Windows 11 Home"), "{said}");
    assert!(said.contains("    2  Professional") && said.contains("Windows 10 Pro (Windows 11 Pro)"), "{said}");
    // The answer file of --edition pro picks image 2 with Pro's generic key; home is refused.
    let oem = oem_folder(dir.path(), &"7f".repeat(32));
    let out = dir.path().join("g.qcow2");
    let dry = arena()
        .args(["vm", "prepare", "--dry-run", "--edition", "pro", "--iso"])
        .arg(&iso)
        .arg("--oem")
        .arg(&oem)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    if dry.status.success() {
        let answer = std::fs::read_to_string(arena_vm::prepare::work_dir(&out).join("autounattend.xml")).unwrap();
        assert!(answer.contains("<Value>2</Value>") && answer.contains("W269N-WFGWX-YVC9B-4J6C9-T83GX"), "{answer}");
    } else {
        // Without QEMU the dry run stops before the answer file is used; the choice is unit-tested.
        assert!(String::from_utf8_lossy(&dry.stderr).contains("qemu"), "{}", String::from_utf8_lossy(&dry.stderr));
    }
    let home = arena()
        .args(["vm", "prepare", "--dry-run", "--edition", "home", "--iso"])
        .arg(&iso)
        .arg("--oem")
        .arg(&oem)
        .arg("--out")
        .arg(dir.path().join("h.qcow2"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&home.stderr);
    assert!(!home.status.success() && err.contains("Home") && err.contains("refused"), "{err}");
    // A --locale the media do not hold is refused in --dry-run, naming theirs, unless forced.
    let german = |extra: &[&str]| {
        arena()
            .args(["vm", "prepare", "--dry-run", "--edition", "pro", "--locale", "de-DE", "--iso"])
            .arg(&iso)
            .arg("--oem")
            .arg(&oem)
            .arg("--out")
            .arg(dir.path().join("de.qcow2"))
            .args(extra)
            .output()
            .unwrap()
    };
    let refused = german(&[]);
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success(), "{err}");
    assert!(err.contains("default language is en-US") && err.contains("--force-locale"), "{err}");
    let forced = german(&["--force-locale"]);
    let err = String::from_utf8_lossy(&forced.stderr);
    assert!(!err.contains("default language is en-US") || err.contains("going on"), "{err}");
    assert_eq!(forced.status.success(), dry.status.success(), "{err}");
}
