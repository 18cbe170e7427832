//! Turns Python source into tokens.
//!
//! It handles what the parser needs and rejects the rest precisely: names,
//! integer and float literals, every string literal form except f-strings and
//! bytes, operators, comments, implicit line joining inside brackets and
//! explicit joining with a trailing backslash.
//! It never panics and every loop consumes input; the first problem becomes a
//! [`Tok::Error`] token so that errors surface in source order.

use super::error::ParseError;

/// A token kind.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Tok {
    Name(String),
    Int(i64),
    Float(f64),
    /// One string literal, escapes already decoded.
    Str(String),
    Op(&'static str),
    /// The end of a logical line.
    Newline,
    Eof,
    /// Lexing stopped here.
    Error(ParseError),
}

/// A token and where it starts (1-based line and column).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Token {
    pub(crate) tok: Tok,
    pub(crate) line: usize,
    pub(crate) column: usize,
}

/// Operators, longest first so that the first match is the longest one.
const OPERATORS: &[&str] = &[
    "**=", "//=", ">>=", "<<=", "...", "->", ":=", "**", "//", "==", "!=", "<=", ">=", "<<", ">>", "+=", "-=", "*=",
    "/=", "%=", "&=", "|=", "^=", "@=", "+", "-", "*", "/", "%", "@", "&", "|", "^", "~", "<", ">", "(", ")", "[", "]",
    "{", "}", ",", ":", ".", ";", "=",
];

struct Lexer {
    chars: Vec<char>,
    pos: usize,
    line: usize,
    column: usize,
    /// Open brackets with their positions, innermost last.
    brackets: Vec<(char, usize, usize)>,
    tokens: Vec<Token>,
}

/// Tokenizes `src`. The result always ends with [`Tok::Eof`] or [`Tok::Error`].
pub(crate) fn tokenize(src: &str) -> Vec<Token> {
    // Python reads source with universal newlines, so `\r\n` and `\r` are `\n`
    // everywhere, including inside string literals.
    let normalized = src.replace("\r\n", "\n").replace('\r', "\n");
    let mut lexer = Lexer {
        chars: normalized.chars().collect(),
        pos: 0,
        line: 1,
        column: 1,
        brackets: Vec::new(),
        tokens: Vec::new(),
    };
    if let Err(err) = lexer.run() {
        let (line, column) = (err.line, err.column);
        lexer.tokens.push(Token { tok: Tok::Error(err), line, column });
    }
    lexer.tokens
}

impl Lexer {
    fn peek(&self) -> Option<char> {
        self.chars.get(self.pos).copied()
    }

    fn peek_at(&self, ahead: usize) -> Option<char> {
        self.chars.get(self.pos + ahead).copied()
    }

    fn bump(&mut self) -> Option<char> {
        let c = self.peek()?;
        self.pos += 1;
        if c == '\n' {
            self.line += 1;
            self.column = 1;
        } else {
            self.column += 1;
        }
        Some(c)
    }

    fn push(&mut self, tok: Tok, line: usize, column: usize) {
        self.tokens.push(Token { tok, line, column });
    }

    fn error(&self, message: impl Into<String>) -> ParseError {
        ParseError::new(self.line, self.column, message)
    }

    fn last_is_newline_or_start(&self) -> bool {
        matches!(self.tokens.last(), None | Some(Token { tok: Tok::Newline, .. }))
    }

