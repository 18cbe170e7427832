//! `arena doctor --input` as a user runs it: the `arena` binary against an embedded
//! stub guest, its JSON read back from stdout and counted against the built-in
//! catalogue; a narrowed run; and bad arguments refused with a clear message.

use std::collections::BTreeMap;
use std::process::Output;

use arena_actionspace::ActionSpace;
use arena_host::driver::stub::{start, StubArgs};
use arena_inputcheck::Catalogue;

/// Runs `arena ARGS` to its end off the runtime's threads, so the stub keeps serving.
async fn arena(args: Vec<String>) -> Output {
    tokio::task::spawn_blocking(move || {
        std::process::Command::new(env!("CARGO_BIN_EXE_arena"))
            .args(&args)
            .env_remove("ARENA_TOKEN")
            .env_remove("ARENA_TOKEN_FILE")
            .env_remove("ARENA_GUEST")
            .output()
            .expect("arena starts")
    })
    .await
    .expect("the child's thread")
}

fn words(list: &[&str]) -> Vec<String> {
    list.iter().map(|w| (*w).to_owned()).collect()
}

fn json_of(output: &Output) -> serde_json::Value {
    serde_json::from_slice(&output.stdout).unwrap_or_else(|err| {
        panic!(
            "stdout is not JSON ({err}):\n{}\nstderr:\n{}",
            String::from_utf8_lossy(&output.stdout),
            String::from_utf8_lossy(&output.stderr)
        )
    })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn doctor_input_passes_the_whole_catalogue_on_the_stub() {
    let stub = start(&StubArgs::default(), None).await.expect("stub");
    let url = stub.url();
    let output = arena(words(&["--guest", &url, "doctor", "--input", "--json"])).await;
    let report = json_of(&output);
    assert!(output.status.success(), "{report:#}\nstderr:\n{}", String::from_utf8_lossy(&output.stderr));

    // Every case once per space that expresses it, every one passed.
    let catalogue = Catalogue::builtin().expect("the built-in catalogue");
    let mut want: BTreeMap<&str, u64> = BTreeMap::new();
    for case in &catalogue.cases {
        for (space, _) in &case.inputs {
            *want.entry(space.name()).or_default() += 1;
        }
    }
    let runs: u64 = want.values().sum();
    assert!(runs >= 500 && catalogue.cases.len() >= 60, "{runs} runs of {} cases", catalogue.cases.len());
    assert_eq!(report["cases"], runs, "{report:#}");
    assert_eq!(report["passed"], runs, "{report:#}");
    assert_eq!(report["mismatches"], serde_json::json!([]));
    let by_space = report["by_space"].as_object().expect("by_space is an object");
    assert_eq!(by_space.len(), ActionSpace::ALL.len(), "{report:#}");
    for (space, count) in want {
        assert_eq!(by_space[space]["cases"], count, "{space}");
        assert_eq!(by_space[space]["passed"], count, "{space}");
    }
    stub.stop().await.expect("stub stops");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn doctor_input_narrows_to_spaces_and_cases_and_refuses_unknown_ones() {
    let stub = start(&StubArgs::default(), None).await.expect("stub");
    let url = stub.url();

    let narrow = ["--guest", &url, "doctor", "--input", "--space", "typed", "--space", "uitars"];
    let output =
        arena(words(&[&narrow[..], &["--case", "press_a", "--case", "scroll_down_3", "--json"]].concat())).await;
    let report = json_of(&output);
    assert!(output.status.success(), "{report:#}");
    // press_a is in both spaces, scroll_down_3 in typed only.
    assert_eq!((report["cases"].as_u64(), report["passed"].as_u64()), (Some(3), Some(3)), "{report:#}");
    assert_eq!(report["by_space"]["typed"]["cases"], 2);
    assert_eq!(report["by_space"]["uitars"]["cases"], 1);

    // The table, without --json.
    let output = arena(words(&["--guest", &url, "doctor", "--input", "--space", "typed", "--case", "press_a"])).await;
    let table = String::from_utf8_lossy(&output.stdout);
    assert!(output.status.success(), "{table}");
    assert!(table.lines().any(|l| l.split_whitespace().eq(["typed", "1", "1"])), "{table}");

    for (args, says) in [
        (&["--case", "no_such_case"][..], "no case is named \"no_such_case\""),
        (&["--space", "telepathy"][..], "unknown action space \"telepathy\""),
        (&["--deep"][..], "cannot be used with"),
    ] {
        let output = arena(words(&[&["--guest", &url, "doctor", "--input"][..], args].concat())).await;
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(!output.status.success(), "{args:?} passed");
        assert!(stderr.contains(says), "{args:?}: {stderr}");
        assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
    }
    // --case without --input is refused too.
    let output = arena(words(&["--guest", &url, "doctor", "--case", "press_a"])).await;
    assert!(!output.status.success());
    stub.stop().await.expect("stub stops");
}
