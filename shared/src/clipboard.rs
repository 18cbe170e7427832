//! Clipboard contents.

use serde::{Deserialize, Serialize};

/// What the clipboard holds. Images travel as base64 PNG.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum ClipboardContent {
    Empty,
    Text {
        text: String,
    },
    Image {
        width: u32,
        height: u32,
        png_base64: String,
    },
    #[serde(other)]
    Unknown,
}
