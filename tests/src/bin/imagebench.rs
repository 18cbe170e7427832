//! `imagebench`: the screenshot image path, ours against Pillow, on one 1440x900
//! desktop-like image; prints a table.
//!
//! The image is drawn here, deterministically: a gradient wallpaper, desktop icons,
//! three windows with title bars and lines of 8x8 text, a smooth "photo" area and a
//! taskbar (no random noise, which no screenshot has and JPEG handles worst). It is
//! written to a temporary PNG that both sides read. Timed, as medians of many runs:
//! - (a) full-size JPEG at quality 75 (Pillow's default quality);
//! - (b) resize to upstream's model size (1228x768) + JPEG at quality 75, with
//!   Pillow's `im.resize((w, h))` as upstream's Navi calls it (the default filter,
//!   BICUBIC) against [`fastimg::rgba_to_model_jpeg`] (Catmull-Rom, the same kernel);
//! - (c) the whole step from PNG bytes: decode, resize, JPEG.
//!
//! (a) and (b) start from decoded pixels on both sides. The `image` crate's encoder
//! and resize, which the guest used before, are timed for reference.
//!
//! Pillow runs in `python3` in the same run; without it the Pillow column says SKIPPED.
//! `imagebench --save-png PATH` also keeps a copy of the test image at PATH.
//! Run it in release mode: `cargo run --release -p arena-tests --bin imagebench`.

#![forbid(unsafe_code)]

use std::process::{Command, ExitCode};
use std::time::Instant;

use anyhow::{bail, Context};
use arena_shared::fastimg::{self, Layout, PILLOW_JPEG_QUALITY};
use font8x8::UnicodeFonts;
use image::{Rgb, RgbImage};

const WIDTH: u32 = 1440;
const HEIGHT: u32 = 900;
/// Timed runs of each operation (after warm-up runs).
const RUNS: usize = 40;
const WARMUP: usize = 3;

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("error: {err:#}");
            ExitCode::FAILURE
        }
    }
}

/// Fills the rectangle at (x, y) of size w x h, clipped to the image.
fn fill(img: &mut RgbImage, x: u32, y: u32, w: u32, h: u32, color: [u8; 3]) {
    for py in y..(y + h).min(img.height()) {
        for px in x..(x + w).min(img.width()) {
            img.put_pixel(px, py, Rgb(color));
        }
    }
}

/// Draws `text` in 8x8 glyphs with its top-left corner at (x, y), clipped to the image.
fn text(img: &mut RgbImage, x: u32, y: u32, text: &str, color: [u8; 3]) {
    for (i, c) in text.chars().enumerate() {
        let Some(glyph) = font8x8::BASIC_FONTS.get(c) else { continue };
        for (row, bits) in glyph.iter().enumerate() {
            for col in 0..8 {
                let (px, py) = (x + i as u32 * 8 + col, y + row as u32);
                if bits & (1 << col) != 0 && px < img.width() && py < img.height() {
                    img.put_pixel(px, py, Rgb(color));
                }
            }
        }
    }
}

/// Lines of window text: prose, a listing and a table, cycled.
const LINES: [&str; 12] = [
    "The quarterly report is attached; please review the totals before Friday.",
    "fn main() { let total: u64 = items.iter().map(|i| i.price).sum(); }",
    "Name            Qty    Price     Total",
    "Widget A         12    $4.50    $54.00",
    "Gadget B          3   $19.99    $59.97",
    "C:\\Users\\Docker\\Documents\\Budget 2024.xlsx   2024-03-14  18 KB",
    "Settings > System > Display > Scale and layout > 100% (Recommended)",
    "  import pandas as pd; df = pd.read_csv('sales.csv'); df.describe()",
    "Subject: Re: meeting notes -- see the action items in section 3.",
    "[OK] 154 tasks loaded, 0 failed, 12 skipped (no network).",
    "Lorem ipsum dolor sit amet, consectetur adipiscing elit, sed do eiusmod",
    "    if (x > 0 && y < height) { draw(x, y); } else { return null; }",
];

