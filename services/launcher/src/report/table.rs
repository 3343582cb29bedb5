//! The table: the merged report as the launcher prints it at the end of a session, for a
//! person at a terminal (percentiles per stage, each topic's flow, the devices' counters, the
//! frame rate, the bridge, the restarts, and the budget's verdict), with the terms it uses.

use common::latency::Metric;

use super::Report;

/// The latency table's terms, printed under it and in `launch --help`.
pub const TERMS: &str = "\
hop          a sample's publish (by the stage before) to its receive here: the bus and the wake-up
process      receive to this stage's publish: its own work
origin->out  the sample's origin (when its source sample entered the pipeline) to this stage's
             publish: the age of what it sends (at the stepper: origin -> world)
origin->px   the renderer only: origin to the frame's GPU work complete (origin -> photon)
sent->drawn  the webxr source only: a hands frame sent by the headset's page to the world that
             answers it drawn there (the page's round trip, on the page's clock)
page js      the webxr source only: the page's JavaScript time per XR frame
received     per topic, the fewest samples any reader of it received; dropped = never read
             (sequence gaps, or published but not received by the end; a source that reads
             a topic back, as a replay or a headset reads the world, counts its gaps only)";

/// The entries of [`TERMS`] whose names are in `used`, in TERMS's order: a report explains
/// the terms it prints and no others (a glove session has no `sent->drawn`).
pub fn terms_of(used: &[&str]) -> String {
    let mut out = String::new();
    let mut keep = false;
    for line in TERMS.lines() {
        if !line.starts_with(' ') {
            let name = line.split("  ").next().unwrap_or("").trim_end();
            keep = used.contains(&name);
        }
        if keep {
            out.push_str(line);
            out.push('\n');
        }
    }
    out
}

