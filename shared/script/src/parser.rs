//! Source to [`Program`]: a real Python parser (`rustpython-parser`) reads the
//! code, and this module lowers its tree into the interpreter's own
//! [`super::ast`], refusing every construct the interpreter does not run with a
//! [`ParseError`] that names it and points at it.
//!
//! Like CPython, which compiles a whole `exec` string before running any of it,
//! a syntax error or an unsupported construct anywhere refuses the whole program.
//!
//! Hostile input cannot exhaust memory or the stack: a program longer than
//! [`MAX_SOURCE_BYTES`] is refused before it is read, and before parsing, the token stream is
//! checked for bracket nesting deeper than [`MAX_DEPTH`], block nesting deeper
//! than [`MAX_BLOCK_DEPTH`] and logical lines longer than [`MAX_LINE_TOKENS`]
//! tokens, and the lowering caps expression nesting at [`MAX_DEPTH`].

use std::sync::Arc;

use rustpython_parser::ast::{self as py, Ranged};
use rustpython_parser::lexer::lex;
use rustpython_parser::{Mode, Tok};

use super::ast::{
    BinOp, CmpOp, CompKind, Const, Expr, ExprKind, FPart, Function, FunctionBody, Generator, Handler, ImportName,
    Param, Program, Stmt, StmtKind, Target, UnaryOp,
};
use super::error::ParseError;

/// How deeply expressions (and brackets) may nest.
pub const MAX_DEPTH: usize = 64;

/// How deeply blocks (`if`, `for`, `def`, ...) may nest.
pub const MAX_BLOCK_DEPTH: usize = 32;

/// The most tokens one logical line may hold.
pub const MAX_LINE_TOKENS: usize = 2000;

/// The longest program parsed, in bytes: 256 KiB. Parsing costs about 200 bytes of
/// memory per source byte (a probe measured 2.15 GB for 10 MB), so this bounds a
/// parse to some 55 MB. Agent code is a few kilobytes, and a `python -c` command
/// line on Windows holds at most 32 767 characters.
pub const MAX_SOURCE_BYTES: usize = 256 << 10;

/// Parses `src` into a [`Program`].
///
/// # Errors
///
/// [`ParseError`] with the line, column and a message naming the unsupported
/// or malformed construct, e.g. "line 1, column 1: class definitions (`class`) are not supported".
pub fn parse(src: &str) -> Result<Program, ParseError> {
    if src.len() > MAX_SOURCE_BYTES {
        return Err(ParseError::new(
            1,
            1,
            format!(
                "the program is {} bytes long; this interpreter reads programs of at most {} KiB",
                src.len(),
                MAX_SOURCE_BYTES >> 10
            ),
        ));
    }
    let lines = LineIndex::new(src);
    let tokens = tokens(src);
    check_token_limits(&tokens, &lines)?;
    let module = rustpython_parser::parse_tokens(tokens, Mode::Module, "<string>").map_err(|err| {
        let (line, column) = lines.position(err.offset.to_usize());
        ParseError::new(line, column, syntax_message(&err.error))
    })?;
    let py::Mod::Module(module) = module else {
        return Err(ParseError::new(1, 1, "expected a module"));
    };
    let mut lower = Lower { lines: &lines, depth: 0, blocks: 0, in_function: false, in_loop: false };
    Ok(Program { statements: lower.block(&module.body)? })
}

/// The tokens of `src`, up to and including the first lexical error (after one,
/// the lexer repeats it forever). Empty statements (`a;;` or a line starting
/// with `;`) are dropped: CPython refuses them, but the WAA task corpus holds
/// `...; time.sleep(0.5);;` and this interpreter has always run it.
fn tokens(src: &str) -> Vec<Result<(Tok, py::text_size::TextRange), rustpython_parser::lexer::LexicalError>> {
    let mut out: Vec<Result<(Tok, py::text_size::TextRange), _>> = Vec::new();
    for item in lex(src, Mode::Module) {
        let failed = item.is_err();
        if let Ok((Tok::Semi, _)) = &item {
            let empty = match out.last() {
                None => true,
                Some(Ok((prev, _))) => matches!(prev, Tok::Semi | Tok::Newline | Tok::Indent | Tok::Dedent),
                Some(Err(_)) => false,
            };
            if empty {
                continue;
            }
        }
        out.push(item);
        if failed {
            break;
        }
    }
    out
}

