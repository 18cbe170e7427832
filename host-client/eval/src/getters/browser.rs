//! Chrome and Edge getters of upstream's `getters/chrome.py`, `getters/edge.py`
//! and `getters/msedge.py`: profile files (Preferences, Secure Preferences,
//! Local State, Bookmarks, and the History and Cookies databases), the open
//! tabs, the active tab's address, desktop shortcuts, and installed web apps.
//!
//! Upstream reads every profile file under `%LOCALAPPDATA%\...\User Data`, the
//! default folder, since its image sets no `UserDataDir` policy. Here the folder
//! is the one the browser really uses: [`arena_client::browser::profile`]'s rule
//! (the policy's folder when one is set, as on this project's image, else the
//! default), the rule the browse-history setup steps write by. Files come
//! through `pull_file`, and SQLite files are saved under the task's work folder
//! as `dest` and queried on the host.
//!
//! Tabs: upstream drives Chrome through Playwright over the DevTools websocket.
//! Tab lists come from the DevTools HTTP `json/list` (forwarded by the guest),
//! and `page_info` and `active_tab_info` read title, address and HTML over the
//! DevTools websocket the guest relays ([`arena_client::browser::page`]). The active
//! tab's address is the value of the omnibox element named "Address and search
//! bar" under a `Chrome_WidgetWin_1` window, exactly as upstream reads it.
//!
//! What it is not: it never scores, and it does not start a browser when none
//! listens on the debugging port (upstream launches one; here that is an error).

use arena_shared::exec::ExecRequest;
use arena_shared::files::{FileKind, KnownFolder};
use arena_shared::observation::{A11yBackend, A11yNode, A11yQuery, A11yTree};
use serde_json::{json, Map, Value};

use super::explorer::known_folder;
use super::{dest_path, guest_join, pull_optional, GetterError, Params};
use crate::value::{py_eq, py_truthy, Fetched};
use crate::EvalContext;
use arena_client::browser::cdp::CdpError;
use arena_client::browser::page::{self, LoadState};
use arena_client::browser::profile::{user_data_dir, Browser, UserDataError, HISTORY};
use arena_client::error::ClientError;

#[cfg(test)]
#[path = "browser_tests.rs"]
mod browser_tests;

/// A getter of this family.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum BrowserGetter {
    DefaultSearchEngine,
    DefaultSearchEngineFromEdge,
    EnableDoNotTrack,
    EnableDoNotTrackFromEdge,
    EnableEnhancedSafetyBrowsing,
    EnableEnhancedSafetyBrowsingFromEdge,
    DataDeleteAutomacally,
    DataDeleteAutomacallyFromEdge,
    ProfileName,
    ProfileNameFromEdge,
    ChromeFontSize,
    EdgeFontSize,
    EdgeDefaultDownloadFolder,
    EdgeHomePage,
    EnabledExperiments,
    Bookmarks,
    Favorites,
    CookieData,
    CookieDataForEdge,
    History,
    HistoryForEdge,
    OpenTabsInfo,
    PageInfo,
    ActiveTabInfo,
    ActiveTabUrlParse,
    UrlDashPart,
    ShortcutsOnDesktop,
    UrlShortcutsOnDesktop,
    ValidatePwaInstalled,
    PdfFromUrl,
}

/// Every getter of the family with its upstream name.
const NAMES: [(&str, BrowserGetter); 30] = [
    ("default_search_engine", BrowserGetter::DefaultSearchEngine),
    ("default_search_engine_from_edge", BrowserGetter::DefaultSearchEngineFromEdge),
    ("enable_do_not_track", BrowserGetter::EnableDoNotTrack),
    ("enable_do_not_track_from_edge", BrowserGetter::EnableDoNotTrackFromEdge),
    ("enable_enhanced_safety_browsing", BrowserGetter::EnableEnhancedSafetyBrowsing),
    ("enable_enhanced_safety_browsing_from_edge", BrowserGetter::EnableEnhancedSafetyBrowsingFromEdge),
    ("data_delete_automacally", BrowserGetter::DataDeleteAutomacally),
    ("data_delete_automacally_from_edge", BrowserGetter::DataDeleteAutomacallyFromEdge),
    ("profile_name", BrowserGetter::ProfileName),
    ("profile_name_from_edge", BrowserGetter::ProfileNameFromEdge),
    ("chrome_font_size", BrowserGetter::ChromeFontSize),
    ("edge_font_size", BrowserGetter::EdgeFontSize),
    ("edge_default_download_folder", BrowserGetter::EdgeDefaultDownloadFolder),
    ("edge_home_page", BrowserGetter::EdgeHomePage),
    ("enabled_experiments", BrowserGetter::EnabledExperiments),
    ("bookmarks", BrowserGetter::Bookmarks),
    ("favorites", BrowserGetter::Favorites),
    ("cookie_data", BrowserGetter::CookieData),
    ("cookie_data_for_edge", BrowserGetter::CookieDataForEdge),
    ("history", BrowserGetter::History),
    ("history_for_edge", BrowserGetter::HistoryForEdge),
    ("open_tabs_info", BrowserGetter::OpenTabsInfo),
    ("page_info", BrowserGetter::PageInfo),
    ("active_tab_info", BrowserGetter::ActiveTabInfo),
    ("active_tab_url_parse", BrowserGetter::ActiveTabUrlParse),
    ("url_dashPart", BrowserGetter::UrlDashPart),
    ("shortcuts_on_desktop", BrowserGetter::ShortcutsOnDesktop),
    ("url_shortcuts_on_desktop", BrowserGetter::UrlShortcutsOnDesktop),
    ("validate_pwa_installed", BrowserGetter::ValidatePwaInstalled),
    ("pdf_from_url", BrowserGetter::PdfFromUrl),
];

/// The getter of this family named `name`, if implemented.
pub(super) fn lookup(name: &str) -> Option<BrowserGetter> {
    super::by_name(&NAMES, name)
}

