use super::*;
use crate::namespace::LimitProps;
use crate::Quality;

/// A namespace of a few items: `V` (analog, with units, descriptions and three limits)
/// and its attribute items, and items for the availability rules.
struct Fake;

fn var(key: &str) -> ItemDef {
    ItemDef {
        source_key: key.into(),
        channel: "*".into(),
        canonical_type: VarType::R4,
        access_rights: 1,
        eu: EuInfo::Analog {
            low: 0.0,
            high: 8.0,
        },
        constant: None,
    }
}

fn v_attrs() -> PropertyAttributes {
    PropertyAttributes {
        description: Some("Poziom".into()),
        description_en: Some("Level".into()),
        eu_units: Some("m".into()),
        eu: EuInfo::Analog {
            low: 0.0,
            high: 8.0,
        },
        limits: LimitProps {
            hihi: Some(7.5),
            hi: Some(7.0),
            lo: Some(1.0),
            lolo: None,
        },
    }
}

impl Namespace for Fake {
    fn resolve(&self, item_id: &str, access_path: &str) -> OpcResult<ItemDef> {
        self.resolve_with_attributes(item_id, access_path)
            .map(|(d, _)| d)
    }

    fn resolve_with_attributes(
        &self,
        item_id: &str,
        _access_path: &str,
    ) -> OpcResult<(ItemDef, PropertyAttributes)> {
        let plain = |key: &str, attrs: PropertyAttributes| {
            let mut d = var(key);
            d.eu = attrs.eu.clone();
            Ok((d, attrs))
        };
        match item_id {
            "V" | "V.CV" | "A" => Ok((var("V"), v_attrs())),
            "V.DESC" | "V.EU_UNIT" | "V.HI_EU" | "V.LO_EU" | "A.DESC" | "V.AlarmHigh.CV"
            | "V.WarnLow.CV" => {
                let mut d = var(item_id);
                d.constant = Some(Value::Bstr("x".into()));
                Ok((d, PropertyAttributes::default()))
            }
            "V.PercentageCV" => Ok((
                var("V.PercentageCV"),
                PropertyAttributes {
                    eu_units: Some("%".into()),
                    ..Default::default()
                },
            )),
            // Enumerated, with a Polish description only.
            "E" => plain(
                "E",
                PropertyAttributes {
                    description: Some("Stan".into()),
                    eu: EuInfo::Enumerated(vec!["stop".into(), "praca".into()]),
                    ..Default::default()
                },
            ),
            // No EU information, an English description only, empty units.
            "N" => plain(
                "N",
                PropertyAttributes {
                    description_en: Some("Counter".into()),
                    eu_units: Some(String::new()),
                    ..Default::default()
                },
            ),
            // Empty descriptions and only the LoLo limit.
            "L" => plain(
                "L",
                PropertyAttributes {
                    description: Some(String::new()),
                    description_en: Some(String::new()),
                    limits: LimitProps {
                        lolo: Some(-1.0),
                        ..Default::default()
                    },
                    ..Default::default()
                },
            ),
            "" | "V." => Err(OpcError::InvalidItemId),
            _ => Err(OpcError::UnknownItemId),
        }
    }

    /// 101 and 310 have item IDs (`<id>.DESC`, `<id>.AlarmLow.CV`), the others none.
    fn property_item_id(&self, item_id: &str, _def: &ItemDef, property_id: u32) -> Option<String> {
        match property_id {
            101 => Some(format!("{item_id}.DESC")),
            310 => Some(format!("{item_id}.AlarmLow.CV")),
            _ => None,
        }
    }
}

fn cx(lang: Lang) -> PropertyContext<'static> {
    PropertyContext {
        ns: &Fake,
        lang,
        scan_rate_ms: 1000,
    }
}

#[test]
fn available_properties_follow_the_item() {
    let c = cx(Lang::English);
    let v = resolve_item(&c, "V").unwrap();
    assert_eq!(
        available_ids(&v, c.lang),
        [1, 2, 3, 4, 5, 6, 7, 100, 101, 102, 103, 307, 308, 309]
    );
    let pct = resolve_item(&c, "V.PercentageCV").unwrap();
    assert_eq!(available_ids(&pct, c.lang), [1, 2, 3, 4, 5, 6, 100]);
    assert_eq!(resolve_item(&c, "").err(), Some(OpcError::InvalidItemId));
    assert_eq!(resolve_item(&c, "W").err(), Some(OpcError::UnknownItemId));
}

