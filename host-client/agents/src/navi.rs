//! [`NaviAgent`]: a Navi-style agent over any OpenAI-compatible
//! chat-completions endpoint.
//!
//! Each step sends one conversation: a system prompt that describes the
//! `computer` API (our own wording of what upstream's planner prompt
//! advertises) and one user message with the task, the screenshot annotated
//! with Set-of-Marks boxes, the previous step's screenshot, the element list,
//! the window titles, the clipboard, the action history and the memory the
//! model keeps. The reply must hold a ```` ```python ```` block (Navi
//! `computer.*` code or pyautogui) or `DONE`/`FAIL`/`WAIT`; see
//! [`super::parse`]. A reply without one, or whose code does not parse, is a
//! [`Prediction`] with no actions and [`Prediction::raw_error`] set; the model
//! is told what was wrong on the next step.
//!
//! The Set-of-Marks boxes come from the configured source ([`NaviConfig::som`],
//! upstream's `--som_origin`): the accessibility tree by default, or OCR, the
//! icon detector and OmniParser through [`arena_som::SomSources`]. A source
//! that fails (Tesseract missing, a service down) fails the step as a model
//! failure does: it is asked again, then the task is left unfinished.
//!
//! It is not a client of any one vendor's API and keeps no conversation
//! between steps beyond the history and memory it writes into the prompt.

use std::sync::Arc;
use std::time::{Duration, Instant};

use image::RgbaImage;
use serde_json::{json, Value};

use super::llm::{self, ApiKind, ModelClient, Refusals, RetryPolicy, TokensField};
use super::parse::{parse_navi_reply, parse_reply};
use super::waa_prompts::{UserInputs, WaaPrompts};
use super::{Agent, AgentError, LogValue, PredictTimings, Prediction, StepLog};
use crate::observation::Observation;
use arena_client::frame::encode_png;
use arena_exec::AgentAction;
use arena_som::{annotate, Marks, ProposedEntity, SomConfig, SomInput, SomSources};
use arena_task::Task;

/// Environment variables the API key is read from, in order, when the configuration has none.
pub const KEY_VARS: [&str; 2] = ["ARENA_LLM_KEY", "OPENAI_API_KEY"];

/// How to reach the model.
#[derive(Debug, Clone, PartialEq)]
pub struct NaviConfig {
    /// Base URL of the API, e.g. `https://api.openai.com/v1` or `http://127.0.0.1:8000/v1`;
    /// `/chat/completions` is appended unless it is already there.
    pub base_url: String,
    pub model: String,
    /// The API key; `None` reads [`KEY_VARS`], and no key at all sends no auth header.
    pub api_key: Option<String>,
    /// Sampling temperature (upstream's Navi: 1.0).
    pub temperature: f64,
    /// Longest answer, in tokens (upstream's Navi: 4096).
    pub max_tokens: u32,
    /// The request field of `max_tokens`; `None` chooses by the model's name.
    pub tokens_field: Option<TokensField>,
    /// Which API the endpoint speaks; `None` detects it from the URL.
    pub api: Option<ApiKind>,
    /// Deadline of one chat-completions call.
    pub timeout: Duration,
    /// How long a failing model is tried again before the task is left unfinished.
    pub retry: RetryPolicy,
    /// The run's view of the endpoint being down (`--llm-unreachable`), shared by its agents.
    pub down: llm::EndpointDown,
    /// How many previous steps the prompt's action history shows (upstream: 15).
    pub max_history: usize,
    /// The message layout and reply rules.
    pub style: NaviStyle,
    /// Upstream's prompt texts, read from the user's WAA checkout (`--waa-root`);
    /// without them [`NaviStyle::Waa`] uses our own words in the same layout.
    pub waa_prompts: Option<std::sync::Arc<WaaPrompts>>,
    /// Where the Set-of-Marks entities come from (upstream's `--som_origin`,
    /// default `a11y`) and how its services are reached.
    pub som: SomConfig,
    /// What a refusal does (upstream: the task is left unfinished).
    pub refusals: Refusals,
}

