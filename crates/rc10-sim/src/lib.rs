//! Host simulator for rc10: runs rc10-core's real bus, scheduler and drivers against a
//! simulated CAN bus and physically modelled DJI ESC + motor plants, at the CAN-frame level,
//! in deterministic virtual time.
//!
//! - [`bus`]: the simulated bus (bit timing with stuffing, arbitration, TX buffer limits);
//! - [`plant`]: ESC + motor models (current loop, back-EMF limit, friction, quantised
//!   feedback, temperature);
//! - [`scenario`]: motors, targets and faults, the world loop, and the fault soak's checks
//!   ([`scenario::soak`]);
//! - [`file`](mod@file): scenario files in TOML;
//! - [`metrics`]: step-response figures and the full-current minimum rise time;
//! - [`output`]: metrics table, CSV traces, SVG plots;
//! - [`sweep`]: a scenario run for every combination of candidate loop gains, ranked.
//!
//! ```
//! use rc10_sim::scenario::{builtin, run};
//! let scenario = &builtin()[0]; // M3508 speed step
//! let result = run(scenario).unwrap();
//! let step = result.metrics[0].metrics;
//! assert!(step.overshoot_percent <= 5.0);
//! ```
#![forbid(unsafe_code)]
#![deny(missing_docs)]

pub mod bus;
pub mod file;
pub mod legacy;
pub mod metrics;
pub mod output;
pub mod plant;
pub mod scenario;
pub mod sweep;
/// The small-vector crate [`scenario::MotorSamples`] is built on, for code that builds samples.
pub use smallvec;
#[cfg(test)]
mod test_values;
