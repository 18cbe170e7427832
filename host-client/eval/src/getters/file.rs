//! Getters of upstream's `getters/file.py`: guest files (`vm_file`), files
//! from the web through the host's download cache (`cloud_file`), and a file
//! existence check (`vm_file_exists_in_vm_folder`); and this project's
//! `host_file`, expected files kept on the host beside the task file.

use std::path::PathBuf;
use std::time::{SystemTime, UNIX_EPOCH};

use serde_json::{Map, Value};

use arena_shared::calendar::{civil_from_days, days_from_civil};
use arena_shared::files::FileKind;

use super::{dest_path, guest_join, one_or_list, GetterError, Params};
use crate::value::Fetched;
use crate::EvalContext;
use arena_client::error::ClientError;

/// `path` and `dest` as one pair, or as two lists with `multi`.
fn pairs<'a>(params: &Params<'a>) -> Result<Vec<(String, String)>, GetterError> {
    if params.truthy("multi") {
        let paths = params.strings("path")?;
        let dests = params.strings("dest")?;
        // Upstream zips the lists, so the shorter one decides; say so instead of guessing.
        if paths.len() != dests.len() {
            return Err(params.bad(format!("`path` has {} entries but `dest` has {}", paths.len(), dests.len())));
        }
        Ok(paths.into_iter().zip(dests).map(|(p, d)| (p.to_owned(), d.to_owned())).collect())
    } else {
        Ok(vec![(params.string("path")?.to_owned(), params.string("dest")?.to_owned())])
    }
}

/// `get_vm_file`: downloads each guest `path` into the work folder as `dest`.
/// Returns the `gives` entries (default the first): a path, or `None` for a
/// file the guest does not have (or refuses to read), as upstream; one entry
/// comes back alone, several as a list. `time_suffix` (single file only)
/// inserts the date before the first dot of both names, as upstream does.
pub(super) async fn vm_file(ctx: &EvalContext, params: &Params<'_>) -> Result<Fetched, GetterError> {
    let mut pairs = pairs(params)?;
    if !params.truthy("multi") && params.truthy("time_suffix") {
        let format = match params.map.get("time_format") {
            Some(_) => params.string("time_format")?,
            None => "%Y_%m_%d",
        };
        let stamp = strftime_utc(format, SystemTime::now());
        for (path, dest) in &mut pairs {
            *path = with_suffix(path, &stamp);
            *dest = with_suffix(dest, &stamp);
        }
    }
    let gives = params.gives()?;
    let mut out = Vec::new();
    for (idx, (path, dest)) in pairs.iter().enumerate() {
        let local = dest_path(ctx, params, dest)?;
        match ctx.client.pull_file(path).await {
            Ok(file) => {
                std::fs::write(&local, &file.bytes).map_err(|err| params.io(&local, err))?;
                if gives.contains(&idx) {
                    out.push(Fetched::File(local));
                }
            }
            // Any answer from the guest that is not the file (404, 403, a
            // directory) is upstream's `None`; a guest that cannot be reached
            // is an error, so an infrastructure fault is not scored as a miss.
            Err(ClientError::Api { .. }) => {
                tracing::debug!(getter = "vm_file", %path, "the guest has no such file");
                if gives.contains(&idx) {
                    out.push(Fetched::None);
                }
            }
            Err(err) => return Err(params.guest(err)),
        }
    }
    Ok(one_or_list(out))
}

/// `get_cloud_file`: fetches each URL through the host's content-addressed
/// download cache and copies it into the work folder as `dest`; returns the
/// `gives` entries like [`vm_file`]. A failed download is an error.
pub(super) async fn cloud_file(ctx: &EvalContext, params: &Params<'_>) -> Result<Fetched, GetterError> {
    let pairs = pairs(params)?;
    let gives = params.gives()?;
    let mut out = Vec::new();
    for (idx, (url, dest)) in pairs.iter().enumerate() {
        let local = dest_path(ctx, params, dest)?;
        let cached = ctx
            .cache
            .fetch(url)
            .await
            .map_err(|err| GetterError::Download { getter: params.getter, message: err.to_string() })?;
        std::fs::copy(&cached, &local).map_err(|err| params.io(&local, err))?;
        if gives.contains(&idx) {
            out.push(Fetched::File(local));
        }
    }
    Ok(one_or_list(out))
}

/// `host_file` (this project's, no upstream task uses it): copies each `path`,
/// relative to the task file's folder, into the work folder as `dest`; returns
/// the `gives` entries like [`vm_file`]. It is how expected files stay with the
/// grader, as `cloud_file` gold does upstream, without a web server: the guest
/// never holds them. A path that is absolute or climbs out of the task's folder
/// is refused, and a missing file is an error (the task is broken, not the agent).
pub(super) fn host_file(ctx: &EvalContext, params: &Params<'_>) -> Result<Fetched, GetterError> {
    let pairs = pairs(params)?;
    let gives = params.gives()?;
    let sources = host_sources(ctx.task_dir.as_deref(), params)?;
    let mut out = Vec::new();
    for (idx, ((_, dest), source)) in pairs.iter().zip(sources).enumerate() {
        let local = dest_path(ctx, params, dest)?;
        std::fs::copy(&source, &local).map_err(|err| params.io(&source, err))?;
        if gives.contains(&idx) {
            out.push(Fetched::File(local));
        }
    }
    Ok(one_or_list(out))
}