impl Report {
    /// The percentile table and topic flow, for a terminal.
    pub fn table(&self) -> String {
        let mut out = String::new();
        // The terms the table uses, explained under it (and no others).
        let mut used: Vec<&'static str> = vec!["received"];
        out.push_str(&format!(
            "{:<12} {:<11} {:>8} {:>9} {:>9} {:>9} {:>9} {:>9}   (microseconds)\n",
            "stage", "latency", "count", "p50", "p90", "p99", "p99.9", "max"
        ));
        for s in &self.stages {
            for m in Metric::ALL {
                let x = s.summary(m);
                if x.count == 0 {
                    continue;
                }
                let name = match m {
                    Metric::Hop => "hop",
                    Metric::Process => "process",
                    Metric::Origin => "origin->out",
                    Metric::Photon => s.stage.photon_label(),
                    Metric::Page => "page js",
                };
                if !used.contains(&name) {
                    used.push(name);
                }
                out.push_str(&format!(
                    "{:<12} {:<11} {:>8} {:>9.1} {:>9.1} {:>9.1} {:>9.1} {:>9.1}\n",
                    s.stage.name(),
                    name,
                    x.count,
                    x.p50,
                    x.p90,
                    x.p99,
                    x.p999,
                    x.max
                ));
            }
        }
        out.push_str(&format!(
            "\n{:<12} {:>10} {:>10} {:>8} {:>8}\n",
            "topic", "published", "received", "dropped", "gaps"
        ));
        let mut not_final: Vec<&str> = Vec::new();
        let mut unread: Vec<&str> = Vec::new();
        for (t, f) in &self.topics {
            let partial = f.readers.values().any(|r| !r.counts_final);
            // A topic no process of this session reads (the world with the renderer and the
            // recorder off): nothing was received, and nothing was lost either.
            let received = if f.readers.is_empty() {
                unread.push(t.name());
                "no reader".to_string()
            } else {
                f.received().to_string()
            };
            out.push_str(&format!(
                "{:<12} {:>10} {:>10} {:>8} {:>8}{}\n",
                t.name(),
                f.published,
                received,
                f.dropped(),
                f.gaps(),
                if partial { "  *" } else { "" }
            ));
            for (name, r) in &f.readers {
                if !r.counts_final && !not_final.contains(name) {
                    not_final.push(name);
                }
            }
        }
        if !unread.is_empty() {
            out.push_str(&format!(
                "no reader: no process of this session subscribes to {} (no recorder{}), so \
                 none was received and none lost\n",
                unread.join(", "),
                if unread.contains(&"world") {
                    ", renderer or bridge"
                } else {
                    ""
                }
            ));
        }
        if !not_final.is_empty() {
            out.push_str(&format!(
                "* counts of {} stop at its last report (it ended without its final report): \
                 dropped there is its sequence gaps only\n",
                not_final.join(", ")
            ));
        }
        let devices: Vec<&common::DeviceCounters> =
            self.stages.iter().flat_map(|s| &s.devices).collect();
        if !devices.is_empty() {
            out.push_str(&format!(
                "\n{:<8} {:>9} {:>8} {:>8} {:>8} {:>7} {:>10} {:>7}\n",
                "device",
                "samples",
                "garbage",
                "rejected",
                "other",
                "losses",
                "reconnects",
                "errors"
            ));
            let serial = devices.iter().any(|d| d.device != 3);
            let headset = devices
                .iter()
                .any(|d| d.kind() == Some(common::samples::DeviceKind::Headset));
            for d in devices {
                out.push_str(&format!(
                    "{:<8} {:>9} {:>8} {:>8} {:>8} {:>7} {:>10} {:>7}\n",
                    d.name().unwrap_or("?"),
                    d.samples,
                    d.garbage_bytes,
                    d.rejected_records,
                    d.other_station_records,
                    d.link_losses,
                    d.reconnects,
                    d.device_errors
                ));
            }
            // What a source refused, by kind (the `rejected` column is their total).
            for (name, kinds) in self.meta.refused.iter().filter(|(_, k)| !k.is_empty()) {
                let each: Vec<String> = kinds.iter().map(|(k, n)| format!("{k} {n}")).collect();
                out.push_str(&format!("{name} refused: {}\n", each.join(", ")));
            }
            if serial {
                out.push_str(
                    "garbage: bytes skipped between records; rejected: malformed or out-of-range \
                     records; other: records of other tracker stations; errors: the device's own \
                     error replies\n",
                );
            }
            if headset {
                out.push_str(
                    "headset: samples: hands frames published; rejected: messages refused (each \
                     kind in the webxr line above); other: frames of a page not driving; losses: \
                     driving sockets lost; reconnects: pages that drove after the first; errors: \
                     tracking gaps over 100 ms (the hand let go)\n",
                );
            }
        }
        out.push('\n');
        out.push_str(&terms_of(&used));
        if let Some(fps) = self.frame_rate() {
            let over = self.world_seconds(self.meta.seconds);
            out.push_str(&format!(
                "\nframes: {fps:.1} per second over the {over:.1} s worlds came in (of {:.1} s)\n",
                self.meta.seconds
            ));
        }
        if let Some(s) = &self.meta.renderer_skipped {
            out.push_str(&format!("\n{s}\n"));
        }
        if let Some(line) = self.bridge_line() {
            out.push_str(&format!("\n{line}\n"));
        }
        if !self.restarts.is_empty() {
            out.push_str(&format!(
                "\n{:<12} {:>3} {:>8} {:>12}  {:<28} lost at the restart\n",
                "restarted", "n", "at s", "downtime ms", "exit"
            ));
            for r in &self.restarts {
                let lost = match (&r.missing_from_recording, &r.lost) {
                    // A recorder's loss is what its recording misses.
                    (Some(m), _) if !m.is_empty() => m
                        .iter()
                        .map(|(t, n)| format!("{} {n}", t.name()))
                        .collect::<Vec<_>>()
                        .join(", "),
                    (Some(_), _) => "-".into(),
                    (None, Some(l)) if !l.is_empty() => l
                        .iter()
                        .map(|l| format!("{} {}", l.topic.name(), l.lost))
                        .collect::<Vec<_>>()
                        .join(", "),
                    (None, Some(_)) => "-".into(),
                    (None, None) => "? (no report after the restart)".into(),
                };
                out.push_str(&format!(
                    "{:<12} {:>3} {:>8.2} {:>12}  {:<28} {lost}\n",
                    r.stage.name(),
                    r.n,
                    r.at_s,
                    r.downtime_s()
                        .map_or("?".into(), |d| format!("{:.1}", d * 1000.0)),
                    r.exit,
                ));
                if let Some(seg) = &r.segment {
                    out.push_str(&format!("{:<12} recording goes on in {seg}\n", ""));
                }
                if let Some(e) = &r.segment_error {
                    out.push_str(&format!("{:<12} its loss is not counted: {e}\n", ""));
                }
            }
            out.push_str(
                "downtime: the exit noticed to the restarted process's first output; lost: \
                 samples published while it was down, never read by it (not counted as \
                 dropped); a recorder's: samples no segment of the recording holds, counted \
                 from their seqs (its unwritten chunk, at most [recorder] flush_ms of them, \
                 and those published while it was down)\n",
            );
        }
        for f in &self.failures {
            out.push_str(&format!("\nFAILED: {f}\n"));
        }
        for n in &self.not_judged {
            out.push_str(&format!("\nnot judged: {n}\n"));
        }
        if self.violations.is_empty() {
            out.push_str("\nbudget: ok\n");
        } else {
            out.push_str("\nbudget: VIOLATED\n");
            for v in &self.violations {
                out.push_str(&format!("  {v}\n"));
            }
            out.push_str(&self.what_to_try());
        }
        out
    }

    /// Under a broken budget: whether the machine looked loaded while the session ran (the
    /// verdict may then be the machine's, not the pipeline's), and what to try.
    fn what_to_try(&self) -> String {
        let Some(load) = &self.meta.machine_load else {
            return "  the machine's load could not be read (/proc/stat): run it again on an idle \
                    machine before blaming the pipeline\n"
                .to_string();
        };
        if load.looked_loaded() {
            format!(
                "  the machine looked loaded: {}. The verdict may be the machine's, not the \
                 pipeline's: run it again when the machine is idle (`top` shows what runs), or \
                 for longer (--duration 10), or compare stage against stage with `handblocks \
                 bench latency`, which measures a peer in the same run\n",
                load.describe()
            )
        } else {
            format!(
                "  the machine looked quiet ({}), so the session itself missed its budget: the \
                 stage rows above show where the time went (docs/latency.md says what each \
                 costs); a lighter scene, the paper model, or a looser [budget] in the session \
                 file are the levers\n",
                load.describe()
            )
        }
    }

