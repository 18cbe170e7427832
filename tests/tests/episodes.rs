//! Whole episodes and runs against real `arena-guest` stub processes: the stub
//! task folder with the scripted agent's oracle plans, a pool of guests with
//! one killed midway, resuming, shards merged, and the HTML report in a
//! headless Chromium.

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use arena_agents::replay::{ReplayAgent, ReplaySource};
use arena_agents::scripted::{PlanSource, ScriptedAgent};
use arena_agents::Agent;
use arena_agents::AgentFactory;
use arena_client::cache::DownloadCache;
use arena_client::client::{ClientConfig, GuestClient};
use arena_exec::AgentAction;
use arena_host::episode::{run_episode, EpisodeConfig, EpisodeRunner};
use arena_host::run::merge::merge;
use arena_host::run::pool::PoolConfig;
use arena_host::run::shard::Shard;
use arena_host::run::{load_tasks, run_tasks, RunOptions, RunOutcome};
use arena_results::summary::Summary;
use arena_results::{EpisodeStatus, RunLayout, RESULT_FILE};
use arena_task::{Difficulty, Task};
use arena_test_support::Served;

fn stub_tasks_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tasks/stub")
}

fn stub_tasks() -> Vec<Task> {
    load_tasks(&stub_tasks_dir(), Difficulty::Normal).expect("the stub tasks load")
}

fn client(url: &str) -> GuestClient {
    GuestClient::new(url, ClientConfig { token: None, timeout: Duration::from_secs(20), retries: 2 })
        .expect("valid url")
}

fn config(cache: &Path) -> EpisodeConfig {
    let mut config = EpisodeConfig::instant(DownloadCache::new(cache).expect("cache"));
    config.model = "oracle".into();
    config
}

fn oracle() -> AgentFactory {
    let plans = stub_tasks_dir().join("plans");
    Arc::new(move || Ok(Box::new(ScriptedAgent::new(PlanSource::Dir(plans.clone()))) as Box<dyn Agent>))
}

fn layout(root: &Path) -> RunLayout {
    RunLayout {
        root: root.to_owned(),
        agent: "scripted".into(),
        observation: "a11y_tree".into(),
        model: "oracle".into(),
        trial: "0".into(),
    }
}

fn options(root: &Path, shard: Shard) -> RunOptions {
    RunOptions {
        layout: layout(root),
        shard,
        resume: true,
        pool: PoolConfig {
            max_attempts: 3,
            probe_interval: Duration::from_millis(200),
            health_timeout: Duration::from_secs(2),
            no_guest_timeout: Duration::from_secs(60),
            ..PoolConfig::default()
        },
        watch: std::sync::Arc::new(arena_host::run::watch::Unwatched),
        title: "stub run".into(),
        order: Default::default(),
        trials: 1,
        budget: Default::default(),
    }
}

async fn run(tasks: Vec<Task>, guests: &[&Served], root: &Path, shard: Shard, cache: &Path) -> RunOutcome {
    let runner = EpisodeRunner { layout: layout(root), config: config(cache), agents: oracle() };
    let guests = guests.iter().map(|g| client(&g.url)).collect();
    run_tasks(tasks, guests, Arc::new(runner), &options(root, shard)).await.expect("the run writes its report")
}

/// `n` tasks made from the stub tasks by repeating them under new names, each
/// carrying its oracle plan inline (the scripted agent reads a task's `plan` key).
fn repeated(n: usize) -> Vec<Task> {
    let base = stub_tasks();
    (0..n)
        .map(|i| {
            let mut task = base[i % base.len()].clone();
            let plan = std::fs::read_to_string(stub_tasks_dir().join("plans").join(format!("{}.json", task.name)))
                .expect("plan");
            task.extra.insert("plan".into(), serde_json::from_str(&plan).expect("plan JSON"));
            task.name = format!("{}-{i:02}", task.name);
            task
        })
        .collect()
}

