//! The scheduler-facing side of a device on a CAN bus ([`CanNode`]), what it declares about
//! its bus use ([`BusUsage`]), and the per-tick batch it packs commands into ([`TxBatch`]).
//!
//! This replaces RC10_LIB's `Motor_Base` virtuals `update()`, `packCommand()`,
//! `matchesFrame()` and `updateFeedback()`. All methods take `&self`: a node is shared, as a
//! `&'static dyn CanNode`, by the scheduler task, the receiver task and application tasks, and
//! keeps its mutable state behind its own short critical section (see [`crate::motor`]).

use crate::can::{CanFrame, Id, IdFilter, RawId, SendError};
use crate::time::Instant;
use core::fmt;

/// Most frames one tick can pack on one bus. At 1 Mbit/s one millisecond carries at most
/// nine 8-byte frames, so 16 leaves room for ticks up to about 2 ms; registration refuses a
/// node that would take a bus past it (`RegisterError::TickBatch`), so no node's frames are
/// left out of the batch every tick.
pub const MAX_FRAMES_PER_TICK: usize = 16;

/// Most ID filters one [`IdSet`] holds (a VESC listening to all five of its status packets
/// needs five).
pub const ID_SET_CAPACITY: usize = 6;

/// A two-byte slot in a shared command frame: DJI ESCs read their current/voltage command
/// from bytes `2·index` and `2·index + 1` of a frame with a standard ID (0x200, 0x1FF, …).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CommandSlot {
    id: u16,
    index: u8,
}

impl CommandSlot {
    /// Slot `index` (0–3) of standard-ID frame `id`; `None` if either is out of range.
    pub const fn new(id: u16, index: u8) -> Option<Self> {
        if id <= 0x7FF && index < 4 {
            Some(Self { id, index })
        } else {
            None
        }
    }

    /// The command frame's standard ID.
    pub const fn id(&self) -> u16 {
        self.id
    }

    /// The slot index, 0–3 (bytes `2·index`, `2·index + 1`).
    pub const fn index(&self) -> u8 {
        self.index
    }

    /// The filter that matches exactly this slot's frame ID.
    pub const fn frame_filter(&self) -> IdFilter {
        IdFilter::standard(self.id)
    }
}

/// A small fixed set of ID filters: the IDs a node listens on, or the IDs it sends whole
/// frames on. `const`-constructible, so a node's declaration can be a constant.
///
/// Adding beyond [`ID_SET_CAPACITY`] filters does not drop anything silently: the set
/// remembers that it overflowed and registration refuses the node
/// ([`RegisterError::TooManyIds`](crate::bus::RegisterError::TooManyIds)).
///
/// ```
/// use rc10_core::can::{CanFrame, IdFilter};
/// use rc10_core::node::IdSet;
/// const FEEDBACK: IdSet = IdSet::EMPTY.with(IdFilter::standard(0x381)).with(IdFilter::standard(0x391));
/// assert!(FEEDBACK.matches(CanFrame::standard(0x391, &[]).unwrap().id()));
/// assert!(!FEEDBACK.matches(CanFrame::standard(0x392, &[]).unwrap().id()));
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct IdSet {
    filters: [IdFilter; ID_SET_CAPACITY],
    len: u8,
    overflowed: bool,
}

impl IdSet {
    /// No IDs.
    pub const EMPTY: Self = Self {
        filters: [IdFilter::standard(0); ID_SET_CAPACITY],
        len: 0,
        overflowed: false,
    };

    /// A set of one filter.
    pub const fn one(filter: IdFilter) -> Self {
        Self::EMPTY.with(filter)
    }