    /// One line on the bridge: what crossed the link and the clock it was stamped by.
    pub fn bridge_line(&self) -> Option<String> {
        let b = self.meta.bridge.as_ref()?;
        let mut parts = Vec::new();
        if let Some(l) = b.get("link").filter(|l| !l.is_null()) {
            let counts = |k: &str| {
                l.get(k)
                    .and_then(|m| m.as_object())
                    .map(|m| {
                        m.iter()
                            .map(|(t, n)| format!("{t} {n}"))
                            .collect::<Vec<_>>()
                            .join(", ")
                    })
                    .filter(|s| !s.is_empty())
            };
            parts.push(format!(
                "bridge: {} {} ({} peer(s) at the end)",
                l["role"].as_str().unwrap_or("?"),
                l["endpoint"].as_str().unwrap_or("?"),
                l["peers_at_end"]
            ));
            if let Some(s) = counts("sent") {
                parts.push(format!("sent {s}"));
            }
            if let Some(s) = counts("taken_in") {
                parts.push(format!("taken in {s}"));
            }
            match l.get("clock").filter(|c| !c.is_null()) {
                Some(c) => parts.push(format!(
                    "the other clock is {:.1} us from ours, +/- {:.1} us ({} round trips)",
                    c["offset_ns"].as_f64().unwrap_or(0.0) / 1e3,
                    c["uncertainty_ns"].as_f64().unwrap_or(0.0) / 1e3,
                    c["exchanges"]
                )),
                None if l["subscribe"].as_array().is_some_and(|a| !a.is_empty()) => {
                    parts.push("the other clock was never reached".into())
                }
                None => {}
            }
            let dropped =
                l["queue_full"].as_u64().unwrap_or(0) + l["malformed"].as_u64().unwrap_or(0);
            if dropped > 0 {
                parts.push(format!(
                    "dropped {dropped} ({} queue full, {} malformed)",
                    l["queue_full"], l["malformed"]
                ));
            }
        }
        if let Some(port) = b.get("foxglove").and_then(|f| f.get("port")) {
            parts.push(format!("Foxglove view served on port {port}"));
        }
        if let Some(s) = b.get("shared") {
            parts.push(shared_line(s));
        }
        (!parts.is_empty()).then(|| parts.join("; "))
    }
}

/// The shared world's part of the bridge line: the host names each participant and what it
/// sent; a participant its number, its hand -> world and the worlds it took in.
fn shared_line(s: &serde_json::Value) -> String {
    let us = |v: &serde_json::Value| v.as_f64().map_or("-".into(), |x| format!("{x:.0}"));
    if s["role"] == "host" {
        let people: Vec<String> = s["participants"]
            .as_array()
            .map(|a| {
                a.iter()
                    .map(|p| {
                        format!(
                            "{} {} ({} hands{}{})",
                            p["participant"],
                            p["name"].as_str().unwrap_or("?"),
                            p["hands_taken"],
                            match p["hands_lost"].as_u64() {
                                Some(n) if n > 0 => format!(", {n} lost"),
                                _ => String::new(),
                            },
                            if p["drops"].as_u64().unwrap_or(0) > 0 {
                                format!(", dropped {} time(s)", p["drops"])
                            } else {
                                String::new()
                            }
                        )
                    })
                    .collect()
            })
            .unwrap_or_default();
        let refused: u64 = s["refused"]
            .as_object()
            .map_or(0, |m| m.values().filter_map(|v| v.as_u64()).sum());
        format!(
            "shared world hosted on {}: {} frame(s), {} world(s) sent to each; participants: {}{}",
            s["endpoint"].as_str().unwrap_or("?"),
            s["frames"],
            s["worlds_sent"],
            if people.is_empty() {
                "none joined".to_string()
            } else {
                people.join(", ")
            },
            if refused > 0 {
                format!("; refused {refused} (by name in the report's bridge.shared.refused)")
            } else {
                String::new()
            }
        )
    } else {
        let h = &s["hand_to_world_us"];
        format!(
            "joined the shared world on {} as participant {} ({}) in {:.2} s: {} hands sent, {} \
             worlds taken in ({} lost); this participant's hand -> world p50 {} us, p99 {} us",
            s["endpoint"].as_str().unwrap_or("?"),
            s["participant"],
            s["name"].as_str().unwrap_or("?"),
            s["join_s"].as_f64().unwrap_or(0.0),
            s["hands_sent"],
            s["worlds_taken_in"],
            s["worlds_lost"],
            us(&h["p50"]),
            us(&h["p99"]),
        )
    }
}
