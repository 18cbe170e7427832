//! The chat-completions client agents use: OpenAI-compatible and classic Azure
//! OpenAI endpoints, and retries that survive real endpoints.
//!
//! - **Endpoints.** [`ApiKind::OpenAi`]: `/chat/completions` is appended to the
//!   base URL's path (before any query string) and the key goes in
//!   `Authorization: Bearer`. [`ApiKind::Azure`] (a deployment URL such as
//!   `https://NAME.openai.azure.com/openai/deployments/DEPLOYMENT?api-version=…`,
//!   WAA's own set-up): the same path rule, the `api-version` query kept, the
//!   key in the `api-key` header. [`ApiKind::detect`] tells them apart.
//! - **Retries.** 408, 409, 429 and 5xx answers, timeouts, connection errors and
//!   an answer cut short (a body that is not JSON) are tried again with
//!   exponential backoff and full jitter, waiting at least what `Retry-After`
//!   asks, until [`RetryPolicy::give_up_after`] has passed. Any other 4xx (a
//!   bad key, a bad request) fails at once. A model that is still failing
//!   then is an [`AgentError::Model`], which leaves the task unfinished.
//! - **A refusal** (`message.refusal` with no content) leaves the task
//!   unfinished by default ([`Refusals::Unfinished`], [`AgentError::Refused`]),
//!   as upstream's Navi, which reads only `content`, cannot go on without one.
//!   [`Refusals::Answer`] (`--refusals answer`, recorded in the results) takes its
//!   text as a reply without actions instead, so the task is scored.
//! - **Other JSON APIs.** [`ModelClient::with_url`] posts to a URL as given and
//!   [`ModelClient::call`] answers the whole JSON reply with the same retries:
//!   the computer-use agents speak Anthropic's Messages API ([`ApiKind::Anthropic`]:
//!   the key in `x-api-key`, extra headers by [`ModelClient::with_header`]) and
//!   OpenAI's Responses API through it.
//!
//! The retry loop is written here rather than taken from a crate because its
//! one unusual need, a per-error minimum delay from `Retry-After`, is most of
//! its dozen lines.

use std::time::Duration;

use rand::Rng as _;
use reqwest::header::{HeaderMap, RETRY_AFTER};
use serde_json::Value;

use super::body::error_chain;
use super::AgentError;

/// Which API the endpoint speaks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ApiKind {
    /// OpenAI and compatible servers (vLLM, llama.cpp, Ollama, ...): Bearer auth.
    OpenAi,
    /// Classic Azure OpenAI: a deployment URL with `api-version`, `api-key` auth.
    Azure,
    /// Anthropic's API: the key in `x-api-key`.
    Anthropic,
}

impl ApiKind {
    /// Azure for a `*.openai.azure.com` host or a URL with an `api-version` query; OpenAI otherwise.
    pub fn detect(base_url: &str) -> ApiKind {
        match reqwest::Url::parse(base_url) {
            Ok(url)
                if url.host_str().is_some_and(|h| h.ends_with(".openai.azure.com"))
                    || url.query_pairs().any(|(k, _)| k == "api-version") =>
            {
                ApiKind::Azure
            }
            _ => ApiKind::OpenAi,
        }
    }
}

/// What a run does about a model endpoint where nothing answers (the connection
/// refused, the host name not resolving): `--llm-unreachable`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Unreachable {
    /// The preflight stops the run before any task; during the run, once a call has
    /// waited its whole retry window for it, later calls give up at their first
    /// refused try, and after [`EndpointDown::STOP_AFTER`] such calls in a row no
    /// new task starts (those left are unfinished, and the run says why).
    #[default]
    Stop,
    /// Every call waits its whole retry window, as for any other failure.
    Wait,
}

impl Unreachable {
    /// `stop` or `wait`.
    pub fn name(self) -> &'static str {
        match self {
            Unreachable::Stop => "stop",
            Unreachable::Wait => "wait",
        }
    }
}

/// Whether a run's model endpoint is down for good, shared by every client made
/// from one run's agent options (clones share it), so that a dead endpoint ends the
/// run instead of costing each task its whole retry window ([`Unreachable`]).
#[derive(Debug, Clone, Default)]
pub struct EndpointDown(std::sync::Arc<DownState>);

