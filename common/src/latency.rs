//! Latency histograms (hdrhistogram): what each stage records, how it travels on the `latency`
//! topic, and how the launcher reads it back.
//!
//! Every stage records, per sample, in nanoseconds:
//! * [`Metric::Hop`]: the input's `publish_ns` to this stage's receive (the bus's own cost plus
//!   the wake-up);
//! * [`Metric::Process`]: receive to this stage's publish (its own work);
//! * [`Metric::Origin`]: the input's `origin_ns` to this stage's publish (the age of what it
//!   sends: origin -> world at the stepper);
//! * [`Metric::Photon`]: the renderer only, origin to the frame's GPU work complete.
//!
//! Recording never allocates; encoding (once a second) does, off the per-sample path.

use hdrhistogram::serialization::{Deserializer, Serializer, V2Serializer};
use hdrhistogram::Histogram;

use crate::bus::{BusError, Outlet};
use crate::samples::{LatencySample, TopicCounter, HISTOGRAM_BYTES, MAX_TOPIC_COUNTERS, METRICS};
use crate::stamp::{monotonic_ns, Stamp};
use crate::topic::{topics, Stage};

/// How long a stopping stage waits for the launcher to read its final report.
const RELEASE_WAIT: std::time::Duration = std::time::Duration::from_secs(5);

/// Highest latency a histogram holds (one hour); larger values are clamped to it.
const HIGHEST_NS: u64 = 3_600_000_000_000;
/// Two significant digits: 1 % resolution, and an encoding that fits one sample.
const SIGNIFICANT_DIGITS: u8 = 2;

/// Which latency a histogram holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Metric {
    Hop = 0,
    Process = 1,
    Origin = 2,
    /// The renderer's origin to GPU work complete; the webxr source's frame sent to the world
    /// that answers it drawn on the headset (the page's round trip).
    Photon = 3,
    /// The webxr source only: the page's JavaScript time per XR frame.
    Page = 4,
}

impl Metric {
    pub const ALL: [Metric; METRICS] = [
        Metric::Hop,
        Metric::Process,
        Metric::Origin,
        Metric::Photon,
        Metric::Page,
    ];

    /// The key in the session report.
    pub fn key(self) -> &'static str {
        match self {
            Metric::Hop => "hop_us",
            Metric::Process => "process_us",
            Metric::Origin => "origin_us",
            Metric::Photon => "photon_us",
            Metric::Page => "page_js_us",
        }
    }
}

/// A new, empty latency histogram in nanoseconds.
pub fn new_histogram() -> Histogram<u64> {
    // Bounds and digits are constants within hdrhistogram's allowed ranges.
    Histogram::new_with_bounds(1, HIGHEST_NS, SIGNIFICANT_DIGITS)
        .expect("constant histogram bounds are valid")
}

/// One stage's histograms.
pub struct LatencyRecorder {
    stage: Stage,
    histograms: [Histogram<u64>; METRICS],
    encoded: Vec<u8>,
    /// A source's last output (its start before the first), and its longest silence so far.
    last_output_ns: u64,
    longest_silence_ns: u64,
    /// When the first output's age was recorded (0: none yet), and the last's.
    first_output_ns: u64,
    recorded_last_ns: u64,
}

impl LatencyRecorder {
    pub fn new(stage: Stage) -> Self {
        LatencyRecorder {
            stage,
            histograms: [
                new_histogram(),
                new_histogram(),
                new_histogram(),
                new_histogram(),
                new_histogram(),
            ],
            encoded: Vec::with_capacity(HISTOGRAM_BYTES),
            last_output_ns: monotonic_ns(),
            longest_silence_ns: 0,
            first_output_ns: 0,
            recorded_last_ns: 0,
        }
    }

    /// Records one value in nanoseconds (0 is counted as 1 ns).
    pub fn record(&mut self, metric: Metric, ns: u64) {
        self.histograms[metric as usize].saturating_record(ns.max(1));
        // Every stage records its output's age (origin -> out) as it publishes or writes it.
        // When it first and last did (one read of the clock per output, vDSO: tens of ns).
        if metric == Metric::Origin {
            let now = monotonic_ns();
            if self.first_output_ns == 0 {
                self.first_output_ns = now;
            }
            self.recorded_last_ns = now;
        }
    }

