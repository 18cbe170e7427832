//! Tests of the system getters against an in-process stub guest, seeded with
//! files, registry values and (for the Explorer and Clock queries) a scenario
//! of windows with accessibility elements. Each getter has a passing and a
//! failing case on real files the tests make (PNG and JPEG images, a 7z
//! archive with a password, a library description, a night-light blob).

use std::io::Cursor;
use std::path::{Path, PathBuf};
use std::time::{Duration, UNIX_EPOCH};

use arena_shared::files::KnownFolder;
use arena_shared::registry::{RegistryValue, RegistryWrite};
use serde_json::{json, Value};

use super::super::tests::{start_guest_with, Guest};
use super::{decode_night_light, has_red_circle, protected_7z_holds, rule_relative_time, Day};
use crate::fetch;
use crate::getters::Params;
use crate::value::Fetched;
use arena_task::GetterSpec;

async fn start(scenario: Option<Value>) -> Guest {
    start_guest_with(scenario, |_| {}).await
}

impl Guest {
    async fn folder(&self, which: KnownFolder) -> String {
        let folders = self.ctx.client.folders().await.expect("folders");
        folders.folders.into_iter().find(|(k, _)| *k == which).map(|(_, p)| p).expect("known folder")
    }

    async fn push(&self, path: &str, bytes: &[u8]) {
        self.ctx.client.push_file(path, bytes.to_vec(), None).await.expect("push");
    }

    async fn set(&self, key: &str, value: &str, data: RegistryValue) {
        let write = RegistryWrite { key: key.into(), value: Some(value.into()), data };
        self.ctx.client.registry_set(&write).await.expect("registry write");
    }

    /// Where the stub keeps a `C:\...` path on this host.
    fn local(&self, guest: &str) -> PathBuf {
        let rest = guest.trim_start_matches("C:").trim_start_matches(['\\', '/']);
        rest.split(['\\', '/']).fold(self.root().join("C"), |path, part| path.join(part))
    }

    /// Runs a getter and compares with `want`: a value, or an error containing the text.
    async fn check(&self, getter: Value, want: Result<Fetched, &str>) {
        let Value::Object(mut map) = getter.clone() else { panic!("a getter is an object") };
        let kind = map.remove("type").and_then(|v| v.as_str().map(str::to_owned)).expect("type");
        let got = fetch(&self.ctx, &GetterSpec { kind, params: map }).await;
        match (&got, &want) {
            (Ok(value), Ok(expected)) => assert_eq!(value, expected, "{getter}"),
            (Err(err), Err(text)) => assert!(err.to_string().contains(text), "{getter}: {err} lacks {text:?}"),
            _ => panic!("{getter}: got {got:?}, want {want:?}"),
        }
    }
}

fn text(s: &str) -> Fetched {
    Fetched::Text(s.into())
}

fn png(width: u32, height: u32, draw: impl Fn(u32, u32) -> [u8; 3]) -> Vec<u8> {
    let image = image::RgbImage::from_fn(width, height, |x, y| image::Rgb(draw(x, y)));
    let mut out = Cursor::new(Vec::new());
    image.write_to(&mut out, image::ImageFormat::Png).expect("encode png");
    out.into_inner()
}

const WHITE: [u8; 3] = [255, 255, 255];
const PAINT_RED: [u8; 3] = [237, 28, 36];
const BLUE: [u8; 3] = [0, 80, 230];

fn ring(cx: f64, cy: f64, r: f64, width: f64, colour: [u8; 3]) -> impl Fn(u32, u32) -> [u8; 3] {
    move |x, y| {
        let d = ((f64::from(x) - cx).powi(2) + (f64::from(y) - cy).powi(2)).sqrt();
        if (d - r).abs() <= width / 2.0 {
            colour
        } else {
            WHITE
        }
    }
}

fn disk(cx: f64, cy: f64, r: f64, colour: [u8; 3]) -> impl Fn(u32, u32) -> [u8; 3] {
    move |x, y| if (f64::from(x) - cx).powi(2) + (f64::from(y) - cy).powi(2) <= r * r { colour } else { WHITE }
}

