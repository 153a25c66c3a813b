//! The late-bound Automation client (`ctopc_com::automation`) against the test double of
//! AsixConnect's `XConnect.ServerCT` (`tests/xconnect-double`): bound by name only, as
//! the asix gateway binds the original (AsixConnect digest §11: names and meanings, no
//! IIDs or DISPIDs).
//!
//! The double is a 32-bit in-process server, so this file runs only as a 32-bit client
//! (`cargo xtask e2e --x86 -p e2e-tests --test xconnect`); xtask builds the double and
//! its type library and registers them with the 32-bit regsvr32. Each test is a
//! single-threaded apartment that pumps messages while it waits for events (the double is
//! apartment-threaded, its timer is a thread timer of the creating thread).

#![cfg(all(windows, target_pointer_width = "32"))]

use ctopc_com::apartment::Apartment;
use ctopc_com::automation::{pump_messages_until, Arg, Event, Object};
use ctopc_core::Value;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

const PROGID: &str = "XConnect.ServerCT";
const CHANNEL: &str = "Demo_Wytwornia_Kwasu";
const DS_CACHE: i32 = 1;
const DS_DEVICE: i32 = 2;
const DS_DRIVER: i32 = 3;
const GOOD: i32 = 0xC0;
const DISP_E_EXCEPTION: i32 = 0x8002_0009_u32 as i32;
const DISP_E_UNKNOWNNAME: i32 = 0x8002_0006_u32 as i32;
const DISP_E_TYPEMISMATCH: i32 = 0x8002_0005_u32 as i32;
const DISP_E_MEMBERNOTFOUND: i32 = 0x8002_0003_u32 as i32;
const E_INVALIDARG: i32 = 0x8007_0057_u32 as i32;
const NET_FIND_SERVER_NOT_FOUND: i32 = 0xC004_8105_u32 as i32;
const NET_ANSWER_TIMEOUT: i32 = 0xC004_810B_u32 as i32;
const ITEM_UNKNOWN: i32 = 0xC004_8120_u32 as i32;
const WRITE_ERROR: i32 = 0xC004_8128_u32 as i32;

fn s(text: &str) -> Value {
    Value::Bstr(text.to_owned())
}

/// A new double, initialised with `options`.
fn server(options: &str) -> Object {
    let server = Object::create(PROGID).expect("XConnect.ServerCT (is the double registered?)");
    server.call("Init", &[s(options)]).expect("Init");
    server
}

/// `Read` with all three out-parameters: (value, quality, timestamp).
fn read(
    server: &Object,
    source: i32,
    item: &str,
) -> Result<(Value, Value, Value), ctopc_com::automation::Error> {
    let mut args = [
        Arg::In(Value::I4(source)),
        Arg::In(s(item)),
        Arg::InOut(Value::Empty),
        Arg::InOut(Value::Empty),
        Arg::InOut(Value::Empty),
    ];
    server.invoke("Read", &mut args)?;
    Ok((
        args[2].value().clone(),
        args[3].value().clone(),
        args[4].value().clone(),
    ))
}

fn date(v: &Value) -> f64 {
    match v {
        Value::Date(d) => *d,
        other => panic!("a VT_DATE expected, got {other:?}"),
    }
}

#[test]
fn binds_by_name_and_reports_no_config_before_initialisation() {
    let _a = Apartment::sta().unwrap();
    let server = Object::create(PROGID).unwrap();
    for name in [
        "LoadChannel",
        "Init",
        "Read",
        "SetItemActive",
        "Write",
        "WriteEx",
        "Active",
        "ServerState",
        "StartTime",
    ] {
        server
            .dispid(name)
            .unwrap_or_else(|e| panic!("{name}: {e}"));
    }
    assert_eq!(
        server.dispid("read").unwrap(),
        server.dispid("Read").unwrap(),
        "names are case-insensitive"
    );
    let e = server.dispid("NoSuchMember").unwrap_err();
    assert_eq!(e.code, DISP_E_UNKNOWNNAME, "{e}");
    assert_eq!(server.get("ServerState").unwrap(), Value::I4(3));
    assert_eq!(server.get("Active").unwrap(), Value::Bool(false));
    let e = read(&server, DS_DEVICE, "KW_A000").unwrap_err();
    assert!(e.description.contains("NetInit"), "{e}");
}

