//! The UI Automation health stage's decision, shared by every backend, and the cap
//! on threads that hung providers keep.
//!
//! UI Automation can answer empty trees while the desktop is lit and windows are in
//! front: another WAA port reports it after a QEMU `loadvm`, until the automation
//! client is created anew. [`check`] walks the foreground window; when it comes back
//! empty over a lit screen with a window in front, it re-creates the client once
//! (on Windows: a new worker process, whose COM apartment and UI Automation client
//! state are new, `desktop::uia_process`)
//! and walks again, and only then reports the stage down, with a reason that says
//! what was tried. The Windows backend and the stub (whose scenario can make its
//! UI Automation answer empty) both answer `Component::Uia` through it.
//!
//! [`call_detached`] runs one call (a window's bulk fetch) on a thread of its own with
//! a deadline, so the element-by-element read that follows a late one starts at once.
//!
//! [`ThreadCap`] bounds the threads that timed-out UI Automation work leaves behind:
//! a worker stuck in a provider that never answers keeps its thread until the call
//! returns, and a new worker is started only while fewer than the cap are alive.
//!
//! Platform-neutral and tested natively.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Instant;

use arena_shared::observation::{A11yTree, TreeBudget};

use super::{DesktopError, DesktopResult};

/// The budget of the health stage's walk: the foreground window only, 2 s, 500
/// nodes (a window with anything in it yields its first nodes long before either).
pub const HEALTH_BUDGET: TreeBudget = TreeBudget { max_depth: 50, max_children: 2048, max_nodes: 500, max_ms: 2_000 };

/// Decides the UI Automation stage.
///
/// `in_front` describes the window in front (its title) when the screen is lit and
/// a window a person sees has the foreground; `None` otherwise, when an empty tree
/// is what a healthy UI Automation answers too. `walk` reads the foreground window
/// with [`HEALTH_BUDGET`]; `recreate` drops the automation client and makes a new one.
///
/// # Errors
///
/// What `walk` or `recreate` fail with (UI Automation missing, a timeout), and
/// [`DesktopError::Os`] when the tree is still empty after one re-creation.
pub fn check(
    in_front: Option<&str>,
    walk: &mut dyn FnMut() -> DesktopResult<A11yTree>,
    recreate: &mut dyn FnMut() -> DesktopResult<()>,
) -> DesktopResult<String> {
    let started = Instant::now();
    let tree = walk()?;
    if tree.node_count > 0 {
        return Ok(format!(
            "UI Automation read {} nodes of the foreground window in {} ms",
            tree.node_count, tree.elapsed_ms
        ));
    }
    let Some(front) = in_front else {
        return Ok("no window in front: UI Automation's empty tree is the right answer".to_owned());
    };
    tracing::warn!(window = front, "UI Automation answered an empty tree over a lit screen; re-creating it");
    recreate()?;
    let tree = walk()?;
    if tree.node_count > 0 {
        return Ok(format!(
            "UI Automation answered an empty tree for {front:?}; re-created the automation client, which then read {} nodes ({} ms in all)",
            tree.node_count,
            started.elapsed().as_millis()
        ));
    }
    Err(DesktopError::Os {
        op: "uia health",
        message: format!(
            "UI Automation answers an empty tree for the window in front ({front:?}) over a lit screen, also after \
             re-creating it once (on Windows a new worker process, with a new COM apartment); a snapshot restore can leave it so: \
             restart the guest's session"
        ),
    })
}

/// At most `max` threads alive at once; each holds a [`ThreadPermit`] until it ends.
#[derive(Debug, Clone)]
pub struct ThreadCap {
    max: usize,
    live: Arc<AtomicUsize>,
}

/// One thread's place under a [`ThreadCap`], given back when dropped (when the thread ends).
#[derive(Debug)]
pub struct ThreadPermit {
    live: Arc<AtomicUsize>,
}

impl Drop for ThreadPermit {
    fn drop(&mut self) {
        self.live.fetch_sub(1, Ordering::AcqRel);
    }
}

impl ThreadCap {
    /// A cap of `max` threads.
    pub fn new(max: usize) -> ThreadCap {
        ThreadCap { max, live: Arc::new(AtomicUsize::new(0)) }
    }

    /// A place for one more thread, or `None` when `max` are alive.
    pub fn try_acquire(&self) -> Option<ThreadPermit> {
        self.live
            .fetch_update(Ordering::AcqRel, Ordering::Acquire, |n| (n < self.max).then_some(n + 1))
            .ok()
            .map(|_| ThreadPermit { live: Arc::clone(&self.live) })
    }

    /// Threads alive now.
    pub fn live(&self) -> usize {
        self.live.load(Ordering::Acquire)
    }

    /// The cap.
    pub fn max(&self) -> usize {
        self.max
    }
}

