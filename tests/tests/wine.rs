//! The Windows backend for real: the cross-built `arena-guest.exe` under Wine,
//! driven over loopback by the real host client (and raw HTTP for the WAA routes).
//!
//! `scripts/wine-test.sh` prepares everything (Xvfb, a private Wine prefix with the
//! `bcryptprimitives.dll` shim, the cross build) and runs this test with
//! `ARENA_WINDOWS_EXE` set. Without it the test prints a loud `SKIPPED:` line and
//! passes, unless `ARENA_REQUIRE_WINE=1`, which turns a skip into a failure (CI sets it).
//!
//! One guest serves all the steps, in order, to keep the suite fast; each step says
//! what it checks. The last step prints measured figures as `BENCH:` lines.
//!
//! The input catalogue (`arena-inputcheck`) runs as a test of its own against the
//! cross-built recorder (`arena-input-recorder.exe`, beside the guest's exe), as
//! `arena doctor --input` runs it; it and the backend's steps take turns at the
//! desktop ([`DESKTOP`]), since the recorder's window covers the screen.

use std::time::{Duration, Instant};

use arena_client::client::{ClientConfig, GuestClient};
use arena_shared::action::{Action, ActionBatch, MouseButton};
use arena_shared::clipboard::ClipboardContent;
use arena_shared::exec::{ExecRequest, LaunchRequest};
use arena_shared::health::Component;
use arena_shared::observation::{A11yBackend, A11yNode, A11yQuery, ScreenshotQuery, WindowInfo, WindowTarget};
use arena_shared::registry::{RegistryValue, RegistryWrite};
use arena_test_support::{eventually, wine_or_skip, Served, WineSetup};
use base64::Engine;

/// Held by a test while it drives the desktop's input: the test harness runs tests
/// on threads of their own, and one test's clicks must not land in another's window.
static DESKTOP: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

/// Finds Wine and the exe, or says loudly why the suite cannot run.
fn setup() -> Option<WineSetup> {
    wine_or_skip("the Wine suite")
}

fn start(setup: &WineSetup, backend: &str) -> Served {
    let exe = setup.exe.to_str().expect("UTF-8 exe path");
    let args = [exe, "--backend", backend, "--port", "0", "--open-settle-ms", "0", "--activate-settle-ms", "0"];
    Served::start(&setup.wine, &args, None)
        .unwrap_or_else(|err| panic!("starting the {backend} guest under Wine: {err:#}"))
}

fn client(url: &str) -> GuestClient {
    GuestClient::new(url, ClientConfig { token: None, timeout: Duration::from_secs(30), retries: 1 })
        .expect("valid url")
}

fn find<'a>(node: &'a A11yNode, pred: &dyn Fn(&A11yNode) -> bool) -> Option<&'a A11yNode> {
    if pred(node) {
        return Some(node);
    }
    node.children.iter().find_map(|child| find(child, pred))
}

fn notepads(windows: &[WindowInfo]) -> Vec<WindowInfo> {
    windows.iter().filter(|w| w.visible && w.title.contains("Notepad")).cloned().collect()
}

/// The edit control's value of notepad window `id`, read through the win32 tree.
async fn notepad_text(client: &GuestClient, id: u64) -> Option<String> {
    let tree = client.a11y(&A11yQuery { backend: A11yBackend::Win32, ..A11yQuery::default() }).await.ok()?;
    let window = tree.windows.iter().find(|w| w.window_id == Some(id))?;
    let edit = find(window, &|n| n.role == "Edit")?;
    edit.value.as_ref().map(|v| v.replace("\r\n", "\n"))
}

