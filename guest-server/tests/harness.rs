//! What the route suites share: a stub desktop at 1440x900 (the size they
//! assume) whose drives live in a folder the test owns, and one request sent to
//! a router without a socket (`tower::ServiceExt::oneshot`), answered whole.

use std::path::Path;

use axum::body::{Body, Bytes};
use axum::http::{HeaderMap, Request, StatusCode};
use axum::Router;
use http_body_util::BodyExt as _;
use tower::ServiceExt as _;

use arena_guest::desktop::stub::{Scenario, StubConfig, StubDesktop};

/// A stub desktop at 1440x900 whose drives are mapped into `root`, seeded by
/// `scenario`; `host_exec` lets commands that are none of its simulated
/// programs run for real.
pub fn stub_in(root: &Path, scenario: Option<Scenario>, host_exec: bool) -> StubDesktop {
    StubDesktop::with_config(StubConfig {
        root: Some(root.into()),
        screen: (1440, 900),
        scenario,
        host_exec,
        ..StubConfig::default()
    })
    .expect("a stub desktop over a temporary folder")
}

/// Sends `request` to `router`: the status, the headers and the whole body.
pub async fn send(router: &Router, request: Request<Body>) -> (StatusCode, HeaderMap, Bytes) {
    let response = router.clone().oneshot(request).await.expect("the router is infallible");
    let status = response.status();
    let headers = response.headers().clone();
    let body = response.into_body().collect().await.expect("the body is read whole").to_bytes();
    (status, headers, body)
}
