//! Upstream's `compare_table(result, expected, rules=[...])`: a list of rules
//! checked in order, all of which must hold (score 1) or the first failing
//! one ends the check (score 0).
//!
//! Rules implemented (every type the corpus uses, plus their close kin):
//! `sheet_name`, `sheet_data` (pandas semantics, see `frame.rs`), `style`
//! (per-cell props over the sheet's used range), `check_cell`, `chart`,
//! `pivot_table`. Conditional formats inside a `style` rule are evaluated as
//! upstream does (see `cond.rs`): cells an `expression` rule holds for take
//! the rule's differential style.

use serde_json::{json, Map, Value as J};
use std::collections::{BTreeMap, BTreeSet};

use super::cond::{Condition, V};
use super::frame::Frame;
use super::xlsx::{parse_coordinate, Dxf, Sheet, Value, Workbook};
use crate::metrics::{file_of, MetricError, MetricInput};
use crate::value::py_eq;

/// The most cells a `style` rule walks (upstream walks the whole used range too,
/// but a stray styled cell at the sheet's end should not exhaust memory).
const MAX_STYLE_CELLS: u64 = 5_000_000;

/// Which workbook a rule's sheet index points into.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Side {
    Result,
    Expected,
}

struct Books {
    result: Workbook,
    expected: Option<Workbook>,
    result_names: Vec<String>,
    expected_names: Option<Vec<String>>,
}

impl Books {
    fn book(&mut self, side: Side) -> Result<&mut Workbook, MetricError> {
        match side {
            Side::Result => Ok(&mut self.result),
            Side::Expected => self
                .expected
                .as_mut()
                .ok_or_else(|| MetricError::BadInput("the rule names the expected workbook, but there is none".into())),
        }
    }

    /// Upstream's `_parse_sheet_idx`: an int (result sheet by position), or
    /// `RI<n>`/`EI<n>` (by position) / `RN<name>`/`EN<name>` (by name). A
    /// position out of range gives the empty name, which no sheet has.
    fn parse_idx(&self, idx: &J) -> Result<(Side, String), MetricError> {
        let by_index = |names: Option<&Vec<String>>, i: i64| -> String {
            let Some(names) = names else { return String::new() };
            let len = names.len() as i64;
            let i = if i < 0 { i + len } else { i };
            usize::try_from(i).ok().and_then(|i| names.get(i)).cloned().unwrap_or_default()
        };
        match idx {
            J::Number(n) => {
                let i =
                    n.as_i64().ok_or_else(|| MetricError::BadInput(format!("sheet index {n} is not an integer")))?;
                Ok((Side::Result, by_index(Some(&self.result_names), i)))
            }
            J::String(s) => {
                let (prefix, rest) = (s.get(..2).unwrap_or_default(), s.get(2..).unwrap_or_default());
                let index = || rest.parse::<i64>().ok();
                match prefix {
                    "RI" => {
                        Ok((Side::Result, index().map(|i| by_index(Some(&self.result_names), i)).unwrap_or_default()))
                    }
                    "RN" => Ok((Side::Result, rest.to_owned())),
                    "EI" => Ok((
                        Side::Expected,
                        index().map(|i| by_index(self.expected_names.as_ref(), i)).unwrap_or_default(),
                    )),
                    "EN" => Ok((Side::Expected, rest.to_owned())),
                    _ => Err(MetricError::BadInput(format!("unrecognized sheet index {s:?}"))),
                }
            }
            other => Err(MetricError::BadInput(format!("unrecognized sheet index {other}"))),
        }
    }

    fn sheet(&mut self, idx: &J) -> Result<(Side, String, Option<Sheet>), MetricError> {
        let (side, name) = self.parse_idx(idx)?;
        let sheet = self.book(side)?.sheet(&name)?;
        Ok((side, name, sheet))
    }
}

