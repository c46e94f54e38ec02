//! The classic CAN frame (standard or extended ID, DLC 0–8) and ID filters.

pub use embedded_can::{ExtendedId, Id, StandardId};

use core::fmt;

/// A classic CAN 2.0 frame: standard (11-bit) or extended (29-bit) ID, 0–8 data bytes or a
/// remote request.
///
/// Implements [`embedded_can::Frame`], so it converts to and from any HAL's frame type through
/// that trait. Bytes beyond the DLC are always zero, so two frames with the same ID, DLC and
/// payload compare equal.
///
/// ```
/// use rc10_core::can::CanFrame;
/// let f = CanFrame::standard(0x200, &[0x01, 0x02]).unwrap();
/// assert_eq!(f.raw_id(), 0x200);
/// assert_eq!(f.data(), &[0x01, 0x02]);
/// assert!(CanFrame::standard(0x800, &[]).is_none()); // 11-bit IDs stop at 0x7FF
/// assert!(CanFrame::standard(0x200, &[0; 9]).is_none()); // classic CAN carries at most 8 bytes
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct CanFrame {
    id: Id,
    dlc: u8,
    remote: bool,
    data: [u8; 8],
}

impl CanFrame {
    /// A data frame, or `None` if `data` is longer than 8 bytes.
    #[inline]
    pub fn new(id: impl Into<Id>, data: &[u8]) -> Option<Self> {
        let mut buf = [0u8; 8];
        buf.get_mut(..data.len())?.copy_from_slice(data);
        Some(Self {
            id: id.into(),
            dlc: data.len() as u8,
            remote: false,
            data: buf,
        })
    }

    /// A standard-ID data frame; `None` if `raw_id > 0x7FF` or `data` is longer than 8 bytes.
    #[inline]
    pub fn standard(raw_id: u16, data: &[u8]) -> Option<Self> {
        Self::new(StandardId::new(raw_id)?, data)
    }

    /// An extended-ID data frame; `None` if `raw_id > 0x1FFF_FFFF` or `data` is too long.
    #[inline]
    pub fn extended(raw_id: u32, data: &[u8]) -> Option<Self> {
        Self::new(ExtendedId::new(raw_id)?, data)
    }

    /// A remote (RTR) frame requesting `dlc` bytes; `None` if `dlc > 8`.
    pub fn remote(id: impl Into<Id>, dlc: usize) -> Option<Self> {
        if dlc > 8 {
            return None;
        }
        Some(Self {
            id: id.into(),
            dlc: dlc as u8,
            remote: true,
            data: [0; 8],
        })
    }

    /// The ID.
    pub const fn id(&self) -> Id {
        self.id
    }

    /// The raw ID number (11 or 29 bits; see [`is_extended`](Self::is_extended)).
    pub fn raw_id(&self) -> u32 {
        match self.id {
            Id::Standard(id) => u32::from(id.as_raw()),
            Id::Extended(id) => id.as_raw(),
        }
    }

    /// Whether the ID is extended (29-bit).
    pub const fn is_extended(&self) -> bool {
        matches!(self.id, Id::Extended(_))
    }

    /// Whether this is a remote (RTR) frame.
    pub const fn is_remote(&self) -> bool {
        self.remote
    }

    /// Data length code, 0–8.
    pub const fn dlc(&self) -> usize {
        self.dlc as usize
    }

    /// The payload (empty for a remote frame).
    pub fn data(&self) -> &[u8] {
        if self.remote {
            &[]
        } else {
            self.data.get(..self.dlc()).unwrap_or(&[])
        }
    }

    /// The payload as one integer, its first byte most significant: `data().len()` bytes,
    /// 0 for a remote or empty frame. Bytes of the buffer beyond the DLC do not count.
    #[allow(
        clippy::arithmetic_side_effects,
        reason = "the payload is at most 8 bytes: 64 − 8·len is 0–64"
    )]
    pub(crate) fn data_word(&self) -> u64 {
        let bits = 8 * self.data().len() as u32;
        // A shift by 64 (no payload) is `None`: the word is 0.
        u64::from_be_bytes(self.data)
            .checked_shr(64 - bits)
            .unwrap_or(0)
    }

    /// The payload as exactly eight bytes, if the frame is a data frame with DLC 8.
    /// Most motor protocols require this; a shorter frame is malformed for them.
    pub fn data8(&self) -> Option<&[u8; 8]> {
        if !self.remote && self.dlc == 8 {
            Some(&self.data)
        } else {
            None
        }
    }

    /// Mutable access to the eight-byte buffer for packing; the DLC is unchanged, and bytes at
    /// and beyond it are not sent.
    pub(crate) fn buffer_mut(&mut self) -> &mut [u8; 8] {
        &mut self.data
    }
}

