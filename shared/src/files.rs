//! File operations. Paths are guest paths (`C:\Users\Docker\Desktop\a.txt`);
//! `%VAR%` and a leading `~` are expanded by the guest.

use serde::{Deserialize, Serialize};

/// What a path names.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FileKind {
    File,
    Dir,
    Other,
    #[serde(other)]
    Unknown,
}

/// Query naming one path, for read, stat, exists, list and delete.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PathQuery {
    pub path: String,
    /// For delete: remove a directory with its contents.
    #[serde(default)]
    pub recursive: bool,
}

/// `GET /v1/files/stat`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FileStat {
    pub path: String,
    pub kind: FileKind,
    pub size: u64,
    /// Last modification, milliseconds since the Unix epoch.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub modified_ms: Option<i64>,
    #[serde(default)]
    pub readonly: bool,
    #[serde(default)]
    pub hidden: bool,
}

/// `GET /v1/files/exists`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Exists {
    pub exists: bool,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kind: Option<FileKind>,
}

/// One entry of `GET /v1/files/list`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DirEntry {
    pub name: String,
    pub kind: FileKind,
    pub size: u64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub modified_ms: Option<i64>,
}

/// `GET /v1/files/list`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DirListing {
    pub path: String,
    pub entries: Vec<DirEntry>,
}

/// Answer to `PUT /v1/files` (raw body) and the `X-Arena-Sha256` of `GET /v1/files`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FileWritten {
    pub path: String,
    pub size: u64,
    /// Lowercase hex SHA-256 of the bytes written.
    pub sha256: String,
}

/// Query of `PUT /v1/files`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WriteQuery {
    pub path: String,
    /// Create missing parent directories (default true).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub create_parents: Option<bool>,
    /// Refuse the write unless the body hashes to this (lowercase hex SHA-256).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sha256: Option<String>,
}

/// Body of `POST /v1/files/mkdir`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MkdirRequest {
    pub path: String,
}

/// Well-known folders the guest can name.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum KnownFolder {
    Home,
    Desktop,
    Documents,
    Downloads,
    Pictures,
    Music,
    Videos,
    AppData,
    LocalAppData,
    Temp,
    #[serde(other)]
    Unknown,
}

impl KnownFolder {
    pub const ALL: [KnownFolder; 10] = [
        KnownFolder::Home,
        KnownFolder::Desktop,
        KnownFolder::Documents,
        KnownFolder::Downloads,
        KnownFolder::Pictures,
        KnownFolder::Music,
        KnownFolder::Videos,
        KnownFolder::AppData,
        KnownFolder::LocalAppData,
        KnownFolder::Temp,
    ];
}

/// `GET /v1/folders`: every known folder's guest path.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct KnownFolders {
    pub folders: Vec<(KnownFolder, String)>,
}
