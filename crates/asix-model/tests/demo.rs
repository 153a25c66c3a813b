//! Tests against the shipped demo database (`demo/wytwornia_kwasu/`) and
//! `asixconnect.ini.example`, loaded from the repository.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use asix_model::config::{
    load_config_file, parse_config, AsixConfig, CHANNEL_OPTIONS, SERVER_OPTIONS, UA_OPTIONS,
};
use asix_model::namespace::{AsixNamespace, BrowseNode, ChannelDatabase, Derivation, LimitProps};
use asix_model::quality_rules::{apply_quality_rules, RuleOptions};
use asix_model::text::decode_windows_1250;
use asix_model::vardb::{load_database_file, parse_attribute_table, Limit, VarDatabase};
use ctopc_core::namespace::{EuInfo, ItemDef, Namespace, OPC_READABLE, OPC_WRITEABLE};
use ctopc_core::value::ArrayValue;
use ctopc_core::{OpcError, Quality, Value, VarType};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn demo_set() -> PathBuf {
    repo().join("demo/wytwornia_kwasu/wytwornia_kwasu.zez")
}

fn demo_db(alias: Option<&str>) -> VarDatabase {
    let (db, warnings) = load_database_file(&demo_set(), alias).unwrap_or_else(|e| panic!("{e}"));
    assert!(warnings.is_empty(), "{warnings:?}");
    db
}

fn example() -> AsixConfig {
    let (config, warnings) =
        load_config_file(&repo().join("asixconnect.ini.example")).unwrap_or_else(|e| panic!("{e}"));
    assert!(warnings.is_empty(), "{warnings:?}");
    config
}

fn example_namespace() -> AsixNamespace {
    let (ns, warnings) = AsixNamespace::load(example());
    assert!(warnings.is_empty(), "{warnings:?}");
    ns
}

#[test]
fn demo_database_loads_cleanly() {
    let db = demo_db(None);
    assert!(db.variables.len() >= 200, "{}", db.variables.len());
    assert_eq!(db.visible_count(), db.variables.len());
    assert_eq!(db.title.as_deref(), Some("Wytwórnia kwasu siarkowego"));
    let a000 = db.find_public("KW_A000").unwrap();
    assert_eq!(a000.description, "Poziom siarki ciekłej w zbiorniku Z101");
    assert_eq!(a000.unit, "m");
    assert_eq!(a000.range, Some((0.0, 8.0)));
    assert_eq!(a000.data_type, VarType::R4);
    assert_eq!(a000.format_text, "%.2f");
    assert!(a000.format.is_some());
    assert_eq!(a000.warn_low, Some(Limit::Value(1.0)));
    assert_eq!(a000.alarm_high, Some(Limit::Value(7.5)));
    assert_eq!(a000.control_variable.as_deref(), Some("KW_K001"));
    assert!(!a000.writable);
    assert!(db.find_public("KW_A110").unwrap().writable);
    assert_eq!(
        db.find_public("KW_A508").unwrap().description,
        "Ciśnienie pary; kolektor wysokoprężny"
    );
    assert_eq!(
        db.find_public("KW_A100").unwrap().alarm_high,
        Some(Limit::Variable("KW_L002".into()))
    );
    // Every variable has a unit-bearing description and a format; every measurement a range.
    for v in &db.variables {
        assert!(
            !v.description.is_empty() && !v.description_en.is_empty(),
            "{}",
            v.name
        );
        assert!(v.format.is_some(), "{}: {}", v.name, v.format_text);
        assert!(v.range.is_some(), "{}", v.name);
    }
    // The tree: six plant sections plus diagnostics; every variable browsable once.
    let top: Vec<&str> = db.root.groups.iter().map(|g| g.name.as_str()).collect();
    assert_eq!(
        top,
        [
            "Magazyn siarki",
            "Spalanie siarki",
            "Węzeł kontaktowy",
            "Absorpcja i suszenie",
            "Magazyn kwasu i ekspedycja",
            "Media",
            "Diagnostyka"
        ]
    );
    fn count(g: &asix_model::vardb::GroupNode) -> usize {
        g.variables.len() + g.groups.iter().map(count).sum::<usize>()
    }
    assert_eq!(count(&db.root), db.variables.len());
}

