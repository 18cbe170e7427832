//! Agents and action execution against a real in-process stub guest on
//! `127.0.0.1:0`, and the Navi agent against a mock OpenAI-compatible server
//! (a real axum HTTP server in the test) whose requests are checked.

use std::collections::VecDeque;
use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use axum::extract::State;
use axum::http::{HeaderMap, StatusCode};
use axum::routing::post;
use axum::{Json, Router};
use base64::Engine as _;
use serde_json::{json, Value};
use tokio::net::TcpListener;

use arena_agents::llm::RetryPolicy;
use arena_agents::navi::{NaviAgent, NaviConfig, NaviStyle};
use arena_agents::observation::Observation;
use arena_agents::replay::{ReplayAgent, ReplaySource, TrajectoryStep};
use arena_agents::scripted::{PlanSource, ScriptedAgent};
use arena_agents::{Agent, AgentError};
use arena_client::client::{ClientConfig, GuestClient};
use arena_exec::AgentAction;
use arena_exec::{execute_with, ActionOutcome, ExecError, ExecOptions};
use arena_script::ComputerState;
use arena_shared::action::Action;
use arena_shared::clipboard::ClipboardContent;
use arena_shared::exec::LaunchRequest;
use arena_shared::observation::{A11yNode, A11yQuery, WindowTarget};
use arena_som::Marks;
use arena_task::Task;
use arena_test_support::StubGuest;

async fn start_guest() -> StubGuest {
    StubGuest::start().await
}

fn client(url: &str) -> GuestClient {
    GuestClient::new(url, ClientConfig { token: None, timeout: Duration::from_secs(20), retries: 1 }).expect("client")
}

/// A guest with Notepad open and focused.
async fn guest_with_notepad() -> (StubGuest, GuestClient) {
    let guest = start_guest().await;
    let c = client(guest.url());
    c.launch(&LaunchRequest { shell: None, argv: vec!["notepad.exe".into()] }).await.expect("launch notepad");
    (guest, c)
}

fn find<'a>(node: &'a A11yNode, pred: &dyn Fn(&A11yNode) -> bool) -> Option<&'a A11yNode> {
    if pred(node) {
        return Some(node);
    }
    node.children.iter().find_map(|c| find(c, pred))
}

/// The text of Notepad's document, read back from the accessibility tree.
async fn notepad_text(c: &GuestClient) -> String {
    let tree = c.a11y(&A11yQuery::default()).await.expect("tree");
    let window = tree.windows.iter().find(|w| w.name.contains("Notepad")).expect("a Notepad window");
    let doc = find(window, &|n| n.role == "Document").expect("a document node");
    doc.value.clone().unwrap_or_default()
}

fn task(dir: &Path, extra: &str) -> Task {
    let domain = dir.join("notepad");
    std::fs::create_dir_all(&domain).expect("domain dir");
    let path = domain.join("type-hello.json");
    let text = format!(
        r#"{{"id": "type-hello", "instruction": "Type hello in Notepad", "config": [], "evaluator": {{"func": "infeasible"}}{extra}}}"#
    );
    std::fs::write(&path, &text).expect("write task");
    Task::load(&path).expect("task loads")
}

async fn run(c: &GuestClient, action: &AgentAction, obs: &Observation, state: &mut ComputerState) -> ActionOutcome {
    execute_with(c, action, obs.marks().as_ref().map(Marks::boxes), state, &ExecOptions::instant())
        .await
        .expect("execute")
}

fn computer(code: &str) -> AgentAction {
    AgentAction::Computer(code.into())
}

#[tokio::test]
async fn move_id_moves_to_the_centre_of_the_mark_and_typing_reaches_notepad() {
    let (_guest, c) = guest_with_notepad().await;
    let obs = Observation::capture(&c, 1, "type").await.expect("observe");
    let marks = obs.marks().expect("marks from the tree");
    let doc = marks.entities.iter().find(|m| m.text == "Text Editor").expect("the document is a mark");
    let r = marks.rects[doc.id];
    let mut state = ComputerState::for_screen(1, 1);

    let code = format!("computer.mouse.move_id(id={})\ncomputer.mouse.single_click()", doc.id);
    let outcome = run(&c, &computer(&code), &obs, &mut state).await;
    assert_eq!(outcome.error, None, "{outcome:?}");
    assert_eq!(outcome.performed, 2);
    let cursor = outcome.cursor.expect("a cursor after input");
    assert_eq!((cursor.x, cursor.y), ((r[0] + r[2]) / 2, (r[1] + r[3]) / 2));
    assert_eq!(state.current_id, Some(doc.id));
    assert_eq!(state.window_rect, [0, 0, obs.screen.physical_width as i32, obs.screen.physical_height as i32]);

    let outcome = run(&c, &computer("computer.keyboard.write(\"hello world\")"), &obs, &mut state).await;
    assert_eq!(outcome.error, None, "{outcome:?}");
    assert_eq!(notepad_text(&c).await, "hello world");
}