#[tokio::test]
async fn every_oracle_plan_scores_one_and_a_wrong_plan_scores_zero() {
    let guest = Served::guest(&[]).expect("guest starts");
    let tmp = tempfile::tempdir().unwrap();
    let tasks = stub_tasks();
    assert_eq!(tasks.len(), 6);
    let outcome = run(tasks.clone(), &[&guest], tmp.path(), Shard::ALL, &tmp.path().join("cache")).await;
    for result in &outcome.pool.results {
        assert_eq!(
            (result.score, &result.status),
            (1.0, &EpisodeStatus::Completed),
            "{}/{}: {}",
            result.domain,
            result.task_name,
            serde_json::to_string_pretty(&result.eval).unwrap()
        );
    }
    assert_eq!(outcome.summary.table().last().unwrap(), &("Overall".to_owned(), 6, 6, 100.0));
    // The folders are upstream's, with a screenshot per step and the trajectory.
    let dir = layout(tmp.path()).task_dir(&tasks[2]);
    assert_eq!(std::fs::read_to_string(dir.path().join(RESULT_FILE)).unwrap(), "1.0\n");
    let traj = dir.read_trajectory().unwrap();
    assert!(traj.len() >= 2, "{traj:?}");
    assert!(dir.path().join(&traj[0].screenshot_file).is_file());
    assert_eq!(traj.last().unwrap().actions, [AgentAction::Done]);

    // The same guest, every task with a plan that only says DONE: nothing is solved.
    let wrong = tempfile::tempdir().unwrap();
    let cache = wrong.path().join("cache");
    let client = client(&guest.url);
    for task in &tasks {
        let mut agent = ScriptedAgent::from_actions(vec![AgentAction::Done]);
        let out = layout(wrong.path()).task_dir(task);
        let result = run_episode(&client, task, &mut agent, &config(&cache), &out).await;
        assert_eq!((result.score, &result.status, result.steps), (0.0, &EpisodeStatus::Completed, 1), "{}", task.name);
    }
}

#[tokio::test]
async fn a_recorded_run_replays_to_the_same_scores() {
    let guest = Served::guest(&[]).expect("guest starts");
    let tmp = tempfile::tempdir().unwrap();
    let cache = tmp.path().join("cache");
    let recorded = tmp.path().join("recorded");
    let first = run(stub_tasks(), &[&guest], &recorded, Shard::ALL, &cache).await;
    // The replay agent reads `traj.jsonl` from `<base>/<domain>/<task>/`.
    let source = layout(&recorded).base();
    let agents: AgentFactory =
        Arc::new(move || Ok(Box::new(ReplayAgent::new(ReplaySource::Dir(source.clone()))) as Box<dyn Agent>));
    let replayed = tmp.path().join("replayed");
    let runner = EpisodeRunner { layout: layout(&replayed), config: config(&cache), agents };
    let second = run_tasks(stub_tasks(), vec![client(&guest.url)], Arc::new(runner), &options(&replayed, Shard::ALL))
        .await
        .unwrap();
    assert_eq!(second.summary.outcomes(), first.summary.outcomes());
    assert_eq!(second.summary.overall.successes, 6);
}

