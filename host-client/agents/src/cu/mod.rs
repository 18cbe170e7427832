//! The computer-use agents: models that drive a desktop through their vendor's
//! own tool protocol and action grammar, scored unchanged.
//!
//! - [`anthropic`]: [`anthropic::AnthropicAgent`], Anthropic's Messages API with the `computer` tool
//!   or the computer toolset.
//! - [`openai`]: [`openai::OpenAiAgent`], OpenAI's Responses API with `computer_use_preview` or the GA `computer` tool.
//! - [`models`]: which tool form and screenshot size each model gets by default, with sources.
//! - [`uitars`]: [`uitars::UiTarsAgent`], UI-TARS over an OpenAI-compatible chat endpoint (vLLM).
//!
//! All three call their endpoint through [`super::llm::ModelClient`] (backoff,
//! `Retry-After`; a model that stays down is [`AgentError::Model`], which leaves
//! the task unfinished), translate answers with [`arena_actionspace`], and keep
//! each step's request (images left out) and response beside the trajectory as
//! Navi does. A state change is committed only once an answer is read, so the
//! episode may ask again after a failed call.
//!
//! What they see of an [`Observation`] goes through one adapter, [`screen_of`]:
//! the observation's [`Frame`], whose encoded bytes are sent as they came when
//! the model takes the screen's size, and whose decoded pixels are resized or
//! cropped (never decoded again) and encoded by the host's one PNG encoder.

pub mod anthropic;
pub mod models;
pub mod openai;
pub mod uitars;

use std::time::Duration;

use base64::Engine as _;
use serde_json::Value;

use arena_client::frame::{encode_png, Frame};

use super::llm::{ApiKind, ModelClient, RetryPolicy};
use super::{AgentError, LogValue, StepLog};
use crate::observation::Observation;

/// What a computer-use agent takes from an observation: the screenshot's frame
/// and the screen's size in physical pixels (which typed actions use).
pub fn screen_of(obs: &Observation) -> (&Frame, (u32, u32)) {
    (&obs.screenshot, obs.screen_size())
}

/// How to reach a computer-use model (the options every vendor shares).
#[derive(Debug, Clone, PartialEq)]
pub struct Endpoint {
    /// The API's base URL (`https://api.anthropic.com`, `https://api.openai.com/v1`,
    /// `http://127.0.0.1:8000/v1`); each agent adds its route.
    pub base_url: String,
    pub model: String,
    /// The key; `None` reads the agent's variables ([`Endpoint::resolved_key`]).
    pub api_key: Option<String>,
    /// Deadline of one call.
    pub timeout: Duration,
    /// How long a failing model is tried again.
    pub retry: RetryPolicy,
    /// The run's view of the endpoint being down (`--llm-unreachable`), shared by its agents.
    pub down: super::llm::EndpointDown,
    /// Longest answer, in tokens.
    pub max_tokens: u32,
}

impl Endpoint {
    pub fn new(base_url: &str, model: &str) -> Endpoint {
        Endpoint {
            base_url: base_url.to_owned(),
            model: model.to_owned(),
            api_key: None,
            timeout: Duration::from_secs(120),
            retry: RetryPolicy::default(),
            down: super::llm::EndpointDown::default(),
            max_tokens: 4096,
        }
    }

    /// The configured key, else the first non-empty variable of `vars`.
    pub fn resolved_key(&self, vars: &[&str]) -> Option<String> {
        self.api_key
            .clone()
            .filter(|k| !k.is_empty())
            .or_else(|| vars.iter().find_map(|var| std::env::var(var).ok().filter(|v| !v.trim().is_empty())))
    }

    /// `route` appended to the base URL's path unless it already ends with it.
    ///
    /// # Errors
    ///
    /// [`AgentError::Config`] for an empty model name or a base URL that is not a URL.
    pub fn url(&self, route: &str) -> Result<String, AgentError> {
        if self.model.trim().is_empty() {
            return Err(AgentError::Config("the model name must not be empty".into()));
        }
        let mut url = reqwest::Url::parse(self.base_url.trim())
            .map_err(|e| AgentError::Config(format!("the model's base URL {:?} is not a URL: {e}", self.base_url)))?;
        let path = url.path().trim_end_matches('/').to_owned();
        if !path.ends_with(route) {
            url.set_path(&format!("{path}{route}"));
        }
        Ok(url.to_string())
    }
}

