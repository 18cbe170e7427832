//! Expected against received: a case's [`Expected`] events against the recorder's
//! [`Recorded`] lines of that case, and the log cut into cases at the separator key.
//!
//! The rules: received points are moved from the recorder's client coordinates to the
//! screen by the origin of its `ready` line; mouse moves are left out unless the case
//! expects some, and then an expected move is any received move to that point before
//! the next expected event; every other event must come in order and equal the
//! expected one (its modifiers always, its extended bit, scan code and wheel point
//! when the expectation names them); an event left over is a mismatch too.

use arena_shared::input_log::{Mods, Recorded};
use arena_shared::vkeys;

use crate::expect::{shown_text, Expected};

/// The key pressed between cases (`F24`, which no case uses); its down and up are
/// where the log is cut.
pub const SEPARATOR_KEY: &str = "f24";

/// How a case's events differ from what it expects: the first place they part.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct Difference {
    /// Index of the expected event where they part (the length of the list when
    /// received events are left over).
    pub at: usize,
    /// The expected event there, in the catalogue's notation (empty when none is left).
    pub expected: String,
    /// What was received there instead (empty when nothing was).
    pub received: String,
}

/// A received line in the expectations' notation (screen points), for messages.
pub fn describe(record: &Recorded, origin: (i32, i32)) -> String {
    match observed(record, origin) {
        Some(event) => event.to_string(),
        None => format!("{record:?}"),
    }
}

/// A received record as the event it is in screen coordinates (`None` for the
/// `ready` line and unknown ones), with its scan code and extended bit filled in.
fn observed(record: &Recorded, origin: (i32, i32)) -> Option<Expected> {
    let at = |x: i32, y: i32| (x + origin.0, y + origin.1);
    Some(match record {
        Recorded::Key { down, sys, vk, scan, extended, mods, .. } => {
            Expected::Key { down: *down, vk: *vk, sys: *sys, mods: *mods, extended: Some(*extended), scan: Some(*scan) }
        }
        Recorded::Char { text, sys, mods, .. } => Expected::Char { text: text.clone(), sys: *sys, mods: *mods },
        Recorded::Button { button, press, x, y, mods, .. } => {
            Expected::Button { button: *button, press: *press, at: at(*x, *y), mods: *mods }
        }
        Recorded::Move { x, y, .. } => Expected::Move { at: at(*x, *y) },
        Recorded::Wheel { horizontal, delta, x, y, mods, .. } => {
            Expected::Wheel { horizontal: *horizontal, delta: *delta, at: Some(at(*x, *y)), mods: *mods }
        }
        Recorded::Ready { .. } | Recorded::Unknown => return None,
    })
}

/// Whether `got` is what `want` asks for (fields `want` leaves open match anything).
fn matches(want: &Expected, got: &Expected) -> bool {
    match (want, got) {
        (
            Expected::Key { down, vk, sys, mods, extended, scan },
            Expected::Key { down: d, vk: v, sys: s, mods: m, extended: e, scan: sc },
        ) => {
            down == d
                && vk == v
                && sys == s
                && mods == m
                && extended.is_none_or(|x| Some(x) == *e)
                && scan.is_none_or(|x| Some(x) == *sc)
        }
        (
            Expected::Wheel { horizontal, delta, at, mods },
            Expected::Wheel { horizontal: h, delta: d, at: a, mods: m },
        ) => horizontal == h && delta == d && mods == m && at.is_none_or(|p| Some(p) == *a),
        (want, got) => want == got,
    }
}

/// Compares one case: `Ok` when `received` is what `expected` asks for.
///
/// # Errors
///
/// The first [`Difference`].
pub fn compare(expected: &[Expected], received: &[Recorded], origin: (i32, i32)) -> Result<(), Difference> {
    let keep_moves = expected.iter().any(|e| matches!(e, Expected::Move { .. }));
    let got: Vec<Expected> = received
        .iter()
        .filter_map(|r| observed(r, origin))
        .filter(|e| keep_moves || !matches!(e, Expected::Move { .. }))
        .collect();
    let mut i = 0;
    for (at, want) in expected.iter().enumerate() {
        let differ = |received: Option<&Expected>| Difference {
            at,
            expected: want.to_string(),
            received: received.map(ToString::to_string).unwrap_or_default(),
        };
        if let Expected::Move { .. } = want {
            loop {
                match got.get(i) {
                    Some(g @ Expected::Move { .. }) => {
                        i += 1;
                        if g == want {
                            break;
                        }
                    }
                    other => return Err(differ(other)),
                }
            }
            continue;
        }
        while matches!(got.get(i), Some(Expected::Move { .. })) {
            i += 1;
        }
        match got.get(i) {
            Some(g) if matches(want, g) => i += 1,
            other => return Err(differ(other)),
        }
    }
    match got[i..].iter().find(|g| !matches!(g, Expected::Move { .. })) {
        Some(extra) => Err(Difference { at: expected.len(), expected: String::new(), received: extra.to_string() }),
        None => Ok(()),
    }
}

/// Compares the joined text of a case's characters (`WM_CHAR`, `WM_UNICHAR`; not
/// `WM_SYSCHAR`) with `text`: the check of typing cases, whose keys differ by layout.
///
/// # Errors
///
/// A [`Difference`] showing both texts.
pub fn compare_text(text: &str, received: &[Recorded]) -> Result<(), Difference> {
    let got: String = received
        .iter()
        .filter_map(|r| match r {
            Recorded::Char { text, sys: false, .. } => Some(text.as_str()),
            _ => None,
        })
        .collect();
    if got == text {
        return Ok(());
    }
    Err(Difference {
        at: 0,
        expected: format!("text {}", shown_text(text)),
        received: format!("text {}", shown_text(&got)),
    })
}

/// Whether `record` is the separator key going down or up, with no modifier held.
fn is_separator(record: &Recorded, down: bool) -> bool {
    let vk = vkeys::vk_code(SEPARATOR_KEY);
    matches!(record, Recorded::Key { down: d, vk: v, .. } if *d == down && Some(*v) == vk)
}

/// What the separators show of a log: the `ready` line's origin and the events
/// between one separator's release and the next one's press, one list per case.
/// Events before the first separator (focusing the window) are left out, and so are
/// the separators' own characters.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Split {
    pub origin: Option<(i32, i32)>,
    pub cases: Vec<Vec<Recorded>>,
    /// Modifiers held at a separator: a key a case left down, named by the case before it.
    pub held_at: Vec<(usize, Mods)>,
}

/// Cuts a log at the separators.
pub fn split(log: &[Recorded]) -> Split {
    let mut origin = None;
    let mut cases: Vec<Vec<Recorded>> = Vec::new();
    let mut held_at = Vec::new();
    let mut current: Option<Vec<Recorded>> = None;
    let mut in_separator = false;
    for record in log {
        if let Recorded::Ready { x, y, .. } = record {
            origin = Some((*x, *y));
            continue;
        }
        if is_separator(record, true) {
            if let Some(done) = current.take() {
                cases.push(done);
            }
            if let Recorded::Key { mods, .. } = record {
                if *mods != Mods::NONE {
                    held_at.push((cases.len(), *mods));
                }
            }
            in_separator = true;
            continue;
        }
        if in_separator {
            if is_separator(record, false) {
                in_separator = false;
                current = Some(Vec::new());
            }
            // The separator's own messages (none but its up, on a plain F24).
            continue;
        }
        if let Some(case) = current.as_mut() {
            case.push(record.clone());
        }
    }
    if let Some(done) = current {
        if !done.is_empty() {
            cases.push(done);
        }
    }
    Split { origin, cases, held_at }
}
