//! `arena env serve` driven from Python (issue 32, item 4): `arena_agent.env.ArenaEnv`
//! plays two stub tasks side by side on two guests, in two action spaces, and gets
//! their scores; the client's errors name what was wrong; and gymnasium's own env
//! checker passes `arena_agent.gym_env.ArenaGymEnv` (with a Python that has
//! gymnasium: `ARENA_GYM_PYTHON`, else a loud skip, a failure with `ARENA_REQUIRE_GYM=1`).

#![cfg(unix)]

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};

use arena_test_support::{agent_pythonpath, python3_or_skip, stub_tasks_dir, workspace_binary, workspace_root};
use serde_json::{json, Value};

/// `arena env serve` on two stub guests with the stub tasks; the child and its URL.
fn serve(out: &std::path::Path) -> (Child, String) {
    serve_with(out, &[])
}

/// [`serve`] with more arguments.
fn serve_with(out: &std::path::Path, more: &[&str]) -> (Child, String) {
    // The URL ends with `/`.
    let mut child = Command::new(workspace_binary("arena-host", "arena").expect("the arena binary"))
        .args(["env", "serve", "--listen", "127.0.0.1:0", "--stub-guests", "2", "--tasks"])
        .arg(stub_tasks_dir().join("examples"))
        .arg("--out")
        .arg(out)
        .args(more)
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("arena env serve starts");
    let mut lines = BufReader::new(child.stdout.take().expect("stdout")).lines();
    let url = loop {
        let line = lines.next().expect("the banner").expect("text");
        if let Some(rest) = line.strip_prefix("environment: ") {
            break rest.split_whitespace().next().expect("a URL").to_owned();
        }
    };
    std::thread::spawn(move || lines.for_each(drop));
    (child, url)
}

/// Runs `script` (in tests/tests/env_serve/) with `python` against `url`.
fn python(python: &str, script: &str, url: &str) -> std::process::Output {
    Command::new(python)
        .arg(workspace_root().join("tests/tests/env_serve").join(script))
        .arg(url)
        .env("PYTHONPATH", agent_pythonpath(&[]))
        .output()
        .expect("python runs")
}

struct Served(Child);

impl Drop for Served {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

#[test]
fn a_python_client_plays_two_stub_tasks_through_the_environment() {
    if !python3_or_skip("a_python_client_plays_two_stub_tasks_through_the_environment") {
        return;
    }
    let tmp = tempfile::tempdir().expect("tmp");
    let (child, url) = serve(&tmp.path().join("out"));
    let _served = Served(child);
    let played = python("python3", "play_two.py", &url);
    let said = String::from_utf8_lossy(&played.stdout);
    assert!(played.status.success(), "{said}\n{}", String::from_utf8_lossy(&played.stderr));
    let scores: Value = serde_json::from_str(said.trim()).expect("the scores as JSON");
    // The tasks' own checks scored them: both solved, and FAIL on the infeasible one.
    for task in ["stub-notepad-draft", "stub-notepad-count", "stub-settings-infeasible"] {
        assert_eq!(scores[task], 1.0, "{task}: {scores}");
    }
    // Each episode left its result folder, as a run's do: one per session and episode.
    let results = results_of(&tmp.path().join("out"), "stub-notepad-draft");
    assert_eq!(results.len(), 1, "{results:?}");
    assert_eq!(std::fs::read_to_string(&results[0]).expect("result.txt").trim(), "1.0");
}

/// The `result.txt` files under `dir` of the task named `task`.
fn results_of(dir: &std::path::Path, task: &str) -> Vec<std::path::PathBuf> {
    let mut found = Vec::new();
    for entry in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        let path = entry.path();
        if path.is_dir() {
            found.extend(results_of(&path, task));
        } else if path.file_name().is_some_and(|n| n == "result.txt")
            && path.parent().and_then(|p| p.file_name()).is_some_and(|n| n == task)
        {
            found.push(path);
        }
    }
    found
}

/// A Python with gymnasium, numpy and Pillow: `ARENA_GYM_PYTHON`, else `python3`.
const GYM: arena_test_support::PythonNeed = arena_test_support::PythonNeed {
    python_var: "ARENA_GYM_PYTHON",
    require_var: "ARENA_REQUIRE_GYM",
    imports: "import gymnasium, numpy, PIL",
    what: "gymnasium",
    reason: "gymnasium not installed",
};

#[test]
fn the_gymnasium_wrapper_passes_gymnasiums_env_checker() {
    let Some(gym) = GYM.find("the_gymnasium_wrapper_passes_gymnasiums_env_checker") else { return };
    let tmp = tempfile::tempdir().expect("tmp");
    let (child, url) = serve(&tmp.path().join("out"));
    let _served = Served(child);
    let checked = python(&gym, "check_gym.py", &url);
    let said = String::from_utf8_lossy(&checked.stdout);
    assert!(checked.status.success(), "{said}\n{}", String::from_utf8_lossy(&checked.stderr));
    assert!(said.contains("gym ok 1.0"), "{said}");
}

