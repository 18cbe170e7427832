//! Which tool form and screenshot size each computer-use model gets when the run
//! does not say (`--computer-tool`, `--max-image-side`): one table per vendor,
//! each row citing where its facts come from. A model no row names gets the
//! vendor's newest form, the newest published image limits, and a notice.
//!
//! Sources, as read on 2026-11-28:
//!
//! - `ANTHROPIC-TOOLS`: Anthropic's computer-use tool page
//!   (<https://platform.claude.com/docs/en/agents-and-tools/tool-use/computer-use-tool>):
//!   beta header `computer-use-2025-11-24` (tool `computer_20251124`) for Claude Opus
//!   4.7, Opus 4.6, Sonnet 4.6 and Opus 4.5; `computer-use-2025-01-24` (tool
//!   `computer_20250124`) for Sonnet 4.5, Haiku 4.5, Opus 4.1, Sonnet 4 and Opus 4.
//! - `ANTHROPIC-IMAGES`: the same page and Anthropic's vision guide: images up to 1568
//!   pixels on the long edge and about 1.15 megapixels before Claude Opus 4.7, up to
//!   2576 pixels and about 3.75 megapixels from Opus 4.7 on (the screenshot sizes the
//!   tool page recommends for the former are kept: XGA, WXGA or FWXGA by aspect ratio).
//! - `ANTHROPIC-SDK`: the `anthropic` Python SDK 2.14.0, `types/computer_toolset_20260801_param.py`
//!   (the toolset is a type of the generally available Messages API, needing no beta
//!   header, and no model list names it): the newest form, for models no row names.
//! - `OPENAI-AGENTS`: the `openai-agents` SDK's model guide ("ComputerTool model
//!   selection"): explicit `gpt-5.4` requests use the GA `computer` tool and
//!   `computer-use-preview` keeps the `computer_use_preview` payload; the `openai` SDK
//!   3.57.0 types both (`types/responses/computer_tool_param.py`,
//!   `computer_use_preview_tool_param.py`).
//! - `OPENAI-IMAGES`: OpenAI's vision guide: at high detail an image is fitted within a
//!   2048 x 2048 square; the computer-use guide's preview examples declare a 1024 x 768 display.

use arena_actionspace::ActionSpace;

/// A computer-use tool form: what a request declares and how answers come.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Form {
    /// Anthropic's `computer_20250124` tool.
    Computer20250124,
    /// Anthropic's `computer_20251124` tool.
    Computer20251124,
    /// Anthropic's `computer_toolset_20260801` toolset.
    ComputerToolset20260801,
    /// OpenAI's `computer_use_preview` tool.
    ComputerUsePreview,
    /// OpenAI's GA `computer` tool.
    Computer,
}

impl Form {
    /// Every form, as `--computer-tool` names them.
    pub const ALL: [Form; 5] = [
        Form::Computer20250124,
        Form::Computer20251124,
        Form::ComputerToolset20260801,
        Form::ComputerUsePreview,
        Form::Computer,
    ];

    /// The name `--computer-tool` takes and results record.
    pub fn name(self) -> &'static str {
        match self {
            Form::Computer20250124 => "computer_20250124",
            Form::Computer20251124 => "computer_20251124",
            Form::ComputerToolset20260801 => "computer_toolset_20260801",
            Form::ComputerUsePreview => "computer_use_preview",
            Form::Computer => "computer",
        }
    }

    /// The vendor whose API the form belongs to.
    pub fn vendor(self) -> Vendor {
        match self {
            Form::ComputerUsePreview | Form::Computer => Vendor::OpenAi,
            _ => Vendor::Anthropic,
        }
    }

    /// The action space the form's actions are read in.
    pub fn action_space(self) -> ActionSpace {
        match self {
            Form::Computer20250124 => ActionSpace::Anthropic20250124,
            Form::Computer20251124 => ActionSpace::Anthropic20251124,
            Form::ComputerToolset20260801 => ActionSpace::AnthropicToolset20260801,
            Form::ComputerUsePreview | Form::Computer => ActionSpace::OpenAi,
        }
    }

    /// The `anthropic-beta` header the form needs, if any.
    pub fn beta_header(self) -> Option<&'static str> {
        match self {
            Form::Computer20250124 => Some("computer-use-2025-01-24"),
            Form::Computer20251124 => Some("computer-use-2025-11-24"),
            _ => None,
        }
    }
}