impl BrowserGetter {
    /// The upstream name, for error messages.
    fn name(self) -> &'static str {
        super::name_of(&NAMES, self).unwrap_or("browser")
    }

    pub(super) async fn fetch(self, ctx: &EvalContext, params: &Map<String, Value>) -> Result<Fetched, GetterError> {
        use Browser::{Chrome, Edge};
        use BrowserGetter as G;
        let p = Params::new(self.name(), params);
        let p = &p;
        match self {
            G::DefaultSearchEngine => Ok(chrome_search_engine(read_profile_json(ctx, p, Chrome, PREFERENCES).await?)),
            G::DefaultSearchEngineFromEdge => {
                Ok(edge_search_engine(read_profile_json(ctx, p, Edge, PREFERENCES).await?))
            }
            G::EnableDoNotTrack => {
                let on = read_profile_json(ctx, p, Chrome, PREFERENCES).await?.and_then(|data| do_not_track(&data));
                Ok(Fetched::Text(if on == Some(true) { "true" } else { "false" }.into()))
            }
            G::EnableDoNotTrackFromEdge => {
                let on = read_profile_json(ctx, p, Edge, PREFERENCES).await?.and_then(|data| do_not_track(&data));
                Ok(Fetched::number(if on == Some(true) { 1.0 } else { 0.0 }))
            }
            G::EnableEnhancedSafetyBrowsing => {
                // Upstream's fallback on an unreadable file is the string "Google".
                let data = read_profile_json(ctx, p, Chrome, PREFERENCES).await?;
                let text = match data.as_ref().map(chrome_enhanced_safe_browsing) {
                    Some(Ok(true)) => "true",
                    Some(Ok(false)) => "false",
                    _ => "Google",
                };
                Ok(Fetched::Text(text.into()))
            }
            G::EnableEnhancedSafetyBrowsingFromEdge => {
                let data = read_profile_json(ctx, p, Edge, PREFERENCES).await?;
                let on = data
                    .as_ref()
                    .and_then(|d| at(d, &["edge", "super_duper_secure_mode", "enabled"]))
                    .is_some_and(py_truthy);
                Ok(Fetched::number(if on { 1.0 } else { 0.0 }))
            }
            G::DataDeleteAutomacally => {
                let data = read_profile_json(ctx, p, Chrome, PREFERENCES).await?;
                let text = match data
                    .as_ref()
                    .map(|d| d.get("profile").map(|profile| py_get(profile, "default_content_setting_values")))
                {
                    Some(Some(Ok(Some(value)))) if !value.is_null() => "true",
                    Some(Some(Ok(_))) => "false",
                    // A missing file, a missing `profile` or a non-dict one: upstream's "Google".
                    _ => "Google",
                };
                Ok(Fetched::Text(text.into()))
            }
            G::DataDeleteAutomacallyFromEdge => {
                let data = read_profile_json(ctx, p, Edge, PREFERENCES).await?;
                let state = data
                    .as_ref()
                    .and_then(|d| d.get("browser"))
                    .and_then(|b| py_get(b, "clear_data_on_exit").ok().flatten());
                let pass = state.is_some_and(|state| py_eq(state, &edge_clear_on_exit_target()));
                Ok(Fetched::number(if pass { 1.0 } else { 0.0 }))
            }
            G::ProfileName => Ok(profile_name(read_profile_json(ctx, p, Chrome, PREFERENCES).await?)),
            G::ProfileNameFromEdge => Ok(profile_name(read_profile_json(ctx, p, Edge, PREFERENCES).await?)),
            G::ChromeFontSize => Ok(font_size(read_profile_json(ctx, p, Chrome, PREFERENCES).await?, true)),
            G::EdgeFontSize => Ok(font_size(read_profile_json(ctx, p, Edge, PREFERENCES).await?, false)),
            G::EdgeDefaultDownloadFolder => {
                let data = read_profile_json(ctx, p, Edge, PREFERENCES).await?;
                let folder = data.as_ref().and_then(|d| at(d, &["download", "default_directory"])).cloned();
                Ok(folder.map_or(Fetched::None, fetched))
            }
            G::EdgeHomePage => edge_home_page(ctx, p).await,
            G::EnabledExperiments => {
                let data = read_profile_json(ctx, p, Chrome, LOCAL_STATE).await?;
                let list = data.as_ref().and_then(|d| at(d, &["browser", "enabled_labs_experiments"])).cloned();
                Ok(Fetched::Json(list.unwrap_or_else(|| json!([]))))
            }
            G::Bookmarks => bookmark_roots(ctx, p, Chrome).await,
            G::Favorites => bookmark_roots(ctx, p, Edge).await,
            G::CookieData => sqlite_rows(ctx, p, Chrome, COOKIES, "SELECT * FROM cookies").await,
            G::CookieDataForEdge => {
                // Edge keeps its cookie database locked while it runs; upstream
                // kills it first (and ignores whether that worked), so do we.
                let kill = ExecRequest {
                    shell: None,
                    argv: ["taskkill", "/F", "/IM", "msedge.exe", "/T"].map(String::from).to_vec(),
                    timeout_ms: Some(30_000),
                    max_output_bytes: Some(4096),
                    cwd: None,
                    stdin: None,
                };
                if let Err(err) = ctx.client.exec(&kill).await {
                    tracing::debug!(%err, "could not stop Edge before reading its cookies");
                }
                sqlite_rows(ctx, p, Edge, COOKIES, "SELECT * FROM cookies").await
            }
            G::History => sqlite_rows(ctx, p, Chrome, HISTORY, "SELECT url, title, last_visit_time FROM urls").await,
            G::HistoryForEdge => {
                sqlite_rows(ctx, p, Edge, HISTORY, "SELECT url, title, last_visit_time FROM urls").await
            }
            G::OpenTabsInfo => {
                let tabs = page_targets(ctx, p).await?;
                Ok(Fetched::Json(Value::Array(tabs.iter().map(|t| json!({"title": t.title, "url": t.url})).collect())))
            }
            G::PageInfo => page_info(ctx, p).await,
            G::ActiveTabInfo => active_tab_info(ctx, p).await,
            G::ActiveTabUrlParse => {
                let Some(url) = active_tab_url(ctx, p).await? else { return Ok(Fetched::None) };
                url_parse(p, &url).map(Fetched::Json)
            }
            G::UrlDashPart => {
                let Some(url) = active_tab_url(ctx, p).await? else { return Ok(Fetched::None) };
                url_dash_part(p, &url)
            }
            G::ShortcutsOnDesktop => desktop_shortcuts(ctx, p, ".lnk").await,
            G::UrlShortcutsOnDesktop => desktop_shortcuts(ctx, p, ".url").await,
            G::ValidatePwaInstalled => validate_pwa_installed(ctx, p).await,
            G::PdfFromUrl => pdf_from_url(ctx, p).await,
        }
    }
}

