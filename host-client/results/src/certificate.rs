//! Task certificates (`arena certify`): what the floor agents and the oracle
//! scored on each task over repeated trials, whether the task is broken, and
//! the guest image it was measured on; and the record a run or report keeps of
//! the tasks certificates call broken (`--certificates DIR`,
//! `certified_broken.json` at the root of a result folder).
//!
//! The format is documented in docs/results.md ("Certificates"). This module
//! computes certificates from scores already read back from result folders,
//! writes and reads them; it runs nothing and does no guest I/O (the command
//! is the host's `cli::certify`).

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::{safe_component, write_atomic, write_json, ResultsError};

/// The version of the certificate format this build writes and reads.
pub const CERTIFICATE_VERSION: u32 = 1;
/// The folder of per-task certificates in `arena certify --out`.
pub const CERTIFICATES_DIR: &str = "certificates";
/// The table of every certificate, beside [`CERTIFICATES_DIR`].
pub const CERTIFICATES_MD: &str = "certificates.md";
/// Every certificate in one file, beside [`CERTIFICATES_DIR`].
pub const CERTIFICATES_JSON: &str = "certificates.json";
/// A result folder's record of the tasks certified broken (`--certificates`).
pub const CERTIFIED_BROKEN_JSON: &str = "certified_broken.json";

/// One agent's finished trials of one task.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct AgentTrials {
    /// The score of each finished trial, in trial order.
    pub scores: Vec<f64>,
    /// Trials that scored 1.
    pub passes: u32,
    /// Trials asked for that have no result (unfinished: the environment failed).
    #[serde(default)]
    pub unfinished: u32,
}

impl AgentTrials {
    /// The trials of scores `scores` (`None`: unfinished).
    pub fn of(scores: &[Option<f64>]) -> AgentTrials {
        let finished: Vec<f64> = scores.iter().flatten().copied().collect();
        let passes = finished.iter().filter(|s| passed(**s)).count() as u32;
        AgentTrials { passes, unfinished: (scores.len() - finished.len()) as u32, scores: finished }
    }

    fn finished(&self) -> u32 {
        self.scores.len() as u32
    }

    /// Trials on the minority side of this agent's own pass/fail outcomes
    /// (a tie counts half the trials).
    fn disagreeing(&self) -> u32 {
        self.passes.min(self.finished() - self.passes)
    }
}

/// A trial passes when it scores 1, as in the summary.
fn passed(score: f64) -> bool {
    score >= 1.0 - 1e-9
}

/// What the guest says it is, from its health route and Windows' version keys.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Default, Serialize, Deserialize)]
pub struct GuestImage {
    /// `stub` or `windows`.
    pub backend: String,
    /// The guest server's version.
    pub version: String,
    /// Its API version.
    pub api_version: String,
    /// The operating system (`ProductName DisplayVersion (build N)`), when the registry answers.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub os: Option<String>,
    /// The golden image the run's VMs started from (`--vm-image`), when it started them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vm_image: Option<String>,
}

/// One task's certificate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Certificate {
    pub certificate_version: u32,
    /// The task file's `id`.
    pub task_id: String,
    /// The task's name (its file stem), which result folders use.
    pub task: String,
    pub domain: String,
    /// Whether the evaluator is upstream's `infeasible` (FAIL is the right answer).
    pub infeasible: bool,
    /// Trials asked of each agent.
    pub trials: u32,
    /// The noop agent (DONE at once) scored 1 in some trial.
    pub passes_without_acting: bool,
    /// The fail agent's mean score over its finished trials (`null` without one).
    pub infeasible_floor: Option<f64>,
    /// The oracle's passed share of its finished trials (`null` without a plan or a finished trial).
    pub oracle_pass_rate: Option<f64>,
    /// Over the three agents' finished trials: the share on the minority side of
    /// their own agent's outcomes on this task (`null` without a finished trial).
    pub flake_rate: Option<f64>,
    /// Noop passed it, or the oracle failed it, in some trial.
    pub certified_broken: bool,
    /// Why it is broken, in words (empty when it is not).
    pub broken_because: Vec<String>,
    /// Each agent's trials, by agent (`noop`, `fail`, `oracle`).
    pub agents: BTreeMap<String, AgentTrials>,
    /// The distinct guest images the trials ran on.
    pub guest_images: Vec<GuestImage>,
}

/// The agents of a certificate, by the name its `agents` map uses.
pub const NOOP: &str = "noop";
/// See [`NOOP`].
pub const FAIL: &str = "fail";
/// See [`NOOP`].
pub const ORACLE: &str = "oracle";