impl Endpoint {
    /// The model client for `url`, with the key of `kind`'s header from the
    /// configuration or the first of `key_vars` that is set.
    ///
    /// # Errors
    ///
    /// [`AgentError::Config`] for a URL that does not parse or an HTTP client that cannot be built.
    pub fn client(&self, url: &str, kind: ApiKind, key_vars: &[&str]) -> Result<ModelClient, AgentError> {
        Ok(ModelClient::with_url(url, kind, self.resolved_key(key_vars), self.timeout, self.retry)?
            .with_down(self.down.clone()))
    }
}

/// A PNG as base64.
pub(crate) fn base64_png(png: &[u8]) -> String {
    base64::engine::general_purpose::STANDARD.encode(png)
}

/// `screen` scaled by `scale` (1 at most: a screenshot is never scaled up), each
/// side truncated to whole pixels and at least 1. The one screenshot-size rule the
/// agents that scale share (Anthropic's fallback, OpenAI's bound).
pub(crate) fn scaled_size(screen: (u32, u32), scale: f64) -> (u32, u32) {
    let scale = scale.min(1.0);
    // A hair above the product, so that an exact fit (1440 * 1024/1440) is not cut a pixel short.
    let side = |v: u32| ((f64::from(v.max(1)) * scale + 1e-6) as u32).max(1);
    (side(screen.0), side(screen.1))
}

/// `screen` scaled down, keeping its aspect ratio, to fit within `bound`; as it is when it fits.
pub(crate) fn fit_within(screen: (u32, u32), bound: (u32, u32)) -> (u32, u32) {
    let (w, h) = (f64::from(screen.0.max(1)), f64::from(screen.1.max(1)));
    scaled_size(screen, (f64::from(bound.0) / w).min(f64::from(bound.1) / h))
}

/// The screenshot resized to `size` (width, height), as PNG: the bytes as they
/// came when it already is that size, else its pixels resized and encoded.
///
/// # Errors
///
/// [`AgentError::Config`] when the pixels cannot be resized or encoded (a guest fault the agent cannot fix).
pub(crate) fn resized_png(frame: &Frame, size: (u32, u32)) -> Result<Vec<u8>, AgentError> {
    if frame.size() == size {
        return Ok(frame.encoded.to_vec());
    }
    let bad = |e: String| AgentError::Config(format!("the screenshot: {e}"));
    let scaled =
        arena_shared::fastimg::resize_rgba(&frame.pixels, size.0, size.1, arena_shared::fastimg::Filter::Bilinear)
            .map_err(|e| bad(e.to_string()))?;
    png(&scaled).map_err(bad)
}

/// The region `[x1, y1, x2, y2]` of the screenshot's pixels, as PNG (black where it leaves the image).
///
/// # Errors
///
/// [`AgentError::Config`] when the crop is too large or cannot be encoded.
pub(crate) fn cropped_png(frame: &Frame, rect: [i32; 4]) -> Result<Vec<u8>, AgentError> {
    let bad = |e: String| AgentError::Config(format!("the screenshot: {e}"));
    let crop = arena_shared::imaging::crop_padded(
        &frame.pixels,
        i64::from(rect[0]),
        i64::from(rect[1]),
        i64::from(rect[2]),
        i64::from(rect[3]),
    )
    .map_err(|e| bad(e.to_string()))?;
    png(&crop).map_err(bad)
}

/// Pixels as PNG through the host's one encoder.
fn png(pixels: &image::RgbaImage) -> Result<Vec<u8>, String> {
    let png = encode_png(pixels);
    if png.is_empty() {
        return Err(format!("a {}x{} image cannot be encoded", pixels.width(), pixels.height()));
    }
    Ok(png)
}

