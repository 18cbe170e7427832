//! Carrying out an [`AgentAction`] on a guest: [`execute_with`], and the runner of
//! an action space's steps, [`perform_steps`].
//!
//! Each kind of action has one way in:
//! - typed actions are one `POST /v1/actions` batch, and a clipboard action one
//!   `PUT /v1/clipboard`;
//! - Navi `computer.*` code, and pyautogui code under [`PyautoguiPolicy::Effects`]
//!   (the default, as upstream's `python -c` runs it), run here on the host in the
//!   `arena_script` interpreter against [`GuestHost`]: a [`arena_script::ScriptHost`]
//!   whose every effect is a typed call of the guest's `/v1` API (an input action is
//!   `POST /v1/actions`, `subprocess.run` is `POST /v1/exec`, `pyperclip.copy` is
//!   `PUT /v1/clipboard`, ...). The interpreter is synchronous, so a script runs on
//!   a blocking worker thread and reaches the async client through the runtime's [`Handle`];
//! - pyautogui code under [`PyautoguiPolicy::TranslateOnly`] is translated whole by
//!   the `pyautogui` action space (for the guest's screen and cursor: [`pointer`])
//!   and its steps carried out by [`perform_steps`]: input and the clipboard only;
//! - under [`PyautoguiPolicy::InputOnly`] (a setup step's `python -c`) code that is
//!   input alone is one typed batch and any other code is left to the caller
//!   ([`perform_input_only`]).
//!
//! Failures are sorted in two: what the agent did wrong or the desktop refused
//! (a Python exception, code that does not translate, an unknown key, a program
//! that is not installed) is recorded in [`ActionOutcome::error`] and the episode
//! goes on, as upstream's `/execute_windows` answers 500 and the runner carries
//! on; a guest [out of reach](arena_client::ClientError::out_of_reach) is an
//! [`ExecError::Guest`], an infrastructure error.
//!
//! Deliberate differences from upstream:
//! - `computer.clipboard.copy_image(id)` crops a fresh screenshot (without the
//!   cursor) instead of the one the agent observed; nothing else changed between
//!   the two unless the script moved things first.
//! - Environment variables are read by running `cmd.exe /d /c echo %NAME%` on the
//!   guest, so they need a Windows guest; on the stub they are unset.
//!
//! [`GuestHost`] (module `guest_host`) implements only the primitives (capture, input, windows, files,
//! processes, registry, clipboard, environment); every behaviour made of them (the
//! window list, `switch_to_application`, `open_program`, `platform.version()`, saved
//! screenshots, crops, command lines) is `arena_script::compose`'s, the same
//! code the guest's own script host runs, so code gives the same result whether it
//! runs here or in the guest's `/execute`.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

use serde::{Deserialize, Serialize};
use tokio::runtime::Handle;

use arena_actionspace::{ActionSpace, Context, Coords, Step};
use arena_client::client::GuestClient;
use arena_client::error::ClientError;
use arena_script::{run, ComputerState, Globals, ScriptError, Stop};
use arena_shared::action::{Action, ActionBatch};
use arena_shared::clipboard::ClipboardContent;
use arena_shared::geometry::Point;
use arena_shared::keys::HeldKeys;

use crate::guest_host::GuestHost;
use crate::options::{Boxes, ExecOptions, PyautoguiPolicy};
use crate::AgentAction;

/// Why an action could not be carried out at all: an infrastructure failure, never the agent's.
#[derive(Debug, thiserror::Error)]
pub enum ExecError {
    /// The guest is out of reach ([`ClientError::out_of_reach`]).
    #[error(transparent)]
    Guest(#[from] ClientError),
    /// The worker thread that ran a script died.
    #[error("the script worker failed: {0}")]
    Worker(String),
}

/// What carrying out one action did.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct ActionOutcome {
    /// What the script printed.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub stdout: String,
    /// Why the action failed: a Python exception (`NameError: ...`), a refused
    /// input action, or printed text containing "error" (upstream's
    /// `/execute_windows` rule). Effects before the failure are not undone.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// The cursor after the last input action, when one was sent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cursor: Option<Point>,
    /// How many input actions were sent to the guest.
    pub performed: usize,
    pub elapsed_ms: u64,
    /// Keys the action pressed with `keyDown` (the episode lets them all go at its end).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub keys_down: Vec<String>,
}