#[tokio::test]
async fn pyautogui_hotkeys_and_the_clipboard_work_through_the_guest() {
    let (_guest, c) = guest_with_notepad().await;
    let obs = Observation::capture(&c, 1, "copy").await.expect("observe");
    let mut state = ComputerState::for_screen(1, 1);
    // pyautogui code runs in the host's interpreter (the default policy, `Effects`),
    // each input call one action on the guest.
    let code = "pyautogui.write('abc')\npyautogui.hotkey('ctrl', 'a')\npyautogui.hotkey('ctrl', 'c')\nprint(pyautogui.position())";
    let outcome = run(&c, &AgentAction::Pyautogui(code.into()), &obs, &mut state).await;
    assert_eq!(outcome.error, None, "{outcome:?}");
    assert_eq!(outcome.performed, 3, "{outcome:?}");
    assert_eq!(c.clipboard_get().await.expect("clipboard"), ClipboardContent::Text { text: "abc".into() });

    // copy_text puts text on the guest's clipboard and in the state, which later steps keep.
    let code = "computer.clipboard.copy_text(\"pasted\")\ncomputer.keyboard.press(\"end\")\ncomputer.clipboard.paste()";
    let outcome = run(&c, &computer(code), &obs, &mut state).await;
    assert_eq!(outcome.error, None, "{outcome:?}");
    assert_eq!(state.clipboard_content.as_deref(), Some("pasted"));
    assert_eq!(notepad_text(&c).await, "abcpasted");
}

#[tokio::test]
async fn typed_actions_open_program_and_switching_windows() {
    let guest = start_guest().await;
    let c = client(guest.url());
    let obs = Observation::capture(&c, 1, "open").await.expect("observe");
    let mut state = ComputerState::for_screen(1, 1);
    let outcome = run(&c, &computer("computer.os.open_program(\"notepad\")"), &obs, &mut state).await;
    assert_eq!(outcome.error, None, "{outcome:?}");
    let windows = c.windows().await.expect("windows");
    let notepad = windows.iter().find(|w| w.title.contains("Notepad")).expect("notepad opened");
    assert!(notepad.focused && notepad.maximized, "{notepad:?}");

    let typed = AgentAction::Typed(vec![Action::TypeText { text: "typed".into(), interval_ms: None }]);
    let outcome = run(&c, &typed, &obs, &mut state).await;
    assert_eq!((outcome.error, outcome.performed), (None, 1));
    assert_eq!(notepad_text(&c).await, "typed");

    let outcome =
        run(&c, &computer("computer.window_manager.switch_to_application(\"Untitled - Notepad\")"), &obs, &mut state)
            .await;
    assert_eq!(outcome.error, None, "{outcome:?}");

    // An unknown program is upstream's printed "error: ..." failure, not a crash.
    let outcome = run(&c, &computer("computer.os.open_program(\"no-such-program-xyz\")"), &obs, &mut state).await;
    assert!(outcome.error.as_deref().is_some_and(|e| e.contains("not installed")), "{outcome:?}");
}

#[tokio::test]
async fn script_errors_are_recorded_and_an_unreachable_guest_is_an_infrastructure_error() {
    let (_guest, c) = guest_with_notepad().await;
    let obs = Observation::capture(&c, 1, "x").await.expect("observe");
    let mut state = ComputerState::for_screen(1, 1);
    let check = |outcome: ActionOutcome, needle: &str| {
        let err = outcome.error.unwrap_or_default();
        assert!(err.contains(needle), "{err:?} lacks {needle:?}");
    };
    check(run(&c, &computer("computer.mouse.move_id(id=100000)"), &obs, &mut state).await, "IndexError");
    check(run(&c, &computer("computer.mouse.single_click("), &obs, &mut state).await, "SyntaxError");
    check(run(&c, &computer("computer.keyboard.presss('a')"), &obs, &mut state).await, "AttributeError");
    let bad_key = AgentAction::Typed(vec![Action::KeyPress { key: "nokey".into(), presses: 1 }]);
    check(run(&c, &bad_key, &obs, &mut state).await, "nokey");

    // Nothing listens on this port any more.
    let dead_url = {
        let listener = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
        format!("http://{}", listener.local_addr().expect("addr"))
    };
    let dead = client(&dead_url);
    let result =
        execute_with(&dead, &computer("computer.mouse.single_click()"), None, &mut state, &ExecOptions::instant())
            .await;
    assert!(matches!(result, Err(ExecError::Guest(_))), "{result:?}");
}

// ----- the mock model -----

/// A recorded request: its `Authorization` header and its JSON body.
type Recorded = (Option<String>, Value);

#[derive(Clone, Default)]
struct Mock {
    requests: Arc<Mutex<Vec<Recorded>>>,
    replies: Arc<Mutex<VecDeque<(u16, String)>>>,
}

async fn completions(
    State(mock): State<Mock>,
    headers: HeaderMap,
    Json(body): Json<Value>,
) -> (StatusCode, Json<Value>) {
    let auth = headers.get("authorization").and_then(|v| v.to_str().ok()).map(str::to_owned);
    mock.requests.lock().expect("lock").push((auth, body));
    let (status, reply) = mock.replies.lock().expect("lock").pop_front().unwrap_or((200, "DONE".to_owned()));
    if status != 200 {
        return (
            StatusCode::from_u16(status).unwrap_or(StatusCode::INTERNAL_SERVER_ERROR),
            Json(json!({"error": reply})),
        );
    }
    (StatusCode::OK, Json(json!({"choices": [{"index": 0, "message": {"role": "assistant", "content": reply}}]})))
}