/// A window at (x, y) of size w x h: border, title bar, caption buttons, text body.
fn window(img: &mut RgbImage, (x, y, w, h): (u32, u32, u32, u32), title: &str, focused: bool, first_line: usize) {
    let (bar, title_color) = if focused { ([0, 84, 153], [255, 255, 255]) } else { ([222, 222, 222], [60, 60, 60]) };
    fill(img, x, y, w, h, [120, 120, 120]);
    fill(img, x + 1, y + 1, w - 2, h - 2, [255, 255, 255]);
    fill(img, x + 1, y + 1, w - 2, 30, bar);
    text(img, x + 12, y + 12, title, title_color);
    for (i, color) in [[196, 43, 28], [200, 200, 200], [200, 200, 200]].into_iter().enumerate() {
        fill(img, x + w - 46 * (i as u32 + 1), y + 1, 45, 30, color);
    }
    // A toolbar strip with a light gradient, then text lines.
    for py in y + 31..y + 61 {
        let v = 250 - ((py - y - 31) * 20 / 30) as u8;
        fill(img, x + 1, py, w - 2, 1, [v, v, v]);
    }
    for b in 0..8 {
        fill(img, x + 10 + b * 34, y + 36, 24, 20, [60 + 20 * b as u8, 120, 200 - 15 * b as u8]);
    }
    let mut line = first_line;
    let mut py = y + 72;
    while py + 8 < y + h - 4 {
        text(img, x + 12, py, LINES[line % LINES.len()], [20, 20, 20]);
        line += 1;
        py += 14;
    }
}

/// The deterministic 1440x900 desktop.
fn desktop() -> RgbImage {
    // Wallpaper: a diagonal blue-to-teal gradient with soft bands.
    let mut img = RgbImage::from_fn(WIDTH, HEIGHT, |x, y| {
        let t = (x + y) as f32 / (WIDTH + HEIGHT) as f32;
        let band = ((x as f32 / 90.0).sin() * (y as f32 / 70.0).cos() * 18.0) as i32;
        let c = |base: f32, span: f32| (base + span * t + band as f32).clamp(0.0, 255.0) as u8;
        Rgb([c(10.0, 40.0), c(60.0, 110.0), c(140.0, 70.0)])
    });
    // Desktop icons with labels.
    for i in 0..6 {
        let y = 20 + i * 90;
        fill(&mut img, 30, y, 48, 48, [240, 200 - 25 * i as u8, 60 + 30 * i as u8]);
        fill(&mut img, 38, y + 8, 32, 6, [255, 255, 255]);
        text(
            &mut img,
            18,
            y + 56,
            ["Recycle", "Chrome", "Edge", "VS Code", "Notes", "Excel"][i as usize],
            [255, 255, 255],
        );
    }
    window(&mut img, (140, 60, 760, 520), "Budget 2024.xlsx - Excel", false, 0);
    window(&mut img, (620, 240, 720, 540), "main.rs - Visual Studio Code", false, 5);
    // The focused window holds a smooth "photo" (a shaded sphere on a sky) and text.
    let (wx, wy, ww, wh) = (360, 150, 640, 470);
    window(&mut img, (wx, wy, ww, wh), "Photos - holiday.jpg", true, 8);
    let (px, py, pw, ph) = (wx + 12, wy + 72, 380, 260);
    for y in 0..ph {
        for x in 0..pw {
            let (dx, dy) = (x as f32 - 250.0, y as f32 - 140.0);
            let d = (dx * dx + dy * dy).sqrt() / 90.0;
            let color = if d < 1.0 {
                let shade = (1.0 - d * d).sqrt();
                [(200.0 * shade + 40.0) as u8, (90.0 * shade + 20.0) as u8, (40.0 * shade) as u8]
            } else {
                let t = y as f32 / ph as f32;
                [(120.0 + 100.0 * t) as u8, (170.0 + 60.0 * t) as u8, (235.0 - 40.0 * t) as u8]
            };
            img.put_pixel(px + x, py + y, Rgb(color));
        }
    }
    // Taskbar with buttons, the active one lighter, and a clock.
    fill(&mut img, 0, HEIGHT - 48, WIDTH, 48, [32, 32, 32]);
    for (i, label) in ["Start", "Excel", "Code", "Photos", "Terminal"].iter().enumerate() {
        let x = 8 + i as u32 * 168;
        fill(&mut img, x, HEIGHT - 42, 160, 36, if i == 3 { [96, 96, 96] } else { [64, 64, 64] });
        text(&mut img, x + 12, HEIGHT - 28, label, [240, 240, 240]);
    }
    text(&mut img, WIDTH - 100, HEIGHT - 34, "10:42 AM", [240, 240, 240]);
    text(&mut img, WIDTH - 100, HEIGHT - 20, "3/14/2024", [240, 240, 240]);
    img
}