/// Carries out `action` on the guest with upstream's timings ([`ExecOptions::default`]).
///
/// `marks` (the Set-of-Marks boxes, when given) become the `computer` state's `rects` with
/// `window_rect = [0, 0, W, H]` and scale 1, as Navi's `/update_computer`;
/// `computer` keeps the clipboard text and the rest across steps.
/// `WAIT`, `DONE` and `FAIL` do nothing here: pausing and stopping are the episode's business.
///
/// # Errors
///
/// [`ExecError::Guest`] when the guest cannot be reached (connection refused,
/// no answer in time, a broken transfer); [`ExecError::Worker`] if the script
/// thread died. Everything else is an [`ActionOutcome::error`].
pub async fn execute(
    client: &GuestClient,
    action: &AgentAction,
    marks: Option<Boxes<'_>>,
    computer: &mut ComputerState,
) -> Result<ActionOutcome, ExecError> {
    execute_with(client, action, marks, computer, &ExecOptions::default()).await
}

/// [`execute`] with explicit [`ExecOptions`].
///
/// # Errors
///
/// As [`execute`].
pub async fn execute_with(
    client: &GuestClient,
    action: &AgentAction,
    marks: Option<Boxes<'_>>,
    computer: &mut ComputerState,
    options: &ExecOptions,
) -> Result<ActionOutcome, ExecError> {
    let started = Instant::now();
    if let Some(marks) = marks {
        apply_marks(computer, marks);
    }
    let mut outcome = match action {
        AgentAction::Wait | AgentAction::Done | AgentAction::Fail => ActionOutcome::default(),
        AgentAction::Typed(actions) => typed(client, actions, options.release_held_keys).await?,
        AgentAction::Clipboard(text) => clipboard(client, text).await?,
        AgentAction::Computer(code) => run_script(client, code, Lang::Computer, computer, options).await?,
        AgentAction::Pyautogui(code) => match options.pyautogui {
            PyautoguiPolicy::Effects => run_script(client, code, Lang::Pyautogui, computer, options).await?,
            PyautoguiPolicy::TranslateOnly => pyautogui(client, code, options).await?,
            PyautoguiPolicy::InputOnly => match perform_input_only(client, code, options.coords).await {
                Ok(InputOnly::Performed { actions, cursor }) => {
                    ActionOutcome { performed: actions, cursor: Some(cursor), ..ActionOutcome::default() }
                }
                Ok(InputOnly::NotInput(why)) => refused(why),
                Err(err) if err.out_of_reach() => return Err(ExecError::Guest(err)),
                Err(err) => refused(err.to_string()),
            },
        },
    };
    outcome.elapsed_ms = u64::try_from(started.elapsed().as_millis()).unwrap_or(u64::MAX);
    Ok(outcome)
}

/// An outcome that did nothing because of `error`.
fn refused(error: String) -> ActionOutcome {
    ActionOutcome { error: Some(error), ..ActionOutcome::default() }
}

/// pyautogui code: translated whole by the `pyautogui` action space for the guest's
/// screen and cursor, in the run's (or the agent's) coordinate convention, then
/// carried out step by step. Code that does not translate does nothing; the
/// translation's error is the outcome's.
async fn pyautogui(client: &GuestClient, code: &str, options: &ExecOptions) -> Result<ActionOutcome, ExecError> {
    let ctx = match pointer(client, options.coords).await {
        Ok(ctx) => ctx,
        Err(err) if err.out_of_reach() => return Err(ExecError::Guest(err)),
        Err(err) => return Ok(refused(format!("reading the screen and the cursor for the pyautogui code: {err}"))),
    };
    match translate_pyautogui(code, &ctx) {
        Ok(steps) => perform_steps(client, &steps, options).await,
        Err(err) => Ok(refused(err)),
    }
}

