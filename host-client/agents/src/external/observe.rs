//! The one adapter from the harness's [`Observation`] to the step protocol's
//! `reset` and `observe` messages: every use of the observation by outside
//! agents is here, so that a change to the observation changes this file only.

use std::path::Path;

use base64::Engine as _;
use serde_json::{json, Map, Value};

use crate::observation::Observation;
use arena_som::Marks;
use arena_task::Task;

use super::protocol::{AgentHello, ScreenshotMode, TreeMode};

/// `reset`: the task, and the screen the episode runs on.
pub fn reset_message(task: &Task, obs: &Observation) -> Value {
    let (width, height) = obs.screen_size();
    json!({
        "type": "reset",
        "task_id": task.id,
        "task_name": task.name,
        "domain": task.domain,
        "instruction": task.instruction,
        "screen_width": width,
        "screen_height": height,
    })
}

/// `observe` with what `hello` asked for, and the Set-of-Marks boxes when it
/// asked for them (the ids `computer.mouse.move_id` resolves against).
///
/// # Errors
///
/// The screenshot file cannot be written (`screenshot: path`).
pub fn observe_message(
    obs: &Observation,
    hello: &AgentHello,
    local: bool,
    files: Option<&Path>,
) -> Result<(Value, Option<Marks>), String> {
    let wants = &hello.observation;
    let (width, height) = obs.screen_size();
    let mut m = Map::new();
    m.insert("type".into(), json!("observe"));
    m.insert("step".into(), json!(obs.step));
    m.insert("instruction".into(), json!(obs.instruction));
    m.insert("screen_width".into(), json!(width));
    m.insert("screen_height".into(), json!(height));
    let mode = wants.screenshot.unwrap_or(if local { ScreenshotMode::Path } else { ScreenshotMode::Inline });
    match (mode, files) {
        (ScreenshotMode::Path, Some(dir)) if local => {
            let path = dir.join(format!("step_{}.png", obs.step));
            std::fs::write(&path, &obs.screenshot.encoded[..])
                .map_err(|err| format!("writing the screenshot {}: {err}", path.display()))?;
            m.insert("screenshot".into(), json!({ "path": path.to_string_lossy() }));
        }
        (ScreenshotMode::Path, _) => {
            return Err("screenshot: path is only for agents on this machine (--agent exec); ask for inline".into());
        }
        (ScreenshotMode::Inline, _) => {
            let b64 = base64::engine::general_purpose::STANDARD.encode(&obs.screenshot.encoded[..]);
            m.insert("screenshot".into(), json!({ "png_base64": b64 }));
        }
        (ScreenshotMode::None, _) => {}
    }
    match (wants.a11y, &obs.a11y) {
        (TreeMode::Xml, Some(tree)) => {
            m.insert("a11y_xml".into(), json!(arena_shared::a11y_xml::to_xml(tree, obs.foreground_id)));
        }
        (TreeMode::Tree, Some(tree)) => {
            m.insert("a11y_tree".into(), serde_json::to_value(tree).unwrap_or(Value::Null));
        }
        (TreeMode::Xml | TreeMode::Tree, None) => {
            m.insert("a11y_xml".into(), Value::Null);
        }
        (TreeMode::None, _) => {}
    }
    if wants.windows {
        m.insert("windows".into(), json!(obs.window_titles));
        m.insert("window_title".into(), json!(obs.foreground_title));
    }
    if wants.clipboard {
        m.insert("clipboard".into(), json!(obs.clipboard));
        m.insert("computer_clipboard".into(), json!(obs.tracked_clipboard));
    }
    let marks = if wants.som { obs.marks() } else { None };
    if let Some(marks) = &marks {
        let listed: Vec<Value> = marks
            .entities
            .iter()
            .map(|e| json!({ "id": e.id, "kind": e.kind, "text": e.text, "rect": marks.rects.get(e.id) }))
            .collect();
        m.insert("som".into(), json!({ "rects": marks.rects, "marks": listed }));
    }
    Ok((Value::Object(m), marks))
}
