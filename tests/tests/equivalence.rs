//! The same agent code run host-side and guest-side gives the same result.
//!
//! An agent's pyautogui code can run in two places: on the host, in the shared
//! interpreter over the guest's `/v1` API (what `arena run` does), or in the guest,
//! through upstream's `/execute` route with `python -c` (what upstream's host does).
//! Both must list a folder in the same order, crop a screenshot region that runs off
//! the screen the same way, and hand a shell line with quotes to the shell unchanged.
//! This test runs one program both ways against the real stub guest and compares
//! what it printed and the files it saved, pixel for pixel.

use std::time::Duration;

use arena_host::agent::exec::{execute_with, ExecOptions};
use arena_host::agent::AgentAction;
use arena_host::{ClientConfig, GuestClient};
use arena_shared::script::ComputerState;
use arena_test_support::Served;
use serde_json::{json, Value};

const FOLDER: &str = r"C:\Users\Docker\Desktop\eq";

/// The program, saving its screenshot under a name of its own for each side.
fn program(side: &str) -> String {
    format!(
        r#"import os, subprocess, pyautogui
print(os.listdir(r'{FOLDER}'))
r = subprocess.run('echo "a  b" \'c d\'', shell=True, stdout=subprocess.PIPE, text=True)
print(repr(r.stdout), r.returncode)
pyautogui.screenshot(r'{FOLDER}\shot_{side}.png', region=(1400, 870, 80, 40))
print(os.path.exists(r'{FOLDER}\shot_{side}.png'), pyautogui.size())
"#
    )
}

/// Runs the program through upstream's `/execute` route: the guest's interpreter.
async fn guest_side(base: &str) -> String {
    let http = reqwest::Client::builder().timeout(Duration::from_secs(60)).build().expect("http");
    let body = json!({"command": ["python", "-c", program("guest")], "shell": false});
    let res = http.post(format!("{base}/execute")).json(&body).send().await.expect("execute");
    assert_eq!(res.status(), 200);
    let answer: Value = res.json().await.expect("json");
    assert_eq!(answer["returncode"], 0, "{answer}");
    answer["output"].as_str().expect("output").to_owned()
}

/// Runs the program on the host, as an agent's pyautogui action.
async fn host_side(client: &GuestClient) -> String {
    let mut computer = ComputerState::for_screen(1440, 900);
    let action = AgentAction::Pyautogui(program("host"));
    let outcome =
        execute_with(client, &action, None, &mut computer, &ExecOptions::instant()).await.expect("guest reachable");
    assert_eq!(outcome.error, None, "{outcome:?}");
    outcome.stdout
}

#[tokio::test]
async fn agent_code_gives_the_same_result_on_the_host_and_in_the_guest() {
    let guest = Served::guest(&[]).expect("guest starts");
    let client =
        GuestClient::new(&guest.url, ClientConfig { token: None, timeout: Duration::from_secs(30), retries: 1 })
            .expect("client");
    // Names whose NTFS order differs from a lowercase or ordinal sort.
    for name in ["b.txt", "_notes.txt", "Zebra.txt", "apple.txt", "A.md", "éclair.txt"] {
        client.push_file(&format!(r"{FOLDER}\{name}"), name.as_bytes().to_vec(), Some(true)).await.expect("push");
    }

    let in_guest = guest_side(&guest.url).await;
    // The host's run lists the folder after the guest's screenshot landed in it, so
    // take that file out again to compare like with like.
    let guest_shot = client.pull_file(&format!(r"{FOLDER}\shot_guest.png")).await.expect("guest screenshot").bytes;
    client.delete(&format!(r"{FOLDER}\shot_guest.png"), false).await.expect("delete");
    let on_host = host_side(&client).await;
    let host_shot = client.pull_file(&format!(r"{FOLDER}\shot_host.png")).await.expect("host screenshot").bytes;

    let expected_listing = "['A.md', 'apple.txt', 'b.txt', 'Zebra.txt', '_notes.txt', 'éclair.txt']";
    let expected_shell = "'a  b c d\\n' 0";
    let expected = format!("{expected_listing}\n{expected_shell}\nTrue Size(width=1440, height=900)\n");
    assert_eq!(in_guest, expected, "guest side");
    assert_eq!(on_host, expected, "host side");

    let decode = |bytes: &[u8]| image::load_from_memory(bytes).expect("png").to_rgba8();
    let (from_guest, from_host) = (decode(&guest_shot), decode(&host_shot));
    assert_eq!(from_guest.dimensions(), (80, 40), "the region's size, though it runs off the screen");
    assert_eq!(from_guest.as_raw(), from_host.as_raw(), "the same pixels from both sides");
    // The part off the 1440x900 screen is black, as Pillow pads it.
    assert_eq!(from_guest.get_pixel(79, 39).0, [0, 0, 0, 255]);
    assert_eq!(from_guest.get_pixel(45, 35).0, [0, 0, 0, 255]);
}
