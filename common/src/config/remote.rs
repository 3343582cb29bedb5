//! The session keys of the bridge (issue 17): `[remote]` (this session's topics sent to, or
//! taken from, another machine over zenoh), `[source] kind = "remote"` (a session fed by
//! another machine's session: a viewer) and `[viewer]` (a live Foxglove view).
//!
//! ```toml
//! [remote]                         # the session that sends
//! endpoint = "tls/127.0.0.1:7447"  # zenoh endpoint: tls/HOST:PORT (TLS 1.3, both sides
//!                                  # authenticated; tcp/ only with allow_plain = true)
//! key_dir = "keys"                 # this side's link certificate and key (default: the user's
//!                                  # data folder, handblocks/link); made on first use
//! peer_certificate = "viewer.pem"  # the only peer trusted: the other side's certificate
//!                                  # (default: this side's own: a peer holding the same key)
//! names = ["studio.lan"]           # a listening side's names in its certificate, besides
//!                                  # localhost, its addresses and the endpoint's host
//! role = "listen"                  # "listen" (default: viewers connect here) | "connect"
//! key = "handblocks/live"          # the zenoh key prefix; a topic goes on KEY/TOPIC
//! publish = ["hand", "world"]      # sent out (the default)
//! subscribe = []                   # taken in from the other side (e.g. a remote "frame")
//! wait_for_viewer_s = 30           # start the source only once a viewer takes every topic
//!                                  # sent (up to this long; 0, the default: do not wait)
//!
//! [source]                         # the session that views
//! kind = "remote"
//! endpoint = "tls/127.0.0.1:7447"  # and key_dir, peer_certificate, names as above
//! role = "connect"                 # the default for a remote source
//! key = "handblocks/live"
//! subscribe = ["hand", "world"]    # the default; must hold both (the renderer reads them)
//! publish = ["frame"]              # optional: the renderer's frame stats, sent back
//!
//! [viewer]
//! foxglove = "127.0.0.1:8765"      # serve the live topics over the Foxglove WebSocket protocol
//! foxglove_clients = 8             # clients served at once (1 to 64); the next is answered 503
//! ```

use std::path::{Path, PathBuf};

use super::catalog::Spec;
use super::reader::{quoted, Reader};
use super::ConfigError;
use crate::topic::Topic;

/// The key prefix when a session names none: both halves of a session must use the same one.
pub const DEFAULT_KEY: &str = "handblocks/session";

/// Which side of the zenoh link opens the socket.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkRole {
    /// Listens on `endpoint` (a local address); any number of peers connect to it.
    Listen,
    /// Connects to `endpoint` (the other side's address), and keeps trying until it answers,
    /// so the two halves start in either order.
    Connect,
}

impl LinkRole {
    pub fn name(self) -> &'static str {
        match self {
            LinkRole::Listen => "listen",
            LinkRole::Connect => "connect",
        }
    }
}

/// `[viewer] foxglove_clients` when the session names none.
pub const DEFAULT_FOXGLOVE_CLIENTS: usize = 8;
/// What `[viewer] foxglove_clients` may be: each client costs the bridge two threads and up to
/// a few MiB of queued messages (services/bridge/src/viewer.rs), so a view is for a handful.
pub const FOXGLOVE_CLIENTS: std::ops::RangeInclusive<u64> = 1..=64;

/// How a link is protected (issue 40: a plain TCP link let any peer read every hand and world,
/// and inject its own).
#[derive(Debug, Clone, PartialEq)]
pub enum LinkSecurity {
    /// `tls/`: TLS 1.3, encrypted, and both sides authenticated by certificate (mutual TLS):
    /// each side presents its own certificate and accepts only `peer_certificate`'s. The bridge
    /// carries it on zenoh's QUIC link (UDP; `bridge::link::zenoh_endpoint`).
    Tls {
        /// This side's certificate and key (`certificate.pem`, `key.pem`): made on first use,
        /// kept 0600 in a 0700 folder, renewed before they expire.
        key_dir: PathBuf,
        /// The other side's certificate, the only one trusted; None: this side's own (a peer
        /// that holds the same key: the other half of a session on this machine, or one given
        /// a copy of `key_dir`).
        peer_certificate: Option<PathBuf>,
        /// Names and addresses a connecting side may use for this side, put in its certificate
        /// besides `localhost`, this machine's addresses and the endpoint's host.
        names: Vec<String>,
    },
    /// `tcp/` with `allow_plain = true`: in clear, and any peer may join.
    Plain,
}

