//! The task list a run was given, kept in each trial folder as `task_list.json`
//! (domain -> task names, in the shape of upstream's `test_all.json`), so that a
//! summary rebuilt from the folders alone knows the tasks that never started:
//! the denominator of the strict rate (docs/compatibility.md, "Strict rate").
//!
//! A run adds its shard's tasks to the file (a union, so resuming with another
//! shard or a longer list only grows it); `arena merge` unions the shards' files.
//! It does no guest I/O.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::{safe_component, write_atomic, ResultsError, EPISODE_FILE, RESULT_FILE};

/// How deep below a root task lists are looked for (a trial folder is 4 levels down).
const MAX_LIST_DEPTH: usize = 6;
use arena_task::Task;

/// The task list's file name, in a trial folder (`<action space>/<observation>/<model>/<trial>`).
pub const TASK_LIST_JSON: &str = "task_list.json";

/// Domain -> task names.
pub type TaskList = BTreeMap<String, Vec<String>>;

/// Reads a task list file; a missing or unreadable one is empty (a folder from
/// before task lists were kept), with a warning for one that does not parse.
pub fn read(path: &Path) -> TaskList {
    let Ok(text) = std::fs::read_to_string(path) else {
        return TaskList::new();
    };
    serde_json::from_str(&text).unwrap_or_else(|err| {
        tracing::warn!(path = %path.display(), %err, "a task list that does not parse is ignored");
        TaskList::new()
    })
}

/// Adds `more` to the task list at `path` (created when absent), each name once.
///
/// # Errors
///
/// The file cannot be written.
pub fn add(path: &Path, more: &TaskList) -> Result<(), ResultsError> {
    let mut list = read(path);
    for (domain, names) in more {
        let entry = list.entry(domain.clone()).or_default();
        for name in names {
            if !entry.contains(name) {
                entry.push(name.clone());
            }
        }
    }
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|err| ResultsError::io(dir, err))?;
    }
    let text = serde_json::to_string_pretty(&list)
        .map_err(|err| ResultsError::Format { path: path.to_owned(), message: err.to_string() })?;
    write_atomic(path, text.as_bytes())
}

/// Records `tasks` in the trial folder `base`.
///
/// # Errors
///
/// The file cannot be written.
pub fn record(base: &Path, tasks: &[&Task]) -> Result<(), ResultsError> {
    let mut list = TaskList::new();
    for task in tasks {
        list.entry(task.domain.clone()).or_default().push(task.name.clone());
    }
    add(&base.join(TASK_LIST_JSON), &list)
}

/// Every task list below `root`, as (its folder relative to `root`, the list).
pub fn lists_below(root: &Path) -> Vec<(PathBuf, TaskList)> {
    fn walk(root: &Path, dir: &Path, depth: usize, out: &mut Vec<(PathBuf, TaskList)>) {
        let file = dir.join(TASK_LIST_JSON);
        if file.is_file() {
            let relative = dir.strip_prefix(root).map(Path::to_path_buf).unwrap_or_default();
            out.push((relative, read(&file)));
        }
        // Task folders hold no task lists, and their own folders are many.
        if depth >= MAX_LIST_DEPTH || dir.join(RESULT_FILE).is_file() || dir.join(EPISODE_FILE).is_file() {
            return;
        }
        let Ok(entries) = std::fs::read_dir(dir) else { return };
        for entry in entries.flatten() {
            // Symbolic links are not followed, as in `scan`.
            if entry.file_type().is_ok_and(|t| t.is_dir()) {
                walk(root, &entry.path(), depth + 1, out);
            }
        }
    }
    let mut out = Vec::new();
    walk(root, root, 0, &mut out);
    out.sort_by(|a, b| a.0.cmp(&b.0));
    out
}

/// Every task listed below `root`: (domain, name, its folder relative to `root`).
pub fn listed_tasks(root: &Path) -> Vec<(String, String, PathBuf)> {
    let mut out = Vec::new();
    for (trial, list) in lists_below(root) {
        for (domain, names) in list {
            for name in names {
                let path = trial.join(safe_component(&domain)).join(safe_component(&name));
                out.push((domain.clone(), name, path));
            }
        }
    }
    out
}

/// Unions the task lists below `from` into the same folders below `to` (`arena merge`).
///
/// # Errors
///
/// A file cannot be written.
pub fn merge_into(to: &Path, from: &Path) -> Result<(), ResultsError> {
    for (trial, list) in lists_below(from) {
        add(&to.join(trial).join(TASK_LIST_JSON), &list)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_list_grows_by_union_and_is_found_below_the_root() {
        let tmp = tempfile::tempdir().expect("tmp");
        let base = tmp.path().join("a/o/m/0");
        let file = base.join(TASK_LIST_JSON);
        add(&file, &[("notepad".to_owned(), vec!["b".to_owned(), "a".to_owned()])].into()).unwrap();
        add(&file, &[("notepad".to_owned(), vec!["a".to_owned(), "c".to_owned()])].into()).unwrap();
        assert_eq!(read(&file)["notepad"], ["b", "a", "c"]);
        let listed = listed_tasks(tmp.path());
        assert_eq!(listed.len(), 3);
        assert_eq!(listed[0], ("notepad".into(), "b".into(), PathBuf::from("a/o/m/0/notepad/b")));
        let merged = tempfile::tempdir().expect("tmp");
        merge_into(merged.path(), tmp.path()).unwrap();
        assert_eq!(read(&merged.path().join("a/o/m/0").join(TASK_LIST_JSON)), read(&file));
        std::fs::write(&file, "not json").unwrap();
        assert!(read(&file).is_empty());
    }
}
