//! Tests of result folders: layout, trajectories, scores, the summary and the report.

use std::collections::BTreeMap;

use super::fixtures::{episode, layout, reset, step, task, write_task};
use super::summary::{self, Summary};
use super::*;

#[test]
fn scores_are_written_as_python_prints_floats() {
    fn check(value: f64, expected: &str) {
        assert_eq!(python_float(value), expected, "{value}");
    }
    check(1.0, "1.0");
    check(0.0, "0.0");
    check(0.5, "0.5");
    check(1.0 / 3.0, "0.3333333333333333");
    check(-2.0, "-2.0");
}

#[test]
fn scores_are_read_in_every_form_upstream_writes() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(RESULT_FILE);
    for (text, expected) in [
        ("1.0\n", Some(1.0)),
        ("0\n", Some(0.0)),
        ("True\n", Some(1.0)),
        ("False", Some(0.0)),
        ("0.25 ", Some(0.25)),
        ("nan", None),
        ("", None),
        ("score", None),
    ] {
        std::fs::write(&path, text).unwrap();
        assert_eq!(read_score(&path).ok(), expected, "{text:?}");
    }
}

#[test]
fn timestamps_are_upstream_format_in_utc() {
    assert_eq!(format_timestamp(0), "19700101@000000");
    assert_eq!(format_timestamp(1_700_000_000), "20231114@221320");
    assert_eq!(format_timestamp(951_782_400), "20000229@000000");
    assert_eq!(timestamp_now().len(), 15);
}

#[test]
fn folder_names_are_made_safe() {
    fn check(input: &str, expected: &str) {
        assert_eq!(safe_component(input), expected, "{input:?}");
    }
    check("gpt-4o", "gpt-4o");
    check("meta/llama-3:70b", "meta_llama-3_70b");
    check("..", "_");
    check("", "_");
    check(r"a\b", "a_b");
}

#[test]
fn layout_mirrors_upstream() {
    let l = layout(Path::new("/out"));
    let dir = l.task_dir(&task("notepad", "draft"));
    assert_eq!(dir.path(), Path::new("/out/scripted/a11y_tree/meta_llama_3/0/notepad/draft"));
}

#[test]
fn result_txt_is_written_last_and_only_for_finished_episodes() {
    let root = tempfile::tempdir().unwrap();
    let l = layout(root.path());
    let dir = l.task_dir(&task("notepad", "draft"));
    dir.prepare().unwrap();
    assert!(!dir.is_finished());
    dir.write_screenshot(None, &format_timestamp(0), b"png").unwrap();
    let mut steps = vec![step(1)];
    steps[0].more.push(ActionRecord { step_num: 1, action: "WAIT".into(), ..ActionRecord::default() });
    let infra = episode("notepad", "draft", 0.0, EpisodeStatus::InfraError("guest gone".into()), 1);
    dir.finish(&infra, Some(&reset()), &steps).unwrap();
    assert!(!dir.is_finished(), "an infrastructure error leaves the task to be run again");
    assert_eq!(dir.read_episode().unwrap(), infra);

    // A new try starts from an empty folder.
    dir.prepare().unwrap();
    assert!(!dir.path().join(EPISODE_FILE).exists());
    assert!(dir.setup_dir().is_dir() && dir.eval_dir().is_dir());
    let done = episode("notepad", "draft", 1.0, EpisodeStatus::Completed, 1);
    dir.finish(&done, Some(&reset()), &steps).unwrap();
    assert!(dir.is_finished());
    assert_eq!(std::fs::read_to_string(dir.path().join(RESULT_FILE)).unwrap(), "1.0\n");
    // Read back: the steps (their further upstream lines are not ours to read).
    let mut back = steps.clone();
    back[0].more.clear();
    assert_eq!(dir.read_trajectory().unwrap(), back);
    // Upstream's lines: the reset line (step 0, action null), then one line per action.
    let text = std::fs::read_to_string(dir.path().join(TRAJ_FILE)).unwrap();
    let lines: Vec<Value> = text.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(lines.len(), 3, "{text}");
    assert_eq!((lines[0]["step_num"].clone(), lines[0]["action"].clone()), (serde_json::json!(0), Value::Null));
    assert_eq!(lines[0]["screenshot"], "screenshot-step_reset_19700101@000000.png");
    for key in ["step_num", "action_timestamp", "action", "reward", "done", "info", "screenshot", "window_title"] {
        assert!(lines[1].get(key).is_some() && lines[2].get(key).is_some(), "traj.jsonl lacks {key}: {text}");
    }
    assert_eq!(lines[1]["screenshot"], "screenshot-step_0_19700101@000000.png");
    for key in ["step", "response", "actions", "ended", "screenshot_file", "timings"] {
        assert!(lines[1].get(key).is_some(), "our key {key} is beside upstream's: {text}");
    }
    assert_eq!(
        (lines[2]["step_num"].clone(), lines[2]["action"].clone()),
        (serde_json::json!(1), serde_json::json!("WAIT"))
    );
    // The task's own page, with its screenshots linked relative to it.
    let page = std::fs::read_to_string(dir.path().join(TRAJ_HTML)).unwrap();
    assert!(page.starts_with("<!DOCTYPE html>") && page.contains("<details open"), "{page}");
    assert!(page.contains("src=\"./screenshot-step_reset_19700101@000000.png\""), "{page}");
    // No temporary files are left behind.
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with(".partial"))
        .collect();
    assert!(leftovers.is_empty());
}

