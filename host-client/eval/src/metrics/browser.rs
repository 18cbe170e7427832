//! Browser metrics of upstream's `metrics/chrome.py` and `metrics/edge.py`:
//! bookmarks, cookies, history, tabs, the active tab, enabled experiments,
//! font sizes, a Steam cart page, and desktop shortcuts; plus Python's
//! `urlparse`-based `compare_urls` they share.
//!
//! What it is not: these functions read only the getters' values (JSON-like
//! data and text); they never talk to the guest. Where upstream's Python would
//! raise (a missing key, an unknown rule type), the metric returns an error,
//! which the evaluator scores 0 with the reason.

use serde_json::{Map, Value};

use super::{malformed, score, MetricError, MetricFn, MetricInput};
use crate::value::{json_kind, py_contains, py_eq, py_truthy, Fetched};

#[cfg(test)]
#[path = "browser_tests.rs"]
mod browser_tests;

/// The metric of this family named `name`, if implemented.
pub(super) fn lookup(name: &str) -> Option<MetricFn> {
    let f: MetricFn = match name {
        "is_expected_bookmarks" => is_expected_bookmarks,
        "is_cookie_deleted" => is_cookie_deleted,
        "check_history_deleted" => check_history_deleted,
        "is_expected_tabs" => is_expected_tabs,
        "is_expected_active_tab" => is_expected_active_tab,
        "check_enabled_experiments" => check_enabled_experiments,
        "check_font_size" => check_font_size,
        "check_edge_font_size" => check_edge_font_size,
        "is_added_to_steam_cart" => is_added_to_steam_cart,
        "is_shortcut_on_desktop" => is_shortcut_on_desktop,
        "is_url_shortcut_on_desktop" => is_url_shortcut_on_desktop,
        _ => return None,
    };
    Some(f)
}

fn bad(message: impl Into<String>) -> MetricError {
    MetricError::BadInput(message.into())
}

/// An error about `what`: the task's when it names the rules (`rules[...]`),
/// else about the result the getter read (what the agent left), the agent's.
fn shape(what: &str, message: String) -> MetricError {
    if what.starts_with("rules") {
        bad(message)
    } else {
        malformed(message)
    }
}

/// `wanted in have` could not be asked: the agent's when the rule's value is a
/// string (the shape every task gives), so the result is what cannot hold it.
fn cannot_search(have: &Value, wanted: &Value) -> MetricError {
    let message = format!("cannot search {} for {}", json_kind(have), json_kind(wanted));
    if wanted.is_string() {
        malformed(message)
    } else {
        bad(message)
    }
}

/// `rule['type']` as a string.
fn rule_type(input: &MetricInput) -> Result<&str, MetricError> {
    match input.rule("type")? {
        Value::String(kind) => Ok(kind),
        other => Err(bad(format!("rules[\"type\"] must be a string, not {}", json_kind(other)))),
    }
}

fn unsupported(kind: &str) -> MetricError {
    bad(format!("rule type {kind:?} is not supported"))
}

/// `value[key]` on a dict, as Python indexes it (a missing key or a non-dict is an error).
fn index<'a>(value: &'a Value, key: &str, what: &str) -> Result<&'a Value, MetricError> {
    match value {
        Value::Object(map) => map.get(key).ok_or_else(|| shape(what, format!("{what} has no {key:?}"))),
        other => Err(shape(what, format!("{what} must be a dict, not {}", json_kind(other)))),
    }
}

fn list<'a>(value: &'a Value, what: &str) -> Result<&'a [Value], MetricError> {
    match value {
        Value::Array(items) => Ok(items),
        other => Err(shape(what, format!("{what} must be a list, not {}", json_kind(other)))),
    }
}

fn string<'a>(value: &'a Value, what: &str) -> Result<&'a str, MetricError> {
    value.as_str().ok_or_else(|| shape(what, format!("{what} must be a string, not {}", json_kind(value))))
}

