//! A reader for the parts of an `.xlsx` workbook that upstream's table
//! metrics look at through openpyxl: sheet names, cell values (cached formula
//! results, as `data_only=True` shows them, and the raw XML view that
//! upstream's `read_cell_value` takes), cell styles (number formats, fonts,
//! fills, differential styles), merged ranges, conditional-formatting rule
//! types, charts and pivot tables.
//!
//! It is not a spreadsheet engine: formulas are never evaluated, and only the
//! style properties the metrics compare are decoded.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use roxmltree::Node;

use arena_shared::calendar::days_from_civil;

use super::package::{parse_xml, Package};
use super::xml::{attr, child, child_val, children, descendants, joined_text, rel_id, toggle, truthy};
use crate::metrics::MetricError;

/// What openpyxl's `Color.rgb` gives for a theme, indexed or automatic colour:
/// the unset descriptor, which prints as this message. Upstream compares it
/// like any other value, so all such colours are equal to each other.
pub(super) const NON_RGB_COLOR: &str = "Values must be of type <class 'str'>";

/// An opened workbook.
#[derive(Debug)]
pub(super) struct Workbook {
    pkg: Package,
    /// Sheet names and their part names, in workbook order.
    sheets: Vec<(String, String)>,
    shared: Vec<String>,
    pub(super) styles: Styles,
    /// Pivot cache definition part by cache id.
    pivot_caches: HashMap<String, String>,
}

/// One cell as the sheet XML stores it.
#[derive(Debug, Clone, Default)]
pub(super) struct Cell {
    /// The `t` attribute (`None` for numbers).
    pub(super) kind: Option<String>,
    /// The `<v>` text.
    pub(super) v: Option<String>,
    /// The text of an inline string (`<is>`).
    pub(super) inline: Option<String>,
    pub(super) has_formula: bool,
    /// Index into the cell formats (`s`).
    pub(super) style: usize,
}

/// A cell value as openpyxl gives it with `data_only=True`.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum Value {
    Empty,
    Number(f64),
    Text(String),
    Bool(bool),
    Error,
    /// A number shown with a date or time format, as openpyxl converts it.
    Date(Moment),
}

/// A date-formatted number as openpyxl's `from_excel` makes it a Python
/// `datetime`, `time` or `timedelta`, in whole milliseconds (openpyxl rounds
/// to them). Values of different kinds are never equal, as in Python.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Moment {
    /// A `datetime`: milliseconds since 1899-12-30 00:00.
    DateTime(i64),
    /// A `time` (a serial in `[0, 1)` under a date format): milliseconds since midnight.
    Time(i64),
    /// A `timedelta` (an elapsed-time format such as `[h]:mm`): milliseconds.
    Duration(i64),
}

const MS_PER_DAY: i64 = 86_400_000;

impl Moment {
    /// `from_excel(serial, timedelta=elapsed)` with the 1900 date system.
    /// `None` where openpyxl fails (a date outside years 1 to 9999, or not a
    /// finite number), which makes the cell an error.
    pub(super) fn from_serial(serial: f64, elapsed: bool) -> Option<Moment> {
        if !serial.is_finite() || serial.abs() > 1e10 {
            return None;
        }
        if elapsed {
            // timedelta(days=v) keeps microseconds; openpyxl then rounds them to
            // milliseconds (half to even) under whole seconds rounded down.
            let micros = (serial * 86_400e6).round_ties_even() as i64;
            let (seconds, rest) = (micros.div_euclid(1_000_000), micros.rem_euclid(1_000_000));
            let millis = (rest as f64 / 1000.0).round_ties_even() as i64;
            return Some(Moment::Duration(seconds * 1000 + millis));
        }
        let day = serial.floor();
        let millis = ((serial - day) * MS_PER_DAY as f64).round_ties_even() as i64;
        if (0.0..1.0).contains(&serial) && millis < MS_PER_DAY {
            return Some(Moment::Time(millis));
        }
        // Excel's phantom 1900-02-29: serials below 60 are a day later in Python.
        let day = day as i64 + i64::from(serial > 0.0 && serial < 60.0);
        let total = day * MS_PER_DAY + millis;
        // datetime covers 0001-01-01 to 9999-12-31.
        let (first, last) = (days_from_civil(1, 1, 1), days_from_civil(10_000, 1, 1));
        let epoch = days_from_civil(1899, 12, 30);
        ((first - epoch) * MS_PER_DAY..(last - epoch) * MS_PER_DAY).contains(&total).then_some(Moment::DateTime(total))
    }
}

