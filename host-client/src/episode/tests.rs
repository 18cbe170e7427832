//! The episode loop's tests on an in-process stub guest: pauses where upstream
//! pauses, step logs and their budgets, held keys released, deadlines, retries,
//! and which failures leave a task unfinished.

use std::collections::VecDeque;
use std::path::PathBuf;

use super::*;
use crate::driver::stub::{start, RunningStub, StubArgs};
use arena_client::client::ClientConfig;
use arena_results::RESULT_FILE;

/// Answers from a script of results; a `None` entry stops the guest first.
struct Fake {
    script: VecDeque<Option<Result<Prediction, AgentError>>>,
    stub: Option<RunningStub>,
}

fn says(actions: Vec<AgentAction>) -> Option<Result<Prediction, AgentError>> {
    Some(Ok(Prediction { response: "ok".into(), actions, ..Prediction::default() }))
}

fn model_down() -> Option<Result<Prediction, AgentError>> {
    Some(Err(AgentError::Model { endpoint: "http://model".into(), reason: "503".into() }))
}

#[async_trait::async_trait]
impl Agent for Fake {
    fn name(&self) -> &str {
        "fake"
    }

    async fn reset(&mut self, _task: &Task) {}

    async fn predict(&mut self, _obs: &Observation) -> Result<Prediction, AgentError> {
        match self.script.pop_front() {
            Some(Some(answer)) => answer,
            Some(None) => {
                if let Some(stub) = self.stub.take() {
                    stub.stop().await.expect("the stub stops");
                }
                Ok(Prediction {
                    response: "typing".into(),
                    actions: vec![AgentAction::Pyautogui("pyautogui.write('x')".into())],
                    ..Prediction::default()
                })
            }
            None => Err(AgentError::Exhausted("script".into())),
        }
    }
}

fn task(func: &str) -> Task {
    let evaluator = if func == "infeasible" {
        r#"{"func": "infeasible"}"#.to_owned()
    } else {
        r#"{"func": "exact_match", "result": {"type": "vm_active_window_title"}, "expected": {"type": "rule", "rules": {"expected": "Untitled - Notepad"}}}"#.to_owned()
    };
    let text = format!(
        r#"{{"id": "t", "instruction": "do it", "config": [{{"type": "launch", "parameters": {{"command": "notepad"}}}}], "evaluator": {evaluator}}}"#
    );
    Task::parse(&text, &PathBuf::from("/tasks/notepad/t.json")).unwrap()
}

