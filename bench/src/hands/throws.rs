//! Scripted throws with a known release velocity, degraded as hand trackers deliver them, and
//! scored for the world's own rules (`[world] hands = "tracked"` and `"paper"`) and for the
//! SDK baselines of [`super::baselines`].
//!
//! **The throw.** A 6 cm cube rests on the floor. A bare check-point hand (thumb, index,
//! middle; three check points each, knuckle to tip; no palm) comes down over it with its
//! fingers open, closes (thumb on the cube's +x face, index and middle on its -x face, every
//! point [`GRIP_DEPTH`] inside the faces, as real grasps interpenetrate), lifts it to a ready
//! point and throws it: the cube's centre G moves along a circular arc (a gently curved path:
//! it turns by 10-30 deg over the wind-up) with speed `v_r sin^2` rising over a wind-up of
//! 0.15-0.35 s to its peak `v_r` at the release time `t_r`, then `v_r cos^2` falling to rest
//! over a 0.15-0.25 s follow-through. The wrist turns about the grip axis by 15-45 deg over
//! the wind-up (in proportion to the path travelled) and the hand is rolled by up to 30 deg
//! about the throw direction. The fingers open from `t_r`: each side 2.5-4 cm (the aperture
//! grows by 5-8 cm) in 60 ms (minimum-jerk). The grip axis is kept square to the path, so the
//! opening fingers never sweep through the flying cube. G is rigid with the wrist throughout:
//! the ground truth is G's velocity at `t_r`, `v_r d`, exactly (the path is closed-form; a
//! test differentiates the hand's own samples to check it). Speeds are log-uniform over
//! 0.5-5 m/s, directions uniform in azimuth over +-90 deg from forward (-z) and in elevation
//! over -10..70 deg (forward, sideways, upward: the hemisphere in front). Everything is drawn
//! from a seeded splitmix64, so a run is reproducible bit for bit.
//!
//! **The degradation** ([`Level`], [`degrade`]): samples at the level's rate, stamped on its
//! grid (`ceil(k 1e9 / rate)` ns); each carries the pose from `t - latency (1 + j)`, j uniform
//! in +-0.1 (latency jitter of +-10 %); white Gaussian noise per sample, one independent offset
//! for the wrist position and one for every finger check point, each of the level's sd per
//! axis (the wrist's rotation is not perturbed); tracking gaps during which the samples repeat
//! the last pose delivered and carry `tracked = 0` (as CARL replay and the webxr stage do).
//! Gaps are placed in the tracker's output time: "during the carry", "ending at the release" or
//! "across the release", the release being `t_r + latency` there.
//!
//! **The worlds**: the samples go through `stepper::timeline::Timeline` exactly as
//! `stepper::simulate_samples_with` feeds them (the world steps at 120 Hz with hands
//! interpolated between samples), into a [`stepper::World`] built from a scene made here.

use std::f64::consts::PI;
use std::path::PathBuf;

use common::config::scene::{BlockSpec, Effects, HandRules, ShapeSpec, WorldSettings};
use common::config::Scene;
use common::{HandSample, Pose, Stamp};
use glam::{DMat3, DQuat, DVec3};
use stepper::timeline::Timeline;
use stepper::{EventKind, World};