/// Every item of `wanted` is equal to some item of `have` (Python's `set(wanted) <= set(have)`).
fn is_subset(wanted: &[Value], have: &[Value]) -> bool {
    wanted.iter().all(|w| have.iter().any(|h| py_eq(w, h)))
}

fn same_set(a: &[Value], b: &[Value]) -> bool {
    is_subset(a, b) && is_subset(b, a)
}

// ----- bookmarks, cookies, history -----

/// `is_expected_bookmarks(bookmarks, rule)` on the Bookmarks `roots`: 0 for
/// no bookmarks; `bookmark_bar_folders_names` / `bookmark_bar_websites_urls`
/// pass when every expected folder name / URL is among the bookmark bar's
/// direct children (WAA relaxed OSWorld's set equality to a subset);
/// `liked_authors_websites_urls` passes when the bar's "Liked Authors" folder
/// holds exactly one choice from each expected entry (a URL or a list of alternatives).
pub(super) fn is_expected_bookmarks(input: &MetricInput) -> Result<f64, MetricError> {
    let bookmarks = input.result.to_json();
    if !py_truthy(&bookmarks) {
        return Ok(0.0);
    }
    let kind = rule_type(input)?;
    let bar = index(&bookmarks, "bookmark_bar", "the bookmarks")?;
    let children = list(index(bar, "children", "the bookmark bar")?, "the bookmark bar's children")?;
    let of_type = |nodes: &[Value], wanted: &str, field: &str| -> Result<Vec<Value>, MetricError> {
        let mut out = Vec::new();
        for node in nodes {
            if string(index(node, "type", "a bookmark")?, "a bookmark's type")? == wanted {
                out.push(index(node, field, "a bookmark")?.clone());
            }
        }
        Ok(out)
    };
    match kind {
        "bookmark_bar_folders_names" => {
            let names = of_type(children, "folder", "name")?;
            Ok(score(is_subset(list(input.rule("names")?, "rules[\"names\"]")?, &names)))
        }
        "bookmark_bar_websites_urls" => {
            let urls = of_type(children, "url", "url")?;
            Ok(score(is_subset(list(input.rule("urls")?, "rules[\"urls\"]")?, &urls)))
        }
        "liked_authors_websites_urls" => {
            let mut folder = None;
            for node in children {
                let is_folder = string(index(node, "type", "a bookmark")?, "a bookmark's type")? == "folder";
                if is_folder && node.get("name").and_then(Value::as_str) == Some("Liked Authors") {
                    folder = Some(node);
                    break;
                }
            }
            let Some(folder) = folder else { return Ok(0.0) };
            let inside =
                of_type(list(index(folder, "children", "the Liked Authors folder")?, "its children")?, "url", "url")?;
            let choices: Vec<Vec<Value>> = list(input.rule("urls")?, "rules[\"urls\"]")?
                .iter()
                .map(|entry| match entry {
                    Value::String(_) => vec![entry.clone()],
                    Value::Array(options) => options.clone(),
                    other => vec![other.clone()],
                })
                .collect();
            Ok(score(any_combination(&choices, &mut Vec::new(), &inside)?))
        }
        other => Err(unsupported(other)),
    }
}

/// Whether one pick per entry of `choices` forms the same set as `target`
/// (`itertools.product` then set equality). Refuses products past a million picks.
fn any_combination(choices: &[Vec<Value>], picked: &mut Vec<Value>, target: &[Value]) -> Result<bool, MetricError> {
    let total = choices.iter().try_fold(1usize, |acc, c| acc.checked_mul(c.len().max(1)));
    if total.is_none_or(|n| n > 1_000_000) {
        return Err(bad("rules[\"urls\"] has too many alternatives to combine"));
    }
    fn walk(choices: &[Vec<Value>], picked: &mut Vec<Value>, target: &[Value]) -> bool {
        match choices.split_first() {
            None => same_set(picked, target),
            Some((first, rest)) => first.iter().any(|option| {
                picked.push(option.clone());
                let found = walk(rest, picked, target);
                picked.pop();
                found
            }),
        }
    }
    Ok(walk(choices, picked, target))
}