/// `compare_table`.
pub(super) fn compare_table(input: &MetricInput) -> Result<f64, MetricError> {
    if input.result.is_none() {
        return Ok(0.0);
    }
    let result = Workbook::open(file_of(&input.result, "result")?)?;
    let expected = match &input.expected {
        None => None,
        Some(value) if value.is_none() => None,
        Some(value) => Some(Workbook::open(file_of(value, "expected")?)?),
    };
    let rules = match input.options.get("rules") {
        Some(J::Array(rules)) => rules,
        Some(other) => return Err(MetricError::BadInput(format!("options.rules must be a list, not {other}"))),
        None => return Err(MetricError::BadInput("compare_table needs options.rules".into())),
    };
    let result_names = result.sheet_names();
    let expected_names = expected.as_ref().map(Workbook::sheet_names);
    let mut books = Books { result, expected, result_names, expected_names };
    for rule in rules {
        let J::Object(rule) = rule else {
            return Err(MetricError::BadInput(format!("a rule must be a dict, not {rule}")));
        };
        let kind = rule.get("type").and_then(J::as_str).unwrap_or_default();
        let pass = match kind {
            "sheet_name" => Some(books.expected_names.as_ref() == Some(&books.result_names)),
            "sheet_data" => sheet_data(&mut books, rule)?,
            "style" => Some(style(&mut books, rule)?),
            "check_cell" => check_cell(&mut books, rule)?,
            "chart" => Some(charts(&mut books, rule, "sheet_idx0")? == charts(&mut books, rule, "sheet_idx1")?),
            "pivot_table" => Some(pivots(&mut books, rule, "sheet_idx0")? == pivots(&mut books, rule, "sheet_idx1")?),
            other => return Err(MetricError::BadInput(format!("unimplemented sheet check: {other}"))),
        };
        match pass {
            // Upstream returns 0 at once when the result sheet a rule reads is missing.
            None => return Ok(0.0),
            Some(false) => {
                tracing::debug!(rule = kind, "compare_table rule failed");
                return Ok(0.0);
            }
            Some(true) => {}
        }
    }
    Ok(1.0)
}

fn idx<'a>(rule: &'a Map<String, J>, key: &str) -> Result<&'a J, MetricError> {
    rule.get(key).ok_or_else(|| MetricError::BadInput(format!("the rule has no `{key}`")))
}

/// `sheet_data`: both sheets read as data frames, rounded to `precision` (4) decimals, `equals`.
/// `None` when the first sheet is missing (upstream scores 0).
fn sheet_data(books: &mut Books, rule: &Map<String, J>) -> Result<Option<bool>, MetricError> {
    let precision = rule.get("precision").and_then(J::as_i64).unwrap_or(4);
    let precision = i32::try_from(precision)
        .map_err(|_| MetricError::BadInput(format!("precision {precision} is out of range")))?;
    let (side0, _, first) = books.sheet(idx(rule, "sheet_idx0")?)?;
    let Some(first) = first else { return Ok(None) };
    let mut frame0 = frame_of(books.book(side0)?, &first);
    let (side1, name1, second) = books.sheet(idx(rule, "sheet_idx1")?)?;
    let Some(second) = second else {
        return match side1 {
            Side::Result => Ok(Some(false)),
            Side::Expected => Err(MetricError::BadInput(format!("the expected workbook has no sheet {name1:?}"))),
        };
    };
    let mut frame1 = frame_of(books.book(side1)?, &second);
    frame0.round(precision);
    frame1.round(precision);
    Ok(Some(frame0.equals(&frame1)))
}

/// The sheet's values from A1 to its last non-empty cell, as `read_excel` reads them.
pub(super) fn frame_of(book: &Workbook, sheet: &Sheet) -> Frame {
    // Bounds come from cells holding values only: a styled but empty cell far
    // down the sheet would be trimmed by pandas anyway and must not size the grid.
    let values: Vec<((u32, u32), Value)> = sheet
        .cells
        .iter()
        .map(|(&pos, cell)| (pos, book.value(cell)))
        .filter(|(_, value)| !matches!(value, Value::Empty))
        .collect();
    let (rows, cols) = values.iter().fold((0, 0), |(r, c), &((row, col), _)| (r.max(row), c.max(col)));
    let mut grid = vec![vec![Value::Empty; cols as usize]; rows as usize];
    for ((row, col), value) in values {
        grid[row as usize - 1][col as usize - 1] = value;
    }
    Frame::from_grid(&grid)
}

