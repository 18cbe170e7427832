//! The whole catalogue, in every action space, against the stub guest's model of the
//! input recorder: every case passes. Steps are carried out here by the plainest
//! runner (typed actions as one batch, clipboard writes as a clipboard write); the
//! host's own executor runs the same check through `arena doctor --input`
//! (`host-client/tests/doctor_input.rs`), and here with two mappings broken on purpose.

use std::time::Duration;

use arena_actionspace::{ActionSpace, Step};
use arena_client::{ClientConfig, GuestClient};
use arena_exec::ExecOptions;
use arena_inputcheck::catalogue::{context, translate};
use arena_inputcheck::{resolve, run_check, Catalogue, CheckOptions, Executor, GuestCheck, StepRunner, STUB_RECORDER};
use arena_shared::action::{Action, ActionBatch};
use arena_shared::clipboard::ClipboardContent;
use arena_test_support::StubGuest;

struct Plain<'a>(&'a GuestClient);

#[async_trait::async_trait]
impl StepRunner for Plain<'_> {
    async fn run(&self, steps: &[Step]) -> Result<(), String> {
        let mut actions = Vec::new();
        for step in steps {
            match step {
                Step::Act(action) => actions.push(action.clone()),
                Step::SetClipboard(text) => {
                    if !actions.is_empty() {
                        let batch = ActionBatch { actions: std::mem::take(&mut actions) };
                        self.0.act(&batch).await.map_err(|e| e.to_string())?;
                    }
                    let content = ClipboardContent::Text { text: text.clone() };
                    self.0.clipboard_set(&content).await.map_err(|e| e.to_string())?;
                }
                _ => {}
            }
        }
        if !actions.is_empty() {
            self.0.act(&ActionBatch { actions }).await.map_err(|e| e.to_string())?;
        }
        Ok(())
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_case_passes_on_the_stubs_recorder() {
    let guest = StubGuest::start().await;
    let client =
        GuestClient::new(guest.url(), ClientConfig { token: None, timeout: Duration::from_secs(30), retries: 1 })
            .expect("url");
    let catalogue = Catalogue::builtin().expect("the built-in catalogue");
    let options = CheckOptions {
        recorder: STUB_RECORDER.into(),
        log: r"C:\Users\Docker\arena-input-log.jsonl".into(),
        spaces: ActionSpace::ALL.to_vec(),
        only: Vec::new(),
        wait: Duration::from_secs(20),
    };
    let report = run_check(&client, &Plain(&client), &catalogue, &options).await.expect("the check runs");
    assert!(report.all_passed(), "{}", report.render_table());
    let runs: usize = catalogue.cases.iter().map(|c| c.inputs.len()).sum();
    assert_eq!(report.cases, runs);
}

/// The host's executor with one mapping broken on purpose before the guest sees it: a
/// wheel delta taken for notches (divided by 120), and a hotkey that lets its keys go
/// in the order it pressed them instead of in reverse.
struct Broken<'a>(Executor<'a>);

fn broken(step: &Step) -> Vec<Step> {
    match step {
        Step::Act(Action::Scroll { x, y, dx, dy }) => {
            vec![Step::Act(Action::Scroll { x: *x, y: *y, dx: dx / 120, dy: dy / 120 })]
        }
        Step::Act(Action::Hotkey { keys }) => {
            let downs = keys.iter().map(|key| Step::Act(Action::KeyDown { key: key.clone() }));
            downs.chain(keys.iter().map(|key| Step::Act(Action::KeyUp { key: key.clone() }))).collect()
        }
        other => vec![other.clone()],
    }
}

fn is_broken(step: &Step) -> bool {
    matches!(step, Step::Act(Action::Scroll { .. } | Action::Hotkey { .. }))
}

#[async_trait::async_trait]
impl StepRunner for Broken<'_> {
    async fn run(&self, steps: &[Step]) -> Result<(), String> {
        let steps: Vec<Step> = steps.iter().flat_map(broken).collect();
        self.0.run(&steps).await
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_mapping_broken_on_purpose_fails_its_cases_and_only_them() {
    let guest = StubGuest::start().await;
    let client =
        GuestClient::new(guest.url(), ClientConfig { token: None, timeout: Duration::from_secs(30), retries: 1 })
            .expect("url");
    let catalogue = Catalogue::builtin().expect("the built-in catalogue");
    let only: Vec<String> = ["scroll_down_3", "hscroll_left", "ctrl_shift_esc", "ctrl_c", "press_a", "click_left"]
        .map(String::from)
        .to_vec();
    let check = GuestCheck { only: only.clone(), wait: Duration::from_secs(20), ..GuestCheck::default() };
    let options = resolve(&client, &check).await.expect("the stub's defaults");
    assert_eq!(options.recorder, STUB_RECORDER);
    assert_eq!(options.spaces, ActionSpace::ALL.to_vec());

    // Sound, the host's executor delivers every one of them.
    let sound = Executor { client: &client, options: ExecOptions::default() };
    let report = run_check(&client, &sound, &catalogue, &options).await.expect("the check runs");
    assert!(report.all_passed(), "{}", report.render_table());

    // Broken, exactly the runs whose steps hold a wheel or a hotkey fail.
    let ctx = context((1440, 900));
    let mut affected = Vec::new();
    for case in catalogue.cases.iter().filter(|c| only.contains(&c.name)) {
        for (space, input) in &case.inputs {
            let steps = translate(*space, input, &ctx).expect("the case translates");
            if steps.iter().any(is_broken) {
                affected.push((case.name.clone(), space.name().to_owned()));
            }
        }
    }
    let broken = Broken(Executor { client: &client, options: ExecOptions::default() });
    let report = run_check(&client, &broken, &catalogue, &options).await.expect("the check runs");
    let mut failed: Vec<(String, String)> =
        report.mismatches.iter().map(|m| (m.case.clone(), m.space.clone())).collect();
    failed.sort();
    affected.sort();
    assert_eq!(failed, affected, "{}", report.render_table());
    for name in ["scroll_down_3", "hscroll_left", "ctrl_shift_esc", "ctrl_c"] {
        assert!(failed.iter().any(|(case, space)| case == name && space == "typed"), "{name}: {failed:?}");
    }
    assert_eq!(report.passed + failed.len(), report.cases);

    // Each says where expected and received parted.
    let wheel = report.mismatches.iter().find(|m| m.case == "scroll_down_3" && m.space == "typed").expect("wheel");
    let difference = wheel.difference.as_ref().expect("the case ran");
    assert_eq!(
        (difference.expected.as_str(), difference.received.as_str()),
        ("wheel -360 400,300", "wheel -3 400,300")
    );
    let chord = report.mismatches.iter().find(|m| m.case == "ctrl_shift_esc" && m.space == "typed").expect("chord");
    let difference = chord.difference.as_ref().expect("the case ran");
    // Esc is let go of first, with both modifiers still down; broken, Ctrl goes first.
    assert!(difference.expected.starts_with("ku esc +shift+ctrl"), "{}", report.render_table());
    assert!(difference.received.starts_with("ku ctrl"), "{}", report.render_table());
    let json = serde_json::to_value(&report).expect("the report as JSON");
    assert_eq!(json["mismatches"].as_array().map(Vec::len), Some(failed.len()));
    assert_eq!(json["by_space"]["typed"]["cases"], 6);
}
