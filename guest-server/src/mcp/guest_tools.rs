//! The tools only the guest's own MCP server offers (`arena_shared::mcp_tools::GUEST_ONLY`):
//! programs (`launch_app`), windows (`switch_window`, `resize_window`), the clipboard,
//! the shell (`shell`, refused without `--mcp-shell`) and numbered elements (`state`,
//! `click_element`, `type_into_element`). Each calls the [`Desktop`] through
//! [`crate::call::blocking`], as every tool does; input-like tools take the input lock's
//! shared side, as the input tools do, and the actions an element tool makes are checked
//! as `/v1/actions` checks a batch (`crate::native::input::validate`) before any runs.
//!
//! Where a behaviour exists already it is reused: `launch_app` starts a program as
//! Navi's `computer.os.open_program` does (`arena_script::Composed::open_program`),
//! the window list is upstream's (`arena_shared::window_list`), and elements are found
//! and numbered by `arena_shared::interactive`.

use std::collections::HashSet;
use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use arena_mcp::{image_png, text, tool_error};
use base64::Engine as _;
use rmcp::model::CallToolResponse;
use serde_json::{json, Value};

use arena_script::Composed as _;
use arena_shared::action::{Action, MouseButton};
use arena_shared::geometry::Rect;
use arena_shared::interactive::{self, Element, Numbering};
use arena_shared::mcp_tools::{ShowState, ToolCall, WindowChange};
use arena_shared::observation::{A11yBackend, ImageFormat, TreeBudget, WindowInfo};
use arena_shared::window_list::{foreground_title_of, window_names};

use crate::call::blocking;
use crate::desktop::{cancel, ClipboardData, Desktop, DesktopError, DesktopResult, ExecLimits, WindowState};
use crate::native::input::validate;
use crate::script_host::DesktopHost;
use crate::state::AppState;

/// How long `launch_app` waits for the program's window.
pub const LAUNCH_WAIT: Duration = Duration::from_secs(10);

/// Most bytes of each output stream `shell` answers with.
pub const SHELL_OUTPUT_BYTES: u64 = 1 << 20;

/// Most characters of clipboard text `clipboard_get` answers with.
pub const CLIPBOARD_CHARS: usize = 1 << 20;

/// Where Start menu shortcuts are, under `%ProgramData%` and `%APPDATA%`.
const START_MENU: &str = r"Microsoft\Windows\Start Menu\Programs";

/// Most Start menu entries looked at, and how deep.
const START_MENU_ENTRIES: usize = 5000;
const START_MENU_DEPTH: usize = 4;

/// One session's numbered elements, shared by its tool calls.
pub type Elements = Arc<Mutex<Numbering>>;

fn failed(tool: &str, err: &DesktopError) -> CallToolResponse {
    tool_error(format!("{tool}: {err}"))
}

/// Answers `result` as JSON text, or a tool error naming `tool`.
fn answer(tool: &str, result: DesktopResult<Result<Value, String>>) -> CallToolResponse {
    match result {
        Ok(Ok(value)) => text(value.to_string()),
        Ok(Err(message)) => tool_error(format!("{tool}: {message}")),
        Err(err) => failed(tool, &err),
    }
}

fn lock(elements: &Elements) -> std::sync::MutexGuard<'_, Numbering> {
    elements.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// One call of a guest-only tool.
