//! Runtime values and how Python prints them.
//!
//! Values behave as plain data: strings and containers share their payload
//! ([`Heap`], counted against the run's memory budget) and copy it only when a
//! shared one is changed, so a mutating method or an item assignment changes the
//! variable it is called on, never an alias of it. Modules and builtins are names
//! the interpreter dispatches on, user functions share their definition, and
//! interpreter objects (a screenshot, the `Computer` parts, a finished process) are
//! small enums. `str` and `repr` follow CPython, including float formatting
//! (`0.5`, `1.0`, `1e-05`, `inf`), and never build more text than the budget holds.
//!
//! This folder is the value model, four files that need one another by nature:
//! [`Value`] holds [`heap`] payloads and the payloads hold values; a dict or set key
//! ([`heap::Key`]) compares with Python's equality from [`ops`]; `%` on a string in
//! [`ops`] is [`format`]'s printf formatting, which looks keys up in dicts. Nothing
//! here knows the interpreter, the host or any module a script imports.

pub(crate) mod format;
pub(crate) mod heap;
pub(crate) mod ops;

use std::collections::HashMap;
use std::fmt::Write as _;
use std::rc::Rc;
use std::sync::Arc;

use self::heap::{DictMap, Heap, SetMap};
use crate::ast::Function;
use crate::error::{ErrorKind, ScriptError};

