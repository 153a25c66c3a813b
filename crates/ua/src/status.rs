//! OPC DA quality and errors as OPC UA status codes, as OPC UA Part 8 Annex A maps them.
//!
//! Quality: GOOD → Good, LOCAL_OVERRIDE → Good_LocalOverride; UNCERTAIN sub-statuses to
//! their Uncertain_ codes (SUB_NORMAL → Uncertain_SubNormal, EGU_EXCEEDED →
//! Uncertain_EngineeringUnitsExceeded, LAST_USABLE → Uncertain_LastUsableValue,
//! SENSOR_CAL → Uncertain_SensorNotAccurate); BAD sub-statuses to their Bad_ codes
//! (COMM_FAILURE → Bad_NoCommunication, NOT_CONNECTED → Bad_NotConnected,
//! OUT_OF_SERVICE and LAST_KNOWN → Bad_OutOfService, WAITING_FOR_INITIAL_DATA →
//! Bad_WaitingForInitialData, CONFIG_ERROR → Bad_ConfigurationError, DEVICE_FAILURE →
//! Bad_DeviceFailure, SENSOR_FAILURE → Bad_SensorFailure). The limit bits (low, high,
//! constant) become the status code's limit bits. The vendor byte (asix: the Second Limit
//! bit) has no place in a status code and is dropped.

use ctopc_core::{OpcError, Quality};
use opcua::types::{StatusCode, StatusCodeLimit};

/// The status code of a DA quality word.
pub fn quality_to_status(q: Quality) -> StatusCode {
    let code = match q.status() {
        0xC0 => StatusCode::Good,
        0xD8 => StatusCode::GoodLocalOverride,
        0x40 => StatusCode::Uncertain,
        0x44 => StatusCode::UncertainLastUsableValue,
        0x50 => StatusCode::UncertainSensorNotAccurate,
        0x54 => StatusCode::UncertainEngineeringUnitsExceeded,
        0x58 => StatusCode::UncertainSubNormal,
        0x04 => StatusCode::BadConfigurationError,
        0x08 => StatusCode::BadNotConnected,
        0x0C => StatusCode::BadDeviceFailure,
        0x10 => StatusCode::BadSensorFailure,
        0x14 | 0x1C => StatusCode::BadOutOfService,
        0x18 => StatusCode::BadNoCommunication,
        0x20 => StatusCode::BadWaitingForInitialData,
        _ if q.is_good() => StatusCode::Good,
        _ if q.is_uncertain() => StatusCode::Uncertain,
        _ => StatusCode::Bad,
    };
    let limit = match q.limit() {
        Quality::LIMIT_LOW => StatusCodeLimit::Low,
        Quality::LIMIT_HIGH => StatusCodeLimit::High,
        Quality::LIMIT_CONST => StatusCodeLimit::Constant,
        _ => StatusCodeLimit::None,
    };
    code.set_limit(limit)
}

/// The status code of a per-item error of a read (`write`: false) or a write.
/// OPC_E_BADRIGHTS is Bad_NotWritable for writes, Bad_NotReadable for reads.
pub fn error_to_status(e: OpcError, write: bool) -> StatusCode {
    match e {
        OpcError::BadRights if write => StatusCode::BadNotWritable,
        OpcError::BadRights => StatusCode::BadNotReadable,
        OpcError::UnknownItemId | OpcError::InvalidItemId => StatusCode::BadNodeIdUnknown,
        OpcError::BadType => StatusCode::BadTypeMismatch,
        OpcError::Range => StatusCode::BadOutOfRange,
        OpcError::Clamp => StatusCode::GoodClamped,
        OpcError::NetAnswerTimeout => StatusCode::BadTimeout,
        OpcError::OutOfMemory => StatusCode::BadOutOfMemory,
        OpcError::InvalidArg => StatusCode::BadInvalidArgument,
        OpcError::NotSupported if write => StatusCode::BadWriteNotSupported,
        _ if e.is_success() => StatusCode::Good,
        _ if write => StatusCode::BadCommunicationError,
        _ => StatusCode::BadNoCommunication,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn annex_a_quality_table() {
        let cases = [
            (Quality::GOOD, StatusCode::Good),
            (Quality::GOOD_LOCAL_OVERRIDE, StatusCode::GoodLocalOverride),
            (
                Quality::UNCERTAIN_SUB_NORMAL,
                StatusCode::UncertainSubNormal,
            ),
            (
                Quality::UNCERTAIN_EU_EXCEEDED,
                StatusCode::UncertainEngineeringUnitsExceeded,
            ),
            (
                Quality::UNCERTAIN_LAST_USABLE,
                StatusCode::UncertainLastUsableValue,
            ),
            (Quality::BAD_COMM_FAILURE, StatusCode::BadNoCommunication),
            (Quality::BAD_NOT_CONNECTED, StatusCode::BadNotConnected),
            (Quality::BAD_OUT_OF_SERVICE, StatusCode::BadOutOfService),
            (Quality::BAD_LAST_KNOWN_VALUE, StatusCode::BadOutOfService),
            (
                Quality::BAD_WAITING_FOR_INITIAL_DATA,
                StatusCode::BadWaitingForInitialData,
            ),
            (Quality::BAD, StatusCode::Bad),
            (Quality::UNCERTAIN, StatusCode::Uncertain),
        ];
        for (q, s) in cases {
            assert_eq!(quality_to_status(q), s, "quality {:#x}", q.0);
        }
    }

    #[test]
    fn limit_bits_are_kept_and_the_vendor_byte_dropped() {
        let q = Quality::GOOD.with_limit(Quality::LIMIT_HIGH);
        let s = quality_to_status(q);
        assert!(s.is_good());
        assert_eq!(s.limit(), StatusCodeLimit::High);
        let q = Quality::UNCERTAIN_EU_EXCEEDED.with_limit(Quality::LIMIT_LOW);
        assert_eq!(
            quality_to_status(q),
            StatusCode::UncertainEngineeringUnitsExceeded.set_limit(StatusCodeLimit::Low)
        );
        let q = Quality::GOOD
            .with_limit(Quality::LIMIT_CONST)
            .with_vendor(Quality::VENDOR_SECOND_LIMIT);
        assert_eq!(
            quality_to_status(q),
            StatusCode::Good.set_limit(StatusCodeLimit::Constant)
        );
    }

    #[test]
    fn errors_map_as_annex_a_says() {
        assert_eq!(
            error_to_status(OpcError::BadRights, true),
            StatusCode::BadNotWritable
        );
        assert_eq!(
            error_to_status(OpcError::BadRights, false),
            StatusCode::BadNotReadable
        );
        assert_eq!(
            error_to_status(OpcError::BadType, true),
            StatusCode::BadTypeMismatch
        );
        assert_eq!(
            error_to_status(OpcError::UnknownItemId, false),
            StatusCode::BadNodeIdUnknown
        );
        assert_eq!(
            error_to_status(OpcError::Range, true),
            StatusCode::BadOutOfRange
        );
        assert_eq!(
            error_to_status(OpcError::Clamp, true),
            StatusCode::GoodClamped
        );
    }
}
