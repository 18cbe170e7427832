//! Result folders for tests (feature `fixtures`, and this crate's own tests): an
//! episode record, a run layout and a finished task written in upstream's layout,
//! so the crates above test what reads results without writing them by hand.

use std::path::{Path, PathBuf};

use serde_json::Value;

use arena_task::Task;

use crate::{
    format_timestamp, ActionRecord, EpisodeResult, EpisodeStatus, ObservationKeys, ResetRecord, RunLayout, StepRecord,
    StepTimings, TaskDir,
};

pub fn episode(domain: &str, name: &str, score: f64, status: EpisodeStatus, steps: u32) -> EpisodeResult {
    EpisodeResult {
        score_is_int: false,
        task_id: format!("{name}-id"),
        task_name: name.to_owned(),
        domain: domain.to_owned(),
        instruction: format!("do {name}"),
        agent: "scripted".into(),
        model: "plan".into(),
        guest: "http://g".into(),
        attempt: 1,
        score,
        status,
        steps,
        last_action: "done".into(),
        elapsed_ms: 1500,
        setup_ms: 100,
        eval_ms: 50,
        started_unix: 0,
        setup: Vec::new(),
        eval: Value::Null,
        timings: Vec::new(),
        options: Default::default(),
        vm: None,
        tokens: None,
        cost_usd: None,
        action_errors: 0,
    }
}

pub fn step(n: u32) -> StepRecord {
    let timestamp = format_timestamp(0);
    StepRecord {
        first: ActionRecord {
            step_num: n,
            action_timestamp: timestamp.clone(),
            action: "DONE".into(),
            reward: 0.0,
            done: true,
            info: serde_json::json!({"done": true}),
            observation: ObservationKeys {
                screenshot: TaskDir::screenshot_name(Some(n - 1), &timestamp),
                instruction: "i".into(),
                window_title: "Untitled - Notepad".into(),
                window_names_str: "Untitled - Notepad".into(),
                ..ObservationKeys::default()
            },
        },
        step: n,
        response: "<b>ok</b>".into(),
        actions: vec![arena_exec::AgentAction::Done],
        ended: true,
        screenshot_source: None,
        screen: None,
        screenshot_file: TaskDir::screenshot_name(None, &timestamp),
        timings: StepTimings { observe_ms: 3, predict_ms: 1, act_ms: 2, pause_ms: 0, ..StepTimings::default() },
        usage: None,
        error: None,
        outcomes: Vec::new(),
        more: Vec::new(),
        logs: Default::default(),
    }
}

pub fn reset() -> ResetRecord {
    ResetRecord {
        step_num: 0,
        action_timestamp: format_timestamp(0),
        action: None,
        observation: ObservationKeys {
            screenshot: TaskDir::screenshot_name(None, &format_timestamp(0)),
            instruction: "i".into(),
            window_title: "Program Manager".into(),
            window_names_str: "Program Manager".into(),
            ..ObservationKeys::default()
        },
    }
}

pub fn layout(root: &Path) -> RunLayout {
    RunLayout {
        root: root.to_owned(),
        agent: "scripted".into(),
        observation: "a11y_tree".into(),
        model: "meta/llama:3".into(),
        trial: "0".into(),
    }
}

pub fn task(domain: &str, name: &str) -> Task {
    let text = r#"{"id": "x", "instruction": "i", "config": [], "evaluator": {"func": "infeasible"}}"#;
    Task::parse(text, &PathBuf::from(format!("/tasks/{domain}/{name}.json"))).unwrap()
}

/// Writes a finished (or unfinished) task under `root` with the upstream layout.
pub fn write_task(root: &Path, domain: &str, name: &str, score: f64, status: EpisodeStatus) {
    let dir = layout(root).task_dir(&task(domain, name));
    dir.prepare().unwrap();
    dir.write_screenshot(None, &format_timestamp(0), b"png").unwrap();
    dir.finish(&episode(domain, name, score, status, 2), Some(&reset()), &[step(1)]).unwrap();
}