/// Which Navi the agent is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum NaviStyle {
    /// Upstream's layout and rules: the user message's nine numbered inputs, the
    /// history newest first, images as `[previous, current annotated]`, and the
    /// reply's first ```` ```python ```` block, ```` ```decision ```` and
    /// ```` ```memory ```` blocks read as upstream reads them
    /// ([`super::parse::parse_navi_reply`]). The prompt's prose is our own wording.
    #[default]
    Waa,
    /// This project's earlier agent: its own prompt and the lenient reply reader
    /// ([`super::parse::parse_reply`]: every code block, control words anywhere, `Memory:` lines).
    Arena,
}

impl NaviConfig {
    pub fn new(base_url: &str, model: &str) -> NaviConfig {
        NaviConfig {
            base_url: base_url.to_owned(),
            model: model.to_owned(),
            api_key: None,
            temperature: 1.0,
            max_tokens: 4096,
            tokens_field: None,
            api: None,
            timeout: Duration::from_secs(120),
            retry: RetryPolicy::default(),
            down: llm::EndpointDown::default(),
            max_history: 15,
            style: NaviStyle::default(),
            waa_prompts: None,
            som: SomConfig::default(),
            refusals: Refusals::default(),
        }
    }

    /// The key to send: the configured one, else the first non-empty [`KEY_VARS`] variable.
    pub fn resolved_key(&self) -> Option<String> {
        self.api_key
            .clone()
            .filter(|k| !k.is_empty())
            .or_else(|| KEY_VARS.iter().find_map(|var| std::env::var(var).ok().filter(|v| !v.trim().is_empty())))
    }

    /// The chat-completions URL (the base URL when it does not parse; the agent refuses it then).
    pub fn endpoint(&self) -> String {
        llm::chat_endpoint(&self.base_url).unwrap_or_else(|_| self.base_url.clone())
    }
}

/// The system prompt: what the model may do and how to answer.
pub const SYSTEM_PROMPT: &str = r#"You operate a Windows 11 computer to complete a task for the user.
Each turn you see the current screen with numbered boxes drawn on the elements you can use, a list of those
elements, the open windows, the clipboard, what you did so far and your own notes.

Act by writing Python in one ```python code block. The object `computer` is ready to use:

- computer.mouse.move_id(id=12)                      move the pointer to the centre of element 12
- computer.mouse.move_abs(x=0.25, y=0.80)            move the pointer to a point given as fractions of the screen width and height
- computer.mouse.single_click()                      left click where the pointer is
- computer.mouse.double_click()                      double click where the pointer is
- computer.mouse.right_click()                       right click where the pointer is
- computer.mouse.scroll(dir="down")                  scroll at the pointer, dir is "up" or "down"
- computer.mouse.drag(x=0.40, y=0.55)                hold the left button, move to that point (fractions of the screen), release
- computer.keyboard.write("some text")               type text
- computer.keyboard.press("enter")                   press a key or a combination such as "ctrl+s" or "alt+f4"
- computer.clipboard.copy_text("some text")          put text on the clipboard
- computer.clipboard.copy_image(id=7, description="a chart")   put the picture of element 7 on the clipboard
- computer.clipboard.paste()                         paste the clipboard
- computer.os.open_program("notepad")                start a program by its executable name (msedge, winword, excel, explorer, ...)
- computer.window_manager.switch_to_application("Document - Word")   bring the window with this title to the front

Move the pointer before you click. Several lines run in order. pyautogui calls (import pyautogui) are also accepted.

When the task is complete, answer DONE. If it cannot be done, answer FAIL. To wait for the screen to change, answer WAIT.
You may keep notes for later turns: write a line starting with "Memory:" followed by what you want to remember;
it replaces your previous notes. Think briefly first, then give the code block or the word."#;

/// The system prompt of [`NaviStyle::Waa`]: the same `computer` API and the
/// reply structure upstream's planner expects (a ```` ```python ```` block, a
/// ```` ```decision ```` block and a ```` ```memory ```` block), in our words.
pub const WAA_SYSTEM_PROMPT: &str = r#"You control a Windows 11 computer to reach the user's objective, one action per turn.
Every turn brings the inputs listed in the user message and two pictures: the screen before your previous
action, then the current screen with numbered boxes on the elements you can target.

