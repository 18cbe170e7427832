//! The tree-walking interpreter: statements, control flow, user functions,
//! expressions, names and scopes.
//!
//! Modules are interpreter objects, never real imports: `import` only binds
//! names from a fixed list ([`KNOWN_MODULES`]); their functions live in
//! [`crate::pyautogui`], [`crate::stdlib`] and [`crate::computer`], which get the
//! run's [`Runtime`] (its effects), never the evaluator. Every effect goes through
//! the [`ScriptHost`].
//!
//! This folder is the evaluator, one type ([`Interp`]) whose `impl` spans three
//! files because they call one another by nature: this file runs statements and
//! expressions and calls the builtins and methods, which call back into it
//! (`sorted(key=f)`, `map(f, ...)`, a method on a subscripted variable): [`builtins`]
//! holds the builtin functions and [`methods`] the methods of plain values.
//!
//! A run always ends: loop iterations and function calls together are capped at
//! [`MAX_STEPS`], calls nest at most [`MAX_CALL_DEPTH`] deep, and what the
//! program builds and reads is charged against an allocation budget.

mod builtins;
mod methods;

use std::collections::HashMap;
use std::rc::Rc;
use std::sync::Arc;

use crate::args::{iterate, no_attribute, static_name, to_f64, to_i64, to_str, Args, LoopIter};
use crate::ast::{
    BinOp, CmpOp, CompKind, Const, Expr, ExprKind, FPart, Function, FunctionBody, Generator, Handler, Program, Stmt,
    StmtKind, Target,
};
use crate::error::{not_supported, type_error, value_error, ErrorKind, ScriptError};
use crate::host::ScriptHost;
use crate::pool::MemoryPool;
use crate::runtime::{ComputerState, RunOutput, Runtime};
use crate::stop::{self, Stop};
use crate::value::heap::{self, DictMap, Key, SetMap};
use crate::value::ops;
use crate::value::{Object, UserFn, Value};

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

pub(crate) const BUILTINS: &[&str] = &[
    "print",
    "type",
    "str",
    "int",
    "float",
    "len",
    "repr",
    "abs",
    "round",
    "min",
    "max",
    "bool",
    "list",
    "tuple",
    "dict",
    "sum",
    "chr",
    "ord",
    "exit",
    "quit",
    "set",
    "range",
    "enumerate",
    "zip",
    "sorted",
    "reversed",
    "any",
    "all",
    "isinstance",
    "map",
    "filter",
    "divmod",
    "pow",
    "format",
    "hex",
    "oct",
    "bin",
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
    "issubclass",
    "hasattr",
    "frozenset",
    "object",
    "super",
    "iter",
    "next",
    "hash",
    "id",
    "callable",
    "complex",
    "slice",
    "property",
    "staticmethod",
    "classmethod",
    "ascii",
];

/// How many loop iterations (of `for`, `while` and comprehensions) and function
/// calls one run may make in total; past it the run stops with a `RuntimeError`
/// that no `except` catches.
pub const MAX_STEPS: u64 = 100_000;

/// How deeply user functions may call each other (CPython allows about 1000; agent
/// code rarely recurses, and every level costs the interpreter's own stack).
pub const MAX_CALL_DEPTH: usize = 50;

/// How deeply statements and expressions may nest while running, counting every
/// call's own nesting, so the interpreter's stack stays small.
const MAX_NESTING: usize = 400;

/// How many bytes a run may hold at once in values and printed text (live, not
/// cumulative: a value that is dropped gives its bytes back). 256 MiB leaves a
/// guest with the 2 GB upstream's VMs are given room for several runs and the
/// desktop, and is far above what agent code holds (kilobytes).
pub const MAX_MEMORY: usize = 256 << 20;

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
    /// The request's deadline and cancel flag: the run stops with `TimeoutError`
    /// within a bounded amount of work once either fires.
    pub stop: Stop,
    /// The memory this run shares with the others running at once (see
    /// [`MemoryPool`]); `None`: only its own [`MAX_MEMORY`].
    pub memory: Option<Arc<MemoryPool>>,
}

impl Globals<'static> {
    /// Plain `python -c`: nothing is bound.
    pub fn python() -> Globals<'static> {
        Globals { computer: None, computer_action_delay: 0.25, preimport: &[], stop: Stop::never(), memory: None }
    }
}

impl<'a> Globals<'a> {
    /// These globals, stopping as `stop` says.
    #[must_use]
    pub fn with_stop(mut self, stop: Stop) -> Globals<'a> {
        self.stop = stop;
        self
    }

    /// These globals, drawing memory from `pool` as well as their own budget.
    #[must_use]
    pub fn with_memory(mut self, pool: Option<Arc<MemoryPool>>) -> Globals<'a> {
        self.memory = pool;
        self
    }

    /// `/execute_windows`: `computer` and `human` are bound to `state`.
    pub fn computer(state: &'a mut ComputerState) -> Globals<'a> {
        Globals {
            computer: Some(state),
            computer_action_delay: 0.25,
            preimport: &[],
            stop: Stop::never(),
            memory: None,
        }
    }
}

/// What a run cost, by the interpreter's own accounting.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RunStats {
    /// The most bytes the program held at once (values and printed text).
    pub peak_bytes: usize,
    /// The bytes still counted once the run's values were dropped (0 unless
    /// something leaked).
    pub live_bytes_after: usize,
    /// Loop iterations and calls.
    pub steps: u64,
    /// Units of work counted inside built-ins.
    pub work: u64,
    /// Deadline and cancel checks made.
    pub stop_checks: u64,
}

/// Runs `program` against `host`.
///
/// # Errors
///
/// [`ScriptError`] for the first exception, carrying what was printed before it.
/// Effects performed before the failure are not undone.
pub fn run(program: &Program, host: &mut dyn ScriptHost, globals: Globals<'_>) -> Result<RunOutput, ScriptError> {
    run_measured(program, host, globals).0
}

/// [`run`], with what the run cost.
pub fn run_measured(
    program: &Program,
    host: &mut dyn ScriptHost,
    globals: Globals<'_>,
) -> (Result<RunOutput, ScriptError>, RunStats) {
    let _meter = heap::MeterScope::enter(MAX_MEMORY, globals.memory.clone());
    let _stop = stop::StopScope::enter(globals.stop.clone());
    let mut steps = 0;
    let result = run_in_scope(program, host, globals, &mut steps);
    let (work, stop_checks) = stop::counters();
    let stats = RunStats { peak_bytes: heap::peak(), live_bytes_after: heap::live(), steps, work, stop_checks };
    (result, stats)
}

fn run_in_scope(
    program: &Program,
    host: &mut dyn ScriptHost,
    globals: Globals<'_>,
    steps: &mut u64,
) -> Result<RunOutput, ScriptError> {
    let mut interp = Interp {
        rt: Runtime::new(host, globals.computer, globals.computer_action_delay),
        vars: HashMap::new(),
        frames: vec![Frame::default()],
        steps: 0,
        calls: 0,
        depth: 0,
        handling: Vec::new(),
    };
    interp.vars.insert("__name__".into(), Value::str("__main__"));
    let preimport_line = program.statements.first().map_or(1, |s| s.line);
    for module in globals.preimport {
        let stmt = StmtKind::Import(vec![crate::ast::ImportName { module: (*module).to_owned(), alias: None }]);
        interp
            .statement(&Stmt { line: preimport_line, column: 1, kind: stmt })
            .map_err(|e| interp.finish_error(e, 1))?;
    }
    if interp.rt.computer.is_some() {
        interp.vars.insert("computer".into(), Value::Object(Object::Computer));
        interp.vars.insert("human".into(), Value::Object(Object::Human));
    }
    for stmt in &program.statements {
        if let Err(err) = interp.block(std::slice::from_ref(stmt)) {
            if err.kind == ErrorKind::SystemExit {
                break;
            }
            *steps = interp.steps;
            return Err(interp.finish_error(err, stmt.line));
        }
    }
    *steps = interp.steps;
    if let Some(code) = interp.rt.exit {
        interp.rt.out.exit_code = code;
    }
    Ok(std::mem::take(&mut interp.rt.out))
}