/// The cube's edge (m).
pub const CUBE: f64 = 0.06;
/// How far the holding check points are inside the cube's faces (m).
pub const GRIP_DEPTH: f64 = 0.004;
/// The cube's G in the wrist frame while held.
pub const G_LOCAL: DVec3 = DVec3::new(0.0, -0.08, 0.0);
/// Half the open hand's aperture (thumb and fingers this far from G along the grip axis).
const OPEN_HALF: f64 = 0.06;
/// Half the holding aperture.
const HOLD_HALF: f64 = CUBE / 2.0 - GRIP_DEPTH;
/// The check points along each finger (wrist frame y, knuckle to tip) and each finger's z.
const POINT_Y: [f64; 3] = [-0.06, -0.08, -0.10];
const FINGER_Z: [f64; 3] = [0.0, -0.012, 0.012];
/// The left hand's check points along each finger, knuckle to tip: how much farther from G
/// than the tip along the grip axis (wrist frame y). Its fingertips press on the cube's y
/// faces, each finger square to its face: a finger lying along a face (points spread along x
/// or z) with its end points within 1 cm of the side faces is one that R1's contact of a
/// point inside the block (its nearest face) reads as touching two opposite side faces once
/// the cube sits a centimetre off in the grip (as it does: R8 lifts the cube out of the floor
/// every time a noisy wrist presses it in, before the lift), and R3 / T1 then never let go.
pub const LEFT_POINT_OUT: [f64; 3] = [0.04, 0.02, 0.0];
/// How far the left's fingers are held off along the wrist frame's +z until they slide in
/// (clear of the cube: FINGER_Z within 1.2 cm, the cube's half 3 cm).
const LEFT_SLIDE: f64 = 0.07;
/// The left joins the right's grasp during the lift: its open fingers slide in along z from
/// LEFT_SLIDE_START to LEFT_CLOSE_START (the cube then 5 cm up or more, so that no left
/// fingertip is ever below its bottom face on the floor), then close over LEFT_CLOSE_END -
/// LEFT_CLOSE_START, as long as the right's closing.
pub const LEFT_SLIDE_START: f64 = 0.65;
pub const LEFT_CLOSE_START: f64 = 0.75;
pub const LEFT_CLOSE_END: f64 = LEFT_CLOSE_START + 0.12;
/// The script's phases (s): the hand comes down over the cube until DESCEND_END, closes
/// until CLOSE_END, holds, lifts from LIFT_START to the ready point at WINDUP_START.
const DESCEND_END: f64 = 0.3;
const CLOSE_END: f64 = 0.42;
const LIFT_START: f64 = 0.5;
pub const WINDUP_START: f64 = 1.2;
/// The hand comes down from this far above the cube.
const DESCEND_FROM: f64 = 0.2;
/// The fingers open over this long from t_r.
pub const OPEN_TIME: f64 = 0.06;
/// The script goes on this long after t_r (the follow-through, then the hand at rest).
pub const AFTER_RELEASE: f64 = 0.45;
/// Where the cube rests at the start, and where the lift takes it (the wind-up's start).
const REST: DVec3 = DVec3::new(0.0, CUBE / 2.0, 0.0);
const READY: DVec3 = DVec3::new(0.0, 0.8, 0.0);

/// A small deterministic PRNG (splitmix64): no dependency, the same numbers everywhere.
#[derive(Debug, Clone)]
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Rng {
        Rng(seed)
    }

    /// A seed from several numbers (each mixed in turn).
    pub fn seeded(parts: &[u64]) -> Rng {
        let mut r = Rng(0x5eed_0f4a_4db1_0c41);
        for p in parts {
            r.0 ^= *p;
            r.0 = r.next_u64();
        }
        r
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in [a, b).
    pub fn range(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * self.uniform()
    }

    /// A random sign.
    pub fn sign(&mut self) -> f64 {
        if self.next_u64() & 1 == 0 {
            1.0
        } else {
            -1.0
        }
    }

    /// Standard normal (Box-Muller).
    pub fn normal(&mut self) -> f64 {
        let u1 = 1.0 - self.uniform();
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (2.0 * PI * u2).cos()
    }

    fn normal3(&mut self, sd: f64) -> DVec3 {
        DVec3::new(self.normal(), self.normal(), self.normal()) * sd
    }
}

/// Minimum-jerk blend 0 -> 1 over s in [0, 1] (clamped).
fn minjerk(s: f64) -> f64 {
    let s = s.clamp(0.0, 1.0);
    s * s * s * (10.0 - 15.0 * s + 6.0 * s * s)
}

/// One scripted throw.
#[derive(Debug, Clone)]
pub struct Throw {
    pub index: usize,
    /// Release speed v_r (m/s).
    pub speed: f64,
    /// Release direction d (unit).
    pub dir: DVec3,
    /// Release time t_r (s): the peak of the speed, the start of the fingers' opening.
    pub t_r: f64,
    /// Wind-up and follow-through durations (s).
    pub windup: f64,
    pub follow: f64,
    /// How far each side of the grip opens (m).
    pub open: f64,
    /// The arc's curvature (1/m) toward `e` and the wrist's turn per metre about `grip`.
    kappa: f64,
    e: DVec3,
    kappa_w: f64,
    /// The wrist's rotation at t_r.
    r_release: DQuat,
    /// Where G is at t_r.
    p_release: DVec3,
}