/// One parsed worksheet.
#[derive(Debug, Default)]
pub(super) struct Sheet {
    /// Cells by (row, column), both from 1.
    pub(super) cells: BTreeMap<(u32, u32), Cell>,
    /// Merged ranges as (first row, first column, last row, last column).
    pub(super) merged: Vec<(u32, u32, u32, u32)>,
    /// The conditional formats, in document order.
    pub(super) conditional: Vec<Conditional>,
    pub(super) part: String,
}

/// One `conditionalFormatting` element: the ranges it covers and its rules.
#[derive(Debug, Clone, Default)]
pub(super) struct Conditional {
    /// The `sqref` ranges as (first row, first column, last row, last column).
    pub(super) ranges: Vec<(u32, u32, u32, u32)>,
    pub(super) rules: Vec<CfRule>,
}

/// A `cfRule`: its type, differential style and formulas.
#[derive(Debug, Clone, Default)]
pub(super) struct CfRule {
    pub(super) kind: String,
    pub(super) dxf: Option<usize>,
    pub(super) formulas: Vec<String>,
}

/// A differential style (`dxf`): the parts it sets (`None` when absent).
#[derive(Debug, Clone, Default)]
pub(super) struct Dxf {
    pub(super) font: Option<Font>,
    pub(super) fill: Option<Fill>,
    pub(super) num_fmt: Option<String>,
}

/// The decoded `styles.xml`.
#[derive(Debug, Default)]
pub(super) struct Styles {
    num_fmts: HashMap<u32, String>,
    fonts: Vec<Font>,
    fills: Vec<Fill>,
    xfs: Vec<Xf>,
    /// Per cell format: whether its number format shows a date (decided once, not per cell).
    date_xfs: Vec<bool>,
    /// The differential styles conditional formats point at.
    pub(super) dxfs: Vec<Dxf>,
    /// Per cell format: whether it is an elapsed-time format (`[h]:mm`), read as a `timedelta`.
    elapsed_xfs: Vec<bool>,
}

#[derive(Debug, Clone, Copy, Default)]
struct Xf {
    num_fmt: u32,
    font: usize,
    fill: usize,
}

/// A font, with the tri-state flags openpyxl keeps (`None` when the element is absent).
#[derive(Debug, Clone, Default, PartialEq)]
pub(super) struct Font {
    pub(super) name: Option<String>,
    pub(super) family: Option<f64>,
    pub(super) size: Option<f64>,
    pub(super) bold: Option<bool>,
    pub(super) italic: Option<bool>,
    pub(super) underline: Option<String>,
    /// `None` when the font has no `<color>`; else the colour's `rgb`.
    pub(super) color: Option<String>,
}

/// A fill: its element name and, for pattern fills, both colours' `rgb`.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Fill {
    pub(super) tag: String,
    pub(super) fg: Option<String>,
    pub(super) bg: Option<String>,
}

impl Default for Fill {
    fn default() -> Fill {
        Fill { tag: "patternFill".into(), fg: Some(DEFAULT_RGB.into()), bg: Some(DEFAULT_RGB.into()) }
    }
}

/// openpyxl's default `Color()` value.
const DEFAULT_RGB: &str = "00000000";

/// A chart as upstream's `load_charts` sees it.
#[derive(Debug, Clone)]
pub(super) struct Chart {
    /// `"val,cat"` formulas of each series joined with `;`.
    pub(super) series: String,
    pub(super) kind: String,
    pub(super) title: Option<String>,
    /// `None` when the chart has no legend.
    pub(super) legend: Option<String>,
    pub(super) bar_dir: Option<String>,
    pub(super) x_title: Option<String>,
    pub(super) y_title: Option<String>,
}

/// A pivot table's definition, with its cache source.
#[derive(Debug, Clone, Default)]
pub(super) struct Pivot {
    pub(super) name: Option<String>,
    pub(super) location: Option<String>,
    pub(super) visual_totals: bool,
    pub(super) show_empty_row: bool,
    pub(super) show_empty_col: bool,
    pub(super) show_headers: bool,
    /// Per pivot field, the `(h, x)` of its items that have an `x`.
    pub(super) fields: Vec<Vec<(Option<bool>, i64)>>,
    pub(super) page_fields: Vec<i64>,
    pub(super) col_fields: Vec<i64>,
    pub(super) row_fields: Vec<i64>,
    /// (fld, name, subtotal, showDataAs)
    pub(super) data_fields: Vec<(i64, String, String, String)>,
    pub(super) source_type: String,
    pub(super) source_ref: Option<String>,
    pub(super) source_sheet: Option<String>,
}