/// The interpreter state for one run.
pub(crate) struct Interp<'h, 'c> {
    /// What the built-in modules act through: the host, the output, the Navi state.
    pub(crate) rt: Runtime<'h, 'c>,
    /// The module's globals.
    vars: HashMap<String, Value>,
    /// The module frame, then one per active user function call.
    frames: Vec<Frame>,
    /// Loop iterations and calls so far, against [`MAX_STEPS`].
    steps: u64,
    /// User function calls in progress.
    calls: usize,
    /// Statement and expression nesting in progress, against [`MAX_NESTING`].
    depth: usize,
    /// The exceptions whose `except` clauses are running, for a bare `raise`.
    handling: Vec<ScriptError>,
}

impl std::fmt::Debug for Interp<'_, '_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Interp").field("vars", &self.vars).field("out", &self.rt.out).finish_non_exhaustive()
    }
}

impl Interp<'_, '_> {
    /// The error a failed statement becomes, with `line` filled in and the output so far attached.
    fn finish_error(&mut self, mut err: ScriptError, line: usize) -> ScriptError {
        if err.line == 0 {
            err.line = line;
        }
        err.stdout = std::mem::take(&mut self.rt.out.stdout);
        err.stderr = std::mem::take(&mut self.rt.out.stderr);
        err
    }

    /// Counts one loop iteration or function call against [`MAX_STEPS`].
    pub(crate) fn step(&mut self) -> Result<(), ScriptError> {
        stop::check()?;
        self.steps += 1;
        if self.steps > MAX_STEPS {
            return Err(ScriptError::new(
                ErrorKind::LoopLimit,
                format!(
                    "the program ran more than {MAX_STEPS} loop iterations and function calls (this interpreter's limit)"
                ),
            ));
        }
        Ok(())
    }

    /// Enters one level of statement or expression nesting, so the interpreter's stack stays bounded.
    fn enter(&mut self) -> Result<(), ScriptError> {
        self.depth += 1;
        if self.depth > MAX_NESTING {
            self.depth -= 1;
            return Err(ScriptError::new(
                ErrorKind::Recursion,
                format!("maximum recursion depth exceeded (this interpreter nests at most {MAX_NESTING} levels)"),
            ));
        }
        Ok(())
    }

    /// Runs a block; a statement's failure carries that statement's line.
    fn block(&mut self, stmts: &[Stmt]) -> Result<Flow, ScriptError> {
        for stmt in stmts {
            let flow = self.statement(stmt).map_err(|mut e| {
                if e.line == 0 {
                    e.line = stmt.line;
                }
                e
            })?;
            if !matches!(flow, Flow::Normal) {
                return Ok(flow);
            }
        }
        Ok(Flow::Normal)
    }

    fn statement(&mut self, stmt: &Stmt) -> Result<Flow, ScriptError> {
        self.enter()?;
        let result = self.statement_inner(stmt);
        self.depth -= 1;
        result
    }

    /// Dispatches on the statement form; like [`Self::eval_uncharged`], every arm is
    /// its own function to keep each nesting level's stack frame small.
    fn statement_inner(&mut self, stmt: &Stmt) -> Result<Flow, ScriptError> {
        match &stmt.kind {
            StmtKind::Pass => Ok(Flow::Normal),
            StmtKind::Break => Ok(Flow::Break),
            StmtKind::Continue => Ok(Flow::Continue),
            StmtKind::Expr(expr) => self.run_expr(expr),
            StmtKind::Import(names) => self.run_import(names),
            StmtKind::FromImport { module, names } => self.run_from_import(module, names),
            StmtKind::Assign { targets, value } => self.run_assign(targets, value),
            StmtKind::AugAssign { target, op, value } => self.run_aug_assign(target, *op, value),
            StmtKind::If { test, body, orelse } => self.run_if(test, body, orelse),
            StmtKind::While { test, body, orelse } => self.run_while(test, body, orelse),
            StmtKind::For { target, iter, body, orelse } => self.run_for(target, iter, body, orelse),
            StmtKind::Try { body, handlers, orelse, finalbody } => self.run_try(body, handlers, orelse, finalbody),
            StmtKind::Raise(exc) => self.run_raise(exc),
            StmtKind::Def(def) => self.run_def(def),
            StmtKind::Return(value) => self.run_return(value.as_ref()),
            StmtKind::Global(names) => {
                if let Some(frame) = self.frames.last_mut() {
                    frame.global_names.extend(names.iter().cloned());
                }
                Ok(Flow::Normal)
            }
            StmtKind::Assert { test, msg } => self.run_assert(test, msg),
            StmtKind::Delete(targets) => self.run_delete(targets),
        }
    }

    #[inline(never)]
    fn run_expr(&mut self, expr: &Expr) -> Result<Flow, ScriptError> {
        self.eval(expr)?;
        Ok(Flow::Normal)
    }

    #[inline(never)]
    fn run_assign(&mut self, targets: &[Target], value: &Expr) -> Result<Flow, ScriptError> {
        let value = self.eval(value)?;
        for target in targets {
            self.assign(target, value.clone(), false)?;
        }
        Ok(Flow::Normal)
    }

    #[inline(never)]
    fn run_aug_assign(&mut self, target: &Target, op: BinOp, value: &Expr) -> Result<Flow, ScriptError> {
        self.aug_assign(target, op, value)?;
        Ok(Flow::Normal)
    }

    #[inline(never)]
    fn run_if(&mut self, test: &Expr, body: &[Stmt], orelse: &[Stmt]) -> Result<Flow, ScriptError> {
        let branch = if self.eval(test)?.truthy() { body } else { orelse };
        self.block(branch)
    }

    #[inline(never)]
    fn run_def(&mut self, def: &Arc<Function>) -> Result<Flow, ScriptError> {
        let f = self.make_function(def)?;
        self.bind(&def.name, f);
        Ok(Flow::Normal)
    }

    #[inline(never)]
    fn run_return(&mut self, value: Option<&Expr>) -> Result<Flow, ScriptError> {
        let value = match value {
            Some(v) => self.eval(v)?,
            None => Value::None,
        };
        Ok(Flow::Return(value))
    }

    #[inline(never)]
    fn run_delete(&mut self, targets: &[Target]) -> Result<Flow, ScriptError> {
        for target in targets {
            self.delete(target)?;
        }
        Ok(Flow::Normal)
    }

    #[inline(never)]
    fn eval_call(&mut self, func: &Expr, args: &[Expr], kwargs: &[(String, Expr)]) -> Result<Value, ScriptError> {
        if let ExprKind::Attr(recv, method) = &func.kind {
            if let Some(value) = self.call_mutating(recv, method, args, kwargs)? {
                return Ok(value);
            }
        }
        let func = self.eval(func)?;
        let call_args = self.eval_args(args, kwargs)?;
        self.call(func, call_args)
    }