#[tokio::test]
async fn a_pool_of_four_finishes_twenty_tasks_with_a_guest_killed_midway() {
    let mut guests: Vec<Option<Served>> = (0..4).map(|_| Some(Served::guest(&[]).expect("guest starts"))).collect();
    let urls: Vec<String> = guests.iter().flatten().map(|g| g.url.clone()).collect();
    let victim = guests[2].take().unwrap();
    let victim_url = victim.url.clone();
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().join("out");
    let runner = EpisodeRunner { layout: layout(&root), config: config(&tmp.path().join("cache")), agents: oracle() };
    let clients = urls.iter().map(|u| client(u)).collect();
    let opts = options(&root, Shard::ALL);
    // Kill the victim once a few tasks are finished, while most are still to do.
    let watch_root = root.clone();
    let killer = tokio::spawn(async move {
        loop {
            let finished = Summary::from_dir(&watch_root).map(|s| s.overall.tasks).unwrap_or(0);
            if finished >= 4 {
                drop(victim);
                return finished;
            }
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
    });
    let outcome = run_tasks(repeated(20), clients, Arc::new(runner), &opts).await.expect("run");
    let killed_after = killer.await.unwrap();
    assert!(killed_after < 20, "the guest was killed midway (after {killed_after} tasks)");
    assert_eq!(outcome.summary.overall.tasks, 20, "every task has a result: {:#?}", outcome.summary.tasks);
    assert_eq!(outcome.summary.overall.successes, 20, "{:#?}", outcome.summary.tasks);
    assert_eq!(outcome.pool.guests_down, std::slice::from_ref(&victim_url));
    assert!(outcome.pool.episodes > 20, "the killed guest's task ran again");
    let retried: Vec<_> = outcome.summary.tasks.iter().filter(|t| t.attempt > 1).collect();
    assert!(!retried.is_empty());
    assert!(retried.iter().all(|t| t.guest != victim_url), "retries ran on other guests");
    drop(guests);
}

#[tokio::test]
async fn resuming_skips_finished_tasks() {
    let guest = Served::guest(&[]).expect("guest starts");
    let tmp = tempfile::tempdir().unwrap();
    let cache = tmp.path().join("cache");
    let first = run(stub_tasks(), &[&guest], tmp.path(), Shard::ALL, &cache).await;
    assert_eq!((first.todo, first.skipped, first.pool.episodes), (6, 0, 6));
    // A crash that lost two tasks' results: only those run again.
    let tasks = stub_tasks();
    for task in &tasks[1..3] {
        std::fs::remove_file(layout(tmp.path()).task_dir(task).path().join(RESULT_FILE)).unwrap();
    }
    let second = run(stub_tasks(), &[&guest], tmp.path(), Shard::ALL, &cache).await;
    assert_eq!((second.todo, second.skipped, second.pool.episodes), (2, 4, 2));
    assert_eq!(second.summary.table(), first.summary.table());
    let third = run(stub_tasks(), &[&guest], tmp.path(), Shard::ALL, &cache).await;
    assert_eq!(third.pool.episodes, 0, "nothing left to do");
}

#[tokio::test]
async fn two_shards_merged_summarise_like_one_run() {
    let (g1, g2) = (Served::guest(&[]).expect("guest"), Served::guest(&[]).expect("guest"));
    let tmp = tempfile::tempdir().unwrap();
    let cache = tmp.path().join("cache");
    let (a, b, merged, whole) =
        (tmp.path().join("a"), tmp.path().join("b"), tmp.path().join("merged"), tmp.path().join("whole"));
    let (first, second) = ([&g1], [&g2]);
    let (sa, sb) = tokio::join!(
        run(stub_tasks(), &first, &a, "1/2".parse().unwrap(), &cache),
        run(stub_tasks(), &second, &b, "2/2".parse().unwrap(), &cache)
    );
    assert_eq!((sa.todo, sb.todo), (3, 3));
    let one = run(stub_tasks(), &[&g1, &g2], &whole, Shard::ALL, &cache).await;
    let report = merge(&merged, &[a, b], "merged").expect("merge");
    assert_eq!(report.copied, 6);
    assert!(report.duplicates.is_empty());
    assert_eq!(report.summary.table(), one.summary.table());
    assert_eq!(report.summary.outcomes(), one.summary.outcomes());
    // The FAIL-always floor survives the merge: one infeasible task of six.
    assert!(one.summary.overall.fail_floor.is_some_and(|f| (f - 100.0 / 6.0).abs() < 1e-9));
    assert_eq!(report.summary.overall.fail_floor, one.summary.overall.fail_floor);
    assert_eq!(Summary::from_dir(&merged).unwrap(), report.summary, "the written summary is the merged one");
}

#[tokio::test]
async fn the_report_opens_in_headless_chromium_and_shows_the_table() {
    let Some(browser) =
        arena_test_support::chromium_or_skip("the_report_opens_in_headless_chromium_and_shows_the_table")
    else {
        return;
    };
    let guest = Served::guest(&[]).expect("guest starts");
    let tmp = tempfile::tempdir().unwrap();
    let outcome = run(stub_tasks(), &[&guest], tmp.path(), Shard::ALL, &tmp.path().join("cache")).await;
    let url = format!("file://{}", outcome.report.display());
    let profile = tmp.path().join("profile");
    let base = |extra: &[&str]| {
        let mut cmd = std::process::Command::new(&browser);
        cmd.args(["--headless", "--no-sandbox", "--disable-gpu", "--allow-file-access-from-files"])
            .arg(format!("--user-data-dir={}", profile.display()))
            .args(extra)
            .arg(&url);
        cmd
    };
    // The DOM after the page ran: the table is there, with every domain and the total.
    let dom = base(&["--dump-dom"]).output().expect("chromium runs");
    assert!(dom.status.success(), "chromium failed: {}", String::from_utf8_lossy(&dom.stderr));
    let dom = String::from_utf8_lossy(&dom.stdout);
    assert!(dom.contains("<table id=\"summary\">"), "{dom}");
    for needle in ["file_explorer", "notepad", "settings", "Overall", "100.0%", "<svg"] {
        assert!(dom.contains(needle), "the rendered page lacks {needle}");
    }
    // A screenshot of the page: a real image that is not blank.
    let shot = tmp.path().join("report.png");
    let out = base(&[&format!("--screenshot={}", shot.display()), "--window-size=1280,1000"])
        .output()
        .expect("chromium runs");
    assert!(out.status.success(), "chromium failed: {}", String::from_utf8_lossy(&out.stderr));
    let png = std::fs::read(&shot).expect("chromium wrote the screenshot");
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
    let distinct: std::collections::HashSet<&[u8]> = png.chunks(64).collect();
    assert!(png.len() > 10_000 && distinct.len() > 100, "the screenshot looks blank ({} bytes)", png.len());
    // ARENA_KEEP_REPORT_SHOT=FILE keeps the screenshot for a human to look at.
    if let Some(keep) = std::env::var_os("ARENA_KEEP_REPORT_SHOT") {
        std::fs::copy(&shot, &keep).expect("copying the screenshot");
        let _ = writeln!(
            std::io::stderr(),
            "report screenshot kept at {} ({} bytes)",
            PathBuf::from(keep).display(),
            png.len()
        );
    }
}

/// `arena run` as a user types it.
fn arena(args: &[&str]) -> std::process::Output {
    let exe = arena_test_support::workspace_binary("arena-host", "arena").expect("the arena binary");
    std::process::Command::new(exe).args(args).output().expect("arena runs")
}

#[test]
fn a_navi_run_that_is_no_preset_says_how_it_differs_from_upstream_and_the_report_carries_it() {
    let dir = tempfile::tempdir().expect("dir");
    let tasks = dir.path().join("tasks/notepad");
    std::fs::create_dir_all(&tasks).expect("tasks");
    std::fs::write(
        tasks.join("t.json"),
        r#"{"id": "t", "instruction": "do it", "config": [], "evaluator": {"func": "infeasible"}}"#,
    )
    .expect("task");
    let out = dir.path().join("out");
    let (tasks, out_arg) = (dir.path().join("tasks"), out.to_str().expect("utf-8").to_owned());
    // Nothing listens on port 9: the model stays down and the task is left unfinished.
    let run = arena(&[
        "run",
        "--agent",
        "navi",
        "--llm-url",
        "http://127.0.0.1:9/v1",
        "--model",
        "m",
        "--llm-retry",
        "0",
        // Nothing listens there: the run goes on, each task the model's failure.
        "--llm-unreachable",
        "wait",
        "--stub-guests",
        "1",
        "--max-steps",
        "1",
        "--tasks",
        tasks.to_str().expect("utf-8"),
        "--out",
        &out_arg,
    ]);
    let stdout = String::from_utf8_lossy(&run.stdout);
    let first = stdout.lines().next().unwrap_or_default();
    assert!(
        first.starts_with("not a reproduction: differs from upstream's default Navi run in som_origin=a11y (upstream: oss); prompt=ours"),
        "{stdout}\n{}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(first.contains("max_steps=1 (upstream: 15)") && first.contains("pauses=fast"), "{first}");
    let summary = Summary::from_dir(&out).expect("summary");
    let recorded = summary.options.get("differs_from_upstream").expect("recorded in the results");
    assert_eq!(format!("not a reproduction: differs from upstream's default Navi run in {}", recorded[0]), first);
    let report = std::fs::read_to_string(out.join("summary.md")).expect("summary.md");
    assert!(report.contains("differs_from_upstream=som_origin=a11y"), "{report}");
    assert!(summary.tasks.iter().all(|t| t.failed_by == "environment" && t.blame == "model"), "{:?}", summary.tasks);

    // A preset without the checkout's prompts is refused before anything runs.
    let preset = arena(&[
        "run",
        "--agent",
        "navi",
        "--llm-url",
        "http://127.0.0.1:9/v1",
        "--model",
        "m",
        "--preset",
        "paper-a11y-uia",
        "--tasks",
        tasks.to_str().expect("utf-8"),
        "--out",
        &out_arg,
    ]);
    assert!(!preset.status.success());
    let stderr = String::from_utf8_lossy(&preset.stderr);
    assert!(stderr.contains("--preset paper-a11y-uia") && stderr.contains("--waa-root"), "{stderr}");
}
