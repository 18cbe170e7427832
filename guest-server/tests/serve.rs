//! The server's connection limits, over real sockets on loopback: too many
//! connections, idle and half-sent requests, bodies that trickle, sockets without the
//! token, oversized heads, and shutdown with connections that never finish. Every wait
//! is bounded; none is measured.

use std::sync::Arc;
use std::time::Duration;

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};

use arena_guest::config::ServerConfig;
use arena_guest::state::AppState;

/// A guest on `127.0.0.1:0` with `configure`d limits; the sender stops it.
struct Guest {
    addr: std::net::SocketAddr,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    served: tokio::task::JoinHandle<std::io::Result<()>>,
    _dir: tempfile::TempDir,
}

async fn start(configure: impl FnOnce(&mut ServerConfig)) -> Guest {
    start_with(None, configure).await
}

const TOKEN: &str = "0123456789abcdef0123";

async fn start_with(token: Option<&str>, configure: impl FnOnce(&mut ServerConfig)) -> Guest {
    let dir = tempfile::tempdir().expect("dir");
    let stub = crate::harness::stub_in(dir.path(), None, false);
    let mut config = ServerConfig::for_stub();
    configure(&mut config);
    let state = AppState::new(Arc::new(stub), config, token.map(str::to_owned));
    let listener = TcpListener::bind("127.0.0.1:0").await.expect("bind");
    let addr = listener.local_addr().expect("addr");
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let served = tokio::spawn(arena_guest::serve(listener, state, async move {
        let _ = stopped.await;
    }));
    Guest { addr, stop: Some(stop), served, _dir: dir }
}

/// Everything the server sends until it closes the connection (bounded by 30 s).
async fn read_to_close(stream: &mut TcpStream) -> String {
    let mut answer = Vec::new();
    let read = tokio::time::timeout(Duration::from_secs(30), stream.read_to_end(&mut answer)).await;
    assert!(read.is_ok(), "the server kept the connection open; it had sent {:?}", String::from_utf8_lossy(&answer));
    String::from_utf8_lossy(&answer).into_owned()
}

async fn get(addr: std::net::SocketAddr, path: &str) -> String {
    let mut stream = TcpStream::connect(addr).await.expect("connect");
    let request = format!("GET {path} HTTP/1.1\r\nhost: 127.0.0.1\r\nconnection: close\r\n\r\n");
    stream.write_all(request.as_bytes()).await.expect("send");
    read_to_close(&mut stream).await
}

