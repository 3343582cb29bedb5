//! Convex polyhedra in their body frame, and the exact geometric queries the rules need.
//!
//! A block (docs/model.md "Conventions") is a rigid convex polyhedron with its body origin at its
//! centre of gravity G. Every query here works in that body frame, relative to G: the caller
//! transforms the few hand points into it instead of transforming the block into the world,
//! so a scene 1 km from the origin behaves as it does at the origin (docs/model.md R9 "Precision").
//!
//! The shapes crate builds the hull from the scene's spec (with parry3d, and the same one the
//! renderer draws); parry3d projects points (GJK) and casts shapes (R12). The face
//! planes, edges and the small exact tests the rules are written in terms of (which faces a
//! locus crosses, which edge a swept finger crosses, SAT penetration depth, the 2-D hull of the
//! floor contacts) are ours: they need the crossed *features*, not only a distance.

use glam::{DQuat, DVec2, DVec3};
use parry3d_f64::shape::ConvexPolyhedron;

use common::config::scene::ShapeSpec;
use shapes::Solid;

/// A face plane in the body frame (the shapes crate builds them with the hull).
pub use shapes::Plane;

/// A block's shape, with G at the origin.
#[derive(Clone)]
pub struct Polyhedron {
    /// Hull vertices, body frame, relative to G.
    pub vertices: Vec<DVec3>,
    pub faces: Vec<Plane>,
    /// Vertex index pairs.
    pub edges: Vec<[usize; 2]>,
    /// Unit directions used by SAT between two blocks: face normals and edge directions
    /// (deduplicated up to sign).
    pub edge_dirs: Vec<DVec3>,
    /// Largest |vertex|: the radius of the bounding sphere about G (broad phase).
    pub radius: f64,
    pub volume: f64,
    /// The same hull for parry's queries (GJK distance, point projection, shape casts).
    pub shape: ConvexPolyhedron,
}

impl std::fmt::Debug for Polyhedron {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Polyhedron")
            .field("vertices", &self.vertices)
            .field("faces", &self.faces.len())
            .field("edges", &self.edges.len())
            .finish()
    }
}

impl Polyhedron {
    /// Builds the block shape of a scene's spec, recentred on its volume centroid.
    pub fn from_spec(spec: &ShapeSpec) -> Result<Polyhedron, String> {
        Solid::from_spec(spec).map(Polyhedron::from_solid)
    }

    /// The convex hull of `points`, recentred so that its volume centroid is the origin.
    pub fn from_points(
        points: &[DVec3],
        known_centroid: Option<DVec3>,
    ) -> Result<Polyhedron, String> {
        Solid::from_points(points, known_centroid).map(Polyhedron::from_solid)
    }

    /// The block as the shapes crate builds it (the one hull the renderer draws too), with
    /// what the rules' queries add: SAT axes and the bounding sphere.
    fn from_solid(solid: Solid) -> Polyhedron {
        let Solid {
            vertices,
            planes: faces,
            edges,
            volume,
            shape,
            ..
        } = solid;
        let mut edge_dirs: Vec<DVec3> = Vec::new();
        for e in &edges {
            let d = (vertices[e[1]] - vertices[e[0]]).normalize_or_zero();
            if d != DVec3::ZERO && !edge_dirs.iter().any(|o| o.dot(d).abs() > 1.0 - 1e-12) {
                edge_dirs.push(d);
            }
        }
        let radius = vertices.iter().fold(0.0f64, |m, v| m.max(v.length()));
        Polyhedron {
            vertices,
            faces,
            edges,
            edge_dirs,
            radius,
            volume,
            shape,
        }
    }

    /// The largest signed face distance of `p` (body frame) and that face's index: negative
    /// inside (minus the depth to the nearest face), positive outside (a lower bound of the
    /// true distance, exact when `p` projects inside that face).
    pub fn max_face_distance(&self, p: DVec3) -> (f64, usize) {
        let mut best = (f64::NEG_INFINITY, 0);
        for (i, f) in self.faces.iter().enumerate() {
            let d = f.distance(p);
            if d > best.0 {
                best = (d, i);
            }
        }
        best
    }

