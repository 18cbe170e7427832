//! One function per setup step type, each doing over the native API what
//! upstream's host and guest did together (waa-api.md §b.3 and §a.4), and
//! [`run`], the dispatch.
//!
//! Every function answers an [`Outcome`]: whether the step did its job and a
//! line saying what happened. Only `download` answers `Err`, because upstream
//! raises there and nothing after it may run.

use std::path::{Component, Path};
use std::time::{Duration, SystemTime};

use arena_exec::InputOnly;
use arena_shared::exec::{ExecRequest, ExecResult, LaunchRequest};
use arena_shared::files::KnownFolder;
use arena_shared::observation::{WindowInfo, WindowTarget};

use arena_client::client::GuestClient;
use arena_task::{CommandArg, DownloadFile, SetupStep, Until};

use super::command::{self, ExecPlan};
use super::outcome::Outcome;
use super::{cdp, history, SetupContext, SetupError};

/// Upstream's pause after opening a file: the guest route sleeps 5 s and the host 2 s more.
const OPEN_PAUSE: Duration = Duration::from_secs(7);
/// Upstream's pause after minimising, and after restoring, in a strict activation.
const ACTIVATE_PAUSE: Duration = Duration::from_secs(1);
/// Upstream's pause between `until` attempts.
const UNTIL_PAUSE: Duration = Duration::from_millis(300);
/// Attempts of an `execute` with `until` that did not match before giving up.
const UNTIL_FAILURES: u32 = 5;
/// Upstream's `/execute` timeout.
const EXEC_TIMEOUT_MS: u64 = 120_000;

/// Runs one step.
///
/// # Errors
///
/// Only for `download`: see [`super::run_step`].
pub(super) async fn run(ctx: &SetupContext, step: &SetupStep) -> Result<Outcome, SetupError> {
    let client = &ctx.client;
    Ok(match step {
        SetupStep::Launch { command, shell } => launch(ctx, command, *shell).await,
        SetupStep::Download { files } => download(ctx, files).await?,
        SetupStep::Sleep { seconds } => {
            let d = Duration::try_from_secs_f64(*seconds).unwrap_or(Duration::ZERO);
            ctx.settle.pause(d).await;
            Outcome::done(format!("slept {} ms (task asked for {seconds} s)", ctx.settle.scale(d).as_millis()))
        }
        SetupStep::Open { path } => {
            let result = client.open(path).await;
            if result.is_ok() {
                ctx.settle.pause(OPEN_PAUSE).await;
            }
            Outcome::of(result, format!("opened {path}"))
        }
        SetupStep::ActivateWindow { window_name, strict, by_class } => {
            activate(ctx, window_name, *strict, *by_class).await
        }
        SetupStep::Execute { command, shell, stdout, stderr, until } => {
            execute(ctx, command, *shell, stdout.as_deref(), stderr.as_deref(), until.as_ref()).await
        }
        SetupStep::CreateFolder { path } => Outcome::of(client.mkdir(path).await, format!("{path} created")),
        SetupStep::RecycleFile { path } => Outcome::of(client.recycle(path).await, format!("{path} recycled")),
        SetupStep::OpenTabs { urls } => cdp::open_tabs(ctx, urls).await,
        SetupStep::CloseTabs { urls } => cdp::close_tabs(ctx, urls).await,
        SetupStep::UpdateBrowseHistory { browser, history: entries } => {
            let entries = entries.clone();
            let built = tokio::task::spawn_blocking(move || history::build(&entries, SystemTime::now())).await;
            match built {
                Ok(Ok(bytes)) => match history::guest_path(client, *browser).await {
                    Ok(path) => Outcome::of(client.push_file(&path, bytes, Some(true)).await, format!("wrote {path}")),
                    Err(err) => Outcome::failed(err),
                },
                Ok(Err(err)) => Outcome::failed(err),
                Err(err) => Outcome::failed(format!("building the History database failed: {err}")),
            }
        }
        SetupStep::UploadFile { files } => upload(client, files).await,
        SetupStep::ChangeWallpaper { path } => {
            Outcome::of(client.set_wallpaper(path).await, format!("wallpaper set to {path}"))
        }
        SetupStep::CloseWindow { window_name, strict, by_class } => {
            close_window(client, window_name, *strict, *by_class).await
        }
        SetupStep::CreateFile { path, content } => {
            // Upstream writes in text mode on Windows: `\n` becomes `\r\n`.
            let bytes = content.replace("\r\n", "\n").replace('\n', "\r\n").into_bytes();
            Outcome::of(client.push_file(path, bytes, Some(true)).await, format!("{path} created"))
        }
        SetupStep::CloseAll => match super::close_all(client).await {
            Ok(n) => Outcome::done(format!("asked {n} windows to close")),
            Err(err) => Outcome::failed(err.to_string()),
        },
        // A step type added to the task model after this module: recorded, not fatal.
        #[allow(unreachable_patterns)]
        other => Outcome::failed(format!("setup step `{}` is not supported by this build", other.kind())),
    })
}

