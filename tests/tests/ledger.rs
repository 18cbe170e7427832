//! The cost ledger end to end with a step-protocol agent that reports `usage`
//! (`ledger/metered_agent.py`, the stub tasks' oracle with fixed counts per
//! answer): tokens per step in `traj.jsonl`, per task in `episode.json` and the
//! summary's rows, per domain and overall in `summary.json`, priced by
//! `--prices`; `--max-cost` and `--max-total-tokens` stop a run from starting
//! tasks after the one that reaches them, recorded in `summary.json`.
//!
//! Needs `python3`: without it each test prints `SKIPPED: <test>: python3 not
//! found` and returns, unless `ARENA_REQUIRE_PYTHON` is set.

#![cfg(unix)]

use std::path::Path;
use std::process::Command;

use arena_test_support::workspace_binary;
use serde_json::{json, Value};

/// What the agent reports per answer.
const INPUT: u64 = 1000;
const CACHED: u64 = 400;
const OUTPUT: u64 = 100;
const MODEL_MS: u64 = 7;
/// USD per million tokens in the test's price file.
const PRICE_INPUT: f64 = 2.0;
const PRICE_CACHED: f64 = 0.5;
const PRICE_OUTPUT: f64 = 10.0;
const MODEL: &str = "metered-model";

/// The cost of one step's usage, in USD, from the prices' definition.
fn step_cost() -> f64 {
    ((INPUT - CACHED) as f64 * PRICE_INPUT + CACHED as f64 * PRICE_CACHED + OUTPUT as f64 * PRICE_OUTPUT) / 1e6
}

/// `arena run` of the metered agent on one stub guest with `extra` arguments; answers its output.
fn run(out: &Path, extra: &[&str]) -> String {
    let prices = out.with_extension("prices.json");
    let text = json!({MODEL: {"input": PRICE_INPUT, "output": PRICE_OUTPUT, "cached_input": PRICE_CACHED}});
    std::fs::write(&prices, text.to_string()).expect("the price file");
    let output = Command::new(workspace_binary("arena-host", "arena").expect("the arena binary"))
        .args(["run", "--stub-guests", "1", "--pauses", "fast", "--tasks"])
        .arg(arena_test_support::workspace_root().join("tasks/stub"))
        .arg("--out")
        .arg(out)
        .args(arena_test_support::exec_sandbox_args())
        .args(["--agent", "exec", "--agent-timeout", "60", "--model", MODEL, "--prices"])
        .arg(&prices)
        .args(extra)
        .arg("--agent-cmd")
        .arg("python3 -m arena_agent metered_agent:Metered")
        .env("PYTHONPATH", arena_test_support::agent_pythonpath(&["tests/tests/agent_protocol", "tests/tests/ledger"]))
        .output()
        .expect("arena run starts");
    format!("{}\n{}", String::from_utf8_lossy(&output.stdout), String::from_utf8_lossy(&output.stderr))
}

fn summary(out: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(out.join("summary.json")).expect("summary.json")).expect("JSON")
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-9
}

#[test]
fn an_exec_agents_usage_is_counted_per_step_task_domain_and_run_and_priced() {
    let test = "an_exec_agents_usage_is_counted_per_step_task_domain_and_run_and_priced";
    if !arena_test_support::python3_or_skip(test) {
        return;
    }
    let tmp = tempfile::tempdir().expect("tmp");
    let out = tmp.path().join("out");
    let log = run(&out, &[]);
    let s = summary(&out);
    let tasks = s["tasks"].as_array().expect("tasks");
    assert_eq!(tasks.len(), 6, "{log}");
    let mut total_steps = 0;
    for task in tasks {
        let steps = task["steps"].as_u64().expect("steps");
        assert!(steps >= 1, "{task}");
        total_steps += steps;
        let want = json!({"input": INPUT * steps, "output": OUTPUT * steps, "cached": CACHED * steps, "model_ms": MODEL_MS * steps});
        assert_eq!(task["tokens"], want, "{}\n{log}", task["name"]);
        assert!(close(task["cost_usd"].as_f64().expect("cost"), step_cost() * steps as f64), "{task}");
        // The record and every step line of the trajectory.
        let dir = out.join(task["path"].as_str().expect("path"));
        let episode: Value =
            serde_json::from_slice(&std::fs::read(dir.join("episode.json")).expect("episode.json")).expect("JSON");
        assert_eq!(episode["tokens"], want);
        let traj = std::fs::read_to_string(dir.join("traj.jsonl")).expect("traj.jsonl");
        let usages: Vec<Value> = traj
            .lines()
            .map(|l| serde_json::from_str::<Value>(l).expect("a JSON line"))
            .filter(|l| l.get("step").is_some())
            .map(|l| l["usage"].clone())
            .collect();
        assert_eq!(usages.len() as u64, steps);
        assert!(
            usages.iter().all(|u| u["input"] == INPUT && u["output"] == OUTPUT && u["cached"] == CACHED),
            "{usages:?}"
        );
    }
    let overall = &s["overall"];
    assert_eq!(overall["tokens"]["input"], INPUT * total_steps);
    assert_eq!(overall["tokens"]["output"], OUTPUT * total_steps);
    assert_eq!(overall["tokens"]["cached"], CACHED * total_steps);
    assert!(close(overall["cost_usd"].as_f64().expect("cost"), step_cost() * total_steps as f64));
    for domain in s["domains"].as_array().expect("domains") {
        let name = domain["domain"].as_str().expect("name");
        let steps: u64 = tasks.iter().filter(|t| t["domain"] == name).map(|t| t["steps"].as_u64().unwrap_or(0)).sum();
        assert_eq!(domain["tokens"]["input"], INPUT * steps, "{name}");
    }
    assert!(s.get("budget").is_none(), "no budget was given");
    let md = std::fs::read_to_string(out.join("summary.md")).expect("summary.md");
    assert!(md.contains("## Cost") && md.contains(&format!("| {} |", INPUT * total_steps)), "{md}");
}

