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
//! - a request's body must keep arriving: after the header timeout's grace, at least
//!   `min_body_rate` bytes a second on average ([`MinRateBody`]); a body that trickles
//!   (one byte every few seconds, to hold a slot) fails, and its connection is closed;
//! - when every slot is taken, a new connection takes the slot of the connection whose
//!   body is furthest behind that rate (one that has been sending for at least
//!   [`BEHIND_AFTER`] and lives only on the grace), so bodies that trickle cannot keep
//!   a legitimate client out even during their grace; with none behind it gets the 503;
//! - with a token configured, connections that have not yet shown it are on probation:
//!   at most `probation_slots` of them at once, and when one more arrives the oldest
//!   that has sent nothing yet is closed (the oldest of all when every one has sent
//!   something), so idle or reconnecting sockets without the token can never hold more
//!   than that share of the slots, and a client that sends its request at once is not
//!   closed for a silent newcomer while its request is read.
//!   The auth guard marks a connection authenticated ([`ConnContext::authenticated`])
//!   and closes it after a 401;
//! - connections may be upgraded (the DevTools websocket relay): every request carries
//!   a [`ConnContext`] whose slot an upgraded connection keeps until it ends, and whose
//!   shutdown signal tells it to close.

use std::future::Future;
use std::pin::{pin, Pin};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};
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
    /// The server's table of connections and this one's id in it.
    connections: Arc<Connections>,
    id: u64,
    /// How far its request body has come, for the choice of a slot to take back.
    body: Arc<Mutex<Option<BodyProgress>>>,
}

impl ConnContext {
    /// The connection showed the token: it leaves probation and is never evicted for
    /// want of it.
    pub fn authenticated(&self) {
        self.connections.authenticated(self.id);
    }
}

/// A request body being read: since when, and how many bytes came.
#[derive(Debug, Clone, Copy)]
struct BodyProgress {
    started: tokio::time::Instant,
    received: u64,
}

/// How long a body must have been arriving before it can count as behind.
pub const BEHIND_AFTER: Duration = Duration::from_millis(500);

/// One open connection, as the choice of one to close for a newcomer sees it.
#[derive(Debug)]
struct Conn {
    /// Whether its peer has sent any byte.
    spoke: Arc<AtomicBool>,
    /// Its request body's progress, while one is being read.
    body: Arc<Mutex<Option<BodyProgress>>>,
    /// Closes it.
    evict: CancellationToken,
    /// It has not shown the token (and a token is required).
    on_probation: bool,
}

/// The open connections of one server, by id (ids grow, so the first is the oldest).
#[derive(Debug)]
struct Connections {
    /// How many may be on probation at once; `None`: no token, no probation.
    probation_cap: Option<usize>,
    open: Mutex<std::collections::BTreeMap<u64, Conn>>,
}

impl Connections {
    fn lock(&self) -> std::sync::MutexGuard<'_, std::collections::BTreeMap<u64, Conn>> {
        self.open.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Adds connection `id`, on probation when a token is required; when all places on
    /// probation are taken, closes the oldest one there that has sent nothing, or the
    /// oldest there if each has.
    fn admit(&self, id: u64, mut conn: Conn) {
        let mut open = self.lock();
        if let Some(cap) = self.probation_cap {
            conn.on_probation = true;
            loop {
                let waiting: Vec<(&u64, &Conn)> = open.iter().filter(|(_, c)| c.on_probation).collect();
                if waiting.len() < cap {
                    break;
                }
                let silent = waiting.iter().find(|(_, c)| !c.spoke.load(Ordering::Relaxed));
                let Some(&old) = silent.or(waiting.first()).map(|(old, _)| *old) else { break };
                tracing::debug!(connection = old, "closing a connection that has not shown the token");
                if let Some(closed) = open.get_mut(&old) {
                    closed.evict.cancel();
                    closed.on_probation = false;
                }
            }
        }
        open.insert(id, conn);
    }

    fn authenticated(&self, id: u64) {
        if let Some(conn) = self.lock().get_mut(&id) {
            conn.on_probation = false;
        }
    }

