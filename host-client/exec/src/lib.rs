//! The executor (`arena-exec`): what an agent, or a task's setup step, wants done
//! on a guest, carried out there. It sits below the setup steps and the harness,
//! so both carry out pyautogui code the same way.
//!
//! What it is: the action type every agent family answers in ([`AgentAction`],
//! also what trajectories record), how each kind reaches the guest (typed input
//! as one batch, the clipboard, Navi `computer.*` and pyautogui code in the host's
//! interpreter against a [`ScriptHost`](arena_script::ScriptHost) over the guest,
//! or pyautogui translated by the action spaces), and the one choice of how
//! pyautogui code runs ([`PyautoguiPolicy`]). What it is not: it does not decide
//! what an agent does or when a step counts (the episode does), and it keeps no
//! state between actions beyond the [`ComputerState`](arena_script::ComputerState)
//! its caller hands it.
//!
//! # Layout
//!
//! - [`action`]: [`AgentAction`], its JSON record and how an action space's steps become actions.
//! - [`execute`]: [`execute_with`], [`perform_steps`], [`perform_input_only`] and their options and outcome.
//! - [`options`]: [`ExecOptions`], [`PyautoguiPolicy`] and [`Boxes`], what the executor is handed.
//! - `guest_host`: [`GuestHost`], the script host over a guest's `/v1` API.

#![forbid(unsafe_code)]

pub mod action;
pub mod execute;
mod guest_host;
pub mod options;

pub use action::{AgentAction, Code};
pub use execute::{
    execute, execute_with, perform_input_only, perform_steps, pointer, translate_pyautogui, ActionOutcome, ExecError,
    InputOnly,
};
pub use guest_host::GuestHost;
pub use options::{Boxes, ExecOptions, PyautoguiPolicy};
