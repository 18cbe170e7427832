//! The same hostile pyautogui code through every way into a step gets the same
//! answer: Navi's reply (against a mock chat endpoint), the step protocol (`--agent
//! exec`, a shell script; `--agent http`, a small HTTP server), MCP's `run_python`
//! (the endpoint's tool-call mapping), a computer-use agent (UI-TARS, where typing
//! goes through the clipboard) and `arena act --pyautogui` (the real binary).
//!
//! By default (as upstream's `python -c`) code reaching for files or processes
//! (`open`, `os.remove`, a saved screenshot, a command) has the same effect on the
//! guest and the same outcome whichever way it came; with `--pyautogui-translate-only`
//! it does nothing on the guest and every way records the one translation error of
//! the `pyautogui` action space (as `arena act --pyautogui` always does); a clipboard
//! paste (`pyperclip.copy` then
//! Ctrl+V) is one clipboard write and one hotkey everywhere, so Notepad gets the
//! text each time. Code reaching for the host (`os.system`, `subprocess.run`, a
//! host file such as `/etc/passwd`) on a stub without `--stub-host-exec` gets the
//! same refusal through every way, and nothing starts on the host. Runs against
//! the in-process stub guest.

#![cfg(unix)]

use std::io::{BufRead, BufReader, Read, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use arena_actionspace::Coords;
use arena_agents::cu::uitars::{UiTarsAgent, UiTarsConfig};
use arena_agents::external::transport::{HttpAgent, ProcessPool};
use arena_agents::external::ExternalAgent;
use arena_agents::navi::{NaviAgent, NaviConfig};
use arena_agents::observation::Observation;
use arena_agents::Agent;
use arena_client::{ClientConfig, GuestClient};
use arena_exec::AgentAction;
use arena_exec::{execute_with, pointer, translate_pyautogui, ExecOptions, PyautoguiPolicy};
use arena_script::ComputerState;
use arena_shared::clipboard::ClipboardContent;
use arena_shared::exec::LaunchRequest;
use arena_shared::mcp_tools::ToolCall;
use arena_shared::observation::A11yQuery;
use arena_task::Task;
use arena_test_support::{workspace_binary, StubGuest};
use serde_json::{json, Value};

use crate::agent_protocol::mock_model;

/// The file the hostile code goes for, and what it holds.
const TARGET: &str = r"C:\Users\Docker\Desktop\keep.txt";
const KEPT: &[u8] = b"still here";

/// Code that reaches outside input: a file written, a file removed, a screenshot
/// saved to a file, a command run.
fn hostile() -> Vec<String> {
    vec![
        "open('C:/Users/Docker/Desktop/keep.txt', 'w').write('gone')".to_owned(),
        "import os\nos.remove(r'C:\\Users\\Docker\\Desktop\\keep.txt')".to_owned(),
        "pyautogui.screenshot(r'C:\\Users\\Docker\\Desktop\\shot.png')".to_owned(),
        "import subprocess\nsubprocess.run(['cmd', '/c', 'del', r'C:\\Users\\Docker\\Desktop\\keep.txt'])".to_owned(),
    ]
}

/// A clipboard paste: the text goes on the clipboard, then Ctrl+V.
const PASTE: &str = "import pyperclip\npyperclip.copy('x')\npyautogui.hotkey('ctrl', 'v')";

fn client(url: &str) -> GuestClient {
    GuestClient::new(url, ClientConfig { token: None, timeout: Duration::from_secs(20), retries: 1 }).expect("client")
}

fn task(dir: &Path) -> Task {
    let path = dir.join("notepad").join("hostile.json");
    std::fs::create_dir_all(path.parent().expect("a folder")).expect("task folder");
    let text =
        r#"{"id": "hostile", "instruction": "Type x in Notepad", "config": [], "evaluator": {"func": "infeasible"}}"#;
    std::fs::write(&path, text).expect("task file");
    Task::load(&path).expect("task loads")
}

/// Notepad's text, from the accessibility tree.
async fn notepad_text(c: &GuestClient) -> String {
    fn find(node: &arena_shared::observation::A11yNode) -> Option<String> {
        if node.role == "Document" {
            return Some(node.value.clone().unwrap_or_default());
        }
        node.children.iter().find_map(find)
    }
    let tree = c.a11y(&A11yQuery::default()).await.expect("tree");
    tree.windows.iter().filter(|w| w.name.contains("Notepad")).find_map(find).expect("Notepad's document")
}

/// What the step's actions did: the errors of their outcomes, in order.
async fn carry_out(c: &GuestClient, actions: &[AgentAction]) -> Vec<String> {
    carry_out_with(c, actions, &ExecOptions::instant()).await
}

async fn carry_out_with(c: &GuestClient, actions: &[AgentAction], options: &ExecOptions) -> Vec<String> {
    let mut state = ComputerState::for_screen(1440, 900);
    let mut errors = Vec::new();
    for action in actions {
        let outcome = execute_with(c, action, None, &mut state, options).await.expect("the guest answers");
        errors.extend(outcome.error);
    }
    errors
}

/// Navi: a reply holding the code in a python block.
async fn navi(obs: &Observation, task: &Task, code: &str) -> Vec<AgentAction> {
    let mock = mock_model::start(&format!("Doing it.\n```python\n{code}\n```")).expect("mock model");
    let mut agent = NaviAgent::new(NaviConfig::new(&mock.url, "mock-model")).expect("navi");
    agent.reset(task).await;
    let actions = agent.predict(obs).await.expect("a prediction").actions;
    assert_eq!(mock.requests.lock().expect("requests").len(), 1, "one model call");
    actions
}

/// The step protocol over a process: a shell script answering with `act.json`.
async fn exec_agent(dir: &Path, obs: &Observation, task: &Task, code: &str) -> Vec<AgentAction> {
    let act = dir.join("act.json");
    std::fs::write(&act, json!({"type": "act", "actions": [code]}).to_string()).expect("act");
    let hello = r#"{"type":"hello","protocol":1,"agent":"sh","action_space":"pyautogui","observation":{"screenshot":"none","a11y":"none","windows":false,"clipboard":false}}"#;
    let script = format!(
        "read -r line\nprintf '%s\\n' '{hello}'\nwhile read -r line; do\n  case \"$line\" in\n    *'\"type\":\"reset\"'*) printf '%s\\n' '{{\"type\":\"ready\"}}' ;;\n    *) cat '{}'; printf '\\n' ;;\n  esac\ndone\n",
        act.display()
    );
    let path = dir.join("agent.sh");
    std::fs::write(&path, script).expect("script");
    let pool = ProcessPool::new(&format!("sh {}", path.display())).expect("a process pool");
    let mut agent = ExternalAgent::new("exec", Arc::new(pool), Duration::from_secs(20));
    agent.reset(task).await;
    agent.predict(obs).await.expect("a prediction").actions
}

/// The step protocol over HTTP: a server answering each message by its type.
async fn http_agent(obs: &Observation, task: &Task, code: &str) -> Vec<AgentAction> {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
    let url = format!("http://{}/agent", listener.local_addr().expect("addr"));
    let act = json!({"type": "act", "actions": [code]});
    std::thread::spawn(move || {
        for stream in listener.incoming().flatten() {
            let act = act.clone();
            std::thread::spawn(move || answer(stream, &act));
        }
    });
    let agent = HttpAgent::new(&url, Duration::from_secs(20)).expect("an http agent");
    let mut agent = ExternalAgent::new("http", Arc::new(agent), Duration::from_secs(20));
    agent.reset(task).await;
    agent.predict(obs).await.expect("a prediction").actions
}

/// One keep-alive connection of the HTTP agent: `hello` → `hello`, `reset` →
/// `ready`, `observe` → `act`.
fn answer(stream: std::net::TcpStream, act: &Value) {
    let mut reader = BufReader::new(stream);
    loop {
        let (mut length, mut line) = (0usize, String::new());
        loop {
            line.clear();
            if reader.read_line(&mut line).unwrap_or(0) == 0 {
                return;
            }
            if let Some(v) = line.to_ascii_lowercase().strip_prefix("content-length:") {
                length = v.trim().parse().unwrap_or(0);
            }
            if line == "\r\n" {
                break;
            }
        }
        let mut body = vec![0; length];
        if reader.read_exact(&mut body).is_err() {
            return;
        }
        let message: Value = serde_json::from_slice(&body).unwrap_or(Value::Null);
        let reply = match message["type"].as_str() {
            Some("hello") => json!({"type": "hello", "protocol": 1, "agent": "http", "action_space": "pyautogui",
                "observation": {"screenshot": "none", "a11y": "none", "windows": false, "clipboard": false}}),
            Some("reset") => json!({"type": "ready"}),
            _ => act.clone(),
        }
        .to_string();
        let response = format!(
            "HTTP/1.1 200 OK\r\nContent-Type: application/json\r\nContent-Length: {}\r\n\r\n{reply}",
            reply.len()
        );
        if reader.get_mut().write_all(response.as_bytes()).is_err() {
            return;
        }
    }
}

/// MCP's `run_python`: the endpoint's one mapping from a tool call to a step's action.
fn mcp(code: &str) -> Vec<AgentAction> {
    arena_host::mcp::agent_action(ToolCall::RunPython(code.to_owned())).into_iter().collect()
}

/// What each way into a step makes of `code`: Navi's reply, an exec agent's and an
/// HTTP agent's act, and MCP's `run_python` (`dir` holds the exec agent's files).
async fn every_way(dir: &Path, obs: &Observation, task: &Task, code: &str) -> Vec<(&'static str, Vec<AgentAction>)> {
    vec![
        ("navi", navi(obs, task, code).await),
        ("exec", exec_agent(dir, obs, task, code).await),
        ("http", http_agent(obs, task, code).await),
        ("mcp", mcp(code)),
    ]
}

/// What a translation error says after quoting the code.
fn reason(error: &str) -> &str {
    error.rfind("\": ").map_or(error, |at| &error[at + 3..])
}

/// `arena act --pyautogui CODE` against the guest: its exit status and stderr.
fn arena_act(url: &str, code: &str) -> (bool, String) {
    let exe = workspace_binary("arena-host", "arena").expect("the arena binary");
    let out = std::process::Command::new(exe)
        .args(["--guest", url, "act", "--pyautogui", code])
        .env_remove("ARENA_TOKEN")
        .env_remove("ARENA_TOKEN_FILE")
        .output()
        .expect("arena act runs");
    (out.status.success(), String::from_utf8_lossy(&out.stderr).into_owned())
}

/// What the guest holds after hostile code: the target file's bytes (if any) and
/// whether the screenshot file exists.
type GuestState = (Option<Vec<u8>>, bool);

async fn guest_state(c: &GuestClient) -> GuestState {
    let kept = c.pull_file(TARGET).await.ok().map(|f| f.bytes);
    let shot = c.exists(r"C:\Users\Docker\Desktop\shot.png").await.expect("exists").exists;
    (kept, shot)
}

/// Puts the target file back and removes the saved screenshot.
async fn restore(c: &GuestClient) {
    c.push_file(TARGET, KEPT.to_vec(), Some(true)).await.expect("the file the code goes for");
    let _ = c.delete(r"C:\Users\Docker\Desktop\shot.png", false).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn hostile_pyautogui_has_the_same_effect_through_every_way_by_default() {
    let guest = StubGuest::start().await;
    let c = client(guest.url());
    let tmp = tempfile::tempdir().expect("tmp");
    let task = task(tmp.path());
    restore(&c).await;
    let obs = Observation::capture(&c, 1, &task.instruction).await.expect("observe");
    let effects = ExecOptions::instant();
    assert_eq!(effects.pyautogui, PyautoguiPolicy::Effects, "upstream's rule is the default");
    for (n, code) in hostile().iter().enumerate() {
        let dir: PathBuf = tmp.path().join(format!("exec-{n}"));
        std::fs::create_dir_all(&dir).expect("dir");
        let ways = every_way(&dir, &obs, &task, code).await;
        let mut seen: Option<(Vec<String>, GuestState)> = None;
        for (way, actions) in ways {
            restore(&c).await;
            let errors = carry_out_with(&c, &actions, &effects).await;
            let after = (errors, guest_state(&c).await);
            match &seen {
                None => seen = Some(after),
                Some(first) => assert_eq!(&after, first, "{way}: {code}"),
            }
        }
        let (errors, (kept, shot)) = seen.expect("four ways");
        // What upstream's `python -c` would do, as far as the host's closed interpreter
        // goes: files are out of its reach (an error, the file kept), a saved
        // screenshot lands on the guest, a command goes to the guest's exec route.
        match n {
            0 | 1 => {
                assert!(
                    errors.len() == 1 && errors[0].contains("not supported by this interpreter"),
                    "{code}: {errors:?}"
                );
                assert_eq!(kept.as_deref(), Some(KEPT), "{code}");
            }
            2 => assert!(errors.is_empty() && shot, "{code}: {errors:?}"),
            _ => assert!(errors.len() == 1 && errors[0].contains("/v1/exec"), "{code}: {errors:?}"),
        }
    }
    restore(&c).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn hostile_pyautogui_gets_the_same_answer_through_every_way_when_translate_only() {
    let guest = StubGuest::start().await;
    let c = client(guest.url());
    let tmp = tempfile::tempdir().expect("tmp");
    let task = task(tmp.path());
    c.push_file(TARGET, KEPT.to_vec(), Some(true)).await.expect("the file the code goes for");
    c.launch(&LaunchRequest { shell: None, argv: vec!["notepad.exe".into()] }).await.expect("notepad");
    let obs = Observation::capture(&c, 1, &task.instruction).await.expect("observe");
    let ctx = pointer(&c, Coords::Pixels).await.expect("screen and cursor");
    let translate_only = ExecOptions { pyautogui: PyautoguiPolicy::TranslateOnly, ..ExecOptions::instant() };

    for (n, code) in hostile().iter().enumerate() {
        let expected = translate_pyautogui(code, &ctx).expect_err("hostile code does not translate");
        let dir: PathBuf = tmp.path().join(format!("exec-{n}"));
        std::fs::create_dir_all(&dir).expect("dir");
        let ways = every_way(&dir, &obs, &task, code).await;
        for (way, actions) in ways {
            // Navi keeps the block's last newline; the code is the same.
            let [AgentAction::Pyautogui(got)] = &actions[..] else { panic!("{way}: {actions:?}") };
            assert_eq!(got.trim_end(), code, "{way}");
            let errors = carry_out_with(&c, &actions, &translate_only).await;
            assert_eq!(errors, vec![translate_pyautogui(got, &ctx).expect_err("refused")], "{way}: {code}");
            assert_eq!(reason(&errors[0]), reason(&expected), "{way}: {code}");
        }
        let (ok, stderr) = arena_act(guest.url(), code);
        assert!(!ok && stderr.contains(&expected), "arena act: {code}: {stderr}");
        let kept = c.pull_file(TARGET).await.expect("the file is still there");
        assert_eq!(kept.bytes, KEPT, "{code}");
        assert!(!c.exists(r"C:\Users\Docker\Desktop\shot.png").await.expect("exists").exists, "{code}");
    }

    // The paste: one clipboard write and Ctrl+V, whichever way it came.
    let dir = tmp.path().join("exec-paste");
    std::fs::create_dir_all(&dir).expect("dir");
    let mock = mock_model::start("Thought: type x.\nAction: type(content='x')").expect("mock model");
    let mut uitars =
        UiTarsAgent::new(UiTarsConfig::new(&mock.url, "ui-tars", "Do this: {instruction}")).expect("ui-tars");
    uitars.reset(&task).await;
    let mut ways = every_way(&dir, &obs, &task, PASTE).await;
    ways.push(("ui-tars", uitars.predict(&obs).await.expect("a prediction").actions));
    let mut typed = String::new();
    for (way, actions) in ways {
        c.clipboard_set(&ClipboardContent::Text { text: String::new() }).await.expect("clear the clipboard");
        assert_eq!(carry_out(&c, &actions).await, Vec::<String>::new(), "{way}");
        assert_eq!(c.clipboard_get().await.expect("clipboard"), ClipboardContent::Text { text: "x".into() }, "{way}");
        typed.push('x');
        assert_eq!(notepad_text(&c).await, typed, "{way}");
    }
    c.clipboard_set(&ClipboardContent::Text { text: String::new() }).await.expect("clear the clipboard");
    let (ok, stderr) = arena_act(guest.url(), PASTE);
    assert!(ok, "arena act: {stderr}");
    assert_eq!(c.clipboard_get().await.expect("clipboard"), ClipboardContent::Text { text: "x".into() });
    typed.push('x');
    assert_eq!(notepad_text(&c).await, typed, "arena act");
}

/// Code that reaches for the host: a shell command and a process that would
/// create `marker` on the host, and a host file outside the stub root.
fn host_reaching(marker: &Path) -> Vec<String> {
    let m = marker.display();
    vec![
        format!("import os\nos.system('touch {m}')"),
        format!("import subprocess\nsubprocess.run(['sh', '-c', 'touch {m}'])"),
        "print(open('/etc/passwd').read())".to_owned(),
    ]
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn on_the_stub_host_reaching_code_is_refused_the_same_way_through_every_way_and_nothing_runs_on_the_host() {
    // The stub as a run starts it: without --stub-host-exec.
    let guest = StubGuest::start().await;
    let c = client(guest.url());
    let tmp = tempfile::tempdir().expect("tmp");
    let task = task(tmp.path());
    let marker = tmp.path().join("host-marker");
    let obs = Observation::capture(&c, 1, &task.instruction).await.expect("observe");
    for (n, code) in host_reaching(&marker).iter().enumerate() {
        let dir: PathBuf = tmp.path().join(format!("host-{n}"));
        std::fs::create_dir_all(&dir).expect("dir");
        let ways = every_way(&dir, &obs, &task, code).await;
        let mut seen: Option<Vec<String>> = None;
        for (way, actions) in ways {
            let errors = carry_out(&c, &actions).await;
            assert!(!marker.exists(), "{way}: {code}: a host process ran");
            match &seen {
                None => seen = Some(errors),
                Some(first) => assert_eq!(&errors, first, "{way}: {code}"),
            }
        }
        let errors = seen.expect("four ways");
        assert_eq!(errors.len(), 1, "{code}: {errors:?}");
        match n {
            0 | 1 => assert!(
                errors[0].contains("only its simulated programs") && errors[0].contains("--stub-host-exec"),
                "{code}: {errors:?}"
            ),
            _ => assert!(errors[0].contains("not supported by this interpreter"), "{code}: {errors:?}"),
        }
        assert!(!errors[0].contains("root:"), "no host file reached the agent: {errors:?}");
        // `arena act --pyautogui` refuses it too, and starts nothing.
        let (ok, stderr) = arena_act(guest.url(), code);
        assert!(!ok, "arena act: {code}: {stderr}");
        assert!(!marker.exists(), "arena act: {code}: a host process ran");
        assert!(!stderr.contains("root:"), "arena act: {stderr}");
    }
}
