//! The DOM elements of the browser's front page in screen pixels, as upstream
//! Navi's `webparse` proposer offers them: [`dom_elements`].
//!
//! Which elements (facts carried over from upstream's proposer): links and
//! areas with an `href`, enabled form controls and buttons, iframes, videos,
//! SVG icons, and anything with a `tabindex` (not `-1`), `contenteditable`, a
//! `role`, an `aria-label` or an `onclick`, shadow roots included; an element
//! counts only where it is not covered (the element at the centre of one of
//! its boxes is it or inside it), and only the innermost of nested ones stay.
//! An element's box is that of its first non-blank text, else its first
//! uncovered box; its text is that text, else a short HTML description.
//! The script that finds them is `dom_elements.js`, our own.
//!
//! Where on the screen: upstream finds the page's screenshot inside the
//! screen's by feature matching (OpenCV KAZE) and scales the page's
//! normalised boxes into that region. Here the page says where its window is
//! (`screenX`/`screenY`, the frame from `outerWidth - innerWidth` and the
//! toolbar height from `outerHeight - innerHeight`, in device-independent
//! pixels) and [`WindowGeometry::to_screen`] multiplies by `devicePixelRatio`,
//! so no image matching is needed and a covered browser window still maps.
//! A page zoomed away from 100 % changes `devicePixelRatio` too, and is not
//! told apart from display scaling.

use serde::Deserialize;
use serde_json::Value;

use arena_shared::geometry::Rect;

use super::cdp::{page_targets, CdpError, CdpSession};
use crate::client::GuestClient;

/// The extraction script.
pub(crate) const DOM_SCRIPT: &str = include_str!("dom_elements.js");

/// One element upstream's `webparse` would propose, in screen pixels.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DomElement {
    /// Where it is on the screen (physical pixels).
    pub rect: Rect,
    /// Its first text, or a short HTML description when it has none.
    pub text: String,
    /// Its tag name, upper case (`A`, `BUTTON`, `INPUT`).
    pub kind: String,
}

/// Where the page's window is, as the page reports it.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct WindowGeometry {
    #[serde(rename = "screenX")]
    pub screen_x: f64,
    #[serde(rename = "screenY")]
    pub screen_y: f64,
    pub outer_width: f64,
    pub outer_height: f64,
    pub inner_width: f64,
    pub inner_height: f64,
    pub device_pixel_ratio: f64,
}

impl WindowGeometry {
    /// The screen rectangle of a box given in CSS pixels of the viewport.
    ///
    /// The viewport's left edge is the window's plus half the width the frame
    /// takes (`(outer - inner) / 2`, the left border); its top is the window's
    /// plus everything above the page (`outer - inner` height, less the bottom
    /// border, taken equal to the side one). A headless page reports an outer
    /// size no larger than the inner one: no frame.
    pub fn to_screen(&self, left: f64, top: f64, right: f64, bottom: f64) -> Rect {
        let scale = if self.device_pixel_ratio.is_finite() && self.device_pixel_ratio > 0.0 {
            self.device_pixel_ratio
        } else {
            1.0
        };
        let border = ((self.outer_width - self.inner_width) / 2.0).max(0.0);
        let above = (self.outer_height - self.inner_height - border).max(0.0);
        let origin_x = self.screen_x + border;
        let origin_y = self.screen_y + above;
        let px = |v: f64| (v * scale).round() as i32;
        Rect::from_ltrb(px(origin_x + left), px(origin_y + top), px(origin_x + right), px(origin_y + bottom))
    }
}

/// What the script answers.
#[derive(Debug, Deserialize)]
struct Extracted {
    window: WindowGeometry,
    items: Vec<RawItem>,
}

#[derive(Debug, Deserialize)]
struct RawItem {
    left: f64,
    top: f64,
    right: f64,
    bottom: f64,
    #[serde(default)]
    text: String,
    #[serde(default)]
    kind: String,
}

