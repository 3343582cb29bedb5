//! Block shapes: from a scene's shape spec to the convex polyhedron every process agrees on.
//!
//! A block (docs/model.md "Conventions") is a rigid convex polyhedron with its body origin at
//! its centre of gravity G. The stepper moves it and the renderer draws it; both build it here,
//! once, from the same [`ShapeSpec`], so the block that is drawn is the block that is
//! simulated, to the last bit of every vertex.
//!
//! The spec types stay in `common::config::scene`: they are part of the scene file, the
//! contract, which `common` parses and checks with errors that name the file and the key. This
//! crate is the geometry built from them, which needs glam and parry3d; processes that never
//! build a block (acquisition, kinematics, the recorder) do not link it.
//!
//! parry3d builds the hull (`transformation::try_convex_hull`, face merging in
//! `ConvexPolyhedron::from_convex_mesh`); the face planes, face polygons and real edges are
//! read from its result here.

use glam::DVec3;
use parry3d_f64::shape::ConvexPolyhedron;

use common::config::scene::ShapeSpec;

/// A face plane in the body frame: points x with `normal . x <= offset` are inside.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plane {
    /// Outward unit normal.
    pub normal: DVec3,
    pub offset: f64,
}

impl Plane {
    /// Signed distance of `p` from the plane (positive outside).
    #[inline]
    pub fn distance(&self, p: DVec3) -> f64 {
        self.normal.dot(p) - self.offset
    }
}

/// A block's convex hull, with its volume centroid G at the origin.
#[derive(Clone)]
pub struct Solid {
    /// Hull vertices, body frame, relative to G.
    pub vertices: Vec<DVec3>,
    /// Face planes, one per face (coplanar triangles merged: a box has six).
    pub planes: Vec<Plane>,
    /// Each face's vertex indices, in the order of `planes`: a convex polygon, counter-clockwise
    /// seen from outside (the renderer draws it as one face with its outline).
    pub faces: Vec<Vec<usize>>,
    /// The solid's edges as vertex index pairs (each lies on two distinct face planes).
    pub edges: Vec<[usize; 2]>,
    /// The hull's triangles (outward, counter-clockwise), indices into `vertices`.
    pub triangles: Vec<[u32; 3]>,
    pub volume: f64,
    /// The same hull for parry's queries (GJK distance, point projection, shape casts).
    pub shape: ConvexPolyhedron,
}

impl std::fmt::Debug for Solid {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Solid")
            .field("vertices", &self.vertices)
            .field("faces", &self.faces)
            .field("edges", &self.edges.len())
            .field("volume", &self.volume)
            .finish()
    }
}

/// The vertices a shape spec names, in the spec's own frame, and its volume centroid when it
/// is known in closed form (exact: a box's G is its centre to the last bit, which matters for
/// "G' exactly on the hull boundary").
pub fn spec_points(spec: &ShapeSpec) -> (Vec<DVec3>, Option<DVec3>) {
    match spec {
        ShapeSpec::Box { size } => {
            let h = DVec3::from_array(*size) * 0.5;
            let mut v = Vec::with_capacity(8);
            for i in 0..8 {
                v.push(DVec3::new(
                    if i & 1 == 0 { -h.x } else { h.x },
                    if i & 2 == 0 { -h.y } else { h.y },
                    if i & 4 == 0 { -h.z } else { h.z },
                ));
            }
            (v, Some(DVec3::ZERO))
        }
        // scene.rs: the right triangle with legs along +x and +y, extruded along z.
        ShapeSpec::Wedge { size } => {
            let [x, y, z] = *size;
            let v = vec![
                DVec3::new(0.0, 0.0, 0.0),
                DVec3::new(x, 0.0, 0.0),
                DVec3::new(0.0, y, 0.0),
                DVec3::new(0.0, 0.0, z),
                DVec3::new(x, 0.0, z),
                DVec3::new(0.0, y, z),
            ];
            (v, Some(DVec3::new(x / 3.0, y / 3.0, z / 2.0)))
        }
        // scene.rs: the origin corner and the three corners one edge away along x, y and z.
        ShapeSpec::Tetra { size } => {
            let [x, y, z] = *size;
            let v = vec![
                DVec3::ZERO,
                DVec3::new(x, 0.0, 0.0),
                DVec3::new(0.0, y, 0.0),
                DVec3::new(0.0, 0.0, z),
            ];
            (v, Some(DVec3::new(x / 4.0, y / 4.0, z / 4.0)))
        }
        ShapeSpec::Hull { vertices } => (
            vertices.iter().map(|p| DVec3::from_array(*p)).collect(),
            None,
        ),
    }
}