#[test]
fn a_budget_stops_the_run_after_the_task_that_reaches_it() {
    let test = "a_budget_stops_the_run_after_the_task_that_reaches_it";
    if !arena_test_support::python3_or_skip(test) {
        return;
    }
    let tmp = tempfile::tempdir().expect("tmp");
    // A token limit of 1: the first task crosses it with its first step, finishes, and alone runs.
    let tokens = tmp.path().join("tokens");
    let log = run(&tokens, &["--order", "sorted", "--max-total-tokens", "1"]);
    let s = summary(&tokens);
    let rows = s["tasks"].as_array().expect("tasks").clone();
    assert_eq!(rows.len(), 1, "{log}");
    let first_steps = rows[0]["steps"].as_u64().expect("steps");
    let budget = &s["budget"];
    assert!(budget["stopped"].as_str().is_some_and(|w| w.contains("--max-total-tokens 1")), "{budget}");
    assert_eq!(budget["max_tokens"], 1);
    assert_eq!(budget["not_started"].as_array().map(Vec::len), Some(5), "{budget}");
    assert!(log.contains("not started: the budget is reached"), "{log}");

    // A cost limit that the second task crosses: two tasks run, four never start.
    let cost = tmp.path().join("cost");
    let limit = step_cost() * (first_steps as f64 + 0.5);
    let log = run(&cost, &["--order", "sorted", "--max-cost", &format!("{limit}")]);
    let s = summary(&cost);
    let rows = s["tasks"].as_array().expect("tasks");
    assert_eq!(rows.len(), 2, "the run stops after the task that crosses the limit\n{log}");
    assert_eq!(rows[0]["name"], summary(&tokens)["tasks"][0]["name"]);
    let spent: u64 = rows.iter().map(|t| t["steps"].as_u64().unwrap_or(0)).sum();
    let budget = &s["budget"];
    assert!(close(budget["max_cost_usd"].as_f64().expect("limit"), limit), "{budget}");
    assert!(budget["stopped"].as_str().is_some_and(|w| w.contains("--max-cost")), "{budget}");
    assert_eq!(budget["not_started"].as_array().map(Vec::len), Some(4), "{budget}");
    assert!(close(budget["spent"]["cost_usd"].as_f64().expect("spent"), step_cost() * spent as f64), "{budget}");
    let md = std::fs::read_to_string(cost.join("summary.md")).expect("summary.md");
    assert!(md.contains("Reached (spent $") && md.contains("4 task(s) not started"), "{md}");

    // Running again with the same budget starts nothing: the folder has spent it.
    let again = run(&tokens, &["--order", "sorted", "--max-total-tokens", "1"]);
    assert_eq!(summary(&tokens)["tasks"].as_array().map(Vec::len), Some(1), "{again}");
}

#[test]
fn the_act_schema_takes_an_optional_usage() {
    let path = arena_test_support::workspace_root().join("schemas/agent-protocol/act.json");
    let schema: Value = serde_json::from_slice(&std::fs::read(path).expect("act.json")).expect("JSON");
    let validator = jsonschema::validator_for(&schema).expect("a valid schema");
    assert!(validator.is_valid(&json!({"type": "act", "usage": {"input_tokens": 5, "output_tokens": 1}})));
    assert!(validator.is_valid(&json!({"type": "act"})));
    assert!(!validator.is_valid(&json!({"type": "act", "usage": {"input_tokens": -5, "output_tokens": 1}})));
    assert!(!validator.is_valid(&json!({"type": "act", "usage": {"output_tokens": 1}})));
}
