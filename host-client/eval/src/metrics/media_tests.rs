//! Table-driven tests of the media metrics on real files the tests make: vlcrc
//! text, PNG and JPEG images, WAV audio generated in code, zip and 7z
//! archives, keybindings files, and (when the host has ffmpeg) MP4 videos
//! ffmpeg renders from its test source.

use std::io::{Cursor, Write};
use std::path::Path;

use serde_json::{json, Value};

use super::video::{phash_of_gray32, same_video};
use crate::metrics::tests::{check, file, input, rules, Want};
use crate::value::Fetched;
use arena_test_support::pdf_showing as pdf_bytes;

/// A vlcrc as VLC writes it: sections, comments, defaults commented out.
fn vlcrc(settings: &str) -> Vec<u8> {
    format!(
        "###\n###  vlc 3.0.21\n###\n\n[qt] # Qt interface\n\n# Maximum volume displayed (integer)\n#qt-max-volume=125\n\n# Show background cone (boolean)\n#qt-bgcone=1\n\n# Start in minimal view (boolean)\n#qt-minimal-view=0\n\n# Resize interface to the native video size (boolean)\n#qt-video-autoresize=1\n\n[core]\n# Record directory\n#input-record-path=\n\n# Play/Pause (string)\n#global-key-play-pause=\n# Play/Pause (string)\n#key-play-pause=Space\n\n# Use only one instance when started from file manager (boolean)\n#one-instance-when-started-from-file=1\n{settings}"
    )
    .into_bytes()
}

