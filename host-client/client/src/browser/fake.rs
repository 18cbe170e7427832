//! A fake DevTools endpoint for tests, speaking the real protocol: the HTTP
//! endpoints (`json/version`, `json/list`, `PUT json/new`, `json/close/<id>`)
//! with `webSocketDebuggerUrl`s, and a websocket per page answering JSON-RPC
//! commands by id (`Runtime.evaluate` of the host's own scripts,
//! `Page.navigate`), with an event sent before every answer to show that
//! clients skip them.
//!
//! It cannot run JavaScript: it recognises the scripts this crate sends and
//! answers what the page it models would.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::{Path, RawQuery, State};
use axum::response::Response;
use axum::routing::{get, put};
use axum::{Json, Router};
use serde_json::{json, Value};

use super::dom::DOM_SCRIPT;
use super::page::{READ_SCRIPT, STATE_SCRIPT};

/// One page the fake browser shows.
#[derive(Debug, Clone, Default)]
pub struct FakePage {
    pub id: String,
    pub title: String,
    pub url: String,
    pub html: String,
    /// What the DOM extraction script answers on this page.
    pub dom: Value,
}

/// What the fake knows: its pages, the sites `Page.navigate` can reach
/// (address to title and HTML), and every method it was sent.
#[derive(Debug, Default)]
pub struct FakeState {
    pub pages: Vec<FakePage>,
    pub sites: HashMap<String, (String, String)>,
    pub methods: Vec<String>,
    next: u32,
    port: u16,
}

pub type Shared = Arc<Mutex<FakeState>>;

/// A running fake; it stops with the test's runtime.
#[derive(Debug)]
pub struct FakeDevtools {
    pub port: u16,
    pub state: Shared,
}

impl FakeDevtools {
    /// Serves `pages` (front page first) on `127.0.0.1:0`.
    pub async fn start(pages: Vec<FakePage>, sites: &[(&str, &str, &str)]) -> FakeDevtools {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.expect("bind the fake devtools");
        let port = listener.local_addr().expect("addr").port();
        let sites = sites
            .iter()
            .map(|(url, title, html)| ((*url).to_owned(), ((*title).to_owned(), (*html).to_owned())))
            .collect();
        let state = Arc::new(Mutex::new(FakeState { pages, sites, port, ..FakeState::default() }));
        let app = Router::new()
            .route("/json/version", get(version))
            .route("/json/list", get(list))
            .route("/json", get(list))
            .route("/json/new", put(new))
            .route("/json/close/{id}", get(close))
            .route("/devtools/page/{id}", get(socket))
            .with_state(Arc::clone(&state));
        tokio::spawn(async move { axum::serve(listener, app).await });
        FakeDevtools { port, state }
    }

    /// The ids of the open pages, front first.
    pub fn page_ids(&self) -> Vec<String> {
        self.state.lock().expect("fake state").pages.iter().map(|p| p.id.clone()).collect()
    }

    /// Every method received so far.
    pub fn methods(&self) -> Vec<String> {
        self.state.lock().expect("fake state").methods.clone()
    }
}

fn target(page: &FakePage, port: u16) -> Value {
    json!({
        "id": page.id, "type": "page", "title": page.title, "url": page.url, "description": "",
        "devtoolsFrontendUrl": format!("/devtools/inspector.html?ws=127.0.0.1:{port}/devtools/page/{}", page.id),
        "webSocketDebuggerUrl": format!("ws://127.0.0.1:{port}/devtools/page/{}", page.id),
    })
}

async fn version(State(state): State<Shared>) -> Json<Value> {
    let port = state.lock().expect("fake state").port;
    Json(
        json!({"Browser": "FakeChrome/1.0", "Protocol-Version": "1.3", "webSocketDebuggerUrl": format!("ws://127.0.0.1:{port}/devtools/browser/fake")}),
    )
}

async fn list(State(state): State<Shared>) -> Json<Value> {
    let state = state.lock().expect("fake state");
    let mut targets: Vec<Value> = state.pages.iter().map(|p| target(p, state.port)).collect();
    targets.push(json!({"id": "SW", "type": "service_worker", "title": "sw", "url": "https://example.org/sw.js"}));
    Json(Value::Array(targets))
}

async fn new(State(state): State<Shared>, RawQuery(url): RawQuery) -> Json<Value> {
    let mut state = state.lock().expect("fake state");
    state.next += 1;
    let url = url.filter(|u| !u.is_empty()).unwrap_or_else(|| "about:blank".into());
    let page = FakePage { id: format!("NEW{}", state.next), title: url.clone(), url, ..FakePage::default() };
    let answer = target(&page, state.port);
    state.pages.insert(0, page);
    Json(answer)
}

async fn close(State(state): State<Shared>, Path(id): Path<String>) -> &'static str {
    state.lock().expect("fake state").pages.retain(|p| p.id != id);
    "Target is closing"
}

async fn socket(State(state): State<Shared>, Path(id): Path<String>, upgrade: WebSocketUpgrade) -> Response {
    upgrade.on_upgrade(move |socket| serve_page(socket, state, id))
}

async fn serve_page(mut socket: WebSocket, state: Shared, id: String) {
    while let Some(Ok(message)) = socket.recv().await {
        let Message::Text(text) = message else { continue };
        let Ok(command) = serde_json::from_str::<Value>(text.as_str()) else { continue };
        let call_id = command["id"].clone();
        let method = command["method"].as_str().unwrap_or_default().to_owned();
        let answer = answer(&state, &id, &method, &command["params"]);
        let event = json!({"method": "Runtime.consoleAPICalled", "params": {"type": "log", "args": []}});
        let mut reply = json!({"id": call_id});
        match answer {
            Ok(result) => reply["result"] = result,
            Err((code, message)) => reply["error"] = json!({"code": code, "message": message}),
        }
        if socket.send(Message::Text(event.to_string().into())).await.is_err()
            || socket.send(Message::Text(reply.to_string().into())).await.is_err()
        {
            break;
        }
    }
}

fn answer(state: &Shared, id: &str, method: &str, params: &Value) -> Result<Value, (i64, String)> {
    let mut state = state.lock().expect("fake state");
    state.methods.push(method.to_owned());
    let sites = state.sites.clone();
    let page = state.pages.iter_mut().find(|p| p.id == id).ok_or((-32000, "No target with given id".to_owned()))?;
    match method {
        "Page.navigate" => {
            let url = params["url"].as_str().unwrap_or_default().to_owned();
            match sites.get(&url) {
                Some((title, html)) => {
                    page.url = url;
                    page.title.clone_from(title);
                    page.html.clone_from(html);
                    Ok(json!({"frameId": "F1", "loaderId": "L1"}))
                }
                None => Ok(json!({"frameId": "F1", "errorText": "net::ERR_NAME_NOT_RESOLVED"})),
            }
        }
        "Runtime.evaluate" => {
            let expression = params["expression"].as_str().unwrap_or_default();
            let value = if expression == DOM_SCRIPT {
                page.dom.clone()
            } else if expression == READ_SCRIPT {
                json!({"title": page.title, "url": page.url, "content": page.html})
            } else if expression == STATE_SCRIPT {
                json!(["complete", page.url])
            } else {
                return Ok(json!({
                    "result": {"type": "object", "subtype": "error"},
                    "exceptionDetails": {"text": "Uncaught", "exception": {"description": "ReferenceError: the fake runs no other script"}},
                }));
            };
            Ok(json!({"result": {"type": "object", "value": value}}))
        }
        other => Err((-32601, format!("'{other}' wasn't found"))),
    }
}