pub async fn call(
    state: &AppState,
    elements: &Elements,
    tool: &str,
    call: ToolCall,
    screen: Option<(u32, u32)>,
) -> CallToolResponse {
    let desktop = &state.desktop;
    let timeout = state.call_timeout();
    match call {
        ToolCall::LaunchApp { name } => {
            let _input = state.input_share().await;
            let wait = LAUNCH_WAIT.min(timeout);
            answer(
                tool,
                blocking(desktop, "launch_app", timeout + wait, move |d| launch(d, &name, timeout, wait)).await,
            )
        }
        ToolCall::SwitchWindow { title } => {
            let _input = state.input_share().await;
            answer(
                tool,
                blocking(desktop, "switch_window", timeout, move |d| {
                    let windows = d.windows()?;
                    let window = match find_window(&windows, &title) {
                        Ok(window) => window,
                        Err(message) => return Ok(Err(message)),
                    };
                    d.activate_window(window.id)?;
                    Ok(Ok(json!({"window": window.title})))
                })
                .await,
            )
        }
        ToolCall::ResizeWindow(change) => {
            let _input = state.input_share().await;
            answer(tool, blocking(desktop, "resize_window", timeout, move |d| resize(d, &change)).await)
        }
        ToolCall::ClipboardGet => match blocking(desktop, "clipboard", timeout, |d| d.clipboard_get()).await {
            Ok(ClipboardData::Text(t)) => {
                let truncated = t.chars().count() > CLIPBOARD_CHARS;
                let kept: String = if truncated { t.chars().take(CLIPBOARD_CHARS).collect() } else { t };
                text(json!({"format": "text", "text": kept, "truncated": truncated}).to_string())
            }
            Ok(ClipboardData::Empty) => text(json!({"format": "empty"}).to_string()),
            Ok(ClipboardData::Image(image)) => match crate::imaging::encode(&image, ImageFormat::Png, 100) {
                Ok(png) => image_png(base64::engine::general_purpose::STANDARD.encode(png)),
                Err(err) => tool_error(format!("{tool}: the clipboard's image does not encode: {err}")),
            },
            Err(err) => failed(tool, &err),
        },
        ToolCall::ClipboardSet(value) => {
            match blocking(desktop, "clipboard", timeout, move |d| d.clipboard_set(&ClipboardData::Text(value))).await {
                Ok(()) => text(json!({"ok": true}).to_string()),
                Err(err) => failed(tool, &err),
            }
        }
        ToolCall::Shell { command, timeout_ms } => {
            if !state.config.mcp_shell {
                return tool_error(format!(
                    "{tool}: refused: this guest was started without --mcp-shell (ARENA_MCP_SHELL=1), \
                     which a shell needs; run_python and the other tools are served"
                ));
            }
            let spec = desktop.shell_command(&command);
            let limits = ExecLimits {
                timeout_ms,
                max_output_bytes: SHELL_OUTPUT_BYTES,
                cwd: desktop.env_var("USERPROFILE"),
                stdin: None,
            };
            // The program is ended at its own timeout; the call's deadline leaves room to collect it.
            let deadline = Duration::from_millis(timeout_ms) + Duration::from_secs(5);
            match blocking(desktop, "shell", deadline, move |d| d.run(&spec, &limits)).await {
                Ok(out) => text(
                    json!({
                        "exit_code": out.exit_code,
                        "stdout": out.stdout,
                        "stderr": out.stderr,
                        "timed_out": out.timed_out,
                        "stdout_truncated": out.stdout_truncated,
                        "stderr_truncated": out.stderr_truncated,
                    })
                    .to_string(),
                ),
                Err(err) => failed(tool, &err),
            }
        }
        ToolCall::State => {
            let deadline = state.config.a11y_timeout();
            let read = blocking(desktop, "state", deadline, |d| {
                let windows = d.windows()?;
                let tree = d.accessibility(A11yBackend::Uia, &TreeBudget::WAA, false)?;
                Ok((windows, tree))
            })
            .await;
            let (windows, tree) = match read {
                Ok(read) => read,
                Err(err) => return failed(tool, &err),
            };
            let (found, capped) = interactive::collect(&tree, &windows, screen.unwrap_or((u32::MAX, u32::MAX)));
            let listed: Vec<Value> = found.iter().map(element_json).collect();
            let (id, first) = lock(elements).number(found);
            let listed: Vec<Value> = listed
                .into_iter()
                .zip(first..)
                .map(|(mut e, n)| {
                    e["element"] = json!(n);
                    e
                })
                .collect();
            text(
                json!({
                    "state": id,
                    "foreground": foreground_title_of(&windows),
                    "windows": window_names(&windows),
                    "elements": listed,
                    "truncated": tree.truncated || capped,
                })
                .to_string(),
            )
        }
        ToolCall::ClickElement { element, button, clicks } => {
            let found = match lock(elements).get(element).cloned() {
                Ok(found) => found,
                Err(message) => return tool_error(format!("{tool}: {message}")),
            };
            let actions = vec![click(found.centre(), button, clicks)];
            act_on_element(state, tool, "click_element", element, found, actions).await
        }
        ToolCall::TypeIntoElement { element, text: typed, clear, press_enter } => {
            let found = match lock(elements).get(element).cloned() {
                Ok(found) => found,
                Err(message) => return tool_error(format!("{tool}: {message}")),
            };
            let mut actions = vec![click(found.centre(), MouseButton::Left, 1)];
            if clear {
                actions.push(Action::Hotkey { keys: vec!["ctrl".into(), "a".into()] });
                actions.push(Action::KeyPress { key: "backspace".into(), presses: 1 });
            }
            actions.push(Action::TypeText { text: typed, interval_ms: None });
            if press_enter {
                actions.push(Action::KeyPress { key: "enter".into(), presses: 1 });
            }
            act_on_element(state, tool, "type_into_element", element, found, actions).await
        }
        other => tool_error(format!("{tool}: not a guest tool ({other:?})")),
    }
}