/// Runs `work` on a thread of its own (one place under `cap`) and waits for it
/// at most `within`: a call that does not come back in time (a UI Automation
/// bulk fetch a provider keeps busy past its transaction timeout) is abandoned,
/// and finishes on its own thread while the caller goes on, so what comes next
/// (the element-by-element read) never waits behind it.
///
/// # Errors
///
/// [`DesktopError::Timeout`] after `within`; [`DesktopError::Os`] when `cap`
/// threads are still busy with abandoned calls, or the thread cannot start.
pub fn call_detached<T: Send + 'static>(
    cap: &ThreadCap,
    within: std::time::Duration,
    op: &'static str,
    work: impl FnOnce() -> T + Send + 'static,
) -> DesktopResult<T> {
    let permit = cap.try_acquire().ok_or_else(|| DesktopError::Os {
        op,
        message: format!("{} abandoned calls are still running; no new one starts until one returns", cap.max()),
    })?;
    let (tx, rx) = std::sync::mpsc::sync_channel(1);
    std::thread::Builder::new()
        .name(op.into())
        .spawn(move || {
            let result = work();
            // The place is free before the caller hears back.
            drop(permit);
            let _ = tx.send(result);
        })
        .map_err(|err| DesktopError::Os { op, message: format!("starting a thread: {err}") })?;
    rx.recv_timeout(within)
        .map_err(|_| DesktopError::Timeout { op, ms: u64::try_from(within.as_millis()).unwrap_or(u64::MAX) })
}

#[cfg(test)]
mod tests {
    use super::*;
    use arena_shared::geometry::CoordinateSpace;
    use arena_shared::observation::A11yBackend;

    fn tree(nodes: u32) -> A11yTree {
        A11yTree {
            backend: A11yBackend::Uia,
            windows: Vec::new(),
            truncated: false,
            node_count: nodes,
            elapsed_ms: 1,
            coordinate_space: CoordinateSpace::Physical,
            windows_walked: Vec::new(),
        }
    }

    /// Runs `check` over walks that answer `answers` in turn; the result and the re-creations.
    fn run(in_front: Option<&str>, answers: &[u32]) -> (DesktopResult<String>, u32) {
        let mut answers = answers.iter().copied();
        let mut recreated = 0;
        let result = check(in_front, &mut || Ok(tree(answers.next().expect("no more walks expected"))), &mut || {
            recreated += 1;
            Ok(())
        });
        (result, recreated)
    }

    #[test]
    fn nodes_are_healthy_at_once() {
        let (result, recreated) = run(Some("Notepad"), &[12]);
        assert!(result.unwrap().contains("12 nodes"));
        assert_eq!(recreated, 0);
    }

    #[test]
    fn an_empty_tree_with_nothing_in_front_is_healthy() {
        let (result, recreated) = run(None, &[0]);
        assert!(result.unwrap().contains("no window in front"));
        assert_eq!(recreated, 0);
    }

    #[test]
    fn an_empty_tree_over_a_window_is_recreated_once() {
        let (result, recreated) = run(Some("Notepad"), &[0, 7]);
        let detail = result.unwrap();
        assert!(detail.contains("re-created") && detail.contains("7 nodes"), "{detail}");
        assert_eq!(recreated, 1);
        let (result, recreated) = run(Some("Notepad"), &[0, 0]);
        let err = result.unwrap_err().to_string();
        assert!(err.contains("\"Notepad\"") && err.contains("after re-creating"), "{err}");
        assert_eq!(recreated, 1);
    }

    #[test]
    fn a_failing_walk_is_the_stage_error() {
        let result =
            check(Some("Notepad"), &mut || Err(DesktopError::Unsupported("no UI Automation here".into())), &mut || {
                panic!("nothing to re-create")
            });
        assert!(matches!(result, Err(DesktopError::Unsupported(_))));
    }

    #[test]
    fn a_detached_call_is_abandoned_at_its_deadline_and_keeps_its_place_until_it_returns() {
        let cap = ThreadCap::new(1);
        assert_eq!(call_detached(&cap, std::time::Duration::from_secs(5), "quick", || 7).unwrap(), 7);
        let (release, wait) = std::sync::mpsc::channel::<()>();
        let started = Instant::now();
        let err = call_detached(&cap, std::time::Duration::from_millis(100), "stuck", move || wait.recv().is_ok())
            .unwrap_err();
        assert!(matches!(err, DesktopError::Timeout { ms: 100, .. }), "{err}");
        assert!(started.elapsed() < std::time::Duration::from_secs(2));
        // The abandoned call holds the only place until it returns.
        assert!(call_detached(&cap, std::time::Duration::from_secs(1), "next", || 1).is_err());
        release.send(()).unwrap();
        let until = Instant::now() + std::time::Duration::from_secs(5);
        while cap.live() > 0 && Instant::now() < until {
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
        assert_eq!(call_detached(&cap, std::time::Duration::from_secs(1), "next", || 2).unwrap(), 2);
    }

    #[test]
    fn the_thread_cap_holds_and_frees_places() {
        let cap = ThreadCap::new(2);
        let a = cap.try_acquire().unwrap();
        let b = cap.try_acquire().unwrap();
        assert!(cap.try_acquire().is_none());
        assert_eq!(cap.live(), 2);
        drop(a);
        let c = cap.try_acquire().unwrap();
        assert!(cap.try_acquire().is_none());
        drop((b, c));
        assert_eq!(cap.live(), 0);
    }
}
