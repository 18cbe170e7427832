//! Set-of-Marks: numbered element boxes, the candidate list the model reads,
//! and the annotated screenshot it sees, from every source of upstream Navi's
//! `--som_origin` (waa-api.md §c.3):
//!
//! | [`SomOrigin`] | entities, in id order |
//! |---|---|
//! | `a11y` | the accessibility tree ([`a11y`]) |
//! | `oss` | browser DOM elements (given by the caller), the icon/image detector ([`detector`], Grounding DINO behind HTTP), Tesseract OCR ([`ocr`]) |
//! | `omni` | OmniParser's server ([`omni`]) |
//! | `mixed-oss` | the tree's drawable entities, then the `oss` entities they do not already cover ([`mixed`]) |
//! | `mixed-omni` | the tree's drawable entities clipped to the screen and re-typed `icon`/`text`, then the OmniParser entities they do not cover |
//!
//! Whatever the source, the entities are numbered as upstream's
//! `parser_to_prompt` numbers them ([`number`]): the id is the index in the
//! whole list, only the entities with `x >= 0`, `y >= 0`, `w > 0`, `h > 0` and
//! `w·h > 1` are drawn and listed, and [`Marks::rects`] keeps one box per id, so
//! `computer.mouse.move_id(id)` indexes it exactly as upstream's `/update_computer`
//! `rects` list. The candidate list's type column is the entity's type as the
//! source names it (`a11y`, `text`, `icon`, `image`, `text/html`); the prompt
//! image draws only the types upstream's prompt colour map has, in its colours
//! ([`SomOrigin::prompt_colour`]).
//!
//! The pixel sources are reached asynchronously through [`SomSources`]; the
//! accessibility proposal alone is [`marks_from_tree`], which needs no I/O.

#![forbid(unsafe_code)]

pub mod a11y;
pub mod detector;
mod draw;
pub mod mixed;
pub mod ocr;
pub mod omni;

use std::time::Duration;

use serde::{Deserialize, Serialize};

use arena_script::float_repr;
use arena_shared::geometry::Rect;
use arena_shared::observation::A11yTree;

pub use a11y::REDUNDANCY_THRESHOLD;
pub use draw::annotate;

/// The header row of the candidate list, exactly as upstream's prompt has it.
pub const CANDIDATE_HEADER: &str = "ID | Type | Text content or description | Normalized location [x1, y1, x2, y2]";

/// The type upstream's web parser gives DOM elements.
pub const DOM_KIND: &str = "text/html";

/// Colours by the names upstream's colour maps use, as Pillow defines those names.
pub mod colour {
    /// Pillow's `red`.
    pub const RED: [u8; 3] = [255, 0, 0];
    /// Pillow's `green` (CSS green, not lime).
    pub const GREEN: [u8; 3] = [0, 128, 0];
    /// Pillow's `blue`.
    pub const BLUE: [u8; 3] = [0, 0, 255];
    /// Pillow's `magenta`.
    pub const MAGENTA: [u8; 3] = [255, 0, 255];
}

/// Where the Set-of-Marks entities come from: upstream's `--som_origin`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum SomOrigin {
    /// The accessibility tree.
    #[default]
    #[serde(rename = "a11y")]
    A11y,
    /// DOM elements, the icon/image detector and Tesseract OCR.
    #[serde(rename = "oss")]
    Oss,
    /// OmniParser.
    #[serde(rename = "omni")]
    Omni,
    /// The tree, then the `oss` entities it does not cover.
    #[serde(rename = "mixed-oss")]
    MixedOss,
    /// The tree (re-typed `icon`/`text`), then the OmniParser entities it does not cover.
    #[serde(rename = "mixed-omni")]
    MixedOmni,
}

impl SomOrigin {
    /// Every origin, in upstream's order of mention.
    pub const ALL: [SomOrigin; 5] =
        [SomOrigin::A11y, SomOrigin::Oss, SomOrigin::Omni, SomOrigin::MixedOss, SomOrigin::MixedOmni];

    /// Upstream's name (`a11y`, `oss`, `omni`, `mixed-oss`, `mixed-omni`).
    pub fn name(self) -> &'static str {
        match self {
            SomOrigin::A11y => "a11y",
            SomOrigin::Oss => "oss",
            SomOrigin::Omni => "omni",
            SomOrigin::MixedOss => "mixed-oss",
            SomOrigin::MixedOmni => "mixed-omni",
        }
    }

    /// The colour entities of `kind` are drawn in on the prompt image, or `None`
    /// when upstream's prompt colour map for this origin leaves the type out
    /// (such entities are listed but not drawn: OCR text and DOM elements in
    /// every pixel mode).
    pub fn prompt_colour(self, kind: &str) -> Option<[u8; 3]> {
        match (self, kind) {
            (SomOrigin::A11y | SomOrigin::MixedOss, a11y::A11Y_KIND) => Some(colour::RED),
            (SomOrigin::A11y, _) => None,
            (_, "image") => Some(colour::RED),
            (_, "icon") => Some(colour::GREEN),
            _ => None,
        }
    }

    /// Whether this origin starts from the browser's DOM elements (upstream's
    /// `oss` pipelines run its web parser first), so each observation must read them.
    pub fn needs_dom(self) -> bool {
        matches!(self, SomOrigin::Oss | SomOrigin::MixedOss)
    }

    /// Whether this origin reads the accessibility tree.
    pub fn uses_tree(self) -> bool {
        matches!(self, SomOrigin::A11y | SomOrigin::MixedOss | SomOrigin::MixedOmni)
    }
}

