//! The node manager in process, over the runtime and the in-process simulation of the
//! demo plant: the lazy address space (browse tree, variable types, properties, access
//! levels), reads through the engine, the checks and results of writes, and monitored
//! items as engine items (one per variable, whichever items ask). Every wait is on a
//! condition, with a deadline.

use asix_model::{parse_config, AsixNamespace};
use asix_net::inproc::InProcessSim;
use ctopc_core::browse::MatchCase;
use ctopc_core::lang::Lang;
use ctopc_core::write_rights::Caller;
use ctopc_runtime::frontend::no_thread_state;
use ctopc_ua::engine::EngineClient;
use ctopc_ua::monitor::Notify;
use ctopc_ua::node_manager::{max_age_ms, write_values, AsixNodeManager, Roles, Setup};
use ctopc_ua::space::{Resolved, ROOT_ID};
use opcua::server::authenticator::UserToken;
use opcua::types::{
    AttributeId, DataValue, NodeClass, NodeId, NumericRange, ObjectId, ObjectTypeId, Range,
    ReferenceTypeId, StatusCode, UAString, VariableTypeId, Variant,
};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

const NS: u16 = 2;

/// Data changes as the subscription cache would get them.
#[derive(Default)]
struct Recorder(Mutex<Vec<(NodeId, DataValue)>>);

impl Notify for Recorder {
    fn data_changes(&self, changes: Vec<(NodeId, DataValue)>) {
        self.0.lock().unwrap().extend(changes);
    }
}

impl Recorder {
    fn count_for(&self, id: &NodeId) -> usize {
        self.0
            .lock()
            .unwrap()
            .iter()
            .filter(|(n, _)| n == id)
            .count()
    }
}

/// Writers are the users named `writer`.
struct ByName;

impl Roles for ByName {
    fn may_write(&self, token: &UserToken) -> bool {
        token.0 == "writer"
    }
}

struct Fixture {
    nm: AsixNodeManager,
    notes: Arc<Recorder>,
}

fn fixture() -> Fixture {
    fixture_with("")
}

/// The fixture with more of `ASIXConnect.ini` (sections after `[Channel:*]`).
fn fixture_with(more_ini: &str) -> Fixture {
    let db = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../demo/wytwornia_kwasu/wytwornia_kwasu.zez"
    );
    let ini = format!(
        "[Server]\nSimulateCurrentData = tak\n[Channel:*]\nItemsDatabase = {db}\n{more_ini}"
    );
    let (cfg, warnings) = parse_config(ini.as_bytes(), "ua.ini").unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    let engine_config = cfg.server.engine_config();
    let ops = cfg.ops_config();
    let ns = Arc::new(AsixNamespace::load(cfg).0);
    let tree = Arc::new(asix_model::address_space::build_address_space(&ns).unwrap());
    let for_source = Arc::clone(&ns);
    let started = ctopc_runtime::start(
        ns,
        MatchCase::Insensitive,
        engine_config,
        &ops,
        no_thread_state,
        Box::new(move |_wake| {
            let sim = InProcessSim::new(for_source, 7, ctopc_runtime::clock::now());
            Ok(Box::new(sim) as Box<dyn ctopc_core::source::Backend>)
        }),
    )
    .unwrap();
    let engine = Arc::new(EngineClient::open(Arc::clone(&started.runtime)));
    let notes = Arc::new(Recorder::default());
    let setup = Setup {
        namespace: started.namespace,
        tree,
        engine,
        roles: Arc::new(ByName),
        lang: Lang::English,
    };
    let nm = AsixNodeManager::new(setup, NS, Arc::clone(&notes) as Arc<dyn Notify>);
    Fixture { nm, notes }
}

fn item(id: &str) -> NodeId {
    NodeId::new(NS, UAString::from(id))
}

fn wait_until(what: &str, mut done: impl FnMut() -> bool) {
    let deadline = Instant::now() + Duration::from_secs(10);
    while !done() {
        assert!(Instant::now() < deadline, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(5));
    }
}

