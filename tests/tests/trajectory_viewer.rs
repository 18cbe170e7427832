//! The trajectory viewer in a real headless Chromium: a computer-use episode
//! (Anthropic's `computer` tool, against a local mock of the Messages API that
//! checks every request's shape) on the embedded stub guest, then the task's
//! `traj.html` opened over the DevTools protocol. What the rendered page shows is
//! compared with what the records say: the model's text (a `<script>` in it
//! shows as text and does not run), a click marker where the recorded click
//! landed (measured on the laid-out page and seen in a screenshot of it), the
//! step's tokens, and the keys that move between steps.
//!
//! Without Chromium the test prints `SKIPPED: ...` (a failure with
//! `ARENA_REQUIRE_CHROMIUM=1`).

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use axum::extract::State;
use axum::http::HeaderMap;
use axum::routing::post;
use axum::{Json, Router};
use futures_util::{SinkExt as _, StreamExt as _};
use serde_json::{json, Value};
use tokio_tungstenite::tungstenite::Message;

use arena_agents::cu::anthropic::{AnthropicAgent, AnthropicConfig};
use arena_agents::cu::models::Form;
use arena_client::cache::DownloadCache;
use arena_client::client::{ClientConfig, GuestClient};
use arena_exec::AgentAction;
use arena_host::episode::{run_episode, EpisodeConfig};
use arena_host::run::load_tasks;
use arena_results::{RunLayout, TRAJ_HTML};
use arena_shared::action::Action;
use arena_task::{Difficulty, Task};
use arena_test_support::StubGuest;

const KEY: &str = "test-key";
/// What the model says in its first step, a script tag included.
const FIRST_TEXT: &str = "I click the text box. <script>window.injected = 1</script>";

/// A request the mock got: its headers and body.
type Request = (HeaderMap, Value);

/// The Messages API mock: answers its replies in order and keeps each request.
#[derive(Clone, Default)]
struct Mock(Arc<Mutex<(Vec<Value>, Vec<Request>)>>);

async fn answer(State(mock): State<Mock>, headers: HeaderMap, Json(body): Json<Value>) -> Json<Value> {
    let mut script = mock.0.lock().expect("the mock's lock");
    script.1.push((headers, body));
    let reply = if script.0.is_empty() { end_turn("Nothing left to do. DONE", 1, 1) } else { script.0.remove(0) };
    Json(reply)
}

/// A Messages API answer: `text`, then a `computer` tool call with `input`, costing `tokens` (in, out).
fn tool_use(id: &str, text: &str, input: Value, tokens: (u64, u64)) -> Value {
    json!({
        "id": format!("msg_{id}"), "type": "message", "role": "assistant", "model": "claude-test",
        "content": [
            {"type": "text", "text": text},
            {"type": "tool_use", "id": id, "name": "computer", "input": input},
        ],
        "stop_reason": "tool_use", "usage": {"input_tokens": tokens.0, "output_tokens": tokens.1},
    })
}

fn end_turn(text: &str, input: u64, output: u64) -> Value {
    json!({
        "id": "msg_end", "type": "message", "role": "assistant", "model": "claude-test",
        "content": [{"type": "text", "text": text}],
        "stop_reason": "end_turn", "usage": {"input_tokens": input, "output_tokens": output},
    })
}

fn stub_task(name: &str) -> Task {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tasks/stub");
    let tasks = load_tasks(&dir, Difficulty::Normal).expect("the stub tasks load");
    tasks.into_iter().find(|t| t.name == name).expect("the stub task")
}

