//! The tree-walking interpreter: statements, expressions, names, builtins and
//! the methods of plain values.
//!
//! Modules are interpreter objects, never real imports: `import` only binds
//! names from a fixed list ([`KNOWN_MODULES`]); their functions live in
//! [`super::pyautogui`], [`super::stdlib`] and [`super::computer`].
//! The interpreter has no loops or user functions, so a run ends after at most
//! one evaluation per syntax node; every effect goes through the [`ScriptHost`].

use std::collections::HashMap;

use super::ast::{Const, Expr, ExprKind, Program, Stmt, StmtKind, Target};
use super::computer::ComputerState;
use super::error::{not_supported, type_error, value_error, ErrorKind, ScriptError};
use super::host::{HostResult, ScriptHost};
use super::ops;
use super::value::{Object, Value};

/// Modules a script may import.
pub const KNOWN_MODULES: &[&str] = &[
    "pyautogui",
    "time",
    "os",
    "os.path",
    "ntpath",
    "subprocess",
    "platform",
    "sys",
    "PIL",
    "PIL.Image",
    "PIL.ImageGrab",
    "pyperclip",
];

const BUILTINS: &[&str] = &[
    "print", "type", "str", "int", "float", "len", "repr", "abs", "round", "min", "max", "bool", "list", "tuple",
    "dict", "sum", "chr", "ord", "exit", "quit",
];

/// Builtins that exist in Python but that this interpreter refuses by design.
const REFUSED_BUILTINS: &[&str] = &[
    "open",
    "eval",
    "exec",
    "compile",
    "__import__",
    "input",
    "getattr",
    "setattr",
    "delattr",
    "globals",
    "locals",
    "vars",
    "dir",
    "help",
    "breakpoint",
    "memoryview",
    "bytearray",
    "bytes",
    "range",
    "enumerate",
    "zip",
    "map",
    "filter",
    "sorted",
    "reversed",
    "isinstance",
    "issubclass",
    "hasattr",
    "set",
    "frozenset",
    "object",
    "super",
    "iter",
    "next",
    "format",
    "hex",
    "oct",
    "bin",
    "hash",
    "id",
    "callable",
    "any",
    "all",
    "divmod",
    "pow",
    "complex",
    "slice",
    "property",
    "staticmethod",
    "classmethod",
    "ascii",
];

/// How many bytes (roughly) a run may allocate for values and printed text in total.
const MAX_ALLOCATED: usize = 256 << 20;

/// How deeply values may nest (`a = [a]` repeated), so printing and dropping them stays shallow.
const MAX_VALUE_DEPTH: usize = 100;

/// What is bound before a program runs.
#[derive(Debug)]
pub struct Globals<'a> {
    /// The Navi `Computer` state; binds `computer` and `human` when present.
    pub computer: Option<&'a mut ComputerState>,
    /// Seconds slept after each `Computer` action (upstream: 0.25).
    pub computer_action_delay: f64,
    /// Modules imported before the program runs, as the upstream host's
    /// `import pyautogui; import time; ...` prefix does.
    pub preimport: &'a [&'a str],
}

impl Globals<'static> {
    /// Plain `python -c`: nothing is bound.
    pub fn python() -> Globals<'static> {
        Globals { computer: None, computer_action_delay: 0.25, preimport: &[] }
    }
}

impl<'a> Globals<'a> {
    /// `/execute_windows`: `computer` and `human` are bound to `state`.
    pub fn computer(state: &'a mut ComputerState) -> Globals<'a> {
        Globals { computer: Some(state), computer_action_delay: 0.25, preimport: &[] }
    }
}

/// What a finished program printed and set.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RunOutput {
    /// Everything printed, exactly as CPython would print it.
    pub stdout: String,
    /// What child processes wrote to stderr, and `sys.exit("message")` texts.
    pub stderr: String,
    /// 0, or the code given to `sys.exit`.
    pub exit_code: i32,
    /// The last `pyautogui.FAILSAFE = ...` assignment (it has no effect here).
    pub failsafe: Option<bool>,
    /// The last `pyautogui.PAUSE = ...` assignment (applied after each pyautogui call).
    pub pause: Option<f64>,
}