/// The guest's home folder, for `~/` words.
async fn home(client: &GuestClient, command: &CommandArg) -> Option<String> {
    if !command::needs_home(command) {
        return None;
    }
    match client.folders().await {
        Ok(folders) => folders.folders.into_iter().find(|(f, _)| *f == KnownFolder::Home).map(|(_, p)| p),
        Err(err) => {
            tracing::warn!(error = %err, "cannot ask the guest for its home folder; `~/` stays as written");
            None
        }
    }
}

async fn launch(ctx: &SetupContext, command: &CommandArg, shell: bool) -> Outcome {
    if let CommandArg::Str(line) = command {
        if !shell && line.contains(' ') {
            tracing::warn!(command = %line, "launch: a string command with spaces and no shell is split on whitespace, as upstream does");
        }
    }
    let home = home(&ctx.client, command).await;
    let spec = command::launch_command(command, shell, home.as_deref());
    let line = command::display(&spec);
    match ctx.client.launch(&LaunchRequest::new(spec)).await {
        Ok(started) => Outcome::done(format!("started pid {}: {line}", started.pid)),
        // Upstream's guest ran launches through the shell and never looked at the
        // result, so a missing program (socat, a cmdlet) was a success there too.
        Err(err) if err.status() == Some(404) => {
            Outcome::done(format!("{line}: program not found (not a failure upstream): {err}"))
        }
        Err(err) => Outcome::failed(format!("{line}: {err}")),
    }
}

async fn download(ctx: &SetupContext, files: &[DownloadFile]) -> Result<Outcome, SetupError> {
    let mut done = Vec::new();
    let mut problems = Vec::new();
    for file in files {
        let local = ctx.cache.fetch(&file.url).await?;
        let bytes = tokio::fs::read(&local)
            .await
            .map_err(|err| SetupError::Cache { path: local.clone(), reason: err.to_string() })?;
        // Upstream's `/setup/upload` could not create missing folders; the native
        // upload can, so a task whose folder does not exist yet works here.
        match ctx.client.push_file(&file.path, bytes, Some(true)).await {
            Ok(written) => done.push(format!("{} -> {} ({} bytes)", file.url, file.path, written.size)),
            Err(err) => problems.push(format!("{}: {err}", file.path)),
        }
    }
    let detail = done.join("; ");
    Ok(if problems.is_empty() {
        Outcome::done(detail)
    } else {
        Outcome::failed(format!("{detail}; {}", problems.join("; ")))
    })
}

