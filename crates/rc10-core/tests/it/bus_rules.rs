//! The bus's bookkeeping rules that mutation testing found unpinned: the frame budget's
//! frame count and its "load fits the limit" boundary, batch overflow reaching the bus
//! counters, the pacer keeping its tick grid, and a real `Ticker` forgetting due ticks on
//! resync. Expected values come from the CAN timing facts (an 8-byte standard frame is
//! 111 bits at 1 Mbit/s) and the documented pacing rules.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]

use rc10_core::bus::{
    BusBuilder, BusConfig, ConfigError, RegisterError, TickPacer, TickSource, TickerTicks,
};
use rc10_core::can::{CanFrame, IdFilter};
use rc10_core::motor::dji::DjiMotor;
use rc10_core::node::{BusUsage, CanNode, FrameError, MAX_FRAMES_PER_TICK, TxBatch};
use rc10_core::time::{Duration, Instant};

fn four_m3508() -> [DjiMotor; 4] {
    [1, 2, 3, 4].map(|id| DjiMotor::m3508(id).unwrap())
}

#[test]
fn budget_counts_feedback_and_command_frames() {
    // Four M3508s on one bus: four feedback frames per 1 ms tick plus one 0x200 command
    // frame = 5 frames, 5 × 111 bits of a 1000-bit tick = 55.5 % nominal load.
    let motors = four_m3508();
    let mut b: BusBuilder<'_, 4> = BusBuilder::new();
    for m in &motors {
        b.register(m).unwrap();
    }
    let budget = b.budget();
    assert!((budget.frames_per_tick - 5.0).abs() < 1e-4, "{budget:?}");
    assert_eq!(budget.command_frames_per_tick, 1);
    assert!(
        (budget.nominal_load_percent - 55.5).abs() < 1e-3,
        "{budget:?}"
    );
    let bus = b.build();
    assert!((bus.budget().frames_per_tick - 5.0).abs() < 1e-4);
}

#[test]
fn a_load_exactly_at_the_limit_fits() {
    let motors = four_m3508();
    let mut probe: BusBuilder<'_, 4> = BusBuilder::new();
    for m in &motors {
        probe.register(m).unwrap();
    }
    let load = probe.budget().nominal_load_percent;

    // The limit is "load ≤ max_load_percent": exactly at it is accepted...
    let at = BusConfig {
        max_load_percent: load,
        ..BusConfig::DEFAULT
    };
    let mut b: BusBuilder<'_, 4> = BusBuilder::with_config(at);
    for m in &motors {
        b.register(m).unwrap();
    }

    // ...and one step of f32 below it is not.
    let below = BusConfig {
        max_load_percent: load.next_down(),
        ..BusConfig::DEFAULT
    };
    let mut b: BusBuilder<'_, 4> = BusBuilder::with_config(below);
    for m in &motors[..3] {
        b.register(m).unwrap();
    }
    assert_eq!(
        b.register(&motors[3]),
        Err(RegisterError::FrameBudget { load_percent: load })
    );
}

/// A node that packs more whole frames than a tick's batch holds: it declares the 16 the batch
/// holds (registration refuses more) and pushes 20.
struct Flood;

const FLOOD_ID: u16 = 0x300;
const FLOOD_DECLARED: u8 = 16;
const FLOOD_PUSHED: u8 = 20;

impl CanNode for Flood {
    fn bus_usage(&self) -> BusUsage {
        BusUsage::NONE.sending(IdFilter::standard(FLOOD_ID), FLOOD_DECLARED)
    }
    fn update_feedback(&self, _frame: &CanFrame, _now: Instant) -> Result<(), FrameError> {
        Ok(())
    }
    fn update(&self, _now: Instant, _dt_s: f32) {}
    fn pack_command(&self, out: &mut TxBatch) {
        let frame = CanFrame::standard(FLOOD_ID, &[0; 8]).unwrap();
        for _ in 0..FLOOD_PUSHED {
            let _ = out.push(frame);
        }
    }
}