fn click(at: arena_shared::geometry::Point, button: MouseButton, count: u32) -> Action {
    Action::Click { x: Some(at.x), y: Some(at.y), button, count }
}

/// An element as `state` lists it (its number is added by the caller).
fn element_json(e: &Element) -> Value {
    let centre = e.centre();
    let mut value = json!({
        "role": e.role,
        "name": e.name,
        "window": e.window,
        "x": centre.x,
        "y": centre.y,
        "rect": {"x": e.rect.x, "y": e.rect.y, "width": e.rect.width, "height": e.rect.height},
    });
    if let Some(v) = &e.value {
        value["value"] = json!(v);
    }
    if e.focused {
        value["focused"] = json!(true);
    }
    value
}

/// `click_element` and `type_into_element`: `actions` (made of the element's centre)
/// checked as `/v1/actions` checks a batch, then, under the input lock's shared side,
/// performed in order once the element is where its state saw it.
async fn act_on_element(
    state: &AppState,
    tool: &str,
    op: &'static str,
    number: u64,
    element: Element,
    actions: Vec<Action>,
) -> CallToolResponse {
    let timeout = state.call_timeout();
    if let Err(err) = validate(&actions, timeout) {
        return tool_error(format!("{tool}: {err}"));
    }
    let _input = state.input_share().await;
    answer(tool, blocking(&state.desktop, op, timeout, move |d| act_on(d, number, &element, &actions)).await)
}

/// Checks that `element` is where its state saw it, then performs `actions`.
fn act_on(d: &dyn Desktop, number: u64, element: &Element, actions: &[Action]) -> DesktopResult<Result<Value, String>> {
    if let Err(message) = interactive::check_current(number, element, &d.windows()?) {
        return Ok(Err(message));
    }
    for action in actions {
        d.perform(action)?;
    }
    let centre = element.centre();
    Ok(Ok(json!({"ok": true, "element": number, "x": centre.x, "y": centre.y})))
}

/// The window `title` names: the topmost titled exactly so, else the topmost whose title
/// contains it in any case; among the windows upstream's window list shows (visible,
/// titled, minimised ones included).
fn find_window(windows: &[WindowInfo], title: &str) -> Result<WindowInfo, String> {
    let listed = |w: &&WindowInfo| w.visible && !w.title.trim().is_empty();
    let mut ordered: Vec<&WindowInfo> = windows.iter().filter(listed).collect();
    ordered.sort_by_key(|w| w.z_order);
    let wanted = title.to_lowercase();
    ordered
        .iter()
        .find(|w| w.title == title)
        .or_else(|| ordered.iter().find(|w| w.title.to_lowercase().contains(&wanted)))
        .map(|w| (*w).clone())
        .ok_or_else(|| {
            format!("no window is titled {title:?} or has it in its title; open windows: {:?}", window_names(windows))
        })
}

/// `resize_window`: the show state, then the position and size.
fn resize(d: &dyn Desktop, change: &WindowChange) -> DesktopResult<Result<Value, String>> {
    let windows = d.windows()?;
    let window = match &change.title {
        Some(title) => match find_window(&windows, title) {
            Ok(window) => window,
            Err(message) => return Ok(Err(message)),
        },
        None => match windows.iter().find(|w| w.focused) {
            Some(window) => window.clone(),
            None => return Ok(Err("no window is in front; name one with title".to_owned())),
        },
    };
    if window.class_name == "Progman" || window.class_name == "WorkerW" {
        return Ok(Err("the desktop itself cannot be moved, resized, maximised or minimised".to_owned()));
    }
    let show = match change.show {
        Some(ShowState::Normal) => Some(WindowState::Normal),
        Some(ShowState::Maximized) => Some(WindowState::Maximized),
        Some(ShowState::Minimized) => Some(WindowState::Minimized),
        None if change.moves() && (window.minimized || window.maximized) => Some(WindowState::Normal),
        None => None,
    };
    if let Some(show) = show {
        d.set_window_state(window.id, show)?;
    }
    if change.moves() {
        // Where the window is now (restored), with what the call names replaced.
        let now = d.windows()?.into_iter().find(|w| w.id == window.id).map_or(window.rect, |w| w.rect);
        let rect = Rect::new(
            change.x.unwrap_or(now.x),
            change.y.unwrap_or(now.y),
            change.width.unwrap_or(now.width),
            change.height.unwrap_or(now.height),
        );
        d.move_window(window.id, rect)?;
    }
    let after = d.windows()?.into_iter().find(|w| w.id == window.id);
    Ok(Ok(match after {
        Some(w) => json!({
            "window": w.title,
            "rect": {"x": w.rect.x, "y": w.rect.y, "width": w.rect.width, "height": w.rect.height},
            "minimized": w.minimized,
            "maximized": w.maximized,
        }),
        None => json!({"window": window.title, "closed": true}),
    }))
}

