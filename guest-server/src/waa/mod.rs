//! The upstream WindowsAgentArena server's 44 URL rules, compatible in methods,
//! request fields, response shapes, status codes and error texts
//! (the reference's `waa-api.md` §a; deviations in `docs/compatibility.md`).
//!
//! This is a thin layer over the same [`Desktop`] calls the native API uses: the
//! routes parse Flask-style bodies, call the backend through [`crate::call::blocking`],
//! and render upstream's answers. They know no Win32.
//!
//! # Layout
//!
//! - [`body`]: `request.json` / `request.form` extraction with Flask's errors and Python dict semantics.
//! - [`py`]: Python renderings (`repr`, `str`, `OSError` texts).
//! - [`execute`]: `/execute`, `/setup/execute`, `/setup/launch`, `/update_computer`, `/execute_windows`.
//! - [`observe`]: screen, windows, accessibility and system-information routes.
//! - [`files`]: file transfer and file-system setup routes.
//! - [`setup`]: window activation and closing.
//! - [`queries`]: the evaluator helpers over the foreground window's accessibility tree and the file system.
//! - [`recording`]: screen recording and the snapshot stubs.
//! - the accessibility tree in upstream's XML is `arena_shared::a11y_xml`.
//!
//! # Errors
//!
//! Everything upstream's catch-all handler would catch becomes a [`WaaError::Catch`]
//! (500, `{"status":"error","message":...}`); the 400/404/501 answers a view returns
//! itself are rebuilt byte for byte as [`WaaError::Custom`] or plain responses.

mod body;
pub mod execute;
mod files;
mod observe;
mod py;
pub(crate) mod queries;
mod recording;
mod setup;

use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use axum::extract::{DefaultBodyLimit, FromRef};
use axum::http::{header, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post, MethodRouter};
use axum::{Json, Router};

use crate::config::{ACTIONS_BODY_BYTES, EXECUTE_BODY_BYTES, JSON_BODY_BYTES};
use crate::desktop::Desktop;
use crate::error::WaaError;
use crate::state::AppState;

pub use execute::ComputerState;

/// What upstream keeps in module globals: the `/update_computer` state and the
/// recording process. (Upstream's third, the human question and answer, never
/// changes here: `human.*` code is refused, so `/obs_winagent` shows its defaults.)
#[derive(Debug, Default)]
pub struct WaaState {
    computer: Mutex<Option<Arc<ComputerState>>>,
    recording: tokio::sync::Mutex<Option<recording::Recording>>,
}

/// Locks a mutex, carrying on with the data if a panicking thread poisoned it:
/// the state is plain data that a panic cannot leave half-updated.
fn lock<T>(mutex: &Mutex<T>) -> MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

impl WaaState {
    /// The state of the last `/update_computer`, or `None` before the first one
    /// (upstream's `computer.mouse` and friends are `None` then).
    pub fn computer(&self) -> Option<Arc<ComputerState>> {
        lock(&self.computer).clone()
    }

    /// Replaces the computer state, as `computer.update(...)` does.
    pub fn set_computer(&self, computer: ComputerState) {
        *lock(&self.computer) = Some(Arc::new(computer));
    }

    /// Replaces the computer state with `next` if it is still `current`: what an
    /// `/execute_windows` run changed never overwrites a newer `/update_computer`.
    pub fn replace_computer(&self, current: &Arc<ComputerState>, next: ComputerState) -> bool {
        let mut slot = lock(&self.computer);
        let unchanged = slot.as_ref().is_some_and(|stored| Arc::ptr_eq(stored, current));
        if unchanged {
            *slot = Some(Arc::new(next));
        }
        unchanged
    }

    /// `human.get_past_input()` before any question: upstream's default text.
    pub fn human_input(&self) -> &'static str {
        "Question: No question asked yet\nAnswer: No answer given yet"
    }
}

/// What WAA handlers can extract: the server's state, and the WAA session state,
/// which belongs to this layer alone (the native API never sees it).
#[derive(Debug, Clone)]
pub(crate) struct WaaContext {
    app: AppState,
    session: Arc<WaaState>,
}

