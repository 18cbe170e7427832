//! The host side of the arena (`arena-host`): the glue of the benchmark harness
//! (the episode loop, runs over a pool of guests) and the `arena` command line,
//! on top of the host's lower layers, each a crate of its own: `arena-client`
//! (the guest client, its errors, the screenshot frame, the guest's browser, the
//! download cache), `arena-actionspace` (the grammars agents answer in),
//! `arena-exec` (the executor of what agents and setup steps want done),
//! `arena-task` (task files), `arena-eval` (getters and metrics), `arena-setup`
//! (setup steps and the reset), `arena-results` (result folders, summaries, the
//! report), `arena-vm` (QEMU VMs, golden images, the OEM folder), `arena-som`
//! (Set-of-Marks) and `arena-agents` (the agents and the observation they see). Nothing of theirs is re-exported here: callers, tests and benches
//! name the crate they use.
//!
//! It is not the guest server (see `arena-guest`, which this crate embeds only with
//! its default `stub-guest` feature, for `arena serve-stub`, `run --stub-guests` and
//! a self-contained `arena demo`), it does not speak the legacy WAA routes, and it
//! serves HTTP only with its default `mcp-endpoint` and `env-server` features (`arena run --agent mcp`, `arena env serve`).
//!
//! # Layout
//!
//! - `mcp` (feature `mcp-endpoint`): the MCP endpoint of `arena run --agent mcp`, where an outside agent drives each episode.
//! - [`episode`]: one episode: reset, setup, the observe/act loop, evaluation.
//! - `envserve` (feature `env-server`): `arena env serve`, episodes a program drives over HTTP (reset, step, evaluate).
//! - [`run`]: task lists, shards, the pool of guests, merging shards.
//! - `driver`: `arena run`'s driver: a resolved plan prepared, its guests started (stub guests, VMs), the preflight, the options recorded and checked, the tasks played.
//! - [`cli`]: the `arena` command line (`main.rs` only parses and calls [`run`]).

#![forbid(unsafe_code)]

pub mod cli;
pub mod driver;
#[cfg(feature = "env-server")]
pub mod envserve;
pub mod episode;
#[cfg(feature = "mcp-endpoint")]
pub mod mcp;
pub mod run;

pub use cli::{run, Cli};