/// `launch_app`: the program as `computer.os.open_program` starts it, else a Start menu
/// shortcut of that name; then up to `wait` for a window that was not there before.
fn launch(d: &dyn Desktop, name: &str, timeout: Duration, wait: Duration) -> DesktopResult<Result<Value, String>> {
    let before: HashSet<u64> = d.windows()?.iter().map(|w| w.id).collect();
    let mut host = DesktopHost::new(d, Instant::now() + timeout);
    let how = match host.open_program(name) {
        Ok(true) => "program",
        Ok(false) => match start_menu_entry(d, name) {
            Ok(shortcut) => {
                d.open_path(&shortcut)?;
                "Start menu"
            }
            Err(message) => return Ok(Err(message)),
        },
        Err(err) => return Ok(Err(err.to_string())),
    };
    let until = Instant::now() + wait;
    loop {
        let windows = d.windows()?;
        if let Some(new) = windows.iter().find(|w| !before.contains(&w.id) && w.visible && !w.title.trim().is_empty()) {
            return Ok(Ok(json!({"launched": name, "from": how, "window": new.title})));
        }
        if Instant::now() >= until {
            return Ok(Ok(json!({
                "launched": name,
                "from": how,
                "window": null,
                "note": format!("no new window within {} s; the program may still be starting, or it showed a window it already had", wait.as_secs()),
            })));
        }
        cancel::sleep(Duration::from_millis(100))?;
    }
}

/// The guest path of the Start menu shortcut (`.lnk`, `.url`) named `name` (any case),
/// or a message naming the close matches.
fn start_menu_entry(d: &dyn Desktop, name: &str) -> Result<String, String> {
    let mut entries: Vec<(String, std::path::PathBuf)> = Vec::new();
    for base in ["ProgramData", "APPDATA"] {
        let Some(root) = d.env_var(base) else { continue };
        let Ok(local) = d.map_path(&format!(r"{root}\{START_MENU}")) else { continue };
        shortcuts(&local, 0, &mut entries);
    }
    let wanted = name.to_lowercase();
    if let Some((_, path)) = entries.iter().find(|(stem, _)| stem.to_lowercase() == wanted) {
        return d.unmap_path(path).map_err(|err| err.to_string());
    }
    let names: Vec<String> = entries.into_iter().map(|(stem, _)| stem).collect();
    let close = arena_script::get_close_matches(name, &names, 3, 0.6);
    let hint = if close.is_empty() { String::new() } else { format!("; close Start menu names: {close:?}") };
    Err(format!("no program or Start menu shortcut is named {name:?}{hint}"))
}

/// The shortcuts under `dir`, as (name without extension, path), within the bounds.
fn shortcuts(dir: &Path, depth: usize, out: &mut Vec<(String, std::path::PathBuf)>) {
    let Ok(read) = std::fs::read_dir(dir) else { return };
    for entry in read.flatten() {
        if out.len() >= START_MENU_ENTRIES {
            return;
        }
        let path = entry.path();
        if path.is_dir() {
            if depth < START_MENU_DEPTH {
                shortcuts(&path, depth + 1, out);
            }
            continue;
        }
        let extension = path.extension().map(|e| e.to_string_lossy().to_lowercase());
        if matches!(extension.as_deref(), Some("lnk" | "url")) {
            if let Some(stem) = path.file_stem() {
                out.push((stem.to_string_lossy().into_owned(), path.clone()));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn window(id: u64, title: &str, z: u32) -> WindowInfo {
        WindowInfo { id, title: title.into(), visible: true, z_order: z, ..WindowInfo::default() }
    }

    #[test]
    fn a_window_is_found_by_its_title_then_by_a_part_of_it() {
        let windows =
            [window(1, "notes.txt - Notepad", 0), window(2, "Notepad", 1), window(3, "Untitled - Notepad", 2)];
        assert_eq!(find_window(&windows, "Notepad").map(|w| w.id), Ok(2), "the exact title first");
        assert_eq!(find_window(&windows, "untitled").map(|w| w.id), Ok(3));
        assert_eq!(find_window(&windows, "notepad").map(|w| w.id), Ok(1), "the topmost that contains it");
        let missing = find_window(&windows, "Paint").expect_err("none");
        assert!(
            missing.contains("no window is titled \"Paint\"") && missing.contains("Untitled - Notepad"),
            "{missing}"
        );
    }
}
