//! Reading the desktop for evaluators: the logic behind upstream's query routes
//! (`/is_details_view`, `/check_if_timer_started`, `/is_directory_read_only_for_user`,
//! `/are_all_images_tagged`, `/library_folders`, ...), which both the WAA layer
//! ([`crate::waa`]) and the native `/v1/eval/*` routes ([`crate::native`]) answer
//! with. Accessibility-tree searches, the ACL rule, EXIF strings and library files;
//! no HTTP and no answer shapes, which each API keeps to itself.

use std::path::Path;

use arena_shared::observation::{A11yNode, A11yTree};

use crate::desktop::Desktop;

/// The first descendant of `node` (not `node` itself), depth first in document order,
/// whose name satisfies `matches`; direct children named exactly `exact` are tried first,
/// as upstream's `find_element_by_name` does with `FindFirst` before walking.
pub fn find_element<'a>(
    node: &'a A11yNode,
    exact: Option<&str>,
    matches: &dyn Fn(&str) -> bool,
) -> Option<&'a A11yNode> {
    if let Some(exact) = exact {
        if let Some(child) = node.children.iter().find(|c| c.name == exact) {
            return Some(child);
        }
    }
    fn walk<'a>(node: &'a A11yNode, matches: &dyn Fn(&str) -> bool) -> Option<&'a A11yNode> {
        for child in &node.children {
            if matches(&child.name) {
                return Some(child);
            }
            if let Some(found) = walk(child, matches) {
                return Some(found);
            }
        }
        None
    }
    walk(node, matches)
}

/// [`find_element`] over every root of a (foreground-only) tree.
pub fn find_in_tree<'a>(
    tree: &'a A11yTree,
    exact: Option<&str>,
    matches: &dyn Fn(&str) -> bool,
) -> Option<&'a A11yNode> {
    tree.windows.iter().find_map(|w| find_element(w, exact, matches))
}

/// `re.match(".*<text>.*", name)`: `.` stops at a newline, so the text must be on the first line.
pub fn first_line_contains(name: &str, text: &str) -> bool {
    name.split('\n').next().unwrap_or("").contains(text)
}

/// The names of the items of File Explorer's item list (the first child of the
/// "Shell Folder View" element) in the foreground window, in display order.
pub fn explorer_items(tree: &A11yTree) -> Option<Vec<String>> {
    let view = find_in_tree(tree, Some("Shell Folder View"), &|n| n == "Shell Folder View")?;
    Some(view.children.first().map(|list| list.children.iter().map(|c| c.name.clone()).collect()).unwrap_or_default())
}

pub fn guest_exists(desktop: &dyn Desktop, guest: &str) -> bool {
    desktop.map_path(guest).is_ok_and(|local| std::fs::metadata(local).is_ok())
}

/// Whether `names` (display order) equals the names sorted by modification time,
/// either files first newest first, or folders first oldest first (upstream's two keys).
pub fn sorted_by_mtime(names: &[String], items: &[(String, i64, bool)]) -> bool {
    let mut desc = items.to_vec();
    desc.sort_by(|a, b| (a.2, -a.1, &a.0).cmp(&(b.2, -b.1, &b.0)));
    let mut asc = items.to_vec();
    asc.sort_by(|a, b| (!a.2, a.1, &a.0).cmp(&(!b.2, b.1, &b.0)));
    let names_of = |v: &[(String, i64, bool)]| v.iter().map(|i| i.0.clone()).collect::<Vec<_>>();
    names == names_of(&desc) || names == names_of(&asc)
}

const FILE_GENERIC_READ: u32 = 0x0012_0089;

const FILE_GENERIC_EXECUTE: u32 = 0x0012_00a0;

const FILE_WRITE_DATA: u32 = 0x0002;

const FILE_APPEND_DATA: u32 = 0x0004;

const FILE_WRITE_EA: u32 = 0x0010;

const FILE_WRITE_ATTRIBUTES: u32 = 0x0100;

/// Upstream's rule on the first ACE naming the user: some read or execute right, and no write right.
pub fn mask_is_read_only(mask: u32) -> bool {
    mask & (FILE_GENERIC_READ | FILE_GENERIC_EXECUTE) != 0
        && mask & (FILE_APPEND_DATA | FILE_WRITE_ATTRIBUTES | FILE_WRITE_DATA | FILE_WRITE_EA) == 0
}

/// Python's `bytes.decode("utf-16", errors="ignore")`: a BOM picks the byte order
/// (little-endian without one), an odd last byte and unpaired surrogates are dropped.
fn decode_utf16_lossy(bytes: &[u8]) -> String {
    let (big_endian, body) = match bytes {
        [0xfe, 0xff, rest @ ..] => (true, rest),
        [0xff, 0xfe, rest @ ..] => (false, rest),
        _ => (false, bytes),
    };
    let units = body.chunks_exact(2).map(|c| {
        if big_endian {
            u16::from_be_bytes([c[0], c[1]])
        } else {
            u16::from_le_bytes([c[0], c[1]])
        }
    });
    char::decode_utf16(units).filter_map(Result::ok).collect()
}

