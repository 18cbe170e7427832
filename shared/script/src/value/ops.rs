//! Arithmetic, comparisons, ordering and rounding with Python's semantics.
//!
//! Integers are 64-bit and overflow raises `OverflowError` instead of
//! growing; floor division and modulo round toward negative infinity; `/`
//! always gives a float; `round` rounds half to even.
//! Results that would be huge (`'a' * 10**9`) raise `MemoryError`.

use std::cmp::Ordering;

use super::heap::{self, reserve_items, Heap, SetMap};
use super::Value;
use crate::ast::{BinOp, UnaryOp};
use crate::error::{type_error, value_error, ErrorKind, ScriptError};

/// The longest string (in bytes) an operation may build.
pub(crate) const MAX_LEN: usize = 10_000_000;

/// The most items a list or tuple operation may build.
pub(crate) const MAX_ITEMS: usize = 1_000_000;

fn overflow() -> ScriptError {
    ScriptError::new(ErrorKind::Overflow, "integer overflow (this interpreter's integers are 64-bit)")
}

fn zero_division(message: &str) -> ScriptError {
    ScriptError::new(ErrorKind::ZeroDivision, message)
}

fn too_big(limit: usize) -> ScriptError {
    ScriptError::new(ErrorKind::Memory, format!("result would exceed {limit} items"))
}

/// A number operand: bools count as ints, as in Python.
#[derive(Clone, Copy)]
enum Num {
    Int(i64),
    Float(f64),
}

fn num(v: &Value) -> Option<Num> {
    match v {
        Value::Bool(b) => Some(Num::Int(i64::from(*b))),
        Value::Int(i) => Some(Num::Int(*i)),
        Value::Float(f) => Some(Num::Float(*f)),
        _ => None,
    }
}

fn as_float(n: Num) -> f64 {
    match n {
        // Precision loss above 2**53 matches Python's int-to-float conversion.
        Num::Int(i) => i as f64,
        Num::Float(f) => f,
    }
}

/// `-x`, `+x`, `~x` and `not x`.
pub(crate) fn unary(op: UnaryOp, v: &Value) -> Result<Value, ScriptError> {
    let symbol = match op {
        UnaryOp::Plus => "+",
        UnaryOp::Minus => "-",
        UnaryOp::Invert => "~",
        UnaryOp::Not => return Ok(Value::Bool(!v.truthy())),
    };
    match (op, num(v)) {
        (UnaryOp::Invert, Some(Num::Int(i))) => Ok(Value::Int(!i)),
        (UnaryOp::Plus, Some(Num::Int(i))) => Ok(Value::Int(i)),
        (UnaryOp::Plus, Some(Num::Float(f))) => Ok(Value::Float(f)),
        (UnaryOp::Minus, Some(Num::Int(i))) => i.checked_neg().map(Value::Int).ok_or_else(overflow),
        (UnaryOp::Minus, Some(Num::Float(f))) => Ok(Value::Float(-f)),
        _ => Err(type_error(format!("bad operand type for unary {symbol}: '{}'", v.type_name()))),
    }
}