fn schema_file(path: &str) -> Value {
    let text = std::fs::read_to_string(workspace_root().join("schemas").join(path)).expect("the schema");
    serde_json::from_str(&text).expect("schema JSON")
}

/// Asserts `value` is valid against `schemas/env/<name>` (its `$ref`s to the step
/// protocol's schemas resolved from `schemas/agent-protocol/`).
fn assert_valid(name: &str, value: &Value) {
    let observe = schema_file("agent-protocol/observe.json");
    let registry = jsonschema::Registry::new()
        .add("https://arena.invalid/schemas/agent-protocol/observe.json", observe)
        .expect("a URI")
        .prepare()
        .expect("the registry");
    let validator = jsonschema::options()
        .with_registry(&registry)
        .build(&schema_file(&format!("env/{name}")))
        .unwrap_or_else(|e| panic!("{name} is a valid schema: {e}"));
    let errors: Vec<String> = validator.iter_errors(value).map(|e| format!("{}: {e}", e.instance_path())).collect();
    assert!(errors.is_empty(), "{name}: {errors:?}\n{value}");
}

#[tokio::test(flavor = "multi_thread")]
async fn every_request_and_answer_has_the_documented_shape_and_bad_requests_are_named() {
    let tmp = tempfile::tempdir().expect("tmp");
    // A second's pause after each action, so that a step lasts long enough to hang up on.
    let (child, url) = serve_with(&tmp.path().join("out"), &["--sleep-after", "1"]);
    let _served = Served(child);
    let http = reqwest::Client::new();
    let post = |path: &str, body: Value| {
        let request = http.post(format!("{url}{path}")).json(&body);
        async move {
            let answer = request.send().await.expect("an answer");
            let status = answer.status().as_u16();
            (status, answer.json::<Value>().await.expect("JSON"))
        }
    };
    let reset = json!({"task": "stub-notepad-draft", "observation": {"screenshot": "none", "a11y": "xml"}});
    assert_valid("reset-request.json", &reset);
    let (status, answer) = post("reset", reset).await;
    assert_eq!(status, 200, "{answer}");
    assert_valid("reset-answer.json", &answer);
    let session = answer["session"].as_str().expect("a session").to_owned();
    let step = json!({"session": session, "actions": ["pyautogui.write('This is a draft.')", "pyautogui.hotkey('ctrl', 's')"], "action_space": "pyautogui"});
    assert_valid("step-request.json", &step);
    let (status, answer) = post("step", step).await;
    assert_eq!((status, &answer["done"]), (200, &json!(false)), "{answer}");
    assert_valid("step-answer.json", &answer);
    // Bad input: a 4xx whose error names it, in the documented shape.
    let too_many = json!({"session": session, "actions": vec!["WAIT"; 257]});
    for (path, body, want, names) in [
        ("step", too_many, 400, "257 actions"),
        (
            "step",
            json!({"session": session, "actions": [{"type": "teleport"}], "action_space": "typed"}),
            400,
            "teleport",
        ),
        ("step", json!({"session": session, "actions": "x", "extra": 1}), 400, "extra"),
        ("evaluate", json!({"session": session}), 409, "still running"),
        ("reset", json!({"task": 7}), 400, "a number"),
        ("reset", json!({"task": {"id": "t", "instruction": "i"}}), 400, "task"),
        ("close", json!({"session": "nope"}), 404, "nope"),
    ] {
        let (status, answer) = post(path, body).await;
        assert_eq!(status, want, "{path}: {answer}");
        assert_valid("error.json", &answer);
        assert!(answer["error"].as_str().is_some_and(|e| e.contains(names)), "{path}: {answer}");
    }
    // A step whose client hangs up before the answer still runs; the next step's
    // answer is the next step's, not the one the client missed.
    let hung_up = http
        .post(format!("{url}step"))
        .timeout(std::time::Duration::from_millis(300))
        .json(&json!({"session": session, "actions": "pyautogui.press('end')"}))
        .send()
        .await;
    assert!(hung_up.is_err(), "the client gave up first");
    tokio::time::sleep(std::time::Duration::from_millis(1200)).await;
    let (status, answer) = post("step", json!({"session": session, "actions": "WAIT"})).await;
    assert_eq!((status, &answer["info"]["step"]), (200, &json!(4)), "steps 2, 3 (missed), 4: {answer}");
    // Both guests held: a third session is refused, saying why.
    let (status, _) = post("reset", json!({"task": "stub-notepad-count"})).await;
    assert_eq!(status, 200);
    let (status, answer) = post("reset", json!({"task": "stub-notepad-count"})).await;
    assert_eq!(status, 503, "{answer}");
    assert!(answer["error"].as_str().is_some_and(|e| e.contains("every guest (2)")), "{answer}");
    let (status, answer) = post("step", json!({"session": session, "actions": "DONE"})).await;
    assert_eq!((status, &answer["done"], &answer["reward"]), (200, &json!(true), &json!(1.0)), "{answer}");
    assert_valid("step-answer.json", &answer);
    let (status, answer) = post("evaluate", json!({"session": session})).await;
    assert_eq!(status, 200);
    assert_valid("evaluate-answer.json", &answer);
    let (status, _) = post("close", json!({"session": session})).await;
    assert_eq!(status, 200);
}