    /// The nearest surface point to `p` (body frame) and its distance (negative inside).
    pub fn nearest_surface_point(&self, p: DVec3) -> (DVec3, f64, usize) {
        let (s, face) = self.max_face_distance(p);
        if s <= 0.0 {
            // Inside: the nearest boundary point is the foot on the nearest face plane.
            (p - self.faces[face].normal * s, s, face)
        } else {
            // Outside: the nearest of the faces' feet that lie on the solid, the edges' nearest
            // points and (through the edges) the vertices. Exact and allocation-free (parry's
            // point projection runs EPA, which allocates, for points this close).
            let scale = self.radius.max(f64::MIN_POSITIVE);
            let mut best = (f64::INFINITY, p);
            for f in &self.faces {
                let d = f.distance(p);
                if d > 0.0 {
                    let foot = p - f.normal * d;
                    if self.max_face_distance(foot).0 <= 1e-12 * scale && d < best.0 {
                        best = (d, foot);
                    }
                }
            }
            for [i, j] in &self.edges {
                let (a, b) = (self.vertices[*i], self.vertices[*j]);
                let ab = b - a;
                let l2 = ab.length_squared();
                let t = if l2 > 0.0 {
                    ((p - a).dot(ab) / l2).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                let q = a + ab * t;
                let d = (p - q).length();
                if d < best.0 {
                    best = (d, q);
                }
            }
            (best.1, best.0, face)
        }
    }

    /// R1: where the locus p0 -> p1 (body frame) first enters the solid through its faces.
    /// Returns the parameter t in [0, 1] of the crossing and the normalised sum of the normals
    /// of every face crossed there (within `tol` metres: a locus through an edge or a vertex).
    /// None when the locus misses the solid or does not enter it from outside.
    pub fn locus_entry(&self, p0: DVec3, p1: DVec3, tol: f64) -> Option<(f64, DVec3)> {
        let delta = p1 - p0;
        let len = delta.length();
        if len == 0.0 {
            return None;
        }
        let mut t_in = 0.0f64;
        let mut t_out = 1.0f64;
        let mut entered = false;
        for f in &self.faces {
            let d0 = f.distance(p0);
            let denom = f.normal.dot(delta);
            if denom == 0.0 {
                if d0 > 0.0 {
                    return None;
                }
                continue;
            }
            let t = -d0 / denom;
            if denom < 0.0 {
                if d0 > 0.0 && t >= t_in {
                    t_in = t;
                    entered = true;
                }
            } else if t < t_out {
                t_out = t;
            }
        }
        if !entered || t_in > t_out || t_in > 1.0 {
            return None;
        }
        let tol_t = tol / len;
        let mut n = DVec3::ZERO;
        for f in &self.faces {
            let d0 = f.distance(p0);
            let denom = f.normal.dot(delta);
            if denom < 0.0 && d0 > 0.0 && (-d0 / denom - t_in).abs() <= tol_t {
                n += f.normal;
            }
        }
        let n = n.normalize_or_zero();
        if n == DVec3::ZERO {
            return None;
        }
        Some((t_in, n))
    }

    /// Whether the segment p0 p1 (body frame) passes through the solid's interior, and the
    /// parameter interval it spends inside.
    pub fn segment_clip(&self, p0: DVec3, p1: DVec3) -> Option<(f64, f64)> {
        let delta = p1 - p0;
        let mut t_in = 0.0f64;
        let mut t_out = 1.0f64;
        for f in &self.faces {
            let d0 = f.distance(p0);
            let denom = f.normal.dot(delta);
            if denom == 0.0 {
                if d0 >= 0.0 {
                    return None;
                }
                continue;
            }
            let t = -d0 / denom;
            if denom < 0.0 {
                t_in = t_in.max(t);
            } else {
                t_out = t_out.min(t);
            }
            if t_in >= t_out {
                return None;
            }
        }
        Some((t_in, t_out))
    }

    /// R2's pseudo-normal of edge `e`: the unit vector from G (the origin) to the foot of the
    /// perpendicular from G onto the edge's line (the paper's Fig. 4).
    pub fn edge_pseudo_normal(&self, e: usize) -> DVec3 {
        let [i, j] = self.edges[e];
        let (a, b) = (self.vertices[i], self.vertices[j]);
        let d = (b - a).normalize_or_zero();
        let foot = a - d * a.dot(d);
        foot.normalize_or_zero()
    }
}

/// Rotates body vertices into `out` (world orientation, relative to G).
pub fn rotate_vertices(poly: &Polyhedron, rot: DQuat, out: &mut Vec<DVec3>) {
    out.clear();
    out.extend(poly.vertices.iter().map(|v| rot * *v));
}

/// The interval `points` cover along `axis`: the one projection every SAT test
/// here is made of.
#[inline]
fn project(points: impl Iterator<Item = DVec3>, axis: DVec3) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in points {
        let x = v.dot(axis);
        lo = lo.min(x);
        hi = hi.max(x);
    }
    (lo, hi)
}

