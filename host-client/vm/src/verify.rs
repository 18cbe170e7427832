//! `arena vm verify IMAGE`: the first contact with a golden image, written
//! down. It boots the image once on an overlay of its own, looks at what a run
//! would meet, and writes a report (`verify.json`, `verify.txt`) into a folder
//! that is also the bundle to attach to a bug report: the guest's health and
//! doctor reports, QEMU's screendump and the guest's screenshot, the sidecar,
//! and the VM's serial and QEMU logs.
//!
//! The checks, each [`Verdict::Pass`], `Warn`, `Fail` or `Skipped`:
//!
//! - `healthy`: the guest answers with every readiness component up;
//! - `settled`: the guest's `shell` component (taskbar shown, the desktop in
//!   front, the CPU idle), as the fleet waits for it before `ready`;
//! - `screen`: QEMU's screendump against the guest's screenshot (size, black),
//!   and the size against the sidecar's (upstream's is 1440x900);
//! - `watermark`: the unsupported-hardware notification cache (`SV1`, `SV2` = 0)
//!   that keeps "System requirements not met" off the screenshots;
//! - `clock`: the guest's clock against this machine's;
//! - `defender`: the doctor's Defender check (Tamper Protection, real-time
//!   protection, detections);
//! - `browser-chrome`, `browser-edge`: each browser's user-data folder by the
//!   one rule the getters use (`arena_client::browser::profile`), and whether it exists;
//! - `licence`: days left, from the sidecar;
//! - `doctor`: the guest's `GET /v1/doctor?deep=true`, every check end to end.
//!
//! The library writes files and prints nothing; `arena vm verify` prints.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use arena_client::browser::profile::{user_data_dir, Browser};
use arena_client::client::GuestClient;
use arena_shared::doctor::CheckStatus;
use arena_shared::observation::ScreenshotQuery;
use arena_shared::registry::RegistryValue;
use serde::{Deserialize, Serialize};

use super::sidecar::{self, ImageFacts, LICENCE_WARN_DAYS};
use super::{Boot, Vm, VmConfig, VmError};

/// The report's name in the bundle.
pub const REPORT_JSON: &str = "verify.json";
/// The readable report's name in the bundle.
pub const REPORT_TEXT: &str = "verify.txt";

/// A guest clock further off than this fails the `clock` check.
pub const CLOCK_TOLERANCE: Duration = Duration::from_secs(60);

/// Upstream's screen size.
pub const UPSTREAM_SCREEN: (u32, u32) = (1440, 900);

/// The unsupported-hardware notification cache, whose `SV1` and `SV2` are 0 on
/// upstream's image (WAA's answer file and dockur's logon script write them).
pub const WATERMARK_KEY: &str = r"HKCU\Control Panel\UnsupportedHardwareNotificationCache";

/// How one check ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    Pass,
    /// Worth reading; a run still works.
    Warn,
    Fail,
    /// Not checked (the guest did not answer, or the image does not say).
    Skipped,
}

impl Verdict {
    fn label(self) -> &'static str {
        match self {
            Verdict::Pass => "PASS",
            Verdict::Warn => "WARN",
            Verdict::Fail => "FAIL",
            Verdict::Skipped => "SKIP",
        }
    }
}

/// One check.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct VerifyCheck {
    pub name: String,
    pub verdict: Verdict,
    pub detail: String,
}

impl VerifyCheck {
    fn new(name: &str, verdict: Verdict, detail: impl Into<String>) -> VerifyCheck {
        VerifyCheck { name: name.to_owned(), verdict, detail: detail.into() }
    }
}

/// The report.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct VerifyReport {
    pub image: PathBuf,
    /// When the verify began, seconds since the Unix epoch.
    pub started_unix: i64,
    /// The accelerator QEMU ran under.
    pub accel: String,
    pub checks: Vec<VerifyCheck>,
    /// The files of the bundle, relative to its folder.
    pub files: Vec<String>,
}

impl VerifyReport {
    /// No check failed.
    pub fn passed(&self) -> bool {
        self.checks.iter().all(|c| c.verdict != Verdict::Fail)
    }

    /// The check named `name`.
    pub fn check(&self, name: &str) -> Option<&VerifyCheck> {
        self.checks.iter().find(|c| c.name == name)
    }

