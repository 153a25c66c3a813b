//! The fuzz targets: each takes arbitrary bytes, feeds them to one decoder of outside
//! input, and checks what must hold for every input (no panic; a decoded value encodes
//! again and decodes to itself where the format round-trips).

use asix_net::proto::discovery::{self, Datagram, FindServer, Resource};
use asix_net::proto::frame::{self, Message, VarRef};
use ctopc_core::browse::{self, MatchCase};
use ctopc_core::convert::Locale;
use ctopc_core::limits;
use ctopc_core::value::ArrayValue;
use ctopc_core::{Quality, Timestamp, Value, VarType, Vqt};

/// asix-net TCP frames: `decode_frame` on a stream prefix, `decode_body` on a body; a
/// decoded frame re-encodes and decodes to itself.
pub fn asix_frame(data: &[u8]) {
    if let Ok(Some((f, used))) = frame::decode_frame(data) {
        assert!(used <= data.len(), "consumed more than given");
        if let Ok(bytes) = frame::frame_bytes(f.request, &f.msg) {
            match frame::decode_frame(&bytes) {
                Ok(Some((again, n))) => {
                    assert_eq!(n, bytes.len());
                    // NaNs compare unequal: compare the encodings instead.
                    let twice = frame::frame_bytes(again.request, &again.msg).ok();
                    assert_eq!(twice.as_deref(), Some(&bytes[..]), "re-encoding differs");
                }
                other => panic!("a re-encoded frame does not decode: {other:?}"),
            }
        }
    }
    let _ = frame::decode_body(data);
    if data.len() >= 4 {
        let _ = frame::body_len([data[0], data[1], data[2], data[3]]);
    }
}

/// asix-net discovery datagrams (UDP): decode; a decoded datagram round-trips.
pub fn asix_datagram(data: &[u8]) {
    if let Ok(d) = discovery::decode_datagram(data) {
        if let Ok(bytes) = discovery::encode_datagram(&d) {
            assert_eq!(
                discovery::decode_datagram(&bytes).ok(),
                Some(d),
                "datagram round trip"
            );
        }
    }
}

/// ASIXConnect.ini: the INI reader (strict and tolerant) and the configuration on top.
pub fn ini(data: &[u8]) {
    let _ = asix_model::ini::parse_ini(data, "fuzz.ini");
    let _ = asix_model::ini::parse_ini_tolerant(data, "fuzz.ini");
    let _ = asix_model::config::parse_config(data, "fuzz.ini");
    if let Ok(s) = std::str::from_utf8(data) {
        let _ = asix_model::ini::split_list(s);
    }
}

/// The CSV attribute table of the variable database.
pub fn csv_attributes(data: &[u8]) {
    let _ = asix_model::vardb::parse_attribute_table(data, "fuzz.csv");
    let (text, _) = asix_model::text::decode_text(data);
    let sep = asix_model::vardb::detect_separator(&text);
    let _ = asix_model::vardb::parse_csv(&text, sep);
}

/// The memo file of the committed Paradox fixture (written by pxlib), for memo references.
pub const PARADOX_MB: &[u8] = include_bytes!("../../crates/asix-model/tests/paradox/types.MB");

/// The Paradox attribute table (`.DB` bytes), without and with a memo file; a table it
/// reads exports to a CSV that reads back to the same table.
pub fn paradox(data: &[u8]) {
    use asix_model::vardb::{paradox_to_csv, parse_attribute_table, parse_paradox_table};
    let _ = parse_paradox_table(data, None, "fuzz.DB");
    let table = parse_paradox_table(data, Some(PARADOX_MB), "fuzz.DB");
    let csv = paradox_to_csv(data, Some(PARADOX_MB), "fuzz.DB", &mut Vec::new());
    if let (Ok((table, _)), Ok(csv)) = (table, csv) {
        let again = parse_attribute_table(csv.as_bytes(), "fuzz.csv")
            .unwrap_or_else(|e| panic!("the export does not read back: {e}"));
        assert_eq!(again.columns, table.columns, "exported columns");
        let cells = |t: &asix_model::vardb::AttributeTable| -> Vec<Vec<String>> {
            t.rows.iter().map(|(_, r)| r.clone()).collect()
        };
        assert_eq!(cells(&again), cells(&table), "exported cells");
    }
}

