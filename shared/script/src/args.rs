//! How built-ins take their arguments: positional and keyword arguments bound like a
//! Python signature ([`Args`]), the conversions every built-in applies to them
//! (`to_f64`, `to_i64`, `to_str`, ...), and the items of an iterable ([`iterate`],
//! and the lazy walk `for` loops use).
//!
//! It sits below the evaluator (`interp`) and the modules a script imports
//! (`pyautogui`, `stdlib`, `computer`), which all call it; it knows values only.

use crate::error::{type_error, ErrorKind, ScriptError};
use crate::stop;
use crate::value::heap::{self, DictMap, Heap, SetMap};
use crate::value::{ops, Value};

/// Positional and keyword arguments of one call.
#[derive(Debug, Default)]
pub(crate) struct Args {
    pub(crate) pos: Vec<Value>,
    pub(crate) kw: Vec<(String, Value)>,
}

impl Args {
    /// Binds arguments to `params` like a Python signature whose first `required`
    /// parameters have no default. Missing optional parameters are `None`.
    pub(crate) fn bind(self, fname: &str, params: &[&str], required: usize) -> Result<Vec<Option<Value>>, ScriptError> {
        if self.pos.len() > params.len() {
            let takes = if required == params.len() {
                format!("{} positional argument{}", params.len(), if params.len() == 1 { "" } else { "s" })
            } else {
                format!("from {required} to {} positional arguments", params.len())
            };
            let given = self.pos.len();
            let verb = if given == 1 { "was" } else { "were" };
            return Err(type_error(format!("{fname}() takes {takes} but {given} {verb} given")));
        }
        let mut bound: Vec<Option<Value>> = vec![None; params.len()];
        for (slot, value) in bound.iter_mut().zip(self.pos) {
            *slot = Some(value);
        }
        for (name, value) in self.kw {
            let Some(i) = params.iter().position(|p| *p == name) else {
                return Err(type_error(format!("{fname}() got an unexpected keyword argument '{name}'")));
            };
            if bound[i].is_some() {
                return Err(type_error(format!("{fname}() got multiple values for argument '{name}'")));
            }
            bound[i] = Some(value);
        }
        let missing: Vec<String> =
            (0..required).filter(|i| bound[*i].is_none()).map(|i| format!("'{}'", params[i])).collect();
        if !missing.is_empty() {
            let list = match missing.len() {
                1 => missing[0].clone(),
                2 => format!("{} and {}", missing[0], missing[1]),
                n => format!("{}, and {}", missing[..n - 1].join(", "), missing[n - 1]),
            };
            let plural = if missing.len() == 1 { "argument" } else { "arguments" };
            return Err(type_error(format!(
                "{fname}() missing {} required positional {plural}: {list}",
                missing.len()
            )));
        }
        Ok(bound)
    }
}

/// A bound argument that is absent or Python `None`.
pub(crate) fn is_none(arg: &Option<Value>) -> bool {
    matches!(arg, None | Some(Value::None))
}

/// A number argument as `f64`.
pub(crate) fn to_f64(v: &Value, what: &str) -> Result<f64, ScriptError> {
    match v {
        Value::Bool(b) => Ok(f64::from(u8::from(*b))),
        // Precision loss above 2**53 matches Python's int-to-float conversion.
        Value::Int(i) => Ok(*i as f64),
        Value::Float(f) => Ok(*f),
        other => Err(type_error(format!("{what} must be a number, not {}", other.type_name()))),
    }
}

/// An integer argument (bools count, floats do not).
pub(crate) fn to_i64(v: &Value, what: &str) -> Result<i64, ScriptError> {
    match v {
        Value::Bool(b) => Ok(i64::from(*b)),
        Value::Int(i) => Ok(*i),
        other => Err(type_error(format!("{what} must be an integer, not {}", other.type_name()))),
    }
}

/// A string argument.
pub(crate) fn to_str<'v>(v: &'v Value, what: &str) -> Result<&'v str, ScriptError> {
    match v {
        Value::Str(s) => Ok(s),
        other => Err(type_error(format!("{what} must be str, not {}", other.type_name()))),
    }
}