Your actions are Python run with a ready `computer` object:
- computer.mouse.move_id(id=12)                      pointer to the centre of element 12
- computer.mouse.move_abs(x=0.25, y=0.80)            pointer to a point given as fractions of the screen's width and height
- computer.mouse.single_click(), double_click(), right_click()
- computer.mouse.scroll(dir="down")                  "up" or "down", at the pointer
- computer.mouse.drag(x=0.40, y=0.55)                press, move to that point, release
- computer.keyboard.write("text"), computer.keyboard.press("ctrl+s")
- computer.clipboard.copy_text("text"), computer.clipboard.copy_image(id=7, description="chart"), computer.clipboard.paste()
- computer.os.open_program("notepad")
- computer.window_manager.switch_to_application("Document - Word")

Answer in this shape. First reason briefly about the screen and the objective. Then:
```python
# the code of this turn's single action
```
```decision
COMMAND
```
where the decision is COMMAND to run the code, DONE when the objective is reached, FAIL when it cannot be
reached, or WAIT to let the screen settle. Last, keep what later turns must know:
```memory
# your notes, which replace the previous ones
```"#;

/// The memory a [`NaviStyle::Waa`] agent starts each task with.
const EMPTY_MEMORY_BLOCK: &str = "```memory\n# nothing noted yet\n```";

/// The memory block a task starts with: upstream's when its prompts are loaded.
fn empty_memory(config: &NaviConfig) -> String {
    config.waa_prompts.as_ref().map_or_else(|| EMPTY_MEMORY_BLOCK.to_owned(), |p| p.empty_memory.clone())
}

/// One line of the action history.
#[derive(Debug, Clone, PartialEq)]
struct Turn {
    step: u32,
    text: String,
}

/// The Navi-style agent. See the module documentation.
#[derive(Debug)]
pub struct NaviAgent {
    config: NaviConfig,
    client: ModelClient,
    history: Vec<Turn>,
    memory: String,
    /// [`NaviStyle::Waa`]: the memory block, fences included, as upstream keeps it.
    memory_block: String,
    /// The previous step's screenshot, as decoded then (never decoded again).
    previous: Option<Arc<RgbaImage>>,
    last_error: Option<String>,
    /// The Set-of-Marks sources of [`NaviConfig::som`].
    som: SomSources,
}

/// An image part as upstream's client sends one: the screenshot at the model
/// size as a JPEG (Pillow's default quality), `detail: auto`, encoded here from
/// the observation's pixels. An image that cannot be converted is sent as PNG.
fn jpeg_part(pixels: &RgbaImage) -> Value {
    let url = match arena_shared::fastimg::rgba_to_model_jpeg(pixels, arena_shared::fastimg::PILLOW_JPEG_QUALITY) {
        Ok(model) => crate::llm::image_data_url("image/jpeg", &model.jpeg),
        Err(err) => {
            tracing::warn!(error = %err, "cannot make the model's JPEG; sending PNG");
            data_uri(pixels)
        }
    };
    json!({"type": "image_url", "image_url": {"url": url, "detail": "auto"}})
}

/// The pixels as a PNG data URI (the [`NaviStyle::Arena`] request).
fn data_uri(pixels: &RgbaImage) -> String {
    crate::llm::image_data_url("image/png", &encode_png(pixels))
}

impl NaviAgent {
    /// The model client, for `arena run`'s preflight.
    pub fn client(&self) -> &crate::llm::ModelClient {
        &self.client
    }

