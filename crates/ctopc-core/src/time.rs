//! UTC timestamps as Windows FILETIME ticks (100 ns since 1601-01-01 UTC).

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
}
