//! What the link refused, by name (issue 40): zenoh refuses a stranger inside its own tasks (a
//! TLS handshake that fails, a peer certificate no trusted authority issued) and says so only
//! in its `tracing` events. This process listens to those events (one small `Subscriber`,
//! interested in nothing else, so every other callsite stays disabled and costs nothing), counts
//! each refusal under a name made from its reason, says the first of each name on stderr, and
//! the bridge puts the counts in `bridge.json`.

use std::collections::BTreeMap;
use std::sync::Mutex;

use tracing::field::{Field, Visit};
use tracing::level_filters::LevelFilter;
use tracing::span;
use tracing::subscriber::Interest;
use tracing::{Event, Metadata};

/// Refusals so far, by name. A refusal is rare (a handshake), never per sample: a lock is fine.
static COUNTS: Mutex<BTreeMap<String, u64>> = Mutex::new(BTreeMap::new());

/// The longest reason kept in a name (zenoh's messages carry addresses and retry periods).
const MAX_NAME: usize = 160;

/// Starts counting (once per process; later calls, or a process that set its own subscriber,
/// change nothing).
pub fn install() {
    let _ = tracing::subscriber::set_global_default(Counter);
}

/// The refusals counted so far, by name.
pub fn counts() -> BTreeMap<String, u64> {
    COUNTS.lock().map(|c| c.clone()).unwrap_or_default()
}

/// Counts one refusal under `name` (the link's own refusals, besides zenoh's), saying it on
/// stderr the first time.
pub fn count(name: &str) {
    let Ok(mut c) = COUNTS.lock() else { return };
    let n = c.entry(name.to_string()).or_default();
    *n += 1;
    if *n == 1 {
        eprintln!("handblocks bridge: the link refused: {name} (counted in bridge.json)");
    }
}

/// The name of a zenoh event that reports a refusal, or None for any other event.
pub fn classify(target: &str, message: &str) -> Option<String> {
    if target.starts_with("zenoh_link_commons::quic") || target.starts_with("zenoh_link_quic") {
        // A listener's QUIC handshake that failed (a `tls/` endpoint is zenoh's QUIC link):
        // quinn's error, which zenoh's accept loop says with a hint about open files.
        let why = message
            .strip_prefix("Cannot accept QUIC connection:")
            .or_else(|| {
                message
                    .strip_suffix(" Hint: increase the system open file limit.")
                    .map(|m| m.trim_start_matches("QUIC acceptor failed:"))
            })?;
        // quinn says its reason as bytes inside a Debug print: `reason: b"..."`.
        let why = why
            .split_once("reason: b\"")
            .and_then(|(_, r)| r.split_once('"'))
            .map_or(why, |(r, _)| r);
        return Some(format!(
            "a connecting peer's TLS handshake: {}",
            reason(why)
        ));
    }
    if target.starts_with("zenoh_link_tls") {
        // A listener's TLS handshake that failed: tls-listener's error, which zenoh says with
        // a hint about open files (its accept loop cannot tell the two apart).
        let why = message
            .strip_prefix("Can not accept TLS connection:")
            .or_else(|| message.strip_suffix(". Hint: increase the system open file limit."))?;
        return Some(format!(
            "a connecting peer's TLS handshake: {}",
            reason(why)
        ));
    }
    // A connecting side: "Unable to connect to configured peer tls/...! REASON. Retry in ...".
    let rest = message.strip_prefix("Unable to connect to configured peer ")?;
    let why = rest.split_once("! ").map_or(rest, |(_, w)| w);
    let why = why.rsplit_once(". Retry in").map_or(why, |(w, _)| w);
    let why = reason(why);
    let lower = why.to_ascii_lowercase();
    // A peer that is not up yet (connection refused, timed out) is no refusal.
    let refused = ["certificate", "alert", "handshake", "decrypt"]
        .iter()
        .any(|k| lower.contains(k));
    refused.then(|| format!("the listening peer, on connecting: {why}"))
}

/// zenoh's reason without where it was made (` at /path/file.rs:N.`) or the link it was for
/// (`Can not create a new TLS link bound to ADDRESS: `), at most [`MAX_NAME`] characters.
fn reason(why: &str) -> String {
    let mut why = why.trim();
    if let Some(at) = why.find(" at /") {
        why = &why[..at];
    }
    if let Some(at) = why.find(" bound to ") {
        // The address is Debug-printed with its own ": "-free parentheses.
        let after = &why[at..];
        if let Some((_, r)) = after.split_once("): ").or_else(|| after.split_once(": ")) {
            why = r;
        }
    }
    let why = why.trim().trim_end_matches('.');
    match why.char_indices().nth(MAX_NAME) {
        Some((at, _)) => format!("{}...", &why[..at]),
        None => why.to_string(),
    }
}