#[test]
fn a_bad_trajectory_line_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(TRAJ_FILE);
    let good = serde_json::to_string(&step(1)).unwrap();
    std::fs::write(&path, format!("{good}\n\n{{\"step\": \"x\"}}\n")).unwrap();
    let err = read_trajectory(&path).unwrap_err().to_string();
    assert!(err.contains("line 3"), "{err}");
    assert!(read_trajectory(&dir.path().join("absent.jsonl")).unwrap().is_empty());
}

#[test]
fn the_summary_gives_the_papers_table() {
    let root = tempfile::tempdir().unwrap();
    write_task(root.path(), "notepad", "a", 1.0, EpisodeStatus::Completed);
    write_task(root.path(), "notepad", "b", 0.0, EpisodeStatus::AgentError("plan used up".into()));
    write_task(root.path(), "notepad", "c", 0.5, EpisodeStatus::Completed);
    write_task(root.path(), "file_explorer", "d", 1.0, EpisodeStatus::Completed);
    write_task(root.path(), "file_explorer", "e", 0.0, EpisodeStatus::InfraError("gone".into()));
    write_task(root.path(), "file_explorer", "f", 0.0, EpisodeStatus::EvaluatorError("expected getter".into()));
    let summary = Summary::from_dir(root.path()).unwrap();
    // Upstream's rate: mean score x 100 over finished tasks; partial credit counts.
    assert_eq!(
        summary.table(),
        vec![
            ("file_explorer".to_owned(), 1, 1, 100.0),
            ("notepad".to_owned(), 3, 1, 50.0),
            ("Overall".to_owned(), 4, 2, 62.5),
        ]
    );
    assert!((summary.domains[1].solved_rate - 100.0 / 3.0).abs() < 1e-9);
    assert_eq!(summary.overall.solved_rate, 50.0);
    assert_eq!(summary.overall.unfinished, 2);
    assert_eq!(summary.overall.evaluator_errors, 1);
    let words = summary.incomplete_words().unwrap_or_default();
    assert!(words.contains("2 of 6 tasks have no result (1 of them because"), "{words}");
    assert_eq!(summary.domains[0].evaluator_errors, 1);
    assert_eq!(summary.domains[1].evaluator_errors, 0);
    assert_eq!(summary.overall.agent_errors, 1);
    assert!((summary.overall.mean_score - 2.5 / 4.0).abs() < 1e-9);
    assert_eq!(summary.overall.avg_steps, 2.0);
    assert_eq!(summary.unfinished().map(|t| t.name.as_str()).collect::<Vec<_>>(), ["e", "f"]);
    assert_eq!(summary.tasks[0].path, "scripted/a11y_tree/meta_llama_3/0/file_explorer/d");
    // Upstream's groups: file_explorer is "Windows System", notepad "Windows Utilities".
    let groups: Vec<(&str, u32, f64)> =
        summary.groups.iter().map(|g| (g.domain.as_str(), g.tasks, g.success_rate)).collect();
    assert_eq!(groups, vec![("Windows System", 1, 100.0), ("Windows Utilities", 3, 50.0)]);

    let (json, md) = summary.write(root.path()).unwrap();
    let back: Summary = serde_json::from_slice(&std::fs::read(json).unwrap()).unwrap();
    assert_eq!(back, summary);
    let md = std::fs::read_to_string(md).unwrap();
    assert!(md.contains("| notepad | 3 | 50.0% | 1 | 33.3% |"), "{md}");
    assert!(md.contains("| **Overall** | 4 | 62.5% | 2 | 50.0% |"), "{md}");
    assert!(md.contains("| *Windows Utilities* | 3 | 50.0% |"), "{md}");
    assert!(md.contains("plan used up"), "{md}");
}