/// A runtime value.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Value {
    None,
    Bool(bool),
    Int(i64),
    Float(f64),
    Str(Heap<String>),
    List(Heap<Vec<Value>>),
    Tuple(Heap<Vec<Value>>),
    /// A dict, in insertion order.
    Dict(Heap<DictMap>),
    /// A set, in insertion order.
    Set(Heap<SetMap>),
    /// `range(start, stop, step)`.
    Range(i64, i64, i64),
    /// A `def` or `lambda` function.
    UserFn(Rc<UserFn>),
    /// An exception class (`ValueError`).
    ExcType(ErrorKind),
    /// An exception instance: its class and its `str()`.
    Exception(ErrorKind, String),
    /// pyautogui's `Point(x, y)` named tuple.
    Point(i64, i64),
    /// pyautogui's `Size(width, height)` named tuple.
    Size(i64, i64),
    /// A module, by its dotted name (`os.path`).
    Module(&'static str),
    /// A module-level function: `module` is the dotted module name, `""` for builtins.
    Function {
        module: &'static str,
        name: &'static str,
    },
    /// A method bound to its receiver.
    Method(Box<Value>, &'static str),
    /// A constant marker such as a pyautogui easing function.
    Marker(&'static str),
    /// A class object, by its qualified name (`PIL.Image.Image`), as `type(x)` returns.
    Type(&'static str),
    Object(Object),
}

/// A function defined by the program: its definition, its evaluated defaults
/// and, for a function defined inside another, the enclosing locals it saw.
#[derive(Debug, PartialEq)]
pub(crate) struct UserFn {
    pub(crate) def: Arc<Function>,
    pub(crate) defaults: Vec<Option<Value>>,
    pub(crate) captured: Option<Rc<HashMap<String, Value>>>,
}

/// Objects made by the interpreter.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Object {
    /// A screenshot: its size and the screen region it covers (`None`: the whole screen).
    Image {
        width: i64,
        height: i64,
        region: Option<[i32; 4]>,
    },
    /// `os.environ`.
    Environ,
    /// A `subprocess.CompletedProcess`.
    Completed {
        args: Box<Value>,
        returncode: i64,
        stdout: Option<String>,
        stderr: Option<String>,
    },
    /// A `subprocess.Popen` whose process was started and not waited for.
    Popen {
        args: Box<Value>,
        pid: i64,
    },
    Computer,
    Mouse,
    Keyboard,
    Clipboard,
    ComputerOs,
    WindowManager,
    Human,
}

impl Object {
    /// The Python class name.
    pub(crate) fn class_name(&self) -> &'static str {
        match self {
            Object::Image { .. } => "PIL.Image.Image",
            Object::Environ => "os._Environ",
            Object::Completed { .. } => "subprocess.CompletedProcess",
            Object::Popen { .. } => "subprocess.Popen",
            Object::Computer => "Computer",
            Object::Mouse => "Mouse",
            Object::Keyboard => "Keyboard",
            Object::Clipboard => "Clipboard",
            Object::ComputerOs => "OS",
            Object::WindowManager => "WindowManager",
            Object::Human => "Human",
        }
    }
}

impl Value {
    /// A `str`.
    pub(crate) fn str(text: impl Into<String>) -> Value {
        Value::Str(Heap::new(text.into()))
    }

    /// A `list`.
    pub(crate) fn list(items: Vec<Value>) -> Value {
        Value::List(Heap::new(items))
    }

    /// A `tuple`.
    pub(crate) fn tuple(items: Vec<Value>) -> Value {
        Value::Tuple(Heap::new(items))
    }

    /// A `dict`.
    pub(crate) fn dict(entries: DictMap) -> Value {
        Value::Dict(Heap::new(entries))
    }

    /// A `set`.
    pub(crate) fn set(items: SetMap) -> Value {
        Value::Set(Heap::new(items))
    }

    /// How deeply it nests containers (0 for scalars and text).
    pub(crate) fn depth(&self) -> u32 {
        match self {
            Value::List(v) | Value::Tuple(v) => v.depth(),
            Value::Dict(d) => d.depth(),
            Value::Set(s) => s.depth(),
            Value::Method(recv, _) => recv.depth().saturating_add(1),
            Value::Object(Object::Completed { args, .. } | Object::Popen { args, .. }) => {
                args.depth().saturating_add(1)
            }
            _ => 0,
        }
    }

    /// The short type name used in error messages (`int`, `str`, `NoneType`).
    pub(crate) fn type_name(&self) -> &'static str {
        match self {
            Value::None => "NoneType",
            Value::Bool(_) => "bool",
            Value::Int(_) => "int",
            Value::Float(_) => "float",
            Value::Str(_) => "str",
            Value::List(_) => "list",
            Value::Tuple(_) => "tuple",
            Value::Dict(_) => "dict",
            Value::Set(_) => "set",
            Value::Range(..) => "range",
            Value::UserFn(_) => "function",
            Value::ExcType(_) => "type",
            Value::Exception(kind, _) => kind.python_name(),
            Value::Point(..) => "Point",
            Value::Size(..) => "Size",
            Value::Module(_) => "module",
            Value::Function { module: "", .. } => "builtin_function_or_method",
            Value::Function { .. } | Value::Marker(_) => "function",
            Value::Method(..) => "method",
            Value::Type(_) => "type",
            Value::Object(obj) => obj.class_name().rsplit('.').next().unwrap_or("object"),
        }
    }

    /// The qualified class name `type(x)` shows: `<class 'PIL.Image.Image'>`.
    pub(crate) fn class_name(&self) -> &'static str {
        match self {
            Value::Point(..) => "pyautogui.Point",
            Value::Size(..) => "pyautogui.Size",
            Value::Object(obj) => obj.class_name(),
            other => other.type_name(),
        }
    }

    /// Python truthiness.
    pub(crate) fn truthy(&self) -> bool {
        match self {
            Value::None => false,
            Value::Bool(b) => *b,
            Value::Int(i) => *i != 0,
            Value::Float(f) => *f != 0.0,
            Value::Str(s) => !s.is_empty(),
            Value::List(v) | Value::Tuple(v) => !v.is_empty(),
            Value::Dict(d) => !d.is_empty(),
            Value::Set(v) => !v.is_empty(),
            Value::Range(start, stop, step) => range_len(*start, *stop, *step) > 0,
            _ => true,
        }
    }

    /// `str(value)`; see [`Value::repr`] for the budget.
    pub(crate) fn to_str(&self) -> String {
        match self {
            Value::Str(s) => s.as_str().to_owned(),
            Value::Exception(_, message) => message.clone(),
            other => other.repr(),
        }
    }

    /// `repr(value)`, cut where it would pass the memory budget; the cut is noted
    /// and fails the run at its next check. Where a `MemoryError` can be raised
    /// on the spot, [`Value::try_repr`] is better.
    pub(crate) fn repr(&self) -> String {
        let mut out = String::new();
        if self.write_repr(&mut out, heap::room()).is_err() {
            heap::overflowed();
        }
        out
    }

    /// `repr(value)`, or `MemoryError` when the text would pass the memory budget.
    pub(crate) fn try_repr(&self) -> Result<String, ScriptError> {
        let mut out = String::new();
        self.write_repr(&mut out, heap::room()).map_err(|Overflow| {
            heap::overflowed();
            let _ = heap::check();
            ScriptError::new(ErrorKind::Memory, "the text of this value would pass the memory budget")
        })?;
        Ok(out)
    }

    /// `str(value)`, or `MemoryError` as [`Value::try_repr`].
    pub(crate) fn try_to_str(&self) -> Result<String, ScriptError> {
        match self {
            Value::Str(_) | Value::Exception(..) => {
                let text = self.to_str();
                heap::reserve_text(text.len())?;
                Ok(text)
            }
            other => other.try_repr(),
        }
    }

    /// Writes `repr(self)` to `out`, failing once `out` passes `cap` bytes.
    fn write_repr(&self, out: &mut String, cap: usize) -> Result<(), Overflow> {
        if out.len() > cap {
            return Err(Overflow);
        }
        match self {
            Value::None => out.push_str("None"),
            Value::Bool(true) => out.push_str("True"),
            Value::Bool(false) => out.push_str("False"),
            Value::Int(i) => {
                let _ = write!(out, "{i}");
            }
            Value::Float(f) => out.push_str(&float_repr(*f)),
            Value::Str(s) => {
                if s.len() > cap.saturating_sub(out.len()) {
                    return Err(Overflow);
                }
                out.push_str(&str_repr(s));
            }
            Value::List(items) => {
                out.push('[');
                write_items(out, items, cap)?;
                out.push(']');
            }
            Value::Tuple(items) => {
                out.push('(');
                write_items(out, items, cap)?;
                if items.len() == 1 {
                    out.push(',');
                }
                out.push(')');
            }
            Value::Dict(entries) => {
                out.push('{');
                for (i, (k, v)) in entries.iter().enumerate() {
                    if i > 0 {
                        out.push_str(", ");
                    }
                    k.0.write_repr(out, cap)?;
                    out.push_str(": ");
                    v.write_repr(out, cap)?;
                }
                out.push('}');
            }
            Value::Set(items) if items.is_empty() => out.push_str("set()"),
            Value::Set(items) => {
                out.push('{');
                for (i, item) in items.iter().enumerate() {
                    if i > 0 {
                        out.push_str(", ");
                    }
                    item.0.write_repr(out, cap)?;
                }
                out.push('}');
            }
            Value::Range(start, stop, step) => {
                let _ = if *step == 1 {
                    write!(out, "range({start}, {stop})")
                } else {
                    write!(out, "range({start}, {stop}, {step})")
                };
            }
            Value::UserFn(f) => {
                let _ = write!(out, "<function {}>", f.def.name);
            }
            Value::ExcType(kind) => {
                let _ = write!(out, "<class '{}'>", kind.python_name());
            }
            Value::Exception(ErrorKind::Key, message) => {
                let _ = write!(out, "KeyError({message})");
            }
            Value::Exception(kind, message) => {
                let _ = write!(out, "{}({})", kind.python_name(), str_repr(message));
            }
            Value::Point(x, y) => {
                let _ = write!(out, "Point(x={x}, y={y})");
            }
            Value::Size(w, h) => {
                let _ = write!(out, "Size(width={w}, height={h})");
            }
            Value::Module(name) => {
                let _ = write!(out, "<module '{name}'>");
            }
            Value::Function { module: "", name } => {
                let _ = write!(out, "<built-in function {name}>");
            }
            Value::Function { name, .. } | Value::Marker(name) => {
                let _ = write!(out, "<function {name}>");
            }
            Value::Method(recv, name) => {
                let _ = write!(out, "<bound method {}.{name}>", recv.type_name());
            }
            Value::Type(name) => {
                let _ = write!(out, "<class '{name}'>");
            }
            Value::Object(Object::Image { width, height, .. }) => {
                let _ = write!(out, "<PIL.Image.Image image mode=RGB size={width}x{height}>");
            }
            Value::Object(Object::Completed { args, returncode, stdout, stderr }) => {
                out.push_str("CompletedProcess(args=");
                args.write_repr(out, cap)?;
                let _ = write!(out, ", returncode={returncode}");
                if let Some(s) = stdout {
                    let _ = write!(out, ", stdout={}", str_repr(s));
                }
                if let Some(s) = stderr {
                    let _ = write!(out, ", stderr={}", str_repr(s));
                }
                out.push(')');
            }
            Value::Object(Object::Popen { args, pid }) => {
                let _ = write!(out, "<Popen: pid={pid} args=");
                args.write_repr(out, cap)?;
                out.push('>');
            }
            Value::Object(obj) => {
                let _ = write!(out, "<{} object>", obj.class_name());
            }
        }
        if out.len() > cap {
            return Err(Overflow);
        }
        Ok(())
    }
}