async fn upload(client: &GuestClient, files: &[(std::path::PathBuf, String)]) -> Outcome {
    let mut done = Vec::new();
    let mut problems = Vec::new();
    for (local, guest) in files {
        match tokio::fs::read(local).await {
            Ok(bytes) => match client.push_file(guest, bytes, Some(true)).await {
                Ok(_) => done.push(format!("{} -> {guest}", local.display())),
                Err(err) => problems.push(format!("{guest}: {err}")),
            },
            Err(err) => problems.push(format!("{}: {err}", local.display())),
        }
    }
    let detail = done.join("; ");
    if problems.is_empty() {
        Outcome::done(detail)
    } else {
        Outcome::failed(format!("{detail}; {}", problems.join("; ")))
    }
}

/// pygetwindow's `getWindowsWithTitle`: visible windows whose title contains `name`, any case, topmost first.
fn matching_windows(windows: Vec<WindowInfo>, name: &str) -> Vec<WindowInfo> {
    let needle = name.to_lowercase();
    let mut found: Vec<WindowInfo> =
        windows.into_iter().filter(|w| w.visible && w.title.to_lowercase().contains(&needle)).collect();
    found.sort_by_key(|w| w.z_order);
    found
}

fn by_id(id: u64) -> WindowTarget {
    WindowTarget { id: Some(id), title: None }
}

async fn activate(ctx: &SetupContext, name: &str, strict: bool, by_class: bool) -> Outcome {
    if by_class {
        return Outcome::failed("Get window by class name is currently not supported on Windows.");
    }
    if name.is_empty() {
        return Outcome::failed("window_name required");
    }
    let client = &ctx.client;
    let windows = match client.windows().await {
        Ok(windows) => matching_windows(windows, name),
        Err(err) => return Outcome::failed(err.to_string()),
    };
    let Some(window) = windows.first() else {
        return Outcome::failed(format!("Window {name} not found (empty results)"));
    };
    let id = window.id;
    if !strict && !ctx.activate_non_strict {
        // Upstream's non-strict mode finds the window and does nothing more.
        return Outcome::done(format!("found {:?}; not activated (non-strict, as upstream)", window.title));
    }
    if !strict {
        // The named deviation: make the window the task names the one in front.
        return match client.activate_window(&by_id(id)).await {
            Ok(_) => Outcome::done(format!("activated {:?}", window.title)),
            Err(err) => {
                tracing::warn!(error = %err, "non-strict activate_window could not activate the window");
                Outcome::done(format!("found {:?}; activation refused (a no-op upstream): {err}", window.title))
            }
        };
    }
    if let Err(err) = client.minimize_window(&by_id(id)).await {
        return Outcome::failed(format!("minimising {:?}: {err}", window.title));
    }
    ctx.settle.pause(ACTIVATE_PAUSE).await;
    if let Err(err) = client.restore_window(&by_id(id)).await {
        return Outcome::failed(format!("restoring {:?}: {err}", window.title));
    }
    // A restored window usually comes to the front on its own; asking makes sure.
    if let Err(err) = client.activate_window(&by_id(id)).await {
        tracing::debug!(error = %err, "activation after restore refused");
    }
    ctx.settle.pause(ACTIVATE_PAUSE).await;
    match client.windows().await {
        Ok(now) if now.iter().any(|w| w.id == id && w.focused) => {
            Outcome::done(format!("activated {:?} (strict)", window.title))
        }
        Ok(_) => Outcome::failed(format!("{:?} is not the foreground window after restoring it", window.title)),
        Err(err) => Outcome::failed(err.to_string()),
    }
}

async fn close_window(client: &GuestClient, name: &str, strict: bool, by_class: bool) -> Outcome {
    if by_class {
        return Outcome::failed("Get window by class name is not supported on Windows currently.");
    }
    let windows = match client.windows().await {
        Ok(windows) => matching_windows(windows, name),
        Err(err) => return Outcome::failed(err.to_string()),
    };
    if windows.is_empty() {
        return Outcome::failed(format!("Window {name} not found (empty results)"));
    }
    // Upstream's strict mode compared a window with its own title and so never
    // matched; the evident intent, an exact title, is what strict means here.
    let target = if strict { windows.iter().find(|w| w.title == name) } else { windows.first() };
    let Some(target) = target else {
        return Outcome::failed(format!("Window {name} not found (strict mode)."));
    };
    Outcome::of(client.close_window(&by_id(target.id)).await, format!("closed {:?}", target.title))
}

