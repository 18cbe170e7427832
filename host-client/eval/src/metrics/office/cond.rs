//! Conditional formats inside a `style` rule, evaluated as upstream's
//! `load_xlsx_styles` does: only `expression` rules are evaluated (any other
//! rule type makes upstream raise `NotImplementedError`, an error here too).
//!
//! Upstream compiles `"=" + formula` with the `formulas` package and calls
//! the compiled function with the covered cell's raw value first, then one
//! list of raw values per absolute range (`$A$2:$A$9`) found in the formula
//! text. The compiled function takes its inputs sorted by their reference
//! text, so the values land on the references in that order, whichever
//! reference they were meant for; this binds them the same way. A formula
//! with an absolute single cell (`$C$1`) makes upstream fail, and so does a
//! call with the wrong number of values: both are errors here.
//!
//! The evaluator covers numbers, text, booleans, references, the comparison
//! and arithmetic operators, `&`, and `MAX`, `MIN`, `SUM`, `AVERAGE`,
//! `COUNT`, `ABS`, `AND`, `OR`, `NOT`, with the package's observed handling
//! of empty cells (`=` is false, `<>` true, anything else an error value) and
//! of error values (a truthy result: the cell counts as matching). Another
//! function is reported as an error rather than guessed.

use std::cmp::Ordering;

use crate::metrics::MetricError;

/// A value inside the formula.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum V {
    Num(f64),
    Str(String),
    Bool(bool),
    /// A cell with no value (upstream's `None`).
    Empty,
    /// An Excel error value (`#VALUE!`, `#DIV/0!`).
    Err,
    /// The values of a range, row by row.
    List(Vec<V>),
}

impl V {
    /// The raw value upstream's `read_cell_value` gives (a float, a string or `None`).
    pub(super) fn from_json(value: &serde_json::Value) -> V {
        match value {
            serde_json::Value::Number(n) => n.as_f64().map_or(V::Empty, V::Num),
            serde_json::Value::String(s) => V::Str(s.clone()),
            serde_json::Value::Bool(b) => V::Bool(*b),
            _ => V::Empty,
        }
    }

    /// Python's `bool()` of the package's result array.
    fn truthy(&self) -> bool {
        match self {
            V::Num(n) => *n != 0.0,
            V::Str(s) => !s.is_empty(),
            V::Bool(b) => *b,
            V::Empty => false,
            V::Err => true,
            V::List(items) => items.len() == 1 && items[0].truthy(),
        }
    }
}

fn unsupported(message: String) -> MetricError {
    MetricError::BadInput(format!("conditional formatting: {message}"))
}

#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Num(f64),
    Str(String),
    /// A reference, upper-cased with `$` removed (`A2`, `A2:A9`).
    Ref(String),
    Func(String),
    Bool(bool),
    Op(&'static str),
    Open,
    Close,
    Comma,
}

