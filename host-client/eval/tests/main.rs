//! The grader-conformance suite of `arena-eval`: every metric of the registry
//! (`arena_eval::metrics::NAMES`) scored on fixtures read from
//! `tests/conformance/<metric>.json`, each with a positive, a negative and a
//! malformed-result case and the exact score expected (the malformed one: 0,
//! the agent's, never an evaluator failure).

mod conformance;
