//! The job object that holds an exec agent and every process it starts (Windows
//! hosts), through `windows-sys` (Microsoft's Win32 bindings): created with
//! `JOB_OBJECT_LIMIT_KILL_ON_JOB_CLOSE` and no breakaway, so that terminating it
//! or closing its last handle ends them all. The agent is created suspended and
//! resumed only once it is inside the job: nothing it starts can be born outside.
//!
//! The calls and their contracts are Microsoft's (Win32 API reference: Job
//! Objects, `CreateJobObjectW`, `SetInformationJobObject`,
//! `AssignProcessToJobObject`, `TerminateJobObject`; Tool Help, `Thread32First`).

use std::os::windows::io::{AsRawHandle, FromRawHandle, OwnedHandle, RawHandle};

use windows_sys::Win32::Foundation::{HANDLE, INVALID_HANDLE_VALUE};
use windows_sys::Win32::System::Diagnostics::ToolHelp::{
    CreateToolhelp32Snapshot, Thread32First, Thread32Next, TH32CS_SNAPTHREAD, THREADENTRY32,
};
use windows_sys::Win32::System::JobObjects::{
    AssignProcessToJobObject, CreateJobObjectW, JobObjectExtendedLimitInformation, SetInformationJobObject,
    TerminateJobObject, JOBOBJECT_EXTENDED_LIMIT_INFORMATION, JOB_OBJECT_LIMIT_KILL_ON_JOB_CLOSE,
};
use windows_sys::Win32::System::Threading::{OpenThread, ResumeThread, CREATE_SUSPENDED, THREAD_SUSPEND_RESUME};

/// The exit code of the processes a job ends (what `taskkill /f` gives).
const KILLED: u32 = 1;

/// Creates the agent's process suspended: it runs once [`Job::adopt`] has put
/// it in its job.
pub fn start_suspended(command: &mut tokio::process::Command) {
    command.creation_flags(CREATE_SUSPENDED);
}

/// One agent's job object. Dropping it closes the handle, which ends the
/// processes still in the job (this is the only handle: it is not inheritable).
#[derive(Debug)]
pub struct Job {
    handle: OwnedHandle,
}

impl Job {
    /// Puts the suspended process `child` in a new job and resumes it; on
    /// failure the process is killed and the error says which call failed.
    ///
    /// # Errors
    ///
    /// The job cannot be created or configured (`CreateJobObjectW`,
    /// `SetInformationJobObject`), the process cannot be put in it (a host
    /// whose own job forbids nesting, before Windows 8), or not resumed.
    pub fn adopt(child: &mut tokio::process::Child) -> Result<Job, String> {
        let adopted = match child.raw_handle() {
            Some(process) => Job::new().and_then(|job| job.hold(process).map(|()| job)),
            None => Err("the agent process has already exited".to_owned()),
        };
        match (adopted, child.id()) {
            (Ok(job), Some(pid)) => resume(pid).map(|()| job),
            (Ok(_), None) => Err("the agent process has already exited".to_owned()),
            (Err(err), _) => Err(err),
        }
        .inspect_err(|_| {
            // A suspended process that is never resumed would hold its pipes forever.
            let _ = child.start_kill();
        })
        .map_err(|err| format!("the agent's job object: {err}"))
    }

    /// A new job whose processes end when its last handle closes.
    fn new() -> Result<Job, String> {
        // SAFETY: null attributes (a handle that is not inherited, default security)
        // and a null name (an unnamed job) are documented arguments.
        let raw = unsafe { CreateJobObjectW(std::ptr::null(), std::ptr::null()) };
        if raw.is_null() {
            return Err(format!("CreateJobObjectW: {}", std::io::Error::last_os_error()));
        }
        // SAFETY: `raw` is a handle CreateJobObjectW just returned, owned by nothing else.
        let handle = unsafe { OwnedHandle::from_raw_handle(raw as RawHandle) };
        let mut limits = JOBOBJECT_EXTENDED_LIMIT_INFORMATION::default();
        limits.BasicLimitInformation.LimitFlags = JOB_OBJECT_LIMIT_KILL_ON_JOB_CLOSE;
        let size = u32::try_from(std::mem::size_of_val(&limits)).unwrap_or(u32::MAX);
        // SAFETY: `handle` is a live job handle; the pointer and size describe
        // `limits`, the structure this information class takes, which outlives the call.
        let set = unsafe {
            SetInformationJobObject(
                handle.as_raw_handle() as HANDLE,
                JobObjectExtendedLimitInformation,
                std::ptr::from_ref(&limits).cast(),
                size,
            )
        };
        if set == 0 {
            return Err(format!("SetInformationJobObject: {}", std::io::Error::last_os_error()));
        }
        Ok(Job { handle })
    }