/// Who may drive the guests: without `--env-token` only loopback `Host` names (a page
/// that rebinds its name to 127.0.0.1 is refused) and never a browser (`Origin`); with
/// it, only a client sending the token, which `ArenaEnv` takes from `ARENA_ENV_TOKEN`;
/// and no non-loopback address without a token.
#[tokio::test(flavor = "multi_thread")]
async fn only_loopback_clients_or_token_holders_drive_the_guests() {
    let tmp = tempfile::tempdir().expect("tmp");
    let http = reqwest::Client::new();
    let info = |url: &str, headers: &[(&str, &str)]| {
        let mut request = http.get(format!("{url}info"));
        for (name, value) in headers {
            request = request.header(*name, *value);
        }
        async move {
            let answer = request.send().await.expect("an answer");
            (answer.status().as_u16(), answer.json::<Value>().await.expect("JSON"))
        }
    };

    let (child, url) = serve(&tmp.path().join("open"));
    let open = Served(child);
    assert_eq!(info(&url, &[]).await.0, 200, "a loopback client without a token");
    let (status, answer) = info(&url, &[("host", "attacker.example:8766")]).await;
    assert_eq!(status, 403, "{answer}");
    assert!(answer["error"].as_str().is_some_and(|e| e.contains("attacker.example")), "{answer}");
    let (status, answer) = info(&url, &[("origin", "http://127.0.0.1:8766")]).await;
    assert_eq!(status, 403, "{answer}");
    assert!(answer["error"].as_str().is_some_and(|e| e.contains("Origin")), "{answer}");
    drop(open);

    let (child, url) = serve_with(&tmp.path().join("token"), &["--env-token", "s3cret-env"]);
    let _guarded = Served(child);
    for headers in [vec![], vec![("authorization", "Bearer wrong")]] {
        let (status, answer) = info(&url, &headers).await;
        assert_eq!(status, 401, "{headers:?}: {answer}");
        assert!(answer["error"].as_str().is_some_and(|e| e.contains("--env-token")), "{answer}");
    }
    let (status, answer) = info(&url, &[("authorization", "Bearer s3cret-env")]).await;
    assert_eq!(status, 200, "{answer}");
    // The Python client sends the token it finds in the environment.
    if python3_or_skip("ArenaEnv with a token") {
        let script = "import sys\nfrom arena_agent.env import ArenaEnv, ArenaEnvError\n\
                      print(len(ArenaEnv(sys.argv[1]).info()['tasks']))\n\
                      try:\n    ArenaEnv(sys.argv[1], token='wrong').info()\nexcept ArenaEnvError as err:\n    print(err.status)\n";
        let ran = Command::new("python3")
            .args(["-c", script, &url])
            .env("PYTHONPATH", agent_pythonpath(&[]))
            .env("ARENA_ENV_TOKEN", "s3cret-env")
            .output()
            .expect("python runs");
        let out = String::from_utf8_lossy(&ran.stdout);
        assert!(ran.status.success(), "{out}{}", String::from_utf8_lossy(&ran.stderr));
        let served = answer["tasks"].as_array().map_or(0, Vec::len);
        assert_eq!(out.lines().collect::<Vec<_>>(), [served.to_string().as_str(), "401"], "{out}");
    }

    // Anyone who reaches a non-loopback address could drive the guests: refused without a token.
    let refused = Command::new(workspace_binary("arena-host", "arena").expect("the arena binary"))
        .args(["env", "serve", "--listen", "0.0.0.0:0", "--stub-guests", "1", "--tasks"])
        .arg(stub_tasks_dir().join("examples"))
        .arg("--out")
        .arg(tmp.path().join("wide"))
        .env_remove("ARENA_ENV_TOKEN")
        .output()
        .expect("arena runs");
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success(), "{stderr}");
    assert!(stderr.contains("not a loopback address") && stderr.contains("--env-token"), "{stderr}");
}
