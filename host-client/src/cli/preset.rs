//! `--preset` and how a run stands to upstream's: the rows of the WAA paper's
//! Navi table a run can reproduce ([`Preset`]), upstream's default run
//! ([`upstream_default`]) and what a run that is no preset changes from it
//! ([`differences_from_upstream`]), recorded in the results as named options.

use anyhow::bail;

use super::emit;
use super::run_args::{A11yBackendArg, NaviStyleArg, PausesArg, Preset, RefusalsArg, RunArgs};
use arena_agents::factory::AgentKind;
use arena_som::SomOrigin;

/// Upstream's default run, the reference a non-preset Navi run is compared with:
/// `run.py` and `start_client.sh` at 6d39ed88 (`--som_origin oss`, `--a11y_backend uia`,
/// `--temperature 1.0`, `--max_steps 15`, `--sleep_after_execution 3`), Navi's
/// `max_tokens` of 4096 (its planner's request), and the prompts of the checkout.
pub mod upstream_default {
    use super::SomOrigin;
    pub const SOM_ORIGIN: SomOrigin = SomOrigin::Oss;
    pub const A11Y_BACKEND: &str = "uia";
    pub const TEMPERATURE: f64 = 1.0;
    pub const MAX_TOKENS: u32 = 4096;
    pub const MAX_STEPS: u32 = crate::episode::DEFAULT_MAX_STEPS;
    pub const SLEEP_AFTER_SECONDS: f64 = 3.0;
}

impl Preset {
    /// `paper-mixed-omni`, ...
    pub fn name(self) -> &'static str {
        match self {
            Preset::PaperMixedOmni => "paper-mixed-omni",
            Preset::PaperOmni => "paper-omni",
            Preset::PaperOss => "paper-oss",
            Preset::PaperA11yUia => "paper-a11y-uia",
            Preset::PaperA11yWin32 => "paper-a11y-win32",
            Preset::PaperMixedOss => "paper-mixed-oss",
        }
    }

    /// The row's Set-of-Marks origin and accessibility backend.
    pub fn row(self) -> (SomOrigin, A11yBackendArg) {
        match self {
            Preset::PaperMixedOmni => (SomOrigin::MixedOmni, A11yBackendArg::Uia),
            // Upstream's default backend is uia; the row does not change it.
            Preset::PaperOmni => (SomOrigin::Omni, A11yBackendArg::Uia),
            Preset::PaperOss => (SomOrigin::Oss, A11yBackendArg::Uia),
            Preset::PaperA11yUia => (SomOrigin::A11y, A11yBackendArg::Uia),
            Preset::PaperA11yWin32 => (SomOrigin::A11y, A11yBackendArg::Win32),
            Preset::PaperMixedOss => (SomOrigin::MixedOss, A11yBackendArg::Uia),
        }
    }

    /// `args` with the row's settings and upstream's model parameters, step cap and pauses.
    ///
    /// # Errors
    ///
    /// Without --waa-root (a reproduction sends upstream's own prompts), or with an agent other than Navi.
    pub fn apply(self, args: &RunArgs) -> anyhow::Result<RunArgs> {
        if args.agent != AgentKind::Navi {
            bail!("--preset {} is a Navi configuration: give --agent navi", self.name());
        }
        if args.waa_root.is_none() {
            bail!(
                "--preset {} reproduces upstream's run and needs upstream's prompts: give --waa-root (or ARENA_WAA_ROOT), a WindowsAgentArena checkout",
                self.name()
            );
        }
        let (som_origin, a11y_backend) = self.row();
        Ok(RunArgs {
            som_origin,
            a11y_backend,
            temperature: upstream_default::TEMPERATURE,
            max_tokens: upstream_default::MAX_TOKENS,
            navi_style: NaviStyleArg::Waa,
            max_steps: upstream_default::MAX_STEPS,
            sleep_after: None,
            fast: false,
            pauses: Some(PausesArg::Upstream),
            no_a11y: false,
            ..args.clone()
        })
    }
}

/// What a Navi run that is no preset changes from upstream's default run, one
/// `name=ours (upstream: theirs)` item each; empty when nothing differs.
pub fn differences_from_upstream(args: &RunArgs, fast: bool) -> Vec<String> {
    let mut out = Vec::new();
    let mut differs = |name: &str, ours: String, theirs: String| {
        if ours != theirs {
            out.push(format!("{name}={ours} (upstream: {theirs})"));
        }
    };
    differs("som_origin", args.som_origin.name().to_owned(), upstream_default::SOM_ORIGIN.name().to_owned());
    let backend = if args.a11y_backend == A11yBackendArg::Win32 { "win32" } else { "uia" };
    differs("a11y_backend", backend.to_owned(), upstream_default::A11Y_BACKEND.to_owned());
    let prompt = match (args.navi_style, &args.waa_root) {
        (NaviStyleArg::Arena, _) => "arena (this project's prompt and reply reader)",
        (NaviStyleArg::Waa, None) => "ours (no --waa-root)",
        (NaviStyleArg::Waa, Some(_)) => "the checkout's",
    };
    differs("prompt", prompt.to_owned(), "the checkout's".to_owned());
    differs("temperature", format!("{}", args.temperature), format!("{}", upstream_default::TEMPERATURE));
    differs("max_tokens", args.max_tokens.to_string(), upstream_default::MAX_TOKENS.to_string());
    differs("max_steps", args.max_steps.to_string(), upstream_default::MAX_STEPS.to_string());
    let upstream_pauses = "5 s after the reset and the setup, 3 s after each action";
    let pauses = if fast { "fast (none)" } else { upstream_pauses };
    differs("pauses", pauses.to_owned(), upstream_pauses.to_owned());
    if let Some(secs) = args.sleep_after {
        differs("sleep_after", format!("{secs}"), format!("{}", upstream_default::SLEEP_AFTER_SECONDS));
    }
    if args.no_a11y {
        differs("a11y", "off".to_owned(), "on".to_owned());
    }
    if args.refusals == RefusalsArg::Answer {
        differs("refusals", "answer".to_owned(), "unfinished".to_owned());
    }
    out
}