// ----- profile files -----

const PREFERENCES: &str = r"Default\Preferences";
const SECURE_PREFERENCES: &str = r"Default\Secure Preferences";
const LOCAL_STATE: &str = "Local State";
const BOOKMARKS: &str = r"Default\Bookmarks";
const COOKIES: &str = r"Default\Network\Cookies";

/// The guest path of a profile file (`relative` under the browser's user-data
/// folder, which [`arena_client::browser::profile`] decides for getters and setup steps alike).
async fn profile_path(
    ctx: &EvalContext,
    p: &Params<'_>,
    browser: Browser,
    relative: &str,
) -> Result<String, GetterError> {
    match user_data_dir(&ctx.client, browser).await {
        Ok(dir) => Ok(dir.file(relative)),
        Err(UserDataError::Guest(err)) => Err(p.guest(err)),
        Err(err) => Err(p.failed(err.to_string())),
    }
}

/// A profile JSON file, or `None` when it is missing or does not parse:
/// upstream catches both and returns its getter's fallback value.
async fn read_profile_json(
    ctx: &EvalContext,
    p: &Params<'_>,
    browser: Browser,
    relative: &str,
) -> Result<Option<Value>, GetterError> {
    let path = profile_path(ctx, p, browser, relative).await?;
    let Some(bytes) = pull_optional(ctx, p, &path).await? else { return Ok(None) };
    match parse_json(&bytes) {
        Ok(value) => Ok(Some(value)),
        Err(err) => {
            tracing::debug!(getter = p.getter, %path, %err, "profile file does not parse");
            Ok(None)
        }
    }
}

/// JSON bytes as Python's `json.loads` takes them (a UTF-8 BOM is tolerated).
fn parse_json(bytes: &[u8]) -> Result<Value, serde_json::Error> {
    let bytes = bytes.strip_prefix(b"\xef\xbb\xbf").unwrap_or(bytes);
    serde_json::from_slice(bytes)
}

/// Python's `value.get(key)`: `Err` when `value` is not a dict (an `AttributeError` upstream).
fn py_get<'a>(value: &'a Value, key: &str) -> Result<Option<&'a Value>, NotADict> {
    match value {
        Value::Object(map) => Ok(map.get(key)),
        _ => Err(NotADict),
    }
}

/// A `.get` on something that is not a dict.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct NotADict;

/// The value at a chain of dict keys, `None` when any link is missing or not a dict.
fn at<'a>(value: &'a Value, keys: &[&str]) -> Option<&'a Value> {
    keys.iter().try_fold(value, |node, key| node.as_object().and_then(|map| map.get(*key)))
}

/// `get_default_search_engine`: the name of Chrome's default engine by its
/// prepopulated GUID, else the `short_name` of its template URL data, else "Google".
fn chrome_search_engine(data: Option<Value>) -> Fetched {
    const GUIDS: [(&str, &str); 4] = [
        ("485bf7d3-0215-45af-87dc-538868000001", "Google"),
        ("485bf7d3-0215-45af-87dc-538868000003", "Bing"),
        ("485bf7d3-0215-45af-87dc-538868000002", "Yahoo!"),
        ("485bf7d3-0215-45af-87dc-538868000092", "DuckDuckGo"),
    ];
    let fallback = Fetched::Text("Google".into());
    let Some(data) = data else { return fallback };
    let provider = match py_get(&data, "default_search_provider") {
        Ok(provider) => provider.cloned().unwrap_or_else(|| json!({})),
        Err(NotADict) => return fallback,
    };
    let guid = match py_get(&provider, "guid") {
        Ok(guid) => guid.and_then(Value::as_str),
        Err(NotADict) => return fallback,
    };
    if let Some(name) = guid.and_then(|guid| GUIDS.iter().find_map(|(g, name)| (*g == guid).then_some(*name))) {
        return Fetched::Text(name.into());
    }
    // `data.get('default_search_provider_data', {}).get('template_url_data', {}).get('short_name', 'Google')`.
    let chain = (|| -> Result<Option<Value>, NotADict> {
        let empty = json!({});
        let outer = py_get(&data, "default_search_provider_data")?.unwrap_or(&empty);
        let template = py_get(outer, "template_url_data")?.unwrap_or(&empty);
        Ok(py_get(template, "short_name")?.cloned())
    })();
    match chain {
        Ok(Some(value)) => fetched(value),
        Ok(None) | Err(NotADict) => fallback,
    }
}

/// A JSON value as a getter returns it: strings as text, `null` as `None`.
fn fetched(value: Value) -> Fetched {
    match value {
        Value::String(text) => Fetched::Text(text),
        Value::Null => Fetched::None,
        other => Fetched::Json(other),
    }
}

/// `get_default_search_engine_from_edge`: Edge's engine by the synced GUID of
/// its default provider (Edge numbers its engines differently), else "Unknown".
fn edge_search_engine(data: Option<Value>) -> Fetched {
    const GUIDS: [(&str, &str); 5] = [
        ("485bf7d3-0215-45af-87dc-538868000001", "Bing"),
        ("485bf7d3-0215-45af-87dc-538868000002", "Yahoo!"),
        ("485bf7d3-0215-45af-87dc-538868000003", "Google"),
        ("485bf7d3-0215-45af-87dc-538868000092", "DuckDuckGo"),
        ("485bf7d3-0215-45af-87dc-538868000015", "Yandex"),
    ];
    let guid = data.as_ref().and_then(|d| at(d, &["default_search_provider", "synced_guid"])).and_then(Value::as_str);
    let name = guid.and_then(|guid| GUIDS.iter().find_map(|(g, name)| (*g == guid).then_some(*name)));
    Fetched::Text(name.unwrap_or("Unknown").into())
}

