//! Mesh files of the `obj`, `ply` and `serialized` shapes, read into one indexed form with texture coordinates
//! in Mitsuba's convention (v downward), and the triangles a shape adds once `to_world`, `face_normals` and
//! `flip_normals` are applied.

use crate::scene::mitsuba::{ply, serialized};
use glam::{DMat3, DMat4, DVec3, Vec2, Vec3};

/// A mesh as its file gives it.
#[derive(Default)]
pub(crate) struct IndexedMesh {
    pub positions: Vec<Vec3>,
    pub triangles: Vec<[u32; 3]>,
    pub normals: Option<Vec<Vec3>>,
    /// Texture coordinates as Mitsuba reads them (v downward: its OBJ reader stores 1 − v by default).
    pub uvs: Option<Vec<Vec2>>,
}

/// Reads an OBJ file as Mitsuba's `obj` does: every object and group into one mesh, v flipped when
/// `flip_tex_coords` (Mitsuba's default).
pub(crate) fn read_obj(bytes: &[u8], flip_tex_coords: bool) -> Result<IndexedMesh, String> {
    let (models, _) = tobj::load_obj_buf(
        &mut std::io::BufReader::new(bytes),
        &tobj::LoadOptions { triangulate: true, single_index: true, ignore_points: true, ignore_lines: true },
        |_| Err(tobj::LoadError::OpenFileFailed),
    )
    .map_err(|e| format!("cannot parse the OBJ file: {e}"))?;
    let mut mesh = IndexedMesh::default();
    let mut normals = Some(Vec::new());
    let mut uvs = Some(Vec::new());
    for model in &models {
        let m = &model.mesh;
        let base = mesh.positions.len() as u32;
        let count = m.positions.len() / 3;
        mesh.positions.extend(m.positions.chunks_exact(3).map(|p| Vec3::new(p[0], p[1], p[2])));
        mesh.triangles.extend(m.indices.chunks_exact(3).map(|t| [base + t[0], base + t[1], base + t[2]]));
        // With single_index, tobj gives normals or coordinates for every vertex or for none; a model without
        // them leaves the whole mesh without them, as some of its triangles would have none.
        if m.normals.len() == 3 * count {
            if let Some(n) = &mut normals {
                n.extend(m.normals.chunks_exact(3).map(|n| Vec3::new(n[0], n[1], n[2])));
            }
        } else {
            normals = None;
        }
        if m.texcoords.len() == 2 * count {
            if let Some(u) = &mut uvs {
                let v = |t: f32| if flip_tex_coords { 1.0 - t } else { t };
                u.extend(m.texcoords.chunks_exact(2).map(|t| Vec2::new(t[0], v(t[1]))));
            }
        } else {
            uvs = None;
        }
    }
    mesh.normals = normals.filter(|n| !n.is_empty());
    mesh.uvs = uvs.filter(|u| !u.is_empty());
    Ok(mesh)
}

/// Reads a PLY file (coordinates as stored: Mitsuba's PLY reader does not flip them).
pub(crate) fn read_ply(bytes: &[u8]) -> Result<IndexedMesh, String> {
    let m = ply::read(bytes).map_err(|e| format!("cannot parse the PLY file: {e}"))?;
    Ok(IndexedMesh { positions: m.positions, triangles: m.triangles, normals: m.normals, uvs: m.uvs })
}

/// Reads mesh `shape_index` of a serialized file; the second value is its own face-normals flag.
pub(crate) fn read_serialized(bytes: &[u8], shape_index: u32) -> Result<(IndexedMesh, bool), String> {
    let m = serialized::read_serialized(bytes, shape_index).map_err(|e| e.to_string())?;
    let v3 = |p: &[f32; 3]| Vec3::from(*p);
    Ok((
        IndexedMesh {
            positions: m.positions.iter().map(v3).collect(),
            triangles: m.triangles,
            normals: m.normals.map(|n| n.iter().map(v3).collect()),
            uvs: m.uvs.map(|u| u.iter().map(|t| Vec2::new(t[0], t[1])).collect()),
        },
        m.face_normals,
    ))
}

/// One world-space triangle of a shape: vertices, vertex normals and photonfarm's texture coordinates (v
/// upward).
pub(crate) struct WorldTriangle {
    pub v: [Vec3; 3],
    pub n: Option<[Vec3; 3]>,
    pub uv: Option<[Vec2; 3]>,
}

/// How a shape's triangles are placed in the world.
#[derive(Clone, Copy)]
pub(crate) struct Placement {
    pub to_world: DMat4,
    pub flip_normals: bool,
}

impl Placement {
    /// The world triangles of `mesh`, without degenerate ones (which Mitsuba never hits either); the second
    /// value counts those left out. Normals transform by the inverse transpose; a mirroring transform keeps the
    /// sides the vertex normals give by reversing the winding, where there are vertex normals (Mitsuba's side is
    /// its shading normal's; without them it is the winding's, which the mirror reverses in both renderers).
    pub fn triangles(&self, mesh: &IndexedMesh) -> Result<(Vec<WorldTriangle>, usize), String> {
        let m = self.to_world;
        let normal_matrix = DMat3::from_mat4(m).inverse().transpose();
        if !normal_matrix.is_finite() {
            return Err("to_world is singular".into());
        }
        let mirror = DMat3::from_mat4(m).determinant() < 0.0;
        let positions: Vec<Vec3> = mesh.positions.iter().map(|p| m.transform_point3(p.as_dvec3()).as_vec3()).collect();
        let normals: Option<Vec<Vec3>> = mesh.normals.as_ref().map(|ns| {
            ns.iter()
                .map(|n| {
                    let w = normal_matrix * n.as_dvec3();
                    let w = w.try_normalize().unwrap_or(DVec3::ZERO).as_vec3();
                    if self.flip_normals {
                        -w
                    } else {
                        w
                    }
                })
                .collect()
        });
        let reverse = self.flip_normals ^ (mirror && normals.is_some());
        let mut out = Vec::with_capacity(mesh.triangles.len());
        let mut skipped = 0;
        for (k, t) in mesh.triangles.iter().enumerate() {
            if t.iter().any(|&i| i as usize >= positions.len()) {
                return Err(format!("triangle {k} names a vertex past the {} the mesh has", positions.len()));
            }
            let order = if reverse { [t[0], t[2], t[1]] } else { *t };
            let v = order.map(|i| positions[i as usize]);
            if !v.iter().all(|p| p.is_finite()) {
                return Err(format!("triangle {k} has a coordinate that is not a finite number"));
            }
            let area2 = (v[1] - v[0]).cross(v[2] - v[0]).length();
            let scale = (v[1] - v[0]).length().max((v[2] - v[0]).length());
            if area2.is_nan() || area2 <= 1e-7 * scale * scale {
                skipped += 1;
                continue;
            }
            let n = normals
                .as_ref()
                .map(|ns| order.map(|i| ns[i as usize]))
                .filter(|n| n.iter().all(|x| x.length_squared() > 0.0));
            let uv = mesh.uvs.as_ref().map(|us| order.map(|i| us[i as usize])).map(|uv| uv.map(photonfarm_uv));
            if uv.is_some_and(|uv| !uv.iter().all(|c| c.is_finite())) {
                return Err(format!("triangle {k} has a texture coordinate that is not a finite number"));
            }
            out.push(WorldTriangle { v, n, uv });
        }
        Ok((out, skipped))
    }
}

/// Mitsuba's texture coordinates (v downward) in photonfarm's (v upward).
pub(crate) fn photonfarm_uv(uv: Vec2) -> Vec2 {
    Vec2::new(uv.x, 1.0 - uv.y)
}