    /// An agent for `config`; the API key is resolved now.
    ///
    /// # Errors
    ///
    /// [`AgentError::Config`] when the base URL is empty or the HTTP client cannot be built.
    pub fn new(config: NaviConfig) -> Result<NaviAgent, AgentError> {
        if config.base_url.trim().is_empty() || config.model.trim().is_empty() {
            return Err(AgentError::Config("the model's base URL and name must not be empty".into()));
        }
        let api = config.api.unwrap_or_else(|| ApiKind::detect(&config.base_url));
        let client = ModelClient::new(&config.base_url, api, config.resolved_key(), config.timeout, config.retry)?
            .with_refusals(config.refusals)
            .with_down(config.down.clone());
        let memory = empty_memory(&config);
        let som = SomSources::new(config.som.clone()).map_err(|e| AgentError::Config(e.to_string()))?;
        Ok(NaviAgent {
            som,
            config,
            client,
            history: Vec::new(),
            memory: String::new(),
            memory_block: memory,
            previous: None,
            last_error: None,
        })
    }

    /// The Set-of-Marks of `obs` from the configured source.
    async fn marks(&self, obs: &Observation) -> Result<Option<Marks>, AgentError> {
        // The browser's DOM elements for `oss` and `mixed-oss` (the episode reads
        // them when `wants_dom` says so; none when no browser answered).
        let dom = dom_entities(obs);
        let input =
            SomInput { tree: obs.a11y.as_ref(), screenshot: &obs.screenshot, size: obs.screen_size(), dom: &dom };
        self.som.marks(&input).await.map_err(|err| AgentError::Model {
            endpoint: format!("the Set-of-Marks source `{}`", self.config.som.origin),
            reason: err.to_string(),
        })
    }

    /// The text part of a [`NaviStyle::Waa`] user message: upstream's numbered
    /// inputs, with our words where it has prose.
    fn waa_prompt_text(&self, obs: &Observation, marks: Option<&Marks>) -> String {
        if let Some(prompts) = &self.config.waa_prompts {
            // Without marks upstream still prints the list's header line.
            let candidates = marks.map_or_else(|| Marks::default().candidate_list(), Marks::candidate_list);
            let codes: Vec<String> = self.history.iter().map(|t| t.text.clone()).collect();
            let history = prompts.history_text(&codes, self.config.max_history);
            let window_names = obs.window_titles.join("\n");
            return prompts.user_message(&UserInputs {
                objective: &obs.instruction,
                window_title: &obs.foreground_title,
                window_names: &window_names,
                clipboard: obs.tracked_clipboard.as_deref(),
                text_rendering: "N/A",
                candidates: &candidates,
                history: &history,
                memory: &self.memory_block,
            });
        }
        // Upstream shows Navi's own tracked clipboard, not the system's.
        let clipboard = obs.tracked_clipboard.as_deref().unwrap_or("(nothing copied yet)");
        let candidates = marks.map_or_else(|| Marks::default().candidate_list(), Marks::candidate_list);
        // Newest first, as upstream's history reads back from time step T-1.
        let skip = self.history.len().saturating_sub(self.config.max_history);
        let history: Vec<String> = self.history[skip..]
            .iter()
            .rev()
            .enumerate()
            .map(|(i, turn)| format!("Action taken at step T-{} (now is T):\n{}\n", i + 1, turn.text))
            .collect();
        let history = if history.is_empty() { "(no actions yet)".to_owned() } else { history.join("\n") };
        format!(
            "Inputs:\n\n1. User objective: {}\n\n2. Window title: {}\n\n3. All window names:\n{}\n\n4. Clipboard content.\n{clipboard}\n\n\
             5. Text rendering:\n(not provided)\n\n6. Candidate elements:\n{candidates}\n\n7. The two screens come as attached images.\n\n\
             8. History of previous actions code blocks taken to reach the current screen.\n{history}\n\n9. Textual memory:\n{}\n\n",
            obs.instruction,
            obs.foreground_title,
            obs.window_titles.join("\n"),
            self.memory_block
        )
    }