    /// The readable report.
    pub fn render_text(&self) -> String {
        let mut out = format!(
            "arena vm verify {}\nstarted {} UTC, {}\n\n",
            self.image.display(),
            arena_shared::calendar::iso_seconds(self.started_unix),
            self.accel
        );
        let width = self.checks.iter().map(|c| c.name.len()).max().unwrap_or(0);
        for check in &self.checks {
            out.push_str(&format!("{} {:width$}  {}\n", check.verdict.label(), check.name, check.detail));
        }
        let count = |v: Verdict| self.checks.iter().filter(|c| c.verdict == v).count();
        out.push_str(&format!(
            "\n{} passed, {} warnings, {} failed, {} skipped\nbundle: {}\n",
            count(Verdict::Pass),
            count(Verdict::Warn),
            count(Verdict::Fail),
            count(Verdict::Skipped),
            self.files.join(", ")
        ));
        out
    }
}

/// What `arena vm verify` was given.
#[derive(Debug, Clone)]
pub struct VerifyOptions {
    /// The VM, on the image; its folder is `<out>/vm`, removed at the end.
    pub config: VmConfig,
    /// The bundle's folder (created; files of an earlier verify are replaced).
    pub out: PathBuf,
}

/// The VM's folder inside the bundle's.
pub fn vm_dir(out: &Path) -> PathBuf {
    out.join("vm")
}

/// Boots the image, checks it and writes the bundle; `progress` hears each check
/// as it ends.
///
/// # Errors
///
/// The bundle's folder cannot be written, the image's sidecar refuses this VM,
/// or QEMU does not start. A guest that never gets healthy is a failed check,
/// not an error: its report and logs are what a bug report needs.
pub async fn verify(options: &VerifyOptions, mut progress: impl FnMut(&VerifyCheck)) -> Result<VerifyReport, VmError> {
    let out = &options.out;
    std::fs::create_dir_all(out).map_err(io(format!("creating {}", out.display())))?;
    let started_unix = arena_shared::clock::now_unix_ms().div_euclid(1000);
    let mut bundle = Files { dir: out.clone(), names: Vec::new() };
    let facts = sidecar::read(&options.config.golden)?;
    if facts.is_some() {
        let text = std::fs::read(sidecar::path_for(&options.config.golden))
            .map_err(io(format!("reading {}", sidecar::path_for(&options.config.golden).display())))?;
        bundle.write("sidecar.json", &text)?;
    }
    let mut config = options.config.clone();
    config.dir = vm_dir(out);
    let mut checks = Vec::new();
    let mut push = |check: VerifyCheck, checks: &mut Vec<VerifyCheck>| {
        progress(&check);
        checks.push(check);
    };
    push(licence(facts.as_ref(), started_unix), &mut checks);

    let mut vm = Vm::start(&config, Boot::Fresh).await?;
    let accel = vm.accel_note.clone();
    let booted = Instant::now();
    let healthy = vm.wait_healthy(config.boot_timeout, |_| {}).await;
    match &healthy {
        Ok(report) => {
            bundle.json("health.json", report)?;
            push(
                VerifyCheck::new(
                    "healthy",
                    Verdict::Pass,
                    format!("every readiness component up {:.0} s after power-on", booted.elapsed().as_secs_f64()),
                ),
                &mut checks,
            );
        }
        Err(err) => push(VerifyCheck::new("healthy", Verdict::Fail, err.to_string()), &mut checks),
    }
    if healthy.is_ok() {
        for check in guest_checks(&vm, &config, facts.as_ref(), &mut bundle).await? {
            push(check, &mut checks);
        }
    } else {
        for name in ["settled", "screen", "watermark", "clock", "defender", "browser-chrome", "browser-edge", "doctor"]
        {
            push(VerifyCheck::new(name, Verdict::Skipped, "the guest is not healthy"), &mut checks);
        }
        if let Ok(dump) = vm.screendump().await {
            bundle.write("screendump.png", &dump.png)?;
        }
    }
    vm.kill().await;
    for log in ["serial.log", "qemu.log"] {
        if let Ok(bytes) = std::fs::read(config.dir.join(log)) {
            bundle.write(log, &bytes)?;
        }
    }
    std::fs::remove_dir_all(&config.dir).map_err(io(format!("removing {}", config.dir.display())))?;
    let mut report =
        VerifyReport { image: options.config.golden.clone(), started_unix, accel, checks, files: Vec::new() };
    bundle.names.push(REPORT_JSON.to_owned());
    bundle.names.push(REPORT_TEXT.to_owned());
    bundle.names.sort();
    report.files = bundle.names.clone();
    bundle.json(REPORT_JSON, &report)?;
    bundle.write(REPORT_TEXT, report.render_text().as_bytes())?;
    Ok(report)
}

