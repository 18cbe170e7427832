//! The host side of the arena (`arena-host`): the glue of the benchmark harness
//! (agents, the episode loop, runs over a pool of guests) and the `arena` command
//! line, on top of the host's lower layers, each a crate of its own:
//! `arena-client` (the guest client, its errors, the screenshot frame, the
//! guest's browser, the download cache), `arena-actionspace` (the grammars agents
//! answer in), `arena-exec` (the executor of what agents and setup steps want
//! done), `arena-task` (task files), `arena-eval` (getters and metrics),
//! `arena-setup` (setup steps and the reset), `arena-results` (result folders,
//! summaries, the report) and `arena-vm` (QEMU VMs, golden images, the OEM
//! folder). Nothing of theirs is re-exported here: callers, tests and benches
//! name the crate they use.
//!
//! It is not the guest server (see `arena-guest`, which this crate embeds only with
//! its default `stub-guest` feature, for `arena serve-stub`, `run --stub-guests` and
//! a self-contained `arena demo`), it does not speak the legacy WAA routes, and it
//! serves HTTP only with its default `mcp-endpoint` and `env-server` features (`arena run --agent mcp`, `arena env serve`).
//!
//! # Layout
//!
//! - [`ports`]: the episode's observation port: the observation builder (its action port is `arena-exec`).
//! - [`som`]: Set-of-Marks from every source of upstream's `--som_origin`: the accessibility tree, OCR, the DOM, a detector, OmniParser and their mixes.
//! - [`agent`]: the agent trait; Navi, scripted, replay and computer-use agents; outside agents over the step protocol; the factory of a run's agent.
//! - `mcp` (feature `mcp-endpoint`): the MCP endpoint of `arena run --agent mcp`, where an outside agent drives each episode.
//! - [`episode`]: one episode: reset, setup, the observe/act loop, evaluation.
//! - `envserve` (feature `env-server`): `arena env serve`, episodes a program drives over HTTP (reset, step, evaluate).
//! - [`run`]: task lists, shards, the pool of guests, merging shards.
//! - [`cli`]: the `arena` command line (`main.rs` only parses and calls [`run`]).

#![forbid(unsafe_code)]

pub mod agent;
pub mod cli;
#[cfg(feature = "env-server")]
pub mod envserve;
pub mod episode;
#[cfg(feature = "mcp-endpoint")]
pub mod mcp;
pub mod ports;
pub mod run;
pub mod som;

pub use cli::{run, Cli};