/// Runs `program` against `host`.
///
/// # Errors
///
/// [`ScriptError`] for the first exception, carrying what was printed before it.
/// Effects performed before the failure are not undone.
pub fn run(program: &Program, host: &mut dyn ScriptHost, globals: Globals<'_>) -> Result<RunOutput, ScriptError> {
    let mut interp = Interp {
        host,
        computer: globals.computer,
        action_delay: globals.computer_action_delay,
        vars: HashMap::new(),
        out: RunOutput::default(),
        exit: None,
        allocated: 0,
    };
    let preimport_line = program.statements.first().map_or(1, |s| s.line);
    for module in globals.preimport {
        let stmt = StmtKind::Import(vec![super::ast::ImportName { module: (*module).to_owned(), alias: None }]);
        interp
            .statement(&Stmt { line: preimport_line, column: 1, kind: stmt })
            .map_err(|e| interp.finish_error(e, 1))?;
    }
    if interp.computer.is_some() {
        interp.vars.insert("computer".into(), Value::Object(Object::Computer));
        interp.vars.insert("human".into(), Value::Object(Object::Human));
    }
    for stmt in &program.statements {
        if let Err(err) = interp.statement(stmt) {
            if err.kind == ErrorKind::SystemExit {
                break;
            }
            return Err(interp.finish_error(err, stmt.line));
        }
    }
    if let Some(code) = interp.exit {
        interp.out.exit_code = code;
    }
    Ok(interp.out)
}

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

/// The items of an iterable value.
pub(crate) fn iterate(v: &Value) -> Result<Vec<Value>, ScriptError> {
    match v {
        Value::List(items) | Value::Tuple(items) => Ok(items.clone()),
        Value::Str(s) => {
            if s.len() > ops::MAX_ITEMS {
                return Err(ScriptError::new(
                    ErrorKind::Memory,
                    format!("result would exceed {} items", ops::MAX_ITEMS),
                ));
            }
            Ok(s.chars().map(|c| Value::Str(c.to_string())).collect())
        }
        Value::Dict(entries) => Ok(entries.iter().map(|(k, _)| k.clone()).collect()),
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

/// The interpreter state for one run.
pub(crate) struct Interp<'h, 'c> {
    pub(crate) host: &'h mut dyn ScriptHost,
    pub(crate) computer: Option<&'c mut ComputerState>,
    pub(crate) action_delay: f64,
    vars: HashMap<String, Value>,
    pub(crate) out: RunOutput,
    /// Set by `sys.exit`.
    pub(crate) exit: Option<i32>,
    /// Bytes charged so far against [`MAX_ALLOCATED`].
    allocated: usize,
}

impl std::fmt::Debug for Interp<'_, '_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Interp").field("vars", &self.vars).field("out", &self.out).finish_non_exhaustive()
    }
}

impl Interp<'_, '_> {
    fn finish_error(&mut self, mut err: ScriptError, line: usize) -> ScriptError {
        if err.line == 0 {
            err.line = line;
        }
        err.stdout = std::mem::take(&mut self.out.stdout);
        err.stderr = std::mem::take(&mut self.out.stderr);
        err
    }

    /// Host failures become `OSError`s carrying the host's message; a timeout or an
    /// unreachable host becomes its own kind, which stops the script.
    pub(crate) fn host<T>(&mut self, result: HostResult<T>) -> Result<T, ScriptError> {
        result.map_err(super::error::host_error)
    }

    pub(crate) fn print(&mut self, text: &str) -> Result<(), ScriptError> {
        self.charge_bytes(text.len())?;
        self.out.stdout.push_str(text);
        Ok(())
    }