    /// Records the hop of a sample received at `receive_ns`.
    pub fn hop(&mut self, input: &Stamp, receive_ns: u64) {
        self.record(Metric::Hop, receive_ns.saturating_sub(input.publish_ns));
    }

    /// Records what a stage did with an input received at `receive_ns` that left as `output`.
    pub fn output(&mut self, receive_ns: u64, output: &Stamp) {
        self.record(
            Metric::Process,
            output.publish_ns.saturating_sub(receive_ns),
        );
        self.record(
            Metric::Origin,
            output.publish_ns.saturating_sub(output.origin_ns),
        );
    }

    /// Records a sample a source just published: the time from its origin to its publish is
    /// both the source's processing and its origin latency.
    pub fn source_output(&mut self, sent: &Stamp) {
        let ns = sent.publish_ns.saturating_sub(sent.origin_ns);
        self.record(Metric::Process, ns);
        self.record(Metric::Origin, ns);
        self.delivered(sent.publish_ns);
    }

    /// A source delivered a sample at `publish_ns`: the silence before it counts.
    pub fn delivered(&mut self, publish_ns: u64) {
        let silence = publish_ns.saturating_sub(self.last_output_ns);
        self.longest_silence_ns = self.longest_silence_ns.max(silence);
        self.last_output_ns = publish_ns;
    }

    /// A source that waits for someone else to start (the bridge of a remote-fed session:
    /// the other half may start later) counts its silences from its first sample on.
    pub fn delivered_after_waiting(&mut self, publish_ns: u64) {
        if self.first_output_ns == 0 {
            self.last_output_ns = publish_ns;
        }
        self.delivered(publish_ns);
    }

    /// Writes this recorder's histograms and the given topic counters into `sample`.
    pub fn fill(
        &mut self,
        sample: &mut LatencySample,
        counters: &[TopicCounter],
        final_report: bool,
    ) {
        sample.stage = self.stage as u32;
        sample.final_report = final_report as u32;
        sample.first_output_ns = self.first_output_ns;
        sample.last_output_ns = self.recorded_last_ns;
        sample.silence_ns = self
            .longest_silence_ns
            .max(monotonic_ns().saturating_sub(self.last_output_ns));
        for (slot, c) in sample.counters.iter_mut().enumerate() {
            *c = counters.get(slot).copied().unwrap_or(TopicCounter {
                topic: u32::MAX,
                ..Default::default()
            });
        }
        for (m, h) in self.histograms.iter().enumerate() {
            self.encoded.clear();
            let out = &mut sample.histograms[m];
            match V2Serializer::new().serialize(h, &mut self.encoded) {
                Ok(n) if n <= HISTOGRAM_BYTES => {
                    out.bytes[..n].copy_from_slice(&self.encoded[..n]);
                    out.len = n as u32;
                }
                // Too large to travel: send the histogram with its resolution reduced.
                _ => {
                    let n = encode_coarse(h, &mut self.encoded);
                    out.bytes[..n].copy_from_slice(&self.encoded[..n]);
                    out.len = n as u32;
                }
            }
        }
    }
}

/// Re-records `h` into 100 µs buckets until its encoding fits (a stage whose latencies spread
/// over six decades); returns the encoded length, 0 if even that did not fit.
fn encode_coarse(h: &Histogram<u64>, buf: &mut Vec<u8>) -> usize {
    let mut coarse = new_histogram();
    for v in h.iter_recorded() {
        let value = (v.value_iterated_to() / 100_000).max(1) * 100_000;
        coarse.saturating_record_n(value, v.count_at_value());
    }
    buf.clear();
    match V2Serializer::new().serialize(&coarse, buf) {
        Ok(n) if n <= HISTOGRAM_BYTES => n,
        _ => 0,
    }
}

/// Decodes one histogram of a latency sample (an empty one if it carried none).
pub fn decode(sample: &LatencySample, metric: Metric) -> Result<Histogram<u64>, String> {
    let h = &sample.histograms[metric as usize];
    let len = (h.len as usize).min(HISTOGRAM_BYTES);
    if len == 0 {
        return Ok(new_histogram());
    }
    let mut reader = &h.bytes[..len];
    Deserializer::new()
        .deserialize::<u64, _>(&mut reader)
        .map_err(|e| format!("histogram {}: {e:?}", metric.key()))
}

