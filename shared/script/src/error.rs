//! The two ways a script fails: it does not parse ([`ParseError`]), or it
//! raises while running ([`ScriptError`]).
//!
//! Messages are styled like CPython's where a host may compare or show them
//! (`NameError: name 'x' is not defined`), and name the construct or function
//! this interpreter does not support where Python would have run it.

use std::fmt;

/// Why a program was rejected before anything ran.
///
/// `line` and `column` are 1-based; the column counts characters.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("line {line}, column {column}: {message}")]
pub struct ParseError {
    pub line: usize,
    pub column: usize,
    /// What is wrong, naming the construct: "`for` loops are not supported".
    pub message: String,
}

impl ParseError {
    pub(crate) fn new(line: usize, column: usize, message: impl Into<String>) -> ParseError {
        ParseError { line, column, message: message.into() }
    }
}

/// The Python exception class a runtime failure corresponds to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum ErrorKind {
    /// The program did not parse.
    Syntax,
    Name,
    Type,
    Value,
    Attribute,
    Index,
    Key,
    ZeroDivision,
    Overflow,
    Memory,
    ModuleNotFound,
    Import,
    /// Valid Python that this interpreter deliberately does not run.
    NotSupported,
    /// The host (desktop, file system, process runner) refused or failed.
    Host,
    /// The host's deadline passed while the script ran; the script stopped there.
    Timeout,
    /// What the host acts on went out of reach; the script stopped there.
    Unreachable,
    /// `subprocess.check_call` / `check_output` saw a non-zero exit code.
    CalledProcess,
    /// `sys.exit()`: [`super::run`] turns it into a normal end with an exit code and never returns it.
    SystemExit,
    /// `raise Exception(...)`.
    Exception,
    /// `raise RuntimeError(...)`.
    Runtime,
    /// A failed `assert`.
    Assertion,
    /// `LookupError`, the parent of `IndexError` and `KeyError`.
    Lookup,
    /// `ArithmeticError`.
    Arithmetic,
    /// User functions called more deeply than the interpreter allows.
    Recursion,
    /// The program ran more loop iterations than the interpreter allows.
    LoopLimit,
}

impl ErrorKind {
    /// The Python exception name, as a traceback's last line starts.
    pub fn python_name(self) -> &'static str {
        match self {
            ErrorKind::Syntax => "SyntaxError",
            ErrorKind::Name => "NameError",
            ErrorKind::Type => "TypeError",
            ErrorKind::Value => "ValueError",
            ErrorKind::Attribute => "AttributeError",
            ErrorKind::Index => "IndexError",
            ErrorKind::Key => "KeyError",
            ErrorKind::ZeroDivision => "ZeroDivisionError",
            ErrorKind::Overflow => "OverflowError",
            ErrorKind::Memory => "MemoryError",
            ErrorKind::ModuleNotFound => "ModuleNotFoundError",
            ErrorKind::Import => "ImportError",
            ErrorKind::NotSupported => "NotImplementedError",
            ErrorKind::Host => "OSError",
            ErrorKind::Timeout => "TimeoutError",
            ErrorKind::Unreachable => "ConnectionError",
            ErrorKind::CalledProcess => "subprocess.CalledProcessError",
            ErrorKind::SystemExit => "SystemExit",
            ErrorKind::Exception => "Exception",
            ErrorKind::Runtime | ErrorKind::LoopLimit => "RuntimeError",
            ErrorKind::Assertion => "AssertionError",
            ErrorKind::Lookup => "LookupError",
            ErrorKind::Arithmetic => "ArithmeticError",
            ErrorKind::Recursion => "RecursionError",
        }
    }

    /// The exception class a program may name (in `except` or `raise`), by its Python name.
    pub(crate) fn from_python_name(name: &str) -> Option<ErrorKind> {
        Some(match name {
            "Exception" | "BaseException" => ErrorKind::Exception,
            "NameError" => ErrorKind::Name,
            "TypeError" => ErrorKind::Type,
            "ValueError" => ErrorKind::Value,
            "AttributeError" => ErrorKind::Attribute,
            "IndexError" => ErrorKind::Index,
            "KeyError" => ErrorKind::Key,
            "LookupError" => ErrorKind::Lookup,
            "ZeroDivisionError" => ErrorKind::ZeroDivision,
            "ArithmeticError" => ErrorKind::Arithmetic,
            "OverflowError" => ErrorKind::Overflow,
            "OSError" | "IOError" | "EnvironmentError" => ErrorKind::Host,
            "RuntimeError" => ErrorKind::Runtime,
            "AssertionError" => ErrorKind::Assertion,
            "ImportError" => ErrorKind::Import,
            "ModuleNotFoundError" => ErrorKind::ModuleNotFound,
            _ => return None,
        })
    }

    /// Whether an `except` clause naming `class` catches an exception of this kind.
    pub(crate) fn is_subclass_of(self, class: ErrorKind) -> bool {
        self == class
            || match class {
                ErrorKind::Exception => true,
                ErrorKind::Lookup => matches!(self, ErrorKind::Index | ErrorKind::Key),
                ErrorKind::Arithmetic => matches!(self, ErrorKind::ZeroDivision | ErrorKind::Overflow),
                ErrorKind::Import => self == ErrorKind::ModuleNotFound,
                ErrorKind::Host => matches!(self, ErrorKind::Timeout | ErrorKind::Unreachable),
                _ => false,
            }
    }
}