#[test]
fn a_folder_of_two_agents_says_its_rows_pool_them_and_gives_each_alone() {
    let root = tempfile::tempdir().unwrap();
    write_task(root.path(), "notepad", "a", 1.0, EpisodeStatus::Completed);
    write_task(root.path(), "notepad", "b", 1.0, EpisodeStatus::Completed);
    let one = Summary::from_dir(root.path()).unwrap();
    assert!(one.agents.is_empty() && one.pooled_words().is_none(), "{:?}", one.agents);
    assert!(!one.markdown().contains("different agents"));
    // A second agent's results in the same folder: a different model level.
    let other = RunLayout { model: "external-0badc0de".into(), ..layout(root.path()) };
    for (name, score) in [("a", 0.0), ("b", 0.0)] {
        let dir = other.task_dir(&task("notepad", name));
        dir.prepare().unwrap();
        dir.finish(&episode("notepad", name, score, EpisodeStatus::Completed, 2), Some(&reset()), &[step(1)]).unwrap();
    }
    let both = Summary::from_dir(root.path()).unwrap();
    assert_eq!(both.overall.success_rate, 50.0);
    let rows: Vec<(&str, u32, f64)> =
        both.agents.iter().map(|r| (r.domain.as_str(), r.tasks, r.success_rate)).collect();
    assert_eq!(
        rows,
        vec![("scripted/a11y_tree/external-0badc0de", 2, 0.0), ("scripted/a11y_tree/meta_llama_3", 2, 100.0)]
    );
    let words = both.pooled_words().unwrap();
    assert!(words.contains("2 different agents or models"), "{words}");
    let md = both.markdown();
    assert!(md.contains(&words), "{md}");
    assert!(md.contains("| scripted/a11y_tree/meta_llama_3 | 2 | 100.0% | 100.0% | 2 | 0 |"), "{md}");
    let html = super::html::render(&both, &[], "t");
    assert!(html.contains("id=\"pooled\"") && html.contains("external-0badc0de"), "{html}");
}

/// (tasks, rate) of a set of tasks.
type Rate = (usize, f64);

/// Upstream's `show_result.py` rules, written here from their description:
/// under the trial folder, each `<domain>/<task>` folder holding `result.txt`
/// counts with `float(text)`, or `float(bool(text))` when that raises; the rate
/// of a set of tasks is `sum / len * 100`. Answers (per domain, overall, and the
/// folders without `result.txt`).
fn upstream_show_result(trial: &Path) -> (BTreeMap<String, Rate>, Rate, Vec<String>) {
    let mut per_domain: BTreeMap<String, Vec<f64>> = BTreeMap::new();
    let mut missing = Vec::new();
    for domain in std::fs::read_dir(trial).unwrap().flatten().filter(|e| e.path().is_dir()) {
        let name = domain.file_name().to_string_lossy().into_owned();
        for task in std::fs::read_dir(domain.path()).unwrap().flatten().filter(|e| e.path().is_dir()) {
            match std::fs::read_to_string(task.path().join(RESULT_FILE)) {
                Ok(text) => {
                    let value = match text.trim().parse::<f64>() {
                        Ok(v) => v,
                        Err(_) => f64::from(u8::from(!text.is_empty())),
                    };
                    per_domain.entry(name.clone()).or_default().push(value);
                }
                Err(_) => missing.push(format!("{name}/{}", task.file_name().to_string_lossy())),
            }
        }
    }
    let rate = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64 * 100.0;
    let all: Vec<f64> = per_domain.values().flatten().copied().collect();
    missing.sort();
    (per_domain.iter().map(|(d, v)| (d.clone(), (v.len(), rate(v)))).collect(), (all.len(), rate(&all)), missing)
}

