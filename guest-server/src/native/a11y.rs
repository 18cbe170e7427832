//! `GET /v1/a11y`: the accessibility tree within a budget.
//!
//! The query's limits override [`TreeBudget::WAA`] one by one. The backend
//! walk stops at the budget and says `truncated`; the request's own deadline
//! is the walk's time budget plus a margin, capped by the server's
//! accessibility timeout, so a provider that ignores the budget still costs
//! only this request.

use std::time::Duration;

use axum::extract::State;
use axum::routing::get;
use axum::Router;

use arena_shared::observation::{A11yBackend, A11yQuery, A11yTree, TreeBudget};

use crate::call::blocking;
use crate::error::{ApiError, AppJson, AppQuery};
use crate::state::AppState;

/// Deepest tree a query may ask for.
const MAX_DEPTH: u32 = 256;
/// Longest time budget a query may ask for.
const MAX_MS: u64 = 120_000;
/// Time the backend gets past the walk's own budget to stop and assemble the tree.
const DEADLINE_MARGIN: Duration = Duration::from_secs(5);

pub(crate) fn routes() -> Router<AppState> {
    Router::new().route("/v1/a11y", get(a11y))
}

async fn a11y(
    State(state): State<AppState>,
    AppQuery(query): AppQuery<A11yQuery>,
) -> Result<AppJson<A11yTree>, ApiError> {
    let budget = budget(&query)?;
    if query.backend == A11yBackend::Unknown {
        return Err(ApiError::BadRequest("backend must be uia or win32".into()));
    }
    let backend = query.backend;
    let foreground_only = query.foreground_only;
    let deadline = (Duration::from_millis(budget.max_ms) + DEADLINE_MARGIN).min(state.config.a11y_timeout());
    let tree = blocking(&state.desktop, "accessibility", deadline, move |d| {
        d.accessibility(backend, &budget, foreground_only)
    })
    .await?;
    Ok(AppJson(tree))
}

/// The walk's budget: the query's limits over upstream's defaults.
fn budget(query: &A11yQuery) -> Result<TreeBudget, ApiError> {
    let defaults = TreeBudget::WAA;
    let budget = TreeBudget {
        max_depth: query.max_depth.unwrap_or(defaults.max_depth),
        max_children: query.max_children.unwrap_or(defaults.max_children),
        max_nodes: query.max_nodes.unwrap_or(defaults.max_nodes),
        max_ms: query.max_ms.unwrap_or(defaults.max_ms),
    };
    if budget.max_depth == 0 || budget.max_depth > MAX_DEPTH {
        return Err(ApiError::BadRequest(format!(
            "max_depth must be from 1 to {MAX_DEPTH} (got {})",
            budget.max_depth
        )));
    }
    if budget.max_nodes == 0 {
        return Err(ApiError::BadRequest("max_nodes must be at least 1".into()));
    }
    if budget.max_ms == 0 || budget.max_ms > MAX_MS {
        return Err(ApiError::BadRequest(format!("max_ms must be from 1 to {MAX_MS} (got {})", budget.max_ms)));
    }
    Ok(budget)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(query: A11yQuery, expected: Result<TreeBudget, &str>) {
        match (budget(&query), expected) {
            (Ok(got), Ok(want)) => assert_eq!(got, want),
            (Err(ApiError::BadRequest(msg)), Err(needle)) => assert!(msg.contains(needle), "{msg:?} lacks {needle:?}"),
            (got, want) => panic!("{query:?}: got {got:?}, expected {want:?}"),
        }
    }

    #[test]
    fn query_limits_override_the_defaults_within_bounds() {
        check(A11yQuery::default(), Ok(TreeBudget::WAA));
        check(
            A11yQuery {
                max_depth: Some(3),
                max_children: Some(0),
                max_nodes: Some(10),
                max_ms: Some(500),
                ..A11yQuery::default()
            },
            Ok(TreeBudget { max_depth: 3, max_children: 0, max_nodes: 10, max_ms: 500 }),
        );
        check(A11yQuery { max_depth: Some(0), ..A11yQuery::default() }, Err("max_depth"));
        check(A11yQuery { max_depth: Some(257), ..A11yQuery::default() }, Err("max_depth"));
        check(A11yQuery { max_nodes: Some(0), ..A11yQuery::default() }, Err("max_nodes"));
        check(A11yQuery { max_ms: Some(0), ..A11yQuery::default() }, Err("max_ms"));
        check(A11yQuery { max_ms: Some(120_001), ..A11yQuery::default() }, Err("max_ms"));
    }
}