    fn close(&self, id: u64) {
        self.lock().remove(&id);
    }

    /// Closes the connection whose body is furthest behind `rate` bytes a second (and
    /// has been arriving for [`BEHIND_AFTER`] at least); answers whether there was one.
    fn close_furthest_behind(&self, rate: u64) -> bool {
        let now = tokio::time::Instant::now();
        let open = self.lock();
        let deficit = |progress: &BodyProgress| {
            let elapsed = now.saturating_duration_since(progress.started);
            (elapsed >= BEHIND_AFTER).then_some((elapsed.as_secs_f64() * rate as f64) - progress.received as f64)
        };
        let behind = open
            .iter()
            .filter_map(|(id, conn)| {
                let progress = (*conn.body.lock().unwrap_or_else(std::sync::PoisonError::into_inner))?;
                deficit(&progress).filter(|d| *d > 0.0).map(|d| (d, *id, &conn.evict))
            })
            .max_by(|a, b| a.0.total_cmp(&b.0));
        match behind {
            Some((deficit, id, evict)) => {
                tracing::info!(
                    connection = id,
                    deficit_bytes = deficit as u64,
                    "every slot is taken: closing the connection whose body is furthest behind"
                );
                evict.cancel();
                true
            }
            None => false,
        }
    }
}

/// A socket that notes when its peer first sends something.
#[derive(Debug)]
struct Heard<S> {
    inner: S,
    spoke: Arc<AtomicBool>,
}

impl<S: tokio::io::AsyncRead + Unpin> tokio::io::AsyncRead for Heard<S> {
    fn poll_read(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut tokio::io::ReadBuf<'_>,
    ) -> Poll<std::io::Result<()>> {
        let this = self.get_mut();
        let before = buf.filled().len();
        let polled = Pin::new(&mut this.inner).poll_read(cx, buf);
        if buf.filled().len() > before {
            this.spoke.store(true, Ordering::Relaxed);
        }
        polled
    }
}

impl<S: tokio::io::AsyncWrite + Unpin> tokio::io::AsyncWrite for Heard<S> {
    fn poll_write(self: Pin<&mut Self>, cx: &mut Context<'_>, data: &[u8]) -> Poll<std::io::Result<usize>> {
        Pin::new(&mut self.get_mut().inner).poll_write(cx, data)
    }

    fn poll_flush(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.get_mut().inner).poll_flush(cx)
    }

    fn poll_shutdown(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.get_mut().inner).poll_shutdown(cx)
    }

    fn poll_write_vectored(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[std::io::IoSlice<'_>],
    ) -> Poll<std::io::Result<usize>> {
        Pin::new(&mut self.get_mut().inner).poll_write_vectored(cx, bufs)
    }

    fn is_write_vectored(&self) -> bool {
        self.inner.is_write_vectored()
    }
}

/// A request body that must keep arriving: it fails once less than `grace` plus one
/// second per `rate` bytes received has passed without the body ending. A client that
/// sends its body at `rate` bytes a second or faster never sees it; one that trickles a
/// byte every few seconds to hold its connection is cut off after about `grace`.
#[derive(Debug)]
pub struct MinRateBody<B> {
    inner: B,
    /// Where the connection's serving loop can see how far the body has come.
    progress: Option<Arc<Mutex<Option<BodyProgress>>>>,
    started: tokio::time::Instant,
    received: u64,
    /// The body ended (or failed): nothing more is owed.
    ended: bool,
    grace: Duration,
    rate: u64,
    deadline: Pin<Box<tokio::time::Sleep>>,
}

impl<B> MinRateBody<B> {
    /// Wraps `inner`, whose headers arrived now.
    pub fn new(inner: B, grace: Duration, rate: u64) -> MinRateBody<B> {
        let started = tokio::time::Instant::now();
        MinRateBody {
            inner,
            progress: None,
            started,
            received: 0,
            ended: false,
            grace,
            rate: rate.max(1),
            deadline: Box::pin(tokio::time::sleep_until(started + grace)),
        }
    }