#[test]
fn upstreams_result_reading_rules_give_the_same_rates_as_the_report() {
    let root = tempfile::tempdir().unwrap();
    write_task(root.path(), "notepad", "a", 1.0, EpisodeStatus::Completed);
    write_task(root.path(), "notepad", "b", 0.25, EpisodeStatus::Completed);
    write_task(root.path(), "chrome", "c", 0.0, EpisodeStatus::AgentError("plan used up".into()));
    write_task(root.path(), "chrome", "d", 1.0 / 3.0, EpisodeStatus::Completed);
    write_task(root.path(), "vlc", "e", 0.0, EpisodeStatus::ModelError("503".into()));
    write_task(root.path(), "vlc", "f", 1.0, EpisodeStatus::Completed);
    let (html_summary, _) = html::write_report(root.path(), "run").unwrap();
    let summary = Summary::from_dir(root.path()).unwrap();
    assert_eq!(html_summary, summary);
    let trial = layout(root.path()).base();
    let (domains, overall, missing) = upstream_show_result(&trial);
    let ours: BTreeMap<String, Rate> =
        summary.domains.iter().map(|d| (d.domain.clone(), (d.tasks as usize, d.success_rate))).collect();
    assert_eq!(domains.keys().collect::<Vec<_>>(), ours.keys().collect::<Vec<_>>());
    for (domain, (n, rate)) in &domains {
        let (our_n, our_rate) = ours[domain];
        assert_eq!(*n, our_n, "{domain}");
        assert!((rate - our_rate).abs() < 1e-9, "{domain}: upstream {rate}, ours {our_rate}");
    }
    assert_eq!(overall.0, summary.overall.tasks as usize);
    assert!((overall.1 - summary.overall.success_rate).abs() < 1e-9, "{overall:?} vs {:?}", summary.overall);
    assert_eq!(missing, vec!["vlc/e".to_owned()]);

    // all_result.json and missing.json as show_result.py writes them, in the trial folder.
    let all: serde_json::Value =
        serde_json::from_slice(&std::fs::read(trial.join(summary::ALL_RESULT_JSON)).unwrap()).unwrap();
    assert_eq!(all["notepad"]["b"], serde_json::json!(0.25));
    assert_eq!(all["vlc"].as_object().map(|m| m.len()), Some(1));
    let text = std::fs::read_to_string(trial.join(summary::MISSING_JSON)).unwrap();
    assert_eq!(text, "{\n    \"vlc\": [\n        \"e\"\n    ]\n}");
}

#[test]
fn a_folder_without_a_record_still_counts_by_its_path() {
    let root = tempfile::tempdir().unwrap();
    let dir = root.path().join("code_block/a11y_tree/gpt-4o/0/chrome/task-1");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join(RESULT_FILE), "1.0\n").unwrap();
    let summary = Summary::from_dir(root.path()).unwrap();
    assert_eq!(summary.table(), vec![("chrome".to_owned(), 1, 1, 100.0), ("Overall".to_owned(), 1, 1, 100.0)]);
    assert_eq!(summary.tasks[0].status, "unknown");
    assert!(Summary::from_dir(&root.path().join("absent")).is_err());
}