impl embedded_can::Frame for CanFrame {
    fn new(id: impl Into<Id>, data: &[u8]) -> Option<Self> {
        CanFrame::new(id, data)
    }

    fn new_remote(id: impl Into<Id>, dlc: usize) -> Option<Self> {
        CanFrame::remote(id, dlc)
    }

    fn is_extended(&self) -> bool {
        CanFrame::is_extended(self)
    }

    fn is_remote_frame(&self) -> bool {
        self.remote
    }

    fn id(&self) -> Id {
        self.id
    }

    fn dlc(&self) -> usize {
        CanFrame::dlc(self)
    }

    fn data(&self) -> &[u8] {
        CanFrame::data(self)
    }
}

#[cfg(feature = "defmt")]
impl defmt::Format for CanFrame {
    fn format(&self, f: defmt::Formatter) {
        let kind = if self.is_extended() { "x" } else { "" };
        defmt::write!(
            f,
            "{=u32:#x}{=str} [{}] {=[u8]:02x}",
            self.raw_id(),
            kind,
            self.dlc,
            self.data()
        )
    }
}

/// An acceptance filter, like a CAN controller's mask filter: an ID of the given kind matches
/// when `(raw_id & mask) == (id & mask)`.
///
/// Devices declare the filter they listen on; the bus uses it to route frames and to reject,
/// at registration, two devices that would both claim one ID.
///
/// ```
/// use rc10_core::can::{CanFrame, IdFilter};
/// let m3508_1 = IdFilter::standard(0x201);
/// assert!(m3508_1.matches(CanFrame::standard(0x201, &[0; 8]).unwrap().id()));
/// // A VESC with controller id 7 answers on extended IDs (packet << 8) | 7.
/// let vesc_7 = IdFilter::extended_masked(0x07, 0xFF);
/// assert!(vesc_7.matches(CanFrame::extended(0x0907, &[0; 8]).unwrap().id()));
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct IdFilter {
    /// Whether the filter matches extended (29-bit) IDs; standard IDs otherwise.
    pub extended: bool,
    /// The ID bits to compare.
    pub id: u32,
    /// Which bits are compared (1 = must equal).
    pub mask: u32,
}

impl IdFilter {
    /// Exactly one standard ID.
    pub const fn standard(raw_id: u16) -> Self {
        Self {
            extended: false,
            id: raw_id as u32,
            mask: 0x7FF,
        }
    }

    /// Exactly one extended ID.
    pub const fn extended(raw_id: u32) -> Self {
        Self {
            extended: true,
            id: raw_id,
            mask: 0x1FFF_FFFF,
        }
    }

    /// Extended IDs whose bits under `mask` equal `raw_id`'s.
    pub const fn extended_masked(raw_id: u32, mask: u32) -> Self {
        Self {
            extended: true,
            id: raw_id & mask,
            mask,
        }
    }

    /// Whether `id` passes the filter.
    pub fn matches(&self, id: Id) -> bool {
        match id {
            Id::Standard(s) if !self.extended => {
                (u32::from(s.as_raw()) ^ self.id) & self.mask & 0x7FF == 0
            }
            Id::Extended(e) if self.extended => {
                (e.as_raw() ^ self.id) & self.mask & 0x1FFF_FFFF == 0
            }
            _ => false,
        }
    }

    /// Whether some ID passes both filters.
    pub const fn overlaps(&self, other: &Self) -> bool {
        // Only the ID's own bits count (11 or 29), as in `matches`.
        let width = if self.extended { 0x1FFF_FFFF } else { 0x7FF };
        self.extended == other.extended
            && (self.id ^ other.id) & self.mask & other.mask & width == 0
    }
}

/// A CAN ID as a number and its kind, for error reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RawId {
    /// The 11- or 29-bit ID.
    pub id: u32,
    /// Whether it is an extended (29-bit) ID.
    pub extended: bool,
}

impl fmt::Display for RawId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.extended {
            write!(f, "extended 0x{:08X}", self.id)
        } else {
            write!(f, "0x{:03X}", self.id)
        }
    }
}

