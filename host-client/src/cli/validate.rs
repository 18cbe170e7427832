//! `arena validate`: load a task folder (or the tasks a test index names) and
//! report, per task, what it needs (setup steps, getters, metrics, apps) and
//! whether this build implements all of it, then totals.
//!
//! It talks to no guest and downloads nothing. A file that does not load is
//! an error (exit code 1) naming the file and the problem; a getter or metric
//! this build lacks is reported, and is an error only with `--strict`. A task
//! whose setup puts its own expected side into the guest is warned about
//! (`arena_task::gold`): the agent could read the answer.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::Args;
use serde::Serialize;

use super::run_args::DifficultyArg;
use arena_eval::{getter_supported, metric_supported};
use arena_task::{load_dir, names, read_index, Difficulty, Task, TaskError};

/// Arguments of `arena validate`.
#[derive(Debug, Clone, Args)]
pub struct ValidateArgs {
    /// A folder of task files (searched recursively); with --index the corpus root
    /// holding `examples/` and `examples_noctxt/`; or, as `arena run` takes it, an
    /// index file (`test_all.json`) whose folder is the corpus root.
    pub folder: PathBuf,
    /// A test index (`test_all.json`): validate only the tasks it names. A
    /// relative path is looked up under FOLDER when it is not found as given.
    #[arg(long, value_name = "FILE")]
    pub index: Option<PathBuf>,
    /// Which variant of the tasks an index resolves to.
    #[arg(long, value_enum, default_value_t = DifficultyArg::Normal, requires = "index")]
    pub difficulty: DifficultyArg,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
    /// Also fail (exit 1) when a task needs a getter or metric this build lacks.
    #[arg(long)]
    pub strict: bool,
}

/// One task's needs and support.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TaskReport {
    pub domain: String,
    pub name: String,
    pub path: PathBuf,
    pub steps: Vec<String>,
    pub getters: Vec<String>,
    pub metrics: Vec<String>,
    pub apps: Vec<String>,
    /// Steps, getters and metrics this build does not implement.
    pub unsupported: Vec<String>,
    /// What is wrong with the task though it runs: setup steps that hand the
    /// agent the expected side ([`arena_task::gold::exposed_answers`]).
    pub warnings: Vec<String>,
}

impl TaskReport {
    fn of(task: &Task) -> TaskReport {
        let needs = task.needs();
        let unsupported = needs
            .steps
            .iter()
            .filter(|s| !names::SETUP_STEPS.contains(&s.as_str()))
            .chain(needs.getters.iter().filter(|g| !getter_supported(g)))
            .chain(needs.metrics.iter().filter(|m| !metric_supported(m)))
            .cloned()
            .collect();
        TaskReport {
            domain: task.domain.clone(),
            name: task.name.clone(),
            path: task.path.clone(),
            steps: needs.steps,
            getters: needs.getters,
            metrics: needs.metrics,
            apps: needs.apps,
            unsupported,
            warnings: arena_task::gold::exposed_answers(task),
        }
    }

    pub fn supported(&self) -> bool {
        self.unsupported.is_empty()
    }
}

/// Counts over the whole folder.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Totals {
    pub files: usize,
    pub loaded: usize,
    pub failed: usize,
    /// Tasks whose every step, getter and metric this build implements.
    pub supported: usize,
    pub steps_used: usize,
    pub getters_used: usize,
    pub getters_implemented: usize,
    pub metrics_used: usize,
    pub metrics_implemented: usize,
    /// Each unimplemented name with the number of tasks that need it.
    pub missing: BTreeMap<String, usize>,
    /// Tasks with at least one warning.
    pub warned: usize,
}

/// The whole report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Report {
    pub tasks: Vec<TaskReport>,
    /// Files that did not load, each naming the file and the problem.
    pub errors: Vec<String>,
    pub totals: Totals,
}