impl std::fmt::Display for SomOrigin {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for SomOrigin {
    type Err = String;

    fn from_str(s: &str) -> Result<SomOrigin, String> {
        SomOrigin::ALL.into_iter().find(|o| o.name() == s).ok_or_else(|| {
            let names: Vec<&str> = SomOrigin::ALL.iter().map(|o| o.name()).collect();
            format!("unknown Set-of-Marks origin `{s}` (expected one of {})", names.join(", "))
        })
    }
}

/// An entity a source proposed, before ids are given: upstream's
/// `{"type", "shape", "text"}` dict. Callers use it to hand in entities of a
/// source this module does not reach itself (the browser's DOM elements for `oss`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ProposedEntity {
    /// The type the source gives it (`a11y`, `text`, `icon`, `image`, `text/html`).
    pub kind: String,
    /// Box in screen pixels.
    pub rect: Rect,
    /// The text; `None` when the source gives none (listed as `-`, as upstream's
    /// entities without a `text` key are).
    pub text: Option<String>,
}

impl ProposedEntity {
    pub fn new(kind: &str, rect: Rect, text: Option<String>) -> ProposedEntity {
        ProposedEntity { kind: kind.to_owned(), rect, text }
    }

    /// A DOM element of upstream's web parser (type `text/html`) with the element's
    /// `textContent`. Upstream lists a missing `textContent` as Python prints
    /// `None`, so `None` becomes the text `None`.
    pub fn dom(rect: Rect, text_content: Option<String>) -> ProposedEntity {
        ProposedEntity::new(DOM_KIND, rect, Some(text_content.unwrap_or_else(|| "None".to_owned())))
    }
}

/// One proposed element, listed and drawn with its id.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Mark {
    /// Index into [`Marks::rects`]; what `move_id` takes.
    pub id: usize,
    /// The entity's type, the candidate list's type column.
    pub kind: String,
    /// The entity's text (an accessible name may be empty).
    pub text: String,
    /// The source gave no text at all (a detector's box): listed as `-`.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub no_text: bool,
    /// Box in screen pixels (the same space as the tree).
    pub rect: Rect,
    /// The box and label colour on the prompt image; `None`: listed, not drawn.
    #[serde(default)]
    pub colour: Option<[u8; 3]>,
}

/// The element boxes of one observation.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Marks {
    /// The entities that are drawn and listed (a subset of the ids, in id order).
    pub entities: Vec<Mark>,
    /// `[x1, y1, x2, y2]` for every id, listed or not: `computer.mouse.move_id` targets the centre of `rects[id]`.
    pub rects: Vec<[i32; 4]>,
    /// Width and height the boxes are measured against (the screen, in the tree's pixels);
    /// the denominators of the normalized locations.
    pub size: (u32, u32),
}

impl Marks {
    /// The boxes as the executor hands them to Navi's `computer` object.
    pub fn boxes(&self) -> arena_exec::Boxes<'_> {
        arena_exec::Boxes { rects: &self.rects, size: self.size }
    }
}

/// Upstream's `parser_to_prompt` numbering: ids over the whole list, the
/// drawable entities listed, colours from `origin`'s prompt colour map.
pub fn number(origin: SomOrigin, entities: Vec<ProposedEntity>, size: (u32, u32)) -> Marks {
    let rects = entities.iter().map(|e| [e.rect.x, e.rect.y, e.rect.right(), e.rect.bottom()]).collect();
    let entities = entities
        .into_iter()
        .enumerate()
        .filter(|(_, e)| a11y::drawable(&e.rect))
        .map(|(id, e)| Mark {
            id,
            colour: origin.prompt_colour(&e.kind),
            no_text: e.text.is_none(),
            text: e.text.unwrap_or_default(),
            kind: e.kind,
            rect: e.rect,
        })
        .collect();
    Marks { entities, rects, size }
}

