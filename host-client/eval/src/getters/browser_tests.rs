//! Browser getters against an in-process stub guest seeded with Chrome- and
//! Edge-shaped profile files (Preferences JSON, Bookmarks, History and Cookies
//! databases with Chrome's table shapes), desktop shortcuts, a scenario whose
//! Chrome window shows an address bar, and a fake DevTools HTTP endpoint.

use std::path::Path;
use std::sync::{Arc, Mutex};

use arena_shared::files::KnownFolder;
use arena_shared::observation::A11yNode;
use serde_json::{json, Value};

use super::super::tests::{start_guest_with, Guest};
use super::{bare_home_page, headless_print_argv, parse_lnk, parse_qs, unquote};
use crate::fetch;
use crate::value::Fetched;
use arena_client::browser::fake::{FakeDevtools, FakePage};
use arena_task::GetterSpec;

/// Starts a stub guest, seeded by `scenario` when given, whose DevTools
/// forward goes to `cdp_port` (default: a port nothing listens on).
async fn start(scenario: Option<Value>, cdp_port: Option<u16>) -> Guest {
    start_guest_with(scenario, |config| config.cdp_port = cdp_port.unwrap_or(1)).await
}

fn spec(value: &Value) -> GetterSpec {
    let Value::Object(mut map) = value.clone() else { panic!("a getter is an object") };
    let kind = map.remove("type").and_then(|v| v.as_str().map(str::to_owned)).expect("type");
    GetterSpec { kind, params: map }
}

/// Runs a getter and compares with `want`: a value, or an error containing the text.
async fn check(guest: &Guest, getter: Value, want: Result<Fetched, &str>) {
    let got = fetch(&guest.ctx, &spec(&getter)).await;
    match (&got, &want) {
        (Ok(value), Ok(expected)) => assert_eq!(value, expected, "{getter}"),
        (Err(err), Err(text)) => assert!(err.to_string().contains(text), "{getter}: {err} lacks {text:?}"),
        _ => panic!("{getter}: got {got:?}, want {want:?}"),
    }
}

async fn folder(guest: &Guest, which: KnownFolder) -> String {
    let folders = guest.ctx.client.folders().await.expect("folders");
    folders.folders.into_iter().find(|(k, _)| *k == which).map(|(_, p)| p).expect("known folder")
}

async fn push(guest: &Guest, path: &str, bytes: Vec<u8>) {
    guest.ctx.client.push_file(path, bytes, None).await.expect("push");
}

/// Pushes `file` under the browser's user-data folder.
async fn push_profile(guest: &Guest, edge: bool, file: &str, bytes: Vec<u8>) {
    let local = folder(guest, KnownFolder::LocalAppData).await;
    let user_data = if edge { r"Microsoft\Edge\User Data" } else { r"Google\Chrome\User Data" };
    push(guest, &format!(r"{local}\{user_data}\{file}"), bytes).await;
}

fn text(s: &str) -> Result<Fetched, &'static str> {
    Ok(Fetched::Text(s.into()))
}

fn number(n: f64) -> Result<Fetched, &'static str> {
    Ok(Fetched::number(n))
}

fn data(value: Value) -> Result<Fetched, &'static str> {
    Ok(Fetched::Json(value))
}

#[tokio::test]
async fn chrome_preferences_getters_read_the_settings() {
    let guest = start(None, None).await;
    // A fresh profile: every getter gives upstream's fallback.
    let fallbacks = [
        ("default_search_engine", text("Google")),
        ("enable_do_not_track", text("false")),
        ("enable_enhanced_safety_browsing", text("Google")),
        ("data_delete_automacally", text("Google")),
        ("profile_name", Ok(Fetched::None)),
        ("chrome_font_size", data(json!({"default_fixed_font_size": 13, "default_font_size": 16}))),
        ("enabled_experiments", data(json!([]))),
    ];
    for (name, want) in fallbacks {
        check(&guest, json!({"type": name}), want).await;
    }

    let prefs = json!({
        "default_search_provider": {"guid": "485bf7d3-0215-45af-87dc-538868000003"},
        "enable_do_not_track": true,
        "safebrowsing": {"enabled": true, "enhanced": true},
        "profile": {"name": "Thomas", "default_content_setting_values": {"cookies": 4}},
        "webkit": {"webprefs": {"default_font_size": 24, "minimum_font_size": 6}},
    });
    push_profile(&guest, false, r"Default\Preferences", prefs.to_string().into_bytes()).await;
    let local_state = json!({"browser": {"enabled_labs_experiments": ["show-performance-metrics-hud@1"]}});
    push_profile(&guest, false, "Local State", local_state.to_string().into_bytes()).await;
    let set = [
        ("default_search_engine", text("Bing")),
        ("enable_do_not_track", text("true")),
        ("enable_enhanced_safety_browsing", text("true")),
        ("data_delete_automacally", text("true")),
        ("profile_name", text("Thomas")),
        ("chrome_font_size", data(json!({"default_font_size": 24, "minimum_font_size": 6}))),
        ("enabled_experiments", data(json!(["show-performance-metrics-hud@1"]))),
    ];
    for (name, want) in set {
        check(&guest, json!({"type": name}), want).await;
    }

    // Defaults written out: the settings are off, and an unknown GUID falls back to the template's name.
    let prefs = json!({
        "default_search_provider": {"guid": "not-a-prepopulated-guid"},
        "default_search_provider_data": {"template_url_data": {"short_name": "Ecosia"}},
        "enable_do_not_track": false,
        "safebrowsing": {"enhanced": false},
        "profile": {"name": "Person 1"},
        "webkit": {},
    });
    push_profile(&guest, false, r"Default\Preferences", prefs.to_string().into_bytes()).await;
    let unset = [
        ("default_search_engine", text("Ecosia")),
        ("enable_do_not_track", text("false")),
        ("enable_enhanced_safety_browsing", text("false")),
        ("data_delete_automacally", text("false")),
        ("profile_name", text("Person 1")),
        (
            "chrome_font_size",
            data(json!({"default_fixed_font_size": 13, "default_font_size": 16, "minimum_font_size": 13})),
        ),
    ];
    for (name, want) in unset {
        check(&guest, json!({"type": name}), want).await;
    }

    // A file that does not parse is upstream's caught exception: the fallback again.
    push_profile(&guest, false, r"Default\Preferences", b"{not json".to_vec()).await;
    check(&guest, json!({"type": "default_search_engine"}), text("Google")).await;
    check(&guest, json!({"type": "enable_do_not_track"}), text("false")).await;
}

