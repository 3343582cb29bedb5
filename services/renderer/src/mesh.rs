//! Static geometry, built once: the floor, a unit cylinder and sphere (finger segments and
//! joints, placed per frame by instance matrices), and one mesh per scene block (the shapes
//! crate's solid, the one the stepper simulates).
//!
//! Vertices carry only a position and four "edge weights", each 0 along some of the polygon's
//! edges and none 0 inside it, so the smallest of them is 0 exactly on the polygon's outline.
//! A triangle face is one triangle (its barycentric coordinates), a quadrilateral two (its
//! u, 1-u, v, 1-v: affine across both halves of a parallelogram, and 0 along its four sides
//! whatever its shape, never along the diagonal), any larger polygon a fan from its centre
//! (weight 1 at the centre, 0 on the rim). The fragment shader darkens pixels within about a
//! pixel of 0 (`w / fwidth(w)`), which draws every block edge at a constant screen width in
//! the same pass, without a line pipeline (lines are 1 px in wgpu and need their own depth
//! bias). Normals come from screen derivatives in the shader, so every face is flat-shaded.
//!
//! Why not a fan everywhere (one weight, fewer attributes): a software rasteriser (llvmpipe)
//! pays per triangle, and a cube's fans are 24 triangles where its quads are 12; a field of
//! 1024 cubes in stereo, with shadows, took 18 ms a frame in triangle set-up alone at 16 x 16
//! pixels (8 ms with quads). Every mesh is indexed too (each distinct vertex once).

use std::ops::Range;

use bytemuck::{Pod, Zeroable};
use common::config::scene::ShapeSpec;
use glam::DVec3;
use shapes::Solid;

#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct Vertex {
    pub position: [f32; 3],
    /// Edge weights: the smallest is 0 exactly on the face's outline (see the module doc);
    /// all 1 on meshes drawn without edges; the floor grid's line strength in the first.
    pub edge: [f32; 4],
}

/// Half the floor's side, metres: blocks stay within ~1 m of the origin; the floor fills the
/// view behind them.
pub const FLOOR_HALF: f32 = 4.0;

/// All static meshes in one vertex and one index buffer, and where each lies in the index
/// buffer (each range is drawn with `draw_indexed`, base vertex 0).
pub struct Meshes {
    pub vertices: Vec<Vertex>,
    pub indices: Vec<u32>,
    pub floor: Range<u32>,
    /// The floor grid, as a line list (see [`grid_lines`]).
    pub grid: Range<u32>,
    pub cylinder: Range<u32>,
    pub sphere: Range<u32>,
    /// One per scene block, in scene order. Blocks of the same shape share one range, so that
    /// the draw list draws them as instances of one mesh (a field of 4096 equal cubes is one
    /// draw call).
    pub blocks: Vec<Range<u32>>,
}

/// Why a block cannot be drawn.
#[derive(Debug, Clone, PartialEq)]
pub struct ShapeError {
    pub block: usize,
    pub problem: String,
}

impl Meshes {
    pub fn build(shapes: &[&ShapeSpec]) -> Result<Meshes, ShapeError> {
        let mut buffers = IndexedBuffers::default();
        let floor = buffers.push(floor_triangles());
        let grid = buffers.push(grid_lines());
        let cylinder = buffers.push(cylinder_triangles(12));
        let sphere = buffers.push(sphere_triangles(12, 6));
        let mut blocks = Vec::with_capacity(shapes.len());
        // Each distinct shape once: scenes hold few (a linear search over them is enough).
        let mut distinct: Vec<(&ShapeSpec, Range<u32>)> = Vec::new();
        for (i, s) in shapes.iter().enumerate() {
            if let Some((_, range)) = distinct.iter().find(|(d, _)| d == s) {
                blocks.push(range.clone());
                continue;
            }
            let solid = Solid::from_spec(s).map_err(|problem| ShapeError { block: i, problem })?;
            let range = buffers.push(solid_triangles(&solid));
            distinct.push((s, range.clone()));
            blocks.push(range);
        }
        Ok(Meshes {
            vertices: buffers.vertices,
            indices: buffers.indices,
            floor,
            grid,
            cylinder,
            sphere,
            blocks,
        })
    }
}

/// The shared vertex and index buffers being filled.
#[derive(Default)]
struct IndexedBuffers {
    vertices: Vec<Vertex>,
    indices: Vec<u32>,
}

