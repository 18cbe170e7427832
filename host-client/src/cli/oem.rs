//! `arena prep`: stage an OEM folder for a new Windows image, verify a staged
//! folder against its manifest, and wait for a prepared VM's guest to be healthy.
//!
//! The work is in [`arena_vm::oem`]; this module only turns arguments into its
//! options and its results into lines on stdout.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use clap::{Args, Subcommand};

use arena_vm::oem::{self, component_name, StageOptions, WaitEvent};

use super::{emit, parse_seconds, Connection};

/// Arguments of `arena prep`.
#[derive(Debug, Clone, Args)]
pub struct PrepArgs {
    #[command(subcommand)]
    pub command: PrepCommand,
}

/// `arena prep ...`.
#[derive(Debug, Clone, Subcommand)]
pub enum PrepCommand {
    /// Fill DIR with arena-guest.exe, the setup scripts, a fresh token and a manifest,
    /// ready to mount as dockur/windows's /oem.
    Stage {
        /// The folder to fill (refused when it holds files, unless --force).
        #[arg(long, value_name = "DIR")]
        out: PathBuf,
        /// The Windows guest exe [default: the cross build under target/windows, release, else debug].
        #[arg(long, value_name = "PATH")]
        exe: Option<PathBuf>,
        /// The folder of setup scripts to copy.
        #[arg(long, value_name = "DIR", default_value = "setup-scripts")]
        scripts: PathBuf,
        /// Where the host's copy of the token goes [default: ~/.config/arena/token].
        #[arg(long, value_name = "PATH")]
        token_out: Option<PathBuf>,
        /// Stage into a folder that already holds files (files not staged are left alone).
        #[arg(long)]
        force: bool,
    },
    /// Re-hash a staged folder's files against its manifest.json.
    Verify {
        /// The staged folder.
        dir: PathBuf,
    },
    /// Wait for a prepared VM's guest (--guest URL) to become healthy, component by
    /// component; with --token or --token-file also check that the token is accepted.
    Wait {
        /// Give up after SECONDS and say what is missing.
        #[arg(long, value_parser = parse_seconds, value_name = "SECONDS", default_value = "900")]
        timeout: Duration,
        /// Poll every SECONDS.
        #[arg(long, value_parser = parse_seconds, value_name = "SECONDS", default_value = "2")]
        poll: Duration,
    },
}

/// Runs `arena prep ...`.
///
/// # Errors
///
/// Whatever failed, naming the file or the guest; a failed verification or a
/// guest that is not healthy in time is an error too, so the exit code says it.
pub async fn run(conn: &Connection, args: PrepArgs) -> anyhow::Result<ExitCode> {
    match args.command {
        PrepCommand::Stage { out, exe, scripts, token_out, force } => {
            let token_out = token_out.or_else(oem::default_token_out);
            let workspace = std::env::current_dir().unwrap_or_else(|_| PathBuf::from("."));
            let staged = oem::stage(&StageOptions { out: out.clone(), exe, scripts, token_out, force, workspace })?;
            let m = &staged.manifest;
            let mut text = format!("staged {} file(s) into {}\n", m.files.len(), out.display());
            text.push_str(&format!("  exe:      {}\n", m.exe_source));
            text.push_str(&format!(
                "  version:  arena {}{}\n",
                m.arena_version,
                match (&m.git_commit, m.git_dirty) {
                    (Some(commit), Some(true)) => format!(", commit {commit} (with uncommitted changes)"),
                    (Some(commit), _) => format!(", commit {commit}"),
                    (None, _) => String::new(),
                }
            ));
            text.push_str(&format!("  token:    {}\n", staged.token_path.display()));
            if let Some(host) = &staged.token_out {
                text.push_str(&format!("  host token: {} (use --token-file {0})\n", host.display()));
            }
            text.push_str("next: mount the folder as /oem of a dockur/windows container (setup-scripts/README.md), then `arena prep wait --guest URL`\n");
            emit(&text)?;
            Ok(ExitCode::SUCCESS)
        }
        PrepCommand::Verify { dir } => {
            let report = oem::verify(&dir)?;
            let mut text = String::new();
            for m in &report.mismatched {
                text.push_str(&format!(
                    "CHANGED  {} (expected sha256 {} {} bytes, found {} {} bytes)\n",
                    m.path, m.expected.sha256, m.expected.size, m.actual.sha256, m.actual.size
                ));
            }
            for path in &report.missing {
                text.push_str(&format!("MISSING  {path}\n"));
            }
            for path in &report.extra {
                text.push_str(&format!("extra    {path} (not in the manifest)\n"));
            }
            text.push_str(&format!(
                "{}: {} matched, {} changed, {} missing, {} extra\n",
                dir.display(),
                report.matched.len(),
                report.mismatched.len(),
                report.missing.len(),
                report.extra.len()
            ));
            emit(&text)?;
            if !report.is_ok() {
                anyhow::bail!("{} does not match its manifest", dir.display());
            }
            Ok(ExitCode::SUCCESS)
        }
        PrepCommand::Wait { timeout, poll } => {
            let client = conn.client()?;
            let started = std::time::Instant::now();
            let result = oem::wait_healthy(&client, timeout, poll, |event| {
                let at = started.elapsed().as_secs_f64();
                let line = match event {
                    WaitEvent::Unreachable { error } => format!("[{at:6.1}s] not reachable yet: {error}\n"),
                    WaitEvent::Reachable { report } => format!(
                        "[{at:6.1}s] guest answers: version {}, backend {}{}{}\n",
                        report.version,
                        report.backend,
                        report.session_id.map(|s| format!(", session {s}")).unwrap_or_default(),
                        if report.auth_required { ", token required" } else { ", NO token required" }
                    ),
                    WaitEvent::Up { component } => {
                        format!("[{at:6.1}s] up    {:<14} {}\n", component_name(component.component), component.detail)
                    }
                    WaitEvent::Down { component } => {
                        format!("[{at:6.1}s] DOWN  {:<14} {}\n", component_name(component.component), component.detail)
                    }
                    WaitEvent::TokenAccepted => format!("[{at:6.1}s] token accepted\n"),
                };
                let _ = emit(&line);
            })
            .await;
            match result {
                Ok(_) => {
                    emit(&format!("guest {} is ready\n", client.base_url()))?;
                    Ok(ExitCode::SUCCESS)
                }
                Err(err) => Err(err.into()),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    use super::super::{Cli, Command};
    use super::*;

    #[test]
    fn prep_wait_takes_the_global_guest_and_its_own_timeout() {
        let cli =
            Cli::try_parse_from(["arena", "prep", "wait", "--guest", "http://20.20.20.21:5000", "--timeout", "60"])
                .unwrap();
        assert_eq!(cli.connection.guest_url(), "http://20.20.20.21:5000");
        let Command::Prep(PrepArgs { command: PrepCommand::Wait { timeout, .. } }) = cli.command else {
            panic!("not prep wait")
        };
        assert_eq!(timeout, Duration::from_secs(60));
    }

    #[test]
    fn prep_stage_needs_an_out_folder() {
        assert!(Cli::try_parse_from(["arena", "prep", "stage"]).is_err());
        let cli = Cli::try_parse_from(["arena", "prep", "stage", "--out", "/tmp/oem", "--force"]).unwrap();
        let Command::Prep(PrepArgs { command: PrepCommand::Stage { out, scripts, force, .. } }) = cli.command else {
            panic!("not stage")
        };
        assert_eq!(out, PathBuf::from("/tmp/oem"));
        assert_eq!(scripts, PathBuf::from("setup-scripts"));
        assert!(force);
    }
}
