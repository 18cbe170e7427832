//! A recursive-descent parser for the supported Python subset.
//!
//! It accepts imports, assignments, `pass` and expression statements separated
//! by newlines or `;` (empty statements allowed), and rejects every other
//! construct with a [`ParseError`] that names it and points at it.
//! Nesting is capped at [`MAX_DEPTH`] levels, so hostile input cannot exhaust
//! the stack, and every loop consumes a token, so parsing always ends.

use super::ast::{BinOp, Const, Expr, ExprKind, ImportName, Program, Stmt, StmtKind, Target, UnaryOp};
use super::error::ParseError;
use super::lexer::{tokenize, Tok, Token};

/// How deeply expressions may nest (brackets, unary operators, operator and call chains).
pub const MAX_DEPTH: usize = 64;

/// Parses `src` into a [`Program`].
///
/// # Errors
///
/// [`ParseError`] with the line, column and a message naming the unsupported
/// or malformed construct, e.g. "line 1, column 1: `for` loops are not supported".
pub fn parse(src: &str) -> Result<Program, ParseError> {
    let mut parser = Parser { tokens: tokenize(src), pos: 0, depth: 0 };
    parser.program()
}

/// Positional and keyword arguments of a call.
type CallArgs = (Vec<Expr>, Vec<(String, Expr)>);

struct Parser {
    tokens: Vec<Token>,
    pos: usize,
    depth: usize,
}

/// Python keywords; a name in this list never starts or continues an expression
/// except `True`, `False` and `None`.
const KEYWORDS: &[&str] = &[
    "False", "None", "True", "and", "as", "assert", "async", "await", "break", "class", "continue", "def", "del",
    "elif", "else", "except", "finally", "for", "from", "global", "if", "import", "in", "is", "lambda", "nonlocal",
    "not", "or", "pass", "raise", "return", "try", "while", "with", "yield",
];

/// The message for a keyword that starts an unsupported construct.
fn keyword_message(kw: &str) -> String {
    match kw {
        "def" => "function definitions (`def`) are not supported".into(),
        "class" => "class definitions (`class`) are not supported".into(),
        "for" => "`for` loops are not supported".into(),
        "while" => "`while` loops are not supported".into(),
        "if" | "elif" | "else" => "`if` statements are not supported".into(),
        "with" => "`with` statements are not supported".into(),
        "try" | "except" | "finally" => "`try` statements are not supported".into(),
        "lambda" => "`lambda` expressions are not supported".into(),
        "and" | "or" | "not" => format!("boolean operators (`{kw}`) are not supported"),
        "in" | "is" => format!("comparison operators (`{kw}`) are not supported"),
        "as" => "invalid syntax: unexpected `as`".into(),
        "import" | "from" => format!("invalid syntax: `{kw}` must start a statement"),
        other => format!("`{other}` statements are not supported"),
    }
}

impl Parser {
    fn peek(&self) -> &Token {
        // The token list always ends with Eof or Error, and `pos` never moves past it.
        &self.tokens[self.pos.min(self.tokens.len() - 1)]
    }

    fn peek_at(&self, ahead: usize) -> &Tok {
        &self.tokens[(self.pos + ahead).min(self.tokens.len() - 1)].tok
    }

    fn advance(&mut self) -> Token {
        let tok = self.peek().clone();
        if !matches!(tok.tok, Tok::Eof | Tok::Error(_)) {
            self.pos += 1;
        }
        tok
    }

    fn is_op(&self, op: &str) -> bool {
        matches!(&self.peek().tok, Tok::Op(o) if *o == op)
    }

    fn is_name(&self, name: &str) -> bool {
        matches!(&self.peek().tok, Tok::Name(n) if n == name)
    }

    fn eat_op(&mut self, op: &str) -> bool {
        let found = self.is_op(op);
        if found {
            self.advance();
        }
        found
    }

    fn expect_op(&mut self, op: &str) -> Result<(), ParseError> {
        if self.eat_op(op) {
            Ok(())
        } else {
            Err(self.unexpected(&format!("expected `{op}`")))
        }
    }

