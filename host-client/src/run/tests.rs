//! Tests of runs: task lists, shards, the pool of stub guests, resuming and merging.

use std::collections::HashMap;
use std::sync::Mutex;
use std::time::Duration;

use super::pool::*;
use super::*;
use arena_client::client::ClientConfig;
use arena_results::fixtures::{episode, layout, write_task};
use arena_results::{EpisodeResult, EpisodeStatus};

fn task(domain: &str, name: &str) -> Task {
    let text = r#"{"id": "x", "instruction": "i", "config": [], "evaluator": {"func": "infeasible"}}"#;
    Task::parse(text, &PathBuf::from(format!("/tasks/{domain}/{name}.json"))).unwrap()
}

fn tasks(n: usize) -> Vec<Task> {
    (0..n).map(|i| task(if i % 2 == 0 { "notepad" } else { "chrome" }, &format!("t{i:02}"))).collect()
}

fn client(url: &str) -> GuestClient {
    GuestClient::new(url, ClientConfig { token: None, timeout: Duration::from_secs(2), retries: 0 }).unwrap()
}

/// A loopback URL nothing listens on.
fn dead_url() -> String {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap();
    drop(listener);
    format!("http://{addr}")
}

fn fast_pool() -> PoolConfig {
    PoolConfig {
        max_attempts: 3,
        probe_interval: Duration::from_millis(50),
        health_timeout: Duration::from_millis(500),
        no_guest_timeout: Duration::from_millis(400),
        ..PoolConfig::default()
    }
}

/// Succeeds on every guest except those listed, where it is an infrastructure
/// error; records how many tasks each guest runs at once.
#[derive(Default)]
struct Fake {
    broken: Vec<String>,
    busy: Mutex<HashMap<String, u32>>,
    max_busy: Mutex<u32>,
    runs: Mutex<Vec<(String, String, u32)>>,
}

#[async_trait::async_trait]
impl TaskRunner for Fake {
    async fn run(
        &self,
        guest: &GuestClient,
        task: &Task,
        attempt: u32,
        _vm: Option<arena_results::VmStart>,
    ) -> EpisodeResult {
        let url = guest.base_url().to_owned();
        {
            let mut busy = self.busy.lock().unwrap();
            let n = busy.entry(url.clone()).or_default();
            *n += 1;
            let mut max = self.max_busy.lock().unwrap();
            *max = (*max).max(*n);
        }
        tokio::time::sleep(Duration::from_millis(5)).await;
        *self.busy.lock().unwrap().get_mut(&url).unwrap() -= 1;
        self.runs.lock().unwrap().push((task.name.clone(), url.clone(), attempt));
        let status = if self.broken.contains(&url) {
            EpisodeStatus::InfraError(format!("{url} failed"))
        } else {
            EpisodeStatus::Completed
        };
        let score = if status.is_infra() { 0.0 } else { 1.0 };
        let mut result = episode(&task.domain, &task.name, score, status, 1);
        result.guest = url;
        result.attempt = attempt;
        result
    }
}

async fn stubs(n: usize) -> Vec<crate::driver::stub::RunningStub> {
    let mut out = Vec::new();
    for _ in 0..n {
        out.push(crate::driver::stub::start(&crate::driver::stub::StubArgs::default(), None).await.unwrap());
    }
    out
}

