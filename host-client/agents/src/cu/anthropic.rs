//! [`AnthropicAgent`]: Claude with Anthropic's `computer` tool or computer toolset,
//! over the Messages API.
//!
//! The protocol is Anthropic's published one (Messages API and computer-use tool docs):
//! `POST {base}/v1/messages` with `x-api-key`, `anthropic-version: 2023-06-01` and
//! the tool's beta header (`computer-use-2025-01-24` for `computer_20250124`,
//! `computer-use-2025-11-24` for `computer_20251124`); the tool is declared as
//! `{"type": "computer_20250124", "name": "computer", "display_width_px", "display_height_px"}`
//! (`"enable_zoom": true` with `computer_20251124` when zoom is on).
//!
//! The toolset `computer_toolset_20260801` (the `anthropic` SDK 2.14.0's
//! `ComputerToolset20260801Param`, a type of the generally available API: no beta
//! header) is one `tools` entry with `type` and, when the run disables members,
//! `configs` (`{"zoom": {"enabled": false}}` unless `--zoom`; every member is on by
//! default, zoom included); it carries no name and no display size. The model
//! answers with `tool_use` blocks named by their member (`left_click`) with
//! `toolset_name: "computer"`, and each `tool_result` carries the same `toolset_name`.
//!
//! - **One conversation per episode.** The first user message holds the task and
//!   the screenshot; each later one holds a `tool_result` for every `tool_use` of
//!   the previous answer, the last carrying the new screenshot (a `cursor_position`
//!   result carries the position, a `zoom` result the region's crop, a toolset
//!   `screenshot` member's result the new screenshot, an action that could not be
//!   read `is_error` and why). The actions of all the answer's `tool_use` blocks
//!   run in order before the next observation, so every screenshot in the answer
//!   is the screen after all of them.
//! - **Screenshots** are scaled to the model's limit ([`super::models`]: for
//!   models limited to 1568 px, the resolution the tool documentation recommends,
//!   `models::recommended_size`: XGA, WXGA or FWXGA by aspect ratio, else within the
//!   API's image limits; for Opus 4.7, up to 2576 px, so a 1440x900 screen is sent
//!   as it is), or to `--max-image-side`, and the model's coordinates are scaled back.
//! - **Images kept**: only the last `keep_images` screenshots stay in the
//!   conversation; older ones become a short text.
//! - **Prompt caching**: the system prompt (and the tool list before it) is
//!   marked `cache_control: ephemeral`, the stable prefix.
//! - **Thinking**: with a budget, `thinking: {type: enabled, budget_tokens}`; the
//!   answer's thinking blocks are sent back unchanged, as the API requires.
//! - **Decisions**: an answer without a tool call ends the episode: `FAIL` when its
//!   text says FAIL (the system prompt asks for that word when the task cannot be
//!   done), `DONE` otherwise. `stop_reason: "refusal"` is `FAIL`.
//!
//! The system prompt is this project's own wording.

use serde_json::{json, Value};

use arena_script::host::cursor_after;

use super::models::{Form, ImageLimit};
use super::{base64_png, cropped_png, exchange_logs, resized_png, screen_of, Endpoint};
use crate::llm::{ApiKind, ModelClient};
use crate::observation::Observation;
use crate::{Agent, AgentError, Prediction, StepLog};
use arena_actionspace::{ActionSpace, Context, Coords, Decision, Step};
use arena_exec::AgentAction;
use arena_task::Task;

/// Environment variables the key is read from, in order.
pub const KEY_VARS: [&str; 2] = ["ARENA_LLM_KEY", "ANTHROPIC_API_KEY"];

/// The Messages API version header.
pub const API_VERSION: &str = "2023-06-01";

/// The system prompt: how to finish, in this project's words.
pub const SYSTEM_PROMPT: &str =
    "You are operating a Windows 11 desktop through the computer tool to complete the user's task. \
Act step by step and look at each new screenshot before the next action. When the task is complete, reply without \
a tool call and end your message with the word DONE. If the task cannot be done on this computer, reply without a \
tool call and end your message with the word FAIL.";