#[test]
fn frames_beyond_the_batch_are_counted_by_the_bus() {
    // A software-queued transport deep enough for 20 frames, and no load limit to speak of.
    let config = BusConfig {
        max_load_percent: 1000.0,
        ..BusConfig::DEFAULT.with_tx_depth(32)
    };
    let flood = Flood;
    let mut b: BusBuilder<'_, 1> = BusBuilder::with_config(config);
    b.register(&flood).unwrap();
    let bus = b.build();
    let mut batch = TxBatch::new();
    let over = u32::from(FLOOD_PUSHED) - MAX_FRAMES_PER_TICK as u32;
    bus.tick(Instant::from_micros(1000), 0.001, &mut batch);
    assert_eq!(batch.frames().len(), MAX_FRAMES_PER_TICK);
    assert_eq!(bus.stats().snapshot().tx_batch_overflow, over);
    bus.tick(Instant::from_micros(2000), 0.001, &mut batch);
    assert_eq!(bus.stats().snapshot().tx_batch_overflow, 2 * over);
    assert_eq!(bus.stats().snapshot().tx_dropped(), 2 * over);
}

#[test]
fn pacer_measures_lateness_against_its_grid_not_the_last_tick() {
    // 1 ms period. Ticks at 0, 1.4 ms (0.4 ms late: within half a period, no resync) and
    // 2.6 ms: that one is due at 2 ms on the grid, 0.6 ms late, so it re-synchronises. A
    // pacer that restarted its grid at 1.4 ms would call it 0.2 ms late.
    let mut p = TickPacer::new(Duration::from_millis(1));
    assert!(
        p.on_tick(Instant::from_micros(0)).resync,
        "first tick aligns"
    );
    let t = p.on_tick(Instant::from_micros(1400));
    assert!(!t.resync, "{t:?}");
    let t = p.on_tick(Instant::from_micros(2600));
    assert!(t.resync, "{t:?}");
    assert_eq!(t.skipped, 0, "{t:?}");
}

#[test]
fn a_task_that_always_wakes_late_ticks_slower_with_a_true_dt() {
    // Every wake-up 0.6 ms after the tick it was re-synchronised to (another task on the
    // executor runs first): each tick is late by more than half a period, so each one
    // re-synchronises and the next comes 1 ms + 0.6 ms later, as documented. dt says so;
    // no whole period went unserved, so nothing is counted as skipped; no two ticks are
    // closer than half a period.
    let mut p = TickPacer::new(Duration::from_millis(1));
    let mut now = 0u64;
    p.on_tick(Instant::from_micros(now));
    for k in 1..100 {
        now += 1600;
        let t = p.on_tick(Instant::from_micros(now));
        assert!(t.resync && t.skipped == 0, "tick {k}: {t:?}");
        assert!((t.dt_s - 0.0016).abs() < 1e-7, "tick {k}: {t:?}");
    }
}

#[test]
fn ticker_resync_forgets_ticks_already_due() {
    // A real embassy-time Ticker on the host clock. After a 55 ms stall five 10 ms ticks are
    // due; without the reset the next tick would come at once. With it, the next tick comes a
    // period later. (Only a lower bound on the wait is asserted: a slow machine waits longer,
    // never shorter.)
    let mut ticks = TickerTicks::every(Duration::from_millis(10));
    embassy_futures::block_on(async {
        ticks.next_tick().await;
        std::thread::sleep(std::time::Duration::from_millis(55));
        ticks.resync(Instant::now());
        let start = std::time::Instant::now();
        ticks.next_tick().await;
        let waited = start.elapsed();
        assert!(
            waited >= std::time::Duration::from_millis(5),
            "next tick after {waited:?}"
        );
    });
}

#[test]
fn a_ticker_keeps_to_the_shortest_period_a_bus_accepts() {
    // A ticker of period 0 is always due: the scheduler loop would never wait and the
    // receiver task on the same executor would never run. Held to 100 µs, the 20th tick
    // cannot come before 2 ms after the ticker was made (a lower bound only: a slow machine
    // takes longer). Measured on the ticker's own clock: the host's differs from it by a
    // fraction of its 1 µs tick, which once read 1.9998 ms.
    let start = embassy_time::Instant::now();
    let mut ticks = TickerTicks::every(Duration::from_ticks(0));
    embassy_futures::block_on(async {
        for _ in 0..20 {
            ticks.next_tick().await;
        }
    });
    let took = start.elapsed();
    assert!(took >= Duration::from_micros(2000), "20 ticks in {took:?}");
}

#[test]
fn a_ticker_period_past_the_end_of_time_is_held_to_an_hour_instead_of_panicking() {
    // embassy-time's `Ticker::every` panics when now + period overflows.
    let mut ticks = TickerTicks::every(Duration::MAX);
    let tick = embassy_futures::poll_once(ticks.next_tick());
    assert!(tick.is_pending());
}