impl Certificate {
    /// The certificate of a task from its agents' trials (`oracle` is `None` without a plan).
    #[allow(clippy::too_many_arguments)]
    pub fn compute(
        task_id: &str,
        domain: &str,
        task: &str,
        infeasible: bool,
        trials: u32,
        noop: AgentTrials,
        fail: AgentTrials,
        oracle: Option<AgentTrials>,
        guest_images: Vec<GuestImage>,
    ) -> Certificate {
        let mean =
            |t: &AgentTrials| (!t.scores.is_empty()).then(|| t.scores.iter().sum::<f64>() / t.scores.len() as f64);
        let passes_without_acting = noop.passes > 0;
        let oracle_pass_rate =
            oracle.as_ref().filter(|o| o.finished() > 0).map(|o| f64::from(o.passes) / f64::from(o.finished()));
        let all: Vec<&AgentTrials> = [Some(&noop), Some(&fail), oracle.as_ref()].into_iter().flatten().collect();
        let finished: u32 = all.iter().map(|t| t.finished()).sum();
        let disagreeing: u32 = all.iter().map(|t| t.disagreeing()).sum();
        let flake_rate = (finished > 0).then(|| f64::from(disagreeing) / f64::from(finished));
        let mut broken_because = Vec::new();
        if passes_without_acting {
            broken_because.push(format!(
                "passes without acting: noop scored 1 in {} of {} trials",
                noop.passes,
                noop.finished()
            ));
        }
        if let Some(o) = oracle.as_ref().filter(|o| o.passes < o.finished()) {
            broken_because.push(format!("the oracle failed {} of {} trials", o.finished() - o.passes, o.finished()));
        }
        let mut agents = BTreeMap::new();
        let infeasible_floor = mean(&fail);
        agents.insert(NOOP.to_owned(), noop);
        agents.insert(FAIL.to_owned(), fail);
        if let Some(o) = oracle {
            agents.insert(ORACLE.to_owned(), o);
        }
        Certificate {
            certificate_version: CERTIFICATE_VERSION,
            task_id: task_id.to_owned(),
            task: task.to_owned(),
            domain: domain.to_owned(),
            infeasible,
            trials,
            passes_without_acting,
            infeasible_floor,
            oracle_pass_rate,
            flake_rate,
            certified_broken: !broken_because.is_empty(),
            broken_because,
            agents,
            guest_images,
        }
    }

    /// Its file below a certificates folder: `<domain>/<task>.json`.
    pub fn relative_path(&self) -> PathBuf {
        PathBuf::from(safe_component(&self.domain)).join(format!("{}.json", safe_component(&self.task)))
    }
}

/// Writes each certificate into `<out>/certificates/<domain>/<task>.json`, all
/// of them into `<out>/certificates.json`, and the table into `<out>/certificates.md`.
///
/// # Errors
///
/// A file cannot be written.
pub fn write_all(out: &Path, certificates: &[Certificate]) -> Result<PathBuf, ResultsError> {
    for cert in certificates {
        let path = out.join(CERTIFICATES_DIR).join(cert.relative_path());
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir).map_err(|err| ResultsError::io(dir, err))?;
        }
        write_json(&path, cert)?;
    }
    write_json(&out.join(CERTIFICATES_JSON), &certificates)?;
    let md = out.join(CERTIFICATES_MD);
    write_atomic(&md, table(certificates).as_bytes())?;
    Ok(md)
}

/// A share as a percentage cell, `-` for none.
fn percent(value: Option<f64>) -> String {
    value.map_or("-".to_owned(), |v| format!("{:.0}%", 100.0 * v))
}

/// The certificates as a Markdown table, broken tasks said in words.
pub fn table(certificates: &[Certificate]) -> String {
    let mut md = String::from("# Task certificates\n\n");
    let trials = certificates.iter().map(|c| c.trials).max().unwrap_or(0);
    let _ = writeln!(
        md,
        "Each task played {trials} time(s) by `noop` (DONE at once), `fail` (FAIL at once) and, where a plan exists, the oracle (the scripted agent). \
         A task is certified broken when noop passes it or the oracle fails it in any trial.\n"
    );
    md.push_str("| Domain | Task | Infeasible | Passes without acting | Infeasible floor | Oracle pass rate | Flake rate | Verdict |\n");
    md.push_str("|---|---|---|---|---:|---:|---:|---|\n");
    for c in certificates {
        let verdict = if c.certified_broken {
            format!("**certified broken**: {}", c.broken_because.join("; "))
        } else if c.oracle_pass_rate.is_none() {
            "not broken by noop; no oracle plan".to_owned()
        } else {
            "ok".to_owned()
        };
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {} | {} | {} | {} |",
            c.domain.replace('|', "\\|"),
            c.task.replace('|', "\\|"),
            if c.infeasible { "yes" } else { "no" },
            if c.passes_without_acting { "**yes**" } else { "no" },
            percent(c.infeasible_floor),
            percent(c.oracle_pass_rate),
            percent(c.flake_rate),
            verdict
        );
    }
    let broken = certificates.iter().filter(|c| c.certified_broken).count();
    let images: std::collections::BTreeSet<&GuestImage> = certificates.iter().flat_map(|c| &c.guest_images).collect();
    let _ = writeln!(md, "\n{broken} of {} task(s) certified broken.", certificates.len());
    for image in images {
        let _ = writeln!(
            md,
            "Guest: {} backend, arena-guest {} (API {}){}{}.",
            image.backend,
            image.version,
            image.api_version,
            image.os.as_deref().map(|os| format!(", {os}")).unwrap_or_default(),
            image.vm_image.as_deref().map(|i| format!(", image {i}")).unwrap_or_default()
        );
    }
    md
}

