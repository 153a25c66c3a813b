//! Item buffering through the group object in process (no proxy): a server context with
//! `MinUpdateRate` 100 ms (as the ini would set it), a 1000 ms group, the tank level
//! sampled at 100 ms with buffering on (IOPCItemSamplingMgt), and the OnDataChange the
//! callback worker assembles: the same client handle several times, oldest first, each
//! its own VARIANT, quality, timestamp and S_OK, next to an unbuffered item sampled as
//! fast that appears once per callback. Harness: `common/mod.rs`; group helpers:
//! `inproc_group_support/mod.rs`.
#![cfg(windows)]
// Test code (helpers included): a panic fails the test, it crosses no COM boundary.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;
mod inproc_group_support;

use common::*;
use ctopc_com::interfaces::*;
use inproc_group_support::*;
use std::time::Duration;

/// A second level of the demo plant (R4, read-only).
const OTHER: &str = "KW_A001";

#[test]
fn on_data_change_carries_every_buffered_sample_of_an_item() {
    let ctx = new_context_with(|c| c.min_update_rate_ms = 100);
    let f = ctopc_com::server::class_factory(&ctx);
    let server: IOPCServer = new_server_of(&f).cast().unwrap();
    let g = add_group(&server, "buffering");
    assert_eq!(g.revised_rate, 1000);
    let h = add_ok(&g, &[LEVEL, OTHER]);
    let sm: IOPCItemSamplingMgt = iface(&g);
    let rates = [100u32, 100];
    let mut revised = poison::<u32>();
    let (hr, errs) = errors_of(2, |e| {
        // SAFETY: valid arrays of two elements and out-pointers.
        unsafe { sm.SetItemSamplingRate(2, h.as_ptr(), rates.as_ptr(), &mut revised, e) }
    });
    assert_eq!((hr, errs), (S_OK, vec![S_OK, S_OK]), "100 ms accepted");
    // SAFETY: the successful call handed out two rates.
    assert_eq!(unsafe { take_array(revised, 2) }, vec![100, 100]);
    let on = [BOOL(1)];
    let (hr, errs) = errors_of(1, |e| {
        // SAFETY: valid one-element arrays.
        unsafe { sm.SetItemBufferEnable(1, h.as_ptr(), on.as_ptr(), e) }
    });
    assert_eq!((hr, errs), (S_OK, vec![S_OK]));

    let (_cookie, rec) = advise(&g);
    let several = rec.wait_for(Duration::from_secs(10), |c| match c {
        Callback::DataChange {
            transaction: 0,
            items,
            ..
        } => items.iter().filter(|i| i.client_handle == 1).count() >= 3,
        _ => false,
    });
    let all = rec.all();
    let Some(Callback::DataChange {
        group,
        master_quality,
        master_error,
        items,
        ..
    }) = several
    else {
        panic!("no OnDataChange with several samples of the buffered item: {all:#?}");
    };
    assert_eq!(group, 1, "the group's client handle");
    let level: Vec<_> = items.iter().filter(|i| i.client_handle == 1).collect();
    assert!(
        level.windows(2).all(|w| w[0].timestamp < w[1].timestamp),
        "oldest first: {level:#?}"
    );
    assert!(level.windows(2).all(|w| w[0].value != w[1].value));
    assert!(
        level.iter().all(|i| i.vt == 4 && i.error == S_OK),
        "R4, S_OK"
    );
    assert_eq!((master_quality, master_error), (S_OK, S_OK));
    for c in &all {
        if let Callback::DataChange { items, .. } = c {
            assert!(
                items.iter().filter(|i| i.client_handle == 2).count() <= 1,
                "the unbuffered item: once per callback"
            );
        }
    }
}