#[tokio::test]
async fn edge_preferences_getters_read_the_settings() {
    let guest = start(None, None).await;
    let fallbacks = [
        ("default_search_engine_from_edge", text("Unknown")),
        ("enable_do_not_track_from_edge", number(0.0)),
        ("enable_enhanced_safety_browsing_from_edge", number(0.0)),
        ("data_delete_automacally_from_edge", number(0.0)),
        ("profile_name_from_edge", Ok(Fetched::None)),
        ("edge_font_size", data(json!({"default_fixed_font_size": 13, "default_font_size": 16}))),
        ("edge_default_download_folder", Ok(Fetched::None)),
        ("edge_home_page", Ok(Fetched::None)),
    ];
    for (name, want) in fallbacks {
        check(&guest, json!({"type": name}), want).await;
    }

    let all_cleared = json!({
        "browsing_history": true, "cache": true, "cookies": true, "download_history": true,
        "form_data": true, "hosted_apps_data": false, "passwords": true, "site_settings": true,
    });
    let prefs = json!({
        "default_search_provider": {"synced_guid": "485bf7d3-0215-45af-87dc-538868000092"},
        "enable_do_not_track": true,
        "edge": {"super_duper_secure_mode": {"enabled": true}},
        "browser": {"clear_data_on_exit": all_cleared},
        "profile": {"name": "Thomas"},
        "webkit": {"webprefs": {"default_font_size": 24}},
        "download": {"default_directory": "C:\\"},
        "homepage": "https://www.bing.com/",
    });
    push_profile(&guest, true, r"Default\Preferences", prefs.to_string().into_bytes()).await;
    let set = [
        ("default_search_engine_from_edge", text("DuckDuckGo")),
        ("enable_do_not_track_from_edge", number(1.0)),
        ("enable_enhanced_safety_browsing_from_edge", number(1.0)),
        ("data_delete_automacally_from_edge", number(1.0)),
        ("profile_name_from_edge", text("Thomas")),
        ("edge_font_size", data(json!({"default_font_size": 24}))),
        ("edge_default_download_folder", text("C:\\")),
        // No Secure Preferences yet: the home page comes from Preferences.
        ("edge_home_page", text("www.bing.com")),
    ];
    for (name, want) in set {
        check(&guest, json!({"type": name}), want).await;
    }
    push_profile(
        &guest,
        true,
        r"Default\Secure Preferences",
        json!({"homepage": "www.wikipedia.org"}).to_string().into_bytes(),
    )
    .await;
    check(&guest, json!({"type": "edge_home_page"}), text("www.wikipedia.org")).await;

    // One category short of "everything but hosted apps" is not the setting upstream asks for.
    let mut partial = all_cleared.clone();
    partial["passwords"] = json!(false);
    let prefs = json!({
        "default_search_provider": {"synced_guid": "485bf7d3-0215-45af-87dc-538868000001"},
        "enable_do_not_track": false,
        "edge": {"super_duper_secure_mode": {"enabled": false}},
        "browser": {"clear_data_on_exit": partial},
    });
    push_profile(&guest, true, r"Default\Preferences", prefs.to_string().into_bytes()).await;
    let unset = [
        ("default_search_engine_from_edge", text("Bing")),
        ("enable_do_not_track_from_edge", number(0.0)),
        ("enable_enhanced_safety_browsing_from_edge", number(0.0)),
        ("data_delete_automacally_from_edge", number(0.0)),
        ("edge_default_download_folder", Ok(Fetched::None)),
    ];
    for (name, want) in unset {
        check(&guest, json!({"type": name}), want).await;
    }
}

