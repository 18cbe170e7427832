//! The DevTools websocket relay (`/v1/browser/devtools/{*path}`) over real
//! sockets: a guest served by `arena_guest::serve` on `127.0.0.1:0`, and a fake
//! browser whose `/devtools/page/<id>` websocket echoes every text message and
//! counts them. Upgrades need a connection, so these tests do not use `oneshot`.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;

use futures_util::{SinkExt as _, StreamExt as _};
use tokio_tungstenite::tungstenite::client::IntoClientRequest as _;
use tokio_tungstenite::tungstenite::http::HeaderValue;
use tokio_tungstenite::tungstenite::{self, Message};

use arena_guest::config::ServerConfig;
use arena_shared::error::ErrorBody;

const TOKEN: &str = "0123456789abcdef0123";

/// A fake browser: a websocket echo on `/devtools/...`; answers its port and how many messages it got.
async fn fake_browser() -> (u16, Arc<AtomicUsize>) {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.expect("bind");
    let port = listener.local_addr().expect("addr").port();
    let received = Arc::new(AtomicUsize::new(0));
    let count = Arc::clone(&received);
    tokio::spawn(async move {
        while let Ok((stream, _)) = listener.accept().await {
            let count = Arc::clone(&count);
            tokio::spawn(async move {
                // The callback's error type is tungstenite's, large by design.
                #[allow(clippy::result_large_err)]
                fn check(
                    request: &tungstenite::handshake::server::Request,
                    response: tungstenite::handshake::server::Response,
                ) -> Result<tungstenite::handshake::server::Response, tungstenite::handshake::server::ErrorResponse>
                {
                    assert!(request.uri().path().starts_with("/devtools/page/"), "{}", request.uri());
                    assert!(request.headers().get("origin").is_none(), "the relay sends no Origin");
                    Ok(response)
                }
                let Ok(mut socket) = tokio_tungstenite::accept_hdr_async(stream, check).await else { return };
                while let Some(Ok(message)) = socket.next().await {
                    if let Message::Text(text) = message {
                        count.fetch_add(1, Ordering::SeqCst);
                        if socket.send(Message::Text(format!("echo {text}").into())).await.is_err() {
                            break;
                        }
                    }
                }
            });
        }
    });
    (port, received)
}

/// A guest with a token whose debugging port is `cdp_port`; answers its address and its stop switch.
async fn guest(
    cdp_port: u16,
) -> (String, tokio::sync::oneshot::Sender<()>, tokio::task::JoinHandle<()>, tempfile::TempDir) {
    let root = tempfile::tempdir().expect("root");
    let mut config = ServerConfig::for_stub();
    config.token = Some(TOKEN.into());
    config.cdp_port = cdp_port;
    config.stub_root = Some(root.path().to_path_buf());
    config.shutdown_grace_ms = 5_000;
    let state = arena_guest::build_state(config).expect("state");
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.expect("bind");
    let addr = listener.local_addr().expect("addr").to_string();
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let served = tokio::spawn(async move {
        let _ = arena_guest::serve(listener, state, async move {
            let _ = stopped.await;
        })
        .await;
    });
    (addr, stop, served, root)
}

