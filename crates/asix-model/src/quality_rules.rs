//! The channel's quality rules (`CheckLimits`, `CheckControlVariables`), as the asix
//! LICZBA and SŁUPEK objects apply them, and the type check of written values.
//!
//! Attributes read (see `docs/variable-database.md`):
//! - `ControlVariable` (CheckControlVariables): the asix name of a control variable. The
//!   control variable reports **failure when its value is nonzero** (any nonzero number,
//!   or `true`); then the value's quality becomes BAD Sensor Failure (0x10, no limit or
//!   vendor bits). Zero means the measurement path is healthy. When the control value is
//!   unknown (`None`: not read yet, or read with bad quality) or not numeric, the quality
//!   is left alone.
//! - `WarnLow`, `WarnHigh`, `AlarmLow`, `AlarmHigh` (CheckLimits): numeric limits. A
//!   value strictly below a low limit or strictly above a high limit crosses it. Alarm
//!   limits are checked first: crossing one sets the limit field to Low/High **and** the
//!   vendor bit 0x0800 Second Limit (an R4 value is compared with the limit rounded to
//!   R4, so a value equal to the written limit does not cross it); crossing only a warning limit sets Low/High and
//!   clears 0x0800; crossing none sets the limit field to OK and clears 0x0800. A
//!   variable without any numeric limit keeps the data source's limit bits. Limits that
//!   name another variable (asix limit variables) are compared with that variable's
//!   current value by [`apply_quality_rules_with`] (both data sources, the in-process
//!   simulation and the asix network, pass their lookup); a limit variable without a
//!   numeric value yet is skipped, and [`apply_quality_rules`] alone skips them all.
//! - Rules never touch a BAD quality, and non-numeric values get no limit check.
//! - The control check comes first; when it fails the limits are not checked.

use super::config::ChannelOptions;
use super::format::value_as_f64;
use super::vardb::Variable;
use ctopc_core::{OpcError, OpcResult, Quality, Value};

/// The switches of the rules (from the item's channel).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RuleOptions {
    pub check_limits: bool,
    pub check_control_variables: bool,
}

impl From<&ChannelOptions> for RuleOptions {
    fn from(o: &ChannelOptions) -> Self {
        RuleOptions {
            check_limits: o.check_limits,
            check_control_variables: o.check_control_variables,
        }
    }
}

/// True when a control variable's value reports a failure (nonzero); `None` when the
/// value says nothing (not numeric).
pub fn control_failure(control_value: &Value) -> Option<bool> {
    match control_value {
        Value::Bool(b) => Some(*b),
        v => value_as_f64(v).map(|x| x != 0.0),
    }
}

/// Applies the rules (see the module documentation) to the quality of `value`, a current
/// value of `var`. `control_value` is the current value of `var`'s control variable.
/// Limits held as another variable's name are not checked here: see
/// [`apply_quality_rules_with`].
pub fn apply_quality_rules(
    var: &Variable,
    value: &Value,
    quality: Quality,
    control_value: Option<&Value>,
    options: RuleOptions,
) -> Quality {
    apply_quality_rules_with(var, value, quality, control_value, options, &|_| None)
}

/// [`apply_quality_rules`], with `limit_of(name)` giving the current value of a limit held
/// as a variable name (an asix limit variable such as `KW_L002`); `None` when unknown (that
/// limit is then not checked).
pub fn apply_quality_rules_with(
    var: &Variable,
    value: &Value,
    quality: Quality,
    control_value: Option<&Value>,
    options: RuleOptions,
    limit_of: &dyn Fn(&str) -> Option<f64>,
) -> Quality {
    let limits = [
        &var.warn_low,
        &var.warn_high,
        &var.alarm_low,
        &var.alarm_high,
    ];
    let has_control = var.control_variable.is_some();
    rules(
        limits,
        has_control,
        value,
        quality,
        control_value,
        options,
        limit_of,
    )
}

/// What the rules read of a variable's definition, and no more: its four limits and
/// whether it names a control variable. A data source keeps this per subscribed item
/// instead of the whole [`Variable`] (its cells, names and texts: about 2 KB).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RuleDef {
    /// `WarnLow`, `WarnHigh`, `AlarmLow`, `AlarmHigh`.
    pub limits: [Option<super::vardb::Limit>; 4],
    /// `ControlVariable` is set.
    pub has_control: bool,
}

impl RuleDef {
    pub fn of(var: &Variable) -> RuleDef {
        RuleDef {
            limits: [
                var.warn_low.clone(),
                var.warn_high.clone(),
                var.alarm_low.clone(),
                var.alarm_high.clone(),
            ],
            has_control: var.control_variable.is_some(),
        }
    }

    /// Nothing for the rules to check: no limit, no control variable.
    pub fn is_empty(&self) -> bool {
        !self.has_control && self.limits.iter().all(Option::is_none)
    }

