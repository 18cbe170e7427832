//! The methods of plain values: `str`, `list`, `tuple`, `dict` and `set`, and the
//! call of a method on any receiver.
//!
//! Methods that change their receiver (`append`, `update`, `sort`, ...) run on
//! the variable the receiver expression names (see `Interp::call_mutating`);
//! called on a temporary value they change only that copy.

use super::{check_hashable, dict_insert, make_set, Interp};
use crate::args::{iterate, no_attribute, to_i64, to_str, Args};
use crate::compose::Composed as _;
use crate::error::{not_supported, type_error, value_error, ErrorKind, ScriptError};
use crate::stop;
use crate::value::heap::{self, Key};
use crate::value::ops;
use crate::value::{Object, Value};

pub(crate) const STR_METHODS: &[&str] = &[
    "lower",
    "upper",
    "strip",
    "lstrip",
    "rstrip",
    "startswith",
    "endswith",
    "replace",
    "split",
    "rsplit",
    "join",
    "find",
    "rfind",
    "index",
    "rindex",
    "count",
    "splitlines",
    "title",
    "capitalize",
    "casefold",
    "swapcase",
    "isdigit",
    "isdecimal",
    "isnumeric",
    "isalpha",
    "isalnum",
    "isspace",
    "isupper",
    "islower",
    "istitle",
    "format",
    "zfill",
    "center",
    "ljust",
    "rjust",
    "partition",
    "rpartition",
    "removeprefix",
    "removesuffix",
];
pub(crate) const LIST_METHODS: &[&str] =
    &["append", "extend", "insert", "pop", "remove", "clear", "sort", "reverse", "index", "count", "copy"];
pub(crate) const TUPLE_METHODS: &[&str] = &["index", "count"];
pub(crate) const DICT_METHODS: &[&str] =
    &["get", "keys", "values", "items", "update", "pop", "setdefault", "clear", "copy", "popitem"];
pub(crate) const SET_METHODS: &[&str] = &[
    "add",
    "discard",
    "remove",
    "update",
    "clear",
    "pop",
    "copy",
    "union",
    "intersection",
    "difference",
    "issubset",
    "issuperset",
    "isdisjoint",
];

/// Whether `name` is a method that changes a list, dict or set.
pub(crate) fn is_mutating(name: &str) -> bool {
    matches!(
        name,
        "append"
            | "extend"
            | "insert"
            | "pop"
            | "remove"
            | "clear"
            | "sort"
            | "reverse"
            | "update"
            | "setdefault"
            | "popitem"
            | "add"
            | "discard"
    )
}

/// Whether `target` has the changing method `name`.
pub(crate) fn mutates(target: &Value, name: &str) -> bool {
    let methods: &[&str] = match target {
        Value::List(_) => LIST_METHODS,
        Value::Dict(_) => DICT_METHODS,
        Value::Set(_) => SET_METHODS,
        _ => &[],
    };
    methods.contains(&name) && is_mutating(name)
}

fn int_value(i: usize) -> Value {
    Value::Int(i64::try_from(i).unwrap_or(i64::MAX))
}

