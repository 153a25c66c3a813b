//! Server model: groups (IOPCServer, IOPCGroupStateMgt/2) and items (IOPCItemMgt,
//! IOPCItemDeadbandMgt, IOPCItemSamplingMgt).

mod model_util;

use ctopc_core::model::*;
use ctopc_core::namespace::{EuInfo, OPC_READABLE, OPC_WRITEABLE};
use ctopc_core::{OpcError, VarType};
use model_util::*;

fn def(id: &str) -> ItemDefinition<'_> {
    ItemDefinition {
        item_id: id,
        access_path: "",
        active: true,
        client_handle: 1,
        requested_type: VarType::EMPTY,
    }
}

#[test]
fn update_rate_below_minimum_is_revised_with_unsupportedrate() {
    let mut sim = Sim::new();
    let s = sim.session();
    let r = sim
        .e
        .add_group(
            sim.now,
            s,
            &GroupParams {
                name: "fast",
                update_rate: 100,
                ..Default::default()
            },
        )
        .unwrap();
    assert_eq!(
        r.update_rate,
        Revised {
            value: 1000,
            revised: true
        }
    );
    assert_eq!(r.update_rate.code(), Some(OpcError::UnsupportedRate));
    let r0 = sim
        .e
        .add_group(
            sim.now,
            s,
            &GroupParams {
                name: "zero",
                update_rate: 0,
                ..Default::default()
            },
        )
        .unwrap();
    assert_eq!(
        r0.update_rate,
        Revised {
            value: 1000,
            revised: true
        }
    );
    let ok = sim
        .e
        .add_group(
            sim.now,
            s,
            &GroupParams {
                name: "slow",
                update_rate: 2500,
                ..Default::default()
            },
        )
        .unwrap();
    assert_eq!(
        ok.update_rate,
        Revised {
            value: 2500,
            revised: false
        }
    );
    assert_eq!(ok.update_rate.code(), None);
    // SetState revises the same way and reports the current rate when none is requested.
    let rev = sim
        .e
        .set_group_state(
            sim.now,
            ok.group,
            &SetGroupState {
                update_rate: Some(10),
                ..Default::default()
            },
        )
        .unwrap();
    assert_eq!(
        rev,
        Revised {
            value: 1000,
            revised: true
        }
    );
    let cur = sim
        .e
        .set_group_state(sim.now, ok.group, &SetGroupState::default())
        .unwrap();
    assert_eq!(
        cur,
        Revised {
            value: 1000,
            revised: false
        }
    );
    assert_eq!(sim.e.group_state(ok.group).unwrap().update_rate, 1000);
}

#[test]
fn configured_minimum_update_rate_applies() {
    let mut sim = Sim::with_config(EngineConfig {
        min_update_rate_ms: 250,
        ..Default::default()
    });
    let s = sim.session();
    let r = sim
        .e
        .add_group(
            sim.now,
            s,
            &GroupParams {
                update_rate: 100,
                ..Default::default()
            },
        )
        .unwrap();
    assert_eq!(
        r.update_rate,
        Revised {
            value: 250,
            revised: true
        }
    );
}

#[test]
fn group_names_are_unique_per_session_and_case_sensitive() {
    let mut sim = Sim::new();
    let s1 = sim.session();
    let s2 = sim.session();
    let p = |name| GroupParams {
        name,
        ..Default::default()
    };
    let g = sim.e.add_group(sim.now, s1, &p("Pumps")).unwrap().group;
    assert_eq!(
        sim.e.add_group(sim.now, s1, &p("Pumps")),
        Err(OpcError::DuplicateName)
    );
    let g_lower = sim.e.add_group(sim.now, s1, &p("pumps")).unwrap().group;
    let g_other = sim.e.add_group(sim.now, s2, &p("Pumps")).unwrap().group;
    assert!(
        g != g_lower && g != g_other && g_lower != g_other,
        "server handles are unique"
    );
    assert_eq!(sim.e.group_by_name(s1, "Pumps"), Ok(g));
    assert_eq!(sim.e.group_by_name(s1, "pumps"), Ok(g_lower));
    assert_eq!(sim.e.group_by_name(s2, "Pumps"), Ok(g_other));
    assert_eq!(sim.e.group_by_name(s1, "PUMPS"), Err(OpcError::InvalidArg));
}

