//! Hand contact and hand-driven motion (paper 2.2-2.3): R1 point loci, R2 segment loci, R3
//! classification, then R5 grasp, R4 one-point push and R6 multi-point push, and R13's
//! release detection.
//!
//! Contacts are found in each block's body frame (the hand's few points are moved into it) and
//! kept relative to G in world orientation, which is what R4 needs.
//!
//! The hand is its check points and finger segments (docs/model.md R1, R2). The palm polyhedron and
//! the finger radius of a hand sample are not part of these rules and are not used.
//!
//! Stages 1 and 2 of `World::step`: `HandContacts::decide_actions` (R1-R3, with its own
//! contact buffer), `end_grasps` (R13) and `move_by_hand` (R5, R4, R6). Each is handed the
//! blocks, the hand now and before and the settings; none needs the world.

use glam::{DQuat, DVec3};

use common::{BlockMode, HandSample, Pose, MAX_FINGERS, MAX_FINGER_POINTS};

use crate::block_set::BlockSet;
use crate::body::{Block, HandAction, Moved};
use crate::geometry::{segment_segment, segment_triangle};
use crate::grid::BlockGrid;
use crate::motion::push_one_point;
use crate::settings::Settings;
use crate::tracked::{TrackedCounts, TrackedRules};
use crate::HAND_SLOTS;

/// Contacts kept per block and step (after merging; more are dropped, never allocated).
pub const MAX_CONTACTS: usize = 64;

/// One hand contact with a block, relative to G in world orientation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Contact {
    /// The contact point C.
    pub c: DVec3,
    /// The pseudo-normal (unit).
    pub n: DVec3,
    /// Where the touching hand point is now (R4's B).
    pub b: DVec3,
    /// The check point it came from, `finger * MAX_FINGER_POINTS + index` (for R2's segment
    /// contacts, the segment's first point): T1 remembers the grip by it.
    pub point: u16,
}

/// The check points as drawn (R5's relocation), in the hand sample's layout.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Fingers {
    pub count: u32,
    pub point_count: [u32; MAX_FINGERS],
    pub points: [[[f64; 3]; MAX_FINGER_POINTS]; MAX_FINGERS],
}

impl Fingers {
    /// No check points (the world before its first step).
    pub(crate) const NONE: Fingers = Fingers {
        count: 0,
        point_count: [0; MAX_FINGERS],
        points: [[[0.0; 3]; MAX_FINGER_POINTS]; MAX_FINGERS],
    };

    /// The hand's check points as they arrive (both models publish them; the paper model's R5
    /// then relocates those inside a grasped block); none without a hand.
    pub(crate) fn copy_from(&mut self, hand: Option<&HandSample>) {
        match hand {
            Some(h) => {
                let fc = (h.finger_count as usize).min(MAX_FINGERS);
                self.count = fc as u32;
                for f in 0..MAX_FINGERS {
                    self.point_count[f] = if f < fc {
                        h.finger_point_count[f].min(MAX_FINGER_POINTS as u32)
                    } else {
                        0
                    };
                }
                self.points = h.finger_points;
            }
            None => {
                self.count = 0;
                self.point_count = [0; MAX_FINGERS];
            }
        }
    }
}

pub use common::samples::{HAND_RANGE_M, MAX_FINGER_RADIUS_M};

/// Why the models cannot use a hand sample (None: they can): [`HandSample::unusable_because`],
/// the contract's one check, which a shared world's host applies too. The stepper refuses
/// such a sample where it enters, names the first and counts them; the hand holds its last
/// good pose.
pub fn unusable_because(h: &HandSample) -> Option<&'static str> {
    h.unusable_because()
}

/// A hand sample the rules can use ([`unusable_because`] finds nothing).
pub fn is_usable(h: &HandSample) -> bool {
    unusable_because(h).is_none()
}

/// The box of a hand's check points ((+inf, -inf) for none): the hand's broad phase. Worked out
/// once per sample (`World::step`), which is then the box "now" of its step and "before" of the
/// next.
pub(crate) fn check_point_box(h: &HandSample) -> (DVec3, DVec3) {
    let (mut lo, mut hi) = EMPTY_BOX;
    for f in 0..(h.finger_count as usize).min(MAX_FINGERS) {
        for p in &h.finger_points[f][..(h.finger_point_count[f] as usize).min(MAX_FINGER_POINTS)] {
            let p = DVec3::from_array(*p);
            lo = lo.min(p);
            hi = hi.max(p);
        }
    }
    (lo, hi)
}