/// Runs the draft task with Anthropic's computer-use agent against the mock on an
/// in-process stub guest (five steps: solved), then the infeasible task (the mock,
/// its script used up, says DONE: failed by the agent); answers the draft's
/// folder and the requests of each episode.
async fn computer_use_episodes(root: &Path) -> (PathBuf, Vec<Vec<Request>>) {
    let replies = vec![
        tool_use("toolu_1", FIRST_TEXT, json!({"action": "left_click", "coordinate": [640, 400]}), (1234, 56)),
        tool_use(
            "toolu_2",
            "Scrolling down.",
            json!({"action": "scroll", "coordinate": [320, 200], "scroll_direction": "down", "scroll_amount": 3}),
            (1500, 40),
        ),
        tool_use("toolu_3", "Typing.", json!({"action": "type", "text": "This is a draft."}), (1600, 30)),
        tool_use("toolu_4", "Saving.", json!({"action": "key", "text": "ctrl+s"}), (1700, 20)),
        end_turn("The draft is saved. DONE", 1800, 10),
    ];
    let mock = Mock(Arc::new(Mutex::new((replies, Vec::new()))));
    let app = Router::new().route("/v1/messages", post(answer)).with_state(mock.clone());
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.expect("bind");
    let base = format!("http://{}", listener.local_addr().expect("addr"));
    tokio::spawn(async move { axum::serve(listener, app).await.expect("the mock serves") });

    let agent = || {
        let mut config = AnthropicConfig::new(&base, "claude-test");
        config.endpoint.api_key = Some(KEY.into());
        config.tool = Form::Computer20250124;
        AnthropicAgent::new(config).expect("agent")
    };
    let guest = StubGuest::start().await;
    let client =
        GuestClient::new(guest.url(), ClientConfig { token: None, timeout: Duration::from_secs(20), retries: 1 })
            .expect("client");
    let mut episode = EpisodeConfig::instant(DownloadCache::new(root.join("cache")).expect("cache"));
    episode.max_steps = 8;
    episode.max_model_retries = 0;
    let layout = RunLayout {
        root: root.to_owned(),
        agent: "anthropic_computer".into(),
        observation: "screenshot".into(),
        model: "claude-test".into(),
        trial: "0".into(),
    };
    let mut requests = Vec::new();
    let mut dirs = Vec::new();
    for (name, steps, score) in [("stub-notepad-draft", 5, 1.0), ("stub-settings-infeasible", 1, 0.0)] {
        let task = stub_task(name);
        let dir = layout.task_dir(&task);
        let result = run_episode(&client, &task, &mut agent(), &episode, &dir).await;
        assert_eq!((result.steps, result.score), (steps, score), "{result:?}");
        requests.push(std::mem::take(&mut mock.0.lock().expect("the mock's lock").1));
        dirs.push(dir.path().to_owned());
    }
    (dirs.swap_remove(0), requests)
}

/// Each request is a Messages API request for the `computer` tool (anthropic-python's types).
fn check_requests(requests: &[Request], steps: usize) {
    assert_eq!(requests.len(), steps);
    for (n, (headers, body)) in requests.iter().enumerate() {
        let header = |name: &str| headers.get(name).and_then(|v| v.to_str().ok()).unwrap_or_default().to_owned();
        assert_eq!(header("x-api-key"), KEY);
        assert_eq!(header("anthropic-version"), "2023-06-01");
        assert_eq!(header("anthropic-beta"), "computer-use-2025-01-24");
        assert_eq!(body["model"], "claude-test");
        let tool = &body["tools"][0];
        assert_eq!((tool["type"].as_str(), tool["name"].as_str()), (Some("computer_20250124"), Some("computer")));
        assert_eq!((tool["display_width_px"].as_u64(), tool["display_height_px"].as_u64()), (Some(1280), Some(800)));
        let messages = body["messages"].as_array().expect("messages");
        assert_eq!(messages.len(), 2 * n + 1, "request {n}: one user turn per step");
        assert_eq!(messages.last().expect("a turn")["role"], "user");
    }
}

/// A headless Chromium on a blank page, the size the pages are checked at.
struct Browser(arena_test_support::Chromium);

impl Browser {
    async fn start(binary: &Path) -> Browser {
        let args = ["--hide-scrollbars", "--window-size=1600,1000", "--force-device-scale-factor=1"];
        Browser(arena_test_support::Chromium::start(binary, &args, "about:blank").await)
    }