/// A new notepad window: launches one and waits for the window that was not there before.
async fn launch_notepad(client: &GuestClient) -> WindowInfo {
    let before: Vec<u64> = notepads(&client.windows().await.unwrap()).iter().map(|w| w.id).collect();
    client.launch(&LaunchRequest { shell: None, argv: vec!["notepad".into()] }).await.expect("launch notepad");
    eventually("a new notepad window", Duration::from_secs(20), || async {
        let windows = client.windows().await.ok()?;
        notepads(&windows).into_iter().find(|w| !before.contains(&w.id))
    })
    .await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn windows_backend_under_wine() {
    let Some(setup) = setup() else {
        return;
    };
    let _desktop = DESKTOP.lock().await;
    let suite_started = Instant::now();

    // 1. The exe serves at all under Wine: the stub backend, reached by the host client.
    {
        let stub = start(&setup, "stub");
        let health = client(&stub.url).health().await.expect("stub health under Wine");
        assert_eq!(health.backend, "stub");
    }

    let guest = start(&setup, "windows");
    let c = client(&guest.url);
    let http = reqwest::Client::new();

    // 2. Health: the Windows backend, in an interactive session, with its parts up.
    let health = c.health().await.expect("health");
    assert_eq!(health.backend, "windows");
    assert!(matches!(health.session_id, Some(s) if s != 0), "session {:?}", health.session_id);
    for part in [Component::Input, Component::Accessibility, Component::Clipboard, Component::Files, Component::Exec] {
        assert!(health.is_up(part), "{part:?} is down: {:?}", health.components);
    }
    // Wine has no UI Automation: its stage is down, and says so (not a timeout).
    let uia = health.components.iter().find(|s| s.component == Component::Uia).expect("the uia stage");
    assert!(!uia.ok && uia.detail.contains("UI Automation is not available"), "{uia:?}");

    let screen = c.screen().await.expect("screen");
    assert!(screen.physical_width >= 640 && screen.physical_height >= 480, "{screen:?}");
    assert!(screen.monitors.iter().any(|m| m.primary), "{screen:?}");

    // 3. A started notepad shows in the window list and in a non-black screenshot.
    let first = launch_notepad(&c).await;
    assert_eq!(first.process_name.to_lowercase(), "notepad.exe");
    assert_eq!(first.class_name, "Notepad");
    assert!(first.process_id != 0 && !first.minimized);
    let shot = c.screenshot(&ScreenshotQuery::default()).await.expect("screenshot");
    assert!(!shot.meta.black_frame, "the screenshot is black");
    assert_eq!((shot.meta.width, shot.meta.height), (shot.meta.physical_width, shot.meta.physical_height));
    let img = arena_guest::imaging::decode(&shot.bytes).expect("a decodable PNG");
    let inside = first.rect.center();
    assert_eq!(
        img.get_pixel(inside.x as u32, inside.y as u32).0[..3],
        [255, 255, 255],
        "notepad's white edit area is not in the screenshot at {inside:?}"
    );

    // 4. A click lands where asked, and typed Unicode text reaches notepad's edit control.
    let target = first.rect.center();
    let report = c
        .act_one(Action::Click { x: Some(target.x), y: Some(target.y), button: MouseButton::Left, count: 1 })
        .await
        .expect("click");
    assert_eq!(report.cursor, target, "the cursor is not where the click was asked");
    let text = "Hello from arena ü€ 😀\nsecond line";
    c.act(&ActionBatch { actions: vec![Action::TypeText { text: text.into(), interval_ms: None }] })
        .await
        .expect("type");
    eventually("the typed text in notepad's edit control", Duration::from_secs(10), || async {
        notepad_text(&c, first.id).await.filter(|t| t == text)
    })
    .await;

    // 5. The clipboard: text set here is pasted by notepad (another process).
    let pasted = "pasted through the clipboard";
    c.clipboard_set(&ClipboardContent::Text { text: pasted.into() }).await.expect("clipboard set");
    assert_eq!(c.clipboard_get().await.expect("clipboard get"), ClipboardContent::Text { text: pasted.into() });
    c.act(&ActionBatch {
        actions: vec![
            Action::Hotkey { keys: vec!["ctrl".into(), "a".into()] },
            Action::Hotkey { keys: vec!["ctrl".into(), "v".into()] },
        ],
    })
    .await
    .expect("select all and paste");
    eventually("notepad to hold the pasted text", Duration::from_secs(10), || async {
        notepad_text(&c, first.id).await.filter(|t| t == pasted)
    })
    .await;

    // Named keys go by virtual key and scan code: End, then three Backspaces.
    c.act(&ActionBatch {
        actions: vec![
            Action::KeyPress { key: "end".into(), presses: 1 },
            Action::KeyPress { key: "backspace".into(), presses: 3 },
        ],
    })
    .await
    .expect("end and backspace");
    let shortened = &pasted[..pasted.len() - 3];
    eventually("three characters deleted", Duration::from_secs(10), || async {
        notepad_text(&c, first.id).await.filter(|t| t == shortened)
    })
    .await;

    // ... and an image set here is read back by a second guest process.
    let (small, _) = arena_guest::imaging::downscale_to_fit(img.clone(), 48);
    let png = arena_guest::imaging::encode(&small, arena_shared::observation::ImageFormat::Png, 90).expect("encode");
    let image = ClipboardContent::Image {
        width: small.width(),
        height: small.height(),
        png_base64: base64::engine::general_purpose::STANDARD.encode(&png),
    };
    c.clipboard_set(&image).await.expect("clipboard set image");
    {
        let other = start(&setup, "windows");
        match client(&other.url).clipboard_get().await.expect("clipboard get from a second process") {
            ClipboardContent::Image { width, height, png_base64 } => {
                assert_eq!((width, height), (small.width(), small.height()));
                let back = arena_guest::imaging::decode(
                    &base64::engine::general_purpose::STANDARD.decode(png_base64).unwrap(),
                )
                .unwrap();
                assert_eq!(back.as_raw(), small.as_raw(), "the image changed on its way through the clipboard");
            }
            other => panic!("the second process read {other:?} instead of the image"),
        }
    }

    // 6. The win32 tree has notepad's edit control with its text.
    let tree = c.a11y(&A11yQuery { backend: A11yBackend::Win32, ..A11yQuery::default() }).await.expect("win32 tree");
    let window = tree.windows.iter().find(|w| w.window_id == Some(first.id)).expect("notepad in the win32 tree");
    let edit = find(window, &|n| n.class_name == "Edit").expect("an Edit child");
    assert_eq!(edit.value.as_deref(), Some(shortened));
    assert!(edit.rect.is_some_and(|r| !r.is_empty()));

    // 6b. pyautogui code sent to /execute as `python -c` runs natively (no Python in the
    // prefix) and its hotkey and typewrite reach notepad; then the text is put back.
    c.activate_window(&WindowTarget { id: Some(first.id), title: None }).await.expect("activate the first notepad");
    for typed in ["typed by pyautogui", shortened] {
        let code = format!("import pyautogui; import time; pyautogui.FAILSAFE = False; pyautogui.hotkey('ctrl', 'a'); pyautogui.typewrite('{typed}')");
        let answer: serde_json::Value = http
            .post(format!("{}/execute", guest.url))
            .json(&serde_json::json!({"command": ["python", "-c", code], "shell": false}))
            .send()
            .await
            .expect("POST /execute")
            .json()
            .await
            .expect("JSON answer");
        assert_eq!((answer["status"].as_str(), answer["returncode"].as_i64()), (Some("success"), Some(0)), "{answer}");
        eventually("notepad to hold the text pyautogui typed", Duration::from_secs(10), || async {
            notepad_text(&c, first.id).await.filter(|t| t == typed)
        })
        .await;
    }

    // 6c. A call whose client goes away stops: a slow type_text abandoned after 1.2 s
    // types no more keys into notepad (the keys used to keep arriving for the whole text).
    c.act(&ActionBatch { actions: vec![Action::Hotkey { keys: vec!["ctrl".into(), "a".into()] }] })
        .await
        .expect("select all");
    let impatient = reqwest::Client::builder().timeout(Duration::from_millis(1200)).build().expect("client");
    let slow = serde_json::json!({"actions": [{"type": "type_text", "text": "0123456789", "interval_ms": 500}]});
    let abandoned = impatient.post(format!("{}/v1/actions", guest.url)).json(&slow).send().await;
    assert!(abandoned.is_err(), "the client gave up before the typing could finish: {abandoned:?}");
    let at_abort = notepad_text(&c, first.id).await.unwrap_or_default().chars().count();
    tokio::time::sleep(Duration::from_millis(2500)).await;
    let later = notepad_text(&c, first.id).await.unwrap_or_default();
    assert!(
        later.chars().count() <= at_abort + 1,
        "typing went on after the call was abandoned: {at_abort} -> {later:?}"
    );
    assert!(later.chars().count() < 10, "the whole text arrived: {later:?}");
    c.act(&ActionBatch {
        actions: vec![
            Action::Hotkey { keys: vec!["ctrl".into(), "a".into()] },
            Action::TypeText { text: shortened.into(), interval_ms: None },
        ],
    })
    .await
    .expect("put the text back");
    eventually("notepad to hold its text again", Duration::from_secs(10), || async {
        notepad_text(&c, first.id).await.filter(|t| t == shortened)
    })
    .await;

    // 6d. Deleting or recycling a drive root (Wine maps Z: to the host's /) is refused.
    for root in [r"C:\", r"Z:\"] {
        let err = c.delete(root, true).await.expect_err("a drive root is never deleted");
        assert_eq!(err.status(), Some(403), "{root}: {err}");
    }

    // 7. Activation changes the foreground; close closes an (unmodified) window.
    let second = launch_notepad(&c).await;
    eventually("the new notepad in the foreground", Duration::from_secs(10), || async {
        c.windows().await.ok()?.into_iter().find(|w| w.id == second.id && w.focused)
    })
    .await;
    let activated = c.activate_window(&WindowTarget { id: Some(first.id), title: None }).await.expect("activate");
    assert_eq!(activated.id, first.id);
    let listed = c.windows().await.unwrap();
    assert!(listed.iter().any(|w| w.id == first.id && w.focused), "the activated window is not the foreground");
    assert!(listed.iter().all(|w| w.id != second.id || !w.focused));
    // Minimise and restore change the window's state as the list reports it.
    let target = WindowTarget { id: Some(second.id), title: None };
    c.minimize_window(&target).await.expect("minimize");
    eventually("the window to be minimised", Duration::from_secs(5), || async {
        c.windows().await.ok()?.into_iter().find(|w| w.id == second.id && w.minimized)
    })
    .await;
    c.restore_window(&target).await.expect("restore");
    eventually("the window to be restored", Duration::from_secs(5), || async {
        c.windows().await.ok()?.into_iter().find(|w| w.id == second.id && !w.minimized)
    })
    .await;
    // Upstream's strict activation: minimise, restore, and the window must be in front.
    let strict = http
        .post(format!("{}/setup/activate_window", guest.url))
        .json(&serde_json::json!({"window_name": "notepad", "strict": true}))
        .send()
        .await
        .unwrap();
    assert_eq!(strict.status(), 200, "{}", strict.text().await.unwrap_or_default());
    c.close_window(&target).await.expect("close");
    eventually("the closed window to be gone", Duration::from_secs(10), || async {
        let windows = c.windows().await.ok()?;
        (!windows.iter().any(|w| w.id == second.id && w.visible)).then_some(())
    })
    .await;

    // 8. exec: output and exit codes, and a timeout that kills the whole process tree.
    let run = |argv: &[&str], timeout_ms: u64| ExecRequest {
        shell: None,
        argv: argv.iter().map(|s| (*s).to_owned()).collect(),
        timeout_ms: Some(timeout_ms),
        max_output_bytes: None,
        cwd: None,
        stdin: None,
    };
    let hi = c.exec(&run(&["cmd", "/c", "echo hi"], 20_000)).await.expect("exec echo");
    assert_eq!((hi.exit_code, hi.stdout.as_str()), (Some(0), "hi\n"));
    let three = c.exec(&run(&["cmd", "/c", "exit 3"], 20_000)).await.expect("exec exit 3");
    assert_eq!(three.exit_code, Some(3));
    let hung = c.exec(&run(&["cmd", "/c", "ping -n 30 127.0.0.1"], 1_000)).await.expect("exec hung");
    assert!(hung.timed_out && hung.exit_code.is_none(), "{hung:?}");
    assert!(hung.duration_ms < 8_000, "the timeout took {} ms", hung.duration_ms);
    // `start /wait notepad` makes notepad a grandchild: it must die with the job.
    let count = || async { notepads(&c.windows().await.unwrap()).len() };
    let before = count().await;
    let tree_run = {
        let c2 = c.clone();
        let req = run(&["cmd", "/c", "start /wait notepad"], 4_000);
        tokio::spawn(async move { c2.exec(&req).await })
    };
    eventually("the grandchild notepad to open", Duration::from_secs(4), || async {
        (count().await > before).then_some(())
    })
    .await;
    let killed = tree_run.await.unwrap().expect("exec start /wait");
    assert!(killed.timed_out, "{killed:?}");
    eventually("the grandchild notepad to die with the job", Duration::from_secs(5), || async {
        (count().await == before).then_some(())
    })
    .await;
    let missing = c.exec(&run(&["no-such-program-arena"], 5_000)).await.expect_err("a missing program");
    assert!(missing.to_string().contains("not found"), "{missing}");

    // 9. Files and the registry round-trip.
    let folders = c.folders().await.expect("known folders");
    let temp = folders
        .folders
        .iter()
        .find(|(f, _)| *f == arena_shared::files::KnownFolder::Temp)
        .map(|(_, p)| p.clone())
        .expect("temp folder");
    let path = format!(r"{temp}\arena-wine-test\data.bin");
    let bytes: Vec<u8> = (0..=255u8).cycle().take(70_000).collect();
    c.push_file(&path, bytes.clone(), Some(true)).await.expect("push");
    assert_eq!(c.pull_file(&path).await.expect("pull").bytes, bytes);
    assert_eq!(c.stat(&path).await.expect("stat").size, bytes.len() as u64);
    let key = r"HKCU\Software\ArenaWineTest";
    for (name, data) in [
        ("Text", RegistryValue::String("Wäll €".into())),
        ("Count", RegistryValue::Dword(42)),
        ("Big", RegistryValue::Qword(1 << 40)),
        ("List", RegistryValue::MultiString(vec!["a".into(), "b".into()])),
    ] {
        c.registry_set(&RegistryWrite { key: key.into(), value: Some(name.into()), data: data.clone() })
            .await
            .expect("registry set");
        assert_eq!(c.registry_get(key, Some(name)).await.expect("registry get").data, data, "{name}");
    }
    let absent = c.registry_get(key, Some("Absent")).await.expect_err("a missing value");
    assert!(absent.to_string().contains("not found"), "{absent}");

    // The wallpaper is set from a file and read back, through the WAA routes.
    let wall = format!(r"{temp}\arena-wine-test\wall.png");
    c.push_file(&wall, png.clone(), Some(true)).await.expect("push wallpaper");
    let changed = http
        .post(format!("{}/setup/change_wallpaper", guest.url))
        .json(&serde_json::json!({"path": wall}))
        .send()
        .await
        .unwrap();
    assert_eq!(changed.status(), 200, "{}", changed.text().await.unwrap_or_default());
    let current = http.post(format!("{}/wallpaper", guest.url)).send().await.unwrap();
    assert_eq!(current.status(), 200);
    assert_eq!(current.bytes().await.unwrap().as_ref(), png.as_slice(), "the wallpaper read back is another file");

    // The DACL check answers for the current user and names an unknown one.
    let user =
        c.exec(&run(&["cmd", "/c", "echo %USERNAME%"], 10_000)).await.expect("username").stdout.trim().to_owned();
    let acl = |who: &str| {
        http.post(format!("{}/is_directory_read_only_for_user", guest.url))
            .json(&serde_json::json!({"directory": temp, "user": who}))
            .send()
    };
    let writable = acl(&user).await.unwrap();
    assert_eq!(writable.status(), 400, "the temp folder should not be read-only for {user}");
    let nobody = acl("no-such-user-arena").await.unwrap();
    assert_eq!(nobody.status(), 500);
    assert!(nobody.text().await.unwrap().contains("not found"));

    // open_path: ShellExecuteW "open" on a program starts it.
    let before = count().await;
    c.open(r"C:\windows\system32\notepad.exe").await.expect("open notepad.exe");
    eventually("notepad opened by ShellExecute", Duration::from_secs(10), || async {
        (count().await > before).then_some(())
    })
    .await;

    // 10. The upstream WAA routes answer as upstream does.
    let get = |path: &str| http.get(format!("{}{path}", guest.url)).send();
    let probe = get("/probe").await.unwrap();
    assert_eq!(probe.status(), 200);
    let execute: serde_json::Value = http
        .post(format!("{}/execute", guest.url))
        .json(&serde_json::json!({"command": "echo waa", "shell": true}))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(execute["output"], "waa\n", "{execute}");
    assert_eq!(execute["returncode"], 0);
    let shot = get("/screenshot").await.unwrap();
    assert_eq!(shot.status(), 200);
    assert!(!arena_guest::imaging::is_black(
        &arena_guest::imaging::decode(&shot.bytes().await.unwrap()).expect("a PNG")
    ));
    let obs = get("/obs_winagent").await.unwrap();
    assert_eq!(obs.status(), 200);
    let obs: serde_json::Value = obs.json().await.unwrap();
    assert!(obs["window_names_str"].as_str().is_some_and(|s| s.contains("Notepad")), "{}", obs["window_names_str"]);
    let at: serde_json::Value = get("/accessibility?backend=win32").await.unwrap().json().await.unwrap();
    let xml = at["AT"].as_str().expect("AT");
    assert!(
        xml.starts_with("<desktop") && xml.contains("<notepad ") && xml.contains(shortened),
        "{}",
        &xml[..xml.len().min(400)]
    );
    let uia_started = Instant::now();
    let uia = get("/accessibility?backend=uia").await.unwrap();
    assert_eq!(uia.status(), 500);
    let uia: serde_json::Value = uia.json().await.unwrap();
    assert!(uia["message"].as_str().is_some_and(|m| m.contains("UI Automation")), "{uia}");
    assert!(
        uia_started.elapsed() < Duration::from_secs(5),
        "uia took {:?} to say it is missing",
        uia_started.elapsed()
    );
    let native_uia = c.a11y(&A11yQuery::default()).await.expect_err("uia under Wine");
    assert!(native_uia.to_string().contains("UI Automation"), "{native_uia}");

    // 11. Figures.
    let mut shots = Vec::new();
    let mut capture_ms = Vec::new();
    for _ in 0..5 {
        let t = Instant::now();
        let s = c.screenshot(&ScreenshotQuery::default()).await.expect("screenshot");
        shots.push(t.elapsed().as_secs_f64() * 1000.0);
        capture_ms.push(s.meta.capture_ms as f64);
    }
    let mut moves = Vec::new();
    for i in 0..20 {
        let t = Instant::now();
        c.act_one(Action::MoveTo { x: 100 + i, y: 100 }).await.expect("move");
        moves.push(t.elapsed().as_secs_f64() * 1000.0);
    }
    let avg = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let exe_size = std::fs::metadata(&setup.exe).map(|m| m.len()).unwrap_or(0);
    println!("BENCH: exe {} ({:.1} MiB)", setup.exe.display(), exe_size as f64 / 1048576.0);
    println!(
        "BENCH: screenshot 1440x900 PNG round trip avg {:.0} ms (guest GDI capture alone avg {:.0} ms) over 5",
        avg(&shots),
        avg(&capture_ms)
    );
    println!("BENCH: action round trip (move_to) avg {:.1} ms over 20", avg(&moves));

    // `arena doctor --deep` on the Wine desktop: Wine's Notepad (the doctor's own)
    // gets its tree timed (UI Automation absent: the row says why) and the round
    // trips are measured; the table is what a user pastes.
    let deep = c.doctor_deep().await.expect("doctor --deep").deep.expect("the deep part");
    for line in deep.render_table().lines() {
        println!("DOCTOR DEEP: {line}");
    }
    let win32 = deep.trees.iter().find(|t| t.app == "Notepad" && t.source == "win32").expect("a win32 Notepad row");
    assert!(win32.error.is_none() && win32.nodes > 0, "{win32:?}");
    assert!(deep.trees.iter().any(|t| t.app == "Notepad" && t.source == "uia" && t.error.is_some()), "{deep:?}");
    let moved = deep.input.iter().find(|r| r.what.starts_with("cursor")).expect("cursor round trips");
    assert!(moved.samples > 0, "{moved:?}");
    println!("BENCH: whole Wine suite {:.1} s", suite_started.elapsed().as_secs_f64());

    // 12. `arena-guest doctor` on the same desktop, as a user runs it first in a new
    // image: it finishes, says UI Automation is unavailable rather than failing, and
    // passes what Wine can do.
    let exe = setup.exe.to_str().expect("UTF-8 exe path");
    let (code, output) = wine_run(&setup, exe, &["doctor", "--backend", "windows"]);
    let report: Vec<&str> =
        output.lines().filter(|l| ["PASS ", "FAIL ", "N/A  ", "INFO "].iter().any(|p| l.starts_with(p))).collect();
    println!("DOCTOR: exit code {code}");
    for line in &report {
        println!("DOCTOR: {line}");
    }
    let status_of = |name: &str| {
        report
            .iter()
            .find(|l| l.split_whitespace().nth(1) == Some(name))
            .map(|l| l.split_whitespace().next().unwrap_or_default())
            .unwrap_or_else(|| panic!("the doctor's report has no {name} line:\n{output}"))
    };
    for name in ["uia_tree", "read_back_uia"] {
        assert_eq!(status_of(name), "N/A", "{name} under Wine:\n{output}");
    }
    for name in [
        "screen",
        "capture",
        "clipboard_text",
        "notepad_start",
        "notepad_typing",
        "read_back_win32",
        "window_close",
        "exec_timeout",
        "files",
    ] {
        assert_eq!(status_of(name), "PASS", "{name} under Wine:\n{output}");
    }
    assert!(output.lines().any(|l| l.starts_with("ok: ") || l.starts_with("FAILED: ")), "no verdict line:\n{output}");
}

/// The whole input catalogue in every action space, as `arena doctor --input` runs it
/// (`arena_inputcheck::check_guest`: the host's executor, the guest's temporary folder
/// for the log), against the Windows backend and the cross-built recorder under Wine.
///
/// Every case passes except those whose `wine` member in the catalogue names what Wine
/// cannot show and why; each of those must fail here (so the catalogue's word stays
/// true), unless the member says Wine fails it only `sometimes`, and passes on the stub's model of the recorder
/// (`host-client/inputcheck/tests/stub.rs`), so what fails here is Wine's, not ours.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn input_catalogue_under_wine() {
    let Some(setup) = setup() else {
        return;
    };
    let _desktop = DESKTOP.lock().await;
    let recorder = setup.exe.with_file_name("arena-input-recorder.exe");
    assert!(recorder.is_file(), "{} is missing: run scripts/build-windows.sh", recorder.display());
    // The guest starts it by its Windows path: Wine shows the Linux root as drive Z:.
    let recorder = format!("Z:{}", recorder.to_str().expect("UTF-8 path").replace('/', "\\"));

    let guest = start(&setup, "windows");
    let c = client(&guest.url);
    let catalogue = arena_inputcheck::Catalogue::builtin().expect("the built-in catalogue");
    let check = arena_inputcheck::GuestCheck {
        recorder: Some(recorder),
        wait: Duration::from_secs(60),
        ..arena_inputcheck::GuestCheck::default()
    };
    let started = Instant::now();
    let report = arena_inputcheck::check_guest(&c, &catalogue, &check).await.expect("the check runs under Wine");
    println!("BENCH: input catalogue under Wine: {} runs in {:.0} s", report.cases, started.elapsed().as_secs_f64());
    for line in report.render_table().lines() {
        println!("INPUT: {line}");
    }
    let runs: usize = catalogue.cases.iter().map(|case| case.inputs.len()).sum();
    assert_eq!(report.cases, runs);
    assert_eq!(report.by_space.len(), arena_actionspace::ActionSpace::ALL.len());

    let wine_of = |name: &str| catalogue.cases.iter().find(|c| c.name == name).and_then(|c| c.wine.as_ref());
    let excused = |case: &str, space: &str| {
        let space = space.parse::<arena_actionspace::ActionSpace>().ok();
        wine_of(case).is_some_and(|wine| space.is_some_and(|s| wine.covers(s)))
    };
    let unexcused: Vec<String> = report
        .mismatches
        .iter()
        .filter(|m| !excused(&m.case, &m.space))
        .map(|m| format!("{} in {}", m.case, m.space))
        .collect();
    assert!(unexcused.is_empty(), "mismatches Wine is not excused from: {unexcused:?}\n{}", report.render_table());
    // Each excused run fails (unless Wine fails it only sometimes), so no exception
    // outlives the reason it names.
    let mut exceptions = 0;
    for case in &catalogue.cases {
        let Some(wine) = &case.wine else { continue };
        for (space, _) in case.inputs.iter().filter(|(space, _)| wine.covers(*space)) {
            exceptions += 1;
            let failed = report.mismatches.iter().any(|m| m.case == case.name && m.space == space.name());
            assert!(
                failed || wine.sometimes,
                "{} in {} passes under Wine now ({}): take it off the case's `wine` member",
                case.name,
                space.name(),
                wine.reason
            );
            let outcome = if failed { "failed" } else { "passed this time" };
            println!("INPUT: Wine exception: {} in {} {outcome}: {}", case.name, space.name(), wine.reason);
        }
    }
    println!("INPUT: {} runs passed, {exceptions} named Wine exceptions", report.passed);
}