/// The truthiness of `data.get('enable_do_not_track', {})`; `None` when `data` is not a dict.
fn do_not_track(data: &Value) -> Option<bool> {
    py_get(data, "enable_do_not_track").ok().map(|v| v.is_some_and(py_truthy))
}

/// The truthiness of `data.get('safebrowsing', {}).get('enhanced', {})`.
fn chrome_enhanced_safe_browsing(data: &Value) -> Result<bool, NotADict> {
    let empty = json!({});
    let safebrowsing = py_get(data, "safebrowsing")?.unwrap_or(&empty);
    Ok(py_get(safebrowsing, "enhanced")?.is_some_and(py_truthy))
}

/// What Edge's "clear browsing data on close" holds when every category but
/// hosted app data is ticked, which upstream requires exactly.
fn edge_clear_on_exit_target() -> Value {
    json!({
        "browsing_history": true, "cache": true, "cookies": true, "download_history": true,
        "form_data": true, "hosted_apps_data": false, "passwords": true, "site_settings": true,
    })
}

/// `data.get('profile', {}).get('name', None)`, `None` on any failure.
fn profile_name(data: Option<Value>) -> Fetched {
    data.as_ref().and_then(|d| at(d, &["profile", "name"])).cloned().map_or(Fetched::None, fetched)
}

/// `data.get('webkit', {}).get('webprefs', defaults)`: the font settings
/// Chrome stores only when they differ from its defaults.
fn font_size(data: Option<Value>, chrome: bool) -> Fetched {
    let defaults = if chrome {
        json!({"default_fixed_font_size": 13, "default_font_size": 16, "minimum_font_size": 13})
    } else {
        json!({"default_fixed_font_size": 13, "default_font_size": 16})
    };
    let exception_fallback = json!({"default_fixed_font_size": 13, "default_font_size": 16});
    let Some(data) = data else { return Fetched::Json(exception_fallback) };
    let chain = (|| -> Result<Option<Value>, NotADict> {
        let empty = json!({});
        let webkit = py_get(&data, "webkit")?.unwrap_or(&empty);
        Ok(py_get(webkit, "webprefs")?.cloned())
    })();
    match chain {
        Ok(Some(webprefs)) => Fetched::Json(webprefs),
        Ok(None) => Fetched::Json(defaults),
        Err(NotADict) => Fetched::Json(exception_fallback),
    }
}

/// `get_edge_home_page`: Edge's home page from `Secure Preferences` (where
/// Windows builds keep the protected `homepage` setting), falling back to
/// `Preferences`. The scheme and one trailing slash are dropped so that a
/// stored `https://www.wikipedia.org/` reads as the `www.wikipedia.org` the
/// task compares with; `None` when no home page is set.
async fn edge_home_page(ctx: &EvalContext, p: &Params<'_>) -> Result<Fetched, GetterError> {
    for file in [SECURE_PREFERENCES, PREFERENCES] {
        let data = read_profile_json(ctx, p, Browser::Edge, file).await?;
        if let Some(Value::String(home)) = data.as_ref().and_then(|d| d.get("homepage")) {
            return Ok(Fetched::Text(bare_home_page(home)));
        }
    }
    Ok(Fetched::None)
}

/// `https://www.example.org/` → `www.example.org`; other text is kept as it is.
fn bare_home_page(url: &str) -> String {
    let trimmed = url.trim();
    let lower = trimmed.to_ascii_lowercase();
    let rest = ["https://", "http://"]
        .iter()
        .find_map(|scheme| lower.starts_with(scheme).then(|| &trimmed[scheme.len()..]))
        .unwrap_or(trimmed);
    // Only a bare host loses its slash: `example.org/wiki/` keeps its path as typed.
    match rest.strip_suffix('/') {
        Some(host) if !host.contains('/') => host.to_owned(),
        _ => rest.to_owned(),
    }
}

/// `get_bookmarks` / `get_favorites`: the `roots` of the Bookmarks file, `[]`
/// when it is missing or empty. A file that does not parse is an error, as upstream raises.
async fn bookmark_roots(ctx: &EvalContext, p: &Params<'_>, browser: Browser) -> Result<Fetched, GetterError> {
    let path = profile_path(ctx, p, browser, BOOKMARKS).await?;
    let bytes = match pull_optional(ctx, p, &path).await? {
        Some(bytes) if !bytes.is_empty() => bytes,
        _ => return Ok(Fetched::Json(json!([]))),
    };
    let data = parse_json(&bytes).map_err(|err| p.failed(format!("{path} is not JSON: {err}")))?;
    match py_get(&data, "roots") {
        Ok(roots) => Ok(Fetched::Json(roots.cloned().unwrap_or_else(|| json!({})))),
        Err(NotADict) => Err(p.failed(format!("{path} holds no bookmark dict"))),
    }
}

/// Saves a profile SQLite database as `dest` and returns every row of `sql`,
/// each a list of column values (blobs as lowercase hex). A missing or
/// unreadable database is an error: upstream returns `None`, which its metrics
/// cannot iterate, so the task scores 0 either way.
async fn sqlite_rows(
    ctx: &EvalContext,
    p: &Params<'_>,
    browser: Browser,
    relative: &str,
    sql: &'static str,
) -> Result<Fetched, GetterError> {
    let local = dest_path(ctx, p, p.string("dest")?)?;
    let path = profile_path(ctx, p, browser, relative).await?;
    let Some(bytes) = pull_optional(ctx, p, &path).await? else {
        return Err(p.failed(format!("the guest has no readable {path}")));
    };
    std::fs::write(&local, &bytes).map_err(|err| p.io(&local, err))?;
    let db = local.clone();
    let rows = tokio::task::spawn_blocking(move || query_rows(&db, sql))
        .await
        .map_err(|err| p.failed(format!("the SQLite query crashed: {err}")))?
        .map_err(|err| p.failed(format!("{path}: {err}")))?;
    Ok(Fetched::Json(Value::Array(rows)))
}