    /// Counts `bytes` against the run's allocation budget.
    fn charge_bytes(&mut self, bytes: usize) -> Result<(), ScriptError> {
        self.allocated = self.allocated.saturating_add(bytes);
        if self.allocated > MAX_ALLOCATED {
            return Err(ScriptError::new(
                ErrorKind::Memory,
                format!("the program allocated more than {} MiB", MAX_ALLOCATED >> 20),
            ));
        }
        Ok(())
    }

    pub(crate) fn sleep(&mut self, seconds: f64) -> Result<(), ScriptError> {
        if seconds.is_nan() {
            return Err(value_error("Invalid value NaN (not a number)"));
        }
        if seconds < 0.0 {
            return Err(value_error("sleep length must be non-negative"));
        }
        let result = self.host.sleep(seconds);
        self.host(result)
    }

    /// Stops the run like `SystemExit`.
    pub(crate) fn system_exit(&mut self, code: i32) -> ScriptError {
        self.exit = Some(code);
        ScriptError::new(ErrorKind::SystemExit, "")
    }

    fn statement(&mut self, stmt: &Stmt) -> Result<(), ScriptError> {
        match &stmt.kind {
            StmtKind::Pass => Ok(()),
            StmtKind::Expr(expr) => self.eval(expr).map(drop),
            StmtKind::Import(names) => {
                for name in names {
                    let module = find_module(&name.module)?;
                    match &name.alias {
                        Some(alias) => {
                            self.vars.insert(alias.clone(), Value::Module(module));
                        }
                        None => {
                            let top = name.module.split('.').next().unwrap_or(&name.module);
                            let top = find_module(top)?;
                            self.vars.insert(top.to_owned(), Value::Module(top));
                        }
                    }
                }
                Ok(())
            }
            StmtKind::FromImport { module, names } => {
                let module = find_module(module)?;
                for (name, alias) in names {
                    let full = format!("{module}.{name}");
                    let value = match KNOWN_MODULES.iter().find(|m| **m == full) {
                        Some(sub) => Value::Module(sub),
                        None => self.module_attr(module, name).map_err(|_| {
                            ScriptError::new(
                                ErrorKind::Import,
                                format!(
                                    "cannot import name '{name}' from '{module}' (not supported by this interpreter)"
                                ),
                            )
                        })?,
                    };
                    self.vars.insert(alias.clone().unwrap_or_else(|| name.clone()), value);
                }
                Ok(())
            }
            StmtKind::Assign { targets, value } => {
                let value = self.eval(value)?;
                for target in targets {
                    match target {
                        Target::Name(name) => {
                            self.vars.insert(name.clone(), value.clone());
                        }
                        Target::Attr(obj, attr) => {
                            let obj = self.eval(obj)?;
                            self.set_attr(&obj, attr, &value)?;
                        }
                    }
                }
                Ok(())
            }
        }
    }

    fn set_attr(&mut self, obj: &Value, attr: &str, value: &Value) -> Result<(), ScriptError> {
        match (obj, attr) {
            (Value::Module("pyautogui"), "FAILSAFE") => {
                self.out.failsafe = Some(value.truthy());
                Ok(())
            }
            (Value::Module("pyautogui"), "PAUSE") => {
                let pause = to_f64(value, "pyautogui.PAUSE")?;
                self.out.pause = Some(pause);
                Ok(())
            }
            (
                Value::Module("pyautogui"),
                "MINIMUM_DURATION" | "MINIMUM_SLEEP" | "DARWIN_CATCH_UP_TIME" | "LOG_SCREENSHOTS",
            ) => Ok(()),
            (Value::Module(module), _) => Err(not_supported(format!("assigning {module}.{attr} is not supported"))),
            _ => Err(not_supported(format!("assigning attributes of {} objects is not supported", obj.type_name()))),
        }
    }

    /// Evaluates `expr`, charging the result against the allocation budget: values are
    /// copied when they are read, so every evaluation counts.
    pub(crate) fn eval(&mut self, expr: &Expr) -> Result<Value, ScriptError> {
        let value = self.eval_uncharged(expr)?;
        let weight = weight(&value, 0).ok_or_else(|| {
            ScriptError::new(ErrorKind::Memory, format!("value nested more than {MAX_VALUE_DEPTH} levels deep"))
        })?;
        self.charge_bytes(weight)?;
        Ok(value)
    }

