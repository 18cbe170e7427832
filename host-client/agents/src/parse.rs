//! Reading a model's reply: fenced code blocks, the control words `DONE`,
//! `FAIL` and `WAIT`, and the memory block the model may rewrite.
//!
//! A reply is usable when it holds at least one fenced code block (```` ```python ````,
//! ```` ```py ````, or unlabelled) or a control word. In a block, a line that
//! is only `DONE`, `FAIL` or `WAIT` ends the code before it and becomes that
//! control action, so `computer.keyboard.press("enter")` followed by `DONE` is
//! two actions. Code that uses the `computer` object is Navi `computer.*` code
//! and anything else pyautogui code, by the one rule both MCP servers use too
//! (`arena_script::dialect_of`). Every code action must parse with the
//! interpreter's parser, so a syntax error is reported here, before anything runs.
//! The decision words are read by `arena_actionspace::Decision`.
//!
//! It does not run anything and does not talk to the model.

use arena_actionspace::Decision;
use arena_script::{dialect_of, Dialect};

use arena_exec::{AgentAction, Code};

/// What a reply holds.
#[derive(Debug, Clone, PartialEq)]
pub struct Parsed {
    pub actions: Vec<AgentAction>,
    /// The text after a `Memory:` line, when the reply has one.
    pub memory: Option<String>,
}

fn control(word: &str) -> Option<AgentAction> {
    Decision::parse(word).map(AgentAction::from)
}

/// The bodies of the fenced code blocks of `text` whose language is Python or
/// unlabelled, in order. An unclosed block runs to the end of the text.
pub fn code_blocks(text: &str) -> Vec<String> {
    let mut blocks = Vec::new();
    let mut current: Option<(bool, Vec<&str>)> = None;
    for line in text.lines() {
        let trimmed = line.trim_start();
        let fence = trimmed.starts_with("```");
        match current.take() {
            None if fence => {
                let lang = trimmed.trim_start_matches('`').trim().to_ascii_lowercase();
                let wanted = matches!(lang.as_str(), "" | "python" | "py" | "python3");
                current = Some((wanted, Vec::new()));
            }
            None => {}
            Some((true, lines)) if fence => blocks.push(lines.join("\n")),
            Some((false, _)) if fence => {}
            Some((wanted, mut lines)) => {
                lines.push(line);
                current = Some((wanted, lines));
            }
        }
    }
    if let Some((true, lines)) = current {
        blocks.push(lines.join("\n"));
    }
    blocks
}

/// Whether `code` has a line that is neither blank nor a comment.
fn meaningful(code: &str) -> bool {
    code.lines().any(|l| {
        let l = l.trim();
        !l.is_empty() && !l.starts_with('#')
    })
}

fn code_action(code: &str) -> Result<Option<AgentAction>, String> {
    if !meaningful(code) {
        return Ok(None);
    }
    // Parsed once, here: the program travels with the action to the executor.
    let parsed = Code::parse(code).map_err(|e| format!("the code block does not parse: {e}"))?;
    Ok(Some(match dialect_of(code) {
        Dialect::Pyautogui => AgentAction::Pyautogui(parsed),
        Dialect::Computer => AgentAction::Computer(parsed),
    }))
}

/// The actions of one code block, split at control-word lines.
fn block_actions(block: &str, out: &mut Vec<AgentAction>) -> Result<(), String> {
    let mut code: Vec<&str> = Vec::new();
    for line in block.lines() {
        if let Some(word) = control(line) {
            if let Some(action) = code_action(&code.join("\n"))? {
                out.push(action);
            }
            code.clear();
            out.push(word);
        } else {
            code.push(line);
        }
    }
    if let Some(action) = code_action(&code.join("\n"))? {
        out.push(action);
    }
    Ok(())
}

/// The memory block: the lines after a line starting with `Memory:` (its rest
/// included), up to a code fence or the end.
pub fn memory(text: &str) -> Option<String> {
    let mut lines = text.lines();
    let first = lines.by_ref().find_map(|l| {
        let t = l.trim_start().trim_start_matches(['#', '*', ' ']);
        t.strip_prefix("Memory:").or_else(|| t.strip_prefix("MEMORY:")).map(|rest| rest.trim_start_matches('*').trim())
    })?;
    let mut out: Vec<&str> = Vec::new();
    if !first.is_empty() {
        out.push(first);
    }
    for line in lines {
        if line.trim_start().starts_with("```") {
            break;
        }
        out.push(line);
    }
    let memory = out.join("\n").trim().to_owned();
    (!memory.is_empty()).then_some(memory)
}