/// Runs `sql` on a database file and returns its rows as JSON lists.
///
/// # Errors
///
/// SQLite's error: not a database, no such table.
pub(crate) fn query_rows(path: &std::path::Path, sql: &str) -> Result<Vec<Value>, rusqlite::Error> {
    use rusqlite::types::ValueRef;
    use rusqlite::OpenFlags;
    // Read-write (without create) on our own copy, so a database left in WAL
    // mode opens without its `-shm` companion.
    let conn = rusqlite::Connection::open_with_flags(
        path,
        OpenFlags::SQLITE_OPEN_READ_WRITE | OpenFlags::SQLITE_OPEN_NO_MUTEX,
    )?;
    let mut stmt = conn.prepare(sql)?;
    let columns = stmt.column_count();
    let mut rows = stmt.query([])?;
    let mut out = Vec::new();
    while let Some(row) = rows.next()? {
        let mut values = Vec::with_capacity(columns);
        for idx in 0..columns {
            values.push(match row.get_ref(idx)? {
                ValueRef::Null => Value::Null,
                ValueRef::Integer(n) => Value::from(n),
                ValueRef::Real(f) => serde_json::Number::from_f64(f).map_or(Value::Null, Value::Number),
                ValueRef::Text(bytes) => Value::String(String::from_utf8_lossy(bytes).into_owned()),
                ValueRef::Blob(bytes) => Value::String(hex::encode(bytes)),
            });
        }
        out.push(Value::Array(values));
    }
    Ok(out)
}

// ----- tabs -----

/// One page target of the DevTools `json/list`.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Tab {
    id: String,
    title: String,
    url: String,
}

/// The browser's page targets (tabs and popups), most recently active first,
/// as `json/list` orders them. Extension pages, workers and other targets are
/// left out, as Playwright's `context.pages` leaves them out.
async fn page_targets(ctx: &EvalContext, p: &Params<'_>) -> Result<Vec<Tab>, GetterError> {
    let body = ctx.client.browser_get("json/list").await.map_err(|err| p.guest(err))?;
    let targets: Value =
        serde_json::from_slice(&body).map_err(|err| p.failed(format!("json/list is not JSON: {err}")))?;
    let Value::Array(targets) = targets else {
        return Err(p.failed("json/list is not a list of targets"));
    };
    Ok(targets.iter().filter_map(as_page).collect())
}

fn as_page(target: &Value) -> Option<Tab> {
    if target.get("type").and_then(Value::as_str) != Some("page") {
        return None;
    }
    let text = |key: &str| target.get(key).and_then(Value::as_str).unwrap_or_default().to_owned();
    Some(Tab { id: text("id"), title: text("title"), url: text("url") })
}

/// `get_page_info`: opens a new tab, navigates it to `url`, waits for
/// `load_state` (Playwright's, default `load`) and returns `{title, url,
/// content}` with the page's HTML, over the DevTools websocket as upstream's
/// Playwright does (see [`arena_client::browser::page`]); the tab is closed
/// afterwards. A page that does not load in time is read as it is, titled
/// `Load timeout`, as upstream's.
async fn page_info(ctx: &EvalContext, p: &Params<'_>) -> Result<Fetched, GetterError> {
    let url = p.string("url")?;
    let load_state = match p.map.get("load_state") {
        Some(_) => p.string("load_state")?,
        None => "load",
    };
    let info = page::open_and_read(&ctx.client, url, LoadState::parse(load_state))
        .await
        .map_err(|err| p.failed(format!("reading {url} over DevTools: {err}")))?;
    Ok(Fetched::Json(json!({"title": info.title, "url": info.url, "content": info.content})))
}

fn uia_query() -> A11yQuery {
    A11yQuery {
        backend: A11yBackend::Uia,
        max_depth: None,
        max_children: None,
        max_nodes: None,
        max_ms: None,
        foreground_only: false,
    }
}

/// The name of the omnibox element upstream's CSS selector looks for.
const ADDRESS_BAR: &str = "Address and search bar";
/// The window class (upstream's tag `chrome_widgetwin_1`) of Chrome's and Edge's windows.
const CHROME_WINDOW_CLASS: &str = "chrome_widgetwin_1";

/// Where upstream's selector `chrome_widgetwin_1 [name="Address and search bar"]`
/// lands: the last matching element in document order (windows topmost first,
/// each node before its children) that has a `Chrome_WidgetWin_1` ancestor,
/// with the index of its top-level window.
fn find_address_bar(tree: &A11yTree) -> Option<(usize, &A11yNode)> {
    fn walk<'a>(node: &'a A11yNode, inside: bool, window: usize, found: &mut Option<(usize, &'a A11yNode)>) {
        if inside && node.name == ADDRESS_BAR {
            *found = Some((window, node));
        }
        let inside = inside || node.class_name.eq_ignore_ascii_case(CHROME_WINDOW_CLASS);
        for child in &node.children {
            walk(child, inside, window, found);
        }
    }
    let mut found = None;
    for (idx, window) in tree.windows.iter().enumerate() {
        walk(window, false, idx, &mut found);
    }
    found
}

/// `get_active_url_from_accessTree`: `goto_prefix` (default `https://`) plus
/// the address bar's value; `None` without a browser window, an address bar or a value.
async fn active_tab_url(ctx: &EvalContext, p: &Params<'_>) -> Result<Option<String>, GetterError> {
    let prefix = match p.map.get("goto_prefix") {
        Some(_) => p.string("goto_prefix")?,
        None => "https://",
    };
    let tree = ctx.client.a11y(&uia_query()).await.map_err(|err| p.guest(err))?;
    Ok(address_bar_url(&tree, prefix))
}

fn address_bar_url(tree: &A11yTree, prefix: &str) -> Option<String> {
    let Some((_, bar)) = find_address_bar(tree) else {
        tracing::debug!("no browser address bar in the accessibility tree");
        return None;
    };
    match bar.value.as_deref() {
        Some(text) if !text.is_empty() => Some(format!("{prefix}{text}")),
        _ => None,
    }
}