/// Every certificate below `dir` (an `arena certify --out` folder or its
/// `certificates` folder): each `*.json` file holding one, up to 3 levels down.
///
/// # Errors
///
/// `dir` cannot be read, holds no certificate, or a file that names a
/// certificate version this build does not read.
pub fn load_dir(dir: &Path) -> Result<Vec<Certificate>, ResultsError> {
    fn walk(dir: &Path, depth: usize, out: &mut Vec<PathBuf>) -> Result<(), ResultsError> {
        let entries = std::fs::read_dir(dir).map_err(|err| ResultsError::io(dir, err))?;
        let mut entries: Vec<_> = entries.flatten().collect();
        entries.sort_by_key(std::fs::DirEntry::file_name);
        for entry in entries {
            let path = entry.path();
            let Ok(kind) = entry.file_type() else { continue };
            if kind.is_dir() && depth < 3 {
                walk(&path, depth + 1, out)?;
            } else if kind.is_file() && path.extension().is_some_and(|e| e == "json") {
                out.push(path);
            }
        }
        Ok(())
    }
    let root = if dir.join(CERTIFICATES_DIR).is_dir() { dir.join(CERTIFICATES_DIR) } else { dir.to_owned() };
    let mut files = Vec::new();
    walk(&root, 0, &mut files)?;
    let mut out: Vec<Certificate> = Vec::new();
    for path in files {
        let Ok(text) = std::fs::read_to_string(&path) else { continue };
        let Ok(value) = serde_json::from_str::<serde_json::Value>(&text) else { continue };
        let Some(version) = value.get("certificate_version") else { continue };
        if version.as_u64() != Some(u64::from(CERTIFICATE_VERSION)) {
            return Err(ResultsError::Format {
                path,
                message: format!("certificate_version {version}: this build reads version {CERTIFICATE_VERSION}"),
            });
        }
        let cert: Certificate = serde_json::from_value(value)
            .map_err(|err| ResultsError::Format { path: path.clone(), message: format!("not a certificate: {err}") })?;
        if !out.iter().any(|c| c.domain == cert.domain && c.task == cert.task) {
            out.push(cert);
        }
    }
    if out.is_empty() {
        return Err(ResultsError::Format {
            path: dir.to_owned(),
            message: "no task certificate found (write some with `arena certify TASKS --out DIR`)".into(),
        });
    }
    Ok(out)
}

/// A task the certificates call broken.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct BrokenTask {
    pub domain: String,
    pub task: String,
    /// Why, from its certificate.
    pub because: Vec<String>,
}

/// What a result folder keeps of the certificates it was given (`certified_broken.json`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct CertifiedRecord {
    /// The certificates folder, as given.
    pub source: String,
    /// How many certificates it held.
    pub certificates: u32,
    /// Those that call their task broken.
    pub broken: Vec<BrokenTask>,
}

impl CertifiedRecord {
    /// The record of the certificates in `dir`.
    ///
    /// # Errors
    ///
    /// As [`load_dir`].
    pub fn from_dir(dir: &Path) -> Result<CertifiedRecord, ResultsError> {
        let certificates = load_dir(dir)?;
        let broken = certificates
            .iter()
            .filter(|c| c.certified_broken)
            .map(|c| BrokenTask { domain: c.domain.clone(), task: c.task.clone(), because: c.broken_because.clone() })
            .collect();
        Ok(CertifiedRecord { source: dir.display().to_string(), certificates: certificates.len() as u32, broken })
    }