    #[inline(never)]
    fn eval_subscript(&mut self, obj: &Expr, index: &Expr) -> Result<Value, ScriptError> {
        if let ExprKind::Slice { lower, upper, step } = &index.kind {
            let obj = self.eval(obj)?;
            let mut bound = |e: &Option<Box<Expr>>| -> Result<Option<i64>, ScriptError> {
                match e {
                    None => Ok(None),
                    Some(e) => match self.eval(e)? {
                        Value::None => Ok(None),
                        Value::Int(i) => Ok(Some(i)),
                        Value::Bool(b) => Ok(Some(i64::from(b))),
                        _ => Err(type_error("slice indices must be integers or None or have an __index__ method")),
                    },
                }
            };
            let (lower, upper, step) = (bound(lower)?, bound(upper)?, bound(step)?);
            return slice(&obj, lower, upper, step);
        }
        // Index a variable in place rather than copying all of it first.
        if let ExprKind::Name(name) = &obj.kind {
            if self.lookup_ref(name).is_some_and(|v| matches!(v, Value::List(_) | Value::Tuple(_) | Value::Dict(_))) {
                let index = self.eval(index)?;
                let container = self.lookup_ref(name).unwrap_or(&Value::None);
                return index_value(container, &index);
            }
        }
        let obj = self.eval(obj)?;
        let index = self.eval(index)?;
        self.subscript(&obj, &index)
    }

    #[inline(never)]
    fn eval_dict(&mut self, items: &[(Expr, Expr)]) -> Result<Value, ScriptError> {
        let mut entries = DictMap::new();
        for (k, v) in items {
            let key = self.eval(k)?;
            let value = self.eval(v)?;
            dict_insert(&mut entries, key, value)?;
        }
        Ok(Value::dict(entries))
    }

    #[inline(never)]
    fn eval_boolop(&mut self, and_: &bool, values: &[Expr]) -> Result<Value, ScriptError> {
        let mut last = Value::None;
        for v in values {
            last = self.eval(v)?;
            if last.truthy() != *and_ {
                return Ok(last);
            }
        }
        Ok(last)
    }

    #[inline(never)]
    fn eval_compare(&mut self, left: &Expr, ops: &[(CmpOp, Expr)]) -> Result<Value, ScriptError> {
        let mut left = self.eval(left)?;
        for (op, right) in ops {
            let right = self.eval(right)?;
            if !self.compare(*op, &left, &right)? {
                return Ok(Value::Bool(false));
            }
            left = right;
        }
        Ok(Value::Bool(true))
    }

    #[inline(never)]
    fn eval_comp(
        &mut self,
        kind: &CompKind,
        elt: &Expr,
        value: &Option<Box<Expr>>,
        generators: &[Generator],
    ) -> Result<Value, ScriptError> {
        if let Some(frame) = self.frames.last_mut() {
            frame.comp.push(HashMap::new());
        }
        let mut items = Vec::new();
        let result = self.comprehension(generators, elt, value.as_deref(), &mut items);
        if let Some(frame) = self.frames.last_mut() {
            frame.comp.pop();
        }
        result?;
        Ok(match kind {
            CompKind::List | CompKind::Generator => Value::list(items),
            CompKind::Set => make_set(items)?,
            CompKind::Dict => {
                let mut entries = DictMap::new();
                for pair in items {
                    if let Value::Tuple(kv) = pair {
                        let mut kv = kv.into_inner();
                        let v = kv.pop().unwrap_or(Value::None);
                        let k = kv.pop().unwrap_or(Value::None);
                        dict_insert(&mut entries, k, v)?;
                    }
                }
                Value::dict(entries)
            }
        })
    }

    #[inline(never)]
    fn run_import(&mut self, names: &[crate::ast::ImportName]) -> Result<Flow, ScriptError> {
        for name in names {
            let module = find_module(&name.module)?;
            match &name.alias {
                Some(alias) => self.bind(alias, Value::Module(module)),
                None => {
                    let top = name.module.split('.').next().unwrap_or(&name.module);
                    let top = find_module(top)?;
                    self.bind(top, Value::Module(top));
                }
            }
        }
        Ok(Flow::Normal)
    }

    #[inline(never)]
    fn run_from_import(&mut self, module: &str, names: &[(String, Option<String>)]) -> Result<Flow, ScriptError> {
        let module = find_module(module)?;
        for (name, alias) in names {
            let full = format!("{module}.{name}");
            let value = match KNOWN_MODULES.iter().find(|m| **m == full) {
                Some(sub) => Value::Module(sub),
                None => self.module_attr(module, name).map_err(|_| {
                    ScriptError::new(
                        ErrorKind::Import,
                        format!("cannot import name '{name}' from '{module}' (not supported by this interpreter)"),
                    )
                })?,
            };
            self.bind(alias.as_ref().unwrap_or(name), value);
        }
        Ok(Flow::Normal)
    }

    #[inline(never)]
    fn run_while(&mut self, test: &Expr, body: &[Stmt], orelse: &[Stmt]) -> Result<Flow, ScriptError> {
        loop {
            if !self.eval(test)?.truthy() {
                return self.block(orelse);
            }
            self.step()?;
            match self.block(body)? {
                Flow::Break => return Ok(Flow::Normal),
                Flow::Normal | Flow::Continue => {}
                ret @ Flow::Return(_) => return Ok(ret),
            }
        }
    }

    #[inline(never)]
    fn run_for(&mut self, target: &Target, iter: &Expr, body: &[Stmt], orelse: &[Stmt]) -> Result<Flow, ScriptError> {
        let iterable = self.eval(iter)?;
        let mut items = LoopIter::new(iterable)?;
        while let Some(item) = items.next() {
            self.step()?;
            self.assign(target, item, false)?;
            match self.block(body)? {
                Flow::Break => return Ok(Flow::Normal),
                Flow::Normal | Flow::Continue => {}
                ret @ Flow::Return(_) => return Ok(ret),
            }
        }
        self.block(orelse)
    }

    #[inline(never)]
    fn run_try(
        &mut self,
        body: &[Stmt],
        handlers: &[Handler],
        orelse: &[Stmt],
        finalbody: &[Stmt],
    ) -> Result<Flow, ScriptError> {
        let result = match self.block(body) {
            Err(err) if err.is_catchable() && !handlers.is_empty() => self.handle(err, handlers),
            Ok(Flow::Normal) => self.block(orelse),
            other => other,
        };
        if matches!(&result, Err(err) if !err.is_catchable()) || finalbody.is_empty() {
            return result;
        }
        match self.block(finalbody)? {
            Flow::Normal => result,
            flow => Ok(flow),
        }
    }

    #[inline(never)]
    fn run_raise(&mut self, exc: &Option<Expr>) -> Result<Flow, ScriptError> {
        let Some(exc) = exc else {
            return Err(self.handling.last().cloned().map_or_else(
                || ScriptError::new(ErrorKind::Runtime, "No active exception to reraise"),
                |mut e| {
                    e.line = 0;
                    e
                },
            ));
        };
        Err(match self.eval(exc)? {
            Value::ExcType(kind) => ScriptError::new(kind, ""),
            Value::Exception(kind, message) => ScriptError::new(kind, message),
            _ => type_error("exceptions must derive from BaseException"),
        })
    }

    #[inline(never)]
    fn run_assert(&mut self, test: &Expr, msg: &Option<Expr>) -> Result<Flow, ScriptError> {
        if !self.eval(test)?.truthy() {
            let message = match msg {
                Some(m) => self.eval(m)?.to_str(),
                None => String::new(),
            };
            return Err(ScriptError::new(ErrorKind::Assertion, message));
        }
        Ok(Flow::Normal)
    }

    /// Runs the first `except` clause that matches `err`, or gives `err` back.
    fn handle(&mut self, err: ScriptError, handlers: &[Handler]) -> Result<Flow, ScriptError> {
        for h in handlers {
            let matches = match &h.types {
                None => true,
                Some(types) => {
                    let types = self.eval(types).map_err(|mut e| {
                        e.line = h.line;
                        e
                    })?;
                    exception_matches(&types, err.kind)?
                }
            };
            if matches {
                if let Some(name) = &h.name {
                    self.bind(name, Value::Exception(err.kind, err.message.clone()));
                }
                self.handling.push(err);
                let result = self.block(&h.body);
                self.handling.pop();
                return result;
            }
        }
        Err(err)
    }