/// The Anthropic agent's settings.
#[derive(Debug, Clone, PartialEq)]
pub struct AnthropicConfig {
    pub endpoint: Endpoint,
    /// [`Form::Computer20250124`], [`Form::Computer20251124`] or [`Form::ComputerToolset20260801`].
    pub tool: Form,
    /// The largest screenshot sent.
    pub image: ImageLimit,
    /// Toolset members the run withholds from the model (`configs`), besides zoom without `--zoom`.
    pub disabled_members: Vec<String>,
    /// How many screenshots stay in the conversation (`--keep-images`).
    pub keep_images: usize,
    /// Extended thinking's budget in tokens, for models that take one.
    pub thinking_budget: Option<u32>,
    /// Mark the stable prefix for prompt caching.
    pub prompt_caching: bool,
    /// Offer `zoom` (`computer_20251124` only).
    pub enable_zoom: bool,
}

impl AnthropicConfig {
    pub fn new(base_url: &str, model: &str) -> AnthropicConfig {
        AnthropicConfig {
            endpoint: Endpoint::new(base_url, model),
            tool: Form::Computer20250124,
            image: ImageLimit::AnthropicRecommended,
            disabled_members: Vec::new(),
            keep_images: 3,
            thinking_budget: None,
            prompt_caching: true,
            enable_zoom: false,
        }
    }

    /// The tool type, which is also the action space's name.
    pub fn tool_type(&self) -> &'static str {
        self.tool.name()
    }

    /// The beta header the tool version needs (none for the toolset).
    pub fn beta(&self) -> Option<&'static str> {
        self.tool.beta_header()
    }

    /// The action space of the tool's answers.
    pub fn space(&self) -> ActionSpace {
        self.tool.action_space()
    }

    /// The toolset's `tools` entry: `type`, and `configs` for each member the run withholds.
    fn toolset_entry(&self) -> Value {
        let mut configs = serde_json::Map::new();
        if !self.enable_zoom {
            configs.insert("zoom".into(), json!({"enabled": false}));
        }
        for member in &self.disabled_members {
            configs.insert(member.clone(), json!({"enabled": false}));
        }
        let mut entry = json!({"type": self.tool_type()});
        if !configs.is_empty() {
            entry["configs"] = Value::Object(configs);
        }
        entry
    }

    /// The Messages URL: `/v1/messages` after the base (or `/messages` after a base ending in `/v1`).
    ///
    /// # Errors
    ///
    /// [`AgentError::Config`] for a URL that does not parse or an empty model name.
    pub fn url(&self) -> Result<String, AgentError> {
        let route = if self.endpoint.base_url.trim().trim_end_matches('/').ends_with("/v1") {
            "/messages"
        } else {
            "/v1/messages"
        };
        self.endpoint.url(route)
    }
}

/// What the next message must answer about a `tool_use` of the last answer.
#[derive(Debug, Clone, PartialEq)]
enum Answer {
    /// Carried out (or nothing to do): the screenshot, if it is the last.
    Done,
    /// A toolset `screenshot` member: the new screenshot.
    Screenshot,
    /// The cursor position.
    Cursor,
    /// The crop of this region of the new screenshot.
    Zoom([i32; 4]),
    /// Not carried out, and why.
    Error(String),
}

#[derive(Debug, Clone, PartialEq)]
struct Pending {
    id: String,
    answer: Answer,
}

/// The Anthropic computer-use agent. See the module documentation.
#[derive(Debug)]
pub struct AnthropicAgent {
    config: AnthropicConfig,
    client: ModelClient,
    messages: Vec<Value>,
    pending: Vec<Pending>,
    /// Where the agent's own actions left the cursor, in screen pixels.
    cursor: (i32, i32),
}

impl AnthropicAgent {
    /// The model client, for `arena run`'s preflight.
    pub fn client(&self) -> &crate::llm::ModelClient {
        &self.client
    }

