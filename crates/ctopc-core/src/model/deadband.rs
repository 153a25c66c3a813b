//! Change detection and the percent deadband (OPC DA 2.05a §2.5.x "Percent Deadband",
//! 3.0 IOPCItemDeadbandMgt).
//!
//! An item is reported to a group when its quality changed or its value changed since the
//! value **last sent** to that group. For items with analog EU information (EU type
//! OPC_ANALOG, [`crate::namespace::EuInfo::Analog`]) and a deadband greater than zero, a
//! value change counts only when it exceeds the deadband:
//!
//! `|new - last sent| > (EU high - EU low) * percent / 100`
//!
//! For arrays the array is reported when any element exceeds it (or the length changed).
//! Values that are not numbers (strings, dates, EMPTY, ...) report any change. The item
//! deadband (IOPCItemDeadbandMgt) overrides the group's.

use super::cache::CachedValue;
use crate::Value;

/// True for a valid percent deadband: 0 ..= 100 (NaN is not).
pub fn valid_percent(percent: f32) -> bool {
    (0.0..=100.0).contains(&percent)
}

/// True when `new` differs from `last` by more than `percent`% of the EU span
/// `eu_high - eu_low`. A NaN or infinite value counts as a change when it differs
/// bit-for-bit (so NaN -> NaN is no change, 1.0 -> NaN is).
pub fn exceeds_percent_deadband(
    new: f64,
    last: f64,
    percent: f64,
    eu_low: f64,
    eu_high: f64,
) -> bool {
    if !new.is_finite() || !last.is_finite() {
        return new.to_bits() != last.to_bits();
    }
    let threshold = (eu_high - eu_low).abs() * percent / 100.0;
    (new - last).abs() > threshold
}

/// The deadband that applies: `(percent, eu_low, eu_high)`, `None` for "any change".
pub(crate) type Band = Option<(f64, f64, f64)>;

/// The band for an item: its own deadband if set, else the group's; only for analog items
/// and a percent above zero.
pub(crate) fn band(
    item_deadband: Option<f32>,
    group_deadband: f32,
    analog: Option<(f64, f64)>,
) -> Band {
    let (low, high) = analog?;
    let percent = f64::from(item_deadband.unwrap_or(group_deadband));
    (percent > 0.0).then_some((percent, low, high))
}