/// One zenoh link of a session and the topics that cross it.
#[derive(Debug, Clone, PartialEq)]
pub struct RemoteLink {
    /// `tls/HOST:PORT`, or `tcp/HOST:PORT` for a plain link.
    pub endpoint: String,
    /// TLS with both sides' certificates, or plain.
    pub security: LinkSecurity,
    pub role: LinkRole,
    /// The key prefix: topic `world` travels on `KEY/world`.
    pub key: String,
    /// Topics this session sends (it reads them from its bus).
    pub publish: Vec<Topic>,
    /// Topics this session takes in (the bridge publishes them on its bus).
    pub subscribe: Vec<Topic>,
    /// A session that expects a viewer (`[remote] wait_for_viewer_s`, seconds; 0: none): its
    /// source starts only once a peer takes every topic it sends, as it starts only once its
    /// local readers are attached, so a viewer started first records the session from its
    /// first sample (issue 40: it lost the first 28-39).
    pub wait_for_viewer_s: u64,
}

/// The longest a session waits for its viewer (`wait_for_viewer_s`).
pub const MAX_WAIT_FOR_VIEWER_S: u64 = 600;

/// What the bridge process of a session does; `None` of both: the session has no bridge.
#[derive(Debug, Clone, PartialEq)]
pub struct BridgeSettings {
    pub link: Option<RemoteLink>,
    /// `[shared]`: this session's side of a shared world (docs/sessions.md "Shared sessions").
    pub shared: Option<super::shared::SharedLink>,
    /// `[viewer] foxglove`: host and port of the Foxglove WebSocket server.
    pub foxglove: Option<(String, u16)>,
    /// `[viewer] foxglove_clients`: the most Foxglove clients served at once.
    pub foxglove_clients: usize,
}

impl Default for BridgeSettings {
    fn default() -> Self {
        BridgeSettings {
            link: None,
            shared: None,
            foxglove: None,
            foxglove_clients: DEFAULT_FOXGLOVE_CLIENTS,
        }
    }
}

impl BridgeSettings {
    /// True when the session runs a bridge process.
    pub fn is_on(&self) -> bool {
        self.link.is_some() || self.foxglove.is_some() || self.shared.is_some()
    }

    /// The topics the bridge reads from the session's bus: those it sends out, and, for a
    /// Foxglove view, every recorded topic the session itself publishes (`local`: the source
    /// is on this machine; a remote-fed session's view takes its samples off the link).
    pub fn inputs(&self, local: bool) -> Vec<Topic> {
        let mut v: Vec<Topic> = self
            .link
            .as_ref()
            .map(|l| l.publish.clone())
            .unwrap_or_default();
        // A shared session's host sends the world it steps; a participant sends its hands.
        match &self.shared {
            Some(s) if s.is_host() => v.push(Topic::World),
            Some(_) => v.push(Topic::Hand),
            None => {}
        }
        if self.foxglove.is_some() && local {
            for t in Topic::RECORDED {
                if !v.contains(&t) {
                    v.push(t);
                }
            }
        }
        v.sort();
        v
    }

    /// The topics the bridge publishes on the session's bus (taken in from the link).
    pub fn outputs(&self) -> Vec<Topic> {
        let mut v: Vec<Topic> = self
            .link
            .as_ref()
            .map(|l| l.subscribe.clone())
            .unwrap_or_default();
        // The host publishes every participant's hands, ordered; a participant the host's world.
        match &self.shared {
            Some(s) if s.is_host() => v.push(Topic::Hand),
            Some(_) => v.push(Topic::World),
            None => {}
        }
        v
    }
}

/// Where a zenoh endpoint is checked: `tls/HOST:PORT` or `tcp/HOST:PORT`, HOST not empty,
/// PORT 1-65535.
fn endpoint(r: &Reader, default: Option<&str>) -> Result<String, ConfigError> {
    endpoint_at(r, "endpoint", default)
}