#[test]
fn the_browse_tree_is_folders_under_objects_and_servercctopc() {
    let f = fixture();
    let space = &f.nm.space;
    let root = space.resolve(&NodeId::new(NS, ROOT_ID)).unwrap();
    let refs = space.references(&root, Lang::English);
    assert!(refs.iter().any(|r| !r.forward
        && r.target.node_id == ObjectId::ObjectsFolder
        && r.reference_type == ReferenceTypeId::Organizes));
    let groups: Vec<_> = refs
        .iter()
        .filter(|r| r.forward && r.reference_type == ReferenceTypeId::Organizes)
        .collect();
    assert!(!groups.is_empty());
    assert!(groups
        .iter()
        .all(|r| r.target.node_class == NodeClass::Object
            && r.target.type_definition == ObjectTypeId::FolderType));
    let magazyn = groups
        .iter()
        .find(|r| r.target.display_name.text.as_ref() == "Magazyn siarki")
        .expect("the group Magazyn siarki");
    // Down to KW_A000 through the folders.
    let m = space.resolve(&magazyn.target.node_id).unwrap();
    assert!(matches!(m, Resolved::Folder(_)));
    let tank = space
        .references(&m, Lang::English)
        .into_iter()
        .find(|r| {
            r.forward && r.target.display_name.text.as_ref() == "Zbiornik siarki ciekłej Z101"
        })
        .expect("the tank folder");
    let tank = space.resolve(&tank.target.node_id).unwrap();
    let vars: Vec<_> = space
        .references(&tank, Lang::English)
        .into_iter()
        .filter(|r| r.forward && r.target.node_class == NodeClass::Variable)
        .map(|r| r.target.node_id)
        .collect();
    assert_eq!(
        vars,
        vec![item("KW_A000"), item("KW_A001"), item("KW_A002")]
    );
}

#[test]
fn a_variable_with_a_range_is_an_analog_item_with_its_properties() {
    let f = fixture();
    let space = &f.nm.space;
    let v = space.resolve(&item("KW_A000")).unwrap();
    let meta = space.meta(&v, Lang::English);
    assert_eq!(
        meta.type_definition,
        NodeId::from(VariableTypeId::AnalogItemType)
    );
    assert_eq!(meta.browse_name.name.as_ref(), "KW_A000");
    let refs = space.references(&v, Lang::English);
    let props: Vec<_> = refs
        .iter()
        .filter(|r| r.forward && r.reference_type == ReferenceTypeId::HasProperty)
        .map(|r| r.target.browse_name.name.as_ref().to_owned())
        .collect();
    for name in [
        "EURange",
        "EngineeringUnits",
        "ItemEUType",
        "HiHiLimit",
        "LoLoLimit",
    ] {
        assert!(props.iter().any(|p| p == name), "{name} in {props:?}");
    }
    let eu_range = refs
        .iter()
        .find(|r| r.target.browse_name.name.as_ref() == "EURange")
        .unwrap();
    let p = space.resolve(&eu_range.target.node_id).unwrap();
    let value = space
        .attribute(&p, AttributeId::Value, false, Lang::English)
        .unwrap();
    let Variant::ExtensionObject(obj) = value else {
        panic!("EURange is not a structure: {value:?}")
    };
    let range: &Range = obj.inner_as().expect("a Range");
    assert_eq!((range.low, range.high), (0.0, 8.0));
    let description = space
        .attribute(&v, AttributeId::Description, false, Lang::English)
        .unwrap();
    assert_eq!(
        description,
        Variant::from(opcua::types::LocalizedText::new(
            "en",
            "Liquid sulphur level in tank Z101"
        ))
    );
    let polish = space
        .attribute(&v, AttributeId::Description, false, Lang::Polish)
        .unwrap();
    assert_eq!(
        polish,
        Variant::from(opcua::types::LocalizedText::new(
            "pl",
            "Poziom siarki ciekłej w zbiorniku Z101"
        ))
    );
    // An item without EU information (the description attribute item) is a DataItemType.
    let d = space.resolve(&item("KW_A000.DESC")).unwrap();
    assert_eq!(
        space.meta(&d, Lang::English).type_definition,
        NodeId::from(VariableTypeId::DataItemType)
    );
}

