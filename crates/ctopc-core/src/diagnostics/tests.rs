use super::*;
use crate::namespace::OPC_WRITEABLE;

fn t(ms: i64) -> Timestamp {
    Timestamp::from_unix_millis(ms)
}

fn client(session: u32, name: Option<&str>) -> ClientCounters {
    ClientCounters {
        session,
        name: name.map(str::to_owned),
        ..ClientCounters::default()
    }
}

#[test]
fn item_ids_parse_into_section_owner_and_field() {
    let i = DiagItem::parse("_Diagnostics.Server.Uptime").unwrap();
    assert_eq!(
        (i.section, i.owner, i.info().name),
        (Section::Server, "", "Uptime")
    );
    let i = DiagItem::parse("_Diagnostics.Clients.HMI#3.LastCallbackLatency").unwrap();
    assert_eq!(i.section, Section::Client);
    assert_eq!(i.owner, "HMI#3");
    assert_eq!(i.info().canonical_type, VarType::R8);
    assert_eq!(i.info().eu_units, Some("ms"));
    let i = DiagItem::parse("_Diagnostics.Channels.*.LinkState").unwrap();
    assert_eq!((i.section, i.owner), (Section::Channel, "*"));
    assert_eq!(i.info().enumerated, LINK_STATES);
    for not_items in [
        "_Diagnostics",
        "_Diagnostics.Server",
        "_Diagnostics.Server.Nothing",
        "_Diagnostics.Clients.HMI",
        "_Diagnostics.Clients..Name",
        "_Diagnostics.Clients.A.B.Name",
        "_Diagnostics.Other.X.Name",
        "_DiagnosticsX.Server.Uptime",
        "KW_A000",
    ] {
        assert_eq!(DiagItem::parse(not_items), None, "{not_items}");
    }
    assert!(is_diagnostic_id("_Diagnostics"));
    assert!(is_diagnostic_id("_Diagnostics.Server"));
    assert!(!is_diagnostic_id("_DiagnosticsX"));
    assert!(!is_diagnostic_id("KW_A000"));
}

#[test]
fn every_field_has_both_descriptions_and_a_readable_type() {
    for s in [Section::Server, Section::Client, Section::Channel] {
        for f in s.fields() {
            assert!(!f.description_pl.is_empty() && !f.description_en.is_empty());
            assert_ne!(f.description_pl, f.description_en, "{}", f.name);
            assert!(
                [VarType::I4, VarType::R8, VarType::BSTR].contains(&f.canonical_type),
                "{}",
                f.name
            );
        }
    }
}

#[test]
fn client_branches_are_names_made_safe_with_fallbacks_and_tie_breakers() {
    let clients = [
        client(1, Some("HMI")),
        client(2, None),
        client(3, Some("a.b\tc")),
        client(4, Some("Hist")),
        client(5, Some("Hist")),
        client(6, Some("")),
    ];
    assert_eq!(
        client_branches(&clients),
        ["HMI", "Client2", "a_b_c", "Hist#4", "Hist#5", "Client6"]
    );
}

#[test]
fn the_sampler_computes_rates_and_rebuilds_the_tree_only_when_branches_change() {
    let mut s = Sampler::new(MatchCase::Insensitive);
    assert!(s.due(t(0)));
    let input = |callbacks: u64, values: u64, clients: Vec<ClientCounters>| Input {
        server: ServerCounters {
            callbacks_total: callbacks,
            values_total: values,
            clients: clients.len() as u64,
            ..ServerCounters::default()
        },
        clients,
        channels: vec![ChannelStatus {
            name: "*".into(),
            link: LinkState::Simulation,
            ..ChannelStatus::default()
        }],
    };
    let a = s.sample(t(10_000), input(100, 1000, vec![client(1, Some("HMI"))]));
    assert_eq!((a.callbacks_per_s, a.values_per_s), (0.0, 0.0));
    assert!(!s.due(t(10_999)));
    assert!(s.due(t(11_000)));
    let b = s.sample(t(12_000), input(120, 1500, vec![client(1, Some("HMI"))]));
    assert_eq!((b.callbacks_per_s, b.values_per_s), (10.0, 250.0));
    assert!(Arc::ptr_eq(&a.space, &b.space), "same branches, same tree");
    let c = s.sample(
        t(13_000),
        input(120, 1500, vec![client(1, Some("HMI")), client(2, None)]),
    );
    assert!(!Arc::ptr_eq(&b.space, &c.space));
    assert!(c
        .space
        .find_item_id("_Diagnostics.Clients.Client2.Name")
        .is_some());
    assert!(c
        .space
        .find_item_id("_Diagnostics.Channels.*.Subscriptions")
        .is_some());
    assert_eq!(c.space.len(), 1 + 4 + 9 + 2 * 8 + 6);
}

