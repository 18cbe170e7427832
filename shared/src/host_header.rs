//! The `Host` header rules of the project's servers, against DNS rebinding: a web
//! page whose name is made to resolve to this machine still sends its own name as
//! `Host`, so a server answers only names that are this machine's by definition.
//!
//! The guest's server takes any address and the loopback names (plus the names its
//! operator allows); `arena env serve` without a token takes loopback only
//! ([`is_loopback`]). Loopback names are `localhost` and any `*.localhost`, which
//! RFC 6761 (section 6.3) reserves for the loopback interface.

use std::net::IpAddr;

/// The name or address of a `Host` value, without its port or IPv6 brackets
/// (`[::1]:80` gives `::1`, `example.com:8000` gives `example.com`). A value whose
/// part after the last colon is not a port is returned whole.
pub fn name(host: &str) -> &str {
    if let Some(rest) = host.strip_prefix('[') {
        return rest.split(']').next().unwrap_or(rest);
    }
    match host.rsplit_once(':') {
        Some((name, port)) if port.chars().all(|c| c.is_ascii_digit()) => name,
        _ => host,
    }
}

/// Whether `name` (see [`name`]) is `localhost` or a name under it, in any case.
pub fn is_localhost(name: &str) -> bool {
    const SUFFIX: &str = ".localhost";
    name.eq_ignore_ascii_case("localhost")
        || (name.len() > SUFFIX.len()
            && name.is_char_boundary(name.len() - SUFFIX.len())
            && name[name.len() - SUFFIX.len()..].eq_ignore_ascii_case(SUFFIX))
}

/// Whether `host` (a `Host` value, port allowed) names the loopback interface: a
/// loopback name or a loopback address.
pub fn is_loopback(host: &str) -> bool {
    let name = name(host);
    is_localhost(name) || name.parse::<IpAddr>().is_ok_and(|ip| ip.is_loopback())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_lose_their_port_and_brackets_only() {
        for (host, expected) in [
            ("localhost", "localhost"),
            ("localhost:8766", "localhost"),
            ("[::1]:8766", "::1"),
            ("[::1]", "::1"),
            ("10.0.0.2:5000", "10.0.0.2"),
            ("example.com:http", "example.com:http"),
            ("", ""),
        ] {
            assert_eq!(name(host), expected, "{host}");
        }
    }

    #[test]
    fn only_loopback_names_and_addresses_are_loopback() {
        for host in [
            "localhost",
            "localhost:8766",
            "LOCALHOST",
            "app.localhost:80",
            "A.B.LocalHost",
            "127.0.0.1",
            "127.0.0.1:0",
            "127.1.2.3:9",
            "[::1]",
            "[::1]:8766",
        ] {
            assert!(is_loopback(host), "{host}");
        }
        for host in [
            "",
            ".localhost",
            "example.com",
            "example.com:8766",
            "10.0.0.2:8766",
            "[::2]:1",
            "localhost.example.com",
            "notlocalhost",
            "127.0.0.1.nip.io",
            "éélocalhost",
        ] {
            assert!(!is_loopback(host), "{host}");
        }
    }
}
