//! PLY meshes (ASCII, binary little- or big-endian) for Mitsuba's `ply` shape, read with `ply-rs-bw`: the
//! `vertex` element's `x`, `y`, `z` and, where given, `nx`, `ny`, `nz` and texture coordinates (`u`, `v`, or `s`,
//! `t`, or `texture_u`, `texture_v`), and the `face` element's `vertex_indices` (or `vertex_index`), polygons as
//! fans of triangles. Other elements and properties are skipped.

use glam::{Vec2, Vec3};
use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{PropertyAccess, PropertyAccessResult};

/// A PLY mesh with per-vertex attributes, texture coordinates as stored.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PlyMesh {
    pub positions: Vec<Vec3>,
    /// Every triangle's three vertex indices, each below the vertex count.
    pub triangles: Vec<[u32; 3]>,
    pub normals: Option<Vec<Vec3>>,
    pub uvs: Option<Vec<Vec2>>,
}

/// Why a PLY file cannot be read, at a line of its header or ASCII body where known.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{}{message}", line.map(|l| format!("line {l}: ")).unwrap_or_default())]
pub struct PlyError {
    pub line: Option<usize>,
    pub message: String,
}

impl PlyError {
    fn whole(message: String) -> Self {
        PlyError { line: None, message }
    }
}

/// Parses a PLY file's bytes.
pub fn read(bytes: &[u8]) -> Result<PlyMesh, PlyError> {
    let fail = |e: ply_rs_bw::parser::ParseError| PlyError { line: e.line(), message: e.to_string() };
    let mut reader = Reader::new(bytes);
    let header = Parser::<Vertex>::new().read_header(&mut reader).map_err(fail)?;
    let mut vertices: Vec<Vertex> = Vec::new();
    let mut faces: Vec<Face> = Vec::new();
    // The payload holds the elements in the header's order: every one is read, those not needed into nothing.
    for (name, element) in &header.elements {
        match name.as_str() {
            "vertex" => {
                vertices = Parser::new().read_payload_for_element(&mut reader, element, &header).map_err(fail)?
            }
            "face" => faces = Parser::new().read_payload_for_element(&mut reader, element, &header).map_err(fail)?,
            _ => {
                Parser::<Ignored>::new().read_payload_for_element(&mut reader, element, &header).map_err(fail)?;
            }
        }
    }
    let has = |what: &[&str]| {
        header.elements.get("vertex").is_some_and(|v| what.iter().all(|p| v.properties.contains_key(*p)))
    };
    if !has(&["x", "y", "z"]) {
        return Err(PlyError::whole("the vertex element lacks x, y or z".into()));
    }
    let normals = has(&["nx", "ny", "nz"]);
    let uvs = has(&["u", "v"]) || has(&["s", "t"]) || has(&["texture_u", "texture_v"]);
    let mut triangles = Vec::with_capacity(faces.len());
    for (k, f) in faces.iter().enumerate() {
        let corners = f.corners();
        if corners.len() < 3 {
            return Err(PlyError::whole(format!("face {k} has {} corners; a face needs three", corners.len())));
        }
        for i in 1..corners.len() - 1 {
            let t = [corners[0], corners[i], corners[i + 1]];
            if t.iter().any(|&c| c as usize >= vertices.len()) {
                return Err(PlyError::whole(format!("face {k}: face vertex index out of bounds")));
            }
            triangles.push(t);
        }
    }
    Ok(PlyMesh {
        positions: vertices.iter().map(|v| v.position).collect(),
        triangles,
        normals: normals.then(|| vertices.iter().map(|v| v.normal).collect()),
        uvs: uvs.then(|| vertices.iter().map(|v| v.uv).collect()),
    })
}

/// One vertex, with what it may carry.
#[derive(Default)]
struct Vertex {
    position: Vec3,
    normal: Vec3,
    uv: Vec2,
}

impl Vertex {
    fn set(&mut self, name: &str, value: f32) -> PropertyAccessResult {
        match name {
            "x" => self.position.x = value,
            "y" => self.position.y = value,
            "z" => self.position.z = value,
            "nx" => self.normal.x = value,
            "ny" => self.normal.y = value,
            "nz" => self.normal.z = value,
            "u" | "s" | "texture_u" => self.uv.x = value,
            "v" | "t" | "texture_v" => self.uv.y = value,
            _ => return PropertyAccessResult::Ignored,
        }
        PropertyAccessResult::Set
    }
}

