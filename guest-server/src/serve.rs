//! The HTTP server loop, with the limits a guest reachable from a VM's network needs.
//!
//! `axum::serve` takes no configuration, so the loop is written here over hyper's
//! HTTP/1 connection builder (the protocol every WAA host and our client speak):
//!
//! - at most `--max-connections` connections at once; one more is answered `503` with
//!   an error body and closed, so idle sockets cannot exhaust the process's handles
//!   and lock everyone out;
//! - a request's headers must arrive within `--header-timeout-ms`, and an idle
//!   keep-alive connection is closed after the same time (hyper's header-read timer);
//! - headers are read into a bounded buffer (hyper answers a bare `431` beyond it; the
//!   router's own limits answer `414`/`431` with an error body well below it);
//! - on shutdown no new connection is taken, requests in flight may finish, and after
//!   `--shutdown-grace-ms` the connections still open (a half-sent request, a client
//!   that does not read) are dropped, so the server always exits;
//! - connections may be upgraded (the DevTools websocket relay): every request carries
//!   a [`ConnContext`] whose slot an upgraded connection keeps until it ends, and whose
//!   shutdown signal tells it to close.

use std::future::Future;
use std::pin::pin;
use std::sync::Arc;
use std::time::Duration;

use axum::body::Body;
use axum::Router;
use hyper::body::Incoming;
use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::service::TowerToHyperService;
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{OwnedSemaphorePermit, Semaphore};
use tokio::task::JoinSet;
use tokio_util::sync::CancellationToken;
use tower::ServiceExt as _;

/// What a request knows of its connection: the connection's slot among
/// `--max-connections` (held as long as any clone lives, so a connection upgraded
/// to a websocket keeps counting until its relay ends) and the server's shutdown
/// signal. Every request served by [`serve`] carries one as an extension.
#[derive(Debug, Clone)]
pub struct ConnContext {
    /// Cancelled when the server starts shutting down.
    pub shutdown: CancellationToken,
    _slot: Arc<OwnedSemaphorePermit>,
}

/// The connection limits of one server.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ConnLimits {
    pub max_connections: usize,
    pub header_timeout: Duration,
    pub shutdown_grace: Duration,
    /// hyper's read buffer, which bounds a request's head.
    pub max_head_bytes: usize,
}

/// Serves `app` on `listener` until `shutdown` completes, within `limits`.
///
/// # Errors
///
/// None today: a failed accept (out of descriptors, a reset connection) is logged and
/// retried after a short pause; the `io::Result` is kept for callers.
pub async fn serve(
    listener: TcpListener,
    app: Router,
    limits: ConnLimits,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> std::io::Result<()> {
    let slots = limits.max_connections.max(1);
    let permits = Arc::new(Semaphore::new(slots));
    let stop = CancellationToken::new();
    let mut connections = JoinSet::new();
    let mut shutdown = pin!(shutdown);
    loop {
        let accepted = tokio::select! {
            accepted = listener.accept() => accepted,
            () = &mut shutdown => break,
        };
        // Finished connections leave the set as they go, so it never grows without bound.
        while connections.try_join_next().is_some() {}
        let (stream, peer) = match accepted {
            Ok(accepted) => accepted,
            Err(err) => {
                tracing::warn!(error = %err, "accept failed; pausing");
                tokio::time::sleep(Duration::from_millis(50)).await;
                continue;
            }
        };
        let Ok(permit) = Arc::clone(&permits).try_acquire_owned() else {
            tracing::warn!(%peer, max = limits.max_connections, "too many connections; refusing one");
            connections.spawn(refuse_busy(stream, limits.max_connections));
            continue;
        };
        let context = ConnContext { shutdown: stop.clone(), _slot: Arc::new(permit) };
        let per_request = context.clone();
        let service = TowerToHyperService::new(app.clone().map_request(move |request: hyper::Request<Incoming>| {
            let mut request = request.map(Body::new);
            request.extensions_mut().insert(per_request.clone());
            request
        }));
        let mut builder = hyper::server::conn::http1::Builder::new();
        builder.timer(TokioTimer::new()).header_read_timeout(limits.header_timeout).max_buf_size(limits.max_head_bytes);
        let connection = builder.serve_connection(TokioIo::new(stream), service).with_upgrades();
        connections.spawn(async move {
            let ConnContext { shutdown, _slot } = context;
            let mut connection = pin!(connection);
            let ended = tokio::select! {
                ended = connection.as_mut() => ended,
                () = shutdown.cancelled() => {
                    // Finish the request in flight, then close; an idle keep-alive closes at once.
                    connection.as_mut().graceful_shutdown();
                    connection.await
                }
            };
            if let Err(err) = ended {
                tracing::debug!(%peer, error = %err, "connection ended with an error");
            }
        });
    }
    drop(listener);
    stop.cancel();
    // Every slot back means every connection, upgraded ones included, has ended.
    let all_back = async {
        while connections.join_next().await.is_some() {}
        let _ = permits.acquire_many(u32::try_from(slots).unwrap_or(u32::MAX)).await;
    };
    tokio::select! {
        () = all_back => tracing::info!("every connection finished"),
        () = tokio::time::sleep(limits.shutdown_grace) => {
            tracing::warn!(
                grace_ms = limits.shutdown_grace.as_millis() as u64,
                "connections still open after the shutdown grace period are dropped"
            );
        }
    }
    connections.shutdown().await;
    Ok(())
}

/// Answers a connection over the limit with a `503` and closes it.
async fn refuse_busy(mut stream: TcpStream, max: usize) {
    use tokio::io::AsyncWriteExt as _;
    let body = serde_json::to_string(&arena_shared::error::ErrorBody {
        error: arena_shared::error::ErrorCode::Unavailable,
        message: format!("this server serves at most {max} connections at once (--max-connections); try again"),
    })
    .unwrap_or_default();
    let answer = format!(
        "HTTP/1.1 503 Service Unavailable\r\ncontent-type: application/json\r\ncontent-length: {}\r\nconnection: close\r\nretry-after: 1\r\n\r\n{body}",
        body.len()
    );
    let _ = tokio::time::timeout(Duration::from_secs(1), stream.write_all(answer.as_bytes())).await;
    let _ = stream.shutdown().await;
}
