//! The threads backend calls run on.
//!
//! tokio's blocking pool starts a thread whenever a call finds none idle, and parks each
//! thread as soon as its call ends. Under many clients that is two thread wake-ups per
//! backend call, and a pool that grew to about 70 threads on two cores, all of them
//! competing with the server's own workers (the 200-client tail of `loadbench`).
//!
//! Backend calls are mostly short, so this pool keeps about as many threads as there
//! are cores working through one queue: a thread that finishes a call takes the next
//! without sleeping, and a call is handed to a parked thread only when one is parked.
//! It starts another thread only when calls are waiting and fewer than that many
//! threads are free of a call that has run longer than [`STUCK_AFTER`]: a hung UI
//! Automation provider, a window that does not answer, or a long interpreter run then
//! holds its own thread while the calls queued behind it go on, as they did on tokio's
//! pool, after at most that delay. Threads beyond the core count end after
//! [`KEEP_ALIVE`] without work.
//!
//! No published pool grows this way: rusty_pool, `blocking` and tokio's own grow as
//! soon as no thread is idle, which is the behaviour this replaces.

use std::collections::VecDeque;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, OnceLock, PoisonError};
use std::time::{Duration, Instant};

/// How long a call may run before the calls queued behind it get a thread of their
/// own. The stub's calls take microseconds and the Windows backend's most take a few
/// milliseconds; a call past this is either slow work (a tree walk, a program) or
/// hung, and in both cases should not hold up the queue.
pub(super) const STUCK_AFTER: Duration = Duration::from_millis(10);

/// How long a thread beyond the core count waits for work before it ends (tokio's
/// blocking threads wait 10 s).
pub(super) const KEEP_ALIVE: Duration = Duration::from_secs(10);

/// The most threads the pool runs at once, as tokio's blocking pool; past it, calls
/// wait in the queue (and their deadlines still answer their requests).
pub(super) const MAX_THREADS: usize = 512;

type Job = Box<dyn FnOnce() + Send>;

/// The shape of a pool; [`global`] uses the constants above.
#[derive(Debug, Clone, Copy)]
pub(super) struct Config {
    /// Threads kept without work: the number of cores, at least 2.
    pub(super) core: usize,
    pub(super) max: usize,
    pub(super) stuck_after: Duration,
    pub(super) keep_alive: Duration,
}

impl Config {
    fn default_for_this_machine() -> Config {
        let cores = std::thread::available_parallelism().map_or(2, std::num::NonZeroUsize::get);
        Config { core: cores.max(2), max: MAX_THREADS, stuck_after: STUCK_AFTER, keep_alive: KEEP_ALIVE }
    }
}

/// A pool of threads for backend calls.
pub(super) struct Pool {
    shared: Arc<Shared>,
}

struct Shared {
    state: Mutex<State>,
    /// Parked threads wait here for a call.
    work: Condvar,
    /// The watchdog waits here for calls queued behind busy threads.
    watch: Condvar,
    config: Config,
}

#[derive(Default)]
struct State {
    queue: VecDeque<Job>,
    /// When each running call started, by the slot of its thread; `None` for a thread
    /// without a call, and for a slot no thread holds (see `free`).
    started: Vec<Option<Instant>>,
    /// Slots no thread holds: every other slot is one running thread's.
    free: Vec<usize>,
    /// Threads waiting on `work`.
    parked: usize,
    /// The watchdog waits for calls to be queued (rather than for a call to turn stuck).
    watchdog_asleep: bool,
    watchdog_started: bool,
}

impl State {
    /// Threads the pool runs now: one per held slot.
    fn threads(&self) -> usize {
        self.started.len() - self.free.len()
    }
}

fn lock(mutex: &Mutex<State>) -> MutexGuard<'_, State> {
    // A job never runs under the lock, so a poisoned lock is only a panic in this
    // module's bookkeeping; the state is still consistent enough to go on.
    mutex.lock().unwrap_or_else(PoisonError::into_inner)
}

/// The pool every backend call of this process runs on.
pub(super) fn global() -> &'static Pool {
    static POOL: OnceLock<Pool> = OnceLock::new();
    POOL.get_or_init(|| Pool::new(Config::default_for_this_machine()))
}