/// The box of no points.
pub(crate) const EMPTY_BOX: (DVec3, DVec3) = (DVec3::INFINITY, DVec3::NEG_INFINITY);

/// Stage 1's broad phase: the box of the hand's check points now and before (each sample's
/// box worked out once, `check_point_box`), grown by `eps`; None when the hand can touch no
/// block: it has no check points, or the box is farther from every block than a touch (one
/// comparison with the box of every centre the grid holds). A far hand then costs its stage
/// this and no more, not a call into `HandContacts::decide_actions`.
#[inline]
pub(crate) fn hand_reach(
    blocks: &[Block],
    grid: &mut BlockGrid,
    now: (DVec3, DVec3),
    before: (DVec3, DVec3),
    eps: f64,
) -> Option<(DVec3, DVec3)> {
    let lo = now.0.min(before.0) - DVec3::splat(eps);
    let hi = now.1.max(before.1) + DVec3::splat(eps);
    (lo.cmple(hi).all() && !grid.nothing_near_box(blocks, lo, hi, eps)).then_some((lo, hi))
}

fn wrist_of(p: &Pose) -> (DVec3, DQuat) {
    let q = DQuat::from_array(p.rotation);
    let l2 = q.length_squared();
    let q = if l2.is_finite() && l2 >= f64::MIN_POSITIVE {
        q.normalize()
    } else {
        // A finite rotation whose squared length overflows (components near 1e300) or
        // underflows (near 1e-160) from a device or a file: scaled by its largest component
        // first, so that it normalises to a unit quaternion, not to NaN (issue 41's fuzzing:
        // a tracked hand holds a block through such a sample, and R5 turned it to NaN).
        let m = p.rotation.iter().fold(0.0f64, |m, c| m.max(c.abs()));
        let scale = 1.0 / m;
        if m.is_finite() && scale.is_finite() {
            (q * scale).normalize()
        } else {
            DQuat::IDENTITY
        }
    };
    (DVec3::from_array(p.position), q)
}

/// Adds a contact unless one closer than `eps` is already there (R3: merged).
fn add(contacts: &mut Vec<Contact>, c: Contact, eps: f64) {
    if contacts.iter().any(|o| (o.c - c.c).length() < eps) || contacts.len() >= MAX_CONTACTS {
        return;
    }
    contacts.push(c);
}

/// Per check point, the locus parameter at which its locus first enters one of the blocks.
pub(crate) type FirstEntries = [[f64; MAX_FINGER_POINTS]; MAX_FINGERS];

/// The check point's previous position (P-), or its current one when the previous hand does
/// not have it.
fn prev_point(hand: &HandSample, prev: Option<&HandSample>, f: usize, k: usize) -> [f64; 3] {
    match prev {
        Some(p) if (f as u32) < p.finger_count && (k as u32) < p.finger_point_count[f] => {
            p.finger_points[f][k]
        }
        _ => hand.finger_points[f][k],
    }
}

/// R1 **[resolved]**: a check point's locus is a finger's path; it is stopped by the first
/// block it enters. Without this a tracker glitch (one sample 1 m off) sweeps a locus through a
/// row of blocks and R4 pushes every one of them to the same point B, one inside the other.
/// Returns, per check point, the parameter along [P-, P] of its first entry into any of the
/// `blocks` for which `near(block)` holds (infinity when it enters none).
pub(crate) fn first_entries<'a>(
    blocks: impl Iterator<Item = &'a Block>,
    hand: &HandSample,
    prev: Option<&HandSample>,
    hull_eps: f64,
) -> FirstEntries {
    let mut first = [[f64::INFINITY; MAX_FINGER_POINTS]; MAX_FINGERS];
    let fc = (hand.finger_count as usize).min(MAX_FINGERS);
    for b in blocks {
        let inv = b.rot().conjugate();
        let to_body = |p: [f64; 3]| inv * (DVec3::from_array(p) - b.pos());
        for (f, row) in first.iter_mut().enumerate().take(fc) {
            let np = (hand.finger_point_count[f] as usize).min(MAX_FINGER_POINTS);
            for (k, t_first) in row.iter_mut().enumerate().take(np) {
                let a0 = to_body(prev_point(hand, prev, f, k));
                let a1 = to_body(hand.finger_points[f][k]);
                if let Some((t, _)) = b.poly.locus_entry(a0, a1, hull_eps) {
                    *t_first = t_first.min(t);
                }
            }
        }
    }
    first
}

