//! The end-to-end suites of `arena-tests` as one test binary: each module is
//! one suite (its file says what it covers). One binary links the guest, the
//! host and their dependencies once, where a binary per file linked them 26
//! times; tests are named `SUITE::TEST` (`cargo test -p arena-tests --test
//! suite -- mcp::` runs one suite).
//!
//! The Wine suites (`wine`, `wine_prep`, run by scripts/wine-test.sh) and the
//! live-desktop suite (the Windows workflow) stay binaries of their own: they
//! are run alone, with an environment of their own.

pub mod action_errors;
pub mod agent_protocol;
pub mod agent_s3;
pub mod agent_sandbox;
pub mod blame;
pub mod certify;
pub mod desktop_tree;
pub mod e2e_client;
pub mod env_serve;
pub mod episodes;
pub mod equivalence;
pub mod gold;
pub mod guest_bounds;
pub mod hostile_agent;
pub mod hostile_pyautogui;
pub mod interrupt;
pub mod ledger;
pub mod mcp;
pub mod preflight;
pub mod progress;
pub mod resume_guard;
pub mod tidy;
pub mod trajectory_viewer;
pub mod trials;
pub mod uitars_parity;
pub mod vm;
pub mod waa_episode;