fn tokenize(text: &str) -> Result<Vec<Tok>, MetricError> {
    let chars: Vec<char> = text.chars().collect();
    let mut out = Vec::new();
    let mut i = 0;
    let bad = |what: &str| unsupported(format!("cannot read formula {text:?} ({what})"));
    while i < chars.len() {
        let c = chars[i];
        match c {
            ' ' => i += 1,
            '(' => {
                out.push(Tok::Open);
                i += 1;
            }
            ')' => {
                out.push(Tok::Close);
                i += 1;
            }
            ',' | ';' => {
                out.push(Tok::Comma);
                i += 1;
            }
            '"' => {
                let mut s = String::new();
                i += 1;
                loop {
                    match chars.get(i) {
                        None => return Err(bad("unterminated text")),
                        Some('"') if chars.get(i + 1) == Some(&'"') => {
                            s.push('"');
                            i += 2;
                        }
                        Some('"') => {
                            i += 1;
                            break;
                        }
                        Some(ch) => {
                            s.push(*ch);
                            i += 1;
                        }
                    }
                }
                out.push(Tok::Str(s));
            }
            '<' | '>' | '=' | '+' | '-' | '*' | '/' | '^' | '&' => {
                let two: String = chars[i..chars.len().min(i + 2)].iter().collect();
                let op = match two.as_str() {
                    "<>" => "<>",
                    "<=" => "<=",
                    ">=" => ">=",
                    _ => match c {
                        '<' => "<",
                        '>' => ">",
                        '=' => "=",
                        '+' => "+",
                        '-' => "-",
                        '*' => "*",
                        '/' => "/",
                        '^' => "^",
                        _ => "&",
                    },
                };
                i += op.len();
                out.push(Tok::Op(op));
            }
            d if d.is_ascii_digit() || d == '.' => {
                let start = i;
                while i < chars.len() && (chars[i].is_ascii_digit() || chars[i] == '.') {
                    i += 1;
                }
                let n: String = chars[start..i].iter().collect();
                out.push(Tok::Num(n.parse().map_err(|_| bad("bad number"))?));
            }
            a if a.is_ascii_alphabetic() || a == '$' || a == '_' => {
                let start = i;
                while i < chars.len() && (chars[i].is_ascii_alphanumeric() || matches!(chars[i], '$' | '_' | '.')) {
                    i += 1;
                }
                let word: String = chars[start..i].iter().collect::<String>().to_ascii_uppercase();
                if chars.get(i) == Some(&'(') {
                    out.push(Tok::Func(word));
                } else if word == "TRUE" || word == "FALSE" {
                    out.push(Tok::Bool(word == "TRUE"));
                } else if is_cell(&word) {
                    let mut name = word.replace('$', "");
                    if chars.get(i) == Some(&':') {
                        let start = i + 1;
                        let mut end = start;
                        while end < chars.len() && (chars[end].is_ascii_alphanumeric() || chars[end] == '$') {
                            end += 1;
                        }
                        let other: String = chars[start..end].iter().collect::<String>().to_ascii_uppercase();
                        if !is_cell(&other) {
                            return Err(bad("bad range"));
                        }
                        name = format!("{name}:{}", other.replace('$', ""));
                        i = end;
                    }
                    out.push(Tok::Ref(name));
                } else {
                    return Err(bad(&format!("unsupported name {word}")));
                }
            }
            _ => return Err(bad(&format!("unsupported character {c:?}"))),
        }
    }
    Ok(out)
}

/// `A1`, `$A$1`, `$A1`, `A$1` (upper case).
fn is_cell(word: &str) -> bool {
    let plain = word.replace('$', "");
    let letters = plain.chars().take_while(char::is_ascii_uppercase).count();
    (1..=3).contains(&letters)
        && plain.len() > letters
        && plain[letters..].chars().all(|c| c.is_ascii_digit())
        && !plain[letters..].starts_with('0')
}

/// A parsed expression.
#[derive(Debug, Clone)]
enum Expr {
    Lit(V),
    Ref(String),
    Neg(Box<Expr>),
    Bin(&'static str, Box<Expr>, Box<Expr>),
    Call(String, Vec<Expr>),
}

struct Parser {
    toks: Vec<Tok>,
    pos: usize,
}

impl Parser {
    fn peek(&self) -> Option<&Tok> {
        self.toks.get(self.pos)
    }

    fn next(&mut self) -> Option<Tok> {
        let t = self.toks.get(self.pos).cloned();
        self.pos += 1;
        t
    }

    fn binary(&mut self, level: usize) -> Result<Expr, MetricError> {
        const LEVELS: [&[&str]; 5] = [&["=", "<>", "<", ">", "<=", ">="], &["&"], &["+", "-"], &["*", "/"], &["^"]];
        if level == LEVELS.len() {
            return self.unary();
        }
        let mut left = self.binary(level + 1)?;
        while let Some(Tok::Op(op)) = self.peek() {
            let op = *op;
            if !LEVELS[level].contains(&op) {
                break;
            }
            self.pos += 1;
            let right = self.binary(level + 1)?;
            left = Expr::Bin(op, Box::new(left), Box::new(right));
        }
        Ok(left)
    }

    fn unary(&mut self) -> Result<Expr, MetricError> {
        match self.peek() {
            Some(Tok::Op("-")) => {
                self.pos += 1;
                Ok(Expr::Neg(Box::new(self.unary()?)))
            }
            Some(Tok::Op("+")) => {
                self.pos += 1;
                self.unary()
            }
            _ => self.primary(),
        }
    }