    /// A DevTools session with the page whose address ends with `suffix`.
    async fn page(&self, suffix: &str) -> Page {
        let list: Vec<Value> = reqwest::get(format!("http://127.0.0.1:{}/json/list", self.0.port))
            .await
            .expect("json/list")
            .json()
            .await
            .expect("json/list is JSON");
        let ws = list
            .iter()
            .find(|t| t["type"] == "page" && t["url"].as_str().is_some_and(|u| u.ends_with(suffix)))
            .and_then(|t| t["webSocketDebuggerUrl"].as_str())
            .unwrap_or_else(|| panic!("no page at {suffix} in {list:?}"))
            .to_owned();
        let (socket, _) = tokio_tungstenite::connect_async(ws.as_str()).await.expect("the page's DevTools socket");
        Page { socket, id: 0 }
    }
}

/// One page's DevTools socket: a command at a time, events ignored.
struct Page {
    socket: tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>,
    id: u64,
}

impl Page {
    async fn call(&mut self, method: &str, params: Value) -> Value {
        let answer = self.try_call(method, params).await;
        assert!(answer.get("error").is_none(), "{method}: {answer}");
        answer["result"].clone()
    }

    /// Opens `url` and waits until its document is complete (a page that is
    /// still navigating answers an evaluation with an error: it is asked again).
    async fn open(&mut self, url: &str) {
        self.call("Page.navigate", json!({"url": url})).await;
        let check = "location.href + ' ' + document.readyState";
        let want = format!("{url} complete");
        let deadline = std::time::Instant::now() + Duration::from_secs(20);
        loop {
            let answer = self.try_call("Runtime.evaluate", json!({"expression": check, "returnByValue": true})).await;
            if answer["result"]["result"]["value"].as_str() == Some(want.as_str()) {
                return;
            }
            assert!(std::time::Instant::now() < deadline, "{url} did not load: {answer}");
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }

    /// A command's whole answer, its error included.
    async fn try_call(&mut self, method: &str, params: Value) -> Value {
        self.id += 1;
        let id = self.id;
        let text = json!({"id": id, "method": method, "params": params}).to_string();
        self.socket.send(Message::text(text)).await.expect("send a command");
        let answer = tokio::time::timeout(Duration::from_secs(30), async {
            loop {
                let message = self.socket.next().await.expect("the socket is open").expect("a message");
                let Message::Text(text) = message else { continue };
                let value: Value = serde_json::from_str(text.as_str()).expect("CDP speaks JSON");
                if value["id"] == id {
                    return value;
                }
            }
        })
        .await
        .unwrap_or_else(|_| panic!("{method}: no answer"));
        answer
    }

    /// The value of a script (a promise is awaited).
    async fn eval(&mut self, expression: &str) -> Value {
        let result = self
            .call("Runtime.evaluate", json!({"expression": expression, "awaitPromise": true, "returnByValue": true}))
            .await;
        assert!(result.get("exceptionDetails").is_none(), "{expression}: {result}");
        result["result"]["value"].clone()
    }

    async fn key(&mut self, key: &str, code: &str, key_code: u32) {
        for kind in ["keyDown", "keyUp"] {
            self.call(
                "Input.dispatchKeyEvent",
                json!({"type": kind, "key": key, "code": code, "windowsVirtualKeyCode": key_code}),
            )
            .await;
        }
    }
}

/// Waits for the page, brings step `n` into view, waits for its image and measures it:
/// the click marker's centre in the screenshot's pixels (from the laid-out
/// marker and image) and in the viewport, the image's natural size, the texts.
const MEASURE: &str = r#"(n) => new Promise(function (resolve) {
  var step, img;
  function ready() {
    if (document.readyState !== "complete") { return false; }
    if (!step) {
      step = document.querySelector('.step[data-step="' + n + '"]');
      step.scrollIntoView({block: "start"});
      img = step.querySelector(".shot img");
    }
    return img.complete && img.naturalWidth > 0;
  }
  function measure() {
    var mark = step.querySelector('.mark[data-kind="click"]');
    var ir = img.getBoundingClientRect();
    var dr = mark.querySelector("circle.dot").getBoundingClientRect();
    var cx = dr.left + dr.width / 2, cy = dr.top + dr.height / 2;
    resolve({
      natural: [img.naturalWidth, img.naturalHeight],
      marker: [(cx - ir.left) * img.naturalWidth / ir.width, (cy - ir.top) * img.naturalHeight / ir.height],
      viewport: [cx, cy],
      data: [Number(mark.getAttribute("data-x")), Number(mark.getAttribute("data-y"))],
      reply: step.querySelector("pre.reply").textContent,
      tokens: step.querySelector(".tokens").textContent,
      scripts: document.scripts.length,
      injected: typeof window.injected
    });
  }
  (function poll() { if (ready()) { measure(); } else { setTimeout(poll, 20); } })();
})"#;