    fn run(&mut self) -> Result<(), ParseError> {
        let mut at_line_start = true;
        loop {
            if at_line_start && self.brackets.is_empty() {
                at_line_start = false;
                self.check_indentation()?;
            }
            let Some(c) = self.peek() else {
                if let Some(&(open, line, column)) = self.brackets.last() {
                    return Err(ParseError::new(line, column, format!("'{open}' was never closed")));
                }
                if !self.last_is_newline_or_start() {
                    self.push(Tok::Newline, self.line, self.column);
                }
                self.push(Tok::Eof, self.line, self.column);
                return Ok(());
            };
            let (line, column) = (self.line, self.column);
            match c {
                ' ' | '\t' | '\x0c' => {
                    self.bump();
                }
                '#' => {
                    while self.peek().is_some_and(|c| c != '\n') {
                        self.bump();
                    }
                }
                '\n' => {
                    self.bump();
                    if self.brackets.is_empty() {
                        if !self.last_is_newline_or_start() {
                            self.push(Tok::Newline, line, column);
                        }
                        at_line_start = true;
                    }
                }
                '\\' => {
                    self.bump();
                    match self.peek() {
                        Some('\n') => {
                            self.bump();
                        }
                        None => return Err(self.error("unexpected end of input after line continuation character")),
                        Some(_) => return Err(self.error("unexpected character after line continuation character")),
                    }
                }
                '\'' | '"' => {
                    let s = self.string(false, line, column)?;
                    self.push(Tok::Str(s), line, column);
                }
                c if c.is_ascii_digit() || (c == '.' && self.peek_at(1).is_some_and(|d| d.is_ascii_digit())) => {
                    let tok = self.number()?;
                    self.push(tok, line, column);
                }
                c if c.is_alphabetic() || c == '_' => {
                    let mut name = String::new();
                    while let Some(c) = self.peek().filter(|c| c.is_alphanumeric() || *c == '_') {
                        name.push(c);
                        self.bump();
                    }
                    if matches!(self.peek(), Some('\'' | '"')) && is_string_prefix(&name) {
                        let lower = name.to_ascii_lowercase();
                        if lower.contains('f') {
                            return Err(ParseError::new(line, column, "f-strings are not supported"));
                        }
                        if lower.contains('b') {
                            return Err(ParseError::new(line, column, "bytes literals (b'...') are not supported"));
                        }
                        let s = self.string(lower.contains('r'), line, column)?;
                        self.push(Tok::Str(s), line, column);
                    } else {
                        self.push(Tok::Name(name), line, column);
                    }
                }
                _ => {
                    let op = OPERATORS
                        .iter()
                        .copied()
                        .find(|op| op.chars().enumerate().all(|(i, oc)| self.peek_at(i) == Some(oc)));
                    let Some(op) = op else {
                        return Err(self.error(format!("invalid character '{c}' (U+{:04X})", c as u32)));
                    };
                    for _ in 0..op.chars().count() {
                        self.bump();
                    }
                    self.track_bracket(op, line, column)?;
                    self.push(Tok::Op(op), line, column);
                }
            }
        }
    }

    /// Rejects indentation at the start of a logical line that holds code.
    fn check_indentation(&mut self) -> Result<(), ParseError> {
        let mut indented = false;
        while let Some(' ' | '\t' | '\x0c') = self.peek() {
            self.bump();
            indented = true;
        }
        let blank = matches!(self.peek(), None | Some('\n' | '#'));
        if indented && !blank {
            return Err(self.error("unexpected indent"));
        }
        Ok(())
    }

    fn track_bracket(&mut self, op: &str, line: usize, column: usize) -> Result<(), ParseError> {
        let close = |open| match open {
            '(' => ')',
            '[' => ']',
            _ => '}',
        };
        match op {
            "(" | "[" | "{" => {
                let open = op.chars().next().unwrap_or('(');
                self.brackets.push((open, line, column));
            }
            ")" | "]" | "}" => match self.brackets.pop() {
                None => return Err(ParseError::new(line, column, format!("unmatched '{op}'"))),
                Some((open, ..)) if close(open).to_string() != op => {
                    return Err(ParseError::new(
                        line,
                        column,
                        format!("closing parenthesis '{op}' does not match opening parenthesis '{open}'"),
                    ));
                }
                Some(_) => {}
            },
            _ => {}
        }
        Ok(())
    }

