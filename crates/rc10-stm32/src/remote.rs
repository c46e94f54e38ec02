//! Remote-control inputs on a board: DR16 DBUS and SBUS from a UART with DMA, PPM (RC10's
//! AirJoy) from edge interrupts. Each feeds one of rc10-core's decoders, kept in a
//! [`Shared`] that control tasks read with its failsafe signal.

use embassy_stm32::exti::ExtiInput;
use embassy_stm32::gpio::Pull;
use embassy_stm32::mode::Async;
use embassy_stm32::usart::{self, DataBits, Parity, RingBufferedUartRx, StopBits};
use embassy_time::Duration;
use rc10_core::remote::dbus::DbusReceiver;
use rc10_core::remote::ppm::PpmReceiver;
use rc10_core::remote::sbus::SbusReceiver;
use rc10_core::remote::{FrameReceiver, ReceiverFrame, Shared};
use rc10_core::time::Instant;

/// UART settings of a DJI DR16 receiver's DBUS output: 100 kbaud, 8 data bits, even parity,
/// one stop bit. The line is inverted; set `inverted` unless your board has a hardware
/// inverter in front of the pin (RoboMaster development boards do).
pub fn dbus_config(inverted: bool) -> usart::Config {
    let mut config = usart::Config::default();
    config.baudrate = 100_000;
    config.data_bits = DataBits::DataBits8;
    config.parity = Parity::ParityEven;
    config.stop_bits = StopBits::STOP1;
    config.invert_rx = inverted;
    // An unplugged receiver leaves the pin floating: pull it to the idle level (low on the
    // inverted line, high behind an inverter) so noise is not read as bytes.
    config.rx_pull = if inverted { Pull::Down } else { Pull::Up };
    config
}

/// One DBUS byte on the wire: 11 bits (start, 8 data, parity, stop) at 100 kbaud, in µs.
pub const DBUS_BYTE_US: u64 = 110;
/// One SBUS byte on the wire: 12 bits (two stop bits) at 100 kbaud, in µs.
pub const SBUS_BYTE_US: u64 = 120;

/// UART settings of SBUS: 100 kbaud, 8 data bits, even parity, two stop bits, inverted line
/// (`inverted` as for [`dbus_config`]).
pub fn sbus_config(inverted: bool) -> usart::Config {
    let mut config = dbus_config(inverted);
    config.stop_bits = StopBits::STOP2;
    config
}

/// Reads a byte stream from a DMA ring-buffered UART into `receiver` until the end of time.
///
/// The DMA reports on line idle and at the half and end of its buffer, so a chunk may hold a
/// whole frame or part of one. Each byte is stamped back from the moment the chunk was read:
/// the last byte then, byte `i` of `n` at `read − (n − 1 − i) · byte_time`. Bytes of a frame
/// thus stay `byte_time` apart even when the DMA splits the frame, and the decoder's frame gap
/// ([`FRAME_GAP`](rc10_core::remote::FRAME_GAP), 2.5 ms) finds frame boundaries as long as
/// this task reads each chunk within about 2.3 ms of its end: run it where nothing holds the
/// executor that long (or on an interrupt executor). The silence the decoder sees between
/// two frames is the real one shortened by how much later the first frame's chunk was read
/// than the second's: with SBUS at 7 ms (4 ms of silence), a chunk read more than 1.5 ms late
/// and the next read on time merge two frames, and both are dropped as one burst too long. UART errors (framing, parity, overrun) are
/// counted in [`Shared::input_errors`]; the decoder resynchronises on the next frame gap.
pub async fn run_uart_receiver<F: ReceiverFrame, const N: usize>(
    mut rx: RingBufferedUartRx<'static>,
    receiver: &Shared<FrameReceiver<F, N>>,
    byte_time: Duration,
) -> ! {
    let mut chunk = [0u8; 64];
    loop {
        match rx.read(&mut chunk).await {
            Ok(n) => receiver.push_bytes_ending_at(
                chunk.get(..n).unwrap_or(&[]),
                Instant::now(),
                byte_time,
            ),
            Err(_) => receiver.record_input_error(),
        }
    }
}

/// The DR16 task: one per board. See [`run_uart_receiver`].
#[embassy_executor::task]
pub async fn dbus_task(
    rx: RingBufferedUartRx<'static>,
    receiver: &'static Shared<DbusReceiver>,
) -> ! {
    run_uart_receiver(rx, receiver, Duration::from_micros(DBUS_BYTE_US)).await
}

/// The SBUS task: one per board. See [`run_uart_receiver`].
#[embassy_executor::task]
pub async fn sbus_task(
    rx: RingBufferedUartRx<'static>,
    receiver: &'static Shared<SbusReceiver>,
) -> ! {
    run_uart_receiver(rx, receiver, Duration::from_micros(SBUS_BYTE_US)).await
}

/// PPM (8 channels, RC10_LIB's AirJoy): times the rising edges of the PPM line and feeds the
/// intervals in µs to the decoder. Edge times are read when the task runs after the EXTI
/// interrupt: spawn it on a high-priority executor (the control executor does) so that this
/// is soon after the edge; in thread mode another task's run time would add to it. Even there
/// an edge that comes during a scheduler tick is timed when the tick ends (10–20 µs later per
/// bus: a few percent of a stick's 1000 µs span, for that one frame), and an edge that comes
/// before the task has re-armed the line is missed: two channels then read as one interval,
/// which is a channel (two short ones add up to at most 2250 µs; the frame then has one
/// channel too few), noise, or a false sync gap, and the decoder drops that frame (and the
/// next, after a false sync). Timer input capture would give
/// hardware edge times; this adapter does not use it yet.
#[embassy_executor::task]
pub async fn ppm_task(
    mut pin: ExtiInput<'static, Async>,
    receiver: &'static Shared<PpmReceiver<8>>,
) -> ! {
    let mut last: Option<Instant> = None;
    loop {
        pin.wait_for_rising_edge().await;
        let now = Instant::now();
        if let Some(prev) = last {
            let interval_us = u32::try_from((now - prev).as_micros()).unwrap_or(u32::MAX);
            receiver.with(|r| {
                let _ = r.push_interval(interval_us, now);
            });
        }
        last = Some(now);
    }
}
