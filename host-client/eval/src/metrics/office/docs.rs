//! The document metrics of upstream's `metrics/docs.py`: text comparison of
//! two documents (docx or odt), line spacing, tab stops, tables, fonts,
//! italic size, strike-through, highlights, subscripts, footer page numbers,
//! centring, and Writer's default font in `registrymodifications.xcu`.
//!
//! Each follows upstream's scoring, including its shortcuts (for example
//! `compare_subscript_contains` passes as soon as one pair of aligned runs is
//! subscript in both files). A missing result scores 0; a file that cannot be
//! parsed is an error.

use std::collections::BTreeSet;
use std::path::Path;

use roxmltree::Node;

use super::docx::{Document, Paragraph};
use super::package::{parse_xml, Package};
use super::xml::{attr, descendants};
use crate::metrics::{file_of, read_text, score, MetricError, MetricInput};

/// The two files of a two-document metric; `None` when either is missing (score 0).
fn pair(input: &MetricInput) -> Result<Option<(&Path, &Path)>, MetricError> {
    let expected = input.expected()?;
    if input.result.is_none() || expected.is_none() {
        return Ok(None);
    }
    Ok(Some((file_of(&input.result, "result")?, file_of(expected, "expected")?)))
}

fn single(input: &MetricInput) -> Result<Option<&Path>, MetricError> {
    if input.result.is_none() {
        return Ok(None);
    }
    file_of(&input.result, "result").map(Some)
}

/// Upstream's `path.endswith('.docx')`: case-sensitive, so `.DOCX` is not a docx.
fn has_extension(path: &Path, ext: &str) -> bool {
    path.extension().is_some_and(|e| e == ext)
}

