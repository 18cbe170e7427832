//! `arena prep stage` against the real Windows exe under Wine: the exe copied into
//! a staged OEM folder starts with `--token-file` on that folder's token, accepts
//! the token the host side kept, and refuses a wrong one.
//!
//! Like `wine.rs`, it needs `ARENA_WINDOWS_EXE` (the cross-built exe) and a prepared
//! `WINEPREFIX` (`scripts/wine-test.sh` sets both up); without them it prints a loud
//! `SKIPPED:` line and passes, unless `ARENA_REQUIRE_WINE=1` makes that a failure.
//! What Wine cannot run (PowerShell, the service control manager's session
//! launch, schtasks, the firewall) is exercised only on a real Windows VM.

use std::path::{Path, PathBuf};
use std::time::Duration;

use arena_client::client::{ClientConfig, GuestClient};
use arena_client::error::ClientError;
use arena_test_support::Served;
use arena_vm::oem::{self, StageOptions};

fn setup() -> Option<(PathBuf, PathBuf)> {
    arena_test_support::wine_or_skip("the Wine prep test").map(|it| (it.wine, it.exe))
}

/// The Windows spelling of a Unix path under Wine's `Z:` drive.
fn wine_path(path: &Path) -> String {
    format!("Z:{}", path.display().to_string().replace('/', "\\"))
}

fn client(url: &str, token: Option<&str>) -> GuestClient {
    GuestClient::new(
        url,
        ClientConfig { token: token.map(str::to_owned), timeout: Duration::from_secs(30), retries: 0 },
    )
    .expect("client")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_staged_exe_serves_with_the_staged_token_under_wine() {
    let Some((wine, exe)) = setup() else {
        return;
    };
    let work = tempfile::tempdir().expect("temp dir");
    let out = work.path().join("oem");
    let token_out = work.path().join("host-token");
    let scripts = Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join("setup-scripts");
    let staged = oem::stage(&StageOptions {
        out: out.clone(),
        exe: Some(exe),
        scripts,
        token_out: Some(token_out.clone()),
        force: false,
        workspace: PathBuf::from("."),
    })
    .expect("stage");
    assert!(oem::verify(&out).expect("verify").is_ok());
    // The logon task's launcher is staged from beside the exe (wine.rs runs it).
    assert!(staged.manifest.files.contains_key(oem::LAUNCHER_NAME), "{:?}", staged.manifest.files.keys());
    // So is the input recorder, the cross-built one (`arena doctor --input` starts it from C:\OEM).
    assert!(staged.manifest.files.contains_key(oem::RECORDER_NAME), "{:?}", staged.manifest.files.keys());

    // The exe from the staged folder, as install-guest.ps1 would copy it, with the
    // token file the service registration passes.
    let staged_exe = out.join(oem::EXE_NAME);
    let args = [
        staged_exe.to_str().expect("UTF-8 path").to_owned(),
        "--backend".into(),
        "stub".into(),
        "--port".into(),
        "0".into(),
        "--token-file".into(),
        wine_path(&staged.token_path),
    ];
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let guest =
        Served::start(&wine, &args, None).unwrap_or_else(|err| panic!("starting the staged exe under Wine: {err:#}"));

    let token = std::fs::read_to_string(&token_out).expect("host token").trim().to_owned();
    let health = client(&guest.url, None).health().await.expect("health needs no token");
    assert!(health.auth_required, "the guest started with --token-file must require it");

    client(&guest.url, Some(&token)).folders().await.expect("the staged token is accepted by the Windows exe");
    let err = client(&guest.url, Some(&"f".repeat(64))).folders().await.unwrap_err();
    assert!(matches!(err, ClientError::Api { status: 401, .. }), "a wrong token: {err}");
    let err = client(&guest.url, None).folders().await.unwrap_err();
    assert!(matches!(err, ClientError::Api { status: 401, .. }), "no token: {err}");

    // The host-side wait sees it healthy and the token accepted.
    oem::wait_healthy(&client(&guest.url, Some(&token)), Duration::from_secs(30), Duration::from_millis(200), |_| {})
        .await
        .expect("prep wait against the Windows exe");
}
