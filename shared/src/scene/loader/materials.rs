//! The `[materials]` table: every material and its albedo texture, by name.

use super::state::Loader;
use crate::bsdf::conductor::ConductorFresnel;
use crate::color::Rgb;
use crate::material::{Material, Surface};
use crate::scene::file::MaterialSection;
use crate::scene::SceneError;
use crate::spectrum::RefractiveIndex;
use crate::texture::Texture;
use std::collections::BTreeMap;
use toml::Spanned;

/// The scene's materials in the order of their names.
pub(super) struct Materials {
    pub(super) list: Vec<Material>,
    /// Index into `list` by name.
    pub(super) index: BTreeMap<String, u32>,
}

impl Loader<'_> {
    /// Every material of the table, in the order of their names (the order their textures are read and hashed
    /// in).
    pub(super) fn materials(
        &mut self,
        table: &BTreeMap<String, Spanned<MaterialSection>>,
    ) -> Result<Materials, SceneError> {
        let mut materials = Materials { list: Vec::new(), index: BTreeMap::new() };
        for (name, m) in table {
            materials.index.insert(name.clone(), materials.list.len() as u32);
            let material = self.material(name, m)?;
            materials.list.push(material);
        }
        Ok(materials)
    }

    /// A material; every family of this format scatters alike from both sides.
    fn material(&mut self, name: &str, m: &Spanned<MaterialSection>) -> Result<Material, SceneError> {
        let s = m.span();
        let f = |x: &str| format!("materials.{name}.{x}");
        Ok(Material::two_sided(match m.get_ref() {
            MaterialSection::Diffuse { albedo, albedo_texture } => {
                let texture = match albedo_texture {
                    Some(t) => Some(self.texture(t, Some(s.clone()), &f("albedo_texture"))?),
                    None => None,
                };
                let albedo = match (albedo, &texture) {
                    (Some(a), _) => self.colour(*a, &s, &f("albedo"), Some(1.0))?,
                    // Texture values are at most 1, so the product stays a valid albedo.
                    (None, Some(_)) => Rgb::ONE,
                    (None, None) => {
                        return Err(self.error(Some(s), f("albedo"), "a diffuse material needs albedo = [r, g, b]"))
                    }
                };
                let reflectance = match texture {
                    Some(image) => Texture::Bitmap { image, factor: albedo },
                    None => Texture::Constant(albedo),
                };
                Surface::Diffuse { reflectance }
            }
            MaterialSection::Mirror { reflectance } => Surface::Conductor {
                fresnel: ConductorFresnel::Perfect,
                specular: Texture::Constant(self.colour(*reflectance, &s, &f("reflectance"), Some(1.0))?),
                roughness: None,
            },
            MaterialSection::Dielectric { ior, ext_ior, anti_reflection, abbe, ext_abbe } => {
                let ior = self.scalar(*ior, &s, &f("ior"), |v| v > 0.0, "a positive index of refraction")?;
                let ext_ior =
                    self.scalar(*ext_ior, &s, &f("ext_ior"), |v| v > 0.0, "a positive index of refraction")?;
                Surface::Dielectric {
                    ior: self.refractive_index(ior, *abbe, &s, &f("abbe"))?,
                    ext_ior: self.refractive_index(ext_ior, *ext_abbe, &s, &f("ext_abbe"))?,
                    anti_reflection: *anti_reflection,
                }
            }
            MaterialSection::Coating { reflectance, transmittance } => {
                let r = self.colour(*reflectance, &s, &f("reflectance"), Some(1.0))?;
                let t = self.colour(*transmittance, &s, &f("transmittance"), Some(1.0))?;
                if (r + t).max_element() > 1.0 + 1e-6 {
                    return Err(self.error(
                        Some(s),
                        f("transmittance"),
                        "reflectance + transmittance must not exceed 1 in any channel",
                    ));
                }
                Surface::Coating { reflectance: r, transmittance: t }
            }
        }))
    }

    /// An index of refraction, dispersive when the glass has an Abbe number.
    fn refractive_index(
        &self,
        n_d: f32,
        abbe: Option<f32>,
        span: &std::ops::Range<usize>,
        field: &str,
    ) -> Result<RefractiveIndex, SceneError> {
        let Some(v) = abbe else { return Ok(RefractiveIndex::constant(n_d)) };
        if !crate::spectrum::ENABLED {
            return Err(self.error(
                Some(span.clone()),
                field,
                "this build renders RGB only (built without the `spectral` feature): a dispersive glass needs the \
                 default build",
            ));
        }
        // Real glasses lie between about 15 (dense flints) and 100 (fluorite); outside that is a typo.
        let v = self.scalar(v, span, field, |v| (5.0..=150.0).contains(&v), "an Abbe number between 5 and 150")?;
        if n_d <= 1.0 {
            return Err(self.error(
                Some(span.clone()),
                field,
                format!("an Abbe number needs a glass index above 1 (dispersion of n − 1), got {n_d}"),
            ));
        }
        Ok(RefractiveIndex::from_abbe(n_d, v))
    }
}