    /// An error at the next token; a lexer error there takes precedence.
    fn unexpected(&self, context: &str) -> ParseError {
        let token = self.peek();
        let found = match &token.tok {
            Tok::Error(err) => return err.clone(),
            Tok::Name(n) if KEYWORDS.contains(&n.as_str()) && !matches!(n.as_str(), "True" | "False" | "None") => {
                return self.error_at(token, keyword_message(n));
            }
            Tok::Name(n) => format!("name `{n}`"),
            Tok::Int(_) | Tok::Float(_) => "number".to_owned(),
            Tok::Str(_) => "string literal".to_owned(),
            Tok::Op(op) => format!("`{op}`"),
            Tok::Newline => "end of line".to_owned(),
            Tok::Eof => "end of input".to_owned(),
        };
        self.error_at(token, format!("invalid syntax: {context}, found {found}"))
    }

    fn error_at(&self, token: &Token, message: impl Into<String>) -> ParseError {
        ParseError::new(token.line, token.column, message)
    }

    fn enter(&mut self) -> Result<(), ParseError> {
        self.depth += 1;
        if self.depth > MAX_DEPTH {
            return Err(
                self.error_at(self.peek(), format!("expression nested too deeply (more than {MAX_DEPTH} levels)"))
            );
        }
        Ok(())
    }

    fn leave(&mut self, levels: usize) {
        self.depth = self.depth.saturating_sub(levels);
    }

    fn name(&mut self, context: &str) -> Result<String, ParseError> {
        match &self.peek().tok {
            Tok::Name(n) if !KEYWORDS.contains(&n.as_str()) => {
                let n = n.clone();
                self.advance();
                Ok(n)
            }
            _ => Err(self.unexpected(context)),
        }
    }

    fn program(&mut self) -> Result<Program, ParseError> {
        let mut statements = Vec::new();
        loop {
            match &self.peek().tok {
                Tok::Eof => return Ok(Program { statements }),
                Tok::Error(err) => return Err(err.clone()),
                Tok::Newline | Tok::Op(";") => {
                    self.advance();
                    continue;
                }
                _ => {}
            }
            statements.push(self.statement()?);
            match &self.peek().tok {
                Tok::Newline | Tok::Op(";") | Tok::Eof => {}
                _ => return Err(self.unexpected("expected `;` or a new line after a statement")),
            }
        }
    }

    fn statement(&mut self) -> Result<Stmt, ParseError> {
        let start = self.peek().clone();
        let kind = match &start.tok {
            Tok::Name(n) if n == "import" => {
                self.advance();
                self.import()?
            }
            Tok::Name(n) if n == "from" => {
                self.advance();
                self.import_from()?
            }
            Tok::Name(n) if n == "pass" => {
                self.advance();
                StmtKind::Pass
            }
            Tok::Name(n) if KEYWORDS.contains(&n.as_str()) && !matches!(n.as_str(), "True" | "False" | "None") => {
                return Err(self.error_at(&start, keyword_message(n)));
            }
            Tok::Op("@") => return Err(self.error_at(&start, "decorators are not supported")),
            _ => self.expression_statement()?,
        };
        Ok(Stmt { line: start.line, column: start.column, kind })
    }

    fn dotted_name(&mut self) -> Result<String, ParseError> {
        if self.is_op(".") || self.is_op("...") {
            return Err(self.error_at(self.peek(), "relative imports are not supported"));
        }
        let mut name = self.name("expected a module name")?;
        while self.eat_op(".") {
            name.push('.');
            name.push_str(&self.name("expected a module name after `.`")?);
        }
        Ok(name)
    }

    fn alias(&mut self) -> Result<Option<String>, ParseError> {
        if self.is_name("as") {
            self.advance();
            return Ok(Some(self.name("expected a name after `as`")?));
        }
        Ok(None)
    }

    fn import(&mut self) -> Result<StmtKind, ParseError> {
        let mut names = Vec::new();
        loop {
            let module = self.dotted_name()?;
            let alias = self.alias()?;
            names.push(ImportName { module, alias });
            if !self.eat_op(",") {
                return Ok(StmtKind::Import(names));
            }
        }
    }

