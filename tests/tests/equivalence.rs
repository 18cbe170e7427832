//! The same agent code run host-side and guest-side gives the same result.
//!
//! An agent's pyautogui code can run with its effects in two places: on the host, in
//! the shared interpreter over the guest's `/v1` API (what `arena run
//! the default does), or in the guest, through upstream's `/execute` route
//! with `python -c` (what upstream's host does).
//! Both must list a folder in the same order, crop a screenshot region that runs off
//! the screen the same way, and hand a shell line with quotes to the shell unchanged.
//! The first test runs one program both ways against the real stub guest and compares
//! what it printed and the files it saved, pixel for pixel and byte for byte.
//!
//! The behaviours composed of script-host primitives (`arena_script::compose`)
//! are each run on both sides: `window_titles` (`pyautogui.getAllTitles()`),
//! `os_version` (`platform.version()`) and `save_screenshot` (a PNG and a JPEG) in the
//! first test; `open_program` and `switch_to_window` (Navi's `computer.os` and
//! `computer.window_manager`, through upstream's `/execute_windows` in the guest) in the
//! second, on two fresh guests whose windows are compared afterwards.

use std::time::Duration;

use arena_client::{ClientConfig, GuestClient};
use arena_exec::AgentAction;
use arena_exec::{execute_with, ExecOptions, PyautoguiPolicy};
use arena_script::ComputerState;
use arena_shared::exec::LaunchRequest;
use arena_shared::observation::WindowTarget;
use arena_test_support::Served;
use serde_json::{json, Value};

const FOLDER: &str = r"C:\Users\Docker\Desktop\eq";

