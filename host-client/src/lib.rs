//! The host side of the arena (`arena-host`): the benchmark harness (agents, the
//! episode loop, results, runs over a pool of guests, Windows VMs) and the `arena`
//! command line, on top of the host's lower layers, each a crate of its own:
//! `arena-client` (the guest client, its errors, the screenshot frame, the
//! guest's browser), `arena-actionspace` (the grammars agents answer in),
//! `arena-task` (task files), `arena-eval` (getters, metrics, the download cache)
//! and `arena-setup` (setup steps and the reset). They are re-exported here under
//! their module names ([`client`], [`actionspace`], [`task`], [`eval`],
//! [`setup`], ...) for callers outside; this crate's own modules import them directly.
//!
//! It is not the guest server (see `arena-guest`, which this crate embeds only with
//! its default `stub-guest` feature, for `arena serve-stub`, `run --stub-guests` and
//! a self-contained `arena demo`), it does not speak the legacy WAA routes, and it
//! serves HTTP only with its default `mcp-endpoint` and `env-server` features (`arena run --agent mcp`, `arena env serve`).
//!
//! # Layout
//!
//! - [`ports`]: the episode's two ports to the guest: the observation builder and the action executor.
//! - [`som`]: Set-of-Marks from every source of upstream's `--som_origin`: the accessibility tree, OCR, the DOM, a detector, OmniParser and their mixes.
//! - [`agent`]: the agent trait; Navi, scripted, replay and computer-use agents; outside agents over the step protocol; the factory of a run's agent.
//! - `mcp` (feature `mcp-endpoint`): the MCP endpoint of `arena run --agent mcp`, where an outside agent drives each episode.
//! - [`episode`]: one episode: reset, setup, the observe/act loop, evaluation.
//! - `envserve` (feature `env-server`): `arena env serve`, episodes a program drives over HTTP (reset, step, evaluate).
//! - [`results`]: result folders in upstream's layout, the summary and the HTML report.
//! - [`run`]: task lists, shards, the pool of guests, merging shards.
//! - [`oem`]: staging a Windows image's OEM folder and waiting for its guest.
//! - [`vm`]: Windows VMs run with QEMU: overlays of a golden image, QMP, snapshots per task, screendumps, golden images from an ISO.
//! - [`cli`]: the `arena` command line (`main.rs` only parses and calls [`run`]).

#![deny(unsafe_code)]

pub mod agent;
pub mod cli;
#[cfg(feature = "env-server")]
pub mod envserve;
pub mod episode;
#[cfg(feature = "mcp-endpoint")]
pub mod mcp;
pub mod oem;
pub mod ports;
pub mod results;
pub mod run;
pub mod som;
// A module with `unsafe`: libc calls for the QEMU processes (prctl, kill, access).
// The other is `agent::external::windows`: Win32 calls for an exec agent's job object.
#[allow(unsafe_code)]
pub mod vm;

pub use arena_actionspace as actionspace;
pub use arena_client::{browser, client, error, frame};
pub use arena_client::{ClientConfig, ClientError, GuestClient};
pub use arena_eval as eval;
pub use arena_setup as setup;
pub use arena_task as task;

pub use cli::{run, Cli};
