//! Mutations and targets of `tests/fuzz_readers.rs`.

pub mod mutate;
pub mod targets;
