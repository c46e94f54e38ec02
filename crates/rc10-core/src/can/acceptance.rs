//! Hardware acceptance-filter planning: which filter elements a CAN controller needs so that
//! it stores exactly the frames the registered nodes listen to, spread over its two RX FIFOs,
//! and rejects the rest in hardware.
//!
//! Pure logic, tested on the host. The STM32 adapter turns a [`FilterPlan`] into FDCAN filter
//! elements (an STM32G4 FDCAN has 28 standard and 8 extended elements, each able to hold two
//! exact IDs, or an ID and a mask, and two 3-deep RX FIFOs).

use super::IdFilter;
use crate::node::BusUsage;
use core::fmt;

/// One of the controller's two RX FIFOs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Fifo {
    /// RX FIFO 0.
    Fifo0,
    /// RX FIFO 1.
    Fifo1,
}

/// One hardware filter element.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FilterElement {
    /// Accept these two exact IDs (the same ID twice for one).
    Dual {
        /// The IDs.
        ids: [u32; 2],
        /// Whether they are extended IDs.
        extended: bool,
        /// Where accepted frames go.
        fifo: Fifo,
    },
    /// Accept IDs whose bits under `mask` equal `id`'s.
    Mask {
        /// The ID bits to compare.
        id: u32,
        /// Which bits are compared.
        mask: u32,
        /// Whether it matches extended IDs.
        extended: bool,
        /// Where accepted frames go.
        fifo: Fifo,
    },
}

impl FilterElement {
    /// The FIFO accepted frames go to.
    pub const fn fifo(&self) -> Fifo {
        match self {
            Self::Dual { fifo, .. } | Self::Mask { fifo, .. } => *fifo,
        }
    }

    /// Whether the element accepts the raw ID `id` of the given kind.
    pub fn accepts(&self, id: u32, is_extended: bool) -> bool {
        match *self {
            Self::Dual { ids, extended, .. } => extended == is_extended && ids.contains(&id),
            Self::Mask {
                id: want,
                mask,
                extended,
                ..
            } => extended == is_extended && (id ^ want) & mask == 0,
        }
    }
}

/// Why no filter plan fits the controller.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PlanError {
    /// The standard-ID filters need `needed` elements; the controller has `available`.
    TooManyStandard {
        /// Elements needed.
        needed: usize,
        /// Elements the controller has.
        available: usize,
    },
    /// The extended-ID filters need `needed` elements; the controller has `available`.
    TooManyExtended {
        /// Elements needed.
        needed: usize,
        /// Elements the controller has.
        available: usize,
    },
}

impl fmt::Display for PlanError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::TooManyStandard { needed, available } => write!(
                f,
                "{needed} standard-ID filter elements needed, {available} available"
            ),
            Self::TooManyExtended { needed, available } => write!(
                f,
                "{needed} extended-ID filter elements needed, {available} available"
            ),
        }
    }
}

impl core::error::Error for PlanError {}

/// The filter elements for one bus: at most `S` standard and `E` extended ones (28 and 8 on
/// an STM32G4).
///
/// Each node's listen IDs go to one FIFO, chosen so that the feedback frames per second of
/// the two FIFOs stay as even as possible (greedy, in registration order): with 3-deep FIFOs,
/// two of them halve the chance that a late receiver loses a frame. Exact IDs of the same
/// FIFO share dual-ID elements; masked filters take one element each.
///
/// ```
/// use rc10_core::can::acceptance::{Fifo, FilterPlan};
/// use rc10_core::motor::dji::DjiMotor;
/// use rc10_core::node::CanNode;
/// let wheels = [DjiMotor::m3508(1).unwrap(), DjiMotor::m3508(2).unwrap(), DjiMotor::m3508(3).unwrap()];
/// let plan = FilterPlan::<28, 8>::new(wheels.iter().map(|w| w.bus_usage())).unwrap();
/// // 0x201 → FIFO 0, 0x202 → FIFO 1, 0x203 → FIFO 0: two elements in FIFO 0, one in FIFO 1.
/// assert_eq!(plan.standard().len(), 2);
/// assert_eq!(plan.fifo_of(0x202, false), Some(Fifo::Fifo1));
/// assert_eq!(plan.fifo_of(0x204, false), None); // rejected in hardware
/// ```
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FilterPlan<const S: usize, const E: usize> {
    standard: heapless::Vec<FilterElement, S>,
    extended: heapless::Vec<FilterElement, E>,
}

