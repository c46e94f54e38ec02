//! Host simulator for rc10.
//!
//! This crate is a skeleton: the simulated CAN bus, the motor plants, the scenarios and the
//! command-line runner are being built (see the project's CHANGELOG). It depends on
//! `rc10-core` so that it runs the same scheduler, motors and controllers as the firmware.
#![forbid(unsafe_code)]
#![deny(missing_docs)]

/// The rc10-core version this simulator drives.
pub const CORE_VERSION: &str = env!("CARGO_PKG_VERSION");
