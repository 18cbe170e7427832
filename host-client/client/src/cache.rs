//! [`DownloadCache`]: the host's content-addressed store of the files that
//! `download` steps fetch, so a run can be repeated offline.
//!
//! Layout of the cache folder:
//!
//! - `blobs/<sha256>`: each file once, named by the lowercase hex SHA-256 of its bytes;
//! - `index.json`: `{"<url>": "<sha256>", ...}`, rewritten atomically (a
//!   temporary file renamed over it) after every new download.
//!
//! A URL in the index whose blob is present (and still hashes to its name) is
//! served without any network. Otherwise the file is fetched with up to three
//! attempts, as upstream's host does. Upstream keyed its cache by
//! `uuid5(url)_<basename>`; content addressing also lets two URLs of the same
//! bytes share one copy, and a corrupted copy is noticed and fetched again.
//!
//! It is not an HTTP cache: no expiry, no revalidation. A URL's content is
//! what it was when first fetched, which is what repeatable runs need. The setup
//! steps (`download`) and the getters (cloud files) share it.

use std::collections::BTreeMap;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use sha2::{Digest, Sha256};

use arena_shared::atomic::AtomicFile;

/// The cache could not serve a URL.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CacheError {
    /// A file could not be downloaded and is not in the cache. Names the URL.
    #[error("download of {url} failed: {reason}")]
    Download { url: String, reason: String },
    /// The cache folder could not be read or written.
    #[error("download cache {}: {reason}", path.display())]
    Cache { path: PathBuf, reason: String },
}

/// Attempts per URL (upstream: 3).
const ATTEMPTS: u32 = 3;
/// Pause after a failed attempt, doubled each time.
const RETRY_PAUSE: Duration = Duration::from_millis(250);
/// Longest wait for the next bytes of a download.
const READ_TIMEOUT: Duration = Duration::from_secs(60);

/// The URL → SHA-256 index.
type Index = BTreeMap<String, String>;

/// The download cache of one host; cheap to clone, clones share the folder and its lock.
#[derive(Debug, Clone)]
pub struct DownloadCache {
    dir: PathBuf,
    http: reqwest::Client,
    /// Serialises index rewrites of this process, so concurrent episodes lose no entry.
    index_lock: Arc<tokio::sync::Mutex<()>>,
}

impl DownloadCache {
    /// A cache in `dir`, created if missing.
    ///
    /// # Errors
    ///
    /// [`CacheError::Cache`] when the folder cannot be created.
    pub fn new(dir: impl Into<PathBuf>) -> Result<DownloadCache, CacheError> {
        let dir = dir.into();
        let blobs = dir.join("blobs");
        std::fs::create_dir_all(&blobs).map_err(|err| cache_error(&blobs, &err))?;
        let http = reqwest::Client::builder()
            .connect_timeout(Duration::from_secs(30))
            .read_timeout(READ_TIMEOUT)
            .build()
            .map_err(|err| CacheError::Cache {
                path: dir.clone(),
                reason: format!("cannot build an HTTP client: {err}"),
            })?;
        Ok(DownloadCache { dir, http, index_lock: Arc::new(tokio::sync::Mutex::new(())) })
    }

