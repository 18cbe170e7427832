//! The episode's observation port: what an agent sees ([`observe`], which builds
//! the [`Observation`]). Its action port, the executor of what the agent answers
//! ([`arena_exec::AgentAction`]), is the crate `arena-exec`, below the setup steps
//! that share it.
//!
//! Every agent family meets the guest only through the two: it is handed an
//! [`Observation`] and answers `AgentAction`s; the episode loop (`arena_host::episode`)
//! calls both.
//!
//! It is not an agent (the rest of this crate) and does not decide when a step counts.
//!
//! # Layout
//!
//! - [`observe`]: [`observe::observe`], the one observation builder, its timings and
//!   the VM display that stands in for a failed screenshot ([`observe::ScreenSource`]).

pub mod observe;

use arena_client::browser::DomElement;
use arena_client::client::GuestClient;
use arena_client::frame::Frame;
use arena_shared::observation::{A11yTree, ScreenInfo};

use arena_som::Marks;

pub use observe::{ObserveConfig, ObserveError};

use arena_results::timings::ObserveTimings;

/// What an agent sees at one step; built only by [`observe::observe`], the
/// harness's own builder (tests use it through [`Observation::capture`]).
#[derive(Debug, Clone)]
pub struct Observation {
    /// 1-based step number.
    pub step: u32,
    /// The task's instruction.
    pub instruction: String,
    /// The full-screen screenshot, decoded once ([`Frame`]: the pixels and the bytes as sent).
    pub screenshot: Frame,
    /// Where the screenshot came from when not from the guest (`vm-display: why`).
    pub screenshot_source: Option<String>,
    pub screen: ScreenInfo,
    /// The accessibility tree, when it could be read (its `truncated` flag says whether the budget cut it).
    pub a11y: Option<A11yTree>,
    /// The window names upstream lists ([`arena_shared::window_list::window_names`]).
    pub window_titles: Vec<String>,
    /// The foreground window's title, `Desktop` for Program Manager or an untitled
    /// window ([`arena_shared::window_list::foreground_title`]).
    pub foreground_title: String,
    /// The foreground window's id, when there is one.
    pub foreground_id: Option<u64>,
    /// The clipboard text the agent's `computer` object tracks (what its
    /// `copy_text` put there), which upstream's Navi is shown as
    /// `computer_clipboard`; `None` until its code copies something.
    pub tracked_clipboard: Option<String>,
    /// The clipboard's text, when it holds text.
    pub clipboard: Option<String>,
    /// The browser's front-page DOM elements in screen pixels (upstream Navi's
    /// `webparse` proposals), read only for an agent whose [`Agent::wants_dom`]
    /// is true; `None` otherwise or when no browser answers.
    pub dom: Option<Vec<DomElement>>,
    /// How long each part took.
    pub timings: ObserveTimings,
}

impl Observation {
    /// The screen's size in physical pixels, which the tree's rectangles use.
    pub fn screen_size(&self) -> (u32, u32) {
        (self.screen.physical_width, self.screen.physical_height)
    }

    /// The Set-of-Marks boxes of this observation, when it has a tree.
    pub fn marks(&self) -> Option<Marks> {
        self.a11y.as_ref().map(|tree| arena_som::marks_from_tree(tree, self.screen_size()))
    }

    /// The harness's observation ([`observe::observe`] with the default
    /// [`ObserveConfig`]: tree read, no DOM), after reading the screen.
    ///
    /// # Errors
    ///
    /// [`ObserveError`] when the screen, the screenshot or the window list cannot be read.
    pub async fn capture(client: &GuestClient, step: u32, instruction: &str) -> Result<Observation, ObserveError> {
        let screen = client
            .screen()
            .await
            .map_err(|err| ObserveError { what: "reading the screen", reason: err.to_string() })?;
        observe::observe(client, &ObserveConfig::default(), &screen, step, instruction).await
    }
}