#[test]
fn access_levels_follow_the_variable_and_the_user() {
    let f = fixture();
    let space = &f.nm.space;
    let read_only = space.resolve(&item("KW_A000")).unwrap();
    let writable = space.resolve(&item("KW_A110")).unwrap();
    let level =
        |r: &Resolved, a: AttributeId, w: bool| space.attribute(r, a, w, Lang::English).unwrap();
    assert_eq!(
        level(&read_only, AttributeId::AccessLevel, true),
        Variant::Byte(1)
    );
    assert_eq!(
        level(&writable, AttributeId::AccessLevel, false),
        Variant::Byte(3)
    );
    assert_eq!(
        level(&writable, AttributeId::UserAccessLevel, false),
        Variant::Byte(1)
    );
    assert_eq!(
        level(&writable, AttributeId::UserAccessLevel, true),
        Variant::Byte(3)
    );
}

#[test]
fn unknown_node_ids_are_bad_node_id_unknown() {
    let f = fixture();
    for id in [
        item("NO_SUCH_VARIABLE"),
        NodeId::new(NS, 77u32),
        NodeId::new(NS, opcua::types::ByteString::from(vec![1u8, 2])),
    ] {
        assert_eq!(
            f.nm.space.resolve(&id).err(),
            Some(StatusCode::BadNodeIdUnknown),
            "{id}"
        );
    }
    let v = f.nm.read_values(&["NO_SUCH_VARIABLE".into()], 0);
    assert_eq!(v[0].status, Some(StatusCode::BadNodeIdUnknown));
}

#[test]
fn a_device_read_gives_the_simulated_value_with_good_status() {
    let f = fixture();
    let v =
        f.nm.read_values(&["KW_A000".into(), "KW_A110".into()], max_age_ms(0.0));
    for dv in &v {
        assert_eq!(dv.status, Some(StatusCode::Good), "{dv:?}");
        assert!(matches!(dv.value, Some(Variant::Float(_))), "{dv:?}");
        assert!(dv.source_timestamp.is_some());
    }
    assert_eq!(max_age_ms(f64::MAX), u32::MAX);
    assert_eq!(max_age_ms(500.0), 500);
}

#[test]
fn writes_are_checked_then_converted_and_written_by_the_engine() {
    let f = fixture();
    let nm = &f.nm;
    let dv = DataValue::value_only(Variant::Double(12.5));
    let check = |id: &str, v: &DataValue, w: bool| {
        nm.check_write(&item(id), AttributeId::Value, &NumericRange::None, v, w)
    };
    assert_eq!(
        check("KW_A000", &dv, true).err(),
        Some(StatusCode::BadNotWritable)
    );
    assert_eq!(
        check("KW_A110", &dv, false).err(),
        Some(StatusCode::BadUserAccessDenied)
    );
    let bytes = DataValue::value_only(Variant::ByteString(vec![1u8].into()));
    assert_eq!(
        check("KW_A110", &bytes, true).err(),
        Some(StatusCode::BadTypeMismatch)
    );
    assert_eq!(
        nm.check_write(
            &item("KW_A110"),
            AttributeId::DisplayName,
            &NumericRange::None,
            &dv,
            true
        )
        .err(),
        Some(StatusCode::BadNotWritable)
    );
    // A text that is no number: the engine's conversion refuses it.
    let text = DataValue::value_only(Variant::from("dużo"));
    let w = check("KW_A110", &text, true).unwrap();
    let s = write_values(&nm.engine, &*nm.space.namespace, &[w], writer("writer"));
    assert_eq!(s, vec![StatusCode::BadTypeMismatch]);
    // A number is written and read back from the device.
    let w = check("KW_A110", &dv, true).unwrap();
    let s = write_values(&nm.engine, &*nm.space.namespace, &[w], writer("writer"));
    assert_eq!(s, vec![StatusCode::Good]);
    let back = nm.read_values(&["KW_A110".into()], 0);
    assert_eq!(back[0].value, Some(Variant::Float(12.5)));
}

