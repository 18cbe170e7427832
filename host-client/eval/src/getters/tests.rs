//! Getters against a real in-process stub guest on `127.0.0.1:0`.

use std::time::Duration;

use arena_guest::config::ServerConfig;
use arena_shared::exec::LaunchRequest;
use arena_shared::files::KnownFolder;
use arena_shared::registry::{RegistryValue, RegistryWrite};
use arena_test_support::StubGuest;
use serde_json::{json, Value};

use super::{lookup, GetterError, Params};
use crate::value::Fetched;
use crate::{fetch, EvalContext};
use arena_client::cache::DownloadCache;
use arena_client::client::{ClientConfig, GuestClient};
use arena_task::GetterSpec;

/// A stub guest serving in a task (the one test launcher), with a host work folder
/// and a download cache; stops when dropped.
pub(crate) struct Guest {
    pub(crate) ctx: EvalContext,
    stub: StubGuest,
    _host: tempfile::TempDir,
}

impl Guest {
    /// The host folder the guest's drives are mapped into.
    pub(crate) fn root(&self) -> &std::path::Path {
        self.stub.root()
    }
}

pub(crate) async fn start_guest() -> Guest {
    start_guest_with(None, |_| {}).await
}

/// A stub guest seeded by `scenario` when given, its configuration adjusted by
/// `configure`, and an evaluation context over it.
pub(crate) async fn start_guest_with(scenario: Option<Value>, configure: impl FnOnce(&mut ServerConfig)) -> Guest {
    let host = tempfile::tempdir().expect("host dir");
    let scenario = scenario.map(|scenario| {
        let path = host.path().join("scenario.json");
        std::fs::write(&path, scenario.to_string()).expect("write scenario");
        path
    });
    let stub = StubGuest::start_with(|config| {
        config.scenario = scenario;
        configure(config);
    })
    .await;
    let client =
        GuestClient::new(stub.url(), ClientConfig { token: None, timeout: Duration::from_secs(20), retries: 0 })
            .expect("client");
    client.wait_ready(&[], Duration::from_secs(20), Duration::from_millis(50)).await.expect("stub ready");
    let cache = DownloadCache::new(host.path().join("cache")).expect("cache");
    let ctx =
        EvalContext { client, cache, work_dir: host.path().join("work"), task_dir: Some(host.path().join("task")) };
    Guest { ctx, stub, _host: host }
}

pub(crate) fn spec(value: Value) -> GetterSpec {
    let Value::Object(mut map) = value else { panic!("a getter is an object") };
    let kind = map.remove("type").and_then(|v| v.as_str().map(str::to_owned)).expect("type");
    GetterSpec { kind, params: map }
}

async fn folder(guest: &Guest, which: KnownFolder) -> String {
    let folders = guest.ctx.client.folders().await.expect("folders");
    folders.folders.into_iter().find(|(k, _)| *k == which).map(|(_, p)| p).expect("known folder")
}

async fn push(guest: &Guest, path: &str, bytes: &[u8]) {
    guest.ctx.client.push_file(path, bytes.to_vec(), None).await.expect("push");
}

/// Runs a getter and compares with `want`: a value, or an error containing the text.
async fn check(guest: &Guest, getter: Value, want: Result<Fetched, &str>) {
    let got = fetch(&guest.ctx, &spec(getter.clone())).await;
    match (&got, &want) {
        (Ok(value), Ok(expected)) => assert_eq!(value, expected, "{getter}"),
        (Err(err), Err(text)) => assert!(err.to_string().contains(text), "{getter}: {err} lacks {text:?}"),
        _ => panic!("{getter}: got {got:?}, want {want:?}"),
    }
}

#[tokio::test]
async fn rule_returns_its_rules() {
    let guest = start_guest().await;
    check(
        &guest,
        json!({"type": "rule", "rules": {"expected": [1, "a"]}}),
        Ok(Fetched::Json(json!({"expected": [1, "a"]}))),
    )
    .await;
    check(&guest, json!({"type": "rule"}), Err("missing parameter `rules`")).await;
}

