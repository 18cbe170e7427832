//! Processes with Python `subprocess` semantics on Windows.
//!
//! - An argv becomes a command line with `list2cmdline` (the MSVC quoting rules) and
//!   goes to `CreateProcessW` with no application name, so Windows searches for the
//!   program exactly as for Python (the server's folder, the current folder, the
//!   system folders, then `PATH`).
//! - A shell line runs as `%COMSPEC% /c "<line>"` with a hidden window (`shell=True`).
//! - With no working directory given, a shell line starts in `%SystemRoot%` and a
//!   program in the server's folder: where upstream's commands end up
//!   ([`winsys::default_exec_dir`]).
//! - A child inherits its three standard handles and nothing else
//!   (`PROC_THREAD_ATTRIBUTE_HANDLE_LIST`), not every inheritable handle the server
//!   holds (the service worker's stop pipe and log file, other runs' pipes).
//! - `run` puts the child in a job object; a timeout terminates the whole job, so
//!   grandchildren die too. A child that exits in time leaves its background
//!   programs running (`start notepad`), as with Python.
//! - Output is read on threads up to the cap, decoded from the ANSI code page, and
//!   CRLF/CR fold to LF: `text=True` on Windows. Bytes the code page does not define
//!   get the system's substitute where Python would raise `UnicodeDecodeError`.
//! - `open` (`os.startfile`) calls `ShellExecuteExW` with COM initialised
//!   apartment-threaded on the calling thread, as the shell requires, and waits for
//!   the shell to finish (`SEE_MASK_NOASYNC`) before COM is uninitialised.

use std::io::Read;
use std::os::windows::io::FromRawHandle;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use windows::core::{PCWSTR, PWSTR};
use windows::Win32::Foundation::{
    SetHandleInformation, HANDLE, HANDLE_FLAGS, HANDLE_FLAG_INHERIT, WAIT_OBJECT_0, WAIT_TIMEOUT,
};
use windows::Win32::Globalization::{MultiByteToWideChar, CP_ACP, MULTI_BYTE_TO_WIDE_CHAR_FLAGS};
use windows::Win32::Security::SECURITY_ATTRIBUTES;
use windows::Win32::System::Com::{COINIT_APARTMENTTHREADED, COINIT_DISABLE_OLE1DDE};
use windows::Win32::System::JobObjects::{
    AssignProcessToJobObject, CreateJobObjectW, JobObjectExtendedLimitInformation, SetInformationJobObject,
    TerminateJobObject, JOBOBJECT_EXTENDED_LIMIT_INFORMATION, JOB_OBJECT_LIMIT, JOB_OBJECT_LIMIT_KILL_ON_JOB_CLOSE,
};
use windows::Win32::System::Pipes::CreatePipe;
use windows::Win32::System::Threading::{
    CreateProcessW, DeleteProcThreadAttributeList, GetExitCodeProcess, InitializeProcThreadAttributeList, ResumeThread,
    TerminateProcess, UpdateProcThreadAttribute, WaitForSingleObject, CREATE_SUSPENDED, EXTENDED_STARTUPINFO_PRESENT,
    LPPROC_THREAD_ATTRIBUTE_LIST, PROCESS_CREATION_FLAGS, PROCESS_INFORMATION, PROC_THREAD_ATTRIBUTE_HANDLE_LIST,
    STARTF_USESHOWWINDOW, STARTF_USESTDHANDLES, STARTUPINFOEXW, STARTUPINFOW,
};
use windows::Win32::UI::Shell::{ShellExecuteExW, SEE_MASK_NOASYNC, SHELLEXECUTEINFOW};
use windows::Win32::UI::WindowsAndMessaging::{SW_HIDE, SW_SHOWNORMAL};

use super::sys::{os, ComApartment, OwnedHandle};
use super::winsys;
use crate::desktop::windows::text::{fold_newlines, wide_nul, CappedBuffer};
use crate::desktop::{CommandSpec, DesktopError, DesktopResult, ExecLimits, ExecOutput};

