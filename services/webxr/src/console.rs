//! What the webxr stage tells the person at the terminal and the session's report: where to
//! open the page (its URL, a QR code, the certificate's fingerprint, the other route), and at
//! the end what the pages did.

use common::config::session::WebxrSource;
use common::HandsUsed;

use crate::address;
use crate::certificate::Certificate;
use crate::driving::Counts;
use crate::server::Tally;

/// The URL, its QR code, the certificate's fingerprint, the other route, where the server
/// listens, and a warning when the token would cross a network in clear.
pub fn tell_the_user(
    url: &str,
    settings: &WebxrSource,
    local: std::net::SocketAddr,
    token: &str,
    certificate: Option<&Certificate>,
) {
    let port = local.port();
    let mut s = String::new();
    s.push_str(&listening(
        local,
        settings.tls,
        &address::interface_addresses(),
    ));
    s.push_str(&format!(
        "handblocks webxr: open this in the headset's browser:\n\n    {url}\n\n"
    ));
    if let Some(qr) = address::qr(url) {
        s.push_str(&qr);
        s.push('\n');
    }
    if let Some(c) = certificate {
        s.push_str(&format!(
            "  The certificate ({}{}) is this machine's own: the browser warns once; accept it\n  \
             (Advanced -> Proceed) after checking its SHA-256 fingerprint:\n  {}\n",
            c.file.display(),
            if c.made { ", made now" } else { "" },
            c.fingerprint
        ));
    }
    s.push_str(&format!(
        "  Or, a Quest on USB: `adb reverse tcp:{port} tcp:{port}` and open \
         {}://localhost:{port}/?token={token}\n",
        if settings.tls { "https" } else { "http" }
    ));
    eprintln!("{s}");
}

/// Where the server listens (every interface's address when it listens on all), and, when it
/// serves plain HTTP beyond this machine, a warning: the token in the URL and every hand
/// frame cross the network in clear, so anyone on it can read the token and drive the hand.
pub fn listening(
    local: std::net::SocketAddr,
    tls: bool,
    interfaces: &[std::net::IpAddr],
) -> String {
    let scheme = if tls { "HTTPS" } else { "plain HTTP" };
    let ip = local.ip();
    let mut s = if ip.is_loopback() {
        format!(
            "handblocks webxr: listening on {local} ({scheme}): this machine only; a headset \
             reaches it through `adb reverse`\n"
        )
    } else if ip.is_unspecified() {
        let list: Vec<String> = interfaces
            .iter()
            .filter(|a| a.is_ipv4() == ip.is_ipv4() || ip.is_ipv6())
            .map(|a| a.to_string())
            .collect();
        format!(
            "handblocks webxr: listening on {local} ({scheme}): every interface ({})\n",
            if list.is_empty() {
                "none found".to_string()
            } else {
                list.join(", ")
            }
        )
    } else {
        format!("handblocks webxr: listening on {local} ({scheme}): that interface only\n")
    };
    if !tls && !ip.is_loopback() {
        s.push_str(
            "handblocks webxr: WARNING: tls = false on a network interface: the token and the \
             hands cross the network in clear, and anyone on it can read the token and drive \
             the hand. Set tls = true, or leave listen out (tls = false then listens on \
             127.0.0.1) and use `adb reverse`.\n",
        );
    }
    s
}

/// What was refused, by kind, for the session report (`refused.headset.json`): the server's
/// refusals and the stage's own (frames out of order, or before the page's clock), adding up
/// to the report's `rejected_records`.
pub fn refusals_json(tally: &Tally, c: &Counts) -> String {
    let mut by_kind: serde_json::Map<String, serde_json::Value> = tally
        .refusals()
        .map(|(k, n)| (k.to_string(), n.into()))
        .collect();
    for (kind, n) in [("order", c.order), ("before_clock", c.before_clock)] {
        if n > 0 {
            by_kind.insert(kind.into(), n.into());
        }
    }
    serde_json::Value::Object(by_kind).to_string()
}

