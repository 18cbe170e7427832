//! The computer-use agents against local mocks of their vendors' APIs (real
//! HTTP servers on 127.0.0.1:0): a Messages API, a Responses API and an
//! OpenAI-compatible chat endpoint serving a UI-TARS reply script. Each mock
//! records every request; the tests check the requests' shapes (headers, tool
//! definitions, image blocks, ids and chaining) and each agent solves stub
//! tasks end to end on an in-process stub guest. Malformed replies, refusals,
//! 429 with `Retry-After`, an endpoint that stays down and safety checks are tested.

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use axum::extract::State;
use axum::http::{HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::routing::post;
use axum::{Json, Router};
use base64::Engine as _;
use serde_json::{json, Value};
use tokio::net::TcpListener;

use arena_actionspace::uitars::UiTarsVersion;
use arena_agents::cu::anthropic::{AnthropicAgent, AnthropicConfig};
use arena_agents::cu::models::Form;
use arena_agents::cu::openai::{OpenAiAgent, OpenAiConfig, SafetyChecks};
use arena_agents::cu::uitars::{UiTarsAgent, UiTarsConfig};
use arena_agents::llm::RetryPolicy;
use arena_agents::observation::Observation;
use arena_agents::{Agent, AgentError};
use arena_client::cache::DownloadCache;
use arena_client::client::{ClientConfig, GuestClient};
use arena_exec::AgentAction;
use arena_host::episode::{run_episode, EpisodeConfig};
use arena_host::run::load_tasks;
use arena_results::{EpisodeResult, EpisodeStatus, RunLayout};
use arena_shared::action::{Action, MouseButton};
use arena_shared::geometry::Point;
use arena_task::{Difficulty, Task};
use arena_test_support::StubGuest;

const KEY: &str = "test-key";

/// One scripted answer: status, extra headers, body.
type Reply = (u16, Vec<(&'static str, &'static str)>, Value);

#[derive(Default)]
struct Script {
    replies: VecDeque<Reply>,
    requests: Vec<(HeaderMap, Value)>,
}

#[derive(Clone, Default)]
struct Mock(Arc<Mutex<Script>>);

impl Mock {
    fn new(replies: Vec<Reply>) -> Mock {
        Mock(Arc::new(Mutex::new(Script { replies: replies.into(), requests: Vec::new() })))
    }

    fn requests(&self) -> Vec<(HeaderMap, Value)> {
        self.0.lock().unwrap().requests.clone()
    }

    fn left(&self) -> usize {
        self.0.lock().unwrap().replies.len()
    }
}

async fn answer(State(mock): State<Mock>, headers: HeaderMap, Json(body): Json<Value>) -> Response {
    let mut script = mock.0.lock().unwrap();
    script.requests.push((headers, body));
    match script.replies.pop_front() {
        Some((status, extra, body)) => {
            let mut response = (StatusCode::from_u16(status).unwrap(), Json(body)).into_response();
            for (name, value) in extra {
                response.headers_mut().insert(name, value.parse().unwrap());
            }
            response
        }
        None => (StatusCode::INTERNAL_SERVER_ERROR, "the mock's script is used up").into_response(),
    }
}

/// Serves `mock` at `route` on 127.0.0.1:0 and answers the base URL.
async fn serve(mock: Mock, route: &str, base_path: &str) -> String {
    let app = Router::new().route(route, post(answer)).with_state(mock);
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    tokio::spawn(async move { axum::serve(listener, app).await.unwrap() });
    format!("http://{addr}{base_path}")
}

fn ok(body: Value) -> Reply {
    (200, Vec::new(), body)
}

fn quick_retry() -> RetryPolicy {
    RetryPolicy {
        initial_delay: Duration::from_millis(10),
        max_delay: Duration::from_millis(50),
        give_up_after: Duration::from_secs(3),
    }
}

fn stub_tasks() -> Vec<Task> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tasks/stub");
    load_tasks(&dir, Difficulty::Normal).expect("the stub tasks load")
}

fn stub_task(name: &str) -> Task {
    stub_tasks().into_iter().find(|t| t.name == name).unwrap_or_else(|| panic!("no stub task {name}"))
}

fn client(url: &str) -> GuestClient {
    GuestClient::new(url, ClientConfig { token: None, timeout: Duration::from_secs(20), retries: 1 }).expect("client")
}

/// Runs one episode of `task` with `agent` on a fresh stub guest; answers the
/// result and the task's result folder.
async fn episode(task: &Task, agent: &mut dyn Agent, root: &Path) -> (EpisodeResult, PathBuf) {
    let guest = StubGuest::start().await;
    let c = client(guest.url());
    let mut config = EpisodeConfig::instant(DownloadCache::new(root.join("cache")).expect("cache"));
    config.max_steps = 8;
    config.max_model_retries = 0;
    let layout = RunLayout {
        root: root.to_owned(),
        agent: agent.name().to_owned(),
        observation: "screenshot".into(),
        model: "mock".into(),
        trial: "0".into(),
    };
    let dir = layout.task_dir(task);
    let result = run_episode(&c, task, agent, &config, &dir).await;
    (result, dir.path().to_owned())
}

fn assert_solved(result: &EpisodeResult) {
    assert_eq!(
        (result.score, &result.status),
        (1.0, &EpisodeStatus::Completed),
        "{}: {}",
        result.task_name,
        serde_json::to_string_pretty(&result.eval).unwrap()
    );
}

/// Each step kept its request and response beside the trajectory (the files
/// count steps from 0, as upstream's recorder names them).
fn assert_exchanges_recorded(dir: &Path, steps: usize) {
    let names: Vec<String> =
        std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    for step in 0..steps {
        for key in ["request", "response"] {
            assert!(
                names.iter().any(|n| n.starts_with(&format!("{key}-step_{step}_"))),
                "no {key} log for step {step} in {names:?}"
            );
        }
    }
    let request = names.iter().find(|n| n.starts_with("request-step_0_")).unwrap();
    let text = std::fs::read_to_string(dir.join(request)).unwrap();
    assert!(text.contains("left out here") && !text.contains("iVBOR"), "images stay out of the logs");
}

fn header<'a>(headers: &'a HeaderMap, name: &str) -> &'a str {
    headers.get(name).and_then(|v| v.to_str().ok()).unwrap_or_else(|| panic!("no {name} header"))
}

/// The (width, height) of a base64 PNG.
fn png_size(b64: &str) -> (u32, u32) {
    let bytes = base64::engine::general_purpose::STANDARD.decode(b64).expect("base64");
    let image = image::load_from_memory(&bytes).expect("a PNG");
    (image.width(), image.height())
}

