//! How much of what an agent sent one step keeps in its record.
//!
//! An agent's answer may be as large as the step protocol's line limit (64 MiB), and
//! everything in it used to be recorded whole: the response, every action's code and
//! text, and the free-form `record` fields. Fifteen such steps made a 786 MB
//! `traj.jsonl`, rewritten whole after each step, and a 3 GB host for one task. The
//! record now keeps at most [`MAX_RECORDED_TEXT`] of any one string and
//! [`STEP_BUDGET`] of the step's strings in all; what it leaves out is said where it
//! was cut. Only the record is bounded: the actions run as the agent sent them.

use serde_json::{Map, Value};

/// The most of any one string a step's record keeps.
pub const MAX_RECORDED_TEXT: usize = 64 * 1024;
/// The most of one step's strings (response, actions, logs) its record keeps.
pub const STEP_BUDGET: usize = 512 * 1024;
/// The most of one of an agent's log files (`<key>-step_<i>_<time>.txt` or `.json`)
/// that is written: vendors' answers and prompts are far smaller, so only an endpoint
/// that answers tens of megabytes per step is cut.
pub const MAX_LOG_FILE: usize = 4 << 20;
/// What each string, number or key costs beyond its bytes (quotes, separators), so
/// that millions of empty strings are bounded too.
const ITEM_COST: usize = 8;

/// The budget of one step's record.
#[derive(Debug)]
pub struct RecordBudget {
    /// The most of any one string.
    max_text: usize,
    /// The most of all strings together.
    total: usize,
    left: usize,
    /// Bytes of strings cut short.
    cut: usize,
    /// Items (array elements, object fields, actions) left out whole.
    dropped: usize,
}

impl Default for RecordBudget {
    fn default() -> Self {
        RecordBudget { max_text: MAX_RECORDED_TEXT, total: STEP_BUDGET, left: STEP_BUDGET, cut: 0, dropped: 0 }
    }
}

impl RecordBudget {
    /// The budget of one log file: [`MAX_LOG_FILE`] for the file and for any string in it.
    pub fn log_file() -> RecordBudget {
        RecordBudget { max_text: MAX_LOG_FILE, total: MAX_LOG_FILE, left: MAX_LOG_FILE, cut: 0, dropped: 0 }
    }

    /// Whether nothing more fits.
    pub fn exhausted(&self) -> bool {
        self.left == 0
    }

    /// Counts `n` items left out whole.
    pub fn drop_items(&mut self, n: usize) {
        self.dropped += n;
    }

    /// `text` as recorded: whole when it fits, else its first bytes (at a character
    /// boundary) and a note of how many were left out.
    pub fn text(&mut self, text: &str) -> String {
        self.left = self.left.saturating_sub(ITEM_COST);
        let room = self.max_text.min(self.left);
        if text.len() <= room {
            self.left -= text.len();
            return text.to_owned();
        }
        let mut end = room;
        while !text.is_char_boundary(end) {
            end -= 1;
        }
        self.left -= end;
        let rest = text.len() - end;
        self.cut += rest;
        format!("{}… [{rest} more bytes not recorded]", &text[..end])
    }

    /// `value` as recorded: its strings through [`RecordBudget::text`], its keys
    /// counted, and the elements and fields that no longer fit left out (counted);
    /// `None` when nothing of it fits.
    pub fn value(&mut self, value: &Value) -> Option<Value> {
        if self.exhausted() {
            self.dropped += 1;
            return None;
        }
        Some(match value {
            Value::String(text) => Value::String(self.text(text)),
            Value::Array(items) => {
                let mut kept = Vec::new();
                for (i, item) in items.iter().enumerate() {
                    match self.value(item) {
                        Some(item) => kept.push(item),
                        None => {
                            self.dropped += items.len() - i - 1;
                            break;
                        }
                    }
                }
                Value::Array(kept)
            }
            Value::Object(fields) => {
                let mut kept = Map::new();
                for (i, (key, item)) in fields.iter().enumerate() {
                    if self.exhausted() {
                        self.dropped += fields.len() - i;
                        break;
                    }
                    let key = self.text(key);
                    let Some(item) = self.value(item) else {
                        // `value` counted this field's value; the rest are left out too.
                        self.dropped += fields.len() - i - 1;
                        break;
                    };
                    if kept.contains_key(&key) {
                        // Two long keys cut to the same text: the later one is left out.
                        self.dropped += 1;
                        continue;
                    }
                    kept.insert(key, item);
                }
                Value::Object(kept)
            }
            other => {
                self.left = self.left.saturating_sub(ITEM_COST);
                other.clone()
            }
        })
    }

    /// What was left out, for the record (`None` when nothing was).
    pub fn note(&self) -> Option<String> {
        (self.cut > 0 || self.dropped > 0).then(|| {
            format!(
                "the record keeps {} bytes of a string and {} in all: \
                 {} bytes cut from strings, {} items left out",
                self.max_text, self.total, self.cut, self.dropped
            )
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn what_fits_is_kept_whole_and_the_rest_is_cut_with_a_note() {
        let mut budget = RecordBudget::default();
        assert_eq!(budget.text("short"), "short");
        assert_eq!(budget.note(), None);
        let long = "é".repeat(MAX_RECORDED_TEXT); // two bytes each
        let kept = budget.text(&long);
        assert!(
            kept.ends_with(&format!("… [{MAX_RECORDED_TEXT} more bytes not recorded]")),
            "{}",
            &kept[kept.len() - 60..]
        );
        assert!(kept.len() < MAX_RECORDED_TEXT + 64);
        assert!(budget.note().is_some_and(|n| n.contains("65536 bytes cut")));
    }

    #[test]
    fn a_step_keeps_its_budget_however_its_record_is_shaped() {
        // Big strings, many small ones, many keys, deep arrays: each ends within the budget.
        let shapes = [
            Value::Array(vec![Value::String("x".repeat(1 << 20)); 64]),
            Value::Array(vec![Value::String(String::new()); 1_000_000]),
            Value::Object((0..200_000).map(|i| (format!("k{i}"), Value::from(i))).collect()),
            Value::Array(vec![Value::Array(vec![Value::from(1); 1000]); 1000]),
        ];
        for shape in shapes {
            let mut budget = RecordBudget::default();
            let kept = budget.value(&shape).expect("something fits");
            let size = serde_json::to_string(&kept).unwrap().len();
            assert!(size <= STEP_BUDGET * 2, "{size} bytes kept");
            assert!(budget.exhausted() && budget.note().is_some());
            assert_eq!(budget.value(&Value::from(1)), None, "nothing more fits");
        }
    }

    #[test]
    fn every_field_left_out_is_counted_once() {
        // Fields of every size, so that the budget runs out on keys and on values.
        for value_size in [0, 1, 7, 100, 5000] {
            let fields = 50_000;
            let object: Value =
                Value::Object((0..fields).map(|i| (format!("k{i}"), Value::String("v".repeat(value_size)))).collect());
            let mut budget = RecordBudget::default();
            let Some(Value::Object(kept)) = budget.value(&object) else { panic!("an object is kept") };
            assert_eq!(kept.len() + budget.dropped, fields, "value size {value_size}");
        }
        // Two keys longer than a string may be, alike up to the cut.
        let long = "k".repeat(MAX_RECORDED_TEXT);
        let object = serde_json::json!({ format!("{long}a"): 1, format!("{long}b"): 2 });
        let mut budget = RecordBudget::default();
        let Some(Value::Object(kept)) = budget.value(&object) else { panic!("an object is kept") };
        assert_eq!((kept.len(), budget.dropped), (1, 1));
    }
}
