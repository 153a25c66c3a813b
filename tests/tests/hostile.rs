//! A hostile client: counts 0 and huge, NULLs the proxy lets through, invalid
//! and foreign handles, 64 Ki-unit and invalid UTF-16 texts, every VARTYPE requested and
//! written, nested arrays, bogus continuation points, sinks that fail or sleep, and a
//! client process that exits without releasing. Every COM call runs under a watchdog
//! (`e2e_tests::hostile::bounded`): a call that does not return in time ends the test
//! process naming the call. After each family the server must still answer GetStatus.
//! The limits checked are `ctopc_core::limits` (`docs/limits.md`).
#![cfg(windows)]
#![allow(clippy::unwrap_used, clippy::expect_used)]

use ctopc_com::variant;
use ctopc_core::limits;
use ctopc_core::value::ArrayValue;
use ctopc_core::{Value, VarType};
use e2e_tests::hostile::*;
use e2e_tests::interfaces::*;
use e2e_tests::start::StartRetrying;
use e2e_tests::{connect, Apartment, PROGID};
use opc_client::{BrowseArgs, ItemDef, OpcGroup, Server};
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use windows::core::{Interface, HRESULT, PCWSTR};
use windows::Win32::Foundation::{E_FAIL, E_INVALIDARG, S_FALSE, S_OK};
use windows::Win32::System::Variant::VARIANT;

/// Sulphur feed rate setpoint (R4 0..20 t/h, writable).
const SETPOINT: &str = "KW_A110";
/// Level of tank Z101 (R4, read-only, changing).
const LEVEL: &str = "KW_A000";
/// RPC_X_NULL_REF_POINTER: the proxy's answer for a NULL [ref] pointer.
const NULL_REF: HRESULT = HRESULT(0x800706F4u32 as i32);
/// 64 Ki UTF-16 units: far over every text limit.
const HUGE: usize = 64 * 1024;

/// GetStatus answers, quickly, with the server's state.
fn assert_answers(server: &Server, after: &str) {
    let status = call(&format!("GetStatus after {after}"), || server.status())
        .unwrap_or_else(|e| panic!("GetStatus after {after}: {e:?}"));
    assert!(status.vendor_info.is_some(), "after {after}");
}

fn group(server: &Server, name: &str) -> (OpcGroup, u32) {
    let g = call("AddGroup", || {
        server.add_group(&opc_client::GroupSpec::new(name))
    })
    .expect("AddGroup");
    (OpcGroup::from_unknown(g.object).unwrap(), g.server_handle)
}

fn add(g: &OpcGroup, ids: &[&str]) -> Vec<u32> {
    let defs: Vec<ItemDef> = ids
        .iter()
        .enumerate()
        .map(|(i, id)| ItemDef::new(id, i as u32 + 1))
        .collect();
    let (hr, out) = call("AddItems", || g.add_items(&defs)).expect("AddItems");
    assert_eq!(hr, S_OK, "{out:?}");
    out.iter().map(|o| o.server_handle).collect()
}

fn sync(g: &OpcGroup) -> IOPCSyncIO {
    g.unknown.cast().unwrap()
}

/// IOPCSyncIO::Read from cache of `handles`: the call's code and the per-item codes.
fn read_codes(io: &IOPCSyncIO, handles: &[u32]) -> (HRESULT, Vec<HRESULT>) {
    let mut states: *mut OPCITEMSTATE = std::ptr::null_mut();
    let mut errors: *mut HRESULT = std::ptr::null_mut();
    // SAFETY: `handles` lives for the call; valid out-pointers; the results are freed.
    unsafe {
        let hr = io.Read(
            OPC_DS_CACHE,
            handles.len() as u32,
            handles.as_ptr(),
            &mut states,
            &mut errors,
        );
        if hr.is_err() {
            return (hr, Vec::new());
        }
        let n = handles.len();
        for s in std::slice::from_raw_parts_mut(states, n) {
            variant::clear(&mut s.vDataValue);
        }
        windows::Win32::System::Com::CoTaskMemFree(Some(states as *const _));
        (hr, opc_client::take_array(errors, n))
    }
}

// ---- counts ---------------------------------------------------------------------------

