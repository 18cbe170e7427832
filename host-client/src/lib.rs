//! The host side of the arena: a typed client of the guest's native API, the
//! benchmark harness on top of it (tasks, setup, agents, episodes, evaluation,
//! results, runs over a pool of guests), and the `arena` command line.
//!
//! It is not the guest server (see `arena-guest`, which this crate embeds only with
//! its default `stub-guest` feature, for `arena serve-stub`, `run --stub-guests` and
//! a self-contained `arena demo`), and it does not speak the legacy WAA routes.
//!
//! # Layout
//!
//! - [`browser`]: the guest's browser over the DevTools protocol (DOM elements, page contents).
//! - [`client`]: [`client::GuestClient`], one async method per `/v1/` route,
//!   with deadlines, retries of idempotent calls and a readiness wait.
//! - [`error`]: [`error::ClientError`], which always names the guest, the call and the cause.
//! - [`task`]: WAA task files, read in two layers (raw mirror, validated task).
//! - [`setup`]: the tasks' setup steps over the guest API, and the download cache.
//! - [`agent`]: the agent trait; Navi, scripted and replay agents; outside agents over the step protocol; running agent code.
//! - [`mcp`]: the MCP endpoint of `arena run --agent mcp`, where an outside agent drives each episode.
//! - [`som`]: Set-of-Marks from every source of upstream's `--som_origin`: the accessibility tree, OCR, the DOM, a detector, OmniParser and their mixes.
//! - [`actionspace`]: the grammars agents answer in (pyautogui, `computer_13`, Anthropic's and OpenAI's computer actions, UI-TARS) translated into typed actions.
//! - [`episode`]: one episode: reset, setup, the observe/act loop, evaluation.
//! - [`eval`]: getters and metrics by closed registries.
//! - [`results`]: result folders in upstream's layout, the summary and the HTML report.
//! - [`run`]: task lists, shards, the pool of guests, merging shards.
//! - [`prep`]: staging a Windows image's OEM folder and waiting for its guest.
//! - [`vm`]: Windows VMs run with QEMU: overlays of a golden image, QMP, snapshots per task, screendumps, golden images from an ISO.
//! - [`cli`]: the `arena` command line (`main.rs` only parses and calls [`run`]).

pub mod actionspace;
pub mod agent;
pub mod browser;
pub mod cli;
pub mod client;
pub mod episode;
pub mod error;
pub mod eval;
pub mod mcp;
pub mod prep;
pub mod results;
pub mod run;
pub mod setup;
pub mod som;
pub mod task;
pub mod vm;

pub use client::{ClientConfig, GuestClient};
pub use error::ClientError;

pub use cli::{run, Cli};
