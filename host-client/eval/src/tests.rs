//! Tests of the evaluation framework: the infeasible rule, FAIL on feasible
//! tasks, `and`/`or` with early stops, mean and max, failures recorded as 0,
//! and what the upstream corpus needs from this build.

use std::collections::BTreeSet;
use std::path::Path;
use std::time::Duration;

use serde_json::{json, Value};

use super::*;
use arena_client::client::ClientConfig;
use arena_task::{load_dir, Task};

/// A context whose guest does not exist: enough for `rule` getters, and a
/// connection error for anything that calls the guest.
fn offline_ctx(dir: &Path) -> EvalContext {
    let config = ClientConfig { token: None, timeout: Duration::from_secs(2), retries: 0 };
    let client = GuestClient::new("http://127.0.0.1:9", config).expect("client");
    let cache = DownloadCache::new(dir.join("cache")).expect("cache");
    EvalContext { client, cache, work_dir: dir.join("work"), task_dir: None }
}

fn evaluator(value: Value) -> Evaluator {
    let text = json!({"id": "t", "instruction": "do it", "evaluator": value}).to_string();
    Task::parse(&text, Path::new("tasks/test/t.json")).expect("valid task").evaluator
}

/// An `exact_match` metric scoring 1 (`pass`) or 0, from `rule` getters only.
fn rule_metric(pass: bool) -> (Value, Value, Value) {
    (json!("exact_match"), json!({"type": "rule", "rules": pass}), json!({"type": "rule", "rules": {"expected": true}}))
}

/// An evaluator of several metrics: `Some(pass)` is a rule metric, `None` one whose getter is not implemented.
fn listed(conj: &str, metrics: &[Option<bool>]) -> Evaluator {
    let (mut funcs, mut results, mut expecteds) = (vec![], vec![], vec![]);
    for metric in metrics {
        let (f, r, e) = match metric {
            Some(pass) => rule_metric(*pass),
            None => (
                json!("exact_match"),
                json!({"type": "vm_screen_size", "dest": "vlcrc"}),
                json!({"type": "rule", "rules": {"expected": 1}}),
            ),
        };
        funcs.push(f);
        results.push(r);
        expecteds.push(e);
    }
    evaluator(json!({"func": funcs, "conj": conj, "result": results, "expected": expecteds}))
}

#[tokio::test]
async fn conjunctions_stop_early_and_combine() {
    let dir = tempfile::tempdir().unwrap();
    let ctx = offline_ctx(dir.path());
    // (conj, metrics, score, how many ran, unfinished). A metric whose getter this
    // build lacks leaves the task unfinished where it is reached.
    type Case<'a> = (&'a str, &'a [Option<bool>], f64, usize, bool);
    let cases: &[Case] = &[
        ("and", &[Some(true), Some(true)], 1.0, 2, false),
        ("and", &[Some(true), Some(false), Some(true)], 0.0, 2, false),
        ("and", &[Some(false), None], 0.0, 1, false),
        ("and", &[Some(true), None, Some(true)], 0.0, 2, true),
        ("or", &[Some(false), Some(true), None], 1.0, 2, false),
        ("or", &[Some(false), Some(false)], 0.0, 2, false),
        ("or", &[None, Some(false), Some(true)], 0.0, 1, true),
        ("or", &[Some(true), Some(false)], 1.0, 1, false),
    ];
    for (conj, metrics, score, ran, unfinished) in cases {
        let outcome = evaluate(&ctx, &listed(conj, metrics), Some(&LastAction::Done)).await;
        assert_eq!(outcome.score, *score, "{conj} {metrics:?}: {outcome:?}");
        assert_eq!(outcome.metrics.len(), *ran, "{conj} {metrics:?}: {outcome:?}");
        assert_eq!(outcome.unfinished.is_some(), *unfinished, "{conj} {metrics:?}: {outcome:?}");
        // An early stop is upstream's `return 0` / `return 1`: an int; a mean or max is a float.
        let early = !unfinished && *ran < metrics.len();
        assert_eq!(outcome.score_is_int, early, "{conj} {metrics:?}: {outcome:?}");
    }
}

#[test]
fn and_is_the_mean_and_or_the_max() {
    let check = |conj, scores: &[f64], want: f64| {
        assert_eq!(combine(conj, scores.iter().copied()), want, "{conj:?} {scores:?}")
    };
    check(Conj::And, &[1.0, 0.5], 0.75);
    check(Conj::And, &[0.25, 0.25, 1.0], 0.5);
    check(Conj::Or, &[0.25, 0.75, 0.5], 0.75);
    check(Conj::Or, &[], 0.0);
    check(Conj::And, &[], 0.0);
}