#[test]
fn demo_database_in_windows_1250_reads_the_same() {
    let path = repo().join("demo/wytwornia_kwasu/atrybuty.csv");
    let utf8 = std::fs::read(&path).unwrap();
    // Encode to Windows-1250 with the inverse of the decoder (unmappable -> '?').
    let table: Vec<char> = (0u8..=255)
        .map(|b| decode_windows_1250(&[b]).chars().next().unwrap())
        .collect();
    let text = String::from_utf8(utf8[3..].to_vec()).unwrap();
    let bytes: Vec<u8> = text
        .chars()
        .map(|c| {
            table
                .iter()
                .position(|&t| t == c && t != '\u{FFFD}')
                .map_or(b'?', |b| b as u8)
        })
        .collect();
    assert!(
        std::str::from_utf8(&bytes).is_err(),
        "the re-encoded table must not be valid UTF-8"
    );
    let t = parse_attribute_table(&bytes, "atrybuty-1250.csv").unwrap();
    let (db, _) = VarDatabase::build(&t, None, None).unwrap();
    assert_eq!(db.variables.len(), demo_db(None).variables.len());
    assert_eq!(
        db.find_public("KW_A121").unwrap().description,
        "Poziom wody w walczaku kotła K203"
    );
    assert_eq!(db.find_public("KW_A001").unwrap().unit, "°C");
}

#[test]
fn example_ini_documents_every_option_and_parses_cleanly() {
    let text = std::fs::read_to_string(repo().join("asixconnect.ini.example")).unwrap();
    for option in SERVER_OPTIONS
        .iter()
        .chain(CHANNEL_OPTIONS)
        .chain(UA_OPTIONS)
    {
        let documented = text.lines().any(|l| {
            let l = l.trim_start_matches([';', ' ']);
            l.starts_with(option) && l[option.len()..].trim_start().starts_with('=')
        });
        assert!(documented, "{option} is not in asixconnect.ini.example");
    }
    let c = example();
    assert_eq!(c.channels.len(), 3);
    // OPC UA beside DA is what the user turns on (its `[UA]` section is commented out).
    assert!(!c.ua.section && !c.ua.beside_da());
    assert_eq!(c.server.min_update_rate_ms, 1000);
    let demo = c.resolve_channel("Demo_Wytwornia_Kwasu").unwrap();
    assert!(demo.options.check_limits && demo.options.check_control_variables);
    assert_eq!(
        c.resolve_channel("Wytwornia_Kwasu_Tagi")
            .unwrap()
            .options
            .alias_attribute_name
            .as_deref(),
        Some("Alias")
    );
    assert_eq!(
        c.resolve_path(c.basic().items_database.as_deref().unwrap()),
        repo().join("demo/wytwornia_kwasu/wytwornia_kwasu.zez")
    );
    // Parsing the same bytes without a path gives the same options.
    let (again, _) = parse_config(text.as_bytes(), "x").unwrap();
    assert_eq!(again.channels, c.channels);
}

#[test]
fn example_namespace_loads_every_channel_database() {
    let ns = example_namespace();
    assert_eq!(ns.no_config_reason(), None);
    let star = ns.database("*").unwrap();
    let demo = ns.database("Demo_Wytwornia_Kwasu").unwrap();
    assert!(Arc::ptr_eq(star, demo), "same file and alias: loaded once");
    let tags = ns.database("Wytwornia_Kwasu_Tagi").unwrap();
    assert!(!Arc::ptr_eq(star, tags));
    assert!(tags.visible_count() < tags.variables.len());
}

fn def(
    key: &str,
    channel: &str,
    ty: VarType,
    rights: u32,
    eu: EuInfo,
    constant: Option<Value>,
) -> ItemDef {
    ItemDef {
        source_key: key.into(),
        channel: channel.into(),
        canonical_type: ty,
        access_rights: rights,
        eu,
        constant,
    }
}

const R: u32 = OPC_READABLE;
const RW: u32 = OPC_READABLE | OPC_WRITEABLE;

fn analog(low: f64, high: f64) -> EuInfo {
    EuInfo::Analog { low, high }
}

fn bstr(s: &str) -> Option<Value> {
    Some(Value::Bstr(s.into()))
}

fn pair(a: f64, b: f64) -> Option<Value> {
    Some(Value::Array(ArrayValue {
        element_type: VarType::R8,
        elements: vec![Value::R8(a), Value::R8(b)],
    }))
}

