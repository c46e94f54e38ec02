//! One CAN bus and the nodes on it: registration with checks ([`BusBuilder`]), the frozen
//! [`Bus`] that the scheduler and receiver tasks share, and those two tasks' loops.
//!
//! # Registration
//!
//! Every node declares, in its [`BusUsage`](crate::node::BusUsage), every ID it listens on
//! and every ID it transmits on (whole frames, or a slot in a shared DJI frame). Registration
//! checks them all against each other, so no frame can be merged into another device's frame,
//! no two senders share an ID and nothing is sent on an ID a device answers on; every tick
//! then holds each node to its declaration (whole frames beyond it are dropped, a write to a
//! command slot other than its own is refused; both counted in `tx_undeclared`). It also
//! checks that one tick's command frames fit the transport's TX buffers
//! ([`BusConfig::tx_depth`], 3 on an STM32G4): rather than refuse some node's frame every
//! tick (it would time out, forever), a bus that cannot serve every node every tick is
//! refused at setup, where the error can be read. Put the rest on another bus.
//!
//! # Tick order (RC10_LIB's `schedulerTask`, kept)
//!
//! Every period (1 ms by default): `update(now, dt)` on every node in registration order
//! (control math only), then `pack_command` on every node (frame assembly only: DJI slots with
//! the same command ID merge into one frame), then the frames are handed to the transport with
//! `try_send`, in packing order (after a tick in which the transport refused a frame, from
//! that frame on, so no node's frame is refused every tick: see [`Bus::transmit`]). Frames
//! the transport cannot queue (TX buffers still full from
//! an earlier tick, or bus-off) are counted in [`BusStats`], never waited for: the next tick
//! sends fresh commands anyway. The nodes that declared a refused frame's ID are told
//! ([`CanNode::frame_refused`]), so a one-shot command (a Damiao "save zero") is sent
//! again instead of lost. After a stall the missed ticks are skipped, not run back to
//! back ([`TickPacer`]).
//!
//! # Receiving
//!
//! Each received frame goes to the node that declared its ID in
//! [`BusUsage::listen`](crate::node::BusUsage::listen) (registration guarantees at most one
//! did), if that node's `matches_frame` claims it; the node parses it in `update_feedback`.
//! `matches_frame` can only narrow a node's declared listen set, never widen it: a frame on
//! an undeclared ID is never offered to anyone (the hardware acceptance filters, built from
//! the same declarations, would not let it in either). A frame nobody claims is counted as
//! unmatched; a claimed frame the node rejects (wrong DLC, out-of-range field) is counted as
//! rejected and changes nothing.
//!
//! # Sync core, async shell
//!
//! [`Bus::tick`], [`Bus::transmit`] and [`Bus::dispatch`] are plain functions that unit tests
//! and the simulator call directly with virtual time. [`run_scheduler`] and [`run_receiver`]
//! are thin async loops over them for Embassy tasks; they are the only code in rc10-core that
//! reads the embassy-time clock ([`run_scheduler_on`] takes the ticks from any
//! [`TickSource`] instead).

use crate::can::RawId;
use crate::can::stats::RateWindow;
use crate::can::{
    BusRates, BusStats, CanFrame, CanReceive, CanTransmit, ErrorState, Id, ReceiveError, SendError,
    timing,
};
use crate::node::{CanNode, CommandSlot, IdSet, MAX_FRAMES_PER_TICK, TxBatch, slot_permission};
use crate::time::{DeltaTime, Duration, Instant};
use core::cell::RefCell;
use core::fmt;
use core::num::NonZeroU64;
use core::sync::atomic::{AtomicU8, Ordering};
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;

/// Bus parameters used for the frame budget and load statistics.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BusConfig {
    /// Nominal bitrate in bits per second (1 Mbit/s for DJI motors).
    pub bitrate_bps: u32,
    /// Scheduler tick period (1 ms): [`run_scheduler`] ticks at it.
    pub tick_period: Duration,
    /// Registration fails when the nominal (unstuffed) load of all declared traffic would
    /// exceed this, in percent. 90 % admits six DJI motors (89 %) and rejects seven (100 %),
    /// matching "5–6 marginal, 8 impossible" (SPEC.md).
    pub max_load_percent: f32,
    /// Window over which [`Bus::rates`] are computed.
    pub rate_window: Duration,
    /// Frames the transport can hold for sending at once: 3 on an STM32G4 FDCAN (its TX
    /// buffers), more for a transport with a software queue. Registration refuses nodes whose
    /// frames per tick would not all fit, so no node's frame is refused every tick.
    pub tx_depth: u8,
}

impl BusConfig {
    /// 1 Mbit/s, 1 kHz tick, 90 % registration limit, 1 s rate window, 3 TX buffers.
    pub const DEFAULT: Self = Self {
        bitrate_bps: 1_000_000,
        tick_period: Duration::from_millis(1),
        max_load_percent: 90.0,
        rate_window: Duration::from_secs(1),
        tx_depth: 3,
    };

    /// Sets [`tx_depth`](Self::tx_depth).
    #[must_use]
    pub const fn with_tx_depth(mut self, frames: u8) -> Self {
        self.tx_depth = frames;
        self
    }

    /// The fastest classic CAN bitrate, in bits per second.
    pub const MAX_BITRATE_BPS: u32 = 1_000_000;

    /// The shortest tick period a bus runs at: 100 µs, less than one 8-byte frame takes at
    /// 1 Mbit/s (111 µs). A shorter tick could not carry a frame per tick, and its work would
    /// outlast its period, so the scheduler task would never wait on its ticker and never
    /// let another task of its executor run.
    pub const MIN_TICK_PERIOD: Duration = Duration::from_micros(100);

