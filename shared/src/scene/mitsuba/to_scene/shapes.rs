//! Shapes: `obj`, `ply`, `serialized`, `rectangle` and `cube` as triangles, `sphere` and `disk` as analytic
//! surfaces, each with its BSDF (Mitsuba's diffuse default when it names none) and an `area` emitter.

use super::params::Params;
use super::{rgb, source, Importer};
use crate::color::Rgb;
use crate::geometry::{Analytic, Annulus, MeshTriangle, Sphere};
use crate::light::Light;
use crate::scene::description::{MeshFormat, ObjectDesc, ShapeDesc};
use crate::scene::mitsuba::meshes::{IndexedMesh, Placement};
use crate::scene::mitsuba::{Category, MitsubaError, Plugin, SpectrumUse};
use glam::{DMat3, DMat4, DVec3, Vec2, Vec3};
use std::sync::Arc;

impl Importer<'_> {
    /// One top-level shape: a shape with its material and emission, or an `instance`, the shapes of its
    /// `shapegroup` moved by its to_world. A group itself is drawn only where an instance places it, as in Mitsuba.
    pub(super) fn shape(&mut self, plugin: &Arc<Plugin>) -> Result<(), MitsubaError> {
        match plugin.kind.to_ascii_lowercase().as_str() {
            "shapegroup" => self.group_shapes(plugin).map(|_| ()),
            "instance" => self.instance(plugin),
            _ => self.placed_shape(plugin, DMat4::IDENTITY, ""),
        }
    }

    /// An instance, expanded: each shape of its group with the instance's to_world applied after the shape's own.
    fn instance(&mut self, plugin: &Arc<Plugin>) -> Result<(), MitsubaError> {
        let p = Params::new(plugin);
        let to_world = p.transform("to_world")?;
        let group = match p.children_of(Category::Shape).as_slice() {
            [one] if one.plugin.kind.eq_ignore_ascii_case("shapegroup") => one.plugin.clone(),
            _ => return Err(p.error("an instance takes one shapegroup (by <ref id=\"…\"/>)")),
        };
        p.finish()?;
        let suffix = format!(" in {} at line {}", plugin.element(), plugin.position.line);
        for shape in self.group_shapes(&group)? {
            self.placed_shape(&shape, to_world, &suffix)?;
        }
        Ok(())
    }

    /// The shapes of a group, refused where Mitsuba refuses them: emitters (Mitsuba does not instance them),
    /// nested groups and instances.
    fn group_shapes(&self, group: &Plugin) -> Result<Vec<Arc<Plugin>>, MitsubaError> {
        let p = Params::new(group);
        let shapes: Vec<Arc<Plugin>> = p.children_of(Category::Shape).into_iter().map(|c| c.plugin.clone()).collect();
        p.finish()?;
        for shape in &shapes {
            let kind = shape.kind.to_ascii_lowercase();
            if kind == "shapegroup" || kind == "instance" {
                return Err(shape.error(format!("a {kind} inside a shapegroup is not allowed (nor in Mitsuba)")));
            }
            if let Some(e) = shape.children_of(Category::Emitter).next() {
                return Err(MitsubaError::at(
                    &e.position,
                    e.plugin.element(),
                    "a shape in a shapegroup cannot emit (Mitsuba does not instance emitters)",
                ));
            }
        }
        Ok(shapes)
    }

    /// A shape with its material and emission, its to_world followed by `outer`; `suffix` ends its name.
    fn placed_shape(&mut self, plugin: &Arc<Plugin>, outer: DMat4, suffix: &str) -> Result<(), MitsubaError> {
        let p = Params::new(plugin);
        // Mitsuba's plugin names are lower case; exporters sometimes capitalise them.
        let kind = plugin.kind.to_ascii_lowercase();
        let bsdfs = p.children_of(Category::Bsdf);
        let material = match bsdfs.as_slice() {
            [] => self.default_material(),
            [one] => self.material(&one.plugin)?,
            [_, second, ..] => {
                return Err(MitsubaError::at(&second.position, second.plugin.element(), "a shape takes one BSDF"))
            }
        };
        let emission = self.area_emission(&p)?;
        let placement =
            Placement { to_world: outer * p.transform("to_world")?, flip_normals: p.boolean("flip_normals", false)? };
        let id = self.objects.len() as u32;
        let name =
            plugin.id.clone().unwrap_or_else(|| format!("{} at line {}", plugin.element(), plugin.position.line))
                + suffix;
        let emission = emission.filter(|e| *e != Rgb::ZERO);
        let shape = match kind.as_str() {
            "rectangle" | "cube" => {
                let mesh = if kind == "rectangle" { rectangle() } else { cube() };
                let (triangles, skipped) = placement.triangles(&mesh).map_err(|m| p.error(m))?;
                if skipped > 0 {
                    self.notes.push(format!("{name}: {skipped} degenerate triangles (no area) left out"));
                }
                if triangles.is_empty() {
                    return Err(p.error("the shape has no triangle with an area"));
                }
                let has_uvs = triangles.iter().all(|t| t.uv.is_some());
                if self.materials[material as usize].uses_uv() && !has_uvs {
                    return Err(p.error("its BSDF is textured but the shape has no texture coordinates"));
                }
                let uvs = has_uvs.then(|| triangles.iter().map(|t| t.uv.expect("checked above")).collect());
                let triangles = triangles.into_iter().map(|t| MeshTriangle { v: t.v, n: t.n }).collect();
                ShapeDesc::Triangles { triangles, uvs }
            }
            "obj" | "ply" | "serialized" => {
                // The build step reads the mesh, places it, and checks its triangles and texture coordinates.
                let filename = p.string("filename")?.ok_or_else(|| p.error("the shape needs a filename"))?;
                let file = self.read_file(filename, &p.plugin.position, &p.plugin.element())?;
                let format = match kind.as_str() {
                    "obj" => MeshFormat::Obj { flip_tex_coords: p.boolean("flip_tex_coords", true)? },
                    "ply" => MeshFormat::Ply,
                    _ => {
                        let index = p.integer("shape_index")?.unwrap_or(0);
                        let index = u32::try_from(index).map_err(|_| p.error("shape_index must not be negative"))?;
                        MeshFormat::Serialized { shape_index: index }
                    }
                };
                let face_normals = p.boolean("face_normals", false)?;
                let (to_world, flip_normals) = (placement.to_world, placement.flip_normals);
                ShapeDesc::PlacedMesh { file, format, face_normals, to_world, flip_normals }
            }
            "sphere" | "disk" => {
                if self.materials[material as usize].uses_uv() {
                    return Err(
                        p.error(format!("its BSDF is textured but photonfarm's {kind} has no texture coordinates"))
                    );
                }
                if placement.flip_normals {
                    return Err(p.error(format!("flip_normals on a {kind} is not supported")));
                }
                let shape = analytic(&p, &kind, &placement)?;
                // Mitsuba's area emitter radiates from the side the surface normal faces: a sphere's outside, a
                // disk's transformed +z, which `analytic` made the disc's emitting side.
                if let Some(le) = emission {
                    if Light::of_analytic(id, &shape, le).is_none() {
                        return Err(p.error(format!("photonfarm's {kind} cannot emit")));
                    }
                }
                ShapeDesc::Analytic(shape)
            }
            other => {
                return Err(p.error(format!(
                    "the shape `{other}` is not supported (obj, ply, serialized, rectangle, cube, sphere and disk are)"
                )))
            }
        };
        for medium in p.children_of(Category::Medium) {
            let refusal = MitsubaError::at(
                &medium.position,
                medium.plugin.element(),
                "participating media are not supported (photonfarm renders surfaces in vacuum)",
            );
            self.approximate(refusal, "without it")?;
        }
        p.finish()?;
        let at = source(&plugin.position, plugin.element());
        self.objects.push(ObjectDesc {
            name,
            lens_name: None,
            material,
            emission,
            emission_texture: None,
            shape,
            source: at.clone(),
            material_source: at,
        });
        Ok(())
    }

    /// The radiance of the shape's `area` emitter, when it has one.
    fn area_emission(&mut self, p: &Params) -> Result<Option<Rgb>, MitsubaError> {
        let emitters = p.children_of(Category::Emitter);
        let Some(emitter) = emitters.first() else { return Ok(None) };
        let e = Params::new(&emitter.plugin);
        if emitters.len() > 1 {
            return Err(e.error("a shape takes one emitter"));
        }
        if emitter.plugin.kind != "area" {
            return Err(e.error(format!("a shape's emitter is an `area` emitter, not `{}`", emitter.plugin.kind)));
        }
        if e.child("radiance").is_some() {
            return Err(e.error("a textured radiance is not supported yet: give a colour or a spectrum"));
        }
        let radiance = rgb(e.colour("radiance", SpectrumUse::Emission)?.unwrap_or([1.0; 3]));
        if !radiance.is_finite() || radiance.min_element() < 0.0 {
            return Err(e.error(format!("the radiance must be finite and not negative, got {radiance:?}")));
        }
        e.finish()?;
        Ok(Some(radiance))
    }
}

