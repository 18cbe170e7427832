//! `report.html`: the run's table, a bar chart of success per domain, a filter
//! of the tasks, and every task's trajectory with its screenshots, in one HTML
//! file; and each task's own page, `traj.html`. A trajectory is the viewer of
//! docs/results.md: per step the screenshot with markers of where the actions
//! landed, the model's reply and tool calls, the actions, errors, timings and
//! tokens ([`super::viewer`] reads them from the records), keys between steps.
//!
//! The file is self-contained in the sense of the result *folder*: CSS and
//! the chart (SVG) are inline and nothing is fetched from a network or needs
//! a server, but screenshots are linked relatively (`<domain>/<task>/step_1.png`)
//! rather than embedded, which keeps the file small (a 20-task run with 15
//! steps would otherwise carry 300 PNGs as base64). Open it from the folder it
//! was written into, or copy the folder with it.
//!
//! It is not a templating engine: the page is written with `format!` and every
//! text from a task or a model goes through [`escape`]. The one script is
//! `SCRIPT`, a constant; the page's Content-Security-Policy allows it alone.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use arena_actionspace::Coords;

use super::summary::{DomainRow, Summary};
use super::viewer::{self, MarkKind};
use super::{scan, write_atomic, FoundTask, ResultsError, StepRecord, REPORT_HTML, TRAJ_FILE};

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
[hidden]{display:none!important}
.step{display:flex;flex-wrap:wrap;gap:1rem;border-top:1px solid #eaeef2;padding:.6rem;align-items:flex-start;scroll-margin-top:.5rem}
.step.current{outline:3px solid #0969da;outline-offset:2px;border-radius:4px}
.shot{position:relative;flex:0 0 auto;width:min(55vw,960px);line-height:0}
.shot img{display:block;width:100%;height:auto;border:1px solid #d0d7de;box-sizing:border-box}
.shot svg.marks{position:absolute;left:0;top:0;width:100%;height:100%;pointer-events:none;overflow:visible}
.info{flex:1 1 22rem;min-width:0}
.info h4{margin:.6rem 0 .2rem;font-size:.8rem;text-transform:uppercase;letter-spacing:.03em;color:#57606a}
.info ol{margin:.2rem 0;padding-left:1.6rem;font-size:.85rem}
pre{white-space:pre-wrap;word-break:break-word;background:#f6f8fa;padding:.5rem;border-radius:4px;font-size:.8rem;margin:.3rem 0}
pre.reply{background:#fff8e6;font-size:.85rem}
.meta{color:#57606a;font-size:.85rem}
.tokens{font-size:.85rem;font-variant-numeric:tabular-nums}
kbd{border:1px solid #d0d7de;border-bottom-width:2px;border-radius:3px;padding:0 .3em;background:#fff;font-size:.8rem}
#filter{display:flex;flex-wrap:wrap;gap:1rem;align-items:center;font-size:.9rem;margin:1rem 0}
";

/// The pages' one script, the same text on every page (its hash is the page's
/// Content-Security-Policy, so no other script runs): keyboard navigation between
/// the visible steps and the report's task filter. It reads the page and never
/// writes text from it as markup.
const SCRIPT: &str = r#"(function () {
  "use strict";
  function visibleSteps() {
    return Array.prototype.filter.call(document.querySelectorAll(".step"), function (s) {
      return s.getClientRects().length > 0;
    });
  }
  function go(delta) {
    var steps = visibleSteps();
    if (!steps.length) { return false; }
    var old = document.querySelector(".step.current");
    var i = steps.indexOf(old);
    i = i < 0 ? (delta > 0 ? 0 : steps.length - 1) : Math.min(steps.length - 1, Math.max(0, i + delta));
    if (old) { old.classList.remove("current"); }
    steps[i].classList.add("current");
    steps[i].scrollIntoView({block: "start"});
    return true;
  }
  var keys = {j: 1, ArrowRight: 1, k: -1, ArrowLeft: -1};
  document.addEventListener("keydown", function (e) {
    if (e.ctrlKey || e.metaKey || e.altKey || e.defaultPrevented) { return; }
    var t = e.target && e.target.tagName;
    if (t === "INPUT" || t === "SELECT" || t === "TEXTAREA") { return; }
    if (Object.prototype.hasOwnProperty.call(keys, e.key) && go(keys[e.key])) { e.preventDefault(); }
  });
  document.addEventListener("click", function (e) {
    var step = e.target && e.target.closest ? e.target.closest(".step") : null;
    if (!step) { return; }
    var old = document.querySelector(".step.current");
    if (old) { old.classList.remove("current"); }
    step.classList.add("current");
  });
  // A link to a task or a step opens the sections around it.
  function openTarget() {
    var el = location.hash.length > 1 ? document.getElementById(decodeURIComponent(location.hash.slice(1))) : null;
    for (; el; el = el.parentElement) {
      if (el.tagName === "DETAILS") { el.open = true; }
    }
  }
  window.addEventListener("hashchange", openTarget);
  openTarget();
  var filter = document.getElementById("filter");
  if (!filter) { return; }
  function apply() {
    var want = {};
    Array.prototype.forEach.call(filter.querySelectorAll("select"), function (s) { want[s.name] = s.value; });
    var shown = 0, total = 0;
    Array.prototype.forEach.call(document.querySelectorAll("[data-task]"), function (el) {
      var ok = Object.keys(want).every(function (k) { return !want[k] || el.getAttribute("data-" + k) === want[k]; });
      el.hidden = !ok;
      if (el.tagName === "TR") { total += 1; if (ok) { shown += 1; } }
    });
    document.getElementById("filter-count").textContent = shown + " of " + total + " tasks shown";
  }
  filter.addEventListener("change", apply);
  apply();
})();
"#;

/// The head of a page titled `title`: its style, and a Content-Security-Policy
/// that lets only `SCRIPT` run (by its hash) and fetches nothing but the
/// folder's own images, so text from a model that escaped escaping still could not act.
fn head(title: &str) -> String {
    use base64::Engine as _;
    use sha2::Digest as _;
    let hash = base64::engine::general_purpose::STANDARD.encode(sha2::Sha256::digest(SCRIPT.as_bytes()));
    format!(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><meta name=\"viewport\" content=\"width=device-width\">\
         <meta http-equiv=\"Content-Security-Policy\" content=\"default-src 'none'; img-src 'self' file: data:; \
         style-src 'unsafe-inline'; script-src 'sha256-{hash}'; base-uri 'none'; form-action 'none'\">\
         <title>{}</title><style>{STYLE}</style></head><body>\n",
        escape(title)
    )
}

/// The keys of the step navigation, as the page says them.
const KEYS_HELP: &str = "<p class=\"meta keys\" id=\"keys\">Steps: <kbd>j</kbd> or <kbd>&rarr;</kbd> next, <kbd>k</kbd> or <kbd>&larr;</kbd> previous (among the steps shown); markers on a screenshot are numbered as the legend beside it.</p>\n";

/// The end of every page: its script.
fn tail() -> String {
    format!("<script>{SCRIPT}</script>\n</body></html>\n")
}

/// Renders the report of the tasks found under `root`, with their trajectories.
pub fn render(summary: &Summary, found: &[FoundTask], title: &str) -> String {
    let mut html = String::new();
    html.push_str(&head(title));
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
    html.push_str(KEYS_HELP);
    for task in found {
        let broken = summary.certificates.as_ref().is_some_and(|r| r.broken(&task.domain(), &task.name()).is_some());
        let rel = relative_str(&task.relative);
        let row = summary.tasks.iter().find(|t| t.path == rel);
        html.push_str(&task_section(task, broken, row));
    }
    html.push_str(&tail());
    html
}

/// The attributes the report's filter reads, on a task's table row and its section.
fn filter_attributes(row: &super::summary::TaskRow) -> String {
    format!(
        " data-task=\"\" data-domain=\"{}\" data-status=\"{}\" data-failed-by=\"{}\"",
        escape(&row.domain),
        escape(&row.status),
        escape(&super::summary::failed_by_text(row))
    )
}

/// The filter above the task table: a choice of each value the run's tasks have.
fn filter_form(summary: &Summary) -> String {
    let mut form = String::from("<form id=\"filter\" role=\"search\" aria-label=\"filter the tasks\">");
    type Column = fn(&super::summary::TaskRow) -> String;
    let columns: [(&str, &str, Column); 3] = [
        ("domain", "Domain", |t| t.domain.clone()),
        ("status", "Status", |t| t.status.clone()),
        ("failed-by", "Failed by", super::summary::failed_by_text),
    ];
    for (name, label, value) in columns {
        let values: std::collections::BTreeSet<String> = summary.tasks.iter().map(value).collect();
        let _ = write!(form, "<label>{label} <select name=\"{name}\"><option value=\"\">all</option>");
        for v in &values {
            let _ = write!(form, "<option value=\"{0}\">{0}</option>", escape(v));
        }
        form.push_str("</select></label>");
    }
    form.push_str("<span class=\"meta\" id=\"filter-count\"></span></form>\n");
    form
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
    if o.tokens == crate::ledger::Usage::default() && o.cost_usd.is_none() && summary.budget.is_none() {
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
    t.push_str(&filter_form(summary));
    t.push_str("<table id=\"tasks\"><thead><tr><th>Domain</th><th>Task</th><th>Score</th><th>Status</th><th>Failed by</th><th>Steps</th><th>Time (s)</th><th>Attempt</th><th>Guest</th><th>Action errors</th></tr></thead><tbody>\n");
    for task in &summary.tasks {
        let (class, score) = match task.score {
            Some(s) if task.success => ("ok", super::python_float(s)),
            Some(s) => ("bad", super::python_float(s)),
            None => ("warn", "-".to_owned()),
        };
        let _ = writeln!(
            t,
            "<tr{}><td>{}</td><td><a href=\"#{}\">{}</a></td><td class=\"num {class}\">{score}</td><td>{}</td><td>{}</td><td class=\"num\">{}</td><td class=\"num\">{:.1}</td><td class=\"num\">{}</td><td>{}</td><td class=\"num action-errors\">{}</td></tr>",
            filter_attributes(task),
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
    let section = task_section(&task, false, None).replacen("<details id=", "<details open id=", 1);
    let page =
        format!("{}{KEYS_HELP}{section}{}", head(&format!("{} / {}", episode.domain, episode.task_name)), tail());
    write_atomic(&dir.path().join(super::TRAJ_HTML), page.as_bytes())
}

/// A task's section; `broken`: certificates call the task broken; `row`: its
/// row of the summary, whose domain, status and blame the report's filter reads.
fn task_section(task: &FoundTask, broken: bool, row: Option<&super::summary::TaskRow>) -> String {
    let rel = relative_str(&task.relative);
    let mut s = String::new();
    let (class, score) = match task.score {
        Some(v) if v >= 1.0 - 1e-9 => ("ok", super::python_float(v)),
        Some(v) => ("bad", super::python_float(v)),
        None => ("warn", "unfinished".to_owned()),
    };
    let id = anchor(&rel);
    let _ = writeln!(
        s,
        "<details id=\"{id}\"{}><summary>{} / {} &mdash; <span class=\"{class}\">{score}</span>{}</summary>",
        row.map(filter_attributes).unwrap_or_default(),
        escape(&task.domain()),
        escape(&task.name()),
        if broken { " <span class=\"warn\">(certified broken)</span>" } else { "" }
    );
    let mut coords = Coords::Pixels;
    if let Some(ep) = &task.episode {
        let _ = writeln!(
            s,
            "<p>{}</p><p class=\"meta\">agent {} &middot; model {} &middot; guest {} &middot; {} steps &middot; {:.1} s (setup {:.1} s, evaluation {:.1} s) &middot; attempt {} &middot; last action {} &middot; action errors <span class=\"action-errors\">{}</span></p>",
            escape(&ep.instruction),
            escape(&ep.agent),
            escape(&ep.model),
            escape(&ep.guest),
            ep.steps,
            ep.elapsed_ms as f64 / 1000.0,
            ep.setup_ms as f64 / 1000.0,
            ep.eval_ms as f64 / 1000.0,
            ep.attempt,
            escape(&ep.last_action),
            ep.action_errors
        );
        if let Some(tokens) = &ep.tokens {
            let _ = writeln!(
                s,
                "<p class=\"tokens\" id=\"{id}-tokens\">Task tokens: {}{}</p>",
                tokens_words(tokens),
                ep.cost_usd.map_or(String::new(), |c| format!("; cost ${c:.4}"))
            );
        }
        if let Some(message) = ep.status.message() {
            let _ = writeln!(s, "<p class=\"bad\">{}: {}</p>", escape(ep.status.kind()), escape(message));
        }
        if !ep.eval.is_null() {
            let eval = serde_json::to_string_pretty(&ep.eval).unwrap_or_default();
            let _ = writeln!(s, "<details><summary>evaluation</summary><pre>{}</pre></details>", escape(&eval));
        }
        coords = ep.options.get("coords").and_then(|c| viewer::coords_named(c)).unwrap_or(Coords::Pixels);
    }
    match super::read_trajectory_lines(&task.dir.path().join(TRAJ_FILE)) {
        Ok(steps) => {
            let mut cursor = None;
            for (step, line) in &steps {
                let (html, after) = step_html(task.dir.path(), &rel, &id, step, line, coords, cursor);
                s.push_str(&html);
                cursor = after;
            }
        }
        Err(err) => {
            let _ = write!(s, "<p class=\"bad\">{}</p>", escape(&err.to_string()));
        }
    }
    s.push_str("</details>\n");
    s
}

/// Tokens in words: `1234 in (1000 cached), 56 out; model 1.2 s`.
fn tokens_words(u: &crate::ledger::Usage) -> String {
    format!(
        "<span class=\"tokens-in\">{}</span> in ({} cached), <span class=\"tokens-out\">{}</span> out; model {:.2} s",
        u.input,
        u.cached,
        u.output,
        u.model_ms as f64 / 1000.0
    )
}

/// Colour of a marker kind.
fn mark_colour(kind: MarkKind) -> &'static str {
    match kind {
        MarkKind::Click | MarkKind::DoubleClick | MarkKind::Press => "#e3008c",
        MarkKind::RightClick => "#e85d04",
        MarkKind::MiddleClick => "#8338ec",
        MarkKind::Drag => "#0077b6",
        MarkKind::Scroll => "#2a9d8f",
        MarkKind::Move | MarkKind::CursorAfter => "#495057",
    }
}

/// A marker as SVG in the screenshot's pixels, `r` its ring's radius there.
fn mark_svg(n: usize, mark: &viewer::Mark, r: f64, scale: (f64, f64)) -> String {
    let c = mark_colour(mark.kind);
    // Drawn in the screenshot's pixels; `data-x`/`data-y` keep the recorded screen pixels.
    let (x, y) = (f64::from(mark.at.0) * scale.0, f64::from(mark.at.1) * scale.1);
    let w = r / 4.0;
    let mut g = format!(
        "<g class=\"mark\" data-n=\"{n}\" data-kind=\"{}\" data-x=\"{}\" data-y=\"{}\" data-action=\"{}\"",
        mark.kind.name(),
        mark.at.0,
        mark.at.1,
        mark.action
    );
    if let Some((x2, y2)) = mark.to {
        let _ = write!(g, " data-x2=\"{x2}\" data-y2=\"{y2}\"");
    }
    let _ = write!(g, "><title>{}</title>", escape(&format!("{n}: {}", mark.describe())));
    let dash = if matches!(mark.kind, MarkKind::Move | MarkKind::CursorAfter) {
        format!(" stroke-dasharray=\"{:.1} {:.1}\"", r / 3.0, r / 4.0)
    } else {
        String::new()
    };
    let ring = if mark.kind == MarkKind::Move { r / 2.0 } else { r };
    let _ = write!(
        g,
        "<circle class=\"ring\" cx=\"{x:.1}\" cy=\"{y:.1}\" r=\"{ring:.1}\" fill=\"none\" stroke=\"{c}\" stroke-width=\"{w:.1}\"{dash}/>"
    );
    if mark.kind == MarkKind::DoubleClick {
        let _ = write!(
            g,
            "<circle cx=\"{x:.1}\" cy=\"{y:.1}\" r=\"{:.1}\" fill=\"none\" stroke=\"{c}\" stroke-width=\"{w:.1}\"/>",
            r * 1.45
        );
    }
    if let Some((x2, y2)) = mark.to {
        let (x2, y2) = (f64::from(x2) * scale.0, f64::from(y2) * scale.1);
        let _ = write!(
            g,
            "<line x1=\"{x:.1}\" y1=\"{y:.1}\" x2=\"{x2:.1}\" y2=\"{y2:.1}\" stroke=\"{c}\" stroke-width=\"{w:.1}\"/>\
             <circle class=\"end\" cx=\"{x2:.1}\" cy=\"{y2:.1}\" r=\"{r:.1}\" fill=\"none\" stroke=\"{c}\" stroke-width=\"{w:.1}\"/>"
        );
    }
    if mark.kind == MarkKind::Scroll {
        // An arrow the way the page moves under the wheel: up for a positive dy.
        let (dx, dy) = mark.scroll;
        let (ux, uy) = (f64::from(dx.signum()), -f64::from(dy.signum()));
        let (ex, ey) = (x + ux * r * 2.2, y + uy * r * 2.2);
        let _ = write!(
            g,
            "<line x1=\"{x:.1}\" y1=\"{y:.1}\" x2=\"{ex:.1}\" y2=\"{ey:.1}\" stroke=\"{c}\" stroke-width=\"{w:.1}\"/>\
             <circle cx=\"{ex:.1}\" cy=\"{ey:.1}\" r=\"{:.1}\" fill=\"{c}\"/>",
            w * 1.2
        );
    }
    if mark.kind != MarkKind::Move {
        let _ = write!(g, "<circle class=\"dot\" cx=\"{x:.1}\" cy=\"{y:.1}\" r=\"{:.1}\" fill=\"{c}\"/>", r / 3.0);
    }
    let _ = write!(
        g,
        "<text x=\"{:.1}\" y=\"{:.1}\" font-size=\"{:.1}\" font-family=\"sans-serif\" font-weight=\"bold\" fill=\"{c}\" stroke=\"#fff\" stroke-width=\"{:.1}\" paint-order=\"stroke\">{n}</text></g>",
        x + r * 1.1,
        y - r * 1.1,
        r * 1.3,
        r / 4.0
    );
    g
}

/// One step: the screenshot with its markers, the reply, tool calls, actions,
/// errors, timings and tokens. Answers the cursor after the step as far as known.
fn step_html(
    dir: &Path,
    rel: &str,
    task_id: &str,
    step: &StepRecord,
    line: &serde_json::Value,
    coords: Coords,
    cursor: Option<(i32, i32)>,
) -> (String, Option<(i32, i32)>) {
    let src = url_path(&format!("{rel}/{}", step.screenshot_file));
    // The screenshot's size from its header, for a file of the task folder (a record names nothing else).
    let plain = !step.screenshot_file.contains(['/', '\\']) && !step.screenshot_file.starts_with('.');
    let size = plain.then(|| image::image_dimensions(dir.join(&step.screenshot_file)).ok()).flatten();
    let coords =
        line.get("coords").and_then(serde_json::Value::as_str).and_then(viewer::coords_named).unwrap_or(coords);
    // Actions are in the screen's physical pixels, which the step records; the
    // screenshot is of the same screen (the same size, unless a capture was scaled).
    let screen = step.screen.map(|[w, h]| (w, h)).filter(|&(w, h)| w > 0 && h > 0).or(size);
    let (marks, after) = viewer::marks_of(step, screen.unwrap_or((1, 1)), coords, cursor);
    let scale = match (size, screen) {
        (Some((sw, sh)), Some((w, h))) => (f64::from(sw) / f64::from(w), f64::from(sh) / f64::from(h)),
        _ => (1.0, 1.0),
    };
    let n = step.step;
    let mut s = format!(
        "<section class=\"step\" id=\"{task_id}-step-{n}\" data-step=\"{n}\"><div class=\"shot\"><a href=\"{src}\"><img loading=\"lazy\" src=\"{src}\" alt=\"step {n} screenshot\"{}></a>",
        size.map_or(String::new(), |(w, h)| format!(" width=\"{w}\" height=\"{h}\""))
    );
    if let Some((w, h)) = size.filter(|_| !marks.is_empty()) {
        let r = (f64::from(w.max(h)) / 72.0).max(6.0);
        let _ = write!(
            s,
            "<svg class=\"marks\" xmlns=\"http://www.w3.org/2000/svg\" viewBox=\"0 0 {w} {h}\" preserveAspectRatio=\"none\" aria-hidden=\"true\">"
        );
        for (i, mark) in marks.iter().enumerate() {
            s.push_str(&mark_svg(i + 1, mark, r, scale));
        }
        s.push_str("</svg>");
    }
    s.push_str("</div><div class=\"info\">");
    let t = &step.timings;
    let _ = write!(
        s,
        "<p><b>Step {n}</b> <span class=\"meta\">{} &middot; then window {}</span></p>\
         <p class=\"meta timings\">observe {} ms (screenshot {}, tree {}), predict {} ms (Set-of-Marks {}, model {}), act {} ms, pause {} ms{}</p>",
        escape(&step.first.action_timestamp),
        escape(&step.first.observation.window_title),
        t.observe_ms,
        t.observe.screenshot_ms,
        t.observe.tree_ms.map_or_else(|| "-".to_owned(), |v| v.to_string()),
        t.predict_ms,
        t.predict.som_ms.map_or_else(|| "-".to_owned(), |v| v.to_string()),
        t.predict.model_ms.map_or_else(|| "-".to_owned(), |v| v.to_string()),
        t.act_ms,
        t.pause_ms,
        if t.predict_retries == 0 { String::new() } else { format!(" &middot; {} retries", t.predict_retries) },
    );
    match &step.usage {
        Some(u) => {
            let _ = write!(
                s,
                "<p class=\"tokens\" data-input=\"{}\" data-output=\"{}\" data-cached=\"{}\">Tokens: {}</p>",
                u.input,
                u.output,
                u.cached,
                tokens_words(u)
            );
        }
        None => s.push_str("<p class=\"meta tokens\">Tokens: not reported</p>"),
    }

    let reply = viewer::reply_of(dir, step, line);
    s.push_str("<h4>Model reply</h4>");
    if reply.texts.is_empty() && reply.tool_calls.is_empty() && reply.problem.is_none() {
        s.push_str("<p class=\"meta\">(empty)</p>");
    }
    for (kind, text) in &reply.texts {
        let label =
            if kind == "text" { String::new() } else { format!("<span class=\"meta\">{}</span>", escape(kind)) };
        let _ = write!(
            s,
            "{label}<pre class=\"reply\" data-kind=\"{}\">{}</pre>",
            escape(kind),
            escape(&viewer::bounded(text))
        );
    }
    if let Some(problem) = &reply.problem {
        let _ = write!(s, "<p class=\"bad\">the reply's record cannot be read: {}</p>", escape(problem));
    }
    if !reply.tool_calls.is_empty() {
        s.push_str("<h4>Tool calls</h4><ol class=\"tool-calls\">");
        for call in &reply.tool_calls {
            let _ = write!(
                s,
                "<li><code>{}</code><pre>{}</pre></li>",
                escape(&call.name),
                escape(&viewer::bounded(&call.input))
            );
        }
        s.push_str("</ol>");
    }
    if let Some(record) = &reply.record {
        let href = url_path(&format!("{rel}/{record}"));
        let _ = write!(s, "<p class=\"meta\">record: <a href=\"{href}\">{}</a></p>", escape(record));
    }

    s.push_str("<h4>Actions</h4>");
    if step.actions.is_empty() {
        s.push_str("<p class=\"meta\">(none)</p>");
    } else {
        s.push_str("<ol class=\"actions\">");
        for action in &step.actions {
            let _ = write!(s, "<li><pre>{}</pre></li>", escape(&viewer::bounded(&action_text(action))));
        }
        s.push_str("</ol>");
    }
    if !marks.is_empty() {
        s.push_str("<h4>Markers</h4>");
        if let (Some((sw, sh)), Some((w, h))) = (size, screen) {
            if (sw, sh) != (w, h) {
                let _ = write!(
                    s,
                    "<p class=\"meta scaled\">positions in the screen's {w}x{h} pixels, drawn on the {sw}x{sh} screenshot</p>"
                );
            }
        }
        s.push_str("<ol class=\"legend\">");
        for mark in &marks {
            let _ = write!(s, "<li>action {}: {}</li>", mark.action, escape(&mark.describe()));
        }
        s.push_str("</ol>");
    }

    let mut errors: Vec<String> = step.error.iter().cloned().collect();
    // Each action the executor ran has an outcome, in order; decisions have none.
    let run = step.actions.iter().enumerate().filter(|(_, a)| a.decision().is_none()).map(|(k, _)| k + 1);
    for (k, outcome) in run.zip(&step.outcomes) {
        if let Some(error) = outcome.get("error").and_then(serde_json::Value::as_str) {
            errors.push(format!("action {k}: {error}"));
        }
    }
    errors.extend(t.timeouts.iter().cloned());
    if !errors.is_empty() {
        s.push_str("<h4>Errors</h4><ul class=\"errors bad\">");
        for e in &errors {
            let _ = write!(s, "<li>{}</li>", escape(&viewer::bounded(e)));
        }
        s.push_str("</ul>");
    }
    if let Some(source) = &step.screenshot_source {
        let _ = write!(s, "<p class=\"meta\">screenshot from {}</p>", escape(source));
    }
    s.push_str("</div></section>\n");
    (s, after)
}

/// An action as the page lists it: code as written, typed actions one per line as JSON.
fn action_text(action: &arena_exec::AgentAction) -> String {
    match action {
        arena_exec::AgentAction::Computer(code) | arena_exec::AgentAction::Pyautogui(code) => code.trim().to_owned(),
        arena_exec::AgentAction::Typed(actions) => {
            actions.iter().map(|a| serde_json::to_string(a).unwrap_or_default()).collect::<Vec<_>>().join("\n")
        }
        other => other.summary(),
    }
}

/// Scans `root`, writes `summary.json`, `summary.md` and `report.html` there, and returns the summary.
/// Each task's `traj.html` is written again from its records too, so a folder
/// written by an older version (or merged from several) gets the current viewer;
/// a page that cannot be written is logged and the report goes on.
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
    for task in &found {
        if let Some(episode) = &task.episode {
            if let Err(err) = write_task_page(&task.dir, episode) {
                tracing::warn!(error = %err, "the task's page was not written again");
            }
        }
    }
    Ok((summary, path))
}
