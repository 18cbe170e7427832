//! The one observation builder: what the harness writes to `traj.jsonl`, what
//! every agent is given and what the tests check are made here and only here.
//!
//! [`observe`] reads the guest the way upstream's `_get_obs` does
//! (`desktop_env.py` at 6d39ed88, waa-api.md §b.5): a full-screen screenshot
//! without the cursor (upstream's frames come from QEMU), the accessibility
//! tree (left out, as upstream's `None`, when it cannot be read), the window
//! list and title by [`arena_shared::window_list`] (upstream's rule: visible,
//! titled, minimised included, each title once, topmost first; `Desktop` for
//! Program Manager or an untitled foreground), the clipboard, and the browser's
//! DOM elements when the agent's Set-of-Marks origin needs them.
//!
//! The screenshot is decoded once, here, into a [`Frame`]; later stages (the
//! Set-of-Marks sources, the annotation, the model's JPEG, the previous
//! step's image) use its pixels, and the guest's own PNG bytes are what is
//! written to the result folder. Encoding happens only at the edges: files,
//! service requests and model requests. `arena_client::frame::decodes_on_this_thread`
//! counts the decodes, so a test can hold a step to one per source image.
//!
//! Each part is timed ([`ObserveTimings`]); the parts run concurrently, so
//! their sum may exceed [`ObserveTimings::total_ms`].

use std::sync::Arc;
use std::time::{Duration, Instant};

use arena_shared::clipboard::ClipboardContent;
use arena_shared::observation::{A11yQuery, ImageFormat, ScreenInfo, ScreenshotQuery};
use arena_shared::window_list;

use super::Observation;
use arena_client::client::GuestClient;
use arena_client::error::ClientError;
use arena_client::frame::Frame;
use arena_results::timings::ObserveTimings;

/// A guest's screen as seen from outside it (QEMU's screendump of its VM).
#[async_trait::async_trait]
pub trait ScreenSource: Send + Sync {
    /// The display of the VM `guest` (its base URL) runs in, as PNG; `None`
    /// when there is none or it cannot be read.
    async fn screendump(&self, guest: &str) -> Option<Vec<u8>>;
}

/// A run's VMs: QEMU's screendump of the VM a guest runs in.
#[async_trait::async_trait]
impl ScreenSource for arena_vm::fleet::VmFleet {
    async fn screendump(&self, guest: &str) -> Option<Vec<u8>> {
        arena_vm::fleet::VmFleet::screendump(self, guest).await
    }
}

impl std::fmt::Debug for dyn ScreenSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("ScreenSource")
    }
}

/// What an observation reads.
#[derive(Debug, Clone)]
pub struct ObserveConfig {
    /// Whether the accessibility tree is read (upstream's `a11y_tree` observation).
    pub a11y: bool,
    /// Budget of one accessibility-tree walk.
    pub a11y_query: A11yQuery,
    /// Whether the browser's DOM elements are read ([`arena_som::SomOrigin::needs_dom`]).
    pub dom: bool,
    /// The VM's own display, when the run owns its VMs: the screenshot when the
    /// guest's capture fails or is black.
    pub screen_source: Option<Arc<dyn ScreenSource>>,
}

impl Default for ObserveConfig {
    fn default() -> ObserveConfig {
        ObserveConfig { a11y: true, a11y_query: A11yQuery::default(), dom: false, screen_source: None }
    }
}

/// Why no observation could be made: the guest is out of reach, or its screenshot is unusable.
#[derive(Debug, thiserror::Error)]
#[error("{what}: {reason}")]
pub struct ObserveError {
    /// What was being read.
    pub what: &'static str,
    pub reason: String,
}

fn failed(what: &'static str, err: impl std::fmt::Display) -> ObserveError {
    ObserveError { what, reason: err.to_string() }
}

fn ms(d: Duration) -> u64 {
    u64::try_from(d.as_millis()).unwrap_or(u64::MAX)
}

/// Why the guest's screenshot should give way to the VM's display, if it should:
/// a black frame (a lock screen, UAC's secure desktop) or a failed capture of a
/// guest that still answers.
pub(crate) fn fallback_reason(shot: &Result<arena_client::client::Screenshot, ClientError>) -> Option<String> {
    match shot {
        Ok(shot) if shot.meta.black_frame => Some("the guest's screenshot was black".to_owned()),
        Ok(_) => None,
        Err(err) if err.out_of_reach() => None,
        Err(err) => Some(format!("the guest's screenshot failed: {err}")),
    }
}

/// Runs `part` and answers its result and how long it took.
async fn timed<T>(part: impl std::future::Future<Output = T>) -> (T, u64) {
    let started = Instant::now();
    let value = part.await;
    (value, ms(started.elapsed()))
}

