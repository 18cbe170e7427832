//! `POST /v1/exec`, `/v1/launch` and `/v1/open`: running programs and opening files.
//!
//! Programs run from an argument vector, so no argument is ever re-parsed, or,
//! when the request gives `shell` instead, from one command line handed to the
//! shell unchanged (as Python's `subprocess` with `shell=True`). A program that exits non-zero or runs out of
//! time is a normal 200 [`ExecResult`]; only a program that cannot be started
//! is an error.

use std::time::Duration;

use axum::extract::State;
use axum::http::StatusCode;
use axum::routing::post;
use axum::Router;

use arena_shared::exec::{ExecRequest, ExecResult, LaunchRequest, LaunchResult};
use arena_shared::files::PathQuery;

use crate::call::blocking;
use crate::desktop::{CommandSpec, DesktopError, ExecLimits};
use crate::error::{ApiError, AppJson};
use crate::paths;
use crate::state::AppState;

use super::files::existing_guest_path;

/// Timeout when the request names none.
const DEFAULT_TIMEOUT_MS: u64 = 60_000;
/// Longest timeout granted: ten minutes.
const MAX_TIMEOUT_MS: u64 = 600_000;
/// Output kept per stream when the request names no limit: 16 MiB.
const DEFAULT_MAX_OUTPUT: u64 = 16 << 20;
/// Most output kept per stream: 256 MiB.
const MAX_OUTPUT: u64 = 256 << 20;
/// Time the backend gets past the program's timeout to kill it and collect the output.
const DEADLINE_MARGIN: Duration = Duration::from_secs(5);

pub(crate) fn routes() -> Router<AppState> {
    Router::new().route("/v1/exec", post(exec)).route("/v1/launch", post(launch)).route("/v1/open", post(open))
}

/// The program a command names, for error messages: `argv[0]`, or the shell.
fn program_of(command: &CommandSpec) -> String {
    match command {
        CommandSpec::Argv(argv) => argv.first().cloned().unwrap_or_default(),
        CommandSpec::Shell(_) => "the shell".to_owned(),
    }
}

/// Makes a backend "not found" name the program, whatever words the backend used.
fn name_program(err: DesktopError, program: &str) -> ApiError {
    match err {
        DesktopError::NotFound(message) if !message.contains(program) => {
            ApiError::NotFound(format!("program {program:?} not found: {message}"))
        }
        other => ApiError::from(other),
    }
}

async fn exec(
    State(state): State<AppState>,
    AppJson(request): AppJson<ExecRequest>,
) -> Result<AppJson<ExecResult>, ApiError> {
    let command = request.command().map_err(ApiError::BadRequest)?;
    let timeout_ms = match request.timeout_ms {
        Some(0) => return Err(ApiError::BadRequest("timeout_ms must be at least 1".into())),
        Some(ms) => ms.min(MAX_TIMEOUT_MS),
        None => DEFAULT_TIMEOUT_MS,
    };
    let max_output_bytes = request.max_output_bytes.unwrap_or(DEFAULT_MAX_OUTPUT).min(MAX_OUTPUT);
    let program = program_of(&command);
    let deadline = Duration::from_millis(timeout_ms) + DEADLINE_MARGIN;
    let ExecRequest { cwd, stdin, .. } = request;
    // One of the programs running at once (`--max-programs`), held by the work itself.
    let place = state.programs.admit().await?;
    // The program may drive the keyboard and mouse as agent code does.
    let _input = state.input_share().await;
    let output = blocking(&state.desktop, "run", deadline, move |d| {
        let _place = place;
        let cwd = cwd.map(|cwd| paths::expand(&cwd, &mut |name| d.env_var(name)));
        let limits = ExecLimits { timeout_ms, max_output_bytes, cwd, stdin: stdin.map(String::into_bytes) };
        d.run(&command, &limits)
    })
    .await
    .map_err(|err| name_program(err, &program))?;
    Ok(AppJson(ExecResult {
        exit_code: output.exit_code,
        stdout: output.stdout,
        stderr: output.stderr,
        stdout_truncated: output.stdout_truncated,
        stderr_truncated: output.stderr_truncated,
        timed_out: output.timed_out,
        duration_ms: output.duration_ms,
    }))
}

async fn launch(
    State(state): State<AppState>,
    AppJson(request): AppJson<LaunchRequest>,
) -> Result<AppJson<LaunchResult>, ApiError> {
    let command = request.command().map_err(ApiError::BadRequest)?;
    let program = program_of(&command);
    let pid = blocking(&state.desktop, "spawn", state.call_timeout(), move |d| d.spawn(&command))
        .await
        .map_err(|err| name_program(err, &program))?;
    Ok(AppJson(LaunchResult { pid }))
}

async fn open(State(state): State<AppState>, AppJson(request): AppJson<PathQuery>) -> Result<StatusCode, ApiError> {
    let opened = blocking(&state.desktop, "open_path", state.call_timeout(), move |d| {
        Ok(existing_guest_path(d, &request.path).and_then(|guest| Ok(d.open_path(&guest)?)))
    })
    .await?;
    opened?;
    Ok(StatusCode::NO_CONTENT)
}