/// Opens the relay to `page/<id>` with the given extra headers.
async fn open(
    addr: &str,
    headers: &[(&'static str, &str)],
) -> Result<
    tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>,
    tungstenite::Error,
> {
    let mut request = format!("ws://{addr}/v1/browser/devtools/page/ABC123").into_client_request().expect("request");
    for (name, value) in headers {
        request.headers_mut().insert(*name, HeaderValue::from_str(value).expect("header"));
    }
    tokio_tungstenite::connect_async(request).await.map(|(socket, _)| socket)
}

/// The status and error message of a refused handshake.
fn refusal(result: Result<impl std::fmt::Debug, tungstenite::Error>) -> (u16, String) {
    match result {
        Err(tungstenite::Error::Http(answer)) => {
            let body: ErrorBody =
                serde_json::from_slice(answer.body().as_deref().unwrap_or_default()).expect("an error body");
            (answer.status().as_u16(), body.message)
        }
        other => panic!("expected an HTTP refusal, got {other:?}"),
    }
}

const BEARER: &str = "Bearer 0123456789abcdef0123";

#[tokio::test]
async fn the_relay_carries_messages_both_ways_with_the_token() {
    let (port, received) = fake_browser().await;
    let (addr, _stop, _served, _root) = guest(port).await;
    let mut socket = open(&addr, &[("authorization", BEARER)]).await.expect("relay opened");
    for n in 0..3 {
        socket.send(Message::Text(format!("{{\"id\":{n}}}").into())).await.expect("send");
        let answer = socket.next().await.expect("an answer").expect("a message");
        assert_eq!(answer, Message::Text(format!("echo {{\"id\":{n}}}").into()));
    }
    assert_eq!(received.load(Ordering::SeqCst), 3);
    socket.close(None).await.expect("close");
}

#[tokio::test]
async fn the_relay_is_guarded_like_every_route() {
    let (port, received) = fake_browser().await;
    let (addr, _stop, _served, _root) = guest(port).await;
    let (status, message) = refusal(open(&addr, &[]).await);
    assert_eq!(status, 401, "{message}");
    let (status, _) = refusal(open(&addr, &[("authorization", "Bearer wrong-token-wrong-token")]).await);
    assert_eq!(status, 401);
    // A page in the VM's browser sends an Origin with its websocket: refused even with the token.
    let (status, message) =
        refusal(open(&addr, &[("authorization", BEARER), ("origin", "https://evil.example")]).await);
    assert_eq!(status, 403, "{message}");
    assert!(message.contains("cross-site"), "{message}");
    assert_eq!(received.load(Ordering::SeqCst), 0, "nothing reached the browser");
}

#[tokio::test]
async fn a_plain_request_to_the_relay_is_told_to_upgrade() {
    let (port, _) = fake_browser().await;
    let (addr, _stop, _served, _root) = guest(port).await;
    let answer = reqwest::Client::new()
        .get(format!("http://{addr}/v1/browser/devtools/page/ABC123"))
        .header("authorization", BEARER)
        .send()
        .await
        .expect("an answer");
    assert_eq!(answer.status().as_u16(), 400);
    let body: ErrorBody = answer.json().await.expect("an error body");
    assert!(body.message.contains("Upgrade: websocket"), "{}", body.message);
    // The DevTools HTTP forward next to it is untouched.
    let answer = reqwest::Client::new()
        .get(format!("http://{addr}/v1/browser/json/version"))
        .header("authorization", BEARER)
        .send()
        .await
        .expect("an answer");
    assert_ne!(answer.status().as_u16(), 400);
}

#[tokio::test]
async fn without_a_browser_the_handshake_is_a_502_naming_the_port() {
    let unused = {
        let listener = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
        listener.local_addr().expect("addr").port()
    };
    let (addr, _stop, _served, _root) = guest(unused).await;
    let (status, message) = refusal(open(&addr, &[("authorization", BEARER)]).await);
    assert_eq!(status, 502);
    assert!(message.contains(&format!("debugging port {unused}")), "{message}");
}

#[tokio::test]
async fn a_message_over_the_bound_closes_the_relay_and_is_not_forwarded() {
    let (port, received) = fake_browser().await;
    let (addr, _stop, _served, _root) = guest(port).await;
    let mut socket = open(&addr, &[("authorization", BEARER)]).await.expect("relay opened");
    let huge = "x".repeat(arena_guest_bound() + 1);
    // The send itself may fail once the guest closes mid-frame.
    let _ = socket.send(Message::Text(huge.into())).await;
    let closed_with = match socket.next().await {
        Some(Ok(Message::Close(frame))) => frame.map(|f| u16::from(f.code)),
        Some(Ok(other)) => panic!("nothing comes back for a refused message: {other:?}"),
        // The guest may reset the socket before the client reads the close frame.
        Some(Err(_)) | None => None,
    };
    assert!(matches!(closed_with, None | Some(1009)), "{closed_with:?}");
    assert_eq!(received.load(Ordering::SeqCst), 0, "the big message never reached the browser");
    // A fresh relay still works.
    let mut socket = open(&addr, &[("authorization", BEARER)]).await.expect("relay opened again");
    socket.send(Message::Text("small".into())).await.expect("send");
    assert_eq!(socket.next().await.expect("answer").expect("message"), Message::Text("echo small".into()));
}

/// The guest's bound on a host message (1 MiB).
fn arena_guest_bound() -> usize {
    1 << 20
}

#[tokio::test]
async fn server_shutdown_closes_open_relays() {
    let (port, _) = fake_browser().await;
    let (addr, stop, served, _root) = guest(port).await;
    let mut socket = open(&addr, &[("authorization", BEARER)]).await.expect("relay opened");
    socket.send(Message::Text("before".into())).await.expect("send");
    assert_eq!(socket.next().await.expect("answer").expect("message"), Message::Text("echo before".into()));
    stop.send(()).expect("stop the guest");
    match socket.next().await {
        Some(Ok(Message::Close(Some(frame)))) => assert_eq!(u16::from(frame.code), 1001, "{frame:?}"),
        other => panic!("expected a close frame going away, got {other:?}"),
    }
    // The server finishes once the relay has ended, well within its grace period.
    tokio::time::timeout(std::time::Duration::from_secs(4), served).await.expect("the server stopped").expect("joined");
}
