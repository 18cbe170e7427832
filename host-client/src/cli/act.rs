//! `arena act`: one input action spelled on the command line, or a batch given as JSON.
//!
//! The words mirror pyautogui (`click`, `double-click`, `hotkey ctrl c`,
//! `key enter`), and every key and button name is checked here, before
//! anything is sent, so a typo is reported with the name that was wrong
//! rather than as a guest error after half a batch ran.
//! `--pyautogui` code goes through the host's one pyautogui translation, the one
//! every agent's pyautogui answer goes through (`arena_exec`), and its
//! steps are carried out the same way: input as typed batches, `pyperclip.copy`
//! as one clipboard call. It is not an action interpreter: the guest performs the batch.

use std::path::PathBuf;

use anyhow::{bail, Context};
use clap::{Args, Subcommand};

use arena_actionspace::{Coords, Step};
use arena_shared::action::{Action, ActionBatch, MouseButton};
use arena_shared::geometry::Point;
use arena_shared::keys::{parse_chord, Key};

/// Arguments of `arena act`.
#[derive(Debug, Clone, Args)]
#[command(args_conflicts_with_subcommands = true)]
pub struct ActArgs {
    /// One action, or a batch, as JSON: `{"type":"click","x":10,"y":20}`,
    /// `[{...},{...}]` or `{"actions":[...]}`.
    #[arg(long, value_name = "JSON", conflicts_with = "json_file")]
    pub json: Option<String>,

    /// A file holding what `--json` takes.
    #[arg(long, value_name = "FILE")]
    pub json_file: Option<PathBuf>,

    /// pyautogui code, as agents write it (`pyautogui.click(10, 20)`), translated into
    /// actions here with the guest's screen size and cursor, as every agent's
    /// pyautogui answer is (`pyperclip.copy` puts text on the clipboard); nothing
    /// runs as Python.
    #[arg(long, value_name = "CODE", conflicts_with_all = ["json", "json_file"])]
    pub pyautogui: Option<String>,

    #[command(subcommand)]
    pub action: Option<ActCommand>,
}

/// One action spelled on the command line. Coordinates are physical screen pixels.
#[derive(Debug, Clone, PartialEq, Eq, Subcommand)]
pub enum ActCommand {
    /// Click at X Y (or where the cursor is).
    Click {
        #[arg(allow_negative_numbers = true)]
        x: Option<i32>,
        #[arg(allow_negative_numbers = true)]
        y: Option<i32>,
        /// left, right or middle.
        #[arg(long, default_value = "left")]
        button: String,
        /// Number of clicks.
        #[arg(long, default_value_t = 1)]
        count: u32,
    },
    /// Move the cursor to X Y (by DX DY with --relative).
    Move {
        #[arg(allow_negative_numbers = true)]
        x: i32,
        #[arg(allow_negative_numbers = true)]
        y: i32,
        #[arg(long)]
        relative: bool,
    },
    /// Double-click with the left button at X Y (or where the cursor is).
    DoubleClick {
        #[arg(allow_negative_numbers = true)]
        x: Option<i32>,
        #[arg(allow_negative_numbers = true)]
        y: Option<i32>,
    },
    /// Right-click at X Y (or where the cursor is).
    RightClick {
        #[arg(allow_negative_numbers = true)]
        x: Option<i32>,
        #[arg(allow_negative_numbers = true)]
        y: Option<i32>,
    },
    /// Press a button where the cursor is (or at --from X,Y), move to X Y, release.
    Drag {
        #[arg(allow_negative_numbers = true)]
        x: i32,
        #[arg(allow_negative_numbers = true)]
        y: i32,
        /// Start point as X,Y.
        #[arg(long, value_name = "X,Y", allow_hyphen_values = true)]
        from: Option<String>,
        #[arg(long, default_value = "left")]
        button: String,
    },
    /// Turn the wheel by DY raw wheel units (120 per notch, positive is up).
    Scroll {
        #[arg(allow_negative_numbers = true)]
        dy: i32,
        /// Horizontal wheel units (positive is right).
        #[arg(long, default_value_t = 0, allow_negative_numbers = true)]
        dx: i32,
        /// Scroll at X,Y instead of where the cursor is.
        #[arg(long, value_name = "X,Y", allow_hyphen_values = true)]
        at: Option<String>,
    },
    /// Type text (Unicode, independent of the keyboard layout).
    Type {
        #[arg(allow_hyphen_values = true)]
        text: String,
        /// Pause between characters in milliseconds.
        #[arg(long)]
        interval_ms: Option<u64>,
    },
    /// Press and release one key (pyautogui name: enter, esc, f5, a).
    Key {
        #[arg(allow_hyphen_values = true)]
        key: String,
        #[arg(long, default_value_t = 1)]
        presses: u32,
    },
    /// Press keys together: `hotkey ctrl c` or `hotkey ctrl+shift+s`.
    Hotkey {
        #[arg(required = true, num_args = 1.., allow_hyphen_values = true)]
        keys: Vec<String>,
    },
    /// Hold a key down.
    KeyDown {
        #[arg(allow_hyphen_values = true)]
        key: String,
    },
    /// Release a held key.
    KeyUp {
        #[arg(allow_hyphen_values = true)]
        key: String,
    },
    /// Press a mouse button (at X Y when given).
    MouseDown {
        #[arg(allow_negative_numbers = true)]
        x: Option<i32>,
        #[arg(allow_negative_numbers = true)]
        y: Option<i32>,
        #[arg(long, default_value = "left")]
        button: String,
    },
    /// Release a mouse button (at X Y when given).
    MouseUp {
        #[arg(allow_negative_numbers = true)]
        x: Option<i32>,
        #[arg(allow_negative_numbers = true)]
        y: Option<i32>,
        #[arg(long, default_value = "left")]
        button: String,
    },
    /// Wait MS milliseconds.
    Wait { ms: u64 },
}

