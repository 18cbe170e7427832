//! `arena merge OUT SHARD_DIR...`: one result folder from the folders of several shards.
//!
//! Every task folder found under a shard (see [`arena_results::scan`]) is
//! copied to the same relative path under `OUT` (hard-linked file by file
//! when the file system allows, copied otherwise), then the summary and the
//! report are written for `OUT`. When two shards hold the same task, a
//! finished one wins over an unfinished one, and otherwise the first given
//! wins; either way the clash is reported. The shards' task lists are
//! unioned, and the first shard's record of certified-broken tasks is kept.

use std::path::{Path, PathBuf};

use arena_results::html::write_report;
use arena_results::summary::Summary;
use arena_results::{scan, ResultsError};

/// What a merge did.
#[derive(Debug)]
pub struct MergeReport {
    /// Task folders copied into the output.
    pub copied: usize,
    /// Tasks found in more than one shard, by relative path, with the folder that was kept.
    pub duplicates: Vec<(String, PathBuf)>,
    pub summary: Summary,
    pub report: PathBuf,
}

/// Merges `shards` into `out` and writes its summary and report.
///
/// # Errors
///
/// A shard cannot be read, `out` is one of the shards, or a file cannot be copied.
pub fn merge(out: &Path, shards: &[PathBuf], title: &str) -> Result<MergeReport, ResultsError> {
    std::fs::create_dir_all(out).map_err(|source| ResultsError::Io { path: out.to_owned(), reason: source })?;
    let out_real = out.canonicalize().map_err(|source| ResultsError::Io { path: out.to_owned(), reason: source })?;
    let mut copied = 0;
    let mut duplicates = Vec::new();
    // Relative path -> whether the copy in `out` is finished.
    let mut seen: std::collections::BTreeMap<PathBuf, bool> = std::collections::BTreeMap::new();
    let mut certified_carried = false;
    for shard in shards {
        let shard_real =
            shard.canonicalize().map_err(|source| ResultsError::Io { path: shard.clone(), reason: source })?;
        if shard_real == out_real || out_real.starts_with(&shard_real) {
            return Err(ResultsError::Format {
                path: shard.clone(),
                message: "the output folder must not be (or be inside) a shard folder".into(),
            });
        }
        for found in scan(shard)? {
            let finished = found.score.is_some();
            let dest = out.join(&found.relative);
            match seen.get(&found.relative) {
                Some(true) => {
                    duplicates.push((found.relative.display().to_string(), dest.clone()));
                    continue;
                }
                Some(false) if !finished => {
                    duplicates.push((found.relative.display().to_string(), dest.clone()));
                    continue;
                }
                Some(false) => {
                    duplicates.push((found.relative.display().to_string(), found.dir.path().to_owned()));
                    std::fs::remove_dir_all(&dest)
                        .map_err(|source| ResultsError::Io { path: dest.clone(), reason: source })?;
                }
                None => {
                    // A folder left by an earlier merge into the same output is replaced.
                    if dest.exists() {
                        std::fs::remove_dir_all(&dest)
                            .map_err(|source| ResultsError::Io { path: dest.clone(), reason: source })?;
                    }
                }
            }
            copy_tree(found.dir.path(), &dest)?;
            seen.insert(found.relative.clone(), finished);
            copied += 1;
        }
        arena_results::task_list::merge_into(out, shard)?;
        // The certificates a shard was given mark the merged folder too (the first shard's win).
        let record = arena_results::certificate::CertifiedRecord::read(shard);
        if let Some(record) = record.filter(|_| !certified_carried) {
            record.write(out)?;
            certified_carried = true;
        }
    }
    let (summary, report) = write_report(out, title)?;
    Ok(MergeReport { copied, duplicates, summary, report })
}

/// Copies the folder `from` to `to` (created), hard-linking files when possible.
fn copy_tree(from: &Path, to: &Path) -> Result<(), ResultsError> {
    let io = |path: &Path| {
        let path = path.to_owned();
        move |source| ResultsError::Io { path, reason: source }
    };
    std::fs::create_dir_all(to).map_err(io(to))?;
    for entry in std::fs::read_dir(from).map_err(io(from))? {
        let entry = entry.map_err(io(from))?;
        let kind = entry.file_type().map_err(io(&entry.path()))?;
        let target = to.join(entry.file_name());
        if kind.is_dir() {
            copy_tree(&entry.path(), &target)?;
        } else if kind.is_file() && std::fs::hard_link(entry.path(), &target).is_err() {
            std::fs::copy(entry.path(), &target).map_err(io(&target))?;
        }
        // Symbolic links are not followed: result folders hold none of their own.
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use arena_results::EpisodeStatus;

    fn write(root: &Path, domain: &str, name: &str, score: f64, status: EpisodeStatus) {
        arena_results::fixtures::write_task(root, domain, name, score, status);
    }

    #[test]
    fn shards_merge_into_one_summary_and_finished_copies_win() {
        let tmp = tempfile::tempdir().unwrap();
        let (a, b, out) = (tmp.path().join("a"), tmp.path().join("b"), tmp.path().join("out"));
        write(&a, "notepad", "t1", 1.0, EpisodeStatus::Completed);
        write(&a, "notepad", "t3", 0.0, EpisodeStatus::InfraError("down".into()));
        write(&b, "notepad", "t2", 0.0, EpisodeStatus::Completed);
        write(&b, "notepad", "t3", 1.0, EpisodeStatus::Completed);
        write(&b, "chrome", "t4", 1.0, EpisodeStatus::Completed);
        let merged = merge(&out, &[a.clone(), b.clone()], "merged").unwrap();
        assert_eq!(merged.copied, 5, "t3 is copied twice: the finished copy replaces the unfinished one");
        assert_eq!(merged.duplicates.len(), 1);
        assert_eq!(
            merged.summary.table(),
            vec![
                ("chrome".into(), 1, 1, 100.0),
                ("notepad".into(), 3, 2, 2.0 / 3.0 * 100.0),
                ("Overall".into(), 4, 3, 75.0)
            ]
        );
        assert!(out.join("report.html").is_file() && out.join("summary.json").is_file());
        // Merging again into the same output gives the same summary.
        let again = merge(&out, &[a.clone(), b], "merged").unwrap();
        assert_eq!(again.summary, merged.summary);
        // The output cannot be a shard.
        assert!(merge(&a, std::slice::from_ref(&a), "x").is_err());
    }
}
