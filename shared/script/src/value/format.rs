//! Python's string formatting: the format-spec mini-language (`format(x, spec)`,
//! f-string `{x:.2f}`), printf-style `%` formatting and `str.format`.
//!
//! Integers, floats, bools and strings take every spec CPython gives them
//! (fill, alignment, sign, `#`, zero padding, width, `,`/`_` grouping,
//! precision and the `d x X o b c e E f F g G % n s` types); other values accept
//! only an empty spec, as `object.__format__` does.

use super::{float_repr, Value};
use crate::error::{not_supported, type_error, value_error, ErrorKind, ScriptError};

/// A parsed format spec.
#[derive(Debug, Default)]
struct Spec {
    fill: Option<char>,
    align: Option<char>,
    sign: Option<char>,
    alternate: bool,
    zero: bool,
    width: usize,
    grouping: Option<char>,
    precision: Option<usize>,
    kind: Option<char>,
}

fn parse_spec(spec: &str) -> Result<Spec, ScriptError> {
    let chars: Vec<char> = spec.chars().collect();
    let mut s = Spec::default();
    let mut i = 0;
    let is_align = |c: char| matches!(c, '<' | '>' | '=' | '^');
    if chars.len() >= 2 && is_align(chars[1]) {
        s.fill = Some(chars[0]);
        s.align = Some(chars[1]);
        i = 2;
    } else if chars.first().copied().is_some_and(is_align) {
        s.align = Some(chars[0]);
        i = 1;
    }
    if let Some(c @ ('+' | '-' | ' ')) = chars.get(i).copied() {
        s.sign = Some(c);
        i += 1;
    }
    if chars.get(i) == Some(&'#') {
        s.alternate = true;
        i += 1;
    }
    if chars.get(i) == Some(&'0') {
        s.zero = true;
        i += 1;
    }
    let digits = |i: &mut usize| -> Result<Option<usize>, ScriptError> {
        let start = *i;
        while chars.get(*i).is_some_and(char::is_ascii_digit) {
            *i += 1;
        }
        if *i == start {
            return Ok(None);
        }
        let text: String = chars[start..*i].iter().collect();
        text.parse::<usize>()
            .ok()
            .filter(|n| *n <= 10_000)
            .map(Some)
            .ok_or_else(|| value_error("Too many decimal digits in format string"))
    };
    s.width = digits(&mut i)?.unwrap_or(0);
    if let Some(c @ (',' | '_')) = chars.get(i).copied() {
        s.grouping = Some(c);
        i += 1;
    }
    if chars.get(i) == Some(&'.') {
        i += 1;
        s.precision = Some(digits(&mut i)?.ok_or_else(|| value_error("Format specifier missing precision"))?);
    }
    if let Some(c) = chars.get(i) {
        s.kind = Some(*c);
        i += 1;
    }
    if i != chars.len() {
        return Err(value_error("Invalid format specifier"));
    }
    Ok(s)
}

/// `format(value, spec)`.
pub(crate) fn format_value(value: &Value, spec: &str) -> Result<String, ScriptError> {
    if spec.is_empty() {
        return Ok(value.to_str());
    }
    let s = parse_spec(spec)?;
    match value {
        Value::Str(text) => format_str(text, &s, "str"),
        Value::Bool(_) | Value::Int(_) => {
            let i = match value {
                Value::Bool(b) => i64::from(*b),
                Value::Int(i) => *i,
                _ => 0,
            };
            match s.kind {
                None | Some('d' | 'n' | 'x' | 'X' | 'o' | 'b' | 'c') => format_int(i, &s),
                // Precision loss above 2**53 matches Python's int-to-float conversion.
                Some('e' | 'E' | 'f' | 'F' | 'g' | 'G' | '%') => format_float(i as f64, &s),
                Some(k) => Err(unknown_code(k, value.type_name())),
            }
        }
        Value::Float(f) => match s.kind {
            None | Some('e' | 'E' | 'f' | 'F' | 'g' | 'G' | '%' | 'n') => format_float(*f, &s),
            Some(k) => Err(unknown_code(k, "float")),
        },
        other => Err(type_error(format!("unsupported format string passed to {}.__format__", other.type_name()))),
    }
}

fn unknown_code(code: char, type_name: &str) -> ScriptError {
    value_error(format!("Unknown format code '{code}' for object of type '{type_name}'"))
}

