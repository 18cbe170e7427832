//! `arena corpus fetch`: the upstream WAA task corpus for users who have not
//! cloned WindowsAgentArena.
//!
//! It downloads the repository's zip archive at one commit, optionally checks the
//! archive's SHA-256, and extracts the corpus folder
//! (`src/win-arena-container/client/evaluation_examples_windows/`: `examples/`,
//! `examples_noctxt/` and the `test_*.json` index files) into `--out`.
//! The archive goes to a temporary folder beside `--out` and the corpus appears
//! there by one rename at the end, so an interrupted or failed fetch (a network
//! error, a truncated or tampered archive, an archive without the corpus) leaves
//! no partial folder behind. `PROVENANCE.txt` beside the corpus records the archive's
//! URL and SHA-256. It is not a general downloader: one archive, one folder.

use std::io::Write as _;
use std::path::{Component, Path, PathBuf};

use anyhow::{bail, ensure, Context};
use clap::{Args, Subcommand};
use sha2::{Digest, Sha256};

use super::{emit, with_spinner};

/// The upstream commit the project's compatibility tests were written against.
pub const DEFAULT_COMMIT: &str = "6d39ed88c545a0d40a7a02e39b928e278df7332b";

/// The note a fetch leaves beside the corpus: where it came from.
pub const PROVENANCE: &str = "PROVENANCE.txt";

/// Where the corpus sits inside the repository.
const CORPUS_FOLDER: &str = "src/win-arena-container/client/evaluation_examples_windows";

/// Arguments of `arena corpus`.
#[derive(Debug, Clone, Args)]
pub struct CorpusArgs {
    #[command(subcommand)]
    pub command: CorpusCommand,
}

/// What to do with the corpus.
#[derive(Debug, Clone, Subcommand)]
pub enum CorpusCommand {
    /// Download the WAA task corpus (examples, examples_noctxt, index files) into a folder.
    Fetch(FetchArgs),
}

/// Arguments of `arena corpus fetch`.
#[derive(Debug, Clone, Args)]
pub struct FetchArgs {
    /// Upstream commit (or tag) to fetch.
    #[arg(long, default_value = DEFAULT_COMMIT)]
    pub commit: String,
    /// Archive URL (default: the upstream repository's zip archive of --commit); for mirrors.
    #[arg(long, value_name = "URL")]
    pub url: Option<String>,
    /// Expected SHA-256 of the archive, in hex; a mismatch writes nothing.
    #[arg(long, value_name = "HEX")]
    pub sha256: Option<String>,
    /// Folder to create (must not exist, or be empty).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
}

/// Runs `arena corpus ...`.
///
/// # Errors
///
/// See [`fetch`].
pub async fn run(args: CorpusArgs) -> anyhow::Result<std::process::ExitCode> {
    match args.command {
        CorpusCommand::Fetch(args) => {
            let counts = with_spinner("fetching the WAA task corpus", fetch(&args)).await?;
            emit(&format!(
                "corpus written to {}: {} tasks in examples, {} in examples_noctxt, {} index files\n",
                args.out.display(),
                counts.examples,
                counts.examples_noctxt,
                counts.indexes
            ))?;
            Ok(std::process::ExitCode::SUCCESS)
        }
    }
}

/// What a fetch wrote.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Written {
    /// Task files under `examples/`.
    pub examples: usize,
    /// Task files under `examples_noctxt/`.
    pub examples_noctxt: usize,
    /// `test_*.json` index files.
    pub indexes: usize,
}

/// The archive URL of `commit`.
pub fn archive_url(commit: &str) -> String {
    format!("https://github.com/microsoft/WindowsAgentArena/archive/{commit}.zip")
}

