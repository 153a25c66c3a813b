//! The per-sample asix pipeline, once for every data source, run by the one adapter
//! [`crate::backend::AsixBackend`] (over the network, [`crate::datasource`], and the
//! in-process simulation, [`crate::sim::inproc`]):
//!
//! 1. **resolution** ([`resolve`]), once per source item (at subscribe time, or once per
//!    request for an item read or written while nothing subscribes it): the item's asix
//!    variable, its derivation, database definition and channel rules, and the variables
//!    its quality rules read (control variable, limits held in variables), each mapped by
//!    the data source to its own handle `V` (an [`ItemKey`] on a channel's client on the network, a plant index
//!    in the simulation);
//! 2. **a sample** ([`Resolved::sample`]): the CheckLimits / CheckControlVariables quality
//!    rules over the current values of the rule variables, then the derivation;
//! 3. **a write** ([`Resolved::check_write`]): derived items are not writable, only
//!    integers and reals are, and a variable the database marks read-only is refused.
//!
//! The rules on which the two sources could part are decided here, once, for both:
//! - a limit variable whose value is BAD (or not numeric, or not known yet) is an
//!   **unknown limit**: the rules skip that limit. A BAD value is no value an operator set.
//! - the database's `Writable` is checked again at the data source, as a second guard
//!   behind the engine's access rights: a write the asix server would refuse anyway is
//!   refused at once and the same way from both sources
//!   (ASKOM_E_WriteErrorDeviceRequestIllegal).

use asix_model::namespace::{AsixNamespace, Derivation};
use asix_model::{check_write_value, Limit, RuleDef, RuleOptions, Variable};
use ctopc_core::model::datasource::SourceItem;
use ctopc_core::{OpcError, Quality, Value, Vqt};

use asix_model::ItemKey;

/// The attribute of the variable database naming a variable's asix channel.
pub const CHANNEL_ATTRIBUTE: &str = "Channel";

/// A source item resolved once: its variable and what its samples and writes need, with
/// the variables as handles `V` of the data source.
#[derive(Debug, Clone, PartialEq)]
pub struct Resolved<V> {
    /// The asix variable.
    pub key: V,
    /// What is done with the variable's samples and with writes. Apart from the key,
    /// because items on different variables mostly share it (a plain value item of a
    /// channel without rules): the adapter keeps one of each kind, not one per item.
    pub treatment: Treatment<V>,
}

/// What the pipeline does with an item's samples and writes, everything of a
/// [`Resolved`] item but its variable.
#[derive(Debug, Clone, PartialEq)]
pub struct Treatment<V> {
    /// How the item's value derives from the variable's.
    pub derivation: Derivation,
    /// What the quality rules read of the variable's database definition (limits,
    /// control variable), only when the channel checks them and there is something to
    /// check; `None` otherwise (descriptive IDs always). Not the whole [`Variable`]: an
    /// item of a 100,000-item subscription must not carry its variable's every cell.
    pub rule_def: Option<Box<RuleDef>>,
    /// The database does not mark the variable `Writable` (never for descriptive IDs).
    pub read_only: bool,
    /// CheckLimits / CheckControlVariables of the item's channel.
    pub rules: RuleOptions,
    /// The control variable, when the rules check it (and the source knows it).
    pub control: Option<V>,
    /// The variables holding the definition's limits (`WarnLow` .. `AlarmHigh` cells that
    /// name a variable, such as `KW_L002`), each once, when the rules check limits, with
    /// the name as the limit gives it (the quality rules look limits up by it).
    pub limits: Vec<(Box<str>, V)>,
}

/// What a source item is, as far as the pipeline can tell.
// Made once per subscribed item and kept (behind an Arc, or unwrapped into the slot):
// boxing the large variant would only add an allocation per item.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq)]
pub enum Resolution<V> {
    /// Not a live asix item (the namespace does not know it): ASKOM_E_ItemUnknown.
    NotLive,
    /// A live item whose variable the source does not know (only a source that knows all
    /// its variables, the simulation, says so), with the item's derivation.
    NoVariable(Derivation),
    /// A live item on a variable of the source.
    Resolved(Resolved<V>),
}

/// The names of the variables a definition's limits are held in, each once.
pub fn limit_variables(def: &Variable) -> Vec<&str> {
    let mut names: Vec<&str> = Vec::new();
    for l in [
        &def.warn_low,
        &def.warn_high,
        &def.alarm_low,
        &def.alarm_high,
    ] {
        if let Some(Limit::Variable(name)) = l {
            if !names.contains(&name.as_str()) {
                names.push(name);
            }
        }
    }
    names
}