/// Mitsuba's `rectangle`: [−1, 1]² in the plane z = 0, facing +z, texture coordinates (0, 0) at (−1, −1).
fn rectangle() -> IndexedMesh {
    IndexedMesh {
        positions: vec![
            Vec3::new(-1.0, -1.0, 0.0),
            Vec3::new(1.0, -1.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(-1.0, 1.0, 0.0),
        ],
        triangles: vec![[0, 1, 2], [0, 2, 3]],
        normals: Some(vec![Vec3::Z; 4]),
        uvs: Some(vec![Vec2::new(0.0, 0.0), Vec2::new(1.0, 0.0), Vec2::new(1.0, 1.0), Vec2::new(0.0, 1.0)]),
    }
}

/// Mitsuba's `cube`: [−1, 1]³ with outward faces, each with its own normal.
fn cube() -> IndexedMesh {
    let mut mesh = IndexedMesh { normals: Some(Vec::new()), ..IndexedMesh::default() };
    let axes = [Vec3::X, Vec3::Y, Vec3::Z];
    for a in 0..3 {
        let (b, c) = (axes[(a + 1) % 3], axes[(a + 2) % 3]);
        for sign in [1.0f32, -1.0] {
            let n = axes[a] * sign;
            let base = mesh.positions.len() as u32;
            for (sb, sc) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                mesh.positions.push(n + b * sb + c * sc);
                mesh.normals.as_mut().expect("set above").push(n);
            }
            // b × c = a: counter-clockwise seen from outside on the + face, the other way round on the − face.
            let quad = if sign > 0.0 { [0, 1, 2, 3] } else { [0, 3, 2, 1] };
            mesh.triangles.push([base + quad[0], base + quad[1], base + quad[2]]);
            mesh.triangles.push([base + quad[0], base + quad[2], base + quad[3]]);
        }
    }
    mesh
}

