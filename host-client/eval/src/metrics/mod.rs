//! The metric registry: upstream metric names mapped to Rust functions.
//!
//! A metric is a plain synchronous function of a [`MetricInput`] (the result
//! getter's value, the expected getter's value if the task has one, the
//! task's `options`, and the agent's last control word) returning a score in
//! `[0, 1]`. Metrics read host files only; they never talk to the guest, so
//! [`crate::evaluate`] can run them on a blocking thread.
//!
//! [`lookup`] is the one place that names metrics: a closed `match` from the
//! upstream name to the function. A name it does not know is a metric this
//! build does not implement. One file per upstream family (`general.rs` for
//! upstream's `metrics/general.py` and the `infeasible` rule, `vscode.rs`
//! for `metrics/vscode.py`).

mod browser;
mod general;
mod media;
mod office;
mod vscode;

#[cfg(test)]
mod tests;

use std::path::{Path, PathBuf};

use serde_json::{Map, Value};

use super::value::Fetched;
use super::LastAction;

/// Everything a metric is called with.
#[derive(Debug, Clone)]
pub struct MetricInput {
    /// The result getter's value (`None` when the task has no result getter).
    pub result: Fetched,
    /// The expected getter's value; `None` when the task has no expected getter,
    /// so upstream calls the metric without it.
    pub expected: Option<Fetched>,
    /// The task's `options` for this metric (keyword arguments upstream).
    pub options: Map<String, Value>,
    /// The agent's final control word, for `infeasible`.
    pub last_action: Option<LastAction>,
}

/// Why a metric could not score. Whose failure it is decides what the run
/// does ([`crate::judge`]): the result's is the agent's 0, the rest leave the
/// task unfinished.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum MetricError {
    /// The expected value, the rules or the options are not what the metric
    /// takes: the task's fault.
    #[error("{0}")]
    BadInput(String),
    /// The result value (what the agent left: its file's contents, its answer)
    /// is not what the metric reads: the agent's 0.
    #[error("{0}")]
    Malformed(String),
    /// A host file could not be read: the agent's when it is the result's file.
    #[error("reading {path}: {source}", path = path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A file or string does not parse as the format the metric reads: the
    /// agent's when `what` is the result's file (its path) or `the result ...`.
    #[error("{what}: {message}")]
    Parse { what: String, message: String },
}

/// A metric function.
pub type MetricFn = fn(&MetricInput) -> Result<f64, MetricError>;

/// The implementation of metric `name`, or `None` when this build has none.
pub fn lookup(name: &str) -> Option<MetricFn> {
    let f: MetricFn = match name {
        "exact_match" => general::exact_match,
        "infeasible" => general::infeasible,
        "check_direct_json_object" => general::check_direct_json_object,
        "compare_text_file" => vscode::compare_text_file,
        "check_json_settings" => vscode::check_json_settings,
        "is_extension_installed" => vscode::is_extension_installed,
        _ => return office::lookup(name).or_else(|| browser::lookup(name)).or_else(|| media::lookup(name)),
    };
    Some(f)
}

// ----- helpers the metric families share -----

impl MetricInput {
    /// The expected value, which this metric needs.
    ///
    /// # Errors
    ///
    /// [`MetricError::BadInput`] when the task gives no expected getter.
    pub fn expected(&self) -> Result<&Fetched, MetricError> {
        self.expected.as_ref().ok_or_else(|| MetricError::BadInput("this metric needs an `expected` getter".into()))
    }

    /// The `rules` dict a `rule` getter produced as the expected value.
    ///
    /// # Errors
    ///
    /// [`MetricError::BadInput`] when the expected value is missing or not a dict.
    pub fn rules(&self) -> Result<&Map<String, Value>, MetricError> {
        match self.expected()? {
            Fetched::Json(Value::Object(rules)) => Ok(rules),
            other => {
                Err(MetricError::BadInput(format!("the expected value must be a rules dict, not {}", other.kind())))
            }
        }
    }

