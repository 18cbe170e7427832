//! The accessibility tree in upstream's XML (`GET /accessibility`, waa-api.md §f).
//!
//! Upstream builds this XML with lxml from pywinauto wrappers; hosts read it with
//! namespace-aware parsers and CSS selectors (Navi's `propose_ents`, the Chrome URL
//! getters), so the tags, attribute names and order, value formats and escaping are
//! reproduced here from a backend-neutral [`A11yTree`]. It is a pure formatter: it
//! never fails, and characters XML cannot carry are dropped instead of failing the
//! request as lxml does.

use crate::observation::{A11yBackend, A11yNode, A11yTree};

/// Deepest level that gets children; top-level windows are depth 1 (upstream's `depth == 50`).
pub const MAX_DEPTH: u32 = 50;

/// Most children written per node (upstream breaks at `i >= 2048`).
pub const MAX_CHILDREN: usize = 2048;

/// The namespaces declared on `<desktop>`, in upstream's order.
pub const NAMESPACES: [(&str, &str); 9] = [
    ("st", "uri:deskat:state.at-spi.gnome.org"),
    ("attr", "uri:deskat:attributes.at-spi.gnome.org"),
    ("cp", "uri:deskat:component.at-spi.gnome.org"),
    ("doc", "uri:deskat:document.at-spi.gnome.org"),
    ("docattr", "uri:deskat:attributes.document.at-spi.gnome.org"),
    ("txt", "uri:deskat:text.at-spi.gnome.org"),
    ("val", "uri:deskat:value.at-spi.gnome.org"),
    ("act", "uri:deskat:action.at-spi.gnome.org"),
    ("win", "uri:deskat:uia.windows.microsoft.org"),
];

const UIA_WRAPPER: &str = "<class 'pywinauto.controls.uiawrapper.UIAWrapper'>";
const UIA_EDIT_WRAPPER: &str = "<class 'pywinauto.controls.uia_controls.EditWrapper'>";
const HWND_WRAPPER: &str = "<class 'pywinauto.controls.hwndwrapper.HwndWrapper'>";
const WIN32_EDIT_WRAPPER: &str = "<class 'pywinauto.controls.win32_controls.EditWrapper'>";

/// Renders `tree` as upstream's `lxml.etree.tostring(desktop, encoding="unicode")`.
///
/// `foreground` is the foreground window's id: a node's `st:active` is whether the
/// window it belongs to is that window.
pub fn to_xml(tree: &A11yTree, foreground: Option<u64>) -> String {
    let mut out = String::with_capacity(256 + 256 * tree.node_count as usize);
    out.push_str("<desktop");
    for (prefix, uri) in NAMESPACES {
        out.push_str(" xmlns:");
        out.push_str(prefix);
        out.push_str("=\"");
        out.push_str(uri);
        out.push('"');
    }
    if tree.windows.is_empty() {
        out.push_str("/>");
        return out;
    }
    out.push('>');
    let ctx = Context { backend: tree.backend, foreground };
    for window in &tree.windows {
        write_node(&mut out, &ctx, window, 1, None);
    }
    out.push_str("</desktop>");
    out
}

struct Context {
    backend: A11yBackend,
    foreground: Option<u64>,
}

fn bool_str(b: bool) -> &'static str {
    if b {
        "true"
    } else {
        "false"
    }
}

