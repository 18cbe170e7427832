//! The input check (`arena-inputcheck`): input you can prove.
//!
//! A catalogue of input intents, written once as data, each with the exact events a
//! window must receive and its expression in every action space that can express it;
//! the run that sends each through the host's own translation to a guest where the
//! input recorder (`arena-input-recorder`, or the stub's model of it) writes what its
//! window received; and the comparison of the two.
//!
//! # Layout
//!
//! - [`expect`]: the notation of expected events (`kd shift +shift`, `down left 400,300`).
//! - [`compare`]: expected against received, and the recorder's log cut into cases.
//! - [`catalogue`]: the built-in catalogue (`catalogue.json`), its reading, and the
//!   translation of a case into steps through `arena_actionspace::parse`.
//! - [`drive`]: the run against a guest and its [`Report`].
//! - [`guest`]: the run as `arena doctor --input` makes it ([`check_guest`]): the
//!   guest's defaults, and the host's executor as the [`StepRunner`].
//!
//! It does no I/O of its own but through the guest client, and carries out steps only
//! through a [`StepRunner`]: the host's executor ([`Executor`]) or one a test gives.

#![forbid(unsafe_code)]

pub mod catalogue;
pub mod compare;
pub mod drive;
pub mod expect;
pub mod guest;

pub use catalogue::{Case, Catalogue, Check, WineException};
pub use drive::{
    default_log, default_recorder, run_check, CheckError, CheckOptions, Mismatch, Report, StepRunner, Tally,
    OEM_RECORDER, RECORDER_TITLE, STUB_RECORDER,
};
pub use guest::{check_guest, resolve, Executor, GuestCheck};

#[cfg(test)]
mod tests;
