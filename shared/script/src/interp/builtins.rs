//! The builtin functions: `print`, conversions (`int`, `float`, `str`, ...),
//! containers (`list`, `dict`, `set`, `range`, ...), iteration helpers
//! (`enumerate`, `zip`, `sorted`, `map`, ...) and numeric helpers.

use super::{dict_insert, make_set, Interp};
use crate::args::{is_none, iterate, to_f64, to_i64, to_str, Args};
use crate::ast::BinOp;
use crate::error::{not_supported, type_error, value_error, ErrorKind, ScriptError};
use crate::stop;
use crate::value::heap::{self, DictMap, SetMap};
use crate::value::ops;
use crate::value::Value;

impl Interp<'_, '_> {
    pub(crate) fn builtin(&mut self, name: &str, args: Args) -> Result<Value, ScriptError> {
        match name {
            "print" => {
                let mut sep = " ".to_owned();
                let mut end = "\n".to_owned();
                for (k, v) in &args.kw {
                    match (k.as_str(), v) {
                        ("sep", Value::None) | ("end", Value::None) | ("flush", _) => {}
                        ("sep", Value::Str(s)) => sep = s.to_string(),
                        ("end", Value::Str(s)) => end = s.to_string(),
                        ("sep" | "end", other) => {
                            return Err(type_error(format!("{k} must be None or a string, not {}", other.type_name())))
                        }
                        ("file", _) => return Err(not_supported("print(file=...) is not supported")),
                        (other, _) => {
                            return Err(type_error(format!("'{other}' is an invalid keyword argument for print()")))
                        }
                    }
                }
                let text: Vec<String> = args.pos.iter().map(Value::try_to_str).collect::<Result<_, _>>()?;
                let line = format!("{}{end}", text.join(&sep));
                self.rt.print(&line)?;
                Ok(Value::None)
            }
            "type" => {
                let a = args.bind("type", &["object"], 1)?;
                Ok(Value::Type(a[0].as_ref().map_or("NoneType", Value::class_name)))
            }
            "str" => {
                let a = args.bind("str", &["object"], 0)?;
                Ok(Value::str(a[0].as_ref().map(Value::try_to_str).transpose()?.unwrap_or_default()))
            }
            "repr" => {
                let a = args.bind("repr", &["obj"], 1)?;
                Ok(Value::str(a[0].as_ref().map(Value::try_repr).transpose()?.unwrap_or_default()))
            }
            "int" => builtin_int(args),
            "float" => builtin_float(args),
            "bool" => {
                let a = args.bind("bool", &["x"], 0)?;
                Ok(Value::Bool(a[0].as_ref().is_some_and(Value::truthy)))
            }
            "len" => {
                let a = args.bind("len", &["obj"], 1)?;
                let n = match a[0].as_ref().unwrap_or(&Value::None) {
                    Value::Str(s) => s.chars().count(),
                    Value::List(v) | Value::Tuple(v) => v.len(),
                    Value::Dict(d) => d.len(),
                    Value::Set(v) => v.len(),
                    Value::Range(start, stop, step) => {
                        usize::try_from(crate::value::range_len(*start, *stop, *step)).unwrap_or(usize::MAX)
                    }
                    Value::Point(..) | Value::Size(..) => 2,
                    other => return Err(type_error(format!("object of type '{}' has no len()", other.type_name()))),
                };
                Ok(Value::Int(i64::try_from(n).unwrap_or(i64::MAX)))
            }
            "abs" => {
                let a = args.bind("abs", &["x"], 1)?;
                match a[0].as_ref().unwrap_or(&Value::None) {
                    Value::Float(f) => Ok(Value::Float(f.abs())),
                    v @ (Value::Int(_) | Value::Bool(_)) => {
                        let i = to_i64(v, "abs() argument")?;
                        i.checked_abs().map(Value::Int).ok_or_else(|| {
                            ScriptError::new(
                                ErrorKind::Overflow,
                                "integer overflow (this interpreter's integers are 64-bit)",
                            )
                        })
                    }
                    other => Err(type_error(format!("bad operand type for abs(): '{}'", other.type_name()))),
                }
            }
            "round" => {
                let a = args.bind("round", &["number", "ndigits"], 1)?;
                let number = a[0].clone().unwrap_or(Value::None);
                if is_none(&a[1]) {
                    return match number {
                        Value::Float(f) => ops::round_to_int(f).map(Value::Int),
                        Value::Int(_) | Value::Bool(_) => Ok(Value::Int(to_i64(&number, "number")?)),
                        other => Err(type_error(format!("type {} doesn't define __round__ method", other.type_name()))),
                    };
                }
                let ndigits = to_i64(a[1].as_ref().unwrap_or(&Value::None), "ndigits")?;
                ops::round_ndigits(&number, ndigits)
            }
            "min" | "max" => {
                let mut key = None;
                let mut default = None;
                for (k, v) in args.kw {
                    match k.as_str() {
                        "key" => key = Some(v).filter(|v| !matches!(v, Value::None)),
                        "default" => default = Some(v),
                        other => {
                            return Err(type_error(format!("'{other}' is an invalid keyword argument for {name}()")))
                        }
                    }
                }
                let items = match args.pos.len() {
                    0 => return Err(type_error(format!("{name} expected at least 1 argument, got 0"))),
                    1 => iterate(&args.pos[0])?,
                    _ => args.pos,
                };
                let mut best: Option<(Value, Value)> = None;
                for item in items {
                    let k = match &key {
                        Some(f) => self.call(f.clone(), Args { pos: vec![item.clone()], kw: Vec::new() })?,
                        None => item.clone(),
                    };
                    best = Some(match best {
                        None => (k, item),
                        Some((best_key, current)) => {
                            let ord = ops::compare(&k, &best_key)?;
                            let better = if name == "min" { ord.is_lt() } else { ord.is_gt() };
                            if better {
                                (k, item)
                            } else {
                                (best_key, current)
                            }
                        }
                    });
                }
                match (best, default) {
                    (Some((_, v)), _) => Ok(v),
                    (None, Some(d)) => Ok(d),
                    (None, None) => Err(value_error(format!("{name}() arg is an empty sequence"))),
                }
            }
            "sum" => {
                let a = args.bind("sum", &["iterable", "start"], 1)?;
                let mut total = a[1].clone().unwrap_or(Value::Int(0));
                with_items(a[0].as_ref().unwrap_or(&Value::None), |items| {
                    for item in items {
                        stop::work(1)?;
                        if matches!(item, Value::Str(_)) {
                            return Err(type_error("sum() can't sum strings [use ''.join(seq) instead]"));
                        }
                        if !matches!(item, Value::Int(_) | Value::Float(_) | Value::Bool(_)) {
                            return Err(not_supported("sum() of non-numbers is not supported"));
                        }
                        total = ops::binary(crate::ast::BinOp::Add, &total, item)?;
                    }
                    Ok(())
                })?;
                Ok(total)
            }
            "list" | "tuple" => {
                let a = args.bind(name, &["iterable"], 0)?;
                let items = match &a[0] {
                    Some(v) => iterate(v)?,
                    None => Vec::new(),
                };
                Ok(if name == "list" { Value::list(items) } else { Value::tuple(items) })
            }
            "dict" => {
                if args.pos.len() > 1 {
                    return Err(type_error(format!("dict expected at most 1 argument, got {}", args.pos.len())));
                }
                let mut entries = match args.pos.first() {
                    Some(Value::Dict(pairs)) => {
                        heap::reserve_items(pairs.len().saturating_mul(2))?;
                        DictMap::clone(pairs)
                    }
                    Some(other) => {
                        let mut entries = DictMap::new();
                        for (k, v) in super::methods::pairs_of(other)? {
                            dict_insert(&mut entries, k, v)?;
                        }
                        entries
                    }
                    None => DictMap::new(),
                };
                for (k, v) in args.kw {
                    dict_insert(&mut entries, Value::str(k), v)?;
                }
                Ok(Value::dict(entries))
            }
            "set" => {
                let a = args.bind("set", &["iterable"], 0)?;
                match &a[0] {
                    Some(v) => make_set(iterate(v)?),
                    None => Ok(Value::set(SetMap::new())),
                }
            }
            "range" => {
                if !args.kw.is_empty() {
                    return Err(type_error("range() takes no keyword arguments"));
                }
                let n: Vec<i64> = args.pos.iter().map(|v| to_i64(v, "range() argument")).collect::<Result<_, _>>()?;
                let (start, stop, step) = match n.as_slice() {
                    [stop] => (0, *stop, 1),
                    [start, stop] => (*start, *stop, 1),
                    [start, stop, step] => (*start, *stop, *step),
                    [] => return Err(type_error("range expected at least 1 argument, got 0")),
                    more => return Err(type_error(format!("range expected at most 3 arguments, got {}", more.len()))),
                };
                if step == 0 {
                    return Err(value_error("range() arg 3 must not be zero"));
                }
                Ok(Value::Range(start, stop, step))
            }
            "enumerate" => {
                let a = args.bind("enumerate", &["iterable", "start"], 1)?;
                let start = match &a[1] {
                    Some(v) => to_i64(v, "enumerate() start")?,
                    None => 0,
                };
                let items = iterate(a[0].as_ref().unwrap_or(&Value::None))?;
                let mut out = Vec::with_capacity(items.len());
                for (i, item) in items.into_iter().enumerate() {
                    let n = i64::try_from(i).ok().and_then(|i| i.checked_add(start)).ok_or_else(|| {
                        ScriptError::new(
                            ErrorKind::Overflow,
                            "integer overflow (this interpreter's integers are 64-bit)",
                        )
                    })?;
                    out.push(Value::tuple(vec![Value::Int(n), item]));
                }
                Ok(Value::list(out))
            }
            "zip" => {
                if let Some((k, _)) = args.kw.first() {
                    return Err(not_supported(format!("zip({k}=...) is not supported")));
                }
                let columns: Vec<Vec<Value>> = args.pos.iter().map(iterate).collect::<Result<_, _>>()?;
                let n = columns.iter().map(Vec::len).min().unwrap_or(0);
                Ok(Value::list((0..n).map(|i| Value::tuple(columns.iter().map(|c| c[i].clone()).collect())).collect()))
            }
            "sorted" => {
                if args.pos.len() != 1 {
                    return Err(type_error(format!("sorted expected 1 argument, got {}", args.pos.len())));
                }
                let mut key = None;
                let mut reverse = false;
                for (k, v) in args.kw {
                    match k.as_str() {
                        "key" => key = Some(v),
                        "reverse" => reverse = v.truthy(),
                        other => {
                            return Err(type_error(format!("'{other}' is an invalid keyword argument for sort()")))
                        }
                    }
                }
                let items = iterate(&args.pos[0])?;
                Ok(Value::list(self.sorted(items, key, reverse)?))
            }
            "reversed" => {
                let a = args.bind("reversed", &["sequence"], 1)?;
                let seq = a[0].clone().unwrap_or(Value::None);
                if matches!(seq, Value::Set(_) | Value::Dict(_)) {
                    return Err(type_error(format!("'{}' object is not reversible", seq.type_name())));
                }
                let mut items = iterate(&seq)?;
                items.reverse();
                Ok(Value::list(items))
            }
            "any" | "all" => {
                let a = args.bind(name, &["iterable"], 1)?;
                with_items(a[0].as_ref().unwrap_or(&Value::None), |items| {
                    stop::work(items.len() as u64)?;
                    Ok(Value::Bool(if name == "any" {
                        items.iter().any(Value::truthy)
                    } else {
                        items.iter().all(Value::truthy)
                    }))
                })
            }
            "isinstance" => {
                let a = args.bind("isinstance", &["obj", "class_or_tuple"], 2)?;
                let obj = a[0].clone().unwrap_or(Value::None);
                is_instance(&obj, a[1].as_ref().unwrap_or(&Value::None)).map(Value::Bool)
            }
            "map" => {
                if args.pos.len() < 2 {
                    return Err(type_error("map() must have at least two arguments."));
                }
                let mut pos = args.pos.into_iter();
                let f = pos.next().unwrap_or(Value::None);
                let columns: Vec<Vec<Value>> = pos.map(|v| iterate(&v)).collect::<Result<_, _>>()?;
                let n = columns.iter().map(Vec::len).min().unwrap_or(0);
                let mut out = Vec::with_capacity(n);
                for i in 0..n {
                    self.step()?;
                    let call_args = Args { pos: columns.iter().map(|c| c[i].clone()).collect(), kw: Vec::new() };
                    out.push(self.call(f.clone(), call_args)?);
                }
                Ok(Value::list(out))
            }
            "filter" => {
                let a = args.bind("filter", &["function", "iterable"], 2)?;
                let f = a[0].clone().unwrap_or(Value::None);
                let mut out = Vec::new();
                for item in iterate(a[1].as_ref().unwrap_or(&Value::None))? {
                    self.step()?;
                    let keep = match &f {
                        Value::None => item.truthy(),
                        f => self.call(f.clone(), Args { pos: vec![item.clone()], kw: Vec::new() })?.truthy(),
                    };
                    if keep {
                        out.push(item);
                    }
                }
                Ok(Value::list(out))
            }
            "divmod" => {
                let a = args.bind("divmod", &["x", "y"], 2)?;
                let (x, y) = (a[0].clone().unwrap_or(Value::None), a[1].clone().unwrap_or(Value::None));
                Ok(Value::tuple(vec![ops::binary(BinOp::FloorDiv, &x, &y)?, ops::binary(BinOp::Mod, &x, &y)?]))
            }
            "pow" => {
                let a = args.bind("pow", &["base", "exp", "mod"], 2)?;
                if !is_none(&a[2]) {
                    return Err(not_supported("pow() with a modulus is not supported"));
                }
                ops::binary(BinOp::Pow, a[0].as_ref().unwrap_or(&Value::None), a[1].as_ref().unwrap_or(&Value::None))
            }
            "format" => {
                let a = args.bind("format", &["value", "format_spec"], 1)?;
                let spec = match &a[1] {
                    Some(v) => to_str(v, "format() argument 2")?.to_owned(),
                    None => String::new(),
                };
                Ok(Value::str(crate::value::format::format_value(a[0].as_ref().unwrap_or(&Value::None), &spec)?))
            }
            "hex" | "oct" | "bin" => {
                let a = args.bind(name, &["number"], 1)?;
                let v = a[0].clone().unwrap_or(Value::None);
                if !matches!(v, Value::Int(_) | Value::Bool(_)) {
                    return Err(type_error(format!("'{}' object cannot be interpreted as an integer", v.type_name())));
                }
                let spec = match name {
                    "hex" => "#x",
                    "oct" => "#o",
                    _ => "#b",
                };
                Ok(Value::str(crate::value::format::format_value(&v, spec)?))
            }
            "chr" => {
                let a = args.bind("chr", &["i"], 1)?;
                let i = to_i64(a[0].as_ref().unwrap_or(&Value::None), "chr() argument")?;
                u32::try_from(i)
                    .ok()
                    .and_then(char::from_u32)
                    .map(|c| Value::str(c.to_string()))
                    .ok_or_else(|| value_error("chr() arg not in range(0x110000) or a surrogate"))
            }
            "ord" => {
                let a = args.bind("ord", &["c"], 1)?;
                let s = to_str(a[0].as_ref().unwrap_or(&Value::None), "ord() argument")?;
                let mut chars = s.chars();
                match (chars.next(), chars.next()) {
                    (Some(c), None) => Ok(Value::Int(i64::from(u32::from(c)))),
                    _ => Err(type_error(format!(
                        "ord() expected a character, but string of length {} found",
                        s.chars().count()
                    ))),
                }
            }
            "exit" | "quit" => {
                let a = args.bind(name, &["code"], 0)?;
                Err(crate::stdlib::exit_with(&mut self.rt, a[0].clone()))
            }
            other => Err(not_supported(format!("{other}() is not supported by this interpreter"))),
        }
    }

