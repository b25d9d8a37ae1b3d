//! Materials as a scene describes them: a BSDF family (`crate::bsdf`) whose parameters may be textured, which
//! side of the surface scatters, and an opacity for cut-outs. `Material::bsdf` resolves one at a surface point,
//! for a path arriving from a given side, into the `Bsdf` the path walk reads. Scene formats build these; the
//! estimators see only `Bsdf`.

use crate::bsdf::conductor::ConductorFresnel;
use crate::bsdf::microfacet::{Distribution, Microfacet};
use crate::bsdf::plastic::Coat;
use crate::bsdf::principled::PrincipledParams;
use crate::bsdf::{
    Bsdf, Coating, Conductor, Dielectric, Diffuse, LobeFlags, Model, Plastic, Principled, RoughDielectric,
    ThinDielectric,
};
use crate::color::Rgb;
use crate::geometry::SurfaceHit;
use crate::sampling::Frame;
use crate::spectrum::RefractiveIndex;
use crate::texture::{Bitmap, BitmapTexture, Texture};
use glam::{Vec2, Vec3};
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// A microfacet roughness that may vary over the surface: α along the shading frame's two tangents.
/// `I` is the image slot of its textures (see `crate::texture::BitmapTexture`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Roughness<I = Arc<Bitmap>> {
    pub distribution: Distribution,
    pub alpha_u: Texture<I>,
    pub alpha_v: Texture<I>,
}

impl<I: PartialEq> Roughness<I> {
    /// An isotropic roughness α everywhere.
    pub fn isotropic(distribution: Distribution, alpha: f32) -> Self {
        Roughness { distribution, alpha_u: Texture::grey(alpha), alpha_v: Texture::grey(alpha) }
    }

    fn varies(&self) -> bool {
        self.alpha_u.varies() || self.alpha_v.varies()
    }

    /// True when α may differ between the two tangents: the shading frame's orientation then matters.
    pub fn is_anisotropic(&self) -> bool {
        self.alpha_u != self.alpha_v
    }

    /// The same roughness with its textures' images turned by `f` (`Texture::try_map`).
    pub fn try_map<J, E>(&self, f: &mut impl FnMut(&BitmapTexture<I>) -> Result<J, E>) -> Result<Roughness<J>, E> {
        Ok(Roughness {
            distribution: self.distribution,
            alpha_u: self.alpha_u.try_map(f)?,
            alpha_v: self.alpha_v.try_map(f)?,
        })
    }
}

impl Roughness {
    /// The distribution at texture coordinates `uv`.
    #[inline]
    pub fn at(&self, uv: Vec2) -> Microfacet {
        Microfacet::new(self.distribution, self.alpha_u.eval_scalar(uv), self.alpha_v.eval_scalar(uv))
    }
}

/// The scattering family of one side of a surface, with its parameters; `I` is the image slot of its textures.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Surface<I = Arc<Bitmap>> {
    /// Lambertian reflection of `reflectance`.
    Diffuse { reflectance: Texture<I> },
    /// A metal: smooth, or rough with `roughness`; its Fresnel reflectance times `specular`.
    Conductor { fresnel: ConductorFresnel, specular: Texture<I>, roughness: Option<Roughness<I>> },
    /// A smooth interface with `ior` behind the surface normal and `ext_ior` in front of it.
    Dielectric { ior: RefractiveIndex, ext_ior: RefractiveIndex, anti_reflection: bool },
    /// A rough interface (Mitsuba's `roughdielectric`): `ior` behind the surface normal, `ext_ior` in front,
    /// factors on the reflected and the refracted light.
    RoughDielectric {
        ior: RefractiveIndex,
        ext_ior: RefractiveIndex,
        roughness: Roughness<I>,
        specular_reflectance: Texture<I>,
        specular_transmittance: Texture<I>,
    },
    /// A thin pane of index `ior` in `ext_ior` (Mitsuba's `thindielectric`), alike from both sides.
    ThinDielectric {
        ior: RefractiveIndex,
        ext_ior: RefractiveIndex,
        specular_reflectance: Texture<I>,
        specular_transmittance: Texture<I>,
    },
    /// A diffuse base under a smooth or rough dielectric coat of relative index `eta` (Mitsuba's `plastic`
    /// and `roughplastic`; `Coat::rough` computes a rough coat's table).
    Plastic { diffuse_reflectance: Texture<I>, specular_reflectance: Texture<I>, eta: f32, nonlinear: bool, coat: Coat },
    /// Mitsuba's `principled`.
    Principled(Box<PrincipledSurface<I>>),
    /// A thin partial reflector that transmits straight through.
    Coating { reflectance: Rgb, transmittance: Rgb },
}