/// Proposes the Set-of-Marks elements of `tree` for a screen of `size` pixels
/// (width, height: the screenshot's size in the tree's pixels): the `a11y` origin.
pub fn marks_from_tree(tree: &A11yTree, size: (u32, u32)) -> Marks {
    number(SomOrigin::A11y, a11y::propose(tree), size)
}

/// Python's `round(v, 2)` printed as Python prints a float (`0.5`, `0.12`, `1.0`).
fn round2(v: f64) -> String {
    // Formatting rounds the exact binary value to two decimals, as CPython's
    // round() does; parsing it back gives the float Python would hold.
    let rounded: f64 = format!("{v:.2}").parse().unwrap_or(v);
    float_repr(rounded)
}

impl Mark {
    /// The text, or `None` when the source gave none.
    pub fn given_text(&self) -> Option<&str> {
        (!self.no_text).then_some(self.text.as_str())
    }
}

impl Marks {
    /// The element with this id, if it is listed.
    pub fn get(&self, id: usize) -> Option<&Mark> {
        self.entities.iter().find(|m| m.id == id)
    }

    /// The candidate list of upstream's prompt: the header, then one row per
    /// listed element, every line ending in a newline as upstream's does, `id | type | text | [x1, y1, x2, y2]` with coordinates as
    /// fractions of the screen rounded to two decimals. The text is printed as
    /// it is, an empty one as nothing, as upstream prints it; only an entity
    /// with no text at all (a detector's box) shows `-`.
    pub fn candidate_list(&self) -> String {
        let w = f64::from(self.size.0.max(1));
        let h = f64::from(self.size.1.max(1));
        let mut out = format!("{CANDIDATE_HEADER}\n");
        for m in &self.entities {
            let r = &m.rect;
            out.push_str(&format!(
                "{} | {} | {} | [{}, {}, {}, {}]\n",
                m.id,
                m.kind,
                m.given_text().unwrap_or("-"),
                round2(f64::from(r.x) / w),
                round2(f64::from(r.y) / h),
                round2(f64::from(r.right()) / w),
                round2(f64::from(r.bottom()) / h),
            ));
        }
        out
    }
}

/// Why the marks could not be made or drawn.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SomError {
    /// Tesseract is missing or failed.
    #[error("OCR: {0}")]
    Ocr(String),
    /// A screen-parsing service (the detector, OmniParser) failed or answered out of shape.
    #[error("{service} at {url}: {reason}")]
    Service { service: &'static str, url: String, reason: String },
    /// The chosen origin needs something that is not configured.
    #[error("Set-of-Marks configuration: {0}")]
    Config(String),
}

/// How to reach the sources of the chosen origin.
#[derive(Debug, Clone, PartialEq)]
pub struct SomConfig {
    pub origin: SomOrigin,
    /// Base URL of the Grounding DINO service ([`detector`]); needed by `oss` and `mixed-oss`.
    pub detector_url: Option<String>,
    /// Base URL of OmniParser's server ([`omni`]); needed by `omni` and `mixed-omni`.
    pub omniparser_url: Option<String>,
    /// The Tesseract program (a name looked up on `PATH`, or a path).
    pub tesseract: String,
    /// Deadline of one service call or OCR run.
    pub timeout: Duration,
}

impl Default for SomConfig {
    fn default() -> SomConfig {
        SomConfig {
            origin: SomOrigin::A11y,
            detector_url: None,
            omniparser_url: None,
            tesseract: ocr::DEFAULT_PROGRAM.to_owned(),
            timeout: Duration::from_secs(120),
        }
    }
}

/// What one observation offers the sources.
#[derive(Debug, Clone, Copy)]
pub struct SomInput<'a> {
    /// The accessibility tree, when it could be read.
    pub tree: Option<&'a A11yTree>,
    /// The full-screen screenshot, decoded once by the observation.
    pub screenshot: &'a arena_client::frame::Frame,
    /// The screen's size in the tree's pixels: the space of the marks.
    pub size: (u32, u32),
    /// The browser's DOM elements for `oss` and `mixed-oss`, in screen pixels
    /// (upstream's web parser; see [`ProposedEntity::dom`]). Empty when there is no browser.
    pub dom: &'a [ProposedEntity],
}

/// The sources of one origin, ready to be asked.
#[derive(Debug, Clone)]
pub struct SomSources {
    config: SomConfig,
    http: reqwest::Client,
}