#[test]
fn snapshot_values_follow_the_counters() {
    let mut s = Sampler::new(MatchCase::Insensitive);
    let snap = s.sample(
        t(5_000),
        Input {
            server: ServerCounters {
                uptime_s: 42,
                clients: 2,
                groups: 3,
                items: 7,
                failed_callbacks: 4,
                dropped_sinks: 1,
                pending_transactions: 5,
                ..ServerCounters::default()
            },
            clients: vec![
                ClientCounters {
                    groups: 3,
                    items: 7,
                    last_latency_ms: Some(1.5),
                    pending: 2,
                    failures: 1,
                    identity: Some("user:PLANT\\op".into()),
                    ..client(7, Some("HMI"))
                },
                client(8, None),
            ],
            channels: vec![ChannelStatus {
                name: "K1".into(),
                link: LinkState::Up,
                server: "ASMEN1".into(),
                failovers: 2,
                last_error: "ASKOM_E_NetLinkToServer".into(),
                subscriptions: 12,
            }],
        },
    );
    let v = |id: &str| snap.value(&DiagItem::parse(id).unwrap());
    assert_eq!(v("_Diagnostics.Server.Uptime"), Some(Value::I4(42)));
    assert_eq!(v("_Diagnostics.Server.Clients"), Some(Value::I4(2)));
    assert_eq!(v("_Diagnostics.Server.Groups"), Some(Value::I4(3)));
    assert_eq!(v("_Diagnostics.Server.Items"), Some(Value::I4(7)));
    assert_eq!(
        v("_Diagnostics.Server.CallbacksPerSecond"),
        Some(Value::R8(0.0))
    );
    assert_eq!(v("_Diagnostics.Server.FailedCallbacks"), Some(Value::I4(4)));
    assert_eq!(v("_Diagnostics.Server.DroppedSinks"), Some(Value::I4(1)));
    assert_eq!(
        v("_Diagnostics.Server.PendingTransactions"),
        Some(Value::I4(5))
    );
    assert_eq!(
        v("_Diagnostics.Clients.HMI.Name"),
        Some(Value::Bstr("HMI".into()))
    );
    assert_eq!(v("_Diagnostics.Clients.HMI.Groups"), Some(Value::I4(3)));
    assert_eq!(v("_Diagnostics.Clients.HMI.Items"), Some(Value::I4(7)));
    assert_eq!(
        v("_Diagnostics.Clients.HMI.LastCallbackLatency"),
        Some(Value::R8(1.5))
    );
    assert_eq!(
        v("_Diagnostics.Clients.HMI.CallbacksPending"),
        Some(Value::I4(2))
    );
    assert_eq!(v("_Diagnostics.Clients.HMI.Failures"), Some(Value::I4(1)));
    assert_eq!(
        v("_Diagnostics.Clients.HMI.Identity"),
        Some(Value::Bstr("user:PLANT\\op".into()))
    );
    assert_eq!(
        v("_Diagnostics.Clients.Client8.Identity"),
        Some(Value::Bstr(String::new()))
    );
    assert_eq!(
        v("_Diagnostics.Clients.Client8.Name"),
        Some(Value::Bstr(String::new()))
    );
    assert_eq!(
        v("_Diagnostics.Clients.Client8.LastCallbackLatency"),
        Some(Value::R8(-1.0))
    );
    assert_eq!(v("_Diagnostics.Clients.Gone.Name"), None);
    assert_eq!(v("_Diagnostics.Channels.K1.LinkState"), Some(Value::I4(1)));
    assert_eq!(
        v("_Diagnostics.Channels.K1.Server"),
        Some(Value::Bstr("ASMEN1".into()))
    );
    assert_eq!(v("_Diagnostics.Channels.K1.Failovers"), Some(Value::I4(2)));
    assert_eq!(
        v("_Diagnostics.Channels.K1.LastError"),
        Some(Value::Bstr("ASKOM_E_NetLinkToServer".into()))
    );
    assert_eq!(
        v("_Diagnostics.Channels.K1.Subscriptions"),
        Some(Value::I4(12))
    );
    assert_eq!(v("_Diagnostics.Channels.K2.Subscriptions"), None);
}

struct Real;
impl Namespace for Real {
    fn resolve(&self, item_id: &str, _: &str) -> OpcResult<ItemDef> {
        if item_id == "KW_A000" {
            Ok(ItemDef {
                source_key: item_id.into(),
                channel: "*".into(),
                canonical_type: VarType::R4,
                access_rights: OPC_READABLE | OPC_WRITEABLE,
                eu: EuInfo::None,
                constant: None,
            })
        } else {
            Err(OpcError::UnknownItemId)
        }
    }