#[test]
fn vlc_settings_follow_upstreams_line_rules() {
    use Want::*;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let defaults = file(d, "defaults", &vlcrc(""));
    let cases: Vec<(&str, Fetched, Value, Want)> = vec![
        (
            "check_qt_max_volume",
            file(d, "v200", &vlcrc("qt-max-volume=200\n")),
            json!({"expected_qt_max_volume": 200}),
            Score(1.0),
        ),
        (
            "check_qt_max_volume",
            file(d, "v200crlf", &vlcrc("qt-max-volume=200\r\n")),
            json!({"expected_qt_max_volume": 200}),
            Score(1.0),
        ),
        ("check_qt_max_volume", defaults.clone(), json!({"expected_qt_max_volume": 200}), Score(0.0)),
        ("check_qt_max_volume", defaults.clone(), json!({"expected_qt_max_volume": 125}), Score(1.0)),
        // Upstream only stringifies ints: a float never matches.
        (
            "check_qt_max_volume",
            file(d, "v100", &vlcrc("qt-max-volume=100\n")),
            json!({"expected_qt_max_volume": 100.0}),
            Score(0.0),
        ),
        (
            "check_qt_max_volume",
            file(d, "v100s", &vlcrc("qt-max-volume=100\n")),
            json!({"expected_qt_max_volume": "100"}),
            Score(1.0),
        ),
        ("check_qt_bgcone", file(d, "cone0", &vlcrc("qt-bgcone=0\n")), json!({"expected_qt_bgcone": 0}), Score(1.0)),
        ("check_qt_bgcone", defaults.clone(), json!({"expected_qt_bgcone": 0}), Score(0.0)),
        (
            "check_qt_minimal_view",
            file(d, "min1", &vlcrc("qt-minimal-view=1\n")),
            json!({"expected_qt_minimal_view": 1}),
            Score(1.0),
        ),
        ("check_qt_minimal_view", defaults.clone(), json!({"expected_qt_minimal_view": 1}), Score(0.0)),
        (
            "check_qt_video_resize",
            file(d, "resize0", &vlcrc("qt-video-autoresize=0\n")),
            json!({"qt-video-autoresize": 0}),
            Score(1.0),
        ),
        ("check_qt_video_resize", defaults.clone(), json!({"qt-video-autoresize": 0}), Score(0.0)),
        // A vlcrc without the line at all reads as upstream's starting value "0".
        ("check_qt_video_resize", file(d, "noresize", b"[qt]\n"), json!({"qt-video-autoresize": 0}), Score(1.0)),
        ("check_qt_video_resize", file(d, "noresize1", b"[qt]\n"), json!({"qt-video-autoresize": 1}), Score(0.0)),
        (
            "check_one_instance_when_started_from_file",
            file(d, "one0", &vlcrc("one-instance-when-started-from-file=0\n")),
            json!({"expected_one_instance_when_started_from_file": 0}),
            Score(1.0),
        ),
        (
            "check_one_instance_when_started_from_file",
            defaults.clone(),
            json!({"expected_one_instance_when_started_from_file": 0}),
            Score(0.0),
        ),
        (
            "check_global_key_play_pause",
            file(d, "gk", &vlcrc("global-key-play-pause=Ctrl+Space\n")),
            json!({"expected_global_key_play_pause": 1}),
            Score(1.0),
        ),
        ("check_global_key_play_pause", defaults.clone(), json!({"expected_global_key_play_pause": 1}), Score(0.0)),
        ("check_global_key_play_pause", defaults.clone(), json!({"expected_global_key_play_pause": 0}), Score(1.0)),
        (
            "is_vlc_recordings_folder",
            file(d, "rec", &vlcrc("input-record-path=C:\\Users\\Docker\\Desktop\n")),
            json!({"recording_file_path": "C:\\Users\\Docker\\Desktop"}),
            Score(1.0),
        ),
        (
            "is_vlc_recordings_folder",
            file(d, "rec2", &vlcrc("input-record-path=C:\\Users\\Docker\\Videos\n")),
            json!({"recording_file_path": "C:\\Users\\Docker\\Desktop"}),
            Score(0.0),
        ),
        // The commented default is skipped for the recordings folder.
        ("is_vlc_recordings_folder", defaults.clone(), json!({"recording_file_path": ""}), Score(0.0)),
        (
            "check_qt_slider_colours",
            file(d, "dark", &vlcrc("qt-slider-colours=0;0;0;20;20;20;50;50;50;99;10;10\n")),
            json!({"type": "blackish"}),
            Score(1.0),
        ),
        (
            "check_qt_slider_colours",
            file(d, "grey", &vlcrc("qt-slider-colours=0;0;0;20;20;20;50;50;50;100;10;10\n")),
            json!({"type": "blackish"}),
            Score(0.0),
        ),
        ("check_qt_slider_colours", defaults.clone(), json!({"type": "blackish"}), Score(0.0)),
        (
            "check_qt_slider_colours",
            file(d, "junk", &vlcrc("qt-slider-colours=black\n")),
            json!({"type": "blackish"}),
            Score(0.0),
        ),
        (
            "check_qt_slider_colours",
            defaults.clone(),
            json!({"type": "match", "expected_qt_slider_colours": "153;210;153;20;210;20;255;199;15;245;39;29"}),
            Score(1.0),
        ),
        (
            "check_qt_slider_colours",
            defaults.clone(),
            json!({"type": "match", "expected_qt_slider_colours": "0;0;0"}),
            Score(0.0),
        ),
        (
            "check_qt_max_volume",
            file(d, "latin1", b"qt-max-volume=\xe9\n"),
            json!({"expected_qt_max_volume": 125}),
            Error("not UTF-8"),
        ),
        ("check_qt_max_volume", Fetched::None, json!({"expected_qt_max_volume": 125}), Error("must be a file")),
        ("check_qt_max_volume", defaults.clone(), json!({"other": 1}), Error("no `expected_qt_max_volume`")),
    ];
    for (metric, result, rule, want) in cases {
        check(metric, input(result, rules(rule), json!({})), want);
    }
}