/// Creating inheritable pipe ends and the process that inherits them happens under
/// this lock. With the handle list a child inherits only its own pipe ends anyway;
/// the lock keeps that true where the list cannot be built and a child inherits
/// every inheritable handle (a leaked pipe end would keep a reader waiting).
static SPAWN_LOCK: Mutex<()> = Mutex::new(());

/// How long to wait for the output readers after the process ended: a background
/// grandchild that inherited the pipes may keep them open.
const READER_GRACE: Duration = Duration::from_millis(500);

/// The command line for `cmd`, and whether the window should be hidden.
fn command_line(cmd: &CommandSpec) -> DesktopResult<(String, bool)> {
    let (line, hide) = match cmd {
        CommandSpec::Argv(argv) => {
            if argv.is_empty() {
                return Err(DesktopError::InvalidInput("empty command".into()));
            }
            (arena_shared::cmdline::list2cmdline(argv), false)
        }
        CommandSpec::Shell(line) => {
            // Python's subprocess: COMSPEC (or cmd.exe) /c "<line>", window hidden.
            let comspec = std::env::var("COMSPEC").unwrap_or_else(|_| "cmd.exe".into());
            (format!("{comspec} {}", arena_shared::cmdline::cmd_arguments(line)), true)
        }
    };
    if line.contains('\0') {
        return Err(DesktopError::InvalidInput("the command contains a NUL character".into()));
    }
    Ok((line, hide))
}

/// The program named by `cmd`, for messages.
fn program_name(cmd: &CommandSpec) -> String {
    match cmd {
        CommandSpec::Argv(argv) => argv.first().cloned().unwrap_or_default(),
        CommandSpec::Shell(_) => std::env::var("COMSPEC").unwrap_or_else(|_| "cmd.exe".into()),
    }
}

fn spawn_error(cmd: &CommandSpec, err: &windows::core::Error) -> DesktopError {
    winsys::win32_code(err.code().0)
        .and_then(|code| winsys::spawn_failure(code, &program_name(cmd)))
        .unwrap_or_else(|| os("CreateProcessW", err))
}

/// One pipe: the end the child inherits and the end this process keeps.
struct Pipe {
    child: OwnedHandle,
    parent: OwnedHandle,
}

/// A pipe whose `child_reads` end (or write end otherwise) is inheritable.
fn pipe(child_reads: bool) -> DesktopResult<Pipe> {
    let sa = SECURITY_ATTRIBUTES {
        nLength: std::mem::size_of::<SECURITY_ATTRIBUTES>() as u32,
        lpSecurityDescriptor: std::ptr::null_mut(),
        bInheritHandle: true.into(),
    };
    let (mut read, mut write) = (HANDLE::default(), HANDLE::default());
    // SAFETY: valid out-pointers and attributes; both handles go to guards at once.
    unsafe { CreatePipe(&mut read, &mut write, Some(&sa), 0) }.map_err(|err| os("CreatePipe", &err))?;
    let read = OwnedHandle::new(read)
        .ok_or_else(|| DesktopError::Os { op: "CreatePipe", message: "no read handle".into() })?;
    let write = OwnedHandle::new(write)
        .ok_or_else(|| DesktopError::Os { op: "CreatePipe", message: "no write handle".into() })?;
    let (child, parent) = if child_reads { (read, write) } else { (write, read) };
    // SAFETY: the handle is live; this only clears its inherit flag.
    unsafe { SetHandleInformation(parent.raw(), HANDLE_FLAG_INHERIT.0, HANDLE_FLAGS(0)) }
        .map_err(|err| os("SetHandleInformation", &err))?;
    Ok(Pipe { child, parent })
}

/// A `PROC_THREAD_ATTRIBUTE_HANDLE_LIST`: the only handles a child may inherit.
/// The list points into `handles`, so both live together and the list is deleted first.
struct InheritList {
    /// The initialised list, inside `_storage`'s heap buffer (which a move of the Vec
    /// leaves in place).
    list: LPPROC_THREAD_ATTRIBUTE_LIST,
    /// The attribute list's opaque storage (pointer-aligned).
    _storage: Vec<usize>,
    handles: Vec<HANDLE>,
}

