//! The OEM folder of a new Windows image (`arena prep`): staging it, checking a
//! staged folder against its manifest, and waiting for a freshly prepared VM's
//! guest to come up, component by component.
//!
//! The OEM folder is what dockur/windows copies to `C:\OEM` and runs
//! `C:\OEM\install.bat` from at first logon: the cross-built `arena-guest.exe` and
//! `arena-guest-logon.exe` (the logon task's launcher, built beside it),
//! `arena-input-recorder.exe` (the input check's recorder window, built beside them and
//! left in `C:\OEM`, where `arena doctor --input` starts it), the PowerShell of
//! `setup-scripts/`, a fresh API token (`arena-token`) and a
//! `manifest.json` with versions and the SHA-256 of every staged file.
//!
//! It is not the installer (that is `setup-scripts/install-guest.ps1`, which runs
//! inside Windows), and it starts no VM: the README of `setup-scripts/` says how
//! to boot one from the staged folder.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use arena_shared::health::{Component, ComponentHealth, HealthReport, Readiness};

use arena_client::client::GuestClient;
use arena_client::error::ClientError;

/// Name of the guest exe inside the staged folder (install-guest.ps1 looks for it there).
pub const EXE_NAME: &str = "arena-guest.exe";
/// Name of the logon task's launcher, a GUI-subsystem exe that ships beside the guest
/// exe (`arena-guest logon-task install` refuses to register a task without it); it is
/// staged from the folder of the exe given or found.
pub const LAUNCHER_NAME: &str = "arena-guest-logon.exe";
/// Name of the input recorder (`arena-input-recorder`), which ships beside the guest
/// exe and stays in `C:\OEM` (`arena_inputcheck::OEM_RECORDER`, where `arena doctor
/// --input` starts it); it is staged from the folder of the exe given or found.
pub const RECORDER_NAME: &str = "arena-input-recorder.exe";
/// Name of the token file inside the staged folder (install-guest.ps1 reads it).
pub const TOKEN_NAME: &str = "arena-token";
/// Name of the manifest inside the staged folder.
pub const MANIFEST_NAME: &str = "manifest.json";
/// Version of the manifest's layout, bumped when a field changes meaning.
pub const MANIFEST_FORMAT: u32 = 1;
/// Where the cross build (`scripts/build-windows.sh`) leaves the exe, relative to the
/// workspace root: release first, since that is what an image should ship.
pub const CROSS_BUILT_EXES: [&str; 2] = [
    "target/windows/x86_64-pc-windows-gnu/release/arena-guest.exe",
    "target/windows/x86_64-pc-windows-gnu/debug/arena-guest.exe",
];

/// Bytes of entropy in a generated token (256 bits).
const TOKEN_BYTES: usize = 32;

/// What went wrong while staging, verifying or waiting.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PrepError {
    /// A file or directory could not be read or written.
    #[error("{action} {}: {source}", path.display())]
    Io { action: &'static str, path: PathBuf, source: std::io::Error },

    /// The output folder holds files and `force` was not given.
    #[error("{} is not empty (give --force to stage into it anyway; files not staged are left alone)", .0.display())]
    NotEmpty(PathBuf),

    /// No guest exe was given and none was found where the cross build puts it.
    #[error("no arena-guest.exe: tried {tried} (run scripts/build-windows.sh --release, or give --exe)")]
    NoExe { tried: String },

    /// The logon task's launcher is not beside the guest exe.
    #[error(
        "no {LAUNCHER_NAME} beside {}: expected {} (scripts/build-windows.sh builds both exes into one folder)",
        exe.display(),
        launcher.display()
    )]
    NoLauncher { exe: PathBuf, launcher: PathBuf },

    /// The input recorder is not beside the guest exe.
    #[error(
        "no {RECORDER_NAME} beside {}: expected {} (scripts/build-windows.sh builds it into the exes' folder; \
         on Windows, cargo build --release -p arena-input-recorder)",
        exe.display(),
        recorder.display()
    )]
    NoRecorder { exe: PathBuf, recorder: PathBuf },

    /// The exe given is not a Windows program.
    #[error("{} is not a Windows executable (no MZ header): the guest must be built for Windows", .0.display())]
    NotWindowsExe(PathBuf),

    /// The scripts folder lacks a file the image needs.
    #[error("the scripts folder {} has no {name}", dir.display())]
    MissingScript { dir: PathBuf, name: &'static str },

    /// The operating system's random source failed.
    #[error("generating a token: {0}")]
    Random(String),

    /// The manifest is missing or is not one this version can read.
    #[error("manifest {}: {reason}", path.display())]
    Manifest { path: PathBuf, reason: String },

    /// The guest did not become healthy in time.
    #[error("{0}")]
    NotHealthy(WaitTimeout),

    /// The guest refused the token: waiting longer will not help.
    #[error("guest {guest}: {message}")]
    TokenRefused { guest: String, message: String },
}