#[tokio::test]
async fn a_computer_use_task_page_shows_the_models_text_a_click_marker_where_it_was_recorded_and_the_tokens() {
    let test = "a_computer_use_task_page_shows_the_models_text_a_click_marker_where_it_was_recorded_and_the_tokens";
    let Some(binary) = arena_test_support::chromium_or_skip(test) else {
        return;
    };
    let tmp = tempfile::tempdir().expect("tmp");
    let (dir, requests) = computer_use_episodes(tmp.path()).await;
    check_requests(&requests[0], 5);
    check_requests(&requests[1], 1);

    // What the records say about step 1: the click in screen pixels (the model's
    // (640, 400) on its 1280x800 image is (720, 450) on the 1440x900 screen), its tokens.
    let traj = std::fs::read_to_string(dir.join("traj.jsonl")).expect("traj.jsonl");
    let step: Value = traj
        .lines()
        .map(|l| serde_json::from_str::<Value>(l).expect("a JSON line"))
        .find(|l| l["step"] == 1)
        .expect("step 1");
    let actions: Vec<AgentAction> = serde_json::from_value(step["actions"].clone()).expect("actions");
    let clicked = actions
        .iter()
        .flat_map(|a| match a {
            AgentAction::Typed(typed) => typed.clone(),
            _ => Vec::new(),
        })
        .find_map(|a| match a {
            Action::Click { x: Some(x), y: Some(y), .. } => Some((x, y)),
            _ => None,
        })
        .expect("a click with its position in step 1");
    assert_eq!(clicked, (720, 450));
    let shot = image::image_dimensions(dir.join(step["screenshot_file"].as_str().expect("screenshot"))).expect("png");
    assert_eq!(step["screen"], json!([shot.0, shot.1]), "the screen the actions are measured on is the screenshot's");
    let (input, output) = (step["usage"]["input"].as_u64(), step["usage"]["output"].as_u64());
    assert_eq!((input, output), (Some(1234), Some(56)));
    // The vendor's answer is a record named in `log_response`, beside the model's text in `response`.
    assert!(step["log_response"].as_str().is_some_and(|r| r.starts_with("response-step_0_")), "{step}");
    assert!(step["response"].as_str().is_some_and(|r| !r.starts_with("response-step_")), "{step}");
    assert_eq!(traj.matches("\"response\":").count(), traj.lines().filter(|l| l.contains("\"step\":")).count());

    let page_file = dir.join(TRAJ_HTML);
    let url = format!("file://{}", page_file.display());
    let browser = Browser::start(&binary).await;
    let mut page = browser.page("about:blank").await;
    page.open(&url).await;
    let m = page.eval(&format!("({MEASURE})(1)")).await;

    // The model's text, the script tag shown as text and not run; the page's own script alone.
    assert_eq!(m["reply"], FIRST_TEXT, "{m}");
    assert_eq!((m["injected"].as_str(), m["scripts"].as_u64()), (Some("undefined"), Some(1)), "{m}");
    // The screenshot loaded at its natural size (the page's policy lets the folder's images in).
    assert_eq!(
        (m["natural"][0].as_u64(), m["natural"][1].as_u64()),
        (Some(u64::from(shot.0)), Some(u64::from(shot.1)))
    );
    // The marker's centre, measured on the laid-out page, is the recorded click.
    let at = |v: &Value, i: usize| v[i].as_f64().expect("a number");
    let (mx, my) = (at(&m["marker"], 0), at(&m["marker"], 1));
    assert!(
        (mx - f64::from(clicked.0)).abs() <= 1.5 && (my - f64::from(clicked.1)).abs() <= 1.5,
        "the marker is at ({mx:.1}, {my:.1}), the click was at {clicked:?}"
    );
    assert_eq!((at(&m["data"], 0), at(&m["data"], 1)), (f64::from(clicked.0), f64::from(clicked.1)));
    // The step's tokens as recorded.
    let tokens = m["tokens"].as_str().expect("tokens");
    assert!(tokens.contains("1234 in") && tokens.contains("56 out"), "{tokens}");

    // A screenshot of the page shows the marker's colour where the page put it.
    let shot = page.call("Page.captureScreenshot", json!({"format": "png"})).await;
    let png = base64::Engine::decode(&base64::engine::general_purpose::STANDARD, shot["data"].as_str().expect("data"))
        .expect("base64");
    let picture = image::load_from_memory(&png).expect("a PNG").to_rgba8();
    let (vx, vy) = (at(&m["viewport"], 0).round() as u32, at(&m["viewport"], 1).round() as u32);
    let pixel = picture.get_pixel(vx, vy).0;
    let near = |a: u8, b: u8| a.abs_diff(b) <= 12;
    assert!(
        near(pixel[0], 0xe3) && near(pixel[1], 0x00) && near(pixel[2], 0x8c),
        "the pixel at the marker ({vx}, {vy}) is {pixel:?}, not the click marker's colour"
    );
    if let Some(keep) = std::env::var_os("ARENA_KEEP_VIEWER_SHOT") {
        std::fs::write(&keep, &png).expect("keeping the screenshot");
    }

    // The keys move between steps: j, j, k, then the right arrow.
    let current = "document.querySelector('.step.current') && document.querySelector('.step.current').dataset.step";
    let mut seen = Vec::new();
    for (key, code, key_code) in
        [("j", "KeyJ", 74), ("j", "KeyJ", 74), ("k", "KeyK", 75), ("ArrowRight", "ArrowRight", 39)]
    {
        page.key(key, code, key_code).await;
        seen.push(page.eval(current).await);
    }
    assert_eq!(seen, [json!("1"), json!("2"), json!("1"), json!("2")]);
    let help = page.eval("document.getElementById('keys').textContent").await;
    assert!(help.as_str().is_some_and(|h| h.contains("j") && h.contains("next")), "{help}");

    // The run's report filters its tasks by domain, status and "Failed by".
    let (summary, report) = arena_results::html::write_report(tmp.path(), "viewer").expect("the report");
    assert_eq!(summary.overall.tasks, 2);
    page.open(&format!("file://{}", report.display())).await;
    let choose = |name: &str, value: &str| {
        format!(
            "(function () {{ var s = document.querySelector('#filter select[name=\"{name}\"]'); s.value = '{value}';\
             s.dispatchEvent(new Event('change', {{ bubbles: true }})); var rows = document.querySelectorAll('#tasks tbody tr');\
             return [document.getElementById('filter-count').textContent,\
               Array.prototype.filter.call(rows, function (r) {{ return !r.hidden; }}).map(function (r) {{ return r.cells[0].textContent; }}),\
               Array.prototype.filter.call(document.querySelectorAll('details[data-task]'), function (d) {{ return d.getClientRects().length > 0; }}).length]; }})()"
        )
    };
    assert_eq!(page.eval(&choose("domain", "")).await, json!(["2 of 2 tasks shown", ["notepad", "settings"], 2]));
    assert_eq!(page.eval(&choose("domain", "settings")).await, json!(["1 of 2 tasks shown", ["settings"], 1]));
    assert_eq!(page.eval(&choose("domain", "")).await, json!(["2 of 2 tasks shown", ["notepad", "settings"], 2]));
    assert_eq!(page.eval(&choose("failed-by", "-")).await, json!(["1 of 2 tasks shown", ["notepad"], 1]));
    assert_eq!(page.eval(&choose("failed-by", "agent")).await, json!(["1 of 2 tasks shown", ["settings"], 1]));
    assert_eq!(page.eval(&choose("domain", "notepad")).await, json!(["0 of 2 tasks shown", [], 0]));
    // A task's link in the table opens its section.
    let follow = "new Promise(function (resolve) { var a = document.querySelector('#tasks a');\
        var target = document.getElementById(a.getAttribute('href').slice(1)); var before = target.open;\
        addEventListener('hashchange', function () { resolve([before, target.open]); }, {once: true}); a.click(); })";
    assert_eq!(page.eval(follow).await, json!([false, true]));
}