/// The rows a SQLite getter returned.
fn rows<'a>(value: &'a Value, what: &str) -> Result<&'a [Value], MetricError> {
    list(value, what)
}

/// `row[idx]` of a list row.
fn column<'a>(row: &'a Value, idx: usize, what: &str) -> Result<&'a Value, MetricError> {
    list(row, what)?.get(idx).ok_or_else(|| shape(what, format!("{what} has no column {idx}")))
}

/// `is_cookie_deleted(cookie_data, rule)`: rule type `domains`; 0 when any
/// cookie's host (column 1 of Chrome's `cookies` table) equals an expected
/// domain under `compare_urls`, else 1.
pub(super) fn is_cookie_deleted(input: &MetricInput) -> Result<f64, MetricError> {
    let data = input.result.to_json();
    let cookies = rows(&data, "the cookie data")?;
    match rule_type(input)? {
        "domains" => {
            let domains = list(input.rule("domains")?, "rules[\"domains\"]")?;
            let hosts = cookies.iter().map(|row| column(row, 1, "a cookie row")).collect::<Result<Vec<_>, _>>()?;
            for domain in domains {
                for host in &hosts {
                    if compare_url_values(domain, host)? {
                        return Ok(0.0);
                    }
                }
            }
            Ok(1.0)
        }
        other => Err(unsupported(other)),
    }
}

/// `check_history_deleted(history_data, rule)`: rule type `keywords`; 0 when
/// any history URL (column 0) contains a keyword, else 1.
pub(super) fn check_history_deleted(input: &MetricInput) -> Result<f64, MetricError> {
    let data = input.result.to_json();
    let history = rows(&data, "the history data")?;
    match rule_type(input)? {
        "keywords" => {
            let keywords = list(input.rule("keywords")?, "rules[\"keywords\"]")?;
            let urls = history.iter().map(|row| column(row, 0, "a history row")).collect::<Result<Vec<_>, _>>()?;
            for keyword in keywords {
                for url in &urls {
                    let found = py_contains(url, keyword).ok_or_else(|| cannot_search(url, keyword))?;
                    if found {
                        return Ok(0.0);
                    }
                }
            }
            Ok(1.0)
        }
        other => Err(unsupported(other)),
    }
}

/// `check_enabled_experiments(enabled_experiments, rule)`: rule type `names`;
/// the experiments' names (the part before `@`) must equal `names`, in order.
pub(super) fn check_enabled_experiments(input: &MetricInput) -> Result<f64, MetricError> {
    let data = input.result.to_json();
    let names = list(&data, "the enabled experiments")?
        .iter()
        .map(|e| string(e, "an experiment").map(|s| Value::String(s.split('@').next().unwrap_or_default().to_owned())))
        .collect::<Result<Vec<_>, _>>()?;
    match rule_type(input)? {
        "names" => Ok(score(py_eq(&Value::Array(names), input.rule("names")?))),
        other => Err(unsupported(other)),
    }
}

// ----- fonts -----

/// A number as Python compares it (`True` is 1).
fn number(value: &Value, what: &str) -> Result<f64, MetricError> {
    match value {
        Value::Number(n) => n.as_f64().ok_or_else(|| shape(what, format!("{what} is not a finite number"))),
        Value::Bool(b) => Ok(f64::from(u8::from(*b))),
        other => Err(shape(what, format!("{what} must be a number, not {}", json_kind(other)))),
    }
}

/// Both font-size metrics: `value` compares with `==`; `range` is `min < size < max`
/// for Chrome and `min <= size < max` for Edge, as upstream writes them.
fn font_size_check(input: &MetricInput, inclusive_min: bool) -> Result<f64, MetricError> {
    let data = input.result.to_json();
    let size = index(&data, "default_font_size", "the font settings")?;
    match rule_type(input)? {
        "value" => Ok(score(py_eq(size, input.rule("value")?))),
        "range" => {
            let size = number(size, "default_font_size")?;
            let min = number(input.rule("min")?, "rules[\"min\"]")?;
            let max = number(input.rule("max")?, "rules[\"max\"]")?;
            let above = if inclusive_min { min <= size } else { min < size };
            Ok(score(above && size < max))
        }
        other => Err(unsupported(other)),
    }
}

