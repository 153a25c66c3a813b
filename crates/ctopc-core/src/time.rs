//! UTC timestamps as Windows FILETIME ticks (100 ns since 1601-01-01 UTC), and the one
//! proleptic Gregorian calendar conversion of the workspace (Howard Hinnant's
//! `days_from_civil` / `civil_from_days`), used by the VARIANT date conversions, the
//! server's log file names and opcdiag's local times.

/// A UTC point in time, in FILETIME ticks (100 ns since 1601-01-01T00:00:00Z).
///
/// The core never reads a clock: callers pass `now` in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct Timestamp(pub i64);

impl Timestamp {
    /// Ticks per millisecond.
    pub const TICKS_PER_MS: i64 = 10_000;
    /// FILETIME ticks between 1601-01-01 and the Unix epoch 1970-01-01.
    pub const UNIX_EPOCH_TICKS: i64 = 116_444_736_000_000_000;
    /// FILETIME ticks between 1601-01-01 and the OLE automation epoch 1899-12-30.
    pub const OLE_EPOCH_TICKS: i64 = 94_353_120_000_000_000;

    pub const fn from_filetime(ticks: i64) -> Self {
        Timestamp(ticks)
    }
    pub const fn filetime(self) -> i64 {
        self.0
    }
    /// FILETIME as its two 32-bit halves (low, high), as COM's FILETIME struct holds it.
    pub const fn filetime_parts(self) -> (u32, u32) {
        (self.0 as u64 as u32, ((self.0 as u64) >> 32) as u32)
    }
    pub const fn from_filetime_parts(low: u32, high: u32) -> Self {
        Timestamp((((high as u64) << 32) | low as u64) as i64)
    }
    pub const fn from_unix_millis(ms: i64) -> Self {
        Timestamp(Self::UNIX_EPOCH_TICKS + ms * Self::TICKS_PER_MS)
    }
    /// Microseconds since the Unix epoch (what `SystemTime::duration_since(UNIX_EPOCH)
    /// .as_micros()` gives), saturating at the largest FILETIME.
    pub fn from_unix_micros(us: u128) -> Self {
        let ticks = i64::try_from(us.saturating_mul(10)).unwrap_or(i64::MAX);
        Timestamp(Self::UNIX_EPOCH_TICKS.saturating_add(ticks))
    }
    pub const fn unix_millis(self) -> i64 {
        (self.0 - Self::UNIX_EPOCH_TICKS).div_euclid(Self::TICKS_PER_MS)
    }
    /// This instant plus `ms` milliseconds (saturating).
    pub const fn add_millis(self, ms: u64) -> Self {
        let add = (ms as i64).saturating_mul(Self::TICKS_PER_MS);
        Timestamp(self.0.saturating_add(add))
    }
    /// Milliseconds from `earlier` to `self` (0 when `earlier` is later).
    pub fn millis_since(self, earlier: Timestamp) -> u64 {
        if self.0 <= earlier.0 {
            0
        } else {
            ((self.0 - earlier.0) / Self::TICKS_PER_MS) as u64
        }
    }
    /// The calendar date and time of day (UTC), truncated to the millisecond.
    pub fn civil(self) -> CivilTime {
        let ms = self.unix_millis();
        let (year, month, day) = civil_from_days(ms.div_euclid(MS_PER_DAY));
        let in_day = ms.rem_euclid(MS_PER_DAY) as u32;
        CivilTime {
            year,
            month,
            day,
            hour: in_day / 3_600_000,
            minute: in_day / 60_000 % 60,
            second: in_day / 1000 % 60,
            millis: in_day % 1000,
        }
    }
    /// OLE automation date (days since 1899-12-30; the fraction is the time of day, and
    /// before the epoch it counts forwards from the whole day: -1.25 is 1899-12-29 06:00).
    pub fn to_ole_date(self) -> f64 {
        const TICKS_PER_DAY: f64 = 864_000_000_000.0;
        let days = (self.0 - Self::OLE_EPOCH_TICKS) as f64 / TICKS_PER_DAY;
        if days >= 0.0 {
            return days;
        }
        let whole = days.floor();
        let frac = days - whole;
        if frac == 0.0 {
            whole
        } else {
            whole - frac
        }
    }

