//! BSDF plugins mapped to photonfarm's materials, which follow Mitsuba 3's plugins and defaults
//! (docs/materials.md): `diffuse`, `conductor`, `roughconductor`, `dielectric`, `roughdielectric`,
//! `thindielectric`, `plastic`, `roughplastic`, `principled`, wrapped in `twosided` (both sides; Mitsuba's BSDFs
//! are otherwise one-sided, `Back::Black`) and `mask` (the opacity). Other BSDFs are refused.

use super::params::{uniform, Params};
use super::{rgb, source, Importer};
use crate::bsdf::conductor::ConductorFresnel;
use crate::bsdf::microfacet::Distribution;
use crate::bsdf::plastic::Coat;
use crate::bsdf::principled::eta_of_specular;
use crate::material::{Back, PrincipledSurface, Roughness, Surface};
use crate::scene::description::{ImageRef, MaterialDesc, TextureDesc};
use crate::scene::mitsuba::{Category, MitsubaError, Plugin, SourcePos, SpectrumUse, Value};
use crate::spectrum::RefractiveIndex;
use crate::texture::Texture;
use std::sync::Arc;

/// Mitsuba's named indices of refraction (its `ior.h`), for `int_ior` and `ext_ior` given as strings.
const NAMED_IORS: &[(&str, f64)] = &[
    ("vacuum", 1.0),
    ("helium", 1.000036),
    ("hydrogen", 1.000132),
    ("air", 1.000277),
    ("carbon dioxide", 1.00045),
    ("water", 1.333),
    ("acetone", 1.36),
    ("ethanol", 1.361),
    ("carbon tetrachloride", 1.461),
    ("glycerol", 1.4729),
    ("benzene", 1.501),
    ("silicone oil", 1.52045),
    ("bromine", 1.661),
    ("water ice", 1.31),
    ("fused quartz", 1.458),
    ("pyrex", 1.47),
    ("acrylic glass", 1.49),
    ("polypropylene", 1.49),
    ("bk7", 1.5046),
    ("sodium chloride", 1.544),
    ("amber", 1.55),
    ("pet", 1.575),
    ("diamond", 2.419),
];

/// Mitsuba's roughness when a rough family is given none.
const DEFAULT_ALPHA: f64 = 0.1;