#[test]
fn the_report_holds_the_table_the_chart_and_escaped_trajectories() {
    let root = tempfile::tempdir().unwrap();
    write_task(root.path(), "notepad", "a b", 1.0, EpisodeStatus::Completed);
    write_task(root.path(), "notepad", "<script>", 0.0, EpisodeStatus::Completed);
    let (summary, path) = html::write_report(root.path(), "Run <1>").unwrap();
    assert_eq!(summary.overall.tasks, 2);
    let page = std::fs::read_to_string(path).unwrap();
    assert!(page.starts_with("<!DOCTYPE html>"));
    assert!(page.contains("<table id=\"summary\">") && page.contains("<svg") && page.contains("Run &lt;1&gt;"));
    assert!(page.contains("&lt;script&gt;") && page.matches("<script>").count() == 1, "task text is escaped");
    assert!(page.contains("&lt;b&gt;ok&lt;/b&gt;"), "model text is escaped");
    // Safe names keep spaces out of folders; links are relative and encoded.
    assert!(
        page.contains(
            "src=\"scripted/a11y_tree/meta_llama_3/0/notepad/a_b/screenshot-step_reset_19700101@000000.png\""
        ),
        "{page}"
    );
    assert!(!page.contains("<link") && !page.contains("url("), "nothing is fetched");
    assert_eq!(page.matches("<script").count(), 1, "the page's own script alone");
    assert!(page.contains("Content-Security-Policy") && page.contains("script-src 'sha256-"));
    assert!(root.path().join(SUMMARY_JSON).is_file() && root.path().join(SUMMARY_MD).is_file());
}

#[test]
fn the_fail_always_floor_is_the_infeasible_share_of_the_task_list_per_row() {
    let root = tempfile::tempdir().unwrap();
    write_task(root.path(), "settings", "inf", 1.0, EpisodeStatus::Completed);
    write_task(root.path(), "notepad", "a", 0.0, EpisodeStatus::Completed);
    // A folder from before the floor was kept: no task list, no floor.
    let old = Summary::from_dir(root.path()).unwrap();
    assert_eq!(old.overall.fail_floor, None);
    assert!(old.floor_words().is_none() && !old.markdown().contains("FAIL-always floor"));
    // The run's list: one infeasible task of four (one never started), recorded beside it.
    let infeasible = task("settings", "inf");
    let mut feasible: Vec<Task> = ["a", "b"].iter().map(|n| task("notepad", n)).collect();
    feasible.push(task("file_explorer", "c"));
    for t in &mut feasible {
        t.evaluator.scoring =
            arena_task::Scoring::Metrics { conj: arena_task::Conj::And, calls: Vec::new(), listed: false };
    }
    let listed: Vec<&Task> = std::iter::once(&infeasible).chain(&feasible).collect();
    task_list::record(&layout(root.path()).base(), &listed).unwrap();
    let summary = Summary::from_dir(root.path()).unwrap();
    assert_eq!(summary.overall.fail_floor, Some(25.0));
    let floor = |name: &str| summary.domains.iter().find(|d| d.domain == name).and_then(|d| d.fail_floor);
    assert_eq!((floor("settings"), floor("notepad"), floor("file_explorer")), (Some(100.0), Some(0.0), Some(0.0)));
    // The Windows System group (file_explorer, settings): one of two.
    let group = summary.groups.iter().find(|g| g.domain == "Windows System").expect("the group");
    assert_eq!(group.fail_floor, Some(50.0));
    assert!(summary.markdown().contains("FAIL-always floor 25.0%"), "{}", summary.markdown());
    let json: Value = serde_json::to_value(&summary).unwrap();
    assert_eq!(json["overall"]["fail_floor"], 25.0);
}