impl PropertyAccess for Vertex {
    fn new() -> Self {
        Vertex::default()
    }
    fn set_float(&mut self, name: &str, value: f32) -> PropertyAccessResult {
        self.set(name, value)
    }
    fn set_double(&mut self, name: &str, value: f64) -> PropertyAccessResult {
        self.set(name, value as f32)
    }
}

/// One face: its first four corners in place (triangles and quads need no allocation), any more beside them.
#[derive(Default)]
struct Face {
    first: [u32; 4],
    count: u8,
    more: Vec<u32>,
}

impl Face {
    fn corners(&self) -> Vec<u32> {
        let mut c = self.first[..(self.count as usize).min(4)].to_vec();
        c.extend_from_slice(&self.more);
        c
    }

    fn set<T: Copy + TryInto<u32>>(&mut self, name: &str, list: &[T]) -> PropertyAccessResult {
        if name != "vertex_indices" && name != "vertex_index" {
            return PropertyAccessResult::Ignored;
        }
        let mut indices = list.iter().map(|&i| i.try_into().unwrap_or(u32::MAX));
        self.count = list.len().min(u8::MAX as usize) as u8;
        for (slot, i) in self.first.iter_mut().zip(indices.by_ref()) {
            *slot = i;
        }
        self.more = indices.collect();
        PropertyAccessResult::Set
    }
}

impl PropertyAccess for Face {
    fn new() -> Self {
        Face::default()
    }
    fn set_list_int(&mut self, name: &str, value: Vec<i32>) -> PropertyAccessResult {
        self.set(name, &value)
    }
    fn set_list_uint(&mut self, name: &str, value: Vec<u32>) -> PropertyAccessResult {
        self.set(name, &value)
    }
    fn set_list_short(&mut self, name: &str, value: Vec<i16>) -> PropertyAccessResult {
        self.set(name, &value)
    }
    fn set_list_ushort(&mut self, name: &str, value: Vec<u16>) -> PropertyAccessResult {
        self.set(name, &value)
    }
    fn set_list_char(&mut self, name: &str, value: Vec<i8>) -> PropertyAccessResult {
        self.set(name, &value)
    }
    fn set_list_uchar(&mut self, name: &str, value: Vec<u8>) -> PropertyAccessResult {
        self.set(name, &value)
    }
}

/// An element the mesh does not need.
struct Ignored;

impl PropertyAccess for Ignored {
    fn new() -> Self {
        Ignored
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEADER: &str =
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n";

    #[test]
    fn an_ascii_quad_is_a_fan_of_two_triangles() {
        let text = format!(
            "{HEADER}element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n"
        );
        let m = read(text.as_bytes()).unwrap();
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3]]);
        assert_eq!(m.positions[2], Vec3::new(1.0, 1.0, 0.0));
        assert!(m.normals.is_none() && m.uvs.is_none());
    }

    #[test]
    fn binary_normals_and_texture_coordinates_are_per_vertex() {
        let mut bytes = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
            property float z\nproperty float nx\nproperty float ny\nproperty float nz\nproperty float s\n\
            property float t\nelement face 1\nproperty list uchar uint vertex_indices\nend_header\n"
            .to_vec();
        for k in 0..3 {
            for f in [k as f32, 0.0, 0.0, 0.0, 0.0, 1.0, 0.5 * k as f32, 0.25] {
                bytes.extend(f.to_le_bytes());
            }
        }
        bytes.push(3);
        for i in [0u32, 1, 2] {
            bytes.extend(i.to_le_bytes());
        }
        let m = read(&bytes).unwrap();
        assert_eq!(m.triangles, vec![[0, 1, 2]]);
        assert_eq!(m.normals, Some(vec![Vec3::Z; 3]));
        assert_eq!(m.uvs, Some(vec![Vec2::new(0.0, 0.25), Vec2::new(0.5, 0.25), Vec2::new(1.0, 0.25)]));
    }

    #[test]
    fn an_index_past_the_vertices_or_a_truncated_file_is_refused() {
        let face = "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n";
        let e = read(format!("{HEADER}{face}3 0 1 4\n").as_bytes()).unwrap_err();
        assert!(e.to_string().contains("out of bounds"), "{e}");
        assert!(read(format!("{HEADER}{face}").as_bytes()).is_err());
        assert!(read(b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nend_header\n\0\0")
            .is_err());
    }
}
