//! The browser tab steps (`chrome_open_tabs`, `edge_open_tabs`,
//! `chrome_close_tabs`) over the browser's DevTools HTTP endpoint, reached
//! through the guest's `/v1/browser/...` forward.
//!
//! Upstream's host drove Playwright over the DevTools websocket
//! (`connect_over_cdp`, up to 15 attempts 5 s apart). Opening, listing and
//! closing tabs need only the HTTP endpoints: `GET /json/version` (is a
//! browser there?), `GET /json/list` (the targets), `PUT /json/new?<url>`
//! (open a tab) and `GET /json/close/<id>`. Upstream waited for each page to
//! load (`goto`, 60 s); `/json/new` answers once the tab exists, so the page
//! may still be loading when the step ends.

use std::time::Duration;

use serde::Deserialize;

use super::outcome::Outcome;
use super::SetupContext;

/// Connection attempts before giving up (upstream: 15).
const CONNECT_ATTEMPTS: u32 = 15;
/// Pause between connection attempts (upstream: 5 s), scaled by [`super::Settle`].
const CONNECT_PAUSE: Duration = Duration::from_secs(5);
/// Upstream's pause before closing tabs.
const CLOSE_PAUSE: Duration = Duration::from_secs(5);

/// One DevTools target of `/json/list` and `/json/new`.
#[derive(Debug, Clone, Deserialize)]
struct Target {
    id: String,
    #[serde(default, rename = "type")]
    kind: String,
    #[serde(default)]
    url: String,
}

/// Waits for the browser's endpoint as upstream's connect loop does; answers the last error.
async fn connect(ctx: &SetupContext) -> Result<(), String> {
    let mut last = String::new();
    for attempt in 1..=CONNECT_ATTEMPTS {
        match ctx.client.browser_get("json/version").await {
            Ok(_) => return Ok(()),
            Err(err) => {
                tracing::debug!(attempt, error = %err, "browser not reachable yet");
                last = err.to_string();
            }
        }
        if attempt < CONNECT_ATTEMPTS {
            ctx.settle.pause(CONNECT_PAUSE).await;
        }
    }
    Err(format!("the browser's DevTools endpoint did not answer after {CONNECT_ATTEMPTS} attempts: {last}"))
}

async fn pages(ctx: &SetupContext) -> Result<Vec<Target>, String> {
    let body = ctx.client.browser_get("json/list").await.map_err(|err| err.to_string())?;
    let targets: Vec<Target> =
        serde_json::from_slice(&body).map_err(|err| format!("/json/list is not a list of targets: {err}"))?;
    Ok(targets.into_iter().filter(|t| t.kind == "page").collect())
}

async fn close(ctx: &SetupContext, id: &str) -> Result<(), String> {
    // Target ids are hex; anything else would change the path, so it is refused.
    if id.is_empty() || !id.chars().all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_') {
        return Err(format!("refusing to close a target with the id {id:?}"));
    }
    ctx.client.browser_get(&format!("json/close/{id}")).await.map(drop).map_err(|err| err.to_string())
}

/// `chrome_open_tabs`: a new tab per URL; after the first, the tab the browser
/// started with is closed, as upstream does.
pub(super) async fn open_tabs(ctx: &SetupContext, urls: &[String]) -> Outcome {
    if let Err(err) = connect(ctx).await {
        return Outcome::failed(err);
    }
    let original = match pages(ctx).await {
        Ok(pages) => pages.into_iter().next(),
        Err(err) => return Outcome::failed(err),
    };
    let mut opened = Vec::new();
    let mut problems = Vec::new();
    for (i, url) in urls.iter().enumerate() {
        match ctx.client.browser_put(&format!("json/new?{url}")).await {
            Ok(_) => opened.push(url.as_str()),
            Err(err) => problems.push(format!("{url}: {err}")),
        }
        if i == 0 {
            if let Some(original) = &original {
                if let Err(err) = close(ctx, &original.id).await {
                    problems.push(format!("closing the original tab: {err}"));
                }
            }
        }
    }
    let detail = format!("opened {} of {} tabs: {}", opened.len(), urls.len(), opened.join(", "));
    if problems.is_empty() {
        Outcome::done(detail)
    } else {
        Outcome::failed(format!("{detail}; {}", problems.join("; ")))
    }
}

/// `chrome_close_tabs`: closes every tab whose URL [`compare_urls`] matches one of `urls`.
pub(super) async fn close_tabs(ctx: &SetupContext, urls: &[String]) -> Outcome {
    ctx.settle.pause(CLOSE_PAUSE).await;
    if let Err(err) = connect(ctx).await {
        return Outcome::failed(err);
    }
    let pages = match pages(ctx).await {
        Ok(pages) => pages,
        Err(err) => return Outcome::failed(err),
    };
    let mut closed = Vec::new();
    let mut problems = Vec::new();
    for page in pages.iter().filter(|p| urls.iter().any(|u| compare_urls(&p.url, u))) {
        match close(ctx, &page.id).await {
            Ok(()) => closed.push(page.url.as_str()),
            Err(err) => problems.push(format!("{}: {err}", page.url)),
        }
    }
    let detail = format!("closed {} tabs: {}", closed.len(), closed.join(", "));
    if problems.is_empty() {
        Outcome::done(detail)
    } else {
        Outcome::failed(format!("{detail}; {}", problems.join("; ")))
    }
}