impl Throw {
    /// Throw number `index` of the run seeded `seed`.
    pub fn new(seed: u64, index: usize) -> Throw {
        let mut rng = Rng::seeded(&[seed, index as u64, 0x7417]);
        let speed = 0.5 * 10f64.powf(rng.uniform());
        let az = rng.range(-90.0, 90.0).to_radians();
        let el = rng.range(-10.0, 70.0).to_radians();
        let dir = DVec3::new(az.sin() * el.cos(), el.sin(), -az.cos() * el.cos());
        let windup = rng.range(0.15, 0.35);
        let follow = rng.range(0.15, 0.25);
        let open = rng.range(0.025, 0.04);
        let roll = rng.range(-30.0, 30.0).to_radians();
        let turn = rng.range(10.0, 30.0).to_radians() * rng.sign();
        let flex = rng.range(15.0, 45.0).to_radians() * rng.sign();
        // The wrist frame at release: local -z along d, local x (the grip axis) square to d,
        // horizontal before the roll.
        let z = -dir;
        let side = dir.cross(DVec3::Y).normalize_or(DVec3::X);
        let x = DQuat::from_axis_angle(dir, roll) * side;
        let y = z.cross(x);
        let r_release = DQuat::from_mat3(&DMat3::from_cols(x, y, z)).normalize();
        let half_path = speed * windup / 2.0;
        let mut t = Throw {
            index,
            speed,
            dir,
            t_r: WINDUP_START + windup,
            windup,
            follow,
            open,
            kappa: turn / half_path,
            e: y,
            kappa_w: flex / half_path,
            r_release,
            p_release: DVec3::ZERO,
        };
        // Place the arc so that the wind-up starts at the ready point.
        let (start, _) = t.arc(-half_path);
        t.p_release = READY - start;
        t
    }

    /// The ground truth: G's velocity at t_r.
    pub fn velocity(&self) -> DVec3 {
        self.dir * self.speed
    }

    /// When the script ends (the hand at rest after the follow-through).
    pub fn end_time(&self) -> f64 {
        self.t_r + AFTER_RELEASE
    }

    /// G's offset from the release point and the wrist's rotation at arc length `s` from the
    /// release (negative before it).
    fn arc(&self, s: f64) -> (DVec3, DQuat) {
        let a = self.kappa * s;
        let g = if self.kappa.abs() < 1e-12 {
            self.dir * s
        } else {
            self.dir * (a.sin() / self.kappa) + self.e * ((1.0 - a.cos()) / self.kappa)
        };
        let grip = self.r_release * DVec3::X;
        let rot = (DQuat::from_axis_angle(grip, self.kappa_w * s) * self.r_release).normalize();
        (self.p_release + g, rot)
    }

    /// Arc length from the release point at time t (wind-up: negative).
    fn arc_length(&self, t: f64) -> f64 {
        let (v, tw, tf) = (self.speed, self.windup, self.follow);
        let ws = self.t_r - tw;
        if t <= ws {
            -v * tw / 2.0
        } else if t <= self.t_r {
            let tau = t - ws;
            v / 2.0 * (tau - tw / PI * (PI * tau / tw).sin()) - v * tw / 2.0
        } else if t <= self.t_r + tf {
            let tau = t - self.t_r;
            v / 2.0 * (tau + tf / PI * (PI * tau / tf).sin())
        } else {
            v * tf / 2.0
        }
    }

    /// G and the wrist's rotation at time t (before the grasp: where G will be held).
    pub fn pose(&self, t: f64) -> (DVec3, DQuat) {
        if t < DESCEND_END {
            let up = DESCEND_FROM * (1.0 - minjerk(t / DESCEND_END));
            (REST + DVec3::Y * up, DQuat::IDENTITY)
        } else if t < LIFT_START {
            (REST, DQuat::IDENTITY)
        } else if t < WINDUP_START {
            let s = minjerk((t - LIFT_START) / (WINDUP_START - LIFT_START));
            let (_, r_ready) = self.arc(self.arc_length(WINDUP_START));
            (
                REST.lerp(READY, s),
                DQuat::IDENTITY.slerp(r_ready, s).normalize(),
            )
        } else {
            self.arc(self.arc_length(t))
        }
    }

    /// G's true speed (m/s) at time t: the script's path differentiated (central, 10 us).
    pub fn g_speed(&self, t: f64) -> f64 {
        let h = 1e-5;
        (self.pose(t + h).0 - self.pose((t - h).max(0.0)).0).length() / (t + h - (t - h).max(0.0))
    }

    /// Half the grip's aperture (thumb and fingers from G along the grip axis) at time t: the
    /// fingers closing over [`close.0`, `close.1`) (the right's: DESCEND_END to CLOSE_END) and
    /// opening from `open_at` (the one-hand throw's: t_r).
    fn half_aperture(&self, t: f64, close: (f64, f64), open_at: f64) -> f64 {
        let (from, to) = close;
        if t < from {
            OPEN_HALF
        } else if t < to {
            OPEN_HALF + (HOLD_HALF - OPEN_HALF) * minjerk((t - from) / (to - from))
        } else if t < open_at {
            HOLD_HALF
        } else {
            HOLD_HALF + self.open * minjerk((t - open_at) / OPEN_TIME)
        }
    }

