//! Table-driven tests of the browser metrics: a passing and a failing case
//! each, on values shaped as the browser getters return them, plus the errors
//! upstream raises; and Python's `urlparse`/`compare_urls` on their edge cases.

use serde_json::{json, Map, Value};

use super::{compare_urls, lookup, urlparse, urlunparse};
use crate::metrics::MetricInput;
use crate::value::Fetched;
use crate::LastAction;

/// What a case should give: a score, or an error whose message contains the text.
#[derive(Debug)]
enum Want {
    Score(f64),
    Error(&'static str),
}
use Want::{Error, Score};

/// Runs `metric` on `result` with `rules` as the expected value.
fn check(metric: &str, result: Fetched, rules: Value, want: Want) {
    let f = lookup(metric).unwrap_or_else(|| panic!("metric {metric} is not registered"));
    let input = MetricInput {
        result,
        expected: Some(Fetched::Json(rules)),
        options: Map::new(),
        last_action: Some(LastAction::Done),
    };
    let got = f(&input);
    match (&got, &want) {
        (Ok(score), Score(expected)) => assert_eq!(score, expected, "{metric} on {input:?}"),
        (Err(err), Error(text)) => assert!(err.to_string().contains(text), "{metric}: error {err} lacks {text:?}"),
        _ => panic!("{metric} on {input:?}: got {got:?}, want {want:?}"),
    }
}

fn data(value: Value) -> Fetched {
    Fetched::Json(value)
}

#[test]
fn bookmarks_on_the_bar() {
    let roots = json!({"bookmark_bar": {"children": [
        {"type": "url", "name": "Transformer", "url": "https://jalammar.github.io/illustrated-transformer/"},
        {"type": "url", "name": "Other", "url": "https://example.org/"},
        {"type": "folder", "name": "Reading", "children": []},
        {"type": "folder", "name": "Liked Authors", "children": [
            {"type": "url", "name": "A", "url": "https://a.example/"},
            {"type": "url", "name": "B", "url": "https://b.example/"},
        ]},
    ]}});
    let urls = |u: Value| json!({"type": "bookmark_bar_websites_urls", "urls": u});
    let cases = [
        (data(roots.clone()), urls(json!(["https://jalammar.github.io/illustrated-transformer/"])), Score(1.0)),
        (data(roots.clone()), urls(json!(["https://jalammar.github.io/illustrated-transformer"])), Score(0.0)),
        (data(json!([])), urls(json!(["https://x/"])), Score(0.0)),
        (data(json!({})), urls(json!(["https://x/"])), Score(0.0)),
        (data(roots.clone()), json!({"type": "bookmark_bar_folders_names", "names": ["Reading"]}), Score(1.0)),
        (data(roots.clone()), json!({"type": "bookmark_bar_folders_names", "names": ["Reading", "Work"]}), Score(0.0)),
        (
            data(roots.clone()),
            json!({"type": "liked_authors_websites_urls", "urls": [["https://a.example/", "https://a2.example/"], "https://b.example/"]}),
            Score(1.0),
        ),
        (
            data(roots.clone()),
            json!({"type": "liked_authors_websites_urls", "urls": ["https://a.example/"]}),
            Score(0.0),
        ),
        (data(roots.clone()), json!({"type": "other_bar", "urls": []}), Error("not supported")),
        (data(json!({"other": {}})), urls(json!([])), Error("has no \"bookmark_bar\"")),
    ];
    for (result, rules, want) in cases {
        check("is_expected_bookmarks", result, rules, want);
    }
}

#[test]
fn cookies_and_history_deleted() {
    let cookie = |host: &str| json!([13_350_000_000_000_000_i64, host, "", "session-id", "", "763130", "/"]);
    let domains = json!({"type": "domains", "domains": [".amazon.com"]});
    let cases = [
        (data(json!([cookie(".google.com"), cookie("www.amazon.com")])), domains.clone(), Score(1.0)),
        (data(json!([])), domains.clone(), Score(1.0)),
        (data(json!([cookie(".google.com"), cookie(".amazon.com")])), domains.clone(), Score(0.0)),
        (data(json!([cookie(".google.com")])), json!({"type": "names", "names": []}), Error("not supported")),
        (Fetched::None, domains.clone(), Error("must be a list")),
        (data(json!([[1]])), domains, Error("no column 1")),
    ];
    for (result, rules, want) in cases {
        check("is_cookie_deleted", result, rules, want);
    }

    let visit = |url: &str| json!([url, "title", 13_350_000_000_000_000_i64]);
    let keywords = json!({"type": "keywords", "keywords": ["youtube"]});
    let cases = [
        (
            data(json!([visit("https://example.org/"), visit("https://www.google.com/search?q=tube")])),
            keywords.clone(),
            Score(1.0),
        ),
        (
            data(json!([visit("https://example.org/"), visit("https://www.youtube.com/watch?v=1")])),
            keywords.clone(),
            Score(0.0),
        ),
        (data(json!([visit("https://example.org/")])), json!({"type": "urls"}), Error("not supported")),
        (data(json!([[null, "t", 1]])), keywords, Error("cannot search")),
    ];
    for (result, rules, want) in cases {
        check("check_history_deleted", result, rules, want);
    }
}

#[test]
fn experiments_and_font_sizes() {
    let names = json!({"type": "names", "names": ["show-performance-metrics-hud"]});
    let cases = [
        (data(json!(["show-performance-metrics-hud@1"])), names.clone(), Score(1.0)),
        (data(json!(["show-performance-metrics-hud@1", "smooth-scrolling@2"])), names.clone(), Score(0.0)),
        (data(json!([])), names.clone(), Score(0.0)),
        (data(json!([])), json!({"type": "ids", "names": []}), Error("not supported")),
    ];
    for (result, rules, want) in cases {
        check("check_enabled_experiments", result, rules, want);
    }

    let range = |min: i64| json!({"type": "range", "min": min, "max": 99999});
    let size = |n: i64| data(json!({"default_fixed_font_size": 13, "default_font_size": n}));
    // Chrome's bound is strict, Edge's inclusive: 24 is "at least 24" only for Edge.
    let cases = [
        ("check_font_size", size(24), range(16), Score(1.0)),
        ("check_font_size", size(16), range(16), Score(0.0)),
        ("check_edge_font_size", size(24), range(24), Score(1.0)),
        ("check_edge_font_size", size(20), range(24), Score(0.0)),
        ("check_font_size", size(20), json!({"type": "value", "value": 20}), Score(1.0)),
        ("check_edge_font_size", size(20), json!({"type": "value", "value": 24}), Score(0.0)),
        ("check_font_size", data(json!({"minimum_font_size": 6})), range(16), Error("no \"default_font_size\"")),
        ("check_edge_font_size", size(20), json!({"type": "largest"}), Error("not supported")),
        ("check_font_size", data(json!({"default_font_size": "24"})), range(16), Error("must be a number")),
    ];
    for (metric, result, rules, want) in cases {
        check(metric, result, rules, want);
    }
}

#[test]
fn tabs_and_the_active_tab() {
    let tabs = |urls: &[&str]| data(Value::Array(urls.iter().map(|u| json!({"title": "t", "url": u})).collect()));
    let expected = json!({"type": "url", "urls": ["https://www.lonelyplanet.com", "https://www.airbnb.com", "https://www.tripadvisor.com"]});
    let cases = [
        (
            tabs(&["https://www.tripadvisor.com/", "https://lonelyplanet.com/", "https://airbnb.com"]),
            expected.clone(),
            Score(1.0),
        ),
        (tabs(&["https://www.tripadvisor.com/", "https://lonelyplanet.com/"]), expected.clone(), Score(0.0)),
        (
            tabs(&["https://www.tripadvisor.com/", "https://lonelyplanet.com/", "https://www.airbnb.com/rooms"]),
            expected.clone(),
            Score(0.0),
        ),
        (tabs(&[]), json!({"type": "title"}), Score(0.0)),
        (data(json!([{"title": "no url"}])), expected, Error("has no \"url\"")),
    ];
    for (result, rules, want) in cases {
        check("is_expected_tabs", result, rules, want);
    }

    let rule = json!({"type": "url", "url": "https://discussions.flightaware.com/t/the-banter-thread/4412"});
    let cases = [
        (
            data(
                json!({"title": "Banter", "url": "https://discussions.flightaware.com/t/the-banter-thread/4412", "content": ""}),
            ),
            rule.clone(),
            Score(1.0),
        ),
        (
            Fetched::Text("https://discussions.flightaware.com/t/the-banter-thread/4412".into()),
            rule.clone(),
            Score(1.0),
        ),
        (
            data(json!({"url": "https://discussions.flightaware.com/t/the-banter-thread/4412/200"})),
            rule.clone(),
            Score(0.0),
        ),
        (Fetched::None, rule.clone(), Score(0.0)),
        (data(json!({"url": "x"})), json!({"type": "title"}), Score(0.0)),
        (data(json!({"url": 5})), rule, Error("must be a string")),
    ];
    for (result, rules, want) in cases {
        check("is_expected_active_tab", result, rules, want);
    }

    let items = json!({"items": ["The Dota 2 Official Soundtrack"]});
    let page = |content: &str| {
        data(json!({"title": "Shopping Cart", "url": "https://store.steampowered.com/cart/", "content": content}))
    };
    let cases = [
        (page("Your cart\nThe Dota 2 Official Soundtrack\n$9.99"), items.clone(), Score(1.0)),
        (page("Your cart is empty"), items.clone(), Score(0.0)),
        (data(json!({"title": "x"})), items, Error("has no \"content\"")),
    ];
    for (result, rules, want) in cases {
        check("is_added_to_steam_cart", result, rules, want);
    }
}

#[test]
fn desktop_shortcuts() {
    let lnk =
        |description: &str| json!({"header": {}, "data": {"description": description}, "link_info": {}}).to_string();
    let description =
        json!({"type": "description", "description": "Play Puzzle Game 2048. Use your arrow keys to move the tiles."});
    let cases = [
        (
            data(
                json!({"2048.lnk": lnk("Play Puzzle Game 2048. Use your arrow keys to move the tiles. Join the numbers.")}),
            ),
            description.clone(),
            Score(1.0),
        ),
        (data(json!({"Other.lnk": lnk("Something else"), "bad.lnk": "not json"})), description.clone(), Score(0.0)),
        (data(json!({})), description.clone(), Score(0.0)),
        (
            data(json!({"a.desktop": "[Desktop Entry]\nName=2048\nExec=x\n"})),
            json!({"type": "name", "name": "2048"}),
            Score(1.0),
        ),
        (
            data(json!({"a.desktop": "[Desktop Entry]\nName=2048 Game\n"})),
            json!({"type": "name", "name": "2048"}),
            Score(0.0),
        ),
        (
            data(json!({"a.url": "[InternetShortcut]\r\nURL=https://www.mathsisfun.com/games/2048.html\r\n"})),
            json!({"type": "url", "url": "https://mathsisfun.com/games/2048.html"}),
            Error("not supported"),
        ),
        (data(json!({"a.lnk": lnk("x")})), json!({"type": "id", "id": "x"}), Error("not supported")),
        (data(json!(["a.lnk"])), description, Error("must be a dict")),
    ];
    for (result, rules, want) in cases {
        check("is_shortcut_on_desktop", result, rules, want);
    }

    let rule = json!({"type": "url", "url_content": "https://www.mathsisfun.com/games/2048.html"});
    let cases = [
        (
            data(json!({"2048.url": "[InternetShortcut]\r\nURL=https://www.mathsisfun.com/games/2048.html\r\n"})),
            rule.clone(),
            Score(1.0),
        ),
        (
            data(json!({"2048.url": "[InternetShortcut]\r\nURL=https://www.mathsisfun.com/\r\n"})),
            rule.clone(),
            Score(0.0),
        ),
        (data(json!({"2048.url": "URL=x"})), json!({"type": "name"}), Error("not supported")),
    ];
    for (result, rules, want) in cases {
        check("is_url_shortcut_on_desktop", result, rules, want);
    }
}

#[test]
fn urlparse_splits_like_python() {
    let check = |url: &str, parts: [&str; 6]| {
        let got = urlparse(url);
        assert_eq!([&*got.scheme, &*got.netloc, &*got.path, &*got.params, &*got.query, &*got.fragment], parts, "{url}");
    };
    check("https://www.Example.org/a/b;p?q=1#frag", ["https", "www.Example.org", "/a/b", "p", "q=1", "frag"]);
    check(".amazon.com", ["", "", ".amazon.com", "", "", ""]);
    check("HTTP://x", ["http", "x", "", "", "", ""]);
    check("localhost:8080/x", ["localhost", "", "8080/x", "", "", ""]);
    check("1http://x", ["", "", "1http://x", "", "", ""]);
    check("  \thttp://x/\n", ["http", "x", "/", "", "", ""]);
    check("//host/p?x#y?z", ["", "host", "/p", "", "x", "y?z"]);
    check("mailto:a@b;c", ["mailto", "", "a@b;c", "", "", ""]);

    let round = |url: &str, want: &str| assert_eq!(urlunparse(&urlparse(url)), want, "{url}");
    round("https://x/a;p?q#f", "https://x/a;p?q#f");
    round("http:///path", "http:///path");
    round("path?q", "path?q");
}

#[test]
fn compare_urls_normalises_like_upstream() {
    let check = |a: Option<&str>, b: Option<&str>, equal: bool| {
        assert_eq!(compare_urls(a, b), equal, "{a:?} vs {b:?}");
        assert_eq!(compare_urls(b, a), equal, "{b:?} vs {a:?}");
    };
    check(Some("https://www.airbnb.com"), Some("https://airbnb.com/"), true);
    check(Some("https://WWW.Airbnb.com/"), Some("https://airbnb.com"), true);
    check(Some("airbnb.com"), Some("http:airbnb.com"), true);
    check(Some("https://airbnb.com"), Some("http://airbnb.com"), false);
    check(Some("https://airbnb.com/a"), Some("https://airbnb.com/a/"), false);
    check(Some(".amazon.com"), Some(".amazon.com"), true);
    check(Some(".amazon.com"), Some("www.amazon.com"), false);
    check(Some("https://x.com/?a=1"), Some("https://x.com?a=1"), true);
    check(None, None, true);
    check(None, Some(""), false);
}
