//! Programs in the stub: the table of known programs that only open a window,
//! command-line parsing to recognise them, and, only under `--stub-host-exec`, real
//! host processes for everything else; without it everything else is refused
//! ([`refusal`]), so agent code on the stub starts nothing on the host.
//!
//! Real processes run on the host (`sh -c` on Unix, `cmd /c` on Windows); they are not
//! sandboxed and see the host file system, not the stub's guest paths.

use std::collections::BTreeMap;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use super::scenario::ScenarioProgram;
use crate::desktop::windows::std_child::{isolate, kill_tree, shell_command};
use crate::desktop::{CommandSpec, DesktopError, DesktopResult, ExecLimits, ExecOutput};

/// A program that the stub "runs" by opening a window.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Program {
    pub(crate) title: String,
    pub(crate) class_name: String,
    pub(crate) process_name: String,
    /// The initial document, for programs whose window holds text.
    pub(crate) text: Option<String>,
    /// The suffix of `"<file> - <app_name>"` window titles.
    pub(crate) app_name: String,
}

impl Program {
    pub(crate) fn from_scenario(name: &str, p: &ScenarioProgram) -> Program {
        let app_name = p.app_name.clone().unwrap_or_else(|| match p.title.rsplit_once(" - ") {
            Some((_, app)) => app.to_owned(),
            None => p.title.clone(),
        });
        Program {
            title: p.title.clone(),
            class_name: p.class_name.clone(),
            process_name: p.process_name.clone().unwrap_or_else(|| format!("{name}.exe")),
            text: p.text.clone(),
            app_name,
        }
    }
}

/// A built-in program: name, title, class, process, initial text, app name.
type ProgramRow = (&'static str, &'static str, &'static str, &'static str, Option<&'static str>, &'static str);

/// The built-in programs, by lower-case name without `.exe`.
pub(crate) fn default_programs() -> BTreeMap<String, Program> {
    let table: &[ProgramRow] = &[
        ("notepad", "Untitled - Notepad", "Notepad", "notepad.exe", Some(""), "Notepad"),
        ("calc", "Calculator", "ApplicationFrameWindow", "CalculatorApp.exe", None, "Calculator"),
        ("chrome", "New Tab - Google Chrome", "Chrome_WidgetWin_1", "chrome.exe", None, "Google Chrome"),
        ("google-chrome", "New Tab - Google Chrome", "Chrome_WidgetWin_1", "chrome.exe", None, "Google Chrome"),
        ("msedge", "New tab - Microsoft Edge", "Chrome_WidgetWin_1", "msedge.exe", None, "Microsoft Edge"),
        ("code", "Visual Studio Code", "Chrome_WidgetWin_1", "Code.exe", None, "Visual Studio Code"),
        ("vlc", "VLC media player", "Qt5QWindowIcon", "vlc.exe", None, "VLC media player"),
        ("explorer", "File Explorer", "CabinetWClass", "explorer.exe", None, "File Explorer"),
        ("soffice", "LibreOffice", "SALFRAME", "soffice.bin", None, "LibreOffice"),
        ("scalc", "Untitled 1 - LibreOffice Calc", "SALFRAME", "soffice.bin", None, "LibreOffice Calc"),
        ("swriter", "Untitled 1 - LibreOffice Writer", "SALFRAME", "soffice.bin", Some(""), "LibreOffice Writer"),
        ("mspaint", "Untitled - Paint", "MSPaintApp", "mspaint.exe", None, "Paint"),
        ("photos", "Photos", "ApplicationFrameWindow", "Microsoft.Photos.exe", None, "Photos"),
        // The input recorder, modelled by `recorder` (the log it writes is its first argument).
        (
            super::recorder::PROGRAM,
            super::recorder::TITLE,
            "ArenaInputRecorder",
            "arena-input-recorder.exe",
            None,
            super::recorder::TITLE,
        ),
    ];
    table
        .iter()
        .map(|(name, title, class, process, text, app)| {
            let program = Program {
                title: (*title).to_owned(),
                class_name: (*class).to_owned(),
                process_name: (*process).to_owned(),
                text: text.map(str::to_owned),
                app_name: (*app).to_owned(),
            };
            ((*name).to_owned(), program)
        })
        .collect()
}