impl Interp<'_, '_> {
    pub(crate) fn call_method(&mut self, recv: Value, name: &'static str, args: Args) -> Result<Value, ScriptError> {
        match &recv {
            Value::Str(s) => str_method(s, name, args),
            Value::List(_) | Value::Tuple(_) | Value::Set(_) | Value::Dict(_) => {
                if is_mutating(name) {
                    // A method called on a value that no variable holds changes only that copy.
                    let mut copy = recv.clone();
                    return self.mutate(&mut copy, name, args);
                }
                self.container_method(&recv, name, args)
            }
            Value::Object(Object::Environ) => {
                let a = args.bind("get", &["key", "default"], 1)?;
                let key = a[0].clone().unwrap_or(Value::None);
                let name = to_str(&key, "environment variable name")?;
                Ok(self.rt.host.env_var(name).map(Value::str).unwrap_or_else(|| a[1].clone().unwrap_or(Value::None)))
            }
            Value::Object(Object::Image { region, .. }) => {
                let a = args.bind("save", &["fp", "format"], 1)?;
                let path = a[0].clone().unwrap_or(Value::None);
                let path = to_str(&path, "save() path")?.to_owned();
                let format = match &a[1] {
                    None | Some(Value::None) => None,
                    Some(format) => Some(to_str(format, "save() format")?.to_owned()),
                };
                let result = self.rt.host.save_screenshot(&path, *region, format.as_deref());
                self.rt.host(result)?;
                Ok(Value::None)
            }
            Value::Object(Object::Completed { args: cmd, returncode, stdout, stderr }) => {
                args.bind("check_returncode", &[], 0)?;
                if *returncode != 0 {
                    return Err(crate::stdlib::called_process_error(cmd, *returncode, stdout.clone(), stderr.clone()));
                }
                Ok(Value::None)
            }
            Value::Object(object) => crate::computer::call_method(&mut self.rt, object.clone(), name, args),
            other => Err(no_attribute(other, name)),
        }
    }

    /// A method of a list, tuple, dict or set that leaves it unchanged.
    fn container_method(&mut self, recv: &Value, name: &str, args: Args) -> Result<Value, ScriptError> {
        match (recv, name) {
            (Value::List(items) | Value::Tuple(items), "index") => {
                let a = args.bind("index", &["value"], 1)?;
                let v = a[0].clone().unwrap_or(Value::None);
                stop::work(items.len() as u64)?;
                items.iter().position(|x| ops::equal(x, &v)).map(int_value).ok_or_else(|| {
                    let what = if matches!(recv, Value::List(_)) {
                        "list.index(x): x not in list"
                    } else {
                        "tuple.index(x): x not in tuple"
                    };
                    value_error(what)
                })
            }
            (Value::List(items) | Value::Tuple(items), "count") => {
                let a = args.bind("count", &["value"], 1)?;
                let v = a[0].clone().unwrap_or(Value::None);
                stop::work(items.len() as u64)?;
                Ok(int_value(items.iter().filter(|x| ops::equal(x, &v)).count()))
            }
            (Value::List(_) | Value::Dict(_) | Value::Set(_), "copy") => {
                args.bind("copy", &[], 0)?;
                Ok(recv.clone())
            }
            (Value::Dict(entries), "get") => {
                let a = args.bind("get", &["key", "default"], 1)?;
                let key = a[0].clone().unwrap_or(Value::None);
                check_hashable(&key)?;
                Ok(entries.get(&Key(key)).cloned().unwrap_or_else(|| a[1].clone().unwrap_or(Value::None)))
            }
            (Value::Dict(entries), "keys") => {
                args.bind("keys", &[], 0)?;
                heap::reserve_items(entries.len())?;
                Ok(Value::list(entries.keys().map(|k| k.0.clone()).collect()))
            }
            (Value::Dict(entries), "values") => {
                args.bind("values", &[], 0)?;
                heap::reserve_items(entries.len())?;
                Ok(Value::list(entries.values().cloned().collect()))
            }
            (Value::Dict(entries), "items") => {
                args.bind("items", &[], 0)?;
                // A list of two-item tuples.
                heap::reserve_items(entries.len().saturating_mul(3))?;
                Ok(Value::list(entries.iter().map(|(k, v)| Value::tuple(vec![k.0.clone(), v.clone()])).collect()))
            }
            (Value::Set(items), "union" | "intersection" | "difference" | "issubset" | "issuperset" | "isdisjoint") => {
                let a = args.bind(name, &["other"], 1)?;
                let other = match make_set(iterate(a[0].as_ref().unwrap_or(&Value::None))?)? {
                    Value::Set(other) => other,
                    _ => return Err(type_error("a set was expected")),
                };
                heap::reserve_items(items.len().saturating_add(other.len()))?;
                Ok(match name {
                    "union" => Value::set(items.iter().chain(other.iter()).cloned().collect()),
                    "intersection" => Value::set(items.iter().filter(|v| other.contains(*v)).cloned().collect()),
                    "difference" => Value::set(items.iter().filter(|v| !other.contains(*v)).cloned().collect()),
                    "issubset" => Value::Bool(items.iter().all(|v| other.contains(v))),
                    "issuperset" => Value::Bool(other.iter().all(|v| items.contains(v))),
                    _ => Value::Bool(!items.iter().any(|v| other.contains(v))),
                })
            }
            (other, _) => Err(no_attribute(other, name)),
        }
    }

