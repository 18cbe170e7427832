//! [`OpenAiAgent`]: OpenAI's computer-use models over the Responses API.
//!
//! The protocol is OpenAI's published one (the computer-use guide, the Responses
//! API reference and the `openai` SDK 3.57.0's types): `POST {base}/responses`
//! with a Bearer key and `truncation: "auto"`, and one of two tools:
//!
//! - `computer_use_preview` ([`Form::ComputerUsePreview`]):
//!   `{"type": "computer_use_preview", "display_width", "display_height", "environment": "windows"}`;
//!   each `computer_call` carries one `action`.
//! - the GA `computer` tool ([`Form::Computer`]): `{"type": "computer"}` and nothing
//!   else (`ComputerToolParam`); each `computer_call` carries an `actions` batch,
//!   run in order.
//!
//! - The first request's input is the task and the screenshot; each later one
//!   chains with `previous_response_id` and answers every `computer_call` of the
//!   last answer with one `computer_call_output` holding the new screenshot
//!   (`computer_screenshot`), taken after all the calls' actions ran.
//! - `pending_safety_checks` on a call follow the policy ([`SafetyChecks`],
//!   `--safety-checks`): `ack` carries out the action and acknowledges the checks
//!   in the next `computer_call_output`; `fail` ends the episode as `FAIL`, the
//!   checks recorded in the step's response.
//! - An answer with no `computer_call` ends the episode: `FAIL` when its text says
//!   FAIL (the instructions ask for that word), `DONE` otherwise; a `refusal`
//!   content part is `FAIL`.
//! - Screenshots: the model's limit ([`super::models`]) or `--max-image-side`
//!   decides the size of every screenshot sent: with the preview tool, the declared
//!   `display_width`/`display_height`, at most [`MAX_DISPLAY`] ([`display_size`]);
//!   with the GA tool, the screen as it is when it fits within 2048 px (aspect ratio
//!   kept, by the same resize and coordinate convention the Anthropic agent uses,
//!   `Coords::Image`), and the model's coordinates are scaled back to the screen's.
//!
//! The instructions text is this project's own wording.

use serde_json::{json, Value};

use super::anthropic::ending;
use super::models::{Form, ImageLimit};
use super::{exchange_logs, resized_png, screen_of, Endpoint};
use crate::llm::{ApiKind, ModelClient};
use crate::observation::Observation;
use crate::{Agent, AgentError, Prediction};
use arena_actionspace::{ActionSpace, Context, Coords, Step};
use arena_exec::AgentAction;
use arena_task::Task;

/// Environment variables the key is read from, in order.
pub const KEY_VARS: [&str; 2] = ["ARENA_LLM_KEY", "OPENAI_API_KEY"];

/// The instructions: how to finish, in this project's words.
pub const INSTRUCTIONS: &str =
    "You are operating a Windows 11 desktop with the computer tool to complete the user's task. \
Do not ask for confirmation; act. When the task is complete, answer without a computer action and end with the word \
DONE. If it cannot be done on this computer, answer without a computer action and end with the word FAIL.";

/// The largest display the agent declares to the model. OpenAI's computer-use guide
/// (<https://platform.openai.com/docs/guides/tools-computer-use>, the
/// `computer_use_preview` tool) has the harness declare the display it sends
/// screenshots of, and every example there declares `display_width` 1024 and
/// `display_height` 768, with the browser viewport or virtual screen set to match.
/// The guide names no hard maximum for this model; a larger guest screen is sent at
/// that scale rather than at a size the published setup never uses.
pub const MAX_DISPLAY: (u32, u32) = (1024, 768);

/// The display size declared in the tool for a guest screen, and the size every
/// screenshot is sent at (see [`MAX_DISPLAY`]).
pub fn display_size(screen: (u32, u32)) -> (u32, u32) {
    super::fit_within(screen, MAX_DISPLAY)
}

/// What to do with a call's `pending_safety_checks`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum SafetyChecks {
    /// Acknowledge them and carry on.
    #[default]
    Ack,
    /// End the episode as FAIL.
    Fail,
}

impl SafetyChecks {
    pub fn name(self) -> &'static str {
        match self {
            SafetyChecks::Ack => "ack",
            SafetyChecks::Fail => "fail",
        }
    }
}

