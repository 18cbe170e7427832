//! Python's `difflib.SequenceMatcher.ratio` and `get_close_matches`, on characters.
//!
//! `Computer.window_manager.switch_to_application` picks a window with
//! `difflib.get_close_matches(name, titles, n=1, cutoff=0.6)`; reproducing the
//! exact ratio (matching blocks from the longest-common-substring recursion,
//! and the "popular element" autojunk heuristic for sequences of 200+
//! characters) makes the same title win.

use std::collections::HashMap;

/// `SequenceMatcher(None, a, b).ratio()`: `2 * matches / (len(a) + len(b))`, 1.0 for two empty strings.
pub fn ratio(a: &str, b: &str) -> f64 {
    let a: Vec<char> = a.chars().collect();
    let b: Vec<char> = b.chars().collect();
    let total = a.len() + b.len();
    if total == 0 {
        return 1.0;
    }
    let matches = Matcher::new(&a, &b).matching_chars();
    2.0 * matches as f64 / total as f64
}

/// `difflib.get_close_matches(word, possibilities, n, cutoff)`: the best `n`
/// possibilities scoring at least `cutoff`, best first; ties go to the larger string,
/// as Python's `heapq.nlargest` over `(score, x)` tuples does.
pub fn get_close_matches<'a>(word: &str, possibilities: &'a [String], n: usize, cutoff: f64) -> Vec<&'a str> {
    let mut scored: Vec<(f64, &str)> =
        possibilities.iter().map(|x| (ratio(x, word), x.as_str())).filter(|(score, _)| *score >= cutoff).collect();
    scored.sort_by(|l, r| r.0.total_cmp(&l.0).then_with(|| r.1.cmp(l.1)));
    scored.into_iter().take(n).map(|(_, x)| x).collect()
}

struct Matcher<'s> {
    a: &'s [char],
    b: &'s [char],
    /// For each character of `b` that is not popular, the indices where it occurs.
    b2j: HashMap<char, Vec<usize>>,
}

impl<'s> Matcher<'s> {
    fn new(a: &'s [char], b: &'s [char]) -> Matcher<'s> {
        let mut b2j: HashMap<char, Vec<usize>> = HashMap::new();
        for (j, c) in b.iter().enumerate() {
            b2j.entry(*c).or_default().push(j);
        }
        // autojunk: in a sequence of 200 or more, an element that occurs in more
        // than 1% (plus one) of the positions is "popular" and not indexed.
        if b.len() >= 200 {
            let limit = b.len() / 100 + 1;
            b2j.retain(|_, idxs| idxs.len() <= limit);
        }
        Matcher { a, b, b2j }
    }

    /// `find_longest_match(alo, ahi, blo, bhi)` without junk (popular elements may
    /// still extend a match at its ends, as in CPython).
    fn longest_match(&self, alo: usize, ahi: usize, blo: usize, bhi: usize) -> (usize, usize, usize) {
        let (mut besti, mut bestj, mut bestsize) = (alo, blo, 0);
        let mut j2len: HashMap<usize, usize> = HashMap::new();
        for i in alo..ahi {
            let mut new_j2len: HashMap<usize, usize> = HashMap::new();
            if let Some(js) = self.b2j.get(&self.a[i]) {
                for &j in js {
                    if j < blo {
                        continue;
                    }
                    if j >= bhi {
                        break;
                    }
                    let k = j.checked_sub(1).and_then(|p| j2len.get(&p)).copied().unwrap_or(0) + 1;
                    new_j2len.insert(j, k);
                    if k > bestsize {
                        besti = i + 1 - k;
                        bestj = j + 1 - k;
                        bestsize = k;
                    }
                }
            }
            j2len = new_j2len;
        }
        while besti > alo && bestj > blo && self.a[besti - 1] == self.b[bestj - 1] {
            besti -= 1;
            bestj -= 1;
            bestsize += 1;
        }
        while besti + bestsize < ahi && bestj + bestsize < bhi && self.a[besti + bestsize] == self.b[bestj + bestsize] {
            bestsize += 1;
        }
        (besti, bestj, bestsize)
    }

    /// The total size of `get_matching_blocks()`.
    fn matching_chars(&self) -> usize {
        let mut queue = vec![(0, self.a.len(), 0, self.b.len())];
        let mut total = 0;
        // Each block found splits its range into two strictly smaller ones, so this ends.
        while let Some((alo, ahi, blo, bhi)) = queue.pop() {
            let (i, j, k) = self.longest_match(alo, ahi, blo, bhi);
            if k == 0 {
                continue;
            }
            total += k;
            if alo < i && blo < j {
                queue.push((alo, i, blo, j));
            }
            if i + k < ahi && j + k < bhi {
                queue.push((i + k, ahi, j + k, bhi));
            }
        }
        total
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ratios_match_python() {
        // Values computed with CPython's difflib.SequenceMatcher(None, a, b).ratio().
        let check = |a: &str, b: &str, expected: f64| {
            let r = ratio(a, b);
            assert!((r - expected).abs() < 1e-12, "ratio({a:?}, {b:?}) = {r}, expected {expected}");
        };
        check("abcd", "bcde", 0.75);
        check("", "", 1.0);
        check("abc", "", 0.0);
        check("Notepad", "notepad", 12.0 / 14.0);
        check("Untitled - Notepad", "Notepad", 14.0 / 25.0);
        check("Google Chrome", "Chrome", 12.0 / 19.0);
        check("private Thread", "Thread", 12.0 / 20.0);
        check("qabxcd", "abycdf", 2.0 * 4.0 / 12.0);
    }

    #[test]
    fn close_matches_pick_the_best_above_cutoff() {
        let titles: Vec<String> = ["Untitled - Notepad", "Settings", "File Explorer", "Google Chrome"]
            .iter()
            .map(|s| (*s).to_owned())
            .collect();
        assert_eq!(get_close_matches("Settings", &titles, 1, 0.6), vec!["Settings"]);
        assert_eq!(get_close_matches("setting", &titles, 1, 0.6), vec!["Settings"]);
        assert_eq!(get_close_matches("Chrome", &titles, 1, 0.6), vec!["Google Chrome"]);
        assert_eq!(get_close_matches("Notepad", &titles, 1, 0.6), Vec::<&str>::new());
        assert_eq!(get_close_matches("Explorer", &titles, 1, 0.6), vec!["File Explorer"]);
        let tie: Vec<String> = vec!["ab".into(), "ba".into()];
        // Both score 0.5 against "a"; the larger string wins the tie.
        assert_eq!(get_close_matches("a", &tie, 1, 0.5), vec!["ba"]);
    }
}