    /// The ideal hand at time t (tracked, stamped 0): the right hand of the one-hand throw,
    /// opening at t_r.
    pub fn hand(&self, t: f64) -> HandSample {
        self.hand_of(Side::Right, t, self.t_r)
    }

    /// The ideal hand on `side` at time t, its fingers opening from `open_at` (t_r: the
    /// throw's). Both have the same wrist. The right pinches across the wrist frame's x
    /// faces ([`Throw::hand`]); the left across its y faces: its thumb on the +y face (toward
    /// the wrist), index and middle on the -y face, each finger square to its face (its
    /// points [`LEFT_POINT_OUT`] out from the tip, at x = 0 and the fingers' z [`FINGER_Z`]),
    /// the tips GRIP_DEPTH inside the faces when held; the same opening. The
    /// right picks the cube up; the left joins during the lift: its open fingers, held
    /// [`LEFT_SLIDE`] off along the wrist's +z until then, slide in from [`LEFT_SLIDE_START`]
    /// and close from [`LEFT_CLOSE_START`] to [`LEFT_CLOSE_END`] (as long as the right's
    /// closing): a hand cannot get a finger under a cube on the floor, and one pushing it up
    /// from below would throw it into the other fingers.
    pub fn hand_of(&self, side: Side, t: f64, open_at: f64) -> HandSample {
        let (g, rot) = self.pose(t);
        let wrist = g - rot * G_LOCAL;
        let close = match side {
            Side::Right => (DESCEND_END, CLOSE_END),
            Side::Left => (LEFT_CLOSE_START, LEFT_CLOSE_END),
        };
        let half = self.half_aperture(t, close, open_at);
        let mut h = HandSample {
            stamp: Stamp::default(),
            wrist: Pose {
                position: wrist.to_array(),
                rotation: rot.to_array(),
            },
            tracked: 1,
            finger_count: 3,
            palm_vertex_count: 0,
            ..HandSample::default()
        };
        let slide = if t < LEFT_SLIDE_START {
            LEFT_SLIDE
        } else {
            LEFT_SLIDE
                * (1.0 - minjerk((t - LEFT_SLIDE_START) / (LEFT_CLOSE_START - LEFT_SLIDE_START)))
        };
        for (f, z) in FINGER_Z.iter().enumerate() {
            let side_sign = if f == 0 { 1.0 } else { -1.0 };
            let x = side_sign * half;
            h.finger_point_count[f] = POINT_Y.len() as u32;
            for (j, y) in POINT_Y.iter().enumerate() {
                let local = match side {
                    Side::Right => G_LOCAL + DVec3::new(x, y - G_LOCAL.y, *z),
                    Side::Left => {
                        G_LOCAL + DVec3::new(0.0, x + side_sign * LEFT_POINT_OUT[j], z + slide)
                    }
                };
                h.finger_points[f][j] = (wrist + rot * local).to_array();
            }
        }
        h
    }
}

/// Which hand: slot 0 of a two-hand world is the right, slot 1 the left.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    Right,
    Left,
}

/// Tracking gaps of a level.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gaps {
    /// Length range (s).
    pub min_s: f64,
    pub max_s: f64,
    /// The chance that a throw has gaps at all.
    pub chance: f64,
    /// A throw with gaps has 1 to this many.
    pub max_count: u32,
    /// Every throw's first gap placed by its index (carry, ending at the release, across the
    /// release, in turn) rather than at random among the three.
    pub cycle: bool,
}

/// One degradation level, as a tracker delivers the hand.
#[derive(Debug, Clone, PartialEq)]
pub struct Level {
    pub name: &'static str,
    pub rate_hz: f64,
    /// White noise sd per axis (m).
    pub noise: f64,
    /// Latency (s).
    pub latency: f64,
    pub gaps: Option<Gaps>,
    /// What it is, for the page.
    pub what: &'static str,
}

impl Level {
    fn ideal(name: &'static str, what: &'static str) -> Level {
        Level {
            name,
            rate_hz: 120.0,
            noise: 0.0,
            latency: 0.0,
            gaps: None,
            what,
        }
    }