    /// The inverse of [`Timestamp::to_ole_date`]; `None` for NaN or out of range.
    pub fn from_ole_date(date: f64) -> Option<Self> {
        const TICKS_PER_DAY: f64 = 864_000_000_000.0;
        if !date.is_finite() {
            return None;
        }
        // Before the epoch the fraction counts forwards: -1.25 is day -1 plus 0.25.
        let days = if date >= 0.0 {
            date
        } else {
            let whole = date.ceil();
            whole + (whole - date)
        };
        let ticks = (days * TICKS_PER_DAY).round() + Self::OLE_EPOCH_TICKS as f64;
        if !(0.0..=i64::MAX as f64).contains(&ticks) {
            return None;
        }
        Some(Timestamp(ticks as i64))
    }
}

const MS_PER_DAY: i64 = 86_400_000;

/// A proleptic Gregorian date and a time of day, as [`Timestamp::civil`] gives it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CivilTime {
    pub year: i64,
    /// 1..=12
    pub month: u32,
    /// 1..=31
    pub day: u32,
    pub hour: u32,
    pub minute: u32,
    pub second: u32,
    pub millis: u32,
}

/// Days from 1970-01-01 to y-m-d (proleptic Gregorian; Howard Hinnant's algorithm).
pub fn days_from_civil(y: i64, m: u32, d: u32) -> i64 {
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let m = i64::from(m);
    let doy = (153 * (if m > 2 { m - 3 } else { m + 9 }) + 2) / 5 + i64::from(d) - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// The date (year, month, day) `z` days after 1970-01-01 (proleptic Gregorian; Howard
/// Hinnant's algorithm; `z` may be negative).
pub fn civil_from_days(z: i64) -> (i64, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    (yoe + era * 400 + i64::from(m <= 2), m, d)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ole_date_round_trips_before_and_after_the_epoch() {
        for ole in [0.0, 0.25, 1.5, 45_000.125, -1.25, -2.0, -700.75] {
            let t = Timestamp::from_ole_date(ole).unwrap();
            assert!(
                (t.to_ole_date() - ole).abs() < 1e-9,
                "{ole} -> {t:?} -> {}",
                t.to_ole_date()
            );
        }
        // 1899-12-29 06:00 is -1.25 in OLE encoding.
        let t = Timestamp(Timestamp::OLE_EPOCH_TICKS - 18 * 3600 * 10_000_000);
        assert_eq!(t.to_ole_date(), -1.25);
    }

    #[test]
    fn unix_epoch_and_filetime_parts() {
        let t = Timestamp::from_unix_millis(1_000);
        assert_eq!(t.unix_millis(), 1_000);
        let (lo, hi) = t.filetime_parts();
        assert_eq!(Timestamp::from_filetime_parts(lo, hi), t);
        assert_eq!(t.add_millis(500).millis_since(t), 500);
        assert_eq!(t.millis_since(t.add_millis(1)), 0);
    }

    // Moved here from the server's logging.rs with the conversion it tested.
    #[test]
    fn civil_dates_from_unix_days() {
        assert_eq!(civil_from_days(0), (1970, 1, 1));
        assert_eq!(civil_from_days(20_414), (2025, 11, 22));
        assert_eq!(civil_from_days(11_016), (2000, 2, 29));
    }

    #[test]
    fn days_and_dates_round_trip_across_eras() {
        for z in (-1_000_000..1_000_000)
            .step_by(997)
            .chain([-719_468, -1, 0, 59, 60])
        {
            let (y, m, d) = civil_from_days(z);
            assert!((1..=12).contains(&m) && (1..=31).contains(&d), "{z}");
            assert_eq!(days_from_civil(y, m, d), z, "{y}-{m}-{d}");
        }
        assert_eq!(civil_from_days(-25_569), (1899, 12, 30)); // the OLE epoch
    }

    #[test]
    fn civil_time_and_unix_micros() {
        let t = Timestamp::from_unix_millis(1_767_618_245_120); // 2026-01-05T13:04:05.120Z
        assert_eq!(
            t.civil(),
            CivilTime {
                year: 2026,
                month: 1,
                day: 5,
                hour: 13,
                minute: 4,
                second: 5,
                millis: 120
            }
        );
        assert_eq!(Timestamp::from_unix_micros(1_767_618_245_120_000), t);
        assert_eq!(
            Timestamp::from_unix_micros(1).0,
            Timestamp::UNIX_EPOCH_TICKS + 10
        );
        assert_eq!(Timestamp::from_unix_micros(u128::MAX).0, i64::MAX);
        // Before 1970 the time of day still counts forwards from midnight.
        let c = Timestamp::from_unix_millis(-1).civil();
        assert_eq!(
            (c.year, c.month, c.day, c.hour, c.millis),
            (1969, 12, 31, 23, 999)
        );
    }
}