/// The OpenAI agent's settings.
#[derive(Debug, Clone, PartialEq)]
pub struct OpenAiConfig {
    pub endpoint: Endpoint,
    pub safety_checks: SafetyChecks,
    /// [`Form::ComputerUsePreview`] or [`Form::Computer`].
    pub tool: Form,
    /// The largest screenshot sent.
    pub image: ImageLimit,
}

impl OpenAiConfig {
    pub fn new(base_url: &str, model: &str) -> OpenAiConfig {
        OpenAiConfig {
            endpoint: Endpoint::new(base_url, model),
            safety_checks: SafetyChecks::default(),
            tool: Form::ComputerUsePreview,
            image: ImageLimit::Display(MAX_DISPLAY.0, MAX_DISPLAY.1),
        }
    }
}

/// A call the next request answers.
#[derive(Debug, Clone, PartialEq)]
struct PendingCall {
    call_id: String,
    acknowledged: Vec<Value>,
}

/// The OpenAI computer-use agent. See the module documentation.
#[derive(Debug)]
pub struct OpenAiAgent {
    config: OpenAiConfig,
    client: ModelClient,
    previous_response_id: Option<String>,
    pending: Vec<PendingCall>,
}

impl OpenAiAgent {
    /// The model client, for `arena run`'s preflight.
    pub fn client(&self) -> &crate::llm::ModelClient {
        &self.client
    }

    /// An agent for `config`; the key is resolved now.
    ///
    /// # Errors
    ///
    /// [`AgentError::Config`] for an unusable URL or model name.
    pub fn new(config: OpenAiConfig) -> Result<OpenAiAgent, AgentError> {
        if config.tool.vendor() != super::models::Vendor::OpenAi {
            return Err(AgentError::Config(format!("{} is not one of OpenAI's computer tools", config.tool.name())));
        }
        let client = config.endpoint.client(&config.endpoint.url("/responses")?, ApiKind::OpenAi, &KEY_VARS)?;
        Ok(OpenAiAgent { config, client, previous_response_id: None, pending: Vec::new() })
    }

    /// The first screenshot's `detail`, which the SDK's `ResponseInputImageParam`
    /// requires: `auto` (what the API assumed when it was left out) with the preview
    /// tool, `high` with the GA tool, whose screenshots the table keeps within the
    /// 2048-pixel box that detail level takes.
    fn image_detail(&self) -> &'static str {
        match self.config.tool {
            Form::Computer => "high",
            _ => "auto",
        }
    }

    /// The `tools` entry of the configured form.
    fn tool(&self, size: (u32, u32)) -> Value {
        match self.config.tool {
            Form::Computer => json!({"type": "computer"}),
            _ => json!({
                "type": "computer_use_preview",
                "display_width": size.0,
                "display_height": size.1,
                "environment": "windows",
            }),
        }
    }
}

#[async_trait::async_trait]
impl Agent for OpenAiAgent {
    fn name(&self) -> &str {
        "openai-cu"
    }

    fn take_usage(&mut self) -> Option<arena_results::ledger::Usage> {
        self.client.take_usage()
    }

    async fn reset(&mut self, _task: &Task) {
        self.previous_response_id = None;
        self.pending.clear();
    }

