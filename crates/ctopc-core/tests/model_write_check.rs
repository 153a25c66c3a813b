//! Server model: the namespace's check of written values (`Namespace::check_write_value`)
//! sees the value as the client sent it, before the conversion to the canonical type, in
//! every write path (Write, WriteVQT, async Write/WriteVQT, the extended-write array).
//! asix accepts only integers and reals (AsixConnect §5), so a numeric string such as
//! "2.5", which would convert to R8 without trouble, is still OPC_E_BADTYPE.

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

fn sim() -> (Sim, GroupHandle, Vec<u32>) {
    let mut sim = Sim::new();
    sim.e.set_namespace(Arc::new(NumericOnly));
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let h = sim.items(g, &["A1", "RO", "D1"]);
    (sim, g, h)
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

fn ext(value: Value) -> Value {
    let stamp = Timestamp::from_unix_millis(1_600_000_000_000);
    Value::Array(ArrayValue::new(
        VarType::VARIANT,
        vec![value, Value::I4(0xC0), Value::Date(stamp.to_ole_date())],
    ))
}

#[test]
fn sync_write_accepts_integers_and_reals_only() {
    let (mut sim, g, h) = sim();
    let items = [
        (h[0], Value::I2(3)),
        (h[0], Value::Bstr("2.5".into())),
        (h[0], Value::Bool(true)),
        (h[0], Value::Date(1.0)),
        (h[0], Value::Cy(10_000)),
        (h[1], Value::Bstr("x".into())),
        (h[0], ext(Value::R4(7.5))),
        (h[0], ext(Value::Bstr("7.5".into()))),
        (h[2], Value::R8(1e300)),
    ];
    let SyncOutcome::Pending(id) = sim.e.write(sim.now, g, &items).unwrap() else {
        panic!("not sent")
    };
    let (req, values) = written(&mut sim);
    assert_eq!(
        values,
        vec![Value::R8(3.0), Value::R8(7.5)],
        "only the numeric values reach the source"
    );
    sim.e
        .handle_source_write_result(sim.now, req, vec![Ok(()), Ok(())]);
    let Some(SyncResult::Write(r)) = sim.e.take_sync_result(id) else {
        panic!("no result")
    };
    assert_eq!(
        r,
        vec![
            Ok(()),
            Err(OpcError::BadType),
            Err(OpcError::BadType),
            Err(OpcError::BadType),
            Err(OpcError::BadType),
            Err(OpcError::BadRights),
            Ok(()),
            Err(OpcError::BadType),
            Err(OpcError::Range),
        ]
    );
}

#[test]
fn write_vqt_and_async_writes_apply_the_same_check() {
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
            ],
        )
        .unwrap()
    else {
        panic!("not sent")
    };
    assert_eq!(written(&mut sim).1, vec![Value::R8(1.0)]);

    sim.e.set_callback_connected(sim.now, g, true).unwrap();
    let started = sim
        .e
        .async_write(
            sim.now,
            g,
            5,
            &[(h[0], Value::Bstr("4".into())), (h[0], Value::I8(4))],
        )
        .unwrap();
    assert_eq!(started.results, vec![Err(OpcError::BadType), Ok(())]);
    assert_eq!(written(&mut sim).1, vec![Value::R8(4.0)]);
    let started = sim
        .e
        .async_write_vqt(sim.now, g, 6, &[(h[0], vqt(Value::Bool(false)))])
        .unwrap();
    assert_eq!(started.results, vec![Err(OpcError::BadType)]);
    assert_eq!(started.cancel_id, 0, "nothing queued");
}