/// The checks that ask the (healthy) guest.
async fn guest_checks(
    vm: &Vm,
    config: &VmConfig,
    facts: Option<&ImageFacts>,
    bundle: &mut Files,
) -> Result<Vec<VerifyCheck>, VmError> {
    let client = vm.client();
    let mut checks = Vec::new();
    checks.push(match vm.wait_settled(config.settle_floor, config.boot_timeout).await {
        Ok(settled) => match settled.shell {
            Some(shell) => VerifyCheck::new(
                "settled",
                Verdict::Pass,
                format!("{shell} ({:.0} s after healthy)", settled.settled_after.as_secs_f64()),
            ),
            None => VerifyCheck::new("settled", Verdict::Warn, "the guest reports no shell component (an older guest)"),
        },
        Err(err) => VerifyCheck::new("settled", Verdict::Fail, err.to_string()),
    });
    checks.push(screen(vm, config, facts, bundle).await?);
    checks.push(watermark(client).await);
    checks.push(clock(client).await);
    let doctor = client.doctor_deep().await;
    match &doctor {
        Ok(report) => {
            bundle.json("doctor.json", report)?;
            bundle.write("doctor.txt", report.render_text().as_bytes())?;
            checks.push(match report.check("defender") {
                Some(check) => judge_defender(check.status, &check.detail),
                None => VerifyCheck::new("defender", Verdict::Skipped, "the guest's doctor has no defender check"),
            });
        }
        Err(err) => checks.push(VerifyCheck::new("defender", Verdict::Skipped, format!("the doctor failed: {err}"))),
    }
    for (name, browser) in [("browser-chrome", Browser::Chrome), ("browser-edge", Browser::Edge)] {
        checks.push(browser_folder(client, name, browser).await);
    }
    checks.push(match &doctor {
        Ok(report) if report.passed() => VerifyCheck::new(
            "doctor",
            Verdict::Pass,
            format!(
                "{} checks end to end in {:.0} s (doctor.txt)",
                report.checks.len(),
                report.total_ms as f64 / 1000.0
            ),
        ),
        Ok(report) => {
            let failed: Vec<&str> =
                report.checks.iter().filter(|c| c.status == CheckStatus::Fail).map(|c| c.name.as_str()).collect();
            VerifyCheck::new("doctor", Verdict::Fail, format!("failed: {} (doctor.txt)", failed.join(", ")))
        }
        Err(err) => VerifyCheck::new("doctor", Verdict::Fail, format!("GET /v1/doctor?deep=true: {err}")),
    });
    Ok(checks)
}

/// The `defender` check's rule over the doctor's: it fails when a detection
/// names the guest's own files; its facts (Tamper Protection, real-time
/// protection) are reported, not judged.
pub fn judge_defender(status: CheckStatus, detail: &str) -> VerifyCheck {
    match status {
        CheckStatus::Pass | CheckStatus::Info => {
            VerifyCheck::new("defender", Verdict::Pass, format!("no detection names the guest's files; {detail}"))
        }
        CheckStatus::Fail => VerifyCheck::new("defender", Verdict::Fail, detail),
        CheckStatus::Unavailable | CheckStatus::Unknown => VerifyCheck::new("defender", Verdict::Skipped, detail),
    }
}

