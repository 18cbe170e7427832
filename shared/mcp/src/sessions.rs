//! Bounded MCP sessions, for both servers: rmcp's [`LocalSessionManager`] keeps every
//! session until its keep-alive passes (300 s by default), so a client that only
//! sends `initialize` grows a server by tens of KiB a call without end.
//! [`BoundedSessions`] wraps it with three rules:
//!
//! - **a cap**: at most [`SessionLimits::max_sessions`] open; a new session first
//!   closes the one idle longest (no call running), and when every open session has a
//!   call running the new one is refused, saying so;
//! - **idle expiry**: a session with no call running and none for
//!   [`SessionLimits::idle`] is closed (a sweeper checks a few times per period), and
//!   its next request gets rmcp's 404, on which the MCP specification has a client
//!   start a new session;
//! - **a hung-up call is cancelled**: when the HTTP response of a request is dropped
//!   before its answer went out (the client closed the connection), the session is sent
//!   the `notifications/cancelled` the client did not send, so rmcp cancels the
//!   request's token and [`crate::Server`] drops the tool's future, which stops its work
//!   (the guest's interpreter through its cancel flag).
//!
//! rmcp's own idle timer is off: it counts time since the session's last message, so it
//! would close a session in the middle of a long call; the sweeper here counts only
//! time with no call running.

use std::collections::HashMap;
use std::pin::Pin;
use std::sync::{Arc, Mutex, PoisonError, Weak};
use std::task::{Context, Poll};
use std::time::{Duration, Instant};

use rmcp::model::{
    CancelledNotification, CancelledNotificationParam, ClientJsonRpcMessage, ClientNotification, JsonRpcMessage,
    RequestId, ServerJsonRpcMessage,
};
use rmcp::transport::common::server_side_http::ServerSseMessage;
use rmcp::transport::streamable_http_server::session::local::{LocalSessionManager, LocalSessionManagerError};
use rmcp::transport::streamable_http_server::{SessionId, SessionManager};
use rmcp::transport::WorkerTransport;

/// How many sessions may be open and how long one may sit idle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SessionLimits {
    /// Most sessions open at once.
    pub max_sessions: usize,
    /// A session with no call running for this long is closed.
    pub idle: Duration,
}

impl SessionLimits {
    /// The defaults both servers document: 64 sessions, closed after 2 minutes idle.
    pub const DEFAULT: SessionLimits = SessionLimits { max_sessions: 64, idle: Duration::from_secs(120) };
}

impl Default for SessionLimits {
    fn default() -> SessionLimits {
        SessionLimits::DEFAULT
    }
}

/// What the manager knows of one open session.
#[derive(Debug, Clone, Copy)]
struct Activity {
    /// When a call last started or ended (or the session opened).
    last: Instant,
    /// Calls whose answer stream is open now.
    running: usize,
}

/// Why a session could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum SessionsError {
    /// Every one of the open sessions has a call running.
    #[error("{0} MCP sessions are open, the most this server keeps, and every one has a call running; try again when one ends")]
    Full(usize),
    /// rmcp's own session manager failed.
    #[error(transparent)]
    Local(#[from] LocalSessionManagerError),
}

/// rmcp's [`LocalSessionManager`] with a cap, idle expiry and hung-up calls cancelled
/// (see the module documentation).
#[derive(Debug)]
pub struct BoundedSessions {
    inner: LocalSessionManager,
    limits: SessionLimits,
    open: Mutex<HashMap<SessionId, Activity>>,
    sweeping: std::sync::atomic::AtomicBool,
    me: Weak<BoundedSessions>,
}

impl BoundedSessions {
    /// A manager enforcing `limits`.
    pub fn new(limits: SessionLimits) -> Arc<BoundedSessions> {
        let mut inner = LocalSessionManager::default();
        // Idle time is this manager's to count (calls running do not count as idle).
        inner.session_config.keep_alive = None;
        let limits = SessionLimits { max_sessions: limits.max_sessions.max(1), idle: limits.idle };
        Arc::new_cyclic(|me| BoundedSessions {
            inner,
            limits,
            open: Mutex::new(HashMap::new()),
            sweeping: std::sync::atomic::AtomicBool::new(false),
            me: me.clone(),
        })
    }

    /// The limits in force.
    pub fn limits(&self) -> SessionLimits {
        self.limits
    }

    /// How many sessions are open now.
    pub fn open_sessions(&self) -> usize {
        self.table().len()
    }

    fn table(&self) -> std::sync::MutexGuard<'_, HashMap<SessionId, Activity>> {
        self.open.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Marks a call of session `id` started (`delta` 1) or ended (`delta` -1).
    fn call(&self, id: &SessionId, started: bool) {
        if let Some(activity) = self.table().get_mut(id) {
            activity.last = Instant::now();
            activity.running = if started { activity.running + 1 } else { activity.running.saturating_sub(1) };
        }
    }

