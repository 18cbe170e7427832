//! `compare_audios`: upstream's MFCC + DTW audio similarity.
//!
//! Upstream (`metrics/vlc.py`) loads both files with `librosa.load` (mono,
//! resampled to 22 050 Hz), takes `librosa.feature.mfcc` (20 coefficients
//! from a 128-band Slaney mel spectrogram of a 2048-point, hop-512, centred
//! Hann STFT, in dB with an 80 dB floor), scales each coefficient by its
//! largest magnitude over time (`librosa.util.normalize(axis=1)`), aligns the
//! two sequences of frames with `fastdtw` (radius 1) under the cosine
//! distance, and scores `1 / (1 + distance)`.
//!
//! This is the same pipeline, written out: the decoding is symphonia's (MP3,
//! AAC/MP4, WAV, FLAC, Ogg Vorbis), the resampling a windowed-sinc filter
//! instead of soxr's, and a frame of all zeros has cosine distance 0 to
//! another zero frame and 1 to anything else (scipy would give NaN). The DTW
//! is FastDTW as the `fastdtw` package computes it, so the scores agree with
//! upstream's to within the resampler's differences: identical audio scores
//! 1, the same audio re-encoded scores close to 1, and different audio scores
//! near 0 (the distance is a sum over every aligned frame).

use std::path::Path;

use rustfft::num_complex::Complex;
use symphonia::core::audio::SampleBuffer;
use symphonia::core::codecs::{DecoderOptions, CODEC_TYPE_NULL};
use symphonia::core::errors::Error as AudioError;
use symphonia::core::formats::FormatOptions;
use symphonia::core::io::MediaSourceStream;
use symphonia::core::meta::MetadataOptions;
use symphonia::core::probe::Hint;

use super::super::{file_of, MetricError, MetricInput};
use super::{missing, parse_error};

/// librosa's default sampling rate.
const SAMPLE_RATE: u32 = 22_050;
const N_FFT: usize = 2048;
const HOP: usize = 512;
const N_MELS: usize = 128;
const N_MFCC: usize = 20;
/// The longest audio decoded, in seconds of output: an hour is far more than any task needs.
const MAX_SECONDS: usize = 3600;

/// `compare_audios(result, expected)`: see the module documentation. A missing file scores 0.
pub(super) fn compare_audios(input: &MetricInput) -> Result<f64, MetricError> {
    let expected = input.expected()?;
    if missing(&input.result) || missing(expected) {
        return Ok(0.0);
    }
    let a = mfcc_of(file_of(&input.result, "result")?)?;
    let b = mfcc_of(file_of(expected, "expected")?)?;
    if a.is_empty() || b.is_empty() {
        return Ok(0.0);
    }
    Ok(1.0 / (1.0 + fast_dtw(&a, &b, 1)))
}

/// The normalised MFCC frames of an audio file.
fn mfcc_of(path: &Path) -> Result<Vec<Vec<f64>>, MetricError> {
    let (samples, rate) = decode_mono(path)?;
    let samples = resample(&samples, rate, SAMPLE_RATE);
    let mut frames = mfcc(&samples, SAMPLE_RATE);
    normalize_rows(&mut frames);
    Ok(frames)
}