/// pyautogui code as steps, through the one entry point of the action spaces.
///
/// # Errors
///
/// The action space's error, naming the code and what does not translate.
pub fn translate_pyautogui(code: &str, ctx: &Context) -> Result<Vec<Step>, String> {
    arena_actionspace::parse(ActionSpace::Pyautogui, &serde_json::Value::String(code.to_owned()), ctx)
        .map_err(|err| err.to_string())
}

/// What [`perform_input_only`] did.
#[derive(Debug, Clone, PartialEq)]
pub enum InputOnly {
    /// The code was input alone, sent as one batch of `actions` input actions.
    Performed { actions: usize, cursor: Point },
    /// The code does more than input (or does not translate): nothing was done; why.
    NotInput(String),
}

/// pyautogui code carried out as one typed batch when it is input alone
/// ([`PyautoguiPolicy::InputOnly`]): translated by the `pyautogui` action space
/// for the guest's screen and cursor, in `coords`. Code that asks for anything
/// else (the clipboard, a screenshot, files, processes) or does not translate is
/// [`InputOnly::NotInput`] and nothing is sent.
///
/// # Errors
///
/// The guest's screen or cursor cannot be read, or it refused the batch.
pub async fn perform_input_only(client: &GuestClient, code: &str, coords: Coords) -> Result<InputOnly, ClientError> {
    let ctx = pointer(client, coords).await?;
    let steps = match translate_pyautogui(code, &ctx) {
        Ok(steps) => steps,
        Err(why) => return Ok(InputOnly::NotInput(why)),
    };
    let mut actions = Vec::with_capacity(steps.len());
    for step in steps {
        match step {
            Step::Act(action) => actions.push(action),
            other => {
                return Ok(InputOnly::NotInput(format!("the code asks for {other:?}, which is not an input action")))
            }
        }
    }
    let n = actions.len();
    let report = client.act(&ActionBatch { actions }).await?;
    Ok(InputOnly::Performed { actions: n, cursor: report.cursor })
}

/// What pyautogui code is translated against on the guest behind `client`: its
/// [`GuestClient::pointer`] (the screen in the coordinate space its input uses, the
/// cursor) and `coords`.
///
/// # Errors
///
/// The guest's screen or cursor cannot be read.
pub async fn pointer(client: &GuestClient, coords: Coords) -> Result<Context, ClientError> {
    let (screen, cursor) = client.pointer().await?;
    Ok(Context { screen, cursor, coords })
}

/// Carries out an action space's steps in order: runs of input actions as one
/// batch each, a clipboard write as `PUT /v1/clipboard`. Decisions and the requests
/// only an agent answers (screenshot, cursor, zoom) do nothing here. Waits are
/// scaled by [`ExecOptions::sleep_scale`], and steps whose waits add up past
/// [`ExecOptions::max_duration`] are refused before anything is done. The first
/// step the guest refuses ends the run; its error is the outcome's.
///
/// # Errors
///
/// [`ExecError::Guest`] when the guest is out of reach.
pub async fn perform_steps(
    client: &GuestClient,
    steps: &[Step],
    options: &ExecOptions,
) -> Result<ActionOutcome, ExecError> {
    let scale = options.sleep_scale.max(0.0);
    let mut waited = 0.0f64;
    let steps: Vec<Step> = steps
        .iter()
        .map(|step| match step {
            Step::Act(Action::Wait { ms }) => {
                let scaled = (*ms as f64 * scale).round();
                waited += scaled;
                // The cast saturates for absurd values, refused just below.
                Step::Act(Action::Wait { ms: scaled as u64 })
            }
            other => other.clone(),
        })
        .collect();
    if waited > options.max_duration.as_secs_f64() * 1000.0 {
        return Ok(refused(format!(
            "the code waits {} s in all, past the action's {} s limit",
            (waited / 1000.0).round(),
            options.max_duration.as_secs()
        )));
    }
    let mut outcome = ActionOutcome::default();
    for action in AgentAction::from_steps(&steps) {
        let part = match &action {
            AgentAction::Typed(actions) => typed(client, actions, options.release_held_keys).await?,
            AgentAction::Clipboard(text) => clipboard(client, text).await?,
            _ => continue,
        };
        outcome.performed += part.performed;
        outcome.cursor = part.cursor.or(outcome.cursor);
        for key in part.keys_down {
            if !outcome.keys_down.contains(&key) {
                outcome.keys_down.push(key);
            }
        }
        if part.error.is_some() {
            outcome.error = part.error;
            break;
        }
    }
    Ok(outcome)
}