impl std::str::FromStr for Form {
    type Err = String;

    fn from_str(s: &str) -> Result<Form, String> {
        Form::ALL.into_iter().find(|f| f.name() == s).ok_or_else(|| {
            let names: Vec<&str> = Form::ALL.iter().map(|f| f.name()).collect();
            format!("unknown computer tool {s:?} (expected one of {})", names.join(", "))
        })
    }
}

/// Whose API.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Vendor {
    Anthropic,
    OpenAi,
}

/// The largest screenshot a model takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ImageLimit {
    /// Anthropic's recommended sizes for models limited to 1568 px and 1.15 MP
    /// ([`recommended_size`]).
    AnthropicRecommended,
    /// At most `side` pixels on the long edge and `pixels` in all; a screen that fits is sent as it is.
    Within { side: u32, pixels: u64 },
    /// A declared display of at most this size (OpenAI's preview tool).
    Display(u32, u32),
}

impl ImageLimit {
    /// The size a `screen` is sent at.
    pub fn size_for(self, screen: (u32, u32)) -> (u32, u32) {
        match self {
            ImageLimit::AnthropicRecommended => recommended_size(screen),
            ImageLimit::Within { side, pixels } => within(screen, side, pixels),
            ImageLimit::Display(w, h) => super::fit_within(screen, (w, h)),
        }
    }

    /// How results record it.
    pub fn describe(self) -> String {
        match self {
            ImageLimit::AnthropicRecommended => "recommended-size".into(),
            ImageLimit::Within { side, pixels } => format!("within-{side}px-{pixels}"),
            ImageLimit::Display(w, h) => format!("within-{w}x{h}"),
        }
    }
}

/// `screen` scaled down to at most `side` on its long edge and `pixels` in all.
pub fn within(screen: (u32, u32), side: u32, pixels: u64) -> (u32, u32) {
    let (w, h) = (f64::from(screen.0.max(1)), f64::from(screen.1.max(1)));
    let scale = (f64::from(side) / w.max(h)).min((pixels as f64 / (w * h)).sqrt());
    super::scaled_size(screen, scale)
}

/// One row: models whose name matches one of `models` get `form` and `image`.
#[derive(Debug, Clone, Copy)]
pub struct Row {
    /// Model names (matched whole: a date such as `-20250514` or `-2025-03-11`, `@`, `-v`,
    /// `:`, `-latest` or the end may follow).
    pub models: &'static [&'static str],
    pub form: Form,
    pub image: ImageLimit,
    /// The source's key in the module documentation.
    pub source: &'static str,
}

const OPUS_4_7_IMAGES: ImageLimit = ImageLimit::Within { side: 2576, pixels: 3_750_000 };

/// Anthropic's models, most specific first.
pub const ANTHROPIC: &[Row] = &[
    Row {
        models: &["claude-opus-4-7"],
        form: Form::Computer20251124,
        image: OPUS_4_7_IMAGES,
        source: "ANTHROPIC-TOOLS, ANTHROPIC-IMAGES",
    },
    Row {
        models: &["claude-opus-4-6", "claude-sonnet-4-6", "claude-opus-4-5"],
        form: Form::Computer20251124,
        image: ImageLimit::AnthropicRecommended,
        source: "ANTHROPIC-TOOLS, ANTHROPIC-IMAGES",
    },
    Row {
        models: &[
            "claude-sonnet-4-5",
            "claude-haiku-4-5",
            "claude-opus-4-1",
            "claude-sonnet-4",
            "claude-opus-4",
            "claude-3-7-sonnet",
        ],
        form: Form::Computer20250124,
        image: ImageLimit::AnthropicRecommended,
        source: "ANTHROPIC-TOOLS, ANTHROPIC-IMAGES",
    },
];

