//! `arena run --agent mcp` end to end: the real binary serves MCP, a client
//! written with the official Rust SDK (`rmcp`) plays two stub tasks through the
//! tools, a bad argument is a tool error on a session that lives on, the tool
//! list has the documented names, and the bearer token is checked (refused without it);
//! and `arena-guest --mcp`, the guest as an MCP server on its own: its own tools
//! (programs, windows, the clipboard, numbered elements, the shell only with
//! `--mcp-shell`), the official Python SDK driving Notepad through them and ending its
//! session without a complaint, and the tool table of docs/agents.md against `tools/list`.

#![cfg(unix)]

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use arena_results::summary::Summary;
use arena_shared::mcp_tools::{self, GUEST_ONLY};
use arena_test_support::workspace_binary;
use rmcp::model::{CallToolRequestParams, CallToolResult, ClientConfig, ProtocolVersion};
use rmcp::service::RunningService;
use rmcp::transport::streamable_http_client::StreamableHttpClientTransportConfig;
use rmcp::transport::StreamableHttpClientTransport;
use rmcp::{RoleClient, ServiceExt};
use serde_json::{json, Value};

const TOKEN: &str = "mcp-test-token";

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Two stub tasks in a task folder of their own.
fn two_tasks(root: &Path) -> PathBuf {
    for name in ["stub-notepad-count", "stub-notepad-draft"] {
        arena_test_support::copy_stub_task("notepad", name, &root.join("tasks/notepad"));
    }
    root.join("tasks")
}

/// `arena run --agent mcp` on one stub guest; answers the child and its MCP URL.
pub(crate) fn start_run(tasks: &Path, out: &Path) -> (Child, String) {
    start_run_with(tasks, out, Stdio::inherit())
}

/// [`start_run`] with the run's stderr sent to `stderr`.
fn start_run_with(tasks: &Path, out: &Path, stderr: Stdio) -> (Child, String) {
    let exe = workspace_binary("arena-host", "arena").expect("the arena binary");
    let mut child = Command::new(exe)
        .args(["run", "--stub-guests", "1", "--pauses", "fast", "--agent", "mcp", "--mcp-listen", "127.0.0.1:0"])
        .args(["--mcp-token", TOKEN, "--agent-timeout", "60", "--tasks"])
        .arg(tasks)
        .arg("--out")
        .arg(out)
        .stdout(Stdio::piped())
        .stderr(stderr)
        .spawn()
        .expect("arena run starts");
    let mut lines = BufReader::new(child.stdout.take().expect("stdout")).lines();
    let deadline = Instant::now() + Duration::from_secs(60);
    let url = loop {
        assert!(Instant::now() < deadline, "arena run did not say where MCP is served");
        let line = lines.next().expect("a line").expect("text");
        if let Some(url) = line.strip_prefix("MCP endpoint: ") {
            break url.trim().to_owned();
        }
    };
    std::thread::spawn(move || lines.for_each(drop));
    (child, url)
}

async fn connect(url: &str) -> RunningService<RoleClient, ClientConfig> {
    connect_with(url, TOKEN).await
}

async fn connect_with(url: &str, token: &str) -> RunningService<RoleClient, ClientConfig> {
    let transport = StreamableHttpClientTransport::from_config(
        StreamableHttpClientTransportConfig::with_uri(url).auth_header(token),
    );
    ClientConfig::default()
        .with_protocol_version(ProtocolVersion::V_2025_06_18)
        .serve(transport)
        .await
        .expect("the MCP session starts")
}

async fn call(client: &RunningService<RoleClient, ClientConfig>, tool: &str, args: Value) -> CallToolResult {
    let Value::Object(args) = args else { panic!("arguments are an object") };
    client
        .call_tool(CallToolRequestParams::new(tool.to_owned()).with_arguments(args))
        .await
        .unwrap_or_else(|e| panic!("{tool}: {e}"))
}