/// QEMU's screen against the guest's, and its size against the image's.
async fn screen(
    vm: &Vm,
    config: &VmConfig,
    facts: Option<&ImageFacts>,
    bundle: &mut Files,
) -> Result<VerifyCheck, VmError> {
    let dump = match vm.screendump().await {
        Ok(dump) => dump,
        Err(err) => return Ok(VerifyCheck::new("screen", Verdict::Fail, format!("QEMU's screendump failed: {err}"))),
    };
    bundle.write("screendump.png", &dump.png)?;
    let query = ScreenshotQuery { cursor: Some(false), ..ScreenshotQuery::default() };
    let shot = match vm.client().screenshot(&query).await {
        Ok(shot) => shot,
        Err(err) => {
            return Ok(VerifyCheck::new("screen", Verdict::Fail, format!("the guest's screenshot failed: {err}")))
        }
    };
    bundle.write("screenshot.png", &shot.bytes)?;
    let guest = (shot.meta.physical_width, shot.meta.physical_height);
    let expected = facts.map_or(config.screen, |f| f.screen);
    Ok(judge_screen((dump.width, dump.height), dump.black, guest, shot.meta.black_frame, expected))
}

/// The `screen` check's rule.
pub fn judge_screen(
    dump: (u32, u32),
    dump_black: bool,
    guest: (u32, u32),
    guest_black: bool,
    expected: (u32, u32),
) -> VerifyCheck {
    let size = |(w, h): (u32, u32)| format!("{w}x{h}");
    if guest_black && !dump_black {
        return VerifyCheck::new(
            "screen",
            Verdict::Fail,
            "the guest's screenshot is black while the VM's display is not (lock screen, secure desktop or a capture failure)",
        );
    }
    if dump_black {
        return VerifyCheck::new("screen", Verdict::Fail, "the VM's display is black");
    }
    if guest != dump {
        return VerifyCheck::new(
            "screen",
            Verdict::Fail,
            format!("the guest captures {} but the VM's display is {}", size(guest), size(dump)),
        );
    }
    if guest != expected {
        return VerifyCheck::new(
            "screen",
            Verdict::Fail,
            format!("the screen is {}, the image was made for {}", size(guest), size(expected)),
        );
    }
    if guest != UPSTREAM_SCREEN {
        return VerifyCheck::new(
            "screen",
            Verdict::Warn,
            format!("{} as the image says, but upstream's tasks were made on {}", size(guest), size(UPSTREAM_SCREEN)),
        );
    }
    VerifyCheck::new("screen", Verdict::Pass, format!("{} in QEMU and in the guest's screenshot", size(guest)))
}

/// `SV1` and `SV2` of the notification cache.
async fn watermark(client: &GuestClient) -> VerifyCheck {
    let mut values = Vec::new();
    for name in ["SV1", "SV2"] {
        values.push(match client.registry_get(WATERMARK_KEY, Some(name)).await {
            Ok(read) => Some(read.data),
            Err(err) if err.status() == Some(404) => None,
            Err(err) => {
                return VerifyCheck::new("watermark", Verdict::Skipped, format!("reading {WATERMARK_KEY}: {err}"))
            }
        });
    }
    judge_watermark(&values)
}

/// The `watermark` check's rule over `SV1` and `SV2` (`None`: not set).
pub fn judge_watermark(values: &[Option<RegistryValue>]) -> VerifyCheck {
    let zero = values.iter().all(|v| matches!(v, Some(RegistryValue::Dword(0))));
    if zero {
        VerifyCheck::new("watermark", Verdict::Pass, format!("{WATERMARK_KEY} SV1 = SV2 = 0"))
    } else {
        VerifyCheck::new(
            "watermark",
            Verdict::Warn,
            format!(
                "{WATERMARK_KEY} SV1/SV2 are {values:?}, not 0: on a machine Windows 11 calls unsupported it draws \"System requirements not met\" over the clock (look at screenshot.png)"
            ),
        )
    }
}

/// The guest's clock against this machine's.
async fn clock(client: &GuestClient) -> VerifyCheck {
    match client.clock().await {
        Ok(reading) => judge_clock(reading.unix_ms - arena_shared::clock::now_unix_ms()),
        Err(err) => VerifyCheck::new("clock", Verdict::Skipped, format!("GET /v1/clock: {err}")),
    }
}

