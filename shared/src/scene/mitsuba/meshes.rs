//! Mesh files of the `obj`, `ply` and `serialized` shapes, read into one indexed form with texture coordinates
//! in Mitsuba's convention (v downward), and the triangles a shape adds once `to_world`, `face_normals` and
//! `flip_normals` are applied.

use crate::scene::mitsuba::{ply, serialized};
use crate::scene::obj::{self, Coverage, NONE};
use glam::{DMat3, DMat4, DVec3, Vec2, Vec3};
use rayon::prelude::*;
use std::collections::HashMap;

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
/// `flip_tex_coords` (Mitsuba's default). The mesh has normals (texture coordinates) when every face corner
/// names one.
pub(crate) fn read_obj(bytes: &[u8], flip_tex_coords: bool) -> Result<IndexedMesh, String> {
    let obj = obj::read(bytes).map_err(|e| format!("cannot parse the OBJ file: {e}"))?;
    let every = |list: &[[u32; 3]]| obj::coverage(list, 0..obj.triangles.len()) == Coverage::All;
    let (with_normals, with_uvs) = (every(&obj.triangle_normals), every(&obj.triangle_texcoords));
    let uv = |t: Vec2| Vec2::new(t.x, if flip_tex_coords { 1.0 - t.y } else { t.y });
    // Where each corner names the texture coordinate and normal of its position's own index, the file's lists
    // already index alike.
    let alike = |used: bool, list: &[[u32; 3]], len: usize| {
        !used || (len == obj.positions.len() && list.par_iter().zip(&obj.triangles).all(|(a, b)| a == b))
    };
    if alike(with_normals, &obj.triangle_normals, obj.normals.len())
        && alike(with_uvs, &obj.triangle_texcoords, obj.texcoords.len())
    {
        return Ok(IndexedMesh {
            positions: obj.positions,
            triangles: obj.triangles,
            normals: with_normals.then_some(obj.normals),
            uvs: with_uvs.then(|| obj.texcoords.into_iter().map(uv).collect()),
        });
    }
    // Otherwise one vertex per distinct (position, texture coordinate, normal), numbered in the order the
    // corners first name them.
    let mut mesh =
        IndexedMesh { normals: with_normals.then(Vec::new), uvs: with_uvs.then(Vec::new), ..Default::default() };
    let mut vertices: HashMap<[u32; 3], u32> = HashMap::with_capacity(obj.positions.len());
    for (t, corners) in obj.triangles.iter().enumerate() {
        let mut triangle = [0; 3];
        for (c, &v) in corners.iter().enumerate() {
            let vt = if with_uvs { obj.triangle_texcoords[t][c] } else { NONE };
            let vn = if with_normals { obj.triangle_normals[t][c] } else { NONE };
            let next = mesh.positions.len() as u32;
            triangle[c] = *vertices.entry([v, vt, vn]).or_insert_with(|| {
                mesh.positions.push(obj.positions[v as usize]);
                if let Some(uvs) = &mut mesh.uvs {
                    uvs.push(uv(obj.texcoords[vt as usize]));
                }
                if let Some(normals) = &mut mesh.normals {
                    normals.push(obj.normals[vn as usize]);
                }
                next
            });
        }
        mesh.triangles.push(triangle);
    }
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

#[cfg(test)]
mod tests {
    use super::*;
    use rand_core::SeedableRng;

    /// `read_obj` as it was with tobj.
    fn read_obj_with_tobj(bytes: &[u8], flip_tex_coords: bool) -> IndexedMesh {
        let options =
            tobj::LoadOptions { triangulate: true, single_index: true, ignore_points: true, ignore_lines: true };
        let (models, _) = tobj::load_obj_buf(&mut &bytes[..], &options, |_| Err(tobj::LoadError::OpenFileFailed))
            .expect("tobj reads the file");
        let mut mesh = IndexedMesh::default();
        let mut normals = Some(Vec::new());
        let mut uvs = Some(Vec::new());
        for model in &models {
            let m = &model.mesh;
            let base = mesh.positions.len() as u32;
            let count = m.positions.len() / 3;
            mesh.positions.extend(m.positions.chunks_exact(3).map(Vec3::from_slice));
            mesh.triangles.extend(m.indices.chunks_exact(3).map(|t| [base + t[0], base + t[1], base + t[2]]));
            match (&mut normals, m.normals.len() == 3 * count) {
                (Some(n), true) => n.extend(m.normals.chunks_exact(3).map(Vec3::from_slice)),
                _ => normals = None,
            }
            match (&mut uvs, m.texcoords.len() == 2 * count) {
                (Some(u), true) => u.extend(
                    m.texcoords
                        .chunks_exact(2)
                        .map(|t| Vec2::new(t[0], if flip_tex_coords { 1.0 - t[1] } else { t[1] })),
                ),
                _ => uvs = None,
            }
        }
        mesh.normals = normals.filter(|n| !n.is_empty());
        mesh.uvs = uvs.filter(|u| !u.is_empty());
        mesh
    }

    type Corners = ([Vec3; 3], Option<[Vec3; 3]>, Option<[Vec2; 3]>);

    /// Every triangle's positions, normals and texture coordinates, which is what the scene takes of a mesh.
    fn corners(mesh: &IndexedMesh) -> Vec<Corners> {
        let at = |t: &[u32; 3]| t.map(|i| i as usize);
        mesh.triangles
            .iter()
            .map(|t| {
                (
                    at(t).map(|i| mesh.positions[i]),
                    mesh.normals.as_ref().map(|n| at(t).map(|i| n[i])),
                    mesh.uvs.as_ref().map(|u| at(t).map(|i| u[i])),
                )
            })
            .collect()
    }

    #[test]
    fn random_files_give_the_triangles_tobj_gave() {
        let mut rng = rand_pcg::Pcg32::seed_from_u64(3);
        for k in 0..300 {
            let text = crate::scene::obj::tests::random_obj(&mut rng);
            let flip = k % 2 == 0;
            let ours = read_obj(text.as_bytes(), flip).unwrap_or_else(|e| panic!("{e}\n{text}"));
            assert_eq!(corners(&ours), corners(&read_obj_with_tobj(text.as_bytes(), flip)), "{text}");
        }
    }

    #[test]
    fn corners_that_name_their_positions_own_normals_and_texture_coordinates_keep_the_files_lists() {
        let text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 5 5 5\nvt 0 0\nvt 1 0\nvt 0 1\nvt 1 1\n\
                    vn 0 0 1\nvn 0 0 1\nvn 0 0 1\nvn 0 1 0\nf 1/1/1 2/2/2 3/3/3\n";
        let mesh = read_obj(text.as_bytes(), true).unwrap();
        assert_eq!((mesh.positions.len(), &mesh.triangles[..]), (4, &[[0, 1, 2]][..]));
        assert_eq!(mesh.uvs.as_ref().map(|u| u[2]), Some(Vec2::new(0.0, 0.0)));
        assert_eq!(corners(&mesh), corners(&read_obj_with_tobj(text.as_bytes(), true)));
    }

    #[test]
    fn each_distinct_corner_becomes_a_vertex_in_the_order_first_named() {
        let text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nvn 0 0 -1\nf 1//1 2//1 3//1\nf 1//2 3//2 2//2\n";
        let mesh = read_obj(text.as_bytes(), true).unwrap();
        assert_eq!(mesh.triangles, vec![[0, 1, 2], [3, 4, 5]]);
        let tobj = read_obj_with_tobj(text.as_bytes(), true);
        assert_eq!((mesh.positions, mesh.normals), (tobj.positions, tobj.normals));
    }

    #[test]
    fn normals_on_only_some_corners_leave_the_mesh_without_normals() {
        let text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nvt 0 0\nf 1//1 2//1 3//1\ng b\nf 1/1 2/1 3/1\n";
        let mesh = read_obj(text.as_bytes(), true).unwrap();
        assert!(mesh.normals.is_none() && mesh.uvs.is_none());
        assert_eq!(corners(&mesh), corners(&read_obj_with_tobj(text.as_bytes(), true)));
    }
}