    /// The longest tick period a bus runs at: an hour (embassy-time's `Ticker` panics when
    /// its next tick would overflow the clock).
    pub const MAX_TICK_PERIOD: Duration = Duration::from_secs(3600);

    /// Whether this configuration can run a bus; [`BusBuilder::register`] refuses every node
    /// on a bus whose configuration cannot. A `tx_depth` of 0 is allowed (a bus that only
    /// listens; a node that sends is refused with [`RegisterError::TxDepth`]), and so is an
    /// infinite `max_load_percent` (no load limit).
    ///
    /// ```
    /// use rc10_core::bus::{BusConfig, ConfigError};
    /// use rc10_core::time::Duration;
    /// assert_eq!(BusConfig::DEFAULT.check(), Ok(()));
    /// let zero_tick = BusConfig { tick_period: Duration::from_ticks(0), ..BusConfig::DEFAULT };
    /// assert_eq!(zero_tick.check(), Err(ConfigError::TickPeriod));
    /// ```
    pub fn check(&self) -> Result<(), ConfigError> {
        if !(Self::MIN_TICK_PERIOD..=Self::MAX_TICK_PERIOD).contains(&self.tick_period) {
            return Err(ConfigError::TickPeriod);
        }
        if self.bitrate_bps == 0 || self.bitrate_bps > Self::MAX_BITRATE_BPS {
            return Err(ConfigError::Bitrate);
        }
        if self.max_load_percent.is_nan() || self.max_load_percent <= 0.0 {
            return Err(ConfigError::MaxLoad);
        }
        // The window's bit counts are 32-bit differences, and a bus carries at most one bit
        // per bit time: bit/s · µs is the window's bit times · 10⁶.
        let too_long = u64::from(self.bitrate_bps)
            .checked_mul(self.rate_window.as_micros())
            .is_none_or(|bit_us| bit_us > u64::from(u32::MAX) * 1_000_000);
        if self.rate_window.as_ticks() == 0 || too_long {
            return Err(ConfigError::RateWindow);
        }
        Ok(())
    }
}

/// What is wrong with a [`BusConfig`] ([`BusConfig::check`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ConfigError {
    /// `tick_period` is outside
    /// [`MIN_TICK_PERIOD`](BusConfig::MIN_TICK_PERIOD)…[`MAX_TICK_PERIOD`](BusConfig::MAX_TICK_PERIOD)
    /// (100 µs to an hour).
    TickPeriod,
    /// `bitrate_bps` is zero or above classic CAN's 1 Mbit/s.
    Bitrate,
    /// `max_load_percent` is NaN, zero or negative: NaN would admit any load, the others
    /// none.
    MaxLoad,
    /// `rate_window` is zero, or so long that the bits the bus can carry in it overflow
    /// [`Bus::rates`]' 32-bit counts (2³² bit times or more: 71.6 minutes at 1 Mbit/s),
    /// which would read a loaded bus as nearly idle.
    RateWindow,
}

impl fmt::Display for ConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::TickPeriod => "bus tick period is not within 100 us to 1 h",
            Self::Bitrate => "bus bitrate is not within 1 bit/s to 1 Mbit/s",
            Self::MaxLoad => "bus load limit is not above zero",
            Self::RateWindow => "bus rate window is zero or 2^32 bit times or more",
        })
    }
}

impl core::error::Error for ConfigError {}

impl Default for BusConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// How much of the bus the registered traffic needs.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FrameBudget {
    /// Frames per tick: feedback plus command frames.
    pub frames_per_tick: f32,
    /// Command frames the bus sends per tick (shared slot frames plus whole frames): what
    /// must fit [`BusConfig::tx_depth`].
    pub command_frames_per_tick: u32,
    /// Load in percent with unstuffed 8-byte frames.
    pub nominal_load_percent: f32,
    /// Load in percent with worst-case stuffing.
    pub worst_case_load_percent: f32,
}

impl FrameBudget {
    /// How comfortable the budget is.
    pub fn level(&self) -> BudgetLevel {
        if self.worst_case_load_percent <= 80.0 {
            BudgetLevel::Comfortable
        } else {
            BudgetLevel::Marginal
        }
    }
}

/// A summary of a [`FrameBudget`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BudgetLevel {
    /// Fits even with worst-case bit stuffing and leaves at least 20 % of the bus free.
    Comfortable,
    /// Fits nominally but may lose frames under worst-case stuffing or extra traffic: expect
    /// TX drops and late feedback. Consider a second bus.
    Marginal,
}

