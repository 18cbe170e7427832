//! `vmbench`: what a clean VM per task costs, on the stand-in guest image
//! (docs/vm-standin.md) under QEMU; prints figures.
//!
//! - a cold boot to a healthy guest, against restoring the `ready` snapshot to a
//!   healthy guest (what `arena run --reset per-task` does before each task);
//! - a pod's start: an overlay on the read-only golden image and a boot, against
//!   copying the golden image into the pod first and booting that copy (what the
//!   old manifests did), with the copy's measured rate applied to a 64 GiB
//!   Windows disk as a projection.
//!
//! The image comes from `ARENA_STANDIN_DIR` or `target/standin`
//! (`scripts/build-standin-image.sh`). `--accel kvm` where KVM works; software
//! emulation otherwise. Run: `cargo run --release -p arena-tests --bin vmbench`.

#![forbid(unsafe_code)]

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

use anyhow::Context;
use arena_vm::disk::make_read_only;
use arena_vm::qemu::{Accel, DiskBus, NicModel};
use arena_vm::{Boot, Vm, VmConfig, READY_SNAPSHOT};

/// Runs of each measurement.
const RUNS: usize = 3;

#[tokio::main]
async fn main() -> ExitCode {
    match run().await {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("error: {err:#}");
            ExitCode::FAILURE
        }
    }
}

fn image_dir() -> PathBuf {
    std::env::var_os("ARENA_STANDIN_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/standin"))
}

fn config(golden: &Path, dir: &Path, accel: Accel) -> VmConfig {
    let mut config = VmConfig::new(golden, dir, "bench");
    config.accel = Some(accel);
    config.memory_mib = 512;
    config.cpus = 1;
    config.machine = "pc".into();
    config.disk_bus = DiskBus::VirtioBlk;
    config.nic = NicModel::VirtioNet;
    config.boot_timeout = Duration::from_secs(300);
    config
}

/// Boots `config` on a new overlay and waits for the guest; the VM and the time.
async fn cold_boot(config: &VmConfig) -> anyhow::Result<(Vm, Duration)> {
    let started = Instant::now();
    let mut vm = Vm::start(config, Boot::Fresh).await?;
    vm.wait_healthy(config.boot_timeout, |_| {}).await?;
    Ok((vm, started.elapsed()))
}

fn summary(label: &str, runs: &[Duration]) -> String {
    let secs: Vec<f64> = runs.iter().map(Duration::as_secs_f64).collect();
    let mean = secs.iter().sum::<f64>() / secs.len() as f64;
    let min = secs.iter().copied().fold(f64::INFINITY, f64::min);
    let max = secs.iter().copied().fold(0.0, f64::max);
    format!("{label:<58} mean {mean:7.2} s  min {min:7.2} s  max {max:7.2} s  ({} runs)", secs.len())
}

