//! Convex hulls of small point sets, as polygons: the renderer draws blocks from the scene's
//! shape specs itself (services share only `common`), so it needs the same polyhedron the
//! stepper uses: the hull of the shape's vertices, centred on its volume centroid G.
//!
//! Brute force over point triples, on purpose: scene shapes have at most 256 vertices and are
//! built once at start-up, and enumerating candidate planes is exact about coplanar points
//! (a box's face comes out as one quad, not two triangles with a diagonal edge to draw), which
//! incremental hull algorithms need special care for.

use glam::DVec3;

/// A convex polyhedron: vertices and faces, each face a convex polygon of vertex indices,
/// counter-clockwise seen from outside.
#[derive(Debug, Clone, PartialEq)]
pub struct Polytope {
    pub vertices: Vec<DVec3>,
    pub faces: Vec<Vec<usize>>,
}

/// A plane `normal . p = offset` with an outward unit normal.
#[derive(Debug, Clone, Copy)]
struct Plane {
    normal: DVec3,
    offset: f64,
}

/// The convex hull of `points`; None when they span no volume (fewer than 4 points not on
/// one plane) or are not finite.
pub fn convex_hull(points: &[DVec3]) -> Option<Polytope> {
    if points.iter().any(|p| !p.is_finite()) {
        return None;
    }
    let (lo, hi) = points.iter().fold(
        (DVec3::splat(f64::MAX), DVec3::splat(f64::MIN)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    let extent = (hi - lo).max_element();
    if extent.is_nan() || extent <= 0.0 {
        return None;
    }
    let eps = extent * 1e-9;
    // Duplicates would make zero-area triangles and doubled polygon corners.
    let mut pts: Vec<DVec3> = Vec::with_capacity(points.len());
    for p in points {
        if !pts.iter().any(|q| q.distance(*p) <= eps) {
            pts.push(*p);
        }
    }
    let n = pts.len();
    let mut planes: Vec<Plane> = Vec::new();
    let on = |pl: &Plane, p: DVec3| (pl.normal.dot(p) - pl.offset).abs() <= eps;
    for i in 0..n {
        for j in i + 1..n {
            for k in j + 1..n {
                let (a, b, c) = (pts[i], pts[j], pts[k]);
                if planes.iter().any(|pl| on(pl, a) && on(pl, b) && on(pl, c)) {
                    continue;
                }
                let cross = (b - a).cross(c - a);
                if cross.length() <= eps * extent {
                    continue; // collinear
                }
                let normal = cross.normalize();
                let offset = normal.dot(a);
                let (mut above, mut below) = (false, false);
                for p in &pts {
                    let s = normal.dot(*p) - offset;
                    above |= s > eps;
                    below |= s < -eps;
                    if above && below {
                        break;
                    }
                }
                if above && below {
                    continue;
                }
                if !above && !below {
                    return None; // every point on one plane: no volume
                }
                let pl = if above {
                    Plane {
                        normal: -normal,
                        offset: -offset,
                    }
                } else {
                    Plane { normal, offset }
                };
                planes.push(pl);
            }
        }
    }
    if planes.len() < 4 {
        return None;
    }
    let faces = planes
        .iter()
        .map(|pl| {
            let mut idx: Vec<usize> = (0..n).filter(|&i| on(pl, pts[i])).collect();
            let c = idx.iter().map(|&i| pts[i]).sum::<DVec3>() / idx.len() as f64;
            let u = pl.normal.any_orthonormal_vector();
            let w = pl.normal.cross(u);
            // Counter-clockwise seen from outside: increasing angle in the (u, w) basis,
            // which is right-handed with the outward normal.
            let angle = |i: usize| {
                let d = pts[i] - c;
                d.dot(w).atan2(d.dot(u))
            };
            idx.sort_by(|&x, &y| angle(x).total_cmp(&angle(y)));
            idx
        })
        .collect();
    Some(Polytope {
        vertices: pts,
        faces,
    })
}

impl Polytope {
    /// Volume and volume centroid (uniform density), by tetrahedra from an interior point to
    /// each face's fan triangles.
    pub fn volume_centroid(&self) -> (f64, DVec3) {
        let r = self.vertices.iter().sum::<DVec3>() / self.vertices.len().max(1) as f64;
        let mut volume = 0.0;
        let mut moment = DVec3::ZERO;
        for f in &self.faces {
            let a = self.vertices[f[0]];
            for w in f[1..].windows(2) {
                let (b, c) = (self.vertices[w[0]], self.vertices[w[1]]);
                let v = (a - r).dot((b - r).cross(c - r)) / 6.0;
                volume += v;
                moment += v * (r + a + b + c) / 4.0;
            }
        }
        if volume.abs() > 0.0 {
            (volume, moment / volume)
        } else {
            (0.0, r)
        }
    }

    /// The same polytope moved by `-by`.
    pub fn shifted(mut self, by: DVec3) -> Polytope {
        for v in &mut self.vertices {
            *v -= by;
        }
        self
    }
}

/// The hull's triangles for a small point set, appended to `out` (cleared first) without
/// allocating once `out` has grown: used every frame for the palm box (8 vertices).
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
        let h = convex_hull(&pts).unwrap();
        assert_eq!(h.faces.len(), 6);
        assert!(h.faces.iter().all(|f| f.len() == 4));
        let (vol, g) = h.volume_centroid();
        assert!((vol - 8.0).abs() < 1e-9, "{vol}");
        assert!(g.length() < 1e-12);
        // Counter-clockwise from outside: the fan's normal points away from the centre.
        for f in &h.faces {
            let (a, b, c) = (h.vertices[f[0]], h.vertices[f[1]], h.vertices[f[2]]);
            assert!((b - a).cross(c - a).dot(a) > 0.0);
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
        let h = convex_hull(&pts).unwrap();
        assert_eq!(h.faces.len(), 5);
        let (vol, g) = h.volume_centroid();
        assert!((vol - x * y * z / 2.0).abs() < 1e-12);
        assert!(
            g.distance(DVec3::new(x / 3.0, y / 3.0, z / 2.0)) < 1e-12,
            "{g}"
        );
    }

    #[test]
    fn flat_or_non_finite_points_have_no_hull() {
        let flat = [DVec3::ZERO, DVec3::X, DVec3::Z, DVec3::new(1.0, 0.0, 1.0)];
        assert!(convex_hull(&flat).is_none());
        let mut nan = cube();
        nan[3].x = f64::NAN;
        assert!(convex_hull(&nan).is_none());
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
