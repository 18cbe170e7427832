//! The doctor's report: what `arena-guest doctor`, `GET /v1/doctor` and
//! `arena doctor` say about a desktop, capability by capability.
//!
//! Health (`/v1/health`) answers "is each part up right now" cheaply and often;
//! the doctor answers "does each capability work end to end" once, slowly, by
//! doing it: capture and look at the pixels, start Notepad and type into it,
//! round-trip the clipboard, walk the tree, run a command past its timeout.
//! It is what a user runs first in a new image.
//!
//! A check is [`CheckStatus::Pass`] or [`CheckStatus::Fail`]; a capability the
//! platform does not have at all (UI Automation under Wine) is
//! [`CheckStatus::Unavailable`], which does not fail the report; facts worth
//! reading but not judged (the integrity level, a reachability hint) are
//! [`CheckStatus::Info`].

use serde::{Deserialize, Serialize};

/// How one check ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CheckStatus {
    Pass,
    Fail,
    /// The platform lacks the capability; not a failure of this image.
    Unavailable,
    /// A fact reported, not judged.
    Info,
    #[serde(other)]
    Unknown,
}

impl CheckStatus {
    /// The word the human report prints.
    pub fn label(self) -> &'static str {
        match self {
            CheckStatus::Pass => "PASS",
            CheckStatus::Fail => "FAIL",
            CheckStatus::Unavailable => "N/A",
            CheckStatus::Info => "INFO",
            CheckStatus::Unknown => "?",
        }
    }
}

/// One capability checked end to end.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DoctorCheck {
    /// Stable name (`capture`, `cursor`, `notepad_typing`, ...).
    pub name: String,
    pub status: CheckStatus,
    /// Wall time the check took.
    pub ms: u64,
    /// What was seen: on a pass the evidence, on a failure the reason.
    pub detail: String,
}

/// The whole report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DoctorReport {
    /// `stub` or `windows`.
    pub backend: String,
    /// The server's version.
    pub version: String,
    pub checks: Vec<DoctorCheck>,
    /// Wall time of the whole run.
    pub total_ms: u64,
    /// `--deep`: the timings of the trees of the heavy applications running and
    /// of input round trips.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub deep: Option<DeepReport>,
}

/// What `arena doctor --deep` measures on a real desktop.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct DeepReport {
    /// One row per window of a heavy application (Edge, File Explorer, Settings,
    /// Notepad, Office, ...) and per tree source.
    pub trees: Vec<TreeTiming>,
    /// Input sent and seen to arrive, timed.
    pub input: Vec<RoundTrip>,
}

/// The tree of one window, walked in front with upstream's budget.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TreeTiming {
    /// The application (`Edge`, `File Explorer`, ...).
    pub app: String,
    /// The window's title.
    pub window: String,
    /// `uia` or `win32`.
    pub source: String,
    pub nodes: u32,
    pub ms: u64,
    /// The budget cut it.
    pub truncated: bool,
    /// UI Automation's bulk fetch failed and the window was read element by element.
    pub partial: bool,
    /// Why the walk failed, when it did.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

/// One kind of input round trip, over several samples.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RoundTrip {
    pub what: String,
    pub samples: u32,
    pub median_ms: f64,
    pub max_ms: f64,
}

impl DeepReport {
    /// The tables a user pastes into an issue (Markdown).
    pub fn render_table(&self) -> String {
        let mut out = String::from("| application | window | source | nodes | ms | cut | element by element |\n|---|---|---|---:|---:|---|---|\n");
        if self.trees.is_empty() {
            out.push_str("| (no heavy application was running) | | | | | | |\n");
        }
        for t in &self.trees {
            let cell = |s: &str| s.replace('|', "\\|").replace('\n', " ");
            let nodes = match &t.error {
                Some(err) => format!("failed: {}", cell(err)),
                None => t.nodes.to_string(),
            };
            out.push_str(&format!(
                "| {} | {} | {} | {nodes} | {} | {} | {} |\n",
                cell(&t.app),
                cell(&t.window),
                t.source,
                t.ms,
                if t.truncated { "yes" } else { "no" },
                if t.partial { "yes" } else { "no" }
            ));
        }
        out.push_str("\n| input round trip | samples | median ms | max ms |\n|---|---:|---:|---:|\n");
        for r in &self.input {
            out.push_str(&format!("| {} | {} | {:.1} | {:.1} |\n", r.what, r.samples, r.median_ms, r.max_ms));
        }
        out
    }
}