/// R1 and R2 for one block: appends its contacts (relative to G, world orientation).
/// `prev(f, k)` and `now(f, k)` are the check points in the world frame; `first` is
/// [`first_entries`]: a locus entering this block after it entered another one is no contact.
pub(crate) fn block_contacts(
    b: &Block,
    hand: &HandSample,
    prev: Option<&HandSample>,
    contact_eps: f64,
    hull_eps: f64,
    first: &FirstEntries,
    contacts: &mut Vec<Contact>,
) {
    let inv = b.rot().conjugate();
    let to_body = |p: [f64; 3]| inv * (DVec3::from_array(p) - b.pos());
    let poly = &b.poly;
    let out = |c: DVec3, n: DVec3, bb: DVec3, f: usize, k: usize| Contact {
        c: b.rot() * c,
        n: b.rot() * n,
        b: b.rot() * bb,
        point: (f * MAX_FINGER_POINTS + k) as u16,
    };
    // The block's box in its body frame: R2's broad phase below.
    let (body_lo, body_hi) = poly.vertices.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), v| (lo.min(*v), hi.max(*v)),
    );
    let fc = (hand.finger_count as usize).min(MAX_FINGERS);
    for f in 0..fc {
        let np = (hand.finger_point_count[f] as usize).min(MAX_FINGER_POINTS);
        let pm = |k: usize| -> [f64; 3] {
            match prev {
                Some(p) if (f as u32) < p.finger_count && (k as u32) < p.finger_point_count[f] => {
                    p.finger_points[f][k]
                }
                _ => hand.finger_points[f][k],
            }
        };
        // R1: point loci.
        for k in 0..np {
            let a0 = to_body(pm(k));
            let a1 = to_body(hand.finger_points[f][k]);
            let (s, face) = poly.max_face_distance(a0);
            if s <= contact_eps {
                // Already inside at P-, or within contact_eps of the surface: a contact at
                // the nearest surface point, with that face's normal.
                let (cpt, dist, _) = poly.nearest_surface_point(a0);
                if dist <= contact_eps {
                    add(
                        contacts,
                        out(cpt, poly.faces[face].normal, a1, f, k),
                        contact_eps,
                    );
                    continue;
                }
            }
            if let Some((t, n)) = poly.locus_entry(a0, a1, hull_eps) {
                // R1 [resolved]: stopped by the first block it entered.
                if first
                    .get(f)
                    .and_then(|row| row.get(k))
                    .is_none_or(|&t_first| t <= t_first)
                {
                    add(contacts, out(a0 + (a1 - a0) * t, n, a1, f, k), contact_eps);
                }
            }
        }
        // R2: segment loci between neighbouring check points.
        for k in 0..np.saturating_sub(1) {
            let (am, bm) = (to_body(pm(k)), to_body(pm(k + 1)));
            let (a, bn) = (
                to_body(hand.finger_points[f][k]),
                to_body(hand.finger_points[f][k + 1]),
            );
            // The swept quad's box against the block's: apart (by more than rounding), no
            // edge of the block can cross the quad, so its 2 x edges triangle tests are
            // skipped (an open hand sweeping a pile: most of a step's R2 work).
            let (q_lo, q_hi) = (am.min(bm).min(bn).min(a), am.max(bm).max(bn).max(a));
            let slack = 1e-9 * (1.0 + q_lo.abs().max(q_hi.abs()).max_element());
            let apart =
                (q_lo - body_hi).max_element() > slack || (body_lo - q_hi).max_element() > slack;
            for (e, [i, j]) in poly.edges.iter().enumerate().filter(|_| !apart) {
                let (e0, e1) = (poly.vertices[*i], poly.vertices[*j]);
                // Quad (a-, b-, b, a) as triangles (a-, b-, b) and (a-, b, a). On the quad,
                // Q(s, t) = (1-t) lerp(a-, b-, s) + t lerp(a, b, s).
                let hit = segment_triangle(e0, e1, am, bm, bn)
                    .map(|(se, w1, w2)| (se, w1 + w2))
                    .or_else(|| segment_triangle(e0, e1, am, bn, a).map(|(se, w1, _)| (se, w1)));
                if let Some((se, s)) = hit {
                    let c = e0 + (e1 - e0) * se;
                    let bb = a + (bn - a) * s;
                    add(
                        contacts,
                        out(c, poly.edge_pseudo_normal(e), bb, f, k),
                        contact_eps,
                    );
                }
            }
            // A finger segment already passing through the block at the start of the step
            // (both check points outside): a contact at the nearest block edge.
            if poly.max_face_distance(am).0 > contact_eps
                && poly.max_face_distance(bm).0 > contact_eps
            {
                if let Some((t0, t1)) = poly.segment_clip(am, bm) {
                    if (t1 - t0) * (bm - am).length() > contact_eps {
                        // The nearest edge; edges equally near (within contact_eps) all count,
                        // so that a finger lying symmetrically across a block pushes it
                        // symmetrically (R3 then classifies them together).
                        let mut best = f64::INFINITY;
                        for [i, j] in &poly.edges {
                            let (_, _, d2) =
                                segment_segment(am, bm, poly.vertices[*i], poly.vertices[*j]);
                            best = best.min(d2.sqrt());
                        }
                        for (e, [i, j]) in poly.edges.iter().enumerate() {
                            let (s, te, d2) =
                                segment_segment(am, bm, poly.vertices[*i], poly.vertices[*j]);
                            if d2.sqrt() > best + contact_eps {
                                continue;
                            }
                            let c =
                                poly.vertices[*i] + (poly.vertices[*j] - poly.vertices[*i]) * te;
                            let bb = a + (bn - a) * s;
                            add(
                                contacts,
                                out(c, poly.edge_pseudo_normal(e), bb, f, k),
                                contact_eps,
                            );
                        }
                    }
                }
            }
        }
    }
}

