//! Register values to rc10-core's transport types: pure functions of the bits the FDCAN
//! reports, kept free of embassy-stm32 so the host tests cover them (the `tests/` crate
//! includes this file).

use rc10_core::can::{BusStatus, ErrorState};

/// The status the transport reports, from PSR's bus-off (`BO`) and error-passive (`EP`)
/// flags and last-error code (`LEC`), and ECR's error counters and error log (`CEL`:
/// protocol errors that moved TEC or REC since ECR was last read, stopping at 255).
///
/// The error log counts the errors: `LEC` holds one error, and a frame sent or received
/// without error clears it, so errors the controller retried successfully between two 1 kHz
/// reads would not be seen. `LEC` values 1–6 (stuff, form, ACK, bit 1, bit 0, CRC; 0 is "no
/// error", 7 "no change since the last read") still mark an error where the log does not
/// move: ACK errors while error-passive leave TEC, and so `CEL`, as they are.
pub fn bus_status(
    bus_off: bool,
    error_passive: bool,
    lec: u8,
    cel: u8,
    tec: u8,
    rec: u8,
) -> BusStatus {
    let state = if bus_off {
        ErrorState::BusOff
    } else if error_passive {
        ErrorState::Passive
    } else {
        ErrorState::Active
    };
    BusStatus {
        state,
        tx_error_count: tec,
        rx_error_count: rec,
        protocol_error: cel > 0 || (1..=6).contains(&lec),
        errors_logged: cel,
    }
}

/// Frames waiting in the TX buffers, from TXBRP's transmission-request-pending bits.
pub fn pending_frames(request_pending: [bool; 3]) -> u8 {
    request_pending.iter().map(|p| u8::from(*p)).sum()
}

/// Which RX FIFO message-lost flags (`IR.RF0L`, `IR.RF1L`) to clear, and whether any message
/// was lost.
pub fn message_lost(rf0l: bool, rf1l: bool) -> Option<[bool; 2]> {
    (rf0l || rf1l).then_some([rf0l, rf1l])
}

/// Whether a FDCAN is in configuration (`CCCR.INIT` and `CCCR.CCE` set), as
/// `CanConfigurator::new` leaves the peripheral it was made from: [`crate::can::start`]
/// checks that the instance it is told names that peripheral (one left at reset has `CCE`
/// clear; one already started, `INIT` clear).
pub fn in_configuration(init: bool, cce: bool) -> bool {
    init && cce
}

/// Whether every bus's scheduler has ticked since the last look, from their tick counters
/// (up to three buses, as a G4 has three FDCANs): what the watchdog task feeds the watchdog
/// on. The first look only records the counts.
#[derive(Debug, Default)]
pub struct TickProgress {
    last: [Option<u32>; 3],
}

impl TickProgress {
    /// Nothing seen yet.
    pub const fn new() -> Self {
        Self { last: [None; 3] }
    }

    /// Records `ticks` (each bus's tick count, in a fixed order; beyond three ignored) and
    /// says whether every count moved since the previous call. A counter that wrapped round
    /// moved. The first call, and a call with no buses, say `true`.
    pub fn all_advanced(&mut self, ticks: impl IntoIterator<Item = u32>) -> bool {
        let mut all = true;
        for (last, now) in self.last.iter_mut().zip(ticks) {
            if *last == Some(now) {
                all = false;
            }
            *last = Some(now);
        }
        all
    }
}