    /// A `def` or `lambda` as a value: its defaults evaluated now, and a snapshot of
    /// the enclosing function's variables when it is defined inside one.
    fn make_function(&mut self, def: &Arc<Function>) -> Result<Value, ScriptError> {
        let mut defaults = Vec::with_capacity(def.params.len());
        for p in &def.params {
            defaults.push(match &p.default {
                Some(d) => Some(self.eval(d)?),
                None => None,
            });
        }
        let captured = match self.frames.last() {
            Some(frame) if frame.locals.is_some() || !frame.comp.is_empty() => {
                let mut seen: HashMap<String, Value> = frame.captured.as_deref().cloned().unwrap_or_default();
                if let Some(locals) = &frame.locals {
                    seen.extend(locals.iter().map(|(k, v)| (k.clone(), v.clone())));
                }
                for scope in &frame.comp {
                    seen.extend(scope.iter().map(|(k, v)| (k.clone(), v.clone())));
                }
                Some(Rc::new(seen))
            }
            _ => None,
        };
        Ok(Value::UserFn(Rc::new(UserFn { def: Arc::clone(def), defaults, captured })))
    }

    /// Calls a `def` or `lambda` function.
    fn call_user(&mut self, f: &UserFn, args: Args) -> Result<Value, ScriptError> {
        let name = f.def.name.as_str();
        let params = &f.def.params;
        if self.calls >= MAX_CALL_DEPTH {
            return Err(ScriptError::new(
                ErrorKind::Recursion,
                format!("maximum recursion depth exceeded (this interpreter allows {MAX_CALL_DEPTH} nested calls)"),
            ));
        }
        self.step()?;
        // Python's grammar puts parameters with defaults last, so the leading ones
        // without a default are the required ones, as `Args::bind` takes them.
        let names: Vec<&str> = params.iter().map(|p| p.name.as_str()).collect();
        let required = f.defaults.iter().take_while(|d| d.is_none()).count();
        let slots = args.bind(name, &names, required)?;
        let mut locals = HashMap::new();
        for ((slot, param), default) in slots.into_iter().zip(params).zip(&f.defaults) {
            // A slot left empty is an optional parameter: bind refused missing required ones.
            locals.insert(param.name.clone(), slot.or_else(|| default.clone()).unwrap_or(Value::None));
        }
        self.frames.push(Frame {
            locals: Some(locals),
            comp: Vec::new(),
            captured: f.captured.clone(),
            global_names: Vec::new(),
        });
        self.calls += 1;
        let result = match &f.def.body {
            FunctionBody::Block(body) => self.block(body).map(|flow| match flow {
                Flow::Return(v) => v,
                _ => Value::None,
            }),
            FunctionBody::Expr(expr) => self.eval(expr),
        };
        self.calls -= 1;
        self.frames.pop();
        result
    }

    /// Binds `name` in the current scope (a function's locals unless declared
    /// `global`, else the module's globals).
    fn bind(&mut self, name: &str, value: Value) {
        if let Some(frame) = self.frames.last_mut() {
            if let Some(locals) = frame.locals.as_mut().filter(|_| !frame.global_names.iter().any(|g| g == name)) {
                locals.insert(name.to_owned(), value);
                return;
            }
        }
        self.vars.insert(name.to_owned(), value);
    }

    /// Assigns `value` to `target`; `comp` binds names in the innermost comprehension scope.
    fn assign(&mut self, target: &Target, value: Value, comp: bool) -> Result<(), ScriptError> {
        match target {
            Target::Name(name) => {
                let scope = if comp { self.frames.last_mut().and_then(|f| f.comp.last_mut()) } else { None };
                match scope {
                    Some(scope) => {
                        scope.insert(name.clone(), value);
                    }
                    None => self.bind(name, value),
                }
                Ok(())
            }
            Target::Attr(obj, attr) => {
                let obj = self.eval(obj)?;
                self.set_attr(&obj, attr, &value)
            }
            Target::Subscript(obj, index) => {
                let key = self.eval(index)?;
                self.set_item(obj, key, value)
            }
            Target::Unpack(targets) => {
                let items = iterate(&value)?;
                if items.len() < targets.len() {
                    return Err(value_error(format!(
                        "not enough values to unpack (expected {}, got {})",
                        targets.len(),
                        items.len()
                    )));
                }
                if items.len() > targets.len() {
                    return Err(value_error(format!("too many values to unpack (expected {})", targets.len())));
                }
                for (t, v) in targets.iter().zip(items) {
                    self.assign(t, v, comp)?;
                }
                Ok(())
            }
        }
    }

    fn aug_assign(&mut self, target: &Target, op: BinOp, value: &Expr) -> Result<(), ScriptError> {
        match target {
            Target::Name(name) => {
                let current = self.lookup(name)?;
                let rhs = self.eval(value)?;
                let new = self.binary(op, &current, &rhs)?;
                self.bind(name, new);
                Ok(())
            }
            Target::Attr(obj, attr) => {
                let obj = self.eval(obj)?;
                let current = self.get_attr(obj.clone(), attr)?;
                let rhs = self.eval(value)?;
                let new = self.binary(op, &current, &rhs)?;
                self.set_attr(&obj, attr, &new)
            }
            Target::Subscript(obj, index) => {
                let container = self.eval(obj)?;
                let key = self.eval(index)?;
                let current = self.subscript(&container, &key)?;
                let rhs = self.eval(value)?;
                let new = self.binary(op, &current, &rhs)?;
                self.set_item(obj, key, new)
            }
            Target::Unpack(_) => Err(type_error("illegal expression for augmented assignment")),
        }
    }

    /// `left op right`, charging what it builds.
    fn binary(&mut self, op: BinOp, left: &Value, right: &Value) -> Result<Value, ScriptError> {
        let value = ops::binary(op, left, right)?;
        self.charge(&value)?;
        Ok(value)
    }

    /// `obj[key] = value`: changes the variable `obj` names (through any subscripts).
    fn set_item(&mut self, obj: &Expr, key: Value, value: Value) -> Result<(), ScriptError> {
        let Some(place) = self.place(obj)? else {
            let container = self.eval(obj)?;
            let mut scratch = container;
            return store_item(&mut scratch, key, value);
        };
        let inserted = value.depth().max(key.depth());
        Self::guard_depth(&place, inserted)?;
        match self.place_mut(&place)? {
            Some(container) => store_item(container, key, value)?,
            None => {
                let mut scratch = self.eval(obj)?;
                return store_item(&mut scratch, key, value);
            }
        }
        self.settle(&place, inserted)
    }

    fn delete(&mut self, target: &Target) -> Result<(), ScriptError> {
        match target {
            Target::Name(name) => {
                let frame = self.frames.last_mut();
                let removed = match frame.and_then(|f| f.locals.as_mut()) {
                    Some(locals) if locals.contains_key(name) => locals.remove(name),
                    _ => self.vars.remove(name),
                };
                removed
                    .map(drop)
                    .ok_or_else(|| ScriptError::new(ErrorKind::Name, format!("name '{name}' is not defined")))
            }
            Target::Subscript(obj, index) => {
                let key = self.eval(index)?;
                let place = self.place(obj)?;
                let container = match &place {
                    Some(place) => self.place_mut(place)?,
                    None => None,
                };
                let Some(container) = container else {
                    let mut scratch = self.eval(obj)?;
                    return remove_item(&mut scratch, &key);
                };
                remove_item(container, &key)
            }
            Target::Attr(..) => Err(not_supported("deleting attributes is not supported")),
            Target::Unpack(targets) => {
                for t in targets {
                    self.delete(t)?;
                }
                Ok(())
            }
        }
    }

