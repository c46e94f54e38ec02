#![doc = include_str!("../README.md")]
#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]
#![deny(missing_docs)]

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
