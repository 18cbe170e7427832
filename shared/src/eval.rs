//! Evaluation queries (`POST /v1/eval/<query>`): questions about the guest's
//! state that upstream's evaluators ask through bespoke WAA routes
//! (`/is_details_view`, `/check_if_timer_started`, `/library_folders`, ...),
//! answered with typed bodies instead of a status code.
//!
//! These are not general-purpose routes: each one mirrors one upstream helper,
//! with its semantics, so the host's getters need neither Python nor PowerShell
//! in the guest.

use serde::{Deserialize, Serialize};

/// `POST /v1/eval/is_details_view`: whether the foreground File Explorer window shows Details view.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct DetailsViewQuery {
    /// The folder the window shows (used to tell a file named "Header" from the column header).
    pub folder_path: String,
}

/// `POST /v1/eval/are_files_sorted_by_modified_time`: whether the foreground
/// File Explorer window lists `directory`'s items by modification time.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct SortedByModifiedQuery {
    pub directory: String,
}

/// `POST /v1/eval/check_if_timer_started`: whether the Clock app runs a timer of this length.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct TimerQuery {
    pub hours: i64,
    pub minutes: i64,
    pub seconds: i64,
}

/// `POST /v1/eval/check_if_world_clock_exists`: whether the Clock app lists `"<city>, <country>"`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct WorldClockQuery {
    pub city: String,
    pub country: String,
}

/// `POST /v1/eval/is_directory_read_only_for_user`: whether the first ACE of
/// `directory`'s DACL naming `user` grants reading and no writing.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ReadOnlyQuery {
    pub directory: String,
    pub user: String,
}

/// `POST /v1/eval/are_all_images_tagged`: whether every JPEG and TIFF in
/// `directory` carries `tag` in its EXIF data (Windows writes tags to `XPKeywords`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ImagesTaggedQuery {
    pub directory: String,
    pub tag: String,
}

/// `POST /v1/eval/library_folders`: the folders of a Windows library.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct LibraryQuery {
    pub library_name: String,
}

/// The answer of the yes-or-no queries.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct EvalAnswer {
    pub value: bool,
    /// Why, in upstream's words where it has them ("Timer does not exist").
    #[serde(default)]
    pub detail: String,
}

/// The answer of `POST /v1/eval/library_folders`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct LibraryFolders {
    /// Whether the library's `.library-ms` file exists.
    pub exists: bool,
    /// The library's folder paths, sorted; empty when it does not exist.
    #[serde(default)]
    pub folders: Vec<String>,
}
