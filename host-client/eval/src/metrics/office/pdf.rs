//! `compare_pdfs(result, expected)`: the text of each PDF (all pages, ends
//! stripped) compared with rapidfuzz's `fuzz.ratio`, averaged over the pairs.
//!
//! Text comes from `pdf-extract` rather than upstream's PyMuPDF, so spacing
//! may differ from upstream's extraction; both files go through the same
//! extractor, which is what the ratio needs.

use std::collections::HashMap;
use std::path::Path;

use crate::metrics::{MetricError, MetricInput};
use crate::value::Fetched;

/// The text of every page of a PDF, with the ends stripped.
///
/// # Errors
///
/// [`MetricError::Parse`] when the file is not a readable PDF (the extractor's
/// panics on malformed files are caught and reported the same way).
fn pdf_text(path: &Path) -> Result<String, MetricError> {
    let bytes = std::fs::read(path).map_err(|source| MetricError::Io { path: path.to_owned(), source })?;
    Ok(pdf_text_of_bytes(&bytes, &path.display().to_string())?.trim().to_owned())
}

/// The text of every page of a PDF held in memory; `what` names it in errors.
///
/// # Errors
///
/// [`MetricError::Parse`] when the bytes are not a readable PDF.
pub(in crate::metrics) fn pdf_text_of_bytes(bytes: &[u8], what: &str) -> Result<String, MetricError> {
    let parse = |message: String| MetricError::Parse { what: what.to_owned(), message };
    std::panic::catch_unwind(|| pdf_extract::extract_text_from_mem(bytes))
        .map_err(|_| parse("the PDF text extractor failed on this file".into()))?
        .map_err(|err| parse(format!("not a readable PDF: {err}")))
}

fn paths(value: &Fetched) -> Vec<Option<&Path>> {
    match value {
        Fetched::List(items) => items.iter().map(Fetched::as_path).collect(),
        other => vec![other.as_path()],
    }
}

/// `compare_pdfs`: the mean of `ratio(text(result_i), text(expected_i))` over
/// the pairs; a missing file scores 0 for its pair. With a single pair, an
/// unreadable PDF is an error (so the reason is kept); in a list it counts 0.
pub(super) fn compare_pdfs(input: &MetricInput) -> Result<f64, MetricError> {
    let expected = input.expected()?;
    let (results, wanted) = (paths(&input.result), paths(expected));
    if wanted.is_empty() {
        return Err(MetricError::BadInput("compare_pdfs needs at least one expected PDF".into()));
    }
    let single = wanted.len() == 1;
    let mut total = 0.0;
    for (result, want) in results.iter().zip(&wanted) {
        let (Some(result), Some(want)) = (result, want) else { continue };
        match pdf_text(result).and_then(|a| Ok((a, pdf_text(want)?))) {
            Ok((a, b)) => total += ratio(&a, &b),
            Err(err) if single => return Err(err),
            Err(err) => tracing::warn!(%err, "compare_pdfs: pair skipped"),
        }
    }
    Ok(total / wanted.len() as f64)
}

/// rapidfuzz's `fuzz.ratio / 100`: the normalised Indel similarity of two
/// strings over Unicode scalar values, `2 * LCS / (len1 + len2)` (1 for two empty strings).
pub(super) fn ratio(a: &str, b: &str) -> f64 {
    let a: Vec<char> = a.chars().collect();
    let b: Vec<char> = b.chars().collect();
    let total = a.len() + b.len();
    if total == 0 {
        return 1.0;
    }
    2.0 * lcs_length(&a, &b) as f64 / total as f64
}

/// Length of the longest common subsequence, bit-parallel (Hyyrö): one pass
/// over `b` updating a bit vector as long as `a`, 64 characters per word.
fn lcs_length(a: &[char], b: &[char]) -> usize {
    if a.is_empty() || b.is_empty() {
        return 0;
    }
    let words = a.len().div_ceil(64);
    let mut masks: HashMap<char, Vec<u64>> = HashMap::new();
    for (i, c) in a.iter().enumerate() {
        masks.entry(*c).or_insert_with(|| vec![0; words])[i / 64] |= 1u64 << (i % 64);
    }
    let mut s = vec![u64::MAX; words];
    for c in b {
        let Some(m) = masks.get(c) else { continue };
        let mut carry = 0u64;
        for (sw, &mw) in s.iter_mut().zip(m) {
            let u = *sw & mw;
            let (sum, c1) = sw.overflowing_add(u);
            let (sum, c2) = sum.overflowing_add(carry);
            carry = u64::from(c1 || c2);
            *sw = sum | (*sw & !mw);
        }
    }
    let ones: usize = s.iter().map(|w| w.count_ones() as usize).sum();
    // Bits past the end of `a` in the last word stay set: they never match.
    let padding = words * 64 - a.len();
    a.len() - (ones - padding)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn naive_lcs(a: &[char], b: &[char]) -> usize {
        let mut dp = vec![vec![0usize; b.len() + 1]; a.len() + 1];
        for i in 1..=a.len() {
            for j in 1..=b.len() {
                dp[i][j] = if a[i - 1] == b[j - 1] { dp[i - 1][j - 1] + 1 } else { dp[i - 1][j].max(dp[i][j - 1]) };
            }
        }
        dp[a.len()][b.len()]
    }

    #[test]
    fn ratio_matches_rapidfuzz_examples() {
        assert!((ratio("this is a test", "this is a test!") - 0.965_517_241_379_310_3).abs() < 1e-12);
        assert_eq!(ratio("", ""), 1.0);
        assert_eq!(ratio("abc", ""), 0.0);
        assert_eq!(ratio("abc", "abc"), 1.0);
    }

    #[test]
    fn bit_parallel_lcs_agrees_with_the_table_across_word_boundaries() {
        let a: Vec<char> = (0..150).map(|i| char::from(b'a' + (i * 7 % 5) as u8)).collect();
        let b: Vec<char> = (0..130).map(|i| char::from(b'a' + (i * 3 % 4) as u8)).collect();
        assert_eq!(lcs_length(&a, &b), naive_lcs(&a, &b));
        assert_eq!(lcs_length(&b, &a), naive_lcs(&b, &a));
    }
}
