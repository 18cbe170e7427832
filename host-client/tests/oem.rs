//! `arena prep`: a staged OEM folder matches its manifest, its token is the one a
//! guest started with `--token-file` on it accepts (and a wrong one is refused),
//! `verify` notices tampering, and `wait_healthy` reports stage by stage.
//!
//! The guest is the in-process stub (`arena_guest::build_state` with
//! `token_file` pointing into the staged folder), so no Windows is needed; the same
//! check against the real Windows exe under Wine is `tests/tests/wine_prep.rs`.

use std::path::{Path, PathBuf};
use std::time::Duration;

use arena_client::client::{sha256_hex, ClientConfig, GuestClient};
use arena_client::error::ClientError;
use arena_test_support::StubGuest;
use arena_vm::oem::{self, PrepError, StageOptions, WaitEvent};

fn scripts_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join("setup-scripts")
}

/// A file that passes for a Windows exe (it starts with `MZ`), with a launcher and the
/// input recorder beside it as the cross build leaves them; the stub guest runs none.
fn fake_exe(dir: &Path) -> PathBuf {
    let path = dir.join("arena-guest.exe");
    std::fs::write(&path, b"MZ\x90\x00 not really a program").expect("fake exe");
    std::fs::write(dir.join(oem::LAUNCHER_NAME), b"MZ\x90\x00 not really a launcher").expect("fake launcher");
    std::fs::write(dir.join(oem::RECORDER_NAME), b"MZ\x90\x00 not really a recorder").expect("fake recorder");
    path
}

fn options(out: &Path, exe: &Path, token_out: &Path) -> StageOptions {
    StageOptions {
        out: out.to_path_buf(),
        exe: Some(exe.to_path_buf()),
        scripts: scripts_dir(),
        token_out: Some(token_out.to_path_buf()),
        force: false,
        workspace: PathBuf::from("."),
    }
}

/// A stub guest reading its token from a staged token file.
async fn start_guest(token_file: &Path) -> StubGuest {
    let token_file = token_file.to_path_buf();
    StubGuest::start_with(|config| config.token_file = Some(token_file)).await
}

fn client(url: &str, token: Option<&str>) -> GuestClient {
    GuestClient::new(
        url,
        ClientConfig { token: token.map(str::to_owned), timeout: Duration::from_secs(10), retries: 0 },
    )
    .expect("client")
}

#[test]
fn a_staged_folder_matches_its_manifest() {
    let work = tempfile::tempdir().unwrap();
    let exe = fake_exe(work.path());
    let out = work.path().join("oem");
    let token_out = work.path().join("config/arena/token");
    let staged = oem::stage(&options(&out, &exe, &token_out)).expect("stage");

    // The layout dockur expects, and the files install-guest.ps1 reads.
    for name in [
        "install.bat",
        "setup.ps1",
        "install-guest.ps1",
        "apps.json",
        "unattend/autounattend-snippet.xml",
        "arena-guest.exe",
        "arena-guest-logon.exe",
        "arena-input-recorder.exe",
        "arena-token",
    ] {
        assert!(
            staged.manifest.files.contains_key(name),
            "{name} is not in the manifest: {:?}",
            staged.manifest.files.keys()
        );
    }
    assert!(!staged.manifest.files.contains_key("manifest.json"), "the manifest does not list itself");
    // Every entry is the file's real hash and size, and the manifest on disk is the one returned.
    for (name, entry) in &staged.manifest.files {
        let bytes = std::fs::read(out.join(name)).unwrap();
        assert_eq!(entry.sha256, sha256_hex(&bytes), "{name}");
        assert_eq!(entry.size, bytes.len() as u64, "{name}");
    }
    assert_eq!(oem::read_manifest(&out).unwrap(), staged.manifest);
    assert_eq!(staged.manifest.arena_version, env!("CARGO_PKG_VERSION"));
    assert_eq!(std::fs::read(out.join("arena-guest.exe")).unwrap(), std::fs::read(&exe).unwrap());
    assert_eq!(
        std::fs::read(out.join(oem::LAUNCHER_NAME)).unwrap(),
        std::fs::read(work.path().join(oem::LAUNCHER_NAME)).unwrap()
    );
    // The recorder, where `arena doctor --input` starts it on a prepared image.
    assert_eq!(
        std::fs::read(out.join(oem::RECORDER_NAME)).unwrap(),
        std::fs::read(work.path().join(oem::RECORDER_NAME)).unwrap()
    );
    assert_eq!(arena_inputcheck::OEM_RECORDER, format!(r"C:\OEM\{}", oem::RECORDER_NAME));

    // The token: 64 hex digits, the same in the folder and in the host's copy.
    let token = std::fs::read_to_string(&staged.token_path).unwrap();
    assert_eq!(token.trim().len(), 64);
    assert_eq!(std::fs::read_to_string(&token_out).unwrap(), token);

    let report = oem::verify(&out).unwrap();
    assert!(report.is_ok(), "{report:?}");
    assert_eq!(report.matched.len(), staged.manifest.files.len());
    assert!(report.extra.is_empty() && report.missing.is_empty());
}