/// The parameters of a principled surface, each a texture but the index and the sampling rates (as in
/// Mitsuba); `Default` gives Mitsuba's defaults.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PrincipledSurface<I = Arc<Bitmap>> {
    pub base_color: Texture<I>,
    pub roughness: Texture<I>,
    pub anisotropic: Texture<I>,
    pub metallic: Texture<I>,
    pub spec_trans: Texture<I>,
    /// Interior over exterior index (`crate::bsdf::principled::eta_of_specular` turns Mitsuba's `specular`
    /// into it).
    pub eta: f32,
    pub spec_tint: Texture<I>,
    pub sheen: Texture<I>,
    pub sheen_tint: Texture<I>,
    pub flatness: Texture<I>,
    pub clearcoat: Texture<I>,
    pub clearcoat_gloss: Texture<I>,
    pub diffuse_reflectance_sampling_rate: f32,
    pub main_specular_sampling_rate: f32,
    pub clearcoat_sampling_rate: f32,
}

impl<I> Default for PrincipledSurface<I> {
    fn default() -> Self {
        let d = PrincipledParams::default();
        PrincipledSurface {
            base_color: Texture::Constant(d.base_color),
            roughness: Texture::grey(d.roughness),
            anisotropic: Texture::grey(d.anisotropic),
            metallic: Texture::grey(d.metallic),
            spec_trans: Texture::grey(d.spec_trans),
            eta: d.eta,
            spec_tint: Texture::grey(d.spec_tint),
            sheen: Texture::grey(d.sheen),
            sheen_tint: Texture::grey(d.sheen_tint),
            flatness: Texture::grey(d.flatness),
            clearcoat: Texture::grey(d.clearcoat),
            clearcoat_gloss: Texture::grey(d.clearcoat_gloss),
            diffuse_reflectance_sampling_rate: d.diffuse_reflectance_sampling_rate,
            main_specular_sampling_rate: d.main_specular_sampling_rate,
            clearcoat_sampling_rate: d.clearcoat_sampling_rate,
        }
    }
}

impl<I> PrincipledSurface<I> {
    fn textures(&self) -> [&Texture<I>; 11] {
        [
            &self.base_color,
            &self.roughness,
            &self.anisotropic,
            &self.metallic,
            &self.spec_trans,
            &self.spec_tint,
            &self.sheen,
            &self.sheen_tint,
            &self.flatness,
            &self.clearcoat,
            &self.clearcoat_gloss,
        ]
    }

    /// The same parameters with their textures' images turned by `f` (`Texture::try_map`).
    pub fn try_map<J, E>(
        &self,
        f: &mut impl FnMut(&BitmapTexture<I>) -> Result<J, E>,
    ) -> Result<PrincipledSurface<J>, E> {
        Ok(PrincipledSurface {
            base_color: self.base_color.try_map(f)?,
            roughness: self.roughness.try_map(f)?,
            anisotropic: self.anisotropic.try_map(f)?,
            metallic: self.metallic.try_map(f)?,
            spec_trans: self.spec_trans.try_map(f)?,
            eta: self.eta,
            spec_tint: self.spec_tint.try_map(f)?,
            sheen: self.sheen.try_map(f)?,
            sheen_tint: self.sheen_tint.try_map(f)?,
            flatness: self.flatness.try_map(f)?,
            clearcoat: self.clearcoat.try_map(f)?,
            clearcoat_gloss: self.clearcoat_gloss.try_map(f)?,
            diffuse_reflectance_sampling_rate: self.diffuse_reflectance_sampling_rate,
            main_specular_sampling_rate: self.main_specular_sampling_rate,
            clearcoat_sampling_rate: self.clearcoat_sampling_rate,
        })
    }
}

