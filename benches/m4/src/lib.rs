//! Instruction counting on QEMU's mps2-an386 (Cortex-M4) for rc10-core's hot paths.
//!
//! QEMU runs with `-icount shift=7,align=off,sleep=off`: every instruction advances the
//! virtual clock by exactly 128 ns, so the CMSDK timer0 (a 25 MHz down-counter at
//! 0x4000_0000) advances by 3.2 ticks per instruction, whatever the host does. A measured
//! region is read as timer ticks, the cost of an empty region is subtracted, and the rest is
//! divided by the ticks per instruction measured on a block of exactly 1000 `nop`s. DWT's
//! cycle counter does not run under QEMU. Output goes through semihosting.
//!
//! This crate touches the timer's registers directly (four volatile accesses); everything it
//! measures is safe code: rc10-core's, and the [`reference`] motors' that the goals are
//! weighed against.
#![no_std]

pub mod reference;

use core::hint::black_box;
use core::sync::atomic::{Ordering, compiler_fence};

const TIMER0_CTRL: *mut u32 = 0x4000_0000 as *mut u32;
const TIMER0_VALUE: *mut u32 = 0x4000_0004 as *mut u32;
const TIMER0_RELOAD: *mut u32 = 0x4000_0008 as *mut u32;

/// Starts timer0 counting down from `u32::MAX` (it wraps after 171 s of virtual time).
pub fn timer_start() {
    // SAFETY: the CMSDK timer0 registers of the mps2-an386 memory map; nothing else uses
    // the timer, and these are plain 32-bit device registers.
    unsafe {
        TIMER0_CTRL.write_volatile(0);
        TIMER0_RELOAD.write_volatile(u32::MAX);
        TIMER0_VALUE.write_volatile(u32::MAX);
        TIMER0_CTRL.write_volatile(1);
    }
}

/// The timer's current value (it counts down).
#[inline(always)]
pub fn timer_now() -> u32 {
    // SAFETY: a read of timer0's VALUE register (see `timer_start`).
    unsafe { TIMER0_VALUE.read_volatile() }
}

/// Timer ticks spent in `f` (uncorrected).
#[inline(always)]
pub fn ticks<R>(f: impl FnOnce() -> R) -> u32 {
    compiler_fence(Ordering::SeqCst);
    let start = timer_now();
    compiler_fence(Ordering::SeqCst);
    black_box(f());
    compiler_fence(Ordering::SeqCst);
    let end = timer_now();
    compiler_fence(Ordering::SeqCst);
    start.wrapping_sub(end)
}

/// Converts timer ticks of measured regions to instructions.
#[derive(Debug, Clone, Copy)]
pub struct Calibration {
    /// Ticks of an empty region (the two timer reads and the fences).
    pub overhead_ticks: u32,
    /// Ticks per instruction × 1000 (3200 at 128 ns per instruction and 25 MHz).
    pub milliticks_per_instruction: u32,
}

impl Calibration {
    /// Measures the empty region and a block of exactly 1000 `nop`s.
    pub fn measure() -> Self {
        let overhead_ticks = (0..16).map(|_| ticks(|| ())).min().unwrap_or(0);
        let nops = (0..16)
            .map(|_| {
                ticks(|| {
                    // SAFETY: 1000 `nop` instructions: no memory, no registers.
                    unsafe {
                        core::arch::asm!(".rept 1000", "nop", ".endr", options(nomem, nostack))
                    }
                })
            })
            .min()
            .unwrap_or(0);
        Self {
            overhead_ticks,
            milliticks_per_instruction: nops.saturating_sub(overhead_ticks).max(1),
        }
    }

    /// Instructions in a region that took `ticks`.
    pub fn instructions(&self, ticks: u32) -> u32 {
        let net = u64::from(ticks.saturating_sub(self.overhead_ticks)) * 1000;
        let per = u64::from(self.milliticks_per_instruction);
        u32::try_from((net + per / 2) / per).unwrap_or(u32::MAX)
    }
}

/// Minimum, median and maximum of a set of samples (sorted in place).
pub fn min_median_max(samples: &mut [u32]) -> (u32, u32, u32) {
    samples.sort_unstable();
    let min = samples.first().copied().unwrap_or(0);
    let max = samples.last().copied().unwrap_or(0);
    let median = samples.get(samples.len() / 2).copied().unwrap_or(0);
    (min, median, max)
}
