//! pyautogui code as OSWorld agents write it, turned into steps: the host's one
//! translation of pyautogui into actions ([`parse`]), for agents under
//! `--pyautogui-translate-only` (every way an answer comes in: Navi, the step
//! protocol, MCP's `run_python`), for `arena act` and for tasks' `execute` setup
//! steps alike, under one deadline. (By default an agent's pyautogui code runs with
//! its effects in the host's interpreter instead: `arena-exec`.)
//!
//! The code runs in the shared interpreter (`arena_script`, the same
//! parser and pyautogui semantics the guest's `/execute` has) against a host that
//! records instead of acting: input calls become [`Step::Act`], `time.sleep` a
//! [`Action::Wait`], `pyperclip.copy` a [`Step::SetClipboard`] (and
//! `pyperclip.paste` gives back what the code copied). Anything else with an effect
//! (files, processes, windows, screenshots) is refused, naming what. The answers
//! `WAIT`, `DONE` and `FAIL` (OSWorld's special actions) are decisions. The whole
//! program is translated before anything is done, so code that fails does nothing.
//!
//! Coordinates: with [`Coords::Fraction`], [`Coords::Grid1000`] or an image size,
//! the `x`/`y` arguments of every pyautogui mouse call (and the offsets of
//! `moveRel`/`dragRel`) are multiplied into screen pixels before pyautogui's own
//! `int()` truncation, by rewriting the parsed program; so `click(0.5, 0.5)` is the
//! centre of the screen. `pyautogui.position()` and `size()` still answer in
//! pixels. With [`Coords::Pixels`] nothing is rewritten.

use arena_script::ast::{BinOp, Const, Expr, ExprKind, FunctionBody, Program, Stmt, StmtKind};
use arena_script::host::cursor_after;
use arena_script::{
    run, CommandOutput, ErrorKind, Globals, HostError, HostResult, PathKind, RecordingHost, ScriptHost, Stop,
    WindowChange,
};
use arena_shared::action::Action;
use arena_shared::cmdline::CommandSpec;
use arena_shared::observation::WindowInfo;
use arena_shared::registry::RegistryValue;
use image::RgbaImage;
use std::time::{Duration, Instant};

use super::{ActionError, ActionSpace, Context, Coords, Decision, Step};

/// How much of the code an error quotes.
const QUOTE_CHARS: usize = 200;

/// Translates one answer: pyautogui code or one of `WAIT`, `DONE`, `FAIL`. The
/// program runs with `pyautogui` and `time` imported (upstream's `python -c "import
/// pyautogui; import time; ..."`), for at most [`TRANSLATE_TIME`].
///
/// # Errors
///
/// [`ActionError`] when the code does not parse, uses something outside the
/// interpreter's subset, does something other than input, or raises; the message
/// names the line and quotes the code.
pub fn parse(code: &str, ctx: &Context) -> Result<Vec<Step>, ActionError> {
    if let Some(decision) = Decision::parse(code) {
        return Ok(vec![decision.into()]);
    }
    let fail = |err: arena_script::ScriptError| {
        let quoted: String = code.chars().take(QUOTE_CHARS).collect();
        let ellipsis = if code.chars().count() > QUOTE_CHARS { "..." } else { "" };
        let what = if err.kind == ErrorKind::Syntax { "cannot parse" } else { "cannot translate" };
        ActionError::new(ActionSpace::Pyautogui, format!("{what} the pyautogui code {quoted:?}{ellipsis}: {err}"))
    };
    let mut program = arena_script::parse(code).map_err(|e| fail(e.into()))?;
    rescale(&mut program, ctx.coords, ctx.screen);
    let mut host = StepHost { rec: RecordingHost::new(ctx.screen, ctx.cursor), steps: Vec::new(), copied: None };
    run_program(&program, &mut host).map_err(fail)?;
    Ok(host.steps)
}

/// Rewrites a parsed program so that the coordinates of its pyautogui mouse calls,
/// given in `coords`, become pixels of `screen` (see the module documentation).
/// The one place this happens: [`parse`], and the host's executor when a run lets
/// pyautogui code run with its effects (the default; not with `--pyautogui-translate-only`). With
/// [`Coords::Pixels`] nothing changes.
pub fn rescale(program: &mut Program, coords: Coords, screen: (u32, u32)) {
    if coords != Coords::Pixels {
        let (fx, fy) = coords.factors(screen);
        scale_block(&mut program.statements, fx, fy);
    }
}

