//! Scenes: one file that says what a database holds and which products to build from it, for
//! `dbms plan` and `dbms build`.

pub mod build;
pub mod file;
pub mod makefile;
pub mod plan;
pub mod snakefile;

pub use file::Scene;
