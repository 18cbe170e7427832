//! Escaping text for XML and HTML, the one escaping both markup syntaxes share: the
//! Task Scheduler definition the guest's service registers (`service::task_xml`) and
//! the host's HTML reports (`results::html`).
//!
//! [`escape`] replaces the five characters markup gives a meaning (`&`, `<`, `>`, `"`,
//! `'`), so its output is safe in element content and in attribute values quoted
//! either way, in XML 1.0 and HTML alike (the apostrophe is `&#39;`, which both read;
//! `&apos;` is not HTML 4).
//!
//! Two other escapers remain on purpose, because they write other syntaxes or must
//! match another program byte for byte: `a11y_xml` reproduces libxml2's serializer
//! (upstream's accessibility tree is written by lxml: newlines and tabs become
//! character references in attributes, apostrophes stay, characters XML cannot carry
//! are dropped), and the host's Markdown summary and QEMU option values have their own
//! syntax (`|` in a table cell, `,` in an option value).

/// `text` with `&`, `<`, `>`, `"` and `'` replaced by references.
pub fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_five_markup_characters_are_replaced_and_the_rest_kept() {
        assert_eq!(
            escape(r#"<a href="x">Tom & 'Jerry'</a> é"#),
            "&lt;a href=&quot;x&quot;&gt;Tom &amp; &#39;Jerry&#39;&lt;/a&gt; é"
        );
        assert_eq!(escape("plain"), "plain");
    }
}