/// `left op right`.
pub(crate) fn binary(op: BinOp, left: &Value, right: &Value) -> Result<Value, ScriptError> {
    if let (Value::Bool(a), Value::Bool(b)) = (left, right) {
        match op {
            BinOp::BitAnd => return Ok(Value::Bool(*a & *b)),
            BinOp::BitOr => return Ok(Value::Bool(*a | *b)),
            BinOp::BitXor => return Ok(Value::Bool(*a ^ *b)),
            _ => {}
        }
    }
    if let (Some(a), Some(b)) = (num(left), num(right)) {
        return match (a, b) {
            (Num::Int(a), Num::Int(b)) => int_op(op, a, b),
            (_, _) if is_bitwise(op) => Err(operand_error(op, left, right)),
            (a, b) => float_op(op, as_float(a), as_float(b)),
        };
    }
    match (op, left, right) {
        (BinOp::Mod, Value::Str(text), args) => Ok(Value::str(super::format::percent(text, args)?)),
        (BinOp::BitOr | BinOp::BitAnd | BinOp::Sub | BinOp::BitXor, Value::Set(a), Value::Set(b)) => {
            reserve_items(a.len().saturating_add(b.len()))?;
            let items: SetMap = match op {
                BinOp::BitOr => a.iter().chain(b.iter()).cloned().collect(),
                BinOp::BitAnd => a.iter().filter(|v| b.contains(*v)).cloned().collect(),
                BinOp::Sub => a.iter().filter(|v| !b.contains(*v)).cloned().collect(),
                _ => {
                    a.iter().filter(|v| !b.contains(*v)).chain(b.iter().filter(|v| !a.contains(*v))).cloned().collect()
                }
            };
            Ok(Value::set(items))
        }
        (BinOp::BitOr, Value::Dict(a), Value::Dict(b)) => {
            reserve_items(a.len().saturating_add(b.len()).saturating_mul(2))?;
            let mut merged = a.clone();
            let mut table = merged.make_mut();
            for (k, v) in b.iter() {
                table.insert(k.clone(), v.clone());
            }
            drop(table);
            Ok(Value::Dict(merged))
        }
        (BinOp::Add, Value::Str(a), Value::Str(b)) => {
            if a.len() + b.len() > MAX_LEN {
                return Err(too_big(MAX_LEN));
            }
            heap::reserve_text(a.len() + b.len())?;
            let mut text = String::with_capacity(a.len() + b.len());
            text.push_str(a);
            text.push_str(b);
            Ok(Value::str(text))
        }
        (BinOp::Add, Value::List(a), Value::List(b)) => Ok(Value::list(concat(a, b)?)),
        (BinOp::Add, Value::Tuple(a), Value::Tuple(b)) => Ok(Value::tuple(concat(a, b)?)),
        (BinOp::Add, Value::Str(_), other) => {
            Err(type_error(format!("can only concatenate str (not \"{}\") to str", other.type_name())))
        }
        (BinOp::Mul, seq, n) | (BinOp::Mul, n, seq)
            if matches!(seq, Value::Str(_) | Value::List(_) | Value::Tuple(_))
                && matches!(n, Value::Int(_) | Value::Bool(_)) =>
        {
            let times = match num(n) {
                Some(Num::Int(i)) => usize::try_from(i.max(0)).unwrap_or(usize::MAX),
                _ => 0,
            };
            repeat(seq, times)
        }
        _ => Err(operand_error(op, left, right)),
    }
}

fn is_bitwise(op: BinOp) -> bool {
    matches!(op, BinOp::BitAnd | BinOp::BitOr | BinOp::BitXor | BinOp::LShift | BinOp::RShift)
}

fn operand_error(op: BinOp, left: &Value, right: &Value) -> ScriptError {
    type_error(format!(
        "unsupported operand type(s) for {}: '{}' and '{}'",
        op.symbol(),
        left.type_name(),
        right.type_name()
    ))
}

/// `a + b` for lists and tuples: the items are shared, not copied.
fn concat(a: &[Value], b: &[Value]) -> Result<Vec<Value>, ScriptError> {
    if a.len() + b.len() > MAX_ITEMS {
        return Err(too_big(MAX_ITEMS));
    }
    reserve_items(a.len() + b.len())?;
    Ok(a.iter().chain(b).cloned().collect())
}

/// `seq * times`: the result's size is checked against the item caps and the memory
/// budget before it is built, and its items share their payloads.
fn repeat(seq: &Value, times: usize) -> Result<Value, ScriptError> {
    let (len, limit) = match seq {
        Value::Str(s) => (s.len(), MAX_LEN),
        Value::List(v) | Value::Tuple(v) => (v.len(), MAX_ITEMS),
        _ => (0, 0),
    };
    let Some(total) = len.checked_mul(times).filter(|total| *total <= limit) else {
        return Err(too_big(limit));
    };
    Ok(match seq {
        Value::Str(s) => {
            heap::reserve_text(total)?;
            Value::str(s.repeat(times))
        }
        Value::List(v) => Value::list(repeat_items(v, times, total)?),
        Value::Tuple(v) => Value::tuple(repeat_items(v, times, total)?),
        other => other.clone(),
    })
}

fn repeat_items(items: &[Value], times: usize, total: usize) -> Result<Vec<Value>, ScriptError> {
    reserve_items(total)?;
    if items.is_empty() {
        // `[] * 10**18` is empty at once, not after 10**18 rounds of nothing.
        return Ok(Vec::new());
    }
    let mut out = Vec::with_capacity(total);
    for _ in 0..times {
        out.extend(items.iter().cloned());
        crate::stop::work(items.len() as u64)?;
    }
    Ok(out)
}