/// Downloads and extracts the corpus into `args.out`.
///
/// # Errors
///
/// `--out` exists and is not an empty folder; the download fails (connection, HTTP
/// status); the archive's SHA-256 differs from `--sha256`; the archive is not a
/// whole zip file, holds no corpus folder, or has an entry that would land outside
/// it. In every case nothing is left at `--out` and no temporary files remain.
pub async fn fetch(args: &FetchArgs) -> anyhow::Result<Written> {
    let out = &args.out;
    let expected = args.sha256.as_deref().map(parse_sha256).transpose()?;
    if args.url.is_none() {
        check_commit(&args.commit)?;
    }
    if out.exists() {
        let empty = std::fs::read_dir(out).map(|mut d| d.next().is_none()).unwrap_or(false);
        if !empty {
            bail!("{} exists and is not an empty folder; choose a new --out", out.display());
        }
    }
    let parent = match out.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    std::fs::create_dir_all(&parent).with_context(|| format!("creating {}", parent.display()))?;
    // Everything is written under this folder, removed on every way out but success.
    let work = tempfile::Builder::new()
        .prefix(".arena-corpus-")
        .tempdir_in(&parent)
        .with_context(|| format!("creating a temporary folder in {}", parent.display()))?;
    let url = args.url.clone().unwrap_or_else(|| archive_url(&args.commit));
    let archive = work.path().join("archive.zip");
    let digest = download(&url, &archive).await?;
    if let Some(expected) = expected {
        if digest != expected {
            bail!(
                "the archive from {url} has SHA-256 {}, not the expected {}; nothing was written",
                hex::encode(digest),
                hex::encode(expected)
            );
        }
    }
    let staged = work.path().join("corpus");
    let written = tokio::task::spawn_blocking({
        let (archive, staged) = (archive.clone(), staged.clone());
        move || extract(&archive, &staged)
    })
    .await
    .context("the extraction worker failed")?
    .with_context(|| format!("reading the archive from {url}"))?;
    // Which upstream this is, for whoever finds the folder later (the archive is gone by then).
    let provenance = format!(
        "Source: {url}, {CORPUS_FOLDER}/ (examples/, examples_noctxt/, test_*.json).\n\
         Archive SHA-256: {}. Fetched by `arena corpus fetch`; the task files are unchanged.\n",
        hex::encode(digest)
    );
    std::fs::write(staged.join(PROVENANCE), provenance)
        .with_context(|| format!("writing {}", staged.join(PROVENANCE).display()))?;
    if out.exists() {
        // Checked empty above; a folder cannot be renamed over on every platform.
        std::fs::remove_dir(out).with_context(|| format!("replacing the empty folder {}", out.display()))?;
    }
    std::fs::rename(&staged, out).with_context(|| format!("moving the corpus into {}", out.display()))?;
    Ok(written)
}

/// A commit or tag goes into the archive URL: nothing that would change its shape.
fn check_commit(commit: &str) -> anyhow::Result<()> {
    let plain = commit.chars().all(|c| c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '-'));
    ensure!(
        !commit.is_empty() && plain,
        "--commit {commit:?} is not a commit hash or tag (letters, digits, '.', '_' and '-' only)"
    );
    Ok(())
}

fn parse_sha256(text: &str) -> anyhow::Result<[u8; 32]> {
    let bytes = hex::decode(text.trim()).with_context(|| format!("--sha256 {text:?} is not hexadecimal"))?;
    bytes.try_into().map_err(|b: Vec<u8>| anyhow::format_err!("--sha256 has {} bytes, not 32", b.len()))
}

/// Streams `url` into `dest`, hashing as it goes.
async fn download(url: &str, dest: &Path) -> anyhow::Result<[u8; 32]> {
    let client = reqwest::Client::builder()
        .connect_timeout(std::time::Duration::from_secs(30))
        // A stalled transfer fails rather than hanging; a slow one may take as long as it needs.
        .read_timeout(std::time::Duration::from_secs(60))
        .build()
        .context("building the HTTP client")?;
    let mut response = client.get(url).send().await.with_context(|| format!("downloading {url}"))?;
    let status = response.status();
    if !status.is_success() {
        bail!("downloading {url}: HTTP {status}");
    }
    let mut file = std::fs::File::create(dest).with_context(|| format!("creating {}", dest.display()))?;
    let mut hasher = Sha256::new();
    while let Some(chunk) = response.chunk().await.with_context(|| format!("downloading {url}"))? {
        hasher.update(&chunk);
        file.write_all(&chunk).with_context(|| format!("writing {}", dest.display()))?;
    }
    file.sync_all().with_context(|| format!("writing {}", dest.display()))?;
    Ok(hasher.finalize().into())
}