    /// The cache folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    fn index_path(&self) -> PathBuf {
        self.dir.join("index.json")
    }

    fn blob_path(&self, sha256: &str) -> PathBuf {
        self.dir.join("blobs").join(sha256)
    }

    /// The cached file of `url`, if the cache holds an intact copy. Does no network.
    ///
    /// # Errors
    ///
    /// [`CacheError::Cache`] when the index exists but cannot be read or parsed.
    pub async fn lookup(&self, url: &str) -> Result<Option<PathBuf>, CacheError> {
        let index = self.read_index().await?;
        let Some(sha256) = index.get(url) else { return Ok(None) };
        if !is_sha256(sha256) {
            tracing::warn!(%url, %sha256, "download cache index holds a malformed hash; ignoring it");
            return Ok(None);
        }
        let blob = self.blob_path(sha256);
        match tokio::fs::read(&blob).await {
            Ok(bytes) if hex::encode(Sha256::digest(&bytes)) == *sha256 => Ok(Some(blob)),
            Ok(_) => {
                tracing::warn!(%url, blob = %blob.display(), "cached file is corrupted; fetching it again");
                Ok(None)
            }
            Err(_) => Ok(None),
        }
    }

    /// The local path of `url`'s bytes: from the cache when it holds them,
    /// otherwise downloaded (up to three attempts) and stored first.
    ///
    /// # Errors
    ///
    /// [`CacheError::Download`] naming the URL when it is not cached and every
    /// attempt failed (no network, a non-2xx status, a broken transfer);
    /// [`CacheError::Cache`] when the cache cannot be read or written.
    pub async fn fetch(&self, url: &str) -> Result<PathBuf, CacheError> {
        if let Some(path) = self.lookup(url).await? {
            tracing::debug!(%url, path = %path.display(), "download served from the cache");
            return Ok(path);
        }
        let mut last_error = String::new();
        for attempt in 1..=ATTEMPTS {
            match self.download(url).await {
                Ok(sha256) => {
                    self.record(url, &sha256).await?;
                    tracing::info!(%url, %sha256, attempt, "downloaded into the cache");
                    return Ok(self.blob_path(&sha256));
                }
                Err(Failure::Cache(err)) => return Err(err),
                Err(Failure::Network(reason)) => {
                    tracing::warn!(%url, attempt, %reason, "download attempt failed");
                    last_error = reason;
                }
            }
            if attempt < ATTEMPTS {
                tokio::time::sleep(RETRY_PAUSE * (1 << (attempt - 1))).await;
            }
        }
        Err(CacheError::Download {
            url: url.to_owned(),
            reason: format!(
                "not in the download cache {} and {ATTEMPTS} attempts to fetch it failed (last: {last_error})",
                self.dir.display()
            ),
        })
    }

    /// One attempt: streams the body into a temporary file in `blobs/`, hashing
    /// as it goes, and renames it to its hash. Answers the hash.
    async fn download(&self, url: &str) -> Result<String, Failure> {
        let mut response = self.http.get(url).send().await.map_err(|err| Failure::Network(describe(&err)))?;
        let status = response.status();
        if !status.is_success() {
            return Err(Failure::Network(format!("HTTP {status}")));
        }
        let blobs = self.dir.join("blobs");
        // Named once the hash is known; the temporary file sits in the same folder.
        let mut blob =
            AtomicFile::create(&blobs.join("incoming")).map_err(|err| Failure::Cache(cache_error(&blobs, &err)))?;
        let mut hasher = Sha256::new();
        while let Some(chunk) = response.chunk().await.map_err(|err| Failure::Network(describe(&err)))? {
            hasher.update(&chunk);
            // A local write of one network chunk: short enough to do in place.
            blob.file().write_all(&chunk).map_err(|err| Failure::Cache(cache_error(blob.temp_path(), &err)))?;
        }
        let sha256 = hex::encode(hasher.finalize());
        let path = self.blob_path(&sha256);
        blob.retarget(&path);
        blob.commit().map_err(|err| Failure::Cache(cache_error(&path, &err)))?;
        Ok(sha256)
    }

    async fn read_index(&self) -> Result<Index, CacheError> {
        let path = self.index_path();
        match tokio::fs::read(&path).await {
            Ok(bytes) => serde_json::from_slice(&bytes).map_err(|err| CacheError::Cache {
                path,
                reason: format!("the index is not a JSON object of URL to hash: {err}"),
            }),
            Err(err) if err.kind() == std::io::ErrorKind::NotFound => Ok(Index::new()),
            Err(err) => Err(cache_error(&path, &err)),
        }
    }

    /// Adds `url → sha256` to the index: read, change, write a temporary file, rename.
    async fn record(&self, url: &str, sha256: &str) -> Result<(), CacheError> {
        let _guard = self.index_lock.lock().await;
        let mut index = self.read_index().await?;
        index.insert(url.to_owned(), sha256.to_owned());
        let path = self.index_path();
        let text = serde_json::to_vec_pretty(&index)
            .map_err(|err| CacheError::Cache { path: path.clone(), reason: err.to_string() })?;
        tokio::task::spawn_blocking(move || -> Result<(), CacheError> {
            arena_shared::atomic::write_atomic(&path, &text).map_err(|err| cache_error(&path, &err))
        })
        .await
        .map_err(|err| CacheError::Cache {
            path: self.index_path(),
            reason: format!("the index writer failed: {err}"),
        })?
    }
}

/// Why one download attempt failed: worth another attempt, or not.
enum Failure {
    Network(String),
    Cache(CacheError),
}

fn cache_error(path: &Path, err: &std::io::Error) -> CacheError {
    CacheError::Cache { path: path.to_owned(), reason: err.to_string() }
}

fn is_sha256(s: &str) -> bool {
    s.len() == 64 && s.bytes().all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b))
}

/// A reqwest error as one line, with its innermost cause ("Connection refused").
fn describe(err: &reqwest::Error) -> String {
    crate::error::flatten(err)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn a_cached_url_is_served_without_network_and_a_corrupt_copy_is_not() {
        let dir = tempfile::tempdir().unwrap();
        let cache = DownloadCache::new(dir.path()).unwrap();
        let bytes = b"hello cache";
        let sha = hex::encode(Sha256::digest(bytes));
        std::fs::write(dir.path().join("blobs").join(&sha), bytes).unwrap();
        cache.record("http://203.0.113.1/a.txt", &sha).await.unwrap();
        let path = cache.fetch("http://203.0.113.1/a.txt").await.unwrap();
        assert_eq!(std::fs::read(path).unwrap(), bytes);

        std::fs::write(dir.path().join("blobs").join(&sha), b"tampered").unwrap();
        assert_eq!(cache.lookup("http://203.0.113.1/a.txt").await.unwrap(), None);
    }

    #[tokio::test]
    async fn the_index_keeps_every_entry_and_rejects_garbage() {
        let dir = tempfile::tempdir().unwrap();
        let cache = DownloadCache::new(dir.path()).unwrap();
        let a = "a".repeat(64);
        let b = "b".repeat(64);
        cache.record("u1", &a).await.unwrap();
        cache.record("u2", &b).await.unwrap();
        let index: Index = serde_json::from_slice(&std::fs::read(dir.path().join("index.json")).unwrap()).unwrap();
        assert_eq!(index.get("u1"), Some(&a));
        assert_eq!(index.get("u2"), Some(&b));
        let leftovers: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .flatten()
            .filter(|e| e.file_name().to_string_lossy().starts_with(".index-"))
            .collect();
        assert!(leftovers.is_empty(), "temporary index files left behind");

        std::fs::write(dir.path().join("index.json"), b"[1, 2]").unwrap();
        let err = cache.lookup("u1").await.unwrap_err();
        assert!(err.to_string().contains("index.json"), "{err}");
    }

    #[test]
    fn hashes_are_64_lowercase_hex_digits() {
        assert!(is_sha256(&"0f".repeat(32)));
        assert!(!is_sha256(&"0F".repeat(32)));
        assert!(!is_sha256("../../etc/passwd"));
    }
}