    fn primary(&mut self) -> Result<Expr, MetricError> {
        let bad = || unsupported("cannot parse the formula".into());
        match self.next().ok_or_else(bad)? {
            Tok::Num(n) => Ok(Expr::Lit(V::Num(n))),
            Tok::Str(s) => Ok(Expr::Lit(V::Str(s))),
            Tok::Bool(b) => Ok(Expr::Lit(V::Bool(b))),
            Tok::Ref(name) => Ok(Expr::Ref(name)),
            Tok::Open => {
                let inner = self.binary(0)?;
                matches!(self.next(), Some(Tok::Close)).then_some(inner).ok_or_else(bad)
            }
            Tok::Func(name) => {
                self.pos += 1; // the opening parenthesis
                let mut args = Vec::new();
                if self.peek() == Some(&Tok::Close) {
                    self.pos += 1;
                } else {
                    loop {
                        args.push(self.binary(0)?);
                        match self.next() {
                            Some(Tok::Comma) => {}
                            Some(Tok::Close) => break,
                            _ => return Err(bad()),
                        }
                    }
                }
                Ok(Expr::Call(name, args))
            }
            _ => Err(bad()),
        }
    }
}

/// A compiled `expression` rule: the formula and the order its inputs take values in.
#[derive(Debug)]
pub(super) struct Condition {
    expr: Expr,
    /// The distinct references, sorted as the compiled function orders its inputs.
    inputs: Vec<String>,
}

impl Condition {
    /// Parses `formula` (the `cfRule`'s first formula, without `=`).
    ///
    /// # Errors
    ///
    /// [`MetricError::BadInput`] for a formula this evaluator does not read.
    pub(super) fn compile(formula: &str) -> Result<Condition, MetricError> {
        let toks = tokenize(formula)?;
        let mut inputs: Vec<String> =
            toks.iter().filter_map(|t| if let Tok::Ref(name) = t { Some(name.clone()) } else { None }).collect();
        inputs.sort();
        inputs.dedup();
        let mut parser = Parser { toks, pos: 0 };
        let expr = parser.binary(0)?;
        if parser.pos != parser.toks.len() {
            return Err(unsupported(format!("cannot parse formula {formula:?}")));
        }
        Ok(Condition { expr, inputs })
    }

    /// Upstream's absolute ranges: `$COL$ROW:$COL$ROW` (upper-case letters
    /// only) in the formula text, in order, each as (first row, first column,
    /// last row, last column).
    ///
    /// # Errors
    ///
    /// [`MetricError::BadInput`] for an absolute single cell, which upstream
    /// turns into the range `C1:` and fails on.
    pub(super) fn absolute_ranges(formula: &str) -> Result<Vec<(u32, u32, u32, u32)>, MetricError> {
        let chars: Vec<char> = formula.chars().collect();
        let absolute_cell = |at: usize| -> Option<(usize, String)> {
            let mut i = at;
            if chars.get(i) != Some(&'$') {
                return None;
            }
            i += 1;
            let col_start = i;
            while i < chars.len() && chars[i].is_ascii_uppercase() && i - col_start < 3 {
                i += 1;
            }
            if i == col_start || chars.get(i) != Some(&'$') {
                return None;
            }
            let col: String = chars[col_start..i].iter().collect();
            i += 1;
            let row_start = i;
            while i < chars.len() && chars[i].is_ascii_digit() {
                i += 1;
            }
            if i == row_start {
                return None;
            }
            let row: String = chars[row_start..i].iter().collect();
            Some((i, format!("{col}{row}")))
        };
        let mut ranges = Vec::new();
        let mut i = 0;
        while i < chars.len() {
            let Some((end, first)) = absolute_cell(i) else {
                i += 1;
                continue;
            };
            let second = if chars.get(end) == Some(&':') { absolute_cell(end + 1) } else { None };
            let Some((end, second)) = second else {
                return Err(unsupported(format!(
                    "formula {formula:?} names the single cell ${first}, which upstream cannot evaluate"
                )));
            };
            let range = super::xlsx::parse_range(&format!("{first}:{second}"))
                .ok_or_else(|| unsupported(format!("bad range in {formula:?}")))?;
            ranges.push(range);
            i = end;
        }
        Ok(ranges)
    }

