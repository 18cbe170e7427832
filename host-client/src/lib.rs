//! The host side of the arena: a typed client of the guest's native API and
//! the `arena` command line built on it.
//!
//! It is not the guest server (see `arena-guest`, which this crate embeds only
//! to offer `arena serve-stub` and a self-contained `arena demo`), and it does
//! not speak the legacy WAA routes.
//!
//! # Layout
//!
//! - [`client`]: [`client::GuestClient`], one async method per `/v1/` route,
//!   with deadlines, retries of idempotent calls and a readiness wait.
//! - [`cli`]: the `arena` command line (`main.rs` only parses and calls [`run`]).
//! - [`error`]: [`error::ClientError`], which always names the guest, the call and the cause.
//! - [`pyaction`]: agents' pyautogui code translated into typed actions.

pub mod agent;
pub mod cli;
pub mod client;
pub mod episode;
pub mod error;
pub mod eval;
pub mod prep;
pub mod pyaction;
pub mod results;
pub mod run;
pub mod setup;
pub mod som;
pub mod task;

pub use client::{ClientConfig, GuestClient};
pub use error::ClientError;

pub use cli::{run, Cli};