fn format_str(text: &str, s: &Spec, type_name: &str) -> Result<String, ScriptError> {
    if let Some(k) = s.kind.filter(|k| *k != 's') {
        return Err(unknown_code(k, type_name));
    }
    if s.sign.is_some() {
        return Err(value_error("Sign not allowed in string format specifier"));
    }
    if s.align == Some('=') {
        return Err(value_error("'=' alignment not allowed in string format specifier"));
    }
    let body: String = match s.precision {
        Some(p) => text.chars().take(p).collect(),
        None => text.to_owned(),
    };
    Ok(pad("", &body, s, '<'))
}

/// Pads `sign` + `body` to the spec's width with its fill and alignment.
fn pad(sign: &str, body: &str, s: &Spec, default_align: char) -> String {
    let len = sign.chars().count() + body.chars().count();
    let (fill, align) = match (s.fill, s.align, s.zero) {
        (Some(f), Some(a), _) => (f, a),
        (None, Some(a), true) => ('0', a),
        (None, Some(a), false) => (' ', a),
        (_, None, true) if default_align == '>' => ('0', '='),
        (_, None, _) => (' ', default_align),
    };
    if len >= s.width {
        return format!("{sign}{body}");
    }
    let extra = s.width - len;
    let fills = |n: usize| fill.to_string().repeat(n);
    match align {
        '<' => format!("{sign}{body}{}", fills(extra)),
        '^' => format!("{}{sign}{body}{}", fills(extra / 2), fills(extra - extra / 2)),
        '=' => format!("{sign}{}{body}", fills(extra)),
        _ => format!("{}{sign}{body}", fills(extra)),
    }
}

fn sign_of(negative: bool, s: &Spec) -> &'static str {
    match (negative, s.sign) {
        (true, _) => "-",
        (false, Some('+')) => "+",
        (false, Some(' ')) => " ",
        _ => "",
    }
}

/// Inserts `sep` every three digits of the integer part of `digits`.
fn group(digits: &str, sep: Option<char>, every: usize) -> String {
    let Some(sep) = sep else { return digits.to_owned() };
    let (int_part, rest) = match digits.find(|c: char| !c.is_ascii_alphanumeric()) {
        Some(i) => digits.split_at(i),
        None => (digits, ""),
    };
    let mut out = String::new();
    let n = int_part.len();
    for (i, c) in int_part.chars().enumerate() {
        if i > 0 && (n - i) % every == 0 {
            out.push(sep);
        }
        out.push(c);
    }
    out.push_str(rest);
    out
}

fn format_int(i: i64, s: &Spec) -> Result<String, ScriptError> {
    if s.precision.is_some() {
        return Err(value_error("Precision not allowed in integer format specifier"));
    }
    let magnitude = i.unsigned_abs();
    let (digits, prefix, every) = match s.kind {
        Some('x') => (format!("{magnitude:x}"), "0x", 4),
        Some('X') => (format!("{magnitude:X}"), "0X", 4),
        Some('o') => (format!("{magnitude:o}"), "0o", 4),
        Some('b') => (format!("{magnitude:b}"), "0b", 4),
        Some('c') => {
            let c = u32::try_from(i)
                .ok()
                .and_then(char::from_u32)
                .ok_or_else(|| ScriptError::new(ErrorKind::Overflow, "%c arg not in range(0x110000)"))?;
            return Ok(pad("", &c.to_string(), s, '<'));
        }
        _ => (magnitude.to_string(), "", 3),
    };
    let digits = group(&digits, s.grouping, every);
    let sign = format!("{}{}", sign_of(i < 0, s), if s.alternate { prefix } else { "" });
    Ok(pad(&sign, &digits, s, '>'))
}

/// `{:.{precision}e}` with Python's exponent form (`e+05`).
fn sci(f: f64, precision: usize, upper: bool) -> String {
    let text = format!("{f:.precision$e}");
    let (mantissa, exp) = text.split_once('e').unwrap_or((&text, "0"));
    let exp: i32 = exp.parse().unwrap_or(0);
    let e = if upper { 'E' } else { 'e' };
    format!("{mantissa}{e}{}{:02}", if exp < 0 { '-' } else { '+' }, exp.abs())
}

fn strip_zeros(text: &str) -> String {
    let (mantissa, exp) = match text.find(['e', 'E']) {
        Some(i) => text.split_at(i),
        None => (text, ""),
    };
    let mantissa = if mantissa.contains('.') { mantissa.trim_end_matches('0').trim_end_matches('.') } else { mantissa };
    format!("{mantissa}{exp}")
}