#[test]
fn empty_group_name_generates_a_unique_name() {
    let mut sim = Sim::new();
    let s = sim.session();
    // Occupy the first generated name.
    sim.e
        .add_group(
            sim.now,
            s,
            &GroupParams {
                name: "Group1",
                ..Default::default()
            },
        )
        .unwrap();
    let a = sim
        .e
        .add_group(sim.now, s, &GroupParams::default())
        .unwrap()
        .group;
    let b = sim
        .e
        .add_group(sim.now, s, &GroupParams::default())
        .unwrap()
        .group;
    let na = sim.e.group_state(a).unwrap().name;
    let nb = sim.e.group_state(b).unwrap().name;
    assert!(!na.is_empty() && !nb.is_empty());
    assert_ne!(na, "Group1");
    assert_ne!(na, nb);
    let names: Vec<String> = sim
        .e
        .groups(s)
        .unwrap()
        .into_iter()
        .map(|(_, n)| n)
        .collect();
    assert_eq!(names, vec!["Group1".to_string(), na, nb]);
}

#[test]
fn percent_deadband_outside_0_to_100_is_invalidarg() {
    let mut sim = Sim::new();
    let s = sim.session();
    for bad in [-0.1f32, 100.5, f32::NAN] {
        let r = sim.e.add_group(
            sim.now,
            s,
            &GroupParams {
                name: "g",
                percent_deadband: bad,
                ..Default::default()
            },
        );
        assert_eq!(r, Err(OpcError::InvalidArg), "{bad}");
    }
    let g = sim
        .e
        .add_group(
            sim.now,
            s,
            &GroupParams {
                name: "g",
                percent_deadband: 100.0,
                ..Default::default()
            },
        )
        .unwrap()
        .group;
    let before = sim.e.group_state(g).unwrap();
    let r = sim.e.set_group_state(
        sim.now,
        g,
        &SetGroupState {
            percent_deadband: Some(101.0),
            update_rate: Some(5000),
            ..Default::default()
        },
    );
    assert_eq!(r, Err(OpcError::InvalidArg));
    assert_eq!(
        sim.e.group_state(g).unwrap(),
        before,
        "nothing changes on E_INVALIDARG"
    );
}

#[test]
fn get_state_reports_what_set_state_set() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim
        .e
        .add_group(
            sim.now,
            s,
            &GroupParams {
                name: "g",
                active: false,
                update_rate: 2000,
                client_handle: 5,
                time_bias: -60,
                percent_deadband: 2.5,
                lcid: 0x0415,
            },
        )
        .unwrap()
        .group;
    let st = sim.e.group_state(g).unwrap();
    assert_eq!(
        st,
        GroupState {
            name: "g".into(),
            active: false,
            update_rate: 2000,
            time_bias: -60,
            percent_deadband: 2.5,
            lcid: 0x0415,
            client_handle: 5,
            server_handle: g,
            keep_alive: 0
        }
    );
    sim.e
        .set_group_state(
            sim.now,
            g,
            &SetGroupState {
                update_rate: Some(3000),
                active: Some(true),
                time_bias: Some(120),
                percent_deadband: Some(0.0),
                lcid: Some(0x0409),
                client_handle: Some(9),
            },
        )
        .unwrap();
    let st = sim.e.group_state(g).unwrap();
    assert_eq!(
        (
            st.update_rate,
            st.active,
            st.time_bias,
            st.percent_deadband,
            st.lcid,
            st.client_handle
        ),
        (3000, true, 120, 0.0, 0x0409, 9)
    );
}

#[test]
fn set_name_rejects_duplicates_and_frees_the_old_name() {
    let mut sim = Sim::new();
    let s = sim.session();
    let a = sim
        .e
        .add_group(
            sim.now,
            s,
            &GroupParams {
                name: "a",
                ..Default::default()
            },
        )
        .unwrap()
        .group;
    sim.e
        .add_group(
            sim.now,
            s,
            &GroupParams {
                name: "b",
                ..Default::default()
            },
        )
        .unwrap();
    assert_eq!(sim.e.set_group_name(a, "b"), Err(OpcError::DuplicateName));
    assert_eq!(sim.e.set_group_name(a, ""), Err(OpcError::InvalidArg));
    assert_eq!(
        sim.e.set_group_name(a, "a"),
        Ok(()),
        "renaming to its own name is fine"
    );
    sim.e.set_group_name(a, "c").unwrap();
    assert_eq!(sim.e.group_by_name(s, "c"), Ok(a));
    assert_eq!(sim.e.group_by_name(s, "a"), Err(OpcError::InvalidArg));
    sim.e
        .add_group(
            sim.now,
            s,
            &GroupParams {
                name: "a",
                ..Default::default()
            },
        )
        .unwrap();
}

