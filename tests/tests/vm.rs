//! VMs under QEMU with the stand-in guest image (docs/vm-standin.md), under
//! software emulation: boot to healthy, snapshot, change, restore, screendump;
//! a run on two VMs with per-task resets that scores as a run on plain stub
//! guests while one VM's QEMU is killed mid-run; `vm prepare` from the
//! stand-in installer, interrupted and resumed; and the errors bad input gets.
//!
//! Without the image or QEMU each test says `SKIPPED:` (counted by test.sh;
//! a failure with ARENA_REQUIRE_QEMU=1).

#![cfg(target_os = "linux")]

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use arena_host::client::{ClientConfig, GuestClient};
use arena_host::results::{read_episode, EPISODE_FILE, RESULT_FILE};
use arena_host::vm::fleet::check_screen;
use arena_host::vm::qemu::{Accel, DiskBus, NicModel};
use arena_host::vm::{Boot, Vm, VmConfig, VmError, READY_SNAPSHOT};
use arena_shared::exec::LaunchRequest;
use arena_test_support::{standin_image, workspace_binary};

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
    let mut pids = Vec::new();
    for entry in std::fs::read_dir("/proc").into_iter().flatten().flatten() {
        let Ok(pid) = entry.file_name().to_string_lossy().parse::<u32>() else { continue };
        let cmdline = std::fs::read(entry.path().join("cmdline")).unwrap_or_default();
        let text = String::from_utf8_lossy(&cmdline).replace('\0', " ");
        if text.contains("qemu-system") && text.contains(needle) {
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

    // QEMU's own view of the screen agrees with the guest's screenshot.
    let screen = check_screen(&vm).await.unwrap();
    assert!(!screen.dump_black, "{screen:?}");
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

fn episodes(root: &Path) -> Vec<arena_host::results::EpisodeResult> {
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

#[test]
fn prepare_from_the_installer_resumes_after_being_killed() {
    let Some(image) = standin_image("prepare_from_the_installer_resumes_after_being_killed") else { return };
    let dir = tempfile::tempdir().unwrap();
    let oem = dir.path().join("oem");
    std::fs::create_dir_all(&oem).unwrap();
    let token = "7f".repeat(32);
    std::fs::write(oem.join(arena_host::prep::TOKEN_NAME), format!("{token}\n")).unwrap();
    let out = dir.path().join("golden2.qcow2");
    let work = arena_host::vm::prepare::work_dir(&out);
    let prepare = || {
        let mut command = arena();
        command
            .args(["vm", "prepare", "--size", "256M", "--shutdown-timeout", "60", "--iso"])
            .arg(&image.installer)
            .arg("--oem")
            .arg(&oem)
            .arg("--out")
            .arg(&out)
            .args(VM_FLAGS)
            .env_remove("ARENA_TOKEN")
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        command
    };

    // The first prepare is killed once the installer runs.
    let mut first = prepare().spawn().unwrap();
    let deadline = Instant::now() + Duration::from_secs(120);
    let pid = loop {
        let state = arena_host::vm::prepare::read_state(&out).unwrap();
        if let Some(pid) =
            state.and_then(|s| (s.stage == arena_host::vm::prepare::Stage::Installing).then_some(s.qemu_pid).flatten())
        {
            let serial = std::fs::read_to_string(work.join("serial.log")).unwrap_or_default();
            if serial.contains("arena-standin") {
                break pid;
            }
        }
        assert!(Instant::now() < deadline, "the installer never started");
        assert!(first.try_wait().unwrap().is_none(), "prepare ended early");
        std::thread::sleep(Duration::from_millis(200));
    };
    first.kill().unwrap();
    first.wait().unwrap();
    // QEMU goes with it.
    let gone = Instant::now() + Duration::from_secs(10);
    while Path::new(&format!("/proc/{pid}")).exists() {
        assert!(Instant::now() < gone, "QEMU {pid} outlived the killed prepare");
        std::thread::sleep(Duration::from_millis(100));
    }

    let status = arena().args(["vm", "prepare", "--status", "--out"]).arg(&out).output().unwrap();
    assert!(String::from_utf8_lossy(&status.stdout).contains("stage installing"), "{status:?}");

    // The same command again goes on from there.
    let second: Output = prepare().output().unwrap();
    let said = String::from_utf8_lossy(&second.stdout);
    assert!(second.status.success(), "{said}\n{}", String::from_utf8_lossy(&second.stderr));
    assert!(said.contains("stage installing (resumed)"), "{said}");
    assert!(said.contains("golden image ready"), "{said}");
    assert!(std::fs::metadata(&out).unwrap().permissions().readonly());

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

    // Commands for a VM that is not running.
    let out = arena().args(["vm", "restore", "--dir"]).arg(dir.path().join("none")).arg("ready").output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("no VM runs in"), "{err}");

    // Nothing was started by any of them.
    assert!(qemus_naming(&dir.path().display().to_string()).is_empty());
}
