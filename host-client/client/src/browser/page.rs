//! A page's title, address and HTML over the DevTools protocol, as upstream's
//! Playwright getters read them (`page.title()`, `page.url`, `page.content()`):
//! [`read_page`] of an open page, [`open_and_read`] of a new tab navigated to
//! an address and left to load.
//!
//! `content` is the document's serialisation as Playwright gives it: the
//! doctype, then the root element's `outerHTML`.
//!
//! Waiting follows Playwright's load states by polling `document.readyState`:
//! `load` waits for `complete`, `domcontentloaded` for anything past
//! `loading`, and `networkidle` for `complete` and then half a second more
//! (Playwright's quiet period; network requests themselves are not watched).

use std::time::Duration;

use serde::Deserialize;
use serde_json::{json, Value};

use super::cdp::{CdpError, CdpSession, Target};
use crate::client::GuestClient;

/// Reads the title, the address and the HTML.
pub(crate) const READ_SCRIPT: &str = "/* arena:read-page */ (() => { let html = ''; \
    if (document.doctype) html = new XMLSerializer().serializeToString(document.doctype); \
    if (document.documentElement) html += document.documentElement.outerHTML; \
    return {title: document.title, url: location.href, content: html}; })()";
/// Reads how far the document has loaded, and its address.
pub(crate) const STATE_SCRIPT: &str = "/* arena:ready-state */ [document.readyState, location.href]";
/// Longest a page may take to reach its load state (Playwright's default timeout).
pub const LOAD_TIMEOUT: Duration = Duration::from_secs(30);
/// Between two looks at `document.readyState`.
const POLL: Duration = Duration::from_millis(100);

/// What the page getters return.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
pub struct PageInfo {
    pub title: String,
    pub url: String,
    pub content: String,
}

/// A Playwright load state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LoadState {
    Load,
    DomContentLoaded,
    NetworkIdle,
}

impl LoadState {
    /// Playwright's name; anything else is `load`, its default.
    pub fn parse(name: &str) -> LoadState {
        match name {
            "domcontentloaded" => LoadState::DomContentLoaded,
            "networkidle" => LoadState::NetworkIdle,
            _ => LoadState::Load,
        }
    }
}

/// The title, address and HTML of the session's page.
///
/// # Errors
///
/// The session's errors; [`CdpError::Decode`] for an answer of another shape.
pub async fn read_page(session: &CdpSession) -> Result<PageInfo, CdpError> {
    let answer = session.evaluate(READ_SCRIPT).await?;
    serde_json::from_value(answer)
        .map_err(|err| CdpError::Decode { what: "the page's title, address and HTML".into(), reason: err.to_string() })
}

/// Waits until the page reaches `state` at an address other than
/// `about:blank` (unless that is where it was sent); `false` when `timeout` passed first.
///
/// # Errors
///
/// The session's errors.
pub async fn wait_for_load(
    session: &CdpSession,
    state: LoadState,
    blank_ok: bool,
    timeout: Duration,
) -> Result<bool, CdpError> {
    let deadline = tokio::time::Instant::now() + timeout;
    loop {
        let answer = session.evaluate(STATE_SCRIPT).await?;
        let ready = answer.get(0).and_then(Value::as_str).unwrap_or_default();
        let url = answer.get(1).and_then(Value::as_str).unwrap_or_default();
        let arrived = blank_ok || url != "about:blank";
        let reached = match state {
            LoadState::DomContentLoaded => ready == "interactive" || ready == "complete",
            LoadState::Load | LoadState::NetworkIdle => ready == "complete",
        };
        if arrived && reached {
            if state == LoadState::NetworkIdle {
                tokio::time::sleep(Duration::from_millis(500)).await;
            }
            return Ok(true);
        }
        if tokio::time::Instant::now() >= deadline {
            return Ok(false);
        }
        tokio::time::sleep(POLL).await;
    }
}

/// Opens a new tab, navigates it to `url` (`Page.navigate`), waits for `state`
/// and reads it; the tab is closed afterwards. A page that does not reach its
/// state within [`LOAD_TIMEOUT`] is read as it is, titled `Load timeout`, as
/// upstream's `get_page_info` does.
///
/// # Errors
///
/// [`CdpError::Http`] when no browser answers, [`CdpError::Protocol`] when the
/// navigation fails (`net::ERR_NAME_NOT_RESOLVED`), the session's errors.
pub async fn open_and_read(client: &GuestClient, url: &str, state: LoadState) -> Result<PageInfo, CdpError> {
    let body = client.browser_put("json/new").await?;
    let target: Target = serde_json::from_slice(&body)
        .map_err(|err| CdpError::Decode { what: "json/new".into(), reason: err.to_string() })?;
    let read = async {
        let ws = target.ws_url.as_deref().ok_or_else(|| CdpError::Decode {
            what: "json/new".into(),
            reason: "the new target has no webSocketDebuggerUrl".into(),
        })?;
        let session = CdpSession::connect(client, ws).await?;
        let read = async {
            let navigated = session.call("Page.navigate", json!({"url": url})).await?;
            if let Some(error) = navigated.get("errorText").and_then(Value::as_str).filter(|e| !e.is_empty()) {
                return Err(CdpError::Protocol {
                    method: "Page.navigate".into(),
                    code: 0,
                    message: format!("{url}: {error}"),
                });
            }
            let loaded = wait_for_load(&session, state, url == "about:blank", LOAD_TIMEOUT).await?;
            let mut info = read_page(&session).await?;
            if !loaded {
                info.title = "Load timeout".into();
            }
            Ok(info)
        }
        .await;
        session.close().await;
        read
    }
    .await;
    if let Err(err) = client.browser_get(&format!("json/close/{}", target.id)).await {
        tracing::debug!(%err, "could not close the tab opened to read {url}");
    }
    read
}
