//! Where a surface ends: the triangle edges beyond which no triangle continues the surface. A density estimate
//! around a point near such an edge must not count the part of its disc that lies past it, where no light can
//! land on the same surface.

use super::mesh::MeshTriangle;
use std::collections::HashMap;

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
    pub fn find(triangles: &[(u32, MeshTriangle)]) -> Self {
        let key = |t: &MeshTriangle, i: usize| {
            let (a, b) = (t.v[i].to_array().map(f32::to_bits), t.v[(i + 1) % 3].to_array().map(f32::to_bits));
            if a <= b {
                (a, b)
            } else {
                (b, a)
            }
        };
        let normals: Vec<_> = triangles.iter().map(|(_, t)| t.cross().normalize_or_zero()).collect();
        let mut by_edge: HashMap<_, Vec<u32>> = HashMap::with_capacity(triangles.len() * 3 / 2);
        for (index, (_, t)) in triangles.iter().enumerate() {
            for i in 0..3 {
                by_edge.entry(key(t, i)).or_default().push(index as u32);
            }
        }
        let bits = triangles
            .iter()
            .enumerate()
            .map(|(index, (_, t))| {
                let mut ends = 0u8;
                for i in 0..3 {
                    let continued = by_edge[&key(t, i)].iter().any(|&other| {
                        other as usize != index && normals[index].dot(normals[other as usize]).abs() >= SAME_SURFACE_COS
                    });
                    if !continued {
                        ends |= 1 << i;
                    }
                }
                ends
            })
            .collect();
        SurfaceEdges { bits }
    }

    /// The edges of triangle `index` that end the surface (bit i: vertex i to vertex i + 1).
    #[inline]
    pub fn of(&self, index: u32) -> u8 {
        self.bits.get(index as usize).copied().unwrap_or(0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Mesh;
    use glam::Vec3;

    fn tagged(mesh: Mesh) -> Vec<(u32, MeshTriangle)> {
        mesh.triangles.into_iter().map(|t| (0, t)).collect()
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
        triangles.extend(Mesh::quad(Vec3::X, Vec3::X, Vec3::Z).triangles.into_iter().map(|t| (1, t)));
        let edges = SurfaceEdges::find(&triangles);
        // The first quad's side at x = 1 (edge b–c of its first triangle) is the second quad's side d–a.
        assert_eq!(edges.of(0), 0b001);
    }
}
