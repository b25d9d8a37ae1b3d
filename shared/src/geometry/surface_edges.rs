//! Where a surface ends: the triangle edges beyond which no triangle continues the surface. A density estimate
//! around a point near such an edge must not count the part of its disc that lies past it, where no light can
//! land on the same surface.

use glam::Vec3;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU8, Ordering};

/// Two surfaces whose normals agree at least this well (|cos|, 25°) count as one surface: a gather takes light
/// landing on either, and an edge between them does not end the surface.
pub const SAME_SURFACE_COS: f32 = 0.9;

/// For every triangle, which of its edges end the surface: bit i for the edge from vertex i to vertex i + 1.
#[derive(Clone, Debug, Default)]
pub struct SurfaceEdges {
    bits: Vec<u8>,
}

impl SurfaceEdges {
    /// Finds the surface's ends among `triangles`: an edge continues the surface when another triangle, of any
    /// object, has an edge with the same two end points (bit for bit, as meshes share their vertices) and a
    /// normal that agrees within `SAME_SURFACE_COS`. Degenerate triangles end the surface on every edge.
    pub fn find(triangles: &[(u32, [Vec3; 3])]) -> Self {
        let key = |edge: usize| {
            let v = &triangles[edge / 3].1;
            let i = edge % 3;
            let (a, b) = (v[i].to_array().map(f32::to_bits), v[(i + 1) % 3].to_array().map(f32::to_bits));
            if a <= b {
                (a, b)
            } else {
                (b, a)
            }
        };
        let normals: Vec<_> =
            triangles.par_iter().map(|(_, v)| (v[1] - v[0]).cross(v[2] - v[0]).normalize_or_zero()).collect();
        // Every edge (3 × triangle + i) sorted by a hash of its end points: the edges that share their end points
        // sit together (with the rare others of the same hash, told apart by their points), in one sort rather
        // than a map of lists, which a mesh of millions of triangles filled slowly.
        let mut edges: Vec<(u64, u32)> =
            (0..3 * triangles.len()).into_par_iter().map(|e| (edge_hash(key(e)), e as u32)).collect();
        edges.par_sort_unstable();
        // Runs of one hash are independent, but two runs may clear bits of the same triangle (its other edges).
        let bits: Vec<AtomicU8> = (0..triangles.len()).map(|_| AtomicU8::new(0b111)).collect();
        edges.par_chunk_by(|a, b| a.0 == b.0).for_each(|same_hash| {
            for &(_, e) in same_hash {
                let (e, index) = (e as usize, e as usize / 3);
                let continued = same_hash.iter().any(|&(_, f)| {
                    let (f, other) = (f as usize, f as usize / 3);
                    other != index && key(f) == key(e) && normals[index].dot(normals[other]).abs() >= SAME_SURFACE_COS
                });
                if continued {
                    bits[index].fetch_and(!(1 << (e % 3)), Ordering::Relaxed);
                }
            }
        });
        let bits = bits.into_iter().map(AtomicU8::into_inner).collect();
        SurfaceEdges { bits }
    }

    /// The edges of triangle `index` that end the surface (bit i: vertex i to vertex i + 1).
    #[inline]
    pub fn of(&self, index: u32) -> u8 {
        self.bits.get(index as usize).copied().unwrap_or(0)
    }
}

/// A hash of an edge's end points (their bits), the same for the same points.
fn edge_hash((a, b): ([u32; 3], [u32; 3])) -> u64 {
    a.into_iter()
        .chain(b)
        .fold(0xcbf2_9ce4_8422_2325u64, |h, w| (h.rotate_left(5) ^ w as u64).wrapping_mul(0x0100_0000_01b3))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Mesh, MeshTriangle};

    fn tagged(mesh: Mesh) -> Vec<(u32, [Vec3; 3])> {
        mesh.triangles.into_iter().map(|t| (0, t.v)).collect()
    }

    #[test]
    fn a_quads_diagonal_continues_the_surface_and_its_sides_end_it() {
        let edges = SurfaceEdges::find(&tagged(Mesh::quad(Vec3::ZERO, Vec3::X, Vec3::Z)));
        // Triangles (a, b, c) and (a, c, d): the diagonal a–c is edge 2 of the first and edge 0 of the second.
        assert_eq!(edges.of(0), 0b011);
        assert_eq!(edges.of(1), 0b110);
    }

    #[test]
    fn a_boxs_edges_all_end_its_faces_however_the_triangles_meet() {
        let edges = SurfaceEdges::find(&tagged(Mesh::axis_box(Vec3::ZERO, Vec3::ONE)));
        // Every face is a quad: its two sides on the cube's edges end it, its diagonal does not.
        for t in 0..12 {
            assert_eq!(edges.of(t).count_ones(), 2, "triangle {t}");
        }
    }

    #[test]
    fn a_coplanar_neighbour_of_another_object_continues_the_surface() {
        let mut triangles = tagged(Mesh::quad(Vec3::ZERO, Vec3::X, Vec3::Z));
        triangles.extend(Mesh::quad(Vec3::X, Vec3::X, Vec3::Z).triangles.into_iter().map(|t| (1, t.v)));
        let edges = SurfaceEdges::find(&triangles);
        // The first quad's side at x = 1 (edge b–c of its first triangle) is the second quad's side d–a.
        assert_eq!(edges.of(0), 0b001);
    }

    #[test]
    fn the_ends_found_are_those_of_a_comparison_of_every_pair_of_edges() {
        // A bumpy 12 × 12 grid (neighbours at every angle, shared vertices), a few triangles reusing its points
        // elsewhere, and a degenerate one.
        let point = |i: usize, j: usize| Vec3::new(i as f32, ((i * 7 + j * 3) % 5) as f32 * 0.3, j as f32);
        let mut triangles = Vec::new();
        for i in 0..12 {
            for j in 0..12 {
                let (a, b, c, d) = (point(i, j), point(i + 1, j), point(i + 1, j + 1), point(i, j + 1));
                triangles.push((0, MeshTriangle { v: [a, b, c], n: None }));
                triangles.push((1, MeshTriangle { v: [a, c, d], n: None }));
            }
        }
        triangles.push((2, MeshTriangle { v: [point(3, 3), point(4, 3), point(3, 9)], n: None }));
        triangles.push((2, MeshTriangle { v: [point(5, 5), point(5, 5), point(6, 5)], n: None }));
        let found = SurfaceEdges::find(&triangles.iter().map(|(o, t)| (*o, t.v)).collect::<Vec<_>>());
        let normal = |t: &MeshTriangle| t.cross().normalize_or_zero();
        let same = |p: Vec3, q: Vec3| p.to_array().map(f32::to_bits) == q.to_array().map(f32::to_bits);
        for (k, (_, t)) in triangles.iter().enumerate() {
            let mut ends = 0u8;
            for i in 0..3 {
                let (a, b) = (t.v[i], t.v[(i + 1) % 3]);
                let continued = triangles.iter().enumerate().any(|(m, (_, u))| {
                    m != k
                        && (0..3).any(|e| {
                            let (c, d) = (u.v[e], u.v[(e + 1) % 3]);
                            (same(a, c) && same(b, d)) || (same(a, d) && same(b, c))
                        })
                        && normal(t).dot(normal(u)).abs() >= SAME_SURFACE_COS
                });
                if !continued {
                    ends |= 1 << i;
                }
            }
            assert_eq!(found.of(k as u32), ends, "triangle {k}");
        }
        assert_eq!(found.of(triangles.len() as u32 - 1), 0b111, "a degenerate triangle ends its surface everywhere");
    }
}