/// [`endpoint`] under another key (`[shared]`'s `listen` and `host`).
pub(super) fn endpoint_at(
    r: &Reader,
    key: &'static str,
    default: Option<&str>,
) -> Result<String, ConfigError> {
    let text = match (r.string(key)?, default) {
        (Some(s), _) => s,
        (None, Some(d)) => d.to_string(),
        (None, None) => {
            return Err(r.err(
                key,
                "required: the zenoh endpoint, tls/HOST:PORT (e.g. \"tls/127.0.0.1:7447\")",
            ))
        }
    };
    let bad = |why: &str| {
        r.err(
            key,
            format!(
                "{text:?} {why}; give tls/HOST:PORT, e.g. \"tls/127.0.0.1:7447\" (TLS, carried on \
                 QUIC, and plain TCP are built in)"
            ),
        )
    };
    let Some(rest) = text
        .strip_prefix("tls/")
        .or_else(|| text.strip_prefix("tcp/"))
    else {
        return Err(bad("is not a TLS or TCP endpoint"));
    };
    let Some((host, port)) = rest.rsplit_once(':') else {
        return Err(bad("has no port"));
    };
    if host.is_empty() || host.contains('/') {
        return Err(bad("has no host"));
    }
    match port.parse::<u16>() {
        Ok(p) if p > 0 => Ok(text),
        _ => Err(bad("has a port outside 1 to 65535")),
    }
}

/// The host of a checked endpoint (`tls/HOST:PORT`), brackets of an IPv6 address removed.
pub fn endpoint_host(endpoint: &str) -> &str {
    let rest = endpoint.split_once('/').map_or(endpoint, |(_, r)| r);
    let host = rest.rsplit_once(':').map_or(rest, |(h, _)| h);
    host.trim_start_matches('[').trim_end_matches(']')
}

/// True for a host that never leaves this machine (`localhost`, 127.0.0.0/8, `::1`).
pub fn is_loopback_host(host: &str) -> bool {
    host == "localhost"
        || host
            .parse::<std::net::IpAddr>()
            .is_ok_and(|a| a.is_loopback())
}

/// The default folder of this user's link keys: `$XDG_DATA_HOME/handblocks/link`, or
/// `~/.local/share/handblocks/link`, or, with neither, `.handblocks/link` here.
pub fn default_key_dir() -> PathBuf {
    if let Some(d) = std::env::var_os("XDG_DATA_HOME").filter(|d| !d.is_empty()) {
        return PathBuf::from(d).join("handblocks/link");
    }
    if let Some(h) = std::env::var_os("HOME").filter(|h| !h.is_empty()) {
        return PathBuf::from(h).join(".local/share/handblocks/link");
    }
    PathBuf::from(".handblocks/link")
}

/// The link's protection from its endpoint's scheme and the keys beside it: `tls/` takes
/// `key_dir`, `peer_certificate` and `names`; `tcp/` only with `allow_plain = true` (it
/// crosses a network in clear and lets any peer join), and then none of the TLS keys.
fn security(r: &Reader, endpoint: &str, dir: &Path) -> Result<LinkSecurity, ConfigError> {
    security_at(r, "endpoint", endpoint, dir)
}