async fn run() -> anyhow::Result<()> {
    let accel = match std::env::args().skip_while(|a| a != "--accel").nth(1).as_deref() {
        Some("kvm") => Accel::Kvm,
        _ => Accel::Tcg,
    };
    let dir = image_dir();
    let golden = dir.join("golden.qcow2");
    anyhow::ensure!(golden.exists(), "{} is missing: run scripts/build-standin-image.sh", golden.display());
    let work = tempfile::tempdir()?;
    println!("stand-in image {} ({:?}), {} MB", golden.display(), accel, std::fs::metadata(&golden)?.len() >> 20);

    // Cold boots, then restores of the snapshot taken after the last one.
    let mut boots = Vec::new();
    let mut last = None;
    for i in 0..RUNS {
        let (vm, took) = cold_boot(&config(&golden, &work.path().join(format!("cold-{i}")), accel)).await?;
        boots.push(took);
        if let Some(mut old) = last.replace(vm) {
            old.kill().await;
        }
    }
    let mut vm = last.context("no boot")?;
    let saved = vm.save_snapshot(READY_SNAPSHOT).await?;
    let mut restores = Vec::new();
    let mut loads = Vec::new();
    for _ in 0..RUNS {
        let started = Instant::now();
        loads.push(vm.restore_snapshot(READY_SNAPSHOT).await?);
        vm.wait_healthy(Duration::from_secs(120), |_| {}).await?;
        restores.push(started.elapsed());
    }
    vm.kill().await;

    // A pod's start: overlay and boot, against copy and boot.
    let mut overlay_starts = Vec::new();
    let mut copy_starts = Vec::new();
    let mut copies = Vec::new();
    for i in 0..RUNS {
        let (mut vm, took) = cold_boot(&config(&golden, &work.path().join(format!("pod-{i}")), accel)).await?;
        overlay_starts.push(took);
        vm.kill().await;

        let pod = work.path().join(format!("copy-{i}"));
        std::fs::create_dir_all(&pod)?;
        let copy = pod.join("disk.qcow2");
        let started = Instant::now();
        std::fs::copy(&golden, &copy)?;
        let copied = started.elapsed();
        copies.push(copied);
        make_read_only(&copy)?;
        let (mut vm, booted) = cold_boot(&config(&copy, &pod.join("vm"), accel)).await?;
        copy_starts.push(copied + booted);
        vm.kill().await;
    }
    // The UEFI machine of `arena vm prepare --firmware uefi`: secure-boot OVMF with
    // SMM, a swtpm TPM 2.0; from QEMU's start to the firmware's first drawn screen,
    // and a snapshot save and restore that carry the TPM's state.
    let mut uefi_starts = Vec::new();
    let mut uefi_snapshots = Vec::new();
    match arena_vm::Uefi::debian_secure_boot() {
        Ok(uefi) => {
            for i in 0..RUNS {
                let mut c = config(&golden, &work.path().join(format!("uefi-{i}")), accel);
                c.machine = "q35".into();
                c.uefi = Some(uefi.clone());
                c.tpm = true;
                let started = Instant::now();
                let mut vm = Vm::start(&c, Boot::Fresh).await?;
                loop {
                    if vm.screendump().await.is_ok_and(|d| !d.black) {
                        break;
                    }
                    anyhow::ensure!(started.elapsed() < Duration::from_secs(120), "OVMF drew nothing in 120 s");
                    tokio::time::sleep(Duration::from_millis(200)).await;
                }
                uefi_starts.push(started.elapsed());
                let started = Instant::now();
                vm.save_snapshot("bench").await?;
                vm.restore_snapshot("bench").await?;
                uefi_snapshots.push(started.elapsed());
                vm.kill().await;
            }
        }
        Err(err) => println!("UEFI figures skipped: {err}"),
    }
    let bytes = std::fs::metadata(&golden)?.len() as f64;
    let copy_secs = copies.iter().map(Duration::as_secs_f64).sum::<f64>() / copies.len() as f64;
    let rate = bytes / copy_secs.max(1e-9);
    let windows_disk = 64.0 * f64::from(1u32 << 30);

    println!("{}", summary("cold boot to a healthy guest", &boots));
    println!("{}", summary("restore of the ready snapshot to a healthy guest", &restores));
    println!("{}", summary("  of which loadvm itself", &loads));
    println!("saving the ready snapshot once: {:.2} s", saved.as_secs_f64());
    if !uefi_starts.is_empty() {
        println!(
            "{}",
            summary("UEFI (secure-boot OVMF, SMM, swtpm): QEMU start to the firmware's screen", &uefi_starts)
        );
        println!("{}", summary("UEFI: savevm + loadvm with the TPM's state", &uefi_snapshots));
    }
    println!("{}", summary("pod start: overlay on the golden image + boot", &overlay_starts));
    println!("{}", summary("pod start: copy the golden image + boot (old manifests)", &copy_starts));
    println!(
        "copy rate here {:.0} MB/s: a 64 GiB Windows disk would take {:.0} s to copy before its boot (projection)",
        rate / 1e6,
        windows_disk / rate
    );
    Ok(())
}