impl FromRef<WaaContext> for AppState {
    fn from_ref(ctx: &WaaContext) -> AppState {
        ctx.app.clone()
    }
}

impl FromRef<WaaContext> for Arc<WaaState> {
    fn from_ref(ctx: &WaaContext) -> Arc<WaaState> {
        ctx.session.clone()
    }
}

/// The 44 upstream URL rules with upstream's methods (plus the `OPTIONS` Flask adds),
/// with a fresh WAA session (no `/update_computer` yet, no recording).
pub fn routes(state: &AppState) -> Router<AppState> {
    let ctx = WaaContext { app: state.clone(), session: Arc::new(WaaState::default()) };
    let small = Router::new()
        .route("/probe", get_rule(observe::probe))
        .route("/shutdown", post_rule(observe::shutdown))
        .route("/setup/launch", post_rule(execute::launch))
        .route("/screenshot", get_rule(observe::screenshot))
        .route("/terminal", get_rule(observe::terminal))
        .route("/obs_winagent", get_rule(observe::obs_winagent))
        .route("/accessibility", get_rule(observe::accessibility))
        .route("/screen_size", post_rule(observe::screen_size))
        .route("/window_size", post_rule(observe::window_size))
        .route("/desktop_path", post_rule(observe::desktop_path))
        .route("/documents_path", post_rule(observe::documents_path))
        .route("/setup/create_folder", post_rule(files::create_folder))
        .route("/setup/recycle", post_rule(files::recycle))
        .route("/folder_exists", post_rule(files::folder_exists))
        .route("/file_exists", post_rule(files::file_exists))
        .route("/is_details_view", post_rule(queries::is_details_view))
        .route("/wallpaper", post_rule(files::wallpaper))
        .route("/list_directory", post_rule(files::list_directory))
        .route("/file", post_rule(files::file))
        .route("/platform", get_rule(observe::platform))
        .route("/cursor_position", get_rule(observe::cursor_position))
        .route("/setup/change_wallpaper", post_rule(files::change_wallpaper))
        .route("/setup/download_file", post_rule(files::download_file))
        .route("/setup/open_file", post_rule(files::open_file))
        .route("/setup/activate_window", post_rule(setup::activate_window))
        .route("/setup/clear_task_files", post_rule(files::clear_task_files))
        .route("/setup/close_all", post_rule(setup::close_all))
        .route("/setup/close_window", post_rule(setup::close_window))
        .route("/start_recording", post_rule(recording::start_recording))
        .route("/end_recording", post_rule(recording::end_recording))
        .route("/save_state", post_rule(recording::save_state))
        .route("/revert_to_snapshot", post_rule(recording::revert_to_snapshot))
        .route("/are_files_sorted_by_modified_time", post_rule(queries::are_files_sorted_by_modified_time))
        .route("/is_directory_read_only_for_user", post_rule(queries::is_directory_read_only_for_user))
        .route("/are_all_images_tagged", post_rule(queries::are_all_images_tagged))
        .route("/library_folders", post_rule(queries::library_folders))
        .route("/check_if_timer_started", post_rule(queries::check_if_timer_started))
        .route("/check_if_world_clock_exists", post_rule(queries::check_if_world_clock_exists))
        .layer(DefaultBodyLimit::max(JSON_BODY_BYTES));
    let execute = Router::new()
        .route("/execute_windows", post_rule(execute::execute_windows))
        .route("/setup/execute", post_rule(execute::execute))
        .route("/execute", post_rule(execute::execute))
        .layer(DefaultBodyLimit::max(EXECUTE_BODY_BYTES));
    let update = Router::new()
        .route("/setup/create_file", post_rule(files::create_file))
        .route("/update_computer", post_rule(execute::update_computer))
        .layer(DefaultBodyLimit::max(ACTIONS_BODY_BYTES));
    // `/setup/upload` keeps the router's `--max-body-bytes`.
    let upload = Router::new().route("/setup/upload", post_rule(files::upload));
    small.merge(execute).merge(update).merge(upload).with_state(ctx)
}

