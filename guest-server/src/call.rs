//! Calling the synchronous backend from async handlers, with a deadline.
//!
//! Every backend call goes through [`blocking`]: it runs on the backend's own
//! thread pool ([`pool`]) and the request gets [`DesktopError::Timeout`] when the deadline
//! passes. A hung window or provider then costs that one request, never the
//! server. The call itself is told to stop ([`crate::desktop::cancel`]): work
//! that checks between its units (keystrokes, pauses) ends within one unit; a
//! call stuck inside the operating system finishes (or not) on its own thread.
//!
//! When the server shuts down, [`cancel_all`] sets the same flag on every call still
//! running against its backend (interpreter runs included, which run as backend
//! calls), so a SIGTERM ends running work instead of waiting for it.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, Weak};
use std::time::Duration;

mod pool;

use crate::desktop::cancel::Scope;
use crate::desktop::{Desktop, DesktopError, DesktopResult};

/// Sets the cancel flag when dropped: after a finished call it changes nothing; after a
/// timeout, or when the client went away and the request future was dropped, it stops
/// the work still running.
struct StopOnDrop(Arc<AtomicBool>);

impl Drop for StopOnDrop {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Relaxed);
    }
}

/// The flags of one running call: `cancel` stops its work (the flag the backend and
/// the interpreter check); `shutdown` says the server's shutdown set it, so the call
/// answers that rather than a timeout.
#[derive(Default)]
struct Flags {
    cancel: Arc<AtomicBool>,
    shutdown: AtomicBool,
}

/// The flags of the calls running now, by the address of their backend, so that
/// shutting one server down stops its calls and no other's.
static RUNNING: Mutex<Running> = Mutex::new(Running { calls: Vec::new(), sweep_at: SWEEP_FLOOR });

/// The calls' flags, with finished ones forgotten now and then: a sweep when the list
/// has doubled since the last one keeps it within twice the running calls (plus
/// [`SWEEP_FLOOR`]) at a constant cost per call, where a sweep per call cost time in
/// proportion to the calls running.
struct Running {
    calls: Vec<(usize, Weak<Flags>)>,
    /// The length at which the next registration sweeps.
    sweep_at: usize,
}

/// The shortest list that is swept.
const SWEEP_FLOOR: usize = 64;

fn backend_key(desktop: &Arc<dyn Desktop>) -> usize {
    Arc::as_ptr(desktop).cast::<()>() as usize
}

fn register(desktop: &Arc<dyn Desktop>, flags: &Arc<Flags>) {
    let mut running = RUNNING.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    if running.calls.len() >= running.sweep_at {
        // Finished calls drop their flags; forget them.
        running.calls.retain(|(_, flags)| flags.strong_count() > 0);
        running.sweep_at = (running.calls.len() * 2).max(SWEEP_FLOOR);
    }
    running.calls.push((backend_key(desktop), Arc::downgrade(flags)));
}

/// Tells every call running against `desktop` to stop, as a timeout does; answers how
/// many were told. The server calls it when it starts shutting down.
pub fn cancel_all(desktop: &Arc<dyn Desktop>) -> usize {
    let key = backend_key(desktop);
    let running = RUNNING.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let mut told = 0;
    for flags in running.calls.iter().filter(|(k, _)| *k == key).filter_map(|(_, flags)| flags.upgrade()) {
        flags.shutdown.store(true, Ordering::Relaxed);
        flags.cancel.store(true, Ordering::Relaxed);
        told += 1;
    }
    told
}

