//! `GET /v1/screen` and `GET /v1/screenshot`.
//!
//! A screenshot is answered as raw image bytes with its [`ScreenshotMeta`] as
//! compact JSON in the `x-arena-screenshot` header, so the host gets the pixels
//! without base64 and still learns how image pixels map to physical pixels.
//! Capture, black-frame check, cursor drawing, downscaling and encoding all run
//! in one backend call on the backend pool; none of that work touches the
//! async workers.

use std::time::Instant;

use axum::extract::State;
use axum::http::{header, HeaderName, HeaderValue};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use axum::Router;

use arena_shared::geometry::CoordinateSpace;
use arena_shared::observation::{ImageFormat, ScreenInfo, ScreenshotMeta, ScreenshotQuery};

use crate::call::blocking;
use crate::desktop::{Desktop, DesktopError, DesktopResult};
use crate::error::{ApiError, AppJson, AppQuery};
use crate::imaging;
use crate::state::AppState;

use super::millis;

/// The header carrying a screenshot's metadata.
pub(crate) const META_HEADER: HeaderName = HeaderName::from_static("x-arena-screenshot");

/// JPEG quality when the query names none.
const DEFAULT_JPEG_QUALITY: u8 = 85;

/// The smallest `max_side` accepted: below this an image says nothing.
const MIN_SIDE: u32 = 16;

pub(crate) fn routes() -> Router<AppState> {
    Router::new().route("/v1/screen", get(screen)).route("/v1/screenshot", get(screenshot))
}

async fn screen(State(state): State<AppState>) -> Result<AppJson<ScreenInfo>, ApiError> {
    let info = blocking(&state.desktop, "screen", state.call_timeout(), |d| d.screen()).await?;
    Ok(AppJson(info))
}

async fn screenshot(
    State(state): State<AppState>,
    AppQuery(query): AppQuery<ScreenshotQuery>,
) -> Result<Response, ApiError> {
    let quality = query.quality.unwrap_or(DEFAULT_JPEG_QUALITY);
    if !(1..=100).contains(&quality) {
        return Err(ApiError::BadRequest(format!("quality must be from 1 to 100 (got {quality})")));
    }
    if let Some(side) = query.max_side.filter(|s| *s < MIN_SIDE) {
        return Err(ApiError::BadRequest(format!("max_side must be at least {MIN_SIDE} (got {side})")));
    }
    if query.format == ImageFormat::Unknown {
        return Err(ApiError::BadRequest("format must be png or jpeg".into()));
    }
    let format = query.format;
    let want_cursor = query.cursor.unwrap_or(true);
    let max_side = query.max_side.unwrap_or(0);
    let (bytes, meta) = blocking(&state.desktop, "screenshot", state.call_timeout(), move |d| {
        shoot(d, format, quality, max_side, want_cursor)
    })
    .await?;
    let meta_json = serde_json::to_string(&meta)
        .map_err(|err| DesktopError::Os { op: "screenshot", message: format!("serialising metadata: {err}") })?;
    let meta_value = HeaderValue::from_str(&meta_json)
        .map_err(|err| DesktopError::Os { op: "screenshot", message: format!("metadata header: {err}") })?;
    let headers = [(header::CONTENT_TYPE, HeaderValue::from_static(format.mime())), (META_HEADER, meta_value)];
    Ok((headers, bytes).into_response())
}

/// Captures, checks, marks and encodes one screenshot.
///
/// The frame is captured without the cursor so that the black-frame check sees
/// the desktop itself; the cursor is then drawn here, which is what upstream
/// does too (it pastes a fixed arrow image).
fn shoot(
    d: &dyn Desktop,
    format: ImageFormat,
    quality: u8,
    max_side: u32,
    want_cursor: bool,
) -> DesktopResult<(Vec<u8>, ScreenshotMeta)> {
    let started = Instant::now();
    // The backend draws the real cursor shape where it can (the Windows backend
    // composites the live cursor); the stub arrow below is the fallback.
    let frame = d.capture(want_cursor)?;
    let capture_ms = millis(started.elapsed());
    let mut image = frame.image;
    let (physical_width, physical_height) = image.dimensions();
    // A cursor drawn on a black (locked or secure) desktop must not hide that it is black.
    let black_frame = match (frame.cursor_drawn, frame.cursor) {
        (true, Some(at)) => imaging::is_black_outside(&image, at, imaging::CURSOR_BOX),
        _ => imaging::is_black(&image),
    };
    let mut cursor_drawn = frame.cursor_drawn;
    if want_cursor && !cursor_drawn {
        if let Some(at) = frame.cursor {
            imaging::draw_cursor(&mut image, at);
            cursor_drawn = true;
        }
    }
    let (image, scale) = imaging::downscale_to_fit(image, max_side);
    let bytes = imaging::encode(&image, format, quality)
        .map_err(|err| DesktopError::Os { op: "screenshot", message: err.to_string() })?;
    let meta = ScreenshotMeta {
        width: image.width(),
        height: image.height(),
        physical_width,
        physical_height,
        scale,
        format,
        coordinate_space: if scale == 1.0 { CoordinateSpace::Physical } else { CoordinateSpace::Image },
        cursor: frame.cursor,
        cursor_drawn,
        black_frame,
        capture_ms,
    };
    Ok((bytes, meta))
}