#[test]
fn home_pages_lose_scheme_and_bare_slash() {
    let check = |stored: &str, want: &str| assert_eq!(bare_home_page(stored), want, "{stored}");
    check("https://www.wikipedia.org/", "www.wikipedia.org");
    check("http://www.wikipedia.org", "www.wikipedia.org");
    check("www.wikipedia.org", "www.wikipedia.org");
    check("HTTPS://example.org/wiki/", "example.org/wiki/");
    check("edge://newtab", "edge://newtab");
}

#[tokio::test]
async fn bookmarks_and_favorites_return_the_roots() {
    let guest = start(None, None).await;
    check(&guest, json!({"type": "bookmarks"}), data(json!([]))).await;
    check(&guest, json!({"type": "favorites"}), data(json!([]))).await;
    let roots = json!({
        "bookmark_bar": {"children": [
            {"type": "url", "name": "The Illustrated Transformer", "url": "https://jalammar.github.io/illustrated-transformer/"},
            {"type": "folder", "name": "Reading", "children": []},
        ], "type": "folder", "name": "Bookmarks bar"},
        "other": {"children": [], "type": "folder"},
    });
    let file = json!({"checksum": "0", "roots": roots, "version": 1}).to_string().into_bytes();
    push_profile(&guest, false, r"Default\Bookmarks", file.clone()).await;
    check(&guest, json!({"type": "bookmarks"}), data(roots.clone())).await;
    check(&guest, json!({"type": "favorites"}), data(json!([]))).await;
    push_profile(&guest, true, r"Default\Bookmarks", file).await;
    check(&guest, json!({"type": "favorites"}), data(roots)).await;
    push_profile(&guest, true, r"Default\Bookmarks", b"{broken".to_vec()).await;
    check(&guest, json!({"type": "favorites"}), Err("is not JSON")).await;
}

/// A History database with Chrome's `urls` table.
fn history_db(dir: &Path, urls: &[(&str, &str)]) -> Vec<u8> {
    let path = dir.join("History");
    let conn = rusqlite::Connection::open(&path).expect("create History");
    conn.execute_batch(
        "CREATE TABLE urls(id INTEGER PRIMARY KEY AUTOINCREMENT, url LONGVARCHAR, title LONGVARCHAR,
         visit_count INTEGER DEFAULT 0 NOT NULL, typed_count INTEGER DEFAULT 0 NOT NULL,
         last_visit_time INTEGER NOT NULL, hidden INTEGER DEFAULT 0 NOT NULL);",
    )
    .expect("urls table");
    for (idx, (url, title)) in urls.iter().enumerate() {
        let time = 13_350_000_000_000_000_i64 + i64::try_from(idx).unwrap();
        conn.execute(
            "INSERT INTO urls(url, title, last_visit_time) VALUES (?1, ?2, ?3)",
            rusqlite::params![url, title, time],
        )
        .expect("insert");
    }
    drop(conn);
    std::fs::read(&path).expect("read History")
}

/// A Cookies database with Chrome's `cookies` table.
fn cookies_db(dir: &Path, hosts: &[&str]) -> Vec<u8> {
    let path = dir.join("Cookies");
    let conn = rusqlite::Connection::open(&path).expect("create Cookies");
    conn.execute_batch(
        "CREATE TABLE cookies(creation_utc INTEGER NOT NULL, host_key TEXT NOT NULL, top_frame_site_key TEXT NOT NULL,
         name TEXT NOT NULL, value TEXT NOT NULL, encrypted_value BLOB NOT NULL, path TEXT NOT NULL,
         expires_utc INTEGER NOT NULL, is_secure INTEGER NOT NULL, is_httponly INTEGER NOT NULL,
         last_access_utc INTEGER NOT NULL, has_expires INTEGER NOT NULL, is_persistent INTEGER NOT NULL,
         priority INTEGER NOT NULL, samesite INTEGER NOT NULL, source_scheme INTEGER NOT NULL,
         source_port INTEGER NOT NULL, last_update_utc INTEGER NOT NULL, source_type INTEGER NOT NULL,
         has_cross_site_ancestor INTEGER NOT NULL);",
    )
    .expect("cookies table");
    for host in hosts {
        conn.execute(
            "INSERT INTO cookies VALUES (1, ?1, '', 'session-id', '', x'763130ff', '/', 0, 1, 1, 1, 1, 1, 1, 0, 2, 443, 1, 0, 0)",
            [host],
        )
        .expect("insert");
    }
    drop(conn);
    std::fs::read(&path).expect("read Cookies")
}