    fn write_refusal(&self, item_id: &str, access_path: &str) -> Option<String> {
        (access_path == "EVO").then(|| format!("{item_id} of EVO takes no writes"))
    }
}

#[test]
fn the_namespace_resolves_diagnostic_items_read_only_and_passes_the_rest_on() {
    let board = Arc::new(Board::new());
    let mut s = Sampler::new(MatchCase::Insensitive);
    board.publish(s.sample(
        t(1_000),
        Input {
            clients: vec![client(1, Some("HMI"))],
            ..Input::default()
        },
    ));
    let ns = DiagNamespace::new(Arc::new(Real), Arc::clone(&board));
    assert_eq!(
        ns.resolve("KW_A000", "").unwrap().canonical_type,
        VarType::R4
    );
    // The real namespace's reasons for read-only items pass through too.
    assert_eq!(
        ns.write_refusal("KW_A000", "EVO").as_deref(),
        Some("KW_A000 of EVO takes no writes")
    );
    assert_eq!(ns.write_refusal("_Diagnostics.Server.Uptime", "EVO"), None);
    let (def, attrs) = ns
        .resolve_with_attributes("_Diagnostics.Clients.HMI.LastCallbackLatency", "")
        .unwrap();
    assert_eq!(def.access_rights, OPC_READABLE);
    assert_eq!(def.canonical_type, VarType::R8);
    assert_eq!(
        def.source_key,
        "_Diagnostics.Clients.HMI.LastCallbackLatency"
    );
    assert_eq!(attrs.eu_units.as_deref(), Some("ms"));
    assert!(attrs.description.unwrap().starts_with("Czas trwania"));
    assert!(attrs.description_en.unwrap().starts_with("Duration"));
    let (def, _) = ns
        .resolve_with_attributes("_Diagnostics.Server.Uptime", "")
        .unwrap();
    assert_eq!(def.eu, EuInfo::None);
    assert_eq!(
        ns.resolve("_Diagnostics.Server.Uptime", "K1"),
        Err(OpcError::UnknownPath)
    );
    for unknown in [
        "_Diagnostics",
        "_Diagnostics.Server",
        "_Diagnostics.Clients.Other.Name",
        "_Diagnostics.Server.Nothing",
    ] {
        assert_eq!(
            ns.resolve(unknown, ""),
            Err(OpcError::UnknownItemId),
            "{unknown}"
        );
    }
    // The client leaves: its items are unknown to new lookups.
    board.publish(s.sample(t(2_000), Input::default()));
    assert_eq!(
        ns.resolve("_Diagnostics.Clients.HMI.Name", ""),
        Err(OpcError::UnknownItemId)
    );
    assert_eq!(
        ns.property_item_id("_Diagnostics.Server.Uptime", &def, 101),
        None
    );
}

#[test]
fn the_branches_have_descriptions_in_both_languages_and_items_none() {
    // (item ID, Polish, English)
    let table: &[(&str, &str, &str)] = &[
        (
            "_Diagnostics",
            "Diagnostyka serwera: serwer, podłączeni klienci, kanały",
            "Server diagnostics: the server, the connected clients, the channels",
        ),
        (
            "_Diagnostics.Server",
            "Liczniki serwera",
            "The server's counters",
        ),
        (
            "_Diagnostics.Clients",
            "Podłączeni klienci, po jednej gałęzi na klienta",
            "The connected clients, one branch per client",
        ),
        (
            "_Diagnostics.Channels",
            "Kanały źródła danych, po jednej gałęzi na kanał",
            "The data source's channels, one branch per channel",
        ),
        ("_Diagnostics.Clients.HMI#3", "Klient HMI#3", "Client HMI#3"),
        (
            "_Diagnostics.Channels.KANAL",
            "Kanał KANAL",
            "Channel KANAL",
        ),
    ];
    for &(id, pl, en) in table {
        assert_eq!(
            branch_description(id, Lang::Polish).as_deref(),
            Some(pl),
            "{id}"
        );
        assert_eq!(
            branch_description(id, Lang::English).as_deref(),
            Some(en),
            "{id}"
        );
    }
    for id in [
        "_Diagnostics.Server.Uptime",
        "_Diagnostics.Clients.HMI.Name",
        "_Diagnostics.Clients.",
        "_Diagnostics.Other",
        "_DiagnosticsX",
        "KW_A000",
        "",
    ] {
        for lang in Lang::ALL {
            assert_eq!(branch_description(id, lang), None, "{id}");
        }
    }
}