impl PrincipledSurface {
    /// The parameters at texture coordinates `uv`.
    #[inline]
    pub fn at(&self, uv: Vec2) -> PrincipledParams {
        PrincipledParams {
            base_color: self.base_color.eval(uv),
            roughness: self.roughness.eval_scalar(uv),
            anisotropic: self.anisotropic.eval_scalar(uv),
            metallic: self.metallic.eval_scalar(uv),
            spec_trans: self.spec_trans.eval_scalar(uv),
            eta: self.eta,
            spec_tint: self.spec_tint.eval_scalar(uv),
            sheen: self.sheen.eval_scalar(uv),
            sheen_tint: self.sheen_tint.eval_scalar(uv),
            flatness: self.flatness.eval_scalar(uv),
            clearcoat: self.clearcoat.eval_scalar(uv),
            clearcoat_gloss: self.clearcoat_gloss.eval_scalar(uv),
            diffuse_reflectance_sampling_rate: self.diffuse_reflectance_sampling_rate,
            main_specular_sampling_rate: self.main_specular_sampling_rate,
            clearcoat_sampling_rate: self.clearcoat_sampling_rate,
        }
    }

    /// True when some point may transmit: the surface is then an interface with an inside.
    fn transmits(&self) -> bool {
        self.spec_trans.varies() || self.spec_trans.eval_scalar(Vec2::ZERO) > 0.0
    }
}

impl<I: PartialEq> Surface<I> {
    /// True when a parameter depends on texture coordinates.
    pub fn varies(&self) -> bool {
        match self {
            Surface::Diffuse { reflectance } => reflectance.varies(),
            Surface::Conductor { specular, roughness, .. } => {
                specular.varies() || roughness.as_ref().is_some_and(Roughness::varies)
            }
            Surface::RoughDielectric { roughness, specular_reflectance, specular_transmittance, .. } => {
                roughness.varies() || specular_reflectance.varies() || specular_transmittance.varies()
            }
            Surface::ThinDielectric { specular_reflectance, specular_transmittance, .. } => {
                specular_reflectance.varies() || specular_transmittance.varies()
            }
            Surface::Plastic { diffuse_reflectance, specular_reflectance, .. } => {
                diffuse_reflectance.varies() || specular_reflectance.varies()
            }
            Surface::Principled(p) => p.textures().iter().any(|t| t.varies()),
            Surface::Dielectric { .. } | Surface::Coating { .. } => false,
        }
    }

    /// The same family with its textures' images turned by `f` (`Texture::try_map`).
    pub fn try_map<J, E>(&self, f: &mut impl FnMut(&BitmapTexture<I>) -> Result<J, E>) -> Result<Surface<J>, E> {
        Ok(match self {
            Surface::Diffuse { reflectance } => Surface::Diffuse { reflectance: reflectance.try_map(f)? },
            Surface::Conductor { fresnel, specular, roughness } => Surface::Conductor {
                fresnel: *fresnel,
                specular: specular.try_map(f)?,
                roughness: match roughness {
                    Some(r) => Some(r.try_map(f)?),
                    None => None,
                },
            },
            &Surface::Dielectric { ior, ext_ior, anti_reflection } => {
                Surface::Dielectric { ior, ext_ior, anti_reflection }
            }
            Surface::RoughDielectric { ior, ext_ior, roughness, specular_reflectance, specular_transmittance } => {
                Surface::RoughDielectric {
                    ior: *ior,
                    ext_ior: *ext_ior,
                    roughness: roughness.try_map(f)?,
                    specular_reflectance: specular_reflectance.try_map(f)?,
                    specular_transmittance: specular_transmittance.try_map(f)?,
                }
            }
            Surface::ThinDielectric { ior, ext_ior, specular_reflectance, specular_transmittance } => {
                Surface::ThinDielectric {
                    ior: *ior,
                    ext_ior: *ext_ior,
                    specular_reflectance: specular_reflectance.try_map(f)?,
                    specular_transmittance: specular_transmittance.try_map(f)?,
                }
            }
            Surface::Plastic { diffuse_reflectance, specular_reflectance, eta, nonlinear, coat } => Surface::Plastic {
                diffuse_reflectance: diffuse_reflectance.try_map(f)?,
                specular_reflectance: specular_reflectance.try_map(f)?,
                eta: *eta,
                nonlinear: *nonlinear,
                coat: *coat,
            },
            Surface::Principled(p) => Surface::Principled(Box::new(p.try_map(f)?)),
            &Surface::Coating { reflectance, transmittance } => Surface::Coating { reflectance, transmittance },
        })
    }
}

