//! The proleptic Gregorian calendar as day counts since 1970-01-01, the one date
//! arithmetic of the workspace (timestamps in reports and result folders, `strftime`
//! in getters, Excel serial dates in the evaluators).
//!
//! The era-based method: 400-year eras of 146 097 days, years counted from March so
//! the leap day falls last (Howard Hinnant's `days_from_civil` and `civil_from_days`,
//! "chrono-Compatible Low-Level Date Algorithms"). It is not a time-zone library: every
//! date here is UTC, and no date crate is needed for these few conversions.

/// Days from 1970-01-01 to the day count's date, as (year, month 1 to 12, day 1 to 31).
pub fn civil_from_days(days: i64) -> (i64, u32, u32) {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let day_of_era = z.rem_euclid(146_097);
    let year_of_era = (day_of_era - day_of_era / 1460 + day_of_era / 36_524 - day_of_era / 146_096) / 365;
    let day_of_year = day_of_era - (365 * year_of_era + year_of_era / 4 - year_of_era / 100);
    let month_index = (5 * day_of_year + 2) / 153;
    // In range by construction: a day of 1 to 31, a month of 1 to 12.
    let day = (day_of_year - (153 * month_index + 2) / 5 + 1) as u32;
    let month = if month_index < 10 { month_index + 3 } else { month_index - 9 } as u32;
    let year = year_of_era + era * 400 + i64::from(month <= 2);
    (year, month, day)
}

/// Days from 1970-01-01 to `year-month-day` (negative before it); the inverse of
/// [`civil_from_days`]. Months outside 1 to 12 and days past a month's end count on
/// as the arithmetic gives, so callers check their input first.
pub fn days_from_civil(year: i64, month: u32, day: u32) -> i64 {
    let year = if month <= 2 { year - 1 } else { year };
    let era = year.div_euclid(400);
    let year_of_era = year.rem_euclid(400);
    let month = i64::from(month);
    let day_of_year = (153 * (if month > 2 { month - 3 } else { month + 9 }) + 2) / 5 + i64::from(day) - 1;
    let day_of_era = year_of_era * 365 + year_of_era / 4 - year_of_era / 100 + day_of_year;
    era * 146_097 + day_of_era - 719_468
}

/// `YYYY-MM-DD HH:MM:SS` of seconds since the Unix epoch (UTC).
pub fn iso_seconds(secs: i64) -> String {
    let (year, month, day) = civil_from_days(secs.div_euclid(86_400));
    let rem = secs.rem_euclid(86_400);
    format!("{year:04}-{month:02}-{day:02} {:02}:{:02}:{:02}", rem / 3600, rem % 3600 / 60, rem % 60)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_dates_and_the_round_trip() {
        assert_eq!(civil_from_days(0), (1970, 1, 1));
        assert_eq!(civil_from_days(-1), (1969, 12, 31));
        // 2024-02-29, a leap day, and the day after.
        assert_eq!(civil_from_days(19_782), (2024, 2, 29));
        assert_eq!(civil_from_days(19_783), (2024, 3, 1));
        assert_eq!(days_from_civil(1899, 12, 30), -25_569);
        assert_eq!(days_from_civil(2000, 3, 1), 11_017);
        for days in [-800_000, -25_569, -1000, 0, 59, 60, 365, 10_956, 20_000, 60_000, 2_932_896] {
            let (y, m, d) = civil_from_days(days);
            assert_eq!(days_from_civil(y, m, d), days, "{y}-{m}-{d}");
        }
        assert_eq!(iso_seconds(1_709_211_909), "2024-02-29 13:05:09");
        assert_eq!(iso_seconds(-1), "1969-12-31 23:59:59");
    }
}