    fn import_from(&mut self) -> Result<StmtKind, ParseError> {
        let module = self.dotted_name()?;
        if !self.is_name("import") {
            return Err(self.unexpected("expected `import`"));
        }
        self.advance();
        if self.is_op("*") {
            return Err(self.error_at(self.peek(), "`from ... import *` is not supported"));
        }
        let parenthesized = self.eat_op("(");
        let mut names = Vec::new();
        loop {
            let name = self.name("expected a name to import")?;
            let alias = self.alias()?;
            names.push((name, alias));
            if !self.eat_op(",") {
                break;
            }
            if parenthesized && self.is_op(")") {
                break;
            }
        }
        if parenthesized {
            self.expect_op(")")?;
        }
        Ok(StmtKind::FromImport { module, names })
    }

    fn expression_statement(&mut self) -> Result<StmtKind, ParseError> {
        let first = self.expr_list()?;
        if let Tok::Op(
            op @ ("+=" | "-=" | "*=" | "/=" | "//=" | "%=" | "**=" | "&=" | "|=" | "^=" | ">>=" | "<<=" | "@="),
        ) = self.peek().tok
        {
            return Err(self.error_at(self.peek(), format!("augmented assignment (`{op}`) is not supported")));
        }
        if self.is_op(":") {
            return Err(self.error_at(self.peek(), "variable annotations are not supported"));
        }
        if !self.is_op("=") {
            return Ok(StmtKind::Expr(first));
        }
        let mut targets = vec![first];
        let mut value;
        loop {
            self.advance();
            value = self.expr_list()?;
            if !self.is_op("=") {
                break;
            }
            targets.push(value);
        }
        let targets = targets.into_iter().map(to_target).collect::<Result<Vec<_>, _>>()?;
        Ok(StmtKind::Assign { targets, value })
    }

    /// `expr (',' expr)* [',']`: a bare tuple when there is a comma.
    fn expr_list(&mut self) -> Result<Expr, ParseError> {
        let first = self.expr()?;
        if !self.is_op(",") {
            return Ok(first);
        }
        let (line, column) = (first.line, first.column);
        let mut items = vec![first];
        while self.eat_op(",") {
            if matches!(self.peek().tok, Tok::Newline | Tok::Eof | Tok::Op(";" | "=")) {
                break;
            }
            items.push(self.expr()?);
        }
        Ok(Expr { line, column, kind: ExprKind::Tuple(items) })
    }

    /// One expression, rejecting the operators that would continue it in full Python.
    fn expr(&mut self) -> Result<Expr, ParseError> {
        self.enter()?;
        if let Tok::Op(op @ ("*" | "**")) = self.peek().tok {
            return Err(self.error_at(self.peek(), format!("unpacking (`{op}`) is not supported")));
        }
        let result = self.arith()?;
        let token = self.peek();
        let message = match &token.tok {
            Tok::Name(n) if n == "if" => Some("conditional expressions (`a if cond else b`) are not supported".into()),
            Tok::Name(n) if n == "for" || n == "async" => {
                Some("comprehensions and generator expressions are not supported".into())
            }
            Tok::Name(n) if matches!(n.as_str(), "and" | "or" | "not" | "in" | "is") => {
                if n == "not" {
                    Some("comparison operators (`not in`) are not supported".into())
                } else {
                    Some(keyword_message(n))
                }
            }
            Tok::Op(op @ ("==" | "!=" | "<" | ">" | "<=" | ">=")) => {
                Some(format!("comparison operators (`{op}`) are not supported"))
            }
            Tok::Op(op @ ("&" | "|" | "^" | "<<" | ">>")) => {
                Some(format!("bitwise operators (`{op}`) are not supported"))
            }
            Tok::Op(":=") => Some("assignment expressions (`:=`) are not supported".into()),
            _ => None,
        };
        if let Some(message) = message {
            return Err(self.error_at(token, message));
        }
        self.leave(1);
        Ok(result)
    }

    fn arith(&mut self) -> Result<Expr, ParseError> {
        let mut left = self.term()?;
        let mut levels = 0;
        loop {
            let op = match self.peek().tok {
                Tok::Op("+") => BinOp::Add,
                Tok::Op("-") => BinOp::Sub,
                _ => break,
            };
            self.enter()?;
            levels += 1;
            self.advance();
            let right = self.term()?;
            left = binary(op, left, right);
        }
        self.leave(levels);
        Ok(left)
    }