    /// This set plus `filter` (marked overflowed if it is already full).
    #[must_use]
    pub const fn with(mut self, filter: IdFilter) -> Self {
        let at = self.len as usize;
        if at < ID_SET_CAPACITY {
            // `get_mut` is not callable in a const fn.
            #[allow(
                clippy::indexing_slicing,
                clippy::arithmetic_side_effects,
                reason = "at = len < ID_SET_CAPACITY (checked on the line above)"
            )]
            {
                self.filters[at] = filter;
                self.len += 1;
            }
        } else {
            self.overflowed = true;
        }
        self
    }

    /// The filters.
    pub fn filters(&self) -> &[IdFilter] {
        self.filters.get(..usize::from(self.len)).unwrap_or(&[])
    }

    /// Whether no filter is in the set.
    pub const fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Whether more filters were added than the set holds.
    pub const fn overflowed(&self) -> bool {
        self.overflowed
    }

    /// Whether `id` passes some filter of the set.
    pub fn matches(&self, id: Id) -> bool {
        self.filters().iter().any(|f| f.matches(id))
    }

    /// Whether any filter of the set uses extended IDs.
    pub fn any_extended(&self) -> bool {
        self.filters().iter().any(|f| f.extended)
    }

    /// An ID that passes both a filter of this set and `filter`, if there is one.
    pub fn common_id(&self, filter: &IdFilter) -> Option<RawId> {
        self.filters().iter().find_map(|f| f.common_id(filter))
    }

    /// An ID that passes a filter of this set and a filter of `other`, if there is one.
    pub fn common_id_with(&self, other: &IdSet) -> Option<RawId> {
        other.filters().iter().find_map(|f| self.common_id(f))
    }
}

impl Default for IdSet {
    fn default() -> Self {
        Self::EMPTY
    }
}

/// What a node does on the bus, declared once at registration so the bus can check every ID
/// against every other node's, the transport's TX depth and the frame budget before anything
/// runs (ARCHITECTURE.md, property 6).
///
/// A node declares *every* ID it listens on and *every* ID it transmits on:
/// - [`listen`](Self::listen): where its feedback arrives (also what the default
///   [`CanNode::matches_frame`] claims, and what a hardware acceptance filter is built from);
/// - [`command_slot`](Self::command_slot): a two-byte slot in a shared command frame (DJI);
/// - [`sends`](Self::sends) and [`frames_per_tick`](Self::frames_per_tick): whole frames it
///   pushes every tick, on IDs from `sends` (VESC, Damiao, your own device).
///
/// Build it with the `const` chainable setters:
///
/// ```
/// use rc10_core::can::IdFilter;
/// use rc10_core::node::BusUsage;
/// // Command on 0x301 every tick, feedback on 0x381 at 1 kHz.
/// const USAGE: BusUsage = BusUsage::NONE
///     .listening(IdFilter::standard(0x381), 1000)
///     .sending(IdFilter::standard(0x301), 1);
/// assert_eq!(USAGE.frames_per_tick, 1);
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BusUsage {
    /// The IDs this node's feedback arrives on (empty: it receives nothing). This is the
    /// whole of what the node can receive: [`Bus::dispatch`](crate::bus::Bus::dispatch)
    /// offers a node only frames on these IDs (and the hardware acceptance filters are built
    /// from them), so [`CanNode::matches_frame`] can narrow it but never widen it.
    pub listen: IdSet,
    /// Feedback frames per second the device sends on all of `listen` together by its own
    /// clock (1000 for a DJI ESC), for the frame budget.
    pub feedback_hz: u32,
    /// Feedback frames the device sends in answer to each tick's commands (a Damiao motor
    /// replies to every command frame: 1), for the frame budget: per tick whatever the tick
    /// period, where [`feedback_hz`](Self::feedback_hz) is per second.
    pub replies_per_tick: u8,
    /// A slot in a shared command frame this node writes every tick.
    pub command_slot: Option<CommandSlot>,
    /// The IDs this node's whole frames go out on.
    pub sends: IdSet,
    /// Whole frames this node pushes per tick besides its slot (VESC, Damiao: 1). Each must
    /// carry an ID from [`sends`](Self::sends).
    pub frames_per_tick: u8,
}

impl BusUsage {
    /// A node that neither listens nor sends.
    pub const NONE: Self = Self {
        listen: IdSet::EMPTY,
        feedback_hz: 0,
        replies_per_tick: 0,
        command_slot: None,
        sends: IdSet::EMPTY,
        frames_per_tick: 0,
    };

    /// Adds a listen filter and `hz` feedback frames per second arriving through it.
    #[must_use]
    pub const fn listening(mut self, filter: IdFilter, hz: u32) -> Self {
        self.listen = self.listen.with(filter);
        self.feedback_hz = self.feedback_hz.saturating_add(hz);
        self
    }

    /// Adds a listen filter and `replies` feedback frames a tick arriving through it in
    /// answer to the node's commands.
    #[must_use]
    pub const fn answering(mut self, filter: IdFilter, replies: u8) -> Self {
        self.listen = self.listen.with(filter);
        self.replies_per_tick = self.replies_per_tick.saturating_add(replies);
        self
    }

    /// Sets the shared-frame command slot.
    #[must_use]
    pub const fn with_slot(mut self, slot: CommandSlot) -> Self {
        self.command_slot = Some(slot);
        self
    }