/// Whether two URLs are the same page by upstream's `compare_urls`: scheme
/// (default `http`) and host lowercased, `www.` removed from the host, a path
/// of just `/` dropped; query and fragment compared as written.
pub fn compare_urls(a: &str, b: &str) -> bool {
    normalize_url(a) == normalize_url(b)
}

/// Python's `urlunparse` of the normalised `urlparse` parts.
fn normalize_url(url: &str) -> String {
    let parts = split_url(url);
    let scheme = if parts.scheme.is_empty() { "http".to_owned() } else { parts.scheme.to_ascii_lowercase() };
    let netloc = parts.netloc.to_lowercase().replace("www.", "");
    let path = if parts.path == "/" { "" } else { parts.path };
    // `urlunsplit`: a netloc, or a scheme that uses one, puts `//` before the path.
    let mut out = path.to_owned();
    if !netloc.is_empty() || (USES_NETLOC.contains(&scheme.as_str()) && !out.starts_with("//")) {
        if !out.is_empty() && !out.starts_with('/') {
            out.insert(0, '/');
        }
        out = format!("//{netloc}{out}");
    }
    out = format!("{scheme}:{out}");
    if let Some(query) = parts.query.filter(|q| !q.is_empty()) {
        out = format!("{out}?{query}");
    }
    if let Some(fragment) = parts.fragment.filter(|f| !f.is_empty()) {
        out = format!("{out}#{fragment}");
    }
    out
}

/// Python's `urllib.parse.uses_netloc`.
const USES_NETLOC: &[&str] = &[
    "", "ftp", "http", "gopher", "nntp", "telnet", "imap", "wais", "file", "mms", "https", "shttp", "snews",
    "prospero", "rtsp", "rtspu", "rsync", "svn", "svn+ssh", "sftp", "nfs", "git", "git+ssh", "ws", "wss",
];

struct UrlParts<'a> {
    scheme: &'a str,
    netloc: &'a str,
    path: &'a str,
    query: Option<&'a str>,
    fragment: Option<&'a str>,
}

/// Python's `urlsplit`, enough for comparing: a scheme is letters, digits,
/// `+`, `-`, `.` starting with a letter before the first `:`.
fn split_url(url: &str) -> UrlParts<'_> {
    let url = url.trim();
    let (scheme, rest) = match url.split_once(':') {
        Some((scheme, rest))
            if scheme.starts_with(|c: char| c.is_ascii_alphabetic())
                && scheme.chars().all(|c| c.is_ascii_alphanumeric() || "+-.".contains(c)) =>
        {
            (scheme, rest)
        }
        _ => ("", url),
    };
    let (netloc, rest) = match rest.strip_prefix("//") {
        Some(after) => {
            let end = after.find(['/', '?', '#']).unwrap_or(after.len());
            (&after[..end], &after[end..])
        }
        None => ("", rest),
    };
    let (rest, fragment) = match rest.split_once('#') {
        Some((rest, fragment)) => (rest, Some(fragment)),
        None => (rest, None),
    };
    let (path, query) = match rest.split_once('?') {
        Some((path, query)) => (path, Some(query)),
        None => (rest, None),
    };
    UrlParts { scheme, netloc, path, query, fragment }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(a: &str, b: &str, same: bool) {
        assert_eq!(compare_urls(a, b), same, "{a} vs {b}");
    }

    #[test]
    fn urls_compare_as_upstream_normalises_them() {
        check("https://www.Example.com/", "https://example.com", true);
        check("HTTPS://example.com/a", "https://EXAMPLE.com/a", true);
        check("https://example.com/a/", "https://example.com/a", false);
        check("http://example.com/a?q=1", "http://example.com/a?q=2", false);
        check("http://example.com/a#top", "http://example.com/a#top", true);
        check("https://example.com", "http://example.com", false);
        // Without a scheme urlparse sees a path, not a host.
        check("example.com", "http://example.com", false);
        check("example.com", "example.com/", false);
    }

    #[test]
    fn normalised_forms_match_python() {
        assert_eq!(normalize_url("example.com"), "http:///example.com");
        assert_eq!(normalize_url("https://www.google.com/"), "https://google.com");
        assert_eq!(normalize_url("about:blank"), "about:blank");
        assert_eq!(normalize_url("chrome://newtab/"), "chrome://newtab");
    }
}
