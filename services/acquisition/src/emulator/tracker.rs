//! An emulated FASTRAK: the commands the driver uses (`c C P F f U u O`), ASCII and binary
//! records, up to four stations sharing 120 records a second, and a receiver that moves the
//! wrist along a circle while turning it gently.

use std::io;
use std::path::Path;
use std::time::Instant;

use glam::DQuat;

use super::{serve, Device, Emit, Emulator, EmulatorReport, Fault};
use crate::devices::fastrak::{encode_record, item, Format};

/// How the emulated tracker behaves.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackerBehaviour {
    /// Which stations (1..=4) have a receiver.
    pub stations: [bool; 4],
    /// Records per second, shared among the active stations (120 on a FASTRAK).
    pub rate_hz: f64,
    /// Faults by record number (all stations' records counted together, from 0).
    pub faults: Vec<(u64, Fault)>,
}

impl TrackerBehaviour {
    /// A healthy tracker with one receiver, on station 1.
    pub fn new() -> TrackerBehaviour {
        TrackerBehaviour {
            stations: [true, false, false, false],
            rate_hz: 120.0,
            faults: Vec::new(),
        }
    }
}

impl Default for TrackerBehaviour {
    fn default() -> Self {
        TrackerBehaviour::new()
    }
}

/// Centre and radius (cm, tracker frame) of the emulated receiver's circle.
pub const CIRCLE_CENTRE_CM: [f64; 3] = [40.0, 0.0, 20.0];
pub const CIRCLE_RADIUS_CM: f64 = 10.0;

/// The emulated receiver at time `t` seconds: position in cm (tracker frame: x forward,
/// y right, z down) on a circle in the x-y plane, and azimuth (degrees) swinging ±30°.
pub fn motion(t: f64) -> ([f64; 3], f64) {
    let a = t * std::f64::consts::TAU / 4.0;
    let pos = [
        CIRCLE_CENTRE_CM[0] + CIRCLE_RADIUS_CM * a.cos(),
        CIRCLE_CENTRE_CM[1] + CIRCLE_RADIUS_CM * a.sin(),
        CIRCLE_CENTRE_CM[2],
    ];
    (pos, 30.0 * (a / 2.0).sin())
}

struct TrackerDevice {
    b: TrackerBehaviour,
    format: Format,
    inches: bool,
    continuous: bool,
    lists: [Vec<u8>; 4],
    command: Vec<u8>,
    in_command: bool,
    next_at: Instant,
    next_station: usize,
    start: Instant,
    rec: Vec<u8>,
}

impl TrackerDevice {
    fn new(b: TrackerBehaviour) -> TrackerDevice {
        let mut d = TrackerDevice {
            b,
            format: Format::Ascii,
            inches: true,
            continuous: false,
            lists: Default::default(),
            command: Vec::new(),
            in_command: false,
            next_at: Instant::now(),
            next_station: 0,
            start: Instant::now(),
            rec: Vec::with_capacity(64),
        };
        d.power_up();
        d
    }

    fn send(&mut self, station: usize, now: Instant, out: &mut Emit) {
        let t = now.duration_since(self.start).as_secs_f64();
        let (mut pos, az) = motion(t);
        if self.inches {
            for p in pos.iter_mut() {
                *p /= 2.54;
            }
        }
        let q = DQuat::from_rotation_z(az.to_radians());
        self.rec.clear();
        encode_record(
            self.format,
            &self.lists[station],
            station as u8 + 1,
            pos,
            [az, 0.0, 0.0],
            [q.w, q.x, q.y, q.z],
            &mut self.rec,
        );
        out.record(&self.rec);
    }

    /// `O<station>,<item>,...` once its carriage return arrives.
    fn output_list(&mut self) {
        let text = String::from_utf8_lossy(&self.command).into_owned();
        self.command.clear();
        let mut parts = text.split(',');
        let Some(Ok(station)) = parts.next().map(|s| s.trim().parse::<usize>()) else {
            return;
        };
        if !(1..=4).contains(&station) {
            return;
        }
        let items: Option<Vec<u8>> = parts.map(|s| s.trim().parse::<u8>().ok()).collect();
        if let Some(items) = items {
            if !items.is_empty() {
                self.lists[station - 1] = items;
            }
        }
    }
}

impl Device for TrackerDevice {
    fn on_input(&mut self, bytes: &[u8], now: Instant, out: &mut Emit) {
        for &c in bytes {
            if self.in_command {
                if c == b'\r' {
                    self.in_command = false;
                    self.output_list();
                } else if self.command.len() < 64 {
                    self.command.push(c);
                }
                continue;
            }
            match c {
                b'C' => {
                    self.continuous = true;
                    self.next_at = now;
                }
                b'c' => self.continuous = false,
                b'P' => {
                    for s in 0..4 {
                        if self.b.stations[s] {
                            self.send(s, now, out);
                        }
                    }
                }
                b'F' => self.format = Format::Ascii,
                b'f' => self.format = Format::Binary,
                b'U' => self.inches = true,
                b'u' => self.inches = false,
                b'O' => {
                    self.in_command = true;
                    self.command.clear();
                }
                _ => {}
            }
        }
    }

    fn on_tick(&mut self, now: Instant, out: &mut Emit) -> Option<Instant> {
        if !self.continuous || !self.b.stations.iter().any(|s| *s) {
            return None;
        }
        if now >= self.next_at {
            // The next active station in turn: the 120 Hz is shared.
            for _ in 0..4 {
                let s = self.next_station;
                self.next_station = (self.next_station + 1) % 4;
                if self.b.stations[s] {
                    self.send(s, now, out);
                    break;
                }
            }
            let period = super::period(self.b.rate_hz);
            self.next_at = (self.next_at + period).max(now);
        }
        Some(self.next_at)
    }

    /// The FASTRAK's power-up defaults: ASCII, inches, not continuous, list 2,4,1.
    fn power_up(&mut self) {
        self.format = Format::Ascii;
        self.inches = true;
        self.continuous = false;
        self.in_command = false;
        for l in self.lists.iter_mut() {
            *l = vec![item::POSITION, item::EULER, item::CRLF];
        }
    }
}

/// Starts an emulated tracker on a thread; its [`Emulator::path`] is the port to open.
pub fn spawn(behaviour: TrackerBehaviour) -> io::Result<Emulator> {
    let faults = behaviour.faults.clone();
    Emulator::spawn("tracker", Box::new(TrackerDevice::new(behaviour)), faults)
}

/// Serves an emulated tracker at `link` until `stop()`.
/// For `handblocks emulate tracker --link PATH`.
pub fn run(
    link: &Path,
    behaviour: TrackerBehaviour,
    stop: &dyn Fn() -> bool,
) -> io::Result<EmulatorReport> {
    let faults = behaviour.faults.clone();
    let mut device = TrackerDevice::new(behaviour);
    serve(link, &mut device, faults, stop)
}