/// The `.zez` variable-set tree of the variable database.
pub fn zez_varset(data: &[u8]) {
    let _ = asix_model::vardb::parse_var_set(data, "fuzz.zez");
}

/// asix item IDs (with some names taken as variables).
pub fn item_id(data: &[u8]) {
    let id = String::from_utf8_lossy(data);
    let _ = asix_model::parse_item_id(&id, |v| v.starts_with("KW_") || v.len() == 3);
}

/// MatchPattern: `pattern NUL subject`, both cases; bounded by the filter limit as the
/// COM layer bounds it.
pub fn match_pattern(data: &[u8]) {
    let text = String::from_utf8_lossy(data);
    let (pattern, subject) = text.split_once('\0').unwrap_or((&text, "KW_A000"));
    if limits::FILTER.check(pattern).is_err() || subject.len() > 4 * limits::ITEM_ID.max_units {
        return;
    }
    let sensitive = browse::match_pattern(subject, pattern, MatchCase::Sensitive);
    let _ = browse::match_pattern(subject, pattern, MatchCase::Insensitive);
    // (No implication between the two: `[!a-c]` matches "A" only case-sensitively.)
    if pattern == "*" {
        assert!(sensitive, "* matches everything");
    }
}

/// The `Format` attribute: parse, then format a few values with it.
pub fn format(data: &[u8]) {
    let text = String::from_utf8_lossy(data);
    if let Ok(spec) = asix_model::FormatSpec::parse(&text) {
        for v in [
            Value::R8(1234.5678),
            Value::R8(f64::NAN),
            Value::R8(-1e300),
            Value::I4(i32::MIN),
            Value::UI8(u64::MAX),
            Value::Bstr("abc".into()),
            Value::Bool(true),
        ] {
            let _ = spec.format_value(&v);
            let _ = asix_model::format::format_value(Some(&spec), &v);
        }
    }
}

/// A [`Value`] from bytes (one kind byte, then its payload; arrays nested at most
/// [`limits::MAX_VARIANT_DEPTH`] deep, as the COM decoder allows); `None` when the bytes
/// run out.
pub fn value_from_bytes(data: &mut &[u8], depth: usize) -> Option<Value> {
    fn take<'a>(data: &mut &'a [u8], n: usize) -> Option<&'a [u8]> {
        if data.len() < n {
            return None;
        }
        let (a, b) = data.split_at(n);
        *data = b;
        Some(a)
    }
    fn arr<const N: usize>(data: &mut &[u8]) -> Option<[u8; N]> {
        take(data, N)?.try_into().ok()
    }
    let kind = take(data, 1)?[0];
    Some(match kind % 18 {
        0 => Value::Empty,
        1 => Value::I1(i8::from_le_bytes(arr(data)?)),
        2 => Value::UI1(arr::<1>(data)?[0]),
        3 => Value::I2(i16::from_le_bytes(arr(data)?)),
        4 => Value::R4(f32::from_le_bytes(arr(data)?)),
        5 => Value::UI2(u16::from_le_bytes(arr(data)?)),
        6 => Value::I4(i32::from_le_bytes(arr(data)?)),
        7 => Value::UI4(u32::from_le_bytes(arr(data)?)),
        8 => {
            let n = take(data, 1)?[0] as usize;
            Value::Bstr(String::from_utf8_lossy(take(data, n.min(data.len()))?).into_owned())
        }
        9 => Value::I8(i64::from_le_bytes(arr(data)?)),
        10 => Value::UI8(u64::from_le_bytes(arr(data)?)),
        11 => Value::R8(f64::from_le_bytes(arr(data)?)),
        12 => Value::Cy(i64::from_le_bytes(arr(data)?)),
        13 => Value::Date(f64::from_le_bytes(arr(data)?)),
        14 => Value::Bool(arr::<1>(data)?[0] & 1 == 1),
        15 => Value::Error(i32::from_le_bytes(arr(data)?)),
        _ if depth >= limits::MAX_VARIANT_DEPTH => Value::Empty,
        16 => {
            // A VT_VARIANT array of up to 8 values.
            let n = (take(data, 1)?[0] % 9) as usize;
            let mut elements = Vec::with_capacity(n);
            for _ in 0..n {
                elements.push(value_from_bytes(data, depth + 1)?);
            }
            Value::Array(ArrayValue {
                element_type: VarType::VARIANT,
                elements,
            })
        }
        _ => {
            // A typed array: elements of the first element's type.
            let n = (take(data, 1)?[0] % 9) as usize;
            let mut elements = Vec::with_capacity(n);
            for _ in 0..n {
                let e = value_from_bytes(data, limits::MAX_VARIANT_DEPTH)?;
                if matches!(e, Value::Empty | Value::Array(_)) {
                    continue;
                }
                if elements
                    .first()
                    .is_some_and(|f: &Value| f.var_type() != e.var_type())
                {
                    continue;
                }
                elements.push(e);
            }
            let element_type = elements.first().map_or(VarType::R8, Value::var_type);
            Value::Array(ArrayValue {
                element_type,
                elements,
            })
        }
    })
}

