//! `arena certify TASKS`: plays every task with the floor agents (`noop`,
//! `fail`) and, where a plan exists, the oracle (the scripted agent), K times
//! each, and writes one certificate per task and their table
//! ([`arena_results::certificate`], docs/results.md "Certificates").
//!
//! It is three `arena run`s on one set of guests: the runs' own machinery
//! (`crate::driver`'s `Prepared` and `play`, through `runs`: the pool, the episode
//! runner, `--trials`, resuming), into `OUT/noop`, `OUT/fail` and `OUT/oracle`,
//! each a result folder of its own with its summary and report. The guests'
//! identity is read once from their health route and Windows' version keys.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::Context as _;
use clap::{Args, Parser};

use super::run_args::{DifficultyArg, PausesArg, RunArgs};
use super::runs;
use super::{emit, Connection};
use crate::driver::{Guests, Prepared};
use arena_agents::factory::{self, AgentKind};
use arena_results::certificate::{self, AgentTrials, Certificate, GuestImage, FAIL, NOOP, ORACLE};
use arena_results::summary::Summary;
use arena_shared::registry::RegistryValue;

/// Arguments of `arena certify`.
#[derive(Debug, Clone, Args)]
pub struct CertifyArgs {
    /// A task folder (or a corpus root holding `examples/`), or an index file such as `test_all.json`.
    #[arg(value_name = "TASKS")]
    pub tasks: PathBuf,
    /// Which variant of the corpus an index or root resolves into.
    #[arg(long, value_enum, default_value_t = DifficultyArg::Normal)]
    pub difficulty: DifficultyArg,
    /// The oracle's plans: one plan file for every task, or a folder of `<task name>.json`
    /// plans [default: `<tasks>/plans` when it exists, else each task's `plan` key].
    /// Tasks without a plan get no oracle (their `oracle_pass_rate` is null).
    #[arg(long, value_name = "PATH")]
    pub plans: Option<PathBuf>,
    /// Trials of each task per agent.
    #[arg(long, default_value_t = 3, value_name = "K", value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub trials: u32,
    /// The certificates and the three runs' result folders (`noop/`, `fail/`, `oracle/`).
    #[arg(long, default_value = "certify", value_name = "DIR")]
    pub out: PathBuf,
    #[command(flatten)]
    pub source: super::run_args::GuestSource,
    /// Step cap per episode (upstream: 15); the floor agents use one step.
    #[arg(long, default_value_t = crate::episode::DEFAULT_MAX_STEPS)]
    pub max_steps: u32,
    /// `upstream` or `fast` pauses, as `arena run --pauses` [default: fast with --stub-guests].
    #[arg(long, value_enum)]
    pub pauses: Option<PausesArg>,
    /// Tries per task after infrastructure errors, the first included.
    #[arg(long, default_value_t = 3)]
    pub attempts: u32,
    /// Seconds a run waits, with tasks left and every guest down, before it ends.
    #[arg(long, default_value_t = 600, value_name = "SECS")]
    pub guest_wait: u64,
    /// Play every trial again, even those with a result.txt.
    #[arg(long)]
    pub no_resume: bool,
}

/// `arena run`'s arguments alone, to get its defaults.
#[derive(Parser)]
struct RunOnly {
    #[command(flatten)]
    run: RunArgs,
}

impl CertifyArgs {
    /// The `arena run` arguments of `agent`'s run into `<out>/<folder>`.
    fn run_args(&self, agent: AgentKind, folder: &str) -> anyhow::Result<RunArgs> {
        let parsed =
            RunOnly::try_parse_from([std::ffi::OsStr::new("arena-run"), "--tasks".as_ref(), self.tasks.as_os_str()])
                .context("the run's defaults")?;
        let mut run = parsed.run;
        run.agent = agent;
        run.difficulty = self.difficulty;
        run.plans = self.plans.clone();
        run.trials = self.trials;
        run.out = self.out.join(folder);
        run.source = self.source.clone();
        // The VMs' folders go beside the three runs, not into one of them.
        run.source.vm_dir = Some(self.source.vm_dir.clone().unwrap_or_else(|| self.out.join("vms")));
        run.max_steps = self.max_steps;
        run.pauses = self.pauses;
        run.attempts = self.attempts;
        run.guest_wait = self.guest_wait;
        run.no_resume = self.no_resume;
        // One download cache for the three runs.
        run.cache = Some(self.out.join("download-cache"));
        Ok(run)
    }
}