#[derive(Debug, Default)]
struct DownState {
    policy: Unreachable,
    /// Calls in a row, over all clients, that gave up with nothing answering.
    given_up: std::sync::atomic::AtomicU32,
    /// Why the run starts no new task, once it is so.
    why: std::sync::OnceLock<String>,
    tripped: tokio::sync::Notify,
}

impl PartialEq for EndpointDown {
    /// The same shared state.
    fn eq(&self, other: &EndpointDown) -> bool {
        std::sync::Arc::ptr_eq(&self.0, &other.0)
    }
}

impl EndpointDown {
    /// Calls in a row that give up with the endpoint unreachable before the run
    /// starts no new task: the first waits its retry window, the others fail at once.
    pub const STOP_AFTER: u32 = 3;

    /// A fresh state with `policy`.
    pub fn new(policy: Unreachable) -> EndpointDown {
        EndpointDown(std::sync::Arc::new(DownState { policy, ..DownState::default() }))
    }

    /// The policy it was made with.
    pub fn policy(&self) -> Unreachable {
        self.0.policy
    }

    /// Why no new task may start, once the endpoint is down for good.
    pub fn why(&self) -> Option<&str> {
        self.0.why.get().map(String::as_str)
    }

    /// Resolves, with the reason, when the endpoint is found down for good.
    pub async fn tripped(&self) -> String {
        loop {
            // Registered before the check, so a trip in between is not missed.
            let notified = self.0.tripped.notified();
            if let Some(why) = self.why() {
                return why.to_owned();
            }
            notified.await;
        }
    }

    /// Whether an earlier call already gave up with nothing answering (and none answered since).
    fn gave_up_before(&self) -> bool {
        self.0.policy == Unreachable::Stop && self.0.given_up.load(std::sync::atomic::Ordering::SeqCst) > 0
    }

    /// A call gave up with nothing answering at `endpoint`.
    fn gave_up(&self, endpoint: &str, reason: &str) {
        if self.0.policy == Unreachable::Wait {
            return;
        }
        let calls = self.0.given_up.fetch_add(1, std::sync::atomic::Ordering::SeqCst) + 1;
        if calls >= Self::STOP_AFTER {
            let why = format!(
                "the model endpoint {endpoint} did not answer in {calls} calls in a row ({reason}); no new task starts (--llm-unreachable wait keeps trying)"
            );
            if self.0.why.set(why).is_ok() {
                self.0.tripped.notify_waiters();
            }
        }
    }

    /// A call was answered: the count starts again.
    fn answered(&self) {
        self.0.given_up.store(0, std::sync::atomic::Ordering::SeqCst);
    }
}

/// How long and how often a failing call is tried again.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RetryPolicy {
    /// The first pause; each later one doubles, up to `max_delay`.
    pub initial_delay: Duration,
    pub max_delay: Duration,
    /// No new try starts once the pauses between tries would exceed this.
    pub give_up_after: Duration,
}

impl Default for RetryPolicy {
    /// 1 s doubling to 60 s, for up to 5 minutes (upstream retries about 30
    /// times with 1 to 60 s pauses).
    fn default() -> RetryPolicy {
        RetryPolicy {
            initial_delay: Duration::from_secs(1),
            max_delay: Duration::from_secs(60),
            give_up_after: Duration::from_secs(300),
        }
    }
}

/// Which request field carries the answer's length limit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TokensField {
    /// `max_tokens`, what chat models take.
    MaxTokens,
    /// `max_completion_tokens`, what reasoning models (o1, o3, o4, gpt-5) require.
    MaxCompletionTokens,
}

impl TokensField {
    /// The field a model needs, judged by its name.
    pub fn for_model(model: &str) -> TokensField {
        let name = model.rsplit('/').next().unwrap_or(model).to_ascii_lowercase();
        if ["o1", "o3", "o4", "gpt-5"].iter().any(|p| name.starts_with(p)) {
            TokensField::MaxCompletionTokens
        } else {
            TokensField::MaxTokens
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            TokensField::MaxTokens => "max_tokens",
            TokensField::MaxCompletionTokens => "max_completion_tokens",
        }
    }
}