/// Every VARTYPE a client may request (and some it may not).
const TARGET_TYPES: [u16; 22] = [
    0, 1, 2, 3, 4, 5, 6, 7, 8, 10, 11, 12, 14, 16, 17, 18, 19, 20, 21, 22, 23, 0xFFFF,
];

/// The pure Value conversion (VariantChangeType rules): any value to any type, both
/// locales, scalars and arrays; a successful conversion to a type has that type.
pub fn value_convert(data: &[u8]) {
    let mut rest = data;
    let Some(v) = value_from_bytes(&mut rest, 0) else {
        return;
    };
    let to_byte = rest.first().copied().unwrap_or(0);
    let mut types: Vec<VarType> = TARGET_TYPES.iter().map(|t| VarType(*t)).collect();
    types.push(VarType(u16::from(to_byte)));
    types.push(VarType::array_of(VarType(u16::from(to_byte) & 0x1F)));
    for to in types {
        for locale in [Locale::EnUs, Locale::PlPl] {
            if let Ok(c) = v.convert_in(to, locale) {
                if to != VarType::EMPTY && to != VarType::VARIANT {
                    assert_eq!(c.var_type(), to, "{v:?} -> {to:?} gave {c:?}");
                }
            }
        }
    }
    let _ = Vqt {
        value: v,
        quality: Quality::GOOD,
        timestamp: Timestamp::default(),
    };
}

/// Valid frames of every message kind, for the seeds.
pub fn sample_frames() -> Vec<Vec<u8>> {
    let var = VarRef::new("K1", "KW_A000");
    let vqt = Vqt {
        value: Value::R4(1.5),
        quality: Quality::GOOD,
        timestamp: Timestamp::default(),
    };
    let msgs = vec![
        Message::Bye { reason: 0 },
        Message::Ping { nonce: 7 },
        Message::Error {
            code: -1,
            message: "zła ramka".into(),
        },
        Message::Unsubscribe {
            handles: vec![1, 2, 3],
        },
        Message::Update {
            items: vec![(1, vqt.clone())],
        },
        Message::Read {
            source: frame::ReadSource::Cache,
            items: vec![var.clone()],
        },
        Message::ReadResult {
            results: vec![Ok(vqt.clone()), Err(-5)],
        },
        Message::Write {
            items: vec![(var.clone(), Value::Bstr("x".into()))],
        },
        Message::WriteVqt {
            items: vec![(var, vqt)],
        },
        Message::WriteResult { results: vec![0] },
    ];
    msgs.iter()
        .filter_map(|m| frame::frame_bytes(9, m).ok())
        .collect()
}

/// Valid discovery datagrams, for the seeds.
pub fn sample_datagrams() -> Vec<Vec<u8>> {
    let d = Datagram::FindServer(FindServer {
        request: 1,
        resource: Resource::channel("K1"),
        client_name: "OPC".into(),
        client_host: "HOST".into(),
    });
    discovery::encode_datagram(&d).into_iter().collect()
}