/// `'g'` formatting of a finite, non-negative `f` with `p` significant digits.
fn general(f: f64, p: usize, alternate: bool, upper: bool) -> String {
    let p = p.max(1);
    let exp = if f == 0.0 {
        0
    } else {
        let text = format!("{f:.prec$e}", prec = p - 1);
        text.split_once('e').and_then(|(_, e)| e.parse::<i64>().ok()).unwrap_or(0)
    };
    let p_i = i64::try_from(p).unwrap_or(i64::MAX);
    let text = if -4 <= exp && exp < p_i {
        let decimals = usize::try_from(p_i - 1 - exp).unwrap_or(0);
        format!("{f:.decimals$}")
    } else {
        sci(f, p - 1, upper)
    };
    if alternate {
        text
    } else {
        strip_zeros(&text)
    }
}

fn format_float(f: f64, s: &Spec) -> Result<String, ScriptError> {
    let negative = f.is_sign_negative() && !(f.is_nan());
    let a = f.abs();
    let upper = matches!(s.kind, Some('E' | 'F' | 'G'));
    let body = if !a.is_finite() {
        let t = if a.is_nan() { "nan" } else { "inf" };
        let t = if upper { t.to_uppercase() } else { t.to_owned() };
        if s.kind == Some('%') {
            format!("{t}%")
        } else {
            t
        }
    } else {
        match s.kind {
            Some('f' | 'F') => format!("{a:.prec$}", prec = s.precision.unwrap_or(6)),
            Some('e' | 'E') => sci(a, s.precision.unwrap_or(6), upper),
            Some('%') => format!("{:.prec$}%", a * 100.0, prec = s.precision.unwrap_or(6)),
            Some('g' | 'G' | 'n') => general(a, s.precision.unwrap_or(6), s.alternate, upper),
            _ => match s.precision {
                None => float_repr(a),
                Some(p) => {
                    let text = general(a, p, s.alternate, false);
                    if text.contains(['.', 'e', 'n', 'i']) {
                        text
                    } else {
                        format!("{text}.0")
                    }
                }
            },
        }
    };
    let body = if s.alternate && !body.contains('.') && a.is_finite() && matches!(s.kind, Some('f' | 'F' | '%')) {
        body.replacen('%', ".%", 1)
    } else {
        body
    };
    let body = if a.is_finite() { group(&body, s.grouping, 3) } else { body };
    Ok(pad(sign_of(negative, s), &body, s, '>'))
}