fn square(x0: u32, y0: u32, side: u32, outline: bool) -> impl Fn(u32, u32) -> [u8; 3] {
    move |x, y| {
        let inside = (x0..x0 + side).contains(&x) && (y0..y0 + side).contains(&y);
        let edge = x < x0 + 3 || y < y0 + 3 || x >= x0 + side - 3 || y >= y0 + side - 3;
        if inside && (!outline || edge) {
            PAINT_RED
        } else {
            WHITE
        }
    }
}

#[test]
fn red_circles_are_told_from_other_shapes() {
    let check = |name: &str, bytes: Vec<u8>, want: bool| {
        let image = image::load_from_memory(&bytes).expect("decode").to_rgb8();
        assert_eq!(has_red_circle(&image), want, "{name}");
    };
    check("red ring", png(200, 160, ring(100.0, 80.0, 50.0, 4.0, PAINT_RED)), true);
    check("thin red ring", png(200, 160, ring(60.0, 60.0, 30.0, 2.0, PAINT_RED)), true);
    check("filled red disk", png(200, 160, disk(90.0, 70.0, 40.0, PAINT_RED)), true);
    check("blue ring", png(200, 160, ring(100.0, 80.0, 50.0, 4.0, BLUE)), false);
    check("filled red square", png(200, 160, square(40, 30, 80, false)), false);
    check("red square outline", png(200, 160, square(40, 30, 80, true)), false);
    check("blank canvas", png(50, 50, |_, _| WHITE), false);
    // A half circle: the arc misses half the sectors.
    let arc = ring(100.0, 80.0, 50.0, 4.0, PAINT_RED);
    check("red arc", png(200, 160, move |x, y| if y < 80 { arc(x, y) } else { WHITE }), false);
    // A small red swatch (like Paint's palette) next to nothing round.
    check("tiny swatch", png(100, 100, square(10, 10, 6, false)), false);
}

#[test]
fn night_light_blobs_decode_like_upstream() {
    let blob = |pairs: &[(usize, u8)]| {
        let mut bytes = vec![0u8; 48];
        for &(i, b) in pairs {
            bytes[i] = b;
        }
        bytes
    };
    let check = |bytes: Vec<u8>, want: Option<Value>| assert_eq!(decode_night_light(&bytes), want, "{bytes:?}");
    check(blob(&[(24, 1), (28, 19), (33, 7)]), Some(json!([true, "07:00 PM", "07:00 AM"])));
    check(
        blob(&[(24, 1), (28, 21), (29, 46), (30, 30), (35, 6), (36, 46), (37, 15)]),
        Some(json!([true, "09:30 PM", "06:15 AM"])),
    );
    check(blob(&[(24, 1), (28, 202)]), Some(json!([true])));
    check(blob(&[(24, 0), (28, 19)]), Some(json!(false)));
    check(vec![0; 20], None);
    check(blob(&[(24, 1), (28, 12), (33, 0)]), Some(json!([true, "00:00 PM", "00:00 AM"])));
}

/// A 7z archive of `entries`, encrypted (content and with AES-256) when a password is given.
fn seven_zip(password: Option<&str>, entries: &[(&str, &[u8])]) -> Vec<u8> {
    use sevenz_rust2::encoder_options::AesEncoderOptions;
    use sevenz_rust2::{ArchiveEntry, ArchiveWriter, EncoderMethod, Password};
    let mut writer = ArchiveWriter::new(Cursor::new(Vec::new())).expect("7z writer");
    if let Some(password) = password {
        writer.set_content_methods(vec![
            AesEncoderOptions::new(Password::from(password)).into(),
            EncoderMethod::LZMA2.into(),
        ]);
    }
    for (name, bytes) in entries {
        writer.push_archive_entry(ArchiveEntry::new_file(name), Some(*bytes)).expect("7z entry");
    }
    writer.finish().expect("7z finish").into_inner()
}

#[test]
fn protected_archives_need_the_right_password_and_entry() {
    let entry = "OldProjects/example.txt";
    let locked = seven_zip(Some("12345"), &[(entry, b"hello world")]);
    assert_eq!(protected_7z_holds(&locked, "12345", entry), Ok(true));
    assert_eq!(protected_7z_holds(&locked, "12345", "OldProjects/other.txt"), Ok(false));
    assert!(protected_7z_holds(&locked, "wrong", entry).is_err(), "a wrong password must not read");
    let open = seven_zip(None, &[(entry, b"hello world")]);
    assert_eq!(protected_7z_holds(&open, "12345", entry), Ok(false));
    assert!(protected_7z_holds(b"PK\x03\x04 not a 7z", "12345", entry).is_err());
}