/// One row per (item ID, access path) of the resolution table in `namespace.rs`.
#[test]
fn resolution_table_against_the_demo_database() {
    let ns = example_namespace();
    let n = EuInfo::None;
    let r8a = VarType::array_of(VarType::R8);
    let rows: Vec<(&str, &str, Result<ItemDef, OpcError>)> = vec![
        // Current values.
        (
            "KW_A000",
            "",
            Ok(def("KW_A000", "*", VarType::R4, R, analog(0.0, 8.0), None)),
        ),
        (
            "KW_A000.CV",
            "*",
            Ok(def("KW_A000", "*", VarType::R4, R, analog(0.0, 8.0), None)),
        ),
        (
            "KW_A000",
            "ANY",
            Ok(def("KW_A000", "*", VarType::R4, R, analog(0.0, 8.0), None)),
        ),
        (
            "KW_A110",
            "Demo_Wytwornia_Kwasu",
            Ok(def(
                "KW_A110",
                "Demo_Wytwornia_Kwasu",
                VarType::R4,
                RW,
                analog(0.0, 20.0),
                None,
            )),
        ),
        (
            "KW_D000",
            "",
            Ok(def("KW_D000", "*", VarType::I2, R, analog(0.0, 1.0), None)),
        ),
        (
            "KW_A016",
            "",
            Ok(def(
                "KW_A016",
                "*",
                VarType::UI2,
                R,
                analog(0.0, 3000.0),
                None,
            )),
        ),
        (
            "KW_D004",
            "",
            Ok(def("KW_D004", "*", VarType::UI4, R, analog(0.0, 4e9), None)),
        ),
        (
            "KW_D201",
            "",
            Ok(def(
                "KW_D201",
                "*",
                VarType::UI1,
                RW,
                analog(0.0, 2.0),
                None,
            )),
        ),
        // Constant attributes.
        (
            "KW_A000.DATA_TYPE",
            "",
            Ok(def(
                "KW_A000.DATA_TYPE",
                "*",
                VarType::I2,
                R,
                n.clone(),
                Some(Value::I2(4)),
            )),
        ),
        (
            "KW_D000.DATA_TYPE",
            "",
            Ok(def(
                "KW_D000.DATA_TYPE",
                "*",
                VarType::I2,
                R,
                n.clone(),
                Some(Value::I2(2)),
            )),
        ),
        (
            "KW_A001.EU_UNIT",
            "",
            Ok(def(
                "KW_A001.EU_UNIT",
                "*",
                VarType::BSTR,
                R,
                n.clone(),
                bstr("°C"),
            )),
        ),
        (
            "KW_A000.DESC",
            "",
            Ok(def(
                "KW_A000.DESC",
                "*",
                VarType::BSTR,
                R,
                n.clone(),
                bstr("Poziom siarki ciekłej w zbiorniku Z101"),
            )),
        ),
        (
            "KW_A000.HI_EU",
            "",
            Ok(def(
                "KW_A000.HI_EU",
                "*",
                VarType::R8,
                R,
                n.clone(),
                Some(Value::R8(8.0)),
            )),
        ),
        (
            "KW_A104.LO_EU",
            "",
            Ok(def(
                "KW_A104.LO_EU",
                "*",
                VarType::R8,
                R,
                n.clone(),
                Some(Value::R8(-5.0)),
            )),
        ),
        (
            "KW_A000.Channel",
            "",
            Ok(def(
                "KW_A000.Channel",
                "*",
                VarType::BSTR,
                R,
                n.clone(),
                bstr("SIARKA"),
            )),
        ),
        (
            "KW_A000.WarnHigh",
            "",
            Ok(def(
                "KW_A000.WarnHigh",
                "*",
                VarType::R8,
                R,
                n.clone(),
                Some(Value::R8(7.0)),
            )),
        ),
        (
            "KW_A100.AlarmHigh",
            "",
            Ok(def(
                "KW_A100.AlarmHigh",
                "*",
                VarType::BSTR,
                R,
                n.clone(),
                bstr("KW_L002"),
            )),
        ),
        (
            "KW_A000.Format",
            "",
            Ok(def(
                "KW_A000.Format",
                "*",
                VarType::BSTR,
                R,
                n.clone(),
                bstr("%.2f"),
            )),
        ),
        (
            "KW_A000.Description",
            "",
            Ok(def(
                "KW_A000.Description",
                "*",
                VarType::BSTR,
                R,
                n.clone(),
                bstr("Poziom siarki ciekłej w zbiorniku Z101"),
            )),
        ),
        (
            "KW_A000.BarBase",
            "",
            Ok(def(
                "KW_A000.BarBase",
                "*",
                VarType::BSTR,
                R,
                n.clone(),
                bstr(""),
            )),
        ),
        // Derived live values.
        (
            "KW_A000.FormatedCV",
            "",
            Ok(def(
                "KW_A000.FormatedCV",
                "*",
                VarType::BSTR,
                R,
                n.clone(),
                None,
            )),
        ),
        (
            "KW_A000.PercentageCV",
            "",
            Ok(def(
                "KW_A000.PercentageCV",
                "*",
                VarType::R8,
                R,
                analog(0.0, 100.0),
                None,
            )),
        ),
        (
            "KW_A000.BarCVs",
            "",
            Ok(def("KW_A000.BarCVs", "*", r8a, R, n.clone(), None)),
        ),
        (
            "KW_A000.BarCV",
            "",
            Ok(def("KW_A000.BarCVs", "*", r8a, R, n.clone(), None)),
        ),
        // <V>.<A>.CV with a numeric attribute.
        (
            "KW_A000.WarnHigh.CV",
            "",
            Ok(def(
                "KW_A000.WarnHigh.CV",
                "*",
                VarType::R8,
                R,
                n.clone(),
                Some(Value::R8(7.0)),
            )),
        ),
        (
            "KW_A000.WarnHigh.CV.FormatedCV",
            "",
            Ok(def(
                "KW_A000.WarnHigh.CV.FormatedCV",
                "*",
                VarType::BSTR,
                R,
                n.clone(),
                bstr("7.00"),
            )),
        ),
        (
            "KW_A000.WarnHigh.CV.PercentageCV",
            "",
            Ok(def(
                "KW_A000.WarnHigh.CV.PercentageCV",
                "*",
                VarType::R8,
                R,
                n.clone(),
                Some(Value::R8(87.5)),
            )),
        ),
        (
            "KW_A000.WarnLow.CV.BarCVs",
            "",
            Ok(def(
                "KW_A000.WarnLow.CV.BarCVs",
                "*",
                r8a,
                R,
                n.clone(),
                pair(12.5, 0.0),
            )),
        ),
        (
            "KW_A121.AlarmHigh.CV.BarCV",
            "",
            Ok(def(
                "KW_A121.AlarmHigh.CV.BarCVs",
                "*",
                r8a,
                R,
                n.clone(),
                pair(37.5, 50.0),
            )),
        ),
        ("KW_A000.WarnHigh.CV.DESC", "", Err(OpcError::UnknownItemId)),
        // <V>.<A>.CV with an indirect variable.
        (
            "KW_A100.AlarmHigh.CV",
            "",
            Ok(def(
                "KW_L002",
                "*",
                VarType::R4,
                RW,
                analog(0.0, 1200.0),
                None,
            )),
        ),
        (
            "KW_A100.AlarmHigh.CV.FormatedCV",
            "",
            Ok(def(
                "KW_L002.FormatedCV",
                "*",
                VarType::BSTR,
                R,
                n.clone(),
                None,
            )),
        ),
        (
            "KW_A100.AlarmHigh.CV.PercentageCV",
            "",
            Ok(def(
                "KW_L002.PercentageCV",
                "*",
                VarType::R8,
                R,
                analog(0.0, 100.0),
                None,
            )),
        ),
        (
            "KW_A100.AlarmHigh.CV.BarCV",
            "",
            Ok(def("KW_L002.BarCVs", "*", r8a, R, n.clone(), None)),
        ),
        (
            "KW_A100.AlarmHigh.CV.DESC",
            "",
            Ok(def(
                "KW_L002.DESC",
                "*",
                VarType::BSTR,
                R,
                n.clone(),
                bstr("Limit alarmowy temperatury pieca"),
            )),
        ),
        (
            "KW_A100.AlarmHigh.CV.Unit",
            "",
            Ok(def(
                "KW_L002.Unit",
                "*",
                VarType::BSTR,
                R,
                n.clone(),
                bstr("°C"),
            )),
        ),
        (
            "KW_A000.ControlVariable.CV",
            "",
            Ok(def(
                "KW_K001",
                "*",
                VarType::I2,
                R,
                analog(0.0, 32767.0),
                None,
            )),
        ),
        // Attributes that hold no number and no variable, or nothing.
        ("KW_A000.Unit.CV", "", Err(OpcError::UnknownItemId)),
        ("KW_A000.BarBase.CV", "", Err(OpcError::UnknownItemId)),
        ("KW_A000.NoSuchColumn", "", Err(OpcError::UnknownItemId)),
        ("KW_A000.NoSuchColumn.CV", "", Err(OpcError::UnknownItemId)),
        // Descriptive IDs, with and without a database.
        (
            "asmen.Camac.06C_A111AF00.R4",
            "",
            Ok(def(
                "asmen.Camac.06C_A111AF00.R4",
                "*",
                VarType::R4,
                RW,
                n.clone(),
                None,
            )),
        ),
        (
            "asmen.KWAS.KW_A000.ui2",
            "NEW1",
            Ok(def(
                "asmen.KWAS.KW_A000.UI2",
                "NEW1",
                VarType::UI2,
                RW,
                n.clone(),
                None,
            )),
        ),
        (
            "asmen.Camac.x.I4",
            "Demo_Wytwornia_Kwasu",
            Ok(def(
                "asmen.Camac.x.I4",
                "Demo_Wytwornia_Kwasu",
                VarType::I4,
                RW,
                n.clone(),
                None,
            )),
        ),
        // Errors.
        ("KW_A000", "NEW1", Err(OpcError::UnknownItemId)),
        ("KW_A000", "Camac", Err(OpcError::UnknownPath)),
        (
            "KW_A000",
            "demo_wytwornia_kwasu",
            Err(OpcError::UnknownPath),
        ),
        ("kw_a000", "", Err(OpcError::UnknownItemId)),
        ("KW_A999", "", Err(OpcError::UnknownItemId)),
        ("KW_A000.desc", "", Err(OpcError::UnknownItemId)),
        ("KW_A000.DESC.CV", "", Err(OpcError::InvalidItemId)),
        ("KW_A000.", "", Err(OpcError::InvalidItemId)),
        ("", "", Err(OpcError::InvalidItemId)),
        ("asmen.Camac.x.R8", "", Err(OpcError::InvalidItemId)),
        // Aliases: names replaced, alias-less variables hidden, indirect targets by asix name.
        (
            "LI101",
            "Wytwornia_Kwasu_Tagi",
            Ok(def(
                "KW_A000",
                "Wytwornia_Kwasu_Tagi",
                VarType::R4,
                R,
                analog(0.0, 8.0),
                None,
            )),
        ),
        (
            "LI101.DESC",
            "Wytwornia_Kwasu_Tagi",
            Ok(def(
                "KW_A000.DESC",
                "Wytwornia_Kwasu_Tagi",
                VarType::BSTR,
                R,
                n.clone(),
                bstr("Poziom siarki ciekłej w zbiorniku Z101"),
            )),
        ),
        (
            "TI201.AlarmHigh.CV.PercentageCV",
            "Wytwornia_Kwasu_Tagi",
            Ok(def(
                "KW_L002.PercentageCV",
                "Wytwornia_Kwasu_Tagi",
                VarType::R8,
                R,
                analog(0.0, 100.0),
                None,
            )),
        ),
        (
            "KW_A000",
            "Wytwornia_Kwasu_Tagi",
            Err(OpcError::UnknownItemId),
        ),
        (
            "KW_K001",
            "Wytwornia_Kwasu_Tagi",
            Err(OpcError::UnknownItemId),
        ),
        ("LI101", "", Err(OpcError::UnknownItemId)),
    ];
    for (id, path, expected) in rows {
        assert_eq!(ns.resolve(id, path), expected, "resolve({id:?}, {path:?})");
    }
}