/// Reads a model reply.
///
/// # Errors
///
/// A message for the model when the reply has neither a code block nor a
/// control word, or when a code block does not parse.
pub fn parse_reply(text: &str) -> Result<Parsed, String> {
    let mut actions = Vec::new();
    for block in code_blocks(text) {
        block_actions(&block, &mut actions)?;
    }
    if actions.is_empty() {
        // No usable block: a control word on a line of its own, or as the reply's last word.
        let last_word = text.split_whitespace().last().and_then(control);
        let on_a_line = text.lines().find_map(control);
        if let Some(word) = on_a_line.or(last_word) {
            actions.push(word);
        }
    }
    if actions.is_empty() {
        return Err("the reply has no ```python code block and no DONE, FAIL or WAIT".to_owned());
    }
    Ok(Parsed { actions, memory: memory(text) })
}

/// The text between the first `` ```<label>\n `` and the next `` ``` `` after it,
/// as upstream's non-greedy `re.search` finds it.
fn fenced(text: &str, label: &str) -> Option<String> {
    let open = format!("```{label}\n");
    let start = text.find(&open)? + open.len();
    let end = text[start..].find("```")?;
    Some(text[start..start + end].to_owned())
}

/// Upstream's `remove_min_leading_spaces`: the smallest count of leading spaces
/// over the non-empty lines is cut from every line. `None` when no line is
/// non-empty (upstream's `min()` of nothing raises there).
fn dedent(code: &str) -> Option<String> {
    let lines: Vec<&str> = code.split('\n').collect();
    let cut = lines.iter().filter(|l| !l.is_empty()).map(|l| l.len() - l.trim_start_matches(' ').len()).min()?;
    Some(lines.iter().map(|l| l.get(cut..).unwrap_or("")).collect::<Vec<_>>().join("\n"))
}

/// The code action of a reply without a usable ```` ```python ```` block, as upstream logs and runs it.
pub const PLAN_NOT_FOUND: &str = "# plan not found";

/// A reply read with upstream Navi's rules.
#[derive(Debug, Clone, PartialEq)]
pub struct NaviReply {
    /// One action: the code of the first ```` ```python ```` block ([`PLAN_NOT_FOUND`]
    /// without one; pyautogui code when it does not use the `computer` object),
    /// replaced by `DONE`, `FAIL` or `WAIT` when a ```` ```decision ```` block names
    /// one (checked in that order, anywhere in the block).
    pub actions: Vec<AgentAction>,
    /// The code as the action history records it (the decision does not change it).
    pub code: String,
    /// `` ```memory\n…``` `` when the reply has a memory block: it replaces the agent's memory.
    pub memory_block: Option<String>,
}

