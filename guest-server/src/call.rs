//! Calling the synchronous backend from async handlers, with a deadline.
//!
//! Every backend call goes through [`blocking`]: it runs on tokio's blocking
//! pool and the request gets [`DesktopError::Timeout`] when the deadline
//! passes. A hung window or provider then costs that one request, never the
//! server. The call itself is told to stop ([`crate::desktop::cancel`]): work
//! that checks between its units (keystrokes, pauses) ends within one unit; a
//! call stuck inside the operating system finishes (or not) on its own thread.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

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

/// Runs `f` against the backend on the blocking pool, failing after `deadline`.
///
/// # Errors
///
/// Whatever `f` returns, [`DesktopError::Timeout`] after `deadline`, or
/// [`DesktopError::Os`] if the call panicked.
pub async fn blocking<T, F>(desktop: &Arc<dyn Desktop>, op: &'static str, deadline: Duration, f: F) -> DesktopResult<T>
where
    F: FnOnce(&dyn Desktop) -> DesktopResult<T> + Send + 'static,
    T: Send + 'static,
{
    let desktop = Arc::clone(desktop);
    let cancel = Arc::new(AtomicBool::new(false));
    let ms = u64::try_from(deadline.as_millis()).unwrap_or(u64::MAX);
    let task = tokio::task::spawn_blocking({
        let cancel = Arc::clone(&cancel);
        move || {
            let _scope = Scope::enter(op, ms, cancel);
            f(desktop.as_ref())
        }
    });
    // Whatever ends this call (its deadline, or the request going away), the work stops.
    let _stop = StopOnDrop(cancel);
    match tokio::time::timeout(deadline, task).await {
        Ok(Ok(res)) => res,
        Ok(Err(join_err)) => {
            tracing::error!(op, error = %join_err, "backend call panicked");
            Err(DesktopError::Os { op, message: "the backend call panicked; see the guest log".into() })
        }
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
    async fn a_panicking_call_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let desktop: Arc<dyn Desktop> = Arc::new(StubDesktop::new(dir.path().to_path_buf()).unwrap());
        let res: DesktopResult<()> = blocking(&desktop, "boom", Duration::from_secs(5), |_| panic!("boom")).await;
        assert!(matches!(res, Err(DesktopError::Os { op: "boom", .. })), "{res:?}");
    }
}