impl Report {
    /// Builds the report from loaded tasks and load errors.
    pub fn new(tasks: &[Task], errors: &[TaskError]) -> Report {
        let tasks: Vec<TaskReport> = tasks.iter().map(TaskReport::of).collect();
        let mut totals = Totals {
            files: tasks.len() + errors.len(),
            loaded: tasks.len(),
            failed: errors.len(),
            ..Totals::default()
        };
        let (mut steps, mut getters, mut metrics) = (BTreeMap::new(), BTreeMap::new(), BTreeMap::new());
        for task in &tasks {
            totals.supported += usize::from(task.supported());
            totals.warned += usize::from(!task.warnings.is_empty());
            for name in &task.unsupported {
                *totals.missing.entry(name.clone()).or_insert(0) += 1;
            }
            steps.extend(task.steps.iter().map(|s| (s.clone(), ())));
            getters.extend(task.getters.iter().map(|g| (g.clone(), ())));
            metrics.extend(task.metrics.iter().map(|m| (m.clone(), ())));
        }
        totals.steps_used = steps.len();
        totals.getters_used = getters.len();
        totals.getters_implemented = getters.keys().filter(|g| getter_supported(g)).count();
        totals.metrics_used = metrics.len();
        totals.metrics_implemented = metrics.keys().filter(|m| metric_supported(m)).count();
        Report { tasks, errors: errors.iter().map(ToString::to_string).collect(), totals }
    }

    /// Whether `validate` succeeds: every file loaded (and, when strict, every task is supported).
    pub fn passes(&self, strict: bool) -> bool {
        self.totals.loaded > 0 && self.errors.is_empty() && (!strict || self.totals.supported == self.totals.loaded)
    }

    /// The human-readable report: a table of tasks, the load errors, then totals.
    pub fn render(&self) -> String {
        let rows: Vec<Vec<String>> = self
            .tasks
            .iter()
            .map(|t| {
                vec![
                    format!("{}/{}", t.domain, t.name),
                    t.steps.join(","),
                    t.getters.join(","),
                    t.metrics.join(","),
                    t.apps.join(","),
                    if t.supported() { "yes".into() } else { format!("no: {}", t.unsupported.join(",")) },
                ]
            })
            .collect();
        let mut out = super::render::table(&["TASK", "STEPS", "GETTERS", "METRICS", "APPS", "SUPPORTED"], &rows);
        for error in &self.errors {
            out.push_str(&format!("error: {error}\n"));
        }
        for task in &self.tasks {
            for warning in &task.warnings {
                out.push_str(&format!("warning: {}/{}: {warning}\n", task.domain, task.name));
            }
        }
        let t = &self.totals;
        out.push_str(&format!(
            "\n{} files: {} loaded, {} failed; {} of {} tasks fully supported\n",
            t.files, t.loaded, t.failed, t.supported, t.loaded
        ));
        out.push_str(&format!(
            "steps used: {}; getters: {} of {} implemented; metrics: {} of {} implemented\n",
            t.steps_used, t.getters_implemented, t.getters_used, t.metrics_implemented, t.metrics_used
        ));
        if t.warned > 0 {
            out.push_str(&format!("{} task(s) hand the agent their expected side (warnings above)\n", t.warned));
        }
        if !t.missing.is_empty() {
            let list: Vec<String> = t.missing.iter().map(|(name, n)| format!("{name} ({n})")).collect();
            out.push_str(&format!("not implemented (tasks needing it): {}\n", list.join(", ")));
        }
        out
    }
}