#[tokio::test]
async fn infeasible_scores_the_last_action() {
    let dir = tempfile::tempdir().unwrap();
    let ctx = offline_ctx(dir.path());
    let task = evaluator(json!({"func": "infeasible", "result": {}, "expected": {}}));
    for (last, want) in
        [(Some(LastAction::Fail), 1.0), (Some(LastAction::Done), 0.0), (Some(LastAction::Other), 0.0), (None, 0.0)]
    {
        let outcome = evaluate(&ctx, &task, last.as_ref()).await;
        assert_eq!(outcome.score, want, "{last:?}");
        assert_eq!(outcome.metrics.len(), 1);
        assert_eq!(outcome.metrics[0].metric, "infeasible");
        assert_eq!(outcome.error, None);
    }
}

#[tokio::test]
async fn fail_on_a_feasible_task_scores_zero_without_fetching() {
    let dir = tempfile::tempdir().unwrap();
    let ctx = offline_ctx(dir.path());
    let (f, r, e) = rule_metric(true);
    let task = evaluator(json!({"func": f, "result": r, "expected": e}));
    let done = evaluate(&ctx, &task, Some(&LastAction::Done)).await;
    assert_eq!(done.score, 1.0, "{done:?}");
    assert_eq!(done.metrics[0].result, Some(json!(true)));
    assert_eq!(done.metrics[0].expected, Some(json!({"expected": true})));
    let failed = evaluate(&ctx, &task, Some(&LastAction::Fail)).await;
    assert_eq!(failed.score, 0.0);
    assert!(failed.metrics.is_empty());
    assert!(failed.note.as_deref().is_some_and(|n| n.contains("FAIL")), "{failed:?}");
}

#[tokio::test]
async fn failures_not_the_agents_leave_the_task_unfinished_naming_their_cause() {
    let dir = tempfile::tempdir().unwrap();
    let ctx = offline_ctx(dir.path());
    let expected = json!({"type": "rule", "rules": {"expected": true}});
    // (result getter, reason, fault): a getter this build lacks and a guest out of
    // reach are the harness's; a getter's bad parameters are the task's. None is
    // the agent's, so none is scored: upstream's one-metric path would return 0.
    let cases = [
        (
            json!({"type": "vm_screen_size", "dest": "vlcrc"}),
            "getter vm_screen_size is not implemented in this build",
            Fault::Harness,
        ),
        (json!({"type": "vm_file", "path": r"C:\a.txt", "dest": "../a.txt"}), "relative file name", Fault::Task),
        // Nothing listens on port 9: the reason names the guest and the call.
        (json!({"type": "vm_file_exists_in_desktop", "file_name": "a.lnk"}), "http://127.0.0.1:9", Fault::Harness),
    ];
    for (result, reason, fault) in cases {
        let task = evaluator(json!({"func": "exact_match", "result": result, "expected": expected}));
        let outcome = evaluate(&ctx, &task, Some(&LastAction::Done)).await;
        assert_eq!(outcome.score, 0.0);
        let error = outcome.metrics[0].error.as_deref().unwrap_or_default();
        assert!(error.contains(reason), "{error:?} lacks {reason:?}");
        assert!(
            outcome.error.as_deref().is_some_and(|e| e.starts_with("exact_match: ") && e.contains(reason)),
            "{outcome:?}"
        );
        assert_eq!(outcome.metrics[0].result, None);
        assert_eq!(outcome.metrics[0].fault, Some(fault), "{outcome:?}");
        let unfinished = outcome.unfinished.as_deref().unwrap_or_default();
        assert!(unfinished.starts_with("exact_match (") && unfinished.contains(reason), "{outcome:?}");
        assert!(unfinished.contains(fault.words()), "{unfinished}");
    }
    // The same in the list path.
    let task = evaluator(json!({
        "func": ["exact_match"],
        "result": [{"type": "vm_file_exists_in_desktop", "file_name": "a.lnk"}],
        "expected": [expected],
    }));
    let outcome = evaluate(&ctx, &task, Some(&LastAction::Done)).await;
    assert!(outcome.unfinished.as_deref().is_some_and(|u| u.contains("127.0.0.1:9")), "{outcome:?}");
    assert_eq!(outcome.metrics[0].failed_at, Some(FailedAt::Result));
    // An expected getter that fails is the task's on both paths.
    let task = evaluator(json!({
        "func": "exact_match",
        "result": {"type": "rule", "rules": true},
        "expected": {"type": "vm_file", "path": r"C:\a.txt", "dest": "../a.txt"},
    }));
    let outcome = evaluate(&ctx, &task, Some(&LastAction::Done)).await;
    assert!(outcome.unfinished.as_deref().is_some_and(|u| u.contains("relative file name")), "{outcome:?}");
    assert_eq!(outcome.metrics[0].failed_at, Some(FailedAt::Expected));
    assert_eq!(outcome.metrics[0].fault, Some(Fault::Task));
    // A metric whose rules are broken (here: without `expected`) is the task's too.
    let task = evaluator(
        json!({"func": "exact_match", "result": {"type": "rule", "rules": 1}, "expected": {"type": "rule", "rules": {"no": 1}}}),
    );
    let outcome = evaluate(&ctx, &task, Some(&LastAction::Done)).await;
    assert_eq!(outcome.score, 0.0);
    assert_eq!(outcome.metrics[0].error.as_deref(), Some("the rules have no `expected`"));
    assert_eq!(outcome.metrics[0].failed_at, Some(FailedAt::Metric));
    assert_eq!(outcome.metrics[0].fault, Some(Fault::Task));
    assert!(outcome.unfinished.is_some(), "{outcome:?}");
}

