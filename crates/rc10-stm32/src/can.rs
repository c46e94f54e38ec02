//! The FDCAN transport: rc10-core's [`CanTransmit`] and [`CanReceive`] over embassy-stm32's
//! FDCAN driver, plus the start-up that programs the acceptance filters from the registered
//! nodes.
//!
//! Choices, from reading embassy-stm32 0.6's `can/fdcan.rs` and `can/fd/peripheral.rs`:
//!
//! - **TX FIFO mode.** In the driver's default *priority* mode a full queue makes `write`
//!   abort a pending frame, and a pending frame with the same ID is never replaced, so on a
//!   loaded bus a stale command can still go out after a fresh one was refused. In FIFO mode
//!   frames go out in the order the tick packed them, nothing is ever evicted, and a full
//!   FIFO is reported (`SendError::Full`, counted in `tx_full`). Frames still waiting from
//!   an earlier tick are counted at the start of each tick (`tx_stale`): they mean the bus
//!   could not carry a period's commands (congestion, or no node acknowledging).
//! - **Non-blocking send.** `CanTx::write` waits for a free buffer; [`FdcanTx::try_send`]
//!   polls it once with a no-op waker: queued, or `Full`.
//! - **Timestamps.** The driver's `Envelope::ts` is not the hardware reception time (it is
//!   derived at read time, with a tick length that is not the counter's); it is not used.
//!   Frames are stamped with embassy-time when the receiver reads them: up to the receiver's
//!   latency late, which rc10-core's consumers allow for.
//! - **Status in one place.** [`FdcanTx::status`] (once per tick) reports bus-off,
//!   error-passive, the error counters and the number of protocol errors the controller
//!   logged since the last read (`ECR.CEL`, reset by the read), so an error the controller
//!   retried successfully within the millisecond is counted too. `PSR`'s last-error code
//!   shows one error at most and is cleared by the next good frame and by reading it; it
//!   still marks errors that leave `CEL` alone (ACK errors while error-passive). The
//!   driver's own receive path also reads `PSR` when its FIFOs are empty and reports the
//!   code as an error: the receiver reads on instead, so nothing is counted twice. (An ACK
//!   error it consumed that way goes uncounted; ACK errors come from nobody acknowledging,
//!   when nothing is received either.)
//! - **RX overrun.** The driver does not report lost messages. The receiver reads the
//!   FIFOs' message-lost interrupt flags (`IR.RF0L`, `IR.RF1L`) through the register API and
//!   clears them (write-1-to-clear, which touches no other flag), reporting
//!   [`ReceiveError::Overrun`] once per occurrence.
//! - **Bus-off** recovery is automatic (the driver restarts the controller from its
//!   interrupt handler); each entry is counted once by the bus.

use crate::{StartError, status};
use core::cell::Cell;
use core::future::Future;
use core::num::{NonZeroU8, NonZeroU16};
use core::task::{Context, Poll, Waker};
use embassy_stm32::can::config::{GlobalFilter, NominalBitTiming, TxBufferMode};
use embassy_stm32::can::filter::{
    Action, EXTENDED_FILTER_MAX, ExtendedFilter, FilterType, STANDARD_FILTER_MAX, StandardFilter,
};
use embassy_stm32::can::util::calc_can_timings;
use embassy_stm32::can::{CanConfigurator, CanRx, CanTx, Frame};
use embassy_stm32::pac;
use embassy_stm32::time::Hertz;
use embedded_can::Frame as _;
use rc10_core::can::acceptance::{Fifo, FilterElement, FilterPlan};
use rc10_core::can::timing::bit_timing;
use rc10_core::can::{
    BusStatus, CanFrame, CanReceive, CanTransmit, ExtendedId, ReceiveError, Received, SendError,
    StandardId,
};
use rc10_core::time::Instant;

/// Standard-ID filter elements of an STM32G4 FDCAN.
pub const STANDARD_FILTERS: usize = STANDARD_FILTER_MAX as usize;
/// Extended-ID filter elements of an STM32G4 FDCAN.
pub const EXTENDED_FILTERS: usize = EXTENDED_FILTER_MAX as usize;
/// TX buffers of an STM32G4 FDCAN (the bus's `tx_depth`).
pub const TX_BUFFERS: u8 = 3;

