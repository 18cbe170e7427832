//! The checks on serve options that are stored to be passed on later (by the service,
//! the logon task and its launcher): parsed as the server parses them, and refused
//! when a stored command line would leak a secret or could never be reached.

use clap::Parser as _;

use crate::config::ServerConfig;
use crate::error::ServiceCliError;

/// Checks the serve options a service or logon task will pass to `arena-guest`, by
/// parsing them as the server will, and returns the configuration they give.
///
/// Beyond what the server itself checks, this refuses `--worker` (the supervisor adds
/// it), `--token` (a command line stored in the service or task is readable by every
/// local user: use `--token-file`) and port 0 (nobody could find the server).
///
/// # Errors
///
/// [`ServiceCliError::InvalidServeOptions`] saying what is wrong.
pub fn validate_serve_args(serve_args: &[String]) -> Result<ServerConfig, ServiceCliError> {
    let invalid = |why: String| Err(ServiceCliError::InvalidServeOptions(why));
    for arg in serve_args {
        let flag = arg.split_once('=').map_or(arg.as_str(), |(flag, _)| flag);
        match flag {
            "--worker" => return invalid("--worker is added by the supervisor; leave it out".into()),
            "--token" => {
                return invalid(
                    "--token would be stored in a command line every local user can read; use --token-file".into(),
                )
            }
            _ => {}
        }
    }
    let argv = std::iter::once("arena-guest").chain(serve_args.iter().map(String::as_str));
    let config = ServerConfig::try_parse_from(argv).map_err(|err| {
        // clap's rendering ends with a usage hint over several lines; the first line says it all.
        let text = err.to_string();
        ServiceCliError::InvalidServeOptions(text.lines().next().unwrap_or("").trim_start_matches("error: ").to_owned())
    })?;
    if config.port == 0 {
        return invalid("--port 0 picks a random port nobody could find; give a fixed port".into());
    }
    Ok(config)
}

/// The serve options the logon task's launcher was started with (all its arguments:
/// it has no options of its own), checked as [`validate_serve_args`] checks them.
///
/// # Errors
///
/// [`ServiceCliError::InvalidServeOptions`] for an argument that is not Unicode or
/// options the server would refuse.
pub fn launcher_serve_args(args: impl IntoIterator<Item = std::ffi::OsString>) -> Result<Vec<String>, ServiceCliError> {
    let args = args
        .into_iter()
        .map(|arg| {
            arg.into_string().map_err(|arg| {
                ServiceCliError::InvalidServeOptions(format!("the argument {arg:?} is not valid Unicode"))
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    validate_serve_args(&args)?;
    Ok(args)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn strings(words: &[&str]) -> Vec<String> {
        words.iter().map(|s| (*s).to_owned()).collect()
    }

    fn check_invalid(args: &[&str], expected: &str) {
        match validate_serve_args(&strings(args)) {
            Err(ServiceCliError::InvalidServeOptions(why)) => assert!(why.contains(expected), "{args:?}: {why}"),
            other => panic!("{args:?} gave {other:?}"),
        }
    }

    #[test]
    fn serve_options_are_checked_before_they_are_stored() {
        let config = validate_serve_args(&strings(&["--port", "5005", "--backend", "stub"])).unwrap();
        assert_eq!(config.port, 5005);
        check_invalid(&["--port", "5005", "--worker"], "--worker");
        check_invalid(&["--token", "0123456789abcdef0123"], "--token-file");
        check_invalid(&["--token=0123456789abcdef0123"], "--token-file");
        check_invalid(&["--port", "0"], "--port 0");
        check_invalid(&["--port", "notaport"], "notaport");
        check_invalid(&["--no-such-flag"], "--no-such-flag");
        let err = validate_serve_args(&strings(&["--port", "0"])).unwrap_err();
        assert_eq!(err.exit_code(), 2);
        assert_eq!(ServiceCliError::OnlyOnWindows("service").exit_code(), 2);
    }

    #[test]
    fn the_launcher_takes_its_whole_command_line_as_serve_options() {
        let args = ["--port", "5000", "--token-file", r"C:\My Token\t.txt", "--backend", "stub"];
        let os = |words: &[&str]| words.iter().map(std::ffi::OsString::from).collect::<Vec<_>>();
        assert_eq!(launcher_serve_args(os(&args)).unwrap(), strings(&args));
        assert_eq!(launcher_serve_args(Vec::new()).unwrap(), Vec::<String>::new());
        // Checked as the service's and the task's serve options are, before anything starts.
        for (bad, said) in [(&["--port", "5000", "--worker"][..], "--worker"), (&["--port", "0"][..], "--port 0")] {
            match launcher_serve_args(os(bad)) {
                Err(ServiceCliError::InvalidServeOptions(why)) => assert!(why.contains(said), "{bad:?}: {why}"),
                other => panic!("{bad:?} gave {other:?}"),
            }
        }
    }

    #[cfg(unix)]
    #[test]
    fn a_launcher_argument_that_is_not_unicode_is_named() {
        use std::os::unix::ffi::OsStringExt as _;
        let bad = std::ffi::OsString::from_vec(b"--port\xff".to_vec());
        let err = launcher_serve_args([bad]).unwrap_err();
        assert!(
            matches!(&err, ServiceCliError::InvalidServeOptions(why) if why.contains("not valid Unicode")),
            "{err}"
        );
        assert_eq!(err.exit_code(), 2);
    }
}
