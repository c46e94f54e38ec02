//! The scheduler-facing side of a device on a CAN bus ([`CanNode`]), what it declares about
//! its bus use ([`BusUsage`]), and the per-tick batch it packs commands into ([`TxBatch`]).
//!
//! This replaces RC10_LIB's `Motor_Base` virtuals `update()`, `packCommand()`,
//! `matchesFrame()` and `updateFeedback()`. All methods take `&self`: a node is shared, as a
//! `&'static dyn CanNode`, by the scheduler task, the receiver task and application tasks, and
//! keeps its mutable state behind its own short critical section (see [`crate::motor`]).

use crate::can::{CanFrame, IdFilter};
use crate::time::Instant;
use core::fmt;

/// Most frames one tick can pack on one bus. At 1 Mbit/s one millisecond carries at most
/// nine 8-byte frames, so 16 leaves room for slower ticks without being a real limit.
pub const MAX_FRAMES_PER_TICK: usize = 16;

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
}

/// What a node does on the bus, declared once at registration so the bus can check ID
/// conflicts and the frame budget before anything runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BusUsage {
    /// The IDs this node's feedback arrives on (`None`: it receives nothing).
    pub listen: Option<IdFilter>,
    /// Feedback frames per second the node's device sends (1000 for a DJI ESC).
    pub feedback_hz: u32,
    /// Whether the feedback frames use extended IDs (for the frame budget).
    pub feedback_extended: bool,
    /// A slot in a shared command frame this node writes every tick.
    pub command_slot: Option<CommandSlot>,
    /// Whole frames this node pushes per tick besides its slot (VESC, DM: 1).
    pub command_frames_per_tick: u8,
    /// Whether those whole frames use extended IDs (for the frame budget).
    pub command_extended: bool,
}

impl BusUsage {
    /// A node that neither listens nor sends.
    pub const NONE: Self = Self {
        listen: None,
        feedback_hz: 0,
        feedback_extended: false,
        command_slot: None,
        command_frames_per_tick: 0,
        command_extended: false,
    };
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
}

impl fmt::Display for FrameError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::WrongLength { dlc } => write!(f, "feedback frame has wrong length {dlc}"),
            Self::OutOfRange => f.write_str("feedback field out of range"),
            Self::Unsupported => f.write_str("feedback frame kind not supported"),
        }
    }
}

impl core::error::Error for FrameError {}

/// The frames one tick sends on one bus, in the order they were packed.
///
/// Slot writes with the same command ID merge into one 8-byte frame whose unwritten slots are
/// zero (an unregistered or offline motor's slot is therefore sent as zero current). Beyond
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
#[derive(Debug, Clone, Default)]
pub struct TxBatch {
    frames: heapless::Vec<CanFrame, MAX_FRAMES_PER_TICK>,
    overflowed: u32,
}

impl TxBatch {
    /// An empty batch.
    pub const fn new() -> Self {
        Self {
            frames: heapless::Vec::new(),
            overflowed: 0,
        }
    }

    /// Writes `value` big-endian into `slot`, creating the zero-filled command frame if this is
    /// the first slot written for its ID this tick. Returns `false` (and counts an overflow) if
    /// the batch has no room for a new frame.
    pub fn write_slot(&mut self, slot: CommandSlot, value: i16) -> bool {
        let at = 2 * usize::from(slot.index);
        let existing = self
            .frames
            .iter_mut()
            .find(|f| !f.is_extended() && f.raw_id() == u32::from(slot.id) && f.dlc() == 8);
        let frame = match existing {
            Some(f) => f,
            None => {
                let Some(fresh) = CanFrame::standard(slot.id, &[0; 8]) else {
                    return false; // unreachable: CommandSlot::new checked the ID
                };
                if self.frames.push(fresh).is_err() {
                    self.overflowed += 1;
                    return false;
                }
                match self.frames.last_mut() {
                    Some(f) => f,
                    None => return false,
                }
            }
        };
        if let Some(bytes) = frame.buffer_mut().get_mut(at..at + 2) {
            bytes.copy_from_slice(&value.to_be_bytes());
        }
        true
    }

    /// Appends a whole frame; hands it back (and counts an overflow) if the batch is full.
    pub fn push(&mut self, frame: CanFrame) -> Result<(), CanFrame> {
        self.frames
            .push(frame)
            .inspect_err(|_| self.overflowed += 1)
    }

    /// The frames packed so far.
    pub fn frames(&self) -> &[CanFrame] {
        &self.frames
    }

    /// Frames that did not fit since the last [`clear`](Self::clear).
    pub const fn overflowed(&self) -> u32 {
        self.overflowed
    }

    /// Empties the batch for the next tick.
    pub fn clear(&mut self) {
        self.frames.clear();
        self.overflowed = 0;
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
    fn matches_frame(&self, frame: &CanFrame) -> bool {
        self.bus_usage()
            .listen
            .is_some_and(|f| f.matches(frame.id()))
    }

    /// Parses a frame this node claimed, received at `now`. Latest value wins: nothing queues.
    fn update_feedback(&self, frame: &CanFrame, now: Instant) -> Result<(), FrameError>;

    /// One control step at `now`, `dt_s` seconds after the previous one. Control math only.
    fn update(&self, now: Instant, dt_s: f32);

    /// Writes this tick's command into `out`. Frame assembly only: no control math.
    fn pack_command(&self, out: &mut TxBatch);
}

#[cfg(test)]
mod tests {
    use super::*;

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