    fn eval_uncharged(&mut self, expr: &Expr) -> Result<Value, ScriptError> {
        match &expr.kind {
            ExprKind::Const(c) => Ok(match c {
                Const::None => Value::None,
                Const::Bool(b) => Value::Bool(*b),
                Const::Int(i) => Value::Int(*i),
                Const::Float(f) => Value::Float(*f),
                Const::Str(s) => Value::Str(s.clone()),
            }),
            ExprKind::Name(name) => self.lookup(name),
            ExprKind::Attr(obj, name) => {
                let obj = self.eval(obj)?;
                self.get_attr(obj, name)
            }
            ExprKind::Call { func, args, kwargs } => {
                let func = self.eval(func)?;
                let mut call_args = Args::default();
                for arg in args {
                    call_args.pos.push(self.eval(arg)?);
                }
                for (name, arg) in kwargs {
                    let value = self.eval(arg)?;
                    call_args.kw.push((name.clone(), value));
                }
                self.call(func, call_args)
            }
            ExprKind::Subscript(obj, index) => {
                let obj = self.eval(obj)?;
                let index = self.eval(index)?;
                self.subscript(&obj, &index)
            }
            ExprKind::List(items) => Ok(Value::List(self.eval_all(items)?)),
            ExprKind::Tuple(items) => Ok(Value::Tuple(self.eval_all(items)?)),
            ExprKind::Dict(items) => {
                let mut entries: Vec<(Value, Value)> = Vec::new();
                for (k, v) in items {
                    let key = self.eval(k)?;
                    let value = self.eval(v)?;
                    check_hashable(&key)?;
                    match entries.iter_mut().find(|(existing, _)| ops::equal(existing, &key)) {
                        Some(entry) => entry.1 = value,
                        None => entries.push((key, value)),
                    }
                }
                Ok(Value::Dict(entries))
            }
            ExprKind::Unary(op, operand) => {
                let v = self.eval(operand)?;
                ops::unary(*op, &v)
            }
            ExprKind::Binary(op, left, right) => {
                let l = self.eval(left)?;
                let r = self.eval(right)?;
                ops::binary(*op, &l, &r)
            }
        }
    }

    fn eval_all(&mut self, items: &[Expr]) -> Result<Vec<Value>, ScriptError> {
        items.iter().map(|e| self.eval(e)).collect()
    }

    fn lookup(&self, name: &str) -> Result<Value, ScriptError> {
        if let Some(v) = self.vars.get(name) {
            return Ok(v.clone());
        }
        if let Some(b) = static_name(BUILTINS, name) {
            return Ok(Value::Function { module: "", name: b });
        }
        if REFUSED_BUILTINS.contains(&name) {
            return Err(not_supported(format!("{name}() is not supported by this interpreter")));
        }
        if name == "computer" || name == "human" {
            return Err(ScriptError::new(
                ErrorKind::Name,
                format!("name '{name}' is not defined (it is only bound for /execute_windows)"),
            ));
        }
        Err(ScriptError::new(ErrorKind::Name, format!("name '{name}' is not defined")))
    }

    pub(crate) fn module_attr(&mut self, module: &'static str, name: &str) -> Result<Value, ScriptError> {
        let found = match module {
            "pyautogui" => super::pyautogui::attr(name, &self.out),
            _ => super::stdlib::attr(module, name),
        };
        found.ok_or_else(|| {
            ScriptError::new(
                ErrorKind::Attribute,
                format!("module '{module}' has no attribute '{name}' ({module}.{name} is not supported by this interpreter)"),
            )
        })
    }