#[tokio::test]
async fn a_dead_guest_is_set_aside_and_its_task_runs_elsewhere() {
    let live = stubs(3).await;
    let dead = dead_url();
    let mut guests: Vec<GuestClient> = vec![client(&dead)];
    guests.extend(live.iter().map(|s| client(&s.url())));
    let fake = Arc::new(Fake { broken: vec![dead.clone()], ..Fake::default() });
    let mut events = Vec::new();
    let report = run_pool(guests, tasks(12), fake.clone(), &fast_pool(), &mut |e| {
        events.push(match e {
            PoolEvent::GuestDown { guest, .. } => format!("down {guest}"),
            PoolEvent::Retrying { task, attempt, .. } => format!("retry {} {attempt}", task.name),
            PoolEvent::Finished { task, .. } => format!("finished {}", task.name),
            _ => String::new(),
        })
    })
    .await;
    assert_eq!(report.results.len(), 12, "every task has a result");
    assert!(report.results.iter().all(|r| r.status == EpisodeStatus::Completed), "{:?}", report.results);
    assert_eq!(report.episodes, 13, "one failed try on the dead guest, then never again");
    assert_eq!(report.guests_down, std::slice::from_ref(&dead));
    assert!(events.contains(&format!("down {dead}")));
    let retried: Vec<_> = fake.runs.lock().unwrap().iter().filter(|(_, _, a)| *a == 2).cloned().collect();
    assert_eq!(retried.len(), 1);
    assert_ne!(retried[0].1, dead, "the retry ran on another guest");
    assert_eq!(*fake.max_busy.lock().unwrap(), 1, "one task per guest at a time");
    for stub in live {
        stub.stop().await.unwrap();
    }
}

#[tokio::test]
async fn a_task_that_keeps_failing_is_given_up_after_its_tries() {
    let live = stubs(1).await;
    let url = live[0].url();
    let fake = Arc::new(Fake { broken: vec![url.clone()], ..Fake::default() });
    let mut gave_up = 0;
    let report = run_pool(vec![client(&url)], tasks(2), fake.clone(), &fast_pool(), &mut |e| {
        if matches!(e, PoolEvent::GaveUp { .. }) {
            gave_up += 1;
        }
    })
    .await;
    // The guest answers its health question, so it stays in the pool; each task gets three tries.
    assert_eq!(report.episodes, 6);
    assert_eq!(gave_up, 2);
    assert_eq!(report.results.len(), 2);
    assert!(report.results.iter().all(|r| r.status.is_infra() && r.attempt == 3));
    assert!(report.guests_down.is_empty());
    live.into_iter().next().unwrap().stop().await.unwrap();
}

#[tokio::test]
async fn with_no_guest_left_the_remaining_tasks_are_given_up() {
    let dead = dead_url();
    let fake = Arc::new(Fake { broken: vec![dead.clone()], ..Fake::default() });
    let started = std::time::Instant::now();
    let report = run_pool(vec![client(&dead)], tasks(3), fake, &fast_pool(), &mut |_| {}).await;
    assert_eq!(report.episodes, 1);
    assert!(report.results.is_empty());
    assert_eq!(report.not_run.len(), 3, "{:?}", report.not_run);
    assert!(started.elapsed() < Duration::from_secs(10));
}

#[tokio::test]
async fn a_guest_that_comes_back_rejoins_the_pool() {
    // The guest is down for its first task and answers once a stub listens on its port.
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = listener.local_addr().unwrap().port();
    drop(listener);
    let url = format!("http://127.0.0.1:{port}");
    struct FlakyOnce {
        failed: Mutex<bool>,
    }
    #[async_trait::async_trait]
    impl TaskRunner for FlakyOnce {
        async fn run(
            &self,
            guest: &GuestClient,
            task: &Task,
            attempt: u32,
            _vm: Option<arena_results::VmStart>,
        ) -> EpisodeResult {
            let first = !std::mem::replace(&mut *self.failed.lock().unwrap(), true);
            let status = if first { EpisodeStatus::InfraError("down".into()) } else { EpisodeStatus::Completed };
            let mut result = episode(&task.domain, &task.name, if first { 0.0 } else { 1.0 }, status, 1);
            result.guest = guest.base_url().to_owned();
            result.attempt = attempt;
            result
        }
    }
    let runner = Arc::new(FlakyOnce { failed: Mutex::new(false) });
    let args = crate::driver::stub::StubArgs { port, ..crate::driver::stub::StubArgs::default() };
    let mut back = 0;
    let pool_config = PoolConfig { no_guest_timeout: Duration::from_secs(20), ..fast_pool() };
    let mut count_back = |e: PoolEvent<'_>| {
        if matches!(e, PoolEvent::GuestBack { .. }) {
            back += 1;
        }
    };
    let (report, stub) =
        tokio::join!(run_pool(vec![client(&url)], tasks(2), runner, &pool_config, &mut count_back), async {
            tokio::time::sleep(Duration::from_millis(300)).await;
            crate::driver::stub::start(&args, None).await.unwrap()
        });
    assert_eq!(back, 1);
    assert_eq!(report.results.len(), 2);
    assert!(report.results.iter().all(|r| r.status == EpisodeStatus::Completed));
    stub.stop().await.unwrap();
}

