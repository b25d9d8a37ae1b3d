//! The `[materials]` table: every material and its textures, by name.

use super::state::Loader;
use crate::bsdf::conductor::ConductorFresnel;
use crate::bsdf::microfacet::Distribution;
use crate::bsdf::plastic::Coat;
use crate::bsdf::principled::eta_of_specular;
use crate::color::Rgb;
use crate::material::{Back, PrincipledSurface, Roughness, Surface};
use crate::scene::description::{ImageRef, MaterialDesc, TextureDesc};
use crate::scene::file::MaterialSection;
use crate::scene::SceneError;
use crate::spectrum::RefractiveIndex;
use crate::texture::{Encoding, Texture};
use std::collections::BTreeMap;
use std::ops::Range;
use toml::Spanned;

/// A material's front family, the `back` it names and its opacity.
type Sides = (Surface<ImageRef>, Option<String>, Option<TextureDesc>);

/// The scene's materials in the order of their names.
pub(super) struct Materials {
    pub(super) list: Vec<MaterialDesc>,
    /// Index into `list` by name.
    pub(super) index: BTreeMap<String, u32>,
}

impl Loader<'_> {
    /// Every material of the table, in the order of their names (the order their textures are read and hashed
    /// in). A material's `back` may name another, whose front family then scatters on its back.
    pub(super) fn materials(
        &mut self,
        table: &BTreeMap<String, Spanned<MaterialSection>>,
    ) -> Result<Materials, SceneError> {
        let mut materials = Materials { list: Vec::new(), index: BTreeMap::new() };
        let mut sides = Vec::new();
        for (name, m) in table {
            materials.index.insert(name.clone(), sides.len() as u32);
            sides.push(self.material(name, m)?);
        }
        let fronts: Vec<Surface<ImageRef>> = sides.iter().map(|(front, _, _)| front.clone()).collect();
        for ((name, m), (front, back, opacity)) in table.iter().zip(sides) {
            let back = match back.as_deref() {
                None | Some("same") => Back::Same,
                Some("black") => Back::Black,
                Some(other) => match materials.index.get(other) {
                    Some(&i) => Back::Other(Box::new(fronts[i as usize].clone())),
                    None => {
                        return Err(self.error(
                            Some(m.span()),
                            format!("materials.{name}.back"),
                            format!("is \"{other}\": give \"same\", \"black\" or the name of a material"),
                        ))
                    }
                },
            };
            let source = self.source(Some(m.span()), format!("materials.{name}"));
            materials.list.push(MaterialDesc { name: name.clone(), front, back, opacity, source });
        }
        Ok(materials)
    }

    /// A material's front family, the `back` it names and its opacity.
    fn material(&mut self, name: &str, m: &Spanned<MaterialSection>) -> Result<Sides, SceneError> {
        let s = m.span();
        let f = |x: &str| format!("materials.{name}.{x}");
        let (opacity, back) = match m.get_ref() {
            MaterialSection::Diffuse { opacity, back, .. }
            | MaterialSection::Mirror { opacity, back, .. }
            | MaterialSection::Conductor { opacity, back, .. }
            | MaterialSection::Dielectric { opacity, back, .. }
            | MaterialSection::ThinDielectric { opacity, back, .. }
            | MaterialSection::Plastic { opacity, back, .. }
            | MaterialSection::Principled { opacity, back, .. }
            | MaterialSection::Coating { opacity, back, .. } => (opacity, back),
        };
        let opacity = match opacity {
            Some(v) => Some(self.scalar_texture(v, &s, &f("opacity"), Some(1.0))?),
            None => None,
        };
        let surface = match m.get_ref() {
            MaterialSection::Diffuse { albedo, albedo_texture, .. } => {
                let reflectance =
                    match (albedo, albedo_texture) {
                        (Some(toml::Value::Table(_)), Some(_)) => return Err(self.error(
                            Some(s),
                            f("albedo_texture"),
                            "albedo_texture multiplies a constant albedo; with a texture table in albedo, give the \
                             file there (albedo = { bitmap = \"...\", factor = [r, g, b] })",
                        )),
                        (Some(a), None) => self.texture(a, &s, &f("albedo"), Some(1.0))?,
                        (a, Some(file)) => {
                            let factor = match a {
                                Some(a) => self.texture(a, &s, &f("albedo"), Some(1.0))?.constant().unwrap_or(Rgb::ONE),
                                None => Rgb::ONE,
                            };
                            let image = self.image(file, Some(s.clone()), &f("albedo_texture"), Encoding::Srgb)?;
                            let mut t = Texture::bitmap(image, factor);
                            // Integer images stay within [0, 1]; a float one (OpenEXR, HDR, PFM) may not.
                            self.check_max(&mut t, &s, &f("albedo_texture"), Some(1.0))?;
                            t
                        }
                        (None, None) => return Err(self.error(
                            Some(s),
                            f("albedo"),
                            "a diffuse material needs albedo = [r, g, b] or a texture (scenes/README.md, \"Textures\")",
                        )),
                    };
                Surface::Diffuse { reflectance }
            }
            MaterialSection::Mirror { reflectance, .. } => Surface::Conductor {
                fresnel: ConductorFresnel::Perfect,
                specular: Texture::Constant(self.colour(*reflectance, &s, &f("reflectance"), Some(1.0))?),
                roughness: None,
            },
            MaterialSection::Conductor {
                material,
                eta,
                k,
                specular_reflectance,
                alpha,
                alpha_u,
                alpha_v,
                distribution,
                ..
            } => {
                let fresnel = match (material, eta, k) {
                    (Some(_), Some(_), _) | (Some(_), _, Some(_)) => {
                        return Err(self.error(Some(s), f("material"), "give a named metal or eta and k, not both"))
                    }
                    (Some(metal), None, None) => ConductorFresnel::named(metal)
                        .map_err(|e| self.error(Some(s.clone()), f("material"), e.to_string()))?,
                    (None, Some(eta), Some(k)) => ConductorFresnel::Complex {
                        eta: self.constant_colour(eta, &s, &f("eta"))?,
                        k: self.constant_colour(k, &s, &f("k"))?,
                    },
                    (None, None, None) => ConductorFresnel::Perfect,
                    (None, _, _) => {
                        return Err(self.error(
                            Some(s),
                            f("eta"),
                            "a conductor given by its index needs both eta and k",
                        ))
                    }
                };
                let specular = self.texture_or(specular_reflectance, 1.0, &s, &f("specular_reflectance"))?;
                let roughness = self.roughness(alpha, alpha_u, alpha_v, distribution, &s, name)?;
                Surface::Conductor { fresnel, specular, roughness }
            }
            MaterialSection::Dielectric {
                ior,
                ext_ior,
                anti_reflection,
                abbe,
                ext_abbe,
                specular_reflectance,
                specular_transmittance,
                alpha,
                alpha_u,
                alpha_v,
                distribution,
                ..
            } => {
                let ior = self.scalar(*ior, &s, &f("ior"), |v| v > 0.0, "a positive index of refraction")?;
                let ext_ior =
                    self.scalar(*ext_ior, &s, &f("ext_ior"), |v| v > 0.0, "a positive index of refraction")?;
                let ior = self.refractive_index(ior, *abbe, &s, &f("abbe"))?;
                let ext_ior = self.refractive_index(ext_ior, *ext_abbe, &s, &f("ext_abbe"))?;
                match self.roughness(alpha, alpha_u, alpha_v, distribution, &s, name)? {
                    Some(roughness) => {
                        if *anti_reflection {
                            return Err(self.error(
                                Some(s),
                                f("anti_reflection"),
                                "the ideal anti-reflection coating is for smooth glass; a rough dielectric has none",
                            ));
                        }
                        Surface::RoughDielectric {
                            ior,
                            ext_ior,
                            roughness,
                            specular_reflectance: self.texture_or(
                                specular_reflectance,
                                1.0,
                                &s,
                                &f("specular_reflectance"),
                            )?,
                            specular_transmittance: self.texture_or(
                                specular_transmittance,
                                1.0,
                                &s,
                                &f("specular_transmittance"),
                            )?,
                        }
                    }
                    None => {
                        for (key, v) in [
                            ("specular_reflectance", specular_reflectance),
                            ("specular_transmittance", specular_transmittance),
                        ] {
                            if v.is_some() {
                                return Err(self.error(
                                    Some(s),
                                    f(key),
                                    "smooth glass reflects and refracts all it receives; give alpha for a rough \
                                     dielectric with these factors",
                                ));
                            }
                        }
                        Surface::Dielectric { ior, ext_ior, anti_reflection: *anti_reflection }
                    }
                }
            }
            MaterialSection::ThinDielectric { ior, ext_ior, specular_reflectance, specular_transmittance, .. } => {
                let ior = self.scalar(*ior, &s, &f("ior"), |v| v > 0.0, "a positive index of refraction")?;
                let ext_ior =
                    self.scalar(*ext_ior, &s, &f("ext_ior"), |v| v > 0.0, "a positive index of refraction")?;
                Surface::ThinDielectric {
                    ior: RefractiveIndex::constant(ior),
                    ext_ior: RefractiveIndex::constant(ext_ior),
                    specular_reflectance: self.texture_or(specular_reflectance, 1.0, &s, &f("specular_reflectance"))?,
                    specular_transmittance: self.texture_or(
                        specular_transmittance,
                        1.0,
                        &s,
                        &f("specular_transmittance"),
                    )?,
                }
            }
            MaterialSection::Plastic {
                diffuse_reflectance,
                specular_reflectance,
                ior,
                ext_ior,
                nonlinear,
                alpha,
                alpha_u,
                alpha_v,
                distribution,
                ..
            } => {
                // Mitsuba 3's defaults: polypropylene in air.
                let ior = self.scalar(ior.unwrap_or(1.49), &s, &f("ior"), |v| v > 0.0, "a positive index")?;
                let ext_ior =
                    self.scalar(ext_ior.unwrap_or(1.000_277), &s, &f("ext_ior"), |v| v > 0.0, "a positive index")?;
                let eta = ior / ext_ior;
                if alpha_u.is_some() || alpha_v.is_some() {
                    return Err(self.error(Some(s), f("alpha_u"), "a rough plastic's coat is isotropic: give alpha"));
                }
                let coat = match self.roughness(alpha, &None, &None, distribution, &s, name)? {
                    None => Coat::Smooth,
                    Some(r) => match r.alpha_u.constant() {
                        Some(a) => Coat::rough(r.distribution, a.x, eta),
                        None => {
                            return Err(self.error(
                                Some(s),
                                f("alpha"),
                                "a rough plastic's roughness is one number (its coat's table is computed for it)",
                            ))
                        }
                    },
                };
                Surface::Plastic {
                    diffuse_reflectance: self.texture_or(diffuse_reflectance, 0.5, &s, &f("diffuse_reflectance"))?,
                    specular_reflectance: self.texture_or(specular_reflectance, 1.0, &s, &f("specular_reflectance"))?,
                    eta,
                    nonlinear: *nonlinear,
                    coat,
                }
            }
            MaterialSection::Principled {
                base_color,
                roughness,
                anisotropic,
                metallic,
                spec_trans,
                specular,
                eta,
                spec_tint,
                sheen,
                sheen_tint,
                flatness,
                clearcoat,
                clearcoat_gloss,
                ..
            } => {
                let mut p = PrincipledSurface::default();
                if let Some(v) = base_color {
                    p.base_color = self.texture(v, &s, &f("base_color"), Some(1.0))?;
                }
                for (key, value, slot) in [
                    ("roughness", roughness, &mut p.roughness),
                    ("anisotropic", anisotropic, &mut p.anisotropic),
                    ("metallic", metallic, &mut p.metallic),
                    ("spec_trans", spec_trans, &mut p.spec_trans),
                    ("spec_tint", spec_tint, &mut p.spec_tint),
                    ("sheen", sheen, &mut p.sheen),
                    ("sheen_tint", sheen_tint, &mut p.sheen_tint),
                    ("flatness", flatness, &mut p.flatness),
                    ("clearcoat", clearcoat, &mut p.clearcoat),
                    ("clearcoat_gloss", clearcoat_gloss, &mut p.clearcoat_gloss),
                ] {
                    if let Some(v) = value {
                        *slot = self.scalar_texture(v, &s, &f(key), Some(1.0))?;
                    }
                }
                p.eta = match (specular, eta) {
                    (Some(_), Some(_)) => {
                        return Err(self.error(
                            Some(s),
                            f("eta"),
                            "give specular or eta, not both (eta follows from specular)",
                        ))
                    }
                    (Some(sp), None) => eta_of_specular(self.scalar(
                        *sp,
                        &s,
                        &f("specular"),
                        |v| (0.0..1.0).contains(&v),
                        "in [0, 1)",
                    )?),
                    (None, Some(e)) => self.scalar(*e, &s, &f("eta"), |v| v > 0.0, "a positive index")?,
                    (None, None) => p.eta,
                };
                Surface::Principled(Box::new(p))
            }
            MaterialSection::Coating { reflectance, transmittance, .. } => {
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
        };
        Ok((surface, back.clone(), opacity))
    }

    /// A colour parameter that defaults to the grey `default`: a reflectance, at most 1 everywhere.
    fn texture_or(
        &mut self,
        value: &Option<toml::Value>,
        default: f32,
        span: &Range<usize>,
        field: &str,
    ) -> Result<TextureDesc, SceneError> {
        match value {
            Some(v) => self.texture(v, span, field, Some(1.0)),
            None => Ok(Texture::grey(default)),
        }
    }

    /// A colour that must be a constant (a complex index's η or k).
    fn constant_colour(&mut self, value: &toml::Value, span: &Range<usize>, field: &str) -> Result<Rgb, SceneError> {
        let t = self.texture(value, span, field, None)?;
        t.constant().ok_or_else(|| self.error(Some(span.clone()), field, "must be a colour [r, g, b] or a number"))
    }

    /// A rough family's microfacet roughness, None for a smooth surface.
    fn roughness(
        &mut self,
        alpha: &Option<toml::Value>,
        alpha_u: &Option<toml::Value>,
        alpha_v: &Option<toml::Value>,
        distribution: &Option<String>,
        span: &Range<usize>,
        name: &str,
    ) -> Result<Option<Roughness<ImageRef>>, SceneError> {
        let f = |x: &str| format!("materials.{name}.{x}");
        let distribution = match distribution.as_deref() {
            None | Some("beckmann") => Distribution::Beckmann,
            Some("ggx") => Distribution::Ggx,
            Some(other) => {
                return Err(self.error(
                    Some(span.clone()),
                    f("distribution"),
                    format!("is \"{other}\": give \"beckmann\" or \"ggx\""),
                ))
            }
        };
        // Mitsuba keeps α away from 0, where a microfacet lobe becomes a delta it cannot sample.
        let alpha_of = |l: &mut Self, v: &toml::Value, key: &str| {
            let t = l.scalar_texture(v, span, &f(key), None)?;
            match t.constant() {
                Some(c) if c.x.is_nan() || c.x <= 0.0 => Err(l.error(
                    Some(span.clone()),
                    f(key),
                    "must be above 0 (leave the roughness out for a smooth surface)",
                )),
                _ => Ok(t),
            }
        };
        match (alpha, alpha_u, alpha_v) {
            (None, None, None) => {
                if distribution != Distribution::Beckmann {
                    return Err(self.error(
                        Some(span.clone()),
                        f("distribution"),
                        "needs alpha (or alpha_u and alpha_v)",
                    ));
                }
                Ok(None)
            }
            (Some(a), None, None) => {
                let a = alpha_of(self, a, "alpha")?;
                Ok(Some(Roughness { distribution, alpha_u: a.clone(), alpha_v: a }))
            }
            (None, Some(u), Some(v)) => Ok(Some(Roughness {
                distribution,
                alpha_u: alpha_of(self, u, "alpha_u")?,
                alpha_v: alpha_of(self, v, "alpha_v")?,
            })),
            _ => Err(self.error(Some(span.clone()), f("alpha"), "give alpha, or both alpha_u and alpha_v")),
        }
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
