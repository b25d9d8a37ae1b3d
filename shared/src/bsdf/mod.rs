//! Scattering at a surface: the BSDF interface every material family implements, one file per family, and
//! [`Bsdf`], a family resolved at one surface point with its shading frame, which is what the path walk reads.
//!
//! # Conventions
//!
//! A family works in a local frame whose z axis is the shading normal turned to the side the path arrived
//! from. `wo` points back along the path (toward the previous vertex: the camera side for a camera path, the
//! light side for a light path), `wi` is the continuation; both are unit vectors leaving the surface.
//! `eval` returns f(wo, wi) without the cosine; `Transport` says which kind of path asks, since a refraction
//! scales radiance by (η_o/η_t)² and flux not at all (Veach's thesis §5.2). [`Bsdf`] turns world directions
//! into local ones, keeps reflection and transmission on the sides the geometric normal allows, and applies
//! the shading-normal correction of the adjoint BSDF (Veach §5.3) to light paths.
//!
//! # Lobes and the estimator
//!
//! A BSDF is a sum of lobes, each diffuse, glossy or specular (a Dirac delta) and reflecting or transmitting.
//! Photon mapping evaluates a BSDF between two independently traced directions, which is hopeless for a delta
//! lobe and noisy for a sharp glossy one, so the non-delta lobes are split in two classes:
//! - **stored** lobes (diffuse ones, and glossy ones with roughness α ≥ [`STORED_MIN_ALPHA`]): camera paths store
//!   backward photons where a BSDF has them, and a gather evaluates them ([`Bsdf::eval_stored`]);
//! - **pass** lobes (delta lobes and sharper glossy ones): camera and light paths sample through them.
//!
//! `sample` picks one lobe class and reports it ([`BsdfSample::stored`]); its `weight` estimates that class's
//! integral alone (f_class · |cos| / pdf_class), so that the camera paths' continuations and the photons
//! together count every path once. Its `direct` weight estimates the whole non-delta BSDF at the sampled
//! direction (f · |cos| / pdf over the non-delta lobes), which an emitter hit right after the vertex uses,
//! against next-event estimation with the same pdf (multiple importance sampling). Where all non-delta lobes
//! are of one class, the two weights are equal.

pub mod coating;
pub mod conductor;
pub mod dielectric;
pub mod diffuse;
pub mod fresnel;
pub mod metals;
pub mod microfacet;
pub mod plastic;
pub mod principled;
pub mod rough_dielectric;
pub mod thin_dielectric;

use crate::color::Rgb;
use crate::sampling::Frame;
use crate::spectrum::{Dispersive, Wavelength};
use glam::{Vec2, Vec3};

pub use coating::Coating;
pub use conductor::Conductor;
pub use dielectric::{Dielectric, Reflection};
pub use diffuse::Diffuse;
pub use plastic::Plastic;
pub use principled::Principled;
pub use rough_dielectric::RoughDielectric;
pub use thin_dielectric::ThinDielectric;

/// Which quantity a path carries across a scattering event: camera paths carry radiance (they are adjoint to
/// light flow), light paths carry flux (importance transport). Veach's thesis §5.2 gives the two rules.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Transport {
    Radiance,
    Importance,
}

/// Glossy lobes at least this rough (the microfacet α, or the geometric mean of an anisotropic pair) are
/// stored: photons gather them. Sharper ones are sampled through. The value is measured in docs/estimator.md
/// ("Glossy surfaces").
pub const STORED_MIN_ALPHA: f32 = 0.3;

/// True when a glossy lobe of roughness `alpha` is one photons gather (see the module's doc).
#[inline]
pub fn stores_glossy(alpha: f32) -> bool {
    alpha >= STORED_MIN_ALPHA
}

/// The kinds of lobes a BSDF has, or the one lobe a sample took, as bits.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct LobeFlags(pub u8);

impl LobeFlags {
    pub const NONE: LobeFlags = LobeFlags(0);
    pub const DIFFUSE: LobeFlags = LobeFlags(1);
    pub const GLOSSY: LobeFlags = LobeFlags(1 << 1);
    /// A Dirac delta: only sampling finds it.
    pub const SPECULAR: LobeFlags = LobeFlags(1 << 2);
    pub const REFLECTION: LobeFlags = LobeFlags(1 << 3);
    pub const TRANSMISSION: LobeFlags = LobeFlags(1 << 4);
    /// A dielectric's reflection where no refraction was possible (set with SPECULAR | REFLECTION).
    pub const TOTAL_INTERNAL: LobeFlags = LobeFlags(1 << 5);
    /// At least one non-delta lobe is stored (photons gather it).
    pub const STORED: LobeFlags = LobeFlags(1 << 6);
    /// At least one non-delta lobe is not stored: paths sample through it.
    pub const PASS: LobeFlags = LobeFlags(1 << 7);