#[tokio::test]
async fn vlc_config_saves_vlcrc() {
    let guest = start(None).await;
    guest.check(json!({"type": "vlc_config", "dest": "vlcrc"}), Err("vlcrc")).await;
    let appdata = guest.folder(KnownFolder::AppData).await;
    guest.push(&format!(r"{appdata}\vlc\vlcrc"), b"[qt]\nqt-max-volume=200\n").await;
    let dest = guest.ctx.work_dir.join("vlcrc");
    guest.check(json!({"type": "vlc_config", "dest": "vlcrc"}), Ok(Fetched::File(dest.clone()))).await;
    assert_eq!(std::fs::read(dest).unwrap(), b"[qt]\nqt-max-volume=200\n");
}

#[tokio::test]
async fn desktop_file_checks() {
    let guest = start(None).await;
    let desktop = guest.folder(KnownFolder::Desktop).await;
    guest.push(&format!(r"{desktop}\numdays.txt"), b"The answer: 230 days\r\n").await;
    // Notepad's "UTF-16 LE" files carry a BOM.
    let utf16: Vec<u8> = [0xff, 0xfe].into_iter().chain("585 days".encode_utf16().flat_map(u16::to_le_bytes)).collect();
    guest.push(&format!(r"{desktop}\wide.txt"), &utf16).await;

    let saved =
        |name: &str, content: &str| json!({"type": "is_file_saved_desktop", "filename": name, "textcontent": content});
    guest.check(saved("numdays.txt", "230 days"), Ok(text("true"))).await;
    guest.check(saved("numdays.txt", "231 days"), Ok(text("false"))).await;
    guest.check(saved("wide.txt", "585 days"), Ok(text("true"))).await;
    guest.check(saved("absent.txt", "230 days"), Ok(text("false"))).await;
    let mut exact = saved("numdays.txt", "230 days");
    exact["exact"] = json!(true);
    guest.check(exact, Ok(text("false"))).await;
    let mut exact = saved("numdays.txt", "The answer: 230 days");
    exact["exact"] = json!(true);
    guest.check(exact, Ok(text("true"))).await;

    guest.check(json!({"type": "is_file_desktop", "filename": "numdays.txt"}), Ok(text("true"))).await;
    guest.check(json!({"type": "is_file_desktop", "filename": "example.txt"}), Ok(text("false"))).await;
    guest.check(json!({"type": "is_file_desktop"}), Err("missing parameter `filename`")).await;
}

#[tokio::test]
async fn hidden_files() {
    let guest = start(None).await;
    let docs = guest.folder(KnownFolder::Documents).await;
    // The stub models the hidden attribute with the dot-file rule.
    guest.push(&format!(r"{docs}\.secret.txt"), b"s").await;
    guest.push(&format!(r"{docs}\secret.txt"), b"s").await;
    let hidden = |name: &str| json!({"type": "is_file_hidden", "file_path": format!(r"{docs}\{name}")});
    guest.check(hidden(".secret.txt"), Ok(text("true"))).await;
    guest.check(hidden("secret.txt"), Ok(text("false"))).await;
    guest.check(hidden("absent.txt"), Ok(text("false"))).await;
}

#[tokio::test]
async fn png_names_listed_in_a_file() {
    let guest = start(None).await;
    let pictures = guest.folder(KnownFolder::Pictures).await;
    for name in ["cs-black-000.png", "Gray.PNG", "photo.jpg"] {
        guest.push(&format!(r"{pictures}\{name}"), b"x").await;
    }
    let getter = json!({"type": "all_png_file_names", "folder_path": pictures, "file_path": format!(r"{pictures}\png_files.txt")});
    guest.check(getter.clone(), Ok(text("false"))).await;
    guest.push(&format!(r"{pictures}\png_files.txt"), b"cs-black-000.png\r\nGray.PNG\r\n").await;
    guest.check(getter.clone(), Ok(text("true"))).await;
    guest.push(&format!(r"{pictures}\png_files.txt"), b"cs-black-000.png\r\n").await;
    guest.check(getter.clone(), Ok(text("false"))).await;
    guest.push(&format!(r"{pictures}\png_files.txt"), b"cs-black-000.png\nGray.PNG\nphoto.jpg\n").await;
    guest.check(getter, Ok(text("false"))).await;
}