/// Signed volume and first moment of the solid bounded by `triangles` (indices into
/// `points`), by the tetrahedra from `points[0]` to every triangle: the centroid is
/// `moment / volume` whichever way the triangles wind.
fn volume_moment(points: &[DVec3], triangles: &[[u32; 3]]) -> (f64, DVec3) {
    let o = points.first().copied().unwrap_or(DVec3::ZERO);
    let mut volume = 0.0;
    let mut moment = DVec3::ZERO;
    for t in triangles {
        let (a, b, c) = (
            points[t[0] as usize],
            points[t[1] as usize],
            points[t[2] as usize],
        );
        let v6 = (a - o).dot((b - o).cross(c - o));
        volume += v6 / 6.0;
        moment += (o + a + b + c) * (v6 / 24.0);
    }
    (volume, moment)
}

impl Solid {
    /// Builds the block shape of a scene's spec, recentred on its volume centroid.
    pub fn from_spec(spec: &ShapeSpec) -> Result<Solid, String> {
        let (points, known_centroid) = spec_points(spec);
        Solid::from_points(&points, known_centroid)
    }

    /// The convex hull of `points`, recentred so that its volume centroid (`known_centroid`
    /// when given, else the hull's own) is the origin. The error says why the points are no
    /// solid, in words for a scene's author.
    pub fn from_points(points: &[DVec3], known_centroid: Option<DVec3>) -> Result<Solid, String> {
        if points.len() < 4 || !points.iter().all(|p| p.is_finite()) {
            return Err("a solid needs at least 4 finite vertices".into());
        }
        let extent = points
            .iter()
            .fold(0.0f64, |m, p| m.max(p.abs().max_element()));
        // Hull the points scaled to a unit extent per axis, then scale back: an axis scaling
        // keeps which points and faces form the hull, and parry's tolerances are relative, so a
        // thin plate (1 m x 0.5 mm) is not collapsed into a flat polygon.
        let lo = points
            .iter()
            .fold(DVec3::splat(f64::INFINITY), |m, p| m.min(*p));
        let hi = points
            .iter()
            .fold(DVec3::splat(f64::NEG_INFINITY), |m, p| m.max(*p));
        let mid = (lo + hi) / 2.0;
        let half = (hi - lo) / 2.0;
        if half.min_element() <= 0.0 {
            return Err("its vertices are flat (no volume): a block must be a solid".into());
        }
        let unit: Vec<DVec3> = points.iter().map(|p| (*p - mid) / half).collect();
        let (unit_hull, tris) = parry3d_f64::transformation::try_convex_hull(&unit)
            .map_err(|e| format!("its vertices do not span a solid (convex hull failed: {e:?})"))?;
        // Map the hull's vertices back to the input points they came from (exact values).
        let hull_pts: Vec<DVec3> = unit_hull
            .iter()
            .map(|u| {
                let i = unit
                    .iter()
                    .enumerate()
                    .min_by(|a, b| {
                        a.1.distance_squared(*u)
                            .total_cmp(&b.1.distance_squared(*u))
                    })
                    .map_or(0, |(i, _)| i);
                points[i]
            })
            .collect();
        let (volume, moment) = volume_moment(&hull_pts, &tris);
        if volume.is_nan() || volume.abs() <= 1e-12 * extent.powi(3) || volume.abs() < 1e-18 {
            return Err("its vertices are flat (no volume): a block must be a solid".into());
        }
        let centroid = known_centroid.unwrap_or(moment / volume);
        let volume = volume.abs();
        let shifted: Vec<DVec3> = hull_pts.iter().map(|p| *p - centroid).collect();
        let shape = ConvexPolyhedron::from_convex_mesh(shifted, &tris)
            .ok_or_else(|| "its convex hull is degenerate (not a closed solid)".to_string())?;
        let vertices: Vec<DVec3> = shape.points().to_vec();
        let adj = shape.vertices_adj_to_face();
        let mut planes = Vec::with_capacity(shape.faces().len());
        let mut faces = Vec::with_capacity(shape.faces().len());
        for f in shape.faces() {
            // parry lists a face's vertices along its outline, in the winding of its
            // (outward, counter-clockwise) triangles.
            let outline = &adj[f.first_vertex_or_edge as usize
                ..(f.first_vertex_or_edge + f.num_vertices_or_edges) as usize];
            faces.push(outline.iter().map(|&i| i as usize).collect());
            let first = adj[f.first_vertex_or_edge as usize] as usize;
            // Offset as the largest of the face's vertices: the plane then bounds all of them.
            let mut offset = f.normal.dot(vertices[first]);
            for k in 0..f.num_vertices_or_edges as usize {
                let v = vertices[adj[f.first_vertex_or_edge as usize + k] as usize];
                offset = offset.max(f.normal.dot(v));
            }
            planes.push(Plane {
                normal: f.normal,
                offset,
            });
        }
        // parry keeps the triangulation's diagonals of merged (coplanar) faces among its
        // edges; a real edge of the solid lies on two distinct face planes.
        let tol = 1e-9 * extent.max(1e-9);
        let on = |f: &Plane, v: DVec3| f.distance(v).abs() <= tol;
        let mut edges: Vec<[usize; 2]> = Vec::new();
        for e in shape.edges() {
            let (i, j) = (e.vertices[0] as usize, e.vertices[1] as usize);
            let count = planes
                .iter()
                .filter(|f| on(f, vertices[i]) && on(f, vertices[j]))
                .count();
            let key = [i.min(j), i.max(j)];
            if count >= 2 && !edges.contains(&key) {
                edges.push(key);
            }
        }
        Ok(Solid {
            vertices,
            planes,
            faces,
            edges,
            triangles: tris,
            volume,
            shape,
        })
    }