/// `check_font_size(font_size, rule)` (Chrome): `rules["min"] < default_font_size < rules["max"]`, or `== rules["value"]`.
pub(super) fn check_font_size(input: &MetricInput) -> Result<f64, MetricError> {
    font_size_check(input, false)
}

/// `check_edge_font_size(font_size, rule)`: `rules["min"] <= default_font_size < rules["max"]`, or `== rules["value"]`.
pub(super) fn check_edge_font_size(input: &MetricInput) -> Result<f64, MetricError> {
    font_size_check(input, true)
}

// ----- tabs -----

/// `is_expected_tabs(open_tabs, rule)`: rule type `url`; the open tabs' URLs
/// and `urls` have the same length and each expected URL matches some tab
/// under `compare_urls`. Another rule type scores 0 (upstream logs it).
pub(super) fn is_expected_tabs(input: &MetricInput) -> Result<f64, MetricError> {
    let data = input.result.to_json();
    let tabs = list(&data, "the open tabs")?;
    match rule_type(input)? {
        "url" => {
            let expected = list(input.rule("urls")?, "rules[\"urls\"]")?;
            let actual = tabs.iter().map(|tab| index(tab, "url", "a tab")).collect::<Result<Vec<_>, _>>()?;
            if expected.len() != actual.len() {
                return Ok(0.0);
            }
            for want in expected {
                let mut found = false;
                for have in &actual {
                    if compare_url_values(want, have)? {
                        found = true;
                        break;
                    }
                }
                if !found {
                    return Ok(0.0);
                }
            }
            Ok(1.0)
        }
        other => {
            tracing::warn!(rule_type = other, "is_expected_tabs: unknown rule type");
            Ok(0.0)
        }
    }
}

/// `is_expected_active_tab(active_tab_info, rule)`: 0 for no tab; rule type
/// `url` compares the tab's `url` (or the value itself when it is not a dict)
/// with `rules["url"]` under `compare_urls`. Another rule type scores 0.
pub(super) fn is_expected_active_tab(input: &MetricInput) -> Result<f64, MetricError> {
    let info = input.result.to_json();
    if !py_truthy(&info) {
        return Ok(0.0);
    }
    match rule_type(input)? {
        "url" => {
            let actual = match &info {
                Value::Object(map) => map.get("url").cloned().unwrap_or(Value::Null),
                other => other.clone(),
            };
            Ok(score(compare_url_values(input.rule("url")?, &actual)?))
        }
        other => {
            tracing::warn!(rule_type = other, "is_expected_active_tab: unknown rule type");
            Ok(0.0)
        }
    }
}

/// `is_added_to_steam_cart(active_tab_info, rule)`: 1 when every one of
/// `rules["items"]` appears in the page's `content`.
pub(super) fn is_added_to_steam_cart(input: &MetricInput) -> Result<f64, MetricError> {
    let info = input.result.to_json();
    let content = index(&info, "content", "the page info")?;
    for item in list(input.rule("items")?, "rules[\"items\"]")? {
        let found = py_contains(content, item).ok_or_else(|| cannot_search(content, item))?;
        if !found {
            return Ok(0.0);
        }
    }
    Ok(1.0)
}

// ----- desktop shortcuts -----

/// The `{file name: content}` dict a shortcut getter returned.
fn shortcuts(result: &Fetched) -> Result<Map<String, Value>, MetricError> {
    match result.to_json() {
        Value::Object(map) => Ok(map),
        other => Err(malformed(format!("the shortcuts must be a dict, not {}", json_kind(&other)))),
    }
}

