//! Chrome's `History` SQLite database for the `update_browse_history` steps.
//!
//! Upstream copies an empty History file shipped with its host, inserts one
//! `urls` row and one `visits` row per entry, and uploads the file over the
//! profile's. Here the database is created from Chrome's schema (the tables
//! and columns a current Chrome History has; no `meta` table, so Chrome stamps
//! its own schema version when it opens the file instead of migrating ours)
//! and filled the same way. Times are WebKit timestamps: microseconds since
//! 1601-01-01 UTC. Upstream computed them from the host's local time, which is
//! off by the host's UTC offset; this uses UTC, as Chrome does.
//!
//! The file goes where the browser keeps its profile ([`guest_path`], by
//! `arena_client::browser::profile`'s rule, which the history getters read by too).
//!
//! It is not a history reader: evaluators read the file back with their own getters.

use std::time::{Duration, SystemTime, UNIX_EPOCH};

use rusqlite::{params, Connection};

use arena_client::browser::profile;
use arena_client::client::GuestClient;
use arena_task::{Browser, HistoryEntry};

/// Seconds from 1601-01-01 to 1970-01-01.
const WEBKIT_TO_UNIX_SECS: i64 = 11_644_473_600;
/// `PAGE_TRANSITION_LINK | CHAIN_START | CHAIN_END`, what upstream writes for every visit.
pub const VISIT_TRANSITION: i64 = 805_306_368;

/// Chrome's History tables (those a fresh profile has), created empty.
const SCHEMA: &str = "
CREATE TABLE urls(id INTEGER PRIMARY KEY AUTOINCREMENT, url LONGVARCHAR, title LONGVARCHAR,
    visit_count INTEGER DEFAULT 0 NOT NULL, typed_count INTEGER DEFAULT 0 NOT NULL,
    last_visit_time INTEGER NOT NULL, hidden INTEGER DEFAULT 0 NOT NULL);
CREATE INDEX urls_url_index ON urls (url);
CREATE TABLE visits(id INTEGER PRIMARY KEY AUTOINCREMENT, url INTEGER NOT NULL, visit_time INTEGER NOT NULL,
    from_visit INTEGER, external_referrer_url TEXT, transition INTEGER DEFAULT 0 NOT NULL, segment_id INTEGER,
    visit_duration INTEGER DEFAULT 0 NOT NULL, incremented_omnibox_typed_score BOOLEAN DEFAULT FALSE NOT NULL,
    opener_visit INTEGER, originator_cache_guid TEXT, originator_visit_id INTEGER, originator_from_visit INTEGER,
    originator_opener_visit INTEGER, is_known_to_sync BOOLEAN DEFAULT FALSE NOT NULL,
    consider_for_ntp_most_visited BOOLEAN DEFAULT FALSE NOT NULL, visited_link_id INTEGER DEFAULT 0 NOT NULL,
    app_id TEXT);
CREATE INDEX visits_url_index ON visits (url);
CREATE INDEX visits_from_index ON visits (from_visit);
CREATE INDEX visits_time_index ON visits (visit_time);
CREATE INDEX visits_originator_id_index ON visits (originator_visit_id);
CREATE TABLE visit_source(id INTEGER PRIMARY KEY, source INTEGER NOT NULL);
CREATE TABLE keyword_search_terms (keyword_id INTEGER NOT NULL, url_id INTEGER NOT NULL,
    term LONGVARCHAR NOT NULL, normalized_term LONGVARCHAR NOT NULL);
CREATE INDEX keyword_search_terms_index1 ON keyword_search_terms (keyword_id, normalized_term);
CREATE INDEX keyword_search_terms_index2 ON keyword_search_terms (url_id);
CREATE INDEX keyword_search_terms_index3 ON keyword_search_terms (term);
CREATE TABLE segments (id INTEGER PRIMARY KEY, name VARCHAR, url_id INTEGER NON NULL);
CREATE INDEX segments_name ON segments(name);
CREATE INDEX segments_url_id ON segments(url_id);
CREATE TABLE segment_usage (id INTEGER PRIMARY KEY, segment_id INTEGER NOT NULL, time_slot INTEGER NOT NULL,
    visit_count INTEGER DEFAULT 0 NOT NULL);