/// Why a node could not be registered. Every variant names what clashed, so the message
/// says which IDs to change.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RegisterError {
    /// The bus's [`BusConfig`] cannot run a bus ([`BusConfig::check`]): no node is accepted.
    Config(ConfigError),
    /// The bus already holds its capacity (`N`) of nodes.
    Full,
    /// The node declared more ID filters than an [`IdSet`] holds.
    TooManyIds,
    /// The node's feedback IDs overlap those of the node registered at `existing` (e.g. an
    /// M3508 with id 5 and a GM6020 with id 1 both answer on 0x205).
    FeedbackConflict {
        /// Index of the node already registered.
        existing: usize,
        /// An ID both listen on.
        id: RawId,
    },
    /// The node writes the same command slot as the node registered at `existing`.
    SlotConflict {
        /// Index of the node already registered.
        existing: usize,
        /// The slot both write.
        slot: CommandSlot,
    },
    /// The node and the node registered at `existing` would both send frames on `id`: two
    /// whole-frame senders, or a whole frame on the ID of a shared slot frame (which would
    /// otherwise be merged with, or sent next to, the DJI slot frame). `existing` is the
    /// node's own index (the number of nodes registered) when it would send a whole frame on
    /// its own slot frame's ID.
    SendConflict {
        /// Index of the node already registered (or the node's own, see above).
        existing: usize,
        /// The ID both send on.
        id: RawId,
    },
    /// A node would transmit on an ID another node (or itself) receives feedback on: the
    /// device answering on that ID and the MCU would both send it.
    CommandOnFeedbackId {
        /// Index of the sending node (the new node's index is `nodes().len()`).
        sender: usize,
        /// Index of the listening node.
        listener: usize,
        /// The ID.
        id: RawId,
    },
    /// With this node the bus would send `frames_per_tick` command frames every tick, more
    /// than the transport's [`BusConfig::tx_depth`] buffers hold: some node would be refused
    /// every tick. Use another bus (or a transport with a deeper queue).
    TxDepth {
        /// Command frames per tick with this node.
        frames_per_tick: u32,
        /// Frames the transport holds.
        tx_depth: u8,
    },
    /// With this node the bus would pack `frames_per_tick` command frames every tick, more
    /// than one tick's [`TxBatch`] holds ([`MAX_FRAMES_PER_TICK`], 16): the nodes packed last
    /// would never have their frames sent. Possible only with a `tx_depth` above 16 (a
    /// software queue) and a slow tick. Use another bus.
    TickBatch {
        /// Command frames per tick with this node.
        frames_per_tick: u32,
    },
    /// With this node the bus would need `load_percent` of its capacity, above
    /// [`BusConfig::max_load_percent`].
    FrameBudget {
        /// Nominal load the bus would have, in percent.
        load_percent: f32,
    },
}

impl fmt::Display for RegisterError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Config(e) => write!(f, "invalid bus configuration: {e}"),
            Self::Full => f.write_str("bus registry full"),
            Self::TooManyIds => f.write_str("node declares more ID filters than fit an IdSet"),
            Self::FeedbackConflict { existing, id } => {
                write!(f, "feedback ID {id} is also node {existing}'s")
            }
            Self::SlotConflict { existing, slot } => write!(
                f,
                "command slot {} of frame 0x{:03X} is also node {existing}'s",
                slot.index(),
                slot.id()
            ),
            Self::SendConflict { existing, id } => {
                write!(f, "node {existing} also sends on {id}")
            }
            Self::CommandOnFeedbackId {
                sender,
                listener,
                id,
            } => write!(
                f,
                "node {sender} would send on {id}, where node {listener} receives feedback"
            ),
            Self::TxDepth {
                frames_per_tick,
                tx_depth,
            } => write!(
                f,
                "{frames_per_tick} command frames per tick do not fit {tx_depth} TX buffers"
            ),
            Self::TickBatch { frames_per_tick } => write!(
                f,
                "{frames_per_tick} command frames per tick do not fit a tick's batch of {MAX_FRAMES_PER_TICK}"
            ),
            Self::FrameBudget { load_percent } => {
                write!(f, "bus would be {load_percent:.0} % loaded")
            }
        }
    }
}

impl core::error::Error for RegisterError {}

/// Registers nodes on one bus, checking capacity, ID and slot conflicts and the frame budget.
/// [`build`](Self::build) freezes it into a [`Bus`].
///
/// ```
/// use rc10_core::bus::{BusBuilder, RegisterError};
/// use rc10_core::motor::dji::DjiMotor;
///
/// let wheel = DjiMotor::m3508(5).unwrap();
/// let yaw = DjiMotor::gm6020_voltage(1).unwrap(); // also answers on 0x205
/// let mut builder = BusBuilder::<4>::new();
/// builder.register(&wheel).unwrap();
/// let err = builder.register(&yaw).unwrap_err();
/// assert!(matches!(err, RegisterError::FeedbackConflict { existing: 0, .. }));
/// assert_eq!(err.to_string(), "feedback ID 0x205 is also node 0's");
/// let bus = builder.build();
/// assert_eq!(bus.nodes().len(), 1);
/// ```
pub struct BusBuilder<'a, const N: usize> {
    nodes: heapless::Vec<&'a dyn CanNode, N>,
    declared: heapless::Vec<Declared, N>,
    config: BusConfig,
}

/// What a node declared: the whole frames it sends, kept to hold it to that every tick, and
/// the IDs it listens on, which bound what [`Bus::dispatch`] hands it.
#[derive(Debug, Clone, Copy)]
struct Declared {
    frames_per_tick: u8,
    sends: IdSet,
    listen: IdSet,
    /// The one command slot it may write, as [`TxBatch::allow_only_slot`] takes it.
    slot_permission: u32,
}

impl Declared {
    /// Whether this node declared `id`: as a whole frame it sends, or as the command ID of
    /// its slot (a slot frame merges several nodes' slots).
    fn declares(&self, id: Id) -> bool {
        let slot_id = match id {
            Id::Standard(standard) => crate::node::slot_permission_id(self.slot_permission)
                .is_some_and(|slot| slot == standard.as_raw()),
            Id::Extended(_) => false,
        };
        slot_id || self.sends.matches(id)
    }
}

/// The first standard ID of [`Bus`]'s direct routing table: DJI feedback arrives on
/// 0x201–0x20B, so `0x200 + k` for `k < ROUTE_LEN` covers every DJI motor.
const ROUTE_BASE: u16 = 0x200;
/// Entries of the direct routing table.
const ROUTE_LEN: usize = 16;

