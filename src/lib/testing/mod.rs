//! Scenes with known answers, for tests and benchmarks: not part of dbms' API (hidden from its
//! documentation, free to change), and compiled only with the `testing` feature, which every
//! `cargo test` and `cargo bench` turns on (`Cargo.toml`): a release build leaves it out.
//!
//! This module sits above every stage (it imports them; nothing in the library imports it but
//! tests), so a test helper needing a stage's internals does not make that stage depend on
//! another.

pub mod shadow_scene;
pub mod solids;
pub mod tiles;
