//! The DevTools client through a real stub guest (with a token) and its
//! websocket relay: against the fake browser of [`super::fake`], and against a
//! real headless Chromium when one is installed (`SKIPPED: ...` otherwise, a
//! failure with `ARENA_REQUIRE_CHROMIUM=1`).

use std::time::Duration;

use arena_shared::geometry::Rect;
use arena_test_support::StubGuest;
use serde_json::json;

use super::cdp::{CdpError, CdpSession};
use super::dom::{dom_elements, DomElement};
use super::fake::{FakeDevtools, FakePage};
use crate::client::{ClientConfig, GuestClient};

const TOKEN: &str = "0123456789abcdef0123";

/// A stub guest with the token whose debugging port is `cdp_port`, and a client with (or without) the token.
async fn guest(cdp_port: u16, with_token: bool) -> (StubGuest, GuestClient) {
    let stub = StubGuest::start_with(|config| {
        config.token = Some(TOKEN.into());
        config.cdp_port = cdp_port;
    })
    .await;
    let token = with_token.then(|| TOKEN.to_owned());
    let client = GuestClient::new(stub.url(), ClientConfig { token, timeout: Duration::from_secs(20), retries: 0 })
        .expect("client");
    (stub, client)
}

/// The front page of the fake: a maximised window at 150 % with two elements.
fn front_page() -> FakePage {
    FakePage {
        id: "FRONT".into(),
        title: "Shop".into(),
        url: "https://shop.example/".into(),
        dom: json!({
            "window": {"screenX": -8, "screenY": -8, "outerWidth": 1456, "outerHeight": 916,
                       "innerWidth": 1440, "innerHeight": 781, "devicePixelRatio": 1.5},
            "title": "Shop",
            "items": [
                {"left": 10, "top": 20, "right": 110, "bottom": 40, "text": "Add to cart", "kind": "BUTTON"},
                {"left": 0, "top": 100, "right": 50, "bottom": 118.4, "text": "<svg aria-label=\"cart\"></svg>", "kind": "A"},
            ],
        }),
        ..FakePage::default()
    }
}

#[tokio::test]
async fn dom_elements_of_the_front_page_come_through_the_relay_in_screen_pixels() {
    let background = FakePage { id: "BACK".into(), url: "https://other.example/".into(), ..FakePage::default() };
    let browser = FakeDevtools::start(vec![front_page(), background], &[]).await;
    let (_stub, client) = guest(browser.port, true).await;
    let elements = dom_elements(&client).await.expect("dom elements");
    // Viewport origin in DIPs: (-8 + 8, -8 + 127) = (0, 119); times 1.5.
    assert_eq!(
        elements,
        [
            DomElement { rect: Rect::from_ltrb(15, 209, 165, 239), text: "Add to cart".into(), kind: "BUTTON".into() },
            DomElement {
                rect: Rect::from_ltrb(0, 329, 75, 356),
                text: "<svg aria-label=\"cart\"></svg>".into(),
                kind: "A".into()
            },
        ]
    );
    assert_eq!(browser.methods(), ["Runtime.evaluate"], "one evaluation of the front page");
}

#[tokio::test]
async fn the_relay_needs_the_token_and_a_browser() {
    let browser = FakeDevtools::start(vec![front_page()], &[]).await;
    let (_stub, anonymous) = guest(browser.port, false).await;
    match CdpSession::connect(&anonymous, &format!("ws://127.0.0.1:{}/devtools/page/FRONT", browser.port)).await {
        Err(CdpError::Connect { reason, .. }) => assert!(reason.starts_with("HTTP 401"), "{reason}"),
        other => panic!("expected a 401, got {other:?}"),
    }
    assert!(browser.methods().is_empty());

    // No browser listening: dom_elements fails naming the port (the episode turns this into `None`).
    let unused = std::net::TcpListener::bind("127.0.0.1:0").expect("bind").local_addr().expect("addr").port();
    let (_stub, client) = guest(unused, true).await;
    let err = dom_elements(&client).await.expect_err("no browser");
    assert!(matches!(err, CdpError::Http(_)), "{err:?}");
    assert!(err.to_string().contains(&format!("debugging port {unused}")), "{err}");
}