impl ActArgs {
    /// The batch these arguments describe, checked.
    ///
    /// # Errors
    ///
    /// Neither an action nor JSON given, an unreadable JSON file, malformed
    /// JSON, an unknown action type, key or button name.
    pub fn to_batch(&self) -> anyhow::Result<ActionBatch> {
        let batch = match (&self.action, &self.json, &self.json_file) {
            (Some(action), None, None) => ActionBatch { actions: vec![action.to_action()?] },
            (None, Some(json), None) => parse_batch_json(json).context("--json")?,
            (None, None, Some(path)) => {
                let text =
                    std::fs::read_to_string(path).with_context(|| format!("reading --json-file {}", path.display()))?;
                parse_batch_json(&text).with_context(|| format!("--json-file {}", path.display()))?
            }
            (None, None, None) if self.pyautogui.is_some() => {
                bail!("--pyautogui needs the guest's screen size: use `ActArgs::steps_for`")
            }
            (None, None, None) => {
                bail!("name an action (`arena act click 100 200`) or give --json / --json-file / --pyautogui")
            }
            _ => bail!("give either an action, --json or --json-file, not several"),
        };
        validate_batch(&batch)?;
        Ok(batch)
    }
}

impl ActArgs {
    /// The steps to carry out on `client`'s guest: [`ActArgs::to_batch`]'s actions,
    /// or the translation of `--pyautogui` code for the guest's screen and cursor.
    ///
    /// # Errors
    ///
    /// What [`ActArgs::to_batch`] refuses, the guest cannot be asked, the code
    /// cannot be translated (the action space's message), or it answers a decision
    /// or asks for something only an agent can (a screenshot), which `arena act`
    /// does not do.
    pub async fn steps_for(&self, client: &arena_client::GuestClient) -> anyhow::Result<Vec<Step>> {
        let Some(code) = &self.pyautogui else {
            return Ok(self.to_batch()?.actions.into_iter().map(Step::Act).collect());
        };
        let ctx = arena_exec::pointer(client, Coords::Pixels).await?;
        let steps = arena_exec::translate_pyautogui(code, &ctx).map_err(anyhow::Error::msg)?;
        let mut actions = Vec::new();
        for step in &steps {
            match step {
                Step::Act(action) => actions.push(action.clone()),
                Step::SetClipboard(_) => {}
                other => bail!("--pyautogui: the code asks for {other:?}, which `arena act` does not do"),
            }
        }
        validate_batch(&ActionBatch { actions }).context("--pyautogui")?;
        Ok(steps)
    }
}

