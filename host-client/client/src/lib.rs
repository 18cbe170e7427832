//! The host's client of one guest (`arena-client`): the lowest host layer, which
//! every other host crate reaches the guest through.
//!
//! It is the typed client of the guest's native `/v1/` API, the one error type
//! of its calls (with the one rule for "the guest is out of reach"), the frame a
//! screenshot is decoded into once, and the guest's browser over the DevTools
//! protocol. It is not the benchmark harness (tasks, setup, agents, episodes:
//! `arena-host` and the crates between), it does not speak the legacy WAA routes,
//! and it serves nothing (the fake DevTools endpoint of its tests is behind the
//! `fake-devtools` feature).
//!
//! # Layout
//!
//! - [`client`]: [`client::GuestClient`], one async method per `/v1/` route,
//!   with deadlines, retries of idempotent calls and a readiness wait.
//! - [`error`]: [`error::ClientError`], which always names the guest, the call and the cause;
//!   [`error::ClientError::out_of_reach`].
//! - [`frame`]: [`frame::Frame`], a screenshot decoded once, and the host's one PNG decoder and encoder.
//! - [`browser`]: the guest's browser over the DevTools protocol (DOM elements, page contents).
//! - [`cache`]: [`cache::DownloadCache`], the host's content-addressed store of the files
//!   setup steps download and getters read from the cloud (below both, which share it).

#![forbid(unsafe_code)]

pub mod browser;
pub mod cache;
pub mod client;
pub mod error;
pub mod frame;

pub use cache::{CacheError, DownloadCache};
pub use client::{ClientConfig, GuestClient};
pub use error::ClientError;
pub use frame::Frame;