/// The built-in file associations: lower-case extension with its dot -> program name.
pub(crate) fn default_associations() -> BTreeMap<String, String> {
    let table: &[(&str, &str)] = &[
        (".txt", "notepad"),
        (".log", "notepad"),
        (".ini", "notepad"),
        (".md", "notepad"),
        (".json", "notepad"),
        (".csv", "scalc"),
        (".xlsx", "scalc"),
        (".xls", "scalc"),
        (".ods", "scalc"),
        (".docx", "swriter"),
        (".doc", "swriter"),
        (".odt", "swriter"),
        (".pdf", "msedge"),
        (".htm", "msedge"),
        (".html", "msedge"),
        (".png", "photos"),
        (".jpg", "photos"),
        (".jpeg", "photos"),
        (".gif", "photos"),
        (".bmp", "photos"),
        (".mp4", "vlc"),
        (".mp3", "vlc"),
        (".mkv", "vlc"),
        (".wav", "vlc"),
    ];
    table.iter().map(|(ext, program)| ((*ext).to_owned(), (*program).to_owned())).collect()
}

/// One word of a command line, remembering whether it was quoted.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Token {
    pub(crate) text: String,
    pub(crate) quoted: bool,
}

/// Splits a command line on whitespace, honouring `"..."` and `'...'` (quotes removed).
pub(crate) fn tokenize(line: &str) -> Vec<Token> {
    let mut tokens = Vec::new();
    let mut current: Option<Token> = None;
    let mut quote: Option<char> = None;
    for c in line.chars() {
        match quote {
            Some(q) if c == q => quote = None,
            Some(_) => current.get_or_insert_with(|| Token { text: String::new(), quoted: true }).text.push(c),
            None if c == '"' || c == '\'' => {
                quote = Some(c);
                current.get_or_insert_with(|| Token { text: String::new(), quoted: true }).quoted = true;
            }
            None if c.is_whitespace() => {
                if let Some(token) = current.take() {
                    tokens.push(token);
                }
            }
            None => current.get_or_insert_with(|| Token { text: String::new(), quoted: false }).text.push(c),
        }
    }
    tokens.extend(current);
    tokens
}

/// Whether a shell line uses operators (pipes, `&&`, redirections), so it is a real shell job.
fn has_shell_operators(line: &str) -> bool {
    let mut quote: Option<char> = None;
    for c in line.chars() {
        match quote {
            Some(q) if c == q => quote = None,
            Some(_) => {}
            None if c == '"' || c == '\'' => quote = Some(c),
            None if matches!(c, '&' | '|' | ';' | '<' | '>' | '`' | '$') => return true,
            None => {}
        }
    }
    false
}

/// The lower-case program name of a command word: directories, quotes and `.exe` stripped.
pub(crate) fn program_key(word: &str) -> String {
    let base = word.trim_matches(['"', '\'']).rsplit(['/', '\\']).next().unwrap_or("").to_lowercase();
    base.strip_suffix(".exe").map(str::to_owned).unwrap_or(base)
}

/// Drops the launch wrappers a command may start with: `cmd /c`, `cmd /k`,
/// and `start` with its options and its quoted window title.
fn skip_wrappers(mut tokens: &[Token]) -> &[Token] {
    loop {
        match tokens.first().map(|t| program_key(&t.text)) {
            Some(first) if first == "cmd" => {
                let flag = tokens.get(1).map(|t| t.text.to_lowercase());
                match flag.as_deref() {
                    Some("/c" | "/k") => tokens = &tokens[2..],
                    _ => return tokens,
                }
            }
            Some(first) if first == "start" => {
                tokens = &tokens[1..];
                if tokens.first().is_some_and(|t| t.quoted) && tokens.len() > 1 {
                    tokens = &tokens[1..];
                }
                while tokens.first().is_some_and(|t| t.text.starts_with('/') && t.text.len() > 1 && !t.quoted) {
                    tokens = &tokens[1..];
                }
            }
            _ => return tokens,
        }
    }
}

/// A command that names a known program: the program's key and its arguments.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct KnownLaunch {
    pub(crate) key: String,
    pub(crate) args: Vec<String>,
}