#[tokio::test]
async fn history_and_cookies_are_read_from_sqlite() {
    let guest = start(None, None).await;
    let scratch = tempfile::tempdir().expect("scratch");
    check(&guest, json!({"type": "history", "dest": "history.sqlite"}), Err("has no readable")).await;

    let history = history_db(
        scratch.path(),
        &[("https://www.youtube.com/watch?v=1", "Video"), ("https://example.org/", "Example")],
    );
    push_profile(&guest, false, r"Default\History", history).await;
    let want = json!([
        ["https://www.youtube.com/watch?v=1", "Video", 13_350_000_000_000_000_i64],
        ["https://example.org/", "Example", 13_350_000_000_000_001_i64],
    ]);
    check(&guest, json!({"type": "history", "dest": "history.sqlite"}), data(want)).await;
    assert!(guest.ctx.work_dir.join("history.sqlite").is_file(), "dest is saved");
    check(&guest, json!({"type": "history_for_edge", "dest": "history.sqlite"}), Err("has no readable")).await;
    let scratch = tempfile::tempdir().expect("scratch");
    let edge_history = history_db(scratch.path(), &[]);
    push_profile(&guest, true, r"Default\History", edge_history).await;
    check(&guest, json!({"type": "history_for_edge", "dest": "edge.sqlite"}), data(json!([]))).await;
    check(&guest, json!({"type": "history"}), Err("missing parameter `dest`")).await;

    let scratch = tempfile::tempdir().expect("scratch");
    push_profile(&guest, false, r"Default\Network\Cookies", cookies_db(scratch.path(), &[".amazon.com"])).await;
    let got = fetch(&guest.ctx, &spec(&json!({"type": "cookie_data", "dest": "Cookies"}))).await.expect("cookies");
    let Fetched::Json(Value::Array(rows)) = got else { panic!("rows: {got:?}") };
    assert_eq!(rows.len(), 1);
    assert_eq!(rows[0][1], json!(".amazon.com"));
    assert_eq!(rows[0][5], json!("763130ff"), "blobs are hex");
    assert_eq!(rows[0].as_array().map(Vec::len), Some(20));

    let scratch = tempfile::tempdir().expect("scratch");
    push_profile(&guest, true, r"Default\Network\Cookies", cookies_db(scratch.path(), &[".bing.com", "github.com"]))
        .await;
    let got = fetch(&guest.ctx, &spec(&json!({"type": "cookie_data_for_edge", "dest": "Cookies"})))
        .await
        .expect("edge cookies");
    let Fetched::Json(Value::Array(rows)) = got else { panic!("rows: {got:?}") };
    let hosts: Vec<&Value> = rows.iter().map(|r| &r[1]).collect();
    assert_eq!(hosts, [&json!(".bing.com"), &json!("github.com")]);

    push_profile(&guest, false, r"Default\Network\Cookies", b"not a database, just text that is long enough".to_vec())
        .await;
    check(&guest, json!({"type": "cookie_data", "dest": "Cookies"}), Err("Cookies")).await;
}

// ----- tabs -----

/// A fake DevTools HTTP endpoint: `json/list`, `PUT json/new?<url>` (the new
/// tab gets the title "Shopping Cart") and `json/close/<id>`.
async fn devtools(tabs: Value) -> (u16, Arc<Mutex<Vec<Value>>>) {
    use axum::extract::{Path as UrlPath, RawQuery, State};
    use axum::routing::{get, put};
    use axum::{Json, Router};
    type Tabs = Arc<Mutex<Vec<Value>>>;
    let Value::Array(tabs) = tabs else { panic!("a list of targets") };
    let state: Tabs = Arc::new(Mutex::new(tabs));
    async fn list(State(tabs): State<Tabs>) -> Json<Value> {
        Json(Value::Array(tabs.lock().expect("tabs").clone()))
    }
    async fn new(State(tabs): State<Tabs>, RawQuery(url): RawQuery) -> Json<Value> {
        let target = json!({"id": "NEW1", "type": "page", "title": "Shopping Cart", "url": url.unwrap_or_default()});
        tabs.lock().expect("tabs").insert(0, target.clone());
        Json(target)
    }
    async fn close(State(tabs): State<Tabs>, UrlPath(id): UrlPath<String>) -> &'static str {
        tabs.lock().expect("tabs").retain(|t| t["id"] != json!(id));
        "Target is closing"
    }
    let app = Router::new()
        .route("/json/list", get(list))
        .route("/json/new", put(new))
        .route("/json/close/{id}", get(close))
        .with_state(state.clone());
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.expect("bind devtools");
    let port = listener.local_addr().expect("addr").port();
    tokio::spawn(async move { axum::serve(listener, app).await });
    (port, state)
}

fn node(role: &str, class_name: &str, name: &str, value: Option<&str>, children: Vec<A11yNode>) -> A11yNode {
    A11yNode {
        role: role.into(),
        class_name: class_name.into(),
        name: name.into(),
        value: value.map(str::to_owned),
        enabled: true,
        visible: true,
        children,
        ..A11yNode::default()
    }
}

/// A scenario with one window of class `class_name` holding an address bar
/// showing `address` and a page document with `page_text`.
fn browser_scenario(class_name: &str, title: &str, address: &str, page_text: &str) -> Value {
    let bar = node("Edit", "OmniboxViewViews", "Address and search bar", Some(address), vec![]);
    let toolbar = node("ToolBar", "ToolbarView", "", None, vec![bar]);
    let page =
        node("Document", "Chrome_RenderWidgetHostHWND", title, None, vec![node("Text", "", page_text, None, vec![])]);
    let elements = serde_json::to_value(vec![toolbar, page]).expect("elements");
    json!({"windows": [{"title": format!("{title} - Google Chrome"), "class_name": class_name, "elements": elements}]})
}

