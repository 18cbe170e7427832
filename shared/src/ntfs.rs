//! The order NTFS lists a directory in, the one listing order both sides use.
//!
//! Python's `os.listdir` (and so `glob` and `os.walk`) returns names in the order the
//! file system enumerates them. On the Windows guests that is NTFS's index order: names
//! compared code unit by code unit in UTF-16 after mapping each unit through the
//! volume's upcase table, so `_notes` sorts after `Zebra` and `a.txt` beside `A.TXT`.
//! The guest's listing routes, its script host's `os.listdir` and the host's agent
//! executor all sort with [`cmp_names`], so a listing is the same from every path and
//! on every backend (the stub's Linux file system returns names in no useful order).
//!
//! [`list_dir`] is `os.listdir` itself for a local folder.
//!
//! The upcase table is approximated by Unicode simple uppercase mapping of code units
//! that map to a single code unit, which is what the table holds for the characters
//! file names use.

use std::cmp::Ordering;

/// One UTF-16 code unit as NTFS's upcase table maps it.
fn upcase(unit: u16) -> u16 {
    let Some(c) = char::from_u32(u32::from(unit)) else {
        // A lone surrogate: the table maps it to itself.
        return unit;
    };
    let mut upper = c.to_uppercase();
    match (upper.next(), upper.next()) {
        (Some(u), None) => u16::try_from(u32::from(u)).unwrap_or(unit),
        // Characters that uppercase to several (German ß) keep their own code unit.
        _ => unit,
    }
}

/// Compares two names as NTFS orders them; names equal but for case fall back to
/// ordinal order, so the result is total and stable (NTFS itself never holds both).
pub fn cmp_names(a: &str, b: &str) -> Ordering {
    let upper = |s: &str| s.encode_utf16().map(upcase).collect::<Vec<u16>>();
    upper(a).cmp(&upper(b)).then_with(|| a.encode_utf16().cmp(b.encode_utf16()))
}

/// Sorts names in NTFS order.
pub fn sort_names(names: &mut [String]) {
    names.sort_by(|a, b| cmp_names(a, b));
}

/// Python's `os.listdir` of a local folder as a Windows guest answers it: the entry
/// names (lossily decoded), in NTFS order. Entries that vanish while listing are left out.
///
/// # Errors
///
/// The folder cannot be read (missing, not a folder, no permission).
pub fn list_dir(folder: &std::path::Path) -> std::io::Result<Vec<String>> {
    let mut names: Vec<String> = std::fs::read_dir(folder)?
        .filter_map(Result::ok)
        .map(|entry| entry.file_name().to_string_lossy().into_owned())
        .collect();
    sort_names(&mut names);
    Ok(names)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(input: &[&str], expected: &[&str]) {
        let mut names: Vec<String> = input.iter().map(|s| s.to_string()).collect();
        sort_names(&mut names);
        assert_eq!(names, expected, "sorting {input:?}");
    }

    #[test]
    fn orders_as_ntfs_lists() {
        check(&["b", "A", "c"], &["A", "b", "c"]);
        // Uppercase comparison: '_' (0x5F) sorts after the letters, not before them as a
        // lowercase comparison (and Python's sorted(key=str.lower)) would put it.
        check(&["_notes", "Zebra", "apple"], &["apple", "Zebra", "_notes"]);
        check(&["[x]", "y", "Y2"], &["y", "Y2", "[x]"]);
        check(&["a~", "a_", "aB"], &["aB", "a_", "a~"]);
        // Digits and dots sort before letters; a shorter prefix first.
        check(
            &["file10.txt", "file1.txt", "file.txt", "file2.txt"],
            &["file.txt", "file1.txt", "file10.txt", "file2.txt"],
        );
        // Case twins (only possible off NTFS) fall back to ordinal order.
        check(&["a.txt", "A.TXT", "A.txt"], &["A.TXT", "A.txt", "a.txt"]);
        // Non-ASCII letters upcase too; ß has no single-unit uppercase and stays itself.
        check(&["éclair", "Eclair", "Zoo"], &["Eclair", "Zoo", "éclair"]);
        check(&["ärger", "Ärger2"], &["ärger", "Ärger2"]);
        check(&["ß", "SS", "t"], &["SS", "t", "ß"]);
        check(&[], &[]);
    }

    #[test]
    fn folders_are_listed_in_ntfs_order() {
        let dir = tempfile::tempdir().expect("dir");
        for name in ["b", "_x", "A"] {
            std::fs::write(dir.path().join(name), b"").expect("write");
        }
        assert_eq!(list_dir(dir.path()).expect("list"), ["A", "b", "_x"]);
        assert!(list_dir(&dir.path().join("missing")).is_err());
    }

    #[test]
    fn compares_in_utf16_units() {
        // Characters above U+FFFF are surrogate pairs (0xD800..) in UTF-16, so they sort
        // before U+FF21, where code point order would put them after it.
        assert_eq!(cmp_names("\u{1F600}", "\u{FF21}"), Ordering::Less);
        assert_eq!(cmp_names("a", "a"), Ordering::Equal);
    }
}