impl Importer<'_> {
    /// The material of a BSDF plugin, mapped once however many shapes reference it.
    pub(super) fn material(&mut self, bsdf: &Arc<Plugin>) -> Result<u32, MitsubaError> {
        let key = Arc::as_ptr(bsdf);
        if let Some(&m) = self.material_of.get(&key) {
            return Ok(m);
        }
        let material = self.wrapped(bsdf)?;
        let index = self.materials.len() as u32;
        self.materials.push(material);
        self.material_of.insert(key, index);
        Ok(index)
    }

    /// The diffuse BSDF Mitsuba gives a shape that names none.
    pub(super) fn default_material(&mut self) -> u32 {
        let index = self.materials.len() as u32;
        self.materials.push(MaterialDesc {
            name: "the default diffuse BSDF".into(),
            front: Surface::Diffuse { reflectance: Texture::grey(0.5) },
            back: Back::Black,
            opacity: None,
            source: source(&SourcePos::file_start(&self.doc.path), "<bsdf type=\"diffuse\">"),
        });
        index
    }

    /// A BSDF with its wrappers: `mask` gives the opacity, `twosided` the back.
    fn wrapped(&mut self, bsdf: &Plugin) -> Result<MaterialDesc, MitsubaError> {
        let p = Params::new(bsdf);
        let material = |front, back, opacity| MaterialDesc {
            name: bsdf.id.clone().unwrap_or_else(|| bsdf.element()),
            front,
            back,
            opacity,
            source: source(&bsdf.position, bsdf.element()),
        };
        let material = match bsdf.kind.as_str() {
            "mask" => {
                let opacity = self.texture_param(&p, "opacity", SpectrumUse::Reflectance, Some(1.0))?;
                let opacity = opacity.unwrap_or(Texture::grey(0.5));
                let inner = single_bsdf(&p)?;
                let inner = self.wrapped(&inner)?;
                if inner.opacity.is_some() {
                    return Err(p.error("a mask inside a mask is not supported"));
                }
                material(inner.front, inner.back, Some(opacity))
            }
            "twosided" => {
                let sides = p.children_of(Category::Bsdf);
                let front = sides.first().ok_or_else(|| p.error("a twosided holds one or two BSDFs"))?;
                if sides.len() > 2 {
                    return Err(p.error("a twosided holds one or two BSDFs"));
                }
                let front_surface = self.surface(&front.plugin)?;
                let back = match sides.get(1) {
                    None => Back::Same,
                    Some(back) => Back::Other(Box::new(self.surface(&back.plugin)?)),
                };
                material(front_surface, back, None)
            }
            "bumpmap" | "normalmap" => {
                let inner = self.unperturbed(&p)?;
                return self.wrapped(&inner);
            }
            // A family reads and checks its own parameters.
            _ => return Ok(material(self.surface(bsdf)?, Back::Black, None)),
        };
        p.finish()?;
        Ok(material)
    }

    /// A BSDF family (no wrapper).
    fn surface(&mut self, bsdf: &Plugin) -> Result<Surface<ImageRef>, MitsubaError> {
        let p = Params::new(bsdf);
        if bsdf.category != Category::Bsdf {
            return Err(p.error(format!("{} is not a BSDF", bsdf.element())));
        }
        let surface = match bsdf.kind.as_str() {
            "diffuse" => Surface::Diffuse { reflectance: self.texture_or(&p, "reflectance", 0.5, Some(1.0))? },
            "conductor" | "roughconductor" => {
                let fresnel = self.conductor_fresnel(&p)?;
                let specular = self.texture_or(&p, "specular_reflectance", 1.0, Some(1.0))?;
                let roughness = if bsdf.kind == "roughconductor" { Some(self.roughness(&p, true)?) } else { None };
                Surface::Conductor { fresnel, specular, roughness }
            }
            "dielectric" | "roughdielectric" => {
                let (ior, ext_ior) = indices(&p)?;
                if bsdf.kind == "roughdielectric" {
                    Surface::RoughDielectric {
                        ior,
                        ext_ior,
                        roughness: self.roughness(&p, true)?,
                        specular_reflectance: self.texture_or(&p, "specular_reflectance", 1.0, Some(1.0))?,
                        specular_transmittance: self.texture_or(&p, "specular_transmittance", 1.0, Some(1.0))?,
                    }
                } else {
                    for name in ["specular_reflectance", "specular_transmittance"] {
                        let t = self.texture_param(&p, name, SpectrumUse::Reflectance, Some(1.0))?;
                        if t.is_some_and(|t| t != Texture::grey(1.0)) {
                            return Err(p.error(format!(
                                "{name} other than 1 on a smooth dielectric is not supported (photonfarm's smooth glass \
                                 reflects and refracts all it receives)"
                            )));
                        }
                    }
                    Surface::Dielectric { ior, ext_ior, anti_reflection: false }
                }
            }
            "thindielectric" => Surface::ThinDielectric {
                ior: indices(&p)?.0,
                ext_ior: indices(&p)?.1,
                specular_reflectance: self.texture_or(&p, "specular_reflectance", 1.0, Some(1.0))?,
                specular_transmittance: self.texture_or(&p, "specular_transmittance", 1.0, Some(1.0))?,
            },
            "plastic" | "roughplastic" => {
                let eta = (ior(&p, "int_ior", 1.49)? / ior(&p, "ext_ior", 1.000277)?) as f32;
                let coat = if bsdf.kind == "roughplastic" {
                    let r = self.roughness(&p, false)?;
                    match r.alpha_u.constant() {
                        Some(a) => Coat::rough(r.distribution, a.x, eta),
                        None => return Err(p.error("a roughplastic's alpha must be one number, not a texture")),
                    }
                } else {
                    Coat::Smooth
                };
                Surface::Plastic {
                    diffuse_reflectance: self.texture_or(&p, "diffuse_reflectance", 0.5, Some(1.0))?,
                    specular_reflectance: self.texture_or(&p, "specular_reflectance", 1.0, Some(1.0))?,
                    eta,
                    nonlinear: p.boolean("nonlinear", false)?,
                    coat,
                }
            }
            "principled" => self.principled(&p)?,
            "bumpmap" | "normalmap" => {
                let inner = self.unperturbed(&p)?;
                return self.surface(&inner);
            }
            "twosided" | "mask" => {
                return Err(p.error(format!("a `{}` is not supported at this depth of nesting", bsdf.kind)))
            }
            other => {
                let refusal = p.error(format!(
                    "the BSDF `{other}` has no counterpart in photonfarm (diffuse, conductor, roughconductor, \
                     dielectric, roughdielectric, thindielectric, plastic, roughplastic, principled, twosided and mask \
                     do)"
                ));
                self.approximate(refusal, "as Mitsuba's default BSDF, diffuse of reflectance 0.5")?;
                return Ok(Surface::Diffuse { reflectance: Texture::grey(0.5) });
            }
        };
        p.finish()?;
        Ok(surface)
    }

    /// A conductor's Fresnel term: a named metal (`material`), `eta` and `k`, or Mitsuba's default, a perfect
    /// mirror (`material="none"`).
    fn conductor_fresnel(&mut self, p: &Params) -> Result<ConductorFresnel, MitsubaError> {
        let material = p.string("material")?;
        let eta = p.colour("eta", SpectrumUse::Unbounded)?;
        let k = p.colour("k", SpectrumUse::Unbounded)?;
        if p.child("eta").is_some() || p.child("k").is_some() {
            return Err(p.error("a textured eta or k is not supported: give a colour or a spectrum"));
        }
        match (material, eta, k) {
            (Some(_), Some(_), _) | (Some(_), _, Some(_)) => Err(p.error("give material or eta and k, not both")),
            (Some(name), None, None) => ConductorFresnel::named(name).map_err(|e| p.error(e.to_string())),
            (None, Some(eta), Some(k)) => Ok(ConductorFresnel::Complex { eta: rgb(eta), k: rgb(k) }),
            (None, None, None) => Ok(ConductorFresnel::Perfect),
            _ => Err(p.error("a conductor given by its index needs both eta and k")),
        }
    }

    /// A rough family's `distribution` and `alpha` (or `alpha_u` and `alpha_v` where `anisotropic` ones exist).
    fn roughness(&mut self, p: &Params, anisotropic: bool) -> Result<Roughness<ImageRef>, MitsubaError> {
        let distribution = match p.string("distribution")?.unwrap_or("beckmann") {
            "beckmann" => Distribution::Beckmann,
            "ggx" => Distribution::Ggx,
            other => return Err(p.error(format!("distribution \"{other}\" is not beckmann or ggx"))),
        };
        // Mitsuba's visible-normal sampling changes how the lobe is sampled, not the image.
        p.ignore(&["sample_visible"]);
        let alpha = |l: &mut Self, name: &str| -> Result<Option<TextureDesc>, MitsubaError> {
            let t = l.texture_param(p, name, SpectrumUse::Reflectance, None)?;
            if let Some(c) = t.as_ref().and_then(Texture::constant) {
                if c.x.is_nan() || c.x <= 0.0 {
                    return Err(p.error(format!("{name} must be above 0, got {}", c.x)));
                }
            }
            Ok(t)
        };
        let a = alpha(self, "alpha")?;
        let (u, v) = if anisotropic { (alpha(self, "alpha_u")?, alpha(self, "alpha_v")?) } else { (None, None) };
        let (alpha_u, alpha_v) = match (a, u, v) {
            (Some(a), None, None) => (a.clone(), a),
            (None, Some(u), Some(v)) => (u, v),
            (None, None, None) => (Texture::grey(DEFAULT_ALPHA as f32), Texture::grey(DEFAULT_ALPHA as f32)),
            _ => return Err(p.error("give alpha, or both alpha_u and alpha_v")),
        };
        Ok(Roughness { distribution, alpha_u, alpha_v })
    }

    /// Mitsuba's `principled`, parameter by parameter.
    fn principled(&mut self, p: &Params) -> Result<Surface<ImageRef>, MitsubaError> {
        let mut s = PrincipledSurface::default();
        if let Some(t) = self.texture_param(p, "base_color", SpectrumUse::Reflectance, Some(1.0))? {
            s.base_color = t;
        }
        for (name, slot) in [
            ("roughness", &mut s.roughness),
            ("anisotropic", &mut s.anisotropic),
            ("metallic", &mut s.metallic),
            ("spec_trans", &mut s.spec_trans),
            ("spec_tint", &mut s.spec_tint),
            ("sheen", &mut s.sheen),
            ("sheen_tint", &mut s.sheen_tint),
            ("flatness", &mut s.flatness),
            ("clearcoat", &mut s.clearcoat),
            ("clearcoat_gloss", &mut s.clearcoat_gloss),
        ] {
            if let Some(t) = self.texture_param(p, name, SpectrumUse::Reflectance, Some(1.0))? {
                *slot = t;
            }
        }
        for (name, slot) in [
            ("diffuse_reflectance_sampling_rate", &mut s.diffuse_reflectance_sampling_rate),
            ("main_specular_sampling_rate", &mut s.main_specular_sampling_rate),
            ("clearcoat_sampling_rate", &mut s.clearcoat_sampling_rate),
        ] {
            if let Some(x) = p.float(name)? {
                *slot = x as f32;
            }
        }
        let specular = p.float("specular")?;
        let eta = p.float("eta")?;
        s.eta = match (specular, eta) {
            (Some(_), Some(_)) => return Err(p.error("give specular or eta, not both")),
            (Some(sp), None) if (0.0..1.0).contains(&sp) => eta_of_specular(sp as f32),
            (Some(sp), None) => return Err(p.error(format!("specular must be in [0, 1), got {sp}"))),
            (None, Some(e)) if e > 0.0 => e as f32,
            (None, Some(e)) => return Err(p.error(format!("eta must be positive, got {e}"))),
            (None, None) => s.eta,
        };
        Ok(Surface::Principled(Box::new(s)))
    }
}

