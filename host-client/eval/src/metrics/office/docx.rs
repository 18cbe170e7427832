//! A `.docx` reader that shows a document the way python-docx does for
//! upstream's metrics: body paragraphs (direct `w:p` children of the body,
//! their text from runs and hyperlinks, their direct runs with run
//! properties), paragraph formatting (alignment, line spacing, tab stops),
//! body tables with python-docx's cell grid, and sections with page geometry
//! and their default footers (inherited from earlier sections when unlinked).
//!
//! Only direct formatting is read, as python-docx's properties do: styles are
//! not resolved. This is not a layout engine.

use std::path::Path;

use roxmltree::Node;

use super::package::{parse_xml, Package};
use super::xml::{attr, child, child_val, children, rel_id, toggle};
use crate::metrics::MetricError;

/// EMU per twip (python-docx lengths are EMU).
const EMU_PER_TWIP: i64 = 635;

/// A parsed document.
#[derive(Debug, Clone, Default)]
pub(super) struct Document {
    pub(super) paragraphs: Vec<Paragraph>,
    pub(super) tables: Vec<Table>,
    pub(super) sections: Vec<Section>,
}

/// A paragraph with its direct formatting.
#[derive(Debug, Clone, Default)]
pub(super) struct Paragraph {
    pub(super) text: String,
    pub(super) runs: Vec<Run>,
    /// `w:jc/@w:val`.
    pub(super) alignment: Option<String>,
    /// python-docx's `line_spacing`: a multiple for `auto` spacing (or no `lineRule`), else a length in EMU.
    pub(super) line_spacing: Option<f64>,
    pub(super) tab_stops: Vec<TabStop>,
}

/// A run with the properties the metrics read (`None` when not set directly).
#[derive(Debug, Clone, Default)]
pub(super) struct Run {
    pub(super) font_name: Option<String>,
    pub(super) italic: Option<bool>,
    pub(super) strike: Option<bool>,
    /// Font size in points.
    pub(super) size: Option<f64>,
    /// `Some(true)` for `vertAlign=subscript`, `Some(false)` for another `vertAlign`.
    pub(super) subscript: Option<bool>,
}

/// A tab stop: its `w:val` alignment and position in EMU.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct TabStop {
    pub(super) alignment: String,
    pub(super) position: i64,
}

/// A table as python-docx indexes it.
#[derive(Debug, Clone, Default)]
pub(super) struct Table {
    pub(super) rows: usize,
    pub(super) columns: usize,
    /// `Table._cells`: one entry per grid position, spans repeated; cell text.
    pub(super) cells: Vec<String>,
}

impl Table {
    /// `table.cell(row, col).text`, `None` where python-docx raises `IndexError`.
    pub(super) fn cell(&self, row: usize, col: usize) -> Option<&str> {
        self.cells.get(row * self.columns + col).map(String::as_str)
    }
}

/// A section: page geometry in EMU and the first paragraph of its default footer.
#[derive(Debug, Clone, Default)]
pub(super) struct Section {
    pub(super) page_width: Option<i64>,
    pub(super) left_margin: Option<i64>,
    pub(super) right_margin: Option<i64>,
    /// The text of the footer's first paragraph (`""` for a footer python-docx would create).
    pub(super) footer_first_text: String,
}

impl Document {
    /// Reads `word/document.xml` (and the footer parts) of a docx file.
    ///
    /// # Errors
    ///
    /// [`MetricError::Parse`] when the file is not a docx document.
    pub(super) fn open(path: &Path) -> Result<Document, MetricError> {
        let mut pkg = Package::open(path)?;
        let main = main_part(&mut pkg)?;
        let rels = pkg.rels(&main)?;
        let text = pkg.required(&main)?;
        let xml = parse_xml(&text).map_err(|err| pkg.error(format!("{main}: {err}")))?;
        let body = child(xml.root_element(), "body").ok_or_else(|| pkg.error(format!("{main} has no w:body")))?;
        let mut doc = Document::default();
        let mut sect_nodes = Vec::new();
        for node in body.children().filter(Node::is_element) {
            match node.tag_name().name() {
                "p" => {
                    if let Some(sect) = child(node, "pPr").and_then(|p| child(p, "sectPr")) {
                        sect_nodes.push(sect);
                    }
                    doc.paragraphs.push(paragraph(node));
                }
                "tbl" => doc.tables.push(table(node)),
                "sectPr" => sect_nodes.push(node),
                _ => {}
            }
        }
        let mut previous_footer: Option<String> = None;
        for sect in sect_nodes {
            let own = children(sect, "footerReference")
                .find(|r| attr(*r, "type").is_none_or(|t| t == "default"))
                .and_then(rel_id)
                .and_then(|id| rels.target(id))
                .map(str::to_owned);
            let footer = own.or_else(|| previous_footer.clone());
            let footer_first_text = match &footer {
                Some(part) => pkg.with_xml(part, |x| {
                    Ok(children(x.root_element(), "p").next().map(paragraph_text).unwrap_or_default())
                })?,
                None => String::new(),
            };
            previous_footer = footer;
            let twips = |node: Option<Node<'_, '_>>, name: &str| {
                node.and_then(|n| attr(n, name)).and_then(|v| v.parse::<f64>().ok()).map(|v| v as i64 * EMU_PER_TWIP)
            };
            let margins = child(sect, "pgMar");
            doc.sections.push(Section {
                page_width: twips(child(sect, "pgSz"), "w"),
                left_margin: twips(margins, "left"),
                right_margin: twips(margins, "right"),
                footer_first_text,
            });
        }
        Ok(doc)
    }
}