/// [`security`] of the endpoint under `endpoint_key`.
pub(super) fn security_at(
    r: &Reader,
    endpoint_key: &'static str,
    endpoint: &str,
    dir: &Path,
) -> Result<LinkSecurity, ConfigError> {
    let allow_plain = r.bool("allow_plain", false)?;
    let key_dir = r.string("key_dir")?.map(|d| dir.join(d));
    let peer_certificate = r.string("peer_certificate")?.map(|f| dir.join(f));
    let names = match r.raw("names", || Spec {
        allowed: "host names or addresses: letters, digits, '.', '-', ':'".into(),
        default: Some("[]".into()),
        ..Spec::of("list of strings")
    }) {
        None => Vec::new(),
        Some(toml::Value::Array(items)) => {
            let mut out = Vec::new();
            for (i, item) in items.iter().enumerate() {
                match item.as_str().filter(|s| {
                    !s.is_empty()
                        && s.chars()
                            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '.' | '-' | ':'))
                }) {
                    Some(s) => out.push(s.to_string()),
                    None => {
                        return Err(r.err(
                            "names",
                            format!(
                                "item {i}: {item} is not a host name or address (letters, \
                                 digits, '.', '-', ':'), e.g. \"studio.lan\" or \"192.168.1.20\""
                            ),
                        ))
                    }
                }
            }
            out
        }
        Some(v) => {
            return Err(r.err(
                "names",
                format!(
                    "expected a list of host names or addresses, found {}",
                    v.type_str()
                ),
            ))
        }
    };
    if endpoint.starts_with("tcp/") {
        if !allow_plain {
            return Err(r.err(
                endpoint_key,
                format!(
                    "{endpoint:?} is plain TCP: every hand and world crosses the network in \
                     clear and any peer that reaches the port may read or inject them. Use \
                     \"tls/{}\" (encrypted, both sides authenticated: docs/sessions.md, \
                     \"A protected link\"), or set allow_plain = true for a link that never \
                     leaves a network you trust",
                    endpoint.trim_start_matches("tcp/")
                ),
            ));
        }
        for (key, given) in [
            ("key_dir", key_dir.is_some()),
            ("peer_certificate", peer_certificate.is_some()),
            ("names", !names.is_empty()),
        ] {
            if given {
                return Err(r.err(
                    key,
                    "a plain tcp/ endpoint uses no certificate: give a tls/ endpoint",
                ));
            }
        }
        return Ok(LinkSecurity::Plain);
    }
    if allow_plain {
        return Err(r.err(
            "allow_plain",
            "only with a tcp/ endpoint; a tls/ link is never plain",
        ));
    }
    Ok(LinkSecurity::Tls {
        key_dir: key_dir.unwrap_or_else(default_key_dir),
        peer_certificate,
        names,
    })
}

/// A zenoh key prefix: chunks of letters, digits, `_`, `-` and `.`, joined by `/`.
fn key(r: &Reader) -> Result<String, ConfigError> {
    key_or(r, DEFAULT_KEY)
}

/// [`key`] with another default.
pub(super) fn key_or(r: &Reader, default: &str) -> Result<String, ConfigError> {
    let k = r.string_or("key", default)?;
    let ok = !k.is_empty()
        && k.split('/').all(|chunk| {
            !chunk.is_empty()
                && chunk
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.'))
        });
    if !ok {
        return Err(r.err(
            "key",
            format!(
                "{k:?} is not a key prefix: give names of letters, digits, _, - and . joined \
                 by / (no wildcards), e.g. \"handblocks/live\"; both halves must use the same"
            ),
        ));
    }
    Ok(k)
}

/// A list of topic names, each a recorded topic, none twice.
pub(super) fn topics(
    r: &Reader,
    name: &'static str,
    default: &[Topic],
) -> Result<Vec<Topic>, ConfigError> {
    let allowed: Vec<&str> = Topic::RECORDED.iter().map(|t| t.name()).collect();
    let Some(v) = r.raw(name, || Spec {
        allowed: format!("each one of {}, none twice", quoted(&allowed)),
        default: Some(format!(
            "[{}]",
            quoted(&default.iter().map(|t| t.name()).collect::<Vec<_>>())
        )),
        ..Spec::of("list of topic names")
    }) else {
        return Ok(default.to_vec());
    };
    let toml::Value::Array(items) = v else {
        return Err(r.err(
            name,
            format!(
                "expected a list of topic names, found {}; allowed: {}",
                v.type_str(),
                quoted(&allowed)
            ),
        ));
    };
    let mut out = Vec::new();
    for (i, item) in items.iter().enumerate() {
        let t = item
            .as_str()
            .and_then(|s| Topic::RECORDED.into_iter().find(|t| t.name() == s))
            .ok_or_else(|| {
                r.err(
                    name,
                    format!(
                        "item {i}: {item} is not a topic; one of: {}",
                        quoted(&allowed)
                    ),
                )
            })?;
        if out.contains(&t) {
            return Err(r.err(name, format!("item {i}: {:?} is named twice", t.name())));
        }
        out.push(t);
    }
    Ok(out)
}