    /// A method that changes `target` in place; returns what the method returns.
    /// A payload shared with another value is copied first (see `heap`).
    pub(crate) fn mutate(&mut self, target: &mut Value, name: &str, args: Args) -> Result<Value, ScriptError> {
        match target {
            Value::List(heap) => match name {
                "append" => {
                    let a = args.bind("append", &["object"], 1)?;
                    check_len(heap.len() + 1)?;
                    let item = a[0].clone().unwrap_or(Value::None);
                    let mut items = heap.make_mut();
                    grow(&items, items.capacity(), 1)?;
                    items.adopt(&item);
                    items.push(item);
                    Ok(Value::None)
                }
                "extend" => {
                    let a = args.bind("extend", &["iterable"], 1)?;
                    let more = iterate(a[0].as_ref().unwrap_or(&Value::None))?;
                    check_len(heap.len() + more.len())?;
                    let mut items = heap.make_mut();
                    grow(&items, items.capacity(), more.len())?;
                    for item in &more {
                        items.adopt(item);
                    }
                    items.extend(more);
                    Ok(Value::None)
                }
                "insert" => {
                    let a = args.bind("insert", &["index", "object"], 2)?;
                    let i = to_i64(a[0].as_ref().unwrap_or(&Value::None), "insert() index")?;
                    let len = i64::try_from(heap.len()).unwrap_or(i64::MAX);
                    let at = if i < 0 { (i + len).max(0) } else { i.min(len) };
                    check_len(heap.len() + 1)?;
                    let item = a[1].clone().unwrap_or(Value::None);
                    let mut items = heap.make_mut();
                    grow(&items, items.capacity(), 1)?;
                    items.adopt(&item);
                    items.insert(usize::try_from(at).unwrap_or(0), item);
                    Ok(Value::None)
                }
                "pop" => {
                    let a = args.bind("pop", &["index"], 0)?;
                    if heap.is_empty() {
                        return Err(ScriptError::new(ErrorKind::Index, "pop from empty list"));
                    }
                    let i = match &a[0] {
                        None => heap.len() - 1,
                        Some(index) => super::seq_index(heap.len(), index, "list")
                            .map_err(|_| ScriptError::new(ErrorKind::Index, "pop index out of range"))?,
                    };
                    Ok(heap.make_mut().remove(i))
                }
                "remove" => {
                    let a = args.bind("remove", &["value"], 1)?;
                    let v = a[0].clone().unwrap_or(Value::None);
                    stop::work(heap.len() as u64)?;
                    let i = heap
                        .iter()
                        .position(|x| ops::equal(x, &v))
                        .ok_or_else(|| value_error("list.remove(x): x not in list"))?;
                    heap.make_mut().remove(i);
                    Ok(Value::None)
                }
                "clear" => {
                    args.bind("clear", &[], 0)?;
                    heap.make_mut().clear();
                    Ok(Value::None)
                }
                "reverse" => {
                    args.bind("reverse", &[], 0)?;
                    let mut items = heap.make_mut();
                    // In slices, so that a long reversal stops at its deadline.
                    let len = items.len();
                    let mut done = 0;
                    while done < len / 2 {
                        let chunk = (len / 2 - done).min(crate::stop::WORK_SLICE as usize);
                        for i in done..done + chunk {
                            items.swap(i, len - 1 - i);
                        }
                        done += chunk;
                        stop::work(chunk as u64)?;
                    }
                    Ok(Value::None)
                }
                "sort" => {
                    if !args.pos.is_empty() {
                        return Err(type_error("sort() takes no positional arguments"));
                    }
                    let a = args.bind("sort", &["key", "reverse"], 0)?;
                    let taken = std::mem::take(&mut *heap.make_mut());
                    let sorted = self.sorted(taken, a[0].clone(), a[1].as_ref().is_some_and(Value::truthy))?;
                    *heap.make_mut() = sorted;
                    Ok(Value::None)
                }
                _ => Err(no_attribute(target, name)),
            },
            Value::Dict(heap) => match name {
                "update" => {
                    if args.pos.len() > 1 {
                        return Err(type_error(format!("update expected at most 1 argument, got {}", args.pos.len())));
                    }
                    let a = (args.pos.into_iter().next(), args.kw);
                    let mut entries = heap.make_mut();
                    if let Some(other) = a.0 {
                        let pairs: Vec<(Value, Value)> = match other {
                            Value::Dict(pairs) => {
                                heap::reserve_items(pairs.len().saturating_mul(2))?;
                                pairs.iter().map(|(k, v)| (k.0.clone(), v.clone())).collect()
                            }
                            other => pairs_of(&other)?,
                        };
                        for (k, v) in pairs {
                            entries.adopt(&k);
                            entries.adopt(&v);
                            dict_insert(&mut entries, k, v)?;
                        }
                    }
                    for (k, v) in a.1 {
                        entries.adopt(&v);
                        dict_insert(&mut entries, Value::str(k), v)?;
                    }
                    Ok(Value::None)
                }
                "pop" => {
                    let has_default = args.pos.len() > 1;
                    let a = args.bind("pop", &["key", "default"], 1)?;
                    let key = a[0].clone().unwrap_or(Value::None);
                    check_hashable(&key)?;
                    if !heap.contains_key(&Key(key.clone())) {
                        return match has_default {
                            true => Ok(a[1].clone().unwrap_or(Value::None)),
                            false => Err(ScriptError::new(ErrorKind::Key, key.repr())),
                        };
                    }
                    Ok(heap.make_mut().shift_remove(&Key(key)).unwrap_or(Value::None))
                }
                "setdefault" => {
                    let a = args.bind("setdefault", &["key", "default"], 1)?;
                    let key = a[0].clone().unwrap_or(Value::None);
                    check_hashable(&key)?;
                    if let Some(v) = heap.get(&Key(key.clone())) {
                        return Ok(v.clone());
                    }
                    let default = a[1].clone().unwrap_or(Value::None);
                    let mut entries = heap.make_mut();
                    entries.adopt(&key);
                    entries.adopt(&default);
                    dict_insert(&mut entries, key, default.clone())?;
                    Ok(default)
                }
                "popitem" => {
                    args.bind("popitem", &[], 0)?;
                    let (k, v) = heap
                        .make_mut()
                        .pop()
                        .ok_or_else(|| ScriptError::new(ErrorKind::Key, "'popitem(): dictionary is empty'"))?;
                    Ok(Value::tuple(vec![k.0, v]))
                }
                "clear" => {
                    args.bind("clear", &[], 0)?;
                    heap.make_mut().clear();
                    Ok(Value::None)
                }
                _ => Err(no_attribute(target, name)),
            },
            Value::Set(heap) => match name {
                "add" | "discard" | "remove" => {
                    let a = args.bind(name, &["elem"], 1)?;
                    let v = a[0].clone().unwrap_or(Value::None);
                    check_hashable(&v)?;
                    let present = heap.contains(&Key(v.clone()));
                    match (name, present) {
                        ("add", false) => {
                            let mut items = heap.make_mut();
                            grow_table(items.len(), items.capacity(), SET_ENTRY)?;
                            items.adopt(&v);
                            items.insert(Key(v));
                        }
                        ("discard" | "remove", true) => {
                            heap.make_mut().shift_remove(&Key(v));
                        }
                        ("remove", false) => return Err(ScriptError::new(ErrorKind::Key, v.repr())),
                        _ => {}
                    }
                    Ok(Value::None)
                }
                "update" => {
                    let a = args.bind("update", &["other"], 1)?;
                    let more = iterate(a[0].as_ref().unwrap_or(&Value::None))?;
                    for item in &more {
                        check_hashable(item)?;
                    }
                    let mut items = heap.make_mut();
                    grow_table(items.len() + more.len(), items.capacity(), SET_ENTRY)?;
                    for item in more {
                        items.adopt(&item);
                        items.insert(Key(item));
                    }
                    Ok(Value::None)
                }
                "pop" => {
                    args.bind("pop", &[], 0)?;
                    if heap.is_empty() {
                        return Err(ScriptError::new(ErrorKind::Key, "'pop from an empty set'"));
                    }
                    Ok(heap.make_mut().shift_remove_index(0).map_or(Value::None, |k| k.0))
                }
                "clear" => {
                    args.bind("clear", &[], 0)?;
                    heap.make_mut().clear();
                    Ok(Value::None)
                }
                _ => Err(no_attribute(target, name)),
            },
            other => Err(no_attribute(other, name)),
        }
    }
}