#[test]
fn static_values_descriptions_in_the_session_language_and_bad_ids() {
    let en = cx(Lang::English);
    let v = resolve_item(&en, "V").unwrap();
    let d = property(&v, 101, true, &en);
    assert_eq!(
        (d.value.clone(), d.description, d.error),
        (Value::Bstr("Level".into()), "Item Description", None)
    );
    let pl = cx(Lang::Polish);
    let d = property(&v, 101, true, &pl);
    assert_eq!(
        (d.value, d.description),
        (Value::Bstr("Poziom".into()), "Opis elementu")
    );
    assert_eq!(property(&v, 102, true, &en).value, Value::R8(8.0));
    assert_eq!(
        (
            property(&v, 307, true, &en).value,
            property(&v, 307, true, &en).description
        ),
        (Value::R8(7.5), "HiHi Limit")
    );
    assert_eq!(
        (
            property(&v, 308, true, &en).value,
            property(&v, 309, true, &en).value
        ),
        (Value::R8(7.0), Value::R8(1.0))
    );
    assert_eq!(
        property(&v, 310, true, &en).error,
        Some(OpcError::InvalidPid),
        "no LoLo limit"
    );
    assert_eq!(
        property(&v, 1, true, &en).value,
        Value::I2(VarType::R4.0 as i16)
    );
    assert_eq!(property(&v, 6, true, &en).value, Value::R4(1000.0));
    assert_eq!(property(&v, 2, true, &en).var_type, VarType::R4);
    assert_eq!(property(&v, 2, true, &en).value, Value::Empty);
    assert_eq!(
        property(&v, 8, true, &en).error,
        Some(OpcError::InvalidPid),
        "analog: no EU info"
    );
    assert_eq!(
        property(&v, 9999, true, &en).error,
        Some(OpcError::InvalidPid)
    );
    assert_eq!(property(&v, 101, false, &en).value, Value::Empty);
}

#[test]
fn live_values_come_from_the_read() {
    let c = cx(Lang::English);
    let v = resolve_item(&c, "V").unwrap();
    let mut props: Vec<Prop> = [2, 3, 4, 5]
        .iter()
        .map(|&id| property(&v, id, true, &c))
        .collect();
    assert!(needs_read(&props));
    let t = crate::Timestamp::from_unix_millis(1_700_000_000_000);
    let state = ItemState {
        client_handle: 0,
        value: Value::R4(2.5),
        quality: Quality::GOOD,
        timestamp: t,
    };
    fill_live(&mut props, &Ok(state));
    assert_eq!(props[0].value, Value::R4(2.5));
    assert_eq!(props[1].value, Value::I2(0xC0));
    assert_eq!(props[2].value, Value::date_from(t));
    let mut props: Vec<Prop> = [2, 5]
        .iter()
        .map(|&id| property(&v, id, true, &c))
        .collect();
    fill_live(&mut props, &Err(OpcError::NetAnswerTimeout));
    assert_eq!(
        (props[0].error, props[1].error),
        (Some(OpcError::NetAnswerTimeout), None)
    );
}

// --- The availability rule of each property ID.

/// (id, value if the item has the property) of the static properties 1, 5-8, 100-103 and
/// 307-310 of one item, with values.
fn table(item_id: &str, lang: Lang) -> Vec<(u32, Option<Value>)> {
    let c = cx(lang);
    let info = resolve_item(&c, item_id).unwrap();
    let ids = [1, 5, 6, 7, 8, 100, 101, 102, 103, 307, 308, 309, 310];
    let props: Vec<Prop> = ids
        .iter()
        .map(|&id| property(&info, id, true, &c))
        .collect();
    for p in &props {
        // A property is either there with its type, or OPC_E_INVALID_PID and nothing else.
        match p.error {
            None => assert_ne!(p.var_type, VarType::EMPTY, "{item_id} {}", p.id),
            Some(e) => assert_eq!(
                (e, p.description, p.value.clone(), p.var_type),
                (OpcError::InvalidPid, "", Value::Empty, VarType::EMPTY),
                "{item_id} {}",
                p.id
            ),
        }
    }
    props
        .into_iter()
        .map(|p| (p.id, p.error.is_none().then_some(p.value)))
        .collect()
}