/// A fake clock: records each pause and returns at once.
#[derive(Debug, Default)]
struct Recorded(std::sync::Mutex<Vec<(Duration, &'static str)>>);

#[async_trait::async_trait]
impl arena_setup::Clock for Recorded {
    async fn sleep(&self, d: Duration, why: &'static str) {
        self.0.lock().unwrap().push((d, why));
    }
}

#[tokio::test]
async fn pauses_fall_where_upstreams_fall() {
    let clock = Arc::new(Recorded::default());
    let script = vec![
        says(vec![AgentAction::Wait]),
        says(vec![AgentAction::Pyautogui("pyautogui.write('x')".into()), AgentAction::Done]),
    ];
    let upstream = |cache| EpisodeConfig {
        settle: Settle::none(),
        exec: ExecOptions::instant(),
        clock: clock.clone(),
        ..EpisodeConfig::upstream(cache)
    };
    let (result, out, _tmp) = play_with(&task("exact_match"), script, false, upstream, None).await;
    assert_eq!(result.status, EpisodeStatus::Completed, "{result:?}");
    let s = Duration::from_secs;
    assert_eq!(
        *clock.0.lock().unwrap(),
        vec![
            (s(5), "after closing the windows"),
            (s(5), "after the setup"),
            (s(6), "for WAIT"),
            (s(3), "after an action"),
            (s(3), "after DONE or FAIL"),
        ]
    );
    let traj = out.read_trajectory().unwrap();
    assert_eq!(traj.iter().map(|t| t.timings.pause_ms).collect::<Vec<_>>(), [6000, 6000]);
    // Upstream observes after every action, DONE included: the step with two
    // actions has two lines, each naming the screenshot taken after it.
    assert_eq!(traj[1].more.len(), 0, "further lines are upstream's only, not read back");
    let text = std::fs::read_to_string(out.path().join(arena_results::TRAJ_FILE)).unwrap();
    let lines: Vec<Value> = text.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    let actions: Vec<(u64, Value, bool)> = lines
        .iter()
        .map(|l| (l["step_num"].as_u64().unwrap(), l["action"].clone(), l["done"].as_bool().unwrap_or(false)))
        .collect();
    assert_eq!(
        actions,
        vec![
            (0, Value::Null, false),
            (1, "WAIT".into(), false),
            (2, "pyautogui.write('x')".into(), false),
            (2, "DONE".into(), true),
        ]
    );
    assert_eq!(lines[3]["info"], serde_json::json!({"done": true}));
    for line in &lines {
        let shot = line["screenshot"].as_str().unwrap();
        assert!(out.path().join(shot).is_file(), "{shot}");
    }
    assert!(lines[3]["screenshot"].as_str().unwrap().starts_with("screenshot-step_1_"));
    // Each observation's tree is kept in upstream's XML, as its recorder keeps it.
    for line in &lines {
        let tree = line["accessibility_tree"].as_str().unwrap();
        assert!(tree.starts_with("accessibility_tree-step_"), "{tree}");
        let xml = std::fs::read_to_string(out.path().join(tree)).unwrap();
        assert!(xml.starts_with('<') && xml.contains("Notepad"), "{xml}");
    }
    assert_eq!(traj[1].screenshot_file, lines[1]["screenshot"].as_str().unwrap(), "what the agent saw at step 2");
    assert_eq!(result.options.get("pauses").map(String::as_str), Some("upstream"));
    assert_eq!(out.read_episode().unwrap().options, result.options);
}

async fn play(
    task: &Task,
    script: Vec<Option<Result<Prediction, AgentError>>>,
    stop_guest: bool,
) -> (EpisodeResult, TaskDir, tempfile::TempDir) {
    let instant = |cache| EpisodeConfig { max_steps: 4, ..EpisodeConfig::instant(cache) };
    play_with(task, script, stop_guest, instant, None).await
}

/// [`play`] with the configuration `configure` makes from the download cache,
/// into the task folder `out` (default: `out` in the answered temporary folder).
async fn play_with(
    task: &Task,
    script: Vec<Option<Result<Prediction, AgentError>>>,
    stop_guest: bool,
    configure: impl FnOnce(DownloadCache) -> EpisodeConfig,
    out: Option<TaskDir>,
) -> (EpisodeResult, TaskDir, tempfile::TempDir) {
    let stub = start(&StubArgs::default(), None).await.unwrap();
    let client =
        GuestClient::new(&stub.url(), ClientConfig { token: None, timeout: Duration::from_secs(5), retries: 1 })
            .unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let config = configure(DownloadCache::new(tmp.path().join("cache")).unwrap());
    let mut agent = Fake { script: script.into(), stub: None };
    let keep = if stop_guest {
        agent.stub = Some(stub);
        None
    } else {
        Some(stub)
    };
    let out = out.unwrap_or_else(|| TaskDir::new(tmp.path().join("out")));
    let result = run_episode(&client, task, &mut agent, &config, &out).await;
    if let Some(stub) = keep {
        stub.stop().await.unwrap();
    }
    (result, out, tmp)
}

#[tokio::test]
async fn an_agents_step_logs_are_written_beside_the_trajectory_as_upstream_names_them() {
    let logs = vec![
        StepLog { key: "user_question".into(), value: LogValue::Text("what to do".into()) },
        StepLog { key: "foreground_window_prompt".into(), value: LogValue::Png(b"png".to_vec()) },
        StepLog { key: "entity_list".into(), value: LogValue::Json(serde_json::json!([{"id": 1}])) },
        StepLog { key: "a11y_truncated".into(), value: LogValue::Inline(Value::Bool(false)) },
    ];
    let done = Prediction { response: "ok".into(), actions: vec![AgentAction::Done], logs, ..Prediction::default() };
    let (result, out, _tmp) = play(&task("exact_match"), vec![Some(Ok(done))], false).await;
    assert_eq!(result.status, EpisodeStatus::Completed);
    let text = std::fs::read_to_string(out.path().join(arena_results::TRAJ_FILE)).unwrap();
    let line: Value = serde_json::from_str(text.lines().nth(1).unwrap()).unwrap();
    let ts = line["action_timestamp"].as_str().unwrap();
    assert_eq!(line["user_question"], format!("user_question-step_0_{ts}.txt"));
    assert_eq!(
        std::fs::read_to_string(out.path().join(format!("user_question-step_0_{ts}.txt"))).unwrap(),
        "what to do"
    );
    assert_eq!(std::fs::read(out.path().join(format!("foreground_window_prompt-step_0_{ts}.png"))).unwrap(), b"png");
    let list: Value =
        serde_json::from_slice(&std::fs::read(out.path().join(format!("entity_list-step_0_{ts}.json"))).unwrap())
            .unwrap();
    assert_eq!(list, serde_json::json!([{"id": 1}]));
    assert_eq!(line["a11y_truncated"], Value::Bool(false));
    assert_eq!(out.read_trajectory().unwrap().len(), 1, "the logs do not disturb reading the steps back");
}

#[test]
fn a_huge_text_or_json_log_is_written_within_its_file_limit() {
    use arena_results::MAX_LOG_FILE;
    let tmp = tempfile::tempdir().unwrap();
    let out = TaskDir::new(tmp.path().to_path_buf());
    let huge = "é".repeat(5 << 20); // 10 MiB
    let logs = [
        StepLog { key: "plan_result".into(), value: LogValue::Text(huge.clone()) },
        StepLog { key: "response".into(), value: LogValue::Json(serde_json::json!({"output": [huge, "b"]})) },
        StepLog { key: "small".into(), value: LogValue::Json(serde_json::json!({"output": "fine"})) },
    ];
    let files: Vec<String> = logs
        .iter()
        .map(|log| write_log(&out, 1, "t", log).unwrap().as_str().expect("a file name").to_owned())
        .collect();
    let read = |name: &str| std::fs::read_to_string(tmp.path().join(name)).unwrap();
    let text = read(&files[0]);
    assert!(text.len() <= MAX_LOG_FILE + 100 && text.ends_with("more bytes not recorded]"), "{}", text.len());
    let json: Value = serde_json::from_str(&read(&files[1])).expect("still JSON");
    assert!(json[NOT_RECORDED].as_str().is_some_and(|n| n.contains("1 items left out")), "{}", json[NOT_RECORDED]);
    assert!(json["kept"]["output"][0].as_str().is_some_and(|s| s.len() <= MAX_LOG_FILE + 100));
    assert!(read(&files[1]).len() <= MAX_LOG_FILE + 1000);
    // Under the limit a log is written as it was.
    assert_eq!(serde_json::from_str::<Value>(&read(&files[2])).unwrap(), serde_json::json!({"output": "fine"}));
}

/// A hostile agent's answer near the line limit: the step runs, and its record
/// keeps a bounded share of the response, the actions and the record fields.
#[tokio::test]
async fn a_huge_answer_is_recorded_within_the_steps_budget() {
    let big = "x".repeat(8 << 20);
    let mut actions: Vec<AgentAction> =
        (0..300).map(|i| AgentAction::Pyautogui(format!("# {i} {}", &big[..100_000]).into())).collect();
    actions.push(AgentAction::Typed(vec![Action::TypeText { text: big.clone(), interval_ms: None }]));
    actions.push(AgentAction::Done);
    let logs = (0..1000)
        .map(|i| StepLog { key: format!("field{i}"), value: LogValue::Inline(Value::String(big[..50_000].into())) })
        .collect();
    let answer = Prediction { response: big.clone(), actions, logs, ..Prediction::default() };
    let (result, out, _tmp) = play(&task("exact_match"), vec![Some(Ok(answer))], false).await;
    assert_eq!(result.status, EpisodeStatus::Completed, "{result:?}");
    let text = std::fs::read_to_string(out.path().join(arena_results::TRAJ_FILE)).unwrap();
    assert!(text.len() < 4 * arena_results::STEP_BUDGET, "{} bytes of trajectory", text.len());
    let lines: Vec<Value> = text.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    let step = &lines[1];
    let response = step["response"].as_str().unwrap();
    assert!(response.starts_with("xxx") && response.ends_with("more bytes not recorded]"), "{}", response.len());
    assert!(step["not_recorded"].as_str().is_some_and(|n| n.contains("items left out")), "{}", step["not_recorded"]);
    assert!(step["actions"].as_array().unwrap().len() < 302, "actions past the budget are left out");
    // Every action ran: 302 upstream lines, the ones past the budget marked so.
    assert_eq!(lines.len(), 1 + 302);
    assert_eq!(lines.last().unwrap()["action"], "[not recorded]");
    assert_eq!(out.read_trajectory().unwrap().len(), 1);
}

#[tokio::test]
async fn the_trajectory_shows_the_clipboard_the_agents_computer_tracks() {
    let copy = AgentAction::Computer("computer.clipboard.copy_text(\"tracked words\")".into());
    let script = vec![says(vec![copy, AgentAction::Done])];
    let (result, out, _tmp) = play(&task("exact_match"), script, false).await;
    assert_eq!(result.status, EpisodeStatus::Completed, "{result:?}");
    let text = std::fs::read_to_string(out.path().join(arena_results::TRAJ_FILE)).unwrap();
    let lines: Vec<Value> = text.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    // Upstream's computer_clipboard is Navi's own copy: empty at the reset, then what the code copied.
    let clipboards: Vec<&str> = lines.iter().map(|l| l["computer_clipboard"].as_str().unwrap()).collect();
    assert_eq!(clipboards, ["", "tracked words", "tracked words"]);
}

#[tokio::test]
async fn keys_the_agent_left_held_are_released_after_the_evaluation() {
    let hold = AgentAction::Typed(vec![Action::KeyDown { key: "shift".into() }]);
    let code = AgentAction::Pyautogui("pyautogui.keyDown('ctrl')".into());
    let script = vec![says(vec![hold]), says(vec![code]), says(vec![AgentAction::Done])];
    let (result, _out, _tmp) = play(&task("exact_match"), script, false).await;
    assert_eq!(result.status, EpisodeStatus::Completed, "{result:?}");
    let teardown: Vec<&Value> = result.setup.iter().filter(|r| r["phase"] == "teardown").collect();
    assert_eq!(teardown.len(), 1, "{:?}", result.setup);
    assert_eq!(teardown[0]["kind"], "release_held_keys");
    assert_eq!(teardown[0]["ok"], true);
    assert_eq!(teardown[0]["detail"], "released shift, ctrl");
    // Nothing to release, nothing reported.
    let (result, _out, _tmp) = play(&task("exact_match"), vec![says(vec![AgentAction::Done])], false).await;
    assert!(result.setup.iter().all(|r| r["phase"] != "teardown"), "{:?}", result.setup);
}

/// A clock that really pauses (on tokio's timer).
#[derive(Debug)]
struct Pausing;

#[async_trait::async_trait]
impl arena_setup::Clock for Pausing {
    async fn sleep(&self, d: Duration, _why: &'static str) {
        tokio::time::sleep(d).await;
    }
}

#[tokio::test]
async fn a_steps_actions_share_its_deadline_and_those_not_begun_in_time_are_not_run() {
    // 50 actions with 100 ms after each would take 5 s; the step has 300 ms.
    let script = vec![says(vec![AgentAction::Pyautogui("pyautogui.press('a')".into()); 50])];
    let configure = |cache| EpisodeConfig {
        max_steps: 1,
        step_timeout: Duration::from_millis(300),
        sleep_after_action: Duration::from_millis(100),
        clock: Arc::new(Pausing),
        ..EpisodeConfig::instant(cache)
    };
    let (_, out, _tmp) = play_with(&task("exact_match"), script, false, configure, None).await;
    let text = std::fs::read_to_string(out.path().join(arena_results::TRAJ_FILE)).unwrap();
    let ran = text.lines().filter(|l| serde_json::from_str::<Value>(l).unwrap()["step_num"] == 1).count();
    assert!((1..50).contains(&ran), "{ran} of the 50 actions ran");
    let traj = out.read_trajectory().unwrap();
    let said = format!("actions {} to 50 not run: the step's 0.3 s were up", ran + 1);
    let timeouts = &traj[0].timings.timeouts;
    assert_eq!(timeouts.last(), Some(&said), "{timeouts:?}");
    // On a loaded machine the action running when the time ran out may be cut too.
    let cut = format!("action {ran}: the action outlasted the step's 0.3 s");
    assert!(timeouts[..timeouts.len() - 1].iter().all(|t| *t == cut), "{timeouts:?}");
}

#[tokio::test]
async fn model_failures_are_retried_within_the_step() {
    let (result, out, _tmp) =
        play(&task("exact_match"), vec![model_down(), model_down(), says(vec![AgentAction::Done])], false).await;
    assert_eq!((result.status.clone(), result.steps, result.score), (EpisodeStatus::Completed, 1, 1.0), "{result:?}");
    assert_eq!(result.last_action, "done");
    assert_eq!(std::fs::read_to_string(out.path().join(RESULT_FILE)).unwrap(), "1.0\n");
    // The retries are in the step's line of traj.jsonl.
    let text = std::fs::read_to_string(out.path().join(arena_results::TRAJ_FILE)).unwrap();
    let line: Value = serde_json::from_str(text.lines().nth(1).unwrap()).unwrap();
    assert_eq!(line["timings"]["predict_retries"], 2, "{line}");
}

#[tokio::test]
async fn every_step_line_times_each_part_of_the_observation_and_the_prediction() {
    let (result, out, _tmp) = play(&task("exact_match"), vec![says(vec![AgentAction::Done])], false).await;
    assert_eq!(result.status, EpisodeStatus::Completed, "{result:?}");
    let text = std::fs::read_to_string(out.path().join(arena_results::TRAJ_FILE)).unwrap();
    let line: Value = serde_json::from_str(text.lines().nth(1).unwrap()).unwrap();
    let timings = &line["timings"];
    for part in ["screenshot_ms", "decode_ms", "tree_ms", "windows_ms", "clipboard_ms", "total_ms"] {
        assert!(timings["observe"][part].is_u64(), "{part} missing: {timings}");
    }
    for part in ["observe_ms", "predict_ms", "act_ms", "pause_ms"] {
        assert!(timings[part].is_u64(), "{part} missing: {timings}");
    }
    assert!(timings["observe"].get("dom_ms").is_none(), "no DOM read for an agent that wants none");
    assert_eq!(timings["observe_ms"], timings["observe"]["total_ms"]);
    // The fake agent has no model: its parts are absent, not zero.
    assert_eq!(timings["predict"], serde_json::json!({}));
    // The episode's record copies them.
    assert_eq!(serde_json::to_value(&result.timings[0]).unwrap(), *timings);
}

#[tokio::test]
async fn the_report_tells_environment_failures_from_the_agents() {
    use arena_results::summary::Summary;
    let root = tempfile::tempdir().unwrap();
    let named = |name: &str| {
        let text = r#"{"id": "t", "instruction": "do it", "config": [{"type": "launch", "parameters": {"command": "notepad"}}],
            "evaluator": {"func": "exact_match", "result": {"type": "vm_active_window_title"}, "expected": {"type": "rule", "rules": {"expected": "Untitled - Notepad"}}}}"#;
        Task::parse(text, &PathBuf::from(format!("/tasks/notepad/{name}.json"))).unwrap()
    };
    let at = |name: &str| Some(TaskDir::new(root.path().join("navi/a11y_tree/m/0/notepad").join(name)));
    let instant = |cache| EpisodeConfig { max_steps: 4, ..EpisodeConfig::instant(cache) };
    // A guest that dies mid-run.
    let script = vec![says(vec![AgentAction::Wait]), None];
    let (dies, _, _t1) = play_with(&named("guest-dies"), script, true, instant, at("guest-dies")).await;
    // A model endpoint that stays down.
    let (down, _, _t2) = play_with(
        &named("model-down"),
        vec![model_down(), model_down(), model_down()],
        false,
        instant,
        at("model-down"),
    )
    .await;
    // An agent that gives up on a feasible task.
    let (gives_up, _, _t3) =
        play_with(&named("gives-up"), vec![says(vec![AgentAction::Fail])], false, instant, at("gives-up")).await;
    // And one that solves it.
    let (solves, _, _t4) =
        play_with(&named("solves"), vec![says(vec![AgentAction::Done])], false, instant, at("solves")).await;
    let blames: Vec<&str> = [&dies, &down, &gives_up, &solves].iter().map(|r| r.blame().name()).collect();
    assert_eq!(blames, ["guest", "model", "agent", "passed"]);

    let summary = Summary::from_dir(root.path()).unwrap();
    let by_name = |n: &str| summary.tasks.iter().find(|t| t.name == n).unwrap();
    assert_eq!(
        (by_name("guest-dies").failed_by.as_str(), by_name("guest-dies").blame.as_str()),
        ("environment", "guest")
    );
    assert_eq!(
        (by_name("model-down").failed_by.as_str(), by_name("model-down").blame.as_str()),
        ("environment", "model")
    );
    assert_eq!(by_name("gives-up").failed_by, "agent");
    assert_eq!(by_name("solves").failed_by, "passed");
    assert_eq!(summary.failures(), (1, 2));
    let md = summary.markdown();
    assert!(md.contains("Failures: 1 the agent's, 2 the environment's (guest 1, model 1)."), "{md}");
    assert!(md.contains("| environment (guest) |") && md.contains("| environment (model) |"), "{md}");
    assert!(md.contains("| notepad | gives-up | 0.0 | completed | agent |"), "{md}");
}

#[tokio::test]
async fn a_model_that_stays_down_leaves_the_task_unfinished() {
    let (result, out, _tmp) = play(&task("exact_match"), vec![model_down(), model_down(), model_down()], false).await;
    assert!(matches!(&result.status, EpisodeStatus::ModelError(m) if m.contains("503")), "{:?}", result.status);
    // Upstream's predict raises: no result.txt, so the next run plays the task again.
    assert!(!out.is_finished());
    assert!(!out.path().join(RESULT_FILE).exists());
    assert_eq!(out.read_episode().unwrap().status, result.status);
    let traj = out.read_trajectory().unwrap();
    assert_eq!(traj.len(), 1);
    assert!(traj[0].ended && traj[0].error.as_deref().unwrap_or("").contains("503"));
}

#[tokio::test]
async fn a_broken_expected_side_leaves_the_task_unfinished_as_an_evaluator_error() {
    // The expected getter reads a guest file that does not exist (`None`), which
    // is no rules dict: the task's gold is broken, not the agent's answer.
    let text = r#"{"id": "t", "instruction": "do it", "evaluator": {"func": "exact_match",
        "result": {"type": "rule", "rules": "x"},
        "expected": {"type": "vm_file", "path": "C:\\nope\\gold.txt", "dest": "gold.txt"}}}"#;
    let task = Task::parse(text, &PathBuf::from("/tasks/notepad/t.json")).unwrap();
    let (result, out, _tmp) = play(&task, vec![says(vec![AgentAction::Done])], false).await;
    assert!(
        matches!(&result.status, EpisodeStatus::EvaluatorError(m) if m.contains("exact_match") && m.contains("the task's evaluator")),
        "{:?}",
        result.status
    );
    assert_eq!(result.status.kind(), "evaluator_error");
    assert_eq!(result.blame(), arena_results::Blame::Evaluator);
    assert!(!out.is_finished(), "no result.txt for an evaluation the task's own parts broke");
    assert_eq!(out.read_episode().unwrap().status, result.status);
}

