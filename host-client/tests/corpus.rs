//! `arena corpus fetch` against a real HTTP server on loopback serving archives the
//! tests build: laid out like upstream's repository archive, with task files this
//! test writes itself, plus truncated, tampered and missing archives.

use std::io::Write as _;
use std::path::Path;

use arena_host::cli::corpus::{fetch, FetchArgs};
use axum::http::StatusCode;
use axum::routing::get;
use axum::Router;
use sha2::{Digest, Sha256};

const TOP: &str = "WindowsAgentArena-0123abcd";
const CORPUS: &str = "src/win-arena-container/client/evaluation_examples_windows";

/// A zip archive of `entries` (path, text), in that order; a path ending in `/` is a
/// folder entry, as in GitHub's archives.
fn zip_of(entries: &[(String, &str)]) -> Vec<u8> {
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let options = zip::write::SimpleFileOptions::default();
    for (path, text) in entries {
        if path.ends_with('/') {
            zip.add_directory(path.as_str(), options).expect("folder entry");
            continue;
        }
        zip.start_file(path.as_str(), options).expect("start entry");
        zip.write_all(text.as_bytes()).expect("write entry");
    }
    zip.finish().expect("finish zip").into_inner()
}

/// The entries of an archive shaped like the upstream repository's: a few task files
/// under the corpus folder, and files elsewhere that must not be extracted.
fn upstream_entries() -> Vec<(String, &'static str)> {
    vec![
        (format!("{TOP}/"), ""),
        (format!("{TOP}/README.md"), "not part of the corpus"),
        (format!("{TOP}/{CORPUS}/"), ""),
        (format!("{TOP}/{CORPUS}/examples/"), ""),
        (format!("{TOP}/{CORPUS}/examples/notepad/"), ""),
        (format!("{TOP}/{CORPUS}/examples/notepad/t1-wos.json"), r#"{"id": "t1", "instruction": "a test task"}"#),
        (format!("{TOP}/{CORPUS}/examples/notepad/t2-wos.json"), r#"{"id": "t2", "instruction": "another"}"#),
        (format!("{TOP}/{CORPUS}/examples_noctxt/notepad/t1-wos.json"), r#"{"id": "t1", "instruction": "hard"}"#),
        (format!("{TOP}/{CORPUS}/test_all.json"), r#"{"notepad": ["t1-wos", "t2-wos"]}"#),
        (format!("{TOP}/{CORPUS}/create_json.py"), "# not part of the corpus"),
        (format!("{TOP}/{CORPUS}/settings/other.json"), "{}"),
        (format!("{TOP}/src/win-arena-container/vm/setup.ps1"), "# not part of the corpus"),
    ]
}

fn archive() -> Vec<u8> {
    zip_of(&upstream_entries())
}

/// Serves `/good.zip`, `/truncated.zip` (the first half) and a 404 elsewhere.
async fn serve(bytes: Vec<u8>) -> String {
    let half = bytes[..bytes.len() / 2].to_vec();
    let app = Router::new()
        .route("/good.zip", get(move || async move { bytes.clone() }))
        .route("/truncated.zip", get(move || async move { half.clone() }))
        .fallback(|| async { (StatusCode::NOT_FOUND, "no such archive") });
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.expect("bind");
    let url = format!("http://{}", listener.local_addr().expect("addr"));
    tokio::spawn(async move { axum::serve(listener, app).await });
    url
}

fn args(url: String, out: &Path, sha256: Option<String>) -> FetchArgs {
    FetchArgs { commit: "0123abcd".into(), url: Some(url), sha256, out: out.to_path_buf() }
}

/// The names left in `dir`: nothing partial may remain after a failure.
fn left_in(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> =
        std::fs::read_dir(dir).expect("list").map(|e| e.expect("entry").file_name().to_string_lossy().into()).collect();
    names.sort();
    names
}

#[tokio::test]
async fn the_corpus_folder_is_extracted_and_nothing_else() {
    let bytes = archive();
    let sha = hex::encode(Sha256::digest(&bytes));
    let base = serve(bytes).await;
    let work = tempfile::tempdir().expect("dir");
    let out = work.path().join("waa-tasks");
    let written = fetch(&args(format!("{base}/good.zip"), &out, Some(sha.clone()))).await.expect("fetched");
    assert_eq!((written.examples, written.examples_noctxt, written.indexes), (2, 1, 1));
    assert_eq!(left_in(&out), ["PROVENANCE.txt", "examples", "examples_noctxt", "test_all.json"]);
    let task = std::fs::read_to_string(out.join("examples/notepad/t2-wos.json")).expect("task");
    assert!(task.contains("another"), "{task}");
    let provenance = std::fs::read_to_string(out.join("PROVENANCE.txt")).expect("provenance");
    assert!(provenance.contains(&format!("{base}/good.zip")) && provenance.contains(&sha), "{provenance}");
    assert_eq!(left_in(work.path()), ["waa-tasks"], "no temporary folder left");
}

#[tokio::test]
async fn a_truncated_archive_is_a_clear_error_and_leaves_nothing() {
    let base = serve(archive()).await;
    let work = tempfile::tempdir().expect("dir");
    let out = work.path().join("waa-tasks");
    let err = fetch(&args(format!("{base}/truncated.zip"), &out, None)).await.expect_err("truncated");
    assert!(format!("{err:#}").contains("not a whole zip archive"), "{err:#}");
    assert!(left_in(work.path()).is_empty(), "{:?}", left_in(work.path()));
}

#[tokio::test]
async fn a_wrong_hash_is_refused_before_anything_is_written() {
    let base = serve(archive()).await;
    let work = tempfile::tempdir().expect("dir");
    let out = work.path().join("waa-tasks");
    let wrong = "00".repeat(32);
    let actual = hex::encode(Sha256::digest(archive()));
    let err = fetch(&args(format!("{base}/good.zip"), &out, Some(wrong.clone()))).await.expect_err("wrong hash");
    let text = format!("{err:#}");
    assert!(text.contains("SHA-256") && text.contains(&wrong) && text.contains(&actual), "{text}");
    assert!(left_in(work.path()).is_empty(), "{:?}", left_in(work.path()));
}

#[tokio::test]
async fn http_errors_and_occupied_folders_are_refused() {
    let base = serve(archive()).await;
    let work = tempfile::tempdir().expect("dir");
    let out = work.path().join("waa-tasks");
    let err = fetch(&args(format!("{base}/missing.zip"), &out, None)).await.expect_err("404");
    assert!(format!("{err:#}").contains("HTTP 404"), "{err:#}");
    assert!(left_in(work.path()).is_empty());

    std::fs::create_dir(&out).expect("mkdir");
    std::fs::write(out.join("mine.txt"), b"keep").expect("write");
    let err = fetch(&args(format!("{base}/good.zip"), &out, None)).await.expect_err("occupied");
    assert!(format!("{err:#}").contains("not an empty folder"), "{err:#}");
    assert_eq!(left_in(&out), ["mine.txt"], "what the user had is kept");
    // An empty folder is fine to fill.
    std::fs::remove_file(out.join("mine.txt")).expect("rm");
    fetch(&args(format!("{base}/good.zip"), &out, None)).await.expect("an empty folder is filled");
    assert!(out.join("test_all.json").is_file());
}

#[tokio::test]
async fn an_archive_without_the_corpus_is_refused() {
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    zip.start_file(format!("{TOP}/README.md"), zip::write::SimpleFileOptions::default()).expect("entry");
    zip.write_all(b"no corpus").expect("write");
    let base = serve(zip.finish().expect("zip").into_inner()).await;
    let work = tempfile::tempdir().expect("dir");
    let out = work.path().join("waa-tasks");
    let err = fetch(&args(format!("{base}/good.zip"), &out, None)).await.expect_err("no corpus");
    assert!(format!("{err:#}").contains("holds no"), "{err:#}");
    assert!(left_in(work.path()).is_empty());
}

#[tokio::test]
async fn an_entry_that_climbs_out_of_its_folder_refuses_the_whole_archive() {
    // One stays inside the archive once resolved (it would become an index file), one
    // climbs past the archive's top; both are crafted, and neither may be written.
    for climbing in
        [format!("{TOP}/{CORPUS}/examples/../test_extra.json"), format!("{TOP}/{CORPUS}/{}x.json", "../".repeat(8))]
    {
        let mut entries = upstream_entries();
        entries.push((climbing.clone(), "{}"));
        let base = serve(zip_of(&entries)).await;
        let work = tempfile::tempdir().expect("dir");
        let out = work.path().join("waa-tasks");
        let err = fetch(&args(format!("{base}/good.zip"), &out, None)).await.expect_err(&climbing);
        assert!(format!("{err:#}").contains("would land outside the corpus folder"), "{climbing}: {err:#}");
        assert!(left_in(work.path()).is_empty(), "{climbing}: {:?}", left_in(work.path()));
    }
}