/// `arena certify`.
///
/// # Errors
///
/// Unusable arguments, tasks that do not load, no guest, a run that fails, or
/// certificates that cannot be written.
pub async fn run(conn: &Connection, args: CertifyArgs) -> anyhow::Result<ExitCode> {
    // Every run is prepared (tasks loaded, agents built) before a guest starts.
    let template = args.run_args(AgentKind::Scripted, ORACLE)?;
    let plans = factory::plan_source(&template.agent_options())?;
    let mut runs: Vec<(&str, Prepared)> = Vec::new();
    for (name, kind) in [(NOOP, AgentKind::Noop), (FAIL, AgentKind::Fail), (ORACLE, AgentKind::Scripted)] {
        let mut prepared = runs::prepare(&args.run_args(kind, name)?).await?;
        if kind == AgentKind::Scripted {
            prepared.tasks.retain(|task| plans.has_plan(task));
            if prepared.tasks.is_empty() {
                emit("certify: no task has an oracle plan; the oracle is not run\n")?;
                continue;
            }
        }
        runs.push((name, prepared));
    }
    let tasks = runs.first().map(|(_, p)| p.tasks.clone()).unwrap_or_default();
    let guests = runs::start_guests(conn, &template).await?;
    let images = guest_images(&guests, args.source.vm_image.as_ref().map(|p| p.display().to_string())).await;
    let mut summaries: BTreeMap<&str, Summary> = BTreeMap::new();
    let mut unfinished = false;
    for (name, prepared) in runs {
        let count = prepared.tasks.len();
        let played = match runs::with_ctrl_c(prepared, &guests).await {
            Ok(played) => played,
            Err(err) => {
                guests.stop().await;
                return Err(err.context(format!("certify: the {name} run")));
            }
        };
        let outcome = played.outcome;
        unfinished |= !outcome.summary.overall.complete;
        emit(&format!(
            "certify: {name}: {count} task(s) x {} trial(s): success rate {:.1}% (report: {})\n",
            args.trials,
            outcome.summary.overall.success_rate,
            outcome.report.display()
        ))?;
        if played.interrupted {
            guests.stop().await;
            emit("certify: interrupted; no certificate written (the same command resumes)\n")?;
            return Ok(ExitCode::from(130));
        }
        summaries.insert(name, outcome.summary);
    }
    guests.stop().await;

    let certificates: Vec<Certificate> = tasks
        .iter()
        .map(|task| {
            let of = |agent: &str| summaries.get(agent).map(|s| agent_trials(s, &task.domain, &task.name, args.trials));
            let oracle = plans.has_plan(task).then(|| of(ORACLE)).flatten();
            Certificate::compute(
                &task.id,
                &task.domain,
                &task.name,
                matches!(task.evaluator.scoring, arena_task::Scoring::Infeasible),
                args.trials,
                of(NOOP).unwrap_or_default(),
                of(FAIL).unwrap_or_default(),
                oracle,
                images.clone(),
            )
        })
        .collect();
    let table = certificate::write_all(&args.out, &certificates)?;
    emit(&format!("\n{}\ncertificates: {}\n", certificate::table(&certificates), table.display()))?;
    if unfinished {
        emit("some trials have no result (the environment failed); run the same command again to finish them\n")?;
        return Ok(ExitCode::from(2));
    }
    Ok(ExitCode::SUCCESS)
}

/// The trials of `domain/name` in a run's summary, those of trial folders 0..K-1.
fn agent_trials(summary: &Summary, domain: &str, name: &str, trials: u32) -> AgentTrials {
    let mut scores: Vec<Option<f64>> = summary
        .tasks
        .iter()
        .filter(|t| t.domain == domain && t.name == name)
        .filter(|t| {
            let trial = t.path.rsplit('/').nth(2).and_then(|s| s.parse::<u32>().ok());
            trial.is_some_and(|k| k < trials)
        })
        .map(|t| t.score)
        .collect();
    let have = scores.len() as u32;
    scores.extend((have..trials).map(|_| None));
    AgentTrials::of(&scores)
}