/// What one set entry weighs besides its slot (see `heap`).
const SET_ENTRY: usize = heap::SLOT + 2 * std::mem::size_of::<usize>();

/// Reserves, against the memory budget, what `more` items pushed onto `items` would
/// make it grow by (a vector doubles its room when it is full).
fn grow(items: &[Value], capacity: usize, more: usize) -> Result<(), ScriptError> {
    let needed = items.len().saturating_add(more);
    if needed <= capacity {
        return Ok(());
    }
    heap::reserve_items(needed.max(capacity.saturating_mul(2)) - capacity)
}

/// Reserves what a table of `capacity` entries grows by to hold `len` entries.
pub(crate) fn grow_table(len: usize, capacity: usize, entry: usize) -> Result<(), ScriptError> {
    if len < capacity {
        return Ok(());
    }
    heap::reserve(capacity.max(len).max(4).saturating_mul(entry))
}

fn check_len(len: usize) -> Result<(), ScriptError> {
    if len > ops::MAX_ITEMS {
        return Err(ScriptError::new(ErrorKind::Memory, format!("result would exceed {} items", ops::MAX_ITEMS)));
    }
    Ok(())
}

/// The `(key, value)` pairs of an iterable of 2-item sequences, as `dict()` reads them.
pub(crate) fn pairs_of(v: &Value) -> Result<Vec<(Value, Value)>, ScriptError> {
    let mut pairs = Vec::new();
    for (i, item) in iterate(v)?.into_iter().enumerate() {
        match iterate(&item)?.as_slice() {
            [k, v] => pairs.push((k.clone(), v.clone())),
            other => {
                return Err(value_error(format!(
                    "dictionary update sequence element #{i} has length {}; 2 is required",
                    other.len()
                )))
            }
        }
    }
    Ok(pairs)
}