/// Loads what the arguments name: every task file below the folder, or the
/// tasks of an index. Load errors are collected, not fatal.
///
/// # Errors
///
/// An index that cannot be read or is malformed, or a folder that does not exist.
pub fn load(args: &ValidateArgs) -> anyhow::Result<(Vec<Task>, Vec<TaskError>)> {
    if args.folder.is_file() && args.index.is_none() {
        // An index file given where `arena run` takes it: its folder is the root.
        let root = args.folder.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
        let by_file = ValidateArgs { folder: root.to_owned(), index: Some(args.folder.clone()), ..args.clone() };
        return load(&by_file);
    }
    if !args.folder.is_dir() {
        anyhow::bail!("{} is neither a folder nor an index file", args.folder.display());
    }
    let Some(index) = &args.index else {
        return Ok(load_dir(&args.folder));
    };
    let index = resolve_index(&args.folder, index);
    let entries = read_index(&index)?;
    let (mut tasks, mut errors) = (Vec::new(), Vec::new());
    for (domain, ids) in entries {
        for id in ids {
            let path =
                args.folder.join(Difficulty::from(args.difficulty).folder()).join(&domain).join(format!("{id}.json"));
            match Task::load(&path) {
                Ok(task) => tasks.push(task),
                Err(err) => errors.push(err),
            }
        }
    }
    Ok((tasks, errors))
}

fn resolve_index(folder: &Path, index: &Path) -> PathBuf {
    if index.is_relative() && !index.exists() && folder.join(index).exists() {
        folder.join(index)
    } else {
        index.to_owned()
    }
}

