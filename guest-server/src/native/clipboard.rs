//! `GET` and `PUT /v1/clipboard`: text and images.
//!
//! Images travel as base64 PNG on the wire and as RGBA in the backend; the
//! conversion (PNG encoding and decoding) runs inside the backend call, on the
//! backend pool.

use axum::extract::State;
use axum::http::StatusCode;
use axum::routing::get;
use axum::Router;
use base64::Engine as _;

use arena_shared::clipboard::ClipboardContent;
use arena_shared::observation::ImageFormat;

use crate::call::blocking;
use crate::desktop::{ClipboardData, DesktopError, DesktopResult};
use crate::error::{ApiError, AppJson};
use crate::imaging;
use crate::state::AppState;

pub(crate) fn routes() -> Router<AppState> {
    Router::new().route("/v1/clipboard", get(read).put(write))
}

async fn read(State(state): State<AppState>) -> Result<AppJson<ClipboardContent>, ApiError> {
    let content =
        blocking(&state.desktop, "clipboard_get", state.call_timeout(), |d| to_wire(d.clipboard_get()?)).await?;
    Ok(AppJson(content))
}

async fn write(
    State(state): State<AppState>,
    AppJson(content): AppJson<ClipboardContent>,
) -> Result<StatusCode, ApiError> {
    if content == ClipboardContent::Unknown {
        return Err(ApiError::BadRequest("unknown clipboard kind (expected empty, text or image)".into()));
    }
    blocking(&state.desktop, "clipboard_set", state.call_timeout(), move |d| d.clipboard_set(&from_wire(content)?))
        .await?;
    Ok(StatusCode::NO_CONTENT)
}

fn to_wire(data: ClipboardData) -> DesktopResult<ClipboardContent> {
    Ok(match data {
        ClipboardData::Empty => ClipboardContent::Empty,
        ClipboardData::Text(text) => ClipboardContent::Text { text },
        ClipboardData::Image(image) => {
            let png = imaging::encode(&image, ImageFormat::Png, 100)
                .map_err(|err| DesktopError::Os { op: "clipboard_get", message: err.to_string() })?;
            ClipboardContent::Image {
                width: image.width(),
                height: image.height(),
                png_base64: base64::engine::general_purpose::STANDARD.encode(png),
            }
        }
    })
}

fn from_wire(content: ClipboardContent) -> DesktopResult<ClipboardData> {
    match content {
        ClipboardContent::Empty => Ok(ClipboardData::Empty),
        ClipboardContent::Text { text } => Ok(ClipboardData::Text(text)),
        ClipboardContent::Image { width, height, png_base64 } => {
            let bytes = base64::engine::general_purpose::STANDARD
                .decode(png_base64.trim())
                .map_err(|err| DesktopError::InvalidInput(format!("png_base64 is not base64: {err}")))?;
            let image =
                imaging::decode(&bytes).map_err(|err| DesktopError::InvalidInput(format!("png_base64: {err}")))?;
            if image.dimensions() != (width, height) {
                return Err(DesktopError::InvalidInput(format!(
                    "the image is {}x{} but the request says {width}x{height}",
                    image.width(),
                    image.height()
                )));
            }
            Ok(ClipboardData::Image(image))
        }
        ClipboardContent::Unknown => Err(DesktopError::InvalidInput("unknown clipboard kind".into())),
    }
}
