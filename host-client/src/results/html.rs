//! `report.html`: the run's table, a bar chart of success per domain, and
//! every task's trajectory with its screenshots, in one HTML file.
//!
//! The file is self-contained in the sense of the result *folder*: CSS and
//! the chart (SVG) are inline and nothing is fetched from a network or needs
//! a server, but screenshots are linked relatively (`<domain>/<task>/step_1.png`)
//! rather than embedded, which keeps the file small (a 20-task run with 15
//! steps would otherwise carry 300 PNGs as base64). Open it from the folder it
//! was written into, or copy the folder with it.
//!
//! It is not a templating engine: the page is written with `format!` and every
//! text from a task or a model goes through [`escape`].

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use super::summary::{DomainRow, Summary};
use super::{read_trajectory, scan, write_atomic, FoundTask, ResultsError, StepRecord, REPORT_HTML, TRAJ_FILE};

/// Escapes text for HTML element content and attribute values.
pub use arena_shared::markup::escape;

/// Percent-encodes a relative path for an `href`/`src`, keeping `/`.
fn url_path(path: &str) -> String {
    let mut out = String::with_capacity(path.len());
    for b in path.bytes() {
        if b.is_ascii_alphanumeric() || matches!(b, b'-' | b'_' | b'.' | b'~' | b'/' | b'@' | b'+') {
            out.push(b as char);
        } else {
            let _ = write!(out, "%{b:02X}");
        }
    }
    out
}

