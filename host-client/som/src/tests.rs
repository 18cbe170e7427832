//! Tests of the Set-of-Marks sources together: numbering, the candidate list,
//! the prompt image's colours, OCR on a rendered image, the fake detector and
//! OmniParser services, and the mixed modes end to end.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use arena_shared::geometry::{CoordinateSpace, Rect};
use arena_shared::observation::{A11yBackend, A11yNode, A11yTree};
use axum::extract::State;
use axum::Json;
use base64::Engine as _;
use font8x8::UnicodeFonts;
use image::{Rgba, RgbaImage};
use serde_json::{json, Value};

use super::*;

fn leaf(name: &str, x: i32, y: i32, w: i32, h: i32) -> A11yNode {
    A11yNode {
        role: "Button".into(),
        name: name.into(),
        rect: Some(Rect::new(x, y, w, h)),
        enabled: true,
        visible: true,
        ..A11yNode::default()
    }
}

fn tree(rect: Rect, children: Vec<A11yNode>) -> A11yTree {
    let window = A11yNode { children, rect: Some(rect), ..leaf("window", 0, 0, 0, 0) };
    A11yTree {
        backend: A11yBackend::Uia,
        windows: vec![window],
        truncated: false,
        node_count: 0,
        elapsed_ms: 0,
        coordinate_space: CoordinateSpace::Physical,
        windows_walked: Vec::new(),
    }
}

fn blank(w: u32, h: u32) -> RgbaImage {
    RgbaImage::from_pixel(w, h, Rgba([250, 250, 250, 255]))
}

/// A screenshot as an observation carries it.
fn frame(w: u32, h: u32) -> arena_client::frame::Frame {
    arena_client::frame::Frame::from_pixels(blank(w, h))
}

/// A listed mark as the mixed-mode tests compare it: id, type, text, colour.
type Row<'a> = (usize, &'a str, Option<&'a str>, Option<[u8; 3]>);

const BACKGROUND: Rgba<u8> = Rgba([250, 250, 250, 255]);

#[test]
fn origins_parse_from_upstreams_names() {
    for (name, origin) in [
        ("a11y", SomOrigin::A11y),
        ("oss", SomOrigin::Oss),
        ("omni", SomOrigin::Omni),
        ("mixed-oss", SomOrigin::MixedOss),
        ("mixed-omni", SomOrigin::MixedOmni),
    ] {
        assert_eq!(name.parse::<SomOrigin>(), Ok(origin));
        assert_eq!(origin.to_string(), name);
        assert_eq!(serde_json::to_value(origin).unwrap(), json!(name));
    }
    let err = "mixed".parse::<SomOrigin>().unwrap_err();
    assert!(err.contains("mixed-oss"), "{err}");
    assert_eq!(SomOrigin::default(), SomOrigin::A11y);
}

#[test]
fn candidate_list_prints_empty_names_as_upstream_and_missing_text_as_a_dash() {
    let t = tree(
        Rect::new(0, 0, 1920, 1080),
        vec![leaf("OK", 192, 108, 96, 54), leaf("", 0, 0, 1920, 1080), leaf("Half", 960, 540, 480, 270)],
    );
    let marks = marks_from_tree(&t, (1920, 1080));
    let expected = "ID | Type | Text content or description | Normalized location [x1, y1, x2, y2]\n\
        0 | a11y | OK | [0.1, 0.1, 0.15, 0.15]\n\
        1 | a11y |  | [0.0, 0.0, 1.0, 1.0]\n\
        2 | a11y | Half | [0.5, 0.5, 0.75, 0.75]\n";
    assert_eq!(marks.candidate_list(), expected);

    // A detector's box has no text key upstream: `-`. A DOM element without textContent: `None`.
    let entities = vec![
        ProposedEntity::new("icon", Rect::new(0, 0, 100, 100), None),
        ProposedEntity::dom(Rect::new(100, 100, 100, 100), None),
        ProposedEntity::new("text", Rect::new(0, 100, 100, 100), Some("File".into())),
    ];
    let marks = number(SomOrigin::Oss, entities, (200, 200));
    let list = marks.candidate_list();
    let rows: Vec<&str> = list.lines().skip(1).collect();
    assert_eq!(
        rows,
        vec![
            "0 | icon | - | [0.0, 0.0, 0.5, 0.5]",
            "1 | text/html | None | [0.5, 0.5, 1.0, 1.0]",
            "2 | text | File | [0.0, 0.5, 0.5, 1.0]"
        ]
    );
}

