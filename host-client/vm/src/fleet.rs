//! The VMs of one run (`arena run --vm-image golden.qcow2 --vms N`): each is
//! booted on its own overlay, waited for (a healthy guest, then a settled
//! desktop and `--vm-settle`: [`Vm::wait_settled`]), and saved as the `ready` snapshot;
//! before a task the pool asks for the snapshot back (`--reset`), and a VM
//! that died or stopped answering is killed and started again from its
//! overlay's snapshot (or, failing that, from a new overlay).

use std::str::FromStr;
use std::time::{Duration, Instant};

use arena_shared::observation::ScreenshotQuery;
use tokio::sync::Mutex;

use super::{Boot, Vm, VmConfig, VmError, READY_SNAPSHOT};
use arena_client::client::GuestClient;
use arena_results::{ClockSync, VmStart};

/// When a VM goes back to its `ready` snapshot.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ResetPolicy {
    /// Before every task (the default: every task starts from the same state).
    PerTask,
    /// Before every K-th task on a VM (the first included).
    Every(u32),
    /// Never: tasks meet what the ones before them left, as upstream's harness runs.
    Never,
}

impl FromStr for ResetPolicy {
    type Err = String;

    fn from_str(text: &str) -> Result<ResetPolicy, String> {
        match text {
            "per-task" => Ok(ResetPolicy::PerTask),
            "never" => Ok(ResetPolicy::Never),
            other => match other.strip_prefix("every:").map(str::parse::<u32>) {
                Some(Ok(k)) if k >= 1 => Ok(ResetPolicy::Every(k)),
                _ => Err(format!("--reset {other:?}: use per-task, every:K (K at least 1) or never")),
            },
        }
    }
}

impl std::fmt::Display for ResetPolicy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ResetPolicy::PerTask => f.write_str("per-task"),
            ResetPolicy::Every(k) => write!(f, "every:{k}"),
            ResetPolicy::Never => f.write_str("never"),
        }
    }
}

impl ResetPolicy {
    /// Whether a VM that has run `since_reset` tasks since its last restore (or
    /// since its snapshot was taken, for `first`) is restored before the next.
    pub fn due(self, since_reset: u32, first: bool) -> bool {
        match self {
            ResetPolicy::PerTask => true,
            ResetPolicy::Every(k) => first || since_reset >= k,
            ResetPolicy::Never => false,
        }
    }
}

pub use arena_results::ScreenCheck;

/// Takes QEMU's screendump and the guest's own screenshot and compares them.
///
/// # Errors
///
/// The screendump fails (a guest screenshot that fails is a `problem`, not an error).
pub async fn check_screen(vm: &Vm) -> Result<ScreenCheck, VmError> {
    let dump = vm.screendump().await?;
    let guest = vm.client().screenshot(&ScreenshotQuery { cursor: Some(false), ..ScreenshotQuery::default() }).await;
    let (guest_width, guest_height, guest_black, mut problem) = match &guest {
        Ok(shot) => (shot.meta.physical_width, shot.meta.physical_height, shot.meta.black_frame, None),
        Err(err) => (0, 0, false, Some(format!("the guest's screenshot failed: {err}"))),
    };
    if problem.is_none() {
        if guest_black && !dump.black {
            problem = Some("the guest's screenshot is black while the VM's display is not (lock screen, secure desktop or a capture failure)".into());
        } else if (guest_width, guest_height) != (dump.width, dump.height) {
            problem = Some(format!(
                "the guest captures {guest_width}x{guest_height} but the VM's display is {}x{}",
                dump.width, dump.height
            ));
        }
    }
    Ok(ScreenCheck {
        dump_width: dump.width,
        dump_height: dump.height,
        dump_black: dump.black,
        guest_width,
        guest_height,
        guest_black,
        problem,
    })
}

/// Sets the guest's clock to this machine's and says how far off it was.
/// A guest that refuses (an older one without `PUT /v1/clock`) is logged and
/// recorded, not an error: the task runs on with the clock it has.
pub async fn sync_clock(client: &GuestClient, vm: &str) -> ClockSync {
    let host = arena_shared::clock::now_unix_ms();
    match client.set_clock(host).await {
        Ok(set) => {
            let corrected = set.corrected_ms();
            tracing::info!(vm, corrected_ms = corrected, "set the guest's clock");
            ClockSync { corrected_ms: Some(corrected), error: None }
        }
        Err(err) => {
            tracing::warn!(vm, error = %err, "the guest's clock was not set");
            ClockSync { corrected_ms: None, error: Some(err.to_string()) }
        }
    }
}