/// OpenAI's models.
pub const OPENAI: &[Row] = &[
    Row {
        models: &["computer-use-preview"],
        form: Form::ComputerUsePreview,
        image: ImageLimit::Display(1024, 768),
        source: "OPENAI-AGENTS, OPENAI-IMAGES",
    },
    Row {
        models: &["gpt-5.4", "gpt-5.5", "gpt-5.6"],
        form: Form::Computer,
        image: ImageLimit::Within { side: 2048, pixels: 2048 * 2048 },
        source: "OPENAI-AGENTS, OPENAI-IMAGES",
    },
];

/// What a model gets when the run does not say.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Choice {
    pub form: Form,
    pub image: ImageLimit,
    /// For a model no row names: the one line to tell the user.
    pub notice: Option<String>,
}

/// Whether `model` (any case, with a provider's prefix such as `anthropic/` or
/// `us.anthropic.`) is `name`, or `name` followed by a version suffix.
pub fn names(model: &str, name: &str) -> bool {
    let model = model.to_lowercase();
    let Some(start) = model.find(name) else { return false };
    if start > 0 && !model[..start].ends_with(['/', '.']) {
        return false;
    }
    let rest = &model[start + name.len()..];
    // A date: `-20250514` or `-2025-03-11`.
    let dated = rest.strip_prefix("-20").is_some_and(|r| r.len() >= 2 && r[..2].chars().all(|c| c.is_ascii_digit()));
    rest.is_empty() || dated || rest.starts_with(['@', ':']) || rest.starts_with("-v") || rest.starts_with("-latest")
}

/// The row for `model` of `vendor`, or the newest form with a notice.
pub fn choose(vendor: Vendor, model: &str) -> Choice {
    let table = match vendor {
        Vendor::Anthropic => ANTHROPIC,
        Vendor::OpenAi => OPENAI,
    };
    if let Some(row) = table.iter().find(|row| row.models.iter().any(|name| names(model, name))) {
        return Choice { form: row.form, image: row.image, notice: None };
    }
    let (form, image) = match vendor {
        Vendor::Anthropic => (Form::ComputerToolset20260801, OPUS_4_7_IMAGES),
        Vendor::OpenAi => (Form::Computer, ImageLimit::Within { side: 2048, pixels: 2048 * 2048 }),
    };
    Choice {
        form,
        image,
        notice: Some(format!(
            "model {model:?} is not in the computer-tool table (docs/agents.md): using the newest form, {}, and screenshots {}; say --computer-tool and --max-image-side to choose",
            form.name(),
            image.describe()
        )),
    }
}