/// `text % args`: printf-style formatting.
pub(crate) fn percent(text: &str, args: &Value) -> Result<String, ScriptError> {
    let items: Vec<Value> = match args {
        Value::Tuple(items) => items.to_vec(),
        other => vec![other.clone()],
    };
    let mut next = items.iter();
    let mut out = String::new();
    let mut chars = text.chars().peekable();
    while let Some(c) = chars.next() {
        if c != '%' {
            out.push(c);
            continue;
        }
        if chars.peek() == Some(&'(') {
            return Err(not_supported("printf-style formatting with mapping keys (`%(name)s`) is not supported"));
        }
        let mut spec = Spec::default();
        while let Some(f @ ('-' | '+' | ' ' | '0' | '#')) = chars.peek().copied() {
            match f {
                '-' => spec.align = Some('<'),
                '+' | ' ' => {
                    if spec.sign != Some('+') {
                        spec.sign = Some(f);
                    }
                }
                '0' => spec.zero = true,
                _ => spec.alternate = true,
            }
            chars.next();
        }
        let mut number = |chars: &mut std::iter::Peekable<std::str::Chars<'_>>| -> Result<Option<usize>, ScriptError> {
            if chars.peek() == Some(&'*') {
                chars.next();
                let v = next.next().ok_or_else(|| type_error("not enough arguments for format string"))?;
                return match v {
                    Value::Int(i) => Ok(Some(usize::try_from(*i).unwrap_or(0))),
                    _ => Err(type_error("* wants int")),
                };
            }
            let mut digits = String::new();
            while let Some(d) = chars.peek().copied().filter(char::is_ascii_digit) {
                digits.push(d);
                chars.next();
            }
            if digits.is_empty() {
                return Ok(None);
            }
            digits.parse::<usize>().ok().filter(|n| *n <= 10_000).map(Some).ok_or_else(|| value_error("width too big"))
        };
        spec.width = number(&mut chars)?.unwrap_or(0);
        if chars.peek() == Some(&'.') {
            chars.next();
            spec.precision = Some(number(&mut chars)?.unwrap_or(0));
        }
        let Some(kind) = chars.next() else {
            return Err(value_error("incomplete format"));
        };
        if spec.align == Some('<') {
            spec.zero = false;
        }
        if kind == '%' {
            out.push('%');
            continue;
        }
        let arg = next.next().ok_or_else(|| type_error("not enough arguments for format string"))?;
        let piece = match kind {
            's' | 'r' | 'a' => {
                let text = if kind == 's' { arg.to_str() } else { arg.repr() };
                spec.zero = false;
                let align = Some(spec.align.unwrap_or('>'));
                format_str(&text, &Spec { sign: None, align, ..spec }, "str")?
            }
            'd' | 'i' | 'u' | 'x' | 'X' | 'o' | 'c' => {
                let i = match arg {
                    Value::Bool(b) => i64::from(*b),
                    Value::Int(i) => *i,
                    Value::Float(f) if kind != 'c' && f.is_finite() => f.trunc() as i64,
                    other => {
                        let what = if matches!(kind, 'x' | 'X' | 'o') { "an integer" } else { "a real number" };
                        return Err(type_error(format!(
                            "%{kind} format: {what} is required, not {}",
                            other.type_name()
                        )));
                    }
                };
                let precision = spec.precision.take();
                spec.kind = Some(match kind {
                    'd' | 'i' | 'u' => 'd',
                    k => k,
                });
                let mut text = format_int(i, &spec)?;
                if let Some(p) = precision {
                    let digits = text.trim_start_matches('-');
                    if digits.len() < p {
                        let zeros = "0".repeat(p - digits.len());
                        text = if i < 0 { format!("-{zeros}{digits}") } else { format!("{zeros}{text}") };
                    }
                }
                text
            }
            'f' | 'F' | 'e' | 'E' | 'g' | 'G' => {
                let f = match arg {
                    Value::Bool(b) => f64::from(u8::from(*b)),
                    // Precision loss above 2**53 matches Python's int-to-float conversion.
                    Value::Int(i) => *i as f64,
                    Value::Float(f) => *f,
                    other => return Err(type_error(format!("must be real number, not {}", other.type_name()))),
                };
                spec.kind = Some(kind);
                spec.precision = Some(spec.precision.unwrap_or(6));
                format_float(f, &spec)?
            }
            other => {
                return Err(value_error(format!("unsupported format character '{other}' (0x{:x})", u32::from(other))))
            }
        };
        out.push_str(&piece);
    }
    if next.next().is_some() {
        return Err(type_error("not all arguments converted during string formatting"));
    }
    Ok(out)
}

/// `text.format(*pos, **kw)`.
pub(crate) fn str_format(text: &str, pos: &[Value], kw: &[(String, Value)]) -> Result<String, ScriptError> {
    let mut auto = 0_usize;
    format_fields(text, pos, kw, &mut auto, 0)
}

fn format_fields(
    text: &str,
    pos: &[Value],
    kw: &[(String, Value)],
    auto: &mut usize,
    depth: usize,
) -> Result<String, ScriptError> {
    if depth > 2 {
        return Err(value_error("Max string recursion exceeded"));
    }
    let mut out = String::new();
    let mut chars = text.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            '{' if chars.peek() == Some(&'{') => {
                chars.next();
                out.push('{');
            }
            '}' if chars.peek() == Some(&'}') => {
                chars.next();
                out.push('}');
            }
            '}' => return Err(value_error("Single '}' encountered in format string")),
            '{' => {
                let mut field = String::new();
                let mut nesting = 0;
                loop {
                    match chars.next() {
                        None => return Err(value_error("expected '}' before end of string")),
                        Some('{') => {
                            nesting += 1;
                            field.push('{');
                        }
                        Some('}') if nesting > 0 => {
                            nesting -= 1;
                            field.push('}');
                        }
                        Some('}') => break,
                        Some(ch) => field.push(ch),
                    }
                }
                let (name_conv, spec) = match field.find(':') {
                    Some(i) => (&field[..i], &field[i + 1..]),
                    None => (field.as_str(), ""),
                };
                let (name, conversion) = match name_conv.find('!') {
                    Some(i) => (&name_conv[..i], Some(&name_conv[i + 1..])),
                    None => (name_conv, None),
                };
                let value = field_value(name, pos, kw, auto)?;
                let value = match conversion {
                    None => value,
                    Some("r" | "a") => Value::str(value.repr()),
                    Some("s") => Value::str(value.to_str()),
                    Some(_) => return Err(value_error("Unknown conversion specifier")),
                };
                let spec =
                    if spec.contains('{') { format_fields(spec, pos, kw, auto, depth + 1)? } else { spec.to_owned() };
                out.push_str(&format_value(&value, &spec)?);
            }
            other => out.push(other),
        }
    }
    Ok(out)
}

