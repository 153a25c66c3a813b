//! Server model: written values are converted to the canonical type as
//! `VariantChangeTypeEx` with the group's LCID would (`ctopc_core::convert::convert_for_write`),
//! in every write path (Write, WriteVQT, async Write/WriteVQT, the extended-write array),
//! and only then checked by the namespace (`Namespace::check_write_value`; asix: integers
//! and reals, AsixConnect §5). Numeric text ("2.5", Polish "12,5"), BOOL (TRUE = 1) and CY
//! reach the source as numbers; DATE and text that is not a number are OPC_E_BADTYPE; a
//! value out of the target's range is OPC_E_RANGE.

mod model_util;

use ctopc_core::model::*;
use ctopc_core::namespace::{ItemDef, Namespace};
use ctopc_core::value::ArrayValue;
use ctopc_core::{OpcError, OpcResult, Quality, Timestamp, Value, VarType};
use model_util::*;
use std::sync::Arc;

/// The fake namespace with asix's write-value rule.
struct NumericOnly;

impl Namespace for NumericOnly {
    fn resolve(&self, item_id: &str, access_path: &str) -> OpcResult<ItemDef> {
        FakeNs.resolve(item_id, access_path)
    }
    fn check_write_value(&self, value: &Value) -> OpcResult<()> {
        asix_model::check_write_value(value)
    }
}

fn sim_with_lcid(lcid: u32) -> (Sim, GroupHandle, Vec<u32>) {
    let mut sim = Sim::new();
    sim.e.set_namespace(Arc::new(NumericOnly));
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    if lcid != 0 {
        sim.e
            .set_group_state(
                sim.now,
                g,
                &SetGroupState {
                    lcid: Some(lcid),
                    ..Default::default()
                },
            )
            .unwrap();
    }
    let h = sim.items(g, &["A1", "RO", "D1"]);
    (sim, g, h)
}

fn sim() -> (Sim, GroupHandle, Vec<u32>) {
    sim_with_lcid(0)
}

/// The values of the write request the engine sent to the data source, and its ID.
fn written(sim: &mut Sim) -> (SourceReqId, Vec<Value>) {
    sim.pump();
    match sim.io.pop() {
        Some(SourceRequest::Write { req_id, items }) => {
            (req_id, items.into_iter().map(|(_, v)| v).collect())
        }
        Some(SourceRequest::WriteVqt { req_id, items }) => {
            (req_id, items.into_iter().map(|(_, v)| v.value).collect())
        }
        other => panic!("no write request: {other:?}"),
    }
}

fn ext_q(value: Value, quality: i32) -> Value {
    let stamp = Timestamp::from_unix_millis(1_600_000_000_000);
    Value::Array(ArrayValue::new(
        VarType::VARIANT,
        vec![value, Value::I4(quality), Value::Date(stamp.to_ole_date())],
    ))
}

fn ext(value: Value) -> Value {
    ext_q(value, 0xC0)
}

/// A sync write of `items`, answered OK by the source; (values sent, results).
fn sync_write(
    sim: &mut Sim,
    g: GroupHandle,
    items: &[(u32, Value)],
) -> (Vec<Value>, Vec<Result<(), OpcError>>) {
    let out = sim.e.write(sim.now, g, items).unwrap();
    let id = match out {
        SyncOutcome::Ready(r) => return (vec![], r),
        SyncOutcome::Pending(id) => id,
    };
    let (req, values) = written(sim);
    let n = values.len();
    sim.e
        .handle_source_write_result(sim.now, req, vec![Ok(()); n]);
    let Some(SyncResult::Write(r)) = sim.e.take_sync_result(id) else {
        panic!("no result")
    };
    (values, r)
}

#[test]
fn sync_write_converts_text_bool_and_cy_and_refuses_dates() {
    let (mut sim, g, h) = sim();
    let items = [
        (h[0], Value::I2(3)),
        (h[0], Value::Bstr("2.5".into())),
        (h[0], Value::Bool(true)),
        (h[0], Value::Date(1.0)),
        (h[0], Value::Cy(10_000)),
        (h[1], Value::Bstr("x".into())),
        (h[0], ext(Value::R4(7.5))),
        (h[0], ext(Value::Bstr(" 7.5 ".into()))),
        (h[2], Value::R8(1e300)),
        (h[0], Value::Bstr("abc".into())),
        (h[2], Value::Bool(false)),
        (h[2], Value::Bstr("1e39".into())),
    ];
    let (values, r) = sync_write(&mut sim, g, &items);
    assert_eq!(
        values,
        vec![
            Value::R8(3.0),
            Value::R8(2.5),
            Value::R8(1.0),
            Value::R8(1.0),
            Value::R8(7.5),
            Value::R8(7.5),
            Value::R4(0.0),
        ],
        "converted values reach the source in the canonical type"
    );
    assert_eq!(
        r,
        vec![
            Ok(()),
            Ok(()),
            Ok(()),
            Err(OpcError::BadType),
            Ok(()),
            Err(OpcError::BadRights),
            Ok(()),
            Ok(()),
            Err(OpcError::Range),
            Err(OpcError::BadType),
            Ok(()),
            Err(OpcError::Range),
        ]
    );
}

