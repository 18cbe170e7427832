//! Plain-text renderings of guest answers for the terminal: aligned tables,
//! the accessibility outline, sizes and times.
//!
//! Every function returns a `String` so the output is tested as text; none
//! prints. Machine-readable output is the JSON the `--json` flags print, not
//! these.

use std::fmt::Write as _;
use std::time::Duration;

use arena_shared::calendar::iso_seconds;
use arena_shared::files::{DirListing, FileKind, FileStat};
use arena_shared::health::{HealthReport, Readiness};
use arena_shared::observation::{A11yNode, A11yTree, ScreenshotMeta, WindowInfo};
use arena_shared::registry::RegistryValue;

use arena_client::error::component_name;

/// Longest value or name shown in the outline before it is cut.
const MAX_OUTLINE_TEXT: usize = 120;

/// Left-aligned columns separated by two spaces; the last column is not padded.
pub fn table(headers: &[&str], rows: &[Vec<String>]) -> String {
    let columns = headers.len();
    let mut widths: Vec<usize> = headers.iter().map(|h| h.chars().count()).collect();
    for row in rows {
        for (i, cell) in row.iter().enumerate().take(columns) {
            widths[i] = widths[i].max(cell.chars().count());
        }
    }
    let mut out = String::new();
    let mut line = |cells: &mut dyn Iterator<Item = &str>| {
        let mut text = String::new();
        for (i, cell) in cells.enumerate().take(columns) {
            if i + 1 == columns {
                text.push_str(cell);
            } else {
                let pad = widths[i] - cell.chars().count();
                text.push_str(cell);
                text.push_str(&" ".repeat(pad + 2));
            }
        }
        out.push_str(text.trim_end());
        out.push('\n');
    };
    line(&mut headers.iter().copied());
    for row in rows {
        line(&mut row.iter().map(String::as_str));
    }
    out
}

fn readiness_name(status: Readiness) -> &'static str {
    match status {
        Readiness::Ready => "ready",
        Readiness::Degraded => "degraded",
        Readiness::Starting => "starting",
        Readiness::Unknown => "unknown",
    }
}

/// The health report: one summary line, then one row per component.
pub fn health(guest: &str, report: &HealthReport) -> String {
    let mut out = format!(
        "guest {guest}: {} (backend {}, version {}, api {}, up {}{})\n",
        readiness_name(report.status),
        report.backend,
        report.version,
        report.api_version,
        duration(Duration::from_millis(report.uptime_ms)),
        if report.auth_required { ", token required" } else { "" },
    );
    let rows: Vec<Vec<String>> = report
        .components
        .iter()
        .map(|c| {
            vec![
                component_name(c.component),
                if c.ok { "up" } else { "DOWN" }.to_owned(),
                c.elapsed_ms.to_string(),
                c.detail.clone(),
            ]
        })
        .collect();
    out.push_str(&table(&["COMPONENT", "STATE", "MS", "DETAIL"], &rows));
    if let Some(integrity) = &report.integrity {
        out.push_str(&format!("integrity: {integrity}\n"));
    }
    out
}

/// Top-level windows, topmost first.
pub fn windows(list: &[WindowInfo]) -> String {
    let rows: Vec<Vec<String>> = list
        .iter()
        .map(|w| {
            let mut state = Vec::new();
            if w.focused {
                state.push("focused");
            }
            if w.minimized {
                state.push("min");
            }
            if w.maximized {
                state.push("max");
            }
            if !w.visible {
                state.push("hidden");
            }
            vec![
                w.id.to_string(),
                w.process_id.to_string(),
                w.process_name.clone(),
                if state.is_empty() { "-".to_owned() } else { state.join(",") },
                format!("{},{} {}x{}", w.rect.x, w.rect.y, w.rect.width, w.rect.height),
                w.title.clone(),
            ]
        })
        .collect();
    table(&["ID", "PID", "PROCESS", "STATE", "RECT", "TITLE"], &rows)
}

/// The accessibility tree as an indented outline: `role "name" [x,y wxh]`,
/// with ` value="..."` when the element has a value.
pub fn outline(tree: &A11yTree) -> String {
    let mut out = String::new();
    for window in &tree.windows {
        outline_node(&mut out, window, 0);
    }
    if tree.truncated {
        let _ = writeln!(
            out,
            "(truncated: {} nodes in {} ms; raise --max-depth, --max-nodes or --max-ms)",
            tree.node_count, tree.elapsed_ms
        );
    }
    out
}