impl InheritList {
    /// A list of `handles` (which must be inheritable), without repeats, which
    /// `CreateProcess` refuses.
    fn new(handles: &[HANDLE]) -> DesktopResult<InheritList> {
        let mut unique: Vec<HANDLE> = Vec::with_capacity(handles.len());
        for handle in handles {
            if !unique.contains(handle) {
                unique.push(*handle);
            }
        }
        let mut size = 0usize;
        // SAFETY: a null list only measures; the expected "buffer too small" error is ignored.
        let _ = unsafe { InitializeProcThreadAttributeList(None, 1, None, &mut size) };
        if size == 0 {
            return Err(super::sys::last_os("InitializeProcThreadAttributeList"));
        }
        let mut storage = vec![0usize; size.div_ceil(std::mem::size_of::<usize>())];
        let list = LPPROC_THREAD_ATTRIBUTE_LIST(storage.as_mut_ptr().cast());
        // SAFETY: `storage` has the measured size and is aligned for the list.
        unsafe { InitializeProcThreadAttributeList(Some(list), 1, None, &mut size) }
            .map_err(|err| os("InitializeProcThreadAttributeList", &err))?;
        // From here on Drop deletes the list.
        let this = InheritList { list, _storage: storage, handles: unique };
        // SAFETY: the list is initialised; the handle array lives in `this` as long as the list.
        unsafe {
            UpdateProcThreadAttribute(
                this.list,
                0,
                PROC_THREAD_ATTRIBUTE_HANDLE_LIST as usize,
                Some(this.handles.as_ptr().cast()),
                std::mem::size_of_val(this.handles.as_slice()),
                None,
                None,
            )
        }
        .map_err(|err| os("UpdateProcThreadAttribute", &err))?;
        Ok(this)
    }
}

impl Drop for InheritList {
    fn drop(&mut self) {
        // SAFETY: the list was initialised in `new` (Self exists only after that) and is deleted once.
        unsafe { DeleteProcThreadAttributeList(self.list) };
    }
}

/// The working directory of `cmd` when the caller gives none: see [`winsys::default_exec_dir`].
fn default_dir(cmd: &CommandSpec) -> Option<String> {
    let system_root = std::env::var("SystemRoot").ok();
    let exe = std::env::current_exe().ok();
    let install_dir = exe.as_deref().and_then(std::path::Path::parent).map(|dir| dir.display().to_string());
    winsys::default_exec_dir(matches!(cmd, CommandSpec::Shell(_)), system_root.as_deref(), install_dir.as_deref())
}

/// A started process.
struct Started {
    process: OwnedHandle,
    thread: OwnedHandle,
    pid: u32,
}

/// `CreateProcessW` with no application name and the command line of `cmd`, in `cwd`
/// or the default folder; with `stdio`, the child inherits those three handles only.
fn create(
    cmd: &CommandSpec,
    cwd: Option<&str>,
    stdio: Option<[HANDLE; 3]>,
    mut flags: PROCESS_CREATION_FLAGS,
) -> DesktopResult<Started> {
    let (line, hide) = command_line(cmd)?;
    let mut line = wide_nul(&line);
    let cwd_wide = cwd.map(str::to_owned).or_else(|| default_dir(cmd)).map(|dir| wide_nul(&dir));
    let inherit = match stdio {
        Some(handles) => match InheritList::new(&handles) {
            Ok(list) => Some(list),
            Err(err) => {
                tracing::debug!(%err, "no handle list: the child inherits every inheritable handle");
                None
            }
        },
        None => None,
    };
    let mut si = STARTUPINFOW { cb: std::mem::size_of::<STARTUPINFOW>() as u32, ..Default::default() };
    if hide {
        si.dwFlags |= STARTF_USESHOWWINDOW;
        si.wShowWindow = SW_HIDE.0 as u16;
    }
    if let Some([stdin, stdout, stderr]) = stdio {
        si.dwFlags |= STARTF_USESTDHANDLES;
        si.hStdInput = stdin;
        si.hStdOutput = stdout;
        si.hStdError = stderr;
    }
    let mut si = STARTUPINFOEXW { StartupInfo: si, lpAttributeList: LPPROC_THREAD_ATTRIBUTE_LIST::default() };
    if let Some(list) = &inherit {
        si.StartupInfo.cb = std::mem::size_of::<STARTUPINFOEXW>() as u32;
        si.lpAttributeList = list.list;
        flags |= EXTENDED_STARTUPINFO_PRESENT;
    }
    let mut pi = PROCESS_INFORMATION::default();
    let cwd_ptr = cwd_wide.as_ref().map_or(PCWSTR::null(), |w| PCWSTR(w.as_ptr()));
    // SAFETY: `line` is a mutable NUL-terminated buffer as CreateProcessW requires; the
    // startup info (extended, with its cb and flag saying so, when a handle list is
    // attached; the list outlives the call) and out-pointer are valid; the handles in
    // `si` are live and inheritable.
    unsafe {
        CreateProcessW(
            PCWSTR::null(),
            Some(PWSTR(line.as_mut_ptr())),
            None,
            None,
            stdio.is_some(),
            flags,
            None,
            cwd_ptr,
            &si.StartupInfo,
            &mut pi,
        )
    }
    .map_err(|err| spawn_error(cmd, &err))?;
    let process = OwnedHandle::new(pi.hProcess)
        .ok_or_else(|| DesktopError::Os { op: "CreateProcessW", message: "no process handle".into() })?;
    let thread = OwnedHandle::new(pi.hThread)
        .ok_or_else(|| DesktopError::Os { op: "CreateProcessW", message: "no thread handle".into() })?;
    Ok(Started { process, thread, pid: pi.dwProcessId })
}

