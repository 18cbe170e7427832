//! Answers stay with the grader (issue 30, item 8): no task of the stub set or
//! of the upstream corpus puts its expected side into the guest, the stub gold
//! is read on the host when the task is scored, and `arena validate` warns
//! about a task that writes its gold into the guest.

use std::path::{Path, PathBuf};
use std::process::Command;

use arena_task::{gold::exposed_answers, load_dir, Scoring};
use arena_test_support::{stub_tasks_dir, waa_corpus, workspace_binary};

fn arena() -> Command {
    Command::new(workspace_binary("arena-host", "arena").expect("the arena binary"))
}

#[test]
fn no_stub_task_puts_an_expected_file_into_the_guest() {
    let (tasks, errors) = load_dir(&stub_tasks_dir().join("examples"));
    assert!(errors.is_empty(), "{errors:?}");
    assert!(tasks.len() >= 6, "{} stub tasks", tasks.len());
    for task in &tasks {
        assert_eq!(exposed_answers(task), Vec::<String>::new(), "{}", task.name);
    }
    // The check is not vacuous: the stub tasks compare files against gold, and
    // every gold file is on the host, read with `host_file` beside the task.
    let mut host_gold = 0;
    for task in &tasks {
        let Scoring::Metrics { calls, .. } = &task.evaluator.scoring else { continue };
        for getter in calls.iter().filter_map(|c| c.expected.as_ref()) {
            assert_ne!(getter.kind, "vm_file", "{}: expected side read from the guest", task.name);
            if getter.kind == "host_file" {
                let path = getter.params["path"].as_str().unwrap();
                let file = task.path.parent().unwrap().join(path);
                assert!(file.is_file(), "{}: {} is missing", task.name, file.display());
                host_gold += 1;
            }
        }
    }
    assert!(host_gold >= 3, "only {host_gold} host gold files");
}

/// One upstream task hands the agent its expected side: it compares the copy the
/// agent makes with the original it downloaded to the Desktop, which the agent
/// can change too. The warning finds it (in both variants) and nothing else;
/// the task scores as upstream's (docs/compatibility.md, "Getters").
#[test]
fn in_the_corpus_only_the_copy_and_rename_task_hands_the_agent_its_expected_side() {
    let Some(corpus) = waa_corpus("in_the_corpus_only_the_copy_and_rename_task_hands_the_agent_its_expected_side")
    else {
        return;
    };
    let (tasks, _) = load_dir(&corpus);
    assert!(tasks.len() > 100, "{} corpus tasks", tasks.len());
    let mut exposed: Vec<String> = tasks
        .iter()
        .filter(|t| !exposed_answers(t).is_empty())
        .map(|t| {
            let variant = t.path.parent().and_then(Path::parent).and_then(Path::file_name).unwrap_or_default();
            format!("{}/{}/{}", variant.to_string_lossy(), t.domain, t.name)
        })
        .collect();
    exposed.sort();
    let task = "file_explorer/b8ab0ae1-d2b4-4e6f-b609-df7d76b456d7-WOS";
    assert_eq!(exposed, [format!("examples/{task}"), format!("examples_noctxt/{task}")]);
    let warning = exposed_answers(tasks.iter().find(|t| t.name.starts_with("b8ab0ae1")).unwrap());
    assert!(
        warning[0].contains("config step 1 (download) writes C:\\Users\\Docker\\Desktop\\example.txt"),
        "{warning:?}"
    );
}

#[test]
fn the_stub_gold_is_read_on_the_host_and_the_oracle_still_scores_every_task() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let run = arena()
        .args(["run", "--stub-guests", "2", "--pauses", "fast", "--tasks"])
        .arg(stub_tasks_dir().join("test_all.json"))
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(find(&out, "summary.json")).unwrap()).unwrap();
    assert_eq!(summary["overall"]["strict_rate"].as_f64(), Some(100.0), "{summary:#}");
    // The count task's gold came from the host into its evaluation folder.
    let gold = find(&out, "example_count_gold.txt");
    assert_eq!(std::fs::read_to_string(gold).unwrap(), "3");
}

#[test]
fn validate_warns_about_a_task_that_writes_its_gold_into_the_guest() {
    let dir = tempfile::tempdir().unwrap();
    let folder = dir.path().join("notepad");
    std::fs::create_dir_all(&folder).unwrap();
    let task = r#"{"id": "leaky", "instruction": "count", "config": [
        {"type": "create_file", "parameters": {"path": "C:\\gold\\count.txt", "content": "3"}}],
      "evaluator": {"func": "compare_text_file",
        "result": {"type": "vm_file", "path": "C:\\Users\\Docker\\count.txt", "dest": "count.txt"},
        "expected": {"type": "vm_file", "path": "C:\\gold\\count.txt", "dest": "gold.txt"}}}"#;
    std::fs::write(folder.join("leaky.json"), task).unwrap();
    let out = arena().arg("validate").arg(dir.path()).output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    // A warning, not a load error: the task still runs.
    assert!(out.status.success(), "{text}");
    assert!(text.contains("warning: notepad/leaky: config step 1 (create_file) writes C:\\gold\\count.txt"), "{text}");
    assert!(text.contains("1 task(s) hand the agent their expected side"), "{text}");

    let clean = arena().arg("validate").arg(stub_tasks_dir().join("test_all.json")).output().unwrap();
    let text = String::from_utf8_lossy(&clean.stdout);
    assert!(clean.status.success(), "{text}");
    assert!(!text.contains("warning:"), "{text}");
}

/// The first file named `name` below `root`.
fn find(root: &Path, name: &str) -> PathBuf {
    let mut stack = vec![root.to_owned()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).unwrap().flatten() {
            let path = entry.path();
            if path.is_dir() {
                stack.push(path);
            } else if path.file_name().is_some_and(|n| n == name) {
                return path;
            }
        }
    }
    panic!("no {name} below {}", root.display())
}