/// Runs `arena validate`.
///
/// # Errors
///
/// See [`load`]; and a failure writing to stdout.
pub fn run(args: &ValidateArgs) -> anyhow::Result<ExitCode> {
    let (tasks, errors) = load(args)?;
    let report = Report::new(&tasks, &errors);
    if args.json {
        super::emit_json(&report)?;
    } else {
        super::emit(&report.render())?;
    }
    if report.totals.loaded == 0 && errors.is_empty() {
        tracing::error!(folder = %args.folder.display(), "no task files found");
    }
    Ok(if report.passes(args.strict) { ExitCode::SUCCESS } else { ExitCode::FAILURE })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The upstream corpus, or `None` after a loud, counted skip.
    fn corpus(test: &str) -> Option<PathBuf> {
        arena_test_support::waa_corpus(test)
    }

    fn args(folder: &Path) -> ValidateArgs {
        ValidateArgs {
            folder: folder.to_owned(),
            index: None,
            difficulty: DifficultyArg::Normal,
            json: false,
            strict: false,
        }
    }

    #[test]
    fn the_corpus_loads_and_unsupported_names_are_reported_not_errors() {
        let Some(root) = corpus("validate::the_corpus_loads_and_unsupported_names_are_reported_not_errors") else {
            return;
        };
        let (tasks, errors) = load(&args(&root)).unwrap();
        let report = Report::new(&tasks, &errors);
        assert!(report.errors.is_empty(), "{:?}", report.errors);
        assert!(report.totals.loaded > 100);
        assert!(report.passes(false));
        assert_eq!(report.totals.metrics_used, 45);
        // Every step the corpus uses is supported; some getters and metrics are not yet.
        assert!(report.tasks.iter().all(|t| t.unsupported.iter().all(|n| !names::SETUP_STEPS.contains(&n.as_str()))));
        let missing_tasks = report.tasks.iter().filter(|t| !t.supported()).count();
        assert_eq!(report.passes(true), missing_tasks == 0);
        let text = report.render();
        assert!(text.starts_with("TASK"), "{text}");
        assert!(
            text.contains(&format!("{} of {} tasks fully supported", report.totals.supported, report.totals.loaded)),
            "{text}"
        );
        let json = serde_json::to_value(&report).unwrap();
        assert_eq!(json["totals"]["loaded"], report.totals.loaded);
    }

    #[test]
    fn an_index_selects_tasks_of_one_difficulty() {
        let Some(root) = corpus("validate::an_index_selects_tasks_of_one_difficulty") else { return };
        for difficulty in [DifficultyArg::Normal, DifficultyArg::Hard] {
            let a = ValidateArgs { index: Some("test_small.json".into()), difficulty, ..args(&root) };
            let (tasks, errors) = load(&a).unwrap();
            assert!(errors.is_empty(), "{errors:?}");
            let expected: usize =
                read_index(&root.join("test_small.json")).unwrap().iter().map(|(_, ids)| ids.len()).sum();
            assert_eq!(tasks.len(), expected);
            assert!(
                tasks
                    .iter()
                    .all(|t| t.path.components().any(|c| c.as_os_str() == Difficulty::from(difficulty).folder())),
                "{difficulty:?}"
            );
        }
        let missing = ValidateArgs { index: Some("absent_index.json".into()), ..args(&root) };
        assert!(load(&missing).is_err());
        // The index file alone, as `arena run` takes it, selects the same tasks.
        let by_folder = load(&ValidateArgs { index: Some("test_small.json".into()), ..args(&root) }).unwrap().0;
        let by_file = load(&args(&root.join("test_small.json"))).unwrap().0;
        let paths = |tasks: &[Task]| tasks.iter().map(|t| t.path.clone()).collect::<Vec<_>>();
        assert_eq!(paths(&by_file), paths(&by_folder));
        assert!(!by_file.is_empty());
    }

    #[test]
    fn a_broken_task_names_the_file_and_the_name() {
        let dir = tempfile::tempdir().unwrap();
        let domain = dir.path().join("notepad");
        std::fs::create_dir_all(&domain).unwrap();
        let good = r#"{"id": "good", "instruction": "i", "config": [{"type": "sleep", "parameters": {"seconds": 1}}],
            "related_apps": ["notepad"],
            "evaluator": {"func": "compare_table", "result": {"type": "vm_screen_size", "dest": "a.xlsx"},
                          "expected": {"type": "cloud_file", "path": "http://x/a.xlsx", "dest": "b.xlsx"}}}"#;
        std::fs::write(domain.join("good.json"), good).unwrap();
        let bad = r#"{"id": "bad", "instruction": "i", "evaluator": {"func": "exact_match", "result": {"type": "vm_fiel", "path": "a"}}}"#;
        std::fs::write(domain.join("bad.json"), bad).unwrap();

        let (tasks, errors) = load(&args(dir.path())).unwrap();
        let report = Report::new(&tasks, &errors);
        assert_eq!((report.totals.loaded, report.totals.failed), (1, 1));
        assert!(!report.passes(false));
        let error = &report.errors[0];
        assert!(error.contains("bad.json") && error.contains("vm_fiel"), "{error}");
        let task = &report.tasks[0];
        assert_eq!(task.steps, ["sleep"]);
        assert_eq!(task.getters, ["vm_screen_size", "cloud_file"]);
        assert_eq!(task.apps, ["notepad"]);
        assert_eq!(task.unsupported, ["vm_screen_size"]);
        assert_eq!(report.totals.missing.get("vm_screen_size"), Some(&1));
        let text = report.render();
        assert!(text.contains("no: vm_screen_size") && text.contains("error: ") && text.contains("bad.json"), "{text}");

        // Without the broken file it passes, except under --strict.
        std::fs::remove_file(domain.join("bad.json")).unwrap();
        let (tasks, errors) = load(&args(dir.path())).unwrap();
        let report = Report::new(&tasks, &errors);
        assert!(report.passes(false));
        assert!(!report.passes(true));
    }

    #[test]
    fn an_empty_or_missing_folder_fails() {
        let dir = tempfile::tempdir().unwrap();
        let (tasks, errors) = load(&args(dir.path())).unwrap();
        assert!(!Report::new(&tasks, &errors).passes(false));
        assert!(load(&args(&dir.path().join("absent"))).is_err());
    }

    #[test]
    fn the_command_line_parses() {
        use clap::Parser;
        let cli = crate::cli::Cli::try_parse_from([
            "arena",
            "validate",
            "tasks",
            "--index",
            "test_all.json",
            "--difficulty",
            "hard",
            "--json",
        ])
        .unwrap();
        let crate::cli::Command::Validate(a) = cli.command else { panic!("not validate") };
        assert_eq!(
            (a.folder, a.index, a.difficulty, a.json, a.strict),
            ("tasks".into(), Some("test_all.json".into()), DifficultyArg::Hard, true, false)
        );
        assert!(crate::cli::Cli::try_parse_from(["arena", "validate", "tasks", "--difficulty", "hard"]).is_err());
    }
}