/// `get_active_tab_info`: `{title, url, content}` of the active tab, as
/// upstream reads it: the address bar's URL (with `goto_prefix`) opened in a
/// new tab, loaded, and read over the DevTools websocket (title, final
/// address, HTML). `None` when no address bar shows a URL, when no browser
/// answers on the debugging port, or when the page cannot be opened
/// (upstream's `None` for each).
async fn active_tab_info(ctx: &EvalContext, p: &Params<'_>) -> Result<Fetched, GetterError> {
    let Some(url) = active_tab_url(ctx, p).await? else { return Ok(Fetched::None) };
    match page::open_and_read(&ctx.client, &url, LoadState::Load).await {
        Ok(info) => Ok(Fetched::Json(json!({"title": info.title, "url": info.url, "content": info.content}))),
        Err(err @ (CdpError::Http(_) | CdpError::Connect { .. } | CdpError::Protocol { .. })) => {
            tracing::warn!(%err, %url, "active_tab_info: the active tab's page could not be opened");
            Ok(Fetched::None)
        }
        Err(err) => Err(p.failed(format!("reading {url} over DevTools: {err}"))),
    }
}

/// `get_active_tab_url_parse`: the first value of each of `parse_keys` in the
/// URL's query (`""` when absent), keys renamed by `replace`, and empty values
/// filled from the key named by `or`. A `replace` or `or` key that was not
/// parsed is an error (a `KeyError` upstream).
fn url_parse(p: &Params<'_>, url: &str) -> Result<Value, GetterError> {
    let keys = p.strings("parse_keys")?;
    let query = parse_qs(url_query(url));
    let mut out = Map::new();
    for key in keys {
        let value = query.iter().find_map(|(k, v)| (k == key).then(|| v.clone())).unwrap_or_default();
        out.insert(key.to_owned(), Value::String(value));
    }
    if let Some(replace) = p.map.get("replace") {
        let Value::Object(replace) = replace else { return Err(p.bad("`replace` must be a dict")) };
        for (old, new) in replace {
            let new = new.as_str().ok_or_else(|| p.bad(format!("`replace[{old}]` must be a string")))?;
            let value = out
                .remove(old)
                .ok_or_else(|| p.failed(format!("`replace` names {old:?}, which is not in `parse_keys`")))?;
            out.insert(new.to_owned(), value);
        }
    }
    if let Some(or) = p.map.get("or") {
        let Value::Object(or) = or else { return Err(p.bad("`or` must be a dict")) };
        for (key, fallback) in or {
            let fallback = fallback.as_str().ok_or_else(|| p.bad(format!("`or[{key}]` must be a string")))?;
            let have =
                out.get(key).cloned().ok_or_else(|| p.failed(format!("`or` names {key:?}, which was not parsed")))?;
            let other = out
                .get(fallback)
                .cloned()
                .ok_or_else(|| p.failed(format!("`or` falls back on {fallback:?}, which was not parsed")))?;
            out.insert(key.clone(), if py_truthy(&have) { have } else { other });
        }
    }
    Ok(Value::Object(out))
}

/// The query of a URL as `urlparse` splits it: after the first `?` of the part before the first `#`.
fn url_query(url: &str) -> &str {
    let before_fragment = url.split_once('#').map_or(url, |(head, _)| head);
    before_fragment.split_once('?').map_or("", |(_, query)| query)
}

/// Python's `parse_qs` (no blank values, `&` separators): the pairs in order,
/// names and values unquoted with `+` as a space. Pieces without `=` are dropped.
fn parse_qs(query: &str) -> Vec<(String, String)> {
    query
        .split('&')
        .filter_map(|piece| piece.split_once('='))
        .filter(|(_, value)| !value.is_empty())
        .map(|(name, value)| (unquote(&name.replace('+', " ")), unquote(&value.replace('+', " "))))
        .collect()
}

