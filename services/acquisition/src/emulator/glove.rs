//! An emulated CyberGlove: answers `?S`, `G`, streams on `S` until 0x03, and moves its hand
//! through a slow open-close cycle so a session shows something alive.

use std::io;
use std::path::Path;
use std::time::Instant;

use common::glove::{sensor_order, GloveJoint};

use super::{serve, Device, Emit, Emulator, EmulatorReport, Fault};
use crate::devices::cyberglove::STOP_STREAM;

/// How the emulated glove behaves.
#[derive(Debug, Clone, PartialEq)]
pub struct GloveBehaviour {
    /// Sensor bytes in each record.
    pub sensors: u8,
    /// The count it answers to `?S` (normally `sensors`; differ to emulate a confused glove).
    pub reported_sensors: u8,
    /// Records per second in streamed mode.
    pub rate_hz: f64,
    /// Faults by record number (records counted from 0 across polled and streamed output).
    pub faults: Vec<(u64, Fault)>,
    /// The glove is not plugged into the interface unit: every sample request is answered
    /// `eg` instead of a record (the unit still answers `?S`).
    pub glove_detached: bool,
}

impl GloveBehaviour {
    /// A healthy glove of `sensors` sensors at 100 Hz.
    pub fn new(sensors: u8) -> GloveBehaviour {
        GloveBehaviour {
            sensors,
            reported_sensors: sensors,
            rate_hz: 100.0,
            faults: Vec::new(),
            glove_detached: false,
        }
    }
}

/// The raw bytes the emulated glove sends for record `k`: every flexion sensor reads the same
/// grip value (a triangle wave over 1..=255 and back, 508 records per cycle), every
/// abduction and wrist sensor reads 128. So any sample a driver returns is internally
/// consistent, and a mix of two records, or a shifted one, is not.
pub fn raw_record(k: u64, sensors: usize, out: &mut [u8]) {
    let phase = (k % 508) as i64;
    let grip = if phase < 254 { phase + 1 } else { 508 - phase };
    let order = sensor_order(sensors as u32);
    for (i, b) in out.iter_mut().enumerate().take(sensors) {
        let flex = match order.and_then(|o| o.get(i)) {
            Some(j) => is_flexion(*j),
            None => true,
        };
        *b = if flex { grip as u8 } else { 128 };
    }
}

/// Whether a sensor bends a joint (as opposed to abduction or the wrist).
pub fn is_flexion(joint: GloveJoint) -> bool {
    use GloveJoint::*;
    !matches!(
        joint,
        ThumbIndexAbduction
            | MiddleIndexAbduction
            | RingMiddleAbduction
            | LittleRingAbduction
            | WristPitch
            | WristYaw
    )
}

struct GloveDevice {
    b: GloveBehaviour,
    streaming: bool,
    next_at: Instant,
    query: bool,
    k: u64,
    rec: Vec<u8>,
}

impl GloveDevice {
    fn new(b: GloveBehaviour) -> GloveDevice {
        GloveDevice {
            b,
            streaming: false,
            next_at: Instant::now(),
            query: false,
            k: 0,
            rec: Vec::with_capacity(32),
        }
    }

    fn send(&mut self, header: u8, out: &mut Emit) {
        if self.b.glove_detached {
            out.reply(b"eg");
            return;
        }
        let n = self.b.sensors as usize;
        self.rec.clear();
        self.rec.push(header);
        self.rec.resize(1 + n, 0);
        raw_record(self.k, n, &mut self.rec[1..]);
        self.rec.push(0);
        out.record(&self.rec);
        self.k += 1;
    }
}

impl Device for GloveDevice {
    fn on_input(&mut self, bytes: &[u8], now: Instant, out: &mut Emit) {
        for &c in bytes {
            if self.query {
                self.query = false;
                if c == b'S' {
                    out.reply(&[b'?', b'S', self.b.reported_sensors, 0]);
                    continue;
                }
            }
            match c {
                b'G' => self.send(b'G', out),
                b'S' => {
                    self.streaming = true;
                    self.next_at = now;
                }
                STOP_STREAM => self.streaming = false,
                b'?' => self.query = true,
                _ => {}
            }
        }
    }

    fn on_tick(&mut self, now: Instant, out: &mut Emit) -> Option<Instant> {
        if !self.streaming {
            return None;
        }
        if now >= self.next_at {
            self.send(b'S', out);
            let period = super::period(self.b.rate_hz);
            self.next_at = (self.next_at + period).max(now);
        }
        Some(self.next_at)
    }

    fn power_up(&mut self) {
        self.streaming = false;
        self.query = false;
    }
}

/// Starts an emulated glove on a thread; its [`Emulator::path`] is the port to open.
pub fn spawn(behaviour: GloveBehaviour) -> io::Result<Emulator> {
    let faults = behaviour.faults.clone();
    Emulator::spawn("glove", Box::new(GloveDevice::new(behaviour)), faults)
}

/// Serves an emulated glove at `link` (a symlink to the pty it creates) until `stop()`.
/// For `handblocks emulate glove --link PATH`.
pub fn run(
    link: &Path,
    behaviour: GloveBehaviour,
    stop: &dyn Fn() -> bool,
) -> io::Result<EmulatorReport> {
    let faults = behaviour.faults.clone();
    let mut device = GloveDevice::new(behaviour);
    serve(link, &mut device, faults, stop)
}