/// The main document part named by the package relationships (`word/document.xml` usually).
fn main_part(pkg: &mut Package) -> Result<String, MetricError> {
    let rels = pkg.rels("")?;
    let main = rels.of_kind("officeDocument").next().unwrap_or("word/document.xml").to_owned();
    Ok(main)
}

fn paragraph(p: Node<'_, '_>) -> Paragraph {
    let ppr = child(p, "pPr");
    let line_spacing = ppr.and_then(|ppr| child(ppr, "spacing")).and_then(|spacing| {
        let line: f64 = attr(spacing, "line")?.parse().ok()?;
        let emu = line * EMU_PER_TWIP as f64;
        // python-docx: `auto` spacing, which a missing `lineRule` means (the
        // schema default), is a multiple of single (240 twips); `exact` and
        // `atLeast` are lengths.
        let multiple = attr(spacing, "lineRule").is_none_or(|rule| rule == "auto");
        Some(if multiple { emu / 152_400.0 } else { emu.trunc() })
    });
    let tab_stops = ppr
        .and_then(|ppr| child(ppr, "tabs"))
        .into_iter()
        .flat_map(|tabs| children(tabs, "tab"))
        .map(|tab| TabStop {
            alignment: attr(tab, "val").unwrap_or_default().to_owned(),
            position: attr(tab, "pos").and_then(|v| v.parse::<i64>().ok()).unwrap_or(0) * EMU_PER_TWIP,
        })
        .collect();
    Paragraph {
        text: paragraph_text(p),
        runs: children(p, "r").map(run).collect(),
        alignment: ppr.and_then(|ppr| child_val(ppr, "jc")).map(str::to_owned),
        line_spacing,
        tab_stops,
    }
}

/// python-docx's paragraph text: the `w:r` and `w:hyperlink` children in
/// order. Anything else (a `w:fldSimple` page field's shown result, content
/// controls, tracked insertions) is not part of it.
fn paragraph_text(p: Node<'_, '_>) -> String {
    let mut text = String::new();
    for node in p.children().filter(Node::is_element) {
        match node.tag_name().name() {
            "r" => text.push_str(&run_text(node)),
            "hyperlink" => children(node, "r").for_each(|r| text.push_str(&run_text(r))),
            _ => {}
        }
    }
    text
}

fn run_text(r: Node<'_, '_>) -> String {
    let mut text = String::new();
    for node in r.children().filter(Node::is_element) {
        match node.tag_name().name() {
            "t" => text.push_str(node.text().unwrap_or_default()),
            "tab" | "ptab" => text.push('\t'),
            "cr" => text.push('\n'),
            "br" if attr(node, "type").is_none_or(|t| t == "textWrapping") => text.push('\n'),
            "noBreakHyphen" => text.push('-'),
            _ => {}
        }
    }
    text
}

fn run(r: Node<'_, '_>) -> Run {
    let rpr = child(r, "rPr");
    Run {
        font_name: rpr.and_then(|p| child(p, "rFonts")).and_then(|f| attr(f, "ascii")).map(str::to_owned),
        italic: rpr.and_then(|p| toggle(p, "i")),
        strike: rpr.and_then(|p| toggle(p, "strike")),
        size: rpr.and_then(|p| child_val(p, "sz")).and_then(|v| v.parse::<f64>().ok()).map(|half| half / 2.0),
        subscript: rpr.and_then(|p| child_val(p, "vertAlign")).map(|v| v == "subscript"),
    }
}

fn table(tbl: Node<'_, '_>) -> Table {
    let columns = child(tbl, "tblGrid").map_or(0, |g| children(g, "gridCol").count());
    let rows: Vec<Node<'_, '_>> = children(tbl, "tr").collect();
    let mut cells: Vec<String> = Vec::new();
    for tr in &rows {
        for tc in children(*tr, "tc") {
            let tcpr = child(tc, "tcPr");
            let span =
                tcpr.and_then(|p| child_val(p, "gridSpan")).and_then(|v| v.parse::<usize>().ok()).unwrap_or(1).max(1);
            let continued =
                tcpr.and_then(|p| child(p, "vMerge")).is_some_and(|m| attr(m, "val").is_none_or(|v| v == "continue"));
            let text = children(tc, "p").map(paragraph_text).collect::<Vec<_>>().join("\n");
            for i in 0..span {
                let value = if continued && columns > 0 && cells.len() >= columns {
                    cells[cells.len() - columns].clone()
                } else if i > 0 {
                    cells.last().cloned().unwrap_or_default()
                } else {
                    text.clone()
                };
                cells.push(value);
            }
        }
    }
    Table { rows: rows.len(), columns, cells }
}