/// Observes the guest behind `client` for step `step`. The screenshot and the
/// window list are required; the tree, the clipboard and the DOM are left out
/// when they cannot be read, unless the guest is out of reach.
///
/// # Errors
///
/// [`ObserveError`] when the guest is out of reach, or the screenshot or the
/// window list cannot be had or decoded.
pub async fn observe(
    client: &GuestClient,
    config: &ObserveConfig,
    screen: &ScreenInfo,
    step: u32,
    instruction: &str,
) -> Result<Observation, ObserveError> {
    let started = Instant::now();
    // Upstream's full-screen frames come from QEMU and carry no cursor.
    let query = ScreenshotQuery { format: ImageFormat::Png, cursor: Some(false), ..ScreenshotQuery::default() };
    // The screenshot is decoded as soon as it is here, while the guest still
    // answers the other questions (the tree takes longest), on this task.
    let screenshot_part = async {
        let (shot, mut screenshot_ms) = timed(client.screenshot(&query)).await;
        let fallback = match (&config.screen_source, fallback_reason(&shot)) {
            (Some(source), Some(reason)) => {
                let (png, took) = timed(source.screendump(client.base_url())).await;
                screenshot_ms += took;
                png.map(|png| (png, reason))
            }
            _ => None,
        };
        let (encoded, source) = match (shot, fallback) {
            (_, Some((png, reason))) => {
                tracing::warn!(step, %reason, "using the VM's display as the screenshot");
                (png, Some(format!("vm-display: {reason}")))
            }
            (Ok(shot), None) => (shot.bytes, None),
            (Err(err), None) => return Err(failed("taking the screenshot", err)),
        };
        let (frame, decode_ms) = timed(async { Frame::decode(encoded) }).await;
        let frame = frame.map_err(|e| failed("decoding the screenshot", e))?;
        Ok((frame, source, screenshot_ms, decode_ms))
    };
    let (shot, (windows, windows_ms), tree, (clipboard, clipboard_ms), dom) = tokio::join!(
        screenshot_part,
        timed(client.windows()),
        async {
            if config.a11y {
                Some(timed(client.a11y(&config.a11y_query)).await)
            } else {
                None
            }
        },
        timed(client.clipboard_get()),
        async {
            if config.dom {
                Some(timed(arena_client::browser::dom_elements(client)).await)
            } else {
                None
            }
        },
    );
    let (screenshot, screenshot_source, screenshot_ms, decode_ms) = shot?;
    let mut timings =
        ObserveTimings { screenshot_ms, decode_ms, windows_ms, clipboard_ms, ..ObserveTimings::default() };
    let windows = windows.map_err(|err| failed("listing windows", err))?;
    let a11y = match tree {
        None => None,
        Some((answer, took)) => {
            timings.tree_ms = Some(took);
            match answer {
                Ok(tree) => Some(tree),
                Err(err) if err.out_of_reach() => return Err(failed("reading the accessibility tree", err)),
                Err(err) => {
                    tracing::warn!(step, error = %err, "no accessibility tree this step");
                    None
                }
            }
        }
    };
    let clipboard = match clipboard {
        Ok(ClipboardContent::Text { text }) => Some(text),
        Ok(_) => None,
        Err(err) if err.out_of_reach() => return Err(failed("reading the clipboard", err)),
        Err(err) => {
            tracing::debug!(error = %err, "no clipboard this step");
            None
        }
    };
    let dom = dom.and_then(|(answer, took)| {
        timings.dom_ms = Some(took);
        match answer {
            Ok(elements) => Some(elements),
            Err(err) => {
                // A task without a browser is no failure.
                tracing::warn!(step, error = %err, "no DOM elements this step");
                None
            }
        }
    });
    timings.total_ms = ms(started.elapsed());
    Ok(Observation {
        step,
        instruction: instruction.to_owned(),
        screenshot,
        screenshot_source,
        screen: screen.clone(),
        a11y,
        window_titles: window_list::window_names(&windows),
        foreground_title: window_list::foreground_title_of(&windows),
        foreground_id: windows.iter().find(|w| w.focused).map(|w| w.id),
        tracked_clipboard: None,
        clipboard,
        dom,
        timings,
    })
}

#[cfg(test)]
mod tests {
    use super::fallback_reason;
    use arena_client::error::ClientError;

    #[test]
    fn the_vm_display_stands_in_for_a_black_or_failed_capture_of_a_guest_that_answers() {
        use arena_client::client::Screenshot;
        use arena_client::error::CallSite;
        use arena_shared::geometry::CoordinateSpace;
        use arena_shared::observation::ScreenshotMeta;
        let shot = |black: bool| -> Result<Screenshot, ClientError> {
            Ok(Screenshot {
                meta: ScreenshotMeta {
                    width: 8,
                    height: 8,
                    physical_width: 8,
                    physical_height: 8,
                    scale: 1.0,
                    format: arena_shared::observation::ImageFormat::Png,
                    coordinate_space: CoordinateSpace::Physical,
                    cursor: None,
                    cursor_drawn: false,
                    black_frame: black,
                    capture_ms: 1,
                },
                bytes: Vec::new(),
            })
        };
        let site = || CallSite { guest: "http://127.0.0.1:1".into(), method: "GET", path: "/v1/screenshot".into() };
        assert_eq!(fallback_reason(&shot(false)), None);
        assert_eq!(fallback_reason(&shot(true)).as_deref(), Some("the guest's screenshot was black"));
        let failed = Err(ClientError::Api {
            call: site(),
            status: 500,
            code: arena_shared::error::ErrorCode::Internal,
            message: "BitBlt failed".into(),
        });
        assert!(fallback_reason(&failed).unwrap().contains("BitBlt failed"));
        // A guest that does not answer is an infrastructure error, not a screen problem.
        let gone = Err(ClientError::Connect { call: site(), reason: "refused".into() });
        assert_eq!(fallback_reason(&gone), None);
    }
}