#[test]
fn keybindings_need_an_equal_entry() {
    use Want::*;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let binding =
        json!({"key": "ctrl+j", "command": "workbench.action.focusActiveEditorGroup", "when": "terminalFocus"});
    let with_comment = format!("// Place your key bindings in this file to override the defaults\n[\n  {binding}\n]\n");
    let expected = rules(json!({"expected": binding}));
    let cases = [
        (file(d, "commented.json", with_comment.as_bytes()), Score(1.0)),
        (file(d, "plain.json", format!("[{binding}]").as_bytes()), Score(1.0)),
        (file(d, "other.json", br#"[{"key": "ctrl+j", "command": "workbench.action.focusActiveEditorGroup"}]"#), Score(0.0)),
        (file(d, "extra.json", br#"[{"key": "ctrl+j", "command": "workbench.action.focusActiveEditorGroup", "when": "terminalFocus", "args": 1}]"#), Score(0.0)),
        (file(d, "empty.json", b"// Place your key bindings in this file to override the defaults\n[]"), Score(0.0)),
        (Fetched::None, Score(0.0)),
        (file(d, "broken.json", b"// comment\n[{\"key\": "), Error("not a JSON list")),
        (file(d, "object.json", br#"{"key": "ctrl+j"}"#), Error("not a JSON list")),
    ];
    for (result, want) in cases {
        check("check_json_keybindings", input(result, expected.clone(), json!({})), want);
    }
}

fn encode(image: &image::RgbImage, format: image::ImageFormat) -> Vec<u8> {
    let mut out = Cursor::new(Vec::new());
    image.write_to(&mut out, format).expect("encode");
    out.into_inner()
}

/// A scene with structure: a gradient sky, a dark disk and stripes.
fn scene(width: u32, height: u32, flipped: bool) -> image::RgbImage {
    image::RgbImage::from_fn(width, height, |x, y| {
        let y = if flipped { height - 1 - y } else { y };
        let (fx, fy) = (f64::from(x) / f64::from(width), f64::from(y) / f64::from(height));
        let disk = (fx - 0.3).powi(2) + (fy - 0.35).powi(2) < 0.04;
        let stripe = ((fx * 12.0) as u32) % 2 == 0 && fy > 0.7;
        let base = (fy * 200.0) as u8;
        if disk {
            image::Rgb([20, 20, 40])
        } else if stripe {
            image::Rgb([230, 230, 230])
        } else {
            image::Rgb([base, base / 2 + 40, 255 - base])
        }
    })
}

#[test]
fn compare_images_is_ssim_like_skimage() {
    use Want::*;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let gold = file(d, "gold.png", &encode(&scene(160, 120, false), image::ImageFormat::Png));
    let cases = [
        (file(d, "same.png", &encode(&scene(160, 120, false), image::ImageFormat::Png)), json!({}), Score(1.0)),
        (
            file(d, "same.jpg", &encode(&scene(160, 120, false), image::ImageFormat::Jpeg)),
            json!({}),
            Between(0.85, 0.999),
        ),
        // The larger image is resized down to the smaller before comparing.
        (file(d, "big.png", &encode(&scene(320, 240, false), image::ImageFormat::Png)), json!({}), Between(0.8, 1.0)),
        (
            file(d, "flipped.png", &encode(&scene(160, 120, true), image::ImageFormat::Png)),
            json!({}),
            Between(0.0, 0.5),
        ),
        (
            file(d, "same2.png", &encode(&scene(160, 120, false), image::ImageFormat::Png)),
            json!({"reference_base_result": 0.5}),
            Score(1.0),
        ),
        (
            file(d, "flipped2.png", &encode(&scene(160, 120, true), image::ImageFormat::Png)),
            json!({"reference_base_result": 0.9}),
            Score(0.0),
        ),
        (Fetched::None, json!({}), Score(0.0)),
        (
            file(d, "tiny.png", &encode(&image::RgbImage::new(5, 5), image::ImageFormat::Png)),
            json!({}),
            Error("smaller than the 7x7"),
        ),
        (file(d, "text.png", b"not an image"), json!({}), Error("not an image")),
    ];
    for (result, options, want) in cases {
        check("compare_images", input(result, Some(gold.clone()), options), want);
    }
}

#[test]
fn ssim_of_known_images() {
    let flat = image::GrayImage::from_pixel(16, 16, image::Luma([100]));
    assert_eq!(super::ssim(&flat, &flat), Ok(1.0));
    let brighter = image::GrayImage::from_pixel(16, 16, image::Luma([200]));
    // Constant images: only the luminance term remains, (2*100*200 + C1) / (100² + 200² + C1).
    let c1 = (0.01f64 * 255.0).powi(2);
    let want = (2.0 * 100.0 * 200.0 + c1) / (100.0f64.powi(2) + 200.0f64.powi(2) + c1);
    let got = super::ssim(&flat, &brighter).unwrap();
    assert!((got - want).abs() < 1e-12, "{got} vs {want}");
}

fn zip_of(entries: &[(&str, &[u8])]) -> Vec<u8> {
    let mut writer = zip::ZipWriter::new(Cursor::new(Vec::new()));
    for (name, bytes) in entries {
        writer.start_file(*name, zip::write::SimpleFileOptions::default()).expect("zip entry");
        writer.write_all(bytes).expect("zip write");
    }
    writer.finish().expect("zip finish").into_inner()
}

fn seven_zip_of(password: Option<&str>, entries: &[(&str, &[u8])]) -> Vec<u8> {
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
fn zip_archives_compare_names_and_bytes() {
    use Want::*;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let entries: [(&str, &[u8]); 2] = [("SamplePPT.pptx", b"PK fake pptx"), ("SampleText.txt", b"hello\r\n")];
    let gold = file(d, "gold.zip", &zip_of(&entries));
    let cases = [
        (file(d, "same.zip", &zip_of(&[entries[1], entries[0]])), json!({}), Score(1.0)),
        (file(d, "less.zip", &zip_of(&entries[..1])), json!({}), Score(0.0)),
        (file(d, "changed.zip", &zip_of(&[entries[0], ("SampleText.txt", b"hello\n")])), json!({}), Score(0.0)),
        (
            file(
                d,
                "nested.zip",
                &zip_of(&[("Downloads/SamplePPT.pptx", entries[0].1), ("Downloads/SampleText.txt", entries[1].1)]),
            ),
            json!({}),
            Score(0.0),
        ),
        (file(d, "same.7z", &seven_zip_of(None, &entries)), json!({}), Score(1.0)),
        (file(d, "locked.7z", &seven_zip_of(Some("pw"), &entries)), json!({"password": "pw"}), Score(1.0)),
        (file(d, "locked2.7z", &seven_zip_of(Some("pw"), &entries)), json!({}), Error("locked2.7z")),
        (Fetched::None, json!({}), Score(0.0)),
        (file(d, "text.zip", b"not a zip"), json!({}), Error("not a zip file")),
    ];
    for (result, options, want) in cases {
        check("compare_zip_files", input(result, Some(gold.clone()), options), want);
    }
}

#[test]
fn zip_pdf_entries_compare_by_extracted_text() {
    use Want::*;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let text = "Quarterly report for the northern region, all figures final";
    let gold_pdf = pdf_bytes(text);
    // Saved again: other bytes (a trailing comment), the same text.
    let mut resaved = gold_pdf.clone();
    resaved.extend_from_slice(b"% saved again\n");
    assert_ne!(gold_pdf, resaved);
    // One character changed in 60: the ratio stays above 0.95.
    let near = pdf_bytes("Quarterly report for the northern region, all figures fina1");
    let other = pdf_bytes("Minutes of the annual meeting");
    let gold = file(d, "gold.zip", &zip_of(&[("Report.PDF", &gold_pdf), ("a.txt", b"x")]));
    let cases = [
        (file(d, "same.zip", &zip_of(&[("Report.PDF", &resaved), ("a.txt", b"x")])), Score(1.0)),
        (file(d, "near.zip", &zip_of(&[("Report.PDF", &near), ("a.txt", b"x")])), Score(1.0)),
        (file(d, "other.zip", &zip_of(&[("Report.PDF", &other), ("a.txt", b"x")])), Score(0.0)),
        (file(d, "text.zip", &zip_of(&[("Report.PDF", &resaved), ("a.txt", b"y")])), Score(0.0)),
        (file(d, "broken.zip", &zip_of(&[("Report.PDF", b"%PDF-1.4 nonsense"), ("a.txt", b"x")])), Error("Report.PDF")),
    ];
    for (result, want) in cases {
        check("compare_zip_files", input(result, Some(gold.clone()), json!({})), want);
    }
}

/// A 16-bit PCM WAV file of `samples` (interleaved when `channels` is 2).
fn wav(rate: u32, channels: u16, samples: &[f64]) -> Vec<u8> {
    let data: Vec<u8> = samples.iter().flat_map(|s| ((s.clamp(-1.0, 1.0) * 32_000.0) as i16).to_le_bytes()).collect();
    let mut out = Vec::new();
    out.extend_from_slice(b"RIFF");
    out.extend_from_slice(&(36 + data.len() as u32).to_le_bytes());
    out.extend_from_slice(b"WAVEfmt ");
    out.extend_from_slice(&16u32.to_le_bytes());
    out.extend_from_slice(&1u16.to_le_bytes());
    out.extend_from_slice(&channels.to_le_bytes());
    out.extend_from_slice(&rate.to_le_bytes());
    out.extend_from_slice(&(rate * u32::from(channels) * 2).to_le_bytes());
    out.extend_from_slice(&(channels * 2).to_le_bytes());
    out.extend_from_slice(&16u16.to_le_bytes());
    out.extend_from_slice(b"data");
    out.extend_from_slice(&(data.len() as u32).to_le_bytes());
    out.extend_from_slice(&data);
    out
}

/// A little melody: notes of 0.25 s with a decaying envelope.
fn melody(rate: u32, notes: &[f64]) -> Vec<f64> {
    let per_note = rate as usize / 4;
    notes
        .iter()
        .flat_map(|&hz| {
            (0..per_note).map(move |i| {
                let t = i as f64 / f64::from(rate);
                0.6 * (-3.0 * t).exp()
                    * ((2.0 * std::f64::consts::PI * hz * t).sin() + 0.3 * (4.0 * std::f64::consts::PI * hz * t).sin())
            })
        })
        .collect()
}

#[test]
fn compare_audios_scores_mfcc_dtw_similarity() {
    use Want::*;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let tune = [262.0, 330.0, 392.0, 523.0, 392.0, 330.0, 262.0, 196.0];
    let gold = file(d, "gold.wav", &wav(22_050, 1, &melody(22_050, &tune)));
    let stereo: Vec<f64> = melody(44_100, &tune).into_iter().flat_map(|s| [s, s]).collect();
    let other = [880.0, 990.0, 1100.0, 1320.0, 1480.0, 1760.0, 1980.0, 2200.0];
    let cases = [
        (file(d, "same.wav", &wav(22_050, 1, &melody(22_050, &tune))), Between(0.999, 1.0)),
        // The same tune at 44.1 kHz in stereo: resampled and mixed down, nearly identical features.
        (file(d, "stereo.wav", &wav(44_100, 2, &stereo)), Between(0.8, 1.0)),
        (file(d, "other.wav", &wav(22_050, 1, &melody(22_050, &other))), Between(0.0, 0.05)),
        (Fetched::None, Score(0.0)),
        (file(d, "noise.wav", b"RIFF....WAVEjunk"), Error("noise.wav")),
    ];
    for (result, want) in cases {
        check("compare_audios", input(result, Some(gold.clone()), json!({})), want);
    }
}

/// `melody(22_050, TUNE)` as a 16-bit WAV, encoded by ffmpeg 5 with libmp3lame
/// at 64 kb/s (`ffmpeg -i melody.wav -codec:a libmp3lame -b:a 64k melody.mp3`):
/// its frames hold 1 408 samples of encoder delay and padding besides the
/// 44 096 of the tune, which its LAME header declares.
const MELODY_MP3: &[u8] = include_bytes!("testdata/melody.mp3");

#[test]
fn an_mp3_scores_against_its_source_wav_as_upstream_does() {
    use Want::*;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let tune = [262.0, 330.0, 392.0, 523.0, 392.0, 330.0, 262.0, 196.0];
    let source = file(d, "melody.wav", &wav(22_050, 1, &melody(22_050, &tune)));
    let mp3 = file(d, "melody.mp3", MELODY_MP3);
    // Gapless decoding drops the encoder's delay and padding, so both decode to
    // the same 44 096 samples, as librosa loads them.
    let (samples, rate) = super::audio::decode_mono(mp3.as_path().unwrap()).unwrap();
    assert_eq!((samples.len(), rate), (44_096, 22_050));
    // Upstream (librosa 0.11, fastdtw) scores this pair 0.81431; without the
    // trimming it scored 0.44 here.
    check("compare_audios", input(mp3.clone(), Some(source.clone()), json!({})), Between(0.81, 0.82));
    check("compare_audios", input(mp3.clone(), Some(mp3), json!({})), Between(0.999, 1.0));
}

#[test]
fn video_hashes_and_the_frame_rule() {
    let gray = |flipped: bool| -> Vec<u8> {
        let img = image::imageops::grayscale(&scene(32, 32, flipped));
        img.into_raw()
    };
    let (a, b) = (phash_of_gray32(&gray(false)), phash_of_gray32(&gray(true)));
    assert_eq!(phash_of_gray32(&gray(false)), a);
    assert!((a ^ b).count_ones() > 5, "a flipped frame must differ: {a:x} vs {b:x}");

    let check = |x: &[u64], y: &[u64], want: bool| assert_eq!(same_video(x, y, 100, 5), want, "{x:?} vs {y:?}");
    let base: Vec<u64> = (0..10).map(|i| 0xffff_0000_ffff_0000u64.rotate_left(i)).collect();
    check(&base, &base, true);
    check(&base, &base[..9], false);
    // Five frames off by many bits are tolerated, six are not.
    let mut five = base.clone();
    for f in five.iter_mut().take(5) {
        *f = !*f;
    }
    check(&base, &five, true);
    let mut six = base.clone();
    for f in six.iter_mut().take(6) {
        *f = !*f;
    }
    check(&base, &six, false);
    // Off by a few bits everywhere still matches.
    let close: Vec<u64> = base.iter().map(|h| h ^ 0b1_0101).collect();
    check(&base, &close, true);
    // Only the first `max_frames` count.
    assert!(same_video(&base[..3], &six[..3], 3, 5));
}

fn ffmpeg_available() -> bool {
    std::process::Command::new("ffmpeg").arg("-version").output().is_ok_and(|o| o.status.success())
}

/// Renders ffmpeg's test pattern as an H.264 MP4.
fn render(dir: &Path, name: &str, seconds: &str, filter: &str) -> Fetched {
    let path = dir.join(name);
    let status = std::process::Command::new("ffmpeg")
        .args(["-v", "error", "-y", "-f", "lavfi", "-i", &format!("testsrc=size=160x120:rate=10:duration={seconds}")])
        .args(["-vf", filter, "-pix_fmt", "yuv420p"])
        .arg(&path)
        .status()
        .expect("run ffmpeg");
    assert!(status.success(), "ffmpeg could not render {name}");
    Fetched::File(path)
}

#[test]
fn compare_videos_decodes_with_ffmpeg_or_says_it_cannot() {
    use Want::*;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    if !ffmpeg_available() {
        let a = file(d, "a.mp4", b"not decoded");
        check("compare_videos", input(a.clone(), Some(a), json!({})), Error("ffmpeg"));
        return;
    }
    let gold = render(d, "gold.mp4", "3", "null");
    let cases = [
        (render(d, "same.mp4", "3", "null"), Score(1.0)),
        (render(d, "flipped.mp4", "3", "vflip"), Score(0.0)),
        (render(d, "short.mp4", "2", "null"), Score(0.0)),
        (file(d, "text.mp4", b"not a video"), Error("ffmpeg cannot decode")),
        (Fetched::None, Score(0.0)),
    ];
    for (result, want) in cases {
        check("compare_videos", input(result, Some(gold.clone()), json!({})), want);
    }
}
