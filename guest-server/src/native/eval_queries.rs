//! `POST /v1/eval/<query>`: the evaluation queries of upstream's bespoke WAA
//! routes, with typed bodies and answers (`arena_shared::eval`).
//!
//! Each route answers the same question as its legacy twin in the WAA layer,
//! with the same logic from [`crate::inspect`] (tree search, the sort rule, the
//! DACL rule, EXIF strings, library XML); only the
//! plumbing differs: paths are expanded like every native path, errors are
//! [`ApiError`]s, and "no" is a 200 with `value: false` rather than a 400.
//!
//! It is not a general query language: one route per upstream helper.

use std::time::Duration;

use axum::extract::State;
use axum::routing::post;
use axum::Router;

use arena_shared::action::{Action, MouseButton};
use arena_shared::eval::{
    DetailsViewQuery, EvalAnswer, ImagesTaggedQuery, LibraryFolders, LibraryQuery, ReadOnlyQuery,
    SortedByModifiedQuery, TimerQuery, WorldClockQuery,
};
use arena_shared::files::KnownFolder;
use arena_shared::ntpath;
use arena_shared::observation::{A11yBackend, A11yTree, TreeBudget};

use crate::call::blocking;
use crate::desktop::{Desktop, DesktopError};
use crate::error::{ApiError, AppJson};
use crate::inspect as logic;
use crate::paths;
use crate::state::AppState;

pub(crate) fn routes() -> Router<AppState> {
    Router::new()
        .route("/v1/eval/is_details_view", post(is_details_view))
        .route("/v1/eval/are_files_sorted_by_modified_time", post(are_files_sorted_by_modified_time))
        .route("/v1/eval/check_if_timer_started", post(check_if_timer_started))
        .route("/v1/eval/check_if_world_clock_exists", post(check_if_world_clock_exists))
        .route("/v1/eval/is_directory_read_only_for_user", post(is_directory_read_only_for_user))
        .route("/v1/eval/are_all_images_tagged", post(are_all_images_tagged))
        .route("/v1/eval/library_folders", post(library_folders))
}

fn answer(value: bool, detail: impl Into<String>) -> AppJson<EvalAnswer> {
    AppJson(EvalAnswer { value, detail: detail.into() })
}

fn non_empty(field: &str, value: &str) -> Result<(), ApiError> {
    if value.trim().is_empty() {
        return Err(ApiError::BadRequest(format!("{field} must not be empty")));
    }
    Ok(())
}

/// A request path with `~` and `%VAR%` expanded, as every native route takes paths.
fn expand(d: &dyn Desktop, path: &str) -> String {
    paths::expand(path, &mut |name| d.env_var(name))
}

/// The foreground window's UIA tree, walked within upstream's budget.
async fn foreground_tree(state: &AppState) -> Result<A11yTree, ApiError> {
    let tree = blocking(&state.desktop, "accessibility", state.config.a11y_timeout(), |d| {
        d.accessibility(A11yBackend::Uia, &TreeBudget::WAA, true)
    })
    .await?;
    Ok(tree)
}

async fn is_details_view(
    State(state): State<AppState>,
    AppJson(query): AppJson<DetailsViewQuery>,
) -> Result<AppJson<EvalAnswer>, ApiError> {
    non_empty("folder_path", &query.folder_path)?;
    let tree = foreground_tree(&state).await?;
    let items = logic::explorer_items(&tree).unwrap_or_default();
    // The column header shows up as an item named "Header"; a file of that name does not count.
    let details = blocking(&state.desktop, "is_details_view", state.call_timeout(), move |d| {
        let folder = expand(d, &query.folder_path);
        Ok(items
            .iter()
            .filter(|n| n.as_str() == "Header")
            .any(|name| !logic::guest_exists(d, &ntpath::join(&[&folder, name]))))
    })
    .await?;
    Ok(if details {
        answer(true, "File Explorer is in Details view")
    } else {
        answer(false, "File Explorer is not in Details view")
    })
}