fn str_method(s: &str, name: &str, args: Args) -> Result<Value, ScriptError> {
    let text = |v: String| Ok(Value::str(v));
    match name {
        "lower" => {
            args.bind("lower", &[], 0)?;
            text(s.to_lowercase())
        }
        "upper" => {
            args.bind("upper", &[], 0)?;
            text(s.to_uppercase())
        }
        "strip" | "lstrip" | "rstrip" => {
            let a = args.bind(name, &["chars"], 0)?;
            let chars: Option<Vec<char>> = match &a[0] {
                None | Some(Value::None) => None,
                Some(v) => Some(to_str(v, "strip arg")?.chars().collect()),
            };
            let pred = |c: char| chars.as_ref().map_or(c.is_whitespace(), |set| set.contains(&c));
            text(match name {
                "strip" => s.trim_matches(pred).to_owned(),
                "lstrip" => s.trim_start_matches(pred).to_owned(),
                _ => s.trim_end_matches(pred).to_owned(),
            })
        }
        "startswith" | "endswith" => {
            let a = args.bind(name, &["prefix"], 1)?;
            let arg = a[0].clone().unwrap_or(Value::None);
            let candidates = match &arg {
                Value::Tuple(items) => items.to_vec(),
                other => vec![other.clone()],
            };
            let mut hit = false;
            for c in &candidates {
                let c = to_str(c, &format!("{name} first arg"))?;
                hit |= if name == "startswith" { s.starts_with(c) } else { s.ends_with(c) };
            }
            Ok(Value::Bool(hit))
        }
        "replace" => {
            let a = args.bind("replace", &["old", "new", "count"], 2)?;
            let old = to_str(a[0].as_ref().unwrap_or(&Value::None), "replace() argument 1")?;
            let new = to_str(a[1].as_ref().unwrap_or(&Value::None), "replace() argument 2")?;
            let count = match &a[2] {
                Some(v) => to_i64(v, "count")?,
                None => -1,
            };
            let occurrences = if old.is_empty() { s.chars().count() + 1 } else { s.matches(old).count() };
            let occurrences =
                if count < 0 { occurrences } else { occurrences.min(usize::try_from(count).unwrap_or(usize::MAX)) };
            if occurrences.saturating_mul(new.len()).saturating_add(s.len()) > ops::MAX_LEN {
                return Err(ScriptError::new(ErrorKind::Memory, "result too large"));
            }
            text(if count < 0 { s.replace(old, new) } else { s.replacen(old, new, occurrences) })
        }
        "split" | "rsplit" => {
            let a = args.bind(name, &["sep", "maxsplit"], 0)?;
            let max = match &a[1] {
                None | Some(Value::None) => -1,
                Some(v) => to_i64(v, "maxsplit")?,
            };
            if s.len() > ops::MAX_ITEMS {
                return Err(ScriptError::new(ErrorKind::Memory, "string too long to split"));
            }
            let limit = usize::try_from(max).ok();
            let parts: Vec<String> = match &a[0] {
                None | Some(Value::None) => split_whitespace(s, limit, name == "rsplit"),
                Some(v) => {
                    let sep = to_str(v, "must be str or None; sep")?;
                    if sep.is_empty() {
                        return Err(value_error("empty separator"));
                    }
                    match (limit, name == "rsplit") {
                        (None, _) => s.split(sep).map(str::to_owned).collect(),
                        (Some(n), false) => s.splitn(n + 1, sep).map(str::to_owned).collect(),
                        (Some(n), true) => {
                            let mut parts: Vec<String> = s.rsplitn(n + 1, sep).map(str::to_owned).collect();
                            parts.reverse();
                            parts
                        }
                    }
                }
            };
            Ok(Value::list(parts.into_iter().map(Value::str).collect()))
        }
        "splitlines" => {
            args.bind("splitlines", &[], 0)?;
            if s.len() > ops::MAX_ITEMS {
                return Err(ScriptError::new(ErrorKind::Memory, "string too long to split"));
            }
            Ok(Value::list(s.lines().map(|p| Value::str(p.to_owned())).collect()))
        }
        "join" => {
            let a = args.bind("join", &["iterable"], 1)?;
            let mut parts = Vec::new();
            for (i, item) in iterate(a[0].as_ref().unwrap_or(&Value::None))?.into_iter().enumerate() {
                match item {
                    Value::Str(p) => parts.push(p),
                    other => {
                        return Err(type_error(format!(
                            "sequence item {i}: expected str instance, {} found",
                            other.type_name()
                        )))
                    }
                }
            }
            let total =
                parts.iter().map(|p| p.len()).sum::<usize>().saturating_add(s.len().saturating_mul(parts.len()));
            if total > ops::MAX_LEN {
                return Err(ScriptError::new(ErrorKind::Memory, "result too large"));
            }
            heap::reserve_text(total)?;
            let mut joined = String::with_capacity(total);
            for (i, part) in parts.iter().enumerate() {
                if i > 0 {
                    joined.push_str(s);
                }
                joined.push_str(part);
                stop::work(1)?;
            }
            text(joined)
        }
        "find" | "rfind" | "index" | "rindex" | "count" => {
            let a = args.bind(name, &["sub", "start", "end"], 1)?;
            let sub = to_str(a[0].as_ref().unwrap_or(&Value::None), "must be str; argument")?;
            let chars: Vec<char> = s.chars().collect();
            let len = i64::try_from(chars.len()).unwrap_or(i64::MAX);
            let bound = |v: &Option<Value>, default: i64| -> Result<usize, ScriptError> {
                let i = match v {
                    None | Some(Value::None) => default,
                    Some(v) => to_i64(v, "slice index")?,
                };
                let i = if i < 0 { (i + len).max(0) } else { i.min(len) };
                Ok(usize::try_from(i).unwrap_or(0))
            };
            let (start, end) = (bound(&a[1], 0)?, bound(&a[2], len)?);
            let window: String = if start <= end { chars[start..end].iter().collect() } else { String::new() };
            let to_chars = |byte: usize| window[..byte].chars().count() + start;
            let found = match name {
                "count" => {
                    let n = if start > end {
                        0
                    } else if sub.is_empty() {
                        window.chars().count() + 1
                    } else {
                        window.matches(sub).count()
                    };
                    return Ok(int_value(n));
                }
                "find" | "index" => window.find(sub).map(to_chars),
                _ => window.rfind(sub).map(to_chars),
            };
            match (found, name) {
                (Some(i), _) => Ok(int_value(i)),
                (None, "find" | "rfind") => Ok(Value::Int(-1)),
                (None, _) => Err(value_error("substring not found")),
            }
        }
        "title" | "capitalize" | "casefold" | "swapcase" => {
            args.bind(name, &[], 0)?;
            text(match name {
                "title" => title_case(s),
                "capitalize" => {
                    let mut chars = s.chars();
                    match chars.next() {
                        Some(first) => first.to_uppercase().chain(chars.flat_map(char::to_lowercase)).collect(),
                        None => String::new(),
                    }
                }
                "casefold" => s.to_lowercase(),
                _ => s
                    .chars()
                    .flat_map(|c| -> Vec<char> {
                        if c.is_uppercase() {
                            c.to_lowercase().collect()
                        } else {
                            c.to_uppercase().collect()
                        }
                    })
                    .collect(),
            })
        }
        "isdigit" | "isdecimal" | "isnumeric" | "isalpha" | "isalnum" | "isspace" | "isupper" | "islower"
        | "istitle" => {
            args.bind(name, &[], 0)?;
            let nonempty = !s.is_empty();
            let cased = s.chars().any(|c| c.is_uppercase() || c.is_lowercase());
            Ok(Value::Bool(match name {
                "isdigit" | "isdecimal" => nonempty && s.chars().all(|c| c.is_ascii_digit()),
                "isnumeric" => nonempty && s.chars().all(char::is_numeric),
                "isalpha" => nonempty && s.chars().all(char::is_alphabetic),
                "isalnum" => nonempty && s.chars().all(char::is_alphanumeric),
                "isspace" => nonempty && s.chars().all(char::is_whitespace),
                "isupper" => cased && !s.chars().any(char::is_lowercase),
                "islower" => cased && !s.chars().any(char::is_uppercase),
                _ => cased && title_case(s) == s,
            }))
        }
        "format" => Ok(Value::str(crate::value::format::str_format(s, &args.pos, &args.kw)?)),
        "zfill" => {
            let a = args.bind("zfill", &["width"], 1)?;
            let width = usize::try_from(to_i64(a[0].as_ref().unwrap_or(&Value::None), "width")?).unwrap_or(0);
            let len = s.chars().count();
            if width <= len {
                return text(s.to_owned());
            }
            check_str_len(width)?;
            let (sign, rest) = match s.chars().next() {
                Some(c @ ('+' | '-')) => (c.to_string(), &s[1..]),
                _ => (String::new(), s),
            };
            text(format!("{sign}{}{rest}", "0".repeat(width - len)))
        }
        "center" | "ljust" | "rjust" => {
            let a = args.bind(name, &["width", "fillchar"], 1)?;
            let width = usize::try_from(to_i64(a[0].as_ref().unwrap_or(&Value::None), "width")?).unwrap_or(0);
            let fill = match &a[1] {
                None => ' ',
                Some(v) => {
                    let f = to_str(v, "fill character")?;
                    let mut chars = f.chars();
                    match (chars.next(), chars.next()) {
                        (Some(c), None) => c,
                        _ => return Err(type_error("The fill character must be exactly one character long")),
                    }
                }
            };
            let len = s.chars().count();
            if width <= len {
                return text(s.to_owned());
            }
            check_str_len(width)?;
            let extra = width - len;
            let (left, right) = match name {
                "ljust" => (0, extra),
                "rjust" => (extra, 0),
                // CPython puts the odd extra character on the left when the width is odd.
                _ => {
                    let left = extra / 2 + (extra & width & 1);
                    (left, extra - left)
                }
            };
            let pad = |n: usize| fill.to_string().repeat(n);
            text(format!("{}{s}{}", pad(left), pad(right)))
        }
        "partition" | "rpartition" => {
            let a = args.bind(name, &["sep"], 1)?;
            let sep = to_str(a[0].as_ref().unwrap_or(&Value::None), "must be str; sep")?;
            if sep.is_empty() {
                return Err(value_error("empty separator"));
            }
            let found = if name == "partition" { s.find(sep) } else { s.rfind(sep) };
            let parts = match found {
                Some(i) => [&s[..i], sep, &s[i + sep.len()..]],
                None if name == "partition" => [s, "", ""],
                None => ["", "", s],
            };
            Ok(Value::tuple(parts.iter().map(|p| Value::str((*p).to_owned())).collect()))
        }
        "removeprefix" | "removesuffix" => {
            let a = args.bind(name, &["affix"], 1)?;
            let affix = to_str(a[0].as_ref().unwrap_or(&Value::None), "must be str; argument")?;
            text(if name == "removeprefix" {
                s.strip_prefix(affix).unwrap_or(s).to_owned()
            } else {
                s.strip_suffix(affix).unwrap_or(s).to_owned()
            })
        }
        other => Err(not_supported(format!("str.{other} is not supported"))),
    }
}