/// Runs `f` against the backend on the backend pool, failing after `deadline`.
///
/// # Errors
///
/// Whatever `f` returns, [`DesktopError::Timeout`] after `deadline`,
/// [`DesktopError::ShuttingDown`] when the server's shutdown stopped it, or
/// [`DesktopError::Os`] if the call panicked.
pub async fn blocking<T, F>(desktop: &Arc<dyn Desktop>, op: &'static str, deadline: Duration, f: F) -> DesktopResult<T>
where
    F: FnOnce(&dyn Desktop) -> DesktopResult<T> + Send + 'static,
    T: Send + 'static,
{
    let desktop = Arc::clone(desktop);
    let flags = Arc::new(Flags::default());
    register(&desktop, &flags);
    let ms = u64::try_from(deadline.as_millis()).unwrap_or(u64::MAX);
    let task = pool::global().run({
        let cancel = Arc::clone(&flags.cancel);
        move || {
            let _scope = Scope::enter(op, ms, cancel);
            f(desktop.as_ref())
        }
    });
    // Whatever ends this call (its deadline, or the request going away), the work stops.
    let _stop = StopOnDrop(Arc::clone(&flags.cancel));
    match tokio::time::timeout(deadline, task).await {
        // Work stopped by the shutdown ends as a timeout would (the backend cannot
        // tell the two apart); the answer says what happened.
        Ok(Ok(Ok(Err(DesktopError::Timeout { .. })))) if flags.shutdown.load(Ordering::Relaxed) => {
            Err(DesktopError::ShuttingDown { op })
        }
        Ok(Ok(Ok(res))) => res,
        Ok(Ok(Err(panic))) => {
            let message = panic
                .downcast_ref::<&str>()
                .map(|s| (*s).to_owned())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_default();
            tracing::error!(op, panic = %message, "backend call panicked");
            Err(DesktopError::Os { op, message: "the backend call panicked; see the guest log".into() })
        }
        Ok(Err(_)) => Err(DesktopError::Os { op, message: "the backend call was dropped before it ran".into() }),
        Err(_) => {
            tracing::warn!(op, deadline_ms = deadline.as_millis() as u64, "backend call timed out");
            Err(DesktopError::Timeout { op, ms: deadline.as_millis() as u64 })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::desktop::stub::StubDesktop;

    #[test]
    fn finished_calls_are_forgotten_so_the_list_stays_bounded() {
        let dir = tempfile::tempdir().unwrap();
        let desktop: Arc<dyn Desktop> = Arc::new(StubDesktop::new(dir.path().to_path_buf()).unwrap());
        let live: Vec<Arc<Flags>> = (0..10).map(|_| Arc::new(Flags::default())).collect();
        for flags in &live {
            register(&desktop, flags);
        }
        for _ in 0..10_000 {
            register(&desktop, &Arc::new(Flags::default())); // finished at once
        }
        let len = RUNNING.lock().unwrap().calls.len();
        // Other tests' calls may be running too; without the sweeps this would be 10 010.
        assert!(len < 2 * (live.len() + 100) + SWEEP_FLOOR, "{len} entries");
        assert_eq!(cancel_all(&desktop), live.len(), "the running calls are all still known");
        assert!(live.iter().all(|flags| flags.cancel.load(Ordering::Relaxed)));
    }

    #[tokio::test]
    async fn a_slow_call_times_out_without_blocking_the_caller() {
        let dir = tempfile::tempdir().unwrap();
        let desktop: Arc<dyn Desktop> = Arc::new(StubDesktop::new(dir.path().to_path_buf()).unwrap());
        let res = blocking(&desktop, "sleepy", Duration::from_millis(20), |_| {
            std::thread::sleep(Duration::from_millis(300));
            Ok(())
        })
        .await;
        assert!(matches!(res, Err(DesktopError::Timeout { op: "sleepy", ms: 20 })), "{res:?}");
    }

    #[tokio::test]
    async fn a_timed_out_call_is_told_to_stop() {
        let dir = tempfile::tempdir().unwrap();
        let desktop: Arc<dyn Desktop> = Arc::new(StubDesktop::new(dir.path().to_path_buf()).unwrap());
        let (done, stopped) = std::sync::mpsc::channel();
        let res = blocking(&desktop, "long", Duration::from_millis(20), move |_| {
            // An hour of work in slices, as typing with pauses is.
            let outcome = crate::desktop::cancel::sleep(Duration::from_secs(3600));
            let _ = done.send(outcome);
            Ok(())
        })
        .await;
        assert!(matches!(res, Err(DesktopError::Timeout { op: "long", ms: 20 })), "{res:?}");
        let outcome = stopped.recv_timeout(Duration::from_secs(30)).expect("the work stopped instead of running on");
        assert!(matches!(outcome, Err(DesktopError::Timeout { op: "long", .. })), "{outcome:?}");
    }

    #[tokio::test]
    async fn shutting_down_stops_the_calls_of_that_backend_only() {
        let dir = tempfile::tempdir().unwrap();
        let desktop: Arc<dyn Desktop> = Arc::new(StubDesktop::new(dir.path().to_path_buf()).unwrap());
        let other: Arc<dyn Desktop> = Arc::new(StubDesktop::new(dir.path().join("other")).unwrap());
        let (started, running) = std::sync::mpsc::channel();
        let call = tokio::spawn({
            let desktop = Arc::clone(&desktop);
            async move {
                blocking(&desktop, "long", Duration::from_secs(3600), move |_| {
                    let _ = started.send(());
                    crate::desktop::cancel::sleep(Duration::from_secs(3600))
                })
                .await
            }
        });
        // Waited for without blocking the test's one runtime thread, which runs the call.
        for _ in 0..3000 {
            if running.try_recv().is_ok() {
                break;
            }
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
        assert_eq!(cancel_all(&other), 0, "another backend's shutdown leaves this call alone");
        assert_eq!(cancel_all(&desktop), 1);
        let res = call.await.expect("joined");
        assert!(matches!(res, Err(DesktopError::ShuttingDown { op: "long" })), "{res:?}");
        assert_eq!(res.unwrap_err().to_string(), "long was stopped: the guest is shutting down");
    }

    #[tokio::test]
    async fn a_panicking_call_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let desktop: Arc<dyn Desktop> = Arc::new(StubDesktop::new(dir.path().to_path_buf()).unwrap());
        let res: DesktopResult<()> = blocking(&desktop, "boom", Duration::from_secs(5), |_| panic!("boom")).await;
        assert!(matches!(res, Err(DesktopError::Os { op: "boom", .. })), "{res:?}");
    }
}