#[tokio::test]
async fn docx_archive_folder() {
    let guest = start(None).await;
    let docs = guest.folder(KnownFolder::Documents).await;
    let getter = json!({"type": "is_all_docx_in_archive", "folder_path": docs});
    guest.push(&format!(r"{docs}\Doc01.docx"), b"d1").await;
    guest.check(getter.clone(), Ok(text("false"))).await;
    guest.ctx.client.mkdir(&format!(r"{docs}\Archive")).await.unwrap();
    guest.check(getter.clone(), Ok(text("false"))).await;
    guest.push(&format!(r"{docs}\Archive\Doc02.docx"), b"d2").await;
    // Doc01.docx is still outside the archive.
    guest.check(getter.clone(), Ok(text("false"))).await;
    guest.ctx.client.delete(&format!(r"{docs}\Doc01.docx"), false).await.unwrap();
    guest.push(&format!(r"{docs}\Archive\Doc01.DOCX"), b"d1").await;
    guest.push(&format!(r"{docs}\notes.txt"), b"n").await;
    guest.check(getter.clone(), Ok(text("true"))).await;
    guest.push(&format!(r"{docs}\Archive\notes.txt"), b"n").await;
    guest.check(getter, Ok(text("false"))).await;
}

#[tokio::test]
async fn files_moved_out_of_downloads() {
    let guest = start(None).await;
    let downloads = guest.folder(KnownFolder::Downloads).await;
    let home = guest.folder(KnownFolder::Home).await;
    let getter = json!({"type": "is_files_moved_downloads", "folder_name": "Test", "file_name": "example.txt"});
    guest.push(&format!(r"{downloads}\Test\example.txt"), b"x").await;
    guest.ctx.client.mkdir(&format!(r"{home}\OldDownloads")).await.unwrap();
    guest.check(getter.clone(), Ok(text("false"))).await;
    // Copied, not moved: Downloads still holds both names.
    guest.push(&format!(r"{home}\OldDownloads\Test\example.txt"), b"x").await;
    guest.check(getter.clone(), Ok(text("false"))).await;
    guest.ctx.client.delete(&format!(r"{downloads}\Test"), true).await.unwrap();
    guest.check(getter.clone(), Ok(text("true"))).await;
    // Flattened: the file is in OldDownloads but not under Test.
    guest.ctx.client.delete(&format!(r"{home}\OldDownloads\Test"), true).await.unwrap();
    guest.push(&format!(r"{home}\OldDownloads\example.txt"), b"x").await;
    guest.check(getter, Ok(text("false"))).await;
}

#[tokio::test]
async fn image_getters_read_pulled_images() {
    let guest = start(None).await;
    let downloads = guest.folder(KnownFolder::Downloads).await;
    guest.push(&format!(r"{downloads}\CanvasSize.png"), &png(800, 600, |_, _| WHITE)).await;
    guest.push(&format!(r"{downloads}\Small.png"), &png(640, 480, |_, _| WHITE)).await;
    guest.push(&format!(r"{downloads}\text.png"), b"not an image").await;
    let dims = |name: &str| json!({"type": "image_dimension_matches_input", "filepath": format!(r"{downloads}\{name}"), "width": "800", "height": "600"});
    guest.check(dims("CanvasSize.png"), Ok(Fetched::Bool(true))).await;
    guest.check(dims("Small.png"), Ok(Fetched::Bool(false))).await;
    guest.check(dims("absent.png"), Ok(Fetched::Bool(false))).await;
    guest.check(dims("text.png"), Err("is not an image")).await;
    let mut bad = dims("CanvasSize.png");
    bad["width"] = json!("wide");
    guest.check(bad, Err("`width` must be an integer")).await;

    guest.push(&format!(r"{downloads}\Screenshot.png"), &png(300, 200, ring(150.0, 100.0, 60.0, 5.0, PAINT_RED))).await;
    guest.push(&format!(r"{downloads}\Blank.png"), &png(300, 200, square(20, 20, 100, false))).await;
    let circle =
        |name: &str| json!({"type": "is_red_circle_present_on_canvas", "filepath": format!(r"{downloads}\{name}")});
    guest.check(circle("Screenshot.png"), Ok(Fetched::Bool(true))).await;
    guest.check(circle("Blank.png"), Ok(Fetched::Bool(false))).await;
    guest.check(circle("absent.png"), Ok(Fetched::Bool(false))).await;
}