#[test]
fn staging_refuses_a_non_empty_folder_without_force_and_a_non_windows_exe() {
    let work = tempfile::tempdir().unwrap();
    let exe = fake_exe(work.path());
    let out = work.path().join("oem");
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(out.join("keep-me.txt"), "user file").unwrap();
    let token_out = work.path().join("token");

    let err = oem::stage(&options(&out, &exe, &token_out)).unwrap_err();
    assert!(matches!(err, PrepError::NotEmpty(_)), "{err}");
    assert!(!out.join("setup.ps1").exists(), "nothing is written when refused");

    let first = oem::stage(&StageOptions { force: true, ..options(&out, &exe, &token_out) }).expect("forced stage");
    assert_eq!(
        std::fs::read_to_string(out.join("keep-me.txt")).unwrap(),
        "user file",
        "unrelated files are left alone"
    );
    assert!(!first.manifest.files.contains_key("keep-me.txt"), "only staged files are in the manifest");
    assert_eq!(oem::verify(&out).unwrap().extra, ["keep-me.txt"]);
    // A second forced stage makes a new token.
    let second = oem::stage(&StageOptions { force: true, ..options(&out, &exe, &token_out) }).expect("restage");
    assert_ne!(first.manifest.files["arena-token"].sha256, second.manifest.files["arena-token"].sha256);

    let linux = work.path().join("arena-guest");
    std::fs::write(&linux, b"\x7fELF a Linux build").unwrap();
    let err = oem::stage(&options(&work.path().join("oem2"), &linux, &token_out)).unwrap_err();
    assert!(matches!(err, PrepError::NotWindowsExe(_)), "{err}");

    // The logon task's launcher must be beside the exe, and be a Windows program too.
    let lonely = work.path().join("lonely");
    std::fs::create_dir_all(&lonely).unwrap();
    let lonely_exe = lonely.join("arena-guest.exe");
    std::fs::copy(&exe, &lonely_exe).unwrap();
    let err = oem::stage(&options(&work.path().join("oem4"), &lonely_exe, &token_out)).unwrap_err();
    assert!(matches!(err, PrepError::NoLauncher { .. }), "{err}");
    assert!(err.to_string().contains("no arena-guest-logon.exe beside "), "{err}");
    assert!(!work.path().join("oem4").join("setup.ps1").exists(), "nothing is written when refused");
    std::fs::write(lonely.join(oem::LAUNCHER_NAME), b"\x7fELF").unwrap();
    let err = oem::stage(&options(&work.path().join("oem4"), &lonely_exe, &token_out)).unwrap_err();
    assert!(matches!(&err, PrepError::NotWindowsExe(path) if path.ends_with(oem::LAUNCHER_NAME)), "{err}");
    // So must the input recorder.
    std::fs::write(lonely.join(oem::LAUNCHER_NAME), b"MZ a launcher").unwrap();
    let err = oem::stage(&options(&work.path().join("oem4"), &lonely_exe, &token_out)).unwrap_err();
    assert!(matches!(err, PrepError::NoRecorder { .. }), "{err}");
    assert!(err.to_string().contains("no arena-input-recorder.exe beside "), "{err}");
    assert!(!work.path().join("oem4").join("setup.ps1").exists(), "nothing is written when refused");
    std::fs::write(lonely.join(oem::RECORDER_NAME), b"\x7fELF").unwrap();
    let err = oem::stage(&options(&work.path().join("oem4"), &lonely_exe, &token_out)).unwrap_err();
    assert!(matches!(&err, PrepError::NotWindowsExe(path) if path.ends_with(oem::RECORDER_NAME)), "{err}");

    let err = oem::stage(&StageOptions {
        scripts: work.path().to_path_buf(),
        ..options(&work.path().join("oem3"), &exe, &token_out)
    })
    .unwrap_err();
    assert!(matches!(err, PrepError::MissingScript { .. }), "{err}");
}