/// The subscriber: enabled for zenoh's QUIC and TLS links' and its connect events only.
struct Counter;

fn interesting(m: &Metadata<'_>) -> bool {
    m.is_event()
        && (m.target().starts_with("zenoh_link_tls")
            || m.target().starts_with("zenoh_link_quic")
            || m.target().starts_with("zenoh_link_commons::quic")
            || m.target().starts_with("zenoh::net::runtime::orchestrator"))
}

/// The event's `message` field.
struct Message(String);

impl Visit for Message {
    fn record_debug(&mut self, field: &Field, value: &dyn std::fmt::Debug) {
        if field.name() == "message" {
            use std::fmt::Write as _;
            let _ = write!(self.0, "{value:?}");
        }
    }
    fn record_str(&mut self, field: &Field, value: &str) {
        if field.name() == "message" {
            self.0.push_str(value);
        }
    }
}

impl tracing::Subscriber for Counter {
    fn register_callsite(&self, m: &'static Metadata<'static>) -> Interest {
        if interesting(m) {
            Interest::always()
        } else {
            Interest::never()
        }
    }
    fn enabled(&self, m: &Metadata<'_>) -> bool {
        interesting(m)
    }
    fn max_level_hint(&self) -> Option<LevelFilter> {
        Some(LevelFilter::DEBUG)
    }
    fn new_span(&self, _: &span::Attributes<'_>) -> span::Id {
        span::Id::from_u64(1)
    }
    fn record(&self, _: &span::Id, _: &span::Record<'_>) {}
    fn record_follows_from(&self, _: &span::Id, _: &span::Id) {}
    fn event(&self, event: &Event<'_>) {
        let mut m = Message(String::new());
        event.record(&mut m);
        if let Some(name) = classify(event.metadata().target(), &m.0) {
            count(&name);
        }
    }
    fn enter(&self, _: &span::Id) {}
    fn exit(&self, _: &span::Id) {}
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_quic_listeners_refused_handshake_is_named_by_its_reason() {
        assert_eq!(
            classify(
                "zenoh_link_commons::quic::unicast",
                "QUIC acceptor failed: ConnectionClosed(ConnectionClose { error_code: \
                 Code::crypto(30), frame_type: None, reason: b\"invalid peer certificate: \
                 UnknownIssuer\" }) at /x/unicast.rs:686. Hint: increase the system open file \
                 limit."
            )
            .as_deref(),
            Some("a connecting peer's TLS handshake: invalid peer certificate: UnknownIssuer")
        );
        assert_eq!(
            classify("zenoh_link_commons::quic::unicast", "Ready to accept"),
            None
        );
    }

    #[test]
    fn zenoh_refusals_are_named_and_a_peer_not_up_yet_is_not_one() {
        assert_eq!(
            classify(
                "zenoh_link_tls::unicast",
                "TLS accept error: invalid peer certificate: UnknownIssuer. Hint: increase the \
                 system open file limit."
            )
            .as_deref(),
            Some(
                "a connecting peer's TLS handshake: TLS accept error: invalid peer certificate: \
                 UnknownIssuer"
            )
        );
        assert_eq!(
            classify(
                "zenoh::net::runtime::orchestrator",
                "Unable to connect to configured peer tls/127.0.0.1:7447! Can not create a new \
                 TLS link bound to IpAddress(V4(Ipv4Addr([127, 0, 0, 1]))): invalid peer \
                 certificate: BadSignature at /root/.cargo/registry/src/x/unicast.rs:226.. \
                 Retry in 500ms."
            )
            .as_deref(),
            Some("the listening peer, on connecting: invalid peer certificate: BadSignature")
        );
        assert_eq!(
            classify(
                "zenoh::net::runtime::orchestrator",
                "Unable to connect to configured peer tls/127.0.0.1:7447! Can not create a new \
                 TLS link bound to IpAddress(V4(Ipv4Addr([127, 0, 0, 1]))): [127.0.0.1:39937: \
                 Connection refused (os error 111) at /root/x.rs:1.. Retry in 100ms."
            ),
            None
        );
        assert_eq!(classify("zenoh_transport", "anything"), None);
    }
}
