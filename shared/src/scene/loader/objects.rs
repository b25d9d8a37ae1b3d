//! The `[[objects]]` entries: each object's material, emission and shape (a mesh, quad or box of triangles, or
//! an analytic sphere, lens surface or annulus), and the area lights of the emitting triangles, spheres and
//! discs.

use super::files::TriangleUvs;
use super::materials::Materials;
use super::state::Loader;
use crate::color::Rgb;
use crate::geometry::{Analytic, Annulus, LensSurface, Mesh, MeshTriangle, Sphere};
use crate::light::{EmissionTexture, Light};
use crate::scene::file::{AnnulusSection, LensSurfaceSection, ObjectSection, SphereSection};
use crate::scene::{SceneError, SceneObject};
use crate::texture::{quad_uvs, Bitmap, Encoding};
use glam::Vec2;
use std::collections::BTreeMap;
use std::sync::Arc;
use toml::Spanned;

/// What the objects add to the scene, gathered object by object.
#[derive(Default)]
pub(super) struct ObjectParts {
    pub(super) objects: Vec<SceneObject>,
    /// Every triangle with the object it belongs to.
    pub(super) triangles: Vec<(u32, MeshTriangle)>,
    /// Texture coordinates of each triangle, parallel to `triangles`.
    pub(super) triangle_uvs: Vec<Option<[Vec2; 3]>>,
    pub(super) analytic: Vec<(u32, Analytic)>,
    /// One area light per emitting triangle, and its emission texture.
    pub(super) area_lights: Vec<Light>,
    pub(super) light_textures: Vec<Option<EmissionTexture>>,
    /// Named lens surfaces, for the sensor camera's rear element (the first object of a name wins).
    pub(super) lens_surfaces: BTreeMap<String, LensSurface>,
}

impl ObjectParts {
    /// Adds the triangles of `object`, with an area light for each one that emits.
    fn add_triangles(
        &mut self,
        object: u32,
        mesh: Mesh,
        uvs: TriangleUvs,
        emission: Option<Rgb>,
        emission_texture: Option<Arc<Bitmap>>,
    ) {
        for (k, t) in mesh.triangles.into_iter().enumerate() {
            let uv = uvs.as_ref().map(|u| u[k]);
            if let Some(le) = emission {
                if le != Rgb::ZERO {
                    let c = t.cross();
                    self.area_lights.push(Light::Area {
                        triangle: self.triangles.len() as u32,
                        emission: le,
                        area: 0.5 * c.length(),
                        normal: c.normalize(),
                    });
                    self.light_textures.push(match (&emission_texture, uv) {
                        (Some(texture), Some(uv)) => {
                            Some(EmissionTexture { texture: texture.clone(), vertices: t.v, uv })
                        }
                        _ => None,
                    });
                }
            }
            self.triangles.push((object, t));
            self.triangle_uvs.push(uv);
        }
    }

    /// Adds the analytic surface of `object`; a lens surface with a name can be a sensor camera's rear element.
    fn add_analytic(&mut self, object: u32, shape: Analytic, name: Option<&String>) {
        if let (Analytic::Lens(l), Some(name)) = (&shape, name) {
            self.lens_surfaces.entry(name.clone()).or_insert(*l);
        }
        self.analytic.push((object, shape));
    }
}