/// Decodes the first audio track to mono samples (the channel mean) and its rate.
///
/// # Errors
///
/// [`MetricError::Io`] when unreadable, [`MetricError::Parse`] for a format or codec symphonia cannot read.
pub(crate) fn decode_mono(path: &Path) -> Result<(Vec<f32>, u32), MetricError> {
    let file = std::fs::File::open(path).map_err(|source| MetricError::Io { path: path.to_owned(), source })?;
    let stream = MediaSourceStream::new(Box::new(file), Default::default());
    let mut hint = Hint::new();
    if let Some(ext) = path.extension().and_then(|e| e.to_str()) {
        hint.with_extension(ext);
    }
    // Gapless: the encoder delay and padding an MP3's LAME/Xing header (or an
    // MP4's edit list) declares are trimmed, as the decoders librosa ends up
    // using (mpg123 through libsndfile, or ffmpeg) do; without it those silent
    // frames shift and stretch the MFCC sequence.
    let format_options = FormatOptions { enable_gapless: true, ..FormatOptions::default() };
    let probed = symphonia::default::get_probe()
        .format(&hint, stream, &format_options, &MetadataOptions::default())
        .map_err(|err| parse_error(path, format!("not a readable audio file: {err}")))?;
    let mut format = probed.format;
    let track = format
        .tracks()
        .iter()
        .find(|t| t.codec_params.codec != CODEC_TYPE_NULL)
        .ok_or_else(|| parse_error(path, "no audio track"))?;
    let track_id = track.id;
    let rate = track.codec_params.sample_rate.ok_or_else(|| parse_error(path, "the audio track has no sample rate"))?;
    let mut decoder = symphonia::default::get_codecs()
        .make(&track.codec_params, &DecoderOptions::default())
        .map_err(|err| parse_error(path, format!("unsupported audio codec: {err}")))?;
    let limit = MAX_SECONDS * rate as usize;
    let mut mono = Vec::new();
    loop {
        let packet = match format.next_packet() {
            Ok(packet) => packet,
            // The end of the stream shows up as an unexpected EOF.
            Err(AudioError::IoError(err)) if err.kind() == std::io::ErrorKind::UnexpectedEof => break,
            Err(AudioError::ResetRequired) => break,
            Err(err) => return Err(parse_error(path, format!("reading audio: {err}"))),
        };
        if packet.track_id() != track_id {
            continue;
        }
        let decoded = match decoder.decode(&packet) {
            Ok(decoded) => decoded,
            // A corrupt packet is skipped, as decoders in players do.
            Err(AudioError::DecodeError(reason)) => {
                tracing::debug!(path = %path.display(), reason, "skipping an undecodable audio packet");
                continue;
            }
            Err(err) => return Err(parse_error(path, format!("decoding audio: {err}"))),
        };
        let spec = *decoded.spec();
        let channels = spec.channels.count().max(1);
        let mut buffer = SampleBuffer::<f32>::new(decoded.capacity() as u64, spec);
        buffer.copy_interleaved_ref(decoded);
        mono.extend(buffer.samples().chunks(channels).map(|frame| frame.iter().sum::<f32>() / channels as f32));
        if mono.len() >= limit {
            mono.truncate(limit);
            break;
        }
    }
    Ok((mono, rate))
}

/// Band-limited resampling with a Hann-windowed sinc (16 zero crossings each
/// side, the cut-off at the lower Nyquist frequency).
fn resample(input: &[f32], from: u32, to: u32) -> Vec<f64> {
    if from == to || input.is_empty() {
        return input.iter().map(|&s| f64::from(s)).collect();
    }
    const ZEROS: f64 = 16.0;
    let ratio = f64::from(to) / f64::from(from);
    let cutoff = ratio.min(1.0);
    let half_width = ZEROS / cutoff;
    let out_len = ((input.len() as f64) * ratio).ceil() as usize;
    (0..out_len)
        .map(|i| {
            let centre = i as f64 / ratio;
            let first = (centre - half_width).ceil().max(0.0) as usize;
            let last = ((centre + half_width).floor() as usize).min(input.len() - 1);
            let mut acc = 0.0;
            for (k, &sample) in input.iter().enumerate().take(last + 1).skip(first) {
                let t = k as f64 - centre;
                let x = t * cutoff;
                let sinc =
                    if x.abs() < 1e-12 { 1.0 } else { (std::f64::consts::PI * x).sin() / (std::f64::consts::PI * x) };
                let window = 0.5 + 0.5 * (std::f64::consts::PI * t / half_width).cos();
                acc += f64::from(sample) * sinc * window * cutoff;
            }
            acc
        })
        .collect()
}

/// Slaney's mel scale, as librosa's `hz_to_mel(htk=False)`.
fn hz_to_mel(hz: f64) -> f64 {
    const F_SP: f64 = 200.0 / 3.0;
    let logstep = 6.4f64.ln() / 27.0;
    if hz < 1000.0 {
        hz / F_SP
    } else {
        15.0 + (hz / 1000.0).ln() / logstep
    }
}

fn mel_to_hz(mel: f64) -> f64 {
    const F_SP: f64 = 200.0 / 3.0;
    let logstep = 6.4f64.ln() / 27.0;
    if mel < 15.0 {
        mel * F_SP
    } else {
        1000.0 * (logstep * (mel - 15.0)).exp()
    }
}