    /// `sorted(items, key=key, reverse=reverse)`: a stable merge sort that stops at the
    /// first comparison Python would refuse.
    pub(crate) fn sorted(
        &mut self,
        items: Vec<Value>,
        key: Option<Value>,
        reverse: bool,
    ) -> Result<Vec<Value>, ScriptError> {
        let keys = match key.filter(|k| !matches!(k, Value::None)) {
            Some(f) => {
                let mut keys = Vec::with_capacity(items.len());
                for item in &items {
                    self.step()?;
                    keys.push(self.call(f.clone(), Args { pos: vec![item.clone()], kw: Vec::new() })?);
                }
                keys
            }
            None => {
                heap::reserve_items(items.len())?;
                items.clone()
            }
        };
        let order = merge_sort((0..items.len()).collect(), &mut |a, b| {
            stop::work(1)?;
            // `b` goes first when it is strictly smaller (strictly larger when reversed).
            let (x, y) = if reverse { (&keys[b], &keys[a]) } else { (&keys[a], &keys[b]) };
            Ok(ops::compare(x, y)?.is_gt())
        })?;
        let mut slots: Vec<Option<Value>> = items.into_iter().map(Some).collect();
        Ok(order.into_iter().filter_map(|i| slots[i].take()).collect())
    }
}