/// The asix channel of a database variable of the item's AsixConnect channel (its
/// `Channel` attribute; "" if none: the server then finds the variable by name).
fn db_channel(ns: &AsixNamespace, channel: &str, def: &Variable) -> String {
    ns.database(channel)
        .and_then(|db| db.attribute(def, CHANNEL_ATTRIBUTE))
        .unwrap_or("")
        .trim()
        .to_owned()
}

/// Resolves a source item through the asix namespace: descriptive IDs carry their asix
/// channel, database variables take it from the `Channel` attribute; control and limit
/// variables are asix names of the item's database, on their own `Channel`, resolved only
/// when the item's channel checks them. `lookup` maps an asix variable to the source's
/// handle (`None`: the source has no such variable).
pub fn resolve<V>(
    ns: &AsixNamespace,
    item: &SourceItem,
    lookup: impl FnMut(&ItemKey) -> Option<V>,
) -> Resolution<V> {
    resolve_id(ns, &item.channel, &item.item_id, lookup)
}

/// [`resolve`] of the item `item_id` of the AsixConnect channel `channel`.
pub fn resolve_id<V>(
    ns: &AsixNamespace,
    channel: &str,
    item_id: &str,
    mut lookup: impl FnMut(&ItemKey) -> Option<V>,
) -> Resolution<V> {
    let Some(live) = ns.live_item(channel, item_id) else {
        return Resolution::NotLive;
    };
    let asix_channel = match (&live.asmen_channel, &live.definition) {
        (Some(c), _) => c.clone(),
        (None, Some(def)) => db_channel(ns, channel, def),
        (None, None) => String::new(),
    };
    let Some(key) = lookup(&ItemKey::new(&asix_channel, &live.variable)) else {
        return Resolution::NoVariable(live.derivation);
    };
    let rules = ns
        .config()
        .resolve_channel(channel)
        .map(|r| RuleOptions::from(r.options))
        .unwrap_or_default();
    let mut rule_var = |name: &str| {
        // Read in place: decoding the variable would keep it decoded in the database.
        let ch = ns
            .database(channel)
            .and_then(|db| {
                let i = db.find_real_index(name)?;
                let col = db.column(CHANNEL_ATTRIBUTE)?;
                Some(db.variables.view(i).cell(col).trim().to_owned())
            })
            .unwrap_or_default();
        lookup(&ItemKey::new(&ch, name))
    };
    let control = match (&live.definition, rules.check_control_variables) {
        (Some(def), true) => def.control_variable.as_deref().and_then(&mut rule_var),
        _ => None,
    };
    let limits = match (&live.definition, rules.check_limits) {
        (Some(def), true) => limit_variables(def)
            .into_iter()
            .filter_map(|name| Some((Box::from(name), rule_var(name)?)))
            .collect(),
        _ => Vec::new(),
    };
    Resolution::Resolved(Resolved {
        key,
        treatment: Treatment {
            derivation: live.derivation,
            rule_def: live
                .definition
                .as_ref()
                .filter(|_| rules.check_limits || rules.check_control_variables)
                .map(RuleDef::of)
                .filter(|d| !d.is_empty())
                .map(Box::new),
            read_only: live.definition.as_ref().is_some_and(|d| !d.writable),
            rules,
            control,
            limits,
        },
    })
}

impl<V> Resolved<V> {
    /// See [`Treatment::rule_variables`].
    pub fn rule_variables(&self) -> Vec<&V>
    where
        V: PartialEq,
    {
        self.treatment.rule_variables()
    }

    /// See [`Treatment::sample`].
    pub fn sample(&self, raw: Vqt, current: impl Fn(&V) -> Option<Vqt>) -> Vqt {
        self.treatment.sample(raw, current)
    }

    /// See [`Treatment::check_write`].
    pub fn check_write(&self, value: &Value) -> Result<(), OpcError> {
        self.treatment.check_write(value)
    }
}

impl<V> Treatment<V> {
    /// The variables the item's quality rules read (control and limit variables), each
    /// once.
    pub fn rule_variables(&self) -> Vec<&V>
    where
        V: PartialEq,
    {
        let mut v: Vec<&V> = Vec::with_capacity(self.limits.len() + 1);
        for k in self
            .control
            .iter()
            .chain(self.limits.iter().map(|(_, k)| k))
        {
            if !v.contains(&k) {
                v.push(k);
            }
        }
        v
    }