/// The median of `runs` timed calls of `f` in milliseconds, after warm-up calls, and the
/// output size of the last call.
fn time_ms(mut f: impl FnMut() -> anyhow::Result<usize>) -> anyhow::Result<(f64, usize)> {
    for _ in 0..WARMUP {
        f()?;
    }
    let mut times = Vec::with_capacity(RUNS);
    let mut size = 0;
    for _ in 0..RUNS {
        let started = Instant::now();
        size = f()?;
        times.push(started.elapsed().as_secs_f64() * 1000.0);
    }
    times.sort_by(f64::total_cmp);
    Ok((times[RUNS / 2], size))
}

/// Pillow's side: the same operations on the same PNG, as JSON
/// `{"a": [ms, bytes], "b": [...], "c": [...], "version": "..."}`.
const PILLOW: &str = r#"
import io, json, statistics, sys, time
from PIL import Image
path, runs, warmup, w, h, q = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5]), int(sys.argv[6])
png = open(path, "rb").read()
im = Image.open(io.BytesIO(png)); im.load(); im = im.convert("RGB")
def a():
    out = io.BytesIO(); im.save(out, "JPEG", quality=q); return out.tell()
def b():
    out = io.BytesIO(); im.resize((w, h)).save(out, "JPEG", quality=q); return out.tell()
def c():
    src = Image.open(io.BytesIO(png)); src.load()
    out = io.BytesIO(); src.convert("RGB").resize((w, h)).save(out, "JPEG", quality=q); return out.tell()
def timed(f):
    for _ in range(warmup): f()
    times, size = [], 0
    for _ in range(runs):
        t = time.perf_counter(); size = f(); times.append((time.perf_counter() - t) * 1000)
    return [statistics.median(times), size]
import PIL
print(json.dumps({"a": timed(a), "b": timed(b), "c": timed(c), "version": PIL.__version__}))
"#;

/// One Pillow figure: milliseconds and bytes.
type Figure = (f64, usize);

/// Pillow's figures for (a), (b), (c) and its version, or why there are none.
fn pillow(png: &std::path::Path, to: (u32, u32)) -> Result<([Figure; 3], String), String> {
    let out = Command::new("python3")
        .arg("-c")
        .arg(PILLOW)
        .arg(png)
        .args([RUNS, WARMUP, to.0 as usize, to.1 as usize, usize::from(PILLOW_JPEG_QUALITY)].map(|n| n.to_string()))
        .output()
        .map_err(|err| format!("python3 could not be run: {err}"))?;
    if !out.status.success() {
        let stderr = String::from_utf8_lossy(&out.stderr);
        return Err(format!("python3 failed: {}", stderr.lines().last().unwrap_or("no output")));
    }
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).map_err(|err| format!("bad output: {err}"))?;
    let figure = |key: &str| -> Option<Figure> { Some((json[key][0].as_f64()?, json[key][1].as_u64()? as usize)) };
    match (figure("a"), figure("b"), figure("c")) {
        (Some(a), Some(b), Some(c)) => Ok(([a, b, c], json["version"].as_str().unwrap_or("?").to_owned())),
        _ => Err(format!("unexpected output: {json}")),
    }
}

