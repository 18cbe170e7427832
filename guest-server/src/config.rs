//! The server's configuration: the serve options ([`ServerConfig`], defined in
//! `arena_guest_launch::config` so that the service's and the logon launcher's checks
//! parse them as the server does) and the body limits of the routes.

pub use arena_guest_launch::config::{BackendKind, LogFormat, ServerConfig, UiaView};

/// Largest body of a JSON control route (windows, registry, exec, files' JSON routes,
/// evaluator queries, the browser forward, and the WAA routes not named below): 1 MiB.
/// Every route reads a small document; a bigger body is refused with 413 before it is
/// buffered and parsed (the whole `--max-body-bytes`, 1 GiB, was buffered before).
pub const JSON_BODY_BYTES: usize = 1 << 20;
/// Largest body of `POST /v1/actions`, `/update_computer` and `/setup/create_file` (a
/// 1 MiB `type_text` escaped as JSON; the Set-of-Marks boxes of a crowded screen; a
/// task's seeded document): 8 MiB.
pub const ACTIONS_BODY_BYTES: usize = 8 << 20;
/// Largest body of `/execute`, `/setup/execute` and `/execute_windows`: 2 MiB, room for
/// the interpreter's source cap written as a JSON string.
pub const EXECUTE_BODY_BYTES: usize = 2 << 20;
/// Largest body of `PUT /v1/clipboard` (an image as base64): 64 MiB.
pub const CLIPBOARD_BODY_BYTES: usize = 64 << 20;