fn present(t: &[(u32, Option<Value>)]) -> Vec<u32> {
    t.iter()
        .filter(|(_, v)| v.is_some())
        .map(|(id, _)| *id)
        .collect()
}

fn value_of(t: &[(u32, Option<Value>)], id: u32) -> Option<Value> {
    t.iter()
        .find(|(i, _)| *i == id)
        .and_then(|(_, v)| v.clone())
}

#[test]
fn analog_items_have_eu_type_1_and_high_low_eu_but_no_eu_info() {
    let t = table("V", Lang::English);
    assert_eq!(present(&t), [1, 5, 6, 7, 100, 101, 102, 103, 307, 308, 309]);
    assert_eq!(value_of(&t, 7), Some(Value::I4(1)), "OPC_ANALOG");
    assert_eq!(value_of(&t, 102), Some(Value::R8(8.0)));
    assert_eq!(value_of(&t, 103), Some(Value::R8(0.0)));
    assert_eq!(value_of(&t, 100), Some(Value::Bstr("m".into())));
    assert_eq!(value_of(&t, 5), Some(Value::I4(1)));
}

#[test]
fn enumerated_items_have_eu_type_2_and_eu_info_but_no_high_low_eu() {
    let t = table("E", Lang::Polish);
    assert_eq!(present(&t), [1, 5, 6, 7, 8, 101]);
    assert_eq!(value_of(&t, 7), Some(Value::I4(2)), "OPC_ENUMERATED");
    assert_eq!(
        value_of(&t, 8),
        Some(Value::Array(ArrayValue {
            element_type: VarType::BSTR,
            elements: vec![Value::Bstr("stop".into()), Value::Bstr("praca".into())],
        }))
    );
    let c = cx(Lang::Polish);
    let e = resolve_item(&c, "E").unwrap();
    let eu_info = property(&e, 8, false, &c);
    assert_eq!(
        (eu_info.var_type, eu_info.value, eu_info.error),
        (VarType::array_of(VarType::BSTR), Value::Empty, None)
    );
}

#[test]
fn items_without_eu_information_have_no_eu_properties() {
    let t = table("N", Lang::English);
    assert_eq!(
        present(&t),
        [1, 5, 6, 101],
        "no 7, 8, 102, 103; an empty unit: no 100"
    );
    let c = cx(Lang::English);
    let n = resolve_item(&c, "N").unwrap();
    assert_eq!(available_ids(&n, c.lang), [1, 2, 3, 4, 5, 6, 101]);
}

#[test]
fn descriptions_fall_back_to_the_other_language() {
    // Only English: Polish sessions get it.
    assert_eq!(
        value_of(&table("N", Lang::Polish), 101),
        Some(Value::Bstr("Counter".into()))
    );
    assert_eq!(
        value_of(&table("N", Lang::English), 101),
        Some(Value::Bstr("Counter".into()))
    );
    // Only Polish: English sessions get it.
    assert_eq!(
        value_of(&table("E", Lang::English), 101),
        Some(Value::Bstr("Stan".into()))
    );
    // Both: each language its own (V); empty texts count as none (L).
    assert_eq!(
        value_of(&table("V", Lang::Polish), 101),
        Some(Value::Bstr("Poziom".into()))
    );
    for lang in Lang::ALL {
        assert_eq!(value_of(&table("L", lang), 101), None, "{lang:?}");
    }
    // The property's own description is in the session's language.
    let c = cx(Lang::Polish);
    let n = resolve_item(&c, "N").unwrap();
    assert_eq!(property(&n, 101, true, &c).description, "Opis elementu");
}