/// What one `execute` attempt answered, in upstream's `/execute` terms.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Ran {
    returncode: Option<i64>,
    output: String,
    error: String,
    how: String,
}

/// Whether `ran` meets `until`: any one of the given conditions (stdout and stderr as substrings).
fn until_met(until: &Until, ran: &Ran) -> bool {
    until.returncode.is_some_and(|code| ran.returncode == Some(code))
        || until.stdout.as_deref().is_some_and(|s| ran.output.contains(s))
        || until.stderr.as_deref().is_some_and(|s| ran.error.contains(s))
}

/// A host file name for `stdout`/`stderr`: plain names and subfolders only, never outside `host_dir`.
fn host_file(host_dir: &Path, name: &str) -> Result<std::path::PathBuf, String> {
    let relative = Path::new(name);
    if name.is_empty() || !relative.components().all(|c| matches!(c, Component::Normal(_))) {
        return Err(format!("refusing to write output to {name:?}: it must be a relative path inside the task folder"));
    }
    Ok(host_dir.join(relative))
}

async fn write_output(host_dir: &Path, name: &str, text: &str) -> Result<(), String> {
    let path = host_file(host_dir, name)?;
    if let Some(parent) = path.parent() {
        tokio::fs::create_dir_all(parent).await.map_err(|err| format!("{}: {err}", parent.display()))?;
    }
    tokio::fs::write(&path, text).await.map_err(|err| format!("{}: {err}", path.display()))
}

async fn execute(
    ctx: &SetupContext,
    command: &CommandArg,
    shell: bool,
    stdout: Option<&str>,
    stderr: Option<&str>,
    until: Option<&Until>,
) -> Outcome {
    let home = home(&ctx.client, command).await;
    let plan = match command::exec_plan(command, shell, home.as_deref()) {
        Ok(plan) => plan,
        Err(err) => return Outcome::failed(err),
    };
    let mut attempts = 0u32;
    loop {
        attempts += 1;
        let ran = run_once(&ctx.client, &plan).await;
        let mut notes = Vec::new();
        if let Ok(ran) = &ran {
            for (name, text) in [(stdout, &ran.output), (stderr, &ran.error)] {
                if let Some(name) = name {
                    if let Err(err) = write_output(&ctx.host_dir, name, text).await {
                        notes.push(err);
                    }
                }
            }
        }
        let describe = |ran: &Ran| {
            let code = ran.returncode.map_or_else(|| "none".to_owned(), |c| c.to_string());
            let mut text = format!("{}; returncode {code}", ran.how);
            if attempts > 1 {
                text.push_str(&format!(" after {attempts} attempts"));
            }
            for note in &notes {
                text.push_str(&format!("; {note}"));
            }
            text
        };
        let Some(until) = until else {
            return match ran {
                Ok(ran) if notes.is_empty() => Outcome::done(describe(&ran)),
                Ok(ran) => Outcome::failed(describe(&ran)),
                Err(err) => Outcome::failed(err),
            };
        };
        let met = ran.as_ref().is_ok_and(|ran| until_met(until, ran));
        if met || attempts >= UNTIL_FAILURES {
            return match ran {
                Ok(ran) if met => Outcome::done(describe(&ran)),
                Ok(ran) => Outcome::failed(format!("until condition not met: {}", describe(&ran))),
                Err(err) => Outcome::failed(format!("until condition not met after {attempts} attempts: {err}")),
            };
        }
        ctx.settle.pause(UNTIL_PAUSE).await;
    }
}