/// True when the value changed enough to be reported (quality is checked by the caller).
pub(crate) fn value_changed(new: &CachedValue, last: &CachedValue, band: Band) -> bool {
    if new == last {
        return false;
    }
    let Some((percent, low, high)) = band else {
        return true;
    };
    match (new, last) {
        (CachedValue::Num(_), CachedValue::Num(_)) => match (new.as_f64(), last.as_f64()) {
            (Some(a), Some(b)) => exceeds_percent_deadband(a, b, percent, low, high),
            _ => true,
        },
        (CachedValue::Shared(a), CachedValue::Shared(b)) => match (&**a, &**b) {
            (Value::Array(x), Value::Array(y)) => {
                x.elements.len() != y.elements.len()
                    || x.elements.iter().zip(&y.elements).any(|(p, q)| {
                        match (p.as_f64(), q.as_f64()) {
                            (Some(p), Some(q)) => {
                                exceeds_percent_deadband(p, q, percent, low, high)
                            }
                            _ => p != q,
                        }
                    })
            }
            _ => true,
        },
        _ => true,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::value::ArrayValue;
    use crate::VarType;
    use proptest::prelude::*;

    fn r8(x: f64) -> CachedValue {
        CachedValue::from_value(Value::R8(x))
    }

    #[test]
    fn deadband_threshold_is_exclusive_percent_of_eu_span() {
        // 10 % of 0..200 is 20: a change of exactly 20 is within the band.
        assert!(!exceeds_percent_deadband(120.0, 100.0, 10.0, 0.0, 200.0));
        assert!(exceeds_percent_deadband(120.5, 100.0, 10.0, 0.0, 200.0));
        assert!(exceeds_percent_deadband(79.0, 100.0, 10.0, 0.0, 200.0));
        // An inverted range is the same span.
        assert!(!exceeds_percent_deadband(120.0, 100.0, 10.0, 200.0, 0.0));
    }

    #[test]
    fn non_analog_or_zero_deadband_reports_any_change() {
        assert_eq!(band(None, 10.0, None), None);
        assert_eq!(band(None, 0.0, Some((0.0, 100.0))), None);
        assert_eq!(band(Some(0.0), 10.0, Some((0.0, 100.0))), None);
        assert_eq!(
            band(Some(5.0), 10.0, Some((0.0, 100.0))),
            Some((5.0, 0.0, 100.0))
        );
        assert!(value_changed(&r8(1.0), &r8(1.000001), None));
        assert!(!value_changed(&r8(1.0), &r8(1.0), None));
    }

    #[test]
    fn strings_report_any_change_even_with_a_deadband() {
        let a = CachedValue::from_value(Value::Bstr("a".into()));
        let b = CachedValue::from_value(Value::Bstr("b".into()));
        let a2 = CachedValue::from_value(Value::Bstr("a".into()));
        let band = Some((50.0, 0.0, 100.0));
        assert!(value_changed(&a, &b, band));
        assert!(!value_changed(&a, &a2, band));
    }

    #[test]
    fn arrays_report_when_any_element_exceeds_the_deadband() {
        let arr = |v: &[f64]| {
            CachedValue::from_value(Value::Array(ArrayValue::new(
                VarType::R8,
                v.iter().map(|&x| Value::R8(x)).collect(),
            )))
        };
        let band = Some((10.0, 0.0, 100.0));
        assert!(!value_changed(&arr(&[1.0, 2.0]), &arr(&[5.0, 8.0]), band));
        assert!(value_changed(&arr(&[1.0, 2.0]), &arr(&[1.0, 12.5]), band));
        assert!(value_changed(&arr(&[1.0]), &arr(&[1.0, 2.0]), band));
    }

    #[test]
    fn type_change_of_same_number_is_within_the_band() {
        let band = Some((1.0, 0.0, 100.0));
        let i = CachedValue::from_value(Value::I4(5));
        let r = CachedValue::from_value(Value::R4(5.0));
        assert!(!value_changed(&i, &r, band));
        assert!(value_changed(&i, &r, None));
    }

    #[test]
    fn nan_is_a_change_from_a_number_but_not_from_nan() {
        assert!(exceeds_percent_deadband(f64::NAN, 1.0, 10.0, 0.0, 100.0));
        assert!(!exceeds_percent_deadband(
            f64::NAN,
            f64::NAN,
            10.0,
            0.0,
            100.0
        ));
    }

    proptest! {
        /// The rule itself: reported iff the difference exceeds percent of the EU span.
        #[test]
        fn deadband_rule_matches_definition(
            low in -1e6f64..1e6, span in 0.0f64..1e6, percent in 0.0f64..=100.0,
            last in -2e6f64..2e6, delta in -2e6f64..2e6,
        ) {
            let high = low + span;
            let new = last + delta;
            let threshold = span * percent / 100.0;
            let reported = value_changed(&r8(new), &r8(last), band(Some(percent as f32), 0.0, Some((low, high))));
            let band_applies = percent as f32 > 0.0;
            if new == last {
                prop_assert!(!reported);
            } else if !band_applies {
                prop_assert!(reported);
            } else {
                let t = span * f64::from(percent as f32) / 100.0;
                prop_assert_eq!(reported, (new - last).abs() > t, "threshold {}", threshold);
            }
        }

        /// Item deadband overrides the group's, both ways.
        #[test]
        fn item_deadband_overrides_group_deadband(item in 0.0f32..=100.0, group in 0.0f32..=100.0) {
            let b = band(Some(item), group, Some((0.0, 100.0)));
            if item > 0.0 {
                prop_assert_eq!(b, Some((f64::from(item), 0.0, 100.0)));
            } else {
                prop_assert_eq!(b, None);
            }
        }
    }
}