fn role(r: &Reader, default: LinkRole) -> Result<LinkRole, ConfigError> {
    let allowed: &[&'static str] = match default {
        LinkRole::Listen => &["listen", "connect"],
        LinkRole::Connect => &["connect", "listen"],
    };
    Ok(match r.choice("role", allowed)? {
        "listen" => LinkRole::Listen,
        _ => LinkRole::Connect,
    })
}

/// `[remote]`: the link of a session whose source is on this machine.
pub(crate) fn remote_table(r: Reader, dir: &Path) -> Result<RemoteLink, ConfigError> {
    let endpoint = endpoint(&r, None)?;
    let link = RemoteLink {
        security: security(&r, &endpoint, dir)?,
        endpoint,
        role: role(&r, LinkRole::Listen)?,
        key: key(&r)?,
        publish: topics(&r, "publish", &[Topic::Hand, Topic::World])?,
        subscribe: topics(&r, "subscribe", &[])?,
        wait_for_viewer_s: r.u64_in("wait_for_viewer_s", 0, 0..=MAX_WAIT_FOR_VIEWER_S)?,
    };
    if let Some(t) = link.publish.iter().find(|t| link.subscribe.contains(t)) {
        return Err(r.err(
            "subscribe",
            format!(
                "{:?} is also in publish: a topic crosses the link one way",
                t.name()
            ),
        ));
    }
    // What this session's own stages publish cannot also come in from the other side: two
    // publishers of one topic would interleave two timelines.
    if let Some(t) = link.subscribe.iter().find(|t| !matches!(t, Topic::Frame)) {
        return Err(r.err(
            "subscribe",
            format!(
                "{:?} is published by this session's own stages; a session with a local \
                 source takes in only \"frame\" (a remote renderer's frame stats)",
                t.name()
            ),
        ));
    }
    r.finish()?;
    Ok(link)
}

/// The keys of `[source] kind = "remote"` (the caller read `kind`): the link a viewer session
/// is fed by. `r` is the `[source]` table.
pub(crate) fn remote_source(r: &Reader, dir: &Path) -> Result<RemoteLink, ConfigError> {
    let endpoint = endpoint(r, None)?;
    let link = RemoteLink {
        security: security(r, &endpoint, dir)?,
        endpoint,
        role: role(r, LinkRole::Connect)?,
        key: key(r)?,
        publish: topics(r, "publish", &[])?,
        subscribe: topics(r, "subscribe", &[Topic::Hand, Topic::World])?,
        wait_for_viewer_s: 0,
    };
    // A viewer's own stages publish only the renderer's frame stats: those it may send back.
    if let Some(t) = link.publish.iter().find(|t| !matches!(t, Topic::Frame)) {
        return Err(r.err(
            "publish",
            format!(
                "{:?} is not published here: a remote-fed session sends back only \"frame\" \
                 (its renderer's frame stats)",
                t.name()
            ),
        ));
    }
    for needed in [Topic::Hand, Topic::World] {
        if !link.subscribe.contains(&needed) {
            return Err(r.err(
                "subscribe",
                format!(
                    "must hold {:?}: the renderer and the recorder of a remote-fed session \
                     read the hand and the world",
                    needed.name()
                ),
            ));
        }
    }
    Ok(link)
}

/// `[viewer]`: `foxglove = "HOST:PORT"` and `foxglove_clients` (the address, and the cap).
pub(crate) fn viewer_table(r: Reader) -> Result<(Option<(String, u16)>, usize), ConfigError> {
    let clients = r.u64_in(
        "foxglove_clients",
        DEFAULT_FOXGLOVE_CLIENTS as u64,
        FOXGLOVE_CLIENTS,
    )? as usize;
    let out = match r.string("foxglove")? {
        None => None,
        Some(text) => {
            let parsed = text
                .rsplit_once(':')
                .filter(|(h, _)| !h.is_empty())
                .and_then(|(h, p)| p.parse::<u16>().ok().map(|p| (h.to_string(), p)));
            match parsed {
                Some(hp) => Some(hp),
                None => {
                    return Err(r.err(
                        "foxglove",
                        format!(
                            "{text:?} is not HOST:PORT; e.g. \"127.0.0.1:8765\" (port 0: any \
                             free port, printed at start)"
                        ),
                    ))
                }
            }
        }
    };
    r.finish()?;
    Ok((out, clients))
}