    /// Volume and volume centroid of the solid as built, from its triangles: the centroid is
    /// the origin up to rounding (exactly G when the spec gave it in closed form).
    pub fn volume_centroid(&self) -> (f64, DVec3) {
        let (volume, moment) = volume_moment(&self.vertices, &self.triangles);
        if volume.abs() > 0.0 {
            (volume.abs(), moment / volume)
        } else {
            (0.0, DVec3::ZERO)
        }
    }
}

/// The hull's triangles for a small point set, appended to `out` (cleared first) without
/// allocating once `out` has grown: for a shape that changes every frame, such as the palm
/// (at most 16 vertices), where building a [`Solid`] would allocate.
///
/// Each triangle of points that has every other point on one side is a hull triangle, oriented
/// outward; a face with four coplanar corners comes out as four overlapping triangles, which
/// draw as one face.
pub fn hull_triangles_into(points: &[DVec3], out: &mut Vec<[DVec3; 3]>) {
    out.clear();
    let n = points.len();
    if n < 4 || points.iter().any(|p| !p.is_finite()) {
        return;
    }
    let extent = points
        .iter()
        .map(|p| p.distance(points[0]))
        .fold(0.0, f64::max);
    let eps = extent * 1e-9;
    for i in 0..n {
        for j in i + 1..n {
            for k in j + 1..n {
                let (a, b, c) = (points[i], points[j], points[k]);
                let normal = (b - a).cross(c - a);
                if normal.length() <= eps * extent {
                    continue;
                }
                let (mut above, mut below) = (false, false);
                for p in points {
                    let s = normal.dot(*p - a);
                    above |= s > eps * normal.length();
                    below |= s < -eps * normal.length();
                }
                match (above, below) {
                    (false, true) => out.push([a, b, c]),
                    (true, false) => out.push([a, c, b]),
                    _ => {}
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cube() -> Vec<DVec3> {
        (0..8)
            .map(|i| {
                DVec3::new(
                    (i & 1) as f64 * 2.0 - 1.0,
                    ((i >> 1) & 1) as f64 * 2.0 - 1.0,
                    ((i >> 2) & 1) as f64 * 2.0 - 1.0,
                )
            })
            .collect()
    }

    #[test]
    fn a_cube_has_six_quads_outward_and_its_centre_as_centroid() {
        let mut pts = cube();
        pts.push(DVec3::ZERO); // interior points are dropped
        pts.push(DVec3::new(1.0, 1.0, 1.0)); // and duplicates
        let h = Solid::from_points(&pts, None).unwrap();
        assert_eq!(h.faces.len(), 6);
        assert!(h.faces.iter().all(|f| f.len() == 4));
        assert_eq!(h.edges.len(), 12);
        let (vol, g) = h.volume_centroid();
        assert!((vol - 8.0).abs() < 1e-9, "{vol}");
        assert!(g.length() < 1e-12);
        // Counter-clockwise from outside: the fan's normal points away from the centre, along
        // the face's plane.
        for (f, pl) in h.faces.iter().zip(&h.planes) {
            let (a, b, c) = (h.vertices[f[0]], h.vertices[f[1]], h.vertices[f[2]]);
            assert!((b - a).cross(c - a).dot(a) > 0.0);
            assert!((b - a).cross(c - a).normalize().dot(pl.normal) > 1.0 - 1e-12);
        }
    }

    #[test]
    fn a_wedge_centroid_is_a_third_of_its_legs_and_half_its_depth() {
        let (x, y, z) = (0.3, 0.2, 0.1);
        let pts = [
            DVec3::ZERO,
            DVec3::new(x, 0.0, 0.0),
            DVec3::new(0.0, y, 0.0),
            DVec3::new(0.0, 0.0, z),
            DVec3::new(x, 0.0, z),
            DVec3::new(0.0, y, z),
        ];
        // The general path (no closed-form centroid) finds the closed form's G.
        let h = Solid::from_points(&pts, None).unwrap();
        assert_eq!(h.faces.len(), 5);
        assert!((h.volume - x * y * z / 2.0).abs() < 1e-12);
        // The origin corner, now at -G.
        let corner = h.vertices.iter().copied().fold(DVec3::MAX, DVec3::min);
        assert!(
            (-corner).distance(DVec3::new(x / 3.0, y / 3.0, z / 2.0)) < 1e-12,
            "{corner}"
        );
    }

    #[test]
    fn flat_or_non_finite_points_have_no_hull() {
        let flat = [DVec3::ZERO, DVec3::X, DVec3::Z, DVec3::new(1.0, 0.0, 1.0)];
        assert!(Solid::from_points(&flat, None).is_err());
        let mut nan = cube();
        nan[3].x = f64::NAN;
        assert!(Solid::from_points(&nan, None).is_err());
        let mut out = Vec::new();
        hull_triangles_into(&nan, &mut out);
        assert!(out.is_empty());
    }

    #[test]
    fn the_per_frame_hull_covers_the_box_outward() {
        let mut out = Vec::new();
        hull_triangles_into(&cube(), &mut out);
        // 4 triangles per face (every triple of a face's 4 corners).
        assert_eq!(out.len(), 24);
        for [a, b, c] in &out {
            assert!((b - *a).cross(c - *a).dot(*a + *b + *c) > 0.0);
        }
    }
}