/// Python's `re.sub(r'\s+', ' ', text).strip()`.
fn squash(text: &str) -> String {
    text.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// Options of `compare_docx_files`.
#[derive(Debug, Clone, Copy)]
struct TextOptions {
    ignore_blanks: bool,
    ignore_case: bool,
    ignore_order: bool,
    content_only: bool,
}

impl TextOptions {
    fn from(input: &MetricInput) -> TextOptions {
        TextOptions {
            ignore_blanks: input.flag("ignore_blanks", true),
            ignore_case: input.flag("ignore_case", false),
            ignore_order: input.flag("ignore_order", false),
            content_only: input.flag("content_only", false),
        }
    }

    const DEFAULT: TextOptions =
        TextOptions { ignore_blanks: true, ignore_case: false, ignore_order: false, content_only: false };
}

/// The paragraph texts of a docx or odt file as upstream collects them.
fn paragraph_texts(path: &Path) -> Result<Vec<String>, MetricError> {
    if has_extension(path, "odt") {
        odt_paragraphs(path)
    } else {
        Ok(Document::open(path)?.paragraphs.into_iter().map(|p| p.text).collect())
    }
}

/// The score of `compare_docx_files(file1, file2, **options)`.
fn text_score(file1: &Path, file2: &Path, options: TextOptions) -> Result<f64, MetricError> {
    let both = |ext| has_extension(file1, ext) && has_extension(file2, ext);
    if !(both("docx") || both("odt")) {
        tracing::debug!(?file1, ?file2, "compare_docx_files: unsupported or mismatched file types");
        return Ok(0.0);
    }
    let mut paras1 = paragraph_texts(file1)?;
    let mut paras2 = paragraph_texts(file2)?;
    if options.ignore_order {
        paras1.sort();
        paras2.sort();
    }
    let joined = |paras: &[String]| {
        let text = squash(&paras.join("\n"));
        if options.ignore_case {
            text.to_lowercase()
        } else {
            text
        }
    };
    if options.content_only {
        return Ok(super::pdf::ratio(&joined(&paras1), &joined(&paras2)));
    }
    if options.ignore_blanks {
        return Ok(score(joined(&paras1) == joined(&paras2)));
    }
    if paras1.len() != paras2.len() {
        return Ok(0.0);
    }
    let same =
        paras1
            .iter()
            .zip(&paras2)
            .all(|(a, b)| if options.ignore_case { a.to_lowercase() == b.to_lowercase() } else { a == b });
    Ok(score(same))
}

/// `compare_docx_files(result, expected, ignore_blanks=True, ignore_case=False,
/// ignore_order=False, content_only=False)`: the paragraph texts agree.
/// With `ignore_blanks` the joined texts are compared with whitespace runs
/// squashed; without it, paragraph by paragraph. `content_only` scores the
/// fuzzy ratio of the squashed texts. Both files must be docx, or both odt.
pub(super) fn compare_docx_files(input: &MetricInput) -> Result<f64, MetricError> {
    let Some((result, expected)) = pair(input)? else { return Ok(0.0) };
    text_score(result, expected, TextOptions::from(input))
}

/// Upstream's guard `if not compare_docx_files(file1, file2): return 0`.
fn same_text(result: &Path, expected: &Path) -> Result<bool, MetricError> {
    Ok(text_score(result, expected, TextOptions::DEFAULT)? > 0.0)
}

/// `compare_line_spacing(result, expected)`: same text, same paragraph count,
/// and every paragraph's line spacing equal.
pub(super) fn compare_line_spacing(input: &MetricInput) -> Result<f64, MetricError> {
    let Some((result, expected)) = pair(input)? else { return Ok(0.0) };
    if !same_text(result, expected)? {
        return Ok(0.0);
    }
    let (doc1, doc2) = (Document::open(result)?, Document::open(expected)?);
    if doc1.paragraphs.len() != doc2.paragraphs.len() {
        return Ok(0.0);
    }
    Ok(score(doc1.paragraphs.iter().zip(&doc2.paragraphs).all(|(a, b)| a.line_spacing == b.line_spacing)))
}

/// `check_tabstops(result, expected, word_number_split_by_tabstop=None, index=0)`:
/// the non-blank paragraphs pair up; with `word_number_split_by_tabstop`, each
/// result paragraph's `index`-th tab-separated part has that many words; then
/// tab stops (ignoring cleared ones and left stops at 0) must match in number
/// and alignment, and the score is 1 minus the mean position difference as a
/// fraction of the expected document's text width.
pub(super) fn check_tabstops(input: &MetricInput) -> Result<f64, MetricError> {
    let Some((result, expected)) = pair(input)? else { return Ok(0.0) };
    let (doc1, doc2) = (Document::open(result)?, Document::open(expected)?);
    let nonblank = |doc: &Document| {
        doc.paragraphs.iter().filter(|p| !p.text.trim().is_empty()).cloned().collect::<Vec<Paragraph>>()
    };
    let (para1, para2) = (nonblank(&doc1), nonblank(&doc2));
    if para1.len() != para2.len() {
        return Ok(0.0);
    }
    if let Some(number) = input.options.get("word_number_split_by_tabstop").filter(|v| !v.is_null()) {
        let number = number.as_u64().ok_or_else(|| {
            MetricError::BadInput(format!("word_number_split_by_tabstop must be a count, not {number}"))
        })?;
        let index = input.options.get("index").and_then(serde_json::Value::as_i64).unwrap_or(0);
        for p in &para1 {
            let splits: Vec<&str> = p.text.split('\t').collect();
            let at = if index < 0 { splits.len() as i64 + index } else { index };
            // Upstream indexes without a guard; a paragraph too short to index cannot pass.
            let Some(part) = usize::try_from(at).ok().and_then(|i| splits.get(i)) else { return Ok(0.0) };
            if part.split_whitespace().count() as u64 != number {
                return Ok(0.0);
            }
        }
    }
    let section =
        doc2.sections.first().ok_or_else(|| MetricError::BadInput("the expected document has no section".into()))?;
    let width = match (section.page_width, section.left_margin, section.right_margin) {
        (Some(w), Some(l), Some(r)) if w - l - r != 0 => (w - l - r) as f64,
        _ => {
            return Err(MetricError::BadInput(
                "the expected document's first section has no usable page width and margins".into(),
            ))
        }
    };
    if para1.is_empty() {
        return Err(MetricError::Malformed(
            "the result document has no non-blank paragraphs to compare (upstream divides by zero)".into(),
        ));
    }
    let kept = |p: &Paragraph| {
        p.tab_stops
            .iter()
            .filter(|t| !(t.alignment == "clear" || (t.alignment == "left" && t.position == 0)))
            .cloned()
            .collect::<Vec<_>>()
    };
    let mut minus = 0.0;
    for (p1, p2) in para1.iter().zip(&para2) {
        let (tabs1, tabs2) = (kept(p1), kept(p2));
        if tabs1.len() != tabs2.len() {
            return Ok(0.0);
        }
        let mut difference = 0.0;
        for (t1, t2) in tabs1.iter().zip(&tabs2) {
            if t1.alignment != t2.alignment {
                return Ok(0.0);
            }
            difference += (t1.position - t2.position).abs() as f64;
        }
        minus += difference / width;
    }
    Ok(1.0 - minus / para1.len() as f64)
}

/// `compare_docx_tables(result, expected)`: same number of tables, each with
/// the same rows and grid columns and equal cell texts (stripped).
pub(super) fn compare_docx_tables(input: &MetricInput) -> Result<f64, MetricError> {
    let Some((result, expected)) = pair(input)? else { return Ok(0.0) };
    let (doc1, doc2) = (Document::open(result)?, Document::open(expected)?);
    if doc1.tables.len() != doc2.tables.len() {
        return Ok(0.0);
    }
    for (t1, t2) in doc1.tables.iter().zip(&doc2.tables) {
        if t1.rows != t2.rows || t1.columns != t2.columns {
            return Ok(0.0);
        }
        for i in 0..t1.rows {
            for j in 0..t1.columns {
                match (t1.cell(i, j), t2.cell(i, j)) {
                    (Some(a), Some(b)) if a.trim() == b.trim() => {}
                    (Some(_), Some(_)) => return Ok(0.0),
                    _ => {
                        return Err(MetricError::BadInput(format!(
                            "table cell ({i}, {j}) is outside the table's cell grid"
                        )))
                    }
                }
            }
        }
    }
    Ok(1.0)
}

/// `rules["font_name"]` as a string.
fn font_rule(input: &MetricInput) -> Result<String, MetricError> {
    input
        .rule("font_name")?
        .as_str()
        .map(str::to_owned)
        .ok_or_else(|| MetricError::BadInput("rules[\"font_name\"] must be a string".into()))
}

/// `compare_font_names(result, rules)`: every run of every body paragraph sets
/// its font (`w:rFonts/@w:ascii`) to `rules["font_name"]`.
pub(super) fn compare_font_names(input: &MetricInput) -> Result<f64, MetricError> {
    let expected = font_rule(input)?;
    let Some(path) = single(input)? else { return Ok(0.0) };
    let doc = Document::open(path)?;
    Ok(score(doc.paragraphs.iter().flat_map(|p| &p.runs).all(|r| r.font_name.as_deref() == Some(expected.as_str()))))
}

/// `check_italic_font_size_14(result, expected)`: same text, and every italic run is 14 pt.
pub(super) fn check_italic_font_size_14(input: &MetricInput) -> Result<f64, MetricError> {
    let Some((result, expected)) = pair(input)? else { return Ok(0.0) };
    if !same_text(result, expected)? {
        return Ok(0.0);
    }
    let doc = Document::open(result)?;
    Ok(score(
        doc.paragraphs.iter().flat_map(|p| &p.runs).filter(|r| r.italic == Some(true)).all(|r| r.size == Some(14.0)),
    ))
}

/// `find_default_font(config, rules)`: Writer's default font (the last
/// `Standard` value under `/org.openoffice.Office.Writer/DefaultFont` in
/// `registrymodifications.xcu`) is `rules["font_name"]`.
pub(super) fn find_default_font(input: &MetricInput) -> Result<f64, MetricError> {
    let expected = font_rule(input)?;
    let Some(path) = single(input)? else { return Ok(0.0) };
    let text = read_text(path)?;
    let xml = parse_xml(&text)
        .map_err(|err| MetricError::Parse { what: path.display().to_string(), message: err.to_string() })?;
    let mut found: Option<String> = None;
    for item in xml.descendants().filter(|n| n.has_tag_name("item")) {
        if attr(item, "path") != Some("/org.openoffice.Office.Writer/DefaultFont") {
            continue;
        }
        for prop in item.descendants().filter(|n| n.has_tag_name("prop") && attr(*n, "name") == Some("Standard")) {
            for value in prop.children().filter(|n| n.has_tag_name("value")) {
                found = value.text().map(str::to_owned);
            }
        }
    }
    Ok(score(found.as_deref() == Some(expected.as_str())))
}

/// `evaluate_strike_through_last_paragraph(result, expected)`: same text, and
/// every run of the last paragraph is struck through.
pub(super) fn evaluate_strike_through_last_paragraph(input: &MetricInput) -> Result<f64, MetricError> {
    let Some((result, expected)) = pair(input)? else { return Ok(0.0) };
    if !same_text(result, expected)? {
        return Ok(0.0);
    }
    let doc = Document::open(result)?;
    let last =
        doc.paragraphs.last().ok_or_else(|| MetricError::Malformed("the result document has no paragraphs".into()))?;
    Ok(score(last.runs.iter().all(|r| r.strike == Some(true))))
}

/// The first text of each highlighted run anywhere in `word/document.xml`
/// (a run with a `w:highlight` other than `none`), as upstream's raw XML scan collects it.
fn highlighted_texts(path: &Path) -> Result<BTreeSet<Option<String>>, MetricError> {
    let mut pkg = Package::open(path)?;
    pkg.with_xml("word/document.xml", |xml| {
        let mut out = BTreeSet::new();
        for r in descendants(xml.root_element(), "r") {
            let highlighted = descendants(r, "highlight").next().is_some_and(|h| attr(h, "val") != Some("none"));
            if highlighted {
                if let Some(t) = descendants(r, "t").next() {
                    out.insert(t.text().map(str::to_owned));
                }
            }
        }
        Ok(out)
    })
}

/// `compare_highlighted_text(result, expected)`: the sets of highlighted run texts are equal.
pub(super) fn compare_highlighted_text(input: &MetricInput) -> Result<f64, MetricError> {
    let Some((result, expected)) = pair(input)? else { return Ok(0.0) };
    Ok(score(highlighted_texts(result)? == highlighted_texts(expected)?))
}

/// `compare_subscript_contains(result, expected)`: some pair of aligned runs
/// (same paragraph and run position) is subscript in both documents.
pub(super) fn compare_subscript_contains(input: &MetricInput) -> Result<f64, MetricError> {
    let Some((result, expected)) = pair(input)? else { return Ok(0.0) };
    let (doc1, doc2) = (Document::open(result)?, Document::open(expected)?);
    let found = doc1.paragraphs.iter().zip(&doc2.paragraphs).any(|(p1, p2)| {
        p1.runs.iter().zip(&p2.runs).any(|(r1, r2)| r1.subscript == Some(true) && r2.subscript == Some(true))
    });
    Ok(score(found))
}

/// `has_page_numbers_in_footers(result)`: every section's default footer
/// (inherited from earlier sections when not its own) has a digit in its first
/// paragraph's python-docx text: a page number in a complex field's runs
/// counts, one inside a `w:fldSimple` does not (python-docx skips it).
pub(super) fn has_page_numbers_in_footers(input: &MetricInput) -> Result<f64, MetricError> {
    let Some(path) = single(input)? else { return Ok(0.0) };
    let doc = Document::open(path)?;
    Ok(score(doc.sections.iter().all(|s| s.footer_first_text.chars().any(|c| c.is_numeric()))))
}

/// `is_first_line_centered(result)`: the first body paragraph is centred.
pub(super) fn is_first_line_centered(input: &MetricInput) -> Result<f64, MetricError> {
    let Some(path) = single(input)? else { return Ok(0.0) };
    let doc = Document::open(path)?;
    let first =
        doc.paragraphs.first().ok_or_else(|| MetricError::Malformed("the result document has no paragraphs".into()))?;
    Ok(score(first.alignment.as_deref() == Some("center")))
}

/// `check_highlighted_words(result, expected)`: same text (odt), and no span
/// of the result uses an automatic style with a yellow (`#ffff00`) background.
pub(super) fn check_highlighted_words(input: &MetricInput) -> Result<f64, MetricError> {
    let Some((result, expected)) = pair(input)? else { return Ok(0.0) };
    if !same_text(result, expected)? {
        return Ok(0.0);
    }
    let mut pkg = Package::open(result)?;
    let highlighted = pkg.with_xml("content.xml", |xml| {
        let root = xml.root_element();
        let yellow: BTreeSet<&str> = descendants(root, "automatic-styles")
            .flat_map(|styles| styles.children().filter(|n| n.is_element()))
            .filter(|style| style.children().any(|prop| attr(prop, "background-color") == Some("#ffff00")))
            .filter_map(|style| attr(style, "name"))
            .collect();
        Ok(descendants(root, "span").any(|span| attr(span, "style-name").is_some_and(|name| yellow.contains(name))))
    })?;
    Ok(score(!highlighted))
}

/// Paragraph texts of an odt file as odfpy's `getElementsByType(P)` gives them
/// (styles.xml before content.xml): each `text:p`'s own text nodes and the
/// text nodes directly inside its direct `text:span` children.
fn odt_paragraphs(path: &Path) -> Result<Vec<String>, MetricError> {
    let mut pkg = Package::open(path)?;
    let mut out = Vec::new();
    for part in ["styles.xml", "content.xml"] {
        let Some(text) = pkg.part(part)? else { continue };
        let xml = parse_xml(&text).map_err(|err| pkg.error(format!("{part}: {err}")))?;
        for p in descendants(xml.root_element(), "p")
            .filter(|n| n.tag_name().namespace().is_some_and(|ns| ns.contains(":text:")))
        {
            out.push(odt_paragraph_text(p));
        }
    }
    Ok(out)
}

fn odt_paragraph_text(p: Node<'_, '_>) -> String {
    let mut text = String::new();
    for node in p.children() {
        if node.is_text() {
            text.push_str(node.text().unwrap_or_default());
        } else if node.is_element() && node.tag_name().name() == "span" {
            for inner in node.children().filter(Node::is_text) {
                text.push_str(inner.text().unwrap_or_default());
            }
        }
    }
    text
}