fn writer(user: &str) -> Caller {
    Caller::Ua {
        user: user.into(),
        roles: vec!["writer".into()],
    }
}

#[test]
fn the_write_rights_policy_decides_ua_writes_by_user_and_role() {
    let f = fixture_with("[WriteRights]\n* = ua:alice, role:operator\n");
    let nm = &f.nm;
    let dv = DataValue::value_only(Variant::Float(7.5));
    let w = nm
        .check_write(
            &item("KW_A110"),
            AttributeId::Value,
            &NumericRange::None,
            &dv,
            true,
        )
        .unwrap();
    let write = |caller: Caller| {
        write_values(
            &nm.engine,
            &*nm.space.namespace,
            std::slice::from_ref(&w),
            caller,
        )
    };
    // A writer role the policy does not name is refused, as a user matter.
    assert_eq!(write(writer("bob")), vec![StatusCode::BadUserAccessDenied]);
    // The policy's user, and a user with the policy's role, may write.
    assert_eq!(write(writer("alice")), vec![StatusCode::Good]);
    let operator = Caller::Ua {
        user: "carol".into(),
        roles: vec!["operator".into()],
    };
    assert_eq!(write(operator), vec![StatusCode::Good]);
    let back = nm.read_values(&["KW_A110".into()], 0);
    assert_eq!(back[0].value, Some(Variant::Float(7.5)));
}

#[test]
fn monitored_items_share_one_engine_item_per_variable_and_deliver_changes() {
    let f = fixture();
    let m = &f.nm.monitor;
    let rate = m.revise(100.0);
    assert_eq!(rate, 1000, "the engine's minimum update rate");
    m.add("KW_A001", rate).unwrap();
    m.add("KW_A001", m.revise(5000.0)).unwrap();
    m.add("KW_A002", rate).unwrap();
    let stats = || f.nm.engine.runtime.lock().engine.stats();
    assert_eq!(stats().group_items, 2, "one engine item per variable");
    assert_eq!(m.variables(), 2);
    wait_until("data changes of both variables", || {
        f.notes.count_for(&item("KW_A001")) >= 1 && f.notes.count_for(&item("KW_A002")) >= 1
    });
    let first = f.notes.0.lock().unwrap()[0].1.clone();
    assert_eq!(first.status, Some(StatusCode::Good));
    // The fast item goes: the variable moves to the 5 s group, still one engine item.
    m.remove("KW_A001", rate);
    assert_eq!(stats().group_items, 2);
    m.remove("KW_A001", 5000);
    m.remove("KW_A002", rate);
    assert_eq!(stats().group_items, 0);
    assert_eq!(m.variables(), 0);
    assert!(m.add("NO_SUCH_VARIABLE", rate).is_err());
    assert_eq!(m.variables(), 0);
}

/// Monitored items created (and deleted) in one request go to the engine together, with
/// the results of one by one: one engine item per variable (a variable twice in the
/// request, at two rates, is placed once), an unknown item refused alone, the others
/// delivering changes.
#[test]
fn monitored_items_created_together_are_placed_as_one_by_one() {
    let f = fixture();
    let m = &f.nm.monitor;
    let (fast, slow) = (m.revise(100.0), m.revise(5000.0));
    let r = m.add_many(&[
        ("KW_A001", slow),
        ("KW_A002", fast),
        ("NO_SUCH_VARIABLE", fast),
        ("KW_A001", fast),
    ]);
    assert!(r[0].is_ok() && r[1].is_ok() && r[3].is_ok(), "{r:?}");
    assert!(r[2].is_err());
    let stats = || f.nm.engine.runtime.lock().engine.stats();
    assert_eq!(stats().group_items, 2, "one engine item per variable");
    assert_eq!(m.variables(), 2);
    wait_until("data changes of both variables", || {
        f.notes.count_for(&item("KW_A001")) >= 1 && f.notes.count_for(&item("KW_A002")) >= 1
    });
    // Deleted together: the fast item of KW_A001 goes, it moves to the slow group, still
    // one engine item; an item never made changes nothing.
    m.remove_many(&[("KW_A001", fast), ("NO_SUCH_VARIABLE", fast)]);
    assert_eq!(stats().group_items, 2);
    assert_eq!(m.variables(), 2);
    m.remove_many(&[("KW_A001", slow), ("KW_A002", fast)]);
    assert_eq!(stats().group_items, 0);
    assert_eq!(m.variables(), 0);
    assert!(m.add_many(&[]).is_empty());
    m.remove_many(&[]);
}