/// R3: the largest angle between any two pseudo-normals (radians).
pub fn largest_angle(contacts: &[Contact]) -> f64 {
    let mut min_dot = 1.0f64;
    for (i, a) in contacts.iter().enumerate() {
        for b in &contacts[i + 1..] {
            min_dot = min_dot.min(a.n.dot(b.n));
        }
    }
    min_dot.clamp(-1.0, 1.0).acos()
}

/// Stage 1's R1-R3 for the blocks near the hand, with its own contact buffer (preallocated for
/// [`MAX_CONTACTS`], so that a step does not allocate).
#[derive(Debug)]
pub(crate) struct HandContacts {
    contacts: Vec<Contact>,
}

impl HandContacts {
    pub(crate) fn new() -> HandContacts {
        HandContacts {
            contacts: Vec::with_capacity(MAX_CONTACTS),
        }
    }

    /// Stage 1: R1-R3 for every block near the hand in slot `slot` (`hand` now, `prev` the
    /// hand of the previous step, P- and W-): decides each block's hand action. `grasp` says whether R5 may
    /// grasp (hand = "grasp"); otherwise two contacts always push (R6). Whether it gave any
    /// block an action: when not, stage 2 has nothing to move.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn decide_actions(
        &mut self,
        blocks: &mut [Block],
        active: &mut BlockSet,
        grid: &mut BlockGrid,
        slot: usize,
        hand: &HandSample,
        prev: Option<&HandSample>,
        reach: (DVec3, DVec3),
        settings: &Settings,
        grasp: bool,
        step: u64,
        counts: &mut TrackedCounts,
    ) -> bool {
        let eps = settings.contact_eps;
        let hull_eps = settings.hull_eps;
        // T1 holds a grip that has not opened by the grip margin, its points up to that far
        // outside the block: the broad phase reaches that far too.
        let reach_eps = eps + settings.tracked.map_or(0.0, |t| t.grip_margin);
        // Broad phase: the box around every check point now and before, grown by eps (`reach`,
        // `hand_reach`: the caller has already found it near a block).
        let (lo, hi) = reach;
        let near =
            |b: &Block| (b.pos().max(lo).min(hi) - b.pos()).length() <= b.poly.radius + reach_eps;
        // The grid's blocks within the box's half diagonal (and eps) of its centre: every block
        // `near` accepts (a superset; `near` decides). In no order: each block's action is its
        // own, and the first entries are minima. The grid sees every block where the last step
        // left it (its stage 6), and nothing has moved since.
        let candidates: &[u32] = grid.near_any_order(
            blocks,
            (lo + hi) * 0.5,
            0.5 * (hi - lo).length() + reach_eps,
        );
        // Nothing near the hand: no block has an action to decide.
        if candidates.is_empty() {
            return false;
        }
        let first = first_entries(
            candidates
                .iter()
                .map(|&j| &blocks[j as usize])
                .filter(|b| near(b)),
            hand,
            prev,
            hull_eps,
        );
        let contacts = &mut self.contacts;
        let mut acted = false;
        for &j in candidates {
            let i = j as usize;
            let b = &mut blocks[i];
            if !near(b) {
                continue;
            }
            contacts.clear();
            block_contacts(b, hand, prev, eps, hull_eps, &first, contacts);
            // R3 judges by release_angle the grasps of this hand (in a one-hand world, every
            // grasp): another hand's grasp is not this hand's to keep.
            let grasped_here = b.grasped_by(slot);
            let mode = match b.mode {
                BlockMode::Grasped if !grasped_here => BlockMode::Free,
                mode => mode,
            };
            let paper = classify(contacts, mode, settings, grasp);
            let action = match settings.tracked {
                // T1: a grasp R3 no longer confirms holds while the hand's grip has not opened
                // by the grip margin since the last firm step, nor left the block by twice it.
                Some(t) if grasp && grasped_here && paper != HandAction::Grasp => {
                    let (inv, at) = (b.rot().conjugate(), b.pos());
                    let poly = &b.poly;
                    let outside = |p: DVec3| poly.max_face_distance(inv * (p - at)).0;
                    let holds = b.grip.grip_holds(
                        slot,
                        hand,
                        settings.release_angle,
                        t.grip_margin,
                        outside,
                    );
                    if b.grip.still_held(slot, holds, t.grip_open_steps) {
                        counts.grip_held_steps += 1;
                        HandAction::Grasp
                    } else {
                        paper
                    }
                }
                // A firm step (R3 itself grasps): T1 remembers the grip and T3 the step. Not
                // after an untracked step (R1 then reads the lost hand's held pose as P-),
                // unless the grasp is new.
                Some(_) if paper == HandAction::Grasp => {
                    if !grasped_here || prev.is_some_and(|p| p.tracked != 0) {
                        b.grip.firm_step = step;
                        // Where R1 found them: at P-.
                        b.grip.record_grip(
                            slot,
                            contacts,
                            prev.unwrap_or(hand),
                            settings.release_angle,
                        );
                    }
                    paper
                }
                _ => paper,
            };
            if action != HandAction::None {
                // The hand acts on it: a resting block joins the step.
                active.insert(i);
                acted = true;
            }
            b.set_action(action);
        }
        acted
    }
}