fn outline_node(out: &mut String, node: &A11yNode, depth: usize) {
    let _ = write!(out, "{}{} {:?}", "  ".repeat(depth), node.role, cut(&node.name));
    if let Some(rect) = &node.rect {
        let _ = write!(out, " [{},{} {}x{}]", rect.x, rect.y, rect.width, rect.height);
    }
    if let Some(value) = node.value.as_deref().filter(|v| !v.is_empty()) {
        let _ = write!(out, " value={:?}", cut(value));
    }
    out.push('\n');
    for child in &node.children {
        outline_node(out, child, depth + 1);
    }
}

fn cut(text: &str) -> String {
    if text.chars().count() <= MAX_OUTLINE_TEXT {
        return text.to_owned();
    }
    let kept: String = text.chars().take(MAX_OUTLINE_TEXT).collect();
    format!("{kept}...")
}

/// One line describing a screenshot and where it went.
pub fn screenshot(meta: &ScreenshotMeta, bytes: usize, path: &str) -> String {
    let format = serde_json::to_value(meta.format).ok().and_then(|v| v.as_str().map(str::to_owned)).unwrap_or_default();
    let mut line = format!(
        "{}x{} {format}, {} -> {path} (screen {}x{}, scale {:.3}, capture {} ms",
        meta.width,
        meta.height,
        size(bytes as u64),
        meta.physical_width,
        meta.physical_height,
        meta.scale,
        meta.capture_ms
    );
    if let Some(cursor) = meta.cursor {
        let _ = write!(line, ", cursor at {},{}", cursor.x, cursor.y);
    }
    if meta.black_frame {
        line.push_str(", BLACK FRAME: the desktop may be locked");
    }
    line.push_str(")\n");
    line
}

fn kind_name(kind: FileKind) -> &'static str {
    match kind {
        FileKind::File => "file",
        FileKind::Dir => "dir",
        FileKind::Other => "other",
        FileKind::Unknown => "?",
    }
}

/// A directory listing.
pub fn listing(list: &DirListing) -> String {
    let rows: Vec<Vec<String>> = list
        .entries
        .iter()
        .map(|e| {
            vec![
                kind_name(e.kind).to_owned(),
                if e.kind == FileKind::Dir { "-".to_owned() } else { e.size.to_string() },
                e.modified_ms.map(timestamp).unwrap_or_else(|| "-".to_owned()),
                e.name.clone(),
            ]
        })
        .collect();
    table(&["KIND", "SIZE", "MODIFIED (UTC)", "NAME"], &rows)
}

/// What `stat` found.
pub fn stat(stat: &FileStat) -> String {
    let mut flags = Vec::new();
    if stat.readonly {
        flags.push("readonly");
    }
    if stat.hidden {
        flags.push("hidden");
    }
    format!(
        "path:     {}\nkind:     {}\nsize:     {} ({})\nmodified: {}\nflags:    {}\n",
        stat.path,
        kind_name(stat.kind),
        stat.size,
        size(stat.size),
        stat.modified_ms.map(timestamp).unwrap_or_else(|| "-".to_owned()),
        if flags.is_empty() { "-".to_owned() } else { flags.join(",") },
    )
}

/// A registry value as `TYPE DATA`.
pub fn registry_value(value: &RegistryValue) -> String {
    match value {
        RegistryValue::String(s) => format!("REG_SZ {s}"),
        RegistryValue::Dword(n) => format!("REG_DWORD {n} (0x{n:08x})"),
        RegistryValue::Qword(n) => format!("REG_QWORD {n} (0x{n:016x})"),
        RegistryValue::MultiString(list) => format!("REG_MULTI_SZ {}", list.join(" | ")),
        RegistryValue::Binary(bytes) => format!("REG_BINARY {}", hex::encode(bytes)),
        RegistryValue::Unknown => "(a value type this client does not know)".to_owned(),
    }
}

/// A byte count for people: `512 B`, `1.5 KiB`, `3.2 MiB`.
pub fn size(bytes: u64) -> String {
    const UNITS: [&str; 4] = ["KiB", "MiB", "GiB", "TiB"];
    if bytes < 1024 {
        return format!("{bytes} B");
    }
    let mut value = bytes as f64 / 1024.0;
    let mut unit = 0;
    while value >= 1024.0 && unit + 1 < UNITS.len() {
        value /= 1024.0;
        unit += 1;
    }
    format!("{value:.1} {}", UNITS[unit])
}