    /// Adds the IDs in `filter` to those whole frames go out on, and `frames` to the whole
    /// frames pushed per tick.
    #[must_use]
    pub const fn sending(mut self, filter: IdFilter, frames: u8) -> Self {
        self.sends = self.sends.with(filter);
        self.frames_per_tick = self.frames_per_tick.saturating_add(frames);
        self
    }

    /// Every ID this node transmits on: its whole-frame IDs and its slot frame's ID.
    pub fn transmit_ids(&self) -> IdSet {
        match self.command_slot {
            Some(slot) => self.sends.with(slot.frame_filter()),
            None => self.sends,
        }
    }
}

/// Why a node did not accept a frame it claimed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FrameError {
    /// The frame's length (or remote flag) is not what the protocol sends.
    WrongLength {
        /// The DLC received.
        dlc: u8,
    },
    /// A field holds a value the protocol never sends (e.g. an encoder count ≥ 8192).
    OutOfRange,
    /// The frame is of a kind this node does not parse (e.g. an unknown VESC status packet).
    Unsupported,
    /// The frame is stamped before the newest one the node took: it is older than the
    /// node's state (a transport that stamps frames itself delivered it late).
    OutOfOrder,
}

impl fmt::Display for FrameError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::WrongLength { dlc } => write!(f, "feedback frame has wrong length {dlc}"),
            Self::OutOfRange => f.write_str("feedback field out of range"),
            Self::Unsupported => f.write_str("feedback frame kind not supported"),
            Self::OutOfOrder => f.write_str("feedback frame older than the last one taken"),
        }
    }
}

impl core::error::Error for FrameError {}

/// The frames one tick sends on one bus, in the order they were packed.
///
/// Slot writes with the same command ID merge into one 8-byte frame whose unwritten slots are
/// zero (an unregistered or offline motor's slot is therefore sent as a zero command: zero current, or 0 V for a GM6020 in voltage mode, which brakes a spinning rotor through its back-EMF rather than letting it coast). Beyond
/// [`MAX_FRAMES_PER_TICK`] frames, further ones are counted in
/// [`overflowed`](Self::overflowed), never silently lost.
///
/// ```
/// use rc10_core::node::{CommandSlot, TxBatch};
/// let mut batch = TxBatch::new();
/// batch.write_slot(CommandSlot::new(0x200, 1).unwrap(), 1000);
/// batch.write_slot(CommandSlot::new(0x200, 3).unwrap(), -1);
/// assert_eq!(batch.frames().len(), 1);
/// assert_eq!(batch.frames()[0].data(), &[0, 0, 0x03, 0xE8, 0, 0, 0xFF, 0xFF]);
/// ```
///
/// A node's [`pack_command`](CanNode::pack_command) gets the batch holding the frames of the
/// nodes packed before it, and can only add to it: emptying it is the bus's alone.
///
/// ```compile_fail
/// fn pack_command(out: &mut rc10_core::node::TxBatch) {
///     out.clear(); // would drop every motor packed before this node
/// }
/// ```
#[derive(Debug, Clone)]
pub struct TxBatch {
    frames: heapless::Vec<CanFrame, MAX_FRAMES_PER_TICK>,
    /// Bit `i` set: frame `i` is a shared slot frame (only these take slot writes).
    slot_frames: u16,
    overflowed: u32,
    /// The slot frame written last, as (command ID, index in `frames`): the motors of one
    /// command frame are usually packed one after another, so the next slot write finds its
    /// frame here without a search. Only ever a slot frame's true position (reset whenever
    /// frames move); the ID [`NO_SLOT_FRAME`] (no standard ID) when there is none.
    last_slot: (u16, u8),
    /// The only slot [`write_slot`](Self::write_slot) may write, as [`slot_key`]: while the
    /// bus packs a node, the slot it declared ([`NO_SLOT`] if none); [`ANY_SLOT`] otherwise.
    allowed_slot: u32,
    /// Slot writes refused since the bus last took the count (a node writing a slot it did
    /// not declare: another motor's, or one on someone's feedback ID).
    refused_slots: u32,
}

/// [`TxBatch`]'s "no slot frame written yet": above every standard ID, so no slot matches it.
const NO_SLOT_FRAME: (u16, u8) = (u16::MAX, 0);