async fn are_files_sorted_by_modified_time(
    State(state): State<AppState>,
    AppJson(query): AppJson<SortedByModifiedQuery>,
) -> Result<AppJson<EvalAnswer>, ApiError> {
    non_empty("directory", &query.directory)?;
    let tree = foreground_tree(&state).await?;
    let Some(items) = logic::explorer_items(&tree) else {
        return Ok(answer(
            false,
            "the foreground window has no \"Shell Folder View\" element (is File Explorer in front?)",
        ));
    };
    let sorted = blocking(&state.desktop, "are_files_sorted_by_modified_time", state.call_timeout(), move |d| {
        let folder = expand(d, &query.directory);
        let mut names = Vec::new();
        let mut stats = Vec::new();
        for name in items {
            let guest = ntpath::join(&[&folder, &name]);
            // Items that are not in the folder (the column header, group headings) are skipped, as upstream does.
            let Some(meta) = d.map_path(&guest).ok().and_then(|local| std::fs::metadata(local).ok()) else {
                continue;
            };
            let modified = meta.modified().map_err(|err| DesktopError::io("stat", &guest, err))?;
            let secs = match modified.duration_since(std::time::UNIX_EPOCH) {
                Ok(after) => i64::try_from(after.as_secs()).unwrap_or(i64::MAX),
                Err(before) => -i64::try_from(before.duration().as_secs()).unwrap_or(i64::MAX),
            };
            stats.push((name.clone(), secs, meta.is_dir()));
            names.push(name);
        }
        Ok(logic::sorted_by_mtime(&names, &stats))
    })
    .await?;
    Ok(if sorted {
        answer(true, "files are sorted by modified time")
    } else {
        answer(false, "files are not sorted by modified time")
    })
}

/// The foreground tree, after pressing the Clock app's "Maximize Clock" button if it shows one
/// (the compact view hides the lists upstream searches).
async fn clock_tree(state: &AppState) -> Result<A11yTree, ApiError> {
    let tree = foreground_tree(state).await?;
    let button = logic::find_in_tree(&tree, Some("Maximize Clock"), &|n| n == "Maximize Clock").and_then(|b| b.rect);
    let Some(rect) = button else {
        return Ok(tree);
    };
    let centre = rect.center();
    let _input = state.input_share().await;
    blocking(&state.desktop, "maximize_clock", state.call_timeout(), move |d| {
        d.perform(&Action::Click { x: Some(centre.x), y: Some(centre.y), button: MouseButton::Left, count: 1 })
    })
    .await?;
    // The window needs a moment to grow before its lists are in the tree.
    tokio::time::sleep(Duration::from_millis(state.config.activate_settle_ms)).await;
    foreground_tree(state).await
}

/// Upstream's timer label: `"<h> hour(s) <m> minute(s) <s> second(s)"`, singular for exactly 1.
fn timer_text(query: &TimerQuery) -> String {
    let part = |n: i64, unit: &str| format!("{n} {unit}{}", if n == 1 { "" } else { "s" });
    format!("{} {} {}", part(query.hours, "hour"), part(query.minutes, "minute"), part(query.seconds, "second"))
}

async fn check_if_timer_started(
    State(state): State<AppState>,
    AppJson(query): AppJson<TimerQuery>,
) -> Result<AppJson<EvalAnswer>, ApiError> {
    let text = timer_text(&query);
    let tree = clock_tree(&state).await?;
    let running = logic::find_in_tree(&tree, None, &|n| logic::first_line_contains(n, &text))
        .and_then(|timer| logic::find_element(timer, Some("Timer running, Pause"), &|n| n == "Timer running, Pause"))
        .is_some();
    Ok(if running { answer(true, "Timer exists") } else { answer(false, "Timer does not exist") })
}

async fn check_if_world_clock_exists(
    State(state): State<AppState>,
    AppJson(query): AppJson<WorldClockQuery>,
) -> Result<AppJson<EvalAnswer>, ApiError> {
    let text = format!("{}, {}", query.city, query.country);
    let tree = clock_tree(&state).await?;
    let exists = logic::find_in_tree(&tree, None, &|n| logic::first_line_contains(n, &text)).is_some();
    Ok(if exists { answer(true, "World clock exists") } else { answer(false, "World clock does not exist") })
}