#[test]
fn text_converts_in_the_groups_locale() {
    let (mut sim, g, h) = sim_with_lcid(0x0415);
    let (values, r) = sync_write(
        &mut sim,
        g,
        &[
            (h[0], Value::Bstr("12,5".into())),
            (h[2], Value::Bstr(" -0,5 ".into())),
            (h[0], Value::Bstr("12.5".into())),
        ],
    );
    assert_eq!(values, vec![Value::R8(12.5), Value::R4(-0.5)]);
    assert_eq!(r, vec![Ok(()), Ok(()), Err(OpcError::BadType)]);

    let (mut sim, g, h) = sim_with_lcid(0x0409);
    let (values, r) = sync_write(&mut sim, g, &[(h[0], Value::Bstr("12.5".into()))]);
    assert_eq!(values, vec![Value::R8(12.5)]);
    assert_eq!(r, vec![Ok(())]);
}

#[test]
fn extended_write_refuses_qualities_outside_16_bits_and_an_empty_value() {
    let (mut sim, g, h) = sim();
    let (values, r) = sync_write(
        &mut sim,
        g,
        &[
            (h[0], ext_q(Value::R8(1.0), 0x100C0)),
            (h[0], ext_q(Value::R8(1.0), -1)),
            (h[0], ext(Value::Empty)),
            (h[0], ext_q(Value::R8(2.0), 0xFFFF)),
        ],
    );
    assert_eq!(values, vec![Value::R8(2.0)], "not truncated to 0xC0");
    assert_eq!(
        r,
        vec![
            Err(OpcError::Range),
            Err(OpcError::Range),
            Err(OpcError::NotSupported),
            Ok(()),
        ]
    );
}

/// WriteVQT with a VT_EMPTY value: quality only or timestamp only. OPC DA 3.0 (IOPCSyncIO2 /
/// IOPCItemIO::WriteVQT, per-item errors): "OPC_E_NOTSUPPORTED: If a client attempts to
/// write any value, quality, timestamp combination and the server does not support the
/// requested combination (which could be a single quantity such as just timestamp), then
/// the server will not perform any write and will return this error code." (The
/// specification's text is not in the project's searchable corpus; Advosol's OPCDA.NET
/// manual, WriteVQT, paraphrases it: "If a client attempts to write VQ, VT, or VQT it
/// should expect that the server will write them all or none at all.") The asix
/// network writes a value always (with a quality and a timestamp if given), so a write
/// without a value is such a combination. VT_EMPTY with neither is no write at all:
/// OPC_E_BADTYPE, as for IOPCSyncIO::Write.
#[test]
fn write_vqt_with_an_empty_value_is_not_supported() {
    let (mut sim, g, h) = sim();
    let vqt = |q: Option<Quality>, t: Option<Timestamp>| ItemVqt {
        value: Value::Empty,
        quality: q,
        timestamp: t,
    };
    let out = sim
        .e
        .write_vqt(
            sim.now,
            g,
            &[
                (h[0], vqt(Some(Quality::GOOD), None)),
                (h[0], vqt(None, Some(ts(5)))),
                (h[0], vqt(Some(Quality::GOOD), Some(ts(5)))),
                (h[0], vqt(None, None)),
                (h[1], vqt(Some(Quality::GOOD), None)),
            ],
        )
        .unwrap();
    let SyncOutcome::Ready(r) = out else {
        panic!("nothing should reach the source")
    };
    assert_eq!(
        r,
        vec![
            Err(OpcError::NotSupported),
            Err(OpcError::NotSupported),
            Err(OpcError::NotSupported),
            Err(OpcError::BadType),
            Err(OpcError::BadRights),
        ]
    );
}

#[test]
fn write_vqt_and_async_writes_apply_the_same_conversion() {
    let (mut sim, g, h) = sim();
    let vqt = |v: Value| ItemVqt {
        value: v,
        quality: Some(Quality::GOOD),
        timestamp: None,
    };
    let SyncOutcome::Pending(_) = sim
        .e
        .write_vqt(
            sim.now,
            g,
            &[
                (h[0], vqt(Value::UI4(1))),
                (h[0], vqt(Value::Bstr("1".into()))),
                (h[0], vqt(Value::Date(1.0))),
            ],
        )
        .unwrap()
    else {
        panic!("not sent")
    };
    assert_eq!(written(&mut sim).1, vec![Value::R8(1.0), Value::R8(1.0)]);

    sim.e.set_callback_connected(sim.now, g, true).unwrap();
    let started = sim
        .e
        .async_write(
            sim.now,
            g,
            5,
            &[
                (h[0], Value::Bstr("4".into())),
                (h[0], Value::I8(4)),
                (h[0], Value::Bstr("four".into())),
            ],
        )
        .unwrap();
    assert_eq!(
        started.results,
        vec![Ok(()), Ok(()), Err(OpcError::BadType)]
    );
    assert_eq!(written(&mut sim).1, vec![Value::R8(4.0), Value::R8(4.0)]);
    let started = sim
        .e
        .async_write_vqt(
            sim.now,
            g,
            6,
            &[
                (h[0], vqt(Value::Bool(true))),
                (h[2], vqt(Value::Date(2.0))),
                (h[2], vqt(Value::Empty)),
            ],
        )
        .unwrap();
    assert_eq!(
        started.results,
        vec![Ok(()), Err(OpcError::BadType), Err(OpcError::NotSupported)]
    );
    assert_eq!(written(&mut sim).1, vec![Value::R8(1.0)]);
}