/// Sorts positions stably; `right_first(a, b)` says whether `b` must come before `a`.
fn merge_sort(
    items: Vec<usize>,
    right_first: &mut dyn FnMut(usize, usize) -> Result<bool, ScriptError>,
) -> Result<Vec<usize>, ScriptError> {
    if items.len() <= 1 {
        return Ok(items);
    }
    let mut left = items;
    let right = left.split_off(left.len() / 2);
    let left = merge_sort(left, right_first)?;
    let right = merge_sort(right, right_first)?;
    let mut out = Vec::with_capacity(left.len() + right.len());
    let (mut i, mut j) = (0, 0);
    while i < left.len() && j < right.len() {
        if right_first(left[i], right[j])? {
            out.push(right[j]);
            j += 1;
        } else {
            out.push(left[i]);
            i += 1;
        }
    }
    out.extend_from_slice(&left[i..]);
    out.extend_from_slice(&right[j..]);
    Ok(out)
}

/// `isinstance(obj, class_or_tuple)` for the builtin types and exception classes.
fn is_instance(obj: &Value, class: &Value) -> Result<bool, ScriptError> {
    match class {
        Value::Tuple(classes) => {
            for c in classes.iter() {
                if is_instance(obj, c)? {
                    return Ok(true);
                }
            }
            Ok(false)
        }
        Value::Function { module: "", name }
            if matches!(*name, "int" | "float" | "str" | "bool" | "list" | "tuple" | "dict" | "set" | "range") =>
        {
            let t = obj.type_name();
            Ok(t == *name
                || (*name == "int" && t == "bool")
                || (*name == "tuple" && matches!(obj, Value::Point(..) | Value::Size(..))))
        }
        Value::ExcType(kind) => Ok(matches!(obj, Value::Exception(k, _) if k.is_subclass_of(*kind))),
        Value::Type(name) => Ok(obj.class_name() == *name),
        _ => Err(type_error("isinstance() arg 2 must be a type, a tuple of types, or a union")),
    }
}

