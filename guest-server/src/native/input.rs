//! `POST /v1/actions`: a batch of typed input actions, executed in order.
//!
//! The whole batch is validated before anything runs, so a typo in the last
//! key name never leaves the desktop half-driven, and so are its bounds: at most
//! [`MAX_ACTIONS`] actions, a `type_text` of at most
//! [`arena_shared::action::MAX_TYPE_TEXT_BYTES`] (1 MiB), and at most
//! [`MAX_BATCH_MS`] (5 minutes) of waits, drags and typing pauses in all. Then every action but
//! [`Action::Wait`] is one backend call; waits sleep asynchronously between
//! calls and hold no blocking thread. The first failure stops the batch and
//! the error says which action failed and how many ran before it.

use std::time::{Duration, Instant};

use axum::extract::State;
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use axum::routing::post;
use axum::{Json, Router};

use arena_shared::action::{Action, ActionBatch, ActionReport, MouseButton};
use arena_shared::error::{ErrorBody, ErrorCode};
use arena_shared::keys::Key;

use crate::call::blocking;
use crate::error::{ApiError, AppJson};
use crate::state::AppState;

use super::millis;

/// Most actions in one batch.
const MAX_ACTIONS: usize = 1000;
/// Longest single wait.
const MAX_WAIT_MS: u64 = 60_000;
/// Most repetitions of one click or key press; more is a runaway loop, not an agent's intent.
const MAX_REPEAT: u32 = 1000;
/// Most keys one hotkey (MCP's `press_keys`) presses together: a chord, not a text.
const MAX_CHORD_KEYS: usize = 64;
/// Most time one batch may plan by its own waits, drags and typing pauses: 5 minutes.
/// (A thousand one-minute waits were accepted before: 16.7 hours holding a connection.)
pub(crate) const MAX_BATCH_MS: u64 = 300_000;

pub(crate) fn routes() -> Router<AppState> {
    Router::new()
        .route("/v1/actions", post(actions))
        .layer(axum::extract::DefaultBodyLimit::max(crate::config::ACTIONS_BODY_BYTES))
}

async fn actions(
    State(state): State<AppState>,
    AppJson(batch): AppJson<ActionBatch>,
) -> Result<AppJson<ActionReport>, Response> {
    validate(&batch.actions, state.call_timeout()).map_err(IntoResponse::into_response)?;
    // Batches share the input; a doctor run takes it alone (see `native::doctor`).
    let _input = state.input_share().await;
    let started = Instant::now();
    let total = batch.actions.len();
    // The cursor the answer reports, read in the last action's own backend call when
    // the batch ends with one (one handoff to the backend pool fewer per batch).
    let mut cursor = None;
    for (index, action) in batch.actions.into_iter().enumerate() {
        if let Action::Wait { ms } = action {
            tokio::time::sleep(Duration::from_millis(ms)).await;
            continue;
        }
        let name = action_name(&action);
        let last = index + 1 == total;
        let res = blocking(&state.desktop, "perform", state.call_timeout(), move |d| {
            d.perform(&action)?;
            Ok(last.then(|| d.cursor_position()))
        })
        .await;
        match res {
            Ok(read) => cursor = read,
            Err(err) => return Err(batch_failed(ApiError::from(err), index, name, total)),
        }
    }
    let cursor = match cursor {
        Some(read) => read,
        None => blocking(&state.desktop, "cursor_position", state.call_timeout(), |d| d.cursor_position()).await,
    }
    .map_err(|err| ApiError::from(err).into_response())?;
    Ok(AppJson(ActionReport { executed: total, cursor, elapsed_ms: millis(started.elapsed()) }))
}

/// Longest pause between typed characters that a backend honours.
const MAX_TYPING_PAUSE_MS: u64 = 10_000;

/// How long an action takes at least, by its own pauses (typing with an interval).
fn planned_duration(action: &Action) -> Duration {
    match action {
        Action::TypeText { text, interval_ms: Some(ms) } => {
            let pauses = u64::try_from(text.chars().count().saturating_sub(1)).unwrap_or(u64::MAX);
            Duration::from_millis(pauses.saturating_mul((*ms).min(MAX_TYPING_PAUSE_MS)))
        }
        Action::Drag { duration_ms: Some(ms), .. } => Duration::from_millis(*ms),
        _ => Duration::ZERO,
    }
}