    /// True when every bit of `other` is set.
    #[inline]
    pub fn contains(self, other: LobeFlags) -> bool {
        self.0 & other.0 == other.0
    }

    /// True when some bit of `other` is set.
    #[inline]
    pub fn intersects(self, other: LobeFlags) -> bool {
        self.0 & other.0 != 0
    }

    /// True for a delta lobe.
    #[inline]
    pub fn is_specular(self) -> bool {
        self.intersects(LobeFlags::SPECULAR)
    }

    /// True when the lobe (or some lobe) is not a delta.
    #[inline]
    pub fn is_non_delta(self) -> bool {
        self.intersects(LobeFlags(LobeFlags::DIFFUSE.0 | LobeFlags::GLOSSY.0))
    }
}

impl std::ops::BitOr for LobeFlags {
    type Output = LobeFlags;

    /// Both sets of bits.
    #[inline]
    fn bitor(self, o: LobeFlags) -> LobeFlags {
        LobeFlags(self.0 | o.0)
    }
}

/// A sampled continuation in a family's local frame, or, from [`Bsdf::sample`], in world space.
#[derive(Clone, Copy, Debug)]
pub struct BsdfSample {
    /// The new direction, leaving the surface.
    pub wi: Vec3,
    /// f_class · |cos θ_i| / pdf_class for the class of lobes picked (see the module's doc), with the transport
    /// mode's factors: what the path's throughput is multiplied by.
    pub weight: Rgb,
    /// f · |cos θ_i| / pdf over all non-delta lobes at `wi`, for an emitter hit right after this vertex; equal
    /// to `weight` for a delta sample and wherever one class holds every non-delta lobe.
    pub direct: Rgb,
    /// Solid-angle pdf of `wi` over the non-delta lobes (what multiple importance sampling compares with a light
    /// sample's); zero for a delta sample.
    pub pdf: f32,
    /// The lobe taken: one of DIFFUSE, GLOSSY, SPECULAR, one of REFLECTION, TRANSMISSION, and TOTAL_INTERNAL
    /// where that applies.
    pub lobe: LobeFlags,
    /// True when the lobe taken is a stored one.
    pub stored: bool,
    /// The (η_o/η_t)² that `weight` holds for a camera path refracted across an interface (1 otherwise): it
    /// rescales radiance rather than losing energy, so Russian roulette must not read it as a loss.
    pub radiance_scale: f32,
}

impl BsdfSample {
    /// A delta event in direction `wi` with weight `weight`, of the given lobe, that rescales no radiance.
    #[inline]
    pub fn specular(wi: Vec3, weight: Rgb, lobe: LobeFlags) -> Self {
        BsdfSample {
            wi,
            weight,
            direct: weight,
            pdf: 0.0,
            lobe: lobe | LobeFlags::SPECULAR,
            stored: false,
            radiance_scale: 1.0,
        }
    }

    /// A non-delta sample whose class holds every non-delta lobe: `weight` is also its `direct` weight.
    #[inline]
    pub fn single_class(wi: Vec3, weight: Rgb, pdf: f32, lobe: LobeFlags, stored: bool) -> Self {
        BsdfSample { wi, weight, direct: weight, pdf, lobe, stored, radiance_scale: 1.0 }
    }

    /// True for a delta sample.
    #[inline]
    pub fn is_delta(&self) -> bool {
        self.lobe.is_specular()
    }
}

/// The continuations a BSDF's delta lobes can take for one direction, each with the probability that sampling
/// picks it ([`Bsdf::delta_branches`]): at most three (a cut-out's hole and two lobes). They are kept inline, not
/// allocated, since the lit-pixel mask asks for them at every surface its rays meet.
#[derive(Clone, Copy, Debug)]
pub struct DeltaBranches {
    items: [(BsdfSample, f32); 3],
    len: usize,
}

impl Default for DeltaBranches {
    #[inline]
    fn default() -> Self {
        let none = (BsdfSample::specular(Vec3::ZERO, Rgb::ZERO, LobeFlags::NONE), 0.0);
        DeltaBranches { items: [none; 3], len: 0 }
    }
}