/// What a refusal (`message.refusal` without content) does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Refusals {
    /// The task is left unfinished, as upstream leaves it.
    #[default]
    Unfinished,
    /// The refusal's text is the reply: the step has no action and the task is scored.
    Answer,
}

impl Refusals {
    /// The name recorded in the results (`unfinished`, `answer`).
    pub fn name(self) -> &'static str {
        match self {
            Refusals::Unfinished => "unfinished",
            Refusals::Answer => "answer",
        }
    }
}

/// A chat-completions endpoint and how to call it.
#[derive(Debug, Clone)]
pub struct ModelClient {
    refusals: Refusals,
    kind: ApiKind,
    endpoint: String,
    key: Option<String>,
    http: reqwest::Client,
    retry: RetryPolicy,
    clock: std::sync::Arc<dyn arena_setup::Clock>,
    /// Headers sent with every request besides the key (`anthropic-version`, `anthropic-beta`).
    headers: Vec<(String, String)>,
    /// The tokens and time of the answers since the last [`ModelClient::take_usage`].
    usage: UsageMeter,
    /// The run's view of the endpoint being down, shared with the run's other clients.
    down: EndpointDown,
}

/// What a client's answers cost since it was last read; a clone starts from
/// nothing, so two agents made from one client never count each other's calls.
#[derive(Debug, Default)]
struct UsageMeter(std::sync::Mutex<Option<super::Usage>>);

impl Clone for UsageMeter {
    fn clone(&self) -> UsageMeter {
        UsageMeter::default()
    }
}

impl UsageMeter {
    fn add(&self, usage: &super::Usage) {
        let mut total = self.0.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        total.get_or_insert_with(super::Usage::default).add(usage);
    }

    fn take(&self) -> Option<super::Usage> {
        self.0.lock().unwrap_or_else(std::sync::PoisonError::into_inner).take()
    }
}

/// Why one try failed, and whether another may succeed.
struct Failure {
    reason: String,
    transient: bool,
    /// The least the server asked us to wait (`Retry-After`).
    wait_at_least: Option<Duration>,
    /// The model refused, with this text ([`Refusals::Unfinished`]).
    refused: Option<String>,
    /// Nothing answered: the connection was refused or the host name did not resolve.
    unreachable: bool,
}

/// An image as a data URL (`data:<mime>;base64,<bytes>`), as every vendor's API
/// takes an inline image: the one place the URL is built.
pub fn image_data_url(mime: &str, bytes: &[u8]) -> String {
    use base64::Engine as _;
    format!("data:{mime};base64,{}", base64::engine::general_purpose::STANDARD.encode(bytes))
}

/// The most of a model's answer that is read: the step protocol's limit on an agent's
/// answer ([`super::body::MAX_ANSWER`]). Vendors' answers are kilobytes; a larger one
/// is an endpoint gone wrong.
pub const MAX_MODEL_ANSWER: usize = super::body::MAX_ANSWER;

/// How much of an error page is read (its first 300 characters are shown).
const ERROR_SHOWN: usize = 4096;

impl ModelClient {
    /// A client for `base_url` (see the module documentation for the two kinds).
    ///
    /// # Errors
    ///
    /// [`AgentError::Config`] for a URL that does not parse or an HTTP client that cannot be built.
    pub fn new(
        base_url: &str,
        kind: ApiKind,
        key: Option<String>,
        timeout: Duration,
        retry: RetryPolicy,
    ) -> Result<ModelClient, AgentError> {
        ModelClient::with_url(&chat_endpoint(base_url)?, kind, key, timeout, retry)
    }