/// Python's `unquote`: `%XX` escapes become bytes, read as UTF-8 with replacement.
fn unquote(text: &str) -> String {
    let bytes = text.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut idx = 0;
    while idx < bytes.len() {
        let hex = |b: u8| char::from(b).to_digit(16);
        if bytes[idx] == b'%' && idx + 2 < bytes.len() {
            if let (Some(hi), Some(lo)) = (hex(bytes[idx + 1]), hex(bytes[idx + 2])) {
                out.push(u8::try_from(hi * 16 + lo).unwrap_or(b'?'));
                idx += 3;
                continue;
            }
        }
        out.push(bytes[idx]);
        idx += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// `get_url_dashPart`: the `partIndex`-th `/`-separated part of the URL
/// (negative from the end, as Python indexes), cut at `?` with
/// `needDeleteId`, returned as a string or as `{key: part}` for `returnType` "json".
fn url_dash_part(p: &Params<'_>, url: &str) -> Result<Fetched, GetterError> {
    let index = p.get("partIndex")?.as_i64().ok_or_else(|| p.bad("`partIndex` must be an integer"))?;
    let parts: Vec<&str> = url.split('/').collect();
    let len = i64::try_from(parts.len()).unwrap_or(i64::MAX);
    let resolved = if index < 0 { index + len } else { index };
    let part = usize::try_from(resolved)
        .ok()
        .and_then(|idx| parts.get(idx))
        .ok_or_else(|| p.failed(format!("{url:?} has no part {index}")))?;
    let part = if p.truthy("needDeleteId") { part.split('?').next().unwrap_or_default() } else { part };
    match p.string("returnType")? {
        "string" => Ok(Fetched::Text(part.to_owned())),
        "json" => {
            let mut map = Map::new();
            map.insert(p.string("key")?.to_owned(), Value::String(part.to_owned()));
            Ok(Fetched::Json(Value::Object(map)))
        }
        _ => Ok(Fetched::None),
    }
}

// ----- desktop shortcuts -----

/// `get_shortcuts_on_desktop` (`.lnk`) and `get_url_shortcuts_on_desktop`
/// (`.url`): a dict from each desktop file name ending in `extension` to its
/// content. `.lnk` files are parsed into the JSON text LnkParse3 prints (the
/// metric reads `data.description`); `.url` files are their UTF-8 text.
async fn desktop_shortcuts(ctx: &EvalContext, p: &Params<'_>, extension: &str) -> Result<Fetched, GetterError> {
    let desktop = known_folder(ctx, p, KnownFolder::Desktop).await?;
    let listing = ctx.client.list_dir(&desktop).await.map_err(|err| p.guest(err))?;
    let mut out = Map::new();
    for entry in listing.entries.iter().filter(|e| e.kind == FileKind::File && e.name.ends_with(extension)) {
        let path = guest_join(&desktop, &entry.name);
        let file = ctx.client.pull_file(&path).await.map_err(|err| p.guest(err))?;
        let content = if extension == ".lnk" {
            let link = parse_lnk(&file.bytes).map_err(|err| p.failed(format!("{path}: {err}")))?;
            link.to_json().to_string()
        } else {
            String::from_utf8(file.bytes).map_err(|err| p.failed(format!("{path} is not UTF-8: {err}")))?
        };
        out.insert(entry.name.clone(), Value::String(content));
    }
    Ok(Fetched::Json(Value::Object(out)))
}

/// What a Windows shell link (`.lnk`) says, in the parts the metrics read.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub(crate) struct ShellLink {
    pub(crate) flags: u32,
    pub(crate) description: Option<String>,
    pub(crate) relative_path: Option<String>,
    pub(crate) working_directory: Option<String>,
    pub(crate) arguments: Option<String>,
    pub(crate) icon_location: Option<String>,
    pub(crate) local_base_path: Option<String>,
}

/// The `LinkFlags` bits of MS-SHLLINK this parser uses, with LnkParse3's names.
const LINK_FLAGS: [(u32, &str); 8] = [
    (0x1, "HasTargetIDList"),
    (0x2, "HasLinkInfo"),
    (0x4, "HasName"),
    (0x8, "HasRelativePath"),
    (0x10, "HasWorkingDir"),
    (0x20, "HasArguments"),
    (0x40, "HasIconLocation"),
    (0x80, "IsUnicode"),
];

impl ShellLink {
    /// The JSON LnkParse3's `print_json` prints, limited to the fields parsed here.
    fn to_json(&self) -> Value {
        let flags: Vec<&str> =
            LINK_FLAGS.iter().filter(|(bit, _)| self.flags & bit != 0).map(|(_, name)| *name).collect();
        let mut data = Map::new();
        for (key, value) in [
            ("description", &self.description),
            ("relative_path", &self.relative_path),
            ("working_directory", &self.working_directory),
            ("command_line_arguments", &self.arguments),
            ("icon_location", &self.icon_location),
        ] {
            if let Some(value) = value {
                data.insert(key.to_owned(), Value::String(value.clone()));
            }
        }
        let mut link_info = Map::new();
        if let Some(path) = &self.local_base_path {
            link_info.insert("local_base_path".to_owned(), Value::String(path.clone()));
        }
        json!({"header": {"link_flags": flags}, "data": data, "link_info": link_info})
    }
}

/// Parses the header, link info and string data of a shell link (MS-SHLLINK).
///
/// # Errors
///
/// A message naming the part that is cut short or malformed.
pub(crate) fn parse_lnk(bytes: &[u8]) -> Result<ShellLink, String> {
    const HEADER_SIZE: usize = 0x4C;
    let u16_at = |at: usize| bytes.get(at..at + 2).map(|b| u16::from_le_bytes([b[0], b[1]]));
    let u32_at = |at: usize| bytes.get(at..at + 4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
    if u32_at(0) != Some(0x4C) || bytes.len() < HEADER_SIZE {
        return Err("not a shell link (bad header)".into());
    }
    let flags = u32_at(20).ok_or("cut short in the header")?;
    let mut link = ShellLink { flags, ..ShellLink::default() };
    let mut at = HEADER_SIZE;
    if flags & 0x1 != 0 {
        let size = u16_at(at).ok_or("cut short in the target ID list")?;
        at += 2 + usize::from(size);
    }
    if flags & 0x2 != 0 {
        let size = u32_at(at).ok_or("cut short in the link info")? as usize;
        let info = bytes.get(at..at + size).ok_or("link info runs past the end")?;
        link.local_base_path = link_info_path(info);
        at += size;
    }
    let unicode = flags & 0x80 != 0;
    let mut read_string = |present: bool| -> Result<Option<String>, String> {
        if !present {
            return Ok(None);
        }
        let count = usize::from(u16_at(at).ok_or("cut short in the string data")?);
        at += 2;
        let len = if unicode { count * 2 } else { count };
        let raw = bytes.get(at..at + len).ok_or("a string runs past the end")?;
        at += len;
        Ok(Some(if unicode {
            let units: Vec<u16> = raw.chunks_exact(2).map(|c| u16::from_le_bytes([c[0], c[1]])).collect();
            String::from_utf16_lossy(&units)
        } else {
            raw.iter().map(|&b| char::from(b)).collect()
        }))
    };
    link.description = read_string(flags & 0x4 != 0)?;
    link.relative_path = read_string(flags & 0x8 != 0)?;
    link.working_directory = read_string(flags & 0x10 != 0)?;
    link.arguments = read_string(flags & 0x20 != 0)?;
    link.icon_location = read_string(flags & 0x40 != 0)?;
    Ok(link)
}

/// The local base path of a LinkInfo structure: the Unicode one when the
/// header is long enough to point at it, else the ANSI one.
fn link_info_path(info: &[u8]) -> Option<String> {
    let u32_at = |at: usize| info.get(at..at + 4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize);
    let header_size = u32_at(4)?;
    let has_local = u32_at(8)? & 0x1 != 0;
    if !has_local {
        return None;
    }
    if header_size >= 0x24 {
        let offset = u32_at(0x1C)?;
        let units: Vec<u16> = info
            .get(offset..)?
            .chunks_exact(2)
            .map(|c| u16::from_le_bytes([c[0], c[1]]))
            .take_while(|&u| u != 0)
            .collect();
        return Some(String::from_utf16_lossy(&units));
    }
    let offset = u32_at(16)?;
    Some(info.get(offset..)?.iter().take_while(|&&b| b != 0).map(|&b| char::from(b)).collect())
}

// ----- installed web apps -----

/// The app `validate_pwa_installed` looks for when the task names none: the corpus installs www.pwabuilder.com.
const DEFAULT_PWA: &str = "pwabuilder";

/// `get_validate_pwa_installed`: `"app_installed"` when a web app whose name
/// or address contains `app` (default "pwabuilder", case-insensitive) is
/// installed, else `"app_not_installed"`.
///
/// Upstream lists AppX packages with PowerShell. This asks natively first: an
/// installed Edge or Chrome web app has a Start menu shortcut (under
/// `%APPDATA%\Microsoft\Windows\Start Menu\Programs`, or a folder there) whose
/// arguments carry `--app-id=`. Only when none matches does it fall back to
/// upstream's `Get-AppxPackage` (Edge also registers its web apps as packages);
/// a guest without PowerShell then simply finds nothing.
async fn validate_pwa_installed(ctx: &EvalContext, p: &Params<'_>) -> Result<Fetched, GetterError> {
    let needle = match p.map.get("app") {
        Some(_) => p.string("app")?.to_lowercase(),
        None => DEFAULT_PWA.to_owned(),
    };
    let installed = pwa_in_start_menu(ctx, p, &needle).await? || pwa_in_appx(ctx, &needle).await;
    Ok(Fetched::Text(if installed { "app_installed" } else { "app_not_installed" }.into()))
}

async fn pwa_in_start_menu(ctx: &EvalContext, p: &Params<'_>, needle: &str) -> Result<bool, GetterError> {
    let roaming = known_folder(ctx, p, KnownFolder::AppData).await?;
    let programs = guest_join(&roaming, r"Microsoft\Windows\Start Menu\Programs");
    let mut folders = vec![programs.clone()];
    let mut checked = 0;
    while let Some(folder) = folders.pop() {
        let listing = match ctx.client.list_dir(&folder).await {
            Ok(listing) => listing,
            Err(ClientError::Api { .. }) => continue,
            Err(err) => return Err(p.guest(err)),
        };
        for entry in &listing.entries {
            let path = guest_join(&folder, &entry.name);
            // Web apps sit at the top or one folder down ("Chrome Apps"); go no deeper.
            if entry.kind == FileKind::Dir && folder == programs {
                folders.push(path);
                continue;
            }
            if entry.kind != FileKind::File || !entry.name.to_lowercase().ends_with(".lnk") {
                continue;
            }
            checked += 1;
            let Some(bytes) = pull_optional(ctx, p, &path).await? else { continue };
            let Ok(link) = parse_lnk(&bytes) else { continue };
            let arguments = link.arguments.clone().unwrap_or_default();
            if !arguments.contains("--app-id=") {
                continue;
            }
            let haystack =
                [Some(&entry.name), link.description.as_ref(), Some(&arguments), link.icon_location.as_ref()]
                    .into_iter()
                    .flatten()
                    .map(|s| s.to_lowercase())
                    .collect::<Vec<_>>()
                    .join("\n");
            if haystack.contains(needle) {
                return Ok(true);
            }
        }
    }
    tracing::debug!(checked, "no web-app shortcut matched in the Start menu");
    Ok(false)
}

async fn pwa_in_appx(ctx: &EvalContext, needle: &str) -> bool {
    let request = ExecRequest {
        shell: None,
        argv: [
            "powershell",
            "-NoProfile",
            "-NonInteractive",
            "-Command",
            "Get-AppxPackage | Select-Object Name, PackageFamilyName | ConvertTo-Json -Compress",
        ]
        .map(String::from)
        .to_vec(),
        timeout_ms: Some(60_000),
        max_output_bytes: Some(8 << 20),
        cwd: None,
        stdin: None,
    };
    match ctx.client.exec(&request).await {
        Ok(result) if result.exit_code == Some(0) => result.stdout.to_lowercase().contains(needle),
        Ok(result) => {
            tracing::debug!(exit = ?result.exit_code, "Get-AppxPackage failed");
            false
        }
        Err(err) => {
            tracing::debug!(%err, "could not run Get-AppxPackage");
            false
        }
    }
}

// ----- PDF of a page -----

/// `get_pdf_from_url`: prints `path` (a URL) to PDF and saves it as `dest`.
///
/// Upstream prints through Playwright over the DevTools websocket, which the
/// guest does not forward. Here the guest's Chrome prints it headless
/// (`--headless --print-to-pdf`, no header or footer, with a throwaway profile
/// so the running browser is left alone) into the guest's temp folder; the
/// file is pulled and the guest copy deleted. Needs `chrome` on the guest's PATH
/// (WAA's image puts it there).
async fn pdf_from_url(ctx: &EvalContext, p: &Params<'_>) -> Result<Fetched, GetterError> {
    let url = p.string("path")?;
    let local = dest_path(ctx, p, p.string("dest")?)?;
    let temp = known_folder(ctx, p, KnownFolder::Temp).await?;
    let stamp =
        std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.as_nanos()).unwrap_or_default();
    let pdf = guest_join(&temp, &format!("arena-pdf-{stamp}.pdf"));
    let profile = guest_join(&temp, &format!("arena-pdf-profile-{stamp}"));
    let request = ExecRequest {
        shell: None,
        argv: headless_print_argv(url, &pdf, &profile),
        timeout_ms: Some(120_000),
        max_output_bytes: Some(64 << 10),
        cwd: None,
        stdin: None,
    };
    let result = ctx.client.exec(&request).await.map_err(|err| p.guest(err))?;
    let pulled = pull_optional(ctx, p, &pdf).await?;
    for (path, recursive) in [(&pdf, false), (&profile, true)] {
        if let Err(err) = ctx.client.delete(path, recursive).await {
            tracing::debug!(%err, %path, "could not remove the headless print's leftovers");
        }
    }
    let Some(bytes) = pulled else {
        return Err(p.failed(format!(
            "headless Chrome printed no PDF of {url} (exit {:?}): {}",
            result.exit_code,
            result.stderr.trim()
        )));
    };
    std::fs::write(&local, &bytes).map_err(|err| p.io(&local, err))?;
    Ok(Fetched::File(local))
}

/// The command line that prints `url` to `pdf` with headless Chrome.
fn headless_print_argv(url: &str, pdf: &str, profile: &str) -> Vec<String> {
    vec![
        "chrome".into(),
        "--headless".into(),
        "--disable-gpu".into(),
        "--no-first-run".into(),
        "--no-default-browser-check".into(),
        // Chrome 111+ spells it this way; older builds read the second form.
        "--no-pdf-header-footer".into(),
        "--print-to-pdf-no-header".into(),
        format!("--user-data-dir={profile}"),
        format!("--print-to-pdf={pdf}"),
        url.to_owned(),
    ]
}