/// A syntax error's text, closer to CPython's than the parser's own where that is cheap.
fn syntax_message(err: &rustpython_parser::ParseErrorType) -> String {
    use rustpython_parser::ParseErrorType;
    match err {
        ParseErrorType::Eof => "invalid syntax: unexpected end of input".to_owned(),
        ParseErrorType::UnrecognizedToken(tok, expected)
            if *tok != Tok::Indent && expected.as_deref() != Some("Indent") =>
        {
            format!("invalid syntax: unexpected {}", describe_token(tok))
        }
        ParseErrorType::ExtraToken(tok) => format!("invalid syntax: unexpected {}", describe_token(tok)),
        other => other.to_string(),
    }
}

fn describe_token(tok: &Tok) -> String {
    match tok {
        Tok::Name { name } => format!("name '{name}'"),
        Tok::Int { .. } | Tok::Float { .. } | Tok::Complex { .. } => "number".to_owned(),
        Tok::String { .. } => "string literal".to_owned(),
        Tok::Newline => "end of line".to_owned(),
        Tok::EndOfFile => "end of input".to_owned(),
        Tok::Dedent => "dedent".to_owned(),
        other => other.to_string(),
    }
}

/// Byte offsets to 1-based lines and character columns.
struct LineIndex<'s> {
    src: &'s str,
    starts: Vec<usize>,
}

impl<'s> LineIndex<'s> {
    fn new(src: &'s str) -> LineIndex<'s> {
        let mut starts = vec![0];
        let bytes = src.as_bytes();
        for (i, b) in bytes.iter().enumerate() {
            match b {
                b'\n' => starts.push(i + 1),
                b'\r' if bytes.get(i + 1) != Some(&b'\n') => starts.push(i + 1),
                _ => {}
            }
        }
        LineIndex { src, starts }
    }

    fn position(&self, offset: usize) -> (usize, usize) {
        let offset = offset.min(self.src.len());
        let line = self.starts.partition_point(|s| *s <= offset).max(1);
        let start = self.starts[line - 1];
        let column = self.src.get(start..offset).map_or(offset - start, |s| s.chars().count()) + 1;
        (line, column)
    }
}

/// Refuses token streams whose nesting would make the parser's tree too deep to handle.
fn check_token_limits(
    tokens: &[Result<(Tok, py::text_size::TextRange), rustpython_parser::lexer::LexicalError>],
    lines: &LineIndex<'_>,
) -> Result<(), ParseError> {
    let (mut brackets, mut blocks, mut line_tokens) = (0_usize, 0_usize, 0_usize);
    for (tok, range) in tokens.iter().flatten() {
        let at = || lines.position(range.start().to_usize());
        line_tokens += 1;
        match tok {
            Tok::Lpar | Tok::Lsqb | Tok::Lbrace => brackets += 1,
            Tok::Rpar | Tok::Rsqb | Tok::Rbrace => brackets = brackets.saturating_sub(1),
            Tok::Indent => blocks += 1,
            Tok::Dedent => blocks = blocks.saturating_sub(1),
            Tok::Newline => line_tokens = 0,
            _ => {}
        }
        if brackets > MAX_DEPTH {
            let (line, column) = at();
            return Err(ParseError::new(
                line,
                column,
                format!("expression nested too deeply (more than {MAX_DEPTH} levels)"),
            ));
        }
        if blocks > MAX_BLOCK_DEPTH {
            let (line, column) = at();
            return Err(ParseError::new(
                line,
                column,
                format!("blocks nested too deeply (more than {MAX_BLOCK_DEPTH} levels)"),
            ));
        }
        if line_tokens > MAX_LINE_TOKENS {
            let (line, column) = at();
            return Err(ParseError::new(line, column, format!("line too long (more than {MAX_LINE_TOKENS} tokens)")));
        }
    }
    Ok(())
}

struct Lower<'a, 's> {
    lines: &'a LineIndex<'s>,
    depth: usize,
    blocks: usize,
    in_function: bool,
    in_loop: bool,
}

type Lowered<T> = Result<T, ParseError>;

impl Lower<'_, '_> {
    fn pos(&self, node: &impl Ranged) -> (usize, usize) {
        self.lines.position(node.start().to_usize())
    }