/// Separating-axis penetration depth of two blocks given their vertices relative to G1
/// (world orientation): `a` around the origin, `b` offset by `b_off` from it. Positive: the
/// solids overlap by that much along the best axis; negative: separated by at least that much.
/// Exact for convex polyhedra when overlapping (the axes are face normals and edge crosses).
pub fn sat_depth(
    pa: &Polyhedron,
    ra: DQuat,
    va: &[DVec3],
    pb: &Polyhedron,
    rb: DQuat,
    vb: &[DVec3],
    b_off: DVec3,
) -> f64 {
    let mut depth = f64::INFINITY;
    let mut test = |axis: DVec3| {
        let (amin, amax) = project(va.iter().copied(), axis);
        let (bmin, bmax) = project(vb.iter().map(|v| *v + b_off), axis);
        let overlap = (amax - bmin).min(bmax - amin);
        depth = depth.min(overlap);
    };
    for f in &pa.faces {
        test(ra * f.normal);
    }
    for f in &pb.faces {
        test(rb * f.normal);
    }
    for ea in &pa.edge_dirs {
        let ea = ra * *ea;
        for eb in &pb.edge_dirs {
            let c = ea.cross(rb * *eb);
            let l = c.length();
            if l > 1e-9 {
                test(c / l);
            }
        }
    }
    depth
}

/// [`sat_depth`] with the axis that gives it: (depth, unit axis pointing from `a` to `b`). R14
/// reads the axis as the pair's contact normal (a supports b when it points up). Where several
/// axes give the least overlap within `tie` (two boxes touching only along an edge, diagonal
/// neighbours), the normal is ambiguous; the most horizontal of them is taken, so such a touch
/// is a side contact and holds nothing up. Kept apart from `sat_depth` so that the paper mode's
/// arithmetic is untouched.
#[allow(clippy::too_many_arguments)]
pub fn sat_axis(
    pa: &Polyhedron,
    ra: DQuat,
    va: &[DVec3],
    pb: &Polyhedron,
    rb: DQuat,
    vb: &[DVec3],
    b_off: DVec3,
    tie: f64,
) -> (f64, DVec3) {
    let least = sat_depth(pa, ra, va, pb, rb, vb, b_off);
    let mut best = (f64::INFINITY, DVec3::Y);
    let mut test = |axis: DVec3| {
        let (amin, amax) = project(va.iter().copied(), axis);
        let (bmin, bmax) = project(vb.iter().map(|v| *v + b_off), axis);
        // b beyond a along +axis, or along -axis: the smaller overlap says which side b is on.
        let (up, down) = (amax - bmin, bmax - amin);
        let (overlap, dir) = if up <= down {
            (up, axis)
        } else {
            (down, -axis)
        };
        if overlap <= least + tie && (best.0 == f64::INFINITY || dir.y.abs() < best.1.y.abs()) {
            best = (overlap, dir);
        }
    };
    for f in &pa.faces {
        test(ra * f.normal);
    }
    for f in &pb.faces {
        test(rb * f.normal);
    }
    for ea in &pa.edge_dirs {
        let ea = ra * *ea;
        for eb in &pb.edge_dirs {
            let c = ea.cross(rb * *eb);
            let l = c.length();
            if l > 1e-9 {
                test(c / l);
            }
        }
    }
    (least, best.1)
}