/// librosa's `filters.mel(sr, n_fft, n_mels=128)`: Slaney scale, Slaney (area) normalisation.
fn mel_filters(rate: u32) -> Vec<Vec<f64>> {
    let bins = N_FFT / 2 + 1;
    let fft_freqs: Vec<f64> = (0..bins).map(|k| k as f64 * f64::from(rate) / N_FFT as f64).collect();
    let (lo, hi) = (hz_to_mel(0.0), hz_to_mel(f64::from(rate) / 2.0));
    let mel_f: Vec<f64> = (0..N_MELS + 2).map(|i| mel_to_hz(lo + (hi - lo) * i as f64 / (N_MELS + 1) as f64)).collect();
    (0..N_MELS)
        .map(|m| {
            let (left, centre, right) = (mel_f[m], mel_f[m + 1], mel_f[m + 2]);
            let enorm = 2.0 / (right - left);
            fft_freqs
                .iter()
                .map(|&f| {
                    let lower = (f - left) / (centre - left);
                    let upper = (right - f) / (right - centre);
                    lower.min(upper).max(0.0) * enorm
                })
                .collect()
        })
        .collect()
}

/// librosa's `feature.mfcc(y, sr)` with its defaults: one 20-coefficient vector per frame.
fn mfcc(samples: &[f64], rate: u32) -> Vec<Vec<f64>> {
    let pad = N_FFT / 2;
    let mut padded = vec![0.0; samples.len() + 2 * pad];
    padded[pad..pad + samples.len()].copy_from_slice(samples);
    let frames = 1 + samples.len() / HOP;
    let window: Vec<f64> =
        (0..N_FFT).map(|n| 0.5 - 0.5 * (2.0 * std::f64::consts::PI * n as f64 / N_FFT as f64).cos()).collect();
    let filters = mel_filters(rate);
    let fft = rustfft::FftPlanner::<f64>::new().plan_fft_forward(N_FFT);
    let mut buffer = vec![Complex::new(0.0, 0.0); N_FFT];
    let mut mel_db = Vec::with_capacity(frames);
    for t in 0..frames {
        let start = t * HOP;
        for (n, slot) in buffer.iter_mut().enumerate() {
            *slot = Complex::new(padded.get(start + n).copied().unwrap_or(0.0) * window[n], 0.0);
        }
        fft.process(&mut buffer);
        let power: Vec<f64> = buffer[..=N_FFT / 2].iter().map(|c| c.norm_sqr()).collect();
        let bands: Vec<f64> = filters.iter().map(|f| f.iter().zip(&power).map(|(w, p)| w * p).sum::<f64>()).collect();
        mel_db.push(bands.into_iter().map(|s| 10.0 * s.max(1e-10).log10()).collect::<Vec<f64>>());
    }
    // power_to_db(top_db=80): nothing below the loudest band less 80 dB.
    let peak = mel_db.iter().flatten().copied().fold(f64::NEG_INFINITY, f64::max);
    let floor = peak - 80.0;
    let scale0 = (1.0 / N_MELS as f64).sqrt();
    let scale = (2.0 / N_MELS as f64).sqrt();
    mel_db
        .iter()
        .map(|bands| {
            let bands: Vec<f64> = bands.iter().map(|&db| db.max(floor)).collect();
            (0..N_MFCC)
                .map(|k| {
                    let sum: f64 = bands
                        .iter()
                        .enumerate()
                        .map(|(n, x)| {
                            x * (std::f64::consts::PI * k as f64 * (2.0 * n as f64 + 1.0) / (2.0 * N_MELS as f64)).cos()
                        })
                        .sum();
                    sum * if k == 0 { scale0 } else { scale }
                })
                .collect()
        })
        .collect()
}

/// `librosa.util.normalize(mfcc, axis=1)`: each coefficient divided by its
/// largest magnitude over all frames (a coefficient that is zero throughout stays).
fn normalize_rows(frames: &mut [Vec<f64>]) {
    for k in 0..N_MFCC {
        let peak = frames.iter().map(|f| f[k].abs()).fold(0.0, f64::max);
        if peak > f64::from(f32::MIN_POSITIVE) {
            for frame in frames.iter_mut() {
                frame[k] /= peak;
            }
        }
    }
}