    fn refuse<T>(&self, node: &impl Ranged, message: impl Into<String>) -> Lowered<T> {
        let (line, column) = self.pos(node);
        Err(ParseError::new(line, column, message))
    }

    fn block(&mut self, stmts: &[py::Stmt]) -> Lowered<Vec<Stmt>> {
        self.blocks += 1;
        if self.blocks > MAX_BLOCK_DEPTH {
            if let Some(first) = stmts.first() {
                return self.refuse(first, format!("blocks nested too deeply (more than {MAX_BLOCK_DEPTH} levels)"));
            }
        }
        let result = stmts.iter().map(|s| self.stmt(s)).collect();
        self.blocks -= 1;
        result
    }

    fn loop_body(&mut self, stmts: &[py::Stmt]) -> Lowered<Vec<Stmt>> {
        let outer = std::mem::replace(&mut self.in_loop, true);
        let result = self.block(stmts);
        self.in_loop = outer;
        result
    }

    fn stmt(&mut self, stmt: &py::Stmt) -> Lowered<Stmt> {
        let (line, column) = self.pos(stmt);
        let kind = match stmt {
            py::Stmt::Import(s) => StmtKind::Import(
                s.names
                    .iter()
                    .map(|a| ImportName {
                        module: a.name.to_string(),
                        alias: a.asname.as_ref().map(ToString::to_string),
                    })
                    .collect(),
            ),
            py::Stmt::ImportFrom(s) => {
                if s.level.is_some_and(|l| l.to_u32() > 0) {
                    return self.refuse(stmt, "relative imports are not supported");
                }
                let Some(module) = &s.module else {
                    return self.refuse(stmt, "relative imports are not supported");
                };
                let mut names = Vec::new();
                for a in &s.names {
                    if a.name.as_str() == "*" {
                        return self.refuse(stmt, "`from ... import *` is not supported");
                    }
                    names.push((a.name.to_string(), a.asname.as_ref().map(ToString::to_string)));
                }
                StmtKind::FromImport { module: module.to_string(), names }
            }
            py::Stmt::Assign(s) => StmtKind::Assign {
                targets: s.targets.iter().map(|t| self.target(t)).collect::<Lowered<_>>()?,
                value: self.expr(&s.value)?,
            },
            py::Stmt::AnnAssign(s) => match &s.value {
                Some(value) => StmtKind::Assign { targets: vec![self.target(&s.target)?], value: self.expr(value)? },
                None => StmtKind::Pass,
            },
            py::Stmt::AugAssign(s) => {
                let target = self.target(&s.target)?;
                if matches!(target, Target::Unpack(_)) {
                    return self.refuse(stmt, "illegal expression for augmented assignment");
                }
                StmtKind::AugAssign { target, op: self.operator(&s.op, stmt)?, value: self.expr(&s.value)? }
            }
            py::Stmt::Expr(s) => StmtKind::Expr(self.expr(&s.value)?),
            py::Stmt::Pass(_) => StmtKind::Pass,
            py::Stmt::Break(_) | py::Stmt::Continue(_) => {
                let word = if matches!(stmt, py::Stmt::Break(_)) { "break" } else { "continue" };
                if !self.in_loop {
                    return self.refuse(stmt, format!("'{word}' outside loop"));
                }
                if word == "break" {
                    StmtKind::Break
                } else {
                    StmtKind::Continue
                }
            }
            py::Stmt::If(s) => {
                StmtKind::If { test: self.expr(&s.test)?, body: self.block(&s.body)?, orelse: self.block(&s.orelse)? }
            }
            py::Stmt::For(s) => StmtKind::For {
                target: self.target(&s.target)?,
                iter: self.expr(&s.iter)?,
                body: self.loop_body(&s.body)?,
                orelse: self.block(&s.orelse)?,
            },
            py::Stmt::While(s) => StmtKind::While {
                test: self.expr(&s.test)?,
                body: self.loop_body(&s.body)?,
                orelse: self.block(&s.orelse)?,
            },
            py::Stmt::Try(s) => {
                let mut handlers = Vec::new();
                for h in &s.handlers {
                    let py::ExceptHandler::ExceptHandler(h) = h;
                    let (line, _) = self.pos(h);
                    handlers.push(Handler {
                        line,
                        types: h.type_.as_deref().map(|t| self.expr(t)).transpose()?,
                        name: h.name.as_ref().map(ToString::to_string),
                        body: self.block(&h.body)?,
                    });
                }
                StmtKind::Try {
                    body: self.block(&s.body)?,
                    handlers,
                    orelse: self.block(&s.orelse)?,
                    finalbody: self.block(&s.finalbody)?,
                }
            }
            py::Stmt::Raise(s) => {
                if s.cause.is_some() {
                    return self.refuse(stmt, "`raise ... from ...` is not supported");
                }
                StmtKind::Raise(s.exc.as_deref().map(|e| self.expr(e)).transpose()?)
            }
            py::Stmt::FunctionDef(s) => {
                if !s.decorator_list.is_empty() {
                    return self.refuse(stmt, "decorators are not supported");
                }
                let params = self.params(&s.args, stmt)?;
                let outer =
                    (std::mem::replace(&mut self.in_function, true), std::mem::replace(&mut self.in_loop, false));
                let body = self.block(&s.body);
                (self.in_function, self.in_loop) = outer;
                StmtKind::Def(Arc::new(Function { name: s.name.to_string(), params, body: FunctionBody::Block(body?) }))
            }
            py::Stmt::Return(s) => {
                if !self.in_function {
                    return self.refuse(stmt, "'return' outside function");
                }
                StmtKind::Return(s.value.as_deref().map(|e| self.expr(e)).transpose()?)
            }
            py::Stmt::Global(s) => StmtKind::Global(s.names.iter().map(ToString::to_string).collect()),
            py::Stmt::Assert(s) => {
                StmtKind::Assert { test: self.expr(&s.test)?, msg: s.msg.as_deref().map(|e| self.expr(e)).transpose()? }
            }
            py::Stmt::Delete(s) => StmtKind::Delete(s.targets.iter().map(|t| self.target(t)).collect::<Lowered<_>>()?),
            py::Stmt::ClassDef(_) => return self.refuse(stmt, "class definitions (`class`) are not supported"),
            py::Stmt::With(_) => return self.refuse(stmt, "`with` statements are not supported"),
            py::Stmt::AsyncFunctionDef(_) | py::Stmt::AsyncFor(_) | py::Stmt::AsyncWith(_) => {
                return self.refuse(stmt, "`async` code is not supported")
            }
            py::Stmt::Nonlocal(_) => return self.refuse(stmt, "`nonlocal` statements are not supported"),
            py::Stmt::Match(_) => return self.refuse(stmt, "`match` statements are not supported"),
            py::Stmt::TryStar(_) => return self.refuse(stmt, "`except*` is not supported"),
            py::Stmt::TypeAlias(_) => return self.refuse(stmt, "`type` aliases are not supported"),
        };
        Ok(Stmt { line, column, kind })
    }