/// Upstream's `_read_cell_style` for one property of one cell, from the
/// cell's own style, or from `dxf` (a conditional format's differential
/// style) when given.
fn cell_style(
    book: &Workbook,
    sheet: &Sheet,
    coord: (u32, u32),
    prop: &str,
    dxf: Option<&Dxf>,
) -> Result<J, MetricError> {
    let merged_away = sheet
        .merged
        .iter()
        .any(|&(r1, c1, r2, c2)| (r1..=r2).contains(&coord.0) && (c1..=c2).contains(&coord.1) && (r1, c1) != coord);
    // Cells hidden under a merge are openpyxl `MergedCell`s with the default style and no value.
    let cell = if merged_away { None } else { sheet.cells.get(&coord) };
    let style = cell.map_or(0, |c| c.style);
    // openpyxl loads without data_only here, so a formula counts as a value.
    let has_value = cell.is_some_and(|c| c.has_formula || c.v.is_some() || c.inline.is_some());
    let styles = &book.styles;
    if let Some(dxf) = dxf {
        return dxf_style(book, cell, has_value, prop, dxf);
    }
    let font = || styles.font(style);
    let opt = |v: Option<J>| v.unwrap_or(J::Null);
    let value = match prop {
        "number_format" => {
            // openpyxl's `data_type == "n"`: a plain number. A number under a
            // date format is a date cell (`"d"`), so it has no number format here.
            let numeric = cell.is_some_and(|c| {
                !c.has_formula
                    && c.v.is_some()
                    && matches!(c.kind.as_deref(), None | Some("n"))
                    && !styles.is_date(c.style)
            });
            if numeric {
                J::String(styles.number_format(style))
            } else {
                J::Null
            }
        }
        "font_name" if has_value => opt(font().name.map(J::String)),
        "font_family" if has_value => opt(font().family.map(J::from)),
        "font_color" if has_value => opt(font().color.map(J::String)),
        "font_bold" if has_value => opt(font().bold.map(J::Bool)),
        "font_italic" if has_value => opt(font().italic.map(J::Bool)),
        "font_underline" if has_value => opt(font().underline.map(J::String)),
        "font_size" if has_value => opt(font().size.map(J::from)),
        "font_name" | "font_family" | "font_color" | "font_bold" | "font_italic" | "font_underline" | "font_size" => {
            J::Null
        }
        "fill_type" => J::String(styles.fill(style).tag),
        "bgcolor" => opt(styles.fill(style).bg.map(J::String)),
        "fgcolor" => opt(styles.fill(style).fg.map(J::String)),
        other => return Err(MetricError::BadInput(format!("unsupported style: {other}"))),
    };
    Ok(value)
}