impl IndexedBuffers {
    /// Appends a mesh given as a plain primitive list (triangles or lines), each distinct
    /// vertex once (equal bits, within this mesh); returns its index range.
    fn push(&mut self, primitives: Vec<Vertex>) -> Range<u32> {
        let mut seen: std::collections::HashMap<[u32; 7], u32> = Default::default();
        let start = self.indices.len() as u32;
        for v in primitives {
            let [x, y, z] = v.position.map(f32::to_bits);
            let [a, b, c, d] = v.edge.map(f32::to_bits);
            let next = self.vertices.len() as u32;
            let index = *seen.entry([x, y, z, a, b, c, d]).or_insert(next);
            if index == next {
                self.vertices.push(v);
            }
            self.indices.push(index);
        }
        start..self.indices.len() as u32
    }
}

fn v(p: DVec3, edge: f32) -> Vertex {
    v4(p, [edge; 4])
}

fn v4(p: DVec3, edge: [f32; 4]) -> Vertex {
    Vertex {
        position: p.as_vec3().to_array(),
        edge,
    }
}

/// A block's mesh: each face of its solid (centred on G, where the world sample's pose puts
/// the block) as one triangle, two (a quadrilateral) or a fan, with edge weights that are 0
/// on its outline (module doc).
pub fn solid_triangles(p: &Solid) -> Vec<Vertex> {
    let mut out = Vec::new();
    for f in &p.faces {
        let corner = |k: usize| p.vertices[f[k]];
        if f.len() == 3 {
            // Barycentric: weight k is 0 on the side opposite corner k.
            out.extend([
                v4(corner(0), [1.0, 0.0, 0.0, 1.0]),
                v4(corner(1), [0.0, 1.0, 0.0, 1.0]),
                v4(corner(2), [0.0, 0.0, 1.0, 1.0]),
            ]);
            continue;
        }
        if f.len() == 4 {
            // Corners at (u, v) = (0, 0), (1, 0), (1, 1), (0, 1); weights u, 1-u, v, 1-v.
            let uv = |k: usize| {
                let (u, v) = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)][k];
                v4(corner(k), [u, 1.0 - u, v, 1.0 - v])
            };
            out.extend([uv(0), uv(1), uv(2), uv(0), uv(2), uv(3)]);
            continue;
        }
        let c = f.iter().map(|&i| p.vertices[i]).sum::<DVec3>() / f.len() as f64;
        for k in 0..f.len() {
            let a = p.vertices[f[k]];
            let b = p.vertices[f[(k + 1) % f.len()]];
            out.extend([v(c, 1.0), v(a, 0.0), v(b, 0.0)]);
        }
    }
    out
}

fn floor_triangles() -> Vec<Vertex> {
    let h = FLOOR_HALF as f64;
    let p = |x: f64, z: f64| v(DVec3::new(x, 0.0, z), 1.0);
    // Counter-clockwise seen from above (+y).
    vec![p(-h, -h), p(-h, h), p(h, h), p(-h, -h), p(h, h), p(h, -h)]
}

/// Half the grid's side, metres.
pub const GRID_HALF: f64 = 3.0;

/// Grid lines every 10 cm (every 50 cm stronger: the edge weight carries the strength), as
/// line geometry 1.5 mm above the floor. Lines rather than a procedural grid in the floor's
/// fragment shader: the floor covers most of the picture, and on a software rasteriser a
/// per-pixel grid cost a third of the frame; lines cost only their own pixels.
fn grid_lines() -> Vec<Vertex> {
    let mut out = Vec::new();
    let n = (GRID_HALF / 0.1).round() as i32;
    for k in -n..=n {
        let c = k as f64 * 0.1;
        let strength = if k % 5 == 0 { 0.8 } else { 0.45 };
        for (a, b) in [
            (
                DVec3::new(c, 0.0015, -GRID_HALF),
                DVec3::new(c, 0.0015, GRID_HALF),
            ),
            (
                DVec3::new(-GRID_HALF, 0.0015, c),
                DVec3::new(GRID_HALF, 0.0015, c),
            ),
        ] {
            out.extend([v(a, strength), v(b, strength)]);
        }
    }
    out
}

/// Radius 1, from y = 0 to y = 1, open ends (the joints' spheres close them).
fn cylinder_triangles(sides: usize) -> Vec<Vertex> {
    let mut out = Vec::new();
    let ring = |k: usize, y: f64| {
        let a = k as f64 / sides as f64 * std::f64::consts::TAU;
        v(DVec3::new(a.cos(), y, -a.sin()), 1.0)
    };
    for k in 0..sides {
        let (a0, a1, b0, b1) = (
            ring(k, 0.0),
            ring(k + 1, 0.0),
            ring(k, 1.0),
            ring(k + 1, 1.0),
        );
        out.extend([a0, a1, b1, a0, b1, b0]);
    }
    out
}