fn run() -> anyhow::Result<()> {
    let dir = tempfile::tempdir().context("temporary directory")?;
    let png_path = dir.path().join("desktop.png");
    desktop().save(&png_path).context("writing the test PNG")?;
    let png = std::fs::read(&png_path)?;
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        match (arg.as_str(), args.next()) {
            ("--save-png", Some(path)) => std::fs::write(&path, &png).with_context(|| format!("writing {path}"))?,
            _ => bail!("usage: imagebench [--save-png PATH]"),
        }
    }
    let rgba = image::load_from_memory(&png).context("decoding the test PNG")?.into_rgba8();
    let size = fastimg::model_size(WIDTH, HEIGHT);
    if (size.width, size.height) != (1228, 768) {
        bail!("model size {}x{}, expected 1228x768", size.width, size.height);
    }
    let q = PILLOW_JPEG_QUALITY;

    let ours_a = time_ms(|| Ok(fastimg::encode_jpeg(rgba.as_raw(), WIDTH, HEIGHT, Layout::Rgba8, q)?.len()))?;
    let ours_b = time_ms(|| Ok(fastimg::rgba_to_model_jpeg(&rgba, q)?.jpeg.len()))?;
    let ours_c = time_ms(|| Ok(fastimg::png_to_model_jpeg(&png, q)?.jpeg.len()))?;

    // The image crate, as the guest encoded and resized before fastimg.
    let image_jpeg = |img: &image::RgbaImage| -> anyhow::Result<usize> {
        let rgb = image::DynamicImage::ImageRgba8(img.clone()).to_rgb8();
        let mut out = Vec::new();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, q).encode_image(&rgb)?;
        Ok(out.len())
    };
    let crate_a = time_ms(|| image_jpeg(&rgba))?;
    let crate_b = time_ms(|| {
        let small = image::imageops::resize(&rgba, size.width, size.height, image::imageops::FilterType::CatmullRom);
        image_jpeg(&small)
    })?;

    // Pillow's row cells, or the reason there are none.
    let pil = pillow(&png_path, (size.width, size.height));
    println!("imagebench: one {WIDTH}x{HEIGHT} desktop-like image ({} bytes of PNG), JPEG quality {q},", png.len());
    println!("  median of {RUNS} runs each; model size {}x{} (upstream's rule)", size.width, size.height);
    match &pil {
        Ok((_, version)) => {
            println!("  Pillow {version}: im.save(JPEG, quality={q}); im.resize((w, h)) uses its default, BICUBIC")
        }
        Err(why) => println!("!!!!! Pillow SKIPPED: {why} !!!!!"),
    }
    println!();
    println!(
        "{:<44} {:>9} {:>10} {:>14} {:>11} {:>12}",
        "operation", "ours ms", "Pillow ms", "Pillow/ours", "ours bytes", "Pillow bytes"
    );
    let rows = [
        ("(a) full-size JPEG", ours_a),
        ("(b) resize to 1228x768 (bicubic) + JPEG", ours_b),
        ("(c) PNG bytes -> decode + (b)", ours_c),
    ];
    for (i, (name, (ms, bytes))) in rows.into_iter().enumerate() {
        let (pil_ms, ratio, pil_bytes) = match &pil {
            Ok((figures, _)) => {
                let (p_ms, p_bytes) = figures[i];
                (format!("{p_ms:.2}"), format!("{:.2}x", p_ms / ms), p_bytes.to_string())
            }
            Err(_) => ("SKIPPED".to_owned(), "-".to_owned(), "-".to_owned()),
        };
        println!("{name:<44} {ms:>9.2} {pil_ms:>10} {ratio:>14} {bytes:>11} {pil_bytes:>12}");
    }
    println!();
    println!("for reference, the image crate (the guest's path before fastimg):");
    println!("{:<44} {:>9.2} ms, {} bytes", "(a) full-size JPEG", crate_a.0, crate_a.1);
    println!("{:<44} {:>9.2} ms, {} bytes", "(b) resize (CatmullRom) + JPEG", crate_b.0, crate_b.1);
    Ok(())
}