impl Surface {
    /// True when the family reads the direction of the shading frame's tangent (anisotropic roughness), which
    /// the surface must then supply. A family with an anisotropic parameter answers here.
    fn needs_tangent(&self) -> bool {
        match self {
            Surface::Conductor { roughness: Some(r), .. } => r.is_anisotropic(),
            _ => false,
        }
    }

    /// True for the families that are an interface between two media, which scatter from both sides by
    /// their nature and tell the sides apart by their indices.
    fn is_interface(&self) -> bool {
        match self {
            Surface::Dielectric { .. } | Surface::RoughDielectric { .. } | Surface::ThinDielectric { .. } => true,
            Surface::Principled(p) => p.transmits(),
            _ => false,
        }
    }

    /// True when the family's behaviour depends on wavelength (a dispersive index).
    fn is_dispersive(&self) -> bool {
        match self {
            Surface::Dielectric { ior, ext_ior, .. }
            | Surface::RoughDielectric { ior, ext_ior, .. }
            | Surface::ThinDielectric { ior, ext_ior, .. } => ior.is_dispersive() || ext_ior.is_dispersive(),
            _ => false,
        }
    }

    /// The family at texture coordinates `uv`, seen from the front of the surface or from its back.
    #[inline(always)]
    fn resolve(&self, uv: Vec2, front: bool) -> Model {
        match self {
            Surface::Diffuse { reflectance } => Model::Diffuse(Diffuse { reflectance: reflectance.eval(uv) }),
            Surface::Conductor { fresnel, specular, roughness } => Model::Conductor(Conductor {
                fresnel: *fresnel,
                specular: specular.eval(uv),
                roughness: roughness.as_ref().map(|r| r.at(uv)),
            }),
            &Surface::Dielectric { ior, ext_ior, anti_reflection } => {
                let (eta_o, eta_t) = if front { (ext_ior, ior) } else { (ior, ext_ior) };
                Model::Dielectric(Dielectric { eta_o, eta_t, anti_reflection })
            }
            Surface::RoughDielectric { ior, ext_ior, roughness, specular_reflectance, specular_transmittance } => {
                let (eta_o, eta_t) = if front { (*ext_ior, *ior) } else { (*ior, *ext_ior) };
                Model::RoughDielectric(RoughDielectric {
                    eta_o,
                    eta_t,
                    microfacet: roughness.at(uv),
                    specular_reflectance: specular_reflectance.eval(uv),
                    specular_transmittance: specular_transmittance.eval(uv),
                })
            }
            Surface::ThinDielectric { ior, ext_ior, specular_reflectance, specular_transmittance } => {
                Model::ThinDielectric(ThinDielectric {
                    int_ior: *ior,
                    ext_ior: *ext_ior,
                    specular_reflectance: specular_reflectance.eval(uv),
                    specular_transmittance: specular_transmittance.eval(uv),
                })
            }
            Surface::Plastic { diffuse_reflectance, specular_reflectance, eta, nonlinear, coat } => Model::Plastic(
                Plastic::new(diffuse_reflectance.eval(uv), specular_reflectance.eval(uv), *eta, *nonlinear, *coat),
            ),
            Surface::Principled(p) => Model::Principled(Principled::new(&p.at(uv), !front)),
            &Surface::Coating { reflectance, transmittance } => Model::Coating(Coating { reflectance, transmittance }),
        }
    }

    /// The lobes the family has at its parameters' first values (textures read at (0, 0)), for checks that
    /// need no surface point.
    fn flags(&self) -> LobeFlags {
        self.resolve(Vec2::ZERO, true).flags()
    }
}

/// What the back of a surface does (the side its geometric normal points away from).
/// `I` is the image slot of its textures.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Back<I = Arc<Bitmap>> {
    /// Absorbs: a one-sided surface, as Mitsuba's BSDFs are unless wrapped in `twosided`.
    Black,
    /// Scatters as the front does.
    Same,
    /// Scatters with another family.
    Other(Box<Surface<I>>),
}

impl<I: PartialEq> Back<I> {
    /// The same back with its textures' images turned by `f` (`Texture::try_map`).
    pub fn try_map<J, E>(&self, f: &mut impl FnMut(&BitmapTexture<I>) -> Result<J, E>) -> Result<Back<J>, E> {
        Ok(match self {
            Back::Black => Back::Black,
            Back::Same => Back::Same,
            Back::Other(s) => Back::Other(Box::new(s.try_map(f)?)),
        })
    }
}