    async fn predict(&mut self, obs: &Observation) -> Result<Prediction, AgentError> {
        let (frame, screen) = screen_of(obs);
        let size = self.config.image.size_for(screen);
        let image_url = crate::llm::image_data_url("image/png", &resized_png(frame, size)?);
        let input = match (&self.previous_response_id, self.pending.is_empty()) {
            (Some(_), false) => Value::Array(
                self.pending
                    .iter()
                    .map(|call| {
                        json!({
                            "type": "computer_call_output",
                            "call_id": call.call_id,
                            "acknowledged_safety_checks": call.acknowledged,
                            "output": {"type": "computer_screenshot", "image_url": image_url},
                        })
                    })
                    .collect(),
            ),
            _ => json!([{
                "role": "user",
                "content": [
                    {"type": "input_text", "text": obs.instruction},
                    {"type": "input_image", "image_url": image_url, "detail": self.image_detail()},
                ],
            }]),
        };
        let mut body = json!({
            "model": self.config.endpoint.model,
            "instructions": INSTRUCTIONS,
            "tools": [self.tool(size)],
            "input": input,
            "truncation": "auto",
            "max_output_tokens": self.config.endpoint.max_tokens,
        });
        if let (Some(id), false) = (&self.previous_response_id, self.pending.is_empty()) {
            body["previous_response_id"] = json!(id);
        }
        let answer = self.client.call(&body).await?;
        let logs = exchange_logs(&body, &answer);
        let malformed = |why: &str| AgentError::Model {
            endpoint: self.client.endpoint().to_owned(),
            reason: format!("the answer is not a Responses API response: {why}"),
        };
        if let Some(error) = answer.get("error").filter(|e| !e.is_null()) {
            return Err(malformed(&format!("it reports an error: {error}")));
        }
        let id = answer.get("id").and_then(Value::as_str).ok_or_else(|| malformed("no `id`"))?.to_owned();
        let output = answer.get("output").and_then(Value::as_array).ok_or_else(|| malformed("no `output` list"))?;

        let mut text = Vec::new();
        let mut refused = false;
        for item in output.iter().filter(|i| i.get("type").and_then(Value::as_str) == Some("message")) {
            for part in item.get("content").and_then(Value::as_array).into_iter().flatten() {
                match part.get("type").and_then(Value::as_str) {
                    Some("output_text") => text.extend(part.get("text").and_then(Value::as_str)),
                    Some("refusal") => {
                        refused = true;
                        text.extend(part.get("refusal").and_then(Value::as_str));
                    }
                    _ => {}
                }
            }
        }
        let text = text.join("\n");
        let calls: Vec<&Value> =
            output.iter().filter(|i| i.get("type").and_then(Value::as_str) == Some("computer_call")).collect();
        if calls.is_empty() || refused {
            self.previous_response_id = Some(id);
            self.pending.clear();
            return Ok(ending(text, refused, logs));
        }
        let mut response = text;
        let mut pending = Vec::new();
        let mut batch = Vec::new();
        let mut all_checks = Vec::new();
        for call in calls {
            let call_id = call
                .get("call_id")
                .and_then(Value::as_str)
                .ok_or_else(|| malformed("a computer_call without call_id"))?;
            // The GA tool batches its actions; the preview tool sends one.
            let actions = match (self.config.tool, call.get("actions"), call.get("action")) {
                (Form::Computer, Some(list @ Value::Array(_)), _) => list.clone(),
                (_, _, Some(one)) if !one.is_null() => one.clone(),
                (Form::Computer, _, _) => return Err(malformed("a computer_call without `actions`")),
                _ => return Err(malformed("a computer_call without `action`")),
            };
            response.push_str(&format!("\n{actions}"));
            batch.push(actions);
            let checks: Vec<Value> =
                call.get("pending_safety_checks").and_then(Value::as_array).cloned().unwrap_or_default();
            all_checks.extend(checks.iter().cloned());
            // Acknowledged checks are exactly the pending ones, with their id, code and message.
            pending.push(PendingCall { call_id: call_id.to_owned(), acknowledged: checks });
        }
        let mut response = response.trim().to_owned();
        if !all_checks.is_empty() {
            response.push_str(&format!(
                "\npending safety checks ({}): {}",
                self.config.safety_checks.name(),
                Value::Array(all_checks)
            ));
            if self.config.safety_checks == SafetyChecks::Fail {
                self.previous_response_id = Some(id);
                self.pending.clear();
                return Ok(super::translated(response, vec![AgentAction::Fail], None, logs));
            }
        }
        // The model's pixels are the screenshot's: scaled back to the screen's.
        let ctx = Context { screen, cursor: (0, 0), coords: Coords::Image { width: size.0, height: size.1 } };
        let mut steps = Vec::new();
        let mut raw_error = None;
        for actions in &batch {
            match arena_actionspace::parse(ActionSpace::OpenAi, actions, &ctx) {
                Ok(more) => steps.extend(more.into_iter().filter(|s| *s != Step::Screenshot)),
                Err(err) => {
                    // Nothing of an answer with an unreadable action is done.
                    raw_error = Some(err.to_string());
                    steps.clear();
                    break;
                }
            }
        }
        let actions = AgentAction::from_steps(&steps);
        self.previous_response_id = Some(id);
        self.pending = pending;
        Ok(super::translated(response, actions, raw_error, logs))
    }
}