#[test]
fn a_ua_monitored_item_and_a_da_group_share_one_source_subscription() {
    use ctopc_core::model::{GroupParams, ItemDefinition};
    use ctopc_core::VarType;
    let f = fixture();
    let rt = &f.nm.engine.runtime;
    // A DA client's group with the variable.
    let da = rt.open_session();
    let params = GroupParams {
        name: "DA",
        active: true,
        update_rate: 1000,
        ..GroupParams::default()
    };
    let g = rt
        .with_engine(|e, now| e.add_group(now, da, &params))
        .unwrap()
        .group;
    let def = ItemDefinition {
        item_id: "KW_A001",
        access_path: "",
        active: true,
        client_handle: 1,
        requested_type: VarType::EMPTY,
    };
    rt.with_engine(|e, now| e.add_items(now, g, std::slice::from_ref(&def)))
        .unwrap()
        .into_iter()
        .for_each(|r| assert!(r.is_ok()));
    let subscribed = || rt.lock().engine.stats().subscribed_items;
    assert_eq!(subscribed(), 1);
    // The UA client monitors it too: still one source subscription.
    f.nm.monitor.add("KW_A001", 1000).unwrap();
    assert_eq!(rt.lock().engine.stats().group_items, 2);
    assert_eq!(subscribed(), 1);
    f.nm.monitor.remove("KW_A001", 1000);
    assert_eq!(subscribed(), 1, "the DA group still subscribes it");
    rt.close_session(da);
}

/// The forward references of a node, as (reference type, browse name, NodeId).
fn forward(space: &ctopc_ua::space::Space, r: &Resolved) -> Vec<(NodeId, String, NodeId)> {
    space
        .references(r, Lang::English)
        .into_iter()
        .filter(|r| r.forward && r.reference_type != ReferenceTypeId::HasTypeDefinition)
        .map(|r| {
            (
                r.reference_type,
                r.target.browse_name.name.as_ref().to_owned(),
                r.target.node_id,
            )
        })
        .collect()
}

