//! The `[[objects]]` entries: each object's material, emission and shape (a mesh, quad or box of triangles, or
//! an analytic sphere, lens surface or annulus).

use super::materials::Materials;
use super::state::Loader;
use crate::color::Rgb;
use crate::geometry::{Analytic, Annulus, LensSurface, Mesh, Sphere};
use crate::light::Light;
use crate::scene::description::{ImageRef, ObjectDesc, ShapeDesc};
use crate::scene::file::{AnnulusSection, LensSurfaceSection, ObjectSection, SphereSection};
use crate::scene::SceneError;
use crate::texture::{quad_uvs, Encoding};
use toml::Spanned;

impl Loader<'_> {
    /// Object `i`: its material, emission and shape.
    pub(super) fn object(
        &mut self,
        i: usize,
        o: &Spanned<ObjectSection>,
        materials: &Materials,
    ) -> Result<ObjectDesc, SceneError> {
        let obj = o.get_ref();
        let field = |f: &str| format!("objects[{i}].{f}");
        let material = self.object_material(obj, materials, &field)?;
        let (emission, emission_texture) = self.emission(obj, &field)?;
        self.check_one_shape(i, o)?;
        let shape = match self.triangle_shape(obj, &field)? {
            Some(shape) => shape,
            None => {
                let shape = self.analytic(obj, &field)?;
                if let Some(le) = emission.filter(|&e| e != Rgb::ZERO) {
                    if Light::of_analytic(i as u32, &shape, le).is_none() {
                        return Err(self.error(
                            obj.emission.as_ref().map(|e| e.span()),
                            field("emission"),
                            "of the analytic surfaces only a sphere and a full disc (an annulus with inner_radius = 0) \
                             can emit; use a mesh, quad or box",
                        ));
                    }
                }
                ShapeDesc::Analytic(shape)
            }
        };
        // A mesh's texture coordinates are known once the build step has read it.
        let without_uvs = matches!(&shape, ShapeDesc::Triangles { uvs: None, .. } | ShapeDesc::Analytic(_));
        if without_uvs {
            self.check_no_texture_needed(obj, &field, materials.list[material as usize].uses_uv())?;
        }
        Ok(ObjectDesc {
            name: obj.name.clone().unwrap_or_else(|| format!("object {i}")),
            lens_name: obj.name.clone(),
            material,
            emission,
            emission_texture,
            shape,
            source: self.source(Some(o.span()), format!("objects[{i}]")),
            material_source: self.source(Some(obj.material.span()), field("material")),
        })
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
    ) -> Result<(Option<Rgb>, Option<ImageRef>), SceneError> {
        let emission = match &obj.emission {
            Some(e) => Some(self.colour(*e.get_ref(), &e.span(), &field("emission"), None)?),
            // An emission texture alone emits its own values.
            None if obj.emission_texture.is_some() => Some(Rgb::ONE),
            None => None,
        };
        let emission_texture = match &obj.emission_texture {
            Some(t) => Some(self.image(t.get_ref(), Some(t.span()), &field("emission_texture"), Encoding::Srgb)?),
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

    /// The shape of a mesh, quad or box; None for an analytic shape.
    fn triangle_shape(
        &mut self,
        obj: &ObjectSection,
        field: &dyn Fn(&str) -> String,
    ) -> Result<Option<ShapeDesc>, SceneError> {
        if let Some(m) = &obj.mesh {
            let file = self.external_file(m.get_ref(), Some(m.span()), &field("mesh"), "mesh")?;
            return Ok(Some(ShapeDesc::Obj { file, source: self.source(Some(m.span()), field("mesh")) }));
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
            let uvs = Some(quad_uvs().to_vec());
            return Ok(Some(ShapeDesc::Triangles { triangles: Mesh::quad(c, e1, e2).triangles, uvs }));
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
            return Ok(Some(ShapeDesc::Triangles { triangles: Mesh::axis_box(lo, hi).triangles, uvs: None }));
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
