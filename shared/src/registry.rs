//! Registry reads (and writes for setup).

use serde::{Deserialize, Serialize};

/// A registry value.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", content = "data", rename_all = "snake_case")]
pub enum RegistryValue {
    /// `REG_SZ` and `REG_EXPAND_SZ` (unexpanded).
    String(String),
    /// `REG_DWORD`.
    Dword(u32),
    /// `REG_QWORD`.
    Qword(u64),
    /// `REG_MULTI_SZ`.
    MultiString(Vec<String>),
    /// `REG_BINARY`, as bytes.
    Binary(Vec<u8>),
    #[serde(other)]
    Unknown,
}

/// Query of `GET /v1/registry`: `key` like `HKCU\Control Panel\Desktop`; an absent `value` is the default value.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RegistryQuery {
    pub key: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub value: Option<String>,
}

/// Body of `PUT /v1/registry`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RegistryWrite {
    pub key: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub value: Option<String>,
    pub data: RegistryValue,
}

/// Answer of `GET /v1/registry`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RegistryRead {
    pub key: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub value: Option<String>,
    pub data: RegistryValue,
}