/// The string forms of an image's EXIF values, as upstream makes them from `_getexif()`:
/// byte strings (the `XP*` tags Windows writes its tags to) decoded as UTF-16, text as
/// text, numbers and tuples of numbers joined with spaces.
pub fn exif_strings(path: &Path) -> Vec<String> {
    let Ok(file) = std::fs::File::open(path) else {
        return Vec::new();
    };
    let Ok(exif) = exif::Reader::new().read_from_container(&mut std::io::BufReader::new(file)) else {
        return Vec::new();
    };
    let join = |parts: Vec<String>| parts.join(" ");
    exif.fields()
        .map(|field| match &field.value {
            exif::Value::Byte(bytes) | exif::Value::Undefined(bytes, _) => decode_utf16_lossy(bytes),
            exif::Value::Ascii(strings) => {
                join(strings.iter().map(|s| String::from_utf8_lossy(s).into_owned()).collect())
            }
            exif::Value::Short(v) => join(v.iter().map(u16::to_string).collect()),
            exif::Value::Long(v) => join(v.iter().map(u32::to_string).collect()),
            exif::Value::SByte(v) => join(v.iter().map(i8::to_string).collect()),
            exif::Value::SShort(v) => join(v.iter().map(i16::to_string).collect()),
            exif::Value::SLong(v) => join(v.iter().map(i32::to_string).collect()),
            exif::Value::Rational(v) => join(v.iter().map(|r| arena_script::float_repr(r.to_f64())).collect()),
            exif::Value::SRational(v) => join(v.iter().map(|r| arena_script::float_repr(r.to_f64())).collect()),
            exif::Value::Float(v) => join(v.iter().map(|f| arena_script::float_repr(f64::from(*f))).collect()),
            exif::Value::Double(v) => join(v.iter().map(|f| arena_script::float_repr(*f)).collect()),
            _ => String::new(),
        })
        .collect()
}

const LIBRARY_NS: &str = "http://schemas.microsoft.com/windows/2009/library";

/// Text of a `.library-ms` file: UTF-8 (with or without BOM) or UTF-16 with a BOM.
pub fn decode_xml_text(bytes: &[u8]) -> String {
    match bytes {
        [0xef, 0xbb, 0xbf, rest @ ..] => String::from_utf8_lossy(rest).into_owned(),
        [0xff, 0xfe, ..] | [0xfe, 0xff, ..] => decode_utf16_lossy(bytes),
        _ => String::from_utf8_lossy(bytes).into_owned(),
    }
}

/// The folder URLs of a Windows library description, sorted.
///
/// # Errors
///
/// The parser's message for malformed XML.
pub fn library_urls(xml: &str) -> Result<Vec<String>, String> {
    let doc = roxmltree::Document::parse(xml).map_err(|err| err.to_string())?;
    let is = |node: &roxmltree::Node<'_, '_>, name: &str| {
        node.is_element() && node.tag_name().name() == name && node.tag_name().namespace() == Some(LIBRARY_NS)
    };
    let mut urls: Vec<String> = doc
        .descendants()
        .filter(|n| is(n, "searchConnectorDescriptionList"))
        .flat_map(|list| list.children().filter(|n| is(n, "searchConnectorDescription")))
        .flat_map(|desc| desc.children().filter(|n| is(n, "simpleLocation")))
        .flat_map(|loc| loc.children().filter(|n| is(n, "url")))
        .filter_map(|url| url.text().map(str::to_owned))
        .collect();
    urls.sort();
    Ok(urls)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mask_rule_matches_upstream() {
        let check = |mask: u32, expected: bool| assert_eq!(mask_is_read_only(mask), expected, "{mask:#x}");
        check(0x0012_00a9, true); // read and execute
        check(0x0012_0089, true); // read
        check(0x001f_01ff, false); // full control
        check(0x0013_01bf, false); // modify
        check(0, false);
        check(0x0012_0089 | FILE_WRITE_EA, false);
    }

    #[test]
    fn mtime_sorting_accepts_both_upstream_orders() {
        let items =
            vec![("b.txt".to_owned(), 30, false), ("a.txt".to_owned(), 10, false), ("dir".to_owned(), 20, true)];
        let names = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        assert!(sorted_by_mtime(&names(&["b.txt", "a.txt", "dir"]), &items));
        assert!(sorted_by_mtime(&names(&["dir", "a.txt", "b.txt"]), &items));
        assert!(!sorted_by_mtime(&names(&["a.txt", "b.txt", "dir"]), &items));
    }

    #[test]
    fn utf16_decoding_ignores_errors() {
        let mut bytes: Vec<u8> = "cat;dog\0".encode_utf16().flat_map(u16::to_le_bytes).collect();
        bytes.push(0x41);
        assert_eq!(decode_utf16_lossy(&bytes), "cat;dog\0");
        assert_eq!(decode_utf16_lossy(&[0xfe, 0xff, 0x00, 0x41, 0xd8, 0x00]), "A");
    }

    #[test]
    fn library_urls_are_read_with_the_namespace_and_sorted() {
        let xml = r#"<?xml version="1.0" encoding="UTF-8"?>
<libraryDescription xmlns="http://schemas.microsoft.com/windows/2009/library">
  <name>@shell32.dll,-34575</name>
  <searchConnectorDescriptionList>
    <searchConnectorDescription><simpleLocation><url>C:\Users\Docker\Pictures</url></simpleLocation></searchConnectorDescription>
    <searchConnectorDescription><simpleLocation><url>C:\Data\Art</url></simpleLocation></searchConnectorDescription>
  </searchConnectorDescriptionList>
  <other xmlns="urn:x"><url>ignored</url></other>
</libraryDescription>"#;
        assert_eq!(library_urls(xml).unwrap(), vec![r"C:\Data\Art".to_owned(), r"C:\Users\Docker\Pictures".to_owned()]);
        assert!(library_urls("<broken").is_err());
    }

    #[test]
    fn timer_text_matches_on_the_first_line() {
        assert!(first_line_contains("Timer 1, 0 hours 30 minutes 0 seconds", "0 hours 30 minutes 0 seconds"));
        assert!(!first_line_contains("Timer\n0 hours 30 minutes 0 seconds", "0 hours 30 minutes 0 seconds"));
    }
}