impl DeltaBranches {
    /// Adds the branch `s` taken with probability `p`.
    #[inline]
    pub fn push(&mut self, s: BsdfSample, p: f32) {
        self.items[self.len] = (s, p);
        self.len += 1;
    }
}

impl std::ops::Deref for DeltaBranches {
    type Target = [(BsdfSample, f32)];

    #[inline]
    fn deref(&self) -> &Self::Target {
        &self.items[..self.len]
    }
}

impl IntoIterator for DeltaBranches {
    type Item = (BsdfSample, f32);
    type IntoIter = std::iter::Take<std::array::IntoIter<(BsdfSample, f32), 3>>;

    #[inline]
    fn into_iter(self) -> Self::IntoIter {
        self.items.into_iter().take(self.len)
    }
}

/// What every family provides, in its local frame (see the module's doc for the conventions).
pub trait Scatter {
    /// The lobes the BSDF has, with `LobeFlags::STORED` when some non-delta lobe is stored.
    fn flags(&self) -> LobeFlags;

    /// f(wo, wi) over the non-delta lobes, or over the stored ones alone with `stored_only`.
    fn eval(&self, wo: Vec3, wi: Vec3, mode: Transport, stored_only: bool) -> Rgb;

    /// The solid-angle density with which `sample` returns `wi` through a non-delta lobe.
    fn pdf(&self, wo: Vec3, wi: Vec3) -> f32;

    /// The density with which `sample` returns `wi` through a stored lobe (and picks that class): `pdf` where
    /// every non-delta lobe is stored, zero where none is. Families with lobes of both classes say it.
    fn pdf_stored(&self, wo: Vec3, wi: Vec3) -> f32 {
        let f = self.flags();
        if f.contains(LobeFlags::STORED) && !f.contains(LobeFlags::PASS) {
            self.pdf(wo, wi)
        } else {
            0.0
        }
    }

    /// Samples a continuation for the uniform numbers `u`; None when the path is absorbed.
    fn sample(&self, wo: Vec3, u: Vec2, mode: Transport) -> Option<BsdfSample>;

    /// The family as a path at one wavelength sees it: colours read at the wavelength (the same value in every
    /// channel), refractive indices evaluated there.
    fn at_wavelength(&self, w: &Wavelength) -> Self
    where
        Self: Sized;

    /// True when the behaviour depends on wavelength (a dispersive refractive index).
    fn is_dispersive(&self) -> bool {
        false
    }
}

/// A family resolved at a surface point: its parameters with the textures read there.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Model {
    /// The back of a one-sided surface: it absorbs.
    Black,
    Diffuse(Diffuse),
    Conductor(Conductor),
    Dielectric(Dielectric),
    RoughDielectric(RoughDielectric),
    ThinDielectric(ThinDielectric),
    Plastic(Plastic),
    Principled(Principled),
    Coating(Coating),
}

/// Dispatches a `Scatter` method to the family of a `Model`.
macro_rules! dispatch {
    ($model:expr, $m:ident => $body:expr, $black:expr) => {
        match $model {
            Model::Black => $black,
            Model::Diffuse($m) => $body,
            Model::Conductor($m) => $body,
            Model::Dielectric($m) => $body,
            Model::RoughDielectric($m) => $body,
            Model::ThinDielectric($m) => $body,
            Model::Plastic($m) => $body,
            Model::Principled($m) => $body,
            Model::Coating($m) => $body,
        }
    };
}

impl Model {
    /// The lobes the model has.
    #[inline]
    pub fn flags(&self) -> LobeFlags {
        dispatch!(self, m => m.flags(), LobeFlags::NONE)
    }

    /// The family in its local frame, for checks of its own (None for `Black`).
    pub fn scatter(&self) -> Option<&dyn Scatter> {
        dispatch!(self, m => Some(m as &dyn Scatter), None)
    }
}

/// A BSDF at one surface point in world space: a resolved family, its shading frame (z on the side the path
/// arrived from) and the geometric normal there, and the surface's opacity (a cut-out lets the rest through).
#[derive(Clone, Copy, Debug)]
pub struct Bsdf {
    pub model: Model,
    frame: Frame,
    /// The geometric normal on the side the path arrived from.
    ng: Vec3,
    /// The probability that the surface is there at all (1 for an ordinary surface); the rest passes straight
    /// through, a delta transmission.
    opacity: f32,
}