#[test]
fn counts_zero_and_huge() {
    let (_com, server) = connect();
    let (g, _) = group(&server, "");
    let io = sync(&g);
    // Count 0: E_INVALIDARG from the server (or the proxy's refusal of the empty array).
    let (hr, _) = call("AddItems(0)", || add_items_raw(&g.item_mgt, &[]));
    assert!(hr == E_INVALIDARG || hr == NULL_REF, "AddItems(0): {hr:?}");
    let (hr, _) = call("Read(0)", || read_codes(&io, &[]));
    assert!(hr == E_INVALIDARG || hr == NULL_REF, "Read(0): {hr:?}");
    assert_answers(&server, "count 0");

    // 100,000 handles, none valid: one error each.
    let handles: Vec<u32> = (0..100_000u32)
        .map(|i| i.wrapping_mul(2_654_435_761))
        .collect();
    let (hr, errs) = call("Read(100,000 invalid handles)", || {
        read_codes(&io, &handles)
    });
    assert_eq!(hr, S_FALSE);
    assert_eq!(errs.len(), handles.len());
    assert!(errs.iter().all(|e| *e == OPC_E_INVALIDHANDLE));
    let (hr, errs) = call("RemoveItems(100,000 invalid handles)", || {
        g.remove_items(&handles)
    })
    .unwrap();
    assert_eq!(hr, S_FALSE);
    assert!(errs.iter().all(|e| *e == OPC_E_INVALIDHANDLE));
    // 20,000 IDs that are not items.
    let defs: Vec<ItemDef> = (0..20_000u32)
        .map(|i| ItemDef::new(&format!("no.such.item.{i}"), i))
        .collect();
    let (hr, out) = call("AddItems(20,000 unknown IDs)", || g.add_items(&defs)).unwrap();
    assert_eq!(hr, S_FALSE);
    assert!(out.iter().all(|o| o.error.is_err()), "every one fails");
    assert_answers(&server, "huge counts");
}

// ---- NULLs ----------------------------------------------------------------------------

#[test]
fn nulls_inside_structures_fail_per_item() {
    let (_com, server) = connect();
    let (g, _) = group(&server, "");
    let id = utf16(SETPOINT);
    // A NULL item ID inside an OPCITEMDEF ([unique] there: the proxy lets it through).
    let (hr, out) = call("AddItems(NULL item ID)", || {
        add_items_raw(&g.item_mgt, &[(None, None, 0), (Some(&id), None, 0)])
    });
    if hr == NULL_REF {
        // Marshalled as [ref] by this proxy: refused before the server.
    } else {
        assert_eq!(hr, S_FALSE);
        assert_eq!(out[0].0, OPC_E_INVALIDITEMID);
        assert_eq!(out[1].0, S_OK, "a NULL access path is the default channel");
    }
    // A NULL element of IOPCItemIO::Read's item ID array.
    let itemio = server.item_io().unwrap();
    let ids = [PCWSTR::null(), PCWSTR(id.as_ptr())];
    let ages = [0u32, 0];
    let (mut v, mut q, mut t, mut e) = (
        std::ptr::null_mut(),
        std::ptr::null_mut(),
        std::ptr::null_mut(),
        std::ptr::null_mut(),
    );
    // SAFETY: arrays of 2 that live for the call; valid out-pointers (results leaked: a
    // test process).
    let hr = call("IOPCItemIO::Read(NULL item ID)", || unsafe {
        itemio.Read(
            2,
            ids.as_ptr(),
            ages.as_ptr(),
            &mut v,
            &mut q,
            &mut t,
            &mut e,
        )
    });
    assert!(
        hr == S_FALSE || hr == NULL_REF || hr == E_INVALIDARG,
        "IOPCItemIO::Read: {hr:?}"
    );
    assert_answers(&server, "NULLs");
}

// ---- handles --------------------------------------------------------------------------