#[test]
fn the_derived_values_are_components_of_the_variable_named_by_their_item_ids() {
    let f = fixture();
    let space = &f.nm.space;
    let v = space.resolve(&item("KW_A000")).unwrap();
    let components: Vec<(String, NodeId)> = forward(space, &v)
        .into_iter()
        .filter(|(t, _, _)| *t == ReferenceTypeId::HasComponent)
        .map(|(_, name, id)| (name, id))
        .collect();
    for suffix in ["FormatedCV", "PercentageCV", "BarCVs"] {
        let id = item(&format!("KW_A000.{suffix}"));
        assert!(
            components.contains(&(suffix.to_owned(), id.clone())),
            "{suffix} in {components:?}"
        );
        // The child names its parent, and is a variable under its suffix.
        let child = space.resolve(&id).unwrap();
        let meta = space.meta(&child, Lang::English);
        assert_eq!(meta.browse_name.name.as_ref(), suffix);
        assert_eq!(meta.node_class, NodeClass::Variable);
        let up: Vec<_> = space
            .references(&child, Lang::English)
            .into_iter()
            .filter(|r| !r.forward && r.reference_type == ReferenceTypeId::HasComponent)
            .map(|r| r.target.node_id)
            .collect();
        assert_eq!(up, vec![item("KW_A000")], "{suffix}");
        // A derived item has no derived items of its own.
        assert!(
            forward(space, &child)
                .iter()
                .all(|(t, _, _)| *t != ReferenceTypeId::HasComponent),
            "{suffix}"
        );
    }
    let percent = space.resolve(&item("KW_A000.PercentageCV")).unwrap();
    assert_eq!(
        space.meta(&percent, Lang::English).type_definition,
        NodeId::from(VariableTypeId::AnalogItemType)
    );
    // Only those that resolve: a variable without a range has a FormatedCV and no
    // PercentageCV.
    let names = |id: &str| -> Vec<String> {
        let r = space.resolve(&item(id)).unwrap();
        forward(space, &r)
            .into_iter()
            .filter(|(t, _, _)| *t == ReferenceTypeId::HasComponent)
            .map(|(_, n, _)| n)
            .collect()
    };
    let all = names("KW_A000");
    assert!(all
        .iter()
        .all(|n| ctopc_ua::space::DERIVED.contains(&n.as_str())));
    // Constant items (attributes) have none.
    assert!(names("KW_A000.DESC").is_empty());
}

#[test]
fn the_derived_values_are_read_and_monitored_like_variables() {
    let f = fixture();
    let v = f.nm.read_values(
        &[
            "KW_A000".into(),
            "KW_A000.FormatedCV".into(),
            "KW_A000.PercentageCV".into(),
            "KW_A000.BarCVs".into(),
        ],
        max_age_ms(0.0),
    );
    for dv in &v {
        assert_eq!(dv.status, Some(StatusCode::Good), "{dv:?}");
    }
    let Some(Variant::Float(level)) = v[0].value else {
        panic!("{:?}", v[0])
    };
    assert!(
        matches!(&v[1].value, Some(Variant::String(s)) if !s.is_empty()),
        "{:?}",
        v[1]
    );
    // KW_A000's range is [0, 8]: the percentage of the value read at the same time.
    let Some(Variant::Double(p)) = v[2].value else {
        panic!("{:?}", v[2])
    };
    assert!(
        (p - f64::from(level) / 8.0 * 100.0).abs() < 1e-3,
        "{p} for {level}"
    );
    assert!(matches!(v[3].value, Some(Variant::Array(_))), "{:?}", v[3]);
    let m = &f.nm.monitor;
    let rate = m.revise(1000.0);
    m.add("KW_A000.PercentageCV", rate).unwrap();
    wait_until("a data change of KW_A000.PercentageCV", || {
        f.notes.count_for(&item("KW_A000.PercentageCV")) >= 1
    });
    m.remove("KW_A000.PercentageCV", rate);
}