fn write_node(out: &mut String, ctx: &Context, node: &A11yNode, depth: u32, parent_window: Option<u64>) {
    let window = node.window_id.or(parent_window);
    let uia = ctx.backend != A11yBackend::Win32;
    let tag = tag_name(&node.class_name);
    out.push('<');
    out.push_str(&tag);

    let mut attr = |name: &str, value: &str| {
        out.push(' ');
        out.push_str(name);
        out.push_str("=\"");
        escape_into(out, value, true);
        out.push('"');
    };
    attr("name", &node.name);
    attr("st:enabled", bool_str(node.enabled));
    attr("st:visible", bool_str(node.visible));
    attr("st:active", bool_str(window.is_some() && window == ctx.foreground));

    // The optional states, in the order upstream probes the wrapper's methods.
    let states = &node.states;
    if let Some(v) = states.minimized {
        attr("st:minimized", bool_str(v));
    }
    if let Some(v) = states.maximized {
        attr("st:maximized", bool_str(v));
    }
    if let (Some(min), Some(max)) = (states.minimized, states.maximized) {
        attr("st:normal", bool_str(!min && !max));
    }
    if !uia {
        // Every win32 HwndWrapper answers `is_unicode`, and Windows windows are Unicode.
        attr("st:unicode", "true");
    }
    if let Some(v) = states.expanded {
        attr("st:collapsed", bool_str(!v));
    }
    if let Some(v) = states.checked {
        attr("st:checked", bool_str(v));
    }
    if let Some(v) = states.selected {
        attr("st:selected", bool_str(v));
    }
    if let Some(v) = states.expanded {
        attr("st:expanded", bool_str(v));
    }
    if let Some(v) = states.editable {
        attr("st:editable", bool_str(v));
    }

    let (x, y, w, h) = node.rect.map_or((0, 0, 0, 0), |r| (r.x, r.y, r.width, r.height));
    attr("cp:screencoord", &format!("({x}, {y})"));
    attr("cp:size", &format!("({w}, {h})"));
    if uia {
        // UIAWrapper defines `select`, so upstream marks every uia node.
        attr("selection", "true");
    }
    if let Some(value) = &node.value {
        attr("val:value", value);
    }
    let is_edit = node.role.eq_ignore_ascii_case("edit") || (!uia && node.class_name.eq_ignore_ascii_case("edit"));
    let class = match (uia, is_edit) {
        (true, true) => UIA_EDIT_WRAPPER,
        (true, false) => UIA_WRAPPER,
        (false, true) => WIN32_EDIT_WRAPPER,
        (false, false) => HWND_WRAPPER,
    };
    attr("win:class", class);

    let text = node.text.as_deref().filter(|t| !t.is_empty() && *t != node.name);
    let children: &[A11yNode] =
        if depth >= MAX_DEPTH { &[] } else { &node.children[..node.children.len().min(MAX_CHILDREN)] };
    if text.is_none() && children.is_empty() {
        out.push_str("/>");
        return;
    }
    out.push('>');
    if let Some(text) = text {
        escape_into(out, text, false);
    }
    for child in children {
        write_node(out, ctx, child, depth + 1, window);
    }
    out.push_str("</");
    out.push_str(&tag);
    out.push('>');
}

/// Upstream's tag from a class name: lowercased, spaces and characters that are not
/// alphanumeric, `_` or `-` turned into `-`, `unknown` when empty, and prefixed with
/// `tag` when the first character is not a letter (`#32770` becomes `tag-32770`).
/// Characters XML does not allow in names also become `-` (lxml would refuse them).
pub fn tag_name(class_name: &str) -> String {
    let mapped: String = class_name
        .to_lowercase()
        .chars()
        .map(|c| if (c.is_alphanumeric() || c == '_' || c == '-') && is_name_char(c) { c } else { '-' })
        .collect();
    match mapped.chars().next() {
        None => "unknown".to_owned(),
        Some(first) if first.is_alphabetic() && is_name_start_char(first) => mapped,
        Some(_) => format!("tag{mapped}"),
    }
}

/// XML 1.0 (fifth edition) `NameStartChar`, without `:`.
fn is_name_start_char(c: char) -> bool {
    matches!(c,
        'A'..='Z' | '_' | 'a'..='z'
        | '\u{C0}'..='\u{D6}' | '\u{D8}'..='\u{F6}' | '\u{F8}'..='\u{2FF}'
        | '\u{370}'..='\u{37D}' | '\u{37F}'..='\u{1FFF}' | '\u{200C}'..='\u{200D}'
        | '\u{2070}'..='\u{218F}' | '\u{2C00}'..='\u{2FEF}' | '\u{3001}'..='\u{D7FF}'
        | '\u{F900}'..='\u{FDCF}' | '\u{FDF0}'..='\u{FFFD}' | '\u{10000}'..='\u{EFFFF}')
}

/// XML 1.0 (fifth edition) `NameChar`, without `:`.
fn is_name_char(c: char) -> bool {
    is_name_start_char(c)
        || matches!(c, '-' | '.' | '0'..='9' | '\u{B7}' | '\u{300}'..='\u{36F}' | '\u{203F}'..='\u{2040}')
}

/// Characters XML 1.0 can carry at all.
fn is_xml_char(c: char) -> bool {
    matches!(c, '\t' | '\n' | '\r' | '\u{20}'..='\u{D7FF}' | '\u{E000}'..='\u{FFFD}' | '\u{10000}'..='\u{10FFFF}')
}