/// How long translating one answer may take.
pub const TRANSLATE_TIME: Duration = Duration::from_secs(5);

fn run_program(program: &Program, host: &mut StepHost) -> Result<(), arena_script::ScriptError> {
    // Translating runs no effects, only the program's own work: a few seconds bound a
    // reply that loops, besides the interpreter's loop budget.
    let stop = Stop::new(Some(Instant::now() + TRANSLATE_TIME), None);
    let globals =
        Globals { computer: None, computer_action_delay: 0.25, preimport: &["pyautogui", "time"], stop, memory: None };
    run(program, host, globals).map(|_| ())
}

/// The pyautogui functions whose coordinates are rescaled, with the positional
/// indexes and keyword names of `x` and `y`.
const COORDINATE_CALLS: &[(&str, usize, &str, &str)] = &[
    ("moveTo", 0, "x", "y"),
    ("dragTo", 0, "x", "y"),
    ("click", 0, "x", "y"),
    ("leftClick", 0, "x", "y"),
    ("rightClick", 0, "x", "y"),
    ("middleClick", 0, "x", "y"),
    ("doubleClick", 0, "x", "y"),
    ("tripleClick", 0, "x", "y"),
    ("mouseDown", 0, "x", "y"),
    ("mouseUp", 0, "x", "y"),
    ("moveRel", 0, "xOffset", "yOffset"),
    ("move", 0, "xOffset", "yOffset"),
    ("dragRel", 0, "xOffset", "yOffset"),
    ("drag", 0, "xOffset", "yOffset"),
    ("scroll", 1, "x", "y"),
    ("vscroll", 1, "x", "y"),
    ("hscroll", 1, "x", "y"),
];

fn scale_block(stmts: &mut [Stmt], fx: f64, fy: f64) {
    for stmt in stmts {
        match &mut stmt.kind {
            StmtKind::Expr(e) | StmtKind::Assign { value: e, .. } | StmtKind::AugAssign { value: e, .. } => {
                scale_expr(e, fx, fy)
            }
            StmtKind::Return(Some(e)) | StmtKind::Raise(Some(e)) => scale_expr(e, fx, fy),
            StmtKind::If { test, body, orelse } | StmtKind::While { test, body, orelse } => {
                scale_expr(test, fx, fy);
                scale_block(body, fx, fy);
                scale_block(orelse, fx, fy);
            }
            StmtKind::For { iter, body, orelse, .. } => {
                scale_expr(iter, fx, fy);
                scale_block(body, fx, fy);
                scale_block(orelse, fx, fy);
            }
            StmtKind::Try { body, handlers, orelse, finalbody } => {
                scale_block(body, fx, fy);
                for h in handlers {
                    scale_block(&mut h.body, fx, fy);
                }
                scale_block(orelse, fx, fy);
                scale_block(finalbody, fx, fy);
            }
            StmtKind::Def(function) => {
                let function = std::sync::Arc::make_mut(function);
                if let FunctionBody::Block(body) = &mut function.body {
                    scale_block(body, fx, fy);
                }
            }
            _ => {}
        }
    }
}

/// Rescales the coordinate arguments of pyautogui calls in `e` and below.
fn scale_expr(e: &mut Expr, fx: f64, fy: f64) {
    if let ExprKind::Call { func, args, kwargs } = &mut e.kind {
        for a in args.iter_mut() {
            scale_expr(a, fx, fy);
        }
        for (_, v) in kwargs.iter_mut() {
            scale_expr(v, fx, fy);
        }
        let name = match &func.kind {
            ExprKind::Attr(object, name) if matches!(&object.kind, ExprKind::Name(m) if m == "pyautogui") => {
                Some(name.as_str())
            }
            _ => None,
        };
        let Some(&(_, first, kx, ky)) = name.and_then(|n| COORDINATE_CALLS.iter().find(|(f, ..)| *f == n)) else {
            return;
        };
        match args.get_mut(first) {
            // `click((x, y))`: a literal pair in the x position.
            Some(Expr { kind: ExprKind::Tuple(items) | ExprKind::List(items), .. }) if items.len() == 2 => {
                scale_one(&mut items[0], fx);
                scale_one(&mut items[1], fy);
            }
            Some(x) => {
                scale_one(x, fx);
                if let Some(y) = args.get_mut(first + 1) {
                    scale_one(y, fy);
                }
            }
            None => {}
        }
        for (key, v) in kwargs.iter_mut() {
            if key == kx {
                scale_one(v, fx);
            } else if key == ky {
                scale_one(v, fy);
            }
        }
    }
}

