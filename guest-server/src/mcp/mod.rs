//! `arena-guest --mcp`: the guest as an MCP server on its own, so that a person
//! can drive the desktop from any MCP client outside a benchmark. Served at
//! `/mcp` on the server's own port (streamable HTTP, with the `rmcp` SDK),
//! behind the same token, `Host` and `Origin` guards as every other route.
//!
//! The tools are the desktop tools of `arena_shared::mcp_tools` (the same names
//! and arguments as the host's benchmark endpoint), without `get_task`, `done`
//! and `fail`, and the guest's own tools ([`guest_tools`]: programs, windows, the
//! clipboard, the shell, numbered elements); the handler, the tool table and the
//! result shapes are `arena_mcp`'s, which the host's endpoint shares. Each tool calls
//! the [`Desktop`](crate::desktop::Desktop) through [`crate::call::blocking`], as the
//! native routes do; `run_python` runs in the shared interpreter.

pub mod guest_tools;

use std::time::{Duration, Instant};

use arena_mcp::{image_png, text, tool_error, BoundedSessions, HttpStatuses, Server, SessionLimits, ToolServer};
use base64::Engine as _;
use rmcp::model::{CallToolRequestParams, CallToolResponse};
use rmcp::transport::streamable_http_server::StreamableHttpService;
use serde_json::json;

use arena_script::{self as script, ComputerState, Globals};
use arena_shared::action::Action;
use arena_shared::mcp_tools::{self, ToolCall};
use arena_shared::observation::{A11yBackend, ImageFormat, TreeBudget};

use crate::call::blocking;
use crate::desktop::DesktopError;
use crate::native::input::validate;
use crate::script_host::DesktopHost;
use crate::state::AppState;

/// The `/mcp` service: one [`GuestMcp`] per session, at most `--mcp-max-sessions`
/// open (a new one closes the one idle longest), each closed after
/// `--mcp-idle-secs` without a call, a call whose client hung up cancelled
/// ([`arena_mcp::BoundedSessions`]), a session's `DELETE` answered `200`
/// ([`HttpStatuses`]). rmcp's own `Host` check is off because
/// [`crate::auth::guard`] in front of it already makes that decision for every
/// route (loopback names, `--allow-host`).
pub fn service(state: AppState) -> HttpStatuses<StreamableHttpService<Server<GuestMcp>, BoundedSessions>> {
    let config = arena_mcp::http_config().disable_allowed_hosts();
    let limits = SessionLimits {
        max_sessions: state.config.mcp_max_sessions as usize,
        idle: Duration::from_secs(state.config.mcp_idle_secs),
    };
    HttpStatuses(StreamableHttpService::new(
        move || Ok(Server(GuestMcp { state: state.clone(), elements: guest_tools::Elements::default() })),
        BoundedSessions::new(limits),
        config,
    ))
}

/// One MCP session over the guest's desktop.
#[derive(Debug, Clone)]
pub struct GuestMcp {
    state: AppState,
    /// The elements this session's latest `state` numbered.
    elements: guest_tools::Elements,
}

fn failed(tool: &str, err: &DesktopError) -> CallToolResponse {
    tool_error(format!("{tool}: {err}"))
}