#[tokio::test]
async fn a_malformed_result_scores_zero_for_the_agent_and_the_next_metric_still_runs() {
    let dir = tempfile::tempdir().unwrap();
    let ctx = offline_ctx(dir.path());
    // `check_direct_json_object` parses its result as JSON: text that is not JSON is the agent's.
    let malformed = json!({"type": "rule", "rules": "{not json"});
    let rules = json!({"type": "rule", "rules": {"expected": {"a": 1}}});
    let one = evaluator(json!({"func": "check_direct_json_object", "result": malformed, "expected": rules}));
    let outcome = evaluate(&ctx, &one, Some(&LastAction::Done)).await;
    assert_eq!((outcome.score, outcome.unfinished.clone()), (0.0, None), "{outcome:?}");
    assert_eq!(outcome.metrics[0].fault, Some(Fault::Agent));
    assert_eq!(outcome.metrics[0].failed_at, Some(FailedAt::Metric));
    assert!(outcome.error.is_some(), "the reason is kept: {outcome:?}");
    // In an `or`, the malformed metric is a 0 and the next one decides.
    let (f, r, e) = rule_metric(true);
    let listed = evaluator(json!({
        "func": ["check_direct_json_object", f], "conj": "or",
        "result": [malformed, r], "expected": [rules, e],
    }));
    let outcome = evaluate(&ctx, &listed, Some(&LastAction::Done)).await;
    assert_eq!((outcome.score, outcome.metrics.len(), outcome.unfinished.clone()), (1.0, 2, None), "{outcome:?}");
}

#[test]
fn the_judge_tells_the_results_files_from_the_tasks() {
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, text: &str| {
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        Fetched::File(path)
    };
    let (good, bad) = (write("good.txt", "same\n"), write("bad.txt", ""));
    std::fs::write(dir.path().join("bad.txt"), [0xff, 0xfe, 0x00]).unwrap();
    let input = |result: &Fetched, expected: &Fetched| MetricInput {
        result: result.clone(),
        expected: Some(expected.clone()),
        options: serde_json::Map::new(),
        last_action: Some(LastAction::Done),
    };
    // Not UTF-8 on the result's side: the agent's 0; on the expected side: the task's.
    let agents = judge("compare_text_file", &input(&bad, &good));
    assert_eq!((agents.score, agents.fault), (0.0, Some(Fault::Agent)), "{agents:?}");
    let tasks = judge("compare_text_file", &input(&good, &bad));
    assert_eq!((tasks.score, tasks.fault), (0.0, Some(Fault::Task)), "{tasks:?}");
    let passes = judge("compare_text_file", &input(&good, &good));
    assert_eq!(passes, Judged { score: 1.0, error: None, fault: None });
    let missing = judge("no_such_metric", &input(&good, &good));
    assert_eq!(missing.fault, Some(Fault::Harness));
}

