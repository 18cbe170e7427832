//! Being asked to stop: Ctrl-C everywhere, and SIGTERM on Unix (a pod being
//! deleted, `docker stop`), which a run takes as its first Ctrl-C.

/// Waits for Ctrl-C or SIGTERM (SIGTERM on Unix only); `false` when Ctrl-C
/// cannot be listened for.
pub(crate) async fn interrupt() -> bool {
    let term = terminate_requested().inspect_err(|err| tracing::warn!(error = %err, "cannot listen for SIGTERM")).ok();
    let terminated = async {
        match term {
            Some(term) => term.await,
            None => std::future::pending::<()>().await,
        }
    };
    tokio::select! {
        signal = tokio::signal::ctrl_c() => signal.is_ok(),
        () = terminated => true,
    }
}

/// A future that resolves when this process is asked to terminate: SIGTERM on
/// Unix, listened for from this call on. Other hosts have no SIGTERM and it
/// never resolves there: Ctrl-C (`tokio::signal::ctrl_c`, heard on both) is how
/// they stop a command.
///
/// # Errors
///
/// The signal handler cannot be installed.
pub(crate) fn terminate_requested() -> std::io::Result<impl std::future::Future<Output = ()> + Send> {
    #[cfg(unix)]
    {
        let mut term = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())?;
        Ok(async move {
            term.recv().await;
        })
    }
    #[cfg(not(unix))]
    {
        Ok(std::future::pending())
    }
}