#[tokio::test]
async fn vm_file_saves_dest_and_returns_none_for_missing_files() {
    let guest = start_guest().await;
    let docs = folder(&guest, KnownFolder::Documents).await;
    push(&guest, &format!(r"{docs}\draft.txt"), b"hello\r\n").await;
    push(&guest, &format!(r"{docs}\second.txt"), b"two").await;
    let work = guest.ctx.work_dir.clone();

    let got =
        fetch(&guest.ctx, &spec(json!({"type": "vm_file", "path": format!(r"{docs}\draft.txt"), "dest": "draft.txt"})))
            .await;
    assert_eq!(got.unwrap(), Fetched::File(work.join("draft.txt")));
    assert_eq!(std::fs::read(work.join("draft.txt")).unwrap(), b"hello\r\n");

    check(
        &guest,
        json!({"type": "vm_file", "path": format!(r"{docs}\absent.txt"), "dest": "absent.txt"}),
        Ok(Fetched::None),
    )
    .await;
    assert!(!work.join("absent.txt").exists());

    // multi + gives: the listed entries, `None` where the guest has no file.
    let multi = json!({
        "type": "vm_file", "multi": true,
        "path": [format!(r"{docs}\draft.txt"), format!(r"{docs}\absent.txt"), format!(r"{docs}\second.txt")],
        "dest": ["a.txt", "b.txt", "c.txt"],
        "gives": [0, 1, 2],
    });
    let want = Fetched::List(vec![Fetched::File(work.join("a.txt")), Fetched::None, Fetched::File(work.join("c.txt"))]);
    check(&guest, multi.clone(), Ok(want)).await;
    let mut one = multi.clone();
    one["gives"] = json!([2]);
    check(&guest, one, Ok(Fetched::File(work.join("c.txt")))).await;
    let mut default_gives = multi.clone();
    default_gives.as_object_mut().unwrap().remove("gives");
    check(&guest, default_gives, Ok(Fetched::File(work.join("a.txt")))).await;
    let mut none = multi;
    none["gives"] = json!([]);
    check(&guest, none, Ok(Fetched::List(vec![]))).await;

    check(&guest, json!({"type": "vm_file", "path": r"C:\x.txt", "dest": "../escape.txt"}), Err("relative file name"))
        .await;
    check(&guest, json!({"type": "vm_file", "path": r"C:\x.txt", "dest": "/tmp/abs.txt"}), Err("relative file name"))
        .await;
    check(&guest, json!({"type": "vm_file", "multi": true, "path": ["a"], "dest": ["a", "b"]}), Err("1 entries")).await;
    check(&guest, json!({"type": "vm_file", "dest": "x"}), Err("missing parameter `path`")).await;
}

#[tokio::test]
async fn vm_file_time_suffix_renames_both_paths() {
    let guest = start_guest().await;
    let docs = folder(&guest, KnownFolder::Documents).await;
    // The stamp is today's date: the getter and the test may straddle midnight,
    // so push the file under both days' names.
    let stamp_now = || {
        let secs = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap().as_secs();
        let (y, m, d) = arena_shared::calendar::civil_from_days(i64::try_from(secs / 86_400).unwrap());
        format!("{y:04}{m:02}{d:02}")
    };
    let before = stamp_now();
    push(&guest, &format!(r"{docs}\report{before}.csv"), b"a,b").await;
    let getter = json!({"type": "vm_file", "path": format!(r"{docs}\report.csv"), "dest": "report.csv", "time_suffix": true, "time_format": "%Y%m%d"});
    let got = fetch(&guest.ctx, &spec(getter)).await.unwrap();
    let after = stamp_now();
    let expected: Vec<_> =
        [before, after].iter().map(|s| Fetched::File(guest.ctx.work_dir.join(format!("report{s}.csv")))).collect();
    assert!(expected.contains(&got), "{got:?}");
}