/// The host files a `host_file` getter reads: each `path` inside `task_dir`.
///
/// # Errors
///
/// [`GetterError::BadParams`] without a task folder, or for a path that is
/// absolute or climbs out of it.
fn host_sources(task_dir: Option<&std::path::Path>, params: &Params<'_>) -> Result<Vec<PathBuf>, GetterError> {
    let Some(task_dir) = task_dir else {
        return Err(params.bad("the task file's folder is not known here, so no host file can be read"));
    };
    pairs(params)?
        .into_iter()
        .map(|(path, _)| {
            let relative = std::path::Path::new(&path);
            let inside = !path.is_empty()
                && !path.contains('\\')
                && relative.components().all(|c| matches!(c, std::path::Component::Normal(_)));
            if inside {
                Ok(task_dir.join(relative))
            } else {
                Err(params.bad(format!("`path` {path:?} must be a relative path inside the task file's folder")))
            }
        })
        .collect()
}

/// Why the `host_file` getter with `params` could not read its gold from
/// `task_dir`, or `None` when every file it names is there (a check made before
/// an episode, so a broken task is refused instead of played).
pub(crate) fn host_file_problem(task_dir: Option<&std::path::Path>, params: &Map<String, Value>) -> Option<String> {
    let params = Params::new("host_file", params);
    match host_sources(task_dir, &params) {
        Err(err) => Some(err.to_string()),
        Ok(sources) => sources
            .iter()
            .find(|source| !source.is_file())
            .map(|source| format!("getter host_file: {} is not a file", source.display())),
    }
}

/// `get_vm_file_exists_in_vm_folder`: `1.0` when the guest has a non-empty
/// file `folder_name\file_name`, else `0.0` (also when either name is empty).
/// Upstream downloads the file and tests the bytes' truthiness, so an empty
/// file counts as missing; a stat gives the same answer without the download.
pub(super) async fn vm_file_exists_in_vm_folder(
    ctx: &EvalContext,
    params: &Params<'_>,
) -> Result<Fetched, GetterError> {
    let folder = params.string("folder_name")?;
    let name = params.string("file_name")?;
    if folder.is_empty() || name.is_empty() {
        return Ok(Fetched::number(0.0));
    }
    let found = match ctx.client.stat(&guest_join(folder, name)).await {
        Ok(stat) => stat.kind == FileKind::File && stat.size > 0,
        Err(ClientError::Api { .. }) => false,
        Err(err) => return Err(params.guest(err)),
    };
    Ok(Fetched::number(if found { 1.0 } else { 0.0 }))
}

/// Upstream's `p.split(".")[0] + stamp + "." + p.split(".")[1] if "." in p else p`
/// (everything after a second dot is dropped, as upstream does).
fn with_suffix(name: &str, stamp: &str) -> String {
    let mut parts = name.split('.');
    match (parts.next(), parts.next()) {
        (Some(stem), Some(ext)) => format!("{stem}{stamp}.{ext}"),
        _ => name.to_owned(),
    }
}

/// `strftime` for the date and time fields (`%Y %y %m %d %H %M %S %j %%`), in UTC.
/// Other `%` sequences are kept as written.
fn strftime_utc(format: &str, now: SystemTime) -> String {
    let secs = now.duration_since(UNIX_EPOCH).map_or(0, |d| d.as_secs());
    let days = i64::try_from(secs / 86_400).unwrap_or(0);
    let rem = secs % 86_400;
    let (year, month, day) = civil_from_days(days);
    let day_of_year = days - days_from_civil(year, 1, 1) + 1;
    let mut out = String::new();
    let mut chars = format.chars();
    while let Some(c) = chars.next() {
        if c != '%' {
            out.push(c);
            continue;
        }
        match chars.next() {
            Some('Y') => out.push_str(&format!("{year:04}")),
            Some('y') => out.push_str(&format!("{:02}", year.rem_euclid(100))),
            Some('m') => out.push_str(&format!("{month:02}")),
            Some('d') => out.push_str(&format!("{day:02}")),
            Some('H') => out.push_str(&format!("{:02}", rem / 3600)),
            Some('M') => out.push_str(&format!("{:02}", rem / 60 % 60)),
            Some('S') => out.push_str(&format!("{:02}", rem % 60)),
            Some('j') => out.push_str(&format!("{day_of_year:03}")),
            Some('%') => out.push('%'),
            Some(other) => {
                out.push('%');
                out.push(other);
            }
            None => out.push('%'),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::*;

    #[test]
    fn dates_format_like_strftime() {
        // 2024-02-29 13:05:09 UTC, a leap day.
        let at = UNIX_EPOCH + Duration::from_secs(1_709_211_909);
        assert_eq!(strftime_utc("%Y_%m_%d", at), "2024_02_29");
        assert_eq!(strftime_utc("%y%m%d-%H%M%S %j %% %Q", at), "240229-130509 060 % %Q");
        assert_eq!(strftime_utc("%Y-%m-%d", UNIX_EPOCH), "1970-01-01");
    }

    #[test]
    fn suffixes_go_before_the_first_dot() {
        assert_eq!(with_suffix(r"C:\Users\Docker\report.xlsx", "2024_01_02"), r"C:\Users\Docker\report2024_01_02.xlsx");
        assert_eq!(with_suffix("a.tar.gz", "X"), "aX.tar");
        assert_eq!(with_suffix("noext", "X"), "noext");
    }
}
