//! Navi's prompt texts, read at run time from the user's WindowsAgentArena
//! checkout (`--waa-root`), so the agent sends upstream's words without this
//! project containing them.
//!
//! The files are parsed with a real Python parser (`rustpython-parser`) and
//! only what the prompts need is evaluated:
//! - `mm_agents/navi/gpt/planner_messages.py`: the system prompt
//!   `planning_system_message_shortened_previmg` (what upstream's Navi uses with
//!   its default `use_last_screen`), a string or an f-string without fields; and
//!   the f-string `msg` of `build_user_msg_visual(...)`, whose fields may be a
//!   parameter, `"text" if PARAM == None else PARAM` or
//!   `"text" if len(PARAM) == 0 else PARAM`. Parameters are matched by position,
//!   as upstream's agent passes them.
//! - `mm_agents/navi/agent.py`: the f-string `prev_actions_to_string` appends per
//!   past action (fields `i` and `action`), and `memory_block_text_empty`.
//!
//! Anything laid out differently is an error naming the file and the symbol.

use std::path::{Path, PathBuf};

use rustpython_parser::ast::{self, CmpOp, Constant, Expr, Stmt};

/// A checkout whose prompt files cannot be read as expected.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {message}", path = path.display())]
pub struct PromptError {
    pub path: PathBuf,
    pub message: String,
}

/// One piece of an f-string.
#[derive(Debug, Clone, PartialEq)]
enum Part {
    Text(String),
    /// A parameter's value.
    Param(usize),
    /// `default if PARAM == None else PARAM`.
    IfNone(usize, String),
    /// `default if len(PARAM) == 0 else PARAM`.
    IfEmpty(usize, String),
}

/// The prompts of upstream's Navi as one checkout has them.
#[derive(Debug, Clone, PartialEq)]
pub struct WaaPrompts {
    pub system: String,
    user: Vec<Part>,
    /// The per-action history line; `Param(0)` is `i`, `Param(1)` is `action`.
    history: Vec<Part>,
    pub empty_memory: String,
    /// `waa@<commit>` (or `waa@unknown` when the checkout has no readable git HEAD).
    pub source: String,
}

/// What the user message is built from, in upstream's parameter order.
#[derive(Debug, Clone, Default)]
pub struct UserInputs<'a> {
    pub objective: &'a str,
    pub window_title: &'a str,
    pub window_names: &'a str,
    /// `None` when the clipboard holds no text (upstream's `None`).
    pub clipboard: Option<&'a str>,
    pub text_rendering: &'a str,
    pub candidates: &'a str,
    /// The history text, empty before the first action.
    pub history: &'a str,
    pub memory: &'a str,
}

const PLANNER: &str = "mm_agents/navi/gpt/planner_messages.py";
const AGENT: &str = "mm_agents/navi/agent.py";

impl WaaPrompts {
    /// Reads the prompts from a WindowsAgentArena checkout (its root, or its
    /// `src/win-arena-container/client` folder).
    ///
    /// # Errors
    ///
    /// [`PromptError`] naming the file and the symbol that is missing or laid out differently.
    pub fn load(root: &Path) -> Result<WaaPrompts, PromptError> {
        let nested = root.join("src/win-arena-container/client");
        let client = if nested.join(PLANNER).is_file() { nested } else { root.to_path_buf() };
        let planner_path = client.join(PLANNER);
        let planner = parse_file(&planner_path)?;
        let err = |path: &Path, message: String| PromptError { path: path.to_owned(), message };

        let system_name = "planning_system_message_shortened_previmg";
        let system = find_assign(&planner, system_name)
            .ok_or_else(|| err(&planner_path, format!("no assignment to `{system_name}`")))
            .and_then(|value| {
                constant_text(value)
                    .ok_or_else(|| err(&planner_path, format!("`{system_name}` is not a constant string")))
            })?;

        let user_name = "build_user_msg_visual";
        let (params, body) = find_function(&planner, user_name)
            .ok_or_else(|| err(&planner_path, format!("no function `{user_name}`")))?;
        let template = find_assign(body, "msg")
            .ok_or_else(|| err(&planner_path, format!("`{user_name}` assigns no f-string to `msg`")))?;
        let user = template_parts(template, &params).map_err(|m| err(&planner_path, format!("`{user_name}`: {m}")))?;
        if params.len() < 8 {
            return Err(err(&planner_path, format!("`{user_name}` takes {} parameters, not 8", params.len())));
        }

        let agent_path = client.join(AGENT);
        let agent = parse_file(&agent_path)?;
        let history_name = "prev_actions_to_string";
        let (_, body) = find_function(&agent, history_name)
            .ok_or_else(|| err(&agent_path, format!("no function `{history_name}`")))?;
        let line = find_aug_assign(body, "result")
            .ok_or_else(|| err(&agent_path, format!("`{history_name}` appends no f-string to `result`")))?;
        let history = template_parts(line, &["i".to_owned(), "action".to_owned()])
            .map_err(|m| err(&agent_path, format!("`{history_name}`: {m}")))?;
        let memory_name = "memory_block_text_empty";
        let empty_memory = find_attribute_assign(&agent, memory_name)
            .and_then(constant_text)
            .ok_or_else(|| err(&agent_path, format!("no constant string assigned to `self.{memory_name}`")))?;

        Ok(WaaPrompts { system, user, history, empty_memory, source: format!("waa@{}", git_head(root)) })
    }