    /// The gaps in words.
    pub fn gaps_text(&self) -> String {
        match &self.gaps {
            None => "none".into(),
            Some(g) => {
                let len = if g.min_s == g.max_s {
                    format!("{:.0} ms", g.min_s * 1e3)
                } else {
                    format!("{:.0}-{:.0} ms", g.min_s * 1e3, g.max_s * 1e3)
                };
                let count = if g.max_count > 1 {
                    format!("1-{} gaps", g.max_count)
                } else {
                    "one gap".into()
                };
                let chance = if g.chance >= 1.0 {
                    "every throw".to_string()
                } else {
                    format!("{:.0} % of throws", g.chance * 100.0)
                };
                format!("{count} of {len} in {chance}")
            }
        }
    }
}

fn one_gap(len_ms: f64) -> Option<Gaps> {
    Some(Gaps {
        min_s: len_ms / 1e3,
        max_s: len_ms / 1e3,
        chance: 1.0,
        max_count: 1,
        cycle: true,
    })
}

/// The named levels: ideal, the headline `quest`, `worst`, then one factor at a time from
/// `ideal` (120 Hz, no noise, no latency, no gaps) with only the named factor changed.
pub fn levels() -> Vec<Level> {
    let mut v = vec![
        Level::ideal("ideal", "120 Hz, exact poses: the rules' own error"),
        Level {
            name: "quest",
            rate_hz: 90.0,
            noise: 0.005,
            latency: 0.040,
            gaps: Some(Gaps {
                min_s: 0.05,
                max_s: 0.10,
                chance: 0.25,
                max_count: 1,
                cycle: false,
            }),
            what: "the headline: a Quest-class tracker",
        },
        Level {
            name: "worst",
            rate_hz: 30.0,
            noise: 0.011,
            latency: 0.040,
            gaps: Some(Gaps {
                min_s: 0.05,
                max_s: 0.20,
                chance: 1.0,
                max_count: 2,
                cycle: false,
            }),
            what: "every factor at its worst",
        },
    ];
    for hz in [30.0, 60.0, 90.0] {
        v.push(Level {
            name: match hz as u32 {
                30 => "rate30",
                60 => "rate60",
                _ => "rate90",
            },
            rate_hz: hz,
            what: "ideal but the rate",
            ..Level::ideal("", "")
        });
    }
    for (name, mm) in [("noise2", 2.0), ("noise5", 5.0), ("noise11", 11.0)] {
        v.push(Level {
            name,
            noise: mm / 1e3,
            what: "ideal but the noise",
            ..Level::ideal("", "")
        });
    }
    for (name, ms) in [("latency0", 0.0), ("latency20", 20.0), ("latency40", 40.0)] {
        v.push(Level {
            name,
            latency: ms / 1e3,
            what: "ideal but the latency",
            ..Level::ideal("", "")
        });
    }
    for (name, ms) in [
        ("gap50", 50.0),
        ("gap100", 100.0),
        ("gap150", 150.0),
        ("gap200", 200.0),
    ] {
        v.push(Level {
            name,
            gaps: one_gap(ms),
            what: "ideal but one gap a throw",
            ..Level::ideal("", "")
        });
    }
    v
}

/// Where a gap goes in a throw.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Placement {
    /// Anywhere in the carry, away from the release.
    Carry,
    /// Ending exactly at the release (as the tracker delivers it).
    BeforeRelease,
    /// Centred on the release.
    AcrossRelease,
}

/// The gaps of one throw at one level: [start, end) in the tracker's output time (s).
pub fn place_gaps(g: &Gaps, throw: &Throw, latency: f64, rng: &mut Rng) -> Vec<(f64, f64)> {
    if rng.uniform() >= g.chance {
        return Vec::new();
    }
    let count = 1 + (rng.next_u64() % u64::from(g.max_count.max(1))) as u32;
    let release = throw.t_r + latency;
    let mut out = Vec::new();
    for n in 0..count {
        let len = rng.range(g.min_s, g.max_s.max(g.min_s));
        let which = if n > 0 {
            Placement::Carry
        } else if g.cycle {
            [
                Placement::Carry,
                Placement::BeforeRelease,
                Placement::AcrossRelease,
            ][throw.index % 3]
        } else {
            [
                Placement::Carry,
                Placement::BeforeRelease,
                Placement::AcrossRelease,
            ][(rng.next_u64() % 3) as usize]
        };
        let start = match which {
            Placement::Carry => {
                // From a little after the grasp to a little before the release.
                let lo = CLOSE_END + latency + 0.1;
                let hi = (release - len - 0.05).max(lo);
                rng.range(lo, hi)
            }
            Placement::BeforeRelease => release - len,
            Placement::AcrossRelease => release - len / 2.0,
        };
        out.push((start, start + len));
    }
    out
}