impl Bsdf {
    /// The BSDF of `model` at a point with geometric normal `ng` and shading frame `frame`, for a path arriving
    /// from `wo`: `frame` and `ng` must already be turned to `wo`'s side of the geometric normal.
    #[inline]
    pub fn new(model: Model, frame: Frame, ng: Vec3, opacity: f32) -> Self {
        Bsdf { model, frame, ng, opacity }
    }

    /// The shading normal on the side the path arrived from.
    #[inline]
    pub fn shading_normal(&self) -> Vec3 {
        self.frame.n
    }

    /// The geometric normal on the side the path arrived from.
    #[inline]
    pub fn geometric_normal(&self) -> Vec3 {
        self.ng
    }

    /// The lobes, with a straight-through delta transmission where the surface is partly cut out.
    #[inline]
    pub fn flags(&self) -> LobeFlags {
        let f = self.model.flags();
        if self.opacity < 1.0 {
            f | LobeFlags::SPECULAR | LobeFlags::TRANSMISSION
        } else {
            f
        }
    }

    /// True when some non-delta lobe is stored: a camera path stores a backward photon here.
    #[inline]
    pub fn has_stored(&self) -> bool {
        self.model.flags().contains(LobeFlags::STORED)
    }

    /// True when some lobe is sampled through rather than stored: a delta lobe (a cut-out's holes included) or
    /// a glossy lobe too sharp to store.
    #[inline]
    pub fn has_pass(&self) -> bool {
        self.flags().intersects(LobeFlags(LobeFlags::SPECULAR.0 | LobeFlags::PASS.0))
    }

    /// True when the surface absorbs everything: the back of a one-sided surface, or a black diffuse one.
    #[inline]
    pub fn is_black(&self) -> bool {
        match self.model {
            Model::Black => true,
            Model::Diffuse(d) => d.reflectance == Rgb::ZERO && self.opacity >= 1.0,
            _ => false,
        }
    }

    /// True when some lobe is not a delta: next-event estimation can find light here.
    #[inline]
    pub fn has_non_delta(&self) -> bool {
        self.model.flags().is_non_delta()
    }

    /// The albedo of a plain Lambertian surface, whose stored lobe a photon can carry premultiplied; None for
    /// every other BSDF.
    #[inline]
    pub fn lambertian(&self) -> Option<Rgb> {
        match self.model {
            Model::Diffuse(d) if self.opacity >= 1.0 => Some(d.reflectance),
            _ => None,
        }
    }

    /// True when `wo` and `wi` leave through the sides of the geometric normal that a reflection (same side) or
    /// a transmission (opposite sides) needs, as the local frame sees them: shading normals must not let light
    /// through a surface or reflect it from behind.
    #[inline]
    fn sides_agree(&self, wi: Vec3, local_wi_z: f32) -> bool {
        (wi.dot(self.ng) > 0.0) == (local_wi_z > 0.0)
    }