/// Runs `arena-guest.exe ARGS` (or any Wine program) to completion: exit code and output.
///
/// The output goes through a file, not a pipe: a `wine` that starts the prefix's
/// wineserver and `services.exe` hands them its handles, and they outlive it, so a
/// pipe would never reach its end.
fn wine_run(setup: &WineSetup, program: &str, args: &[&str]) -> (i32, String) {
    let mut out = tempfile::tempfile().expect("a temporary file");
    let status = std::process::Command::new(&setup.wine)
        .arg(program)
        .args(args)
        .stdin(std::process::Stdio::null())
        .stdout(out.try_clone().expect("clone the file handle"))
        .stderr(out.try_clone().expect("clone the file handle"))
        .status()
        .unwrap_or_else(|err| panic!("running {program} under Wine: {err}"));
    use std::io::{Read, Seek};
    let mut bytes = Vec::new();
    out.rewind().and_then(|()| out.read_to_end(&mut bytes)).expect("read the output back");
    (status.code().unwrap_or(-1), String::from_utf8_lossy(&bytes).into_owned())
}

/// A loopback port nobody listens on right now.
fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").and_then(|l| l.local_addr()).map(|a| a.port()).expect("a free port")
}

/// Uninstalls the test service however the test ends: an automatic-start service left
/// in the prefix would start with every later Wine run of it.
struct ServiceGuard<'a> {
    setup: &'a WineSetup,
    name: &'a str,
}

