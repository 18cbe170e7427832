//! The syntax tree of the supported Python subset.
//!
//! [`super::parser`] lowers the tree of a real Python parser into this one and
//! refuses, before anything runs, every construct it does not hold: classes,
//! `with`, `async`, generators, star-arguments, walrus, `match`, decorators.
//! It holds imports; assignments (plain, chained, unpacking, augmented, to a
//! name, an attribute or an item); `if`/`for`/`while` with `break`/`continue`;
//! `try`/`except`/`else`/`finally` and `raise`; `def` and `lambda` with
//! positional, default and keyword parameters; `global`, `assert`, `del`,
//! `pass`; and expressions built from literals, names, attribute access, calls,
//! subscripts and slices, containers, comprehensions, f-strings, arithmetic,
//! comparisons, boolean operators and conditional expressions.
//! Every node carries its 1-based source position for error messages.

use std::sync::Arc;

/// A parsed program: statements in source order. It is `Send` and `Sync`, so a
/// caller may parse on one thread and run on another.
#[derive(Debug, Clone, PartialEq)]
pub struct Program {
    pub statements: Vec<Stmt>,
}

const _: () = {
    const fn send_and_sync<T: Send + Sync>() {}
    send_and_sync::<Program>();
};

/// One statement and where it starts.
#[derive(Debug, Clone, PartialEq)]
pub struct Stmt {
    pub line: usize,
    pub column: usize,
    pub kind: StmtKind,
}

/// The statement forms.
#[derive(Debug, Clone, PartialEq)]
pub enum StmtKind {
    /// `import a.b as c, d`.
    Import(Vec<ImportName>),
    /// `from a.b import c as d, e`.
    FromImport {
        module: String,
        names: Vec<(String, Option<String>)>,
    },
    /// `a = b = value`: every target gets the same value.
    Assign {
        targets: Vec<Target>,
        value: Expr,
    },
    /// `target op= value`.
    AugAssign {
        target: Target,
        op: BinOp,
        value: Expr,
    },
    /// An expression evaluated for its effect, like a call.
    Expr(Expr),
    /// `pass`.
    Pass,
    Break,
    Continue,
    /// `if test: body else: orelse` (`elif` is a nested `If` in `orelse`).
    If {
        test: Expr,
        body: Vec<Stmt>,
        orelse: Vec<Stmt>,
    },
    /// `for target in iter: body else: orelse`.
    For {
        target: Target,
        iter: Expr,
        body: Vec<Stmt>,
        orelse: Vec<Stmt>,
    },
    /// `while test: body else: orelse`.
    While {
        test: Expr,
        body: Vec<Stmt>,
        orelse: Vec<Stmt>,
    },
    /// `try: body except ...: ... else: orelse finally: finalbody`.
    Try {
        body: Vec<Stmt>,
        handlers: Vec<Handler>,
        orelse: Vec<Stmt>,
        finalbody: Vec<Stmt>,
    },
    /// `raise` (re-raise) or `raise exc`.
    Raise(Option<Expr>),
    /// `def name(params): body`.
    Def(Arc<Function>),
    /// `return` or `return value`.
    Return(Option<Expr>),
    /// `global a, b`.
    Global(Vec<String>),
    /// `assert test, msg`.
    Assert {
        test: Expr,
        msg: Option<Expr>,
    },
    /// `del a, b[k]`.
    Delete(Vec<Target>),
}

/// One module of an `import` statement.
#[derive(Debug, Clone, PartialEq)]
pub struct ImportName {
    /// The dotted module name, `os.path`.
    pub module: String,
    /// The `as` name, if any.
    pub alias: Option<String>,
}

/// One `except` clause.
#[derive(Debug, Clone, PartialEq)]
pub struct Handler {
    pub line: usize,
    /// The exception class or tuple of classes; `None` for a bare `except:`.
    pub types: Option<Expr>,
    /// The `as` name.
    pub name: Option<String>,
    pub body: Vec<Stmt>,
}

/// A `def` or a `lambda`.
#[derive(Debug, Clone, PartialEq)]
pub struct Function {
    /// The name (`<lambda>` for a lambda).
    pub name: String,
    pub params: Vec<Param>,
    pub body: FunctionBody,
}

/// What a function runs.
#[derive(Debug, Clone, PartialEq)]
pub enum FunctionBody {
    /// A `def` body.
    Block(Vec<Stmt>),
    /// A `lambda`'s expression, whose value is returned.
    Expr(Expr),
}

/// One parameter and its default value expression, evaluated when the `def` runs.
#[derive(Debug, Clone, PartialEq)]
pub struct Param {
    pub name: String,
    pub default: Option<Expr>,
}