#[test]
fn diagnostics_is_a_folder_of_readable_variables_first_under_the_root() {
    let f = fixture();
    let space = &f.nm.space;
    let root = space.resolve(&NodeId::new(NS, ROOT_ID)).unwrap();
    let organized: Vec<_> = forward(space, &root)
        .into_iter()
        .filter(|(t, _, _)| *t == ReferenceTypeId::Organizes)
        .collect();
    assert_eq!(organized[0].1, "_Diagnostics");
    assert_eq!(organized[0].2, item("_Diagnostics"));
    assert!(organized.len() > 1, "the real branches follow");
    let diag = space.resolve(&item("_Diagnostics")).unwrap();
    assert!(matches!(diag, Resolved::Folder(_)));
    let meta = space.meta(&diag, Lang::English);
    assert_eq!(meta.type_definition, NodeId::from(ObjectTypeId::FolderType));
    let up: Vec<_> = space
        .references(&diag, Lang::English)
        .into_iter()
        .filter(|r| !r.forward && r.reference_type == ReferenceTypeId::Organizes)
        .map(|r| r.target.node_id)
        .collect();
    assert_eq!(up, vec![NodeId::new(NS, ROOT_ID)]);
    let sections: Vec<String> = forward(space, &diag)
        .into_iter()
        .map(|(_, n, _)| n)
        .collect();
    assert_eq!(sections, ["Server", "Clients", "Channels"]);
    let server = space.resolve(&item("_Diagnostics.Server")).unwrap();
    let fields: Vec<_> = forward(space, &server);
    let uptime = fields
        .iter()
        .find(|(_, n, _)| n == "Uptime")
        .expect("_Diagnostics.Server.Uptime");
    assert_eq!(uptime.2, item("_Diagnostics.Server.Uptime"));
    let u = space.resolve(&uptime.2).unwrap();
    assert!(matches!(u, Resolved::Variable(_)));
    assert_eq!(
        space.meta(&u, Lang::English).node_class,
        NodeClass::Variable
    );
    assert_eq!(
        space
            .attribute(&u, AttributeId::Description, false, Lang::Polish)
            .unwrap(),
        Variant::from(opcua::types::LocalizedText::new(
            "pl",
            "Czas pracy serwera od startu"
        ))
    );
    assert_eq!(
        space
            .attribute(&u, AttributeId::Description, false, Lang::English)
            .unwrap(),
        Variant::from(opcua::types::LocalizedText::new(
            "en",
            "Time since the server started"
        ))
    );
    // Read and monitored as in DA: the value of the current snapshot.
    wait_until("a Good read of _Diagnostics.Server.Clients", || {
        let v = f.nm.read_values(&["_Diagnostics.Server.Clients".into()], 0);
        v[0].status == Some(StatusCode::Good) && matches!(v[0].value, Some(Variant::Int32(_)))
    });
    let m = &f.nm.monitor;
    let rate = m.revise(1000.0);
    m.add("_Diagnostics.Server.Uptime", rate).unwrap();
    wait_until("a data change of _Diagnostics.Server.Uptime", || {
        f.notes.count_for(&item("_Diagnostics.Server.Uptime")) >= 1
    });
    m.remove("_Diagnostics.Server.Uptime", rate);
    // The channels' branch lists the basic channel.
    let channels = space.resolve(&item("_Diagnostics.Channels")).unwrap();
    assert!(!forward(space, &channels).is_empty());
    assert_eq!(
        space.resolve(&item("_Diagnostics.NoSuchSection")).err(),
        Some(StatusCode::BadNodeIdUnknown)
    );
}

/// The text of a LocalizedText attribute, with its locale.
fn text(
    space: &ctopc_ua::space::Space,
    r: &Resolved,
    a: AttributeId,
    lang: Lang,
) -> (String, String) {
    match space.attribute(r, a, false, lang).unwrap() {
        Variant::LocalizedText(t) => (t.locale.as_ref().to_owned(), t.text.as_ref().to_owned()),
        other => panic!("{a:?} is not a LocalizedText: {other:?}"),
    }
}