CREATE INDEX segment_usage_time_slot_segment_id ON segment_usage(time_slot, segment_id);
CREATE INDEX segments_usage_seg_id ON segment_usage(segment_id);
CREATE TABLE downloads (id INTEGER PRIMARY KEY, guid VARCHAR NOT NULL, current_path LONGVARCHAR NOT NULL,
    target_path LONGVARCHAR NOT NULL, start_time INTEGER NOT NULL, received_bytes INTEGER NOT NULL,
    total_bytes INTEGER NOT NULL, state INTEGER NOT NULL, danger_type INTEGER NOT NULL,
    interrupt_reason INTEGER NOT NULL, hash BLOB NOT NULL, end_time INTEGER NOT NULL, opened INTEGER NOT NULL,
    last_access_time INTEGER NOT NULL, transient INTEGER NOT NULL, referrer VARCHAR NOT NULL,
    site_url VARCHAR NOT NULL, embedder_download_data VARCHAR NOT NULL, tab_url VARCHAR NOT NULL,
    tab_referrer_url VARCHAR NOT NULL, http_method VARCHAR NOT NULL, by_ext_id VARCHAR NOT NULL,
    by_ext_name VARCHAR NOT NULL, by_web_app_id VARCHAR NOT NULL, etag VARCHAR NOT NULL,
    last_modified VARCHAR NOT NULL, mime_type VARCHAR(255) NOT NULL, original_mime_type VARCHAR(255) NOT NULL);
CREATE TABLE downloads_url_chains (id INTEGER NOT NULL, chain_index INTEGER NOT NULL, url LONGVARCHAR NOT NULL,
    PRIMARY KEY (id, chain_index));
CREATE TABLE downloads_slices (download_id INTEGER NOT NULL, offset INTEGER NOT NULL,
    received_bytes INTEGER NOT NULL, finished INTEGER NOT NULL DEFAULT 0, PRIMARY KEY (download_id, offset));
";

/// The guest path of a browser's History file: under the user-data folder
/// [`profile::user_data_dir`] finds, the folder the history getters read.
///
/// # Errors
///
/// The rule's error as text: a failed guest call or a policy naming no usable folder.
pub async fn guest_path(client: &GuestClient, browser: Browser) -> Result<String, String> {
    let browser = match browser {
        Browser::Chrome => profile::Browser::Chrome,
        Browser::Edge => profile::Browser::Edge,
    };
    let dir = profile::user_data_dir(client, browser).await.map_err(|err| err.to_string())?;
    Ok(dir.file(profile::HISTORY))
}

/// Microseconds since 1601-01-01 UTC of `time` (Chrome's `base::Time` internal value).
pub fn webkit_micros(time: SystemTime) -> i64 {
    let since_unix = match time.duration_since(UNIX_EPOCH) {
        Ok(d) => i64::try_from(d.as_micros()).unwrap_or(i64::MAX),
        Err(before) => -i64::try_from(before.duration().as_micros()).unwrap_or(i64::MAX),
    };
    since_unix.saturating_add(WEBKIT_TO_UNIX_SECS * 1_000_000)
}

/// `now` minus a task's `visit_time_from_now_in_seconds` (negative values lie in the future).
fn visit_time(now: SystemTime, seconds_ago: f64) -> SystemTime {
    let magnitude = Duration::try_from_secs_f64(seconds_ago.abs()).unwrap_or(Duration::ZERO);
    let shifted = if seconds_ago >= 0.0 { now.checked_sub(magnitude) } else { now.checked_add(magnitude) };
    shifted.unwrap_or(now)
}