fn check_str_len(len: usize) -> Result<(), ScriptError> {
    if len > ops::MAX_LEN {
        return Err(ScriptError::new(ErrorKind::Memory, "result too large"));
    }
    Ok(())
}

/// `str.title()`: the first letter of every run of letters upper case, the rest lower case.
fn title_case(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    let mut previous_cased = false;
    for c in s.chars() {
        if previous_cased {
            out.extend(c.to_lowercase());
        } else {
            out.extend(c.to_uppercase());
        }
        previous_cased = c.is_alphabetic();
    }
    out
}

/// `str.split()` without a separator: runs of white space, at most `limit` splits
/// from the left (or the right for `rsplit`).
fn split_whitespace(s: &str, limit: Option<usize>, from_right: bool) -> Vec<String> {
    let Some(limit) = limit else {
        return s.split_whitespace().map(str::to_owned).collect();
    };
    let mut parts = Vec::new();
    if from_right {
        let mut rest = s.trim_end();
        while !rest.is_empty() {
            if parts.len() == limit {
                parts.push(rest.to_owned());
                break;
            }
            match rest.rfind(char::is_whitespace) {
                Some(i) => {
                    let ws_len = rest[i..].chars().next().map_or(1, char::len_utf8);
                    parts.push(rest[i + ws_len..].to_owned());
                    rest = rest[..i].trim_end();
                }
                None => {
                    parts.push(rest.to_owned());
                    break;
                }
            }
        }
        parts.reverse();
    } else {
        let mut rest = s.trim_start();
        while !rest.is_empty() {
            if parts.len() == limit {
                parts.push(rest.to_owned());
                break;
            }
            match rest.find(char::is_whitespace) {
                Some(i) => {
                    parts.push(rest[..i].to_owned());
                    rest = rest[i..].trim_start();
                }
                None => {
                    parts.push(rest.to_owned());
                    break;
                }
            }
        }
    }
    parts
}