#[test]
fn limits_are_properties_only_where_the_item_has_them_as_numbers() {
    // V: HiHi, Hi, Lo; L: only LoLo; attribute items and PercentageCV: none.
    let v = table("V", Lang::English);
    assert_eq!(
        (307..=310).map(|id| value_of(&v, id)).collect::<Vec<_>>(),
        [
            Some(Value::R8(7.5)),
            Some(Value::R8(7.0)),
            Some(Value::R8(1.0)),
            None
        ]
    );
    let l = table("L", Lang::English);
    assert_eq!(present(&l), [1, 5, 6, 310]);
    assert_eq!(value_of(&l, 310), Some(Value::R8(-1.0)));
    for id in ["V.DESC", "V.AlarmHigh.CV", "V.PercentageCV"] {
        let t = table(id, Lang::English);
        assert!(
            present(&t).iter().all(|p| !(307..=310).contains(p)),
            "{id}: {t:?}"
        );
    }
    // Each limit has its OPC description.
    let c = cx(Lang::English);
    let v = resolve_item(&c, "V").unwrap();
    let d: Vec<&str> = [308, 309]
        .iter()
        .map(|&id| property(&v, id, false, &c).description)
        .collect();
    assert_eq!(d, ["Hi Limit", "Lo Limit"]);
}

#[test]
fn static_properties_of_all_or_chosen_ids() {
    let c = cx(Lang::English);
    let all = static_properties(&c, "V", None, false).unwrap();
    assert_eq!(
        all.iter().map(|p| p.id).collect::<Vec<_>>(),
        [1, 2, 3, 4, 5, 6, 7, 100, 101, 102, 103, 307, 308, 309]
    );
    assert!(all
        .iter()
        .all(|p| p.error.is_none() && p.value == Value::Empty));
    assert_eq!(all[8].item_id.as_deref(), Some("V.DESC"), "101");
    let chosen = static_properties(&c, "V", Some(&[102, 9999, 2]), true).unwrap();
    assert_eq!(
        chosen
            .iter()
            .map(|p| (p.id, p.error, p.value.clone()))
            .collect::<Vec<_>>(),
        [
            (102, None, Value::R8(8.0)),
            (9999, Some(OpcError::InvalidPid), Value::Empty),
            (2, None, Value::Empty),
        ]
    );
    assert!(needs_read(&chosen));
    assert!(!needs_read(&chosen[..2]));
    assert_eq!(
        static_properties(&c, "", None, false),
        Err(OpcError::InvalidItemId)
    );
    assert_eq!(
        static_properties(&c, "W", Some(&[1]), true),
        Err(OpcError::UnknownItemId)
    );
}

#[test]
fn lookup_item_ids_answers_invalid_pid_for_properties_without_an_item_id() {
    let c = cx(Lang::English);
    assert_eq!(
        lookup_item_ids(&c, "V", &[101, 1, 2, 102, 9999, 8, 310]).unwrap(),
        [
            Ok("V.DESC".to_owned()),
            // Every item has 1 and 2, but they have no item ID; nor has 102 here.
            Err(OpcError::InvalidPid),
            Err(OpcError::InvalidPid),
            Err(OpcError::InvalidPid),
            // Not an OPC property.
            Err(OpcError::InvalidPid),
            // Not a property of an analog item.
            Err(OpcError::InvalidPid),
            // The namespace would name an item, but V has no LoLo limit.
            Err(OpcError::InvalidPid),
        ]
    );
    assert_eq!(
        lookup_item_ids(&c, "L", &[310]).unwrap(),
        [Ok("L.AlarmLow.CV".to_owned())]
    );
    assert_eq!(
        lookup_item_ids(&c, "", &[101]),
        Err(OpcError::InvalidItemId)
    );
    assert_eq!(
        lookup_item_ids(&c, "W", &[101]),
        Err(OpcError::UnknownItemId)
    );
}

/// A namespace with the trait's defaults: no attributes, no property item IDs.
struct Plain;

impl Namespace for Plain {
    fn resolve(&self, item_id: &str, _access_path: &str) -> OpcResult<ItemDef> {
        Ok(var(item_id))
    }
}

#[test]
fn the_default_namespace_has_only_the_fixed_properties_and_no_item_ids() {
    let c = PropertyContext {
        ns: &Plain,
        lang: Lang::English,
        scan_rate_ms: 250,
    };
    let props = static_properties(&c, "X", None, true).unwrap();
    assert_eq!(
        props.iter().map(|p| p.id).collect::<Vec<_>>(),
        p::FIXED_PROPERTY_IDS
    );
    assert!(props.iter().all(|p| p.item_id.is_none()));
    assert_eq!(props[5].value, Value::R4(250.0));
    assert_eq!(
        lookup_item_ids(&c, "X", &[1, 6]).unwrap(),
        [Err(OpcError::InvalidPid), Err(OpcError::InvalidPid)]
    );
}