impl IdFilter {
    /// An ID that passes both filters, if there is one (the bits either filter fixes, the
    /// rest zero).
    pub const fn common_id(&self, other: &Self) -> Option<RawId> {
        if !self.overlaps(other) {
            return None;
        }
        let width = if self.extended { 0x1FFF_FFFF } else { 0x7FF };
        Some(RawId {
            id: ((self.id & self.mask) | (other.id & other.mask)) & width,
            extended: self.extended,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use embedded_can::Frame as _;

    #[test]
    fn data_word_is_the_payload_first_byte_high_without_bytes_beyond_the_dlc() {
        let junk_tail = CanFrame {
            id: StandardId::new(0x201).unwrap().into(),
            dlc: 3,
            remote: false,
            data: [0x12, 0x34, 0x56, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF],
        };
        assert_eq!(junk_tail.data_word(), 0x12_3456);
        let full = CanFrame::standard(0x200, &[1, 2, 3, 4, 5, 6, 7, 8]).unwrap();
        assert_eq!(full.data_word(), 0x0102_0304_0506_0708);
        let empty = CanFrame {
            dlc: 0,
            ..junk_tail
        };
        assert_eq!(empty.data_word(), 0);
        let remote = CanFrame {
            dlc: 8,
            remote: true,
            ..junk_tail
        };
        assert_eq!(remote.data_word(), 0);
    }

    #[test]
    fn frame_pads_beyond_dlc_with_zero_and_compares_by_content() {
        let a = CanFrame::standard(0x123, &[1, 2, 3]).unwrap();
        let b = CanFrame::standard(0x123, &[1, 2, 3]).unwrap();
        assert_eq!(a, b);
        assert_eq!(a.dlc(), 3);
        assert_eq!(a.data8(), None);
    }

    #[test]
    fn embedded_can_trait_round_trips() {
        let id = ExtendedId::new(0x1234_5678 & 0x1FFF_FFFF).unwrap();
        let f = <CanFrame as embedded_can::Frame>::new(id, &[9, 8]).unwrap();
        assert!(f.is_extended());
        assert_eq!(embedded_can::Frame::data(&f), &[9, 8]);
        let r = CanFrame::new_remote(StandardId::new(0x10).unwrap(), 4).unwrap();
        assert!(r.is_remote_frame());
        assert_eq!(r.dlc(), 4);
        assert_eq!(embedded_can::Frame::data(&r), &[] as &[u8]);
        assert!(CanFrame::remote(StandardId::ZERO, 9).is_none());
    }

    #[test]
    fn extended_id_limit_enforced() {
        assert!(CanFrame::extended(0x2000_0000, &[]).is_none());
        assert!(CanFrame::extended(0x1FFF_FFFF, &[]).is_some());
    }

    #[test]
    fn filter_kinds_do_not_cross() {
        let std_filter = IdFilter::standard(0x201);
        assert!(!std_filter.matches(CanFrame::extended(0x201, &[]).unwrap().id()));
        assert!(!IdFilter::extended(0x201).overlaps(&std_filter));
    }

    #[test]
    fn bits_beyond_the_id_width_do_not_hide_an_overlap() {
        let a = IdFilter::standard(0x201);
        let b = IdFilter {
            extended: false,
            id: 0x1201, // a stray bit above the 11-bit ID
            mask: 0xFFFF,
        };
        assert!(b.matches(CanFrame::standard(0x201, &[]).unwrap().id()));
        assert!(a.overlaps(&b) && b.overlaps(&a));
    }

    #[test]
    fn bits_beyond_the_extended_id_width_do_not_hide_a_match() {
        // Bit 29 is no part of a 29-bit ID: the filter matches extended ID 0x07, as its
        // overlap with the exact filter (and the hardware filter built from it) says.
        let stray = IdFilter::extended_masked(0x2000_0007, 0xFFFF_FFFF);
        let id = CanFrame::extended(0x07, &[]).unwrap().id();
        assert!(stray.matches(id));
        assert!(stray.overlaps(&IdFilter::extended(0x07)));
        assert!(!stray.matches(CanFrame::extended(0x08, &[]).unwrap().id()));
    }

    #[test]
    fn masked_filters_overlap_when_some_id_matches_both() {
        let vesc_7 = IdFilter::extended_masked(0x07, 0xFF);
        let exact = IdFilter::extended(0x0907);
        assert!(vesc_7.overlaps(&exact));
        assert!(!vesc_7.overlaps(&IdFilter::extended_masked(0x08, 0xFF)));
        assert!(IdFilter::standard(0x205).overlaps(&IdFilter::standard(0x205)));
        assert!(!IdFilter::standard(0x205).overlaps(&IdFilter::standard(0x206)));
    }
}