impl RoundTrip {
    /// The median and maximum of `samples` (milliseconds).
    pub fn of(what: &str, samples: &[f64]) -> RoundTrip {
        let mut sorted = samples.to_vec();
        sorted.sort_by(f64::total_cmp);
        let median = match sorted.len() {
            0 => 0.0,
            n if n % 2 == 1 => sorted[n / 2],
            n => (sorted[n / 2 - 1] + sorted[n / 2]) / 2.0,
        };
        RoundTrip {
            what: what.to_owned(),
            samples: u32::try_from(sorted.len()).unwrap_or(u32::MAX),
            median_ms: median,
            max_ms: sorted.last().copied().unwrap_or(0.0),
        }
    }
}

impl DoctorReport {
    /// True when no check failed (unavailable and informational ones do not count).
    pub fn passed(&self) -> bool {
        !self.checks.iter().any(|c| c.status == CheckStatus::Fail)
    }

    /// The check of this name, if it ran.
    pub fn check(&self, name: &str) -> Option<&DoctorCheck> {
        self.checks.iter().find(|c| c.name == name)
    }

    /// The human report: one aligned line per check, then a verdict line.
    pub fn render_text(&self) -> String {
        let width = self.checks.iter().map(|c| c.name.len()).max().unwrap_or(0);
        let mut out = format!("arena-guest {} doctor, {} backend\n", self.version, self.backend);
        for c in &self.checks {
            out.push_str(&format!(
                "{:<5} {:<width$} {:>7} ms  {}\n",
                c.status.label(),
                c.name,
                c.ms,
                c.detail.replace('\n', " "),
            ));
        }
        let failed = self.checks.iter().filter(|c| c.status == CheckStatus::Fail).count();
        let unavailable = self.checks.iter().filter(|c| c.status == CheckStatus::Unavailable).count();
        out.push_str(&format!(
            "{}: {} checks, {failed} failed, {unavailable} unavailable, {} ms\n",
            if failed == 0 { "ok" } else { "FAILED" },
            self.checks.len(),
            self.total_ms
        ));
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(name: &str, status: CheckStatus) -> DoctorCheck {
        DoctorCheck { name: name.into(), status, ms: 12, detail: format!("{name} detail\nsecond line") }
    }

    #[test]
    fn only_a_failed_check_fails_the_report() {
        let mut report = DoctorReport {
            backend: "stub".into(),
            version: "1.0".into(),
            checks: vec![check("capture", CheckStatus::Pass), check("uia", CheckStatus::Unavailable)],
            total_ms: 40,
            deep: None,
        };
        report.checks.push(check("integrity", CheckStatus::Info));
        assert!(report.passed());
        report.checks.push(check("clipboard_text", CheckStatus::Fail));
        assert!(!report.passed());
        let text = report.render_text();
        assert!(text.contains("FAIL  clipboard_text      12 ms  clipboard_text detail second line\n"), "{text}");
        assert!(text.contains("N/A   uia"), "{text}");
        assert!(text.ends_with("FAILED: 4 checks, 1 failed, 1 unavailable, 40 ms\n"), "{text}");
        assert_eq!(report.check("uia").map(|c| c.status), Some(CheckStatus::Unavailable));
    }

    #[test]
    fn the_deep_table_is_markdown_a_user_can_paste() {
        let deep = DeepReport {
            trees: vec![TreeTiming {
                app: "Edge".into(),
                window: "New tab | Work".into(),
                source: "uia".into(),
                nodes: 812,
                ms: 2400,
                truncated: true,
                partial: true,
                error: None,
            }],
            input: vec![RoundTrip::of("cursor move, read back", &[3.0, 1.0, 2.0, 10.0])],
        };
        let table = deep.render_table();
        assert!(table.contains("| Edge | New tab \\| Work | uia | 812 | 2400 | yes | yes |"), "{table}");
        assert!(table.contains("| cursor move, read back | 4 | 2.5 | 10.0 |"), "{table}");
        assert!(DeepReport::default().render_table().contains("no heavy application"));
    }

    #[test]
    fn statuses_travel_as_snake_case_and_unknown_ones_are_kept_readable() {
        assert_eq!(serde_json::to_string(&CheckStatus::Unavailable).unwrap(), "\"unavailable\"");
        let read: CheckStatus = serde_json::from_str("\"skipped_by_newer_guest\"").unwrap();
        assert_eq!(read, CheckStatus::Unknown);
    }
}