#[test]
fn live_items_and_derivations() {
    let ns = example_namespace();
    let live = |id: &str, path: &str| {
        let d = ns.resolve(id, path).unwrap();
        assert!(d.constant.is_none(), "{id}");
        ns.live_item(&d.channel, &d.source_key)
            .unwrap_or_else(|| panic!("{id}"))
    };
    let v = live("KW_A000", "");
    assert_eq!(
        (v.variable.as_str(), v.asmen_channel.as_deref(), v.var_type),
        ("KW_A000", None, VarType::R4)
    );
    assert_eq!(v.derivation, Derivation::Value);
    assert_eq!(
        v.definition.as_ref().unwrap().control_variable.as_deref(),
        Some("KW_K001")
    );
    let rows: &[(&str, &str, Value, Option<Value>)] = &[
        ("KW_A000", "", Value::R4(2.5), Some(Value::R4(2.5))),
        (
            "KW_A000.FormatedCV",
            "",
            Value::R4(2.5),
            Some(Value::Bstr("2.50".into())),
        ),
        (
            "KW_A121.FormatedCV",
            "",
            Value::R4(12.0),
            Some(Value::Bstr("+12".into())),
        ),
        (
            "KW_D004.FormatedCV",
            "",
            Value::UI4(4_000_000_000),
            Some(Value::Bstr("4000000000".into())),
        ),
        (
            "KW_A000.PercentageCV",
            "",
            Value::R4(2.0),
            Some(Value::R8(25.0)),
        ),
        ("KW_A000.PercentageCV", "", Value::Bstr("x".into()), None),
        ("KW_A000.BarCVs", "", Value::R4(2.0), pair(25.0, 0.0)),
        ("KW_A104.BarCVs", "", Value::R4(10.0), pair(50.0, 25.0)),
        (
            "KW_A100.AlarmHigh.CV.PercentageCV",
            "",
            Value::R4(600.0),
            Some(Value::R8(50.0)),
        ),
        (
            "TI201.FormatedCV",
            "Wytwornia_Kwasu_Tagi",
            Value::R4(955.4),
            Some(Value::Bstr("955".into())),
        ),
    ];
    for (id, path, input, expected) in rows {
        assert_eq!(
            live(id, path).derivation.apply(input),
            *expected,
            "{id} of {input:?}"
        );
    }
    let d = live("asmen.Camac.06C_A111AF00.R4", "");
    assert_eq!(
        (
            d.variable.as_str(),
            d.asmen_channel.as_deref(),
            d.definition
        ),
        ("06C_A111AF00", Some("Camac"), None)
    );
    assert_eq!(live("TI201", "Wytwornia_Kwasu_Tagi").variable, "KW_A100");
    // Constants and unknown keys have no live item.
    assert!(ns.live_item("*", "KW_A000.DESC").is_none());
    assert!(ns.live_item("*", "KW_A999").is_none());
}

