//! A lean HTTP/1.1 client for the mixed workload: one kept-alive connection per client
//! over hyper's connection API, each answer read whole and its status checked, nothing
//! decoded. It spends a fraction of the CPU that the host's `GuestClient` spends (a
//! connection pool, retries, JSON decoding), so on a machine whose cores the clients
//! share with the guest, more of them go to the guest being measured.

use std::time::{Duration, Instant};

use anyhow::Context;
use arena_shared::action::{Action, ActionBatch};
use http_body_util::{BodyExt as _, Full};
use hyper::body::Bytes;

/// The request of kind `kind` (an index into [`super::KINDS`]), the `n`th of its client.
fn request(authority: &str, kind: usize, n: usize) -> anyhow::Result<hyper::Request<Full<Bytes>>> {
    let get =
        |path: &str| hyper::Request::get(path).header(hyper::header::HOST, authority).body(Full::new(Bytes::new()));
    Ok(match kind {
        0 => get("/v1/health")?,
        1 => get("/v1/screen")?,
        2 => {
            let batch = ActionBatch { actions: vec![Action::MoveTo { x: (n % 1400) as i32, y: 300 }] };
            hyper::Request::post("/v1/actions")
                .header(hyper::header::HOST, authority)
                .header(hyper::header::CONTENT_TYPE, "application/json")
                .body(Full::new(Bytes::from(serde_json::to_vec(&batch)?)))?
        }
        3 => get("/v1/files/stat?path=C%3A%5CUsers%5CDocker%5CDesktop")?,
        _ => get("/v1/a11y?foreground_only=true")?,
    })
}

/// One client's loop over its own connection until `until`: each answer's kind and
/// latency, and the number of errors (a status other than 200 counts as one).
pub(crate) async fn client_loop(
    addr: String,
    until: Instant,
    id: usize,
) -> anyhow::Result<(Vec<(usize, Duration)>, usize)> {
    let stream = tokio::net::TcpStream::connect(&addr).await.with_context(|| format!("connecting to {addr}"))?;
    stream.set_nodelay(true)?;
    let (mut sender, connection) =
        hyper::client::conn::http1::handshake(hyper_util::rt::TokioIo::new(stream)).await.context("handshake")?;
    let driver = tokio::spawn(connection);
    let (mut latencies, mut errors) = (Vec::new(), 0);
    let mut n = id;
    while Instant::now() < until {
        let kind = n % super::KINDS.len();
        let request = request(&addr, kind, n)?;
        let started = Instant::now();
        sender.ready().await.context("the connection closed")?;
        let answer = sender.send_request(request).await.context("sending a request")?;
        let ok = answer.status() == hyper::StatusCode::OK;
        answer.into_body().collect().await.context("reading an answer")?;
        if ok {
            latencies.push((kind, started.elapsed()));
        } else {
            errors += 1;
        }
        n += 1;
    }
    drop(sender);
    let _ = driver.await;
    Ok((latencies, errors))
}