    /// The item's VQT from a raw sample of its variable: the quality rules, then the
    /// derivation. `current` gives the current raw VQT of a rule variable (`None`: not
    /// known). A limit variable without a usable value (unknown, BAD quality, not numeric)
    /// is an unknown limit: the rules skip that limit.
    pub fn sample(&self, raw: Vqt, current: impl Fn(&V) -> Option<Vqt>) -> Vqt {
        let quality = match &self.rule_def {
            Some(def) => {
                let control = self.control.as_ref().and_then(&current).map(|c| c.value);
                let limit_of = |name: &str| {
                    let (_, k) = self.limits.iter().find(|(n, _)| &**n == name)?;
                    let l = current(k)?;
                    if l.quality.is_bad() {
                        return None;
                    }
                    l.value.as_f64()
                };
                def.apply(
                    &raw.value,
                    raw.quality,
                    control.as_ref(),
                    self.rules,
                    &limit_of,
                )
            }
            _ => raw.quality,
        };
        derive(
            &self.derivation,
            Vqt::new(raw.value, quality, raw.timestamp),
        )
    }

    /// May `value` be written to the item? See [`check_write`].
    pub fn check_write(&self, value: &Value) -> Result<(), OpcError> {
        check_write(&self.derivation, self.read_only, value)
    }
}

/// The write checks of an item: a derived item (formatted, percent, bars) is never
/// writable (OPC_E_BADRIGHTS), values must be integers or reals (the engine has already
/// converted what the client sent, text and BOOL included, to the variable's canonical
/// type: `ctopc_core::convert::convert_for_write`), and a variable the
/// database does not mark `Writable` is refused (ASKOM_E_WriteErrorDeviceRequestIllegal:
/// a second guard behind the engine's access rights).
pub fn check_write(
    derivation: &Derivation,
    read_only: bool,
    value: &Value,
) -> Result<(), OpcError> {
    if *derivation != Derivation::Value {
        return Err(OpcError::BadRights);
    }
    check_write_value(value)?;
    if read_only {
        return Err(OpcError::WriteErrorDeviceRequestIllegal);
    }
    Ok(())
}

/// Applies a derivation to a sample; a value that cannot be derived is BAD Config Error.
/// An empty value (a variable without a value) stays as it is, with its quality.
pub fn derive(d: &Derivation, v: Vqt) -> Vqt {
    if matches!(d, Derivation::Value) || v.value == Value::Empty {
        return v;
    }
    match d.apply(&v.value) {
        Some(value) => Vqt::new(value, v.quality, v.timestamp),
        None => Vqt::new(Value::Empty, Quality::BAD_CONFIG_ERROR, v.timestamp),
    }
}

#[cfg(test)]
mod tests {
    //! The pipeline against a fake raw source: variables by name, values set by the test.
    use super::*;
    use ctopc_core::Timestamp;
    use std::collections::HashMap;
    use std::path::Path;

    fn ns(rules: &str) -> AsixNamespace {
        let db = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../demo/wytwornia_kwasu/wytwornia_kwasu.zez");
        let ini = format!("[Channel:*]\nItemsDatabase = {}\n{rules}", db.display());
        let (config, warnings) = asix_model::parse_config(ini.as_bytes(), "test.ini").unwrap();
        assert!(warnings.is_empty(), "{warnings:?}");
        AsixNamespace::load(config).0
    }

    const BOTH: &str = "CheckLimits = tak\nCheckControlVariables = tak\n";

    /// A fake raw source: the variable names it knows, with their current VQTs.
    struct Fake(HashMap<String, Vqt>);

    impl Fake {
        fn new(vars: &[(&str, Value, Quality)]) -> Fake {
            Fake(
                vars.iter()
                    .map(|(n, v, q)| (n.to_string(), Vqt::new(v.clone(), *q, Timestamp(7))))
                    .collect(),
            )
        }
        fn resolve(&self, ns: &AsixNamespace, id: &str) -> Resolution<String> {
            resolve_id(ns, "*", id, |k| {
                self.0
                    .contains_key(&*k.variable)
                    .then(|| k.variable.to_string())
            })
        }
        fn sample(&self, r: &Resolved<String>) -> Vqt {
            r.sample(self.0[&r.key].clone(), |k| self.0.get(k).cloned())
        }
    }

    fn resolved(r: Resolution<String>) -> Resolved<String> {
        match r {
            Resolution::Resolved(r) => r,
            other => panic!("{other:?}"),
        }
    }

    /// KW_A100: WarnLow 900, WarnHigh KW_L001, AlarmLow 850, AlarmHigh KW_L002, control
    /// variable KW_K002, not writable.
    fn furnace(l1: Quality, l2: Quality) -> Fake {
        Fake::new(&[
            ("KW_A100", Value::R4(1000.0), Quality::GOOD),
            ("KW_L001", Value::R4(990.0), l1),
            ("KW_L002", Value::R4(950.0), l2),
            ("KW_K002", Value::I2(0), Quality::GOOD),
        ])
    }