/// Checks `bodies` (the API each speaks, the body sent) against the vendors' SDK
/// types with `cu_agents/sdk_check.py`, in a Python that has the SDKs; a loud skip
/// without one.
fn check_against_sdk_types(test: &str, bodies: &[(&str, &Value)]) {
    let Some(python) = arena_test_support::gui_agents_python_or_skip(test) else { return };
    let here = Path::new(env!("CARGO_MANIFEST_DIR"));
    let list: Vec<Value> = bodies.iter().map(|(api, body)| json!({"api": api, "body": body})).collect();
    let mut child = std::process::Command::new(python)
        .arg(here.join("tests/cu_agents/sdk_check.py"))
        .arg(here.join("../examples/agent_s3/mock_models.py"))
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("the checker starts");
    std::io::Write::write_all(&mut child.stdin.take().unwrap(), serde_json::to_string(&list).unwrap().as_bytes())
        .unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{test}: requests the SDK types do not allow:\n{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// A folder holding the infeasible stub task alone, in `tmp/tasks`.
fn infeasible_task_folder(tmp: &Path) -> PathBuf {
    let domain = tmp.join("tasks").join("settings");
    std::fs::create_dir_all(&domain).unwrap();
    let source =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../tasks/stub/examples/settings/stub-settings-infeasible.json");
    std::fs::copy(&source, domain.join("stub-settings-infeasible.json")).unwrap();
    tmp.join("tasks")
}

/// `arena run` of the infeasible stub task on one stub guest into `tmp/out`,
/// without the preflight (the mocks answer only their scripted replies; the
/// preflight is tests/tests/preflight.rs's), with `args` (the agent and its
/// options); the run must succeed. Answers the results folder.
async fn run_infeasible_task(tmp: &Path, args: &[&str]) -> PathBuf {
    use clap::Parser as _;
    let tasks = infeasible_task_folder(tmp);
    let out = tmp.join("out");
    let mut words = vec!["arena", "run", "--tasks", tasks.to_str().unwrap(), "--stub-guests", "1"];
    words.extend(["--out", out.to_str().unwrap(), "--no-preflight"]);
    words.extend(args);
    let mut cli = arena_host::Cli::try_parse_from(words).expect("arguments parse");
    cli.connection.token = None;
    cli.connection.token_file = None;
    cli.connection.guest = None;
    let code = arena_host::run(cli).await.expect("the run runs");
    assert_eq!(code, std::process::ExitCode::SUCCESS, "{args:?}");
    out
}

// ---------------------------------------------------------------- Anthropic

fn tool_use(id: &str, input: Value) -> Value {
    json!({
        "id": format!("msg_{id}"), "type": "message", "role": "assistant", "model": "claude-test",
        "content": [
            {"type": "text", "text": "Next I act."},
            {"type": "tool_use", "id": id, "name": "computer", "input": input},
        ],
        "stop_reason": "tool_use", "usage": {"input_tokens": 1, "output_tokens": 1},
    })
}

fn end_turn(text: &str) -> Value {
    json!({
        "id": "msg_end", "type": "message", "role": "assistant", "model": "claude-test",
        "content": [{"type": "text", "text": text}],
        "stop_reason": "end_turn", "usage": {"input_tokens": 1, "output_tokens": 1},
    })
}

async fn anthropic_agent(mock: &Mock, tool: Form) -> AnthropicAgent {
    let base = serve(mock.clone(), "/v1/messages", "").await;
    let mut config = AnthropicConfig::new(&base, "claude-test");
    config.endpoint.api_key = Some(KEY.into());
    config.endpoint.retry = quick_retry();
    config.tool = tool;
    config.keep_images = 2;
    AnthropicAgent::new(config).expect("agent")
}

/// Checks every request of an Anthropic conversation against the protocol.
fn check_anthropic_requests(requests: &[(HeaderMap, Value)], replies: &[Value], instruction: &str, beta: &str) {
    for (n, (headers, body)) in requests.iter().enumerate() {
        assert_eq!(header(headers, "x-api-key"), KEY);
        assert_eq!(header(headers, "anthropic-version"), "2023-06-01");
        assert_eq!(header(headers, "anthropic-beta"), beta);
        assert_eq!(body["model"], "claude-test");
        assert!(body["max_tokens"].as_u64().unwrap() > 0);
        assert_eq!(body["system"][0]["cache_control"], json!({"type": "ephemeral"}), "the stable prefix is cached");
        let tool = &body["tools"][0];
        assert_eq!(tool["name"], "computer");
        // The stub's 1440x900 screen goes at WXGA, as the tool docs recommend.
        assert_eq!((tool["display_width_px"].as_u64(), tool["display_height_px"].as_u64()), (Some(1280), Some(800)));
        let messages = body["messages"].as_array().unwrap();
        assert_eq!(messages.len(), 2 * n + 1, "request {n}: one user turn per step, answers in between");
        assert_eq!(messages[0]["content"][0]["text"], instruction);
        // Every image is a base64 PNG at the declared size, and at most two are kept.
        let text = serde_json::to_string(messages).unwrap();
        assert!(text.matches("\"type\":\"image\"").count() <= 2, "request {n}: --keep-images 2");
        let last = messages.last().unwrap();
        assert_eq!(last["role"], "user");
        let image = if n == 0 {
            &last["content"][1]
        } else {
            // The answer to the previous tool call, by its id, carrying the new screenshot.
            assert_eq!(messages[2 * n - 1]["content"], replies[n - 1]["content"], "the answer is sent back as it was");
            let id = replies[n - 1]["content"][1]["id"].as_str().unwrap();
            let result = &last["content"][0];
            assert_eq!((result["type"].as_str(), result["tool_use_id"].as_str()), (Some("tool_result"), Some(id)));
            result["content"].as_array().unwrap().last().unwrap()
        };
        assert_eq!(image["type"], "image");
        assert_eq!(image["source"]["media_type"], "image/png");
        assert_eq!(png_size(image["source"]["data"].as_str().unwrap()), (1280, 800));
    }
}

#[tokio::test]
async fn anthropic_cu_solves_two_stub_tasks_and_every_request_is_well_formed() {
    let tmp = tempfile::tempdir().unwrap();
    // Draft: type, then save with xdotool's key syntax.
    let draft = stub_task("stub-notepad-draft");
    let replies = vec![
        tool_use("toolu_1", json!({"action": "type", "text": "This is a draft."})),
        tool_use("toolu_2", json!({"action": "key", "text": "ctrl+s"})),
        end_turn("The draft is saved. DONE"),
    ];
    let mock = Mock::new(replies.iter().cloned().map(ok).collect());
    let mut agent = anthropic_agent(&mock, Form::Computer20250124).await;
    let (result, dir) = episode(&draft, &mut agent, tmp.path()).await;
    assert_solved(&result);
    assert_eq!(result.steps, 3);
    // Each reply's usage (1 in, 1 out) is counted per step and summed for the task.
    let tokens = result.tokens.expect("the task's tokens");
    assert_eq!((tokens.input, tokens.output, tokens.cached), (3, 3, 0));
    check_anthropic_requests(&mock.requests(), &replies, &draft.instruction, "computer-use-2025-01-24");
    assert_exchanges_recorded(&dir, 3);

    // Count: a move in the model's coordinates, the cursor read back, then the answer, with computer_20251124.
    let count = stub_task("stub-notepad-count");
    let replies = vec![
        tool_use("toolu_a", json!({"action": "mouse_move", "coordinate": [640, 400]})),
        tool_use("toolu_b", json!({"action": "cursor_position"})),
        tool_use("toolu_c", json!({"action": "type", "text": "3"})),
        tool_use("toolu_d", json!({"action": "key", "text": "ctrl+s"})),
        end_turn("Saved. DONE"),
    ];
    let mock = Mock::new(replies.iter().cloned().map(ok).collect());
    let mut agent = anthropic_agent(&mock, Form::Computer20251124).await;
    let (result, _) = episode(&count, &mut agent, tmp.path()).await;
    assert_solved(&result);
    let requests = mock.requests();
    check_anthropic_requests(&requests, &replies, &count.instruction, "computer-use-2025-11-24");
    assert_eq!(requests[0].1["tools"][0]["type"], "computer_20251124");
    // The cursor comes back in the screenshot's coordinates: (720, 450) on the screen.
    let cursor = &requests[2].1["messages"].as_array().unwrap().last().unwrap()["content"][0]["content"][0];
    assert_eq!(cursor["text"], "X=640,Y=400");
    let bodies: Vec<(&str, &Value)> = requests.iter().map(|(_, b)| ("anthropic-beta", b)).collect();
    check_against_sdk_types("anthropic_cu_solves_two_stub_tasks_and_every_request_is_well_formed", &bodies);

    // Infeasible: the model says FAIL in its last message.
    let infeasible = stub_task("stub-settings-infeasible");
    let mock = Mock::new(vec![ok(end_turn("This computer has no such setting. FAIL"))]);
    let mut agent = anthropic_agent(&mock, Form::Computer20250124).await;
    let (result, _) = episode(&infeasible, &mut agent, tmp.path()).await;
    assert_solved(&result);
}

#[tokio::test]
async fn anthropic_cu_errors_malformed_refusal_429_and_bad_actions() {
    let guest = StubGuest::start().await;
    let c = client(guest.url());
    let obs = Observation::capture(&c, 1, "do it").await.expect("observe");

    // A refusal ends the episode as FAIL.
    let mock = Mock::new(vec![ok(json!({
        "id": "msg_r", "type": "message", "role": "assistant", "content": [], "stop_reason": "refusal",
    }))]);
    let mut agent = anthropic_agent(&mock, Form::Computer20250124).await;
    let p = agent.predict(&obs).await.expect("an answer");
    assert_eq!(p.actions, [AgentAction::Fail]);
    assert!(p.response.contains("refused"), "{}", p.response);

    // A malformed reply is a model error (the task is left unfinished), naming what is wrong.
    let mock = Mock::new(vec![ok(json!({"type": "message", "text": "hi"}))]);
    let mut agent = anthropic_agent(&mock, Form::Computer20250124).await;
    match agent.predict(&obs).await {
        Err(AgentError::Model { reason, .. }) => assert!(reason.contains("no `content` list"), "{reason}"),
        other => panic!("expected a model error, got {other:?}"),
    }

    // 429 with Retry-After: the agent waits and tries again; the answer then counts.
    let mock = Mock::new(vec![
        (429, vec![("retry-after", "1")], json!({"type": "error", "error": {"type": "rate_limit_error"}})),
        ok(tool_use("toolu_1", json!({"action": "key", "text": "Return"}))),
    ]);
    let mut agent = anthropic_agent(&mock, Form::Computer20250124).await;
    let started = std::time::Instant::now();
    let p = agent.predict(&obs).await.expect("an answer after the 429");
    assert!(started.elapsed() >= Duration::from_secs(1), "Retry-After is honoured");
    assert_eq!(mock.requests().len(), 2);
    assert_eq!(
        p.actions,
        [AgentAction::Typed(vec![arena_shared::action::Action::KeyPress { key: "enter".into(), presses: 1 }])]
    );

    // An endpoint that stays down: a model error once the retry budget is spent.
    let mock = Mock::new((0..500).map(|_| (503, Vec::new(), json!({"error": "overloaded"}))).collect());
    let mut agent = anthropic_agent(&mock, Form::Computer20250124).await;
    match agent.predict(&obs).await {
        Err(AgentError::Model { reason, .. }) => assert!(reason.contains("gave up"), "{reason}"),
        other => panic!("expected a model error, got {other:?}"),
    }

    // An unknown action: no action this step, the error recorded, and the model told with is_error.
    let mock = Mock::new(vec![
        ok(tool_use("toolu_x", json!({"action": "teleport", "coordinate": [1, 1]}))),
        ok(end_turn("DONE")),
    ]);
    let mut agent = anthropic_agent(&mock, Form::Computer20250124).await;
    let p = agent.predict(&obs).await.expect("an answer");
    assert!(p.actions.is_empty());
    assert!(p.raw_error.as_deref().unwrap_or_default().contains("unknown action \"teleport\""), "{p:?}");
    let p = agent.predict(&obs).await.expect("an answer");
    assert_eq!(p.actions, [AgentAction::Done]);
    let second = &mock.requests()[1].1;
    let result = &second["messages"].as_array().unwrap().last().unwrap()["content"][0];
    assert_eq!(result["is_error"], true);
    assert!(result["content"][0]["text"].as_str().unwrap().contains("teleport"));
}

/// One assistant message with several `tool_use` blocks (`blocks`: id, name, input;
/// toolset members carry `toolset_name`).
fn tool_uses(id: &str, blocks: &[(&str, &str, Value)], toolset: bool) -> Value {
    let mut content = vec![json!({"type": "text", "text": "Several actions at once."})];
    for (block_id, name, input) in blocks {
        let mut block = json!({"type": "tool_use", "id": block_id, "name": name, "input": input});
        if toolset {
            block["toolset_name"] = json!("computer");
        }
        content.push(block);
    }
    json!({
        "id": format!("msg_{id}"), "type": "message", "role": "assistant", "model": "claude-test",
        "content": content, "stop_reason": "tool_use", "usage": {"input_tokens": 1, "output_tokens": 1},
    })
}

/// The tool results of request `n` answer every block of `reply`, in order, in
/// one user message; `toolset` results name their toolset. Answers the results.
fn check_results_answer(body: &Value, reply: &Value, toolset: bool) -> Vec<Value> {
    let ids: Vec<&str> = reply["content"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|b| b["id"].as_str())
        .filter(|id| id.starts_with("toolu"))
        .collect();
    let last = body["messages"].as_array().unwrap().last().unwrap().clone();
    assert_eq!(last["role"], "user");
    let results = last["content"].as_array().unwrap().clone();
    let answered: Vec<&str> = results.iter().map(|r| r["tool_use_id"].as_str().unwrap()).collect();
    assert_eq!(answered, ids, "one tool_result per tool_use, in order, in one message");
    for result in &results {
        assert_eq!(result["type"], "tool_result");
        assert_eq!(result.get("toolset_name").and_then(Value::as_str), toolset.then_some("computer"), "{result}");
        assert!(result.get("is_error").is_none(), "{result}");
    }
    results
}

#[tokio::test]
async fn anthropic_toolset_solves_the_draft_with_several_members_in_one_turn() {
    let tmp = tempfile::tempdir().unwrap();
    let draft = stub_task("stub-notepad-draft");
    let replies = [
        tool_uses(
            "1",
            &[
                ("toolu_1", "left_click", json!({"coordinate": [640, 400]})),
                ("toolu_2", "type", json!({"text": "This is a draft."})),
                ("toolu_3", "screenshot", json!({})),
                ("toolu_4", "key", json!({"text": "ctrl+s"})),
            ],
            true,
        ),
        end_turn("Saved. DONE"),
    ];
    let mock = Mock::new(replies.iter().cloned().map(ok).collect());
    let base = serve(mock.clone(), "/v1/messages", "").await;
    let mut config = AnthropicConfig::new(&base, "claude-test");
    config.endpoint.api_key = Some(KEY.into());
    config.tool = Form::ComputerToolset20260801;
    config.image = arena_agents::cu::models::ImageLimit::Within { side: 2576, pixels: 3_750_000 };
    config.disabled_members = vec!["hold_key".into()];
    let mut agent = AnthropicAgent::new(config).expect("agent");
    let (result, _) = episode(&draft, &mut agent, tmp.path()).await;
    assert_solved(&result);
    assert_eq!(result.steps, 2, "four members in one turn are one step");
    let requests = mock.requests();
    assert_eq!(requests.len(), 2);
    for (headers, body) in &requests {
        // The toolset is a type of the GA API: no beta header.
        assert!(headers.get("anthropic-beta").is_none(), "{headers:?}");
        assert_eq!(header(headers, "anthropic-version"), "2023-06-01");
        // The entry carries only type and configs: no name, no display size.
        assert_eq!(
            body["tools"],
            json!([{"type": "computer_toolset_20260801",
                    "configs": {"zoom": {"enabled": false}, "hold_key": {"enabled": false}}}])
        );
    }
    // The screen goes as it is: Opus 4.7's limit takes 1440x900.
    let first = &requests[0].1["messages"][0]["content"][1];
    assert_eq!(png_size(first["source"]["data"].as_str().unwrap()), (1440, 900));
    let results = check_results_answer(&requests[1].1, &replies[0], true);
    // The screenshot member and the last result carry the screen after all four.
    for (i, result) in results.iter().enumerate() {
        let images = result["content"].as_array().unwrap().iter().filter(|c| c["type"] == "image").count();
        assert_eq!(images, usize::from(i == 2 || i == 3), "result {i}: {result}");
    }
    // The answer went back as it came, members and toolset names included.
    assert_eq!(requests[1].1["messages"][1]["content"], replies[0]["content"]);
    let bodies: Vec<(&str, &Value)> = requests.iter().map(|(_, b)| ("anthropic", b)).collect();
    check_against_sdk_types("anthropic_toolset_solves_the_draft_with_several_members_in_one_turn", &bodies);
}

#[tokio::test]
async fn anthropic_toolset_errors_name_the_member_and_nothing_of_the_turn_runs() {
    let guest = StubGuest::start().await;
    let c = client(guest.url());
    let obs = Observation::capture(&c, 1, "do it").await.expect("observe");
    let replies = [tool_uses(
        "1",
        &[("toolu_1", "type", json!({"text": "x"})), ("toolu_2", "key", json!({"text": "a", "repeat": 500}))],
        true,
    )];
    let mock = Mock::new(replies.iter().cloned().map(ok).collect());
    let base = serve(mock.clone(), "/v1/messages", "").await;
    let mut config = AnthropicConfig::new(&base, "claude-test");
    config.endpoint.api_key = Some(KEY.into());
    config.tool = Form::ComputerToolset20260801;
    let mut agent = AnthropicAgent::new(config).expect("agent");
    let prediction = agent.predict(&obs).await.expect("an answer");
    assert!(prediction.actions.is_empty(), "{:?}", prediction.actions);
    let error = prediction.raw_error.expect("the unreadable member");
    assert!(
        error.contains("computer_toolset_20260801") && error.contains("key:") && error.contains("repeat"),
        "{error}"
    );
}

#[tokio::test]
async fn anthropic_20251124_answers_several_tool_uses_of_one_turn_in_one_message() {
    let tmp = tempfile::tempdir().unwrap();
    let draft = stub_task("stub-notepad-draft");
    let replies = [
        tool_uses(
            "1",
            &[
                ("toolu_1", "computer", json!({"action": "type", "text": "This is a draft."})),
                ("toolu_2", "computer", json!({"action": "key", "text": "ctrl+s"})),
            ],
            false,
        ),
        end_turn("Saved. DONE"),
    ];
    let mock = Mock::new(replies.iter().cloned().map(ok).collect());
    let mut agent = anthropic_agent(&mock, Form::Computer20251124).await;
    let (result, _) = episode(&draft, &mut agent, tmp.path()).await;
    assert_solved(&result);
    let requests = mock.requests();
    assert_eq!(header(&requests[0].0, "anthropic-beta"), "computer-use-2025-11-24");
    let results = check_results_answer(&requests[1].1, &replies[0], false);
    assert_eq!(results.len(), 2);
    let bodies: Vec<(&str, &Value)> = requests.iter().map(|(_, b)| ("anthropic-beta", b)).collect();
    check_against_sdk_types("anthropic_20251124_answers_several_tool_uses_of_one_turn_in_one_message", &bodies);
}

// ---------------------------------------------------------------- OpenAI

fn computer_call(id: &str, call_id: &str, action: Value, checks: Value) -> Value {
    json!({
        "id": id, "object": "response", "status": "completed",
        "output": [
            {"type": "reasoning", "id": format!("rs_{id}"), "summary": []},
            {"type": "computer_call", "id": format!("cu_{id}"), "call_id": call_id, "action": action,
             "pending_safety_checks": checks, "status": "completed"},
        ],
    })
}

fn message(id: &str, part: Value) -> Value {
    json!({
        "id": id, "object": "response", "status": "completed",
        "output": [{"type": "message", "id": format!("msg_{id}"), "role": "assistant", "content": [part]}],
    })
}

async fn openai_agent(mock: &Mock, policy: SafetyChecks) -> OpenAiAgent {
    let base = serve(mock.clone(), "/v1/responses", "/v1").await;
    let mut config = OpenAiConfig::new(&base, "computer-use-preview");
    config.endpoint.api_key = Some(KEY.into());
    config.endpoint.retry = quick_retry();
    config.safety_checks = policy;
    OpenAiAgent::new(config).expect("agent")
}

/// The display `openai-cu` declares for the 1440x900 stub screen: scaled to fit
/// within 1024x768, the size OpenAI's computer-use guide declares in its examples.
const OPENAI_DISPLAY: (u32, u32) = (1024, 640);

/// Checks every request of a Responses conversation: the tool (its display the
/// size of every screenshot sent), truncation, the chaining by id and the
/// screenshot answering each call.
fn check_openai_requests(requests: &[(HeaderMap, Value)], replies: &[Value], instruction: &str) {
    for (n, (headers, body)) in requests.iter().enumerate() {
        assert_eq!(header(headers, "authorization"), format!("Bearer {KEY}"));
        assert_eq!(body["model"], "computer-use-preview");
        assert_eq!(body["truncation"], "auto");
        assert_eq!(
            body["tools"],
            json!([{"type": "computer_use_preview", "display_width": OPENAI_DISPLAY.0,
                    "display_height": OPENAI_DISPLAY.1, "environment": "windows"}])
        );
        let input = &body["input"][0];
        let url = if n == 0 {
            assert!(body.get("previous_response_id").is_none());
            assert_eq!(input["role"], "user");
            assert_eq!(input["content"][0], json!({"type": "input_text", "text": instruction}));
            input["content"][1]["image_url"].as_str().unwrap()
        } else {
            let previous = &replies[n - 1];
            assert_eq!(body["previous_response_id"], previous["id"]);
            assert_eq!(input["type"], "computer_call_output");
            assert_eq!(input["call_id"], previous["output"][1]["call_id"]);
            assert_eq!(input["acknowledged_safety_checks"], previous["output"][1]["pending_safety_checks"]);
            assert_eq!(input["output"]["type"], "computer_screenshot");
            input["output"]["image_url"].as_str().unwrap()
        };
        let b64 = url.strip_prefix("data:image/png;base64,").expect("a PNG data URL");
        assert_eq!(png_size(b64), OPENAI_DISPLAY, "request {n}: the image is the declared display's size");
    }
}

#[tokio::test]
async fn openai_cu_solves_two_stub_tasks_with_chaining_and_acknowledged_safety_checks() {
    let tmp = tempfile::tempdir().unwrap();
    let draft = stub_task("stub-notepad-draft");
    let check = json!([{"id": "sc_1", "code": "malicious_instructions", "message": "Check the screen."}]);
    let replies = vec![
        computer_call("resp_1", "call_1", json!({"type": "type", "text": "This is a draft."}), json!([])),
        computer_call("resp_2", "call_2", json!({"type": "keypress", "keys": ["CTRL", "S"]}), check),
        message("resp_3", json!({"type": "output_text", "text": "Saved. DONE", "annotations": []})),
    ];
    let mock = Mock::new(replies.iter().cloned().map(ok).collect());
    let mut agent = openai_agent(&mock, SafetyChecks::Ack).await;
    let (result, dir) = episode(&draft, &mut agent, tmp.path()).await;
    assert_solved(&result);
    let requests = mock.requests();
    assert_eq!(requests.len(), 3);
    check_openai_requests(&requests, &replies, &draft.instruction);
    assert_eq!(requests[2].1["input"][0]["acknowledged_safety_checks"][0]["id"], "sc_1");
    assert_exchanges_recorded(&dir, 3);

    let append = stub_task("stub-notepad-append");
    let replies = vec![
        computer_call("r1", "c1", json!({"type": "keypress", "keys": ["CTRL", "END"]}), json!([])),
        computer_call("r2", "c2", json!({"type": "type", "text": "buy eggs\n"}), json!([])),
        computer_call("r3", "c3", json!({"type": "screenshot"}), json!([])),
        computer_call("r4", "c4", json!({"type": "keypress", "keys": ["CTRL", "S"]}), json!([])),
        message("r5", json!({"type": "output_text", "text": "DONE", "annotations": []})),
    ];
    let mock = Mock::new(replies.iter().cloned().map(ok).collect());
    let mut agent = openai_agent(&mock, SafetyChecks::Ack).await;
    let (result, _) = episode(&append, &mut agent, tmp.path()).await;
    assert_solved(&result);
    let requests = mock.requests();
    check_openai_requests(&requests, &replies, &append.instruction);
    let bodies: Vec<(&str, &Value)> = requests.iter().map(|(_, b)| ("openai", b)).collect();
    check_against_sdk_types("openai_cu_solves_two_stub_tasks_with_chaining_and_acknowledged_safety_checks", &bodies);
}

/// A GA `computer` answer: one `computer_call` with an `actions` batch.
fn computer_batch(id: &str, call_id: &str, actions: Value) -> Value {
    json!({
        "id": id, "object": "response", "status": "completed",
        "output": [
            {"type": "computer_call", "id": format!("cu_{id}"), "call_id": call_id, "actions": actions,
             "pending_safety_checks": [], "status": "completed"},
        ],
    })
}

#[tokio::test]
async fn openai_ga_computer_runs_a_batch_in_order_and_answers_the_call_once() {
    let tmp = tempfile::tempdir().unwrap();
    let draft = stub_task("stub-notepad-draft");
    let replies = [
        computer_batch(
            "resp_1",
            "call_1",
            json!([
                {"type": "click", "button": "left", "x": 700, "y": 400},
                {"type": "type", "text": "This is a draft."},
                {"type": "keypress", "keys": ["CTRL", "s"]},
                {"type": "screenshot"},
            ]),
        ),
        message("resp_2", json!({"type": "output_text", "text": "Saved. DONE", "annotations": []})),
    ];
    let mock = Mock::new(replies.iter().cloned().map(ok).collect());
    let base = serve(mock.clone(), "/v1/responses", "/v1").await;
    let mut config = OpenAiConfig::new(&base, "gpt-5.4");
    config.endpoint.api_key = Some(KEY.into());
    config.tool = Form::Computer;
    config.image = arena_agents::cu::models::choose(arena_agents::cu::models::Vendor::OpenAi, "gpt-5.4").image;
    let mut agent = OpenAiAgent::new(config).expect("agent");
    let (result, _) = episode(&draft, &mut agent, tmp.path()).await;
    assert_solved(&result);
    assert_eq!(result.steps, 2, "the batch is one step");
    let requests = mock.requests();
    assert_eq!(requests.len(), 2);
    for (_, body) in &requests {
        assert_eq!(body["tools"], json!([{"type": "computer"}]), "the GA tool carries nothing but its type");
    }
    let url = requests[0].1["input"][0]["content"][1]["image_url"].as_str().unwrap();
    assert_eq!(png_size(url.strip_prefix("data:image/png;base64,").unwrap()), (1440, 900), "sent as it is");
    let input = requests[1].1["input"].as_array().unwrap();
    assert_eq!(input.len(), 1, "one output for the one call: {input:?}");
    assert_eq!(input[0]["type"], "computer_call_output");
    assert_eq!(input[0]["call_id"], "call_1");
    assert_eq!(requests[1].1["previous_response_id"], "resp_1");
    let bodies: Vec<(&str, &Value)> = requests.iter().map(|(_, b)| ("openai", b)).collect();
    check_against_sdk_types("openai_ga_computer_runs_a_batch_in_order_and_answers_the_call_once", &bodies);
    // A GA call without its batch is a malformed answer.
    let mock = Mock::new(vec![ok(
        json!({"id": "r", "output": [{"type": "computer_call", "call_id": "c", "pending_safety_checks": []}]}),
    )]);
    let base = serve(mock.clone(), "/v1/responses", "/v1").await;
    let mut config = OpenAiConfig::new(&base, "gpt-5.4");
    config.endpoint.api_key = Some(KEY.into());
    config.tool = Form::Computer;
    let mut agent = OpenAiAgent::new(config).expect("agent");
    let guest = StubGuest::start().await;
    let obs = Observation::capture(&client(guest.url()), 1, "do it").await.expect("observe");
    let err = agent.predict(&obs).await.unwrap_err().to_string();
    assert!(err.contains("without `actions`"), "{err}");
}

/// `arena run` without `--computer-tool` asks the table: the recorded options say
/// which tool and image limit the model got, and from where.
#[tokio::test]
async fn without_computer_tool_the_models_row_chooses_and_the_run_records_it() {
    let cases = [
        ("claude-opus-4-7", "anthropic-cu", "computer_20251124 (model table)", "computer-use-2025-11-24"),
        ("claude-sonnet-4-5", "anthropic-cu", "computer_20250124 (model table)", "computer-use-2025-01-24"),
        ("claude-opus-5", "anthropic-cu", "computer_toolset_20260801 (newest, model not in the table)", ""),
    ];
    for (model, agent, recorded, beta) in cases {
        let tmp = tempfile::tempdir().unwrap();
        let mock = Mock::new(vec![ok(end_turn("No such setting. FAIL"))]);
        let base = serve(mock.clone(), "/v1/messages", "").await;
        let out = run_infeasible_task(tmp.path(), &["--agent", agent, "--llm-url", &base, "--model", model]).await;
        let summary: Value = serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
        assert_eq!(summary["options"]["computer_tool"], json!([recorded]), "{model}: {summary}");
        assert!(summary["options"]["image_limit"][0].as_str().is_some(), "{model}");
        let requests = mock.requests();
        let sent = requests[0].0.get("anthropic-beta").map(|v| v.to_str().unwrap().to_owned()).unwrap_or_default();
        assert_eq!(sent, beta, "{model}");
    }
}

#[tokio::test]
async fn openai_cu_errors_safety_fail_refusal_malformed_and_429() {
    let guest = StubGuest::start().await;
    let c = client(guest.url());
    let obs = Observation::capture(&c, 1, "do it").await.expect("observe");

    // Coordinates are the declared display's (1024x640 for 1440x900), scaled back:
    // (512, 320) is the screen's centre, a drag's ends and a scroll's point likewise.
    let replies = vec![
        computer_call("r1", "c1", json!({"type": "click", "button": "left", "x": 512, "y": 320}), json!([])),
        computer_call(
            "r2",
            "c2",
            json!({"type": "drag", "path": [{"x": 0, "y": 0}, {"x": 1023, "y": 639}]}),
            json!([]),
        ),
    ];
    let mock = Mock::new(replies.iter().cloned().map(ok).collect());
    let mut agent = openai_agent(&mock, SafetyChecks::Ack).await;
    let p = agent.predict(&obs).await.expect("an answer");
    assert_eq!(
        p.actions,
        [AgentAction::Typed(vec![Action::Click { x: Some(720), y: Some(450), button: MouseButton::Left, count: 1 }])]
    );
    let p = agent.predict(&obs).await.expect("an answer");
    let AgentAction::Typed(drag) = &p.actions[0] else { panic!("a typed drag: {p:?}") };
    assert!(
        matches!(drag[..], [Action::Drag { from: Some(Point { x: 0, y: 0 }), to: Point { x: 1439, y: 899 }, .. }]),
        "{drag:?}"
    );
    check_openai_requests(&mock.requests(), &replies, "do it");

    // `--safety-checks fail`: the episode ends as FAIL and the checks are recorded.
    let check = json!([{"id": "sc_9", "code": "sensitive_domain", "message": "A bank."}]);
    let mock = Mock::new(vec![ok(computer_call("r1", "c1", json!({"type": "move", "x": 1, "y": 1}), check))]);
    let mut agent = openai_agent(&mock, SafetyChecks::Fail).await;
    let p = agent.predict(&obs).await.expect("an answer");
    assert_eq!(p.actions, [AgentAction::Fail]);
    assert!(p.response.contains("sensitive_domain") && p.response.contains("(fail)"), "{}", p.response);

    // A refusal is FAIL.
    let mock = Mock::new(vec![ok(message("r1", json!({"type": "refusal", "refusal": "I can't help with that."})))]);
    let mut agent = openai_agent(&mock, SafetyChecks::Ack).await;
    let p = agent.predict(&obs).await.expect("an answer");
    assert_eq!(p.actions, [AgentAction::Fail]);
    assert!(p.response.contains("can't help"), "{}", p.response);

    // Malformed: no output list.
    let mock = Mock::new(vec![ok(json!({"id": "r1", "object": "response"}))]);
    let mut agent = openai_agent(&mock, SafetyChecks::Ack).await;
    match agent.predict(&obs).await {
        Err(AgentError::Model { reason, .. }) => assert!(reason.contains("no `output` list"), "{reason}"),
        other => panic!("expected a model error, got {other:?}"),
    }

    // 429 with Retry-After, then an unknown action: recorded, nothing done, the chain goes on.
    let mock = Mock::new(vec![
        (429, vec![("retry-after", "1")], json!({"error": {"message": "slow down"}})),
        ok(computer_call("r1", "c1", json!({"type": "teleport"}), json!([]))),
        ok(message("r2", json!({"type": "output_text", "text": "DONE"}))),
    ]);
    let mut agent = openai_agent(&mock, SafetyChecks::Ack).await;
    let started = std::time::Instant::now();
    let p = agent.predict(&obs).await.expect("an answer after the 429");
    assert!(started.elapsed() >= Duration::from_secs(1));
    assert!(p.actions.is_empty());
    assert!(p.raw_error.unwrap().contains("unknown action type \"teleport\""));
    let p = agent.predict(&obs).await.expect("an answer");
    assert_eq!(p.actions, [AgentAction::Done]);
    let requests = mock.requests();
    assert_eq!(requests[2].1["previous_response_id"], "r1");
    assert_eq!(requests[2].1["input"][0]["call_id"], "c1");
}

// ---------------------------------------------------------------- UI-TARS

/// A template of our own with the published placeholders (the real one is the user's file).
const TEMPLATE: &str = "TEST TEMPLATE. Language: {language}. Task: {instruction}";

fn chat(content: &str) -> Reply {
    ok(json!({
        "id": "chatcmpl-1", "object": "chat.completion",
        "choices": [{"index": 0, "message": {"role": "assistant", "content": content}, "finish_reason": "stop"}],
        // The chat-completions usage vLLM reports (openai-python's CompletionUsage).
        "usage": {"prompt_tokens": 7, "completion_tokens": 2, "total_tokens": 9,
                  "prompt_tokens_details": {"cached_tokens": 4}},
    }))
}

async fn uitars_agent(mock: &Mock, version: UiTarsVersion, history_images: usize) -> UiTarsAgent {
    let base = serve(mock.clone(), "/v1/chat/completions", "/v1").await;
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("prompt.txt");
    std::fs::write(&path, TEMPLATE).unwrap();
    let template = UiTarsConfig::read_prompt(&path).expect("the prompt file reads");
    let mut config = UiTarsConfig::new(&base, "ui-tars-1.5-7b", &template);
    config.endpoint.api_key = Some(KEY.into());
    config.endpoint.retry = quick_retry();
    config.version = version;
    config.history_images = history_images;
    UiTarsAgent::new(config).expect("agent")
}

fn check_uitars_requests(requests: &[(HeaderMap, Value)], replies: &[&str], instruction: &str, keep: usize) {
    for (n, (headers, body)) in requests.iter().enumerate() {
        assert_eq!(header(headers, "authorization"), format!("Bearer {KEY}"));
        assert_eq!(body["model"], "ui-tars-1.5-7b");
        let messages = body["messages"].as_array().unwrap();
        assert_eq!(messages[0]["content"][0]["text"], format!("TEST TEMPLATE. Language: English. Task: {instruction}"));
        let assistants: Vec<&str> =
            messages.iter().filter(|m| m["role"] == "assistant").map(|m| m["content"].as_str().unwrap()).collect();
        assert_eq!(assistants, replies[..n], "request {n}: the earlier replies, in order");
        let images: Vec<&Value> = messages.iter().filter(|m| m["content"][0]["type"] == "image_url").collect();
        assert_eq!(images.len(), (n + 1).min(keep), "request {n}: the last {keep} screenshots");
        let last = messages.last().unwrap();
        let url = last["content"][0]["image_url"]["url"].as_str().expect("the current screenshot is last");
        assert_eq!(png_size(url.strip_prefix("data:image/png;base64,").unwrap()), (1440, 900));
    }
}

#[tokio::test]
async fn ui_tars_solves_two_stub_tasks_with_history_and_both_coordinate_versions() {
    let tmp = tempfile::tempdir().unwrap();
    let draft = stub_task("stub-notepad-draft");
    // Typing goes by the clipboard and ctrl+v, as the published parser does.
    let replies = [
        "Thought: I type the sentence.\nAction: type(content='This is a draft.')",
        "Thought: Save it.\nAction: hotkey(key='ctrl s')",
        "Thought: Done.\nAction: finished(content='saved')",
    ];
    let mock = Mock::new(replies.iter().map(|r| chat(r)).collect());
    let mut agent = uitars_agent(&mock, UiTarsVersion::V1_5, 2).await;
    let (result, dir) = episode(&draft, &mut agent, tmp.path()).await;
    assert_solved(&result);
    check_uitars_requests(&mock.requests(), &replies, &draft.instruction, 2);
    assert_exchanges_recorded(&dir, 3);
    // Each step's usage in traj.jsonl, the task's sum in its result.
    let tokens = result.tokens.expect("the task's tokens");
    assert_eq!((tokens.input, tokens.output, tokens.cached), (21, 6, 12));
    let traj = std::fs::read_to_string(dir.join("traj.jsonl")).unwrap();
    // The first line of each step's record carries its usage (a step's other
    // actions have lines of their own, as upstream writes them).
    let usages: Vec<Value> =
        traj.lines().filter_map(|line| serde_json::from_str::<Value>(line).ok()?.get("usage").cloned()).collect();
    assert_eq!(usages.len(), 3, "{traj}");
    for usage in usages {
        assert_eq!(
            (usage["input"].as_u64(), usage["output"].as_u64(), usage["cached"].as_u64()),
            (Some(7), Some(2), Some(4))
        );
    }

    // UI-TARS 1.0's 0..1000 grid: a hover at the centre, then the answer and a save.
    let count = stub_task("stub-notepad-count");
    let replies = [
        "Thought: Look.\nAction: hover(start_box='<|box_start|>(500,500)<|box_end|>')",
        "Action: type(content='3')",
        "Action: hotkey(key='ctrl s')\n\nfinished(content='3')",
    ];
    let mock = Mock::new(replies.iter().map(|r| chat(r)).collect());
    let mut agent = uitars_agent(&mock, UiTarsVersion::V1, 5).await;
    let (result, dir) = episode(&count, &mut agent, tmp.path()).await;
    assert_solved(&result);
    check_uitars_requests(&mock.requests(), &replies, &count.instruction, 5);
    let traj = std::fs::read_to_string(dir.join("traj.jsonl")).unwrap();
    assert!(traj.contains("\"x\":720") && traj.contains("\"y\":450"), "the grid's centre is the screen's: {traj}");
}

#[tokio::test]
async fn ui_tars_errors_unreadable_replies_call_user_and_429() {
    let guest = StubGuest::start().await;
    let c = client(guest.url());
    let obs = Observation::capture(&c, 1, "do it").await.expect("observe");
    let mock = Mock::new(vec![
        (429, vec![("retry-after", "1")], json!({"error": "busy"})),
        chat("Thought: I am not sure."),
        chat("Action: click(start_box='(1,2,3)')"),
        chat("Thought: I need the password.\nAction: call_user()"),
    ]);
    let mut agent = uitars_agent(&mock, UiTarsVersion::V1_5, 5).await;
    let started = std::time::Instant::now();
    let p = agent.predict(&obs).await.expect("an answer after the 429");
    assert!(started.elapsed() >= Duration::from_secs(1));
    assert!(p.actions.is_empty());
    assert!(p.raw_error.unwrap().contains("no `Action:`"));
    let p = agent.predict(&obs).await.expect("an answer");
    assert!(p.raw_error.unwrap().contains("(x,y) or (x1,y1,x2,y2)"));
    let p = agent.predict(&obs).await.expect("an answer");
    assert_eq!(p.actions, [AgentAction::Fail]);
    assert_eq!(mock.left(), 0);

    // A prompt file without the placeholder, or missing, is refused naming the file.
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("bad.txt");
    std::fs::write(&path, "no placeholder").unwrap();
    let err = UiTarsConfig::read_prompt(&path).unwrap_err().to_string();
    assert!(err.contains("bad.txt") && err.contains("{instruction}"), "{err}");
    assert!(UiTarsConfig::read_prompt(&tmp.path().join("missing.txt"))
        .unwrap_err()
        .to_string()
        .contains("missing.txt"));
}

// ---------------------------------------------------------------- the command line

#[test]
fn run_help_lists_the_agents_and_the_coordinate_conventions() {
    use clap::Parser as _;
    let err = arena_host::Cli::try_parse_from(["arena", "run", "--help"]).expect_err("help is printed as an error");
    let help = err.to_string();
    for needle in [
        "anthropic-cu",
        "openai-cu",
        "ui-tars",
        "--coords",
        "grid1000",
        "--safety-checks",
        "--prompt-file",
        "--keep-images",
        "computer_toolset_20260801",
        "computer_use_preview",
        "--max-image-side",
        "--toolset-disable",
    ] {
        assert!(help.contains(needle), "`arena run --help` lacks {needle}");
    }
}

#[tokio::test]
async fn arena_run_with_openai_cu_records_agent_model_action_space_and_coordinates() {
    let tmp = tempfile::tempdir().unwrap();
    let mock = Mock::new(vec![ok(message("r1", json!({"type": "output_text", "text": "No such setting. FAIL"})))]);
    let base = serve(mock.clone(), "/v1/responses", "/v1").await;
    let args =
        ["--agent", "openai-cu", "--llm-url", &base, "--model", "computer-use-preview", "--safety-checks", "fail"];
    let out = run_infeasible_task(tmp.path(), &args).await;
    assert_eq!(mock.requests().len(), 1);
    let summary: Value = serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let options = &summary["options"];
    assert_eq!(options["agent"], json!(["openai-cu"]), "{summary}");
    assert_eq!(options["action_space"], json!(["openai_computer"]));
    assert_eq!(options["coords"], json!(["image:within-1024x768"]));
    assert_eq!(options["model"], json!(["computer-use-preview"]));
    assert_eq!(options["safety_checks"], json!(["fail"]));
    let result =
        out.join("openai_computer/a11y_tree/computer-use-preview/0/settings/stub-settings-infeasible/result.txt");
    assert!(result.is_file(), "the result is filed under the action space and the model");
}

#[tokio::test]
async fn a_mock_models_usage_is_the_tasks_and_the_runs_tokens_and_cost() {
    use clap::Parser as _;
    let tmp = tempfile::tempdir().unwrap();
    // The Responses API's usage (openai-python's ResponseUsage).
    let mut reply = message("r1", json!({"type": "output_text", "text": "No such setting. FAIL"}));
    reply["usage"] = json!({"input_tokens": 1500, "input_tokens_details": {"cached_tokens": 1000},
        "output_tokens": 40, "output_tokens_details": {"reasoning_tokens": 0}, "total_tokens": 1540});
    let mock = Mock::new(vec![ok(reply)]);
    let base = serve(mock.clone(), "/v1/responses", "/v1").await;
    let prices = tmp.path().join("prices.json");
    std::fs::write(&prices, r#"{"computer-use-preview": {"input": 3.0, "output": 12.0, "cached_input": 0.75}}"#)
        .unwrap();
    let model = ["--agent", "openai-cu", "--llm-url", &base, "--model", "computer-use-preview"];
    let out = run_infeasible_task(tmp.path(), &[&model[..], &["--prices", prices.to_str().unwrap()]].concat()).await;
    let dir = out.join("openai_computer/a11y_tree/computer-use-preview/0/settings/stub-settings-infeasible");
    let traj = std::fs::read_to_string(dir.join("traj.jsonl")).unwrap();
    let step: Value =
        traj.lines().map(|l| serde_json::from_str::<Value>(l).unwrap()).find(|l| l.get("step").is_some()).unwrap();
    assert_eq!(
        (step["usage"]["input"].clone(), step["usage"]["output"].clone(), step["usage"]["cached"].clone()),
        (json!(1500), json!(40), json!(1000))
    );
    assert!(step["usage"]["model_ms"].is_u64());
    let cost = (500.0 * 3.0 + 1000.0 * 0.75 + 40.0 * 12.0) / 1e6;
    let episode: Value = serde_json::from_slice(&std::fs::read(dir.join("episode.json")).unwrap()).unwrap();
    assert_eq!(episode["tokens"]["input"], 1500);
    assert!((episode["cost_usd"].as_f64().unwrap() - cost).abs() < 1e-12, "{}", episode["cost_usd"]);
    let summary: Value = serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["overall"]["tokens"]["input"], 1500, "{summary}");
    assert_eq!(summary["overall"]["tokens"]["output"], 40);
    assert_eq!(summary["tasks"][0]["tokens"]["cached"], 1000);
    assert!((summary["overall"]["cost_usd"].as_f64().unwrap() - cost).abs() < 1e-12);

    // A price file without the run's model is refused before anything runs, naming both.
    std::fs::write(&prices, r#"{"gpt-4o": {"input": 2.5, "output": 10.0}}"#).unwrap();
    let fresh = tmp.path().join("fresh");
    let tasks = tmp.path().join("tasks");
    let words = [
        "arena",
        "run",
        "--tasks",
        tasks.to_str().unwrap(),
        "--agent",
        "openai-cu",
        "--llm-url",
        &base,
        "--model",
        "computer-use-preview",
        "--stub-guests",
        "1",
        "--out",
        fresh.to_str().unwrap(),
        "--prices",
        prices.to_str().unwrap(),
    ];
    let mut cli = arena_host::Cli::try_parse_from(words).expect("arguments parse");
    cli.connection.token = None;
    cli.connection.token_file = None;
    cli.connection.guest = None;
    let err = format!("{:#}", arena_host::run(cli).await.expect_err("no price for the model"));
    assert!(err.contains("\"computer-use-preview\"") && err.contains("\"gpt-4o\""), "{err}");
    assert!(!fresh.exists(), "nothing was written");
    assert_eq!(mock.requests().len(), 1, "the model was not called again");
}

/// Observes the stub guest and asks `agent` for `steps` steps, holding each step to
/// one decode of the screenshot: the observation's. The agent's images (resized,
/// cropped for a zoom, or the bytes as sent) come from the observation's frame.
async fn one_decode_per_step(agent: &mut dyn Agent, steps: u32) {
    use arena_client::frame::decodes_on_this_thread;
    let guest = StubGuest::start().await;
    let c = client(guest.url());
    let task = stub_task("stub-notepad-draft");
    agent.reset(&task).await;
    for step in 1..=steps {
        // The test's runtime runs on this thread, so every decode of the step is counted.
        let before = decodes_on_this_thread();
        let obs = Observation::capture(&c, step, &task.instruction).await.expect("observe");
        let prediction = agent.predict(&obs).await.expect("a prediction");
        assert_eq!(prediction.raw_error, None, "step {step}");
        assert_eq!(decodes_on_this_thread() - before, 1, "{}: step {step}", agent.name());
    }
}

#[tokio::test]
async fn one_anthropic_step_decodes_each_screenshot_once() {
    // A zoom (a crop of the current screenshot) answered in the second step's request,
    // and a screenshot resized to the recommended size in both.
    let mock = Mock::new(vec![
        ok(tool_use("t1", json!({"action": "zoom", "region": [0, 0, 400, 300]}))),
        ok(end_turn("Done.")),
    ]);
    let base = serve(mock.clone(), "/v1/messages", "").await;
    let mut config = AnthropicConfig::new(&base, "claude-test");
    config.endpoint.api_key = Some(KEY.into());
    config.tool = Form::Computer20251124;
    config.enable_zoom = true;
    let mut agent = AnthropicAgent::new(config).expect("agent");
    one_decode_per_step(&mut agent, 2).await;
    assert_eq!(mock.left(), 0, "both answers were asked for");
}

#[tokio::test]
async fn one_openai_step_decodes_each_screenshot_once() {
    let mock = Mock::new(vec![
        ok(computer_call("r1", "c1", json!({"type": "click", "button": "left", "x": 10, "y": 20}), json!([]))),
        ok(computer_call("r2", "c2", json!({"type": "type", "text": "x"}), json!([]))),
    ]);
    let mut agent = openai_agent(&mock, SafetyChecks::Ack).await;
    one_decode_per_step(&mut agent, 2).await;
    assert_eq!(mock.left(), 0, "both answers were asked for");
}

#[tokio::test]
async fn one_ui_tars_step_decodes_each_screenshot_once() {
    let mock = Mock::new(vec![chat("Thought: click.\nAction: click(start_box='(100,200)')"), chat("Action: wait()")]);
    let mut agent = uitars_agent(&mock, UiTarsVersion::V1_5, 5).await;
    one_decode_per_step(&mut agent, 2).await;
    assert_eq!(mock.left(), 0, "both answers were asked for");
}
