//! Replays the upstream WAA host's call sequence for one episode (waa-api.md §b.5)
//! against the real `arena-guest` binary, speaking HTTP exactly as the Python
//! host does: JSON bodies, urlencoded forms and multipart uploads.
//!
//! The task is the corpus's notepad task a7d4b6c5 (count "example" in a file and
//! save the count); the agent's work is played by uploads a scripted agent makes.

use std::time::Duration;

use arena_test_support::Served;
use base64::Engine;
use serde_json::{json, Value};

const DOCS: &str = r"C:\Users\Docker\Documents";

fn http() -> reqwest::Client {
    reqwest::Client::builder().timeout(Duration::from_secs(60)).build().expect("client")
}

async fn post_json(client: &reqwest::Client, url: &str, body: Value) -> (u16, String) {
    let res = client.post(url).json(&body).send().await.expect("request");
    (res.status().as_u16(), res.text().await.expect("body"))
}

async fn upload(client: &reqwest::Client, base: &str, guest_path: &str, bytes: Vec<u8>) -> (u16, String) {
    let name = guest_path.rsplit('\\').next().unwrap_or("file").to_owned();
    let form = reqwest::multipart::Form::new()
        .text("file_path", guest_path.to_owned())
        .part("file_data", reqwest::multipart::Part::bytes(bytes).file_name(name));
    let res = client.post(format!("{base}/setup/upload")).multipart(form).send().await.expect("upload");
    (res.status().as_u16(), res.text().await.expect("body"))
}

#[tokio::test]
async fn upstream_host_sequence_for_one_episode() {
    let guest = Served::guest(&["--stub-host-exec"]).expect("guest starts");
    let base = guest.url.clone();
    let client = http();

    // run.py: readiness polling.
    let res = client.get(format!("{base}/probe")).send().await.unwrap();
    assert_eq!(res.status(), 200);
    let probe: Value = res.json().await.unwrap();
    assert_eq!(probe["status"], "Probe successful");

    // env.reset(): close_all, probe, clear_task_files.
    let (status, text) = post_json(&client, &format!("{base}/setup/close_all"), json!({})).await;
    assert_eq!((status, text.as_str()), (200, "All windows closed successfully."));
    let (status, text) = post_json(&client, &format!("{base}/setup/clear_task_files"), json!({})).await;
    assert_eq!(status, 200, "{text}");
    assert!(text.contains("Downloads"), "{text}");

    // SetupController.setup(config): the `download` step uploads what the host fetched.
    let largefile = "an example line\nanother example\nno match here\nexample again\n".repeat(50);
    let (status, text) =
        upload(&client, &base, &format!(r"{DOCS}\largefile.txt"), largefile.clone().into_bytes()).await;
    assert_eq!((status, text.as_str()), (200, "File Uploaded"));
    // A `launch` step as the corpus writes them.
    let (status, text) =
        post_json(&client, &format!("{base}/setup/launch"), json!({"command": ["notepad"], "shell": false})).await;
    assert_eq!((status, text.as_str()), (200, "['notepad'] launched successfully"));

    // _get_obs(): accessibility tree (uia) and obs_winagent.
    let res = client.get(format!("{base}/accessibility?backend=uia")).send().await.unwrap();
    assert_eq!(res.status(), 200);
    let at: Value = res.json().await.unwrap();
    let xml = at["AT"].as_str().expect("AT is a string");
    assert!(xml.starts_with("<desktop "), "{}", &xml[..xml.len().min(200)]);
    assert!(xml.contains(r#"xmlns:st="uri:deskat:state.at-spi.gnome.org""#));
    assert!(xml.contains(r#"name="Untitled - Notepad""#), "the launched notepad is in the tree");

    let res = client.get(format!("{base}/obs_winagent")).send().await.unwrap();
    assert_eq!(res.status(), 200);
    let obs: Value = res.json().await.unwrap();
    assert_eq!(obs["status"], "success");
    assert_eq!(obs["window_title"], "Untitled - Notepad");
    assert!(obs["window_names_str"].as_str().unwrap().lines().any(|l| l == "Untitled - Notepad"));
    assert!(obs["computer_clipboard"].is_null(), "no /update_computer yet");
    let png = base64::engine::general_purpose::STANDARD.decode(obs["image"].as_str().unwrap()).unwrap();
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");

    // One agent step: /update_computer, then the action channel.
    let screenshot = base64::engine::general_purpose::STANDARD.encode(&png);
    let (status, text) = post_json(
        &client,
        &format!("{base}/update_computer"),
        json!({"rects": [[0, 0, 100, 40]], "window_rect": [0, 0, 1440, 900], "screenshot": screenshot,
               "scale": [1.0, 1.0], "clipboard_content": null, "swap_ctrl_alt": false}),
    )
    .await;
    assert_eq!(status, 200, "{text}");
    assert_eq!(serde_json::from_str::<Value>(&text).unwrap(), json!({"success": true}));

    // The scripted agent's work: it writes the answer file (as typing and Ctrl+S would).
    let count = largefile.matches("example").count();
    let (status, _) =
        upload(&client, &base, &format!(r"{DOCS}\example_count.txt"), count.to_string().into_bytes()).await;
    assert_eq!(status, 200);

    // evaluator.postconfig: open both files, activate one strictly.
    for name in ["largefile.txt", "example_count.txt"] {
        let (status, text) =
            post_json(&client, &format!("{base}/setup/open_file"), json!({"path": format!(r"{DOCS}\{name}")})).await;
        assert_eq!((status, text.as_str()), (200, "File opened successfully"));
    }
    let (status, text) = post_json(
        &client,
        &format!("{base}/setup/activate_window"),
        json!({"window_name": "largefile.txt - Notepad", "strict": true}),
    )
    .await;
    assert_eq!((status, text.as_str()), (200, "Window activated successfully"));
    let obs: Value = client.get(format!("{base}/obs_winagent")).send().await.unwrap().json().await.unwrap();
    assert_eq!(obs["window_title"], "largefile.txt - Notepad");

    // The `execute` postconfig step with the corpus's string-`"true"` shell flag.
    let (status, text) =
        post_json(&client, &format!("{base}/setup/execute"), json!({"command": "echo saved", "shell": "true"})).await;
    assert_eq!(status, 200, "{text}");
    let out: Value = serde_json::from_str(&text).unwrap();
    assert_eq!(out["status"], "success");
    assert_eq!(out["output"], "saved\n");
    assert_eq!(out["returncode"], 0);

    // The vm_file getter: POST /file with an urlencoded form.
    let res = client
        .post(format!("{base}/file"))
        .form(&[("file_path", format!(r"{DOCS}\example_count.txt"))])
        .send()
        .await
        .unwrap();
    assert_eq!(res.status(), 200);
    assert_eq!(res.text().await.unwrap(), count.to_string());
    // A missing file is the getter's "None".
    let res = client.post(format!("{base}/file")).form(&[("file_path", r"C:\nope.txt")]).send().await.unwrap();
    assert_eq!(res.status(), 404);

    // Next reset closes the task's windows again.
    let (status, _) = post_json(&client, &format!("{base}/setup/close_all"), json!({})).await;
    assert_eq!(status, 200);
    let obs: Value = client.get(format!("{base}/obs_winagent")).send().await.unwrap().json().await.unwrap();
    assert_eq!(obs["window_title"], "Desktop", "only Program Manager is left");
}