/// Said when no page sent a hand, before the budget's verdict (source_silence_ms: the source
/// delivered no sample), which is what a session without a hand gets: exit 1.
pub fn no_headset(pages: u64) -> String {
    format!(
        "handblocks webxr: no headset joined this session: no page sent a hand ({pages} \
         pages opened the URL). The session fails its budget (source_silence_ms) and \
         exits with status 1, as any session whose source delivered nothing does."
    )
}

/// The stage's last line: pages, frames, worlds, refusals, drivers, gaps and the clock.
pub fn summary(c: &Counts, worlds_sent: u64, tally: &Tally, hands: HandsUsed) -> String {
    let pages = tally.sockets.load(std::sync::atomic::Ordering::Relaxed);
    let refused: Vec<String> = tally.refusals().map(|(k, n)| format!("{k} {n}")).collect();
    format!(
        "handblocks webxr: {} pages connected; {} frames published ({}), {} worlds \
         sent; refused: {}{}{}; frames missing from the driver's seqs {}; frames of a page \
         not driving {}; driving sockets lost {}; pages dropped for not answering pings {}; \
         drivers whose time was moved on to follow the published {}; \
         tracking gaps over 100 ms (the hand let go) {}; clock offset {:.3} ms from the best \
         of {} pings (round trip {:.3} ms), held for the session",
        pages,
        c.published,
        match hands {
            HandsUsed::Both => format!(
                "untracked: the right hand {}, the left {}",
                c.untracked[0], c.untracked[1]
            ),
            HandsUsed::One(_) => format!("{} untracked", c.untracked[0]),
        },
        worlds_sent,
        if refused.is_empty() {
            "none".to_string()
        } else {
            refused.join(", ")
        },
        if c.order > 0 {
            format!(", order {}", c.order)
        } else {
            String::new()
        },
        if c.before_clock > 0 {
            format!(", before the clock {}", c.before_clock)
        } else {
            String::new()
        },
        c.seq_gaps,
        c.other_page,
        c.drops,
        tally.unanswered.load(std::sync::atomic::Ordering::Relaxed),
        c.shifted,
        c.long_gaps,
        c.offset_ns as f64 / 1e6,
        c.offset_pongs,
        c.offset_round_trip_ns as f64 / 1e6,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_terminal_says_where_the_server_listens_and_warns_of_plain_http_on_a_network() {
        let lan = [
            std::net::IpAddr::from([192, 168, 1, 5]),
            std::net::IpAddr::from([127, 0, 0, 1]),
        ];
        let local = listening("127.0.0.1:8443".parse().unwrap(), false, &lan);
        assert!(
            local.contains("127.0.0.1:8443") && local.contains("this machine only"),
            "{local}"
        );
        assert!(!local.contains("WARNING"), "{local}");
        let all = listening("0.0.0.0:8443".parse().unwrap(), true, &lan);
        assert!(
            all.contains("every interface (192.168.1.5, 127.0.0.1)"),
            "{all}"
        );
        assert!(!all.contains("WARNING"), "{all}");
        let clear = listening("0.0.0.0:8443".parse().unwrap(), false, &lan);
        assert!(
            clear.contains("WARNING") && clear.contains("in clear"),
            "{clear}"
        );
    }

    #[test]
    fn the_refusals_add_the_stages_own_to_the_servers() {
        let tally = Tally::default();
        tally.refuse("flood");
        tally.refuse("flood");
        let c = Counts {
            order: 3,
            ..Counts::default()
        };
        assert_eq!(refusals_json(&tally, &c), r#"{"flood":2,"order":3}"#);
        let line = summary(&c, 7, &tally, HandsUsed::Both);
        assert!(
            line.contains("refused: flood 2, order 3;") && line.contains("7 worlds"),
            "{line}"
        );
    }
}