/// A `POST` rule; Flask also answers `OPTIONS` on it.
fn post_rule<H, T>(handler: H) -> MethodRouter<WaaContext>
where
    H: axum::handler::Handler<T, WaaContext>,
    T: 'static,
{
    post(handler).options(|| async { allow("OPTIONS, POST") })
}

/// A `GET` rule; axum answers `HEAD` from it, and Flask also answers `OPTIONS`.
fn get_rule<H, T>(handler: H) -> MethodRouter<WaaContext>
where
    H: axum::handler::Handler<T, WaaContext>,
    T: 'static,
{
    get(handler).options(|| async { allow("GET, HEAD, OPTIONS") })
}

/// Flask's automatic `OPTIONS` answer: an empty 200 naming the allowed methods.
fn allow(methods: &'static str) -> Response {
    let mut res = text(StatusCode::OK, "");
    res.headers_mut().insert(header::ALLOW, HeaderValue::from_static(methods));
    res
}

/// What a WAA handler returns.
pub(crate) type WaaResult = Result<Response, WaaError>;

/// A `str` a Flask view returns: `text/html; charset=utf-8`.
pub(crate) fn text(status: StatusCode, body: impl Into<String>) -> Response {
    let mut res = (status, body.into()).into_response();
    res.headers_mut().insert(header::CONTENT_TYPE, HeaderValue::from_static("text/html; charset=utf-8"));
    res
}

/// A `jsonify(...)` with a status.
pub(crate) fn json(status: StatusCode, value: serde_json::Value) -> Response {
    (status, Json(value)).into_response()
}

/// A route's own error answer (`return jsonify({...}), 400`) as a [`WaaError`].
pub(crate) fn json_err(status: StatusCode, value: serde_json::Value) -> WaaError {
    WaaError::custom(json(status, value))
}

/// A route's own text error answer (`return "...", 404`) as a [`WaaError`].
pub(crate) fn text_err(status: StatusCode, body: impl Into<String>) -> WaaError {
    WaaError::custom(text(status, body))
}

/// Runs synchronous work (backend calls, `std::fs`) on the backend pool with the
/// ordinary call deadline.
pub(crate) async fn on_backend<T, F>(state: &AppState, op: &'static str, f: F) -> Result<T, WaaError>
where
    F: FnOnce(&dyn Desktop) -> Result<T, WaaError> + Send + 'static,
    T: Send + 'static,
{
    on_backend_within(state, op, state.call_timeout(), f).await
}

/// [`on_backend`] with an explicit deadline.
pub(crate) async fn on_backend_within<T, F>(
    state: &AppState,
    op: &'static str,
    deadline: Duration,
    f: F,
) -> Result<T, WaaError>
where
    F: FnOnce(&dyn Desktop) -> Result<T, WaaError> + Send + 'static,
    T: Send + 'static,
{
    crate::call::blocking(&state.desktop, op, deadline, move |desktop| Ok(f(desktop))).await?
}

/// `os.path.expandvars(os.path.expanduser(path))` with the guest's environment.
pub(crate) fn expand(desktop: &dyn Desktop, path: &str) -> String {
    crate::paths::expand(path, &mut |name| desktop.env_var(name))
}

/// `os.path.expanduser(path)` with the guest's environment.
pub(crate) fn expand_user(desktop: &dyn Desktop, path: &str) -> String {
    arena_shared::ntpath::expanduser(path, &mut |name| desktop.env_var(name))
}

/// A required string argument: Python would raise `TypeError` in `os.fspath` for anything else.
pub(crate) fn path_arg(value: &serde_json::Value) -> Result<String, WaaError> {
    match value {
        serde_json::Value::String(s) => Ok(s.clone()),
        other => {
            Err(WaaError::catch(format!("expected str, bytes or os.PathLike object, not {}", py::type_name(other))))
        }
    }
}