async fn start_mock(replies: &[(u16, &str)]) -> (String, Mock) {
    let mock = Mock::default();
    mock.replies.lock().expect("lock").extend(replies.iter().map(|(s, r)| (*s, (*r).to_owned())));
    let app = Router::new().route("/v1/chat/completions", post(completions)).with_state(mock.clone());
    let listener = TcpListener::bind("127.0.0.1:0").await.expect("bind");
    let url = format!("http://{}/v1", listener.local_addr().expect("addr"));
    tokio::spawn(async move {
        let _ = axum::serve(listener, app).await;
    });
    (url, mock)
}

/// The image data URIs and the text of a recorded request's user message.
fn user_parts(body: &Value) -> (Vec<String>, String) {
    let content = body["messages"][1]["content"].as_array().expect("user content parts");
    let images = content.iter().filter_map(|p| p["image_url"]["url"].as_str().map(str::to_owned)).collect();
    let text = content.iter().filter_map(|p| p["text"].as_str()).collect::<Vec<_>>().join("\n");
    (images, text)
}

#[tokio::test]
async fn navi_sends_the_annotated_screenshot_and_elements_and_retries_malformed_output() {
    let (_guest, c) = guest_with_notepad().await;
    let (url, mock) = start_mock(&[
        (200, "I am not sure what to do here."),
        (200, "Click the editor and type.\nMemory: typing hello into the editor\n```python\ncomputer.mouse.move_id(id=ID)\ncomputer.mouse.single_click()\ncomputer.keyboard.write(\"hello\")\n```"),
        (200, "It is typed.\n```python\nDONE\n```"),
        (500, "overloaded"),
    ])
    .await;
    let mut config = NaviConfig::new(&url, "mock-model");
    config.api_key = Some("test-key".into());
    config.style = NaviStyle::Arena;
    // The 500 at the end is reported at once, not tried again.
    config.retry = RetryPolicy { give_up_after: Duration::ZERO, ..RetryPolicy::default() };
    let mut agent = NaviAgent::new(config).expect("agent");
    let dir = tempfile::tempdir().expect("dir");
    agent.reset(&task(dir.path(), "")).await;

    // Step 1: a reply without a code block is recorded, not a crash.
    let obs = Observation::capture(&c, 1, "Type hello in Notepad").await.expect("observe");
    let marks = obs.marks().expect("marks");
    let doc_id = marks.entities.iter().find(|m| m.text == "Text Editor").expect("document mark").id;
    let p = agent.predict(&obs).await.expect("prediction");
    assert!(p.actions.is_empty());
    assert!(p.raw_error.as_deref().is_some_and(|e| e.contains("no ```python code block")), "{p:?}");

    let requests = mock.requests.lock().expect("lock").clone();
    let (auth, body) = &requests[0];
    assert_eq!(auth.as_deref(), Some("Bearer test-key"));
    assert_eq!(body["model"], "mock-model");
    assert!(body["messages"][0]["content"].as_str().is_some_and(|s| s.contains("computer.mouse.move_id")));
    let (images, text) = user_parts(body);
    assert_eq!(images.len(), 1, "no previous screenshot on the first step");
    let annotated = images[0].strip_prefix("data:image/png;base64,").expect("a PNG data URI");
    let annotated = base64::engine::general_purpose::STANDARD.decode(annotated).expect("base64");
    let sent = image::load_from_memory(&annotated).expect("decodes").to_rgba8();
    let raw = obs.screenshot.pixels.as_ref();
    assert_ne!(&sent, raw, "the screenshot sent is annotated");
    assert_eq!(sent.dimensions(), raw.dimensions());
    let r = marks.rects[doc_id];
    let (x, y) = (r[0] as u32 + 1, r[3] as u32 - 1);
    assert_ne!(sent.get_pixel(x, y), raw.get_pixel(x, y), "a box is drawn on the document's edge");
    assert!(text.contains("Type hello in Notepad"));
    assert!(text.contains(&marks.candidate_list()), "{text}");
    assert!(text.contains(&format!("{doc_id} | a11y | Text Editor | [")), "{text}");
    assert!(text.contains("Untitled - Notepad (foreground)"), "{text}");

    // Step 2: the model is told about its unusable reply and answers with code.
    {
        let mut replies = mock.replies.lock().expect("lock");
        let next = replies.front_mut().expect("reply");
        next.1 = next.1.replace("ID", &doc_id.to_string());
    }
    let obs2 = Observation::capture(&c, 2, "Type hello in Notepad").await.expect("observe");
    let p = agent.predict(&obs2).await.expect("prediction");
    assert_eq!(p.raw_error, None);
    assert_eq!(p.actions.len(), 1);
    let body = mock.requests.lock().expect("lock")[1].1.clone();
    let (images, text) = user_parts(&body);
    assert_eq!(images.len(), 2, "the previous screenshot is sent too");
    assert!(text.contains("could not be used"), "{text}");
    let mut state = ComputerState::for_screen(1, 1);
    let outcome =
        execute_with(&c, &p.actions[0], p.marks.as_ref().map(Marks::boxes), &mut state, &ExecOptions::instant())
            .await
            .expect("execute");
    assert_eq!(outcome.error, None, "{outcome:?}");
    assert_eq!(notepad_text(&c).await, "hello");

    // Step 3: memory and history are in the prompt; DONE ends it.
    let obs3 = Observation::capture(&c, 3, "Type hello in Notepad").await.expect("observe");
    let p = agent.predict(&obs3).await.expect("prediction");
    assert_eq!(p.actions, vec![AgentAction::Done]);
    let (_, text) = user_parts(&mock.requests.lock().expect("lock")[2].1);
    assert!(text.contains("Memory: typing hello into the editor"), "{text}");
    assert!(text.contains("Step 1: (reply not usable"), "{text}");
    assert!(text.contains("computer.keyboard.write(\"hello\")"), "{text}");

    // An HTTP failure of the endpoint is an error the caller sees.
    let err = agent.predict(&obs3).await.expect_err("HTTP 500");
    assert!(matches!(err, AgentError::Model { .. }) && err.to_string().contains("500"), "{err}");
}