/// The throw's samples as `level` delivers them; `seed` and the level's index make the draw.
pub fn degrade(throw: &Throw, level: &Level, level_index: usize, seed: u64) -> Vec<HandSample> {
    degrade_hand(throw, level, level_index, seed, None, |t| throw.hand(t))
}

/// [`degrade`] for any ideal hand of the throw, `hand(t)`: the samples as `level` delivers
/// them, on its time grid. `salt` None draws exactly as [`degrade`]; `Some(s)` mixes `s` into
/// the seed, so that each hand of a pair gets its own noise, gaps and latency jitter.
pub fn degrade_hand(
    throw: &Throw,
    level: &Level,
    level_index: usize,
    seed: u64,
    salt: Option<u64>,
    hand: impl Fn(f64) -> HandSample,
) -> Vec<HandSample> {
    let mut rng = match salt {
        None => Rng::seeded(&[seed, level_index as u64, throw.index as u64, 0xde9]),
        Some(s) => Rng::seeded(&[seed, level_index as u64, throw.index as u64, 0xde9, s]),
    };
    let gaps = level
        .gaps
        .as_ref()
        .map(|g| place_gaps(g, throw, level.latency, &mut rng))
        .unwrap_or_default();
    let end = throw.end_time() + level.latency;
    let rate = level.rate_hz.max(1.0);
    let mut out: Vec<HandSample> = Vec::with_capacity((end * rate) as usize + 2);
    for k in 0u64.. {
        let t_ns = (k as f64 * 1e9 / rate).ceil() as u64;
        let t = t_ns as f64 / 1e9;
        if t > end {
            break;
        }
        let in_gap = gaps.iter().any(|&(a, b)| t >= a && t < b);
        let mut h = match (in_gap, out.last()) {
            (true, Some(last)) => {
                let mut h = *last;
                h.tracked = 0;
                h
            }
            _ => {
                let pose_t = if level.latency > 0.0 {
                    (t - level.latency * (1.0 + rng.range(-0.1, 0.1))).max(0.0)
                } else {
                    t
                };
                let mut h = hand(pose_t);
                if level.noise > 0.0 {
                    let w = DVec3::from_array(h.wrist.position) + rng.normal3(level.noise);
                    h.wrist.position = w.to_array();
                    for f in 0..h.finger_count as usize {
                        for j in 0..h.finger_point_count[f] as usize {
                            let p =
                                DVec3::from_array(h.finger_points[f][j]) + rng.normal3(level.noise);
                            h.finger_points[f][j] = p.to_array();
                        }
                    }
                }
                h
            }
        };
        h.stamp = Stamp {
            seq: k,
            source_time_ns: t_ns,
            ..Stamp::default()
        };
        out.push(h);
    }
    out
}

/// The scene every throw runs in: the cube on the floor, default world settings but `hands`,
/// R13 with throw_window = 1 (the paper's).
pub fn scene(rules: HandRules) -> Scene {
    Scene {
        file: PathBuf::from(format!("<bench hands: {}>", rules.name())),
        world: WorldSettings {
            hands: rules,
            throw_window: 1,
            ..WorldSettings::default()
        },
        effects: Effects::default(),
        blocks: vec![BlockSpec {
            name: "cube".into(),
            shape: ShapeSpec::Box { size: [CUBE; 3] },
            position: REST.to_array(),
            rotation: [0.0, 0.0, 0.0, 1.0],
            velocity: [0.0; 3],
        }],
        hand: None,
        left_hand: None,
    }
}

/// What one world did with one throw's samples.
#[derive(Debug, Clone, Default)]
pub struct WorldRun {
    /// The step's duration (s).
    pub dt: f64,
    /// The cube's grasp and release events: (step, kind), in order.
    pub events: Vec<(u64, EventKind)>,
    /// The cube's velocity (v / dt) right after each Release event: (step, velocity).
    pub release_velocity: Vec<(u64, DVec3)>,
    /// Per step (index step - 1): the wrist the world was given, and the cube's G after it.
    pub wrist: Vec<(DVec3, DQuat)>,
    pub block: Vec<DVec3>,
}

impl WorldRun {
    /// The wrist and G after step `step` (1-based); None outside the run.
    pub fn at_step(&self, step: u64) -> Option<((DVec3, DQuat), DVec3)> {
        let i = usize::try_from(step).ok()?.checked_sub(1)?;
        Some((*self.wrist.get(i)?, *self.block.get(i)?))
    }
}