/// The words of a simple launch command with its wrappers (`cmd /c`, `start`) dropped;
/// `None` for a shell line with operators, which only a real shell can run.
pub(crate) fn launch_words(cmd: &CommandSpec) -> Option<Vec<String>> {
    let tokens: Vec<Token> = match cmd {
        CommandSpec::Shell(line) => {
            if has_shell_operators(line) {
                return None;
            }
            tokenize(line)
        }
        CommandSpec::Argv(argv) => argv.iter().map(|a| Token { text: a.clone(), quoted: false }).collect(),
    };
    let words: Vec<String> = skip_wrappers(&tokens).iter().map(|t| t.text.clone()).collect();
    (!words.is_empty()).then_some(words)
}

/// Recognises a command that launches one of `programs`.
pub(crate) fn known_launch(cmd: &CommandSpec, programs: &BTreeMap<String, Program>) -> Option<KnownLaunch> {
    let words = launch_words(cmd)?;
    let key = program_key(&words[0]);
    programs.contains_key(&key).then(|| KnownLaunch { key, args: words[1..].to_vec() })
}

/// The name of the program a command runs, for error messages.
pub(crate) fn command_name(cmd: &CommandSpec) -> String {
    match cmd {
        CommandSpec::Argv(argv) => argv.first().cloned().unwrap_or_default(),
        CommandSpec::Shell(line) => {
            let tokens = tokenize(line);
            skip_wrappers(&tokens).first().map(|t| t.text.clone()).unwrap_or_default()
        }
    }
}

/// The answer to a command that is none of the simulated programs when real host
/// processes are off: the same words whichever way the command came. It is "not
/// found" (404), as a program missing from a Windows guest is, so callers that
/// treat a missing program as upstream does (`open_program`'s "not installed")
/// keep doing so.
pub(crate) fn refusal(cmd: &CommandSpec) -> DesktopError {
    DesktopError::NotFound(format!(
        "program {} not found: the stub guest runs only its simulated programs and host processes are off (start the guest with --stub-host-exec to run real commands on this machine)",
        command_name(cmd)
    ))
}

/// Builds the host command for `cmd`.
fn host_command(cmd: &CommandSpec) -> DesktopResult<Command> {
    match cmd {
        CommandSpec::Argv(argv) => {
            let Some((program, args)) = argv.split_first() else {
                return Err(DesktopError::InvalidInput("the command is empty".into()));
            };
            if program.is_empty() {
                return Err(DesktopError::InvalidInput("the program name is empty".into()));
            }
            let mut command = Command::new(program);
            command.args(args);
            Ok(command)
        }
        CommandSpec::Shell(line) => {
            if line.trim().is_empty() {
                return Err(DesktopError::InvalidInput("the command line is empty".into()));
            }
            Ok(shell_command(line))
        }
    }
}

fn spawn_error(cmd: &CommandSpec, err: std::io::Error) -> DesktopError {
    if err.kind() == std::io::ErrorKind::NotFound {
        DesktopError::NotFound(format!("program {} not found", command_name(cmd)))
    } else {
        DesktopError::io("starting a program", &command_name(cmd), err)
    }
}

/// Shell words that are not programs on the PATH.
const SHELL_BUILTINS: &[&str] = &[
    "cd", "echo", "exit", "export", "set", "unset", "true", "false", "test", "[", "exec", "eval", "read", "printf",
    "pwd", "type", "command", "if", "for", "while", "until", "case", "{", "(", "!", ".", ":", "source", "sleep",
    "umask", "wait", "trap", "shift", "return", "kill", "ulimit", "times", "alias", "local",
];

/// Whether the program a shell line starts with can be found, so that `spawn`
/// can report a missing program instead of a shell that fails in the background.
fn shell_program_exists(line: &str) -> bool {
    if crate::desktop::windows::target::SHELL_REPORTS_MISSING_PROGRAMS {
        return true;
    }
    let tokens = tokenize(line);
    let Some(first) = skip_wrappers(&tokens).first() else {
        return true;
    };
    let word = first.text.as_str();
    if word.contains('=') || SHELL_BUILTINS.contains(&word) {
        return true;
    }
    if word.contains('/') {
        return Path::new(word).exists();
    }
    on_path(word)
}

/// Whether `name` is a program on `PATH`.
pub(crate) fn on_path(name: &str) -> bool {
    arena_shared::search_path::find_program(Path::new(name)).is_some()
}