#[test]
fn the_plan_takes_the_shard_and_skips_finished_tasks() {
    let root = tempfile::tempdir().unwrap();
    let layout = layout(root.path());
    let mut all = tasks(6);
    sort_tasks(&mut all);
    let names = |ts: &[Task]| ts.iter().map(|t| t.name.clone()).collect::<Vec<_>>();
    assert_eq!(names(&all), ["t01", "t03", "t05", "t00", "t02", "t04"], "sorted by domain, then name");
    // `write_task` uses the same layout as `layout`.
    write_task(root.path(), "chrome", "t01", 1.0, EpisodeStatus::Completed);
    write_task(root.path(), "notepad", "t02", 0.0, EpisodeStatus::InfraError("x".into()));
    let p = plan(all.clone(), Shard::ALL, &layout, true, TaskOrder::Sorted);
    assert_eq!(names(&p.finished), ["t01"]);
    assert_eq!(names(&p.todo), ["t03", "t05", "t00", "t02", "t04"], "an infrastructure error is not finished");
    let p = plan(all.clone(), Shard::ALL, &layout, false, TaskOrder::Sorted);
    assert_eq!(p.todo.len(), 6);
    let p = plan(all, "2/2".parse().unwrap(), &layout, true, TaskOrder::Sorted);
    assert_eq!(names(&p.todo), ["t03", "t00", "t04"]);
}

#[test]
fn a_shard_runs_in_the_order_asked_for_and_shards_do_not_depend_on_it() {
    let root = tempfile::tempdir().unwrap();
    let layout = layout(root.path());
    // As an index file lists them: not sorted.
    let mut all = tasks(8);
    all.reverse();
    let names = |ts: &[Task]| ts.iter().map(|t| t.name.clone()).collect::<Vec<_>>();
    let loaded = names(&all);
    let index = plan(all.clone(), Shard::ALL, &layout, false, TaskOrder::Index);
    assert_eq!(names(&index.todo), loaded, "upstream's order: the index's");
    let sorted = plan(all.clone(), Shard::ALL, &layout, false, TaskOrder::Sorted);
    let mut by_domain = all.clone();
    sort_tasks(&mut by_domain);
    assert_eq!(names(&sorted.todo), names(&by_domain));
    let shuffled = |seed| names(&plan(all.clone(), Shard::ALL, &layout, false, TaskOrder::Shuffle { seed }).todo);
    assert_eq!(shuffled(7), shuffled(7), "a seed gives one order");
    assert_ne!(shuffled(7), shuffled(8));
    let mut same = shuffled(7);
    same.sort();
    let mut every = loaded.clone();
    every.sort();
    assert_eq!(same, every, "a shuffle runs every task once");
    // Shard membership is the same whatever the order; within it the order holds.
    for order in [TaskOrder::Index, TaskOrder::Sorted, TaskOrder::Shuffle { seed: 3 }] {
        let mut members = names(&plan(all.clone(), "1/3".parse().unwrap(), &layout, false, order).todo);
        members.sort();
        let mut expected = names(&plan(all.clone(), "1/3".parse().unwrap(), &layout, false, TaskOrder::Sorted).todo);
        expected.sort();
        assert_eq!(members, expected, "{order}");
    }
    let first = names(&plan(all.clone(), "1/3".parse().unwrap(), &layout, false, TaskOrder::Index).todo);
    let positions: Vec<usize> = first.iter().map(|n| loaded.iter().position(|l| l == n).unwrap()).collect();
    assert!(positions.windows(2).all(|w| w[0] < w[1]), "index order within the shard: {first:?}");
}