    fn params(&mut self, args: &py::Arguments, at: &impl Ranged) -> Lowered<Vec<Param>> {
        if args.vararg.is_some() || args.kwarg.is_some() {
            return self.refuse(at, "`*args` and `**kwargs` parameters are not supported");
        }
        if !args.kwonlyargs.is_empty() || !args.posonlyargs.is_empty() {
            return self.refuse(at, "keyword-only and positional-only parameters are not supported");
        }
        args.args
            .iter()
            .map(|a| {
                Ok(Param {
                    name: a.def.arg.to_string(),
                    default: a.default.as_deref().map(|d| self.expr(d)).transpose()?,
                })
            })
            .collect()
    }

    fn target(&mut self, expr: &py::Expr) -> Lowered<Target> {
        match expr {
            py::Expr::Name(n) => Ok(Target::Name(n.id.to_string())),
            py::Expr::Attribute(a) => Ok(Target::Attr(self.expr(&a.value)?, a.attr.to_string())),
            py::Expr::Subscript(s) => Ok(Target::Subscript(self.expr(&s.value)?, self.expr(&s.slice)?)),
            py::Expr::Tuple(py::ExprTuple { elts, .. }) | py::Expr::List(py::ExprList { elts, .. }) => {
                self.enter(expr)?;
                let targets = elts.iter().map(|e| self.target(e)).collect::<Lowered<_>>();
                self.depth -= 1;
                Ok(Target::Unpack(targets?))
            }
            py::Expr::Starred(_) => self.refuse(expr, "starred assignment targets (`a, *b = ...`) are not supported"),
            _ => self.refuse(expr, "cannot assign to this expression"),
        }
    }

