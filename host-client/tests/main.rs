//! The integration suites of `arena-host` as one test binary (each module is one
//! suite; its file says what it covers): one link of the crate and its
//! dependencies where a binary per file linked them 7 times.

pub mod action_spaces;
pub mod agent;
pub mod cli;
pub mod corpus;
pub mod cu_agents;
pub mod doctor_input;
pub mod oem;
pub mod setup_scripts;