/// A filter plan sized for an STM32G4 FDCAN.
pub type G4FilterPlan = FilterPlan<STANDARD_FILTERS, EXTENDED_FILTERS>;

/// Which FDCAN peripheral (for the registers the driver does not expose).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Instance {
    /// FDCAN1.
    Fdcan1,
    /// FDCAN2.
    Fdcan2,
    /// FDCAN3.
    Fdcan3,
}

impl Instance {
    fn regs(self) -> pac::can::Fdcan {
        match self {
            Self::Fdcan1 => pac::FDCAN1,
            Self::Fdcan2 => pac::FDCAN2,
            Self::Fdcan3 => pac::FDCAN3,
        }
    }

    /// The FDCAN kernel clock (`config.rcc.mux.fdcansel`), Hz.
    fn kernel_clock_hz(self) -> u32 {
        use embassy_stm32::peripherals::{FDCAN1, FDCAN2, FDCAN3};
        use embassy_stm32::rcc::frequency;
        match self {
            Self::Fdcan1 => frequency::<FDCAN1>().0,
            Self::Fdcan2 => frequency::<FDCAN2>().0,
            Self::Fdcan3 => frequency::<FDCAN3>().0,
        }
    }
}

/// Configures a FDCAN for rc10 and starts it in normal mode: classic CAN at `bitrate_bps`,
/// TX FIFO mode, automatic bus-off recovery, the acceptance filters of `plan` (everything
/// else rejected in hardware). Returns the two halves for the scheduler and receiver tasks.
///
/// `instance` must name the peripheral the configurator was made from: the transport reads
/// that FDCAN's status, message-lost and pending-buffer registers. `bitrate_bps` should be the
/// bus's own (`BusConfig::bitrate_bps`, which its load figures use): [`crate::start_can`]
/// takes it from the bus.
///
/// The FDCAN kernel clock must be configured (`config.rcc.mux.fdcansel`, e.g. PCLK1) before
/// `CanConfigurator::new`: its default source is HSE, so without HSE enabled it panics at run
/// time (with HSE enabled, the FDCAN runs from the crystal directly).
///
/// The bit timing is [`rc10_core::can::timing::bit_timing`]'s for that clock: at 1 Mbit/s
/// from 170 MHz, 10 quanta sampled at 80 % with a jump width of 2 (from 85 MHz, 17 quanta
/// at 82 %, jump width 3), close to the 78.6 % DJI's RoboMaster boards use. A bitrate no
/// whole number of 8–25 quanta gives falls back to embassy-stm32's search
/// (`can::util::calc_can_timings`: 3 to 10 quanta at 1 Mbit/s, 3 to 17 below, sampled near
/// 87.5 %; it divides the clock by the bitrate rounding down, so from a clock that is not a
/// whole multiple of the bitrate its timing is only near it).
///
/// # Errors
///
/// [`StartError::NoBitTiming`] if neither search finds a timing for `bitrate_bps` from the
/// FDCAN kernel clock (1 Mbit/s from a 170 MHz or 85 MHz clock works): the configurator is
/// dropped unstarted. embassy-stm32's own `set_bitrate` would panic there.
///
/// [`StartError::WrongInstance`] if `instance` is not in configuration, so cannot be the
/// configurator's peripheral (a copy-paste slip such as `Instance::Fdcan1` with FDCAN2's configurator would
/// otherwise read, and clear, another bus's status and message-lost flags); nothing is
/// started. The check cannot tell two configurators alive at once apart: start each bus
/// before making the next one's configurator.
pub fn start(
    mut configurator: CanConfigurator<'static>,
    instance: Instance,
    plan: &G4FilterPlan,
    bitrate_bps: u32,
) -> Result<(FdcanTx, FdcanRx), StartError> {
    let cccr = instance.regs().cccr().read();
    if !status::in_configuration(cccr.init(), cccr.cce()) {
        return Err(StartError::WrongInstance(instance));
    }
    // rc10's timing (sample point 80 %, the widest jump width); embassy-stm32's own search
    // only when no 8–25 quanta give the bitrate exactly. Its `set_bitrate` would panic (and
    // link core::fmt's Debug machinery for its error) when that finds nothing either.
    let kernel_clock_hz = instance.kernel_clock_hz();
    let timing = bit_timing(kernel_clock_hz, bitrate_bps)
        .and_then(|t| {
            Some(NominalBitTiming {
                prescaler: NonZeroU16::new(t.prescaler)?,
                seg1: NonZeroU8::new(t.seg1)?,
                seg2: NonZeroU8::new(t.seg2)?,
                sync_jump_width: NonZeroU8::new(t.sync_jump_width)?,
            })
        })
        .or_else(|| {
            let t = calc_can_timings(Hertz(kernel_clock_hz), bitrate_bps).ok()?;
            Some(NominalBitTiming {
                prescaler: t.prescaler,
                seg1: t.seg1,
                seg2: t.seg2,
                sync_jump_width: t.sync_jump_width,
            })
        })
        .ok_or(StartError::NoBitTiming {
            kernel_clock_hz,
            bitrate_bps,
        })?;
    let config = configurator.config().set_nominal_bit_timing(timing);
    configurator.set_config(config);
    let config = configurator
        .config()
        .set_tx_buffer_mode(TxBufferMode::Fifo)
        .set_automatic_bus_off_recovery(true)
        .set_global_filter(GlobalFilter::reject_all());
    configurator.set_config(config);
    let mut standard = [StandardFilter::disable(); STANDARD_FILTERS];
    for (slot, element) in standard.iter_mut().zip(plan.standard()) {
        *slot = standard_filter(element);
    }
    let mut extended = [ExtendedFilter::disable(); EXTENDED_FILTERS];
    for (slot, element) in extended.iter_mut().zip(plan.extended()) {
        *slot = extended_filter(element);
    }
    configurator.properties().set_standard_filters(&standard);
    configurator.properties().set_extended_filters(&extended);
    let (tx, rx, _properties) = configurator.into_normal_mode().split();
    let regs = instance.regs();
    Ok((
        FdcanTx {
            tx,
            regs,
            bus_off: Cell::new(false),
        },
        FdcanRx {
            rx,
            regs,
            held: None,
        },
    ))
}

