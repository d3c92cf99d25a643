//! The library behind `cargo xtask`: the tasks' logic, so that tests and doctests can reach it.
//!
//! - [`reproduce`]: `cargo xtask reproduce`, the paper's tables on our data sets.
//! - [`crates_guide`]: `docs/crates.md`, whose examples run as this crate's doctests.

pub mod reproduce;

#[doc = include_str!("../../docs/crates.md")]
pub mod crates_guide {}