    /// The variable and the keys an expression like `a[1]['k']` names, if it names one.
    fn place(&mut self, expr: &Expr) -> Result<Option<Place>, ScriptError> {
        match &expr.kind {
            ExprKind::Name(name) if self.lookup_ref(name).is_some() => {
                Ok(Some(Place { root: name.clone(), keys: Vec::new() }))
            }
            ExprKind::Subscript(obj, index) if !matches!(index.kind, ExprKind::Slice { .. }) => {
                let Some(mut place) = self.place(obj)? else { return Ok(None) };
                place.keys.push(self.eval(index)?);
                Ok(Some(place))
            }
            _ => Ok(None),
        }
    }

    /// The value a [`Place`] names, to change it in place; `None` when it is not
    /// reachable for writing (a variable captured by a closure, a string in the path).
    fn place_mut(&mut self, place: &Place) -> Result<Option<&mut Value>, ScriptError> {
        self.place_mut_raising(place, None)
    }

    /// Notes that a value nesting `inserted` levels was put into the container a
    /// [`Place`] names, so that it and every container on the way record their depth.
    fn settle(&mut self, place: &Place, inserted: u32) -> Result<(), ScriptError> {
        if let Some(leaf) = self.place_mut_raising(place, Some(inserted))? {
            raise_depth(leaf, inserted);
        }
        Ok(())
    }

    /// Refuses to put a value nesting `inserted` levels into the container a
    /// [`Place`] names when the variable would then nest too deeply.
    fn guard_depth(place: &Place, inserted: u32) -> Result<(), ScriptError> {
        let total = usize::try_from(inserted).unwrap_or(usize::MAX).saturating_add(place.keys.len() + 1);
        if total > MAX_VALUE_DEPTH {
            return Err(too_deep());
        }
        Ok(())
    }

    /// [`Self::place_mut`]; with `raise`, each container on the way notes that an
    /// item below it now nests `raise` levels more than the leaf's position.
    fn place_mut_raising(&mut self, place: &Place, raise: Option<u32>) -> Result<Option<&mut Value>, ScriptError> {
        let frame_index = self.frames.len().checked_sub(1);
        let mut current: Option<&mut Value> = None;
        if let Some(i) = frame_index {
            let in_comp = self.frames[i].comp.iter().rposition(|s| s.contains_key(&place.root));
            let in_locals = self.frames[i].locals.as_ref().is_some_and(|l| l.contains_key(&place.root));
            let frame = &mut self.frames[i];
            if let Some(c) = in_comp {
                current = frame.comp[c].get_mut(&place.root);
            } else if in_locals {
                current = frame.locals.as_mut().and_then(|l| l.get_mut(&place.root));
            } else if frame.captured.as_ref().is_some_and(|c| c.contains_key(&place.root)) {
                return Ok(None);
            }
        }
        let mut current = match current {
            Some(v) => v,
            None => match self.vars.get_mut(&place.root) {
                Some(v) => v,
                None => return Ok(None),
            },
        };
        let levels = place.keys.len();
        for (i, key) in place.keys.iter().enumerate() {
            if let Some(inserted) = raise {
                let below = u32::try_from(levels - i).unwrap_or(u32::MAX);
                raise_depth(current, inserted.saturating_add(below));
            }
            current = match current {
                Value::List(items) => {
                    let i = seq_index(items.len(), key, "list")?;
                    &mut items.items_mut()[i]
                }
                Value::Tuple(items) => {
                    let i = seq_index(items.len(), key, "tuple")?;
                    &mut items.items_mut()[i]
                }
                Value::Dict(entries) => match entries.items_mut().get_mut(&Key(key.clone())) {
                    Some(v) => v,
                    None => return Err(ScriptError::new(ErrorKind::Key, key.repr())),
                },
                _ => return Ok(None),
            };
        }
        Ok(Some(current))
    }

    /// Calls a list, dict or set method that changes its receiver, on the variable
    /// the receiver expression names; `None` when the call is not such a method.
    fn call_mutating(
        &mut self,
        recv: &Expr,
        method: &str,
        args: &[Expr],
        kwargs: &[(String, Expr)],
    ) -> Result<Option<Value>, ScriptError> {
        if !self::methods::is_mutating(method) {
            return Ok(None);
        }
        let Some(place) = self.place(recv)? else { return Ok(None) };
        let applies = match self.place_mut(&place)? {
            Some(target) => self::methods::mutates(target, method),
            None => false,
        };
        if !applies {
            return Ok(None);
        }
        let call_args = self.eval_args(args, kwargs)?;
        let inserted = call_args.pos.iter().chain(call_args.kw.iter().map(|(_, v)| v)).map(Value::depth).max();
        let inserted = inserted.unwrap_or(0).saturating_add(1);
        Self::guard_depth(&place, inserted)?;
        // The receiver is taken out while the method runs, so that a key function may run code.
        let Some(slot) = self.place_mut(&place)? else { return Ok(None) };
        let mut target = std::mem::replace(slot, Value::None);
        let result = self.mutate(&mut target, method, call_args);
        if let Some(slot) = self.place_mut(&place)? {
            *slot = target;
        }
        self.settle(&place, inserted)?;
        let value = result?;
        self.charge(&value)?;
        Ok(Some(value))
    }

    fn eval_args(&mut self, args: &[Expr], kwargs: &[(String, Expr)]) -> Result<Args, ScriptError> {
        let mut call_args = Args::default();
        for arg in args {
            call_args.pos.push(self.eval(arg)?);
        }
        for (name, arg) in kwargs {
            let value = self.eval(arg)?;
            call_args.kw.push((name.clone(), value));
        }
        Ok(call_args)
    }