/// Plays `task` on a fresh stub guest that first holds `files` (guest path, bytes).
async fn play_on_stub_holding(task: &Task, files: &[(&str, &[u8])]) -> (EpisodeResult, TaskDir, tempfile::TempDir) {
    let stub = start(&StubArgs::default(), None).await.unwrap();
    let client =
        GuestClient::new(&stub.url(), ClientConfig { token: None, timeout: Duration::from_secs(5), retries: 1 })
            .unwrap();
    for (path, bytes) in files {
        client.push_file(path, bytes.to_vec(), None).await.unwrap();
    }
    let tmp = tempfile::tempdir().unwrap();
    let config =
        EpisodeConfig { max_steps: 2, ..EpisodeConfig::instant(DownloadCache::new(tmp.path().join("cache")).unwrap()) };
    let mut agent = Fake { script: vec![says(vec![AgentAction::Done])].into(), stub: None };
    let out = TaskDir::new(tmp.path().join("out"));
    let result = run_episode(&client, task, &mut agent, &config, &out).await;
    stub.stop().await.unwrap();
    (result, out, tmp)
}

#[tokio::test]
async fn a_settings_file_the_agent_left_as_a_list_scores_zero_for_the_agent() {
    // Issue 43: `[]` in the settings.json `check_json_settings` grades used to be
    // `eval_error` (unfinished, "Failed by: environment"); it is the agent's 0.
    let text = r#"{"id": "t", "instruction": "set the font size", "evaluator": {"func": "check_json_settings",
        "result": {"type": "vm_file", "path": "C:\\Users\\Docker\\settings.json", "dest": "settings.json"},
        "expected": {"type": "rule", "rules": {"expected": {"editor.fontSize": 14}}}}}"#;
    let task = Task::parse(text, &PathBuf::from("/tasks/vs_code/t.json")).unwrap();
    let settings = r"C:\Users\Docker\settings.json";
    let (result, out, _tmp) = play_on_stub_holding(&task, &[(settings, b"[]")]).await;
    assert_eq!(result.status, EpisodeStatus::Completed, "{:?}", result.eval);
    assert_eq!(result.score, 0.0);
    assert_eq!(result.blame(), arena_results::Blame::Agent);
    assert!(out.is_finished(), "the agent's 0 is a result: it counts in the rate and is not replayed");
    let metric = &result.eval["metrics"][0];
    assert_eq!(metric["fault"], "agent", "{metric}");
    assert!(metric["error"].as_str().unwrap_or("").contains("not a settings object"), "{metric}");
    // The same task with the settings the agent should have written passes: the 0 was the list's.
    let good = br#"{"editor.fontSize": 14, "files.autoSave": "off"}"#;
    let (result, _out, _tmp) = play_on_stub_holding(&task, &[(settings, good)]).await;
    assert_eq!((result.status.clone(), result.score), (EpisodeStatus::Completed, 1.0), "{:?}", result.eval);
}