/// The elements of the script's answer, placed on the screen.
///
/// # Errors
///
/// [`CdpError::Decode`] when the answer is not the script's shape.
pub fn elements_from(answer: Value) -> Result<Vec<DomElement>, CdpError> {
    let extracted: Extracted = serde_json::from_value(answer)
        .map_err(|err| CdpError::Decode { what: "the DOM extraction's answer".into(), reason: err.to_string() })?;
    let window = extracted.window;
    Ok(extracted
        .items
        .into_iter()
        .map(|item| DomElement {
            rect: window.to_screen(item.left, item.top, item.right, item.bottom),
            text: item.text,
            kind: item.kind,
        })
        .filter(|element| !element.rect.is_empty())
        .collect())
}

/// The DOM elements of the browser's front page (the most recently active
/// page target), in screen pixels.
///
/// # Errors
///
/// [`CdpError::Http`] when no browser answers on the guest's debugging port,
/// [`CdpError::NoPage`] without a page, and the session's errors.
pub async fn dom_elements(client: &GuestClient) -> Result<Vec<DomElement>, CdpError> {
    let targets = page_targets(client).await?;
    let target =
        targets.iter().find(|t| t.ws_url.is_some() && !t.url.starts_with("devtools://")).ok_or(CdpError::NoPage)?;
    let session = CdpSession::connect(client, target.ws_url.as_deref().unwrap_or_default()).await?;
    let answer = session.evaluate(DOM_SCRIPT).await;
    session.close().await;
    elements_from(answer?)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn window(screen_x: f64, screen_y: f64, outer: (f64, f64), inner: (f64, f64), dpr: f64) -> WindowGeometry {
        WindowGeometry {
            screen_x,
            screen_y,
            outer_width: outer.0,
            outer_height: outer.1,
            inner_width: inner.0,
            inner_height: inner.1,
            device_pixel_ratio: dpr,
        }
    }

    #[test]
    fn page_boxes_land_below_the_toolbar_at_the_display_scale() {
        // A maximised Chrome on Windows: the frame hangs 8 px off the screen.
        let maximised = window(-8.0, -8.0, (1456.0, 916.0), (1440.0, 781.0), 1.0);
        assert_eq!(maximised.to_screen(10.0, 20.0, 110.0, 40.0), Rect::from_ltrb(10, 139, 110, 159));
        // The same at 150 %: window geometry in DIPs, the screen in physical pixels.
        let scaled = window(100.0, 50.0, (816.0, 616.0), (800.0, 520.0), 1.5);
        assert_eq!(scaled.to_screen(0.0, 0.0, 100.0, 10.0), Rect::from_ltrb(162, 207, 312, 222));
        // Headless: no frame at all.
        let headless = window(0.0, 0.0, (800.0, 600.0), (800.0, 600.0), 1.0);
        assert_eq!(headless.to_screen(5.5, 6.4, 50.0, 60.0), Rect::from_ltrb(6, 6, 50, 60));
    }

    #[test]
    fn the_answer_is_decoded_and_empty_boxes_dropped() {
        let answer = serde_json::json!({
            "window": {"screenX": 0, "screenY": 0, "outerWidth": 800, "outerHeight": 700, "innerWidth": 800, "innerHeight": 600, "devicePixelRatio": 2},
            "title": "t",
            "items": [
                {"left": 1, "top": 2, "right": 11, "bottom": 12, "text": "Go", "kind": "BUTTON"},
                {"left": 5, "top": 5, "right": 5, "bottom": 9, "text": "", "kind": "A"},
            ],
        });
        let elements = elements_from(answer).expect("decoded");
        assert_eq!(
            elements,
            [DomElement { rect: Rect::from_ltrb(2, 204, 22, 224), text: "Go".into(), kind: "BUTTON".into() }]
        );
        assert!(matches!(elements_from(serde_json::json!({"items": 3})), Err(CdpError::Decode { .. })));
    }
}