#[test]
fn clone_group_is_inactive_with_new_handles_and_same_items() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "orig", 2000, 5.0);
    let h = sim.items(g, &["A1", "D1"]);
    sim.e.set_item_deadband(g, &[(h[0], 7.5)]).unwrap();
    sim.e.set_item_sampling_rate(g, &[(h[1], 3000)]).unwrap();
    sim.e.set_datatypes(g, &[(h[0], VarType::I4)]).unwrap();
    assert_eq!(
        sim.e.clone_group(sim.now, g, "orig"),
        Err(OpcError::DuplicateName)
    );
    let c = sim.e.clone_group(sim.now, g, "copy").unwrap();
    assert_ne!(c, g);
    let st = sim.e.group_state(c).unwrap();
    assert!(!st.active, "a clone starts inactive");
    assert_eq!(
        (
            st.name.as_str(),
            st.update_rate,
            st.percent_deadband,
            st.client_handle
        ),
        ("copy", 2000, 5.0, 7)
    );
    let orig = sim.e.item_attributes(g).unwrap();
    let copy = sim.e.item_attributes(c).unwrap();
    assert_eq!(orig.len(), copy.len());
    for (o, c) in orig.iter().zip(&copy) {
        assert_ne!(o.server_handle, c.server_handle, "new item server handles");
        assert_eq!(
            (
                o.item_id.as_str(),
                o.client_handle,
                o.requested_type,
                o.active
            ),
            (
                c.item_id.as_str(),
                c.client_handle,
                c.requested_type,
                c.active
            )
        );
    }
    assert_eq!(
        sim.e
            .get_item_deadband(c, &[copy[0].server_handle])
            .unwrap(),
        vec![Ok(7.5)]
    );
    assert_eq!(
        sim.e
            .get_item_sampling_rate(c, &[copy[1].server_handle])
            .unwrap(),
        vec![Ok(3000)]
    );
    // An empty name generates one.
    let c2 = sim.e.clone_group(sim.now, g, "").unwrap();
    assert!(!sim.e.group_state(c2).unwrap().name.is_empty());
}

#[test]
fn remove_group_in_use_returns_inuse_and_frees_on_release() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    sim.items(g, &["A1"]);
    assert_eq!(sim.subscribed.len(), 1);
    sim.e.group_add_ref(g).unwrap();
    assert_eq!(
        sim.e.remove_group(sim.now, s, g, false),
        Ok(RemoveGroupOutcome::InUse)
    );
    sim.pump();
    assert!(
        sim.subscribed.is_empty(),
        "a group marked deleted no longer subscribes"
    );
    // Marked deleted: its name is free, calls on it fail, it is not enumerated.
    assert_eq!(sim.e.group_state(g).map(|_| ()), Err(OpcError::Fail));
    assert_eq!(sim.e.group_by_name(s, "g"), Err(OpcError::InvalidArg));
    assert!(sim.e.groups(s).unwrap().is_empty());
    let g2 = sim.group(s, "g", 1000, 0.0);
    assert_ne!(g2, g);
    assert_eq!(
        sim.e.remove_group(sim.now, s, g, false),
        Err(OpcError::InvalidArg),
        "already removed"
    );
    assert_eq!(sim.e.group_release(sim.now, g), Ok(0));
    assert_eq!(
        sim.e.group_release(sim.now, g),
        Err(OpcError::Fail),
        "handle released with the last reference"
    );
}