fn int_op(op: BinOp, a: i64, b: i64) -> Result<Value, ScriptError> {
    let int = |r: Option<i64>| r.map(Value::Int).ok_or_else(overflow);
    match op {
        BinOp::Add => int(a.checked_add(b)),
        BinOp::Sub => int(a.checked_sub(b)),
        BinOp::Mul => int(a.checked_mul(b)),
        BinOp::Div => {
            if b == 0 {
                return Err(zero_division("division by zero"));
            }
            Ok(Value::Float(a as f64 / b as f64))
        }
        BinOp::FloorDiv | BinOp::Mod => {
            if b == 0 {
                return Err(zero_division("integer division or modulo by zero"));
            }
            let q = a.checked_div(b).ok_or_else(overflow)?;
            let r = a.checked_rem(b).ok_or_else(overflow)?;
            // Rust truncates toward zero; Python floors, so adjust when the signs differ.
            let (q, r) = if r != 0 && ((r < 0) != (b < 0)) { (q - 1, r + b) } else { (q, r) };
            Ok(Value::Int(if op == BinOp::FloorDiv { q } else { r }))
        }
        BinOp::Pow => {
            if b < 0 {
                if a == 0 {
                    return Err(zero_division("0.0 cannot be raised to a negative power"));
                }
                return Ok(Value::Float((a as f64).powf(b as f64)));
            }
            let exp = u32::try_from(b).map_err(|_| overflow())?;
            int(a.checked_pow(exp))
        }
        BinOp::BitAnd => Ok(Value::Int(a & b)),
        BinOp::BitOr => Ok(Value::Int(a | b)),
        BinOp::BitXor => Ok(Value::Int(a ^ b)),
        BinOp::LShift | BinOp::RShift => {
            if b < 0 {
                return Err(value_error("negative shift count"));
            }
            if op == BinOp::RShift {
                return Ok(Value::Int(if b >= 64 {
                    if a < 0 {
                        -1
                    } else {
                        0
                    }
                } else {
                    a >> b
                }));
            }
            if a == 0 {
                return Ok(Value::Int(0));
            }
            let shifted = u32::try_from(b).ok().filter(|b| *b < 63).map(|b| a.wrapping_shl(b));
            match shifted {
                Some(v) if v >> b == a => Ok(Value::Int(v)),
                _ => Err(overflow()),
            }
        }
    }
}

fn float_op(op: BinOp, a: f64, b: f64) -> Result<Value, ScriptError> {
    let value = match op {
        BinOp::Add => a + b,
        BinOp::Sub => a - b,
        BinOp::Mul => a * b,
        BinOp::Div => {
            if b == 0.0 {
                return Err(zero_division("float division by zero"));
            }
            a / b
        }
        BinOp::FloorDiv | BinOp::Mod => {
            if b == 0.0 {
                return Err(zero_division("float modulo"));
            }
            let (div, rem) = float_divmod(a, b);
            if op == BinOp::FloorDiv {
                div
            } else {
                rem
            }
        }
        BinOp::BitAnd | BinOp::BitOr | BinOp::BitXor | BinOp::LShift | BinOp::RShift => {
            return Err(type_error(format!("unsupported operand type(s) for {}: 'float' and 'float'", op.symbol())));
        }
        BinOp::Pow => {
            if a == 0.0 && b < 0.0 {
                return Err(zero_division("0.0 cannot be raised to a negative power"));
            }
            if a < 0.0 && b.fract() != 0.0 && b.is_finite() {
                return Err(ScriptError::new(
                    ErrorKind::NotSupported,
                    "complex results (a negative number to a fractional power) are not supported",
                ));
            }
            a.powf(b)
        }
    };
    Ok(Value::Float(value))
}

/// CPython's `float_divmod`.
fn float_divmod(a: f64, b: f64) -> (f64, f64) {
    let mut rem = a % b;
    let mut div = (a - rem) / b;
    if rem != 0.0 {
        if (b < 0.0) != (rem < 0.0) {
            rem += b;
            div -= 1.0;
        }
    } else {
        rem = 0.0_f64.copysign(b);
    }
    let floordiv = if div != 0.0 {
        let mut f = div.floor();
        if div - f > 0.5 {
            f += 1.0;
        }
        f
    } else {
        0.0_f64.copysign(a / b)
    };
    (floordiv, rem)
}

/// Orders two values for `min`/`max` and `sorted`: numbers with numbers, strings
/// with strings, lists with lists and tuples with tuples (item by item).
pub(crate) fn compare(a: &Value, b: &Value) -> Result<Ordering, ScriptError> {
    compare_with("<", a, b)
}

