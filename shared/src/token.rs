//! Bearer tokens as both sides read them from a token file or an option: the one
//! rule, so a token the guest accepts is the token the host sends; and the one check
//! of a request's `Authorization` header against the token, which every server of the
//! project (the guest's routes and its MCP endpoint, the host's MCP endpoint) uses.
//!
//! A token file holds the token on its first line; a UTF-8 byte-order mark (which
//! Windows editors and PowerShell's `Out-File` write) and surrounding white space are
//! not part of it. A token is printable ASCII without spaces, since it travels in an
//! HTTP header: anything else could never match and would lock every client out.

/// Why a token cannot be used.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum TokenError {
    #[error("the token is empty")]
    Empty,
    #[error(
        "the token has a character that cannot travel in an HTTP header ({0:?} at position {1}); use printable ASCII"
    )]
    BadCharacter(char, usize),
}

/// The token in a token file's text, or given as an option.
///
/// # Errors
///
/// The first line is empty, or holds a character other than printable ASCII.
pub fn parse(text: &str) -> Result<String, TokenError> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let token = text.lines().next().unwrap_or("").trim();
    if token.is_empty() {
        return Err(TokenError::Empty);
    }
    if let Some((i, c)) = token.chars().enumerate().find(|(_, c)| !c.is_ascii_graphic()) {
        return Err(TokenError::BadCharacter(c, i));
    }
    Ok(token.to_owned())
}

/// Whether an `Authorization` header's value (`None`: no header) carries `token` as
/// bearer credentials: `Bearer` (the scheme compares without regard to case, RFC 7235
/// section 2.1), one or more spaces, then the token (RFC 6750 section 2.1), with
/// surrounding white space ignored. The token is compared in constant time, so how
/// long a wrong token takes to refuse says nothing of how much of it was right.
pub fn bearer_matches(authorization: Option<&[u8]>, token: &str) -> bool {
    use subtle::ConstantTimeEq as _;
    let Some(value) = authorization else { return false };
    let value = value.trim_ascii();
    let scheme = b"bearer";
    if value.len() <= scheme.len() || !value[..scheme.len()].eq_ignore_ascii_case(scheme) {
        return false;
    }
    let rest = &value[scheme.len()..];
    if rest.first() != Some(&b' ') {
        return false;
    }
    let given = rest.trim_ascii_start();
    !token.is_empty() && bool::from(given.ct_eq(token.as_bytes()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tokens_are_read_as_written_by_any_editor() {
        let check = |text: &str, expected: Result<&str, TokenError>| {
            assert_eq!(parse(text), expected.map(str::to_owned), "{text:?}");
        };
        check("0123456789abcdef\n", Ok("0123456789abcdef"));
        check("\u{feff}0123456789abcdef\r\n", Ok("0123456789abcdef"));
        check("  0123456789abcdef  \nsecond line", Ok("0123456789abcdef"));
        check("\n0123456789abcdef", Err(TokenError::Empty));
        check("", Err(TokenError::Empty));
        check("0123456789abcdéf", Err(TokenError::BadCharacter('é', 14)));
        check("0123 456789abcdef", Err(TokenError::BadCharacter(' ', 4)));
    }

    #[test]
    fn bearer_credentials_are_checked_as_rfc_6750_writes_them() {
        let token = "0123456789abcdef0123";
        let check = |header: Option<&str>| bearer_matches(header.map(str::as_bytes), token);
        assert!(check(Some("Bearer 0123456789abcdef0123")));
        // The scheme is case-insensitive; spaces between it and the token, and around, are allowed.
        assert!(check(Some("bearer 0123456789abcdef0123")));
        assert!(check(Some("BEARER 0123456789abcdef0123")));
        assert!(check(Some("bEaReR   0123456789abcdef0123 ")));
        // A missing header, a wrong token of the same length, another scheme, no space, no token.
        assert!(!check(None));
        assert!(!check(Some("Bearer 0123456789abcdef0124")));
        assert!(!check(Some("Bearer 1123456789abcdef0123")));
        assert!(!check(Some("Bearer 0123456789abcdef012")));
        assert!(!check(Some("Bearer 0123456789abcdef01234")));
        assert!(!check(Some("Basic 0123456789abcdef0123")));
        assert!(!check(Some("Bearer0123456789abcdef0123")));
        assert!(!check(Some("Bearer ")));
        assert!(!check(Some("Bearer")));
        assert!(!check(Some("")));
        assert!(!check(Some("0123456789abcdef0123")));
        // Bytes that are not UTF-8 are just a wrong token; an empty token matches nothing.
        assert!(!bearer_matches(Some(b"Bearer \xff\xfe"), token));
        assert!(!bearer_matches(Some(b"Bearer "), ""));
    }
}
