//! Every error type says what went wrong: its message names the problem and carries the
//! values a user needs to find it (the ID, the length, the load), so a `defmt`/log line of
//! it is enough to act on.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]

use rc10_core::bus::RegisterError;
use rc10_core::can::acceptance::PlanError;
use rc10_core::can::{RawId, ReceiveError, SendError};
use rc10_core::chassis::ChassisError;
use rc10_core::encoder::EncoderError;
use rc10_core::motor::TargetError;
use rc10_core::motor::dji::DjiError;
use rc10_core::motor::dm::DmError;
use rc10_core::motor::vesc::VescError;
use rc10_core::node::{CommandSlot, FrameError};
use rc10_core::pid::PidConfigError;
use rc10_core::remote::dbus::DbusError;
use rc10_core::remote::ppm::PpmError;
use rc10_core::remote::sbus::SbusError;
use rc10_core::telemetry::BufferTooSmall;

/// The message of `e`, checked to contain every one of `parts`.
#[track_caller]
fn says(e: impl std::fmt::Display, parts: &[&str]) {
    let msg = e.to_string();
    for part in parts {
        assert!(msg.contains(part), "{msg:?} does not mention {part:?}");
    }
}

#[test]
fn bus_registration_errors_name_the_nodes_and_ids() {
    let std_id = |id| RawId {
        id,
        extended: false,
    };
    says(RegisterError::Full, &["full"]);
    says(RegisterError::TooManyIds, &["ID"]);
    says(
        RegisterError::FeedbackConflict {
            existing: 2,
            id: std_id(0x205),
        },
        &["feedback", "0x205", "2"],
    );
    says(
        RegisterError::SlotConflict {
            existing: 1,
            slot: CommandSlot::new(0x1FF, 3).unwrap(),
        },
        &["slot 3", "0x1FF", "node 1"],
    );
    says(
        RegisterError::SendConflict {
            existing: 4,
            id: std_id(0x301),
        },
        &["node 4", "0x301"],
    );
    says(
        RegisterError::CommandOnFeedbackId {
            sender: 5,
            listener: 6,
            id: std_id(0x201),
        },
        &["node 5", "node 6", "0x201"],
    );
    says(
        RegisterError::TxDepth {
            frames_per_tick: 4,
            tx_depth: 3,
        },
        &["4 command frames", "3 TX"],
    );
    says(
        RegisterError::FrameBudget { load_percent: 99.6 },
        &["100 %"],
    );
}

#[test]
fn can_errors_and_ids_read_as_on_an_analyser() {
    says(
        RawId {
            id: 0x7,
            extended: false,
        },
        &["0x007"],
    );
    says(
        RawId {
            id: 0x1234,
            extended: true,
        },
        &["extended 0x00001234"],
    );
    says(SendError::Full, &["full"]);
    says(SendError::BusOff, &["bus-off"]);
    says(ReceiveError::Overrun, &["overrun"]);
    says(ReceiveError::BusOff, &["bus-off"]);
    says(ReceiveError::BusError, &["error"]);
    says(
        PlanError::TooManyStandard {
            needed: 30,
            available: 28,
        },
        &["30 standard", "28"],
    );
    says(
        PlanError::TooManyExtended {
            needed: 9,
            available: 8,
        },
        &["9 extended", "8"],
    );
    says(FrameError::WrongLength { dlc: 6 }, &["length 6"]);
    says(FrameError::OutOfRange, &["out of range"]);
    says(FrameError::Unsupported, &["not supported"]);
    says(FrameError::OutOfOrder, &["older"]);
}

#[test]
fn device_and_algorithm_errors_name_the_bad_setting() {
    says(DjiError::IdOutOfRange { id: 9, max: 8 }, &["id 9", "1..=8"]);
    says(
        DjiError::Pid(PidConfigError::GainNotFinite),
        &["loop", "gain"],
    );
    says(DjiError::InvalidOrigin, &["8192"]);
    says(DjiError::InvalidThermal, &["thermal"]);
    says(DjiError::InvalidVoltageLimit, &["voltage"]);
    says(DmError::InvalidId, &["ID"]);
    says(DmError::InvalidLimit, &["range"]);
    says(VescError::ZeroPolePairs, &["pole pairs"]);
    says(VescError::InvalidLimit, &["limit"]);
    says(VescError::NoStatus1, &["STATUS_1"]);
    says(VescError::BroadcastId, &["255", "broadcast"]);
    says(TargetError::NotFinite, &["NaN"]);
    says(TargetError::Unsupported, &["mode"]);
    says(TargetError::OutOfRange, &["range"]);
    for (e, word) in [
        (PidConfigError::GainNotFinite, "gain"),
        (PidConfigError::InvalidLimit, "limit"),
        (PidConfigError::InvalidDeadband, "deadband"),
        (PidConfigError::InvalidSeparation, "separation"),
        (PidConfigError::InvalidFilter, "filter"),
        (PidConfigError::InvalidPeriod, "period"),
        (PidConfigError::InvalidTrackingRate, "tracking"),
    ] {
        says(e, &[word]);
    }
    says(EncoderError::OutOfRange { raw: 9000 }, &["9000"]);
    says(ChassisError::InvalidDimension, &["dimension"]);
    says(ChassisError::Singular, &["twist"]);
    says(ChassisError::InvalidSign, &["sign"]);
}

#[test]
fn remote_and_telemetry_errors_carry_the_bad_value() {
    says(DbusError::WrongLength(17), &["17 bytes", "18"]);
    says(DbusError::StickOutOfRange, &["stick"]);
    says(DbusError::InvalidSwitch, &["switch"]);
    says(PpmError::BadInterval(4000), &["4000 µs"]);
    says(PpmError::WrongChannelCount(5), &["5 channels"]);
    says(SbusError::WrongLength(24), &["24 bytes", "25"]);
    says(SbusError::BadHeader(0x10), &["0x10"]);
    says(SbusError::BadFooter(0x24), &["0x24"]);
    says(BufferTooSmall { needed: 37 }, &["37 bytes"]);
}
