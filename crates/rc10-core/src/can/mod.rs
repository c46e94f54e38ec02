//! The CAN layer: frames, ID filters, bit timing, transport traits and bus statistics.
//! No hardware here: the STM32 adapter and the simulator implement the transport traits.

pub mod acceptance;
mod frame;
pub mod loopback;
pub mod stats;
pub mod timing;
mod transport;

pub use frame::{CanFrame, ExtendedId, Id, IdFilter, RawId, StandardId};
pub use stats::{BusCounters, BusRates, BusStats};
pub use transport::{
    BusStatus, CanReceive, CanTransmit, ErrorState, ReceiveError, Received, SendError,
};
