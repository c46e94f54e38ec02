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
    /// Each frame on the wire is lost with `probability` in `[from_ms, to_ms)`: it takes
    /// its time on the bus and reaches nobody, and is not sent again. On a real bus a frame
    /// spoiled by noise is answered with an error frame and retransmitted by the controller,
    /// so this is what reaches the software when that fails too (a frame dropped in a busy
    /// ESC or a saturated receive path): a stress on rc10's timeouts and counters, not a
    /// model of the wire's error handling.
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
    /// frames wait in the two 3-deep RX FIFOs (each motor's feedback in the FIFO rc10's
    /// filter plan gives it), later ones are dropped, and when the stall ends the receiver
    /// reports one overrun to rc10 if any were dropped, then reads FIFO 0, then FIFO 1.
    RxStall {
        /// Start, ms.
        from_ms: u64,
        /// End, ms.
        to_ms: u64,
    },
    /// The controller is bus-off in `[from_ms, to_ms)`: it sends and receives nothing, and
    /// refuses new frames; those already in its TX buffers go out when it recovers.
    BusOff {
        /// Start, ms.
        from_ms: u64,
        /// End, ms.
        to_ms: u64,
    },
    /// Each frame arrives with a wrong DLC with `probability` in `[from_ms, to_ms)`. The
    /// wire's CRC would catch a corrupted DLC; this stands for a malformed frame that is
    /// valid on the wire (a device's firmware fault, a foreign node on a reused ID), which
    /// rc10 must reject and count rather than parse.
    Corruption {
        /// Probability per frame, 0–1.
        probability: f64,
        /// Start, ms.
        from_ms: u64,
        /// End, ms.
        to_ms: u64,
    },
    /// No node acknowledges the controller in `[from_ms, to_ms)` (the other nodes unpowered,
    /// or the wire to them broken): its frames are retransmitted without end and stay in its
    /// 3 TX buffers, so `try_send` reports them full and every tick finds them still queued;
    /// its status reads error-passive with an ACK error; it receives nothing. The frames
    /// held leave when the window ends. See [`SimBus::set_mcu_no_ack`].
    NoAck {
        /// Start, ms.
        from_ms: u64,
        /// End, ms.
        to_ms: u64,
    },
    /// The scheduler task is held up in `[from_ms, to_ms)` (a higher-priority task, a
    /// debugger): the ticks due then do not run; the next runs at `to_ms`, late, and rc10's
    /// tick pacing skips the missed ones instead of running them back to back.
    SchedulerStall {
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

/// If the scheduler is held up at `t_ms`, the end of that hold-up (ms): the time it runs
/// again, after every overlapping or adjoining stall.
pub(super) fn scheduler_stall_end(scenario: &Scenario, t_ms: u64) -> Option<u64> {
    let mut end = None;
    let mut t = t_ms;
    while let Some(to) = scenario.faults.iter().find_map(|f| match *f {
        Fault::SchedulerStall { from_ms, to_ms } if in_window(t, from_ms, to_ms) => Some(to_ms),
        _ => None,
    }) {
        end = Some(to);
        t = to;
    }
    end
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

/// A motor's bit in a mask of motors (none beyond the 64th).
fn motor_bit(motor: usize) -> u64 {
    u32::try_from(motor)
        .ok()
        .and_then(|m| 1u64.checked_shl(m))
        .unwrap_or(0)
}

/// Applies the faults that set a state (bus-off, no acknowledgement, power cut, stall,
/// over-temperature) for millisecond `t_ms`: call it once, at that millisecond's start,
/// after the plants have been stepped up to it (the windows are whole milliseconds; a
/// second call would force an over-temperature again). A state is on while any of its
/// windows is: a motor can be cut twice, the bus go off twice.
pub(super) fn apply_state_faults(
    scenario: &Scenario,
    bus: &mut SimBus,
    escs: &mut [DjiEsc],
    t_ms: u64,
) {
    // Which states some fault sets (`has_*`, bit masks of motors) and which are on now.
    let (mut has_bus_off, mut bus_off, mut has_no_ack, mut no_ack) = (false, false, false, false);
    let (mut cut, mut unpowered, mut stalled, mut locked) = (0u64, 0u64, 0u64, 0u64);
    for fault in &scenario.faults {
        match *fault {
            Fault::BusOff { from_ms, to_ms } => {
                has_bus_off = true;
                bus_off |= in_window(t_ms, from_ms, to_ms);
            }
            Fault::NoAck { from_ms, to_ms } => {
                has_no_ack = true;
                no_ack |= in_window(t_ms, from_ms, to_ms);
            }
            Fault::PowerCut {
                motor,
                from_ms,
                to_ms,
            } => {
                cut |= motor_bit(motor);
                if in_window(t_ms, from_ms, to_ms) {
                    unpowered |= motor_bit(motor);
                }
            }
            Fault::Stall {
                motor,
                from_ms,
                to_ms,
            } => {
                stalled |= motor_bit(motor);
                if in_window(t_ms, from_ms, to_ms) {
                    locked |= motor_bit(motor);
                }
            }
            Fault::OverTemperature {
                motor,
                at_ms,
                celsius,
            } if t_ms == at_ms => {
                if let Some(esc) = escs.get_mut(motor) {
                    esc.set_temperature_c(celsius);
                }
            }
            _ => {}
        }
    }
    if has_bus_off {
        bus.set_mcu_bus_off(bus_off);
    }
    if has_no_ack {
        bus.set_mcu_no_ack(no_ack);
    }
    for (i, esc) in escs.iter_mut().enumerate() {
        let bit = motor_bit(i);
        if cut & bit != 0 {
            let powered = unpowered & bit == 0;
            if esc.powered() && !powered {
                // An unpowered ESC sends nothing: not the feedback it had queued, nor the
                // rest of a frame it was sending.
                bus.power_off_device(i);
            }
            esc.set_powered(powered);
        }
        if stalled & bit != 0 {
            esc.set_locked(locked & bit != 0);
        }
    }
}