    fn number(&mut self) -> Result<Tok, ParseError> {
        let (line, column) = (self.line, self.column);
        let invalid = |what: &str| ParseError::new(line, column, format!("invalid {what} literal"));
        let radix = match (self.peek(), self.peek_at(1).map(|c| c.to_ascii_lowercase())) {
            (Some('0'), Some('x')) => Some((16, "hexadecimal")),
            (Some('0'), Some('o')) => Some((8, "octal")),
            (Some('0'), Some('b')) => Some((2, "binary")),
            _ => None,
        };
        if let Some((radix, what)) = radix {
            self.bump();
            self.bump();
            // Python allows one underscore right after the prefix: `0x_ff`.
            if self.peek() == Some('_') {
                self.bump();
            }
            let digits = self.digits(|c| c.is_digit(radix)).ok_or_else(|| invalid(what))?;
            if self.peek().is_some_and(|c| c.is_alphanumeric() || c == '_') {
                return Err(invalid(what));
            }
            return i64::from_str_radix(&digits, radix).map(Tok::Int).map_err(|_| too_large(line, column));
        }
        let mut text = String::new();
        let mut is_float = false;
        if self.peek() != Some('.') {
            text = self.digits(|c| c.is_ascii_digit()).ok_or_else(|| invalid("decimal"))?;
        }
        if self.peek() == Some('.') {
            self.bump();
            is_float = true;
            text.push('.');
            if self.peek().is_some_and(|c| c.is_ascii_digit()) {
                text.push_str(&self.digits(|c| c.is_ascii_digit()).ok_or_else(|| invalid("decimal"))?);
            }
        }
        if matches!(self.peek(), Some('e' | 'E')) {
            let sign = self.peek_at(1).filter(|c| matches!(c, '+' | '-'));
            let digit_at = if sign.is_some() { 2 } else { 1 };
            if self.peek_at(digit_at).is_some_and(|c| c.is_ascii_digit()) {
                self.bump();
                text.push('e');
                if let Some(sign) = sign {
                    self.bump();
                    text.push(sign);
                }
                text.push_str(&self.digits(|c| c.is_ascii_digit()).ok_or_else(|| invalid("decimal"))?);
                is_float = true;
            }
        }
        if matches!(self.peek(), Some('j' | 'J')) {
            return Err(ParseError::new(line, column, "complex number literals are not supported"));
        }
        if self.peek().is_some_and(|c| c.is_alphanumeric() || c == '_') {
            return Err(invalid("decimal"));
        }
        if is_float {
            return text.parse::<f64>().map(Tok::Float).map_err(|_| invalid("decimal"));
        }
        if text.len() > 1 && text.starts_with('0') && text.chars().any(|c| c != '0') {
            return Err(ParseError::new(
                line,
                column,
                "leading zeros in decimal integer literals are not permitted; use an 0o prefix for octal integers",
            ));
        }
        text.parse::<i64>().map(Tok::Int).map_err(|_| too_large(line, column))
    }

    /// Reads digits with single underscores between them; `None` for a misplaced underscore.
    fn digits(&mut self, is_digit: impl Fn(char) -> bool) -> Option<String> {
        let mut out = String::new();
        let mut last_underscore = false;
        loop {
            match self.peek() {
                Some('_') if !out.is_empty() && !last_underscore => {
                    last_underscore = true;
                    self.bump();
                }
                Some(c) if is_digit(c) => {
                    out.push(c);
                    last_underscore = false;
                    self.bump();
                }
                _ => break,
            }
        }
        (!out.is_empty() && !last_underscore).then_some(out)
    }

    /// Reads a string literal whose opening quote is next, decoding escapes unless `raw`.
    fn string(&mut self, raw: bool, line: usize, column: usize) -> Result<String, ParseError> {
        let quote = self.bump().unwrap_or('"');
        let triple = self.peek() == Some(quote) && self.peek_at(1) == Some(quote);
        if triple {
            self.bump();
            self.bump();
        }
        let unterminated = |at: usize| {
            let what = if triple { "unterminated triple-quoted string literal" } else { "unterminated string literal" };
            ParseError::new(line, column, format!("{what} (detected at line {at})"))
        };
        let mut out = String::new();
        loop {
            let Some(c) = self.bump() else {
                return Err(unterminated(self.line));
            };
            match c {
                '\n' if !triple => return Err(unterminated(self.line - 1)),
                c if c == quote => {
                    if !triple {
                        return Ok(out);
                    }
                    if self.peek() == Some(quote) && self.peek_at(1) == Some(quote) {
                        self.bump();
                        self.bump();
                        return Ok(out);
                    }
                    out.push(c);
                }
                '\\' => {
                    let (esc_line, esc_column) = (self.line, self.column - 1);
                    let Some(next) = self.bump() else {
                        return Err(unterminated(self.line));
                    };
                    if raw {
                        out.push('\\');
                        out.push(next);
                    } else {
                        self.escape(next, &mut out, esc_line, esc_column)?;
                    }
                }
                c => out.push(c),
            }
        }
    }

