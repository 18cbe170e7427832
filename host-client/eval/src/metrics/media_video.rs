//! `compare_videos`: upstream's frame-by-frame perceptual-hash comparison.
//!
//! Upstream (`metrics/vlc.py`) reads both videos with OpenCV frame by frame,
//! up to `max_frames_to_check` (100) frames: when one video ends, it scores
//! whether both ended together; otherwise it counts the frames whose
//! perceptual hashes (`imagehash.phash`) differ by more than `threshold` (5)
//! bits, and scores 0 once more than `threshold` frames differ; 1 otherwise.
//!
//! No pure-Rust decoder reads the H.264 MP4 files the corpus uses, so the
//! frames come from the host's `ffmpeg` (the `ARENA_FFMPEG` variable, else
//! `ffmpeg` on `PATH`): it decodes the first video stream (rotation metadata
//! applied, as OpenCV does), converts each frame to grayscale and scales it to
//! 32×32 with Lanczos, exactly the image `phash` hashes. The hash itself and
//! the scoring rule are computed here as upstream does. Without ffmpeg the
//! metric fails with a message saying so (scored 0). A file ffmpeg cannot
//! decode is an error too, where upstream would read zero frames (and score
//! two unreadable files as equal).

use std::path::Path;
use std::process::{Command, Stdio};

use serde_json::Value;

use super::super::{file_of, score, MetricError, MetricInput};
use super::{missing, parse_error};

/// The side of the image `phash` hashes (hash size 8 × high-frequency factor 4).
const HASH_IMAGE: usize = 32;
/// The low-frequency corner of the DCT kept in the hash.
const HASH_SIZE: usize = 8;

/// `compare_videos(result, expected, max_frames_to_check=100, threshold=5)`.
pub(super) fn compare_videos(input: &MetricInput) -> Result<f64, MetricError> {
    let expected = input.expected()?;
    if missing(&input.result) || missing(expected) {
        return Ok(0.0);
    }
    let option = |key: &str, default: usize| -> Result<usize, MetricError> {
        match input.options.get(key) {
            None => Ok(default),
            Some(Value::Number(n)) => n
                .as_u64()
                .and_then(|n| usize::try_from(n).ok())
                .ok_or_else(|| MetricError::BadInput(format!("`{key}` must be a non-negative integer, not {n}"))),
            Some(other) => Err(MetricError::BadInput(format!("`{key}` must be a non-negative integer, not {other}"))),
        }
    };
    let max_frames = option("max_frames_to_check", 100)?;
    let threshold = option("threshold", 5)?;
    let a = frame_hashes(file_of(&input.result, "result")?, max_frames)?;
    let b = frame_hashes(file_of(expected, "expected")?, max_frames)?;
    Ok(score(same_video(&a, &b, max_frames, threshold)))
}

/// Upstream's loop over the two hash sequences (each at most `max_frames` long).
pub(crate) fn same_video(a: &[u64], b: &[u64], max_frames: usize, threshold: usize) -> bool {
    let mut mismatches = 0;
    for i in 0..max_frames {
        let (more_a, more_b) = (i < a.len(), i < b.len());
        if !more_a || !more_b {
            return more_a == more_b;
        }
        if (a[i] ^ b[i]).count_ones() as usize > threshold {
            mismatches += 1;
            if mismatches > threshold {
                return false;
            }
        }
    }
    true
}

/// The ffmpeg program to run.
fn ffmpeg_program() -> std::ffi::OsString {
    std::env::var_os("ARENA_FFMPEG").filter(|p| !p.is_empty()).unwrap_or_else(|| "ffmpeg".into())
}

/// The perceptual hashes of the first `max_frames` frames of a video.
fn frame_hashes(path: &Path, max_frames: usize) -> Result<Vec<u64>, MetricError> {
    if max_frames == 0 {
        return Ok(Vec::new());
    }
    let program = ffmpeg_program();
    let output = Command::new(&program)
        .args(["-v", "error", "-nostdin", "-i"])
        .arg(path)
        .args(["-map", "0:v:0", "-frames:v", &max_frames.to_string()])
        .args(["-vf", &format!("format=gray,scale={HASH_IMAGE}:{HASH_IMAGE}:flags=lanczos"), "-f", "rawvideo", "-pix_fmt", "gray", "-"])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .output()
        .map_err(|err| {
            MetricError::BadInput(format!(
                "compare_videos decodes frames with ffmpeg, which could not be run ({}: {err}); install ffmpeg or set ARENA_FFMPEG",
                program.to_string_lossy()
            ))
        })?;
    if !output.status.success() {
        let stderr = String::from_utf8_lossy(&output.stderr);
        return Err(parse_error(path, format!("ffmpeg cannot decode its video: {}", stderr.trim())));
    }
    Ok(output.stdout.chunks_exact(HASH_IMAGE * HASH_IMAGE).map(phash_of_gray32).collect())
}

/// `imagehash.phash` of a 32×32 grayscale image (row-major bytes): the 2-D
/// DCT-II, its top-left 8×8 corner, each bit set where the coefficient
/// exceeds the corner's median (bit 63 first, in row-major order).
pub(crate) fn phash_of_gray32(pixels: &[u8]) -> u64 {
    let n = HASH_IMAGE;
    let cos: Vec<f64> = (0..HASH_SIZE * n)
        .map(|i| ((std::f64::consts::PI * (i / n) as f64 * (2.0 * (i % n) as f64 + 1.0)) / (2.0 * n as f64)).cos())
        .collect();
    // DCT along the columns (axis 0) for the first 8 frequencies, then along the rows.
    let mut cols = vec![0.0; HASH_SIZE * n];
    for k in 0..HASH_SIZE {
        for x in 0..n {
            cols[k * n + x] = (0..n).map(|y| f64::from(pixels[y * n + x]) * cos[k * n + y]).sum::<f64>() * 2.0;
        }
    }
    let mut low = [0.0f64; HASH_SIZE * HASH_SIZE];
    for k in 0..HASH_SIZE {
        for l in 0..HASH_SIZE {
            low[k * HASH_SIZE + l] = (0..n).map(|x| cols[k * n + x] * cos[l * n + x]).sum::<f64>() * 2.0;
        }
    }
    let mut sorted = low;
    sorted.sort_by(f64::total_cmp);
    let median = (sorted[31] + sorted[32]) / 2.0;
    low.iter().fold(0u64, |bits, &c| (bits << 1) | u64::from(c > median))
}