    /// A client that posts to `url` as it is (no path added).
    ///
    /// # Errors
    ///
    /// [`AgentError::Config`] for a URL that does not parse or an HTTP client that cannot be built.
    pub fn with_url(
        url: &str,
        kind: ApiKind,
        key: Option<String>,
        timeout: Duration,
        retry: RetryPolicy,
    ) -> Result<ModelClient, AgentError> {
        let endpoint = reqwest::Url::parse(url.trim())
            .map_err(|e| AgentError::Config(format!("the model's URL {url:?} is not a URL: {e}")))?
            .to_string();
        let http = reqwest::Client::builder()
            .timeout(timeout)
            .build()
            .map_err(|e| AgentError::Config(format!("cannot build the HTTP client: {e}")))?;
        Ok(ModelClient {
            refusals: Refusals::default(),
            kind,
            endpoint,
            key,
            http,
            retry,
            clock: std::sync::Arc::new(arena_setup::RealClock),
            headers: Vec::new(),
            usage: UsageMeter::default(),
            down: EndpointDown::default(),
        })
    }

    /// The same client sharing `down` with the run's other clients ([`Unreachable`]).
    #[must_use]
    pub fn with_down(mut self, down: EndpointDown) -> ModelClient {
        self.down = down;
        self
    }

    /// The same client sending `name: value` with every request.
    #[must_use]
    pub fn with_header(mut self, name: &str, value: &str) -> ModelClient {
        self.headers.push((name.to_owned(), value.to_owned()));
        self
    }

    /// The same client with refusals handled as `refusals` says.
    #[must_use]
    pub fn with_refusals(mut self, refusals: Refusals) -> ModelClient {
        self.refusals = refusals;
        self
    }

    /// The same client with its pauses between tries on `clock` (a test's fake clock).
    #[must_use]
    pub fn with_clock(mut self, clock: std::sync::Arc<dyn arena_setup::Clock>) -> ModelClient {
        self.clock = clock;
        self
    }

    /// The URL requests go to.
    pub fn endpoint(&self) -> &str {
        &self.endpoint
    }

    /// The tokens and model time of the answers since the last call (`None`
    /// when no answer said its `usage`): what the agent reports for its step.
    pub fn take_usage(&self) -> Option<super::Usage> {
        self.usage.take()
    }

    /// Sends `body` and answers the reply's text, trying again as the policy says.
    ///
    /// # Errors
    ///
    /// [`AgentError::Model`] naming the last failure when no try succeeded.
    pub async fn complete(&self, body: &Value) -> Result<String, AgentError> {
        self.complete_counted(body).await.map(|(text, _)| text)
    }

    /// [`ModelClient::complete`], with the number of tries it took.
    ///
    /// # Errors
    ///
    /// [`AgentError::Model`] naming the last failure when no try succeeded;
    /// [`AgentError::Refused`] for a refusal under [`Refusals::Unfinished`].
    pub async fn complete_counted(&self, body: &Value) -> Result<(String, u32), AgentError> {
        let (answer, tries) = self.call_counted(body, true).await?;
        // A chat answer without its text is refused by `try_once`, so this is never empty by omission.
        Ok((reply_text(&answer).unwrap_or_default(), tries))
    }

    /// Sends `body` and answers the reply's JSON, trying again as the policy says
    /// (the computer-use agents' Messages and Responses APIs).
    ///
    /// # Errors
    ///
    /// [`AgentError::Model`] naming the last failure when no try succeeded.
    pub async fn call(&self, body: &Value) -> Result<Value, AgentError> {
        self.call_counted(body, false).await.map(|(answer, _)| answer)
    }