/// The screenshot size the computer-use documentation recommends for a screen:
/// the first of XGA (1024×768), WXGA (1280×800) and FWXGA (1366×768) whose aspect
/// ratio is within 0.02 of the screen's and which is smaller; else the screen
/// scaled to fit the API's image limits (1568 pixels on the long side, about 1.15
/// megapixels), or left as it is when it fits.
pub fn recommended_size(screen: (u32, u32)) -> (u32, u32) {
    const TARGETS: [(u32, u32); 3] = [(1024, 768), (1280, 800), (1366, 768)];
    let (w, h) = (screen.0.max(1), screen.1.max(1));
    let ratio = f64::from(w) / f64::from(h);
    if let Some(&t) = TARGETS.iter().find(|(tw, th)| (f64::from(*tw) / f64::from(*th) - ratio).abs() < 0.02 && *tw < w)
    {
        return t;
    }
    let long = f64::from(w.max(h));
    super::scaled_size((w, h), (1568.0 / long).min((1_150_000.0 / (f64::from(w) * f64::from(h))).sqrt()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_anthropic_row_chooses_its_tool_and_image_limit() {
        let cases = [
            ("claude-opus-4-7", Form::Computer20251124, (1440, 900)),
            ("anthropic/claude-opus-4-7", Form::Computer20251124, (1440, 900)),
            ("claude-opus-4-6", Form::Computer20251124, (1280, 800)),
            ("claude-sonnet-4-6", Form::Computer20251124, (1280, 800)),
            ("claude-opus-4-5-20251101", Form::Computer20251124, (1280, 800)),
            ("claude-sonnet-4-5-20250929", Form::Computer20250124, (1280, 800)),
            ("claude-haiku-4-5", Form::Computer20250124, (1280, 800)),
            ("claude-opus-4-1", Form::Computer20250124, (1280, 800)),
            ("claude-sonnet-4-20250514", Form::Computer20250124, (1280, 800)),
            ("claude-opus-4@20250514", Form::Computer20250124, (1280, 800)),
            ("us.anthropic.claude-3-7-sonnet-20250219-v1:0", Form::Computer20250124, (1280, 800)),
        ];
        for (model, form, size) in cases {
            let choice = choose(Vendor::Anthropic, model);
            assert_eq!((choice.form, choice.image.size_for((1440, 900))), (form, size), "{model}");
            assert_eq!(choice.notice, None, "{model}");
        }
        for row in ANTHROPIC {
            assert_eq!(row.form.vendor(), Vendor::Anthropic);
            assert!(row.source.contains("ANTHROPIC-TOOLS"));
        }
    }

    #[test]
    fn each_openai_row_chooses_its_tool_and_image_limit() {
        let preview = choose(Vendor::OpenAi, "computer-use-preview-2025-03-11");
        assert_eq!((preview.form, preview.image.size_for((1440, 900))), (Form::ComputerUsePreview, (1024, 640)));
        for model in ["gpt-5.4", "gpt-5.4-2026-03-05", "gpt-5.5", "gpt-5.6"] {
            let choice = choose(Vendor::OpenAi, model);
            assert_eq!((choice.form, choice.image.size_for((1440, 900))), (Form::Computer, (1440, 900)), "{model}");
            assert_eq!(choice.image.size_for((3840, 2160)), (2048, 1152));
        }
        for row in OPENAI {
            assert_eq!(row.form.vendor(), Vendor::OpenAi);
        }
    }

    #[test]
    fn an_unknown_model_gets_the_newest_form_and_a_notice() {
        let claude = choose(Vendor::Anthropic, "claude-opus-5");
        assert_eq!(claude.form, Form::ComputerToolset20260801);
        assert!(claude
            .notice
            .as_deref()
            .is_some_and(|n| n.contains("claude-opus-5") && n.contains("computer_toolset_20260801")));
        // A newer minor version is not an older row's model.
        assert_eq!(choose(Vendor::Anthropic, "claude-opus-4-8").form, Form::ComputerToolset20260801);
        assert_eq!(choose(Vendor::Anthropic, "claude-sonnet-4-7").form, Form::ComputerToolset20260801);
        assert_eq!(choose(Vendor::OpenAi, "gpt-6").form, Form::Computer);
        assert!(!names("xclaude-opus-4-7", "claude-opus-4-7"));
        assert!(!names("gpt-5.45", "gpt-5.4"));
    }

    #[test]
    fn forms_parse_by_name_and_belong_to_one_vendor() {
        for form in Form::ALL {
            assert_eq!(form.name().parse::<Form>(), Ok(form));
        }
        assert!("computer_2099".parse::<Form>().unwrap_err().contains("computer_toolset_20260801"));
        assert_eq!(Form::ComputerToolset20260801.beta_header(), None);
        assert_eq!(Form::Computer20251124.beta_header(), Some("computer-use-2025-11-24"));
    }
}