/// R3 for one block's merged contacts: none, one (R4), or two and more, grasped (R5) when
/// their pseudo-normals open wider than grasp_angle (release_angle once grasped) and R6's
/// translation otherwise. `grasp`: whether R5 may grasp at all (hand = "grasp").
fn classify(contacts: &[Contact], mode: BlockMode, settings: &Settings, grasp: bool) -> HandAction {
    let (eps, hull_eps) = (settings.contact_eps, settings.hull_eps);
    match contacts.len() {
        0 => HandAction::None,
        1 => HandAction::Push {
            c: contacts[0].c,
            b: contacts[0].b,
        },
        _ => {
            let threshold = if mode == BlockMode::Grasped {
                settings.release_angle
            } else {
                settings.grasp_angle
            };
            if grasp && largest_angle(contacts) > threshold {
                HandAction::Grasp
            } else {
                // R6: the mean of the contacts' T vectors, leaving ones excluded.
                let mut sum = DVec3::ZERO;
                let mut n = 0usize;
                for c in contacts.iter() {
                    if let Some(p) = push_one_point(c.c, c.b, DVec3::ZERO, hull_eps, eps) {
                        sum += p.t;
                        n += 1;
                    }
                }
                if n > 0 {
                    HandAction::Translate(sum / n as f64)
                } else {
                    HandAction::None
                }
            }
        }
    }
}