/// Checks every action of a batch before any runs: names, counts, and that no action
/// is planned to outlast the call deadline (it would be cut off part-way). The guest's
/// MCP input tools go through it too, each call as a batch of one.
pub(crate) fn validate(actions: &[Action], call_deadline: Duration) -> Result<(), ApiError> {
    if actions.len() > MAX_ACTIONS {
        return Err(ApiError::BadRequest(format!(
            "a batch holds at most {MAX_ACTIONS} actions (got {})",
            actions.len()
        )));
    }
    let mut total = Duration::ZERO;
    for (index, action) in actions.iter().enumerate() {
        check_action(action)
            .map_err(|why| ApiError::BadRequest(format!("action {index} ({}): {why}", action_name(action))))?;
        let planned = planned_duration(action);
        total = total.saturating_add(match action {
            Action::Wait { ms } => Duration::from_millis(*ms),
            _ => planned,
        });
        if total > Duration::from_millis(MAX_BATCH_MS) {
            return Err(ApiError::BadRequest(format!(
                "the batch would take more than {} s by its waits and pauses (reached at action {index}); \
                 send it in parts",
                MAX_BATCH_MS / 1000
            )));
        }
        if planned >= call_deadline {
            return Err(ApiError::BadRequest(format!(
                "action {index} ({}) would take {:.1} s by its own pauses, past the call deadline of {:.1} s \
                 (--call-timeout-ms); split the text or shorten the interval",
                action_name(action),
                planned.as_secs_f64(),
                call_deadline.as_secs_f64()
            )));
        }
    }
    Ok(())
}

fn check_action(action: &Action) -> Result<(), String> {
    let key = |name: &str| Key::parse(name).map(drop).map_err(|err| err.to_string());
    let button = |b: &MouseButton| match b {
        MouseButton::Unknown => Err("unknown mouse button (expected left, right or middle)".to_owned()),
        _ => Ok(()),
    };
    let repeat = |what: &str, n: u32| match n {
        0 => Err(format!("{what} must be at least 1")),
        n if n > MAX_REPEAT => Err(format!("{what} must be at most {MAX_REPEAT} (got {n})")),
        _ => Ok(()),
    };
    let coords = |x: &Option<i32>, y: &Option<i32>| {
        if x.is_some() == y.is_some() {
            Ok(())
        } else {
            Err("give both x and y, or neither".to_owned())
        }
    };
    match action {
        Action::Unknown => Err("unknown action type".to_owned()),
        Action::KeyPress { key: name, presses } => {
            key(name)?;
            repeat("presses", *presses)
        }
        Action::KeyDown { key: name } | Action::KeyUp { key: name } => key(name),
        Action::Hotkey { keys } if keys.is_empty() => Err("a hotkey needs at least one key".to_owned()),
        Action::Hotkey { keys } if keys.len() > MAX_CHORD_KEYS => {
            Err(format!("a hotkey presses at most {MAX_CHORD_KEYS} keys together (got {})", keys.len()))
        }
        Action::Hotkey { keys } => keys.iter().try_for_each(|name| key(name)),
        Action::Click { x, y, button: b, count } => {
            coords(x, y)?;
            button(b)?;
            repeat("count", *count)
        }
        Action::MouseDown { button: b, x, y } | Action::MouseUp { button: b, x, y } => {
            coords(x, y)?;
            button(b)
        }
        Action::Drag { duration_ms: Some(ms), .. } if *ms > MAX_WAIT_MS => {
            Err(format!("a drag lasts at most {MAX_WAIT_MS} ms (got {ms})"))
        }
        Action::Drag { button: b, .. } => button(b),
        Action::Scroll { x, y, .. } | Action::DoubleClick { x, y } | Action::RightClick { x, y } => coords(x, y),
        Action::Wait { ms } if *ms > MAX_WAIT_MS => Err(format!("a wait lasts at most {MAX_WAIT_MS} ms (got {ms})")),
        Action::TypeText { text, .. } => arena_shared::action::check_typed_length(text),
        Action::Wait { .. } | Action::MoveTo { .. } | Action::MoveRel { .. } => Ok(()),
    }
}

/// The wire name of an action's type, for messages.
fn action_name(action: &Action) -> &'static str {
    match action {
        Action::MoveTo { .. } => "move_to",
        Action::MoveRel { .. } => "move_rel",
        Action::Click { .. } => "click",
        Action::DoubleClick { .. } => "double_click",
        Action::RightClick { .. } => "right_click",
        Action::MouseDown { .. } => "mouse_down",
        Action::MouseUp { .. } => "mouse_up",
        Action::Drag { .. } => "drag",
        Action::Scroll { .. } => "scroll",
        Action::KeyPress { .. } => "key_press",
        Action::Hotkey { .. } => "hotkey",
        Action::KeyDown { .. } => "key_down",
        Action::KeyUp { .. } => "key_up",
        Action::TypeText { .. } => "type_text",
        Action::Wait { .. } => "wait",
        Action::Unknown => "unknown",
    }
}