    /// The user message's text, as `build_user_msg_visual` builds it.
    pub fn user_message(&self, inputs: &UserInputs<'_>) -> String {
        let values = [
            Some(inputs.objective),
            Some(inputs.window_title),
            Some(inputs.window_names),
            inputs.clipboard,
            Some(inputs.text_rendering),
            Some(inputs.candidates),
            Some(inputs.history),
            Some(inputs.memory),
        ];
        render(&self.user, &values)
    }

    /// The history text of `actions` (oldest first), as `prev_actions_to_string`
    /// builds it: newest first, at most `n` of them.
    pub fn history_text(&self, actions: &[String], n: usize) -> String {
        let mut text = String::new();
        for (i, action) in actions.iter().rev().take(n).enumerate() {
            let number = (i + 1).to_string();
            text.push_str(&render(&self.history, &[Some(number.as_str()), Some(action.as_str())]));
        }
        text
    }
}

fn render(parts: &[Part], values: &[Option<&str>]) -> String {
    let value = |i: usize| values.get(i).copied().flatten();
    let mut out = String::new();
    for part in parts {
        match part {
            Part::Text(text) => out.push_str(text),
            // Python's f-string of None is "None".
            Part::Param(i) => out.push_str(value(*i).unwrap_or("None")),
            Part::IfNone(i, default) => out.push_str(value(*i).unwrap_or(default)),
            Part::IfEmpty(i, default) => match value(*i) {
                Some(v) if !v.is_empty() => out.push_str(v),
                _ => out.push_str(default),
            },
        }
    }
    out
}

fn parse_file(path: &Path) -> Result<Vec<Stmt>, PromptError> {
    let source = std::fs::read_to_string(path)
        .map_err(|e| PromptError { path: path.to_owned(), message: format!("cannot read it: {e}") })?;
    <ast::Suite as rustpython_parser::Parse>::parse(&source, &path.display().to_string())
        .map_err(|e| PromptError { path: path.to_owned(), message: format!("not Python this parser reads: {e}") })
}

/// Every statement, nested bodies included, in source order.
fn walk<'a>(stmts: &'a [Stmt], out: &mut Vec<&'a Stmt>) {
    for stmt in stmts {
        out.push(stmt);
        match stmt {
            Stmt::FunctionDef(f) => walk(&f.body, out),
            Stmt::ClassDef(c) => walk(&c.body, out),
            Stmt::For(f) => walk(&f.body, out),
            Stmt::While(w) => walk(&w.body, out),
            Stmt::If(i) => {
                walk(&i.body, out);
                walk(&i.orelse, out);
            }
            Stmt::With(w) => walk(&w.body, out),
            Stmt::Try(t) => walk(&t.body, out),
            _ => {}
        }
    }
}

fn all(stmts: &[Stmt]) -> Vec<&Stmt> {
    let mut out = Vec::new();
    walk(stmts, &mut out);
    out
}

fn find_assign<'a>(stmts: &'a [Stmt], name: &str) -> Option<&'a Expr> {
    all(stmts).into_iter().find_map(|stmt| match stmt {
        Stmt::Assign(a) if a.targets.iter().any(|t| matches!(t, Expr::Name(n) if n.id.as_str() == name)) => {
            Some(a.value.as_ref())
        }
        _ => None,
    })
}

fn find_attribute_assign<'a>(stmts: &'a [Stmt], attr: &str) -> Option<&'a Expr> {
    all(stmts).into_iter().find_map(|stmt| match stmt {
        Stmt::Assign(a) if a.targets.iter().any(|t| matches!(t, Expr::Attribute(x) if x.attr.as_str() == attr)) => {
            Some(a.value.as_ref())
        }
        _ => None,
    })
}

fn find_aug_assign<'a>(stmts: &'a [Stmt], name: &str) -> Option<&'a Expr> {
    all(stmts).into_iter().find_map(|stmt| match stmt {
        Stmt::AugAssign(a) if matches!(a.target.as_ref(), Expr::Name(n) if n.id.as_str() == name) => {
            Some(a.value.as_ref())
        }
        _ => None,
    })
}

/// A function's positional parameter names and body.
fn find_function<'a>(stmts: &'a [Stmt], name: &str) -> Option<(Vec<String>, &'a [Stmt])> {
    all(stmts).into_iter().find_map(|stmt| match stmt {
        Stmt::FunctionDef(f) if f.name.as_str() == name => {
            let params = f.args.args.iter().map(|a| a.def.arg.to_string()).collect();
            Some((params, f.body.as_slice()))
        }
        _ => None,
    })
}