impl Drop for ServiceGuard<'_> {
    fn drop(&mut self) {
        let exe = self.setup.exe.to_str().unwrap_or_default();
        let _ = wine_run(self.setup, exe, &["service", "uninstall", "--name", self.name]);
    }
}

/// Linux pids of the Wine processes whose command line holds every one of `words`.
fn wine_pids(words: &[&str]) -> Vec<i32> {
    let Ok(entries) = std::fs::read_dir("/proc") else { return Vec::new() };
    entries
        .filter_map(|e| e.ok()?.file_name().to_str()?.parse::<i32>().ok())
        .filter(|pid| {
            let cmdline = std::fs::read(format!("/proc/{pid}/cmdline")).unwrap_or_default();
            let cmdline = String::from_utf8_lossy(&cmdline).replace('\0', " ");
            words.iter().all(|w| cmdline.contains(w))
        })
        .collect()
}

/// The service mode for real under Wine's service control manager: install (twice:
/// idempotent), the registry entry, `sc start`, the worker answering `/v1/health` on
/// the configured port, a killed worker started again, `service status`, `sc stop`
/// stopping the worker through its standard input, and uninstall.
///
/// Wine has no real sessions: `WTSGetActiveConsoleSessionId` is 1, `WTSQueryUserToken`
/// gives the service's own token, so `CreateProcessAsUserW` runs without the
/// `--allow-same-session` fallback. What Wine cannot show: a real session 0, a second
/// session, logon and logoff events, and the logon task (its `schtasks /Create` knows
/// only `/XML`).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn windows_service_under_wine() {
    let Some(setup) = setup() else {
        return;
    };
    let started = Instant::now();
    let exe = setup.exe.to_str().expect("UTF-8 exe path");
    let name = "ArenaGuestWineTest";
    let port = free_port().to_string();
    let _ = wine_run(&setup, exe, &["service", "uninstall", "--name", name]);
    let _guard = ServiceGuard { setup: &setup, name };

    // Options are checked before anything is registered.
    let (code, text) = wine_run(&setup, exe, &["service", "install", "--name", name, "--port", "0"]);
    assert_eq!(code, 2, "{text}");
    assert!(text.contains("--port 0"), "{text}");

    let install = ["service", "install", "--name", name, "--port", &port, "--backend", "stub"];
    let (code, text) = wine_run(&setup, exe, &install);
    assert_eq!(code, 0, "install: {text}");
    assert!(text.contains("is installed"), "{text}");
    let (code, text) = wine_run(&setup, exe, &install);
    assert_eq!(code, 0, "install again: {text}");
    assert!(text.contains("already installed") && text.contains("left as is"), "{text}");

    let key = format!(r"HKLM\System\CurrentControlSet\Services\{name}");
    let (code, text) = wine_run(&setup, "reg", &["query", &key]);
    assert_eq!(code, 0, "reg query: {text}");
    let expected = format!("service run --name {name} -- --port {port} --backend stub");
    assert!(text.contains("ImagePath") && text.contains(&expected), "{text}");
    assert!(text.contains("0x2"), "not automatic start: {text}");

    let (code, text) = wine_run(&setup, "sc", &["start", name]);
    assert_eq!(code, 0, "sc start: {text}");
    let guest = client(&format!("http://127.0.0.1:{port}"));
    let health =
        eventually("the worker's /v1/health", Duration::from_secs(30), || async { guest.health().await.ok() }).await;
    assert_eq!(health.backend, "stub");
    let (code, text) = wine_run(&setup, exe, &["service", "status", "--name", name]);
    assert_eq!(code, 0, "{text}");
    assert!(text.contains(": running"), "{text}");

    // A worker that dies is started again (after the 1 s backoff).
    let workers = wine_pids(&["--worker", &port]);
    assert_eq!(workers.len(), 1, "one worker process: {workers:?}");
    let killed = std::process::Command::new("kill").args(["-9", &workers[0].to_string()]).status().expect("kill");
    assert!(killed.success());
    eventually("a new worker after the old one was killed", Duration::from_secs(20), || async {
        let now = wine_pids(&["--worker", &port]);
        let health = guest.health().await.ok()?;
        (now.len() == 1 && now[0] != workers[0] && health.backend == "stub").then_some(())
    })
    .await;

    // Stop: the supervisor closes the worker's standard input and the worker shuts down.
    let (code, text) = wine_run(&setup, "sc", &["stop", name]);
    assert_eq!(code, 0, "sc stop: {text}");
    eventually("the worker to stop with the service", Duration::from_secs(15), || async {
        (guest.health().await.is_err() && wine_pids(&["--worker", &port]).is_empty()).then_some(())
    })
    .await;

    let (code, text) = wine_run(&setup, exe, &["service", "uninstall", "--name", name]);
    assert_eq!(code, 0, "uninstall: {text}");
    assert!(text.contains("deleted"), "{text}");
    let (code, _) = wine_run(&setup, "reg", &["query", &key]);
    assert_ne!(code, 0, "the service's registry key is still there");
    let (code, text) = wine_run(&setup, exe, &["service", "status", "--name", name]);
    assert_eq!(code, 1, "{text}");
    assert!(text.contains("not installed"), "{text}");

    // The logon task goes through schtasks.exe, whose Wine 8 version knows only `/XML`
    // (and once hung in our runs), so only the option check runs here.
    let (code, text) = wine_run(&setup, exe, &["logon-task", "install", "--port", "0"]);
    assert_eq!(code, 2, "{text}");
    assert!(text.contains("--port 0"), "{text}");
    println!(
        "BENCH: service test (install, start, relaunch, stop, uninstall) {:.1} s",
        started.elapsed().as_secs_f64()
    );
}