/// [`TxBatch::allowed_slot`]: every slot may be written (a batch used on its own).
const ANY_SLOT: u32 = u32::MAX;
/// [`TxBatch::allowed_slot`]: no slot may be written (a node that declared none).
const NO_SLOT: u32 = u32::MAX - 1;

/// A slot as one number (ID in bits 8–18, index in bits 0–7): never [`ANY_SLOT`] or
/// [`NO_SLOT`].
const fn slot_key(slot: CommandSlot) -> u32 {
    (slot.id as u32) << 8 | slot.index as u32
}

/// What [`TxBatch::allow_only_slot`] takes for a node that declared `slot` (worked out once,
/// at registration).
pub(crate) const fn slot_permission(slot: Option<CommandSlot>) -> u32 {
    match slot {
        Some(slot) => slot_key(slot),
        None => NO_SLOT,
    }
}

/// The command ID of the slot a [`slot_permission`] value allows, if it names one.
pub(crate) const fn slot_permission_id(permission: u32) -> Option<u16> {
    match permission {
        ANY_SLOT | NO_SLOT => None,
        // The ID takes bits 8–18 of the key: it fits a u16.
        key => Some((key >> 8) as u16),
    }
}

impl Default for TxBatch {
    /// An empty batch, as [`TxBatch::new`] (a derived default would remember a slot frame
    /// with ID 0x000 at index 0 that is not there).
    fn default() -> Self {
        Self::new()
    }
}

impl TxBatch {
    /// An empty batch.
    pub const fn new() -> Self {
        Self {
            frames: heapless::Vec::new(),
            slot_frames: 0,
            overflowed: 0,
            last_slot: NO_SLOT_FRAME,
            allowed_slot: ANY_SLOT,
            refused_slots: 0,
        }
    }

    /// The index of the slot frame for command ID `id`, if one is in the batch.
    fn slot_frame_index(&self, id: u16) -> Option<usize> {
        let slot_frames = self.slot_frames;
        self.frames
            .iter()
            .enumerate()
            .position(|(i, f)| slot_frames & (1 << i) != 0 && f.raw_id() == u32::from(id))
    }

    /// Writes `value` big-endian into `slot`, creating the zero-filled command frame if this is
    /// the first slot written for its ID this tick. Returns `false` (and counts an overflow) if
    /// the batch has no room for a new frame.
    ///
    /// Slot writes merge only into slot frames: a whole frame [`push`](Self::push)ed on the
    /// same ID is never written into (registration rejects that clash; should it happen
    /// anyway, the two frames stay separate).
    ///
    /// While a [`Bus`](crate::bus::Bus) packs a node, only the slot that node declared
    /// ([`BusUsage::command_slot`]) can be written: any other write returns `false`, changes
    /// nothing and is counted in `tx_undeclared`, so a node cannot overwrite another motor's
    /// command or send a slot frame registration did not check.
    pub fn write_slot(&mut self, slot: CommandSlot, value: i16) -> bool {
        let key = slot_key(slot);
        if self.allowed_slot != key && self.allowed_slot != ANY_SLOT {
            self.refused_slots = self.refused_slots.saturating_add(1);
            return false;
        }
        let index = match self.last_slot {
            (id, index) if id == slot.id => usize::from(index),
            _ => {
                let index = match self.slot_frame_index(slot.id) {
                    Some(i) => i,
                    None => {
                        let Some(fresh) = CanFrame::standard(slot.id, &[0; 8]) else {
                            return false; // unreachable: CommandSlot::new checked the ID
                        };
                        let index = self.frames.len();
                        if self.frames.push(fresh).is_err() {
                            self.count_overflow();
                            return false;
                        }
                        self.slot_frames |= 1 << index;
                        index
                    }
                };
                // index < MAX_FRAMES_PER_TICK = 16: fits a u8.
                self.last_slot = (slot.id, index as u8);
                index
            }
        };
        let Some(frame) = self.frames.get_mut(index) else {
            return false; // unreachable: the index is a frame's
        };
        // Slot `index` is bytes 2·index and 2·index + 1; `index & 3` is `index` (below 4, as
        // `CommandSlot::new` checked) in a form the compiler knows is in bounds.
        let (pairs, _) = frame.buffer_mut().as_chunks_mut::<2>();
        if let Some(pair) = pairs.get_mut(usize::from(slot.index & 3)) {
            *pair = value.to_be_bytes();
        }
        true
    }

    /// Counts a frame that did not fit. Saturating: the count is cleared every tick and can
    /// reach at most the frames one tick packs, but it must never wrap to a small number.
    fn count_overflow(&mut self) {
        self.overflowed = self.overflowed.saturating_add(1);
    }