/// `is_shortcut_on_desktop(shortcuts, rule)`, rule types:
/// - `name`: some shortcut holds the line `Name=<name>` (Linux `.desktop` files);
/// - `description`: some `.lnk` shortcut's parsed `data.description` contains `description`;
///
/// every other type (`url` and `id` included) is an error, as upstream raises
/// `TypeError` for them (`is_url_shortcut_on_desktop` is the URL check).
pub(super) fn is_shortcut_on_desktop(input: &MetricInput) -> Result<f64, MetricError> {
    let shortcuts = shortcuts(&input.result)?;
    let contents: Vec<&str> = shortcuts.values().filter_map(Value::as_str).collect();
    if contents.len() != shortcuts.len() {
        return Err(malformed("every shortcut's content must be text"));
    }
    match rule_type(input)? {
        "name" => {
            let line = format!("Name={}\n", string(input.rule("name")?, "rules[\"name\"]")?);
            Ok(score(contents.iter().any(|c| c.contains(&line))))
        }
        "description" => {
            let wanted = input.rule("description")?;
            // Upstream wraps each shortcut in a bare `except`: one that does
            // not parse, or has no description, is skipped.
            let found = contents.iter().any(|content| {
                let Ok(parsed) = serde_json::from_str::<Value>(content) else { return false };
                parsed.get("data").and_then(|d| d.get("description")).and_then(|d| py_contains(d, wanted)) == Some(true)
            });
            Ok(score(found))
        }
        other => Err(unsupported(other)),
    }
}

/// `is_url_shortcut_on_desktop(shortcuts, rule)`: rule type `url`; 1 when
/// some `.url` file's text contains `rules["url_content"]`.
pub(super) fn is_url_shortcut_on_desktop(input: &MetricInput) -> Result<f64, MetricError> {
    let shortcuts = shortcuts(&input.result)?;
    match rule_type(input)? {
        "url" => {
            let wanted = input.rule("url_content")?;
            let mut found = false;
            for content in shortcuts.values() {
                found |= py_contains(content, wanted).ok_or_else(|| cannot_search(content, wanted))?;
            }
            Ok(score(found))
        }
        other => Err(unsupported(other)),
    }
}

// ----- Python's urlparse and compare_urls -----

/// The six parts of Python's `urlparse`.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub(crate) struct ParsedUrl {
    pub(crate) scheme: String,
    pub(crate) netloc: String,
    pub(crate) path: String,
    pub(crate) params: String,
    pub(crate) query: String,
    pub(crate) fragment: String,
}

/// Schemes whose paths carry `;params` (`urllib.parse.uses_params`).
const USES_PARAMS: [&str; 15] = [
    "", "ftp", "hdl", "prospero", "http", "imap", "https", "shttp", "rtsp", "rtspu", "sip", "sips", "mms", "sftp",
    "tel",
];
/// Schemes written with `//netloc` (`urllib.parse.uses_netloc`).
const USES_NETLOC: [&str; 26] = [
    "",
    "ftp",
    "http",
    "gopher",
    "nntp",
    "telnet",
    "imap",
    "wais",
    "file",
    "mms",
    "https",
    "shttp",
    "snews",
    "prospero",
    "rtsp",
    "rtspu",
    "rsync",
    "svn",
    "svn+ssh",
    "sftp",
    "nfs",
    "git",
    "git+ssh",
    "ws",
    "wss",
    "itms-services",
];