#[tokio::test]
async fn file_and_folder_existence() {
    let guest = start_guest().await;
    let docs = folder(&guest, KnownFolder::Documents).await;
    let desktop = folder(&guest, KnownFolder::Desktop).await;
    push(&guest, &format!(r"{docs}\draft.txt"), b"text").await;
    push(&guest, &format!(r"{docs}\empty.txt"), b"").await;
    guest.ctx.client.mkdir(&format!(r"{docs}\MyFolder")).await.unwrap();
    push(&guest, &format!(r"{desktop}\Projects - Shortcut.lnk"), b"L\0\0\0").await;

    let in_folder = |name: &str| json!({"type": "vm_file_exists_in_vm_folder", "folder_name": docs, "file_name": name});
    check(&guest, in_folder("draft.txt"), Ok(Fetched::number(1.0))).await;
    check(&guest, in_folder("absent.txt"), Ok(Fetched::number(0.0))).await;
    // Upstream tests the downloaded bytes' truthiness: an empty file is "missing".
    check(&guest, in_folder("empty.txt"), Ok(Fetched::number(0.0))).await;
    check(&guest, in_folder("MyFolder"), Ok(Fetched::number(0.0))).await;
    check(&guest, in_folder(""), Ok(Fetched::number(0.0))).await;

    let docs_folder = |name: &str| json!({"type": "vm_folder_exists_in_documents", "folder_name": name});
    check(&guest, docs_folder("MyFolder"), Ok(Fetched::Bool(true))).await;
    check(&guest, docs_folder("myfolder"), Ok(Fetched::Bool(true))).await;
    check(&guest, docs_folder("Other"), Ok(Fetched::Bool(false))).await;
    check(&guest, docs_folder("draft.txt"), Ok(Fetched::Bool(false))).await;

    let on_desktop = |name: &str| json!({"type": "vm_file_exists_in_desktop", "file_name": name});
    check(&guest, on_desktop("Projects - Shortcut.lnk"), Ok(Fetched::Bool(true))).await;
    check(&guest, on_desktop("Projects.lnk"), Ok(Fetched::Bool(false))).await;
    check(&guest, json!({"type": "vm_file_exists_in_desktop"}), Err("missing parameter `file_name`")).await;
}

#[cfg(unix)]
#[tokio::test]
async fn vm_command_line_returns_stdout() {
    // Real commands: the stub runs host processes only when told to.
    let guest = start_guest_with(None, |config| config.stub_host_exec = true).await;
    check(
        &guest,
        json!({"type": "vm_command_line", "command": ["sh", "-c", "echo ms-python.python; exit 3"]}),
        Ok(Fetched::Text("ms-python.python\n".into())),
    )
    .await;
    check(
        &guest,
        json!({"type": "vm_command_line", "command": "echo 'two words'"}),
        Ok(Fetched::Text("two words\n".into())),
    )
    .await;
    check(
        &guest,
        json!({"type": "vm_command_line", "command": ["no-such-program-xyz"]}),
        Err("getter vm_command_line"),
    )
    .await;
    check(&guest, json!({"type": "vm_command_line", "command": 5}), Err("string or a list")).await;
}

#[test]
fn command_lines_become_commands_like_upstream() {
    use arena_shared::cmdline::CommandSpec;
    let argv = |w: &[&str]| Ok(CommandSpec::Argv(w.iter().map(|s| (*s).to_owned()).collect()));
    let shell = |line: &str| Ok(CommandSpec::Shell(line.to_owned()));
    let check = |params: Value, want: Result<CommandSpec, &str>| {
        let Value::Object(map) = params.clone() else { panic!() };
        match (super::general::command_spec(&Params::new("vm_command_line", &map)), want) {
            (Ok(got), Ok(want)) => assert_eq!(got, want, "{params}"),
            (Err(err), Err(text)) => assert!(err.to_string().contains(text), "{err}"),
            (got, want) => panic!("{params}: got {got:?}, want {want:?}"),
        }
    };
    check(
        json!({"command": ["cmd", "/c", "code", "--list-extensions", "|", "findstr", "x"]}),
        argv(&["cmd", "/c", "code", "--list-extensions", "|", "findstr", "x"]),
    );
    check(
        json!({"command": "powershell -Command \"Get-TimeZone\""}),
        argv(&["powershell", "-Command", "Get-TimeZone"]),
    );
    check(json!({"command": "dir C:\\x", "shell": true}), shell("dir C:\\x"));
    check(json!({"command": "echo \"a b\" > x.txt", "shell": true}), shell("echo \"a b\" > x.txt"));
    check(json!({"command": ["dir", "C:\\Program Files"], "shell": true}), shell("dir \"C:\\Program Files\""));
    check(json!({"command": "echo 'open"}), Err("does not split"));
    check(json!({"command": []}), Err("empty"));
}

#[tokio::test]
async fn active_window_title_is_the_foreground_window() {
    let guest = start_guest().await;
    guest
        .ctx
        .client
        .launch(&LaunchRequest { shell: None, argv: vec!["notepad".into()] })
        .await
        .expect("launch notepad");
    check(&guest, json!({"type": "vm_active_window_title"}), Ok(Fetched::Text("Untitled - Notepad".into()))).await;
}