#[tokio::test]
async fn zipped_folder_on_the_desktop() {
    let guest = start(None).await;
    let desktop = guest.folder(KnownFolder::Desktop).await;
    let path = format!(r"{desktop}\OldProjects.7z");
    let getter = json!({"type": "zipped_folder_in_desktop", "filename": path, "password": "12345"});
    guest.check(getter.clone(), Ok(text("false"))).await;
    guest.push(&path, &seven_zip(None, &[("OldProjects/example.txt", b"hello")])).await;
    guest.check(getter.clone(), Ok(text("false"))).await;
    guest.push(&path, &seven_zip(Some("12345"), &[("OldProjects/example.txt", b"hello")])).await;
    guest.check(getter.clone(), Ok(text("true"))).await;
    let mut wrong = getter;
    wrong["password"] = json!("54321");
    guest.check(wrong, Ok(text("false"))).await;
}

#[tokio::test]
async fn registry_backed_settings() {
    let guest = start(None).await;
    // Night light.
    let key = super::NIGHT_LIGHT_KEY;
    guest.check(json!({"type": "night_light_state"}), Err("no night light settings")).await;
    let mut blob = vec![0u8; 44];
    blob[24] = 1;
    blob[28] = 19;
    blob[33] = 7;
    guest.set(key, "Data", RegistryValue::Binary(blob.clone())).await;
    guest.check(json!({"type": "night_light_state"}), Ok(Fetched::Json(json!([true, "07:00 PM", "07:00 AM"])))).await;
    blob[24] = 0;
    guest.set(key, "Data", RegistryValue::Binary(blob)).await;
    guest.check(json!({"type": "night_light_state"}), Ok(Fetched::Json(json!(false)))).await;

    // Storage Sense.
    let policy = super::STORAGE_POLICY_KEY;
    guest.check(json!({"type": "storage_sense_run_frequency"}), Ok(Fetched::None)).await;
    guest.set(policy, "01", RegistryValue::Dword(1)).await;
    guest.set(policy, "2048", RegistryValue::Dword(7)).await;
    guest.check(json!({"type": "storage_sense_run_frequency"}), Ok(text("7"))).await;
    guest.set(policy, "01", RegistryValue::Dword(0)).await;
    guest.check(json!({"type": "storage_sense_run_frequency"}), Ok(Fetched::None)).await;

    // Notifications.
    let push = super::PUSH_NOTIFICATIONS_KEY;
    guest.check(json!({"type": "system_notifications"}), Ok(text("False"))).await;
    guest.set(push, "ToastEnabled", RegistryValue::Dword(0)).await;
    guest.check(json!({"type": "system_notifications"}), Ok(text("True"))).await;
    guest.set(push, "ToastEnabled", RegistryValue::Dword(1)).await;
    guest.check(json!({"type": "system_notifications"}), Ok(Fetched::None)).await;

    // Desktop background: a solid colour has no wallpaper path.
    guest.check(json!({"type": "desktop_background"}), Ok(text("True"))).await;
    guest.set(super::DESKTOP_KEY, "Wallpaper", RegistryValue::String(r"C:\Windows\Web\img0.jpg".into())).await;
    guest.check(json!({"type": "desktop_background"}), Ok(text("False"))).await;
    guest.set(super::DESKTOP_KEY, "Wallpaper", RegistryValue::String(String::new())).await;
    guest.check(json!({"type": "desktop_background"}), Ok(text("True"))).await;

    // Time zone.
    guest.check(json!({"type": "system_timezone"}), Err("does not name its time zone")).await;
    guest
        .set(super::TIME_ZONE_INFO_KEY, "TimeZoneKeyName", RegistryValue::String("Pacific Standard Time".into()))
        .await;
    guest.check(json!({"type": "system_timezone"}), Err("no display name")).await;
    let zone = format!(r"{}\Pacific Standard Time", super::TIME_ZONES_KEY);
    guest.set(&zone, "Display", RegistryValue::String("(UTC-08:00) Pacific Time (US & Canada)".into())).await;
    guest.check(json!({"type": "system_timezone"}), Ok(text("(UTC-08:00) Pacific Time (US & Canada)"))).await;
}