impl SomSources {
    /// Checks that the origin's services are configured and builds the HTTP client.
    ///
    /// # Errors
    ///
    /// [`SomError::Config`] when a needed URL is missing or the client cannot be built.
    pub fn new(config: SomConfig) -> Result<SomSources, SomError> {
        let needs = |url: &Option<String>, what: &str, flag: &str| match url.as_deref().map(str::trim) {
            Some(u) if !u.is_empty() => Ok(()),
            _ => Err(SomError::Config(format!("--som-origin {} needs {what} ({flag})", config.origin))),
        };
        match config.origin {
            SomOrigin::A11y => {}
            SomOrigin::Oss | SomOrigin::MixedOss => {
                needs(&config.detector_url, "the Grounding DINO service", "--detector-url or ARENA_DETECTOR_URL")?;
            }
            SomOrigin::Omni | SomOrigin::MixedOmni => {
                needs(&config.omniparser_url, "OmniParser's server", "--omniparser-url or ARENA_OMNIPARSER_URL")?;
            }
        }
        let http = reqwest::Client::builder()
            .timeout(config.timeout)
            .build()
            .map_err(|e| SomError::Config(format!("cannot build the HTTP client: {e}")))?;
        Ok(SomSources { config, http })
    }

    pub fn config(&self) -> &SomConfig {
        &self.config
    }

    /// The marks of one observation from the configured origin. `None` for
    /// `a11y` without a tree (no element list this turn, as before); the mixed
    /// modes without a tree use the pixel source alone.
    ///
    /// # Errors
    ///
    /// [`SomError`] when the screenshot cannot be read, Tesseract fails or a service fails.
    pub async fn marks(&self, input: &SomInput<'_>) -> Result<Option<Marks>, SomError> {
        let origin = self.config.origin;
        let tree_entities = || input.tree.map(a11y::propose).unwrap_or_default();
        let entities = match origin {
            SomOrigin::A11y => return Ok(input.tree.map(|t| marks_from_tree(t, input.size))),
            SomOrigin::Oss => self.oss(input).await?,
            SomOrigin::Omni => self.omni(input).await?,
            SomOrigin::MixedOss => {
                let a11y: Vec<ProposedEntity> =
                    tree_entities().into_iter().filter(|e| a11y::drawable(&e.rect)).collect();
                let pixel = self.oss(input).await?;
                mixed::merge(a11y, pixel, input.size)
            }
            SomOrigin::MixedOmni => {
                let a11y: Vec<ProposedEntity> =
                    tree_entities().into_iter().filter(|e| a11y::drawable(&e.rect)).collect();
                let a11y = a11y::clip_to_screen(a11y, input.size);
                let pixel = self.omni(input).await?;
                let mut merged = mixed::merge(a11y, pixel, input.size);
                mixed::retype_a11y(&mut merged);
                merged
            }
        };
        Ok(Some(number(origin, entities, input.size)))
    }

    /// Upstream's `ScreenParser` pipeline: DOM, then the detector, then OCR.
    async fn oss(&self, input: &SomInput<'_>) -> Result<Vec<ProposedEntity>, SomError> {
        let shot = Screenshot::read(input.screenshot, input.size);
        let url = self.config.detector_url.as_deref().unwrap_or_default();
        let params = detector::DetectorParams::default();
        // The services are sent the screenshot's bytes as the guest sent them (no re-encoding).
        let (detected, words) = tokio::join!(
            detector::detect_all(&self.http, url, &input.screenshot.encoded, shot.dims, &params),
            ocr::recognise(&self.config.tesseract, &input.screenshot.pixels, self.config.timeout),
        );
        let mut entities = input.dom.to_vec();
        entities.extend(shot.to_screen(detected?));
        entities.extend(shot.to_screen(words?));
        Ok(entities)
    }

    async fn omni(&self, input: &SomInput<'_>) -> Result<Vec<ProposedEntity>, SomError> {
        let shot = Screenshot::read(input.screenshot, input.size);
        let url = self.config.omniparser_url.as_deref().unwrap_or_default();
        Ok(shot.to_screen(omni::parse(&self.http, url, &input.screenshot.encoded, shot.dims).await?))
    }
}

/// The screenshot's pixel size against the screen's, for boxes found in its pixels.
struct Screenshot {
    dims: (u32, u32),
    screen: (u32, u32),
}

impl Screenshot {
    fn read(frame: &arena_client::frame::Frame, screen: (u32, u32)) -> Screenshot {
        Screenshot { dims: frame.size(), screen }
    }

    /// Boxes in screenshot pixels moved to screen pixels (unchanged when the two agree, as upstream's always do).
    fn to_screen(&self, mut entities: Vec<ProposedEntity>) -> Vec<ProposedEntity> {
        if self.dims == self.screen || self.dims.0 == 0 || self.dims.1 == 0 {
            return entities;
        }
        let sx = f64::from(self.screen.0) / f64::from(self.dims.0);
        let sy = f64::from(self.screen.1) / f64::from(self.dims.1);
        let s = |v: i32, k: f64| (f64::from(v) * k).round() as i32;
        for e in &mut entities {
            let r = e.rect;
            e.rect = Rect::new(s(r.x, sx), s(r.y, sy), s(r.width, sx), s(r.height, sy));
        }
        entities
    }
}

#[cfg(test)]
mod tests;
