//! Fuzzes the script parser (`rustpython-parser` and the lowering into the
//! interpreter's tree): on any UTF-8 input it must return (a program or a
//! `ParseError` with a line and column inside the input), never panic, hang or
//! overflow the stack.

#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|src: &str| {
    if let Err(err) = arena_script::parse(src) {
        // Positions are 1-based and never beyond the end of the input.
        let breaks = src.matches(['\n', '\r']).count();
        assert!(err.line >= 1 && err.column >= 1, "{err:?}");
        assert!(err.line <= breaks + 2, "{err:?} for {breaks} line breaks");
    }
});