#[test]
fn rounding_matches_python() {
    for (v, expected) in
        [(0.125, "0.12"), (0.375, "0.38"), (1.0 / 3.0, "0.33"), (0.999, "1.0"), (0.005, "0.01"), (0.0, "0.0")]
    {
        assert_eq!(round2(v), expected, "round({v}, 2)");
    }
}

#[test]
fn prompt_colours_follow_upstreams_maps() {
    use colour::{GREEN, RED};
    assert_eq!(SomOrigin::A11y.prompt_colour("a11y"), Some(RED));
    for origin in [SomOrigin::Oss, SomOrigin::Omni, SomOrigin::MixedOss, SomOrigin::MixedOmni] {
        assert_eq!(origin.prompt_colour("icon"), Some(GREEN), "{origin}");
        assert_eq!(origin.prompt_colour("image"), Some(RED), "{origin}");
        assert_eq!(origin.prompt_colour("text"), None, "{origin}");
        assert_eq!(origin.prompt_colour("text/html"), None, "{origin}");
    }
    assert_eq!(SomOrigin::MixedOss.prompt_colour("a11y"), Some(RED));
    assert_eq!(SomOrigin::Oss.prompt_colour("a11y"), None);
}

fn pixel(annotated: &RgbaImage, x: u32, y: u32) -> Rgba<u8> {
    *annotated.get_pixel(x, y)
}

#[test]
fn every_a11y_box_is_red_with_its_label_below_right() {
    let t = tree(
        Rect::new(0, 0, 400, 200),
        vec![leaf("a", 20, 20, 60, 40), leaf("b", 200, 40, 60, 40), leaf("c", 300, 100, 60, 40)],
    );
    let marks = marks_from_tree(&t, (400, 200));
    let annotated = annotate(&blank(400, 200), &marks);
    let red = Rgba([255, 0, 0, 255]);
    for m in &marks.entities {
        let (x, y) = (m.rect.x as u32, m.rect.y as u32);
        // The outline's top-left pixels and the inclusive right edge at x + w.
        assert_eq!(pixel(&annotated, x, y), red, "mark {}", m.id);
        assert_eq!(pixel(&annotated, x + 1, y + 10), red, "mark {}", m.id);
        assert_eq!(pixel(&annotated, m.rect.right() as u32, y + 10), red, "mark {}", m.id);
        assert_eq!(pixel(&annotated, x + 30, y + 20), BACKGROUND, "inside mark {}", m.id);
    }
    // Mark 0's label: 18x12 below the box, its right edge at the box's (x 62..=80, y 60..=72),
    // red with white glyph pixels.
    let img = &annotated;
    assert_eq!(img.get_pixel(63, 71), &red);
    let white =
        (60..72).flat_map(|y| (62..80).map(move |x| (x, y))).any(|(x, y)| img.get_pixel(x, y) == &Rgba([255; 4]));
    assert!(white, "no label glyphs below the box");
    // Nothing above the box.
    assert_eq!(img.get_pixel(70, 15), &BACKGROUND);
}