/// Asix.Evo REST answers: the decoder of `variable/value` answers, the ISO 8601 times,
/// and the REST link's core fed the decoded states (conversion to each variable type,
/// quality, the batch check) as the answer to a poll of as many names.
pub fn asix_rest_answer(data: &[u8]) {
    use asix_net::rest::core::{convert, RestCore, RestCoreConfig};
    use asix_net::rest::decode::{decode_values, format_iso8601, parse_iso8601};
    if let Ok(s) = std::str::from_utf8(data) {
        if let Some(t) = parse_iso8601(s) {
            assert_eq!(
                parse_iso8601(&format_iso8601(t)),
                Some(t),
                "time round trip"
            );
        }
    }
    let Ok(states) = decode_values(data) else {
        return;
    };
    for s in &states {
        for vt in [
            VarType::EMPTY,
            VarType::R4,
            VarType::I2,
            VarType::BOOL,
            VarType::BSTR,
        ] {
            let _ = convert(s.value.clone(), vt);
        }
    }
    let t0 = std::time::Instant::now();
    let now = asix_net::client::core::Now {
        mono: t0,
        wall: Timestamp::from_unix_millis(0),
    };
    let mut core = RestCore::new(RestCoreConfig {
        channel: "F".into(),
        stations: vec!["http://a".into(), "http://b".into()],
        max_batch: 1000,
        max_in_flight: 1,
        retry_interval: std::time::Duration::from_millis(10),
        come_back_interval: std::time::Duration::from_millis(10),
    });
    let n = states.len().clamp(1, 64);
    let keys = (0..n)
        .map(|i| {
            let name = states
                .get(i)
                .and_then(|s| s.id.clone())
                .unwrap_or_else(|| format!("V{i}"));
            (asix_model::ItemKey::new("", &name), VarType::R8)
        })
        .collect();
    core.subscribe(now, keys, 100);
    core.handle_timeout(now);
    while let Some(g) = core.poll_get() {
        core.handle_answer(now, g.id, Ok(states.clone()));
    }
    while core.poll_event().is_some() {}
}

/// Asix.Evo REST answers to start from: the shapes the server and the simulator give.
pub fn sample_rest_answers() -> Vec<Vec<u8>> {
    [
        r#"[{"id":"A000","readSucceeded":true,"readStatusString":"","timeStamp":"2024-05-01T10:00:00.1234567Z","quality":192,"value":12.5}]"#,
        r#"[{"Id":"A004","ReadSucceeded":false,"ReadStatusString":"Unknown variable","TimeStamp":"2024-05-01T12:00:00+02:00","Quality":0,"Value":null}]"#,
        r#"[{"id":"A","value":true,"quality":216},{"id":"B","value":"tekst","quality":65},{"id":"C","value":-7,"quality":192}]"#,
        r#"[]"#,
    ]
    .iter()
    .map(|s| s.as_bytes().to_vec())
    .collect()
}

/// OPC UA: a request body (its type's NodeId, then the request) decoded by async-opcua
/// with the server's limits (the defaults, and small ones), as the server decodes a
/// message; a refusal is a status code, never a panic.
pub fn ua_request(data: &[u8]) {
    use ctopc_ua::limits::{decode_request, Limits};
    let _ = decode_request(data, &Limits::default());
    let small = Limits {
        max_array_length: 16,
        max_string_length: 4096,
        max_message_size: 8192,
        ..Limits::default()
    };
    let _ = decode_request(data, &small);
}

/// Encoded request bodies of the services the server answers, for the seeds.
pub fn sample_ua_requests() -> Vec<Vec<u8>> {
    use opcua::types::{
        BinaryEncodable, BrowseDescription, BrowseRequest, ContextOwned, NodeId, ObjectId,
        ReadRequest, ReadValueId, WriteRequest, WriteValue,
    };
    let owned = ContextOwned::default();
    let ctx = owned.context();
    let item = || NodeId::new(2, "KW_A000");
    let body = |id: ObjectId, enc: &dyn Fn(&mut Vec<u8>)| {
        let mut out = Vec::new();
        let _ = NodeId::from(id).encode(&mut out, &ctx);
        enc(&mut out);
        out
    };
    let read = ReadRequest {
        nodes_to_read: Some(vec![ReadValueId::from(item())]),
        ..Default::default()
    };
    let browse = BrowseRequest {
        nodes_to_browse: Some(vec![BrowseDescription {
            node_id: item(),
            ..Default::default()
        }]),
        ..Default::default()
    };
    let write = WriteRequest {
        nodes_to_write: Some(vec![WriteValue {
            node_id: item(),
            attribute_id: 13,
            value: opcua::types::DataValue::value_only(12.5f64),
            ..Default::default()
        }]),
        ..Default::default()
    };
    vec![
        body(ObjectId::ReadRequest_Encoding_DefaultBinary, &|o| {
            let _ = read.encode(o, &ctx);
        }),
        body(ObjectId::BrowseRequest_Encoding_DefaultBinary, &|o| {
            let _ = browse.encode(o, &ctx);
        }),
        body(ObjectId::WriteRequest_Encoding_DefaultBinary, &|o| {
            let _ = write.encode(o, &ctx);
        }),
    ]
}

