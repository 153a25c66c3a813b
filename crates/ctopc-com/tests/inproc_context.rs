//! The server's context, in process: no process-wide state. Each context (`host::start`,
//! here through `common::new_context`) has its own runtime, group identities and lifetime
//! counts; it lives as long as its class object or any object made from it, and when it
//! drops, its runtime (driver thread, engine, data source) goes with it.
#![cfg(windows)]
// Test code (helpers included): a panic fails the test, it crosses no COM boundary.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use common::*;
use ctopc_com::interfaces::*;
use ctopc_com::lifetime::{ExitReason, StopSignal};
use ctopc_com::server;
use ctopc_core::model::GroupHandle;
use std::sync::Arc;
use std::time::Duration;

const SHORT: Duration = Duration::from_millis(50);

#[test]
fn a_context_lives_while_its_objects_do_and_then_stops_its_runtime() {
    let ctx = new_context();
    let runtime = Arc::downgrade(&ctx.runtime);
    let f = server::class_factory(&ctx);
    drop(ctx);
    // SAFETY: a valid class object; no aggregation.
    let s: IOPCServer = unsafe { f.CreateInstance(None) }.expect("CreateInstance");
    let g = add_group(&s, "context");
    drop(f);
    assert!(runtime.upgrade().is_some(), "the server object keeps it");
    drop(s);
    assert!(runtime.upgrade().is_some(), "the group object keeps it");
    drop(g);
    assert!(
        runtime.upgrade().is_none(),
        "the runtime (and its driver thread) ends with the context's last object"
    );
}

#[test]
fn two_contexts_have_their_own_engines_and_group_identities() {
    let a: IOPCServer = new_server_of(&server::class_factory(&new_context()))
        .cast()
        .unwrap();
    let b: IOPCServer = new_server_of(&server::class_factory(&new_context()))
        .cast()
        .unwrap();
    let ga = add_group(&a, "same name");
    // Another context: the name is free there, and the first server does not see it.
    let gb = add_group(&b, "same name");
    assert_ne!(ga.unknown.as_raw(), gb.unknown.as_raw());
    let name = wide("same name");
    let mut out = OutUnk::null();
    // SAFETY: valid pointers for the call.
    let r = hr(unsafe { a.GetGroupByName(pcwstr(&name), &IUnknown::IID, out.as_out()) });
    assert_eq!(r, S_OK);
    let found = out.take().expect("a group object");
    assert_eq!(
        found.as_raw(),
        ga.unknown.as_raw(),
        "one identity per group, per context"
    );
}

#[test]
fn two_servers_of_one_class_object_share_its_context() {
    let ctx = new_context();
    let f = server::class_factory(&ctx);
    // SAFETY: a valid class object; no aggregation.
    let (a, b): (IOPCServer, IOPCServer) = unsafe {
        (
            f.CreateInstance(None).expect("CreateInstance"),
            f.CreateInstance(None).expect("CreateInstance"),
        )
    };
    let ga = add_group(&a, "one");
    let gb = add_group(&b, "two");
    let sessions = ctx.runtime.with_engine(|e, _| {
        [ga.server_handle, gb.server_handle].map(|h| e.group_session(GroupHandle(h)))
    });
    let [Ok(sa), Ok(sb)] = sessions else {
        panic!("both groups are in the one engine: {sessions:?}");
    };
    assert_ne!(sa, sb, "one session per server object");
}

#[test]
fn a_test_has_one_context_while_its_objects_live() {
    let a = opc_server();
    let ga = add_group(&a, "test's");
    let b = opc_server();
    // The same server: the name is another client's there (allowed), and both sessions
    // are in one engine.
    let gb = add_group(&b, "test's");
    let ctx = start();
    let sessions = ctx.runtime.with_engine(|e, _| {
        [ga.server_handle, gb.server_handle].map(|h| e.group_session(GroupHandle(h)))
    });
    assert!(sessions.iter().all(Result::is_ok), "{sessions:?}");
    drop((a, b, ga, gb));
    let runtime = Arc::downgrade(&ctx.runtime);
    drop(ctx);
    assert!(runtime.upgrade().is_none(), "gone with the test's objects");
    // A new one after that, which serves.
    let again = opc_server();
    add_group(&again, "test's");
}

#[test]
fn lifetime_counts_the_objects_of_its_context_only() {
    let ctx = new_context();
    let other = new_context();
    let f = server::class_factory(&ctx);
    // SAFETY: a valid class object; no aggregation.
    let s: IOPCServer = unsafe { f.CreateInstance(None) }.expect("CreateInstance");
    // The other context was never used: it would exit after its grace period.
    assert_eq!(
        other.lifetime.wait_until_unused(SHORT, SHORT),
        ExitReason::NeverUsed
    );
    // LockServer keeps this one up after its last object has gone.
    // SAFETY: plain values.
    unsafe { f.LockServer(true) }.expect("LockServer");
    drop(s);
    let waiter = {
        let l = Arc::clone(&ctx.lifetime);
        std::thread::spawn(move || l.wait_until_unused(Duration::from_secs(30), SHORT))
    };
    std::thread::sleep(SHORT * 4);
    assert!(!waiter.is_finished(), "locked");
    // SAFETY: plain values.
    unsafe { f.LockServer(false) }.expect("LockServer");
    assert_eq!(waiter.join().unwrap(), ExitReason::LastClientGone);
}

#[test]
fn a_stop_signal_stops_only_the_context_it_is_handed_to() {
    let (a, b) = (new_context(), new_context());
    let stop = StopSignal::new();
    a.lifetime.stop_on(&stop);
    stop.trigger("a test");
    assert_eq!(
        a.lifetime.wait_until_unused(Duration::from_secs(30), SHORT),
        ExitReason::StopRequested
    );
    assert_eq!(a.lifetime.stop_reason(), "a test");
    assert_eq!(
        b.lifetime.wait_until_unused(SHORT, SHORT),
        ExitReason::NeverUsed
    );
}