    /// Appends a whole frame; hands it back (and counts an overflow) if the batch is full.
    pub fn push(&mut self, frame: CanFrame) -> Result<(), CanFrame> {
        self.frames
            .push(frame)
            .inspect_err(|_| self.count_overflow())
    }

    /// Drops the whole frames packed at index `from` and after that a node did not declare:
    /// on an ID outside `sends`, or beyond the first `frames_per_tick` on IDs in it (slot
    /// frames are left alone). Returns how many were dropped. The bus calls this after each node's
    /// `pack_command`, so a node can never send what registration did not check.
    /// Crate-private: a node must not be able to drop the frames of the nodes packed before it.
    #[allow(
        clippy::arithmetic_side_effects,
        reason = "i < frames.len() ≤ MAX_FRAMES_PER_TICK = 16 (shifts by at most 16 in 32 bits) and dropped ≤ i"
    )]
    pub(crate) fn keep_declared(&mut self, from: usize, frames_per_tick: u8, sends: &IdSet) -> u32 {
        let mut whole = 0u8;
        let mut dropped = 0u32;
        let mut i = from;
        while let Some(frame) = self.frames.get(i) {
            if self.slot_frames & (1 << i) != 0 {
                i += 1;
                continue;
            }
            // Only declared frames use up the allowance: an undeclared one dropped before a
            // declared one must not take the declared one down with it.
            let declared = sends.matches(frame.id());
            if declared {
                whole = whole.saturating_add(1);
            }
            if !declared || whole > frames_per_tick {
                self.frames.remove(i);
                // Frames after `i` moved down: the remembered slot frame may have moved.
                self.last_slot = NO_SLOT_FRAME;
                // Slot-frame flags above `i` move down with their frames.
                // In 32 bits: `i + 1` reaches 16 when the 16th frame goes, a full shift of a
                // u16 (a panic with overflow checks, bit 0 copied to bit 15 without).
                let flags = u32::from(self.slot_frames);
                let below = flags & ((1u32 << i) - 1);
                let above = (flags >> (i + 1)) << i;
                // Both below bit 16: `above` has lost the top flag's place, `below` is under i.
                self.slot_frames = (below | above) as u16;
                dropped += 1;
            } else {
                i += 1;
            }
        }
        dropped
    }

    /// The frames packed so far.
    pub fn frames(&self) -> &[CanFrame] {
        &self.frames
    }

    /// Frames that did not fit since the batch was last emptied (the bus empties it at the
    /// start of each tick).
    pub const fn overflowed(&self) -> u32 {
        self.overflowed
    }

    /// Empties the batch for the next tick. Crate-private: a node's `pack_command` gets the
    /// batch with the frames of the nodes packed before it, and must not be able to drop them.
    pub(crate) fn clear(&mut self) {
        self.frames.clear();
        self.slot_frames = 0;
        self.overflowed = 0;
        self.last_slot = NO_SLOT_FRAME;
    }

    /// From now on, only the slot `permission` ([`slot_permission`]) names may be written:
    /// the bus calls this before each node's `pack_command`, with the slot the node declared.
    pub(crate) fn allow_only_slot(&mut self, permission: u32) {
        self.allowed_slot = permission;
    }

    /// Every slot may be written again; returns how many slot writes were refused since the
    /// last call (and forgets them).
    pub(crate) fn allow_any_slot(&mut self) -> u32 {
        self.allowed_slot = ANY_SLOT;
        core::mem::take(&mut self.refused_slots)
    }
}

/// The scheduler-facing side of a device on a CAN bus.
///
/// The bus calls, every tick, [`update`](Self::update) on every node (control math only), then
/// [`pack_command`](Self::pack_command) on every node (frame assembly only), then sends.
/// The receiver calls [`update_feedback`](Self::update_feedback) on the one node whose
/// [`matches_frame`](Self::matches_frame) claims a received frame.
///
/// None of these may block or panic; each should hold its node's lock only for its own few
/// instructions.
pub trait CanNode: Sync {
    /// What this node listens to and sends, for registration checks and the frame budget.
    fn bus_usage(&self) -> BusUsage;

