//! How long the parts of a step took, as the step's record keeps them: the
//! observation's parts ([`ObserveTimings`], filled by the harness's observation
//! builder) and the agent's ([`PredictTimings`], filled by each agent).

use serde::{Deserialize, Serialize};

/// How long each part of one observation took, in milliseconds. `None`: the part was not read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct ObserveTimings {
    /// The guest's screenshot call (and the VM display's, when it stood in).
    pub screenshot_ms: u64,
    /// Decoding the screenshot into pixels.
    pub decode_ms: u64,
    /// The accessibility tree.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tree_ms: Option<u64>,
    /// The window list.
    pub windows_ms: u64,
    /// The clipboard.
    pub clipboard_ms: u64,
    /// The browser's DOM elements.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dom_ms: Option<u64>,
    /// The whole observation, wall time.
    pub total_ms: u64,
}

/// The parts of one prediction an agent times, in milliseconds; `None`: the agent has no such part.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct PredictTimings {
    /// Making the Set-of-Marks (its sources and the annotated image).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub som_ms: Option<u64>,
    /// The model call, its own retries included.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model_ms: Option<u64>,
    /// Tries the model client made (1 when the first answered; 0 without a model).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub model_tries: u32,
}

fn is_zero(n: &u32) -> bool {
    *n == 0
}
