//! The icon and image detector of the `oss` proposal: Grounding DINO reached as
//! an HTTP service (the model's weights stay outside this program).
//!
//! # The service
//!
//! `POST {detector-url}/detect` with a JSON body, once per prompt, in upstream's
//! prompt order (`icon`, then `image`):
//!
//! ```json
//! {"image": "<the screenshot, base64 PNG>", "prompt": "icon",
//!  "box_threshold": 0.03, "text_threshold": 0.4}
//! ```
//!
//! The service runs Grounding DINO on the image with the caption as upstream's
//! `get_grounding_output` makes it (lower case, trimmed, ending in `.`), keeps
//! the boxes whose best token score is above `box_threshold`, and answers
//!
//! ```json
//! {"boxes": [{"box": [x1, y1, x2, y2], "score": 0.41, "phrase": "icon"}]}
//! ```
//!
//! with each box in pixels of the image it was sent (corners, floats allowed;
//! `score` and `phrase` are optional and only informational).
//!
//! # What the client does with the boxes (upstream's `det`)
//!
//! Corners are truncated to integers, boxes larger than 5 % of the image are
//! dropped, and the rest are grown by 10 pixels on every side, clamped to the
//! image. Each becomes an entity whose type is the prompt and which has no text.

use base64::Engine as _;
use serde::{Deserialize, Serialize};

use arena_shared::geometry::Rect;

use super::{ProposedEntity, SomError};

/// Upstream's `ScreenParser` prompts, in its order.
pub const PROMPTS: [&str; 2] = ["icon", "image"];

/// The request body of `POST /detect`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DetectRequest {
    /// The image, base64 PNG.
    pub image: String,
    pub prompt: String,
    pub box_threshold: f64,
    pub text_threshold: f64,
}

/// One box of the answer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DetectedBox {
    /// `[x1, y1, x2, y2]` in the sent image's pixels.
    #[serde(rename = "box")]
    pub bbox: [f64; 4],
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub score: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub phrase: Option<String>,
}

/// The answer of `POST /detect`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DetectResponse {
    pub boxes: Vec<DetectedBox>,
}

/// Upstream's `det` thresholds and post-processing.
#[derive(Debug, Clone, PartialEq)]
pub struct DetectorParams {
    pub prompts: Vec<String>,
    pub box_threshold: f64,
    pub text_threshold: f64,
    /// Boxes with more than this share of the image's area are dropped.
    pub max_area_share: f64,
    /// Pixels added on every side of a kept box.
    pub padding: i64,
}

impl Default for DetectorParams {
    fn default() -> DetectorParams {
        DetectorParams {
            prompts: PROMPTS.iter().map(|p| (*p).to_owned()).collect(),
            box_threshold: 0.03,
            text_threshold: 0.4,
            max_area_share: 0.05,
            padding: 10,
        }
    }
}

/// The endpoint for a base URL (a trailing `/` is allowed).
pub fn endpoint(base_url: &str) -> String {
    format!("{}/detect", base_url.trim().trim_end_matches('/'))
}

/// Upstream's post-processing of one prompt's boxes into entities (module doc).
pub fn boxes_to_entities(
    prompt: &str,
    boxes: &[DetectedBox],
    (w, h): (u32, u32),
    p: &DetectorParams,
) -> Vec<ProposedEntity> {
    let (w, h) = (i64::from(w), i64::from(h));
    let limit = p.max_area_share * (w * h) as f64;
    boxes
        .iter()
        .filter(|b| b.bbox.iter().all(|v| v.is_finite()))
        .map(|b| b.bbox.map(|v| v.trunc() as i64))
        .filter(|[x1, y1, x2, y2]| (((x2 - x1) * (y2 - y1)) as f64) <= limit)
        .map(|[x1, y1, x2, y2]| {
            let (x1, y1) = ((x1 - p.padding).max(0), (y1 - p.padding).max(0));
            let (x2, y2) = ((x2 + p.padding).min(w), (y2 + p.padding).min(h));
            let fit = |v: i64| i32::try_from(v).unwrap_or(if v < 0 { i32::MIN } else { i32::MAX });
            ProposedEntity::new(prompt, Rect::new(fit(x1), fit(y1), fit(x2 - x1), fit(y2 - y1)), None)
        })
        .collect()
}

/// Asks the service at `base_url` for every prompt of `params`, in order, and
/// returns the entities in the image's pixels (`dims`: its width and height).
///
/// # Errors
///
/// [`SomError::Service`] when the service is unreachable, answers with an
/// error status, or answers out of shape.
pub async fn detect_all(
    http: &reqwest::Client,
    base_url: &str,
    png: &[u8],
    dims: (u32, u32),
    params: &DetectorParams,
) -> Result<Vec<ProposedEntity>, SomError> {
    let url = endpoint(base_url);
    let fail = |reason: String| SomError::Service { service: "the Grounding DINO detector", url: url.clone(), reason };
    let image = base64::engine::general_purpose::STANDARD.encode(png);
    let mut out = Vec::new();
    for prompt in &params.prompts {
        let body = DetectRequest {
            image: image.clone(),
            prompt: prompt.clone(),
            box_threshold: params.box_threshold,
            text_threshold: params.text_threshold,
        };
        let response = http.post(&url).json(&body).send().await.map_err(|e| fail(e.to_string()))?;
        let status = response.status();
        if !status.is_success() {
            let text = response.text().await.unwrap_or_default();
            return Err(fail(format!("HTTP {status}: {}", text.chars().take(300).collect::<String>())));
        }
        let answer: DetectResponse =
            response.json().await.map_err(|e| fail(format!("the answer is not the documented shape: {e}")))?;
        out.extend(boxes_to_entities(prompt, &answer.boxes, dims, params));
    }
    Ok(out)
}