impl Workbook {
    /// Opens and indexes a workbook (sheet list, shared strings, styles).
    ///
    /// # Errors
    ///
    /// [`MetricError::Parse`] when the file is not an xlsx workbook.
    pub(super) fn open(path: &Path) -> Result<Workbook, MetricError> {
        let mut pkg = Package::open(path)?;
        let book_rels = pkg.rels("xl/workbook.xml")?;
        let (sheets, cache_ids) = pkg.with_xml("xl/workbook.xml", |doc| {
            let root = doc.root_element();
            let mut sheets = Vec::new();
            for sheet in child(root, "sheets").into_iter().flat_map(|s| children(s, "sheet")) {
                let name = attr(sheet, "name").unwrap_or_default().to_owned();
                let part = rel_id(sheet).and_then(|id| book_rels.target(id)).unwrap_or_default().to_owned();
                sheets.push((name, part));
            }
            let mut caches = Vec::new();
            for cache in child(root, "pivotCaches").into_iter().flat_map(|c| children(c, "pivotCache")) {
                if let (Some(id), Some(rid)) = (attr(cache, "cacheId"), rel_id(cache)) {
                    caches.push((id.to_owned(), rid.to_owned()));
                }
            }
            Ok((sheets, caches))
        })?;
        let pivot_caches =
            cache_ids.into_iter().filter_map(|(id, rid)| book_rels.target(&rid).map(|t| (id, t.to_owned()))).collect();
        let shared_part = book_rels.of_kind("sharedStrings").next().unwrap_or("xl/sharedStrings.xml").to_owned();
        let shared = match pkg.part(&shared_part)? {
            Some(text) => {
                let doc = parse_xml(&text).map_err(|err| pkg.error(format!("{shared_part}: {err}")))?;
                children(doc.root_element(), "si").map(joined_text).collect()
            }
            None => Vec::new(),
        };
        let styles_part = book_rels.of_kind("styles").next().unwrap_or("xl/styles.xml").to_owned();
        let styles = match pkg.part(&styles_part)? {
            Some(text) => {
                let doc = parse_xml(&text).map_err(|err| pkg.error(format!("{styles_part}: {err}")))?;
                Styles::parse(doc.root_element())
            }
            None => Styles::default(),
        };
        Ok(Workbook { pkg, sheets, shared, styles, pivot_caches })
    }

    /// The sheet names, in order (chart sheets included, as openpyxl lists them).
    pub(super) fn sheet_names(&self) -> Vec<String> {
        self.sheets.iter().map(|(name, _)| name.clone()).collect()
    }

    fn part_of(&self, name: &str) -> Option<String> {
        self.sheets.iter().find(|(n, _)| n == name).map(|(_, part)| part.clone())
    }

    /// Parses sheet `name`; `None` when the workbook has no such sheet.
    ///
    /// # Errors
    ///
    /// [`MetricError::Parse`] when the sheet part is missing or not XML.
    pub(super) fn sheet(&mut self, name: &str) -> Result<Option<Sheet>, MetricError> {
        let Some(part) = self.part_of(name) else { return Ok(None) };
        let text = self.pkg.required(&part)?;
        let doc = parse_xml(&text).map_err(|err| self.pkg.error(format!("{part}: {err}")))?;
        let mut sheet = Sheet { part: part.clone(), ..Sheet::default() };
        let root = doc.root_element();
        if let Some(data) = child(root, "sheetData") {
            let mut row_no = 0u32;
            for row in children(data, "row") {
                row_no = attr(row, "r").and_then(|r| r.parse().ok()).unwrap_or(row_no + 1);
                let mut col_no = 0u32;
                for c in children(row, "c") {
                    let (r, col) = match attr(c, "r").and_then(parse_coordinate) {
                        Some((r, col)) => (r, col),
                        None => (row_no, col_no + 1),
                    };
                    col_no = col;
                    let cell = Cell {
                        kind: attr(c, "t").map(str::to_owned),
                        v: child(c, "v").map(|v| v.text().unwrap_or_default().to_owned()),
                        inline: child(c, "is").map(joined_text),
                        has_formula: child(c, "f").is_some(),
                        style: attr(c, "s").and_then(|s| s.parse().ok()).unwrap_or(0),
                    };
                    sheet.cells.insert((r, col), cell);
                }
            }
        }
        for merge in child(root, "mergeCells").into_iter().flat_map(|m| children(m, "mergeCell")) {
            if let Some(range) = attr(merge, "ref").and_then(parse_range) {
                sheet.merged.push(range);
            }
        }
        for cf in children(root, "conditionalFormatting") {
            let ranges = attr(cf, "sqref").unwrap_or_default().split_whitespace().filter_map(parse_range).collect();
            let rules = children(cf, "cfRule")
                .map(|rule| CfRule {
                    kind: attr(rule, "type").unwrap_or_default().to_owned(),
                    dxf: attr(rule, "dxfId").and_then(|v| v.parse().ok()),
                    formulas: children(rule, "formula").map(|f| f.text().unwrap_or_default().to_owned()).collect(),
                })
                .collect();
            sheet.conditional.push(Conditional { ranges, rules });
        }
        Ok(Some(sheet))
    }