    /// Puts the process whose handle is `process` in this job.
    fn hold(&self, process: RawHandle) -> Result<(), String> {
        // SAFETY: both are live handles: the job's, owned by `self`, and the
        // process's, owned by the `Child` the caller borrows for this call.
        let assigned = unsafe { AssignProcessToJobObject(self.handle.as_raw_handle() as HANDLE, process as HANDLE) };
        if assigned == 0 {
            return Err(format!("AssignProcessToJobObject: {}", std::io::Error::last_os_error()));
        }
        Ok(())
    }

    /// Ends every process in the job now.
    pub fn end(&self) {
        // SAFETY: the job's handle is live (owned by `self`); a job already
        // empty is not an error.
        unsafe {
            TerminateJobObject(self.handle.as_raw_handle() as HANDLE, KILLED);
        }
    }
}

/// Resumes the threads of the suspended process `pid` (one, its first, as
/// `CREATE_SUSPENDED` leaves it), found through a Tool Help snapshot.
fn resume(pid: u32) -> Result<(), String> {
    // SAFETY: a flag and a process id; the snapshot handle is checked next.
    let raw = unsafe { CreateToolhelp32Snapshot(TH32CS_SNAPTHREAD, 0) };
    if raw == INVALID_HANDLE_VALUE || raw.is_null() {
        return Err(format!("CreateToolhelp32Snapshot: {}", std::io::Error::last_os_error()));
    }
    // SAFETY: `raw` is the snapshot handle just returned, owned by nothing else.
    let snapshot = unsafe { OwnedHandle::from_raw_handle(raw as RawHandle) };
    let mut entry = THREADENTRY32 {
        dwSize: u32::try_from(std::mem::size_of::<THREADENTRY32>()).unwrap_or(u32::MAX),
        ..THREADENTRY32::default()
    };
    let mut resumed = 0u32;
    // SAFETY: a live snapshot handle and an entry whose `dwSize` is set, as Thread32First requires.
    let mut more = unsafe { Thread32First(snapshot.as_raw_handle() as HANDLE, &mut entry) } != 0;
    while more {
        if entry.th32OwnerProcessID == pid {
            // SAFETY: an access right, FALSE (not inherited) and a thread id; the handle is checked next.
            let thread = unsafe { OpenThread(THREAD_SUSPEND_RESUME, 0, entry.th32ThreadID) };
            if !thread.is_null() {
                // SAFETY: `thread` is the handle just opened, owned by nothing else.
                let thread = unsafe { OwnedHandle::from_raw_handle(thread as RawHandle) };
                // SAFETY: a live thread handle opened with THREAD_SUSPEND_RESUME.
                if unsafe { ResumeThread(thread.as_raw_handle() as HANDLE) } != u32::MAX {
                    resumed += 1;
                }
            }
        }
        // SAFETY: as for Thread32First.
        more = unsafe { Thread32Next(snapshot.as_raw_handle() as HANDLE, &mut entry) } != 0;
    }
    if resumed == 0 {
        return Err(format!("no thread of process {pid} could be resumed: {}", std::io::Error::last_os_error()));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use tokio::io::AsyncBufReadExt;
    use windows_sys::Win32::Foundation::WAIT_OBJECT_0;
    use windows_sys::Win32::System::JobObjects::{JobObjectBasicProcessIdList, QueryInformationJobObject};
    use windows_sys::Win32::System::Threading::{
        OpenProcess, QueryFullProcessImageNameW, WaitForSingleObject, PROCESS_NAME_WIN32,
        PROCESS_QUERY_LIMITED_INFORMATION, PROCESS_SYNCHRONIZE,
    };

    /// `JOBOBJECT_BASIC_PROCESS_ID_LIST` with room for 64 ids.
    #[repr(C)]
    struct IdList {
        assigned: u32,
        listed: u32,
        ids: [usize; 64],
    }

    /// The processes in `job` now.
    fn members(job: &Job) -> Vec<u32> {
        let mut list = IdList { assigned: 0, listed: 0, ids: [0; 64] };
        let size = u32::try_from(std::mem::size_of::<IdList>()).expect("size");
        // SAFETY: a live job handle and a buffer of `size` bytes laid out as the class requires.
        let ok = unsafe {
            QueryInformationJobObject(
                job.handle.as_raw_handle() as HANDLE,
                JobObjectBasicProcessIdList,
                std::ptr::from_mut(&mut list).cast(),
                size,
                std::ptr::null_mut(),
            )
        };
        assert_ne!(ok, 0, "QueryInformationJobObject: {}", std::io::Error::last_os_error());
        let listed = usize::try_from(list.listed).expect("count").min(list.ids.len());
        list.ids[..listed].iter().map(|&id| u32::try_from(id).expect("a process id")).collect()
    }

    /// The program of process `pid`, lowercase (empty when it cannot be read).
    fn program(pid: u32) -> String {
        // SAFETY: an access right, FALSE (not inherited) and a process id; the handle is checked next.
        let raw = unsafe { OpenProcess(PROCESS_QUERY_LIMITED_INFORMATION, 0, pid) };
        if raw.is_null() {
            return String::new();
        }
        // SAFETY: `raw` is the handle just opened, owned by nothing else.
        let process = unsafe { OwnedHandle::from_raw_handle(raw as RawHandle) };
        let mut name = [0u16; 1024];
        let mut len = 1024u32;
        // SAFETY: a live process handle with the right to query; `name` holds `len` UTF-16 units.
        let ok = unsafe {
            QueryFullProcessImageNameW(
                process.as_raw_handle() as HANDLE,
                PROCESS_NAME_WIN32,
                name.as_mut_ptr(),
                &mut len,
            )
        };
        if ok == 0 {
            return String::new();
        }
        String::from_utf16_lossy(&name[..usize::try_from(len).unwrap_or(0).min(name.len())]).to_lowercase()
    }

    /// Whether process `pid` has ended, waiting up to 10 s for it (it ends at
    /// once when the job works: the wait only bounds a failure).
    fn ended(pid: u32) -> bool {
        // SAFETY: an access right, FALSE (not inherited) and a process id; the handle is checked next.
        let raw = unsafe { OpenProcess(PROCESS_SYNCHRONIZE, 0, pid) };
        if raw.is_null() {
            // No such process any more.
            return true;
        }
        // SAFETY: `raw` is the handle just opened, owned by nothing else.
        let process = unsafe { OwnedHandle::from_raw_handle(raw as RawHandle) };
        // SAFETY: a live process handle opened with SYNCHRONIZE.
        unsafe { WaitForSingleObject(process.as_raw_handle() as HANDLE, 10_000) == WAIT_OBJECT_0 }
    }

    /// Starts `agent.cmd` (a plain child, one started with `start /b`, one in a
    /// new console with `start`) in its job, the way `tree` starts an exec
    /// agent, and answers the job and every process in it once all are running.
    async fn agent_with_children(dir: &std::path::Path) -> (tokio::process::Child, Job, Vec<u32>) {
        let script = dir.join("agent.cmd");
        let long = "ping -n 1000 127.0.0.1 >nul";
        std::fs::write(
            &script,
            format!("@echo off\r\nstart /b {long}\r\nstart \"new console\" /min {long}\r\necho ready\r\n{long}\r\n"),
        )
        .expect("script written");
        let mut command = tokio::process::Command::new("cmd");
        command.arg("/c").arg(&script).stdout(std::process::Stdio::piped()).kill_on_drop(true);
        start_suspended(&mut command);
        let mut child = command.spawn().expect("cmd starts");
        let job = Job::adopt(&mut child).expect("in a job");
        let stdout = child.stdout.take().expect("stdout");
        let mut line = String::new();
        tokio::io::BufReader::new(stdout).read_line(&mut line).await.expect("a line");
        assert_eq!(line.trim(), "ready", "the agent ran after being resumed");
        // The three pings, each in the job (`start` returns once its program runs;
        // the plain one starts after "ready").
        let pings = |inside: &[u32]| inside.iter().filter(|&&pid| program(pid).ends_with("ping.exe")).count();
        let mut inside = members(&job);
        for _ in 0..500 {
            if pings(&inside) >= 3 {
                break;
            }
            tokio::time::sleep(std::time::Duration::from_millis(20)).await;
            inside = members(&job);
        }
        let named: Vec<String> = inside.iter().map(|&pid| format!("{pid} {}", program(pid))).collect();
        assert_eq!(pings(&inside), 3, "the three children in the agent's job: {named:?}");
        assert!(inside.contains(&child.id().expect("running")), "the agent in its job: {named:?}");
        (child, job, inside)
    }

    #[tokio::test]
    async fn ending_the_job_ends_the_agent_and_every_child() {
        let dir = tempfile::tempdir().expect("a folder");
        let (mut child, job, inside) = agent_with_children(dir.path()).await;
        job.end();
        let _ = child.wait().await;
        for pid in inside {
            assert!(ended(pid), "process {pid} outlived its agent's job");
        }
    }

    #[tokio::test]
    async fn closing_the_job_ends_them_as_when_this_program_dies() {
        let dir = tempfile::tempdir().expect("a folder");
        let (mut child, job, inside) = agent_with_children(dir.path()).await;
        // The system closes a dead program's handles: the same as this drop.
        drop(job);
        let _ = child.wait().await;
        for pid in inside {
            assert!(ended(pid), "process {pid} outlived its agent's closed job");
        }
    }
}