/// Text that would pass the memory budget.
#[derive(Debug)]
struct Overflow;

/// Dict keys and set items compare as Python's `==` does (`1`, `1.0` and `True` are one key).
impl PartialEq for heap::Key {
    fn eq(&self, other: &heap::Key) -> bool {
        ops::equal(&self.0, &other.0)
    }
}

/// How many numbers `range(start, stop, step)` holds (`step` is never 0).
pub(crate) fn range_len(start: i64, stop: i64, step: i64) -> u64 {
    let (lo, hi, step) = if step > 0 { (start, stop, step) } else { (stop, start, step.saturating_neg()) };
    if lo >= hi {
        return 0;
    }
    let span = i128::from(hi) - i128::from(lo);
    u64::try_from((span - 1) / i128::from(step) + 1).unwrap_or(u64::MAX)
}

fn write_items(out: &mut String, items: &[Value], cap: usize) -> Result<(), Overflow> {
    for (i, item) in items.iter().enumerate() {
        if i > 0 {
            out.push_str(", ");
        }
        item.write_repr(out, cap)?;
    }
    Ok(())
}

/// Python's `repr(float)`: the shortest digits that round-trip, in positional
/// notation for exponents -4..16 and scientific notation (`1e-05`, `1e+16`) otherwise.
pub fn float_repr(f: f64) -> String {
    if f.is_nan() {
        return "nan".to_owned();
    }
    if f.is_infinite() {
        return if f > 0.0 { "inf" } else { "-inf" }.to_owned();
    }
    if f == 0.0 {
        return if f.is_sign_negative() { "-0.0" } else { "0.0" }.to_owned();
    }
    // `{:e}` gives the shortest round-tripping digits as `d.ddde<exp>`.
    let sci = format!("{:e}", f.abs());
    let (mantissa, exp) = sci.split_once('e').unwrap_or((&sci, "0"));
    let exp: i32 = exp.parse().unwrap_or(0);
    let digits: String = mantissa.chars().filter(|c| *c != '.').collect();
    let sign = if f < 0.0 { "-" } else { "" };
    if (-4..16).contains(&exp) {
        if exp >= 0 {
            let point = exp as usize + 1;
            if digits.len() <= point {
                format!("{sign}{digits}{}.0", "0".repeat(point - digits.len()))
            } else {
                format!("{sign}{}.{}", &digits[..point], &digits[point..])
            }
        } else {
            format!("{sign}0.{}{digits}", "0".repeat((-exp - 1) as usize))
        }
    } else {
        let (first, rest) = digits.split_at(1);
        let frac = if rest.is_empty() { String::new() } else { format!(".{rest}") };
        let exp_sign = if exp < 0 { '-' } else { '+' };
        format!("{sign}{first}{frac}e{exp_sign}{:02}", exp.abs())
    }
}