/// A task folder holding one computer-use step: a 40x20 screenshot, the
/// vendor's answer kept as `response-step_0_<time>.json` (a log named `response`,
/// so the line has its name in `log_response` beside the model's text), a click
/// and a drag in typed actions, the step's tokens and an action error.
fn computer_use_task(root: &Path, answer: &Value) -> TaskDir {
    let dir = layout(root).task_dir(&task("notepad", "cu"));
    dir.prepare().unwrap();
    let timestamp = format_timestamp(0);
    let mut png = Vec::new();
    image::RgbaImage::from_pixel(40, 20, image::Rgba([200, 200, 200, 255]))
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .unwrap();
    let shot = dir.write_screenshot(None, &timestamp, &png).unwrap();
    let record = format!("response-step_0_{timestamp}.json");
    dir.write_file(&record, serde_json::to_vec(answer).unwrap().as_slice()).unwrap();
    let mut first = step(1);
    first.screenshot_file = shot;
    first.response = "the model's text".into();
    first.logs.insert("response".into(), Value::String(record));
    first.actions = vec![
        arena_exec::AgentAction::Typed(vec![
            arena_shared::action::Action::Click { x: Some(30), y: Some(5), button: Default::default(), count: 1 },
            arena_shared::action::Action::Drag {
                from: Some(arena_shared::geometry::Point::new(2, 3)),
                to: arena_shared::geometry::Point::new(12, 13),
                button: Default::default(),
                duration_ms: None,
            },
        ]),
        arena_exec::AgentAction::Done,
    ];
    first.outcomes = vec![serde_json::json!({"error": "key <x> unknown", "performed": 1, "elapsed_ms": 1})];
    first.usage = Some(crate::ledger::Usage { input: 1234, output: 56, cached: 1000, model_ms: 250 });
    let mut episode = episode("notepad", "cu", 0.0, EpisodeStatus::Completed, 1);
    episode.action_errors = 1;
    dir.finish(&episode, Some(&reset()), &[first]).unwrap();
    dir
}

/// An agent's `record` (or any log) naming fields the line already has cannot
/// overwrite them: each goes in as `log_<name>`, and no key is written twice.
#[test]
fn logs_named_as_the_lines_own_fields_never_overwrite_them() {
    let root = tempfile::tempdir().unwrap();
    let dir = layout(root.path()).task_dir(&task("notepad", "hostile"));
    dir.prepare().unwrap();
    let mut first = step(1);
    first.response = "hi".into();
    first.screenshot_file = "shot.png".into();
    for (key, value) in [
        ("step", serde_json::json!("pwned")),
        ("reward", serde_json::json!(99)),
        ("screenshot_file", serde_json::json!("../../../../etc/passwd")),
        ("log_step", serde_json::json!("taken")),
        ("thoughts", serde_json::json!("fine")),
    ] {
        first.logs.insert(key.into(), value);
    }
    let episode = episode("notepad", "hostile", 0.0, EpisodeStatus::Completed, 1);
    dir.finish(&episode, Some(&reset()), std::slice::from_ref(&first)).unwrap();
    let text = std::fs::read_to_string(dir.path().join(TRAJ_FILE)).unwrap();
    let line = text.lines().nth(1).expect("the step's line");
    for key in ["\"step\":", "\"reward\":", "\"screenshot_file\":", "\"log_step\":"] {
        assert_eq!(line.matches(key).count(), 1, "{key} once in {line}");
    }
    let value: Value = serde_json::from_str(line).unwrap();
    assert_eq!(
        (&value["step"], &value["reward"], &value["screenshot_file"]),
        (&serde_json::json!(1), &serde_json::json!(0.0), &serde_json::json!("shot.png"))
    );
    assert_eq!(value["log_reward"], 99);
    assert_eq!(value["log_screenshot_file"], "../../../../etc/passwd");
    assert_eq!(
        (&value["log_step"], &value["log_log_step"]),
        (&serde_json::json!("taken"), &serde_json::json!("pwned"))
    );
    assert_eq!(value["thoughts"], "fine", "a name the line does not have goes in as it is");
    assert!(line.starts_with("{\"step_num\":1,"), "the line's own fields keep their order: {line}");
    let back = dir.read_trajectory().unwrap();
    assert_eq!((back.len(), back[0].step, back[0].screenshot_file.as_str()), (1, 1, "shot.png"));
}