    /// Whether a received frame is this node's feedback. The default uses
    /// [`BusUsage::listen`].
    ///
    /// The bus asks only about frames on IDs in the node's declared
    /// [`BusUsage::listen`] set: an override can refuse some of those (narrow the set, e.g. by
    /// DLC or remote flag), but claiming an ID outside it has no effect, since such a frame
    /// is never offered to the node (nor let in by the acceptance filters built from the
    /// declarations).
    fn matches_frame(&self, frame: &CanFrame) -> bool {
        self.bus_usage().listen.matches(frame.id())
    }

    /// Parses a frame this node claimed, received at `now`. Latest value wins: nothing queues.
    fn update_feedback(&self, frame: &CanFrame, now: Instant) -> Result<(), FrameError>;

    /// One control step at `now`, `dt_s` seconds after the previous one. Control math only.
    fn update(&self, now: Instant, dt_s: f32);

    /// Writes this tick's command into `out`. Frame assembly only: no control math.
    fn pack_command(&self, out: &mut TxBatch);

    /// The transport refused `frame`, which this node packed this tick, for `reason` (TX
    /// buffers full, or bus-off): it was not queued and will not go out. Called by
    /// [`Bus::transmit`](crate::bus::Bus::transmit) right after the refusal, before the next
    /// tick, on the node that declared the frame's ID as a whole frame
    /// ([`BusUsage::sending`]) or, for a merged command-slot frame, on every node that
    /// declared a slot of it.
    ///
    /// A node whose commands repeat every tick needs nothing here (the default does
    /// nothing): the next tick sends a fresh one. A node that sends one-shot frames (a
    /// Damiao "save zero") queues the refused one again, or it is lost: it can match the
    /// refusal against what it packed last, since the bus reports refusals of the latest
    /// tick's batch before the next tick (given `transmit` is called as the scheduler does).
    /// The transport's refusal is all the bus knows: a frame it queued can still go
    /// unacknowledged.
    fn frame_refused(&self, frame: &CanFrame, reason: SendError) {
        let _ = (frame, reason);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dropping_an_undeclared_frame_keeps_the_slot_frames_around_it() {
        // Frames: slot frame 0x200, a whole frame on 0x300 nobody declared, slot frame 0x1FF.
        let (a0, a1) = (
            CommandSlot::new(0x200, 0).unwrap(),
            CommandSlot::new(0x200, 1).unwrap(),
        );
        let (b1, b2) = (
            CommandSlot::new(0x1FF, 1).unwrap(),
            CommandSlot::new(0x1FF, 2).unwrap(),
        );
        let mut batch = TxBatch::new();
        assert!(batch.write_slot(a0, 100));
        batch
            .push(CanFrame::standard(0x300, &[1]).unwrap())
            .unwrap();
        assert!(batch.write_slot(b1, 200));
        assert_eq!(batch.keep_declared(1, 0, &IdSet::EMPTY), 1);
        assert_eq!(batch.frames().len(), 2);
        // Both slot frames are still known as such: later slots merge into them.
        assert!(batch.write_slot(a1, 300));
        assert!(batch.write_slot(b2, 400));
        assert_eq!(batch.frames().len(), 2);
        assert_eq!(batch.frames()[0].raw_id(), 0x200);
        assert_eq!(batch.frames()[0].data(), &[0, 100, 0x01, 0x2C, 0, 0, 0, 0]);
        assert_eq!(batch.frames()[1].raw_id(), 0x1FF);
        assert_eq!(batch.frames()[1].data(), &[0, 0, 0, 200, 0x01, 0x90, 0, 0]);
        // A whole frame pushed now is checked like any other, not mistaken for a slot frame.
        batch
            .push(CanFrame::standard(0x300, &[2]).unwrap())
            .unwrap();
        assert_eq!(batch.keep_declared(2, 0, &IdSet::EMPTY), 1);
        assert_eq!(batch.keep_declared(0, 0, &IdSet::EMPTY), 0);
        assert_eq!(batch.frames().len(), 2);
    }

    #[test]
    fn command_slot_rejects_out_of_range() {
        assert!(CommandSlot::new(0x200, 4).is_none());
        assert!(CommandSlot::new(0x800, 0).is_none());
        assert!(CommandSlot::new(0x7FF, 3).is_some());
    }

    #[test]
    fn slots_of_different_ids_make_separate_frames_in_pack_order() {
        let mut b = TxBatch::new();
        b.write_slot(CommandSlot::new(0x1FF, 0).unwrap(), 0x0102);
        b.write_slot(CommandSlot::new(0x200, 0).unwrap(), 0x0304);
        b.write_slot(CommandSlot::new(0x1FF, 2).unwrap(), 0x0506);
        let ids: Vec<u32> = b.frames().iter().map(|f| f.raw_id()).collect();
        assert_eq!(ids, vec![0x1FF, 0x200]);
        assert_eq!(b.frames()[0].data(), &[1, 2, 0, 0, 5, 6, 0, 0]);
        assert_eq!(b.frames()[1].data(), &[3, 4, 0, 0, 0, 0, 0, 0]);
    }

    #[test]
    fn slot_write_never_merges_into_a_whole_frame_on_the_same_id() {
        // A (misconfigured) Damiao motor on CAN ID 0x200 pushed its MIT frame first: the C620
        // slot must not overwrite its bytes, nor may the C620s read its fields as currents.
        let mut b = TxBatch::new();
        let mit = CanFrame::standard(0x200, &[0x7F, 0xFF, 0x7F, 0xF0, 0, 0, 0x07, 0xFF]).unwrap();
        b.push(mit).unwrap();
        b.write_slot(CommandSlot::new(0x200, 0).unwrap(), 0x0102);
        b.write_slot(CommandSlot::new(0x200, 1).unwrap(), 0x0304);
        assert_eq!(b.frames().len(), 2);
        assert_eq!(b.frames()[0], mit);
        assert_eq!(b.frames()[1].data(), &[1, 2, 3, 4, 0, 0, 0, 0]);
    }

    #[test]
    fn undeclared_whole_frames_are_dropped_and_slot_frames_kept() {
        let mut b = TxBatch::new();
        b.write_slot(CommandSlot::new(0x200, 0).unwrap(), 1);
        b.push(CanFrame::standard(0x301, &[1]).unwrap()).unwrap(); // declared
        b.write_slot(CommandSlot::new(0x1FF, 0).unwrap(), 2); // a slot frame after it
        b.push(CanFrame::standard(0x305, &[2]).unwrap()).unwrap(); // undeclared ID
        b.push(CanFrame::standard(0x301, &[3]).unwrap()).unwrap(); // one too many
        let sends = IdSet::one(IdFilter::standard(0x301));
        assert_eq!(b.keep_declared(1, 1, &sends), 2);
        let ids: Vec<u32> = b.frames().iter().map(|f| f.raw_id()).collect();
        assert_eq!(ids, [0x200, 0x301, 0x1FF]);
        // The slot flag moved with its frame: a later slot write still merges into it.
        b.write_slot(CommandSlot::new(0x1FF, 1).unwrap(), 3);
        assert_eq!(b.frames().len(), 3);
        assert_eq!(b.frames()[2].data(), &[0, 2, 0, 3, 0, 0, 0, 0]);
    }

    #[test]
    fn an_undeclared_frame_does_not_use_up_the_allowance_of_a_declared_one() {
        // A node allowed one frame on 0x301 packs a stray 0x305 first: the stray goes, the
        // command stays (counting the stray dropped both, and the motor timed out).
        let mut b = TxBatch::new();
        b.push(CanFrame::standard(0x305, &[1]).unwrap()).unwrap();
        b.push(CanFrame::standard(0x301, &[2]).unwrap()).unwrap();
        let sends = IdSet::one(IdFilter::standard(0x301));
        assert_eq!(b.keep_declared(0, 1, &sends), 1);
        let ids: Vec<u32> = b.frames().iter().map(|f| f.raw_id()).collect();
        assert_eq!(ids, [0x301]);
    }

    #[test]
    fn slot_write_finds_its_frame_after_an_undeclared_frame_before_it_is_dropped() {
        let mut b = TxBatch::new();
        b.push(CanFrame::standard(0x305, &[9]).unwrap()).unwrap(); // undeclared
        b.write_slot(CommandSlot::new(0x200, 0).unwrap(), 0x0102);
        assert_eq!(b.keep_declared(0, 0, &IdSet::EMPTY), 1);
        // The slot frame moved from index 1 to 0: the next write must land in it.
        b.write_slot(CommandSlot::new(0x200, 1).unwrap(), 0x0304);
        assert_eq!(b.frames().len(), 1);
        assert_eq!(b.frames()[0].data(), &[1, 2, 3, 4, 0, 0, 0, 0]);
        // A cleared batch starts a fresh frame.
        b.clear();
        b.write_slot(CommandSlot::new(0x200, 2).unwrap(), 0x0506);
        assert_eq!(b.frames().len(), 1);
        assert_eq!(b.frames()[0].data(), &[0, 0, 0, 0, 5, 6, 0, 0]);
    }

    #[test]
    fn dropping_the_sixteenth_frame_keeps_the_slot_flags_right() {
        // A slot frame at index 0, 14 declared whole frames, then a 16th frame on an
        // undeclared ID: dropping it shifts the flags by 16 places (a u16 cannot).
        let mut b = TxBatch::new();
        b.write_slot(CommandSlot::new(0x200, 0).unwrap(), 1);
        for k in 0..14u8 {
            b.push(CanFrame::standard(0x301, &[k]).unwrap()).unwrap();
        }
        b.push(CanFrame::standard(0x305, &[0xEE]).unwrap()).unwrap();
        assert_eq!(b.frames().len(), MAX_FRAMES_PER_TICK);
        let sends = IdSet::one(IdFilter::standard(0x301));
        assert_eq!(b.keep_declared(1, 14, &sends), 1);
        assert_eq!(b.frames().len(), 15);
        // Only frame 0 is a slot frame: a whole frame pushed into the freed place is judged
        // as one (dropped: one over the 14 declared), not skipped as a slot frame.
        b.push(CanFrame::standard(0x301, &[0xFF]).unwrap()).unwrap();
        assert_eq!(b.keep_declared(1, 14, &sends), 1);
        assert_eq!(b.frames().len(), 15);
        // And a slot write for another command ID makes its own frame, not a merge into it.
        b.write_slot(CommandSlot::new(0x1FF, 1).unwrap(), 0x0203);
        assert_eq!(b.frames().len(), 16);
        assert_eq!(b.frames()[15].data(), &[0, 0, 2, 3, 0, 0, 0, 0]);
    }

    #[test]
    fn a_default_batch_is_an_empty_one() {
        // Slot ID 0x000 is a valid standard ID: a default batch must not think it already
        // holds that slot frame.
        let mut b = TxBatch::default();
        assert!(b.write_slot(CommandSlot::new(0x000, 1).unwrap(), 0x0102));
        assert_eq!(b.frames().len(), 1);
        assert_eq!(b.frames()[0].raw_id(), 0x000);
        assert_eq!(b.frames()[0].data(), &[0, 0, 1, 2, 0, 0, 0, 0]);
    }

    #[test]
    fn id_set_overflow_is_remembered_not_dropped_silently() {
        let mut s = IdSet::EMPTY;
        for i in 0..ID_SET_CAPACITY as u16 {
            s = s.with(IdFilter::standard(0x100 + i));
        }
        assert!(!s.overflowed());
        s = s.with(IdFilter::standard(0x200));
        assert!(s.overflowed());
        assert_eq!(s.filters().len(), ID_SET_CAPACITY);
    }

    #[test]
    fn transmit_ids_include_the_slot_frame() {
        let u = BusUsage::NONE
            .with_slot(CommandSlot::new(0x1FF, 2).unwrap())
            .sending(IdFilter::extended(0x0103), 1);
        let ids = u.transmit_ids();
        assert!(ids.matches(CanFrame::standard(0x1FF, &[]).unwrap().id()));
        assert!(ids.matches(CanFrame::extended(0x0103, &[]).unwrap().id()));
        assert!(!ids.matches(CanFrame::standard(0x200, &[]).unwrap().id()));
    }

    #[test]
    fn common_id_of_masked_and_exact_filters() {
        let vesc = IdFilter::extended_masked(0x07, 0xFF);
        let exact = IdFilter::extended(0x0907);
        assert_eq!(
            vesc.common_id(&exact),
            Some(RawId {
                id: 0x0907,
                extended: true
            })
        );
        assert_eq!(vesc.common_id(&IdFilter::extended(0x0908)), None);
        assert_eq!(vesc.common_id(&IdFilter::standard(0x007)), None);
    }

    #[test]
    fn full_batch_counts_overflow_and_hands_frame_back() {
        let mut b = TxBatch::new();
        for i in 0..MAX_FRAMES_PER_TICK as u16 {
            b.push(CanFrame::standard(i, &[]).unwrap()).unwrap();
        }
        let extra = CanFrame::standard(0x100, &[1]).unwrap();
        assert_eq!(b.push(extra), Err(extra));
        assert!(!b.write_slot(CommandSlot::new(0x200, 0).unwrap(), 1));
        assert_eq!(b.overflowed(), 2);
        b.clear();
        assert_eq!((b.frames().len(), b.overflowed()), (0, 0));
    }
}
