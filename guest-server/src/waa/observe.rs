//! Observation and system-information routes: `/obs_winagent`, `/accessibility`,
//! `/screenshot`, `/screen_size`, `/window_size`, `/cursor_position`, `/desktop_path`,
//! `/documents_path`, `/platform`, `/terminal`, `/probe` and `/shutdown`.

use axum::extract::{RawQuery, State};
use axum::http::{header, HeaderValue, StatusCode};
use axum::response::IntoResponse;
use base64::Engine;
use serde_json::{json, Value};

use arena_shared::files::KnownFolder;
use arena_shared::geometry::Rect;
use arena_shared::observation::{A11yBackend, ImageFormat, TreeBudget, WindowInfo};

use crate::desktop::Desktop;
use crate::error::WaaError;
use crate::state::AppState;
use crate::waa::body::{parse_urlencoded, PyForm};
use crate::waa::WaaState;
use crate::waa::{json, json_err, on_backend, on_backend_within, text, text_err, WaaResult};
use arena_shared::{a11y_xml, window_list};
use std::sync::Arc;

/// `platform.platform()` of the Windows 11 guests WAA runs on; `/terminal` names it.
const PLATFORM: &str = "Windows-10-10.0.22631-SP0";

/// Visible top-level windows in z-order, topmost first.
pub(crate) fn visible_windows(desktop: &dyn Desktop) -> Result<Vec<WindowInfo>, WaaError> {
    Ok(sorted_visible(desktop.windows()?))
}

fn sorted_visible(windows: Vec<WindowInfo>) -> Vec<WindowInfo> {
    let mut windows: Vec<WindowInfo> = windows.into_iter().filter(|w| w.visible).collect();
    windows.sort_by_key(|w| w.z_order);
    windows
}

/// `GET /probe`.
pub(crate) async fn probe() -> WaaResult {
    Ok(json(StatusCode::OK, json!({"status": "Probe successful", "message": "Service is operational"})))
}

/// `POST /shutdown`.
pub(crate) async fn shutdown(State(state): State<AppState>) -> WaaResult {
    on_backend(&state, "shutdown", |desktop| Ok(desktop.shutdown()?)).await?;
    Ok(json(
        StatusCode::OK,
        json!({"status": "Shutdown started successfully", "message": "Shutdown started successfully"}),
    ))
}

/// `GET /platform`.
pub(crate) async fn platform() -> WaaResult {
    Ok(text(StatusCode::OK, "Windows"))
}

/// `GET /terminal`: not implemented on Windows upstream either.
pub(crate) async fn terminal() -> WaaResult {
    Err(text_err(StatusCode::INTERNAL_SERVER_ERROR, format!("Currently not implemented for platform {PLATFORM}.")))
}

/// `GET /cursor_position`: upstream crashes building the response; this answers `{"x", "y"}`.
pub(crate) async fn cursor_position(State(state): State<AppState>) -> WaaResult {
    let at = on_backend(&state, "cursor_position", |desktop| Ok(desktop.cursor_position()?)).await?;
    Ok(json(StatusCode::OK, json!({"x": at.x, "y": at.y})))
}

/// `POST /screen_size`: the primary screen in physical pixels (`GetSystemMetrics` of a DPI-aware process).
pub(crate) async fn screen_size(State(state): State<AppState>) -> WaaResult {
    let screen = on_backend(&state, "screen_size", |desktop| Ok(desktop.screen()?)).await?;
    Ok(json(StatusCode::OK, json!({"width": screen.physical_width, "height": screen.physical_height})))
}

/// `POST /window_size`: upstream asks X11, which fails on Windows after the field check.
pub(crate) async fn window_size(form: PyForm) -> WaaResult {
    if form.field("app_class_name").is_none() {
        return Err(json_err(StatusCode::BAD_REQUEST, json!({"error": "app_class_name is required"})));
    }
    Err(WaaError::catch("Bad display name \"\""))
}

/// `GET /screenshot`: the primary screen with the cursor drawn in, as PNG.
pub(crate) async fn screenshot(State(state): State<AppState>) -> WaaResult {
    let png = on_backend(&state, "screenshot", |desktop| {
        let mut frame = desktop.capture(true)?;
        if !frame.cursor_drawn {
            if let Some(at) = frame.cursor {
                crate::imaging::draw_cursor(&mut frame.image, at);
            }
        }
        crate::imaging::encode(&frame.image, ImageFormat::Png, 0).map_err(|err| WaaError::catch(err.to_string()))
    })
    .await?;
    let mut res = png.into_response();
    res.headers_mut().insert(header::CONTENT_TYPE, HeaderValue::from_static("image/png"));
    res.headers_mut().insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
    Ok(res)
}

/// Crops `image` (the primary screen, origin at 0,0) to `rect` as upstream's Pillow
/// does: parts off the screen are black. A rectangle entirely off-screen (a minimised
/// foreground window, where upstream fails) gives one black pixel, so the observation
/// still succeeds.
fn crop_window(image: &image::RgbaImage, rect: Rect) -> image::RgbaImage {
    let black = || image::RgbaImage::from_pixel(1, 1, image::Rgba([0, 0, 0, 255]));
    let screen = Rect::new(0, 0, image.width() as i32, image.height() as i32);
    if !rect.intersects(&screen) {
        return black();
    }
    let (left, top) = (i64::from(rect.x), i64::from(rect.y));
    let (right, bottom) = (left + i64::from(rect.width), top + i64::from(rect.height));
    arena_shared::imaging::crop_padded(image, left, top, right, bottom).unwrap_or_else(|_| black())
}

