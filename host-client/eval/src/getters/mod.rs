//! The getter registry: upstream getter names mapped to Rust functions that
//! fetch a value through the guest API or the host's download cache.
//!
//! [`lookup`] is the one place that names getters: a closed `match` from the
//! upstream `type` to a [`Getter`], and [`Getter::fetch`] dispatches on it with
//! an exhaustive `match`, so adding a getter is one variant, one name and one
//! arm. A name [`lookup`] does not know is a getter this build does not implement.
//!
//! One file per upstream family: `general.rs` (`rule`, `vm_command_line`),
//! `file.rs` (`vm_file`, `cloud_file`, `vm_file_exists_in_vm_folder`),
//! `explorer.rs` (known-folder existence checks), `info.rs` (window title, wallpaper).
//!
//! Getters do not score: they return a [`Fetched`] value, or an error the
//! evaluator records before scoring the metric 0.

mod browser;
mod explorer;
mod file;
mod general;
mod info;
mod system;

#[cfg(test)]
mod tests;

use std::path::{Component, Path, PathBuf};

use serde_json::{Map, Value};

use super::value::{json_kind, Fetched};
use super::EvalContext;
use arena_client::error::ClientError;

/// Why a getter produced no value. The evaluator records the message and scores 0.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum GetterError {
    /// The getter name is a known upstream name this build does not implement.
    #[error("getter {0} is not implemented in this build")]
    NotImplemented(String),
    /// A parameter is missing or has the wrong type.
    #[error("getter {getter}: {message}")]
    BadParams { getter: &'static str, message: String },
    /// A guest call failed.
    #[error("getter {getter}: {source}")]
    Guest {
        getter: &'static str,
        #[source]
        source: Box<ClientError>,
    },
    /// A host file could not be written or read.
    #[error("getter {getter}: {path}: {source}", path = path.display())]
    Io {
        getter: &'static str,
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A download through the host cache failed.
    #[error("getter {getter}: {message}")]
    Download { getter: &'static str, message: String },
    /// The guest answered, but not with what the getter needs.
    #[error("getter {getter}: {message}")]
    Failed { getter: &'static str, message: String },
}

/// A getter this build implements.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum Getter {
    Rule,
    CloudFile,
    /// This project's `host_file` (names::ARENA_EXPECTED_GETTERS).
    HostFile,
    VmFile,
    VmFileExistsInVmFolder,
    VmFolderExistsInDocuments,
    VmFileExistsInDesktop,
    VmCommandLine,
    VmActiveWindowTitle,
    VmWallpaper,
    /// Chrome and Edge profile files, tabs over DevTools, desktop shortcuts (`browser.rs`).
    Browser(browser::BrowserGetter),
    /// Settings, File Explorer, Clock, VLC and other system queries (`system.rs`).
    System(system::SystemGetter),
}

pub(crate) use file::host_file_problem;

/// The entry of a family's name table called `name`.
pub(super) fn by_name<G: Copy>(table: &[(&'static str, G)], name: &str) -> Option<G> {
    table.iter().find_map(|(known, getter)| (*known == name).then_some(*getter))
}

/// The upstream name of `getter` in a family's name table.
pub(super) fn name_of<G: Copy + PartialEq>(table: &[(&'static str, G)], getter: G) -> Option<&'static str> {
    table.iter().find_map(|(name, known)| (*known == getter).then_some(*name))
}

/// The implementation of getter `name` (a task's `type`), or `None`.
pub fn lookup(name: &str) -> Option<Getter> {
    Some(match name {
        "rule" => Getter::Rule,
        "cloud_file" => Getter::CloudFile,
        "host_file" => Getter::HostFile,
        "vm_file" => Getter::VmFile,
        "vm_file_exists_in_vm_folder" => Getter::VmFileExistsInVmFolder,
        "vm_folder_exists_in_documents" => Getter::VmFolderExistsInDocuments,
        "vm_file_exists_in_desktop" => Getter::VmFileExistsInDesktop,
        "vm_command_line" => Getter::VmCommandLine,
        "vm_active_window_title" => Getter::VmActiveWindowTitle,
        "vm_wallpaper" => Getter::VmWallpaper,
        _ => return browser::lookup(name).map(Getter::Browser).or_else(|| system::lookup(name).map(Getter::System)),
    })
}

impl Getter {
    /// Runs the getter with a task's parameters (every key of the getter object but `type`).
    ///
    /// # Errors
    ///
    /// [`GetterError`] naming the getter: bad parameters, a failed guest call,
    /// a failed download or a host file that could not be written.
    pub async fn fetch(self, ctx: &EvalContext, params: &Map<String, Value>) -> Result<Fetched, GetterError> {
        match self {
            Getter::Rule => general::rule(&Params::new("rule", params)),
            Getter::CloudFile => file::cloud_file(ctx, &Params::new("cloud_file", params)).await,
            Getter::HostFile => file::host_file(ctx, &Params::new("host_file", params)),
            Getter::VmFile => file::vm_file(ctx, &Params::new("vm_file", params)).await,
            Getter::VmFileExistsInVmFolder => {
                file::vm_file_exists_in_vm_folder(ctx, &Params::new("vm_file_exists_in_vm_folder", params)).await
            }
            Getter::VmFolderExistsInDocuments => {
                explorer::vm_folder_exists_in_documents(ctx, &Params::new("vm_folder_exists_in_documents", params))
                    .await
            }
            Getter::VmFileExistsInDesktop => {
                explorer::vm_file_exists_in_desktop(ctx, &Params::new("vm_file_exists_in_desktop", params)).await
            }
            Getter::VmCommandLine => general::vm_command_line(ctx, &Params::new("vm_command_line", params)).await,
            Getter::VmActiveWindowTitle => {
                info::vm_active_window_title(ctx, &Params::new("vm_active_window_title", params)).await
            }
            Getter::VmWallpaper => info::vm_wallpaper(ctx, &Params::new("vm_wallpaper", params)).await,
            Getter::Browser(getter) => getter.fetch(ctx, params).await,
            Getter::System(getter) => getter.fetch(ctx, params).await,
        }
    }
}

/// A getter's parameters with typed access; errors name the getter and the key.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Params<'a> {
    pub(crate) getter: &'static str,
    pub(crate) map: &'a Map<String, Value>,
}

impl<'a> Params<'a> {
    pub(crate) fn new(getter: &'static str, map: &'a Map<String, Value>) -> Params<'a> {
        Params { getter, map }
    }

    pub(crate) fn bad(&self, message: impl Into<String>) -> GetterError {
        GetterError::BadParams { getter: self.getter, message: message.into() }
    }

    pub(crate) fn guest(&self, source: ClientError) -> GetterError {
        GetterError::Guest { getter: self.getter, source: Box::new(source) }
    }

    pub(crate) fn io(&self, path: &Path, source: std::io::Error) -> GetterError {
        GetterError::Io { getter: self.getter, path: path.to_owned(), source }
    }

    pub(crate) fn failed(&self, message: impl Into<String>) -> GetterError {
        GetterError::Failed { getter: self.getter, message: message.into() }
    }

    pub(crate) fn get(&self, key: &str) -> Result<&'a Value, GetterError> {
        self.map.get(key).ok_or_else(|| self.bad(format!("missing parameter `{key}`")))
    }

    pub(crate) fn string(&self, key: &str) -> Result<&'a str, GetterError> {
        match self.get(key)? {
            Value::String(s) => Ok(s),
            other => Err(self.bad(format!("`{key}` must be a string, not {}", json_kind(other)))),
        }
    }

    /// A list of strings (`multi` paths and dests).
    pub(crate) fn strings(&self, key: &str) -> Result<Vec<&'a str>, GetterError> {
        match self.get(key)? {
            Value::Array(items) => items
                .iter()
                .enumerate()
                .map(|(idx, v)| v.as_str().ok_or_else(|| self.bad(format!("`{key}[{idx}]` must be a string"))))
                .collect(),
            other => Err(self.bad(format!("`{key}` must be a list of strings, not {}", json_kind(other)))),
        }
    }

    /// Python truthiness of an optional key (absent is false).
    pub(crate) fn truthy(&self, key: &str) -> bool {
        self.map.get(key).is_some_and(super::value::py_truthy)
    }

    /// `set(config.get("gives", [0]))`: which of several files a getter returns.
    pub(crate) fn gives(&self) -> Result<Vec<usize>, GetterError> {
        match self.map.get("gives") {
            None => Ok(vec![0]),
            Some(Value::Array(items)) => items
                .iter()
                .map(|v| {
                    v.as_u64()
                        .and_then(|n| usize::try_from(n).ok())
                        .ok_or_else(|| self.bad(format!("`gives` holds {v}, not a file index")))
                })
                .collect(),
            Some(other) => Err(self.bad(format!("`gives` must be a list of indices, not {}", json_kind(other)))),
        }
    }
}

/// Where a getter saves `dest` on the host: a plain relative name inside the
/// task's work folder (created if missing). Upstream joins `dest` to its
/// cache folder unchecked; here a task cannot write outside the folder.
///
/// # Errors
///
/// [`GetterError::BadParams`] for an empty, absolute or `..` name;
/// [`GetterError::Io`] when the folder cannot be created.
pub(crate) fn dest_path(ctx: &EvalContext, params: &Params<'_>, dest: &str) -> Result<PathBuf, GetterError> {
    let relative = Path::new(dest);
    let plain =
        !dest.is_empty() && !dest.contains('\\') && relative.components().all(|c| matches!(c, Component::Normal(_)));
    if !plain {
        return Err(params.bad(format!("`dest` {dest:?} must be a relative file name inside the work folder")));
    }
    let path = ctx.work_dir.join(relative);
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).map_err(|err| params.io(parent, err))?;
    }
    Ok(path)
}

/// Upstream's `cache_paths[0] if len(cache_paths) == 1 else cache_paths`.
pub(crate) fn one_or_list(mut values: Vec<Fetched>) -> Fetched {
    if values.len() == 1 {
        values.pop().unwrap_or(Fetched::None)
    } else {
        Fetched::List(values)
    }
}

/// Joins a guest folder and a name as Windows paths are joined (`ntpath.join`).
pub(crate) fn guest_join(folder: &str, name: &str) -> String {
    arena_shared::ntpath::join(&[folder, name])
}

/// A guest file's bytes; `None` when the guest answers that it has no such
/// readable file (or refuses it), as upstream's `get_file` returns `None` for
/// any non-200. A guest that cannot be reached is an error, so an
/// infrastructure fault is not scored as a miss.
pub(crate) async fn pull_optional(
    ctx: &EvalContext,
    p: &Params<'_>,
    path: &str,
) -> Result<Option<Vec<u8>>, GetterError> {
    match ctx.client.pull_file(path).await {
        Ok(file) => Ok(Some(file.bytes)),
        Err(ClientError::Api { .. }) => {
            tracing::debug!(getter = p.getter, %path, "the guest has no such file");
            Ok(None)
        }
        Err(err) => Err(p.guest(err)),
    }
}