/// One attempt of an `execute` step: pyautogui code as typed actions when it is only
/// input (the executor's [`arena_exec::PyautoguiPolicy::InputOnly`], in pixels),
/// any other command (or code doing more than input: files, processes, the
/// clipboard) run on the guest.
async fn run_once(client: &GuestClient, plan: &ExecPlan) -> Result<Ran, String> {
    let spec = match plan {
        ExecPlan::Run(spec) => spec,
        ExecPlan::Python { code, command } => {
            match arena_exec::perform_input_only(client, code, Default::default())
                .await
                .map_err(|err| err.to_string())?
            {
                InputOnly::Performed { actions, .. } => {
                    return Ok(Ran {
                        returncode: Some(0),
                        output: String::new(),
                        error: String::new(),
                        how: format!("python -c translated into {actions} input actions"),
                    });
                }
                InputOnly::NotInput(why) => {
                    tracing::info!(reason = %why, "python code is not only input; running it on the guest");
                    command
                }
            }
        }
    };
    let request = ExecRequest { timeout_ms: Some(EXEC_TIMEOUT_MS), ..ExecRequest::new(spec.clone()) };
    let result: ExecResult = client.exec(&request).await.map_err(|err| err.to_string())?;
    let mut how = format!("ran {}", command::display(spec));
    if result.timed_out {
        how.push_str(&format!(" (killed after {} s)", EXEC_TIMEOUT_MS / 1000));
    }
    Ok(Ran { returncode: result.exit_code.map(i64::from), output: result.stdout, error: result.stderr, how })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ran(code: Option<i64>, out: &str, err: &str) -> Ran {
        Ran { returncode: code, output: out.into(), error: err.into(), how: String::new() }
    }

    #[test]
    fn until_matches_any_condition_with_substrings() {
        let check =
            |until: Until, r: Ran, expected: bool| assert_eq!(until_met(&until, &r), expected, "{until:?} {r:?}");
        check(Until { returncode: Some(0), ..Until::default() }, ran(Some(0), "", ""), true);
        check(Until { returncode: Some(0), ..Until::default() }, ran(Some(1), "", ""), false);
        check(Until { returncode: Some(0), ..Until::default() }, ran(None, "", ""), false);
        check(Until { stdout: Some("ready".into()), ..Until::default() }, ran(Some(1), "is ready now", ""), true);
        check(Until { stderr: Some("x".into()), ..Until::default() }, ran(Some(1), "x", ""), false);
        check(
            Until { returncode: Some(3), stderr: Some("warn".into()), ..Until::default() },
            ran(Some(0), "", "warning"),
            true,
        );
        check(Until::default(), ran(Some(0), "", ""), false);
    }

    #[test]
    fn output_files_stay_inside_the_task_folder() {
        let dir = Path::new("/tmp/task");
        assert_eq!(host_file(dir, "out.txt").unwrap(), dir.join("out.txt"));
        assert_eq!(host_file(dir, "sub/out.txt").unwrap(), dir.join("sub/out.txt"));
        for bad in ["", "../x", "/etc/passwd", "a/../../b"] {
            assert!(host_file(dir, bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn windows_match_by_case_insensitive_substring_topmost_first() {
        let window = |id: u64, title: &str, visible: bool, z: u32| WindowInfo {
            id,
            title: title.into(),
            class_name: String::new(),
            process_id: 1,
            process_name: String::new(),
            rect: arena_shared::geometry::Rect::new(0, 0, 10, 10),
            visible,
            minimized: false,
            maximized: false,
            focused: false,
            z_order: z,
        };
        let found = matching_windows(
            vec![
                window(1, "a.docx - Word", true, 2),
                window(2, "A.DOCX - LibreOffice", true, 1),
                window(3, "a.docx", false, 0),
            ],
            "a.docx",
        );
        let ids: Vec<u64> = found.iter().map(|w| w.id).collect();
        assert_eq!(ids, vec![2, 1]);
    }
}