/// `GET /obs_winagent`.
pub(crate) async fn obs_winagent(State(state): State<AppState>, State(session): State<Arc<WaaState>>) -> WaaResult {
    let clipboard = session.computer().map_or(Value::Null, |c| c.clipboard_content.clone());
    let human_input = session.human_input();
    let (image, title, rect, names) = on_backend(&state, "obs_winagent", |desktop| {
        let all = desktop.windows()?;
        let foreground = all.iter().find(|w| w.focused);
        // One rule for the title and the list, shared with the host's observation.
        let title = window_list::foreground_title(foreground.map(|w| w.title.as_str()));
        let names = window_list::window_names(&all).join("\n");
        let (title, rect, crop) = match foreground {
            Some(w) if !w.title.is_empty() && w.title != window_list::PROGRAM_MANAGER => {
                let r = w.rect;
                (title, json!([r.x, r.y, r.right(), r.bottom()]), r)
            }
            _ => {
                // Upstream reports the primary monitor as (x, y, width, height) here (Q13).
                let screen = desktop.screen()?;
                let primary = screen.monitors.iter().find(|m| m.primary).map(|m| m.rect).unwrap_or(Rect::new(
                    0,
                    0,
                    screen.physical_width as i32,
                    screen.physical_height as i32,
                ));
                (title, json!([primary.x, primary.y, primary.width, primary.height]), primary)
            }
        };
        let frame = desktop.capture(false)?;
        let png = crate::imaging::encode(&crop_window(&frame.image, crop), ImageFormat::Png, 0)
            .map_err(|err| WaaError::catch(err.to_string()))?;
        Ok((base64::engine::general_purpose::STANDARD.encode(png), title, rect, names))
    })
    .await?;
    Ok(json(
        StatusCode::OK,
        json!({
            "image": image,
            "window_title": title,
            "rect": rect,
            "window_names_str": names,
            "computer_clipboard": clipboard,
            "human_input": human_input,
            "status": "success",
        }),
    ))
}

/// `GET /accessibility?backend=win32|uia` (default `win32`).
pub(crate) async fn accessibility(State(state): State<AppState>, RawQuery(query): RawQuery) -> WaaResult {
    let pairs = parse_urlencoded(query.unwrap_or_default().as_bytes());
    let backend = pairs.iter().find(|(k, _)| k == "backend").map_or("win32", |(_, v)| v.as_str());
    let backend = match backend {
        "win32" => A11yBackend::Win32,
        "uia" => A11yBackend::Uia,
        _ => return Err(text_err(StatusCode::BAD_REQUEST, "Invalid backend specified")),
    };
    let xml = on_backend_within(&state, "accessibility", state.config.a11y_timeout(), move |desktop| {
        let tree = desktop.accessibility(backend, &TreeBudget::WAA, false)?;
        if tree.truncated {
            tracing::warn!(nodes = tree.node_count, "accessibility tree hit its budget; answering the partial tree");
        }
        // `st:active` compares each node's window with the foreground window.
        let foreground = desktop.windows()?.into_iter().find(|w| w.focused).map(|w| w.id);
        Ok(a11y_xml::to_xml(&tree, foreground))
    })
    .await?;
    Ok(json(StatusCode::OK, json!({"AT": xml})))
}

/// The guest path of a known folder when the folder exists.
async fn existing_known_folder(state: &AppState, folder: KnownFolder) -> Option<String> {
    on_backend(state, "known_folder", move |desktop| {
        let path = desktop.known_folder(folder)?;
        let exists = desktop.map_path(&path).map(|local| local.exists()).unwrap_or(false);
        Ok(exists.then_some(path))
    })
    .await
    .ok()
    .flatten()
}

/// `POST /desktop_path`.
pub(crate) async fn desktop_path(State(state): State<AppState>) -> WaaResult {
    match existing_known_folder(&state, KnownFolder::Desktop).await {
        Some(path) => Ok(json(StatusCode::OK, json!({"desktop_path": path}))),
        None => Err(json_err(
            StatusCode::NOT_FOUND,
            json!({"error": "Unsupported operating system or desktop path not found"}),
        )),
    }
}

/// `POST /documents_path`.
pub(crate) async fn documents_path(State(state): State<AppState>) -> WaaResult {
    match existing_known_folder(&state, KnownFolder::Documents).await {
        Some(path) => Ok(json(StatusCode::OK, json!({"documents_path": path}))),
        None => Err(json_err(
            StatusCode::BAD_REQUEST,
            json!({"error": "Unsupported operating system or documents path not found"}),
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crops_pad_off_screen_parts_like_pillow() {
        let img = image::RgbaImage::from_pixel(100, 50, image::Rgba([1, 2, 3, 255]));
        let check = |rect: Rect, size: (u32, u32)| assert_eq!(crop_window(&img, rect).dimensions(), size, "{rect:?}");
        check(Rect::new(10, 10, 20, 20), (20, 20));
        // A maximised window's frame hangs 8 px over every edge: padded, as upstream.
        check(Rect::from_ltrb(-8, -8, 108, 58), (116, 66));
        check(Rect::new(-32000, -32000, 160, 28), (1, 1));
        check(Rect::new(90, 40, 50, 50), (50, 50));
        let padded = crop_window(&img, Rect::new(90, 40, 50, 50));
        assert_eq!(padded.get_pixel(0, 0).0, [1, 2, 3, 255]);
        assert_eq!(padded.get_pixel(20, 20).0, [0, 0, 0, 255]);
    }
}
