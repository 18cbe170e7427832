//! Small lookups over roxmltree nodes shared by the OOXML and ODF readers:
//! children by local name, `val` attributes, relationship ids and the
//! OOXML boolean forms (`1`, `true`, `on`).
//!
//! Elements are matched by local name only: producers disagree on prefixes
//! and on the transitional/strict namespace URIs, and within one part a local
//! name is unambiguous for what the metrics read.

use roxmltree::Node;

/// The first element child of `node` named `local`.
pub(super) fn child<'a, 'i>(node: Node<'a, 'i>, local: &str) -> Option<Node<'a, 'i>> {
    node.children().find(|n| n.is_element() && n.tag_name().name() == local)
}

/// The element children of `node` named `local`, in order.
pub(super) fn children<'a, 'i: 'a>(node: Node<'a, 'i>, local: &'a str) -> impl Iterator<Item = Node<'a, 'i>> + 'a {
    node.children().filter(move |n| n.is_element() && n.tag_name().name() == local)
}

/// The element descendants of `node` (itself included) named `local`, in document order.
pub(super) fn descendants<'a, 'i: 'a>(node: Node<'a, 'i>, local: &'a str) -> impl Iterator<Item = Node<'a, 'i>> + 'a {
    node.descendants().filter(move |n| n.is_element() && n.tag_name().name() == local)
}

/// An attribute by local name, whatever its namespace.
pub(super) fn attr<'a>(node: Node<'a, '_>, local: &str) -> Option<&'a str> {
    node.attributes().find(|a| a.name() == local).map(|a| a.value())
}

/// The `val` attribute of child `local` (`<w:jc w:val="center"/>`).
pub(super) fn child_val<'a>(node: Node<'a, '_>, local: &str) -> Option<&'a str> {
    child(node, local).and_then(|c| attr(c, "val"))
}

/// The relationship id of a node (`r:id` or `r:embed`-style attributes named `id`
/// in a relationships namespace).
pub(super) fn rel_id<'a>(node: Node<'a, '_>) -> Option<&'a str> {
    node.attributes()
        .find(|a| a.name() == "id" && a.namespace().is_some_and(|ns| ns.ends_with("/relationships")))
        .map(|a| a.value())
}

/// An OOXML boolean attribute value (`1`, `true`, `on` are true).
pub(super) fn truthy(value: &str) -> bool {
    matches!(value, "1" | "true" | "on" | "True")
}

/// A toggle property such as `<w:b/>` or `<b val="0"/>`: `None` when absent,
/// true when present without `val`, else the value of `val`.
pub(super) fn toggle(node: Node<'_, '_>, local: &str) -> Option<bool> {
    child(node, local).map(|c| attr(c, "val").is_none_or(truthy))
}

/// The text of an element's `t` descendants joined (shared strings, inline strings),
/// skipping phonetic runs (`rPh`), as openpyxl reads them.
pub(super) fn joined_text(node: Node<'_, '_>) -> String {
    let mut out = String::new();
    for t in node.descendants().filter(|n| n.is_element() && n.tag_name().name() == "t") {
        if t.ancestors().any(|a| a.tag_name().name() == "rPh") {
            continue;
        }
        out.push_str(t.text().unwrap_or_default());
    }
    out
}