#[test]
fn item_attributes_for_properties() {
    let ns = example_namespace();
    let a = ns.item_attributes("KW_A001", "").unwrap();
    assert_eq!(
        a.description.as_deref(),
        Some("Temperatura siarki w zbiorniku Z101")
    );
    assert_eq!(
        a.description_en.as_deref(),
        Some("Sulphur temperature in tank Z101")
    );
    assert_eq!(a.eu_units.as_deref(), Some("°C"));
    assert_eq!(a.eu, analog(100.0, 180.0));
    let p = ns.item_attributes("KW_A001.PercentageCV", "").unwrap();
    assert_eq!(
        (p.eu_units.as_deref(), p.eu),
        (Some("%"), analog(0.0, 100.0))
    );
    let d = ns.item_attributes("KW_A001.DESC", "").unwrap();
    assert_eq!(
        (d.description.as_deref(), d.eu_units, d.eu),
        (
            Some("Temperatura siarki w zbiorniku Z101"),
            None,
            EuInfo::None
        )
    );
    let i = ns.item_attributes("KW_A100.AlarmHigh.CV", "").unwrap();
    assert_eq!(
        i.description.as_deref(),
        Some("Limit alarmowy temperatury pieca")
    );
    assert_eq!(
        ns.item_attributes("asmen.Camac.x.R4", "").unwrap(),
        Default::default()
    );
    assert_eq!(
        ns.item_attributes("KW_A999", ""),
        Err(OpcError::UnknownItemId)
    );
}

