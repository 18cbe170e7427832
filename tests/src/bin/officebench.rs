//! `officebench`: times the office metrics on representative files and prints
//! the figures, for comparison with upstream's Python (openpyxl + pandas for
//! `compare_table`, python-docx for `compare_docx_files`).
//!
//! It writes a pair of 1000-row x 20-column workbooks (numbers, text and a
//! formula column with cached results; one fill-styled column) and a pair of
//! 200-paragraph documents into a temporary folder, then calls the registered
//! metrics through `arena_eval::metrics::lookup`, exactly as an
//! evaluation does. Each comparison opens and parses both files from disk.
//! Run it in release mode: `cargo run --release -p arena-tests --bin officebench [iterations] [--keep DIR]`.
//! `--keep DIR` writes the files into DIR and leaves them there, so that
//! `tests/bench/office_upstream.py DIR` can time the Python libraries on the same files.

#![forbid(unsafe_code)]

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

use anyhow::{bail, Context};
use arena_eval::metrics::{lookup, MetricInput};
use arena_eval::Fetched;
use rust_xlsxwriter::{Format, FormatPattern, Formula, Workbook};
use serde_json::{json, Map, Value};

const ROWS: u32 = 1000;
const COLS: u16 = 20;
const PARAGRAPHS: usize = 200;

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("error: {err:#}");
            ExitCode::FAILURE
        }
    }
}

fn run() -> anyhow::Result<()> {
    let mut iterations = 20;
    let mut keep: Option<PathBuf> = None;
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--keep" => keep = Some(args.next().context("--keep needs a folder")?.into()),
            n => iterations = n.parse().with_context(|| format!("{n:?} is not a number of iterations"))?,
        }
    }
    let temp = tempfile::tempdir()?;
    let dir_path = match &keep {
        Some(dir) => {
            std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
            dir.clone()
        }
        None => temp.path().to_path_buf(),
    };
    let dir = dir_path.as_path();
    let (a, b) = (dir.join("result.xlsx"), dir.join("gold.xlsx"));
    write_workbook(&a)?;
    write_workbook(&b)?;
    let (c, d) = (dir.join("result.docx"), dir.join("gold.docx"));
    write_document(&c)?;
    write_document(&d)?;
    println!(
        "officebench: {iterations} iterations; xlsx {ROWS}x{COLS} ({} KiB), docx {PARAGRAPHS} paragraphs ({} KiB)",
        size_kib(&a),
        size_kib(&c)
    );

    let sheet_data = json!({"rules": [{"type": "sheet_data", "sheet_idx0": 0, "sheet_idx1": "EI0"}]});
    let style =
        json!({"rules": [{"type": "style", "sheet_idx0": 0, "sheet_idx1": "EI0", "props": ["bgcolor", "font_color"]}]});
    bench("compare_table sheet_data", "compare_table", &a, &b, &sheet_data, iterations)?;
    bench("compare_table style", "compare_table", &a, &b, &style, iterations)?;
    bench("compare_docx_files", "compare_docx_files", &c, &d, &json!({}), iterations)?;
    bench(
        "compare_docx_files ignore_blanks=false",
        "compare_docx_files",
        &c,
        &d,
        &json!({"ignore_blanks": false}),
        iterations,
    )?;
    Ok(())
}

fn size_kib(path: &Path) -> u64 {
    std::fs::metadata(path).map(|m| m.len() / 1024).unwrap_or(0)
}