#[test]
fn a_computer_use_step_shows_the_models_text_tool_calls_markers_tokens_and_errors_escaped() {
    let root = tempfile::tempdir().unwrap();
    let answer = serde_json::json!({
        "type": "message", "role": "assistant", "stop_reason": "tool_use",
        "content": [
            {"type": "thinking", "thinking": "Where is the box?"},
            {"type": "text", "text": "I click <script>alert(1)</script> & go"},
            {"type": "tool_use", "id": "t1", "name": "computer", "input": {"action": "left_click", "coordinate": [27, 4]}},
        ],
        "usage": {"input_tokens": 234, "cache_read_input_tokens": 1000, "output_tokens": 56},
    });
    let dir = computer_use_task(root.path(), &answer);
    let page = std::fs::read_to_string(dir.path().join(TRAJ_HTML)).unwrap();
    // The model's text and reasoning, escaped; the tool call with its input.
    assert!(page.contains("I click &lt;script&gt;alert(1)&lt;/script&gt; &amp; go"), "{page}");
    assert!(!page.contains("<script>alert"), "a reply cannot inject markup");
    assert_eq!(page.matches("<script").count(), 1, "the page's own script alone");
    assert!(page.contains("Where is the box?") && page.contains("<code>computer</code>"));
    assert!(page.contains("&quot;left_click&quot;") && page.contains("&quot;coordinate&quot;"), "{page}");
    assert!(page.contains("href=\"./response-step_0_19700101@000000.json\""), "the record is linked");
    // Markers in the screenshot's pixels over an image of its natural size.
    assert!(page.contains("viewBox=\"0 0 40 20\""), "{page}");
    assert!(page.contains("data-kind=\"click\" data-x=\"30\" data-y=\"5\" data-action=\"1\""), "{page}");
    assert!(
        page.contains("data-kind=\"drag\" data-x=\"2\" data-y=\"3\" data-action=\"1\" data-x2=\"12\" data-y2=\"13\"")
    );
    assert!(page.contains("<li>action 1: drag from (2, 3) to (12, 13)</li>"));
    // Tokens, the action error (escaped), the keys.
    assert!(page.contains("data-input=\"1234\" data-output=\"56\" data-cached=\"1000\""), "{page}");
    assert!(page.contains("action 1: key &lt;x&gt; unknown"), "{page}");
    assert!(page.contains("<span class=\"action-errors\">1</span>"));
    assert!(page.contains("id=\"keys\"") && page.contains("<kbd>j</kbd>"));
    // The saved screenshot is left as it was: markers are drawn by the page.
    let shot = image::open(dir.path().join(TaskDir::screenshot_name(None, &format_timestamp(0)))).unwrap();
    assert!(shot.to_rgba8().pixels().all(|p| p.0 == [200, 200, 200, 255]));
}

#[test]
fn markers_of_a_screen_larger_than_its_screenshot_are_drawn_scaled_onto_it() {
    let root = tempfile::tempdir().unwrap();
    let dir = computer_use_task(root.path(), &serde_json::json!({"content": "ok"}));
    let mut steps = dir.read_trajectory().unwrap();
    // The screen was 80x40 and the screenshot is 40x20: the click at (30, 5) is drawn at (15, 2.5).
    steps[0].screen = Some([80, 40]);
    let episode = dir.read_episode().unwrap();
    dir.write_trajectory(None, &steps).unwrap();
    html::write_task_page(&dir, &episode).unwrap();
    let page = std::fs::read_to_string(dir.path().join(TRAJ_HTML)).unwrap();
    assert!(page.contains("data-kind=\"click\" data-x=\"30\" data-y=\"5\""), "{page}");
    assert!(page.contains("<circle class=\"dot\" cx=\"15.0\" cy=\"2.5\""), "{page}");
    assert!(page.contains("positions in the screen's 80x40 pixels, drawn on the 40x20 screenshot"));
}

