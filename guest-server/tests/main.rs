//! The integration suites of `arena-guest` as one test binary (each module is one
//! suite; its file says what it covers): one link of the crate and its
//! dependencies where a binary per file linked them each. `guards` stays a
//! binary of its own: its counting allocator measures the whole process, so no
//! other suite may run beside it.

pub mod devtools_ws;
pub mod harness;
pub mod native_routes;
pub mod python_corpus;
pub mod serve;
pub mod waa_routes;