fn builtin_int(args: Args) -> Result<Value, ScriptError> {
    let a = args.bind("int", &["x", "base"], 0)?;
    let Some(x) = &a[0] else { return Ok(Value::Int(0)) };
    if let Some(base) = &a[1] {
        let base = to_i64(base, "int() base")?;
        let s = to_str(x, "int() can't convert non-string with explicit base; argument")?;
        return parse_int(s, base);
    }
    match x {
        Value::Bool(b) => Ok(Value::Int(i64::from(*b))),
        Value::Int(i) => Ok(Value::Int(*i)),
        Value::Float(f) => {
            if f.is_nan() {
                return Err(value_error("cannot convert float NaN to integer"));
            }
            if f.is_infinite() {
                return Err(ScriptError::new(ErrorKind::Overflow, "cannot convert float infinity to integer"));
            }
            let t = f.trunc();
            if !(-9.223_372_036_854_776e18..9.223_372_036_854_776e18).contains(&t) {
                return Err(ScriptError::new(
                    ErrorKind::Overflow,
                    "integer overflow (this interpreter's integers are 64-bit)",
                ));
            }
            Ok(Value::Int(t as i64))
        }
        Value::Str(s) => parse_int(s, 10),
        other => Err(type_error(format!(
            "int() argument must be a string, a bytes-like object or a real number, not '{}'",
            other.type_name()
        ))),
    }
}