    /// Whether the rule holds for a cell whose raw value is `cell`, with
    /// `ranges` the values of the absolute ranges.
    ///
    /// # Errors
    ///
    /// [`MetricError::BadInput`] when the values do not fit the inputs, or a
    /// function is not implemented.
    pub(super) fn holds(&self, cell: V, ranges: &[V]) -> Result<bool, MetricError> {
        let args: Vec<V> = std::iter::once(cell).chain(ranges.iter().cloned()).collect();
        if args.len() != self.inputs.len() {
            return Err(unsupported(format!(
                "the formula has {} inputs ({}) but upstream passes {} values",
                self.inputs.len(),
                self.inputs.join(", "),
                args.len()
            )));
        }
        let env: Vec<(&str, V)> = self.inputs.iter().map(String::as_str).zip(args).collect();
        Ok(eval(&self.expr, &env)?.truthy())
    }
}

fn number_of(v: &V) -> Option<f64> {
    match v {
        V::Num(n) => Some(*n),
        V::Bool(b) => Some(f64::from(u8::from(*b))),
        V::Str(s) => s.trim().parse().ok(),
        _ => None,
    }
}

fn eval(expr: &Expr, env: &[(&str, V)]) -> Result<V, MetricError> {
    Ok(match expr {
        Expr::Lit(v) => v.clone(),
        Expr::Ref(name) => env.iter().find(|(n, _)| n == name).map(|(_, v)| v.clone()).unwrap_or(V::Empty),
        Expr::Neg(inner) => match number_of(&eval(inner, env)?) {
            Some(n) => V::Num(-n),
            None => V::Err,
        },
        Expr::Bin(op, a, b) => binary(op, eval(a, env)?, eval(b, env)?),
        Expr::Call(name, args) => {
            let values = args.iter().map(|a| eval(a, env)).collect::<Result<Vec<_>, _>>()?;
            call(name, &values)?
        }
    })
}

fn binary(op: &str, a: V, b: V) -> V {
    if a == V::Err || b == V::Err || matches!(a, V::List(_)) || matches!(b, V::List(_)) {
        return V::Err;
    }
    match op {
        "=" | "<>" | "<" | ">" | "<=" | ">=" => {
            if a == V::Empty || b == V::Empty {
                return match op {
                    "=" => V::Bool(false),
                    "<>" => V::Bool(true),
                    _ => V::Err,
                };
            }
            let ordering = compare(&a, &b);
            V::Bool(match op {
                "=" => ordering == Ordering::Equal,
                "<>" => ordering != Ordering::Equal,
                "<" => ordering == Ordering::Less,
                ">" => ordering == Ordering::Greater,
                "<=" => ordering != Ordering::Greater,
                _ => ordering != Ordering::Less,
            })
        }
        "&" => match (text_of(&a), text_of(&b)) {
            (Some(x), Some(y)) => V::Str(x + &y),
            _ => V::Err,
        },
        _ => {
            let (Some(x), Some(y)) = (number_of(&a), number_of(&b)) else { return V::Err };
            let value = match op {
                "+" => x + y,
                "-" => x - y,
                "*" => x * y,
                "/" if y == 0.0 => return V::Err,
                "/" => x / y,
                _ => x.powf(y),
            };
            if value.is_finite() {
                V::Num(value)
            } else {
                V::Err
            }
        }
    }
}

/// Excel's ordering across types: numbers, then text (case-insensitive), then booleans.
fn compare(a: &V, b: &V) -> Ordering {
    let rank = |v: &V| match v {
        V::Num(_) => 0,
        V::Str(_) => 1,
        _ => 2,
    };
    match (a, b) {
        (V::Num(x), V::Num(y)) => x.partial_cmp(y).unwrap_or(Ordering::Equal),
        (V::Str(x), V::Str(y)) => x.to_lowercase().cmp(&y.to_lowercase()),
        (V::Bool(x), V::Bool(y)) => x.cmp(y),
        _ => rank(a).cmp(&rank(b)),
    }
}

fn text_of(v: &V) -> Option<String> {
    match v {
        V::Num(n) if n.fract() == 0.0 && n.abs() < 1e15 => Some(format!("{}", *n as i64)),
        V::Num(n) => Some(n.to_string()),
        V::Str(s) => Some(s.clone()),
        V::Bool(b) => Some(if *b { "TRUE" } else { "FALSE" }.into()),
        _ => None,
    }
}

/// The numbers an aggregate sees: a range's numbers (blank cells, text and
/// booleans skipped; numeric text is an error value in the package), a
/// scalar argument's number.
fn numbers(args: &[V]) -> Result<Vec<f64>, ()> {
    let mut out = Vec::new();
    for arg in args {
        match arg {
            V::List(items) => {
                for item in items {
                    match item {
                        V::Num(n) => out.push(*n),
                        V::Err => return Err(()),
                        V::Str(s) if s.trim().parse::<f64>().is_ok() => return Err(()),
                        _ => {}
                    }
                }
            }
            V::Empty => {}
            other => out.push(number_of(other).ok_or(())?),
        }
    }
    Ok(out)
}

fn call(name: &str, args: &[V]) -> Result<V, MetricError> {
    let aggregate = |f: fn(&[f64]) -> Option<f64>| match numbers(args) {
        Ok(nums) => f(&nums).map_or(V::Err, V::Num),
        Err(()) => V::Err,
    };
    let logical = |v: &V| match v {
        V::Str(_) | V::Err | V::List(_) => None,
        other => Some(other.truthy()),
    };
    Ok(match name {
        "MAX" => {
            aggregate(|n| Some(if n.is_empty() { 0.0 } else { n.iter().copied().fold(f64::NEG_INFINITY, f64::max) }))
        }
        "MIN" => aggregate(|n| Some(if n.is_empty() { 0.0 } else { n.iter().copied().fold(f64::INFINITY, f64::min) })),
        "SUM" => aggregate(|n| Some(n.iter().sum())),
        "AVERAGE" => aggregate(|n| (!n.is_empty()).then(|| n.iter().sum::<f64>() / n.len() as f64)),
        "COUNT" => aggregate(|n| Some(n.len() as f64)),
        "ABS" if args.len() == 1 => number_of(&args[0]).map_or(V::Err, |n| V::Num(n.abs())),
        "NOT" if args.len() == 1 => logical(&args[0]).map_or(V::Err, |b| V::Bool(!b)),
        "AND" | "OR" => {
            let flags: Option<Vec<bool>> = args.iter().map(logical).collect();
            match flags {
                Some(flags) if name == "AND" => V::Bool(flags.iter().all(|b| *b)),
                Some(flags) => V::Bool(flags.iter().any(|b| *b)),
                None => V::Err,
            }
        }
        other => return Err(unsupported(format!("function {other} with {} arguments is not implemented", args.len()))),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn list(values: &[f64]) -> V {
        V::List(values.iter().map(|n| V::Num(*n)).collect())
    }

    #[test]
    fn inputs_bind_in_sorted_order_as_the_formulas_package_does() {
        let top = Condition::compile("C2=MAX($C$2:$C$5)").unwrap();
        assert_eq!(top.inputs, vec!["C2", "C2:C5"]);
        let values = [list(&[1.0, 3.0, 2.0, 0.5])];
        assert!(top.holds(V::Num(3.0), &values).unwrap());
        assert!(!top.holds(V::Num(2.0), &values).unwrap());
        // Written the other way round the inputs sort the same.
        let flipped = Condition::compile("MAX($C$2:$C$5)=C2").unwrap();
        assert!(flipped.holds(V::Num(3.0), &values).unwrap());
        // B10 sorts before B9: the cell's value goes to B10.
        assert_eq!(Condition::compile("B10>B9").unwrap().inputs, vec!["B10", "B9"]);
        assert_eq!(
            Condition::absolute_ranges("C2=MAX($C$2:$C$5)+$a$1").unwrap(),
            vec![(2, 3, 5, 3)],
            "lower-case references are not absolute ranges upstream"
        );
        assert!(Condition::absolute_ranges("C2>$D$1").is_err());
    }

    #[test]
    fn values_follow_the_packages_rules() {
        let above = Condition::compile("A2>5").unwrap();
        assert!(above.holds(V::Num(6.0), &[]).unwrap());
        assert!(!above.holds(V::Num(5.0), &[]).unwrap());
        // Text sorts after numbers; an empty cell gives an error value, which is truthy.
        assert!(above.holds(V::Str("x".into()), &[]).unwrap());
        assert!(above.holds(V::Empty, &[]).unwrap());
        assert!(!Condition::compile("A2=5").unwrap().holds(V::Empty, &[]).unwrap());
        assert!(Condition::compile("A2<>5").unwrap().holds(V::Empty, &[]).unwrap());
        assert!(Condition::compile("A2=\"abc\"").unwrap().holds(V::Str("ABC".into()), &[]).unwrap());
        assert!(Condition::compile("A2+1>2").unwrap().holds(V::Str("3".into()), &[]).unwrap());
        // Blank cells and text in a range are skipped by MAX.
        let top = Condition::compile("A2=MAX($A$2:$A$5)").unwrap();
        let mixed = [V::List(vec![V::Num(1.0), V::Num(2.0), V::Str("a".into()), V::Empty])];
        assert!(top.holds(V::Num(2.0), &mixed).unwrap());
        // A value too many or too few is upstream's failure.
        assert!(Condition::compile("AND(A2>1,B2<3)").unwrap().holds(V::Num(2.0), &[]).is_err());
        assert!(Condition::compile("LARGE($A$2:$A$5,1)=A2").unwrap().holds(V::Num(1.0), &[list(&[1.0])]).is_err());
    }
}