fn bench(
    label: &str,
    metric: &str,
    result: &Path,
    expected: &Path,
    options: &Value,
    iterations: usize,
) -> anyhow::Result<()> {
    let f = lookup(metric).with_context(|| format!("metric {metric} is not registered"))?;
    let options: Map<String, Value> = options.as_object().cloned().unwrap_or_default();
    let input = MetricInput {
        result: Fetched::File(result.to_owned()),
        expected: Some(Fetched::File(expected.to_owned())),
        options,
        last_action: None,
    };
    let mut times: Vec<Duration> = Vec::with_capacity(iterations);
    for _ in 0..iterations.max(1) {
        let start = Instant::now();
        let score = f(&input).with_context(|| format!("{label} failed"))?;
        times.push(start.elapsed());
        if score != 1.0 {
            bail!("{label} scored {score} on identical files");
        }
    }
    times.sort();
    let ms = |d: Duration| d.as_secs_f64() * 1000.0;
    let mean = times.iter().map(|d| ms(*d)).sum::<f64>() / times.len() as f64;
    let p50 = ms(times[times.len() / 2]);
    let max = ms(times[times.len() - 1]);
    println!("{label:<42} mean {mean:>8.2} ms   p50 {p50:>8.2} ms   max {max:>8.2} ms");
    Ok(())
}

/// A header row, then rows of numbers, text and a formula column with cached results.
fn write_workbook(path: &PathBuf) -> anyhow::Result<()> {
    let mut book = Workbook::new();
    let sheet = book.add_worksheet();
    let fill =
        Format::new().set_pattern(FormatPattern::Solid).set_background_color(0xFFFF00).set_foreground_color(0xFFFF00);
    for col in 0..COLS {
        sheet.write_string(0, col, format!("Column {col}"))?;
    }
    for row in 1..=ROWS {
        for col in 0..COLS {
            let n = f64::from(row) * 1.25 + f64::from(col);
            match col % 4 {
                0 => {
                    sheet.write_string(row, col, format!("item-{row}-{col}"))?;
                }
                1 => {
                    sheet.write_number(row, col, f64::from(row))?;
                }
                2 => {
                    sheet.write_formula(
                        row,
                        col,
                        Formula::new(format!("=B{}*1.25", row + 1)).set_result(n.to_string()),
                    )?;
                }
                _ if col == COLS - 1 => {
                    sheet.write_number_with_format(row, col, n / 3.0, &fill)?;
                }
                _ => {
                    sheet.write_number(row, col, n / 3.0)?;
                }
            }
        }
    }
    book.save(path)?;
    Ok(())
}

/// A minimal docx of numbered paragraphs with a few runs each.
fn write_document(path: &PathBuf) -> anyhow::Result<()> {
    const W: &str = "http://schemas.openxmlformats.org/wordprocessingml/2006/main";
    let mut body = String::new();
    for i in 0..PARAGRAPHS {
        body.push_str(&format!(
            r#"<w:p><w:pPr><w:spacing w:line="360" w:lineRule="auto"/></w:pPr><w:r><w:t xml:space="preserve">Paragraph {i}: the quick brown fox </w:t></w:r><w:r><w:rPr><w:i/><w:sz w:val="28"/></w:rPr><w:t xml:space="preserve">jumps over </w:t></w:r><w:r><w:t>the lazy dog, again and again, until the paragraph is long enough to wrap.</w:t></w:r></w:p>"#
        ));
    }
    // A complete package (content types included), so python-docx opens the same file.
    let parts = [
        (
            "[Content_Types].xml",
            r#"<Types xmlns="http://schemas.openxmlformats.org/package/2006/content-types"><Default Extension="rels" ContentType="application/vnd.openxmlformats-package.relationships+xml"/><Default Extension="xml" ContentType="application/xml"/><Override PartName="/word/document.xml" ContentType="application/vnd.openxmlformats-officedocument.wordprocessingml.document.main+xml"/></Types>"#.to_owned(),
        ),
        (
            "_rels/.rels",
            r#"<Relationships xmlns="http://schemas.openxmlformats.org/package/2006/relationships"><Relationship Id="rId1" Type="http://schemas.openxmlformats.org/officeDocument/2006/relationships/officeDocument" Target="word/document.xml"/></Relationships>"#.to_owned(),
        ),
        ("word/document.xml", format!(r#"<w:document xmlns:w="{W}"><w:body>{body}</w:body></w:document>"#)),
    ];
    let mut zip = zip::ZipWriter::new(std::fs::File::create(path)?);
    let options = zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Deflated);
    for (name, text) in parts {
        zip.start_file(name, options)?;
        zip.write_all(text.as_bytes())?;
    }
    zip.finish()?;
    Ok(())
}