const STYLE: &str = "
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:2rem;color:#1d232a;background:#fafbfc}
h1{font-size:1.6rem;margin-bottom:.2rem} h2{margin-top:2rem;border-bottom:1px solid #d0d7de;padding-bottom:.3rem}
table{border-collapse:collapse;margin:1rem 0;background:#fff}
th,td{border:1px solid #d0d7de;padding:.35rem .6rem;text-align:left;font-size:.9rem}
th{background:#eef1f4} td.num{text-align:right;font-variant-numeric:tabular-nums}
tr.overall td{font-weight:700;background:#f3f6f9}
.ok{color:#116329;font-weight:600} .bad{color:#a40e26;font-weight:600} .warn{color:#9a6700;font-weight:600}
details{background:#fff;border:1px solid #d0d7de;border-radius:6px;margin:.5rem 0;padding:.4rem .8rem}
summary{cursor:pointer;font-weight:600}
.step{display:flex;gap:1rem;border-top:1px solid #eaeef2;padding:.6rem 0;align-items:flex-start}
.step img{max-width:480px;width:40vw;border:1px solid #d0d7de}
pre{white-space:pre-wrap;word-break:break-word;background:#f6f8fa;padding:.5rem;border-radius:4px;font-size:.8rem;margin:.3rem 0}
.meta{color:#57606a;font-size:.85rem}
";

/// Renders the report of the tasks found under `root`, with their trajectories.
pub fn render(summary: &Summary, found: &[FoundTask], title: &str) -> String {
    let mut html = String::new();
    let _ = write!(
        html,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><meta name=\"viewport\" content=\"width=device-width\">\
         <title>{}</title><style>{STYLE}</style></head><body>\n",
        escape(title)
    );
    let o = &summary.overall;
    let _ = writeln!(
        html,
        "<h1>{}</h1><p class=\"meta\" id=\"overall\">Success rate {:.1}% (mean score × 100 over {} finished tasks, as upstream computes it); \
         Strict rate {:.1}% (over all {} tasks, those without a result counted as 0); {} solved outright ({:.1}%); {} unfinished.</p>",
        escape(title),
        o.success_rate,
        o.tasks,
        o.strict_rate,
        o.tasks + o.unfinished,
        o.successes,
        o.solved_rate,
        o.unfinished
    );
    if let Some(words) = summary.floor_words() {
        let _ = writeln!(html, "<p class=\"meta\" id=\"floor\">{}.</p>", escape(&words));
    }
    if let Some(record) = &summary.certificates {
        let broken = summary.certified_broken();
        let items: Vec<String> = broken
            .iter()
            .map(|(d, n, why)| {
                format!("<li><code>{}</code>: certified broken: {}</li>", escape(&format!("{d}/{n}")), escape(why))
            })
            .collect();
        let _ = writeln!(
            html,
            "<div class=\"warn\" id=\"certified-broken\"><p>Certificates from {} ({} task(s)): {} task(s) of this run certified broken.</p><ul>{}</ul></div>",
            escape(&record.source),
            record.certificates,
            broken.len(),
            items.join("")
        );
    }
    if let Some(words) = summary.incomplete_words() {
        let missing: Vec<String> =
            summary.missing.iter().map(|m| escape(&format!("{}/{}", m.domain, m.name))).collect();
        let _ = writeln!(
            html,
            "<p class=\"warn\" id=\"incomplete\">{} Missing: {}.</p>",
            escape(&words),
            missing.join(", ")
        );
    }
    if let Some(words) = summary.pooled_words() {
        let _ = writeln!(html, "<p class=\"warn\" id=\"pooled\">{}</p>", escape(&words));
        html.push_str("<table id=\"agents\"><tr><th>Agent and model</th><th>Tasks</th><th>Success rate</th><th>Strict rate</th><th>Unfinished</th></tr>\n");
        for row in &summary.agents {
            let _ = writeln!(
                html,
                "<tr><td>{}</td><td>{}</td><td>{:.1}%</td><td>{:.1}%</td><td>{}</td></tr>",
                escape(&row.domain),
                row.tasks,
                row.success_rate,
                row.strict_rate,
                row.unfinished
            );
        }
        html.push_str("</table>\n");
    }
    html.push_str(&trials_html(summary));
    html.push_str(&ledger_html(summary));
    html.push_str("<h2>Success per domain</h2>\n");
    html.push_str(&chart(&summary.domains, o));
    html.push_str(&table(summary));
    html.push_str("<h2>Tasks</h2>\n");
    for task in found {
        let broken = summary.certificates.as_ref().is_some_and(|r| r.broken(&task.domain(), &task.name()).is_some());
        html.push_str(&task_section(task, broken));
    }
    html.push_str("</body></html>\n");
    html
}

/// A horizontal bar per domain and one for the total: upstream's success rate, with `solved/tasks`.
fn chart(domains: &[DomainRow], overall: &DomainRow) -> String {
    const LABEL: u32 = 170;
    const BAR: u32 = 360;
    const ROW: u32 = 26;
    let rows: Vec<&DomainRow> = domains.iter().chain(std::iter::once(overall)).collect();
    let height = ROW * rows.len() as u32 + 24;
    let width = LABEL + BAR + 130;
    let mut svg = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" id=\"chart\" role=\"img\" aria-label=\"success rate per domain\" width=\"{width}\" height=\"{height}\" viewBox=\"0 0 {width} {height}\" font-family=\"sans-serif\" font-size=\"13\">\n"
    );
    for pct in [0u32, 50, 100] {
        let x = LABEL + BAR * pct / 100;
        let _ = writeln!(svg, "<line x1=\"{x}\" y1=\"0\" x2=\"{x}\" y2=\"{}\" stroke=\"#d0d7de\"/><text x=\"{x}\" y=\"{}\" text-anchor=\"middle\" fill=\"#57606a\">{pct}%</text>", height - 18, height - 4);
    }
    for (i, row) in rows.iter().enumerate() {
        let y = ROW * i as u32 + 4;
        let w = (row.success_rate.clamp(0.0, 100.0) / 100.0 * f64::from(BAR)).round() as u32;
        let is_total = i + 1 == rows.len();
        let fill = if is_total { "#0969da" } else { "#54aeff" };
        let _ = writeln!(
            svg,
            "<text x=\"{}\" y=\"{}\" text-anchor=\"end\"{}>{}</text><rect x=\"{LABEL}\" y=\"{y}\" width=\"{w}\" height=\"{}\" fill=\"{fill}\"/><text x=\"{}\" y=\"{}\">{}/{} ({:.1}%)</text>",
            LABEL - 8,
            y + 15,
            if is_total { " font-weight=\"bold\"" } else { "" },
            escape(&row.domain),
            ROW - 8,
            LABEL + w + 6,
            y + 15,
            row.successes,
            row.tasks,
            row.success_rate
        );
    }
    svg.push_str("</svg>\n");
    svg
}

/// The run's tokens, model time and cost, and its budget, when any task reported tokens.
fn ledger_html(summary: &Summary) -> String {
    let o = &summary.overall;
    if o.tokens == crate::agent::Usage::default() && o.cost_usd.is_none() && summary.budget.is_none() {
        return String::new();
    }
    let mut h = format!(
        "<p class=\"meta\" id=\"cost\">Tokens: {} input ({} cached), {} output; model time {:.1} s{}.",
        o.tokens.input,
        o.tokens.cached,
        o.tokens.output,
        o.tokens.model_ms as f64 / 1000.0,
        o.cost_usd.map_or(String::new(), |c| format!("; cost ${c:.4}"))
    );
    if let Some(b) = &summary.budget {
        match &b.stopped {
            Some(why) => {
                let _ = write!(h, " Budget reached ({}): {} task(s) not started.", escape(why), b.not_started.len());
            }
            None => h.push_str(" Budget not reached."),
        }
    }
    h.push_str("</p>\n");
    h
}

/// The success rate's interval; with more than one trial per task, pass@k and
/// pass^k per domain and the flaky tasks.
fn trials_html(summary: &Summary) -> String {
    let mut h = String::new();
    if let Some([low, high]) = summary.overall.rate_ci95 {
        let _ = writeln!(
            h,
            "<p class=\"meta\" id=\"interval\">95% interval of the success rate (seeded bootstrap over tasks): [{low:.1}%, {high:.1}%].</p>"
        );
    }
    let most = summary.overall.pass_at_k.keys().next_back().copied().unwrap_or(0);
    if most <= 1 {
        return h;
    }
    let _ = writeln!(
        h,
        "<h2>Trials</h2>\n<p class=\"meta\">Up to {most} trials per task; a trial passes when it scores 1. pass@k: at least one of k trials passes; pass^k: all k pass.</p>"
    );
    h.push_str("<table id=\"trials\"><thead><tr><th>Domain</th>");
    for k in 1..=most {
        let _ = write!(h, "<th>pass@{k}</th><th>pass^{k}</th>");
    }
    h.push_str("<th>95% interval</th></tr></thead><tbody>\n");
    for (row, class) in
        summary.domains.iter().map(|r| (r, "")).chain(std::iter::once((&summary.overall, " class=\"overall\"")))
    {
        let _ = write!(h, "<tr{class}><td>{}</td>", escape(&row.domain));
        for k in 1..=most {
            for map in [&row.pass_at_k, &row.pass_hat_k] {
                let cell = map.get(&k).map_or("-".to_owned(), |v| format!("{v:.1}%"));
                let _ = write!(h, "<td class=\"num\">{cell}</td>");
            }
        }
        let ci = row.rate_ci95.map_or("-".to_owned(), |[l, hi]| format!("[{l:.1}%, {hi:.1}%]"));
        let _ = writeln!(h, "<td class=\"num\">{ci}</td></tr>");
    }
    h.push_str("</tbody></table>\n");
    if summary.flaky_tasks.is_empty() {
        h.push_str("<p id=\"flaky\">No flaky task: every task passed in all its trials or in none.</p>\n");
    } else {
        let _ = writeln!(h, "<p>Flaky tasks (passed in some trials, failed in others):</p><ul id=\"flaky\">");
        for t in &summary.flaky_tasks {
            let _ = writeln!(
                h,
                "<li>{} / {}: {} of {} trials passed</li>",
                escape(&t.domain),
                escape(&t.name),
                t.passes,
                t.trials
            );
        }
        h.push_str("</ul>\n");
    }
    h
}

fn table(summary: &Summary) -> String {
    let mut t = String::from(
        "<table id=\"summary\"><thead><tr><th>Domain</th><th>Tasks</th><th>Success rate</th><th>Solved</th><th>Solved rate</th>\
         <th>Avg steps</th><th>Avg time (s)</th><th>Agent errors</th><th>Unfinished</th></tr></thead><tbody>\n",
    );
    for (row, class) in summary
        .domains
        .iter()
        .map(|r| (r, ""))
        .chain(std::iter::once((&summary.overall, " class=\"overall\"")))
        .chain(summary.groups.iter().map(|r| (r, " class=\"group\"")))
    {
        let _ = writeln!(
            t,
            "<tr{class}><td>{}</td><td class=\"num\">{}</td><td class=\"num\">{:.1}%</td><td class=\"num\">{}</td><td class=\"num\">{:.1}%</td>\
             <td class=\"num\">{:.1}</td><td class=\"num\">{:.1}</td><td class=\"num\">{}</td><td class=\"num\">{}</td></tr>",
            escape(&row.domain),
            row.tasks,
            row.success_rate,
            row.successes,
            row.solved_rate,
            row.avg_steps,
            row.avg_seconds,
            row.agent_errors,
            row.unfinished
        );
    }
    t.push_str("</tbody></table>\n");
    t.push_str("<table id=\"tasks\"><thead><tr><th>Domain</th><th>Task</th><th>Score</th><th>Status</th><th>Failed by</th><th>Steps</th><th>Time (s)</th><th>Attempt</th><th>Guest</th><th>Action errors</th></tr></thead><tbody>\n");
    for task in &summary.tasks {
        let (class, score) = match task.score {
            Some(s) if task.success => ("ok", super::python_float(s)),
            Some(s) => ("bad", super::python_float(s)),
            None => ("warn", "-".to_owned()),
        };
        let _ = writeln!(
            t,
            "<tr><td>{}</td><td><a href=\"#{}\">{}</a></td><td class=\"num {class}\">{score}</td><td>{}</td><td>{}</td><td class=\"num\">{}</td><td class=\"num\">{:.1}</td><td class=\"num\">{}</td><td>{}</td><td class=\"num action-errors\">{}</td></tr>",
            escape(&task.domain),
            anchor(&task.path),
            escape(&task.name),
            escape(&task.status),
            escape(&super::summary::failed_by_text(task)),
            task.steps,
            task.elapsed_ms as f64 / 1000.0,
            task.attempt,
            escape(&task.guest),
            task.action_errors
        );
    }
    t.push_str("</tbody></table>\n");
    t
}

fn anchor(path: &str) -> String {
    let id: String = path.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' { c } else { '_' }).collect();
    format!("t-{id}")
}

fn relative_str(path: &Path) -> String {
    path.components().map(|c| c.as_os_str().to_string_lossy().into_owned()).collect::<Vec<_>>().join("/")
}

/// `traj.html` in a task folder: the task's own page (its record, evaluation and
/// every step with the screenshot the agent saw), readable without the run's
/// report, as upstream keeps one per task.
///
/// # Errors
///
/// The page cannot be written.
pub fn write_task_page(dir: &super::TaskDir, episode: &super::EpisodeResult) -> Result<(), ResultsError> {
    let score = (!episode.status.is_unfinished()).then_some(episode.score);
    let task = FoundTask { dir: dir.clone(), relative: PathBuf::from("."), score, episode: Some(episode.clone()) };
    let section = task_section(&task, false).replacen("<details id=", "<details open id=", 1);
    let page = format!(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><meta name=\"viewport\" content=\"width=device-width\">\
         <title>{} / {}</title><style>{STYLE}</style></head><body>\n{section}</body></html>\n",
        escape(&episode.domain),
        escape(&episode.task_name)
    );
    write_atomic(&dir.path().join(super::TRAJ_HTML), page.as_bytes())
}

/// A task's section; `broken`: certificates call the task broken.
fn task_section(task: &FoundTask, broken: bool) -> String {
    let rel = relative_str(&task.relative);
    let mut s = String::new();
    let (class, score) = match task.score {
        Some(v) if v >= 1.0 - 1e-9 => ("ok", super::python_float(v)),
        Some(v) => ("bad", super::python_float(v)),
        None => ("warn", "unfinished".to_owned()),
    };
    let _ = writeln!(
        s,
        "<details id=\"{}\"><summary>{} / {} &mdash; <span class=\"{class}\">{score}</span>{}</summary>",
        anchor(&rel),
        escape(&task.domain()),
        escape(&task.name()),
        if broken { " <span class=\"warn\">(certified broken)</span>" } else { "" }
    );
    if let Some(ep) = &task.episode {
        let _ = writeln!(
            s,
            "<p>{}</p><p class=\"meta\">agent {} &middot; model {} &middot; guest {} &middot; {} steps &middot; {:.1} s (setup {:.1} s, evaluation {:.1} s) &middot; attempt {} &middot; last action {}</p>",
            escape(&ep.instruction),
            escape(&ep.agent),
            escape(&ep.model),
            escape(&ep.guest),
            ep.steps,
            ep.elapsed_ms as f64 / 1000.0,
            ep.setup_ms as f64 / 1000.0,
            ep.eval_ms as f64 / 1000.0,
            ep.attempt,
            escape(&ep.last_action)
        );
        if let Some(message) = ep.status.message() {
            let _ = writeln!(s, "<p class=\"bad\">{}: {}</p>", escape(ep.status.kind()), escape(message));
        }
        if !ep.eval.is_null() {
            let eval = serde_json::to_string_pretty(&ep.eval).unwrap_or_default();
            let _ = writeln!(s, "<details><summary>evaluation</summary><pre>{}</pre></details>", escape(&eval));
        }
    }
    match read_trajectory(&task.dir.path().join(TRAJ_FILE)) {
        Ok(steps) => {
            for step in &steps {
                s.push_str(&step_html(&rel, step));
            }
        }
        Err(err) => {
            let _ = write!(s, "<p class=\"bad\">{}</p>", escape(&err.to_string()));
        }
    }
    s.push_str("</details>\n");
    s
}

fn step_html(rel: &str, step: &StepRecord) -> String {
    let src = url_path(&format!("{rel}/{}", step.screenshot_file));
    let t = &step.timings;
    let mut s = format!(
        "<div class=\"step\"><a href=\"{src}\"><img loading=\"lazy\" src=\"{src}\" alt=\"step {n} screenshot\"></a><div>\
         <p><b>Step {n}</b> <span class=\"meta\">{} &middot; then window {} &middot; observe {} ms (screenshot {}, tree {}), predict {} ms (Set-of-Marks {}, model {}), act {} ms{}</span></p>\
         <pre>{}</pre><p class=\"meta\">response</p><pre>{}</pre>",
        escape(&step.first.action_timestamp),
        escape(&step.first.observation.window_title),
        t.observe_ms,
        t.observe.screenshot_ms,
        t.observe.tree_ms.map_or_else(|| "-".to_owned(), |v| v.to_string()),
        t.predict_ms,
        t.predict.som_ms.map_or_else(|| "-".to_owned(), |v| v.to_string()),
        t.predict.model_ms.map_or_else(|| "-".to_owned(), |v| v.to_string()),
        t.act_ms,
        if t.timeouts.is_empty() && t.predict_retries == 0 {
            String::new()
        } else {
            escape(&format!(" · {} retries; {}", t.predict_retries, t.timeouts.join("; ")))
        },
        escape(&step.actions.iter().map(crate::ports::AgentAction::summary).collect::<Vec<_>>().join("\n")),
        escape(&step.response),
        n = step.step
    );
    if let Some(error) = &step.error {
        let _ = write!(s, "<p class=\"bad\">{}</p>", escape(error));
    }
    s.push_str("</div></div>\n");
    s
}

/// Scans `root`, writes `summary.json`, `summary.md` and `report.html` there, and returns the summary.
///
/// # Errors
///
/// `root` cannot be read or a file cannot be written.
pub fn write_report(root: &Path, title: &str) -> Result<(Summary, PathBuf), ResultsError> {
    let found = scan(root)?;
    let mut summary = Summary::from_found_in(root, &found);
    summary.budget = super::ledger::BudgetRecord::read(root);
    summary.write(root)?;
    let path = root.join(REPORT_HTML);
    write_atomic(&path, render(&summary, &found, title).as_bytes())?;
    Ok((summary, path))
}