/// `e * factor`, unless `e` is the literal `None` (the current position).
fn scale_one(e: &mut Expr, factor: f64) {
    if matches!(e.kind, ExprKind::Const(Const::None)) {
        return;
    }
    let (line, column) = (e.line, e.column);
    let inner = std::mem::replace(e, Expr { line, column, kind: ExprKind::Const(Const::None) });
    let factor = Expr { line, column, kind: ExprKind::Const(Const::Float(factor)) };
    *e = Expr { line, column, kind: ExprKind::Binary(BinOp::Mul, Box::new(inner), Box::new(factor)) };
}

/// A host without I/O that records steps: input, sleeps and clipboard writes.
/// Every other effect is refused by the [`RecordingHost`] it wraps.
struct StepHost {
    rec: RecordingHost,
    steps: Vec<Step>,
    /// What the code copied, for `pyperclip.paste()`.
    copied: Option<String>,
}

impl ScriptHost for StepHost {
    // The steps are kept until the whole program is translated: the run counts them
    // against its memory budget, as its own values.
    fn keeps_actions(&self) -> bool {
        true
    }

    fn perform(&mut self, action: Action) -> HostResult<()> {
        self.rec.cursor = cursor_after(&action, self.rec.cursor);
        self.steps.push(Step::Act(action));
        Ok(())
    }

    fn sleep(&mut self, seconds: f64) -> HostResult<()> {
        let ms = (seconds * 1000.0).round();
        if ms >= 1.0 {
            // The cast saturates for absurd values, which the guest's wait limit refuses.
            self.steps.push(Step::Act(Action::Wait { ms: ms as u64 }));
        }
        Ok(())
    }

    fn cursor_position(&mut self) -> HostResult<(i32, i32)> {
        self.rec.cursor_position()
    }

    fn screen_size(&mut self) -> HostResult<(u32, u32)> {
        self.rec.screen_size()
    }

    fn capture(&mut self) -> HostResult<RgbaImage> {
        self.rec.capture()
    }

    fn observed_screenshot(&mut self) -> HostResult<RgbaImage> {
        self.rec.observed_screenshot()
    }

    fn windows(&mut self) -> HostResult<Vec<WindowInfo>> {
        self.rec.windows()
    }

    fn change_window(&mut self, id: u64, change: WindowChange) -> HostResult<()> {
        self.rec.change_window(id, change)
    }

    fn path_kind(&mut self, path: &str) -> Option<PathKind> {
        self.rec.path_kind(path)
    }

    fn list_dir(&mut self, path: &str) -> HostResult<Vec<String>> {
        self.rec.list_dir(path)
    }

    fn write_file(&mut self, path: &str, bytes: Vec<u8>) -> HostResult<()> {
        self.rec.write_file(path, bytes)
    }

    fn run(&mut self, command: &CommandSpec) -> HostResult<CommandOutput> {
        self.rec.run(command)
    }

    fn launch(&mut self, command: &CommandSpec) -> HostResult<Option<u32>> {
        self.rec.launch(command)
    }

    fn registry_read(&mut self, key: &str, value: Option<&str>) -> HostResult<Option<RegistryValue>> {
        self.rec.registry_read(key, value)
    }

    fn clipboard_set_text(&mut self, text: &str) -> HostResult<()> {
        self.copied = Some(text.to_owned());
        self.steps.push(Step::SetClipboard(text.to_owned()));
        Ok(())
    }

    fn clipboard_get_text(&mut self) -> HostResult<String> {
        self.copied.clone().ok_or_else(|| {
            HostError::Failed("reading a clipboard this code did not write cannot be translated into actions".into())
        })
    }

    fn clipboard_set_image(&mut self, image: RgbaImage) -> HostResult<()> {
        self.rec.clipboard_set_image(image)
    }

    fn env_var(&mut self, name: &str) -> Option<String> {
        self.rec.env_var(name)
    }
}
