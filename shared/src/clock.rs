//! The guest's wall clock: `GET /v1/clock` reads it, `PUT /v1/clock` sets it.
//!
//! A VM restored from a snapshot wakes with the wall time it was saved at
//! (Windows keeps its own clock across `loadvm` and nothing resyncs it), so the
//! host sets the guest's clock to its own after every restore and records how
//! far off it was. Times are milliseconds since the Unix epoch, in UTC; the
//! range a guest accepts, and a time's calendar fields (what Windows'
//! `SYSTEMTIME` takes), are decided here once for both backends.

use serde::{Deserialize, Serialize};

use crate::calendar::civil_from_days;

/// `GET /v1/clock`: the guest's wall clock now.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct ClockReading {
    /// Milliseconds since 1970-01-01 00:00 UTC.
    pub unix_ms: i64,
}

/// `PUT /v1/clock`: the time to set, milliseconds since the Unix epoch (UTC).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct ClockSet {
    pub unix_ms: i64,
}

/// What `PUT /v1/clock` did: the guest's clock just before, and the time set.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct ClockSetResult {
    /// The guest's clock just before it was set.
    pub previous_unix_ms: i64,
    /// The time it was set to.
    pub unix_ms: i64,
}

impl ClockSetResult {
    /// How far the guest's clock was behind the time set (negative: ahead).
    pub fn corrected_ms(&self) -> i64 {
        self.unix_ms - self.previous_unix_ms
    }
}

/// The earliest time a guest accepts: 2000-01-01 00:00 UTC. Anything earlier is a
/// host whose own clock is wrong (or a unit mistake, seconds for milliseconds).
pub const EARLIEST_MS: i64 = 946_684_800_000;
/// The first time a guest refuses: 10000-01-01 00:00 UTC (a four-digit year).
pub const END_MS: i64 = 253_402_300_800_000;

/// Checks a time to set, naming what is wrong.
///
/// # Errors
///
/// The time is before 2000 or past the year 9999.
pub fn check(unix_ms: i64) -> Result<(), String> {
    if (EARLIEST_MS..END_MS).contains(&unix_ms) {
        Ok(())
    } else {
        Err(format!(
            "unix_ms {unix_ms} is outside the times a guest's clock is set to ({EARLIEST_MS}, 2000-01-01, to before {END_MS}, the year 10000); it is milliseconds since 1970-01-01 UTC"
        ))
    }
}

/// A time's UTC calendar fields, as Windows' `SYSTEMTIME` has them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CivilTime {
    pub year: u16,
    pub month: u16,
    /// 0 is Sunday, as `SYSTEMTIME::wDayOfWeek`.
    pub day_of_week: u16,
    pub day: u16,
    pub hour: u16,
    pub minute: u16,
    pub second: u16,
    pub millisecond: u16,
}

/// The UTC calendar fields of `unix_ms`, once [`check`] accepted it.
///
/// # Errors
///
/// As [`check`].
pub fn civil(unix_ms: i64) -> Result<CivilTime, String> {
    check(unix_ms)?;
    let days = unix_ms.div_euclid(86_400_000);
    let in_day = unix_ms.rem_euclid(86_400_000);
    let (year, month, day) = civil_from_days(days);
    // 1970-01-01 was a Thursday (4).
    let day_of_week = (days + 4).rem_euclid(7);
    let field = |v: i64| u16::try_from(v).map_err(|_| format!("unix_ms {unix_ms}: a calendar field out of range"));
    Ok(CivilTime {
        year: field(year)?,
        month: field(i64::from(month))?,
        day_of_week: field(day_of_week)?,
        day: field(i64::from(day))?,
        hour: field(in_day / 3_600_000)?,
        minute: field(in_day / 60_000 % 60)?,
        second: field(in_day / 1000 % 60)?,
        millisecond: field(in_day % 1000)?,
    })
}

/// This machine's wall clock, in milliseconds since the Unix epoch.
pub fn now_unix_ms() -> i64 {
    match std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH) {
        Ok(since) => i64::try_from(since.as_millis()).unwrap_or(i64::MAX),
        Err(before) => -i64::try_from(before.duration().as_millis()).unwrap_or(i64::MAX),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn times_break_into_systemtime_fields() {
        // 2026-12-02 09:48:00.123 UTC, a Wednesday.
        let t = civil(1_796_204_880_123).unwrap();
        assert_eq!(
            t,
            CivilTime {
                year: 2026,
                month: 12,
                day_of_week: 3,
                day: 2,
                hour: 9,
                minute: 48,
                second: 0,
                millisecond: 123
            }
        );
        // The first accepted instant, a Saturday, and the last one.
        let first = civil(EARLIEST_MS).unwrap();
        assert_eq!((first.year, first.month, first.day, first.day_of_week, first.hour), (2000, 1, 1, 6, 0));
        let last = civil(END_MS - 1).unwrap();
        assert_eq!((last.year, last.month, last.day, last.hour, last.minute, last.second), (9999, 12, 31, 23, 59, 59));
        assert_eq!(last.millisecond, 999);
    }

    #[test]
    fn times_outside_the_range_are_refused_by_name() {
        for bad in [0, EARLIEST_MS - 1, END_MS, -5, 1_796_204_880] {
            let err = check(bad).unwrap_err();
            assert!(err.contains(&bad.to_string()) && err.contains("milliseconds since 1970"), "{err}");
            assert!(civil(bad).is_err());
        }
    }

    #[test]
    fn the_correction_is_how_far_behind_the_guest_was() {
        let set = ClockSetResult { previous_unix_ms: 1_000_000_000_000, unix_ms: 1_000_000_090_500 };
        assert_eq!(set.corrected_ms(), 90_500);
        let ahead = ClockSetResult { previous_unix_ms: 1_000_000_001_000, unix_ms: 1_000_000_000_000 };
        assert_eq!(ahead.corrected_ms(), -1000);
        assert!(now_unix_ms() > EARLIEST_MS);
    }
}