    /// [`apply_quality_rules_with`] over this definition.
    pub fn apply(
        &self,
        value: &Value,
        quality: Quality,
        control_value: Option<&Value>,
        options: RuleOptions,
        limit_of: &dyn Fn(&str) -> Option<f64>,
    ) -> Quality {
        let [wl, wh, al, ah] = &self.limits;
        rules(
            [wl, wh, al, ah],
            self.has_control,
            value,
            quality,
            control_value,
            options,
            limit_of,
        )
    }
}

/// The rules over a definition's limits (`[WarnLow, WarnHigh, AlarmLow, AlarmHigh]`).
fn rules(
    limits: [&Option<super::vardb::Limit>; 4],
    has_control: bool,
    value: &Value,
    quality: Quality,
    control_value: Option<&Value>,
    options: RuleOptions,
    limit_of: &dyn Fn(&str) -> Option<f64>,
) -> Quality {
    if quality.is_bad() {
        return quality;
    }
    if options.check_control_variables && has_control {
        if let Some(true) = control_value.and_then(control_failure) {
            return Quality::BAD_SENSOR_FAILURE;
        }
    }
    if !options.check_limits {
        return quality;
    }
    let Some(v) = value_as_f64(value) else {
        return quality;
    };
    // An R4 value is compared with the limit rounded to R4, so a value equal to the limit
    // as written in the database does not cross it.
    let is_r4 = matches!(value, Value::R4(_));
    let limit = |l: &Option<super::vardb::Limit>| {
        l.as_ref()
            .and_then(|l| match l {
                super::vardb::Limit::Value(x) => Some(*x),
                super::vardb::Limit::Variable(name) => limit_of(name),
            })
            .map(|x| if is_r4 { x as f32 as f64 } else { x })
    };
    let (wl, wh, al, ah) = (
        limit(limits[0]),
        limit(limits[1]),
        limit(limits[2]),
        limit(limits[3]),
    );
    if wl.is_none() && wh.is_none() && al.is_none() && ah.is_none() {
        return quality;
    }
    let below = |l: Option<f64>| l.is_some_and(|l| v < l);
    let above = |l: Option<f64>| l.is_some_and(|l| v > l);
    let (limit_bits, second) = if below(al) {
        (Quality::LIMIT_LOW, true)
    } else if above(ah) {
        (Quality::LIMIT_HIGH, true)
    } else if below(wl) {
        (Quality::LIMIT_LOW, false)
    } else if above(wh) {
        (Quality::LIMIT_HIGH, false)
    } else {
        (Quality::LIMIT_OK, false)
    };
    let q = Quality(quality.0 & !Quality::VENDOR_SECOND_LIMIT).with_limit(limit_bits);
    if second {
        q.with_vendor(Quality::VENDOR_SECOND_LIMIT)
    } else {
        q
    }
}