/// Stage 1's R13: a grasp that R3 no longer confirms ends (also when there is no hand this
/// step). The block is free with v = its last grasped displacement (the mean over throw_window
/// steps); "releases take effect for the next step": R7 moves it from the next step on, so
/// that after k more steps it is at p + k v + g_step k (k + 1) / 2 (the floor stage still looks
/// at it this step, so a block let go on the floor rests or tips with that inertia as its Gm).
/// Under tracked hands T1 and T2 decide which grasps stage 1 confirms, and `letting` is T3's
/// fit or T2's drop.
pub(crate) fn end_grasps(
    blocks: &mut [Block],
    active: &BlockSet,
    inertia: bool,
    letting_of: impl Fn(u8) -> Letting,
    counts: &mut TrackedCounts,
) {
    // A grasped block is never at rest: it is in `active`.
    for i in active.iter() {
        let b = &mut blocks[i];
        if b.mode == BlockMode::Grasped && b.action() != HandAction::Grasp {
            // How the hands that held it let go (T2's drop only when every one of them was
            // lost for longer than gap_hold).
            let letting = letting_of(b.held_by);
            b.released = true;
            b.released_by = b.held_by;
            b.held_by = 0;
            b.mode = BlockMode::Free;
            b.v = match letting {
                _ if !inertia => DVec3::ZERO,
                Letting::Throw => b.throw_displacement(),
                // T3: the fitted velocity, where there are tracked points to fit; a grasp
                // with fewer than two (one step long) throws nothing: its one displacement may
                // be a hand catching up after a tracking gap, not a throw (`bench hands`: a
                // cube left at 19 m/s from a 4.3 m/s throw so).
                Letting::FittedThrow { now, rules } => match b.grip.throw_velocity(now, &rules) {
                    Some(v) => {
                        counts.fitted_throws += 1;
                        v * rules.dt
                    }
                    None => DVec3::ZERO,
                },
                // T2: a hand lost for longer than gap_hold lets go with nothing to throw by.
                Letting::Drop => {
                    counts.gap_releases += 1;
                    DVec3::ZERO
                }
            };
            // T3: the step that lets go gives the block its throw and nothing else: a finger
            // still inside it (the thumb of an opening hand) would push it along that finger's
            // normal alone (R4 sets v = T), and the throw would go where the thumb points.
            if !matches!(letting, Letting::Throw) {
                b.set_action(HandAction::None);
            }
        }
    }
}

/// How [`end_grasps`] lets a block go.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Letting {
    /// R13: the last grasped displacement (the mean over throw_window steps).
    Throw,
    /// T3: the fit of the held block's path, at step `now`.
    FittedThrow { now: u64, rules: TrackedRules },
    /// T2: no throw (v = 0), the hand was lost for too long.
    Drop,
}