/// The items of an iterable value, sharing their payloads; the list of them is
/// reserved against the memory budget before it is built.
pub(crate) fn iterate(v: &Value) -> Result<Vec<Value>, ScriptError> {
    match v {
        Value::List(items) | Value::Tuple(items) => {
            heap::reserve_items(items.len())?;
            Ok(items.to_vec())
        }
        Value::Str(s) => {
            if s.len() > ops::MAX_ITEMS {
                return Err(ScriptError::new(
                    ErrorKind::Memory,
                    format!("result would exceed {} items", ops::MAX_ITEMS),
                ));
            }
            // Each character becomes a string of its own.
            heap::reserve_items(s.len().saturating_mul(2))?;
            Ok(s.chars().map(|c| Value::str(c.to_string())).collect())
        }
        Value::Dict(entries) => {
            heap::reserve_items(entries.len())?;
            Ok(entries.keys().map(|k| k.0.clone()).collect())
        }
        Value::Set(items) => {
            heap::reserve_items(items.len())?;
            Ok(items.iter().map(|k| k.0.clone()).collect())
        }
        Value::Range(start, stop, step) => {
            let len = crate::value::range_len(*start, *stop, *step);
            if len > ops::MAX_ITEMS as u64 {
                return Err(ScriptError::new(
                    ErrorKind::Memory,
                    format!("result would exceed {} items", ops::MAX_ITEMS),
                ));
            }
            heap::reserve_items(usize::try_from(len).unwrap_or(usize::MAX))?;
            let mut it = LoopIter::Range { next: *start, stop: *stop, step: *step };
            let mut out = Vec::with_capacity(usize::try_from(len).unwrap_or(0));
            while let Some(v) = it.next() {
                out.push(v);
                if out.len() % 1024 == 0 {
                    stop::work(1024)?;
                }
            }
            Ok(out)
        }
        Value::Point(a, b) | Value::Size(a, b) => Ok(vec![Value::Int(*a), Value::Int(*b)]),
        other => Err(type_error(format!("'{}' object is not iterable", other.type_name()))),
    }
}

/// Finds `name` in `list` and returns the list's `'static` copy.
pub(crate) fn static_name(list: &[&'static str], name: &str) -> Option<&'static str> {
    list.iter().copied().find(|n| *n == name)
}

pub(crate) fn no_attribute(value: &Value, name: &str) -> ScriptError {
    ScriptError::new(ErrorKind::Attribute, format!("'{}' object has no attribute '{name}'", value.type_name()))
}

/// What a `for` loop or a comprehension walks: the items of a list, tuple, dict or
/// set, shared with the value looped over (a change to the variable during the
/// loop changes a copy), a range counted lazily, or the items of anything else.
pub(crate) enum LoopIter {
    Seq(Heap<Vec<Value>>, usize),
    Keys(Heap<DictMap>, usize),
    Set(Heap<SetMap>, usize),
    Items(std::vec::IntoIter<Value>),
    Range { next: i64, stop: i64, step: i64 },
}

impl LoopIter {
    pub(crate) fn new(v: Value) -> Result<LoopIter, ScriptError> {
        Ok(match v {
            Value::Range(start, stop, step) => LoopIter::Range { next: start, stop, step },
            Value::List(items) | Value::Tuple(items) => LoopIter::Seq(items, 0),
            Value::Dict(entries) => LoopIter::Keys(entries, 0),
            Value::Set(items) => LoopIter::Set(items, 0),
            other => LoopIter::Items(iterate(&other)?.into_iter()),
        })
    }

    pub(crate) fn next(&mut self) -> Option<Value> {
        match self {
            LoopIter::Seq(items, i) => {
                let item = items.get(*i).cloned();
                *i += 1;
                item
            }
            LoopIter::Keys(entries, i) => {
                let key = entries.get_index(*i).map(|(k, _)| k.0.clone());
                *i += 1;
                key
            }
            LoopIter::Set(items, i) => {
                let item = items.get_index(*i).map(|k| k.0.clone());
                *i += 1;
                item
            }
            LoopIter::Items(items) => items.next(),
            LoopIter::Range { next, stop, step } => {
                let more = if *step > 0 { *next < *stop } else { *next > *stop };
                if !more {
                    return None;
                }
                let current = *next;
                match next.checked_add(*step) {
                    Some(n) => *next = n,
                    None => *next = *stop,
                }
                Some(Value::Int(current))
            }
        }
    }
}