#[tokio::test]
async fn navi_in_upstreams_layout_reads_replies_by_upstreams_rules() {
    let (_guest, c) = guest_with_notepad().await;
    let (url, mock) = start_mock(&[
        (200, "Focus the editor.\n```python\n    computer.mouse.move_id(id=ID)\n    computer.mouse.single_click()\n```\n```decision\nCOMMAND\n```\n```memory\nthe editor has focus\n```"),
        (200, "Type it.\n```python\ncomputer.keyboard.write(\"hello\")\n```\n```python\ncomputer.keyboard.press(\"enter\")\n```"),
        (200, "Typed.\n```python\ncomputer.keyboard.press(\"enter\")\n```\n```decision\nDONE\n```"),
    ])
    .await;
    let mut agent = NaviAgent::new(NaviConfig::new(&url, "mock-model")).expect("agent");
    let dir = tempfile::tempdir().expect("dir");
    agent.reset(&task(dir.path(), "")).await;

    let obs = Observation::capture(&c, 1, "Type hello in Notepad").await.expect("observe");
    let doc_id = obs.marks().expect("marks").entities.iter().find(|m| m.text == "Text Editor").expect("mark").id;
    {
        let mut replies = mock.replies.lock().expect("lock");
        let next = replies.front_mut().expect("reply");
        next.1 = next.1.replace("ID", &doc_id.to_string());
    }
    let p = agent.predict(&obs).await.expect("prediction");
    // The first python block, dedented; COMMAND keeps it.
    let code = format!("computer.mouse.move_id(id={doc_id})\ncomputer.mouse.single_click()\n");
    assert_eq!(p.actions, vec![AgentAction::Computer(code.clone().into())]);
    let body = mock.requests.lock().expect("lock")[0].1.clone();
    assert_eq!((body["temperature"].clone(), body["max_tokens"].clone()), (json!(1.0), json!(4096)));
    let (images, text) = user_parts(&body);
    assert_eq!(images.len(), 2, "on the first step the current screen stands in for the previous one");
    let (width, height) = obs.screenshot.size();
    let want = arena_shared::fastimg::model_size(width, height);
    for url in &images {
        let jpeg = url.strip_prefix("data:image/jpeg;base64,").expect("a JPEG data URI");
        let jpeg = base64::engine::general_purpose::STANDARD.decode(jpeg).expect("base64");
        let sent = image::load_from_memory_with_format(&jpeg, image::ImageFormat::Jpeg).expect("a JPEG");
        assert_eq!((sent.width(), sent.height()), (want.width, want.height), "upstream's model size");
    }
    for label in [
        "1. User objective: Type hello in Notepad",
        "2. Window title: Untitled - Notepad",
        "3. All window names:",
        "4. Clipboard content.",
        "6. Candidate elements:",
        "8. History of previous actions",
        "9. Textual memory:",
    ] {
        assert!(text.contains(label), "{label} missing from {text}");
    }
    assert!(body["messages"][0]["content"].as_str().is_some_and(|s| s.contains("```decision")));
    let keys: Vec<&str> = p.logs.iter().map(|l| l.key.as_str()).collect();
    for key in ["user_question", "plan_result", "request", "foreground_window_prompt", "entity_list", "a11y_truncated"]
    {
        assert!(keys.contains(&key), "{key} not logged: {keys:?}");
    }

    let obs2 = Observation::capture(&c, 2, "Type hello in Notepad").await.expect("observe");
    let p = agent.predict(&obs2).await.expect("prediction");
    assert_eq!(
        p.actions,
        vec![AgentAction::Computer("computer.keyboard.write(\"hello\")\n".into())],
        "only the first block"
    );
    let body = mock.requests.lock().expect("lock")[1].1.clone();
    let content = body["messages"][1]["content"].as_array().expect("parts").clone();
    let kinds: Vec<&str> = content.iter().map(|p| p["type"].as_str().unwrap_or("")).collect();
    assert_eq!(kinds, ["text", "image_url", "image_url"], "the previous screen, then the current one");
    assert_eq!(content[1]["image_url"]["detail"], "auto");
    let previous = content[1]["image_url"]["url"].as_str().unwrap();
    let expected =
        arena_shared::fastimg::rgba_to_model_jpeg(&obs.screenshot.pixels, arena_shared::fastimg::PILLOW_JPEG_QUALITY)
            .expect("jpeg")
            .jpeg;
    let previous =
        base64::engine::general_purpose::STANDARD.decode(previous.strip_prefix("data:image/jpeg;base64,").unwrap());
    assert_eq!(previous.unwrap(), expected, "the previous screen as it was, unannotated");
    let (_, text) = user_parts(&body);
    assert!(text.contains("```memory\nthe editor has focus\n```"), "{text}");
    assert!(text.contains(&code), "{text}");

    let obs3 = Observation::capture(&c, 3, "Type hello in Notepad").await.expect("observe");
    let p = agent.predict(&obs3).await.expect("prediction");
    assert_eq!(p.actions, vec![AgentAction::Done], "the decision wins over the code");
    let (_, text) = user_parts(&mock.requests.lock().expect("lock")[2].1);
    let newest = text.find("computer.keyboard.write").expect("step 2 in the history");
    let oldest = text.find("computer.mouse.single_click").expect("step 1 in the history");
    assert!(newest < oldest, "the history is newest first: {text}");
}

