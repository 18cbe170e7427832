//! Agent S3 from the published `gui-agents` package, unchanged, solves a stub task
//! through the step protocol: `arena run --agent exec` runs `python -m
//! arena_agent.agent_s3` (its main model on an OpenAI endpoint, its grounding
//! model on a Hugging Face TGI one), both answered by `examples/agent_s3/mock_models.py`,
//! two real HTTP servers that check every request against the `openai` SDK's types.
//! `stub-notepad-draft` must score 1.0 in three steps (type, save, done), the
//! click Agent S3 wrote must be the grounding model's answer scaled by Agent S3's
//! own code from its 1920x1080 space to the screen, and the mocks must refuse a
//! malformed request.
//!
//! Needs a Python with `gui-agents` (see `.ci/run`: `--no-deps` plus what its
//! agent imports): `ARENA_GUI_AGENTS_PYTHON`, else `python3` when it has it;
//! without one each test prints `SKIPPED: <test>: gui-agents not installed`
//! (counted by `./test.sh`), a failure with `ARENA_REQUIRE_GUI_AGENTS=1`.

#![cfg(unix)]

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};

use arena_test_support::workspace_binary;
use serde_json::{json, Value};

const KEY: &str = "mock-key-0123";
const GROUNDING: (u32, u32) = (1920, 1080);

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The two mock models, ended when dropped.
struct Mocks {
    child: Child,
    _stdin: ChildStdin,
    planner: String,
    grounding: String,
}

impl Mocks {
    fn start(python: &str, log: &Path) -> Mocks {
        let (w, h) = GROUNDING;
        let mut child = Command::new(python)
            .arg(repo().join("examples/agent_s3/mock_models.py"))
            .args(["--api-key", KEY, "--planner-model", "mock-planner", "--grounding-model", "tgi"])
            .arg("--grounding-size")
            .arg(format!("{w}x{h}"))
            .arg("--log")
            .arg(log)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("the mock models start");
        let stdin = child.stdin.take().expect("stdin");
        let mut lines = BufReader::new(child.stdout.take().expect("stdout")).lines();
        let mut url = |name: &str| {
            let line = lines.next().and_then(Result::ok).unwrap_or_default();
            line.strip_prefix(&format!("{name} ")).unwrap_or_else(|| panic!("the mocks said {line:?}")).to_owned()
        };
        let planner = url("planner");
        let grounding = url("grounding");
        Mocks { child, _stdin: stdin, planner, grounding }
    }
}

impl Drop for Mocks {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn read_jsonl(path: &Path) -> Vec<Value> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    text.lines().map(|l| serde_json::from_str(l).expect("a JSON line")).collect()
}