/// A duration for people: `87 ms`, `1.24 s`, `3m05s`.
pub fn duration(d: Duration) -> String {
    let ms = d.as_millis();
    if ms < 1000 {
        format!("{ms} ms")
    } else if ms < 60_000 {
        format!("{:.2} s", d.as_secs_f64())
    } else {
        let secs = d.as_secs();
        format!("{}m{:02}s", secs / 60, secs % 60)
    }
}

/// Milliseconds since the Unix epoch as `YYYY-MM-DD HH:MM:SS` in UTC.
pub fn timestamp(ms: i64) -> String {
    iso_seconds(ms.div_euclid(1000))
}

#[cfg(test)]
mod tests {
    use arena_shared::geometry::{CoordinateSpace, Rect};
    use arena_shared::health::{Component, ComponentHealth};
    use arena_shared::observation::A11yBackend;

    use super::*;

    #[test]
    fn tables_align_columns() {
        let text = table(
            &["A", "LONGER", "LAST"],
            &[vec!["xyz".into(), "1".into(), "end".into()], vec!["q".into(), "22".into(), "".into()]],
        );
        assert_eq!(text, "A    LONGER  LAST\nxyz  1       end\nq    22\n");
    }

    #[test]
    fn outline_indents_children_and_shows_rects_and_values() {
        let edit = A11yNode {
            role: "Edit".into(),
            name: "Text editor".into(),
            value: Some("hello \"you\"".into()),
            rect: Some(Rect::new(10, 20, 300, 200)),
            ..A11yNode::default()
        };
        let window = A11yNode {
            role: "Window".into(),
            name: "Untitled - Notepad".into(),
            children: vec![edit],
            ..A11yNode::default()
        };
        let tree = A11yTree {
            backend: A11yBackend::Uia,
            windows: vec![window],
            truncated: true,
            node_count: 2,
            elapsed_ms: 7,
            coordinate_space: CoordinateSpace::Physical,
            windows_walked: Vec::new(),
        };
        assert_eq!(
            outline(&tree),
            "Window \"Untitled - Notepad\"\n  Edit \"Text editor\" [10,20 300x200] value=\"hello \\\"you\\\"\"\n\
             (truncated: 2 nodes in 7 ms; raise --max-depth, --max-nodes or --max-ms)\n"
        );
    }

    #[test]
    fn health_marks_down_components() {
        let report = HealthReport {
            status: Readiness::Degraded,
            version: "0.1.0".into(),
            api_version: "1".into(),
            backend: "stub".into(),
            components: vec![
                ComponentHealth { component: Component::Capture, ok: true, detail: "1440x900".into(), elapsed_ms: 3 },
                ComponentHealth {
                    component: Component::Accessibility,
                    ok: false,
                    detail: "no UIA".into(),
                    elapsed_ms: 12,
                },
            ],
            uptime_ms: 1500,
            auth_required: true,
            session_id: None,
            integrity: None,
            boot_id: None,
        };
        let text = health("http://g:5000", &report);
        assert_eq!(
            text,
            "guest http://g:5000: degraded (backend stub, version 0.1.0, api 1, up 1.50 s, token required)\n\
             COMPONENT      STATE  MS  DETAIL\n\
             capture        up     3   1440x900\n\
             accessibility  DOWN   12  no UIA\n"
        );
        let elevated = HealthReport { integrity: Some("High, elevated (full administrator token)".into()), ..report };
        assert!(health("g", &elevated).ends_with("integrity: High, elevated (full administrator token)\n"));
    }

    #[test]
    fn sizes_durations_and_timestamps() {
        fn check(actual: String, expected: &str) {
            assert_eq!(actual, expected);
        }
        check(size(0), "0 B");
        check(size(1023), "1023 B");
        check(size(1536), "1.5 KiB");
        check(size(5 * 1024 * 1024), "5.0 MiB");
        check(duration(Duration::from_millis(87)), "87 ms");
        check(duration(Duration::from_millis(1240)), "1.24 s");
        check(duration(Duration::from_secs(185)), "3m05s");
        check(timestamp(0), "1970-01-01 00:00:00");
        check(timestamp(951_782_400_000), "2000-02-29 00:00:00");
        check(timestamp(1_700_000_000_123), "2023-11-14 22:13:20");
        check(timestamp(-1000), "1969-12-31 23:59:59");
        check(registry_value(&RegistryValue::Dword(10)), "REG_DWORD 10 (0x0000000a)");
    }
}
