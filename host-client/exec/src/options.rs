//! What the executor is handed besides the action: how scripts run and how
//! pyautogui code is carried out ([`ExecOptions`], [`PyautoguiPolicy`]), and the
//! Set-of-Marks boxes Navi's `computer` object takes ([`Boxes`]).

use std::time::Duration;

use arena_actionspace::Coords;

/// How scripts are run.
#[derive(Debug, Clone, PartialEq)]
pub struct ExecOptions {
    /// Multiplies every sleep a script asks for (1.0 in real runs; 0.0 makes tests fast).
    pub sleep_scale: f64,
    /// Seconds slept after each `computer.*` call (upstream: 0.25).
    pub computer_action_delay: f64,
    /// Longest a script may run; a sleep past it stops the script (upstream's client gives up after 90 s).
    pub max_duration: Duration,
    /// Let go of keys an action leaves held (`keyDown` without `keyUp`) when that
    /// action ends, instead of at the end of the episode (`--held-keys action`).
    pub release_held_keys: bool,
    /// What the coordinates of pyautogui code are measured in (`--coords`): every
    /// pyautogui answer, from any agent, is read in this convention, whichever
    /// [`PyautoguiPolicy`] carries it out. A prediction may name its own (the
    /// host's `Prediction::coords`).
    pub coords: Coords,
    /// How pyautogui code is carried out.
    pub pyautogui: PyautoguiPolicy,
}

/// How pyautogui code is carried out: the one choice each caller of the executor names.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PyautoguiPolicy {
    /// With its effects (agents' default, as upstream's `python -c` runs it): in
    /// the host's interpreter against [`GuestHost`], files, processes and
    /// screenshots through the guest's API.
    #[default]
    Effects,
    /// Translated by the `pyautogui` action space (`--pyautogui-translate-only`):
    /// input and the clipboard only; code reaching for anything else is the step's error.
    TranslateOnly,
    /// Carried out only when it is input alone, as one typed batch (a setup step's
    /// `python -c`); other code is refused here, and [`perform_input_only`] tells
    /// its caller so, which then runs the command on the guest as upstream does.
    InputOnly,
}

impl Default for ExecOptions {
    fn default() -> ExecOptions {
        ExecOptions {
            sleep_scale: 1.0,
            computer_action_delay: 0.25,
            max_duration: Duration::from_secs(90),
            release_held_keys: false,
            coords: Coords::Pixels,
            pyautogui: PyautoguiPolicy::Effects,
        }
    }
}

impl ExecOptions {
    /// No sleeping at all: for tests and the stub.
    pub fn instant() -> ExecOptions {
        ExecOptions { sleep_scale: 0.0, computer_action_delay: 0.0, ..ExecOptions::default() }
    }
}

/// The Set-of-Marks boxes of an observation, as Navi's `computer` object takes them:
/// one rectangle `[left, top, right, bottom]` per element id, on a screen of `size`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Boxes<'a> {
    pub rects: &'a [[i32; 4]],
    pub size: (u32, u32),
}
