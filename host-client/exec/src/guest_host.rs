//! [`GuestHost`]: the [`ScriptHost`] whose every effect is a typed call of one
//! guest's `/v1` API, which agents' `computer` and pyautogui code runs against on the host.

use std::future::Future;
use std::sync::Arc;
use std::time::{Duration, Instant};

use base64::Engine as _;
use image::RgbaImage;
use tokio::runtime::Handle;

use arena_client::client::GuestClient;
use arena_client::error::ClientError;
use arena_client::frame::{encode_png, Frame};
use arena_script::{CommandOutput, HostError, HostResult, PathKind, ScriptHost, WindowChange};
use arena_shared::action::{Action, ActionBatch};
use arena_shared::clipboard::ClipboardContent;
use arena_shared::cmdline::CommandSpec;
use arena_shared::exec::{ExecRequest, LaunchRequest};
use arena_shared::files::FileKind;
use arena_shared::geometry::Point;
use arena_shared::keys::HeldKeys;
use arena_shared::observation::{ImageFormat, ScreenshotQuery, WindowInfo, WindowTarget};
use arena_shared::registry::RegistryValue;

use crate::options::ExecOptions;

/// A [`ScriptHost`] whose effects are calls of one guest's `/v1` API.
///
/// It must run on a thread that is not a runtime worker (a `spawn_blocking`
/// thread), because it blocks on the client's futures through `rt`. On a
/// current-thread runtime this works only while that thread is inside
/// `Runtime::block_on` (awaiting the script), which drives the I/O; [`execute`]
/// guarantees that by awaiting the worker.
#[derive(Debug)]
pub struct GuestHost {
    client: GuestClient,
    rt: Handle,
    options: ExecOptions,
    started: Instant,
    /// The cursor after the last input action.
    pub cursor: Option<Point>,
    /// How many input actions were sent.
    pub performed: usize,
    /// The first error that showed the guest unreachable. The script saw it as a
    /// [`HostError::Unreachable`] and stopped; the client error is kept for the caller.
    pub unreachable: Option<ClientError>,
    /// Keys the script pressed with `keyDown` and has not released yet.
    pub held: HeldKeys,
    /// Every key the script pressed with `keyDown`, each once.
    pub keys_down: Vec<String>,
}

impl GuestHost {
    pub fn new(client: GuestClient, rt: Handle, options: ExecOptions) -> GuestHost {
        GuestHost {
            client,
            rt,
            options,
            started: Instant::now(),
            cursor: None,
            performed: 0,
            unreachable: None,
            held: HeldKeys::default(),
            keys_down: Vec::new(),
        }
    }

    /// Runs one client call to completion, remembering an unreachable guest.
    fn call<T, F>(&mut self, call: impl FnOnce(GuestClient) -> F) -> HostResult<T>
    where
        F: Future<Output = Result<T, ClientError>>,
    {
        if let Some(err) = &self.unreachable {
            return Err(HostError::Unreachable(format!("the guest is unreachable: {err}")));
        }
        let result = self.rt.block_on(call(self.client.clone()));
        result.map_err(|err| self.client_error(err))
    }

    /// A client error as the script sees it; an unreachable guest is remembered.
    fn client_error(&mut self, err: ClientError) -> HostError {
        let message = err.to_string();
        if err.out_of_reach() {
            self.unreachable = Some(err);
            return HostError::Unreachable(message);
        }
        HostError::Failed(message)
    }

    fn remaining(&self) -> Duration {
        self.options.max_duration.saturating_sub(self.started.elapsed())
    }
}

impl ScriptHost for GuestHost {
    fn perform(&mut self, action: Action) -> HostResult<()> {
        let tracked = action.clone();
        let report = self.call(|c| async move { c.act_one(action).await })?;
        self.held.track(&tracked);
        if let Action::KeyDown { key } = &tracked {
            if !self.keys_down.contains(key) {
                self.keys_down.push(key.clone());
            }
        }
        self.cursor = Some(report.cursor);
        self.performed += 1;
        Ok(())
    }

    fn sleep(&mut self, seconds: f64) -> HostResult<()> {
        let scaled = (seconds * self.options.sleep_scale).max(0.0);
        let wanted = Duration::try_from_secs_f64(scaled).unwrap_or(Duration::MAX);
        if wanted > self.remaining() {
            return Err(HostError::TimedOut(format!(
                "sleeping {seconds} s would take the action past its {} s limit",
                self.options.max_duration.as_secs()
            )));
        }
        std::thread::sleep(wanted);
        Ok(())
    }

    fn cursor_position(&mut self) -> HostResult<(i32, i32)> {
        // An empty batch does nothing and reports where the cursor is.
        let report = self.call(|c| async move { c.act(&ActionBatch { actions: Vec::new() }).await })?;
        self.cursor = Some(report.cursor);
        Ok((report.cursor.x, report.cursor.y))
    }

    fn screen_size(&mut self) -> HostResult<(u32, u32)> {
        let screen = self.call(|c| async move { c.screen().await })?;
        Ok((screen.physical_width, screen.physical_height))
    }

    fn capture(&mut self) -> HostResult<RgbaImage> {
        let query = ScreenshotQuery { format: ImageFormat::Png, cursor: Some(false), ..ScreenshotQuery::default() };
        let shot = self.call(|c| async move { c.screenshot(&query).await })?;
        Frame::decode(shot.bytes)
            .map(|frame| Arc::unwrap_or_clone(frame.pixels))
            .map_err(|e| HostError::Failed(format!("cannot decode the screenshot: {e}")))
    }

