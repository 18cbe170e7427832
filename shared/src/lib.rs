//! The wire vocabulary both sides of the arena speak, and every decision both sides
//! share.
//!
//! This crate is the only place that derives serde for types that cross the
//! guest/host boundary: typed input actions, observations (screen, windows,
//! accessibility), exec requests and results, file operations, the staged
//! health report and the one error body. Beside the types it holds the rules the
//! guest and the host must apply alike (key names, command lines, Windows paths,
//! listing order, image crops and encodings, tokens, the MCP tool table), so that
//! each is written once.
//! Its only I/O is on the local file system and environment, where both sides must
//! behave alike: [`atomic`] writes files, [`ntfs`] lists folders, [`search_path`] looks
//! for a program on `PATH`. It knows nothing of HTTP, Windows APIs or tokio.
//!
//! # Layout
//!
//! - [`geometry`]: points and rectangles in a named coordinate space.
//! - [`action`]: the [`action::Action`] enum and mouse buttons.
//! - [`keys`]: pyautogui key names and chord parsing; [`vkeys`]: their Windows virtual-key codes.
//! - [`input_log`]: the input recorder's log lines (what its window received).
//! - [`observation`]: screen, screenshot, window and accessibility types.
//! - [`exec`], [`files`], [`clipboard`], [`registry`]: request and result types.
//! - [`clock`]: the guest's wall clock, read and set (after a snapshot restore).
//! - [`eval`]: the evaluation queries under `/v1/eval/`.
//! - [`fastimg`]: upstream's model-image size, a SIMD resize and a SIMD JPEG encoder.
//! - [`health`]: the staged readiness report; [`doctor`]: the end-to-end capability report.
//! - [`error`]: the error body every native route answers with.
//! - [`window_list`]: the window list and title the model is shown, as upstream builds them.
//! - [`mcp_tools`]: the desktop tools both MCP servers offer, each call checked into an action;
//!   [`interactive`]: the numbered interactive elements of the `state` tool.
//! - [`token`]: a bearer token parsed from a token file's text or an option, and the one
//!   check of an `Authorization` header against it, which every server uses.
//! - [`ntpath`]: Python 3.10's Windows path rules (`os.path` on upstream's guest).
//! - [`cmdline`], [`ntfs`], [`imaging`], [`atomic`], [`close_all`], [`a11y_xml`]:
//!   decisions both sides share (command lines, listing order, crop and encode, atomic
//!   writes, which windows a reset spares, upstream's accessibility XML).
//! - [`calendar`] (day counts to dates), [`markup`] (XML/HTML escaping), [`search_path`]
//!   (the `PATH` lookup): the one copy of each small utility.
//!
//! # Compatibility
//!
//! New fields are `Option` or `#[serde(default)]`, and enums that a newer peer
//! may extend carry an `Unknown` fallback, so an older host can talk to a newer
//! guest and the other way round.

#![forbid(unsafe_code)]

pub mod a11y_xml;
pub mod action;
pub mod atomic;
pub mod calendar;
pub mod clipboard;
pub mod clock;
pub mod close_all;
pub mod cmdline;
pub mod doctor;
pub mod error;
pub mod eval;
pub mod exec;
pub mod fastimg;
pub mod files;
pub mod geometry;
pub mod health;
pub mod host_header;
pub mod imaging;
pub mod input_log;
pub mod interactive;
pub mod keys;
pub mod markup;
pub mod mcp_tools;
pub mod ntfs;
pub mod ntpath;
pub mod observation;
pub mod registry;
pub mod search_path;
pub mod token;
pub mod vkeys;
pub mod window_list;

/// The version of the native API spoken under `/v1/`.
pub const API_VERSION: &str = "1";