    /// An agent for `config`; the key is resolved now.
    ///
    /// # Errors
    ///
    /// [`AgentError::Config`] for an unusable URL, model, tool version or thinking budget.
    pub fn new(config: AnthropicConfig) -> Result<AnthropicAgent, AgentError> {
        if config.tool.vendor() != super::models::Vendor::Anthropic {
            return Err(AgentError::Config(format!(
                "{} is not a version of Anthropic's computer tool",
                config.tool.name()
            )));
        }
        if config.enable_zoom && config.tool == Form::Computer20250124 {
            return Err(AgentError::Config("zoom needs the computer_20251124 tool or the computer toolset".into()));
        }
        if let Some(bad) = config
            .disabled_members
            .iter()
            .find(|m| !arena_actionspace::anthropic::TOOLSET_MEMBERS.contains(&m.as_str()))
        {
            return Err(AgentError::Config(format!(
                "{bad:?} is not a member of computer_toolset_20260801 (members: {})",
                arena_actionspace::anthropic::TOOLSET_MEMBERS.join(", ")
            )));
        }
        if !config.disabled_members.is_empty() && config.tool != Form::ComputerToolset20260801 {
            return Err(AgentError::Config("only the computer toolset has members to disable".into()));
        }
        if let Some(budget) = config.thinking_budget {
            if budget < 1024 || budget >= config.endpoint.max_tokens {
                return Err(AgentError::Config(format!(
                    "the thinking budget ({budget}) must be at least 1024 and below the answer's length limit ({})",
                    config.endpoint.max_tokens
                )));
            }
        }
        let mut client = config
            .endpoint
            .client(&config.url()?, ApiKind::Anthropic, &KEY_VARS)?
            .with_header("anthropic-version", API_VERSION);
        if let Some(beta) = config.beta() {
            client = client.with_header("anthropic-beta", beta);
        }
        Ok(AnthropicAgent { config, client, messages: Vec::new(), pending: Vec::new(), cursor: (0, 0) })
    }

    fn body(&self, messages: &[Value], size: (u32, u32)) -> Value {
        let tool = if self.config.tool == Form::ComputerToolset20260801 {
            self.config.toolset_entry()
        } else {
            let mut tool = json!({
                "type": self.config.tool_type(),
                "name": "computer",
                "display_width_px": size.0,
                "display_height_px": size.1,
            });
            if self.config.enable_zoom {
                tool["enable_zoom"] = json!(true);
            }
            tool
        };
        let mut system = json!({"type": "text", "text": SYSTEM_PROMPT});
        if self.config.prompt_caching {
            system["cache_control"] = json!({"type": "ephemeral"});
        }
        let mut body = json!({
            "model": self.config.endpoint.model,
            "max_tokens": self.config.endpoint.max_tokens,
            "system": [system],
            "tools": [tool],
            "messages": messages,
        });
        if let Some(budget) = self.config.thinking_budget {
            body["thinking"] = json!({"type": "enabled", "budget_tokens": budget});
        }
        body
    }
}

fn image_block(png: &[u8]) -> Value {
    json!({"type": "image", "source": {"type": "base64", "media_type": "image/png", "data": base64_png(png)}})
}

fn text_block(text: &str) -> Value {
    json!({"type": "text", "text": text})
}

/// Replaces all but the last `keep` images of the conversation with a short text.
fn keep_last_images(messages: &mut [Value], keep: usize) {
    let mut seen = 0;
    for message in messages.iter_mut().rev() {
        let Some(parts) = message.get_mut("content").and_then(Value::as_array_mut) else { continue };
        for part in parts.iter_mut().rev() {
            let nested = part.get_mut("content").and_then(Value::as_array_mut);
            let blocks: Vec<&mut Value> = match nested {
                Some(inner) => inner.iter_mut().rev().collect(),
                None => vec![part],
            };
            for block in blocks {
                if block.get("type").and_then(Value::as_str) == Some("image") {
                    seen += 1;
                    if seen > keep {
                        *block = text_block("(an earlier screenshot, left out)");
                    }
                }
            }
        }
    }
}

/// The decision of an answer that calls no tool.
pub(crate) fn final_decision(text: &str) -> AgentAction {
    if Decision::Fail.said_in(text) {
        AgentAction::Fail
    } else {
        AgentAction::Done
    }
}

/// The prediction that ends an episode when a computer-use model answers without
/// an action: `FAIL` for a refusal (its text kept, marked), else [`final_decision`]
/// of its text. Both the Anthropic and the OpenAI agent end this way.
pub(crate) fn ending(text: String, refused: bool, logs: Vec<StepLog>) -> Prediction {
    let (decision, response) = if refused {
        (AgentAction::Fail, format!("(the model refused) {text}").trim().to_owned())
    } else {
        (final_decision(&text), text)
    };
    super::translated(response, vec![decision], None, logs)
}

#[async_trait::async_trait]
impl Agent for AnthropicAgent {
    fn name(&self) -> &str {
        "anthropic-cu"
    }

    fn take_usage(&mut self) -> Option<arena_results::ledger::Usage> {
        self.client.take_usage()
    }