    /// A cell's value as openpyxl reads it with `data_only=True` (cached formula results, dates by format).
    pub(super) fn value(&self, cell: &Cell) -> Value {
        match cell.kind.as_deref() {
            Some("s") => cell
                .v
                .as_deref()
                .and_then(|v| v.trim().parse::<usize>().ok())
                .and_then(|i| self.shared.get(i))
                .map_or(Value::Empty, |s| Value::Text(s.clone())),
            Some("str") => cell.v.clone().map_or(Value::Empty, Value::Text),
            Some("inlineStr") => cell.inline.clone().or_else(|| cell.v.clone()).map_or(Value::Empty, Value::Text),
            Some("b") => cell.v.as_deref().map_or(Value::Empty, |v| Value::Bool(v.trim() == "1" || v.trim() == "true")),
            Some("e") => Value::Error,
            Some("d") => cell.v.as_deref().and_then(iso_to_millis).map_or_else(
                || cell.v.clone().map_or(Value::Empty, Value::Text),
                |ms| Value::Date(Moment::DateTime(ms)),
            ),
            _ => match cell.v.as_deref().map(str::trim) {
                None | Some("") => Value::Empty,
                Some(v) => match v.parse::<f64>() {
                    Ok(n) if self.styles.is_date(cell.style) => {
                        Moment::from_serial(n, self.styles.is_elapsed(cell.style)).map_or(Value::Error, Value::Date)
                    }
                    Ok(n) => Value::Number(n),
                    Err(_) => Value::Text(v.to_owned()),
                },
            },
        }
    }

    /// Upstream's `read_cell_value`: the raw XML value (`float(v)` for numbers,
    /// the shared or formula string for text, `None` otherwise).
    pub(super) fn raw_value(&self, cell: Option<&Cell>) -> serde_json::Value {
        use serde_json::Value as J;
        let Some(cell) = cell else { return J::Null };
        match cell.kind.as_deref() {
            None | Some("n") => cell
                .v
                .as_deref()
                .and_then(|v| v.trim().parse::<f64>().ok())
                .and_then(serde_json::Number::from_f64)
                .map_or(J::Null, J::Number),
            Some("s") => cell
                .v
                .as_deref()
                .and_then(|v| v.trim().parse::<usize>().ok())
                .and_then(|i| self.shared.get(i))
                .map_or(J::Null, |s| J::String(s.clone())),
            Some("str") => cell.v.clone().map_or(J::Null, J::String),
            _ => J::Null,
        }
    }

    /// The charts drawn on sheet `sheet` (a parsed sheet of this workbook).
    ///
    /// # Errors
    ///
    /// [`MetricError::Parse`] when a drawing or chart part is not XML.
    pub(super) fn charts(&mut self, sheet: &Sheet) -> Result<Vec<Chart>, MetricError> {
        let rels = self.pkg.rels(&sheet.part)?;
        let mut charts = Vec::new();
        for drawing in rels.of_kind("drawing").map(str::to_owned).collect::<Vec<_>>() {
            let drawing_rels = self.pkg.rels(&drawing)?;
            let chart_parts: Vec<String> = self.pkg.with_xml(&drawing, |doc| {
                Ok(descendants(doc.root_element(), "chart")
                    .filter_map(rel_id)
                    .filter_map(|id| drawing_rels.target(id).map(str::to_owned))
                    .collect())
            })?;
            for part in chart_parts {
                if let Some(chart) = self.pkg.with_xml(&part, |doc| Ok(parse_chart(doc.root_element())))? {
                    charts.push(chart);
                }
            }
        }
        Ok(charts)
    }

    /// The pivot tables of sheet `sheet`.
    ///
    /// # Errors
    ///
    /// [`MetricError::Parse`] when a pivot part is not XML.
    pub(super) fn pivots(&mut self, sheet: &Sheet) -> Result<Vec<Pivot>, MetricError> {
        let rels = self.pkg.rels(&sheet.part)?;
        let mut pivots = Vec::new();
        for part in rels.of_kind("pivotTable").map(str::to_owned).collect::<Vec<_>>() {
            let (mut pivot, cache_id) = self.pkg.with_xml(&part, |doc| Ok(parse_pivot(doc.root_element())))?;
            let cache_part = match cache_id.and_then(|id| self.pivot_caches.get(&id).cloned()) {
                Some(cache) => Some(cache),
                None => self.pkg.rels(&part)?.of_kind("pivotCacheDefinition").next().map(str::to_owned),
            };
            if let Some(cache_part) = cache_part {
                self.pkg.with_xml(&cache_part, |doc| {
                    if let Some(source) = child(doc.root_element(), "cacheSource") {
                        pivot.source_type = attr(source, "type").unwrap_or_default().to_owned();
                        if let Some(ws) = child(source, "worksheetSource") {
                            pivot.source_ref = attr(ws, "ref").or_else(|| attr(ws, "name")).map(str::to_owned);
                            pivot.source_sheet = attr(ws, "sheet").map(str::to_owned);
                        }
                    }
                    Ok(())
                })?;
            }
            pivots.push(pivot);
        }
        Ok(pivots)
    }
}

