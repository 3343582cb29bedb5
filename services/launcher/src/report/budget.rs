//! The budget: a merged report judged against the session's `[budget]` (latency
//! percentiles, samples dropped) and against what every session keeps without asking: a
//! source that delivers, and a renderer that keeps its frame rate, measured over the time
//! there were worlds to draw.

use common::config::session::Budget;
use common::latency::Metric;
use common::{Stage, Topic};

use super::{Report, SessionFacts};

impl Report {
    /// The session's `[budget]` keys: a line for each one it broke.
    pub(super) fn judge(&self, b: &Budget, facts: &SessionFacts) -> Vec<String> {
        let mut v = Vec::new();
        if let Some(limit) = b.origin_to_world_p99_us {
            match self.stage(Stage::Stepper) {
                Some(s) if s.summary(Metric::Origin).count > 0 => {
                    let p99 = s.summary(Metric::Origin).p99;
                    if p99 > limit {
                        v.push(format!("origin_to_world_p99_us: {p99} > {limit}"));
                    }
                }
                _ => v.push("origin_to_world_p99_us: the stepper published no world state".into()),
            }
        }
        if let Some(limit) = b.hop_p99_us {
            for s in &self.stages {
                let p99 = s.summary(Metric::Hop).p99;
                if s.summary(Metric::Hop).count > 0 && p99 > limit {
                    v.push(format!("hop_p99_us ({}): {p99} > {limit}", s.stage.name()));
                }
            }
        }
        if let Some(limit_ms) = b.origin_to_photon_p99_ms.filter(|_| facts.renders) {
            match self.stage(Stage::Renderer) {
                Some(s) if s.summary(Metric::Photon).count > 0 => {
                    let p99_ms = s.summary(Metric::Photon).p99 / 1000.0;
                    if p99_ms > limit_ms {
                        v.push(format!("origin_to_photon_p99_ms: {p99_ms} > {limit_ms}"));
                    }
                }
                _ => v.push("origin_to_photon_p99_ms: the renderer drew no frame".into()),
            }
        }
        if let Some(limit) = b.max_dropped {
            let dropped: u64 = self.topics.values().map(|f| f.dropped()).sum();
            if dropped > limit {
                v.push(format!("max_dropped: {dropped} > {limit}"));
            }
        }
        v
    }

    /// The budget every session keeps without asking: a source that delivers, and a renderer
    /// that keeps its frame rate.
    pub(super) fn judge_what_users_assume(&mut self, b: &Budget, facts: &SessionFacts) {
        let source = self.stage(facts.source).map(|s| {
            (
                s.silence_ns,
                s.summary(Metric::Origin).count,
                s.stage.name(),
            )
        });
        match source {
            Some((_, 0, name)) => self.violations.push(format!(
                "source_silence_ms: the source ({name}) delivered no sample in {:.1} s",
                facts.seconds
            )),
            Some((silence_ns, _, name)) if silence_ns as f64 / 1e6 > b.source_silence_ms => {
                self.violations.push(format!(
                    "source_silence_ms: the source ({name}) delivered no sample for {:.0} ms > {}",
                    silence_ns as f64 / 1e6,
                    b.source_silence_ms
                ))
            }
            Some(_) => {}
            None => self
                .violations
                .push("source_silence_ms: the source sent no report".into()),
        }
        if !facts.renders {
            // Nothing drew (off by choice, or no GPU adapter): no frame rate to judge.
            if b.origin_to_photon_p99_ms.is_some() {
                self.not_judged.push(
                    "origin_to_photon_p99_ms: the renderer did not run (skipped: no GPU adapter)"
                        .into(),
                );
            }
            return;
        }
        if facts.seconds < 0.5 {
            self.not_judged
                .push("frame_hz: the session was too short to measure a frame rate".into());
            return;
        }
        if !facts.real_time {
            self.not_judged.push(
                "frame_hz: a speed-0 replay runs as fast as its slowest reader, not in real time"
                    .into(),
            );
            return;
        }
        let frames = self
            .stage(Stage::Renderer)
            .map_or(0, |s| s.summary(Metric::Photon).count);
        // The world's publisher: the stepper, or the bridge of a remote-fed session.
        let worlds = self
            .stage(Stage::Stepper)
            .map(|s| s.summary(Metric::Origin).count)
            .or_else(|| self.topics.get(&Topic::World).map(|f| f.published))
            .unwrap_or(0);
        // Judged over the time there were worlds to draw: from the world publisher's first
        // world to its last (a viewer started before its session, or left running after it,
        // had nothing to draw then), or the whole session where that is not known.
        let world_s = self.world_seconds(facts.seconds);
        if worlds > 0 && world_s < 0.5 {
            self.not_judged.push(format!(
                "frame_hz: worlds arrived for only {world_s:.2} s, too short to measure a frame rate"
            ));
            return;
        }
        // While a restarted renderer was down there were no frames to draw: judged without it.
        let drawing_s = (world_s - facts.renderer_down_s).max(0.5);
        let fps = frames as f64 / drawing_s;
        // A frame is drawn for each new world state: fewer worlds than frame_hz is not the
        // renderer's shortfall.
        let world_hz = worlds as f64 / world_s.max(0.5);
        let wanted = b.frame_hz.min(world_hz);
        let floor = wanted * (1.0 - b.frame_rate_margin);
        if fps < floor {
            self.violations.push(format!(
                "frame_hz: {fps:.1} frames per second < {floor:.1} ({} {wanted:.1} less \
                 frame_rate_margin {:.0} %)",
                if wanted < b.frame_hz {
                    "the world's rate"
                } else {
                    "frame_hz"
                },
                b.frame_rate_margin * 100.0
            ));
        }
    }

    /// How long there were worlds to draw: from the world publisher's (the stepper's, or the
    /// bridge's of a remote-fed session) first world to its last, at most `seconds` (the
    /// session's); `seconds` where that is not known.
    pub(super) fn world_seconds(&self, seconds: f64) -> f64 {
        self.stage(Stage::Stepper)
            .or_else(|| self.stage(Stage::Bridge))
            .filter(|s| s.first_output_ns > 0 && s.last_output_ns > s.first_output_ns)
            .map_or(seconds, |s| {
                ((s.last_output_ns - s.first_output_ns) as f64 / 1e9).min(seconds)
            })
    }

    /// Frames per second the renderer drew, over the time there were worlds to draw.
    pub fn frame_rate(&self) -> Option<f64> {
        let s = self.stage(Stage::Renderer)?;
        let n = s.summary(Metric::Photon).count;
        let over = self.world_seconds(self.meta.seconds);
        (n > 0 && over > 0.0).then(|| n as f64 / over.max(0.5))
    }
}