    fn set_attr(&mut self, obj: &Value, attr: &str, value: &Value) -> Result<(), ScriptError> {
        match (obj, attr) {
            (Value::Module("pyautogui"), "FAILSAFE") => {
                self.rt.out.failsafe = Some(value.truthy());
                Ok(())
            }
            (Value::Module("pyautogui"), "PAUSE") => {
                let pause = to_f64(value, "pyautogui.PAUSE")?;
                self.rt.out.pause = Some(pause);
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
        self.enter()?;
        let value = self.eval_uncharged(expr);
        self.depth -= 1;
        self.charged(value)
    }

    /// `value`, once checked against the memory budget and the nesting cap.
    #[inline(never)]
    fn charged(&mut self, value: Result<Value, ScriptError>) -> Result<Value, ScriptError> {
        let value = value?;
        self.charge(&value)?;
        Ok(value)
    }

    /// Checks, right after `value` was made, that the run still holds no more than
    /// its memory budget (values that were sized beforehand were refused before
    /// they were built) and that `value` does not nest too deeply.
    pub(crate) fn charge(&mut self, value: &Value) -> Result<(), ScriptError> {
        if usize::try_from(value.depth()).unwrap_or(usize::MAX) > MAX_VALUE_DEPTH {
            return Err(too_deep());
        }
        heap::check()
    }

    /// Dispatches on the expression form; every arm is its own function so that each
    /// level of nesting costs the stack only this small frame and the arm it runs.
    fn eval_uncharged(&mut self, expr: &Expr) -> Result<Value, ScriptError> {
        match &expr.kind {
            ExprKind::Const(c) => Ok(const_value(c)),
            ExprKind::Name(name) => self.lookup(name),
            ExprKind::Attr(obj, name) => self.eval_attr(obj, name),
            ExprKind::Call { func, args, kwargs } => self.eval_call(func, args, kwargs),
            ExprKind::Subscript(obj, index) => self.eval_subscript(obj, index),
            ExprKind::Slice { .. } => Err(not_supported("slice objects outside a subscript are not supported")),
            ExprKind::List(items) => self.eval_sequence(items, 'l'),
            ExprKind::Tuple(items) => self.eval_sequence(items, 't'),
            ExprKind::Set(items) => self.eval_sequence(items, 's'),
            ExprKind::Dict(items) => self.eval_dict(items),
            ExprKind::Unary(op, operand) => self.eval_unary(*op, operand),
            ExprKind::Binary(op, left, right) => self.eval_binary(*op, left, right),
            ExprKind::BoolOp { and_, values } => self.eval_boolop(and_, values),
            ExprKind::Compare { left, ops } => self.eval_compare(left, ops),
            ExprKind::IfExp { test, body, orelse } => self.eval_ifexp(test, body, orelse),
            ExprKind::FString(parts) => self.eval_fstring(parts),
            ExprKind::Comp { kind, elt, value, generators } => self.eval_comp(kind, elt, value, generators),
            ExprKind::Lambda(def) => self.make_function(def),
        }
    }

    #[inline(never)]
    fn eval_attr(&mut self, obj: &Expr, name: &str) -> Result<Value, ScriptError> {
        let obj = self.eval(obj)?;
        self.get_attr(obj, name)
    }

    #[inline(never)]
    fn eval_sequence(&mut self, items: &[Expr], kind: char) -> Result<Value, ScriptError> {
        let values = self.eval_all(items)?;
        match kind {
            'l' => Ok(Value::list(values)),
            't' => Ok(Value::tuple(values)),
            _ => make_set(values),
        }
    }

    #[inline(never)]
    fn eval_unary(&mut self, op: crate::ast::UnaryOp, operand: &Expr) -> Result<Value, ScriptError> {
        let v = self.eval(operand)?;
        ops::unary(op, &v)
    }

    #[inline(never)]
    fn eval_binary(&mut self, op: BinOp, left: &Expr, right: &Expr) -> Result<Value, ScriptError> {
        let l = self.eval(left)?;
        let r = self.eval(right)?;
        ops::binary(op, &l, &r)
    }

    #[inline(never)]
    fn eval_ifexp(&mut self, test: &Expr, body: &Expr, orelse: &Expr) -> Result<Value, ScriptError> {
        if self.eval(test)?.truthy() {
            self.eval(body)
        } else {
            self.eval(orelse)
        }
    }

    #[inline(never)]
    fn eval_fstring(&mut self, parts: &[FPart]) -> Result<Value, ScriptError> {
        Ok(Value::str(self.fstring(parts)?))
    }

    /// Runs the `for`/`if` clauses of a comprehension from `generators[0]`, pushing
    /// each element (a `(key, value)` tuple for a dict) to `out`.
    fn comprehension(
        &mut self,
        generators: &[Generator],
        elt: &Expr,
        value: Option<&Expr>,
        out: &mut Vec<Value>,
    ) -> Result<(), ScriptError> {
        let Some((first, rest)) = generators.split_first() else {
            let item = self.eval(elt)?;
            let item = match value {
                Some(v) => Value::tuple(vec![item, self.eval(v)?]),
                None => item,
            };
            if out.len() >= ops::MAX_ITEMS {
                return Err(ScriptError::new(
                    ErrorKind::Memory,
                    format!("result would exceed {} items", ops::MAX_ITEMS),
                ));
            }
            out.push(item);
            return Ok(());
        };
        let iterable = self.eval(&first.iter)?;
        let mut items = LoopIter::new(iterable)?;
        'items: while let Some(item) = items.next() {
            self.step()?;
            self.assign(&first.target, item, true)?;
            for cond in &first.ifs {
                if !self.eval(cond)?.truthy() {
                    continue 'items;
                }
            }
            self.comprehension(rest, elt, value, out)?;
        }
        Ok(())
    }

    /// The text of an f-string.
    fn fstring(&mut self, parts: &[FPart]) -> Result<String, ScriptError> {
        let mut out = String::new();
        for part in parts {
            match part {
                FPart::Lit(s) => out.push_str(s),
                FPart::Field { expr, conversion, spec } => {
                    let value = self.eval(expr)?;
                    let value = match conversion {
                        Some('r' | 'a') => Value::str(value.repr()),
                        Some(_) => Value::str(value.to_str()),
                        None => value,
                    };
                    let spec = self.fstring(spec)?;
                    out.push_str(&crate::value::format::format_value(&value, &spec)?);
                }
            }
            if out.len() > ops::MAX_LEN {
                return Err(ScriptError::new(ErrorKind::Memory, format!("result would exceed {} items", ops::MAX_LEN)));
            }
        }
        Ok(out)
    }

    /// One comparison of a chain.
    fn compare(&mut self, op: CmpOp, left: &Value, right: &Value) -> Result<bool, ScriptError> {
        Ok(match op {
            CmpOp::Eq => ops::equal(left, right),
            CmpOp::NotEq => !ops::equal(left, right),
            CmpOp::Lt | CmpOp::LtE | CmpOp::Gt | CmpOp::GtE => ops::ordered(op.symbol(), left, right)?,
            CmpOp::In => self.contains(right, left)?,
            CmpOp::NotIn => !self.contains(right, left)?,
            CmpOp::Is => identical(left, right),
            CmpOp::IsNot => !identical(left, right),
        })
    }

    /// `item in container`.
    pub(crate) fn contains(&mut self, container: &Value, item: &Value) -> Result<bool, ScriptError> {
        Ok(match container {
            Value::Str(s) => match item {
                Value::Str(sub) => s.contains(sub.as_str()),
                other => {
                    return Err(type_error(format!(
                        "'in <string>' requires string as left operand, not {}",
                        other.type_name()
                    )))
                }
            },
            Value::List(items) | Value::Tuple(items) => {
                stop::work(items.len() as u64)?;
                items.iter().any(|v| ops::equal(v, item))
            }
            Value::Set(items) => {
                check_hashable(item)?;
                items.contains(&Key(item.clone()))
            }
            Value::Dict(entries) => {
                check_hashable(item)?;
                entries.contains_key(&Key(item.clone()))
            }
            Value::Range(start, stop, step) => match item {
                Value::Int(i) => {
                    let inside = if *step > 0 { start <= i && i < stop } else { stop < i && i <= start };
                    inside && (i128::from(*i) - i128::from(*start)) % i128::from(*step) == 0
                }
                _ => iterate(container)?.iter().any(|v| ops::equal(v, item)),
            },
            Value::Point(a, b) | Value::Size(a, b) => {
                ops::equal(&Value::Int(*a), item) || ops::equal(&Value::Int(*b), item)
            }
            Value::Object(Object::Environ) => {
                let name = to_str(item, "environment variable name")?;
                self.rt.host.env_var(name).is_some()
            }
            other => return Err(type_error(format!("argument of type '{}' is not iterable", other.type_name()))),
        })
    }

    fn eval_all(&mut self, items: &[Expr]) -> Result<Vec<Value>, ScriptError> {
        items.iter().map(|e| self.eval(e)).collect()
    }

    /// A variable's value without copying it: comprehension scopes, then the
    /// function's locals and what its closure saw, then the globals.
    fn lookup_ref(&self, name: &str) -> Option<&Value> {
        if let Some(frame) = self.frames.last() {
            for scope in frame.comp.iter().rev() {
                if let Some(v) = scope.get(name) {
                    return Some(v);
                }
            }
            if let Some(v) = frame.locals.as_ref().and_then(|l| l.get(name)) {
                return Some(v);
            }
            if let Some(v) = frame.captured.as_ref().and_then(|c| c.get(name)) {
                return Some(v);
            }
        }
        self.vars.get(name)
    }

    fn lookup(&self, name: &str) -> Result<Value, ScriptError> {
        if let Some(v) = self.lookup_ref(name) {
            return Ok(v.clone());
        }
        if let Some(b) = static_name(BUILTINS, name) {
            return Ok(Value::Function { module: "", name: b });
        }
        if let Some(kind) = ErrorKind::from_python_name(name) {
            return Ok(Value::ExcType(kind));
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
            "pyautogui" => crate::pyautogui::attr(name, &self.rt.out),
            _ => crate::stdlib::attr(module, name),
        };
        found.ok_or_else(|| {
            ScriptError::new(
                ErrorKind::Attribute,
                format!("module '{module}' has no attribute '{name}' ({module}.{name} is not supported by this interpreter)"),
            )
        })
    }

    fn get_attr(&mut self, obj: Value, name: &str) -> Result<Value, ScriptError> {
        use self::methods::{DICT_METHODS, LIST_METHODS, SET_METHODS, STR_METHODS, TUPLE_METHODS};
        let method = |list: &[&'static str], obj: &Value| {
            static_name(list, name).map(|m| Value::Method(Box::new(obj.clone()), m))
        };
        let found = match &obj {
            Value::Module(module) => return self.module_attr(module, name),
            Value::Str(_) => method(STR_METHODS, &obj),
            Value::Dict(_) => method(DICT_METHODS, &obj),
            Value::List(_) => method(LIST_METHODS, &obj),
            Value::Tuple(_) => method(TUPLE_METHODS, &obj),
            Value::Set(_) => method(SET_METHODS, &obj),
            Value::Type(t) if name == "__name__" => Some(Value::str(t.rsplit('.').next().unwrap_or(t).to_owned())),
            Value::ExcType(kind) if name == "__name__" => Some(Value::str(kind.python_name().to_owned())),
            Value::Function { name: f, .. } if name == "__name__" => Some(Value::str((*f).to_owned())),
            Value::UserFn(f) if name == "__name__" => Some(Value::str(f.def.name.clone())),
            Value::Exception(_, message) => match name {
                "args" => Some(Value::tuple(vec![Value::str(message.clone())])),
                _ => None,
            },
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
                    "size" => Some(Value::tuple(vec![Value::Int(*width), Value::Int(*height)])),
                    "width" => Some(Value::Int(*width)),
                    "height" => Some(Value::Int(*height)),
                    "mode" => Some(Value::str("RGB")),
                    "save" => method(&["save"], &obj),
                    _ => {
                        return Err(not_supported(format!("Image.{name} is not supported by this interpreter")));
                    }
                },
                Object::Environ => method(&["get"], &obj),
                Object::Completed { args, returncode, stdout, stderr } => match name {
                    "args" => Some((**args).clone()),
                    "returncode" => Some(Value::Int(*returncode)),
                    "stdout" => Some(stdout.clone().map_or(Value::None, Value::str)),
                    "stderr" => Some(stderr.clone().map_or(Value::None, Value::str)),
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
                _ => return crate::computer::attr(&mut self.rt, object, name),
            },
            _ => None,
        };
        found.ok_or_else(|| no_attribute(&obj, name))
    }