fn tab(id: &str, title: &str, url: &str) -> Value {
    json!({"id": id, "type": "page", "title": title, "url": url, "webSocketDebuggerUrl": format!("ws://127.0.0.1/devtools/page/{id}")})
}

#[tokio::test]
async fn open_tabs_come_from_the_devtools_list() {
    let (port, _) = devtools(json!([
        tab("A", "Lonely Planet", "https://www.lonelyplanet.com/"),
        {"id": "W", "type": "service_worker", "title": "sw", "url": "https://www.airbnb.com/sw.js"},
        tab("B", "Airbnb", "https://www.airbnb.com/"),
    ]))
    .await;
    let guest = start(None, Some(port)).await;
    let want = json!([
        {"title": "Lonely Planet", "url": "https://www.lonelyplanet.com/"},
        {"title": "Airbnb", "url": "https://www.airbnb.com/"},
    ]);
    check(&guest, json!({"type": "open_tabs_info"}), data(want)).await;

    // No browser on the debugging port is an error naming the port.
    let guest = start(None, None).await;
    check(&guest, json!({"type": "open_tabs_info"}), Err("debugging port")).await;
}

/// A fake browser speaking the DevTools protocol, showing `pages`, able to
/// navigate to the cart page and the banter thread.
async fn fake_browser(pages: Vec<FakePage>) -> FakeDevtools {
    FakeDevtools::start(
        pages,
        &[
            (
                "https://store.steampowered.com/cart/",
                "Shopping Cart",
                "<!DOCTYPE html><html><body><div class=\"cart_item\">The Dota 2 Official Soundtrack</div></body></html>",
            ),
            (
                "https://discussions.flightaware.com/t/the-banter-thread/4412",
                "The Banter Thread - FlightAware Discussions",
                "<html><body>Banter replies</body></html>",
            ),
        ],
    )
    .await
}

fn page(id: &str, title: &str, url: &str) -> FakePage {
    FakePage { id: id.into(), title: title.into(), url: url.into(), ..FakePage::default() }
}

#[tokio::test]
async fn page_info_opens_reads_and_closes_a_tab() {
    let browser = fake_browser(vec![page("A", "Steam", "https://store.steampowered.com/")]).await;
    let guest = start(None, Some(browser.port)).await;
    let getter =
        json!({"type": "page_info", "url": "https://store.steampowered.com/cart/", "load_state": "domcontentloaded"});
    let got = fetch(&guest.ctx, &spec(&getter)).await.expect("page_info");
    let Fetched::Json(info) = got else { panic!("{got:?}") };
    assert_eq!(info["title"], json!("Shopping Cart"));
    assert_eq!(info["url"], json!("https://store.steampowered.com/cart/"));
    let content = info["content"].as_str().expect("content");
    assert!(content.starts_with("<!DOCTYPE html>") && content.contains("The Dota 2 Official Soundtrack"), "{content}");
    assert_eq!(browser.page_ids(), ["A"], "the opened tab is closed again");
    let methods = browser.methods();
    assert!(
        methods.contains(&"Page.navigate".to_owned()) && methods.contains(&"Runtime.evaluate".to_owned()),
        "{methods:?}"
    );
    check(&guest, json!({"type": "page_info"}), Err("missing parameter `url`")).await;
    // A navigation the browser cannot make is an error, as Playwright's `goto` raises.
    check(&guest, json!({"type": "page_info", "url": "https://nowhere.invalid/"}), Err("ERR_NAME_NOT_RESOLVED")).await;
    assert_eq!(browser.page_ids(), ["A"], "the failed tab is closed too");
    // No browser on the debugging port is an error naming the port.
    let guest = start(None, None).await;
    check(&guest, json!({"type": "page_info", "url": "https://example.org/"}), Err("debugging port")).await;
}