/// The desktop tools, in the order `tools/list` gives them.
const DESKTOP_TOOLS: [&str; 12] = [
    "screenshot",
    "accessibility_tree",
    "list_windows",
    "click",
    "double_click",
    "move",
    "drag",
    "scroll",
    "type_text",
    "press_keys",
    "run_python",
    "wait",
];

/// Asserts that `url` checks the bearer token as every server of the project does
/// (`arena_shared::token::bearer_matches`): no header and a wrong token of the right
/// length are refused with 401; the right token passes with the scheme in any case.
async fn assert_bearer_checked(url: &str, token: &str) {
    let status = |authorization: Option<String>| async move {
        let mut request = reqwest::Client::new()
            .post(url)
            .header("Content-Type", "application/json")
            .header("Accept", "application/json, text/event-stream")
            .body(r#"{"jsonrpc":"2.0","id":1,"method":"tools/list"}"#);
        if let Some(value) = authorization {
            request = request.header("Authorization", value);
        }
        request.send().await.expect("an answer").status().as_u16()
    };
    assert_eq!(status(None).await, 401, "no token, no MCP");
    let mut wrong = token.to_owned();
    let last = if wrong.ends_with('x') { 'y' } else { 'x' };
    wrong.pop();
    wrong.push(last);
    assert_eq!(status(Some(format!("Bearer {wrong}"))).await, 401, "a wrong token of the same length");
    for scheme in ["bearer", "BEARER"] {
        let passed = status(Some(format!("{scheme} {token}"))).await;
        assert_ne!(passed, 401, "the scheme is case-insensitive (RFC 7235): {scheme}");
    }
}

async fn tool_names(client: &RunningService<RoleClient, ClientConfig>) -> Vec<String> {
    client.list_all_tools().await.expect("tools/list").iter().map(|t| t.name.to_string()).collect()
}

/// Asserts that a `screenshot` answer is one PNG image.
fn assert_png(shot: &CallToolResult) {
    let image = serde_json::to_value(&shot.content[0]).expect("content");
    assert_eq!((image["type"].as_str(), image["mimeType"].as_str()), (Some("image"), Some("image/png")), "{image}");
    let png = base64::Engine::decode(&base64::engine::general_purpose::STANDARD, image["data"].as_str().expect("data"))
        .expect("base64");
    assert!(png.starts_with(b"\x89PNG"), "a PNG");
}

fn text_of(result: &CallToolResult) -> String {
    result
        .content
        .iter()
        .filter_map(|c| serde_json::to_value(c).ok())
        .filter_map(|c| c["text"].as_str().map(str::to_owned))
        .collect::<Vec<_>>()
        .join("\n")
}

fn json_of(result: &CallToolResult) -> Value {
    serde_json::from_str(&text_of(result)).unwrap_or_else(|e| panic!("JSON text: {e}: {result:?}"))
}

fn wait_exit(mut child: Child, within: Duration) -> std::process::ExitStatus {
    let deadline = Instant::now() + within;
    loop {
        if let Some(status) = child.try_wait().expect("wait") {
            return status;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            panic!("arena run did not finish within {within:?}");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

#[tokio::test(flavor = "multi_thread")]
async fn an_rmcp_client_plays_two_stub_tasks() {
    let tmp = tempfile::tempdir().expect("tmp");
    let (tasks, out) = (two_tasks(tmp.path()), tmp.path().join("out"));
    let (child, url) = start_run(&tasks, &out);

    assert_bearer_checked(&url, TOKEN).await;

    let client = connect(&url).await;
    let mut expected = vec!["get_task"];
    expected.extend(DESKTOP_TOOLS);
    expected.extend(["done", "fail"]);
    assert_eq!(tool_names(&client).await, expected);

    // An action before any task is a tool error.
    let early = call(&client, "type_text", json!({"text": "x"})).await;
    assert_eq!(early.is_error, Some(true), "{early:?}");

    let mut played = Vec::new();
    loop {
        let task = json_of(&call(&client, "get_task", json!({})).await);
        let Some(name) = task["task_id"].as_str().map(str::to_owned) else { break };
        assert!(task["instruction"].as_str().is_some_and(|s| !s.is_empty()), "{task}");
        assert!(task["screen_width"].as_u64().is_some_and(|w| w > 0) && task["steps_left"] == json!(15), "{task}");

        assert_png(&call(&client, "screenshot", json!({})).await);
        let tree = call(&client, "accessibility_tree", json!({"backend": "uia"})).await;
        assert!(text_of(&tree).starts_with("<desktop"), "{tree:?}");
        let windows = json_of(&call(&client, "list_windows", json!({})).await);
        assert!(windows["windows"].as_array().is_some_and(|w| !w.is_empty()), "{windows}");

        // A bad argument is a tool error naming it, and the session goes on.
        let bad = call(&client, "click", json!({"x": "left", "y": 3})).await;
        assert_eq!(bad.is_error, Some(true), "{bad:?}");
        assert!(text_of(&bad).contains("x must be an integer"), "{bad:?}");

        let text = if name.contains("count") || task["instruction"].as_str().unwrap_or("").contains("count") {
            "3"
        } else {
            "This is a draft."
        };
        let typed = json_of(&call(&client, "type_text", json!({"text": text})).await);
        assert_eq!(typed["ok"], json!(true), "{typed}");
        let saved = json_of(&call(&client, "press_keys", json!({"keys": ["ctrl", "s"]})).await);
        assert_eq!(saved["steps_left"], json!(13), "{saved}");
        let ended = json_of(&call(&client, "done", json!({})).await);
        assert_eq!(ended["episode_ended"], json!(true), "{ended}");
        assert_eq!(ended["result"]["score"], json!(1.0), "the task is solved: {ended}");
        played.push(name);
    }
    assert_eq!(played.len(), 2, "two tasks played: {played:?}");
    let _ = client.cancel().await;

    let status = wait_exit(child, Duration::from_secs(60));
    assert!(status.success(), "arena run: {status:?}");
    let summary = Summary::from_dir(&out).expect("summary");
    assert_eq!(summary.tasks.len(), 2);
    for task in &summary.tasks {
        assert_eq!((task.status.as_str(), task.score), ("completed", Some(1.0)), "{task:?}");
        // Each action tool call is a step (reading tools are not).
        assert_eq!(task.steps, 3, "{task:?}");
    }
}

#[test]
fn the_python_mcp_example_plays_two_stub_tasks() {
    let Some(python) = arena_test_support::python_with_mcp("the_python_mcp_example_plays_two_stub_tasks") else {
        return;
    };
    let tmp = tempfile::tempdir().expect("tmp");
    let tasks = tmp.path().join("tasks/mixed");
    for (domain, name) in [("notepad", "stub-notepad-draft"), ("settings", "stub-settings-infeasible")] {
        arena_test_support::copy_stub_task(domain, name, &tasks);
    }
    let out = tmp.path().join("out");
    let (child, url) = start_run(&tmp.path().join("tasks"), &out);
    let played = Command::new(python)
        .arg(repo().join("examples/mcp_agent.py"))
        .args([url.as_str(), TOKEN])
        .output()
        .expect("the example runs");
    let said = String::from_utf8_lossy(&played.stdout);
    let stderr = String::from_utf8_lossy(&played.stderr);
    assert!(played.status.success(), "{said}\n{stderr}");
    // The endpoint answers the session's DELETE as the SDK expects (arena_mcp::HttpStatuses).
    assert!(!stderr.contains("Session termination failed"), "{stderr}");
    assert!(said.contains("stub-notepad-draft: 1.0") && said.contains("stub-settings-infeasible: 1.0"), "{said}");
    assert!(wait_exit(child, Duration::from_secs(60)).success());
    let summary = Summary::from_dir(&out).expect("summary");
    assert!(summary.tasks.iter().all(|t| t.score == Some(1.0)), "{:?}", summary.tasks);
}

const GUEST_TOKEN: &str = "guest-secret-token-0123";

/// `arena-guest --mcp` on the stub with `more` options; answers it and its MCP URL.
fn guest_mcp(more: &[&str]) -> (arena_test_support::Served, String) {
    let mut args = vec!["--mcp", "--token", GUEST_TOKEN];
    args.extend_from_slice(more);
    let guest = arena_test_support::Served::guest(&args).expect("arena-guest --mcp");
    let url = format!("{}/mcp", guest.url.trim_end_matches('/'));
    (guest, url)
}

/// A call that must succeed, its JSON text parsed.
async fn ok(client: &RunningService<RoleClient, ClientConfig>, tool: &str, args: Value) -> Value {
    let answer = call(client, tool, args).await;
    assert_ne!(answer.is_error, Some(true), "{tool}: {answer:?}");
    json_of(&answer)
}

/// A call that must fail, its message.
async fn refused(client: &RunningService<RoleClient, ClientConfig>, tool: &str, args: Value) -> String {
    let answer = call(client, tool, args).await;
    assert_eq!(answer.is_error, Some(true), "{tool} should fail: {answer:?}");
    text_of(&answer)
}

/// The guest's tools as the one table (`arena_shared::mcp_tools::tool_list`) gives them.
fn guest_tool_table() -> Vec<&'static str> {
    mcp_tools::tool_list(false).into_iter().map(|(name, _, _)| name).collect()
}

#[tokio::test(flavor = "multi_thread")]
async fn the_guest_serves_mcp_behind_its_token() {
    let (_guest, url) = guest_mcp(&[]);

    assert_bearer_checked(&url, GUEST_TOKEN).await;

    let client = connect_with(&url, GUEST_TOKEN).await;
    let mut expected: Vec<&str> = DESKTOP_TOOLS.to_vec();
    expected.extend(GUEST_ONLY);
    assert_eq!(guest_tool_table(), expected, "the desktop tools, then the guest's own");
    assert_eq!(
        tool_names(&client).await,
        expected,
        "the desktop tools and the guest's own, without the task and decision tools"
    );
    assert_png(&call(&client, "screenshot", json!({})).await);
    ok(&client, "type_text", json!({"text": "hello"})).await;
    let bad = refused(&client, "get_task", json!({})).await;
    assert!(bad.contains("unknown tool \"get_task\""), "no task tools on the guest: {bad}");
    let ran = ok(&client, "run_python", json!({"code": "print(pyautogui.size())"})).await;
    assert_eq!(ran["exit_code"], json!(0), "{ran}");
    let _ = client.cancel().await;
}

/// The JSON-RPC message of an MCP HTTP answer, whether sent as JSON or as an SSE event.
fn rpc_answer(body: &str) -> Value {
    let data = body.lines().filter_map(|l| l.strip_prefix("data:")).map(str::trim).find(|d| d.starts_with('{'));
    serde_json::from_str(data.unwrap_or(body)).unwrap_or_else(|e| panic!("an MCP answer: {e}: {body}"))
}

/// A client that speaks MCP over plain HTTP, holds the session's standalone stream
/// open, takes a task with `get_task`, then vanishes without ending its session:
/// what a crashed agent process leaves behind. Answers the task it was given.
async fn take_a_task_and_vanish(url: &str) -> String {
    let http = reqwest::Client::new();
    let post = |session: Option<&str>, body: Value| {
        let mut request = http
            .post(url)
            .bearer_auth(TOKEN)
            .header("Accept", "application/json, text/event-stream")
            .header("MCP-Protocol-Version", "2025-06-18")
            .json(&body);
        if let Some(session) = session {
            request = request.header("Mcp-Session-Id", session);
        }
        request.send()
    };
    let init = post(
        None,
        json!({"jsonrpc": "2.0", "id": 1, "method": "initialize", "params": {
        "protocolVersion": "2025-06-18", "capabilities": {}, "clientInfo": {"name": "vanishing", "version": "0"}}}),
    )
    .await
    .expect("initialize");
    let session = init.headers()["mcp-session-id"].to_str().expect("a session id").to_owned();
    let _ = init.text().await;
    let initialized = post(Some(&session), json!({"jsonrpc": "2.0", "method": "notifications/initialized"}))
        .await
        .expect("initialized");
    assert!(initialized.status().is_success(), "{}", initialized.status());
    let stream = http
        .get(url)
        .bearer_auth(TOKEN)
        .header("Accept", "text/event-stream")
        .header("Mcp-Session-Id", &session)
        .header("MCP-Protocol-Version", "2025-06-18")
        .send()
        .await
        .expect("the standalone stream");
    assert_eq!(stream.status(), 200, "the standalone stream opens");
    let taken = post(
        Some(&session),
        json!({"jsonrpc": "2.0", "id": 2, "method": "tools/call",
        "params": {"name": "get_task", "arguments": {}}}),
    )
    .await
    .expect("get_task")
    .text()
    .await
    .expect("get_task's answer");
    let answer = rpc_answer(&taken);
    let task: Value = serde_json::from_str(answer["result"]["content"][0]["text"].as_str().expect("text"))
        .unwrap_or_else(|e| panic!("{e}: {answer}"));
    // Gone: the stream and every connection closed, no DELETE sent.
    drop(stream);
    drop(http);
    task["task_id"].as_str().expect("a task").to_owned()
}

/// Plays one stub notepad task with `client` (typing its answer, saving, done)
/// and answers its result.
async fn play_notepad_task(client: &RunningService<RoleClient, ClientConfig>, task: &Value) -> Value {
    let text = if task["instruction"].as_str().unwrap_or("").contains("count") { "3" } else { "This is a draft." };
    call(client, "type_text", json!({"text": text})).await;
    call(client, "press_keys", json!({"keys": ["ctrl", "s"]})).await;
    json_of(&call(client, "done", json!({})).await)
}

#[tokio::test(flavor = "multi_thread")]
async fn a_task_whose_mcp_session_went_away_before_acting_goes_to_the_next_session_within_seconds() {
    let tmp = tempfile::tempdir().expect("tmp");
    let (tasks, out) = (two_tasks(tmp.path()), tmp.path().join("out"));
    let log_path = tmp.path().join("run.stderr");
    let log = std::fs::File::create(&log_path).expect("a log file");
    let (child, url) = start_run_with(&tasks, &out, Stdio::from(log));

    // A client takes the first task and vanishes (stream lost, no DELETE).
    let first = take_a_task_and_vanish(&url).await;
    let player = connect(&url).await;
    let asked = Instant::now();
    let task = json_of(&call(&player, "get_task", json!({})).await);
    let waited = asked.elapsed();
    assert_eq!(task["task_id"].as_str(), Some(first.as_str()), "the vanished client's task is handed on: {task}");
    assert!(waited < Duration::from_secs(20), "handed back after {waited:?}, not the --agent-timeout of 60 s");
    assert_eq!(task["steps_left"], json!(15), "nothing was spent: {task}");
    let ended = play_notepad_task(&player, &task).await;
    assert_eq!(ended["result"]["score"], json!(1.0), "{ended}");

    // A client that ends its session (DELETE) after taking a task hands it back at once.
    let quitter = connect(&url).await;
    let second = json_of(&call(&quitter, "get_task", json!({})).await);
    let second_id = second["task_id"].as_str().expect("a second task").to_owned();
    let _ = quitter.cancel().await;
    let asked = Instant::now();
    let task = json_of(&call(&player, "get_task", json!({})).await);
    assert_eq!(task["task_id"].as_str(), Some(second_id.as_str()), "{task}");
    assert!(asked.elapsed() < Duration::from_secs(10), "handed back after {:?}", asked.elapsed());
    let ended = play_notepad_task(&player, &task).await;
    assert_eq!(ended["result"]["score"], json!(1.0), "{ended}");
    let none = json_of(&call(&player, "get_task", json!({})).await);
    assert_eq!(none["task_id"], Value::Null, "{none}");
    let _ = player.cancel().await;

    assert!(wait_exit(child, Duration::from_secs(60)).success());
    let summary = Summary::from_dir(&out).expect("summary");
    assert_eq!(summary.tasks.len(), 2);
    for task in &summary.tasks {
        assert_eq!((task.status.as_str(), task.score, task.steps), ("completed", Some(1.0), 3), "{task:?}");
    }
    let log = std::fs::read_to_string(&log_path).expect("the run's stderr");
    assert!(log.contains("opened") && log.contains("lost its stream"), "sessions are said: {log}");
    assert_eq!(log.matches("went away before acting; the task goes back to the queue").count(), 2, "{log}");
}

/// The guest's section of docs/agents.md has one row per guest-only tool, in the
/// table's order, and names each of its arguments.
#[test]
fn the_guest_tools_are_documented_as_the_table_has_them() {
    let doc = std::fs::read_to_string(repo().join("docs/agents.md")).expect("docs/agents.md");
    let section = doc.split("\n## The guest as an MCP server\n").nth(1).expect("the guest's section");
    // Up to the next heading: the comparison with Windows-MCP that follows has a table too.
    let section = section.split("\n#").next().expect("its text");
    let rows: Vec<(&str, &str)> =
        section.lines().filter_map(|line| line.strip_prefix("| `")).filter_map(|line| line.split_once("` |")).collect();
    let names: Vec<&str> = rows.iter().map(|(name, _)| *name).collect();
    assert_eq!(names, GUEST_ONLY, "the guest's tool table in docs/agents.md");
    for (name, _, schema) in mcp_tools::tool_list(false) {
        let Some((_, row)) = rows.iter().find(|(n, _)| *n == name) else { continue };
        let arguments = schema["properties"].as_object().expect("properties");
        for argument in arguments.keys() {
            assert!(
                row.contains(&format!("`{argument}`")),
                "docs/agents.md's row for {name} names `{argument}`: {row}"
            );
        }
    }
}

/// The guest's own tools on the stub: programs, windows, the clipboard and numbered
/// elements (typing through one, stale numbers refused, bad input checked as
/// `/v1/actions` checks it); `shell` refused without `--mcp-shell`.
#[tokio::test(flavor = "multi_thread")]
async fn the_guest_tools_drive_windows_programs_the_clipboard_and_elements() {
    let (_guest, url) = guest_mcp(&[]);
    let client = connect_with(&url, GUEST_TOKEN).await;

    let launched = ok(&client, "launch_app", json!({"name": "notepad"})).await;
    assert_eq!(launched["window"], json!("Untitled - Notepad"), "{launched}");
    let unknown = refused(&client, "launch_app", json!({"name": "no-such-program-xyz"})).await;
    assert!(unknown.contains("no program or Start menu shortcut is named \"no-such-program-xyz\""), "{unknown}");
    let shell_syntax = refused(&client, "launch_app", json!({"name": "notepad & calc"})).await;
    assert!(shell_syntax.contains("is not a program name"), "{shell_syntax}");
    let opened = ok(&client, "launch_app", json!({"name": "calc"})).await;
    assert_eq!(opened["window"], json!("Calculator"), "{opened}");

    // Notepad, behind Calculator, comes to the front by a part of its title.
    let switched = ok(&client, "switch_window", json!({"title": "notepad"})).await;
    assert_eq!(switched["window"], json!("Untitled - Notepad"), "{switched}");
    let windows = ok(&client, "list_windows", json!({})).await;
    assert_eq!(windows["foreground"], json!("Untitled - Notepad"), "{windows}");
    let missing = refused(&client, "switch_window", json!({"title": "Paint"})).await;
    assert!(missing.contains("no window is titled \"Paint\""), "{missing}");

    let resized =
        ok(&client, "resize_window", json!({"title": "Notepad", "x": 100, "y": 50, "width": 640, "height": 480})).await;
    assert_eq!(resized["rect"], json!({"x": 100, "y": 50, "width": 640, "height": 480}), "{resized}");
    let maximised = ok(&client, "resize_window", json!({"state": "maximized"})).await;
    assert_eq!(
        (maximised["window"].as_str(), maximised["maximized"].as_bool()),
        (Some("Untitled - Notepad"), Some(true))
    );
    let minimised = ok(&client, "resize_window", json!({"title": "Calculator", "state": "minimized"})).await;
    assert_eq!(minimised["minimized"], json!(true), "{minimised}");
    let desktop = refused(&client, "resize_window", json!({"title": "Program Manager", "width": 5})).await;
    assert!(desktop.contains("the desktop itself"), "{desktop}");

    assert_eq!(ok(&client, "clipboard_get", json!({})).await["format"], json!("empty"));
    ok(&client, "clipboard_set", json!({"text": "from the clipboard"})).await;
    let clip = ok(&client, "clipboard_get", json!({})).await;
    assert_eq!((clip["format"].as_str(), clip["text"].as_str()), (Some("text"), Some("from the clipboard")), "{clip}");

    // Numbered elements: the maximised Notepad's text area, then its Close button.
    let early = refused(&client, "click_element", json!({"element": 1})).await;
    assert!(early.contains("call state first"), "{early}");
    let state = ok(&client, "state", json!({})).await;
    assert_eq!(state["foreground"], json!("Untitled - Notepad"), "{state}");
    let elements = state["elements"].as_array().expect("elements");
    let find = |role: &str, name: &str| {
        elements
            .iter()
            .find(|e| {
                e["window"] == json!("Untitled - Notepad") && e["role"] == json!(role) && e["name"] == json!(name)
            })
            .unwrap_or_else(|| panic!("{role} {name:?} in {state}"))
            .clone()
    };
    let area = find("Document", "Text Editor");
    assert!(elements.iter().all(|e| e["window"] != json!("Calculator")), "a minimised window lists nothing: {state}");
    let number = area["element"].as_u64().expect("a number");
    ok(&client, "type_into_element", json!({"element": number, "text": "typed", "press_enter": true})).await;
    ok(&client, "type_into_element", json!({"element": number, "text": "again", "clear": true})).await;
    let tree = text_of(&call(&client, "accessibility_tree", json!({})).await);
    assert!(tree.contains("again") && !tree.contains("typed"), "clear emptied the field first: {tree}");
    // What the element tools type is checked as /v1/actions checks a type_text.
    let huge = "x".repeat(arena_shared::action::MAX_TYPE_TEXT_BYTES + 1);
    let too_long = refused(&client, "type_into_element", json!({"element": number, "text": huge})).await;
    assert!(too_long.contains("type_text holds 1048577 bytes"), "{too_long}");
    let tree = text_of(&call(&client, "accessibility_tree", json!({})).await);
    assert!(tree.contains("again") && !tree.contains("xxxx"), "nothing was typed: the check runs before any action");
    let unknown = refused(&client, "click_element", json!({"element": 100_000})).await;
    assert!(unknown.starts_with("click_element: element 100000 is unknown"), "{unknown}");

    // Moving the window makes its elements stale.
    let close = find("Button", "Close")["element"].as_u64().expect("a number");
    ok(&client, "resize_window", json!({"title": "Notepad", "state": "normal"})).await;
    let stale = refused(&client, "click_element", json!({"element": close})).await;
    assert!(stale.contains(&format!("element {close} is stale")) && stale.contains("moved or was resized"), "{stale}");
    // A new state numbers on from the last, so the old numbers stay stale.
    let again = ok(&client, "state", json!({})).await;
    let first = again["elements"][0]["element"].as_u64().expect("a number");
    assert!(first > close, "numbers are not reused: {again}");
    let old = refused(&client, "click_element", json!({"element": number})).await;
    assert!(old.contains(&format!("element {number} is stale")), "{old}");

    let shell = refused(&client, "shell", json!({"command": "echo hi"})).await;
    assert!(shell.contains("refused") && shell.contains("--mcp-shell"), "{shell}");
    let _ = client.cancel().await;
}

/// `--mcp-shell` lets `shell` run: on the stub, its simulated programs (the rest is
/// refused, naming `--stub-host-exec`), and with `--stub-host-exec` a real `sh -c`.
#[tokio::test(flavor = "multi_thread")]
async fn the_guest_shell_runs_only_with_its_option() {
    let (_guest, url) = guest_mcp(&["--mcp-shell"]);
    let client = connect_with(&url, GUEST_TOKEN).await;
    let ran = ok(&client, "shell", json!({"command": "notepad"})).await;
    assert_eq!(ran["exit_code"], json!(0), "{ran}");
    let windows = ok(&client, "list_windows", json!({})).await;
    assert_eq!(windows["foreground"], json!("Untitled - Notepad"), "the stub's Notepad opened: {windows}");
    let real = refused(&client, "shell", json!({"command": "echo hi"})).await;
    assert!(real.contains("--stub-host-exec"), "{real}");
    let _ = client.cancel().await;

    let (_guest, url) = guest_mcp(&["--mcp-shell", "--stub-host-exec"]);
    let client = connect_with(&url, GUEST_TOKEN).await;
    let ran = ok(&client, "shell", json!({"command": "echo shell-says-hi; exit 3"})).await;
    assert_eq!((ran["stdout"].as_str(), ran["exit_code"].as_i64()), (Some("shell-says-hi\n"), Some(3)), "{ran}");
    assert_eq!(ran["timed_out"], json!(false), "{ran}");
    let _ = client.cancel().await;
}

/// `--mcp-shell` is an option of `--mcp`: alone it is refused at start.
#[test]
fn the_shell_option_needs_mcp() {
    let exe = workspace_binary("arena-guest", "arena-guest").expect("the arena-guest binary");
    let out = Command::new(exe).args(["--backend", "stub", "--mcp-shell"]).output().expect("arena-guest runs");
    assert!(!out.status.success());
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(said.contains("--mcp-shell") && said.contains("--mcp"), "{said}");
}

/// The official Python SDK (`mcp`) drives the guest: lists the tools, starts Notepad,
/// types into its text area by the number `state` gave it, copies it and reads the
/// clipboard, sets and reads the clipboard, is refused `shell`, and ends its session
/// without `Session termination failed: 202` (the SDK's complaint about a `DELETE`
/// answered anything but 200 or 204).
#[test]
fn the_python_sdk_drives_the_guest_and_ends_its_session_cleanly() {
    let test = "the_python_sdk_drives_the_guest_and_ends_its_session_cleanly";
    let Some(python) = arena_test_support::python_with_mcp(test) else { return };
    let (_guest, url) = guest_mcp(&[]);
    let ran = Command::new(python)
        .arg(repo().join("examples/guest_mcp_client.py"))
        .args([url.as_str(), GUEST_TOKEN, "Typed by the Python SDK"])
        .output()
        .expect("the example runs");
    let (stdout, stderr) = (String::from_utf8_lossy(&ran.stdout), String::from_utf8_lossy(&ran.stderr));
    assert!(ran.status.success(), "{stdout}\n{stderr}");
    assert!(
        !stderr.contains("Session termination failed"),
        "the session's end was answered as the SDK expects: {stderr}"
    );
    let said: Value = serde_json::from_str(stdout.trim()).unwrap_or_else(|e| panic!("{e}: {stdout}"));
    let names: Vec<&str> = said["tools"].as_array().expect("tools").iter().filter_map(Value::as_str).collect();
    assert_eq!(names, guest_tool_table(), "{said}");
    assert_eq!(said["launched"]["window"], json!("Untitled - Notepad"), "{said}");
    assert_eq!(said["element"]["role"], json!("Document"), "{said}");
    assert_eq!(said["typed"]["ok"], json!(true), "{said}");
    assert_eq!(said["copied"]["text"], json!("Typed by the Python SDK"), "{said}");
    assert_eq!(said["set"]["text"], json!("Set by the Python SDK"), "{said}");
    assert_eq!(said["stale"]["is_error"], json!(true), "{said}");
    assert!(said["stale"]["text"].as_str().is_some_and(|t| t.contains("is stale")), "{said}");
    assert_eq!(said["shell"]["is_error"], json!(true), "{said}");
    assert!(said["shell"]["text"].as_str().is_some_and(|t| t.contains("--mcp-shell")), "{said}");
}
