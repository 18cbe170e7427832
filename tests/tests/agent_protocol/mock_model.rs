//! A chat-completions endpoint for tests and benches: answers every request with
//! one fixed reply and keeps each request body, in order.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpListener;
use std::sync::{Arc, Mutex};

/// A running mock: its base URL (`http://ADDR/v1`) and the bodies it was sent.
#[derive(Debug, Clone)]
pub(crate) struct MockModel {
    pub(crate) url: String,
    pub(crate) requests: Arc<Mutex<Vec<serde_json::Value>>>,
}

/// Starts a mock whose every answer's content is `reply`.
///
/// # Errors
///
/// No loopback port.
pub(crate) fn start(reply: &str) -> std::io::Result<MockModel> {
    let listener = TcpListener::bind("127.0.0.1:0")?;
    let url = format!("http://{}/v1", listener.local_addr()?);
    let requests = Arc::new(Mutex::new(Vec::new()));
    let answer = serde_json::json!({
        "id": "mock", "object": "chat.completion", "model": "mock",
        "choices": [{"index": 0, "finish_reason": "stop", "message": {"role": "assistant", "content": reply}}],
        "usage": {"prompt_tokens": 1, "completion_tokens": 1, "total_tokens": 2}
    })
    .to_string();
    let kept = Arc::clone(&requests);
    std::thread::spawn(move || {
        for stream in listener.incoming().flatten() {
            let (answer, kept) = (answer.clone(), Arc::clone(&kept));
            std::thread::spawn(move || serve(stream, &answer, &kept));
        }
    });
    Ok(MockModel { url, requests })
}

fn serve(stream: std::net::TcpStream, answer: &str, kept: &Mutex<Vec<serde_json::Value>>) {
    let mut reader = BufReader::new(stream);
    loop {
        let mut length = 0usize;
        let mut line = String::new();
        loop {
            line.clear();
            if reader.read_line(&mut line).unwrap_or(0) == 0 {
                return;
            }
            if let Some(v) = line.to_ascii_lowercase().strip_prefix("content-length:") {
                length = v.trim().parse().unwrap_or(0);
            }
            if line == "\r\n" {
                break;
            }
        }
        let mut body = vec![0; length];
        if reader.read_exact(&mut body).is_err() {
            return;
        }
        if let (Ok(value), Ok(mut kept)) = (serde_json::from_slice(&body), kept.lock()) {
            kept.push(value);
        }
        let response = format!(
            "HTTP/1.1 200 OK\r\nContent-Type: application/json\r\nContent-Length: {}\r\n\r\n{answer}",
            answer.len()
        );
        if reader.get_mut().write_all(response.as_bytes()).is_err() {
            return;
        }
    }
}