    /// `rules[key]`, which upstream indexes without a default.
    ///
    /// # Errors
    ///
    /// [`MetricError::BadInput`] when the rules or the key are missing.
    pub fn rule(&self, key: &str) -> Result<&Value, MetricError> {
        self.rules()?.get(key).ok_or_else(|| MetricError::BadInput(format!("the rules have no `{key}`")))
    }

    /// An option as a bool with a default (Python truthiness of the value).
    pub fn flag(&self, key: &str, default: bool) -> bool {
        self.options.get(key).map_or(default, super::value::py_truthy)
    }
}

/// The path of a file value.
///
/// # Errors
///
/// [`MetricError::Malformed`] when the `result` is not a file,
/// [`MetricError::BadInput`] naming `role` when another value is not.
pub(crate) fn file_of<'a>(value: &'a Fetched, role: &str) -> Result<&'a Path, MetricError> {
    value.as_path().ok_or_else(|| {
        let message = format!("the {role} value must be a file, not {}", value.kind());
        if role == "result" {
            MetricError::Malformed(message)
        } else {
            MetricError::BadInput(message)
        }
    })
}

/// A malformed result: the agent's failure, scored 0.
pub(crate) fn malformed(message: impl Into<String>) -> MetricError {
    MetricError::Malformed(message.into())
}

/// Every metric this build implements, by upstream's name, sorted.
pub const NAMES: &[&str] = &[
    "check_direct_json_object",
    "check_edge_font_size",
    "check_enabled_experiments",
    "check_font_size",
    "check_global_key_play_pause",
    "check_highlighted_words",
    "check_history_deleted",
    "check_italic_font_size_14",
    "check_json_keybindings",
    "check_json_settings",
    "check_one_instance_when_started_from_file",
    "check_qt_bgcone",
    "check_qt_max_volume",
    "check_qt_minimal_view",
    "check_qt_slider_colours",
    "check_qt_video_resize",
    "check_tabstops",
    "compare_audios",
    "compare_docx_files",
    "compare_docx_tables",
    "compare_font_names",
    "compare_highlighted_text",
    "compare_images",
    "compare_line_spacing",
    "compare_pdfs",
    "compare_subscript_contains",
    "compare_table",
    "compare_text_file",
    "compare_videos",
    "compare_zip_files",
    "evaluate_strike_through_last_paragraph",
    "exact_match",
    "find_default_font",
    "has_page_numbers_in_footers",
    "infeasible",
    "is_added_to_steam_cart",
    "is_cookie_deleted",
    "is_expected_active_tab",
    "is_expected_bookmarks",
    "is_expected_tabs",
    "is_extension_installed",
    "is_first_line_centered",
    "is_shortcut_on_desktop",
    "is_url_shortcut_on_desktop",
    "is_vlc_recordings_folder",
];

/// Reads a file as Python's `open(path).read()` does: UTF-8 text with
/// universal newlines (`\r\n` and `\r` become `\n`).
///
/// # Errors
///
/// [`MetricError::Io`] when unreadable, [`MetricError::Parse`] when not UTF-8.
pub(crate) fn read_text(path: &Path) -> Result<String, MetricError> {
    let bytes = std::fs::read(path).map_err(|source| MetricError::Io { path: path.to_owned(), source })?;
    let text = String::from_utf8(bytes).map_err(|err| MetricError::Parse {
        what: path.display().to_string(),
        message: format!("not UTF-8 text: {err}"),
    })?;
    Ok(universal_newlines(&text))
}

fn universal_newlines(text: &str) -> String {
    if text.contains('\r') {
        text.replace("\r\n", "\n").replace('\r', "\n")
    } else {
        text.to_owned()
    }
}

/// A score from a Python comparison.
pub(crate) fn score(pass: bool) -> f64 {
    if pass {
        1.0
    } else {
        0.0
    }
}