impl<'a, const N: usize> BusBuilder<'a, N> {
    /// An empty builder with [`BusConfig::DEFAULT`].
    pub const fn new() -> Self {
        Self::with_config(BusConfig::DEFAULT)
    }

    /// An empty builder with `config`.
    pub const fn with_config(config: BusConfig) -> Self {
        Self {
            nodes: heapless::Vec::new(),
            declared: heapless::Vec::new(),
            config,
        }
    }

    /// Adds `node`, or says why it cannot be added (the builder is then unchanged).
    ///
    /// Checks the bus's configuration first ([`BusConfig::check`]); then, against every
    /// node already registered: no shared feedback ID, no shared
    /// command slot, no two senders on one ID (whole frames, or a whole frame on a slot
    /// frame's ID), no transmission on an ID anyone listens on; against the node itself: no
    /// transmission on an ID it listens on, no whole frame on its own slot frame's ID
    /// ([`RegisterError::SendConflict`] with `existing` its own index); then that all
    /// command frames of a tick fit [`BusConfig::tx_depth`] and a tick's batch
    /// ([`MAX_FRAMES_PER_TICK`]), and the load fits
    /// [`BusConfig::max_load_percent`].
    pub fn register(&mut self, node: &'a dyn CanNode) -> Result<(), RegisterError> {
        self.config.check().map_err(RegisterError::Config)?;
        if self.nodes.is_full() {
            return Err(RegisterError::Full);
        }
        let mine = node.bus_usage();
        if mine.listen.overflowed() || mine.sends.overflowed() {
            return Err(RegisterError::TooManyIds);
        }
        let me = self.nodes.len();
        let my_tx = mine.transmit_ids();
        if my_tx.overflowed() {
            return Err(RegisterError::TooManyIds); // the slot frame's ID did not fit
        }
        if let Some(id) = mine.listen.common_id_with(&my_tx) {
            return Err(RegisterError::CommandOnFeedbackId {
                sender: me,
                listener: me,
                id,
            });
        }
        // A whole frame on its own slot frame's ID: two different frames on one ID each tick
        // (the other ESCs on that command frame would read the whole frame as theirs).
        if let Some(slot) = mine.command_slot
            && let Some(id) = mine.sends.common_id_with(&IdSet::one(slot.frame_filter()))
        {
            return Err(RegisterError::SendConflict { existing: me, id });
        }
        for (i, other) in self.nodes.iter().enumerate() {
            let theirs = other.bus_usage();
            let their_tx = theirs.transmit_ids();
            if let Some(id) = mine.listen.common_id_with(&theirs.listen) {
                return Err(RegisterError::FeedbackConflict { existing: i, id });
            }
            if let Some(slot) = mine.command_slot
                && Some(slot) == theirs.command_slot
            {
                return Err(RegisterError::SlotConflict { existing: i, slot });
            }
            let send_clash = mine
                .sends
                .common_id_with(&their_tx)
                .or_else(|| theirs.sends.common_id_with(&my_tx));
            if let Some(id) = send_clash {
                return Err(RegisterError::SendConflict { existing: i, id });
            }
            if let Some(id) = my_tx.common_id_with(&theirs.listen) {
                return Err(RegisterError::CommandOnFeedbackId {
                    sender: me,
                    listener: i,
                    id,
                });
            }
            if let Some(id) = their_tx.common_id_with(&mine.listen) {
                return Err(RegisterError::CommandOnFeedbackId {
                    sender: i,
                    listener: me,
                    id,
                });
            }
        }
        let budget = self.budget_with(Some(node));
        if budget.command_frames_per_tick > u32::from(self.config.tx_depth) {
            return Err(RegisterError::TxDepth {
                frames_per_tick: budget.command_frames_per_tick,
                tx_depth: self.config.tx_depth,
            });
        }
        if budget.command_frames_per_tick > MAX_FRAMES_PER_TICK as u32 {
            return Err(RegisterError::TickBatch {
                frames_per_tick: budget.command_frames_per_tick,
            });
        }
        if budget.nominal_load_percent > self.config.max_load_percent {
            return Err(RegisterError::FrameBudget {
                load_percent: budget.nominal_load_percent,
            });
        }
        self.nodes.push(node).map_err(|_| RegisterError::Full)?;
        let declared = Declared {
            frames_per_tick: mine.frames_per_tick,
            sends: mine.sends,
            listen: mine.listen,
            slot_permission: slot_permission(mine.command_slot),
        };
        // Same capacity as `nodes`, which just took the node.
        let _ = self.declared.push(declared);
        Ok(())
    }

    /// The frame budget of the nodes registered so far.
    pub fn budget(&self) -> FrameBudget {
        self.budget_with(None)
    }

    fn budget_with(&self, extra: Option<&dyn CanNode>) -> FrameBudget {
        frame_budget(self.nodes.iter().copied().chain(extra), &self.config)
    }

    /// Freezes the registry. Nothing can be registered after this.
    pub fn build(self) -> Bus<'a, N> {
        // Standard IDs 0x200 + k: which node (index + 1; 0 for none) declared each. The
        // listen sets are disjoint (registration checked), so at most one node declares any.
        let mut route = [0u8; ROUTE_LEN];
        for (k, slot) in (0u16..).zip(route.iter_mut()) {
            let id = crate::can::StandardId::new(ROUTE_BASE.saturating_add(k))
                .map(crate::can::Id::Standard);
            let owner = id.and_then(|id| self.declared.iter().position(|d| d.listen.matches(id)));
            *slot = owner
                .and_then(|i| u8::try_from(i).ok())
                .map_or(0, |i| i.saturating_add(1));
        }
        Bus {
            nodes: self.nodes,
            declared: self.declared,
            route,
            config: self.config,
            stats: BusStats::new(),
            window: Mutex::new(RefCell::new(RateWindow::new())),
            first_refused: AtomicU8::new(0),
        }
    }
}