#[tokio::test]
async fn commands_answer_by_id_and_errors_are_named() {
    let browser = FakeDevtools::start(vec![front_page()], &[]).await;
    let (_stub, client) = guest(browser.port, true).await;
    let session = CdpSession::connect(&client, &format!("ws://127.0.0.1:{}/devtools/page/FRONT", browser.port))
        .await
        .expect("session");
    // Concurrent calls each get their own answer.
    let (a, b) = tokio::join!(
        session.evaluate(super::page::STATE_SCRIPT),
        session.call("Page.navigate", json!({"url": "https://nowhere.invalid/"})),
    );
    assert_eq!(a.expect("state"), json!(["complete", "https://shop.example/"]));
    assert_eq!(b.expect("navigate")["errorText"], json!("net::ERR_NAME_NOT_RESOLVED"));
    let err = session.call("DOM.getDocument", json!({})).await.expect_err("unknown to the fake");
    assert!(matches!(&err, CdpError::Protocol { code: -32601, .. }), "{err:?}");
    let err = session.evaluate("1 + 1").await.expect_err("the fake runs no script");
    assert!(matches!(&err, CdpError::Script(text) if text.contains("ReferenceError")), "{err:?}");
    session.close().await;
}

#[tokio::test]
async fn a_real_headless_chromium_is_driven_through_the_relay() {
    let Some(binary) = arena_test_support::chromium_or_skip("a_real_headless_chromium_is_driven_through_the_relay")
    else {
        return;
    };
    let html = "<!DOCTYPE html><html><head><title>Arena test page</title></head>\
        <body style=\"margin:0\"><button id=\"go\" style=\"position:absolute;left:10px;top:20px;width:100px;height:30px\">Go now</button>\
        <a href=\"https://example.org/next\" style=\"position:absolute;left:10px;top:80px\">Next page</a>\
        <div style=\"position:absolute;left:10px;top:140px\"><button disabled>Off</button></div>\
        <p>Plain text is not proposed</p></body></html>";
    let dir = tempfile::tempdir().expect("page dir");
    let page = dir.path().join("page.html");
    std::fs::write(&page, html).expect("write the page");
    let url = format!("file://{}", page.display());
    let chromium = arena_test_support::Chromium::start(&binary, &["--window-size=800,600"], &url).await;
    let (_stub, client) = guest(chromium.port, true).await;

    // The page may still be loading when DevTools first answers.
    let mut elements = Vec::new();
    for _ in 0..100 {
        match dom_elements(&client).await {
            Ok(found) if found.len() >= 2 => {
                elements = found;
                break;
            }
            Ok(_) | Err(CdpError::NoPage) => tokio::time::sleep(Duration::from_millis(100)).await,
            Err(err) => panic!("dom_elements: {err}"),
        }
    }
    let kinds: Vec<(&str, &str)> = elements.iter().map(|e| (e.kind.as_str(), e.text.as_str())).collect();
    assert_eq!(kinds, [("BUTTON", "Go now"), ("A", "Next page")], "{elements:?}");
    // Headless: no frame, so screen pixels are the page's CSS pixels times the ratio (1 here).
    let button = &elements[0];
    assert!(button.rect.x >= 10 && button.rect.right() <= 110, "{:?}", button.rect);
    assert!(button.rect.y >= 20 && button.rect.bottom() <= 50, "{:?}", button.rect);

    // The page getters' reading over the same relay.
    let targets = super::cdp::page_targets(&client).await.expect("targets");
    let front = targets.iter().find(|t| t.url.starts_with("file://")).expect("the page's target");
    let session = CdpSession::connect(&client, front.ws_url.as_deref().expect("ws url")).await.expect("session");
    let info = super::page::read_page(&session).await.expect("read");
    assert_eq!(info.title, "Arena test page");
    assert!(
        info.content.starts_with("<!DOCTYPE html>") && info.content.contains("Plain text is not proposed"),
        "{}",
        info.content
    );
    session.close().await;
}
