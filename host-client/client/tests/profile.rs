//! The browsers' user-data rule against a real in-process stub guest: the
//! `UserDataDir` policy read back through `/v1/registry` (HKLM before HKCU, a
//! value of another type skipped), and the folder the image's
//! `setup-scripts/prep-browser.ps1` writes being the folder the rule resolves to.

use std::path::Path;
use std::time::Duration;

use arena_client::browser::profile::{user_data_dir, Browser, UserDataError, POLICY_VALUE};
use arena_client::client::{ClientConfig, GuestClient};
use arena_shared::registry::{RegistryValue, RegistryWrite};
use arena_test_support::StubGuest;

const LOCAL: &str = r"C:\Users\Docker\AppData\Local";

fn client(url: &str) -> GuestClient {
    GuestClient::new(url, ClientConfig { token: None, timeout: Duration::from_secs(20), retries: 1 }).expect("client")
}

async fn set(client: &GuestClient, key: &str, data: RegistryValue) {
    let write = RegistryWrite { key: key.to_owned(), value: Some(POLICY_VALUE.to_owned()), data };
    client.registry_set(&write).await.expect("registry write");
}

/// The single-quoted text of the first line of `source` that starts with `prefix`.
fn quoted_after<'a>(source: &'a str, prefix: &str) -> &'a str {
    let line = source
        .lines()
        .map(str::trim)
        .find(|line| line.starts_with(prefix))
        .unwrap_or_else(|| panic!("prep-browser.ps1 has no line starting with {prefix:?}"));
    let rest = &line[prefix.len()..];
    let start = rest.find('\'').unwrap_or_else(|| panic!("{line:?} holds no quoted text")) + 1;
    let len = rest[start..].find('\'').unwrap_or_else(|| panic!("{line:?} has an unclosed quote"));
    &rest[start..start + len]
}

#[tokio::test]
async fn the_policy_folder_wins_over_the_default_hklm_before_hkcu() {
    let stub = StubGuest::start().await;
    let client = client(stub.url());

    // Upstream's image: no policy, the default folders.
    for (browser, default) in
        [(Browser::Chrome, r"Google\Chrome\User Data"), (Browser::Edge, r"Microsoft\Edge\User Data")]
    {
        let dir = user_data_dir(&client, browser).await.expect("default folder");
        assert_eq!((dir.path, dir.policy_key), (format!(r"{LOCAL}\{default}"), None));
    }

    // A policy in HKCU applies when HKLM has none.
    set(&client, r"HKCU\SOFTWARE\Policies\Google\Chrome", RegistryValue::String(r"${documents}\Mine".into())).await;
    assert_eq!(user_data_dir(&client, Browser::Chrome).await.unwrap().path, r"C:\Users\Docker\Documents\Mine");
    // A DWORD in HKLM is not a path: skipped, HKCU's string still applies.
    set(&client, r"HKLM\SOFTWARE\Policies\Google\Chrome", RegistryValue::Dword(1)).await;
    assert_eq!(user_data_dir(&client, Browser::Chrome).await.unwrap().path, r"C:\Users\Docker\Documents\Mine");
    // HKLM's string wins over HKCU's.
    set(&client, r"HKLM\SOFTWARE\Policies\Google\Chrome", RegistryValue::String(r"${local_app_data}\Machine".into()))
        .await;
    let dir = user_data_dir(&client, Browser::Chrome).await.unwrap();
    assert_eq!(dir.path, format!(r"{LOCAL}\Machine"));
    assert_eq!(dir.policy_key.as_deref(), Some(r"HKLM\SOFTWARE\Policies\Google\Chrome"));
    // Edge's policy is its own key: still the default.
    assert_eq!(user_data_dir(&client, Browser::Edge).await.unwrap().policy_key, None);

    // A relative value is an error naming the browser, the key and the value.
    set(&client, r"HKLM\SOFTWARE\Policies\Microsoft\Edge", RegistryValue::String(r"Arena\Edge".into())).await;
    let err = user_data_dir(&client, Browser::Edge).await.unwrap_err();
    assert!(matches!(err, UserDataError::Policy { .. }), "{err}");
    assert!(err.to_string().contains(r"HKLM\SOFTWARE\Policies\Microsoft\Edge\UserDataDir"), "{err}");

    // A guest out of reach is the client's error, not a default folder.
    drop(stub);
    let err = user_data_dir(&client, Browser::Chrome).await.unwrap_err();
    assert!(matches!(&err, UserDataError::Guest(source) if source.out_of_reach()), "{err}");
}

#[tokio::test]
async fn the_folder_prep_browser_writes_is_the_folder_the_rule_resolves_to() {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../setup-scripts/prep-browser.ps1");
    let source = std::fs::read_to_string(&script).unwrap_or_else(|err| panic!("{}: {err}", script.display()));
    let stub = StubGuest::start().await;
    let client = client(stub.url());
    for (browser, key_var, dir_var, folder) in [
        (Browser::Chrome, "$chrome", "$ChromeUserDataDir", r"Arena\Chrome"),
        (Browser::Edge, "$edge", "$EdgeUserDataDir", r"Arena\Edge"),
    ] {
        // The script writes the value under the key its variable names (`HKLM:\...`, PowerShell's drive).
        let key = quoted_after(&source, &format!("{key_var} =")).replacen("HKLM:", "HKLM", 1);
        assert_eq!(key, browser.policy_key("HKLM"), "prep-browser.ps1 writes {}'s policy elsewhere", browser.name());
        let value = quoted_after(&source, &format!("[string]{dir_var} ="));
        let write = format!("Set-RegistryValue {key_var} 'UserDataDir' {dir_var} 'String'");
        assert!(source.contains(&write), "prep-browser.ps1 no longer runs {write:?}");
        set(&client, &key, RegistryValue::String(value.to_owned())).await;
        let dir = user_data_dir(&client, browser).await.expect("the image's policy resolves");
        assert_eq!(dir.path, format!(r"{LOCAL}\{folder}"), "{value:?}");
    }
}