/// Python's `repr(str)`: single quotes unless the text holds `'` and no `"`,
/// escapes for backslash, the quote, `\n`, `\r`, `\t` and non-printable characters.
pub fn str_repr(s: &str) -> String {
    let quote = if s.contains('\'') && !s.contains('"') { '"' } else { '\'' };
    let mut out = String::with_capacity(s.len() + 2);
    out.push(quote);
    for c in s.chars() {
        match c {
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            '\t' => out.push_str("\\t"),
            c if c == quote => {
                out.push('\\');
                out.push(c);
            }
            c if !is_printable(c) => {
                let code = c as u32;
                let _ = if code < 0x100 {
                    write!(out, "\\x{code:02x}")
                } else if code < 0x10000 {
                    write!(out, "\\u{code:04x}")
                } else {
                    write!(out, "\\U{code:08x}")
                };
            }
            c => out.push(c),
        }
    }
    out.push(quote);
    out
}

/// An approximation of Python's `str.isprintable` for one character: control,
/// format, separator (other than space) and private-use characters are not printable.
/// Unassigned code points, which Python also escapes, are printed as they are.
fn is_printable(c: char) -> bool {
    let code = c as u32;
    !(c.is_control()
        || matches!(code, 0xA0 | 0xAD | 0x1680 | 0x2000..=0x200F | 0x2028..=0x202F | 0x205F..=0x2064)
        || matches!(code, 0x3000 | 0xFEFF | 0xE000..=0xF8FF | 0xF0000..=0x10FFFF)
        || matches!(code, 0x600..=0x605 | 0x61C | 0x6DD | 0x70F | 0x180E | 0xFFF9..=0xFFFB))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floats_print_like_python() {
        let check = |f: f64, expected: &str| assert_eq!(float_repr(f), expected, "{f:?}");
        check(0.5, "0.5");
        check(1.0, "1.0");
        check(-2.0, "-2.0");
        check(1e-05, "1e-05");
        check(0.0001, "0.0001");
        check(1e16, "1e+16");
        check(1e15, "1000000000000000.0");
        check(123456789012345678.0, "1.2345678901234568e+17");
        check(0.1 + 0.2, "0.30000000000000004");
        check(1.5e-7, "1.5e-07");
        check(f64::INFINITY, "inf");
        check(f64::NEG_INFINITY, "-inf");
        check(f64::NAN, "nan");
        check(-0.0, "-0.0");
        check(1e300, "1e+300");
        check(2.5e-300, "2.5e-300");
        check(123.456, "123.456");
    }

    #[test]
    fn strings_repr_like_python() {
        let check = |s: &str, expected: &str| assert_eq!(str_repr(s), expected, "{s:?}");
        check("abc", "'abc'");
        check("it's", "\"it's\"");
        check("both ' and \"", "'both \\' and \"'");
        check("a\\b\n\t\r", "'a\\\\b\\n\\t\\r'");
        check("\x07\u{7f}", "'\\x07\\x7f'");
        check("é日本", "'é日本'");
        check("\u{a0}\u{200b}", "'\\xa0\\u200b'");
    }

    #[test]
    fn containers_repr_like_python() {
        let mut dict = DictMap::new();
        dict.insert(heap::Key(Value::str("k")), Value::Float(0.5));
        let v = Value::list(vec![
            Value::Int(1),
            Value::str("a"),
            Value::None,
            Value::tuple(vec![Value::Bool(true)]),
            Value::tuple(vec![]),
            Value::dict(dict),
        ]);
        assert_eq!(v.to_str(), "[1, 'a', None, (True,), (), {'k': 0.5}]");
        assert_eq!(Value::Point(10, 20).to_str(), "Point(x=10, y=20)");
        assert_eq!(Value::Size(1440, 900).to_str(), "Size(width=1440, height=900)");
        assert_eq!(Value::Type("PIL.Image.Image").to_str(), "<class 'PIL.Image.Image'>");
        assert_eq!(Value::str("x").to_str(), "x");
    }
}
