//! The task list a run was given, kept in each trial folder as `task_list.json`
//! (domain -> task names, in the shape of upstream's `test_all.json`), so that a
//! summary rebuilt from the folders alone knows the tasks that never started:
//! the denominator of the strict rate (docs/compatibility.md, "Strict rate").
//!
//! A run adds its shard's tasks to the file (a union, so resuming with another
//! shard or a longer list only grows it); `arena merge` unions the shards' files.
//! It does no guest I/O.
//!
//! Beside it, `infeasible_tasks.json` (the same shape) names the listed tasks
//! whose evaluator is upstream's `infeasible`: what an agent answering FAIL to
//! every task scores is their share of the list, the run's FAIL-always floor
//! ([`listed_kinds`]).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::{safe_component, write_json, ResultsError, EPISODE_FILE, RESULT_FILE};

/// How deep below a root task lists are looked for (a trial folder is 4 levels down).
const MAX_LIST_DEPTH: usize = 6;
use arena_task::Task;

/// The task list's file name, in a trial folder (`<action space>/<observation>/<model>/<trial>`).
pub const TASK_LIST_JSON: &str = "task_list.json";

/// The infeasible tasks of the task list, beside it in each trial folder.
pub const INFEASIBLE_JSON: &str = "infeasible_tasks.json";

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
    write_json(path, &list)
}

/// Records `tasks` in the trial folder `base`.
///
/// # Errors
///
/// The file cannot be written.
pub fn record(base: &Path, tasks: &[&Task]) -> Result<(), ResultsError> {
    let mut list = TaskList::new();
    let mut infeasible = TaskList::new();
    for task in tasks {
        list.entry(task.domain.clone()).or_default().push(task.name.clone());
        if matches!(task.evaluator.scoring, arena_task::Scoring::Infeasible) {
            infeasible.entry(task.domain.clone()).or_default().push(task.name.clone());
        }
    }
    // Written even when empty: "none is infeasible" is known, unlike a folder from before.
    add(&base.join(INFEASIBLE_JSON), &infeasible)?;
    add(&base.join(TASK_LIST_JSON), &list)
}

/// Every task listed below `root` with whether its evaluator is `infeasible`:
/// (domain, name, infeasible); `None` when a task list has no
/// `infeasible_tasks.json` beside it (a folder from before the floor was kept)
/// or there is no task list.
pub fn listed_kinds(root: &Path) -> Option<Vec<(String, String, bool)>> {
    let lists = lists_below(root);
    if lists.is_empty() {
        return None;
    }
    let mut out = Vec::new();
    for (trial, list) in lists {
        let file = root.join(&trial).join(INFEASIBLE_JSON);
        if !file.is_file() {
            return None;
        }
        let infeasible = read(&file);
        for (domain, names) in list {
            for name in names {
                let kind = infeasible.get(&domain).is_some_and(|n| n.contains(&name));
                out.push((domain.clone(), name, kind));
            }
        }
    }
    Some(out)
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
        let infeasible = from.join(&trial).join(INFEASIBLE_JSON);
        if infeasible.is_file() {
            add(&to.join(&trial).join(INFEASIBLE_JSON), &read(&infeasible))?;
        }
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

    #[test]
    fn the_kinds_of_listed_tasks_need_the_infeasible_file_beside_every_list() {
        let tmp = tempfile::tempdir().expect("tmp");
        let (a, b) = (tmp.path().join("x/o/m/0"), tmp.path().join("x/o/m/1"));
        let list: TaskList = [("settings".to_owned(), vec!["inf".to_owned(), "ok".to_owned()])].into();
        let infeasible: TaskList = [("settings".to_owned(), vec!["inf".to_owned()])].into();
        assert_eq!(listed_kinds(tmp.path()), None);
        add(&a.join(TASK_LIST_JSON), &list).unwrap();
        add(&b.join(TASK_LIST_JSON), &list).unwrap();
        add(&a.join(INFEASIBLE_JSON), &infeasible).unwrap();
        // Trial 1 is from before the floor was kept: unknown.
        assert_eq!(listed_kinds(tmp.path()), None);
        add(&b.join(INFEASIBLE_JSON), &TaskList::new()).unwrap();
        let kinds = listed_kinds(tmp.path()).expect("known");
        let flags: Vec<bool> = kinds.iter().map(|k| k.2).collect();
        assert_eq!(flags, [true, false, false, false]);
        // A merge carries the infeasible files with the lists.
        let merged = tempfile::tempdir().expect("tmp");
        merge_into(merged.path(), tmp.path()).unwrap();
        assert_eq!(listed_kinds(merged.path()), Some(kinds));
    }
}