/// How the run stands to upstream's, as named options: `preset` for a preset,
/// else, for Navi, `differs_from_upstream` listing what differs, announced in one
/// line now (and shown by the report, which lists the options).
pub(crate) fn reproduction(args: &RunArgs, fast: bool) -> anyhow::Result<Vec<(String, String)>> {
    if let Some(preset) = args.preset {
        emit(&format!("preset {}: reproducing that row of upstream's Navi table\n", preset.name()))?;
        return Ok(vec![("preset".into(), preset.name().into())]);
    }
    if args.agent != AgentKind::Navi {
        return Ok(Vec::new());
    }
    let differences = differences_from_upstream(args, fast);
    let text = if differences.is_empty() { "none".to_owned() } else { differences.join("; ") };
    emit(&format!("not a reproduction: differs from upstream's default Navi run in {text}\n"))?;
    Ok(vec![("differs_from_upstream".into(), text)])
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    use super::*;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        run: RunArgs,
    }

    fn parse(args: &[&str]) -> Result<RunArgs, clap::Error> {
        Cli::try_parse_from(["arena", "--tasks", "t"].iter().chain(args)).map(|c| c.run)
    }

    const NAVI: [&str; 6] = ["--agent", "navi", "--llm-url", "http://127.0.0.1:9/v1", "--model", "m"];

    #[test]
    fn each_preset_sets_its_rows_origin_and_backend_and_upstreams_parameters_and_pauses() {
        let rows = [
            ("paper-mixed-omni", SomOrigin::MixedOmni, A11yBackendArg::Uia),
            ("paper-omni", SomOrigin::Omni, A11yBackendArg::Uia),
            ("paper-oss", SomOrigin::Oss, A11yBackendArg::Uia),
            ("paper-a11y-uia", SomOrigin::A11y, A11yBackendArg::Uia),
            ("paper-a11y-win32", SomOrigin::A11y, A11yBackendArg::Win32),
            ("paper-mixed-oss", SomOrigin::MixedOss, A11yBackendArg::Uia),
        ];
        for (name, origin, backend) in rows {
            let mut args = NAVI.to_vec();
            args.extend(["--preset", name, "--waa-root", "/waa", "--stub-guests", "1"]);
            let parsed = parse(&args).unwrap();
            let preset = parsed.preset.expect("a preset");
            assert_eq!(preset.name(), name);
            let applied = preset.apply(&parsed).unwrap();
            assert_eq!((applied.som_origin, applied.a11y_backend), (origin, backend), "{name}");
            assert_eq!((applied.temperature, applied.max_tokens, applied.max_steps), (1.0, 4096, 15), "{name}");
            assert_eq!(applied.navi_style, NaviStyleArg::Waa, "{name}");
            // Upstream's pauses even against stub guests, which would otherwise run fast.
            assert_eq!(applied.pauses, Some(PausesArg::Upstream), "{name}");
            // Only the prompt source and the refusal rule could still differ; neither does.
            let differences = differences_from_upstream(&applied, false);
            let allowed = ["som_origin=", "a11y_backend="];
            assert!(differences.iter().all(|d| allowed.iter().any(|a| d.starts_with(a))), "{name}: {differences:?}");

            // A preset needs the checkout's prompts and the Navi agent.
            let without_root: Vec<&str> = NAVI.iter().copied().chain(["--preset", name]).collect();
            let err = preset.apply(&parse(&without_root).unwrap()).unwrap_err().to_string();
            assert!(err.contains("--waa-root") && err.contains(name), "{err}");
            let scripted = parse(&["--preset", name, "--waa-root", "/waa"]).unwrap();
            assert!(preset.apply(&scripted).unwrap_err().to_string().contains("--agent navi"));
        }
    }

    #[test]
    fn a_preset_refuses_settings_that_would_change_its_row() {
        for extra in [["--som-origin", "oss"], ["--temperature", "0.5"], ["--max-steps", "30"], ["--pauses", "fast"]] {
            let mut args = NAVI.to_vec();
            args.extend(["--preset", "paper-oss", "--waa-root", "/waa"]);
            args.extend(extra);
            let err = parse(&args).err().unwrap_or_else(|| panic!("{extra:?} accepted"));
            assert_eq!(err.kind(), clap::error::ErrorKind::ArgumentConflict, "{extra:?}");
        }
    }

    #[test]
    fn a_default_navi_run_names_every_difference_from_upstreams_default_run() {
        let args = parse(&NAVI).unwrap();
        assert_eq!(
            differences_from_upstream(&args, true),
            [
                "som_origin=a11y (upstream: oss)",
                "prompt=ours (no --waa-root) (upstream: the checkout's)",
                "pauses=fast (none) (upstream: 5 s after the reset and the setup, 3 s after each action)",
            ]
        );
        let mut close = NAVI.to_vec();
        close.extend(["--som-origin", "oss", "--waa-root", "/waa", "--refusals", "answer", "--a11y-backend", "win32"]);
        assert_eq!(
            differences_from_upstream(&parse(&close).unwrap(), false),
            ["a11y_backend=win32 (upstream: uia)", "refusals=answer (upstream: unfinished)"]
        );
    }
}