#[test]
fn pixel_modes_draw_icons_green_images_red_and_leave_text_undrawn() {
    let entities = vec![
        ProposedEntity::new("icon", Rect::new(10, 10, 40, 40), None),
        ProposedEntity::new("image", Rect::new(100, 10, 40, 40), None),
        ProposedEntity::new("text", Rect::new(200, 10, 40, 40), Some("word".into())),
    ];
    let marks = number(SomOrigin::Oss, entities, (300, 100));
    assert_eq!(marks.entities.len(), 3, "text is listed");
    let annotated = annotate(&blank(300, 100), &marks);
    assert_eq!(pixel(&annotated, 10, 10), Rgba([0, 128, 0, 255]));
    assert_eq!(pixel(&annotated, 100, 10), Rgba([255, 0, 0, 255]));
    assert_eq!(pixel(&annotated, 200, 10), BACKGROUND);
}

#[test]
fn annotate_scales_to_a_downscaled_screenshot() {
    let marks = marks_from_tree(&tree(Rect::new(0, 0, 400, 200), vec![leaf("box", 200, 80, 120, 80)]), (400, 200));
    let annotated = annotate(&blank(200, 100), &marks);
    assert_eq!(pixel(&annotated, 160, 80), Rgba([255, 0, 0, 255]));
    assert_eq!(pixel(&annotated, 100, 40), Rgba([255, 0, 0, 255]));
}

#[test]
fn annotate_leaves_the_observations_pixels_alone() {
    let marks = marks_from_tree(&tree(Rect::new(0, 0, 400, 200), vec![leaf("box", 200, 80, 120, 80)]), (400, 200));
    let shot = blank(400, 200);
    let annotated = annotate(&shot, &marks);
    assert_eq!(pixel(&annotated, 200, 80), Rgba([255, 0, 0, 255]));
    assert_eq!(pixel(&shot, 200, 80), BACKGROUND, "the previous-step image must stay unannotated");
}

// ---- OCR ----

/// Draws `text` in black with the 8x8 font at `scale` on a white image.
fn render_words(img: &mut RgbaImage, x0: u32, y0: u32, text: &str, scale: u32) {
    for (i, c) in text.chars().enumerate() {
        let Some(rows) = font8x8::BASIC_FONTS.get(c) else { continue };
        for (row, bits) in rows.iter().enumerate() {
            for col in 0..8u32 {
                if bits & (1 << col) != 0 {
                    for dy in 0..scale {
                        for dx in 0..scale {
                            let x = x0 + (i as u32 * 8 + col) * scale + dx;
                            let y = y0 + row as u32 * scale + dy;
                            img.put_pixel(x, y, Rgba([0, 0, 0, 255]));
                        }
                    }
                }
            }
        }
    }
}

/// Whether Tesseract is here; a counted skip (or a failure under ARENA_REQUIRE_TESSERACT=1) when not.
fn tesseract_or_skip(test: &str) -> bool {
    arena_test_support::program_or_skip(
        test,
        ocr::DEFAULT_PROGRAM,
        &["--version"],
        "tesseract not found",
        "ARENA_REQUIRE_TESSERACT",
    )
}

#[tokio::test]
async fn ocr_finds_rendered_words_where_they_were_drawn() {
    if !tesseract_or_skip("ocr_finds_rendered_words_where_they_were_drawn") {
        return;
    }
    let mut img = RgbaImage::from_pixel(900, 400, Rgba([255, 255, 255, 255]));
    // 40-pixel glyphs (the 8x8 font at scale 5), words far apart.
    // (The blocky font makes Tesseract misread some letters; these words it reads.)
    let drawn = [("FILE", 60, 60), ("SAVE", 500, 260), ("Hello", 300, 160)];
    for (word, x, y) in drawn {
        render_words(&mut img, x as u32, y as u32, word, 5);
    }
    let words = ocr::recognise(ocr::DEFAULT_PROGRAM, &img, Duration::from_secs(60)).await.expect("ocr");
    let find = |w: &str| {
        words
            .iter()
            .find(|e| e.text.as_deref().map(str::trim) == Some(w))
            .unwrap_or_else(|| panic!("{w} not found in {words:?}"))
    };
    for (word, x, y) in drawn {
        let e = find(word);
        assert_eq!(e.kind, "text");
        // Drawn at (x, y), 40 pixels per letter (the glyphs' ink is a little smaller).
        let r = e.rect;
        let width = 40 * word.len() as i32;
        assert!((r.x - x).abs() <= 12 && (r.y - y).abs() <= 12, "{word} at {r:?}");
        assert!((r.width - width).abs() <= 24 && (r.height - 40).abs() <= 12, "{word} sized {r:?}");
    }
}