/// Escapes like libxml2's serializer: `&`, `<` and `>` everywhere; in attributes also
/// `"` and the whitespace characters a parser would normalise (`&#10;`, `&#13;`, `&#9;`);
/// in text a carriage return. Characters XML cannot carry are dropped.
fn escape_into(out: &mut String, s: &str, attribute: bool) {
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '\r' => out.push_str("&#13;"),
            '"' if attribute => out.push_str("&quot;"),
            '\n' if attribute => out.push_str("&#10;"),
            '\t' if attribute => out.push_str("&#9;"),
            c if is_xml_char(c) => out.push(c),
            _ => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{CoordinateSpace, Rect};
    use crate::observation::A11yStates;

    const ST: &str = "uri:deskat:state.at-spi.gnome.org";
    const CP: &str = "uri:deskat:component.at-spi.gnome.org";
    const VAL: &str = "uri:deskat:value.at-spi.gnome.org";

    fn node(role: &str, class: &str, name: &str, rect: Rect) -> A11yNode {
        A11yNode {
            role: role.into(),
            class_name: class.into(),
            name: name.into(),
            rect: Some(rect),
            enabled: true,
            visible: true,
            ..A11yNode::default()
        }
    }

    fn tree(backend: A11yBackend, windows: Vec<A11yNode>) -> A11yTree {
        A11yTree {
            backend,
            windows,
            truncated: false,
            node_count: 0,
            elapsed_ms: 0,
            coordinate_space: CoordinateSpace::Physical,
            windows_walked: Vec::new(),
        }
    }

    const DECLS: &str = r#"xmlns:st="uri:deskat:state.at-spi.gnome.org" xmlns:attr="uri:deskat:attributes.at-spi.gnome.org" xmlns:cp="uri:deskat:component.at-spi.gnome.org" xmlns:doc="uri:deskat:document.at-spi.gnome.org" xmlns:docattr="uri:deskat:attributes.document.at-spi.gnome.org" xmlns:txt="uri:deskat:text.at-spi.gnome.org" xmlns:val="uri:deskat:value.at-spi.gnome.org" xmlns:act="uri:deskat:action.at-spi.gnome.org" xmlns:win="uri:deskat:uia.windows.microsoft.org""#;

    /// A Chrome window with an omnibox, and the taskbar behind it.
    fn chrome_tree() -> A11yTree {
        let mut chrome = node("Window", "Chrome_WidgetWin_1", "New Tab - Google Chrome", Rect::new(-8, -8, 1936, 1056));
        chrome.window_id = Some(7);
        chrome.states = A11yStates { minimized: Some(false), maximized: Some(true), ..A11yStates::default() };
        let mut omnibox = node("Edit", "OmniboxViewViews", "Address and search bar", Rect::new(120, 48, 900, 28));
        omnibox.value = Some("www.google.com/search?q=x&y=\"1\"".into());
        let mut pane = node("Pane", "", "", Rect::new(0, 0, 1920, 1040));
        pane.children.push(omnibox);
        chrome.children.push(pane);
        let mut taskbar = node("Pane", "Shell_TrayWnd", "Taskbar", Rect::new(0, 1040, 1920, 40));
        taskbar.window_id = Some(9);
        tree(A11yBackend::Uia, vec![chrome, taskbar])
    }

    #[test]
    fn uia_tree_matches_hand_written_xml() {
        let expected = format!(
            concat!(
                "<desktop {decls}>",
                r#"<chrome_widgetwin_1 name="New Tab - Google Chrome" st:enabled="true" st:visible="true" st:active="true" st:minimized="false" st:maximized="true" st:normal="false" cp:screencoord="(-8, -8)" cp:size="(1936, 1056)" selection="true" win:class="&lt;class 'pywinauto.controls.uiawrapper.UIAWrapper'&gt;">"#,
                r#"<unknown name="" st:enabled="true" st:visible="true" st:active="true" cp:screencoord="(0, 0)" cp:size="(1920, 1040)" selection="true" win:class="&lt;class 'pywinauto.controls.uiawrapper.UIAWrapper'&gt;">"#,
                r#"<omniboxviewviews name="Address and search bar" st:enabled="true" st:visible="true" st:active="true" cp:screencoord="(120, 48)" cp:size="(900, 28)" selection="true" val:value="www.google.com/search?q=x&amp;y=&quot;1&quot;" win:class="&lt;class 'pywinauto.controls.uia_controls.EditWrapper'&gt;"/>"#,
                "</unknown></chrome_widgetwin_1>",
                r#"<shell_traywnd name="Taskbar" st:enabled="true" st:visible="true" st:active="false" cp:screencoord="(0, 1040)" cp:size="(1920, 40)" selection="true" win:class="&lt;class 'pywinauto.controls.uiawrapper.UIAWrapper'&gt;"/>"#,
                "</desktop>"
            ),
            decls = DECLS
        );
        assert_eq!(to_xml(&chrome_tree(), Some(7)), expected);
    }

    #[test]
    fn win32_nodes_carry_hwnd_wrapper_attributes() {
        let mut dialog = node("Dialog", "#32770", "Save As", Rect::new(10, 20, 300, 200));
        dialog.window_id = Some(3);
        let mut edit = node("Edit", "Edit", "File name:", Rect::new(20, 30, 100, 20));
        edit.text = Some("report.txt".into());
        dialog.children.push(edit);
        let expected = format!(
            concat!(
                "<desktop {decls}>",
                r#"<tag-32770 name="Save As" st:enabled="true" st:visible="true" st:active="false" st:unicode="true" cp:screencoord="(10, 20)" cp:size="(300, 200)" win:class="&lt;class 'pywinauto.controls.hwndwrapper.HwndWrapper'&gt;">"#,
                r#"<edit name="File name:" st:enabled="true" st:visible="true" st:active="false" st:unicode="true" cp:screencoord="(20, 30)" cp:size="(100, 20)" win:class="&lt;class 'pywinauto.controls.win32_controls.EditWrapper'&gt;">report.txt</edit>"#,
                "</tag-32770></desktop>"
            ),
            decls = DECLS
        );
        assert_eq!(to_xml(&tree(A11yBackend::Win32, vec![dialog]), Some(99)), expected);
    }

    #[test]
    fn empty_desktop_is_self_closing() {
        assert_eq!(to_xml(&tree(A11yBackend::Uia, vec![]), None), format!("<desktop {DECLS}/>"));
    }

    #[test]
    fn tags_are_sanitised_like_upstream() {
        let check = |class: &str, expected: &str| assert_eq!(tag_name(class), expected, "{class:?}");
        check("Chrome_WidgetWin_1", "chrome_widgetwin_1");
        check("Shell_TrayWnd", "shell_traywnd");
        check("#32770", "tag-32770");
        check("", "unknown");
        check("Windows.UI.Core.CoreWindow", "windows-ui-core-corewindow");
        check("My Class", "my-class");
        check("_private", "tag_private");
        check("1abc", "tag1abc");
        check("Ünïcode", "ünïcode");
        check("x²", "x-");
        check("a:b", "a-b");
    }

    #[test]
    fn text_and_escaping_follow_lxml() {
        let mut n = node("Text", "Static", "a\"b\nc\td\re<>&\u{1}\u{b}", Rect::new(0, 0, 1, 1));
        n.text = Some("line1\nline2 & <x>\r\u{0}".into());
        let xml = to_xml(&tree(A11yBackend::Uia, vec![n]), None);
        assert!(xml.contains(r#"name="a&quot;b&#10;c&#9;d&#13;e&lt;&gt;&amp;""#), "{xml}");
        assert!(xml.contains(">line1\nline2 &amp; &lt;x&gt;&#13;</static>"), "{xml}");
        let doc = roxmltree::Document::parse(&xml).expect("well-formed");
        let el = doc.root_element().first_element_child().unwrap();
        assert_eq!(el.attribute("name"), Some("a\"b\nc\td\re<>&"));
        assert_eq!(el.text(), Some("line1\nline2 & <x>\r"));
    }

    #[test]
    fn text_equal_to_name_is_omitted() {
        let mut n = node("Text", "Static", "same", Rect::new(0, 0, 1, 1));
        n.text = Some("same".into());
        assert!(to_xml(&tree(A11yBackend::Uia, vec![n]), None).contains("/></desktop>"));
    }

    #[test]
    fn depth_and_width_are_capped() {
        // A chain 60 deep: depth 50 is written without children.
        let mut deep = node("Pane", "Leaf", "d60", Rect::new(0, 0, 1, 1));
        for i in (1..60).rev() {
            let mut parent = node("Pane", "Chain", &format!("d{i}"), Rect::new(0, 0, 1, 1));
            parent.children.push(deep);
            deep = parent;
        }
        let xml = to_xml(&tree(A11yBackend::Uia, vec![deep]), None);
        let doc = roxmltree::Document::parse(&xml).unwrap();
        let max_depth = doc.descendants().filter(|n| n.is_element()).map(|n| n.ancestors().count() - 1).max().unwrap();
        // The root `<desktop>` sits at depth 1 of the document, windows at 2, so 50 levels reach 51.
        assert_eq!(max_depth, 51);
        assert!(xml.contains(r#"name="d50""#) && !xml.contains(r#"name="d51""#));

        let mut wide = node("List", "List", "wide", Rect::new(0, 0, 1, 1));
        wide.children = (0..3000).map(|i| node("ListItem", "Item", &i.to_string(), Rect::new(0, 0, 1, 1))).collect();
        let xml = to_xml(&tree(A11yBackend::Uia, vec![wide]), None);
        let doc = roxmltree::Document::parse(&xml).unwrap();
        assert_eq!(doc.root_element().first_element_child().unwrap().children().count(), MAX_CHILDREN);
    }

    #[test]
    fn namespaces_parse_back() {
        let xml = to_xml(&chrome_tree(), Some(7));
        let doc = roxmltree::Document::parse(&xml).unwrap();
        let root = doc.root_element();
        assert_eq!(root.tag_name().name(), "desktop");
        for (prefix, uri) in NAMESPACES {
            assert_eq!(root.lookup_namespace_uri(Some(prefix)), Some(uri), "{prefix}");
        }
        let chrome = root.first_element_child().unwrap();
        assert_eq!(chrome.attribute((ST, "active")), Some("true"));
        assert_eq!(chrome.attribute(("uri:deskat:uia.windows.microsoft.org", "class")), Some(UIA_WRAPPER));
    }

    /// Navi's `propose_ents`: leaves of visible windows that are visible and enabled,
    /// with `(x, y)` and `(w, h)` parsed by splitting on the comma.
    #[test]
    fn navi_leaf_selection_reads_the_attributes() {
        let xml = to_xml(&chrome_tree(), Some(7));
        let doc = roxmltree::Document::parse(&xml).unwrap();
        let parse_pair = |s: &str| -> (i32, i32) {
            let (a, b) = s.split_once(',').unwrap();
            (a.trim().trim_matches(['(', ')']).parse().unwrap(), b.trim().trim_matches(['(', ')']).parse().unwrap())
        };
        let mut entities = Vec::new();
        for window in doc.root_element().children().filter(|n| n.is_element()) {
            assert_eq!(window.attribute((ST, "visible")), Some("true"));
            for n in window.descendants().filter(|n| n.is_element() && n.children().all(|c| !c.is_element())) {
                if n.attribute((ST, "visible")) == Some("true") && n.attribute((ST, "enabled")) == Some("true") {
                    let pos = parse_pair(n.attribute((CP, "screencoord")).unwrap());
                    let size = parse_pair(n.attribute((CP, "size")).unwrap());
                    entities.push((n.attribute("name").unwrap().to_owned(), pos, size));
                }
            }
        }
        assert_eq!(
            entities,
            vec![
                ("Address and search bar".to_owned(), (120, 48), (900, 28)),
                ("Taskbar".to_owned(), (0, 1040), (1920, 40)),
            ]
        );
    }

    /// The Chrome URL getters: `chrome_widgetwin_1 [name=Address\ and\ search\ bar]`,
    /// last match, `val:value`.
    #[test]
    fn chrome_address_bar_lookup_finds_the_url() {
        let xml = to_xml(&chrome_tree(), Some(7));
        let doc = roxmltree::Document::parse(&xml).unwrap();
        let matches: Vec<_> = doc
            .descendants()
            .filter(|n| n.is_element() && n.tag_name().name() == "chrome_widgetwin_1")
            .flat_map(|w| w.descendants().skip(1))
            .filter(|n| n.is_element() && n.attribute("name") == Some("Address and search bar"))
            .collect();
        assert_eq!(matches.len(), 1);
        let value = matches.last().and_then(|n| n.attribute((VAL, "value")));
        assert_eq!(value, Some("www.google.com/search?q=x&y=\"1\""));
    }

    proptest::proptest! {
        /// Whatever the names and class names, the output is well-formed XML with the names intact
        /// (minus the characters XML cannot carry).
        #[test]
        fn output_is_always_well_formed(class in "\\PC{0,8}", name in "\\PC{0,12}", text in "[\\x00-\\x7f]{0,12}") {
            let mut n = node("Pane", &class, &name, Rect::new(0, 0, 1, 1));
            n.text = Some(text);
            let xml = to_xml(&tree(A11yBackend::Uia, vec![n]), None);
            let doc = roxmltree::Document::parse(&xml);
            proptest::prop_assert!(doc.is_ok(), "{xml}");
            let doc = doc.unwrap();
            let expected: String = name.chars().filter(|c| is_xml_char(*c)).collect();
            proptest::prop_assert_eq!(doc.root_element().first_element_child().unwrap().attribute("name"), Some(expected.as_str()));
        }
    }
}
