//! OmniParser for the `omni` and `mixed-omni` proposals, through the HTTP
//! server OmniParser publishes (`omnitool/omniparserserver`, a FastAPI app).
//!
//! `POST {omniparser-url}/parse/` with `{"base64_image": "<the screenshot, base64 PNG>"}`
//! answers `{"som_image_base64", "parsed_content_list", "latency"}`, where each
//! parsed element is `{"type": "text" | "icon", "bbox": [x1, y1, x2, y2],
//! "interactivity": bool, "content": str | null, ...}` with the corners as
//! fractions of the image's width and height. Its own annotated image is not used.
//!
//! Each element becomes an entity as upstream's `Omniparser.propose_ents`
//! makes one: the type as given, the corners converted to pixels, and x, y,
//! width and height each truncated to an integer, the text the element's
//! content (an uncaptioned icon has an empty text). Upstream lists the OCR
//! text entities before the icons; the order is kept within each group.

use base64::Engine as _;
use serde::{Deserialize, Serialize};

use arena_shared::geometry::Rect;

use super::{ProposedEntity, SomError};

/// The request body of `POST /parse/`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParseRequest {
    pub base64_image: String,
}

/// One element of `parsed_content_list`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParsedElement {
    #[serde(rename = "type")]
    pub kind: String,
    /// `[x1, y1, x2, y2]` as fractions of the image's size.
    pub bbox: [f64; 4],
    #[serde(default)]
    pub interactivity: bool,
    #[serde(default)]
    pub content: Option<String>,
}

/// The answer of `POST /parse/` (the fields this client reads).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParseResponse {
    #[serde(default)]
    pub som_image_base64: Option<String>,
    pub parsed_content_list: Vec<ParsedElement>,
    #[serde(default)]
    pub latency: Option<f64>,
}

/// The endpoint for a base URL (a trailing `/` is allowed).
pub fn endpoint(base_url: &str) -> String {
    format!("{}/parse/", base_url.trim().trim_end_matches('/'))
}

/// The elements as entities in pixels of an image of `dims` (module doc).
pub fn to_entities(elements: &[ParsedElement], (w, h): (u32, u32)) -> Vec<ProposedEntity> {
    let (w, h) = (f64::from(w), f64::from(h));
    let entity = |e: &ParsedElement| {
        let [x1, y1, x2, y2] = e.bbox;
        // Python's int(): truncation (a float `as` conversion also saturates).
        let int = |v: f64| v.trunc() as i32;
        // Sizes from the pixel corners, so 0.6 - 0.5 of 600 is 60, not 59.
        let rect = Rect::new(int(x1 * w), int(y1 * h), int(x2 * w - x1 * w), int(y2 * h - y1 * h));
        ProposedEntity::new(&e.kind, rect, Some(e.content.clone().unwrap_or_default()))
    };
    let texts = elements.iter().filter(|e| e.kind == "text");
    let others = elements.iter().filter(|e| e.kind != "text");
    texts.chain(others).map(entity).collect()
}

/// Asks OmniParser's server at `base_url` to parse the PNG `png` (of `dims` pixels).
///
/// # Errors
///
/// [`SomError::Service`] when the server is unreachable, answers with an error
/// status, or answers out of shape.
pub async fn parse(
    http: &reqwest::Client,
    base_url: &str,
    png: &[u8],
    dims: (u32, u32),
) -> Result<Vec<ProposedEntity>, SomError> {
    let url = endpoint(base_url);
    let fail = |reason: String| SomError::Service { service: "OmniParser", url: url.clone(), reason };
    let body = ParseRequest { base64_image: base64::engine::general_purpose::STANDARD.encode(png) };
    let response = http.post(&url).json(&body).send().await.map_err(|e| fail(e.to_string()))?;
    let status = response.status();
    if !status.is_success() {
        let text = response.text().await.unwrap_or_default();
        return Err(fail(format!("HTTP {status}: {}", text.chars().take(300).collect::<String>())));
    }
    let answer: ParseResponse =
        response.json().await.map_err(|e| fail(format!("the answer is not OmniParser's shape: {e}")))?;
    Ok(to_entities(&answer.parsed_content_list, dims))
}