#[test]
fn tsv_rows_become_word_entities_as_pytesseract_reads_them() {
    let tsv = "level\tpage_num\tblock_num\tpar_num\tline_num\tword_num\tleft\ttop\twidth\theight\tconf\ttext\n\
        1\t1\t0\t0\t0\t0\t0\t0\t900\t400\t-1\t\n\
        4\t1\t1\t1\t1\t0\t60\t60\t200\t40\t-1\t\n\
        5\t1\t1\t1\t1\t1\t60\t60\t200\t40\t96.42\tHELLO\n\
        5\t1\t2\t1\t1\t1\t500\t260\t199\t41\t0\tW0RLD\n\
        5\t1\t3\t1\t1\t1\t10\t10\t5\t5\t12.5";
    let words = ocr::parse_tsv(tsv);
    let got: Vec<(Rect, Option<&str>)> = words.iter().map(|e| (e.rect, e.text.as_deref())).collect();
    assert_eq!(
        got,
        vec![
            (Rect::new(60, 60, 200, 40), Some("HELLO")),
            // Confidence 0 is kept: only -1 is left out.
            (Rect::new(500, 260, 199, 41), Some("W0RLD")),
            // The last row without its text column, as pytesseract pads it.
            (Rect::new(10, 10, 5, 5), Some("")),
        ]
    );
    assert!(ocr::parse_tsv("").is_empty());
}

#[test]
fn tesseract_is_called_as_pytesseract_calls_it() {
    let args: Vec<String> = ocr::command_args(std::path::Path::new("shot.png"))
        .into_iter()
        .map(|a| a.to_string_lossy().into_owned())
        .collect();
    assert_eq!(args, ["shot.png", "stdout", "--psm", "11", "--oem", "3", "tsv"]);
}

#[tokio::test]
async fn a_missing_tesseract_is_a_clear_error() {
    let err = ocr::recognise("arena-no-such-tesseract", &blank(10, 10), Duration::from_secs(5)).await.unwrap_err();
    let text = err.to_string();
    assert!(matches!(err, SomError::Ocr(_)) && text.contains("not found") && text.contains("tesseract-ocr"), "{text}");
}

// ---- the fake services ----

#[derive(Debug, Default)]
struct Seen(Mutex<Vec<Value>>);

/// Serves `router` on a free port; its base URL.
async fn serve(router: axum::Router) -> String {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.expect("bind");
    let addr = listener.local_addr().expect("addr");
    tokio::spawn(async move { axum::serve(listener, router).await.expect("serve") });
    format!("http://{addr}")
}

/// A Grounding DINO service: answers each prompt with fixed boxes and records the requests.
async fn fake_detector(seen: Arc<Seen>) -> String {
    async fn detect(State(seen): State<Arc<Seen>>, Json(body): Json<Value>) -> Json<Value> {
        let prompt = body["prompt"].as_str().unwrap_or_default().to_owned();
        seen.0.lock().unwrap().push(body);
        Json(match prompt.as_str() {
            // Truncated to (100, 50, 140, 80), grown by 10.
            "icon" => json!({"boxes": [
                {"box": [100.7, 50.2, 140.9, 80.99], "score": 0.31, "phrase": "icon"},
                // 400 x 300 = 120000 > 5 % of 1000 x 600 (30000): dropped.
                {"box": [0, 0, 400, 300], "score": 0.9, "phrase": "icon"},
                // At the corner: clamped to the image.
                {"box": [995, 595, 1000, 600]}
            ]}),
            _ => json!({"boxes": [{"box": [500, 300, 560, 340], "score": 0.2}]}),
        })
    }
    serve(axum::Router::new().route("/detect", axum::routing::post(detect)).with_state(seen)).await
}