#[test]
fn remove_group_with_force_removes_despite_references() {
    let mut sim = Sim::new();
    let s = sim.session();
    let other = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    sim.e.group_add_ref(g).unwrap();
    assert_eq!(
        sim.e.remove_group(sim.now, other, g, true),
        Err(OpcError::InvalidArg),
        "not this session's group"
    );
    assert_eq!(
        sim.e.remove_group(sim.now, s, g, true),
        Ok(RemoveGroupOutcome::Removed)
    );
    assert_eq!(
        sim.e.add_items(sim.now, g, &[def("A1")]).map(|_| ()),
        Err(OpcError::Fail)
    );
    assert_eq!(
        sim.e.remove_group(sim.now, s, GroupHandle(12345), false),
        Err(OpcError::InvalidArg)
    );
    // Without references a plain remove is S_OK.
    let g2 = sim.group(s, "g2", 1000, 0.0);
    assert_eq!(
        sim.e.remove_group(sim.now, s, g2, false),
        Ok(RemoveGroupOutcome::Removed)
    );
}

#[test]
fn close_session_removes_its_groups_and_subscriptions() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    sim.items(g, &["A1", "A2"]);
    assert_eq!(sim.subscribed.len(), 2);
    sim.e.close_session(sim.now, s).unwrap();
    sim.pump();
    assert!(sim.subscribed.is_empty());
    assert_eq!(sim.e.stats().groups, 0);
    assert_eq!(
        sim.e.stats().source_items,
        0,
        "unreferenced cache entries are freed"
    );
}

#[test]
fn set_keep_alive_revises_and_zero_disables() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    assert_eq!(
        sim.e.set_keep_alive(sim.now, g, 200).unwrap(),
        Revised {
            value: 1000,
            revised: true
        }
    );
    assert_eq!(
        sim.e.set_keep_alive(sim.now, g, 5000).unwrap(),
        Revised {
            value: 5000,
            revised: false
        }
    );
    assert_eq!(sim.e.keep_alive(g), Ok(5000));
    assert_eq!(
        sim.e.set_keep_alive(sim.now, g, 0).unwrap(),
        Revised {
            value: 0,
            revised: false
        }
    );
    assert_eq!(sim.e.keep_alive(g), Ok(0));
}

#[test]
fn add_items_reports_namespace_errors_per_item() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let defs = [
        def("A1"),
        def("bad id"),
        def("NOPE"),
        ItemDefinition {
            access_path: "Nowhere",
            ..def("A2")
        },
        ItemDefinition {
            requested_type: VarType::array_of(VarType::R8),
            ..def("A3")
        },
        ItemDefinition {
            requested_type: VarType::ERROR,
            ..def("A4")
        },
        ItemDefinition {
            requested_type: VarType(0x0FFF),
            ..def("A5")
        },
        ItemDefinition {
            requested_type: VarType::BSTR,
            ..def("A6")
        },
        def(""),
        def("RO"),
    ];
    let r = sim.e.add_items(sim.now, g, &defs).unwrap();
    assert_eq!(r.len(), defs.len());
    let ok = r[0].unwrap();
    assert_ne!(ok.server_handle, 0);
    assert_eq!(
        (ok.canonical_type, ok.access_rights),
        (VarType::R8, OPC_READABLE | OPC_WRITEABLE)
    );
    assert_eq!(r[1], Err(OpcError::InvalidItemId));
    assert_eq!(r[2], Err(OpcError::UnknownItemId));
    assert_eq!(r[3], Err(OpcError::UnknownPath));
    assert_eq!(r[4], Err(OpcError::BadType), "scalar to array");
    assert_eq!(r[5], Err(OpcError::BadType), "number to VT_ERROR");
    assert_eq!(r[6], Err(OpcError::BadType), "not a VARTYPE");
    assert!(r[7].is_ok(), "any convertible type is accepted");
    assert_eq!(r[8], Err(OpcError::InvalidItemId));
    assert_eq!(r[9].unwrap().access_rights, OPC_READABLE);
    assert_eq!(
        sim.e.item_attributes(g).unwrap().len(),
        3,
        "only the successful items were added"
    );
}

