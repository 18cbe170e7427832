//! What the modules a script imports act through: the [`Runtime`] of one run (the
//! host, the output so far, `sys.exit`'s code, the Navi `Computer`'s state), with the
//! effects every module shares (printing against the memory budget, sleeping through
//! the host, stopping like `SystemExit`).
//!
//! The evaluator (`interp`) owns one and lends it to `pyautogui`, `stdlib` and
//! `computer`, which therefore never see the evaluator: they cannot run Python code,
//! only effects. [`RunOutput`] is what a run leaves, and [`ComputerState`] what
//! `/update_computer` sets.

use crate::error::{value_error, ErrorKind, ScriptError};
use crate::host::{HostResult, ScriptHost};
use crate::stop;
use crate::value::heap;

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

/// What `/update_computer` set: the Set-of-Marks boxes and how to map them to the screen.
#[derive(Debug, Clone, PartialEq)]
pub struct ComputerState {
    /// Element boxes `[x1, y1, x2, y2]` in screenshot pixels; the index is the element id.
    pub rects: Vec<[i32; 4]>,
    /// `[x0, y0, x1, y1]` of the observed view; `move_abs` fractions are relative to it.
    pub window_rect: [i32; 4],
    /// Multiplies element centres in `move_id`.
    pub scale: (f64, f64),
    /// The "virtual clipboard" text `/obs_winagent` echoes back.
    pub clipboard_content: Option<String>,
    /// Use alt+c / alt+v instead of ctrl+c / ctrl+v.
    pub swap_ctrl_alt: bool,
    /// The element last moved to with `move_id`.
    pub current_id: Option<usize>,
}

impl ComputerState {
    /// A state for a `width` x `height` screen with no elements, as after an
    /// `/update_computer` with an empty `rects` list.
    pub fn for_screen(width: i32, height: i32) -> ComputerState {
        ComputerState {
            rects: Vec::new(),
            window_rect: [0, 0, width, height],
            scale: (1.0, 1.0),
            clipboard_content: None,
            swap_ctrl_alt: false,
            current_id: None,
        }
    }
}

/// The effects side of one run, which the evaluator lends to the built-in modules.
pub(crate) struct Runtime<'h, 'c> {
    pub(crate) host: &'h mut dyn ScriptHost,
    /// The Navi `Computer`'s state, for `/execute_windows`.
    pub(crate) computer: Option<&'c mut ComputerState>,
    /// Seconds slept after each `Computer` action.
    pub(crate) action_delay: f64,
    pub(crate) out: RunOutput,
    /// Set by `sys.exit`.
    pub(crate) exit: Option<i32>,
    /// Bytes printed, held against the memory budget until the run ends.
    printed: usize,
}

impl<'h, 'c> Runtime<'h, 'c> {
    pub(crate) fn new(
        host: &'h mut dyn ScriptHost,
        computer: Option<&'c mut ComputerState>,
        action_delay: f64,
    ) -> Runtime<'h, 'c> {
        Runtime { host, computer, action_delay, out: RunOutput::default(), exit: None, printed: 0 }
    }
}

impl Drop for Runtime<'_, '_> {
    fn drop(&mut self) {
        heap::release(self.printed);
    }
}

impl std::fmt::Debug for Runtime<'_, '_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Runtime").field("out", &self.out).field("exit", &self.exit).finish_non_exhaustive()
    }
}

impl Runtime<'_, '_> {
    /// Host failures become `OSError`s carrying the host's message; a timeout or an
    /// unreachable host becomes its own kind, which stops the script.
    pub(crate) fn host<T>(&mut self, result: HostResult<T>) -> Result<T, ScriptError> {
        result.map_err(crate::error::host_error)
    }

    pub(crate) fn print(&mut self, text: &str) -> Result<(), ScriptError> {
        heap::hold(text.len())?;
        self.printed += text.len();
        self.out.stdout.push_str(text);
        Ok(())
    }

    pub(crate) fn sleep(&mut self, seconds: f64) -> Result<(), ScriptError> {
        if seconds.is_nan() {
            return Err(value_error("Invalid value NaN (not a number)"));
        }
        if seconds < 0.0 {
            return Err(value_error("sleep length must be non-negative"));
        }
        // A pause that cannot end before the run must stop is refused at once, rather
        // than waited out to fail at the deadline anyway.
        if let Some(left) = stop::time_left() {
            if seconds > left.as_secs_f64() {
                return Err(ScriptError::new(
                    ErrorKind::Timeout,
                    format!(
                        "time.sleep({seconds}) would outlast the program's deadline ({:.3} s left); nothing was waited",
                        left.as_secs_f64()
                    ),
                ));
            }
        }
        if self.host.keeps_actions() && (seconds * 1000.0).round() >= 1.0 {
            heap::hold(std::mem::size_of::<arena_shared::action::Action>())?;
        }
        let result = self.host.sleep(seconds);
        self.host(result)
    }

    /// Stops the run like `SystemExit`.
    pub(crate) fn system_exit(&mut self, code: i32) -> ScriptError {
        self.exit = Some(code);
        ScriptError::new(ErrorKind::SystemExit, "")
    }
}