/// Radius 1, centred on the origin.
fn sphere_triangles(slices: usize, stacks: usize) -> Vec<Vertex> {
    let mut out = Vec::new();
    let p = |i: usize, j: usize| {
        let theta = j as f64 / stacks as f64 * std::f64::consts::PI; // from +y down
        let phi = i as f64 / slices as f64 * std::f64::consts::TAU;
        v(
            DVec3::new(
                theta.sin() * phi.cos(),
                theta.cos(),
                -theta.sin() * phi.sin(),
            ),
            1.0,
        )
    };
    for j in 0..stacks {
        for i in 0..slices {
            let (a, b, c, d) = (p(i, j), p(i + 1, j), p(i + 1, j + 1), p(i, j + 1));
            if j != 0 {
                out.extend([a, d, c]);
            }
            if j + 1 != stacks {
                out.extend([a, c, b]);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn outward(tris: &[Vertex], centre: DVec3) -> bool {
        tris.chunks(3).all(|t| {
            let [a, b, c] = [0, 1, 2].map(|i| DVec3::from_array(t[i].position.map(|x| x as f64)));
            let n = (b - a).cross(c - a);
            n.length() < 1e-12 || n.dot((a + b + c) / 3.0 - centre) > 0.0
        })
    }

    #[test]
    fn every_mesh_faces_outward_counter_clockwise() {
        assert!(outward(&cylinder_triangles(12), DVec3::new(0.0, 0.5, 0.0)));
        assert!(outward(&sphere_triangles(12, 6), DVec3::ZERO));
        for spec in [
            ShapeSpec::Box {
                size: [0.1, 0.2, 0.3],
            },
            ShapeSpec::Wedge {
                size: [0.1, 0.2, 0.3],
            },
            ShapeSpec::Tetra {
                size: [0.1, 0.2, 0.3],
            },
        ] {
            let p = Solid::from_spec(&spec).unwrap();
            assert!(outward(&solid_triangles(&p), DVec3::ZERO), "{spec:?}");
        }
    }

    #[test]
    fn indexing_keeps_every_triangle_and_stores_each_distinct_vertex_once() {
        let cube = ShapeSpec::Box { size: [0.1; 3] };
        let meshes = Meshes::build(&[&cube, &cube]).unwrap();
        let tris = solid_triangles(&Solid::from_spec(&cube).unwrap());
        let range = meshes.blocks[0].clone();
        assert_eq!(meshes.blocks[1], range, "equal shapes share one mesh");
        let drawn: Vec<Vertex> = meshes.indices[range.start as usize..range.end as usize]
            .iter()
            .map(|&i| meshes.vertices[i as usize])
            .collect();
        assert_eq!(drawn, tris, "the same triangles, in the same order");
        let mut used: Vec<u32> = meshes.indices[range.start as usize..range.end as usize].to_vec();
        used.sort_unstable();
        used.dedup();
        let mut distinct: Vec<Vec<u32>> = tris
            .iter()
            .map(|v| {
                v.position
                    .iter()
                    .chain(&v.edge)
                    .map(|x| x.to_bits())
                    .collect()
            })
            .collect();
        distinct.sort_unstable();
        distinct.dedup();
        // Two triangles a face; a corner is one vertex where its faces give it equal weights.
        assert_eq!(tris.len(), 36);
        assert_eq!(used.len(), distinct.len());
        assert!(used.len() < 24, "{}", used.len());
    }

    #[test]
    fn block_meshes_are_centred_on_g_as_the_stepper_defines_it() {
        // Tetra: G at a quarter of each leg from the origin corner (scene.rs definition).
        let p = Solid::from_spec(&ShapeSpec::Tetra {
            size: [0.4, 0.2, 0.1],
        })
        .unwrap();
        let corner = p
            .vertices
            .iter()
            .copied()
            .min_by(|a, b| a.length_squared().total_cmp(&b.length_squared()))
            .unwrap();
        assert!(
            corner.distance(DVec3::new(-0.1, -0.05, -0.025)) < 1e-12,
            "{corner}"
        );
        // A hull given off-centre is recentred on its own centroid.
        let h = ShapeSpec::Hull {
            vertices: (0..8)
                .map(|i| {
                    [
                        5.0 + (i & 1) as f64,
                        7.0 + ((i >> 1) & 1) as f64,
                        ((i >> 2) & 1) as f64,
                    ]
                })
                .collect(),
        };
        let p = Solid::from_spec(&h).unwrap();
        let (_, g) = p.volume_centroid();
        assert!(g.length() < 1e-9);
        assert_eq!(p.faces.len(), 6);
    }
}