/// A material: its front's family, its back, and its opacity (a cut-out's holes let light straight through).
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    pub front: Surface,
    pub back: Back,
    /// The probability that the surface is there, 1 where None.
    pub opacity: Option<Texture>,
    uses_uv: bool,
    needs_tangent: bool,
    has_delta: bool,
}

impl Material {
    /// A material of `front` and `back` with an optional opacity.
    pub fn new(front: Surface, back: Back, opacity: Option<Texture>) -> Self {
        let (back_varies, back_tangent) = match &back {
            Back::Other(s) => (s.varies(), s.needs_tangent()),
            _ => (false, false),
        };
        let uses_uv = front.varies() || back_varies || opacity.as_ref().is_some_and(Texture::varies);
        let needs_tangent = front.needs_tangent() || back_tangent;
        let back_delta = match &back {
            Back::Other(s) => s.flags().is_specular(),
            _ => false,
        };
        let has_delta = front.flags().is_specular() || back_delta || opacity.is_some();
        Material { front, back, opacity, uses_uv, needs_tangent, has_delta }
    }

    /// A material that scatters alike from both sides (every family of photonfarm's own scene format).
    pub fn two_sided(surface: Surface) -> Self {
        Material::new(surface, Back::Same, None)
    }

    /// True when a parameter depends on texture coordinates, which a surface point must then supply.
    #[inline]
    pub fn uses_uv(&self) -> bool {
        self.uses_uv
    }

    /// True when the BSDF depends on the direction of the surface's tangent (anisotropic roughness): a surface
    /// point must then supply ∂p/∂u ([`Material::bsdf_with_tangent`]).
    #[inline]
    pub fn needs_tangent(&self) -> bool {
        self.needs_tangent
    }

    /// True for a smooth dielectric interface, where ghosts reflect.
    pub fn is_dielectric(&self) -> bool {
        matches!(self.front, Surface::Dielectric { .. })
    }

    /// True when the material's behaviour depends on wavelength: a scene with one renders spectrally.
    pub fn is_dispersive(&self) -> bool {
        let back = match &self.back {
            Back::Other(s) => s.is_dispersive(),
            _ => false,
        };
        self.front.is_dispersive() || back
    }

    /// True when some side has a delta lobe (then caustics exist), or the surface is partly cut out.
    #[inline]
    pub fn has_delta(&self) -> bool {
        self.has_delta
    }

    /// The BSDF at `hit` (texture coordinates `uv`) for a path arriving from `wo`: the side `wo` lies on, by
    /// the geometric normal, chooses the family, and the frame is turned to that side. The frame's tangents are
    /// those `Frame::from_normal` picks (Mitsuba's `coordinate_system`).
    #[inline(always)]
    pub fn bsdf(&self, hit: &SurfaceHit, uv: Vec2, wo: Vec3) -> Bsdf {
        self.bsdf_in_frame(hit, uv, None, wo)
    }

    /// The BSDF as [`Material::bsdf`] gives it, with the shading frame's first tangent along `tangent` (∂p/∂u,
    /// made perpendicular to the shading normal), as Mitsuba orients anisotropic materials.
    #[inline]
    pub fn bsdf_with_tangent(&self, hit: &SurfaceHit, uv: Vec2, tangent: Vec3, wo: Vec3) -> Bsdf {
        self.bsdf_in_frame(hit, uv, Some(tangent), wo)
    }

    #[inline(always)]
    fn bsdf_in_frame(&self, hit: &SurfaceHit, uv: Vec2, tangent: Option<Vec3>, wo: Vec3) -> Bsdf {
        let front = wo.dot(hit.ng) >= 0.0;
        let (ng, ns) = if front { (hit.ng, hit.ns) } else { (-hit.ng, -hit.ns) };
        let surface = match (&self.back, front) {
            _ if front || self.front.is_interface() => &self.front,
            (Back::Same, _) => &self.front,
            (Back::Other(s), _) => s,
            (Back::Black, _) => return Bsdf::new(Model::Black, Frame::from_normal(ns), ng, 1.0),
        };
        let opacity = self.opacity.as_ref().map_or(1.0, |t| t.eval_scalar(uv).clamp(0.0, 1.0));
        let frame = match tangent {
            Some(t) => Frame::from_normal_tangent(ns, t),
            None => Frame::from_normal(ns),
        };
        Bsdf::new(surface.resolve(uv, front), frame, ng, opacity)
    }
}
