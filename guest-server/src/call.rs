//! Calling the synchronous backend from async handlers, with a deadline.
//!
//! Every backend call goes through [`blocking`]: it runs on tokio's blocking
//! pool and the request gets [`DesktopError::Timeout`] when the deadline
//! passes. A hung window or provider then costs that one request, never the
//! server; the abandoned call finishes (or not) on its own thread.

use std::sync::Arc;
use std::time::Duration;

use crate::desktop::{Desktop, DesktopError, DesktopResult};

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
    let task = tokio::task::spawn_blocking(move || f(desktop.as_ref()));
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
    async fn a_panicking_call_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let desktop: Arc<dyn Desktop> = Arc::new(StubDesktop::new(dir.path().to_path_buf()).unwrap());
        let res: DesktopResult<()> = blocking(&desktop, "boom", Duration::from_secs(5), |_| panic!("boom")).await;
        assert!(matches!(res, Err(DesktopError::Os { op: "boom", .. })), "{res:?}");
    }
}