impl ActCommand {
    /// The [`Action`] this command stands for.
    ///
    /// # Errors
    ///
    /// An unknown key or button name, an X without a Y, a malformed `X,Y`.
    pub fn to_action(&self) -> anyhow::Result<Action> {
        let action = match self {
            ActCommand::Click { x, y, button, count } => {
                let (x, y) = optional_point(*x, *y)?;
                if *count == 0 {
                    bail!("--count must be at least 1");
                }
                Action::Click { x, y, button: button_named(button)?, count: *count }
            }
            ActCommand::Move { x, y, relative: false } => Action::MoveTo { x: *x, y: *y },
            ActCommand::Move { x, y, relative: true } => Action::MoveRel { dx: *x, dy: *y },
            ActCommand::DoubleClick { x, y } => {
                let (x, y) = optional_point(*x, *y)?;
                Action::DoubleClick { x, y }
            }
            ActCommand::RightClick { x, y } => {
                let (x, y) = optional_point(*x, *y)?;
                Action::RightClick { x, y }
            }
            ActCommand::Drag { x, y, from, button } => Action::Drag {
                from: from.as_deref().map(|text| parse_point(text).context("--from")).transpose()?,
                to: Point::new(*x, *y),
                button: button_named(button)?,
                duration_ms: None,
            },
            ActCommand::Scroll { dy, dx, at } => {
                let at = at.as_deref().map(|text| parse_point(text).context("--at")).transpose()?;
                Action::Scroll { x: at.map(|p| p.x), y: at.map(|p| p.y), dx: *dx, dy: *dy }
            }
            ActCommand::Type { text, interval_ms } => {
                Action::TypeText { text: text.clone(), interval_ms: *interval_ms }
            }
            ActCommand::Key { key, presses } => {
                check_key(key)?;
                Action::KeyPress { key: key.clone(), presses: *presses }
            }
            ActCommand::Hotkey { keys } => {
                // Each word may itself be a chord (`ctrl+c`), as WAA's keyboard.press allows.
                let mut names = Vec::new();
                for word in keys {
                    let parsed = parse_chord(word).map_err(|err| anyhow::anyhow!("hotkey {word:?}: {err}"))?;
                    names.extend(parsed.iter().map(Key::to_string));
                }
                Action::Hotkey { keys: names }
            }
            ActCommand::KeyDown { key } => {
                check_key(key)?;
                Action::KeyDown { key: key.clone() }
            }
            ActCommand::KeyUp { key } => {
                check_key(key)?;
                Action::KeyUp { key: key.clone() }
            }
            ActCommand::MouseDown { x, y, button } => {
                let (x, y) = optional_point(*x, *y)?;
                Action::MouseDown { button: button_named(button)?, x, y }
            }
            ActCommand::MouseUp { x, y, button } => {
                let (x, y) = optional_point(*x, *y)?;
                Action::MouseUp { button: button_named(button)?, x, y }
            }
            ActCommand::Wait { ms } => Action::Wait { ms: *ms },
        };
        Ok(action)
    }
}

/// Parses one action, an array of actions, or `{"actions": [...]}`.
///
/// # Errors
///
/// Malformed JSON, with serde's line and column.
pub fn parse_batch_json(text: &str) -> anyhow::Result<ActionBatch> {
    let value: serde_json::Value = serde_json::from_str(text).context("malformed JSON")?;
    let batch = match value {
        serde_json::Value::Array(_) => {
            ActionBatch { actions: serde_json::from_value(value).context("not a list of actions")? }
        }
        serde_json::Value::Object(ref map) if map.contains_key("actions") => {
            serde_json::from_value(value).context("not an action batch")?
        }
        serde_json::Value::Object(_) => {
            ActionBatch { actions: vec![serde_json::from_value(value).context("not an action")?] }
        }
        _ => bail!("expected an action object, a list of actions or {{\"actions\": [...]}}"),
    };
    Ok(batch)
}

/// Refuses what the guest would refuse, naming the action: unknown types and key names.
fn validate_batch(batch: &ActionBatch) -> anyhow::Result<()> {
    if batch.actions.is_empty() {
        bail!("the batch has no actions");
    }
    for (index, action) in batch.actions.iter().enumerate() {
        let at = || format!("action {index}");
        match action {
            Action::Unknown => bail!("{}: unknown action type (see `arena act --help` for the known ones)", at()),
            Action::KeyPress { key, .. } | Action::KeyDown { key } | Action::KeyUp { key } => {
                check_key(key).with_context(at)?
            }
            Action::Hotkey { keys } => {
                if keys.is_empty() {
                    bail!("{}: a hotkey needs at least one key", at());
                }
                for key in keys {
                    check_key(key).with_context(at)?;
                }
            }
            Action::Click { button, .. }
            | Action::MouseDown { button, .. }
            | Action::MouseUp { button, .. }
            | Action::Drag { button, .. }
                if *button == MouseButton::Unknown =>
            {
                bail!("{}: unknown mouse button (expected left, right or middle)", at())
            }
            _ => {}
        }
    }
    Ok(())
}

fn check_key(name: &str) -> anyhow::Result<()> {
    match Key::parse(name) {
        Ok(_) => Ok(()),
        Err(err) if name.chars().count() > 1 && (name.contains('+') || name.contains('-')) => {
            bail!("{err}; for a chord use `arena act hotkey {name}`")
        }
        Err(err) => Err(err.into()),
    }
}