impl Styles {
    fn parse(root: Node<'_, '_>) -> Styles {
        let mut styles = Styles::default();
        for fmt in child(root, "numFmts").into_iter().flat_map(|n| children(n, "numFmt")) {
            if let (Some(id), Some(code)) =
                (attr(fmt, "numFmtId").and_then(|i| i.parse().ok()), attr(fmt, "formatCode"))
            {
                styles.num_fmts.insert(id, code.to_owned());
            }
        }
        styles.fonts = child(root, "fonts").into_iter().flat_map(|f| children(f, "font")).map(parse_font).collect();
        styles.fills = child(root, "fills").into_iter().flat_map(|f| children(f, "fill")).map(parse_fill).collect();
        styles.dxfs = child(root, "dxfs")
            .into_iter()
            .flat_map(|d| children(d, "dxf"))
            .map(|dxf| Dxf {
                font: child(dxf, "font").map(parse_font),
                fill: child(dxf, "fill").map(parse_fill),
                num_fmt: child(dxf, "numFmt").and_then(|n| attr(n, "formatCode")).map(str::to_owned),
            })
            .collect();
        styles.xfs = child(root, "cellXfs")
            .into_iter()
            .flat_map(|x| children(x, "xf"))
            .map(|xf| Xf {
                num_fmt: attr(xf, "numFmtId").and_then(|v| v.parse().ok()).unwrap_or(0),
                font: attr(xf, "fontId").and_then(|v| v.parse().ok()).unwrap_or(0),
                fill: attr(xf, "fillId").and_then(|v| v.parse().ok()).unwrap_or(0),
            })
            .collect();
        styles.date_xfs = (0..styles.xfs.len()).map(|i| is_date_format(&styles.number_format(i))).collect();
        styles.elapsed_xfs = (0..styles.xfs.len()).map(|i| is_elapsed_format(&styles.number_format(i))).collect();
        styles
    }

    /// Whether cell format `style` shows numbers as dates.
    pub(super) fn is_date(&self, style: usize) -> bool {
        match self.date_xfs.get(style) {
            Some(date) => *date,
            None => is_date_format(&self.number_format(style)),
        }
    }

    /// Whether cell format `style` is an elapsed-time format (openpyxl's `is_timedelta_format`).
    pub(super) fn is_elapsed(&self, style: usize) -> bool {
        match self.elapsed_xfs.get(style) {
            Some(elapsed) => *elapsed,
            None => is_elapsed_format(&self.number_format(style)),
        }
    }

    fn xf(&self, style: usize) -> Xf {
        self.xfs.get(style).or_else(|| self.xfs.first()).copied().unwrap_or_default()
    }

    /// The number format code of cell format `style` (built-in ids as openpyxl names them).
    pub(super) fn number_format(&self, style: usize) -> String {
        let id = self.xf(style).num_fmt;
        self.num_fmts.get(&id).cloned().unwrap_or_else(|| builtin_format(id).to_owned())
    }

    /// The font of cell format `style`.
    pub(super) fn font(&self, style: usize) -> Font {
        self.fonts.get(self.xf(style).font).cloned().unwrap_or_default()
    }

    /// The fill of cell format `style`.
    pub(super) fn fill(&self, style: usize) -> Fill {
        self.fills.get(self.xf(style).fill).cloned().unwrap_or_default()
    }
}

fn parse_font(node: Node<'_, '_>) -> Font {
    Font {
        name: child_val(node, "name").map(str::to_owned),
        family: child_val(node, "family").and_then(|v| v.parse().ok()),
        size: child_val(node, "sz").and_then(|v| v.parse().ok()),
        bold: toggle(node, "b"),
        italic: toggle(node, "i"),
        underline: child(node, "u").map(|u| attr(u, "val").unwrap_or("single").to_owned()),
        color: child(node, "color").map(color_rgb),
    }
}