/// R12 (R14) for two touching blocks: whether translating `a` by `d` keeps them apart along
/// some separating axis, that is, some SAT axis on which they are separated or touch (within
/// `touch`) and which the step does not close by more than the gap plus `tol`. For convex solids
/// such an axis proves that no point of the way enters the other block. Every axis counts, not
/// only the one of least overlap: an edge resting against a wall touches it along the wall's
/// normal and along its own face's normal at once, and only the first lets it slide down.
#[allow(clippy::too_many_arguments)]
pub fn sat_allows_motion(
    pa: &Polyhedron,
    ra: DQuat,
    va: &[DVec3],
    pb: &Polyhedron,
    rb: DQuat,
    vb: &[DVec3],
    b_off: DVec3,
    d: DVec3,
    touch: f64,
    tol: f64,
) -> bool {
    // Along one axis: they touch (overlap at most `touch`, what a turn limited to hull_eps and
    // rounding far from the origin leave) and the step closes at most the gap plus `tol`, or,
    // where they already overlap, does not go deeper (no creeping into a neighbour).
    let dl = d.length();
    let keeps = |gap: f64, closing: f64| {
        gap >= -touch && closing <= if gap >= 0.0 { gap + tol } else { 1e-9 * dl }
    };
    let keeps_apart = |axis: DVec3| {
        let (amin, amax) = project(va.iter().copied(), axis);
        let (bmin, bmax) = project(vb.iter().map(|v| *v + b_off), axis);
        // b beyond a along +axis (gap bmin - amax) or along -axis (gap amin - bmax).
        let (gap_up, gap_down) = (bmin - amax, amin - bmax);
        let closing = d.dot(axis);
        keeps(gap_up, closing) || keeps(gap_down, -closing)
    };
    pa.faces.iter().any(|f| keeps_apart(ra * f.normal))
        || pb.faces.iter().any(|f| keeps_apart(rb * f.normal))
        || pa.edge_dirs.iter().any(|ea| {
            let ea = ra * *ea;
            pb.edge_dirs.iter().any(|eb| {
                let c = ea.cross(rb * *eb);
                let l = c.length();
                l > 1e-9 && keeps_apart(c / l)
            })
        })
}

/// R14's contact manifold of two blocks within `eps`, appended to `out` relative to a's G (world
/// orientation; b's G at `b_off`), at most `cap` points in `out` in all:
/// - every vertex of either block within `eps` of the other solid (inside or on it:
///   `max_face_distance <= eps` in the other's body frame);
/// - every crossing of an edge of either block with a face plane of the other that lies within
///   `eps` of the other solid. These give the corners of the true overlap polygon where no vertex
///   of either block lies on the other's face (a box turned 45 deg on another: an octagon).
///
/// Points of either kind lie on one block's surface and within `eps` of the other: all of them
/// are in the contact patch, so their 2-D hull is the patch's outline.
#[allow(clippy::too_many_arguments)]
pub fn contact_points(
    pa: &Polyhedron,
    ra: DQuat,
    va: &[DVec3],
    pb: &Polyhedron,
    rb: DQuat,
    vb: &[DVec3],
    b_off: DVec3,
    eps: f64,
    cap: usize,
    out: &mut Vec<DVec3>,
) {
    let (ia, ib) = (ra.conjugate(), rb.conjugate());
    let in_a = |x: DVec3| pa.max_face_distance(ia * x).0 <= eps;
    let in_b = |x: DVec3| pb.max_face_distance(ib * (x - b_off)).0 <= eps;
    let push = |out: &mut Vec<DVec3>, p: DVec3| {
        if out.len() < cap {
            out.push(p);
        }
    };
    for v in vb {
        let p = *v + b_off;
        if in_a(p) {
            push(out, p);
        }
    }
    for v in va {
        if in_b(*v) {
            push(out, *v);
        }
    }
    // Edges of a against b's face planes, in b's body frame.
    for e in &pa.edges {
        let p0 = ib * (va[e[0]] - b_off);
        let p1 = ib * (va[e[1]] - b_off);
        for f in &pb.faces {
            let (d0, d1) = (f.distance(p0), f.distance(p1));
            if (d0 < 0.0 && d1 > 0.0) || (d0 > 0.0 && d1 < 0.0) {
                let x = p0 + (p1 - p0) * (d0 / (d0 - d1));
                if pb.max_face_distance(x).0 <= eps {
                    push(out, rb * x + b_off);
                }
            }
        }
    }
    // Edges of b against a's face planes, in a's body frame.
    for e in &pb.edges {
        let p0 = ia * (vb[e[0]] + b_off);
        let p1 = ia * (vb[e[1]] + b_off);
        for f in &pa.faces {
            let (d0, d1) = (f.distance(p0), f.distance(p1));
            if (d0 < 0.0 && d1 > 0.0) || (d0 > 0.0 && d1 < 0.0) {
                let x = p0 + (p1 - p0) * (d0 / (d0 - d1));
                if pa.max_face_distance(x).0 <= eps {
                    push(out, ra * x);
                }
            }
        }
    }
}