    fn get_attr(&mut self, obj: Value, name: &str) -> Result<Value, ScriptError> {
        const STR_METHODS: &[&str] = &[
            "lower",
            "upper",
            "strip",
            "lstrip",
            "rstrip",
            "startswith",
            "endswith",
            "replace",
            "split",
            "join",
            "find",
            "count",
            "splitlines",
        ];
        const DICT_METHODS: &[&str] = &["get", "keys", "values", "items"];
        let method = |list: &[&'static str], obj: &Value| {
            static_name(list, name).map(|m| Value::Method(Box::new(obj.clone()), m))
        };
        let found = match &obj {
            Value::Module(module) => return self.module_attr(module, name),
            Value::Str(_) => method(STR_METHODS, &obj),
            Value::Dict(_) => method(DICT_METHODS, &obj),
            Value::Point(x, y) => match name {
                "x" => Some(Value::Int(*x)),
                "y" => Some(Value::Int(*y)),
                _ => None,
            },
            Value::Size(w, h) => match name {
                "width" => Some(Value::Int(*w)),
                "height" => Some(Value::Int(*h)),
                _ => None,
            },
            Value::Object(object) => match object {
                Object::Image { width, height, .. } => match name {
                    "size" => Some(Value::Tuple(vec![Value::Int(*width), Value::Int(*height)])),
                    "width" => Some(Value::Int(*width)),
                    "height" => Some(Value::Int(*height)),
                    "mode" => Some(Value::Str("RGB".into())),
                    "save" => method(&["save"], &obj),
                    _ => {
                        return Err(not_supported(format!("Image.{name} is not supported by this interpreter")));
                    }
                },
                Object::Environ => method(&["get"], &obj),
                Object::Completed { args, returncode, stdout, stderr } => match name {
                    "args" => Some((**args).clone()),
                    "returncode" => Some(Value::Int(*returncode)),
                    "stdout" => Some(stdout.clone().map_or(Value::None, Value::Str)),
                    "stderr" => Some(stderr.clone().map_or(Value::None, Value::Str)),
                    "check_returncode" => method(&["check_returncode"], &obj),
                    _ => None,
                },
                Object::Popen { args, pid } => match name {
                    "args" => Some((**args).clone()),
                    "pid" => Some(Value::Int(*pid)),
                    "wait" | "communicate" | "poll" | "kill" | "terminate" | "returncode" => {
                        return Err(not_supported(format!(
                            "Popen.{name} is not supported: processes started with Popen run detached"
                        )));
                    }
                    _ => None,
                },
                _ => return super::computer::attr(self, object, name),
            },
            _ => None,
        };
        found.ok_or_else(|| no_attribute(&obj, name))
    }

    fn subscript(&mut self, obj: &Value, index: &Value) -> Result<Value, ScriptError> {
        let seq_index = |len: usize, what: &str| -> Result<usize, ScriptError> {
            let i = match index {
                Value::Int(_) | Value::Bool(_) => to_i64(index, "index")?,
                other => {
                    return Err(type_error(format!(
                        "{what} indices must be integers or slices, not {}",
                        other.type_name()
                    )))
                }
            };
            let len_i = i64::try_from(len).unwrap_or(i64::MAX);
            let resolved = if i < 0 { i + len_i } else { i };
            if resolved < 0 || resolved >= len_i {
                return Err(ScriptError::new(ErrorKind::Index, format!("{what} index out of range")));
            }
            Ok(usize::try_from(resolved).unwrap_or(0))
        };
        match obj {
            Value::List(items) => Ok(items[seq_index(items.len(), "list")?].clone()),
            Value::Tuple(items) => Ok(items[seq_index(items.len(), "tuple")?].clone()),
            Value::Point(a, b) | Value::Size(a, b) => Ok(Value::Int(if seq_index(2, "tuple")? == 0 { *a } else { *b })),
            Value::Str(s) => {
                let chars: Vec<char> = s.chars().collect();
                let i = seq_index(chars.len(), "string")?;
                Ok(Value::Str(chars[i].to_string()))
            }
            Value::Dict(entries) => entries
                .iter()
                .find(|(k, _)| ops::equal(k, index))
                .map(|(_, v)| v.clone())
                .ok_or_else(|| ScriptError::new(ErrorKind::Key, index.repr())),
            Value::Object(Object::Environ) => {
                let name = to_str(index, "environment variable name")?;
                self.host.env_var(name).map(Value::Str).ok_or_else(|| ScriptError::new(ErrorKind::Key, index.repr()))
            }
            other => Err(type_error(format!("'{}' object is not subscriptable", other.type_name()))),
        }
    }