/// Starts a real host process without waiting; a background thread reaps it.
///
/// # Errors
///
/// [`DesktopError::NotFound`] naming a missing program; the I/O error otherwise.
pub(crate) fn spawn_real(cmd: &CommandSpec, cwd: Option<PathBuf>) -> DesktopResult<u32> {
    if let CommandSpec::Shell(line) = cmd {
        if !shell_program_exists(line) {
            return Err(DesktopError::NotFound(format!("program {} not found", command_name(cmd))));
        }
    }
    let mut command = host_command(cmd)?;
    command.stdin(Stdio::null()).stdout(Stdio::null()).stderr(Stdio::null());
    if let Some(cwd) = cwd {
        command.current_dir(cwd);
    }
    isolate(&mut command);
    let mut child = command.spawn().map_err(|err| spawn_error(cmd, err))?;
    let pid = child.id();
    let name = command_name(cmd);
    let reaper = std::thread::Builder::new().name(format!("reap-{pid}")).spawn(move || match child.wait() {
        Ok(status) => tracing::debug!(pid, %name, %status, "spawned process exited"),
        Err(err) => tracing::warn!(pid, %name, %err, "waiting for a spawned process failed"),
    });
    if let Err(err) = reaper {
        tracing::warn!(pid, %err, "could not start a reaper thread; the process may linger as a zombie");
    }
    Ok(pid)
}

/// What one output stream produced.
#[derive(Debug, Default)]
struct Captured {
    bytes: Vec<u8>,
    truncated: bool,
    done: bool,
}

/// Reads `source` to its end on a thread, keeping at most `cap` bytes.
fn drain<R: Read + Send + 'static>(mut source: R, cap: usize) -> Arc<Mutex<Captured>> {
    let shared = Arc::new(Mutex::new(Captured::default()));
    let out = Arc::clone(&shared);
    let spawned = std::thread::Builder::new().name("exec-output".into()).spawn(move || {
        let mut buf = vec![0u8; 64 * 1024];
        loop {
            let n = match source.read(&mut buf) {
                Ok(0) | Err(_) => break,
                Ok(n) => n,
            };
            let mut captured = out.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
            let room = cap.saturating_sub(captured.bytes.len());
            if n > room {
                captured.truncated = true;
            }
            captured.bytes.extend_from_slice(&buf[..n.min(room)]);
        }
        out.lock().unwrap_or_else(std::sync::PoisonError::into_inner).done = true;
    });
    if spawned.is_err() {
        shared.lock().unwrap_or_else(std::sync::PoisonError::into_inner).done = true;
    }
    shared
}

/// Decodes output as lossy UTF-8 with CRLF and lone CR folded to LF.
pub(crate) fn decode_output(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).replace("\r\n", "\n").replace('\r', "\n")
}