#[test]
fn invalid_and_foreign_handles_fail_per_item() {
    let (_com, server) = connect();
    let (com2, other) = (Apartment::mta().unwrap(), Server::connect(PROGID).unwrap());
    let (mine, my_group) = group(&server, "mine");
    let (theirs, their_group) = group(&other, "theirs");
    let their_items = add(&theirs, &[SETPOINT, LEVEL]);
    let my_items = add(&mine, &[SETPOINT]);
    // Handles of another group (and another client's), 0, all ones, a group handle.
    let foreign: Vec<u32> = their_items
        .iter()
        .copied()
        .chain([0, u32::MAX, 0xDEAD_BEEF, their_group, my_group])
        .filter(|h| !my_items.contains(h))
        .collect();
    let (hr, errs) = call("Read(foreign handles)", || {
        read_codes(&sync(&mine), &foreign)
    });
    assert_eq!(hr, S_FALSE);
    assert!(errs.iter().all(|e| *e == OPC_E_INVALIDHANDLE), "{errs:x?}");
    let (hr, errs) = call("SetActiveState(foreign handles)", || {
        mine.set_active_state(&foreign, false)
    })
    .unwrap();
    assert_eq!(hr, S_FALSE);
    assert!(errs.iter().all(|e| *e == OPC_E_INVALIDHANDLE), "{errs:x?}");
    // Another client's group: not this client's to remove.
    for h in [their_group, 0, u32::MAX] {
        let hr = call("RemoveGroup(foreign)", || server.remove_group(h, true));
        let code = hr.unwrap_or_else(|e| e.code());
        assert!(
            code == E_INVALIDARG || code == E_FAIL,
            "RemoveGroup({h:#x}): {code:?}"
        );
    }
    // Their group is untouched.
    let (hr, errs) = call("Read(their items)", || {
        read_codes(&sync(&theirs), &their_items)
    });
    assert_eq!((hr, errs), (S_OK, vec![S_OK; 2]));
    assert_answers(&server, "foreign handles");
    assert_answers(&other, "foreign handles");
    drop((theirs, other, com2));
}

// ---- texts ----------------------------------------------------------------------------

#[test]
fn huge_and_invalid_texts_answer_with_the_limits_errors() {
    let (_com, server) = connect();
    let (g, _) = group(&server, "");
    let huge = "a".repeat(HUGE);
    let huge16 = utf16(&huge);
    let lone = lone_surrogates(HUGE);
    let at_limit = utf16(&"a".repeat(limits::ITEM_ID.max_units));
    let id = utf16(SETPOINT);

    // AddItems / ValidateItems: item IDs and access paths, per item.
    let (hr, out) = call("AddItems(huge and invalid texts)", || {
        add_items_raw(
            &g.item_mgt,
            &[
                (Some(&huge16), None, 0),
                (Some(&lone), None, 0),
                (Some(&id), Some(&huge16), 0),
                (Some(&id), Some(&lone), 0),
                (Some(&at_limit), None, 0),
                (Some(&id), None, 0),
            ],
        )
    });
    assert_eq!(hr, S_FALSE);
    let codes: Vec<HRESULT> = out.iter().map(|o| o.0).collect();
    assert_eq!(
        codes[..4],
        [
            OPC_E_INVALIDITEMID,
            OPC_E_INVALIDITEMID,
            OPC_E_UNKNOWNPATH,
            OPC_E_UNKNOWNPATH
        ]
    );
    assert!(codes[4] == OPC_E_UNKNOWNITEMID || codes[4] == OPC_E_INVALIDITEMID);
    assert_eq!(codes[5], S_OK);
    let (hr, out) = call("ValidateItems(huge item ID)", || {
        g.validate_items(&[ItemDef::new(&huge, 1)])
    })
    .unwrap();
    assert_eq!((hr, out[0].error), (S_FALSE, OPC_E_INVALIDITEMID));

    // Group and client names.
    for name in [&huge16, &lone] {
        let mut h = 0u32;
        let mut rate = 0u32;
        let mut unk: Option<windows::core::IUnknown> = None;
        // SAFETY: a NUL-terminated name and valid pointers for the call.
        let hr = call("AddGroup(huge or invalid name)", || unsafe {
            server.server.AddGroup(
                PCWSTR(name.as_ptr()),
                true.into(),
                1000,
                1,
                std::ptr::null(),
                std::ptr::null(),
                0x409,
                &mut h,
                &mut rate,
                &IID_IOPCItemMgt,
                &mut unk,
            )
        });
        assert_eq!(hr, E_INVALIDARG);
        // SAFETY: as above.
        let hr = call("SetClientName(huge or invalid)", || unsafe {
            server.common.SetClientName(PCWSTR(name.as_ptr()))
        });
        assert_eq!(windows::core::HRESULT::from(hr), E_INVALIDARG);
    }
    let r = call("GetGroupByName(huge)", || server.group_by_name(&huge));
    assert_eq!(e2e_tests::code(&r), E_INVALIDARG);
    let r = call("SetName(huge)", || g.set_name(&huge));
    assert_eq!(e2e_tests::code(&r), E_INVALIDARG);

    // Browsing, properties, IOPCItemIO.
    let r = call("BrowseOPCItemIDs(huge filter)", || {
        server.browse_item_ids(OPC_FLAT, &huge, 0, 0)
    });
    assert_eq!(e2e_tests::code(&r), OPC_E_INVALIDFILTER);
    let r = call("ChangeBrowsePosition(huge)", || {
        server.change_browse_position(OPC_BROWSE_DOWN, &huge)
    });
    assert_eq!(e2e_tests::code(&r), E_INVALIDARG);
    let r = call("GetItemID(huge)", || server.get_item_id(&huge));
    assert_eq!(e2e_tests::code(&r), E_INVALIDARG);
    let r = call("QueryAvailableProperties(huge)", || {
        server.query_available_properties(&huge)
    });
    assert_eq!(e2e_tests::code(&r), OPC_E_INVALIDITEMID);
    let r = call("IOPCItemIO::Read(huge)", || server.item_read(&[(&huge, 0)])).unwrap();
    assert_eq!((r.0, r.1[0].error), (S_FALSE, OPC_E_INVALIDITEMID));
    let mut args = BrowseArgs::all(&huge);
    let r = call("Browse(huge item ID)", || server.browse(&args));
    assert_eq!(e2e_tests::code(&r), OPC_E_UNKNOWNITEMID);
    args = BrowseArgs::all("");
    args.name_filter = huge.clone();
    let r = call("Browse(huge name filter)", || server.browse(&args));
    assert_eq!(e2e_tests::code(&r), OPC_E_INVALIDFILTER);
    assert_answers(&server, "huge and invalid texts");
}