fn leaves(nodes: &[BrowseNode]) -> Vec<&BrowseNode> {
    nodes.iter().filter(|n| n.is_leaf).collect()
}

#[test]
fn browse_tree_of_channel_star() {
    let ns = example_namespace();
    let nodes: Vec<BrowseNode> = ns.browse_nodes().collect();
    let db = ns.database("*").unwrap();
    assert_eq!(leaves(&nodes).len(), db.variables.len());
    assert_eq!(
        nodes[0],
        BrowseNode {
            path: vec!["Magazyn siarki".into()],
            item_id: None,
            is_leaf: false
        }
    );
    let first_leaf = leaves(&nodes)[0];
    assert_eq!(
        first_leaf.path,
        ["Magazyn siarki", "Zbiornik siarki ciekłej Z101", "KW_A000"]
    );
    assert_eq!(first_leaf.item_id.as_deref(), Some("KW_A000"));
    // Pre-order: every node's parent path was listed before it as a branch.
    for (i, n) in nodes.iter().enumerate() {
        let parent = &n.path[..n.path.len() - 1];
        assert!(
            parent.is_empty() || nodes[..i].iter().any(|b| !b.is_leaf && b.path == parent),
            "{n:?}"
        );
    }
    // Every leaf's item ID resolves.
    for n in leaves(&nodes) {
        assert!(
            ns.resolve(n.item_id.as_deref().unwrap(), "").is_ok(),
            "{n:?}"
        );
    }

    // AttributesAsItems: variables become branches with five (or three) leaves.
    let mut config = example();
    config.server.attributes_as_items = true;
    let (ns, _) = AsixNamespace::load(config);
    let nodes: Vec<BrowseNode> = ns.browse_nodes().collect();
    let a000: Vec<&BrowseNode> = nodes
        .iter()
        .filter(|n| n.path.get(2).map(String::as_str) == Some("KW_A000"))
        .collect();
    let got: Vec<(Option<&str>, bool)> = a000
        .iter()
        .map(|n| (n.item_id.as_deref(), n.is_leaf))
        .collect();
    assert_eq!(
        got,
        [
            (Some("KW_A000"), false),
            (Some("KW_A000.CV"), true),
            (Some("KW_A000.DESC"), true),
            (Some("KW_A000.EU_UNIT"), true),
            (Some("KW_A000.HI_EU"), true),
            (Some("KW_A000.LO_EU"), true),
        ]
    );
    assert_eq!(leaves(&nodes).len(), 5 * db.variables.len());
    for n in leaves(&nodes) {
        assert!(
            ns.resolve(n.item_id.as_deref().unwrap(), "").is_ok(),
            "{n:?}"
        );
    }

    // Alias mode on channel *: aliases in the tree, alias-less variables left out.
    let mut config = example();
    config.channels.get_mut("*").unwrap().alias_attribute_name = Some("Alias".into());
    let (ns, _) = AsixNamespace::load(config);
    let nodes: Vec<BrowseNode> = ns.browse_nodes().collect();
    let db = ns.database("*").unwrap();
    assert_eq!(leaves(&nodes).len(), db.visible_count());
    assert_eq!(leaves(&nodes)[0].item_id.as_deref(), Some("LI101"));
    assert!(!nodes
        .iter()
        .any(|n| n.item_id.as_deref() == Some("KW_K001")));
    assert!(
        !nodes.iter().any(|n| n.path[0] == "Diagnostyka"),
        "groups of hidden variables are not browsed"
    );
}