/// `_read_cell_style(prop, cell, diff_style)`: the property from the
/// differential style. A font property of a cell with a value needs the dxf
/// to have a font (upstream fails otherwise), a fill property is `None`
/// without a fill, a number format needs the dxf's (plain numbers only).
fn dxf_style(
    book: &Workbook,
    cell: Option<&super::xlsx::Cell>,
    has_value: bool,
    prop: &str,
    dxf: &Dxf,
) -> Result<J, MetricError> {
    let no_font =
        || MetricError::BadInput("a conditional format's style has no font, which upstream cannot read".into());
    let opt = |v: Option<J>| v.unwrap_or(J::Null);
    Ok(match prop {
        "number_format" => {
            let numeric = cell.is_some_and(|c| {
                !c.has_formula
                    && c.v.is_some()
                    && matches!(c.kind.as_deref(), None | Some("n"))
                    && !book.styles.is_date(c.style)
            });
            if !numeric {
                J::Null
            } else {
                J::String(dxf.num_fmt.clone().ok_or_else(|| {
                    MetricError::BadInput(
                        "a conditional format's style has no number format, which upstream cannot read".into(),
                    )
                })?)
            }
        }
        "font_name" | "font_family" | "font_color" | "font_bold" | "font_italic" | "font_underline" | "font_size"
            if !has_value =>
        {
            J::Null
        }
        "font_name" => opt(dxf.font.as_ref().ok_or_else(no_font)?.name.clone().map(J::String)),
        "font_family" => opt(dxf.font.as_ref().ok_or_else(no_font)?.family.map(J::from)),
        "font_color" => opt(dxf.font.as_ref().ok_or_else(no_font)?.color.clone().map(J::String)),
        "font_bold" => opt(dxf.font.as_ref().ok_or_else(no_font)?.bold.map(J::Bool)),
        "font_italic" => opt(dxf.font.as_ref().ok_or_else(no_font)?.italic.map(J::Bool)),
        "font_underline" => opt(dxf.font.as_ref().ok_or_else(no_font)?.underline.clone().map(J::String)),
        "font_size" => opt(dxf.font.as_ref().ok_or_else(no_font)?.size.map(J::from)),
        "fill_type" => opt(dxf.fill.as_ref().map(|f| J::String(f.tag.clone()))),
        "bgcolor" => opt(dxf.fill.as_ref().and_then(|f| f.bg.clone()).map(J::String)),
        "fgcolor" => opt(dxf.fill.as_ref().and_then(|f| f.fg.clone()).map(J::String)),
        other => return Err(MetricError::BadInput(format!("unsupported style: {other}"))),
    })
}

/// Upstream's conditional-format pass of `load_xlsx_styles`: for every
/// `expression` rule, each covered cell the formula holds for gets its style
/// list from the rule's differential style (later rules overwrite earlier
/// ones). Any other rule type is an error, as upstream raises.
fn conditional_styles(
    book: &Workbook,
    sheet: &Sheet,
    props: &[String],
    out: &mut BTreeMap<(u32, u32), Vec<J>>,
) -> Result<(), MetricError> {
    let raw = |coord: (u32, u32)| V::from_json(&book.raw_value(sheet.cells.get(&coord)));
    for format in &sheet.conditional {
        for rule in &format.rules {
            if rule.kind != "expression" {
                return Err(MetricError::BadInput(format!(
                    "conditional formatting rule type {:?} is not evaluated (upstream raises NotImplementedError)",
                    rule.kind
                )));
            }
            let formula = rule
                .formulas
                .first()
                .ok_or_else(|| MetricError::BadInput("a conditional formatting expression has no formula".into()))?;
            let condition = Condition::compile(formula)?;
            let ranges: Vec<V> = Condition::absolute_ranges(formula)?
                .into_iter()
                .map(|(r1, c1, r2, c2)| {
                    V::List((r1..=r2).flat_map(|r| (c1..=c2).map(move |c| (r, c))).map(raw).collect())
                })
                .collect();
            let dxf = rule.dxf.and_then(|i| book.styles.dxfs.get(i));
            for &(r1, c1, r2, c2) in &format.ranges {
                if u64::from(r2 - r1 + 1) * u64::from(c2 - c1 + 1) > MAX_STYLE_CELLS {
                    return Err(MetricError::BadInput("a conditional format covers too many cells to evaluate".into()));
                }
                for row in r1..=r2 {
                    for col in c1..=c2 {
                        if condition.holds(raw((row, col)), &ranges)? {
                            let values = props
                                .iter()
                                .map(|p| cell_style(book, sheet, (row, col), p, dxf))
                                .collect::<Result<Vec<_>, _>>()?;
                            out.insert((row, col), values);
                        }
                    }
                }
            }
        }
    }
    Ok(())
}