/// Runs a real host process to completion or its timeout, capturing its output.
///
/// # Errors
///
/// [`DesktopError::NotFound`] naming a missing program, [`DesktopError::InvalidInput`]
/// for an empty command; the I/O error otherwise.
pub(crate) fn run_real(cmd: &CommandSpec, limits: &ExecLimits, cwd: Option<PathBuf>) -> DesktopResult<ExecOutput> {
    let started = Instant::now();
    let deadline = started + Duration::from_millis(limits.timeout_ms);
    let mut command = host_command(cmd)?;
    command.stdout(Stdio::piped()).stderr(Stdio::piped());
    command.stdin(if limits.stdin.is_some() { Stdio::piped() } else { Stdio::null() });
    if let Some(cwd) = cwd {
        command.current_dir(cwd);
    }
    isolate(&mut command);
    let mut child = command.spawn().map_err(|err| spawn_error(cmd, err))?;
    let cap = usize::try_from(limits.max_output_bytes).unwrap_or(usize::MAX);
    let stdout = child.stdout.take().map(|s| drain(s, cap));
    let stderr = child.stderr.take().map(|s| drain(s, cap));
    if let (Some(mut stdin), Some(bytes)) = (child.stdin.take(), limits.stdin.clone()) {
        // A separate thread, so a child that does not read its input cannot block us.
        let _ = std::thread::Builder::new().name("exec-stdin".into()).spawn(move || {
            let _ = stdin.write_all(&bytes);
        });
    }

    let mut timed_out = false;
    let mut pause = Duration::from_millis(1);
    let status = loop {
        match child.try_wait() {
            Ok(Some(status)) => break Some(status),
            Ok(None) => {}
            Err(err) => return Err(DesktopError::io("waiting for a program", &command_name(cmd), err)),
        }
        let now = Instant::now();
        if now >= deadline {
            timed_out = true;
            kill_tree(&mut child);
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(pause.min(deadline - now));
        pause = (pause * 2).min(Duration::from_millis(20));
    };

    // A background grandchild may hold the pipes open; wait a little for the
    // readers, then return what they have.
    let grace = Instant::now() + Duration::from_millis(500);
    let readers_done = || {
        [&stdout, &stderr]
            .iter()
            .all(|s| s.as_ref().is_none_or(|c| c.lock().unwrap_or_else(std::sync::PoisonError::into_inner).done))
    };
    while !readers_done() && Instant::now() < grace {
        std::thread::sleep(Duration::from_millis(2));
    }
    let take = |s: &Option<Arc<Mutex<Captured>>>| match s {
        Some(c) => {
            let c = c.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
            (decode_output(&c.bytes), c.truncated)
        }
        None => (String::new(), false),
    };
    let (stdout, stdout_truncated) = take(&stdout);
    let (stderr, stderr_truncated) = take(&stderr);
    Ok(ExecOutput {
        exit_code: status.and_then(exit_code),
        stdout,
        stderr,
        stdout_truncated,
        stderr_truncated,
        timed_out,
        duration_ms: u64::try_from(started.elapsed().as_millis()).unwrap_or(u64::MAX),
    })
}

/// The exit code, or minus the signal number for a process a signal killed (as Python reports it).
fn exit_code(status: std::process::ExitStatus) -> Option<i32> {
    if let Some(code) = status.code() {
        return Some(code);
    }
    #[cfg(unix)]
    {
        use std::os::unix::process::ExitStatusExt;
        status.signal().map(|s| -s)
    }
    #[cfg(not(unix))]
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(cmd: CommandSpec, expected: Option<(&str, &[&str])>) {
        let programs = default_programs();
        let got = known_launch(&cmd, &programs);
        let want = expected
            .map(|(key, args)| KnownLaunch { key: key.into(), args: args.iter().map(|a| (*a).to_owned()).collect() });
        assert_eq!(got, want, "{cmd:?}");
    }

    fn shell(line: &str) -> CommandSpec {
        CommandSpec::Shell(line.into())
    }

    #[test]
    fn known_programs_are_recognised() {
        check(shell("notepad"), Some(("notepad", &[])));
        check(shell("NOTEPAD.EXE C:\\a.txt"), Some(("notepad", &["C:\\a.txt"])));
        check(
            shell(r#""C:\Program Files\Google\Chrome\Application\chrome.exe" --new-window"#),
            Some(("chrome", &["--new-window"])),
        );
        check(shell("start notepad"), Some(("notepad", &[])));
        check(shell(r#"start "" /max msedge https://x"#), Some(("msedge", &["https://x"])));
        check(shell("cmd /c start calc"), Some(("calc", &[])));
        check(shell("cmd.exe /C code"), Some(("code", &[])));
        check(CommandSpec::Argv(vec!["/usr/bin/google-chrome".into(), "a".into()]), Some(("google-chrome", &["a"])));
        check(shell("notepad && echo hi"), None);
        check(shell("echo notepad"), None);
        check(shell("python -c 1"), None);
        check(shell(""), None);
    }

    #[test]
    fn tokenizer_keeps_quoted_words_together() {
        let tokens = tokenize(r#"a "b c" 'd e' "" f"g"h"#);
        let texts: Vec<&str> = tokens.iter().map(|t| t.text.as_str()).collect();
        assert_eq!(texts, vec!["a", "b c", "d e", "", "fgh"]);
        assert!(tokens[3].quoted && !tokens[0].quoted);
    }

    #[test]
    fn output_newlines_are_folded() {
        assert_eq!(decode_output(b"a\r\nb\rc\n\xff"), "a\nb\nc\n\u{fffd}");
    }
}