/// A job whose processes all die when `kill_on_close` and the last handle closes.
fn job(kill_on_close: bool) -> DesktopResult<OwnedHandle> {
    // SAFETY: an anonymous job with default security; the handle goes to a guard.
    let job = unsafe { CreateJobObjectW(None, PCWSTR::null()) }.map_err(|err| os("CreateJobObjectW", &err))?;
    let job = OwnedHandle::new(job)
        .ok_or_else(|| DesktopError::Os { op: "CreateJobObjectW", message: "no job handle".into() })?;
    set_kill_on_close(&job, kill_on_close)?;
    Ok(job)
}

fn set_kill_on_close(job: &OwnedHandle, on: bool) -> DesktopResult<()> {
    let mut info = JOBOBJECT_EXTENDED_LIMIT_INFORMATION::default();
    info.BasicLimitInformation.LimitFlags = if on { JOB_OBJECT_LIMIT_KILL_ON_JOB_CLOSE } else { JOB_OBJECT_LIMIT(0) };
    // SAFETY: `info` is the structure the information class names, with its exact size.
    unsafe {
        SetInformationJobObject(
            job.raw(),
            JobObjectExtendedLimitInformation,
            &info as *const _ as *const core::ffi::c_void,
            std::mem::size_of::<JOBOBJECT_EXTENDED_LIMIT_INFORMATION>() as u32,
        )
    }
    .map_err(|err| os("SetInformationJobObject", &err))
}

/// Decodes bytes from the ANSI code page (what `text=True` uses on Windows) and folds newlines.
pub(super) fn decode_ansi(bytes: &[u8]) -> String {
    if bytes.is_empty() {
        return String::new();
    }
    // SAFETY: the input slice is valid; the first call only measures.
    let needed = unsafe { MultiByteToWideChar(CP_ACP, MULTI_BYTE_TO_WIDE_CHAR_FLAGS(0), bytes, None) };
    let Ok(len) = usize::try_from(needed) else {
        return fold_newlines(&String::from_utf8_lossy(bytes));
    };
    let mut wide = vec![0u16; len];
    // SAFETY: `wide` has room for the measured length.
    let written = unsafe { MultiByteToWideChar(CP_ACP, MULTI_BYTE_TO_WIDE_CHAR_FLAGS(0), bytes, Some(&mut wide)) };
    if written <= 0 {
        return fold_newlines(&String::from_utf8_lossy(bytes));
    }
    fold_newlines(&String::from_utf16_lossy(&wide[..written as usize]))
}

/// Output captured by a reader thread.
#[derive(Default)]
struct Captured {
    buf: CappedBuffer,
    done: bool,
}

