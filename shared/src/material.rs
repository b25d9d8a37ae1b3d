//! Materials as a scene describes them: a BSDF family (`crate::bsdf`) whose parameters may be textured, which
//! side of the surface scatters, and an opacity for cut-outs. `Material::bsdf` resolves one at a surface point,
//! for a path arriving from a given side, into the `Bsdf` the path walk reads. Scene formats build these; the
//! estimators see only `Bsdf`.

use crate::bsdf::conductor::ConductorFresnel;
use crate::bsdf::microfacet::{Distribution, Microfacet};
use crate::bsdf::{Bsdf, Coating, Conductor, Dielectric, Diffuse, LobeFlags, Model};
use crate::color::Rgb;
use crate::geometry::SurfaceHit;
use crate::sampling::Frame;
use crate::spectrum::RefractiveIndex;
use crate::texture::Texture;
use glam::{Vec2, Vec3};

/// A microfacet roughness that may vary over the surface: α along the shading frame's two tangents.
#[derive(Clone, Debug, PartialEq)]
pub struct Roughness {
    pub distribution: Distribution,
    pub alpha_u: Texture,
    pub alpha_v: Texture,
}

impl Roughness {
    /// An isotropic roughness α everywhere.
    pub fn isotropic(distribution: Distribution, alpha: f32) -> Self {
        Roughness { distribution, alpha_u: Texture::grey(alpha), alpha_v: Texture::grey(alpha) }
    }

    /// The distribution at texture coordinates `uv`.
    #[inline]
    pub fn at(&self, uv: Vec2) -> Microfacet {
        Microfacet::new(self.distribution, self.alpha_u.eval_scalar(uv), self.alpha_v.eval_scalar(uv))
    }

    fn varies(&self) -> bool {
        self.alpha_u.varies() || self.alpha_v.varies()
    }
}

/// The scattering family of one side of a surface, with its parameters.
#[derive(Clone, Debug, PartialEq)]
pub enum Surface {
    /// Lambertian reflection of `reflectance`.
    Diffuse { reflectance: Texture },
    /// A metal: smooth, or rough with `roughness`; its Fresnel reflectance times `specular`.
    Conductor { fresnel: ConductorFresnel, specular: Texture, roughness: Option<Roughness> },
    /// A smooth interface with `ior` behind the surface normal and `ext_ior` in front of it.
    Dielectric { ior: RefractiveIndex, ext_ior: RefractiveIndex, anti_reflection: bool },
    /// A thin partial reflector that transmits straight through.
    Coating { reflectance: Rgb, transmittance: Rgb },
}

impl Surface {
    /// True when a parameter depends on texture coordinates.
    fn varies(&self) -> bool {
        match self {
            Surface::Diffuse { reflectance } => reflectance.varies(),
            Surface::Conductor { specular, roughness, .. } => {
                specular.varies() || roughness.as_ref().is_some_and(Roughness::varies)
            }
            Surface::Dielectric { .. } | Surface::Coating { .. } => false,
        }
    }

    /// True for the families that are an interface between two media, which scatter from both sides by
    /// their nature and tell the sides apart by their indices.
    fn is_interface(&self) -> bool {
        matches!(self, Surface::Dielectric { .. })
    }

    /// The family at texture coordinates `uv`, seen from the front of the surface or from its back.
    #[inline]
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
#[derive(Clone, Debug, PartialEq)]
pub enum Back {
    /// Absorbs: a one-sided surface, as Mitsuba's BSDFs are unless wrapped in `twosided`.
    Black,
    /// Scatters as the front does.
    Same,
    /// Scatters with another family.
    Other(Box<Surface>),
}

/// A material: its front's family, its back, and its opacity (a cut-out's holes let light straight through).
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    pub front: Surface,
    pub back: Back,
    /// The probability that the surface is there, 1 where None.
    pub opacity: Option<Texture>,
    uses_uv: bool,
}

impl Material {
    /// A material of `front` and `back` with an optional opacity.
    pub fn new(front: Surface, back: Back, opacity: Option<Texture>) -> Self {
        let back_varies = match &back {
            Back::Other(s) => s.varies(),
            _ => false,
        };
        let uses_uv = front.varies() || back_varies || opacity.as_ref().is_some_and(Texture::varies);
        Material { front, back, opacity, uses_uv }
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

    /// True for a smooth dielectric interface, where ghosts reflect.
    pub fn is_dielectric(&self) -> bool {
        matches!(self.front, Surface::Dielectric { .. })
    }

    /// True when the material's behaviour depends on wavelength: a scene with one renders spectrally.
    pub fn is_dispersive(&self) -> bool {
        matches!(self.front, Surface::Dielectric { ior, ext_ior, .. } if ior.is_dispersive() || ext_ior.is_dispersive())
    }

    /// True when some side has a delta lobe (then caustics exist), or the surface is partly cut out.
    pub fn has_delta(&self) -> bool {
        let back = match &self.back {
            Back::Other(s) => s.flags().is_specular(),
            _ => false,
        };
        self.front.flags().is_specular() || back || self.opacity.is_some()
    }

    /// The BSDF at `hit` (texture coordinates `uv`) for a path arriving from `wo`: the side `wo` lies on, by
    /// the geometric normal, chooses the family, and the frame is turned to that side.
    #[inline]
    pub fn bsdf(&self, hit: &SurfaceHit, uv: Vec2, wo: Vec3) -> Bsdf {
        let front = wo.dot(hit.ng) >= 0.0;
        let (ng, ns) = if front { (hit.ng, hit.ns) } else { (-hit.ng, -hit.ns) };
        let surface = match (&self.back, front) {
            _ if front || self.front.is_interface() => &self.front,
            (Back::Same, _) => &self.front,
            (Back::Other(s), _) => s,
            (Back::Black, _) => return Bsdf::new(Model::Black, Frame::from_normal(ns), ng, 1.0),
        };
        let opacity = self.opacity.as_ref().map_or(1.0, |t| t.eval_scalar(uv).clamp(0.0, 1.0));
        Bsdf::new(surface.resolve(uv, front), Frame::from_normal(ns), ng, opacity)
    }
}