    /// f(wo, wi) over the non-delta lobes, zero where the geometric normal forbids the pair. `wo` and `wi` are
    /// world directions.
    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3, mode: Transport) -> Rgb {
        self.eval_lobes(wo, wi, mode, false)
    }

    /// f(wo, wi) over the stored lobes, what a backward photon's gather evaluates.
    #[inline]
    pub fn eval_stored(&self, wo: Vec3, wi: Vec3, mode: Transport) -> Rgb {
        self.eval_lobes(wo, wi, mode, true)
    }

    #[inline]
    fn eval_lobes(&self, wo: Vec3, wi: Vec3, mode: Transport, stored_only: bool) -> Rgb {
        let (lo, li) = (self.frame.to_local(wo), self.frame.to_local(wi));
        if !self.sides_agree(wi, li.z) {
            return Rgb::ZERO;
        }
        let f = dispatch!(&self.model, m => m.eval(lo, li, mode, stored_only), Rgb::ZERO);
        f * self.opacity * self.correction(wo, wi, mode)
    }

    /// The density with which `sample` returns `wi` through a non-delta lobe.
    #[inline]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        let (lo, li) = (self.frame.to_local(wo), self.frame.to_local(wi));
        if !self.sides_agree(wi, li.z) {
            return 0.0;
        }
        dispatch!(&self.model, m => m.pdf(lo, li), 0.0) * self.opacity
    }

    /// Samples a continuation from `wo` (world) for the uniform numbers `u`: the straight-through part of a
    /// cut-out first, then the family. None when the path is absorbed or would leave through the wrong side of
    /// the geometry.
    #[inline]
    pub fn sample(&self, wo: Vec3, u: Vec2, mode: Transport) -> Option<BsdfSample> {
        // A smooth dielectric's own sampling is its choice by Fresnel reflectance.
        self.sample_reflecting(wo, u, mode, Reflection::Fresnel)
    }

    /// `sample` where a smooth dielectric chooses between reflection and refraction by `choice` rather than by
    /// its Fresnel reflectance (`Dielectric::sample_reflecting`); other families sample as `sample` does.
    #[inline(always)]
    pub fn sample_reflecting(&self, wo: Vec3, mut u: Vec2, mode: Transport, choice: Reflection) -> Option<BsdfSample> {
        if self.opacity < 1.0 {
            // The cut-out's share passes straight through, a delta transmission of weight 1.
            let pass = 1.0 - self.opacity;
            if u.x < pass {
                return Some(BsdfSample::specular(-wo, Rgb::ONE, LobeFlags::TRANSMISSION));
            }
            u.x = ((u.x - pass) / self.opacity).min(1.0 - f32::EPSILON / 2.0);
        }
        let lo = self.frame.to_local(wo);
        let mut s = match &self.model {
            Model::Dielectric(d) => d.sample_reflecting(lo, u, mode, choice),
            m => dispatch!(m, m => m.sample(lo, u, mode), None),
        }?;
        let local_z = s.wi.z;
        s.wi = self.frame.to_world(s.wi);
        if !s.is_delta() && !self.sides_agree(s.wi, local_z) {
            return None;
        }
        // The family is chosen with probability `opacity` and weighs `opacity` as much: its weights stand, its
        // density over the whole surface is `opacity` of its own.
        s.pdf *= self.opacity;
        if mode == Transport::Importance {
            let c = self.correction(wo, s.wi, mode);
            if c.is_nan() || c <= 0.0 {
                return None;
            }
            s.weight *= c;
            s.direct *= c;
        }
        Some(s)
    }

    /// The shading-normal factor of the adjoint BSDF: |wo·ns| |wi·ng| / (|wo·ng| |wi·ns|) for light paths
    /// (Veach §5.3), 1 for camera paths.
    #[inline]
    fn correction(&self, wo: Vec3, wi: Vec3, mode: Transport) -> f32 {
        match mode {
            Transport::Radiance => 1.0,
            Transport::Importance => {
                let ns = self.frame.n;
                let den = wo.dot(self.ng).abs() * wi.dot(ns).abs();
                if den <= 0.0 {
                    return 0.0;
                }
                wo.dot(ns).abs() * wi.dot(self.ng).abs() / den
            }
        }
    }

    /// Every continuation a delta lobe can take for `wo` with the probability that `sample` picks it. Empty
    /// where no lobe is a delta. Lets a caller follow every specular branch of a camera path instead of
    /// sampling one.
    pub fn delta_branches(&self, wo: Vec3) -> DeltaBranches {
        let mut branches = DeltaBranches::default();
        if self.opacity < 1.0 {
            branches.push(BsdfSample::specular(-wo, Rgb::ONE, LobeFlags::TRANSMISSION), 1.0 - self.opacity);
        }
        let lo = self.frame.to_local(wo);
        let family = match &self.model {
            Model::Dielectric(d) => d.delta_branches(lo),
            Model::Conductor(c) => c.delta_branches(lo),
            Model::Coating(c) => c.delta_branches(lo),
            Model::ThinDielectric(t) => t.delta_branches(lo),
            Model::Plastic(p) => p.delta_branches(lo),
            Model::Diffuse(_) | Model::RoughDielectric(_) | Model::Principled(_) | Model::Black => return branches,
        };
        for (mut s, p) in family {
            s.wi = self.frame.to_world(s.wi);
            branches.push(s, p * self.opacity);
        }
        branches
    }

    /// True when the sample was a specular reflection at a smooth dielectric: a ghost's reflection
    /// (`crate::ghost`).
    #[inline]
    pub fn is_dielectric_reflection(&self, s: &BsdfSample) -> bool {
        matches!(self.model, Model::Dielectric(_)) && s.lobe.contains(LobeFlags::SPECULAR | LobeFlags::REFLECTION)
    }

    /// True for a smooth dielectric interface (a lens surface, a glass's face).
    #[inline]
    pub fn is_dielectric(&self) -> bool {
        matches!(self.model, Model::Dielectric(_))
    }
}

impl Dispersive for Bsdf {
    /// True when the family's behaviour depends on wavelength: a path that meets it becomes spectral.
    #[inline]
    fn is_dispersive(&self) -> bool {
        dispatch!(&self.model, m => m.is_dispersive(), false)
    }

