//! Shared pieces of rc10's fuzz targets: decoding the fuzz input ([`input`]), independent
//! decoders of every wire format written from the protocol descriptions in SPEC.md and the
//! drivers' module docs, not from rc10-core's code ([`proto`]), and the `bus_dispatch`
//! target's fleet, operations and invariants ([`fleet`], [`ops`], [`model`]), and the remote
//! receivers' stream harness ([`remote`]).
//!
//! Every invariant is an `assert!`: libFuzzer reports a failed assertion like any other
//! panic, as a crash with the input that caused it.

pub mod fleet;
pub mod input;
pub mod model;
pub mod ops;
pub mod proto;
pub mod remote;

/// Bugs the fuzz targets found that are reported and not fixed yet. Each switch keeps its
/// target away from the one input class that triggers the bug, so `fuzz/run --ci` stays
/// useful for everything else; each has an `#[ignore]`d regression test in
/// `crates/rc10-core/tests/it/fuzz_regressions.rs`. When the fix lands: set the switch to
/// `false`, remove the test's `#[ignore]`, and run the target.
pub mod pending {
    /// `DmMotor::new` accepts any finite positive MIT range, but with ranges near `f32::MAX`
    /// the driver's own arithmetic overflows: the speed it reports (rad/s → rpm) or the angle
    /// (rad → degrees) becomes infinite, and `MitCommand::pack` with a range whose span
    /// `2 · max` overflows packs every field as code 0. While pending, the targets keep MIT
    /// ranges below 1e30 (real motors: tens).
    pub const DM_HUGE_RANGES: bool = false;

    /// `MitCommand::pack` clamps each field into its range, so a command with every field at
    /// or beyond its maximum (position ≥ PMAX, velocity ≥ VMAX, kp ≥ 500, kd ≥ 5) and a
    /// torque just below TMAX packs to `FF FF FF FF FF FF FF FB..FE`: the motor reads that as
    /// a special command (clear error / enable / disable / *save position zero*), not as an
    /// MIT command. While pending, the targets accept that one shape from an MIT command.
    pub const DM_MIT_SPECIAL_COLLISION: bool = false;

    /// The largest MIT range the targets use while [`DM_HUGE_RANGES`] is pending.
    pub const DM_RANGE_CAP: f32 = if DM_HUGE_RANGES { 1.0e30 } else { f32::MAX };
}