/// A sphere or a disk, whose `to_world` must keep it round (a rotation, a uniform scale and a translation).
fn analytic(p: &Params, kind: &str, placement: &Placement) -> Result<Analytic, MitsubaError> {
    let m = placement.to_world;
    let linear = DMat3::from_mat4(m);
    let scale = linear.determinant().abs().cbrt();
    let similar = scale > 0.0 && {
        let q = linear * (1.0 / scale);
        (q.transpose() * q - DMat3::IDENTITY).to_cols_array().iter().all(|x| x.abs() < 1e-5)
    };
    if !similar {
        return Err(p.error(format!(
            "the {kind}'s to_world stretches it unevenly, which photonfarm's analytic {kind} cannot: use a mesh"
        )));
    }
    if kind == "sphere" {
        let center = p.point("center")?.unwrap_or(DVec3::ZERO);
        let radius = p.float("radius")?.unwrap_or(1.0);
        if radius <= 0.0 {
            return Err(p.error(format!("the radius must be positive, got {radius}")));
        }
        return Ok(Analytic::Sphere(Sphere {
            center: m.transform_point3(center).as_vec3(),
            radius: (radius * scale) as f32,
        }));
    }
    // photonfarm's annulus faces −axis; Mitsuba's disk faces its transformed +z.
    let normal = (linear.inverse().transpose() * DVec3::Z).normalize();
    Ok(Analytic::Annulus(Annulus {
        center: m.transform_point3(DVec3::ZERO).as_vec3(),
        axis: (-normal).as_vec3(),
        inner_radius: 0.0,
        outer_radius: scale as f32,
    }))
}