    /// The BSDF as a path at one wavelength sees it.
    fn at_wavelength(&self, w: &Wavelength) -> Bsdf {
        let model = match &self.model {
            Model::Black => Model::Black,
            Model::Diffuse(m) => Model::Diffuse(m.at_wavelength(w)),
            Model::Conductor(m) => Model::Conductor(m.at_wavelength(w)),
            Model::Dielectric(m) => Model::Dielectric(m.at_wavelength(w)),
            Model::RoughDielectric(m) => Model::RoughDielectric(m.at_wavelength(w)),
            Model::ThinDielectric(m) => Model::ThinDielectric(m.at_wavelength(w)),
            Model::Plastic(m) => Model::Plastic(m.at_wavelength(w)),
            Model::Principled(m) => Model::Principled(m.at_wavelength(w)),
            Model::Coating(m) => Model::Coating(m.at_wavelength(w)),
        };
        Bsdf { model, ..*self }
    }
}

/// A family's non-delta BSDF and sampling density at one pair of directions, split by lobe class: what a family
/// with lobes of both classes (stored and pass) turns into a sample of one class.
#[derive(Clone, Copy, Debug, Default)]
pub struct ByClass {
    /// f of the stored lobes.
    pub stored_f: Rgb,
    /// The density of sampling the direction through a stored lobe (the class's choice included).
    pub stored_pdf: f32,
    /// f of the pass lobes.
    pub pass_f: Rgb,
    /// The density of sampling the direction through a pass lobe.
    pub pass_pdf: f32,
}

impl ByClass {
    /// f over every non-delta lobe, or over the stored ones alone.
    #[inline]
    pub fn f(&self, stored_only: bool) -> Rgb {
        if stored_only {
            self.stored_f
        } else {
            self.stored_f + self.pass_f
        }
    }

    /// The density over every non-delta lobe.
    #[inline]
    pub fn pdf(&self) -> f32 {
        self.stored_pdf + self.pass_pdf
    }

    /// The sample of `wi` (cosine `cos_i` with the local normal) taken through a lobe of the stored class or of
    /// the pass class: its weight estimates that class, its `direct` weight every non-delta lobe. None where the
    /// class's density vanishes or a weight is not finite.
    #[inline]
    pub fn sample(&self, wi: Vec3, lobe: LobeFlags, stored: bool, radiance_scale: f32) -> Option<BsdfSample> {
        let cos = wi.z.abs();
        let (f, pdf) = if stored { (self.stored_f, self.stored_pdf) } else { (self.pass_f, self.pass_pdf) };
        let pdf_all = self.pdf();
        if !(pdf > 0.0 && pdf.is_finite()) {
            return None;
        }
        let weight = f * (cos / pdf);
        let direct = self.f(false) * (cos / pdf_all);
        if !(weight.is_finite() && direct.is_finite()) {
            return None;
        }
        Some(BsdfSample { wi, weight, direct, pdf: pdf_all, lobe, stored, radiance_scale })
    }
}

/// A third uniform number for a family whose sampling needs one more than the two it is given (a choice that
/// depends on the microfacet normal the two numbers drew, as Mitsuba's rough dielectric makes): a hash of the
/// two numbers' bits. Every pair of inputs gives an unrelated output, so over the pairs the three numbers are as
/// independent as a pseudo-random stream's, and the path walk's count of numbers per bounce stays two.
#[inline]
pub fn third_uniform(u: Vec2) -> f32 {
    let mut z = ((u.x.to_bits() as u64) << 32 | u.y.to_bits() as u64).wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 40) as f32 * (1.0 / 16_777_216.0)
}

/// Mirror reflection of `wo` about `n`.
#[inline]
pub fn reflect(wo: Vec3, n: Vec3) -> Vec3 {
    2.0 * wo.dot(n) * n - wo
}

/// The refraction of `wo` (leaving the surface on the side of `n`) into the other side, for η = η_o/η_t;
/// None under total internal reflection.
#[inline]
pub fn refract(wo: Vec3, n: Vec3, eta: f32) -> Option<Vec3> {
    let cos_o = wo.dot(n);
    let sin2_t = eta * eta * (1.0 - cos_o * cos_o).max(0.0);
    if sin2_t >= 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    Some((-wo * eta + n * (eta * cos_o - cos_t)).normalize())
}

/// A colour read at one wavelength: its value there in every channel.
#[inline]
pub fn grey_at(c: Rgb, w: &Wavelength) -> Rgb {
    Rgb::splat(w.value_of(c))
}