#[tokio::test]
async fn wallpaper_is_saved_to_dest() {
    let guest = start_guest().await;
    check(&guest, json!({"type": "vm_wallpaper", "dest": "wall.png"}), Err("no wallpaper")).await;
    let pictures = folder(&guest, KnownFolder::Pictures).await;
    let image = format!(r"{pictures}\space.png");
    push(&guest, &image, b"\x89PNG not really").await;
    let write = RegistryWrite {
        key: r"HKCU\Control Panel\Desktop".into(),
        value: Some("Wallpaper".into()),
        data: RegistryValue::String(image),
    };
    guest.ctx.client.registry_set(&write).await.expect("set wallpaper");
    let path = guest.ctx.work_dir.join("wall.png");
    check(&guest, json!({"type": "vm_wallpaper", "dest": "wall.png"}), Ok(Fetched::File(path.clone()))).await;
    assert_eq!(std::fs::read(path).unwrap(), b"\x89PNG not really");
}

#[tokio::test]
async fn unimplemented_getters_say_so() {
    let guest = start_guest().await;
    assert!(lookup("no_such_getter").is_none());
    let err = fetch(&guest.ctx, &spec(json!({"type": "no_such_getter", "dest": "vlcrc"}))).await.unwrap_err();
    assert!(matches!(err, GetterError::NotImplemented(_)));
    assert_eq!(err.to_string(), "getter no_such_getter is not implemented in this build");
}

/// A one-file HTTP server on `127.0.0.1:0`: `/gold.txt` and `/other.txt` are
/// served, anything else is 404. Counts the requests it answers.
async fn file_server() -> (String, std::sync::Arc<std::sync::atomic::AtomicUsize>, tokio::task::JoinHandle<()>) {
    use std::sync::atomic::{AtomicUsize, Ordering};
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.expect("bind");
    let url = format!("http://{}", listener.local_addr().expect("addr"));
    let hits = std::sync::Arc::new(AtomicUsize::new(0));
    let counter = hits.clone();
    let task = tokio::spawn(async move {
        while let Ok((mut socket, _)) = listener.accept().await {
            counter.fetch_add(1, Ordering::SeqCst);
            let mut request = vec![0u8; 4096];
            let n = socket.read(&mut request).await.unwrap_or(0);
            let head = String::from_utf8_lossy(&request[..n]).to_string();
            let body: Option<&[u8]> = if head.starts_with("GET /gold.txt ") {
                Some(b"gold text\n")
            } else if head.starts_with("GET /other.txt ") {
                Some(b"other")
            } else {
                None
            };
            let response = match body {
                Some(body) => {
                    let mut r =
                        format!("HTTP/1.1 200 OK\r\ncontent-length: {}\r\nconnection: close\r\n\r\n", body.len())
                            .into_bytes();
                    r.extend_from_slice(body);
                    r
                }
                None => b"HTTP/1.1 404 Not Found\r\ncontent-length: 0\r\nconnection: close\r\n\r\n".to_vec(),
            };
            let _ = socket.write_all(&response).await;
            let _ = socket.shutdown().await;
        }
    });
    (url, hits, task)
}

#[tokio::test]
async fn host_file_copies_gold_from_beside_the_task_and_refuses_paths_out_of_it() {
    let guest = start_guest().await;
    let work = guest.ctx.work_dir.clone();
    let task_dir = guest.ctx.task_dir.clone().unwrap();
    std::fs::create_dir_all(task_dir.join("gold")).unwrap();
    std::fs::write(task_dir.join("gold/count.txt"), "3").unwrap();
    check(
        &guest,
        json!({"type": "host_file", "path": "gold/count.txt", "dest": "count_gold.txt"}),
        Ok(Fetched::File(work.join("count_gold.txt"))),
    )
    .await;
    assert_eq!(std::fs::read(work.join("count_gold.txt")).unwrap(), b"3");
    for outside in ["../secret.txt", "/etc/hostname", "gold\\count.txt", ""] {
        check(
            &guest,
            json!({"type": "host_file", "path": outside, "dest": "x.txt"}),
            Err("must be a relative path inside the task file's folder"),
        )
        .await;
    }
    check(&guest, json!({"type": "host_file", "path": "gold/none.txt", "dest": "n.txt"}), Err("none.txt")).await;
    // Nothing of it is in the guest.
    assert!(guest.ctx.client.stat("C:\\arena-gold\\count.txt").await.is_err());
}