fn reader(handle: OwnedHandle, cap: u64, name: &str) -> Arc<Mutex<Captured>> {
    let shared = Arc::new(Mutex::new(Captured { buf: CappedBuffer::new(cap), done: false }));
    let out = Arc::clone(&shared);
    // SAFETY: the handle is an owned, open pipe read end; the File takes it over and closes it.
    let mut file = unsafe { std::fs::File::from_raw_handle(handle.into_raw().0 as _) };
    let spawned = std::thread::Builder::new().name(format!("exec-{name}")).spawn(move || {
        let mut chunk = [0u8; 8192];
        loop {
            match file.read(&mut chunk) {
                Ok(0) | Err(_) => break,
                Ok(n) => out.lock().unwrap_or_else(std::sync::PoisonError::into_inner).buf.push(&chunk[..n]),
            }
        }
        out.lock().unwrap_or_else(std::sync::PoisonError::into_inner).done = true;
    });
    if spawned.is_err() {
        shared.lock().unwrap_or_else(std::sync::PoisonError::into_inner).done = true;
    }
    shared
}

fn wait(process: &OwnedHandle, timeout: Duration) -> DesktopResult<bool> {
    let ms = u32::try_from(timeout.as_millis()).unwrap_or(u32::MAX - 1);
    // SAFETY: the process handle is live.
    let res = unsafe { WaitForSingleObject(process.raw(), ms) };
    if res == WAIT_OBJECT_0 {
        Ok(true)
    } else if res == WAIT_TIMEOUT {
        Ok(false)
    } else {
        Err(super::sys::last_os("WaitForSingleObject"))
    }
}

/// Runs `cmd` to completion or its timeout. See the module documentation.
///
/// # Errors
///
/// [`DesktopError::NotFound`] for a missing program or working directory,
/// [`DesktopError::InvalidInput`] for an empty command; OS errors otherwise.
pub(super) fn run(cmd: &CommandSpec, limits: &ExecLimits) -> DesktopResult<ExecOutput> {
    let started_at = Instant::now();
    let job = job(true)?;
    let (started, stdout, stderr, stdin) = {
        let _guard = SPAWN_LOCK.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        let stdin = pipe(true)?;
        let stdout = pipe(false)?;
        let stderr = pipe(false)?;
        let started = create(
            cmd,
            limits.cwd.as_deref(),
            Some([stdin.child.raw(), stdout.child.raw(), stderr.child.raw()]),
            CREATE_SUSPENDED,
        )?;
        // The child ends drop here, inside the lock: only the child holds them now.
        (started, stdout.parent, stderr.parent, stdin.parent)
    };
    // SAFETY: both handles are live; a process that cannot join the job (an old system
    // where the server itself runs in a job) still runs, only its tree is not killed.
    if let Err(err) = unsafe { AssignProcessToJobObject(job.raw(), started.process.raw()) } {
        tracing::warn!(%err, "could not put the child in a job; a timeout will kill only the child itself");
    }
    // SAFETY: the thread handle is the suspended main thread of our child.
    if unsafe { ResumeThread(started.thread.raw()) } == u32::MAX {
        // SAFETY: the process handle is live.
        let _ = unsafe { TerminateProcess(started.process.raw(), 1) };
        return Err(super::sys::last_os("ResumeThread"));
    }
    let out = reader(stdout, limits.max_output_bytes, "stdout");
    let err = reader(stderr, limits.max_output_bytes, "stderr");
    match limits.stdin.clone() {
        Some(bytes) if !bytes.is_empty() => {
            // SAFETY: an owned, open pipe write end; the File takes it over and closes it when done.
            let mut file = unsafe { std::fs::File::from_raw_handle(stdin.into_raw().0 as _) };
            let _ = std::thread::Builder::new().name("exec-stdin".into()).spawn(move || {
                use std::io::Write;
                let _ = file.write_all(&bytes);
            });
        }
        // No input: close the pipe so a program that reads stdin sees its end at once.
        _ => drop(stdin),
    }

    let timeout = Duration::from_millis(limits.timeout_ms);
    let finished = wait(&started.process, timeout)?;
    let timed_out = !finished;
    if timed_out {
        // SAFETY: the job handle is live; this ends every process in it.
        if unsafe { TerminateJobObject(job.raw(), 1) }.is_err() {
            // SAFETY: the process handle is live.
            let _ = unsafe { TerminateProcess(started.process.raw(), 1) };
        }
        let _ = wait(&started.process, Duration::from_secs(5));
    } else {
        // Background programs the child started outlive it, as with Python: stop the
        // job from killing them when its handle closes.
        if let Err(err) = set_kill_on_close(&job, false) {
            tracing::debug!(%err, "could not clear kill-on-close; background programs of the child may be ended");
        }
    }
    let exit_code = if timed_out {
        None
    } else {
        let mut code = 0u32;
        // SAFETY: the process handle is live and the process has exited.
        unsafe { GetExitCodeProcess(started.process.raw(), &mut code) }.map_err(|e| os("GetExitCodeProcess", &e))?;
        Some(code as i32)
    };

    let grace = Instant::now() + READER_GRACE;
    let done = |c: &Arc<Mutex<Captured>>| c.lock().unwrap_or_else(std::sync::PoisonError::into_inner).done;
    while !(done(&out) && done(&err)) && Instant::now() < grace {
        std::thread::sleep(Duration::from_millis(2));
    }
    let take = |c: &Arc<Mutex<Captured>>| {
        let c = c.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        (decode_ansi(&c.buf.bytes), c.buf.truncated)
    };
    let (stdout, stdout_truncated) = take(&out);
    let (stderr, stderr_truncated) = take(&err);
    drop(job);
    Ok(ExecOutput {
        exit_code,
        stdout,
        stderr,
        stdout_truncated,
        stderr_truncated,
        timed_out,
        duration_ms: u64::try_from(started_at.elapsed().as_millis()).unwrap_or(u64::MAX),
    })
}

