//! Tests of task loading: every upstream corpus file, the index files, and the errors
//! that name the file and the unknown name.

use super::*;

/// The upstream corpus, or `None` after a loud, counted skip.
fn corpus_root(test: &str) -> Option<PathBuf> {
    arena_test_support::waa_corpus(test)
}

#[test]
fn every_upstream_task_file_loads() {
    let Some(root) = corpus_root("task::every_upstream_task_file_loads") else { return };
    let (tasks, errors) = load_dir(&root);
    let errors: Vec<String> = errors.iter().map(ToString::to_string).collect();
    assert!(errors.is_empty(), "task files that do not load:\n{}", errors.join("\n"));
    assert_eq!(tasks.len(), 308, "154 normal + 154 hard task files");
    assert_eq!(tasks.iter().filter(|t| matches!(t.evaluator.scoring, Scoring::Infeasible)).count(), 26);
}

#[test]
fn every_index_resolves_in_both_difficulties() {
    let Some(root) = corpus_root("task::every_index_resolves_in_both_difficulties") else { return };
    for (index, count) in [("test_all.json", 154), ("test_small.json", 6), ("test_custom.json", 1)] {
        for difficulty in [Difficulty::Normal, Difficulty::Hard] {
            let tasks = load_index(&root, &root.join(index), difficulty).unwrap();
            assert_eq!(tasks.len(), count, "{index} {difficulty:?}");
        }
    }
}

#[test]
fn the_name_is_the_file_stem_and_the_domain_the_folder() {
    let Some(root) = corpus_root("task::the_name_is_the_file_stem_and_the_domain_the_folder") else { return };
    let path = root.join("examples/vlc/INF-0d95d28a-9587-433b-a805-1fbe5467d598-WOS.json");
    let task = Task::load(&path).unwrap();
    assert_eq!(task.name, "INF-0d95d28a-9587-433b-a805-1fbe5467d598-WOS");
    assert_eq!(task.id, "INF-5ac2891a-eacd-4954-b339-98abba077adb-WOS");
    assert_eq!(task.domain, "vlc");
}

#[test]
fn the_corpus_uses_every_step_type_once_at_least() {
    let Some(root) = corpus_root("task::the_corpus_uses_every_step_type_once_at_least") else { return };
    let (tasks, _) = load_dir(&root);
    let mut seen: Vec<&str> =
        tasks.iter().flat_map(|t| t.config.iter().chain(&t.evaluator.postconfig)).map(SetupStep::kind).collect();
    seen.sort_unstable();
    seen.dedup();
    assert_eq!(seen.len(), 12, "{seen:?}");
}

fn check(json: &str, expected_error: &str) {
    let err = Task::parse(json, Path::new("tasks/demo/t1.json")).unwrap_err().to_string();
    assert!(err.starts_with("tasks/demo/t1.json: "), "{err}");
    assert!(err.contains(expected_error), "expected {expected_error:?} in {err:?}");
}