fn io<'a>(action: &'static str, path: &'a Path) -> impl FnOnce(std::io::Error) -> PrepError + 'a {
    move |source| PrepError::Io { action, path: path.to_path_buf(), source }
}

/// One staged file in the manifest.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct FileEntry {
    /// Lowercase hex SHA-256 of the file's bytes.
    pub sha256: String,
    pub size: u64,
}

/// `manifest.json`: what was staged, from which build, with the hash of every file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    pub format: u32,
    /// Version of the `arena` that staged the folder.
    pub arena_version: String,
    /// Commit of the source tree the scripts came from, when it is a git checkout.
    #[serde(default)]
    pub git_commit: Option<String>,
    /// Whether that checkout had uncommitted changes.
    #[serde(default)]
    pub git_dirty: Option<bool>,
    /// Seconds since the Unix epoch when the folder was staged.
    pub created_unix: u64,
    /// Where the exe was copied from.
    pub exe_source: String,
    /// Every staged file but the manifest, by `/`-separated path relative to the folder.
    pub files: BTreeMap<String, FileEntry>,
}

/// How to stage a folder.
#[derive(Debug, Clone)]
pub struct StageOptions {
    /// The folder to fill (created when missing).
    pub out: PathBuf,
    /// The guest exe; `None` looks for the cross build under `workspace`.
    pub exe: Option<PathBuf>,
    /// The folder of PowerShell scripts and answer-file snippets.
    pub scripts: PathBuf,
    /// A second copy of the token, for the host client (`None`: only the staged one).
    pub token_out: Option<PathBuf>,
    /// Stage into a folder that already holds files.
    pub force: bool,
    /// Where to look for the cross-built exe and the git checkout.
    pub workspace: PathBuf,
}

/// What [`stage`] did.
#[derive(Debug, Clone)]
pub struct Staged {
    pub manifest: Manifest,
    /// The staged token file.
    pub token_path: PathBuf,
    /// The host's copy of the token, when one was written.
    pub token_out: Option<PathBuf>,
}

/// The exe a stage without `--exe` uses: the first cross build that exists.
pub fn default_exe(workspace: &Path) -> Option<PathBuf> {
    CROSS_BUILT_EXES.iter().map(|rel| workspace.join(rel)).find(|p| p.is_file())
}

/// Where the host client's copy of the token goes by default:
/// `$XDG_CONFIG_HOME/arena/token`, else `~/.config/arena/token`.
pub fn default_token_out() -> Option<PathBuf> {
    let config = std::env::var_os("XDG_CONFIG_HOME").filter(|v| !v.is_empty()).map(PathBuf::from).or_else(|| {
        std::env::var_os("HOME").filter(|v| !v.is_empty()).map(|home| PathBuf::from(home).join(".config"))
    })?;
    Some(config.join("arena").join("token"))
}

/// A fresh 256-bit token from the operating system's random source, as 64 hex digits
/// (plain ASCII, so it survives every shell, registry and file encoding on the way).
///
/// # Errors
///
/// [`PrepError::Random`] if the operating system cannot supply random bytes.
pub fn generate_token() -> Result<String, PrepError> {
    use rand::TryRngCore;
    let mut bytes = [0u8; TOKEN_BYTES];
    rand::rngs::OsRng.try_fill_bytes(&mut bytes).map_err(|err| PrepError::Random(err.to_string()))?;
    Ok(hex::encode(bytes))
}

