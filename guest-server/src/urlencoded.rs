//! `application/x-www-form-urlencoded` decoding: `+` is a space, `%XX` a byte, and a
//! `%` not followed by two hex digits is itself. The WAA layer's form bodies
//! (Werkzeug decodes them this way, then as lossy UTF-8) and the native query
//! strings' UTF-8 check (which refuses instead) both decode with [`decode`].

/// The bytes a form-encoded name or value stands for.
pub fn decode(raw: &str) -> Vec<u8> {
    decode_bytes(raw.as_bytes())
}

/// [`decode`] of raw bytes (a request body).
pub fn decode_bytes(raw: &[u8]) -> Vec<u8> {
    let hex = |b: u8| (b as char).to_digit(16);
    let mut out = Vec::with_capacity(raw.len());
    let mut i = 0;
    while i < raw.len() {
        match raw[i] {
            b'+' => out.push(b' '),
            b'%' => match (raw.get(i + 1).copied().and_then(hex), raw.get(i + 2).copied().and_then(hex)) {
                (Some(hi), Some(lo)) => {
                    out.push((hi * 16 + lo) as u8);
                    i += 2;
                }
                _ => out.push(b'%'),
            },
            b => out.push(b),
        }
        i += 1;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decodes_like_werkzeug() {
        let check = |raw: &str, expected: &[u8]| assert_eq!(decode(raw), expected, "{raw:?}");
        check("a+b%20c", b"a b c");
        check("%C3%A9", "é".as_bytes());
        check("%ff", &[0xff]);
        check("100%", b"100%");
        check("%zz%4", b"%zz%4");
    }
}