#[test]
fn agent_s3_from_gui_agents_solves_a_stub_task_through_the_step_protocol() {
    let test = "agent_s3_from_gui_agents_solves_a_stub_task_through_the_step_protocol";
    let Some(python) = arena_test_support::gui_agents_python_or_skip(test) else { return };
    let tmp = tempfile::tempdir().expect("tmp");
    let tasks = tmp.path().join("tasks/notepad");
    arena_test_support::copy_stub_task("notepad", "stub-notepad-draft", &tasks);
    let log = tmp.path().join("models.jsonl");
    let mocks = Mocks::start(&python, &log);

    let (gw, gh) = GROUNDING;
    let agent_cmd = format!(
        "{python} -m arena_agent.agent_s3 --provider openai --model mock-planner --model_url {} \
         --model_api_key {KEY} --ground_provider huggingface --ground_url {} --ground_api_key {KEY} \
         --ground_model ui-tars-1.5-7b --grounding_width {gw} --grounding_height {gh}",
        mocks.planner, mocks.grounding
    );
    let out = tmp.path().join("out");
    let exe = workspace_binary("arena-host", "arena").expect("the arena binary");
    let run = Command::new(exe)
        .args(["run", "--stub-guests", "1", "--pauses", "fast", "--agent", "exec", "--agent-timeout", "60"])
        .args(arena_test_support::exec_sandbox_args())
        .arg("--agent-cmd")
        .arg(&agent_cmd)
        .arg("--tasks")
        .arg(tmp.path().join("tasks"))
        .arg("--out")
        .arg(&out)
        .env("PYTHONPATH", repo().join("python"))
        .output()
        .expect("arena run");
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "arena run: {:?}\n{stderr}", run.status);

    // Every request was well formed.
    let requests = read_jsonl(&log);
    for request in &requests {
        assert_eq!(request["problems"], json!([]), "a request the mocks refused: {request}\n{stderr}");
    }

    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).expect("summary.json")).expect("JSON");
    let task = &summary["tasks"][0];
    assert_eq!(task["name"], "stub-notepad-draft", "{summary}");
    assert_eq!((task["status"].as_str(), task["score"].as_f64()), (Some("completed"), Some(1.0)), "{task}\n{stderr}");
    assert_eq!(task["steps"], 3, "type, save, done: {task}");

    // Who was asked what: the worker each step, the reflection agent from the
    // second step on, the grounding model twice for the one grounded action
    // (Agent S3's format check evaluates the action, then the worker does).
    let roles: Vec<&str> = requests.iter().filter_map(|r| r["role"].as_str()).collect();
    assert_eq!(
        roles,
        ["worker", "grounding", "grounding", "reflection", "worker", "reflection", "worker"],
        "{requests:#?}"
    );
    let dir = out.join(task["path"].as_str().expect("path"));
    let trajectory = read_jsonl(&dir.join("traj.jsonl"));
    let steps: Vec<&Value> = trajectory.iter().filter(|l| l["step_num"].as_u64().is_some_and(|n| n >= 1)).collect();
    let first = steps.first().expect("step 1");
    let shot = first["screenshot_file"].as_str().expect("the screenshot it was shown");
    let screen = image::image_dimensions(dir.join(shot)).expect("a PNG");
    let grounded = requests.iter().find(|r| r["role"] == "grounding").expect("a grounding request");
    let image = (grounded["images"][0][0].as_u64().expect("width"), grounded["images"][0][1].as_u64().expect("height"));
    assert_eq!(image, (u64::from(screen.0), u64::from(screen.1)), "the screenshot is sent at the screen's size");

    // The click is the grounding model's point, scaled by Agent S3 from its space to the screen.
    let answer = grounded["answer"].as_str().expect("answer");
    let (gx, gy) = answer
        .trim_matches(|c| c == '(' || c == ')')
        .split_once(',')
        .map(|(x, y)| (x.parse::<f64>().expect("x"), y.parse::<f64>().expect("y")))
        .expect("(x,y)");
    // Python's round(), half to even.
    let x = (gx * f64::from(screen.0) / f64::from(gw)).round_ties_even();
    let y = (gy * f64::from(screen.1) / f64::from(gh)).round_ties_even();
    let code = first["exec_code"].as_str().expect("exec_code recorded");
    assert!(code.contains(&format!("pyautogui.click({x}, {y})")), "{code}");
    assert!(code.contains("pyautogui.write('This is a draft.')"), "{code}");
    assert_eq!(first["action_space"], "pyautogui", "{first}");
    assert!(first["plan_code"].as_str().is_some_and(|c| c.contains("agent.type(")), "{first}");
    assert_eq!(steps[1]["exec_code"], "import pyautogui; pyautogui.hotkey('ctrl', 's')", "{}", steps[1]);
    assert_eq!(steps[2]["exec_code"], "DONE", "{}", steps[2]);
}

#[tokio::test]
async fn the_mock_models_refuse_what_the_sdk_types_refuse() {
    let test = "the_mock_models_refuse_what_the_sdk_types_refuse";
    let Some(python) = arena_test_support::gui_agents_python_or_skip(test) else { return };
    let tmp = tempfile::tempdir().expect("tmp");
    let mocks = Mocks::start(&python, &tmp.path().join("models.jsonl"));
    let client = reqwest::Client::new();
    let url = format!("{}/chat/completions", mocks.planner);
    let system = json!({"role": "system", "content": [{"type": "text", "text": "You are a helpful assistant."}]});
    let user = json!({"role": "user", "content": [{"type": "text", "text": "hello"}]});
    let good = json!({"model": "mock-planner", "messages": [system, user], "temperature": 0.0});
    let cases = [
        (good.clone(), KEY, None),
        (json!({"model": "mock-planner", "messages": [system, user], "temprature": 0.0}), KEY, Some("'temprature'")),
        (
            json!({"model": "mock-planner", "messages": [system, {"role": "wizard", "content": "x"}]}),
            KEY,
            Some("wizard"),
        ),
        (
            json!({"model": "mock-planner", "messages": [system, {"role": "user", "content": [{"type": "image_url", "image_url": {"uri": "x"}}]}]}),
            KEY,
            Some("'url'"),
        ),
        (json!({"model": "mock-planner", "messages": [system, user], "temperature": "hot"}), KEY, Some("'hot'")),
        (json!({"messages": [system, user]}), KEY, Some("'model'")),
        (good.clone(), "wrong-key", Some("bearer")),
    ];
    for (body, key, refused) in cases {
        let answer = client.post(&url).bearer_auth(key).json(&body).send().await.expect("the mock answers");
        let status = answer.status().as_u16();
        let text = answer.text().await.expect("a body");
        match refused {
            None => assert_eq!(status, 200, "{body} should pass: {text}"),
            Some(word) => {
                assert_eq!(status, 400, "{body} should be refused: {text}");
                let error: Value = serde_json::from_str(&text).expect("an error body");
                let message = error["error"]["message"].as_str().expect("error.message");
                assert!(message.contains(word), "{body}: the error names {word}: {message}");
            }
        }
    }
}
