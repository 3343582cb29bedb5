//! The hand as kinematic colliders: each finger segment (neighbouring check points) a capsule
//! of the finger's radius, a finger of one check point a ball, the palm the convex hull of the
//! palm vertices. Position-based kinematic bodies: each step sets their next pose from the
//! step's hand, and rapier gives them the velocity that motion implies, so a moving finger
//! pushes and a closing hand squeezes with the hand's own speed.
//!
//! A bare check-point hand (no hand model) has radius 0; a collider needs one, so such fingers
//! get `[precise] bare_finger_radius`. Shapes are built once per hand layout; a segment whose
//! length changes (a bare hand interpolates its points freely) gets a new capsule.

use glam::{DQuat, DVec3};
use rapier3d_f64::prelude::{
    CoefficientCombineRule, ColliderBuilder, ColliderHandle, Pose, RigidBodyBuilder,
    RigidBodyHandle, SharedShape,
};

use common::{HandSample, MAX_FINGERS, MAX_FINGER_POINTS};

use super::PhysicsWorld;
use super::KIND_HAND;

/// The usability check both models share (`crate::hand::unusable_because`: it covers the radii
/// and palm vertices colliders are built from, too).
pub(super) fn is_usable(h: &HandSample) -> bool {
    crate::hand::is_usable(h)
}

/// One finger segment (or a one-point finger's ball).
struct Segment {
    finger: usize,
    /// Index of its first check point; the second is `point + 1` (a ball has only `point`).
    point: usize,
    ball: bool,
    radius: f64,
    half_length: f64,
    body: RigidBodyHandle,
    collider: ColliderHandle,
    /// The last rotation, kept when the segment degenerates to a point.
    rotation: DQuat,
}

struct Palm {
    body: RigidBodyHandle,
    collider: ColliderHandle,
    /// The vertices in the wrist's frame the hull was built from.
    local: Vec<DVec3>,
}

/// The hand's kinematic bodies and the layout they were built for.
pub(super) struct HandBodies {
    bare_radius: f64,
    /// The blocks' Coulomb friction: a grasp holds a block by friction alone here (no R5),
    /// so the fingers and palm grip as the floor does.
    friction: f64,
    layout: Option<Layout>,
    segments: Vec<Segment>,
    palm: Option<Palm>,
    on: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Layout {
    finger_count: u32,
    point_count: [u32; MAX_FINGERS],
    palm_vertex_count: u32,
}

fn layout_of(h: &HandSample) -> Layout {
    Layout {
        finger_count: h.finger_count,
        point_count: h.finger_point_count,
        palm_vertex_count: h.palm_vertex_count,
    }
}

fn point(h: &HandSample, f: usize, j: usize) -> DVec3 {
    DVec3::from_array(h.finger_points[f][j.min(MAX_FINGER_POINTS - 1)])
}

fn wrist(h: &HandSample) -> (DVec3, DQuat) {
    let q = DQuat::from_array(h.wrist.rotation);
    let q = if q.length_squared() > 0.0 {
        q.normalize()
    } else {
        DQuat::IDENTITY
    };
    (DVec3::from_array(h.wrist.position), q)
}

/// A segment's pose: its midpoint, its local y axis along a -> b.
fn segment_pose(a: DVec3, b: DVec3, previous: DQuat) -> (Pose, f64, DQuat) {
    let d = b - a;
    let len = d.length();
    let rotation = if len > 1e-9 {
        DQuat::from_rotation_arc(DVec3::Y, d / len)
    } else {
        previous
    };
    (
        Pose::from_parts((a + b) * 0.5, rotation),
        len * 0.5,
        rotation,
    )
}

impl HandBodies {
    pub fn new(bare_radius: f64, friction: f64) -> Self {
        HandBodies {
            bare_radius,
            friction,
            layout: None,
            segments: Vec::new(),
            palm: None,
            on: false,
        }
    }

    /// Whether `h` has another layout (finger and point counts, palm) than the bodies.
    pub fn needs_layout(&self, h: &HandSample) -> bool {
        self.layout != Some(layout_of(h))
    }

    fn radius(&self, h: &HandSample, f: usize) -> f64 {
        let r = h.finger_radius[f];
        if r > 1e-6 {
            r
        } else {
            self.bare_radius
        }
    }

    /// Puts the colliders at `h` at once (no motion): at the start, when the hand comes back
    /// after a gap, or when its layout changed (then the bodies are rebuilt).
    pub fn place(&mut self, world: &mut PhysicsWorld, h: &HandSample) {
        if self.needs_layout(h) {
            self.rebuild(world, h);
        }
        self.set_poses(world, h, true);
    }

    /// Moves the colliders to `h` over this step.
    pub fn drive(&mut self, world: &mut PhysicsWorld, h: &HandSample) {
        if !self.on {
            self.set_poses(world, h, true);
        } else {
            self.set_poses(world, h, false);
        }
    }

    /// No hand this step: its colliders take no part until it comes back.
    pub fn switch_off(&mut self, world: &mut PhysicsWorld) {
        if !self.on {
            return;
        }
        self.on = false;
        let colliders = self
            .segments
            .iter()
            .map(|s| s.collider)
            .chain(self.palm.as_ref().map(|p| p.collider));
        for c in colliders {
            if let Some(c) = world.colliders.get_mut(c) {
                c.set_enabled(false);
            }
        }
    }

