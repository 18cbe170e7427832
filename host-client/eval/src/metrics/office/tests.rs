//! Table-driven tests of the office metrics on real files written here: xlsx
//! workbooks from rust_xlsxwriter (values, formulas, fills, fonts, merges,
//! charts, conditional formats), a pivot-table workbook and docx/odt
//! documents zipped from OOXML/ODF parts written by hand, and small PDFs.

use std::io::Write;
use std::path::Path;

use rust_xlsxwriter::{
    Chart, ChartLegendPosition, ChartType, ConditionalFormatCell, ConditionalFormatCellRule, ConditionalFormatFormula,
    Format, FormatPattern, Formula, Workbook as XlsxBook,
};
use serde_json::{json, Map, Value};

use crate::metrics::{lookup, MetricInput};
use crate::value::Fetched;
use arena_test_support::pdf_showing as pdf_bytes;

/// What a case should give: a score, or an error whose message contains the text.
#[derive(Debug)]
enum Want {
    Score(f64),
    Error(&'static str),
}
use Want::{Error, Score};

fn check(metric: &str, result: Fetched, expected: Option<Fetched>, options: Value, want: Want) {
    let f = lookup(metric).unwrap_or_else(|| panic!("metric {metric} is not registered"));
    let options = match options {
        Value::Object(map) => map,
        _ => Map::new(),
    };
    let input = MetricInput { result, expected, options, last_action: None };
    let got = f(&input);
    match (&got, &want) {
        (Ok(score), Score(expected)) => {
            assert!((score - expected).abs() < 1e-9, "{metric}: got {score}, want {expected} on {input:?}")
        }
        (Err(err), Error(text)) => assert!(err.to_string().contains(text), "{metric}: error {err} lacks {text:?}"),
        _ => panic!("{metric} on {input:?}: got {got:?}, want {want:?}"),
    }
}

fn rules(value: Value) -> Option<Fetched> {
    Some(Fetched::Json(value))
}

fn zip_file(dir: &Path, name: &str, parts: &[(&str, String)]) -> Fetched {
    let path = dir.join(name);
    let file = std::fs::File::create(&path).expect("create zip");
    let mut zip = zip::ZipWriter::new(file);
    let options = zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Deflated);
    for (part, text) in parts {
        zip.start_file(*part, options).expect("start part");
        zip.write_all(text.as_bytes()).expect("write part");
    }
    zip.finish().expect("finish zip");
    Fetched::File(path)
}

/// A copy of a file the test made, under another name.
fn raw_copy(file: &Fetched, dir: &Path, name: &str) -> Fetched {
    let bytes = std::fs::read(file.as_path().expect("a file")).expect("read test file");
    raw_file(dir, name, &bytes)
}

fn raw_file(dir: &Path, name: &str, bytes: &[u8]) -> Fetched {
    let path = dir.join(name);
    std::fs::write(&path, bytes).expect("write file");
    Fetched::File(path)
}

// ----- xlsx -----

/// A workbook: Sheet1 holds a header and numbers, one as a formula with a cached result.
fn data_book(dir: &Path, name: &str, b3: f64, use_formula: bool) -> Fetched {
    let mut book = XlsxBook::new();
    let sheet = book.add_worksheet();
    sheet.write_string(0, 0, "Item").unwrap();
    sheet.write_string(0, 1, "Price").unwrap();
    for (row, (item, price)) in [("pen", 2.0), ("ink", b3)].iter().enumerate() {
        let row = row as u32 + 1;
        sheet.write_string(row, 0, *item).unwrap();
        if use_formula && row == 2 {
            sheet.write_formula(row, 1, Formula::new("=B2*2").set_result(price.to_string())).unwrap();
        } else {
            sheet.write_number(row, 1, *price).unwrap();
        }
    }
    let path = dir.join(name);
    book.save(&path).unwrap();
    Fetched::File(path)
}

fn styled_book(dir: &Path, name: &str, fill: u32, font: u32, bold: bool) -> Fetched {
    let mut book = XlsxBook::new();
    let sheet = book.add_worksheet();
    sheet.set_name("Profile").unwrap();
    let mut format = Format::new()
        .set_pattern(FormatPattern::Solid)
        .set_background_color(fill)
        .set_foreground_color(fill)
        .set_font_color(font);
    if bold {
        format = format.set_bold();
    }
    sheet.merge_range(0, 0, 0, 2, "Demographic Profile", &format).unwrap();
    sheet.write_number(1, 0, 7.0).unwrap();
    let path = dir.join(name);
    book.save(&path).unwrap();
    Fetched::File(path)
}

fn chart_book(dir: &Path, name: &str, kind: ChartType, title: &str, legend: ChartLegendPosition) -> Fetched {
    let mut book = XlsxBook::new();
    let sheet = book.add_worksheet();
    for row in 0..4u32 {
        sheet.write_string(row, 0, format!("m{row}")).unwrap();
        sheet.write_number(row, 1, f64::from(row) * 3.0).unwrap();
    }
    let mut chart = Chart::new(kind);
    chart.add_series().set_categories("Sheet1!$A$1:$A$4").set_values("Sheet1!$B$1:$B$4");
    chart.title().set_name(title);
    chart.legend().set_position(legend);
    sheet.insert_chart(5, 3, &chart).unwrap();
    let path = dir.join(name);
    book.save(&path).unwrap();
    Fetched::File(path)
}

fn conditional_book(dir: &Path, name: &str) -> Fetched {
    let mut book = XlsxBook::new();
    let sheet = book.add_worksheet();
    sheet.write_number(0, 0, 9.0).unwrap();
    let rule = ConditionalFormatCell::new()
        .set_rule(ConditionalFormatCellRule::GreaterThan(5))
        .set_format(Format::new().set_font_color(0xFF0000));
    sheet.add_conditional_format(0, 0, 5, 0, &rule).unwrap();
    let path = dir.join(name);
    book.save(&path).unwrap();
    Fetched::File(path)
}