/// Something an assignment, a `for` loop or `del` can bind.
#[derive(Debug, Clone, PartialEq)]
pub enum Target {
    /// `x = ...`.
    Name(String),
    /// `obj.attr = ...`, such as `pyautogui.FAILSAFE = False`.
    Attr(Expr, String),
    /// `obj[index] = ...`.
    Subscript(Expr, Expr),
    /// `a, (b, c) = ...` or `[a, b] = ...`.
    Unpack(Vec<Target>),
}

/// An expression and where it starts.
#[derive(Debug, Clone, PartialEq)]
pub struct Expr {
    pub line: usize,
    pub column: usize,
    pub kind: ExprKind,
}

/// The expression forms.
#[derive(Debug, Clone, PartialEq)]
pub enum ExprKind {
    Const(Const),
    Name(String),
    Attr(Box<Expr>, String),
    Call {
        func: Box<Expr>,
        args: Vec<Expr>,
        kwargs: Vec<(String, Expr)>,
    },
    /// `obj[index]`; a slice index is an [`ExprKind::Slice`].
    Subscript(Box<Expr>, Box<Expr>),
    /// `lower:upper:step` inside a subscript.
    Slice {
        lower: Option<Box<Expr>>,
        upper: Option<Box<Expr>>,
        step: Option<Box<Expr>>,
    },
    List(Vec<Expr>),
    Tuple(Vec<Expr>),
    Dict(Vec<(Expr, Expr)>),
    Set(Vec<Expr>),
    Unary(UnaryOp, Box<Expr>),
    Binary(BinOp, Box<Expr>, Box<Expr>),
    /// `a and b and c` (`and_` true) or `a or b`.
    BoolOp {
        and_: bool,
        values: Vec<Expr>,
    },
    /// `a < b <= c`: the left operand and each operator with its right operand.
    Compare {
        left: Box<Expr>,
        ops: Vec<(CmpOp, Expr)>,
    },
    /// `body if test else orelse`.
    IfExp {
        test: Box<Expr>,
        body: Box<Expr>,
        orelse: Box<Expr>,
    },
    /// An f-string's parts.
    FString(Vec<FPart>),
    /// A list, set or dict comprehension or a generator expression (evaluated eagerly).
    Comp {
        kind: CompKind,
        elt: Box<Expr>,
        value: Option<Box<Expr>>,
        generators: Vec<Generator>,
    },
    Lambda(Arc<Function>),
}

/// One part of an f-string.
#[derive(Debug, Clone, PartialEq)]
pub enum FPart {
    Lit(String),
    /// `{expr!conversion:spec}`; the spec may itself hold replacement fields.
    Field {
        expr: Box<Expr>,
        conversion: Option<char>,
        spec: Vec<FPart>,
    },
}

/// What a comprehension builds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CompKind {
    List,
    Set,
    Dict,
    /// A generator expression, which this interpreter evaluates to a list at once.
    Generator,
}

/// One `for target in iter if cond ...` clause of a comprehension.
#[derive(Debug, Clone, PartialEq)]
pub struct Generator {
    pub target: Target,
    pub iter: Expr,
    pub ifs: Vec<Expr>,
}

/// A literal.
#[derive(Debug, Clone, PartialEq)]
pub enum Const {
    None,
    Bool(bool),
    Int(i64),
    Float(f64),
    Str(String),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum UnaryOp {
    Plus,
    Minus,
    Not,
    Invert,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BinOp {
    Add,
    Sub,
    Mul,
    Div,
    FloorDiv,
    Mod,
    Pow,
    BitAnd,
    BitOr,
    BitXor,
    LShift,
    RShift,
}

impl BinOp {
    /// The operator as written in Python, for error messages.
    pub fn symbol(self) -> &'static str {
        match self {
            BinOp::Add => "+",
            BinOp::Sub => "-",
            BinOp::Mul => "*",
            BinOp::Div => "/",
            BinOp::FloorDiv => "//",
            BinOp::Mod => "%",
            BinOp::Pow => "** or pow()",
            BinOp::BitAnd => "&",
            BinOp::BitOr => "|",
            BinOp::BitXor => "^",
            BinOp::LShift => "<<",
            BinOp::RShift => ">>",
        }
    }
}

/// Comparison operators.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CmpOp {
    Eq,
    NotEq,
    Lt,
    LtE,
    Gt,
    GtE,
    In,
    NotIn,
    Is,
    IsNot,
}

impl CmpOp {
    /// The operator as written in Python, for error messages.
    pub fn symbol(self) -> &'static str {
        match self {
            CmpOp::Eq => "==",
            CmpOp::NotEq => "!=",
            CmpOp::Lt => "<",
            CmpOp::LtE => "<=",
            CmpOp::Gt => ">",
            CmpOp::GtE => ">=",
            CmpOp::In => "in",
            CmpOp::NotIn => "not in",
            CmpOp::Is => "is",
            CmpOp::IsNot => "is not",
        }
    }
}