/// The distinct identities of the guests: their health report, and Windows'
/// version keys where the registry answers.
async fn guest_images(guests: &Guests, vm_image: Option<String>) -> Vec<GuestImage> {
    let vm_urls = guests.fleet.as_ref().map(|f| f.urls()).unwrap_or_default();
    let mut images = Vec::new();
    for (url, client) in guests.urls.iter().zip(&guests.clients) {
        let client = client.with_timeout(Duration::from_secs(30));
        let health = match client.health().await {
            Ok(health) => health,
            Err(err) => {
                tracing::warn!(guest = %url, error = %err, "certify: the guest's identity could not be read");
                continue;
            }
        };
        let key = r"HKLM\SOFTWARE\Microsoft\Windows NT\CurrentVersion";
        let mut parts = Vec::new();
        for value in ["ProductName", "DisplayVersion", "CurrentBuild"] {
            if let Ok(read) = client.registry_get(key, Some(value)).await {
                match read.data {
                    RegistryValue::String(text) if value == "CurrentBuild" => parts.push(format!("(build {text})")),
                    RegistryValue::String(text) => parts.push(text),
                    _ => {}
                }
            }
        }
        let image = GuestImage {
            backend: health.backend,
            version: health.version,
            api_version: health.api_version,
            os: (!parts.is_empty()).then(|| parts.join(" ")),
            vm_image: vm_urls.contains(url).then(|| vm_image.clone()).flatten(),
        };
        if !images.contains(&image) {
            images.push(image);
        }
    }
    images.sort();
    images
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        certify: CertifyArgs,
    }

    #[test]
    fn each_agents_run_gets_its_folder_and_the_certify_options() {
        let cli = Cli::try_parse_from([
            "arena",
            "tasks/stub/test_all.json",
            "--stub-guests",
            "2",
            "--out",
            "o",
            "--pauses",
            "fast",
        ])
        .unwrap();
        assert_eq!(cli.certify.trials, 3);
        let run = cli.certify.run_args(AgentKind::Noop, NOOP).unwrap();
        assert_eq!(run.agent, AgentKind::Noop);
        assert_eq!(run.out, PathBuf::from("o/noop"));
        assert_eq!((run.trials, run.source.stub_guests, run.pauses), (3, Some(2), Some(PausesArg::Fast)));
        assert_eq!(run.tasks, PathBuf::from("tasks/stub/test_all.json"));
        // `arena run`'s own defaults otherwise.
        assert_eq!(run.max_steps, crate::episode::DEFAULT_MAX_STEPS);
        assert_eq!(run.cache, Some(PathBuf::from("o/download-cache")));
        assert!(Cli::try_parse_from(["arena", "t", "--trials", "0"]).is_err());
    }

    #[test]
    fn an_agents_trials_are_read_from_its_summary_within_k_trial_folders() {
        let row = |trial: u32, score: Option<f64>| arena_results::summary::TaskRow {
            domain: "d".into(),
            name: "t".into(),
            path: format!("noop/a11y_tree/noop/{trial}/d/t"),
            score,
            success: score == Some(1.0),
            status: "completed".into(),
            error: None,
            steps: 1,
            elapsed_ms: 0,
            attempt: 1,
            guest: String::new(),
            blame: String::new(),
            failed_by: String::new(),
            tokens: None,
            cost_usd: None,
            certified_broken: false,
            action_errors: 0,
        };
        let mut summary = Summary::from_found(&[]);
        // Trial 2 unfinished, trial 3 from an earlier, longer certification.
        summary.tasks = vec![row(0, Some(1.0)), row(1, Some(0.0)), row(2, None), row(3, Some(1.0))];
        let trials = agent_trials(&summary, "d", "t", 3);
        assert_eq!((trials.scores.clone(), trials.passes, trials.unfinished), (vec![1.0, 0.0], 1, 1));
        // A task that never started in a run of 2 trials: both unfinished.
        let none = agent_trials(&summary, "d", "other", 2);
        assert_eq!((none.scores.len(), none.unfinished), (0, 2));
    }
}