// ---- continuation points ------------------------------------------------------------------

#[test]
fn bogus_continuation_points_are_refused() {
    let (_com, server) = connect();
    for cp in ["garbage", "0", "\u{FFFF}\u{1F600}", &"x".repeat(HUGE)] {
        let mut args = BrowseArgs::all("");
        args.max_elements = 1;
        args.continuation_point = Some(cp.to_owned());
        let r = call("Browse(bogus continuation point)", || server.browse(&args));
        assert_eq!(
            e2e_tests::code(&r),
            OPC_E_INVALIDCONTINUATIONPOINT,
            "{:?}",
            &cp[..cp.len().min(16)]
        );
    }
    assert_answers(&server, "bogus continuation points");
}

// ---- VARTYPEs ---------------------------------------------------------------------------

/// One value of every kind the client library makes, scalars and arrays.
fn every_value() -> Vec<Value> {
    let scalars = vec![
        Value::Empty,
        Value::I1(-1),
        Value::UI1(1),
        Value::I2(-2),
        Value::UI2(2),
        Value::I4(-4),
        Value::UI4(4),
        Value::I8(-8),
        Value::UI8(8),
        Value::R4(1.5),
        Value::R8(f64::NAN),
        Value::Cy(15_000),
        Value::Date(45_000.5),
        Value::Bstr("12.5".into()),
        Value::Bstr("\u{1F600}".into()),
        Value::Bool(true),
        Value::Error(0x8000_4005u32 as i32),
    ];
    let mut all = scalars.clone();
    for s in scalars.iter().skip(1) {
        all.push(Value::Array(ArrayValue {
            element_type: s.var_type(),
            elements: vec![s.clone(); 3],
        }));
    }
    all
}