#[tokio::test]
async fn a_chrome_task_on_the_stub_is_an_evaluator_error_not_the_agents_zero() {
    // Issue 43: upstream's Chrome tasks on the stub read the tabs over the debugging
    // port, where no browser listens; that is the harness's, never the agent's 0.
    let text = r#"{"id": "t", "instruction": "open two tabs", "evaluator": {"func": "is_expected_tabs",
        "result": {"type": "open_tabs_info"},
        "expected": {"type": "rule", "rules": {"type": "url", "urls": ["https://example.org/"]}}}}"#;
    let task = Task::parse(text, &PathBuf::from("/tasks/chrome/t.json")).unwrap();
    let (result, out, _tmp) = play_on_stub_holding(&task, &[]).await;
    let EpisodeStatus::EvaluatorError(reason) = &result.status else {
        panic!("{:?}: {:?}", result.status, result.eval)
    };
    assert!(reason.contains("no browser is listening on the debugging port"), "{reason}");
    assert!(reason.contains("is_expected_tabs") && reason.contains("result getter"), "{reason}");
    assert_eq!(result.blame(), arena_results::Blame::Evaluator);
    assert_eq!(result.blame().side(), "environment");
    assert!(!out.is_finished());
    assert_eq!(result.eval["metrics"][0]["fault"], "harness");
}