/// Runs a world of `scene` on `samples` the way `stepper::simulate_samples_with` does: the
/// first sample is the previous hand of step 1, and each sample brings the steps up to its
/// source time, with the hand interpolated between samples.
pub fn run_world(scene: &Scene, samples: &[HandSample]) -> Result<WorldRun, String> {
    let mut world =
        World::new(scene).map_err(|e| format!("{}: {}", e.file.display(), e.problem))?;
    let mut timeline = Timeline::new(scene.world.step_hz);
    let mut run = WorldRun {
        dt: 1.0 / scene.world.step_hz,
        ..WorldRun::default()
    };
    for hand in samples {
        if !timeline.started() {
            world.set_previous_hand(Some(hand));
        }
        timeline.advance(hand, |h| {
            world.step(h);
            let wrist = h.map_or((DVec3::ZERO, DQuat::IDENTITY), |h| {
                (
                    DVec3::from_array(h.wrist.position),
                    DQuat::from_array(h.wrist.rotation),
                )
            });
            run.wrist.push(wrist);
            let view = world.block(0);
            run.block.push(view.map_or(DVec3::ZERO, |b| b.position));
            for e in world.events() {
                if e.block != 0 || !matches!(e.kind, EventKind::Grasp | EventKind::Release) {
                    continue;
                }
                run.events.push((e.step, e.kind));
                if e.kind == EventKind::Release {
                    let v = view.map_or(DVec3::ZERO, |b| b.v) / run.dt;
                    run.release_velocity.push((e.step, v));
                }
            }
        });
    }
    Ok(run)
}

/// Grasp/release events of one estimator in time (s), as judged against the script.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Hold {
    Grab,
    Let,
}

/// How one estimator did on one throw.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Outcome {
    pub grasped: bool,
    /// Releases while the script still held (before t_r - one sample interval).
    pub false_drops: u32,
    /// Releases followed by a grasp within [`FLICKER_S`].
    pub flickers: u32,
    /// The release scored (the first at or after t_r - one sample interval; else the last
    /// one, a drop never recovered from): its time (s). None: never released.
    pub release_t: Option<f64>,
    /// The release scored is such a drop: the block was lost before the throw.
    pub lost: bool,
}

/// A release followed by a grasp within this long is a flicker.
pub const FLICKER_S: f64 = 0.2;

/// Judges a sequence of (time, grab or let go) against the script's release at `t_r`, for a
/// tracker sampling every `interval` seconds. Returns the outcome and the index of the scored
/// release in `events`.
pub fn judge(events: &[(f64, Hold)], t_r: f64, interval: f64) -> (Outcome, Option<usize>) {
    let mut o = Outcome {
        grasped: events.iter().any(|e| e.1 == Hold::Grab),
        ..Outcome::default()
    };
    let early = t_r - interval;
    let mut scored = None;
    let mut last_let = None;
    for (i, &(t, kind)) in events.iter().enumerate() {
        if kind != Hold::Let {
            continue;
        }
        last_let = Some(i);
        if t < early {
            o.false_drops += 1;
        } else if scored.is_none() {
            scored = Some(i);
        }
        if events[i + 1..]
            .iter()
            .take_while(|e| e.0 <= t + FLICKER_S + 1e-9)
            .any(|e| e.1 == Hold::Grab)
        {
            o.flickers += 1;
        }
    }
    let pick = scored.or(last_let);
    o.release_t = pick.map(|i| events[i].0);
    o.lost = scored.is_none() && last_let.is_some();
    (o, pick)
}

impl WorldRun {
    /// The world's events as (time, grab or let go).
    pub fn holds(&self) -> Vec<(f64, Hold)> {
        self.events
            .iter()
            .map(|&(step, kind)| {
                (
                    step as f64 * self.dt,
                    if kind == EventKind::Grasp {
                        Hold::Grab
                    } else {
                        Hold::Let
                    },
                )
            })
            .collect()
    }

    /// The step of the event at index `i` of `events`.
    pub fn step_of(&self, i: usize) -> Option<u64> {
        self.events.get(i).map(|e| e.0)
    }

    /// The velocity right after the Release of step `step`.
    pub fn velocity_at(&self, step: u64) -> Option<DVec3> {
        self.release_velocity
            .iter()
            .find(|r| r.0 == step)
            .map(|r| r.1)
    }

    /// The last Grasp at or before `step`.
    pub fn grasp_before(&self, step: u64) -> Option<u64> {
        self.events
            .iter()
            .filter(|e| e.1 == EventKind::Grasp && e.0 <= step)
            .map(|e| e.0)
            .next_back()
    }
}