/// The `clock` check's rule: `ahead_ms` is the guest's clock minus this machine's.
pub fn judge_clock(ahead_ms: i64) -> VerifyCheck {
    let off = Duration::from_millis(ahead_ms.unsigned_abs());
    let way = if ahead_ms >= 0 { "ahead of" } else { "behind" };
    let detail = format!("the guest's clock is {:.1} s {way} this machine's", off.as_secs_f64());
    if off <= CLOCK_TOLERANCE {
        VerifyCheck::new("clock", Verdict::Pass, detail)
    } else {
        VerifyCheck::new(
            "clock",
            Verdict::Fail,
            format!(
                "{detail}: a whole number of hours is the RTC's base (the image's zone and -rtc base=utc|localtime)"
            ),
        )
    }
}

/// A browser's user-data folder by the getters' rule, and whether it exists.
async fn browser_folder(client: &GuestClient, name: &str, browser: Browser) -> VerifyCheck {
    let dir = match user_data_dir(client, browser).await {
        Ok(dir) => dir,
        Err(err) => return VerifyCheck::new(name, Verdict::Fail, err.to_string()),
    };
    let by = match &dir.policy_key {
        Some(key) => format!("its policy {key}\\UserDataDir"),
        None => "the default (no UserDataDir policy)".to_owned(),
    };
    match client.exists(&dir.path).await {
        Ok(seen) if seen.exists => VerifyCheck::new(name, Verdict::Pass, format!("{} by {by}; it exists", dir.path)),
        Ok(_) => VerifyCheck::new(
            name,
            Verdict::Warn,
            format!("{} by {by}; it does not exist yet (the browser is not installed or never ran)", dir.path),
        ),
        Err(err) => VerifyCheck::new(name, Verdict::Skipped, format!("{} by {by}; {err}", dir.path)),
    }
}

/// Days of licence left, from the sidecar.
pub fn licence(facts: Option<&ImageFacts>, now_unix: i64) -> VerifyCheck {
    let Some(facts) = facts else {
        return VerifyCheck::new(
            "licence",
            Verdict::Skipped,
            "the image has no sidecar (made before arena recorded one, or elsewhere)",
        );
    };
    let edition = facts.edition.as_deref().unwrap_or("an edition not recorded");
    match facts.licence_expires_unix {
        None => VerifyCheck::new("licence", Verdict::Pass, format!("{edition}: no end known here (not an evaluation)")),
        Some(expires) => {
            let date = arena_shared::calendar::iso_seconds(expires);
            let days = (expires - now_unix).div_euclid(86_400);
            if expires <= now_unix {
                VerifyCheck::new("licence", Verdict::Fail, format!("{edition}: ended on {date} UTC"))
            } else if days < LICENCE_WARN_DAYS {
                VerifyCheck::new("licence", Verdict::Warn, format!("{edition}: {days} days left, until {date} UTC"))
            } else {
                VerifyCheck::new("licence", Verdict::Pass, format!("{edition}: {days} days left, until {date} UTC"))
            }
        }
    }
}

/// The bundle's files, as they are written.
struct Files {
    dir: PathBuf,
    names: Vec<String>,
}

impl Files {
    fn write(&mut self, name: &str, bytes: &[u8]) -> Result<(), VmError> {
        let path = self.dir.join(name);
        arena_shared::atomic::write_atomic(&path, bytes)
            .map_err(|err| VmError::Invalid(format!("writing {}: {err}", path.display())))?;
        if !self.names.iter().any(|n| n == name) && name != REPORT_JSON && name != REPORT_TEXT {
            self.names.push(name.to_owned());
        }
        Ok(())
    }

    fn json(&mut self, name: &str, value: &impl Serialize) -> Result<(), VmError> {
        let text = serde_json::to_string_pretty(value).map_err(|err| VmError::Invalid(err.to_string()))?;
        self.write(name, format!("{text}\n").as_bytes())
    }
}