#[test]
fn empty_item_list_is_invalidarg() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let now = sim.now;
    let e = &mut sim.e;
    assert_eq!(e.add_items(now, g, &[]), Err(OpcError::InvalidArg));
    assert_eq!(e.validate_items(g, &[]), Err(OpcError::InvalidArg));
    assert_eq!(e.remove_items(now, g, &[]), Err(OpcError::InvalidArg));
    assert_eq!(
        e.set_active_state(now, g, &[], true),
        Err(OpcError::InvalidArg)
    );
    assert_eq!(e.set_client_handles(g, &[]), Err(OpcError::InvalidArg));
    assert_eq!(e.set_datatypes(g, &[]), Err(OpcError::InvalidArg));
    assert_eq!(e.set_item_deadband(g, &[]), Err(OpcError::InvalidArg));
    assert_eq!(e.get_item_sampling_rate(g, &[]), Err(OpcError::InvalidArg));
    assert_eq!(
        e.read(now, g, DataSource::Cache, &[]),
        Err(OpcError::InvalidArg)
    );
    assert_eq!(e.read_max_age(now, g, &[]), Err(OpcError::InvalidArg));
    assert_eq!(e.write(now, g, &[]), Err(OpcError::InvalidArg));
    assert_eq!(e.async_read(now, g, 1, &[]), Err(OpcError::InvalidArg));
    assert_eq!(e.async_write(now, g, 1, &[]), Err(OpcError::InvalidArg));
}

#[test]
fn validate_items_adds_nothing() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let r = sim.e.validate_items(g, &[def("A1"), def("NOPE")]).unwrap();
    assert_eq!(
        r[0],
        Ok(ItemResult {
            server_handle: 0,
            canonical_type: VarType::R8,
            access_rights: 3
        })
    );
    assert_eq!(r[1], Err(OpcError::UnknownItemId));
    assert!(sim.e.item_attributes(g).unwrap().is_empty());
    sim.pump();
    assert!(sim.sub_log.is_empty(), "validation does not subscribe");
}

#[test]
fn remove_items_reports_invalid_handles_per_item() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let h = sim.items(g, &["A1", "A2", "A3"]);
    let r = sim
        .e
        .remove_items(sim.now, g, &[h[0], 999_999, h[0]])
        .unwrap();
    assert_eq!(
        r,
        vec![
            Ok(()),
            Err(OpcError::InvalidHandle),
            Err(OpcError::InvalidHandle)
        ]
    );
    // The remaining items keep their handles.
    let left: Vec<u32> = sim
        .e
        .item_attributes(g)
        .unwrap()
        .iter()
        .map(|a| a.server_handle)
        .collect();
    assert_eq!(left.len(), 2);
    assert!(left.contains(&h[1]) && left.contains(&h[2]));
    assert_eq!(
        sim.e.set_client_handles(g, &[(h[2], 55)]).unwrap(),
        vec![Ok(())]
    );
    assert_eq!(
        sim.e.set_client_handles(g, &[(h[0], 55)]).unwrap(),
        vec![Err(OpcError::InvalidHandle)]
    );
}

#[test]
fn item_server_handles_are_never_reused() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let h1 = sim.items(g, &["A1"]);
    sim.e.remove_items(sim.now, g, &h1).unwrap();
    let h2 = sim.items(g, &["A1"]);
    assert_ne!(h1, h2);
}

#[test]
fn set_datatypes_checks_conversion_per_item() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let h = sim.items(g, &["A1", "ARR"]);
    let r = sim
        .e
        .set_datatypes(
            g,
            &[
                (h[0], VarType::BSTR),
                (h[0], VarType::array_of(VarType::I4)),
                (h[1], VarType::array_of(VarType::I4)),
                (h[1], VarType::I4),
                (7, VarType::I4),
            ],
        )
        .unwrap();
    assert_eq!(
        r,
        vec![
            Ok(()),
            Err(OpcError::BadType),
            Ok(()),
            Err(OpcError::BadType),
            Err(OpcError::InvalidHandle)
        ]
    );
    let attrs = sim.e.item_attributes(g).unwrap();
    assert_eq!(attrs[0].requested_type, VarType::BSTR);
}