#[test]
fn replies_of_each_vendor_shape_and_the_report_filter() {
    use super::viewer::vendor_reply;
    let responses = serde_json::json!({"output": [
        {"type": "reasoning", "summary": [{"type": "summary_text", "text": "think"}]},
        {"type": "message", "content": [{"type": "output_text", "text": "hello"}]},
        {"type": "computer_call", "call_id": "c", "action": {"type": "click", "x": 1, "y": 2}},
        {"type": "function_call", "name": "f", "arguments": "{\"a\": 1}"},
    ]});
    let r = vendor_reply(&responses).unwrap();
    assert_eq!(r.texts, [("reasoning".to_owned(), "think".to_owned()), ("text".to_owned(), "hello".to_owned())]);
    assert_eq!(r.tool_calls.iter().map(|c| c.name.as_str()).collect::<Vec<_>>(), ["computer", "f"]);
    assert!(r.tool_calls[0].input.contains("\"click\"") && r.tool_calls[1].input.contains("\"a\": 1"));
    let chat = serde_json::json!({"choices": [{"message": {"content": "Thought: x\nAction: click(start_box='(1,2)')",
        "tool_calls": [{"function": {"name": "g", "arguments": "not json"}}]}}]});
    let r = vendor_reply(&chat).unwrap();
    assert!(r.texts[0].1.starts_with("Thought: x"));
    assert_eq!((r.tool_calls[0].name.as_str(), r.tool_calls[0].input.as_str()), ("g", "not json"));
    assert_eq!(vendor_reply(&serde_json::json!({"content": "uitars"})).unwrap().texts[0].1, "uitars");
    assert!(vendor_reply(&serde_json::json!({"other": 1})).is_none());

    // A record name that leaves the folder is text, never a file read.
    let root = tempfile::tempdir().unwrap();
    let dir = computer_use_task(root.path(), &serde_json::json!({"content": "ok"}));
    let mut s = step(1);
    s.response = "../../response-step_0_x.json".into();
    let reply = super::viewer::reply_of(dir.path(), &s, &Value::Null);
    assert_eq!((reply.record, reply.texts[0].1.as_str()), (None, "../../response-step_0_x.json"));
    // A reply that only looks like a record name, with no such file: its text, and why it is no record.
    s.response = "response-step_9_nothing.json".into();
    let reply = super::viewer::reply_of(dir.path(), &s, &Value::Null);
    assert_eq!(reply.texts[0].1, "response-step_9_nothing.json");
    assert!(reply.problem.is_some_and(|p| p.starts_with("response-step_9_nothing.json: ")));

    // The report's filter offers each domain, status and "Failed by" of the run;
    // writing the report writes each task's page again (a folder of an older version gets the viewer).
    write_task(root.path(), "settings", "b", 1.0, EpisodeStatus::Completed);
    std::fs::write(dir.path().join(TRAJ_HTML), "old").unwrap();
    let (_, path) = html::write_report(root.path(), "run").unwrap();
    assert!(std::fs::read_to_string(dir.path().join(TRAJ_HTML)).unwrap().contains("class=\"step\""));
    let page = std::fs::read_to_string(path).unwrap();
    for option in ["<option value=\"notepad\">", "<option value=\"settings\">", "<option value=\"completed\">"] {
        assert!(page.contains(option), "{option}: {page}");
    }
    assert!(page.contains("<select name=\"failed-by\">") && page.contains("<option value=\"agent\">"), "{page}");
    assert!(page.contains("data-task=\"\" data-domain=\"settings\" data-status=\"completed\" data-failed-by=\"-\""));
}

#[test]
fn an_io_error_is_said_once_in_a_chain() {
    let err =
        super::ResultsError::io(Path::new("/nowhere/results"), std::io::Error::from(std::io::ErrorKind::NotFound));
    let said = format!("{:#}", anyhow::Error::new(err).context("arena report"));
    assert_eq!(said.matches("not found").count(), 1, "{said}");
    assert!(said.contains("/nowhere/results"), "{said}");
}

#[test]
fn an_old_eval_error_is_read_as_evaluator_error_and_written_by_the_new_name() {
    // Folders written before the rename hold `eval_error`; they must merge and resume.
    let old: EpisodeStatus =
        serde_json::from_value(serde_json::json!({"kind": "eval_error", "message": "exact_match: gold"})).unwrap();
    assert_eq!(old, EpisodeStatus::EvaluatorError("exact_match: gold".into()));
    assert!(old.is_unfinished());
    assert_eq!(old.kind(), "evaluator_error");
    assert_eq!(Blame::of(&old, 0.0), Blame::Evaluator);
    assert_eq!(
        serde_json::to_value(&old).unwrap(),
        serde_json::json!({"kind": "evaluator_error", "message": "exact_match: gold"})
    );
}