fn parse_fill(node: Node<'_, '_>) -> Fill {
    if let Some(pattern) = child(node, "patternFill") {
        let color = |local| Some(child(pattern, local).map_or_else(|| DEFAULT_RGB.to_owned(), color_rgb));
        Fill { tag: "patternFill".into(), fg: color("fgColor"), bg: color("bgColor") }
    } else if child(node, "gradientFill").is_some() {
        Fill { tag: "gradientFill".into(), fg: None, bg: None }
    } else {
        Fill::default()
    }
}

/// openpyxl's `Color.rgb`: the aRGB string (6 digits get an `00` alpha), or
/// the unset-descriptor text for theme, indexed and automatic colours.
fn color_rgb(node: Node<'_, '_>) -> String {
    match attr(node, "rgb") {
        Some(rgb) if rgb.len() == 6 => format!("00{rgb}"),
        Some(rgb) => rgb.to_owned(),
        None if attr(node, "indexed").is_some() || attr(node, "theme").is_some() || attr(node, "auto").is_some() => {
            NON_RGB_COLOR.to_owned()
        }
        None => DEFAULT_RGB.to_owned(),
    }
}

fn parse_chart(space: Node<'_, '_>) -> Option<Chart> {
    let chart = child(space, "chart")?;
    let plot = child(chart, "plotArea")?;
    let first = plot.children().find(|n| n.is_element() && n.tag_name().name().ends_with("Chart"))?;
    let formula = |ser: Node<'_, '_>, local: &str| -> String {
        child(ser, local)
            .and_then(|v| child(v, "numRef").or_else(|| child(v, "strRef")))
            .and_then(|r| child(r, "f"))
            .and_then(|f| f.text())
            .unwrap_or_default()
            .to_owned()
    };
    let series = children(first, "ser")
        .map(|ser| format!("{},{}", formula(ser, "val"), formula(ser, "cat")))
        .collect::<Vec<_>>()
        .join(";");
    let axis_title = |local: &str| {
        plot.children()
            .filter(|n| n.is_element() && n.tag_name().name().ends_with("Ax"))
            .find(|ax| {
                child_val(*ax, "axPos").is_some_and(|p| {
                    if local == "x" {
                        p == "b" || p == "t"
                    } else {
                        p == "l" || p == "r"
                    }
                })
            })
            .and_then(|ax| child(ax, "title"))
            .and_then(rich_title)
    };
    Some(Chart {
        series,
        kind: first.tag_name().name().to_owned(),
        title: child(chart, "title").and_then(rich_title),
        legend: child(chart, "legend").map(|l| child_val(l, "legendPos").unwrap_or("r").to_owned()),
        bar_dir: child_val(first, "barDir").map(str::to_owned),
        x_title: axis_title("x"),
        y_title: axis_title("y"),
    })
}

/// `title.tx.rich.p[0].r[0].t`: the first run of the first paragraph of a rich title.
fn rich_title(title: Node<'_, '_>) -> Option<String> {
    let rich = child(child(title, "tx")?, "rich")?;
    let p = child(rich, "p")?;
    let r = child(p, "r")?;
    child(r, "t").and_then(|t| t.text()).map(str::to_owned)
}

fn parse_pivot(root: Node<'_, '_>) -> (Pivot, Option<String>) {
    let flag = |name: &str, default: bool| attr(root, name).map_or(default, truthy);
    let index = |n: Node<'_, '_>, name: &str| attr(n, name).and_then(|v| v.parse::<i64>().ok());
    let fields = child(root, "pivotFields")
        .into_iter()
        .flat_map(|f| children(f, "pivotField"))
        .map(|field| {
            child(field, "items")
                .into_iter()
                .flat_map(|items| children(items, "item"))
                .filter_map(|item| index(item, "x").map(|x| (attr(item, "h").map(truthy), x)))
                .collect()
        })
        .collect();
    let list = |outer: &str, inner: &'static str, key: &'static str| -> Vec<i64> {
        child(root, outer).into_iter().flat_map(|o| children(o, inner)).filter_map(|n| index(n, key)).collect()
    };
    let data_fields = child(root, "dataFields")
        .into_iter()
        .flat_map(|d| children(d, "dataField"))
        .map(|d| {
            (
                index(d, "fld").unwrap_or(0),
                attr(d, "name").unwrap_or_default().to_owned(),
                attr(d, "subtotal").unwrap_or("sum").to_owned(),
                attr(d, "showDataAs").unwrap_or("normal").to_owned(),
            )
        })
        .collect();
    let pivot = Pivot {
        name: attr(root, "name").map(str::to_owned),
        location: child(root, "location").and_then(|l| attr(l, "ref")).map(str::to_owned),
        visual_totals: flag("visualTotals", true),
        show_empty_row: flag("showEmptyRow", false),
        show_empty_col: flag("showEmptyCol", false),
        show_headers: flag("showHeaders", true),
        fields,
        page_fields: list("pageFields", "pageField", "fld"),
        col_fields: list("colFields", "field", "x"),
        row_fields: list("rowFields", "field", "x"),
        data_fields,
        ..Pivot::default()
    };
    (pivot, attr(root, "cacheId").map(str::to_owned))
}