impl GuestMcp {
    /// One tool call on this machine's desktop.
    async fn answer(&self, request: CallToolRequestParams) -> CallToolResponse {
        let tool = request.name.to_string();
        let desktop = &self.state.desktop;
        let timeout = self.state.call_timeout();
        let screen = match blocking(desktop, "screen", timeout, |d| d.screen()).await {
            Ok(info) => Some((info.physical_width, info.physical_height)),
            Err(err) => return failed(&tool, &err),
        };
        let call = match mcp_tools::parse(&tool, request.arguments, screen, false) {
            Ok(call) => call,
            Err(message) => return tool_error(message),
        };
        // The checks of `/v1/actions` (keys, counts, durations), the call as a batch of one.
        if let ToolCall::Input(action) = &call {
            if let Err(err) = validate(std::slice::from_ref(action), timeout) {
                return tool_error(format!("{tool}: {err}"));
            }
        }
        match call {
            ToolCall::Screenshot => {
                let png = blocking(desktop, "screenshot", timeout, |d| {
                    let frame = d.capture(false)?;
                    crate::imaging::encode(&frame.image, ImageFormat::Png, 100)
                        .map_err(|err| DesktopError::Os { op: "screenshot", message: err.to_string() })
                })
                .await;
                match png {
                    Ok(png) => image_png(base64::engine::general_purpose::STANDARD.encode(png)),
                    Err(err) => failed(&tool, &err),
                }
            }
            ToolCall::AccessibilityTree { win32 } => {
                let backend = if win32 { A11yBackend::Win32 } else { A11yBackend::Uia };
                let deadline = self.state.config.a11y_timeout();
                let xml = blocking(desktop, "accessibility", deadline, move |d| {
                    let foreground = d.windows()?.iter().find(|w| w.focused).map(|w| w.id);
                    let tree = d.accessibility(backend, &TreeBudget::WAA, false)?;
                    Ok(arena_shared::a11y_xml::to_xml(&tree, foreground))
                })
                .await;
                match xml {
                    Ok(xml) => text(xml),
                    Err(err) => failed(&tool, &err),
                }
            }
            ToolCall::ListWindows => match blocking(desktop, "windows", timeout, |d| d.windows()).await {
                Ok(windows) => text(
                    json!({
                        "windows": arena_shared::window_list::window_names(&windows),
                        "foreground": arena_shared::window_list::foreground_title_of(&windows),
                    })
                    .to_string(),
                ),
                Err(err) => failed(&tool, &err),
            },
            ToolCall::Input(Action::Wait { ms }) => {
                tokio::time::sleep(Duration::from_millis(ms)).await;
                text(json!({"ok": true}).to_string())
            }
            ToolCall::Input(action) => {
                let _input = self.state.input_share().await;
                match blocking(desktop, "perform", timeout, move |d| d.perform(&action)).await {
                    Ok(()) => text(json!({"ok": true}).to_string()),
                    Err(err) => failed(&tool, &err),
                }
            }
            ToolCall::RunPython(code) => self.run_python(&tool, code, screen).await,
            ToolCall::GetTask | ToolCall::Done | ToolCall::Fail => tool_error(format!("unknown tool {tool:?}")),
            guest => guest_tools::call(&self.state, &self.elements, &tool, guest, screen).await,
        }
    }

    /// `computer` code (when it names the object, with a fresh `computer` for
    /// the screen) or pyautogui code (with `pyautogui` and `time` imported).
    async fn run_python(&self, tool: &str, code: String, screen: Option<(u32, u32)>) -> CallToolResponse {
        let program = match script::parse(&code) {
            Ok(program) => program,
            Err(err) => return tool_error(format!("{tool}: SyntaxError: {err}")),
        };
        let timeout = self.state.call_timeout();
        let (w, h) = screen.unwrap_or((0, 0));
        let place = match self.state.programs.admit().await {
            Ok(place) => place,
            Err(busy) => return tool_error(format!("{tool}: {busy}")),
        };
        let _input = self.state.input_share().await;
        let ran = blocking(&self.state.desktop, "run_python", timeout, move |d| {
            let memory = Some(place.memory());
            let deadline = Instant::now() + timeout;
            let mut host = DesktopHost::new(d, deadline);
            let mut computer =
                ComputerState::for_screen(i32::try_from(w).unwrap_or(i32::MAX), i32::try_from(h).unwrap_or(i32::MAX));
            // The call's deadline and its cancel flag (set on timeout, a dropped request or shutdown).
            let stop = script::Stop::new(Some(deadline), crate::desktop::cancel::flag());
            let globals = if script::dialect_of(&code) == script::Dialect::Computer {
                Globals { computer: Some(&mut computer), computer_action_delay: 0.0, preimport: &[], stop, memory }
            } else {
                Globals { computer: None, computer_action_delay: 0.0, preimport: &["pyautogui", "time"], stop, memory }
            };
            Ok(script::run(&program, &mut host, globals))
        })
        .await;
        match ran {
            Ok(Ok(out)) => {
                text(json!({"stdout": out.stdout, "stderr": out.stderr, "exit_code": out.exit_code}).to_string())
            }
            Ok(Err(err)) => tool_error(format!("{tool}: {}{}", err.stderr, err.traceback())),
            Err(err) => failed(tool, &err),
        }
    }
}

impl ToolServer for GuestMcp {
    const NAME: &'static str = "arena-guest";
    const VERSION: &'static str = env!("CARGO_PKG_VERSION");
    const INSTRUCTIONS: &'static str =
        "The desktop of this machine: screenshot, accessibility tree, numbered interactive elements (state), windows, \
         programs, the clipboard, mouse and keyboard.";
    const WITH_TASK: bool = false;

    async fn call(&self, request: CallToolRequestParams) -> CallToolResponse {
        self.answer(request).await
    }
}