    pub(crate) fn call(&mut self, func: Value, args: Args) -> Result<Value, ScriptError> {
        match func {
            Value::Function { module: "", name } => self.builtin(name, args),
            Value::Function { module: "pyautogui", name } => super::pyautogui::call(self, name, args),
            Value::Function { module, name } => super::stdlib::call(self, module, name, args),
            Value::Method(recv, name) => self.call_method(*recv, name, args),
            Value::Marker(name) => Err(not_supported(format!("calling {name}() is not supported"))),
            other => Err(type_error(format!("'{}' object is not callable", other.type_name()))),
        }
    }

    fn call_method(&mut self, recv: Value, name: &'static str, args: Args) -> Result<Value, ScriptError> {
        match &recv {
            Value::Str(s) => str_method(s, name, args),
            Value::Dict(entries) => match name {
                "get" => {
                    let a = args.bind("get", &["key", "default"], 1)?;
                    let key = a[0].clone().unwrap_or(Value::None);
                    Ok(entries
                        .iter()
                        .find(|(k, _)| ops::equal(k, &key))
                        .map(|(_, v)| v.clone())
                        .unwrap_or_else(|| a[1].clone().unwrap_or(Value::None)))
                }
                "keys" => Ok(Value::List(entries.iter().map(|(k, _)| k.clone()).collect())),
                "values" => Ok(Value::List(entries.iter().map(|(_, v)| v.clone()).collect())),
                _ => Ok(Value::List(entries.iter().map(|(k, v)| Value::Tuple(vec![k.clone(), v.clone()])).collect())),
            },
            Value::Object(Object::Environ) => {
                let a = args.bind("get", &["key", "default"], 1)?;
                let key = a[0].clone().unwrap_or(Value::None);
                let name = to_str(&key, "environment variable name")?;
                Ok(self.host.env_var(name).map(Value::Str).unwrap_or_else(|| a[1].clone().unwrap_or(Value::None)))
            }
            Value::Object(Object::Image { region, .. }) => {
                let a = args.bind("save", &["fp", "format"], 1)?;
                let path = a[0].clone().unwrap_or(Value::None);
                let path = to_str(&path, "save() path")?.to_owned();
                let result = self.host.save_screenshot(&path, *region);
                self.host(result)?;
                Ok(Value::None)
            }
            Value::Object(Object::Completed { args: cmd, returncode, stdout, stderr }) => {
                args.bind("check_returncode", &[], 0)?;
                if *returncode != 0 {
                    return Err(super::stdlib::called_process_error(cmd, *returncode, stdout.clone(), stderr.clone()));
                }
                Ok(Value::None)
            }
            Value::Object(object) => super::computer::call_method(self, object.clone(), name, args),
            other => Err(no_attribute(other, name)),
        }
    }