/// scipy's cosine distance; see the module documentation for zero vectors.
fn cosine(u: &[f64], v: &[f64]) -> f64 {
    let dot: f64 = u.iter().zip(v).map(|(a, b)| a * b).sum();
    let (nu, nv) = (u.iter().map(|a| a * a).sum::<f64>().sqrt(), v.iter().map(|a| a * a).sum::<f64>().sqrt());
    match (nu == 0.0, nv == 0.0) {
        (true, true) => 0.0,
        (true, false) | (false, true) => 1.0,
        // scipy clips rounding errors into the distance's range [0, 2].
        _ => (1.0 - dot / (nu * nv)).clamp(0.0, 2.0),
    }
}

/// The `fastdtw` package's FastDTW distance between two sequences of vectors.
pub(crate) fn fast_dtw(x: &[Vec<f64>], y: &[Vec<f64>], radius: usize) -> f64 {
    fast_dtw_path(x, y, radius).0
}

/// FastDTW: the distance and the warping path (pairs of indices).
fn fast_dtw_path(x: &[Vec<f64>], y: &[Vec<f64>], radius: usize) -> (f64, Vec<(usize, usize)>) {
    let min_size = radius + 2;
    if x.len() < min_size || y.len() < min_size {
        let full: Vec<(usize, usize)> = (0..x.len()).map(|_| (0, y.len().saturating_sub(1))).collect();
        return dtw(x, y, &full);
    }
    let (xs, ys) = (reduce_by_half(x), reduce_by_half(y));
    let (_, path) = fast_dtw_path(&xs, &ys, radius);
    let window = expand_window(&path, x.len(), y.len(), radius);
    dtw(x, y, &window)
}

/// Averages of consecutive pairs (a trailing odd element is dropped, as `fastdtw` does).
fn reduce_by_half(x: &[Vec<f64>]) -> Vec<Vec<f64>> {
    x.chunks_exact(2).map(|pair| pair[0].iter().zip(&pair[1]).map(|(a, b)| (a + b) / 2.0).collect()).collect()
}

/// `fastdtw`'s `__expand_window`: the coarse path widened by `radius`, doubled
/// in resolution, then, row by row, the first contiguous run of cells at or
/// after the previous row's start. Each row is an inclusive column range.
fn expand_window(path: &[(usize, usize)], len_x: usize, len_y: usize, radius: usize) -> Vec<(usize, usize)> {
    let r = radius as i64;
    // Coarse rows, offset by `r` so that rows above the path fit.
    let coarse_rows = len_x / 2 + 1 + 2 * radius + 1;
    let mut coarse: Vec<Option<(i64, i64)>> = vec![None; coarse_rows + radius];
    for &(i, j) in path {
        for a in -r..=r {
            let row = i as i64 + a + r;
            if row < 0 || row as usize >= coarse.len() {
                continue;
            }
            let (lo, hi) = (j as i64 - r, j as i64 + r);
            let slot = &mut coarse[row as usize];
            *slot = Some(slot.map_or((lo, hi), |(l, h)| (l.min(lo), h.max(hi))));
        }
    }
    let mut window = Vec::with_capacity(len_x);
    let mut start_j: i64 = 0;
    for i in 0..len_x {
        let coarse_row = (i / 2) as i64 + r;
        let range = coarse.get(coarse_row as usize).copied().flatten().map(|(lo, hi)| (2 * lo, 2 * hi + 1));
        let clipped =
            range.map(|(lo, hi)| (lo.max(start_j).max(0), hi.min(len_y as i64 - 1))).filter(|(lo, hi)| lo <= hi);
        // A row left empty (which `fastdtw` never produces) keeps the previous start so the path stays connected.
        let (lo, hi) = clipped.unwrap_or((start_j.min(len_y as i64 - 1), start_j.min(len_y as i64 - 1)));
        window.push((lo as usize, hi as usize));
        start_j = lo;
    }
    window
}