#[test]
fn item_attributes_report_item_id_access_path_and_eu() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let defs = [
        ItemDefinition {
            item_id: "A1",
            access_path: "Camac",
            active: false,
            client_handle: 11,
            requested_type: VarType::I2,
        },
        ItemDefinition {
            item_id: "alias.A1",
            access_path: "",
            active: true,
            client_handle: 12,
            requested_type: VarType::EMPTY,
        },
        ItemDefinition {
            item_id: "D1",
            access_path: "*",
            active: true,
            client_handle: 13,
            requested_type: VarType::EMPTY,
        },
    ];
    let h: Vec<u32> = sim
        .e
        .add_items(sim.now, g, &defs)
        .unwrap()
        .into_iter()
        .map(|r| r.unwrap().server_handle)
        .collect();
    let a = sim.e.item_attributes(g).unwrap();
    assert_eq!(a.len(), 3);
    assert_eq!(
        a[0],
        ItemAttributes {
            access_path: "Camac".into(),
            item_id: "A1".into(),
            active: false,
            client_handle: 11,
            server_handle: h[0],
            access_rights: 3,
            requested_type: VarType::I2,
            canonical_type: VarType::R8,
            eu: EuInfo::Analog {
                low: 0.0,
                high: 100.0
            },
        }
    );
    assert_eq!(
        (a[1].item_id.as_str(), a[1].access_path.as_str()),
        ("alias.A1", ""),
        "the client's item ID, not the source key"
    );
    assert_eq!(
        (a[2].item_id.as_str(), a[2].access_path.as_str(), &a[2].eu),
        ("D1", "*", &EuInfo::None)
    );
    // alias.A1 and A1 on the basic channel share one cache entry; A1 on Camac is another.
    assert_eq!(sim.e.stats().source_items, 3);
}

#[test]
fn item_deadband_set_get_clear_follow_deadbandmgt() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let h = sim.items(g, &["A1", "D1"]);
    let (analog, plain) = (h[0], h[1]);
    assert_eq!(
        sim.e.get_item_deadband(g, &[analog]).unwrap(),
        vec![Err(OpcError::DeadbandNotSet)]
    );
    assert_eq!(
        sim.e.clear_item_deadband(g, &[analog]).unwrap(),
        vec![Err(OpcError::DeadbandNotSet)]
    );
    let r = sim
        .e
        .set_item_deadband(
            g,
            &[
                (analog, 12.5),
                (plain, 1.0),
                (analog, 100.5),
                (analog, -1.0),
                (4242, 1.0),
            ],
        )
        .unwrap();
    assert_eq!(
        r,
        vec![
            Ok(()),
            Err(OpcError::DeadbandNotSupported),
            Err(OpcError::InvalidArg),
            Err(OpcError::InvalidArg),
            Err(OpcError::InvalidHandle)
        ]
    );
    assert_eq!(
        sim.e.get_item_deadband(g, &[analog, plain]).unwrap(),
        vec![Ok(12.5), Err(OpcError::DeadbandNotSupported)]
    );
    assert_eq!(
        sim.e.clear_item_deadband(g, &[analog, plain]).unwrap(),
        vec![Ok(()), Err(OpcError::DeadbandNotSupported)]
    );
    assert_eq!(
        sim.e.get_item_deadband(g, &[analog]).unwrap(),
        vec![Err(OpcError::DeadbandNotSet)]
    );
}