    async fn reset(&mut self, _task: &Task) {
        self.messages.clear();
        self.pending.clear();
        self.cursor = (0, 0);
    }

    async fn predict(&mut self, obs: &Observation) -> Result<Prediction, AgentError> {
        let (frame, screen) = screen_of(obs);
        let size = self.config.image.size_for(screen);
        let toolset = self.config.tool == Form::ComputerToolset20260801;
        let coords = Coords::Image { width: size.0, height: size.1 };
        let shot = image_block(&resized_png(frame, size)?);

        let mut messages = self.messages.clone();
        if messages.is_empty() {
            messages.push(json!({"role": "user", "content": [text_block(&obs.instruction), shot]}));
        } else {
            let mut results = Vec::new();
            for (i, pending) in self.pending.iter().enumerate() {
                let mut content = Vec::new();
                let mut is_error = false;
                let last = i + 1 == self.pending.len();
                match &pending.answer {
                    Answer::Done => {}
                    Answer::Screenshot if !last => content.push(shot.clone()),
                    Answer::Screenshot => {}
                    Answer::Cursor => {
                        let (x, y) = coords.from_screen(self.cursor.0, self.cursor.1, screen);
                        content.push(text_block(&format!("X={},Y={}", x.round(), y.round())));
                    }
                    Answer::Zoom(rect) => content.push(image_block(&cropped_png(frame, *rect)?)),
                    Answer::Error(why) => {
                        is_error = true;
                        content.push(text_block(why));
                    }
                }
                if last {
                    content.push(shot.clone());
                }
                let mut result = json!({"type": "tool_result", "tool_use_id": pending.id, "content": content});
                if is_error {
                    result["is_error"] = json!(true);
                }
                if toolset {
                    result["toolset_name"] = json!("computer");
                }
                results.push(result);
            }
            if results.is_empty() {
                results.push(shot);
            }
            messages.push(json!({"role": "user", "content": results}));
        }
        keep_last_images(&mut messages, self.config.keep_images.max(1));
        let body = self.body(&messages, size);
        let answer = self.client.call(&body).await?;
        let logs = exchange_logs(&body, &answer);

        let malformed = |why: &str| AgentError::Model {
            endpoint: self.client.endpoint().to_owned(),
            reason: format!("the answer is not a Messages API message: {why}"),
        };
        let content = answer.get("content").and_then(Value::as_array).ok_or_else(|| malformed("no `content` list"))?;
        let text: Vec<&str> = content
            .iter()
            .filter(|b| b.get("type").and_then(Value::as_str) == Some("text"))
            .filter_map(|b| b.get("text").and_then(Value::as_str))
            .collect();
        let text = text.join("\n");
        messages.push(json!({"role": "assistant", "content": content}));

        let stop_reason = answer.get("stop_reason").and_then(Value::as_str).unwrap_or_default();
        let uses: Vec<&Value> =
            content.iter().filter(|b| b.get("type").and_then(Value::as_str) == Some("tool_use")).collect();
        if stop_reason == "refusal" || uses.is_empty() {
            self.messages = messages;
            self.pending.clear();
            return Ok(ending(text, stop_reason == "refusal", logs));
        }
        let mut response = text;

        let ctx = Context { screen, cursor: self.cursor, coords };
        let mut pending = Vec::new();
        let mut steps = Vec::new();
        let mut errors = Vec::new();
        for block in &uses {
            let id = block.get("id").and_then(Value::as_str).ok_or_else(|| malformed("a tool_use without an id"))?;
            let input = block.get("input").cloned().unwrap_or(Value::Null);
            response.push_str(&format!("\n{input}"));
            let space = self.config.space();
            let parsed = match (block.get("name").and_then(Value::as_str), toolset) {
                (Some("computer"), false) => arena_actionspace::parse(space, &input, &ctx),
                // A member's block: its name and input are the action.
                (Some(_), true) if block.get("toolset_name").and_then(Value::as_str) == Some("computer") => {
                    arena_actionspace::parse(space, block, &ctx)
                }
                (other, _) => Err(arena_actionspace::ActionError::new(space, format!("unknown tool {other:?}"))),
            };
            let answer = match parsed {
                Ok(s) => {
                    let answer =
                        match s.iter().find(|s| matches!(s, Step::CursorPosition | Step::Zoom(_) | Step::Screenshot)) {
                            Some(Step::Zoom(rect)) => Answer::Zoom(*rect),
                            Some(Step::CursorPosition) => Answer::Cursor,
                            Some(_) if toolset => Answer::Screenshot,
                            _ => Answer::Done,
                        };
                    steps.extend(s);
                    answer
                }
                Err(err) => {
                    errors.push(err.to_string());
                    Answer::Error(err.to_string())
                }
            };
            pending.push(Pending { id: id.to_owned(), answer });
        }
        let raw_error = (!errors.is_empty()).then(|| errors.join("; "));
        let actions = if raw_error.is_some() {
            // Nothing of a turn with an unreadable action is done; every call is told so.
            for p in &mut pending {
                if !matches!(p.answer, Answer::Error(_)) {
                    p.answer = Answer::Error("not carried out: another action of this turn could not be read".into());
                }
            }
            Vec::new()
        } else {
            for step in &steps {
                if let Step::Act(action) = step {
                    self.cursor = cursor_after(action, self.cursor);
                }
            }
            AgentAction::from_steps(&steps)
        };
        self.messages = messages;
        self.pending = pending;
        Ok(super::translated(response.trim().to_owned(), actions, raw_error, logs))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cu::models::recommended_size;

    #[test]
    fn the_recommended_sizes_follow_the_aspect_ratio() {
        assert_eq!(recommended_size((1920, 1080)), (1366, 768));
        assert_eq!(recommended_size((1440, 900)), (1280, 800));
        assert_eq!(recommended_size((2048, 1536)), (1024, 768));
        assert_eq!(recommended_size((1024, 768)), (1024, 768));
        assert_eq!(recommended_size((800, 600)), (800, 600));
        let (w, h) = recommended_size((3440, 1440));
        assert!(w <= 1568 && u64::from(w) * u64::from(h) <= 1_150_000, "{w}x{h}");
    }

    #[test]
    fn only_the_last_images_are_kept() {
        let img = || json!({"type": "image", "source": {"type": "base64", "media_type": "image/png", "data": "x"}});
        let mut messages = vec![
            json!({"role": "user", "content": [text_block("task"), img()]}),
            json!({"role": "assistant", "content": [text_block("ok")]}),
            json!({"role": "user", "content": [{"type": "tool_result", "tool_use_id": "a", "content": [img()]}]}),
            json!({"role": "user", "content": [{"type": "tool_result", "tool_use_id": "b", "content": [img()]}]}),
        ];
        keep_last_images(&mut messages, 2);
        let images = serde_json::to_string(&messages).unwrap().matches("\"image\"").count();
        assert_eq!(images, 2);
        assert_eq!(messages[0]["content"][1]["text"], "(an earlier screenshot, left out)");
        assert_eq!(messages[3]["content"][0]["content"][0]["type"], "image");
    }

    #[test]
    fn a_final_message_decides_by_its_words() {
        assert_eq!(final_decision("The file is saved. DONE"), AgentAction::Done);
        assert_eq!(final_decision("This setting does not exist here. FAIL"), AgentAction::Fail);
        assert_eq!(final_decision("No failures. DONE"), AgentAction::Done);
    }

    #[test]
    fn configurations_that_cannot_work_are_refused() {
        let mut config = AnthropicConfig::new("https://api.anthropic.com", "claude");
        config.enable_zoom = true;
        assert!(AnthropicAgent::new(config.clone()).is_err());
        config.tool = Form::Computer20251124;
        assert!(AnthropicAgent::new(config.clone()).is_ok());
        config.disabled_members = vec!["scroll".into()];
        assert!(AnthropicAgent::new(config.clone()).is_err(), "members are the toolset's");
        config.tool = Form::ComputerToolset20260801;
        assert!(AnthropicAgent::new(config.clone()).is_ok());
        config.disabled_members = vec!["teleport".into()];
        assert!(AnthropicAgent::new(config.clone()).is_err(), "not a member");
        config.disabled_members.clear();
        config.thinking_budget = Some(8192);
        assert!(AnthropicAgent::new(config.clone()).is_err(), "a budget above max_tokens");
        config.thinking_budget = None;
        config.tool = Form::Computer;
        assert!(AnthropicAgent::new(config).is_err());
        assert_eq!(AnthropicConfig::new("https://gw.example/v1", "m").url().unwrap(), "https://gw.example/v1/messages");
    }
}