fn field_value(name: &str, pos: &[Value], kw: &[(String, Value)], auto: &mut usize) -> Result<Value, ScriptError> {
    let (head, index) = match name.find('[') {
        Some(i) => (&name[..i], Some(&name[i..])),
        None => (name, None),
    };
    if head.contains('.') {
        return Err(not_supported("attribute access in str.format fields is not supported"));
    }
    let mut value = if head.is_empty() {
        let v = pos.get(*auto).cloned().ok_or_else(|| {
            ScriptError::new(
                ErrorKind::Index,
                format!("Replacement index {} out of range for positional args tuple", *auto),
            )
        })?;
        *auto += 1;
        v
    } else if let Ok(i) = head.parse::<usize>() {
        pos.get(i).cloned().ok_or_else(|| {
            ScriptError::new(ErrorKind::Index, format!("Replacement index {i} out of range for positional args tuple"))
        })?
    } else {
        kw.iter()
            .find(|(k, _)| k == head)
            .map(|(_, v)| v.clone())
            .ok_or_else(|| ScriptError::new(ErrorKind::Key, super::str_repr(head)))?
    };
    let mut rest = index.unwrap_or("");
    while let Some(stripped) = rest.strip_prefix('[') {
        let Some(end) = stripped.find(']') else {
            return Err(value_error("Missing ']' in format string"));
        };
        let key = &stripped[..end];
        rest = &stripped[end + 1..];
        value = match (&value, key.parse::<usize>()) {
            (Value::List(items) | Value::Tuple(items), Ok(i)) => {
                items.get(i).cloned().ok_or_else(|| ScriptError::new(ErrorKind::Index, "list index out of range"))?
            }
            // A str key equals only a str of the same text, so this is the dict's own lookup.
            (Value::Dict(entries), _) => entries
                .iter()
                .find_map(|(k, v)| matches!(&k.0, Value::Str(s) if s.as_str() == key).then(|| v.clone()))
                .ok_or_else(|| ScriptError::new(ErrorKind::Key, super::str_repr(key)))?,
            (other, _) => return Err(type_error(format!("'{}' object is not subscriptable", other.type_name()))),
        };
    }
    if !rest.is_empty() {
        return Err(value_error("Only '.' or '[' may follow ']' in format field specifier"));
    }
    Ok(value)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specs_format_like_python() {
        let check = |v: Value, spec: &str, expected: &str| {
            assert_eq!(format_value(&v, spec).unwrap(), expected, "{v:?} {spec}");
        };
        check(Value::Float(2.34567), ".2f", "2.35");
        check(Value::Float(2.5), ".0f", "2");
        check(Value::Float(1234567.891), ",.2f", "1,234,567.89");
        check(Value::Float(0.256), ".1%", "25.6%");
        check(Value::Float(12345.678), ".3e", "1.235e+04");
        check(Value::Float(0.0001234), "g", "0.0001234");
        check(Value::Float(1234567.0), "g", "1.23457e+06");
        check(Value::Float(1.0), ".3", "1.0");
        check(Value::Float(-1.5), "+08.2f", "-0001.50");
        check(Value::Int(42), "05d", "00042");
        check(Value::Int(255), "#x", "0xff");
        check(Value::Int(1234567), ",", "1,234,567");
        check(Value::Int(7), ">4", "   7");
        check(Value::Int(7), "*^5", "**7**");
        check(Value::str("ab"), "<4", "ab  ");
        check(Value::str("abcdef"), ".3", "abc");
        check(Value::Int(3), ".2f", "3.00");
    }

    #[test]
    fn percent_and_format_like_python() {
        let tuple = Value::tuple(vec![Value::str("a"), Value::Int(5), Value::Float(2.0 / 3.0)]);
        assert_eq!(percent("%s=%03d (%.2f) 100%%", &tuple).unwrap(), "a=005 (0.67) 100%");
        assert_eq!(percent("%-4s|%r", &Value::tuple(vec![Value::Int(1), Value::str("x")])).unwrap(), "1   |'x'");
        assert_eq!(percent("%d items", &Value::Int(3)).unwrap(), "3 items");
        assert!(percent("%s %s", &Value::Int(3)).is_err());
        let pos = [Value::Int(1), Value::str("b")];
        let kw = [("n".to_owned(), Value::Float(0.5))];
        assert_eq!(str_format("{} {}|{0}{1!r}|{n:.1f}|{{x}}", &pos, &kw).unwrap(), "1 b|1'b'|0.5|{x}");
    }
}