/// Every cell of the used range (A1 to the last row and column holding any
/// cell, merged ranges included) mapped to its list of style values, then
/// the conditional formats' styles of the cells they apply to.
fn sheet_styles(book: &Workbook, sheet: &Sheet, props: &[String]) -> Result<BTreeMap<(u32, u32), Vec<J>>, MetricError> {
    let mut rows = 0;
    let mut cols = 0;
    for &(r, c) in sheet.cells.keys() {
        rows = rows.max(r);
        cols = cols.max(c);
    }
    for &(_, _, r2, c2) in &sheet.merged {
        rows = rows.max(r2);
        cols = cols.max(c2);
    }
    if u64::from(rows) * u64::from(cols) > MAX_STYLE_CELLS {
        return Err(MetricError::BadInput(format!(
            "the sheet's used range ({rows} rows x {cols} columns) is too large to compare styles"
        )));
    }
    let mut out = BTreeMap::new();
    for col in 1..=cols {
        for row in 1..=rows {
            let values =
                props.iter().map(|p| cell_style(book, sheet, (row, col), p, None)).collect::<Result<Vec<_>, _>>()?;
            out.insert((row, col), values);
        }
    }
    conditional_styles(book, sheet, props, &mut out)?;
    Ok(out)
}

fn string_list(rule: &Map<String, J>, key: &str) -> Vec<String> {
    rule.get(key)
        .and_then(J::as_array)
        .map(|a| a.iter().filter_map(J::as_str).map(str::to_owned).collect())
        .unwrap_or_default()
}

/// `style`: the style dicts of both sheets are equal (a missing sheet gives an empty dict).
fn style(books: &mut Books, rule: &Map<String, J>) -> Result<bool, MetricError> {
    let props = string_list(rule, "props");
    let mut dicts = Vec::new();
    for key in ["sheet_idx0", "sheet_idx1"] {
        let (side, _, sheet) = books.sheet(idx(rule, key)?)?;
        let dict = match sheet {
            Some(sheet) => sheet_styles(books.book(side)?, &sheet, &props)?,
            None => BTreeMap::new(),
        };
        dicts.push(dict);
    }
    Ok(dicts[0].len() == dicts[1].len()
        && dicts[0]
            .iter()
            .zip(&dicts[1])
            .all(|((ka, va), (kb, vb))| ka == kb && va.iter().zip(vb).all(|(a, b)| py_eq(a, b))))
}

/// `check_cell`: each prop of one cell matches its `{method, ref}` rule.
fn check_cell(books: &mut Books, rule: &Map<String, J>) -> Result<Option<bool>, MetricError> {
    let (side, _, sheet) = books.sheet(idx(rule, "sheet_idx")?)?;
    let Some(sheet) = sheet else { return Ok(None) };
    let coordinate = idx(rule, "coordinate")?.as_str().unwrap_or_default();
    let coord =
        parse_coordinate(coordinate).ok_or_else(|| MetricError::BadInput(format!("bad coordinate {coordinate:?}")))?;
    let props = match idx(rule, "props")? {
        J::Object(props) => props,
        other => return Err(MetricError::BadInput(format!("check_cell props must be a dict, not {other}"))),
    };
    let book = books.book(side)?;
    for (prop, matcher) in props {
        let value = if prop == "value" {
            book.raw_value(sheet.cells.get(&coord))
        } else {
            cell_style(book, &sheet, coord, prop, None)?
        };
        if !match_value_to_rule(&value, matcher)? {
            return Ok(Some(false));
        }
    }
    Ok(Some(true))
}