    fn subscript(&mut self, obj: &Value, index: &Value) -> Result<Value, ScriptError> {
        match obj {
            Value::Object(Object::Environ) => {
                let name = to_str(index, "environment variable name")?;
                self.rt.host.env_var(name).map(Value::str).ok_or_else(|| ScriptError::new(ErrorKind::Key, index.repr()))
            }
            other => index_value(other, index),
        }
    }

    pub(crate) fn call(&mut self, func: Value, args: Args) -> Result<Value, ScriptError> {
        match func {
            Value::Function { module: "", name } => self.builtin(name, args),
            Value::Function { module: "pyautogui", name } => crate::pyautogui::call(&mut self.rt, name, args),
            Value::Function { module, name } => crate::stdlib::call(&mut self.rt, module, name, args),
            Value::Method(recv, name) => self.call_method(*recv, name, args),
            Value::UserFn(f) => self.call_user(&f, args),
            Value::ExcType(kind) => {
                if !args.kw.is_empty() {
                    return Err(type_error(format!("{}() takes no keyword arguments", kind.python_name())));
                }
                let message = match args.pos.as_slice() {
                    [] => String::new(),
                    [one] if kind == ErrorKind::Key => one.repr(),
                    [one] => one.to_str(),
                    many => Value::tuple(many.to_vec()).repr(),
                };
                Ok(Value::Exception(kind, message))
            }
            Value::Marker(name) => Err(not_supported(format!("calling {name}() is not supported"))),
            other => Err(type_error(format!("'{}' object is not callable", other.type_name()))),
        }
    }
}

/// A value nested deeper than [`MAX_VALUE_DEPTH`].
fn too_deep() -> ScriptError {
    ScriptError::new(ErrorKind::Memory, format!("value nested more than {MAX_VALUE_DEPTH} levels deep"))
}