    /// The text part of an [`NaviStyle::Arena`] user message.
    fn prompt_text(&self, obs: &Observation, marks: Option<&Marks>) -> String {
        let mut t = String::new();
        t.push_str(&format!("Task: {}\n\nStep: {}\n\n", obs.instruction, obs.step));
        t.push_str("Open windows:\n");
        if obs.window_titles.is_empty() {
            t.push_str("(none)\n");
        }
        for title in &obs.window_titles {
            let mark = if *title == obs.foreground_title { " (foreground)" } else { "" };
            t.push_str(&format!("- {title}{mark}\n"));
        }
        t.push_str(&format!(
            "\nClipboard: {}\n\n",
            obs.clipboard.as_deref().filter(|c| !c.is_empty()).unwrap_or("(empty)")
        ));
        t.push_str("Previous actions:\n");
        if self.history.is_empty() {
            t.push_str("(none)\n");
        }
        let skip = self.history.len().saturating_sub(self.config.max_history);
        for turn in &self.history[skip..] {
            t.push_str(&format!("Step {}: {}\n", turn.step, turn.text));
        }
        t.push_str(&format!("\nMemory: {}\n\n", if self.memory.is_empty() { "(empty)" } else { &self.memory }));
        match marks {
            Some(marks) => {
                t.push_str("Elements on the screen (the numbers drawn on the screenshot):\n");
                t.push_str(&marks.candidate_list());
            }
            None => t.push_str("No element list is available this turn: use computer.mouse.move_abs.\n"),
        }
        if let Some(err) = &self.last_error {
            t.push_str(&format!(
                "\nYour previous reply could not be used: {err}\nAnswer with one ```python code block, or DONE, FAIL or WAIT.\n"
            ));
        }
        t
    }

    /// The chat-completions request body.
    /// The text part of the user message, in the configured style.
    fn user_text(&self, obs: &Observation, marks: Option<&Marks>) -> String {
        match self.config.style {
            NaviStyle::Waa => self.waa_prompt_text(obs, marks),
            NaviStyle::Arena => self.prompt_text(obs, marks),
        }
    }

    fn request_body(&self, obs: &Observation, marks: Option<&Marks>, annotated: &RgbaImage) -> Value {
        let text = self.user_text(obs, marks);
        let (system, content) = match self.config.style {
            NaviStyle::Waa => {
                // Upstream's order and form: the previous screen as it was (the
                // current one on the first step), then the current one annotated,
                // each resized to the model size and sent as JPEG.
                let previous = self.previous.as_deref().unwrap_or(&obs.screenshot.pixels);
                let content = vec![json!({"type": "text", "text": text}), jpeg_part(previous), jpeg_part(annotated)];
                let system = self.config.waa_prompts.as_ref().map_or(WAA_SYSTEM_PROMPT, |p| p.system.as_str());
                (system, content)
            }
            NaviStyle::Arena => {
                let mut content = vec![
                    json!({"type": "text", "text": text}),
                    json!({"type": "text", "text": "The current screen, with the elements' numbers:"}),
                    json!({"type": "image_url", "image_url": {"url": data_uri(annotated)}}),
                ];
                if let Some(previous) = &self.previous {
                    content.push(json!({"type": "text", "text": "The screen before your last action:"}));
                    content.push(json!({"type": "image_url", "image_url": {"url": data_uri(previous)}}));
                }
                (SYSTEM_PROMPT, content)
            }
        };
        json!({
            "model": self.config.model,
            "messages": [
                {"role": "system", "content": system},
                {"role": "user", "content": content},
            ],
            "temperature": self.config.temperature,
            self.config.tokens_field.unwrap_or_else(|| TokensField::for_model(&self.config.model)).name(): self.config.max_tokens,
        })
    }

