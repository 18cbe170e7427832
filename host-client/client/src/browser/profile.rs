//! Where the guest's Chrome and Edge keep their user data: the one rule the
//! profile-file getters (`arena-eval`) and the browse-history setup steps
//! (`arena-setup`) follow, so a step writes where a getter reads and both read
//! where the browser itself does.
//!
//! A Chromium browser on Windows looks for its `UserDataDir` policy under
//! `HKLM\SOFTWARE\Policies\Google\Chrome` (Edge: `...\Microsoft\Edge`), then under
//! the same key in `HKCU`; the first string value found wins over the command
//! line's `--user-data-dir`. Without one (or with an empty one) the folder is the
//! default, `Google\Chrome\User Data` or `Microsoft\Edge\User Data` under the
//! user's local application data. The image's `setup-scripts/prep-browser.ps1`
//! sets the policy, because Chrome 136 and later refuse `--remote-debugging-port`
//! on the default folder; upstream's image sets none, so there both agree.
//! The registry is read through the guest's `/v1/registry` route.
//!
//! The value is expanded as Chromium's policy path parser expands it:
//! quotes around the whole value are dropped, then each of its variables is
//! replaced where it first occurs. The four per-user folders come from the
//! guest's known folders (`${local_app_data}`, `${roaming_app_data}`,
//! `${documents}`, `${profile}`); the others become the environment variable
//! the guest expands when it is handed the path (`${windows}`, `${program_files}`,
//! `${global_app_data}`, `${user_name}`, `${machine_name}` (`%COMPUTERNAME%`, the
//! NetBIOS name, where Chromium asks for the DNS host name: the same on a
//! machine outside a domain), `${client_name}`, `${session_name}`).
//! `%VAR%` text, which a `REG_EXPAND_SZ` value holds and Windows expands on
//! reading, is left for the guest's expansion too: the wire does not tell the
//! two string types apart. Trailing separators are dropped, as Chrome drops them.
//!
//! What it refuses: a value that is still relative once expanded (Chrome would
//! take it against its working folder, which the host cannot know) is an
//! error naming the key and the value. A value that is not a string is not a
//! policy path: Chrome skips it, and so does this (with a log line).

use arena_shared::files::{KnownFolder, KnownFolders};
use arena_shared::ntpath;
use arena_shared::registry::RegistryValue;

use crate::client::GuestClient;
use crate::error::ClientError;

/// The policy's value name, the same for both browsers.
pub const POLICY_VALUE: &str = "UserDataDir";

/// The hives a browser reads its policies from, in the order it reads them.
pub const POLICY_HIVES: [&str; 2] = ["HKLM", "HKCU"];

/// The History database, relative to the user-data folder.
pub const HISTORY: &str = r"Default\History";

/// A browser whose profile lives in the guest.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum Browser {
    Chrome,
    Edge,
}

impl Browser {
    /// The browser's name, for messages.
    pub fn name(self) -> &'static str {
        match self {
            Browser::Chrome => "Chrome",
            Browser::Edge => "Edge",
        }
    }

    /// The policy key under `SOFTWARE\Policies` of a hive.
    fn vendor_key(self) -> &'static str {
        match self {
            Browser::Chrome => r"Google\Chrome",
            Browser::Edge => r"Microsoft\Edge",
        }
    }

    /// The browser's policy key in `hive` (`HKLM` or `HKCU`).
    pub fn policy_key(self, hive: &str) -> String {
        format!(r"{hive}\SOFTWARE\Policies\{}", self.vendor_key())
    }

    /// The default user-data folder, relative to the local application data folder.
    pub fn default_folder(self) -> &'static str {
        match self {
            Browser::Chrome => r"Google\Chrome\User Data",
            Browser::Edge => r"Microsoft\Edge\User Data",
        }
    }
}

/// A browser's user-data folder in the guest, and what decided it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UserDataDir {
    /// The guest path of the folder (it may hold `%VAR%` text the guest expands).
    pub path: String,
    /// The policy key whose `UserDataDir` chose it; `None` for the default folder.
    pub policy_key: Option<String>,
}

impl UserDataDir {
    /// The guest path of a file under the folder (`Default\Bookmarks`, `Local State`).
    pub fn file(&self, relative: &str) -> String {
        ntpath::join(&[&self.path, relative])
    }
}