#[test]
fn descriptions_and_property_names_are_in_the_language_asked_with_its_locale() {
    let f = fixture();
    let space = &f.nm.space;
    let d = AttributeId::Description;
    // (node, language, expected (locale, text) of its Description)
    let v = space.resolve(&item("KW_A000")).unwrap();
    let formatted = space.resolve(&item("KW_A000.FormatedCV")).unwrap();
    let root = space.resolve(&NodeId::new(NS, ROOT_ID)).unwrap();
    let diag = space.resolve(&item("_Diagnostics")).unwrap();
    let server = space.resolve(&item("_Diagnostics.Server")).unwrap();
    let channels = space.resolve(&item("_Diagnostics.Channels")).unwrap();
    let table: &[(&Resolved, Lang, (&str, &str))] = &[
        (
            &v,
            Lang::Polish,
            ("pl", "Poziom siarki ciekłej w zbiorniku Z101"),
        ),
        (
            &v,
            Lang::English,
            ("en", "Liquid sulphur level in tank Z101"),
        ),
        // A derived value has its variable's description.
        (
            &formatted,
            Lang::Polish,
            ("pl", "Poziom siarki ciekłej w zbiorniku Z101"),
        ),
        (
            &formatted,
            Lang::English,
            ("en", "Liquid sulphur level in tank Z101"),
        ),
        (
            &root,
            Lang::Polish,
            ("pl", ctopc_ua::space::ROOT_DESCRIPTION[0]),
        ),
        (
            &root,
            Lang::English,
            ("en", ctopc_ua::space::ROOT_DESCRIPTION[1]),
        ),
        (
            &diag,
            Lang::Polish,
            (
                "pl",
                "Diagnostyka serwera: serwer, podłączeni klienci, kanały",
            ),
        ),
        (
            &diag,
            Lang::English,
            (
                "en",
                "Server diagnostics: the server, the connected clients, the channels",
            ),
        ),
        (&server, Lang::Polish, ("pl", "Liczniki serwera")),
        (&server, Lang::English, ("en", "The server's counters")),
        (
            &channels,
            Lang::English,
            ("en", "The data source's channels, one branch per channel"),
        ),
    ];
    for (r, lang, (locale, expected)) in table {
        assert_eq!(
            text(space, r, d, *lang),
            (locale.to_string(), expected.to_string()),
            "{r:?} in {lang:?}"
        );
    }
    // A branch of the variable set has no description in either language.
    let groups: Vec<_> = forward(space, &root)
        .into_iter()
        .filter(|(_, n, _)| n != "_Diagnostics")
        .collect();
    let group = space.resolve(&groups[0].2).unwrap();
    assert!(matches!(group, Resolved::Folder(_)));
    for lang in Lang::ALL {
        assert_eq!(
            space.attribute(&group, d, false, lang).unwrap(),
            Variant::from(opcua::types::LocalizedText::null())
        );
    }
    // The properties: DisplayName and Description are the DA property's description in
    // the language asked (the BrowseName stays); EURange keeps its name.
    let props = |lang: Lang| -> Vec<(String, String, String)> {
        space
            .references(&v, lang)
            .into_iter()
            .filter(|r| r.forward && r.reference_type == ReferenceTypeId::HasProperty)
            .map(|r| {
                (
                    r.target.browse_name.name.as_ref().to_owned(),
                    r.target.display_name.locale.as_ref().to_owned(),
                    r.target.display_name.text.as_ref().to_owned(),
                )
            })
            .collect()
    };
    let (pl, en) = (props(Lang::Polish), props(Lang::English));
    let eu_type_pl = pl.iter().find(|p| p.0 == "ItemEUType").unwrap();
    let eu_type_en = en.iter().find(|p| p.0 == "ItemEUType").unwrap();
    assert_eq!(
        (eu_type_pl.1.as_str(), eu_type_pl.2.as_str()),
        ("pl", "Typ jednostek inżynierskich elementu")
    );
    assert_eq!(
        (eu_type_en.1.as_str(), eu_type_en.2.as_str()),
        ("en", "Item EU Type")
    );
    for list in [&pl, &en] {
        let eu_range = list.iter().find(|p| p.0 == "EURange").unwrap();
        assert_eq!((eu_range.1.as_str(), eu_range.2.as_str()), ("", "EURange"));
    }
    let eu_type = space
        .resolve(&space.property_node_id(ctopc_core::properties::OPC_PROPERTY_EU_TYPE, "KW_A000"))
        .unwrap();
    assert_eq!(
        text(space, &eu_type, d, Lang::Polish),
        ("pl".into(), "Typ jednostek inżynierskich elementu".into())
    );
    assert_eq!(
        text(space, &eu_type, AttributeId::DisplayName, Lang::English),
        ("en".into(), "Item EU Type".into())
    );
    // A variable's DisplayName is its name, the same in both languages.
    for lang in Lang::ALL {
        assert_eq!(
            text(space, &v, AttributeId::DisplayName, lang),
            (String::new(), "KW_A000".into())
        );
    }
}
