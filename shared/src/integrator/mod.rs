//! Camera-path pieces shared by the reference path tracer and the PBPM backward pass: the image layers and
//! next-event estimation of direct light; also which pixels see a light (`lit_pixels`), for the lit mask.

pub mod camera_path;
pub mod lit_pixels;
pub mod path_tracer;
pub mod walk;

use crate::bsdf::{Bsdf, Transport};
use crate::color::Rgb;
use crate::geometry::{ray::offset_origin, SurfaceHit};
use crate::sampling::Sampler;
use crate::scene::Scene;
use crate::spectrum::PathSpectrum;
use glam::Vec3;

/// The illumination components the image is split into (paper §2's layers 1–4).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layer {
    /// Emitters seen from the camera directly or through specular surfaces only (E S* L).
    VisibleLights = 0,
    /// Light reaching the first diffuse vertex straight from an emitter (E S* D L).
    Direct = 1,
    /// Light with at least one bounce before the second diffuse vertex's view, i.e. every path with two or more
    /// diffuse vertices.
    Indirect = 2,
    /// Light reaching the first diffuse vertex through specular surfaces only (E S* D S+ L).
    Caustic = 3,
}

impl Layer {
    /// All layers in storage order.
    pub const ALL: [Layer; 4] = [Layer::VisibleLights, Layer::Direct, Layer::Indirect, Layer::Caustic];

    /// Name used for EXR layers and records.
    pub fn name(self) -> &'static str {
        match self {
            Layer::VisibleLights => "visible_lights",
            Layer::Direct => "direct",
            Layer::Indirect => "indirect",
            Layer::Caustic => "caustic",
        }
    }
}

/// One pixel's estimate split into layers.
pub type LayerValues = [Rgb; 4];

/// Adds a camera path's contribution to its layer and, on a ghost path (`crate::ghost`), to the ghost light.
#[inline]
pub(crate) fn add_contribution(out: &mut LayerValues, ghost: &mut Option<Rgb>, layer: Layer, value: Rgb) {
    out[layer as usize] += value;
    if let Some(g) = ghost {
        *g += value;
    }
}

/// A next-event estimate at a vertex, before MIS weighting and before the path throughput.
#[derive(Clone, Copy, Debug)]
pub struct DirectSample {
    /// f · Li · |cos| / pdf_light.
    pub value: Rgb,
    /// Solid-angle pdf of the light sample (selection included).
    pub light_pdf: f32,
    /// True for point and spot lights, which the BSDF can never hit.
    pub delta: bool,
    /// Solid-angle pdf with which sampling the BSDF would have picked the same direction.
    pub bsdf_pdf: f32,
}

/// Samples direct light at a vertex with BSDF `bsdf` and outgoing direction `wo` (paper eq. 5's light term),
/// in the path's colour terms (`bsdf` already is), over the BSDF's non-delta lobes or, with `stored_only`, over
/// its stored ones. Returns None when the sample carries nothing (wrong side, occluded).
pub fn sample_direct<const S: bool>(
    scene: &Scene,
    hit: &SurfaceHit,
    bsdf: &Bsdf,
    wo: Vec3,
    stored_only: bool,
    path: &PathSpectrum<S>,
    sampler: &mut Sampler,
) -> Option<DirectSample> {
    let u_select = sampler.next_f32();
    let u = sampler.next_2d();
    let ls = scene.lights.sample_incident(&scene.geometry, hit.p, u_select, u)?;
    let f = if stored_only {
        bsdf.eval_stored(wo, ls.wi, Transport::Radiance)
    } else {
        bsdf.eval(wo, ls.wi, Transport::Radiance)
    };
    let cos = ls.wi.dot(bsdf.shading_normal()).abs();
    if f == Rgb::ZERO || cos <= 0.0 || ls.li == Rgb::ZERO {
        return None;
    }
    let origin = offset_origin(hit.p, hit.ng, ls.wi);
    if !scene.geometry.unoccluded(origin, ls.point) {
        return None;
    }
    Some(DirectSample {
        value: f * path.quantity(ls.li) * (cos / ls.pdf),
        light_pdf: ls.pdf,
        delta: ls.delta,
        bsdf_pdf: bsdf.pdf(wo, ls.wi),
    })
}