/// `IMAGE_SUBSYSTEM_WINDOWS_GUI`: Windows gives such a process no console.
const SUBSYSTEM_GUI: u16 = 2;
/// `IMAGE_SUBSYSTEM_WINDOWS_CUI`: a console program.
const SUBSYSTEM_CONSOLE: u16 = 3;

/// The `Subsystem` field of a PE32+ image's optional header, read from the file: the
/// DOS header's `e_lfanew` (offset 0x3C) points at the `PE\0\0` signature, which the
/// 20-byte COFF file header follows, then the optional header (magic 0x20B for PE32+),
/// whose `Subsystem` is the 16-bit field at offset 68 (Microsoft's PE format
/// specification, "Optional Header Windows-Specific Fields").
fn pe_subsystem(path: &std::path::Path) -> u16 {
    use std::io::Read as _;
    let mut head = Vec::new();
    let file = std::fs::File::open(path).unwrap_or_else(|err| panic!("opening {}: {err}", path.display()));
    file.take(4096).read_to_end(&mut head).unwrap_or_else(|err| panic!("reading {}: {err}", path.display()));
    let u16_at = |at: usize| u16::from_le_bytes([head[at], head[at + 1]]);
    assert_eq!(&head[..2], b"MZ", "{} has no DOS header", path.display());
    let pe = u32::from_le_bytes([head[0x3C], head[0x3D], head[0x3E], head[0x3F]]) as usize;
    assert!(pe + 24 + 70 <= head.len(), "{}: the PE header is past the first 4 KiB", path.display());
    assert_eq!(&head[pe..pe + 4], b"PE\0\0", "{} has no PE signature", path.display());
    let optional = pe + 4 + 20;
    assert_eq!(u16_at(optional), 0x20B, "{} is not a PE32+ image", path.display());
    u16_at(optional + 68)
}