/// Builds a History database holding `entries`, visited relative to `now`, and answers its bytes.
///
/// # Errors
///
/// The SQLite or file error, as text, when the database cannot be built in a temporary file.
pub fn build(entries: &[HistoryEntry], now: SystemTime) -> Result<Vec<u8>, String> {
    let dir = tempfile::tempdir().map_err(|err| format!("cannot make a temporary folder: {err}"))?;
    let path = dir.path().join("History");
    {
        let mut db = Connection::open(&path).map_err(|err| format!("cannot create {}: {err}", path.display()))?;
        db.execute_batch(SCHEMA).map_err(|err| format!("cannot create the History tables: {err}"))?;
        let tx = db.transaction().map_err(|err| err.to_string())?;
        for entry in entries {
            let time = webkit_micros(visit_time(now, entry.visit_time_from_now_in_seconds));
            tx.execute(
                "INSERT INTO urls (url, title, visit_count, typed_count, last_visit_time, hidden) VALUES (?1, ?2, 1, 0, ?3, 0)",
                params![entry.url, entry.title, time],
            )
            .map_err(|err| format!("inserting {}: {err}", entry.url))?;
            let url_id = tx.last_insert_rowid();
            tx.execute(
                "INSERT INTO visits (url, visit_time, from_visit, transition, segment_id, visit_duration) VALUES (?1, ?2, 0, ?3, 0, 0)",
                params![url_id, time, VISIT_TRANSITION],
            )
            .map_err(|err| format!("inserting the visit of {}: {err}", entry.url))?;
        }
        tx.commit().map_err(|err| err.to_string())?;
    }
    std::fs::read(&path).map_err(|err| format!("cannot read back {}: {err}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn webkit_time_counts_from_1601() {
        assert_eq!(webkit_micros(UNIX_EPOCH), 11_644_473_600_000_000);
        assert_eq!(webkit_micros(UNIX_EPOCH + Duration::from_secs(1)), 11_644_473_601_000_000);
        assert_eq!(webkit_micros(UNIX_EPOCH - Duration::from_secs(1)), 11_644_473_599_000_000);
    }

    #[test]
    fn visits_lie_the_given_seconds_before_now() {
        let now = UNIX_EPOCH + Duration::from_secs(1_000_000);
        assert_eq!(visit_time(now, 60.0), UNIX_EPOCH + Duration::from_secs(999_940));
        assert_eq!(visit_time(now, -1.5), UNIX_EPOCH + Duration::from_millis(1_000_001_500));
        assert_eq!(visit_time(now, f64::NAN), now);
    }

    #[test]
    fn the_database_holds_one_url_and_one_visit_per_entry() {
        let now = UNIX_EPOCH + Duration::from_secs(1_700_000_000);
        let entries = vec![
            HistoryEntry {
                url: "https://a.example/".into(),
                title: "A".into(),
                visit_time_from_now_in_seconds: 3600.0,
            },
            HistoryEntry { url: "https://b.example/".into(), title: "B".into(), visit_time_from_now_in_seconds: 0.0 },
        ];
        let bytes = build(&entries, now).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("History");
        std::fs::write(&path, bytes).unwrap();
        let db = Connection::open(&path).unwrap();
        let mut rows = db
            .prepare("SELECT u.url, u.title, u.visit_count, u.last_visit_time, v.visit_time, v.transition FROM urls u JOIN visits v ON v.url = u.id ORDER BY u.id")
            .unwrap();
        let rows: Vec<(String, String, i64, i64, i64, i64)> = rows
            .query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?, r.get(3)?, r.get(4)?, r.get(5)?)))
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap();
        let now_webkit = 11_644_473_600_000_000 + 1_700_000_000_000_000;
        assert_eq!(
            rows,
            vec![
                (
                    "https://a.example/".into(),
                    "A".into(),
                    1,
                    now_webkit - 3_600_000_000,
                    now_webkit - 3_600_000_000,
                    VISIT_TRANSITION
                ),
                ("https://b.example/".into(), "B".into(), 1, now_webkit, now_webkit, VISIT_TRANSITION),
            ]
        );
    }
}