/// Why a browser's user-data folder could not be told.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum UserDataError {
    /// A registry or known-folder call failed (a missing policy value is not a failure).
    #[error("{0}")]
    Guest(#[source] ClientError),
    /// The policy's value names no usable folder.
    #[error("{browser}'s policy {key}\\UserDataDir = {value:?}: {reason}")]
    Policy { browser: &'static str, key: String, value: String, reason: String },
    /// The guest does not report a known folder the rule needs.
    #[error("{browser}'s user-data folder: the guest does not report its {folder:?} folder")]
    Folder { browser: &'static str, folder: KnownFolder },
}

/// The guest's `UserDataDir` policy for `browser`: the key and the string value
/// of the first hive that has one, or `None`.
///
/// # Errors
///
/// A failed registry read other than "not found".
pub async fn read_policy(client: &GuestClient, browser: Browser) -> Result<Option<(String, String)>, ClientError> {
    for hive in POLICY_HIVES {
        let key = browser.policy_key(hive);
        match client.registry_get(&key, Some(POLICY_VALUE)).await {
            Ok(read) => match read.data {
                RegistryValue::String(value) => return Ok(Some((key, value))),
                other => {
                    tracing::warn!(%key, value = ?other, "a UserDataDir policy that is not a string is skipped, as the browser skips it");
                }
            },
            Err(err) if err.status() == Some(404) => {}
            Err(err) => return Err(err),
        }
    }
    Ok(None)
}

/// The user-data folder of `browser` in the guest: its policy's folder when one
/// is set, else the default folder.
///
/// # Errors
///
/// [`UserDataError`]: a failed guest call, a policy naming no usable folder, or
/// a known folder the guest does not report.
pub async fn user_data_dir(client: &GuestClient, browser: Browser) -> Result<UserDataDir, UserDataError> {
    let policy = read_policy(client, browser).await.map_err(UserDataError::Guest)?;
    let folders = client.folders().await.map_err(UserDataError::Guest)?;
    resolve(browser, policy.as_ref().map(|(key, value)| (key.as_str(), value.as_str())), &folders)
}

/// The rule without I/O: the folder `policy` (its key and value, when set) gives
/// `browser` on a guest with these known folders.
///
/// # Errors
///
/// [`UserDataError::Policy`] for a value still relative once expanded;
/// [`UserDataError::Folder`] when a folder it needs is not reported.
pub fn resolve(
    browser: Browser,
    policy: Option<(&str, &str)>,
    folders: &KnownFolders,
) -> Result<UserDataDir, UserDataError> {
    let folder = |which: KnownFolder| {
        folders
            .folders
            .iter()
            .find_map(|(known, path)| (*known == which).then(|| path.clone()))
            .ok_or(UserDataError::Folder { browser: browser.name(), folder: which })
    };
    if let Some((key, value)) = policy {
        let expanded = expand(value, &folder)?;
        if !expanded.is_empty() {
            let path = strip_trailing_separators(&expanded);
            // `%VAR%` at the start is the guest's to expand; anything else must be absolute.
            if !path.starts_with('%') && !ntpath::isabs(path) {
                return Err(UserDataError::Policy {
                    browser: browser.name(),
                    key: key.to_owned(),
                    value: value.to_owned(),
                    reason: format!("{path:?} is not an absolute path once expanded"),
                });
            }
            return Ok(UserDataDir { path: path.to_owned(), policy_key: Some(key.to_owned()) });
        }
        tracing::debug!(%key, "an empty UserDataDir policy leaves the default folder");
    }
    let local = folder(KnownFolder::LocalAppData)?;
    Ok(UserDataDir { path: ntpath::join(&[&local, browser.default_folder()]), policy_key: None })
}

/// Where a policy variable's value comes from.
enum Source {
    Folder(KnownFolder),
    Env(&'static str),
}

/// Chromium's policy path variables on Windows, in the order its parser replaces them.
const VARIABLES: [(&str, Source); 11] = [
    ("${windows}", Source::Env("%SystemRoot%")),
    ("${program_files}", Source::Env("%ProgramFiles%")),
    ("${global_app_data}", Source::Env("%ProgramData%")),
    ("${profile}", Source::Folder(KnownFolder::Home)),
    ("${local_app_data}", Source::Folder(KnownFolder::LocalAppData)),
    ("${roaming_app_data}", Source::Folder(KnownFolder::AppData)),
    ("${documents}", Source::Folder(KnownFolder::Documents)),
    ("${user_name}", Source::Env("%USERNAME%")),
    ("${machine_name}", Source::Env("%COMPUTERNAME%")),
    ("${client_name}", Source::Env("%CLIENTNAME%")),
    ("${session_name}", Source::Env("%SESSIONNAME%")),
];

/// A policy value with its quotes dropped and its variables replaced (each at
/// its first occurrence, as Chromium's parser does).
fn expand(value: &str, folder: &dyn Fn(KnownFolder) -> Result<String, UserDataError>) -> Result<String, UserDataError> {
    let unquoted =
        ['"', '\''].iter().find_map(|&q| value.strip_prefix(q).and_then(|rest| rest.strip_suffix(q))).unwrap_or(value);
    let mut result = unquoted.to_owned();
    for (name, source) in &VARIABLES {
        let Some(at) = result.find(name) else { continue };
        let replacement = match source {
            Source::Folder(which) => folder(*which)?,
            Source::Env(text) => (*text).to_owned(),
        };
        result.replace_range(at..at + name.len(), &replacement);
    }
    Ok(result)
}

/// `C:\a\b\` → `C:\a\b`; a drive's root keeps its separator.
fn strip_trailing_separators(path: &str) -> &str {
    let stripped = path.trim_end_matches(['\\', '/']);
    if stripped.len() == path.len() || (!stripped.is_empty() && !stripped.ends_with(':')) {
        stripped
    } else {
        // A root (`C:\`, `\`): keep one separator.
        &path[..stripped.len() + 1]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn folders() -> KnownFolders {
        KnownFolders {
            folders: vec![
                (KnownFolder::Home, r"C:\Users\Docker".into()),
                (KnownFolder::Documents, r"C:\Users\Docker\Documents".into()),
                (KnownFolder::AppData, r"C:\Users\Docker\AppData\Roaming".into()),
                (KnownFolder::LocalAppData, r"C:\Users\Docker\AppData\Local".into()),
            ],
        }
    }

    const KEY: &str = r"HKLM\SOFTWARE\Policies\Google\Chrome";

    fn check(value: &str, want: &str) {
        let got =
            resolve(Browser::Chrome, Some((KEY, value)), &folders()).unwrap_or_else(|err| panic!("{value}: {err}"));
        assert_eq!(got.path, want, "{value}");
        assert_eq!(got.policy_key.as_deref(), Some(KEY));
    }

    #[test]
    fn no_policy_is_the_default_folder_of_each_browser() {
        let chrome = resolve(Browser::Chrome, None, &folders()).unwrap();
        assert_eq!(
            chrome,
            UserDataDir { path: r"C:\Users\Docker\AppData\Local\Google\Chrome\User Data".into(), policy_key: None }
        );
        let edge = resolve(Browser::Edge, None, &folders()).unwrap();
        assert_eq!(edge.path, r"C:\Users\Docker\AppData\Local\Microsoft\Edge\User Data");
        assert_eq!(
            edge.file(r"Default\Bookmarks"),
            r"C:\Users\Docker\AppData\Local\Microsoft\Edge\User Data\Default\Bookmarks"
        );
        // An empty policy (quotes and all) is no policy.
        for empty in ["", "''", "\"\""] {
            assert_eq!(resolve(Browser::Chrome, Some((KEY, empty)), &folders()).unwrap(), chrome, "{empty:?}");
        }
    }

    #[test]
    fn policy_variables_expand_as_chromium_expands_them() {
        check(r"${local_app_data}\Arena\Chrome", r"C:\Users\Docker\AppData\Local\Arena\Chrome");
        check(r"${roaming_app_data}\C", r"C:\Users\Docker\AppData\Roaming\C");
        check(r"${documents}\C", r"C:\Users\Docker\Documents\C");
        check(r"${profile}\C\${user_name}", r"C:\Users\Docker\C\%USERNAME%");
        check(r"${global_app_data}\${machine_name}", r"%ProgramData%\%COMPUTERNAME%");
        check(r"${windows}\${program_files}", r"%SystemRoot%\%ProgramFiles%");
        check(r"D:\p\${client_name}-${session_name}", r"D:\p\%CLIENTNAME%-%SESSIONNAME%");
        // A REG_EXPAND_SZ-style value is the guest's to expand.
        check(r"%LOCALAPPDATA%\Arena\Chrome", r"%LOCALAPPDATA%\Arena\Chrome");
        // Quotes around the whole value go; trailing separators go, a root keeps its own.
        check(r#""C:\Browser Data\""#, r"C:\Browser Data");
        check(r"'C:\x'", r"C:\x");
        check(r"C:\", r"C:\");
        check(r"\\server\share\x\\", r"\\server\share\x");
        // Only the first occurrence is replaced; unknown names stay as written.
        check(r"C:\${user_name}\${user_name}\${nope}", r"C:\%USERNAME%\${user_name}\${nope}");
        // Names are matched as written, as Chromium matches them.
        check(r"C:\${LOCAL_APP_DATA}", r"C:\${LOCAL_APP_DATA}");
    }

    #[test]
    fn a_relative_policy_or_a_missing_folder_is_a_clear_error() {
        for value in [r"Arena\Chrome", "C:Arena", r"${nope}\x"] {
            let err = resolve(Browser::Edge, Some((KEY, value)), &folders()).unwrap_err();
            let text = err.to_string();
            assert!(
                text.contains("Edge") && text.contains("UserDataDir") && text.contains("not an absolute path"),
                "{text}"
            );
        }
        let bare = KnownFolders { folders: vec![] };
        let err = resolve(Browser::Chrome, Some((KEY, r"${documents}\x")), &bare).unwrap_err();
        assert!(matches!(err, UserDataError::Folder { folder: KnownFolder::Documents, .. }), "{err}");
        let err = resolve(Browser::Chrome, None, &bare).unwrap_err();
        assert!(err.to_string().contains("LocalAppData"), "{err}");
        // A folder the value does not name is not needed.
        assert_eq!(resolve(Browser::Chrome, Some((KEY, r"E:\p")), &bare).unwrap().path, r"E:\p");
    }

    #[test]
    fn policy_keys_are_the_vendors_keys() {
        assert_eq!(Browser::Chrome.policy_key("HKLM"), r"HKLM\SOFTWARE\Policies\Google\Chrome");
        assert_eq!(Browser::Edge.policy_key("HKCU"), r"HKCU\SOFTWARE\Policies\Microsoft\Edge");
    }
}
