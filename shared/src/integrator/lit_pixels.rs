//! Deciding the lit-pixel mask (`accumulation::LitMask`) from the scene: stratified primary rays per pixel that
//! follow every specular branch and look for an emitter, or for an environment where they leave the scene.

use crate::accumulation::lit_mask::{LitMask, LIT_MASK_SAMPLES};
use crate::color::Rgb;
use crate::geometry::{ray::offset_origin, Ray};
use crate::scene::Scene;
use glam::Vec2;
use rayon::prelude::*;

/// Segments traced per pixel at most. The branches of a pixel's primary rays are followed likeliest first: the
/// main chain of every ray costs a segment per surface (about 14 through the double Gauss lens of `lens.toml`),
/// and each uncoated surface it crosses spawns a reflection.
const PIXEL_BUDGET: u32 = 16 * LIT_MASK_SAMPLES;

/// Branches less likely than this (the product of their reflection and transmission probabilities) are not
/// followed. A light seen through glass, in a reflection off it, or after two reflections inside a glass
/// sphere (a 0.2% branch, whose rare, bright samples are what a noise-based mask would drop after the first
/// one) makes a pixel lit.
const MIN_BRANCH_PROBABILITY: f32 = 1e-4;

/// Fixed scrambling of the mask's Sobol points: the mask must not depend on the run's seed.
const MASK_SEED: u32 = 0x6c69_7431;

impl LitMask {
    /// Decides which pixels of `scene` see an emitter directly or through specular surfaces only, within
    /// `max_depth` segments: `LIT_MASK_SAMPLES` primary rays per pixel, their pixel positions and aperture
    /// points the first four coordinates of a scrambled Sobol sequence (stratified in both), each followed
    /// into every reflection and transmission of the delta surfaces it meets, likeliest branch first, up to
    /// `PIXEL_BUDGET` segments per pixel; the pixels next to those are lit too (`with_neighbours_lit`).
    pub fn of_scene(scene: &Scene, max_depth: u32) -> LitMask {
        let camera = &scene.camera;
        let w = camera.width as usize;
        let lit: Vec<bool> = (0..camera.pixel_count())
            .into_par_iter()
            .with_min_len(64)
            .map(|i| {
                let (x, y) = ((i % w) as u32, (i / w) as u32);
                let rays = (0..LIT_MASK_SAMPLES).filter_map(|k| {
                    let u = sobol_burley::sample_4d(k, 0, MASK_SEED ^ i as u32);
                    let r = camera.generate_ray(x, y, Vec2::new(u[0], u[1]), Vec2::new(u[2], u[3]));
                    (r.weight > 0.0).then_some(r.ray)
                });
                sees_emitter(scene, rays, max_depth)
            })
            .collect();
        LitMask::from_flags(camera.width, camera.height, lit, LIT_MASK_SAMPLES).with_neighbours_lit()
    }
}

/// A ray of the specular tree still to trace: its segment number and the probability of its branch.
struct Branch {
    ray: Ray,
    segment: u32,
    probability: f32,
}

/// True when some branch of the specular trees from `rays` reaches an emitter, or leaves the scene toward an
/// infinite light's radiance, before a diffuse surface.
fn sees_emitter(scene: &Scene, rays: impl Iterator<Item = Ray>, max_depth: u32) -> bool {
    let mut frontier: Vec<Branch> = rays.map(|ray| Branch { ray, segment: 1, probability: 1.0 }).collect();
    for _ in 0..PIXEL_BUDGET {
        // The frontier holds a few branches per primary ray: a scan for the likeliest is cheap.
        let Some(next) =
            (0..frontier.len()).max_by(|&a, &b| frontier[a].probability.total_cmp(&frontier[b].probability))
        else {
            return false;
        };
        let Branch { ray, segment, probability } = frontier.swap_remove(next);
        let Some(hit) = scene.geometry.intersect(&ray) else {
            // A ray that leaves the scene sees the infinite lights.
            if scene.lights.escaped(ray.direction, None) != Rgb::ZERO {
                return true;
            }
            continue;
        };
        if scene.lights.emitted(&hit, ray.direction) != Rgb::ZERO {
            return true;
        }
        // Most surfaces have no delta lobe: a cached flag skips resolving their BSDF, which would find no branch.
        if segment >= max_depth || !scene.material_at(&hit).has_delta() {
            continue;
        }
        let wo = -ray.direction;
        for (s, p) in scene.bsdf(&hit, wo).delta_branches(wo) {
            if s.weight != Rgb::ZERO && probability * p >= MIN_BRANCH_PROBABILITY {
                let ray = Ray::new(offset_origin(hit.p, hit.ng, s.wi), s.wi);
                frontier.push(Branch { ray, segment: segment + 1, probability: probability * p });
            }
        }
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn delta_branches_of_glass_are_a_reflection_and_a_refraction_whose_probabilities_add_to_one() {
        use crate::geometry::SurfaceHit;
        use crate::material::{Material, Surface};
        use crate::spectrum::RefractiveIndex;
        use crate::texture::Texture;
        use glam::{Vec2, Vec3};
        let glass = Material::two_sided(Surface::Dielectric {
            ior: RefractiveIndex::constant(1.5),
            ext_ior: RefractiveIndex::constant(1.0),
            anti_reflection: false,
        });
        let hit = SurfaceHit { t: 1.0, p: Vec3::ZERO, ng: Vec3::Z, ns: Vec3::Z, object: 0, triangle: u32::MAX };
        let wo = Vec3::new(0.3, 0.0, 1.0).normalize();
        let b = glass.bsdf(&hit, Vec2::ZERO, wo).delta_branches(wo);
        assert_eq!(b.len(), 2);
        assert!((b[0].1 + b[1].1 - 1.0).abs() < 1e-6);
        assert!(b[0].0.wi.z > 0.0 && b[1].0.wi.z < 0.0, "reflected up, refracted down");
        let diffuse = Material::two_sided(Surface::Diffuse { reflectance: Texture::Constant(Rgb::ONE) });
        assert!(diffuse.bsdf(&hit, Vec2::ZERO, wo).delta_branches(wo).is_empty());
    }
}