#[tokio::test]
async fn malformed_output_spends_a_step_and_the_cap_ends_the_loop() {
    let malformed = Some(Ok(Prediction {
        response: "no code here".into(),
        actions: vec![],
        marks: None,
        raw_error: Some("no code block".into()),
        logs: Vec::new(),
        timings: Default::default(),
        coords: None,
        usage: None,
    }));
    let script =
        vec![malformed, says(vec![AgentAction::Wait]), says(vec![AgentAction::Wait]), says(vec![AgentAction::Wait])];
    let (result, out, _tmp) = play(&task("infeasible"), script, false).await;
    assert_eq!(
        (result.status.clone(), result.steps, result.last_action.as_str()),
        (EpisodeStatus::Completed, 4, "wait")
    );
    assert_eq!(result.score, 0.0, "an infeasible task not answered with FAIL");
    let traj = out.read_trajectory().unwrap();
    assert_eq!(traj.len(), 4);
    assert_eq!(traj[0].error.as_deref(), Some("no code block"));
    assert!(traj[3].ended && !traj[2].ended);
    for (i, step) in traj.iter().enumerate() {
        assert_eq!(step.step, i as u32 + 1);
        assert!(out.path().join(&step.screenshot_file).is_file());
    }
    assert_eq!(result.timings.len(), 4);
}

#[tokio::test]
async fn fail_scores_an_infeasible_task() {
    let (result, out, _tmp) = play(&task("infeasible"), vec![says(vec![AgentAction::Fail])], false).await;
    assert_eq!((result.score, result.last_action.as_str(), result.steps), (1.0, "fail", 1));
    // Upstream's `evaluate` returns the int 1 here, so result.txt holds "1".
    assert_eq!(std::fs::read_to_string(out.path().join(RESULT_FILE)).unwrap(), "1\n");
}

#[tokio::test]
async fn a_guest_that_dies_mid_episode_is_an_infrastructure_error_without_a_result() {
    let (result, out, _tmp) = play(&task("exact_match"), vec![says(vec![AgentAction::Wait]), None], true).await;
    assert!(
        matches!(&result.status, EpisodeStatus::InfraError(m) if m.contains("stopped answering")),
        "{:?}",
        result.status
    );
    assert!(!out.is_finished(), "no result.txt: the run will try again");
    assert_eq!(out.read_episode().unwrap().status, result.status);
    assert_eq!(out.read_trajectory().unwrap().len(), 2, "the steps before the failure are kept");
}