    /// What a step keeps beside the trajectory: the user message (upstream's
    /// `user_question`), the reply (`plan_result`), the annotated image
    /// (`foreground_window_prompt`), the element list with boxes, whether the
    /// tree was cut short, and the request as sent with its images left out.
    fn step_logs(
        &self,
        obs: &Observation,
        marks: Option<&Marks>,
        body: &Value,
        annotated: &Arc<RgbaImage>,
        response: &str,
    ) -> Vec<StepLog> {
        let log = |key: &str, value: LogValue| StepLog { key: key.to_owned(), value };
        let user_question =
            body.pointer("/messages/1/content/0/text").and_then(Value::as_str).unwrap_or_default().to_owned();
        let mut request = body.clone();
        if let Some(parts) = request.pointer_mut("/messages/1/content").and_then(Value::as_array_mut) {
            for part in parts {
                if let Some(url) = part.pointer_mut("/image_url/url") {
                    let size = url.as_str().map_or(0, str::len);
                    *url = Value::String(format!("(an image, {size} bytes of data URI, left out here)"));
                }
            }
        }
        let mut logs = vec![
            // The user message's text as sent, not built a second time.
            log("user_question", LogValue::Text(user_question)),
            log("plan_result", LogValue::Text(response.to_owned())),
            log("request", LogValue::Json(request)),
        ];
        if let Some(marks) = marks {
            logs.push(log("foreground_window_prompt", LogValue::Image(Arc::clone(annotated))));
            logs.push(log("entity_list", LogValue::Json(serde_json::to_value(marks).unwrap_or(Value::Null))));
        }
        if let Some(tree) = &obs.a11y {
            logs.push(log("a11y_truncated", LogValue::Inline(Value::Bool(tree.truncated))));
        }
        logs
    }
}

fn ms(d: Duration) -> u64 {
    u64::try_from(d.as_millis()).unwrap_or(u64::MAX)
}

/// The observation's DOM elements as Set-of-Marks entities (`text/html`; an
/// element without text is listed as upstream lists it).
fn dom_entities(obs: &Observation) -> Vec<ProposedEntity> {
    obs.dom
        .iter()
        .flatten()
        .map(|e| ProposedEntity::dom(e.rect, (!e.text.is_empty()).then(|| e.text.clone())))
        .collect()
}

#[async_trait::async_trait]
impl Agent for NaviAgent {
    fn name(&self) -> &str {
        "navi"
    }

    fn take_usage(&mut self) -> Option<arena_results::ledger::Usage> {
        self.client.take_usage()
    }

    /// Upstream's `oss` pipelines start with the browser's DOM elements.
    fn wants_dom(&self) -> bool {
        self.config.som.origin.needs_dom()
    }

    async fn reset(&mut self, _task: &Task) {
        self.history.clear();
        self.memory.clear();
        self.memory_block = empty_memory(&self.config);
        self.previous = None;
        self.last_error = None;
    }