impl<const N: usize> Default for BusBuilder<'_, N> {
    fn default() -> Self {
        Self::new()
    }
}

fn frame_budget<'n>(
    nodes: impl Iterator<Item = &'n dyn CanNode>,
    config: &BusConfig,
) -> FrameBudget {
    let tick_s = crate::time::micros_to_s(config.tick_period.as_micros().max(1));
    let mut slot_ids: heapless::Vec<u16, MAX_FRAMES_PER_TICK> = heapless::Vec::new();
    let mut command_frames = 0u32;
    let (mut frames, mut nominal_bits, mut worst_bits) = (0.0f32, 0.0f32, 0.0f32);
    let mut add = |count: f32, extended: bool| {
        frames += count;
        let nominal = if extended { 131.0 } else { 111.0 };
        nominal_bits += count * nominal;
        worst_bits += count * timing::worst_case_bits(extended, 8) as f32;
    };
    for node in nodes {
        let u = node.bus_usage();
        add(u.feedback_hz as f32 * tick_s, u.listen.any_extended());
        add(f32::from(u.replies_per_tick), u.listen.any_extended());
        add(f32::from(u.frames_per_tick), u.sends.any_extended());
        command_frames = command_frames.saturating_add(u32::from(u.frames_per_tick));
        if let Some(slot) = u.command_slot
            && !slot_ids.contains(&slot.id())
        {
            // More distinct slot IDs than a batch holds cannot fit a bus anyway; count them
            // regardless.
            let _ = slot_ids.push(slot.id());
            command_frames = command_frames.saturating_add(1);
            add(1.0, false);
        }
    }
    let capacity_bits = config.bitrate_bps as f32 * tick_s;
    FrameBudget {
        frames_per_tick: frames,
        command_frames_per_tick: command_frames,
        nominal_load_percent: 100.0 * nominal_bits / capacity_bits,
        worst_case_load_percent: 100.0 * worst_bits / capacity_bits,
    }
}

/// What happened to a received frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Dispatch {
    /// The node at this index parsed it.
    Handled(usize),
    /// The node at this index claimed it but rejected it as malformed.
    Rejected(usize, crate::node::FrameError),
    /// No node claimed it.
    Unmatched,
}

/// What one [`Bus::transmit`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TransmitReport {
    /// Frames the transport accepted into its TX buffers. Queued is not yet sent: a frame
    /// still waits for arbitration (and for an acknowledgement) after this.
    pub queued: u8,
    /// Frames not queued: TX buffers full.
    pub full: u8,
    /// Frames not queued: controller bus-off.
    pub bus_off: u8,
}

/// A frozen bus: its nodes, statistics and rates. Shared as `&'static` by the scheduler task,
/// the receiver task and anyone reading statistics.
pub struct Bus<'a, const N: usize> {
    nodes: heapless::Vec<&'a dyn CanNode, N>,
    declared: heapless::Vec<Declared, N>,
    /// Direct routing of standard IDs `ROUTE_BASE + k`: the index + 1 of the node that
    /// declared the ID in its listen set, 0 for none (built once, from the declarations).
    route: [u8; ROUTE_LEN],
    config: BusConfig,
    stats: BusStats,
    window: Mutex<CriticalSectionRawMutex, RefCell<RateWindow>>,
    /// Index (in the batch) of the first frame the transport refused last tick: this tick
    /// starts there, so a backlog never refuses the same node every tick.
    first_refused: AtomicU8,
}

impl<'a, const N: usize> Bus<'a, N> {
    /// The registered nodes, in registration (and tick) order.
    pub fn nodes(&self) -> &[&'a dyn CanNode] {
        &self.nodes
    }

    /// The configuration.
    pub const fn config(&self) -> &BusConfig {
        &self.config
    }

    /// The frame budget of the registered nodes.
    pub fn budget(&self) -> FrameBudget {
        frame_budget(self.nodes.iter().copied(), &self.config)
    }

    /// Live counters.
    pub const fn stats(&self) -> &BusStats {
        &self.stats
    }

    /// Rates over the last complete [`BusConfig::rate_window`] (zero before one has
    /// completed). Computed here, in the caller's task, from the counts the tick latched: if
    /// the scheduler stops ticking, the last window stays (compare
    /// [`BusCounters`](crate::can::BusCounters) snapshots to see that nothing moves).
    pub fn rates(&self) -> BusRates {
        // Copied out under the lock, computed after it.
        match self.window.lock(|w| w.borrow().latched()) {
            Some((elapsed, counts)) => counts.rates(elapsed, self.config.bitrate_bps),
            None => BusRates::default(),
        }
    }

