//! Local time to UTC: the Automation server stamps values in the asix station's local
//! time (a VT_DATE without a zone); the asix protocol carries UTC.
//!
//! A zone is a Windows time-zone rule ([`ZoneRule`], the fields of
//! `TIME_ZONE_INFORMATION`): a bias, a daylight bias and the two yearly transitions as
//! "the n-th (5 = last) weekday of a month at a local time". The plant's default is
//! Europe/Warsaw ([`ZoneRule::europe_warsaw`]): CET (UTC+1), CEST (UTC+2) from the last
//! Sunday of March 02:00 to the last Sunday of October 03:00.
//!
//! The conversion is pure: no clock, no OS zone database. Two local readings need a choice:
//! - **The autumn hour** (02:00–03:00 in Warsaw happens twice): the reading nearest to the
//!   `hint` (the moment the gate received the value; a DataChange is at most seconds old,
//!   so the nearest reading is the right one in both halves of the repeated hour). Without
//!   a hint, the first occurrence (daylight time): the earlier instant, so a value is
//!   never dated in the future of one that followed it.
//! - **The spring gap** (02:00–03:00 does not exist): read with the standard bias (as if
//!   the clock had not yet moved forward), i.e. 02:30 is 01:30 UTC = 03:30 CEST.

use ctopc_core::time::days_from_civil;
use ctopc_core::Timestamp;

const TICKS_PER_MINUTE: i64 = 600_000_000;
const TICKS_PER_DAY: i64 = 1440 * TICKS_PER_MINUTE;

/// A yearly transition as Windows writes it (`SYSTEMTIME` in day-in-month form): the
/// `week`-th (1–4, 5 = last) `weekday` (0 = Sunday) of `month` at `hour:minute` local
/// time (the time in force before the transition).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Transition {
    pub month: u32,
    pub week: u32,
    pub weekday: u32,
    pub hour: u32,
    pub minute: u32,
}

/// A time zone as a Windows rule: UTC = local + `bias` (minutes; -60 for CET), and while
/// daylight time is in force UTC = local + `bias` + `daylight_bias`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ZoneRule {
    pub bias: i32,
    pub daylight_bias: i32,
    /// Start of daylight time (given in standard local time) and its end (given in
    /// daylight local time); `None`: no daylight time.
    pub daylight: Option<(Transition, Transition)>,
}

impl ZoneRule {
    /// UTC itself.
    pub const UTC: ZoneRule = ZoneRule {
        bias: 0,
        daylight_bias: 0,
        daylight: None,
    };

    /// Europe/Warsaw (Windows "Central European Standard Time"), the plant's default.
    pub const fn europe_warsaw() -> ZoneRule {
        ZoneRule {
            bias: -60,
            daylight_bias: -60,
            daylight: Some((
                Transition {
                    month: 3,
                    week: 5,
                    weekday: 0,
                    hour: 2,
                    minute: 0,
                },
                Transition {
                    month: 10,
                    week: 5,
                    weekday: 0,
                    hour: 3,
                    minute: 0,
                },
            )),
        }
    }

    /// Reads a zone as `asix-gate.ini` spells it: `Europe/Warsaw`, `UTC`, or a Windows
    /// rule `BIAS, DAYLIGHT_BIAS, START, END` with START/END as `MONTH/WEEK/WEEKDAY/HH:MM`
    /// (`-60, -60, 3/5/0/02:00, 10/5/0/03:00` is Europe/Warsaw), or `BIAS` alone.
    pub fn parse(text: &str) -> Option<ZoneRule> {
        let t = text.trim();
        if t.eq_ignore_ascii_case("Europe/Warsaw")
            || t.eq_ignore_ascii_case("Central European Standard Time")
        {
            return Some(ZoneRule::europe_warsaw());
        }
        if t.eq_ignore_ascii_case("UTC") {
            return Some(ZoneRule::UTC);
        }
        let parts: Vec<&str> = t.split(',').map(str::trim).collect();
        let bias: i32 = parts.first()?.parse().ok()?;
        match parts.len() {
            1 => Some(ZoneRule {
                bias,
                daylight_bias: 0,
                daylight: None,
            }),
            4 => Some(ZoneRule {
                bias,
                daylight_bias: parts[1].parse().ok()?,
                daylight: Some((parse_transition(parts[2])?, parse_transition(parts[3])?)),
            }),
            _ => None,
        }
    }