    fn enter(&mut self, at: &impl Ranged) -> Lowered<()> {
        self.depth += 1;
        if self.depth > MAX_DEPTH {
            return self.refuse(at, format!("expression nested too deeply (more than {MAX_DEPTH} levels)"));
        }
        Ok(())
    }

    fn expr(&mut self, expr: &py::Expr) -> Lowered<Expr> {
        self.enter(expr)?;
        let result = self.expr_inner(expr);
        self.depth -= 1;
        let (line, column) = self.pos(expr);
        Ok(Expr { line, column, kind: result? })
    }

    fn boxed(&mut self, expr: &py::Expr) -> Lowered<Box<Expr>> {
        self.expr(expr).map(Box::new)
    }

    fn exprs(&mut self, exprs: &[py::Expr]) -> Lowered<Vec<Expr>> {
        exprs.iter().map(|e| self.expr(e)).collect()
    }

    fn expr_inner(&mut self, expr: &py::Expr) -> Lowered<ExprKind> {
        Ok(match expr {
            py::Expr::Constant(c) => ExprKind::Const(self.constant(&c.value, expr)?),
            py::Expr::Name(n) => ExprKind::Name(n.id.to_string()),
            py::Expr::Attribute(a) => ExprKind::Attr(self.boxed(&a.value)?, a.attr.to_string()),
            py::Expr::Call(c) => {
                let mut args = Vec::new();
                for a in &c.args {
                    if matches!(a, py::Expr::Starred(_)) {
                        return self.refuse(a, "unpacking (`*`) in calls is not supported");
                    }
                    args.push(self.expr(a)?);
                }
                let mut kwargs = Vec::new();
                for k in &c.keywords {
                    let Some(name) = &k.arg else {
                        return self.refuse(k, "unpacking (`**`) in calls is not supported");
                    };
                    kwargs.push((name.to_string(), self.expr(&k.value)?));
                }
                ExprKind::Call { func: self.boxed(&c.func)?, args, kwargs }
            }
            py::Expr::Subscript(s) => ExprKind::Subscript(self.boxed(&s.value)?, self.boxed(&s.slice)?),
            py::Expr::Slice(s) => ExprKind::Slice {
                lower: s.lower.as_deref().map(|e| self.boxed(e)).transpose()?,
                upper: s.upper.as_deref().map(|e| self.boxed(e)).transpose()?,
                step: s.step.as_deref().map(|e| self.boxed(e)).transpose()?,
            },
            py::Expr::List(l) => ExprKind::List(self.items(&l.elts)?),
            py::Expr::Tuple(t) => ExprKind::Tuple(self.items(&t.elts)?),
            py::Expr::Set(s) => ExprKind::Set(self.items(&s.elts)?),
            py::Expr::Dict(d) => {
                let mut items = Vec::new();
                for (k, v) in d.keys.iter().zip(&d.values) {
                    let Some(k) = k else {
                        return self.refuse(v, "dict unpacking (`**`) is not supported");
                    };
                    items.push((self.expr(k)?, self.expr(v)?));
                }
                ExprKind::Dict(items)
            }
            py::Expr::UnaryOp(u) => {
                let op = match u.op {
                    py::UnaryOp::UAdd => UnaryOp::Plus,
                    py::UnaryOp::USub => UnaryOp::Minus,
                    py::UnaryOp::Not => UnaryOp::Not,
                    py::UnaryOp::Invert => UnaryOp::Invert,
                };
                // `-5` is a literal in Python's eyes; fold it so `-9223372036854775808` works.
                if let (UnaryOp::Minus, py::Expr::Constant(c)) = (op, &*u.operand) {
                    if let py::Constant::Int(i) = &c.value {
                        if let Ok(v) = format!("-{i}").parse::<i64>() {
                            return Ok(ExprKind::Const(Const::Int(v)));
                        }
                    }
                }
                ExprKind::Unary(op, self.boxed(&u.operand)?)
            }
            py::Expr::BinOp(b) => {
                ExprKind::Binary(self.operator(&b.op, expr)?, self.boxed(&b.left)?, self.boxed(&b.right)?)
            }
            py::Expr::BoolOp(b) => {
                ExprKind::BoolOp { and_: matches!(b.op, py::BoolOp::And), values: self.exprs(&b.values)? }
            }
            py::Expr::Compare(c) => {
                let mut ops = Vec::new();
                for (op, right) in c.ops.iter().zip(&c.comparators) {
                    let op = match op {
                        py::CmpOp::Eq => CmpOp::Eq,
                        py::CmpOp::NotEq => CmpOp::NotEq,
                        py::CmpOp::Lt => CmpOp::Lt,
                        py::CmpOp::LtE => CmpOp::LtE,
                        py::CmpOp::Gt => CmpOp::Gt,
                        py::CmpOp::GtE => CmpOp::GtE,
                        py::CmpOp::In => CmpOp::In,
                        py::CmpOp::NotIn => CmpOp::NotIn,
                        py::CmpOp::Is => CmpOp::Is,
                        py::CmpOp::IsNot => CmpOp::IsNot,
                    };
                    ops.push((op, self.expr(right)?));
                }
                ExprKind::Compare { left: self.boxed(&c.left)?, ops }
            }
            py::Expr::IfExp(i) => ExprKind::IfExp {
                test: self.boxed(&i.test)?,
                body: self.boxed(&i.body)?,
                orelse: self.boxed(&i.orelse)?,
            },
            py::Expr::JoinedStr(j) => ExprKind::FString(self.fstring(&j.values)?),
            py::Expr::FormattedValue(_) => ExprKind::FString(self.fstring(std::slice::from_ref(expr))?),
            py::Expr::ListComp(c) => self.comp(CompKind::List, &c.elt, None, &c.generators)?,
            py::Expr::SetComp(c) => self.comp(CompKind::Set, &c.elt, None, &c.generators)?,
            py::Expr::GeneratorExp(c) => self.comp(CompKind::Generator, &c.elt, None, &c.generators)?,
            py::Expr::DictComp(c) => self.comp(CompKind::Dict, &c.key, Some(&c.value), &c.generators)?,
            py::Expr::Lambda(l) => {
                let params = self.params(&l.args, expr)?;
                let body = self.expr(&l.body)?;
                ExprKind::Lambda(Arc::new(Function {
                    name: "<lambda>".to_owned(),
                    params,
                    body: FunctionBody::Expr(body),
                }))
            }
            py::Expr::Starred(_) => return self.refuse(expr, "unpacking (`*`) is not supported"),
            py::Expr::NamedExpr(_) => return self.refuse(expr, "assignment expressions (`:=`) are not supported"),
            py::Expr::Await(_) => return self.refuse(expr, "`await` is not supported"),
            py::Expr::Yield(_) | py::Expr::YieldFrom(_) => {
                return self.refuse(expr, "generators (`yield`) are not supported")
            }
        })
    }

