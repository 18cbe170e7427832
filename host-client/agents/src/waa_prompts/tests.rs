//! The prompt reader on fake checkouts the tests write themselves: laid out as
//! upstream's files are (same paths, symbols and f-string shapes), with text of
//! their own.

use super::*;

/// Writes a fake checkout under `root`: `planner` and `agent` are the two files' sources.
fn checkout(root: &Path, planner: &str, agent: &str) {
    let client = root.join("src/win-arena-container/client");
    for (file, text) in [(PLANNER, planner), (AGENT, agent)] {
        let path = client.join(file);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(path, text).unwrap();
    }
    std::fs::create_dir_all(root.join(".git/refs/heads")).unwrap();
    std::fs::write(root.join(".git/HEAD"), "ref: refs/heads/main\n").unwrap();
    std::fs::write(root.join(".git/refs/heads/main"), "0123456789abcdef0123456789abcdef01234567\n").unwrap();
}

const PLANNER_TEXT: &str = r#"
intro = "unused"

planning_system_message_shortened_previmg = f"""\
Fake system text for a test.
It spans lines, with a brace {{kept}}."""

def build_user_msg_visual(query, window_title, window_names_str, clipboard_content, text_rendering, candidates, prev_actions, textual_memory):
    msg = f"""Goal: {query}
Front: {window_title}
All:
{window_names_str}
Clip: {"nothing copied" if clipboard_content==None else clipboard_content}
Marks:
{candidates}
Past:
{"nothing yet" if len(prev_actions)==0 else prev_actions}
Notes:
{textual_memory}
"""
    return msg
"#;

const AGENT_TEXT: &str = r#"
def prev_actions_to_string(prev_actions, n_prev=3):
    result = ""
    n_prev = min(n_prev, len(prev_actions))
    for i in range(1, n_prev + 1):
        action = prev_actions[-i]
        result += f"Back {i}:\n{action}\n\n"
    return result

class NaviAgent:
    def __init__(self, server="azure"):
        self.memory_block_text_empty = """
```memory
# blank notes
```
"""
"#;

/// A fake checkout with the texts above, for other modules' tests.
pub(crate) fn fake_checkout(root: &Path) {
    checkout(root, PLANNER_TEXT, AGENT_TEXT);
}

#[test]
fn prompts_are_read_from_a_checkout_laid_out_as_upstreams() {
    let root = tempfile::tempdir().unwrap();
    checkout(root.path(), PLANNER_TEXT, AGENT_TEXT);
    let prompts = WaaPrompts::load(root.path()).expect("the fake checkout reads");
    assert_eq!(prompts.system, "Fake system text for a test.\nIt spans lines, with a brace {kept}.");
    assert_eq!(prompts.empty_memory, "\n```memory\n# blank notes\n```\n");
    assert_eq!(prompts.source, "waa@0123456789ab");

    let history = prompts.history_text(&["first()".into(), "second()".into(), "third()".into()], 2);
    assert_eq!(history, "Back 1:\nthird()\n\nBack 2:\nsecond()\n\n", "newest first, at most n");

    let mut inputs = UserInputs {
        objective: "Type hello",
        window_title: "Untitled - Notepad",
        window_names: "Untitled - Notepad\nProgram Manager",
        clipboard: None,
        text_rendering: "N/A",
        candidates: "1 | a11y | Text Editor",
        history: "",
        memory: &prompts.empty_memory,
    };
    let text = prompts.user_message(&inputs);
    assert!(
        text.starts_with("Goal: Type hello\nFront: Untitled - Notepad\nAll:\nUntitled - Notepad\nProgram Manager\n"),
        "{text}"
    );
    assert!(text.contains("Clip: nothing copied\n") && text.contains("Past:\nnothing yet\n"), "{text}");
    assert!(text.contains("Marks:\n1 | a11y | Text Editor\n") && text.contains("# blank notes"), "{text}");
    inputs.clipboard = Some("copied words");
    inputs.history = &history;
    let text = prompts.user_message(&inputs);
    assert!(text.contains("Clip: copied words\n") && text.contains("Past:\nBack 1:\nthird()"), "{text}");

    // The checkout's client folder may be given directly.
    let client = WaaPrompts::load(&root.path().join("src/win-arena-container/client")).unwrap();
    assert_eq!(client.system, prompts.system);
}