    fn rebuild(&mut self, world: &mut PhysicsWorld, h: &HandSample) {
        for s in self.segments.drain(..) {
            world.remove_body(s.body);
        }
        if let Some(p) = self.palm.take() {
            world.remove_body(p.body);
        }
        let mut index = 0u128;
        let fc = (h.finger_count as usize).min(MAX_FINGERS);
        for f in 0..fc {
            let n = (h.finger_point_count[f] as usize).min(MAX_FINGER_POINTS);
            let radius = self.radius(h, f);
            let pieces: Vec<(usize, bool)> = if n == 1 {
                vec![(0, true)]
            } else {
                (0..n.saturating_sub(1)).map(|j| (j, false)).collect()
            };
            for (j, ball) in pieces {
                let (half_length, shape) = if ball {
                    (0.0, SharedShape::ball(radius))
                } else {
                    let hl = (point(h, f, j + 1) - point(h, f, j)).length() * 0.5;
                    (hl, SharedShape::capsule_y(hl, radius))
                };
                let body = world.insert_body(RigidBodyBuilder::kinematic_position_based());
                let collider = world.insert_collider(
                    ColliderBuilder::new(shape)
                        .friction(self.friction)
                        .friction_combine_rule(CoefficientCombineRule::Max)
                        .user_data(KIND_HAND | index),
                    Some(body),
                );
                index += 1;
                self.segments.push(Segment {
                    finger: f,
                    point: j,
                    ball,
                    radius,
                    half_length,
                    body,
                    collider,
                    rotation: DQuat::IDENTITY,
                });
            }
        }
        self.palm = None;
        if h.palm_vertex_count >= 4 {
            let (w, q) = wrist(h);
            let local: Vec<DVec3> = h
                .palm()
                .iter()
                .map(|v| q.inverse() * (DVec3::from_array(*v) - w))
                .collect();
            if let Some(builder) = ColliderBuilder::convex_hull(&local) {
                let body = world.insert_body(RigidBodyBuilder::kinematic_position_based());
                let collider = world.insert_collider(
                    builder
                        .friction(self.friction)
                        .friction_combine_rule(CoefficientCombineRule::Max)
                        .user_data(KIND_HAND | index),
                    Some(body),
                );
                self.palm = Some(Palm {
                    body,
                    collider,
                    local,
                });
            }
        }
        self.layout = Some(layout_of(h));
        self.on = true;
    }

    /// Sets every collider's pose from `h`: at once (`teleport`) or as the next kinematic pose.
    fn set_poses(&mut self, world: &mut PhysicsWorld, h: &HandSample, teleport: bool) {
        if !self.on {
            self.on = true;
            let colliders = self
                .segments
                .iter()
                .map(|s| s.collider)
                .chain(self.palm.as_ref().map(|p| p.collider));
            for c in colliders {
                if let Some(c) = world.colliders.get_mut(c) {
                    c.set_enabled(true);
                }
            }
        }
        for s in &mut self.segments {
            let a = point(h, s.finger, s.point);
            let (pose, half_length) = if s.ball {
                (Pose::from_translation(a), 0.0)
            } else {
                let b = point(h, s.finger, s.point + 1);
                let (pose, hl, rotation) = segment_pose(a, b, s.rotation);
                s.rotation = rotation;
                (pose, hl)
            };
            if !s.ball && (half_length - s.half_length).abs() > 1e-7 {
                // A bare hand's segment changed length: a new capsule (rare; never for a
                // hand model, whose bones are rigid).
                s.half_length = half_length;
                if let Some(c) = world.colliders.get_mut(s.collider) {
                    c.set_shape(SharedShape::capsule_y(half_length, s.radius));
                }
            }
            move_body(world, s.body, pose, teleport);
        }
        if let Some(p) = &mut self.palm {
            let (w, q) = wrist(h);
            // The hull is rigid in the wrist's frame for the hand model; a source whose palm
            // deforms (joints) gets a new hull when a vertex moved by more than 1 mm in it.
            let moved = h
                .palm()
                .iter()
                .zip(&p.local)
                .any(|(v, l)| (q.inverse() * (DVec3::from_array(*v) - w) - *l).length() > 1e-3);
            if moved {
                for (l, v) in p.local.iter_mut().zip(h.palm()) {
                    *l = q.inverse() * (DVec3::from_array(*v) - w);
                }
                if let (Some(shape), Some(c)) = (
                    SharedShape::convex_hull(&p.local),
                    world.colliders.get_mut(p.collider),
                ) {
                    c.set_shape(shape);
                }
            }
            move_body(world, p.body, Pose::from_parts(w, q), teleport);
        }
    }
}

fn move_body(world: &mut PhysicsWorld, body: RigidBodyHandle, pose: Pose, teleport: bool) {
    if let Some(b) = world.bodies.get_mut(body) {
        if teleport {
            b.set_position(pose, true);
        }
        b.set_next_kinematic_position(pose);
    }
}