/// Speed error (%, relative, absolute value) and direction error (deg) of `est` against
/// `truth`.
pub fn errors(est: DVec3, truth: DVec3) -> (f64, f64) {
    let t = truth.length();
    let speed = if t > 0.0 {
        (est.length() - t).abs() / t * 100.0
    } else {
        f64::NAN
    };
    let dir = if est.length() > 0.0 && t > 0.0 {
        est.normalize()
            .dot(truth / t)
            .clamp(-1.0, 1.0)
            .acos()
            .to_degrees()
    } else {
        180.0
    };
    (speed, dir)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn g_of(h: &HandSample) -> DVec3 {
        DVec3::from_array(h.wrist.position) + DQuat::from_array(h.wrist.rotation) * G_LOCAL
    }

    #[test]
    fn the_scripted_path_gives_the_release_velocity_back() {
        for i in 0..20 {
            let th = Throw::new(7, i);
            let h = 1e-6;
            let v = (g_of(&th.hand(th.t_r + h)) - g_of(&th.hand(th.t_r - h))) / (2.0 * h);
            let truth = th.velocity();
            assert!(
                (v - truth).length() < 1e-5 * truth.length(),
                "throw {i}: {v} vs {truth}"
            );
            assert!((0.5..=5.0).contains(&th.speed));
            // The path is continuous where the phases meet, and G stays above the floor.
            for t in [LIFT_START, WINDUP_START, th.t_r, th.t_r + th.follow] {
                let (a, b) = (g_of(&th.hand(t - 1e-9)), g_of(&th.hand(t + 1e-9)));
                assert!((a - b).length() < 1e-6, "throw {i} at {t}: {a} {b}");
            }
            let mut t = 0.0;
            while t < th.end_time() {
                assert!(g_of(&th.hand(t)).y > 0.029, "throw {i} at {t}");
                t += 0.01;
            }
        }
    }

    #[test]
    fn the_degradation_is_deterministic() {
        let th = Throw::new(3, 5);
        let ls = levels();
        for (k, l) in ls.iter().enumerate() {
            let a = degrade(&th, l, k, 11);
            let b = degrade(&th, l, k, 11);
            assert_eq!(a.len(), b.len());
            assert!(a.iter().zip(&b).all(|(x, y)| x.wrist == y.wrist
                && x.finger_points == y.finger_points
                && x.stamp.source_time_ns == y.stamp.source_time_ns
                && x.tracked == y.tracked));
        }
        let worst = ls.iter().position(|l| l.name == "worst").unwrap_or(0);
        let s = degrade(&th, &ls[worst], worst, 11);
        assert!(s.iter().any(|h| h.tracked == 0), "worst has gaps");
        let ideal = degrade(&th, &ls[0], 0, 11);
        let h = &ideal[60];
        assert_eq!(h.finger_points, th.hand(60.0 / 120.0).finger_points);
    }

    #[test]
    fn the_paper_world_grasps_and_throws_an_ideal_throw() {
        let scene = scene(HandRules::Paper);
        for i in 0..4 {
            let th = Throw::new(1, i);
            let s = degrade(&th, &levels()[0], 0, 1);
            let run = run_world(&scene, &s).expect("world");
            let (o, pick) = judge(&run.holds(), th.t_r, 1.0 / 120.0);
            assert!(o.grasped, "throw {i}: {:?}", run.events);
            assert_eq!(o.false_drops, 0, "throw {i}: {:?}", run.events);
            let step = pick.and_then(|p| run.step_of(p)).expect("released");
            let v = run.velocity_at(step).expect("velocity");
            let (speed, dir) = errors(v, th.velocity());
            assert!(speed < 10.0 && dir < 15.0, "throw {i}: {speed} % {dir} deg");
        }
    }

    #[test]
    fn judge_counts_drops_flickers_and_the_release() {
        use Hold::{Grab, Let};
        let ev = [
            (0.4, Grab),
            (0.8, Let),
            (0.9, Grab),
            (1.31, Let),
            (1.4, Grab),
        ];
        let (o, pick) = judge(&ev, 1.3, 0.01);
        assert_eq!((o.false_drops, o.flickers, pick), (1, 2, Some(3)));
        assert_eq!(o.release_t, Some(1.31));
        let (o, pick) = judge(&[(0.4, Grab), (0.8, Let)], 1.3, 0.01);
        assert_eq!((o.false_drops, pick, o.release_t), (1, Some(1), Some(0.8)));
        assert!(o.lost);
        let (o, _) = judge(&[], 1.3, 0.01);
        assert!(!o.grasped && o.release_t.is_none());
    }
}