/// An accessibility node for scenario `elements`.
fn el(role: &str, name: &str, children: Vec<Value>) -> Value {
    json!({"role": role, "class_name": "", "name": name, "enabled": true, "visible": true, "children": children})
}

fn explorer(items: &[&str]) -> Value {
    let list = el("List", "Items View", items.iter().map(|n| el("ListItem", n, vec![])).collect());
    json!({"windows": [{"title": "Documents - File Explorer", "class_name": "CabinetWClass", "process_name": "explorer.exe",
        "focused": true, "elements": [el("Pane", "Shell Folder View", vec![list])]}]})
}

fn clock(elements: Vec<Value>) -> Value {
    json!({"windows": [{"title": "Clock", "class_name": "ApplicationFrameWindow", "focused": true,
        "rect": {"x": 0, "y": 0, "width": 800, "height": 600}, "elements": elements}]})
}

#[tokio::test]
async fn explorer_views_come_from_the_foreground_window() {
    let docs = r"C:\Users\Docker\Documents";
    let details = json!({"type": "is_details_view", "folder_path": "C:/Users/Docker/Documents"});
    let guest = start(Some(explorer(&["Header", "a.txt"]))).await;
    guest.check(details.clone(), Ok(Fetched::Bool(true))).await;
    guest.check(json!({"type": "is_details_view", "folder_path": ""}), Ok(Fetched::Bool(false))).await;
    let guest = start(Some(explorer(&["a.txt"]))).await;
    guest.check(details, Ok(Fetched::Bool(false))).await;

    let sorted = json!({"type": "are_files_sorted_by_modified_time", "directory": docs});
    for (items, want) in [
        (&["Header", "new.txt", "old.txt"][..], true),
        (&["old.txt", "new.txt"][..], true),
        (&["new.txt", "mid.txt", "old.txt"][..], true),
        (&["old.txt", "new.txt", "mid.txt"][..], false),
    ] {
        let guest = start(Some(explorer(items))).await;
        for (name, secs) in [("old.txt", 1_000_000u64), ("mid.txt", 1_500_000), ("new.txt", 2_000_000)] {
            let guest_path = format!(r"{docs}\{name}");
            guest.push(&guest_path, b"x").await;
            set_mtime(&guest.local(&guest_path), secs);
        }
        guest.check(sorted.clone(), Ok(Fetched::Bool(want))).await;
    }
}

fn set_mtime(path: &Path, secs: u64) {
    let file = std::fs::File::options().write(true).open(path).expect("open");
    file.set_modified(UNIX_EPOCH + Duration::from_secs(secs)).expect("set mtime");
}

#[tokio::test]
async fn clock_timers_and_world_clocks() {
    let timer =
        el("Group", "Timer 1, 0 hours 30 minutes 0 seconds", vec![el("Button", "Timer running, Pause", vec![])]);
    let paused = el("Group", "Timer 2, 3 hours 0 minutes 0 seconds", vec![el("Button", "Start", vec![])]);
    let kyoto = el("ListItem", "Kyoto, Japan, 8:00 AM", vec![]);
    let guest = start(Some(clock(vec![timer, paused, kyoto]))).await;
    let started = |h: Value, m: Value, s: Value| json!({"type": "check_if_timer_started", "hours": h, "minutes": m, "seconds": s});
    guest.check(started(json!(0), json!(30), json!(0)), Ok(text("True"))).await;
    guest.check(started(json!("0"), json!(30.0), json!(0)), Ok(text("True"))).await;
    guest.check(started(json!(3), json!(0), json!(0)), Ok(text("False"))).await;
    guest
        .check(json!({"type": "check_if_timer_started", "hours": 0, "minutes": 30}), Err("missing parameter `seconds`"))
        .await;

    let world =
        |city: &str, country: &str| json!({"type": "check_if_world_clock_exists", "city": city, "country": country});
    guest.check(world("Kyoto", "Japan"), Ok(text("True"))).await;
    guest.check(world("Munich", "Germany"), Ok(text("False"))).await;
}