fn parse_int(s: &str, base: i64) -> Result<Value, ScriptError> {
    let invalid = || value_error(format!("invalid literal for int() with base {base}: {}", crate::value::str_repr(s)));
    if !(base == 0 || (2..=36).contains(&base)) {
        return Err(value_error("int() base must be >= 2 and <= 36, or 0"));
    }
    let t = s.trim();
    let (neg, t) = match t.strip_prefix('-') {
        Some(rest) => (true, rest),
        None => (false, t.strip_prefix('+').unwrap_or(t)),
    };
    let lower = t.to_ascii_lowercase();
    let (radix, digits) = match (base, lower.get(..2)) {
        (0 | 16, Some("0x")) => (16, &t[2..]),
        (0 | 8, Some("0o")) => (8, &t[2..]),
        (0 | 2, Some("0b")) => (2, &t[2..]),
        (0, _) => (10, t),
        (b, _) => (u32::try_from(b).unwrap_or(10), t),
    };
    let digits = digits.strip_prefix('_').filter(|_| radix != 10 || base == 0).unwrap_or(digits);
    if digits.is_empty() || digits.starts_with('_') || digits.ends_with('_') || digits.contains("__") {
        return Err(invalid());
    }
    let clean: String = digits.chars().filter(|c| *c != '_').collect();
    if !clean.chars().all(|c| c.is_digit(radix)) {
        return Err(invalid());
    }
    let value = i64::from_str_radix(&clean, radix).map_err(|_| {
        ScriptError::new(ErrorKind::Overflow, "integer overflow (this interpreter's integers are 64-bit)")
    })?;
    Ok(Value::Int(if neg { -value } else { value }))
}