#[tokio::test]
async fn active_tab_getters_read_the_address_bar() {
    let browser = fake_browser(vec![page("T2", "Other", "https://example.org/")]).await;
    let address = "discussions.flightaware.com/t/the-banter-thread/4412";
    let scenario = browser_scenario("Chrome_WidgetWin_1", "The Banter Thread", address, "Banter replies");
    let guest = start(Some(scenario), Some(browser.port)).await;
    // Upstream opens the address bar's URL in a new tab and reads title, address and HTML.
    let want = json!({
        "title": "The Banter Thread - FlightAware Discussions",
        "url": "https://discussions.flightaware.com/t/the-banter-thread/4412",
        "content": "<html><body>Banter replies</body></html>",
    });
    check(&guest, json!({"type": "active_tab_info", "goto_prefix": "https://"}), data(want)).await;
    assert_eq!(browser.page_ids(), ["T2"], "the tab opened to read it is closed again");
    check(&guest, json!({"type": "url_dashPart", "goto_prefix": "https://www.", "partIndex": -1, "needDeleteId": false, "returnType": "string"}), text("4412")).await;
    check(
        &guest,
        json!({"type": "url_dashPart", "partIndex": 3, "needDeleteId": false, "returnType": "json", "key": "part"}),
        data(json!({"part": "t"})),
    )
    .await;
    check(
        &guest,
        json!({"type": "url_dashPart", "partIndex": 40, "needDeleteId": false, "returnType": "string"}),
        Err("has no part 40"),
    )
    .await;

    // A flight search: the query's keys, one renamed.
    let address = "www.expedia.com/Flights-Search?fromStation=BOM&toStation=STO&departing=2024-05-06&x=%20y#top";
    let guest = start(Some(browser_scenario("Chrome_WidgetWin_1", "Flights", address, "")), None).await;
    let parse = json!({"type": "active_tab_url_parse", "goto_prefix": "https://www.", "parse_keys": ["fromStation", "toStation", "departing", "missing"], "replace": {"departing": "time"}});
    check(&guest, parse, data(json!({"fromStation": "BOM", "toStation": "STO", "time": "2024-05-06", "missing": ""})))
        .await;
    let with_or =
        json!({"type": "active_tab_url_parse", "parse_keys": ["missing", "toStation"], "or": {"missing": "toStation"}});
    check(&guest, with_or, data(json!({"missing": "STO", "toStation": "STO"}))).await;
    let bad_replace =
        json!({"type": "active_tab_url_parse", "parse_keys": ["toStation"], "replace": {"departing": "time"}});
    check(&guest, bad_replace, Err("not in `parse_keys`")).await;
    check(
        &guest,
        json!({"type": "url_dashPart", "partIndex": -1, "needDeleteId": true, "returnType": "string"}),
        text("Flights-Search"),
    )
    .await;
    // Without a browser on the debugging port there is no tab to read: upstream's `None`.
    check(&guest, json!({"type": "active_tab_info"}), Ok(Fetched::None)).await;

    // An "Address and search bar" outside a Chrome window is not the omnibox.
    let guest = start(Some(browser_scenario("Notepad", "Notes", "example.org", "")), None).await;
    for getter in [
        json!({"type": "active_tab_info"}),
        json!({"type": "url_dashPart", "partIndex": -1, "needDeleteId": false, "returnType": "string"}),
        json!({"type": "active_tab_url_parse", "parse_keys": ["q"]}),
    ] {
        check(&guest, getter, Ok(Fetched::None)).await;
    }
    // An empty omnibox is no URL either.
    let guest = start(Some(browser_scenario("Chrome_WidgetWin_1", "New Tab", "", "")), None).await;
    check(&guest, json!({"type": "active_tab_info"}), Ok(Fetched::None)).await;
}

#[test]
fn query_strings_parse_like_python() {
    let got = parse_qs("a=1&b=&c&d=x+y%21&a=2&e=%E2%9C%93");
    let want: Vec<(String, String)> = [("a", "1"), ("d", "x y!"), ("a", "2"), ("e", "✓")]
        .iter()
        .map(|(k, v)| ((*k).to_owned(), (*v).to_owned()))
        .collect();
    assert_eq!(got, want);
    assert_eq!(unquote("100%"), "100%");
    assert_eq!(unquote("%zz%41"), "%zzA");
    assert_eq!(unquote("%ff"), "\u{fffd}");
}

// ----- shortcuts -----

/// A Unicode shell link with a description, arguments and a local target path.
fn build_lnk(description: &str, arguments: &str, target: &str) -> Vec<u8> {
    let flags: u32 = 0x2 | 0x4 | 0x20 | 0x80;
    let mut out = Vec::new();
    out.extend(0x4C_u32.to_le_bytes());
    out.extend([0x01, 0x14, 0x02, 0x00, 0, 0, 0, 0, 0xC0, 0, 0, 0, 0, 0, 0, 0x46]);
    out.extend(flags.to_le_bytes());
    out.resize(0x4C, 0);
    // LinkInfo with an ANSI local base path.
    let volume: Vec<u8> = [0x11_u32, 3, 0x1234, 0x10].iter().flat_map(|v| v.to_le_bytes()).chain([0]).collect();
    let base_offset = 0x1C + volume.len();
    let suffix_offset = base_offset + target.len() + 1;
    let size = suffix_offset + 1;
    for value in [size, 0x1C, 1, 0x1C, base_offset, 0, suffix_offset] {
        out.extend(u32::try_from(value).unwrap().to_le_bytes());
    }
    out.extend(&volume);
    out.extend(target.as_bytes());
    out.extend([0, 0]);
    for text in [description, arguments] {
        let units: Vec<u16> = text.encode_utf16().collect();
        out.extend(u16::try_from(units.len()).unwrap().to_le_bytes());
        out.extend(units.iter().flat_map(|u| u.to_le_bytes()));
    }
    out
}