#[tokio::test]
async fn cloud_file_downloads_through_the_cache_and_replays_offline() {
    let guest = start_guest().await;
    let work = guest.ctx.work_dir.clone();
    let (url, hits, server) = file_server().await;
    let gold = format!("{url}/gold.txt");

    check(
        &guest,
        json!({"type": "cloud_file", "path": gold, "dest": "gold.txt"}),
        Ok(Fetched::File(work.join("gold.txt"))),
    )
    .await;
    assert_eq!(std::fs::read(work.join("gold.txt")).unwrap(), b"gold text\n");

    let multi = json!({
        "type": "cloud_file", "multi": true,
        "path": [gold, format!("{url}/other.txt")], "dest": ["g2.txt", "o.txt"], "gives": [0, 1],
    });
    check(
        &guest,
        multi.clone(),
        Ok(Fetched::List(vec![Fetched::File(work.join("g2.txt")), Fetched::File(work.join("o.txt"))])),
    )
    .await;
    assert_eq!(std::fs::read(work.join("o.txt")).unwrap(), b"other");

    check(
        &guest,
        json!({"type": "cloud_file", "path": format!("{url}/missing.txt"), "dest": "m.txt"}),
        Err("missing.txt"),
    )
    .await;

    // With the server gone, cached URLs are still served; the cache was asked once per URL.
    server.abort();
    let served = hits.load(std::sync::atomic::Ordering::SeqCst);
    std::fs::remove_file(work.join("gold.txt")).unwrap();
    check(
        &guest,
        json!({"type": "cloud_file", "path": gold, "dest": "gold.txt"}),
        Ok(Fetched::File(work.join("gold.txt"))),
    )
    .await;
    assert_eq!(std::fs::read(work.join("gold.txt")).unwrap(), b"gold text\n");
    check(
        &guest,
        multi,
        Ok(Fetched::List(vec![Fetched::File(work.join("g2.txt")), Fetched::File(work.join("o.txt"))])),
    )
    .await;
    assert_eq!(hits.load(std::sync::atomic::Ordering::SeqCst), served);
}

/// The shape of upstream's notepad task 366de66e: `and` of an existence check
/// and a text comparison against a downloaded gold file.
#[tokio::test]
async fn a_corpus_style_task_evaluates_end_to_end() {
    use crate::{evaluate, LastAction};
    let guest = start_guest().await;
    let (url, _hits, _server) = file_server().await;
    let docs = folder(&guest, KnownFolder::Documents).await;
    let task = json!({
        "id": "t", "instruction": "write it",
        "evaluator": {
            "func": ["exact_match", "compare_text_file"],
            "result": [
                {"type": "vm_file_exists_in_vm_folder", "folder_name": docs, "file_name": "draft.txt"},
                {"type": "vm_file", "path": format!(r"{docs}\draft.txt"), "dest": "draft.txt"}
            ],
            "expected": [
                {"type": "rule", "rules": {"expected": 1.0}},
                {"type": "cloud_file", "path": format!("{url}/gold.txt"), "dest": "draft_gold.txt"}
            ]
        }
    });
    let evaluator =
        arena_task::Task::parse(&task.to_string(), std::path::Path::new("notepad/t.json")).unwrap().evaluator;

    let missing = evaluate(&guest.ctx, &evaluator, Some(&LastAction::Done)).await;
    assert_eq!((missing.score, missing.metrics.len()), (0.0, 1), "{missing:?}");

    push(&guest, &format!(r"{docs}\draft.txt"), b"gold text\r\n").await;
    let right = evaluate(&guest.ctx, &evaluator, Some(&LastAction::Done)).await;
    assert_eq!(right.score, 1.0, "{right:?}");
    assert_eq!(right.metrics.len(), 2);
    assert!(right.error.is_none(), "{right:?}");

    push(&guest, &format!(r"{docs}\draft.txt"), b"gold text, edited\r\n").await;
    let wrong = evaluate(&guest.ctx, &evaluator, Some(&LastAction::Done)).await;
    assert_eq!(wrong.score, 0.0, "{wrong:?}");
    assert_eq!(wrong.metrics.iter().map(|m| m.score).collect::<Vec<_>>(), [1.0, 0.0]);
    let json = serde_json::to_value(&wrong).unwrap();
    assert_eq!(json["metrics"][1]["metric"], "compare_text_file");
}
