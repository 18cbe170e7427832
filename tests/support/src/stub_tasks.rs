//! The project's own stub tasks (`tasks/stub`), and copies of some of them for
//! tests that run a chosen few: a task travels with its domain's `gold/`
//! folder, which its evaluator reads on the host (`host_file`).

use std::path::{Path, PathBuf};

/// `tasks/stub` of this workspace.
pub fn stub_tasks_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tasks/stub")
}

/// Copies the stub task `domain/name` into the folder `to` (created), as
/// `to/<name>.json`, with its domain's gold files in `to/gold/`.
///
/// # Panics
///
/// When the task does not exist or a copy fails (a broken test set-up).
pub fn copy_stub_task(domain: &str, name: &str, to: &Path) {
    let from = stub_tasks_dir().join("examples").join(domain);
    std::fs::create_dir_all(to).unwrap_or_else(|err| panic!("{}: {err}", to.display()));
    let json = from.join(format!("{name}.json"));
    std::fs::copy(&json, to.join(format!("{name}.json"))).unwrap_or_else(|err| panic!("{}: {err}", json.display()));
    let gold = from.join("gold");
    if gold.is_dir() {
        std::fs::create_dir_all(to.join("gold")).unwrap_or_else(|err| panic!("{}: {err}", to.display()));
        for entry in std::fs::read_dir(&gold).unwrap_or_else(|err| panic!("{}: {err}", gold.display())).flatten() {
            std::fs::copy(entry.path(), to.join("gold").join(entry.file_name()))
                .unwrap_or_else(|err| panic!("{}: {err}", entry.path().display()));
        }
    }
}