    fn touch(&self, id: &SessionId) {
        if let Some(activity) = self.table().get_mut(id) {
            activity.last = Instant::now();
        }
    }

    /// Closes the sessions idle past the limit; answers how many.
    pub async fn sweep(&self) -> usize {
        let idle = self.limits.idle;
        let expired: Vec<SessionId> = self
            .table()
            .iter()
            .filter(|(_, a)| a.running == 0 && a.last.elapsed() >= idle)
            .map(|(id, _)| id.clone())
            .collect();
        for id in &expired {
            tracing::info!(session = %id, idle_secs = idle.as_secs(), "closing an idle MCP session");
            let _ = self.close_session(id).await;
        }
        expired.len()
    }

    /// Starts the sweeper once, on the runtime of the first session.
    fn start_sweeper(&self) {
        if self.sweeping.swap(true, std::sync::atomic::Ordering::Relaxed) {
            return;
        }
        let me = self.me.clone();
        let period = (self.limits.idle / 4).clamp(Duration::from_millis(50), Duration::from_secs(15));
        tokio::spawn(async move {
            loop {
                tokio::time::sleep(period).await;
                // The sweeper ends with the manager.
                let Some(sessions) = me.upgrade() else { return };
                sessions.sweep().await;
            }
        });
    }

    /// Makes room for one more session: closes the one idle longest when at the cap.
    async fn make_room(&self) -> Result<(), SessionsError> {
        loop {
            let victim = {
                let table = self.table();
                if table.len() < self.limits.max_sessions {
                    return Ok(());
                }
                table.iter().filter(|(_, a)| a.running == 0).min_by_key(|(_, a)| a.last).map(|(id, _)| id.clone())
            };
            match victim {
                Some(id) => {
                    tracing::info!(session = %id, max = self.limits.max_sessions, "closing the MCP session idle longest to open a new one");
                    self.close_session(&id).await?;
                }
                None => return Err(SessionsError::Full(self.limits.max_sessions)),
            }
        }
    }
}

/// The `notifications/cancelled` a client sends for `request`, sent on its behalf.
fn cancelled(request: RequestId) -> ClientJsonRpcMessage {
    let reason = "the client closed the connection before the answer".to_owned();
    let notification = CancelledNotification::new(CancelledNotificationParam::new(Some(request), Some(reason)));
    ClientJsonRpcMessage::notification(ClientNotification::CancelledNotification(notification))
}

/// Whether `message` answers `request`.
fn answers(message: &ServerJsonRpcMessage, request: &RequestId) -> bool {
    match message {
        JsonRpcMessage::Response(response) => &response.id == request,
        JsonRpcMessage::Error(error) => error.id.as_ref() == Some(request),
        _ => false,
    }
}

/// A request's answer stream: counts the call as running while it is open, and when
/// it is dropped before the answer went out, cancels the request.
struct CallStream {
    inner: Pin<Box<dyn futures_util::Stream<Item = ServerSseMessage> + Send + Sync>>,
    sessions: Weak<BoundedSessions>,
    session: SessionId,
    request: RequestId,
    answered: bool,
}

impl futures_util::Stream for CallStream {
    type Item = ServerSseMessage;

    fn poll_next(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Option<ServerSseMessage>> {
        let polled = self.inner.as_mut().poll_next(cx);
        match &polled {
            Poll::Ready(Some(sse)) => {
                if sse.message.as_deref().is_some_and(|m| answers(m, &self.request)) {
                    self.answered = true;
                }
            }
            // The session ended the stream: nothing is left to cancel.
            Poll::Ready(None) => self.answered = true,
            Poll::Pending => {}
        }
        polled
    }
}

impl Drop for CallStream {
    fn drop(&mut self) {
        let Some(sessions) = self.sessions.upgrade() else { return };
        sessions.call(&self.session, false);
        if self.answered {
            return;
        }
        let (session, request) = (self.session.clone(), self.request.clone());
        tracing::info!(%session, %request, "the MCP client went away before the answer: cancelling the call");
        if let Ok(runtime) = tokio::runtime::Handle::try_current() {
            runtime.spawn(async move {
                // A session closed meanwhile has nothing left to cancel.
                let _ = sessions.inner.accept_message(&session, cancelled(request)).await;
            });
        }
    }
}

impl SessionManager for BoundedSessions {
    type Error = SessionsError;
    type Transport = WorkerTransport<rmcp::transport::streamable_http_server::session::local::LocalSessionWorker>;

    async fn create_session(&self) -> Result<(SessionId, Self::Transport), Self::Error> {
        self.start_sweeper();
        self.make_room().await?;
        let (id, transport) = self.inner.create_session().await?;
        self.table().insert(id.clone(), Activity { last: Instant::now(), running: 0 });
        Ok((id, transport))
    }

