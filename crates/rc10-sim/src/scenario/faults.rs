//! Injected faults: what they are, and how they change the plants, the bus and the receive path.

use super::Scenario;
use crate::bus::SimBus;
use crate::plant::DjiEsc;

/// An injected fault.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Fault {
    /// The motor's ESC loses power (referee cut) in `[from_ms, to_ms)`.
    PowerCut {
        /// Motor index.
        motor: usize,
        /// Start, ms.
        from_ms: u64,
        /// End, ms.
        to_ms: u64,
    },
    /// The rotor is locked in `[from_ms, to_ms)`.
    Stall {
        /// Motor index.
        motor: usize,
        /// Start, ms.
        from_ms: u64,
        /// End, ms.
        to_ms: u64,
    },
    /// The winding is forced to `celsius` at `at_ms`.
    OverTemperature {
        /// Motor index.
        motor: usize,
        /// When, ms.
        at_ms: u64,
        /// Temperature, °C.
        celsius: f64,
    },
    /// Each frame on the wire is lost with `probability` in `[from_ms, to_ms)`.
    FrameLoss {
        /// Probability per frame, 0–1.
        probability: f64,
        /// Start, ms.
        from_ms: u64,
        /// End, ms.
        to_ms: u64,
    },
    /// Frames reach the controller `delay_us` late in `[from_ms, to_ms)` (a slow receive path).
    Delay {
        /// Extra latency, µs.
        delay_us: u64,
        /// Start, ms.
        from_ms: u64,
        /// End, ms.
        to_ms: u64,
    },
    /// The controller's receive path (its RX interrupt) is blocked in `[from_ms, to_ms)`:
    /// frames wait in the 3-deep RX FIFO, later ones are dropped and reported to rc10 as
    /// overruns, and the FIFO drains when the stall ends.
    RxStall {
        /// Start, ms.
        from_ms: u64,
        /// End, ms.
        to_ms: u64,
    },
    /// The controller is bus-off in `[from_ms, to_ms)`: it sends and receives nothing.
    BusOff {
        /// Start, ms.
        from_ms: u64,
        /// End, ms.
        to_ms: u64,
    },
    /// Each frame arrives with a wrong DLC with `probability` in `[from_ms, to_ms)`.
    Corruption {
        /// Probability per frame, 0–1.
        probability: f64,
        /// Start, ms.
        from_ms: u64,
        /// End, ms.
        to_ms: u64,
    },
}

/// Whether `t_ms` lies in `[from_ms, to_ms)`.
pub(super) fn in_window(t_ms: u64, from_ms: u64, to_ms: u64) -> bool {
    (from_ms..to_ms).contains(&t_ms)
}

/// Whether the controller's receive path is stalled at `t_ms`.
pub(super) fn rx_stalled(scenario: &Scenario, t_ms: u64) -> bool {
    scenario
        .faults
        .iter()
        .any(|f| matches!(*f, Fault::RxStall { from_ms, to_ms } if in_window(t_ms, from_ms, to_ms)))
}

/// The receive delay in force at `t_ms`, µs.
pub(super) fn delay_us(scenario: &Scenario, t_ms: u64) -> u64 {
    scenario
        .faults
        .iter()
        .filter_map(|f| match *f {
            Fault::Delay {
                delay_us,
                from_ms,
                to_ms,
            } if in_window(t_ms, from_ms, to_ms) => Some(delay_us),
            _ => None,
        })
        .max()
        .unwrap_or(0)
}

/// Applies the faults that set a state (bus-off, power cut, stall, over-temperature) at `t_ms`;
/// one-shot faults fire only `on_ms_edge`.
pub(super) fn apply_state_faults(
    scenario: &Scenario,
    bus: &mut SimBus,
    escs: &mut [DjiEsc],
    t_ms: u64,
    on_ms_edge: bool,
) {
    for fault in &scenario.faults {
        match *fault {
            Fault::BusOff { from_ms, to_ms } => {
                bus.set_mcu_bus_off(in_window(t_ms, from_ms, to_ms));
            }
            Fault::PowerCut {
                motor,
                from_ms,
                to_ms,
            } => {
                if let Some(esc) = escs.get_mut(motor) {
                    esc.set_powered(!in_window(t_ms, from_ms, to_ms));
                }
            }
            Fault::Stall {
                motor,
                from_ms,
                to_ms,
            } => {
                if let Some(esc) = escs.get_mut(motor) {
                    esc.set_locked(in_window(t_ms, from_ms, to_ms));
                }
            }
            Fault::OverTemperature {
                motor,
                at_ms,
                celsius,
            } if on_ms_edge && t_ms == at_ms => {
                if let Some(esc) = escs.get_mut(motor) {
                    esc.set_temperature_c(celsius);
                }
            }
            _ => {}
        }
    }
}
