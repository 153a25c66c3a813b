//! Server model: the write-rights policy (`ctopc_core::write_rights`) decides every write
//! path (IOPCSyncIO::Write, IOPCSyncIO2::WriteVQT, IOPCAsyncIO2/3 writes, IOPCItemIO::WriteVQT)
//! by the session's caller and the item's channel. A refused item is OPC_E_BADRIGHTS and
//! never reaches the data source; the others of the same call go on.

mod model_util;

use ctopc_core::model::*;
use ctopc_core::write_rights::{Caller, Channels, Principal, Rule, WriteRights};
use ctopc_core::{OpcError, Value};
use model_util::*;
use std::sync::Arc;

fn operator() -> Caller {
    Caller::Windows {
        account: "PLANT\\op".into(),
        groups: vec!["PLANT\\Operators".into()],
    }
}

fn rule(channels: Channels, principal: &str) -> Rule {
    Rule::new(channels, Principal::parse(principal).unwrap())
}

/// Operators may write channel `Camac` only; nobody else anything.
fn camac_for_operators() -> Arc<WriteRights> {
    Arc::new(WriteRights::new(vec![rule(
        Channels::One("Camac".into()),
        "group:Operators",
    )]))
}

/// A group with `A1` on the basic channel and `A2` on `Camac` (server handles in order).
fn setup(rights: Arc<WriteRights>, caller: Caller) -> (Sim, SessionHandle, GroupHandle, Vec<u32>) {
    let mut sim = Sim::new();
    sim.e.set_write_rights(rights);
    let s = sim.session();
    sim.e.set_session_caller(s, caller);
    let g = sim.group(s, "g", 1000, 0.0);
    let defs = [("A1", ""), ("A2", "Camac")].map(|(id, path)| ItemDefinition {
        item_id: id,
        access_path: path,
        active: true,
        client_handle: 1,
        requested_type: ctopc_core::VarType::EMPTY,
    });
    let h = sim
        .e
        .add_items(sim.now, g, &defs)
        .unwrap()
        .into_iter()
        .map(|r| r.unwrap().server_handle)
        .collect();
    sim.pump();
    (sim, s, g, h)
}

/// The item IDs of the last write request sent to the source, answered with success.
fn written_ids(sim: &mut Sim) -> Vec<String> {
    sim.pump();
    match sim.io.pop() {
        Some(SourceRequest::Write { req_id, items }) => {
            let n = items.len();
            sim.e
                .handle_source_write_result(sim.now, req_id, vec![Ok(()); n]);
            items.iter().map(|(i, _)| i.item_id.to_string()).collect()
        }
        other => panic!("no write request: {other:?}"),
    }
}

fn sync_result(sim: &mut Sim, out: SyncOutcome<WriteResults>) -> WriteResults {
    match out {
        SyncOutcome::Ready(r) => r,
        SyncOutcome::Pending(id) => match sim.e.take_sync_result(id) {
            Some(SyncResult::Write(r)) => r,
            other => panic!("{other:?}"),
        },
    }
}

#[test]
fn without_a_policy_everyone_writes_as_before() {
    let (mut sim, _, g, h) = setup(Arc::new(WriteRights::open()), Caller::unknown("Wine"));
    assert!(sim.e.write_rights().is_open());
    let out = sim
        .e
        .write(
            sim.now,
            g,
            &[(h[0], Value::R8(1.0)), (h[1], Value::R8(2.0))],
        )
        .unwrap();
    assert_eq!(written_ids(&mut sim), ["A1", "A2"]);
    assert_eq!(sync_result(&mut sim, out), vec![Ok(()), Ok(())]);
    assert_eq!(sim.e.denied_by_policy(g, &h), [false, false]);
}