#[tokio::test]
async fn the_detector_client_speaks_the_documented_shape_and_post_processes_as_upstream() {
    let seen = Arc::new(Seen::default());
    let url = fake_detector(Arc::clone(&seen)).await;
    let shot = frame(1000, 600);
    let http = reqwest::Client::new();
    let params = detector::DetectorParams::default();
    let entities =
        detector::detect_all(&http, &format!("{url}/"), &shot.encoded, (1000, 600), &params).await.expect("detect");
    let got: Vec<(&str, Rect, Option<&str>)> =
        entities.iter().map(|e| (e.kind.as_str(), e.rect, e.text.as_deref())).collect();
    assert_eq!(
        got,
        vec![
            ("icon", Rect::new(90, 40, 60, 50), None),
            ("icon", Rect::new(985, 585, 15, 15), None),
            ("image", Rect::new(490, 290, 80, 60), None),
        ]
    );
    let requests = seen.0.lock().unwrap().clone();
    let prompts: Vec<&str> = requests.iter().map(|r| r["prompt"].as_str().unwrap()).collect();
    assert_eq!(prompts, ["icon", "image"]);
    assert_eq!(
        (requests[0]["box_threshold"].as_f64(), requests[0]["text_threshold"].as_f64()),
        (Some(0.03), Some(0.4))
    );
    let image = base64::engine::general_purpose::STANDARD.decode(requests[0]["image"].as_str().unwrap()).unwrap();
    assert_eq!(image, *shot.encoded);
}

#[tokio::test]
async fn a_failing_detector_names_itself_and_its_url() {
    let url = serve(axum::Router::new().route(
        "/detect",
        axum::routing::post(|| async { (axum::http::StatusCode::INTERNAL_SERVER_ERROR, "CUDA out of memory") }),
    ))
    .await;
    let err =
        detector::detect_all(&reqwest::Client::new(), &url, &frame(10, 10).encoded, (10, 10), &Default::default())
            .await
            .unwrap_err();
    let text = err.to_string();
    assert!(
        text.contains("Grounding DINO") && text.contains("/detect") && text.contains("CUDA out of memory"),
        "{text}"
    );
}

/// OmniParser's server: `POST /parse/` answering a fixed parse, recording the requests.
async fn fake_omniparser(seen: Arc<Seen>) -> String {
    async fn parse(State(seen): State<Arc<Seen>>, Json(body): Json<Value>) -> Json<Value> {
        seen.0.lock().unwrap().push(body);
        Json(json!({
            "som_image_base64": "iVBORw0KGgo=",
            "parsed_content_list": [
                {"type": "icon", "bbox": [0.5, 0.5, 0.55, 0.6], "interactivity": true, "content": "Settings gear", "source": "box_yolo_content_yolo"},
                {"type": "text", "bbox": [0.1, 0.1, 0.3, 0.15], "interactivity": false, "content": "File name", "source": "box_ocr_content_ocr"},
                {"type": "icon", "bbox": [0.0, 0.0, 0.02, 0.03], "interactivity": true, "content": null, "source": "box_yolo_content_yolo"}
            ],
            "latency": 0.42
        }))
    }
    serve(axum::Router::new().route("/parse/", axum::routing::post(parse)).with_state(seen)).await
}

