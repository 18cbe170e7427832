//! Text helpers the Windows backend needs and that are plain data work: newline
//! folding of program output, UTF-16 buffers with NUL terminators, and clipping of
//! captured output to a byte cap.
//!
//! Platform-neutral and tested natively. The code-page conversion itself
//! (`MultiByteToWideChar(CP_ACP)`) is an OS call and lives in `desktop/windows/`; it
//! hands its UTF-16 result to [`fold_newlines`].

/// Folds CRLF and lone CR to LF, as Python's universal newlines (`text=True`) do.
pub fn fold_newlines(s: &str) -> String {
    if !s.contains('\r') {
        return s.to_owned();
    }
    let mut out = String::with_capacity(s.len());
    let mut chars = s.chars().peekable();
    while let Some(c) = chars.next() {
        if c == '\r' {
            if chars.peek() == Some(&'\n') {
                chars.next();
            }
            out.push('\n');
        } else {
            out.push(c);
        }
    }
    out
}

/// `s` as UTF-16 with a terminating NUL, for `PCWSTR` arguments.
pub fn wide_nul(s: &str) -> Vec<u16> {
    s.encode_utf16().chain(std::iter::once(0)).collect()
}

/// The text of a UTF-16 buffer up to its first NUL (or its end), lossily decoded.
pub fn from_wide_until_nul(buf: &[u16]) -> String {
    let end = buf.iter().position(|&u| u == 0).unwrap_or(buf.len());
    String::from_utf16_lossy(&buf[..end])
}

/// A double-NUL-terminated UTF-16 list (as `SHFileOperationW` and `REG_MULTI_SZ` use) of `items`.
///
/// # Errors
///
/// The first item that contains a NUL, which would cut the list short.
pub fn wide_multi(items: &[String]) -> Result<Vec<u16>, String> {
    let mut out = Vec::new();
    for item in items {
        if item.contains('\0') {
            return Err(format!("{item:?} contains a NUL character"));
        }
        out.extend(item.encode_utf16());
        out.push(0);
    }
    out.push(0);
    if items.is_empty() {
        out.push(0);
    }
    Ok(out)
}

/// Splits a `REG_MULTI_SZ` buffer into its strings (empty strings inside are kept;
/// the final terminator is not a string).
pub fn split_multi(buf: &[u16]) -> Vec<String> {
    let mut items: Vec<String> = buf.split(|&u| u == 0).map(String::from_utf16_lossy).collect();
    // The list ends with two NULs: drop the empty pieces they leave after the last string.
    while items.last().is_some_and(String::is_empty) {
        items.pop();
    }
    items
}

/// Bytes captured from one output stream, keeping at most `cap` of them.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct CappedBuffer {
    pub bytes: Vec<u8>,
    cap: usize,
    /// Whether anything was dropped.
    pub truncated: bool,
}

impl CappedBuffer {
    pub fn new(cap: u64) -> CappedBuffer {
        CappedBuffer { bytes: Vec::new(), cap: usize::try_from(cap).unwrap_or(usize::MAX), truncated: false }
    }

    /// Appends what still fits and remembers whether something did not.
    pub fn push(&mut self, chunk: &[u8]) {
        let room = self.cap.saturating_sub(self.bytes.len());
        if chunk.len() > room {
            self.truncated = true;
        }
        self.bytes.extend_from_slice(&chunk[..chunk.len().min(room)]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(input: &str, expected: &str) {
        assert_eq!(fold_newlines(input), expected, "folding {input:?}");
    }

    #[test]
    fn newlines_fold_like_python_text_mode() {
        check("hi\r\n", "hi\n");
        check("a\rb\r\nc\n", "a\nb\nc\n");
        check("\r\r\n", "\n\n");
        check("no newline", "no newline");
        check("trailing\r", "trailing\n");
        check("é\r\nü", "é\nü");
    }

    #[test]
    fn wide_strings_round_trip() {
        let w = wide_nul("C:\\Ünï");
        assert_eq!(w.last(), Some(&0));
        assert_eq!(from_wide_until_nul(&w), "C:\\Ünï");
        assert_eq!(from_wide_until_nul(&[0x41, 0, 0x42]), "A");
        assert_eq!(from_wide_until_nul(&[0x41, 0x42]), "AB");
    }

    #[test]
    fn multi_strings_round_trip() {
        let items = vec!["one".to_owned(), "two".to_owned()];
        let buf = wide_multi(&items).unwrap();
        assert_eq!(buf.iter().filter(|&&u| u == 0).count(), 3);
        assert_eq!(split_multi(&buf), items);
        assert_eq!(wide_multi(&[]).unwrap(), vec![0, 0]);
        assert!(split_multi(&[0, 0]).is_empty());
        assert!(wide_multi(&["a\0b".to_owned()]).is_err());
    }

    #[test]
    fn capped_buffer_keeps_the_head_and_flags_the_rest() {
        let mut buf = CappedBuffer::new(5);
        buf.push(b"abc");
        assert!(!buf.truncated);
        buf.push(b"defg");
        assert_eq!(buf.bytes, b"abcde");
        assert!(buf.truncated);
        buf.push(b"");
        assert_eq!(buf.bytes.len(), 5);
    }
}