/// The exe at `from`, alone in the new folder `to` (a hard link when the file system allows).
fn alone_in(from: &std::path::Path, to: &std::path::Path) -> std::path::PathBuf {
    std::fs::create_dir_all(to).unwrap_or_else(|err| panic!("creating {}: {err}", to.display()));
    let target = to.join(from.file_name().expect("a file name"));
    if std::fs::hard_link(from, &target).is_err() {
        std::fs::copy(from, &target).unwrap_or_else(|err| panic!("copying {} to a temp dir: {err}", from.display()));
    }
    target
}

/// The logon task's log in the Wine prefix (`C:\ProgramData\arena\logon-task.log`).
fn logon_log() -> String {
    let prefix = std::env::var_os("WINEPREFIX").map(std::path::PathBuf::from).expect("WINEPREFIX");
    let path = prefix.join("drive_c").join("ProgramData").join("arena").join("logon-task.log");
    std::fs::read_to_string(&path).unwrap_or_default()
}

/// Ends the launcher and any server of its port however the test ends.
struct LauncherGuard {
    launcher: std::process::Child,
    port: String,
}

impl Drop for LauncherGuard {
    fn drop(&mut self) {
        let _ = self.launcher.kill();
        let _ = self.launcher.wait();
        for pid in wine_pids(&["--worker", &self.port]) {
            let _ = std::process::Command::new("kill").args(["-9", &pid.to_string()]).status();
        }
    }
}

