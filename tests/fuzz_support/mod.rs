//! Mutations and targets of `tests/fuzz_readers.rs`.

pub mod mutate;
pub mod project_targets;
pub mod targets;