    /// The retry loop: the reply's JSON and the number of tries; `chat` checks
    /// the chat-completions reply (a refusal, its text).
    async fn call_counted(&self, body: &Value, chat: bool) -> Result<(Value, u32), AgentError> {
        let mut waited = Duration::ZERO;
        let mut delay = self.retry.initial_delay;
        let mut tries = 0u32;
        loop {
            tries += 1;
            let started = std::time::Instant::now();
            let failure = match self.try_once(body, chat).await {
                Ok(answer) => {
                    let mut usage = super::Usage::of_response(&answer).unwrap_or_default();
                    usage.model_ms = started.elapsed().as_millis() as u64;
                    self.usage.add(&usage);
                    self.down.answered();
                    return Ok((answer, tries));
                }
                Err(failure) => failure,
            };
            if let Some(text) = failure.refused {
                return Err(AgentError::Refused { endpoint: self.endpoint.clone(), text });
            }
            if failure.unreachable && self.down.gave_up_before() {
                // An earlier call waited its whole window for this endpoint and
                // nothing has answered since: this one does not wait again.
                self.down.gave_up(&self.endpoint, &failure.reason);
                let why = self.down.why().map_or_else(String::new, |why| format!("; {why}"));
                return Err(AgentError::Model {
                    endpoint: self.endpoint.clone(),
                    reason: format!(
                        "{} (still nothing answering after an earlier call's whole retry window){why}",
                        failure.reason
                    ),
                });
            }
            let pause = rand::rng().random_range(Duration::ZERO..=delay).max(failure.wait_at_least.unwrap_or_default());
            // Time spent waiting counts against the budget (the tries themselves are
            // bounded by the call timeout), so a fake clock sees the same decisions.
            if !failure.transient || waited + pause > self.retry.give_up_after {
                let why = if failure.transient { format!(" (gave up after {tries} tries)") } else { String::new() };
                if failure.unreachable {
                    self.down.gave_up(&self.endpoint, &failure.reason);
                }
                return Err(AgentError::Model {
                    endpoint: self.endpoint.clone(),
                    reason: format!("{}{why}", failure.reason),
                });
            }
            tracing::warn!(endpoint = %self.endpoint, reason = %failure.reason, tries, pause_ms = pause.as_millis() as u64, "model call failed; trying again");
            self.clock.sleep(pause, "before trying the model again").await;
            waited += pause;
            delay = (delay * 2).min(self.retry.max_delay);
        }
    }

    /// One minimal request before a run's first task (`arena run`'s preflight),
    /// never tried again: `Err` naming the endpoint and status when it answers
    /// 401, 403 or 404 (a wrong key, model or URL, which no retry mends), or when
    /// nothing answers there and the policy is [`Unreachable::Stop`];
    /// `Ok(Some(note))` for any other failure (the run goes on and its own calls
    /// retry as usual); `Ok(None)` when it answered.
    ///
    /// # Errors
    ///
    /// The endpoint refused the key or does not exist, in words.
    pub async fn preflight(&self, body: &Value) -> Result<Option<String>, String> {
        let response = match self.request(body).send().await {
            Ok(response) => response,
            Err(err) if err.is_connect() && self.down.policy() == Unreachable::Stop => {
                return Err(format!(
                    "nothing answers at the model endpoint {}: {} (is the model server running and the URL right? --llm-unreachable wait goes on anyway)",
                    self.endpoint,
                    error_chain(&err)
                ));
            }
            Err(err) => return Ok(Some(format!("{}: {}", self.endpoint, error_chain(&err)))),
        };
        let status = response.status();
        if status.is_success() {
            return Ok(None);
        }
        let start = super::body::read_bounded(response, "the model's", ERROR_SHOWN, true).await.unwrap_or_default();
        let snippet: String = String::from_utf8_lossy(&start).chars().take(300).collect();
        let said = format!("{} answered HTTP {status}: {snippet}", self.endpoint);
        match status.as_u16() {
            401 | 403 => {
                Err(format!("{said} (is the key right? it comes from ARENA_LLM_KEY or the agent's own variable)"))
            }
            404 => Err(format!("{said} (is the URL or the model name right?)")),
            _ => Ok(Some(said)),
        }
    }

    /// The request of `body` with the key and the extra headers.
    fn request(&self, body: &Value) -> reqwest::RequestBuilder {
        let mut request = self.http.post(&self.endpoint).json(body);
        if let Some(key) = &self.key {
            request = match self.kind {
                ApiKind::OpenAi => request.bearer_auth(key),
                ApiKind::Azure => request.header("api-key", key),
                ApiKind::Anthropic => request.header("x-api-key", key),
            };
        }
        for (name, value) in &self.headers {
            request = request.header(name, value);
        }
        request
    }