    fn observed_screenshot(&mut self) -> HostResult<RgbaImage> {
        // The agent's own observation is not kept here (see the module doc).
        self.capture()
    }

    fn windows(&mut self) -> HostResult<Vec<WindowInfo>> {
        self.call(|c| async move { c.windows().await })
    }

    fn change_window(&mut self, id: u64, change: WindowChange) -> HostResult<()> {
        let target = WindowTarget { id: Some(id), title: None };
        self.call(|c| async move {
            match change {
                WindowChange::Restore => c.restore_window(&target).await,
                WindowChange::Maximize => c.maximize_window(&target).await,
                WindowChange::Activate => c.activate_window(&target).await,
            }
        })
        .map(drop)
    }

    fn path_kind(&mut self, path: &str) -> Option<PathKind> {
        let path = path.to_owned();
        let exists = self.call(|c| async move { c.exists(&path).await }).ok()?;
        match (exists.exists, exists.kind) {
            (false, _) => None,
            (true, Some(FileKind::Dir)) => Some(PathKind::Dir),
            (true, _) => Some(PathKind::File),
        }
    }

    fn list_dir(&mut self, path: &str) -> HostResult<Vec<String>> {
        let path = path.to_owned();
        let listing = self.call(|c| async move { c.list_dir(&path).await })?;
        let mut names: Vec<String> = listing.entries.into_iter().map(|e| e.name).collect();
        // The guest lists in this order already; sorting keeps `os.listdir` right
        // against a guest that does not.
        arena_shared::ntfs::sort_names(&mut names);
        Ok(names)
    }

    fn write_file(&mut self, path: &str, bytes: Vec<u8>) -> HostResult<()> {
        let path = path.to_owned();
        // As Python's `open(path, "wb")`: no missing folder is created.
        self.call(|c| async move { c.push_file(&path, bytes, Some(false)).await }).map(drop)
    }

    fn run(&mut self, command: &CommandSpec) -> HostResult<CommandOutput> {
        let timeout_ms = u64::try_from(self.remaining().as_millis()).unwrap_or(u64::MAX).max(1);
        let request = ExecRequest { timeout_ms: Some(timeout_ms), ..ExecRequest::new(command.clone()) };
        let result = self.call(|c| async move { c.exec(&request).await })?;
        if result.timed_out {
            return Err(HostError::TimedOut("the command ran out of time".to_owned()));
        }
        Ok(CommandOutput { code: result.exit_code.unwrap_or(-1), stdout: result.stdout, stderr: result.stderr })
    }

    fn launch(&mut self, command: &CommandSpec) -> HostResult<Option<u32>> {
        if let Some(err) = &self.unreachable {
            return Err(HostError::Unreachable(format!("the guest is unreachable: {err}")));
        }
        let request = LaunchRequest::new(command.clone());
        match self.rt.block_on(self.client.launch(&request)) {
            Ok(launched) => Ok(Some(launched.pid)),
            // The guest answers 404 when the program does not exist.
            Err(err) if err.status() == Some(404) => Ok(None),
            Err(err) => Err(self.client_error(err)),
        }
    }

    fn registry_read(&mut self, key: &str, value: Option<&str>) -> HostResult<Option<RegistryValue>> {
        if let Some(err) = &self.unreachable {
            return Err(HostError::Unreachable(format!("the guest is unreachable: {err}")));
        }
        match self.rt.block_on(self.client.registry_get(key, value)) {
            Ok(read) => Ok(Some(read.data)),
            // The guest answers 404 when the key or the value does not exist.
            Err(err) if err.status() == Some(404) => Ok(None),
            Err(err) => Err(self.client_error(err)),
        }
    }

    fn clipboard_set_text(&mut self, text: &str) -> HostResult<()> {
        let content = ClipboardContent::Text { text: text.to_owned() };
        self.call(|c| async move { c.clipboard_set(&content).await })
    }

    fn clipboard_get_text(&mut self) -> HostResult<String> {
        match self.call(|c| async move { c.clipboard_get().await })? {
            ClipboardContent::Text { text } => Ok(text),
            // pyperclip.paste() gives "" when the clipboard holds no text.
            _ => Ok(String::new()),
        }
    }

    fn clipboard_set_image(&mut self, image: RgbaImage) -> HostResult<()> {
        let png = encode_png(&image);
        if png.is_empty() {
            return Err(HostError::Failed("cannot encode the image".into()));
        }
        let content = ClipboardContent::Image {
            width: image.width(),
            height: image.height(),
            png_base64: base64::engine::general_purpose::STANDARD.encode(png),
        };
        self.call(|c| async move { c.clipboard_set(&content).await })
    }

    fn env_var(&mut self, name: &str) -> Option<String> {
        if name.is_empty() || !name.chars().all(|c| c.is_ascii_alphanumeric() || "_()".contains(c)) {
            return None;
        }
        let out = self.run(&CommandSpec::Shell(format!("echo %{name}%"))).ok()?;
        let value = out.stdout.trim_end_matches(['\r', '\n']).to_owned();
        // cmd.exe echoes an undefined variable's reference unchanged.
        (out.code == 0 && value != format!("%{name}%")).then_some(value)
    }
}