/// The error of a batch stopped by action `index`: the backend error's status and
/// code, with a message that says which action failed and how many ran.
///
/// The status comes from [`ApiError`]'s own mapping; only the message is rewritten,
/// because a timeout's message is fixed by [`crate::desktop::DesktopError`].
fn batch_failed(err: ApiError, index: usize, name: &str, total: usize) -> Response {
    let message = format!("action {index} ({name}) failed after {index} of {total} actions ran: {err}");
    tracing::warn!(index, total, error = %err, "action batch stopped");
    let status = err.into_response().status();
    let code = match status {
        StatusCode::BAD_REQUEST | StatusCode::FORBIDDEN => ErrorCode::BadRequest,
        StatusCode::NOT_FOUND => ErrorCode::NotFound,
        StatusCode::CONFLICT => ErrorCode::Conflict,
        StatusCode::NOT_IMPLEMENTED => ErrorCode::Unsupported,
        StatusCode::GATEWAY_TIMEOUT => ErrorCode::Timeout,
        _ => ErrorCode::Internal,
    };
    (status, Json(ErrorBody { error: code, message })).into_response()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(action: Action, expected: Result<(), &str>) {
        let got = check_action(&action);
        match expected {
            Ok(()) => assert_eq!(got, Ok(()), "{action:?}"),
            Err(needle) => {
                let msg = got.expect_err("expected a rejection");
                assert!(msg.contains(needle), "{action:?}: {msg:?} lacks {needle:?}");
            }
        }
    }

    #[test]
    fn actions_are_checked_before_running() {
        check(Action::KeyPress { key: "enter".into(), presses: 1 }, Ok(()));
        check(Action::KeyPress { key: "entr".into(), presses: 1 }, Err("entr"));
        check(Action::KeyPress { key: "a".into(), presses: 0 }, Err("presses"));
        check(Action::KeyDown { key: "shift".into() }, Ok(()));
        check(Action::KeyUp { key: "hyper".into() }, Err("hyper"));
        check(Action::Hotkey { keys: vec!["ctrl".into(), "c".into()] }, Ok(()));
        check(Action::Hotkey { keys: vec!["ctrl".into(), "nokey".into()] }, Err("nokey"));
        check(Action::Hotkey { keys: vec![] }, Err("at least one key"));
        check(Action::Hotkey { keys: vec!["a".into(); 200_000] }, Err("at most 64 keys"));
        check(Action::Wait { ms: 60_000 }, Ok(()));
        check(Action::Wait { ms: 60_001 }, Err("at most"));
        check(Action::Unknown, Err("unknown action"));
        check(Action::Click { x: None, y: None, button: MouseButton::Unknown, count: 1 }, Err("mouse button"));
        check(Action::Click { x: Some(1), y: Some(2), button: MouseButton::Right, count: 2 }, Ok(()));
        check(Action::DoubleClick { x: Some(1), y: None }, Err("both x and y"));
        check(Action::MouseUp { button: MouseButton::Left, x: None, y: Some(1) }, Err("both x and y"));
        check(Action::Scroll { x: None, y: None, dx: 0, dy: -120 }, Ok(()));
    }

    #[test]
    fn a_batch_over_the_limit_is_refused() {
        let deadline = Duration::from_secs(30);
        let batch = vec![Action::Wait { ms: 0 }; MAX_ACTIONS + 1];
        assert!(matches!(validate(&batch, deadline), Err(ApiError::BadRequest(m)) if m.contains("at most")));
        assert!(validate(&batch[..MAX_ACTIONS], deadline).is_ok());
    }

    #[test]
    fn texts_and_batch_durations_have_caps() {
        let deadline = Duration::from_secs(30);
        let max = arena_shared::action::MAX_TYPE_TEXT_BYTES;
        let typing = |n: usize| vec![Action::TypeText { text: "x".repeat(n), interval_ms: None }];
        assert!(validate(&typing(max), deadline).is_ok());
        let err = validate(&typing(max + 1), deadline).expect_err("over the text cap");
        assert!(err.to_string().contains("at most 1048576"), "{err}");
        // 1000 one-minute waits (16.7 h) are refused before anything runs; five are not.
        let waits = |n: usize| vec![Action::Wait { ms: 60_000 }; n];
        assert!(validate(&waits(5), deadline).is_ok());
        let err = validate(&waits(1000), deadline).expect_err("over the batch duration");
        assert!(err.to_string().contains("300 s") && err.to_string().contains("action 5"), "{err}");
    }

    #[test]
    fn typing_planned_past_the_call_deadline_is_refused_up_front() {
        let deadline = Duration::from_secs(30);
        let typing = |text: &str, ms: u64| vec![Action::TypeText { text: text.into(), interval_ms: Some(ms) }];
        // 20 characters 2 s apart: 38 s of pauses.
        let err = validate(&typing("abcdefghijklmnopqrst", 2000), deadline).expect_err("too slow");
        let ApiError::BadRequest(message) = err else { panic!("{err:?}") };
        assert!(
            message.contains("38.0 s") && message.contains("30.0 s") && message.contains("call-timeout"),
            "{message}"
        );
        assert!(validate(&typing("abcde", 2000), deadline).is_ok(), "8 s fits");
        assert!(validate(&typing(&"x".repeat(100_000), 0), deadline).is_ok(), "no pauses, no time limit");
        assert_eq!(planned_duration(&typing("ab", u64::MAX)[0]), Duration::from_millis(MAX_TYPING_PAUSE_MS));
    }
}