#[test]
fn a_configuration_that_cannot_run_a_bus_refuses_every_node() {
    let motor = DjiMotor::m3508(1).unwrap();
    let ok = BusConfig::DEFAULT;
    let too_long_window = Duration::from_micros(u64::from(u32::MAX) + 1); // 2^32 µs at 1 Mbit/s
    let cases = [
        (
            BusConfig {
                tick_period: Duration::from_ticks(0),
                ..ok
            },
            ConfigError::TickPeriod,
            "invalid bus configuration: bus tick period is not within 100 us to 1 h",
        ),
        (
            BusConfig {
                tick_period: Duration::from_micros(99),
                ..ok
            },
            ConfigError::TickPeriod,
            "invalid bus configuration: bus tick period is not within 100 us to 1 h",
        ),
        (
            BusConfig {
                tick_period: Duration::from_micros(3_600_000_001),
                ..ok
            },
            ConfigError::TickPeriod,
            "invalid bus configuration: bus tick period is not within 100 us to 1 h",
        ),
        (
            BusConfig {
                bitrate_bps: 0,
                ..ok
            },
            ConfigError::Bitrate,
            "invalid bus configuration: bus bitrate is not within 1 bit/s to 1 Mbit/s",
        ),
        (
            BusConfig {
                bitrate_bps: 1_000_001,
                ..ok
            },
            ConfigError::Bitrate,
            "invalid bus configuration: bus bitrate is not within 1 bit/s to 1 Mbit/s",
        ),
        (
            BusConfig {
                max_load_percent: 0.0,
                ..ok
            },
            ConfigError::MaxLoad,
            "invalid bus configuration: bus load limit is not above zero",
        ),
        (
            BusConfig {
                max_load_percent: -5.0,
                ..ok
            },
            ConfigError::MaxLoad,
            "invalid bus configuration: bus load limit is not above zero",
        ),
        (
            BusConfig {
                rate_window: Duration::from_ticks(0),
                ..ok
            },
            ConfigError::RateWindow,
            "invalid bus configuration: bus rate window is zero or 2^32 bit times or more",
        ),
        (
            BusConfig {
                rate_window: too_long_window,
                ..ok
            },
            ConfigError::RateWindow,
            "invalid bus configuration: bus rate window is zero or 2^32 bit times or more",
        ),
    ];
    for (config, error, message) in cases {
        assert_eq!(config.check(), Err(error));
        let mut b: BusBuilder<'_, 2> = BusBuilder::with_config(config);
        let refused = b.register(&motor).unwrap_err();
        assert_eq!(refused, RegisterError::Config(error));
        assert_eq!(refused.to_string(), message);
        assert!(b.build().nodes().is_empty());
    }
    // NaN would have compared false against every load and admitted anything.
    let nan = BusConfig {
        max_load_percent: f32::NAN,
        ..ok
    };
    assert_eq!(nan.check(), Err(ConfigError::MaxLoad));
    let mut b: BusBuilder<'_, 2> = BusBuilder::with_config(nan);
    assert!(matches!(
        b.register(&motor),
        Err(RegisterError::Config(ConfigError::MaxLoad))
    ));
}

#[test]
fn the_edges_of_a_valid_configuration_are_accepted() {
    // Ticks of 100 µs and of an hour, 1 bit/s to 1 Mbit/s, any positive load limit
    // (infinity: none), a 1 µs rate window and one of 2^32 − 1 bit times (2^32 − 1 µs at
    // 1 Mbit/s, 2^32 − 1 s at 1 bit/s), no TX buffers (a listen-only bus).
    for config in [
        BusConfig {
            tick_period: Duration::from_micros(100),
            rate_window: Duration::from_micros(1),
            ..BusConfig::DEFAULT
        },
        BusConfig {
            tick_period: Duration::from_secs(3600),
            ..BusConfig::DEFAULT
        },
        BusConfig {
            rate_window: Duration::from_micros(u64::from(u32::MAX)),
            ..BusConfig::DEFAULT
        },
        BusConfig {
            bitrate_bps: 1,
            rate_window: Duration::from_secs(u64::from(u32::MAX)),
            ..BusConfig::DEFAULT
        },
        BusConfig {
            max_load_percent: f32::MIN_POSITIVE,
            ..BusConfig::DEFAULT
        },
        BusConfig {
            max_load_percent: f32::INFINITY,
            ..BusConfig::DEFAULT
        },
        BusConfig::DEFAULT.with_tx_depth(0),
    ] {
        assert_eq!(config.check(), Ok(()), "{config:?}");
    }
    // No load limit: eight M3508s on one bus (8 feedback + 2 command frames, 111 % of a
    // 1 Mbit/s millisecond) register.
    let motors: [DjiMotor; 8] = core::array::from_fn(|i| DjiMotor::m3508(i as u8 + 1).unwrap());
    let unlimited = BusConfig {
        max_load_percent: f32::INFINITY,
        ..BusConfig::DEFAULT
    };
    let mut b: BusBuilder<'_, 8> = BusBuilder::with_config(unlimited);
    for m in &motors {
        b.register(m).unwrap();
    }
    assert!((b.budget().nominal_load_percent - 111.0).abs() < 1e-3);
    // A listen-only bus refuses a node that sends, for its TX depth.
    let mut b: BusBuilder<'_, 2> = BusBuilder::with_config(BusConfig::DEFAULT.with_tx_depth(0));
    assert_eq!(
        b.register(&motors[0]),
        Err(RegisterError::TxDepth {
            frames_per_tick: 1,
            tx_depth: 0
        })
    );
}