    async fn try_once(&self, body: &Value, chat: bool) -> Result<Value, Failure> {
        let request = self.request(body);
        let transient = |reason: String| Failure {
            reason,
            transient: true,
            wait_at_least: None,
            refused: None,
            unreachable: false,
        };
        let response =
            request.send().await.map_err(|e| Failure { unreachable: e.is_connect(), ..transient(error_chain(&e)) })?;
        let status = response.status();
        let wait_at_least = retry_after(response.headers());
        // An answer past the limit is refused (not tried again: the endpoint would
        // send another); of an error page only the start is read.
        let (limit, cut) = if status.is_success() { (MAX_MODEL_ANSWER, false) } else { (ERROR_SHOWN, true) };
        let body = match super::body::read_bounded(response, "the model's", limit, cut).await {
            Ok(body) => body,
            Err(super::body::BodyError::Read(err)) => return Err(transient(err)),
            Err(err @ super::body::BodyError::TooLong { .. }) => {
                return Err(Failure {
                    reason: err.to_string(),
                    transient: false,
                    wait_at_least: None,
                    refused: None,
                    unreachable: false,
                });
            }
        };
        if !status.is_success() {
            let snippet: String = String::from_utf8_lossy(&body).chars().take(300).collect();
            let code = status.as_u16();
            return Err(Failure {
                reason: format!("HTTP {status}: {snippet}"),
                transient: matches!(code, 408 | 409 | 429) || status.is_server_error(),
                wait_at_least,
                refused: None,
                unreachable: false,
            });
        }
        let value: Value = serde_json::from_slice(&body)
            .map_err(|e| transient(format!("the answer is not JSON (cut short?): {e}")))?;
        if !chat {
            return Ok(value);
        }
        if self.refusals == Refusals::Unfinished {
            if let Some(text) = refusal(&value) {
                return Err(Failure {
                    reason: format!("refused: {text}"),
                    transient: false,
                    wait_at_least: None,
                    refused: Some(text),
                    unreachable: false,
                });
            }
        }
        if reply_text(&value).is_none() {
            return Err(Failure {
                reason: "the answer has no choices[0].message.content".into(),
                transient: false,
                wait_at_least: None,
                refused: None,
                unreachable: false,
            });
        }
        Ok(value)
    }
}

/// The chat-completions URL of a base URL: `/chat/completions` added to the
/// path unless it is there, any query string (Azure's `api-version`) kept.
///
/// # Errors
///
/// [`AgentError::Config`] when `base_url` is not a URL.
pub fn chat_endpoint(base_url: &str) -> Result<String, AgentError> {
    let mut url = reqwest::Url::parse(base_url.trim())
        .map_err(|e| AgentError::Config(format!("the model's base URL {base_url:?} is not a URL: {e}")))?;
    let path = url.path().trim_end_matches('/').to_owned();
    if !path.ends_with("/chat/completions") {
        url.set_path(&format!("{path}/chat/completions"));
    }
    Ok(url.to_string())
}

/// `Retry-After` in seconds (the HTTP-date form is rare from model APIs and is ignored).
fn retry_after(headers: &HeaderMap) -> Option<Duration> {
    let text = headers.get(RETRY_AFTER)?.to_str().ok()?;
    let secs: f64 = text.trim().parse().ok()?;
    Duration::try_from_secs_f64(secs).ok()
}

/// The refusal's text when `choices[0].message` holds a refusal and no content.
fn refusal(answer: &Value) -> Option<String> {
    let message = answer.get("choices")?.get(0)?.get("message")?;
    match message.get("content") {
        Some(Value::String(_) | Value::Array(_)) => None,
        _ => message.get("refusal").and_then(Value::as_str).map(str::to_owned),
    }
}

/// `choices[0].message.content`, as a string or as a list of text parts; a
/// refusal without content gives the refusal's text.
pub(crate) fn reply_text(answer: &Value) -> Option<String> {
    let message = answer.get("choices")?.get(0)?.get("message")?;
    match message.get("content") {
        Some(Value::String(s)) => Some(s.clone()),
        Some(Value::Array(parts)) => {
            Some(parts.iter().filter_map(|p| p.get("text").and_then(Value::as_str)).collect::<Vec<_>>().join("\n"))
        }
        _ => message.get("refusal").and_then(Value::as_str).map(str::to_owned),
    }
}

#[cfg(test)]
mod tests;