impl fmt::Display for ErrorKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.python_name())
    }
}

/// Why a program stopped: a parse error or an exception while running.
///
/// Side effects that happened before the failure (actions performed, text
/// printed) are not undone; `stdout` and `stderr` hold what was printed
/// before the failure, so a caller can answer exactly like a Python process
/// that died with a traceback.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("line {line}: {kind}: {message}")]
pub struct ScriptError {
    pub kind: ErrorKind,
    /// The 1-based line of the statement that failed.
    pub line: usize,
    /// The exception text without the class name: "name 'x' is not defined".
    pub message: String,
    /// Everything printed to stdout before the failure.
    pub stdout: String,
    /// Everything written to stderr before the failure (child process output).
    pub stderr: String,
}

impl ScriptError {
    pub(crate) fn new(kind: ErrorKind, message: impl Into<String>) -> ScriptError {
        ScriptError { kind, line: 0, message: message.into(), stdout: String::new(), stderr: String::new() }
    }

    /// Whether `try`/`except` may catch this failure.
    ///
    /// The interpreter's own limits (loop, recursion and allocation budgets), code
    /// outside the subset, a host that timed out or went away, and `sys.exit` stop
    /// the program whatever it catches, so that a broad `except Exception:` never
    /// hides that the run was cut short or that the interpreter did something
    /// other than what CPython would have done.
    pub fn is_catchable(&self) -> bool {
        match self.kind {
            ErrorKind::Syntax
            | ErrorKind::NotSupported
            | ErrorKind::Memory
            | ErrorKind::Recursion
            | ErrorKind::LoopLimit
            | ErrorKind::Timeout
            | ErrorKind::Unreachable
            | ErrorKind::SystemExit => false,
            ErrorKind::ModuleNotFound | ErrorKind::Import => false,
            ErrorKind::Attribute => !self.message.contains("not supported by this interpreter"),
            _ => true,
        }
    }

    /// The last line of a Python traceback: `NameError: name 'x' is not defined`.
    pub fn python_message(&self) -> String {
        if self.message.is_empty() {
            // `raise ValueError` prints the class alone, as CPython does.
            return self.kind.to_string();
        }
        format!("{}: {}", self.kind, self.message)
    }

    /// The text CPython would write to stderr for this failure of a `python -c` program.
    pub fn traceback(&self) -> String {
        if self.kind == ErrorKind::Syntax {
            return format!("  File \"<string>\", line {}\nSyntaxError: {}\n", self.line, self.message);
        }
        format!(
            "Traceback (most recent call last):\n  File \"<string>\", line {}, in <module>\n{}\n",
            self.line,
            self.python_message()
        )
    }
}

impl From<ParseError> for ScriptError {
    fn from(err: ParseError) -> ScriptError {
        ScriptError {
            kind: ErrorKind::Syntax,
            line: err.line,
            message: format!("column {}: {}", err.column, err.message),
            stdout: String::new(),
            stderr: String::new(),
        }
    }
}

/// Shorthands for building runtime errors inside the interpreter.
pub(crate) fn type_error(message: impl Into<String>) -> ScriptError {
    ScriptError::new(ErrorKind::Type, message)
}

pub(crate) fn value_error(message: impl Into<String>) -> ScriptError {
    ScriptError::new(ErrorKind::Value, message)
}

pub(crate) fn not_supported(message: impl Into<String>) -> ScriptError {
    ScriptError::new(ErrorKind::NotSupported, message)
}

/// A host failure as the exception the script sees.
pub(crate) fn host_error(err: super::host::HostError) -> ScriptError {
    use super::host::HostError;
    match err {
        HostError::Failed(message) => ScriptError::new(ErrorKind::Host, message),
        HostError::TimedOut(message) => ScriptError::new(ErrorKind::Timeout, message),
        HostError::Unreachable(message) => ScriptError::new(ErrorKind::Unreachable, message),
    }
}