/// Python's `urllib.parse.urlparse`.
pub(crate) fn urlparse(url: &str) -> ParsedUrl {
    // WHATWG leading C0 controls and spaces go, and so do tabs and newlines anywhere.
    let url: String =
        url.trim_start_matches(|c: char| c <= ' ').chars().filter(|c| !matches!(c, '\t' | '\r' | '\n')).collect();
    let mut rest = url.as_str();
    let mut out = ParsedUrl::default();
    if let Some(colon) = rest.find(':') {
        let candidate = &rest[..colon];
        let first_alpha = candidate.chars().next().is_some_and(|c| c.is_ascii_alphabetic());
        if colon > 0
            && first_alpha
            && candidate.chars().all(|c| c.is_ascii_alphanumeric() || matches!(c, '+' | '-' | '.'))
        {
            out.scheme = candidate.to_ascii_lowercase();
            rest = &rest[colon + 1..];
        }
    }
    if let Some(after) = rest.strip_prefix("//") {
        let end = after.find(['/', '?', '#']).unwrap_or(after.len());
        out.netloc = after[..end].to_owned();
        rest = &after[end..];
    }
    if let Some((head, fragment)) = rest.split_once('#') {
        out.fragment = fragment.to_owned();
        rest = head;
    }
    if let Some((head, query)) = rest.split_once('?') {
        out.query = query.to_owned();
        rest = head;
    }
    let mut path = rest.to_owned();
    if USES_PARAMS.contains(&out.scheme.as_str()) && path.contains(';') {
        let split = match path.rfind('/') {
            Some(slash) => path[slash..].find(';').map(|i| slash + i),
            None => path.find(';'),
        };
        if let Some(i) = split {
            out.params = path[i + 1..].to_owned();
            path.truncate(i);
        }
    }
    out.path = path;
    out
}

/// Python's `urllib.parse.urlunparse` (3.12).
pub(crate) fn urlunparse(parts: &ParsedUrl) -> String {
    let mut url = parts.path.clone();
    if !parts.params.is_empty() {
        url = format!("{url};{}", parts.params);
    }
    if !parts.netloc.is_empty() {
        if !url.is_empty() && !url.starts_with('/') {
            url.insert(0, '/');
        }
        url = format!("//{}{url}", parts.netloc);
    } else if url.starts_with("//")
        || (!parts.scheme.is_empty()
            && USES_NETLOC.contains(&parts.scheme.as_str())
            && (url.is_empty() || url.starts_with('/')))
    {
        // A path that itself starts with `//`, or an empty or rooted path of a
        // netloc scheme, gets an empty netloc so it reads back the same.
        url = format!("//{url}");
    }
    if !parts.scheme.is_empty() {
        url = format!("{}:{url}", parts.scheme);
    }
    if !parts.query.is_empty() {
        url = format!("{url}?{}", parts.query);
    }
    if !parts.fragment.is_empty() {
        url = format!("{url}#{}", parts.fragment);
    }
    url
}

/// Upstream's `compare_urls`: both URLs normalised (scheme default `http`,
/// lower-case scheme and host, every `www.` dropped from the host, a bare `/`
/// path emptied) and compared as strings. Two `None`s are equal.
pub(crate) fn compare_urls(a: Option<&str>, b: Option<&str>) -> bool {
    fn normalize(url: &str) -> String {
        let mut parts = urlparse(url);
        if parts.scheme.is_empty() {
            parts.scheme = "http".into();
        }
        parts.scheme = parts.scheme.to_ascii_lowercase();
        parts.netloc = parts.netloc.to_lowercase().replace("www.", "");
        if parts.path == "/" {
            parts.path.clear();
        }
        urlunparse(&parts)
    }
    match (a, b) {
        (Some(a), Some(b)) => normalize(a) == normalize(b),
        (a, b) => a == b,
    }
}

/// [`compare_urls`] on JSON values: `None` is Python's `None`; anything else
/// but a string cannot be parsed (upstream's `urlparse` raises). `rule` is the
/// task's URL, `found` the result's: a bad one is the task's, the other the agent's.
fn compare_url_values(rule: &Value, found: &Value) -> Result<bool, MetricError> {
    let as_url = |v: &Value| -> Result<Option<String>, String> {
        match v {
            Value::Null => Ok(None),
            Value::String(s) => Ok(Some(s.clone())),
            other => Err(format!("a URL must be a string, not {}", json_kind(other))),
        }
    };
    let rule = as_url(rule).map_err(bad)?;
    let found = as_url(found).map_err(malformed)?;
    Ok(compare_urls(rule.as_deref(), found.as_deref()))
}