#[test]
fn shell_links_parse_to_lnkparse_json() {
    let bytes = build_lnk(
        "Play Puzzle Game 2048. Use your arrow keys to move the tiles.",
        "--profile-directory=Default --app-id=abc",
        r"C:\Program Files\Google\Chrome\Application\chrome_proxy.exe",
    );
    let link = parse_lnk(&bytes).expect("parses");
    let json = link.to_json();
    assert_eq!(json["data"]["description"], json!("Play Puzzle Game 2048. Use your arrow keys to move the tiles."));
    assert_eq!(json["data"]["command_line_arguments"], json!("--profile-directory=Default --app-id=abc"));
    assert_eq!(
        json["link_info"]["local_base_path"],
        json!(r"C:\Program Files\Google\Chrome\Application\chrome_proxy.exe")
    );
    assert_eq!(json["header"]["link_flags"], json!(["HasLinkInfo", "HasName", "HasArguments", "IsUnicode"]));
    assert!(parse_lnk(b"[InternetShortcut]\r\nURL=https://x\r\n").is_err());
    assert!(parse_lnk(&bytes[..bytes.len() - 3]).unwrap_err().contains("past the end"));
}

#[tokio::test]
async fn desktop_shortcuts_are_listed_by_kind() {
    let guest = start(None, None).await;
    check(&guest, json!({"type": "shortcuts_on_desktop"}), data(json!({}))).await;
    let desktop = folder(&guest, KnownFolder::Desktop).await;
    let lnk = build_lnk("Play Puzzle Game 2048.", "--app-id=abc", r"C:\chrome_proxy.exe");
    push(&guest, &format!(r"{desktop}\2048.lnk"), lnk.clone()).await;
    let url_file = "[InternetShortcut]\r\nURL=https://www.mathsisfun.com/games/2048.html\r\n";
    push(&guest, &format!(r"{desktop}\2048.url"), url_file.as_bytes().to_vec()).await;
    push(&guest, &format!(r"{desktop}\notes.txt"), b"x".to_vec()).await;

    let got = fetch(&guest.ctx, &spec(&json!({"type": "shortcuts_on_desktop"}))).await.expect("shortcuts");
    let Fetched::Json(Value::Object(map)) = got else { panic!("{got:?}") };
    assert_eq!(map.keys().collect::<Vec<_>>(), ["2048.lnk"]);
    let parsed: Value = serde_json::from_str(map["2048.lnk"].as_str().expect("text")).expect("JSON text");
    assert_eq!(parsed["data"]["description"], json!("Play Puzzle Game 2048."));
    check(&guest, json!({"type": "url_shortcuts_on_desktop"}), data(json!({"2048.url": url_file}))).await;

    push(&guest, &format!(r"{desktop}\broken.lnk"), b"garbage".to_vec()).await;
    check(&guest, json!({"type": "shortcuts_on_desktop"}), Err("broken.lnk")).await;
}

#[tokio::test]
async fn installed_web_apps_are_found_by_their_start_menu_shortcut() {
    let guest = start(None, None).await;
    check(&guest, json!({"type": "validate_pwa_installed"}), text("app_not_installed")).await;
    let roaming = folder(&guest, KnownFolder::AppData).await;
    let programs = format!(r"{roaming}\Microsoft\Windows\Start Menu\Programs");
    // A plain program shortcut that mentions the name is not a web app.
    push(&guest, &format!(r"{programs}\PWABuilder notes.lnk"), build_lnk("PWABuilder", "", r"C:\notes.exe")).await;
    check(&guest, json!({"type": "validate_pwa_installed"}), text("app_not_installed")).await;
    let args =
        "--profile-directory=Default --app-id=jbkkkchaknfdnjmnadhlnnacbjiecgkb --app-url=https://www.pwabuilder.com/";
    push(&guest, &format!(r"{programs}\Edge Apps\PWABuilder.lnk"), build_lnk("", args, r"C:\msedge_proxy.exe")).await;
    check(&guest, json!({"type": "validate_pwa_installed"}), text("app_installed")).await;
    check(&guest, json!({"type": "validate_pwa_installed", "app": "Squoosh"}), text("app_not_installed")).await;
}

#[tokio::test]
async fn pdf_from_url_needs_chrome_in_the_guest() {
    let guest = start(None, None).await;
    let getter = json!({"type": "pdf_from_url", "path": "https://lilianweng.github.io/posts/2023-06-23-agent/", "dest": "gold.pdf"});
    // The stub guest has no Chrome, so the print fails and says so.
    check(&guest, getter, Err("getter pdf_from_url")).await;
    let argv = headless_print_argv("https://example.org/", r"C:\Temp\out.pdf", r"C:\Temp\profile");
    assert_eq!(argv[0], "chrome");
    assert!(argv.contains(&"--headless".to_owned()));
    assert!(argv.contains(&r"--print-to-pdf=C:\Temp\out.pdf".to_owned()));
    assert!(argv.contains(&r"--user-data-dir=C:\Temp\profile".to_owned()));
    assert_eq!(argv.last().map(String::as_str), Some("https://example.org/"));
}

/// Writes `value` as `browser`'s `UserDataDir` policy in the guest's HKLM.
async fn set_policy(guest: &Guest, browser: arena_client::browser::profile::Browser, value: &str) {
    use arena_shared::registry::{RegistryValue, RegistryWrite};
    let write = RegistryWrite {
        key: browser.policy_key("HKLM"),
        value: Some("UserDataDir".into()),
        data: RegistryValue::String(value.into()),
    };
    guest.ctx.client.registry_set(&write).await.expect("policy write");
}

