//! Bearer tokens as both sides read them from a token file or an option: the one
//! rule, so a token the guest accepts is the token the host sends.
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
}