    /// One scheduler tick at `now`, `dt_s` seconds after the previous: update every node, then
    /// pack every node into `out` (cleared first). Does not send; see [`transmit`](Self::transmit).
    pub fn tick(&self, now: Instant, dt_s: f32, out: &mut TxBatch) {
        out.clear();
        for node in &self.nodes {
            node.update(now, dt_s);
        }
        for (node, declared) in self.nodes.iter().zip(&self.declared) {
            let from = out.frames().len();
            out.allow_only_slot(declared.slot_permission);
            node.pack_command(out);
            let dropped = out.keep_declared(from, declared.frames_per_tick, &declared.sends);
            if dropped > 0 {
                self.stats.record_tx_undeclared(dropped);
            }
        }
        let refused = out.allow_any_slot();
        if refused > 0 {
            self.stats.record_tx_undeclared(refused);
        }
        if out.overflowed() > 0 {
            self.stats.record_batch_overflow(out.overflowed());
        }
        self.stats.record_tick();
        self.window.lock(|w| {
            w.borrow_mut()
                .update(now, &self.stats, self.config.rate_window)
        });
    }

    /// Hands the batch's frames to `tx` with `try_send`, counting what was queued and what was
    /// not, and first the frames of earlier ticks still waiting
    /// ([`CanTransmit::still_queued`], counted in `tx_stale`).
    ///
    /// Frames go in packing order, except that after a tick in which the transport refused a
    /// frame (its buffers still held frames of an earlier tick), the next tick starts with
    /// the first refused one: a backlog delays every node in turn instead of starving the
    /// last-packed one every tick.
    ///
    /// Bus-off is tracked here and only here: the controller is taken to be bus-off during
    /// this tick if `status()` says so *or* any `try_send` reported it, and
    /// [`BusCounters::bus_off_events`](crate::can::BusCounters) counts each entry once,
    /// whichever way the transport reports it. A tick with nothing to send and no bus-off
    /// status leaves the state as it was (there was nothing to learn it from).
    ///
    /// Each refused frame is reported to the nodes that declared its ID
    /// ([`CanNode::frame_refused`]) as it is refused. Pass the batch of the latest
    /// [`tick`](Self::tick), once, before the next tick (as [`run_scheduler`] does): a node
    /// matches a refusal against what it packed last, so it would misread a refusal of an
    /// older batch's frame, or of the same batch sent twice (a Damiao driver could put back
    /// a zero that did go out).
    pub fn transmit(&self, batch: &TxBatch, tx: &mut impl CanTransmit) -> TransmitReport {
        let stale = tx.still_queued();
        if stale > 0 {
            self.stats.record_tx_stale(u32::from(stale));
        }
        let status = tx.status();
        // Every error the controller logged, or one for a bare "there was an error".
        let errors = status.errors_logged.max(u8::from(status.protocol_error));
        if errors > 0 {
            self.stats.record_bus_errors(u32::from(errors));
        }
        let mut bus_off = status.state == ErrorState::BusOff;
        let mut report = TransmitReport::default();
        let frames = batch.frames();
        let start = usize::from(self.first_refused.load(Ordering::Relaxed));
        let start = if start < frames.len() { start } else { 0 };
        let (tail, head) = frames.split_at(start);
        // Each frame with its index in the batch.
        let rotated = head.iter().zip(start..).chain(tail.iter().zip(0..));
        let mut first_refused = None;
        // The report's counts are bounded by the batch (at most MAX_FRAMES_PER_TICK frames);
        // they saturate rather than wrap all the same.
        for (frame, index) in rotated {
            match tx.try_send(frame) {
                Ok(()) => {
                    self.stats.record_tx(timing::unstuffed_bits(frame));
                    report.queued = report.queued.saturating_add(1);
                }
                Err(reason) => {
                    match reason {
                        SendError::Full => {
                            self.stats.record_tx_full();
                            report.full = report.full.saturating_add(1);
                            first_refused.get_or_insert(index);
                        }
                        SendError::BusOff => {
                            self.stats.record_tx_bus_off();
                            bus_off = true;
                            report.bus_off = report.bus_off.saturating_add(1);
                        }
                    }
                    self.tell_refused(frame, reason);
                }
            }
        }
        if bus_off || !batch.frames().is_empty() {
            self.stats.record_bus_off_state(bus_off);
        }
        let next = first_refused
            .and_then(|i| u8::try_from(i).ok())
            .unwrap_or(0);
        self.first_refused.store(next, Ordering::Relaxed);
        report
    }

    /// Tells the nodes that declared `frame`'s ID that the transport refused it
    /// ([`CanNode::frame_refused`]). Off the common path: only for refused frames.
    #[cold]
    fn tell_refused(&self, frame: &CanFrame, reason: SendError) {
        let id = frame.id();
        for (node, declared) in self.nodes.iter().zip(&self.declared) {
            if declared.declares(id) {
                node.frame_refused(frame, reason);
            }
        }
    }

    /// Routes a received frame to the node that claims it.
    ///
    /// A node is offered only frames on IDs it declared in its
    /// [`BusUsage::listen`](crate::node::BusUsage::listen) set (registration guarantees at
    /// most one node declares any ID); its [`CanNode::matches_frame`] then decides whether it
    /// takes the frame, so it can narrow its declared set (e.g. refuse remote frames) but never
    /// widen it: a frame on an ID no node declared is unmatched, whatever `matches_frame`
    /// would say. This is what the hardware acceptance filters, built from the same
    /// declarations ([`crate::can::acceptance`]), let through anyway. The declaring node is
    /// found by a table indexed by the ID for standard IDs 0x200–0x20F (every DJI feedback
    /// ID), by a scan of the declared sets otherwise: the cost does not grow with traffic.
    pub fn dispatch(&self, frame: &CanFrame, now: Instant) -> Dispatch {
        self.stats.record_rx(timing::unstuffed_bits(frame));
        if let Some(i) = self.declared_listener(frame)
            && let Some(node) = self.nodes.get(i)
            && node.matches_frame(frame)
        {
            return match node.update_feedback(frame, now) {
                Ok(()) => Dispatch::Handled(i),
                Err(e) => {
                    self.stats.record_rejected();
                    Dispatch::Rejected(i, e)
                }
            };
        }
        self.stats.record_unmatched();
        Dispatch::Unmatched
    }