fn action(fifo: Fifo) -> Action {
    match fifo {
        Fifo::Fifo0 => Action::StoreInFifo0,
        Fifo::Fifo1 => Action::StoreInFifo1,
    }
}

/// The planned element as an FDCAN standard filter (a disabled one if the plan's IDs do not
/// fit 11 bits, which the plan never produces).
fn standard_filter(element: &FilterElement) -> StandardFilter {
    let std = |id: u32| u16::try_from(id).ok().and_then(StandardId::new);
    let filter = match *element {
        FilterElement::Dual { ids: [a, b], .. } => match (std(a), std(b)) {
            (Some(a), Some(b)) => FilterType::DedicatedDual(a, b),
            _ => FilterType::Disabled,
        },
        FilterElement::Mask { id, mask, .. } => match (u16::try_from(id), u16::try_from(mask)) {
            (Ok(filter), Ok(mask)) => FilterType::BitMask { filter, mask },
            _ => FilterType::Disabled,
        },
    };
    StandardFilter {
        filter,
        action: action(element.fifo()),
    }
}

/// The planned element as an FDCAN extended filter.
fn extended_filter(element: &FilterElement) -> ExtendedFilter {
    let filter = match *element {
        FilterElement::Dual { ids: [a, b], .. } => match (ExtendedId::new(a), ExtendedId::new(b)) {
            (Some(a), Some(b)) => FilterType::DedicatedDual(a, b),
            _ => FilterType::Disabled,
        },
        FilterElement::Mask { id, mask, .. } => FilterType::BitMask { filter: id, mask },
    };
    ExtendedFilter {
        filter,
        action: action(element.fifo()),
    }
}

/// The sending half, for the scheduler task.
pub struct FdcanTx {
    tx: CanTx<'static>,
    regs: pac::can::Fdcan,
    /// Bus-off as of the last `status()` (which the bus reads at the start of each tick's
    /// transmit): while off the bus, new frames are refused rather than queued to go out
    /// stale after recovery. (Frames already queued when the bus went off are not cancelled:
    /// at most three, sent on recovery just before the next tick's.)
    bus_off: Cell<bool>,
}