#[test]
fn a_getters_failure_is_the_harnesss_when_the_guest_failed_and_the_agents_when_it_answered() {
    use arena_client::error::{CallSite, ClientError};
    use arena_shared::error::ErrorCode;
    let api = |status: u16, code: ErrorCode| GetterError::Guest {
        getter: "open_tabs_info",
        source: Box::new(ClientError::Api {
            call: CallSite { guest: "http://g".into(), method: "GET", path: "/v1/browser/json/list".into() },
            status,
            code,
            message: "m".into(),
        }),
    };
    let cases = [
        // No browser on the debugging port: the guest's 502.
        (api(502, ErrorCode::Internal), Fault::Harness),
        (api(500, ErrorCode::Internal), Fault::Harness),
        // The guest answered that it has no such thing, or refused it.
        (api(404, ErrorCode::NotFound), Fault::Agent),
        (api(403, ErrorCode::Forbidden), Fault::Agent),
        (GetterError::Failed { getter: "bookmarks", message: "not JSON".into() }, Fault::Agent),
        (GetterError::BadParams { getter: "vm_file", message: "no path".into() }, Fault::Task),
        (GetterError::Download { getter: "cloud_file", message: "503".into() }, Fault::Harness),
        (GetterError::NotImplemented("x".into()), Fault::Harness),
    ];
    for (err, fault) in cases {
        assert_eq!(getter_failure(&err, FailedAt::Result).1, fault, "{err}");
        // The expected side is never the agent's.
        let (_, on_expected) = getter_failure(&err, FailedAt::Expected);
        assert_eq!(on_expected, if fault == Fault::Agent { Fault::Task } else { fault }, "{err}");
    }
    assert_eq!(getter_failure(&GetterError::NotImplemented("x".into()), FailedAt::Result).0, FailedAt::Missing);
}

#[test]
fn last_actions_are_written_as_the_decision_words() {
    assert_eq!(serde_json::to_value(LastAction::Fail).unwrap(), json!("FAIL"));
    assert_eq!(serde_json::to_value(LastAction::Other).unwrap(), json!("OTHER"));
}

#[test]
fn supported_names_come_from_the_registries() {
    assert!(getter_supported("vm_file") && getter_supported("rule") && getter_supported("cloud_file"));
    assert!(!getter_supported("vm_screen_size") && !getter_supported("nonsense"));
    assert!(metric_supported("exact_match") && metric_supported("infeasible"));
    assert!(metric_supported("compare_table") && !metric_supported("no_such_metric"));
    let text = json!({
        "id": "t", "instruction": "i",
        "evaluator": {"func": ["compare_table", "exact_match"], "result": [{"type": "vm_screen_size", "dest": "a"}, {"type": "rule", "rules": 1}],
                      "expected": [{"type": "cloud_file", "path": "http://x/a", "dest": "b"}, {"type": "rule", "rules": {"expected": 1}}]}
    })
    .to_string();
    let task = Task::parse(&text, Path::new("x/t.json")).unwrap();
    assert_eq!(unsupported_names(&task), ["vm_screen_size"]);
}

/// What the upstream corpus names and how much of it this build implements: everything.
#[test]
fn corpus_coverage() {
    let Some(dir) = arena_test_support::waa_corpus("eval::corpus_coverage") else { return };
    let (tasks, errors) = load_dir(&dir);
    assert!(errors.is_empty(), "corpus files fail to load: {errors:?}");
    assert!(tasks.len() > 100, "found only {} tasks under {}", tasks.len(), dir.display());
    let (mut getters, mut metrics) = (BTreeSet::new(), BTreeSet::new());
    for task in &tasks {
        let needs = task.needs();
        getters.extend(needs.getters);
        metrics.extend(needs.metrics);
    }
    let have_getters = getters.iter().filter(|g| getter_supported(g)).count();
    let have_metrics = metrics.iter().filter(|m| metric_supported(m)).count();
    println!(
        "implemented: {have_getters} getters of {}, {have_metrics} metrics of {} used by the corpus",
        getters.len(),
        metrics.len()
    );
    let missing: Vec<&String> = getters
        .iter()
        .filter(|g| !getter_supported(g))
        .chain(metrics.iter().filter(|m| !metric_supported(m)))
        .collect();
    println!("unimplemented ({}): {missing:?}", missing.len());
    // The upstream counts (58 result + 6 expected getters overlap in `vm_file`; 45 metrics).
    assert_eq!(metrics.len(), 45, "{metrics:?}");
    assert!(missing.is_empty(), "getters or metrics the corpus uses are not implemented: {missing:?}");
}