    fn report(&self) {
        if let Some(progress) = &self.progress {
            let mut slot = progress.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
            *slot = (!self.ended).then_some(BodyProgress { started: self.started, received: self.received });
        }
    }

    fn next_deadline(&self) -> tokio::time::Instant {
        let earned = Duration::from_secs_f64(self.received as f64 / self.rate as f64);
        self.started + self.grace + earned
    }
}

/// The error of a body that arrived too slowly.
#[derive(Debug, thiserror::Error)]
#[error("the request body arrived slower than {rate} bytes a second ({received} bytes in {elapsed_ms} ms)")]
pub struct BodyTooSlow {
    rate: u64,
    received: u64,
    elapsed_ms: u64,
}

impl<B: hyper::body::Body> MinRateBody<B> {
    /// Reports the body's progress into `progress` as it arrives (cleared at its end).
    fn reporting_to(mut self, progress: Arc<Mutex<Option<BodyProgress>>>) -> MinRateBody<B> {
        self.progress = Some(progress);
        self.ended = self.inner.is_end_stream();
        self.report();
        self
    }
}

impl<B> Drop for MinRateBody<B> {
    fn drop(&mut self) {
        // A body no longer read (served, refused or abandoned) is owed nothing.
        self.ended = true;
        self.report();
    }
}

impl<B> hyper::body::Body for MinRateBody<B>
where
    B: hyper::body::Body<Data = axum::body::Bytes> + Unpin,
    B::Error: Into<axum::BoxError>,
{
    type Data = axum::body::Bytes;
    type Error = axum::BoxError;

    fn poll_frame(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<Result<hyper::body::Frame<Self::Data>, Self::Error>>> {
        let this = self.get_mut();
        match Pin::new(&mut this.inner).poll_frame(cx) {
            Poll::Ready(Some(Ok(frame))) => {
                if let Some(data) = frame.data_ref() {
                    this.received += data.len() as u64;
                    let next = this.next_deadline();
                    this.deadline.as_mut().reset(next);
                }
                this.ended = this.inner.is_end_stream();
                this.report();
                Poll::Ready(Some(Ok(frame)))
            }
            Poll::Ready(Some(Err(err))) => {
                this.ended = true;
                this.report();
                Poll::Ready(Some(Err(err.into())))
            }
            Poll::Ready(None) => {
                this.ended = true;
                this.report();
                Poll::Ready(None)
            }
            Poll::Pending => match this.deadline.as_mut().poll(cx) {
                Poll::Ready(()) => {
                    this.ended = true;
                    this.report();
                    let elapsed_ms = u64::try_from(this.started.elapsed().as_millis()).unwrap_or(u64::MAX);
                    tracing::warn!(received = this.received, elapsed_ms, "closing a request whose body trickles");
                    Poll::Ready(Some(Err(Box::new(BodyTooSlow {
                        rate: this.rate,
                        received: this.received,
                        elapsed_ms,
                    }))))
                }
                Poll::Pending => Poll::Pending,
            },
        }
    }

    fn is_end_stream(&self) -> bool {
        self.inner.is_end_stream()
    }

    fn size_hint(&self) -> hyper::body::SizeHint {
        self.inner.size_hint()
    }
}

/// The connection limits of one server.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ConnLimits {
    pub max_connections: usize,
    pub header_timeout: Duration,
    pub shutdown_grace: Duration,
    /// hyper's read buffer, which bounds a request's head.
    pub max_head_bytes: usize,
    /// Slowest average rate a request body may arrive at, in bytes a second, after a
    /// grace of `header_timeout`.
    pub min_body_rate: u64,
    /// When a token is required: how many connections that have not shown it may be
    /// open at once (the oldest is closed for a new one). `None`: no probation.
    pub probation_slots: Option<usize>,
}

/// The slowest body rate served by default: 1 KiB a second, after the header timeout.
pub const MIN_BODY_RATE: u64 = 1024;