/// Puts `text` on the guest's clipboard (one `PUT /v1/clipboard`).
async fn clipboard(client: &GuestClient, text: &str) -> Result<ActionOutcome, ExecError> {
    match client.clipboard_set(&ClipboardContent::Text { text: text.to_owned() }).await {
        Ok(()) => Ok(ActionOutcome::default()),
        Err(err) if err.out_of_reach() => Err(ExecError::Guest(err)),
        Err(err) => Ok(refused(err.to_string())),
    }
}

/// Navi's `/update_computer` from the Set-of-Marks: the element boxes, the whole
/// screen as the view, and scale 1. `current_id` is forgotten when the boxes change.
fn apply_marks(computer: &mut ComputerState, marks: Boxes<'_>) {
    if computer.rects != marks.rects {
        computer.rects = marks.rects.to_vec();
        computer.current_id = None;
    }
    let (w, h) = marks.size;
    computer.window_rect = [0, 0, i32::try_from(w).unwrap_or(i32::MAX), i32::try_from(h).unwrap_or(i32::MAX)];
    computer.scale = (1.0, 1.0);
}

async fn typed(client: &GuestClient, actions: &[Action], release: bool) -> Result<ActionOutcome, ExecError> {
    // By default a key a typed batch holds stays held into the next step (upstream's
    // computer_13 KEY_DOWN, CLICK, KEY_UP are three steps) and the episode lets it go
    // at its end; with `release` the batch lets go of it itself.
    let mut batch = actions.to_vec();
    if release {
        let mut held = HeldKeys::default();
        actions.iter().for_each(|a| held.track(a));
        batch.extend(held.releases());
    }
    match client.act(&ActionBatch { actions: batch }).await {
        Ok(report) => {
            // The releases appended above are not the agent's actions.
            let performed = report.executed.min(actions.len());
            Ok(ActionOutcome {
                cursor: Some(report.cursor),
                performed,
                keys_down: keys_down(&actions[..performed]),
                ..ActionOutcome::default()
            })
        }
        Err(err) if err.out_of_reach() => Err(ExecError::Guest(err)),
        Err(err) => Ok(refused(err.to_string())),
    }
}

/// Sets a script's cancel flag when dropped (see `run_script`).
struct CancelOnDrop(Arc<AtomicBool>);

impl Drop for CancelOnDrop {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Relaxed);
    }
}

/// Which code [`run_script`] runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Lang {
    /// Navi's `computer.*` code, with `computer` bound (upstream's `/execute_windows`).
    Computer,
    /// pyautogui code with its effects (the default), with `pyautogui` and
    /// `time` imported (upstream's `python -c`).
    Pyautogui,
}