/// [`compare`] with the operator named in the error message; `None` from a NaN is `Equal`.
pub(crate) fn compare_with(symbol: &str, a: &Value, b: &Value) -> Result<Ordering, ScriptError> {
    match (num(a), num(b)) {
        (Some(Num::Int(x)), Some(Num::Int(y))) => return Ok(x.cmp(&y)),
        (Some(x), Some(y)) => return Ok(as_float(x).partial_cmp(&as_float(y)).unwrap_or(Ordering::Equal)),
        _ => {}
    }
    match (a, b) {
        (Value::Str(x), Value::Str(y)) => Ok(x.cmp(y)),
        (Value::List(x), Value::List(y)) | (Value::Tuple(x), Value::Tuple(y)) => {
            for (p, q) in x.iter().zip(y.iter()) {
                if !equal(p, q) {
                    return compare_with(symbol, p, q);
                }
            }
            Ok(x.len().cmp(&y.len()))
        }
        _ => Err(type_error(format!(
            "'{symbol}' not supported between instances of '{}' and '{}'",
            a.type_name(),
            b.type_name()
        ))),
    }
}

/// Whether `a < b` (or another ordering operator) holds; NaN compares false.
pub(crate) fn ordered(symbol: &str, a: &Value, b: &Value) -> Result<bool, ScriptError> {
    if let (Some(x), Some(y)) = (num(a), num(b)) {
        if matches!(x, Num::Float(_)) || matches!(y, Num::Float(_)) {
            let (x, y) = (as_float(x), as_float(y));
            return Ok(match symbol {
                "<" => x < y,
                "<=" => x <= y,
                ">" => x > y,
                _ => x >= y,
            });
        }
    }
    let ord = compare_with(symbol, a, b)?;
    Ok(match symbol {
        "<" => ord.is_lt(),
        "<=" => ord.is_le(),
        ">" => ord.is_gt(),
        _ => ord.is_ge(),
    })
}

/// Python `==`: numbers by value across int, float and bool; containers item by
/// item (dicts and sets regardless of order); everything else structurally.
pub(crate) fn equal(a: &Value, b: &Value) -> bool {
    match (num(a), num(b)) {
        (Some(Num::Int(x)), Some(Num::Int(y))) => return x == y,
        (Some(x), Some(y)) => return as_float(x) == as_float(y),
        (Some(_), None) | (None, Some(_)) => return false,
        _ => {}
    }
    let seq = |x: &[Value], y: &[Value]| x.len() == y.len() && x.iter().zip(y).all(|(p, q)| equal(p, q));
    match (a, b) {
        (Value::List(x), Value::List(y)) | (Value::Tuple(x), Value::Tuple(y)) => Heap::ptr_eq(x, y) || seq(x, y),
        (Value::Set(x), Value::Set(y)) => x.len() == y.len() && x.iter().all(|p| y.contains(p)),
        (Value::Dict(x), Value::Dict(y)) => {
            x.len() == y.len() && x.iter().all(|(k, v)| y.get(k).is_some_and(|v2| equal(v, v2)))
        }
        (Value::Str(x), Value::Str(y)) => x.as_str() == y.as_str(),
        (Value::Range(..), Value::Range(..)) => a == b,
        (Value::Type(t), Value::Function { module: "", name })
        | (Value::Function { module: "", name }, Value::Type(t)) => t == name,
        (Value::Point(..) | Value::Size(..), Value::Tuple(y))
        | (Value::Tuple(y), Value::Point(..) | Value::Size(..)) => {
            let (Value::Point(p, q) | Value::Size(p, q)) = (if matches!(a, Value::Tuple(_)) { b } else { a }) else {
                return false;
            };
            seq(&[Value::Int(*p), Value::Int(*q)], y)
        }
        _ => a == b,
    }
}

/// `round(x)`: a float rounded half to even, as an int.
pub(crate) fn round_to_int(f: f64) -> Result<i64, ScriptError> {
    if f.is_nan() {
        return Err(value_error("cannot convert float NaN to integer"));
    }
    if f.is_infinite() {
        return Err(ScriptError::new(ErrorKind::Overflow, "cannot convert float infinity to integer"));
    }
    let r = f.round_ties_even();
    if !(-9.223_372_036_854_776e18..9.223_372_036_854_776e18).contains(&r) {
        return Err(overflow());
    }
    Ok(r as i64)
}

