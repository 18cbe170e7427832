//! Test helpers shared by every crate's tests: the one home for "start a guest"
//! and for "skip loudly when something is absent".
//!
//! - [`StubGuest`] (feature `guest`, on by default): the one way a test starts an
//!   in-process stub guest on `127.0.0.1:0`, with the real router, stopped on drop.
//! - [`Served`]: the real `arena-guest` (or `arena`) binary as a child process on
//!   port 0, for end-to-end tests and bench binaries; [`workspace_binary`] builds it.
//! - [`waa_corpus`]: where the upstream WAA task corpus is, or a loud, counted skip.
//! - [`wine_or_skip`]: the Wine pieces the Windows-backend suite needs, or a loud skip.
//! - [`standin_image`]: the QEMU stand-in guest image and `qemu-system-x86_64`, or a
//!   loud, counted skip.
//! - [`python_with_mcp`]: a Python with the official MCP SDK, or a loud, counted skip.
//! - [`chromium_or_skip`]: a headless Chromium, or a loud skip; [`Chromium`] (feature
//!   `guest`) starts it with DevTools on a free port.
//! - [`eventually`] (feature `guest`): polling a condition until it holds or a deadline passes.
//! - [`skip`] and [`program_or_skip`]: the one way a test says it was skipped (a
//!   counted line, or a failure under its `ARENA_REQUIRE_*` switch).
//! - [`png_claiming`]: a PNG header claiming any size, for the image guards; [`pdf_showing`]: a one-page PDF for the metric tests.
//! - [`copy_stub_task`]: a stub task with its host-side gold, copied for a test.
//! - [`bwrap_or_skip`] and [`exec_sandbox_args`]: the exec agents' sandbox (bubblewrap).
//!
//! It is not product code, and it does not depend on `arena-host`: the host's own
//! tests use it, and a dependency back on the host would build the host twice.
//! The launchers hand back a URL, never a client, so each test builds the client
//! of the crate it tests.
//!
//! Layout: `guest.rs` (in-process launcher), `process.rs` (child-process launcher),
//! `chromium.rs` (Chromium locator and launcher), `corpus.rs` (corpus locator), `wine.rs` (Wine locator), `standin.rs` (stand-in
//! image locator), `mcp_sdk.rs` (MCP SDK locator), `wait.rs` (polling), `png.rs` (PNG bombs), `pdf.rs` (a one-page PDF), `skip.rs` (skip lines),
//! `stub_tasks.rs` (the stub tasks), `sandbox.rs` (bubblewrap).

#![forbid(unsafe_code)]

mod chromium;
mod corpus;
#[cfg(feature = "guest")]
mod guest;
mod mcp_sdk;
mod pdf;
mod png;
mod process;
mod sandbox;
mod skip;
mod standin;
mod stub_tasks;
#[cfg(feature = "guest")]
mod wait;
mod wine;

#[cfg(feature = "guest")]
pub use chromium::Chromium;
pub use chromium::{chromium_or_skip, find_chromium, CHROMIUM_VAR, REQUIRE_CHROMIUM_VAR};
pub use corpus::{waa_corpus, CORPUS_VAR, REQUIRE_CORPUS_VAR};
#[cfg(feature = "guest")]
pub use guest::StubGuest;
pub use mcp_sdk::{python_with_mcp, MCP_PYTHON_VAR, MCP_SDK, MCP_SDK_SKIP, REQUIRE_MCP_SDK_VAR};
pub use pdf::pdf_showing;
pub use png::png_claiming;
pub use process::{
    agent_pythonpath, bench_guests, gui_agents_python_or_skip, python3_or_skip, workspace_binary, workspace_root,
    PythonNeed, Served, BENCH_GUESTS_VAR, GUI_AGENTS,
};
pub use sandbox::{bwrap_or_skip, exec_sandbox_args, REQUIRE_BWRAP_VAR};
pub use skip::{program_or_skip, skip, SKIP_PREFIX, UPSTREAM_CHECKOUT_SKIP};
pub use standin::{standin_image, StandinImage, REQUIRE_QEMU_VAR, STANDIN_DIR_VAR};
pub use stub_tasks::{copy_stub_task, stub_tasks_dir};
#[cfg(feature = "guest")]
pub use wait::eventually;
pub use wine::{wine_or_skip, WineSetup};