/// Starts `cmd` without waiting and without a job; returns its process id.
///
/// # Errors
///
/// As [`run`].
pub(super) fn spawn(cmd: &CommandSpec) -> DesktopResult<u32> {
    let started = create(cmd, None, None, PROCESS_CREATION_FLAGS(0))?;
    drop(started.thread);
    drop(started.process);
    Ok(started.pid)
}

/// Opens `path` with its associated program (`ShellExecuteExW` "open", as `os.startfile`),
/// with COM initialised apartment-threaded on this thread for the call, as the shell
/// requires (its handlers are COM objects); `SEE_MASK_NOASYNC` makes the shell finish
/// before COM is uninitialised again.
///
/// # Errors
///
/// [`DesktopError::NotFound`] for a missing file, [`DesktopError::Os`] for no
/// association (see [`winsys::open_failure`]).
pub(super) fn open(path: &str) -> DesktopResult<()> {
    // A thread already in the multithreaded apartment (another part of the server set
    // it up) keeps it: the shell still works there, only without its preferred model.
    let _com = match ComApartment::init(COINIT_APARTMENTTHREADED | COINIT_DISABLE_OLE1DDE) {
        Ok(com) => Some(com),
        Err(err) => {
            tracing::debug!(%err, "COM is already initialised differently on this thread; opening anyway");
            None
        }
    };
    let file = wide_nul(path);
    let verb = wide_nul("open");
    let mut info = SHELLEXECUTEINFOW {
        cbSize: std::mem::size_of::<SHELLEXECUTEINFOW>() as u32,
        fMask: SEE_MASK_NOASYNC,
        lpVerb: PCWSTR(verb.as_ptr()),
        lpFile: PCWSTR(file.as_ptr()),
        nShow: SW_SHOWNORMAL.0,
        ..Default::default()
    };
    // SAFETY: `info` is a SHELLEXECUTEINFOW whose cbSize says so; its strings are
    // NUL-terminated and outlive the call.
    match unsafe { ShellExecuteExW(&mut info) } {
        Ok(()) => Ok(()),
        Err(err) => Err(match winsys::win32_code(err.code().0) {
            Some(code) => winsys::open_failure(code, path),
            None => os("ShellExecuteExW", &err),
        }),
    }
}