#[tokio::test]
async fn a_connection_over_the_limit_is_answered_503_and_closed() {
    let guest = start(|c| c.max_connections = 2).await;
    // Two idle connections take both places.
    let _a = TcpStream::connect(guest.addr).await.expect("connect");
    let _b = TcpStream::connect(guest.addr).await.expect("connect");
    tokio::time::sleep(Duration::from_millis(100)).await;
    let answer = get(guest.addr, "/v1/screen").await;
    assert!(answer.starts_with("HTTP/1.1 503"), "{answer}");
    assert!(answer.contains("\"error\":\"unavailable\"") && answer.contains("--max-connections"), "{answer}");
    // When they go, a place is free again.
    drop((_a, _b));
    let mut answer = String::new();
    for _ in 0..100 {
        answer = get(guest.addr, "/v1/screen").await;
        if answer.starts_with("HTTP/1.1 200") {
            break;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    assert!(answer.starts_with("HTTP/1.1 200"), "{answer}");
}

#[tokio::test]
async fn idle_and_half_sent_requests_are_closed_after_the_header_timeout() {
    let guest = start(|c| c.header_timeout_ms = 200).await;
    let mut idle = TcpStream::connect(guest.addr).await.expect("connect");
    let said = read_to_close(&mut idle).await;
    assert!(!said.starts_with("HTTP/1.1 200"), "{said}");
    let mut slow = TcpStream::connect(guest.addr).await.expect("connect");
    slow.write_all(b"GET /v1/screen HTTP/1.1\r\nhost: 127.0.0.1\r\n").await.expect("half a head");
    read_to_close(&mut slow).await;
    // A finished request on a keep-alive connection, then silence: closed too.
    let mut kept = TcpStream::connect(guest.addr).await.expect("connect");
    kept.write_all(b"GET /probe HTTP/1.1\r\nhost: 127.0.0.1\r\n\r\n").await.expect("send");
    let answer = read_to_close(&mut kept).await;
    assert!(answer.starts_with("HTTP/1.1 200"), "{answer}");
}

#[tokio::test]
async fn oversized_targets_and_headers_get_an_error_body() {
    let guest = start(|_| {}).await;
    let long = format!("/v1/files/stat?path={}", "a".repeat(20 << 10));
    let answer = get(guest.addr, &long).await;
    assert!(answer.starts_with("HTTP/1.1 414"), "{}", &answer[..answer.len().min(200)]);
    assert!(answer.contains("request target") && answer.contains("bad_request"), "{answer}");

    let mut stream = TcpStream::connect(guest.addr).await.expect("connect");
    let filler = "x".repeat(8 << 10);
    let mut request = String::from("GET /probe HTTP/1.1\r\nhost: 127.0.0.1\r\nconnection: close\r\n");
    for i in 0..10 {
        request.push_str(&format!("x-filler-{i}: {filler}\r\n"));
    }
    request.push_str("\r\n");
    stream.write_all(request.as_bytes()).await.expect("send");
    let answer = read_to_close(&mut stream).await;
    assert!(answer.starts_with("HTTP/1.1 431"), "{}", &answer[..answer.len().min(200)]);
    assert!(answer.contains("\"status\":\"error\"") && answer.contains("headers are"), "{answer}");
}

#[tokio::test]
async fn shutdown_ends_even_with_connections_that_never_finish() {
    let mut guest = start(|c| {
        c.shutdown_grace_ms = 300;
        c.header_timeout_ms = 3_600_000;
    })
    .await;
    // A half-sent request that will never complete.
    let mut stuck = TcpStream::connect(guest.addr).await.expect("connect");
    stuck
        .write_all(b"POST /v1/actions HTTP/1.1\r\nhost: 127.0.0.1\r\ncontent-length: 1000\r\n\r\n{")
        .await
        .expect("send");
    tokio::time::sleep(Duration::from_millis(100)).await;
    let _ = guest.stop.take().expect("stop").send(());
    let ended = tokio::time::timeout(Duration::from_secs(30), &mut guest.served).await;
    let served = ended.expect("the server ended within the grace period, not waiting for the client");
    assert!(matches!(served, Ok(Ok(()))), "{served:?}");
    read_to_close(&mut stuck).await;
    assert!(TcpStream::connect(guest.addr).await.is_err(), "no new connection after shutdown");
}

#[tokio::test]
async fn a_body_that_trickles_is_cut_off_and_its_connection_closed() {
    // hyper's header timer stops once the head is in: only the body's rate can close
    // this connection, after the header timeout's grace.
    let guest = start(|c| c.header_timeout_ms = 500).await;
    let (mut read, mut write) = TcpStream::connect(guest.addr).await.expect("connect").into_split();
    let head = "POST /v1/actions HTTP/1.1\r\nhost: 127.0.0.1\r\ncontent-type: application/json\r\n\
                content-length: 1000000\r\n\r\n{";
    write.write_all(head.as_bytes()).await.expect("send");
    // The probe's client sent a byte every 5 s and was never closed; this one sends a
    // byte every 50 ms, 20 bytes a second, far below the minimum rate.
    let trickle = tokio::spawn(async move {
        while write.write_all(b" ").await.is_ok() {
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    });
    let mut answer = Vec::new();
    let read = tokio::time::timeout(Duration::from_secs(30), read.read_to_end(&mut answer)).await;
    trickle.abort();
    let answer = String::from_utf8_lossy(&answer);
    assert!(read.is_ok(), "the server kept reading a trickling body; it had sent {answer:?}");
    assert!(answer.is_empty() || answer.starts_with("HTTP/1.1 4"), "{answer}");
}

#[tokio::test]
async fn a_newcomer_takes_the_slot_of_a_trickling_body_when_all_are_taken() {
    // Four slots, each held by a body that trickles within an hour's grace.
    let guest = start(|c| {
        c.max_connections = 4;
        c.header_timeout_ms = 3_600_000;
    })
    .await;
    let head = "POST /v1/actions HTTP/1.1\r\nhost: 127.0.0.1\r\ncontent-type: application/json\r\n\
                content-length: 1000000\r\n\r\n{";
    let mut tricklers = Vec::new();
    for _ in 0..4 {
        let mut stream = TcpStream::connect(guest.addr).await.expect("connect");
        stream.write_all(head.as_bytes()).await.expect("send");
        tricklers.push(stream);
    }
    // Each counts as behind once it has been sending for half a second.
    tokio::time::sleep(arena_guest::serve::BEHIND_AFTER + Duration::from_millis(200)).await;
    for _ in 0..3 {
        let answer = get(guest.addr, "/v1/screen").await;
        assert!(answer.starts_with("HTTP/1.1 200"), "{answer}");
    }
    // One trickler was closed to make room; the requests after the first took the slot
    // it left (each closed its connection), so no other was closed.
    let mut closed = 0;
    for stream in &mut tricklers {
        let mut byte = [0u8; 1];
        // Closed with the body unread: an end of stream or a reset.
        if let Ok(Ok(0) | Err(_)) = tokio::time::timeout(Duration::from_millis(200), stream.read(&mut byte)).await {
            closed += 1;
        }
    }
    assert_eq!(closed, 1);
    // Idle connections are not behind on anything: over the limit, a newcomer gets the 503.
    let idle = start(|c| c.max_connections = 2).await;
    let _held =
        (TcpStream::connect(idle.addr).await.expect("connect"), TcpStream::connect(idle.addr).await.expect("connect"));
    tokio::time::sleep(arena_guest::serve::BEHIND_AFTER + Duration::from_millis(200)).await;
    assert!(get(idle.addr, "/v1/screen").await.starts_with("HTTP/1.1 503"));
}

#[tokio::test]
async fn a_body_sent_at_an_ordinary_pace_is_served() {
    let guest = start(|c| c.header_timeout_ms = 200).await;
    let mut stream = TcpStream::connect(guest.addr).await.expect("connect");
    let body = br#"{"actions": [{"type": "move_to", "x": 5, "y": 5}]}"#;
    let head = format!(
        "POST /v1/actions HTTP/1.1\r\nhost: 127.0.0.1\r\ncontent-type: application/json\r\nconnection: close\r\n\
         content-length: {}\r\n\r\n",
        body.len()
    );
    stream.write_all(head.as_bytes()).await.expect("head");
    stream.write_all(body).await.expect("body");
    let answer = read_to_close(&mut stream).await;
    assert!(answer.starts_with("HTTP/1.1 200"), "{answer}");
}

#[tokio::test]
async fn sockets_without_the_token_hold_a_small_share_of_the_slots() {
    // 32 slots, so at most 4 connections may be open without having shown the token; an
    // hour's header timeout, so only that rule can close the idle ones.
    let guest = start_with(Some(TOKEN), |c| {
        c.max_connections = 32;
        c.header_timeout_ms = 3_600_000;
    })
    .await;
    let mut idle = Vec::new();
    for _ in 0..10 {
        idle.push(TcpStream::connect(guest.addr).await.expect("connect"));
        // Accepted in order, so "oldest" is well defined.
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    // A client with the token gets in at once.
    let mut stream = TcpStream::connect(guest.addr).await.expect("connect");
    let request = format!(
        "GET /v1/screen HTTP/1.1\r\nhost: 127.0.0.1\r\nauthorization: Bearer {TOKEN}\r\nconnection: close\r\n\r\n"
    );
    stream.write_all(request.as_bytes()).await.expect("send");
    let answer = read_to_close(&mut stream).await;
    assert!(answer.starts_with("HTTP/1.1 200"), "{answer}");
    // The oldest idle sockets were closed to make room, not left to hold their slots.
    for socket in idle.iter_mut().take(6) {
        let said = read_to_close(socket).await;
        assert!(said.is_empty(), "{said}");
    }
    // A request without the token is answered 401 and its connection closed.
    let mut stream = TcpStream::connect(guest.addr).await.expect("connect");
    stream.write_all(b"GET /v1/screen HTTP/1.1\r\nhost: 127.0.0.1\r\n\r\n").await.expect("send");
    let answer = read_to_close(&mut stream).await;
    assert!(answer.starts_with("HTTP/1.1 401"), "{answer}");
}

#[tokio::test]
async fn silent_newcomers_close_silent_sockets_before_one_whose_request_is_arriving() {
    // 32 slots: at most 4 connections without the token at once.
    let guest = start_with(Some(TOKEN), |c| {
        c.max_connections = 32;
        c.header_timeout_ms = 3_600_000;
    })
    .await;
    // The oldest connection has begun its request; ten silent ones come after it.
    let mut talker = TcpStream::connect(guest.addr).await.expect("connect");
    talker.write_all(b"GET /v1/screen HTTP/1.1\r\nhost: 127.0.0.1\r\n").await.expect("send");
    tokio::time::sleep(Duration::from_millis(50)).await;
    let mut silent = Vec::new();
    for _ in 0..10 {
        silent.push(TcpStream::connect(guest.addr).await.expect("connect"));
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    // The silent ones made room among themselves: the six oldest of them are closed.
    for socket in silent.iter_mut().take(6) {
        let said = read_to_close(socket).await;
        assert!(said.is_empty(), "{said}");
    }
    // The talker was not: its request ends with the token and is served.
    let rest = format!("authorization: Bearer {TOKEN}\r\nconnection: close\r\n\r\n");
    talker.write_all(rest.as_bytes()).await.expect("the talker's connection is open");
    let answer = read_to_close(&mut talker).await;
    assert!(answer.starts_with("HTTP/1.1 200"), "{answer}");
}

/// `arena-guest doctor` beside a running server asks that server (whose doctor takes
/// turns with its actions) instead of typing over it from a second process.
#[tokio::test]
async fn the_doctor_command_asks_the_server_running_on_its_port() {
    let guest = start_with(Some(TOKEN), |_| {}).await;
    let mut config = ServerConfig::for_stub();
    config.port = guest.addr.port();
    let report = arena_guest::native::ask_running_server(&config, Some(TOKEN)).await.expect("the server's report");
    let report = report.expect("a server runs on the port");
    assert!(!report.checks.is_empty(), "{report:?}");
    let err = arena_guest::native::ask_running_server(&config, Some("not-the-token-0123456789")).await.unwrap_err();
    assert!(err.contains("401") && err.contains("--token"), "{err}");
    // Nothing on the port: the command checks in its own process.
    let Guest { addr, mut stop, served, _dir } = guest;
    let _ = stop.take().expect("sender").send(());
    served.await.expect("joined").expect("served");
    config.port = addr.port();
    assert_eq!(arena_guest::native::ask_running_server(&config, Some(TOKEN)).await, Ok(None));
    config.port = 0;
    assert_eq!(arena_guest::native::ask_running_server(&config, None).await, Ok(None));
}