/// OPC UA Variant → Value (a write's value) and back: a Variant decoded with the
/// server's limits converts to a Value or is refused with a status code; a Value converts
/// to a Variant that converts back; the Value goes through the write conversion to the
/// variable types.
pub fn ua_variant(data: &[u8]) {
    use opcua::types::{BinaryDecodable, ContextOwned, NamespaceMap, Variant};
    let owned = ContextOwned::new_default(
        NamespaceMap::new(),
        ctopc_ua::limits::Limits::default().decoding_options(),
    );
    let ctx = owned.context();
    let mut stream = std::io::Cursor::new(data);
    let Ok(variant) = Variant::decode(&mut stream, &ctx) else {
        return;
    };
    let Ok(value) = ctopc_ua::value::from_variant(&variant) else {
        return;
    };
    let back = ctopc_ua::value::to_variant(&value);
    assert!(
        ctopc_ua::value::from_variant(&back).is_ok(),
        "{value:?} -> {back:?} does not convert back"
    );
    for to in [VarType::R8, VarType::I4, VarType::BSTR, VarType::BOOL] {
        let _ = value.convert_in(to, Locale::EnUs);
    }
}

/// The OPC UA users file: any text parses to users (malformed lines skipped).
pub fn ua_users(data: &[u8]) {
    let text = String::from_utf8_lossy(data);
    let users = ctopc_ua::users::parse(&text, "fuzz-users.txt");
    assert!(users.len() <= text.lines().count());
}

/// The lazy address space over the embedded demo plant (for [`ua_node_id`]).
fn demo_space() -> &'static ctopc_ua::space::Space {
    use std::sync::{Arc, OnceLock};
    static SPACE: OnceLock<ctopc_ua::space::Space> = OnceLock::new();
    SPACE.get_or_init(|| {
        let loaded = asix_model::startup::embedded_demo().expect("the embedded demo loads");
        let ns = Arc::new(loaded.namespace);
        let tree =
            Arc::new(asix_model::address_space::build_address_space(&ns).expect("the demo's tree"));
        ctopc_ua::space::Space {
            ns: 2,
            namespace: ns,
            tree,
            scan_rate_ms: 100,
            // An empty `_Diagnostics` board: its NodeIds resolve to the folder only.
            diag: Arc::new(ctopc_core::diagnostics::Board::new()),
        }
    })
}

/// OPC UA NodeId ↔ item ID: a NodeId (binary, with the server's limits, or text)
/// resolves to an item, a property, a folder or a status code; an item ID's NodeId
/// parses back to the item ID.
pub fn ua_node_id(data: &[u8]) {
    use ctopc_ua::space::Parsed;
    use opcua::types::{BinaryDecodable, ContextOwned, NamespaceMap, NodeId};
    let space = demo_space();
    let owned = ContextOwned::new_default(
        NamespaceMap::new(),
        ctopc_ua::limits::Limits::default().decoding_options(),
    );
    let ctx = owned.context();
    let mut ids = Vec::new();
    if let Ok(id) = NodeId::decode(&mut std::io::Cursor::new(data), &ctx) {
        ids.push(id);
    }
    let text = String::from_utf8_lossy(data);
    if let Ok(id) = text.parse::<NodeId>() {
        ids.push(id);
    }
    ids.push(space.item_node_id(&text));
    for mut id in ids {
        let _ = space.resolve(&id);
        id.namespace = space.ns;
        let _ = space.resolve(&id);
    }
    if !text.is_empty() {
        assert_eq!(
            space.parse(&space.item_node_id(&text)),
            Some(Parsed::Item(text.clone().into_owned()))
        );
    }
}