    /// The UTC instant of a local reading (FILETIME ticks of the local wall clock, as if
    /// it were UTC); `hint` chooses in the autumn hour (see the module doc).
    pub fn local_to_utc(&self, local: Timestamp, hint: Option<Timestamp>) -> Timestamp {
        let standard = local.0 + i64::from(self.bias) * TICKS_PER_MINUTE;
        let Some(_) = self.daylight else {
            return Timestamp(standard);
        };
        let daylight = standard + i64::from(self.daylight_bias) * TICKS_PER_MINUTE;
        let std_ok = !self.is_daylight(Timestamp(standard));
        let dst_ok = self.is_daylight(Timestamp(daylight));
        Timestamp(match (std_ok, dst_ok) {
            (true, false) => standard,
            (false, true) => daylight,
            // Both: the repeated hour.
            (true, true) => match hint {
                Some(h) if (standard - h.0).abs() < (daylight - h.0).abs() => standard,
                _ => standard.min(daylight),
            },
            // Neither: the skipped hour, read with the standard bias.
            (false, false) => standard,
        })
    }

    /// A VT_DATE in local time to UTC (`None` for a date out of range).
    pub fn ole_local_to_utc(&self, date: f64, hint: Option<Timestamp>) -> Option<Timestamp> {
        Timestamp::from_ole_date(date).map(|l| self.local_to_utc(l, hint))
    }

    /// A UTC instant as a local VT_DATE (for WriteEx's timestamp).
    pub fn utc_to_ole_local(&self, utc: Timestamp) -> f64 {
        let mut bias = i64::from(self.bias);
        if self.is_daylight(utc) {
            bias += i64::from(self.daylight_bias);
        }
        Timestamp(utc.0 - bias * TICKS_PER_MINUTE).to_ole_date()
    }

    /// Is daylight time in force at this UTC instant?
    pub fn is_daylight(&self, utc: Timestamp) -> bool {
        let Some((start, end)) = self.daylight else {
            return false;
        };
        let bias = i64::from(self.bias) * TICKS_PER_MINUTE;
        let dbias = i64::from(self.daylight_bias) * TICKS_PER_MINUTE;
        // The year of the standard local time (transitions are near no new year).
        let year = Timestamp(utc.0 - bias).civil().year;
        let start_utc = transition_local(year, start) + bias;
        let end_utc = transition_local(year, end) + bias + dbias;
        if start_utc < end_utc {
            (start_utc..end_utc).contains(&utc.0)
        } else {
            // Southern hemisphere: daylight time spans the new year.
            utc.0 >= start_utc || utc.0 < end_utc
        }
    }
}

fn parse_transition(s: &str) -> Option<Transition> {
    let (date, time) = s.split_once('/').and_then(|(m, rest)| {
        let (w, rest) = rest.split_once('/')?;
        let (d, hm) = rest.split_once('/')?;
        Some(((m, w, d), hm))
    })?;
    let (h, mi) = time.split_once(':')?;
    let t = Transition {
        month: date.0.trim().parse().ok()?,
        week: date.1.trim().parse().ok()?,
        weekday: date.2.trim().parse().ok()?,
        hour: h.trim().parse().ok()?,
        minute: mi.trim().parse().ok()?,
    };
    let valid = (1..=12).contains(&t.month)
        && (1..=5).contains(&t.week)
        && t.weekday <= 6
        && t.hour <= 23
        && t.minute <= 59;
    valid.then_some(t)
}

