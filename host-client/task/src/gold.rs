//! Answers an agent could reach: a task whose setup puts into the guest what
//! its evaluator reads as the expected side. WAA keeps expected files on the
//! host (the evaluator downloads `cloud_file` gold when it scores), so an agent
//! never sees them; a task that writes its gold into the guest lets the agent
//! read the answer, or overwrite it. `arena validate` warns about each case.

use crate::{GetterSpec, Scoring, SetupStep, Task};

/// One way `task`'s setup hands the agent its expected side, in words naming
/// the step, the path or URL and the getter. Empty when there is none.
pub fn exposed_answers(task: &Task) -> Vec<String> {
    let Scoring::Metrics { calls, .. } = &task.evaluator.scoring else { return Vec::new() };
    let expected: Vec<&GetterSpec> = calls.iter().filter_map(|call| call.expected.as_ref()).collect();
    let mut found = Vec::new();
    let steps =
        task.config.iter().map(|s| ("config", s)).chain(task.evaluator.postconfig.iter().map(|s| ("postconfig", s)));
    for (n, (list, step)) in steps.enumerate() {
        let place = format!("{list} step {} ({})", n + 1, step.kind());
        for written in guest_paths(step) {
            for getter in expected.iter().filter(|g| g.kind == "vm_file") {
                if getter_strings(getter, "path").iter().any(|p| same_guest_path(p, &written)) {
                    found.push(format!(
                        "{place} writes {written} into the guest, which the evaluator reads as the expected side (vm_file): the agent can read or change the answer"
                    ));
                }
            }
        }
        if let SetupStep::Download { files } = step {
            for file in files {
                for getter in expected.iter().filter(|g| g.kind == "cloud_file") {
                    if getter_strings(getter, "path").contains(&file.url) {
                        found.push(format!(
                            "{place} downloads {} into the guest as {}, the file the evaluator fetches as the expected side (cloud_file): the agent can read the answer",
                            file.url, file.path
                        ));
                    }
                }
            }
        }
    }
    found
}

/// The guest paths a setup step writes.
fn guest_paths(step: &SetupStep) -> Vec<String> {
    match step {
        SetupStep::CreateFile { path, .. } => vec![path.clone()],
        SetupStep::Download { files } => files.iter().map(|f| f.path.clone()).collect(),
        SetupStep::UploadFile { files } => files.iter().map(|(_, guest)| guest.clone()).collect(),
        _ => Vec::new(),
    }
}

/// A getter parameter that is a string or a list of strings (`multi`).
fn getter_strings(getter: &GetterSpec, key: &str) -> Vec<String> {
    match getter.params.get(key) {
        Some(serde_json::Value::String(s)) => vec![s.clone()],
        Some(serde_json::Value::Array(items)) => items.iter().filter_map(|v| v.as_str().map(str::to_owned)).collect(),
        _ => Vec::new(),
    }
}

/// Windows paths compare without case, either slash, and a trailing separator.
fn same_guest_path(a: &str, b: &str) -> bool {
    let norm = |p: &str| p.replace('/', "\\").trim_end_matches('\\').to_lowercase();
    norm(a) == norm(b)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn task(config: &str, expected: &str) -> Task {
        let text = format!(
            r#"{{"id": "t", "instruction": "i", "config": {config},
                "evaluator": {{"func": "compare_text_file",
                  "result": {{"type": "vm_file", "path": "C:\\Users\\Docker\\out.txt", "dest": "out.txt"}},
                  "expected": {expected}}}}}"#
        );
        Task::parse(&text, Path::new("/tasks/notepad/t.json")).unwrap()
    }

    #[test]
    fn gold_written_into_the_guest_is_found_whatever_the_case_and_slashes() {
        let t = task(
            r#"[{"type": "create_file", "parameters": {"path": "c:/arena-gold/Count.txt", "content": "3"}}]"#,
            r#"{"type": "vm_file", "path": "C:\\arena-gold\\count.txt", "dest": "gold.txt"}"#,
        );
        let found = exposed_answers(&t);
        assert_eq!(found.len(), 1, "{found:?}");
        assert!(found[0].contains("config step 1 (create_file)") && found[0].contains("c:/arena-gold/Count.txt"));
    }

    #[test]
    fn a_download_of_the_expected_url_is_found_and_other_files_are_not() {
        let t = task(
            r#"[{"type": "download", "parameters": {"files": [
                 {"url": "https://example.org/input.docx", "path": "C:\\Users\\Docker\\input.docx"},
                 {"url": "https://example.org/gold.docx", "path": "C:\\Users\\Docker\\g.docx"}]}},
                {"type": "create_file", "parameters": {"path": "C:\\Users\\Docker\\out.txt", "content": ""}}]"#,
            r#"{"type": "cloud_file", "path": "https://example.org/gold.docx", "dest": "gold.docx"}"#,
        );
        let found = exposed_answers(&t);
        assert_eq!(found.len(), 1, "{found:?}");
        assert!(found[0].contains("https://example.org/gold.docx") && found[0].contains("cloud_file"), "{found:?}");
        // The result side written by setup (an empty file to fill) is not an answer.
        let t = task(
            r#"[{"type": "create_file", "parameters": {"path": "C:\\Users\\Docker\\out.txt", "content": ""}}]"#,
            r#"{"type": "host_file", "path": "gold/out.txt", "dest": "gold.txt"}"#,
        );
        assert!(exposed_answers(&t).is_empty());
    }
}