/// The segment a0 a1 crossing the triangle (t0, t1, t2) (Moller-Trumbore, both sides):
/// returns (s along the segment, barycentric w1, w2) of the crossing. A segment parallel to
/// the triangle's plane, or a zero-area triangle, gives None (docs/model.md R2).
pub fn segment_triangle(
    a0: DVec3,
    a1: DVec3,
    t0: DVec3,
    t1: DVec3,
    t2: DVec3,
) -> Option<(f64, f64, f64)> {
    let e1 = t1 - t0;
    let e2 = t2 - t0;
    let area2 = e1.cross(e2).length_squared();
    let scale = e1.length_squared().max(e2.length_squared());
    if area2 <= 1e-24 * scale * scale || scale == 0.0 {
        return None;
    }
    let dir = a1 - a0;
    let p = dir.cross(e2);
    let det = e1.dot(p);
    if det.abs() <= 1e-15 * dir.length() * area2.sqrt() {
        return None;
    }
    let inv = 1.0 / det;
    let s0 = a0 - t0;
    let u = s0.dot(p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s0.cross(e1);
    let v = dir.dot(q) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let s = e2.dot(q) * inv;
    if !(0.0..=1.0).contains(&s) {
        return None;
    }
    Some((s, u, v))
}

/// Closest points of segments p0 p1 and q0 q1: (s on p, t on q, squared distance).
pub fn segment_segment(p0: DVec3, p1: DVec3, q0: DVec3, q1: DVec3) -> (f64, f64, f64) {
    let d1 = p1 - p0;
    let d2 = q1 - q0;
    let r = p0 - q0;
    let a = d1.dot(d1);
    let e = d2.dot(d2);
    let f = d2.dot(r);
    let (s, t);
    if a <= 1e-30 && e <= 1e-30 {
        s = 0.0;
        t = 0.0;
    } else if a <= 1e-30 {
        s = 0.0;
        t = (f / e).clamp(0.0, 1.0);
    } else {
        let c = d1.dot(r);
        if e <= 1e-30 {
            t = 0.0;
            s = (-c / a).clamp(0.0, 1.0);
        } else {
            let b = d1.dot(d2);
            let denom = a * e - b * b;
            let mut s0 = if denom > 1e-30 {
                ((b * f - c * e) / denom).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let mut t0 = (b * s0 + f) / e;
            if t0 < 0.0 {
                t0 = 0.0;
                s0 = (-c / a).clamp(0.0, 1.0);
            } else if t0 > 1.0 {
                t0 = 1.0;
                s0 = ((b - c) / a).clamp(0.0, 1.0);
            }
            s = s0;
            t = t0;
        }
    }
    let dist = (p0 + d1 * s - (q0 + d2 * t)).length_squared();
    (s, t, dist)
}

/// The 2-D convex hull (Andrew's monotone chain) of `pts`, counter-clockwise, collinear points
/// dropped, written into `out`. `pts` is sorted in place. No allocation when `out` has room.
pub fn convex_hull_2d(pts: &mut [DVec2], out: &mut Vec<DVec2>) {
    out.clear();
    pts.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    let n = pts.len();
    if n <= 2 {
        out.extend_from_slice(pts);
        if n == 2 && pts[0] == pts[1] {
            out.pop();
        }
        return;
    }
    let cross = |o: DVec2, a: DVec2, b: DVec2| (a - o).perp_dot(b - o);
    for &p in pts.iter() {
        while out.len() >= 2 && cross(out[out.len() - 2], out[out.len() - 1], p) <= 0.0 {
            out.pop();
        }
        out.push(p);
    }
    let lower = out.len() + 1;
    for &p in pts.iter().rev().skip(1) {
        while out.len() >= lower && cross(out[out.len() - 2], out[out.len() - 1], p) <= 0.0 {
            out.pop();
        }
        out.push(p);
    }
    out.pop();
    if out.len() == 2 && out[0] == out[1] {
        out.pop();
    }
}

/// Distance from `p` to the segment a b in 2-D, and the parameter of the foot.
pub fn point_segment_2d(p: DVec2, a: DVec2, b: DVec2) -> (f64, f64) {
    let ab = b - a;
    let l2 = ab.length_squared();
    let t = if l2 > 0.0 {
        ((p - a).dot(ab) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    ((a + ab * t - p).length(), t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_has_six_faces_twelve_edges_and_g_at_centre() {
        let p = Polyhedron::from_spec(&ShapeSpec::Box {
            size: [0.2, 0.1, 0.4],
        })
        .unwrap();
        assert_eq!(p.vertices.len(), 8);
        assert_eq!(p.faces.len(), 6);
        assert_eq!(p.edges.len(), 12);
        assert!((p.volume - 0.008).abs() < 1e-15);
        for v in &p.vertices {
            assert_eq!(v.abs(), DVec3::new(0.1, 0.05, 0.2));
        }
    }

    #[test]
    fn wedge_and_tetra_are_centred_on_their_volume_centroid() {
        let w = Polyhedron::from_spec(&ShapeSpec::Wedge {
            size: [0.3, 0.3, 0.3],
        })
        .unwrap();
        assert_eq!((w.vertices.len(), w.faces.len(), w.edges.len()), (6, 5, 9));
        let t = Polyhedron::from_spec(&ShapeSpec::Tetra {
            size: [0.4, 0.4, 0.4],
        })
        .unwrap();
        assert_eq!((t.vertices.len(), t.faces.len(), t.edges.len()), (4, 4, 6));
        // The general path (hull) computes the same centroid as the closed form.
        let pts: Vec<[f64; 3]> = vec![
            [0.0, 0.0, 0.0],
            [0.4, 0.0, 0.0],
            [0.0, 0.4, 0.0],
            [0.0, 0.0, 0.4],
        ];
        let h = Polyhedron::from_spec(&ShapeSpec::Hull { vertices: pts }).unwrap();
        let mean: DVec3 = h.vertices.iter().copied().sum::<DVec3>() / 4.0;
        assert!(mean.length() < 1e-15, "{mean}");
    }

    #[test]
    fn flat_hull_is_refused() {
        let pts = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0],
            [1.0, 0.0, 1.0],
        ];
        assert!(Polyhedron::from_spec(&ShapeSpec::Hull { vertices: pts }).is_err());
    }

    #[test]
    fn r1_locus_through_an_edge_sums_the_two_normals() {
        let p = Polyhedron::from_spec(&ShapeSpec::Box {
            size: [2.0, 2.0, 2.0],
        })
        .unwrap();
        let (t, n) = p
            .locus_entry(DVec3::new(2.0, 2.0, 0.0), DVec3::new(0.0, 0.0, 0.0), 1e-9)
            .unwrap();
        assert!((t - 0.5).abs() < 1e-12);
        let s = std::f64::consts::FRAC_1_SQRT_2;
        assert!((n - DVec3::new(s, s, 0.0)).length() < 1e-12, "{n}");
    }

    #[test]
    fn hull_2d_drops_collinear_points() {
        let mut pts = [
            DVec2::new(0.0, 0.0),
            DVec2::new(1.0, 0.0),
            DVec2::new(2.0, 0.0),
            DVec2::new(2.0, 1.0),
            DVec2::new(0.0, 1.0),
        ];
        let mut out = Vec::new();
        convex_hull_2d(&mut pts, &mut out);
        assert_eq!(out.len(), 4);
        let mut line = [
            DVec2::new(0.0, 0.0),
            DVec2::new(1.0, 0.0),
            DVec2::new(2.0, 0.0),
        ];
        convex_hull_2d(&mut line, &mut out);
        assert_eq!(out.len(), 2);
    }
}