/// The program, saving its screenshot under a name of its own for each side.
fn program(side: &str) -> String {
    format!(
        r#"import os, subprocess, platform, pyautogui
print(os.listdir(r'{FOLDER}'))
r = subprocess.run('echo "a  b" \'c d\'', shell=True, stdout=subprocess.PIPE, text=True)
print(repr(r.stdout), r.returncode)
pyautogui.screenshot(r'{FOLDER}\shot_{side}.png', region=(1400, 870, 80, 40))
pyautogui.screenshot(region=(0, 0, 320, 200)).save(r'{FOLDER}\full_{side}.jpg')
print(os.path.exists(r'{FOLDER}\shot_{side}.png'), pyautogui.size())
print(pyautogui.getAllTitles(), platform.version())
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

/// Runs the program on the host, as an agent's pyautogui action with its effects.
async fn host_side(client: &GuestClient) -> String {
    let mut computer = ComputerState::for_screen(1440, 900);
    let action = AgentAction::Pyautogui(program("host").into());
    let options = ExecOptions { pyautogui: PyautoguiPolicy::Effects, ..ExecOptions::instant() };
    let outcome = execute_with(client, &action, None, &mut computer, &options).await.expect("guest reachable");
    assert_eq!(outcome.error, None, "{outcome:?}");
    outcome.stdout
}

fn client_of(guest: &Served) -> GuestClient {
    GuestClient::new(&guest.url, ClientConfig { token: None, timeout: Duration::from_secs(30), retries: 1 })
        .expect("client")
}

#[tokio::test]
async fn agent_code_gives_the_same_result_on_the_host_and_in_the_guest() {
    let guest = Served::guest(&["--stub-host-exec"]).expect("guest starts");
    let client = client_of(&guest);
    // Names whose NTFS order differs from a lowercase or ordinal sort.
    for name in ["b.txt", "_notes.txt", "Zebra.txt", "apple.txt", "A.md", "éclair.txt"] {
        client.push_file(&format!(r"{FOLDER}\{name}"), name.as_bytes().to_vec(), Some(true)).await.expect("push");
    }
    // Two windows of one title, one of them minimised, and a third in front: the list
    // names each title once, minimised windows included, topmost first.
    for program in ["notepad", "notepad", "calc"] {
        client
            .launch(&LaunchRequest::new(arena_shared::cmdline::CommandSpec::Shell(program.into())))
            .await
            .expect("launch");
    }
    let notepad = client.windows().await.expect("windows").into_iter().find(|w| w.title == "Untitled - Notepad");
    let target = WindowTarget { id: notepad.map(|w| w.id), title: None };
    client.minimize_window(&target).await.expect("minimise");

    let in_guest = guest_side(&guest.url).await;
    // The host's run lists the folder after the guest's screenshots landed in it, so
    // take those files out again to compare like with like.
    let guest_shot = client.pull_file(&format!(r"{FOLDER}\shot_guest.png")).await.expect("guest screenshot").bytes;
    let guest_jpeg = client.pull_file(&format!(r"{FOLDER}\full_guest.jpg")).await.expect("guest JPEG").bytes;
    for name in ["shot_guest.png", "full_guest.jpg"] {
        client.delete(&format!(r"{FOLDER}\{name}"), false).await.expect("delete");
    }
    let on_host = host_side(&client).await;
    let host_shot = client.pull_file(&format!(r"{FOLDER}\shot_host.png")).await.expect("host screenshot").bytes;
    let host_jpeg = client.pull_file(&format!(r"{FOLDER}\full_host.jpg")).await.expect("host JPEG").bytes;

    let expected_listing = "['A.md', 'apple.txt', 'b.txt', 'Zebra.txt', '_notes.txt', 'éclair.txt']";
    let expected_shell = "'a  b c d\\n' 0";
    let expected_titles = "['Calculator', 'Untitled - Notepad', 'Program Manager'] 10.0.22631";
    let expected =
        format!("{expected_listing}\n{expected_shell}\nTrue Size(width=1440, height=900)\n{expected_titles}\n");
    assert_eq!(in_guest, expected, "guest side");
    assert_eq!(on_host, expected, "host side");

    let decode = |bytes: &[u8]| image::load_from_memory(bytes).expect("image").to_rgba8();
    let (from_guest, from_host) = (decode(&guest_shot), decode(&host_shot));
    assert_eq!(from_guest.dimensions(), (80, 40), "the region's size, though it runs off the screen");
    assert_eq!(from_guest.as_raw(), from_host.as_raw(), "the same pixels from both sides");
    // The part off the 1440x900 screen is black, as Pillow pads it.
    assert_eq!(from_guest.get_pixel(79, 39).0, [0, 0, 0, 255]);
    assert_eq!(from_guest.get_pixel(45, 35).0, [0, 0, 0, 255]);
    // `.jpg` is JPEG on both sides (Pillow's format from the extension), from one encoder.
    assert_eq!(image::guess_format(&guest_jpeg).expect("format"), image::ImageFormat::Jpeg);
    assert_eq!(decode(&guest_jpeg).dimensions(), (320, 200));
    assert_eq!(guest_jpeg, host_jpeg, "the same JPEG bytes from both sides");
}

/// Navi's code that opens a program and switches back to another window.
const COMPUTER_CODE: [&str; 2] =
    ["computer.os.open_program('notepad')", "computer.window_manager.switch_to_application('Calculator')"];

/// What a reader of the desktop sees of its windows, topmost first.
async fn window_state(client: &GuestClient) -> Vec<(String, bool, bool, bool)> {
    let mut windows = client.windows().await.expect("windows");
    windows.sort_by_key(|w| w.z_order);
    windows.into_iter().filter(|w| w.visible).map(|w| (w.title, w.focused, w.maximized, w.minimized)).collect()
}

/// A fresh guest with Calculator open, as both sides start.
async fn calculator_desktop() -> (Served, GuestClient) {
    let guest = Served::guest(&["--stub-host-exec"]).expect("guest starts");
    let client = client_of(&guest);
    client.launch(&LaunchRequest::new(arena_shared::cmdline::CommandSpec::Shell("calc".into()))).await.expect("calc");
    (guest, client)
}

#[tokio::test]
async fn computer_behaviours_leave_the_same_desktop_from_the_host_and_from_the_guest() {
    // Guest side: upstream's `/execute_windows`, the guest's own interpreter.
    let (guest, guest_client) = calculator_desktop().await;
    let http = reqwest::Client::builder().timeout(Duration::from_secs(60)).build().expect("http");
    // Navi sets the computer up before its first action; no elements, the whole screen.
    let shot =
        arena_shared::imaging::encode(&image::RgbaImage::new(4, 4), arena_shared::observation::ImageFormat::Png, 0)
            .expect("png");
    let update = json!({
        "rects": [], "window_rect": [0, 0, 1440, 900], "scale": [1.0, 1.0],
        "screenshot": base64::Engine::encode(&base64::engine::general_purpose::STANDARD, shot),
        "clipboard_content": null, "swap_ctrl_alt": false,
    });
    let res = http.post(format!("{}/update_computer", guest.url)).json(&update).send().await.expect("update_computer");
    assert_eq!(res.status(), 200);
    for code in COMPUTER_CODE {
        let res = http.post(format!("{}/execute_windows", guest.url)).json(&json!({"command": code})).send().await;
        let answer: Value = res.expect("execute_windows").json().await.expect("json");
        assert_eq!(answer, json!({"status": "success"}), "{code}");
    }
    let in_guest = window_state(&guest_client).await;

    // Host side: the same code as Navi actions run by `arena run`.
    let (_host_guest, host_client) = calculator_desktop().await;
    let mut computer = ComputerState::for_screen(1440, 900);
    for code in COMPUTER_CODE {
        let action = AgentAction::Computer(code.into());
        let outcome = execute_with(&host_client, &action, None, &mut computer, &ExecOptions::instant())
            .await
            .expect("guest reachable");
        assert_eq!(outcome.error, None, "{code}: {outcome:?}");
    }
    let on_host = window_state(&host_client).await;

    assert_eq!(in_guest, on_host, "the same windows in the same states");
    let front = &on_host[0];
    assert_eq!((front.0.as_str(), front.1, front.2), ("Calculator", true, true), "switched to and maximised");
    assert!(on_host.iter().any(|w| w.0 == "Untitled - Notepad"), "notepad was opened: {on_host:?}");
}