#[tokio::test]
async fn the_omniparser_client_speaks_its_servers_shape() {
    let seen = Arc::new(Seen::default());
    let url = fake_omniparser(Arc::clone(&seen)).await;
    let shot = frame(1000, 600);
    let entities = omni::parse(&reqwest::Client::new(), &url, &shot.encoded, (1000, 600)).await.expect("parse");
    let got: Vec<(&str, Rect, Option<&str>)> =
        entities.iter().map(|e| (e.kind.as_str(), e.rect, e.text.as_deref())).collect();
    assert_eq!(
        got,
        vec![
            // Text first, as upstream lists them; x, y, w, h each truncated.
            ("text", Rect::new(100, 60, 200, 30), Some("File name")),
            ("icon", Rect::new(500, 300, 50, 60), Some("Settings gear")),
            ("icon", Rect::new(0, 0, 20, 18), Some("")),
        ]
    );
    let body = seen.0.lock().unwrap()[0].clone();
    let image = base64::engine::general_purpose::STANDARD.decode(body["base64_image"].as_str().unwrap()).unwrap();
    assert_eq!(image, *shot.encoded);
}

// ---- the origins end to end ----

fn sources(config: SomConfig) -> SomSources {
    SomSources::new(config).expect("sources")
}

#[test]
fn origins_that_need_a_service_refuse_to_start_without_its_url() {
    let config = |origin| SomConfig { origin, ..SomConfig::default() };
    for (origin, flag) in [
        (SomOrigin::Oss, "--detector-url"),
        (SomOrigin::MixedOss, "--detector-url"),
        (SomOrigin::Omni, "--omniparser-url"),
        (SomOrigin::MixedOmni, "--omniparser-url"),
    ] {
        let err = SomSources::new(config(origin)).unwrap_err().to_string();
        assert!(err.contains(flag) && err.contains(origin.name()), "{err}");
    }
    assert!(SomSources::new(config(SomOrigin::A11y)).is_ok());
}

#[tokio::test]
async fn a11y_without_a_tree_has_no_marks_and_with_one_matches_marks_from_tree() {
    let s = sources(SomConfig::default());
    let shot = frame(400, 200);
    let input = SomInput { tree: None, screenshot: &shot, size: (400, 200), dom: &[] };
    assert_eq!(s.marks(&input).await.unwrap(), None);
    let t = tree(Rect::new(0, 0, 400, 200), vec![leaf("a", 10, 10, 50, 20)]);
    let input = SomInput { tree: Some(&t), ..input };
    assert_eq!(s.marks(&input).await.unwrap(), Some(marks_from_tree(&t, (400, 200))));
}

#[tokio::test]
async fn omni_and_mixed_omni_merge_as_upstream() {
    let url = fake_omniparser(Arc::new(Seen::default())).await;
    let shot = frame(1000, 600);
    // The a11y tree: a square button over OmniParser's gear icon, a wide text field, an
    // off-screen element clipped away, and a zero-size one that mixed modes drop.
    let t = tree(
        Rect::new(0, 0, 1000, 600),
        vec![
            leaf("Gear", 495, 295, 60, 62),
            leaf("Name field", 90, 200, 300, 30),
            leaf("Edge", 990, 10, 40, 40),
            leaf("Nothing", 0, 0, 0, 0),
        ],
    );
    let config = |origin| SomConfig { origin, omniparser_url: Some(url.clone()), ..SomConfig::default() };
    let input = SomInput { tree: Some(&t), screenshot: &shot, size: (1000, 600), dom: &[] };

    let omni = sources(config(SomOrigin::Omni)).marks(&input).await.unwrap().unwrap();
    let rows: Vec<(usize, &str, Option<&str>)> =
        omni.entities.iter().map(|m| (m.id, m.kind.as_str(), m.given_text())).collect();
    assert_eq!(rows, vec![(0, "text", Some("File name")), (1, "icon", Some("Settings gear")), (2, "icon", Some(""))]);

    let mixed = sources(config(SomOrigin::MixedOmni)).marks(&input).await.unwrap().unwrap();
    let rows: Vec<Row> = mixed.entities.iter().map(|m| (m.id, m.kind.as_str(), m.given_text(), m.colour)).collect();
    assert_eq!(
        rows,
        vec![
            // a11y first, re-typed by shape; "Edge" is clipped to 10 x 40 and is text.
            (0, "icon", Some("Gear"), Some(colour::GREEN)),
            (1, "text", Some("Name field"), None),
            (2, "text", Some("Edge"), None),
            // Then OmniParser's entities the a11y boxes do not cover: the gear is covered.
            (3, "text", Some("File name"), None),
            (4, "icon", Some(""), Some(colour::GREEN)),
        ]
    );
    assert_eq!(mixed.rects[2], [990, 10, 1000, 50]);
    assert_eq!(mixed.rects.len(), 5);
}

