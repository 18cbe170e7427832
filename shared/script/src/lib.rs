//! A safe interpreter for the Python that WAA hosts send: pyautogui one-liners
//! (`python -c "import pyautogui; pyautogui.click(x=100, y=200)"`), evaluator
//! getters (`import os; print(os.path.join(os.getenv('LOCALAPPDATA'), ...))`)
//! and Navi's `computer.*` actions for `/execute_windows`.
//!
//! It is not CPython: a real Python parser reads the code and [`parser`] keeps
//! the subset agents write (imports, assignments of every form, `if`/`for`/
//! `while` with `break`/`continue`, `try`/`except`/`finally`/`raise`, `def` and
//! `lambda`, comprehensions, f-strings, slices, comparisons and boolean logic),
//! refusing the rest (classes, `with`, generators, star-arguments, ...) with a
//! precise [`ParseError`] before anything runs. Modules are interpreter objects,
//! never real imports, and every effect goes through a [`ScriptHost`], so this
//! crate does no I/O of its own. Output is what CPython would print; failures are
//! [`ScriptError`]s styled like Python exceptions.
//!
//! # Layout
//!
//! - [`parser`]: source to [`ast::Program`] through `rustpython-parser`; [`parse`].
//! - `interp/`: the evaluator: statements, control flow, scopes, user functions,
//!   expressions ([`run`], [`Globals`]), with the builtin functions (`builtins`) and
//!   the methods of `str`, `list`, `tuple`, `dict`, `set` (`methods`), which call back
//!   into it.
//! - `value/`: runtime values and `str`/`repr`; `heap`, the shared, copy-on-write
//!   payloads of strings and containers, the live memory meter they are counted on,
//!   and the hash-table keys of dicts and sets; `ops`, arithmetic and comparisons with
//!   Python semantics; `format`, format specs, `%` and `str.format`.
//! - `stop`: the deadline and cancel flag ([`Stop`]) a run checks as it works.
//! - `args`: how built-ins bind and convert their arguments, and iteration.
//! - `runtime`: the effects side of a run (host, output, `sys.exit`, [`ComputerState`]),
//!   what the imported modules act through; [`RunOutput`].
//! - `pyautogui`: the pyautogui 0.9.54 module mapped to [`Action`]s.
//! - `stdlib`: `time`, `os`, `os.path` ([`arena_shared::ntpath`]), `subprocess`, `platform`, `sys`, `PIL`, `pyperclip`.
//! - `computer`: the Navi `Computer` object over [`ComputerState`]; `difflib` for its fuzzy window match.
//! - `dialect`: [`dialect_of`], whether agent code is Navi's `computer` code or pyautogui code.
//! - [`host`]: the [`ScriptHost`] trait of primitives (input, capture, windows, files,
//!   processes, registry, clipboard, environment) and the I/O-free [`RecordingHost`].
//! - [`compose`]: the behaviours made of primitives ([`Composed`]: the window list,
//!   switching windows, opening a program, the OS version, saving a screenshot,
//!   `subprocess`), written once for the guest and the host.
//! - `argv`: recognising `python -c CODE` command lines.
//!
//! The modules import one another in layers, without loops: the imported modules
//! (`pyautogui`, `stdlib`, `computer`) get a `runtime`, never the evaluator, and the
//! two folders hold what is mutually recursive by nature (see `ARCHITECTURE.md`).
//!
//! # Safety properties
//!
//! Parsing never panics and always ends (programs are capped at
//! [`parser::MAX_SOURCE_BYTES`], nesting at [`parser::MAX_DEPTH`] and
//! [`parser::MAX_BLOCK_DEPTH`]). Running always ends: loop iterations and
//! function calls together are capped at [`MAX_STEPS`], calls nest at most
//! [`MAX_CALL_DEPTH`] deep, what a program holds at once is counted live against
//! [`MAX_MEMORY`] (sized results are refused before they are built), and a
//! [`Stop`] (the request's deadline and cancel flag) is checked at every step and
//! every slice of work inside long built-ins; these limits stop the run whatever
//! it catches. Integers are 64-bit with overflow errors; strings are capped at
//! 10 million bytes and lists at a million items; sleeps, clicks and key presses
//! go through the host, which may refuse them.

#![forbid(unsafe_code)]

mod args;
mod argv;
pub mod ast;
pub mod compose;
mod computer;
mod dialect;
mod difflib;
mod error;
pub mod host;
mod interp;
pub mod parser;
mod pool;
mod pyautogui;
mod runtime;
mod stdlib;
mod stop;
mod value;

#[cfg(test)]
mod tests;

pub use argv::{is_python_program, python_code_from_argv, python_code_from_command_line};
pub use compose::Composed;
pub use dialect::{dialect_of, Dialect};
pub use difflib::{get_close_matches, ratio as sequence_ratio};
pub use error::{ErrorKind, ParseError, ScriptError};
pub use host::{
    action_bytes, CommandArg, CommandOutput, HostError, HostResult, PathKind, RecordingHost, ScriptHost, WindowChange,
};
pub use interp::{run, run_measured, Globals, RunStats, KNOWN_MODULES, MAX_CALL_DEPTH, MAX_MEMORY, MAX_STEPS};
pub use parser::parse;
pub use pool::{MemoryPool, CHUNK as MEMORY_CHUNK};
pub use runtime::{ComputerState, RunOutput};
pub use stop::Stop;
pub use value::{float_repr, str_repr};

/// Parses and runs `src` in one step.
///
/// # Errors
///
/// [`ScriptError`] with kind [`ErrorKind::Syntax`] when `src` does not parse,
/// otherwise the first exception raised while running.
pub fn run_source(src: &str, host: &mut dyn ScriptHost, globals: Globals<'_>) -> Result<RunOutput, ScriptError> {
    let program = parse(src)?;
    run(&program, host, globals)
}