#[test]
fn load_channel_knows_its_channel_and_applies_the_environment_options() {
    let _a = Apartment::sta().unwrap();
    let server = Object::create(PROGID).unwrap();
    let e = server.call("LoadChannel", &[s("Nowhere")]).unwrap_err();
    assert_eq!(
        (e.hresult, e.code),
        (DISP_E_EXCEPTION, NET_FIND_SERVER_NOT_FOUND),
        "{e}"
    );
    assert!(e.description.contains("Nowhere"), "{e}");
    std::env::set_var("XCONNECT_DOUBLE_OPTIONS", "State=5;Fail=Write");
    let loaded = server.call("LoadChannel", &[s(CHANNEL)]);
    std::env::remove_var("XCONNECT_DOUBLE_OPTIONS");
    loaded.unwrap();
    assert_eq!(server.get("ServerState").unwrap(), Value::I4(5));
    let e = server
        .call("Write", &[s("KW_A000"), Value::I4(1)])
        .unwrap_err();
    assert_eq!(e.code, WRITE_ERROR, "{e}");
    assert!(e.description.contains("WriteError"), "{e}");
}

#[test]
fn read_from_each_data_source() {
    let _a = Apartment::sta().unwrap();
    let server = server("");
    let start = date(&server.get("StartTime").unwrap());
    for source in [DS_DEVICE, DS_DRIVER] {
        let (value, quality, ts) = read(&server, source, "KW_A001").unwrap();
        assert_eq!(
            (value, quality),
            (Value::R8(20.0), Value::I4(GOOD)),
            "source {source}"
        );
        assert!(
            date(&ts) >= start,
            "the timestamp is local time after StartTime"
        );
    }
    // The cache holds active variables only.
    let (value, quality, _) = read(&server, DS_CACHE, "KW_A001").unwrap();
    assert_eq!((value, quality), (Value::Empty, Value::I4(0x1C)));
    server
        .call("SetItemActive", &[s("KW_A001"), Value::Bool(true)])
        .unwrap();
    let (value, quality, _) = read(&server, DS_CACHE, "KW_A001").unwrap();
    assert_eq!((value, quality), (Value::R8(20.0), Value::I4(GOOD)));
    // TimeStamp is optional.
    let mut args = [
        Arg::In(Value::I2(2)),
        Arg::In(s("KW_A002")),
        Arg::InOut(Value::Empty),
        Arg::InOut(Value::Empty),
        Arg::Missing,
    ];
    server.invoke("Read", &mut args).unwrap();
    assert_eq!(args[2].value(), &Value::R8(30.0));
    let e = read(&server, DS_DEVICE, "NoSuchVariable").unwrap_err();
    assert_eq!(e.code, ITEM_UNKNOWN, "{e}");
    let e = read(&server, 7, "KW_A001").unwrap_err();
    assert_eq!(e.code, E_INVALIDARG, "{e}");
    assert!(e.description.contains("dsCache"), "{e}");
}

#[test]
fn write_and_write_ex_read_back() {
    let _a = Apartment::sta().unwrap();
    let server = server("Vars=AI201,AI202");
    server.call("Write", &[s("AI201"), Value::I4(42)]).unwrap();
    let (value, quality, _) = read(&server, DS_DEVICE, "AI201").unwrap();
    assert_eq!((value, quality), (Value::R8(42.0), Value::I4(GOOD)));
    let stamp = 45_000.5; // 2023-03-15 12:00, local time
    server
        .call(
            "WriteEx",
            &[
                s("AI202"),
                Value::R4(1.5),
                Value::I4(0x40),
                Value::Date(stamp),
            ],
        )
        .unwrap();
    let (value, quality, ts) = read(&server, DS_DRIVER, "AI202").unwrap();
    assert_eq!(
        (value, quality, ts),
        (Value::R8(1.5), Value::I4(0x40), Value::Date(stamp))
    );
    let e = server.call("Write", &[s("AI201"), s("text")]).unwrap_err();
    assert_eq!(e.code, DISP_E_TYPEMISMATCH, "{e}");
    assert!(e.description.contains("integer or real"), "{e}");
}