/// Writes `token` and a newline to `path`, readable by its owner only (mode 0600 on
/// Unix), creating the parent folder (0700 when it is new).
///
/// # Errors
///
/// [`PrepError::Io`] naming the file.
pub fn write_token_file(path: &Path, token: &str) -> Result<(), PrepError> {
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        if !parent.exists() {
            create_private_dir(parent)?;
        }
    }
    // Remove first, so the mode below applies: `mode` only counts when the file is created.
    match std::fs::remove_file(path) {
        Ok(()) => {}
        Err(err) if err.kind() == std::io::ErrorKind::NotFound => {}
        Err(source) => return Err(PrepError::Io { action: "replacing", path: path.to_path_buf(), source }),
    }
    let mut options = std::fs::OpenOptions::new();
    options.write(true).create_new(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.mode(0o600);
    }
    let mut file = options.open(path).map_err(io("creating", path))?;
    file.write_all(format!("{token}\n").as_bytes()).map_err(io("writing", path))?;
    file.sync_all().map_err(io("syncing", path))
}

fn create_private_dir(dir: &Path) -> Result<(), PrepError> {
    let mut builder = std::fs::DirBuilder::new();
    builder.recursive(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::DirBuilderExt;
        builder.mode(0o700);
    }
    builder.create(dir).map_err(io("creating", dir))
}

/// Fills `options.out` with the guest's two exes and the input recorder, the scripts, a fresh token and the manifest.
///
/// The scripts folder is copied as it is (hidden files left out), so `install.bat`
/// and `setup.ps1` land at the top of the folder, where dockur runs them from.
/// Files already in a forced folder that this stage does not write are left alone
/// and are not in the manifest ([`verify`] lists them as extra).
///
/// # Errors
///
/// [`PrepError::NotEmpty`] for a non-empty folder without `force`,
/// [`PrepError::NoExe`] or [`PrepError::NotWindowsExe`] for a missing or wrong exe,
/// [`PrepError::NoLauncher`] when the logon task's launcher is not beside the exe,
/// [`PrepError::NoRecorder`] when the input recorder is not,
/// [`PrepError::MissingScript`] when the scripts lack `install.bat`, `setup.ps1`,
/// `install-guest.ps1` or `arena-common.ps1` (which the others dot-source), and [`PrepError::Io`] naming the file that failed.
pub fn stage(options: &StageOptions) -> Result<Staged, PrepError> {
    let out = &options.out;
    if out.exists() {
        let mut entries = std::fs::read_dir(out).map_err(io("listing", out))?;
        if entries.next().is_some() && !options.force {
            return Err(PrepError::NotEmpty(out.clone()));
        }
    }
    let exe = match &options.exe {
        Some(exe) => exe.clone(),
        None => default_exe(&options.workspace).ok_or_else(|| PrepError::NoExe {
            tried: CROSS_BUILT_EXES
                .iter()
                .map(|rel| options.workspace.join(rel).display().to_string())
                .collect::<Vec<_>>()
                .join(", "),
        })?,
    };
    check_windows_exe(&exe)?;
    let launcher = exe.with_file_name(LAUNCHER_NAME);
    if !launcher.is_file() {
        return Err(PrepError::NoLauncher { exe, launcher });
    }
    check_windows_exe(&launcher)?;
    let recorder = exe.with_file_name(RECORDER_NAME);
    if !recorder.is_file() {
        return Err(PrepError::NoRecorder { exe, recorder });
    }
    check_windows_exe(&recorder)?;
    for name in ["install.bat", "setup.ps1", "install-guest.ps1", "arena-common.ps1"] {
        if !options.scripts.join(name).is_file() {
            return Err(PrepError::MissingScript { dir: options.scripts.clone(), name });
        }
    }

    std::fs::create_dir_all(out).map_err(io("creating", out))?;
    let mut written = Vec::new();
    copy_tree(&options.scripts, out, &mut written)?;
    let staged_exe = out.join(EXE_NAME);
    std::fs::copy(&exe, &staged_exe).map_err(io("copying the exe to", &staged_exe))?;
    let staged_launcher = out.join(LAUNCHER_NAME);
    std::fs::copy(&launcher, &staged_launcher).map_err(io("copying the launcher to", &staged_launcher))?;
    let staged_recorder = out.join(RECORDER_NAME);
    std::fs::copy(&recorder, &staged_recorder).map_err(io("copying the input recorder to", &staged_recorder))?;

    let token = generate_token()?;
    let token_path = out.join(TOKEN_NAME);
    write_token_file(&token_path, &token)?;
    written.push(staged_exe);
    written.push(staged_launcher);
    written.push(staged_recorder);
    written.push(token_path.clone());
    if let Some(host_copy) = &options.token_out {
        write_token_file(host_copy, &token)?;
    }

    let (git_commit, git_dirty) = git_state(&options.scripts);
    let manifest = Manifest {
        format: MANIFEST_FORMAT,
        arena_version: env!("CARGO_PKG_VERSION").to_owned(),
        git_commit,
        git_dirty,
        created_unix: SystemTime::now().duration_since(UNIX_EPOCH).map(|d| d.as_secs()).unwrap_or(0),
        exe_source: exe.display().to_string(),
        files: hash_files(out, &written)?,
    };
    let manifest_path = out.join(MANIFEST_NAME);
    let mut text = serde_json::to_string_pretty(&manifest)
        .map_err(|err| PrepError::Manifest { path: manifest_path.clone(), reason: err.to_string() })?;
    text.push('\n');
    // Atomically: a staged folder with a half-written manifest would check as broken.
    arena_shared::atomic::write_atomic(&manifest_path, text.as_bytes()).map_err(io("writing", &manifest_path))?;
    tracing::info!(out = %out.display(), files = manifest.files.len(), "staged the OEM folder");
    Ok(Staged { manifest, token_path, token_out: options.token_out.clone() })
}

