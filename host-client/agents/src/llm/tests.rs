//! The model client against a local mock endpoint (a real HTTP server) that
//! answers from a script: 429s with and without `Retry-After`, 500s, slow and
//! cut-short answers, refusals, a bad key; and Azure's URL and header.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex};

use axum::extract::{Request, State};
use axum::http::{HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use serde_json::json;

use super::*;

/// One scripted answer: status, `Retry-After`, body, and how long to wait first.
#[derive(Clone)]
struct Answer {
    status: u16,
    retry_after: Option<&'static str>,
    body: String,
    delay: Duration,
}

fn ok(text: &str) -> Answer {
    let body = json!({"choices": [{"message": {"role": "assistant", "content": text}}]}).to_string();
    Answer { status: 200, retry_after: None, body, delay: Duration::ZERO }
}

fn status(code: u16, retry_after: Option<&'static str>) -> Answer {
    Answer { status: code, retry_after, body: format!("{{\"error\": \"{code}\"}}"), delay: Duration::ZERO }
}

#[derive(Default)]
struct Mock {
    script: Mutex<VecDeque<Answer>>,
    /// (path and query, headers) of each request.
    seen: Mutex<Vec<(String, HeaderMap)>>,
}

async fn answer(State(mock): State<Arc<Mock>>, request: Request) -> Response {
    let target = request.uri().path_and_query().map(ToString::to_string).unwrap_or_default();
    mock.seen.lock().unwrap().push((target, request.headers().clone()));
    let next = mock.script.lock().unwrap().pop_front().unwrap_or_else(|| status(599, None));
    tokio::time::sleep(next.delay).await;
    let mut response = (StatusCode::from_u16(next.status).unwrap(), next.body).into_response();
    if let Some(after) = next.retry_after {
        response.headers_mut().insert("retry-after", after.parse().unwrap());
    }
    response
}

/// A mock endpoint answering `script`; its base URL (`http://127.0.0.1:PORT{path}`).
async fn serve(script: Vec<Answer>, path: &str) -> (String, Arc<Mock>) {
    let mock = Arc::new(Mock { script: Mutex::new(script.into()), seen: Mutex::default() });
    let app = axum::Router::new().fallback(answer).with_state(Arc::clone(&mock));
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    tokio::spawn(async move { axum::serve(listener, app).await.unwrap() });
    (format!("http://{addr}{path}"), mock)
}

/// Records the pauses between tries instead of sleeping.
#[derive(Debug, Default)]
struct Pauses(Mutex<Vec<Duration>>);

#[async_trait::async_trait]
impl arena_setup::Clock for Pauses {
    async fn sleep(&self, d: Duration, _why: &'static str) {
        self.0.lock().unwrap().push(d);
    }
}

fn model(base: &str, kind: ApiKind, timeout: Duration, retry: RetryPolicy) -> (ModelClient, Arc<Pauses>) {
    let pauses = Arc::new(Pauses::default());
    let client =
        ModelClient::new(base, kind, Some("sk-test".into()), timeout, retry).unwrap().with_clock(pauses.clone());
    (client, pauses)
}

fn body() -> Value {
    json!({"model": "m", "messages": [{"role": "user", "content": "hi"}]})
}

#[test]
fn endpoints_keep_the_query_and_add_the_path_once() {
    let check = |base: &str, want: &str| assert_eq!(chat_endpoint(base).unwrap(), want, "{base}");
    check("https://api.openai.com/v1", "https://api.openai.com/v1/chat/completions");
    check("http://127.0.0.1:8000/v1/", "http://127.0.0.1:8000/v1/chat/completions");
    check("http://h/v1/chat/completions", "http://h/v1/chat/completions");
    check(
        "https://lab.openai.azure.com/openai/deployments/gpt-4o?api-version=2024-02-01",
        "https://lab.openai.azure.com/openai/deployments/gpt-4o/chat/completions?api-version=2024-02-01",
    );
    assert!(matches!(chat_endpoint("not a url"), Err(AgentError::Config(m)) if m.contains("not a URL")));
    assert_eq!(ApiKind::detect("https://lab.openai.azure.com/openai/deployments/d"), ApiKind::Azure);
    assert_eq!(ApiKind::detect("https://proxy.example/openai/deployments/d?api-version=2024-02-01"), ApiKind::Azure);
    assert_eq!(ApiKind::detect("https://api.openai.com/v1"), ApiKind::OpenAi);
    assert_eq!(TokensField::for_model("o3-mini"), TokensField::MaxCompletionTokens);
    assert_eq!(TokensField::for_model("openai/gpt-5"), TokensField::MaxCompletionTokens);
    assert_eq!(TokensField::for_model("gpt-4o"), TokensField::MaxTokens);
}

#[tokio::test]
async fn rate_limits_and_server_errors_are_waited_out_honouring_retry_after() {
    let script = vec![status(429, Some("7")), status(429, None), status(500, None), status(503, Some("2")), ok("fine")];
    let (base, mock) = serve(script, "/v1").await;
    let retry = RetryPolicy {
        initial_delay: Duration::from_secs(1),
        max_delay: Duration::from_secs(4),
        ..RetryPolicy::default()
    };
    let (client, pauses) = model(&base, ApiKind::OpenAi, Duration::from_secs(10), retry);
    assert_eq!(client.complete(&body()).await.unwrap(), "fine");
    let pauses = pauses.0.lock().unwrap().clone();
    assert_eq!(pauses.len(), 4, "{pauses:?}");
    assert!(pauses[0] >= Duration::from_secs(7), "Retry-After: 7 is honoured: {pauses:?}");
    // Full jitter under a doubling cap: at most 2 s, then 4 s (the cap).
    assert!(pauses[1] <= Duration::from_secs(2) && pauses[2] <= Duration::from_secs(4), "{pauses:?}");
    assert!(pauses[3] >= Duration::from_secs(2), "{pauses:?}");
    let seen = mock.seen.lock().unwrap();
    assert_eq!(seen.len(), 5);
    assert_eq!(seen[0].0, "/v1/chat/completions");
    assert_eq!(seen[0].1.get("authorization").unwrap(), "Bearer sk-test");
}

#[tokio::test]
async fn slow_and_cut_short_answers_are_tried_again_and_a_refusal_leaves_the_task_unfinished() {
    let refusal = || Answer {
        body: json!({"choices": [{"message": {"content": null, "refusal": "I can't help with that."}}]}).to_string(),
        ..ok("")
    };
    let slow = Answer { delay: Duration::from_secs(3), ..ok("late") };
    let cut = Answer { body: r#"{"choices": [{"message": {"content": "par"#.into(), ..ok("") };
    let (base, mock) = serve(vec![slow, cut, refusal()], "/v1").await;
    let (client, pauses) = model(&base, ApiKind::OpenAi, Duration::from_millis(300), RetryPolicy::default());
    // Upstream's Navi reads only `content`: a refusal leaves the task unfinished, asked once.
    let err = client.complete(&body()).await.unwrap_err();
    assert!(matches!(&err, AgentError::Refused { text, .. } if text == "I can't help with that."), "{err:?}");
    assert_eq!(mock.seen.lock().unwrap().len(), 3);
    assert_eq!(pauses.0.lock().unwrap().len(), 2);

    // `--refusals answer`: the refusal's text is the reply.
    let (base, _mock) = serve(vec![refusal()], "/v1").await;
    let (client, _) = model(&base, ApiKind::OpenAi, Duration::from_secs(5), RetryPolicy::default());
    let client = client.with_refusals(Refusals::Answer);
    assert_eq!(client.complete_counted(&body()).await.unwrap(), ("I can't help with that.".to_owned(), 1));
}

#[tokio::test]
async fn a_bad_key_fails_at_once_and_a_model_that_stays_down_gives_up_with_the_reason() {
    let (base, mock) = serve(vec![status(401, None)], "/v1").await;
    let (client, pauses) = model(&base, ApiKind::OpenAi, Duration::from_secs(5), RetryPolicy::default());
    let err = client.complete(&body()).await.unwrap_err().to_string();
    assert!(err.contains("401") && !err.contains("gave up"), "{err}");
    assert_eq!((mock.seen.lock().unwrap().len(), pauses.0.lock().unwrap().len()), (1, 0));

    let (base, mock) = serve(vec![status(503, None); 50], "/v1").await;
    let retry = RetryPolicy {
        initial_delay: Duration::from_secs(1),
        max_delay: Duration::from_secs(60),
        give_up_after: Duration::from_secs(30),
    };
    let (client, pauses) = model(&base, ApiKind::OpenAi, Duration::from_secs(5), retry);
    let err = client.complete(&body()).await.unwrap_err();
    let AgentError::Model { reason, .. } = &err else { panic!("{err:?}") };
    assert!(reason.contains("503") && reason.contains("gave up after"), "{reason}");
    let waited: Duration = pauses.0.lock().unwrap().iter().sum();
    assert!(waited <= Duration::from_secs(30), "the budget holds: {waited:?}");
    assert!(mock.seen.lock().unwrap().len() >= 2);
}

#[tokio::test]
async fn azure_deployments_get_their_path_query_and_api_key_header() {
    let (base, mock) = serve(vec![ok("azure")], "/openai/deployments/gpt-4o?api-version=2024-02-01").await;
    assert_eq!(ApiKind::detect(&base), ApiKind::Azure);
    let (client, _) = model(&base, ApiKind::detect(&base), Duration::from_secs(5), RetryPolicy::default());
    assert_eq!(client.complete(&body()).await.unwrap(), "azure");
    let seen = mock.seen.lock().unwrap();
    assert_eq!(seen[0].0, "/openai/deployments/gpt-4o/chat/completions?api-version=2024-02-01");
    assert_eq!(seen[0].1.get("api-key").unwrap(), "sk-test");
    assert!(seen[0].1.get("authorization").is_none());
}

/// A model endpoint whose answer never ends (chunked, a MiB of JSON whitespace at a
/// time), or that announces a gigabyte: the answer is refused at its limit, once,
/// without the host holding more than the limit.
#[tokio::test]
async fn an_endless_or_huge_answer_is_refused_at_the_limit_and_not_asked_again() {
    use std::sync::atomic::{AtomicUsize, Ordering};
    let asked = Arc::new(AtomicUsize::new(0));
    let sent = Arc::new(AtomicUsize::new(0));
    let app = axum::Router::new().route(
        "/endless/chat/completions",
        axum::routing::post({
            let (asked, sent) = (Arc::clone(&asked), Arc::clone(&sent));
            move || async move {
                asked.fetch_add(1, Ordering::Relaxed);
                let chunk = axum::body::Bytes::from(vec![b' '; 1 << 20]);
                let stream = futures_util::stream::repeat_with(move || {
                    sent.fetch_add(chunk.len(), Ordering::Relaxed);
                    Ok::<_, std::convert::Infallible>(chunk.clone())
                });
                Response::new(axum::body::Body::from_stream(stream))
            }
        }),
    );
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let endless = listener.local_addr().unwrap();
    tokio::spawn(async move { axum::serve(listener, app).await.unwrap() });
    // A gigabyte announced and never sent: written by hand, since hyper's server will
    // not send a length its body does not have.
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let announced = listener.local_addr().unwrap();
    tokio::spawn({
        let asked = Arc::clone(&asked);
        async move {
            use tokio::io::{AsyncReadExt as _, AsyncWriteExt as _};
            let mut held = Vec::new();
            while let Ok((mut conn, _)) = listener.accept().await {
                asked.fetch_add(1, Ordering::Relaxed);
                let mut request = [0u8; 4096];
                let _ = conn.read(&mut request).await;
                let _ = conn.write_all(b"HTTP/1.1 200 OK\r\ncontent-length: 1073741824\r\n\r\n{}").await;
                held.push(conn);
            }
        }
    });

    for (path, addr) in [("endless", endless), ("announced", announced)] {
        asked.store(0, Ordering::Relaxed);
        let (client, pauses) =
            model(&format!("http://{addr}/{path}"), ApiKind::OpenAi, Duration::from_secs(60), RetryPolicy::default());
        let err = client.complete(&body()).await.unwrap_err();
        let AgentError::Model { reason, .. } = &err else { panic!("{path}: {err:?}") };
        assert!(reason.contains("the model's answer is longer than 64 MiB"), "{path}: {reason}");
        assert_eq!((asked.load(Ordering::Relaxed), pauses.0.lock().unwrap().len()), (1, 0), "{path}: asked once");
    }
    // The endless answer was read to its limit and no further (plus what was in flight).
    let sent = sent.load(Ordering::Relaxed);
    assert!((MAX_MODEL_ANSWER..MAX_MODEL_ANSWER + (32 << 20)).contains(&sent), "{sent} bytes sent");
}

/// A base URL on a loopback port where nothing listens (bound, then let go).
fn closed_base() -> String {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = listener.local_addr().unwrap().port();
    drop(listener);
    format!("http://127.0.0.1:{port}/v1")
}

#[tokio::test]
async fn a_dead_endpoint_costs_one_retry_window_then_calls_give_up_at_once_and_the_run_is_told() {
    let retry = RetryPolicy {
        initial_delay: Duration::from_secs(1),
        max_delay: Duration::from_secs(4),
        give_up_after: Duration::from_secs(20),
    };
    let down = EndpointDown::new(Unreachable::Stop);
    let (client, pauses) = model(&closed_base(), ApiKind::OpenAi, Duration::from_secs(5), retry);
    let client = client.with_down(down.clone());
    // The first call waits out its window, as for any failure.
    let err = client.complete(&body()).await.unwrap_err().to_string();
    assert!(err.contains("gave up after"), "{err}");
    let first = pauses.0.lock().unwrap().len();
    assert!(first >= 2, "retried: {first}");
    assert_eq!(down.why(), None, "one call is not the endpoint down for good");
    // A second client of the same run (another task's agent) does not wait again.
    let (other, other_pauses) = model(&closed_base(), ApiKind::OpenAi, Duration::from_secs(5), retry);
    let other = other.with_down(down.clone());
    let err = other.complete(&body()).await.unwrap_err().to_string();
    assert!(err.contains("still nothing answering"), "{err}");
    assert!(other_pauses.0.lock().unwrap().is_empty(), "no pause: {:?}", other_pauses.0.lock().unwrap());
    assert_eq!(down.why(), None);
    // The third call in a row ends the run's new tasks, and says why.
    let tripped = tokio::spawn({
        let down = down.clone();
        async move { down.tripped().await }
    });
    let err = other.complete(&body()).await.unwrap_err().to_string();
    assert!(err.contains("no new task starts"), "{err}");
    let why = tokio::time::timeout(Duration::from_secs(10), tripped).await.expect("tripped in time").unwrap();
    assert!(why.contains("did not answer in 3 calls in a row") && why.contains("127.0.0.1"), "{why}");

    // An answer in between starts the count again.
    let down = EndpointDown::new(Unreachable::Stop);
    let (dead, _) = model(&closed_base(), ApiKind::OpenAi, Duration::from_secs(5), retry);
    let dead = dead.with_down(down.clone());
    let (base, _mock) = serve(vec![ok("back")], "/v1").await;
    let (alive, _) = model(&base, ApiKind::OpenAi, Duration::from_secs(5), retry);
    let alive = alive.with_down(down.clone());
    dead.complete(&body()).await.unwrap_err();
    dead.complete(&body()).await.unwrap_err();
    assert_eq!(alive.complete(&body()).await.unwrap(), "back");
    let err = dead.complete(&body()).await.unwrap_err().to_string();
    assert!(err.contains("gave up after"), "a full window again after an answer: {err}");
    assert_eq!(down.why(), None);

    // `--llm-unreachable wait`: every call waits its window and nothing trips.
    let down = EndpointDown::new(Unreachable::Wait);
    let (client, pauses) = model(&closed_base(), ApiKind::OpenAi, Duration::from_secs(5), retry);
    let client = client.with_down(down.clone());
    for _ in 0..3 {
        let err = client.complete(&body()).await.unwrap_err().to_string();
        assert!(err.contains("gave up after"), "{err}");
    }
    assert!(pauses.0.lock().unwrap().len() >= 6);
    assert_eq!(down.why(), None);
}

#[tokio::test]
async fn the_preflight_stops_at_a_dead_endpoint_unless_told_to_wait() {
    let base = closed_base();
    let (client, _) = model(&base, ApiKind::OpenAi, Duration::from_secs(5), RetryPolicy::default());
    let err = client.with_down(EndpointDown::new(Unreachable::Stop)).preflight(&body()).await.unwrap_err();
    assert!(err.contains("nothing answers at the model endpoint") && err.contains("--llm-unreachable wait"), "{err}");
    let (client, _) = model(&base, ApiKind::OpenAi, Duration::from_secs(5), RetryPolicy::default());
    let note = client.with_down(EndpointDown::new(Unreachable::Wait)).preflight(&body()).await.unwrap();
    assert!(note.is_some_and(|n| n.contains("127.0.0.1")));
}