impl<const S: usize, const E: usize> FilterPlan<S, E> {
    /// Plans the filters for nodes with these declarations (in registration order).
    pub fn new(usages: impl Iterator<Item = BusUsage>) -> Result<Self, PlanError> {
        let mut load_hz = [0u64; 2];
        let mut plan = Self {
            standard: heapless::Vec::new(),
            extended: heapless::Vec::new(),
        };
        // Counts of elements needed, kept going past capacity for the error report.
        let mut needed = [0usize; 2];
        // A half-filled dual element per (kind, FIFO): its index and first ID.
        let mut open: [[Option<usize>; 2]; 2] = [[None; 2]; 2];
        for usage in usages {
            if usage.listen.is_empty() {
                continue;
            }
            let f = usize::from(load_hz[1] < load_hz[0]);
            let fifo = if f == 0 { Fifo::Fifo0 } else { Fifo::Fifo1 };
            if let Some(load) = load_hz.get_mut(f) {
                // Only compared between the FIFOs: saturating is as good as exact here. Replies
                // to commands count as frames a second at the usual 1 kHz tick.
                *load = load
                    .saturating_add(u64::from(usage.feedback_hz))
                    .saturating_add(1000 * u64::from(usage.replies_per_tick));
            }
            for filter in usage.listen.filters() {
                plan.add(filter, fifo, f, &mut needed, &mut open);
            }
        }
        if needed[0] > S {
            return Err(PlanError::TooManyStandard {
                needed: needed[0],
                available: S,
            });
        }
        if needed[1] > E {
            return Err(PlanError::TooManyExtended {
                needed: needed[1],
                available: E,
            });
        }
        Ok(plan)
    }

    fn add(
        &mut self,
        filter: &IdFilter,
        fifo: Fifo,
        f: usize,
        needed: &mut [usize; 2],
        open: &mut [[Option<usize>; 2]; 2],
    ) {
        let kind = usize::from(filter.extended);
        let full = if filter.extended { 0x1FFF_FFFF } else { 0x7FF };
        let exact = filter.mask & full == full;
        let list: &mut [FilterElement] = if filter.extended {
            &mut self.extended
        } else {
            &mut self.standard
        };
        let slot = open.get_mut(kind).and_then(|o| o.get_mut(f));
        if exact
            && let Some(slot) = slot
            && let Some(at) = slot.take()
        {
            // Complete the half-filled dual element of this kind and FIFO.
            if let Some(FilterElement::Dual { ids, .. }) = list.get_mut(at) {
                ids[1] = filter.id & full;
            }
            return;
        }
        let element = if exact {
            FilterElement::Dual {
                ids: [filter.id & full; 2],
                extended: filter.extended,
                fifo,
            }
        } else {
            FilterElement::Mask {
                id: filter.id & filter.mask & full,
                mask: filter.mask & full,
                extended: filter.extended,
                fifo,
            }
        };
        if let Some(n) = needed.get_mut(kind) {
            *n = n.saturating_add(1);
        }
        // The index the element takes if it fits.
        let pushed = if filter.extended {
            let at = self.extended.len();
            self.extended.push(element).is_ok().then_some(at)
        } else {
            let at = self.standard.len();
            self.standard.push(element).is_ok().then_some(at)
        };
        if exact
            && let Some(at) = pushed
            && let Some(slot) = open.get_mut(kind).and_then(|o| o.get_mut(f))
        {
            *slot = Some(at);
        }
    }

    /// The standard-ID elements, in order.
    pub fn standard(&self) -> &[FilterElement] {
        &self.standard
    }