/// Upstream's `_match_value_to_rule` for the methods that need no formula engine.
pub(super) fn match_value_to_rule(value: &J, rule: &J) -> Result<bool, MetricError> {
    let method = rule.get("method").and_then(J::as_str).unwrap_or_default();
    let reference = rule.get("ref").unwrap_or(&J::Null);
    let number = |v: &J| v.as_f64().or_else(|| v.as_bool().map(|b| f64::from(u8::from(b))));
    let order = |a: &J, b: &J| -> Result<std::cmp::Ordering, MetricError> {
        match (a, b) {
            (J::String(x), J::String(y)) => Ok(x.cmp(y)),
            _ => match (number(a), number(b)) {
                (Some(x), Some(y)) => x.partial_cmp(&y).ok_or_else(|| MetricError::BadInput("cannot order NaN".into())),
                _ => Err(MetricError::BadInput(format!("cannot order {a} and {b}"))),
            },
        }
    };
    use std::cmp::Ordering::*;
    match method {
        "eq" => Ok(py_eq(value, reference)),
        "ne" => Ok(!py_eq(value, reference)),
        "lt" => Ok(order(value, reference)? == Less),
        "le" => Ok(order(value, reference)? != Greater),
        "gt" => Ok(order(value, reference)? == Greater),
        "ge" => Ok(order(value, reference)? != Less),
        m if m.starts_with("approx:") => {
            let threshold: f64 = m[7..].parse().map_err(|_| MetricError::BadInput(format!("bad method {m}")))?;
            let wanted = number(reference)
                .ok_or_else(|| MetricError::BadInput(format!("approx needs a numeric ref, not {reference}")))?;
            let got = match value {
                J::String(s) => s.trim().parse::<f64>().ok(),
                other => number(other),
            };
            Ok(got.is_some_and(|g| (g - wanted).abs() <= threshold))
        }
        m if m.starts_with("range.") && m.len() == 8 => {
            let bounds = reference
                .as_array()
                .filter(|a| a.len() == 2)
                .ok_or_else(|| MetricError::BadInput("range needs a [low, high] ref".into()))?;
            let (left, right) = (&m[6..7], &m[7..8]);
            let low = order(&bounds[0], value)?;
            let high = order(value, &bounds[1])?;
            let ok = |o: std::cmp::Ordering, strict: &str| if strict == "t" { o == Less } else { o != Greater };
            Ok(ok(low, left) && ok(high, right))
        }
        "str_list_eq" | "str_set_eq" => {
            let text = value.as_str().unwrap_or_default().trim_matches(|c| c == '"' || c == '\'');
            let items: Vec<&str> = text.split(',').collect();
            let refs: Vec<&str> =
                reference.as_array().map(|a| a.iter().filter_map(J::as_str).collect()).unwrap_or_default();
            if method == "str_list_eq" {
                Ok(items == refs)
            } else {
                Ok(items.into_iter().collect::<BTreeSet<_>>() == refs.into_iter().collect::<BTreeSet<_>>())
            }
        }
        other => Err(MetricError::BadInput(format!("unsupported match method {other:?}"))),
    }
}

/// `load_charts`: charts of the sheet keyed by their series formulas, with the asked properties.
fn charts(books: &mut Books, rule: &Map<String, J>, key: &str) -> Result<BTreeMap<String, J>, MetricError> {
    let props = string_list(rule, "chart_props");
    let (side, _, sheet) = books.sheet(idx(rule, key)?)?;
    let Some(sheet) = sheet else { return Ok(BTreeMap::new()) };
    let mut out = BTreeMap::new();
    for chart in books.book(side)?.charts(&sheet)? {
        let mut info = Map::new();
        for prop in &props {
            let value = match prop.as_str() {
                "title" => json!(chart.title),
                "legend" => json!(chart.legend),
                "type" => json!(chart.kind),
                "direction" => json!(chart.bar_dir),
                "xtitle" => json!(chart.x_title),
                "ytitle" => json!(chart.y_title),
                // openpyxl never reads a chart's size back: every loaded chart has its defaults.
                "width" => json!(15.0),
                "height" => json!(7.5),
                other => return Err(MetricError::BadInput(format!("unsupported chart property {other:?}"))),
            };
            info.insert(prop.clone(), value);
        }
        out.insert(chart.series.clone(), J::Object(info));
    }
    Ok(out)
}