/// A node that sends `frames` whole frames a tick on `base`, `base + 1`, ….
struct Sender {
    base: u16,
    frames: u8,
}

impl CanNode for Sender {
    fn bus_usage(&self) -> BusUsage {
        BusUsage::NONE.sending(
            IdFilter {
                extended: false,
                id: u32::from(self.base),
                mask: 0x7F0,
            },
            self.frames,
        )
    }
    fn update_feedback(&self, _frame: &CanFrame, _now: Instant) -> Result<(), FrameError> {
        Ok(())
    }
    fn update(&self, _now: Instant, _dt_s: f32) {}
    fn pack_command(&self, out: &mut TxBatch) {
        for i in 0..self.frames {
            let _ = out.push(CanFrame::standard(self.base + u16::from(i), &[i]).unwrap());
        }
    }
}

#[test]
fn a_node_whose_frames_would_not_fit_a_ticks_batch_is_refused() {
    // A software TX queue of 32 frames and a 10 ms tick: neither the TX depth nor the load
    // (17 frames of at most 111 bits in 10,000 bit times) stops a 17th frame a tick. But a
    // tick's batch holds 16: the frames of the node packed last would never go out.
    let config = BusConfig {
        tick_period: Duration::from_millis(10),
        ..BusConfig::DEFAULT.with_tx_depth(32)
    };
    let (a, b, c) = (
        Sender {
            base: 0x300,
            frames: 8,
        },
        Sender {
            base: 0x310,
            frames: 8,
        },
        Sender {
            base: 0x320,
            frames: 1,
        },
    );
    let mut builder: BusBuilder<'_, 4> = BusBuilder::with_config(config);
    builder.register(&a).unwrap();
    builder.register(&b).unwrap();
    let refused = builder.register(&c).unwrap_err();
    assert_eq!(
        refused,
        RegisterError::TickBatch {
            frames_per_tick: 17
        }
    );
    assert_eq!(
        refused.to_string(),
        "17 command frames per tick do not fit a tick's batch of 16"
    );
    // The 16 that registered all go out every tick.
    let bus = builder.build();
    let mut batch = TxBatch::new();
    bus.tick(Instant::from_millis(10), 0.01, &mut batch);
    assert_eq!(batch.frames().len(), 16);
    assert_eq!(batch.overflowed(), 0);
}

/// A node that listens on more IDs than an `IdSet` holds (and sends nothing).
struct Eavesdropper;

impl CanNode for Eavesdropper {
    fn bus_usage(&self) -> BusUsage {
        let mut usage = BusUsage::NONE;
        for id in 0x600..0x600 + rc10_core::node::ID_SET_CAPACITY as u16 + 1 {
            usage = usage.listening(IdFilter::standard(id), 10);
        }
        usage
    }
    fn update_feedback(&self, _frame: &CanFrame, _now: Instant) -> Result<(), FrameError> {
        Ok(())
    }
    fn update(&self, _now: Instant, _dt_s: f32) {}
    fn pack_command(&self, _out: &mut TxBatch) {}
}

#[test]
fn a_listen_set_that_overflowed_is_refused_even_with_nothing_to_send() {
    // The set dropped its seventh filter: registering it would silently deafen the node to
    // that ID, so registration refuses it.
    assert!(Eavesdropper.bus_usage().listen.overflowed());
    let node = Eavesdropper;
    let mut b: BusBuilder<'_, 2> = BusBuilder::new();
    assert_eq!(b.register(&node), Err(RegisterError::TooManyIds));
}