impl CanTransmit for FdcanTx {
    fn try_send(&mut self, frame: &CanFrame) -> Result<(), SendError> {
        if self.bus_off.get() {
            return Err(SendError::BusOff);
        }
        let Some(out) = to_hal(frame) else {
            return Err(SendError::Full); // unreachable: every CanFrame is a classic frame
        };
        // Polled once with a no-op waker: the driver would otherwise keep the scheduler's
        // waker and wake the control task on every FDCAN interrupt.
        let write = core::pin::pin!(self.tx.write(&out));
        match write.poll(&mut Context::from_waker(Waker::noop())) {
            // In FIFO mode the driver never evicts a pending frame, so `Some` cannot occur.
            Poll::Ready(_) => Ok(()),
            Poll::Pending => Err(SendError::Full),
        }
    }

    fn status(&self) -> BusStatus {
        // The one read of each: reading PSR clears LEC, reading ECR resets CEL.
        let psr = self.regs.psr().read();
        let ecr = self.regs.ecr().read();
        self.bus_off.set(psr.bo());
        status::bus_status(
            psr.bo(),
            psr.ep(),
            psr.lec().to_bits(),
            ecr.cel(),
            ecr.tec(),
            ecr.rec(),
        )
    }

    fn still_queued(&self) -> u8 {
        let pending = self.regs.txbrp().read();
        status::pending_frames([pending.trp(0), pending.trp(1), pending.trp(2)])
    }
}

/// The receiving half, for the receiver task.
pub struct FdcanRx {
    rx: CanRx<'static>,
    regs: pac::can::Fdcan,
    /// A frame read together with a message-lost flag: the overrun is reported first.
    held: Option<Received>,
}

impl FdcanRx {
    /// Whether a FIFO lost a message since the last check; clears the flags it saw.
    fn take_message_lost(&mut self) -> bool {
        let ir = self.regs.ir().read();
        match status::message_lost(ir.rfl(0), ir.rfl(1)) {
            Some(lost) => {
                // Write-1-to-clear: only these two flags change.
                self.regs.ir().write(|w| {
                    w.set_rfl(0, lost[0]);
                    w.set_rfl(1, lost[1]);
                });
                true
            }
            None => false,
        }
    }
}

impl CanReceive for FdcanRx {
    async fn receive(&mut self) -> Result<Received, ReceiveError> {
        if let Some(received) = self.held.take() {
            return Ok(received);
        }
        if self.take_message_lost() {
            return Err(ReceiveError::Overrun);
        }
        loop {
            match self.rx.read().await {
                Ok(envelope) => {
                    let timestamp = Instant::now();
                    let Some(frame) = from_hal(&envelope.frame) else {
                        return Err(ReceiveError::BusError); // unreachable for classic frames
                    };
                    let received = Received { frame, timestamp };
                    if self.take_message_lost() {
                        self.held = Some(received);
                        return Err(ReceiveError::Overrun);
                    }
                    return Ok(received);
                }
                // A protocol error the driver read from PSR.LEC: the transmit side's
                // `status` counts errors from ECR.CEL (every error, once). Read on.
                Err(_protocol_error) => {}
            }
        }
    }
}

/// rc10-core's frame as embassy-stm32's. (embassy-stm32 0.6 sends a remote frame with a
/// non-zero DLC as a data frame; rc10's own nodes send no remote frames.)
pub fn to_hal(frame: &CanFrame) -> Option<Frame> {
    if frame.is_remote() {
        Frame::new_remote(frame.id(), frame.dlc()).ok()
    } else {
        Frame::new_data(frame.id(), frame.data()).ok()
    }
}

/// embassy-stm32's frame as rc10-core's.
pub fn from_hal(frame: &Frame) -> Option<CanFrame> {
    if frame.is_remote_frame() {
        CanFrame::remote(*frame.id(), frame.dlc())
    } else {
        CanFrame::new(*frame.id(), frame.data())
    }
}