    fn builtin(&mut self, name: &str, args: Args) -> Result<Value, ScriptError> {
        match name {
            "print" => {
                let mut sep = " ".to_owned();
                let mut end = "\n".to_owned();
                for (k, v) in &args.kw {
                    match (k.as_str(), v) {
                        ("sep", Value::None) | ("end", Value::None) | ("flush", _) => {}
                        ("sep", Value::Str(s)) => sep = s.clone(),
                        ("end", Value::Str(s)) => end = s.clone(),
                        ("sep" | "end", other) => {
                            return Err(type_error(format!("{k} must be None or a string, not {}", other.type_name())))
                        }
                        ("file", _) => return Err(not_supported("print(file=...) is not supported")),
                        (other, _) => {
                            return Err(type_error(format!("'{other}' is an invalid keyword argument for print()")))
                        }
                    }
                }
                let text: Vec<String> = args.pos.iter().map(Value::to_str).collect();
                let line = format!("{}{end}", text.join(&sep));
                self.print(&line)?;
                Ok(Value::None)
            }
            "type" => {
                let a = args.bind("type", &["object"], 1)?;
                Ok(Value::Type(a[0].as_ref().map_or("NoneType", Value::class_name)))
            }
            "str" => {
                let a = args.bind("str", &["object"], 0)?;
                Ok(Value::Str(a[0].as_ref().map(Value::to_str).unwrap_or_default()))
            }
            "repr" => {
                let a = args.bind("repr", &["obj"], 1)?;
                Ok(Value::Str(a[0].as_ref().map(Value::repr).unwrap_or_default()))
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
                if let Some((k, _)) = args.kw.first() {
                    return Err(not_supported(format!("{name}({k}=...) is not supported")));
                }
                let items = if args.pos.len() == 1 { iterate(&args.pos[0])? } else { args.pos };
                let mut best: Option<Value> = None;
                for item in items {
                    best = Some(match best {
                        None => item,
                        Some(current) => {
                            let ord = ops::compare(&item, &current)?;
                            let better = if name == "min" { ord.is_lt() } else { ord.is_gt() };
                            if better {
                                item
                            } else {
                                current
                            }
                        }
                    });
                }
                best.ok_or_else(|| value_error(format!("{name}() arg is an empty sequence")))
            }
            "sum" => {
                let a = args.bind("sum", &["iterable", "start"], 1)?;
                let mut total = a[1].clone().unwrap_or(Value::Int(0));
                for item in iterate(a[0].as_ref().unwrap_or(&Value::None))? {
                    if matches!(item, Value::Str(_)) {
                        return Err(type_error("sum() can't sum strings [use ''.join(seq) instead]"));
                    }
                    if !matches!(item, Value::Int(_) | Value::Float(_) | Value::Bool(_)) {
                        return Err(not_supported("sum() of non-numbers is not supported"));
                    }
                    total = ops::binary(super::ast::BinOp::Add, &total, &item)?;
                }
                Ok(total)
            }
            "list" | "tuple" => {
                let a = args.bind(name, &["iterable"], 0)?;
                let items = match &a[0] {
                    Some(v) => iterate(v)?,
                    None => Vec::new(),
                };
                Ok(if name == "list" { Value::List(items) } else { Value::Tuple(items) })
            }
            "dict" => {
                let mut entries = Vec::new();
                if let Some(first) = args.pos.first() {
                    for item in iterate(first)? {
                        match iterate(&item)?.as_slice() {
                            [k, v] => entries.push((k.clone(), v.clone())),
                            _ => return Err(value_error("dictionary update sequence element has the wrong length")),
                        }
                    }
                }
                for (k, v) in args.kw {
                    entries.push((Value::Str(k), v));
                }
                Ok(Value::Dict(entries))
            }
            "chr" => {
                let a = args.bind("chr", &["i"], 1)?;
                let i = to_i64(a[0].as_ref().unwrap_or(&Value::None), "chr() argument")?;
                u32::try_from(i)
                    .ok()
                    .and_then(char::from_u32)
                    .map(|c| Value::Str(c.to_string()))
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
                Err(super::stdlib::exit_with(self, a[0].clone()))
            }
            other => Err(not_supported(format!("{other}() is not supported by this interpreter"))),
        }
    }
}

/// Roughly how many bytes `v` occupies, or `None` when it nests too deeply.
fn weight(v: &Value, depth: usize) -> Option<usize> {
    const SLOT: usize = std::mem::size_of::<Value>();
    if depth > MAX_VALUE_DEPTH {
        return None;
    }
    let items = |items: &[Value]| items.iter().try_fold(SLOT, |acc, item| Some(acc + weight(item, depth + 1)?));
    match v {
        Value::Str(s) => Some(SLOT + s.len()),
        Value::List(v) | Value::Tuple(v) => items(v),
        Value::Dict(entries) => {
            entries.iter().try_fold(SLOT, |acc, (k, v)| Some(acc + weight(k, depth + 1)? + weight(v, depth + 1)?))
        }
        Value::Method(recv, _) => Some(SLOT + weight(recv, depth + 1)?),
        Value::Object(Object::Completed { args, stdout, stderr, .. }) => Some(
            SLOT + weight(args, depth + 1)?
                + stdout.as_ref().map_or(0, String::len)
                + stderr.as_ref().map_or(0, String::len),
        ),
        Value::Object(Object::Popen { args, .. }) => Some(SLOT + weight(args, depth + 1)?),
        _ => Some(SLOT),
    }
}