    fn items(&mut self, elts: &[py::Expr]) -> Lowered<Vec<Expr>> {
        for e in elts {
            if matches!(e, py::Expr::Starred(_)) {
                return self.refuse(e, "unpacking (`*`) in displays is not supported");
            }
        }
        self.exprs(elts)
    }

    fn comp(
        &mut self,
        kind: CompKind,
        elt: &py::Expr,
        value: Option<&py::Expr>,
        generators: &[py::Comprehension],
    ) -> Lowered<ExprKind> {
        let mut lowered = Vec::new();
        for g in generators {
            if g.is_async {
                return self.refuse(&g.iter, "`async` comprehensions are not supported");
            }
            lowered.push(Generator {
                target: self.target(&g.target)?,
                iter: self.expr(&g.iter)?,
                ifs: self.exprs(&g.ifs)?,
            });
        }
        Ok(ExprKind::Comp {
            kind,
            elt: self.boxed(elt)?,
            value: value.map(|v| self.boxed(v)).transpose()?,
            generators: lowered,
        })
    }

    fn fstring(&mut self, values: &[py::Expr]) -> Lowered<Vec<FPart>> {
        let mut parts = Vec::new();
        for v in values {
            match v {
                py::Expr::Constant(py::ExprConstant { value: py::Constant::Str(s), .. }) => {
                    parts.push(FPart::Lit(s.clone()));
                }
                py::Expr::FormattedValue(f) => {
                    let conversion = match f.conversion {
                        py::ConversionFlag::None => None,
                        py::ConversionFlag::Str => Some('s'),
                        py::ConversionFlag::Repr => Some('r'),
                        py::ConversionFlag::Ascii => Some('a'),
                    };
                    let spec = match f.format_spec.as_deref() {
                        None => Vec::new(),
                        Some(py::Expr::JoinedStr(j)) => {
                            self.enter(v)?;
                            let spec = self.fstring(&j.values);
                            self.depth -= 1;
                            spec?
                        }
                        Some(other) => self.fstring(std::slice::from_ref(other))?,
                    };
                    parts.push(FPart::Field { expr: self.boxed(&f.value)?, conversion, spec });
                }
                py::Expr::JoinedStr(j) => parts.extend(self.fstring(&j.values)?),
                other => return self.refuse(other, "unexpected f-string part"),
            }
        }
        Ok(parts)
    }