#[test]
fn verify_detects_changed_missing_and_extra_files() {
    let work = tempfile::tempdir().unwrap();
    let exe = fake_exe(work.path());
    let out = work.path().join("oem");
    oem::stage(&options(&out, &exe, &work.path().join("token"))).unwrap();

    // One byte of install-guest.ps1 changed, setup.ps1 gone, an installer added.
    let target = out.join("install-guest.ps1");
    let mut bytes = std::fs::read(&target).unwrap();
    bytes[0] ^= 0x20;
    std::fs::write(&target, &bytes).unwrap();
    std::fs::remove_file(out.join("setup.ps1")).unwrap();
    std::fs::create_dir_all(out.join("installers")).unwrap();
    std::fs::write(out.join("installers/vlc.exe"), b"MZ").unwrap();

    let report = oem::verify(&out).unwrap();
    assert!(!report.is_ok());
    assert_eq!(report.mismatched.iter().map(|m| m.path.as_str()).collect::<Vec<_>>(), ["install-guest.ps1"]);
    assert_eq!(report.missing, ["setup.ps1"]);
    assert_eq!(report.extra, ["installers/vlc.exe"]);

    std::fs::remove_file(out.join("manifest.json")).unwrap();
    assert!(matches!(oem::verify(&out), Err(PrepError::Manifest { .. })));
}

#[tokio::test]
async fn the_staged_token_is_accepted_and_a_wrong_one_refused() {
    let work = tempfile::tempdir().unwrap();
    let exe = fake_exe(work.path());
    let out = work.path().join("oem");
    let token_out = work.path().join("host-token");
    let staged = oem::stage(&options(&out, &exe, &token_out)).unwrap();
    let guest = start_guest(&staged.token_path).await;
    let token = std::fs::read_to_string(&token_out).unwrap().trim().to_owned();

    // Health is open, and says a token is required.
    let health = client(guest.url(), None).health().await.unwrap();
    assert!(health.auth_required);

    client(guest.url(), Some(&token)).folders().await.expect("the staged token is accepted");
    let wrong = "0".repeat(64);
    let err = client(guest.url(), Some(&wrong)).folders().await.unwrap_err();
    assert!(matches!(err, ClientError::Api { status: 401, .. }), "{err}");
    let err = client(guest.url(), None).folders().await.unwrap_err();
    assert!(matches!(err, ClientError::Api { status: 401, .. }), "{err}");

    // wait_healthy: every component reported up, then the token checked.
    let mut events = Vec::new();
    let report = oem::wait_healthy(
        &client(guest.url(), Some(&token)),
        Duration::from_secs(10),
        Duration::from_millis(100),
        |e| {
            events.push(match e {
                WaitEvent::Reachable { .. } => "reachable".to_owned(),
                WaitEvent::Up { component } => format!("up {}", oem::component_name(component.component)),
                WaitEvent::TokenAccepted => "token".to_owned(),
                other => format!("{other:?}"),
            });
        },
    )
    .await
    .expect("healthy");
    assert_eq!(events.first().map(String::as_str), Some("reachable"));
    assert_eq!(events.last().map(String::as_str), Some("token"));
    assert_eq!(events.iter().filter(|e| e.starts_with("up ")).count(), report.components.len(), "{events:?}");

    // The wrong token ends the wait at once, with a reason.
    let err = oem::wait_healthy(
        &client(guest.url(), Some(&wrong)),
        Duration::from_secs(10),
        Duration::from_millis(100),
        |_| {},
    )
    .await
    .unwrap_err();
    assert!(matches!(err, PrepError::TokenRefused { .. }), "{err}");
}

#[tokio::test]
async fn waiting_for_a_guest_that_never_answers_says_so() {
    // A port that was free a moment ago: nothing listens there.
    let port = {
        let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        listener.local_addr().unwrap().port()
    };
    let c = client(&format!("http://127.0.0.1:{port}"), None);
    let mut unreachable = 0;
    let err = oem::wait_healthy(&c, Duration::from_millis(600), Duration::from_millis(100), |e| {
        if matches!(e, WaitEvent::Unreachable { .. }) {
            unreachable += 1;
        }
    })
    .await
    .unwrap_err();
    let PrepError::NotHealthy(timeout) = &err else { panic!("not a timeout: {err}") };
    assert!(!timeout.reached);
    assert!(timeout.last_error.is_some());
    assert_eq!(unreachable, 1, "the same reason is reported once");
    assert!(err.to_string().contains("never answered"), "{err}");
}