struct Slot {
    url: String,
    state: Mutex<SlotState>,
}

struct SlotState {
    config: VmConfig,
    vm: Option<Vm>,
    since_reset: u32,
    first: bool,
    rebuilt: bool,
}

/// The VMs of a run.
pub struct VmFleet {
    slots: Vec<Slot>,
    reset: ResetPolicy,
}

impl std::fmt::Debug for VmFleet {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("VmFleet")
            .field("vms", &self.slots.iter().map(|s| s.url.as_str()).collect::<Vec<_>>())
            .field("reset", &self.reset)
            .finish()
    }
}

/// Boots a VM on a new overlay, waits for its guest and saves `ready`.
async fn boot_ready(config: &mut VmConfig) -> Result<Vm, VmError> {
    let started = Instant::now();
    let mut vm = Vm::start(config, Boot::Fresh).await?;
    // Rebuilds reuse the port, so the guest's URL never changes.
    config.host_port = vm.spec.host_port;
    let name = config.name.clone();
    vm.wait_healthy(config.boot_timeout, |event| tracing::debug!(vm = %name, ?event, "boot")).await?;
    let booted = started.elapsed();
    // Tasks start from this snapshot: not before the desktop has settled (and the floor passed).
    let settled = vm.wait_settled(config.settle_floor, config.boot_timeout.saturating_sub(booted)).await?;
    match &settled.shell {
        Some(shell) => {
            tracing::info!(vm = %name, settled_s = settled.settled_after.as_secs_f64(), waited_s = settled.waited.as_secs_f64(), %shell, "desktop settled")
        }
        None => {
            tracing::warn!(vm = %name, waited_s = settled.waited.as_secs_f64(), "the guest reports no shell component (an older guest): only --vm-settle was waited")
        }
    }
    let saved = vm.save_snapshot(READY_SNAPSHOT).await?;
    tracing::info!(vm = %config.name, url = vm.url(), boot_s = booted.as_secs_f64(), snapshot_s = saved.as_secs_f64(), accel = %vm.accel_note, "VM ready");
    Ok(vm)
}

impl VmFleet {
    /// Boots one VM per config, all at once, each to a saved `ready` snapshot.
    ///
    /// # Errors
    ///
    /// The first VM that fails (the others are stopped).
    pub async fn boot(configs: Vec<VmConfig>, reset: ResetPolicy) -> Result<VmFleet, VmError> {
        // `--vm-dir` holds the VMs' folders: it must be ours too (or new, or empty).
        if let Some(parent) = configs.first().and_then(|c| c.dir.parent()) {
            super::claim_dir(parent)?;
        }
        let mut set = tokio::task::JoinSet::new();
        for (i, mut config) in configs.into_iter().enumerate() {
            set.spawn(async move { (i, boot_ready(&mut config).await, config) });
        }
        let mut booted: Vec<(usize, Vm, VmConfig)> = Vec::new();
        let mut failure = None;
        while let Some(joined) = set.join_next().await {
            match joined {
                Ok((i, Ok(vm), config)) => booted.push((i, vm, config)),
                Ok((_, Err(err), _)) => {
                    failure.get_or_insert(err);
                }
                Err(err) => {
                    failure.get_or_insert(VmError::Invalid(format!("a VM's boot task failed: {err}")));
                }
            }
        }
        if let Some(err) = failure {
            for (_, mut vm, _) in booted {
                vm.kill().await;
            }
            return Err(err);
        }
        booted.sort_by_key(|(i, _, _)| *i);
        let slots = booted
            .into_iter()
            .map(|(_, vm, config)| Slot {
                url: vm.url().to_owned(),
                state: Mutex::new(SlotState { config, vm: Some(vm), since_reset: 0, first: true, rebuilt: false }),
            })
            .collect();
        Ok(VmFleet { slots, reset })
    }

    /// The guests' URLs, in VM order.
    pub fn urls(&self) -> Vec<String> {
        self.slots.iter().map(|s| s.url.clone()).collect()
    }

    fn slot(&self, guest: &GuestClient) -> Result<&Slot, String> {
        self.slots
            .iter()
            .find(|s| s.url == guest.base_url())
            .ok_or_else(|| format!("{} is not one of this run's VMs", guest.base_url()))
    }

