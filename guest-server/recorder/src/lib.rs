//! The input recorder (`arena-input-recorder`): a window that writes every input
//! message it receives as JSON lines ([`arena_shared::input_log::Recorded`]), the
//! witness the host's input check (`arena-inputcheck`) compares
//! with what each case of its catalogue should deliver.
//!
//! # Layout
//!
//! - this file: the command line ([`Options`]).
//! - [`decode`]: what a message's `wParam`/`lParam` say (scan code, extended and repeat
//!   bits, coordinates, wheel deltas, modifier flags, UTF-16 units joined), platform-neutral
//!   and tested everywhere.
//! - [`windows`]: the window, its class (`CS_DBLCLKS`) and message loop, `cfg(windows)`
//!   FFI glue; elsewhere [`windows::run`] says the recorder is Windows-only.

#![deny(unsafe_code)]

pub mod decode;
// The one module with `unsafe`: the Win32 calls of the window and its message loop.
#[allow(unsafe_code)]
pub mod windows;

/// How to call the recorder.
pub const USAGE: &str = "usage: arena-input-recorder LOG [--x N] [--y N] [--width N] [--height N] [--title TEXT]";

/// The title of the recorder's window, by which the host finds it.
pub const TITLE: &str = "Arena input recorder";

/// The command line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Options {
    /// The JSON-lines file written (created, or emptied when it exists).
    pub log: std::path::PathBuf,
    /// The window's place and size in screen pixels; `None`: the primary screen's.
    pub x: Option<i32>,
    pub y: Option<i32>,
    pub width: Option<i32>,
    pub height: Option<i32>,
    pub title: String,
}

impl Options {
    /// Reads the arguments after the program name.
    ///
    /// # Errors
    ///
    /// A message naming a missing log, an unknown option, or a value that is not a
    /// number (sizes must be 1 to 16384).
    pub fn parse(args: impl IntoIterator<Item = String>) -> Result<Options, String> {
        let mut args = args.into_iter();
        let mut options = Options {
            log: std::path::PathBuf::new(),
            x: None,
            y: None,
            width: None,
            height: None,
            title: TITLE.to_owned(),
        };
        let mut log = None;
        while let Some(arg) = args.next() {
            let mut value = |name: &str| args.next().ok_or_else(|| format!("{name} needs a value"));
            let number = |name: &str, text: String| {
                text.parse::<i32>().map_err(|_| format!("{name} must be a whole number, got {text:?}"))
            };
            match arg.as_str() {
                "--x" => options.x = Some(number("--x", value("--x")?)?),
                "--y" => options.y = Some(number("--y", value("--y")?)?),
                "--width" | "--height" => {
                    let n = number(&arg, value(&arg)?)?;
                    if !(1..=16384).contains(&n) {
                        return Err(format!("{arg} must be 1 to 16384, got {n}"));
                    }
                    if arg == "--width" {
                        options.width = Some(n);
                    } else {
                        options.height = Some(n);
                    }
                }
                "--title" => options.title = value("--title")?,
                other if other.starts_with("--") => return Err(format!("unknown option {other}")),
                other if log.is_none() => log = Some(std::path::PathBuf::from(other)),
                other => return Err(format!("one log file only, got a second: {other}")),
            }
        }
        options.log = log.ok_or("the log file is missing")?;
        Ok(options)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(args: &[&str]) -> Result<Options, String> {
        Options::parse(args.iter().map(|s| (*s).to_owned()))
    }

    #[test]
    fn the_command_line_reads_and_refuses_clearly() {
        let o = parse(&["C:\\log.jsonl", "--x", "10", "--width", "800"]).unwrap();
        assert_eq!(o.log, std::path::PathBuf::from("C:\\log.jsonl"));
        assert_eq!((o.x, o.y, o.width, o.height), (Some(10), None, Some(800), None));
        assert_eq!(o.title, TITLE);
        assert_eq!(parse(&[]).unwrap_err(), "the log file is missing");
        assert!(parse(&["l", "--x"]).unwrap_err().contains("--x needs a value"));
        assert!(parse(&["l", "--x", "ten"]).unwrap_err().contains("whole number"));
        assert!(parse(&["l", "--width", "0"]).unwrap_err().contains("1 to 16384"));
        assert!(parse(&["l", "--bogus"]).unwrap_err().contains("unknown option --bogus"));
        assert!(parse(&["l", "m"]).unwrap_err().contains("second"));
    }
}