#[test]
fn every_vartype_requested_and_written_gets_an_answer() {
    let (_com, server) = connect();
    let (g, _) = group(&server, "");
    let id = utf16(SETPOINT);
    // Every VARTYPE requested, with VT_ARRAY and VT_BYREF.
    let mut vts: Vec<u16> = (0..=0x4Fu16).collect();
    vts.extend((0..=0x24u16).map(|v| v | 0x2000));
    vts.extend((0..=0x24u16).map(|v| v | 0x4000));
    vts.extend([0xFFFF, 0x1FFF, 0x6003]);
    let defs: Vec<_> = vts.iter().map(|vt| (Some(&id[..]), None, *vt)).collect();
    let (hr, out) = call("AddItems(every requested VARTYPE)", || {
        add_items_raw(&g.item_mgt, &defs)
    });
    assert!(hr == S_OK || hr == S_FALSE, "{hr:?}");
    assert_eq!(out.len(), vts.len());
    assert_eq!(out[0].0, S_OK, "VT_EMPTY: the canonical type");
    assert_answers(&server, "every requested VARTYPE");

    // Every value written to a writable R4 (one item per value, one call).
    let h = add(&g, &[SETPOINT])[0];
    let values = every_value();
    let mut vars: Vec<VARIANT> = values
        .iter()
        .map(|v| variant::to_variant(v).unwrap())
        .collect();
    let handles = vec![h; vars.len()];
    let (hr, errs) = call("Write(every VARTYPE)", || {
        write_raw(&sync(&g), &handles, &vars)
    });
    assert!(hr == S_OK || hr == S_FALSE, "{hr:?}");
    assert_eq!(errs.len(), vars.len());
    assert_eq!(errs[9], S_OK, "R4 1.5 is written");
    vars.iter_mut().for_each(variant::clear);
    assert_answers(&server, "every VARTYPE written");
}

// ---- nested arrays ----------------------------------------------------------------------

/// The stack of [`on_big_stack`]: 1 GiB in a 64-bit client, 256 MiB in a 32-bit one
/// (reserved, not committed; a 32-bit process has no room for more).
const BIG_STACK: usize = if cfg!(target_pointer_width = "64") {
    1 << 30
} else {
    256 << 20
};

/// Runs `f` on a thread with a [`BIG_STACK`] stack: the client's own marshalling of a deep
/// VARIANT (oleaut32's VARIANT_UserSize/Marshal) recurses once per level, which a test
/// thread's 2 MiB do not hold at 10,000 levels.
fn on_big_stack(f: impl FnOnce() + Send + 'static) {
    let t = std::thread::Builder::new()
        .stack_size(BIG_STACK)
        .spawn(f)
        .unwrap();
    if let Err(e) = t.join() {
        std::panic::resume_unwind(e);
    }
}

#[test]
fn nested_arrays_deeper_than_the_limit_are_bad_type_and_quick() {
    on_big_stack(nested_arrays);
}

/// The deepest nested VARIANT the hostile test sends by default.
const DEEPEST: usize = 400_000;