    fn term(&mut self) -> Result<Expr, ParseError> {
        let mut left = self.factor()?;
        let mut levels = 0;
        loop {
            let op = match self.peek().tok {
                Tok::Op("*") => BinOp::Mul,
                Tok::Op("/") => BinOp::Div,
                Tok::Op("//") => BinOp::FloorDiv,
                Tok::Op("%") => BinOp::Mod,
                Tok::Op("@") => return Err(self.error_at(self.peek(), "matrix multiplication (`@`) is not supported")),
                _ => break,
            };
            self.enter()?;
            levels += 1;
            self.advance();
            let right = self.factor()?;
            left = binary(op, left, right);
        }
        self.leave(levels);
        Ok(left)
    }

    fn factor(&mut self) -> Result<Expr, ParseError> {
        let token = self.peek().clone();
        let op = match token.tok {
            Tok::Op("+") => UnaryOp::Plus,
            Tok::Op("-") => UnaryOp::Minus,
            Tok::Op("~") => return Err(self.error_at(&token, "bitwise operators (`~`) are not supported")),
            _ => return self.power(),
        };
        self.enter()?;
        self.advance();
        let operand = self.factor()?;
        self.leave(1);
        Ok(Expr { line: token.line, column: token.column, kind: ExprKind::Unary(op, Box::new(operand)) })
    }

    fn power(&mut self) -> Result<Expr, ParseError> {
        let base = self.primary()?;
        if !self.eat_op("**") {
            return Ok(base);
        }
        self.enter()?;
        let exponent = self.factor()?;
        self.leave(1);
        Ok(binary(BinOp::Pow, base, exponent))
    }

    fn primary(&mut self) -> Result<Expr, ParseError> {
        let mut expr = self.atom()?;
        let start = (expr.line, expr.column);
        let mut levels = 0;
        loop {
            let token = self.peek().clone();
            let kind = match token.tok {
                Tok::Op(".") => {
                    self.advance();
                    let attr = match &self.peek().tok {
                        Tok::Name(n) => n.clone(),
                        _ => return Err(self.unexpected("expected an attribute name after `.`")),
                    };
                    self.advance();
                    ExprKind::Attr(Box::new(expr), attr)
                }
                Tok::Op("(") => {
                    self.advance();
                    let (args, kwargs) = self.call_args()?;
                    ExprKind::Call { func: Box::new(expr), args, kwargs }
                }
                Tok::Op("[") => {
                    self.advance();
                    if self.is_op(":") {
                        return Err(self.error_at(self.peek(), "slices are not supported"));
                    }
                    let index = self.expr()?;
                    if self.is_op(":") {
                        return Err(self.error_at(self.peek(), "slices are not supported"));
                    }
                    if self.is_op(",") {
                        return Err(self.error_at(self.peek(), "tuple subscripts are not supported"));
                    }
                    self.expect_op("]")?;
                    ExprKind::Subscript(Box::new(expr), Box::new(index))
                }
                _ => break,
            };
            self.enter()?;
            levels += 1;
            // A trailer's node starts where its primary starts, as in Python's AST.
            expr = Expr { line: start.0, column: start.1, kind };
        }
        self.leave(levels);
        Ok(expr)
    }

    fn call_args(&mut self) -> Result<CallArgs, ParseError> {
        let mut args = Vec::new();
        let mut kwargs: Vec<(String, Expr)> = Vec::new();
        while !self.is_op(")") {
            let token = self.peek().clone();
            match (&token.tok, self.peek_at(1)) {
                (Tok::Name(name), Tok::Op("=")) if !KEYWORDS.contains(&name.as_str()) => {
                    if kwargs.iter().any(|(k, _)| k == name) {
                        return Err(self.error_at(&token, format!("keyword argument repeated: {name}")));
                    }
                    let name = name.clone();
                    self.advance();
                    self.advance();
                    kwargs.push((name, self.expr()?));
                }
                _ => {
                    let arg = self.expr()?;
                    if !kwargs.is_empty() {
                        return Err(self.error_at(&token, "positional argument follows keyword argument"));
                    }
                    args.push(arg);
                }
            }
            if !self.eat_op(",") {
                break;
            }
        }
        self.expect_op(")")?;
        Ok((args, kwargs))
    }