/// A stand-in `tesseract` that records its arguments and prints a fixed TSV.
#[cfg(unix)]
fn fake_tesseract(dir: &std::path::Path) -> String {
    use std::os::unix::fs::PermissionsExt;
    let script = dir.join("tesseract");
    let args = dir.join("args");
    let body = format!(
        "#!/bin/sh\nprintf '%s\\n' \"$@\" > '{}'\n\
         printf 'level\\tpage_num\\tblock_num\\tpar_num\\tline_num\\tword_num\\tleft\\ttop\\twidth\\theight\\tconf\\ttext\\n'\n\
         printf '5\\t1\\t1\\t1\\t1\\t1\\t100\\t55\\t30\\t15\\t90\\tcovered\\n'\n\
         printf '5\\t1\\t1\\t1\\t1\\t1\\t600\\t500\\t80\\t20\\t91\\tSave\\n'\n",
        args.display()
    );
    std::fs::write(&script, body).unwrap();
    std::fs::set_permissions(&script, std::fs::Permissions::from_mode(0o755)).unwrap();
    script.to_string_lossy().into_owned()
}

#[cfg(unix)]
#[tokio::test]
async fn oss_and_mixed_oss_order_dom_detector_ocr_and_merge_as_upstream() {
    let dir = tempfile::tempdir().unwrap();
    let tesseract = fake_tesseract(dir.path());
    let url = fake_detector(Arc::new(Seen::default())).await;
    let shot = frame(1000, 600);
    let dom = vec![ProposedEntity::dom(Rect::new(700, 100, 200, 30), Some("Sign in".into()))];
    // An a11y button over the detector's first icon (90, 40, 60, 50) and the first OCR word.
    let t = tree(Rect::new(0, 0, 1000, 600), vec![leaf("Back", 85, 35, 70, 60)]);
    let config = |origin| SomConfig {
        origin,
        detector_url: Some(url.clone()),
        tesseract: tesseract.clone(),
        ..SomConfig::default()
    };
    let input = SomInput { tree: Some(&t), screenshot: &shot, size: (1000, 600), dom: &dom };

    let oss = sources(config(SomOrigin::Oss)).marks(&input).await.unwrap().unwrap();
    let rows: Vec<(usize, &str, Option<&str>)> =
        oss.entities.iter().map(|m| (m.id, m.kind.as_str(), m.given_text())).collect();
    assert_eq!(
        rows,
        vec![
            (0, "text/html", Some("Sign in")),
            (1, "icon", None),
            (2, "icon", None),
            (3, "image", None),
            (4, "text", Some("covered")),
            (5, "text", Some("Save")),
        ]
    );
    let args = std::fs::read_to_string(dir.path().join("args")).unwrap();
    let args: Vec<&str> = args.lines().skip(1).collect();
    assert_eq!(args, ["stdout", "--psm", "11", "--oem", "3", "tsv"]);

    let mixed = sources(config(SomOrigin::MixedOss)).marks(&input).await.unwrap().unwrap();
    let rows: Vec<Row> = mixed.entities.iter().map(|m| (m.id, m.kind.as_str(), m.given_text(), m.colour)).collect();
    assert_eq!(
        rows,
        vec![
            (0, "a11y", Some("Back"), Some(colour::RED)),
            (1, "text/html", Some("Sign in"), None),
            (2, "icon", None, Some(colour::GREEN)),
            (3, "image", None, Some(colour::RED)),
            (4, "text", Some("Save"), None),
        ]
    );
}