    /// The index of the node whose declared listen set holds the frame's ID, if any.
    #[inline]
    fn declared_listener(&self, frame: &CanFrame) -> Option<usize> {
        let id = frame.id();
        if let crate::can::Id::Standard(standard) = id
            && let Some(&entry) = self
                .route
                .get(usize::from(standard.as_raw().wrapping_sub(ROUTE_BASE)))
        {
            return usize::from(entry).checked_sub(1);
        }
        self.declared.iter().position(|d| d.listen.matches(id))
    }

    /// Counts a receive-side error reported by the transport. A bus-off report from the
    /// receive side is not counted here: [`transmit`](Self::transmit) is the one place that
    /// tracks bus-off (the same condition is visible to it through `status()` or `try_send`),
    /// so each entry counts once.
    pub fn record_receive_error(&self, error: ReceiveError) {
        match error {
            ReceiveError::Overrun => self.stats.record_overrun(),
            ReceiveError::BusError => self.stats.record_bus_error(),
            ReceiveError::BusOff => {}
        }
    }

    /// Counts scheduler ticks that were skipped to re-synchronise after a stall.
    pub fn record_skipped_ticks(&self, ticks: u32) {
        if ticks > 0 {
            self.stats.record_skipped_ticks(ticks);
        }
    }
}

/// Where the scheduler's ticks come from. On a board: [`TickerTicks`] (an embassy-time
/// `Ticker`); in tests, a fake clock.
#[allow(async_fn_in_trait)] // Used through generics in Embassy tasks; no Send bound is wanted.
pub trait TickSource {
    /// Waits for the next tick and returns the time it started.
    async fn next_tick(&mut self) -> Instant;

    /// Forgets any ticks that are already due: the next tick comes one period after `now`.
    fn resync(&mut self, now: Instant);
}

/// An embassy-time `Ticker` as a [`TickSource`]. Reads the global embassy-time clock: this
/// and [`run_receiver`]'s back-off are the only places in rc10-core that do.
pub struct TickerTicks {
    ticker: embassy_time::Ticker,
}

impl TickerTicks {
    /// Ticks every `period`, held within [`BusConfig::MIN_TICK_PERIOD`] (100 µs) and
    /// [`BusConfig::MAX_TICK_PERIOD`] (an hour), the periods a bus accepts. Below the
    /// minimum a tick's work would outlast its period: the ticker would always be due, the
    /// task would never wait, and no other task on its executor would run (a period of 0
    /// never waits at all). Above the maximum embassy-time's `Ticker` panics on overflowing
    /// its clock.
    pub fn every(period: Duration) -> Self {
        let period = period.clamp(BusConfig::MIN_TICK_PERIOD, BusConfig::MAX_TICK_PERIOD);
        Self {
            ticker: embassy_time::Ticker::every(period),
        }
    }
}

impl TickSource for TickerTicks {
    async fn next_tick(&mut self) -> Instant {
        self.ticker.next().await;
        Instant::now()
    }

    fn resync(&mut self, _now: Instant) {
        // `Ticker::reset` schedules the next tick one period from the present.
        self.ticker.reset();
    }
}

/// What [`TickPacer::on_tick`] decided for one tick.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PacedTick {
    /// Seconds since the previous tick, within `[period / 2, 10 · period]`.
    pub dt_s: f32,
    /// Whether the tick source must be re-synchronised (this tick was late by half a period
    /// or more, so the ticks that fell due meanwhile are skipped rather than run back to back).
    pub resync: bool,
    /// Whole periods skipped by that re-synchronisation.
    pub skipped: u32,
}

/// The scheduler's timing rules, kept apart from any clock so they can be tested with fake
/// time.
///
/// embassy-time's `Ticker` (like a FreeRTOS `vTaskDelayUntil` loop) fires ticks it missed
/// during a stall back to back, a few microseconds apart. Control loops would then see a burst
/// of tiny `dt`s (D terms spike) and the bus a burst of commands. The pacer tracks when the
/// next tick is due; a tick that starts half a period or more after that is *late*: the source
/// is re-synchronised (the missed ticks are skipped and counted) and the next tick comes one
/// period later. Ticks are therefore never closer than half a period, and every `dt` is at
/// most ten periods after a long stall ([`DeltaTime`] bounds it).
///
/// The price of that spacing: a scheduler task that *always* wakes half a period or more
/// late (its executor busy with other work at every tick) runs slower, each period stretched
/// by its lateness (0.6 ms late at 1 kHz: every 1.6 ms), with a true `dt` and with no tick
/// counted as skipped (no whole period passed unserved). Give the scheduler its own
/// higher-priority executor (`InterruptExecutor`) so that it wakes on time.
///
/// ```
/// use rc10_core::bus::TickPacer;
/// use rc10_core::time::{Duration, Instant};
/// let mut pacer = TickPacer::new(Duration::from_millis(1));
/// pacer.on_tick(Instant::from_millis(0));
/// let late = pacer.on_tick(Instant::from_millis(50)); // a 49 ms stall
/// assert!(late.resync);
/// assert_eq!(late.skipped, 49);
/// assert_eq!(late.dt_s, 0.01); // bounded to ten periods
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TickPacer {
    /// The period in ticks: never zero, so dividing by it cannot fail.
    period: NonZeroU64,
    next_due: Option<Instant>,
    dt: DeltaTime,
}