/// Code run on the host against [`GuestHost`].
async fn run_script(
    client: &GuestClient,
    code: &crate::action::Code,
    lang: Lang,
    computer: &mut ComputerState,
    options: &ExecOptions,
) -> Result<ActionOutcome, ExecError> {
    // The program the agent's reply check kept, else the text parsed now.
    let mut program = match code.program() {
        Ok(program) => program,
        Err(err) => return Ok(refused(format!("SyntaxError: {err}"))),
    };
    if lang == Lang::Pyautogui && options.coords != Coords::Pixels {
        let screen = match client.pointer().await {
            Ok((screen, _)) => screen,
            Err(err) if err.out_of_reach() => return Err(ExecError::Guest(err)),
            Err(err) => {
                let error = format!("reading the screen size to rescale {} coordinates: {err}", options.coords.name());
                return Ok(refused(error));
            }
        };
        arena_actionspace::pyautogui::rescale(&mut program, options.coords, screen);
    }
    let mut host = GuestHost::new(client.clone(), Handle::current(), options.clone());
    let mut state = computer.clone();
    let delay = options.computer_action_delay;
    // The interpreter stops at the script's deadline, and when this step is dropped
    // (the episode cancelled) the flag stops the code still running on its thread.
    let cancel = Arc::new(AtomicBool::new(false));
    let stop = Stop::new(Some(Instant::now() + options.max_duration), Some(Arc::clone(&cancel)));
    let _cancel_on_drop = CancelOnDrop(cancel);
    let (result, state, mut host) = tokio::task::spawn_blocking(move || {
        let globals = match lang {
            Lang::Computer => {
                Globals { computer: Some(&mut state), computer_action_delay: delay, preimport: &[], stop, memory: None }
            }
            Lang::Pyautogui => Globals {
                computer: None,
                computer_action_delay: delay,
                preimport: &["pyautogui", "time"],
                stop,
                memory: None,
            },
        };
        let result = run(&program, &mut host, globals);
        (result, state, host)
    })
    .await
    .map_err(|err| ExecError::Worker(err.to_string()))?;
    *computer = state;
    // With --held-keys action, a key the code left held (a keyDown without its keyUp,
    // or code that stopped between the two) is let go now; by default it stays held
    // into the next step, as upstream's, and the episode lets it go at its end.
    let releases = if options.release_held_keys { host.held.releases() } else { Vec::new() };
    if !releases.is_empty() && host.unreachable.is_none() {
        if let Err(err) = client.act(&ActionBatch { actions: releases }).await {
            if err.out_of_reach() {
                return Err(ExecError::Guest(err));
            }
            tracing::warn!(error = %err, "releasing the keys the agent's code left held failed");
        }
    }
    if let Some(err) = host.unreachable {
        // The script stopped at the first call that found the guest gone
        // (`ErrorKind::Unreachable`); the client's error says how.
        return Err(ExecError::Guest(err));
    }
    let mut outcome = ActionOutcome {
        cursor: host.cursor,
        performed: host.performed,
        keys_down: std::mem::take(&mut host.keys_down),
        ..ActionOutcome::default()
    };
    match result {
        Ok(out) => {
            // Upstream's /execute_windows fails a call whose printed output mentions
            // "error" (open_program's "error: Program X is not installed").
            if lang == Lang::Computer && out.stdout.to_lowercase().contains("error") {
                outcome.error = Some(out.stdout.trim_end().to_owned());
            }
            outcome.stdout = out.stdout;
        }
        Err(err) => {
            outcome.error = Some(script_error(&err));
            outcome.stdout = err.stdout;
        }
    }
    Ok(outcome)
}

/// The keys `actions` press with `keyDown`, each once, in order.
fn keys_down(actions: &[Action]) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    for action in actions {
        if let Action::KeyDown { key } = action {
            if !out.contains(key) {
                out.push(key.clone());
            }
        }
    }
    out
}

fn script_error(err: &ScriptError) -> String {
    if err.line > 0 {
        format!("line {}: {}", err.line, err.python_message())
    } else {
        err.python_message()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn marks_set_the_computer_state_as_update_computer_does() {
        let mut state = ComputerState::for_screen(10, 10);
        state.current_id = Some(0);
        state.clipboard_content = Some("kept".into());
        let rects = [[1, 2, 3, 4]];
        let marks = Boxes { rects: &rects, size: (1920, 1080) };
        apply_marks(&mut state, marks);
        assert_eq!(state.rects, vec![[1, 2, 3, 4]]);
        assert_eq!(state.window_rect, [0, 0, 1920, 1080]);
        assert_eq!(state.current_id, None);
        assert_eq!(state.clipboard_content.as_deref(), Some("kept"));
        state.current_id = Some(0);
        apply_marks(&mut state, marks);
        assert_eq!(state.current_id, Some(0), "the same boxes keep the current id");
    }
}