/// Item sampling rates and deadbands are kept apart from the items: each is set and
/// cleared on its own, goes with its item, is copied by CloneGroup to the new handles and
/// does not come back when the item is added again; the rate still counts at the source.
#[test]
fn item_sampling_rates_and_deadbands_follow_their_items() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 5000, 0.0);
    let h = sim.items(g, &["A1", "A2"]);
    let rate = |sim: &Sim, g, h| sim.e.get_item_sampling_rate(g, &[h]).unwrap()[0];
    let band = |sim: &Sim, g, h| sim.e.get_item_deadband(g, &[h]).unwrap()[0];
    sim.e.set_item_sampling_rate(g, &[(h[0], 1000)]).unwrap();
    sim.e
        .set_item_deadband(g, &[(h[0], 5.0), (h[1], 7.0)])
        .unwrap();
    sim.pump();
    assert_eq!(sim.subscribed["A1"], 1000);
    assert_eq!(
        (rate(&sim, g, h[0]), band(&sim, g, h[0])),
        (Ok(1000), Ok(5.0))
    );
    assert_eq!(
        (rate(&sim, g, h[1]), band(&sim, g, h[1])),
        (Err(OpcError::RateNotSet), Ok(7.0))
    );
    // Clearing the deadband keeps the rate, and the other way round.
    sim.e.clear_item_deadband(g, &[h[0]]).unwrap();
    assert_eq!(
        (rate(&sim, g, h[0]), band(&sim, g, h[0])),
        (Ok(1000), Err(OpcError::DeadbandNotSet))
    );
    sim.e.set_item_deadband(g, &[(h[0], 6.0)]).unwrap();
    assert_eq!(
        sim.e.clear_item_sampling_rate(g, &[h[1]]).unwrap(),
        vec![Err(OpcError::RateNotSet)]
    );
    let c = sim.e.clone_group(sim.now, g, "copy").unwrap();
    let ch = sim
        .e
        .item_attributes(c)
        .unwrap()
        .iter()
        .map(|a| a.server_handle)
        .collect::<Vec<_>>();
    assert_eq!(
        (rate(&sim, c, ch[0]), band(&sim, c, ch[0])),
        (Ok(1000), Ok(6.0))
    );
    assert_eq!(
        (rate(&sim, c, ch[1]), band(&sim, c, ch[1])),
        (Err(OpcError::RateNotSet), Ok(7.0))
    );
    sim.e.clear_item_sampling_rate(g, &[h[0]]).unwrap();
    sim.pump();
    assert_eq!(sim.subscribed["A1"], 5000);
    assert_eq!(
        (rate(&sim, g, h[0]), band(&sim, g, h[0])),
        (Err(OpcError::RateNotSet), Ok(6.0))
    );
    assert_eq!(rate(&sim, c, ch[0]), Ok(1000), "the clone keeps its own");
    // Removed and added again: nothing set.
    sim.e.set_item_sampling_rate(g, &[(h[1], 2000)]).unwrap();
    sim.e.remove_items(sim.now, g, &h).unwrap();
    sim.pump();
    let h = sim.items(g, &["A1", "A2"]);
    for &h in &h {
        assert_eq!(
            (rate(&sim, g, h), band(&sim, g, h)),
            (Err(OpcError::RateNotSet), Err(OpcError::DeadbandNotSet))
        );
    }
    sim.pump();
    assert_eq!((sim.subscribed["A1"], sim.subscribed["A2"]), (5000, 5000));
}

#[test]
fn sampling_rate_set_get_clear_and_the_buffer_setting() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 5000, 0.0);
    let h = sim.items(g, &["A1"])[0];
    assert_eq!(
        sim.e.get_item_sampling_rate(g, &[h]).unwrap(),
        vec![Err(OpcError::RateNotSet)]
    );
    assert_eq!(
        sim.e.clear_item_sampling_rate(g, &[h]).unwrap(),
        vec![Err(OpcError::RateNotSet)]
    );
    let r = sim
        .e
        .set_item_sampling_rate(g, &[(h, 10), (77, 1000)])
        .unwrap();
    assert_eq!(
        r[0],
        Ok(Revised {
            value: 1000,
            revised: true
        })
    );
    assert_eq!(r[0].unwrap().code(), Some(OpcError::UnsupportedRate));
    assert_eq!(r[1], Err(OpcError::InvalidHandle));
    assert_eq!(
        sim.e.get_item_sampling_rate(g, &[h]).unwrap(),
        vec![Ok(1000)]
    );
    assert_eq!(
        sim.e.set_item_sampling_rate(g, &[(h, 2000)]).unwrap(),
        vec![Ok(Revised {
            value: 2000,
            revised: false
        })]
    );
    assert_eq!(
        sim.e.clear_item_sampling_rate(g, &[h]).unwrap(),
        vec![Ok(())]
    );
    assert_eq!(
        sim.e.get_item_sampling_rate(g, &[h]).unwrap(),
        vec![Err(OpcError::RateNotSet)]
    );
    assert_eq!(
        sim.e
            .set_item_buffer_enable(g, &[(h, true), (h, false), (9, true)])
            .unwrap(),
        vec![Ok(()), Ok(()), Err(OpcError::InvalidHandle)]
    );
    assert_eq!(
        sim.e.get_item_buffer_enable(g, &[h]).unwrap(),
        vec![Ok(false)]
    );
    sim.e.set_item_buffer_enable(g, &[(h, true)]).unwrap();
    assert_eq!(
        sim.e.get_item_buffer_enable(g, &[h, 9]).unwrap(),
        vec![Ok(true), Err(OpcError::InvalidHandle)]
    );
}