impl TickPacer {
    /// A pacer for ticks every `period` (zero is raised to 1 µs).
    pub const fn new(period: Duration) -> Self {
        let period = match NonZeroU64::new(period.as_ticks()) {
            Some(ticks) => ticks,
            None => match NonZeroU64::new(Duration::from_micros(1).as_ticks()) {
                Some(ticks) => ticks,
                None => NonZeroU64::MIN, // unreachable: 1 µs rounds up to at least one tick
            },
        };
        Self {
            period,
            next_due: None,
            dt: DeltaTime::new(
                Duration::from_ticks(period.get()),
                Duration::from_ticks(period.get().saturating_mul(10)),
            ),
        }
    }

    /// Called at the start of each tick with the time `now`.
    pub fn on_tick(&mut self, now: Instant) -> PacedTick {
        let (resync, skipped) = match self.next_due {
            // The first tick: align the source with the pacer.
            None => (true, 0),
            Some(due) => {
                let late = now.saturating_duration_since(due).as_ticks();
                // `late · 2 ≥ period`, without overflowing for a timestamp far ahead.
                if late >= self.period.get().div_ceil(2) {
                    let missed = late / self.period;
                    (true, u32::try_from(missed).unwrap_or(u32::MAX))
                } else {
                    (false, 0)
                }
            }
        };
        // Saturates at the end of time (u64 ticks) instead of panicking.
        let period = Duration::from_ticks(self.period.get());
        self.next_due = Some(match (resync, self.next_due) {
            (false, Some(due)) => due.saturating_add(period),
            _ => now.saturating_add(period),
        });
        PacedTick {
            dt_s: self.dt.update(now),
            resync,
            skipped,
        }
    }
}

/// The scheduler task's loop: every [`BusConfig::tick_period`] of the bus from an
/// embassy-time `Ticker`, [`Bus::tick`] then [`Bus::transmit`]. Timing follows
/// [`TickPacer`]: `dt` stays within `[period / 2, 10 · period]`, and after a stall the
/// missed ticks are skipped (counted in `ticks_skipped`), not run back to back.
///
/// The period is the bus's own, so the ticks, the `dt` the controllers get and the load
/// figures registration checked against ([`BusConfig`]) cannot disagree. (A bus whose
/// configuration fails [`BusConfig::check`] holds no nodes; its ticker keeps to the
/// accepted periods: [`TickerTicks::every`].)
pub async fn run_scheduler<T: CanTransmit, const N: usize>(bus: &Bus<'_, N>, tx: T) -> ! {
    let period = bus.config().tick_period;
    run_scheduler_on(bus, tx, TickerTicks::every(period)).await
}

/// [`run_scheduler`] with the ticks taken from `ticks` (a fake clock in tests, or your own
/// timer), which should come every [`BusConfig::tick_period`] of the bus: the pacer holds
/// `dt` to that period's bounds and counts ticks later than it as skipped.
pub async fn run_scheduler_on<T: CanTransmit, S: TickSource, const N: usize>(
    bus: &Bus<'_, N>,
    mut tx: T,
    mut ticks: S,
) -> ! {
    let mut pacer = TickPacer::new(bus.config().tick_period);
    let mut batch = TxBatch::new();
    loop {
        let now = ticks.next_tick().await;
        let paced = pacer.on_tick(now);
        if paced.resync {
            ticks.resync(now);
            bus.record_skipped_ticks(paced.skipped);
        }
        bus.tick(now, paced.dt_s, &mut batch);
        bus.transmit(&batch, &mut tx);
    }
}

/// How long [`run_receiver`] waits after consecutive receive errors: nothing after the first
/// (an overrun is a one-off event and the FIFO should be drained at once), then 100 µs,
/// doubling up to 10 ms while errors continue; back to nothing after a frame arrives.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ReceiveBackoff {
    consecutive_errors: u32,
}

impl ReceiveBackoff {
    /// First wait after a repeated error.
    pub const FIRST: Duration = Duration::from_micros(100);
    /// Longest wait.
    pub const MAX: Duration = Duration::from_millis(10);

    /// No errors yet.
    pub const fn new() -> Self {
        Self {
            consecutive_errors: 0,
        }
    }

    /// A frame arrived: errors are no longer consecutive.
    pub fn on_frame(&mut self) {
        self.consecutive_errors = 0;
    }

    /// An error was reported: how long to wait before receiving again, if at all.
    pub fn on_error(&mut self) -> Option<Duration> {
        self.consecutive_errors = self.consecutive_errors.saturating_add(1);
        let doublings = self.consecutive_errors.checked_sub(2)?;
        let first = Self::FIRST.as_ticks();
        let wait = first
            .checked_shl(doublings.min(16))
            .unwrap_or(u64::MAX)
            .min(Self::MAX.as_ticks());
        Some(Duration::from_ticks(wait))
    }
}

/// The receiver task's loop: awaits frames and dispatches each with its timestamp. A
/// transport that keeps reporting errors does not make it spin: see [`ReceiveBackoff`].
pub async fn run_receiver<R: CanReceive, const N: usize>(bus: &Bus<'_, N>, mut rx: R) -> ! {
    let mut backoff = ReceiveBackoff::new();
    loop {
        match rx.receive().await {
            Ok(received) => {
                backoff.on_frame();
                bus.dispatch(&received.frame, received.timestamp);
            }
            Err(e) => {
                bus.record_receive_error(e);
                if let Some(wait) = backoff.on_error() {
                    embassy_time::Timer::after(wait).await;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests;