#[test]
fn task_lists_load_from_folders_and_indexes_and_report_every_broken_file() {
    let root = tempfile::tempdir().unwrap();
    let examples = root.path().join("examples");
    for (domain, name) in [("notepad", "b"), ("notepad", "a"), ("chrome", "c")] {
        std::fs::create_dir_all(examples.join(domain)).unwrap();
        std::fs::write(
            examples.join(domain).join(format!("{name}.json")),
            format!(r#"{{"id": "{name}", "instruction": "i", "config": [], "evaluator": {{"func": "infeasible"}}}}"#),
        )
        .unwrap();
    }
    std::fs::write(root.path().join("test_small.json"), r#"{"notepad": ["b"], "chrome": ["c"]}"#).unwrap();
    let names = |ts: Vec<Task>| ts.into_iter().map(|t| format!("{}/{}", t.domain, t.name)).collect::<Vec<_>>();
    assert_eq!(names(load_tasks(root.path(), Difficulty::Normal).unwrap()), ["chrome/c", "notepad/a", "notepad/b"]);
    assert_eq!(names(load_tasks(&examples, Difficulty::Normal).unwrap()), ["chrome/c", "notepad/a", "notepad/b"]);
    // An index keeps its own order, as upstream runs it.
    assert_eq!(
        names(load_tasks(&root.path().join("test_small.json"), Difficulty::Normal).unwrap()),
        ["notepad/b", "chrome/c"]
    );
    assert!(matches!(load_tasks(&root.path().join("test_small.json"), Difficulty::Hard), Err(LoadError::Tasks(_))));
    std::fs::write(examples.join("chrome/bad.json"), "{").unwrap();
    std::fs::write(examples.join("chrome/worse.json"), r#"{"id": "w", "instruction": "i", "config": [{"type": "teleport", "parameters": {}}], "evaluator": {"func": "infeasible"}}"#).unwrap();
    let err = load_tasks(root.path(), Difficulty::Normal).unwrap_err().to_string();
    assert!(err.contains("2 task file(s)") && err.contains("bad.json") && err.contains("teleport"), "{err}");
    let empty = tempfile::tempdir().unwrap();
    assert!(matches!(load_tasks(empty.path(), Difficulty::Normal), Err(LoadError::Empty { .. })));
}

#[test]
fn trials_are_queued_trial_major_each_in_its_folder_and_resume_alone() {
    let root = tempfile::tempdir().unwrap();
    let layout = layout(root.path());
    let all = tasks(3);
    let names: Vec<String> = all.iter().map(|t| t.name.clone()).collect();
    // Trial 1 of the second task is already finished (trial folder `1`).
    let mut done = all[1].clone();
    done.extra.insert(arena_results::TRIAL_KEY.into(), 1.into());
    let dir = layout.task_dir(&done);
    assert!(dir.path().ends_with(format!("1/{}/{}", done.domain, done.name)), "{}", dir.path().display());
    dir.prepare().unwrap();
    dir.write_result("1.0").unwrap();

    let p = plan_trials(all.clone(), Shard::ALL, &layout, true, TaskOrder::Index, 3);
    let queued: Vec<(u64, String)> =
        p.todo.iter().map(|t| (arena_results::trial_of(t).unwrap(), t.name.clone())).collect();
    let mut want = Vec::new();
    for trial in 0..3u64 {
        for (i, name) in names.iter().enumerate() {
            if !(trial == 1 && i == 1) {
                want.push((trial, name.clone()));
            }
        }
    }
    assert_eq!(queued, want, "every task of trial 0, then of trial 1, ...");
    assert_eq!(p.finished.len(), 1);

    // One trial: no mark, upstream's trial folder, and a task file cannot choose one.
    let mut sneaky = all.clone();
    sneaky[0].extra.insert(arena_results::TRIAL_KEY.into(), 7.into());
    let p = plan_trials(sneaky, Shard::ALL, &layout, true, TaskOrder::Index, 1);
    assert!(p.todo.iter().all(|t| arena_results::trial_of(t).is_none()));
    assert_eq!(layout.task_dir(&p.todo[0]).path(), layout.base().join(&all[0].domain).join(&all[0].name));
}