    /// Comma-separated expressions up to `close`, allowing a trailing comma.
    fn items(&mut self, close: &str) -> Result<Vec<Expr>, ParseError> {
        let mut items = Vec::new();
        while !self.is_op(close) {
            items.push(self.expr()?);
            if !self.eat_op(",") {
                break;
            }
        }
        self.expect_op(close)?;
        Ok(items)
    }

    fn atom(&mut self) -> Result<Expr, ParseError> {
        let token = self.peek().clone();
        let at = |kind| Expr { line: token.line, column: token.column, kind };
        let kind = match &token.tok {
            Tok::Int(i) => {
                self.advance();
                ExprKind::Const(Const::Int(*i))
            }
            Tok::Float(f) => {
                self.advance();
                ExprKind::Const(Const::Float(*f))
            }
            Tok::Str(_) => {
                let mut s = String::new();
                while let Tok::Str(part) = &self.peek().tok {
                    s.push_str(part);
                    self.advance();
                }
                ExprKind::Const(Const::Str(s))
            }
            Tok::Name(n) => {
                let kind = match n.as_str() {
                    "True" => ExprKind::Const(Const::Bool(true)),
                    "False" => ExprKind::Const(Const::Bool(false)),
                    "None" => ExprKind::Const(Const::None),
                    kw if KEYWORDS.contains(&kw) => return Err(self.error_at(&token, keyword_message(kw))),
                    name => ExprKind::Name(name.to_owned()),
                };
                self.advance();
                kind
            }
            Tok::Op("(") => {
                self.advance();
                if self.eat_op(")") {
                    return Ok(at(ExprKind::Tuple(Vec::new())));
                }
                let first = self.expr()?;
                if self.eat_op(")") {
                    return Ok(first);
                }
                if !self.is_op(",") {
                    return Err(self.unexpected("expected `,` or `)`"));
                }
                self.advance();
                let mut items = vec![first];
                items.extend(self.items(")")?);
                ExprKind::Tuple(items)
            }
            Tok::Op("[") => {
                self.advance();
                ExprKind::List(self.items("]")?)
            }
            Tok::Op("{") => {
                self.advance();
                ExprKind::Dict(self.dict_items()?)
            }
            Tok::Op("...") => return Err(self.error_at(&token, "Ellipsis (`...`) is not supported")),
            _ => return Err(self.unexpected("expected an expression")),
        };
        Ok(at(kind))
    }

    fn dict_items(&mut self) -> Result<Vec<(Expr, Expr)>, ParseError> {
        let mut items = Vec::new();
        while !self.is_op("}") {
            if self.is_op("**") {
                return Err(self.error_at(self.peek(), "unpacking (`**`) is not supported"));
            }
            let key = self.expr()?;
            if self.is_op(",") || self.is_op("}") {
                return Err(self.error_at(self.peek(), "set literals are not supported"));
            }
            self.expect_op(":")?;
            let value = self.expr()?;
            items.push((key, value));
            if !self.eat_op(",") {
                break;
            }
        }
        self.expect_op("}")?;
        Ok(items)
    }
}

fn binary(op: BinOp, left: Expr, right: Expr) -> Expr {
    Expr { line: left.line, column: left.column, kind: ExprKind::Binary(op, Box::new(left), Box::new(right)) }
}

fn to_target(expr: Expr) -> Result<Target, ParseError> {
    let err = |msg: &str| Err(ParseError::new(expr.line, expr.column, msg));
    match expr.kind {
        ExprKind::Name(name) => Ok(Target::Name(name)),
        ExprKind::Attr(obj, attr) => Ok(Target::Attr(*obj, attr)),
        ExprKind::Tuple(_) | ExprKind::List(_) => err("unpacking assignments (`a, b = ...`) are not supported"),
        ExprKind::Subscript(..) => err("item assignment (`x[i] = ...`) is not supported"),
        ExprKind::Call { .. } => err("cannot assign to function call"),
        _ => err("cannot assign to expression"),
    }
}