/// openpyxl's built-in number formats by id (`General` for ids it does not know).
fn builtin_format(id: u32) -> &'static str {
    match id {
        1 => "0",
        2 => "0.00",
        3 => "#,##0",
        4 => "#,##0.00",
        5 => "\"$\"#,##0_);(\"$\"#,##0)",
        6 => "\"$\"#,##0_);[Red](\"$\"#,##0)",
        7 => "\"$\"#,##0.00_);(\"$\"#,##0.00)",
        8 => "\"$\"#,##0.00_);[Red](\"$\"#,##0.00)",
        9 => "0%",
        10 => "0.00%",
        11 => "0.00E+00",
        12 => "# ?/?",
        13 => "# ??/??",
        14 => "mm-dd-yy",
        15 => "d-mmm-yy",
        16 => "d-mmm",
        17 => "mmm-yy",
        18 => "h:mm AM/PM",
        19 => "h:mm:ss AM/PM",
        20 => "h:mm",
        21 => "h:mm:ss",
        22 => "m/d/yy h:mm",
        37 => "#,##0_);(#,##0)",
        38 => "#,##0_);[Red](#,##0)",
        39 => "#,##0.00_);(#,##0.00)",
        40 => "#,##0.00_);[Red](#,##0.00)",
        41 => "_(* #,##0_);_(* \\(#,##0\\);_(* \"-\"_);_(@_)",
        42 => "_(\"$\"* #,##0_);_(\"$\"* \\(#,##0\\);_(\"$\"* \"-\"_);_(@_)",
        43 => "_(* #,##0.00_);_(* \\(#,##0.00\\);_(* \"-\"??_);_(@_)",
        44 => "_(\"$\"* #,##0.00_)_(\"$\"* \\(#,##0.00\\)_(\"$\"* \"-\"??_)_(@_)",
        45 => "mm:ss",
        46 => "[h]:mm:ss",
        47 => "mmss.0",
        48 => "##0.0E+0",
        49 => "@",
        _ => "General",
    }
}

/// openpyxl's `is_date_format`: the first section, with quoted text, escaped
/// characters and bracketed codes other than elapsed-time ones removed, holds
/// a d, m, y, h or s not preceded by `_` or `\`.
pub(super) fn is_date_format(format: &str) -> bool {
    let first = format.split(';').next().unwrap_or_default();
    let mut stripped = String::new();
    let mut chars = first.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            '"' => {
                for q in chars.by_ref() {
                    if q == '"' {
                        break;
                    }
                }
            }
            '\\' => {
                chars.next();
            }
            '[' => {
                let mut inner = String::new();
                for q in chars.by_ref() {
                    if q == ']' {
                        break;
                    }
                    inner.push(q);
                }
                if matches!(inner.to_ascii_lowercase().as_str(), "h" | "hh" | "m" | "mm" | "s" | "ss") {
                    stripped.push('[');
                    stripped.push_str(&inner);
                    stripped.push(']');
                }
            }
            other => stripped.push(other),
        }
    }
    let chars: Vec<char> = stripped.chars().collect();
    chars.iter().enumerate().any(|(i, c)| {
        matches!(c.to_ascii_lowercase(), 'd' | 'm' | 'y' | 'h' | 's') && (i == 0 || !matches!(chars[i - 1], '_' | '\\'))
    })
}

/// openpyxl's `is_timedelta_format`: the first section holds, anywhere and in
/// any case, `[h]` or `[hh]` (optionally `:mm`, `:ss`, `.0…`), `[m]`/`[mm]`
/// (optionally `:ss`…) or `[s]`/`[ss]`.
pub(super) fn is_elapsed_format(format: &str) -> bool {
    let first = format.split(';').next().unwrap_or_default().to_ascii_lowercase();
    // Any of the alternatives matches as soon as its bracketed unit does; the
    // optional tails never make a match fail.
    ["[h]", "[hh]", "[m]", "[mm]", "[s]", "[ss]"].iter().any(|unit| first.contains(unit))
}