/// `value` with every embedded image (base64 `data` of an image source, `data:`
/// URLs) replaced by a note of its size, for the step's logs.
pub(crate) fn without_images(value: &Value) -> Value {
    match value {
        Value::Object(map) => {
            let is_base64_source = map.get("type").and_then(Value::as_str) == Some("base64");
            Value::Object(
                map.iter()
                    .map(|(k, v)| {
                        let v = match v {
                            Value::String(s) if (k == "data" && is_base64_source) || s.starts_with("data:image/") => {
                                Value::String(format!("(an image, {} bytes of base64, left out here)", s.len()))
                            }
                            other => without_images(other),
                        };
                        (k.clone(), v)
                    })
                    .collect(),
            )
        }
        Value::Array(items) => Value::Array(items.iter().map(without_images).collect()),
        other => other.clone(),
    }
}

/// The step's logs: the request as sent (images left out) and the response as received.
pub(crate) fn exchange_logs(request: &Value, response: &Value) -> Vec<StepLog> {
    vec![
        StepLog { key: "request".into(), value: LogValue::Json(without_images(request)) },
        StepLog { key: "response".into(), value: LogValue::Json(response.clone()) },
    ]
}

/// A computer-use agent's prediction. The agent has already scaled its model's
/// coordinates back to the screen, so its actions are in pixels whatever the run's
/// `--coords`; it has no marks and no timings of its own.
pub(crate) fn translated(
    response: String,
    actions: Vec<super::AgentAction>,
    raw_error: Option<String>,
    logs: Vec<StepLog>,
) -> super::Prediction {
    super::Prediction {
        response,
        actions,
        marks: None,
        raw_error,
        logs,
        timings: Default::default(),
        coords: Some(arena_actionspace::Coords::Pixels),
        usage: None,
    }
}

#[cfg(test)]
mod tests {
    use serde_json::json;

    use super::*;

    #[test]
    fn images_are_left_out_of_logs_and_the_rest_is_kept() {
        let request = json!({
            "messages": [{"content": [
                {"type": "image", "source": {"type": "base64", "media_type": "image/png", "data": "AAAA"}},
                {"type": "input_image", "image_url": "data:image/png;base64,BBBB"},
                {"type": "text", "text": "data"},
            ]}]
        });
        let logged = without_images(&request);
        let parts = &logged["messages"][0]["content"];
        assert_eq!(parts[0]["source"]["data"], "(an image, 4 bytes of base64, left out here)");
        assert_eq!(parts[0]["source"]["media_type"], "image/png");
        assert!(parts[1]["image_url"].as_str().unwrap().starts_with("(an image"));
        assert_eq!(parts[2]["text"], "data");
    }

    #[test]
    fn sizes_fit_within_a_bound_keeping_the_aspect_ratio() {
        assert_eq!(fit_within((1440, 900), (1024, 768)), (1024, 640));
        assert_eq!(fit_within((1920, 1080), (1024, 768)), (1024, 576));
        assert_eq!(fit_within((1024, 768), (1024, 768)), (1024, 768));
        assert_eq!(fit_within((800, 600), (1024, 768)), (800, 600), "never scaled up");
        assert_eq!(fit_within((768, 2000), (1024, 768)), (294, 768));
    }

    #[test]
    fn routes_are_added_once() {
        let url = |base: &str, route: &str| Endpoint::new(base, "m").url(route).unwrap();
        assert_eq!(url("https://api.anthropic.com", "/v1/messages"), "https://api.anthropic.com/v1/messages");
        assert_eq!(
            url("https://api.anthropic.com/v1/messages", "/v1/messages"),
            "https://api.anthropic.com/v1/messages"
        );
        assert_eq!(url("https://api.openai.com/v1/", "/responses"), "https://api.openai.com/v1/responses");
        assert!(Endpoint::new("not a url", "m").url("/x").is_err());
        assert!(Endpoint::new("http://h", " ").url("/x").is_err());
    }
}