/// A value written to a process variable must be an integer or a real (VT_I1..VT_UI8,
/// VT_R4, VT_R8); anything else (strings, BOOL, DATE, CY, EMPTY, arrays) is
/// `OPC_E_BADTYPE`. This is checked on the value **after** the engine converted what the
/// client sent to the variable's canonical type (`ctopc_core::convert::convert_for_write`:
/// numeric text in the group's locale, BOOL as 1/0, CY and DECIMAL convert; DATE and other
/// text do not), so a client may write `"12,5"`, TRUE or a CY to a numeric variable; it is
/// the last guard before a value reaches the asix network (`asix_net::pipeline`).
pub fn check_write_value(value: &Value) -> OpcResult<()> {
    match value {
        Value::I1(_)
        | Value::UI1(_)
        | Value::I2(_)
        | Value::UI2(_)
        | Value::I4(_)
        | Value::UI4(_)
        | Value::I8(_)
        | Value::UI8(_)
        | Value::R4(_)
        | Value::R8(_) => Ok(()),
        _ => Err(OpcError::BadType),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vardb::Limit;
    use ctopc_core::value::ArrayValue;
    use ctopc_core::VarType;

    fn var(
        wl: Option<Limit>,
        wh: Option<Limit>,
        al: Option<Limit>,
        ah: Option<Limit>,
        control: bool,
    ) -> Variable {
        Variable {
            name: "KW_A000".into(),
            public_name: "KW_A000".into(),
            line: 2,
            description: String::new(),
            description_en: String::new(),
            unit: String::new(),
            range: Some((0.0, 100.0)),
            data_type: VarType::R4,
            format_text: String::new(),
            format: None,
            warn_low: wl,
            warn_high: wh,
            alarm_low: al,
            alarm_high: ah,
            control_variable: control.then(|| "KW_K001".to_owned()),
            bar_base: None,
            writable: true,
            cells: Vec::new(),
        }
    }

    fn n(v: f64) -> Option<Limit> {
        Some(Limit::Value(v))
    }

    const GOOD: Quality = Quality::GOOD;
    const LOW: u16 = Quality::LIMIT_LOW;
    const HIGH: u16 = Quality::LIMIT_HIGH;
    const SECOND: u16 = Quality::VENDOR_SECOND_LIMIT;

    #[test]
    fn limits_table() {
        let full = var(n(20.0), n(80.0), n(10.0), n(90.0), false);
        let on = RuleOptions {
            check_limits: true,
            check_control_variables: false,
        };
        let off = RuleOptions::default();
        let rows: &[(&str, &Variable, f64, Quality, RuleOptions, u16)] = &[
            ("inside", &full, 50.0, GOOD, on, 0xC0),
            ("at warning low is not below", &full, 20.0, GOOD, on, 0xC0),
            ("below warning low", &full, 19.9, GOOD, on, 0xC0 | LOW),
            ("above warning high", &full, 80.1, GOOD, on, 0xC0 | HIGH),
            ("below alarm low", &full, 5.0, GOOD, on, 0xC0 | LOW | SECOND),
            (
                "above alarm high",
                &full,
                95.0,
                GOOD,
                on,
                0xC0 | HIGH | SECOND,
            ),
            (
                "uncertain keeps substatus",
                &full,
                95.0,
                Quality::UNCERTAIN_SENSOR_NOT_ACCURATE,
                on,
                0x50 | HIGH | SECOND,
            ),
            (
                "local override kept",
                &full,
                85.0,
                Quality::GOOD_LOCAL_OVERRIDE,
                on,
                0xD8 | HIGH,
            ),
            (
                "inside clears source bits",
                &full,
                50.0,
                Quality(0xC0 | HIGH | SECOND),
                on,
                0xC0,
            ),
            (
                "warning clears second",
                &full,
                85.0,
                Quality(0xC0 | SECOND),
                on,
                0xC0 | HIGH,
            ),
            (
                "bad untouched",
                &full,
                95.0,
                Quality::BAD_COMM_FAILURE,
                on,
                0x18,
            ),
            ("off", &full, 95.0, GOOD, off, 0xC0),
        ];
        for (name, v, value, q, o, expected) in rows {
            let got = apply_quality_rules(v, &Value::R4(*value as f32), *q, None, *o);
            assert_eq!(got, Quality(*expected), "{name}");
        }
    }

    #[test]
    fn partial_indirect_and_non_numeric() {
        let on = RuleOptions {
            check_limits: true,
            check_control_variables: false,
        };
        let rows: &[(&str, Variable, Value, u16)] = &[
            (
                "alarm only",
                var(None, None, None, n(90.0), false),
                Value::I2(91),
                0xC0 | HIGH | SECOND,
            ),
            (
                "warning only",
                var(n(0.0), None, None, None, false),
                Value::R8(-1.0),
                0xC0 | LOW,
            ),
            (
                "no limits keeps source bits",
                var(None, None, None, None, false),
                Value::R8(1.0),
                0xC0 | HIGH,
            ),
            (
                "indirect limits not evaluated",
                var(
                    None,
                    Some(Limit::Variable("KW_L001".into())),
                    None,
                    None,
                    false,
                ),
                Value::R8(1e9),
                0xC0 | HIGH,
            ),
            (
                "string value",
                var(n(0.0), n(1.0), None, None, false),
                Value::Bstr("5".into()),
                0xC0 | HIGH,
            ),
            (
                "unsigned",
                var(None, n(10.0), None, None, false),
                Value::UI4(11),
                0xC0 | HIGH,
            ),
        ];
        for (name, v, value, expected) in rows {
            assert_eq!(
                apply_quality_rules(v, value, Quality(0xC0 | HIGH), None, on),
                Quality(*expected),
                "{name}"
            );
        }
    }

    #[test]
    #[allow(clippy::type_complexity)]
    fn control_variable_table() {
        let with = var(n(20.0), n(80.0), None, None, true);
        let without = var(n(20.0), n(80.0), None, None, false);
        let both = RuleOptions {
            check_limits: true,
            check_control_variables: true,
        };
        let ctl = RuleOptions {
            check_limits: false,
            check_control_variables: true,
        };
        let rows: &[(&str, &Variable, Option<Value>, RuleOptions, Quality, u16)] = &[
            (
                "zero is healthy",
                &with,
                Some(Value::I2(0)),
                ctl,
                GOOD,
                0xC0,
            ),
            (
                "nonzero is failure",
                &with,
                Some(Value::I2(1)),
                ctl,
                GOOD,
                0x10,
            ),
            (
                "negative is failure",
                &with,
                Some(Value::I4(-1)),
                ctl,
                GOOD,
                0x10,
            ),
            ("real nonzero", &with, Some(Value::R4(0.5)), ctl, GOOD, 0x10),
            ("bool true", &with, Some(Value::Bool(true)), ctl, GOOD, 0x10),
            (
                "bool false",
                &with,
                Some(Value::Bool(false)),
                ctl,
                GOOD,
                0xC0,
            ),
            ("unknown control value", &with, None, ctl, GOOD, 0xC0),
            (
                "string control value",
                &with,
                Some(Value::Bstr("1".into())),
                ctl,
                GOOD,
                0xC0,
            ),
            (
                "no control variable",
                &without,
                Some(Value::I2(1)),
                ctl,
                GOOD,
                0xC0,
            ),
            (
                "option off",
                &with,
                Some(Value::I2(1)),
                RuleOptions::default(),
                GOOD,
                0xC0,
            ),
            (
                "failure wins over limits",
                &with,
                Some(Value::I2(3)),
                both,
                GOOD,
                0x10,
            ),
            (
                "failure clears vendor bits",
                &with,
                Some(Value::I2(3)),
                both,
                Quality(0xC0 | SECOND | HIGH),
                0x10,
            ),
            (
                "healthy then limits",
                &with,
                Some(Value::I2(0)),
                both,
                GOOD,
                0xC0 | HIGH,
            ),
            (
                "uncertain becomes bad",
                &with,
                Some(Value::I2(1)),
                ctl,
                Quality::UNCERTAIN,
                0x10,
            ),
            (
                "bad stays",
                &with,
                Some(Value::I2(1)),
                ctl,
                Quality::BAD_NOT_CONNECTED,
                0x08,
            ),
        ];
        for (name, v, cv, o, q, expected) in rows {
            let got = apply_quality_rules(v, &Value::R8(85.0), *q, cv.as_ref(), *o);
            assert_eq!(got, Quality(*expected), "{name}");
        }
    }

    #[test]
    fn write_values() {
        let ok = [
            Value::I1(-1),
            Value::UI1(1),
            Value::I2(2),
            Value::UI2(2),
            Value::I4(4),
            Value::UI4(4),
            Value::I8(8),
            Value::UI8(8),
            Value::R4(1.5),
            Value::R8(2.5),
        ];
        for v in &ok {
            assert_eq!(check_write_value(v), Ok(()), "{v:?}");
        }
        let bad = [
            Value::Empty,
            Value::Bstr("12".into()),
            Value::Bool(true),
            Value::Date(1.0),
            Value::Cy(10_000),
            Value::Error(0),
            Value::Array(ArrayValue {
                element_type: VarType::R8,
                elements: vec![Value::R8(1.0)],
            }),
        ];
        for v in &bad {
            assert_eq!(check_write_value(v), Err(OpcError::BadType), "{v:?}");
        }
    }
}

#[cfg(test)]
mod variable_limit_tests {
    use super::*;
    use crate::vardb::{Limit, Variable};
    use ctopc_core::VarType;

    fn var_with_alarm_high_variable() -> Variable {
        Variable {
            name: "T".into(),
            public_name: "T".into(),
            line: 2,
            description: String::new(),
            description_en: String::new(),
            unit: "°C".into(),
            range: Some((0.0, 200.0)),
            data_type: VarType::R4,
            format_text: String::new(),
            format: None,
            warn_low: None,
            warn_high: Some(Limit::Value(100.0)),
            alarm_low: None,
            alarm_high: Some(Limit::Variable("T_ALARM".into())),
            control_variable: None,
            bar_base: None,
            writable: false,
            cells: Vec::new(),
        }
    }

    #[test]
    fn a_limit_held_as_a_variable_name_is_checked_with_that_variables_value() {
        let var = var_with_alarm_high_variable();
        let opts = RuleOptions {
            check_limits: true,
            check_control_variables: false,
        };
        let lookup = |name: &str| (name == "T_ALARM").then_some(150.0);
        // Above the warning limit only.
        let q =
            apply_quality_rules_with(&var, &Value::R4(120.0), Quality::GOOD, None, opts, &lookup);
        assert_eq!(q, Quality::GOOD.with_limit(Quality::LIMIT_HIGH));
        // Above the alarm limit read from T_ALARM: high and Second Limit.
        let q =
            apply_quality_rules_with(&var, &Value::R4(160.0), Quality::GOOD, None, opts, &lookup);
        assert_eq!(
            q,
            Quality::GOOD
                .with_limit(Quality::LIMIT_HIGH)
                .with_vendor(Quality::VENDOR_SECOND_LIMIT)
        );
        // Without a lookup (or an unknown limit variable) that limit is not checked.
        let q = apply_quality_rules(&var, &Value::R4(160.0), Quality::GOOD, None, opts);
        assert_eq!(q, Quality::GOOD.with_limit(Quality::LIMIT_HIGH));
    }
}