const MAIN_NS: &str = "http://schemas.openxmlformats.org/spreadsheetml/2006/main";
const REL_NS: &str = "http://schemas.openxmlformats.org/officeDocument/2006/relationships";
const PKG_REL_NS: &str = "http://schemas.openxmlformats.org/package/2006/relationships";

/// A workbook whose Sheet2 holds a pivot table over Sheet1!A1:C20, built from parts.
fn pivot_book(dir: &Path, name: &str, row_field: i64, data_field: i64) -> Fetched {
    let rel = |id: &str, kind: &str, target: &str| {
        format!(r#"<Relationship Id="{id}" Type="{REL_NS}/{kind}" Target="{target}"/>"#)
    };
    let parts = [
        (
            "_rels/.rels",
            format!(
                r#"<Relationships xmlns="{PKG_REL_NS}">{}</Relationships>"#,
                rel("rId1", "officeDocument", "xl/workbook.xml")
            ),
        ),
        (
            "xl/workbook.xml",
            format!(
                r#"<workbook xmlns="{MAIN_NS}" xmlns:r="{REL_NS}"><sheets><sheet name="Sheet1" sheetId="1" r:id="rId1"/><sheet name="Sheet2" sheetId="2" r:id="rId2"/></sheets><pivotCaches><pivotCache cacheId="5" r:id="rId3"/></pivotCaches></workbook>"#
            ),
        ),
        (
            "xl/_rels/workbook.xml.rels",
            format!(
                r#"<Relationships xmlns="{PKG_REL_NS}">{}{}{}</Relationships>"#,
                rel("rId1", "worksheet", "worksheets/sheet1.xml"),
                rel("rId2", "worksheet", "worksheets/sheet2.xml"),
                rel("rId3", "pivotCacheDefinition", "pivotCache/pivotCacheDefinition1.xml")
            ),
        ),
        ("xl/worksheets/sheet1.xml", format!(r#"<worksheet xmlns="{MAIN_NS}"><sheetData/></worksheet>"#)),
        ("xl/worksheets/sheet2.xml", format!(r#"<worksheet xmlns="{MAIN_NS}"><sheetData/></worksheet>"#)),
        (
            "xl/worksheets/_rels/sheet2.xml.rels",
            format!(
                r#"<Relationships xmlns="{PKG_REL_NS}">{}</Relationships>"#,
                rel("rId1", "pivotTable", "../pivotTables/pivotTable1.xml")
            ),
        ),
        (
            "xl/pivotTables/pivotTable1.xml",
            format!(
                r#"<pivotTableDefinition xmlns="{MAIN_NS}" name="DataPilot1" cacheId="5"><location ref="A1:B4"/><pivotFields count="3"><pivotField axis="axisRow"><items count="3"><item x="1"/><item x="0"/><item t="default"/></items></pivotField><pivotField dataField="1"/><pivotField/></pivotFields><rowFields count="1"><field x="{row_field}"/></rowFields><dataFields count="1"><dataField name="Sum - Sales" fld="{data_field}" subtotal="sum"/></dataFields></pivotTableDefinition>"#
            ),
        ),
        (
            "xl/pivotCache/pivotCacheDefinition1.xml",
            format!(
                r#"<pivotCacheDefinition xmlns="{MAIN_NS}"><cacheSource type="worksheet"><worksheetSource ref="A1:C20" sheet="Sheet1"/></cacheSource></pivotCacheDefinition>"#
            ),
        ),
    ];
    zip_file(dir, name, &parts)
}

#[test]
fn compare_table_sheet_data_follows_pandas() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let gold = data_book(d, "gold.xlsx", 3.0, false);
    let by_formula = data_book(d, "formula.xlsx", 3.0, true);
    let wrong = data_book(d, "wrong.xlsx", 4.0, false);
    let as_float = data_book(d, "float.xlsx", 3.00001, false);
    let near = data_book(d, "near.xlsx", 3.00002, false);
    let first = json!({"rules": [{"type": "sheet_data", "sheet_idx0": 0, "sheet_idx1": "EI0"}]});
    let cases = [
        (by_formula.clone(), gold.clone(), first.clone(), Score(1.0)),
        (wrong.clone(), gold.clone(), first.clone(), Score(0.0)),
        // An integral column and a float column differ in dtype, so `equals` fails.
        (as_float.clone(), gold.clone(), first.clone(), Score(0.0)),
        // Two float columns equal after rounding to 4 decimals.
        (near.clone(), as_float.clone(), first.clone(), Score(1.0)),
        (
            near.clone(),
            as_float.clone(),
            json!({"rules": [{"type": "sheet_data", "sheet_idx0": 0, "sheet_idx1": "EI0", "precision": 6}]}),
            Score(0.0),
        ),
        (
            gold.clone(),
            gold.clone(),
            json!({"rules": [{"type": "sheet_data", "sheet_idx0": "RNSheet1", "sheet_idx1": "ENSheet1"}]}),
            Score(1.0),
        ),
        // A result sheet that does not exist scores 0.
        (
            gold.clone(),
            gold.clone(),
            json!({"rules": [{"type": "sheet_data", "sheet_idx0": "RNSheet2", "sheet_idx1": "ENSheet1"}]}),
            Score(0.0),
        ),
        (
            gold.clone(),
            gold.clone(),
            json!({"rules": [{"type": "sheet_data", "sheet_idx0": "RNSheet1", "sheet_idx1": "ENSheet9"}]}),
            Error("no sheet"),
        ),
        (
            gold.clone(),
            gold.clone(),
            json!({"rules": [{"type": "sheet_data", "sheet_idx0": "XX0", "sheet_idx1": "EI0"}]}),
            Error("unrecognized sheet index"),
        ),
        (gold.clone(), gold.clone(), json!({"rules": [{"type": "sparkle"}]}), Error("unimplemented sheet check")),
        (gold.clone(), gold.clone(), json!({"rules": [{"type": "sheet_name"}]}), Score(1.0)),
    ];
    for (result, expected, options, want) in cases {
        check("compare_table", result, Some(expected), options, want);
    }
    check("compare_table", Fetched::None, Some(gold.clone()), first.clone(), Score(0.0));
    let broken = raw_file(d, "broken.xlsx", b"not a zip at all");
    check("compare_table", broken, Some(gold), first, Error("not an Office document"));
}

/// A cell of [`column_book`]: a number with an optional number format, text, or nothing.
enum Cell<'a> {
    Num(f64, Option<&'a str>),
    Text(&'a str),
    Blank,
}

/// A one-column workbook: a header, then `cells` down column A.
fn column_book(dir: &Path, name: &str, cells: &[Cell<'_>]) -> Fetched {
    let mut book = XlsxBook::new();
    let sheet = book.add_worksheet();
    sheet.write_string(0, 0, "When").unwrap();
    for (i, cell) in cells.iter().enumerate() {
        let row = i as u32 + 1;
        match cell {
            Cell::Num(value, Some(format)) => {
                sheet.write_number_with_format(row, 0, *value, &Format::new().set_num_format(*format)).unwrap();
            }
            Cell::Num(value, None) => {
                sheet.write_number(row, 0, *value).unwrap();
            }
            Cell::Text(text) => {
                sheet.write_string(row, 0, *text).unwrap();
            }
            Cell::Blank => {}
        }
    }
    let path = dir.join(name);
    book.save(&path).unwrap();
    Fetched::File(path)
}

#[test]
fn compare_table_dates_times_and_blank_rows_follow_pandas() {
    use Cell::*;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let day = Some("yyyy-mm-dd");
    let clock = Some("hh:mm");
    // 45293 is 2024-01-02.
    let gold = column_book(d, "gold.xlsx", &[Num(45293.0, day), Num(45294.0, day)]);
    let cases = [
        // The same dates under another date format: equal datetimes.
        (column_book(d, "same.xlsx", &[Num(45293.0, Some("dd/mm/yyyy")), Num(45294.0, day)]), Score(1.0)),
        // Typed as plain numbers: an int64 column against datetime64.
        (column_book(d, "number.xlsx", &[Num(45293.0, None), Num(45294.0, None)]), Score(0.0)),
        // The same day at noon is another datetime, though the format hides the time.
        (column_book(d, "noon.xlsx", &[Num(45293.5, day), Num(45294.0, day)]), Score(0.0)),
        // A missing date is NaT in the same datetime64 column, not equal to a date.
        (column_book(d, "gap.xlsx", &[Num(45293.0, day), Blank, Num(45294.0, day)]), Score(0.0)),
    ];
    let rule = json!({"rules": [{"type": "sheet_data", "sheet_idx0": 0, "sheet_idx1": "EI0"}]});
    for (result, want) in cases {
        check("compare_table", result, Some(gold.clone()), rule.clone(), want);
    }
    // Times of day are Python `time` objects compared exactly.
    let half_past = column_book(d, "t1.xlsx", &[Num(0.354_166_666_666_666_7, clock)]);
    let half_past_again = column_book(d, "t2.xlsx", &[Num(0.354_166_666_666_666_7, clock)]);
    let nine = column_book(d, "t3.xlsx", &[Num(0.375, clock)]);
    check("compare_table", half_past.clone(), Some(half_past_again), rule.clone(), Score(1.0));
    check("compare_table", nine, Some(half_past), rule.clone(), Score(0.0));
    // pandas keeps empty and whitespace-only rows of a one-column sheet.
    let words = column_book(d, "w1.xlsx", &[Text("a"), Text("b")]);
    let with_empty = column_book(d, "w2.xlsx", &[Text("a"), Blank, Text("b")]);
    let with_space = column_book(d, "w3.xlsx", &[Text("a"), Text("  "), Text("b")]);
    check("compare_table", with_empty.clone(), Some(words.clone()), rule.clone(), Score(0.0));
    check("compare_table", with_space.clone(), Some(words), rule.clone(), Score(0.0));
    check("compare_table", with_space, Some(with_empty), rule.clone(), Score(0.0));

    // openpyxl gives a date cell no number format (its data type is "d", not "n").
    let formats =
        json!({"rules": [{"type": "style", "sheet_idx0": 0, "sheet_idx1": "EI0", "props": ["number_format"]}]});
    let other_format = column_book(d, "fmt.xlsx", &[Num(45293.0, Some("dd/mm/yyyy")), Num(45294.0, day)]);
    check("compare_table", other_format.clone(), Some(gold.clone()), formats.clone(), Score(1.0));
    let numbers = column_book(d, "n1.xlsx", &[Num(3.0, Some("0.00"))]);
    let numbers_other = column_book(d, "n2.xlsx", &[Num(3.0, Some("0.000"))]);
    check("compare_table", numbers, Some(numbers_other), formats, Score(0.0));
    let cell_format = |want: Value| {
        json!({"rules": [{"type": "check_cell", "sheet_idx": 0, "coordinate": "A2",
            "props": {"number_format": {"method": "eq", "ref": want}}}]})
    };
    check("compare_table", other_format.clone(), None, cell_format(json!(null)), Score(1.0));
    check("compare_table", other_format, None, cell_format(json!("dd/mm/yyyy")), Score(0.0));
}

#[test]
fn compare_table_sheet_names_styles_and_cells() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let blue = styled_book(d, "blue.xlsx", 0x0000FF, 0xFFFFFF, true);
    let blue_again = styled_book(d, "blue2.xlsx", 0x0000FF, 0xFFFFFF, true);
    let red = styled_book(d, "red.xlsx", 0xFF0000, 0xFFFFFF, true);
    let plain = data_book(d, "plain.xlsx", 3.0, false);
    let cell = |bold: bool| {
        json!({"rules": [{"type": "check_cell", "sheet_idx": "RNProfile", "coordinate": "A1", "props": {
            "bgcolor": {"method": "eq", "ref": "FF0000FF"},
            "font_color": {"method": "eq", "ref": "FFFFFFFF"},
            "font_bold": {"method": "eq", "ref": bold},
            "value": {"method": "eq", "ref": "Demographic Profile"}}}]})
    };
    let style =
        |props: Value| json!({"rules": [{"type": "style", "sheet_idx0": 0, "sheet_idx1": "EI0", "props": props}]});
    let cases = [
        (blue.clone(), Some(blue_again.clone()), json!({"rules": [{"type": "sheet_name"}]}), Score(1.0)),
        (plain.clone(), Some(blue_again.clone()), json!({"rules": [{"type": "sheet_name"}]}), Score(0.0)),
        (blue.clone(), None, cell(true), Score(1.0)),
        (blue.clone(), None, cell(false), Score(0.0)),
        (red.clone(), None, cell(true), Score(0.0)),
        (
            blue.clone(),
            None,
            json!({"rules": [{"type": "check_cell", "sheet_idx": "RNMissing", "coordinate": "A1", "props": {}}]}),
            Score(0.0),
        ),
        (
            blue.clone(),
            None,
            json!({"rules": [{"type": "check_cell", "sheet_idx": 0, "coordinate": "B2", "props": {"value": {"method": "approx:0.1", "ref": 7.05}}}]}),
            Score(0.0),
        ),
        (
            blue.clone(),
            None,
            json!({"rules": [{"type": "check_cell", "sheet_idx": 0, "coordinate": "A2", "props": {"value": {"method": "approx:0.1", "ref": 7.05}}}]}),
            Score(1.0),
        ),
        (
            blue.clone(),
            None,
            json!({"rules": [{"type": "check_cell", "sheet_idx": 0, "coordinate": "A1", "props": {"value": {"method": "re", "ref": "x"}}}]}),
            Error("unsupported match method"),
        ),
        (blue.clone(), Some(blue_again.clone()), style(json!(["bgcolor", "font_color"])), Score(1.0)),
        (red.clone(), Some(blue_again.clone()), style(json!(["bgcolor"])), Score(0.0)),
        // Only the fill differs, so a rule about fonts passes.
        (red.clone(), Some(blue_again.clone()), style(json!(["font_color", "font_bold"])), Score(1.0)),
        (blue.clone(), Some(blue_again.clone()), style(json!(["shadow"])), Error("unsupported style")),
    ];
    for (result, expected, options, want) in cases {
        check("compare_table", result, expected, options, want);
    }
    let cond = conditional_book(d, "cond.xlsx");
    check("compare_table", cond.clone(), Some(cond), style(json!(["font_color"])), Error("conditional formatting"));
}

/// How [`rates_book`] marks a rate in green.
enum Green<'a> {
    /// A conditional format with this formula over C2:C5.
    Rule(&'a str),
    /// A direct green font on the cell in this row (from 0).
    Direct(u32),
}

/// Task 21ab7b40's shape: rates in C2:C5 with a header, one marked green.
fn rates_book(dir: &Path, name: &str, green: Green<'_>) -> Fetched {
    let mut book = XlsxBook::new();
    let sheet = book.add_worksheet();
    sheet.write_string(0, 2, "Period Rate (%)").unwrap();
    let font = Format::new().set_font_color(0x00FF00);
    for (i, rate) in [1.5, 4.25, 2.0, 3.75].iter().enumerate() {
        let row = i as u32 + 1;
        match green {
            Green::Direct(r) if r == row => sheet.write_number_with_format(row, 2, *rate, &font).unwrap(),
            _ => sheet.write_number(row, 2, *rate).unwrap(),
        };
    }
    if let Green::Rule(formula) = green {
        let rule = ConditionalFormatFormula::new().set_rule(formula).set_format(&font);
        sheet.add_conditional_format(1, 2, 4, 2, &rule).unwrap();
    }
    let path = dir.join(name);
    book.save(&path).unwrap();
    Fetched::File(path)
}

#[test]
fn compare_table_style_evaluates_expression_conditional_formats() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let style = json!({"rules": [{"type": "style", "sheet_idx0": 0, "sheet_idx1": "EI0", "props": ["font_color"]}]});
    let gold = rates_book(d, "gold.xlsx", Green::Rule("=C2=MAX($C$2:$C$5)"));
    let cases = [
        (rates_book(d, "same.xlsx", Green::Rule("=C2=MAX($C$2:$C$5)")), Score(1.0)),
        // The highest rate (row 2) painted green by hand looks the same.
        (rates_book(d, "direct.xlsx", Green::Direct(2)), Score(1.0)),
        (rates_book(d, "wrong_cell.xlsx", Green::Direct(1)), Score(0.0)),
        (rates_book(d, "lowest.xlsx", Green::Rule("=C2=MIN($C$2:$C$5)")), Score(0.0)),
        // Written the other way round, the formula still binds the cell to C2.
        (rates_book(d, "flipped.xlsx", Green::Rule("=MAX($C$2:$C$5)=C2")), Score(1.0)),
        // An absolute single cell makes upstream fail.
        (rates_book(d, "single.xlsx", Green::Rule("=C2>$C$1")), Error("single cell")),
        (rates_book(d, "large.xlsx", Green::Rule("=C2=LARGE($C$2:$C$5,1)")), Error("LARGE")),
    ];
    for (result, want) in cases {
        check("compare_table", result, Some(gold.clone()), style.clone(), want);
    }
}

#[test]
fn compare_table_charts_and_pivots() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let line = chart_book(d, "line.xlsx", ChartType::Line, "Sales", ChartLegendPosition::Bottom);
    let line_again = chart_book(d, "line2.xlsx", ChartType::Line, "Sales", ChartLegendPosition::Bottom);
    let bar = chart_book(d, "bar.xlsx", ChartType::Column, "Sales", ChartLegendPosition::Bottom);
    let retitled = chart_book(d, "title.xlsx", ChartType::Line, "Totals", ChartLegendPosition::Right);
    let chart = |props: Value| json!({"rules": [{"type": "chart", "sheet_idx0": 0, "sheet_idx1": "EI0", "chart_props": props}]});
    let pivot = json!({"rules": [{"type": "pivot_table", "sheet_idx0": "RNSheet2", "sheet_idx1": "ENSheet2",
        "pivot_props": ["col_fields", "filter", "row_fields", "data_fields"]}]});
    let cases = [
        (line.clone(), line_again.clone(), chart(json!(["type", "legend", "title"])), Score(1.0)),
        (bar.clone(), line_again.clone(), chart(json!(["type"])), Score(0.0)),
        (bar.clone(), line_again.clone(), chart(json!(["title"])), Score(1.0)),
        (retitled.clone(), line_again.clone(), chart(json!(["title"])), Score(0.0)),
        (retitled.clone(), line_again.clone(), chart(json!(["legend"])), Score(0.0)),
        (line.clone(), line_again.clone(), chart(json!(["anchor"])), Error("unsupported chart property")),
        (pivot_book(d, "p1.xlsx", 0, 1), pivot_book(d, "p2.xlsx", 0, 1), pivot.clone(), Score(1.0)),
        (pivot_book(d, "p3.xlsx", 0, 2), pivot_book(d, "p4.xlsx", 0, 1), pivot.clone(), Score(0.0)),
        (pivot_book(d, "p5.xlsx", 1, 1), pivot_book(d, "p6.xlsx", 0, 1), pivot.clone(), Score(0.0)),
        // A sheet without pivots against one with a pivot.
        (
            line.clone(),
            pivot_book(d, "p7.xlsx", 0, 1),
            json!({"rules": [{"type": "pivot_table", "sheet_idx0": 0, "sheet_idx1": "ENSheet2", "pivot_props": ["row_fields"]}]}),
            Score(0.0),
        ),
    ];
    for (result, expected, options, want) in cases {
        check("compare_table", result, Some(expected), options, want);
    }
}

// ----- docx -----

const W_NS: &str = "http://schemas.openxmlformats.org/wordprocessingml/2006/main";

/// A docx with `body` inside `w:body` and footers (`rIdF<n>` → `footer<n>.xml`) with the given paragraphs.
fn docx(dir: &Path, name: &str, body: &str, footers: &[&str]) -> Fetched {
    let mut parts = vec![
        (
            "[Content_Types].xml",
            r#"<Types xmlns="http://schemas.openxmlformats.org/package/2006/content-types"><Default Extension="xml" ContentType="application/xml"/></Types>"#.to_owned(),
        ),
        (
            "_rels/.rels",
            format!(r#"<Relationships xmlns="{PKG_REL_NS}"><Relationship Id="rId1" Type="{REL_NS}/officeDocument" Target="word/document.xml"/></Relationships>"#),
        ),
        ("word/document.xml", format!(r#"<w:document xmlns:w="{W_NS}" xmlns:r="{REL_NS}"><w:body>{body}</w:body></w:document>"#)),
    ];
    let mut rels = String::new();
    let names: Vec<String> = (1..=footers.len()).map(|i| format!("word/footer{i}.xml")).collect();
    for (i, footer) in footers.iter().enumerate() {
        rels.push_str(&format!(
            r#"<Relationship Id="rIdF{}" Type="{REL_NS}/footer" Target="footer{}.xml"/>"#,
            i + 1,
            i + 1
        ));
        parts.push((names[i].as_str(), format!(r#"<w:ftr xmlns:w="{W_NS}" xmlns:r="{REL_NS}">{footer}</w:ftr>"#)));
    }
    parts.push((
        "word/_rels/document.xml.rels",
        format!(r#"<Relationships xmlns="{PKG_REL_NS}">{rels}</Relationships>"#),
    ));
    zip_file(dir, name, &parts)
}

fn run(props: &str, text: &str) -> String {
    format!(r#"<w:r><w:rPr>{props}</w:rPr><w:t xml:space="preserve">{text}</w:t></w:r>"#)
}

fn para(ppr: &str, runs: &[String]) -> String {
    format!("<w:p><w:pPr>{ppr}</w:pPr>{}</w:p>", runs.concat())
}

fn plain(text: &str) -> String {
    para("", &[run("", text)])
}

fn sect(footer: Option<&str>) -> String {
    let reference =
        footer.map(|id| format!(r#"<w:footerReference w:type="default" r:id="{id}"/>"#)).unwrap_or_default();
    format!(
        r#"<w:sectPr>{reference}<w:pgSz w:w="12240" w:h="15840"/><w:pgMar w:left="1440" w:right="1440" w:top="1440" w:bottom="1440"/></w:sectPr>"#
    )
}

#[test]
fn compare_docx_files_compares_paragraph_text() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let gold = docx(d, "gold.docx", &(plain("Hello world.") + &plain("Second line")), &[]);
    let spaced = docx(d, "spaced.docx", &(plain("Hello   world.") + &plain("") + &plain("Second line")), &[]);
    let other = docx(d, "other.docx", &(plain("Hello world!") + &plain("Second line")), &[]);
    let upper = docx(d, "upper.docx", &(plain("HELLO world.") + &plain("Second LINE")), &[]);
    let odt_gold = odt(d, "gold.odt", &["Hello world.", "Second line"], &[]);
    let odt_same = odt(d, "same.odt", &["Hello world.", "Second line"], &[]);
    let odt_other = odt(d, "other.odt", &["Hello there.", "Second line"], &[]);
    let cases = [
        (gold.clone(), gold.clone(), json!({}), Score(1.0)),
        (spaced.clone(), gold.clone(), json!({}), Score(1.0)),
        (spaced.clone(), gold.clone(), json!({"ignore_blanks": false}), Score(0.0)),
        (other.clone(), gold.clone(), json!({}), Score(0.0)),
        (upper.clone(), gold.clone(), json!({"ignore_case": true}), Score(1.0)),
        (upper.clone(), gold.clone(), json!({"ignore_blanks": false, "ignore_case": true}), Score(1.0)),
        (upper.clone(), gold.clone(), json!({}), Score(0.0)),
        (odt_same.clone(), odt_gold.clone(), json!({}), Score(1.0)),
        (odt_other.clone(), odt_gold.clone(), json!({}), Score(0.0)),
        // Mixed file types are unsupported upstream and score 0.
        (odt_same.clone(), gold.clone(), json!({}), Score(0.0)),
        // Upstream's `endswith('.docx')` is case-sensitive: an upper-case extension is unsupported.
        (raw_copy(&gold, d, "GOLD.DOCX"), gold.clone(), json!({}), Score(0.0)),
    ];
    for (result, expected, options, want) in cases {
        check("compare_docx_files", result, Some(expected), options, want);
    }
    let score = super::pdf::ratio("Hello world. Second line", "Hello world! Second line");
    check("compare_docx_files", other, Some(gold.clone()), json!({"content_only": true}), Score(score));
    check("compare_docx_files", Fetched::None, Some(gold.clone()), json!({}), Score(0.0));
    let broken = raw_file(d, "broken.docx", b"PK garbage");
    check("compare_docx_files", broken, Some(gold), json!({}), Error("not an Office document"));
}

#[test]
fn line_spacing_fonts_italics_strike_and_centering() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let spacing = |line: u32, rule: &str| {
        let rule = if rule.is_empty() { String::new() } else { format!(r#" w:lineRule="{rule}""#) };
        para(&format!(r#"<w:spacing w:line="{line}"{rule}/>"#), &[run("", "Body text")])
    };
    let double = docx(d, "double.docx", &(spacing(480, "auto") + &plain("tail")), &[]);
    let double_again = docx(d, "double2.docx", &(spacing(480, "auto") + &plain("tail")), &[]);
    let single = docx(d, "single.docx", &(spacing(240, "auto") + &plain("tail")), &[]);
    // No `lineRule` is the schema's default `auto`: the same double spacing (python-docx reads 2.0).
    let double_no_rule = docx(d, "double3.docx", &(spacing(480, "") + &plain("tail")), &[]);
    // `exact` 480 twips is a 24 pt length, not a multiple.
    let exact = docx(d, "exact.docx", &(spacing(480, "exact") + &plain("tail")), &[]);
    check("compare_line_spacing", double.clone(), Some(double_again.clone()), json!({}), Score(1.0));
    check("compare_line_spacing", single.clone(), Some(double_again.clone()), json!({}), Score(0.0));
    check("compare_line_spacing", double_no_rule.clone(), Some(double_again.clone()), json!({}), Score(1.0));
    check("compare_line_spacing", exact.clone(), Some(double_again.clone()), json!({}), Score(0.0));
    check("compare_line_spacing", exact, Some(double_no_rule), json!({}), Score(0.0));

    let font = |name: &str| format!(r#"<w:rFonts w:ascii="{name}" w:hAnsi="{name}"/>"#);
    let times = docx(
        d,
        "times.docx",
        &para("", &[run(&font("Times New Roman"), "a"), run(&font("Times New Roman"), "b")]),
        &[],
    );
    let mixed = docx(d, "mixed.docx", &para("", &[run(&font("Times New Roman"), "a"), run("", "b")]), &[]);
    let font_rule = rules(json!({"font_name": "Times New Roman"}));
    check("compare_font_names", times.clone(), font_rule.clone(), json!({}), Score(1.0));
    check("compare_font_names", mixed.clone(), font_rule.clone(), json!({}), Score(0.0));
    check("compare_font_names", times.clone(), rules(json!({"other": 1})), json!({}), Error("font_name"));

    let italic =
        |size: u32| para("", &[run("", "Plain "), run(&format!(r#"<w:i/><w:sz w:val="{size}"/>"#), "slanted")]);
    let big = docx(d, "big.docx", &italic(28), &[]);
    let gold = docx(d, "gold.docx", &italic(24), &[]);
    let small = docx(d, "small.docx", &italic(24), &[]);
    check("check_italic_font_size_14", big.clone(), Some(gold.clone()), json!({}), Score(1.0));
    check("check_italic_font_size_14", small, Some(gold.clone()), json!({}), Score(0.0));
    check("check_italic_font_size_14", times.clone(), Some(gold.clone()), json!({}), Score(0.0));

    let struck = |strike: &str| plain("Intro") + &para("", &[run(strike, "Last "), run("<w:strike/>", "paragraph")]);
    let all_struck = docx(d, "struck.docx", &struck("<w:strike/>"), &[]);
    let half = docx(d, "half.docx", &struck(r#"<w:strike w:val="0"/>"#), &[]);
    let strike_gold = docx(d, "strike_gold.docx", &(plain("Intro") + &plain("Last paragraph")), &[]);
    check("evaluate_strike_through_last_paragraph", all_struck, Some(strike_gold.clone()), json!({}), Score(1.0));
    check("evaluate_strike_through_last_paragraph", half, Some(strike_gold), json!({}), Score(0.0));

    let centered =
        docx(d, "centered.docx", &(para(r#"<w:jc w:val="center"/>"#, &[run("", "Title")]) + &plain("body")), &[]);
    let left = docx(d, "left.docx", &(para(r#"<w:jc w:val="left"/>"#, &[run("", "Title")]) + &plain("body")), &[]);
    let empty = docx(d, "empty.docx", "", &[]);
    check("is_first_line_centered", centered, None, json!({}), Score(1.0));
    check("is_first_line_centered", left, None, json!({}), Score(0.0));
    check("is_first_line_centered", empty, None, json!({}), Error("no paragraphs"));
}

#[test]
fn tab_stops_tables_subscripts_highlights_and_footers() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let tabbed = |pos: u32, text: &str| {
        para(
            &format!(r#"<w:tabs><w:tab w:val="right" w:pos="{pos}"/><w:tab w:val="left" w:pos="0"/></w:tabs>"#),
            &[run("", text)],
        )
    };
    let words = "One two three\tand the rest";
    let gold = docx(d, "tabs_gold.docx", &(tabbed(9360, words) + &sect(None)), &[]);
    let same = docx(d, "tabs_same.docx", &(tabbed(9360, words) + &sect(None)), &[]);
    let shifted = docx(d, "tabs_shift.docx", &(tabbed(9360 - 936, words) + &sect(None)), &[]);
    let four = docx(d, "tabs_four.docx", &(tabbed(9360, "One two three four\tand the rest") + &sect(None)), &[]);
    let options = json!({"word_number_split_by_tabstop": 3, "index": 0});
    check("check_tabstops", same.clone(), Some(gold.clone()), options.clone(), Score(1.0));
    // 936 twips off over a 9360-twip text width: 1 - 0.1.
    check("check_tabstops", shifted, Some(gold.clone()), options.clone(), Score(0.9));
    check("check_tabstops", four, Some(gold.clone()), options.clone(), Score(0.0));
    check("check_tabstops", same, Some(docx(d, "nosect.docx", &tabbed(9360, words), &[])), json!({}), Error("section"));

    let cell = |text: &str| format!("<w:tc>{}</w:tc>", plain(text));
    let table = |cells: &[&str]| {
        format!(
            r#"<w:tbl><w:tblGrid><w:gridCol/><w:gridCol/></w:tblGrid><w:tr>{}{}</w:tr><w:tr>{}{}</w:tr></w:tbl>"#,
            cell(cells[0]),
            cell(cells[1]),
            cell(cells[2]),
            cell(cells[3])
        )
    };
    let t_gold = docx(d, "t_gold.docx", &table(&["a", "b", "c", "d"]), &[]);
    let t_same = docx(d, "t_same.docx", &table(&["a ", "b", "c", " d"]), &[]);
    let t_diff = docx(d, "t_diff.docx", &table(&["a", "b", "c", "e"]), &[]);
    let t_none = docx(d, "t_none.docx", &plain("a, b, c, d"), &[]);
    check("compare_docx_tables", t_same, Some(t_gold.clone()), json!({}), Score(1.0));
    check("compare_docx_tables", t_diff, Some(t_gold.clone()), json!({}), Score(0.0));
    check("compare_docx_tables", t_none, Some(t_gold), json!({}), Score(0.0));

    let h2o = |sub: &str| para("", &[run("", "H"), run(sub, "2"), run("", "O")]);
    let sub_gold = docx(d, "sub_gold.docx", &h2o(r#"<w:vertAlign w:val="subscript"/>"#), &[]);
    let sub_ok = docx(d, "sub_ok.docx", &h2o(r#"<w:vertAlign w:val="subscript"/>"#), &[]);
    let sup = docx(d, "sup.docx", &h2o(r#"<w:vertAlign w:val="superscript"/>"#), &[]);
    check("compare_subscript_contains", sub_ok, Some(sub_gold.clone()), json!({}), Score(1.0));
    check("compare_subscript_contains", sup, Some(sub_gold), json!({}), Score(0.0));

    let marked = |which: &[bool]| {
        let runs: Vec<String> = ["#first note", "plain", "#second note"]
            .iter()
            .zip(which)
            .map(|(text, on)| run(if *on { r#"<w:highlight w:val="yellow"/>"# } else { "" }, text))
            .collect();
        para("", &runs)
    };
    let hl_gold = docx(d, "hl_gold.docx", &marked(&[true, false, true]), &[]);
    let hl_ok = docx(d, "hl_ok.docx", &marked(&[true, false, true]), &[]);
    let hl_missing = docx(d, "hl_missing.docx", &marked(&[true, false, false]), &[]);
    check("compare_highlighted_text", hl_ok, Some(hl_gold.clone()), json!({}), Score(1.0));
    check("compare_highlighted_text", hl_missing, Some(hl_gold), json!({}), Score(0.0));

    let page_field = r#"<w:p><w:r><w:t xml:space="preserve">Page </w:t></w:r><w:r><w:fldChar w:fldCharType="begin"/></w:r><w:r><w:instrText> PAGE </w:instrText></w:r><w:r><w:fldChar w:fldCharType="separate"/></w:r><w:r><w:t>1</w:t></w:r><w:r><w:fldChar w:fldCharType="end"/></w:r></w:p>"#;
    let simple_field = r#"<w:p><w:fldSimple w:instr="PAGE"><w:r><w:t>3</w:t></w:r></w:fldSimple></w:p>"#;
    let numbered = docx(
        d,
        "numbered.docx",
        &(plain("one") + &para(&sect(Some("rIdF1")), &[]) + &plain("two") + &sect(None)),
        &[page_field],
    );
    let simple = docx(d, "simple.docx", &(plain("one") + &sect(Some("rIdF1"))), &[simple_field]);
    let unnumbered =
        docx(d, "unnumbered.docx", &(plain("one") + &sect(Some("rIdF1"))), &["<w:p><w:r><w:t>Draft</w:t></w:r></w:p>"]);
    let no_footer = docx(d, "nofooter.docx", &(plain("one") + &sect(None)), &[]);
    check("has_page_numbers_in_footers", numbered, None, json!({}), Score(1.0));
    // python-docx's paragraph text skips `w:fldSimple`, so its page number is not seen.
    check("has_page_numbers_in_footers", simple, None, json!({}), Score(0.0));
    check("has_page_numbers_in_footers", unnumbered, None, json!({}), Score(0.0));
    check("has_page_numbers_in_footers", no_footer, None, json!({}), Score(0.0));
    check("has_page_numbers_in_footers", Fetched::None, None, json!({}), Score(0.0));
}

// ----- odt, xcu, pdf -----

const TEXT_NS: &str = "urn:oasis:names:tc:opendocument:xmlns:text:1.0";
const OFFICE_NS: &str = "urn:oasis:names:tc:opendocument:xmlns:office:1.0";
const STYLE_NS: &str = "urn:oasis:names:tc:opendocument:xmlns:style:1.0";
const FO_NS: &str = "urn:oasis:names:tc:opendocument:xmlns:xsl-fo-compatible:1.0";

/// An odt whose paragraphs are `paras`; spans listed in `spans` (paragraph, text, background) are appended.
fn odt(dir: &Path, name: &str, paras: &[&str], spans: &[(usize, &str, &str)]) -> Fetched {
    let mut styles = String::new();
    let mut body = String::new();
    for (i, p) in paras.iter().enumerate() {
        let mut inner = (*p).to_owned();
        for (k, (_, text, background)) in spans.iter().enumerate().filter(|(_, s)| s.0 == i) {
            styles.push_str(&format!(
                r#"<style:style style:name="T{k}" style:family="text"><style:text-properties fo:background-color="{background}"/></style:style>"#
            ));
            inner.push_str(&format!(r#"<text:span text:style-name="T{k}">{text}</text:span>"#));
        }
        body.push_str(&format!("<text:p>{inner}</text:p>"));
    }
    let content = format!(
        r#"<office:document-content xmlns:office="{OFFICE_NS}" xmlns:text="{TEXT_NS}" xmlns:style="{STYLE_NS}" xmlns:fo="{FO_NS}"><office:automatic-styles>{styles}</office:automatic-styles><office:body><office:text>{body}</office:text></office:body></office:document-content>"#
    );
    zip_file(dir, name, &[("mimetype", "application/vnd.oasis.opendocument.text".into()), ("content.xml", content)])
}

#[test]
fn highlighted_words_default_font_and_pdfs() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let gold = odt(d, "gold.odt", &["Hello "], &[(0, "caller", "transparent")]);
    let cleared = odt(d, "cleared.odt", &["Hello "], &[(0, "caller", "#ffffff")]);
    let yellow = odt(d, "yellow.odt", &["Hello "], &[(0, "caller", "#ffff00")]);
    let changed = odt(d, "changed.odt", &["Goodbye "], &[(0, "caller", "#ffffff")]);
    check("check_highlighted_words", cleared, Some(gold.clone()), json!({}), Score(1.0));
    check("check_highlighted_words", yellow, Some(gold.clone()), json!({}), Score(0.0));
    check("check_highlighted_words", changed, Some(gold), json!({}), Score(0.0));

    let xcu = |font: &str| {
        format!(
            r#"<?xml version="1.0" encoding="UTF-8"?><oor:items xmlns:oor="http://openoffice.org/2001/registry"><item oor:path="/org.openoffice.Office.Writer/DefaultFont"><prop oor:name="Standard" oor:op="fuse"><value>{font}</value></prop></item></oor:items>"#
        )
    };
    let want = rules(json!({"font_name": "Times New Roman"}));
    check(
        "find_default_font",
        raw_file(d, "a.xcu", xcu("Times New Roman").as_bytes()),
        want.clone(),
        json!({}),
        Score(1.0),
    );
    check(
        "find_default_font",
        raw_file(d, "b.xcu", xcu("Liberation Serif").as_bytes()),
        want.clone(),
        json!({}),
        Score(0.0),
    );
    check("find_default_font", raw_file(d, "c.xcu", b"<oor:items"), want.clone(), json!({}), Error("c.xcu"));
    check("find_default_font", Fetched::None, want, json!({}), Score(0.0));

    let hello = raw_file(d, "hello.pdf", &pdf_bytes("Hello World"));
    let hello_again = raw_file(d, "hello2.pdf", &pdf_bytes("Hello World"));
    let other = raw_file(d, "other.pdf", &pdf_bytes("Goodbye Moon"));
    check("compare_pdfs", hello.clone(), Some(hello_again.clone()), json!({}), Score(1.0));
    let f = lookup("compare_pdfs").unwrap();
    let partial =
        f(&MetricInput { result: other, expected: Some(hello_again.clone()), options: Map::new(), last_action: None })
            .unwrap();
    assert!(partial > 0.0 && partial < 0.8, "different PDFs scored {partial}");
    check(
        "compare_pdfs",
        raw_file(d, "bad.pdf", b"%PDF-1.4 nonsense"),
        Some(hello_again.clone()),
        json!({}),
        Error("bad.pdf"),
    );
    check("compare_pdfs", Fetched::None, Some(hello_again), json!({}), Score(0.0));
}

#[test]
fn unparseable_documents_are_errors_with_the_reason() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let good = docx(d, "good.docx", &plain("text"), &[]);
    let broken = raw_file(d, "broken.docx", b"this is not a zip");
    let broken_odt = raw_file(d, "broken.odt", b"this is not a zip");
    let font = rules(json!({"font_name": "Arial"}));
    let cases: [(&str, Fetched, Option<Fetched>); 13] = [
        ("compare_docx_files", broken.clone(), Some(good.clone())),
        ("compare_line_spacing", broken.clone(), Some(good.clone())),
        ("check_tabstops", broken.clone(), Some(good.clone())),
        ("compare_docx_tables", broken.clone(), Some(good.clone())),
        ("compare_font_names", broken.clone(), font),
        ("check_italic_font_size_14", broken.clone(), Some(good.clone())),
        ("evaluate_strike_through_last_paragraph", broken.clone(), Some(good.clone())),
        ("compare_highlighted_text", broken.clone(), Some(good.clone())),
        ("compare_subscript_contains", broken.clone(), Some(good.clone())),
        ("has_page_numbers_in_footers", broken.clone(), None),
        ("is_first_line_centered", broken.clone(), None),
        ("check_highlighted_words", broken_odt.clone(), Some(broken_odt.clone())),
        ("compare_table", raw_file(d, "broken.xlsx", b"nope"), Some(good.clone())),
    ];
    for (metric, result, expected) in cases {
        check(metric, result, expected, json!({"rules": [{"type": "sheet_name"}]}), Error("not an Office document"));
    }
    // A missing result scores 0 without reading the other file.
    check("compare_line_spacing", Fetched::None, Some(broken.clone()), json!({}), Score(0.0));
    // A docx without a body is reported, not scored.
    let no_body = zip_file(d, "nobody.docx", &[("word/document.xml", format!(r#"<w:document xmlns:w="{W_NS}"/>"#))]);
    check("is_first_line_centered", no_body, None, json!({}), Error("no w:body"));
}