/// A JPEG carrying `keywords` in EXIF `XPKeywords` (UTF-16 LE), as Explorer writes tags.
fn tagged_jpeg(keywords: Option<&str>) -> Vec<u8> {
    let image = image::RgbImage::from_pixel(16, 16, image::Rgb([200, 120, 40]));
    let mut jpeg = Cursor::new(Vec::new());
    image.write_to(&mut jpeg, image::ImageFormat::Jpeg).expect("encode jpeg");
    let jpeg = jpeg.into_inner();
    let Some(keywords) = keywords else {
        return jpeg;
    };
    let value: Vec<u8> = keywords.encode_utf16().chain([0]).flat_map(u16::to_le_bytes).collect();
    // Little-endian TIFF: header, IFD0 with one BYTE entry (tag 0x9C9E) pointing past the IFD.
    let mut tiff = b"II*\0".to_vec();
    tiff.extend_from_slice(&8u32.to_le_bytes());
    tiff.extend_from_slice(&1u16.to_le_bytes());
    tiff.extend_from_slice(&0x9c9eu16.to_le_bytes());
    tiff.extend_from_slice(&1u16.to_le_bytes());
    tiff.extend_from_slice(&(value.len() as u32).to_le_bytes());
    tiff.extend_from_slice(&(8u32 + 2 + 12 + 4).to_le_bytes());
    tiff.extend_from_slice(&0u32.to_le_bytes());
    tiff.extend_from_slice(&value);
    let mut app1 = b"Exif\0\0".to_vec();
    app1.extend_from_slice(&tiff);
    let mut out = jpeg[..2].to_vec();
    out.extend_from_slice(&[0xff, 0xe1]);
    out.extend_from_slice(&((app1.len() + 2) as u16).to_be_bytes());
    out.extend_from_slice(&app1);
    out.extend_from_slice(&jpeg[2..]);
    out
}

#[tokio::test]
async fn dacls_tags_and_libraries() {
    let vacation = r"C:\Users\Docker\Pictures\Vacation Photos";
    let scenario = json!({"dirs": [vacation], "acls": {vacation: {"TestAccount": 0x1200A9, "Guest": 0x1F01FF}}});
    let guest = start(Some(scenario)).await;
    let read_only =
        |user: &str, dir: &str| json!({"type": "is_directory_read_only_for_user", "directory": dir, "user": user});
    guest.check(read_only("TestAccount", vacation), Ok(Fetched::Bool(true))).await;
    guest.check(read_only("Guest", vacation), Ok(Fetched::Bool(false))).await;
    guest.check(read_only("Nobody", vacation), Ok(Fetched::Bool(false))).await;
    guest.check(read_only("TestAccount", r"C:\Users\Docker\Pictures\Absent"), Ok(Fetched::Bool(false))).await;
    guest.check(read_only("", vacation), Err("`user` is required")).await;

    let trip = r"C:\Users\Docker\Pictures\Summer Trip";
    guest.push(&format!(r"{trip}\TestImage1.jpg"), &tagged_jpeg(Some("2023Vacation"))).await;
    guest.push(&format!(r"{trip}\TestImage2.JPG"), &tagged_jpeg(Some("beach;2023Vacation"))).await;
    guest.push(&format!(r"{trip}\notes.txt"), b"not an image").await;
    let tagged = json!({"type": "are_all_images_tagged", "directory": trip, "tag": "2023Vacation"});
    guest.check(tagged.clone(), Ok(Fetched::Bool(true))).await;
    guest.push(&format!(r"{trip}\TestImage3.jpeg"), &tagged_jpeg(None)).await;
    guest.check(tagged, Ok(Fetched::Bool(false))).await;
    guest
        .check(
            json!({"type": "are_all_images_tagged", "directory": r"C:\Users\Docker\Pictures\Nowhere", "tag": "x"}),
            Ok(Fetched::Bool(false)),
        )
        .await;

    let appdata = guest.folder(KnownFolder::AppData).await;
    let library = format!(r"{appdata}\Microsoft\Windows\Libraries\Arena.library-ms");
    let xml = r#"<?xml version="1.0" encoding="UTF-8"?>
<libraryDescription xmlns="http://schemas.microsoft.com/windows/2009/library">
  <searchConnectorDescriptionList>
    <searchConnectorDescription><simpleLocation><url>C:\Users\Docker\Downloads\Arena Docs</url></simpleLocation></searchConnectorDescription>
    <searchConnectorDescription><simpleLocation><url>C:\Users\Docker\Downloads\Arena Code</url></simpleLocation></searchConnectorDescription>
  </searchConnectorDescriptionList>
</libraryDescription>"#;
    let mut utf16 = vec![0xff, 0xfe];
    utf16.extend(xml.encode_utf16().flat_map(u16::to_le_bytes));
    guest.push(&library, &utf16).await;
    guest
        .check(
            json!({"type": "vm_library_folders", "library_name": "Arena"}),
            Ok(Fetched::Json(json!([
                r"C:\Users\Docker\Downloads\Arena Code",
                r"C:\Users\Docker\Downloads\Arena Docs"
            ]))),
        )
        .await;
    guest.check(json!({"type": "vm_library_folders", "library_name": "Other"}), Ok(Fetched::None)).await;
    guest.check(json!({"type": "vm_library_folders", "library_name": r"..\x"}), Err("plain name")).await;
}

