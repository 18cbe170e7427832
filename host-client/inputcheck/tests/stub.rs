//! The whole catalogue, in every action space, against the stub guest's model of the
//! input recorder: every case passes. Steps are carried out here by the plainest
//! runner (typed actions as one batch, clipboard writes as a clipboard write); the
//! host's own executor runs the same check in `tests/tests/input_check.rs`.

use std::time::Duration;

use arena_actionspace::{ActionSpace, Step};
use arena_client::{ClientConfig, GuestClient};
use arena_inputcheck::{run_check, Catalogue, CheckOptions, StepRunner, STUB_RECORDER};
use arena_shared::action::ActionBatch;
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