    /// QEMU's process id of VM `index` (for tests that kill one).
    pub async fn pid(&self, index: usize) -> Option<u32> {
        let slot = self.slots.get(index)?;
        slot.state.lock().await.vm.as_ref().and_then(Vm::pid)
    }

    /// Stops every VM (QEMU quits; the overlays stay for inspection).
    pub async fn stop(self) {
        for slot in self.slots {
            let mut state = slot.state.into_inner();
            if let Some(mut vm) = state.vm.take() {
                vm.kill().await;
            }
        }
    }
}

impl VmFleet {
    /// Before a task on `guest`: restores its VM's `ready` snapshot when the
    /// [`ResetPolicy`] says it is due, and checks the restored screen.
    ///
    /// # Errors
    ///
    /// The VM is not one of this fleet's, is not running, or did not come back.
    pub async fn before_task(&self, guest: &GuestClient) -> Result<Option<VmStart>, String> {
        let slot = self.slot(guest)?;
        let mut state = slot.state.lock().await;
        let state = &mut *state;
        let name = state.config.name.clone();
        let Some(vm) = state.vm.as_mut() else { return Err(format!("VM {name} is not running")) };
        if let Some(status) = vm.exited() {
            return Err(format!("VM {name}: QEMU exited ({status})"));
        }
        let mut start = VmStart {
            vm: name.clone(),
            snapshot: None,
            restore_ms: 0,
            rebuilt: state.rebuilt,
            screen: None,
            clock: None,
        };
        if self.reset.due(state.since_reset, state.first) {
            let started = Instant::now();
            vm.restore_snapshot(READY_SNAPSHOT).await.map_err(|e| e.to_string())?;
            vm.wait_healthy(state.config.boot_timeout, |_| {}).await.map_err(|e| e.to_string())?;
            start.snapshot = Some(READY_SNAPSHOT.to_owned());
            start.restore_ms = u64::try_from(started.elapsed().as_millis()).unwrap_or(u64::MAX);
            // Before anything else runs: a restored guest's clock is the snapshot's.
            start.clock = Some(sync_clock(vm.client(), &name).await);
            // QEMU's view of the restored screen against the guest's own capture.
            match check_screen(vm).await {
                Ok(check) => {
                    if let Some(problem) = &check.problem {
                        tracing::warn!(vm = %name, %problem, "screen check after the restore");
                    }
                    start.screen = Some(check);
                }
                Err(err) => tracing::warn!(vm = %name, error = %err, "no screen check after the restore"),
            }
            state.since_reset = 0;
            tracing::info!(vm = %name, restore_ms = start.restore_ms, "restored the ready snapshot");
        }
        if start.clock.is_none() && state.rebuilt {
            // Rebuilt from the snapshot and not restored (`--reset never`): the same clock.
            start.clock = Some(sync_clock(vm.client(), &name).await);
        }
        state.since_reset += 1;
        state.first = false;
        state.rebuilt = false;
        Ok(Some(start))
    }

    /// Kills `guest`'s VM and starts it again from its overlay's `ready`
    /// snapshot, or failing that from a new overlay.
    ///
    /// # Errors
    ///
    /// The VM is not one of this fleet's, or neither way brought it back.
    pub async fn revive(&self, guest: &GuestClient) -> Result<(), String> {
        let slot = self.slot(guest)?;
        let mut state = slot.state.lock().await;
        let state = &mut *state;
        if let Some(mut old) = state.vm.take() {
            old.kill().await;
        }
        tracing::warn!(vm = %state.config.name, "rebuilding the VM from its overlay's ready snapshot");
        let resumed = async {
            let mut vm = Vm::start(&state.config, Boot::FromSnapshot(READY_SNAPSHOT.to_owned())).await?;
            vm.wait_healthy(state.config.boot_timeout, |_| {}).await?;
            Ok::<Vm, VmError>(vm)
        }
        .await;
        let vm = match resumed {
            Ok(vm) => vm,
            Err(err) => {
                tracing::warn!(vm = %state.config.name, error = %err, "the overlay did not come back; booting a new one");
                boot_ready(&mut state.config).await.map_err(|e| e.to_string())?
            }
        };
        state.vm = Some(vm);
        state.since_reset = 0;
        state.first = true;
        state.rebuilt = true;
        Ok(())
    }
}

/// How long a guest that stopped answering waits for its QEMU's exit to show:
/// a killed process closes its sockets a moment before it can be reaped.
const EXIT_SHOWS_WITHIN: Duration = Duration::from_secs(1);