/// Where an archive entry goes under the corpus folder, if it belongs to the corpus:
/// `examples/...`, `examples_noctxt/...` or a top-level `test_*.json`.
fn corpus_path(entry: &Path) -> Option<PathBuf> {
    // Archives put the repository in one top folder (`WindowsAgentArena-<commit>/`).
    let mut parts = entry.components().skip(1);
    for expected in CORPUS_FOLDER.split('/') {
        match parts.next() {
            Some(Component::Normal(name)) if name == expected => {}
            _ => return None,
        }
    }
    let rest: PathBuf = parts.collect();
    let mut names = rest.components();
    match names.next() {
        Some(Component::Normal(first)) if first == "examples" || first == "examples_noctxt" => Some(rest),
        Some(Component::Normal(name)) if names.next().is_none() => {
            let name = name.to_string_lossy();
            (name.starts_with("test_") && name.ends_with(".json")).then_some(rest)
        }
        _ => None,
    }
}

fn extract(archive: &Path, dest: &Path) -> anyhow::Result<Written> {
    let file = std::fs::File::open(archive).with_context(|| format!("opening {}", archive.display()))?;
    let mut zip = zip::ZipArchive::new(std::io::BufReader::new(file))
        .context("the download is not a whole zip archive (truncated or not a zip file)")?;
    let mut written = Written::default();
    for i in 0..zip.len() {
        let mut entry = zip.by_index(i).with_context(|| format!("reading entry {i} of the archive"))?;
        // `enclosed_name` resolves `..` inside the archive; a repository archive has none,
        // so an entry with one (or an absolute path) is a crafted archive, refused whole.
        let climbs = entry.name().split(['/', '\\']).any(|part| part == "..");
        let Some(inside) = entry.enclosed_name().filter(|_| !climbs) else {
            bail!("the archive entry {:?} would land outside the corpus folder; nothing was written", entry.name());
        };
        let Some(relative) = corpus_path(&inside) else { continue };
        let target = dest.join(&relative);
        if entry.is_dir() {
            std::fs::create_dir_all(&target).with_context(|| format!("creating {}", target.display()))?;
            continue;
        }
        if let Some(parent) = target.parent() {
            std::fs::create_dir_all(parent).with_context(|| format!("creating {}", parent.display()))?;
        }
        let mut out = std::fs::File::create(&target).with_context(|| format!("creating {}", target.display()))?;
        std::io::copy(&mut entry, &mut out)
            .with_context(|| format!("extracting {} (the archive may be damaged)", relative.display()))?;
        let is_task = relative.extension().is_some_and(|e| e == "json");
        match relative.components().next() {
            Some(Component::Normal(first)) if first == "examples" && is_task => written.examples += 1,
            Some(Component::Normal(first)) if first == "examples_noctxt" && is_task => written.examples_noctxt += 1,
            Some(Component::Normal(_)) if relative.components().count() == 1 => written.indexes += 1,
            _ => {}
        }
    }
    if written == Written::default() {
        bail!("the archive holds no {CORPUS_FOLDER} folder with task files");
    }
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_the_corpus_folder_is_taken() {
        let check = |entry: &str, expected: Option<&str>| {
            assert_eq!(corpus_path(Path::new(entry)), expected.map(PathBuf::from), "{entry}");
        };
        let base = format!("WAA-abc/{CORPUS_FOLDER}");
        check(&format!("{base}/examples/chrome/a.json"), Some("examples/chrome/a.json"));
        check(&format!("{base}/examples_noctxt/vlc/b.json"), Some("examples_noctxt/vlc/b.json"));
        check(&format!("{base}/test_all.json"), Some("test_all.json"));
        check(&format!("{base}/settings.json"), None);
        check(&format!("{base}/other/test_all.json"), None);
        check("WAA-abc/src/README.md", None);
        check("WAA-abc/examples/a.json", None);
        check(&format!("{CORPUS_FOLDER}/examples/a.json"), None);
    }

    #[test]
    fn hashes_must_be_32_hex_bytes() {
        assert!(parse_sha256(&"ab".repeat(32)).is_ok());
        assert!(parse_sha256("abc").is_err());
        assert!(parse_sha256(&"ab".repeat(31)).is_err());
    }

    #[test]
    fn commits_are_plain_names() {
        assert!(check_commit(DEFAULT_COMMIT).is_ok());
        assert!(check_commit("v1.0-rc_2").is_ok());
        for bad in ["", "main/../x", "abc?x=1", "a b", "abc#frag"] {
            let err = check_commit(bad).expect_err(bad).to_string();
            assert!(err.contains("--commit"), "{err}");
        }
    }
}