/// The one BSDF a wrapper holds.
fn single_bsdf(p: &Params) -> Result<Arc<Plugin>, MitsubaError> {
    let inner = p.children_of(Category::Bsdf);
    match inner.as_slice() {
        [one] => Ok(one.plugin.clone()),
        _ => Err(p.error(format!("{} holds exactly one BSDF, found {}", p.plugin.element(), inner.len()))),
    }
}

impl Importer<'_> {
    /// The BSDF inside a `bumpmap` or `normalmap`, which `--approximate` renders with the geometry's own normals;
    /// refused otherwise.
    fn unperturbed(&mut self, p: &Params) -> Result<Arc<Plugin>, MitsubaError> {
        let refusal = p.error(format!(
            "`{}` is not supported: photonfarm shades with the geometry's own normals (remove the wrapper to render \
             the BSDF inside it without the perturbed normals)",
            p.plugin.kind
        ));
        self.approximate(refusal, "as the BSDF inside it, with the geometry's own normals")?;
        single_bsdf(p)
    }
}

/// A dielectric's `int_ior` and `ext_ior`, Mitsuba's BK7 in air by default.
fn indices(p: &Params) -> Result<(RefractiveIndex, RefractiveIndex), MitsubaError> {
    let constant = |x: f64| RefractiveIndex::constant(x as f32);
    Ok((constant(ior(p, "int_ior", 1.5046)?), constant(ior(p, "ext_ior", 1.000277)?)))
}

/// An index of refraction given as a number or one of Mitsuba's names.
fn ior(p: &Params, name: &str, default: f64) -> Result<f64, MitsubaError> {
    let Some(param) = p.get(name) else { return Ok(default) };
    let value = match &param.value {
        Value::String(s) => NAMED_IORS.iter().find(|(n, _)| n == s).map(|(_, v)| *v).ok_or_else(|| {
            let names: Vec<&str> = NAMED_IORS.iter().map(|(n, _)| *n).collect();
            p.error_at(param, format!("\"{s}\" is not one of Mitsuba's named indices ({})", names.join(", ")))
        })?,
        v => uniform(v).ok_or_else(|| p.error_at(param, "must be a number or a named index such as \"bk7\""))?,
    };
    if !(value > 0.0 && value.is_finite()) {
        return Err(p.error_at(param, format!("must be a positive index, got {value}")));
    }
    Ok(value)
}