impl VmFleet {
    /// Why the VM of `guest` (its base URL) stopped, when the cause is outside
    /// the guest (QEMU gone or killed); `None` when it still runs, or stopped
    /// from inside.
    pub async fn outside_failure(&self, guest: &str) -> Option<String> {
        let slot = self.slots.iter().find(|s| s.url == guest)?;
        let until = Instant::now() + EXIT_SHOWS_WITHIN;
        loop {
            {
                let mut state = slot.state.lock().await;
                let name = state.config.name.clone();
                let Some(vm) = state.vm.as_mut() else { return Some(format!("VM {name} is not running")) };
                if let Some(why) = vm.ended_outside_guest() {
                    return Some(format!("VM {name}: {why}"));
                }
            }
            if Instant::now() >= until {
                return None;
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }
}

impl VmFleet {
    /// QEMU's screendump of the VM `guest` (its base URL) runs in, as PNG.
    pub async fn screendump(&self, guest: &str) -> Option<Vec<u8>> {
        let slot = self.slots.iter().find(|s| s.url == guest)?;
        let state = slot.state.lock().await;
        match state.vm.as_ref()?.screendump().await {
            Ok(dump) => Some(dump.png),
            Err(err) => {
                tracing::warn!(vm = %state.config.name, error = %err, "QEMU's screendump failed");
                None
            }
        }
    }
}

/// The per-VM configs of a fleet: `template` with its folder under `root` as `vm-1`, `vm-2`, ...
pub fn configs(template: &VmConfig, count: usize) -> Vec<VmConfig> {
    (1..=count)
        .map(|i| {
            let mut config = template.clone();
            config.name = format!("vm-{i}");
            config.dir = template.dir.join(&config.name);
            if template.host_port != 0 {
                config.host_port = template.host_port + u16::try_from(i - 1).unwrap_or(0);
            }
            if let Some(vnc) = template.vnc {
                config.vnc = Some(vnc + u16::try_from(i - 1).unwrap_or(0));
            }
            config
        })
        .collect()
}

/// Nothing here waits on wall time in tests: the policy is plain arithmetic.
#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reset_policies_parse_and_decide() {
        assert_eq!("per-task".parse::<ResetPolicy>().unwrap(), ResetPolicy::PerTask);
        assert_eq!("every:3".parse::<ResetPolicy>().unwrap(), ResetPolicy::Every(3));
        assert_eq!("never".parse::<ResetPolicy>().unwrap(), ResetPolicy::Never);
        for bad in ["every:0", "every:x", "sometimes", ""] {
            let err = bad.parse::<ResetPolicy>().unwrap_err();
            assert!(err.contains("per-task, every:K"), "{err}");
        }
        assert_eq!(ResetPolicy::Every(3).to_string(), "every:3");

        // Which of six tasks on one VM start from the snapshot.
        let plan = |policy: ResetPolicy| {
            let (mut since, mut first, mut restored) = (0, true, Vec::new());
            for task in 1..=6 {
                if policy.due(since, first) {
                    restored.push(task);
                    since = 0;
                }
                since += 1;
                first = false;
            }
            restored
        };
        assert_eq!(plan(ResetPolicy::PerTask), vec![1, 2, 3, 4, 5, 6]);
        assert_eq!(plan(ResetPolicy::Every(2)), vec![1, 3, 5]);
        assert_eq!(plan(ResetPolicy::Every(4)), vec![1, 5]);
        assert!(plan(ResetPolicy::Never).is_empty());
    }

    #[test]
    fn fleet_configs_get_their_own_folders_ports_and_displays() {
        let mut template = VmConfig::new("/g/golden.qcow2".as_ref(), "/run/vms".as_ref(), "vm");
        template.host_port = 6000;
        template.vnc = Some(1);
        let configs = configs(&template, 3);
        let names: Vec<_> =
            configs.iter().map(|c| (c.name.as_str(), c.dir.display().to_string(), c.host_port, c.vnc)).collect();
        assert_eq!(
            names,
            vec![
                ("vm-1", "/run/vms/vm-1".to_owned(), 6000, Some(1)),
                ("vm-2", "/run/vms/vm-2".to_owned(), 6001, Some(2)),
                ("vm-3", "/run/vms/vm-3".to_owned(), 6002, Some(3)),
            ]
        );
        template.host_port = 0;
        assert!(super::configs(&template, 2).iter().all(|c| c.host_port == 0));
    }
}
