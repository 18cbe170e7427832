//! An exec agent's processes on a Windows host: a job object per agent, so that
//! everything the agent starts (detached or in a console of its own included)
//! ends with it. [`super::tree`] uses it where Unix uses a process group.
//!
//! - `job` (compiled for Windows only): the agent starts suspended
//!   ([`start_suspended`]), is put into a job object created with
//!   `JOB_OBJECT_LIMIT_KILL_ON_JOB_CLOSE` and then resumed ([`Job::adopt`]), so
//!   that even its first child is born inside the job; ending the job
//!   ([`Job::end`]) or closing its last handle (which the system does when this
//!   program dies, however it dies) ends every process in it. The job allows no
//!   breakaway, so `CREATE_BREAKAWAY_FROM_JOB` cannot take a child out of it.

// Win32 calls through `windows-sys`, each with its SAFETY note.
#[cfg(windows)]
#[allow(unsafe_code)]
mod job;

#[cfg(windows)]
pub use job::{start_suspended, Job};