fn find_module(name: &str) -> Result<&'static str, ScriptError> {
    KNOWN_MODULES.iter().copied().find(|m| *m == name).ok_or_else(|| {
        ScriptError::new(
            ErrorKind::ModuleNotFound,
            format!("No module named '{name}' (this interpreter provides: {})", KNOWN_MODULES.join(", ")),
        )
    })
}

fn check_hashable(key: &Value) -> Result<(), ScriptError> {
    match key {
        Value::List(_) | Value::Dict(_) => Err(type_error(format!("unhashable type: '{}'", key.type_name()))),
        _ => Ok(()),
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
    let invalid = || value_error(format!("invalid literal for int() with base {base}: {}", super::value::str_repr(s)));
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
                .ok_or_else(|| value_error(format!("could not convert string to float: {}", super::value::str_repr(s))))
        }
        Some(v @ (Value::Int(_) | Value::Bool(_) | Value::Float(_))) => Ok(Value::Float(to_f64(v, "x")?)),
        Some(other) => {
            Err(type_error(format!("float() argument must be a string or a real number, not '{}'", other.type_name())))
        }
    }
}

fn str_method(s: &str, name: &str, args: Args) -> Result<Value, ScriptError> {
    let text = |v: String| Ok(Value::Str(v));
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
                Value::Tuple(items) => items.clone(),
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
        "split" => {
            let a = args.bind("split", &["sep", "maxsplit"], 0)?;
            if !is_none(&a[1]) {
                return Err(not_supported("str.split(maxsplit=...) is not supported"));
            }
            if s.len() > ops::MAX_ITEMS {
                return Err(ScriptError::new(ErrorKind::Memory, "string too long to split"));
            }
            let parts: Vec<Value> = match &a[0] {
                None | Some(Value::None) => s.split_whitespace().map(|p| Value::Str(p.to_owned())).collect(),
                Some(v) => {
                    let sep = to_str(v, "must be str or None; sep")?;
                    if sep.is_empty() {
                        return Err(value_error("empty separator"));
                    }
                    s.split(sep).map(|p| Value::Str(p.to_owned())).collect()
                }
            };
            Ok(Value::List(parts))
        }
        "splitlines" => {
            args.bind("splitlines", &[], 0)?;
            if s.len() > ops::MAX_ITEMS {
                return Err(ScriptError::new(ErrorKind::Memory, "string too long to split"));
            }
            Ok(Value::List(s.lines().map(|p| Value::Str(p.to_owned())).collect()))
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
                parts.iter().map(String::len).sum::<usize>().saturating_add(s.len().saturating_mul(parts.len()));
            if total > ops::MAX_LEN {
                return Err(ScriptError::new(ErrorKind::Memory, "result too large"));
            }
            text(parts.join(s))
        }
        "find" | "count" => {
            let a = args.bind(name, &["sub"], 1)?;
            let sub = to_str(a[0].as_ref().unwrap_or(&Value::None), "must be str; argument")?;
            if name == "count" {
                let n = if sub.is_empty() { s.chars().count() + 1 } else { s.matches(sub).count() };
                return Ok(Value::Int(i64::try_from(n).unwrap_or(i64::MAX)));
            }
            Ok(Value::Int(s.find(sub).map_or(-1, |byte| i64::try_from(s[..byte].chars().count()).unwrap_or(i64::MAX))))
        }
        other => Err(not_supported(format!("str.{other} is not supported"))),
    }
}