fn check_windows_exe(exe: &Path) -> Result<(), PrepError> {
    let mut head = [0u8; 2];
    let mut file = std::fs::File::open(exe).map_err(io("opening the exe", exe))?;
    std::io::Read::read_exact(&mut file, &mut head).map_err(|_| PrepError::NotWindowsExe(exe.to_path_buf()))?;
    if &head != b"MZ" {
        return Err(PrepError::NotWindowsExe(exe.to_path_buf()));
    }
    Ok(())
}

/// Copies every file under `from` into `to`, keeping the folder layout, and adds the
/// copies to `written`; hidden files and folders (editor and VCS leftovers) are not staged.
fn copy_tree(from: &Path, to: &Path, written: &mut Vec<PathBuf>) -> Result<(), PrepError> {
    for entry in std::fs::read_dir(from).map_err(io("listing", from))? {
        let entry = entry.map_err(io("listing", from))?;
        let name = entry.file_name();
        if name.to_string_lossy().starts_with('.') {
            continue;
        }
        let source = entry.path();
        let target = to.join(&name);
        if source.is_dir() {
            std::fs::create_dir_all(&target).map_err(io("creating", &target))?;
            copy_tree(&source, &target, written)?;
        } else {
            std::fs::copy(&source, &target).map_err(io("copying to", &target))?;
            written.push(target);
        }
    }
    Ok(())
}

/// The SHA-256 and size of `files` (all under `dir`), by relative path.
fn hash_files(dir: &Path, files: &[PathBuf]) -> Result<BTreeMap<String, FileEntry>, PrepError> {
    files.iter().map(|path| Ok((relative_name(dir, path), hash_file(path)?))).collect()
}

/// The SHA-256 and size of every file under `dir` but the manifest, by relative path.
fn hash_tree(dir: &Path) -> Result<BTreeMap<String, FileEntry>, PrepError> {
    let mut files = BTreeMap::new();
    let mut pending = vec![dir.to_path_buf()];
    while let Some(current) = pending.pop() {
        for entry in std::fs::read_dir(&current).map_err(io("listing", &current))? {
            let path = entry.map_err(io("listing", &current))?.path();
            if path.is_dir() {
                pending.push(path);
                continue;
            }
            let relative = relative_name(dir, &path);
            if relative == MANIFEST_NAME {
                continue;
            }
            files.insert(relative, hash_file(&path)?);
        }
    }
    Ok(files)
}