fn io(what: String) -> impl FnOnce(std::io::Error) -> VmError {
    move |source| VmError::Io { what, source }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_screen_is_judged_against_qemu_the_image_and_upstream() {
        let up = UPSTREAM_SCREEN;
        assert_eq!(judge_screen(up, false, up, false, up).verdict, Verdict::Pass);
        let black = judge_screen(up, false, up, true, up);
        assert!(black.verdict == Verdict::Fail && black.detail.contains("black"), "{black:?}");
        let apart = judge_screen(up, false, (1024, 768), false, up);
        assert!(apart.verdict == Verdict::Fail && apart.detail.contains("captures 1024x768"), "{apart:?}");
        let other = judge_screen((1920, 1080), false, (1920, 1080), false, up);
        assert!(other.verdict == Verdict::Fail && other.detail.contains("made for 1440x900"), "{other:?}");
        let own = judge_screen((1920, 1080), false, (1920, 1080), false, (1920, 1080));
        assert!(own.verdict == Verdict::Warn && own.detail.contains("upstream"), "{own:?}");
    }

    #[test]
    fn the_watermark_the_clock_and_the_licence() {
        let zero = Some(RegistryValue::Dword(0));
        assert_eq!(judge_watermark(&[zero.clone(), zero.clone()]).verdict, Verdict::Pass);
        assert_eq!(judge_watermark(&[zero, None]).verdict, Verdict::Warn);
        assert_eq!(judge_watermark(&[Some(RegistryValue::Dword(1)), None]).verdict, Verdict::Warn);

        let taken = judge_defender(CheckStatus::Fail, "Defender detected the guest's own files (Wacatac)");
        assert!(taken.verdict == Verdict::Fail && taken.detail.contains("Wacatac"), "{taken:?}");
        let facts = judge_defender(CheckStatus::Info, "Tamper Protection on, real-time protection off");
        assert!(facts.verdict == Verdict::Pass && facts.detail.starts_with("no detection"), "{facts:?}");
        assert_eq!(judge_defender(CheckStatus::Unavailable, "no Defender").verdict, Verdict::Skipped);

        assert_eq!(judge_clock(-3_000).verdict, Verdict::Pass);
        let hour = judge_clock(-3_600_000);
        assert!(hour.verdict == Verdict::Fail && hour.detail.contains("3600.0 s behind"), "{hour:?}");
        assert!(judge_clock(61_000).detail.contains("ahead of"));

        assert_eq!(licence(None, 0).verdict, Verdict::Skipped);
        let mut facts = ImageFacts {
            format: sidecar::FORMAT,
            firmware: "bios".into(),
            secure_boot: false,
            screen: UPSTREAM_SCREEN,
            machine: "q35".into(),
            disk_bus: crate::qemu::DiskBus::Ahci,
            nic: crate::qemu::NicModel::E1000e,
            tpm: false,
            edition: Some("EnterpriseEval".into()),
            build: None,
            language: None,
            timezone: None,
            installed_unix: 0,
            licence_expires_unix: sidecar::licence_expiry(Some("EnterpriseEval"), 0),
            uefi_vars: None,
            startup_apps_off: Vec::new(),
            allowed_failed_steps: Vec::new(),
        };
        assert_eq!(licence(Some(&facts), 0).verdict, Verdict::Pass);
        let near = licence(Some(&facts), 80 * 86_400);
        assert!(near.verdict == Verdict::Warn && near.detail.contains("10 days left"), "{near:?}");
        assert_eq!(licence(Some(&facts), 91 * 86_400).verdict, Verdict::Fail);
        facts.licence_expires_unix = None;
        assert_eq!(licence(Some(&facts), 91 * 86_400).verdict, Verdict::Pass);
    }

    #[test]
    fn the_text_report_lists_every_check_and_the_bundle() {
        let report = VerifyReport {
            image: "golden.qcow2".into(),
            started_unix: 1_790_000_000,
            accel: "tcg".into(),
            checks: vec![
                VerifyCheck::new("healthy", Verdict::Pass, "up"),
                VerifyCheck::new("watermark", Verdict::Warn, "not set"),
                VerifyCheck::new("clock", Verdict::Fail, "an hour behind"),
            ],
            files: vec!["screendump.png".into(), REPORT_JSON.into()],
        };
        assert!(!report.passed());
        let text = report.render_text();
        assert!(text.contains("PASS healthy    up") && text.contains("FAIL clock      an hour behind"), "{text}");
        assert!(text.contains("1 passed, 1 warnings, 1 failed, 0 skipped"), "{text}");
        assert!(text.contains("bundle: screendump.png, verify.json"), "{text}");
    }
}