impl Pool {
    pub(super) fn new(config: Config) -> Pool {
        let config = Config { core: config.core.max(1), max: config.max.max(config.core.max(1)), ..config };
        Pool {
            shared: Arc::new(Shared {
                state: Mutex::new(State::default()),
                work: Condvar::new(),
                watch: Condvar::new(),
                config,
            }),
        }
    }

    /// Runs `f` on a pool thread; the receiver gets its result, or the panic it ended
    /// with. Dropping the receiver does not stop `f`.
    pub(super) fn run<T, F>(&self, f: F) -> tokio::sync::oneshot::Receiver<std::thread::Result<T>>
    where
        F: FnOnce() -> T + Send + 'static,
        T: Send + 'static,
    {
        let (tx, rx) = tokio::sync::oneshot::channel();
        self.submit(Box::new(move || {
            let _ = tx.send(catch_unwind(AssertUnwindSafe(f)));
        }));
        rx
    }

    fn submit(&self, job: Job) {
        let shared = &self.shared;
        let mut state = lock(&shared.state);
        state.queue.push_back(job);
        if state.parked > 0 {
            shared.work.notify_one();
        } else if state.threads() < shared.config.core && spawn_thread(shared, &mut state) {
            return;
        }
        // More calls wait than parked threads will take: the watchdog finds out whether
        // the busy threads are stuck.
        if state.queue.len() > state.parked {
            if !state.watchdog_started {
                state.watchdog_started = true;
                let shared = Arc::clone(shared);
                let started =
                    std::thread::Builder::new().name("backend-watchdog".into()).spawn(move || watchdog(&shared));
                if let Err(err) = started {
                    tracing::error!(error = %err, "could not start the backend pool's watchdog");
                    state.watchdog_started = false;
                }
            } else if state.watchdog_asleep {
                state.watchdog_asleep = false;
                shared.watch.notify_one();
            }
        }
    }

    /// Threads the pool runs now.
    #[cfg(test)]
    pub(super) fn threads(&self) -> usize {
        lock(&self.shared.state).threads()
    }
}

/// Starts a pool thread; false when the system would not.
fn spawn_thread(shared: &Arc<Shared>, state: &mut State) -> bool {
    let slot = state.free.pop().unwrap_or_else(|| {
        state.started.push(None);
        state.started.len() - 1
    });
    let worker = Arc::clone(shared);
    let spawned = std::thread::Builder::new().name("backend".into()).spawn(move || work(&worker, slot));
    if let Err(err) = spawned {
        // The queued calls wait for a running thread (or time out); the server goes on.
        tracing::error!(error = %err, "could not start a backend thread");
        state.free.push(slot);
        return false;
    }
    true
}

/// One pool thread: runs queued calls until it has waited `keep_alive` for one while
/// the pool has more threads than its core.
fn work(shared: &Shared, slot: usize) {
    let mut state = lock(&shared.state);
    loop {
        if let Some(job) = state.queue.pop_front() {
            state.started[slot] = Some(Instant::now());
            drop(state);
            job();
            state = lock(&shared.state);
            state.started[slot] = None;
            continue;
        }
        state.parked += 1;
        let (next, timeout) =
            shared.work.wait_timeout(state, shared.config.keep_alive).unwrap_or_else(PoisonError::into_inner);
        state = next;
        state.parked -= 1;
        if timeout.timed_out() && state.queue.is_empty() && state.threads() > shared.config.core {
            state.free.push(slot);
            return;
        }
    }
}