fn relative_name(root: &Path, path: &Path) -> String {
    let relative = path.strip_prefix(root).unwrap_or(path);
    relative.components().map(|c| c.as_os_str().to_string_lossy().into_owned()).collect::<Vec<_>>().join("/")
}

fn hash_file(path: &Path) -> Result<FileEntry, PrepError> {
    let mut file = std::fs::File::open(path).map_err(io("opening", path))?;
    let mut hasher = Sha256::new();
    let size = std::io::copy(&mut file, &mut hasher).map_err(io("reading", path))?;
    Ok(FileEntry { sha256: hex::encode(hasher.finalize()), size })
}

/// The commit and dirtiness of the checkout holding `dir`, when git is there to say.
fn git_state(dir: &Path) -> (Option<String>, Option<bool>) {
    let git = |args: &[&str]| -> Option<String> {
        let output = std::process::Command::new("git").arg("-C").arg(dir).args(args).output().ok()?;
        output.status.success().then(|| String::from_utf8_lossy(&output.stdout).trim().to_owned())
    };
    let commit = git(&["rev-parse", "HEAD"]).filter(|c| !c.is_empty());
    let dirty = commit.as_ref().and_then(|_| git(&["status", "--porcelain", "--", "."])).map(|s| !s.is_empty());
    (commit, dirty)
}

/// Reads `dir/manifest.json`.
///
/// # Errors
///
/// [`PrepError::Manifest`] when it is missing, not JSON of this shape, or of a
/// newer format.
pub fn read_manifest(dir: &Path) -> Result<Manifest, PrepError> {
    let path = dir.join(MANIFEST_NAME);
    let text = std::fs::read_to_string(&path)
        .map_err(|err| PrepError::Manifest { path: path.clone(), reason: err.to_string() })?;
    let manifest: Manifest = serde_json::from_str(&text)
        .map_err(|err| PrepError::Manifest { path: path.clone(), reason: err.to_string() })?;
    if manifest.format > MANIFEST_FORMAT {
        return Err(PrepError::Manifest {
            path,
            reason: format!("format {} is newer than this arena understands ({MANIFEST_FORMAT})", manifest.format),
        });
    }
    Ok(manifest)
}

/// A file whose bytes are not those the manifest recorded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Mismatch {
    pub path: String,
    pub expected: FileEntry,
    pub actual: FileEntry,
}

/// What [`verify`] found.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct VerifyReport {
    /// Files whose hash matches.
    pub matched: Vec<String>,
    /// Files whose hash or size differs.
    pub mismatched: Vec<Mismatch>,
    /// Files the manifest lists that are gone.
    pub missing: Vec<String>,
    /// Files in the folder the manifest does not list (installers a user added, say):
    /// reported, but not a failure.
    pub extra: Vec<String>,
}

impl VerifyReport {
    /// Whether every listed file is present with its recorded hash.
    pub fn is_ok(&self) -> bool {
        self.mismatched.is_empty() && self.missing.is_empty()
    }
}

/// Re-hashes every file of a staged folder against its manifest.
///
/// # Errors
///
/// [`PrepError::Manifest`] for an unreadable manifest and [`PrepError::Io`] for a
/// file that cannot be read; differences are in the report, not errors.
pub fn verify(dir: &Path) -> Result<VerifyReport, PrepError> {
    let manifest = read_manifest(dir)?;
    let found = hash_tree(dir)?;
    let mut report = VerifyReport::default();
    for (path, expected) in &manifest.files {
        match found.get(path) {
            None => report.missing.push(path.clone()),
            Some(actual) if actual == expected => report.matched.push(path.clone()),
            Some(actual) => report.mismatched.push(Mismatch {
                path: path.clone(),
                expected: expected.clone(),
                actual: actual.clone(),
            }),
        }
    }
    report.extra = found.keys().filter(|path| !manifest.files.contains_key(*path)).cloned().collect();
    Ok(report)
}