/// The share of the connection slots that connections without the token may hold:
/// an eighth, and at least 4.
pub fn probation_slots(max_connections: usize) -> usize {
    (max_connections / 8).max(4)
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
    let table =
        Arc::new(Connections { probation_cap: limits.probation_slots.map(|cap| cap.max(1)), open: Mutex::default() });
    let mut next_id: u64 = 0;
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
        // A free slot; or, when all are taken, the slot of a body that trickles, given
        // back as its connection ends; or the 503.
        let slot = match Arc::clone(&permits).try_acquire_owned() {
            Ok(permit) => Slot::Free(permit),
            Err(_) if table.close_furthest_behind(limits.min_body_rate) => Slot::Freed(Arc::clone(&permits)),
            Err(_) => {
                tracing::warn!(%peer, max = limits.max_connections, "too many connections; refusing one");
                connections.spawn(refuse_busy(stream, limits.max_connections));
                continue;
            }
        };
        next_id += 1;
        let id = next_id;
        let shared = Shared { limits, app: app.clone(), stop: stop.clone(), table: Arc::clone(&table) };
        connections.spawn(async move {
            let permit = match slot {
                Slot::Free(permit) => permit,
                Slot::Freed(permits) => {
                    match tokio::time::timeout(Duration::from_secs(1), permits.acquire_owned()).await {
                        Ok(Ok(permit)) => permit,
                        _ => return refuse_busy(stream, limits.max_connections).await,
                    }
                }
            };
            serve_connection(shared, stream, peer, id, permit).await;
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

/// Where a new connection's slot comes from.
enum Slot {
    Free(OwnedSemaphorePermit),
    /// A trickling connection was closed: its slot comes back as its task ends.
    Freed(Arc<Semaphore>),
}

/// What every connection of one server shares.
struct Shared {
    limits: ConnLimits,
    app: Router,
    stop: CancellationToken,
    table: Arc<Connections>,
}

/// Serves one accepted connection in its slot until it ends, is closed for a
/// newcomer, or the server shuts down.
async fn serve_connection(
    shared: Shared,
    stream: TcpStream,
    peer: std::net::SocketAddr,
    id: u64,
    permit: OwnedSemaphorePermit,
) {
    let Shared { limits, app, stop, table } = shared;
    let evict = CancellationToken::new();
    let spoke = Arc::new(AtomicBool::new(false));
    let body: Arc<Mutex<Option<BodyProgress>>> = Arc::default();
    let conn = Conn { spoke: Arc::clone(&spoke), body: Arc::clone(&body), evict: evict.clone(), on_probation: false };
    table.admit(id, conn);
    // A child of the server's token: cancelled with it, but each wake of this
    // connection checks its own, so connections do not contend for one lock.
    let shutdown = stop.child_token();
    let context = ConnContext { shutdown, _slot: Arc::new(permit), connections: Arc::clone(&table), id, body };
    let per_request = context.clone();
    let (grace, rate) = (limits.header_timeout, limits.min_body_rate);
    let service = TowerToHyperService::new(app.map_request(move |request: hyper::Request<Incoming>| {
        let progress = Arc::clone(&per_request.body);
        let mut request = request.map(|body| Body::new(MinRateBody::new(body, grace, rate).reporting_to(progress)));
        request.extensions_mut().insert(per_request.clone());
        request
    }));
    let mut builder = hyper::server::conn::http1::Builder::new();
    builder.timer(TokioTimer::new()).header_read_timeout(limits.header_timeout).max_buf_size(limits.max_head_bytes);
    let connection = builder.serve_connection(TokioIo::new(Heard { inner: stream, spoke }), service).with_upgrades();
    let ConnContext { shutdown, _slot, .. } = context;
    let mut connection = pin!(connection);
    let ended = tokio::select! {
        ended = connection.as_mut() => ended,
        () = evict.cancelled() => Ok(()),
        () = shutdown.cancelled() => {
            // Finish the request in flight, then close; an idle keep-alive closes at once.
            connection.as_mut().graceful_shutdown();
            connection.await
        }
    };
    table.close(id);
    if let Err(err) = ended {
        tracing::debug!(%peer, error = %err, "connection ended with an error");
    }
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
