//! The catalogue (`catalogue.json` beside this crate's `Cargo.toml`, built in): input
//! intents written once as data, each with the events the recorder must see and its
//! expression in every action space that can express it, and the translation of an
//! expression into steps through `arena_actionspace::parse`, the host's one
//! translation.
//!
//! A case is an object: `name` (unique), `intent` (what a person would say), `expect`
//! (event lines, [`crate::expect`]) or `expect_text` (the characters typed, for cases
//! whose keys differ by layout or by how a space types), optionally `expect_by_space`
//! (a space whose translation differs on purpose, with its own lines, such as UI-TARS
//! typing by paste), `note`, `wine` (a [`WineException`]: what Wine cannot show of the
//! case, `{"reason": "...", "spaces": [...], "sometimes": true}`, every space when
//! `spaces` is left out, `sometimes` when Wine fails it only now and then),
//! and one member per action space: `pyautogui` (code),
//! `computer_13`, `anthropic` (the `computer` tool's input, run as
//! `computer_20250124`, as `computer_20251124` and, as member-named blocks, as
//! `computer_toolset_20260801`), `openai_computer` (a `computer_call` action or a GA
//! batch), `uitars` (a reply) and `typed` (`/v1/actions` actions).

use serde_json::{Map, Value};

use arena_actionspace::{ActionSpace, Context, Coords, Step};

use crate::expect::Expected;

/// The built-in catalogue's text.
pub const BUILTIN: &str = include_str!("../catalogue.json");

/// What a case checks.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Check {
    /// These events, in this order.
    Events(Vec<Expected>),
    /// Exactly these characters (`WM_CHAR`), whatever keys carried them.
    Text(String),
}

/// A case, in some spaces or all, that the Windows backend under Wine cannot pass for
/// a reason of Wine's (not of the backend's), named so the Wine suite can hold it to
/// failing there while it passes on the stub and is still checked on a real guest.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WineException {
    /// Why Wine cannot show it.
    pub reason: String,
    /// The spaces it is excused in; every space when empty.
    pub spaces: Vec<ActionSpace>,
    /// Wine fails it only some of the time (a race in Wine, not a fixed answer), so a
    /// run that passes is no sign the reason has gone.
    pub sometimes: bool,
}

impl WineException {
    /// Whether the exception covers `space`.
    pub fn covers(&self, space: ActionSpace) -> bool {
        self.spaces.is_empty() || self.spaces.contains(&space)
    }
}

/// One intent.
#[derive(Debug, Clone, PartialEq)]
pub struct Case {
    pub name: String,
    pub intent: String,
    pub check: Check,
    /// Spaces that reach the intent with other events on purpose, and those events.
    pub by_space: Vec<(ActionSpace, Check)>,
    pub note: Option<String>,
    /// What Wine cannot show of the case, and why.
    pub wine: Option<WineException>,
    /// The case in each action space that expresses it, in [`ActionSpace::ALL`]'s order.
    pub inputs: Vec<(ActionSpace, Value)>,
}

impl Case {
    /// What `space`'s expression of the case must deliver.
    pub fn check_for(&self, space: ActionSpace) -> &Check {
        self.by_space.iter().find(|(s, _)| *s == space).map_or(&self.check, |(_, c)| c)
    }

    /// Whether the case clicks (the check waits out the double-click time after it).
    pub fn clicks(&self) -> bool {
        let clicks = |check: &Check| match check {
            Check::Events(events) => events.iter().any(|e| matches!(e, Expected::Button { .. })),
            Check::Text(_) => false,
        };
        clicks(&self.check) || self.by_space.iter().any(|(_, c)| clicks(c))
    }
}

/// The whole catalogue.
#[derive(Debug, Clone, PartialEq)]
pub struct Catalogue {
    pub cases: Vec<Case>,
}

/// The members of a case that are not an action space.
const CASE_FIELDS: [&str; 7] = ["name", "intent", "expect", "expect_text", "expect_by_space", "note", "wine"];

impl Catalogue {
    /// The catalogue built into this crate.
    ///
    /// # Errors
    ///
    /// What [`Catalogue::parse`] finds wrong with it (a test keeps it right).
    pub fn builtin() -> Result<Catalogue, String> {
        Catalogue::parse(BUILTIN)
    }

    /// Reads a catalogue.
    ///
    /// # Errors
    ///
    /// A message naming the case and what is wrong: not JSON, a missing or duplicate
    /// name, an unknown member or action space, a bad event line.
    pub fn parse(text: &str) -> Result<Catalogue, String> {
        let root: Value = serde_json::from_str(text).map_err(|err| format!("the catalogue is not JSON: {err}"))?;
        let Some(Value::Array(items)) = root.get("cases") else {
            return Err("the catalogue needs `cases`, a list".into());
        };
        let mut cases: Vec<Case> = Vec::new();
        for (n, item) in items.iter().enumerate() {
            let case = parse_case(item).map_err(|err| {
                let name = item.get("name").and_then(Value::as_str).map_or_else(|| format!("#{n}"), str::to_owned);
                format!("case {name}: {err}")
            })?;
            if cases.iter().any(|c| c.name == case.name) {
                return Err(format!("case {} is there twice", case.name));
            }
            cases.push(case);
        }
        Ok(Catalogue { cases })
    }
}

fn parse_check(value: &Value) -> Result<Check, String> {
    match value {
        Value::Array(lines) => lines
            .iter()
            .map(|line| match line {
                Value::String(line) => Expected::parse(line),
                other => Err(format!("an event line must be a string, got {other}")),
            })
            .collect::<Result<Vec<_>, _>>()
            .map(Check::Events),
        other => Err(format!("`expect` must be a list of event lines, got {other}")),
    }
}