#[test]
fn without_a_database_only_descriptive_ids_resolve() {
    let (config, _) = parse_config(b"", "ASIXConnect.ini").unwrap();
    let (ns, _) = AsixNamespace::load(config);
    assert!(matches!(
        ns.database_state("*"),
        ChannelDatabase::NotConfigured
    ));
    assert_eq!(
        ns.no_config_reason().as_deref(),
        Some("no ItemsDatabase is configured for channel *")
    );
    assert_eq!(ns.browse_nodes().count(), 0);
    assert!(ns.resolve("asmen.Camac.06C_A111AF00.R4", "").is_ok());
    assert_eq!(ns.resolve("KW_A000", ""), Err(OpcError::UnknownItemId));
    assert_eq!(ns.resolve("asmen.Camac", ""), Err(OpcError::InvalidItemId));
}

#[test]
fn missing_and_invalid_databases_are_typed_errors() {
    let dir = std::env::temp_dir().join(format!("ctopc-asix-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("zla.zez"), "Attributes = zla.csv\n[Grupa]\nA\n").unwrap();
    std::fs::write(dir.join("zla.csv"), "Name;RangeFrom\nA;0\nB;dużo\n").unwrap();
    std::fs::write(
        dir.join("bez_tabeli.zez"),
        "Attributes = brak.csv\n[Grupa]\nA\n",
    )
    .unwrap();
    let ini = format!(
        "[Channel:*]\nItemsDatabase = {}\n[Channel:Bad]\nItemsDatabase = zla.zez\n[Channel:NoTable]\nItemsDatabase = bez_tabeli.zez\n",
        dir.join("nie_ma.zez").display()
    );
    std::fs::write(dir.join("ASIXConnect.ini"), ini).unwrap();
    let (config, _) = load_config_file(&dir.join("ASIXConnect.ini")).unwrap();
    let (ns, _) = AsixNamespace::load(config);
    let err = |channel: &str| match ns.database_state(channel) {
        ChannelDatabase::Failed(e) => e.clone(),
        other => panic!("{channel}: {other:?}"),
    };
    let e = err("*");
    assert_eq!((e.code, e.line), (OpcError::VarBaseNotFound, 0));
    assert!(e.file.ends_with("nie_ma.zez"), "{e}");
    let e = err("Bad");
    assert_eq!((e.code, e.line), (OpcError::ErrorDuringOpeningVarBase, 3));
    assert!(
        e.file.ends_with("zla.csv") && e.message.contains("dużo"),
        "{e}"
    );
    assert!(e.to_string().contains("zla.csv:3: "), "{e}");
    let e = err("NoTable");
    assert_eq!(e.code, OpcError::VarBaseNotFound);
    assert!(e.file.ends_with("brak.csv"), "{e}");
    assert!(ns
        .no_config_reason()
        .unwrap()
        .contains("ASKOM_E_VarBaseNotFound"));
    // Descriptive IDs still work on every channel.
    for channel in ["*", "Bad", "NoTable"] {
        assert!(ns.resolve("asmen.KWAS.KW_A000.R4", channel).is_ok());
        assert_eq!(ns.resolve("KW_A000", channel), Err(OpcError::UnknownItemId));
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn quality_rules_on_demo_variables() {
    let db = demo_db(None);
    let both = RuleOptions {
        check_limits: true,
        check_control_variables: true,
    };
    let good = Quality::GOOD;
    let rows: &[(&str, Value, Option<Value>, u16)] = &[
        // KW_A000: level 0..8 m, warn 1/7, alarm 0.5/7.5, control KW_K001.
        ("KW_A000", Value::R4(4.0), Some(Value::I2(0)), 0xC0),
        ("KW_A000", Value::R4(7.2), Some(Value::I2(0)), 0xC2),
        ("KW_A000", Value::R4(7.6), Some(Value::I2(0)), 0x08C2),
        ("KW_A000", Value::R4(0.8), None, 0xC1),
        ("KW_A000", Value::R4(0.2), None, 0x08C1),
        ("KW_A000", Value::R4(4.0), Some(Value::I2(2)), 0x10),
        // KW_A217: conversion with only low limits.
        ("KW_A217", Value::R4(99.5), None, 0xC1),
        ("KW_A217", Value::R4(99.0), None, 0x08C1),
        ("KW_A217", Value::R4(100.0), None, 0xC0),
        ("KW_A217", Value::R4(99.6), None, 0xC0),
        ("KW_A217", Value::R8(99.6), None, 0xC0),
        ("KW_A217", Value::R8(99.59), None, 0xC1),
        // KW_A100: WarnHigh and AlarmHigh are indirect (KW_L001/KW_L002): only WarnLow/AlarmLow checked.
        ("KW_A100", Value::R4(1190.0), None, 0xC0),
        ("KW_A100", Value::R4(800.0), None, 0x08C1),
        // Control variables themselves have no control variable and no limits.
        ("KW_K001", Value::I2(5), Some(Value::I2(5)), 0xC0),
    ];
    for (name, value, control, expected) in rows {
        let var = db.find_real(name).unwrap();
        let q = apply_quality_rules(var, value, good, control.as_ref(), both);
        assert_eq!(
            q,
            Quality(*expected),
            "{name} = {value:?}, control {control:?}"
        );
    }
}

#[test]
fn value_items_carry_their_numeric_limits_for_the_limit_properties() {
    let ns = example_namespace();
    let limits = |id: &str| ns.resolve_with_attributes(id, "").map(|(_, a)| a.limits);
    // KW_A000: WarnLow 1, WarnHigh 7, AlarmLow 0.5, AlarmHigh 7.5.
    let a000 = LimitProps {
        hihi: Some(7.5),
        hi: Some(7.0),
        lo: Some(1.0),
        lolo: Some(0.5),
    };
    assert_eq!(limits("KW_A000"), Ok(a000));
    assert_eq!(limits("KW_A000.CV"), Ok(a000));
    // KW_A100: the high limits are held in variables (KW_L001, KW_L002): not properties.
    assert_eq!(
        limits("KW_A100"),
        Ok(LimitProps {
            hihi: None,
            hi: None,
            lo: Some(900.0),
            lolo: Some(850.0)
        })
    );
    // No limits: a binary signal; attribute and derived items never have them.
    assert_eq!(limits("KW_D000"), Ok(LimitProps::default()));
    assert_eq!(limits("KW_A000.DESC"), Ok(LimitProps::default()));
    assert_eq!(limits("KW_A000.PercentageCV"), Ok(LimitProps::default()));
    // The limit properties' item IDs (LookupItemIDs) are the numeric attributes as items.
    for (id, v) in [
        ("KW_A000.AlarmHigh.CV", 7.5),
        ("KW_A000.WarnHigh.CV", 7.0),
        ("KW_A000.WarnLow.CV", 1.0),
        ("KW_A000.AlarmLow.CV", 0.5),
    ] {
        let d = Namespace::resolve(&ns, id, "").unwrap();
        assert_eq!(d.constant, Some(Value::R8(v)), "{id}");
    }
}