fn builtin_float(args: Args) -> Result<Value, ScriptError> {
    let a = args.bind("float", &["x"], 0)?;
    match &a[0] {
        None => Ok(Value::Float(0.0)),
        Some(Value::Str(s)) => {
            let t = s.trim();
            let lower = t.to_ascii_lowercase();
            let unsigned = lower.trim_start_matches(['+', '-']);
            let special = matches!(unsigned, "inf" | "infinity" | "nan");
            let valid_chars = t.chars().all(|c| c.is_ascii_digit() || matches!(c, '.' | 'e' | 'E' | '+' | '-' | '_'));
            let parsed = if special || (valid_chars && !t.contains("__") && !t.starts_with('_') && !t.ends_with('_')) {
                t.replace('_', "").parse::<f64>().ok()
            } else {
                None
            };
            parsed
                .map(Value::Float)
                .ok_or_else(|| value_error(format!("could not convert string to float: {}", crate::value::str_repr(s))))
        }
        Some(v @ (Value::Int(_) | Value::Bool(_) | Value::Float(_))) => Ok(Value::Float(to_f64(v, "x")?)),
        Some(other) => {
            Err(type_error(format!("float() argument must be a string or a real number, not '{}'", other.type_name())))
        }
    }
}

/// Runs `f` over the items of an iterable: a list's or tuple's own items, without
/// copying them, or the items [`iterate`] makes of anything else.
fn with_items<T>(v: &Value, f: impl FnOnce(&[Value]) -> Result<T, ScriptError>) -> Result<T, ScriptError> {
    match v {
        Value::List(items) | Value::Tuple(items) => f(items),
        other => f(&iterate(other)?),
    }
}