impl Loader<'_> {
    /// Object `i`: its material, emission and shape, added to `parts`.
    pub(super) fn object(
        &mut self,
        i: usize,
        o: &Spanned<ObjectSection>,
        materials: &Materials,
        parts: &mut ObjectParts,
    ) -> Result<(), SceneError> {
        let obj = o.get_ref();
        let field = |f: &str| format!("objects[{i}].{f}");
        let material = self.object_material(obj, materials, &field)?;
        let (emission, emission_texture) = self.emission(obj, &field)?;
        self.check_one_shape(i, o)?;
        let id = parts.objects.len() as u32;
        let triangles = self.triangle_shape(obj, &field)?;
        if triangles.as_ref().is_none_or(|(_, uvs)| uvs.is_none()) {
            self.check_no_texture_needed(obj, &field, materials.list[material as usize].uses_uv())?;
        }
        match triangles {
            Some((mesh, uvs)) => parts.add_triangles(id, mesh, uvs, emission, emission_texture),
            None => {
                let shape = self.analytic(obj, &field)?;
                if let Some(le) = emission.filter(|&e| e != Rgb::ZERO) {
                    let light = Light::of_analytic(id, &shape, le).ok_or_else(|| {
                        self.error(
                            obj.emission.as_ref().map(|e| e.span()),
                            field("emission"),
                            "of the analytic surfaces only a sphere and a full disc (an annulus with inner_radius = 0) \
                             can emit; use a mesh, quad or box",
                        )
                    })?;
                    parts.area_lights.push(light);
                    parts.light_textures.push(None);
                }
                parts.add_analytic(id, shape, obj.name.as_ref());
            }
        }
        parts.objects.push(SceneObject {
            name: obj.name.clone().unwrap_or_else(|| format!("object {i}")),
            material,
            emission,
        });
        Ok(())
    }

    /// The index of the object's material.
    fn object_material(
        &self,
        obj: &ObjectSection,
        materials: &Materials,
        field: &dyn Fn(&str) -> String,
    ) -> Result<u32, SceneError> {
        let Some(&material) = materials.index.get(obj.material.get_ref()) else {
            let known: Vec<&String> = materials.index.keys().collect();
            return Err(self.error(
                Some(obj.material.span()),
                field("material"),
                format!("unknown material '{}' (defined: {known:?})", obj.material.get_ref()),
            ));
        };
        Ok(material)
    }

    /// The object's emitted radiance and emission texture, when it emits.
    fn emission(
        &mut self,
        obj: &ObjectSection,
        field: &dyn Fn(&str) -> String,
    ) -> Result<(Option<Rgb>, Option<Arc<Bitmap>>), SceneError> {
        let emission = match &obj.emission {
            Some(e) => Some(self.colour(*e.get_ref(), &e.span(), &field("emission"), None)?),
            // An emission texture alone emits its own values.
            None if obj.emission_texture.is_some() => Some(Rgb::ONE),
            None => None,
        };
        let emission_texture = match &obj.emission_texture {
            Some(t) => Some(self.bitmap(t.get_ref(), Some(t.span()), &field("emission_texture"), Encoding::Srgb)?),
            None => None,
        };
        Ok((emission, emission_texture))
    }

    /// Refuses an object with no shape or with more than one.
    fn check_one_shape(&self, i: usize, o: &Spanned<ObjectSection>) -> Result<(), SceneError> {
        let obj = o.get_ref();
        let shapes = [
            obj.mesh.is_some(),
            obj.quad.is_some(),
            obj.box_shape.is_some(),
            obj.sphere.is_some(),
            obj.lens_surface.is_some(),
            obj.annulus.is_some(),
        ];
        let count = shapes.iter().filter(|&&s| s).count();
        if count != 1 {
            return Err(self.error(
                Some(o.span()),
                format!("objects[{i}]"),
                format!("needs exactly one shape (mesh, quad, box, sphere, lens_surface or annulus), found {count}"),
            ));
        }
        Ok(())
    }

    /// The triangles of a mesh, quad or box and their texture coordinates; None for an analytic shape.
    fn triangle_shape(
        &mut self,
        obj: &ObjectSection,
        field: &dyn Fn(&str) -> String,
    ) -> Result<Option<(Mesh, TriangleUvs)>, SceneError> {
        if let Some(m) = &obj.mesh {
            return self.mesh(m, &field("mesh")).map(Some);
        }
        if let Some(q) = &obj.quad {
            let s = q.span();
            let q = q.get_ref();
            let (c, e1, e2) = (
                self.vec3(q.corner, &s, &field("quad.corner"))?,
                self.vec3(q.edge1, &s, &field("quad.edge1"))?,
                self.vec3(q.edge2, &s, &field("quad.edge2"))?,
            );
            if e1.cross(e2).length_squared() <= 0.0 {
                return Err(self.error(Some(s), field("quad"), "edge1 and edge2 are parallel: the quad has no area"));
            }
            return Ok(Some((Mesh::quad(c, e1, e2), Some(quad_uvs().to_vec()))));
        }
        if let Some(b) = &obj.box_shape {
            let s = b.span();
            let (lo, hi) = (
                self.vec3(b.get_ref().min, &s, &field("box.min"))?,
                self.vec3(b.get_ref().max, &s, &field("box.max"))?,
            );
            if (hi - lo).min_element() <= 0.0 {
                return Err(self.error(Some(s), field("box"), "max must exceed min on every axis"));
            }
            return Ok(Some((Mesh::axis_box(lo, hi), None)));
        }
        Ok(None)
    }

    /// Refuses a texture on a shape without texture coordinates (only quads and OBJ meshes with `vt` have them):
    /// an emission texture, or a texture of the object's material (`textured_material`).
    fn check_no_texture_needed(
        &self,
        obj: &ObjectSection,
        field: &dyn Fn(&str) -> String,
        textured_material: bool,
    ) -> Result<(), SceneError> {
        let shape = if obj.box_shape.is_some() {
            "a box"
        } else if obj.mesh.is_some() {
            "this OBJ mesh (it has no vt lines)"
        } else if obj.sphere.is_some() {
            "a sphere"
        } else {
            "a lens_surface"
        };
        if let Some(t) = &obj.emission_texture {
            return Err(self.error(
                Some(t.span()),
                field("emission_texture"),
                format!("{shape} has no texture coordinates; use a quad or an OBJ mesh with vt"),
            ));
        }
        if textured_material {
            return Err(self.error(
                Some(obj.material.span()),
                field("material"),
                format!(
                    "material '{}' is textured (an albedo_texture or a texture table) but {shape} has no texture \
                     coordinates; use a quad or an OBJ mesh with vt",
                    obj.material.get_ref()
                ),
            ));
        }
        Ok(())
    }

    /// The analytic shape of an object that has one (a sphere, an annulus or a lens surface).
    fn analytic(&self, obj: &ObjectSection, field: &dyn Fn(&str) -> String) -> Result<Analytic, SceneError> {
        if let Some(sphere) = &obj.sphere {
            return self.sphere(sphere, field);
        }
        if let Some(annulus) = &obj.annulus {
            return self.annulus(annulus, field);
        }
        let Some(lens) = &obj.lens_surface else {
            unreachable!("the caller checked that the object has exactly one shape")
        };
        self.lens_surface(lens, field)
    }

    fn sphere(&self, sp: &Spanned<SphereSection>, field: &dyn Fn(&str) -> String) -> Result<Analytic, SceneError> {
        let s = sp.span();
        let center = self.vec3(sp.get_ref().center, &s, &field("sphere.center"))?;
        let radius = self.scalar(sp.get_ref().radius, &s, &field("sphere.radius"), |v| v > 0.0, "a positive radius")?;
        Ok(Analytic::Sphere(Sphere { center, radius }))
    }

    fn annulus(&self, an: &Spanned<AnnulusSection>, field: &dyn Fn(&str) -> String) -> Result<Analytic, SceneError> {
        let s = an.span();
        let a = an.get_ref();
        let center = self.vec3(a.center, &s, &field("annulus.center"))?;
        let axis = self.vec3(a.axis, &s, &field("annulus.axis"))?;
        if axis.length_squared() == 0.0 {
            return Err(self.error(Some(s), field("annulus.axis"), "must not be the zero vector"));
        }
        let inner = self.scalar(
            a.inner_radius,
            &s,
            &field("annulus.inner_radius"),
            |v| v >= 0.0,
            "zero (a full disc) or a positive radius",
        )?;
        let outer = self.scalar(
            a.outer_radius,
            &s,
            &field("annulus.outer_radius"),
            |v| v > inner,
            &format!("larger than inner_radius = {inner}"),
        )?;
        Ok(Analytic::Annulus(Annulus { center, axis: axis.normalize(), inner_radius: inner, outer_radius: outer }))
    }

    fn lens_surface(
        &self,
        l: &Spanned<LensSurfaceSection>,
        field: &dyn Fn(&str) -> String,
    ) -> Result<Analytic, SceneError> {
        let s = l.span();
        let lens = l.get_ref();
        let vertex = self.vec3(lens.vertex, &s, &field("lens_surface.vertex"))?;
        let axis = self.vec3(lens.axis, &s, &field("lens_surface.axis"))?;
        if axis.length_squared() == 0.0 {
            return Err(self.error(Some(s), field("lens_surface.axis"), "must not be the zero vector"));
        }
        let aperture = self.scalar(
            lens.aperture_radius,
            &s,
            &field("lens_surface.aperture_radius"),
            |v| v > 0.0,
            "a positive radius",
        )?;
        let r = self.scalar(
            lens.curvature_radius,
            &s,
            &field("lens_surface.curvature_radius"),
            |_| true,
            "a finite number",
        )?;
        if r != 0.0 && r.abs() <= aperture {
            return Err(self.error(
                Some(s),
                field("lens_surface.aperture_radius"),
                format!("must be smaller than |curvature_radius| = {}", r.abs()),
            ));
        }
        Ok(Analytic::Lens(LensSurface {
            vertex,
            axis: axis.normalize(),
            curvature_radius: r,
            aperture_radius: aperture,
        }))
    }
}