    /// The extended-ID elements, in order.
    pub fn extended(&self) -> &[FilterElement] {
        &self.extended
    }

    /// Where the controller would store a frame with this ID, or `None` if it rejects it.
    pub fn fifo_of(&self, id: u32, extended: bool) -> Option<Fifo> {
        let list = if extended {
            self.extended()
        } else {
            self.standard()
        };
        list.iter()
            .find(|e| e.accepts(id, extended))
            .map(FilterElement::fifo)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motor::dji::DjiMotor;
    use crate::motor::vesc::{VescConfig, VescMotor, VescStatusSet};
    use crate::node::{CanNode, IdSet};

    type G4Plan = FilterPlan<28, 8>;

    #[test]
    fn every_listened_id_is_accepted_and_nothing_else() {
        let dji: Vec<DjiMotor> = (1..=8).map(|i| DjiMotor::m3508(i).unwrap()).collect();
        let plan = G4Plan::new(dji.iter().map(|m| m.bus_usage())).unwrap();
        for id in 0u32..=0x7FF {
            let listened = (0x201..=0x208).contains(&id);
            assert_eq!(plan.fifo_of(id, false).is_some(), listened, "0x{id:03X}");
        }
        // Eight exact IDs in two FIFOs: four dual elements.
        assert_eq!(plan.standard().len(), 4);
        assert!(plan.extended().is_empty());
    }

    #[test]
    fn feedback_is_spread_evenly_over_both_fifos() {
        let dji: Vec<DjiMotor> = (1..=4).map(|i| DjiMotor::m3508(i).unwrap()).collect();
        let plan = G4Plan::new(dji.iter().map(|m| m.bus_usage())).unwrap();
        let in0 = (0x201..=0x204)
            .filter(|id| plan.fifo_of(*id, false) == Some(Fifo::Fifo0))
            .count();
        assert_eq!(in0, 2);
    }

    #[test]
    fn vesc_status_ids_are_extended_elements() {
        let mut cfg = VescConfig::new(7);
        cfg.status_packets = VescStatusSet::STATUS_1.with(VescStatusSet::STATUS_4);
        let v = VescMotor::new(0x21, cfg).unwrap();
        let plan = G4Plan::new(core::iter::once(v.bus_usage())).unwrap();
        assert_eq!(plan.extended().len(), 1); // two exact IDs, one dual element
        assert!(plan.fifo_of(0x0921, true).is_some());
        assert!(plan.fifo_of(0x1021, true).is_some());
        assert!(plan.fifo_of(0x0921, false).is_none()); // a standard 0x921 is not it
        assert!(plan.fifo_of(0x0E21, true).is_none());
    }

    #[test]
    fn masked_listeners_take_a_mask_element() {
        let u = BusUsage {
            listen: IdSet::one(IdFilter::extended_masked(0x07, 0xFF)),
            ..BusUsage::NONE
        };
        let plan = G4Plan::new(core::iter::once(u)).unwrap();
        assert_eq!(
            plan.extended(),
            &[FilterElement::Mask {
                id: 0x07,
                mask: 0xFF,
                extended: true,
                fifo: Fifo::Fifo0
            }]
        );
        assert!(plan.fifo_of(0x1_2307, true).is_some());
    }

    #[test]
    fn too_many_filters_is_an_error_with_counts() {
        let usages = (0..9u32).map(|i| BusUsage {
            listen: IdSet::one(IdFilter::extended_masked(i, 0xFF)),
            ..BusUsage::NONE
        });
        assert_eq!(
            G4Plan::new(usages),
            Err(PlanError::TooManyExtended {
                needed: 9,
                available: 8
            })
        );
        let usages = (0..57u16).map(|i| BusUsage::NONE.listening(IdFilter::standard(i), 1));
        assert_eq!(
            FilterPlan::<28, 8>::new(usages),
            Err(PlanError::TooManyStandard {
                needed: 29,
                available: 28
            })
        );
    }
}