/// A string constant, or an f-string whose parts are all constant.
fn constant_text(expr: &Expr) -> Option<String> {
    match expr {
        Expr::Constant(ast::ExprConstant { value: Constant::Str(s), .. }) => Some(s.clone()),
        Expr::JoinedStr(j) => j.values.iter().map(constant_text).collect(),
        _ => None,
    }
}

fn param_index(expr: &Expr, params: &[String]) -> Option<usize> {
    match expr {
        Expr::Name(n) => params.iter().position(|p| p == n.id.as_str()),
        _ => None,
    }
}

/// The pieces of an f-string (or a plain string) over `params`.
fn template_parts(expr: &Expr, params: &[String]) -> Result<Vec<Part>, String> {
    let values: Vec<&Expr> = match expr {
        Expr::JoinedStr(j) => j.values.iter().collect(),
        Expr::Constant(_) => vec![expr],
        _ => return Err("the template is not an f-string".into()),
    };
    let mut parts = Vec::new();
    for value in values {
        if let Some(text) = constant_text(value) {
            parts.push(Part::Text(text));
            continue;
        }
        let Expr::FormattedValue(field) = value else {
            return Err("an f-string part this reader does not know".into());
        };
        if field.format_spec.is_some() {
            return Err("a field with a format specification".into());
        }
        parts.push(field_part(&field.value, params)?);
    }
    Ok(parts)
}

fn field_part(expr: &Expr, params: &[String]) -> Result<Part, String> {
    if let Some(i) = param_index(expr, params) {
        return Ok(Part::Param(i));
    }
    let unknown = || "a field expression other than a parameter or `\"text\" if … else PARAM`".to_owned();
    let Expr::IfExp(choice) = expr else { return Err(unknown()) };
    let (Some(default), Some(orelse)) = (constant_text(&choice.body), param_index(&choice.orelse, params)) else {
        return Err(unknown());
    };
    let Expr::Compare(test) = choice.test.as_ref() else { return Err(unknown()) };
    let [op] = test.ops.as_slice() else { return Err(unknown()) };
    let [against] = test.comparators.as_slice() else { return Err(unknown()) };
    match (op, test.left.as_ref(), against) {
        (CmpOp::Eq | CmpOp::Is, left, Expr::Constant(c)) if c.value == Constant::None => {
            (param_index(left, params) == Some(orelse)).then_some(Part::IfNone(orelse, default)).ok_or_else(unknown)
        }
        (CmpOp::Eq, Expr::Call(call), Expr::Constant(c)) if matches!(&c.value, Constant::Int(n) if n.to_string() == "0") =>
        {
            let is_len = matches!(call.func.as_ref(), Expr::Name(n) if n.id.as_str() == "len");
            let arg = call.args.first().and_then(|a| param_index(a, params));
            (is_len && arg == Some(orelse)).then_some(Part::IfEmpty(orelse, default)).ok_or_else(unknown)
        }
        _ => Err(unknown()),
    }
}

/// The commit of the checkout `root` is in: the root itself, or a folder inside
/// a checkout (the `src/win-arena-container/client` folder); the first `.git`
/// found going up is read, a folder (a clone) or a file (`gitdir: PATH`, a
/// worktree or a submodule, whose branch refs live in its `commondir`). The
/// HEAD's commit, detached or through its branch's ref (loose or packed), to
/// 12 characters; `unknown` when no `.git` is found or it cannot be read.
pub fn git_head(root: &Path) -> String {
    let found = root.ancestors().find_map(|dir| {
        let git = dir.join(".git");
        if git.is_dir() {
            return Some(git);
        }
        let text = std::fs::read_to_string(&git).ok()?;
        let target = text.lines().find_map(|l| l.strip_prefix("gitdir:"))?.trim();
        Some(dir.join(target))
    });
    let Some(git) = found else { return "unknown".into() };
    let common = std::fs::read_to_string(git.join("commondir")).map_or_else(|_| git.clone(), |c| git.join(c.trim()));
    let short = |id: &str| id.trim().chars().take(12).collect::<String>();
    let Ok(head) = std::fs::read_to_string(git.join("HEAD")) else { return "unknown".into() };
    let head = head.trim();
    let Some(reference) = head.strip_prefix("ref: ") else { return short(head) };
    for dir in [&git, &common] {
        if let Ok(id) = std::fs::read_to_string(dir.join(reference)) {
            return short(&id);
        }
    }
    let packed = std::fs::read_to_string(common.join("packed-refs")).unwrap_or_default();
    packed
        .lines()
        .find_map(|l| l.strip_suffix(reference).filter(|id| id.ends_with(' ')).map(short))
        .unwrap_or_else(|| "unknown".into())
}

#[cfg(test)]
pub(crate) mod tests;