/// Starts a thread whenever calls are waiting and fewer than `core` threads are free
/// of a stuck call.
fn watchdog(shared: &Arc<Shared>) {
    let config = shared.config;
    let mut state = lock(&shared.state);
    loop {
        if state.queue.len() <= state.parked {
            state.watchdog_asleep = true;
            state = shared.watch.wait(state).unwrap_or_else(PoisonError::into_inner);
            continue;
        }
        let now = Instant::now();
        let mut stuck = 0;
        let mut next_check = config.stuck_after;
        for started in state.started.iter().flatten() {
            let running = now.saturating_duration_since(*started);
            if running >= config.stuck_after {
                stuck += 1;
            } else {
                next_check = next_check.min(config.stuck_after - running);
            }
        }
        let threads = state.threads();
        if threads - stuck < config.core && threads < config.max && spawn_thread(shared, &mut state) {
            continue;
        }
        state.watchdog_asleep = false;
        state = shared.watch.wait_timeout(state, next_check).unwrap_or_else(PoisonError::into_inner).0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::mpsc;

    /// The answer of a call, waited for without a runtime (for at most a minute, so a
    /// broken pool fails the test instead of hanging it).
    fn answer<T>(mut rx: tokio::sync::oneshot::Receiver<std::thread::Result<T>>) -> std::thread::Result<T> {
        let until = Instant::now() + Duration::from_secs(60);
        loop {
            match rx.try_recv() {
                Ok(answer) => return answer,
                Err(tokio::sync::oneshot::error::TryRecvError::Empty) if Instant::now() < until => {
                    std::thread::sleep(Duration::from_millis(1));
                }
                Err(err) => panic!("no answer: {err:?}"),
            }
        }
    }

    fn pool(core: usize, stuck_after: Duration, keep_alive: Duration) -> Pool {
        Pool::new(Config { core, max: MAX_THREADS, stuck_after, keep_alive })
    }

    #[test]
    fn calls_queued_behind_hung_calls_still_run() {
        let pool = pool(2, Duration::from_millis(10), KEEP_ALIVE);
        let (release, hung) = mpsc::channel::<()>();
        let hung = Arc::new(Mutex::new(hung));
        let hung_calls: Vec<_> = (0..2)
            .map(|_| {
                let hung = Arc::clone(&hung);
                pool.run(move || {
                    let _ = hung.lock().unwrap().recv();
                })
            })
            .collect();
        // Both core threads are now (or soon) stuck; these must still be answered.
        for n in 0..3 {
            assert_eq!(answer(pool.run(move || n * 2)).unwrap(), n * 2);
        }
        assert!(pool.threads() > 2, "a thread was started beside the stuck ones");
        drop(release);
        for call in hung_calls {
            answer(call).unwrap();
        }
    }

    #[test]
    fn short_calls_never_grow_the_pool_past_its_core() {
        // Nothing counts as stuck, so only the core threads may run, however many
        // callers submit at once (tokio's pool starts one whenever none is idle).
        let pool = Arc::new(pool(2, Duration::from_secs(3600), KEEP_ALIVE));
        let callers: Vec<_> = (0..8)
            .map(|caller| {
                let pool = Arc::clone(&pool);
                std::thread::spawn(move || {
                    let calls: Vec<_> =
                        (0..500).map(|n| pool.run(move || (0..100u64).sum::<u64>() + n + caller)).collect();
                    for (n, call) in (0..).zip(calls) {
                        assert_eq!(answer(call).unwrap(), 4950 + n + caller);
                    }
                    500
                })
            })
            .collect();
        let answered: usize = callers.into_iter().map(|c| c.join().unwrap()).sum();
        assert_eq!(answered, 8 * 500);
        assert_eq!(pool.threads(), 2);
    }

    #[test]
    fn threads_past_the_core_end_once_idle() {
        let pool = pool(1, Duration::from_millis(10), Duration::from_millis(50));
        let (release, hung) = mpsc::channel::<()>();
        let hung_call = pool.run(move || {
            let _ = hung.recv();
        });
        assert_eq!(answer(pool.run(|| 7)).unwrap(), 7);
        assert_eq!(pool.threads(), 2);
        drop(release);
        answer(hung_call).unwrap();
        let until = Instant::now() + Duration::from_secs(60);
        while pool.threads() > 1 && Instant::now() < until {
            std::thread::sleep(Duration::from_millis(5));
        }
        assert_eq!(pool.threads(), 1, "the extra thread ended after its keep-alive");
    }

    #[test]
    fn a_call_that_panics_is_answered_and_its_thread_goes_on() {
        let pool = pool(1, Duration::from_millis(10), KEEP_ALIVE);
        let panicked = answer(pool.run(|| -> u32 { panic!("boom") }));
        assert_eq!(panicked.unwrap_err().downcast_ref::<&str>(), Some(&"boom"));
        assert_eq!(answer(pool.run(|| 5)).unwrap(), 5);
        assert_eq!(pool.threads(), 1);
    }
}
