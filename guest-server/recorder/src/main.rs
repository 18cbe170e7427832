//! `arena-input-recorder LOG [--x N] [--y N] [--width N] [--height N] [--title TEXT]`:
//! opens a top-level window (by default over the whole primary screen, topmost) that
//! writes every input message it receives to `LOG` as JSON lines
//! (`arena_shared::input_log`), until it is closed. Elsewhere than Windows it says that
//! it is Windows-only and exits 2.
//!
//! A GUI-subsystem program: started by the guest, no console window opens beside it.

#![windows_subsystem = "windows"]
#![forbid(unsafe_code)]

use std::process::ExitCode;

fn main() -> ExitCode {
    let options = match arena_input_recorder::Options::parse(std::env::args().skip(1)) {
        Ok(options) => options,
        Err(err) => {
            eprintln!("error: {err}\n{}", arena_input_recorder::USAGE);
            return ExitCode::from(2);
        }
    };
    match arena_input_recorder::windows::run(&options) {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("error: {err}");
            ExitCode::from(if arena_input_recorder::windows::IS_WINDOWS { 1 } else { 2 })
        }
    }
}
