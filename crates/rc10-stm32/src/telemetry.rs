//! VOFA+ telemetry over a UART with DMA: the named channels of rc10-core's
//! [`Channels`] sent as JustFloat frames at a fixed rate.
//!
//! Producers (control loops, any task, any priority) only store values (one atomic word
//! each). The sender snapshots them every period and writes the frame with DMA; when the UART
//! is still busy with the previous frame at the next period, that sample is dropped and
//! counted rather than queued, so telemetry never delays anything and never lags.

use core::sync::atomic::{AtomicU32, Ordering};
use embassy_stm32::mode::Async;
use embassy_stm32::usart::UartTx;
use embassy_time::{Duration, Instant, Ticker};
use rc10_core::bus::TickPacer;
use rc10_core::telemetry::Channels;

/// Largest JustFloat frame sent: 4 bytes per channel plus the 4-byte tail.
pub const MAX_FRAME_BYTES: usize = 4 * 32 + 4;

/// Counters of a [`run_vofa`] sender.
#[derive(Debug, Default)]
pub struct VofaStats {
    sent: AtomicU32,
    dropped: AtomicU32,
    errors: AtomicU32,
}

impl VofaStats {
    /// All zero.
    pub const fn new() -> Self {
        Self {
            sent: AtomicU32::new(0),
            dropped: AtomicU32::new(0),
            errors: AtomicU32::new(0),
        }
    }

    /// Frames written.
    pub fn sent(&self) -> u32 {
        self.sent.load(Ordering::Relaxed)
    }

    /// Samples skipped because the UART was still busy.
    pub fn dropped(&self) -> u32 {
        self.dropped.load(Ordering::Relaxed)
    }

    /// UART write errors.
    pub fn errors(&self) -> u32 {
        self.errors.load(Ordering::Relaxed)
    }
}

/// Sends `channels` as a JustFloat frame every `period` on `tx` (up to 32 channels: more fails
/// the build of the firmware that spawns it).
/// At 921 600 baud a frame of 8 channels (36 bytes) takes 0.4 ms: 1 kHz is possible; 115 200
/// baud manages about 300 Hz.
pub async fn run_vofa<const N: usize>(
    mut tx: UartTx<'static, Async>,
    channels: &Channels<N>,
    period: Duration,
    stats: &VofaStats,
) -> ! {
    const {
        assert!(
            4 * N + 4 <= MAX_FRAME_BYTES,
            "run_vofa sends at most 32 channels"
        )
    };
    let mut ticker = Ticker::every(period);
    let mut pacer = TickPacer::new(period);
    let mut frame = [0u8; MAX_FRAME_BYTES];
    loop {
        ticker.next().await;
        let paced = pacer.on_tick(Instant::now());
        if paced.resync {
            // The previous write took longer than a period: those samples are gone.
            ticker.reset();
            stats.dropped.fetch_add(paced.skipped, Ordering::Relaxed);
        }
        let Ok(len) = channels.encode_justfloat(&mut frame) else {
            stats.errors.fetch_add(1, Ordering::Relaxed); // cannot happen: N ≤ 32 above
            continue;
        };
        match tx.write(frame.get(..len).unwrap_or(&[])).await {
            Ok(()) => stats.sent.fetch_add(1, Ordering::Relaxed),
            Err(_) => stats.errors.fetch_add(1, Ordering::Relaxed),
        };
    }
}