/// Progress of [`wait_healthy`], for the caller to show.
#[derive(Debug, Clone, Copy)]
pub enum WaitEvent<'a> {
    /// The guest could not be reached (said once per new reason).
    Unreachable { error: &'a str },
    /// The guest answered its first health report.
    Reachable { report: &'a HealthReport },
    /// A component came up.
    Up { component: &'a ComponentHealth },
    /// A component that was up went down again.
    Down { component: &'a ComponentHealth },
    /// The configured token was accepted by an authenticated route.
    TokenAccepted,
}

/// What was still missing when [`wait_healthy`] gave up.
#[derive(Debug, Clone, PartialEq)]
pub struct WaitTimeout {
    pub guest: String,
    pub waited: Duration,
    /// Whether the guest ever answered.
    pub reached: bool,
    /// The components not up at the end, with the guest's reason.
    pub missing: Vec<ComponentHealth>,
    /// The last connection error, when the guest never answered or stopped answering.
    pub last_error: Option<String>,
}

impl std::fmt::Display for WaitTimeout {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "guest {}: not healthy after {} s: ", self.guest, self.waited.as_secs())?;
        if !self.reached {
            return write!(
                f,
                "it never answered ({}); is the VM up, did install-guest.ps1 finish (%ProgramData%\\arena\\logs\\setup.log), and does the firewall rule let the host in?",
                self.last_error.as_deref().unwrap_or("no answer")
            );
        }
        let missing: Vec<String> =
            self.missing.iter().map(|c| format!("{} ({})", component_name(c.component), c.detail)).collect();
        write!(f, "still down: {}", missing.join("; "))?;
        if let Some(err) = &self.last_error {
            write!(f, "; last error: {err}")?;
        }
        Ok(())
    }
}

/// The wire name of a component (`capture`, `accessibility`, ...).
pub fn component_name(component: Component) -> String {
    serde_json::to_value(component)
        .ok()
        .and_then(|v| v.as_str().map(str::to_owned))
        .unwrap_or_else(|| format!("{component:?}"))
}

/// Polls the guest's `/v1/health` every `poll` until every component it reports
/// that gates readiness is up (all but `shell`), telling `progress` about each
/// step, then, when the client has a token, checks that an authenticated route
/// accepts it.
///
/// # Errors
///
/// [`PrepError::NotHealthy`] after `overall` with what is still down, and
/// [`PrepError::TokenRefused`] at once when the guest refuses the token.
pub async fn wait_healthy(
    client: &GuestClient,
    overall: Duration,
    poll: Duration,
    progress: impl FnMut(WaitEvent<'_>),
) -> Result<HealthReport, PrepError> {
    wait_healthy_but(client, overall, poll, &[], progress).await
}

/// [`wait_healthy`], with the components in `ignore` left out of the wait (a
/// prepare that let a failed OEM step through does not wait for `setup`).
///
/// # Errors
///
/// As [`wait_healthy`].
pub async fn wait_healthy_but(
    client: &GuestClient,
    overall: Duration,
    poll: Duration,
    ignore: &[Component],
    mut progress: impl FnMut(WaitEvent<'_>),
) -> Result<HealthReport, PrepError> {
    let waited = |c: &ComponentHealth| c.component.gates_readiness() && !ignore.contains(&c.component);
    let started = Instant::now();
    let mut reached = false;
    let mut up: Vec<Component> = Vec::new();
    let mut last_error: Option<String> = None;
    let mut last_report: Option<HealthReport> = None;
    loop {
        match client.health().await {
            Ok(report) => {
                if !reached {
                    reached = true;
                    progress(WaitEvent::Reachable { report: &report });
                }
                last_error = None;
                for component in &report.components {
                    let was_up = up.contains(&component.component);
                    if component.ok && !was_up {
                        up.push(component.component);
                        progress(WaitEvent::Up { component });
                    } else if !component.ok && was_up {
                        up.retain(|c| *c != component.component);
                        progress(WaitEvent::Down { component });
                    }
                }
                // The shell's settle is not readiness: the fleet waits for it on its own.
                let all_up = report.components.iter().any(waited)
                    && report.components.iter().filter(|c| waited(c)).all(|c| c.ok);
                if all_up || (report.components.is_empty() && report.status == Readiness::Ready) {
                    check_token(client).await?;
                    if client.config().token.is_some() {
                        progress(WaitEvent::TokenAccepted);
                    }
                    return Ok(report);
                }
                last_report = Some(report);
            }
            Err(err) => {
                let text = err.to_string();
                if last_error.as_deref() != Some(text.as_str()) {
                    progress(WaitEvent::Unreachable { error: &text });
                }
                last_error = Some(text);
            }
        }
        let remaining = overall.saturating_sub(started.elapsed());
        if remaining.is_zero() {
            let missing = match &last_report {
                Some(report) => report.components.iter().filter(|c| !c.ok && waited(c)).cloned().collect(),
                None => Vec::new(),
            };
            return Err(PrepError::NotHealthy(WaitTimeout {
                guest: client.base_url().to_owned(),
                waited: started.elapsed(),
                reached,
                missing,
                last_error,
            }));
        }
        tokio::time::sleep(poll.min(remaining)).await;
    }
}

/// With a token configured, one authenticated read (`GET /v1/folders`) proves the
/// guest knows the same token; without one there is nothing to check.
async fn check_token(client: &GuestClient) -> Result<(), PrepError> {
    if client.config().token.is_none() {
        return Ok(());
    }
    match client.folders().await {
        Ok(_) => Ok(()),
        Err(err @ ClientError::Api { status: 401 | 403, .. }) => Err(PrepError::TokenRefused {
            guest: client.base_url().to_owned(),
            message: format!("the token was refused: {err}"),
        }),
        // Any other failure still means the token got past the guard.
        Err(err) => {
            tracing::debug!(error = %err, "token check answered with an error past the guard");
            Ok(())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tokens_are_256_bits_of_hex_and_differ() {
        let a = generate_token().unwrap();
        let b = generate_token().unwrap();
        assert_eq!(a.len(), 64);
        assert!(a.bytes().all(|c| c.is_ascii_hexdigit() && !c.is_ascii_uppercase()), "{a}");
        assert_ne!(a, b);
    }

    #[test]
    fn relative_names_use_forward_slashes() {
        fn check(root: &str, path: &str, expected: &str) {
            assert_eq!(relative_name(Path::new(root), Path::new(path)), expected);
        }
        check("/oem", "/oem/setup.ps1", "setup.ps1");
        check("/oem", "/oem/unattend/autounattend-snippet.xml", "unattend/autounattend-snippet.xml");
    }

    #[test]
    fn timeouts_say_what_is_missing() {
        let down = ComponentHealth {
            component: Component::Accessibility,
            ok: false,
            detail: "UIA not ready".into(),
            elapsed_ms: 3,
        };
        let text = WaitTimeout {
            guest: "http://g:5000".into(),
            waited: Duration::from_secs(9),
            reached: true,
            missing: vec![down],
            last_error: None,
        }
        .to_string();
        assert_eq!(text, "guest http://g:5000: not healthy after 9 s: still down: accessibility (UIA not ready)");
        let never = WaitTimeout {
            guest: "http://g:5000".into(),
            waited: Duration::from_secs(1),
            reached: false,
            missing: vec![],
            last_error: Some("refused".into()),
        }
        .to_string();
        assert!(never.contains("never answered (refused)"), "{never}");
    }

    #[cfg(unix)]
    #[test]
    fn token_files_are_private() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("cfg/arena/token");
        write_token_file(&path, "abc").unwrap();
        write_token_file(&path, "def").unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "def\n");
        assert_eq!(std::fs::metadata(&path).unwrap().permissions().mode() & 0o777, 0o600);
        assert_eq!(std::fs::metadata(path.parent().unwrap()).unwrap().permissions().mode() & 0o777, 0o700);
    }
}