/// The percentiles a report shows, in microseconds.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Summary {
    pub p50: f64,
    pub p90: f64,
    pub p99: f64,
    pub p999: f64,
    pub max: f64,
    pub count: u64,
}

impl Summary {
    pub fn of(h: &Histogram<u64>) -> Summary {
        if h.is_empty() {
            return Summary::default();
        }
        let us = |ns: u64| (ns as f64 / 1000.0 * 10.0).round() / 10.0;
        Summary {
            p50: us(h.value_at_quantile(0.50)),
            p90: us(h.value_at_quantile(0.90)),
            p99: us(h.value_at_quantile(0.99)),
            p999: us(h.value_at_quantile(0.999)),
            max: us(h.max()),
            count: h.len(),
        }
    }
}

/// Publishes a stage's histograms and counters on `latency`: about once a second, and once
/// more, final, when the stage stops. The sample buffer is allocated once.
pub struct Reporter {
    pub recorder: LatencyRecorder,
    outlet: Outlet<topics::Latency>,
    sample: Box<LatencySample>,
    next_report_ns: u64,
    period_ns: u64,
}

impl Reporter {
    pub fn new(stage: Stage, outlet: Outlet<topics::Latency>) -> Self {
        Reporter {
            recorder: LatencyRecorder::new(stage),
            outlet,
            sample: Box::default(),
            next_report_ns: monotonic_ns() + 1_000_000_000,
            period_ns: 1_000_000_000,
        }
    }

    /// What the devices counted, carried by every report from now on (the acquisition process
    /// sets it before its final report).
    pub fn set_devices(&mut self, devices: [crate::DeviceCounters; 2]) {
        self.sample.devices = devices;
    }

    /// Publishes a periodic report if one is due.
    pub fn maybe_report(&mut self, counters: &[TopicCounter]) -> Result<(), BusError> {
        let now = monotonic_ns();
        if now < self.next_report_ns {
            return Ok(());
        }
        self.next_report_ns = now + self.period_ns;
        self.report(counters, false)
    }

    /// Publishes the final report, then holds this process's ports until the launcher has read
    /// it and releases the process (see [`crate::shutdown`]), at most `RELEASE_WAIT`.
    pub fn finish(&mut self, counters: &[TopicCounter]) -> Result<(), BusError> {
        self.report(counters, true)?;
        crate::shutdown::wait_for_release(RELEASE_WAIT);
        Ok(())
    }

    /// Publishes a report now.
    pub fn report(
        &mut self,
        counters: &[TopicCounter],
        final_report: bool,
    ) -> Result<(), BusError> {
        debug_assert!(counters.len() <= MAX_TOPIC_COUNTERS);
        self.recorder.fill(&mut self.sample, counters, final_report);
        self.sample.stamp = Stamp::at_origin(0, 0);
        self.outlet.publish(&self.sample).map(|_| ())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn histograms_survive_the_wire() {
        let mut r = LatencyRecorder::new(Stage::Stepper);
        for i in 1..=10_000u64 {
            r.record(Metric::Hop, i * 1000);
            r.record(Metric::Origin, 5_000 + i);
        }
        let mut s = Box::<LatencySample>::default();
        r.fill(&mut s, &[], true);
        let hop = decode(&s, Metric::Hop).unwrap();
        assert_eq!(hop.len(), 10_000);
        let p50 = Summary::of(&hop).p50;
        assert!((p50 - 5000.0).abs() / 5000.0 < 0.01, "p50 {p50}");
        assert_eq!(decode(&s, Metric::Photon).unwrap().len(), 0);
    }

    #[test]
    fn a_wide_spread_still_fits() {
        let mut r = LatencyRecorder::new(Stage::Renderer);
        let mut x = 12345u64;
        for _ in 0..200_000 {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            r.record(Metric::Photon, 1 + (x >> 20) % 3_000_000_000_000);
        }
        let mut s = Box::<LatencySample>::default();
        r.fill(&mut s, &[], false);
        assert!(s.histograms[Metric::Photon as usize].len > 0);
        assert_eq!(decode(&s, Metric::Photon).unwrap().len(), 200_000);
    }
}
