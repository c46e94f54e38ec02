#![doc = include_str!("../README.md")]
#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]
#![deny(missing_docs)]
// Every integer operation that could overflow, divide by zero or panic is written as
// wrapping, saturating or checked, or is allowed locally with its bound as the reason (see
// the README's "Panic-free" section). Unit tests may use plain arithmetic.
#![cfg_attr(not(test), deny(clippy::arithmetic_side_effects))]

pub mod bus;
pub mod can;
pub mod chassis;
pub mod encoder;
pub mod filter;
pub mod geometry;
pub mod gimbal;
pub mod math;
pub mod motor;
pub mod node;
pub mod pid;
pub mod remote;
pub mod telemetry;
pub mod time;