    #[test]
    fn resolution_names_the_rule_variables_once_and_only_when_checked() {
        let f = furnace(Quality::GOOD, Quality::GOOD);
        let r = resolved(f.resolve(&ns(BOTH), "KW_A100"));
        assert_eq!(r.key, "KW_A100");
        assert_eq!(r.treatment.control.as_deref(), Some("KW_K002"));
        let limits: Vec<&str> = r.treatment.limits.iter().map(|(n, _)| &**n).collect();
        assert_eq!(limits, ["KW_L001", "KW_L002"]);
        assert_eq!(r.rule_variables().len(), 3);
        let r = resolved(f.resolve(&ns(""), "KW_A100"));
        assert_eq!((r.treatment.control, r.treatment.limits.len()), (None, 0));
        assert_eq!(
            f.resolve(&ns(BOTH), "no such item at all!"),
            Resolution::NotLive
        );
        // A source that has no such variable (the fake knows no KW_A000).
        assert!(matches!(
            f.resolve(&ns(BOTH), "KW_A000.PercentageCV"),
            Resolution::NoVariable(Derivation::Percentage { .. })
        ));
    }

    #[test]
    fn limits_held_in_variables_apply_with_good_values() {
        let f = furnace(Quality::GOOD, Quality::GOOD);
        let v = f.sample(&resolved(f.resolve(&ns(BOTH), "KW_A100")));
        assert_eq!(v.value, Value::R4(1000.0));
        assert_eq!(
            v.quality,
            Quality::GOOD
                .with_limit(Quality::LIMIT_HIGH)
                .with_vendor(Quality::VENDOR_SECOND_LIMIT)
        );
    }

    /// Decided for both sources: a BAD limit variable is an unknown limit (the network
    /// test `a_limit_variable_without_a_value_is_an_unknown_limit` pins the same rule end
    /// to end), the simulation's plant values included.
    #[test]
    fn a_bad_limit_variable_is_an_unknown_limit() {
        let f = furnace(Quality::GOOD, Quality::BAD);
        let v = f.sample(&resolved(f.resolve(&ns(BOTH), "KW_A100")));
        assert_eq!(v.quality, Quality::GOOD.with_limit(Quality::LIMIT_HIGH));
        let f = furnace(Quality::BAD, Quality::BAD_CONFIG_ERROR);
        let v = f.sample(&resolved(f.resolve(&ns(BOTH), "KW_A100")));
        assert_eq!(v.quality, Quality::GOOD);
        // A limit variable the source does not know is unknown too.
        let mut f = furnace(Quality::GOOD, Quality::GOOD);
        f.0.remove("KW_L002");
        let v = f.sample(&resolved(f.resolve(&ns(BOTH), "KW_A100")));
        assert_eq!(v.quality, Quality::GOOD.with_limit(Quality::LIMIT_HIGH));
    }

    #[test]
    fn a_failed_control_variable_is_a_sensor_failure_and_rules_off_change_nothing() {
        let mut f = furnace(Quality::GOOD, Quality::GOOD);
        f.0.get_mut("KW_K002").unwrap().value = Value::I2(1);
        let v = f.sample(&resolved(f.resolve(&ns(BOTH), "KW_A100")));
        assert_eq!(v.quality, Quality::BAD_SENSOR_FAILURE);
        let v = f.sample(&resolved(f.resolve(&ns(""), "KW_A100")));
        assert_eq!(v.quality, Quality::GOOD);
    }

    #[test]
    fn derived_items_derive_and_an_empty_value_stays_empty() {
        let f = Fake::new(&[("KW_A000", Value::R4(4.0), Quality::GOOD)]);
        let r = resolved(f.resolve(&ns(""), "KW_A000.PercentageCV"));
        let v = f.sample(&r);
        assert!(matches!(v.value, Value::R8(_)), "{v:?}");
        let empty = Vqt::new(Value::Empty, Quality::BAD, Timestamp(3));
        assert_eq!(r.sample(empty.clone(), |_| None), empty);
    }

    /// Decided for both sources: the database's Writable is checked again at the data
    /// source, with the code the asix server would answer.
    #[test]
    fn writes_check_derivation_value_kind_and_writable() {
        let f = Fake::new(&[
            ("KW_A000", Value::R4(4.0), Quality::GOOD),
            ("KW_A110", Value::R4(4.0), Quality::GOOD),
        ]);
        let n = ns("");
        let set_point = resolved(f.resolve(&n, "KW_A110"));
        assert_eq!(set_point.check_write(&Value::R8(12.5)), Ok(()));
        assert!(set_point.check_write(&Value::Bstr("x".into())).is_err());
        assert_eq!(
            resolved(f.resolve(&n, "KW_A000")).check_write(&Value::R8(1.0)),
            Err(OpcError::WriteErrorDeviceRequestIllegal)
        );
        assert_eq!(
            resolved(f.resolve(&n, "KW_A000.PercentageCV")).check_write(&Value::R8(1.0)),
            Err(OpcError::BadRights)
        );
    }
}
