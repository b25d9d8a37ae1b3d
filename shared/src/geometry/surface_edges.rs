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
        // Worked out where needed rather than kept: the triangle's points are in the cache then (see below).
        let normal = |index: usize| {
            let v = &triangles[index].1;
            (v[1] - v[0]).cross(v[2] - v[0]).normalize_or_zero()
        };
        // Every edge (3 × triangle + i) sorted by the Morton code of its midpoint: the edges that share their end
        // points sit together (with the rare others of the same code, told apart by their points), in one sort
        // rather than a map of lists, which a mesh of millions of triangles filled slowly. Runs next to each
        // other in that order lie next to each other in space, so the triangles they read are mostly in the
        // cache already where the mesh lists nearby triangles near each other, as meshes do; a hash of the end
        // points scattered those reads over the whole mesh.
        let cells = MortonCells::around(triangles);
        let mut edges: Vec<(u64, u32)> = (0..3 * triangles.len())
            .into_par_iter()
            .map(|e| {
                // From the ordered end points, so that both triangles of an edge compute the same midpoint.
                let (a, b) = key(e);
                let point = |bits: [u32; 3]| Vec3::from_array(bits.map(f32::from_bits));
                (cells.code((point(a) + point(b)) * 0.5), e as u32)
            })
            .collect();
        edges.par_sort_unstable();
        // Runs of one code are independent, but two runs may clear bits of the same triangle (its other edges).
        let bits: Vec<AtomicU8> = (0..triangles.len()).map(|_| AtomicU8::new(0b111)).collect();
        edges.par_chunk_by(|a, b| a.0 == b.0).for_each(|same_cell| {
            for &(_, e) in same_cell {
                let (e, index) = (e as usize, e as usize / 3);
                let continued = same_cell.iter().any(|&(_, f)| {
                    let (f, other) = (f as usize, f as usize / 3);
                    other != index && key(f) == key(e) && normal(index).dot(normal(other)).abs() >= SAME_SURFACE_COS
                });
                if continued {
                    bits[index].fetch_and(!(1 << (e % 3)), Ordering::Relaxed);
                }
            }
        });
        let bits = bits.into_iter().map(AtomicU8::into_inner).collect();
        SurfaceEdges { bits }
    }

    /// Edges as `bits` gives them: one byte per triangle, as a cache stored them.
    pub(crate) fn from_bits(bits: Vec<u8>) -> Self {
        SurfaceEdges { bits }
    }

    /// One byte per triangle, bit i set when the edge from vertex i to vertex i + 1 ends the surface.
    pub(crate) fn bits(&self) -> &[u8] {
        &self.bits
    }

    /// The edges of triangle `index` that end the surface (bit i: vertex i to vertex i + 1).
    #[inline]
    pub fn of(&self, index: u32) -> u8 {
        self.bits.get(index as usize).copied().unwrap_or(0)
    }
}

/// The cells of a 2²¹-per-axis grid over the triangles' box, numbered along a Morton (Z-order) curve: points
/// in one cell share a code, and cells close in the numbering are mostly close in space.
struct MortonCells {
    lo: Vec3,
    scale: Vec3,
}

impl MortonCells {
    const CELLS: f32 = (1u32 << 21) as f32;

    fn around(triangles: &[(u32, [Vec3; 3])]) -> Self {
        let (lo, hi) = triangles
            .par_iter()
            .map(|(_, v)| (v[0].min(v[1]).min(v[2]), v[0].max(v[1]).max(v[2])))
            .reduce(|| (Vec3::INFINITY, Vec3::NEG_INFINITY), |a, b| (a.0.min(b.0), a.1.max(b.1)));
        // A flat or empty box gets cells of any size on its flat axes: every point there has cell 0.
        let size = (hi - lo).max(Vec3::splat(f32::MIN_POSITIVE));
        MortonCells { lo, scale: Vec3::splat(Self::CELLS) / size }
    }

    /// The code of the cell holding `p`; the same point always has the same code.
    fn code(&self, p: Vec3) -> u64 {
        // `as` saturates (and takes NaN to 0), so the far faces of the box fall into the last cell.
        let cell = ((p - self.lo) * self.scale).to_array().map(|c| (c as u32).min((1 << 21) - 1));
        spread(cell[0]) | spread(cell[1]) << 1 | spread(cell[2]) << 2
    }
}

/// The 21 low bits of `x`, two zero bits after each: the bits of one axis in a 3D Morton code.
fn spread(x: u32) -> u64 {
    let mut x = x as u64 & 0x1f_ffff;
    x = (x | x << 32) & 0x1f_0000_0000_ffff;
    x = (x | x << 16) & 0x1f_0000_ff00_00ff;
    x = (x | x << 8) & 0x100f_00f0_0f00_f00f;
    x = (x | x << 4) & 0x10c3_0c30_c30c_30c3;
    x = (x | x << 2) & 0x1249_2492_4924_9249;
    x
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
        the_ends_found_match_a_comparison_of_every_pair(None);
    }

    #[test]
    fn edges_sharing_one_grid_cell_are_still_told_apart_by_their_points() {
        // A triangle far away makes the grid's cells so large that the whole bumpy grid shares a few of them.
        the_ends_found_match_a_comparison_of_every_pair(Some(Vec3::splat(1e7)));
    }

    /// A bumpy 12 × 12 grid (neighbours at every angle, shared vertices), a few triangles reusing its points
    /// elsewhere, a degenerate one, and optionally a small triangle at `far`, against every pair of edges.
    fn the_ends_found_match_a_comparison_of_every_pair(far: Option<Vec3>) {
        let point = |i: usize, j: usize| Vec3::new(i as f32, ((i * 7 + j * 3) % 5) as f32 * 0.3, j as f32);
        let mut triangles = Vec::new();
        if let Some(f) = far {
            triangles.push((3, MeshTriangle { v: [f, f + Vec3::X, f + Vec3::Z], n: None }));
        }
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

    #[test]
    fn a_morton_code_interleaves_the_cells_bits_x_first() {
        assert_eq!(spread(0b1), 0b1);
        assert_eq!(spread(0b11), 0b1001);
        assert_eq!(spread((1 << 21) - 1), 0x1249_2492_4924_9249);
        let cells = MortonCells { lo: Vec3::ZERO, scale: Vec3::ONE };
        assert_eq!(cells.code(Vec3::new(1.5, 0.0, 0.0)), 0b001);
        assert_eq!(cells.code(Vec3::new(0.0, 1.0, 0.0)), 0b010);
        assert_eq!(cells.code(Vec3::new(0.0, 0.0, 1.0)), 0b100);
        // Beyond the last cell (and NaN, at cell 0) nothing wraps into another axis's bits.
        assert_eq!(cells.code(Vec3::new(1e30, 0.0, f32::NAN)), spread((1 << 21) - 1));
    }
}