/// 10,000, or `CTOPC_HOSTILE_LEVELS` (to measure how deep the transport carries).
fn probe_levels() -> usize {
    std::env::var("CTOPC_HOSTILE_LEVELS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(10_000)
}

fn nested_arrays() {
    let (_com, server) = connect();
    let (g, _) = group(&server, "");
    let h = add(&g, &[SETPOINT])[0];
    let io = sync(&g);
    // One level: the extended write [value, quality, timestamp] is accepted.
    let mut ext = [variant::to_variant(&Value::Array(ArrayValue {
        element_type: VarType::VARIANT,
        elements: vec![Value::R4(2.5), Value::I4(0xC0), Value::Empty],
    }))
    .unwrap()];
    let (hr, errs) = call("Write(extended write)", || write_raw(&io, &[h], &ext));
    variant::clear(&mut ext[0]);
    assert_ne!(errs.first(), Some(&OPC_E_BADTYPE), "{hr:?} {errs:x?}");

    for (levels, limit) in [
        (limits::MAX_VARIANT_DEPTH + 1, Duration::from_secs(20)),
        (1_000, Duration::from_secs(20)),
        (10_000, Duration::from_secs(30)),
        // The deepest the transport is known to carry with the server's 256 MiB stack
        // reserve (docs/limits.md): oleaut32 unmarshals it on the RPC thread, recursing
        // once per level, before the server's decoding refuses it.
        (DEEPEST, Duration::from_secs(120)),
        (probe_levels(), Duration::from_secs(120)),
    ] {
        let inner = variant::to_variant(&Value::R4(1.0)).unwrap();
        let vars = [
            variant::nest(inner, levels).unwrap(),
            variant::to_variant(&Value::R4(3.0)).unwrap(),
        ];
        let t = Instant::now();
        let (hr, errs) = bounded(&format!("Write({levels} levels)"), limit, || {
            write_raw(&io, &[h, h], &vars)
        });
        let took = t.elapsed();
        let [nested, _] = vars;
        variant::clear_nested(nested);
        assert_eq!(hr, S_FALSE, "{levels} levels");
        assert_eq!(errs, [OPC_E_BADTYPE, S_OK], "{levels} levels: per item");
        eprintln!("nested VARIANT of {levels} levels: answered in {took:?}");
        assert_answers(&server, &format!("a VARIANT of {levels} levels"));
    }
}

// ---- sinks ------------------------------------------------------------------------------

#[test]
fn sinks_that_fail_or_sleep_do_not_stall_the_server() {
    let (_com, server) = connect();
    let failing = Arc::new(AtomicU32::new(0));
    let sleeping = Arc::new(AtomicU32::new(0));
    let mut cookies = Vec::new();
    let mut groups = Vec::new();
    for (how, calls) in [
        (Rudeness::Fail, &failing),
        (Rudeness::Sleep(Duration::from_secs(3)), &sleeping),
    ] {
        let (g, _) = group(&server, "");
        add(&g, &[LEVEL, SETPOINT]);
        let sink = RudeSink::create(how, calls);
        let cookie = call("Advise(rude sink)", || {
            opc_client::advise_data_callback(&g.unknown, &sink)
        })
        .unwrap();
        cookies.push(cookie);
        groups.push(g);
    }
    // The first OnDataChange comes at once (every item's first value); the sleeping sink
    // holds it 3 s: the server answers meanwhile, within a second each time.
    let deadline = Instant::now() + Duration::from_secs(15);
    while (failing.load(Ordering::SeqCst) == 0 || sleeping.load(Ordering::SeqCst) == 0)
        && Instant::now() < deadline
    {
        bounded(
            "GetStatus while a sink sleeps",
            Duration::from_secs(5),
            || server.status().unwrap(),
        );
        std::thread::sleep(Duration::from_millis(200));
    }
    assert!(
        failing.load(Ordering::SeqCst) > 0,
        "the failing sink was called"
    );
    assert!(
        sleeping.load(Ordering::SeqCst) > 0,
        "the sleeping sink was called"
    );
    for _ in 0..5 {
        bounded(
            "GetStatus while a sink sleeps",
            Duration::from_secs(5),
            || server.status().unwrap(),
        );
        std::thread::sleep(Duration::from_millis(300));
    }
    // Unadvise and RemoveGroup while a callback may be under way.
    for (g, cookie) in groups.iter().zip(cookies) {
        let r = call("Unadvise(rude sink)", || {
            opc_client::unadvise_data_callback(&g.unknown, cookie)
        });
        assert!(r.is_ok(), "{r:?}");
    }
    drop(groups);
    assert_answers(&server, "rude sinks");
}

// ---- a client that exits without releasing ---------------------------------------------

const CHILD_VAR: &str = "CTOPC_HOSTILE_CHILD";

/// Not a test on its own: the child process of
/// `z_a_client_that_exits_without_releasing_leaves_the_server_answering`. Connects,
/// subscribes, waits for a callback, then exits the process holding every reference.
#[test]
#[ignore = "child process of z_a_client_that_exits_without_releasing_leaves_the_server_answering"]
fn hostile_child() {
    if std::env::var_os(CHILD_VAR).is_none() {
        return;
    }
    let (_com, server) = connect();
    server.set_client_name("hostile child").unwrap();
    let (g, _) = group(&server, "child");
    add(&g, &[LEVEL, SETPOINT]);
    let calls = Arc::new(AtomicU32::new(0));
    let sink = RudeSink::create(Rudeness::Sleep(Duration::from_millis(1)), &calls);
    opc_client::advise_data_callback(&g.unknown, &sink).unwrap();
    let deadline = Instant::now() + Duration::from_secs(20);
    while calls.load(Ordering::SeqCst) == 0 && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(50));
    }
    // Exit with every reference held (no Release, no CoUninitialize).
    std::mem::forget((g, sink, server, _com));
    std::process::exit(if calls.load(Ordering::SeqCst) > 0 {
        0
    } else {
        3
    });
}

