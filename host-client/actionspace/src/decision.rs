//! The step decisions `WAIT`, `DONE` and `FAIL`: the one place their words are read.
//!
//! Every way into a step reads them here: the action spaces (a pyautogui answer
//! that is only `DONE`, `computer_13`'s `action_type`), Navi's replies (a line of
//! its own, a ```` ```decision ```` block), the step protocol (a decision string
//! among the actions, the `decision` field), scripted plans, replayed trajectories
//! and the computer-use agents' closing text.
//!
//! Three readings, for three places upstream reads them differently:
//! - [`Decision::parse`]: a text that is one decision word (the common case);
//! - [`Decision::named_in`]: upstream Navi's ```` ```decision ```` block, where the first
//!   of `DONE`, `FAIL`, `WAIT` the block contains wins;
//! - [`Decision::said_in`]: a word of its own anywhere in a text (a computer-use
//!   model's final message saying `FAIL`).

use serde::{Deserialize, Serialize};

/// A step decision.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "UPPERCASE")]
pub enum Decision {
    /// Nothing this step; look again.
    Wait,
    /// The task is done.
    Done,
    /// The task cannot be done.
    Fail,
}

impl Decision {
    /// Every decision, in upstream Navi's order of precedence.
    pub const ALL: [Decision; 3] = [Decision::Done, Decision::Fail, Decision::Wait];

    /// The word: `WAIT`, `DONE` or `FAIL`.
    pub fn word(self) -> &'static str {
        match self {
            Decision::Wait => "WAIT",
            Decision::Done => "DONE",
            Decision::Fail => "FAIL",
        }
    }

    /// `text` as one decision word: white space, and the Markdown a model puts
    /// around a word (backticks, asterisks, a full stop), are left out; the word is
    /// upper case, as upstream's and OSWorld's agents write it.
    pub fn parse(text: &str) -> Option<Decision> {
        let word = text.trim().trim_matches(|c: char| c == '`' || c == '.' || c == '*').trim();
        Decision::ALL.into_iter().find(|d| d.word() == word)
    }

    /// Upstream Navi's reading of a ```` ```decision ```` block: the first of `DONE`,
    /// `FAIL`, `WAIT` (in that order) that `text` contains anywhere.
    pub fn named_in(text: &str) -> Option<Decision> {
        Decision::ALL.into_iter().find(|d| text.contains(d.word()))
    }

    /// Whether `text` says this decision as a word of its own (letters and digits
    /// around it split words).
    pub fn said_in(self, text: &str) -> bool {
        text.split(|c: char| !c.is_ascii_alphanumeric()).any(|w| w == self.word())
    }
}

impl std::fmt::Display for Decision {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.word())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_word_is_a_decision_with_or_without_markdown_around_it() {
        for (text, want) in [
            ("DONE", Some(Decision::Done)),
            ("  FAIL\n", Some(Decision::Fail)),
            ("`WAIT`", Some(Decision::Wait)),
            ("**DONE**.", Some(Decision::Done)),
            ("done", None),
            ("DONE now", None),
            ("UNDONE", None),
            ("", None),
        ] {
            assert_eq!(Decision::parse(text), want, "{text:?}");
        }
    }

    #[test]
    fn a_decision_block_names_the_first_of_done_fail_wait() {
        assert_eq!(Decision::named_in("WAIT or DONE"), Some(Decision::Done));
        assert_eq!(Decision::named_in("FAIL, then WAIT"), Some(Decision::Fail));
        assert_eq!(Decision::named_in("COMMAND"), None);
    }

    #[test]
    fn a_word_of_its_own_is_said_and_part_of_a_word_is_not() {
        assert!(Decision::Fail.said_in("I cannot do this. FAIL"));
        assert!(!Decision::Fail.said_in("FAILED to find it"));
        assert_eq!(serde_json::to_string(&Decision::Wait).expect("json"), "\"WAIT\"");
        assert_eq!(serde_json::from_str::<Decision>("\"FAIL\"").expect("json"), Decision::Fail);
    }
}