/// The local wall-clock instant (ticks, as if UTC) of a transition in `year`.
fn transition_local(year: i64, t: Transition) -> i64 {
    let first = days_from_civil(year, t.month, 1);
    // 1970-01-01 was a Thursday (weekday 4).
    let first_weekday = (first + 4).rem_euclid(7);
    let mut day = first + (i64::from(t.weekday) - first_weekday).rem_euclid(7);
    day += 7 * (i64::from(t.week) - 1);
    let (ny, nm) = if t.month == 12 {
        (year + 1, 1)
    } else {
        (year, t.month + 1)
    };
    let next_month = days_from_civil(ny, nm, 1);
    while day >= next_month {
        day -= 7;
    }
    Timestamp::UNIX_EPOCH_TICKS
        + day * TICKS_PER_DAY
        + (i64::from(t.hour) * 60 + i64::from(t.minute)) * TICKS_PER_MINUTE
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A wall-clock reading (ticks as if UTC).
    fn at(y: i64, mo: u32, d: u32, h: i64, mi: i64) -> Timestamp {
        Timestamp(
            Timestamp::UNIX_EPOCH_TICKS
                + days_from_civil(y, mo, d) * TICKS_PER_DAY
                + (h * 60 + mi) * TICKS_PER_MINUTE,
        )
    }

    const W: ZoneRule = ZoneRule::europe_warsaw();

    #[test]
    fn winter_and_summer_offsets() {
        assert_eq!(
            W.local_to_utc(at(2026, 1, 15, 12, 0), None),
            at(2026, 1, 15, 11, 0)
        );
        assert_eq!(
            W.local_to_utc(at(2026, 7, 15, 12, 0), None),
            at(2026, 7, 15, 10, 0)
        );
    }

    #[test]
    fn the_autumn_hour_is_read_by_the_reception_time() {
        // 2026-10-25 (last Sunday of October): 03:00 CEST = 01:00 UTC, the clock goes back
        // to 02:00 CET; 02:30 local is 00:30 UTC (CEST) and again 01:30 UTC (CET).
        let local = at(2026, 10, 25, 2, 30);
        let first = at(2026, 10, 25, 0, 30);
        let second = at(2026, 10, 25, 1, 30);
        assert_eq!(W.local_to_utc(local, Some(at(2026, 10, 25, 0, 30))), first);
        assert_eq!(W.local_to_utc(local, Some(at(2026, 10, 25, 0, 59))), first);
        assert_eq!(W.local_to_utc(local, Some(at(2026, 10, 25, 1, 31))), second);
        assert_eq!(W.local_to_utc(local, Some(at(2026, 10, 25, 1, 2))), second);
        // Without a hint: the first occurrence (daylight time).
        assert_eq!(W.local_to_utc(local, None), first);
        // Around the hour: no choice.
        assert_eq!(
            W.local_to_utc(at(2026, 10, 25, 1, 59), None),
            at(2026, 10, 24, 23, 59)
        );
        assert_eq!(
            W.local_to_utc(at(2026, 10, 25, 3, 0), None),
            at(2026, 10, 25, 2, 0)
        );
        // The hour's edges: 02:00 local is ambiguous too (00:00 or 01:00 UTC).
        assert_eq!(
            W.local_to_utc(at(2026, 10, 25, 2, 0), Some(at(2026, 10, 25, 1, 0))),
            at(2026, 10, 25, 1, 0)
        );
    }

    #[test]
    fn a_stream_of_values_through_the_autumn_change_stays_in_order() {
        // A value every 10 minutes from 00:00 to 02:00 UTC, stamped in local time and
        // received at once: converted back, each is its own instant.
        let mut utc = at(2026, 10, 25, 0, 0);
        while utc < at(2026, 10, 25, 2, 0) {
            let local = W.utc_to_ole_local(utc);
            assert_eq!(W.ole_local_to_utc(local, Some(utc)), Some(utc), "{utc:?}");
            utc = utc.add_millis(600_000);
        }
    }

    #[test]
    fn the_spring_gap_is_read_with_the_standard_bias() {
        // 2026-03-29: 02:00 CET -> 03:00 CEST (01:00 UTC).
        assert_eq!(
            W.local_to_utc(at(2026, 3, 29, 1, 59), None),
            at(2026, 3, 29, 0, 59)
        );
        assert_eq!(
            W.local_to_utc(at(2026, 3, 29, 2, 30), None),
            at(2026, 3, 29, 1, 30)
        );
        assert_eq!(
            W.local_to_utc(at(2026, 3, 29, 3, 0), None),
            at(2026, 3, 29, 1, 0)
        );
    }

    #[test]
    fn transitions_of_other_years_are_the_last_sundays() {
        // 2024: March 31, October 27. 2025: March 30, October 26.
        assert_eq!(
            W.local_to_utc(at(2024, 3, 31, 3, 0), None),
            at(2024, 3, 31, 1, 0)
        );
        assert_eq!(
            W.local_to_utc(at(2024, 3, 30, 3, 0), None),
            at(2024, 3, 30, 2, 0)
        );
        assert_eq!(
            W.local_to_utc(at(2025, 10, 26, 3, 0), None),
            at(2025, 10, 26, 2, 0)
        );
        assert_eq!(
            W.local_to_utc(at(2025, 10, 26, 1, 0), None),
            at(2025, 10, 25, 23, 0)
        );
    }

    #[test]
    fn a_southern_zone_spans_the_new_year() {
        // Daylight from the first Sunday of October 02:00 to the first Sunday of April
        // 03:00, standard UTC+10 (Sydney-like).
        let z = ZoneRule::parse("-600, -60, 10/1/0/02:00, 4/1/0/03:00").expect("rule");
        assert_eq!(
            z.local_to_utc(at(2026, 1, 10, 12, 0), None),
            at(2026, 1, 10, 1, 0)
        );
        assert_eq!(
            z.local_to_utc(at(2026, 6, 10, 12, 0), None),
            at(2026, 6, 10, 2, 0)
        );
    }

    #[test]
    fn zones_parse() {
        assert_eq!(ZoneRule::parse("europe/warsaw"), Some(W));
        assert_eq!(
            ZoneRule::parse("-60, -60, 3/5/0/02:00, 10/5/0/03:00"),
            Some(W)
        );
        assert_eq!(ZoneRule::parse("UTC"), Some(ZoneRule::UTC));
        assert_eq!(ZoneRule::parse("-120").map(|z| z.bias), Some(-120));
        assert_eq!(
            ZoneRule::parse("-60, -60, 13/5/0/02:00, 10/5/0/03:00"),
            None
        );
        assert_eq!(ZoneRule::parse("Mars/Olympus"), None);
    }
}