    fn constant(&self, c: &py::Constant, at: &py::Expr) -> Lowered<Const> {
        Ok(match c {
            py::Constant::None => Const::None,
            py::Constant::Bool(b) => Const::Bool(*b),
            py::Constant::Str(s) => Const::Str(s.clone()),
            py::Constant::Int(i) => match i.to_string().parse::<i64>() {
                Ok(v) => Const::Int(v),
                Err(_) => return self.refuse(at, "integer literal too large (this interpreter's integers are 64-bit)"),
            },
            py::Constant::Float(f) => Const::Float(*f),
            py::Constant::Bytes(_) => return self.refuse(at, "bytes literals (b'...') are not supported"),
            py::Constant::Complex { .. } => return self.refuse(at, "complex number literals are not supported"),
            py::Constant::Ellipsis => return self.refuse(at, "`...` (Ellipsis) is not supported"),
            py::Constant::Tuple(_) => return self.refuse(at, "constant tuples are not supported"),
        })
    }

    fn operator(&self, op: &py::Operator, at: &impl Ranged) -> Lowered<BinOp> {
        Ok(match op {
            py::Operator::Add => BinOp::Add,
            py::Operator::Sub => BinOp::Sub,
            py::Operator::Mult => BinOp::Mul,
            py::Operator::Div => BinOp::Div,
            py::Operator::FloorDiv => BinOp::FloorDiv,
            py::Operator::Mod => BinOp::Mod,
            py::Operator::Pow => BinOp::Pow,
            py::Operator::BitAnd => BinOp::BitAnd,
            py::Operator::BitOr => BinOp::BitOr,
            py::Operator::BitXor => BinOp::BitXor,
            py::Operator::LShift => BinOp::LShift,
            py::Operator::RShift => BinOp::RShift,
            py::Operator::MatMult => return self.refuse(at, "the matrix operator (`@`) is not supported"),
        })
    }
}
