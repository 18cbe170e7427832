//! `/v1/files` and `/v1/folders`: reading, writing, inspecting and removing
//! guest files.
//!
//! Every path is a guest path (`C:\Users\Docker\a.txt`, `~\a.txt`,
//! `%TEMP%\a.txt`): it is expanded the way upstream's Python does
//! ([`crate::paths::expand`]) with the guest's environment, then mapped by the
//! backend onto a path this process can open ([`Desktop::map_path`]), which
//! refuses relative paths and paths that climb out of the backend's root.
//! The file work itself is plain `std::fs`, inside the backend call so that it
//! runs on the backend pool under the call's deadline.
//!
//! Writes are atomic: the body goes to a temporary file beside the target,
//! is flushed to disk and then renamed over the target, so a failed or
//! interrupted write leaves either the old content or the new, never a mix.

use std::path::PathBuf;
use std::time::SystemTime;

use axum::extract::State;
use axum::http::{header, HeaderName, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::Router;
use sha2::{Digest, Sha256};

use arena_shared::atomic::AtomicFile;

use arena_shared::files::{
    DirEntry, DirListing, Exists, FileKind, FileStat, FileWritten, KnownFolder, KnownFolders, MkdirRequest, PathQuery,
    WriteQuery,
};

use crate::call::blocking;
use crate::desktop::{Desktop, DesktopError};
use crate::error::{ApiError, AppJson, AppQuery};
use crate::paths;
use crate::state::AppState;

/// The header carrying the SHA-256 of a file read.
pub(crate) const SHA256_HEADER: HeaderName = HeaderName::from_static("x-arena-sha256");

pub(crate) fn routes() -> Router<AppState> {
    Router::new()
        .route("/v1/files", get(read).put(write).delete(delete))
        .route("/v1/files/stat", get(stat))
        .route("/v1/files/exists", get(exists))
        .route("/v1/files/list", get(list))
        .route("/v1/files/mkdir", post(mkdir))
        .route("/v1/files/recycle", post(recycle))
        .route("/v1/folders", get(folders))
}

/// Runs `f` as one backend call under the ordinary deadline.
///
/// `f` answers with [`ApiError`] so that file-level outcomes (a directory where a
/// file was expected, a hash mismatch) keep their precise status.
async fn run<T, F>(state: &AppState, op: &'static str, f: F) -> Result<T, ApiError>
where
    F: FnOnce(&dyn Desktop) -> Result<T, ApiError> + Send + 'static,
    T: Send + 'static,
{
    blocking(&state.desktop, op, state.call_timeout(), move |d| Ok(f(d))).await?
}

/// A guest path and where this process finds it.
#[derive(Debug)]
struct Located {
    guest: String,
    local: PathBuf,
}

/// Expands and maps a request's path.
fn locate(d: &dyn Desktop, path: &str) -> Result<Located, ApiError> {
    if path.trim().is_empty() {
        return Err(ApiError::BadRequest("path must not be empty".into()));
    }
    let guest = paths::expand(path, &mut |name| d.env_var(name));
    let local = d.map_path(&guest)?;
    Ok(Located { guest, local })
}

fn io_error(op: &'static str, loc: &Located, err: std::io::Error) -> ApiError {
    ApiError::Desktop(DesktopError::io(op, &loc.guest, err))
}

fn kind_of(meta: &std::fs::Metadata) -> FileKind {
    if meta.is_file() {
        FileKind::File
    } else if meta.is_dir() {
        FileKind::Dir
    } else {
        FileKind::Other
    }
}

/// Milliseconds since the Unix epoch, negative before it.
fn epoch_ms(time: SystemTime) -> Option<i64> {
    match time.duration_since(SystemTime::UNIX_EPOCH) {
        Ok(after) => i64::try_from(after.as_millis()).ok(),
        Err(before) => i64::try_from(before.duration().as_millis()).ok().map(|ms| -ms),
    }
}

// ----- read -----

/// Size of the chunks files are hashed, read and written in.
const CHUNK: usize = 256 << 10;

/// Streams the file: it is hashed in a first pass (for the `x-arena-sha256` header),
/// then sent from disk chunk by chunk, so a large file costs a chunk of memory, not
/// its size.
async fn read(State(state): State<AppState>, AppQuery(query): AppQuery<PathQuery>) -> Result<Response, ApiError> {
    let (local, size, sha256) = run(&state, "read_file", move |d| {
        let loc = locate(d, &query.path)?;
        let meta = std::fs::metadata(&loc.local).map_err(|err| io_error("read_file", &loc, err))?;
        if meta.is_dir() {
            return Err(ApiError::BadRequest(format!("{} is a directory", loc.guest)));
        }
        let sha256 = hash_file(&loc.local).map_err(|err| io_error("read_file", &loc, err))?;
        Ok((loc.local, meta.len(), sha256))
    })
    .await?;
    let file = tokio::fs::File::open(&local)
        .await
        .map_err(|err| ApiError::Desktop(DesktopError::io("read_file", &local.display().to_string(), err)))?;
    let body = axum::body::Body::from_stream(tokio_util::io::ReaderStream::with_capacity(file, CHUNK));
    let headers = [
        (header::CONTENT_TYPE, HeaderValue::from_static("application/octet-stream")),
        (header::CONTENT_LENGTH, HeaderValue::from(size)),
        (SHA256_HEADER, HeaderValue::from_str(&sha256).unwrap_or(HeaderValue::from_static(""))),
    ];
    Ok((headers, body).into_response())
}

/// The SHA-256 of a file, read in chunks.
fn hash_file(path: &std::path::Path) -> std::io::Result<String> {
    use std::io::Read as _;
    let mut file = std::fs::File::open(path)?;
    let mut hasher = Sha256::new();
    let mut buf = vec![0; CHUNK];
    loop {
        match file.read(&mut buf)? {
            0 => return Ok(hex::encode(hasher.finalize())),
            n => hasher.update(&buf[..n]),
        }
    }
}

// ----- write -----

/// Streams the body into a temporary file beside the target while hashing it, and
/// renames it into place only when the whole body arrived and matches `sha256`.
async fn write(
    State(state): State<AppState>,
    AppQuery(query): AppQuery<WriteQuery>,
    body: axum::body::Body,
) -> Result<AppJson<FileWritten>, ApiError> {
    use futures_util::StreamExt as _;
    use tokio::io::AsyncWriteExt as _;
    let expected = match query.sha256 {
        Some(sha) if sha.len() == 64 && sha.bytes().all(|b| b.is_ascii_hexdigit()) => Some(sha.to_ascii_lowercase()),
        Some(sha) => return Err(ApiError::BadRequest(format!("sha256 must be 64 hex digits (got {sha:?})"))),
        None => None,
    };
    let create_parents = query.create_parents.unwrap_or(true);
    let limit = state.config.max_body_bytes;
    let (loc, mut temp) = run(&state, "write_file", move |d| {
        let loc = locate(d, &query.path)?;
        crate::protect::refuse_destructive(d, "overwrite", &loc.guest)?;
        prepare_write(&loc, create_parents)?;
        let temp = AtomicFile::create(&loc.local).map_err(|err| io_error("write_file", &loc, err))?;
        Ok((loc, temp))
    })
    .await?;
    let io = |err: std::io::Error| ApiError::Desktop(DesktopError::io("write_file", &loc.guest, err));
    let mut file = tokio::fs::File::from_std(temp.file().try_clone().map_err(io)?);
    let (mut hasher, mut size) = (Sha256::new(), 0usize);
    let mut stream = body.into_data_stream();
    while let Some(chunk) = stream.next().await {
        let chunk = chunk.map_err(|err| ApiError::BadRequest(format!("reading the body: {err}")))?;
        size += chunk.len();
        if size > limit {
            return Err(ApiError::PayloadTooLarge(format!(
                "the body is over {limit} bytes (--max-body-bytes); nothing was written"
            )));
        }
        hasher.update(&chunk);
        file.write_all(&chunk).await.map_err(io)?;
    }
    file.flush().await.map_err(io)?;
    drop(file);
    let sha256 = hex::encode(hasher.finalize());
    if let Some(expected) = expected.filter(|e| *e != sha256) {
        return Err(ApiError::Conflict(format!("the body hashes to {sha256}, not {expected}; nothing was written")));
    }
    let guest = loc.guest.clone();
    run(&state, "write_file", move |_| temp.commit().map_err(|err| io_error("write_file", &loc, err))).await?;
    Ok(AppJson(FileWritten { path: guest, size: size as u64, sha256 }))
}

/// Checks that `loc` may be written (not a folder, not read-only) and that its
/// folder exists, creating it when asked.
fn prepare_write(loc: &Located, create_parents: bool) -> Result<(), ApiError> {
    let io = |err| io_error("write_file", loc, err);
    if loc.local.is_dir() {
        return Err(ApiError::BadRequest(format!("{} is a directory", loc.guest)));
    }
    // Windows refuses to replace a read-only file; a rename would do it on any backend.
    if std::fs::metadata(&loc.local).is_ok_and(|meta| meta.permissions().readonly()) {
        return Err(ApiError::Forbidden(format!("{} is read-only; nothing was written", loc.guest)));
    }
    let parent =
        loc.local.parent().ok_or_else(|| ApiError::BadRequest(format!("{} has no parent folder", loc.guest)))?;
    match std::fs::metadata(parent) {
        Ok(meta) if meta.is_dir() => {}
        Ok(_) => return Err(ApiError::Conflict(format!("the parent of {} is a file, not a folder", loc.guest))),
        Err(err) if err.kind() == std::io::ErrorKind::NotFound => {
            if !create_parents {
                return Err(ApiError::NotFound(format!(
                    "the parent folder of {} does not exist (pass create_parents=true to create it)",
                    loc.guest
                )));
            }
            std::fs::create_dir_all(parent).map_err(io)?;
        }
        Err(err) => return Err(io(err)),
    }
    Ok(())
}

// ----- inspect -----

async fn stat(
    State(state): State<AppState>,
    AppQuery(query): AppQuery<PathQuery>,
) -> Result<AppJson<FileStat>, ApiError> {
    let stat = run(&state, "stat", move |d| {
        let loc = locate(d, &query.path)?;
        let meta = std::fs::metadata(&loc.local).map_err(|err| io_error("stat", &loc, err))?;
        Ok(FileStat {
            kind: kind_of(&meta),
            size: meta.len(),
            modified_ms: meta.modified().ok().and_then(epoch_ms),
            readonly: meta.permissions().readonly(),
            hidden: d.is_hidden(&loc.local),
            path: loc.guest,
        })
    })
    .await?;
    Ok(AppJson(stat))
}

async fn exists(
    State(state): State<AppState>,
    AppQuery(query): AppQuery<PathQuery>,
) -> Result<AppJson<Exists>, ApiError> {
    let exists = run(&state, "exists", move |d| {
        let loc = locate(d, &query.path)?;
        match std::fs::metadata(&loc.local) {
            Ok(meta) => Ok(Exists { exists: true, kind: Some(kind_of(&meta)) }),
            Err(err) if is_absent(&err) => Ok(Exists { exists: false, kind: None }),
            Err(err) => Err(io_error("exists", &loc, err)),
        }
    })
    .await?;
    Ok(AppJson(exists))
}

/// Whether an error means "there is nothing at this path" (including a path
/// that runs through a file, which cannot exist either).
fn is_absent(err: &std::io::Error) -> bool {
    matches!(err.kind(), std::io::ErrorKind::NotFound | std::io::ErrorKind::NotADirectory)
}

async fn list(
    State(state): State<AppState>,
    AppQuery(query): AppQuery<PathQuery>,
) -> Result<AppJson<DirListing>, ApiError> {
    let listing = run(&state, "list", move |d| {
        let loc = locate(d, &query.path)?;
        let meta = std::fs::metadata(&loc.local).map_err(|err| io_error("list", &loc, err))?;
        if !meta.is_dir() {
            return Err(ApiError::BadRequest(format!("{} is not a directory", loc.guest)));
        }
        let mut entries = Vec::new();
        for entry in std::fs::read_dir(&loc.local).map_err(|err| io_error("list", &loc, err))? {
            let entry = entry.map_err(|err| io_error("list", &loc, err))?;
            entries.extend(dir_entry(&entry));
        }
        entries.sort_by(|a, b| arena_shared::ntfs::cmp_names(&a.name, &b.name));
        Ok(DirListing { path: loc.guest, entries })
    })
    .await?;
    Ok(AppJson(listing))
}

/// One listing entry, following links; an entry that vanished meanwhile is skipped.
fn dir_entry(entry: &std::fs::DirEntry) -> Option<DirEntry> {
    let meta = std::fs::metadata(entry.path()).or_else(|_| entry.metadata());
    match meta {
        Ok(meta) => Some(DirEntry {
            name: entry.file_name().to_string_lossy().into_owned(),
            kind: kind_of(&meta),
            size: meta.len(),
            modified_ms: meta.modified().ok().and_then(epoch_ms),
        }),
        Err(err) => {
            tracing::debug!(path = %entry.path().display(), error = %err, "skipping an entry that cannot be read");
            None
        }
    }
}

// ----- change -----

async fn delete(State(state): State<AppState>, AppQuery(query): AppQuery<PathQuery>) -> Result<StatusCode, ApiError> {
    run(&state, "delete", move |d| {
        let loc = locate(d, &query.path)?;
        crate::protect::refuse_destructive(d, "delete", &loc.guest)?;
        let io = |err| io_error("delete", &loc, err);
        let meta = std::fs::symlink_metadata(&loc.local).map_err(io)?;
        if !meta.is_dir() {
            return std::fs::remove_file(&loc.local).map_err(io);
        }
        if query.recursive {
            return std::fs::remove_dir_all(&loc.local).map_err(io);
        }
        if std::fs::read_dir(&loc.local).map_err(io)?.next().is_some() {
            return Err(ApiError::Conflict(format!(
                "{} is a directory that is not empty (pass recursive=true)",
                loc.guest
            )));
        }
        std::fs::remove_dir(&loc.local).map_err(io)
    })
    .await?;
    Ok(StatusCode::NO_CONTENT)
}

async fn mkdir(State(state): State<AppState>, AppJson(request): AppJson<MkdirRequest>) -> Result<StatusCode, ApiError> {
    run(&state, "mkdir", move |d| {
        let loc = locate(d, &request.path)?;
        if loc.local.exists() && !loc.local.is_dir() {
            return Err(ApiError::Conflict(format!("{} exists and is not a directory", loc.guest)));
        }
        std::fs::create_dir_all(&loc.local).map_err(|err| io_error("mkdir", &loc, err))
    })
    .await?;
    Ok(StatusCode::NO_CONTENT)
}

async fn recycle(State(state): State<AppState>, AppJson(request): AppJson<PathQuery>) -> Result<StatusCode, ApiError> {
    run(&state, "recycle", move |d| {
        let loc = locate(d, &request.path)?;
        crate::protect::refuse_destructive(d, "recycle", &loc.guest)?;
        ensure_exists(&loc)?;
        Ok(d.recycle(&loc.guest)?)
    })
    .await?;
    Ok(StatusCode::NO_CONTENT)
}

/// 404 unless something is at `loc` (a dangling link counts as something).
fn ensure_exists(loc: &Located) -> Result<(), ApiError> {
    match std::fs::symlink_metadata(&loc.local) {
        Ok(_) => Ok(()),
        Err(err) => Err(io_error("exists", loc, err)),
    }
}

async fn folders(State(state): State<AppState>) -> Result<AppJson<KnownFolders>, ApiError> {
    let folders = run(&state, "known_folder", |d| {
        let folders = KnownFolder::ALL
            .into_iter()
            .map(|folder| Ok((folder, d.known_folder(folder)?)))
            .collect::<Result<_, ApiError>>()?;
        Ok(KnownFolders { folders })
    })
    .await?;
    Ok(AppJson(folders))
}

/// Expands and maps `path` and checks that it exists, for routes in other modules
/// that hand a guest path to the backend (`/v1/open`). Answers the expanded guest path.
pub(super) fn existing_guest_path(d: &dyn Desktop, path: &str) -> Result<String, ApiError> {
    let loc = locate(d, path)?;
    ensure_exists(&loc)?;
    Ok(loc.guest)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn epoch_milliseconds_are_signed() {
        let after = SystemTime::UNIX_EPOCH + std::time::Duration::from_millis(1500);
        let before = SystemTime::UNIX_EPOCH - std::time::Duration::from_millis(2500);
        assert_eq!(epoch_ms(after), Some(1500));
        assert_eq!(epoch_ms(before), Some(-2500));
    }

    #[test]
    fn writes_are_prepared_only_where_they_may_go() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("new").join("a.txt");
        let loc = Located { guest: r"C:\new\a.txt".into(), local: target.clone() };
        assert!(matches!(prepare_write(&loc, false), Err(ApiError::NotFound(_))));
        prepare_write(&loc, true).unwrap();
        assert!(target.parent().unwrap().is_dir(), "the folder was created");
        let as_dir = Located { guest: r"C:\d".into(), local: dir.path().to_path_buf() };
        assert!(matches!(prepare_write(&as_dir, true), Err(ApiError::BadRequest(_))));
    }

    #[test]
    fn files_are_hashed_in_chunks() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("big.bin");
        let bytes: Vec<u8> = (0..(CHUNK * 2 + 7)).map(|i| (i % 251) as u8).collect();
        std::fs::write(&path, &bytes).unwrap();
        assert_eq!(hash_file(&path).unwrap(), hex::encode(Sha256::digest(&bytes)));
    }
}