/// Dynamic time warping restricted to `window` (for row `i`, columns
/// `window[i].0..=window[i].1`); steps from above, the left and the diagonal,
/// ties resolved in that order as `fastdtw`'s `min` does.
fn dtw(x: &[Vec<f64>], y: &[Vec<f64>], window: &[(usize, usize)]) -> (f64, Vec<(usize, usize)>) {
    let (n, m) = (x.len(), y.len());
    if n == 0 || m == 0 {
        return (f64::INFINITY, Vec::new());
    }
    // Row i of the table covers columns window[i]; `step` remembers where each cell came from.
    let mut cost: Vec<Vec<f64>> = Vec::with_capacity(n);
    let mut step: Vec<Vec<u8>> = Vec::with_capacity(n);
    let at = |cost: &Vec<Vec<f64>>, i: usize, j: usize| -> f64 {
        let (lo, hi) = window[i];
        if j < lo || j > hi {
            f64::INFINITY
        } else {
            cost[i][j - lo]
        }
    };
    for i in 0..n {
        let (lo, hi) = window[i];
        let mut row = Vec::with_capacity(hi + 1 - lo);
        let mut steps = Vec::with_capacity(hi + 1 - lo);
        for j in lo..=hi {
            let d = cosine(&x[i], &y[j]);
            if i == 0 && j == 0 {
                row.push(d);
                steps.push(3);
                continue;
            }
            let up = if i > 0 { at(&cost, i - 1, j) } else { f64::INFINITY };
            let left = if j > lo { row[j - 1 - lo] } else { f64::INFINITY };
            let diag = if i > 0 && j > 0 { at(&cost, i - 1, j - 1) } else { f64::INFINITY };
            let (best, from) = [(up, 0u8), (left, 1), (diag, 2)].into_iter().fold((f64::INFINITY, 0u8), |acc, c| {
                if c.0 < acc.0 {
                    c
                } else {
                    acc
                }
            });
            row.push(best + d);
            steps.push(from);
        }
        cost.push(row);
        step.push(steps);
    }
    let total = at(&cost, n - 1, m - 1);
    let mut path = Vec::new();
    let (mut i, mut j) = (n - 1, m - 1);
    if total.is_finite() {
        loop {
            path.push((i, j));
            let from = step[i][j - window[i].0];
            match from {
                0 => i -= 1,
                1 => j -= 1,
                2 => {
                    i -= 1;
                    j -= 1;
                }
                _ => break,
            }
        }
        path.reverse();
    }
    (total, path)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn seq(values: &[f64]) -> Vec<Vec<f64>> {
        values.iter().map(|&v| vec![1.0, v]).collect()
    }

    #[test]
    fn dtw_of_identical_sequences_is_zero_and_grows_with_difference() {
        let a = seq(&[0.0, 0.5, 1.0, 2.0, 3.0, 2.0, 1.0, 0.0, -1.0, -2.0]);
        assert!(fast_dtw(&a, &a, 1).abs() < 1e-12);
        // A stretched copy aligns with no cost.
        let stretched = seq(&[0.0, 0.0, 0.5, 0.5, 1.0, 2.0, 3.0, 3.0, 2.0, 1.0, 0.0, -1.0, -2.0]);
        assert!(fast_dtw(&a, &stretched, 1) < 1e-9);
        let other = seq(&[-2.0, -1.0, 0.0, 1.0, 2.0, 3.0, 2.0, 1.0, 0.5, 0.0]);
        assert!(fast_dtw(&a, &other, 1) > 0.5);
    }

    #[test]
    fn windows_cover_the_corners() {
        let path: Vec<(usize, usize)> = (0..5).map(|i| (i, i)).collect();
        let window = expand_window(&path, 11, 10, 1);
        assert_eq!(window.len(), 11);
        assert_eq!(window[0].0, 0);
        assert_eq!(window[10].1, 9);
        assert!(window.windows(2).all(|w| w[1].0 >= w[0].0 && w[1].0 <= w[0].1 + 1), "{window:?}");
    }

    #[test]
    fn mel_scale_round_trips() {
        for hz in [0.0, 440.0, 1000.0, 4000.0, 11_025.0] {
            assert!((mel_to_hz(hz_to_mel(hz)) - hz).abs() < 1e-6, "{hz}");
        }
        assert!((hz_to_mel(1000.0) - 15.0).abs() < 1e-12);
    }
}