#[tokio::test]
async fn scripted_agent_follows_a_plan_file_against_the_stub() {
    let (_guest, c) = guest_with_notepad().await;
    let dir = tempfile::tempdir().expect("dir");
    let plan = json!({"steps": [
        {"code": "computer.mouse.move_abs(x=0.5, y=0.5)\ncomputer.mouse.single_click()"},
        {"code": "pyautogui.write('hi ')", "lang": "pyautogui"},
        {"actions": [{"type": "type_text", "text": "there"}]},
        "WAIT",
        "DONE"
    ]});
    let plans = dir.path().join("plans");
    std::fs::create_dir_all(plans.join("notepad")).expect("plans dir");
    std::fs::write(plans.join("notepad").join("type-hello.json"), plan.to_string()).expect("plan");
    let mut agent = ScriptedAgent::new(PlanSource::Dir(plans));
    let t = task(dir.path(), "");
    agent.reset(&t).await;
    let mut state = ComputerState::for_screen(1, 1);
    let mut seen = Vec::new();
    for step in 1..=5 {
        let obs = Observation::capture(&c, step, &t.instruction).await.expect("observe");
        let p = agent.predict(&obs).await.expect("prediction");
        assert_eq!(p.actions.len(), 1);
        let outcome =
            execute_with(&c, &p.actions[0], p.marks.as_ref().map(Marks::boxes), &mut state, &ExecOptions::instant())
                .await
                .expect("execute");
        assert_eq!(outcome.error, None, "step {step}: {outcome:?}");
        seen.push(p.actions[0].clone());
    }
    assert_eq!(seen[3..], [AgentAction::Wait, AgentAction::Done]);
    assert_eq!(notepad_text(&c).await, "hi there");
    let obs = Observation::capture(&c, 6, "").await.expect("observe");
    assert!(matches!(agent.predict(&obs).await, Err(AgentError::Exhausted(_))));

    // Reset starts over; a plan inside the task file works too; a missing plan is a clear error.
    agent.reset(&t).await;
    assert!(agent.predict(&obs).await.expect("again").actions[0] == seen[0]);
    let mut inline = ScriptedAgent::new(PlanSource::TaskKey);
    inline.reset(&task(dir.path(), r#", "plan": {"steps": ["FAIL"]}"#)).await;
    assert_eq!(inline.predict(&obs).await.expect("inline").actions, vec![AgentAction::Fail]);
    let mut missing = ScriptedAgent::new(PlanSource::Dir(dir.path().join("nowhere")));
    missing.reset(&task(dir.path(), "")).await;
    let err = missing.predict(&obs).await.expect_err("no plan");
    assert!(err.to_string().contains("type-hello"), "{err}");
    let bad = dir.path().join("bad.json");
    std::fs::write(&bad, r#"{"steps": ["MAYBE"]}"#).expect("write");
    let err = ScriptedAgent::from_file(&bad).expect_err("bad plan");
    assert!(err.to_string().contains("step 1") && err.to_string().contains("MAYBE"), "{err}");
}

#[tokio::test]
async fn a_plan_step_in_a_computer_use_space_is_translated_against_the_screen() {
    let (_guest, c) = guest_with_notepad().await;
    let plan = json!({"steps": [
        {"space": "computer_20250124", "input": [{"action": "type", "text": "hi "}, {"action": "key", "text": "shift+a"}]},
        {"space": "openai_computer", "input": {"type": "type", "text": "bc"}},
        {"space": "uitars", "input": "Action: finished(content='done')"}
    ]});
    let dir = tempfile::tempdir().expect("dir");
    let path = dir.path().join("plan.json");
    std::fs::write(&path, plan.to_string()).expect("plan");
    let mut agent = ScriptedAgent::from_file(&path).expect("the plan loads");
    let t = task(dir.path(), "");
    agent.reset(&t).await;
    let mut state = ComputerState::for_screen(1, 1);
    let mut last = Vec::new();
    for step in 1..=3 {
        let obs = Observation::capture(&c, step, &t.instruction).await.expect("observe");
        let p = agent.predict(&obs).await.expect("prediction");
        assert!(p.response.starts_with(&format!("plan step {step}: ")), "{}", p.response);
        for action in &p.actions {
            let outcome = execute_with(&c, action, None, &mut state, &ExecOptions::instant()).await.expect("execute");
            assert_eq!(outcome.error, None, "step {step}: {outcome:?}");
        }
        last = p.actions;
    }
    assert_eq!(notepad_text(&c).await, "hi Abc");
    assert_eq!(last, vec![AgentAction::Done], "UI-TARS's finished() is the decision DONE");

    // An unknown space, or an input its space does not take, fails when the plan loads.
    for (step, says) in [
        (json!({"space": "computer_1999", "input": {}}), "unknown action space"),
        (json!({"space": "computer_20250124", "input": {"action": "fly"}}), "computer_20250124"),
    ] {
        std::fs::write(&path, json!({"steps": [step]}).to_string()).expect("plan");
        let err = ScriptedAgent::from_file(&path).expect_err("a bad step");
        assert!(err.to_string().contains("step 1") && err.to_string().contains(says), "{err}");
    }
}
#[tokio::test]
async fn replay_repeats_a_recorded_trajectory() {
    let (_guest, c) = guest_with_notepad().await;
    let dir = tempfile::tempdir().expect("dir");
    let t = task(dir.path(), "");
    let recorded = vec![
        TrajectoryStep { step: 1, actions: vec![computer("computer.keyboard.write(\"again\")")] },
        TrajectoryStep { step: 2, actions: vec![] },
        TrajectoryStep {
            step: 3,
            actions: vec![
                AgentAction::Typed(vec![Action::KeyPress { key: "backspace".into(), presses: 1 }]),
                AgentAction::Done,
            ],
        },
    ];
    // As the episode writer lays it out, with extra fields the replay ignores.
    let task_dir = dir.path().join("results").join("notepad").join("type-hello");
    std::fs::create_dir_all(&task_dir).expect("dir");
    let lines: Vec<String> = recorded
        .iter()
        .map(|s| {
            let mut v = serde_json::to_value(s).expect("json");
            v["response"] = json!("recorded reply");
            v["elapsed_ms"] = json!(12);
            v.to_string()
        })
        .collect();
    std::fs::write(task_dir.join("traj.jsonl"), lines.join("\n") + "\n").expect("write");

    let mut agent = ReplayAgent::new(ReplaySource::Dir(dir.path().join("results")));
    agent.reset(&t).await;
    let mut state = ComputerState::for_screen(1, 1);
    let mut replayed = Vec::new();
    for step in 1..=3 {
        let obs = Observation::capture(&c, step, &t.instruction).await.expect("observe");
        let p = agent.predict(&obs).await.expect("prediction");
        for action in &p.actions {
            execute_with(&c, action, p.marks.as_ref().map(Marks::boxes), &mut state, &ExecOptions::instant())
                .await
                .expect("execute");
        }
        replayed.push(TrajectoryStep { step, actions: p.actions });
    }
    assert_eq!(replayed, recorded);
    assert_eq!(notepad_text(&c).await, "agai");
    let obs = Observation::capture(&c, 4, "").await.expect("observe");
    assert!(matches!(agent.predict(&obs).await, Err(AgentError::Exhausted(_))));

    let broken = dir.path().join("broken.jsonl");
    std::fs::write(&broken, "{\"step\": 1, \"actions\": []}\nnot json\n").expect("write");
    let mut agent = ReplayAgent::new(ReplaySource::File(broken));
    agent.reset(&t).await;
    let err = agent.predict(&obs).await.expect_err("broken trajectory");
    assert!(err.to_string().contains("line 2"), "{err}");
}

#[tokio::test]
async fn a_key_left_held_stays_down_across_steps_unless_actions_release_it() {
    let (_guest, c) = guest_with_notepad().await;
    let obs = Observation::capture(&c, 1, "type").await.expect("observe");
    let mut state = ComputerState::for_screen(1, 1);
    // As upstream: Shift held by one step's code is still down in the next step.
    let held = AgentAction::Pyautogui("pyautogui.keyDown('shift')\npyautogui.press('x')".into());
    let outcome = run(&c, &held, &obs, &mut state).await;
    assert_eq!((outcome.error, outcome.keys_down), (None, vec!["shift".to_owned()]));
    let typed = AgentAction::Pyautogui("pyautogui.press('y')\npyautogui.keyUp('shift')".into());
    assert_eq!(run(&c, &typed, &obs, &mut state).await.error, None);
    assert_eq!(notepad_text(&c).await, "XY");

    // --held-keys action: the code block and the typed batch let go of what they hold.
    let release = ExecOptions { release_held_keys: true, ..ExecOptions::instant() };
    let go = |action: AgentAction| {
        let c = c.clone();
        let release = release.clone();
        async move {
            let mut state = ComputerState::for_screen(1, 1);
            execute_with(&c, &action, None, &mut state, &release).await.expect("execute")
        }
    };
    go(AgentAction::Pyautogui("pyautogui.keyDown('shift')\npyautogui.press('z')".into())).await;
    go(AgentAction::Pyautogui("pyautogui.press('w')".into())).await;
    let batch = vec![Action::KeyDown { key: "shift".into() }, Action::KeyPress { key: "v".into(), presses: 1 }];
    let outcome = go(AgentAction::Typed(batch)).await;
    assert_eq!((outcome.error, outcome.performed), (None, 2));
    go(AgentAction::Typed(vec![Action::KeyPress { key: "u".into(), presses: 1 }])).await;
    assert_eq!(notepad_text(&c).await, "XYZwVu");
}

#[tokio::test]
async fn the_observation_lists_windows_and_names_the_foreground_as_upstream() {
    let guest = start_guest().await;
    let c = client(guest.url());
    // Two windows of the same title, and Paint, minimised.
    for program in ["notepad.exe", "notepad.exe", "mspaint.exe"] {
        c.launch(&LaunchRequest { shell: None, argv: vec![program.into()] }).await.expect("launch");
    }
    let paint = WindowTarget { title: Some("Untitled - Paint".into()), id: None };
    assert!(c.minimize_window(&paint).await.expect("minimise").minimized);
    // The desktop itself in front.
    c.activate_window(&WindowTarget { title: Some("Program Manager".into()), id: None }).await.expect("activate");
    let raw = c.windows().await.expect("windows");
    assert_eq!(raw.iter().filter(|w| w.title == "Untitled - Notepad").count(), 2, "{raw:?}");
    assert!(raw.iter().any(|w| w.title == "Program Manager" && w.focused), "{raw:?}");

    let obs = Observation::capture(&c, 1, "look").await.expect("observe");
    // Upstream: every visible titled window, minimised ones included, each title once, topmost
    // first (the desktop stays at the bottom of the z-order even when it has the focus).
    assert_eq!(obs.window_titles, ["Untitled - Paint", "Untitled - Notepad", "Program Manager"]);
    // Upstream's window title for the desktop in front.
    assert_eq!(obs.foreground_title, "Desktop");
    assert!(obs.a11y.as_ref().is_some_and(|t| !t.truncated), "the tree and its truncated flag");
    let t = obs.timings;
    assert!(t.total_ms >= t.screenshot_ms && t.tree_ms.is_some() && t.dom_ms.is_none(), "{t:?}");
}

#[tokio::test]
async fn one_navi_step_decodes_each_screenshot_once() {
    use arena_client::frame::decodes_on_this_thread;
    let (_guest, c) = guest_with_notepad().await;
    let reply = "Look.\n```python\ncomputer.mouse.move_abs(x=0.5, y=0.5)\n```\n```decision\nCOMMAND\n```";
    let (url, _mock) = start_mock(&[(200, reply), (200, reply)]).await;
    let mut agent = NaviAgent::new(NaviConfig::new(&url, "mock-model")).expect("agent");
    let dir = tempfile::tempdir().expect("dir");
    agent.reset(&task(dir.path(), "")).await;
    for step in 1..=2 {
        // The test's runtime runs on this thread, so every decode of the step is counted.
        let before = decodes_on_this_thread();
        let obs = Observation::capture(&c, step, "Type hello in Notepad").await.expect("observe");
        let p = agent.predict(&obs).await.expect("prediction");
        assert_eq!(p.actions.len(), 1);
        // Set-of-Marks, the annotation, both model images (the previous one included) and
        // the logs all use the observation's pixels.
        assert_eq!(decodes_on_this_thread() - before, 1, "step {step}");
        assert!(p.timings.som_ms.is_some() && p.timings.model_ms.is_some(), "{:?}", p.timings);
        assert_eq!(p.timings.model_tries, 1);
    }
}

/// An outside agent over the step protocol (`--agent exec`), a shell script that
/// answers `hello` with `hello` (adding `extra` to it), `reset` with `ready`, the
/// first `observe` with `code` in pyautogui and the next with `DONE`.
#[cfg(unix)]
fn exec_agent(dir: &Path, extra: &str, code: &str) -> arena_agents::external::ExternalAgent {
    use arena_agents::external::transport::ProcessPool;
    let hello = format!(
        r#"{{"type":"hello","protocol":1,"agent":"sh","action_space":"pyautogui"{extra},"observation":{{"screenshot":"none","a11y":"none","windows":false,"clipboard":false}}}}"#
    );
    let act = json!({"type": "act", "actions": [code]}).to_string();
    let script = format!(
        "read -r line\nprintf '%s\\n' '{hello}'\nn=0\nwhile read -r line; do\n  case \"$line\" in\n    *'\"type\":\"reset\"'*) printf '%s\\n' '{{\"type\":\"ready\"}}' ;;\n    *) n=$((n+1)); if [ $n -eq 1 ]; then printf '%s\\n' '{act}'; else printf '%s\\n' '{{\"type\":\"act\",\"decision\":\"DONE\"}}'; fi ;;\n  esac\ndone\n"
    );
    let path = dir.join("agent.sh");
    std::fs::write(&path, script).expect("write the agent script");
    let pool = ProcessPool::new(&format!("sh {}", path.display())).expect("a process pool");
    arena_agents::external::ExternalAgent::new("exec", Arc::new(pool), Duration::from_secs(20))
}

/// Runs one episode of `agent` on a fresh stub guest (1440x900) with the run's
/// `coords`, and answers where the cursor ended.
#[cfg(unix)]
async fn cursor_after_episode(
    mut agent: arena_agents::external::ExternalAgent,
    coords: arena_actionspace::Coords,
    dir: &Path,
) -> (i32, i32) {
    use arena_host::episode::{run_episode, EpisodeConfig};
    use arena_results::EpisodeStatus;
    let guest = start_guest().await;
    let c = client(guest.url());
    let mut config =
        EpisodeConfig::instant(arena_client::cache::DownloadCache::new(dir.join("cache")).expect("a download cache"));
    config.exec.coords = coords;
    let task = task(dir, "");
    let layout = arena_results::RunLayout {
        root: dir.join("results"),
        agent: "exec".into(),
        observation: "screenshot".into(),
        model: "sh".into(),
        trial: coords.name(),
    };
    let result = run_episode(&c, &task, &mut agent, &config, &layout.task_dir(&task)).await;
    assert_eq!(result.status, EpisodeStatus::Completed, "{result:?}");
    let report = c.act(&arena_shared::action::ActionBatch { actions: Vec::new() }).await.expect("the cursor");
    (report.cursor.x, report.cursor.y)
}

#[cfg(unix)]
#[tokio::test]
async fn an_exec_agents_pyautogui_is_rescaled_from_the_runs_or_its_own_coordinate_convention() {
    use arena_actionspace::Coords;
    let tmp = tempfile::tempdir().expect("tmp");
    // The run's --coords grid1000: (250, 750) on the grid is (360, 675) of 1440x900.
    let dir = tmp.path().join("grid");
    let agent = exec_agent(&dir_made(&dir), "", "pyautogui.click(250, 750)").with_coords(Coords::Grid1000);
    assert_eq!(cursor_after_episode(agent, Coords::Grid1000, &dir).await, (360, 675));
    // The same answer in a pixels run lands where it says.
    let dir = tmp.path().join("pixels");
    let agent = exec_agent(&dir_made(&dir), "", "pyautogui.click(250, 750)");
    assert_eq!(cursor_after_episode(agent, Coords::Pixels, &dir).await, (250, 750));
    // An agent whose hello names fractions is read in fractions, whatever the run's.
    let dir = tmp.path().join("fraction");
    let agent = exec_agent(&dir_made(&dir), r#","coords":"fraction""#, "pyautogui.moveTo(0.25, 0.75)");
    assert_eq!(cursor_after_episode(agent, Coords::Pixels, &dir).await, (360, 675));
}

#[cfg(unix)]
fn dir_made(dir: &Path) -> std::path::PathBuf {
    std::fs::create_dir_all(dir).expect("a folder");
    dir.to_owned()
}

/// One step of an outside agent over the step protocol that asks for everything an
/// observation offers (the screenshot inline, the tree as XML, the windows, the
/// clipboard, the Set-of-Marks boxes) decodes each screenshot once: the observation's.
#[cfg(unix)]
#[tokio::test]
async fn one_step_protocol_step_decodes_each_screenshot_once() {
    use arena_agents::external::transport::ProcessPool;
    use arena_agents::external::ExternalAgent;
    use arena_client::frame::decodes_on_this_thread;
    let (_guest, c) = guest_with_notepad().await;
    let dir = tempfile::tempdir().expect("dir");
    let hello = r#"{"type":"hello","protocol":1,"agent":"sh","action_space":"pyautogui","observation":{"screenshot":"inline","a11y":"xml","windows":true,"clipboard":true,"som":true}}"#;
    let act = json!({"type": "act", "actions": ["pyautogui.click(1, 2)"]}).to_string();
    let script = format!(
        "read -r line\nprintf '%s\\n' '{hello}'\nwhile read -r line; do\n  case \"$line\" in\n    *'\"type\":\"reset\"'*) printf '%s\\n' '{{\"type\":\"ready\"}}' ;;\n    *) printf '%s\\n' '{act}' ;;\n  esac\ndone\n"
    );
    let path = dir.path().join("agent.sh");
    std::fs::write(&path, script).expect("write the agent script");
    let pool = ProcessPool::new(&format!("sh {}", path.display())).expect("a process pool");
    let mut agent = ExternalAgent::new("exec", Arc::new(pool), Duration::from_secs(20));
    agent.reset(&task(dir.path(), "")).await;
    for step in 1..=2 {
        let before = decodes_on_this_thread();
        let obs = Observation::capture(&c, step, "Type hello in Notepad").await.expect("observe");
        let p = agent.predict(&obs).await.expect("prediction");
        assert_eq!(p.actions, vec![AgentAction::Pyautogui("pyautogui.click(1, 2)".into())]);
        assert!(p.marks.is_some(), "the Set-of-Marks boxes were asked for");
        assert_eq!(decodes_on_this_thread() - before, 1, "step {step}");
    }
}
