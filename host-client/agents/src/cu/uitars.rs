//! [`UiTarsAgent`]: UI-TARS over an OpenAI-compatible chat endpoint (a
//! vLLM-served UI-TARS), with the prompt the user points at.
//!
//! - **The prompt** is read at run time from `--prompt-file`: the computer-use
//!   template as the UI-TARS project publishes it, with `{instruction}` and
//!   `{language}` filled in. This repository ships none of its prose.
//! - **Messages**, as OSWorld's UI-TARS agent lays them out: the prompt as the
//!   first user message, then for each earlier step its screenshot (only the last
//!   `history_images` screenshots, the current one included, are sent) and the
//!   model's reply, then the current screenshot.
//! - **Replies** are read by [`arena_actionspace::uitars`] with the coordinate
//!   convention of the configured [`UiTarsVersion`] for the screenshot sent
//!   (the screen's own size).

use serde_json::{json, Value};

use super::{exchange_logs, screen_of, Endpoint};
use crate::llm::{ApiKind, ModelClient};
use crate::observation::Observation;
use crate::{Agent, AgentError, Prediction};
use arena_actionspace::uitars::UiTarsVersion;
use arena_actionspace::{ActionSpace, Context};
use arena_exec::AgentAction;
use arena_task::Task;

/// Environment variables the key is read from, in order (vLLM takes any key, or none).
pub const KEY_VARS: [&str; 2] = ["ARENA_LLM_KEY", "OPENAI_API_KEY"];

/// The UI-TARS agent's settings.
#[derive(Debug, Clone, PartialEq)]
pub struct UiTarsConfig {
    pub endpoint: Endpoint,
    pub version: UiTarsVersion,
    /// The prompt template's text (from `--prompt-file`).
    pub prompt_template: String,
    /// What fills `{language}` (the language of the model's thoughts).
    pub language: String,
    /// How many screenshots a request carries, the current one included.
    pub history_images: usize,
    pub temperature: f64,
}

impl UiTarsConfig {
    pub fn new(base_url: &str, model: &str, prompt_template: &str) -> UiTarsConfig {
        UiTarsConfig {
            endpoint: Endpoint::new(base_url, model),
            version: UiTarsVersion::default(),
            prompt_template: prompt_template.to_owned(),
            language: "English".into(),
            history_images: 5,
            temperature: 0.0,
        }
    }

    /// Reads the template from `path`.
    ///
    /// # Errors
    ///
    /// [`AgentError::Config`] naming the file when it cannot be read, or when it has no `{instruction}`.
    pub fn read_prompt(path: &std::path::Path) -> Result<String, AgentError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| AgentError::Config(format!("cannot read the UI-TARS prompt file {}: {e}", path.display())))?;
        if !text.contains("{instruction}") {
            return Err(AgentError::Config(format!(
                "the UI-TARS prompt file {} has no {{instruction}} placeholder",
                path.display()
            )));
        }
        Ok(text)
    }
}

/// One earlier step: the screenshot it saw and the model's reply.
#[derive(Debug, Clone, PartialEq)]
struct Turn {
    image_url: String,
    reply: String,
}

/// The UI-TARS agent. See the module documentation.
#[derive(Debug)]
pub struct UiTarsAgent {
    config: UiTarsConfig,
    client: ModelClient,
    history: Vec<Turn>,
}

impl UiTarsAgent {
    /// The model client, for `arena run`'s preflight.
    pub fn client(&self) -> &crate::llm::ModelClient {
        &self.client
    }

    /// An agent for `config`; the key is resolved now.
    ///
    /// # Errors
    ///
    /// [`AgentError::Config`] for an unusable URL, model name or prompt.
    pub fn new(config: UiTarsConfig) -> Result<UiTarsAgent, AgentError> {
        if !config.prompt_template.contains("{instruction}") {
            return Err(AgentError::Config("the UI-TARS prompt has no {instruction} placeholder".into()));
        }
        let client = config.endpoint.client(&config.endpoint.url("/chat/completions")?, ApiKind::OpenAi, &KEY_VARS)?;
        Ok(UiTarsAgent { config, client, history: Vec::new() })
    }

    fn body(&self, instruction: &str, image_url: &str) -> Value {
        let prompt = self
            .config
            .prompt_template
            .replace("{instruction}", instruction)
            .replace("{language}", &self.config.language);
        let image = |url: &str| json!({"role": "user", "content": [{"type": "image_url", "image_url": {"url": url}}]});
        let mut messages = vec![json!({"role": "user", "content": [{"type": "text", "text": prompt}]})];
        // The current screenshot counts among the images sent.
        let first_image = (self.history.len() + 1).saturating_sub(self.config.history_images.max(1));
        for (i, turn) in self.history.iter().enumerate() {
            if i >= first_image {
                messages.push(image(&turn.image_url));
            }
            messages.push(json!({"role": "assistant", "content": turn.reply}));
        }
        messages.push(image(image_url));
        json!({
            "model": self.config.endpoint.model,
            "messages": messages,
            "temperature": self.config.temperature,
            "max_tokens": self.config.endpoint.max_tokens,
        })
    }
}

#[async_trait::async_trait]
impl Agent for UiTarsAgent {
    fn name(&self) -> &str {
        "ui-tars"
    }

    fn take_usage(&mut self) -> Option<arena_results::ledger::Usage> {
        self.client.take_usage()
    }

    async fn reset(&mut self, _task: &Task) {
        self.history.clear();
    }

    async fn predict(&mut self, obs: &Observation) -> Result<Prediction, AgentError> {
        let (frame, screen) = screen_of(obs);
        let image_url = crate::llm::image_data_url("image/png", &frame.encoded);
        let body = self.body(&obs.instruction, &image_url);
        let reply = self.client.complete(&body).await?;
        let logs = exchange_logs(&body, &json!({"content": reply}));
        let ctx = Context::new(screen, self.config.version.coords(screen));
        let (actions, raw_error) =
            match arena_actionspace::parse(ActionSpace::UiTars, &Value::String(reply.clone()), &ctx) {
                Ok(steps) => (AgentAction::from_steps(&steps), None),
                Err(err) => (Vec::new(), Some(err.to_string())),
            };
        self.history.push(Turn { image_url, reply: reply.clone() });
        Ok(super::translated(reply, actions, raw_error, logs))
    }
}