#[test]
fn a_checkout_laid_out_differently_is_refused_naming_the_file_and_symbol() {
    let root = tempfile::tempdir().unwrap();
    checkout(root.path(), &PLANNER_TEXT.replace("build_user_msg_visual", "make_message"), AGENT_TEXT);
    let err = WaaPrompts::load(root.path()).unwrap_err().to_string();
    assert!(err.contains("planner_messages.py") && err.contains("build_user_msg_visual"), "{err}");

    let odd_field = PLANNER_TEXT.replace("{query}", "{query.upper()}");
    checkout(root.path(), &odd_field, AGENT_TEXT);
    let err = WaaPrompts::load(root.path()).unwrap_err().to_string();
    assert!(err.contains("build_user_msg_visual") && err.contains("field expression"), "{err}");

    checkout(root.path(), PLANNER_TEXT, &AGENT_TEXT.replace("memory_block_text_empty", "notes"));
    let err = WaaPrompts::load(root.path()).unwrap_err().to_string();
    assert!(err.contains("agent.py") && err.contains("memory_block_text_empty"), "{err}");

    checkout(root.path(), "def broken(:\n", AGENT_TEXT);
    let err = WaaPrompts::load(root.path()).unwrap_err().to_string();
    assert!(err.contains("planner_messages.py") && err.contains("not Python"), "{err}");

    let empty = tempfile::tempdir().unwrap();
    let err = WaaPrompts::load(empty.path()).unwrap_err().to_string();
    assert!(err.contains("planner_messages.py") && err.contains("cannot read"), "{err}");
}

#[test]
fn the_users_checkout_reads_when_one_is_given() {
    let Some(root) = std::env::var_os("ARENA_WAA_ROOT") else {
        arena_test_support::skip(
            "the_users_checkout_reads_when_one_is_given",
            arena_test_support::UPSTREAM_CHECKOUT_SKIP,
            "ARENA_REQUIRE_WAA_ROOT",
        );
        return;
    };
    let prompts = WaaPrompts::load(Path::new(&root)).expect("the checkout's prompts read");
    assert!(prompts.system.len() > 200, "a system prompt: {} bytes", prompts.system.len());
    let inputs = UserInputs { objective: "OBJECTIVE-MARK", candidates: "CANDIDATES-MARK", ..UserInputs::default() };
    let text = prompts.user_message(&inputs);
    assert!(text.contains("OBJECTIVE-MARK") && text.contains("CANDIDATES-MARK"), "{text}");
    assert!(prompts.empty_memory.contains("```memory"), "{}", prompts.empty_memory);
    assert!(prompts.history_text(&["ACTION-MARK".into()], 15).contains("ACTION-MARK"));
}

#[test]
fn provenance_names_the_commit_of_a_client_folder_root_and_of_a_worktree_git_file() {
    let root = tempfile::tempdir().unwrap();
    checkout(root.path(), PLANNER_TEXT, AGENT_TEXT);
    // The client folder given as the root: the checkout's .git is found above it.
    let client = WaaPrompts::load(&root.path().join("src/win-arena-container/client")).unwrap();
    assert_eq!(client.source, "waa@0123456789ab");

    // A worktree: `.git` is a file naming its git folder, whose branch ref lives in the
    // main repository's folder (`commondir`), packed.
    let main_git = root.path().join(".git");
    let wt_git = main_git.join("worktrees/wt");
    std::fs::create_dir_all(&wt_git).unwrap();
    std::fs::write(wt_git.join("HEAD"), "ref: refs/heads/feature\n").unwrap();
    std::fs::write(wt_git.join("commondir"), "../..\n").unwrap();
    std::fs::write(
        main_git.join("packed-refs"),
        "# pack-refs with: peeled\nfedcba9876543210fedcba9876543210fedcba98 refs/heads/feature\n",
    )
    .unwrap();
    let worktree = tempfile::tempdir().unwrap();
    checkout(worktree.path(), PLANNER_TEXT, AGENT_TEXT);
    std::fs::remove_dir_all(worktree.path().join(".git")).unwrap();
    std::fs::write(worktree.path().join(".git"), format!("gitdir: {}\n", wt_git.display())).unwrap();
    assert_eq!(WaaPrompts::load(worktree.path()).unwrap().source, "waa@fedcba987654");
    assert_eq!(
        WaaPrompts::load(&worktree.path().join("src/win-arena-container/client")).unwrap().source,
        "waa@fedcba987654"
    );

    // No git at all: said plainly.
    let bare = tempfile::tempdir().unwrap();
    checkout(bare.path(), PLANNER_TEXT, AGENT_TEXT);
    std::fs::remove_dir_all(bare.path().join(".git")).unwrap();
    assert_eq!(git_head(&bare.path().join("src/win-arena-container/client")), "unknown");
}