#[test]
fn z_a_client_that_exits_without_releasing_leaves_the_server_answering() {
    let (com, server) = connect();
    let child = bounded("the child client", Duration::from_secs(90), || {
        std::process::Command::new(std::env::current_exe().unwrap())
            .args(["--exact", "hostile_child", "--ignored", "--test-threads=1"])
            .env(CHILD_VAR, "1")
            .stdin(std::process::Stdio::null())
            .output_retrying()
            .unwrap()
    });
    assert!(
        child.status.success(),
        "the child subscribed and exited: {:?} {}",
        child.status,
        String::from_utf8_lossy(&child.stderr)
    );
    assert_answers(&server, "a client that exited without releasing");
    // The combination that must not hang: AddItems with a 64 Ki access path of lone
    // surrogates on a server holding a crashed client's session, tried repeatedly while
    // the server's callbacks to the dead sink fail.
    let (g, _) = group(&server, "");
    let id = utf16(SETPOINT);
    let lone = lone_surrogates(HUGE);
    for i in 0..16 {
        let (hr, out) = call(&format!("AddItems(lone surrogate path) #{i}"), || {
            add_items_raw(&g.item_mgt, &[(Some(&id), Some(&lone), 0)])
        });
        assert_eq!((hr, out[0].0), (S_FALSE, OPC_E_UNKNOWNPATH));
        assert_answers(&server, "AddItems with a path of lone surrogates");
        std::thread::sleep(Duration::from_millis(100));
    }
    drop(g);
    drop(server);
    drop(com);
    // The dead client's references keep the server up for ever under Wine (no DCOM
    // ping): end it, so that later tests start a server of their own.
    let ended = terminate_servers();
    eprintln!("ended {ended} server process(es) kept alive by the dead client");
}

/// Opt-in (`CTOPC_HOSTILE_KILL_LEVELS=N`): a VARIANT of N levels, deep enough that
/// oleaut32's unmarshalling overflows the server's RPC thread (docs/limits.md: past about
/// 800,000 levels with the 256 MiB reserve; a 64-bit client only). Under Wine that RPC
/// thread dies and the call never returns; the server must go on answering GetStatus, on
/// the connection it had and on a new one. The deep call runs on a thread of its own that
/// is never joined; the server is ended at the end (it holds the dead call).
#[test]
fn z_b_a_variant_deeper_than_the_transport_carries_leaves_the_server_answering() {
    let Some(levels) = std::env::var("CTOPC_HOSTILE_KILL_LEVELS")
        .ok()
        .and_then(|s| s.parse::<usize>().ok())
    else {
        return;
    };
    let (_com, server) = connect();
    assert_answers(&server, "connecting");
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::Builder::new()
        .stack_size(BIG_STACK)
        .spawn(move || {
            let (_com, server) = connect();
            let (g, _) = group(&server, "");
            let h = add(&g, &[SETPOINT])[0];
            let io = sync(&g);
            let inner = variant::to_variant(&Value::R4(1.0)).unwrap();
            let vars = [variant::nest(inner, levels).unwrap()];
            let _ = tx.send(());
            let t = Instant::now();
            let r = write_raw(&io, &[h], &vars);
            eprintln!("{levels} levels answered after {:?}: {r:x?}", t.elapsed());
            let [nested] = vars;
            variant::clear_nested(nested);
        })
        .unwrap();
    rx.recv_timeout(Duration::from_secs(120))
        .expect("the deep VARIANT is built");
    // While the deep call is sent, unmarshalled and overflows, and after: every 2 s.
    let until = Instant::now() + Duration::from_secs(60);
    while Instant::now() < until {
        assert_answers(&server, &format!("a VARIANT of {levels} levels"));
        std::thread::sleep(Duration::from_secs(2));
    }
    let fresh = call("connect after the deep VARIANT", || Server::connect(PROGID))
        .expect("a new connection after the deep VARIANT");
    assert_answers(&fresh, "a new connection after the deep VARIANT");
    drop(fresh);
    drop(server);
    let ended = terminate_servers();
    eprintln!("ended {ended} server process(es) holding the dead call");
}