fn text_field(obj: &Map<String, Value>, key: &str) -> Result<String, String> {
    match obj.get(key) {
        Some(Value::String(s)) if !s.is_empty() => Ok(s.clone()),
        _ => Err(format!("`{key}` must be a non-empty string")),
    }
}

fn parse_case(item: &Value) -> Result<Case, String> {
    let Value::Object(obj) = item else {
        return Err("a case must be an object".into());
    };
    let name = text_field(obj, "name")?;
    let intent = text_field(obj, "intent")?;
    let check = match (obj.get("expect"), obj.get("expect_text")) {
        (Some(events), None) => parse_check(events)?,
        (None, Some(Value::String(text))) => Check::Text(text.clone()),
        _ => return Err("give either `expect` (event lines) or `expect_text` (a string)".into()),
    };
    let mut by_space = Vec::new();
    if let Some(map) = obj.get("expect_by_space") {
        let Value::Object(map) = map else {
            return Err("`expect_by_space` must map space names to event lines".into());
        };
        for (space, lines) in map {
            for space in spaces_of(space)? {
                by_space.push((space, parse_check(lines)?));
            }
        }
    }
    let note = obj.get("note").and_then(Value::as_str).map(str::to_owned);
    let wine = obj.get("wine").map(parse_wine).transpose()?;
    let mut inputs = Vec::new();
    for (key, input) in obj {
        if CASE_FIELDS.contains(&key.as_str()) {
            continue;
        }
        for space in spaces_of(key)? {
            let input =
                if space == ActionSpace::AnthropicToolset20260801 { toolset_blocks(input)? } else { input.clone() };
            inputs.push((space, input));
        }
    }
    inputs.sort_by_key(|(space, _)| ActionSpace::ALL.iter().position(|s| s == space));
    if let Some(wine) = &wine {
        if let Some(space) = wine.spaces.iter().find(|s| !inputs.iter().any(|(i, _)| i == *s)) {
            return Err(format!("`wine` names {}, which the case is not expressed in", space.name()));
        }
    }
    Ok(Case { name, intent, check, by_space, note, wine, inputs })
}

/// A case's `wine` member: `{"reason": "...", "spaces": ["typed", "anthropic", ...]}`.
fn parse_wine(value: &Value) -> Result<WineException, String> {
    let Value::Object(obj) = value else {
        return Err("`wine` must be an object with `reason` (and `spaces`)".into());
    };
    if let Some(key) = obj.keys().find(|k| !["reason", "spaces", "sometimes"].contains(&k.as_str())) {
        return Err(format!("`wine` has an unknown member {key:?} (expected reason, spaces, sometimes)"));
    }
    let sometimes = match obj.get("sometimes") {
        None => false,
        Some(Value::Bool(b)) => *b,
        Some(other) => return Err(format!("`wine`: `sometimes` must be true or false, got {other}")),
    };
    let reason = text_field(obj, "reason").map_err(|err| format!("`wine`: {err}"))?;
    let mut spaces = Vec::new();
    match obj.get("spaces") {
        None => {}
        Some(Value::Array(names)) if !names.is_empty() => {
            for name in names {
                let Value::String(name) = name else {
                    return Err(format!("`wine`: a space must be a name, got {name}"));
                };
                spaces.extend(spaces_of(name).map_err(|err| format!("`wine`: {err}"))?);
            }
        }
        Some(other) => return Err(format!("`wine`: `spaces` must be a non-empty list of names, got {other}")),
    }
    Ok(WineException { reason, spaces, sometimes })
}

/// The spaces a member name stands for.
fn spaces_of(key: &str) -> Result<Vec<ActionSpace>, String> {
    if key == "anthropic" {
        return Ok(vec![
            ActionSpace::Anthropic20250124,
            ActionSpace::Anthropic20251124,
            ActionSpace::AnthropicToolset20260801,
        ]);
    }
    match key.parse::<ActionSpace>() {
        Ok(ActionSpace::Anthropic20250124 | ActionSpace::Anthropic20251124 | ActionSpace::AnthropicToolset20260801) => {
            Err(format!("{key}: write Anthropic's input once, as `anthropic`"))
        }
        Ok(space) => Ok(vec![space]),
        Err(err) => Err(format!("unknown member {key:?}: {err}, or anthropic")),
    }
}

/// The `computer` tool's input (one action or a list) as the toolset's member-named
/// blocks: `{"action": "left_click", ...}` is `{"name": "left_click", "input": {...}}`.
fn toolset_blocks(input: &Value) -> Result<Value, String> {
    let block = |action: &Value| -> Result<Value, String> {
        let Value::Object(map) = action else {
            return Err(format!("an Anthropic action must be an object, got {action}"));
        };
        let mut rest = map.clone();
        let name = rest.remove("action").ok_or("an Anthropic action needs `action`")?;
        Ok(serde_json::json!({"name": name, "input": rest}))
    };
    match input {
        Value::Array(actions) => actions.iter().map(block).collect::<Result<Vec<_>, _>>().map(Value::Array),
        one => block(one),
    }
}

/// The context cases are translated in: the guest's screen, pixels.
pub fn context(screen: (u32, u32)) -> Context {
    Context::new(screen, Coords::Pixels)
}

/// A case's expression in `space` as steps, through the host's one translation.
///
/// # Errors
///
/// The translation's error, as a message.
pub fn translate(space: ActionSpace, input: &Value, ctx: &Context) -> Result<Vec<Step>, String> {
    arena_actionspace::parse(space, input, ctx).map_err(|err| err.to_string())
}