/// `A1` to (row, column), both from 1.
pub(super) fn parse_coordinate(text: &str) -> Option<(u32, u32)> {
    let text = text.trim().replace('$', "");
    let split = text.find(|c: char| c.is_ascii_digit())?;
    let (letters, digits) = text.split_at(split);
    if letters.is_empty() || letters.len() > 3 || !letters.chars().all(|c| c.is_ascii_alphabetic()) {
        return None;
    }
    let col = letters.chars().fold(0u32, |acc, c| acc * 26 + (c.to_ascii_uppercase() as u32 - 'A' as u32 + 1));
    let row = digits.parse().ok()?;
    (row > 0).then_some((row, col))
}

pub(super) fn parse_range(text: &str) -> Option<(u32, u32, u32, u32)> {
    let (a, b) = text.split_once(':').unwrap_or((text, text));
    let (r1, c1) = parse_coordinate(a)?;
    let (r2, c2) = parse_coordinate(b)?;
    Some((r1.min(r2), c1.min(c2), r1.max(r2), c1.max(c2)))
}

/// An ISO date or date-time (`t="d"` cells) as milliseconds since 1899-12-30.
fn iso_to_millis(text: &str) -> Option<i64> {
    let (date, time) = text.trim().split_once('T').unwrap_or((text.trim(), ""));
    let mut parts = date.split('-');
    let y: i64 = parts.next()?.parse().ok()?;
    let m: u32 = parts.next()?.parse().ok()?;
    let d: u32 = parts.next()?.parse().ok()?;
    let days = days_from_civil(y, m, d) - days_from_civil(1899, 12, 30);
    let mut seconds = 0.0;
    if !time.is_empty() {
        let time = time.trim_end_matches('Z');
        let mut hms = time.split(':');
        let h: f64 = hms.next()?.parse().ok()?;
        let mi: f64 = hms.next().unwrap_or("0").parse().ok()?;
        let s: f64 = hms.next().unwrap_or("0").parse().ok()?;
        seconds = h * 3600.0 + mi * 60.0 + s;
    }
    Some(days * MS_PER_DAY + (seconds * 1000.0).round() as i64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn date_formats_are_recognised_as_openpyxl_does() {
        for (format, date) in [
            ("General", false),
            ("0.00", false),
            ("mm-dd-yy", true),
            ("[$-409]d-mmm-yy;@", true),
            ("\"day\" 0", false),
            ("[Red]0.00", false),
            ("[h]:mm:ss", true),
            ("_(* #,##0.00_)", false),
            ("yyyy-mm-dd hh:mm", true),
        ] {
            assert_eq!(is_date_format(format), date, "{format}");
        }
    }

    #[test]
    fn coordinates_and_serials() {
        assert_eq!(parse_coordinate("A1"), Some((1, 1)));
        assert_eq!(parse_coordinate("$AB$12"), Some((12, 28)));
        assert_eq!(parse_coordinate("12"), None);
        assert_eq!(iso_to_millis("1900-03-01"), Some(61 * MS_PER_DAY));
        assert_eq!(iso_to_millis("2024-01-01T12:00:00"), Some(45292 * MS_PER_DAY + MS_PER_DAY / 2));
    }

    #[test]
    fn serials_convert_as_openpyxls_from_excel() {
        use Moment::*;
        // 2024-01-02 12:00 and the same day at midnight are different datetimes.
        assert_eq!(Moment::from_serial(45293.5, false), Some(DateTime(45293 * MS_PER_DAY + MS_PER_DAY / 2)));
        assert_eq!(Moment::from_serial(45293.0, false), Some(DateTime(45293 * MS_PER_DAY)));
        // A serial below 1 is a time of day; below 60 a day later (Excel's 1900-02-29).
        assert_eq!(Moment::from_serial(0.25, false), Some(Time(6 * 3_600_000)));
        assert_eq!(Moment::from_serial(0.0, false), Some(Time(0)));
        assert_eq!(Moment::from_serial(1.0, false), Some(DateTime(2 * MS_PER_DAY)));
        assert_eq!(Moment::from_serial(61.0, false), Some(DateTime(61 * MS_PER_DAY)));
        // Rounded to the millisecond.
        assert_eq!(
            Moment::from_serial(45293.0 + 1.0000004 / 86_400.0, false),
            Some(DateTime(45293 * MS_PER_DAY + 1000))
        );
        // Elapsed-time formats give durations, past a day too.
        assert_eq!(Moment::from_serial(1.25, true), Some(Duration(30 * 3_600_000)));
        // Past year 9999 openpyxl gives up and the cell is an error.
        assert_eq!(Moment::from_serial(3e6, false), None);
        for (format, elapsed) in [("[h]:mm:ss", true), ("[MM]:ss", true), ("h:mm", false), ("0;[h]", false)] {
            assert_eq!(is_elapsed_format(format), elapsed, "{format}");
        }
    }
}