/// Reads a reply as upstream's Navi does: only the first ```` ```python ```` block
/// counts (dedented), a ```` ```decision ```` block takes precedence over it, and a
/// ```` ```memory ```` block replaces the memory. A python block with no
/// non-empty line (which makes upstream's agent raise) counts as no block.
pub fn parse_navi_reply(text: &str) -> NaviReply {
    let memory_block = fenced(text, "memory").map(|inner| format!("```memory\n{inner}```"));
    let code = fenced(text, "python").and_then(|c| dedent(&c));
    let mut actions = vec![match &code {
        // Code that does not use the `computer` object is pyautogui code, carried out
        // as every pyautogui answer is (upstream runs any code as `computer` code).
        Some(code) if dialect_of(code) == Dialect::Pyautogui && meaningful(code) => {
            AgentAction::Pyautogui(code.clone().into())
        }
        Some(code) => AgentAction::Computer(code.clone().into()),
        None => AgentAction::Computer(PLAN_NOT_FOUND.into()),
    }];
    let code = code.unwrap_or_else(|| PLAN_NOT_FOUND.to_owned());
    if let Some(decision) = fenced(text, "decision").as_deref().and_then(Decision::named_in) {
        actions = vec![decision.into()];
    }
    NaviReply { actions, code, memory_block }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_code_block_is_parsed_once_and_its_program_goes_with_the_action() {
        let parsed = parse_reply("```python\npyautogui.click(3, 4)\n```\n```python\ncomputer.mouse.move_id(id=2)\n```");
        let actions = parsed.expect("a usable reply").actions;
        assert_eq!(actions.len(), 2, "{actions:?}");
        for action in &actions {
            match action {
                AgentAction::Pyautogui(code) | AgentAction::Computer(code) => assert!(code.is_parsed(), "{code:?}"),
                other => panic!("{other:?}"),
            }
        }
    }

    #[test]
    fn navi_replies_follow_upstreams_rules() {
        let computer = |code: &str| vec![AgentAction::Computer(code.into())];
        // Only the first python block, dedented by its smallest indent.
        let r = parse_navi_reply(
            "Plan.\n```python\n    computer.mouse.move_id(id=3)\n      x = 1\n```\n```python\nother()\n```",
        );
        assert_eq!(r.actions, computer("computer.mouse.move_id(id=3)\n  x = 1\n"));
        // A decision wins over code, DONE before FAIL before WAIT; the history keeps the code.
        let r = parse_navi_reply("```python\ncomputer.keyboard.press(\"enter\")\n```\n```decision\nWAIT or DONE\n```");
        assert_eq!(
            (r.actions.clone(), r.code.as_str()),
            (vec![AgentAction::Done], "computer.keyboard.press(\"enter\")\n")
        );
        assert_eq!(parse_navi_reply("```decision\nFAIL\n```").actions, vec![AgentAction::Fail]);
        assert_eq!(parse_navi_reply("```decision\nCOMMAND\n```").actions, computer(PLAN_NOT_FOUND));
        // No python block: upstream's placeholder, which runs as a comment.
        let r = parse_navi_reply("DONE");
        assert_eq!((r.actions, r.code.as_str(), r.memory_block), (computer(PLAN_NOT_FOUND), PLAN_NOT_FOUND, None));
        assert_eq!(parse_navi_reply("```py\nx()\n```").actions, computer(PLAN_NOT_FOUND), "only ```python counts");
        assert_eq!(parse_navi_reply("```python\n\n```").actions, computer(PLAN_NOT_FOUND));
        // Code that does not use the `computer` object is pyautogui code.
        assert_eq!(
            parse_navi_reply("```python\nimport os\nos.remove('C:/x.txt')\n```").actions,
            vec![AgentAction::Pyautogui("import os\nos.remove('C:/x.txt')\n".into())]
        );
        // The memory block is kept whole, fences included.
        let r = parse_navi_reply("```memory\nsaved file.txt\n```\n```python\nf()\n```");
        assert_eq!(r.memory_block.as_deref(), Some("```memory\nsaved file.txt\n```"));
    }

    fn check(reply: &str, expected: Result<Vec<AgentAction>, &str>) {
        match (parse_reply(reply), expected) {
            (Ok(parsed), Ok(actions)) => assert_eq!(parsed.actions, actions, "{reply}"),
            (Err(err), Err(needle)) => assert!(err.contains(needle), "{err} lacks {needle}"),
            (got, want) => panic!("{reply:?}: got {got:?}, expected {want:?}"),
        }
    }

    fn computer(code: &str) -> AgentAction {
        AgentAction::Computer(code.into())
    }

    #[test]
    fn replies() {
        check(
            "I will click.\n```python\ncomputer.mouse.move_id(id=3)\ncomputer.mouse.single_click()\n```",
            Ok(vec![computer("computer.mouse.move_id(id=3)\ncomputer.mouse.single_click()")]),
        );
        check(
            "```\nimport pyautogui\npyautogui.hotkey('ctrl', 's')\n```",
            Ok(vec![AgentAction::Pyautogui("import pyautogui\npyautogui.hotkey('ctrl', 's')".into())]),
        );
        check(
            "```python\ncomputer.keyboard.press(\"enter\")\nDONE\n```",
            Ok(vec![computer("computer.keyboard.press(\"enter\")"), AgentAction::Done]),
        );
        check("```python\nDONE\n```", Ok(vec![AgentAction::Done]));
        check("The task is impossible.\nFAIL", Ok(vec![AgentAction::Fail]));
        check("Nothing to do yet, WAIT", Ok(vec![AgentAction::Wait]));
        check("```python\n# only a comment\n```\nDONE", Ok(vec![AgentAction::Done]));
        check("Two blocks:\n```python\ncomputer.mouse.move_abs(x=0.5, y=0.5)\n```\nthen\n```py\ncomputer.mouse.single_click()\n```", Ok(vec![
            computer("computer.mouse.move_abs(x=0.5, y=0.5)"),
            computer("computer.mouse.single_click()"),
        ]));
        check("```json\n{\"a\": 1}\n```", Err("no ```python code block"));
        check("I am not sure what to do.", Err("no ```python code block"));
        check("```python\nclass A:\n    pass\n```", Err("does not parse"));
        check("```python\ncomputer.mouse.single_click(\n", Err("does not parse"));
    }

    #[test]
    fn memory_blocks() {
        let check = |reply: &str, expected: Option<&str>| assert_eq!(memory(reply).as_deref(), expected, "{reply}");
        check("Memory: the file is saved\n```python\nDONE\n```", Some("the file is saved"));
        check(
            "Plan...\nMemory:\n- opened notepad\n- typed hello\n```python\n```",
            Some("- opened notepad\n- typed hello"),
        );
        check("**Memory:** step two", Some("step two"));
        check("no memory here", None);
        check("Memory:\n```python\n```", None);
    }
}
