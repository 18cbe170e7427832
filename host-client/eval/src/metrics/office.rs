//! Metrics of upstream's `metrics/table.py` (spreadsheets), `metrics/docs.py`
//! (Word and Writer documents) and `compare_pdfs`, read natively: xlsx and
//! docx packages are unzipped and their XML parts parsed here (no openpyxl,
//! pandas or python-docx), PDFs go through `pdf-extract`.
//!
//! Layout: `package.rs` (zip parts and relationships) and `xml.rs` (node
//! lookups) are shared; `xlsx.rs` reads workbooks, `frame.rs` reproduces the
//! pandas behaviour `sheet_data` depends on, `table.rs` is `compare_table`;
//! `docx.rs` reads documents as python-docx shows them, `docs.rs` holds the
//! document metrics; `pdf.rs` is `compare_pdfs` with rapidfuzz's `ratio`.
//!
//! A file that cannot be parsed is an error (the run scores 0 and keeps the
//! reason); a missing result (`None`) scores 0 as upstream does.

mod cond;
mod docs;
mod docx;
mod frame;
mod package;
mod pdf;
mod table;
mod xlsx;
mod xml;

#[cfg(test)]
mod tests;

use super::MetricFn;

pub(super) use pdf::pdf_text_of_bytes;

/// The metric of this family named `name`, if implemented.
pub(super) fn lookup(name: &str) -> Option<MetricFn> {
    let f: MetricFn = match name {
        "compare_table" => table::compare_table,
        "compare_docx_files" => docs::compare_docx_files,
        "compare_line_spacing" => docs::compare_line_spacing,
        "check_tabstops" => docs::check_tabstops,
        "compare_docx_tables" => docs::compare_docx_tables,
        "compare_font_names" => docs::compare_font_names,
        "check_italic_font_size_14" => docs::check_italic_font_size_14,
        "find_default_font" => docs::find_default_font,
        "evaluate_strike_through_last_paragraph" => docs::evaluate_strike_through_last_paragraph,
        "compare_highlighted_text" => docs::compare_highlighted_text,
        "compare_subscript_contains" => docs::compare_subscript_contains,
        "has_page_numbers_in_footers" => docs::has_page_numbers_in_footers,
        "check_highlighted_words" => docs::check_highlighted_words,
        "is_first_line_centered" => docs::is_first_line_centered,
        "compare_pdfs" => pdf::compare_pdfs,
        _ => return None,
    };
    Some(f)
}