#[test]
fn relative_time_rules_fill_dates() {
    // 2024-08-21 12:00 UTC, a Wednesday.
    let wednesday = UNIX_EPOCH + Duration::from_secs(1_724_241_600);
    let check = |rules: Value, want: Result<Value, &str>| {
        let Value::Object(map) = json!({"rules": rules}) else { unreachable!() };
        let got = rule_relative_time(&Params::new("rule_relativeTime", &map), wednesday);
        match (got, want) {
            (Ok(Fetched::Json(value)), Ok(expected)) => assert_eq!(value, expected),
            (Err(err), Err(text)) => assert!(err.to_string().contains(text), "{err}"),
            (got, want) => panic!("got {got:?}, want {want:?}"),
        }
    };
    let corpus = json!({"relativeTime": {"from": "next Monday"}, "expected": {"fromStation": "BOM", "toStation": "STO", "time": "{Year}-{Month0D}-{Day0D}"}});
    let mut filled = corpus.clone();
    filled["expected"]["time"] = json!("2024-08-26");
    check(corpus, Ok(filled));
    check(
        json!({"relativeTime": {"from": "tomorrow"}, "expected": {"time": "{DoW}, {Month} {DayD} {Year}"}}),
        Ok(json!({"relativeTime": {"from": "tomorrow"}, "expected": {"time": "Thu, Aug 22 2024"}})),
    );
    check(
        json!({"relativeTime": {"from": "5th next month", "to": "this Sunday"}, "expected": {"from": "{MonthFull} {DayD}", "to": "{month} {Day0D}"}}),
        Ok(
            json!({"relativeTime": {"from": "5th next month", "to": "this Sunday"}, "expected": {"from": "September 5", "to": "august 25"}}),
        ),
    );
    check(json!({"relativeTime": {"from": "next Tuesday"}, "expected": {"time": "{Year}"}}), Err("not supported"));
    check(json!({"relativeTime": {"from": "tomorrow"}, "expected": {"date": "{Year}"}}), Err("no `time`"));
    check(
        json!({"relativeTime": {"from": "tomorrow"}, "timezone": "Asia/Tokyo", "expected": {"time": "{Year}"}}),
        Err("not supported"),
    );
}

#[test]
fn weekdays_and_month_steps() {
    // 1970-01-01 was a Thursday; 2024-02-29 a Thursday too.
    assert_eq!(Day::from_days(0).weekday, 3);
    let leap = Day::from_days(19_782);
    assert_eq!((leap.year, leap.month, leap.day, leap.weekday), (2024, 2, 29, 3));
    let first_monday = super::resolve_relative("first monday four months later", leap).unwrap();
    assert_eq!((first_monday.year, first_monday.month, first_monday.day, first_monday.weekday), (2024, 6, 3, 0));
    let dec = Day::from_days(20_088); // 2024-12-31
    let next = super::resolve_relative("10th next month", dec).unwrap();
    assert_eq!((next.year, next.month, next.day), (2025, 1, 10));
}

#[tokio::test]
async fn relative_time_through_the_registry() {
    let guest = start(None).await;
    let got = fetch(
        &guest.ctx,
        &GetterSpec { kind: "rule_relativeTime".into(), params: json!({"rules": {"relativeTime": {"from": "tomorrow"}, "expected": {"time": "{Year}-{Month0D}-{Day0D}"}}}).as_object().unwrap().clone() },
    )
    .await
    .expect("rule_relativeTime");
    let Fetched::Json(value) = got else { panic!("not JSON: {got:?}") };
    let time = value["expected"]["time"].as_str().expect("time");
    assert!(time.len() == 10 && time.as_bytes()[4] == b'-' && !time.contains('{'), "{time}");
}