    /// Writes `certified_broken.json` into the result folder `root`.
    ///
    /// # Errors
    ///
    /// The file cannot be written.
    pub fn write(&self, root: &Path) -> Result<(), ResultsError> {
        std::fs::create_dir_all(root).map_err(|err| ResultsError::io(root, err))?;
        write_json(&root.join(CERTIFIED_BROKEN_JSON), self)
    }

    /// Reads `certified_broken.json` from `root`; `None` when there is none or it does not parse.
    pub fn read(root: &Path) -> Option<CertifiedRecord> {
        let text = std::fs::read_to_string(root.join(CERTIFIED_BROKEN_JSON)).ok()?;
        serde_json::from_str(&text).ok()
    }

    /// Why `domain/task` is broken, when the record says it is.
    pub fn broken(&self, domain: &str, task: &str) -> Option<&BrokenTask> {
        self.broken.iter().find(|b| b.domain == domain && b.task == task)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn trials(scores: &[Option<f64>]) -> AgentTrials {
        AgentTrials::of(scores)
    }

    #[test]
    fn a_certificate_says_floor_oracle_flakes_and_why_a_task_is_broken() {
        let image =
            GuestImage { backend: "stub".into(), version: "1".into(), api_version: "1".into(), ..Default::default() };
        // A sound feasible task: noop and fail 0, the oracle always passes.
        let sound = Certificate::compute(
            "t",
            "notepad",
            "t",
            false,
            3,
            trials(&[Some(0.0); 3]),
            trials(&[Some(0.0); 3]),
            Some(trials(&[Some(1.0); 3])),
            vec![image.clone()],
        );
        assert!(!sound.certified_broken && !sound.passes_without_acting, "{sound:?}");
        assert_eq!(
            (sound.infeasible_floor, sound.oracle_pass_rate, sound.flake_rate),
            (Some(0.0), Some(1.0), Some(0.0))
        );
        // Noop passes once and the oracle fails once of three; an unfinished fail trial is left out.
        let broken = Certificate::compute(
            "b",
            "settings",
            "b",
            false,
            3,
            trials(&[Some(0.0), Some(1.0), Some(0.0)]),
            trials(&[Some(0.0), None, Some(0.5)]),
            Some(trials(&[Some(1.0), Some(0.0), Some(1.0)])),
            vec![image],
        );
        assert!(broken.certified_broken && broken.passes_without_acting);
        assert_eq!(broken.broken_because.len(), 2, "{:?}", broken.broken_because);
        assert_eq!(broken.infeasible_floor, Some(0.25));
        assert_eq!(broken.agents[FAIL].unfinished, 1);
        assert!((broken.oracle_pass_rate.unwrap() - 2.0 / 3.0).abs() < 1e-12);
        // Noop 1 of 3 off its majority, fail 0 of 2, the oracle 1 of 3: 2 of 8.
        assert_eq!(broken.flake_rate, Some(0.25));
        // Without a plan the oracle is null and cannot break the task.
        let no_plan = Certificate::compute(
            "i",
            "settings",
            "i",
            true,
            2,
            trials(&[Some(0.0); 2]),
            trials(&[Some(1.0); 2]),
            None,
            vec![],
        );
        assert_eq!((no_plan.oracle_pass_rate, no_plan.certified_broken), (None, false));
        assert!(!no_plan.agents.contains_key(ORACLE));
        let table = table(&[sound.clone(), broken.clone(), no_plan]);
        assert!(table.contains("**certified broken**: passes without acting"), "{table}");
        assert!(table.contains("1 of 3 task(s) certified broken"), "{table}");
        assert!(table.contains("Guest: stub backend"), "{table}");

        // Written and read back; a record keeps the broken one.
        let tmp = tempfile::tempdir().expect("tmp");
        write_all(tmp.path(), &[sound.clone(), broken.clone()]).unwrap();
        assert!(tmp.path().join("certificates/settings/b.json").is_file());
        let loaded = load_dir(tmp.path()).unwrap();
        assert_eq!(loaded, [sound.clone(), broken.clone()]);
        let record = CertifiedRecord::from_dir(&tmp.path().join(CERTIFICATES_DIR)).unwrap();
        assert_eq!(record.certificates, 2);
        assert_eq!(record.broken(&broken.domain, &broken.task).map(|b| b.because.len()), Some(2));
        assert!(record.broken("notepad", "t").is_none());
        // A folder without certificates, and a newer format, are errors that say so.
        let empty = tempfile::tempdir().expect("tmp");
        assert!(load_dir(empty.path()).unwrap_err().to_string().contains("no task certificate"));
        std::fs::write(tmp.path().join("certificates/newer.json"), r#"{"certificate_version": 9}"#).unwrap();
        assert!(load_dir(tmp.path()).unwrap_err().to_string().contains("certificate_version 9"));
    }
}