    async fn predict(&mut self, obs: &Observation) -> Result<Prediction, AgentError> {
        let som_started = Instant::now();
        let marks = self.marks(obs).await?;
        let annotated = match &marks {
            Some(m) => Arc::new(annotate(&obs.screenshot.pixels, m)),
            None => Arc::clone(&obs.screenshot.pixels),
        };
        let som_ms = ms(som_started.elapsed());
        let body = self.request_body(obs, marks.as_ref(), &annotated);
        let model_started = Instant::now();
        let (response, model_tries) = self.client.complete_counted(&body).await?;
        let timings = PredictTimings { som_ms: Some(som_ms), model_ms: Some(ms(model_started.elapsed())), model_tries };
        let logs = self.step_logs(obs, marks.as_ref(), &body, &annotated, &response);
        self.previous = Some(Arc::clone(&obs.screenshot.pixels));
        if self.config.style == NaviStyle::Waa {
            let reply = parse_navi_reply(&response);
            if let Some(block) = reply.memory_block {
                self.memory_block = block;
            }
            self.history.push(Turn { step: obs.step, text: reply.code });
            return Ok(Prediction {
                response,
                actions: reply.actions,
                marks,
                raw_error: None,
                logs,
                timings,
                coords: None,
                usage: None,
            });
        }
        let prediction = match parse_reply(&response) {
            Ok(parsed) => {
                if let Some(memory) = parsed.memory {
                    self.memory = memory;
                }
                let summary: Vec<String> = parsed.actions.iter().map(AgentAction::summary).collect();
                self.history.push(Turn { step: obs.step, text: summary.join(" | ") });
                self.last_error = None;
                Prediction {
                    response,
                    actions: parsed.actions,
                    marks,
                    raw_error: None,
                    logs,
                    timings,
                    coords: None,
                    usage: None,
                }
            }
            Err(err) => {
                tracing::info!(step = obs.step, error = %err, "unusable model reply");
                self.history.push(Turn { step: obs.step, text: format!("(reply not usable: {err})") });
                self.last_error = Some(err.clone());
                Prediction {
                    response,
                    actions: Vec::new(),
                    marks,
                    raw_error: Some(err),
                    logs,
                    timings,
                    coords: None,
                    usage: None,
                }
            }
        };
        Ok(prediction)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use arena_som::SomOrigin;

    #[test]
    fn endpoints() {
        let check = |base: &str, expected: &str| assert_eq!(NaviConfig::new(base, "m").endpoint(), expected);
        check("http://127.0.0.1:8000/v1", "http://127.0.0.1:8000/v1/chat/completions");
        check("http://127.0.0.1:8000/v1/", "http://127.0.0.1:8000/v1/chat/completions");
        check("https://x.example/openai/v1/chat/completions", "https://x.example/openai/v1/chat/completions");
    }

    #[test]
    fn reply_text_reads_strings_and_parts() {
        let check = |answer: Value, expected: Option<&str>| assert_eq!(llm::reply_text(&answer).as_deref(), expected);
        check(json!({"choices": [{"message": {"content": "DONE"}}]}), Some("DONE"));
        check(
            json!({"choices": [{"message": {"content": [{"type": "text", "text": "a"}, {"type": "text", "text": "b"}]}}]}),
            Some("a\nb"),
        );
        check(json!({"choices": []}), None);
        check(json!({"error": "x"}), None);
    }

    #[test]
    fn a_configured_key_wins_over_the_environment() {
        let mut config = NaviConfig::new("http://x/v1", "m");
        config.api_key = Some("configured".into());
        assert_eq!(config.resolved_key().as_deref(), Some("configured"));
    }

    #[tokio::test]
    async fn https_endpoints_are_supported() {
        // Port 9 on loopback has no TLS server: the call must fail while
        // connecting, not because the build cannot speak https.
        let mut config = NaviConfig::new("https://127.0.0.1:9/v1", "m");
        config.timeout = Duration::from_secs(5);
        config.retry = RetryPolicy { give_up_after: Duration::ZERO, ..RetryPolicy::default() };
        let agent = NaviAgent::new(config).expect("agent");
        let err = agent.client.complete(&json!({})).await.expect_err("nothing listens");
        let text = err.to_string();
        assert!(text.contains("https://127.0.0.1:9/v1/chat/completions"), "{text}");
        assert!(!text.contains("scheme is not http"), "{text}");
    }

    #[test]
    fn empty_configuration_is_refused() {
        assert!(matches!(NaviAgent::new(NaviConfig::new("", "m")), Err(AgentError::Config(_))));
    }

    #[test]
    fn a_pixel_som_origin_without_its_service_is_refused() {
        let mut config = NaviConfig::new("http://x/v1", "gpt-4o");
        assert_eq!(config.som.origin, arena_som::SomOrigin::A11y);
        config.som.origin = arena_som::SomOrigin::Omni;
        let Err(AgentError::Config(message)) = NaviAgent::new(config.clone()) else { panic!("accepted") };
        assert!(message.contains("--omniparser-url"), "{message}");
        config.som.omniparser_url = Some("http://127.0.0.1:8000".into());
        assert!(NaviAgent::new(config).is_ok());
    }

    #[test]
    fn oss_origins_ask_for_the_dom_and_list_its_elements_as_upstream() {
        let mut config = NaviConfig::new("http://x/v1", "gpt-4o");
        assert!(!NaviAgent::new(config.clone()).unwrap().wants_dom());
        config.som.detector_url = Some("http://127.0.0.1:9".into());
        for (origin, wants) in [(SomOrigin::Oss, true), (SomOrigin::MixedOss, true), (SomOrigin::A11y, false)] {
            config.som.origin = origin;
            assert_eq!(NaviAgent::new(config.clone()).unwrap().wants_dom(), wants, "{origin}");
        }
        let mut obs = observation();
        assert!(dom_entities(&obs).is_empty());
        let rect = arena_shared::geometry::Rect::new(10, 20, 30, 40);
        obs.dom = Some(vec![
            arena_client::browser::DomElement { rect, text: "Sign in".into(), kind: "BUTTON".into() },
            arena_client::browser::DomElement { rect, text: String::new(), kind: "A".into() },
        ]);
        let entities = dom_entities(&obs);
        assert_eq!(entities, vec![ProposedEntity::dom(rect, Some("Sign in".into())), ProposedEntity::dom(rect, None)]);
        assert_eq!(entities[1].text.as_deref(), Some("None"));
    }

    fn observation() -> Observation {
        Observation {
            step: 1,
            instruction: "do it".into(),
            screenshot: arena_client::frame::Frame::from_pixels(RgbaImage::new(16, 10)),
            screenshot_source: None,
            screen: arena_shared::observation::ScreenInfo {
                physical_width: 1280,
                physical_height: 800,
                logical_width: 1280,
                logical_height: 800,
                scale_factor: 1.0,
                monitors: Vec::new(),
                coordinate_space: arena_shared::geometry::CoordinateSpace::Physical,
            },
            a11y: None,
            window_titles: Vec::new(),
            foreground_title: String::new(),
            foreground_id: None,
            tracked_clipboard: None,
            clipboard: None,
            dom: None,
            timings: Default::default(),
        }
    }

    #[test]
    fn requests_carry_upstreams_sampling_defaults_and_the_right_length_field() {
        let obs = observation();
        let agent = NaviAgent::new(NaviConfig::new("http://x/v1", "gpt-4o")).unwrap();
        let body = agent.request_body(&obs, None, &obs.screenshot.pixels);
        assert_eq!((body["temperature"].clone(), body["max_tokens"].clone()), (json!(1.0), json!(4096)));
        let agent = NaviAgent::new(NaviConfig::new("http://x/v1", "o3-mini")).unwrap();
        let body = agent.request_body(&obs, None, &obs.screenshot.pixels);
        assert!(body.get("max_tokens").is_none() && body["max_completion_tokens"] == json!(4096), "{body}");

        // With a checkout's prompts, its texts are what is sent.
        let root = tempfile::tempdir().unwrap();
        crate::waa_prompts::tests::fake_checkout(root.path());
        let mut config = NaviConfig::new("http://x/v1", "gpt-4o");
        config.waa_prompts = Some(std::sync::Arc::new(WaaPrompts::load(root.path()).unwrap()));
        let agent = NaviAgent::new(config).unwrap();
        let body = agent.request_body(&obs, None, &obs.screenshot.pixels);
        assert_eq!(
            body["messages"][0]["content"],
            "Fake system text for a test.\nIt spans lines, with a brace {kept}."
        );
        let text = body["messages"][1]["content"][0]["text"].as_str().unwrap();
        assert!(
            text.starts_with("Goal: do it\n")
                && text.contains("Clip: nothing copied")
                && text.contains("# blank notes"),
            "{text}"
        );
        // The clipboard shown is the one the agent's computer tracks, not the system's.
        let tracked =
            Observation { tracked_clipboard: Some("tracked".into()), clipboard: Some("system".into()), ..obs.clone() };
        let body = agent.request_body(&tracked, None, &tracked.screenshot.pixels);
        let text = body["messages"][1]["content"][0]["text"].as_str().unwrap();
        assert!(text.contains("Clip: tracked\n") && !text.contains("system"), "{text}");
    }
}