/// `load_pivot_tables`: pivots of the sheet keyed by their (trimmed) source range.
fn pivots(books: &mut Books, rule: &Map<String, J>, key: &str) -> Result<BTreeMap<String, J>, MetricError> {
    let props: BTreeSet<String> = string_list(rule, "pivot_props").into_iter().collect();
    let (side, _, sheet) = books.sheet(idx(rule, key)?)?;
    let Some(sheet) = sheet else { return Ok(BTreeMap::new()) };
    let mut out = BTreeMap::new();
    for pvt in books.book(side)?.pivots(&sheet)? {
        // Fields without selected items at either end are dropped, and the
        // source range and field indices shifted to match.
        let left = pvt.fields.iter().take_while(|f| f.is_empty()).count();
        let rest = &pvt.fields[left..];
        let right = rest.iter().rev().take_while(|f| f.is_empty()).count();
        let selection = &rest[..rest.len() - right];
        let source_ref = pvt.source_ref.clone().unwrap_or_default();
        let source =
            match source_ref.split_once(':').and_then(|(a, b)| Some((parse_coordinate(a)?, parse_coordinate(b)?))) {
                Some(((r1, c1), (r2, c2))) => format!(
                    "{};({}, {}):({}, {});{}",
                    pvt.source_type,
                    r1,
                    i64::from(c1) + left as i64,
                    r2,
                    i64::from(c2) - right as i64,
                    pvt.source_sheet.clone().unwrap_or_else(|| "None".into())
                ),
                None => format!("{};{};{}", pvt.source_type, source_ref, pvt.source_sheet.clone().unwrap_or_default()),
            };
        let bias = left as i64;
        let mut info = Map::new();
        if props.contains("name") {
            info.insert("name".into(), json!(pvt.name));
        }
        if props.contains("show_total") {
            info.insert("show_total".into(), json!(pvt.visual_totals));
        }
        if props.contains("show_empty_row") {
            info.insert("show_empty_row".into(), json!(pvt.show_empty_row));
        }
        if props.contains("show_empty_col") {
            info.insert("show_empty_col".into(), json!(pvt.show_empty_col));
        }
        if props.contains("show_headers") {
            info.insert("show_headers".into(), json!(pvt.show_headers));
        }
        if props.contains("location") {
            info.insert("location".into(), json!(pvt.location));
        }
        if props.contains("filter") || props.contains("selection") {
            let encode =
                |items: &[(Option<bool>, i64)]| -> Vec<J> { items.iter().map(|(h, x)| json!([h, x])).collect() };
            let value: Vec<J> = if props.contains("ordered") {
                selection.iter().map(|f| J::Array(encode(f))).collect()
            } else {
                selection
                    .iter()
                    .map(|f| {
                        let set: BTreeSet<(Option<bool>, i64)> = f.iter().copied().collect();
                        J::Array(encode(&set.into_iter().collect::<Vec<_>>()))
                    })
                    .collect()
            };
            info.insert("selection".into(), J::Array(value));
        }
        if props.contains("filter") {
            let set: BTreeSet<i64> = pvt.page_fields.iter().copied().collect();
            info.insert("filter_fields".into(), json!(set.into_iter().collect::<Vec<_>>()));
        }
        if props.contains("col_fields") {
            info.insert("col_fields".into(), json!(pvt.col_fields.iter().map(|x| x - bias).collect::<Vec<_>>()));
        }
        if props.contains("row_fields") {
            info.insert("row_fields".into(), json!(pvt.row_fields.iter().map(|x| x - bias).collect::<Vec<_>>()));
        }
        if props.contains("data_fields") {
            let with_name = props.contains("data_fields_name");
            let fields: Vec<String> = pvt
                .data_fields
                .iter()
                .map(|(fld, name, subtotal, show)| {
                    format!("{};{};{};{}", fld - bias, if with_name { name.as_str() } else { "" }, subtotal, show)
                })
                .collect();
            info.insert("data_fields".into(), json!(fields));
        }
        out.insert(source, J::Object(info));
    }
    Ok(out)
}