/// Notes on a container that an item of it now nests `child` levels.
fn raise_depth(v: &mut Value, child: u32) {
    match v {
        Value::List(h) | Value::Tuple(h) => h.raise_depth(child),
        Value::Dict(h) => h.raise_depth(child),
        Value::Set(h) => h.raise_depth(child),
        _ => {}
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

pub(crate) fn check_hashable(key: &Value) -> Result<(), ScriptError> {
    match key {
        Value::List(_) | Value::Dict(_) | Value::Set(_) => {
            Err(type_error(format!("unhashable type: '{}'", key.type_name())))
        }
        Value::Tuple(items) => items.iter().try_for_each(check_hashable),
        _ => Ok(()),
    }
}

/// How a statement ended.
#[derive(Debug)]
enum Flow {
    Normal,
    Break,
    Continue,
    Return(Value),
}

/// One function call's variables; the module level is a frame without locals.
#[derive(Debug, Default)]
struct Frame {
    /// `None` at module level, where names bind in the globals.
    locals: Option<HashMap<String, Value>>,
    /// Comprehension variables, innermost last.
    comp: Vec<HashMap<String, Value>>,
    /// The enclosing function's variables when this function was defined, for closures.
    captured: Option<Rc<HashMap<String, Value>>>,
    /// Names declared `global` in this call.
    global_names: Vec<String>,
}

/// A variable and the keys of the subscripts applied to it: `a[1]['k']`.
#[derive(Debug)]
struct Place {
    root: String,
    keys: Vec<Value>,
}

/// The position `index` names in a sequence of `len` items (negative counts from the end).
pub(crate) fn seq_index(len: usize, index: &Value, what: &str) -> Result<usize, ScriptError> {
    let i = match index {
        Value::Int(_) | Value::Bool(_) => to_i64(index, "index")?,
        other => {
            return Err(type_error(format!("{what} indices must be integers or slices, not {}", other.type_name())))
        }
    };
    let len_i = i64::try_from(len).unwrap_or(i64::MAX);
    let resolved = if i < 0 { i + len_i } else { i };
    if resolved < 0 || resolved >= len_i {
        return Err(ScriptError::new(ErrorKind::Index, format!("{what} index out of range")));
    }
    Ok(usize::try_from(resolved).unwrap_or(0))
}

/// `container[index]` for plain values.
fn index_value(container: &Value, index: &Value) -> Result<Value, ScriptError> {
    match container {
        Value::List(items) => Ok(items[seq_index(items.len(), index, "list")?].clone()),
        Value::Tuple(items) => Ok(items[seq_index(items.len(), index, "tuple")?].clone()),
        Value::Point(a, b) | Value::Size(a, b) => {
            Ok(Value::Int(if seq_index(2, index, "tuple")? == 0 { *a } else { *b }))
        }
        Value::Str(s) if s.is_ascii() => {
            let i = seq_index(s.len(), index, "string")?;
            Ok(Value::str(&s[i..=i]))
        }
        Value::Str(s) => {
            let i = seq_index(s.chars().count(), index, "string")?;
            Ok(Value::str(s.chars().nth(i).map(String::from).unwrap_or_default()))
        }
        Value::Range(start, stop, step) => {
            let len = usize::try_from(crate::value::range_len(*start, *stop, *step)).unwrap_or(usize::MAX);
            let i = i64::try_from(seq_index(len, index, "range object")?).unwrap_or(0);
            Ok(Value::Int(start + i * step))
        }
        Value::Dict(entries) => {
            check_hashable(index)?;
            entries.get(&Key(index.clone())).cloned().ok_or_else(|| ScriptError::new(ErrorKind::Key, index.repr()))
        }
        other => Err(type_error(format!("'{}' object is not subscriptable", other.type_name()))),
    }
}

/// The positions `[lower:upper:step]` selects from a sequence of `len` items, as Python computes them.
fn slice_indices(
    len: usize,
    lower: Option<i64>,
    upper: Option<i64>,
    step: Option<i64>,
) -> Result<Vec<usize>, ScriptError> {
    let step = step.unwrap_or(1);
    if step == 0 {
        return Err(value_error("slice step cannot be zero"));
    }
    let len = i64::try_from(len).unwrap_or(i64::MAX);
    let clamp = |x: i64, low: i64, high: i64| {
        let x = if x < 0 { x.saturating_add(len) } else { x };
        x.clamp(low, high)
    };
    let mut out = Vec::new();
    if step > 0 {
        let start = lower.map_or(0, |x| clamp(x, 0, len));
        let stop = upper.map_or(len, |x| clamp(x, 0, len));
        let mut i = start;
        while i < stop {
            out.push(usize::try_from(i).unwrap_or(0));
            i = i.saturating_add(step);
        }
    } else {
        let start = lower.map_or(len - 1, |x| clamp(x, -1, len - 1));
        let stop = upper.map_or(-1, |x| clamp(x, -1, len - 1));
        let mut i = start;
        while i > stop {
            out.push(usize::try_from(i).unwrap_or(0));
            i = i.saturating_add(step);
        }
    }
    Ok(out)
}

/// `obj[lower:upper:step]`.
fn slice(obj: &Value, lower: Option<i64>, upper: Option<i64>, step: Option<i64>) -> Result<Value, ScriptError> {
    match obj {
        Value::List(items) | Value::Tuple(items) => {
            let indices = slice_indices(items.len(), lower, upper, step)?;
            heap::reserve_items(indices.len())?;
            let picked = indices.into_iter().map(|i| items[i].clone()).collect();
            Ok(if matches!(obj, Value::List(_)) { Value::list(picked) } else { Value::tuple(picked) })
        }
        Value::Str(s) if s.is_ascii() => {
            let indices = slice_indices(s.len(), lower, upper, step)?;
            heap::reserve_text(indices.len())?;
            let bytes = s.as_bytes();
            Ok(Value::str(indices.into_iter().map(|i| char::from(bytes[i])).collect::<String>()))
        }
        Value::Str(s) => {
            let chars: Vec<char> = s.chars().collect();
            let indices = slice_indices(chars.len(), lower, upper, step)?;
            heap::reserve_text(indices.len().saturating_mul(4))?;
            Ok(Value::str(indices.into_iter().map(|i| chars[i]).collect::<String>()))
        }
        Value::Point(a, b) | Value::Size(a, b) => {
            slice(&Value::tuple(vec![Value::Int(*a), Value::Int(*b)]), lower, upper, step)
        }
        other => Err(type_error(format!("'{}' object is not subscriptable", other.type_name()))),
    }
}

/// `container[key] = value` on a value.
fn store_item(container: &mut Value, key: Value, value: Value) -> Result<(), ScriptError> {
    match container {
        Value::List(items) => {
            let i = seq_index(items.len(), &key, "list").map_err(|e| {
                if e.kind == ErrorKind::Index {
                    ScriptError::new(ErrorKind::Index, "list assignment index out of range")
                } else {
                    e
                }
            })?;
            items.items_mut()[i] = value;
            Ok(())
        }
        Value::Dict(entries) => dict_insert(&mut entries.make_mut(), key, value),
        Value::Object(Object::Environ) => Err(not_supported("setting os.environ entries is not supported")),
        other => Err(type_error(format!("'{}' object does not support item assignment", other.type_name()))),
    }
}

/// `del container[key]` on a value.
fn remove_item(container: &mut Value, key: &Value) -> Result<(), ScriptError> {
    match container {
        Value::List(items) => {
            let i = seq_index(items.len(), key, "list").map_err(|e| {
                if e.kind == ErrorKind::Index {
                    ScriptError::new(ErrorKind::Index, "list assignment index out of range")
                } else {
                    e
                }
            })?;
            items.make_mut().remove(i);
            Ok(())
        }
        Value::Dict(entries) => {
            check_hashable(key)?;
            match entries.make_mut().shift_remove(&Key(key.clone())) {
                Some(_) => Ok(()),
                None => Err(ScriptError::new(ErrorKind::Key, key.repr())),
            }
        }
        other => Err(type_error(format!("'{}' object doesn't support item deletion", other.type_name()))),
    }
}

/// Inserts or replaces `key` in a dict's entries.
pub(crate) fn dict_insert(entries: &mut DictMap, key: Value, value: Value) -> Result<(), ScriptError> {
    check_hashable(&key)?;
    self::methods::grow_table(entries.len(), entries.capacity(), 2 * heap::SLOT + 2 * std::mem::size_of::<usize>())?;
    // Python keeps the first key of equal ones (`{1: 'a', 1.0: 'b'}` is `{1: 'b'}`).
    match entries.get_mut(&Key(key.clone())) {
        Some(slot) => *slot = value,
        None => {
            entries.insert(Key(key), value);
        }
    }
    Ok(())
}

/// A set of `items`, first occurrences kept in order.
pub(crate) fn make_set(items: Vec<Value>) -> Result<Value, ScriptError> {
    let mut set = SetMap::with_capacity(items.len());
    for item in items {
        check_hashable(&item)?;
        set.insert(Key(item));
    }
    Ok(Value::set(set))
}

/// `a is b`: the singletons and equal scalars, names and functions are identical;
/// two containers never are, since values here are copies.
fn identical(a: &Value, b: &Value) -> bool {
    match (a, b) {
        (Value::UserFn(x), Value::UserFn(y)) => Rc::ptr_eq(x, y),
        (Value::List(_) | Value::Dict(_) | Value::Set(_), _) => false,
        (Value::Float(_), Value::Float(_)) => false,
        _ => std::mem::discriminant(a) == std::mem::discriminant(b) && a == b,
    }
}

/// Whether an `except` clause's class (or tuple of classes) catches `kind`.
fn exception_matches(types: &Value, kind: ErrorKind) -> Result<bool, ScriptError> {
    match types {
        Value::ExcType(class) => Ok(kind.is_subclass_of(*class)),
        Value::Tuple(items) => {
            for item in items.iter() {
                if exception_matches(item, kind)? {
                    return Ok(true);
                }
            }
            Ok(false)
        }
        _ => Err(type_error("catching classes that do not inherit from BaseException is not allowed")),
    }
}

/// A literal's value.
fn const_value(c: &Const) -> Value {
    match c {
        Const::None => Value::None,
        Const::Bool(b) => Value::Bool(*b),
        Const::Int(i) => Value::Int(*i),
        Const::Float(f) => Value::Float(*f),
        Const::Str(s) => Value::str(s.clone()),
    }
}