#[test]
fn sync_writes_are_refused_per_item_by_channel_and_caller() {
    let (mut sim, s, g, h) = setup(camac_for_operators(), operator());
    let out = sim
        .e
        .write(
            sim.now,
            g,
            &[(h[0], Value::R8(1.0)), (h[1], Value::R8(2.0))],
        )
        .unwrap();
    assert_eq!(
        written_ids(&mut sim),
        ["A2"],
        "the refused item never reaches the source"
    );
    assert_eq!(
        sync_result(&mut sim, out),
        vec![Err(OpcError::BadRights), Ok(())]
    );
    assert_eq!(sim.e.denied_by_policy(g, &h), [true, false]);
    // Invalid handles are not the policy's refusals.
    assert_eq!(sim.e.denied_by_policy(g, &[9999]), [false]);

    // The same session, now told another caller: both refused, and said so by WriteVQT.
    sim.e
        .set_session_caller(s, Caller::unknown("RPC_E_CALL_COMPLETE"));
    let out = sim
        .e
        .write_vqt(
            sim.now,
            g,
            &[
                (h[0], ItemVqt::value(Value::R8(1.0))),
                (h[1], ItemVqt::value(Value::R8(2.0))),
            ],
        )
        .unwrap();
    sim.pump();
    assert!(sim.io.is_empty(), "{:?}", sim.io);
    assert_eq!(
        sync_result(&mut sim, out),
        vec![Err(OpcError::BadRights), Err(OpcError::BadRights)]
    );
    assert_eq!(sim.e.denied_by_policy(g, &h), [true, true]);
    let d = sim.e.write_decision(s, "Camac");
    assert!(!d.allowed);
    assert!(d.to_string().contains("unknown"), "{d}");
}

#[test]
fn async_writes_are_refused_at_call_time() {
    let (mut sim, _, g, h) = setup(camac_for_operators(), operator());
    let started = sim
        .e
        .async_write_vqt(
            sim.now,
            g,
            5,
            &[
                (h[0], ItemVqt::value(Value::R8(1.0))),
                (h[1], ItemVqt::value(Value::R8(2.0))),
            ],
        )
        .unwrap();
    assert_eq!(started.results, vec![Err(OpcError::BadRights), Ok(())]);
    assert_eq!(written_ids(&mut sim), ["A2"]);
}

#[test]
fn item_io_writes_are_decided_on_the_basic_channel() {
    // IOPCItemIO has no access path: its items are on the basic channel, which has only
    // the `*` entries.
    let (mut sim, s, _, _) = setup(camac_for_operators(), operator());
    let out = sim
        .e
        .item_io_write_vqt(sim.now, s, &[("A1", ItemVqt::value(Value::R8(1.0)))])
        .unwrap();
    sim.pump();
    assert!(sim.io.is_empty());
    assert_eq!(sync_result(&mut sim, out), vec![Err(OpcError::BadRights)]);
    assert_eq!(
        sim.e.item_io_denied_by_policy(s, &["A1", "NOPE"]),
        [true, false]
    );

    let everyone = Arc::new(WriteRights::new(vec![rule(Channels::All, "*")]));
    sim.e.set_write_rights(everyone);
    sim.e.set_session_caller(s, Caller::unknown("Wine"));
    let out = sim
        .e
        .item_io_write_vqt(sim.now, s, &[("A1", ItemVqt::value(Value::R8(1.0)))])
        .unwrap();
    assert_eq!(written_ids(&mut sim), ["A1"]);
    assert_eq!(sync_result(&mut sim, out), vec![Ok(())]);
    assert_eq!(sim.e.item_io_denied_by_policy(s, &["A1"]), [false]);
}

#[test]
fn read_only_items_stay_bad_rights_and_are_not_the_policys() {
    // `RO` is read-only in the namespace: OPC_E_BADRIGHTS whoever writes; the audit's
    // denial flag is the policy's alone (the policy would allow this caller).
    let all = Arc::new(WriteRights::new(vec![rule(
        Channels::All,
        "group:Operators",
    )]));
    let (mut sim, _, g, _) = setup(all, operator());
    let h = sim.items(g, &["RO"]);
    let out = sim.e.write(sim.now, g, &[(h[0], Value::R8(1.0))]).unwrap();
    assert_eq!(sync_result(&mut sim, out), vec![Err(OpcError::BadRights)]);
    assert_eq!(sim.e.denied_by_policy(g, &h), [false]);
}

#[test]
fn a_new_session_is_unknown_until_told() {
    let mut sim = Sim::new();
    let s = sim.session();
    assert!(sim.e.session_caller(s).unwrap().is_unknown());
    sim.e.set_session_caller(s, operator());
    assert_eq!(sim.e.session_caller(s), Some(&operator()));
    // Unknown sessions are ignored.
    sim.e.set_session_caller(SessionHandle(999), operator());
    assert_eq!(sim.e.session_caller(SessionHandle(999)), None);
}
