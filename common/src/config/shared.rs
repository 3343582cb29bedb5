//! `[shared]`: several people, each on their own machine with their own source of hands, in one
//! block world (docs/sessions.md "Shared sessions", issue 45).
//!
//! The design is one authoritative world: the host's stepper orders every participant's hands
//! on the host's clock and steps the one world; every participant is sent that world, sample
//! for sample. A participant never steps a world of its own, so no two worlds can diverge
//! (each world a participant shows is the host's, bit for bit: `inspect --world-hashes`), a
//! late joiner is in step with the next world it receives, and a participant whose link stalls
//! holds nobody up: the host steps on its own clock, and that participant's hands are held,
//! then let go, as a tracker's lost hand is.
//!
//! ```toml
//! # the host (config/sessions/shared-host.toml)
//! [source]
//! kind = "shared"                 # the participants' hands are this session's source
//! [shared]
//! listen = "tls/0.0.0.0:7460"     # where participants connect
//! # token = "..."                 # default: a new one each session, printed with the command
//! #                               #   that joins it
//!
//! # a participant (config/sessions/shared-join.toml): any source of hands
//! [shared]
//! host = "tls/studio.lan:7460"    # --set shared.host=...
//! token = "..."                   # --set shared.token=...
//! name = "alice"
//! ```

use std::path::Path;

use super::reader::Reader;
use super::remote::{endpoint_at, key_or, security_at, LinkSecurity};
use super::ConfigError;

/// The key prefix of a shared session when it names none.
pub const DEFAULT_SHARED_KEY: &str = "handblocks/shared";
/// The port a host listens on when `listen` names none.
pub const DEFAULT_SHARED_LISTEN: &str = "tls/0.0.0.0:7460";
/// The shortest token: as the webxr page's, 16 characters of `A-Za-z0-9-_` (96 bits).
pub const MIN_TOKEN_CHARS: usize = 16;

/// Which side of a shared session this one is.
#[derive(Debug, Clone, PartialEq)]
pub enum SharedRole {
    /// Orders the participants' hands and steps the one world (`[source] kind = "shared"`).
    Host {
        /// `drop_after_s`: a participant none of whose hands has come for this long is named
        /// and dropped: its hands let go and its place is kept empty (it may join again).
        drop_after_s: f64,
        /// `hold_ms`: a participant none of whose hands has come for this long has them sent
        /// as lost (`tracked = 0`), holding what they hold, as a tracker's gap is (T2).
        hold_ms: u64,
    },
    /// Sends this session's hands to the host and shows the world it sends back.
    Join {
        /// `name`: how the host's report names this participant.
        name: String,
    },
}

/// `[shared]`: one side of a shared session's link.
#[derive(Debug, Clone, PartialEq)]
pub struct SharedLink {
    pub role: SharedRole,
    /// The host's `listen`, or a participant's `host`: `tls/HOST:PORT` (or `tcp/` with
    /// `allow_plain`).
    pub endpoint: String,
    pub security: LinkSecurity,
    /// `key`: the zenoh key prefix; host and participants must use the same.
    pub key: String,
    /// `token`: what a participant must give to join. A host's default is a new random one
    /// each session (None here: the bridge makes it and prints it).
    pub token: Option<String>,
}

impl SharedLink {
    pub fn is_host(&self) -> bool {
        matches!(self.role, SharedRole::Host { .. })
    }
}

/// The token's form: at least [`MIN_TOKEN_CHARS`] of `A-Za-z0-9-_`.
/// A participant's file may leave it out (the shipped one does): its bridge then stops with the
/// command that gives it.
fn token(r: &Reader) -> Result<Option<String>, ConfigError> {
    let given = r.string("token")?;
    match &given {
        Some(t)
            if t.len() < MIN_TOKEN_CHARS
                || !t
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_')) =>
        {
            Err(r.err(
                "token",
                format!(
                    "at least {MIN_TOKEN_CHARS} characters of A-Za-z0-9-_ (a guessable token \
                     lets anyone who reaches the port put hands in the world); leave it out \
                     on the host for a new random one each session"
                ),
            ))
        }
        _ => Ok(given),
    }
}

/// `[shared]` of a session; `host_session`: its `[source] kind` is `"shared"`.
pub(crate) fn shared_table(
    r: Reader,
    host_session: bool,
    dir: &Path,
) -> Result<SharedLink, ConfigError> {
    let (endpoint_key, other_key) = if host_session {
        ("listen", "host")
    } else {
        ("host", "listen")
    };
    if r.has(other_key) {
        return Err(r.err(
            other_key,
            if host_session {
                "not on the host ([source] kind = \"shared\"): it listens, on `listen`"
            } else {
                "only on the host ([source] kind = \"shared\"); a participant names the host's \
                 address as `host`"
            },
        ));
    }
    let endpoint = endpoint_at(
        &r,
        endpoint_key,
        host_session.then_some(DEFAULT_SHARED_LISTEN),
    )?;
    let security = security_at(&r, endpoint_key, &endpoint, dir)?;
    let role = if host_session {
        if r.has("name") {
            return Err(r.err(
                "name",
                "a participant's name; the host names participants by theirs",
            ));
        }
        SharedRole::Host {
            drop_after_s: r
                .f64_in("drop_after_s", Some(5.0), 0.5..=600.0)?
                .unwrap_or(5.0),
            hold_ms: r.u64_in("hold_ms", 100, 10..=10_000)?,
        }
    } else {
        for key in ["drop_after_s", "hold_ms"] {
            if r.has(key) {
                return Err(r.err(key, "only on the host ([source] kind = \"shared\")"));
            }
        }
        let name = r.string_or("name", "participant")?;
        if name.is_empty()
            || name.len() > 32
            || !name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'))
        {
            return Err(r.err(
                "name",
                format!("{name:?}: 1 to 32 characters of A-Za-z0-9-_. (the host's report names you by it)"),
            ));
        }
        SharedRole::Join { name }
    };
    let link = SharedLink {
        role,
        endpoint,
        security,
        key: key_or(&r, DEFAULT_SHARED_KEY)?,
        token: token(&r)?,
    };
    r.finish()?;
    Ok(link)
}