#[test]
fn data_change_events_arrive_for_active_variables_while_active() {
    let _a = Apartment::sta().unwrap();
    let server = server("Vars=A,B;PeriodMs=20");
    let events: Arc<Mutex<Vec<Event>>> = Arc::default();
    let sink = Arc::clone(&events);
    let connection = server
        .advise_events(move |e| sink.lock().unwrap().push(e.clone()))
        .unwrap();
    server
        .call("SetItemActive", &[s("B"), Value::Bool(true)])
        .unwrap();
    server.put("Active", &Value::Bool(true)).unwrap();
    assert_eq!(server.get("Active").unwrap(), Value::Bool(true));
    let arrived = pump_messages_until(Duration::from_secs(20), || {
        events.lock().unwrap().len() >= 3
    });
    server.put("Active", &Value::Bool(false)).unwrap();
    assert!(arrived, "three DataChange events within 20 s");
    let events = events.lock().unwrap().clone();
    let start = date(&server.get("StartTime").unwrap());
    let mut last = 20.0;
    for e in &events {
        assert_eq!(e.name, "DataChange");
        assert_eq!(e.args.len(), 4, "{e:?}");
        assert_eq!(e.args[0], s("B"), "only the active variable: {e:?}");
        let Value::R8(v) = e.args[1] else {
            panic!("{e:?}")
        };
        assert_eq!(v, last + 1.0, "each tick adds 1: {e:?}");
        last = v;
        assert_eq!(e.args[2], Value::I4(GOOD));
        assert!(date(&e.args[3]) >= start, "{e:?}");
    }
    // The cache has what the events said.
    let (value, _, _) = read(&server, DS_CACHE, "B").unwrap();
    assert_eq!(value, Value::R8(last));
    assert!(connection.cookie() != 0);
    drop(connection);
}

#[test]
fn server_state_reports_each_state_and_is_read_only() {
    let _a = Apartment::sta().unwrap();
    let server = Object::create(PROGID).unwrap();
    for state in 1..=5 {
        server
            .call("Init", &[s(&format!("State={state}"))])
            .unwrap();
        assert_eq!(server.get("ServerState").unwrap(), Value::I4(state));
    }
    let e = server.put("ServerState", &Value::I4(1)).unwrap_err();
    assert_eq!(e.code, DISP_E_MEMBERNOTFOUND, "{e}");
    let e = server.call("Init", &[s("State=9")]).unwrap_err();
    assert_eq!(e.code, E_INVALIDARG, "{e}");
    assert!(e.description.contains("State=9"), "{e}");
}

#[test]
fn a_failing_call_carries_its_code_and_text() {
    let _a = Apartment::sta().unwrap();
    let server = server("Fail=Read,WriteEx");
    let e = read(&server, DS_DEVICE, "KW_A000").unwrap_err();
    assert_eq!(
        (e.hresult, e.code),
        (DISP_E_EXCEPTION, NET_ANSWER_TIMEOUT),
        "{e}"
    );
    assert!(e.description.contains("NetAnswerTimeout"), "{e}");
    assert!(e.to_string().contains("Read: 0xC004810B"), "{e}");
    let e = server
        .call(
            "WriteEx",
            &[
                s("KW_A000"),
                Value::I4(1),
                Value::I4(GOOD),
                Value::Date(45_000.0),
            ],
        )
        .unwrap_err();
    assert_eq!(e.code, WRITE_ERROR, "{e}");
    // Other methods still work.
    server.call("Write", &[s("KW_A000"), Value::I4(5)]).unwrap();
}

#[test]
fn a_hanging_call_answers_after_its_hang() {
    let _a = Apartment::sta().unwrap();
    let server = server("Hang=Write;HangMs=300");
    let started = Instant::now();
    server.call("Write", &[s("KW_A000"), Value::I4(7)]).unwrap();
    let took = started.elapsed();
    assert!(
        took >= Duration::from_millis(300),
        "Write answered after {took:?}"
    );
    let (value, _, _) = read(&server, DS_DEVICE, "KW_A000").unwrap();
    assert_eq!(value, Value::R8(7.0), "the hanging Write did its work");
}