/// Stage 2: R5 grasp (rigidly with the wrist), R4 one-point push, R6 translation, as stage 1
/// decided them; `fingers` are the check points as drawn, which R5 relocates. Whether it moved
/// any block (R10 carries from those).
#[allow(clippy::too_many_arguments)]
pub(crate) fn move_by_hand(
    blocks: &mut [Block],
    active: &BlockSet,
    hands: [Option<&HandSample>; HAND_SLOTS],
    prevs: [Option<&HandSample>; HAND_SLOTS],
    settings: &Settings,
    fingers: &mut [Fingers; HAND_SLOTS],
    path_step: Option<u64>,
    two_handed: bool,
) -> bool {
    // R5's wrist motion of each hand, worked out for the first block that hand grasps (a hand
    // that acts on nothing costs this stage a pass over the active set and nothing more); None
    // for a hand that is not there this step (a block it holds through a gap stays put).
    let wrist_motion = |slot: usize| {
        let hand = hands[slot]?;
        let (w_pos, w_rot) = wrist_of(&hand.wrist);
        let (wm_pos, wm_rot) = match prevs[slot] {
            Some(p) => wrist_of(&p.wrist),
            None => (w_pos, w_rot),
        };
        Some((w_pos, wm_pos, (w_rot * wm_rot.conjugate()).normalize()))
    };
    let mut grasp_motion: [Option<Option<(DVec3, DVec3, DQuat)>>; HAND_SLOTS] = [None; HAND_SLOTS];
    let eps = settings.contact_eps;
    let hull_eps = settings.hull_eps;
    let mut any_grasp = false;
    let mut any_moved = false;
    // Stage 1 put every block the hand acts on in `active`.
    for i in active.iter() {
        let b = &mut blocks[i];
        if !b.acted() {
            continue;
        }
        match b.action() {
            HandAction::None => {}
            HandAction::Grasp => {
                // R5: pose <- W W-^-1 pose, with the wrist of each hand that grasps it; two
                // hands move it by the mean of their two motions (the middle of the two
                // positions, the rotation halfway), so neither hand's tracking error flings it
                // and a hand letting go of a two-hand grasp leaves it moving with the other.
                let holders = if two_handed { b.acting_hands } else { 1 };
                // The mean over the hands that grasp it (people sharing a world hold a block
                // together the same way): positions summed from the first, rotations summed on
                // the first's side, so that one hand's motion is its own bit for bit and two
                // hands' are the middle and `halfway`, as before shared worlds.
                let mut moved_to: Option<(DVec3, DQuat)> = None;
                let mut holding = 0u32;
                for (slot, motion) in grasp_motion.iter_mut().enumerate() {
                    if holders & (1 << slot) == 0 {
                        continue;
                    }
                    let Some((w_pos, wm_pos, dq)) =
                        *motion.get_or_insert_with(|| wrist_motion(slot))
                    else {
                        continue;
                    };
                    let pos = w_pos + dq * (b.pos() - wm_pos);
                    let rot = (dq * b.rot()).normalize();
                    holding += 1;
                    moved_to = Some(match moved_to {
                        None => (pos, rot),
                        Some((p0, r0)) => {
                            (p0 + pos, r0 + if r0.dot(rot) < 0.0 { -rot } else { rot })
                        }
                    });
                }
                let moved_to = moved_to.map(|(p, r)| match holding {
                    1 => (p, r),
                    n => (p * (1.0 / f64::from(n)), r.normalize()),
                });
                if b.mode_before != BlockMode::Grasped {
                    b.grasp_history_len = 0;
                    b.grip.clear();
                }
                b.held_by = holders;
                let Some((new_pos, new_rot)) = moved_to else {
                    // Held through a gap by hands that are not there: it stays.
                    b.mode = BlockMode::Grasped;
                    continue;
                };
                let d = new_pos - b.pos();
                b.set_position(new_pos);
                b.set_rotation(new_rot);
                b.push_grasp_displacement(d);
                // T3: the path of a block a tracked hand holds (untracked steps are no data,
                // nor are the steps its grip is found open: the fingers have left it).
                if let Some(step) = path_step.filter(|_| !b.grip.opening()) {
                    b.grip.push(step, new_pos);
                }
                b.v = d;
                b.moved = Moved::Hand;
                b.mode = BlockMode::Grasped;
                any_grasp = true;
                any_moved = true;
            }
            HandAction::Push { c, b: bp } => {
                // R4.
                if let Some(p) = push_one_point(c, bp, DVec3::ZERO, hull_eps, eps) {
                    b.translate(p.t);
                    if let Some(axis) = p.axis {
                        b.rotate_about(DQuat::from_axis_angle(axis, p.theta), DVec3::ZERO);
                    }
                    b.v = p.t;
                    b.moved = Moved::Hand;
                    b.mode = BlockMode::Pushed;
                    any_moved = true;
                }
            }
            HandAction::Translate(t) => {
                // R6.
                b.translate(t);
                b.v = t;
                b.moved = Moved::Hand;
                b.mode = BlockMode::Pushed;
                any_moved = true;
            }
        }
    }
    if any_grasp {
        for (slot, (hand, fingers)) in hands.iter().zip(fingers.iter_mut()).enumerate() {
            if let Some(hand) = hand {
                relocate_fingers(blocks, active, slot, hand, fingers);
            }
        }
    }
    any_moved
}

/// R5: check points that end inside a grasped block are moved to its surface (nearest point),
/// for drawing; P- stays the hand's own sample.
fn relocate_fingers(
    blocks: &[Block],
    active: &BlockSet,
    slot: usize,
    hand: &HandSample,
    fingers: &mut Fingers,
) {
    let fc = (hand.finger_count as usize).min(MAX_FINGERS);
    for f in 0..fc {
        for k in 0..(hand.finger_point_count[f] as usize).min(MAX_FINGER_POINTS) {
            let p = DVec3::from_array(fingers.points[f][k]);
            // A grasped block is never at rest: in `active`, lowest index first (the order of a
            // loop over every block, without the loop: a point costs the active blocks).
            for b in active.iter().map(|i| &blocks[i]) {
                if !b.grasped_by(slot) {
                    continue;
                }
                let local = b.rot().conjugate() * (p - b.pos());
                let (s, face) = b.poly.max_face_distance(local);
                if s < 0.0 {
                    let on = local - b.poly.faces[face].normal * s;
                    fingers.points[f][k] = (b.pos() + b.rot() * on).to_array();
                    break;
                }
            }
        }
    }
}