async fn is_directory_read_only_for_user(
    State(state): State<AppState>,
    AppJson(query): AppJson<ReadOnlyQuery>,
) -> Result<AppJson<EvalAnswer>, ApiError> {
    non_empty("directory", &query.directory)?;
    non_empty("user", &query.user)?;
    let ReadOnlyQuery { directory, user } = query;
    let (mask, shown) = blocking(&state.desktop, "directory_access_mask", state.call_timeout(), move |d| {
        let folder = expand(d, &directory);
        let mask = d.directory_access_mask(&folder, &user)?;
        Ok((mask, format!("{folder} for {user}")))
    })
    .await?;
    Ok(match mask {
        Some(mask) if logic::mask_is_read_only(mask) => answer(true, format!("{shown}: read-only (mask {mask:#x})")),
        Some(mask) => answer(false, format!("{shown}: not read-only (mask {mask:#x})")),
        None => answer(false, format!("{shown}: no access entry names the user")),
    })
}

async fn are_all_images_tagged(
    State(state): State<AppState>,
    AppJson(query): AppJson<ImagesTaggedQuery>,
) -> Result<AppJson<EvalAnswer>, ApiError> {
    non_empty("directory", &query.directory)?;
    let ImagesTaggedQuery { directory, tag } = query;
    let untagged = blocking(&state.desktop, "are_all_images_tagged", state.call_timeout(), move |d| {
        let folder = expand(d, &directory);
        let local = d.map_path(&folder)?;
        // Upstream walks `os.listdir`.
        let names = arena_shared::ntfs::list_dir(&local).map_err(|err| DesktopError::io("list", &folder, err))?;
        let image = |name: &str| {
            let lower = name.to_lowercase();
            lower.ends_with("jpg") || lower.ends_with("jpeg") || lower.ends_with("tiff")
        };
        Ok(names
            .into_iter()
            .filter(|name| image(name))
            .find(|name| !logic::exif_strings(&local.join(name)).iter().any(|value| value.contains(tag.as_str())))
            .map(|name| (name, tag)))
    })
    .await?;
    Ok(match untagged {
        None => answer(true, "all images are tagged"),
        Some((name, tag)) => answer(false, format!("{name} is not tagged with {tag}")),
    })
}

async fn library_folders(
    State(state): State<AppState>,
    AppJson(query): AppJson<LibraryQuery>,
) -> Result<AppJson<LibraryFolders>, ApiError> {
    non_empty("library_name", &query.library_name)?;
    let name = query.library_name;
    if name.contains(['\\', '/']) || name.contains("..") {
        return Err(ApiError::BadRequest(format!("library_name {name:?} must be a plain name")));
    }
    let found = blocking(&state.desktop, "library_folders", state.call_timeout(), move |d| {
        let appdata = match d.env_var("APPDATA") {
            Some(dir) => dir,
            None => d.known_folder(KnownFolder::AppData)?,
        };
        let guest = ntpath::join(&[&appdata, &format!("Microsoft\\Windows\\Libraries\\{name}.library-ms")]);
        let bytes = d.map_path(&guest).ok().and_then(|local| std::fs::read(local).ok());
        Ok(bytes.map(|bytes| (guest, logic::decode_xml_text(&bytes))))
    })
    .await?;
    let Some((guest, xml)) = found else {
        return Ok(AppJson(LibraryFolders { exists: false, folders: Vec::new() }));
    };
    let folders = logic::library_urls(&xml).map_err(|err| {
        ApiError::Desktop(DesktopError::Os { op: "library_folders", message: format!("{guest}: {err}") })
    })?;
    Ok(AppJson(LibraryFolders { exists: true, folders }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timer_labels_use_singular_for_one() {
        let check =
            |hours, minutes, seconds, want: &str| assert_eq!(timer_text(&TimerQuery { hours, minutes, seconds }), want);
        check(0, 30, 0, "0 hours 30 minutes 0 seconds");
        check(1, 1, 1, "1 hour 1 minute 1 second");
        check(3, 0, 0, "3 hours 0 minutes 0 seconds");
    }
}
