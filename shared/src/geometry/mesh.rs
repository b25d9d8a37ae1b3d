//! Triangle meshes: loaded from OBJ files or generated for quads and boxes.

use glam::Vec3;

/// One triangle with optional per-vertex shading normals.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MeshTriangle {
    pub v: [Vec3; 3],
    pub n: Option<[Vec3; 3]>,
}

impl MeshTriangle {
    /// Twice the area's vector: its direction is the CCW (front) normal.
    pub fn cross(&self) -> Vec3 {
        (self.v[1] - self.v[0]).cross(self.v[2] - self.v[0])
    }

    /// Surface area.
    pub fn area(&self) -> f32 {
        0.5 * self.cross().length()
    }
}

/// A list of triangles belonging to one scene object.
#[derive(Clone, Debug, Default)]
pub struct Mesh {
    pub triangles: Vec<MeshTriangle>,
}

impl Mesh {
    /// A parallelogram `corner`, `corner + edge1`, `corner + edge1 + edge2`, `corner + edge2`, front face along
    /// edge1 × edge2.
    pub fn quad(corner: Vec3, edge1: Vec3, edge2: Vec3) -> Mesh {
        let (a, b, c, d) = (corner, corner + edge1, corner + edge1 + edge2, corner + edge2);
        Mesh { triangles: vec![MeshTriangle { v: [a, b, c], n: None }, MeshTriangle { v: [a, c, d], n: None }] }
    }

    /// An axis-aligned box with outward-facing triangles.
    pub fn axis_box(min: Vec3, max: Vec3) -> Mesh {
        let s = max - min;
        let (x, y, z) = (Vec3::X * s.x, Vec3::Y * s.y, Vec3::Z * s.z);
        let faces = [
            (min, z, y),     // x = min, normal −x
            (min + x, y, z), // x = max, normal +x
            (min, x, z),     // y = min, normal −y
            (min + y, z, x), // y = max, normal +y
            (min, y, x),     // z = min, normal −z
            (min + z, x, y), // z = max, normal +z
        ];
        let mut mesh = Mesh::default();
        for (corner, e1, e2) in faces {
            mesh.triangles.extend(Mesh::quad(corner, e1, e2).triangles);
        }
        mesh
    }

    /// Total surface area.
    pub fn area(&self) -> f32 {
        self.triangles.iter().map(MeshTriangle::area).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_faces_point_outward() {
        let b = Mesh::axis_box(Vec3::ZERO, Vec3::new(1.0, 2.0, 3.0));
        let centre = Vec3::new(0.5, 1.0, 1.5);
        assert_eq!(b.triangles.len(), 12);
        for t in &b.triangles {
            let c = (t.v[0] + t.v[1] + t.v[2]) / 3.0;
            assert!(t.cross().dot(c - centre) > 0.0, "inward face {:?}", t);
        }
        assert!((b.area() - 2.0 * (2.0 + 3.0 + 6.0)).abs() < 1e-4);
    }
}