/// The logon task's launcher, `arena-guest-logon.exe`, for real under Wine (what Task
/// Scheduler would start at logon; Wine 8's `schtasks` cannot run the task itself):
/// its PE header says GUI subsystem while `arena-guest.exe` stays a console program;
/// each exe names the other when it is missing; started with serve options, it runs
/// `arena-guest.exe` from its folder, which answers `/v1/health`; a killed server is
/// started again; and ending the launcher (as `schtasks /End` would) stops the server
/// through its closed standard input.
///
/// What Wine cannot show: whether a console window would flash (Wine opens none for
/// either kind of program without `wineconsole`); that is a prediction from Windows'
/// documented behaviour (see docs/windows.md, "The logon task").
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn logon_launcher_under_wine() {
    let Some(setup) = setup() else {
        return;
    };
    let started = Instant::now();
    let launcher = setup.exe.with_file_name("arena-guest-logon.exe");
    assert!(
        launcher.is_file(),
        "{} is missing: scripts/build-windows.sh builds it beside {}",
        launcher.display(),
        setup.exe.display()
    );

    // 1. The launcher gets no console from Windows; the server stays a console program
    // (its console, hidden, is what the programs it runs for agents share).
    assert_eq!(pe_subsystem(&launcher), SUBSYSTEM_GUI, "{}", launcher.display());
    assert_eq!(pe_subsystem(&setup.exe), SUBSYSTEM_CONSOLE, "{}", setup.exe.display());

    // 2. Each exe names the other when it is missing from its folder.
    let alone = tempfile::tempdir().expect("temp dir");
    let server_alone = alone_in(&setup.exe, &alone.path().join("server"));
    let (code, text) =
        wine_run(&setup, server_alone.to_str().expect("UTF-8"), &["logon-task", "install", "--port", "5000"]);
    assert_eq!(code, 2, "{text}");
    assert!(text.contains("arena-guest-logon.exe is missing: expected at "), "{text}");
    let launcher_alone = alone_in(&launcher, &alone.path().join("launcher"));
    let port = free_port().to_string();
    let (code, text) =
        wine_run(&setup, launcher_alone.to_str().expect("UTF-8"), &["--port", &port, "--backend", "stub"]);
    assert_eq!(code, 2, "the launcher without arena-guest.exe beside it: {text}");
    let log = logon_log();
    let last = log.lines().last().unwrap_or_default();
    assert!(last.contains("error: arena-guest.exe is missing: expected at "), "the log ends with {last:?}");
    // Bad options are refused before anything starts, and said in the log.
    let (code, _) = wine_run(&setup, launcher.to_str().expect("UTF-8"), &["--port", "0"]);
    assert_eq!(code, 2);
    assert!(logon_log().lines().last().unwrap_or_default().contains("--port 0"), "{}", logon_log());

    // 3. The launcher runs the server from its own folder.
    let child = std::process::Command::new(&setup.wine)
        .arg(&launcher)
        .args(["--port", &port, "--backend", "stub"])
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("starting the launcher under Wine");
    let mut guard = LauncherGuard { launcher: child, port: port.clone() };
    let guest = client(&format!("http://127.0.0.1:{port}"));
    let health =
        eventually("the server the launcher started", Duration::from_secs(30), || async { guest.health().await.ok() })
            .await;
    assert_eq!(health.backend, "stub");
    let servers = wine_pids(&["--worker", &port]);
    assert_eq!(servers.len(), 1, "one server: {servers:?}");
    let cmdline = std::fs::read(format!("/proc/{}/cmdline", servers[0])).unwrap_or_default();
    assert!(String::from_utf8_lossy(&cmdline).contains("arena-guest.exe"), "{cmdline:?}");
    let said = "started the server (pid ";
    let with = format!("with [\"--port\", \"{port}\", \"--backend\", \"stub\"]");
    assert!(logon_log().lines().any(|l| l.contains(said) && l.contains(&with)), "{}", logon_log());

    // A server that dies is started again (after the 1 s backoff).
    let killed = std::process::Command::new("kill").args(["-9", &servers[0].to_string()]).status().expect("kill");
    assert!(killed.success());
    eventually("a new server after the old one was killed", Duration::from_secs(20), || async {
        let now = wine_pids(&["--worker", &port]);
        let health = guest.health().await.ok()?;
        (now.len() == 1 && now[0] != servers[0] && health.backend == "stub").then_some(())
    })
    .await;

    // Ending the launcher closes the server's standard input: the server stops too.
    guard.launcher.kill().expect("ending the launcher");
    let _ = guard.launcher.wait();
    eventually("the server to stop with its launcher", Duration::from_secs(15), || async {
        (guest.health().await.is_err() && wine_pids(&["--worker", &port]).is_empty()).then_some(())
    })
    .await;
    println!(
        "BENCH: logon launcher test (subsystems, missing exes, start, relaunch, stop) {:.1} s",
        started.elapsed().as_secs_f64()
    );
}
