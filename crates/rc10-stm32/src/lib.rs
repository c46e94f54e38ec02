//! The Embassy adapter of rc10 for STM32G4 boards.
//!
//! This crate is a skeleton: the FDCAN transport, the scheduler and receiver tasks and the
//! input drivers arrive with the STM32 adapter work. It is built for `thumbv7em-none-eabihf`
//! only (it is not a default workspace member, so host `cargo test` never builds it).
#![no_std]
#![forbid(unsafe_code)]
#![deny(missing_docs)]

pub use rc10_core;