fn task_json(config: &str, evaluator: &str) -> String {
    format!(r#"{{"id": "t1", "instruction": "do it", "config": {config}, "evaluator": {evaluator}}}"#)
}

#[test]
fn bad_tasks_fail_at_load_naming_the_file_and_the_name() {
    let ok_eval = r#"{"func": "exact_match", "result": {"type": "vm_file", "path": "a"}, "expected": {"type": "rule", "rules": {}}}"#;
    check(
        &task_json(r#"[{"type": "teleport", "parameters": {}}]"#, ok_eval),
        "config[0] (teleport): unknown setup step type `teleport`",
    );
    check(
        &task_json(r#"[{"type": "sleep", "parameters": {}}]"#, ok_eval),
        "config[0] (sleep): missing parameter `seconds`",
    );
    check(
        &task_json(r#"[{"type": "sleep", "parameters": {"seconds": "2"}}]"#, ok_eval),
        "`seconds` must be a number, not a string",
    );
    check(
        &task_json(r#"[{"type": "launch", "parameters": {"command": 5}}]"#, ok_eval),
        "`command` must be a string or a list of strings",
    );
    check(&task_json("[]", r#"{"func": "made_up_metric"}"#), "unknown metric `made_up_metric`");
    check(
        &task_json("[]", r#"{"func": "exact_match", "result": {"type": "vm_fiel"}}"#),
        "evaluator.result: unknown getter `vm_fiel`",
    );
    check(
        &task_json("[]", r#"{"func": ["exact_match", "compare_text_file"], "result": [{"type": "vm_file"}]}"#),
        "evaluator.result has 1 entries for 2 metrics",
    );
    check(&task_json("[]", r#"{"func": "exact_match", "conj": "xor"}"#), "evaluator.conj must be");
    check(
        &task_json("[]", r#"{"func": "exact_match", "postconfig": [{"type": "nope"}]}"#),
        "evaluator.postconfig[0] (nope)",
    );
    check("{\"id\": 1}", "invalid JSON");
}

#[test]
fn upstream_shapes_are_understood() {
    let json = task_json(
        r#"[{"type": "execute", "parameters": {"command": "taskkill /f /im x.exe", "shell": "true", "until": {"returncode": 0}}},
            {"type": "command", "parameters": {"command": ["cmd", "/c", "echo"]}},
            {"type": "activate_window", "parameters": {"window_name": "Notepad", "strict": true}}]"#,
        r#"{"func": ["exact_match", "compare_text_file"], "conj": "or",
            "result": [{"type": "vm_file", "path": "a"}, {"type": "vm_file", "path": "b"}],
            "expected": [{"type": "rule", "rules": {"expected": 1}}, null],
            "options": [{}, {"ignore_blanks": true}], "_comments": "kept"}"#,
    );
    let task = Task::parse(&json, Path::new("x/notepad/t1.json")).unwrap();
    assert_eq!(task.domain, "notepad");
    assert_eq!(
        task.config[0],
        SetupStep::Execute {
            command: CommandArg::Str("taskkill /f /im x.exe".into()),
            shell: true,
            stdout: None,
            stderr: None,
            until: Some(Until { returncode: Some(0), stdout: None, stderr: None }),
        }
    );
    assert_eq!(task.config[1].kind(), "execute");
    let Scoring::Metrics { conj, calls, .. } = &task.evaluator.scoring else { panic!("metrics expected") };
    assert_eq!(*conj, Conj::Or);
    assert_eq!(calls.len(), 2);
    assert_eq!(calls[1].expected, None);
    assert_eq!(calls[1].options.get("ignore_blanks"), Some(&Value::Bool(true)));
    let needs = task.needs();
    assert_eq!(needs.steps, ["execute", "activate_window"]);
    assert_eq!(needs.getters, ["vm_file", "rule"]);
}

#[test]
fn index_entries_are_task_ids_not_paths() {
    let dir = tempfile::tempdir().unwrap();
    let index = dir.path().join("test_x.json");
    let check = |json: &str, needle: Option<&str>| {
        std::fs::write(&index, json).unwrap();
        match (read_index(&index), needle) {
            (Ok(entries), None) => assert!(!entries.is_empty(), "{json}"),
            (Err(err), Some(needle)) => {
                let message = err.to_string();
                assert!(message.contains(needle) && message.contains("test_x.json"), "{json}: {message}");
            }
            (got, want) => panic!("{json}: got {got:?}, expected an error with {want:?}"),
        }
    };
    check(r#"{"chrome": ["0d8b7de3-e8de-4d86-b9fd-dd2dce58a217-WOS"]}"#, None);
    check(r#"{"chrome": ["../../x/evil"]}"#, Some("not a plain name"));
    check(r#"{"chrome": ["/etc/passwd"]}"#, Some("not a plain name"));
    check(r#"{"chrome": ["C:\\x\\evil"]}"#, Some("not a plain name"));
    check(r#"{"chrome": ["a\\b"]}"#, Some("not a plain name"));
    check(r#"{"chrome": [".."]}"#, Some("not a plain name"));
    check(r#"{"chrome": [""]}"#, Some("empty"));
    check(r#"{"../examples": ["x"]}"#, Some("domain"));
}

#[test]
fn oversize_task_files_and_instructions_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let domain = dir.path().join("chrome");
    std::fs::create_dir_all(&domain).unwrap();
    let task = |instruction: &str| {
        format!(r#"{{"id": "t", "instruction": "{instruction}", "config": [], "evaluator": {{"func": "infeasible"}}}}"#)
    };
    let ok = domain.join("ok.json");
    std::fs::write(&ok, task("Open Chrome.")).unwrap();
    assert!(Task::load(&ok).is_ok());
    let long = domain.join("long.json");
    std::fs::write(&long, task(&"x".repeat(MAX_INSTRUCTION_BYTES + 1))).unwrap();
    let err = Task::load(&long).unwrap_err().to_string();
    assert!(err.contains("long.json") && err.contains("instruction") && err.contains("65536"), "{err}");
    let huge = domain.join("huge.json");
    let file = std::fs::File::create(&huge).unwrap();
    file.set_len(MAX_TASK_FILE_BYTES + 1).unwrap();
    let err = Task::load(&huge).unwrap_err().to_string();
    assert!(err.contains("huge.json") && err.contains("at most 4194304"), "{err}");
}