/// The shape of upstream's chrome task 7a5a7856 (a page saved to the bookmark
/// bar, read from the Bookmarks file) and of a Preferences task (Edge's profile
/// name), written here: each scores 1 with the profile at the `UserDataDir`
/// policy's folder and the policy set, as on this project's image, and 1 with
/// the profile at the default folder and no policy, as on upstream's. A profile
/// left at the default folder while the policy points elsewhere is not read.
#[tokio::test]
async fn profile_tasks_score_at_the_policy_folder_and_at_the_default() {
    use crate::{evaluate, LastAction};
    use arena_client::browser::profile::Browser;
    let url = "https://jalammar.github.io/illustrated-transformer/";
    let bookmarks_task = json!({
        "id": "bookmark-bar", "instruction": "save this page to the bookmarks bar",
        "evaluator": {
            "func": "is_expected_bookmarks",
            "result": {"type": "bookmarks"},
            "expected": {"type": "rule", "rules": {"type": "bookmark_bar_websites_urls", "urls": [url]}}
        }
    });
    let name_task = json!({
        "id": "profile-name", "instruction": "name the Edge profile Arena",
        "evaluator": {
            "func": "exact_match",
            "result": {"type": "profile_name_from_edge"},
            "expected": {"type": "rule", "rules": {"expected": "Arena"}}
        }
    });
    let evaluator = |task: &Value, path: &str| {
        arena_task::Task::parse(&task.to_string(), Path::new(path)).expect("task parses").evaluator
    };
    let bookmarks_eval = evaluator(&bookmarks_task, "chrome/bookmark-bar.json");
    let name_eval = evaluator(&name_task, "msedge/profile-name.json");
    let bookmarks = json!({"roots": {
        "bookmark_bar": {"type": "folder", "name": "Bookmarks bar", "children": [
            {"type": "url", "name": "The Illustrated Transformer", "url": url}
        ]},
        "other": {"type": "folder", "children": []}
    }})
    .to_string()
    .into_bytes();
    let prefs = json!({"profile": {"name": "Arena"}}).to_string().into_bytes();
    let score = |outcome: crate::EvalOutcome| outcome.score;

    // This project's image: the policy moves both profiles.
    let guest = start(None, None).await;
    let local = folder(&guest, KnownFolder::LocalAppData).await;
    set_policy(&guest, Browser::Chrome, r"${local_app_data}\Arena\Chrome").await;
    set_policy(&guest, Browser::Edge, r"${local_app_data}\Arena\Edge").await;
    // The files at the default folders are not the browsers' any more.
    push_profile(&guest, false, r"Default\Bookmarks", bookmarks.clone()).await;
    push_profile(&guest, true, r"Default\Preferences", prefs.clone()).await;
    assert_eq!(score(evaluate(&guest.ctx, &bookmarks_eval, Some(&LastAction::Done)).await), 0.0);
    assert_eq!(score(evaluate(&guest.ctx, &name_eval, Some(&LastAction::Done)).await), 0.0);
    push(&guest, &format!(r"{local}\Arena\Chrome\Default\Bookmarks"), bookmarks.clone()).await;
    push(&guest, &format!(r"{local}\Arena\Edge\Default\Preferences"), prefs.clone()).await;
    let outcome = evaluate(&guest.ctx, &bookmarks_eval, Some(&LastAction::Done)).await;
    assert_eq!((outcome.score, &outcome.error), (1.0, &None), "{outcome:?}");
    let outcome = evaluate(&guest.ctx, &name_eval, Some(&LastAction::Done)).await;
    assert_eq!((outcome.score, &outcome.error), (1.0, &None), "{outcome:?}");

    // Upstream's image: no policy, the default folders.
    let guest = start(None, None).await;
    assert_eq!(score(evaluate(&guest.ctx, &bookmarks_eval, Some(&LastAction::Done)).await), 0.0);
    push_profile(&guest, false, r"Default\Bookmarks", bookmarks).await;
    push_profile(&guest, true, r"Default\Preferences", prefs).await;
    let outcome = evaluate(&guest.ctx, &bookmarks_eval, Some(&LastAction::Done)).await;
    assert_eq!((outcome.score, &outcome.error), (1.0, &None), "{outcome:?}");
    let outcome = evaluate(&guest.ctx, &name_eval, Some(&LastAction::Done)).await;
    assert_eq!((outcome.score, &outcome.error), (1.0, &None), "{outcome:?}");
}

/// A policy naming no usable folder fails the getter with a message naming the
/// policy (scored 0 with the reason recorded), never a silent miss at another folder.
#[tokio::test]
async fn a_relative_policy_fails_the_profile_getters_by_name() {
    use arena_client::browser::profile::Browser;
    let guest = start(None, None).await;
    set_policy(&guest, Browser::Chrome, r"Arena\Chrome").await;
    check(&guest, json!({"type": "bookmarks"}), Err(r"HKLM\SOFTWARE\Policies\Google\Chrome\UserDataDir")).await;
    check(&guest, json!({"type": "history", "dest": "h.db"}), Err("not an absolute path")).await;
    // Edge's profile is not concerned.
    check(&guest, json!({"type": "favorites"}), data(json!([]))).await;
}
