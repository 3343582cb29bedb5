//! The session keys of the bridge (issue 17): `[remote]` (this session's topics sent to, or
//! taken from, another machine over zenoh), `[source] kind = "remote"` (a session fed by
//! another machine's session: a viewer) and `[viewer]` (a live Foxglove view).
//!
//! ```toml
//! [remote]                         # the session that sends
//! endpoint = "tcp/127.0.0.1:7447"  # zenoh endpoint: tcp/HOST:PORT
//! role = "listen"                  # "listen" (default: viewers connect here) | "connect"
//! key = "handblocks/live"          # the zenoh key prefix; a topic goes on KEY/TOPIC
//! publish = ["hand", "world"]      # sent out (the default)
//! subscribe = []                   # taken in from the other side (e.g. a remote "frame")
//!
//! [source]                         # the session that views
//! kind = "remote"
//! endpoint = "tcp/127.0.0.1:7447"
//! role = "connect"                 # the default for a remote source
//! key = "handblocks/live"
//! subscribe = ["hand", "world"]    # the default; must hold both (the renderer reads them)
//! publish = ["frame"]              # optional: the renderer's frame stats, sent back
//!
//! [viewer]
//! foxglove = "127.0.0.1:8765"      # serve the live topics over the Foxglove WebSocket protocol
//! ```

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

/// One zenoh link of a session and the topics that cross it.
#[derive(Debug, Clone, PartialEq)]
pub struct RemoteLink {
    /// `tcp/HOST:PORT` (the bridge is built with zenoh's TCP transport only).
    pub endpoint: String,
    pub role: LinkRole,
    /// The key prefix: topic `world` travels on `KEY/world`.
    pub key: String,
    /// Topics this session sends (it reads them from its bus).
    pub publish: Vec<Topic>,
    /// Topics this session takes in (the bridge publishes them on its bus).
    pub subscribe: Vec<Topic>,
}

/// What the bridge process of a session does; `None` of both: the session has no bridge.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct BridgeSettings {
    pub link: Option<RemoteLink>,
    /// `[viewer] foxglove`: host and port of the Foxglove WebSocket server.
    pub foxglove: Option<(String, u16)>,
}

impl BridgeSettings {
    /// True when the session runs a bridge process.
    pub fn is_on(&self) -> bool {
        self.link.is_some() || self.foxglove.is_some()
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
        self.link
            .as_ref()
            .map(|l| l.subscribe.clone())
            .unwrap_or_default()
    }
}

/// Where a zenoh endpoint is checked: `tcp/HOST:PORT`, HOST not empty, PORT 1-65535.
fn endpoint(r: &Reader, default: Option<&str>) -> Result<String, ConfigError> {
    let text = match (r.string("endpoint")?, default) {
        (Some(s), _) => s,
        (None, Some(d)) => d.to_string(),
        (None, None) => {
            return Err(r.err(
                "endpoint",
                "required: the zenoh endpoint, tcp/HOST:PORT (e.g. \"tcp/127.0.0.1:7447\")",
            ))
        }
    };
    let bad = |why: &str| {
        r.err(
            "endpoint",
            format!("{text:?} {why}; give tcp/HOST:PORT, e.g. \"tcp/127.0.0.1:7447\" (only TCP is built in)"),
        )
    };
    let Some(rest) = text.strip_prefix("tcp/") else {
        return Err(bad("is not a TCP endpoint"));
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

/// A zenoh key prefix: chunks of letters, digits, `_`, `-` and `.`, joined by `/`.
fn key(r: &Reader) -> Result<String, ConfigError> {
    let Some(k) = r.string("key")? else {
        return Ok(DEFAULT_KEY.to_string());
    };
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
    let Some(v) = r.raw(name) else {
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
pub(crate) fn remote_table(r: Reader) -> Result<RemoteLink, ConfigError> {
    let link = RemoteLink {
        endpoint: endpoint(&r, None)?,
        role: role(&r, LinkRole::Listen)?,
        key: key(&r)?,
        publish: topics(&r, "publish", &[Topic::Hand, Topic::World])?,
        subscribe: topics(&r, "subscribe", &[])?,
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
pub(crate) fn remote_source(r: &Reader) -> Result<RemoteLink, ConfigError> {
    let link = RemoteLink {
        endpoint: endpoint(r, None)?,
        role: role(r, LinkRole::Connect)?,
        key: key(r)?,
        publish: topics(r, "publish", &[])?,
        subscribe: topics(r, "subscribe", &[Topic::Hand, Topic::World])?,
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

/// `[viewer]`: `foxglove = "HOST:PORT"`.
pub(crate) fn viewer_table(r: Reader) -> Result<Option<(String, u16)>, ConfigError> {
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
    Ok(out)
}
