//! The Host allow-list, against DNS rebinding: a page on `evil.example`
//! whose name is made to resolve to 127.0.0.1 reaches a loopback server
//! from the visitor's browser as a same-origin request, but its `Host`
//! header still says `evil.example`, so such requests are refused.

use std::net::SocketAddr;

/// Which `Host` headers a server answers.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum AllowedHosts {
    /// Any host (a server reachable under names it cannot know).
    Any,
    /// These host names or `host:port` pairs, lowercase.
    List(Vec<String>),
}

/// Names of the loopback interface, allowed by default on a loopback
/// address.
pub const LOOPBACK_HOSTS: [&str; 3] = ["localhost", "127.0.0.1", "[::1]"];

impl AllowedHosts {
    /// The allow-list of `--allowed-hosts` for a server bound to `addr`:
    /// the given entries (`*` alone: any host); without any, the loopback
    /// names on a loopback address and any host elsewhere.
    pub fn resolve(given: &[String], addr: SocketAddr) -> Result<AllowedHosts, String> {
        let given: Vec<String> = given
            .iter()
            .map(|h| h.trim())
            .filter(|h| !h.is_empty())
            .map(normalise)
            .collect();
        if given.iter().any(|h| h == "*") {
            if given.len() > 1 {
                return Err("`*` allows any host and cannot be listed with others".into());
            }
            return Ok(AllowedHosts::Any);
        }
        for h in &given {
            if split_host(h).is_none() {
                return Err(format!(
                    "`{h}` is not a host name, an IP address or host:port"
                ));
            }
        }
        if !given.is_empty() {
            return Ok(AllowedHosts::List(given));
        }
        if addr.ip().is_loopback() {
            Ok(AllowedHosts::List(
                LOOPBACK_HOSTS.iter().map(|h| h.to_string()).collect(),
            ))
        } else {
            Ok(AllowedHosts::Any)
        }
    }

    /// Whether a request whose `Host` is `host` is allowed. One without
    /// any (HTTP/1.0) is: browsers, through which rebinding works, always
    /// send it.
    pub fn allows(&self, host: Option<&str>) -> bool {
        let AllowedHosts::List(list) = self else {
            return true;
        };
        let Some(given) = host.map(normalise) else {
            return true;
        };
        let Some((name, _)) = split_host(&given) else {
            return false;
        };
        list.iter().any(|entry| match split_host(entry) {
            Some((n, None)) => n == name,
            Some(_) => *entry == given,
            None => false,
        })
    }
}

/// Lowercase, without the trailing dot of a fully qualified name.
fn normalise(h: &str) -> String {
    let h = h.trim().to_ascii_lowercase();
    match h.split_once(':') {
        _ if h.starts_with('[') => h,
        Some((name, port)) => format!("{}:{port}", name.trim_end_matches('.')),
        None => h.trim_end_matches('.').to_string(),
    }
}

/// Splits `host[:port]` (`[v6]` literals kept in brackets); None when it is
/// no valid authority.
fn split_host(h: &str) -> Option<(&str, Option<u16>)> {
    let (name, port) = if h.starts_with('[') {
        let end = h.find(']')?;
        let rest = &h[end + 1..];
        let port = match rest {
            "" => None,
            _ => Some(rest.strip_prefix(':')?),
        };
        (&h[..=end], port)
    } else {
        match h.rsplit_once(':') {
            Some((n, p)) => (n, Some(p)),
            None => (h, None),
        }
    };
    let port = match port {
        None => None,
        Some(p) => Some(p.parse::<u16>().ok()?),
    };
    let ok = match name.strip_prefix('[').and_then(|n| n.strip_suffix(']')) {
        Some(v6) => v6.parse::<std::net::Ipv6Addr>().is_ok(),
        None => {
            !name.is_empty()
                && name
                    .bytes()
                    .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'-' | b'.' | b'_'))
        }
    };
    ok.then_some((name, port))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn list(given: &[&str], addr: &str) -> AllowedHosts {
        let given: Vec<String> = given.iter().map(|s| s.to_string()).collect();
        AllowedHosts::resolve(&given, addr.parse().unwrap()).unwrap()
    }

    #[test]
    fn loopback_default_allows_loopback_names_on_any_port() {
        let a = list(&[], "127.0.0.1:8080");
        for ok in [
            "localhost",
            "localhost:8080",
            "LOCALHOST:1",
            "localhost.:80",
            "127.0.0.1:9",
            "[::1]",
            "[::1]:8080",
        ] {
            assert!(a.allows(Some(ok)), "{ok}");
        }
        for bad in [
            "evil.example",
            "evil.example:8080",
            "localhost.evil.example",
            "127.0.0.2",
            "[::2]:80",
            "localhost:notaport",
            "",
        ] {
            assert!(!a.allows(Some(bad)), "{bad}");
        }
        assert!(a.allows(None));
        assert_eq!(list(&[], "[::1]:80"), a);
    }

    #[test]
    fn other_addresses_allow_any_unless_configured() {
        assert_eq!(list(&[], "0.0.0.0:8080"), AllowedHosts::Any);
        assert!(list(&[], "0.0.0.0:8080").allows(None));
        assert_eq!(list(&["*"], "127.0.0.1:1"), AllowedHosts::Any);
        let a = list(&["tiles.example", "api.example:8443"], "0.0.0.0:8080");
        assert!(a.allows(Some("tiles.example:8080")));
        assert!(a.allows(Some("Tiles.Example")));
        assert!(a.allows(Some("api.example:8443")));
        assert!(!a.allows(Some("api.example:8080")));
        assert!(!a.allows(Some("localhost")));
    }

    #[test]
    fn bad_entries_are_refused() {
        let addr = "127.0.0.1:1".parse().unwrap();
        for bad in [&["a b"][..], &["x:99999"], &["*", "a"], &["a/b"]] {
            let given: Vec<String> = bad.iter().map(|s| s.to_string()).collect();
            assert!(AllowedHosts::resolve(&given, addr).is_err(), "{bad:?}");
        }
    }
}
