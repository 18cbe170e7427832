//! The syntax tree of the supported Python subset.
//!
//! It holds only what the parser accepts: imports, assignments to a name or an
//! attribute, `pass`, and expression statements built from literals, names,
//! attribute access, calls, subscripts, containers and arithmetic.
//! Every node carries its 1-based source position for error messages.

/// A parsed program: statements in source order.
#[derive(Debug, Clone, PartialEq)]
pub struct Program {
    pub statements: Vec<Stmt>,
}

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
    FromImport { module: String, names: Vec<(String, Option<String>)> },
    /// `a = b = value`: every target gets the same value.
    Assign { targets: Vec<Target>, value: Expr },
    /// An expression evaluated for its effect, like a call.
    Expr(Expr),
    /// `pass`.
    Pass,
}

/// One module of an `import` statement.
#[derive(Debug, Clone, PartialEq)]
pub struct ImportName {
    /// The dotted module name, `os.path`.
    pub module: String,
    /// The `as` name, if any.
    pub alias: Option<String>,
}

/// Something an assignment can bind.
#[derive(Debug, Clone, PartialEq)]
pub enum Target {
    /// `x = ...`.
    Name(String),
    /// `obj.attr = ...`, such as `pyautogui.FAILSAFE = False`.
    Attr(Expr, String),
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
    Call { func: Box<Expr>, args: Vec<Expr>, kwargs: Vec<(String, Expr)> },
    Subscript(Box<Expr>, Box<Expr>),
    List(Vec<Expr>),
    Tuple(Vec<Expr>),
    Dict(Vec<(Expr, Expr)>),
    Unary(UnaryOp, Box<Expr>),
    Binary(BinOp, Box<Expr>, Box<Expr>),
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
        }
    }
}