fn button_named(name: &str) -> anyhow::Result<MouseButton> {
    MouseButton::from_name(name)
        .ok_or_else(|| anyhow::anyhow!("unknown mouse button {name:?} (expected left, right or middle)"))
}

fn optional_point(x: Option<i32>, y: Option<i32>) -> anyhow::Result<(Option<i32>, Option<i32>)> {
    match (x, y) {
        (Some(_), None) => bail!("an X coordinate needs a Y coordinate too"),
        other => Ok(other),
    }
}

/// Parses `X,Y` (spaces allowed).
fn parse_point(text: &str) -> anyhow::Result<Point> {
    let (x, y) = text.split_once(',').ok_or_else(|| anyhow::anyhow!("{text:?} is not X,Y"))?;
    let number =
        |s: &str| s.trim().parse::<i32>().map_err(|_| anyhow::anyhow!("{text:?} is not X,Y with whole numbers"));
    Ok(Point::new(number(x)?, number(y)?))
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    use super::*;

    #[derive(Debug, Parser)]
    struct Harness {
        #[command(flatten)]
        act: ActArgs,
    }

    fn parse(words: &[&str]) -> anyhow::Result<ActionBatch> {
        let argv = std::iter::once("act").chain(words.iter().copied());
        let harness = Harness::try_parse_from(argv)?;
        harness.act.to_batch()
    }

    fn check(words: &[&str], expected: Action) {
        match parse(words) {
            Ok(batch) => assert_eq!(batch.actions, vec![expected], "act {words:?}"),
            Err(err) => panic!("act {words:?} failed: {err:#}"),
        }
    }

    fn check_err(words: &[&str], needle: &str) {
        match parse(words) {
            Ok(batch) => panic!("act {words:?} should fail, got {batch:?}"),
            Err(err) => {
                let text = format!("{err:#}");
                assert!(text.contains(needle), "act {words:?}: {text:?} lacks {needle:?}");
            }
        }
    }

    #[test]
    fn mouse_words() {
        check(
            &["click", "100", "200"],
            Action::Click { x: Some(100), y: Some(200), button: MouseButton::Left, count: 1 },
        );
        check(
            &["click", "100", "200", "--button", "right", "--count", "2"],
            Action::Click { x: Some(100), y: Some(200), button: MouseButton::Right, count: 2 },
        );
        check(&["click"], Action::Click { x: None, y: None, button: MouseButton::Left, count: 1 });
        check(&["click", "-5", "10"], Action::Click { x: Some(-5), y: Some(10), button: MouseButton::Left, count: 1 });
        check(&["move", "10", "20"], Action::MoveTo { x: 10, y: 20 });
        check(&["move", "--relative", "-3", "4"], Action::MoveRel { dx: -3, dy: 4 });
        check(&["double-click"], Action::DoubleClick { x: None, y: None });
        check(&["double-click", "5", "6"], Action::DoubleClick { x: Some(5), y: Some(6) });
        check(&["right-click"], Action::RightClick { x: None, y: None });
        check(
            &["drag", "300", "400"],
            Action::Drag { from: None, to: Point::new(300, 400), button: MouseButton::Left, duration_ms: None },
        );
        check(
            &["drag", "300", "400", "--from", "1,2", "--button", "middle"],
            Action::Drag {
                from: Some(Point::new(1, 2)),
                to: Point::new(300, 400),
                button: MouseButton::Middle,
                duration_ms: None,
            },
        );
        check(&["scroll", "-240"], Action::Scroll { x: None, y: None, dx: 0, dy: -240 });
        check(
            &["scroll", "120", "--dx", "-120", "--at", "50, 60"],
            Action::Scroll { x: Some(50), y: Some(60), dx: -120, dy: 120 },
        );
        check(&["mouse-down"], Action::MouseDown { button: MouseButton::Left, x: None, y: None });
        check(&["mouse-up", "--button", "right"], Action::MouseUp { button: MouseButton::Right, x: None, y: None });
        check(&["wait", "250"], Action::Wait { ms: 250 });
    }

    #[test]
    fn keyboard_words() {
        check(&["type", "hello world"], Action::TypeText { text: "hello world".into(), interval_ms: None });
        check(&["type", "-dash first"], Action::TypeText { text: "-dash first".into(), interval_ms: None });
        check(&["type", "x", "--interval-ms", "20"], Action::TypeText { text: "x".into(), interval_ms: Some(20) });
        check(&["key", "enter"], Action::KeyPress { key: "enter".into(), presses: 1 });
        check(&["key", "pgdn", "--presses", "3"], Action::KeyPress { key: "pgdn".into(), presses: 3 });
        check(&["hotkey", "ctrl", "c"], Action::Hotkey { keys: vec!["ctrl".into(), "c".into()] });
        check(&["hotkey", "ctrl+shift+s"], Action::Hotkey { keys: vec!["ctrl".into(), "shift".into(), "s".into()] });
        check(&["key-down", "shift"], Action::KeyDown { key: "shift".into() });
        check(&["key-up", "shift"], Action::KeyUp { key: "shift".into() });
    }

    #[test]
    fn json_forms() {
        check(
            &["--json", r#"{"type":"click","x":1,"y":2}"#],
            Action::Click { x: Some(1), y: Some(2), button: MouseButton::Left, count: 1 },
        );
        check(&["--json", r#"[{"type":"key_press","key":"esc"}]"#], Action::KeyPress { key: "esc".into(), presses: 1 });
        check(&["--json", r#"{"actions":[{"type":"wait","ms":5}]}"#], Action::Wait { ms: 5 });
    }

    #[test]
    fn json_file_is_read() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("batch.json");
        std::fs::write(&path, r#"[{"type":"type_text","text":"hi"},{"type":"hotkey","keys":["ctrl","s"]}]"#).unwrap();
        let batch = parse(&["--json-file", path.to_str().unwrap()]).unwrap();
        assert_eq!(batch.actions.len(), 2);
        assert_eq!(batch.actions[1], Action::Hotkey { keys: vec!["ctrl".into(), "s".into()] });
    }

    #[tokio::test]
    async fn pyautogui_code_is_translated_for_the_guest_and_sent() {
        let harness = Harness::try_parse_from([
            "act",
            "--pyautogui",
            "pyautogui.moveTo(30, 40); pyautogui.moveRel(1, 2); pyautogui.click()",
        ])
        .expect("parses");
        assert!(format!("{:#}", harness.act.to_batch().expect_err("needs the guest")).contains("steps_for"));
        let stub =
            crate::driver::stub::start(&crate::driver::stub::StubArgs::default(), None).await.expect("stub guest");
        let client =
            arena_client::GuestClient::new(&stub.url(), arena_client::ClientConfig::default()).expect("client");
        let steps = harness.act.steps_for(&client).await.expect("translated");
        assert_eq!(
            steps,
            vec![
                Step::Act(Action::MoveTo { x: 30, y: 40 }),
                Step::Act(Action::MoveRel { dx: 1, dy: 2 }),
                Step::Act(Action::Click { x: None, y: None, button: MouseButton::Left, count: 1 }),
            ]
        );
        let options = arena_exec::ExecOptions::default();
        let outcome = arena_exec::perform_steps(&client, &steps, &options).await.expect("performed");
        let cursor = outcome.cursor.expect("a cursor");
        assert_eq!((cursor.x, cursor.y, outcome.performed), (31, 42, 3));
        let bad = Harness::try_parse_from(["act", "--pyautogui", "pyautogui.screenshot('x.png')"]).expect("parses");
        let err = format!("{:#}", bad.act.steps_for(&client).await.expect_err("not input"));
        assert!(err.contains("saving a screenshot"), "{err}");
        let done = Harness::try_parse_from(["act", "--pyautogui", "DONE"]).expect("parses");
        assert!(format!("{:#}", done.act.steps_for(&client).await.expect_err("a decision")).contains("Done"));
        assert!(Harness::try_parse_from(["act", "--pyautogui", "x", "--json", "[]"]).is_err());
        stub.stop().await.expect("stops");
    }

    #[test]
    fn bad_input_names_what_was_wrong() {
        check_err(&["key", "entr"], "unknown key name \"entr\"");
        check_err(&["key", "ctrl+c"], "arena act hotkey ctrl+c");
        check_err(&["hotkey", "ctrl", "bogus"], "\"bogus\"");
        check_err(&["key-down", "shiftt"], "\"shiftt\"");
        check_err(&["click", "1", "2", "--button", "sideways"], "unknown mouse button \"sideways\"");
        check_err(&["click", "1"], "needs a Y");
        check_err(&["click", "--count", "0"], "--count");
        check_err(&["drag", "1", "2", "--from", "3"], "is not X,Y");
        check_err(&["--json", "{not json"], "malformed JSON");
        check_err(&["--json", r#"{"type":"teleport"}"#], "unknown action type");
        check_err(&["--json", r#"{"type":"key_press","key":"nope"}"#], "action 0");
        check_err(&["--json", "[]"], "no actions");
        check_err(&["--json", "3"], "expected an action object");
        check_err(&["--json-file", "/definitely/not/here.json"], "/definitely/not/here.json");
        check_err(&[], "name an action");
    }
}