/// IOPCItemIO::WriteVQT has no group: its text converts in the session's LCID, the one the
/// client set with IOPCCommon::SetLocaleID. A Polish session's "12,5" is 12.5; in an
/// English one the comma groups digits,
/// so "12,5" is 125 (VarR8FromStr with en-US) and "12.5" is 12.5.
#[test]
fn item_io_writes_convert_in_the_sessions_locale() {
    let vqt = |v: &str| ItemVqt {
        value: Value::Bstr(v.into()),
        quality: None,
        timestamp: None,
    };
    /// (LCID set, texts written to A1, D1, A1; values sent; per-item results)
    type Case<'a> = (
        Option<u32>,
        &'a [&'a str],
        Vec<Value>,
        Vec<Result<(), OpcError>>,
    );
    let cases: [Case; 4] = [
        (
            Some(0x0415),
            &["12,5", " -0,5 ", "12.5"],
            vec![Value::R8(12.5), Value::R4(-0.5)],
            vec![Ok(()), Ok(()), Err(OpcError::BadType)],
        ),
        (
            Some(0x0409),
            &["12,5", "12.5"],
            vec![Value::R8(125.0), Value::R4(12.5)],
            vec![Ok(()), Ok(())],
        ),
        // The sort ID (bits 16-19) is ignored.
        (
            Some(0x0001_0415),
            &["12,5"],
            vec![Value::R8(12.5)],
            vec![Ok(())],
        ),
        // Never set: the server's default conversion locale (en-US here).
        (None, &["12.5"], vec![Value::R8(12.5)], vec![Ok(())]),
    ];
    for (lcid, texts, want_values, want) in cases {
        let mut sim = Sim::new();
        sim.e.set_namespace(Arc::new(NumericOnly));
        let s = sim.session();
        if let Some(lcid) = lcid {
            sim.e.set_session_lcid(s, lcid).unwrap();
            assert_eq!(sim.e.session_lcid(s), Ok(lcid));
        }
        let ids = ["A1", "D1", "A1"];
        let items: Vec<(&str, ItemVqt)> = texts
            .iter()
            .enumerate()
            .map(|(i, t)| (ids[i], vqt(t)))
            .collect();
        let SyncOutcome::Pending(id) = sim.e.item_io_write_vqt(sim.now, s, &items).unwrap() else {
            panic!("{lcid:?}: nothing sent")
        };
        let (req, values) = written(&mut sim);
        assert_eq!(values, want_values, "{lcid:?}");
        let n = values.len();
        sim.e
            .handle_source_write_result(sim.now, req, vec![Ok(()); n]);
        let Some(SyncResult::Write(r)) = sim.e.take_sync_result(id) else {
            panic!("no result")
        };
        assert_eq!(r, want, "{lcid:?}");
    }
}

#[test]
fn session_lcid_is_validated_and_per_session() {
    let mut sim = Sim::new();
    let a = sim.session();
    let b = sim.session();
    assert_eq!(
        sim.e.session_lcid(a),
        Ok(0x0800),
        "LOCALE_SYSTEM_DEFAULT until set"
    );
    sim.e.set_session_lcid(a, 0x0415).unwrap();
    assert_eq!(
        sim.e.set_session_lcid(a, 0xDEAD_BEEF),
        Err(OpcError::InvalidArg)
    );
    assert_eq!(
        sim.e.set_session_lcid(a, 0x0407),
        Err(OpcError::InvalidArg),
        "German"
    );
    assert_eq!(
        sim.e.session_lcid(a),
        Ok(0x0415),
        "unchanged by a refused LCID"
    );
    assert_eq!(sim.e.session_lcid(b), Ok(0x0800), "per session");
    for ok in [0x0000, 0x0400, 0x0800, 0x007F, 0x0809] {
        assert_eq!(sim.e.set_session_lcid(b, ok), Ok(()), "{ok:#x}");
    }
    sim.e.close_session(sim.now, a).unwrap();
    assert_eq!(sim.e.set_session_lcid(a, 0x0409), Err(OpcError::InvalidArg));
    assert_eq!(sim.e.session_lcid(a), Err(OpcError::InvalidArg));
}