    /// Decodes the escape sequence whose first character after the backslash is `c`.
    fn escape(&mut self, c: char, out: &mut String, line: usize, column: usize) -> Result<(), ParseError> {
        let simple = match c {
            '\n' => Some(None),
            '\\' => Some(Some('\\')),
            '\'' => Some(Some('\'')),
            '"' => Some(Some('"')),
            'a' => Some(Some('\x07')),
            'b' => Some(Some('\x08')),
            'f' => Some(Some('\x0c')),
            'n' => Some(Some('\n')),
            'r' => Some(Some('\r')),
            't' => Some(Some('\t')),
            'v' => Some(Some('\x0b')),
            _ => None,
        };
        if let Some(decoded) = simple {
            out.extend(decoded);
            return Ok(());
        }
        let err = |msg: String| ParseError::new(line, column, msg);
        match c {
            '0'..='7' => {
                let mut value = c.to_digit(8).unwrap_or(0);
                for _ in 0..2 {
                    match self.peek().and_then(|d| d.to_digit(8)) {
                        Some(d) => {
                            value = value * 8 + d;
                            self.bump();
                        }
                        None => break,
                    }
                }
                out.extend(char::from_u32(value));
            }
            'x' | 'u' | 'U' => {
                let (len, form) = match c {
                    'x' => (2, "\\xXX"),
                    'u' => (4, "\\uXXXX"),
                    _ => (8, "\\UXXXXXXXX"),
                };
                let mut value: u32 = 0;
                for _ in 0..len {
                    match self.peek().and_then(|d| d.to_digit(16)) {
                        Some(d) => {
                            value = value.saturating_mul(16).saturating_add(d);
                            self.bump();
                        }
                        None => return Err(err(format!("(unicode error) truncated {form} escape"))),
                    }
                }
                match char::from_u32(value) {
                    Some(ch) => out.push(ch),
                    None if (0xD800..0xE000).contains(&value) => {
                        return Err(err(format!("surrogate escape \\u{value:04x} is not supported")))
                    }
                    None => return Err(err(format!("(unicode error) illegal Unicode character {form} escape"))),
                }
            }
            'N' => return Err(err("\\N{...} escapes are not supported".to_owned())),
            other => {
                // Python keeps the backslash of an unknown escape (with a warning).
                out.push('\\');
                out.push(other);
            }
        }
        Ok(())
    }
}

fn too_large(line: usize, column: usize) -> ParseError {
    ParseError::new(line, column, "integer literal too large (this interpreter's integers are 64-bit)")
}

/// Whether `name` is a string prefix Python accepts (`r`, `u`, `b`, `f`, `br`, `rb`, `fr`, `rf`, any case).
fn is_string_prefix(name: &str) -> bool {
    matches!(name.to_ascii_lowercase().as_str(), "r" | "u" | "b" | "f" | "br" | "rb" | "fr" | "rf")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kinds(src: &str) -> Vec<Tok> {
        tokenize(src).into_iter().map(|t| t.tok).collect()
    }

    #[test]
    fn brackets_join_lines_and_backslash_continues() {
        assert_eq!(
            kinds("f(1,\n 2)\nx = \\\n 3"),
            vec![
                Tok::Name("f".into()),
                Tok::Op("("),
                Tok::Int(1),
                Tok::Op(","),
                Tok::Int(2),
                Tok::Op(")"),
                Tok::Newline,
                Tok::Name("x".into()),
                Tok::Op("="),
                Tok::Int(3),
                Tok::Newline,
                Tok::Eof,
            ]
        );
    }

    #[test]
    fn numbers() {
        let check = |src: &str, tok: Tok| assert_eq!(kinds(src)[0], tok, "{src}");
        check("0x_ff", Tok::Int(255));
        check("0o17", Tok::Int(15));
        check("0b101", Tok::Int(5));
        check("1_000", Tok::Int(1000));
        check("00", Tok::Int(0));
        check("1.5", Tok::Float(1.5));
        check(".5", Tok::Float(0.5));
        check("5.", Tok::Float(5.0));
        check("1e3", Tok::Float(1000.0));
        check("1E-2", Tok::Float(0.01));
        check("1_0.0_1e1_0", Tok::Float(10.01e10));
    }

    #[test]
    fn positions_count_characters() {
        let toks = tokenize("é = 'ü'\n  # c\nb");
        let pos: Vec<(usize, usize)> = toks.iter().map(|t| (t.line, t.column)).collect();
        assert_eq!(pos[..3], [(1, 1), (1, 3), (1, 5)]);
        assert_eq!(toks[4].tok, Tok::Name("b".into()));
        assert_eq!((toks[4].line, toks[4].column), (3, 1));
    }
}