/// `round(x, ndigits)`.
pub(crate) fn round_ndigits(v: &Value, ndigits: i64) -> Result<Value, ScriptError> {
    match num(v) {
        Some(Num::Int(i)) => {
            if ndigits >= 0 {
                return Ok(Value::Int(i));
            }
            let Some(unit) =
                ndigits.checked_neg().and_then(|n| u32::try_from(n).ok()).and_then(|e| 10_i64.checked_pow(e))
            else {
                return Ok(Value::Int(0));
            };
            let (q, r) = (i.div_euclid(unit), i.rem_euclid(unit));
            let twice = r.saturating_mul(2);
            let up = twice > unit || (twice == unit && q % 2 != 0);
            let q = if up { q + 1 } else { q };
            q.checked_mul(unit).map(Value::Int).ok_or_else(overflow)
        }
        Some(Num::Float(f)) => {
            if !f.is_finite() || ndigits > 323 {
                return Ok(Value::Float(f));
            }
            if ndigits >= 0 {
                // Formatting rounds the exact binary value half to even, like CPython's dtoa.
                let text = format!("{f:.*}", ndigits as usize);
                return Ok(Value::Float(text.parse().unwrap_or(f)));
            }
            if ndigits < -308 {
                return Ok(Value::Float(0.0_f64.copysign(f)));
            }
            let unit = 10_f64.powi(-ndigits as i32);
            Ok(Value::Float((f / unit).round_ties_even() * unit))
        }
        None => Err(type_error(format!("type {} doesn't define __round__ method", v.type_name()))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(op: BinOp, a: Value, b: Value, expected: Value) {
        assert_eq!(binary(op, &a, &b).unwrap(), expected, "{a:?} {op:?} {b:?}");
    }

    #[test]
    fn arithmetic_follows_python() {
        use Value::{Float as F, Int as I};
        check(BinOp::FloorDiv, I(-7), I(2), I(-4));
        check(BinOp::Mod, I(-7), I(2), I(1));
        check(BinOp::Mod, I(7), I(-2), I(-1));
        check(BinOp::Div, I(7), I(2), F(3.5));
        check(BinOp::Div, I(1), I(3), F(1.0 / 3.0));
        check(BinOp::Mod, F(-7.5), F(2.0), F(0.5));
        check(BinOp::FloorDiv, F(7.5), F(-2.0), F(-4.0));
        check(BinOp::Pow, I(2), I(10), I(1024));
        check(BinOp::Pow, I(2), I(-1), F(0.5));
        check(BinOp::Add, Value::Bool(true), I(1), I(2));
        check(BinOp::Mul, Value::str("ab"), I(3), Value::str("ababab"));
        check(BinOp::Mul, I(-1), Value::str("ab"), Value::str(""));
        check(BinOp::Add, Value::str("a"), Value::str("b"), Value::str("ab"));
    }

    #[test]
    fn arithmetic_errors_are_python_exceptions() {
        let err = |op, a, b| binary(op, &a, &b).unwrap_err().python_message();
        assert_eq!(err(BinOp::Div, Value::Int(1), Value::Int(0)), "ZeroDivisionError: division by zero");
        assert_eq!(
            err(BinOp::Add, Value::str("a"), Value::Int(1)),
            "TypeError: can only concatenate str (not \"int\") to str"
        );
        assert_eq!(
            err(BinOp::Sub, Value::str("a"), Value::Int(1)),
            "TypeError: unsupported operand type(s) for -: 'str' and 'int'"
        );
        assert!(err(BinOp::Mul, Value::Int(i64::MAX), Value::Int(2)).starts_with("OverflowError"));
        assert!(err(BinOp::Mul, Value::str("ab"), Value::Int(1 << 40)).starts_with("MemoryError"));
    }

    #[test]
    fn rounding_is_half_to_even() {
        assert_eq!(round_to_int(0.5).unwrap(), 0);
        assert_eq!(round_to_int(1.5).unwrap(), 2);
        assert_eq!(round_to_int(2.5).unwrap(), 2);
        assert_eq!(round_to_int(-2.5).unwrap(), -2);
        assert_eq!(round_ndigits(&Value::Float(2.675), 2).unwrap(), Value::Float(2.67));
        assert_eq!(round_ndigits(&Value::Float(0.125), 2).unwrap(), Value::Float(0.12));
        assert_eq!(round_ndigits(&Value::Int(1250), -2).unwrap(), Value::Int(1200));
        assert_eq!(round_ndigits(&Value::Int(1350), -2).unwrap(), Value::Int(1400));
        assert_eq!(round_ndigits(&Value::Float(1234.5), -2).unwrap(), Value::Float(1200.0));
        assert!(round_to_int(f64::NAN).is_err());
    }
}