    async fn initialize_session(
        &self,
        id: &SessionId,
        message: ClientJsonRpcMessage,
    ) -> Result<ServerJsonRpcMessage, Self::Error> {
        self.touch(id);
        Ok(self.inner.initialize_session(id, message).await?)
    }

    async fn has_session(&self, id: &SessionId) -> Result<bool, Self::Error> {
        Ok(self.inner.has_session(id).await?)
    }

    async fn close_session(&self, id: &SessionId) -> Result<(), Self::Error> {
        self.table().remove(id);
        Ok(self.inner.close_session(id).await?)
    }

    async fn create_stream(
        &self,
        id: &SessionId,
        message: ClientJsonRpcMessage,
    ) -> Result<impl futures_util::Stream<Item = ServerSseMessage> + Send + Sync + 'static, Self::Error> {
        let request = match &message {
            JsonRpcMessage::Request(request) => Some(request.id.clone()),
            _ => None,
        };
        self.call(id, true);
        let stream = match self.inner.create_stream(id, message).await {
            Ok(stream) => stream,
            Err(err) => {
                self.call(id, false);
                return Err(err.into());
            }
        };
        let Some(request) = request else {
            // Not a request (rmcp sends only requests here): nothing to cancel.
            self.call(id, false);
            return Ok(CallStream {
                inner: Box::pin(stream),
                sessions: Weak::new(),
                session: id.clone(),
                request: RequestId::Number(0),
                answered: true,
            });
        };
        Ok(CallStream {
            inner: Box::pin(stream),
            sessions: self.me.clone(),
            session: id.clone(),
            request,
            answered: false,
        })
    }

    async fn accept_message(&self, id: &SessionId, message: ClientJsonRpcMessage) -> Result<(), Self::Error> {
        self.touch(id);
        Ok(self.inner.accept_message(id, message).await?)
    }

    async fn create_standalone_stream(
        &self,
        id: &SessionId,
    ) -> Result<impl futures_util::Stream<Item = ServerSseMessage> + Send + Sync + 'static, Self::Error> {
        self.touch(id);
        Ok(self.inner.create_standalone_stream(id).await?)
    }

    async fn resume(
        &self,
        id: &SessionId,
        last_event_id: String,
    ) -> Result<impl futures_util::Stream<Item = ServerSseMessage> + Send + Sync + 'static, Self::Error> {
        self.touch(id);
        Ok(self.inner.resume(id, last_event_id).await?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn sessions_past_the_cap_close_the_one_idle_longest() {
        let sessions = BoundedSessions::new(SessionLimits { max_sessions: 3, idle: Duration::from_secs(600) });
        let mut ids = Vec::new();
        for _ in 0..3 {
            ids.push(sessions.create_session().await.expect("opens").0);
        }
        // The first is busy and the second was used last: the third is the one idle longest.
        sessions.call(&ids[0], true);
        sessions.touch(&ids[1]);
        let (fourth, _) = sessions.create_session().await.expect("opens by closing one");
        assert_eq!(sessions.open_sessions(), 3);
        assert!(!sessions.has_session(&ids[2]).await.expect("answers"), "the one idle longest was closed");
        assert!(sessions.has_session(&ids[0]).await.expect("answers"), "a busy session stays");
        assert!(sessions.has_session(&fourth).await.expect("answers"));
        // With every session busy, a new one is refused, saying why.
        sessions.call(&ids[1], true);
        sessions.call(&fourth, true);
        let Err(err) = sessions.create_session().await else { panic!("a session opened though all are busy") };
        assert!(err.to_string().contains("3 MCP sessions are open"), "{err}");
    }

    #[tokio::test]
    async fn twenty_thousand_sessions_stay_at_the_cap() {
        let sessions = BoundedSessions::new(SessionLimits { max_sessions: 64, idle: Duration::from_secs(600) });
        for _ in 0..20_000 {
            sessions.create_session().await.expect("opens");
        }
        assert_eq!(sessions.open_sessions(), 64);
        assert_eq!(sessions.inner.sessions.read().await.len(), 64, "rmcp's own table holds no more");
    }

    #[tokio::test]
    async fn idle_sessions_expire_and_busy_ones_do_not() {
        let sessions = BoundedSessions::new(SessionLimits { max_sessions: 8, idle: Duration::ZERO });
        // This test sweeps itself, at the moments it chooses.
        sessions.sweeping.store(true, std::sync::atomic::Ordering::Relaxed);
        let (idle, _) = sessions.create_session().await.expect("opens");
        let (busy, _) = sessions.create_session().await.expect("opens");
        sessions.call(&busy, true);
        assert_eq!(sessions.sweep().await, 1);
        assert!(!sessions.has_session(&idle).await.expect("answers"));
        assert!(sessions.has_session(&busy).await.expect("answers"));
    }
}
